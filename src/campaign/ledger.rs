//! The ledger: which runs are finished, recorded by commit files that become visible by an
//! atomic rename (no database, nothing NFS breaks), plus the per-shard locks.
//!
//! Commit protocol for a batch of finished runs (one writer per shard):
//! 1. each table part is written to a hidden `.NAME.pending` file and fsynced;
//! 2. the commit record `ledger/<shard>/commit-<seq>.json` (runs + files) is written
//!    atomically: this is the commit point;
//! 3. the pending files are renamed to their final names;
//! 4. the committed runs' checkpoints are deleted.
//!
//! Recovery rolls a crash after (2) forward (renames the pending files) and one before (2)
//! back (deletes unreferenced pending files), so no row is ever lost or doubled.
//!
//! Every committed file is recorded with its size and SHA-256 (`store::checksum`), and every
//! part carries its commit in its footer (`granular.commit`), so that `campaign::integrity`
//! can check the tables against the ledger, and rebuild a lost record from the parts.
//!
//! `granular compact` folds the commit records into `ledger/index.json`: the same commits
//! ("groups": runs and files), with the merged files of several in one group. It first writes
//! its plan to `ledger/compaction.json` (the journal), then publishes the new table generations
//! and writes the index; a compaction stopped in between is rolled forward by `recover`.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::campaign::error::CampaignError;
use crate::campaign::plan::Shard;
use crate::exit_codes::{Classed, ExitClass};
use crate::fsutil::{self, Dir, Kind};
use crate::store::checksum::FileSum;
use crate::store::layout;
use crate::store::LEDGER_FORMAT;

#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum RunStatus {
    Done,
    Failed,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct CommittedRun {
    pub run_id: u64,
    pub status: RunStatus,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct Commit {
    pub format_version: u32,
    pub shard: String,
    pub seq: u64,
    pub runs: Vec<CommittedRun>,
    /// Table files of this commit (paths relative to the campaign directory), with their
    /// sizes and SHA-256.
    pub files: Vec<FileSum>,
    /// Whether this commit is a group of the folded index (not a record file).
    #[serde(skip)]
    pub in_index: bool,
}

impl Commit {
    /// `shard/seq`, how messages name a commit.
    pub fn name(&self) -> String {
        if self.in_index {
            format!("{}/{} (ledger/index.json)", self.shard, self.seq)
        } else {
            format!("{}/{}", self.shard, self.seq)
        }
    }
}

/// What every part of a commit says of it in its footer (`granular.commit`).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct PartCommit {
    pub shard: String,
    pub seq: u64,
    /// The tables the commit wrote a part of, `runs` first.
    pub tables: Vec<String>,
}

pub fn ledger_dir(root: &Path, tag: &str) -> PathBuf {
    root.join("ledger").join(tag)
}

pub fn commit_path(root: &Path, tag: &str, seq: u64) -> PathBuf {
    ledger_dir(root, tag).join(format!("commit-{seq:08}.json"))
}

/// A commit's part of `table`, relative to the campaign directory.
pub fn part_rel(table: &str, tag: &str, seq: u64) -> String {
    format!("tables/{table}/part-{tag}-{seq:08}.parquet")
}

/// The hidden name a table part has until its commit is durable.
pub fn pending_path(final_path: &Path) -> PathBuf {
    let name = final_path.file_name().expect("file name").to_string_lossy();
    final_path.with_file_name(format!(".{name}.pending"))
}

/// One commit of the folded index, its runs as ranges.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq, Default)]
pub struct Group {
    pub shard: String,
    pub seq: u64,
    /// Runs finished as done, as inclusive ranges of run ids.
    pub done: Vec<(u64, u64)>,
    /// Runs finished as failed.
    pub failed: Vec<u64>,
    pub files: Vec<FileSum>,
}

impl Group {
    pub fn of(c: &Commit) -> Group {
        let mut ids: Vec<&CommittedRun> = c.runs.iter().collect();
        ids.sort_by_key(|r| r.run_id);
        let mut done: Vec<(u64, u64)> = Vec::new();
        let mut failed = Vec::new();
        for r in ids {
            match r.status {
                RunStatus::Done => match done.last_mut() {
                    Some((_, hi)) if *hi + 1 == r.run_id => *hi = r.run_id,
                    _ => done.push((r.run_id, r.run_id)),
                },
                RunStatus::Failed => failed.push(r.run_id),
            }
        }
        Group {
            shard: c.shard.clone(),
            seq: c.seq,
            done,
            failed,
            files: c.files.clone(),
        }
    }

    fn as_commit(&self) -> Commit {
        let mut runs: Vec<CommittedRun> = self
            .done
            .iter()
            .flat_map(|&(a, b)| a..=b)
            .map(|run_id| CommittedRun {
                run_id,
                status: RunStatus::Done,
            })
            .chain(self.failed.iter().map(|&run_id| CommittedRun {
                run_id,
                status: RunStatus::Failed,
            }))
            .collect();
        runs.sort_by_key(|r| r.run_id);
        Commit {
            format_version: LEDGER_FORMAT,
            shard: self.shard.clone(),
            seq: self.seq,
            runs,
            files: self.files.clone(),
            in_index: true,
        }
    }
}

/// The folded ledger written by `granular compact`: the commits it replaced, so that
/// `status` and `resume` read one file instead of one per flush.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq, Default)]
pub struct LedgerIndex {
    pub format_version: u32,
    /// Always "granular.ledger_index".
    pub kind: String,
    /// Per shard tag, the highest commit sequence number folded in (commit records of that
    /// shard up to it are ignored if still present: a compaction stopped before deleting them).
    pub folded: BTreeMap<String, u64>,
    /// Compactions so far: the merged files of the next one are `part-c<n+1>-<k>.parquet`.
    pub compactions: u64,
    pub groups: Vec<Group>,
}

pub const INDEX_KIND: &str = "granular.ledger_index";

pub fn index_path(root: &Path) -> PathBuf {
    root.join("ledger").join("index.json")
}

/// The journal of a compaction in progress (see the module's text).
pub fn journal_path(root: &Path) -> PathBuf {
    root.join("ledger").join("compaction.json")
}

