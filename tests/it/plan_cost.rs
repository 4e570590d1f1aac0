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

/// A binary mixture: restitution 0.5 and 0.9 by a second-species mass of 2, 4 and 8, two
/// replicas each (tiny: 60 particles to t = 2).
fn mixture(eps: &[f64], masses: &[u32], replicas: u32) -> Value {
    json!({
        "name": "mixture", "model": "dsmc", "seed": 3, "replicas": replicas,
        "params": {
            "method": "low_rank",
            "species": {"list": [{"mass": 1, "diameter": 1, "count": 40},
                                 {"mass": 2, "diameter": 1, "count": 20}]},
            "number_density": 0.1,
            "restitution": {"constant": 0.5},
            "t_end": 2.0,
            "output_times": {"list": [1.0, 2.0]},
            "observables": ["temperature"]
        },
        "sweep": {"restitution.constant": eps, "species.list.1.mass": masses}
    })
}

/// The new point of `plan --json` whose label has every one of `has`.
fn new_point<'a>(p: &'a Value, has: &[&str]) -> &'a Value {
    p["points"]
        .as_array()
        .unwrap()
        .iter()
        .find(|x| has.iter().all(|h| x["label"].as_str().unwrap().contains(h)))
        .unwrap_or_else(|| panic!("no new point {has:?} in {}", p["points"]))
}

/// Issue 26, `plan` of a grown and of a shrunk campaign. A new point names only the leaves
/// that differ from its truly nearest point (`species.list.1.mass: 8 -> 16`, never the
/// species list's JSON; restitution 0.8 is nearest to 0.9, not to 0.5 which ties on the
/// number of differing keys and comes first); the expected time of the new work is given
/// (JSON `new_work`, and a text line at `--threads`). A shrunk manifest lists the points and
/// replicas that leave it, with their ids, runs and differences, and says that they are
/// kept. On 2757bb9: `differs` was `species.list: [{...}] -> [{...}]` of point 0, 0.8 was
/// described from 0.5, and there was no `new_work`, `leaving_points` or `leaving_runs`.
#[test]
fn plan_names_leaf_differences_nearest_points_leaving_runs_and_time() {
    let _h = heavy();
    let dir = tempfile::tempdir().unwrap();
    let (m, c, log) = (
        dir.path().join("m.json"),
        dir.path().join("c"),
        dir.path().join("log"),
    );
    util::write_json(&m, &mixture(&[0.5, 0.9], &[2, 4, 8], 2));
    let code = run_granular(
        &["run", s(&m), "--out", s(&c), "--quiet", "--threads", "2"],
        &log,
        LIMIT,
    );
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    // Grown: mass 16 and restitution 0.8.
    let g = dir.path().join("g.json");
    util::write_json(&g, &mixture(&[0.5, 0.8, 0.9], &[2, 4, 8, 16], 2));
    let p = plan_json(&g, &c, &["--threads", "2"], &log);
    assert_eq!(p["new_points"].as_array().unwrap().len(), 6, "{p}");
    let sixteen = new_point(&p, &["restitution.constant=0.5", "mass=16"]);
    assert_eq!(
        sixteen["differs"],
        json!(["species.list.1.mass: 8 -> 16"]),
        "{sixteen}"
    );
    let eight_tenths = new_point(&p, &["restitution.constant=0.8", "mass=2"]);
    assert_eq!(
        eight_tenths["differs"],
        json!(["restitution.constant: 0.9 -> 0.8"]),
        "{eight_tenths}"
    );
    let w = &p["new_work"];
    assert_eq!(w["runs"], json!(12), "{w}");
    assert_eq!(w["threads"], json!(2), "{w}");
    assert!(
        f(&w["wall_seconds"]) > 0.0 && f(&w["core_hours"]) > 0.0,
        "{w}"
    );
    assert!(p["leaving_points"].as_array().unwrap().is_empty(), "{p}");
    let (code, text) = run_capture(&["plan", s(&g), "--out", s(&c), "--threads", "2"], &log);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    assert!(text.contains("species.list.1.mass: 8 -> 16"), "{text}");
    assert!(!text.contains("[{"), "JSON in the plan:\n{text}");
    assert!(
        text.contains("  expected time of the new work (12 run(s) added): ~"),
        "{text}"
    );
    assert!(text.contains(" s wall at 2 thread(s)"), "{text}");
    // Shrunk: restitution 0.5 only, masses 2 and 4, one replica.
    let k = dir.path().join("k.json");
    util::write_json(&k, &mixture(&[0.5], &[2, 4], 1));
    let p = plan_json(&k, &c, &["--no-probe"], &log);
    let leaving = p["leaving_points"].as_array().unwrap();
    assert_eq!(leaving.len(), 4, "{p}");
    for x in leaving {
        assert_eq!(
            (x["runs"].clone(), x["finished"].clone()),
            (json!(2), json!(2)),
            "{x}"
        );
        assert!(x["nearest"].is_u64(), "{x}");
    }
    let far = leaving
        .iter()
        .find(|x| {
            let l = x["label"].as_str().unwrap();
            l.contains("restitution.constant=0.9") && l.contains("mass=8")
        })
        .unwrap_or_else(|| panic!("{p}"));
    assert_eq!(
        far["differs"],
        json!([
            "restitution.constant: 0.9 -> 0.5",
            "species.list.1.mass: 8 -> 4"
        ]),
        "{far}"
    );
    let runs = p["leaving_runs"].as_array().unwrap();
    assert_eq!(runs.len(), 2, "{p}");
    for x in runs {
        assert_eq!(x["replicas"], json!([1]), "{x}");
        assert_eq!(x["finished"], json!(1), "{x}");
    }
    let (code, text) = run_capture(&["plan", s(&k), "--out", s(&c), "--no-probe"], &log);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    assert!(
        text.contains("leaving the manifest: 4 point(s) and 2 run(s) of points it keeps (10 run(s), 10 finished); they stay in the campaign, nothing is deleted"),
        "{text}"
    );
    assert!(text.contains("  leaving point "), "{text}");
    assert!(text.contains("  leaving runs of point "), "{text}");
}
