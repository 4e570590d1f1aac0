//! Tests of the RFM simulation; each states its tolerance.

use super::*;
use crate::rfm::freepath::FreePathConfig;

fn no_noise(dim: u32, eps_n: f64, eps_t: f64, dt: f64, l: f64) -> RfmConfig {
    RfmConfig {
        dim,
        n_particles: 2,
        box_length: Some(l),
        noise_strength: 0.0,
        restitution_normal: eps_n,
        restitution_tangential: eps_t,
        dt: Some(dt),
        ..RfmConfig::default()
    }
}

/// Two discs approaching with normal relative speed `gn` and tangential `gt` along the
/// direction at angle `angle`; contact starts at fraction `phase` of a step. Returns the
/// ratios (normal, tangential) of the relative velocity after / before.
fn two_disc(dim: u32, eps_n: f64, eps_t: f64, dt: f64, phase: f64, gn: f64, gt: f64) -> (f64, f64) {
    let cfg = no_noise(dim, eps_n, eps_t, dt, if dim == 1 { 1.0 } else { 0.1 });
    let d = cfg.diameter();
    let gap = d + gn * dt * (3.0 + phase);
    let (x, v, e, t) = if dim == 1 {
        (
            vec![0.2, 0.2 + gap],
            vec![0.5 * gn, -0.5 * gn],
            [1.0, 0.0],
            [0.0, 0.0],
        )
    } else {
        let a: f64 = 0.5;
        let e = [a.cos(), a.sin()];
        let t = [-a.sin(), a.cos()];
        let c = [0.05, 0.05];
        (
            vec![
                c[0] - 0.5 * gap * e[0],
                c[1] - 0.5 * gap * e[1],
                c[0] + 0.5 * gap * e[0],
                c[1] + 0.5 * gap * e[1],
            ],
            vec![
                0.5 * (gn * e[0] + gt * t[0]),
                0.5 * (gn * e[1] + gt * t[1]),
                -0.5 * (gn * e[0] + gt * t[0]),
                -0.5 * (gn * e[1] + gt * t[1]),
            ],
            e,
            t,
        )
    };
    let dimu = dim as usize;
    let mut sim = RfmSim::from_parts(cfg, 1, x, v).unwrap();
    let tc = sim.config().damped_contact_time();
    sim.advance((2.0 * tc / dt) as u64 + 10);
    let v = sim.velocities();
    let g: Vec<f64> = (0..dimu).map(|k| v[k] - v[dimu + k]).collect();
    let gn_after: f64 = (0..dimu).map(|k| g[k] * e[k]).sum();
    let gt_after: f64 = (0..dimu).map(|k| g[k] * t[k]).sum();
    (-gn_after / gn, if gt != 0.0 { gt_after / gt } else { 1.0 })
}

/// Effective normal restitution over 50 contact-start phases at dt = 1e-6, 1D and 2D: the
/// phase average within 0.5% of nominal and every phase within 2% (issue 4's targets; the
/// exact pair flow in fact gives round-off, checked at 1e-9).
#[test]
fn two_disc_restitution_every_phase() {
    for dim in [1, 2] {
        for eps in [0.1, 0.3, 0.6, 0.9] {
            let r: Vec<f64> = (0..50)
                .map(|p| two_disc(dim, eps, 1.0, 1e-6, (p as f64 + 0.5) / 50.0, 1.0, 0.0).0 / eps)
                .collect();
            let mean = r.iter().sum::<f64>() / 50.0;
            assert!(
                (mean - 1.0).abs() < 5e-3,
                "dim {dim} eps {eps}: mean {mean}"
            );
            for (p, x) in r.iter().enumerate() {
                assert!((x - 1.0).abs() < 2e-2, "dim {dim} eps {eps} phase {p}: {x}");
                assert!((x - 1.0).abs() < 1e-9, "dim {dim} eps {eps} phase {p}: {x}");
            }
        }
    }
}

/// The table of mod.rs docs: effective eps vs dt (mean and range over 50 phases). Asserts
/// the documented bound |eps_eff/eps - 1| < 1e-9 (round-off of the overlap, which is the
/// difference of positions ~0.05 m, over ~4-230 steps).
#[test]
fn restitution_table() {
    for dt in [1e-7, 1e-6, 2e-6, 5e-6] {
        for eps in [0.1, 0.3, 0.6, 0.9] {
            let r: Vec<f64> = (0..50)
                .map(|p| two_disc(2, eps, 1.0, dt, (p as f64 + 0.5) / 50.0, 1.0, 0.0).0)
                .collect();
            let mean = r.iter().sum::<f64>() / 50.0;
            let lo = r.iter().cloned().fold(f64::MAX, f64::min);
            let hi = r.iter().cloned().fold(f64::MIN, f64::max);
            eprintln!("dt {dt:e} eps {eps}: mean {mean:.12} range {lo:.12}-{hi:.12}");
            assert!((lo / eps - 1.0).abs() < 1e-9 && (hi / eps - 1.0).abs() < 1e-9);
        }
    }
}