/// A compaction's journal: the index it will write and the generations it will publish.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct Journal {
    pub format_version: u32,
    pub kind: String,
    /// (table, generation) to publish.
    pub publish: Vec<(String, u64)>,
    pub index: LedgerIndex,
}

pub const JOURNAL_KIND: &str = "granular.compaction_journal";

pub fn read_index(root: &Path) -> Result<Option<LedgerIndex>, CampaignError> {
    let p = index_path(root);
    // Only granular's own files are read: a link (`ledger` or the index) is not followed; it
    // is damage that `integrity` names and `resume` sets aside.
    let read = Dir::open(root).and_then(|d| match d.sub("ledger")? {
        Some(l) => l.read("index.json"),
        None => Ok(None),
    });
    let text = match read {
        Ok(Some(t)) => t,
        Ok(None) => return Ok(None),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) if fsutil::not_own(&e).is_some() => return Ok(None),
        Err(e) => return Err(CampaignError::at(&p, e)),
    };
    let ix: LedgerIndex = serde_json::from_slice(&text).map_err(|e| {
        CampaignError::Refused(format!("{}: corrupt ledger index: {e}", p.display()))
    })?;
    if ix.kind != INDEX_KIND || ix.format_version != LEDGER_FORMAT {
        return Err(CampaignError::Refused(format!(
            "{}: not a ledger index of format {LEDGER_FORMAT} (kind {:?}, format {})",
            p.display(),
            ix.kind,
            ix.format_version
        )));
    }
    if let Some(f) = ix
        .groups
        .iter()
        .flat_map(|g| &g.files)
        .find(|f| !layout::is_table_file(&f.path))
    {
        return Err(CampaignError::Refused(format!(
            "{}: a ledger index naming {:?}, not a file of a table (tables/<table>/<name>)",
            p.display(),
            f.path
        )));
    }
    Ok(Some(ix))
}

/// Write the index atomically.
pub fn write_index(root: &Path, ix: &LedgerIndex) -> Result<(), CampaignError> {
    let p = index_path(root);
    fsutil::create_dir_durable(&root.join("ledger")).map_err(|e| CampaignError::at(&p, e))?;
    fsutil::write_atomic(&p, &serde_json::to_vec(ix).expect("index serialises"))
        .map_err(|e| CampaignError::at(&p, e))
}

/// The shard directories of `ledger/`, sorted (none if there is no ledger). Only directories
/// of granular's own: a link (to a directory elsewhere) is not a shard's, and is not followed.
pub fn shard_dirs(root: &Path) -> Vec<PathBuf> {
    let Some(ledger) = Dir::open(root)
        .ok()
        .and_then(|d| d.sub("ledger").ok().flatten())
    else {
        return Vec::new();
    };
    ledger
        .entries()
        .unwrap_or_default()
        .into_iter()
        .filter(|(_, k)| *k == Kind::Dir)
        .map(|(n, _)| root.join("ledger").join(n))
        .collect()
}

/// Commit record files (`commit-<seq>.json`, regular files) of a shard's directory with their
/// sequence numbers, sorted: from the directory's entries, not following a link at `dir`
/// (refused) or at a record (not listed); `ledger` itself must not be a link.
pub fn commit_files(dir: &Path) -> Result<Vec<(u64, PathBuf)>, CampaignError> {
    let err = |e: std::io::Error| CampaignError::at(dir, e);
    if let Some(parent) = dir.parent() {
        if let Ok(Some(k)) = fsutil::kind(parent) {
            if k != Kind::Dir {
                return Err(CampaignError::Refused(format!(
                    "{}: {}, where granular keeps its own directory (not followed)",
                    parent.display(),
                    fsutil::describe_kind(k)
                )));
            }
        }
    }
    let d = Dir::open_nofollow(dir).map_err(err)?;
    Ok(record_names(&d.entries().map_err(err)?)
        .into_iter()
        .map(|(seq, n)| (seq, dir.join(n)))
        .collect())
}

/// The commit records among a shard directory's entries (regular files named
/// `commit-<seq>.json`), sorted by sequence number.
fn record_names(entries: &[(String, Kind)]) -> Vec<(u64, String)> {
    let mut v: Vec<(u64, String)> = entries
        .iter()
        .filter(|(_, k)| *k == Kind::File)
        .filter_map(|(n, _)| {
            let seq = n
                .strip_prefix("commit-")?
                .strip_suffix(".json")?
                .parse::<u64>()
                .ok()?;
            Some((seq, n.clone()))
        })
        .collect();
    v.sort();
    v
}

/// The whole ledger as read: good commits, and what could not be read.
#[derive(Debug, Clone, Default)]
pub struct Ledger {
    /// The index's groups first, then every shard's commit records not folded into it,
    /// ordered by (shard, seq).
    pub commits: Vec<Commit>,
    pub index: Option<LedgerIndex>,
    /// Commit records that are not readable commits of this format: (path, why).
    pub bad_records: Vec<(PathBuf, String)>,
    /// The index, if it exists and is not readable: why.
    pub bad_index: Option<String>,
}

impl Ledger {
    /// Whether something of the ledger could not be read.
    pub fn damaged(&self) -> bool {
        !self.bad_records.is_empty() || self.bad_index.is_some()
    }

    /// The damage, one line each.
    pub fn damage(&self) -> Vec<String> {
        let mut v: Vec<String> = self
            .bad_records
            .iter()
            .map(|(p, why)| format!("{}: {why}", p.display()))
            .collect();
        v.extend(self.bad_index.iter().cloned());
        v
    }
}

/// Every commit (see `Ledger`). A record that vanishes while being read (a compaction
/// folding it into the index at that moment) makes the whole read start again.
pub fn read_ledger(root: &Path) -> Result<Ledger, CampaignError> {
    let mut last = String::new();
    for _ in 0..20 {
        match read_ledger_once(root) {
            Ok(Some(v)) => return Ok(v),
            Ok(None) => std::thread::sleep(std::time::Duration::from_millis(50)),
            Err(e) => return Err(e),
        }
        last = "commit records kept vanishing while being read (a compaction running?)".into();
    }
    Err(CampaignError::Io(format!("{}: {last}", root.display())))
}

