//! `granular submit --slurm` against stand-in `sbatch`/`squeue`/`scontrol` scripts (the real
//! one-node cluster is `scripts/slurm-test.sh`): scripts and record written, MaxArraySize
//! respected by packing, the compaction chained with afterok, `--dry-run` writes nothing,
//! `--missing` resubmits exactly the unfinished shards that are not queued, bad input refused;
//! array tasks run by hand give the single-machine tables; a grown manifest is resubmitted.

use std::fs;
use std::os::unix::fs::PermissionsExt;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use serde_json::{json, Value};

use super::util::{self, bin, heavy, log_text, read_tables, run_granular, write_json};

const LIMIT: Duration = Duration::from_secs(300);

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// 10 short runs (2 points x 5 replicas).
fn manifest() -> Value {
    json!({
        "name": "slurm-fake",
        "model": "dsmc",
        "seed": 99,
        "replicas": 5,
        "params": {
            "method": "low_rank",
            "species": {"power_law": {"n1": 0.1, "N1": 2000, "theta": 3}},
            "restitution": {"constant": 0.7},
            "t_end": 5.0,
            "output_times": {"list": [1.0, 5.0]},
            "observables": ["temperature"]
        },
        "sweep": {"restitution.constant": [0.7, 0.4]}
    })
}

/// Stand-ins: `sbatch` logs its arguments and prints job ids 101, 102, ...; `scontrol`
/// reports MaxArraySize = 3; `squeue` prints the file `squeue.out`.
fn fake_tools(dir: &Path) {
    let write = |name: &str, body: &str| {
        let p = dir.join(name);
        fs::write(&p, format!("#!/bin/sh\n{body}\n")).unwrap();
        fs::set_permissions(&p, fs::Permissions::from_mode(0o755)).unwrap();
    };
    let d = dir.display();
    write(
        "sbatch",
        &format!(
            "echo \"$@\" >> {d}/sbatch.log\nn=$(cat {d}/next 2>/dev/null || echo 101)\necho $((n + 1)) > {d}/next\necho \"$n;cluster\""
        ),
    );
    write(
        "scontrol",
        "echo 'MaxJobCount             = 10000'\necho 'MaxArraySize            = 3'",
    );
    write("squeue", &format!("cat {d}/squeue.out 2>/dev/null; exit 0"));
}

fn submit(dir: &Path, args: &[&str], log: &Path) -> (Option<i32>, String) {
    let f = fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(log)
        .unwrap();
    let out = Command::new(bin())
        .arg("submit")
        .args(args)
        .env("GRANULAR_SBATCH", dir.join("sbatch"))
        .env("GRANULAR_SQUEUE", dir.join("squeue"))
        .env("GRANULAR_SCONTROL", dir.join("scontrol"))
        .stdin(Stdio::null())
        .stderr(f)
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
    )
}

