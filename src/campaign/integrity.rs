//! The tables against the ledger: every committed file present with its recorded size (a
//! quick check) and SHA-256 (a full scrub), no committed part without a commit, no run in two
//! commits, every rebuilt table (points, theory, summaries: files written whole) matching its
//! sidecar (`sums/`). `run`/`resume` heal what they find ([`heal`]); `status` and `compact` refuse and
//! name the command that heals it; `verify` reports.
//!
//! Healing never trusts what it cannot check and never doubles a row:
//! - a commit with a missing or damaged file is undone: its files are set aside (moved to
//!   `quarantine/<time>-<pid>/`), then its record (or its group of the index) is removed, so
//!   its runs run again (bit-identical: rows depend only on the seed and parameters);
//! - of two commits holding one run, the later is undone;
//! - an unreadable commit record or index is set aside; the parts it named become parts
//!   without a commit;
//! - parts without a commit are grouped by the commit their footers name (`granular.commit`):
//!   a complete group (every table its footer lists, all readable, runs committed nowhere else)
//!   gets its commit record back (a lost ledger is rebuilt this way); anything else is set
//!   aside and its runs run again;
//! - a rebuilt table whose file does not match its sidecar, and the summaries once runs are
//!   undone, are set aside and written again.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};

use arrow_array::cast::AsArray;
use arrow_array::types::UInt64Type;

use super::ledger::{self, Commit, CommittedRun, PartCommit, RunStatus};
use super::{tables, Campaign};
use crate::fsutil;
use crate::store::checksum::{self, FileSum, Mismatch};
use crate::store::layout;
use crate::store::parquet_io;
use crate::store::LEDGER_FORMAT;

/// How deep the check goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Depth {
    /// Presence and sizes (cheap: one `stat` per file).
    Quick,
    /// Sizes and SHA-256 of every file (reads everything).
    Full,
}

/// A committed file that does not match its commit.
#[derive(Debug, Clone)]
pub struct BadFile {
    /// Index into `Check::commits`.
    pub commit: usize,
    pub file: FileSum,
    pub found: Mismatch,
}

/// What a check found.
#[derive(Debug, Clone, Default)]
pub struct Check {
    /// The ledger as read (good commits).
    pub commits: Vec<Commit>,
    /// Unreadable commit records and index: (path, why).
    pub bad_ledger: Vec<(PathBuf, String)>,
    pub bad_files: Vec<BadFile>,
    /// Runs in more than one commit: run -> indexes into `commits`, first first.
    pub doubled: BTreeMap<u64, Vec<usize>>,
    /// Committed parts (`part-*.parquet`) in no commit, relative to the campaign directory.
    pub orphans: Vec<String>,
    /// Rebuilt tables' files that do not match their sidecar: (relative path, why).
    pub bad_derived: Vec<(String, String)>,
    /// Visible files in a table directory that are not Parquet files.
    pub foreign: Vec<String>,
    /// Shards whose writers are live (their commits in flight are not judged).
    pub live: Vec<String>,
    /// Why the check was skipped (a compaction running), if it was.
    pub skipped: Option<String>,
}

impl Check {
    pub fn clean(&self) -> bool {
        self.bad_ledger.is_empty()
            && self.bad_files.is_empty()
            && self.doubled.is_empty()
            && self.orphans.is_empty()
            && self.bad_derived.is_empty()
            && self.foreign.is_empty()
    }

    /// One line per problem.
    pub fn problems(&self) -> Vec<String> {
        let mut v = Vec::new();
        for (p, why) in &self.bad_ledger {
            v.push(format!("{}: {why}", p.display()));
        }
        for b in &self.bad_files {
            let c = &self.commits[b.commit];
            v.push(match &b.found {
                Mismatch::Missing => format!(
                    "{}: missing (committed by {} with {} runs)",
                    b.file.path,
                    c.name(),
                    c.runs.len()
                ),
                found => format!(
                    "{}: {found}, but commit {} recorded {} bytes, SHA-256 {}",
                    b.file.path,
                    c.name(),
                    b.file.bytes,
                    b.file.sha256
                ),
            });
        }
        for (run, cs) in &self.doubled {
            let names: Vec<String> = cs.iter().map(|&i| self.commits[i].name()).collect();
            v.push(format!(
                "run {run} is in {} commits: {}",
                cs.len(),
                names.join(", ")
            ));
        }
        for o in &self.orphans {
            v.push(format!("{o}: a table part in no commit"));
        }
        for (p, why) in &self.bad_derived {
            v.push(format!("{p}: {why}"));
        }
        for f in &self.foreign {
            v.push(format!(
                "{f}: not a table file (it does not belong in tables/)"
            ));
        }
        v
    }
}

