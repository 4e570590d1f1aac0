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

use super::util::s;
use super::util::{self, bin, heavy, log_text, read_tables, run_granular, write_json};

const LIMIT: Duration = Duration::from_secs(300);

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

/// One short run (1 point, 1 replica).
fn tiny_manifest(name: &str) -> Value {
    let mut m = manifest();
    m["name"] = json!(name);
    m["replicas"] = json!(1);
    m.as_object_mut().unwrap().remove("sweep");
    m
}

/// A path or value that no line of a script can carry is refused with exit 2, every one at
/// once, before anything is written (no directory, no script, no sbatch call): a line break in
/// `--out` (before: `--dry-run` printed a script whose `#SBATCH --output=` line ended there and
/// whose next line, `touch PWNED`, bash would have run), a backslash in it (SLURM strips it
/// from `--output` and then expands no `%A_%a`), line breaks and `hetjob` in `--partition` and
/// `--sbatch-arg`.
#[test]
fn submit_refuses_what_no_script_line_can_hold() {
    let logs = tempfile::tempdir().unwrap();
    let log = logs.path().join("log");
    let dir = tempfile::tempdir().unwrap();
    let t = dir.path();
    fake_tools(t);
    let m = t.join("m.json");
    write_json(&m, &tiny_manifest("slurm-refuse"));
    let before = util::snapshot(t);
    let first = |out: &str| -> Vec<String> {
        [
            s(&m),
            "--out",
            out,
            "--slurm",
            "--tasks",
            "1",
            "--per-task-runs",
            "1",
            "--time",
            "5",
        ]
        .iter()
        .map(|a| a.to_string())
        .collect()
    };
    let injected = format!("{}/x\ntouch PWNED\n#", t.display());
    let backslash = format!("{}/back\\slash", t.display());
    let plain = t.join("C").display().to_string();
    let cases: Vec<(Vec<String>, Vec<&str>)> = vec![
        (
            [first(&injected), vec!["--dry-run".into()]].concat(),
            vec![
                "error: --out \"",
                "x\\ntouch PWNED\\n#\": contains a line break",
            ],
        ),
        (
            first(&injected),
            vec!["x\\ntouch PWNED\\n#\": contains a line break"],
        ),
        (
            first(&backslash),
            vec!["back\\\\slash\": contains a backslash"],
        ),
        (
            [
                first(&plain),
                vec![
                    "--partition".into(),
                    "short\nrm -rf /".into(),
                    "--sbatch-arg=--comment=a\rb".into(),
                    "--sbatch-arg=--comment=HetJob".into(),
                    "--dry-run".into(),
                ],
            ]
            .concat(),
            vec![
                "--partition \"short\\nrm -rf /\": contains a line break",
                "--sbatch-arg \"--comment=a\\rb\": contains a carriage return",
                "--sbatch-arg \"--comment=HetJob\": contains \"hetjob\"",
            ],
        ),
    ];
    for (args, wanted) in cases {
        let _ = fs::remove_file(&log);
        let argv: Vec<&str> = args.iter().map(String::as_str).collect();
        let (code, out) = submit(t, &argv, &log);
        let text = log_text(&log);
        assert_eq!(code, Some(2), "{args:?}: stdout:\n{out}\nstderr:\n{text}");
        assert!(out.is_empty(), "{args:?} printed:\n{out}");
        for w in wanted {
            assert!(text.contains(w), "{args:?}: stderr lacks {w:?}:\n{text}");
        }
        assert!(!text.contains("panicked"), "{text}");
        assert_eq!(
            util::snapshot(t),
            before,
            "{args:?} wrote into the working directory"
        );
    }
}

/// `s` in POSIX single quotes (as the test's own reference, independent of the crate's).
fn sh_quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', "'\\''"))
}

