//! The standard figures of the rfm and auxiliary models, end to end: tiny campaigns run, then
//! `granular plot` writes exactly the expected figures (PNG + SVG) and `granular report`
//! embeds the same ones (`<figure id="fig-...">`); an rfm campaign's report shows what
//! `granular analyze` wrote (the fits table, the figures as data-URI images) once it exists;
//! more points than one figure holds are split over `<id>-<i>of<n>` figures.

use std::collections::BTreeSet;
use std::path::Path;
use std::time::Duration;

use serde_json::{json, Value};

use super::util::s;
use super::util::{heavy, log_text, repo_root, run_capture, run_granular, write_json};

const LIMIT: Duration = Duration::from_secs(300);

/// The names (without extension) of the files of `dir` ending in `.ext`.
fn stems(dir: &Path, ext: &str) -> BTreeSet<String> {
    std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == ext))
        .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
        .collect()
}

/// The ids of the `<figure id="fig-...">` elements of a report.
fn report_figures(html: &str) -> BTreeSet<String> {
    html.split("<figure id=\"fig-")
        .skip(1)
        .map(|rest| rest[..rest.find('"').unwrap()].to_string())
        .collect()
}

/// Run `manifest` into `dir/c`, then `plot` and `report`: the figure names of both (which
/// must agree, PNG and SVG alike) and the page.
fn run_plot_report(dir: &Path, manifest: &Value) -> (BTreeSet<String>, String) {
    let (m, c, log) = (dir.join("m.json"), dir.join("c"), dir.join("log"));
    write_json(&m, manifest);
    let code = run_granular(&["run", s(&m), "--out", s(&c), "--quiet"], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let figs = dir.join("figs");
    let (code, out) = run_capture(&["plot", s(&c), "--out", s(&figs)], &log);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let png = stems(&figs, "png");
    assert_eq!(png, stems(&figs, "svg"), "a PNG and an SVG per figure");
    assert!(
        out.contains(&format!("wrote {} files", 2 * png.len())),
        "{out}"
    );
    let (code, out) = run_capture(&["report", s(&c)], &log);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let html = std::fs::read_to_string(c.join("report.html")).unwrap();
    assert_eq!(
        report_figures(&html),
        png,
        "the report embeds what plot draws"
    );
    assert!(out.contains(&format!("{} figures", png.len())), "{out}");
    assert!(!html.contains("has no standard figures"));
    assert!(!html.to_ascii_lowercase().contains("<script"));
    (png, html)
}

fn names(v: &[&str]) -> BTreeSet<String> {
    v.iter().map(|x| x.to_string()).collect()
}

/// A tiny 2D rfm campaign with every histogram-free and histogram observable: 2 points x 2
/// replicas, well under a second.
fn rfm_manifest() -> Value {
    json!({
        "name": "rfm-figures",
        "model": "rfm",
        "seed": 3,
        "replicas": 2,
        "params": {
            "dim": 2, "n_particles": 60, "packing_fraction": 0.2,
            "warmup": 0.002, "duration": 0.01, "sample_every": 200,
            "observables": ["velocity_moments", "velocity_histogram", "structure_factor",
                            "radial_distribution", "free_paths", "post_collision_velocity"],
            "velocity_histogram": {"range": [-2, 2], "bins": 40},
            "structure_factor": {"k_max": 8, "every": 2},
            "radial_distribution": {"r_max": 0.01, "bins": 20}
        },
        "sweep": {"packing_fraction": [0.1, 0.2]}
    })
}

#[test]
fn rfm_figures_and_analysis_in_the_report() {
    let _g = heavy();
    let tmp = tempfile::tempdir().unwrap();
    let (figs, html) = run_plot_report(tmp.path(), &rfm_manifest());
    assert_eq!(
        figs,
        names(&[
            "temperature",
            "velocity-moments",
            "velocity-distribution",
            "post-collision-velocity-distribution",
            "free-path-distribution",
            "structure-factor",
            "radial-distribution",
        ])
    );
    // Both points in the overlays' legends (in the SVG text), by the physics name of
    // `packing_fraction` (issue 26, `labels`).
    assert!(html.contains("φ=0.1") && html.contains("φ=0.2"));
    assert!(
        !html.contains("id=\"analysis\""),
        "no analysis section before analyze"
    );

    // After `analyze`: its fits as a table and each of its SVG figures as an image.
    let (c, log) = (tmp.path().join("c"), tmp.path().join("log"));
    let code = run_granular(&["analyze", s(&c)], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let analysis_svgs = stems(&c.join("analysis").join("figures"), "svg");
    assert!(!analysis_svgs.is_empty());
    let (code, out) = run_capture(&["report", s(&c)], &log);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    assert!(
        out.contains(&format!("{} analysis figures", analysis_svgs.len())),
        "{out}"
    );
    let html = std::fs::read_to_string(c.join("report.html")).unwrap();
    assert!(html.contains("<h2 id=\"analysis\">"));
    assert!(html.contains("<h3 id=\"analysis-analysis_fits\">"));
    assert!(
        html.contains("<th>quantity</th>"),
        "the fits table's columns"
    );
    assert!(
        html.contains(" rows.</p>\n<table>"),
        "the fits table has rows"
    );
    for f in &analysis_svgs {
        assert!(
            html.contains(&format!(
                "<figure id=\"analysis-fig-{f}\">\n<img alt=\"{f}\" src=\"data:image/svg+xml;base64,"
            )),
            "analysis figure {f} missing"
        );
    }
    assert_eq!(report_figures(&html), figs, "the model's figures unchanged");
    assert!(!html.to_ascii_lowercase().contains("<script"));
}

/// 13 points (one more than a figure holds): two figures of 7 and 6 points.
#[test]
fn many_points_split_over_figures() {
    let _g = heavy();
    let tmp = tempfile::tempdir().unwrap();
    let noise: Vec<f64> = (1..=13).map(|i| i as f64 * 1e-9).collect();
    let m = json!({
        "name": "rfm-many",
        "model": "rfm",
        "seed": 4,
        "params": {
            "dim": 2, "n_particles": 20, "packing_fraction": 0.1,
            "warmup": 0.001, "duration": 0.004, "sample_every": 200, "noise_strength": 1e-8
        },
        "sweep": {"noise_strength": noise}
    });
    let (figs, html) = run_plot_report(tmp.path(), &m);
    assert_eq!(figs, names(&["temperature-1of2", "temperature-2of2"]));
    assert!(html.contains("(points 0-6)") && html.contains("(points 7-12)"));
}

#[test]
fn auxiliary_model_figures() {
    let _g = heavy();
    for (model, want) in [
        ("bisection", vec!["length-distribution", "moments"]),
        (
            "cascade",
            vec![
                "structure-factor",
                "placement-structure-factor",
                "placement-0000",
                "placement-0001",
                "placement-0002",
            ],
        ),
        (
            "spm",
            vec!["velocity-distribution", "velocity-distribution-walk"],
        ),
    ] {
        let tmp = tempfile::tempdir().unwrap();
        let path = repo_root().join(format!("tests/manifests/good/aux_{model}.json"));
        let m: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        let (figs, html) = run_plot_report(tmp.path(), &m);
        assert_eq!(figs, names(&want), "{model}");
        // The points' legend labels come from their parameters.
        let label = match model {
            "bisection" => "concave A=0.3",
            "cascade" => "meakin1, n=6",
            _ => "l=0.0036 m",
        };
        assert!(html.contains(label), "{model}: {label} missing");
    }
}
