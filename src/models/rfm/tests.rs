//! Tests of RFM runs set up from manifest parameters: bitwise restore, the observables
//! against each other and against exact results, the validation of their settings.

mod run {
    use crate::models::rfm::params::*;
    use crate::models::rfm::Rfm;
    use crate::models::{Model, Simulation};
    use crate::rfm::observe::*;
    use crate::rfm::{RfmConfig, RfmSim};
    use crate::rng::StreamVersion;

    fn params(dim: u32) -> RfmParams {
        let mut v = serde_json::json!({
            "dim": dim,
            "n_particles": 300,
            "warmup": 0.01,
            "duration": 0.03,
            "sample_every": 500,
            "observables": ["velocity_moments", "velocity_histogram"],
            "velocity_histogram": {"range": [-2, 2], "bins": 200}
        });
        if dim == 2 {
            v["packing_fraction"] = serde_json::json!(0.3);
            v["restitution_tangential"] = serde_json::json!(0.6);
        } else {
            v["reduced_length"] = serde_json::json!(0.5);
        }
        serde_json::from_value(v).unwrap()
    }

    /// `params` with every structure observable of the dimension on, and the free paths and
    /// post-collision velocities.
    fn params_all(dim: u32) -> RfmParams {
        let mut p = params(dim);
        p.observables.push(RfmObservable::FreePaths);
        p.observables.push(RfmObservable::PostCollisionVelocity);
        if dim == 1 {
            p.observables.push(RfmObservable::NeighbourDistances);
            p.neighbour_distances = Some(crate::models::rfm::params::NeighbourSpec {
                h_max: 4,
                range: Some([1e-8, 0.5]),
                bins_per_decade: 10,
            });
        } else {
            p.observables.push(RfmObservable::StructureFactor);
            p.observables.push(RfmObservable::RadialDistribution);
            p.structure_factor = Some(crate::models::rfm::params::StructureFactorSpec {
                k_max: Some(25.0),
                every: 2,
            });
        }
        p
    }

    /// A restored run draws as exactly the stream version it was started on (its checkpoint
    /// records the version).
    #[test]
    fn restored_runs_draw_as_their_stream() {
        let p = params(2);
        let all = [
            StreamVersion::V1,
            StreamVersion::V2,
            StreamVersion::V3,
            StreamVersion::V4,
        ];
        for started in all {
            let mut run = Rfm::start(&p, 9, started).unwrap();
            run.advance(2_000).unwrap();
            let restored = Rfm::restore(&p, &Simulation::state_bytes(&mut run)).unwrap();
            for v in all {
                assert_eq!(
                    restored.draws_as(v),
                    v == started,
                    "started {started:?}, asked {v:?}"
                );
            }
        }
    }

    /// A run restored from a checkpoint taken at any point continues bit for bit: the same
    /// rows as the uninterrupted run (warm-up, mid-sampling, state after a sample).
    #[test]
    fn restore_is_bitwise() {
        for dim in [1, 2] {
            let p = params_all(dim);
            let mut errors = Vec::new();
            p.check("", &mut errors);
            assert!(errors.is_empty(), "{errors:?}");
            let mut a = RfmRun::new(&p.run_config(), 9).unwrap();
            while !a.advance(777).unwrap() {}
            let want = a.finish();
            for cut in [5_000u64, 10_000, 10_500, 17_321] {
                let mut b = RfmRun::new(&p.run_config(), 9).unwrap();
                b.advance(cut).unwrap();
                let bytes = b.state_bytes();
                let mut c = RfmRun::from_state_bytes(&p.run_config(), &bytes).unwrap();
                while !c.advance(1000).unwrap() {}
                assert_eq!(c.finish(), want, "dim {dim}, restored at step {cut}");
            }
            if dim == 1 {
                assert_eq!(want.neighbour_moments.len(), 4 * 9);
                assert!(want
                    .histograms
                    .iter()
                    .any(|h| h.kind == "neighbour_distance"));
            } else {
                assert!(!want.structure_factor.is_empty() && !want.radial.is_empty());
            }
            let n_paths = want.free_path_moments[0].n_paths;
            let n_v: u64 = want
                .histograms
                .iter()
                .filter(|h| h.kind == "post_collision_velocity")
                .map(|h| h.count)
                .sum();
            eprintln!("dim {dim}: {n_paths} free paths, {n_v} post-collision components");
            assert!(n_paths > 100 && n_v > 100 * dim as u64);
            // A checkpoint of other observables is refused.
            let b = RfmRun::new(&p.run_config(), 9).unwrap();
            assert!(RfmRun::from_state_bytes(&params(dim).run_config(), &b.state_bytes()).is_err());
        }
    }

