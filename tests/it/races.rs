//! Two commands at once on one campaign: every decision is taken under the lock on state read
//! under it. Racing growths both land (neither overwrites the other's registry), a resume that
//! read the campaign before a growth runs the grown campaign, a growth refused while another
//! holds the lock names it truthfully, summaries describe exactly the latest manifest (fewer
//! replicas, other seeds), a commit record lost while a campaign runs is healed before the
//! command says it is done, `upgrade` decides under the lock.
//!
//! The interleavings are made deterministic with the test-only pause points of
//! `granular::campaign::test_hook` (`GRANULAR_TEST_PAUSE=<point>:<file>`: the process creates
//! the file when it first reaches the point and waits until the test removes it), or by
//! driving the library directly with a campaign opened before the other command ran.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Child;
use std::time::{Duration, Instant};

use serde_json::{json, Value};

use super::util::s;
use super::util::{
    self, assert_same_current, granular, heavy, log_text, read_table, run_granular, wait_limited,
    Cell,
};

const LIMIT: Duration = Duration::from_secs(300);

/// A tiny DSMC campaign (1 restitution value x 2 replicas, ~1200 particles, t_end 5): each
/// run takes milliseconds.
fn base() -> Value {
    json!({
        "name": "race",
        "model": "dsmc",
        "seed": 7,
        "replicas": 2,
        "params": {
            "method": "low_rank",
            "species": {"power_law": {"n1": 0.1, "N1": 1000, "theta": 3}},
            "restitution": {"constant": 0.5},
            "t_end": 5.0,
            "output_times": {"list": [1.0]},
            "observables": ["temperature"]
        },
        "sweep": {"restitution.constant": [0.5, 0.9]}
    })
}

/// `base` with one more restitution value.
fn with_value(v: f64) -> Value {
    let mut m = base();
    m["sweep"]["restitution.constant"] = json!([0.5, 0.9, v]);
    m
}

fn write(dir: &Path, name: &str, v: &Value) -> PathBuf {
    let p = dir.join(name);
    util::write_json(&p, v);
    p
}

fn run_args<'a>(m: &'a Path, out: &'a Path) -> Vec<&'a str> {
    vec![
        "run",
        s(m),
        "--out",
        s(out),
        "--threads",
        "2",
        "--quiet",
        "--flush-every",
        "0",
    ]
}

fn run_ok(m: &Path, out: &Path, log: &Path) {
    let code = run_granular(&run_args(m, out), log, LIMIT);
    assert_eq!(code, Some(0), "run {}:\n{}", m.display(), log_text(log));
}

