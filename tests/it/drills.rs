//! Reliability drills: a second process on a running shard, corrupted checkpoints, truncated
//! and foreign Parquet parts, a full disk, compaction in the middle of a campaign. (Repeated
//! SIGKILLs are `resume::kill_9_and_resume_gives_identical_tables`.)

use std::fs;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serde_json::{json, Value};

use super::util::s;
use super::util::{
    self, granular, heavy, log_text, read_tables, run_capture, run_granular, wait_limited,
    write_json, Tables,
};

const LIMIT: Duration = Duration::from_secs(300);

/// 4 runs of ~0.5-1 s each (N1 = 1.5e5, t_end = 40): long enough to be caught running.
fn slow_manifest() -> Value {
    json!({
        "name": "drill",
        "model": "dsmc",
        "seed": 4242,
        "replicas": 2,
        "params": {
            "method": "low_rank",
            "species": {"power_law": {"n1": 0.1, "N1": 150000, "theta": 3}},
            "restitution": {"constant": 0.8},
            "t_end": 40.0,
            "output_times": {"log": {"from": 0.1, "to": 40.0, "per_decade": 4}},
            "observables": ["msd"]
        },
        "sweep": {"restitution.constant": [0.8, 0.6]}
    })
}

/// The uninterrupted run of `m` into `dir/ref`.
fn reference(dir: &Path, m: &Path, log: &Path) -> Tables {
    let r = dir.join("ref");
    let code = run_granular(
        &["run", s(m), "--out", s(&r), "--threads", "2", "--quiet"],
        log,
        LIMIT,
    );
    assert_eq!(code, Some(0), "reference run failed:\n{}", log_text(log));
    read_tables(&r)
}

