//! Campaigns that grow: a manifest with more replicas, more sweep values, a new sweep key or a
//! longer `t_end` run into an existing campaign directory runs only what is new, never rewrites
//! a finished run's rows, and ends bit for bit equal (run for run, keyed by params and
//! replica) to a campaign started straight from the final manifest; a longer run continues
//! from the shorter run's final state. Refused growth changes nothing. A campaign directory of
//! format 1 (the version before growth) is upgraded in place and continued.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use serde_json::{json, Value};

use super::util::s;
use super::util::{
    self, assert_same_current, assert_same_current_except, heavy, log_text, read_all, read_table,
    run_capture, run_granular, Cell, Table,
};

/// Upper bound on any single `granular` process of these tests (a hang is a failure).
const LIMIT: Duration = Duration::from_secs(300);

/// Bytes of every Parquet file under `tables/`, by path relative to `tables/`.
fn table_files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    for (t, _) in read_all(dir) {
        let d = dir.join("tables").join(&t);
        for e in fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            let n = p.file_name().unwrap().to_string_lossy().into_owned();
            if n.ends_with(".parquet") && !n.starts_with('.') {
                out.insert(format!("{t}/{n}"), fs::read(&p).unwrap());
            }
        }
    }
    out
}

/// The committed part files of the raw tables (runs, model rows): a grown campaign never
/// rewrites them. (Summaries, theory and points are whole-table files that growth adds to or
/// rewrites.)
fn committed_parts(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    table_files(dir)
        .into_iter()
        .filter(|(k, _)| k.contains("/part-"))
        .collect()
}

/// `granular plan MANIFEST --out DIR --json`.
fn plan(m: &Path, dir: &Path, log: &Path) -> Value {
    let (code, out) = run_capture(&["plan", s(m), "--out", s(dir), "--json"], log);
    assert_eq!(
        code,
        Some(0),
        "plan {}: log:\n{}",
        m.display(),
        log_text(log)
    );
    serde_json::from_str(&out).unwrap()
}

fn run_ok(m: &Path, dir: &Path, log: &Path) {
    let code = run_granular(
        &[
            "run",
            s(m),
            "--out",
            s(dir),
            "--threads",
            "2",
            "--quiet",
            "--flush-every",
            "0",
        ],
        log,
        LIMIT,
    );
    assert_eq!(
        code,
        Some(0),
        "run {}: log:\n{}",
        m.display(),
        log_text(log)
    );
}

/// The number of rows of `runs` (finished runs).
fn n_runs(dir: &Path) -> usize {
    read_table(dir, "runs").rows.len()
}

/// A small DSMC campaign: 2 restitution values x 2 replicas of ~2400 particles with MSD,
/// t_end = 10 (outputs 1, 5, 10).
fn dsmc_base() -> Value {
    json!({
        "name": "grow",
        "model": "dsmc",
        "seed": 99,
        "replicas": 2,
        "params": {
            "method": "low_rank",
            "species": {"power_law": {"n1": 0.1, "N1": 2000, "theta": 3}},
            "restitution": {"constant": 0.7},
            "t_end": 10.0,
            "output_times": {"list": [1.0, 5.0]},
            "observables": ["msd"]
        },
        "sweep": {"restitution.constant": [0.5, 0.7]}
    })
}

/// The manifests of a campaign that grows step by step: more replicas; one more restitution
/// value; a new sweep key (the existing points keep the old fixed method); a longer t_end
/// (the old end stays an output, so every finished run continues); and, for each step, how
/// many runs it adds and how many of them continue a finished run.
fn dsmc_steps() -> Vec<(&'static str, Value, u64, u64)> {
    let a = dsmc_base();
    let mut b = a.clone();
    b["replicas"] = json!(3);
    let mut c = b.clone();
    c["sweep"]["restitution.constant"] = json!([0.5, 0.7, 0.9]);
    let mut d = c.clone();
    d["sweep"]["method"] = json!(["low_rank", "bird"]);
    let mut e = d.clone();
    e["params"]["t_end"] = json!(25.0);
    e["params"]["output_times"]["list"] = json!([1.0, 5.0, 10.0, 20.0]);
    vec![
        ("more replicas", b, 2, 0),
        ("one more sweep value", c, 3, 0),
        ("a new sweep key", d, 9, 0),
        ("a longer t_end", e, 18, 18),
    ]
}

