//! The auxiliary models (`bisection`, `cascade`, `spm`) through the whole engine: their
//! tables against the exact theory (tolerances from the expected statistical noise, fixed
//! seeds), the cascade's D_f for UCP n = 8 against T 6.2, the SPM's scaling and tail
//! coefficients, and kill + resume bit-identity of each model's tables.

use std::path::Path;
use std::time::Duration;

use serde_json::{json, Value};

use super::util::{
    granular, heavy, log_text, read_table, run_granular, wait_limited, write_json, Cell, Table,
};

fn f(c: &Cell) -> f64 {
    match c {
        Cell::F(bits) => f64::from_bits(*bits),
        Cell::Null => f64::NAN,
        other => panic!("expected a float, got {other}"),
    }
}

fn fcol(t: &Table, name: &str) -> Vec<f64> {
    t.column(name).into_iter().map(f).collect()
}

fn run(dir: &Path, name: &str, m: &Value) -> std::path::PathBuf {
    let path = dir.join(format!("{name}.json"));
    write_json(&path, m);
    let out = dir.join(name);
    let log = dir.join(format!("{name}.log"));
    let code = run_granular(
        &[
            "run",
            path.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--threads",
            "2",
            "--quiet",
        ],
        &log,
        Duration::from_secs(300),
    );
    assert_eq!(code, Some(0), "{}", log_text(&log));
    out
}

/// Uniform bisection at n = 9 (F 3.15): the histogram against the exact bin averages of
/// P_9(x) = (-ln x)^8/8! and the moments against (1+m)^{-9}. Noise: each table value is a
/// mean over R = 4000 independent realisations with its standard error from their spread
/// (the 512 lengths of one realisation are correlated, so this, not a Poisson error, is the
/// right scale); |mean - exact| < 5 sem per bin/moment has a false-alarm rate ~6e-7 each,
/// and the chi^2 over the well-filled bins is checked against its expectation (dof +- 5
/// sqrt(2 dof)). The concave split (A = 0.3): lengths normalised (sum of density x width =
/// 1), <x> = 2^{-n} exactly (the split is symmetric: <a> = 1/2), <x^m> against <a^m>^n.
#[test]
fn bisection_matches_exact_distribution_and_moments() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let out = run(
        dir.path(),
        "bis",
        &json!({
            "name": "bis-it", "model": "bisection", "seed": 9,
            "params": {"level": 9, "realisations": 4000, "split": "uniform",
                       "histogram": {"bins_per_decade": 5}},
            "sweep": {"split": ["uniform", {"concave": {"exponent": 0.3}}]}
        }),
    );
    let h = read_table(&out, "bisection_histogram");
    let (pt, cnt) = (h.column("point_id"), h.column("count"));
    let (lo, hi) = (fcol(&h, "x_lo"), fcol(&h, "x_hi"));
    let (d, sem, ex) = (
        fcol(&h, "density"),
        fcol(&h, "density_sem"),
        fcol(&h, "density_exact"),
    );
    let (mut chi2, mut dof) = (0.0, 0usize);
    let mut norm = [0.0f64; 2];
    let mut total = [0u64; 2];
    for i in 0..h.rows.len() {
        let p = pt[i].as_u64() as usize;
        norm[p] += d[i] * (hi[i] - lo[i]);
        total[p] += cnt[i].as_u64();
        if p != 0 {
            assert!(ex[i].is_nan(), "no exact P_n for the concave split");
            continue;
        }
        if cnt[i].as_u64() >= 100 {
            let z = (d[i] - ex[i]) / sem[i];
            assert!(
                z.abs() < 5.0,
                "bin [{}, {}): {} vs exact {} ({z:.1} sigma)",
                lo[i],
                hi[i],
                d[i],
                ex[i]
            );
            chi2 += z * z;
            dof += 1;
        }
    }
    eprintln!("bisection n=9: chi2 {chi2:.1} over {dof} bins");
    assert!(dof >= 20);
    assert!(
        (chi2 - dof as f64).abs() < 5.0 * (2.0 * dof as f64).sqrt(),
        "chi2 {chi2} dof {dof}"
    );
    for p in 0..2 {
        assert!(
            (norm[p] - 1.0).abs() < 1e-9,
            "point {p}: normalisation {}",
            norm[p]
        );
        assert_eq!(total[p], 4000 * 512);
    }
    let m = read_table(&out, "bisection_moments");
    let (pt, ord) = (m.column("point_id"), m.column("order"));
    let (mean, sem, exact, zeta) = (
        fcol(&m, "mean"),
        fcol(&m, "sem"),
        fcol(&m, "exact"),
        fcol(&m, "zeta_exact"),
    );
    for i in 0..m.rows.len() {
        let (p, o) = (pt[i].as_u64(), ord[i].as_u64() as i32);
        let rel = (mean[i] - exact[i]) / exact[i];
        eprintln!(
            "bisection point {p} m={o}: <x^m> = {:.6e} +- {:.1e}, exact {:.6e}, rel {rel:+.2e}",
            mean[i], sem[i], exact[i]
        );
        if p == 0 {
            assert!((exact[i] / (1.0 + o as f64).powi(-9) - 1.0).abs() < 1e-13);
            assert!((zeta[i] - (1.0 + o as f64).log2()).abs() < 1e-12);
        }
        if o == 1 {
            // sum of the lengths = 1 in every realisation: <x> = 2^-9 to rounding.
            assert!((mean[i] - 2f64.powi(-9)).abs() < 1e-15, "{}", mean[i]);
        } else {
            assert!(
                (mean[i] - exact[i]).abs() < 5.0 * sem[i],
                "point {p} m={o}: {} vs {} ({:.1} sigma)",
                mean[i],
                exact[i],
                (mean[i] - exact[i]) / sem[i]
            );
        }
    }
}