/// Oblique 2D contact with eps_t < 1: the tangential relative velocity is multiplied by
/// eps_t^(omega_0/omega_d) (what we implement, spec 6.7) within 2e-3 relative, and the
/// normal one by eps_n within 1e-3. Small normal speed so the line of centres barely turns.
#[test]
fn oblique_tangential_restitution() {
    for (en, et) in [(0.6, 0.6), (0.1, 0.1), (0.9, 0.3)] {
        let c = RfmConfig {
            restitution_normal: en,
            restitution_tangential: et,
            ..RfmConfig::default()
        };
        let want_t = c.effective_tangential_restitution();
        for phase in [0.1, 0.5, 0.9] {
            let (rn, rt) = two_disc(2, en, et, 1e-6, phase, 0.01, 0.004);
            assert!((rn / en - 1.0).abs() < 1e-3, "{en} {et}: normal {rn}");
            assert!(
                (rt / want_t - 1.0).abs() < 2e-3,
                "{en} {et}: tangential {rt} vs {want_t}"
            );
        }
    }
    // Sliding friction alone (eps_t = 1, mu set) reduces, never reverses, g_t.
    let cfg = RfmConfig {
        friction: Some(0.2),
        ..no_noise(2, 0.6, 1.0, 1e-6, 0.1)
    };
    let d = cfg.diameter();
    let mut sim = RfmSim::from_parts(
        cfg,
        1,
        vec![0.05, 0.05, 0.05 + d + 1e-6, 0.05],
        vec![0.5, 0.05, -0.5, -0.05],
    )
    .unwrap();
    sim.advance(60);
    let v = sim.velocities();
    let gt_ratio = (v[1] - v[3]) / 0.1;
    // Expected: 1 - mu (1 + eps_n) g_n / g_t = 1 - 0.2 * 1.6 * 1 / 0.1 < 0 => stops sliding;
    // measured along the initial tangent, the line of centres turns by ~g_t t_c / d ~ 7e-4
    // rad, leaking ~7e-4 * eps_n g_n into it: allow 1e-2 of g_t.
    assert!(gt_ratio.abs() < 1e-2, "{gt_ratio}");
}

fn free_particles(dim: u32, n: usize) -> RfmSim {
    // Particles 1 m apart: no contacts.
    let side = (n as f64).sqrt().ceil() as usize;
    let (cfg, x) = if dim == 1 {
        (
            RfmConfig {
                n_particles: n,
                ..RfmConfig::thesis_1d(n, 0.6)
            },
            (0..n)
                .map(|i| i as f64 * (1.0 + 0.003))
                .collect::<Vec<f64>>(),
        )
    } else {
        (
            RfmConfig {
                n_particles: n,
                box_length: Some(side as f64),
                ..RfmConfig::default()
            },
            (0..n)
                .flat_map(|i| [(i % side) as f64 + 0.5, (i / side) as f64 + 0.5])
                .collect(),
        )
    };
    let cfg = RfmConfig {
        reduced_length: if dim == 1 { Some(n as f64) } else { None },
        ..cfg
    };
    let v = vec![0.0; n * dim as usize];
    RfmSim::from_parts(cfg, 9, x, v).unwrap()
}

/// Free particles, noise only: per-component velocity variance after t equals
/// (1 - 1/N) 2 D t / M^2 (the (1 - 1/N) from the symmetrisation) within 3 standard errors
/// (SE = var sqrt(2 / (N dim)) for the sample variance of N dim normal components).
#[test]
fn free_particle_velocity_variance() {
    for dim in [1u32, 2] {
        let n = 4000;
        let mut sim = free_particles(dim, n);
        let steps = 2000;
        sim.advance(steps);
        let c = sim.config();
        let t = steps as f64 * c.dt();
        let want = (1.0 - 1.0 / n as f64) * 2.0 * c.noise_strength * t / c.mass.powi(2);
        let v = sim.velocities();
        let m = v.len() as f64;
        let got = v.iter().map(|a| a * a).sum::<f64>() / m;
        let se = want * (2.0 / m).sqrt();
        assert!(
            (got - want).abs() < 3.0 * se,
            "dim {dim}: {got} vs {want} (se {se})"
        );
    }
}

/// Total momentum stays zero to round-off (|P| / (M N v_rms) < 1e-12) over 20000 steps of
/// noise and contacts, 1D and 2D; contacts did happen (temperature finite, list rebuilt).
#[test]
fn momentum_stays_zero() {
    let cfgs = [
        RfmConfig {
            n_particles: 400,
            box_length: None,
            packing_fraction: Some(0.4),
            ..RfmConfig::default()
        },
        RfmConfig {
            reduced_length: Some(0.05),
            ..RfmConfig::thesis_1d(200, 0.3)
        },
    ];
    for cfg in cfgs {
        let mut sim = RfmSim::new(cfg, 17).unwrap();
        sim.advance(20_000);
        let c = sim.config();
        let t = sim.temperature();
        assert!(t.is_finite() && t > 0.0);
        let p: f64 = sim.momentum().iter().map(|a| a * a).sum::<f64>().sqrt();
        let scale = c.mass * c.n_particles as f64 * t.sqrt();
        assert!(p / scale < 1e-12, "dim {}: {p} vs {scale}", c.dim);
        if c.dim == 1 {
            // Ring order preserved: positions increasing, within one period.
            let x = sim.positions();
            assert!(x.windows(2).all(|w| w[1] - w[0] > 0.5 * c.diameter()));
            assert!(x[0] + c.box_length() - x[x.len() - 1] > 0.5 * c.diameter());
        } else {
            assert!(sim.list_builds() > 1);
        }
    }
}

/// A run restored from its checkpoint bytes continues bit for bit (1D and 2D).
#[test]
fn checkpoint_restore_is_bit_identical() {
    let cfgs = [
        RfmConfig {
            n_particles: 300,
            box_length: None,
            packing_fraction: Some(0.45),
            restitution_tangential: 0.5,
            ..RfmConfig::default()
        },
        RfmConfig {
            reduced_length: Some(0.05),
            ..RfmConfig::thesis_1d(100, 0.3)
        },
    ];
    for cfg in cfgs {
        let mut a = RfmSim::new(cfg.clone(), 5).unwrap();
        a.advance(3000);
        let bytes = a.state_bytes();
        let mut b = RfmSim::from_state_bytes(cfg, &bytes).unwrap();
        a.advance(4000);
        b.advance(1234);
        b.advance(2766);
        assert_eq!(a.step(), b.step());
        let bits = |v: Vec<f64>| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(a.positions()), bits(b.positions()));
        assert_eq!(bits(a.velocities()), bits(b.velocities()));
        assert_eq!(a.state_bytes(), b.state_bytes());
    }
}

