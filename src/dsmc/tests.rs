//! A finished run continued to a later end equals, bit for bit, the run made straight to it.

use super::*;
use crate::dsmc::system::{power_law_species, RestitutionModel};

/// A small polydisperse gas (N1 = 800, theta = 2.5, n1 = 0.1) ending at `t_end` with
/// outputs at `times` (t_end added).
fn system(method: Method, msd: bool, viscoelastic: bool, t_end: f64, times: &[f64]) -> DsmcSystem {
    let species = power_law_species(800, 2.5, 1.0).unwrap();
    let volume = 800.0 / 0.1;
    let mut output_times: Vec<f64> = times.iter().copied().filter(|&t| t < t_end).collect();
    output_times.push(t_end);
    DsmcSystem {
        method,
        species,
        volume,
        restitution: if viscoelastic {
            RestitutionModel::Viscoelastic { a_kappa: 0.2 }
        } else {
            RestitutionModel::Constant(0.5)
        },
        t_end,
        output_times,
        msd,
        tamsd: None,
        vdist: None,
        refresh_every: 0.3,
        rate_scale: std::f64::consts::PI / (4.0 * volume),
    }
}

/// Advance to the end in chunks of `chunk` trials.
fn run(sim: &mut DsmcSim, chunk: u64) {
    while !sim.advance(chunk).unwrap() {}
}

/// The outputs of the longer runs: those of the shorter run, then more.
const TIMES: &[f64] = &[0.0, 0.5, 1.0, 3.0, 7.0, 7.5, 12.0, 20.0, 31.0];

/// For both methods, with and without displacements, constant and viscoelastic restitution:
/// run to t1, keep the final state, continue it (in other chunks) to t2 and then to t3; the
/// final state (velocities, displacements, every row, counters, random streams, candidates)
/// equals that of the run made straight to t3, and every intermediate one the run made
/// straight to its end. The ends include one a hair past t1 (the stopping collision is then
/// usually past it too: the continued run stops again at once).
#[test]
fn continued_runs_equal_direct_runs() {
    let ends = [(7.0, 7.0 * (1.0 + 1e-12), 31.0), (3.0, 12.0, 20.0)];
    for method in [Method::LowRank, Method::Bird] {
        for (msd, visco) in [(false, false), (true, false), (false, true)] {
            for (case, &(t1, t2, t3)) in ends.iter().enumerate() {
                let seed = 11 + case as u64;
                // Every end is an output of the longer runs.
                let mut times = TIMES.to_vec();
                times.extend([t1, t2]);
                times.sort_by(f64::total_cmp);
                times.dedup();
                let sys = |t_end: f64| system(method, msd, visco, t_end, &times);
                let direct = |t_end: f64| {
                    let mut s = DsmcSim::new(sys(t_end), seed);
                    run(&mut s, u64::MAX);
                    s
                };
                let mut d1 = direct(t1);
                let fin1 = d1.final_state().expect("a finished run has a final state");
                let mut c2 = DsmcSim::continue_from(sys(t2), &fin1).unwrap();
                run(&mut c2, 977);
                let mut d2 = direct(t2);
                let what = format!("{method:?} msd={msd} visco={visco} {t1} -> {t2}");
                assert!(c2.state_bytes() == d2.state_bytes(), "{what}");
                let fin2 = c2.final_state().unwrap();
                assert!(fin2 == d2.final_state().unwrap(), "{what}: final states");
                let mut c3 = DsmcSim::continue_from(sys(t3), &fin2).unwrap();
                run(&mut c3, 1 << 20);
                let mut d3 = direct(t3);
                assert!(d3.st.rows.len() > d1.st.rows.len());
                assert!(c3.state_bytes() == d3.state_bytes(), "{what} -> {t3}");
            }
        }
    }
}

/// A run restored from a checkpoint keeps a final state that continues like the run's own.
#[test]
fn restored_runs_keep_their_final_state() {
    for method in [Method::LowRank, Method::Bird] {
        let sys = system(method, false, false, 7.0, TIMES);
        let mut a = DsmcSim::new(sys.clone(), 5);
        assert!(!a.advance(2_000).unwrap());
        let mut b = DsmcSim::from_state_bytes(sys.clone(), &a.state_bytes()).unwrap();
        run(&mut a, u64::MAX);
        run(&mut b, 3_000);
        let fa = a.final_state();
        assert!(fa.is_some() && fa == b.final_state());
        // Restored after its end (a checkpoint taken then): its stop is unknown, so it keeps
        // no final state rather than a wrong one.
        let mut late = DsmcSim::from_state_bytes(sys, &a.state_bytes()).unwrap();
        assert!(late.is_done());
        assert!(late.final_state().is_none());
    }
}