    /// A finished run continued to a longer duration equals, bit for bit, the run made
    /// straight to it: every observable of each dimension, sample counts that are not
    /// multiples of the 10 blocks (60 -> 73 -> 137), the last extension in two steps; the
    /// final states of the continued and the direct run are equal too. A shorter duration or
    /// other observables are refused.
    #[test]
    fn continued_runs_equal_direct_runs() {
        for dim in [1, 2] {
            let with = |duration: f64| {
                let mut p = params_all(dim);
                p.duration = duration;
                p.run_config()
            };
            // 0.03 s = 60 samples of 500 steps at dt = 1e-6.
            let (d1, d2, d3) = (0.03, 0.0365, 0.0685);
            assert_eq!(with(d1).sim.duration_steps() / 500, 60);
            let direct = |d: f64| {
                let mut r = RfmRun::new(&with(d), 9).unwrap();
                while !r.advance(1 << 20).unwrap() {}
                r
            };
            let first = direct(d1);
            let fin = first
                .final_state()
                .expect("a finished run has a final state");
            let mut second = RfmRun::continue_from(&with(d2), &fin).unwrap();
            assert!(!second.is_done());
            while !second.advance(3_333).unwrap() {}
            let want2 = direct(d2);
            assert!(
                second.final_state() == want2.final_state(),
                "dim {dim}: final states"
            );
            let fin2 = second.final_state().unwrap();
            assert_eq!(second.finish(), want2.finish(), "dim {dim}: {d1} -> {d2}");
            let mut third = RfmRun::continue_from(&with(d3), &fin2).unwrap();
            while !third.advance(50_000).unwrap() {}
            let want3 = direct(d3);
            let (got, want) = (third.finish(), want3.finish());
            assert!(got.timeseries.len() == 137 && !got.moments.is_empty());
            assert_eq!(got, want, "dim {dim}: {d1} -> {d2} -> {d3}");
            // The blocks moved: the first run's moments are not a prefix of the longer ones.
            assert_ne!(direct(d1).finish().moments, want.moments);
            assert!(RfmRun::continue_from(&with(0.02), &fin).is_err(), "shorter");
            let mut other = params(dim);
            other.duration = d2;
            assert!(
                RfmRun::continue_from(&other.run_config(), &fin).is_err(),
                "observables"
            );
            // Not finished: no final state.
            let mut running = RfmRun::new(&with(d1), 9).unwrap();
            running.advance(5_000).unwrap();
            assert!(running.final_state().is_none());
        }
    }

    /// 1D engine (eps = 0.6, N = 300, L' = 0.5): the neighbour histograms hold N separations
    /// per h and snapshot, <R_h> = h L'/N (the gaps sum to L'; soft overlaps counted with
    /// |.| add a little), and the moments are non-degenerate (<R^2> >= <R>^2).
    #[test]
    fn neighbour_distances_in_the_engine() {
        let p = params_all(1);
        let mut r = RfmRun::new(&p.run_config(), 5).unwrap();
        while !r.advance(u64::MAX).unwrap() {}
        let samples = r.sampler.samples_total;
        let out = r.finish();
        for h in 1..=4u32 {
            let total: u64 = out
                .histograms
                .iter()
                .filter(|x| x.kind == "neighbour_distance" && x.h == h)
                .map(|x| x.count)
                .sum();
            assert_eq!(total, samples * 300);
            let m: Vec<&_> = out.neighbour_moments.iter().filter(|x| x.h == h).collect();
            let want = h as f64 * 0.5 / 300.0;
            let rel = m[0].value / want - 1.0;
            eprintln!(
                "1D: <R_{h}> / (h L'/N) - 1 = {rel:.2e}, sem {:.2e}",
                m[0].sem.unwrap()
            );
            // sum_i (x_{i+h} - x_i - h d) = h L' exactly on the ring, and |.| >= .: so
            // <R_h> >= h L'/N up to rounding (1e-12), and soft overlaps are rare and small.
            assert!((-1e-12..1e-4).contains(&rel), "h {h}: {rel}");
            assert!(m[1].value >= m[0].value * m[0].value);
        }
    }