/// Every commit, or an error naming the damaged ledger files and the command that heals them.
pub fn read_commits(root: &Path) -> Result<Vec<Commit>, CampaignError> {
    let l = read_ledger(root)?;
    if l.damaged() {
        return Err(CampaignError::Refused(format!(
            "{}; `granular resume {}` sets it aside and rebuilds the commit from its parts",
            l.damage().join("; "),
            root.display()
        )));
    }
    Ok(l.commits)
}

/// `Ok(None)`: a commit record listed was gone when opened. Only granular's own directories
/// and files are read (never through a link: a link is damage that `integrity` names).
fn read_ledger_once(root: &Path) -> Result<Option<Ledger>, CampaignError> {
    let mut out = Ledger::default();
    match read_index(root) {
        Ok(ix) => out.index = ix,
        Err(e) => out.bad_index = Some(e.to_string()),
    }
    if let Some(ix) = &out.index {
        out.commits.extend(ix.groups.iter().map(Group::as_commit));
    }
    let at = |p: &Path, e: std::io::Error| CampaignError::Io(format!("{}: {e}", p.display()));
    let ledger = match Dir::open(root).and_then(|d| d.sub("ledger")) {
        Ok(Some(l)) => l,
        Ok(None) => return Ok(Some(out)),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Some(out)),
        Err(e) if fsutil::not_own(&e).is_some() => return Ok(Some(out)),
        Err(e) => return Err(at(&root.join("ledger"), e)),
    };
    let entries = ledger.entries().map_err(|e| at(&root.join("ledger"), e))?;
    for (name, kind) in entries {
        if kind != Kind::Dir {
            continue;
        }
        let tag = root.join("ledger").join(&name);
        let shard = match ledger.sub(&name) {
            Ok(Some(d)) => d,
            Ok(None) => continue,
            Err(e) if fsutil::not_own(&e).is_some() => continue,
            Err(e) => return Err(at(&tag, e)),
        };
        let folded = out
            .index
            .as_ref()
            .and_then(|ix| ix.folded.get(&name).copied())
            .unwrap_or(0);
        for (seq, file) in record_names(&shard.entries().map_err(|e| at(&tag, e))?) {
            if seq <= folded {
                continue;
            }
            let f = tag.join(&file);
            let text = match shard.read(&file) {
                Ok(Some(t)) => t,
                Ok(None) => return Ok(None),
                // Swapped for a link since it was listed: not read.
                Err(e) if fsutil::not_own(&e).is_some() => continue,
                Err(e) => return Err(at(&f, e)),
            };
            match parse_commit(&text, &name, seq) {
                Ok(c) => match c.files.iter().find(|x| !layout::is_table_file(&x.path)) {
                    None => out.commits.push(c),
                    Some(x) => out.bad_records.push((
                        f,
                        format!(
                            "a commit record naming {:?}, not a file of a table (tables/<table>/<name>)",
                            x.path
                        ),
                    )),
                },
                Err(why) => out.bad_records.push((f, why.to_string())),
            }
        }
    }
    Ok(Some(out))
}

fn parse_commit(text: &[u8], tag: &str, seq: u64) -> Result<Commit, CampaignError> {
    let corrupt = CampaignError::Refused;
    let c: Commit =
        serde_json::from_slice(text).map_err(|e| corrupt(format!("corrupt commit record: {e}")))?;
    if c.format_version != LEDGER_FORMAT {
        return Err(corrupt(format!(
            "a commit record of format {}, this granular reads {LEDGER_FORMAT}",
            c.format_version
        )));
    }
    if c.shard != tag || c.seq != seq {
        return Err(corrupt(format!(
            "a commit record of {}/{} under the name of {tag}/{seq}",
            c.shard, c.seq
        )));
    }
    Ok(c)
}

/// run_id -> status of every committed run (the first commit wins).
pub fn finished_runs(commits: &[Commit]) -> BTreeMap<u64, RunStatus> {
    let mut m = BTreeMap::new();
    for c in commits {
        for r in &c.runs {
            m.entry(r.run_id).or_insert(r.status);
        }
    }
    m
}

pub fn next_seq(root: &Path, tag: &str) -> u64 {
    let files = commit_files(&ledger_dir(root, tag))
        .ok()
        .and_then(|f| f.last().map(|(s, _)| *s))
        .unwrap_or(0);
    let folded = read_index(root)
        .ok()
        .flatten()
        .and_then(|ix| ix.folded.get(tag).copied())
        .unwrap_or(0);
    files.max(folded) + 1
}

/// Finish a compaction stopped after its journal was written: publish its generations, write
/// its index, delete the records it folded, remove the journal. Only while no compaction runs.
pub fn roll_forward_compaction(root: &Path) -> Result<Option<String>, CampaignError> {
    let jp = journal_path(root);
    let text = match fs::read(&jp) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(CampaignError::at(&jp, e)),
    };
    let j: Journal = match serde_json::from_slice(&text) {
        Ok(j) => j,
        Err(e) => {
            // The journal is written atomically: unreadable means damaged, not half-written.
            return Err(CampaignError::Refused(format!(
                "{}: corrupt compaction journal ({e}); move it away and run `granular compact` again",
                jp.display()
            )));
        }
    };
    if j.kind != JOURNAL_KIND || j.format_version != LEDGER_FORMAT {
        return Err(CampaignError::Refused(format!(
            "{}: not a compaction journal of format {LEDGER_FORMAT}",
            jp.display()
        )));
    }
    complete_compaction(root, &j)?;
    Ok(Some(format!(
        "completed an interrupted compaction ({} table generations published, the ledger index written)",
        j.publish.len()
    )))
}

