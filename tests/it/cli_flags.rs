//! Every numeric flag of every command is checked when the command line is parsed: NaN,
//! infinities, negative, fractional where an integer is expected, overflowing, absurdly large
//! values and 0 where it means nothing give exit 2 with a message naming the flag, no panic,
//! and leave the working directory (a manifest, a campaign directory, the `--out` path)
//! exactly as it was. And a valid value of each flag is accepted (`validate`, `status`,
//! `schema`, `theory`, `plot` and `verify` have no numeric flags).

use std::fs;
use std::path::Path;
use std::process::{Command, Output, Stdio};

use serde_json::json;

use super::util::{bin, heavy, repo_root, snapshot, write_json};

/// Values that no numeric flag accepts.
const BAD: &[&str] = &[
    "nan",
    "NaN",
    "inf",
    "-inf",
    "infinity",
    "-1",
    "1e300",
    "18446744073709551616",
    "abc",
    "",
    "1.5.2",
];

/// A flag, a value it accepts (used while another flag of the command is tested) and its own
/// bad values besides `BAD`.
struct Flag {
    name: &'static str,
    good: &'static str,
    bad: &'static [&'static str],
}

/// A command line: fixed arguments (paths relative to the case's directory, which holds
/// the manifest `m.json` and the campaign `c`; `out` does not exist), its numeric flags, and
/// the variants of its tail (e.g. with and without `--dry-run`).
struct Cmd {
    prefix: &'static [&'static str],
    flags: &'static [Flag],
    tails: &'static [&'static [&'static str]],
}

const THREADS: Flag = Flag {
    name: "--threads",
    good: "1",
    bad: &["1025", "20000", "1.5", "0x10"],
};
const CHECKPOINT: Flag = Flag {
    name: "--checkpoint-every",
    good: "0.5",
    bad: &["0", "-0", "1e-400", "1e8", "-0.5"],
};
const FLUSH: Flag = Flag {
    name: "--flush-every",
    good: "0.1",
    bad: &["1e8", "-0.1"],
};
const SHARD: Flag = Flag {
    name: "--shard",
    good: "1/1",
    bad: &[
        "0",
        "0/1",
        "2/1",
        "1/0",
        "1/4294967296",
        "-1/2",
        "1/2/3",
        "nan/2",
    ],
};
const RUNTIME: &[Flag] = &[THREADS, CHECKPOINT, FLUSH, SHARD];
const SUBMIT: &[Flag] = &[
    Flag {
        name: "--tasks",
        good: "2",
        bad: &["0", "4000002", "1.5"],
    },
    Flag {
        name: "--per-task-runs",
        good: "1",
        bad: &["0", "1000000001", "1.5"],
    },
    Flag {
        name: "--time",
        good: "10",
        bad: &["2h", "1:2:3:4", "12345", "1.5"],
    },
    Flag {
        name: "--cpus-per-task",
        good: "1",
        bad: &["0", "1025", "1.5"],
    },
    Flag {
        name: "--checkpoint-every",
        good: "60",
        bad: &["0", "1e8"],
    },
];

