//! Campaign status across all shards: done / failed / running / pending, per point. Reads the
//! commit records and the live shards' heartbeats; of the tables only their sizes (the quick
//! integrity check).

use crate::rng::StreamVersion;
use std::collections::BTreeSet;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::error::CampaignError;
use super::ledger::{self, RunStatus};
use super::{integrity, Campaign};
use crate::fsutil;

#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct Counts {
    pub done: u64,
    pub failed: u64,
    pub running: u64,
    pub pending: u64,
    /// Pending or running runs that have a checkpoint to resume from.
    pub checkpointed: u64,
    /// Unfinished runs the latest manifest no longer asks for (they do not run).
    #[serde(default)]
    pub dropped: u64,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct PointStatus {
    pub point_id: u32,
    /// The swept values of the point, `key=value`.
    pub point: String,
    /// Whether the latest manifest asks for this point (a point it no longer lists keeps its
    /// finished runs).
    pub in_manifest: bool,
    #[serde(flatten)]
    pub counts: Counts,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct CampaignStatus {
    pub name: String,
    /// Every run of the campaign (of every accepted manifest).
    pub runs: u64,
    #[serde(flatten)]
    pub counts: Counts,
    /// The runs the latest manifest asks for, and their counts.
    #[serde(default)]
    pub current_runs: u64,
    #[serde(default)]
    pub current: Counts,
    /// Manifests accepted so far (the latest is the campaign's).
    #[serde(default)]
    pub manifests: usize,
    /// How the campaign's runs draw their random numbers (`campaign.json`; see
    /// [`describe_stream`]).
    #[serde(default)]
    pub stream_version: StreamVersion,
    pub live_shards: Vec<String>,
    pub points: Vec<PointStatus>,
    /// SLURM submissions (`granular submit`), with their jobs' states when squeue answers.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub slurm: Vec<super::slurm::SubmissionStatus>,
    /// What the quick check of the tables against the ledger found (see `integrity`); the
    /// counts above are the ledger's. `granular resume` heals it.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub damage: Vec<String>,
    /// A campaign with error targets: each target's error against its goal per point.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub targets: Option<super::targets::TargetsStatus>,
}

#[derive(Serialize, Deserialize)]
struct Heartbeat {
    running: Vec<u64>,
}

pub fn write_heartbeat(root: &Path, tag: &str, running: &BTreeSet<u64>) -> std::io::Result<()> {
    let hb = Heartbeat {
        running: running.iter().copied().collect(),
    };
    fsutil::write_atomic(
        &root.join("locks").join(format!("{tag}.running.json")),
        &serde_json::to_vec(&hb).expect("heartbeat"),
    )
}

pub fn remove_heartbeat(root: &Path, tag: &str) {
    let _ = std::fs::remove_file(root.join("locks").join(format!("{tag}.running.json")));
}

/// The JSON of a status, as `granular status --json` prints it and `granular serve` answers
/// `/api/status`.
/// What a random stream version is, for people: "version 2 (ChaCha8, counter-addressed RFM
/// noise)".
pub fn describe_stream(v: StreamVersion) -> String {
    let what = match v.number() {
        1 => "ChaCha8, sequential draws",
        2 => "ChaCha8, counter-addressed RFM noise",
        3 => "counter-addressed RFM noise, DSMC from AES-128-CTR",
        4 => "RFM noise addressed by storage slot, DSMC from AES-128-CTR",
        _ => "unknown",
    };
    format!("version {} ({what})", v.number())
}

pub fn to_json(s: &CampaignStatus) -> String {
    serde_json::to_string_pretty(s).expect("status serialises")
}

/// A cheap fingerprint of what [`status`] reads, for callers that cache it (`granular
/// serve`): the modification times and sizes of `campaign.json`, of the ledger, lock,
/// checkpoint, table, generation, sidecar and SLURM directories and of their entries (a
/// commit, heartbeat, checkpoint, part or generation is a rename into one of them), and the
/// live lock holders (a process that died leaves its lock file unchanged). A table file
/// changed in place without a rename is not seen: the cache's age limit covers it.
pub fn fingerprint(root: &Path) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    let stat = |p: &Path, h: &mut std::collections::hash_map::DefaultHasher| {
        match std::fs::symlink_metadata(p) {
            Ok(m) => (m.modified().ok(), m.len(), m.is_dir()).hash(h),
            Err(_) => 0u8.hash(h),
        }
    };
    stat(&root.join("campaign.json"), &mut h);
    for (dir, entries) in [
        ("ledger", true),
        ("locks", true),
        ("checkpoints", false),
        ("tables", true),
        ("tables/.gen", true),
        ("sums", true),
        ("slurm", true),
    ] {
        let d = root.join(dir);
        dir.hash(&mut h);
        stat(&d, &mut h);
        if !entries {
            continue;
        }
        let mut names: Vec<_> = std::fs::read_dir(&d)
            .map(|it| it.filter_map(|e| e.ok()).map(|e| e.path()).collect())
            .unwrap_or_default();
        names.sort();
        for p in names {
            p.hash(&mut h);
            stat(&p, &mut h);
        }
    }
    for l in ledger::live_locks(root) {
        serde_json::to_string(&l).unwrap_or_default().hash(&mut h);
    }
    h.finish()
}