/// Steps 2-4 of a compaction whose journal is durable (idempotent). Nothing is followed: the
/// generation links are written in `tables` opened without following a link, and records are
/// deleted only in shard directories of granular's own (`ledger` a link is refused).
pub fn complete_compaction(root: &Path, j: &Journal) -> Result<(), CampaignError> {
    let at = CampaignError::at;
    let rd = Dir::open(root).map_err(|e| at(root, e))?;
    rd.sub("ledger").map_err(|e| at(&root.join("ledger"), e))?;
    for (table, gen) in &j.publish {
        let current = match layout::table_dir(root, table) {
            Ok(layout::TableDir::Generation { gen: g, .. }) => Some(g),
            _ => None,
        };
        if current != Some(*gen) {
            layout::publish_generation(root, table, *gen).map_err(|e| {
                CampaignError::Io(format!(
                    "{}: {e}",
                    root.join("tables").join(table).display()
                ))
            })?;
        }
    }
    write_index(root, &j.index)?;
    let ledger = rd
        .sub("ledger")
        .map_err(|e| at(&root.join("ledger"), e))?
        .ok_or_else(|| CampaignError::Io(format!("{}: gone", root.join("ledger").display())))?;
    for (tag, &upto) in &j.index.folded {
        // A shard directory that is a link is not followed: nothing is deleted through it.
        let Ok(Some(d)) = ledger.sub(tag) else {
            continue;
        };
        for (seq, name) in record_names(&d.entries().unwrap_or_default()) {
            if seq <= upto {
                let _ = d.remove_file(&name);
            }
        }
        let _ = d.sync();
    }
    let jp = journal_path(root);
    ledger
        .remove_file("compaction.json")
        .map_err(|e| at(&jp, e))?;
    let _ = ledger.sync();
    Ok(())
}

/// Roll forward committed parts and roll back uncommitted ones, for every shard whose lock
/// is not held by a live process (our own shard's lock is held by us: pass it as `ours`).
///
/// Nothing is followed out of the campaign directory: directories are opened without
/// following links (`fsutil::Dir`), tables only through granular's own generation links.
/// Where the ledger is not granular's own (`ledger`, a shard's directory or the compaction
/// journal a link), the commits behind it are unknown: no compaction is rolled forward and no
/// pending part of those shards is discarded, until `granular resume` has set the link aside.
pub fn recover(root: &Path, ours: &str) -> Result<Vec<String>, CampaignError> {
    let mut notes = Vec::new();
    let live: Vec<String> = live_locks(root)
        .into_iter()
        .map(|l| l.shard_tag)
        .filter(|t| t != ours)
        .collect();
    let rd = Dir::open(root).map_err(|e| CampaignError::at(root, e))?;
    let unknown = unknown_shards(root, &rd)?;
    if unknown.is_some() && !live.iter().any(|t| t == COMPACT_TAG) {
        notes.extend(roll_forward_compaction(root)?);
    }
    let referenced = roll_forward_commits(root, &rd, &live, &mut notes)?;
    notes.extend(remove_stale_temporaries(root));
    let Some(unknown) = unknown else {
        return Ok(notes);
    };
    roll_back_pending(root, &rd, &live, &unknown, &referenced, &mut notes)?;
    Ok(notes)
}

/// The shards whose commits cannot be known, because their ledger directory is not
/// granular's own (`None`: none of them can, the ledger or the compaction journal is not).
fn unknown_shards(root: &Path, rd: &Dir) -> Result<Option<Vec<String>>, CampaignError> {
    let at = CampaignError::at;
    Ok(match rd.sub("ledger") {
        Ok(None) => Some(Vec::new()),
        Ok(Some(l)) => {
            let entries = l.entries().map_err(|e| at(&root.join("ledger"), e))?;
            if entries
                .iter()
                .any(|(n, k)| n == "compaction.json" && *k != Kind::File)
            {
                None
            } else {
                Some(
                    entries
                        .into_iter()
                        .filter(|(n, k)| {
                            *k != Kind::Dir && !n.ends_with(".json") && !n.starts_with('.')
                        })
                        .map(|(n, _)| n)
                        .collect(),
                )
            }
        }
        Err(e) if fsutil::not_own(&e).is_some() => None,
        Err(e) => return Err(at(&root.join("ledger"), e)),
    })
}

/// Roll forward: the pending parts that a commit of a shard not `live` references are renamed
/// to their final names. Returns every pending name (`<table dir>/.<part>.pending`) that a
/// commit references, live shards' included.
fn roll_forward_commits(
    root: &Path,
    rd: &Dir,
    live: &[String],
    notes: &mut Vec<String>,
) -> Result<std::collections::HashSet<String>, CampaignError> {
    let at = CampaignError::at;
    // Unreadable records are left to `integrity` (they are set aside there); their pending
    // parts, if any, are rolled back below like those of a commit that never happened.
    let commits = read_ledger(root)?.commits;
    let mut referenced = std::collections::HashSet::new();
    for c in &commits {
        for f in &c.files {
            let (dir, name) = layout::split(&f.path);
            let pending = format!(".{name}.pending");
            referenced.insert(format!("{dir}/{pending}"));
            if live.contains(&c.shard) {
                continue;
            }
            // A table behind a link that is not granular's own is not touched.
            let Ok(Some(d)) = layout::walk(rd, dir) else {
                continue;
            };
            let here = |n: &str| d.kind(n).map_err(|e| at(&root.join(dir).join(n), e));
            if here(name)?.is_none() && here(&pending)? == Some(Kind::File) {
                d.rename(&pending, &d, name)
                    .map_err(|e| at(&root.join(dir).join(&pending), e))?;
                let _ = d.sync();
                notes.push(format!(
                    "completed the commit of {}",
                    root.join(&f.path).display()
                ));
            }
        }
    }
    Ok(referenced)
}

/// Roll back: the pending parts in granular's own table directories that no commit references
/// are deleted, except those of `live` shards and of shards whose commits are `unknown`.
fn roll_back_pending(
    root: &Path,
    rd: &Dir,
    live: &[String],
    unknown: &[String],
    referenced: &std::collections::HashSet<String>,
    notes: &mut Vec<String>,
) -> Result<(), CampaignError> {
    let at = CampaignError::at;
    let Ok(Some(tables)) = rd.sub("tables") else {
        return Ok(());
    };
    for (t, _) in tables.entries().map_err(|e| at(&root.join("tables"), e))? {
        if t.starts_with('.') {
            continue;
        }
        // Only granular's own table directories (a link out is not followed).
        let Ok(Some(d)) = layout::open_table_at(&tables, &t) else {
            continue;
        };
        let mut removed = false;
        for (name, kind) in d.entries().map_err(|e| at(d.path(), e))? {
            if !name.ends_with(".pending")
                || kind == Kind::Dir
                || referenced.contains(&format!("tables/{t}/{name}"))
            {
                continue;
            }
            // `.part-<tag>-<seq>.parquet.pending`
            let tag = name
                .trim_start_matches(".part-")
                .split('-')
                .next()
                .unwrap_or("")
                .to_string();
            if live.contains(&tag) || unknown.contains(&tag) {
                continue;
            }
            // A file, or a link itself (never what it points to).
            d.remove_file(&name)
                .map_err(|e| at(&d.path().join(&name), e))?;
            removed = true;
            notes.push(format!(
                "discarded the uncommitted part {}",
                d.path().join(&name).display()
            ));
        }
        if removed {
            let _ = d.sync();
        }
    }
    Ok(())
}

