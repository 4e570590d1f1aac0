//! Random stream versions (issue 25): the way a campaign's runs draw is recorded in its
//! `campaign.json` when it is created and never changes. Campaigns made before versions were
//! recorded (the committed fixture `tests/fixtures/format3-streams.tar.gz`, made by granular
//! 8e852f0, see tests/fixtures/README.md) are version 1: the new binary resumes and grows them
//! on that stream to the tables the old binary made. A new campaign records this granular's
//! current version (and `campaign.json` format 4, which granulars that predate versions
//! refuse); growth keeps it. A version this granular does not know is refused with exit 3,
//! nothing written.

use std::fs;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

use serde_json::{json, Value};

use super::util::{self, heavy, log_text, read_all, run_capture, run_granular, s, Cell};

const LIMIT: Duration = Duration::from_secs(300);

/// The stream version of new campaigns (`StreamVersion::CURRENT`).
const CURRENT: u64 = 4;

/// Unpack the committed fixture into `dir` (see tests/fixtures/README.md).
fn unpack(dir: &Path) {
    unpack_fixture(dir, "format3-streams.tar.gz");
}

fn unpack_fixture(dir: &Path, name: &str) {
    let tar = util::repo_root().join("tests/fixtures").join(name);
    let ok = Command::new("tar")
        .args(["xzf", s(&tar), "-C", s(dir)])
        .status()
        .unwrap();
    assert!(ok.success());
}

fn info(dir: &Path) -> Value {
    serde_json::from_slice(&fs::read(dir.join("campaign.json")).unwrap()).unwrap()
}

fn write_info(dir: &Path, v: &Value) {
    util::write_json(&dir.join("campaign.json"), v);
}

/// `granular ARGS` exits 0 (the log in the message otherwise).
fn ok(args: &[&str], log: &Path) {
    fs::write(log, "").unwrap();
    let code = run_granular(args, log, LIMIT);
    assert_eq!(
        code,
        Some(0),
        "granular {}: {}",
        args.join(" "),
        log_text(log)
    );
}

/// `granular run M --out DIR` (one thread, commits at once, no final states as the fixture
/// was made).
fn run(m: &Path, dir: &Path, log: &Path) {
    ok(
        &[
            "run",
            s(m),
            "--out",
            s(dir),
            "--threads",
            "1",
            "--flush-every",
            "0",
            "--no-final-states",
            "--quiet",
        ],
        log,
    );
}

/// Every table of two campaigns holds the same rows bit for bit (rows sorted; the measured
/// `runs.wall_seconds` left out).
fn assert_same_tables(a: &Path, b: &Path, what: &str) {
    let (ta, tb) = (read_all(a), read_all(b));
    assert_eq!(
        ta.keys().collect::<Vec<_>>(),
        tb.keys().collect::<Vec<_>>(),
        "{what}: other tables"
    );
    for (name, t) in &ta {
        let u = &tb[name];
        assert_eq!(t.columns, u.columns, "{what}: {name}: other columns");
        let rows = |t: &util::Table| {
            let wall = (name == "runs").then(|| t.col("wall_seconds"));
            let mut rows = t.rows.clone();
            for r in &mut rows {
                if let Some(j) = wall {
                    r[j] = Cell::Null;
                }
            }
            rows.sort();
            rows
        };
        let (ra, rb) = (rows(t), rows(u));
        assert_eq!(ra.len(), rb.len(), "{what}: {name}: row counts differ");
        let differing = ra.iter().zip(&rb).filter(|(x, y)| x != y).count();
        assert_eq!(differing, 0, "{what}: {name}: {differing} rows differ");
    }
}

/// What `status --json` says of the stream, and the text line of `status`.
fn status_stream(dir: &Path, log: &Path) -> (Value, String) {
    let st = util::status_json(dir, log);
    let (code, text) = run_capture(&["status", s(dir)], log);
    assert_eq!(code, Some(0), "{}", log_text(log));
    let line = text
        .lines()
        .find(|l| l.contains("random stream"))
        .unwrap_or_else(|| panic!("status names no random stream:\n{text}"))
        .trim()
        .to_string();
    (st["stream_version"].clone(), line)
}