/// The cascade: UCP n = 8 with 200 realisations gives D_f within T 6.2's 1.602 +- 0.066
/// (fit over 2 pi/L <= k <= 2 pi 2^5/L); Meakin 1 (degenerate) lies well below and within
/// its 1.287 +- 0.084; UCP conserves the total weight exactly, Meakin 1 multiplies it by
/// 1.001 per level; the placement puts N discs without (periodic) overlap.
#[test]
fn cascade_fractal_dimension_weights_and_placement() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let out = run(
        dir.path(),
        "casc",
        &json!({
            "name": "casc-it", "model": "cascade", "seed": 3,
            "params": {"level": 8, "variant": "ucp", "realisations": 200},
            "sweep": {"variant": ["ucp", "meakin1"]}
        }),
    );
    let fit = read_table(&out, "cascade_fit");
    assert_eq!(fit.rows.len(), 2);
    let var = fit.column("variant");
    let (df, dfe, th, the, ws, wsem) = (
        fcol(&fit, "d_f"),
        fcol(&fit, "d_f_err"),
        fcol(&fit, "d_f_thesis"),
        fcol(&fit, "d_f_thesis_err"),
        fcol(&fit, "weight_sum_mean"),
        fcol(&fit, "weight_sum_sem"),
    );
    for i in 0..2 {
        eprintln!(
            "cascade {} n=8: D_f = {:.3} +- {:.3} (thesis {} +- {}), weight {:.6} +- {:.1e}",
            var[i].as_str(),
            df[i],
            dfe[i],
            th[i],
            the[i],
            ws[i],
            wsem[i]
        );
        assert!(
            (df[i] - th[i]).abs() < the[i],
            "{}: D_f {} vs {} +- {}",
            var[i].as_str(),
            df[i],
            th[i],
            the[i]
        );
        match var[i].as_str() {
            "ucp" => assert!((ws[i] - 1.0).abs() < 1e-12 && wsem[i] < 1e-12),
            "meakin1" => assert!((ws[i] - 1.001f64.powi(8)).abs() < 1e-9),
            other => panic!("unexpected variant {other}"),
        }
    }
    // S(k) rows: every shell 0 < p^2 + q^2 <= 128^2, shell-mean >= 0, k = 2 pi sqrt(n2)/L.
    let sk = read_table(&out, "cascade_structure_factor");
    let (n2, k, s) = (sk.column("n2"), fcol(&sk, "k"), fcol(&sk, "s_mean"));
    // One replica: the summary is the run's S(k) with its error.
    let sum = read_table(&out, "cascade_structure_factor_summary");
    assert_eq!(sum.rows.len(), sk.rows.len());
    let total: f64 = s.iter().sum();
    let total_sum: f64 = fcol(&sum, "s_mean").iter().sum();
    assert!((total - total_sum).abs() < 1e-12 * total);
    assert!(sum.column("n_replicas").iter().all(|c| c.as_u64() == 1));
    assert_eq!(sk.rows.len() % 2, 0);
    for i in 0..sk.rows.len() {
        let n = n2[i].as_u64();
        assert!(n >= 1 && n <= 128 * 128);
        assert!((k[i] - 2.0 * std::f64::consts::PI * (n as f64).sqrt()).abs() < 1e-9 * k[i]);
        assert!(s[i] > 0.0);
    }

    // Placement (F 6.3, scaled down): 600 discs of r = 1.5 mm in L = 0.1 m, field n = 6.
    let out = run(
        dir.path(),
        "place",
        &json!({
            "name": "place-it", "model": "cascade", "seed": 4,
            "params": {"level": 6, "box_length": 0.1, "variant": "ucp", "realisations": 2,
                       "placement": {"n_particles": 600, "radius": 1.5e-3}}
        }),
    );
    let p = read_table(&out, "cascade_placement");
    assert_eq!(p.rows.len(), 600);
    let (x, y) = (fcol(&p, "x"), fcol(&p, "y"));
    let l = 0.1;
    for i in 0..x.len() {
        assert!((0.0..l).contains(&x[i]) && (0.0..l).contains(&y[i]));
        for j in 0..i {
            let mut dx = (x[i] - x[j]).abs();
            let mut dy = (y[i] - y[j]).abs();
            dx = dx.min(l - dx);
            dy = dy.min(l - dy);
            assert!(
                dx * dx + dy * dy >= 9e-6 * (1.0 - 1e-12),
                "discs {i} and {j} overlap"
            );
        }
    }
    let sk = read_table(&out, "cascade_structure_factor");
    let src = sk.column("source");
    assert!(src.iter().any(|s| s.as_str() == "placement"));
    assert!(src.iter().any(|s| s.as_str() == "field"));
}

