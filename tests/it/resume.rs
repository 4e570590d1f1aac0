//! Campaign directories through the CLI: kill -9 and resume, thread counts and shards all
//! give bit-identical tables; a directory holding another campaign is refused untouched; a
//! finished campaign re-run adds nothing; `status --json` reports the runs.

use std::fs;
use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use serde_json::{json, Value};

use super::util::{
    self, heavy, log_text, read_table, read_tables, run_granular, status_json, Lcg, Tables,
};
use super::util::{dead_pid, s};

/// Upper bound on any single `granular` process of these tests (a hang is a failure).
const LIMIT: Duration = Duration::from_secs(300);

/// The campaign of the kill test: 2 methods x 3 replicas = 6 runs of ~96 000 particles (a
/// power law N_k = round(N1 k^-3), 54 species), t_end = 30 with 19 output times, MSD and
/// time-averaged MSD (20 tracers per species, ~470 in all, on a grid of 300 steps, so the
/// tracer trajectories are part of every checkpoint); about 3-6 s uninterrupted on 2 threads.
fn campaign_manifest() -> Value {
    json!({
        "name": "kill-test",
        "description": "integration test: kill -9 / resume",
        "model": "dsmc",
        "seed": 20240607,
        "replicas": 3,
        "params": {
            "method": "low_rank",
            "species": {"power_law": {"n1": 0.1, "N1": 80000, "theta": 3}},
            "restitution": {"constant": 0.9},
            "t_end": 30.0,
            "output_times": {"log": {"from": 0.01, "to": 30.0, "per_decade": 5}},
            "observables": ["temperature", "msd", "tamsd"],
            "tamsd": {"lags": [0.5, 3.0, 10.0], "tracers": 20, "grid": 300}
        },
        "sweep": {"method": ["low_rank", "bird"]}
    })
}

const N_RUNS: u64 = 6;

/// A small campaign (4 runs, well under a second) for the directory-handling tests.
fn small_manifest(seed: u64) -> Value {
    json!({
        "name": "small",
        "model": "dsmc",
        "seed": seed,
        "replicas": 2,
        "params": {
            "method": "low_rank",
            "species": {"power_law": {"n1": 0.1, "N1": 2000, "theta": 3}},
            "restitution": {"constant": 0.7},
            "t_end": 10.0,
            "output_times": {"list": [1.0, 5.0]},
            "observables": ["msd"]
        },
        "sweep": {"method": ["low_rank", "bird"]}
    })
}

struct Reference {
    tables: Tables,
    /// Wall time of the uninterrupted run (the kill moments are scaled to it).
    seconds: f64,
}

static REFERENCE: OnceLock<Reference> = OnceLock::new();

/// Sanity of a finished campaign's tables: every run once, done, with its rows.
fn check_complete(t: &Tables, n_runs: u64, what: &str) {
    let runs = &t["runs"];
    let mut ids: Vec<u64> = runs.column("run_id").iter().map(|c| c.as_u64()).collect();
    ids.sort();
    assert_eq!(
        ids,
        (0..n_runs).collect::<Vec<_>>(),
        "{what}: run ids in the runs table"
    );
    assert!(
        runs.column("status").iter().all(|c| c.as_str() == "done"),
        "{what}: not every run is done"
    );
    assert!(
        runs.column("collisions").iter().all(|c| c.as_u64() > 0),
        "{what}: a run without collisions"
    );
    let species_runs: std::collections::BTreeSet<u64> = t["dsmc_species"]
        .column("run_id")
        .iter()
        .map(|c| c.as_u64())
        .collect();
    assert_eq!(
        species_runs.len() as u64,
        n_runs,
        "{what}: runs with dsmc_species rows"
    );
    assert!(
        !t["dsmc_species_summary"].rows.is_empty(),
        "{what}: empty summary"
    );
    // With the observable `tamsd`: rows of every run, a summary with the theory joined.
    let tamsd = &t["dsmc_tamsd"];
    if !tamsd.rows.is_empty() {
        let tamsd_runs: std::collections::BTreeSet<u64> =
            tamsd.column("run_id").iter().map(|c| c.as_u64()).collect();
        assert_eq!(
            tamsd_runs.len() as u64,
            n_runs,
            "{what}: runs with dsmc_tamsd rows"
        );
        let summary = &t["dsmc_tamsd_summary"];
        let replicas = n_runs as usize / t["points"].rows.len();
        assert_eq!(
            summary.rows.len() * replicas,
            tamsd.rows.len(),
            "{what}: tamsd summary rows"
        );
        assert!(
            summary
                .column("tamsd_theory")
                .iter()
                .all(|c| **c != util::Cell::Null),
            "{what}: tamsd summary without theory"
        );
    }
}