/// Check the campaign's tables against its ledger (see the module's text). Commits of live
/// writers are judged only once their parts are visible; with a compaction running nothing is
/// checked.
pub fn check(c: &Campaign, depth: Depth) -> Result<Check, String> {
    let first = check_once(&c.root, depth)?;
    if first.clean() || first.live.is_empty() {
        return Ok(first);
    }
    // A writer may have committed, or rewritten a table, while we looked: look once more.
    std::thread::sleep(std::time::Duration::from_millis(200));
    check_once(&c.root, depth)
}

fn check_once(root: &Path, depth: Depth) -> Result<Check, String> {
    let mut out = Check::default();
    let live_locks = ledger::live_locks(root);
    let ours = |l: &ledger::LockInfo| l.pid == std::process::id() && l.host == ledger::hostname();
    if let Some(l) = live_locks
        .iter()
        .find(|l| l.shard_tag == ledger::COMPACT_TAG && !ours(l))
    {
        out.skipped = Some(format!(
            "a compaction is running (process {} on {})",
            l.pid, l.host
        ));
        return Ok(out);
    }
    out.live = live_locks
        .into_iter()
        .filter(|l| !ours(l))
        .map(|l| l.shard_tag)
        .collect();
    let l = ledger::read_ledger(root)?;
    out.bad_ledger = l.bad_records.clone();
    if let Some(why) = &l.bad_index {
        out.bad_ledger.push((ledger::index_path(root), why.clone()));
    }
    out.commits = l.commits;
    let full = depth == Depth::Full;
    let mut committed: BTreeSet<String> = BTreeSet::new();
    let mut runs: BTreeMap<u64, Vec<usize>> = BTreeMap::new();
    for (i, c) in out.commits.iter().enumerate() {
        for r in &c.runs {
            runs.entry(r.run_id).or_default().push(i);
        }
        let live = out.live.contains(&c.shard);
        for f in &c.files {
            committed.insert(f.path.clone());
            let path = root.join(&f.path);
            if live && ledger::pending_path(&path).exists() {
                continue; // in flight
            }
            if let Some(found) =
                checksum::check(&path, f, full).map_err(|e| format!("{}: {e}", path.display()))?
            {
                out.bad_files.push(BadFile {
                    commit: i,
                    file: f.clone(),
                    found,
                });
            }
        }
    }
    out.doubled = runs.into_iter().filter(|(_, v)| v.len() > 1).collect();
    // A sidecar without its file: a rebuilt table's file is gone.
    for (table, name) in checksum::sidecars(root) {
        if !root.join("tables").join(&table).join(&name).exists() {
            out.bad_derived.push((
                format!("tables/{table}/{name}"),
                "missing (its checksum sidecar is there)".into(),
            ));
        }
    }
    for table in layout::table_names(root).map_err(|e| format!("{}: {e}", root.display()))? {
        let dir = root.join("tables").join(&table);
        let Ok(entries) = fs::read_dir(&dir) else {
            continue;
        };
        let mut names: Vec<String> = entries
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        for name in names {
            if name.starts_with('.') {
                continue;
            }
            let rel = format!("tables/{table}/{name}");
            if committed.contains(&rel) {
                continue;
            }
            if !name.ends_with(".parquet") {
                out.foreign.push(rel);
                continue;
            }
            if is_part_name(&name) {
                out.orphans.push(rel);
                continue;
            }
            let path = dir.join(&name);
            let why = match checksum::read_sidecar(root, &table, &name) {
                None => Some("a rebuilt table's file without a valid checksum sidecar".to_string()),
                Some(rec) => checksum::check(&path, &rec, full)
                    .map_err(|e| format!("{}: {e}", path.display()))?
                    .map(|m| {
                        format!(
                            "{m}, but its sidecar recorded {} bytes, SHA-256 {}",
                            rec.bytes, rec.sha256
                        )
                    }),
            };
            if let Some(why) = why {
                out.bad_derived.push((rel, why));
            }
        }
    }
    Ok(out)
}

/// `tables/<t>/<name>` (a path relative to the campaign directory) -> (`<t>`, `<name>`).
pub fn table_and_name(rel: &str) -> (&str, &str) {
    let mut parts = rel.splitn(3, '/').skip(1);
    (parts.next().unwrap_or(""), parts.next().unwrap_or(""))
}

/// Committed parts are named `part-*.parquet` (and, before checksums, `compact-*.parquet`);
/// every other file of a table is written whole and rebuilt.
pub fn is_part_name(name: &str) -> bool {
    (name.starts_with("part-") || name.starts_with("compact-")) && name.ends_with(".parquet")
}

