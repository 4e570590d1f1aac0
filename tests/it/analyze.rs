//! `granular analyze`: tiny 1D and 2D RFM campaigns -> analysis_fits with the expected
//! columns and sane values (zeta_1 = 1 exactly by (3.19)), figures, a partly finished
//! campaign (warning, exit 0), a cascade campaign's D_f, a non-thesis system whose fits are
//! flagged (the `quality` column, a warning, the summary's mark, the report's), and the error
//! cases (no campaign, a model without analysis, a missing table).

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

use arrow_array::cast::AsArray;
use arrow_array::types::{Float64Type, UInt32Type};
use arrow_array::Array;
use serde_json::json;

use super::util::{heavy, log_text, repo_root, run_capture, run_granular, write_json};

/// (quantity, key) -> (value, error, chi2_reduced, n_points, window, reference, quality).
type Fits = BTreeMap<
    (String, String),
    (
        f64,
        Option<f64>,
        Option<f64>,
        u32,
        String,
        Option<f64>,
        String,
    ),
>;

fn read_fits(path: &Path) -> Fits {
    let batches = granular::store::parquet_io::read_file(path, "analysis_fits").unwrap();
    let mut out = Fits::new();
    for b in batches {
        let names: Vec<String> = b
            .schema()
            .fields()
            .iter()
            .map(|f| f.name().clone())
            .collect();
        assert_eq!(
            names,
            [
                "campaign",
                "quantity",
                "key",
                "value",
                "error",
                "chi2_reduced",
                "n_points",
                "window",
                "reference",
                "quality"
            ]
        );
        let s = |n: &str| b.column_by_name(n).unwrap().as_string::<i32>().clone();
        let f = |n: &str| {
            b.column_by_name(n)
                .unwrap()
                .as_primitive::<Float64Type>()
                .clone()
        };
        let (q, k, w, qu) = (s("quantity"), s("key"), s("window"), s("quality"));
        let (v, e, c, r) = (f("value"), f("error"), f("chi2_reduced"), f("reference"));
        let n = b
            .column_by_name("n_points")
            .unwrap()
            .as_primitive::<UInt32Type>()
            .clone();
        let opt = |a: &arrow_array::Float64Array, i: usize| (!a.is_null(i)).then(|| a.value(i));
        for i in 0..b.num_rows() {
            out.insert(
                (q.value(i).to_string(), k.value(i).to_string()),
                (
                    v.value(i),
                    opt(&e, i),
                    opt(&c, i),
                    n.value(i),
                    w.value(i).to_string(),
                    opt(&r, i),
                    qu.value(i).to_string(),
                ),
            );
        }
    }
    out
}

fn manifest_1d() -> serde_json::Value {
    json!({
        "name": "analyze-1d",
        "model": "rfm",
        "seed": 5,
        "replicas": 2,
        "params": {
            "dim": 1,
            "n_particles": 30,
            "reduced_length": 1.0,
            "restitution_normal": 0.5,
            "warmup": 0.2,
            "duration": 0.5,
            "sample_every": 1000,
            "observables": ["velocity_moments", "velocity_histogram", "neighbour_distances"],
            "velocity_histogram": {"range": [-3, 3], "bins": 600},
            "neighbour_distances": {"h_max": 1}
        },
        "sweep": {"n_particles": [30, 60, 120]}
    })
}

fn manifest_2d() -> serde_json::Value {
    json!({
        "name": "analyze-2d",
        "model": "rfm",
        "seed": 6,
        "replicas": 2,
        "params": {
            "dim": 2,
            "n_particles": 300,
            "packing_fraction": 0.4,
            "restitution_normal": 0.3,
            "restitution_tangential": 0.3,
            "warmup": 0.05,
            "duration": 0.1,
            "sample_every": 1000,
            "observables": ["velocity_histogram", "structure_factor", "radial_distribution", "free_paths"],
            "velocity_histogram": {"range": [-3, 3], "bins": 600},
            "structure_factor": {"k_max": 10, "every": 2},
            "radial_distribution": {"every": 5},
            "free_paths": {"bins_per_decade": 10}
        }
    })
}

fn run(args: &[&str], log: &Path) -> Option<i32> {
    run_granular(args, log, Duration::from_secs(300))
}