/// A DSMC campaign grown in four steps equals, run for run and bit for bit, the campaign of
/// its final manifest; each step runs only its new runs, writes nothing over committed parts,
/// keeps the manifest history; the longer t_end continues every run from its final state.
#[test]
fn dsmc_growth_equals_a_direct_campaign() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let grown = dir.path().join("grown");
    let m0 = dir.path().join("m0.json");
    util::write_json(&m0, &dsmc_base());
    run_ok(&m0, &grown, &log);
    assert_eq!(n_runs(&grown), 4);
    let mut total = 4;
    for (k, (what, m, new_runs, continued)) in dsmc_steps().into_iter().enumerate() {
        let path = dir.path().join(format!("m{}.json", k + 1));
        util::write_json(&path, &m);
        let p = plan(&path, &grown, &log);
        assert_eq!(p["new_runs"], json!(new_runs), "{what}: plan {p:#}");
        assert_eq!(p["continued_runs"], json!(continued), "{what}: plan {p:#}");
        assert_eq!(p["to_run"], json!(new_runs), "{what}: plan {p:#}");
        assert_eq!(
            p["runs"].as_array().unwrap().len() as u64,
            new_runs,
            "{what}"
        );
        let parts_before = committed_parts(&grown);
        run_ok(&path, &grown, &log);
        total += new_runs as usize;
        assert_eq!(n_runs(&grown), total, "{what}: finished runs");
        let parts_after = committed_parts(&grown);
        for (f, bytes) in &parts_before {
            assert!(
                parts_after.get(f) == Some(bytes),
                "{what}: committed part {f} was rewritten or removed"
            );
        }
        // The same manifest again adds nothing.
        let p = plan(&path, &grown, &log);
        assert_eq!(
            (p["new_runs"].as_u64(), p["to_run"].as_u64()),
            (Some(0), Some(0))
        );
    }
    assert!(
        !log_text(&log).contains("cannot continue"),
        "a run was rerun instead of continued:\n{}",
        log_text(&log)
    );
    // Every run of the last step continued one of t_end = 10 (whose final states are gone:
    // the longer runs' replace them).
    let runs = read_table(&grown, "runs");
    let cont = runs.col("continued_from");
    let continued: Vec<u64> = runs
        .rows
        .iter()
        .filter(|r| r[cont] != Cell::Null)
        .map(|r| r[cont].as_u64())
        .collect();
    assert_eq!(continued.len(), 18);
    let finals: BTreeSet<String> = fs::read_dir(grown.join("finals"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(finals.len(), 18, "{finals:?}");
    for old in &continued {
        assert!(!finals.contains(&format!("run-{old:010}.final")));
    }
    // History: five manifests, the latest frozen.
    let info: Value =
        serde_json::from_slice(&fs::read(grown.join("campaign.json")).unwrap()).unwrap();
    assert_eq!(info["history"].as_array().unwrap().len(), 5);
    for k in 0..5 {
        assert!(grown.join(format!("manifests/{k}.json")).exists());
    }
    // Points no longer asked for (t_end = 10) are kept and listed as such.
    let st = util::status_json(&grown, &log);
    let points = st["points"].as_array().unwrap();
    assert_eq!(points.len(), 12);
    let retired = points
        .iter()
        .filter(|p| p["in_manifest"] == json!(false))
        .count();
    assert_eq!(retired, 6);
    assert!(points.iter().all(|p| p["done"] == json!(3)), "{st:#}");
    // Summaries cover the points of the latest manifest only (issue 22: as a direct campaign
    // of it would); the retired points keep their rows in the raw tables.
    let summary = read_table(&grown, "dsmc_species_summary");
    let ids: BTreeSet<u64> = summary
        .column("point_id")
        .iter()
        .map(|c| c.as_u64())
        .collect();
    assert_eq!(ids.len(), 6);
    let raw: BTreeSet<u64> = read_table(&grown, "dsmc_species")
        .column("point_id")
        .iter()
        .map(|c| c.as_u64())
        .collect();
    assert_eq!(raw.len(), 12, "rows of every point are kept");
    let theory = read_table(&grown, "dsmc_theory_point");
    assert_eq!(theory.rows.len(), 12, "one theory row per point");

    // The campaign of the final manifest, started directly.
    let direct = dir.path().join("direct");
    run_ok(&dir.path().join("m4.json"), &direct, &log);
    assert_same_current(&grown, &direct, "grown vs direct");
    // verify is clean on the grown campaign, and stays so after a compaction, which changes
    // no row.
    for cmd in [
        vec!["verify", s(&grown)],
        vec!["compact", s(&grown)],
        vec!["verify", s(&grown)],
    ] {
        assert_eq!(
            run_granular(&cmd, &log, LIMIT),
            Some(0),
            "{cmd:?}: {}",
            log_text(&log)
        );
    }
    assert_same_current(&grown, &direct, "grown and compacted vs direct");
}

/// Replay one run: a manifest that gives a run's seed (`seeds`) and its point's params runs
/// it again bit for bit, in another campaign with another campaign seed, and with one more
/// observable (the displacements do not change the trajectory: the temperatures and
/// collision counts are the same bits).
#[test]
fn a_run_replayed_from_its_seed_and_params() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let c = dir.path().join("c");
    let mut m = dsmc_base();
    m["params"]["observables"] = json!(["temperature"]);
    let mp = dir.path().join("m.json");
    util::write_json(&mp, &m);
    run_ok(&mp, &c, &log);
    let runs = read_table(&c, "runs");
    let points = read_table(&c, "points");
    // Run 3: point 1, replica 1.
    let r = runs
        .rows
        .iter()
        .find(|r| r[runs.col("run_id")].as_u64() == 3)
        .unwrap();
    let seed = r[runs.col("seed")].as_u64();
    let pid = r[runs.col("point_id")].as_u64();
    let prow = points
        .rows
        .iter()
        .find(|p| p[points.col("point_id")].as_u64() == pid)
        .unwrap();
    let params: Value = serde_json::from_str(prow[points.col("params")].as_str()).unwrap();
    let species = read_table(&c, "dsmc_species");
    let rows_of = |t: &Table, run: u64, cols: &[&str]| -> Vec<Vec<Cell>> {
        let idx: Vec<usize> = cols.iter().map(|c| t.col(c)).collect();
        let mut v: Vec<Vec<Cell>> = t
            .rows
            .iter()
            .filter(|row| row[t.col("run_id")].as_u64() == run)
            .map(|row| idx.iter().map(|&j| row[j].clone()).collect())
            .collect();
        v.sort();
        v
    };
    let cols = ["t", "species", "temperature", "collisions"];
    let want = rows_of(&species, 3, &cols);
    assert!(!want.is_empty());
    for (k, observables) in [json!(["temperature"]), json!(["temperature", "msd"])]
        .iter()
        .enumerate()
    {
        let mut p = params.clone();
        p["observables"] = observables.clone();
        let replay = json!({"name": format!("replay{k}"), "model": "dsmc", "seed": 1,
                            "seeds": [seed], "params": p});
        let rp = dir.path().join(format!("replay{k}.json"));
        util::write_json(&rp, &replay);
        let out = dir.path().join(format!("replay{k}"));
        run_ok(&rp, &out, &log);
        let got = read_table(&out, "dsmc_species");
        assert_eq!(rows_of(&got, 0, &cols), want, "replay with {observables}");
        let rr = read_table(&out, "runs");
        assert_eq!(rr.column("seed"), vec![&Cell::U(seed)]);
        assert_eq!(rr.column("trials"), vec![&r[runs.col("trials")]]);
    }
}