/// What healing did.
#[derive(Debug, Clone, Default)]
pub struct Healed {
    /// One line per action.
    pub actions: Vec<String>,
    /// Runs whose commit was undone (they run again).
    pub undone_runs: BTreeSet<u64>,
    /// Where the set-aside files are, if any were.
    pub quarantine: Option<PathBuf>,
}

struct Quarantine {
    root: PathBuf,
    dir: PathBuf,
    used: bool,
}

impl Quarantine {
    fn new(root: &Path) -> Self {
        let secs = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_secs())
            .unwrap_or(0);
        Quarantine {
            root: root.to_path_buf(),
            dir: root
                .join("quarantine")
                .join(format!("{secs}-{}", std::process::id())),
            used: false,
        }
    }

    /// Move `rel` (relative to the campaign directory) into the quarantine; a file already
    /// gone is fine.
    fn set_aside(&mut self, rel: &str) -> Result<bool, String> {
        let from = self.root.join(rel);
        if fs::symlink_metadata(&from).is_err() {
            return Ok(false);
        }
        let to = self.dir.join(rel);
        let parent = to.parent().expect("parent");
        fsutil::create_dir_durable(parent).map_err(|e| format!("{}: {e}", parent.display()))?;
        match fs::rename(&from, &to) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(false),
            Err(e) => return Err(format!("{}: {e}", from.display())),
        }
        if let Some(d) = from.parent() {
            let _ = fsutil::sync_dir(d);
        }
        self.used = true;
        Ok(true)
    }
}

