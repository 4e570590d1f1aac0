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
//!
//! The campaign directory is a closed world: nothing is followed out of it. Everything is
//! read, moved and removed through `fsutil::Dir` (directories opened without following a
//! link, files with `O_NOFOLLOW`); the only links followed are the generation links
//! granular writes itself (`tables/<t>` -> `.gen/<t>.<n>`, see `store::layout`). A link, or
//! an entry of the wrong kind, where granular keeps its own file or directory
//! ([`OWN_DIRS`], [`OWN_FILES`], and below them) is damage (`Check::not_own`), named by
//! every check and healed first: the link itself (never its target) is moved into the
//! quarantine, then everything is looked at again without it (the files it hid are then
//! missing, and healed as such). A `quarantine` that is not a directory is renamed to a
//! fresh name in the campaign directory (`quarantine.moved-<time>-<pid>`): nothing is ever
//! written through it.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use super::error::CampaignError;
use super::ledger::{self, Commit, CommittedRun, PartCommit, RunStatus};
use super::{tables, Campaign};
use crate::fsutil::{self, Dir, Kind};
use crate::store::checksum::{self, FileSum, Mismatch};
use crate::store::layout;
use crate::store::parquet_io;
use crate::store::LEDGER_FORMAT;

/// How deep the check goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Depth {
    /// Presence and sizes (cheap: one `stat` per file).
    #[default]
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
    /// Entries that are not granular's own where granular keeps its own file or directory
    /// (a symbolic link, never followed, or an entry of the wrong kind): (relative path,
    /// what is there). What is behind them is not judged until they are set aside.
    pub not_own: Vec<(String, String)>,
    /// How deep this check went.
    pub depth: Depth,
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
            && self.not_own.is_empty()
    }

    /// One line per problem.
    pub fn problems(&self) -> Vec<String> {
        let mut v = Vec::new();
        for (p, what) in &self.not_own {
            v.push(format!("{p}: {what}"));
        }
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
                Mismatch::NotOwn(what) => format!(
                    "{}: {what} (committed by {} with {} runs)",
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
pub fn check(c: &Campaign, depth: Depth) -> Result<Check, CampaignError> {
    let mut found = check_once(&c.root, depth)?;
    // A live writer may have committed, or rewritten a table (its sidecar first, then the
    // file), while we looked: look again, a little later each time (a busy machine can take
    // a second between the two), before calling it damage.
    let mut wait = std::time::Duration::from_millis(200);
    for _ in 0..4 {
        if found.clean() || found.live.is_empty() {
            break;
        }
        std::thread::sleep(wait);
        wait *= 2;
        found = check_once(&c.root, depth)?;
    }
    Ok(found)
}

fn check_once(root: &Path, depth: Depth) -> Result<Check, CampaignError> {
    let mut out = Check {
        depth,
        ..Default::default()
    };
    if let Some(why) = live_writers(root, &mut out) {
        out.skipped = Some(why);
        return Ok(out);
    }
    // The campaign directory as the user named it (a link there is followed, once).
    let rd = Dir::open(root).map_err(|e| CampaignError::Io(format!("{}: {e}", root.display())))?;
    out.not_own = not_own(&rd);
    let l = ledger::read_ledger(root)?;
    out.bad_ledger = l.bad_records.clone();
    if let Some(why) = &l.bad_index {
        out.bad_ledger.push((ledger::index_path(root), why.clone()));
    }
    out.commits = l.commits;
    let committed = check_committed(root, &rd, &mut out)?;
    check_sidecars_have_files(root, &rd, &mut out);
    check_uncommitted(root, &rd, &committed, &mut out)?;
    Ok(out)
}

/// The shards whose writers are live (other than this process) into `out.live`; why the
/// check is skipped (a compaction running), if it is.
fn live_writers(root: &Path, out: &mut Check) -> Option<String> {
    let live_locks = ledger::live_locks(root);
    let ours = |l: &ledger::LockInfo| l.pid == std::process::id() && l.host == ledger::hostname();
    if let Some(l) = live_locks
        .iter()
        .find(|l| l.shard_tag == ledger::COMPACT_TAG && !ours(l))
    {
        return Some(format!(
            "a compaction is running (process {} on {})",
            l.pid, l.host
        ));
    }
    out.live = live_locks
        .into_iter()
        .filter(|l| !ours(l))
        .map(|l| l.shard_tag)
        .collect();
    None
}

/// An I/O error reading `rel` of the campaign at `root`.
fn read_err(root: &Path, rel: &str, e: std::io::Error) -> CampaignError {
    CampaignError::Io(format!("{}: {e}", root.join(rel).display()))
}

/// Every committed file against its commit (`out.bad_files`), runs in two commits
/// (`out.doubled`); the committed files' paths.
fn check_committed(
    root: &Path,
    rd: &Dir,
    out: &mut Check,
) -> Result<BTreeSet<String>, CampaignError> {
    let full = out.depth == Depth::Full;
    let at = |rel: &str, e| read_err(root, rel, e);
    let mut committed: BTreeSet<String> = BTreeSet::new();
    let mut runs: BTreeMap<u64, Vec<usize>> = BTreeMap::new();
    for (i, c) in out.commits.iter().enumerate() {
        for r in &c.runs {
            runs.entry(r.run_id).or_default().push(i);
        }
        let live = out.live.contains(&c.shard);
        for f in &c.files {
            committed.insert(f.path.clone());
            let (parent, name) = layout::split(&f.path);
            let dir = match layout::walk(rd, parent) {
                Ok(d) => d,
                // Behind an entry that is not granular's own (named in `not_own`): not judged.
                Err(e) if fsutil::not_own(&e).is_some() => continue,
                Err(e) => return Err(at(parent, e)),
            };
            if live
                && dir.as_ref().is_some_and(|d| {
                    d.kind(&format!(".{name}.pending")).ok().flatten() == Some(Kind::File)
                })
            {
                continue; // in flight
            }
            let found = match dir.map(|d| d.open_file(name)).transpose() {
                Ok(None) | Ok(Some(None)) => Some(Mismatch::Missing),
                Ok(Some(Some(file))) => {
                    checksum::check_open(file, f, full).map_err(|e| at(&f.path, e))?
                }
                Err(e) => match fsutil::not_own(&e) {
                    Some(n) => Some(Mismatch::NotOwn(n.what())),
                    None => return Err(at(&f.path, e)),
                },
            };
            if let Some(found) = found {
                out.bad_files.push(BadFile {
                    commit: i,
                    file: f.clone(),
                    found,
                });
            }
        }
    }
    out.doubled = runs.into_iter().filter(|(_, v)| v.len() > 1).collect();
    Ok(committed)
}

/// A sidecar without its file: a rebuilt table's file is gone (`out.bad_derived`).
fn check_sidecars_have_files(root: &Path, rd: &Dir, out: &mut Check) {
    for (table, name) in checksum::sidecars(root) {
        let there = match layout::open_table(rd, &table) {
            Ok(Some(d)) => d.kind(&name).ok().flatten().is_some(),
            Ok(None) => false,
            // Behind an entry that is not granular's own (named in `not_own`): not judged.
            Err(_) => continue,
        };
        if !there {
            out.bad_derived.push((
                format!("tables/{table}/{name}"),
                "missing (its checksum sidecar is there)".into(),
            ));
        }
    }
}

/// The visible entries of the table directories that no commit names: links and special
/// files (`out.not_own`), what is not a Parquet file (`out.foreign`), parts without a commit
/// (`out.orphans`), rebuilt tables' files against their sidecars (`out.bad_derived`).
fn check_uncommitted(
    root: &Path,
    rd: &Dir,
    committed: &BTreeSet<String>,
    out: &mut Check,
) -> Result<(), CampaignError> {
    let full = out.depth == Depth::Full;
    let tables = layout::table_names(root)
        .map_err(|e| CampaignError::Io(format!("{}: {e}", root.display())))?;
    for table in tables {
        let Ok(Some(dir)) = layout::open_table(rd, &table) else {
            continue;
        };
        let Ok(entries) = dir.entries() else {
            continue;
        };
        for (name, kind) in entries {
            if name.starts_with('.') {
                continue;
            }
            let rel = format!("tables/{table}/{name}");
            if committed.contains(&rel) {
                continue;
            }
            if matches!(kind, Kind::Link | Kind::Other) {
                out.not_own.push((
                    rel,
                    format!(
                        "{}, where granular keeps its own files (not followed)",
                        dir.describe(&name, kind)
                    ),
                ));
                continue;
            }
            if kind == Kind::Dir || !name.ends_with(".parquet") {
                out.foreign.push(rel);
                continue;
            }
            if is_part_name(&name) {
                out.orphans.push(rel);
                continue;
            }
            let why = match checksum::read_sidecar(root, &table, &name) {
                None => Some("a rebuilt table's file without a valid checksum sidecar".to_string()),
                Some(rec) => match dir.open_file(&name) {
                    // Replaced while we looked (a writer rewriting it): looked at next time.
                    Ok(None) => None,
                    Ok(Some(file)) => checksum::check_open(file, &rec, full)
                        .map_err(|e| read_err(root, &rel, e))?
                        .map(|m| {
                            format!(
                                "{m}, but its sidecar recorded {} bytes, SHA-256 {}",
                                rec.bytes, rec.sha256
                            )
                        }),
                    Err(e) => Some(e.to_string()),
                },
            };
            if let Some(why) = why {
                out.bad_derived.push((rel, why));
            }
        }
    }
    Ok(())
}

/// The directories granular keeps in a campaign directory.
pub const OWN_DIRS: [&str; 11] = [
    "manifests",
    "ledger",
    "locks",
    "checkpoints",
    "finals",
    "sums",
    "quarantine",
    "tables",
    super::ANALYSIS_DIR,
    "figures",
    "slurm",
];

/// The files granular keeps in a campaign directory.
pub const OWN_FILES: [&str; 4] = [
    "campaign.json",
    "manifest.json",
    "report.html",
    "upgrade.log",
];

/// Granular's directories that hold only its own files and directories, and how deep: a
/// link anywhere in them is not granular's (`tables/` is looked at on its own; `quarantine/`
/// holds what healing set aside, links included).
const NO_LINKS_BELOW: [(&str, usize); 9] = [
    ("manifests", 1),
    ("ledger", 2),
    ("locks", 1),
    ("checkpoints", 1),
    ("finals", 1),
    ("sums", 2),
    (super::ANALYSIS_DIR, 2),
    ("figures", 1),
    ("slurm", 2),
];

/// Entries that are not granular's own where granular keeps its own (see the module's text),
/// parents before what is below them: (relative path, what is there). Nothing is followed.
fn not_own(rd: &Dir) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let what = |found: String, expected: &str| {
        format!("{found}, where granular keeps its own {expected} (not followed)")
    };
    for (names, want, expected) in [
        (&OWN_DIRS[..], Kind::Dir, "directory"),
        (&OWN_FILES[..], Kind::File, "file"),
    ] {
        for name in names {
            if let Ok(Some(k)) = rd.kind(name) {
                if k != want {
                    out.push((name.to_string(), what(rd.describe(name, k), expected)));
                }
            }
        }
    }
    fn links_below(d: &Dir, rel: &str, depth: usize, out: &mut Vec<(String, String)>) {
        for (n, k) in d.entries().unwrap_or_default() {
            let r = format!("{rel}/{n}");
            match k {
                Kind::Link => out.push((
                    r,
                    format!(
                        "{}, where granular keeps its own files (not followed)",
                        d.describe(&n, k)
                    ),
                )),
                Kind::Dir if depth > 1 => {
                    if let Ok(Some(s)) = d.sub(&n) {
                        links_below(&s, &r, depth - 1, out);
                    }
                }
                _ => {}
            }
        }
    }
    for (name, depth) in NO_LINKS_BELOW {
        if let Ok(Some(d)) = rd.sub(name) {
            links_below(&d, name, depth, &mut out);
        }
    }
    let Ok(Some(tables)) = rd.sub("tables") else {
        return out;
    };
    for (name, kind) in tables.entries().unwrap_or_default() {
        let rel = format!("tables/{name}");
        if name == layout::GEN_DIR {
            match kind {
                Kind::Dir => {
                    if let Ok(Some(gens)) = tables.sub(&name) {
                        links_below(&gens, &rel, 1, &mut out);
                    }
                }
                k => out.push((rel, what(tables.describe(&name, k), "directory"))),
            }
            continue;
        }
        if name.starts_with('.') {
            continue; // a temporary (`ledger::recover` removes those of dead processes)
        }
        match layout::open_table_at(&tables, &name) {
            Ok(Some(_)) => {}
            Ok(None) => out.push((
                rel,
                what(
                    format!(
                        "{}, a generation that is not there",
                        tables.describe(&name, kind)
                    ),
                    "table directory",
                ),
            )),
            Err(e) => match fsutil::not_own(&e) {
                Some(n) if n.path == tables.path().join(&name) => out.push((rel, n.what())),
                // `.gen` not granular's own: named above.
                Some(_) => {}
                None => out.push((rel, format!("cannot be read: {e}"))),
            },
        }
    }
    out
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

/// Where healing sets things aside: `quarantine/<time>-<pid>/`, created when first needed,
/// in directories opened without following links; an entry is moved itself (a link too,
/// never what it points to), to the same relative path inside it.
struct Quarantine<'a> {
    root: &'a Dir,
    stamp: String,
    dir: Option<Dir>,
    used: bool,
}

impl<'a> Quarantine<'a> {
    fn new(root: &'a Dir) -> Self {
        let secs = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_secs())
            .unwrap_or(0);
        Quarantine {
            root,
            stamp: format!("{secs}-{}", std::process::id()),
            dir: None,
            used: false,
        }
    }

    fn path(&self) -> PathBuf {
        self.root.path().join("quarantine").join(&self.stamp)
    }

    /// The quarantine directory (made now if need be: a `quarantine` that is a link or a
    /// file is refused, never written through).
    fn dir(&mut self) -> Result<&Dir, CampaignError> {
        if self.dir.is_none() {
            let path = self.path();
            let d = self
                .root
                .create_dir("quarantine")
                .and_then(|q| q.create_dir(&self.stamp))
                .map_err(|e| CampaignError::at(&path, e))?;
            self.dir = Some(d);
        }
        Ok(self.dir.as_ref().expect("made above"))
    }

    /// Move `rel` (relative to the campaign directory) into the quarantine; a file already
    /// gone is fine. The directories on the way are opened without following a link (but a
    /// table's generation link): one that is not granular's own is an error.
    fn set_aside(&mut self, rel: &str) -> Result<bool, CampaignError> {
        let full = self.root.path().join(rel);
        let at = |e: std::io::Error| CampaignError::at(&full, e);
        let (parent, name) = layout::split(rel);
        let Some(from) = layout::walk(self.root, parent).map_err(at)? else {
            return Ok(false);
        };
        if from.kind(name).map_err(at)?.is_none() {
            return Ok(false);
        }
        let to = self.dir()?.create_dirs(parent).map_err(at)?;
        if !from.rename(name, &to, name).map_err(at)? {
            return Ok(false);
        }
        let _ = from.sync();
        let _ = to.sync();
        self.used = true;
        Ok(true)
    }

    /// Write `actions.log` into the quarantine.
    fn log(&mut self, actions: &[String]) -> Result<PathBuf, CampaignError> {
        let mut text = actions.join("\n");
        text.push('\n');
        let path = self.path().join("actions.log");
        self.dir()?
            .write_atomic("actions.log", text.as_bytes())
            .map_err(|e| CampaignError::at(&path, e))?;
        Ok(self.path())
    }
}