/// Given seeds: a run is its point and seed; more seeds add only their runs, and the result
/// equals the campaign started with all the seeds.
#[test]
fn given_seeds_grow_like_replicas() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let mut a = dsmc_base();
    a.as_object_mut().unwrap().remove("replicas");
    a["seeds"] = json!([5, 17]);
    let mut b = a.clone();
    b["seeds"] = json!([5, 17, 23]);
    let (ma, mb) = (dir.path().join("a.json"), dir.path().join("b.json"));
    util::write_json(&ma, &a);
    util::write_json(&mb, &b);
    let grown = dir.path().join("grown");
    run_ok(&ma, &grown, &log);
    let p = plan(&mb, &grown, &log);
    assert_eq!(p["new_runs"], json!(2), "{p:#}");
    run_ok(&mb, &grown, &log);
    let runs = read_table(&grown, "runs");
    let seeds: BTreeSet<u64> = runs.column("seed").iter().map(|c| c.as_u64()).collect();
    assert_eq!(seeds, BTreeSet::from([5, 17, 23]));
    assert_eq!(runs.rows.len(), 6);
    let direct = dir.path().join("direct");
    run_ok(&mb, &direct, &log);
    assert_same_current(&grown, &direct, "given seeds");
    // Both a seed list and replicas: refused before anything is written.
    let mut both = b.clone();
    both["replicas"] = json!(2);
    let mboth = dir.path().join("both.json");
    util::write_json(&mboth, &both);
    let before = util::snapshot(&grown);
    let code = run_granular(
        &["run", s(&mboth), "--out", s(&grown), "--quiet"],
        &log,
        LIMIT,
    );
    assert_eq!(code, Some(2), "log:\n{}", log_text(&log));
    assert!(
        util::snapshot(&grown) == before,
        "a refused manifest changed the directory"
    );
}