/// Heal what `check` found (see the module's text), for a process holding a shard lock (or
/// the compaction lock): commits of live shards other than `ours` are left alone. Every
/// action is returned and logged in the quarantine's `actions.log`.
pub fn heal(c: &Campaign, found: &Check, ours: &str) -> Result<Healed, String> {
    let root = &c.root;
    let mut h = Healed::default();
    let mut q = Quarantine::new(root);
    let live: Vec<&String> = found.live.iter().filter(|t| *t != ours).collect();
    let is_live = |shard: &str| live.iter().any(|t| *t == shard);

    // Unreadable ledger files: set aside; the parts they named become parts without a commit.
    for (p, why) in &found.bad_ledger {
        let rel = p
            .strip_prefix(root)
            .unwrap_or(p)
            .to_string_lossy()
            .into_owned();
        if q.set_aside(&rel)? {
            h.actions
                .push(format!("set aside the unreadable {rel} ({why})"));
        }
    }

    // Commits to undo: those with a bad file, and the later holders of a doubled run.
    let mut undo: BTreeSet<usize> = found.bad_files.iter().map(|b| b.commit).collect();
    for cs in found.doubled.values() {
        undo.extend(cs.iter().skip(1));
    }
    // Files a kept commit names stay (two records of one commit name the same files).
    let kept_files: BTreeSet<&str> = found
        .commits
        .iter()
        .enumerate()
        .filter(|(i, _)| !undo.contains(i))
        .flat_map(|(_, cm)| cm.files.iter().map(|f| f.path.as_str()))
        .collect();
    let mut index_changed = false;
    let mut index = ledger::read_index(root).ok().flatten();
    for &i in &undo {
        let cm = &found.commits[i];
        if !cm.in_index && is_live(&cm.shard) {
            h.actions.push(format!(
                "left commit {} alone: its shard is running (resume it once that shard stops)",
                cm.name()
            ));
            continue;
        }
        // Files first: a stop in between leaves a commit with missing files (undone again).
        for f in cm
            .files
            .iter()
            .filter(|f| !kept_files.contains(f.path.as_str()))
        {
            q.set_aside(&f.path)?;
        }
        if cm.in_index {
            if let Some(ix) = index.as_mut() {
                ix.groups
                    .retain(|g| !(g.shard == cm.shard && g.seq == cm.seq));
                index_changed = true;
            }
        } else {
            let rec = ledger::commit_path(root, &cm.shard, cm.seq);
            let rel = rec
                .strip_prefix(root)
                .unwrap_or(&rec)
                .to_string_lossy()
                .into_owned();
            q.set_aside(&rel)?;
        }
        let why: Vec<String> = found
            .bad_files
            .iter()
            .filter(|b| b.commit == i)
            .map(|b| format!("{} {}", b.file.path, b.found))
            .collect();
        h.actions.push(format!(
            "undid commit {} ({} runs run again; {})",
            cm.name(),
            cm.runs.len(),
            if why.is_empty() {
                "its runs were committed before".to_string()
            } else {
                why.join(", ")
            }
        ));
        h.undone_runs.extend(cm.runs.iter().map(|r| r.run_id));
    }
    if index_changed {
        if let Some(ix) = &index {
            ledger::write_index(root, ix)?;
        }
    }
    // Runs still committed elsewhere are not run again.
    let kept: BTreeSet<u64> = found
        .commits
        .iter()
        .enumerate()
        .filter(|(i, _)| !undo.contains(i))
        .flat_map(|(_, cm)| cm.runs.iter().map(|r| r.run_id))
        .collect();
    h.undone_runs.retain(|r| !kept.contains(r));

    // Parts without a commit (including those of records set aside above).
    let after = check_once(root, Depth::Quick)?;
    adopt_or_set_aside(c, &after, &is_live, &mut q, &mut h)?;

    // Rebuilt tables: damaged ones, and the summaries once runs were undone.
    let mut derived: Vec<(String, String)> = found.bad_derived.clone();
    for d in &after.bad_derived {
        if !derived.iter().any(|(p, _)| *p == d.0) {
            derived.push(d.clone());
        }
    }
    if !h.undone_runs.is_empty() {
        let keep: Vec<&str> = std::iter::once(tables::POINTS)
            .chain(c.theory_tables())
            .collect();
        for table in layout::table_names(root).map_err(|e| e.to_string())? {
            if keep.contains(&table.as_str()) {
                continue;
            }
            for f in c.data().files(&table).map_err(|e| e.to_string())? {
                let name = f.file_name().unwrap().to_string_lossy().into_owned();
                if !is_part_name(&name) {
                    let rel = format!("tables/{table}/{name}");
                    if !derived.iter().any(|(p, _)| *p == rel) {
                        derived.push((rel, "a summary of runs that run again".into()));
                    }
                }
            }
        }
    }
    for (rel, why) in &derived {
        let (t, n) = table_and_name(rel);
        let side = checksum::sidecar_path(root, t, n);
        if q.set_aside(rel)? {
            let _ = fs::remove_file(&side);
            h.actions
                .push(format!("set aside {rel} ({why}); it is written again"));
        } else if fs::remove_file(&side).is_ok() {
            h.actions.push(format!(
                "removed the checksum sidecar of the missing {rel}; it is written again"
            ));
        }
    }
    let mut foreign = found.foreign.clone();
    foreign.extend(
        after
            .foreign
            .iter()
            .filter(|f| !found.foreign.contains(f))
            .cloned(),
    );
    for rel in &foreign {
        if q.set_aside(rel)? {
            h.actions
                .push(format!("set aside {rel} (not a table file)"));
        }
    }
    if q.used {
        let log = q.dir.join("actions.log");
        let mut text = h.actions.join("\n");
        text.push('\n');
        fsutil::write_atomic(&log, text.as_bytes())
            .map_err(|e| format!("{}: {e}", log.display()))?;
        h.quarantine = Some(q.dir.clone());
    }
    Ok(h)
}

/// A part without a commit: its footer's commit, or why it has none.
fn part_commit(c: &Campaign, rel: &str) -> Result<PartCommit, String> {
    let path = c.root.join(rel);
    let (info, _) = parquet_io::inspect(&path).map_err(|e| e.to_string())?;
    let table = table_and_name(rel).0;
    parquet_io::check_part(&path, &info, table, Some(&c.identity)).map_err(|e| e.to_string())?;
    let Some(json) = info.commit else {
        return Err(format!(
            "{rel}: its footer names no commit (written before commits were recorded in parts)"
        ));
    };
    serde_json::from_str(&json).map_err(|e| format!("{rel}: unreadable granular.commit: {e}"))
}

/// Every row of a part, decoded (a damaged page is an error), and its runs if it is `runs`.
fn read_whole(c: &Campaign, rel: &str) -> Result<Vec<CommittedRun>, String> {
    let table = table_and_name(rel).0;
    let batches = c
        .data()
        .read_file(&c.root.join(rel), table)
        .map_err(|e| e.to_string())?;
    if table != tables::RUNS {
        return Ok(Vec::new());
    }
    let mut runs = Vec::new();
    for b in &batches {
        let ids = b
            .column_by_name("run_id")
            .and_then(|c| c.as_primitive_opt::<UInt64Type>())
            .ok_or_else(|| format!("{rel}: no run_id column"))?;
        let status = b
            .column_by_name("status")
            .and_then(|c| c.as_string_opt::<i32>())
            .ok_or_else(|| format!("{rel}: no status column"))?;
        for (id, st) in ids.iter().zip(status.iter()) {
            let (Some(run_id), Some(st)) = (id, st) else {
                return Err(format!("{rel}: a null run_id or status"));
            };
            let status = match st {
                "done" => RunStatus::Done,
                "failed" => RunStatus::Failed,
                other => return Err(format!("{rel}: run {run_id} has status {other:?}")),
            };
            runs.push(CommittedRun { run_id, status });
        }
    }
    Ok(runs)
}

