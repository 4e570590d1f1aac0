//! The campaign directory is a closed world: a symbolic link where granular keeps its own file
//! or directory is damage, and no command reads, writes, moves or deletes through it. Each
//! drill plants a link to a directory outside the campaign (or a file where the quarantine
//! belongs) in a copy of a finished campaign, hashes every file of the outside directory, runs
//! `verify`, `status`, `compact`, `plot`, `report` and `resume`, and asserts: nothing outside
//! changed (no file written, moved or deleted); `verify` names the link (exit 3); `status`,
//! `compact` and `plot` refuse (exit 3, `compact` changing nothing); `resume` sets the link
//! itself aside (into the quarantine, logged in `actions.log`; a `quarantine` that is not a
//! directory renamed beside it) and heals the campaign to tables identical to the undamaged
//! campaign's, which `verify` then passes, with no link left but the generation links. The
//! commands are given the campaign directory through a link of its own (the user's choice,
//! followed once). `campaign.json` as a link is refused by every command (exit 3), naming it.

use std::fs;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use serde_json::{json, Value};

use super::util::{self, heavy, log_text, read_tables, run_capture, run_granular, write_json};
use super::util::{copy_dir, dead_pid, s};

const LIMIT: Duration = Duration::from_secs(300);

/// 4 small runs (two points x two replicas), each its own commit.
fn manifest() -> Value {
    json!({
        "name": "links",
        "model": "dsmc",
        "seed": 78,
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

/// A finished campaign in `dir/base`.
fn base(dir: &Path, log: &Path) -> PathBuf {
    let m = dir.join("m.json");
    write_json(&m, &manifest());
    let base = dir.join("base");
    let code = run_granular(
        &[
            "run",
            s(&m),
            "--out",
            s(&base),
            "--flush-every",
            "0",
            "--quiet",
        ],
        log,
        LIMIT,
    );
    assert_eq!(code, Some(0), "{}", log_text(log));
    base
}

fn symlink(target: &Path, link: &Path) {
    std::os::unix::fs::symlink(target, link).unwrap();
}

/// Files that a command following links would take for its own, in the outside directory:
/// an uncommitted part (recover deletes those), a stale temporary file of a dead process
/// (recover deletes those), a file that is not a table file (healing sets those aside).
fn bait(out: &Path, pid: u32) {
    fs::create_dir_all(out).unwrap();
    fs::write(out.join("secret.txt"), b"not granular's").unwrap();
    fs::write(out.join(".part-s1of1-00000009.parquet.pending"), b"p").unwrap();
    fs::write(
        out.join(format!(
            ".run-0000000003.ckpt.{pid}-1@{}.tmp",
            granular::fsutil::host_tag()
        )),
        b"t",
    )
    .unwrap();
}

/// Every entry under `dir` (bytes, times) and the directory's own modification time.
type Snapshot = (
    std::collections::BTreeMap<PathBuf, (Vec<u8>, SystemTime)>,
    SystemTime,
);

fn snap(dir: &Path) -> Snapshot {
    (
        util::snapshot(dir),
        fs::metadata(dir).unwrap().modified().unwrap(),
    )
}

/// The symbolic links under `dir` (not below `quarantine*`) that are not a table's link to
/// its generation.
fn foreign_links(dir: &Path) -> Vec<String> {
    let mut v = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            let rel = p.strip_prefix(dir).unwrap().to_string_lossy().into_owned();
            if rel.starts_with("quarantine") {
                continue;
            }
            let md = fs::symlink_metadata(&p).unwrap();
            if md.file_type().is_symlink() {
                let t = fs::read_link(&p).unwrap().to_string_lossy().into_owned();
                let table = rel.strip_prefix("tables/").unwrap_or("");
                let ours = !table.is_empty()
                    && !table.contains('/')
                    && t.strip_prefix(&format!(".gen/{table}."))
                        .is_some_and(|g| g.bytes().all(|b| b.is_ascii_digit()));
                if !ours {
                    v.push(format!("{rel} -> {t}"));
                }
            } else if md.is_dir() {
                stack.push(p);
            }
        }
    }
    v
}

struct Drill {
    name: &'static str,
    /// The entry planted, relative to the campaign directory: what `verify` must name and
    /// `resume` set aside.
    rel: &'static str,
    /// What `verify` says it is.
    is: &'static str,
    /// Plant it in the campaign `c`, pointing into `out` (a directory outside it).
    plant: fn(c: &Path, out: &Path),
}

fn drills() -> Vec<Drill> {
    vec![
        Drill {
            name: "tables -> a copy of the tables outside",
            rel: "tables",
            is: "a symbolic link",
            plant: |c, out| {
                let ok = std::process::Command::new("cp")
                    .args(["-a", &format!("{}/.", s(&c.join("tables"))), s(out)])
                    .status()
                    .unwrap();
                assert!(ok.success());
                fs::remove_dir_all(c.join("tables")).unwrap();
                symlink(out, &c.join("tables"));
            },
        },
        Drill {
            name: "a table's link (tables/runs) -> a copy of its files outside",
            rel: "tables/runs",
            is: "not to a generation of table runs",
            plant: |c, out| {
                for e in fs::read_dir(c.join("tables/runs")).unwrap() {
                    let p = e.unwrap().path();
                    fs::copy(&p, out.join(p.file_name().unwrap())).unwrap();
                }
                fs::remove_file(c.join("tables/runs")).unwrap();
                symlink(out, &c.join("tables/runs"));
            },
        },
        Drill {
            name: "a new table name (tables/evil) -> outside",
            rel: "tables/evil",
            is: "not to a generation of table evil",
            plant: |c, out| symlink(out, &c.join("tables/evil")),
        },
        Drill {
            name: "a committed part -> an identical copy outside",
            rel: "tables/dsmc_species/part-s1of1-00000002.parquet",
            is: "a symbolic link",
            plant: |c, out| {
                let part = c.join("tables/dsmc_species/part-s1of1-00000002.parquet");
                fs::copy(&part, out.join("part.parquet")).unwrap();
                fs::remove_file(&part).unwrap();
                symlink(&out.join("part.parquet"), &part);
            },
        },
        Drill {
            name: "quarantine -> outside, with a foreign file to set aside",
            rel: "quarantine",
            is: "a symbolic link",
            plant: |c, out| {
                symlink(out, &c.join("quarantine"));
                fs::write(c.join("tables/runs/notes.txt"), b"hello").unwrap();
            },
        },
        Drill {
            name: "quarantine a regular file, with a foreign file to set aside",
            rel: "quarantine",
            is: "a regular file",
            plant: |c, _| {
                fs::write(c.join("quarantine"), b"precious").unwrap();
                fs::write(c.join("tables/runs/notes.txt"), b"hello").unwrap();
            },
        },
        Drill {
            name: "ledger/s1of1 -> a copy of its records outside",
            rel: "ledger/s1of1",
            is: "a symbolic link",
            plant: |c, out| {
                for e in fs::read_dir(c.join("ledger/s1of1")).unwrap() {
                    let p = e.unwrap().path();
                    fs::copy(&p, out.join(p.file_name().unwrap())).unwrap();
                }
                fs::remove_dir_all(c.join("ledger/s1of1")).unwrap();
                symlink(out, &c.join("ledger/s1of1"));
            },
        },
        Drill {
            name: "checkpoints -> outside",
            rel: "checkpoints",
            is: "a symbolic link",
            plant: |c, out| {
                fs::write(out.join("run-0000000000.ckpt"), b"not a checkpoint").unwrap();
                fs::remove_dir_all(c.join("checkpoints")).unwrap();
                symlink(out, &c.join("checkpoints"));
            },
        },
    ]
}

/// Every drill on a copy of one finished campaign.
#[test]
fn links_out_of_the_campaign_are_named_never_followed_and_set_aside() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let base = base(dir.path(), &log);
    let want = read_tables(&base);
    let pid = dead_pid();
    for (k, d) in drills().into_iter().enumerate() {
        let c = dir.path().join(format!("c{k}"));
        let out = dir.path().join(format!("outside{k}"));
        copy_dir(&base, &c);
        bait(&out, pid);
        (d.plant)(&c, &out);
        // The commands reach the campaign through a link the user made: followed, once.
        let given = dir.path().join(format!("l{k}"));
        symlink(&c, &given);
        let link = fs::symlink_metadata(c.join(d.rel))
            .unwrap()
            .file_type()
            .is_symlink();
        let outside = snap(&out);
        let what = d.name;

        // The full check names it; the quick check (status) and the readers refuse it.
        fs::write(&log, "").unwrap();
        let (code, stdout) = run_capture(&["verify", s(&given)], &log);
        let text = log_text(&log);
        assert_eq!(code, Some(3), "{what}: verify:\n{stdout}\n{text}");
        let line = text.lines().find(|l| l.contains(&format!(" {}: ", d.rel)));
        assert!(
            line.is_some_and(|l| l.contains(d.is) && l.contains("not followed")),
            "{what}: verify does not name {} as {:?}:\n{text}",
            d.rel,
            d.is
        );
        for cmd in ["status", "plot"] {
            fs::write(&log, "").unwrap();
            let (code, _) = run_capture(&[cmd, s(&given)], &log);
            let text = log_text(&log);
            assert_eq!(code, Some(3), "{what}: {cmd}:\n{text}");
            assert!(
                text.contains(d.rel),
                "{what}: {cmd} does not name it:\n{text}"
            );
        }
        let files_of = |c: &Path| {
            let mut m = util::snapshot(c);
            m.retain(|p, _| !p.starts_with(c.join("locks")));
            m
        };
        let before = files_of(&c);
        fs::write(&log, "").unwrap();
        let (code, _) = run_capture(&["compact", s(&given)], &log);
        assert_eq!(code, Some(3), "{what}: compact:\n{}", log_text(&log));
        assert!(
            files_of(&c) == before,
            "{what}: the refused compact changed files"
        );
        // The report shows a damaged campaign (read as far as it can be without the link).
        fs::write(&log, "").unwrap();
        let (code, _) = run_capture(&["report", s(&given)], &log);
        assert_eq!(code, Some(0), "{what}: report:\n{}", log_text(&log));
        let page = fs::read_to_string(c.join("report.html")).unwrap();
        assert!(
            page.contains("damaged"),
            "{what}: the report does not say damaged"
        );
        assert!(
            snap(&out) == outside,
            "{what}: the commands changed the outside directory"
        );

        // `resume` sets the link itself aside and heals.
        fs::write(&log, "").unwrap();
        let code = run_granular(&["resume", s(&given)], &log, LIMIT);
        let text = log_text(&log);
        assert_eq!(code, Some(0), "{what}: resume:\n{text}");
        assert!(
            snap(&out) == outside,
            "{what}: resume changed the outside directory:\n{text}"
        );
        assert!(text.contains("healed:"), "{what}: nothing healed:\n{text}");
        let quarantines: Vec<PathBuf> = fs::read_dir(c.join("quarantine"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        assert_eq!(quarantines.len(), 1, "{what}: {quarantines:?}");
        let q = &quarantines[0];
        let actions = fs::read_to_string(q.join("actions.log")).unwrap();
        assert!(actions.contains(d.rel), "{what}: actions.log:\n{actions}");
        if d.rel == "quarantine" {
            // Renamed beside it: the link or the file itself, unchanged.
            let moved: Vec<PathBuf> = fs::read_dir(&c)
                .unwrap()
                .map(|e| e.unwrap().path())
                .filter(|p| {
                    p.file_name()
                        .unwrap()
                        .to_string_lossy()
                        .starts_with("quarantine.moved-")
                })
                .collect();
            assert_eq!(moved.len(), 1, "{what}: {moved:?}\n{actions}");
            if link {
                assert_eq!(fs::read_link(&moved[0]).unwrap(), out, "{what}");
            } else {
                assert_eq!(fs::read(&moved[0]).unwrap(), b"precious", "{what}");
            }
            assert!(
                actions.contains("tables/runs/notes.txt"),
                "{what}: the foreign file was not set aside:\n{actions}"
            );
            assert!(q.join("tables/runs/notes.txt").is_file(), "{what}");
        } else {
            let aside = q.join(d.rel);
            assert!(
                fs::symlink_metadata(&aside)
                    .unwrap_or_else(|e| panic!("{what}: {}: {e}\n{actions}", aside.display()))
                    .file_type()
                    .is_symlink(),
                "{what}: not the link itself in the quarantine"
            );
            assert!(fs::read_link(&aside).unwrap().starts_with(&out), "{what}");
        }
        assert_eq!(
            foreign_links(&c),
            Vec::<String>::new(),
            "{what}: links left in the campaign"
        );
        let (code, stdout) = run_capture(&["verify", s(&given)], &log);
        assert_eq!(
            code,
            Some(0),
            "{what}: verify after healing:\n{stdout}\n{}",
            log_text(&log)
        );
        util::assert_tables_identical(&want, &read_tables(&c), what);
        let (code, _) = run_capture(&["status", s(&given)], &log);
        assert_eq!(code, Some(0), "{what}: status after healing");
        assert!(
            snap(&out) == outside,
            "{what}: the outside directory changed"
        );
    }
}

/// `campaign.json` as a link (to a copy of itself outside): refused by every command that
/// opens a campaign (exit 3), naming it, before anything is read through it or written.
#[test]
fn campaign_json_as_a_link_is_refused_by_every_command() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let c = base(dir.path(), &log);
    let out = dir.path().join("outside");
    bait(&out, dead_pid());
    fs::rename(c.join("campaign.json"), out.join("campaign.json")).unwrap();
    symlink(&out.join("campaign.json"), &c.join("campaign.json"));
    let outside = snap(&out);
    let inside = util::snapshot(&c);
    let m = dir.path().join("m.json");
    for args in [
        vec!["verify", s(&c)],
        vec!["status", s(&c)],
        vec!["compact", s(&c)],
        vec!["plot", s(&c)],
        vec!["report", s(&c)],
        vec!["resume", s(&c)],
        vec!["run", s(&m), "--out", s(&c)],
    ] {
        fs::write(&log, "").unwrap();
        let (code, _) = run_capture(&args, &log);
        let text = log_text(&log);
        assert_eq!(code, Some(3), "{args:?}:\n{text}");
        assert!(
            text.contains("campaign.json") && text.contains("symbolic link"),
            "{args:?} does not name the link:\n{text}"
        );
        assert!(
            snap(&out) == outside,
            "{args:?} changed the outside directory"
        );
        assert!(
            util::snapshot(&c) == inside,
            "{args:?} changed the campaign"
        );
    }
}
