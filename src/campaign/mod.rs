//! The campaign engine: a campaign directory, its frozen manifest and plan, and `run`, which
//! drives the pending runs of a shard on a rayon pool while one dispatcher (this thread) owns
//! the campaign state, fans events out to the reporter and feeds the single table writer.
//!
//! Directory layout:
//! ```text
//! <out>/campaign.json            format, code version, frozen manifest
//! <out>/manifest.json            the manifest as given
//! <out>/locks/<shard>.lock       who runs a shard (pid, host); <shard>.running.json heartbeat
//! <out>/ledger/<shard>/commit-*.json   finished runs and their table parts (see ledger)
//! <out>/checkpoints/run-*.ckpt   running simulations
//! <out>/tables/<table>/*.parquet one dataset per table
//! ```

pub mod compact;
pub mod ledger;
pub mod slurm;
pub mod status;
pub mod verify;
pub mod worker;
pub mod writer;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::fsutil;
use crate::manifest::{self, Manifest, ManifestErrors};
use crate::plan::{canonical, Plan, RunSpec, Shard};
use crate::store::FORMAT_VERSION;
use crate::CODE_VERSION;
use ledger::{RunStatus, ShardLock};
use worker::{RunEnd, RunResult};

#[derive(Debug, thiserror::Error)]
pub enum CampaignError {
    #[error("{0}")]
    Manifest(#[from] ManifestErrors),
    /// The directory holds another campaign, is locked, or is not a campaign directory.
    #[error("{0}")]
    Refused(String),
    #[error("{0}")]
    Io(String),
}

/// `campaign.json`.
#[derive(Serialize, Deserialize, Clone, Debug)]
pub struct CampaignInfo {
    pub format_version: u32,
    pub code_version: String,
    pub name: String,
    pub n_runs: u64,
    pub manifest: Value,
}

/// An opened campaign directory.
pub struct Campaign {
    pub root: PathBuf,
    pub manifest: Manifest,
    pub plan: Plan,
    /// Canonical JSON of the manifest (stored in every table file's metadata).
    pub manifest_json: String,
}

fn io_err(p: &Path, e: impl std::fmt::Display) -> CampaignError {
    CampaignError::Io(format!("{}: {e}", p.display()))
}

impl Campaign {
    /// Validate `manifest_path` and create `out` for it, or open `out` if it already holds
    /// the same campaign (a different one is refused). Nothing is written for a bad manifest.
    pub fn create_or_open(manifest_path: &Path, out: &Path) -> Result<Campaign, CampaignError> {
        let (manifest, plan) = manifest::load_manifest(manifest_path)?;
        let value = serde_json::to_value(&manifest).expect("manifest serialises");
        let info_path = out.join("campaign.json");
        if info_path.exists() {
            let existing = Self::open(out)?;
            let old = serde_json::to_value(&existing.manifest).expect("manifest serialises");
            if canonical(&old) != canonical(&value) {
                let mut diffs = Vec::new();
                if let (Some(a), Some(b)) = (old.as_object(), value.as_object()) {
                    for k in a.keys().chain(b.keys()) {
                        if a.get(k) != b.get(k) && !diffs.contains(k) {
                            diffs.push(k.clone());
                        }
                    }
                }
                return Err(CampaignError::Refused(format!(
                    "{} holds a different campaign ({:?}; differs in: {}); use another --out, or `granular resume {}`",
                    out.display(),
                    existing.manifest.name,
                    diffs.join(", "),
                    out.display()
                )));
            }
            return Ok(existing);
        }
        if out.exists() {
            let non_empty = std::fs::read_dir(out)
                .map_err(|e| io_err(out, e))?
                .next()
                .is_some();
            if non_empty {
                return Err(CampaignError::Refused(format!(
                    "{} exists and is not a granular campaign directory (no campaign.json); refusing to write into it",
                    out.display()
                )));
            }
        }
        fsutil::create_dir_durable(out).map_err(|e| io_err(out, e))?;
        let text = std::fs::read(manifest_path).map_err(|e| io_err(manifest_path, e))?;
        let info = CampaignInfo {
            format_version: FORMAT_VERSION,
            code_version: CODE_VERSION.into(),
            name: manifest.name.clone(),
            n_runs: plan.n_runs(),
            manifest: value.clone(),
        };
        let bytes = serde_json::to_vec_pretty(&info).expect("info serialises");
        // campaign.json first: it alone makes the directory a campaign (manifest.json is a copy
        // for people), so a kill between the two writes leaves a resumable directory.
        fsutil::write_atomic(&info_path, &bytes).map_err(|e| io_err(&info_path, e))?;
        fsutil::write_atomic(&out.join("manifest.json"), &text).map_err(|e| io_err(out, e))?;
        Ok(Campaign {
            root: out.to_path_buf(),
            manifest,
            plan,
            manifest_json: canonical(&value),
        })
    }