    fn elastic_gas() -> RfmParams {
        serde_json::from_value(serde_json::json!({
            "dim": 2,
            "n_particles": 500,
            "packing_fraction": 0.05,
            "restitution_normal": 1.0,
            "warmup": 0.05,
            "duration": 0.1,
            "sample_every": 5000,
            "observables": ["structure_factor", "radial_distribution"],
            "radial_distribution": {"bins": 400}
        }))
        .unwrap()
    }

    /// The elastic dilute gas (eps_n = eps_t = 1, phi = 0.05, N = 500, 20 snapshots): S(k) -> 1
    /// at large k (k d in [10, 20]: mean within 0.01, every window of width 1 in k d within
    /// 0.05), and g(R) = 0 inside the core (R < 0.95 d), -> 1 at large R (R in [3 d, L/2]: mean
    /// within 0.02, every 20-bin window within 0.1), C(R) -> the ideal (N-1) pi R^2/L^2.
    #[test]
    fn elastic_gas_structure() {
        let p = elastic_gas();
        let cfg = p.config();
        let (d, l) = (cfg.diameter(), cfg.box_length());
        let mut r = RfmRun::new(&p.run_config(), 21).unwrap();
        let t0 = std::time::Instant::now();
        while !r.advance(u64::MAX).unwrap() {}
        let out = r.finish();
        eprintln!("elastic gas run: {:.2} s", t0.elapsed().as_secs_f64());
        let sk = &out.structure_factor;
        assert!(sk.last().unwrap().k * d <= 20.0 && sk.last().unwrap().k * d > 19.9);
        let window = |lo: f64, hi: f64| {
            let (s, w) = sk
                .iter()
                .filter(|x| x.k * d >= lo && x.k * d < hi)
                .fold((0.0, 0.0), |a, x| {
                    (a.0 + x.s * x.n_vectors as f64, a.1 + x.n_vectors as f64)
                });
            s / w
        };
        let large = window(10.0, 20.0);
        eprintln!(
            "elastic gas: S(k d in [10, 20]) = {large:.4}, S(first shell) = {:.3}",
            sk[0].s
        );
        assert!((large - 1.0).abs() < 0.01, "{large}");
        for j in 5..20 {
            let s = window(j as f64, j as f64 + 1.0);
            assert!((s - 1.0).abs() < 0.05, "k d in [{j}, {}]: {s}", j + 1);
        }
        let g = &out.radial;
        assert!(g.iter().filter(|x| x.r_hi < 0.95 * d).all(|x| x.count == 0));
        let far: Vec<_> = g.iter().filter(|x| x.r_lo >= 3.0 * d).collect();
        let mean = far.iter().map(|x| x.g).sum::<f64>() / far.len() as f64;
        eprintln!(
            "elastic gas: g(R >= 3d) = {mean:.4}, contact g = {:.3}",
            g.iter().find(|x| x.r_lo >= d).unwrap().g
        );
        assert!((mean - 1.0).abs() < 0.02, "{mean}");
        for w in far.chunks(20) {
            let m = w.iter().map(|x| x.g).sum::<f64>() / w.len() as f64;
            assert!((m - 1.0).abs() < 0.1, "g near R = {}: {m}", w[0].r_lo);
        }
        let last = g.last().unwrap();
        let ideal = 499.0 * std::f64::consts::PI * last.r_hi.powi(2) / (l * l);
        assert!(
            (last.c / ideal - 1.0).abs() < 0.01,
            "C(L/2) = {} vs {ideal}",
            last.c
        );
    }