/// The neighbour list finds the same pair corrections as all pairs for a random dense,
/// overlapping configuration (per-particle sums agree to 1e-12 of their largest value).
#[test]
fn neighbour_list_matches_brute_force() {
    let cfg = RfmConfig {
        n_particles: 600,
        box_length: None,
        packing_fraction: Some(0.5),
        restitution_tangential: 0.4,
        ..RfmConfig::default()
    };
    let l = cfg.box_length();
    let mut rng = RunRng::new(4);
    let x: Vec<[f64; 2]> = (0..600).map(|_| [rng.f64() * l, rng.f64() * l]).collect();
    let v: Vec<[f64; 2]> = (0..600)
        .map(|_| [rng.f64() - 0.5, rng.f64() - 0.5])
        .collect();
    let mut core = Core::<2>::new(&cfg, x, v, RunRng::new(1), StreamVersion::V1);
    let list = core.corrections(false);
    let brute = core.corrections(true);
    let scale = brute
        .iter()
        .flat_map(|(dx, dv)| [dx[0].abs(), dx[1].abs(), dv[0].abs(), dv[1].abs()])
        .fold(0.0, f64::max);
    let touched = brute.iter().filter(|(_, dv)| dv[0] != 0.0).count();
    assert!(touched > 300, "{touched}");
    for (a, b) in list.iter().zip(&brute) {
        for k in 0..2 {
            assert!((a.1[k] - b.1[k]).abs() <= 1e-12 * scale);
            assert!((a.0[k] - b.0[k]).abs() <= 1e-12 * scale);
        }
    }
}

/// Every initial layout places non-overlapping discs (min distance >= d) with zero mean
/// velocity (to 1e-15 m/s).
#[test]
fn initial_layouts_do_not_overlap() {
    for layout in [
        InitialLayout::Uniform,
        InitialLayout::Square,
        InitialLayout::Hexagonal,
    ] {
        let cfg = RfmConfig {
            n_particles: 500,
            box_length: Some(0.1),
            initial_layout: layout,
            ..RfmConfig::default()
        };
        let sim = RfmSim::new(cfg.clone(), 2).unwrap();
        let x = sim.positions();
        let l = cfg.box_length();
        let mut min = f64::MAX;
        for i in 0..500 {
            for j in i + 1..500 {
                let dx = super::super::neighbours::min_image(x[2 * i] - x[2 * j], l);
                let dy = super::super::neighbours::min_image(x[2 * i + 1] - x[2 * j + 1], l);
                min = min.min((dx * dx + dy * dy).sqrt());
            }
        }
        assert!(min >= cfg.diameter(), "{layout:?}: {min}");
        assert!(sim
            .momentum()
            .iter()
            .all(|p| p.abs() < 1e-15 * cfg.mass * 500.0));
    }
}

/// The uniform layout's random sequential addition, one try at a time (the code before the
/// tries were batched and pre-tested on several threads), and the velocities drawn after it.
fn rsa_reference(cfg: &RfmConfig, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let mut rng = RunRng::new(seed);
    let (n, l, d) = (cfg.n_particles, cfg.box_length(), cfg.diameter());
    let sp = d * (1.0 + 1e-3);
    let nc = ((l / sp).floor() as usize)
        .min((2.0 * (n as f64).sqrt()) as usize)
        .max(1);
    let side = l / nc as f64;
    let mut cells: Vec<Vec<u32>> = vec![Vec::new(); nc * nc];
    let mut x: Vec<f64> = Vec::new();
    while x.len() < 2 * n {
        let p = [rng.f64() * l, rng.f64() * l];
        let cx = ((p[0] / side) as usize).min(nc - 1);
        let cy = ((p[1] / side) as usize).min(nc - 1);
        let mut ok = true;
        'search: for dy in -1isize..=1 {
            for dx in -1isize..=1 {
                let ix = (cx as isize + dx).rem_euclid(nc as isize) as usize;
                let iy = (cy as isize + dy).rem_euclid(nc as isize) as usize;
                for &q in &cells[iy * nc + ix] {
                    let q = q as usize;
                    let rx = super::super::neighbours::min_image(p[0] - x[2 * q], l);
                    let ry = super::super::neighbours::min_image(p[1] - x[2 * q + 1], l);
                    if rx * rx + ry * ry < sp * sp {
                        ok = false;
                        break 'search;
                    }
                }
            }
        }
        if ok {
            cells[cy * nc + cx].push((x.len() / 2) as u32);
            x.extend_from_slice(&p);
        }
    }
    let mut v: Vec<f64> = (0..2 * n).map(|_| 0.1 * (rng.f64() - 0.5)).collect();
    for k in 0..2 {
        let m = v.iter().skip(k).step_by(2).sum::<f64>() / n as f64;
        for a in v.iter_mut().skip(k).step_by(2) {
            *a -= m;
        }
    }
    (x, v)
}

/// The uniform layout drawn in batches of tries, pre-tested on 1, 2 and 3 threads, places the
/// points of one try at a time and leaves the stream where one try at a time leaves it (the
/// velocities drawn after the layout are the same bits), above the parallel threshold
/// (N = 5000 at phi = 0.53: many batches, the last one cut short) and below it (N = 1500).
#[test]
fn uniform_layout_is_one_try_at_a_time_on_any_threads() {
    for n in [5000, 1500] {
        let cfg = dense_2d(n);
        let (x, v) = rsa_reference(&cfg, 11);
        for k in [1, 2, 3] {
            let sim = pool(k)
                .install(|| RfmSim::with_stream(cfg.clone(), 11, StreamVersion::V2).unwrap());
            assert!(sim.positions() == x, "N {n}, {k} threads: positions differ");
            assert!(
                sim.velocities() == v,
                "N {n}, {k} threads: velocities differ"
            );
        }
    }
}

