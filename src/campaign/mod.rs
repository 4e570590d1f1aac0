//! The campaign engine, the same for every model: a campaign directory, its frozen manifest
//! and plan ([`Campaign`]), the events between workers and the dispatcher, and the pieces that
//! [`dispatch::run`] drives (plan, ledger, worker, writer, status, slurm, compact, verify).
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
pub mod dispatch;
pub mod ledger;
pub mod plan;
pub mod resources;
pub mod slurm;
pub mod status;
pub mod tables;
pub mod verify;
pub mod worker;
pub mod writer;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicU8;
use std::sync::Arc;
use std::time::Duration;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::fsutil;
use crate::manifest::validate::ManifestErrors;
use crate::manifest::Manifest;
use crate::models::{CampaignView, ModelParams, PointView};
use crate::store::dataset::Dataset;
use crate::store::FORMAT_VERSION;
use crate::CODE_VERSION;
use ledger::RunStatus;
use plan::{canonical, Plan, Shard};

#[derive(Debug, thiserror::Error)]
pub enum CampaignError {
    #[error("{0}")]
    Manifest(#[from] ManifestErrors),
    /// The directory holds another campaign, is locked, or is not a campaign directory.
    #[error("{0}")]
    Refused(String),
    #[error("{0}")]
    Io(String),
    /// A run needs more of the machine than it has (refused before anything is written).
    #[error("{0}")]
    TooLarge(String),
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

pub(crate) fn io_err(p: &Path, e: impl std::fmt::Display) -> CampaignError {
    CampaignError::Io(format!("{}: {e}", p.display()))
}

impl Campaign {
    /// Validate `manifest_path` and create `out` for it, or open `out` if it already holds
    /// the same campaign (a different one is refused). Nothing is written for a bad manifest.
    pub fn create_or_open(manifest_path: &Path, out: &Path) -> Result<Campaign, CampaignError> {
        let (manifest, plan) = plan::load(manifest_path)?;
        if let Some(mem) = resources::Memory::of_this_machine() {
            resources::check(&plan, mem).map_err(CampaignError::TooLarge)?;
        }
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
        let (manifest, plan) = plan::parse(&text, &info_path.display().to_string())?;
        Ok(Campaign {
            root: root.to_path_buf(),
            manifest,
            plan,
            manifest_json: canonical(&info.manifest),
        })
    }

    /// The campaign's tables.
    pub fn data(&self) -> Dataset {
        Dataset::new(&self.root, &self.manifest_json)
    }

    /// The campaign as its model sees it; `done` maps the runs finished with status done to
    /// their replica numbers.
    pub fn view<'a>(
        &'a self,
        data: &'a Dataset,
        done: &'a BTreeMap<u64, u32>,
    ) -> CampaignView<'a, ModelParams> {
        CampaignView {
            name: &self.manifest.name,
            points: self
                .plan
                .points
                .iter()
                .map(|p| PointView {
                    point_id: p.point_id,
                    params: &p.params,
                    label: self.plan.label(p.point_id),
                })
                .collect(),
            replicas: self.plan.replicas,
            done,
            data,
        }
    }

    /// Every table of the campaign (the model's and `runs`, `points`).
    pub fn tables(&self) -> Vec<&'static str> {
        let points: Vec<&ModelParams> = self.plan.points.iter().map(|p| &p.params).collect();
        let mut t = vec![tables::RUNS, tables::POINTS];
        t.extend(self.plan.model.tables(&points));
        t
    }

    /// Write the replica summaries of the runs finished so far.
    pub fn write_summaries(
        &self,
        finished: &BTreeMap<u64, RunStatus>,
    ) -> Result<(), crate::store::parquet_io::StoreError> {
        let done: BTreeMap<u64, u32> = finished
            .iter()
            .filter(|(_, s)| **s == RunStatus::Done)
            .map(|(r, _)| (*r, self.plan.replica_of(*r)))
            .collect();
        let data = self.data();
        self.plan.model.write_summaries(&self.view(&data, &done))
    }

    /// The model's kinetic-theory tables (none for models without theory).
    pub fn theory_tables(&self) -> Vec<&'static str> {
        self.plan.theory_tables()
    }

    /// Write the kinetic-theory tables that do not exist yet.
    pub fn write_theory(&self) -> Result<(), crate::store::parquet_io::StoreError> {
        let data = self.data();
        let none = BTreeMap::new();
        self.plan.model.write_theory(&self.view(&data, &none))
    }

    /// The model's standard figures from the summary tables; `Ok(None)` if it has none.
    pub fn figures(
        &self,
    ) -> Result<Option<Vec<(String, crate::plot::Figure)>>, crate::store::parquet_io::StoreError>
    {
        let data = self.data();
        let none = BTreeMap::new();
        self.plan.model.figures(&self.view(&data, &none))
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