/// What cannot be continued is refused with the reason: a grid that does not begin with the
/// old outputs, an end not past the old one, the time-averaged MSD, a foreign payload.
#[test]
fn continuation_refusals() {
    let mut d = DsmcSim::new(system(Method::LowRank, false, false, 7.0, TIMES), 3);
    run(&mut d, u64::MAX);
    let fin = d.final_state().unwrap();
    let other_grid = system(
        Method::LowRank,
        false,
        false,
        20.0,
        &[0.0, 0.5, 1.0, 3.5, 7.0],
    );
    let err = DsmcSim::continue_from(other_grid, &fin)
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("output 3"), "{err}");
    let no_old_end = system(
        Method::LowRank,
        false,
        false,
        20.0,
        &[0.0, 0.5, 1.0, 3.0, 12.0],
    );
    let err = DsmcSim::continue_from(no_old_end, &fin)
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("listing 7"), "{err}");
    let same = system(Method::LowRank, false, false, 7.0, TIMES);
    assert!(DsmcSim::continue_from(same, &fin).is_err());
    let mut tamsd = system(Method::LowRank, true, false, 20.0, TIMES);
    tamsd.tamsd = Some(system::TamsdPlan {
        grid: 10,
        tracers: tamsd.species.iter().map(|_| 1).collect(),
        lag_steps: vec![1],
        lags: vec![2.0],
    });
    assert!(DsmcSim::continue_from(tamsd, &fin)
        .err()
        .unwrap()
        .to_string()
        .contains("time-averaged"));
    let longer = || system(Method::LowRank, false, false, 20.0, TIMES);
    assert!(DsmcSim::continue_from(longer(), &fin[..fin.len() / 2]).is_err());
    // Another method's state, another gas.
    let bird = system(Method::Bird, false, false, 20.0, TIMES);
    assert!(DsmcSim::continue_from(bird, &fin).is_err());
    assert!(DsmcSim::continue_from(longer(), &fin).is_ok());
}

/// The velocity distribution draws no random numbers: for both methods the same seed with and
/// without it gives the same trajectory (velocities, counters, random streams) and the same
/// temperature and collision columns; with it, a2 is recorded at every output and the speed
/// histogram at its times only, its densities summing to the fraction below c_max.
#[test]
fn velocity_distribution_leaves_the_trajectory_alone() {
    for method in [Method::LowRank, Method::Bird] {
        let plain = system(method, false, false, 12.0, TIMES);
        let mut with = plain.clone();
        with.vdist = Some(system::VdistPlan {
            times: vec![3.0, 12.0],
            bins: 40,
            c_max: 4.0,
        });
        let mut a = DsmcSim::new(plain.clone(), 9);
        let mut b = DsmcSim::new(with.clone(), 9);
        run(&mut a, u64::MAX);
        run(&mut b, 1_000);
        // Restored from a checkpoint taken after the first histogram: the same rows (a2
        // included) and histograms; a plain run's payload is refused for it and vice versa.
        let mut c = DsmcSim::new(with.clone(), 9);
        while c.st.hist.is_empty() {
            c.advance(500).unwrap();
        }
        let mut c = DsmcSim::from_state_bytes(with.clone(), &c.state_bytes()).unwrap();
        run(&mut c, 700);
        assert_eq!((&c.st.rows, &c.st.hist), (&b.st.rows, &b.st.hist));
        assert!(DsmcSim::from_state_bytes(with.clone(), &a.state_bytes()).is_err());
        assert!(DsmcSim::from_state_bytes(plain, &b.state_bytes()).is_err());
        assert_eq!(a.st.vel, b.st.vel, "{method:?}");
        assert_eq!(
            (a.st.trials, a.st.collisions),
            (b.st.trials, b.st.collisions)
        );
        assert_eq!(a.rng.position(), b.rng.position());
        assert_eq!(a.st.rows.len(), b.st.rows.len());
        for (x, y) in a.st.rows.iter().zip(&b.st.rows) {
            assert_eq!(x.temperature.to_bits(), y.temperature.to_bits());
            assert_eq!((x.t, x.collisions), (y.t, y.collisions));
            assert!(x.a2.is_none());
            let a2 = y.a2.expect("a2 recorded");
            assert!(a2.is_finite() && a2 > -1.0, "{a2}");
        }
        let hist = b.take_hist();
        let species = b.sys.species.len();
        assert_eq!(hist.len(), 2 * species * 40);
        assert!(hist.iter().all(|h| h.t == 3.0 || h.t == 12.0));
        for k in 1..=species as u32 {
            let h: Vec<_> = hist
                .iter()
                .filter(|h| h.species == k && h.t == 12.0)
                .collect();
            let n: u64 = h.iter().map(|h| h.count).sum();
            let integral: f64 = h.iter().map(|h| h.density * (h.c_hi - h.c_lo)).sum();
            let count = b.sys.species[k as usize - 1].count;
            assert!(n <= count);
            assert!((integral - n as f64 / count as f64).abs() < 1e-12);
        }
        assert!(a.take_hist().is_empty());
    }
}