fn dense_2d(n: usize) -> RfmConfig {
    RfmConfig {
        n_particles: n,
        box_length: None,
        packing_fraction: Some(0.53),
        restitution_normal: 0.1,
        restitution_tangential: 0.1,
        ..RfmConfig::default()
    }
}

/// The free-path tracking of the tests that track (paths and post-collision velocities,
/// recorded from the first step).
fn tracked() -> FreePathConfig {
    FreePathConfig {
        paths: true,
        lo: 1e-9,
        hi: 1.0,
        bins_per_decade: 20,
        velocity: Some(([-5.0, 5.0], 200)),
        from_step: 0,
        sample_every: 50,
    }
}

fn pool(k: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(k)
        .build()
        .unwrap()
}

/// Stream versions 2 and 4: a run stepped in rayon pools of 1, 2 and 3 threads gives
/// bit-identical states, above the parallel threshold (2D N = 9000, with and without
/// free-path tracking, so that the pair pass and the corrections with the drift (applied per
/// particle block, each particle's in pair order) run in blocks; one thread applies them in
/// pair order; version 2 with free paths: stored by cell on 2 and 3 threads, in particle
/// order on one, so the tracker's map from storage to particles is checked) and below it
/// (N = 1500); its noise is not version 1's, and version 4's is not version 2's above the
/// threshold (and is below it). Version 4 stores the particles by cell on one thread too.
#[test]
fn v2_threads_give_identical_states() {
    for (n, steps, fp) in [(9000, 300, false), (9000, 200, true), (1500, 300, false)] {
        let mut v2 = None;
        for stream in [StreamVersion::V2, StreamVersion::V4] {
            let run = |k: usize| {
                pool(k).install(|| {
                    let mut s = RfmSim::with_stream(dense_2d(n), 7, stream).unwrap();
                    if fp {
                        s.track_free_paths(tracked());
                    }
                    s.advance(steps);
                    assert_eq!(s.stream_version(), stream);
                    let Inner::D2(c) = &s.inner else {
                        unreachable!()
                    };
                    let sorted =
                        n >= PARALLEL_MIN_PARTICLES && (stream == StreamVersion::V4 || k > 1);
                    assert_eq!(!c.ids.is_empty(), sorted, "N {n} {stream:?} {k} threads");
                    s
                })
            };
            let one = run(1);
            for k in [2, 3] {
                let other = run(k);
                assert!(
                    one.state_bytes() == other.state_bytes(),
                    "N {n} fp {fp} {stream:?}: {k} threads differ from 1"
                );
            }
            let mut v1 = RfmSim::new(dense_2d(n), 7).unwrap();
            v1.advance(steps);
            assert_ne!(
                v1.velocities(),
                one.velocities(),
                "N {n}: {stream:?} drew as V1"
            );
            match v2.take() {
                None => v2 = Some(one.velocities()),
                // Version 4 addresses the noise by slot from PARALLEL_MIN_PARTICLES on.
                Some(w) if n >= PARALLEL_MIN_PARTICLES => {
                    assert_ne!(w, one.velocities(), "N {n}: V4 drew as V2")
                }
                Some(w) => assert_eq!(w, one.velocities(), "N {n}: V4 did not draw as V2"),
            }
        }
    }
}

/// Stream version 4 (the noise follows the storage slots, particles stored by cell): a run
/// with free-path tracking is the run without it (the tracker maps slots to particles and
/// never changes the order), and one restored from its checkpoint mid-run continues bit for
/// bit, tracker included, stays version 4 and keeps its storage order, on 1 and 2 threads.
#[test]
fn v4_free_paths_and_checkpoints_keep_the_run() {
    let cfg = dense_2d(5000);
    let bits = |v: Vec<f64>| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    let mut states = Vec::new();
    for k in [1, 2] {
        pool(k).install(|| {
            let mut plain = RfmSim::with_stream(cfg.clone(), 9, StreamVersion::V4).unwrap();
            let mut a = RfmSim::with_stream(cfg.clone(), 9, StreamVersion::V4).unwrap();
            a.track_free_paths(tracked());
            a.advance(700);
            let bytes = a.state_bytes();
            let mut b = RfmSim::from_state_bytes(cfg.clone(), &bytes).unwrap();
            assert_eq!(b.stream_version(), StreamVersion::V4);
            let (Inner::D2(ca), Inner::D2(cb)) = (&a.inner, &b.inner) else {
                unreachable!()
            };
            assert!(
                !ca.ids.is_empty() && ca.ids == cb.ids,
                "storage order not restored"
            );
            plain.advance(1500);
            a.advance(800);
            b.advance(123);
            b.advance(677);
            assert_eq!(bits(a.positions()), bits(plain.positions()), "{k} threads");
            assert_eq!(
                bits(a.velocities()),
                bits(plain.velocities()),
                "{k} threads"
            );
            assert_eq!(a.state_bytes(), b.state_bytes(), "{k} threads");
            let (hist, _) = a.free_path_rows(1);
            assert!(hist.iter().any(|r| r.count > 0), "no free paths recorded");
            states.push(a.state_bytes());
        });
    }
    assert!(states[0] == states[1], "1 and 2 threads differ");
}

/// Stream version 1 stepped on several threads (pair pass and drift in blocks, the noise
/// drawn sequentially as before) gives the states of one thread.
#[test]
fn v1_threads_give_identical_states() {
    let run = |k: usize| {
        pool(k).install(|| {
            let mut s = RfmSim::new(dense_2d(6000), 3).unwrap();
            s.advance(200);
            s.state_bytes()
        })
    };
    assert!(run(1) == run(2));
}