/// SPM at fixed l: Q(v, l) collapses under v -> v/v_l, v_l = (D l/M^2)^{1/3} (computed here
/// independently): two runs with different l, M and D have the same density x v_l at the same
/// v/v_l up to the statistical noise of the walks; the Gaussian tail coefficient of (5.12) is
/// near 0.98 (measured on 2.5 <= |v|/v_l <= 4.5); the predicted alpha for D_f = 1.63 is 0.972
/// (5.29) and K = 9.48 for C = 121 (5.27).
#[test]
fn spm_scaling_tail_and_prediction() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let out = run(
        dir.path(),
        "spm",
        &json!({
            "name": "spm-it", "model": "spm", "seed": 5,
            "params": {"walks": 40000, "free_path": {"fixed": {"length": 0.0036}},
                       "gaussian_fit": [2.5, 4.5], "mass": 3.53e-5, "noise_strength": 1e-8},
            "sweep": {"free_path": [{"fixed": {"length": 0.0036}}, {"fixed": {"length": 0.05}},
                                     {"fitted": {"c": 121, "fractal_dimension": 1.63}}],
                      "mass": [3.53e-5, 1e-4]}
        }),
    );
    let s = read_table(&out, "spm_summary");
    let (pt, mode) = (s.column("point_id"), s.column("mode"));
    let (vl, gc, gce, ap, kp, am) = (
        fcol(&s, "v_l"),
        fcol(&s, "gaussian_coefficient"),
        fcol(&s, "gaussian_coefficient_err"),
        fcol(&s, "alpha_predicted"),
        fcol(&s, "k_predicted"),
        fcol(&s, "alpha_measured"),
    );
    // points: (l, M) = (0.0036, 3.53e-5), (0.0036, 1e-4), (0.05, 3.53e-5), (0.05, 1e-4),
    // fitted x 2.
    let lm: [(f64, f64); 4] = [
        (0.0036, 3.53e-5),
        (0.0036, 1e-4),
        (0.05, 3.53e-5),
        (0.05, 1e-4),
    ];
    for i in 0..s.rows.len() {
        let p = pt[i].as_u64() as usize;
        if mode[i].as_str() == "fixed" {
            let (l, m) = lm[p];
            let expect = (1e-8 * l / (m * m)).cbrt();
            assert!(
                (vl[i] - expect).abs() < 1e-12 * expect,
                "v_l {} vs {expect}",
                vl[i]
            );
            eprintln!(
                "spm fixed l={l} M={m}: gaussian coefficient {:.3} +- {:.3} (thesis 0.98)",
                gc[i], gce[i]
            );
            assert!((gc[i] - 0.98).abs() < 0.1, "Gaussian coefficient {}", gc[i]);
        } else {
            eprintln!(
                "spm fitted: alpha predicted {:.4}, measured {:.3}; K predicted {:.3}",
                ap[i], am[i], kp[i]
            );
            assert!((ap[i] - 0.972).abs() < 1e-3);
            if p == 4 {
                assert!((kp[i] - 9.48).abs() < 0.02, "K {}", kp[i]);
            }
        }
    }
    // Collapse: the histograms of the four fixed-l points on a common grid of |v|/v_l
    // (0.25-wide bins up to 4), density x v_l. Noise: walks are the independent units; with
    // 40000 walks the relative error of a coarse bin holding a fraction f of the samples is
    // below ~2/sqrt(40000 f) (a walk contributes a correlated block of samples; the factor 2
    // covers that), so the points must agree within 5 such errors.
    let h = read_table(&out, "spm_velocity_histogram");
    let (hp, cnt) = (h.column("point_id"), h.column("count"));
    let (slo, shi, d) = (
        fcol(&h, "v_scaled_lo"),
        fcol(&h, "v_scaled_hi"),
        fcol(&h, "density"),
    );
    let vls: Vec<f64> = (0..4)
        .map(|p| (1e-8 * lm[p].0 / (lm[p].1 * lm[p].1)).cbrt())
        .collect();
    let mut grid = vec![[0.0f64; 16]; 4];
    let mut cgrid = vec![[0u64; 16]; 4];
    for i in 0..h.rows.len() {
        let p = hp[i].as_u64() as usize;
        if p >= 4 {
            continue;
        }
        let c = 0.5 * (slo[i] + shi[i]).abs();
        let b = (c / 0.25) as usize;
        if b < 16 {
            // density (per m/s) x bin width (m/s) = probability; per unit v/v_l below.
            grid[p][b] += d[i] * (shi[i] - slo[i]) * vls[p];
            cgrid[p][b] += cnt[i].as_u64();
        }
    }
    let total: u64 = cgrid[0].iter().sum();
    for b in 0..16 {
        let frac = cgrid[0][b] as f64 / total as f64;
        if frac < 1e-3 {
            continue;
        }
        let tol = 5.0 * 2.0 / (40000.0 * frac).sqrt();
        for p in 1..4 {
            let rel = grid[p][b] / grid[0][b] - 1.0;
            assert!(
                rel.abs() < tol,
                "bin {b} point {p}: relative difference {rel:.3} > {tol:.3}"
            );
        }
    }
}

