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

/// Every table a campaign of each job in `jobs/` (and each good test manifest) has is
/// described, in one line (`granular tables`).
#[test]
fn every_table_of_every_job_has_a_description() {
    let mut missing = Vec::new();
    let mut seen = 0;
    for sub in ["jobs", "tests/manifests/good"] {
        let mut paths: Vec<_> = fs::read_dir(repo_root().join(sub))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|x| x == "json"))
            .collect();
        paths.sort();
        for p in paths {
            let (m, plan) = granular::campaign::plan::load(&p)
                .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            for t in granular::campaign::tables_of(&m, &plan) {
                seen += 1;
                match granular::campaign::table_description(plan.model, t) {
                    Some(d) if !d.is_empty() && !d.contains('\n') => {}
                    other => missing.push(format!("{}: {t}: {other:?}", p.display())),
                }
            }
        }
    }
    for t in ["analysis_fits", "analysis_curves"] {
        for model in ["dsmc", "rfm", "cascade"] {
            let model = serde_json::from_value(Value::from(model)).unwrap();
            assert!(
                granular::campaign::table_description(model, t).is_some(),
                "{t}"
            );
        }
    }
    assert!(seen > 50, "only {seen} tables seen");
    assert!(missing.is_empty(), "{}", missing.join("\n"));
}

/// 2 points x 2 replicas of a few hundred particles: a finished campaign in a second.
fn tiny_campaign(dir: &std::path::Path, log: &std::path::Path) -> std::path::PathBuf {
    let m = dir.join("m.json");
    util::write_json(
        &m,
        &serde_json::json!({
            "name": "machine", "model": "dsmc", "seed": 27, "replicas": 2,
            "params": {"method": "low_rank",
                       "species": {"power_law": {"n1": 0.1, "N1": 400, "theta": 3}},
                       "restitution": {"constant": 0.9}, "t_end": 20.0,
                       "output_times": {"list": [1.0, 10.0]}, "observables": ["msd"]},
            "sweep": {"restitution.constant": [0.8, 0.9]}
        }),
    );
    let out = dir.join("c");
    let code = util::run_granular(
        &[
            "run",
            s(&m),
            "--out",
            s(&out),
            "--quiet",
            "--flush-every",
            "0",
        ],
        log,
        std::time::Duration::from_secs(120),
    );
    assert_eq!(code, Some(0), "{}", util::log_text(log));
    out
}

fn tables_json(dir: &std::path::Path, log: &std::path::Path) -> (Option<i32>, Value) {
    let (code, out) = util::run_capture(&["tables", s(dir), "--json"], log);
    let v = serde_json::from_str(&out)
        .unwrap_or_else(|e| panic!("{e}: {out}\nlog:\n{}", util::log_text(log)));
    (code, v)
}

/// `tables --json` on a finished campaign names every table, each described, with the
/// directory to read (inside the campaign), its files, and rows equal to the rows read from
/// those files; columns with their Arrow types. Damage: exit 3 naming `granular resume`, as
/// `status`. A table link out of the campaign is not followed: an error, no path.
#[test]
fn tables_json_lists_every_table() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let c = {
        let _g = util::heavy();
        tiny_campaign(dir.path(), &log)
    };
    let (code, v) = tables_json(&c, &log);
    assert_eq!(code, Some(0), "{v}\n{}", util::log_text(&log));
    assert_eq!(v["name"], "machine", "{v}");
    assert_eq!(v["model"], "dsmc", "{v}");
    let tables = v["tables"].as_array().expect("tables");
    let names: Vec<&str> = tables.iter().map(|t| t["name"].as_str().unwrap()).collect();
    for want in [
        "runs",
        "points",
        "registered_runs",
        "dsmc_species",
        "dsmc_species_summary",
        "dsmc_theory",
        "dsmc_theory_point",
    ] {
        assert!(names.contains(&want), "{want} not in {names:?}");
    }
    for t in tables {
        let name = t["name"].as_str().unwrap();
        assert!(t.get("error").is_none(), "{t}");
        assert!(
            t["description"].as_str().is_some_and(|d| !d.is_empty()),
            "{t}"
        );
        assert_eq!(t["written"], true, "{t}");
        let path = t["path"].as_str().unwrap_or_else(|| panic!("no path: {t}"));
        let full = c.join(path);
        assert!(full.is_dir(), "{t}");
        // Resolved: a real directory inside the campaign, no link left in it.
        assert!(
            !fs::symlink_metadata(&full)
                .unwrap()
                .file_type()
                .is_symlink(),
            "{t}"
        );
        let n_files = fs::read_dir(&full)
            .unwrap()
            .filter(|e| {
                let n = e
                    .as_ref()
                    .unwrap()
                    .file_name()
                    .to_string_lossy()
                    .into_owned();
                !n.starts_with('.') && n.ends_with(".parquet")
            })
            .count();
        assert_eq!(t["files"], n_files as u64, "{t}");
        let read = util::read_table(&c, name);
        assert_eq!(read.files.len(), n_files, "{t}");
        assert_eq!(t["rows"], read.rows.len() as u64, "{t}");
        let cols = t["columns"].as_array().expect("columns");
        assert_eq!(cols.len(), read.columns.len(), "{t}");
        for (col, want) in cols.iter().zip(&read.columns) {
            assert_eq!(col["name"], want.0.as_str(), "{t}");
            assert_eq!(col["type"], want.1.to_string(), "{t}");
        }
    }
    let runs = tables.iter().find(|t| t["name"] == "runs").unwrap();
    assert_eq!(runs["rows"], 4, "{runs}");
    let run_id = &runs["columns"][0];
    assert_eq!(run_id["name"], "run_id", "{runs}");
    assert_eq!(run_id["type"], "UInt64", "{runs}");
    // The text form: one line per table (and a header).
    let (code, text) = util::run_capture(&["tables", s(&c)], &log);
    assert_eq!(code, Some(0));
    assert_eq!(text.lines().count(), tables.len() + 1, "{text}");

    // Damage (a part of `runs` deleted): exit 3 naming `granular resume`, as status.
    let damaged = dir.path().join("damaged");
    util::copy_dir(&c, &damaged);
    let runs_dir = damaged.join(runs["path"].as_str().unwrap());
    let part = fs::read_dir(&runs_dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|x| x == "parquet"))
        .expect("a part of runs");
    fs::remove_file(&part).unwrap();
    fs::write(&log, "").unwrap();
    let (code, _) = util::run_capture(&["tables", s(&damaged), "--json"], &log);
    assert_eq!(code, Some(3), "{}", util::log_text(&log));
    assert!(
        util::log_text(&log).contains(&format!("`granular resume {}`", damaged.display())),
        "{}",
        util::log_text(&log)
    );

    // tables/runs replaced by a link to a directory outside: not followed.
    let linked = dir.path().join("linked");
    util::copy_dir(&c, &linked);
    let outside = dir.path().join("outside");
    util::copy_dir(&c.join(runs["path"].as_str().unwrap()), &outside);
    let link = linked.join("tables/runs");
    if fs::symlink_metadata(&link).unwrap().is_dir() {
        fs::remove_dir_all(&link).unwrap();
    } else {
        fs::remove_file(&link).unwrap();
    }
    std::os::unix::fs::symlink(&outside, &link).unwrap();
    fs::write(&log, "").unwrap();
    let (code, v) = tables_json(&linked, &log);
    assert_eq!(code, Some(3), "{v}\n{}", util::log_text(&log));
    let runs = v["tables"]
        .as_array()
        .unwrap()
        .iter()
        .find(|t| t["name"] == "runs")
        .unwrap();
    assert!(runs["path"].is_null(), "{runs}");
    assert_eq!(runs["written"], false, "{runs}");
    assert_eq!(runs["rows"], 0, "{runs}");
    let err = runs["error"].as_str().unwrap_or_else(|| panic!("{runs}"));
    assert!(
        err.contains("not followed") && err.contains(s(&outside)),
        "{err}"
    );
}