fn wait_for(what: &str, limit: Duration, mut cond: impl FnMut() -> bool) {
    let start = Instant::now();
    while !cond() {
        assert!(start.elapsed() < limit, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn checkpoints(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = fs::read_dir(dir.join("checkpoints"))
        .map(|it| {
            it.filter_map(|e| e.ok())
                .map(|e| e.path())
                .filter(|p| {
                    let n = p.file_name().unwrap().to_string_lossy();
                    n.starts_with("run-") && n.ends_with(".ckpt")
                })
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

fn sigint(pid: u32) {
    // SAFETY: a signal to our own child.
    assert_eq!(unsafe { libc::kill(pid as libc::pid_t, libc::SIGINT) }, 0);
}

/// While a shard runs, a second process on the same shard, on a different shard layout, and
/// a compaction are all refused (exit 3) without touching anything.
#[test]
fn second_process_on_a_running_shard_is_refused() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let m = dir.path().join("m.json");
    write_json(&m, &slow_manifest());
    let log = dir.path().join("log");
    let b = dir.path().join("B");
    let mut child = granular(
        &["run", s(&m), "--out", s(&b), "--threads", "1", "--quiet"],
        &log,
    )
    .spawn()
    .unwrap();
    wait_for("the shard lock", Duration::from_secs(60), || {
        b.join("locks/s1of1.lock").exists()
    });
    for args in [
        vec!["resume", s(&b), "--threads", "1", "--quiet"],
        vec!["run", s(&m), "--out", s(&b), "--threads", "1", "--quiet"],
        vec!["resume", s(&b), "--shard", "1/2", "--quiet"],
        vec!["compact", s(&b)],
    ] {
        let (code, _) = run_capture(&args, &log);
        assert_eq!(
            code,
            Some(3),
            "`granular {}` while shard 1/1 runs: log:\n{}",
            args.join(" "),
            log_text(&log)
        );
    }
    assert!(
        log_text(&log).contains("in use"),
        "no 'in use' message:\n{}",
        log_text(&log)
    );
    let st = wait_limited(&mut child, LIMIT, "the first process", &log);
    assert_eq!(st.code(), Some(0), "log:\n{}", log_text(&log));
}

/// A checkpoint with a flipped byte is detected by its CRC: the run restarts from its
/// previous good checkpoint, or from t = 0 when both are damaged (one truncated), with a
/// warning; the final tables are those of an uninterrupted run.
#[test]
fn corrupted_checkpoints_are_detected_and_runs_restart_identically() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let m = dir.path().join("m.json");
    write_json(&m, &slow_manifest());
    let log = dir.path().join("log");
    let want = reference(dir.path(), &m, &log);
    let b = dir.path().join("B");
    let mut child = granular(
        &[
            "run",
            s(&m),
            "--out",
            s(&b),
            "--threads",
            "2",
            "--checkpoint-every",
            "0.02",
            "--quiet",
        ],
        &log,
    )
    .spawn()
    .unwrap();
    // Both running runs have a current and a previous checkpoint.
    wait_for("two checkpoints with .prev", LIMIT, || {
        let c = checkpoints(&b);
        c.len() >= 2 && c.iter().all(|p| p.with_extension("ckpt.prev").exists())
    });
    sigint(child.id());
    let st = wait_limited(&mut child, LIMIT, "interrupted run", &log);
    assert_eq!(st.code(), Some(130), "log:\n{}", log_text(&log));
    let c = checkpoints(&b);
    assert!(c.len() >= 2, "checkpoints after Ctrl-C: {c:?}");
    // Run A: flip one byte in the middle of the current checkpoint (the .prev is good).
    let mut bytes = fs::read(&c[0]).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x40;
    fs::write(&c[0], &bytes).unwrap();
    // Run B: truncate the current one and flip the previous one: nothing usable.
    let bytes = fs::read(&c[1]).unwrap();
    fs::write(&c[1], &bytes[..bytes.len() / 3]).unwrap();
    let prev = c[1].with_extension("ckpt.prev");
    let mut pb = fs::read(&prev).unwrap();
    let last = pb.len() - 1;
    pb[last] ^= 1;
    fs::write(&prev, &pb).unwrap();
    let code = run_granular(&["resume", s(&b), "--threads", "2", "--quiet"], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let text = log_text(&log);
    assert!(
        text.contains("checksum mismatch"),
        "no checksum warning:\n{text}"
    );
    assert!(
        text.contains("truncated or padded"),
        "no truncation warning:\n{text}"
    );
    assert!(
        text.contains("restarting from t = 0") || text.contains("from zero"),
        "no restart-from-zero warning:\n{text}"
    );
    util::assert_tables_identical(&want, &read_tables(&b), "after corrupted checkpoints");
}

/// A finished campaign with a small run of another campaign beside it.
fn two_campaigns(dir: &Path, log: &Path) -> (PathBuf, PathBuf) {
    let mut small = slow_manifest();
    small["params"]["species"]["power_law"]["N1"] = json!(2000);
    small["params"]["t_end"] = json!(5.0);
    small["params"]["output_times"] = json!({"list": [1.0, 5.0]});
    let m = dir.join("m.json");
    write_json(&m, &small);
    let a = dir.join("A");
    let code = run_granular(
        &[
            "run",
            s(&m),
            "--out",
            s(&a),
            "--threads",
            "2",
            "--quiet",
            "--flush-every",
            "0",
        ],
        log,
        LIMIT,
    );
    assert_eq!(code, Some(0), "log:\n{}", log_text(log));
    small["seed"] = json!(1);
    let m2 = dir.join("m2.json");
    write_json(&m2, &small);
    let other = dir.join("other");
    let code = run_granular(
        &[
            "run",
            s(&m2),
            "--out",
            s(&other),
            "--threads",
            "2",
            "--quiet",
        ],
        log,
        LIMIT,
    );
    assert_eq!(code, Some(0), "log:\n{}", log_text(log));
    (a, other)
}

fn first_part(dir: &Path, table: &str) -> PathBuf {
    let mut v: Vec<PathBuf> = fs::read_dir(dir.join("tables").join(table))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "parquet"))
        .collect();
    v.sort();
    v.remove(0)
}

/// A truncated part and a part of another campaign are reported by `verify` and refused by
/// `compact` (exit 3, naming the file); a summary never reads them as data.
#[test]
fn truncated_and_foreign_parquet_parts_are_detected() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let (a, other) = two_campaigns(dir.path(), &log);
    let (code, out) = run_capture(&["verify", s(&a)], &log);
    assert_eq!(code, Some(0), "clean campaign: {out}\n{}", log_text(&log));

    // Truncated: the footer is gone.
    let part = first_part(&a, "dsmc_species");
    let bytes = fs::read(&part).unwrap();
    fs::write(&part, &bytes[..bytes.len() - 100]).unwrap();
    let (code, _) = run_capture(&["verify", s(&a)], &log);
    assert_eq!(code, Some(3));
    let text = log_text(&log);
    assert!(
        text.contains(&part.file_name().unwrap().to_string_lossy().to_string())
            && text.contains("not a readable Parquet file"),
        "verify did not name the truncated part:\n{text}"
    );
    let (code, _) = run_capture(&["compact", s(&a)], &log);
    assert_eq!(code, Some(3), "compact of a campaign with a truncated part");
    fs::write(&part, &bytes).unwrap();

    // Foreign: a valid part of the other campaign (same table, same schema) copied in.
    let foreign = a
        .join("tables/dsmc_species")
        .join("part-s1of1-99999999.parquet");
    fs::copy(first_part(&other, "dsmc_species"), &foreign).unwrap();
    let before = fs::read_to_string(&log).unwrap_or_default().len();
    let (code, _) = run_capture(&["verify", s(&a)], &log);
    assert_eq!(code, Some(3));
    let text = log_text(&log)[before..].to_string();
    assert!(
        text.contains("part-s1of1-99999999.parquet") && text.contains("another campaign"),
        "verify did not report the foreign part:\n{text}"
    );
    let (code, _) = run_capture(&["compact", s(&a)], &log);
    assert_eq!(code, Some(3), "compact of a campaign with a foreign part");
    // A foreign runs part doubles nothing unnoticed either: verify counts runs.
    fs::remove_file(&foreign).unwrap();
    let foreign_runs = a.join("tables/runs").join("part-s1of1-99999999.parquet");
    fs::copy(first_part(&a, "runs"), &foreign_runs).unwrap();
    let before = fs::read_to_string(&log).unwrap_or_default().len();
    let (code, _) = run_capture(&["verify", s(&a)], &log);
    assert_eq!(code, Some(3));
    assert!(
        log_text(&log)[before..].contains("more than once"),
        "a doubled runs part was not reported:\n{}",
        log_text(&log)
    );
}

/// A foreign part (another campaign's) in the tables of a campaign whose last shard then
/// finishes is never averaged into the summaries: the shard's check finds a part in no
/// commit, sets it aside (naming it and why: another campaign's) and finishes (exit 0) with
/// `verify` clean and the foreign part out of the tables.
#[test]
fn summaries_refuse_a_foreign_part() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let (_, other) = two_campaigns(dir.path(), &log);
    let m = dir.path().join("m.json");
    let c = dir.path().join("C");
    let code = run_granular(
        &["run", s(&m), "--out", s(&c), "--shard", "1/2", "--quiet"],
        &log,
        LIMIT,
    );
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let foreign = c
        .join("tables/dsmc_species")
        .join("part-x-00000001.parquet");
    fs::copy(first_part(&other, "dsmc_species"), &foreign).unwrap();
    let code = run_granular(&["resume", s(&c), "--shard", "2/2", "--quiet"], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    assert!(
        log_text(&log).contains("part-x-00000001.parquet")
            && log_text(&log).contains("another campaign")
            && log_text(&log).contains("set aside"),
        "log:\n{}",
        log_text(&log)
    );
    assert!(!foreign.exists(), "the foreign part is still in the table");
    let (code, out) = run_capture(&["verify", s(&c)], &log);
    assert_eq!(code, Some(0), "{out}\n{}", log_text(&log));
    // The summaries average this campaign's runs only: those of a campaign run whole.
    let whole = dir.path().join("whole");
    assert_eq!(
        run_granular(&["run", s(&m), "--out", s(&whole), "--quiet"], &log, LIMIT),
        Some(0)
    );
    util::assert_tables_identical(
        &read_tables(&whole),
        &read_tables(&c),
        "after a foreign part",
    );
}

/// A full disk (simulated with RLIMIT_FSIZE = 4 kB set on the running process: every larger
/// write fails with EFBIG) while the tables are written: a clear error (exit 4), no partial or
/// uncommitted file left visible, the ledger consistent; after "space is freed" (a new
/// process without the limit) the campaign resumes to the uninterrupted tables.
#[test]
fn disk_full_is_a_clear_error_and_the_campaign_resumes() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let m = dir.path().join("m.json");
    write_json(&m, &slow_manifest());
    let log = dir.path().join("log");
    let want = reference(dir.path(), &m, &log);
    let b = dir.path().join("B");
    let mut cmd = granular(
        &[
            "run",
            s(&m),
            "--out",
            s(&b),
            "--threads",
            "1",
            "--flush-every",
            "0",
            "--quiet",
        ],
        &log,
    );
    // SAFETY: async-signal-safe call between fork and exec.
    unsafe {
        cmd.pre_exec(|| {
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            Ok(())
        });
    }
    let mut child = cmd.spawn().unwrap();
    // Once the campaign's fixed tables exist, the disk "fills up".
    wait_for("the theory tables", LIMIT, || {
        b.join("tables/dsmc_theory_point")
            .read_dir()
            .is_ok_and(|mut d| {
                d.any(|e| e.is_ok_and(|e| e.file_name().to_string_lossy().ends_with(".parquet")))
            })
    });
    let lim = libc::rlimit {
        rlim_cur: 4096,
        rlim_max: libc::RLIM_INFINITY,
    };
    // SAFETY: setting a resource limit of our child.
    let rc = unsafe {
        libc::prlimit(
            child.id() as libc::pid_t,
            libc::RLIMIT_FSIZE,
            &lim,
            std::ptr::null_mut(),
        )
    };
    assert_eq!(rc, 0, "prlimit failed");
    let st = wait_limited(&mut child, LIMIT, "run on a full disk", &log);
    assert_eq!(st.code(), Some(4), "log:\n{}", log_text(&log));
    let text = log_text(&log);
    assert!(
        text.contains("writing the tables failed") && text.contains("File too large"),
        "unclear error:\n{text}"
    );
    // Nothing partial: no pending or temporary files, every visible file checks out.
    let mut stack = vec![b.clone()];
    while let Some(d) = stack.pop() {
        for e in fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            let n = p.file_name().unwrap().to_string_lossy().into_owned();
            assert!(
                !n.ends_with(".pending") && !n.ends_with(".tmp"),
                "partial file left: {}",
                p.display()
            );
            if p.is_dir() && !fs::symlink_metadata(&p).unwrap().file_type().is_symlink() {
                stack.push(p);
            }
        }
    }
    let (code, out) = run_capture(&["verify", s(&b)], &log);
    assert_eq!(
        code,
        Some(0),
        "verify after a full disk: {out}\n{}",
        log_text(&log)
    );
    let code = run_granular(&["resume", s(&b), "--threads", "2", "--quiet"], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    util::assert_tables_identical(&want, &read_tables(&b), "after a full disk and resume");
}

/// Compaction between shards: shard 1 of 2 runs, the campaign is compacted (parts merged,
/// commit records folded into ledger/index.json), shard 2 runs and the campaign is compacted
/// again; the tables equal a single run's, status counts every run once.
#[test]
fn compaction_mid_campaign_keeps_tables_and_ledger_exact() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let mut small = slow_manifest();
    small["params"]["species"]["power_law"]["N1"] = json!(3000);
    small["params"]["t_end"] = json!(5.0);
    small["params"]["output_times"] = json!({"list": [1.0, 5.0]});
    small["replicas"] = json!(4);
    let m = dir.path().join("m.json");
    write_json(&m, &small);
    let want = reference(dir.path(), &m, &log);
    let c = dir.path().join("C");
    for (shard, first) in [("1/2", true), ("2/2", false)] {
        let mut args = if first {
            vec!["run", s(&m), "--out", s(&c)]
        } else {
            vec!["resume", s(&c)]
        };
        args.extend(["--shard", shard, "--flush-every", "0", "--quiet"]);
        assert_eq!(
            run_granular(&args, &log, LIMIT),
            Some(0),
            "{}",
            log_text(&log)
        );
        let (code, out) = run_capture(&["compact", s(&c), "--target-size", "1MB"], &log);
        assert_eq!(code, Some(0), "{out}\n{}", log_text(&log));
        assert!(c.join("ledger/index.json").exists());
        let st = util::status_json(&c, &log);
        let done = if first { 4 } else { 8 };
        assert_eq!(st["done"].as_u64(), Some(done), "{st}");
        assert_eq!(st["pending"].as_u64(), Some(8 - done), "{st}");
    }
    // One merged file per table of parts; the commit records are folded away.
    let runs_files = fs::read_dir(c.join("tables/runs")).unwrap().count();
    assert_eq!(runs_files, 1, "runs parts after compaction");
    let commits: Vec<_> = fs::read_dir(c.join("ledger"))
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.path().is_dir())
        .flat_map(|d| fs::read_dir(d.path()).unwrap().filter_map(|e| e.ok()))
        .collect();
    assert!(commits.is_empty(), "commit records left: {}", commits.len());
    util::assert_tables_identical(&want, &read_tables(&c), "compacted between shards");
    let (code, out) = run_capture(&["verify", s(&c)], &log);
    assert_eq!(code, Some(0), "{out}");
    // Finished and compacted: a rerun does nothing.
    assert_eq!(
        run_granular(&["resume", s(&c), "--quiet"], &log, LIMIT),
        Some(0)
    );
    util::assert_tables_identical(&want, &read_tables(&c), "resumed after compaction");
}