/// A version-2 run restored from its checkpoint mid-run continues bit for bit and stays
/// version 2 (1D, 2D below and above the parallel threshold, the latter on 2 threads).
#[test]
fn v2_checkpoint_restore_is_bit_identical() {
    let cfgs = [
        RfmConfig {
            n_particles: 300,
            box_length: None,
            packing_fraction: Some(0.45),
            restitution_tangential: 0.5,
            ..RfmConfig::default()
        },
        RfmConfig {
            reduced_length: Some(0.05),
            ..RfmConfig::thesis_1d(100, 0.3)
        },
        dense_2d(5000),
    ];
    for cfg in cfgs {
        pool(2).install(|| {
            let mut a = RfmSim::with_stream(cfg.clone(), 5, StreamVersion::V2).unwrap();
            a.advance(700);
            let bytes = a.state_bytes();
            let mut b = RfmSim::from_state_bytes(cfg.clone(), &bytes).unwrap();
            assert_eq!(b.stream_version(), StreamVersion::V2);
            a.advance(800);
            b.advance(123);
            b.advance(677);
            let bits = |v: Vec<f64>| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(a.positions()), bits(b.positions()));
            assert_eq!(bits(a.velocities()), bits(b.velocities()));
            assert_eq!(a.state_bytes(), b.state_bytes());
            // Momentum stays zero with the version-2 kicks.
            let t = a.temperature();
            let p: f64 = a.momentum().iter().map(|x| x * x).sum::<f64>().sqrt();
            let scale = cfg.mass * cfg.n_particles as f64 * t.sqrt();
            assert!(t > 0.0 && p / scale < 1e-12, "{p} vs {scale}");
        });
    }
}

/// Checkpoint bytes written by granular c713da0 (before stream versions; 2D N = 3, L = 0.03,
/// seed 11, 5 steps) restore as a version-1 run that continues as the same run made fresh,
/// and version 1 still writes those bytes; a version number this granular does not know is
/// refused.
#[test]
fn old_checkpoints_restore_as_v1() {
    let cfg = RfmConfig {
        n_particles: 3,
        box_length: Some(0.03),
        ..RfmConfig::default()
    };
    let old: Vec<u8> = (0..OLD_STATE_HEX.len() / 2)
        .map(|i| u8::from_str_radix(&OLD_STATE_HEX[2 * i..2 * i + 2], 16).unwrap())
        .collect();
    let mut fresh = RfmSim::new(cfg.clone(), 11).unwrap();
    fresh.advance(5);
    assert_eq!(fresh.state_bytes(), old);
    let mut b = RfmSim::from_state_bytes(cfg.clone(), &old).unwrap();
    assert_eq!(b.stream_version(), StreamVersion::V1);
    fresh.advance(50);
    b.advance(50);
    assert_eq!(fresh.state_bytes(), b.state_bytes());
    let mut bad = old.clone();
    bad.push(9);
    let e = RfmSim::from_state_bytes(cfg, &bad)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("stream version 9"), "{e}");
}

/// `state_bytes` of granular c713da0, see [`old_checkpoints_restore_as_v1`].
const OLD_STATE_HEX: &str = "0205068739520ebbe9853fec0292ed7234663f9bbb7d48514a883f4032471a7f00913fa07a1b0d53c0793f303eb9f091b19a3f063e1a9b33736da1bf148651b9b09796bfdaea8036863aa93f9dc19a9ee17ca1bf7142970b4c348fbfa68443fbb9c8ac3f06d69ee0aad2e9853f0219b68d9f34663fc9acaf962f4a883f6280a0478b00913fa4cd9a3767c0793f4b6d5b2f80b19a3ff3ee1ef7d0013b3d0b540000";

/// FNV-1a 64 of a run's checkpoint bytes (positions, velocities, reference, stream, step).
fn fnv(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
    })
}

/// The runs of [`states_are_those_of_545c337`]: (label, config, stream, free paths, steps,
/// advance chunk).
fn golden_runs() -> Vec<(&'static str, RfmConfig, StreamVersion, bool, u64, u64)> {
    let one_d = RfmConfig {
        reduced_length: Some(0.05),
        ..RfmConfig::thesis_1d(3000, 0.3)
    };
    vec![
        (
            "2d v2 N5000",
            dense_2d(5000),
            StreamVersion::V2,
            false,
            240,
            80,
        ),
        (
            "2d v2 N5000 fp",
            dense_2d(5000),
            StreamVersion::V2,
            true,
            120,
            60,
        ),
        (
            "2d v1 N5000",
            dense_2d(5000),
            StreamVersion::V1,
            false,
            150,
            150,
        ),
        (
            "2d v2 N1500",
            dense_2d(1500),
            StreamVersion::V2,
            false,
            300,
            100,
        ),
        (
            "1d v2 N3000",
            one_d.clone(),
            StreamVersion::V2,
            false,
            300,
            150,
        ),
        (
            "1d v1 N3000",
            one_d.clone(),
            StreamVersion::V1,
            false,
            200,
            200,
        ),
        (
            "2d v4 N5000",
            dense_2d(5000),
            StreamVersion::V4,
            false,
            240,
            80,
        ),
        (
            "2d v4 N5000 fp",
            dense_2d(5000),
            StreamVersion::V4,
            true,
            120,
            60,
        ),
        (
            "2d v4 N1500",
            dense_2d(1500),
            StreamVersion::V4,
            false,
            300,
            100,
        ),
        ("1d v4 N3000", one_d, StreamVersion::V4, false, 300, 150),
    ]
}