/// Start `granular args` that pauses at `point` (creating `flag`), and wait until it does.
fn paused(args: &[&str], point: &str, flag: &Path, log: &Path) -> Child {
    let mut cmd = granular(args, log);
    cmd.env("GRANULAR_TEST_PAUSE", format!("{point}:{}", flag.display()));
    let mut child = cmd.spawn().expect("spawn granular");
    let start = Instant::now();
    while !flag.exists() {
        if let Some(st) = child.try_wait().unwrap() {
            panic!(
                "granular {} ended ({st}) before pausing at {point}:\n{}",
                args.join(" "),
                log_text(log)
            );
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "granular {} never reached {point}:\n{}",
            args.join(" "),
            log_text(log)
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    child
}

/// Let a paused process go on and wait for its exit code.
fn release(mut child: Child, flag: &Path, log: &Path) -> Option<i32> {
    fs::remove_file(flag).unwrap();
    wait_limited(&mut child, LIMIT, "the paused granular", log).code()
}

/// The restitution of each point (by id) in the `points` table, and whether it is current.
fn points_by_restitution(dir: &Path) -> Vec<(u64, f64, bool)> {
    let t = read_table(dir, "points");
    let (id, params, cur) = (t.col("point_id"), t.col("params"), t.col("in_manifest"));
    let mut v: Vec<(u64, f64, bool)> = t
        .rows
        .iter()
        .map(|r| {
            let p: Value = serde_json::from_str(r[params].as_str()).unwrap();
            (
                r[id].as_u64(),
                p["restitution"]["constant"].as_f64().unwrap(),
                r[cur] == Cell::Bool(true),
            )
        })
        .collect();
    v.sort_by_key(|x| x.0);
    v
}

/// The temperature rows (t, species, temperature bits) of the runs of the point with
/// restitution `eps`, keyed by replica: what a campaign computed for that point.
fn temperatures_of(dir: &Path, eps: f64) -> Vec<(u64, String, u64, u64)> {
    let points = points_by_restitution(dir);
    let ids: Vec<u64> = points.iter().filter(|p| p.1 == eps).map(|p| p.0).collect();
    assert_eq!(ids.len(), 1, "one point with restitution {eps}: {points:?}");
    let runs = read_table(dir, "runs");
    let (rid, rpoint, rrep) = (
        runs.col("run_id"),
        runs.col("point_id"),
        runs.col("replica"),
    );
    let replica: std::collections::BTreeMap<u64, u64> = runs
        .rows
        .iter()
        .filter(|r| r[rpoint].as_u64() == ids[0])
        .map(|r| (r[rid].as_u64(), r[rrep].as_u64()))
        .collect();
    let t = read_table(dir, "dsmc_species");
    let (run, time, sp, temp) = (
        t.col("run_id"),
        t.col("t"),
        t.col("species"),
        t.col("temperature"),
    );
    let mut v: Vec<(u64, String, u64, u64)> = t
        .rows
        .iter()
        .filter_map(|r| {
            let rep = *replica.get(&r[run].as_u64())?;
            Some((
                rep,
                r[time].to_string(),
                r[sp].as_u64(),
                cell_bits(&r[temp]),
            ))
        })
        .collect();
    v.sort();
    v
}

fn cell_bits(c: &Cell) -> u64 {
    match c {
        Cell::F(bits) => *bits,
        other => panic!("expected a float, got {other}"),
    }
}

fn verify_clean(dir: &Path, log: &Path) {
    let code = run_granular(&["verify", s(dir)], log, LIMIT);
    assert_eq!(code, Some(0), "verify:\n{}", log_text(log));
}

/// Two growths at once: B reads the campaign, then A grows it and runs, then B takes the lock.
/// B must grow A's registry (re-read under the lock), not overwrite it: A's manifest stays
/// `manifests/1.json`, A's point keeps its restitution and rows, B's point is new, and the
/// summaries are those of B's manifest (the latest), equal to a direct campaign of it.
#[test]
fn two_growths_at_once_both_land() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let camp = dir.path().join("camp");
    let m0 = write(dir.path(), "m0.json", &base());
    let ma = write(dir.path(), "a.json", &with_value(0.3));
    let mb = write(dir.path(), "b.json", &with_value(0.6));
    run_ok(&m0, &camp, &log);
    let flag = dir.path().join("b.paused");
    let b = paused(&run_args(&mb, &camp), "accept-read", &flag, &log);
    // B has read the campaign (before A's growth) and waits before taking the lock.
    run_ok(&ma, &camp, &log);
    assert_eq!(release(b, &flag, &log), Some(0), "B:\n{}", log_text(&log));

    let history: Vec<Value> = (0..3)
        .map(|k| {
            let text = fs::read_to_string(camp.join(format!("manifests/{k}.json"))).unwrap();
            serde_json::from_str(&text).unwrap()
        })
        .collect();
    assert_eq!(history[1], with_value(0.3), "A's manifest was overwritten");
    assert_eq!(history[2], with_value(0.6));
    let points = points_by_restitution(&camp);
    assert_eq!(
        points.iter().map(|p| (p.1, p.2)).collect::<Vec<_>>(),
        vec![(0.5, true), (0.9, true), (0.3, false), (0.6, true)],
        "{points:?}"
    );
    // A's point holds A's rows (those of a direct campaign of A), B's point B's.
    let direct_a = dir.path().join("direct-a");
    let direct_b = dir.path().join("direct-b");
    run_ok(&ma, &direct_a, &log);
    run_ok(&mb, &direct_b, &log);
    assert_eq!(temperatures_of(&camp, 0.3), temperatures_of(&direct_a, 0.3));
    assert_eq!(temperatures_of(&camp, 0.6), temperatures_of(&direct_b, 0.6));
    assert_same_current(&camp, &direct_b, "after two racing growths");
    verify_clean(&camp, &log);
}

/// A growth while another process holds the campaign's exclusive lock is refused (exit 3),
/// naming what that process does and its pid, and changes nothing; once the lock is free it
/// is accepted.
#[test]
fn growth_refused_while_another_growth_holds_the_lock() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let camp = dir.path().join("camp");
    let m0 = write(dir.path(), "m0.json", &base());
    let ma = write(dir.path(), "a.json", &with_value(0.3));
    let mb = write(dir.path(), "b.json", &with_value(0.6));
    run_ok(&m0, &camp, &log);
    let flag = dir.path().join("a.paused");
    let a = paused(&run_args(&ma, &camp), "accept-locked", &flag, &log);
    let pid = a.id();
    let before = util::snapshot(&camp);
    let blog = dir.path().join("b.log");
    let code = run_granular(&run_args(&mb, &camp), &blog, LIMIT);
    let text = log_text(&blog);
    assert_eq!(code, Some(3), "B while A holds the lock:\n{text}");
    assert!(
        text.contains("change of the campaign's manifest")
            && text.contains(&format!("process {pid}")),
        "the refusal names the growth and its process {pid}:\n{text}"
    );
    assert!(!text.contains("compaction"), "not a compaction:\n{text}");
    let mut after = util::snapshot(&camp);
    // A's lock file is the only difference (it was taken before the snapshot).
    after.retain(|p, _| before.contains_key(p));
    assert!(after == before, "a refused growth changed the directory");
    assert_eq!(release(a, &flag, &log), Some(0), "A:\n{}", log_text(&log));
    run_ok(&mb, &camp, &log);
    let points = points_by_restitution(&camp);
    assert_eq!(points.len(), 4, "{points:?}");
}

