//! Damage to a campaign directory never passes silently (issue 14): each drill damages a copy
//! of a finished campaign, of the same campaign compacted, and of a half-finished one (bytes flipped in a part, a part, a table, a commit record, the
//! ledger deleted; a corrupt record or index; a foreign or orphan file), then asserts the
//! promised outcome: `verify` (the full scrub) names the damage (exit 3); `status` (the quick
//! check, sizes only) exits 3 where sizes show it; `compact` refuses it (exit 3) and changes
//! nothing; `resume` heals it (exit 0, each action logged) to tables identical to the undamaged
//! campaign's, which `verify` then passes. A lock whose pid now belongs to another process is
//! stale; a compaction killed at any moment is finished by the next command.

use std::fs;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde_json::{json, Value};

use super::util::{
    self, heavy, log_text, read_tables, run_capture, run_granular, write_json, Tables,
};
use super::util::{copy_dir, s};

const LIMIT: Duration = Duration::from_secs(300);

/// 4 small runs (two points x two replicas), committed one by one (`--flush-every 0`), so the
/// ledger has four commit records.
fn manifest() -> Value {
    json!({
        "name": "damage",
        "model": "dsmc",
        "seed": 77,
        "replicas": 2,
        "params": {
            "method": "low_rank",
            "species": {"power_law": {"n1": 0.1, "N1": 4000, "theta": 3}},
            "restitution": {"constant": 0.9},
            "t_end": 200.0,
            "output_times": {"list": [1.0, 10.0, 100.0]},
            "observables": ["msd"]
        },
        "sweep": {"method": ["low_rank", "bird"]}
    })
}

/// `granular run m --out out EXTRA --flush-every 0` (every run its own commit), which must
/// succeed.
fn run_committing_each(m: &Path, out: &Path, extra: &[&str], log: &Path) {
    let mut args = vec![
        "run",
        s(m),
        "--out",
        s(out),
        "--flush-every",
        "0",
        "--quiet",
    ];
    args.extend_from_slice(extra);
    assert_eq!(
        run_granular(&args, log, LIMIT),
        Some(0),
        "{}",
        log_text(log)
    );
}

/// Flip 8 bytes in the middle of a file (its size unchanged).
fn flip(p: &Path) {
    let mut b = fs::read(p).unwrap();
    let m = b.len() / 2;
    for x in &mut b[m..m + 8] {
        *x ^= 0xff;
    }
    fs::write(p, b).unwrap();
}

/// The `i`-th visible Parquet file of a table (sorted), or its last (a compacted table has
/// fewer).
fn nth(dir: &Path, table: &str, i: usize) -> PathBuf {
    let v = files(dir, table);
    v[i.min(v.len() - 1)].clone()
}

/// The visible Parquet files of a table, sorted.
fn files(dir: &Path, table: &str) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = fs::read_dir(dir.join("tables").join(table))
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| {
            let n = p.file_name().unwrap().to_string_lossy();
            !n.starts_with('.') && n.ends_with(".parquet")
        })
        .collect();
    v.sort();
    v
}

struct Drill {
    name: &'static str,
    /// Whether the quick check (`status`, sizes) sees it; a flip of bytes it cannot.
    quick_sees: bool,
    /// Whether `resume` must run runs again (else it only rebuilds a table or a record).
    reruns: bool,
    damage: fn(&Path),
}