/// Set aside what `found.not_own` names, parents first (what is below an entry set aside
/// goes with it): the entry itself, never what a link points to. A `quarantine` that is not a
/// directory is renamed to a fresh name beside it. `manifest.json` (a copy for people) is
/// written again from the history.
fn set_aside_not_own(
    c: &Campaign,
    rd: &Dir,
    found: &Check,
    q: &mut Quarantine,
    h: &mut Healed,
) -> Result<(), CampaignError> {
    let mut gone: Vec<String> = Vec::new();
    if let Some((_, what)) = found.not_own.iter().find(|(r, _)| r == "quarantine") {
        let to = format!("quarantine.moved-{}", q.stamp);
        let moved = rd
            .rename("quarantine", rd, &to)
            .map_err(|e| CampaignError::at(&rd.path().join("quarantine"), e))?;
        if moved {
            let _ = rd.sync();
            h.actions.push(format!(
                "renamed quarantine ({what}) to {to}: nothing was written into it; what healing sets aside goes to a quarantine directory of its own"
            ));
            q.used = true;
        }
        gone.push("quarantine".into());
    }
    for (rel, what) in &found.not_own {
        if gone
            .iter()
            .any(|g| rel == g || rel.starts_with(&format!("{g}/")))
        {
            continue;
        }
        if q.set_aside(rel)? {
            h.actions.push(format!(
                "set aside {rel} ({what}); moved itself, nothing it points to was read or changed"
            ));
        }
        gone.push(rel.clone());
    }
    if found.not_own.iter().any(|(r, _)| r == "manifest.json") {
        if let Some(latest) = c.history.last() {
            let (dir, name) = layout::split(&latest.file);
            if let Ok(Some(Some(text))) =
                layout::walk(rd, dir).and_then(|d| d.map(|d| d.read(name)).transpose())
            {
                rd.write_atomic("manifest.json", &text)
                    .map_err(|e| CampaignError::at(&rd.path().join("manifest.json"), e))?;
                h.actions
                    .push(format!("wrote manifest.json again from {}", latest.file));
            }
        }
    }
    Ok(())
}