const COMMANDS: &[Cmd] = &[
    Cmd {
        prefix: &["run", "m.json", "--out", "out", "--quiet"],
        flags: RUNTIME,
        tails: &[&[]],
    },
    Cmd {
        prefix: &["plan", "m.json", "--out", "out", "--no-probe"],
        flags: &[THREADS],
        tails: &[&[]],
    },
    Cmd {
        prefix: &["resume", "c", "--quiet"],
        flags: RUNTIME,
        tails: &[&[]],
    },
    Cmd {
        prefix: &["slurm-task", "c"],
        flags: &[
            Flag {
                name: "--shards",
                good: "2",
                bad: &["0", "4000002", "1.5"],
            },
            // 2 is refused after parsing (not below --shards 2), before anything is opened.
            Flag {
                name: "--index",
                good: "0",
                bad: &["2", "4000001", "1.5"],
            },
            THREADS,
            CHECKPOINT,
            FLUSH,
        ],
        tails: &[&[]],
    },
    Cmd {
        prefix: &["submit", "m.json", "--out", "out", "--slurm"],
        flags: SUBMIT,
        tails: &[&[], &["--dry-run"]],
    },
    Cmd {
        prefix: &["submit", "c", "--missing", "--slurm"],
        flags: SUBMIT,
        tails: &[&[], &["--dry-run"]],
    },
    Cmd {
        prefix: &["compact", "c"],
        flags: &[Flag {
            name: "--target-size",
            good: "1MB",
            bad: &[
                "0",
                "0.1",
                "1025GB",
                "99999999999999999999GB",
                "1e300MB",
                "5XB",
            ],
        }],
        tails: &[&[]],
    },
    Cmd {
        prefix: &["analyze", "c", "--no-figures"],
        flags: &[
            Flag {
                name: "--n-min",
                good: "100",
                bad: &["1e10", "-0.5"],
            },
            Flag {
                name: "--count-error-factor",
                good: "2",
                bad: &["0", "101"],
            },
            Flag {
                name: "--chi2-accept",
                good: "1.3",
                bad: &["0", "1001"],
            },
            Flag {
                name: "--fixed-df",
                good: "1.5",
                bad: &["0", "2.01", "3"],
            },
        ],
        tails: &[&[]],
    },
];

/// `granular args` in `dir`, with stand-ins for the SLURM tools that do not exist (so that
/// nothing could reach a real cluster).
fn granular(dir: &Path, args: &[&str]) -> Output {
    Command::new(bin())
        .args(args)
        .current_dir(dir)
        .env("GRANULAR_SBATCH", "/nonexistent/sbatch")
        .env("GRANULAR_SQUEUE", "/nonexistent/squeue")
        .env("GRANULAR_SCONTROL", "/nonexistent/scontrol")
        .env_remove("SLURM_ARRAY_TASK_ID")
        .stdin(Stdio::null())
        .output()
        .expect("run granular")
}

/// Copy a directory tree, symbolic links (the tables' generations) as links.
fn copy_tree(from: &Path, to: &Path) {
    fs::create_dir(to).unwrap();
    for e in fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let (src, dst) = (e.path(), to.join(e.file_name()));
        let t = e.file_type().unwrap();
        if t.is_symlink() {
            std::os::unix::fs::symlink(fs::read_link(&src).unwrap(), &dst).unwrap();
        } else if t.is_dir() {
            copy_tree(&src, &dst);
        } else {
            fs::copy(&src, &dst).unwrap();
        }
    }
}