    /// Dilute elastic gas (2D, eps_n = eps_t = 1, phi = 0.01, N = 1000, L = 0.84 m): the mean
    /// free path against kinetic theory l_kin = 1/(2 sqrt(2) n d) = pi d/(8 sqrt(2) phi)
    /// (Maxwellian, relative-speed factor sqrt 2), with the Enskog contact value of the pair
    /// correlation chi = (1 - 7 phi/16)/(1 - phi)^2 = 1.016 as the finite-density correction:
    /// expect <l> = l_kin/chi. Started from the random layout with Maxwellian velocities
    /// (2 m/s per component) and weak noise (D = 1e-10: the velocity diffuses by < 0.2% over a
    /// free time, so flights are straight), 0.2 s (~6 mean free times) to relax and to open
    /// every particle's path history (with a shorter warm-up the first blocks under-count
    /// long paths: 0.05 s gave block means rising from 0.057 to 0.08 m), paths arriving in the
    /// next 0.3 s (~9 mean free times, ~9000 paths). Tolerance 3 sem (10 blocks) + 1% (Enskog is itself
    /// approximate at this order; soft contacts).
    #[test]
    fn dilute_gas_mean_free_path() {
        let cfg = RfmConfig {
            n_particles: 1000,
            box_length: None,
            packing_fraction: Some(0.01),
            noise_strength: 1e-10,
            restitution_normal: 1.0,
            restitution_tangential: 1.0,
            warmup: 0.2,
            duration: 0.3,
            ..RfmConfig::default()
        };
        let x = RfmSim::new(cfg.clone(), 13).unwrap().positions();
        let mut rng = crate::rng::RunRng::new(14);
        let mut v: Vec<f64> = (0..2000).map(|_| 2.0 * rng.normal()).collect();
        for k in 0..2 {
            let m = v.iter().skip(k).step_by(2).sum::<f64>() / 1000.0;
            for a in v.iter_mut().skip(k).step_by(2) {
                *a -= m;
            }
        }
        let mut sim = RfmSim::from_parts(cfg.clone(), 15, x, v).unwrap();
        let (warm, window) = (cfg.warmup_steps(), cfg.duration_steps());
        sim.track_free_paths(crate::rfm::freepath::FreePathConfig {
            paths: true,
            lo: 1e-6,
            hi: 10.0,
            bins_per_decade: 20,
            velocity: Some(([-10.0, 10.0], 200)),
            from_step: warm,
            sample_every: cfg.sample_every,
        });
        let d = cfg.diameter();
        let phi = 0.01;
        let l_kin = std::f64::consts::PI * d / (8.0 * 2f64.sqrt() * phi);
        let chi = (1.0 - 7.0 * phi / 16.0) / (1.0 - phi).powi(2);
        let t0 = std::time::Instant::now();
        sim.advance(warm + window);
        let samples = window / cfg.sample_every;
        let (hist, m) = sim.free_path_rows(samples);
        let acc = sim.free_path_acc().unwrap();
        let (sums, _) = crate::rfm::blocks::group(&acc.interval_sums, samples);
        let counts: Vec<u64> = (0..crate::rfm::blocks::BLOCKS)
            .map(|b| {
                acc.interval_counts
                    .iter()
                    .enumerate()
                    .filter(|(k, _)| crate::rfm::blocks::block_of(*k as u64, samples) == b)
                    .map(|(_, c)| c)
                    .sum()
            })
            .collect();
        eprintln!(
            "dilute gas: block means {:?}",
            sums.iter()
                .zip(&counts)
                .map(|(s, &c)| format!("{:.4} ({c})", s[0] / c as f64))
                .collect::<Vec<_>>()
        );
        let (mean, sem) = (m[0].value, m[0].sem.unwrap());
        let want = l_kin / chi;
        eprintln!(
            "dilute gas ({:.1} s, T = {:.3} m^2/s^2): <l> = {mean:.5} +- {sem:.5} m over {} paths; \
             l_kin = {l_kin:.5}, l_kin/chi = {want:.5}, ratio {:.4}; <l^2>/(2<l>^2) = {:.4}",
            t0.elapsed().as_secs_f64(),
            sim.temperature(),
            m[0].n_paths,
            mean / want,
            m[1].value / (2.0 * mean * mean)
        );
        assert!(m[0].n_paths > 5000);
        assert!(
            (mean - want).abs() < 3.0 * sem + 0.01 * want,
            "<l> = {mean} +- {sem}, want {want}"
        );
        // Post-collision velocities: two components per path start in the window, zero mean.
        let pcv: Vec<&HistRow> = hist
            .iter()
            .filter(|h| h.kind == "post_collision_velocity" && h.density.is_some())
            .collect();
        let n: u64 = pcv.iter().map(|h| h.count).sum();
        let mean_v = pcv
            .iter()
            .map(|h| 0.5 * (h.lo + h.hi) * h.count as f64)
            .sum::<f64>()
            / n as f64;
        eprintln!("dilute gas: {n} post-collision components, mean {mean_v:.4} m/s");
        assert!(n > 10000 && mean_v.abs() < 0.1);
    }