fn drills() -> Vec<Drill> {
    vec![
        Drill {
            name: "8 bytes flipped in a dsmc_species part",
            quick_sees: false,
            reruns: true,
            damage: |d| flip(&nth(d, "dsmc_species", 1)),
        },
        Drill {
            name: "8 bytes flipped in a runs part",
            quick_sees: false,
            reruns: true,
            damage: |d| flip(&nth(d, "runs", 0)),
        },
        Drill {
            name: "8 bytes flipped in dsmc_theory",
            quick_sees: false,
            reruns: false,
            damage: |d| flip(&nth(d, "dsmc_theory", 0)),
        },
        Drill {
            name: "8 bytes flipped in dsmc_species_summary",
            quick_sees: false,
            reruns: false,
            damage: |d| flip(&nth(d, "dsmc_species_summary", 0)),
        },
        Drill {
            name: "a part truncated",
            quick_sees: true,
            reruns: true,
            damage: |d| {
                let p = &nth(d, "dsmc_species", 2);
                let n = fs::metadata(p).unwrap().len();
                fs::OpenOptions::new()
                    .write(true)
                    .open(p)
                    .unwrap()
                    .set_len(n / 2)
                    .unwrap();
            },
        },
        Drill {
            name: "rm -rf tables",
            quick_sees: true,
            reruns: true,
            damage: |d| fs::remove_dir_all(d.join("tables")).unwrap(),
        },
        Drill {
            name: "one runs part deleted",
            quick_sees: true,
            reruns: true,
            damage: |d| fs::remove_file(&nth(d, "runs", 3)).unwrap(),
        },
        Drill {
            name: "a summary deleted",
            quick_sees: false,
            reruns: false,
            damage: |d| fs::remove_file(&nth(d, "dsmc_species_summary", 0)).unwrap(),
        },
        Drill {
            name: "rm -rf ledger",
            quick_sees: true,
            reruns: false,
            damage: |d| fs::remove_dir_all(d.join("ledger")).unwrap(),
        },
        Drill {
            name: "one commit record deleted",
            quick_sees: true,
            reruns: false,
            damage: |d| {
                let dir = fs::read_dir(d.join("ledger"))
                    .unwrap()
                    .next()
                    .unwrap()
                    .unwrap()
                    .path();
                fs::remove_file(dir.join("commit-00000002.json")).unwrap()
            },
        },
        Drill {
            name: "a commit record corrupted",
            quick_sees: true,
            reruns: false,
            damage: |d| {
                fs::write(d.join("ledger/s1of1/commit-00000003.json"), b"{\"format").unwrap()
            },
        },
        Drill {
            name: "a commit record doubled under another shard",
            quick_sees: true,
            reruns: false,
            damage: |d| {
                let dir = fs::read_dir(d.join("ledger"))
                    .unwrap()
                    .next()
                    .unwrap()
                    .unwrap()
                    .path();
                let text = fs::read_to_string(dir.join("commit-00000001.json")).unwrap();
                let mut v: Value = serde_json::from_str(&text).unwrap();
                v["shard"] = json!("s9of9");
                fs::create_dir_all(d.join("ledger/s9of9")).unwrap();
                write_json(&d.join("ledger/s9of9/commit-00000001.json"), &v);
            },
        },
        Drill {
            name: "a part copied under another commit's name",
            quick_sees: true,
            reruns: false,
            damage: |d| {
                fs::copy(
                    &nth(d, "runs", 0),
                    d.join("tables/runs/part-s1of1-00000009.parquet"),
                )
                .unwrap();
            },
        },
        Drill {
            name: "a foreign file in a table",
            quick_sees: true,
            reruns: false,
            damage: |d| fs::write(d.join("tables/runs/notes.txt"), b"hello").unwrap(),
        },
        Drill {
            name: "a checksum sidecar deleted",
            quick_sees: true,
            reruns: false,
            damage: |d| fs::remove_file(d.join("sums/points/points.parquet.sum.json")).unwrap(),
        },
    ]
}