/// Delete temporary files (`.NAME.<pid>-<nanos>@<host>.tmp`, see `fsutil::temp_path`) left by
/// processes of this host that died while writing (a kill during a checkpoint, say). Files of
/// other hosts are left alone: their processes cannot be checked from here.
///
/// Directories are opened without following links (`fsutil::Dir`; a table only through its
/// generation link): nothing is removed outside the campaign directory.
fn remove_stale_temporaries(root: &Path) -> Vec<String> {
    let mut notes = Vec::new();
    let Ok(rd) = Dir::open(root) else {
        return notes;
    };
    let mut dirs: Vec<Dir> = Vec::new();
    for name in ["checkpoints", "finals", "locks", "tables", "ledger"] {
        if let Ok(Some(d)) = rd.sub(name) {
            dirs.push(d);
        }
    }
    for sub in ["tables", "ledger", "sums"] {
        let Ok(Some(d)) = rd.sub(sub) else { continue };
        for (n, k) in d.entries().unwrap_or_default() {
            let opened = if sub == "tables" && !n.starts_with('.') {
                layout::open_table_at(&d, &n)
            } else if k == Kind::Dir {
                d.sub(&n)
            } else {
                continue;
            };
            if let Ok(Some(x)) = opened {
                dirs.push(x);
            }
        }
    }
    if let Ok(r) = rd.try_clone() {
        dirs.insert(0, r);
    }
    for dir in dirs {
        let Ok(entries) = dir.entries() else { continue };
        for (name, kind) in entries {
            if kind != Kind::File && kind != Kind::Link {
                continue;
            }
            let Some(stem) = name.strip_suffix(".tmp") else {
                continue;
            };
            if !name.starts_with('.') {
                continue;
            }
            let Some((stem, host)) = stem.rsplit_once('@') else {
                continue;
            };
            if host != fsutil::host_tag() {
                continue;
            }
            let pid = stem
                .rsplit_once('.')
                .and_then(|(_, tail)| tail.split('-').next())
                .and_then(|p| p.parse::<u32>().ok());
            if let Some(pid) = pid {
                if !pid_alive(pid) && dir.remove_file(&name).unwrap_or(false) {
                    notes.push(format!(
                        "removed the stale temporary file {}",
                        dir.path().join(&name).display()
                    ));
                }
            }
        }
    }
    notes
}

/// Who holds a lock of the campaign: a shard, or the exclusive lock (`compact.lock`).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct LockInfo {
    pub pid: u32,
    pub host: String,
    pub shard: String,
    pub shard_tag: String,
    pub shard_count: u32,
    /// The process's start time (clock ticks after boot, `/proc/<pid>/stat` field 22), so
    /// that a lock whose pid was reused by another process is seen to be stale.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub start_time: Option<u64>,
    /// What the holder of the exclusive lock does ([`Purpose`]); absent in shard locks and in
    /// the locks of granular before it was recorded (then: a compaction).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub purpose: Option<Purpose>,
}

impl LockInfo {
    /// A lock of this process.
    pub fn ours(shard: &str, shard_tag: &str, shard_count: u32) -> LockInfo {
        let pid = std::process::id();
        LockInfo {
            pid,
            host: hostname(),
            shard: shard.into(),
            shard_tag: shard_tag.into(),
            shard_count,
            start_time: process_start_time(pid),
            purpose: None,
        }
    }

    /// Whether this lock was taken by this process.
    pub fn is_ours(&self) -> bool {
        self.pid == std::process::id()
            && self.host == hostname()
            && self.start_time == process_start_time(self.pid)
    }

    /// Whether this is the exclusive lock (compaction, growth, upgrade, ...).
    pub fn is_exclusive(&self) -> bool {
        self.shard_tag == COMPACT_TAG
    }

    /// What the holder does, in words: `shard 2/4 (granular run/resume)`, `a growth ...`.
    pub fn doing(&self) -> String {
        if self.is_exclusive() {
            self.purpose.unwrap_or(Purpose::Compaction).doing().into()
        } else {
            format!(
                "shard {} (`granular run`, `resume` or a SLURM task)",
                self.shard
            )
        }
    }

    /// `process N on HOST`.
    pub fn by(&self) -> String {
        format!("process {} on {}", self.pid, self.host)
    }
}

/// Why the exclusive lock is held: every change to the campaign other than running its runs.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Purpose {
    /// `granular compact`.
    Compaction,
    /// A manifest being accepted: a new campaign recorded, or a campaign grown.
    Growth,
    /// `granular upgrade`.
    Upgrade,
    /// `granular theory` writing kinetic-theory tables.
    Theory,
    /// The next round of replicas of an error-target campaign being decided.
    Round,
}

impl Purpose {
    fn doing(self) -> &'static str {
        match self {
            Purpose::Compaction => "a compaction (`granular compact`)",
            Purpose::Growth => "a change of the campaign's manifest (`granular run` or `submit` with a new manifest)",
            Purpose::Upgrade => "an upgrade (`granular upgrade`)",
            Purpose::Theory => "the kinetic-theory tables (`granular theory`)",
            Purpose::Round => "the decision of the next round of replicas (error targets)",
        }
    }
}

/// Why a lock could not be taken: another live process holds the directory (exit 3), or the
/// lock file could not be written (no space, read-only file system, permissions: exit 4).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LockError {
    /// Held by a live process (what it does and its pid in the message): refused.
    #[error("{0}")]
    Held(String),
    /// The lock cannot be written or read (disk full, read-only, permissions): I/O.
    #[error("{0}")]
    Io(String),
}

impl Classed for LockError {
    fn class(&self) -> ExitClass {
        match self {
            LockError::Held(_) => ExitClass::Refused,
            LockError::Io(_) => ExitClass::Io,
        }
    }
}

