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

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::campaign::plan::Shard;
use crate::fsutil;
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
    /// Table files of this commit, relative to the campaign directory.
    pub files: Vec<String>,
}

pub fn ledger_dir(root: &Path, tag: &str) -> PathBuf {
    root.join("ledger").join(tag)
}

pub fn commit_path(root: &Path, tag: &str, seq: u64) -> PathBuf {
    ledger_dir(root, tag).join(format!("commit-{seq:08}.json"))
}

/// The hidden name a table part has until its commit is durable.
pub fn pending_path(final_path: &Path) -> PathBuf {
    let name = final_path.file_name().expect("file name").to_string_lossy();
    final_path.with_file_name(format!(".{name}.pending"))
}

/// The folded ledger written by `granular compact`: every run committed by the commit records
/// it replaced, so that `status` and `resume` read one file instead of one per flush.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq, Default)]
pub struct LedgerIndex {
    pub format_version: u32,
    /// Always "granular.ledger_index".
    pub kind: String,
    /// Per shard tag, the highest commit sequence number folded in (commit records of that
    /// shard up to it are ignored if still present: a compaction stopped before deleting them).
    pub folded: BTreeMap<String, u64>,
    /// Runs finished as done, as inclusive ranges of run ids.
    pub done: Vec<(u64, u64)>,
    /// Runs finished as failed.
    pub failed: Vec<u64>,
}

pub const INDEX_KIND: &str = "granular.ledger_index";

pub fn index_path(root: &Path) -> PathBuf {
    root.join("ledger").join("index.json")
}

pub fn read_index(root: &Path) -> Result<Option<LedgerIndex>, String> {
    let p = index_path(root);
    let text = match fs::read_to_string(&p) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(format!("{}: {e}", p.display())),
    };
    let ix: LedgerIndex = serde_json::from_str(&text)
        .map_err(|e| format!("{}: corrupt ledger index: {e}", p.display()))?;
    if ix.kind != INDEX_KIND || ix.format_version != LEDGER_FORMAT {
        return Err(format!(
            "{}: not a ledger index of format {LEDGER_FORMAT} (kind {:?}, format {})",
            p.display(),
            ix.kind,
            ix.format_version
        ));
    }
    Ok(Some(ix))
}

impl LedgerIndex {
    /// Build the index of `commits` (the first commit of a run wins).
    pub fn fold(commits: &[Commit]) -> LedgerIndex {
        let finished = finished_runs(commits);
        let mut folded: BTreeMap<String, u64> = BTreeMap::new();
        for c in commits {
            if c.shard == INDEX_SHARD {
                continue;
            }
            let e = folded.entry(c.shard.clone()).or_insert(0);
            *e = (*e).max(c.seq);
        }
        let mut done: Vec<(u64, u64)> = Vec::new();
        let mut failed = Vec::new();
        for (&r, &st) in &finished {
            match st {
                RunStatus::Done => match done.last_mut() {
                    Some((_, hi)) if *hi + 1 == r => *hi = r,
                    _ => done.push((r, r)),
                },
                RunStatus::Failed => failed.push(r),
            }
        }
        LedgerIndex {
            format_version: LEDGER_FORMAT,
            kind: INDEX_KIND.into(),
            folded,
            done,
            failed,
        }
    }

    /// The index as one commit (shard `index`, no files), placed before all others.
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
            shard: INDEX_SHARD.into(),
            seq: 0,
            runs,
            files: Vec::new(),
        }
    }
}

/// The shard name of the folded index in `read_commits`' output.
pub const INDEX_SHARD: &str = "index";

/// Commit record files of a shard directory with their sequence numbers, sorted.
fn commit_files(dir: &Path) -> Result<Vec<(u64, PathBuf)>, String> {
    let mut files: Vec<(u64, PathBuf)> = fs::read_dir(dir)
        .map_err(|e| format!("{}: {e}", dir.display()))?
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let n = e.file_name().to_string_lossy().into_owned();
            let seq = n
                .strip_prefix("commit-")?
                .strip_suffix(".json")?
                .parse::<u64>()
                .ok()?;
            Some((seq, e.path()))
        })
        .collect();
    files.sort();
    Ok(files)
}

