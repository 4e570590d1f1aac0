//! Data-driven manifest validation.
//!
//! `tests/manifests/good/*.json` must validate. Each `tests/manifests/bad/X.json` has a
//! sibling `X.expected` with one `PATH: substring` line per error that must be reported
//! (blank lines and `#` comments are ignored; `/` stands for the empty JSON pointer, i.e. the
//! whole document). The path must match exactly and the message must contain the substring;
//! all of them must come from one validation (every error is reported at once).

use std::fs;
use std::path::{Path, PathBuf};
use std::time::Duration;

use granular::campaign::plan::load as load_manifest;

use super::util::{self, repo_root};

fn json_files(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .collect();
    v.sort();
    v
}

/// (path, substring) pairs of an `.expected` file.
fn expected_errors(path: &Path) -> Vec<(String, String)> {
    let text = fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e} (every bad manifest needs one)", path.display()));
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let (p, msg) = line.split_once(": ").unwrap_or_else(|| {
            panic!(
                "{}:{}: expected `PATH: substring`, got {line:?}",
                path.display(),
                n + 1
            )
        });
        let p = if p == "/" {
            String::new()
        } else {
            p.to_string()
        };
        out.push((p, msg.to_string()));
    }
    assert!(
        !out.is_empty(),
        "{}: lists no expected error",
        path.display()
    );
    out
}

#[test]
fn good_manifests_validate() {
    let files = json_files(&repo_root().join("tests/manifests/good"));
    assert!(
        files.len() >= 3,
        "expected the good manifests in tests/manifests/good"
    );
    let mut failures = Vec::new();
    for f in &files {
        match load_manifest(f) {
            Ok((m, plan)) => {
                assert!(plan.n_runs() >= 1, "{}: no runs", f.display());
                assert_eq!(
                    plan.n_runs(),
                    plan.points.len() as u64 * m.replicas.unwrap_or(1) as u64
                );
            }
            Err(e) => failures.push(e.to_string()),
        }
    }
    assert!(
        failures.is_empty(),
        "good manifests rejected:\n{}",
        failures.join("\n")
    );
}

/// Each error once: an error of the base params is not repeated for every sweep value (at
/// 421c2bb `volume` and `number_density` together, swept over 3 restitution values, gave 4
/// errors: the base's and "with this value, ..." at each value), while a sweep value's own
/// error is still reported at that value.
#[test]
fn an_error_of_the_base_params_is_reported_once() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.json");
    util::write_json(
        &path,
        &serde_json::json!({
            "name": "once", "model": "dsmc", "seed": 1,
            "params": {"method": "low_rank",
                       "species": {"list": [{"mass": 1, "diameter": 1, "count": 10}]},
                       "number_density": 0.1, "volume": 10,
                       "restitution": {"constant": 0.5}, "t_end": 1.0},
            "sweep": {"restitution.constant": [0.1, 0.2, 7.0]}
        }),
    );
    let e = load_manifest(&path).unwrap_err();
    let both: Vec<_> = e
        .errors
        .iter()
        .filter(|x| x.message.contains("not both"))
        .collect();
    assert_eq!(both.len(), 1, "{e}");
    assert_eq!(both[0].path, "/params/number_density", "{e}");
    assert!(
        e.errors
            .iter()
            .any(|x| x.path == "/sweep/restitution.constant/2"),
        "{e}"
    );
    assert_eq!(e.errors.len(), 2, "{e}");
}

/// A schema error does not hide the checks the schema cannot express, and nothing left out to
/// run them is reported as an error of its own: the fixture's unknown observable and its
/// `volume` beside `number_density`, exactly those two (421c2bb: the observable only).
#[test]
fn schema_errors_and_checks_are_reported_together_each_once() {
    let f = repo_root().join("tests/manifests/bad/all_at_once_schema_and_checks.json");
    let e = load_manifest(&f).unwrap_err();
    let paths: Vec<&str> = e.errors.iter().map(|x| x.path.as_str()).collect();
    assert_eq!(
        paths,
        vec!["/params/observables/0", "/params/number_density"],
        "{e}"
    );
}