/// Runs of stream versions 1 and 2 (1D, 2D below and above the parallel threshold, with
/// free-path tracking) end in the checkpoint bytes that granular 545c337 gave, on 1 and 2
/// threads, whether advanced in chunks or one step at a time: the stepping may change,
/// the bits may not (hashes recorded at 545c337; those of version 4 when it was made).
#[test]
fn states_are_those_of_545c337() {
    const WANT: [u64; 10] = [
        0x2fc1_3367_d4d9_0d0a,
        0x00d9_39ee_297d_96af,
        0xb539_3222_de78_0fb1,
        0x5baf_2dbb_0a14_2f60,
        0x7f6a_6b02_dc6b_f10c,
        0x461d_014b_417f_f150,
        0xc41d_6667_f416_b649,
        0x1417_b5bd_4551_bd6e,
        // Version 4's smaller 2D runs and its 1D runs draw as version 2's: the states of
        // "2d v2 N1500" and "1d v2 N3000" but for the stream version at the end.
        0x5baf_33bb_0a14_3992,
        0x7f6a_6902_dc6b_eda6,
    ];
    let mut got = Vec::new();
    for (label, cfg, stream, fp, steps, chunk) in golden_runs() {
        let mut hashes = Vec::new();
        for (k, chunk) in [(1, chunk), (2, chunk), (2, 1)] {
            let h = pool(k).install(|| {
                let mut s = RfmSim::with_stream(cfg.clone(), 13, stream).unwrap();
                if fp {
                    s.track_free_paths(tracked());
                }
                let mut done = 0;
                while done < steps {
                    let c = chunk.min(steps - done);
                    s.advance(c);
                    done += c;
                }
                fnv(&s.state_bytes())
            });
            hashes.push(h);
        }
        println!("{label}: {hashes:x?}");
        assert!(
            hashes.iter().all(|&h| h == hashes[0]),
            "{label}: {hashes:x?}"
        );
        got.push(hashes[0]);
    }
    assert_eq!(got, WANT, "{got:#x?}");
}

/// The AVX2 drift is the portable drift bit for bit: positions, velocities and the largest
/// displacement, for block lengths with every remainder (0..=9 particles past a multiple of
/// four), start maxima of 0, of a value above every displacement and NaN, and a NaN position.
#[test]
fn avx2_drift_is_the_portable_drift() {
    #[cfg(target_arch = "x86_64")]
    {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        let mut rng = crate::rng::RunRng::new(77);
        for n in (0..=9).chain([64, 2048, 2049, 2051]) {
            for (case, m0) in [0.0, 1e9, f64::NAN, 0.0].into_iter().enumerate() {
                let mut x: Vec<[f64; 2]> =
                    (0..n).map(|_| [rng.f64() * 3.0, rng.f64() * 3.0]).collect();
                let mut v: Vec<[f64; 2]> =
                    (0..n).map(|_| [rng.f64() - 0.5, rng.f64() - 0.5]).collect();
                let r: Vec<[f64; 2]> = x
                    .iter()
                    .map(|p| [p[0] + rng.f64() * 0.1, p[1] - rng.f64() * 0.1])
                    .collect();
                if case == 3 && n > 5 {
                    x[5][1] = f64::NAN;
                }
                let c = [rng.f64() * 1e-3, -rng.f64() * 1e-3];
                let h = 1e-3 * (1.0 + rng.f64());
                let (mut xa, mut va) = (x.clone(), v.clone());
                let a = super::drift_block(&mut xa, &mut va, &r, c, h, m0);
                let b = super::drift_portable(&mut x, &mut v, &r, c, h, m0);
                assert_eq!(
                    a.to_bits(),
                    b.to_bits(),
                    "n {n} case {case}: max {a} vs {b}"
                );
                for i in 0..n {
                    for k in 0..2 {
                        assert_eq!(xa[i][k].to_bits(), x[i][k].to_bits(), "n {n} x[{i}][{k}]");
                        assert_eq!(va[i][k].to_bits(), v[i][k].to_bits(), "n {n} v[{i}][{k}]");
                    }
                }
            }
        }
    }
}

/// The drift and the gathered kick in one pass (`drift_kick_block`, AVX2 where the CPU has
/// it) are the portable drift and the gathered kick one after the other, bit for bit:
/// positions, velocities and both maxima, for block lengths with every remainder past a
/// multiple of four, ids a permutation or repeated, a NaN position and a NaN normal (a NaN
/// velocity compares as NaN: its payload is the compiler's operand order, not the physics).
#[test]
fn drift_and_kick_in_one_pass_are_the_two_passes() {
    let kicks = crate::rfm::noise::Kicks::new(2.5e-7, 1.3, 1e-3);
    let k = kicks.counter_blocks();
    let mut rng = crate::rng::RunRng::new(78);
    let same = |a: f64, b: f64| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
    let mut cases = 0;
    for n in (0..=9).chain([64, 1024, 1027]) {
        for case in 0..4 {
            let slots = n + 3;
            let mut x: Vec<[f64; 2]> = (0..n).map(|_| [rng.f64() * 3.0, rng.f64() * 3.0]).collect();
            let mut v: Vec<[f64; 2]> = (0..n).map(|_| [rng.f64() - 0.5, rng.f64() - 0.5]).collect();
            let r: Vec<[f64; 2]> = x
                .iter()
                .map(|p| [p[0] + rng.f64() * 0.1, p[1] - rng.f64() * 0.1])
                .collect();
            let mut z: Vec<f64> = (0..2 * slots).map(|_| 3.0 * (rng.f64() - 0.5)).collect();
            let ids: Vec<u32> = if case % 2 == 0 {
                let mut p: Vec<u32> = (0..slots as u32).collect();
                for i in (1..p.len()).rev() {
                    p.swap(i, (rng.f64() * (i + 1) as f64) as usize);
                }
                p.truncate(n);
                p
            } else {
                (0..n).map(|_| (rng.f64() * slots as f64) as u32).collect()
            };
            if case == 2 && n > 5 {
                x[5][1] = f64::NAN;
            }
            if case == 3 && n > 2 {
                z[2 * ids[2] as usize] = f64::NAN;
            }
            let c = [rng.f64() * 1e-3, -rng.f64() * 1e-3];
            let h = 1e-3 * (1.0 + rng.f64());
            let (mut xa, mut va) = (x.clone(), v.clone());
            let (ma, ka) = super::drift_kick_block(&mut xa, &mut va, &r, c, h, &ids, &z, &k);
            let mb = super::drift_portable(&mut x, &mut v, &r, c, h, 0.0);
            let kb = k.kick_gathered(&mut v, &ids, &z);
            assert!(same(ma, mb), "n {n} case {case}: drift max {ma} vs {mb}");
            assert!(same(ka, kb), "n {n} case {case}: kick max {ka} vs {kb}");
            for i in 0..n {
                for q in 0..2 {
                    assert!(same(xa[i][q], x[i][q]), "n {n} case {case} x[{i}][{q}]");
                    assert!(same(va[i][q], v[i][q]), "n {n} case {case} v[{i}][{q}]");
                }
            }
            cases += 1;
        }
    }
    assert_eq!(cases, 52);
}