/// Every commit: the folded index first (if any), then every shard's commit records not
/// folded into it, ordered by (shard, seq). A record that vanishes while being read (a
/// compaction folding it into the index at that moment) makes the whole read start again.
pub fn read_commits(root: &Path) -> Result<Vec<Commit>, String> {
    let mut last = String::new();
    for _ in 0..20 {
        match read_commits_once(root) {
            Ok(Some(v)) => return Ok(v),
            Ok(None) => std::thread::sleep(std::time::Duration::from_millis(50)),
            Err(e) => return Err(e),
        }
        last = "commit records kept vanishing while being read (a compaction running?)".into();
    }
    Err(format!("{}: {last}", root.display()))
}

/// `Ok(None)`: a commit record listed was gone when opened.
fn read_commits_once(root: &Path) -> Result<Option<Vec<Commit>>, String> {
    let mut out = Vec::new();
    let index = read_index(root)?;
    if let Some(ix) = &index {
        out.push(ix.as_commit());
    }
    let dir = root.join("ledger");
    let Ok(entries) = fs::read_dir(&dir) else {
        return Ok(Some(out));
    };
    let mut tags: Vec<PathBuf> = entries
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| p.is_dir())
        .collect();
    tags.sort();
    for tag in tags {
        let name = tag
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let folded = index
            .as_ref()
            .and_then(|ix| ix.folded.get(&name).copied())
            .unwrap_or(0);
        for (seq, f) in commit_files(&tag)? {
            if seq <= folded {
                continue;
            }
            let text = match fs::read_to_string(&f) {
                Ok(t) => t,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
                Err(e) => return Err(format!("{}: {e}", f.display())),
            };
            let c: Commit = serde_json::from_str(&text)
                .map_err(|e| format!("{}: corrupt commit record: {e}", f.display()))?;
            if c.format_version != LEDGER_FORMAT {
                return Err(format!(
                    "{}: format version {}, this granular reads {LEDGER_FORMAT}",
                    f.display(),
                    c.format_version
                ));
            }
            out.push(c);
        }
    }
    Ok(Some(out))
}