/// An RFM campaign grows by replicas and then by a longer duration (40 -> 85 samples: the 10
/// blocks of the errors move): the longer runs continue the finished ones from their final
/// states, and the campaign equals the one of the final manifest.
#[test]
fn rfm_growth_equals_a_direct_campaign() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let a = json!({
        "name": "grow-rfm",
        "model": "rfm",
        "seed": 5,
        "replicas": 1,
        "params": {
            "dim": 2, "n_particles": 40, "packing_fraction": 0.3,
            "warmup": 0.002, "duration": 0.02, "sample_every": 500,
            "observables": ["temperature", "velocity_moments", "structure_factor",
                            "radial_distribution", "free_paths"],
            "structure_factor": {"k_max": 5, "every": 2},
            "radial_distribution": {"bins": 20, "every": 3}
        },
        "sweep": {"n_particles": [30, 40]}
    });
    let mut b = a.clone();
    b["replicas"] = json!(2);
    let mut c = b.clone();
    c["params"]["duration"] = json!(0.0425);
    let grown = dir.path().join("grown");
    let paths: Vec<PathBuf> = (0..3)
        .map(|k| dir.path().join(format!("r{k}.json")))
        .collect();
    for (p, m) in paths.iter().zip([&a, &b, &c]) {
        util::write_json(p, m);
    }
    run_ok(&paths[0], &grown, &log);
    run_ok(&paths[1], &grown, &log);
    assert_eq!(n_runs(&grown), 4);
    let p = plan(&paths[2], &grown, &log);
    assert_eq!(
        (p["new_runs"].as_u64(), p["continued_runs"].as_u64()),
        (Some(4), Some(4))
    );
    assert_eq!(p["notes"], json!([]), "{p:#}");
    run_ok(&paths[2], &grown, &log);
    assert_eq!(n_runs(&grown), 8);
    assert!(
        !log_text(&log).contains("cannot continue"),
        "{}",
        log_text(&log)
    );
    let runs = read_table(&grown, "runs");
    let cont = runs.col("continued_from");
    assert_eq!(
        runs.rows.iter().filter(|r| r[cont] != Cell::Null).count(),
        4
    );
    let direct = dir.path().join("direct");
    run_ok(&paths[2], &direct, &log);
    assert_same_current(&grown, &direct, "rfm grown vs direct");
}

/// Growth that is refused leaves the directory as it was: another name, model or seed; a
/// shorter t_end; an invalid manifest; a manifest accepted while a shard runs. `plan` and
/// `run --dry-run` write nothing.
#[test]
fn refused_growth_changes_nothing() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let c = dir.path().join("c");
    let m = dir.path().join("m.json");
    util::write_json(&m, &dsmc_base());
    run_ok(&m, &c, &log);
    let mut cases: Vec<(&str, Value, i32, &str)> = Vec::new();
    let mut x = dsmc_base();
    x["seed"] = json!(100);
    cases.push(("another seed", x, 3, "holds another campaign"));
    let mut x = dsmc_base();
    x["name"] = json!("other");
    cases.push(("another name", x, 3, "holds another campaign"));
    let mut x = dsmc_base();
    x["params"]["t_end"] = json!(8.0);
    cases.push(("a shorter t_end", x, 3, "never shortens"));
    let mut x = dsmc_base();
    x["replicas"] = json!(0);
    cases.push(("no replicas", x, 2, "replicas"));
    let mut x = dsmc_base();
    x["sweep"]["restitution.constant"] = json!([0.5, 1.7]);
    cases.push(("a bad sweep value", x, 2, "restitution"));
    let before = util::snapshot(&c);
    for (what, m, code, says) in &cases {
        let path = dir.path().join("bad.json");
        util::write_json(&path, m);
        for cmd in [
            vec!["run", s(&path), "--out", s(&c), "--quiet"],
            vec!["plan", s(&path), "--out", s(&c)],
        ] {
            fs::write(&log, "").unwrap();
            let got = run_granular(&cmd, &log, LIMIT);
            assert_eq!(
                got,
                Some(*code),
                "{what}: {cmd:?}: log:\n{}",
                log_text(&log)
            );
            assert!(log_text(&log).contains(says), "{what}: {}", log_text(&log));
            assert!(
                util::snapshot(&c) == before,
                "{what}: {cmd:?} changed the directory"
            );
        }
    }
    // A valid growth previewed writes nothing either.
    let mut grow = dsmc_base();
    grow["replicas"] = json!(3);
    let g = dir.path().join("grow.json");
    util::write_json(&g, &grow);
    let code = run_granular(&["run", s(&g), "--out", s(&c), "--dry-run"], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let code = run_granular(&["plan", s(&g), "--out", s(&c)], &log, LIMIT);
    assert_eq!(code, Some(0));
    assert!(
        util::snapshot(&c) == before,
        "plan or --dry-run changed the directory"
    );
    // While a shard runs, the campaign cannot change.
    let mut slow = dsmc_base();
    slow["params"]["species"]["power_law"]["N1"] = json!(60000);
    slow["params"]["t_end"] = json!(2000.0);
    slow["params"]["restitution"]["constant"] = json!(0.99);
    slow["name"] = json!("slow");
    let slow_m = dir.path().join("slow.json");
    util::write_json(&slow_m, &slow);
    let sc = dir.path().join("slow");
    let mut child = util::granular(
        &[
            "run",
            s(&slow_m),
            "--out",
            s(&sc),
            "--threads",
            "1",
            "--quiet",
        ],
        &log,
    )
    .spawn()
    .unwrap();
    let t0 = std::time::Instant::now();
    let live = |d: &Path| {
        d.join("campaign.json").exists()
            && util::status_json(d, &log)["live_shards"]
                .as_array()
                .is_some_and(|a| !a.is_empty())
    };
    while !live(&sc) {
        assert!(t0.elapsed() < LIMIT, "the slow campaign never started");
        std::thread::sleep(Duration::from_millis(20));
    }
    let mut more = slow.clone();
    more["replicas"] = json!(3);
    let more_m = dir.path().join("more.json");
    util::write_json(&more_m, &more);
    let info = fs::read(sc.join("campaign.json")).unwrap();
    fs::write(&log, "").unwrap();
    let code = run_granular(
        &["run", s(&more_m), "--out", s(&sc), "--quiet"],
        &log,
        LIMIT,
    );
    let _ = child.kill();
    let _ = child.wait();
    assert_eq!(code, Some(3), "log:\n{}", log_text(&log));
    assert!(
        log_text(&log).contains("cannot change the campaign"),
        "{}",
        log_text(&log)
    );
    assert_eq!(fs::read(sc.join("campaign.json")).unwrap(), info);
}