fn adopt_or_set_aside(
    c: &Campaign,
    found: &Check,
    is_live: &dyn Fn(&str) -> bool,
    q: &mut Quarantine,
    h: &mut Healed,
) -> Result<(), String> {
    if found.orphans.is_empty() {
        return Ok(());
    }
    let mut groups: BTreeMap<(String, u64), (PartCommit, Vec<String>)> = BTreeMap::new();
    let mut loose: Vec<(String, String)> = Vec::new();
    for rel in &found.orphans {
        match part_commit(c, rel) {
            Ok(pc) => groups
                .entry((pc.shard.clone(), pc.seq))
                .or_insert_with(|| (pc.clone(), Vec::new()))
                .1
                .push(rel.clone()),
            Err(why) => loose.push((rel.clone(), why)),
        }
    }
    let existing: BTreeSet<(String, u64)> = found
        .commits
        .iter()
        .map(|cm| (cm.shard.clone(), cm.seq))
        .collect();
    let mut taken: BTreeSet<u64> = found
        .commits
        .iter()
        .flat_map(|cm| cm.runs.iter().map(|r| r.run_id))
        .collect();
    for ((shard, seq), (pc, files)) in groups {
        if is_live(&shard) {
            continue;
        }
        let verdict = (|| -> Result<Vec<CommittedRun>, String> {
            if existing.contains(&(shard.clone(), seq)) {
                return Err(format!("commit {shard}/{seq} exists and does not name it"));
            }
            let mut runs = Vec::new();
            for t in &pc.tables {
                let rel = files
                    .iter()
                    .find(|f| table_and_name(f).0 == t.as_str())
                    .ok_or_else(|| format!("its {t} part is missing"))?;
                let r = read_whole(c, rel)?;
                if t == tables::RUNS {
                    runs = r;
                }
            }
            if let Some(f) = files
                .iter()
                .find(|f| !pc.tables.iter().any(|t| table_and_name(f).0 == t.as_str()))
            {
                return Err(format!("{f} is of a table its commit does not list"));
            }
            if runs.is_empty() {
                return Err("no runs".into());
            }
            if let Some(r) = runs.iter().find(|r| taken.contains(&r.run_id)) {
                return Err(format!("run {} is committed already", r.run_id));
            }
            Ok(runs)
        })();
        match verdict {
            Ok(runs) => {
                let mut sums = Vec::new();
                for t in &pc.tables {
                    let rel = files
                        .iter()
                        .find(|f| table_and_name(f).0 == t.as_str())
                        .expect("checked");
                    let path = c.root.join(rel);
                    let (bytes, sha256) = checksum::sum_file(&path)
                        .map_err(|e| format!("{}: {e}", path.display()))?;
                    sums.push(FileSum {
                        path: rel.clone(),
                        bytes,
                        sha256,
                    });
                }
                let n = runs.len();
                taken.extend(runs.iter().map(|r| r.run_id));
                let commit = Commit {
                    format_version: LEDGER_FORMAT,
                    shard: shard.clone(),
                    seq,
                    runs,
                    files: sums,
                    in_index: false,
                };
                let p = ledger::commit_path(&c.root, &shard, seq);
                let dir = ledger::ledger_dir(&c.root, &shard);
                fsutil::create_dir_durable(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
                fsutil::write_atomic(&p, &serde_json::to_vec(&commit).expect("commit serialises"))
                    .map_err(|e| format!("{}: {e}", p.display()))?;
                h.actions.push(format!(
                    "rebuilt the commit record of {shard}/{seq} ({n} runs, {} parts) from its parts' footers",
                    files.len()
                ));
            }
            Err(why) => {
                for f in &files {
                    q.set_aside(f)?;
                }
                h.actions.push(format!(
                    "set aside the {} part(s) of commit {shard}/{seq}, which has no record and cannot get one back ({why}); its runs run again",
                    files.len()
                ));
            }
        }
    }
    for (rel, why) in loose {
        if q.set_aside(&rel)? {
            h.actions
                .push(format!("set aside {rel}, a part in no commit ({why})"));
        }
    }
    Ok(())
}