/// Heal what `check` found (see the module's text), for a process holding a shard lock (or
/// the compaction lock): commits of live shards other than `ours` are left alone. Every
/// action is returned and logged in the quarantine's `actions.log`.
pub fn heal(c: &Campaign, found: &Check, ours: &str) -> Result<Healed, CampaignError> {
    let root = &c.root;
    let rd = Dir::open(root).map_err(|e| CampaignError::Io(format!("{}: {e}", root.display())))?;
    let mut h = Healed::default();
    let mut q = Quarantine::new(&rd);
    let live: Vec<&String> = found.live.iter().filter(|t| *t != ours).collect();
    let is_live = |shard: &str| live.iter().any(|t| *t == shard);

    let fresh = heal_not_own(c, &rd, found, &mut q, &mut h)?;
    let found = fresh.as_ref().unwrap_or(found);
    set_aside_bad_ledger(root, found, &mut q, &mut h)?;
    undo_commits(root, found, &is_live, &mut q, &mut h)?;
    // Parts without a commit (including those of records set aside above).
    let after = check_once(root, Depth::Quick)?;
    adopt_or_set_aside(c, &rd, &after, &is_live, &mut q, &mut h)?;
    set_aside_derived(c, found, &after, &mut q, &mut h)?;
    set_aside_foreign(found, &after, &mut q, &mut h)?;
    if q.used {
        h.quarantine = Some(q.log(&h.actions)?);
    }
    Ok(h)
}