/// The `{"progress": ...}` lines of stderr, each parsed (a line that does not parse fails).
fn progress_lines(stderr: &str) -> Vec<Value> {
    stderr
        .lines()
        .filter(|l| l.starts_with("{\"progress\""))
        .map(|l| serde_json::from_str::<Value>(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .map(|v| v["progress"].clone())
        .collect()
}

fn assert_progress(lines: &[Value], runs: u64, stderr: &str) {
    assert!(lines.len() >= 2, "{stderr}");
    let mut last = 0;
    for p in lines {
        let f = p["finished"].as_u64().unwrap_or_else(|| panic!("{p}"));
        assert!(f >= last, "finished went down: {stderr}");
        last = f;
        assert_eq!(p["total"], runs, "{p}");
        assert!(p["running"].as_u64().is_some() && p["failed"] == 0, "{p}");
        let x = p["fraction"].as_f64().unwrap_or_else(|| panic!("{p}"));
        assert!((0.0..=1.0).contains(&x), "{p}");
    }
    let end = lines.last().unwrap();
    assert_eq!(end["finished"], runs, "{stderr}");
    assert_eq!(end["fraction"], 1.0, "{stderr}");
    assert_eq!(end["running"], 0, "{stderr}");
}

/// `run --progress-json` (and `resume`) write the progress as JSON lines on stderr besides the
/// logs: each parses, finished never goes down, the last has finished == total == the runs
/// and fraction 1.
#[test]
fn run_and_resume_write_progress_as_json_lines() {
    let dir = tempfile::tempdir().unwrap();
    let m = dir.path().join("m.json");
    util::write_json(
        &m,
        &serde_json::json!({
            "name": "progress", "model": "dsmc", "seed": 28, "replicas": 3,
            "params": {"method": "low_rank",
                       "species": {"power_law": {"n1": 0.1, "N1": 400, "theta": 3}},
                       "restitution": {"constant": 0.9}, "t_end": 20.0,
                       "output_times": {"list": [1.0, 10.0]}}
        }),
    );
    let out = dir.path().join("c");
    let _g = util::heavy();
    let run = std::process::Command::new(util::bin())
        .args([
            "run",
            s(&m),
            "--out",
            s(&out),
            "--progress-json",
            "--threads",
            "2",
        ])
        .stdin(std::process::Stdio::null())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr).into_owned();
    assert_eq!(run.status.code(), Some(0), "{stderr}");
    // Besides the logs, not instead of them.
    assert!(stderr.contains("starting"), "{stderr}");
    assert_progress(&progress_lines(&stderr), 3, &stderr);
    // Nothing on stdout.
    assert!(
        run.stdout.is_empty(),
        "{}",
        String::from_utf8_lossy(&run.stdout)
    );

    // resume of the finished campaign: nothing planned, at once complete.
    let resume = std::process::Command::new(util::bin())
        .args(["resume", s(&out), "--progress-json"])
        .stdin(std::process::Stdio::null())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&resume.stderr).into_owned();
    assert_eq!(resume.status.code(), Some(0), "{stderr}");
    let lines = progress_lines(&stderr);
    let end = lines
        .last()
        .unwrap_or_else(|| panic!("no progress line: {stderr}"));
    assert_eq!(end["total"], 0, "{stderr}");
    assert_eq!(end["fraction"], 1.0, "{stderr}");
}