#[test]
fn analyze_end_to_end() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log.txt");
    let (m1, m2) = (dir.path().join("m1.json"), dir.path().join("m2.json"));
    write_json(&m1, &manifest_1d());
    write_json(&m2, &manifest_2d());
    let (a, b) = (dir.path().join("A"), dir.path().join("B"));
    let (a_s, b_s) = (a.to_str().unwrap(), b.to_str().unwrap());

    // Half of the 1D campaign: analysed with a warning.
    let code = run(
        &[
            "run",
            m1.to_str().unwrap(),
            "--out",
            a_s,
            "--shard",
            "1/2",
            "--quiet",
        ],
        &log,
    );
    assert_eq!(code, Some(0), "{}", log_text(&log));
    let (code, out) = run_capture(&["analyze", a_s, "--no-figures"], &log);
    assert_eq!(code, Some(0), "{out}\n{}", log_text(&log));
    assert!(
        log_text(&log).contains("of 6 runs are finished"),
        "{}",
        log_text(&log)
    );
    let code = run(&["resume", a_s, "--quiet"], &log);
    assert_eq!(code, Some(0), "{}", log_text(&log));

    // The whole campaign, N >= 30 (the default N >= 398 would leave no point).
    let (code, out) = run_capture(&["analyze", a_s, "--n-min", "30"], &log);
    assert_eq!(code, Some(0), "{out}\n{}", log_text(&log));
    eprintln!("{out}");
    let fits = read_fits(&a.join("analysis").join("analysis_fits.parquet"));
    let key = "eps=0.5,L'=1".to_string();
    let xi2 = &fits[&("xi_2".to_string(), key.clone())];
    // Mean field 2/3, thesis ~0.53-0.6 for eps = 0.5; tiny noisy systems: a wide band.
    assert!(xi2.0 > 0.2 && xi2.0 < 1.1, "xi_2 = {}", xi2.0);
    assert!(xi2.1.unwrap() > 0.0 && xi2.1.unwrap() < 0.5);
    assert_eq!(xi2.3, 3);
    assert!(xi2.4.contains("N in [30, 120]"), "{}", xi2.4);
    // zeta_1 = 1: <R> = L'/N exactly (3.19); the bisection reference is 1.
    let z1 = &fits[&("zeta_1".to_string(), key.clone())];
    assert!((z1.0 - 1.0).abs() < 0.01, "zeta_1 = {}", z1.0);
    assert_eq!(z1.5, Some(1.0));
    let z2 = &fits[&("zeta_2".to_string(), key.clone())];
    assert!((z2.5.unwrap() - 3f64.ln() / 2f64.ln()).abs() < 1e-12);
    assert!(z2.0 > 1.0 && z2.0 < 3.0, "zeta_2 = {}", z2.0);
    assert!(fits.contains_key(&("lambda".to_string(), key.clone())));
    // G_1 beside the closed-form uniform bisection P_n, n = log2 N.
    let g = &fits[&(
        "G_1_vs_bisection_rms_log_ratio".to_string(),
        format!("{key},N=120"),
    )];
    assert!(g.0.is_finite() && g.0 >= 0.0 && g.3 > 0);
    // A number that is no fit (no parameter) is never flagged; xi_2 over N = 30..120 is (3
    // points for 2 parameters, and N below the thesis's cut 398).
    assert_eq!(g.6, "ok");
    assert!(
        xi2.6.contains("window: 3 points for 2 parameters") && xi2.6.contains("N from 30 < 398"),
        "{}",
        xi2.6
    );
    assert!(a
        .join("analysis/figures/g1-bisection-eps_0.5_L__1_N_120.png")
        .is_file());
    // Every order of the velocity moments has its exponent.
    assert!((1..=12).all(|m| fits.contains_key(&(format!("xi_{m}"), key.clone()))));
    let figs = a.join("analysis").join("figures");
    for f in ["xi2-fit.png", "xi-m.svg", "zeta-m.png", "collapse.png"] {
        assert!(figs.join(f).is_file(), "{f} missing");
    }
    assert!(a.join("analysis").join("analysis_curves.parquet").is_file());

    // 2D: D_f from S(k) (L = 0.073 m < L_Eff, so k < 2 k_D: the two lowest shells),
    // C(R), free paths.
    let code = run(
        &["run", m2.to_str().unwrap(), "--out", b_s, "--quiet"],
        &log,
    );
    assert_eq!(code, Some(0), "{}", log_text(&log));
    let out_dir = dir.path().join("an2");
    let (code, out) = run_capture(&["analyze", b_s, "--out", out_dir.to_str().unwrap()], &log);
    assert_eq!(code, Some(0), "{out}\n{}", log_text(&log));
    eprintln!("{out}");
    let fits = read_fits(&out_dir.join("analysis_fits.parquet"));
    let df = fits
        .iter()
        .find(|(k, _)| k.0 == "D_f_structure_factor")
        .expect("D_f row");
    assert!(df.0 .1.starts_with("phi=0.4,L=0.07"), "{}", df.0 .1);
    assert_eq!(df.1 .3, 2);
    // Two shells for two parameters: no residual freedom, flagged (and the box is below
    // L_min: no shell in k < k_D).
    assert!(
        df.1 .6.contains("window: 2 points for 2 parameters"),
        "{}",
        df.1 .6
    );
    assert!(df.1 .4.starts_with("k < 2 k_D"), "{}", df.1 .4);
    assert!(
        df.1 .0.is_finite() && df.1 .0 > -1.0 && df.1 .0 < 4.0,
        "{}",
        df.1 .0
    );
    let c = fits
        .iter()
        .find(|(k, _)| k.0 == "C_R_exponent")
        .expect("C(R) row");
    // C(R) ~ R^2 at large R.
    assert!((c.1 .0 - 2.0).abs() < 0.3, "C(R) exponent {}", c.1 .0);
    assert!(fits.iter().any(|(k, _)| k.0 == "v_r"));
    assert!(fits.values().all(|v| v.0.is_finite()));
    assert!(std::fs::read_dir(out_dir.join("figures")).unwrap().count() >= 4);

    // A cascade campaign: D_f per point from its runs' S(k) (cascade_structure_factor),
    // keyed by its typed params (variant, level, box_length), over 1 <= k L / 2 pi <=
    // 2^(n-3). (The exact D_f of a synthetic S = 2 k^-1.6, n = 8, L = 1, is
    // `models::cascade::analysis::tests::df_of_a_power_law_structure_factor`.)
    let m3 = dir.path().join("m3.json");
    write_json(
        &m3,
        &json!({
            "name": "analyze-cascade",
            "model": "cascade",
            "seed": 7,
            "params": {"level": 5, "box_length": 1.0, "variant": "ucp", "realisations": 8}
        }),
    );
    let cas_dir = dir.path().join("C");
    let code = run(
        &[
            "run",
            m3.to_str().unwrap(),
            "--out",
            cas_dir.to_str().unwrap(),
            "--quiet",
        ],
        &log,
    );
    assert_eq!(code, Some(0), "{}", log_text(&log));
    let (code, out) = run_capture(&["analyze", cas_dir.to_str().unwrap()], &log);
    assert_eq!(code, Some(0), "{out}\n{}", log_text(&log));
    let fits = read_fits(&cas_dir.join("analysis").join("analysis_fits.parquet"));
    let cas = fits
        .iter()
        .find(|(k, _)| k.0 == "D_f_cascade")
        .expect("cascade D_f row");
    assert!(cas.0 .1.starts_with("variant="), "{}", cas.0 .1);
    assert_eq!(cas.0 .1, "variant=ucp,n=5,L=1");
    assert!(
        cas.1 .0.is_finite() && cas.1 .0 > 0.5 && cas.1 .0 < 2.5,
        "cascade D_f {}",
        cas.1 .0
    );
    // Shells n^2 = a^2 + b^2 in (0, 16] (k L / 2 pi <= 2^(5-3)): every one is in the window.
    let shells = (0..=4i64)
        .flat_map(|a| (0..=4i64).map(move |b| a * a + b * b))
        .filter(|&s| s > 0 && s <= 16)
        .collect::<std::collections::BTreeSet<_>>()
        .len();
    assert_eq!(cas.1 .3 as usize, shells);
    assert!(cas_dir
        .join("analysis/figures/cascade-sk-variant_ucp_n_5_L_1.svg")
        .is_file());

    // A missing table: refused (exit 3), not a panic; its committed parts are named missing
    // by the integrity check that analyze makes first (`granular resume` runs them again).
    std::fs::remove_dir_all(b.join("tables").join("rfm_structure_factor")).unwrap();
    let (code, _) = run_capture(&["analyze", b_s], &log);
    assert_eq!(code, Some(3), "{}", log_text(&log));
    assert!(
        log_text(&log).contains("tables/rfm_structure_factor/")
            && log_text(&log).contains(": missing")
            && log_text(&log).contains("granular resume"),
        "{}",
        log_text(&log)
    );
}