/// What is not granular's own first; then everything again, without it (what it hid may be
/// not granular's own in turn: a table's link to a generation under a `.gen` that was a
/// link, say). The check after the last round, if there was one.
fn heal_not_own(
    c: &Campaign,
    rd: &Dir,
    found: &Check,
    q: &mut Quarantine,
    h: &mut Healed,
) -> Result<Option<Check>, CampaignError> {
    let mut fresh: Option<Check> = None;
    for _ in 0..3 {
        let cur = fresh.as_ref().unwrap_or(found);
        if cur.not_own.is_empty() {
            break;
        }
        set_aside_not_own(c, rd, cur, q, h)?;
        fresh = Some(check_once(&c.root, found.depth)?);
    }
    Ok(fresh)
}

/// Unreadable ledger files: set aside; the parts they named become parts without a commit.
fn set_aside_bad_ledger(
    root: &Path,
    found: &Check,
    q: &mut Quarantine,
    h: &mut Healed,
) -> Result<(), CampaignError> {
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
    Ok(())
}

/// Undo the commits with a bad file and the later holders of a doubled run (their files set
/// aside first, then their records or index groups); their runs, unless committed elsewhere,
/// into `h.undone_runs`.
fn undo_commits(
    root: &Path,
    found: &Check,
    is_live: &dyn Fn(&str) -> bool,
    q: &mut Quarantine,
    h: &mut Healed,
) -> Result<(), CampaignError> {
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
        h.actions.push(undid(found, i));
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
    Ok(())
}

