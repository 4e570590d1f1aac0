//! Issue 26, the manifest's `labels`: the names of the figures (`plot`, `report`) over the
//! models' physics defaults; a key naming nothing of the manifest refused at `/labels/KEY`
//! (exit 2, nothing written); a manifest differing only in `labels` plans and runs nothing
//! new. On main cd536dd (and 2757bb9) `labels` was an unknown top-level key (exit 2).

use std::path::Path;
use std::time::Duration;

use serde_json::{json, Value};

use super::util::{self, heavy, log_text, run_capture, run_granular, s};

const LIMIT: Duration = Duration::from_secs(300);

/// A tiny binary mixture over the second species' mass (60 particles to t = 2, one replica
/// per point), with `labels` if given.
fn mixture(labels: Option<Value>) -> Value {
    let mut m = json!({
        "name": "labels", "model": "dsmc", "seed": 5,
        "params": {
            "method": "low_rank",
            "species": {"list": [{"mass": 1, "diameter": 1, "count": 40},
                                 {"mass": 2, "diameter": 1, "count": 20}]},
            "number_density": 0.1,
            "restitution": {"constant": 0.8},
            "t_end": 2.0,
            "output_times": {"list": [1.0, 2.0]},
            "observables": ["temperature"]
        },
        "sweep": {"species.list.1.mass": [2, 4, 8]}
    });
    if let Some(l) = labels {
        m["labels"] = l;
    }
    m
}

/// `granular plot c --out figs`: the text of the across-sweep figure of T_1 (SVG).
fn across_sweep_svg(c: &Path, figs: &Path, log: &Path) -> String {
    let (code, out) = run_capture(&["plot", s(c), "--out", s(figs)], log);
    assert_eq!(code, Some(0), "{out}\nlog:\n{}", log_text(log));
    let svg = figs.join("sweep-species_list_1_mass-temperature-k1.svg");
    std::fs::read_to_string(&svg).unwrap_or_else(|e| {
        let names: Vec<_> = std::fs::read_dir(figs)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        panic!("{}: {e}; figures: {names:?}", svg.display())
    })
}

/// `plan --json` of `m` on `c`: its new runs.
fn new_runs(m: &Path, c: &Path, log: &Path) -> u64 {
    let (code, out) = run_capture(&["plan", s(m), "--out", s(c), "--json", "--no-probe"], log);
    assert_eq!(code, Some(0), "{out}\nlog:\n{}", log_text(log));
    let p: Value = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"));
    p["new_runs"]
        .as_u64()
        .unwrap_or_else(|| panic!("no new_runs: {p}"))
}

/// The label of a sweep key names the axis, title and file of the across-sweep figure in
/// `plot` and `report` (the physics default `m_2` gone); the same manifest without `labels`
/// (and back with them) plans 0 new runs, runs nothing, keeps every table, and its figures
/// show `m_2` again.
#[test]
fn labels_name_the_figures_and_change_no_run() {
    let _h = heavy();
    let dir = tempfile::tempdir().unwrap();
    let (m, c, log) = (
        dir.path().join("m.json"),
        dir.path().join("c"),
        dir.path().join("log"),
    );
    util::write_json(
        &m,
        &mixture(Some(json!({"species.list.1.mass": "mass ratio"}))),
    );
    let code = run_granular(&["run", s(&m), "--out", s(&c), "--quiet"], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let tables = util::read_tables(&c);

    let svg = across_sweep_svg(&c, &dir.path().join("figs"), &log);
    assert!(svg.contains("mass ratio"), "{svg}");
    assert!(!svg.contains("m_2"), "{svg}");
    let (code, out) = run_capture(&["report", s(&c)], &log);
    assert_eq!(code, Some(0), "{out}\nlog:\n{}", log_text(&log));
    let html = std::fs::read_to_string(c.join("report.html")).unwrap();
    assert!(
        html.contains("mass ratio"),
        "the report's figures name the label"
    );

    // Without labels: the same runs, the physics name on the axis.
    let bare = dir.path().join("bare.json");
    util::write_json(&bare, &mixture(None));
    assert_eq!(new_runs(&bare, &c, &log), 0, "labels are no part of a run");
    let code = run_granular(&["run", s(&bare), "--out", s(&c), "--quiet"], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    util::assert_tables_identical(&tables, &util::read_tables(&c), "labels removed");
    let svg = across_sweep_svg(&c, &dir.path().join("figs-bare"), &log);
    assert!(svg.contains("m_2"), "{svg}");
    assert!(!svg.contains("mass ratio"), "{svg}");

    // Other labels again: still nothing new.
    let other = dir.path().join("other.json");
    util::write_json(
        &other,
        &mixture(Some(
            json!({"species_list_1_mass": "m_2/m_1", "temperature": "T"}),
        )),
    );
    assert_eq!(new_runs(&other, &c, &log), 0, "labels are no part of a run");
    let code = run_granular(&["run", s(&other), "--out", s(&c), "--quiet"], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let svg = across_sweep_svg(&c, &dir.path().join("figs-other"), &log);
    assert!(svg.contains("m_2/m_1"), "{svg}");
    util::assert_tables_identical(&tables, &util::read_tables(&c), "labels changed");
}

/// A key of `labels` that names nothing of the manifest, and an empty or too long name: exit
/// 2, each error at its `/labels/KEY` (the unknown key with the nearest names), nothing
/// written.
#[test]
fn bad_labels_are_refused_at_their_keys() {
    let dir = tempfile::tempdir().unwrap();
    let (m, c, log) = (
        dir.path().join("m.json"),
        dir.path().join("c"),
        dir.path().join("log"),
    );
    util::write_json(
        &m,
        &mixture(Some(json!({
            "species.list.1.mas": "mass ratio",
            "restitution.constant": "",
            "t_end": "x".repeat(61),
        }))),
    );
    let (code, out) = run_capture(&["run", s(&m), "--out", s(&c), "--quiet"], &log);
    let text = format!("{out}{}", log_text(&log));
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("/labels/species.list.1.mas"), "{text}");
    assert!(
        text.contains("`species.list.1.mass`"),
        "nearest name: {text}"
    );
    assert!(text.contains("/labels/restitution.constant"), "{text}");
    assert!(text.contains("/labels/t_end"), "{text}");
    assert!(!c.exists(), "nothing written");
}