/// kill -9 at several moments of a grown run (a longer t_end, so runs continue from final
/// states, and more replicas), each followed by the same command: the tables end equal to the
/// direct campaign's.
#[test]
fn kill_9_during_growth_then_rerun_gives_the_direct_tables() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let mut a = dsmc_base();
    a["params"]["species"]["power_law"]["N1"] = json!(20000);
    a["params"]["t_end"] = json!(20.0);
    a["params"]["output_times"]["list"] = json!([1.0, 5.0, 10.0]);
    let mut b = a.clone();
    b["replicas"] = json!(3);
    b["params"]["t_end"] = json!(60.0);
    b["params"]["output_times"]["list"] = json!([1.0, 5.0, 10.0, 20.0, 40.0]);
    let (ma, mb) = (dir.path().join("a.json"), dir.path().join("b.json"));
    util::write_json(&ma, &a);
    util::write_json(&mb, &b);
    let direct = dir.path().join("direct");
    let t0 = std::time::Instant::now();
    run_ok(&mb, &direct, &log);
    let full = t0.elapsed().as_secs_f64();
    let c = dir.path().join("c");
    run_ok(&ma, &c, &log);
    let mut kills = 0;
    for frac in [0.0, 0.05, 0.2, 0.45, 0.7] {
        let mut child = util::granular(
            &[
                "run",
                s(&mb),
                "--out",
                s(&c),
                "--threads",
                "2",
                "--quiet",
                "--checkpoint-every",
                "0.05",
                "--flush-every",
                "0",
            ],
            &log,
        )
        .spawn()
        .unwrap();
        std::thread::sleep(Duration::from_secs_f64(frac * full));
        if child.try_wait().unwrap().is_none() {
            kills += 1;
        }
        let _ = child.kill();
        let _ = child.wait();
    }
    run_ok(&mb, &c, &log);
    assert!(
        kills >= 2,
        "only {kills} kills landed while running ({full:.2} s direct)"
    );
    assert_same_current(&c, &direct, "killed growth vs direct");
}

/// Two campaigns' tables hold the same rows (sorted), but for `runs.wall_seconds` and
/// `runs.code_version`.
fn assert_same_rows(a: &Path, b: &Path, what: &str) {
    let ignore = [("runs", "wall_seconds"), ("runs", "code_version")];
    let (tc, ti) = (read_all(a), read_all(b));
    assert_eq!(tc.keys().collect::<Vec<_>>(), ti.keys().collect::<Vec<_>>());
    for (name, t) in &tc {
        let u = &ti[name];
        assert_eq!(t.columns, u.columns, "{name}");
        let strip = |t: &Table| {
            let skip: Vec<usize> = ignore
                .iter()
                .filter(|(tt, _)| tt == name)
                .filter_map(|(_, c)| t.columns.iter().position(|x| x.0 == *c))
                .collect();
            let mut rows: Vec<Vec<Cell>> = t
                .rows
                .iter()
                .map(|r| {
                    let mut r = r.clone();
                    for &j in &skip {
                        r[j] = Cell::Null;
                    }
                    r
                })
                .collect();
            rows.sort();
            rows
        };
        assert!(strip(t) == strip(u), "{name}: {what}: rows differ");
    }
}