    /// Open an existing campaign directory.
    pub fn open(root: &Path) -> Result<Campaign, CampaignError> {
        let info_path = root.join("campaign.json");
        let text = std::fs::read_to_string(&info_path).map_err(|e| {
            CampaignError::Refused(format!(
                "{}: not a granular campaign directory ({e})",
                root.display()
            ))
        })?;
        let info: CampaignInfo = serde_json::from_str(&text).map_err(|e| {
            CampaignError::Refused(format!(
                "{}: corrupt or foreign file: {e}",
                info_path.display()
            ))
        })?;
        if info.format_version != FORMAT_VERSION {
            return Err(CampaignError::Refused(format!(
                "{}: format version {}, this granular reads {FORMAT_VERSION}",
                info_path.display(),
                info.format_version
            )));
        }
        if info.code_version != CODE_VERSION {
            tracing::warn!(was = %info.code_version, now = CODE_VERSION, "campaign was started by another code version");
        }
        let text = serde_json::to_string(&info.manifest).expect("value serialises");
        let (manifest, plan) = manifest::parse_manifest(&text, &info_path.display().to_string())?;
        Ok(Campaign {
            root: root.to_path_buf(),
            manifest,
            plan,
            manifest_json: canonical(&info.manifest),
        })
    }

    /// Whether any point records the time-averaged MSD (then, and only then, the campaign has
    /// the `dsmc_tamsd*` and `dsmc_theory_tamsd` tables).
    pub fn observes_tamsd(&self) -> bool {
        self.plan.points.iter().any(|p| match &p.params {
            crate::plan::ModelParams::Dsmc(d) => d.wants_tamsd(),
            _ => false,
        })
    }

    /// The RFM tables this campaign has (raw and summaries), by the observables it records.
    pub fn rfm_tables(&self) -> Vec<&'static str> {
        use crate::manifest::rfm::RfmObservable as O;
        use crate::store::tables as t;
        let wants = |o: O| {
            self.plan.points.iter().any(|p| match &p.params {
                crate::plan::ModelParams::Rfm(r) => r.wants(o),
                _ => false,
            })
        };
        let mut v = vec![
            t::RFM_TIMESERIES,
            t::RFM_TIMESERIES_SUMMARY,
            t::RFM_TEMPERATURE_BLOCKS,
        ];
        if wants(O::Snapshot) {
            v.push(t::RFM_SNAPSHOTS);
        }
        if wants(O::VelocityMoments) {
            v.extend([t::RFM_MOMENTS, t::RFM_MOMENTS_SUMMARY]);
        }
        if wants(O::VelocityHistogram)
            || wants(O::NeighbourDistances)
            || wants(O::FreePaths)
            || wants(O::PostCollisionVelocity)
        {
            v.extend([t::RFM_HISTOGRAMS, t::RFM_HISTOGRAMS_SUMMARY]);
        }
        if wants(O::NeighbourDistances) {
            v.extend([t::RFM_NEIGHBOUR_MOMENTS, t::RFM_NEIGHBOUR_MOMENTS_SUMMARY]);
        }
        if wants(O::StructureFactor) {
            v.extend([t::RFM_STRUCTURE_FACTOR, t::RFM_STRUCTURE_FACTOR_SUMMARY]);
        }
        if wants(O::RadialDistribution) {
            v.extend([t::RFM_RADIAL, t::RFM_RADIAL_SUMMARY]);
        }
        if wants(O::FreePaths) {
            v.extend([t::RFM_FREE_PATH_MOMENTS, t::RFM_FREE_PATH_MOMENTS_SUMMARY]);
        }
        v
    }

    pub fn checkpoint_dir(&self) -> PathBuf {
        self.root.join("checkpoints")
    }
}