/// The arguments of a script's `#SBATCH` lines as sbatch reads them (`_get_argument` in
/// SLURM's src/sbatch/opt.c, 17.11 on: white space ends an unquoted argument, `'` and `"`
/// quote, a backslash escapes the next character (inside quotes too), an unquoted `#` ends the
/// line; the lines before the first command). Lines holding `hetjob`/`packjob` fail the test.
fn sbatch_directives(script: &str) -> Vec<String> {
    let mut args = Vec::new();
    for line in script.lines().skip(1) {
        let Some(rest) = line.strip_prefix("#SBATCH") else {
            if line.trim_start().starts_with('#') || line.trim().is_empty() {
                continue;
            }
            break;
        };
        let lower = line.to_ascii_lowercase();
        assert!(
            !lower.contains("hetjob") && !lower.contains("packjob"),
            "{line}"
        );
        let mut chars = rest.chars().peekable();
        loop {
            while chars.peek().is_some_and(|c| c.is_whitespace()) {
                chars.next();
            }
            if chars.peek().is_none_or(|&c| c == '#') {
                break;
            }
            assert_ne!(chars.peek(), Some(&':'), "sbatch: Unexpected `:` in {line}");
            let (mut arg, mut quote, mut escape) = (String::new(), None, false);
            while let Some(&c) = chars.peek() {
                if quote.is_none() && c.is_whitespace() {
                    break;
                }
                chars.next();
                if escape {
                    escape = false;
                } else if c == '\\' {
                    escape = true;
                    continue;
                } else if let Some(q) = quote {
                    if c == q {
                        quote = None;
                        continue;
                    }
                } else if c == '"' || c == '\'' {
                    quote = Some(c);
                    continue;
                } else if c == '#' {
                    break;
                }
                arg.push(c);
            }
            assert!(quote.is_none(), "sbatch: unmatched quote in {line}");
            args.push(arg);
        }
    }
    args
}

/// SLURM's expansion of a batch job's output file name (slurmstepd `fname_create`): `%%` is
/// `%`, `%A`/`%a`/`%j` the array job, task and job id; a backslash anywhere turns every
/// expansion off (and is dropped).
fn slurm_file_name(pattern: &str, array_job: u32, task: u32, job: u32) -> String {
    if pattern.contains('\\') {
        return pattern.replace('\\', "");
    }
    let mut out = String::new();
    let mut chars = pattern.chars();
    while let Some(c) = chars.next() {
        if c != '%' {
            out.push(c);
            continue;
        }
        match chars.next() {
            Some('%') => out.push('%'),
            Some('A') => out.push_str(&array_job.to_string()),
            Some('a') => out.push_str(&task.to_string()),
            Some('j') => out.push_str(&job.to_string()),
            Some(other) => {
                out.push('%');
                out.push(other);
            }
            None => out.push('%'),
        }
    }
    out
}