/// Every drill on a copy of one finished campaign (and of the same campaign compacted).
#[test]
fn damage_is_named_refused_or_healed_to_identical_tables() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let m = dir.path().join("m.json");
    write_json(&m, &manifest());
    let base = dir.path().join("base");
    run_committing_each(&m, &base, &[], &log);
    let want: Tables = read_tables(&base);
    let compacted = dir.path().join("compacted");
    copy_dir(&base, &compacted);
    let (code, out) = run_capture(&["compact", s(&compacted), "--target-size", "1MB"], &log);
    assert_eq!(code, Some(0), "{out}{}", log_text(&log));
    util::assert_tables_identical(&want, &read_tables(&compacted), "compacted");

    // Half-finished: shard 1 of 2 done (runs 0 and 2), committed one by one.
    let half = dir.path().join("half");
    run_committing_each(&m, &half, &["--shard", "1/2"], &log);

    let mut table = Vec::new();
    for (k, d) in drills().into_iter().enumerate() {
        for (from, layout) in [
            (&base, "commits"),
            (&compacted, "compacted"),
            (&half, "half"),
        ] {
            // Drills that name commit records apply to the campaigns that have them; a
            // half-finished campaign has no summary yet and two commits.
            let summary = d.name.contains("summary");
            if (layout == "compacted" && d.name.contains("commit record"))
                || (layout == "half" && (summary || d.name.contains("commit record corrupted")))
            {
                continue;
            }
            let c = dir.path().join(format!("d{k}-{layout}"));
            copy_dir(from, &c);
            (d.damage)(&c);
            let what = format!("{} ({layout})", d.name);

            let (v, vout) = run_capture(&["verify", s(&c)], &log);
            assert_eq!(
                v,
                Some(3),
                "{what}: verify passed damage:\n{vout}\n{}",
                log_text(&log)
            );
            let (st, _) = run_capture(&["status", s(&c)], &log);
            if d.quick_sees {
                assert_eq!(
                    st,
                    Some(3),
                    "{what}: status did not see it\n{}",
                    log_text(&log)
                );
            }
            // Everything but `locks/` (where the refusing compaction's lock came and went).
            let files_of = |c: &Path| {
                let mut m = util::snapshot(c);
                m.retain(|p, _| !p.starts_with(c.join("locks")));
                m
            };
            let before = files_of(&c);
            let (cc, _) = run_capture(&["compact", s(&c)], &log);
            assert_eq!(
                cc,
                Some(3),
                "{what}: compact did not refuse\n{}",
                log_text(&log)
            );
            assert!(
                files_of(&c) == before,
                "{what}: the refused compact changed files"
            );

            fs::write(&log, "").unwrap();
            let code = run_granular(&["resume", s(&c)], &log, LIMIT);
            let text = log_text(&log);
            assert_eq!(code, Some(0), "{what}: resume:\n{text}");
            assert!(
                text.contains("healed:"),
                "{what}: nothing logged as healed:\n{text}"
            );
            // "shard plan ... pending=N" once per round: runs ran again if some N is not 0.
            let reran = text
                .match_indices("pending=")
                .any(|(i, m)| !text[i + m.len()..].starts_with('0'));
            if layout != "half" {
                assert_eq!(reran, d.reruns, "{what}: runs run again: {reran}\n{text}");
            }
            let (v, vout) = run_capture(&["verify", s(&c)], &log);
            assert_eq!(
                v,
                Some(0),
                "{what}: verify after healing:\n{vout}\n{}",
                log_text(&log)
            );
            util::assert_tables_identical(&want, &read_tables(&c), &what);
            let (st, _) = run_capture(&["status", s(&c)], &log);
            assert_eq!(st, Some(0), "{what}: status after healing");
            table.push(format!(
                "{what}: verify 3, resume healed (runs again: {reran})"
            ));
        }
    }
    eprintln!("{}", table.join("\n"));
}

/// A lock left by a process whose pid now belongs to another process (recorded start time
/// differs) is stale: `resume` takes the shard instead of refusing.
#[test]
fn a_lock_of_a_reused_pid_is_stale() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let m = dir.path().join("m.json");
    write_json(&m, &manifest());
    let c = dir.path().join("c");
    assert_eq!(
        run_granular(&["validate", s(&m)], &log, LIMIT),
        Some(0),
        "{}",
        log_text(&log)
    );
    // A live process of this host (the test itself) with another start time.
    let host = fs::read_to_string("/proc/sys/kernel/hostname").unwrap();
    let lock = json!({
        "pid": std::process::id(), "host": host.trim(), "shard": "1/1", "shard_tag": "s1of1",
        "shard_count": 1, "start_time": 1
    });
    // The campaign must exist for resume: create it with run, then plant the lock.
    assert_eq!(
        run_granular(&["run", s(&m), "--out", s(&c), "--quiet"], &log, LIMIT),
        Some(0),
        "{}",
        log_text(&log)
    );
    write_json(&c.join("locks/s1of1.lock"), &lock);
    let code = run_granular(&["resume", s(&c), "--quiet"], &log, LIMIT);
    assert_eq!(
        code,
        Some(0),
        "a reused pid's lock blocked:\n{}",
        log_text(&log)
    );
    // The same lock with this process's real start time is live: refused (exit 3).
    let stat = fs::read_to_string("/proc/self/stat").unwrap();
    let start: u64 = stat
        .rsplit_once(')')
        .unwrap()
        .1
        .split_whitespace()
        .nth(19)
        .unwrap()
        .parse()
        .unwrap();
    let mut live = lock.clone();
    live["start_time"] = json!(start);
    write_json(&c.join("locks/s1of1.lock"), &live);
    let (code, _) = run_capture(&["resume", s(&c)], &log);
    assert_eq!(
        code,
        Some(3),
        "a live lock was not respected:\n{}",
        log_text(&log)
    );
}

