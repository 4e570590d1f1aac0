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

use crate::fsutil;
use crate::plan::Shard;
use crate::store::FORMAT_VERSION;

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

/// Every commit of every shard, ordered by (shard, seq).
pub fn read_commits(root: &Path) -> Result<Vec<Commit>, String> {
    let mut out = Vec::new();
    let dir = root.join("ledger");
    let Ok(entries) = fs::read_dir(&dir) else {
        return Ok(out);
    };
    let mut tags: Vec<PathBuf> = entries
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| p.is_dir())
        .collect();
    tags.sort();
    for tag in tags {
        let mut files: Vec<PathBuf> = fs::read_dir(&tag)
            .map_err(|e| format!("{}: {e}", tag.display()))?
            .filter_map(|e| e.ok())
            .map(|e| e.path())
            .filter(|p| {
                p.file_name().is_some_and(|n| {
                    n.to_string_lossy().starts_with("commit-")
                        && n.to_string_lossy().ends_with(".json")
                })
            })
            .collect();
        files.sort();
        for f in files {
            let text = fs::read_to_string(&f).map_err(|e| format!("{}: {e}", f.display()))?;
            let c: Commit = serde_json::from_str(&text)
                .map_err(|e| format!("{}: corrupt commit record: {e}", f.display()))?;
            if c.format_version != FORMAT_VERSION {
                return Err(format!(
                    "{}: format version {}, this granular reads {FORMAT_VERSION}",
                    f.display(),
                    c.format_version
                ));
            }
            out.push(c);
        }
    }
    Ok(out)
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
    let Ok(entries) = fs::read_dir(ledger_dir(root, tag)) else {
        return 1;
    };
    entries
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let n = e.file_name().to_string_lossy().into_owned();
            n.strip_prefix("commit-")?
                .strip_suffix(".json")?
                .parse::<u64>()
                .ok()
        })
        .max()
        .unwrap_or(0)
        + 1
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
        root.join("locks"),
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

fn lock_is_live(l: &LockInfo) -> bool {
    // A lock of another host cannot be checked from here: treat it as live.
    l.host != hostname() || pid_alive(l.pid)
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
        .filter(lock_is_live)
        .collect()
}

/// An exclusive claim on one shard of a campaign directory, released on drop.
pub struct ShardLock {
    path: PathBuf,
}

impl ShardLock {
    pub fn acquire(root: &Path, shard: Shard) -> Result<ShardLock, String> {
        let dir = root.join("locks");
        fsutil::create_dir_durable(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        for other in live_locks(root) {
            if other.shard_count != shard.count {
                return Err(format!(
                    "{} is in use by process {} on {} running shard {} (a different shard layout than {shard})",
                    root.display(),
                    other.pid,
                    other.host,
                    other.shard
                ));
            }
        }
        let path = dir.join(format!("{}.lock", shard.tag()));
        let info = LockInfo {
            pid: std::process::id(),
            host: hostname(),
            shard: shard.to_string(),
            shard_tag: shard.tag(),
            shard_count: shard.count,
        };
        for _ in 0..2 {
            match fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&path)
            {
                Ok(mut f) => {
                    use std::io::Write;
                    f.write_all(serde_json::to_string(&info).expect("lock info").as_bytes())
                        .and_then(|_| f.sync_all())
                        .map_err(|e| format!("{}: {e}", path.display()))?;
                    let _ = fsutil::sync_dir(&dir);
                    return Ok(ShardLock { path });
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                    let holder = fs::read_to_string(&path)
                        .ok()
                        .and_then(|s| serde_json::from_str::<LockInfo>(&s).ok());
                    match holder {
                        Some(h) if lock_is_live(&h) => {
                            return Err(format!(
                                "{} is in use: shard {} is being run by process {} on {} (lock {})",
                                root.display(),
                                h.shard,
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
}

impl Drop for ShardLock {
    fn drop(&mut self) {
        let _ = fs::remove_file(&self.path);
    }
}