/// `granular ARGS` as a process that cannot write the campaign directory `c` (a read-only
/// file system or no permission, as far as granular can tell): as root (whom permissions do
/// not stop) it runs as `nobody`, else `c` and its `locks` are made read-only. Returns the
/// exit code and stderr.
fn without_write_permission(args: &[&str], c: &Path, log: &Path) -> (Option<i32>, String) {
    use std::os::unix::fs::PermissionsExt;
    // SAFETY: geteuid has no preconditions.
    let root = unsafe { libc::geteuid() } == 0;
    let mode = |p: &Path, m: u32| fs::set_permissions(p, fs::Permissions::from_mode(m)).unwrap();
    if root {
        // `nobody` must reach the campaign: every directory above it readable and searchable.
        let mut p = c.parent();
        while let Some(d) = p {
            if d.starts_with(std::env::temp_dir()) && d != std::env::temp_dir() {
                mode(d, 0o755);
            }
            p = d.parent();
        }
    } else {
        mode(&c.join("locks"), 0o555);
        mode(c, 0o555);
    }
    let mut cmd = granular(args, log);
    if root {
        // SAFETY: async-signal-safe calls between fork and exec.
        unsafe {
            cmd.pre_exec(|| {
                if libc::setgroups(0, std::ptr::null()) != 0
                    || libc::setresgid(65534, 65534, 65534) != 0
                    || libc::setresuid(65534, 65534, 65534) != 0
                {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
    }
    let before = log_text(log).len();
    let code = wait_limited(&mut cmd.spawn().unwrap(), LIMIT, &args.join(" "), log).code();
    if !root {
        mode(c, 0o755);
        mode(&c.join("locks"), 0o755);
    }
    (code, log_text(log)[before..].to_string())
}

/// A lock that cannot be written (a read-only campaign directory, no permission) is an I/O
/// error (exit 4, README "Exit codes"), never "locked" (3): at a shard's lock (`resume`),
/// also where a stale lock of a dead process must be removed first, and at the exclusive
/// lock (`compact`).
#[test]
fn an_unwritable_lock_is_an_io_error() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let m = dir.path().join("m.json");
    write_json(
        &m,
        &json!({
            "name": "ro",
            "model": "dsmc",
            "seed": 3,
            "replicas": 1,
            "params": {
                "method": "low_rank",
                "species": {"power_law": {"n1": 0.1, "N1": 1000, "theta": 3}},
                "restitution": {"constant": 0.5},
                "t_end": 2.0,
                "output_times": {"list": [1.0]},
                "observables": ["temperature"]
            }
        }),
    );
    let c = dir.path().join("c");
    assert_eq!(
        run_granular(&["run", s(&m), "--out", s(&c), "--quiet"], &log, LIMIT),
        Some(0),
        "{}",
        log_text(&log)
    );
    let lock = c.join("locks").join("s1of1.lock");
    for (what, args, stale) in [
        ("resume", ["resume", s(&c)], false),
        ("resume over a stale lock", ["resume", s(&c)], true),
        ("compact", ["compact", s(&c)], false),
    ] {
        if stale {
            let info = json!({
                "pid": util::dead_pid(),
                "host": granular::campaign::ledger::hostname(),
                "shard": "1/1",
                "shard_tag": "s1of1",
                "shard_count": 1
            });
            fs::write(&lock, info.to_string()).unwrap();
            // Left by an earlier takeover of a stale lock (a campaign resumed after a kill):
            // the takeover itself is then possible, only the stale lock cannot be removed.
            fs::write(c.join("locks").join("takeover.flock"), "").unwrap();
        }
        let (code, err) = without_write_permission(&args, &c, &log);
        assert_eq!(code, Some(4), "{what}:\n{err}");
        assert!(err.contains("locks/"), "{what}: the lock is named:\n{err}");
        assert!(
            !err.contains("try again"),
            "{what}: not a lock held:\n{err}"
        );
    }
}