/// A resume that opened the campaign before a growth, and takes its shard lock after the
/// growth's run, works on the grown campaign: its summaries include the grown points (the
/// stale plan would have rewritten them without). Driven through the library, with the
/// campaign opened before the growth.
#[test]
fn a_stale_resume_runs_the_grown_campaign() {
    use granular::campaign::{dispatch, Campaign, RunOptions, Silent};
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let camp = dir.path().join("camp");
    let m0 = write(dir.path(), "m0.json", &base());
    let ma = write(dir.path(), "a.json", &with_value(0.3));
    run_ok(&m0, &camp, &log);
    let stale = Campaign::open(&camp).unwrap();
    run_ok(&ma, &camp, &log);
    let opts = RunOptions {
        threads: 1,
        ..RunOptions::default()
    };
    let outcome = dispatch::run(&stale, &opts, &mut Silent).unwrap();
    assert!(outcome.complete, "{outcome:?}");
    let summary = read_table(&camp, "dsmc_species_summary");
    let ids: std::collections::BTreeSet<u64> = summary
        .column("point_id")
        .iter()
        .map(|c| c.as_u64())
        .collect();
    assert_eq!(
        ids.len(),
        3,
        "the summary covers the 3 points of the latest manifest"
    );
    let direct = dir.path().join("direct");
    run_ok(&ma, &direct, &log);
    assert_same_current(&camp, &direct, "after a stale resume");
    verify_clean(&camp, &log);
    // The same through the command line: a resume paused after opening the campaign.
    let mb = write(dir.path(), "b.json", &with_value(0.6));
    let flag = dir.path().join("resume.paused");
    let r = paused(
        &["resume", s(&camp), "--quiet"],
        "resume-opened",
        &flag,
        &log,
    );
    run_ok(&mb, &camp, &log);
    assert_eq!(release(r, &flag, &log), Some(0), "{}", log_text(&log));
    let direct_b = dir.path().join("direct-b");
    run_ok(&mb, &direct_b, &log);
    assert_same_current(&camp, &direct_b, "after a stale command-line resume");
}