impl LockError {
    /// The message with `what` before it (`cannot change the campaign: ...`).
    pub fn context(self, what: &str) -> LockError {
        match self {
            LockError::Held(m) => LockError::Held(format!("{what}: {m}")),
            LockError::Io(m) => LockError::Io(format!("{what}: {m}")),
        }
    }
}

/// When a process of this host started (clock ticks after boot), if it exists.
pub fn process_start_time(pid: u32) -> Option<u64> {
    let s = fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // Fields after the command name (which may hold spaces and parentheses): state is field
    // 3, starttime field 22.
    let rest = s.rsplit_once(')')?.1;
    rest.split_whitespace().nth(19)?.parse().ok()
}

pub fn hostname() -> String {
    fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| fs::read_to_string("/etc/hostname"))
        .map(|s| s.trim().to_string())
        .unwrap_or_else(|_| "unknown".into())
}

/// Whether a process is alive on this host (zombies count as dead).
pub fn pid_alive(pid: u32) -> bool {
    match fs::read_to_string(format!("/proc/{pid}/stat")) {
        Ok(s) => {
            let state = s
                .rsplit_once(')')
                .and_then(|(_, rest)| rest.trim_start().chars().next());
            !matches!(state, Some('Z') | Some('X'))
        }
        Err(_) => false,
    }
}

/// A lock of another host (a cluster node) whose heartbeat is older than this is stale: its
/// process is taken to be gone (node failure). Heartbeats are written every 2 s.
pub const REMOTE_STALE_AFTER: std::time::Duration = std::time::Duration::from_secs(600);

/// The lock's tag of the exclusive lock (`locks/compact.lock`: compaction, growth, upgrade,
/// theory; the name is kept from when only compaction took it).
pub const COMPACT_TAG: &str = "compact";

fn lock_is_live(locks: &Dir, l: &LockInfo) -> bool {
    if l.host == hostname() {
        // A pid now used by another process (started at another time) holds nothing.
        return pid_alive(l.pid)
            && l.start_time
                .is_none_or(|t| process_start_time(l.pid) == Some(t));
    }
    // Another host's process cannot be checked from here: it is live while its heartbeat (or,
    // before the first heartbeat, its lock file) is recent.
    let newest = [
        format!("{}.running.json", l.shard_tag),
        format!("{}.lock", l.shard_tag),
    ]
    .iter()
    .filter_map(|n| locks.open_file(n).ok()??.metadata().ok()?.modified().ok())
    .max();
    match newest {
        Some(t) => t.elapsed().map_or(true, |age| age < REMOTE_STALE_AFTER),
        None => false,
    }
}

/// The holder recorded in the lock file `name` of `locks/` (None: missing, unreadable, a link,
/// or not a lock).
fn read_lock(locks: &Dir, name: &str) -> Option<LockInfo> {
    let bytes = locks.read(name).ok()??;
    serde_json::from_slice::<LockInfo>(&bytes).ok()
}

/// `DIR/locks`, opened without following a link; None if there is none (or it is not
/// granular's own: a link or a file there is set aside by the next lock taken).
fn locks_dir(root: &Path) -> Option<Dir> {
    Dir::open(root).ok()?.sub("locks").ok()?
}

/// Locks of live processes.
pub fn live_locks(root: &Path) -> Vec<LockInfo> {
    let Some(locks) = locks_dir(root) else {
        return Vec::new();
    };
    let Ok(entries) = locks.entries() else {
        return Vec::new();
    };
    entries
        .into_iter()
        .filter(|(n, k)| n.ends_with(".lock") && *k == Kind::File)
        .filter_map(|(n, _)| read_lock(&locks, &n))
        .filter(|l| lock_is_live(&locks, l))
        .collect()
}

/// `DIR/locks` opened (created if missing) without following a link. A link or a file in its
/// place is not granular's own: it is renamed aside (`locks.moved-<time>-<pid>`, the link
/// itself, never its target) and a directory made, so that no lock is ever written outside.
fn own_locks_dir(root: &Path) -> Result<Dir, LockError> {
    let io = |e: std::io::Error, p: &Path| LockError::Io(format!("{}: {e}", p.display()));
    let top = Dir::open(root).map_err(|e| io(e, root))?;
    match top.kind("locks").map_err(|e| io(e, root))? {
        None | Some(Kind::Dir) => {}
        Some(k) => {
            let aside = format!(
                "locks.moved-{}-{}",
                std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map(|d| d.as_secs())
                    .unwrap_or(0),
                std::process::id()
            );
            tracing::warn!(
                "{} is {}, not granular's own directory of locks: renamed to {aside}",
                root.join("locks").display(),
                top.describe("locks", k)
            );
            top.rename("locks", &top, &aside)
                .map_err(|e| io(e, &root.join("locks")))?;
        }
    }
    top.create_dir("locks")
        .map_err(|e| io(e, &root.join("locks")))
}

/// A mutual exclusion among the processes of this campaign held for a short while, by
/// `flock(2)` on a file of `locks/` that is never deleted (the kernel releases it when its
/// process dies, kill -9 included). Used to take over stale lock files one process at a time
/// and to serialise the upkeep of shards that run at the same time ([`Upkeep`]).
struct Flock {
    _file: fs::File,
}

impl Flock {
    /// Block until `locks/<name>` is ours. A file system without `flock` (some network file
    /// systems) gives `Ok(None)`: the caller goes on without it (its other checks stand).
    fn acquire(root: &Path, name: &str) -> Result<Option<Flock>, LockError> {
        use std::os::unix::io::AsRawFd;
        let locks = own_locks_dir(root)?;
        let path = root.join("locks").join(name);
        let io = |e: std::io::Error| LockError::Io(format!("{}: {e}", path.display()));
        let file = loop {
            if let Some(f) = locks.open_file(name).map_err(io)? {
                break f;
            }
            match locks.create_new(name) {
                Ok(f) => break f,
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
                Err(e) => return Err(io(e)),
            }
        };
        loop {
            // SAFETY: flock on a file descriptor we own; no memory is passed.
            let r = unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX) };
            if r == 0 {
                return Ok(Some(Flock { _file: file }));
            }
            let e = std::io::Error::last_os_error();
            match e.raw_os_error() {
                Some(libc::EINTR) => continue,
                Some(libc::ENOLCK) | Some(libc::EOPNOTSUPP) => return Ok(None),
                _ => return Err(io(e)),
            }
        }
    }
}