/// A missing required parameter (or one left out for its own error, like a restitution of the
/// wrong form) does not hide the other errors: the checks run with a stand-in made from the
/// schema, and none of the stand-in's consequences is reported (97f6d98: the bad sweep value
/// and the bad initial temperature went unreported while `t_end` was missing, or `species`;
/// a stand-in `t_end` of 1 must not give "output time after t_end").
#[test]
fn a_missing_required_parameter_hides_no_other_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.json");
    let base = serde_json::json!({
        "name": "req", "model": "dsmc", "seed": 1,
        "params": {"method": "low_rank",
                   "species": {"power_law": {"n1": 0.1, "N1": 2000, "theta": 3}},
                   "restitution": 0.8, "initial_temperature": 1.0,
                   "output_times": {"log": {"from": 0.01, "to": 10.0, "per_decade": 5}}},
        "sweep": {"method": ["low_rank", "nope"]}
    });
    util::write_json(&path, &base);
    let e = load_manifest(&path).unwrap_err();
    let paths: Vec<&str> = e.errors.iter().map(|x| x.path.as_str()).collect();
    assert_eq!(
        paths,
        vec!["/params/restitution", "/params", "/sweep/method/1"],
        "{e}"
    );
    assert!(e.errors[1].message.contains("\"t_end\""), "{e}");
    // Without `species`: its absence and the sweep value's error.
    let mut m = base.clone();
    m["params"]["t_end"] = serde_json::json!(10.0);
    m["params"]["restitution"] = serde_json::json!({"constant": 0.5});
    m["params"].as_object_mut().unwrap().remove("species");
    util::write_json(&path, &m);
    let e = load_manifest(&path).unwrap_err();
    let paths: Vec<&str> = e.errors.iter().map(|x| x.path.as_str()).collect();
    assert_eq!(paths, vec!["/params", "/sweep/method/1"], "{e}");
}