/// `plan M --out DIR --json --no-probe`'s stream version.
fn plan_stream(m: &Path, dir: &Path, log: &Path) -> Value {
    let (code, out) = run_capture(
        &["plan", s(m), "--out", s(dir), "--json", "--no-probe"],
        log,
    );
    assert_eq!(code, Some(0), "{}", log_text(log));
    let p: Value = serde_json::from_str(&out).unwrap();
    p["stream_version"].clone()
}

/// The fixture's campaigns, made before stream versions, are version 1: the interrupted one
/// resumes from its old checkpoint to the complete one's tables, the complete ones grow by a
/// replica to the tables the old binary made by the same growth (`grown/`, `grown1d/`): the
/// old rows unchanged and the new runs drawn on stream 1. Their `campaign.json` stays of
/// format 3 and version 1.
#[test]
fn campaigns_before_stream_versions_continue_on_stream_1() {
    let _g = heavy();
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let log = d.join("log");
    unpack(d);
    let (complete, interrupted) = (d.join("complete"), d.join("interrupted"));
    assert!(info(&complete).get("stream_version").is_none());

    let (v, line) = status_stream(&complete, &log);
    assert_eq!(
        v,
        json!(1),
        "status --json of a campaign that predates versions"
    );
    assert_eq!(line, "random stream: version 1 (ChaCha8, sequential draws)");
    assert_eq!(
        plan_stream(&d.join("m-grown.json"), &complete, &log),
        json!(1)
    );

    ok(
        &["resume", s(&interrupted), "--threads", "1", "--quiet"],
        &log,
    );
    assert!(
        !log_text(&log).contains("restarting from t = 0"),
        "the old checkpoint was not resumed:\n{}",
        log_text(&log)
    );
    assert_same_tables(&interrupted, &complete, "interrupted/ resumed vs complete/");

    for (c, m, grown) in [
        ("complete", "m-grown.json", "grown"),
        ("complete1d", "m1d-grown.json", "grown1d"),
    ] {
        let c = d.join(c);
        run(&d.join(m), &c, &log);
        assert_same_tables(&c, &d.join(grown), &format!("{} grown", c.display()));
    }
    for c in ["complete", "interrupted", "complete1d"] {
        let i = info(&d.join(c));
        assert_eq!(i["format_version"], json!(3), "{c}");
        assert!(
            matches!(i.get("stream_version"), None | Some(&Value::Number(_)))
                && i.get("stream_version").map_or(1, |v| v.as_u64().unwrap()) == 1,
            "{c}: {i}"
        );
        assert_eq!(status_stream(&d.join(c), &log).0, json!(1), "{c}");
    }
}

/// A campaign of stream version 3 (`format4-stream3.tar.gz`, made by granular 2a65aa2: RFM 2D
/// runs of N = 4200, whose noise version 4 addresses by storage slot) stays version 3: the
/// interrupted one resumes from its checkpoint to the complete one's tables, the complete one
/// grows by a replica to the tables the old binary made by the same growth, and `status` and
/// `plan` say version 3; a new campaign of the same manifest (version 4) draws other numbers.
#[test]
fn stream_3_campaigns_continue_on_stream_3() {
    let _g = heavy();
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let log = d.join("log");
    unpack_fixture(d, "format4-stream3.tar.gz");
    let (complete, interrupted) = (d.join("complete"), d.join("interrupted"));
    util::copy_dir(&complete, &d.join("fixture-complete"));
    assert_eq!(info(&complete)["stream_version"], json!(3));
    let (v, line) = status_stream(&complete, &log);
    assert_eq!(v, json!(3));
    assert_eq!(
        line,
        "random stream: version 3 (counter-addressed RFM noise, DSMC from AES-128-CTR)"
    );
    assert_eq!(
        plan_stream(&d.join("m-grown.json"), &complete, &log),
        json!(3)
    );
    ok(
        &["resume", s(&interrupted), "--threads", "1", "--quiet"],
        &log,
    );
    assert!(
        !log_text(&log).contains("restarting from t = 0"),
        "the version-3 checkpoint was not resumed:\n{}",
        log_text(&log)
    );
    assert_same_tables(&interrupted, &complete, "interrupted/ resumed vs complete/");
    run(&d.join("m-grown.json"), &complete, &log);
    assert_same_tables(&complete, &d.join("grown"), "complete/ grown vs grown/");
    for c in ["complete", "interrupted"] {
        let i = info(&d.join(c));
        assert_eq!(i["stream_version"], json!(3), "{c}");
        assert_eq!(i["format_version"], json!(4), "{c}");
    }
    // The same manifest as a new campaign: version 4, other noise, so other rows.
    let fresh = d.join("fresh");
    run(&d.join("m.json"), &fresh, &log);
    assert_eq!(info(&fresh)["stream_version"], json!(CURRENT));
    let rows = |c: &Path| {
        let mut r = read_all(c)["rfm_timeseries_summary"].rows.clone();
        r.sort();
        r
    };
    let (a, b) = (rows(&fresh), rows(&d.join("fixture-complete")));
    assert!(!a.is_empty() && a.len() == b.len());
    assert!(a != b, "version 4 drew as version 3");
}