/// A campaign directory (and a partition, an extra sbatch argument) with spaces, quotes,
/// `$()`, backticks, `;`, `&`, `#` and `%`: the scripts pass `bash -n`; sbatch reads their
/// `#SBATCH` lines into single arguments with the log paths SLURM expands into the campaign's
/// `slurm/logs/`; run by bash with a stub in place of granular, the commands get the directory
/// unchanged, and nothing injected runs; run for real, the array task runs the campaign and
/// the compaction job compacts it. (Before: `#SBATCH --output=` held the path unquoted,
/// which sbatch splits at the first space and cuts at `#`; the partition and extra arguments
/// were written verbatim.)
#[test]
fn scripts_carry_odd_paths_unchanged() {
    let _g = heavy();
    let tmp = tempfile::tempdir().unwrap();
    let t = &tmp.path().canonicalize().unwrap();
    fake_tools(t);
    let m = t.join("m.json");
    write_json(&m, &tiny_manifest("slurm-odd"));
    let log = t.join("log");
    let odd = t
        .join("sub dir")
        .join("odd 'q' \"dq\" $(touch PWNED1) `touch PWNED2`; touch PWNED3 & #c %A 100%");
    let dir = s(&odd);
    let args = [
        s(&m),
        "--out",
        dir,
        "--slurm",
        "--tasks",
        "1",
        "--per-task-runs",
        "1",
        "--time",
        "00:05:00",
        "--partition",
        "short queue #1",
        "--sbatch-arg=--comment=it's \"ok\"; $(touch PWNED4)",
    ];
    let (code, out) = submit(t, &args, &log);
    assert_eq!(code, Some(0), "stdout:\n{out}\nlog:\n{}", log_text(&log));
    let array = fs::read_to_string(odd.join("slurm/array-001.sh")).unwrap();
    let compact = fs::read_to_string(odd.join("slurm/compact-001.sh")).unwrap();

    // bash parses both scripts.
    for (name, text) in [("array", &array), ("compact", &compact)] {
        let st = Command::new("bash")
            .args(["-n", "-c", text])
            .status()
            .unwrap();
        assert!(st.success(), "bash -n {name} script:\n{text}");
    }

    // sbatch reads every directive as one argument, the log paths inside the campaign.
    let logs = format!("{dir}/slurm/logs/");
    for (name, text, want_log) in [
        ("array", &array, format!("{logs}101_0.out")),
        ("compact", &compact, format!("{logs}compact-102.out")),
    ] {
        let d = sbatch_directives(text);
        let output: Vec<&String> = d.iter().filter(|a| a.starts_with("--output=")).collect();
        assert_eq!(output.len(), 1, "{name}: {d:?}\n{text}");
        let file = slurm_file_name(&output[0]["--output=".len()..], 101, 0, 102);
        assert_eq!(file, want_log, "{name}: {d:?}\n{text}");
        for want in [
            "--partition=short queue #1",
            "--comment=it's \"ok\"; $(touch PWNED4)",
            "--time=00:05:00",
            "--ntasks=1",
        ] {
            assert!(
                d.iter().any(|a| a == want),
                "{name} lacks {want:?}: {d:?}\n{text}"
            );
        }
        assert!(
            d.iter().all(|a| a.starts_with("--")),
            "{name}: an argument split apart: {d:?}\n{text}"
        );
    }

    // bash runs the scripts' commands with the directory unchanged: granular replaced by a
    // stub on PATH that records its arguments.
    let stubs = t.join("stubs");
    fs::create_dir(&stubs).unwrap();
    let stub = stubs.join("granular");
    fs::write(&stub, "#!/bin/sh\nprintf '%s\\0' \"$@\" > \"$STUB_OUT\"\n").unwrap();
    fs::set_permissions(&stub, fs::Permissions::from_mode(0o755)).unwrap();
    let exe = sh_quote(s(&fs::canonicalize(bin()).unwrap()));
    let path = format!(
        "{}:{}",
        stubs.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    for (name, text, want) in [
        (
            "array",
            &array,
            vec![
                "slurm-task",
                dir,
                "--shards",
                "1",
                "--threads",
                "1",
                "--checkpoint-every",
                "300",
            ],
        ),
        ("compact", &compact, vec!["compact", dir]),
    ] {
        assert_eq!(text.matches(&exe).count(), 1, "{name}:\n{text}");
        let stubbed = text.replace(&exe, "granular");
        let recorded = t.join(format!("{name}.args"));
        let out = Command::new("bash")
            .args(["-c", &stubbed])
            .current_dir(t)
            .env("PATH", &path)
            .env("STUB_OUT", &recorded)
            .env("SLURM_ARRAY_TASK_ID", "0")
            .env_remove("SLURM_CPUS_PER_TASK")
            .output()
            .unwrap();
        assert!(out.status.success(), "{name}: {out:?}\n{stubbed}");
        let got = fs::read(&recorded).unwrap();
        let got: Vec<String> = got
            .split(|&b| b == 0)
            .filter(|a| !a.is_empty())
            .map(|a| String::from_utf8(a.to_vec()).unwrap())
            .collect();
        assert_eq!(got, want, "{name}:\n{stubbed}");
    }

    // Run for real by bash: the task runs the campaign, the compaction job compacts it.
    for (name, text) in [("array", &array), ("compact", &compact)] {
        let out = Command::new("bash")
            .args(["-c", text])
            .current_dir(t)
            .env("SLURM_ARRAY_TASK_ID", "0")
            .env_remove("SLURM_CPUS_PER_TASK")
            .stdin(Stdio::null())
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{name} script: {}\n{}",
            String::from_utf8_lossy(&out.stderr),
            text
        );
    }
    let st = util::status_json(&odd, &log);
    assert_eq!(st["done"], json!(1), "{st}");
    assert!(odd.join("ledger/index.json").exists(), "not compacted");

    // Nothing injected ran anywhere.
    let pwned: Vec<_> = util::snapshot(t)
        .into_keys()
        .filter(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("PWNED"))
        })
        .collect();
    assert!(pwned.is_empty(), "injected commands ran: {pwned:?}");
}

/// A tiny error-target campaign: a binary mixture (500 + 500 particles), gamma = T_2/T_1 at
/// t_end to 0.5 % at two mass ratios, 3 pilot replicas.
fn target_manifest() -> Value {
    json!({
        "name": "slurm-target",
        "model": "dsmc",
        "seed": 31,
        "min_replicas": 3,
        "max_replicas": 100,
        "params": {
            "method": "low_rank",
            "species": {"list": [
                {"mass": 1, "diameter": 1, "count": 500},
                {"mass": 2, "diameter": 1, "count": 500}
            ]},
            "volume": 10000,
            "restitution": {"constant": 0.8},
            "initial_temperature": {"hcs": {"mean": 1.0}},
            "t_end": 2,
            "output_times": {"list": [1, 2]},
            "observables": ["temperature"]
        },
        "sweep": {"species.list.1.mass": [2, 8]},
        "derived": {"gamma": "temperature[species=2] / temperature[species=1]"},
        "target": [{"quantity": "gamma", "t": "t_end", "sem_rel": 0.005}]
    })
}