#[test]
fn bad_manifests_report_every_expected_error() {
    let files = json_files(&repo_root().join("tests/manifests/bad"));
    assert!(
        files.len() >= 10,
        "expected the bad manifests in tests/manifests/bad"
    );
    let mut failures = Vec::new();
    for f in &files {
        let expected = expected_errors(&f.with_extension("expected"));
        let errors = match load_manifest(f) {
            Ok(_) => {
                failures.push(format!(
                    "{}: accepted, expected {} error(s)",
                    f.display(),
                    expected.len()
                ));
                continue;
            }
            Err(e) => e,
        };
        let missing: Vec<String> = expected
            .iter()
            .filter(|(p, sub)| {
                !errors
                    .errors
                    .iter()
                    .any(|e| &e.path == p && e.message.contains(sub.as_str()))
            })
            .map(|(p, sub)| format!("    {}: ...{sub}...", if p.is_empty() { "/" } else { p }))
            .collect();
        if !missing.is_empty() {
            failures.push(format!(
                "{}: missing expected error(s):\n{}\n  reported:\n{}",
                f.display(),
                missing.join("\n"),
                errors
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "{} bad manifest(s) not reported as expected:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

/// The library reports every error with a path; the CLI `validate` exits 2 and prints them.
#[test]
fn validate_cli_exits_2_and_prints_paths() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let bad = repo_root().join("tests/manifests/bad/several_errors.json");
    let (code, _) = util::run_capture(&["validate", bad.to_str().unwrap()], &log);
    assert_eq!(code, Some(2), "log:\n{}", util::log_text(&log));
    let text = util::log_text(&log);
    for p in [
        "/replicas",
        "/extra",
        "/params/restitution/constant",
        "/sweep/restitution.value",
    ] {
        assert!(
            text.contains(&format!("at {p}: ")),
            "validate output lacks {p}:\n{text}"
        );
    }
    let good = repo_root().join("tests/manifests/good/power_law_sweep.json");
    let (code, out) = util::run_capture(&["validate", good.to_str().unwrap()], &log);
    assert_eq!(code, Some(0), "log:\n{}", util::log_text(&log));
    assert!(out.contains("4 points x 2 replicas = 8 runs"), "{out}");
}

/// `granular run` with a bad manifest exits 2 and writes nothing: neither a missing --out nor
/// an existing empty one gets any file.
#[test]
fn run_with_bad_manifest_exits_2_and_creates_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let bad_dir = repo_root().join("tests/manifests/bad");
    for name in [
        "several_errors.json",
        "duplicate_sweep_values.json",
        "not_json.json",
        "output_times_beyond_swept_t_end.json",
    ] {
        let manifest = bad_dir.join(name);
        let missing = dir.path().join(format!("out-missing-{name}"));
        let code = util::run_granular(
            &[
                "run",
                manifest.to_str().unwrap(),
                "--out",
                missing.to_str().unwrap(),
                "--threads",
                "1",
                "--quiet",
            ],
            &log,
            Duration::from_secs(60),
        );
        assert_eq!(code, Some(2), "{name}: log:\n{}", util::log_text(&log));
        assert!(
            !missing.exists(),
            "{name}: run created {}",
            missing.display()
        );

        let empty = dir.path().join(format!("out-empty-{name}"));
        fs::create_dir(&empty).unwrap();
        let code = util::run_granular(
            &[
                "run",
                manifest.to_str().unwrap(),
                "--out",
                empty.to_str().unwrap(),
                "--threads",
                "1",
                "--quiet",
            ],
            &log,
            Duration::from_secs(60),
        );
        assert_eq!(code, Some(2), "{name}: log:\n{}", util::log_text(&log));
        let left: Vec<_> = fs::read_dir(&empty)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        assert!(
            left.is_empty(),
            "{name}: run wrote into the empty --out: {left:?}"
        );
    }
}

/// What a run of the parameters would fail on (the engine's limits) and what no machine could
/// hold or finish is refused by `validate` (exit 2) and by `run` before it writes anything.
/// Before: `validate` accepted all but the float count, and `run` failed (exit 1, a campaign
/// directory left behind), ran out of memory or hung; the `bounds_*` of physical scales,
/// viscoelastic beta, the theory's cost and the runs' work were accepted, and `run` panicked
/// (n1 = 1e308: exit 101 in the theory, a directory left behind; a cascade placement's cell
/// grid), ran for minutes in the theory (a_kappa = 1e10) or never ended; `validate` itself
/// panicked on an RFM box of 1e308.
#[test]
fn validate_and_run_refuse_what_a_run_could_not_do() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    for name in [
        "bounds_particles_power_law",
        "bounds_particles_list",
        "bounds_species",
        "bounds_rfm_packing_uniform",
        "bounds_rfm_packing_square",
        "bounds_t_end_collision_times",
        "bounds_output_times",
        "bounds_runs",
        "bounds_runs_seeds",
        "bounds_sweep_points",
        "integer_written_as_float_in_params",
        // Inputs that overflowed, panicked or never ended (issue: bounded inputs).
        "bounds_n1_overflow",
        "bounds_viscoelastic_beta",
        "bounds_theory_cost",
        "bounds_dsmc_scales",
        "bounds_temperature_ratio",
        "bounds_power_law_one_particle",
        "bounds_rfm_scales",
        "bounds_bisection_work",
        "bounds_cascade_placement",
        "bounds_spm_walks",
    ] {
        let manifest = repo_root().join(format!("tests/manifests/bad/{name}.json"));
        let m = manifest.to_str().unwrap();
        let code = util::run_granular(&["validate", m], &log, Duration::from_secs(60));
        assert_eq!(
            code,
            Some(2),
            "validate {name}: log:\n{}",
            util::log_text(&log)
        );
        let out = dir.path().join(format!("out-{name}"));
        let code = util::run_granular(
            &["run", m, "--out", out.to_str().unwrap(), "--quiet"],
            &log,
            Duration::from_secs(60),
        );
        assert_eq!(code, Some(2), "run {name}: log:\n{}", util::log_text(&log));
        assert!(!out.exists(), "run {name} created {}", out.display());
    }
}

/// A manifest whose kinetic theory is long (400 species with msd: ~200 CPU s estimated) is
/// valid, with a warning that gives the estimate, from `validate` and `plan` (and `run`,
/// before it computes the theory); a short one gets none. Before: no estimate anywhere.
#[test]
fn a_long_kinetic_theory_is_estimated_and_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let species: Vec<serde_json::Value> = (1..=400)
        .map(|k| {
            let k = k as f64;
            serde_json::json!({"mass": k, "diameter": k.cbrt(), "count": 2})
        })
        .collect();
    let mut m = serde_json::json!({
        "name": "long-theory", "model": "dsmc", "seed": 1,
        "params": {"method": "low_rank", "species": {"list": species}, "number_density": 0.1,
                   "restitution": {"constant": 0.5}, "t_end": 1e9,
                   "output_times": {"log": {"from": 0.01, "to": 1e9, "per_decade": 2}},
                   "observables": ["msd"]}
    });
    let path = dir.path().join("m.json");
    util::write_json(&path, &m);
    let (code, _) = util::run_capture(&["validate", path.to_str().unwrap()], &log);
    assert_eq!(code, Some(0), "log:\n{}", util::log_text(&log));
    let text = util::log_text(&log);
    assert!(
        text.contains("the kinetic theory, computed before the runs, is estimated at ~")
            && text.contains("CPU s for 1 point(s)"),
        "{text}"
    );
    let out = dir.path().join("c");
    let (code, stdout) = util::run_capture(
        &[
            "plan",
            path.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
        &log,
    );
    assert_eq!(code, Some(0), "log:\n{}", util::log_text(&log));
    assert!(
        stdout.contains("kinetic theory of the new points (before the runs): ~"),
        "{stdout}"
    );
    assert!(util::log_text(&log).contains("is estimated at ~"));
    assert!(!out.exists(), "plan wrote {}", out.display());
    // Two species: no warning.
    m["params"]["species"]["list"] = serde_json::json!([
        {"mass": 1, "diameter": 1, "count": 10}, {"mass": 2, "diameter": 1.2, "count": 10}]);
    util::write_json(&path, &m);
    fs::write(&log, "").unwrap();
    let (code, _) = util::run_capture(&["validate", path.to_str().unwrap()], &log);
    assert_eq!(code, Some(0));
    assert!(
        !util::log_text(&log).contains("kinetic theory"),
        "{}",
        util::log_text(&log)
    );
}

/// A manifest file is read up to 16 MiB (+1 byte): a larger file, or one without end, is
/// refused at once with exit 2 (before: `validate /dev/zero` read without end).
#[test]
fn oversized_and_endless_manifest_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let big = dir.path().join("big.json");
    let mut text = String::from("{\"name\": \"x\", \"description\": \"");
    text.push_str(&"a".repeat(16 << 20));
    text.push_str("\"}");
    fs::write(&big, text).unwrap();
    let mut files = vec![big.to_str().unwrap().to_string()];
    if Path::new("/dev/zero").exists() {
        files.push("/dev/zero".into());
    }
    for f in &files {
        let (code, _) = util::run_capture(&["validate", f], &log);
        assert_eq!(
            code,
            Some(2),
            "validate {f}: log:\n{}",
            util::log_text(&log)
        );
        let text = util::log_text(&log);
        assert!(text.contains("larger than 16 MiB"), "{f}:\n{text}");
    }
}

/// A UTF-8 byte-order mark before the JSON (some editors write one) is skipped (before:
/// "expected value at line 1 column 1").
#[test]
fn a_byte_order_mark_is_accepted() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let good = fs::read(repo_root().join("tests/manifests/good/power_law_sweep.json")).unwrap();
    let bom = dir.path().join("bom.json");
    fs::write(&bom, [b"\xef\xbb\xbf".as_slice(), &good].concat()).unwrap();
    let (code, out) = util::run_capture(&["validate", bom.to_str().unwrap()], &log);
    assert_eq!(code, Some(0), "log:\n{}", util::log_text(&log));
    assert!(out.contains("4 points x 2 replicas = 8 runs"), "{out}");
    let (m, _) = load_manifest(&bom).expect("the library accepts it too");
    assert_eq!(m.name, "good-power-law-sweep");
}