/// The action line of undoing commit `i` of `found`.
fn undid(found: &Check, i: usize) -> String {
    let cm = &found.commits[i];
    let why: Vec<String> = found
        .bad_files
        .iter()
        .filter(|b| b.commit == i)
        .map(|b| format!("{} {}", b.file.path, b.found))
        .collect();
    format!(
        "undid commit {} ({} runs run again; {})",
        cm.name(),
        cm.runs.len(),
        if why.is_empty() {
            "its runs were committed before".to_string()
        } else {
            why.join(", ")
        }
    )
}

/// Rebuilt tables: damaged ones, and the summaries once runs were undone, set aside (their
/// sidecars removed) to be written again.
fn set_aside_derived(
    c: &Campaign,
    found: &Check,
    after: &Check,
    q: &mut Quarantine,
    h: &mut Healed,
) -> Result<(), CampaignError> {
    let root = &c.root;
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
        let io = |e: &dyn std::fmt::Display| CampaignError::Io(e.to_string());
        for table in layout::table_names(root).map_err(|e| io(&e))? {
            if keep.contains(&table.as_str()) {
                continue;
            }
            for f in c.data().files(&table).map_err(|e| io(&e))? {
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
        let remove_sidecar = || checksum::remove_sidecar(root, t, n).unwrap_or(false);
        if q.set_aside(rel)? {
            remove_sidecar();
            h.actions
                .push(format!("set aside {rel} ({why}); it is written again"));
        } else if remove_sidecar() {
            h.actions.push(format!(
                "removed the checksum sidecar of the missing {rel}; it is written again"
            ));
        }
    }
    Ok(())
}

/// What does not belong in `tables/`, set aside.
fn set_aside_foreign(
    found: &Check,
    after: &Check,
    q: &mut Quarantine,
    h: &mut Healed,
) -> Result<(), CampaignError> {
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
    Ok(())
}

/// Why a part without a commit cannot get one back (it is set aside).
#[derive(Debug)]
struct NoCommit(String);

impl std::fmt::Display for NoCommit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// A part without a commit: its footer's commit, or why it has none.
fn part_commit(c: &Campaign, rd: &Dir, rel: &str) -> Result<PartCommit, NoCommit> {
    let path = c.root.join(rel);
    let no = |e: &dyn std::fmt::Display| NoCommit(e.to_string());
    let file = layout::open_file(rd, rel)
        .map_err(|e| no(&parquet_io::open_error(&path, e)))?
        .ok_or_else(|| NoCommit(format!("{rel}: gone")))?;
    let (info, _) = parquet_io::inspect_file(file, &path).map_err(|e| no(&e))?;
    let table = table_and_name(rel).0;
    parquet_io::check_part(&path, &info, table, Some(&c.identity)).map_err(|e| no(&e))?;
    let Some(json) = info.commit else {
        return Err(NoCommit(format!(
            "{rel}: its footer names no commit (written before commits were recorded in parts)"
        )));
    };
    serde_json::from_str(&json)
        .map_err(|e| NoCommit(format!("{rel}: unreadable granular.commit: {e}")))
}

/// Every row of a part, decoded (a damaged page is an error), and its runs if it is `runs`.
fn read_whole(c: &Campaign, rd: &Dir, rel: &str) -> Result<Vec<CommittedRun>, NoCommit> {
    let table = table_and_name(rel).0;
    let path = c.root.join(rel);
    let no = |e: &dyn std::fmt::Display| NoCommit(e.to_string());
    let file = layout::open_file(rd, rel)
        .map_err(|e| no(&parquet_io::open_error(&path, e)))?
        .ok_or_else(|| NoCommit(format!("{rel}: gone")))?;
    let batches =
        parquet_io::read_campaign_opened(file, &path, table, &c.identity).map_err(|e| no(&e))?;
    if table != tables::RUNS {
        return Ok(Vec::new());
    }
    let mut runs = Vec::new();
    for b in &batches {
        let cols = tables::RunsTableCols::read(b, rel).map_err(|e| no(&e))?;
        let (ids, status) = (cols.run_id, cols.status);
        for (id, st) in ids.iter().zip(status.iter()) {
            let (Some(run_id), Some(st)) = (id, st) else {
                return Err(NoCommit(format!("{rel}: a null run_id or status")));
            };
            let status = match st {
                "done" => RunStatus::Done,
                "failed" => RunStatus::Failed,
                other => {
                    return Err(NoCommit(format!(
                        "{rel}: run {run_id} has status {other:?}"
                    )))
                }
            };
            runs.push(CommittedRun { run_id, status });
        }
    }
    Ok(runs)
}

/// Parts without a commit: each complete group (see the module's text) gets its commit
/// record back, anything else is set aside and its runs run again.
fn adopt_or_set_aside(
    c: &Campaign,
    rd: &Dir,
    found: &Check,
    is_live: &dyn Fn(&str) -> bool,
    q: &mut Quarantine,
    h: &mut Healed,
) -> Result<(), CampaignError> {
    if found.orphans.is_empty() {
        return Ok(());
    }
    let (groups, loose) = group_orphans(c, rd, found);
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
        let group = Orphans {
            shard: &shard,
            seq,
            pc: &pc,
            files: &files,
        };
        match group.verdict(c, rd, &existing, &taken) {
            Ok(runs) => {
                taken.extend(runs.iter().map(|r| r.run_id));
                group.rebuild_record(c, rd, runs, h)?;
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

/// The parts without a commit by the commit their footers name ((shard, seq) -> the
/// footer's commit and the parts), and those whose footer names none (with why).
#[allow(clippy::type_complexity)]
fn group_orphans(
    c: &Campaign,
    rd: &Dir,
    found: &Check,
) -> (
    BTreeMap<(String, u64), (PartCommit, Vec<String>)>,
    Vec<(String, NoCommit)>,
) {
    let mut groups: BTreeMap<(String, u64), (PartCommit, Vec<String>)> = BTreeMap::new();
    let mut loose: Vec<(String, NoCommit)> = Vec::new();
    for rel in &found.orphans {
        match part_commit(c, rd, rel) {
            Ok(pc) => groups
                .entry((pc.shard.clone(), pc.seq))
                .or_insert_with(|| (pc.clone(), Vec::new()))
                .1
                .push(rel.clone()),
            Err(why) => loose.push((rel.clone(), why)),
        }
    }
    (groups, loose)
}

/// The parts without a commit whose footers name one commit.
struct Orphans<'a> {
    shard: &'a str,
    seq: u64,
    pc: &'a PartCommit,
    files: &'a [String],
}

impl Orphans<'_> {
    /// This group's part of `table`.
    fn part(&self, table: &str) -> Option<&String> {
        self.files.iter().find(|f| table_and_name(f).0 == table)
    }

    /// The runs of a complete group (every table its footer lists, all readable, runs
    /// committed nowhere else), or why it is not one.
    fn verdict(
        &self,
        c: &Campaign,
        rd: &Dir,
        existing: &BTreeSet<(String, u64)>,
        taken: &BTreeSet<u64>,
    ) -> Result<Vec<CommittedRun>, NoCommit> {
        let (shard, seq) = (self.shard, self.seq);
        let no = NoCommit;
        if shard.is_empty() || shard.starts_with('.') || shard.contains(['/', '\0']) {
            return Err(no(format!("its footer names the shard {shard:?}")));
        }
        if existing.contains(&(shard.to_string(), seq)) {
            return Err(no(format!(
                "commit {shard}/{seq} exists and does not name it"
            )));
        }
        let mut runs = Vec::new();
        for t in &self.pc.tables {
            let rel = self
                .part(t)
                .ok_or_else(|| no(format!("its {t} part is missing")))?;
            let r = read_whole(c, rd, rel)?;
            if t == tables::RUNS {
                runs = r;
            }
        }
        if let Some(f) = self.files.iter().find(|f| {
            !self
                .pc
                .tables
                .iter()
                .any(|t| table_and_name(f).0 == t.as_str())
        }) {
            return Err(no(format!("{f} is of a table its commit does not list")));
        }
        if runs.is_empty() {
            return Err(no("no runs".into()));
        }
        if let Some(r) = runs.iter().find(|r| taken.contains(&r.run_id)) {
            return Err(no(format!("run {} is committed already", r.run_id)));
        }
        Ok(runs)
    }

    /// Write the commit record of a complete group again, from its parts (sizes and SHA-256
    /// read now) and its runs.
    fn rebuild_record(
        &self,
        c: &Campaign,
        rd: &Dir,
        runs: Vec<CommittedRun>,
        h: &mut Healed,
    ) -> Result<(), CampaignError> {
        let (shard, seq) = (self.shard, self.seq);
        let mut sums = Vec::new();
        for t in &self.pc.tables {
            let rel = self.part(t).expect("checked");
            let path = c.root.join(rel);
            let file = layout::open_file(rd, rel)
                .map_err(|e| CampaignError::Io(parquet_io::open_error(&path, e).to_string()))?
                .ok_or_else(|| CampaignError::Io(format!("{rel}: gone")))?;
            let (bytes, sha256) = checksum::sum_reader(file)
                .map_err(|e| CampaignError::Io(format!("{}: {e}", path.display())))?;
            sums.push(FileSum {
                path: rel.clone(),
                bytes,
                sha256,
            });
        }
        let n = runs.len();
        let commit = Commit {
            format_version: LEDGER_FORMAT,
            shard: shard.to_string(),
            seq,
            runs,
            files: sums,
            in_index: false,
        };
        let p = ledger::commit_path(&c.root, shard, seq);
        let name = p
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        rd.create_dir("ledger")
            .and_then(|l| l.create_dir(shard))
            .and_then(|d| {
                d.write_atomic(
                    &name,
                    &serde_json::to_vec(&commit).expect("commit serialises"),
                )
            })
            .map_err(|e| CampaignError::at(&p, e))?;
        h.actions.push(format!(
            "rebuilt the commit record of {shard}/{seq} ({n} runs, {} parts) from its parts' footers",
            self.files.len()
        ));
        Ok(())
    }
}