/// The kick of the AVX2 drift-and-kick pass, with no drift (c = 0, h = 0: v - 0 is v, bit for
/// bit), is the gathered kick bit for bit: random permutations and repeated ids, lengths
/// around the four-particle rounds, and velocities and normals with NaN, infinities, signed
/// zeros and subnormals (the maximum must skip NaN as `a2 > m` does, whichever lane sees it).
/// A NaN velocity must be NaN in both; its payload is the compiler's choice of operand order,
/// not the physics (a run with one fails).
#[test]
fn gathered_kick_avx2_is_the_portable_loop() {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(25);
        let special = [
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            0.0,
            -0.0,
            f64::MIN_POSITIVE / 3.0,
            1e300,
        ];
        let draw = |rng: &mut rand_chacha::ChaCha8Rng| -> f64 {
            if rng.random_bool(0.05) {
                special[rng.random_range(0..special.len())]
            } else {
                rng.random_range(-3.0..3.0)
            }
        };
        let same = |a: &[[f64; 2]], b: &[[f64; 2]]| {
            a.iter()
                .flatten()
                .zip(b.iter().flatten())
                .all(|(a, b)| a.to_bits() == b.to_bits() || a.is_nan() && b.is_nan())
        };
        let mut checked = 0;
        for n in [
            0usize, 1, 3, 4, 5, 7, 8, 15, 16, 17, 20, 21, 37, 1000, 1023, 1024,
        ] {
            for round in 0..20 {
                let slots = n + rng.random_range(0..4);
                let z: Vec<f64> = (0..2 * slots).map(|_| draw(&mut rng)).collect();
                let ids: Vec<u32> = if round % 2 == 0 {
                    let mut p: Vec<u32> = (0..slots as u32).collect();
                    for i in (1..p.len()).rev() {
                        p.swap(i, rng.random_range(0..=i));
                    }
                    p.truncate(n);
                    p
                } else {
                    (0..n)
                        .map(|_| rng.random_range(0..slots.max(1) as u32))
                        .collect()
                };
                let v0: Vec<[f64; 2]> = (0..n).map(|_| [draw(&mut rng), draw(&mut rng)]).collect();
                let strength = if round == 3 {
                    0.0
                } else {
                    rng.random_range(0.0..2.0)
                };
                let kicks = crate::rfm::noise::Kicks::new(strength, 1.0, 0.5);
                let k = kicks.counter_blocks();
                let mut want = v0.clone();
                let mw = k.kick_gathered(&mut want, &ids, &z);
                let mut got = v0.clone();
                let mut x = vec![[0.0f64; 2]; n];
                let r = x.clone();
                let (_, mg) =
                    super::drift_kick_block(&mut x, &mut got, &r, [0.0; 2], 0.0, &ids, &z, &k);
                assert_eq!(mg.to_bits(), mw.to_bits(), "n {n} round {round}: maximum");
                assert!(same(&got, &want), "n {n} round {round}: velocities");
                checked += 1;
            }
        }
        assert!(checked > 300, "{checked} cases");
    }
}

/// The drift-and-kick pass refuses an id past the normals (a panic, as the two passes' kick
/// index does); with AVX2 it checks each round's ids before the round's drift or kick writes
/// anything: the first round drifted and kicked, the second untouched.
#[test]
fn drift_and_kick_refuse_an_id_past_the_normals() {
    let kicks = crate::rfm::noise::Kicks::new(2.5e-7, 1.3, 1e-3);
    let k = kicks.counter_blocks();
    let ids = [0u32, 1, 2, 3, 4, 8, 5, 6];
    let z = vec![1.0; 16];
    let r = vec![[0.0f64; 2]; 8];
    let mut x = vec![[0.5f64; 2]; 8];
    let mut v = vec![[1.0f64; 2]; 8];
    let res = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        super::drift_kick_block(&mut x, &mut v, &r, [0.0; 2], 1e-3, &ids, &z, &k)
    }));
    assert!(res.is_err(), "an id past the normals must panic");
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        let msg = res.unwrap_err();
        let msg = (msg.downcast_ref::<&str>().map(|m| m.to_string()))
            .or_else(|| msg.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        assert!(msg.contains("past the normals"), "{msg:?}");
        assert!(x[..4].iter().all(|p| *p != [0.5, 0.5]), "{x:?}");
        assert!(v[..4].iter().all(|p| *p != [1.0, 1.0]), "{v:?}");
        assert!(x[4..].iter().all(|p| *p == [0.5, 0.5]), "{x:?}");
        assert!(v[4..].iter().all(|p| *p == [1.0, 1.0]), "{v:?}");
        // No drift and sigma = 1: the first round kicked by z = 1, the second untouched.
        let mut v = vec![[0.0f64; 2]; 8];
        let mut x = vec![[0.0f64; 2]; 8];
        let res = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| unsafe {
            super::drift_kick2_avx2(
                x.as_flattened_mut(),
                v.as_flattened_mut(),
                r.as_flattened(),
                [0.0; 2],
                0.0,
                &ids,
                &z,
                1.0,
            )
        }));
        assert!(res.is_err(), "an id past the normals must panic");
        assert!(v[..4].iter().all(|p| *p == [1.0, 1.0]), "{v:?}");
        assert!(v[4..].iter().all(|p| *p == [0.0, 0.0]), "{v:?}");
    }
}