/// A key given twice in one object (serde_json keeps the last one silently) is refused by
/// every command that reads a manifest (validate, plan, run, run --dry-run, theory, submit),
/// exit 2, every duplicate at its object's JSON path, nothing written (before: accepted with
/// the last values, exit 0, and `run` ran the campaign).
#[test]
fn duplicate_keys_are_refused_by_every_command() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let f = repo_root().join("tests/manifests/bad/duplicate_keys.json");
    let f = f.to_str().unwrap();
    let out = dir.path().join("out");
    let o = out.to_str().unwrap();
    let submit = [
        "submit",
        f,
        "--out",
        o,
        "--slurm",
        "--tasks",
        "1",
        "--per-task-runs",
        "1",
        "--time",
        "5",
    ];
    let commands: Vec<Vec<&str>> = vec![
        vec!["validate", f],
        vec!["plan", f, "--out", o],
        vec!["plan", f, "--out", o, "--json"],
        vec!["run", f, "--out", o, "--quiet"],
        vec!["run", f, "--out", o, "--dry-run"],
        vec!["theory", f, "--out", o],
        submit.to_vec(),
        [&submit[..], &["--dry-run"]].concat(),
    ];
    for args in commands {
        let _ = fs::remove_file(&log);
        let (code, stdout) = util::run_capture(&args, &log);
        let text = util::log_text(&log);
        assert_eq!(
            code,
            Some(2),
            "{args:?}: stdout:\n{stdout}\nstderr:\n{text}"
        );
        for want in [
            "invalid manifest (4 errors)",
            "at /: duplicate key \"seed\"",
            "at /params/species/list/1: duplicate key \"mass\"",
            "at /params/restitution: duplicate key \"constant\"",
            "at /sweep: duplicate key \"restitution.constant\"",
        ] {
            assert!(
                text.contains(want),
                "{args:?}: stderr lacks {want:?}:\n{text}"
            );
        }
        assert!(!out.exists(), "{args:?} created {}", out.display());
    }
}