/// A new campaign records this granular's current stream version (`campaign.json` of format
/// 4), shows it in `status`, `status --json` and `plan`, and keeps it when it grows; the
/// grown campaign equals the one started from the final manifest (both drawing on the
/// current stream).
#[test]
fn new_campaigns_record_the_current_stream_and_keep_it() {
    let _g = heavy();
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let log = d.join("log");
    unpack(d);
    let (m, mg) = (d.join("m.json"), d.join("m-grown.json"));
    let (a, b) = (d.join("a"), d.join("b"));
    assert_eq!(plan_stream(&m, &a, &log), json!(CURRENT));
    assert!(!a.exists(), "plan wrote");
    run(&m, &a, &log);
    let i = info(&a);
    assert_eq!(i["stream_version"], json!(CURRENT));
    assert_eq!(i["format_version"], json!(4));
    let (v, line) = status_stream(&a, &log);
    assert_eq!(v, json!(CURRENT));
    assert_eq!(
        line,
        "random stream: version 4 (RFM noise addressed by storage slot, DSMC from AES-128-CTR)"
    );
    assert_eq!(plan_stream(&mg, &a, &log), json!(CURRENT));

    // Growth and a resume keep it.
    run(&mg, &a, &log);
    ok(&["resume", s(&a), "--threads", "1", "--quiet"], &log);
    let i = info(&a);
    assert_eq!(i["stream_version"], json!(CURRENT));
    assert_eq!(i["format_version"], json!(4));
    run(&mg, &b, &log);
    // Run ids depend on the order of growth: compared by params and replica.
    util::assert_same_current(&a, &b, "grown vs started from the final manifest");
    ok(&["verify", s(&a)], &log);
}