/// Unpack the committed fixture `tests/fixtures/<name>` into `dir`: its `complete/` and
/// `interrupted/` campaigns and their manifest `m.json`.
fn unpack_fixture(name: &str, dir: &Path) -> (PathBuf, PathBuf, PathBuf) {
    let tar = util::repo_root().join("tests/fixtures").join(name);
    let ok = Command::new("tar")
        .args(["xzf", s(&tar), "-C", s(dir)])
        .status()
        .unwrap();
    assert!(ok.success());
    (
        dir.join("complete"),
        dir.join("interrupted"),
        dir.join("m.json"),
    )
}

/// Each of `refused` exits 3 naming `granular upgrade d` and changes nothing; then `granular
/// upgrade d` succeeds, its log holds every one of `logged`, `campaign.json` is of format 3,
/// and a second upgrade changes nothing.
fn refused_then_upgraded(d: &Path, refused: &[Vec<&str>], logged: &[&str], log: &Path) {
    let before = util::snapshot(d);
    for cmd in refused {
        fs::write(log, "").unwrap();
        assert_eq!(run_granular(cmd, log, LIMIT), Some(3), "{}", log_text(log));
        assert!(
            log_text(log).contains(&format!("granular upgrade {}", d.display())),
            "{}",
            log_text(log)
        );
    }
    assert!(
        util::snapshot(d) == before,
        "a refused command changed {}",
        d.display()
    );
    assert_eq!(
        run_granular(&["upgrade", s(d)], log, LIMIT),
        Some(0),
        "{}",
        log_text(log)
    );
    let upgrade_log = fs::read_to_string(d.join("upgrade.log")).unwrap();
    assert!(
        logged.iter().all(|l| upgrade_log.contains(l)),
        "{upgrade_log}"
    );
    let info: Value = serde_json::from_slice(&fs::read(d.join("campaign.json")).unwrap()).unwrap();
    assert_eq!(info["format_version"], json!(3));
    let again = util::snapshot(d);
    assert_eq!(run_granular(&["upgrade", s(d)], log, LIMIT), Some(0));
    assert!(util::snapshot(d) == again, "a second upgrade changed files");
}

/// The interrupted fixture campaign resumed from its old checkpoint; the complete one resumed
/// too (it rewrites the old version's summaries, now with the sweep columns, and nothing
/// else); then both hold the same rows.
fn resume_fixtures(complete: &Path, interrupted: &Path, log: &Path, what: &str) {
    fs::write(log, "").unwrap();
    let code = run_granular(&["resume", s(interrupted), "--quiet"], log, LIMIT);
    assert_eq!(code, Some(0), "{}", log_text(log));
    assert!(
        !log_text(log).contains("restarting from t = 0"),
        "the old checkpoint was not resumed:\n{}",
        log_text(log)
    );
    fs::write(log, "").unwrap();
    let code = run_granular(&["resume", s(complete), "--quiet"], log, LIMIT);
    assert_eq!(code, Some(0), "{}", log_text(log));
    assert_eq!(
        read_table(complete, "dsmc_species_summary").columns[1].0,
        "method",
        "the rewritten summary has the sweep column"
    );
    assert_same_rows(complete, interrupted, what);
}

/// The fixtures' manifest grown by a third replica and t_end 3000 -> 3500 (the old end kept
/// as an output), written to `dir/grown.json`.
fn grown_fixture_manifest(m: &Path, dir: &Path) -> PathBuf {
    let mut grown: Value = serde_json::from_slice(&fs::read(m).unwrap()).unwrap();
    grown["replicas"] = json!(3);
    grown["params"]["t_end"] = json!(3500.0);
    grown["params"]["output_times"]["list"] = json!([1.0, 10.0, 100.0, 3000.0]);
    let mg = dir.join("grown.json");
    util::write_json(&mg, &grown);
    mg
}