#[test]
fn analyze_refuses_what_it_cannot_analyse() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log.txt");
    // Not a campaign.
    let (code, _) = run_capture(&["analyze", dir.path().to_str().unwrap()], &log);
    assert_eq!(code, Some(3), "{}", log_text(&log));
    assert!(log_text(&log).contains("not a granular campaign directory"));
    // A DSMC campaign (theory tables only, no simulation).
    let d = dir.path().join("dsmc");
    let m = repo_root().join("tests/manifests/good/power_law_sweep.json");
    let code = run_granular(
        &["theory", m.to_str().unwrap(), "--out", d.to_str().unwrap()],
        &log,
        Duration::from_secs(120),
    );
    assert_eq!(code, Some(0), "{}", log_text(&log));
    let (code, _) = run_capture(&["analyze", d.to_str().unwrap()], &log);
    assert_eq!(code, Some(3), "{}", log_text(&log));
    assert!(
        log_text(&log).contains("is of model dsmc")
            && log_text(&log).contains("which has no analysis"),
        "{}",
        log_text(&log)
    );
}

/// A non-thesis system (issue 26): a nearly elastic 2D gas (eps_n = eps_t = 0.95) at phi =
/// 0.1 in a box far below L_min = 2 pi/k_D (k_D (4.5) = 2.07 1/m: L_min = 3.04 m, the box
/// 0.12 m), where the clustering law C(R) ~ R^D_f has no range. The C(R) fit is flagged in
/// the `quality` column (the window by the law's validity, and a poor fit exactly when its
/// chi2_r is above the 99.9 % quantile of its dof), a warning names it with what to do, the
/// summary marks it, and the report shades it. Exit 0: a flag is no failure.
#[test]
fn analyze_flags_fits_outside_their_law() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log.txt");
    let m = dir.path().join("m.json");
    write_json(
        &m,
        &json!({
            "name": "non-thesis",
            "model": "rfm",
            "seed": 11,
            "replicas": 2,
            "params": {
                "dim": 2,
                "n_particles": 200,
                "packing_fraction": 0.1,
                "restitution_normal": 0.95,
                "restitution_tangential": 0.95,
                "warmup": 0.05,
                "duration": 0.1,
                "sample_every": 1000,
                "observables": ["structure_factor", "radial_distribution"],
                "structure_factor": {"k_max": 10, "every": 2},
                "radial_distribution": {"every": 5}
            }
        }),
    );
    let c = dir.path().join("C");
    let c_s = c.to_str().unwrap();
    let code = run(&["run", m.to_str().unwrap(), "--out", c_s, "--quiet"], &log);
    assert_eq!(code, Some(0), "{}", log_text(&log));
    let (code, out) = run_capture(&["analyze", c_s, "--no-figures"], &log);
    assert_eq!(code, Some(0), "{out}\n{}", log_text(&log));
    let fits = read_fits(&c.join("analysis").join("analysis_fits.parquet"));
    let (key, f) = fits
        .iter()
        .find(|(k, _)| k.0 == "C_R_exponent")
        .expect("C(R) row");
    let quality = &f.6;
    assert!(
        quality.starts_with("window: box L = 0.1189 m < L_min = 2 pi/k_D = ")
            && quality.contains("no k < k_D in the box"),
        "{quality}"
    );
    let limit = granular::analysis::chi2_reduced_limit(f.3 - 2).unwrap();
    let chi = f.2.expect("a weighted fit");
    assert_eq!(
        quality.contains("; poor_fit: chi2_r "),
        chi > limit,
        "chi2_r {chi}, limit {limit}: {quality}"
    );
    // Every fit here has the box below L_min: none is "ok".
    assert!(fits.values().all(|v| v.6 != "ok"), "{fits:?}");
    // The warning names the quantity, the reason and what to do.
    let text = log_text(&log);
    assert!(
        text.contains(&format!("C_R_exponent [{}] = ", key.1))
            && text.contains("is flagged, not a result: window: box L = 0.1189 m < L_min")
            && text.contains("use a box larger than L_Eff = "),
        "{text}"
    );
    // The summary marks it.
    let line = out
        .lines()
        .find(|l| l.trim_start().starts_with("C_R_exponent"))
        .expect("C(R) in the summary");
    assert!(line.contains("  [window: L < L_min"), "{out}");
    assert!(out.contains("flagged [..]: not results"), "{out}");
    // The report shades the row and names the flagged count.
    let code = run(&["report", c_s], &log);
    assert_eq!(code, Some(0), "{}", log_text(&log));
    let html = std::fs::read_to_string(c.join("report.html")).unwrap();
    assert!(
        html.contains("<tr class=\"flagged\"><td>non-thesis</td><td>C_R_exponent</td>"),
        "{html}"
    );
    assert!(html.contains("<td class=\"q\">window: box L = 0.1189 m"));
    assert!(html.contains("flagged rows (shaded; see their quality): not results."));
}