    /// The tables agree with each other exactly: the time average of T (2.19), which sums the
    /// components, equals D <v_c^2> from the moments (the same snapshots); the histogram holds
    /// every component of every snapshot and its densities integrate to the in-range fraction.
    #[test]
    fn observables_are_consistent() {
        for dim in [1u32, 2] {
            let p = params(dim);
            let mut r = RfmRun::new(&p.run_config(), 3).unwrap();
            while !r.advance(u64::MAX).unwrap() {}
            let samples = r.sampler.samples_total;
            let out = r.finish();
            assert_eq!(out.timeseries.len() as u64, samples);
            let t_mean = out.timeseries.iter().map(|x| x.temperature).sum::<f64>() / samples as f64;
            let m2 = out.moments[1].value;
            assert!(
                (t_mean - dim as f64 * m2).abs() < 1e-12 * t_mean,
                "dim {dim}: {t_mean} vs {}",
                dim as f64 * m2
            );
            let total: u64 = out.histograms.iter().map(|h| h.count).sum();
            assert_eq!(total, samples * 300 * dim as u64);
            let inside: f64 = out
                .histograms
                .iter()
                .filter_map(|h| h.density.map(|d| d * (h.hi - h.lo)))
                .sum();
            let outside: u64 = out
                .histograms
                .iter()
                .filter(|h| h.density.is_none())
                .map(|h| h.count)
                .sum();
            assert!((inside - (total - outside) as f64 / total as f64).abs() < 1e-12);
            // Moments grow like a (non-degenerate) distribution: <|v|^2> >= <|v|>^2.
            assert!(out.moments[1].value >= out.moments[0].value.powi(2));
        }
    }
}

mod snapshots {
    use crate::models::rfm::params::*;
    use crate::rfm::observe::*;

    fn params(dim: u32, times: &[f64]) -> RfmParams {
        let mut v = serde_json::json!({
            "dim": dim,
            "n_particles": 200,
            "warmup": 0.01,
            "duration": 0.02,
            "sample_every": 500,
            "observables": ["snapshot"],
            "snapshot": {"times": times}
        });
        if dim == 2 {
            v["packing_fraction"] = serde_json::json!(0.3);
        } else {
            v["reduced_length"] = serde_json::json!(0.5);
        }
        serde_json::from_value(v).unwrap()
    }