/// The committed fixture `tests/fixtures/format1.tar.gz` (made by granular b2aa8d6, the
/// version before this format; see tests/fixtures/README.md): a complete campaign and the same
/// campaign interrupted (2 runs done, 1 checkpointed, 1 pending). The new binary refuses them
/// with the command that upgrades them; `granular upgrade` migrates them in place (logged);
/// the interrupted one then resumes from its old checkpoint to the complete one's tables; the
/// upgraded campaign grows, and its runs keep their format-1 seeds.
#[test]
fn format1_campaigns_upgrade_and_continue() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let (complete, interrupted, m) = unpack_fixture("format1.tar.gz", dir.path());
    for d in [&complete, &interrupted] {
        let refused = [
            vec!["resume", s(d), "--quiet"],
            vec!["run", s(&m), "--out", s(d), "--quiet"],
        ];
        // Format 1 is upgraded through 2 to today's 3 (checksums).
        refused_then_upgraded(d, &refused, &["format 1 -> 2"], &log);
    }
    resume_fixtures(
        &complete,
        &interrupted,
        &log,
        "the resumed campaign vs the complete one",
    );
    // Growth of the upgraded campaign: a third replica and a longer t_end (the old end kept as
    // an output). Format 1 kept no final states, so the longer runs run again from t = 0 (with
    // a warning), with their format-1 seeds: up to the old end their rows are the old runs'.
    let mg = grown_fixture_manifest(&m, dir.path());
    fs::write(&log, "").unwrap();
    run_ok(&mg, &complete, &log);
    assert!(
        log_text(&log).contains("cannot continue run"),
        "{}",
        log_text(&log)
    );
    let runs = read_table(&complete, "runs");
    assert_eq!(runs.rows.len(), 4 + 6);
    let (rid, pid, rep, seed) = (
        runs.col("run_id"),
        runs.col("point_id"),
        runs.col("replica"),
        runs.col("seed"),
    );
    let by_id: BTreeMap<u64, &Vec<Cell>> = runs.rows.iter().map(|r| (r[rid].as_u64(), r)).collect();
    let species = read_table(&complete, "dsmc_species");
    let (srun, st) = (species.col("run_id"), species.col("t"));
    let rows_of = |run: u64, upto: f64| -> Vec<Vec<Cell>> {
        let mut v: Vec<Vec<Cell>> = species
            .rows
            .iter()
            .filter(|r| r[srun].as_u64() == run)
            .filter(|r| matches!(r[st], Cell::F(b) if f64::from_bits(b) <= upto))
            .map(|r| {
                let mut r = r.clone();
                r[srun] = Cell::Null;
                r[species.col("point_id")] = Cell::Null;
                r
            })
            .collect();
        v.sort();
        v
    };
    for old in 0..4u64 {
        let o = by_id[&old];
        let longer = runs
            .rows
            .iter()
            .find(|r| {
                r[rid].as_u64() >= 4 && r[rep] == o[rep] && r[seed] == o[seed] && r[pid] != o[pid]
            })
            .unwrap_or_else(|| panic!("no longer run with the seed of run {old}"));
        let new_id = longer[rid].as_u64();
        assert_eq!(
            rows_of(new_id, 3000.0),
            rows_of(old, 3000.0),
            "run {new_id} vs {old}"
        );
        assert!(rows_of(new_id, 4000.0).len() > rows_of(old, 4000.0).len());
    }
}

