//! What the Python module `granular` reads from the command line, never human text:
//! `validate --json`, `run`/`resume --progress-json`, `tables --json`. Tiny campaigns,
//! seconds.

use std::fs;

use serde_json::Value;

use super::util::{self, repo_root, s};

/// `validate --json` prints one JSON object on stdout: the errors with their JSON pointers
/// ("/" for the manifest as a whole), the campaign when valid, the warnings `validate` logs.
#[test]
fn validate_json_is_one_object() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let bad = repo_root().join("tests/manifests/bad/several_errors.json");
    let (code, out) = util::run_capture(&["validate", s(&bad), "--json"], &log);
    assert_eq!(code, Some(2), "log:\n{}", util::log_text(&log));
    let v: Value = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"));
    assert_eq!(v["valid"], false, "{v}");
    assert_eq!(v["file"], s(&bad), "{v}");
    let paths: Vec<&str> = v["errors"]
        .as_array()
        .expect("errors")
        .iter()
        .map(|e| {
            assert!(e["message"].as_str().is_some_and(|m| !m.is_empty()), "{e}");
            e["path"].as_str().expect("path")
        })
        .collect();
    for p in [
        "/replicas",
        "/extra",
        "/params/restitution/constant",
        "/sweep/restitution.value",
    ] {
        assert!(paths.contains(&p), "{p} not in {paths:?}");
    }
    assert!(v.get("campaign").is_none(), "{v}");

    // The manifest as a whole: "/".
    let whole = dir.path().join("whole.json");
    fs::write(&whole, "[1]").unwrap();
    let (code, out) = util::run_capture(&["validate", s(&whole), "--json"], &log);
    assert_eq!(code, Some(2));
    let v: Value = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"));
    assert_eq!(v["errors"][0]["path"], "/", "{v}");

    let good = repo_root().join("tests/manifests/good/power_law_sweep.json");
    let (code, out) = util::run_capture(&["validate", s(&good), "--json"], &log);
    assert_eq!(code, Some(0), "log:\n{}", util::log_text(&log));
    let v: Value = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"));
    assert_eq!(v["valid"], true, "{v}");
    assert_eq!(v["errors"], serde_json::json!([]), "{v}");
    assert_eq!(v["warnings"], serde_json::json!([]), "{v}");
    assert_eq!(v["campaign"]["model"], "dsmc", "{v}");
    assert_eq!(v["campaign"]["points"], 4, "{v}");
    assert_eq!(v["campaign"]["runs"], 8, "{v}");
    assert_eq!(v["campaign"]["name"], "good-power-law-sweep", "{v}");

    // A long kinetic theory: valid, its warning in "warnings".
    let species: Vec<Value> = (1..=400)
        .map(|k| {
            let k = k as f64;
            serde_json::json!({"mass": k, "diameter": k.cbrt(), "count": 2})
        })
        .collect();
    let m = serde_json::json!({
        "name": "long-theory", "model": "dsmc", "seed": 1,
        "params": {"method": "low_rank", "species": {"list": species}, "number_density": 0.1,
                   "restitution": {"constant": 0.5}, "t_end": 1e9,
                   "output_times": {"log": {"from": 0.01, "to": 1e9, "per_decade": 2}},
                   "observables": ["msd"]}
    });
    let path = dir.path().join("long.json");
    util::write_json(&path, &m);
    let (code, out) = util::run_capture(&["validate", s(&path), "--json"], &log);
    assert_eq!(code, Some(0), "log:\n{}", util::log_text(&log));
    let v: Value = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"));
    let w = v["warnings"].as_array().expect("warnings");
    assert!(
        w.iter().any(|w| w
            .as_str()
            .is_some_and(|w| w.contains("the kinetic theory, computed before the runs"))),
        "{v}"
    );
}