    /// Each requested time gives one snapshot of every particle at the first sample at or
    /// after it; the snapshot's velocities give exactly the temperature (2.19) recorded at that
    /// sample; the block means (2.20) average back to the mean of the series.
    #[test]
    fn snapshots_and_block_means() {
        for dim in [1u32, 2] {
            let p = params(dim, &[0.0153, 0.01, 0.03]);
            let mut r = RfmRun::new(&p.run_config(), 5).unwrap();
            while !r.advance(u64::MAX).unwrap() {}
            let out = r.finish();
            let ts: Vec<f64> = {
                let mut t: Vec<f64> = out.snapshots.iter().map(|s| s.t).collect();
                t.dedup();
                t
            };
            assert_eq!(ts.len(), 3, "dim {dim}: {ts:?}");
            assert_eq!(out.snapshots.len(), 3 * 200);
            // 0.01 is before the first sample (0.0105): snapped to it; 0.0153 -> 0.0155.
            assert!(
                (ts[0] - 0.0105).abs() < 1e-12
                    && (ts[1] - 0.0155).abs() < 1e-12
                    && (ts[2] - 0.03).abs() < 1e-12,
                "{ts:?}"
            );
            for &t in &ts {
                let rows: Vec<&SnapshotRow> = out.snapshots.iter().filter(|s| s.t == t).collect();
                let n = rows.len() as f64;
                let (mx, my) = (
                    rows.iter().map(|s| s.vx).sum::<f64>() / n,
                    rows.iter().map(|s| s.vy.unwrap_or(0.0)).sum::<f64>() / n,
                );
                let temp = rows
                    .iter()
                    .map(|s| (s.vx - mx).powi(2) + (s.vy.unwrap_or(0.0) - my).powi(2))
                    .sum::<f64>()
                    / n;
                let want = out
                    .timeseries
                    .iter()
                    .find(|r| r.t == t)
                    .unwrap()
                    .temperature;
                assert!(
                    (temp - want).abs() <= 1e-12 * want,
                    "dim {dim} t {t}: {temp} vs {want}"
                );
            }
            let total: u32 = out.temperature_blocks.iter().map(|b| b.n_samples).sum();
            assert_eq!(total as usize, out.timeseries.len());
            assert_eq!(out.temperature_blocks.len(), BLOCKS);
            let weighted = out
                .temperature_blocks
                .iter()
                .map(|b| b.temperature * b.n_samples as f64)
                .sum::<f64>()
                / total as f64;
            let mean = out.timeseries.iter().map(|r| r.temperature).sum::<f64>() / total as f64;
            assert!((weighted - mean).abs() < 1e-12 * mean);
        }
    }

    /// Free-path settings: without their observables, bad ranges (JSON paths); both
    /// observables are valid in 1D and 2D, and the defaults follow l_0 (spec 1.8).
    #[test]
    fn free_path_settings_are_validated() {
        for dim in [1u32, 2] {
            let mut p = params(dim, &[0.015]);
            p.free_paths = Some(crate::models::rfm::params::FreePathSpec {
                range: Some([1e-3, 1e-4]),
                bins_per_decade: 10,
            });
            p.post_collision_velocity = Some(HistogramSpec {
                range: [1.0, -1.0],
                bins: 10,
            });
            let mut errors = Vec::new();
            p.check("/params", &mut errors);
            let paths: Vec<&str> = errors.iter().map(|e| e.0.as_str()).collect();
            assert!(
                paths.contains(&"/params/free_paths")
                    && paths.contains(&"/params/post_collision_velocity")
                    && paths.contains(&"/params/post_collision_velocity/range"),
                "{errors:?}"
            );
            p.observables.push(RfmObservable::FreePaths);
            p.observables.push(RfmObservable::PostCollisionVelocity);
            let mut errors = Vec::new();
            p.check("/params", &mut errors);
            let paths: Vec<&str> = errors.iter().map(|e| e.0.as_str()).collect();
            assert_eq!(
                paths,
                [
                    "/params/post_collision_velocity/range",
                    "/params/free_paths/range"
                ],
                "{errors:?}"
            );
            p.free_paths = None;
            p.post_collision_velocity = None;
            let mut errors = Vec::new();
            p.check("/params", &mut errors);
            assert!(errors.is_empty(), "dim {dim}: {errors:?}");
            let fc = p.free_path_config().unwrap();
            let l0 = p.mean_free_path();
            assert!(
                (fc.lo / (1e-6 * l0) - 1.0).abs() < 1e-12
                    && (fc.hi / (100.0 * l0) - 1.0).abs() < 1e-12
            );
            assert_eq!(fc.velocity, Some(([-5.0, 5.0], 2000)));
            assert_eq!(fc.from_step, 10_000);
        }
    }

    #[test]
    fn snapshot_times_outside_the_sampled_window_are_errors() {
        let p = params(2, &[0.005, 0.04]);
        let mut errors = Vec::new();
        p.check("/params", &mut errors);
        let paths: Vec<&str> = errors.iter().map(|e| e.0.as_str()).collect();
        assert!(
            paths.contains(&"/params/snapshot/times/0")
                && paths.contains(&"/params/snapshot/times/1"),
            "{errors:?}"
        );
    }
}
