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
        observe: Observed {
            msd,
            ..Default::default()
        },
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
/// usually past it too: the continued run stops again at once). For ChaCha8 words (stream
/// versions 1 and 2) and AES ones (3).
#[test]
fn continued_runs_equal_direct_runs() {
    let ends = [(7.0, 7.0 * (1.0 + 1e-12), 31.0), (3.0, 12.0, 20.0)];
    for (method, stream) in [
        (Method::LowRank, StreamVersion::V1),
        (Method::Bird, StreamVersion::V1),
        (Method::LowRank, StreamVersion::V3),
        (Method::Bird, StreamVersion::V3),
    ] {
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
                    let mut s = DsmcSim::with_stream(sys(t_end), seed, stream);
                    run(&mut s, u64::MAX);
                    s
                };
                let mut d1 = direct(t1);
                let fin1 = d1.final_state().expect("a finished run has a final state");
                let mut c2 = DsmcSim::continue_from(sys(t2), &fin1).unwrap();
                run(&mut c2, 977);
                let mut d2 = direct(t2);
                assert_eq!(c2.generator(), stream.dsmc_generator());
                let what = format!("{method:?} {stream:?} msd={msd} visco={visco} {t1} -> {t2}");
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

/// A run restored from a checkpoint keeps a final state that continues like the run's own
/// (ChaCha8 and AES words).
#[test]
fn restored_runs_keep_their_final_state() {
    for (method, stream) in [
        (Method::LowRank, StreamVersion::V1),
        (Method::Bird, StreamVersion::V1),
        (Method::LowRank, StreamVersion::V3),
        (Method::Bird, StreamVersion::V3),
    ] {
        let sys = system(method, false, false, 7.0, TIMES);
        let mut a = DsmcSim::with_stream(sys.clone(), 5, stream);
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
    tamsd.observe.tamsd = Some(system::TamsdPlan {
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
        with.observe.vdist = Some(system::VdistPlan {
            times: vec![3.0, 12.0],
            bins: 40,
            c_max: 4.0,
        });
        with.observe.values.insert(RowValue::A2);
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
            assert!(x.value(RowValue::A2).is_none());
            let a2 = y.value(RowValue::A2).expect("a2 recorded");
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

/// The per-row values other than a2 (here the test-only `Probe`, the mean x velocity) go
/// through the one generic mechanism: computed per species at every output without touching
/// the trajectory, saved in the generic section after the state (after the a2 section when
/// both are on) and restored bit for bit; a payload without the section is refused for a run
/// that records one and vice versa, and a payload with a section of other values too.
#[test]
fn generic_row_values_are_recorded_and_checkpointed() {
    for method in [Method::LowRank, Method::Bird] {
        let plain = system(method, false, false, 12.0, TIMES);
        let mut probe = plain.clone();
        probe.observe.values.insert(RowValue::Probe);
        let mut both = probe.clone();
        both.observe.vdist = Some(system::VdistPlan {
            times: vec![12.0],
            bins: 10,
            c_max: 4.0,
        });
        both.observe.values.insert(RowValue::A2);
        let mut a = DsmcSim::new(plain.clone(), 5);
        run(&mut a, u64::MAX);
        for sys in [&probe, &both] {
            let mut b = DsmcSim::new(sys.clone(), 5);
            run(&mut b, 1_000);
            assert_eq!(a.st.vel, b.st.vel, "{method:?}");
            assert_eq!(a.rng.position(), b.rng.position());
            assert_eq!(a.st.rows.len(), b.st.rows.len());
            for (x, y) in a.st.rows.iter().zip(&b.st.rows) {
                assert_eq!(x.temperature.to_bits(), y.temperature.to_bits());
                assert_eq!(x.value(RowValue::Probe), None);
                let p = y.value(RowValue::Probe).expect("probe recorded");
                assert!(p.is_finite());
                assert_eq!(y.value(RowValue::A2).is_some(), sys.observe.vdist.is_some());
            }
            // The last output is at the end, where the velocities still are.
            let m = b.sys.species.len();
            for (s, row) in b.st.rows[b.st.rows.len() - m..].iter().enumerate() {
                let range = b.off[s]..b.off[s + 1];
                let mean = b.st.vel[range].iter().map(|v| v[0]).sum::<f64>()
                    / b.sys.species[s].count as f64;
                assert_eq!(row.value(RowValue::Probe), Some(mean), "species {}", s + 1);
            }
            // Restored from a checkpoint taken midway: the same rows, values included.
            let mut c = DsmcSim::new(sys.clone(), 5);
            while c.st.rows.len() < 4 * m {
                c.advance(500).unwrap();
            }
            let mut c = DsmcSim::from_state_bytes(sys.clone(), &c.state_bytes()).unwrap();
            run(&mut c, 700);
            assert_eq!((&c.st.rows, &c.st.hist), (&b.st.rows, &b.st.hist));
            assert!(c.st.rows.iter().all(|r| r.value(RowValue::Probe).is_some()));
            // Mismatched payloads are refused.
            assert!(DsmcSim::from_state_bytes(sys.clone(), &a.state_bytes()).is_err());
            assert!(DsmcSim::from_state_bytes(plain.clone(), &b.state_bytes()).is_err());
        }
        let mut p = DsmcSim::new(probe.clone(), 5);
        let mut v = DsmcSim::new(both.clone(), 5);
        p.advance(3_000).unwrap();
        v.advance(3_000).unwrap();
        assert!(DsmcSim::from_state_bytes(both.clone(), &p.state_bytes()).is_err());
        assert!(DsmcSim::from_state_bytes(probe.clone(), &v.state_bytes()).is_err());
        // A section naming another value is refused.
        let mut bytes = postcard::to_stdvec(&p.st).unwrap();
        let other = row_values::RowValuesExtra {
            columns: vec![("other".into(), vec![None; p.st.rows.len()])],
        };
        bytes.extend(postcard::to_stdvec(&other).unwrap());
        let err = DsmcSim::from_state_bytes(probe.clone(), &bytes)
            .err()
            .unwrap();
        assert!(err.to_string().contains("per-row values"), "{err}");
    }
}

/// Without per-row values other than a2 the payload is the dsmc/5 state (and the
/// `VdistExtra` with `velocity_distribution`), nothing after it: the layout that builds
/// before the generic section wrote, so their checkpoints and final states still load.
#[test]
fn payload_without_generic_values_is_the_dsmc5_layout() {
    let plain = system(Method::LowRank, true, false, 12.0, TIMES);
    let mut vd = plain.clone();
    vd.observe.vdist = Some(system::VdistPlan {
        times: vec![3.0],
        bins: 8,
        c_max: 4.0,
    });
    vd.observe.values.insert(RowValue::A2);
    for sys in [plain, vd] {
        let mut sim = DsmcSim::new(sys.clone(), 3);
        sim.advance(20_000).unwrap();
        let bytes = sim.state_bytes();
        let mut want = postcard::to_stdvec(&sim.st).unwrap();
        if sys.observe.vdist.is_some() {
            let extra = VdistExtra {
                a2: sim.st.rows.iter().map(|r| r.value(RowValue::A2)).collect(),
                hist: sim.st.hist.clone(),
            };
            assert!(extra.a2.iter().all(|a| a.is_some()));
            want.extend(postcard::to_stdvec(&extra).unwrap());
        }
        assert_eq!(bytes, want);
    }
}

/// Stream version 3 draws a run's words from AES-128 in counter mode: its checkpoint ends with
/// the version (a ChaCha8 run's writes none, as before versions), restores to the same
/// generator and continues bit for bit; it is another realisation than the ChaCha8 run of the
/// same seed (same counts, other velocities); a payload naming a ChaCha8 version or an unknown
/// one is refused.
#[test]
fn stream_version_3_draws_from_aes() {
    for method in [Method::LowRank, Method::Bird] {
        let sys = system(method, false, false, 7.0, TIMES);
        let mut chacha = DsmcSim::with_stream(sys.clone(), 9, StreamVersion::V2);
        let mut aes = DsmcSim::with_stream(sys.clone(), 9, StreamVersion::V3);
        assert_eq!(chacha.generator(), Generator::ChaCha8);
        assert_eq!(aes.generator(), Generator::Aes128Ctr);
        assert!(
            chacha.st.vel != aes.st.vel,
            "{method:?}: the same initial velocities"
        );
        assert!(!aes.advance(3_000).unwrap());
        let bytes = aes.state_bytes();
        assert_eq!(
            bytes.last(),
            Some(&3),
            "{method:?}: version 3 is the last byte"
        );
        let chacha_bytes = chacha.state_bytes();
        let restored = DsmcSim::from_state_bytes(sys.clone(), &chacha_bytes).unwrap();
        assert_eq!(restored.generator(), Generator::ChaCha8);
        let mut b = DsmcSim::from_state_bytes(sys.clone(), &bytes).unwrap();
        assert_eq!(b.generator(), Generator::Aes128Ctr);
        run(&mut aes, u64::MAX);
        run(&mut b, 1_234);
        assert!(
            aes.state_bytes() == b.state_bytes(),
            "{method:?}: restored run differs"
        );
        for (v, why) in [(2u8, "write no version"), (99, "not known")] {
            let mut bad = chacha_bytes.clone();
            bad.push(v);
            let e = DsmcSim::from_state_bytes(sys.clone(), &bad)
                .err()
                .expect("refused");
            assert!(e.to_string().contains(why), "{method:?} version {v}: {e}");
        }
    }
}

/// The final state's two parts concatenated are the postcard encoding of its [`FinalState`]
/// (what `continue_from` decodes), for both methods and both generators.
#[test]
fn final_state_parts_are_its_encoding() {
    for method in [Method::LowRank, Method::Bird] {
        for stream in [StreamVersion::V1, StreamVersion::V3] {
            let sys = system(method, true, false, 3.0, TIMES);
            let mut s = DsmcSim::with_stream(sys, 4, stream);
            run(&mut s, u64::MAX);
            let [head, state] = s.final_state_parts().unwrap();
            let whole = FinalState {
                t_end: s.sys.t_end,
                output_times: s.sys.output_times.clone(),
                stop: s.stop,
                state: s.state_bytes(),
            };
            assert!(state.len() > 128, "a state of {} bytes", state.len());
            assert!(
                [head, state].concat() == postcard::to_stdvec(&whole).unwrap(),
                "{method:?} {stream:?}"
            );
        }
    }
}

/// `max_and_sum_speed2` gives the bits of the one-lane loop it replaced (`f64::max` from 0.0,
/// the sum from -0.0 in order), for every length 0..=9 (all remainders of its four lanes),
/// with zeros, ties, huge values, a NaN and an infinity among the speeds.
#[test]
fn max_and_sum_speed2_is_the_one_lane_loop() {
    fn one_lane(vel: &[[f64; 3]]) -> (f64, f64) {
        let (mut m, mut s): (f64, f64) = (0.0, -0.0);
        for v in vel {
            let v2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
            m = m.max(v2);
            s += v2;
        }
        (m, s)
    }
    let mut rng = crate::rng::RunRng::new(7);
    let special = [0.0, -0.0, 1e200, f64::NAN, f64::INFINITY, 3.0, 3.0];
    for n in 0..=9 {
        for trial in 0..200 {
            let vel: Vec<[f64; 3]> = (0..n)
                .map(|_| {
                    let mut v = [rng.normal(), rng.normal(), rng.normal()];
                    // One record in four is special in one component (from trial 100 on).
                    if trial >= 100 && rng.f64() < 0.25 {
                        v[(rng.f64() * 3.0) as usize] = special[(rng.f64() * 7.0) as usize];
                    }
                    v
                })
                .collect();
            let (a, b) = (max_and_sum_speed2(&vel), one_lane(&vel));
            assert_eq!(
                (a.0.to_bits(), a.1.to_bits()),
                (b.0.to_bits(), b.1.to_bits()),
                "{vel:?}"
            );
        }
    }
}

/// The low-rank loop compiled for x86-64-v3 (what `advance` runs where the CPU has it) and
/// compiled for the baseline (`advance_low_rank_with` called here, in a function compiled for
/// the baseline) give the same state bit for bit: ChaCha8 and AES words, with and without
/// displacements, constant and viscoelastic restitution, in chunks that end mid-batch. Where
/// the CPU lacks x86-64-v3 both sides run the baseline copy and the test checks only that
/// chunking does not matter.
#[test]
fn low_rank_loop_is_the_same_for_every_cpu() {
    for stream in [StreamVersion::V1, StreamVersion::V3] {
        for (msd, visco) in [(false, false), (true, false), (false, true)] {
            let sys = system(Method::LowRank, msd, visco, 20.0, TIMES);
            let mut a = DsmcSim::with_stream(sys.clone(), 3, stream);
            let mut b = DsmcSim::with_stream(sys, 3, stream);
            run(&mut a, 1_000);
            while !b.advance_low_rank_with(777).unwrap() {}
            assert!(a.st.collisions > 3_000, "{}", a.st.collisions);
            let what = format!("{stream:?} msd={msd} visco={visco}");
            assert!(a.state_bytes() == b.state_bytes(), "{what}");
        }
    }
}