/// Runtime options shared by `run` and `resume`.
#[derive(Clone)]
pub struct RunOptions {
    pub threads: usize,
    pub checkpoint_every: Duration,
    pub shard: Shard,
    /// 0 = run; >= 1 = checkpoint and stop (set by Ctrl-C / SIGTERM).
    pub interrupt: Arc<AtomicU8>,
    /// Flush finished runs to the tables at least this often.
    pub flush_every: Duration,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            threads: 0,
            checkpoint_every: Duration::from_secs(300),
            shard: Shard::ALL,
            interrupt: Arc::new(AtomicU8::new(0)),
            flush_every: Duration::from_secs(30),
        }
    }
}

/// What workers tell the dispatcher.
#[derive(Debug, Clone)]
pub enum Event {
    /// The shard's work: `pending` runs to do out of `total` in the shard.
    Plan {
        total: u64,
        already: u64,
        pending: u64,
    },
    Started {
        run_id: u64,
        resumed_from: Option<f64>,
    },
    Progress {
        run_id: u64,
        fraction: f64,
    },
    Checkpointed {
        run_id: u64,
        t: f64,
    },
    Finished {
        run_id: u64,
        seed: u64,
        status: RunStatus,
        reason: Option<String>,
        t: f64,
        wall_seconds: f64,
    },
    Interrupted {
        run_id: u64,
    },
    Committed {
        runs: usize,
        seq: u64,
    },
    Warning {
        message: String,
    },
}

/// Receives events (progress bar, logs); called on the dispatcher thread only.
pub trait Reporter {
    fn event(&mut self, e: &Event);
}

/// A reporter that ignores everything (tests, benchmarks).
pub struct Silent;
impl Reporter for Silent {
    fn event(&mut self, _e: &Event) {}
}

#[derive(Debug, Clone, Default, PartialEq)]
pub struct Outcome {
    pub done: u64,
    pub failed: u64,
    /// Failed runs of this shard, in this session or earlier ones.
    pub failed_in_shard: u64,
    pub remaining: u64,
    pub interrupted: bool,
    /// Every run of the campaign (all shards) is finished and the summaries are written.
    pub complete: bool,
}