/// A lock file of this process: `locks/<name>` of the campaign at `root`.
struct LockFile {
    root: PathBuf,
    name: String,
}

/// Create `locks/<tag>.lock` exclusively (O_EXCL, which NFS v3+ honours; never through a
/// link), replacing a stale one; `Err(Held)` names the live holder and what it does.
fn take_lock_file(root: &Path, info: &LockInfo) -> Result<LockFile, LockError> {
    let locks = own_locks_dir(root)?;
    let name = format!("{}.lock", info.shard_tag);
    let path = root.join("locks").join(&name);
    let io = |e: std::io::Error| LockError::Io(format!("{}: {e}", path.display()));
    // Enough tries to outwait an unreadable lock file (its writer killed between creating and
    // writing it: 100 ms a try) until it is old enough (5 s) to be taken for a crash; a live
    // holder is answered at once, a stale lock is removed and the next try takes it.
    for _ in 0..80 {
        match locks.create_new(&name) {
            Ok(mut f) => {
                use std::io::Write;
                let written = f
                    .write_all(serde_json::to_string(info).expect("lock info").as_bytes())
                    .and_then(|_| f.sync_all());
                if let Err(e) = written {
                    drop(f);
                    let _ = locks.remove_file(&name);
                    return Err(io(e));
                }
                let _ = locks.sync();
                return Ok(LockFile {
                    root: root.to_path_buf(),
                    name,
                });
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                if let Some(h) = read_lock(&locks, &name).filter(|h| lock_is_live(&locks, h)) {
                    return Err(LockError::Held(format!(
                        "{} is in use: {} is being run by {} (lock {}); wait for it to finish (`granular status DIR` shows its progress) or run another shard",
                        root.display(),
                        h.doing(),
                        h.by(),
                        path.display()
                    )));
                }
                // Stale (its process is gone) or unreadable (crashed while writing): removed
                // by one process at a time, after reading it again under the takeover lock,
                // so that a lock just taken by another process is never removed.
                let _guard = Flock::acquire(root, "takeover.flock")?;
                let seen = locks
                    .open_file(&name)
                    .ok()
                    .flatten()
                    .and_then(|f| f.metadata().ok());
                match read_lock(&locks, &name) {
                    Some(h) if lock_is_live(&locks, &h) => continue,
                    Some(_) => remove_stale(&locks, &name).map_err(io)?,
                    None => {
                        // Unreadable (or a link: removed itself): a lock being written right
                        // now looks the same for a moment; only one older than a few seconds
                        // is taken to be a crash.
                        let kind = locks.kind(&name);
                        let old = match kind {
                            Ok(Some(Kind::File)) => seen
                                .and_then(|m| m.modified().ok())
                                .and_then(|t| t.elapsed().ok())
                                .is_some_and(|age| age > std::time::Duration::from_secs(5)),
                            Ok(Some(_)) => true,
                            _ => false,
                        };
                        if old && matches!(kind, Ok(Some(Kind::File))) {
                            remove_stale(&locks, &name).map_err(io)?;
                        } else if old {
                            let _ = locks.remove_file(&name);
                        } else {
                            std::thread::sleep(std::time::Duration::from_millis(100));
                        }
                    }
                }
            }
            Err(e) => return Err(io(e)),
        }
    }
    Err(LockError::Held(format!(
        "{}: could not take the lock (another process keeps taking it); try again",
        path.display()
    )))
}

/// Remove a stale lock file (gone already is fine): a lock that cannot be removed (a
/// read-only file system, permissions) is an I/O error at the lock, not a lock held.
fn remove_stale(locks: &Dir, name: &str) -> std::io::Result<()> {
    locks.remove_file(name).map(|_| ())
}

/// Remove a lock file if it is still ours (a lock taken over as stale by another process,
/// a remote node's after `REMOTE_STALE_AFTER`, is left to its new holder).
fn release(lock: &LockFile) {
    if let Some(locks) = locks_dir(&lock.root) {
        if read_lock(&locks, &lock.name).is_some_and(|l| l.is_ours()) {
            let _ = locks.remove_file(&lock.name);
        }
    }
}

/// An exclusive claim on a campaign directory: no shard may run while it is held, and it is
/// refused while any shard runs or another process holds it. Taken by every change to the
/// campaign other than running its runs ([`Purpose`]): the holder then reads `campaign.json`,
/// the registry and the ledger, and decides on what it read. Released on drop.
pub struct ExclusiveLock {
    file: LockFile,
}

impl ExclusiveLock {
    pub fn acquire(root: &Path, purpose: Purpose) -> Result<ExclusiveLock, LockError> {
        let mut info = LockInfo::ours(COMPACT_TAG, COMPACT_TAG, 0);
        info.purpose = Some(purpose);
        let file = take_lock_file(root, &info)?;
        let lock = ExclusiveLock { file };
        // Take, then check (shards do the same the other way round): of two processes
        // starting at once, at least one sees the other.
        let running: Vec<LockInfo> = live_locks(root)
            .into_iter()
            .filter(|l| !l.is_exclusive())
            .collect();
        if let Some(l) = running.first() {
            return Err(LockError::Held(format!(
                "{} is in use: {} is being run by {} ({} shard(s) running); {} waits until no shard runs: try again when they have finished (`granular status DIR` shows their progress)",
                root.display(),
                l.doing(),
                l.by(),
                running.len(),
                purpose.doing()
            )));
        }
        Ok(lock)
    }
}

impl Drop for ExclusiveLock {
    fn drop(&mut self) {
        release(&self.file);
    }
}

/// An exclusive claim on one shard of a campaign directory, released on drop.
pub struct ShardLock {
    file: LockFile,
}