/// A manifest `m.json` and its campaign `c` (theory tables only) in `dir`.
fn template(dir: &Path) {
    let m = repo_root().join("tests/manifests/good/power_law_sweep.json");
    fs::copy(&m, dir.join("m.json")).unwrap();
    let o = granular(dir, &["theory", "m.json", "--out", "c"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// The command line of `cmd` with `flag` set to `value` and the other flags to good values.
fn args<'a>(cmd: &'a Cmd, flag: &'a Flag, value: &'a str, tail: &[&'a str]) -> Vec<&'a str> {
    let mut a = cmd.prefix.to_vec();
    for f in cmd.flags.iter().filter(|f| f.name != flag.name) {
        a.extend([f.name, f.good]);
    }
    a.extend([flag.name, value]);
    a.extend(tail);
    a
}

#[test]
fn bad_numeric_flags_are_refused_before_anything_is_written() {
    // Light, but hundreds of processes: not beside the timing-sensitive tests.
    let _g = heavy();
    let base = tempfile::tempdir().unwrap();
    let tpl = base.path().join("template");
    fs::create_dir(&tpl).unwrap();
    template(&tpl);
    let mut cases = 0;
    for cmd in COMMANDS {
        for flag in cmd.flags {
            for tail in cmd.tails {
                for &value in BAD.iter().chain(flag.bad) {
                    let dir = base.path().join(format!("case{cases}"));
                    copy_tree(&tpl, &dir);
                    let before = snapshot(&dir);
                    let a = args(cmd, flag, value, tail);
                    let o = granular(&dir, &a);
                    let err = String::from_utf8_lossy(&o.stderr);
                    let what = format!("granular {a:?}: exit {:?}, stderr:\n{err}", o.status);
                    assert_eq!(o.status.code(), Some(2), "{what}");
                    assert!(err.contains(flag.name), "message names the flag: {what}");
                    assert!(!err.contains("panicked"), "{what}");
                    assert!(snapshot(&dir) == before, "the directory changed: {what}");
                    fs::remove_dir_all(&dir).unwrap();
                    cases += 1;
                }
            }
        }
    }
    eprintln!("{cases} bad values refused");
}

fn ok(dir: &Path, args: &[&str]) -> String {
    let o = granular(dir, args);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(
        o.status.code(),
        Some(0),
        "granular {args:?}:\n{err}{}",
        String::from_utf8_lossy(&o.stdout)
    );
    err
}

#[test]
fn good_numeric_flags_are_accepted() {
    let _g = heavy();
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    fs::copy(
        repo_root().join("tests/manifests/good/power_law_sweep.json"),
        d.join("m.json"),
    )
    .unwrap();
    ok(d, &["validate", "m.json"]);
    let run = [
        "run",
        "m.json",
        "--out",
        "c",
        "--quiet",
        "--threads",
        "1",
        "--checkpoint-every",
        "0.5",
        "--flush-every",
        "0.1",
        "--shard",
        "1/2",
    ];
    ok(d, &run);
    // The largest values; more threads than 4 per core are reduced with a warning.
    let resume = [
        "resume",
        "c",
        "--quiet",
        "--threads",
        "1024",
        "--checkpoint-every",
        "1e7",
        "--flush-every",
        "0",
        "--shard",
        "2/2",
    ];
    let err = ok(d, &resume);
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    if cores * 4 < 1024 {
        assert!(
            err.contains("--threads 1024") && err.contains(&format!("using {}", cores * 4)),
            "{err}"
        );
    }
    let status = granular(d, &["status", "c", "--json"]);
    let s: serde_json::Value = serde_json::from_slice(&status.stdout).unwrap();
    assert_eq!(s["done"], 8, "{s}");
    ok(
        d,
        &[
            "slurm-task",
            "c",
            "--shards",
            "1",
            "--index",
            "0",
            "--threads",
            "0",
            "--checkpoint-every",
            "300",
            "--flush-every",
            "30",
        ],
    );
    ok(d, &["compact", "c", "--target-size", "1MB"]);
    ok(d, &["compact", "c", "--target-size", "1024GB"]);
    // Largest submit values; --dry-run writes nothing.
    let before = snapshot(d);
    let dry = ok(
        d,
        &[
            "submit",
            "m.json",
            "--out",
            "planned",
            "--slurm",
            "--tasks",
            "4000001",
            "--per-task-runs",
            "1000000000",
            "--time",
            "0",
            "--cpus-per-task",
            "1024",
            "--checkpoint-every",
            "1e7",
            "--dry-run",
        ],
    );
    assert!(snapshot(d) == before, "--dry-run wrote something: {dry}");
    analyze_flags(d);
}

/// `analyze` with its flags at both ends of their ranges on a one-run 1D rfm campaign.
fn analyze_flags(d: &Path) {
    write_json(
        &d.join("rfm.json"),
        &serde_json::json!({
            "name": "cli-flags-rfm",
            "model": "rfm",
            "seed": 5,
            "params": {
                "dim": 1,
                "n_particles": 30,
                "reduced_length": 1.0,
                "restitution_normal": 0.5,
                "warmup": 0.01,
                "duration": 0.02,
                "sample_every": 1000,
                "observables": ["velocity_moments", "velocity_histogram"],
                "velocity_histogram": {"range": [-3, 3], "bins": 60}
            }
        }),
    );
    ok(d, &["run", "rfm.json", "--out", "r", "--quiet"]);
    for (n, f, chi2, df) in [("0", "1e-3", "1e-3", "1e-3"), ("1e9", "100", "1000", "2")] {
        let args = [
            "analyze",
            "r",
            "--no-figures",
            "--n-min",
            n,
            "--count-error-factor",
            f,
            "--chi2-accept",
            chi2,
            "--fixed-df",
            df,
        ];
        ok(d, &args);
    }
}

/// `--out` (or `DIR`) naming a regular file, a dangling symbolic link or a path through a
/// file is "not a campaign directory": exit 3 with that message from every command, nothing
/// created, the file untouched (before: `run`/`theory`/`plan`/`submit` gave exit 4 or 0).
#[test]
fn out_naming_a_file_or_a_dangling_link_exits_3() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    fs::copy(
        repo_root().join("tests/manifests/good/power_law_sweep.json"),
        d.join("m.json"),
    )
    .unwrap();
    fs::write(d.join("file"), b"not a campaign").unwrap();
    std::os::unix::fs::symlink(d.join("nowhere"), d.join("dangling")).unwrap();
    for out in ["file", "dangling", "file/sub"] {
        let with_manifest: [&[&str]; 4] = [
            &["run", "m.json", "--out", out, "--quiet"],
            &["plan", "m.json", "--out", out],
            &["theory", "m.json", "--out", out],
            &[
                "submit",
                "m.json",
                "--out",
                out,
                "--slurm",
                "--tasks",
                "1",
                "--per-task-runs",
                "1",
                "--time",
                "1",
                "--dry-run",
            ],
        ];
        let with_dir: [&[&str]; 10] = [
            &["resume", out, "--quiet"],
            &["serve", out, "--addr", "127.0.0.1:0"],
            &["status", out],
            &["verify", out],
            &["compact", out],
            &["plot", out],
            &["upgrade", out],
            &["analyze", out],
            &["report", out],
            &["submit", "--missing", out, "--time", "1", "--dry-run"],
        ];
        for args in with_manifest.iter().chain(with_dir.iter()) {
            let before = snapshot(d);
            let o = granular(d, args);
            let err = String::from_utf8_lossy(&o.stderr);
            let what = format!("granular {args:?}: exit {:?}, stderr:\n{err}", o.status);
            assert_eq!(o.status.code(), Some(3), "{what}");
            assert!(
                err.contains("not a") && err.contains("campaign directory"),
                "{what}"
            );
            assert!(snapshot(d) == before, "the directory changed: {what}");
        }
    }
    assert!(!d.join("nowhere").exists());
}

/// Ctrl-C / SIGTERM before any simulation has started (here: in the kinetic-theory step of a
/// 200-species mixture, which takes many seconds) stops `theory` and `run` at once with exit
/// 130; before, `run` had installed its checkpoint-and-stop handler, which the theory step
/// never looks at.
#[test]
fn a_signal_before_any_run_started_exits_130() {
    let _g = heavy();
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    write_json(
        &d.join("m.json"),
        &serde_json::json!({
            "name": "slow-theory",
            "model": "dsmc",
            "seed": 1,
            "params": {
                "method": "low_rank",
                "species": {"power_law": {"n1": 0.1, "N1": 4000000, "theta": 3}},
                "restitution": {"constant": 0.5},
                "t_end": 100.0,
                "output_times": {"log": {"from": 0.01, "to": 100, "per_decade": 10}},
                "observables": ["msd"]
            }
        }),
    );
    for (args, signal) in [
        (["theory", "m.json", "--out", "t", ""], libc::SIGTERM),
        (["run", "m.json", "--out", "r", "--quiet"], libc::SIGTERM),
        (["run", "m.json", "--out", "r2", "--quiet"], libc::SIGINT),
    ] {
        let args: Vec<&str> = args.into_iter().filter(|a| !a.is_empty()).collect();
        let mut child = Command::new(bin())
            .args(&args)
            .current_dir(d)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(1500));
        // SAFETY: a signal to the child process spawned above.
        assert_eq!(unsafe { libc::kill(child.id() as libc::pid_t, signal) }, 0);
        let start = std::time::Instant::now();
        let status = loop {
            if let Some(s) = child.try_wait().unwrap() {
                break s;
            }
            if start.elapsed() > std::time::Duration::from_secs(60) {
                let _ = child.kill();
                panic!("granular {args:?} still running 60 s after the signal");
            }
            std::thread::sleep(std::time::Duration::from_millis(20));
        };
        let mut err = String::new();
        std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
        assert_eq!(status.code(), Some(130), "granular {args:?}:\n{err}");
        assert!(
            err.contains("interrupted before any simulation started"),
            "{err}"
        );
    }
}

/// Every command that prints ends quietly when its reader has gone (`granular plan M --json |
/// head -1`): stdout is a pipe whose read end is closed before the command starts, so its
/// first write fails with EPIPE; the command ends with its usual exit code (0 here), no panic,
/// no backtrace, no error message (before: `println!` panicked, exit 101). A stdout that fails
/// otherwise (`/dev/full`) is an error: exit 4, said once.
#[test]
fn a_closed_stdout_ends_printing_quietly() {
    let _g = heavy();
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    // 2 short runs; a sweep of 300 points for `plan`.
    let m = json!({
        "name": "closed-stdout",
        "model": "dsmc",
        "seed": 5,
        "replicas": 2,
        "params": {
            "method": "low_rank",
            "species": {"power_law": {"n1": 0.1, "N1": 2000, "theta": 3}},
            "restitution": {"constant": 0.7},
            "t_end": 5.0,
            "output_times": {"list": [1.0, 5.0]},
            "observables": ["temperature"]
        }
    });
    write_json(&d.join("m.json"), &m);
    let mut big = m.clone();
    big["sweep"] =
        json!({"restitution.constant": (1..=300).map(|i| i as f64 / 301.0).collect::<Vec<_>>()});
    write_json(&d.join("big.json"), &big);
    let o = granular(
        d,
        &["run", "m.json", "--out", "c", "--quiet", "--threads", "1"],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    let commands: &[&[&str]] = &[
        &["--help"],
        &["schema"],
        &["validate", "big.json"],
        &["plan", "big.json", "--out", "new"],
        &["plan", "big.json", "--out", "new", "--json"],
        &["run", "big.json", "--out", "new", "--dry-run"],
        &["status", "c"],
        &["status", "c", "--json"],
        &["verify", "c"],
        &["verify", "c", "--quick"],
        &["plot", "c", "--out", "figs"],
        &["report", "c", "--out", "r.html"],
        &["theory", "m.json", "--out", "t"],
        &["upgrade", "c"],
        &["compact", "c"],
        &[
            "submit",
            "big.json",
            "--out",
            "s",
            "--slurm",
            "--tasks",
            "1",
            "--per-task-runs",
            "1",
            "--time",
            "5",
            "--dry-run",
        ],
    ];
    for args in commands {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let o = Command::new(bin())
            .args(*args)
            .current_dir(d)
            .env("GRANULAR_SCONTROL", "/nonexistent/scontrol")
            .env_remove("RUST_BACKTRACE")
            .stdin(Stdio::null())
            .stdout(writer)
            .stderr(Stdio::piped())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(0), "{args:?}: {:?}\n{err}", o.status);
        for bad in ["panicked", "backtrace", "Broken pipe", "standard output"] {
            assert!(!err.contains(bad), "{args:?}: stderr says {bad:?}:\n{err}");
        }
    }

    if Path::new("/dev/full").exists() {
        for args in [&["schema"][..], &["status", "c"]] {
            let full = fs::OpenOptions::new()
                .write(true)
                .open("/dev/full")
                .unwrap();
            let o = Command::new(bin())
                .args(args)
                .current_dir(d)
                .stdin(Stdio::null())
                .stdout(full)
                .stderr(Stdio::piped())
                .output()
                .unwrap();
            let err = String::from_utf8_lossy(&o.stderr);
            assert_eq!(o.status.code(), Some(4), "{args:?}: {:?}\n{err}", o.status);
            assert_eq!(
                err.matches("error: cannot write to standard output")
                    .count(),
                1,
                "{args:?}:\n{err}"
            );
            assert!(!err.contains("panicked"), "{args:?}:\n{err}");
        }
    }
}