/// Run (or continue) the pending runs of `opts.shard`.
pub fn run(
    c: &Campaign,
    opts: &RunOptions,
    reporter: &mut dyn Reporter,
) -> Result<Outcome, CampaignError> {
    let _lock = ShardLock::acquire(&c.root, opts.shard).map_err(CampaignError::Refused)?;
    let tag = opts.shard.tag();
    for note in ledger::recover(&c.root, &tag).map_err(CampaignError::Io)? {
        reporter.event(&Event::Warning { message: note });
    }
    let commits = ledger::read_commits(&c.root).map_err(CampaignError::Refused)?;
    let finished = ledger::finished_runs(&commits);
    let mine: Vec<RunSpec> = (0..c.plan.n_runs())
        .filter(|r| opts.shard.contains(*r))
        .map(|r| c.plan.run(r))
        .collect();
    let pending: Vec<RunSpec> = mine
        .iter()
        .filter(|r| !finished.contains_key(&r.run_id))
        .copied()
        .collect();
    reporter.event(&Event::Plan {
        total: mine.len() as u64,
        already: (mine.len() - pending.len()) as u64,
        pending: pending.len() as u64,
    });

    let ckpt_dir = c.checkpoint_dir();
    fsutil::create_dir_durable(&ckpt_dir).map_err(|e| io_err(&ckpt_dir, e))?;
    let mut writer = writer::Writer::new(c, &tag).map_err(|e| CampaignError::Io(e.to_string()))?;
    writer
        .ensure_points()
        .map_err(|e| CampaignError::Io(e.to_string()))?;
    writer
        .ensure_theory()
        .map_err(|e| CampaignError::Io(e.to_string()))?;

    let threads = if opts.threads == 0 {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
    } else {
        opts.threads
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("granular-worker-{i}"))
        .build()
        .map_err(|e| CampaignError::Io(format!("cannot start {threads} worker threads: {e}")))?;

    let (tx, rx) = std::sync::mpsc::channel::<(Event, Option<RunResult>)>();
    let mut outcome = Outcome::default();
    let mut fatal: Option<CampaignError> = None;
    let mut last_heartbeat = Instant::now() - Duration::from_secs(60);
    let mut running: std::collections::BTreeSet<u64> = Default::default();
    std::thread::scope(|scope| {
        let tx_workers = tx.clone();
        let pending = &pending;
        let pool = &pool;
        scope.spawn(move || {
            // A shared queue: each worker takes the next pending run in plan order.
            let next = std::sync::atomic::AtomicUsize::new(0);
            let next = &next;
            pool.scope(|s| {
                for _ in 0..threads {
                    let mut tx = tx_workers.clone();
                    s.spawn(move |_| loop {
                        let j = next.fetch_add(1, Ordering::SeqCst);
                        let Some(spec) = pending.get(j) else { break };
                        worker::run_one(c, spec, opts, &mut tx);
                    });
                }
            });
            drop(tx_workers);
        });
        drop(tx);
        loop {
            let msg = rx.recv_timeout(Duration::from_millis(200));
            match msg {
                Ok((event, result)) => {
                    match &event {
                        Event::Started { run_id, .. } => {
                            running.insert(*run_id);
                        }
                        Event::Finished { run_id, status, .. } => {
                            running.remove(run_id);
                            match status {
                                RunStatus::Done => outcome.done += 1,
                                RunStatus::Failed => outcome.failed += 1,
                            }
                        }
                        Event::Interrupted { run_id } => {
                            running.remove(run_id);
                            outcome.interrupted = true;
                        }
                        _ => {}
                    }
                    reporter.event(&event);
                    if let Some(r) = result {
                        if fatal.is_none() {
                            writer.add(r);
                        }
                    }
                }
                Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
                Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => break,
            }
            if fatal.is_none() && writer.due(opts.flush_every) {
                match writer.flush() {
                    Ok(Some((runs, seq))) => reporter.event(&Event::Committed { runs, seq }),
                    Ok(None) => {}
                    Err(e) => {
                        // Stop the workers (they checkpoint); nothing of this batch is committed.
                        opts.interrupt.fetch_max(1, Ordering::SeqCst);
                        fatal = Some(CampaignError::Io(format!("writing the tables failed: {e}")));
                    }
                }
            }
            if last_heartbeat.elapsed() > Duration::from_secs(2) {
                last_heartbeat = Instant::now();
                let _ = status::write_heartbeat(&c.root, &tag, &running);
            }
        }
    });
    if let Some(e) = fatal {
        return Err(e);
    }
    match writer.flush() {
        Ok(Some((runs, seq))) => reporter.event(&Event::Committed { runs, seq }),
        Ok(None) => {}
        Err(e) => return Err(CampaignError::Io(format!("writing the tables failed: {e}"))),
    }
    status::remove_heartbeat(&c.root, &tag);
    if opts.interrupt.load(Ordering::SeqCst) > 0 {
        outcome.interrupted = true;
    }
    let commits = ledger::read_commits(&c.root).map_err(CampaignError::Refused)?;
    let finished = ledger::finished_runs(&commits);
    outcome.remaining = mine
        .iter()
        .filter(|r| !finished.contains_key(&r.run_id))
        .count() as u64;
    outcome.failed_in_shard = mine
        .iter()
        .filter(|r| finished.get(&r.run_id) == Some(&RunStatus::Failed))
        .count() as u64;
    if outcome.remaining == 0 {
        outcome.interrupted = false;
    }
    if finished.len() as u64 == c.plan.n_runs() {
        crate::store::summary::write_summaries(c, &finished)
            .map_err(|e| CampaignError::Io(e.to_string()))?;
        outcome.complete = true;
    }
    Ok(outcome)
}

/// Run a single run to completion in memory, without a campaign directory (tests, benches).
pub fn run_in_memory(
    params: &crate::plan::ModelParams,
    seed: u64,
) -> Result<crate::engine::RunOutput, crate::dsmc::PhysicsError> {
    let mut e = crate::engine::Engine::start(params, seed)
        .map_err(|reason| crate::dsmc::PhysicsError { t: 0.0, reason })?;
    while !e.advance(u64::MAX)? {}
    Ok(e.finish())
}

impl RunResult {
    pub fn is_final(&self) -> bool {
        matches!(self.end, RunEnd::Done(_) | RunEnd::Failed { .. })
    }
}