/// The committed fixture `tests/fixtures/format2.tar.gz` (made by granular 66a0e87, the version
/// before checksums; see tests/fixtures/README.md): a complete, compacted campaign and the same
/// campaign interrupted (2 runs committed, 1 checkpointed, 1 pending). The new binary refuses
/// both with the command that upgrades them and changes nothing; `granular upgrade` records the
/// size and SHA-256 of every committed file (the compacted index becomes one group) and a
/// sidecar for every rebuilt table; `verify` (the full scrub) passes; the interrupted one
/// resumes from its old checkpoint to the complete one's rows; the upgraded campaign grows
/// (longer runs continue from the final states kept by format 2) and compacts.
#[test]
fn format2_campaigns_upgrade_to_checksums_and_continue() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let (complete, interrupted, m) = unpack_fixture("format2.tar.gz", dir.path());
    for d in [&complete, &interrupted] {
        let refused = [
            vec!["resume", s(d), "--quiet"],
            vec!["verify", s(d)],
            vec!["run", s(&m), "--out", s(d), "--quiet"],
        ];
        refused_then_upgraded(d, &refused, &["format 2 -> 3", "SHA-256"], &log);
        let (code, out) = run_capture(&["verify", s(d)], &log);
        assert_eq!(code, Some(0), "{out}\n{}", log_text(&log));
        assert!(out.contains("SHA-256 checked"), "{out}");
    }
    // The compacted index of format 2 became one group with every compacted file.
    let index: Value =
        serde_json::from_slice(&fs::read(complete.join("ledger/index.json")).unwrap()).unwrap();
    assert_eq!(index["format_version"], json!(2));
    assert_eq!(index["groups"].as_array().unwrap().len(), 1, "{index}");
    assert_eq!(
        index["groups"][0]["files"].as_array().unwrap().len(),
        2,
        "{index}"
    );
    resume_fixtures(
        &complete,
        &interrupted,
        &log,
        "the resumed upgraded campaign vs the complete one",
    );
    // Growth: a third replica and a longer t_end; format 2 kept final states, so the longer
    // runs continue them (no rerun warning). The reference is the same campaign without its
    // final states, whose longer runs are made again from t = 0: a new campaign would draw
    // its DSMC runs from AES words (stream version 3 on), the fixture from ChaCha8 (version 1).
    let mg = grown_fixture_manifest(&m, dir.path());
    let direct = dir.path().join("direct");
    util::copy_dir(&complete, &direct);
    fs::remove_dir_all(direct.join("finals")).unwrap();
    fs::write(&log, "").unwrap();
    run_ok(&mg, &complete, &log);
    assert!(
        !log_text(&log).contains("cannot continue run"),
        "{}",
        log_text(&log)
    );
    fs::write(&log, "").unwrap();
    run_ok(&mg, &direct, &log);
    assert!(
        log_text(&log).contains("cannot continue run"),
        "the reference continued final states: {}",
        log_text(&log)
    );
    // The fixture's theory table predates the Sonine columns and is never rewritten: the
    // points the growth adds get the fixture's columns, the summary nulls there.
    let sonine = [
        "a2",
        "temperature_sonine",
        "temperature_sonine_dev_sigma",
        "temperature_sonine_dev_rel",
        "msd_sonine",
        "msd_sonine_dev_sigma",
        "msd_sonine_dev_rel",
        "a2_theory",
    ];
    let theory = read_table(&complete, "dsmc_theory");
    assert!(!theory.columns.iter().any(|(n, _)| n == "a2"));
    let summary = read_table(&complete, "dsmc_species_summary");
    for c in ["temperature_sonine", "msd_sonine", "a2_theory"] {
        let i = summary.columns.iter().position(|(n, _)| n == c).expect(c);
        assert!(summary.rows.iter().all(|r| r[i] == util::Cell::Null), "{c}");
    }
    assert_same_current_except(&complete, &direct, "upgraded and grown vs direct", &sonine);
    // One schema per table: the grown campaign's new parts of dsmc_species have the fixture's
    // columns (no `a2`, which the fresh campaign has, null), so every reader sees one table.
    let mut schemas = BTreeSet::new();
    for e in fs::read_dir(complete.join("tables/dsmc_species")).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "parquet") {
            let s = granular::store::schema::file_schema(&p).unwrap();
            let names: Vec<String> = s.fields().iter().map(|f| f.name().clone()).collect();
            assert!(!names.contains(&"a2".to_string()), "{}", p.display());
            schemas.insert(names);
        }
    }
    assert_eq!(schemas.len(), 1, "{schemas:?}");
    // A new campaign of the grown manifest has `a2`.
    let fresh = dir.path().join("fresh");
    run_ok(&mg, &fresh, &log);
    let d_species = granular::store::schema::file_schema(
        &fs::read_dir(fresh.join("tables/dsmc_species"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.extension().is_some_and(|x| x == "parquet"))
            .unwrap(),
    )
    .unwrap();
    assert!(d_species.index_of("a2").is_ok());
    // Points that would fill `a2` cannot join that table: refused, naming the column and the
    // points, and nothing in the directory changes.
    let mut mv: Value = serde_json::from_slice(&fs::read(&mg).unwrap()).unwrap();
    mv["params"]["observables"] = json!(["msd", "velocity_distribution"]);
    let mvp = dir.path().join("vdist.json");
    util::write_json(&mvp, &mv);
    let before = util::snapshot(&complete);
    fs::write(&log, "").unwrap();
    let (code, out) = run_capture(&["run", s(&mvp), "--out", s(&complete), "--quiet"], &log);
    let err = log_text(&log);
    assert_eq!(code, Some(3), "{out}\n{err}");
    assert!(
        err.contains("point(s) [") && err.contains("column \"a2\" of table dsmc_species"),
        "{err}"
    );
    assert!(err.contains("new campaign"), "{err}");
    assert!(
        util::snapshot(&complete) == before,
        "a refused growth wrote"
    );
    for cmd in [vec!["compact", s(&complete)], vec!["verify", s(&complete)]] {
        let (code, out) = run_capture(&cmd, &log);
        assert_eq!(code, Some(0), "{cmd:?}: {out}\n{}", log_text(&log));
    }
    assert_same_current_except(
        &complete,
        &direct,
        "upgraded, grown and compacted vs direct",
        &sonine,
    );
}