/// A 2D version-2 run above the parallel threshold keeps its particles stored by cell
/// (`Core::sort_by_cell`, re-sorted at every list build) and is the same run bit for bit as
/// the run kept in particle order: checkpoint bytes, positions, velocities and temperature
/// after 4000 steps (several list builds) on 1 and 2 threads; on 2 threads the storage is a
/// permutation, not the particle order, ordered by cell at the last build (one thread keeps
/// the particle order). A run that moves between pools (sorted on 2 threads, then stepped
/// on 1, put back in particle order at its next build, then on 2 again) is the same run.
#[test]
fn stored_by_cell_is_the_run_in_particle_order() {
    let cfg = dense_2d(5000);
    let run = |keep_order: bool, threads: usize| {
        pool(threads).install(|| {
            let mut s = RfmSim::with_stream(cfg.clone(), 21, StreamVersion::V2).unwrap();
            let Inner::D2(c) = &mut s.inner else {
                unreachable!()
            };
            if keep_order {
                c.keep_order = true;
                c.unsort();
                assert!(c.ids.is_empty());
            }
            s.advance(1500);
            s.advance(2500);
            let Inner::D2(c) = &s.inner else {
                unreachable!()
            };
            assert!(c.builds > 3, "{} builds", c.builds);
            if keep_order || threads == 1 {
                // One thread keeps the particle order (`Core::by_cell`).
                assert!(c.ids.is_empty());
            } else {
                let mut seen = vec![false; c.x.len()];
                for (t, &p) in c.ids.iter().enumerate() {
                    assert!(!seen[p as usize] && c.at[p as usize] as usize == t);
                    seen[p as usize] = true;
                }
                assert!(c.ids.iter().enumerate().any(|(t, &p)| t != p as usize));
                let (nc, side) = cell_grid::<2>(c.x.len(), c.l, c.d + c.skin).unwrap();
                let cells: Vec<usize> = c.x_ref.iter().map(|p| cell_index(p, nc, side)).collect();
                assert!(cells.windows(2).all(|w| w[0] <= w[1]));
            }
            (
                s.state_bytes(),
                s.positions(),
                s.velocities(),
                s.temperature(),
            )
        })
    };
    let want = run(true, 1);
    let moved = {
        let mut s = pool(2).install(|| {
            let mut s = RfmSim::with_stream(cfg.clone(), 21, StreamVersion::V2).unwrap();
            s.advance(1300);
            s
        });
        let Inner::D2(c) = &s.inner else {
            unreachable!()
        };
        assert!(!c.ids.is_empty());
        let builds = c.builds;
        pool(1).install(|| s.advance(1400));
        let Inner::D2(c) = &s.inner else {
            unreachable!()
        };
        // A build on one thread put the particles back in particle order.
        assert!(
            c.builds > builds && c.ids.is_empty(),
            "{} builds",
            c.builds - builds
        );
        pool(2).install(|| s.advance(1300));
        s.state_bytes()
    };
    assert!(moved == want.0, "a run moved between pools differs");
    for threads in [1, 2] {
        let got = run(false, threads);
        assert!(
            got.0 == want.0,
            "checkpoint bytes differ ({threads} threads)"
        );
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&got.1), bits(&want.1));
        assert_eq!(bits(&got.2), bits(&want.2));
        assert_eq!(got.3.to_bits(), want.3.to_bits());
    }
}

/// The parallel pair pass's blocks cover the list once, in order, in a multiple of the
/// thread count of blocks of at most PAIR_BLOCK pairs whose lengths differ by at most one
/// (so that each thread of the pool gets as many pairs, to one block's rounding).
#[test]
fn pair_blocks_share_the_pairs_evenly() {
    for pairs in [0, 1, 5, 4095, 4096, 4097, 36_865, 38_000, 100_003] {
        for threads in [1, 2, 3, 4, 7] {
            let nb = pair_blocks(pairs, threads);
            assert_eq!(nb % threads, 0, "{pairs} pairs, {threads} threads: nb {nb}");
            let mut next = 0;
            let (mut lo, mut hi) = (usize::MAX, 0);
            for k in 0..nb {
                let r = pair_block(pairs, nb, k);
                assert_eq!(r.start, next, "{pairs} pairs, {threads} threads: block {k}");
                assert!(r.len() <= PAIR_BLOCK);
                lo = lo.min(r.len());
                hi = hi.max(r.len());
                next = r.end;
            }
            assert_eq!(
                next, pairs,
                "{pairs} pairs, {threads} threads: not all covered"
            );
            assert!(hi - lo <= 1, "{pairs} pairs, {threads} threads: {lo}..{hi}");
            // The least such multiple: one block set fewer would exceed PAIR_BLOCK.
            if nb > threads {
                assert!(pairs.div_ceil(nb - threads) > PAIR_BLOCK);
            }
        }
    }
}
