//! The cost estimate of `plan` (and `run --dry-run`), issue 24 item 4: the runs to do, the
//! core-hours and the wall time at `--threads`, from the models' cost model calibrated on the
//! campaign's finished runs, else a probe run, else (`--no-probe`) as it is, the calibration
//! named; a target campaign's pilot; the report's estimate against what the runs took. No
//! timing is asserted: only which calibration is used and how the numbers relate.

use std::path::Path;
use std::time::Duration;

use serde_json::{json, Value};

use super::util::{self, heavy, log_text, run_capture, run_granular, s};

const LIMIT: Duration = Duration::from_secs(300);

fn manifest() -> Value {
    json!({
        "name": "cost", "model": "dsmc", "seed": 1, "replicas": 2,
        "params": {
            "method": "low_rank",
            "species": {"list": [{"mass": 1, "diameter": 1, "count": 1000},
                                 {"mass": 4, "diameter": 1.5, "count": 100}]},
            "number_density": 0.1,
            "restitution": {"constant": 0.8},
            "t_end": 20.0,
            "output_times": {"log": {"from": 0.1, "to": 20, "per_decade": 3}},
            "observables": ["temperature"]
        },
        "sweep": {"restitution.constant": [0.8, 0.9]}
    })
}

fn plan_json(m: &Path, dir: &Path, extra: &[&str], log: &Path) -> Value {
    let mut args = vec!["plan", s(m), "--out", s(dir), "--json"];
    args.extend_from_slice(extra);
    let (code, out) = run_capture(&args, log);
    assert_eq!(code, Some(0), "plan {extra:?}: log:\n{}", log_text(log));
    serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"))
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

/// A new campaign: `plan --no-probe` estimates its 4 runs with the cost model as it is
/// (calibration "reference", factor 1), the wall time falls with more threads and the
/// estimate is the same twice (a function of the params); without `--no-probe` a probe run
/// calibrates it; the text names the calibration. After the runs, a grown manifest is
/// estimated from the finished runs, and the report compares the estimate with what they
/// took. A target manifest's plan gives the pilot and what the rounds may add. Before issue
/// 24's cost model: `estimate: none (no finished run to estimate from)`, no `--no-probe`.
#[test]
fn plan_estimates_the_cost_and_names_its_calibration() {
    let _h = heavy();
    let dir = tempfile::tempdir().unwrap();
    let (m, c, log) = (
        dir.path().join("m.json"),
        dir.path().join("c"),
        dir.path().join("log"),
    );
    util::write_json(&m, &manifest());
    let one = plan_json(&m, &c, &["--no-probe", "--threads", "1"], &log);
    let two = plan_json(&m, &c, &["--no-probe", "--threads", "2"], &log);
    let e = &two["estimate"];
    assert_eq!(e["runs"], json!(4), "{e}");
    assert_eq!(e["threads"], json!(2));
    assert_eq!(e["calibration"]["source"], json!("reference"), "{e}");
    assert_eq!(f(&e["calibration"]["factor"]), 1.0);
    assert!(
        f(&e["core_seconds"]) > 0.0 && f(&e["wall_seconds"]) > 0.0,
        "{e}"
    );
    assert!((f(&e["core_hours"]) * 3600.0 - f(&e["core_seconds"])).abs() < 1e-9);
    assert_eq!(one["estimate"]["core_seconds"], e["core_seconds"]);
    assert!(f(&one["estimate"]["wall_seconds"]) > f(&e["wall_seconds"]));
    assert_eq!(
        plan_json(&m, &c, &["--no-probe", "--threads", "2"], &log)["estimate"],
        *e
    );
    let probed = plan_json(&m, &c, &["--threads", "2"], &log);
    let cal = &probed["estimate"]["calibration"];
    assert_eq!(cal["source"], json!("probe"), "{cal}");
    assert!(f(&cal["factor"]) > 0.0 && f(&cal["factor"]).is_finite());
    let (code, text) = run_capture(&["plan", s(&m), "--out", s(&c), "--no-probe"], &log);
    assert_eq!(code, Some(0));
    assert!(text.contains("  estimate: 4 runs, ~"), "{text}");
    assert!(text.contains("core-hours"), "{text}");
    assert!(text.contains("  calibration: reference ("), "{text}");
    assert!(!c.exists(), "plan wrote the campaign directory");
    // The runs, then a grown manifest: calibrated on the finished runs.
    let code = run_granular(
        &["run", s(&m), "--out", s(&c), "--quiet", "--threads", "2"],
        &log,
        LIMIT,
    );
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let mut grown = manifest();
    grown["replicas"] = json!(3);
    let g = dir.path().join("g.json");
    util::write_json(&g, &grown);
    let p = plan_json(&g, &c, &["--threads", "2"], &log);
    let e = &p["estimate"];
    assert_eq!(e["runs"], json!(2), "{e}");
    assert_eq!(e["calibration"]["source"], json!("finished runs"), "{e}");
    assert!(f(&e["calibration"]["factor"]) > 0.0);
    let (code, text) = run_capture(&["run", s(&g), "--out", s(&c), "--dry-run"], &log);
    assert_eq!(code, Some(0));
    assert!(text.contains("  calibration: finished runs ("), "{text}");
    // The report: the estimate against what the runs took.
    let html = dir.path().join("r.html");
    let code = run_granular(&["report", s(&c), "--out", s(&html)], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let page = std::fs::read_to_string(&html).unwrap();
    assert!(
        page.contains("<p id=\"progress-cost\">Cost: the 4 finished run(s) were estimated at "),
        "no cost line in the report"
    );
    assert!(page.contains("core-hours (the cost model at its reference machine), took "));
    // Error targets: the pilot is what is estimated; the rest is decided in rounds.
    let mut t = manifest();
    t.as_object_mut().unwrap().remove("replicas");
    t["derived"] = json!({"gamma": "temperature[species=2] / temperature[species=1]"});
    t["target"] = json!([{"quantity": "gamma", "sem_rel": 1e-3}]);
    t["min_replicas"] = json!(3);
    t["max_replicas"] = json!(50);
    let tm = dir.path().join("t.json");
    util::write_json(&tm, &t);
    let fresh = dir.path().join("t");
    let p = plan_json(&tm, &fresh, &["--no-probe"], &log);
    assert_eq!(p["estimate"]["runs"], json!(6), "{p}");
    assert_eq!(p["targets"]["min_replicas"], json!(3));
    assert_eq!(p["targets"]["max_runs"], json!(100));
    assert!(f(&p["targets"]["max_core_hours"]) > f(&p["targets"]["pilot_core_hours"]));
    let (code, text) = run_capture(&["plan", s(&tm), "--out", s(&fresh), "--no-probe"], &log);
    assert_eq!(code, Some(0));
    assert!(
        text.contains("error targets: the pilot of 3 replica(s) per point"),
        "{text}"
    );
    assert!(text.contains("decided in rounds"), "{text}");
}