/// Summaries describe exactly the latest manifest's runs: after `replicas` 2 -> 1 every
/// summary has `n_replicas` 1 and equals a direct campaign of the manifest; after switching to
/// `seeds` the summary averages those seeds' runs only, numbered as in a direct campaign.
/// Rows of the runs left out stay in the raw tables, flagged in `registered_runs`.
#[test]
fn summaries_describe_the_latest_manifest() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let camp = dir.path().join("camp");
    let m0 = write(dir.path(), "m0.json", &base());
    run_ok(&m0, &camp, &log);
    let mut one = base();
    one["replicas"] = json!(1);
    let m1 = write(dir.path(), "m1.json", &one);
    run_ok(&m1, &camp, &log);
    let summary = read_table(&camp, "dsmc_species_summary");
    let n: Vec<u64> = summary
        .column("n_replicas")
        .iter()
        .map(|c| c.as_u64())
        .collect();
    assert!(
        !n.is_empty() && n.iter().all(|&x| x == 1),
        "n_replicas {n:?}"
    );
    let direct1 = dir.path().join("direct1");
    run_ok(&m1, &direct1, &log);
    assert_same_current(&camp, &direct1, "replicas 2 -> 1");
    assert_eq!(read_table(&camp, "runs").rows.len(), 4, "rows are kept");
    let reg = read_table(&camp, "registered_runs");
    let cur = reg.column("in_manifest");
    assert_eq!(cur.iter().filter(|c| **c == &Cell::Bool(true)).count(), 2);
    assert_eq!(cur.iter().filter(|c| **c == &Cell::Bool(false)).count(), 2);

    let mut seeds = base();
    seeds.as_object_mut().unwrap().remove("replicas");
    seeds["seeds"] = json!([11, 3, 7]);
    let m2 = write(dir.path(), "m2.json", &seeds);
    run_ok(&m2, &camp, &log);
    let summary = read_table(&camp, "dsmc_species_summary");
    let n: Vec<u64> = summary
        .column("n_replicas")
        .iter()
        .map(|c| c.as_u64())
        .collect();
    assert!(
        !n.is_empty() && n.iter().all(|&x| x == 3),
        "n_replicas {n:?}"
    );
    let direct2 = dir.path().join("direct2");
    run_ok(&m2, &direct2, &log);
    assert_same_current(&camp, &direct2, "switched to seeds");
    assert_eq!(read_table(&camp, "runs").rows.len(), 10, "rows are kept");
    // The summary's bits equal the direct campaign's (summed in the same replica order).
    let bits = |d: &Path| {
        let t = read_table(d, "dsmc_species_summary");
        let c = t.col("temperature_mean");
        let mut v: Vec<u64> = t.rows.iter().map(|r| cell_bits(&r[c])).collect();
        v.sort();
        v
    };
    assert_eq!(bits(&camp), bits(&direct2));
}

/// A commit record lost while the campaign runs (deleted right after it was written) is found
/// before the command reports: the run is healed (its record rebuilt from its parts) and the
/// command exits 0 only with every run finished; `status` says so and `verify` is clean.
#[test]
fn a_commit_record_lost_during_a_run_is_healed_before_success() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let camp = dir.path().join("camp");
    let m0 = write(dir.path(), "m0.json", &base());
    let flag = dir.path().join("committed.paused");
    let mut args = run_args(&m0, &camp);
    args[5] = "1"; // one worker: the other runs are still to come after the first commit
    let child = paused(&args, "committed", &flag, &log);
    let records: Vec<PathBuf> = fs::read_dir(camp.join("ledger/s1of1"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    assert_eq!(records.len(), 1, "{records:?}");
    fs::remove_file(&records[0]).unwrap();
    assert_eq!(release(child, &flag, &log), Some(0), "{}", log_text(&log));
    let st = util::status_json(&camp, &log);
    assert_eq!(st["current"]["done"], st["current_runs"], "{st:#}");
    assert_eq!(st["current_runs"], json!(4), "{st:#}");
    verify_clean(&camp, &log);
    let direct = dir.path().join("direct");
    run_ok(&m0, &direct, &log);
    assert_same_current(&camp, &direct, "after a lost record");
}

/// `upgrade` decides under the lock: while a shard runs it is refused (exit 3, naming the
/// shard), even on a directory of the current format.
#[test]
fn upgrade_is_refused_while_a_shard_runs() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let camp = dir.path().join("camp");
    let m0 = write(dir.path(), "m0.json", &base());
    run_ok(&m0, &camp, &log);
    let flag = dir.path().join("shard.paused");
    let r = paused(
        &["resume", s(&camp), "--quiet"],
        "shard-locked",
        &flag,
        &log,
    );
    let ulog = dir.path().join("upgrade.log");
    let code = run_granular(&["upgrade", s(&camp)], &ulog, LIMIT);
    let text = log_text(&ulog);
    assert_eq!(code, Some(3), "upgrade while a shard runs:\n{text}");
    assert!(
        text.contains("shard 1/1") && text.contains(&format!("process {}", r.id())),
        "{text}"
    );
    assert_eq!(release(r, &flag, &log), Some(0), "{}", log_text(&log));
    assert_eq!(run_granular(&["upgrade", s(&camp)], &ulog, LIMIT), Some(0));
}

