//! Ctrl-C (SIGINT): once = every running simulation is checkpointed and the process stops with
//! exit code 130; `resume` then finishes the campaign with tables bit-identical to an
//! uninterrupted run. Twice = exit at once. (Before any simulation has started, once = exit
//! at once: `cli_flags::a_signal_before_any_run_started_exits_130`.)

use std::fs;
use std::time::{Duration, Instant};

use serde_json::{json, Value};

use super::util::{
    self, granular, heavy, log_text, read_tables, run_granular, wait_limited, write_json,
};

fn manifest() -> Value {
    json!({
        "name": "interrupt-test",
        "model": "dsmc",
        "seed": 31337,
        "replicas": 2,
        "params": {
            "method": "low_rank",
            "species": {"power_law": {"n1": 0.1, "N1": 150000, "theta": 3}},
            "restitution": {"constant": 0.8},
            "t_end": 40.0,
            "output_times": {"log": {"from": 0.1, "to": 40.0, "per_decade": 4}},
            "observables": ["msd"]
        }
    })
}

fn sigint(pid: u32) {
    // SAFETY: sending a signal to a child process we spawned.
    let rc = unsafe { libc::kill(pid as libc::pid_t, libc::SIGINT) };
    assert_eq!(rc, 0, "kill(SIGINT) failed");
}

#[test]
fn ctrl_c_once_checkpoints_stops_and_resume_is_identical() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let m = dir.path().join("m.json");
    write_json(&m, &manifest());
    let log = dir.path().join("log.txt");
    let (a, b) = (dir.path().join("A"), dir.path().join("B"));
    let start = Instant::now();
    let code = run_granular(
        &[
            "run",
            m.to_str().unwrap(),
            "--out",
            a.to_str().unwrap(),
            "--threads",
            "2",
            "--quiet",
        ],
        &log,
        Duration::from_secs(300),
    );
    assert_eq!(code, Some(0), "reference run failed:\n{}", log_text(&log));
    let reference = start.elapsed();

    // Interrupt once both runs are in flight (2 runs, 2 threads): the debug log says when a
    // run has started (before that the campaign computes its theory tables).
    let blog = dir.path().join("b.txt");
    let mut child = granular(
        &[
            "run",
            m.to_str().unwrap(),
            "--out",
            b.to_str().unwrap(),
            "--threads",
            "2",
            "--quiet",
            "--checkpoint-every",
            "3600",
        ],
        &blog,
    )
    .env("GRANULAR_LOG", "debug")
    .spawn()
    .unwrap();
    let t0 = Instant::now();
    while log_text(&blog).matches("run started").count() < 2 {
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "runs never started:\n{}",
            log_text(&blog)
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    std::thread::sleep(reference.mul_f64(0.1));
    sigint(child.id());
    let log = blog;
    let status = wait_limited(&mut child, Duration::from_secs(60), "interrupted run", &log);
    assert_eq!(
        status.code(),
        Some(130),
        "Ctrl-C once must exit 130 after checkpointing:\n{}",
        log_text(&log)
    );
    // The only checkpoints are those written on the interrupt (the timer is an hour).
    let ckpts: Vec<_> = fs::read_dir(b.join("checkpoints"))
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".ckpt"))
        .collect();
    assert!(
        !ckpts.is_empty(),
        "no checkpoint written on Ctrl-C:\n{}",
        log_text(&log)
    );
    let st = util::status_json(&b, &log);
    assert_eq!(
        st["checkpointed"].as_u64(),
        Some(ckpts.len() as u64),
        "{st}"
    );
    assert!(st["pending"].as_u64().unwrap() >= 1, "{st}");

    let code = run_granular(
        &["resume", b.to_str().unwrap(), "--threads", "2", "--quiet"],
        &log,
        Duration::from_secs(300),
    );
    assert_eq!(code, Some(0), "resume failed:\n{}", log_text(&log));
    util::assert_tables_identical(
        &read_tables(&a),
        &read_tables(&b),
        "uninterrupted vs Ctrl-C + resume",
    );
}

#[test]
fn ctrl_c_twice_exits_at_once() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let m = dir.path().join("m.json");
    let mut man = manifest();
    // Long enough that it cannot finish during the test.
    man["params"]["t_end"] = json!(1e6);
    man["params"]["output_times"] = json!({"list": [1.0]});
    write_json(&m, &man);
    let log = dir.path().join("log.txt");
    let out = dir.path().join("C");
    let mut child = granular(
        &[
            "run",
            m.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--threads",
            "2",
            "--quiet",
        ],
        &log,
    )
    .env("GRANULAR_LOG", "debug")
    .spawn()
    .unwrap();
    // Once a run has started (before that, one signal exits at once: see
    // `cli_flags::a_signal_before_any_run_started_exits_130`).
    let t0 = Instant::now();
    while !log_text(&log).contains("run started") {
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "runs never started:\n{}",
            log_text(&log)
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    sigint(child.id());
    // The second signal once the first is handled: two SIGINTs that arrive while the first is
    // still pending are one signal to the kernel (seen on a loaded machine with a 5 ms gap).
    let t1 = Instant::now();
    while !log_text(&log).contains("interrupt: checkpointing") {
        assert!(t1.elapsed() < Duration::from_secs(20), "{}", log_text(&log));
        std::thread::sleep(Duration::from_millis(1));
    }
    sigint(child.id());
    let t = Instant::now();
    let status = wait_limited(
        &mut child,
        Duration::from_secs(20),
        "twice-interrupted run",
        &log,
    );
    assert_eq!(status.code(), Some(130), "{}", log_text(&log));
    assert!(
        t.elapsed() < Duration::from_secs(5),
        "second Ctrl-C took {:?}",
        t.elapsed()
    );
    assert!(
        log_text(&log).contains("interrupted twice"),
        "{}",
        log_text(&log)
    );
}