/// The uninterrupted 2-thread run of `campaign_manifest`, done once per test binary.
/// Callers must not hold `heavy()` (this takes it).
fn reference() -> &'static Reference {
    REFERENCE.get_or_init(|| {
        let _g = heavy();
        let dir = tempfile::tempdir().unwrap();
        let manifest = dir.path().join("m.json");
        util::write_json(&manifest, &campaign_manifest());
        let a = dir.path().join("A");
        let log = dir.path().join("log");
        let start = Instant::now();
        let code = run_granular(
            &[
                "run",
                s(&manifest),
                "--out",
                s(&a),
                "--threads",
                "2",
                "--quiet",
            ],
            &log,
            LIMIT,
        );
        let seconds = start.elapsed().as_secs_f64();
        assert_eq!(
            code,
            Some(0),
            "uninterrupted run failed; log:\n{}",
            log_text(&log)
        );
        let tables = read_tables(&a);
        check_complete(&tables, N_RUNS, "uninterrupted run");
        eprintln!("reference campaign: {seconds:.2} s uninterrupted on 2 threads");
        Reference { tables, seconds }
    })
}

fn files_named(dir: &Path, pred: &dyn Fn(&str) -> bool) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(it) = fs::read_dir(&d) else { continue };
        for e in it {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if pred(&p.file_name().unwrap().to_string_lossy()) {
                out.push(p);
            }
        }
    }
    out
}

/// What one kill-and-resume scenario did.
struct Scenario {
    kills: u32,
    attempts: u32,
    finished_early: bool,
}