/// Commands given a directory that is not a campaign name `campaign.json` (not "os error 2").
#[test]
fn a_non_campaign_directory_is_named_as_such() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let empty = dir.path().join("empty");
    fs::create_dir(&empty).unwrap();
    for cmd in [
        "upgrade", "report", "status", "verify", "resume", "compact", "plot", "serve",
    ] {
        let clog = dir.path().join(format!("{cmd}.log"));
        let code = run_granular(&[cmd, s(&empty)], &clog, LIMIT);
        let text = log_text(&clog);
        assert_eq!(code, Some(3), "{cmd}:\n{text}");
        assert!(
            text.contains("not a granular campaign directory (no campaign.json"),
            "{cmd}:\n{text}"
        );
        assert!(!text.contains("os error"), "{cmd}:\n{text}");
        assert!(
            fs::read_dir(&empty).unwrap().next().is_none(),
            "{cmd} wrote into a directory that is not a campaign"
        );
    }
    let _ = log;
}

/// A campaign read again from `campaign.json` (as every command now does under its lock) is
/// the campaign that was written: a sweep value that a fast float parser reads one unit in the
/// last place off (7.000000000000001e-9: serde_json without `float_roundtrip` read it as
/// 7.0000000000000015e-9, and the same value read again from campaign.json as a third one)
/// keeps its point in the manifest, and its run is run.
#[test]
fn a_reread_campaign_keeps_every_point() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let camp = dir.path().join("camp");
    let text = r#"{"name": "ulp", "model": "rfm", "seed": 4,
        "params": {"dim": 2, "n_particles": 20, "packing_fraction": 0.1, "warmup": 0.001,
                   "duration": 0.004, "sample_every": 200, "noise_strength": 1e-8},
        "sweep": {"noise_strength": [6.000000000000001e-09, 7.000000000000001e-09, 1e-08]}}"#;
    let m = dir.path().join("m.json");
    fs::write(&m, text).unwrap();
    run_ok(&m, &camp, &log);
    let st = util::status_json(&camp, &log);
    assert_eq!(st["current_runs"], json!(3), "{st:#}");
    assert_eq!(st["current"]["done"], json!(3), "{st:#}");
    let points = st["points"].as_array().unwrap();
    assert!(
        points.iter().all(|p| p["in_manifest"] == json!(true)),
        "{st:#}"
    );
    let summary = read_table(&camp, "rfm_timeseries_summary");
    let ids: std::collections::BTreeSet<u64> = summary
        .column("point_id")
        .iter()
        .map(|c| c.as_u64())
        .collect();
    assert_eq!(ids.len(), 3, "every point summarised");
}

/// A campaign that ran given `seeds` and is then asked for `replicas`: its given-seed runs
/// would count as replicas that a campaign started from the manifest would not have (their
/// seeds derive from the campaign seed), so the summaries could not equal a direct campaign's.
/// Refused (exit 3) before anything is written, naming the point. (Found by the race drill.)
#[test]
fn replicas_after_given_seeds_are_refused() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let camp = dir.path().join("camp");
    let mut seeds = base();
    seeds.as_object_mut().unwrap().remove("replicas");
    seeds["seeds"] = json!([3, 5]);
    let ms = write(dir.path(), "seeds.json", &seeds);
    run_ok(&ms, &camp, &log);
    let mr = write(dir.path(), "replicas.json", &base());
    let before = util::snapshot(&camp);
    let rlog = dir.path().join("r.log");
    let code = run_granular(&run_args(&mr, &camp), &rlog, LIMIT);
    let text = log_text(&rlog);
    assert_eq!(code, Some(3), "{text}");
    assert!(
        text.contains("given seeds at replica place(s) [0, 1]"),
        "{text}"
    );
    assert!(
        util::snapshot(&camp) == before,
        "a refused growth changed the directory"
    );
    // More seeds still grow it.
    seeds["seeds"] = json!([3, 5, 8]);
    let ms2 = write(dir.path(), "seeds2.json", &seeds);
    run_ok(&ms2, &camp, &log);
}