fn record(c: &Path) -> Value {
    serde_json::from_str(&fs::read_to_string(c.join("slurm/submission.json")).unwrap()).unwrap()
}

/// `granular slurm-round DIR --submission K` with the stand-in tools: (exit code, stdout).
fn slurm_round(t: &Path, c: &Path, k: u64, log: &Path) -> (Option<i32>, String) {
    let f = fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(log)
        .unwrap();
    let out = Command::new(bin())
        .args(["slurm-round", s(c), "--submission", &k.to_string()])
        .env("GRANULAR_SBATCH", t.join("sbatch"))
        .env("GRANULAR_SQUEUE", t.join("squeue"))
        .env("GRANULAR_SCONTROL", t.join("scontrol"))
        .stdin(Stdio::null())
        .stderr(f)
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
    )
}

/// An error-target campaign under SLURM (stand-in sbatch): `submit` writes array-001 and
/// round-001 chained by afterany (no compaction yet); array tasks run by hand, `slurm-round`
/// then submits the next round's array of exactly the shards with pending runs and the next
/// round job after it, until every target is met, and then the compaction job. A task that
/// did not run: its shard is resubmitted once (try 2), then the round job gives up (exit 1,
/// said by `status`); an older round job is superseded; `submit --missing` restarts the chain.
/// The tables equal a local `granular run` of the same manifest. (Before: `submit` chained
/// only a compaction, and no command decided rounds under SLURM.)
#[test]
fn target_campaign_runs_as_chained_arrays() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let t = dir.path();
    fake_tools(t);
    let m = t.join("m.json");
    write_json(&m, &target_manifest());
    let log = t.join("log");
    let c = t.join("C");
    let sbatch_calls = || -> Vec<String> {
        fs::read_to_string(t.join("sbatch.log"))
            .unwrap_or_default()
            .lines()
            .map(String::from)
            .collect()
    };
    let task = |i: u64| {
        let code = run_granular(
            &[
                "slurm-task",
                s(&c),
                "--shards",
                "3",
                "--index",
                &i.to_string(),
            ],
            &log,
            LIMIT,
        );
        assert_eq!(code, Some(0), "task {i}; log:\n{}", log_text(&log));
    };
    let done = || util::status_json(&c, &log)["done"].as_u64().unwrap();

    // 6 pilot runs at 2 per task: 3 shards (MaxArraySize 3).
    let (code, out) = submit(
        t,
        &[
            s(&m),
            "--out",
            s(&c),
            "--slurm",
            "--tasks",
            "2",
            "--per-task-runs",
            "2",
            "--time",
            "00:05:00",
        ],
        &log,
    );
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    assert!(
        out.contains("job 101") && out.contains("round 1 job 102"),
        "{out}"
    );
    let rec = record(&c);
    assert_eq!(rec["shards"], json!(3));
    assert_eq!(rec["submissions"][0]["round"], json!(1));
    assert_eq!(rec["submissions"][0]["round_job"], json!("102"));
    assert_eq!(rec["submissions"][0]["compact_job"], Value::Null);
    let round = fs::read_to_string(c.join("slurm/round-001.sh")).unwrap();
    assert!(
        round.contains(" slurm-round ") && round.contains("--submission 1"),
        "{round}"
    );
    assert!(!c.join("slurm/compact-001.sh").exists());
    let calls = sbatch_calls();
    assert_eq!(calls.len(), 2, "{calls:?}");
    assert!(calls[0].contains("array-001.sh"));
    assert!(
        calls[1].contains("--dependency=afterany:101") && calls[1].contains("round-001.sh"),
        "{calls:?}"
    );

    // Task 0 never ran: the round job resubmits shard 0 once (try 2, its own round job)...
    task(1);
    task(2);
    let (code, out) = slurm_round(t, &c, 1, &log);
    assert_eq!(code, Some(0), "{out}\nlog:\n{}", log_text(&log));
    assert!(out.contains("try 2") && out.contains("array 0%2"), "{out}");
    let rec = record(&c);
    assert_eq!(rec["submissions"][1]["round"], json!(1));
    assert_eq!(rec["submissions"][1]["attempt"], json!(2));
    let calls = sbatch_calls();
    assert!(calls[3].contains("--dependency=afterany:103") && calls[3].contains("round-002.sh"));
    // ... and gives up when it still did not run, saying so in status.
    let (code, _) = slurm_round(t, &c, 2, &log);
    assert_eq!(code, Some(1), "log:\n{}", log_text(&log));
    assert!(log_text(&log).contains("still not committed after 2 array submissions"));
    let st = Command::new(bin())
        .args(["status", s(&c)])
        .env("GRANULAR_SQUEUE", t.join("squeue"))
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&st.stdout);
    assert!(
        text.contains("slurm submission 2: round 1 (try 2): array 0%2 job 103, round job 104")
            && text.contains("the round jobs gave up at round 1"),
        "{text}"
    );
    // A round job of an earlier submission does nothing.
    let before = sbatch_calls().len();
    let (code, out) = slurm_round(t, &c, 1, &log);
    assert_eq!(
        (code, out.contains("followed by submission 2")),
        (Some(0), true),
        "{out}"
    );
    assert_eq!(sbatch_calls().len(), before);

    // `submit --missing` restarts the chain: shard 0, round 1, a new round job.
    let (code, out) = submit(t, &["--missing", s(&c)], &log);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    assert!(
        out.contains("array 0%2") && out.contains("round 1 job 106"),
        "{out}"
    );
    assert_eq!(record(&c)["outcome"], Value::Null);

    // The chain: run the tasks of the latest array, then its round job, until final. Every
    // array holds exactly the shards with pending runs (a task of another shard runs nothing).
    let mut rounds = 0;
    let final_out = loop {
        let rec = record(&c);
        let subs = rec["submissions"].as_array().unwrap();
        let last = subs.last().unwrap();
        let k = last["number"].as_u64().unwrap();
        let indices: Vec<u64> = last["indices"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap())
            .collect();
        assert_eq!(last["attempt"], json!(1), "{rec}");
        for i in 0..3 {
            let before = done();
            task(i);
            let ran = done() > before;
            assert_eq!(
                ran,
                indices.contains(&i),
                "shard {i}, array {indices:?}: {rec}"
            );
        }
        let (code, out) = slurm_round(t, &c, k, &log);
        assert_eq!(code, Some(0), "{out}\nlog:\n{}", log_text(&log));
        if out.contains("targets ") {
            break out;
        }
        assert!(out.contains("run(s) added"), "{out}");
        let rec = record(&c);
        let n = rec["submissions"].as_array().unwrap().len();
        let new = &rec["submissions"][n - 1];
        let script = fs::read_to_string(c.join(new["script"].as_str().unwrap())).unwrap();
        assert!(script.contains("--shards 3"), "{script}");
        let calls = sbatch_calls();
        let dep = format!(
            "--dependency=afterany:{}",
            new["array_job"].as_str().unwrap()
        );
        assert!(
            calls[calls.len() - 1].contains(&dep)
                && calls[calls.len() - 1].contains(&format!("round-{:03}.sh", k + 1)),
            "{calls:?}"
        );
        rounds += 1;
        assert!(rounds < 20, "no end of rounds");
    };
    assert!(
        rounds >= 1,
        "the pilot met the targets: no chained round tested"
    );
    assert!(
        final_out.contains("targets met") && final_out.contains("compaction job"),
        "{final_out}"
    );
    let rec = record(&c);
    assert_eq!(rec["outcome"]["verdict"], json!("met"), "{rec}");
    let calls = sbatch_calls();
    let last = calls.last().unwrap();
    assert!(
        last.contains("compact-") && !last.contains("--dependency"),
        "{calls:?}"
    );
    let st = util::status_json(&c, &log);
    assert_eq!(st["targets"]["verdict"], json!("met"), "{st}");
    assert!(
        st["slurm"].as_array().unwrap().last().unwrap()["outcome"]["verdict"] == json!("met"),
        "{st}"
    );
    assert_eq!(
        run_granular(&["compact", s(&c)], &log, LIMIT),
        Some(0),
        "log:\n{}",
        log_text(&log)
    );

    // The tables equal a local run's (same rounds, decided from the same committed rows).
    let r = t.join("R");
    assert_eq!(
        run_granular(&["run", s(&m), "--out", s(&r), "--quiet"], &log, LIMIT),
        Some(0),
        "log:\n{}",
        log_text(&log)
    );
    util::assert_tables_identical(
        &read_tables(&r),
        &read_tables(&c),
        "SLURM rounds vs one run",
    );
}