#[test]
fn submit_packs_chains_and_resubmits_missing_shards() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let t = dir.path();
    fake_tools(t);
    let m = t.join("m.json");
    write_json(&m, &manifest());
    let log = t.join("log");
    let c = t.join("C");
    let first = [
        s(&m),
        "--out",
        s(&c),
        "--slurm",
        "--tasks",
        "2",
        "--per-task-runs",
        "1",
        "--time",
        "00:05:00",
        "--partition",
        "short",
        "--sbatch-arg=--account=abc",
    ];

    // Bad input: nothing written.
    let mut bad = first.to_vec();
    bad[9] = "2h";
    let (code, _) = submit(t, &bad, &log);
    assert_eq!(code, Some(2), "bad --time; log:\n{}", log_text(&log));
    assert!(log_text(&log).contains("--time \"2h\""));
    let (code, _) = submit(t, &["--missing", s(&t.join("nowhere"))], &log);
    assert_eq!(code, Some(3));
    assert!(!c.exists());

    // --dry-run prints the script and writes nothing.
    let mut dry = first.to_vec();
    dry.push("--dry-run");
    let (code, out) = submit(t, &dry, &log);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    assert!(out.contains("#SBATCH --array=0-2%2"), "{out}");
    assert!(!c.exists(), "--dry-run created the campaign directory");
    assert!(!t.join("sbatch.log").exists(), "--dry-run called sbatch");

    // 10 runs at 1 per task would need 10 array indices, MaxArraySize is 3: 4 runs per task.
    let (code, out) = submit(t, &first, &log);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    assert!(
        out.contains("job 101") && out.contains("compaction job 102"),
        "{out}"
    );
    assert!(log_text(&log).contains("packed 4 runs per task into 3 tasks"));
    let rec: Value =
        serde_json::from_str(&fs::read_to_string(c.join("slurm/submission.json")).unwrap())
            .unwrap();
    assert_eq!(rec["shards"], json!(3));
    assert_eq!(rec["submissions"][0]["array_job"], json!("101"));
    assert_eq!(rec["submissions"][0]["compact_job"], json!("102"));
    let script = fs::read_to_string(c.join("slurm/array-001.sh")).unwrap();
    for want in [
        "#SBATCH --array=0-2%2",
        "#SBATCH --time=00:05:00",
        "#SBATCH --partition=short",
        "#SBATCH --account=abc",
        "slurm-task",
        "--shards 3",
        "--checkpoint-every 300",
    ] {
        assert!(script.contains(want), "script lacks {want}:\n{script}");
    }
    let compact = fs::read_to_string(c.join("slurm/compact-001.sh")).unwrap();
    assert!(compact.contains(" compact ") && compact.contains("--kill-on-invalid-dep=yes"));
    let calls = fs::read_to_string(t.join("sbatch.log")).unwrap();
    let calls: Vec<&str> = calls.lines().collect();
    assert_eq!(calls.len(), 2, "{calls:?}");
    assert!(calls[0].contains("array-001.sh"));
    assert!(calls[1].contains("--dependency=afterok:101") && calls[1].contains("compact-001.sh"));
    // A second first submission is refused.
    let (code, _) = submit(t, &first, &log);
    assert_eq!(code, Some(3));

    // SLURM runs tasks 0 and 2; task 1 is cancelled before finishing.
    for i in ["0", "2"] {
        let code = run_granular(
            &["slurm-task", s(&c), "--shards", "3", "--index", i],
            &log,
            LIMIT,
        );
        assert_eq!(code, Some(0), "task {i}; log:\n{}", log_text(&log));
    }
    // While task 1 is still queued, --missing has nothing to submit.
    fs::write(t.join("squeue.out"), "101 1 PENDING\n").unwrap();
    let (code, out) = submit(t, &["--missing", s(&c)], &log);
    assert_eq!(code, Some(0));
    assert!(out.contains("nothing to submit"), "{out}");
    // Once it is gone, exactly shard index 1 is resubmitted, with a new compaction job.
    fs::write(t.join("squeue.out"), "").unwrap();
    let (code, out) = submit(t, &["--missing", s(&c), "--time", "00:10:00"], &log);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    assert!(
        out.contains("array 1%2") && out.contains("job 103"),
        "{out}"
    );
    let script = fs::read_to_string(c.join("slurm/array-002.sh")).unwrap();
    assert!(script.contains("#SBATCH --array=1%2") && script.contains("--time=00:10:00"));
    let calls = fs::read_to_string(t.join("sbatch.log")).unwrap();
    assert!(calls.lines().nth(3).unwrap().contains("afterok:103"));

    let code = run_granular(
        &["slurm-task", s(&c), "--shards", "3", "--index", "1"],
        &log,
        LIMIT,
    );
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let (code, out) = submit(t, &["--missing", s(&c)], &log);
    assert_eq!((code, out.contains("nothing to submit")), (Some(0), true));
    // status lists both submissions and asks squeue for their jobs.
    let out = Command::new(bin())
        .args(["status", s(&c)])
        .env("GRANULAR_SQUEUE", t.join("squeue"))
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains(
            "slurm submission 1: array 0-2%2 job 101, compaction job 102 (nothing queued)"
        ) && text.contains("slurm submission 2: array 1%2 job 103, compaction job 104"),
        "{text}"
    );

    // The tables equal a single-machine run's.
    let r = t.join("R");
    assert_eq!(
        run_granular(&["run", s(&m), "--out", s(&r), "--quiet"], &log, LIMIT),
        Some(0)
    );
    util::assert_tables_identical(&read_tables(&r), &read_tables(&c), "SLURM tasks vs one run");

    // The campaign grows (2 more replicas per point): `submit` with the grown manifest is a
    // resubmission of the shards that now have unfinished runs; the same manifest again is
    // refused like any second first submission (naming --missing), and --missing has nothing
    // to submit while those are queued. Run, the tables equal a single-machine run of the grown
    // manifest.
    let mut grown = manifest();
    grown["replicas"] = json!(7);
    let mg = t.join("grown.json");
    write_json(&mg, &grown);
    fs::write(t.join("squeue.out"), "").unwrap();
    let (code, out) = submit(t, &[s(&mg), "--out", s(&c), "--slurm"], &log);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    // New runs 10..13 fall in shards 1, 2, 0, 1 of 3.
    assert!(
        out.contains("array 0-2%2") && out.contains("job 105"),
        "{out}"
    );
    fs::write(
        t.join("squeue.out"),
        "105 0 PENDING\n105 1 PENDING\n105 2 PENDING\n",
    )
    .unwrap();
    let (code, _) = submit(t, &[s(&mg), "--out", s(&c), "--slurm"], &log);
    assert_eq!(code, Some(3), "log:\n{}", log_text(&log));
    assert!(log_text(&log).contains("granular submit --missing"));
    let (code, out) = submit(t, &["--missing", s(&c)], &log);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    assert!(out.contains("nothing to submit"), "{out}");
    for i in ["0", "1", "2"] {
        let code = run_granular(
            &["slurm-task", s(&c), "--shards", "3", "--index", i],
            &log,
            LIMIT,
        );
        assert_eq!(code, Some(0), "task {i}; log:\n{}", log_text(&log));
    }
    let rg = t.join("RG");
    assert_eq!(
        run_granular(&["run", s(&mg), "--out", s(&rg), "--quiet"], &log, LIMIT),
        Some(0)
    );
    util::assert_same_current(&c, &rg, "grown SLURM campaign vs one run");
}