impl ShardLock {
    pub fn acquire(root: &Path, shard: Shard) -> Result<ShardLock, LockError> {
        let exclusive = |root: &Path| {
            live_locks(root)
                .into_iter()
                .find(|l| l.is_exclusive())
                .map(|l| {
                    LockError::Held(format!(
                        "{} is in use: {} is being made by {}; run or resume when it has finished",
                        root.display(),
                        l.doing(),
                        l.by()
                    ))
                })
        };
        if let Some(e) = exclusive(root) {
            return Err(e);
        }
        for other in live_locks(root) {
            if !other.is_exclusive() && other.shard_count != shard.count {
                return Err(LockError::Held(format!(
                    "{} is in use by {} running shard {} (a different shard layout than {shard}): use its shard count, or wait until it has finished",
                    root.display(),
                    other.by(),
                    other.shard
                )));
            }
        }
        let info = LockInfo::ours(&shard.to_string(), &shard.tag(), shard.count);
        let file = take_lock_file(root, &info)?;
        let lock = ShardLock { file };
        if let Some(e) = exclusive(root) {
            return Err(e);
        }
        Ok(lock)
    }
}

impl Drop for ShardLock {
    fn drop(&mut self) {
        release(&self.file);
    }
}

/// The upkeep of a campaign by the shards that run it at the same time, one process at a
/// time: recovering dead shards' commits, healing damage, and writing the summaries (each
/// reads the ledger under it and acts on what it read). Held by a shard that holds its
/// [`ShardLock`] (so the registry cannot change meanwhile: growth needs the
/// [`ExclusiveLock`]). Released on drop, or by the kernel when the process dies.
pub struct Upkeep {
    _flock: Option<Flock>,
}

impl Upkeep {
    pub fn acquire(root: &Path) -> Result<Upkeep, LockError> {
        Ok(Upkeep {
            _flock: Flock::acquire(root, "upkeep.flock")?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A lock that cannot be written (here the directory is gone, as a full disk or a read-only
    /// file system would refuse it) is an I/O error (exit 4), not "in use" (exit 3); a lock held
    /// by a live process is "in use", naming what the holder does and its pid.
    #[test]
    fn lock_errors_are_io_or_held() {
        let d = tempfile::tempdir().unwrap();
        let gone = d.path().join("no-such-directory");
        match ShardLock::acquire(&gone, Shard::ALL) {
            Err(LockError::Io(m)) => assert!(m.contains("no-such-directory"), "{m}"),
            Err(other) => panic!("expected an I/O error, got {other:?}"),
            Ok(_) => panic!("took a lock in a directory that does not exist"),
        }
        assert!(matches!(
            ExclusiveLock::acquire(&gone, Purpose::Growth),
            Err(LockError::Io(_))
        ));

        let d = tempfile::tempdir().unwrap();
        let held = ExclusiveLock::acquire(d.path(), Purpose::Upgrade).unwrap();
        match ShardLock::acquire(d.path(), Shard::ALL) {
            Err(LockError::Held(m)) => {
                assert!(m.contains("an upgrade"), "{m}");
                assert!(
                    m.contains(&format!("process {}", std::process::id())),
                    "{m}"
                );
            }
            Err(other) => panic!("expected held, got {other:?}"),
            Ok(_) => panic!("a shard started while an upgrade held the campaign"),
        }
        drop(held);
        assert!(
            !d.path().join("locks/compact.lock").exists(),
            "released on drop"
        );
        let shard = ShardLock::acquire(d.path(), Shard::ALL).unwrap();
        match ExclusiveLock::acquire(d.path(), Purpose::Compaction) {
            Err(LockError::Held(m)) => assert!(m.contains("shard 1/1"), "{m}"),
            other => panic!("expected held by the shard, got {:?}", other.err()),
        }
        drop(shard);
    }

    /// A stale lock (its process gone) is taken over; a lock file that is not ours is never
    /// removed by our drop.
    #[test]
    fn stale_locks_are_taken_over_and_others_are_left_alone() {
        let d = tempfile::tempdir().unwrap();
        fs::create_dir(d.path().join("locks")).unwrap();
        let mut dead = LockInfo::ours("compact", COMPACT_TAG, 0);
        dead.pid = u32::MAX - 1; // no such process
        dead.start_time = Some(1);
        let path = d.path().join("locks/compact.lock");
        fs::write(&path, serde_json::to_string(&dead).unwrap()).unwrap();
        let lock = ExclusiveLock::acquire(d.path(), Purpose::Theory).unwrap();
        let now: LockInfo = serde_json::from_str(&fs::read_to_string(&path).unwrap()).unwrap();
        assert!(now.is_ours() && now.purpose == Some(Purpose::Theory));
        // Someone else's lock in its place (taken over as stale from another host, say).
        fs::write(&path, serde_json::to_string(&dead).unwrap()).unwrap();
        drop(lock);
        assert!(path.exists(), "a lock that is not ours was removed");
    }
}

#[cfg(test)]
mod closed_world_tests {
    use super::*;

    /// `locks` as a link out of the campaign (or a file): the link is set aside, never
    /// followed; no lock is written outside.
    #[test]
    fn a_locks_link_is_set_aside_not_followed() {
        let d = tempfile::tempdir().unwrap();
        let camp = d.path().join("camp");
        let outside = d.path().join("outside");
        fs::create_dir_all(&camp).unwrap();
        fs::create_dir_all(&outside).unwrap();
        std::os::unix::fs::symlink(&outside, camp.join("locks")).unwrap();
        let lock = ShardLock::acquire(&camp, Shard::ALL).unwrap();
        assert!(
            fs::read_dir(&outside).unwrap().next().is_none(),
            "written outside"
        );
        assert!(fs::symlink_metadata(camp.join("locks")).unwrap().is_dir());
        let aside: Vec<String> = fs::read_dir(&camp)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with("locks.moved-"))
            .collect();
        assert_eq!(aside.len(), 1, "{aside:?}");
        assert!(fs::symlink_metadata(camp.join(&aside[0]))
            .unwrap()
            .file_type()
            .is_symlink());
        drop(lock);
        let _ = Upkeep::acquire(&camp).unwrap();
        assert!(
            fs::read_dir(&outside).unwrap().next().is_none(),
            "written outside"
        );
        // A file in its place: set aside too.
        fs::remove_dir_all(camp.join("locks")).unwrap();
        fs::write(camp.join("locks"), b"x").unwrap();
        let _l = ExclusiveLock::acquire(&camp, Purpose::Compaction).unwrap();
        assert!(fs::symlink_metadata(camp.join("locks")).unwrap().is_dir());
    }
}