/// A lock file left empty (its writer killed between creating and writing it) is taken for a
/// crash once it is 5 s old: the next command waits for that rather than giving up after a few
/// tries with "another process keeps taking it" (which a kill at the wrong moment of the drill
/// below once hit in CI).
#[test]
fn an_empty_lock_file_is_outwaited_and_taken_over() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let m = dir.path().join("m.json");
    write_json(&m, &manifest());
    let c = dir.path().join("c");
    assert_eq!(
        run_granular(&["run", s(&m), "--out", s(&c), "--quiet"], &log, LIMIT),
        Some(0),
        "{}",
        log_text(&log)
    );
    fs::write(c.join("locks").join("compact.lock"), "").unwrap();
    let (code, out) = run_capture(&["compact", s(&c)], &log);
    assert_eq!(code, Some(0), "{out}\n{}", log_text(&log));
    assert!(
        !log_text(&log).contains("keeps taking it"),
        "{}",
        log_text(&log)
    );
}

/// `granular compact` killed (SIGKILL) at moments spread over its run: the next `compact`
/// (or `resume`) finishes or redoes it; the tables equal the undamaged campaign's, `verify`
/// passes, no record is left beside its folded group.
#[test]
fn a_compaction_killed_at_any_moment_is_finished_by_the_next_command() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let m = dir.path().join("m.json");
    let mut man = manifest();
    man["replicas"] = json!(6);
    write_json(&m, &man);
    let base = dir.path().join("base");
    run_committing_each(&m, &base, &[], &log);
    let want = read_tables(&base);
    // How long a compaction takes here.
    let probe = dir.path().join("probe");
    copy_dir(&base, &probe);
    let t0 = std::time::Instant::now();
    let (code, _) = run_capture(&["compact", s(&probe), "--target-size", "1MB"], &log);
    assert_eq!(code, Some(0));
    let full = t0.elapsed();
    let mut rng = util::Lcg(2024);
    let mut interrupted = 0;
    for i in 0..12 {
        let c = dir.path().join(format!("k{i}"));
        copy_dir(&base, &c);
        let mut child = util::granular(&["compact", s(&c), "--target-size", "1MB"], &log)
            .spawn()
            .unwrap();
        let at = full.mul_f64(rng.next_f64());
        std::thread::sleep(at);
        let _ = child.kill();
        let st = child.wait().unwrap();
        if !st.success() {
            interrupted += 1;
        }
        let next = if i % 2 == 0 { "compact" } else { "resume" };
        let (code, out) = run_capture(&[next, s(&c)], &log);
        assert_eq!(
            code,
            Some(0),
            "{next} after a killed compaction:\n{out}\n{}",
            log_text(&log)
        );
        let (v, vout) = run_capture(&["verify", s(&c)], &log);
        assert_eq!(v, Some(0), "verify after a killed compaction:\n{vout}");
        assert!(!c.join("ledger/compaction.json").exists());
        util::assert_tables_identical(&want, &read_tables(&c), "killed compaction");
    }
    assert!(
        interrupted >= 3,
        "only {interrupted} kills landed ({full:?} per compaction)"
    );
}