pub fn status(c: &Campaign) -> Result<CampaignStatus, CampaignError> {
    let check = integrity::check(c, integrity::Depth::Quick)?;
    let commits = ledger::read_ledger(&c.root)?.commits;
    let finished = ledger::finished_runs(&commits);
    let live = ledger::live_locks(&c.root);
    let running = running_runs(c, &live);
    let ckpts = checkpointed_runs(c);
    let mut points = point_rows(c);
    let (total, current, current_runs) = count_runs(c, &finished, &running, &ckpts, &mut points);
    Ok(CampaignStatus {
        name: c.manifest.name.clone(),
        runs: c.plan.n_runs(),
        counts: total,
        current_runs,
        current,
        manifests: c.history.len(),
        stream_version: c.stream,
        live_shards: live
            .iter()
            .map(|l| format!("{} (pid {} on {})", l.shard, l.pid, l.host))
            .collect(),
        points,
        slurm: super::slurm::submission_status(&c.root)?,
        targets: if check.problems().is_empty() {
            super::targets::status(c, &finished)
        } else {
            None
        },
        damage: check.problems(),
    })
}

/// The runs that the heartbeats of the `live` shards name as running (a heartbeat that is
/// missing or unreadable names none).
fn running_runs(c: &Campaign, live: &[ledger::LockInfo]) -> BTreeSet<u64> {
    let mut running = BTreeSet::new();
    for l in live {
        let p = c
            .root
            .join("locks")
            .join(format!("{}.running.json", l.shard_tag));
        if let Some(hb) = std::fs::read_to_string(p)
            .ok()
            .and_then(|s| serde_json::from_str::<Heartbeat>(&s).ok())
        {
            running.extend(hb.running);
        }
    }
    running
}

/// The runs that have a checkpoint (`checkpoints/run-<id>.ckpt`).
fn checkpointed_runs(c: &Campaign) -> BTreeSet<u64> {
    std::fs::read_dir(c.checkpoint_dir())
        .map(|it| {
            it.filter_map(|e| e.ok())
                .filter_map(|e| {
                    let n = e.file_name().to_string_lossy().into_owned();
                    n.strip_prefix("run-")?
                        .strip_suffix(".ckpt")?
                        .parse::<u64>()
                        .ok()
                })
                .collect()
        })
        .unwrap_or_default()
}

/// One row per registered point, in the plan's order, with its swept values and zero counts.
fn point_rows(c: &Campaign) -> Vec<PointStatus> {
    c.plan
        .points
        .iter()
        .map(|p| PointStatus {
            point_id: p.point_id,
            point: c
                .plan
                .sweep_keys
                .iter()
                .zip(&p.values)
                .map(|(k, v)| format!("{k}={v}"))
                .collect::<Vec<_>>()
                .join(" "),
            in_manifest: p.current,
            counts: Counts::default(),
        })
        .collect()
}

/// Count every run into its point's row and the campaign's totals; returns the totals, the
/// counts of the runs the latest manifest asks for, and how many runs it asks for.
fn count_runs(
    c: &Campaign,
    finished: &std::collections::BTreeMap<u64, RunStatus>,
    running: &BTreeSet<u64>,
    ckpts: &BTreeSet<u64>,
    points: &mut [PointStatus],
) -> (Counts, Counts, u64) {
    let mut total = Counts::default();
    let mut current = Counts::default();
    let mut current_runs = 0;
    for run_id in 0..c.plan.n_runs() {
        let spec = c.plan.run(run_id);
        let pc = &mut points[spec.point_id as usize].counts;
        if c.plan.is_current(&spec) {
            current_runs += 1;
            match finished.get(&run_id) {
                Some(RunStatus::Done) => current.done += 1,
                Some(RunStatus::Failed) => current.failed += 1,
                None if running.contains(&run_id) => current.running += 1,
                None => current.pending += 1,
            }
            if !finished.contains_key(&run_id) && ckpts.contains(&run_id) {
                current.checkpointed += 1;
            }
        }
        match finished.get(&run_id) {
            Some(RunStatus::Done) => {
                pc.done += 1;
                total.done += 1
            }
            Some(RunStatus::Failed) => {
                pc.failed += 1;
                total.failed += 1
            }
            None if !c.plan.is_current(&spec) => {
                pc.dropped += 1;
                total.dropped += 1;
            }
            None => {
                if running.contains(&run_id) {
                    pc.running += 1;
                    total.running += 1;
                } else {
                    pc.pending += 1;
                    total.pending += 1;
                }
                if ckpts.contains(&run_id) {
                    pc.checkpointed += 1;
                    total.checkpointed += 1;
                }
            }
        }
    }
    (total, current, current_runs)
}