/// A `campaign.json` naming a stream version this granular does not know (a newer granular
/// made it), or one that is not a version, or a format that does not match its version, is
/// refused by every command with exit 3, naming the file and what is wrong; nothing changes.
#[test]
fn unknown_stream_versions_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let log = d.join("log");
    unpack(d);
    let c = d.join("complete");
    let m = d.join("m.json");
    let original = info(&c);
    let report = d.join("report.html");
    // (what, the fields changed, what the message says, whether `upgrade` refuses it too: a
    // format that does not match its version is found by the commands that open the
    // campaign, `upgrade` has nothing to do for a format it writes).
    let cases: Vec<(&str, Value, &[&str], bool)> = vec![
        (
            "version 99",
            json!({"format_version": 4, "stream_version": 99}),
            &["stream_version", "random stream version 99 is not known"],
            true,
        ),
        (
            "version 99 of format 3",
            json!({"stream_version": 99}),
            &["stream_version", "99"],
            true,
        ),
        (
            "not a number",
            json!({"format_version": 4, "stream_version": "two"}),
            &[
                "stream_version",
                "expected a random stream version",
                "found \"two\"",
            ],
            true,
        ),
        (
            "version 0",
            json!({"format_version": 4, "stream_version": 0}),
            &[
                "stream_version",
                "expected a random stream version",
                "found 0",
            ],
            true,
        ),
        (
            "version 2 in format 3",
            json!({"stream_version": 2}),
            &["format version 3 with random stream version 2"],
            false,
        ),
        (
            "version 1 in format 4",
            json!({"format_version": 4, "stream_version": 1}),
            &["format version 4 with random stream version 1"],
            false,
        ),
    ];
    for (what, edit, said, upgrade_refuses) in cases {
        let mut i = original.clone();
        for (k, v) in edit.as_object().unwrap() {
            i[k] = v.clone();
        }
        write_info(&c, &i);
        let before = util::snapshot(&c);
        let mut commands: Vec<Vec<&str>> = vec![
            vec!["status", s(&c)],
            vec!["status", s(&c), "--json"],
            vec!["resume", s(&c), "--quiet"],
            vec!["run", s(&m), "--out", s(&c), "--quiet"],
            vec!["plan", s(&m), "--out", s(&c), "--no-probe"],
            vec!["verify", s(&c)],
            vec!["report", s(&c), "--out", s(&report)],
        ];
        if upgrade_refuses {
            commands.push(vec!["upgrade", s(&c)]);
        }
        for cmd in commands {
            fs::write(&log, "").unwrap();
            let code = run_granular(&cmd, &log, LIMIT);
            let text = log_text(&log);
            assert_eq!(code, Some(3), "{what}: granular {}: {text}", cmd.join(" "));
            assert!(
                text.contains("campaign.json") && said.iter().all(|w| text.contains(w)),
                "{what}: granular {}: the message names neither the file nor {said:?}:\n{text}",
                cmd.join(" ")
            );
            assert!(!text.contains("panicked"), "{text}");
        }
        assert!(
            util::snapshot(&c) == before,
            "{what}: a refused command wrote"
        );
    }
}

/// A checkpoint that does not draw as its campaign's stream (here the fixture's version-1
/// checkpoint of run 2 in a campaign whose `campaign.json` was edited to the current version,
/// as a checkpoint copied in from another campaign would be) is not resumed: the run starts
/// again from t = 0 on the campaign's stream, with a warning that says why, and its rows are
/// those of run 2 of a new campaign of the same manifest. Without the check the run would go
/// on drawing from version 1 in a campaign of version 4.
#[test]
fn checkpoints_of_another_stream_are_not_resumed() {
    let _g = heavy();
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let log = d.join("log");
    unpack(d);
    let interrupted = d.join("interrupted");
    let mut i = info(&interrupted);
    i["format_version"] = json!(4);
    i["stream_version"] = json!(CURRENT);
    write_info(&interrupted, &i);
    ok(
        &["resume", s(&interrupted), "--threads", "1", "--quiet"],
        &log,
    );
    let text = log_text(&log);
    assert!(
        text.contains(&format!(
            "run 2: checkpoint unusable (it does not draw as the campaign's random stream \
             (version {CURRENT})); restarting from t = 0"
        )),
        "no warning for the version-1 checkpoint:\n{text}"
    );
    let fresh = d.join("fresh");
    run(&d.join("m.json"), &fresh, &log);
    // Run 2's rows in every table with a run id: the fresh campaign's (runs 0 and 1 were
    // committed on version 1 before the edit).
    let (a, b) = (read_all(&interrupted), read_all(&fresh));
    let mut compared = 0;
    for (name, t) in &a {
        let Some(j) = t.columns.iter().position(|(c, _)| c == "run_id") else {
            continue;
        };
        let run2 = |t: &util::Table| {
            let wall = t.columns.iter().position(|(c, _)| c == "wall_seconds");
            let mut rows: Vec<Vec<Cell>> = t
                .rows
                .iter()
                .filter(|r| r[j] == Cell::U(2))
                .cloned()
                .collect();
            for r in &mut rows {
                if let Some(w) = wall {
                    r[w] = Cell::Null;
                }
            }
            rows.sort();
            rows
        };
        let (ra, rb) = (run2(t), run2(&b[name]));
        assert!(!ra.is_empty(), "{name}: no rows of run 2");
        assert_eq!(ra, rb, "{name}: run 2 differs from a new campaign's");
        compared += 1;
    }
    assert!(compared >= 2, "only {compared} tables with run ids");
}