/// Run the campaign into `b`, SIGKILLing it `planned` times at LCG-drawn moments
/// (`scale` x [4%, 12%] of the uninterrupted wall time `seconds`, i.e. ~0.15-0.7 s), resuming
/// after each kill, then resuming until a resume exits 0.
fn kill_scenario(
    manifest: &Path,
    b: &Path,
    log: &Path,
    planned: u32,
    scale: f64,
    lcg: &mut Lcg,
    seconds: f64,
) -> Scenario {
    let mut sc = Scenario {
        kills: 0,
        attempts: 0,
        finished_early: false,
    };
    let opts = [
        "--threads",
        "2",
        "--checkpoint-every",
        "0.05",
        "--flush-every",
        "0.2",
        "--quiet",
    ];
    while sc.kills < planned {
        let mut args: Vec<&str> = if sc.attempts == 0 {
            vec!["run", s(manifest), "--out", s(b)]
        } else {
            vec!["resume", s(b)]
        };
        args.extend(opts);
        // The first attempt lives at least 0.2 s, so that the directory exists as a campaign
        // (`resume` needs its campaign.json).
        let floor = if sc.attempts == 0 { 0.2 } else { 0.05 };
        let delay =
            Duration::from_secs_f64((seconds * scale * (0.04 + 0.08 * lcg.next_f64())).max(floor));
        let _ = fs::OpenOptions::new()
            .append(true)
            .create(true)
            .open(log)
            .and_then(|mut f| {
                use std::io::Write;
                writeln!(
                    f,
                    "---- attempt {}: granular {} (kill after {delay:?})",
                    sc.attempts + 1,
                    args.join(" ")
                )
            });
        let mut child = util::granular(&args, log).spawn().expect("spawn");
        sc.attempts += 1;
        let start = Instant::now();
        let mut exited = None;
        while start.elapsed() < delay {
            if let Some(st) = child.try_wait().unwrap() {
                exited = Some(st);
                break;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        let status = match exited {
            Some(st) => st,
            None => {
                child.kill().expect("SIGKILL");
                child.wait().unwrap()
            }
        };
        match (status.code(), status.signal()) {
            (_, Some(9)) => sc.kills += 1,
            (Some(0), _) => {
                // Finished before the kill landed.
                sc.finished_early = true;
                return sc;
            }
            _ => panic!(
                "attempt {} ended with {status:?} (expected SIGKILL or exit 0); log:\n{}",
                sc.attempts,
                log_text(log)
            ),
        }
        // After a kill the directory is a consistent campaign: status works and counts every
        // run once; the killed process holds nothing.
        assert!(
            b.join("campaign.json").exists(),
            "no campaign.json after {delay:?}; log:\n{}",
            log_text(log)
        );
        let st = status_json(b, log);
        let count = |k: &str| {
            st[k]
                .as_u64()
                .unwrap_or_else(|| panic!("status lacks {k}: {st}"))
        };
        assert_eq!(count("runs"), N_RUNS, "{st}");
        assert_eq!(
            count("done") + count("pending") + count("running") + count("failed"),
            N_RUNS,
            "{st}"
        );
        assert_eq!(count("failed"), 0, "{st}");
        assert_eq!(
            count("running"),
            0,
            "a killed process is reported running: {st}"
        );
        assert_eq!(
            st["live_shards"],
            json!([]),
            "a killed process is reported live: {st}"
        );
    }
    let mut args = vec!["resume", s(b)];
    args.extend(opts);
    let _ = fs::OpenOptions::new()
        .append(true)
        .open(log)
        .and_then(|mut f| {
            use std::io::Write;
            writeln!(f, "---- final: granular {}", args.join(" "))
        });
    let code = run_granular(&args, log, LIMIT);
    sc.attempts += 1;
    assert_eq!(
        code,
        Some(0),
        "final resume failed; log:\n{}",
        log_text(log)
    );
    sc
}

/// Acceptance (and the reliability drill): a campaign SIGKILLed at pseudo-random moments (at
/// least 20 times) and resumed each time ends with tables bit-identical to an uninterrupted
/// run, without duplicated rows.
#[test]
fn kill_9_and_resume_gives_identical_tables() {
    let reference = reference();
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let manifest = dir.path().join("m.json");
    util::write_json(&manifest, &campaign_manifest());
    let mut lcg = Lcg(0x9e37_79b9_7f4a_7c15);
    // 21 kills at 4-12 % of the uninterrupted time, scaled by 0.35, take ~60 % of it. If the
    // machine got faster between the reference run and this one, the campaign may end before
    // 20 kills: then retry in a fresh directory with the kill moments scaled down (each
    // scenario's tables are compared all the same).
    let mut scale = 0.35;
    for round in 1..=3 {
        let b = dir.path().join(format!("B{round}"));
        let log = dir.path().join(format!("log{round}"));
        let start = Instant::now();
        let sc = kill_scenario(&manifest, &b, &log, 21, scale, &mut lcg, reference.seconds);
        eprintln!(
            "kill scenario {round}: {} kills in {} attempts{}, {:.1} s (uninterrupted: {:.1} s)",
            sc.kills,
            sc.attempts,
            if sc.finished_early {
                ", finished before a planned kill"
            } else {
                ""
            },
            start.elapsed().as_secs_f64(),
            reference.seconds
        );
        let tables = read_tables(&b);
        check_complete(&tables, N_RUNS, "killed and resumed campaign");
        util::assert_tables_identical(
            &reference.tables,
            &tables,
            &format!("uninterrupted vs killed {} times and resumed", sc.kills),
        );
        // Nothing of the crashes is left: no uncommitted parts, no checkpoints of finished runs.
        // (Hidden temporary files of killed writers are the subject of
        // `stale_temporary_files_are_removed_on_resume`; here they are only counted.)
        let pending = files_named(&b, &|n| n.ends_with(".pending"));
        assert!(pending.is_empty(), "uncommitted parts left: {pending:?}");
        let ckpts = files_named(&b.join("checkpoints"), &|n| n.starts_with("run-"));
        assert!(
            ckpts.is_empty(),
            "checkpoints left after completion: {ckpts:?}"
        );
        let stale = files_named(&b, &|n| n.starts_with('.') && n.ends_with(".tmp"));
        if !stale.is_empty() {
            eprintln!("kill scenario {round}: {} stale temporary file(s) of killed processes left: {stale:?}", stale.len());
        }
        let st = status_json(&b, &log);
        assert_eq!(
            (st["done"].as_u64(), st["pending"].as_u64()),
            (Some(N_RUNS), Some(0)),
            "{st}"
        );
        if sc.kills >= 20 {
            return;
        }
        scale *= 0.5;
    }
    panic!("the campaign finished before 20 kills in 3 scenarios; make campaign_manifest() bigger");
}

/// One thread, and two shards run one after the other, give the same tables as the
/// 2-thread run (seeds and summaries do not depend on scheduling).
#[test]
fn threads_and_shards_give_identical_tables() {
    let reference = reference();
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let manifest = dir.path().join("m.json");
    util::write_json(&manifest, &campaign_manifest());
    let log = dir.path().join("log");

    let c = dir.path().join("C");
    let code = run_granular(
        &[
            "run",
            s(&manifest),
            "--out",
            s(&c),
            "--threads",
            "1",
            "--quiet",
        ],
        &log,
        LIMIT,
    );
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    util::assert_tables_identical(&reference.tables, &read_tables(&c), "2 threads vs 1 thread");

    let d = dir.path().join("D");
    let code = run_granular(
        &[
            "run",
            s(&manifest),
            "--out",
            s(&d),
            "--threads",
            "2",
            "--shard",
            "1/2",
            "--quiet",
        ],
        &log,
        LIMIT,
    );
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    // Shard 1 of 2 holds the even run ids, and the campaign is not complete yet.
    let runs = read_table(&d, "runs");
    let ids: Vec<u64> = runs.column("run_id").iter().map(|c| c.as_u64()).collect();
    let mut sorted = ids.clone();
    sorted.sort();
    assert_eq!(sorted, vec![0, 2, 4], "runs of shard 1/2");
    let st = status_json(&d, &log);
    assert_eq!(
        (st["done"].as_u64(), st["pending"].as_u64()),
        (Some(3), Some(3)),
        "{st}"
    );
    let code = run_granular(
        &[
            "run",
            s(&manifest),
            "--out",
            s(&d),
            "--threads",
            "2",
            "--shard",
            "2/2",
            "--quiet",
        ],
        &log,
        LIMIT,
    );
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    util::assert_tables_identical(
        &reference.tables,
        &read_tables(&d),
        "one process vs shards 1/2 + 2/2",
    );
}

/// A directory holding another campaign (another name, seed or model) is refused (exit 3) and
/// left exactly as it was (and so is a non-empty directory that is no campaign); running the
/// same manifest again on the finished directory exits 0 and changes no table. (A grown
/// manifest of the same campaign is accepted: tests/it/growth.rs.)
#[test]
fn other_campaign_refused_and_rerun_adds_nothing() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let m1 = dir.path().join("m1.json");
    util::write_json(&m1, &small_manifest(1));
    let e = dir.path().join("E");
    let code = run_granular(
        &["run", s(&m1), "--out", s(&e), "--threads", "2", "--quiet"],
        &log,
        LIMIT,
    );
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let before_tables = read_tables(&e);
    check_complete(&before_tables, 4, "small campaign");
    let before = util::snapshot(&e);

    let mut other_seed = small_manifest(2);
    other_seed["name"] = json!("small-other");
    let mut other_name = small_manifest(1);
    other_name["name"] = json!("small-renamed");
    let only_seed = small_manifest(2);
    let mut other_model = small_manifest(1);
    other_model["model"] = json!("rfm");
    other_model["params"] = json!({"dim": 1, "n_particles": 20, "reduced_length": 1.0, "warmup": 0.01, "duration": 0.02, "sample_every": 100});
    other_model.as_object_mut().unwrap().remove("sweep");
    for (i, m) in [other_seed, other_name, only_seed, other_model]
        .iter()
        .enumerate()
    {
        let path = dir.path().join(format!("other{i}.json"));
        util::write_json(&path, m);
        let code = run_granular(
            &["run", s(&path), "--out", s(&e), "--threads", "2", "--quiet"],
            &log,
            LIMIT,
        );
        assert_eq!(
            code,
            Some(3),
            "other manifest {i}: log:\n{}",
            log_text(&log)
        );
        let after = util::snapshot(&e);
        let changed: Vec<_> = before
            .keys()
            .chain(after.keys())
            .filter(|k| before.get(*k) != after.get(*k))
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .collect();
        assert!(
            changed.is_empty(),
            "other manifest {i}: refused run changed {changed:?}"
        );
    }

    // A non-empty directory that is no campaign is refused too, untouched.
    let foreign = dir.path().join("foreign");
    fs::create_dir(&foreign).unwrap();
    fs::write(foreign.join("notes.txt"), "mine").unwrap();
    let foreign_before = util::snapshot(&foreign);
    let code = run_granular(
        &[
            "run",
            s(&m1),
            "--out",
            s(&foreign),
            "--threads",
            "2",
            "--quiet",
        ],
        &log,
        LIMIT,
    );
    assert_eq!(code, Some(3), "log:\n{}", log_text(&log));
    assert_eq!(
        util::snapshot(&foreign),
        foreign_before,
        "refused run touched a foreign directory"
    );
    // `resume` of a directory that is no campaign is refused as well.
    let code = run_granular(
        &["resume", s(&foreign), "--threads", "1", "--quiet"],
        &log,
        LIMIT,
    );
    assert_eq!(code, Some(3), "log:\n{}", log_text(&log));

    // The same manifest again, then resume: nothing to do, no table changes (bit for bit,
    // wall_seconds included, since no run is redone).
    let code = run_granular(
        &["run", s(&m1), "--out", s(&e), "--threads", "2", "--quiet"],
        &log,
        LIMIT,
    );
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let code = run_granular(&["resume", s(&e), "--threads", "2", "--quiet"], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let after_tables = read_tables(&e);
    let diffs = util::table_differences(&before_tables, &after_tables, &[]);
    assert!(
        diffs.is_empty(),
        "re-running a finished campaign changed its tables:\n{}",
        diffs.join("\n")
    );
    assert_eq!(
        after_tables["runs"].files, before_tables["runs"].files,
        "re-running added table parts"
    );
}

/// `granular status DIR --json` after completion: every run done, per point too.
#[test]
fn status_json_after_completion() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let m = dir.path().join("m.json");
    util::write_json(&m, &small_manifest(5));
    let e = dir.path().join("E");
    let st = {
        // Before any run the directory is not a campaign.
        let (code, _) = util::run_capture(&["status", s(&e), "--json"], &log);
        assert_eq!(
            code,
            Some(3),
            "status of a missing directory; log:\n{}",
            log_text(&log)
        );
        let code = run_granular(
            &["run", s(&m), "--out", s(&e), "--threads", "2", "--quiet"],
            &log,
            LIMIT,
        );
        assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
        status_json(&e, &log)
    };
    assert_eq!(st["name"], json!("small"), "{st}");
    for (k, want) in [
        ("runs", 4),
        ("done", 4),
        ("failed", 0),
        ("running", 0),
        ("pending", 0),
        ("checkpointed", 0),
    ] {
        assert_eq!(st[k].as_u64(), Some(want), "status {k}: {st}");
    }
    assert_eq!(st["live_shards"], json!([]), "{st}");
    let points = st["points"]
        .as_array()
        .unwrap_or_else(|| panic!("no points: {st}"));
    assert_eq!(points.len(), 2, "{st}");
    for (i, p) in points.iter().enumerate() {
        assert_eq!(p["point_id"].as_u64(), Some(i as u64), "{st}");
        assert_eq!(
            (
                p["done"].as_u64(),
                p["pending"].as_u64(),
                p["failed"].as_u64()
            ),
            (Some(2), Some(0), Some(0)),
            "{st}"
        );
    }
    assert!(
        points[0]["point"].as_str().unwrap().contains("low_rank")
            && points[1]["point"].as_str().unwrap().contains("bird"),
        "{st}"
    );
}

/// A finished small campaign in `dir/E`; returns (campaign dir, log, its tables).
fn finished_small(dir: &Path) -> (PathBuf, PathBuf, Tables) {
    let log = dir.join("log");
    let m = dir.join("m.json");
    util::write_json(&m, &small_manifest(9));
    let e = dir.join("E");
    let code = run_granular(
        &["run", s(&m), "--out", s(&e), "--threads", "2", "--quiet"],
        &log,
        LIMIT,
    );
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let t = read_tables(&e);
    check_complete(&t, 4, "small campaign");
    (e, log, t)
}

/// The ledger's recovery, staged by hand: a part whose commit record exists but which was
/// not yet renamed (a crash between commit point and rename) is rolled forward; a part with
/// no commit record (a crash before the commit point) is rolled back. Either way the tables
/// end as before, with no duplicated rows.
#[test]
fn interrupted_commits_are_recovered_on_resume() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let (e, log, before) = finished_small(dir.path());
    let runs_dir = e.join("tables/runs");
    let part = runs_dir.join(&before["runs"].files[0]);
    let name = part.file_name().unwrap().to_string_lossy().into_owned();
    // Roll forward: the committed part is back under its pending name.
    fs::rename(&part, runs_dir.join(format!(".{name}.pending"))).unwrap();
    // Roll back: an uncommitted part (a copy of real rows, so it would double them).
    let species_dir = e.join("tables/dsmc_species");
    let sp = species_dir.join(&before["dsmc_species"].files[0]);
    let orphan = species_dir.join(".part-s1of1-00000099.parquet.pending");
    fs::copy(&sp, &orphan).unwrap();
    let code = run_granular(&["resume", s(&e), "--threads", "2", "--quiet"], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    assert!(
        part.exists(),
        "the committed part was not rolled forward; log:\n{}",
        log_text(&log)
    );
    assert!(
        !orphan.exists(),
        "the uncommitted part was not rolled back; log:\n{}",
        log_text(&log)
    );
    let after = read_tables(&e);
    let diffs = util::table_differences(&before, &after, &[]);
    assert!(
        diffs.is_empty(),
        "recovery changed the tables:\n{}",
        diffs.join("\n")
    );
}

/// Temporary files that a killed process leaves behind (a checkpoint or a summary being
/// written: hidden `.NAME.<pid>-<nanos>@<host>.tmp`, possibly as large as a whole checkpoint) are removed
/// by the next run or resume of the campaign once their process is dead, like uncommitted
/// parts are; otherwise every kill during a write leaks up to one checkpoint of disk.
#[test]
fn stale_temporary_files_are_removed_on_resume() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let (e, log, before) = finished_small(dir.path());
    let pid = dead_pid();
    // Named as `fsutil::temp_path` names them (`.NAME.<pid>-<nanos>@<host>.tmp`) in a process
    // `pid` of this host.
    let host = granular::fsutil::host_tag();
    let stale = [
        e.join(format!(
            "checkpoints/.run-0000000001.ckpt.{pid}-123456789@{host}.tmp"
        )),
        e.join(format!(
            "tables/dsmc_species_summary/.summary.parquet.{pid}-987654321@{host}.tmp"
        )),
    ];
    for p in &stale {
        fs::write(p, vec![0u8; 4096]).unwrap();
    }
    let code = run_granular(&["resume", s(&e), "--threads", "2", "--quiet"], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let after = read_tables(&e);
    assert!(util::table_differences(&before, &after, &[]).is_empty());
    let left: Vec<&PathBuf> = stale.iter().filter(|p| p.exists()).collect();
    assert!(
        left.is_empty(),
        "stale temporary files of a dead process (pid {pid}) survive a resume: {left:?}"
    );
}