/// Each model's campaign interrupted twice with SIGKILL (checkpoints every 0.05 s) and resumed
/// gives tables identical bit for bit to an uninterrupted run.
#[test]
fn aux_models_resume_identically() {
    let _g = heavy();
    let cases: [(&str, Value, &[(&str, &[&str])]); 3] = [
        (
            "bisection",
            json!({"name": "bis-r", "model": "bisection", "seed": 2, "replicas": 2,
                   "params": {"level": 16, "realisations": 800}}),
            &[
                ("bisection_histogram", &["run_id", "x_lo"]),
                ("bisection_moments", &["run_id", "order"]),
            ],
        ),
        (
            "cascade",
            json!({"name": "casc-r", "model": "cascade", "seed": 2, "replicas": 2,
                   "params": {"level": 8, "variant": "ucp", "realisations": 600, "box_length": 0.2,
                              "placement": {"n_particles": 1500, "radius": 1.5e-3}}}),
            &[
                ("cascade_structure_factor", &["run_id", "source", "n2"]),
                ("cascade_fit", &["run_id", "source"]),
                (
                    "cascade_structure_factor_summary",
                    &["point_id", "source", "n2"],
                ),
                ("cascade_placement", &["run_id", "particle"]),
            ],
        ),
        (
            "spm",
            json!({"name": "spm-r", "model": "spm", "seed": 2, "replicas": 2,
                   "params": {"walks": 60000, "free_path": {"fitted": {"c": 121, "fractal_dimension": 1.63}}}}),
            &[
                ("spm_velocity_histogram", &["run_id", "v_lo"]),
                ("spm_summary", &["run_id"]),
            ],
        ),
    ];
    for (name, m, tables) in cases {
        let dir = tempfile::tempdir().unwrap();
        let a = run(dir.path(), "a", &m);
        let mp = dir.path().join("m.json");
        write_json(&mp, &m);
        let b = dir.path().join("B");
        let log = dir.path().join("b.log");
        for delay in [250u64, 600] {
            let mut child = granular(
                &[
                    "run",
                    mp.to_str().unwrap(),
                    "--out",
                    b.to_str().unwrap(),
                    "--threads",
                    "2",
                    "--quiet",
                    "--checkpoint-every",
                    "0.05",
                    "--flush-every",
                    "0.1",
                ],
                &log,
            )
            .spawn()
            .unwrap();
            std::thread::sleep(Duration::from_millis(delay));
            let _ = child.kill();
            let _ = wait_limited(&mut child, Duration::from_secs(30), "killed aux run", &log);
        }
        let ckpts = std::fs::read_dir(b.join("checkpoints"))
            .map(|d| d.count())
            .unwrap_or(0);
        eprintln!("{name}: {ckpts} checkpoint files after the kills");
        let code = run_granular(
            &["resume", b.to_str().unwrap(), "--threads", "1", "--quiet"],
            &log,
            Duration::from_secs(300),
        );
        assert_eq!(code, Some(0), "{}", log_text(&log));
        let all: Vec<(&str, &[&str])> = tables
            .iter()
            .copied()
            .chain([("runs", &["run_id"][..])])
            .collect();
        for (table, keys) in all {
            let (ta, tb) = (read_table(&a, table), read_table(&b, table));
            assert_eq!(ta.columns, tb.columns, "{name} {table}");
            let (ra, rb) = (ta.sorted_by(keys).unwrap(), tb.sorted_by(keys).unwrap());
            assert_eq!(ra.len(), rb.len(), "{name} {table}: row counts");
            for (x, y) in ra.iter().zip(&rb) {
                for (j, (col, _)) in ta.columns.iter().enumerate() {
                    if col != "wall_seconds" {
                        assert_eq!(
                            x[j], y[j],
                            "{name} {table}.{col} differs after kill + resume"
                        );
                    }
                }
            }
        }
    }
}