/// Fold every commit record into `ledger/index.json` and delete the records folded in. Only
/// for a campaign no process is writing to (`granular compact` holds the compaction lock) and
/// after `recover` (every commit's parts renamed into place). Returns the records removed.
pub fn fold_into_index(root: &Path) -> Result<usize, String> {
    let commits = read_commits(root)?;
    let ix = LedgerIndex::fold(&commits);
    let p = index_path(root);
    fsutil::write_atomic(&p, &serde_json::to_vec(&ix).expect("index serialises"))
        .map_err(|e| format!("{}: {e}", p.display()))?;
    let mut removed = 0;
    for c in &commits {
        if c.shard == INDEX_SHARD {
            continue;
        }
        let f = commit_path(root, &c.shard, c.seq);
        if fs::remove_file(&f).is_ok() {
            removed += 1;
        }
    }
    if let Ok(entries) = fs::read_dir(root.join("ledger")) {
        for d in entries.filter_map(|e| e.ok()).filter(|e| e.path().is_dir()) {
            let _ = fsutil::sync_dir(&d.path());
        }
    }
    Ok(removed)
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

/// Roll forward committed parts and roll back uncommitted ones, for every shard whose lock
/// is not held by a live process (our own shard's lock is held by us: pass it as `ours`).
pub fn recover(root: &Path, ours: &str) -> Result<Vec<String>, String> {
    let mut notes = Vec::new();
    let commits = read_commits(root)?;
    let live: Vec<String> = live_locks(root)
        .into_iter()
        .map(|l| l.shard_tag)
        .filter(|t| t != ours)
        .collect();
    let mut referenced = std::collections::HashSet::new();
    for c in &commits {
        for f in &c.files {
            let fin = root.join(f);
            referenced.insert(pending_path(&fin));
            if live.contains(&c.shard) {
                continue;
            }
            let pend = pending_path(&fin);
            if !fin.exists() && pend.exists() {
                fs::rename(&pend, &fin).map_err(|e| format!("{}: {e}", pend.display()))?;
                notes.push(format!("completed the commit of {}", fin.display()));
            }
        }
    }
    notes.extend(remove_stale_temporaries(root));
    let tables = root.join("tables");
    if let Ok(entries) = fs::read_dir(&tables) {
        for t in entries.filter_map(|e| e.ok()) {
            let Ok(files) = fs::read_dir(t.path()) else {
                continue;
            };
            for f in files.filter_map(|e| e.ok()) {
                let p = f.path();
                let name = f.file_name().to_string_lossy().into_owned();
                if !name.ends_with(".pending") || referenced.contains(&p) {
                    continue;
                }
                // `.part-<tag>-<seq>.parquet.pending`
                let tag = name
                    .trim_start_matches(".part-")
                    .split('-')
                    .next()
                    .unwrap_or("")
                    .to_string();
                if live.contains(&tag) {
                    continue;
                }
                fs::remove_file(&p).map_err(|e| format!("{}: {e}", p.display()))?;
                notes.push(format!("discarded the uncommitted part {}", p.display()));
            }
            let _ = fsutil::sync_dir(&t.path());
        }
    }
    Ok(notes)
}

/// Delete temporary files (`.NAME.<pid>-<nanos>@<host>.tmp`, see `fsutil::temp_path`) left by
/// processes of this host that died while writing (a kill during a checkpoint, say). Files of
/// other hosts are left alone: their processes cannot be checked from here.
fn remove_stale_temporaries(root: &Path) -> Vec<String> {
    let mut notes = Vec::new();
    let mut dirs = vec![
        root.to_path_buf(),
        root.join("checkpoints"),
        root.join("finals"),
        root.join("locks"),
        root.join("tables"),
        root.join("ledger"),
    ];
    for sub in ["tables", "ledger"] {
        if let Ok(it) = fs::read_dir(root.join(sub)) {
            dirs.extend(
                it.filter_map(|e| e.ok())
                    .map(|e| e.path())
                    .filter(|p| p.is_dir()),
            );
        }
    }
    for dir in dirs {
        let Ok(it) = fs::read_dir(&dir) else { continue };
        for f in it.filter_map(|e| e.ok()) {
            let name = f.file_name().to_string_lossy().into_owned();
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
                if !pid_alive(pid) && fs::remove_file(f.path()).is_ok() {
                    notes.push(format!(
                        "removed the stale temporary file {}",
                        f.path().display()
                    ));
                }
            }
        }
    }
    notes
}

/// Who holds a shard.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct LockInfo {
    pub pid: u32,
    pub host: String,
    pub shard: String,
    pub shard_tag: String,
    pub shard_count: u32,
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

/// The lock's tag of a compaction (`granular compact`).
pub const COMPACT_TAG: &str = "compact";

fn lock_is_live(root: &Path, l: &LockInfo) -> bool {
    if l.host == hostname() {
        return pid_alive(l.pid);
    }
    // Another host's process cannot be checked from here: it is live while its heartbeat (or,
    // before the first heartbeat, its lock file) is recent.
    let locks = root.join("locks");
    let newest = [
        locks.join(format!("{}.running.json", l.shard_tag)),
        locks.join(format!("{}.lock", l.shard_tag)),
    ]
    .iter()
    .filter_map(|p| fs::metadata(p).ok()?.modified().ok())
    .max();
    match newest {
        Some(t) => t.elapsed().map_or(true, |age| age < REMOTE_STALE_AFTER),
        None => false,
    }
}

/// Locks of live processes.
pub fn live_locks(root: &Path) -> Vec<LockInfo> {
    let Ok(entries) = fs::read_dir(root.join("locks")) else {
        return Vec::new();
    };
    entries
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".lock"))
        .filter_map(|e| serde_json::from_str::<LockInfo>(&fs::read_to_string(e.path()).ok()?).ok())
        .filter(|l| lock_is_live(root, l))
        .collect()
}

/// Create `locks/<tag>.lock` exclusively (O_EXCL, which NFS v3+ honours), replacing a stale
/// one; `Err` names the live holder.
fn take_lock_file(root: &Path, info: &LockInfo) -> Result<PathBuf, String> {
    let dir = root.join("locks");
    fsutil::create_dir_durable(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let path = dir.join(format!("{}.lock", info.shard_tag));
    for _ in 0..2 {
        match fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&path)
        {
            Ok(mut f) => {
                use std::io::Write;
                f.write_all(serde_json::to_string(info).expect("lock info").as_bytes())
                    .and_then(|_| f.sync_all())
                    .map_err(|e| format!("{}: {e}", path.display()))?;
                let _ = fsutil::sync_dir(&dir);
                return Ok(path);
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                let holder = fs::read_to_string(&path)
                    .ok()
                    .and_then(|s| serde_json::from_str::<LockInfo>(&s).ok());
                match holder {
                    Some(h) if lock_is_live(root, &h) => {
                        return Err(format!(
                            "{} is in use: {} is being run by process {} on {} (lock {})",
                            root.display(),
                            if h.shard_tag == COMPACT_TAG {
                                "a compaction".to_string()
                            } else {
                                format!("shard {}", h.shard)
                            },
                            h.pid,
                            h.host,
                            path.display()
                        ))
                    }
                    _ => {
                        // Stale (its process is gone) or unreadable (crashed while writing).
                        let _ = fs::remove_file(&path);
                    }
                }
            }
            Err(e) => return Err(format!("{}: {e}", path.display())),
        }
    }
    Err(format!("{}: could not take the lock", path.display()))
}

/// An exclusive claim on a campaign directory for `granular compact`: no shard may run while
/// it is held, and it is refused while any shard runs. Released on drop.
pub struct CompactLock {
    path: PathBuf,
}

impl CompactLock {
    pub fn acquire(root: &Path) -> Result<CompactLock, String> {
        let info = LockInfo {
            pid: std::process::id(),
            host: hostname(),
            shard: COMPACT_TAG.into(),
            shard_tag: COMPACT_TAG.into(),
            shard_count: 0,
        };
        let path = take_lock_file(root, &info)?;
        let lock = CompactLock { path };
        // Take, then check (shards do the same the other way round): of two processes
        // starting at once, at least one sees the other.
        let running: Vec<LockInfo> = live_locks(root)
            .into_iter()
            .filter(|l| l.shard_tag != COMPACT_TAG)
            .collect();
        if let Some(l) = running.first() {
            return Err(format!(
                "{} is in use: shard {} is being run by process {} on {} ({} shard(s) running); compact when no shard runs",
                root.display(),
                l.shard,
                l.pid,
                l.host,
                running.len()
            ));
        }
        Ok(lock)
    }
}

impl Drop for CompactLock {
    fn drop(&mut self) {
        let _ = fs::remove_file(&self.path);
    }
}

/// An exclusive claim on one shard of a campaign directory, released on drop.
pub struct ShardLock {
    path: PathBuf,
}

impl ShardLock {
    pub fn acquire(root: &Path, shard: Shard) -> Result<ShardLock, String> {
        let compacting = |root: &Path| {
            live_locks(root)
                .into_iter()
                .find(|l| l.shard_tag == COMPACT_TAG)
                .map(|l| {
                    format!(
                        "{} is being compacted by process {} on {}; run or resume when `granular compact` has finished",
                        root.display(),
                        l.pid,
                        l.host
                    )
                })
        };
        if let Some(e) = compacting(root) {
            return Err(e);
        }
        for other in live_locks(root) {
            if other.shard_tag != COMPACT_TAG && other.shard_count != shard.count {
                return Err(format!(
                    "{} is in use by process {} on {} running shard {} (a different shard layout than {shard})",
                    root.display(),
                    other.pid,
                    other.host,
                    other.shard
                ));
            }
        }
        let info = LockInfo {
            pid: std::process::id(),
            host: hostname(),
            shard: shard.to_string(),
            shard_tag: shard.tag(),
            shard_count: shard.count,
        };
        let path = take_lock_file(root, &info)?;
        let lock = ShardLock { path };
        if let Some(e) = compacting(root) {
            return Err(e);
        }
        Ok(lock)
    }
}

impl Drop for ShardLock {
    fn drop(&mut self) {
        let _ = fs::remove_file(&self.path);
    }
}
