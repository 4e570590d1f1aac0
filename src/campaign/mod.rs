//! The campaign engine, the same for every model: a campaign directory, its frozen manifest
//! and plan ([`Campaign`]), the events between workers and the dispatcher, and the pieces that
//! [`dispatch::run`] drives (plan, ledger, worker, writer, status, slurm, compact, verify).
//!
//! Directory layout:
//! ```text
//! <out>/campaign.json            format, code version, latest manifest, registry of points and runs
//! <out>/manifest.json            the latest manifest as given
//! <out>/manifests/<k>.json       every accepted manifest, as given (history in campaign.json)
//! <out>/finals/run-*.final       final states of finished runs that can be continued
//! <out>/locks/<shard>.lock       who runs a shard (pid, host); <shard>.running.json heartbeat
//! <out>/ledger/<shard>/commit-*.json   finished runs and their table parts (see ledger)
//! <out>/checkpoints/run-*.ckpt   running simulations
//! <out>/tables/<table>/*.parquet one dataset per table
//! <out>/sums/<table>/*.sum.json  size and SHA-256 of the table files written whole
//! <out>/quarantine/<time>-<pid>/ what healing set aside (see integrity), with actions.log
//! ```

pub mod compact;
pub mod derived_tables;
pub mod dispatch;
pub mod error;
pub mod history;
pub mod integrity;
pub mod ledger;
pub mod plan;
pub mod preview;
pub mod registry;
pub mod resources;
pub mod rounds;
pub mod slurm;
pub mod status;
pub mod tables;
pub mod targets;
pub mod upgrade;
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

use crate::analysis::{Analysis, AnalysisError, Options, Report as AnalysisReport};
use crate::fsutil;
use crate::manifest::validate::ManifestErrors;
use crate::manifest::Manifest;
use crate::models::{CampaignView, ModelKind, ModelParams, PointView};
use crate::rng::StreamVersion;
use crate::store::dataset::Dataset;
use crate::store::parquet_io::Stamp;
use crate::store::FORMAT_VERSION;
use crate::CODE_VERSION;
pub use error::CampaignError;
use ledger::RunStatus;
use ledger::{ExclusiveLock, LockError, Purpose};
use plan::{canonical, Plan, Shard};
use registry::{Asked, Growth, Registry};

/// `campaign.json`: what makes a directory a campaign, written atomically; its registry
/// changes only when a grown manifest is accepted.
#[derive(Serialize, Deserialize, Clone, Debug)]
pub struct CampaignInfo {
    pub format_version: u32,
    pub code_version: String,
    pub name: String,
    pub n_runs: u64,
    /// The latest accepted manifest.
    pub manifest: Value,
    /// Every point and run (format 2; absent in format 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub registry: Option<Registry>,
    /// Every accepted manifest (the latest last).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub history: Vec<history::Accepted>,
    /// The rounds of a campaign with error targets (`targets`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rounds: Option<targets::Rounds>,
    /// How the campaign's runs draw their random numbers, fixed when it is created (absent:
    /// a campaign made before stream versions were recorded, version 1).
    #[serde(default)]
    pub stream_version: StreamVersion,
}

/// The format version of `campaign.json` of a campaign whose random stream is not version 1
/// (the tables and everything else are of [`FORMAT_VERSION`]). A granular that predates
/// stream versions ignores the `stream_version` field; it refuses this format instead of
/// continuing such a campaign on stream version 1.
pub const STREAMS_FORMAT: u32 = FORMAT_VERSION + 1;

/// The format version of `campaign.json` of a campaign of random stream `stream`:
/// [`FORMAT_VERSION`] for version 1 (what every granular of that format reads),
/// [`STREAMS_FORMAT`] for another.
pub fn info_format(stream: StreamVersion) -> u32 {
    if stream == StreamVersion::V1 {
        FORMAT_VERSION
    } else {
        STREAMS_FORMAT
    }
}

/// The formats of `campaign.json` that this granular reads as they are.
pub fn is_current_format(format_version: u32) -> bool {
    format_version == FORMAT_VERSION || format_version == STREAMS_FORMAT
}

impl From<LockError> for CampaignError {
    fn from(e: LockError) -> Self {
        match e {
            LockError::Held(m) => CampaignError::Refused(m),
            LockError::Io(m) => CampaignError::Io(m),
        }
    }
}

impl CampaignInfo {
    /// `root/campaign.json`, of any format version; a missing or unreadable one is refused as
    /// "not a campaign directory", a corrupt one as such.
    pub fn read(root: &Path) -> Result<CampaignInfo, CampaignError> {
        let info_path = root.join("campaign.json");
        let text = fsutil::read_inside(root, "campaign.json").map_err(|e| {
            CampaignError::Refused(if e.kind() == std::io::ErrorKind::NotFound {
                format!(
                    "{}: not a granular campaign directory (no campaign.json in it): give the \
                     directory that `granular run MANIFEST --out DIR` wrote",
                    root.display()
                )
            } else {
                format!(
                    "{}: not a readable granular campaign directory ({e})",
                    root.display()
                )
            })
        })?;
        let corrupt = |e: serde_json::Error| {
            CampaignError::Refused(format!(
                "{}: corrupt or foreign file: {e}; restore it from a backup (`granular verify DIR` checks the tables), or start over in another --out",
                info_path.display()
            ))
        };
        let value: Value = serde_json::from_str(&text).map_err(corrupt)?;
        // A stream version this granular does not know is said as such (a newer granular
        // made the campaign), not as a corrupt file.
        if let Some(v) = value.get("stream_version") {
            if StreamVersion::deserialize(v).is_err() {
                let newer = v
                    .as_u64()
                    .filter(|&n| n > u64::from(StreamVersion::CURRENT.number()));
                return Err(CampaignError::Refused(match newer {
                    Some(n) => format!(
                        "{}: stream_version: {}; continue it with that granular",
                        info_path.display(),
                        crate::rng::UnknownStreamVersion(n.min(u32::MAX as u64) as u32)
                    ),
                    None => format!(
                        "{}: stream_version: expected a random stream version (a number from 1 to {}), found {v}",
                        info_path.display(),
                        StreamVersion::CURRENT.number()
                    ),
                }));
            }
        }
        serde_json::from_value(value).map_err(corrupt)
    }
}

/// The directory of a campaign where `granular analyze` writes by default (its tables
/// `*.parquet` and `figures/`): [`Campaign::analysis_dir`].
pub const ANALYSIS_DIR: &str = "analysis";

/// An opened campaign directory.
pub struct Campaign {
    pub root: PathBuf,
    /// The latest accepted manifest.
    pub manifest: Manifest,
    pub plan: Plan,
    /// Canonical JSON of the latest manifest (in the metadata of the table files written).
    pub manifest_json: String,
    /// The campaign's identity (name, model, seed as canonical JSON), in every table file.
    pub identity: String,
    /// Every accepted manifest.
    pub history: Vec<history::Accepted>,
    /// The rounds decided (error targets; empty otherwise).
    pub rounds: targets::Rounds,
    /// How its runs draw their random numbers (recorded when it was created, never changed).
    pub stream: StreamVersion,
}

/// `--out` must be a directory or not exist: a regular file, a dangling symbolic link or a
/// path through a file is "not a campaign directory" (refused, exit 3), not an I/O failure.
fn refuse_non_directory(out: &Path) -> Result<(), CampaignError> {
    let refuse = |what: String| {
        Err(CampaignError::Refused(format!(
            "{} {what}: not a campaign directory; refusing to write there (use another --out)",
            out.display()
        )))
    };
    match std::fs::symlink_metadata(out) {
        Ok(link) => match std::fs::metadata(out) {
            Ok(m) if m.is_dir() => Ok(()),
            Ok(_) => refuse("exists and is not a directory".into()),
            Err(_) if link.file_type().is_symlink() => refuse(format!(
                "is a symbolic link to {}, which does not exist",
                std::fs::read_link(out)
                    .map(|t| t.display().to_string())
                    .unwrap_or_else(|_| "?".into())
            )),
            Err(e) => refuse(format!("cannot be read ({e})")),
        },
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) if e.raw_os_error() == Some(libc::ENOTDIR) => {
            refuse("lies below a file that is not a directory".into())
        }
        Err(_) => Ok(()),
    }
}

/// A directory that is not a campaign must be empty (or hold only `allowed`: the lock a
/// process creating the campaign has just taken) to become one.
fn refuse_non_empty(out: &Path, allowed: &[&str]) -> Result<(), CampaignError> {
    let entries = match std::fs::read_dir(out) {
        Ok(it) => it,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(io_err(out, e)),
    };
    for e in entries {
        let e = e.map_err(|e| io_err(out, e))?;
        if !allowed.iter().any(|a| e.file_name() == **a) {
            return Err(CampaignError::Refused(format!(
                "{} exists and is not a granular campaign directory (no campaign.json); refusing to write into it: give a new or empty directory with --out",
                out.display()
            )));
        }
    }
    Ok(())
}

/// Pauses for tests of races: `GRANULAR_TEST_PAUSE=<point>:<file>` makes a process that
/// first reaches `<point>` create `<file>` and wait (up to a minute) until the test removes it, so
/// that a test holds one process at a known moment (holding a lock, say) while it starts
/// another. Without the variable nothing happens (one environment lookup).
pub mod test_hook {
    pub fn pause(point: &str) {
        let Some(spec) = std::env::var_os("GRANULAR_TEST_PAUSE") else {
            return;
        };
        let spec = spec.to_string_lossy();
        let Some((at, file)) = spec.split_once(':') else {
            return;
        };
        // Once per process: the first time the point is reached.
        static FIRED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
        if at != point || FIRED.swap(true, std::sync::atomic::Ordering::SeqCst) {
            return;
        }
        let file = std::path::Path::new(file);
        if std::fs::write(file, std::process::id().to_string()).is_err() {
            return;
        }
        let start = std::time::Instant::now();
        while file.exists() && start.elapsed() < std::time::Duration::from_secs(60) {
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
    }
}

pub(crate) fn io_err(p: &Path, e: impl std::fmt::Display) -> CampaignError {
    CampaignError::Io(format!("{}: {e}", p.display()))
}

impl Campaign {
    /// Validate `manifest_path` and create `out` for it, or open `out` and accept the manifest
    /// as the campaign's latest: a grown one registers its new points and runs (see
    /// `registry`); a different campaign (name, model or seed), a shorter run, or growth while
    /// a shard runs is refused. Nothing is written for a bad manifest or a refusal.
    pub fn create_or_open(manifest_path: &Path, out: &Path) -> Result<Campaign, CampaignError> {
        Self::prepare(manifest_path, out, true).map(|(c, _)| c)
    }

    /// As `create_or_open`; with `apply` false nothing is written (what would be: the
    /// campaign as it would be, and what the manifest adds).
    ///
    /// A manifest that changes the campaign (a new campaign, growth) is accepted under the
    /// campaign's exclusive lock, on `campaign.json` as read under it: of two processes that
    /// grow a campaign at once, the second sees the first's registry (or is refused while the
    /// first holds the lock), never overwrites it. A manifest equal to the campaign's latest
    /// changes nothing and takes no lock (the shards of a campaign start side by side).
    pub fn prepare(
        manifest_path: &Path,
        out: &Path,
        apply: bool,
    ) -> Result<(Campaign, Growth), CampaignError> {
        // One (bounded) reading of the file: what is validated is what is recorded.
        let text = crate::manifest::validate::read(manifest_path)?;
        let (manifest, fresh) = plan::parse(&text, &manifest_path.display().to_string())?;
        let text = text.into_bytes();
        if let Some(mem) = resources::Memory::of_this_machine() {
            resources::check(&fresh, mem)?;
        }
        refuse_non_directory(out)?;
        if out.join("campaign.json").exists() {
            let existing = Self::open(out)?;
            if !apply {
                return existing.accept(manifest, &text, false);
            }
            let asked = canonical(&serde_json::to_value(&manifest).expect("serialises"));
            if existing.manifest_json == asked {
                existing.refuse_other_identity(&manifest)?;
                return Ok((existing, Growth::default()));
            }
            // What would be refused is refused before anything (the lock) is written; the
            // growth is computed again under the lock, on the campaign as it is then.
            existing.accept(manifest.clone(), &text, false)?;
            test_hook::pause("accept-read");
        } else {
            refuse_non_empty(out, &[])?;
            if !apply {
                let growth = everything(&fresh);
                return Ok((Self::new_campaign(out, manifest, fresh), growth));
            }
            fsutil::create_dir_durable(out).map_err(|e| io_err(out, e))?;
        }
        // Under the lock, on what is on disk now.
        let _lock = ExclusiveLock::acquire(out, Purpose::Growth)
            .map_err(|e| e.context("cannot change the campaign"))?;
        test_hook::pause("accept-locked");
        if out.join("campaign.json").exists() {
            return Self::open(out)?.accept(manifest, &text, true);
        }
        // A new campaign: the directory holds nothing but the lock just taken.
        refuse_non_empty(out, &["locks"])?;
        let growth = everything(&fresh);
        let mut c = Self::new_campaign(out, manifest, fresh);
        c.record(&text, growth.new_runs.len() as u64)?;
        Ok((c, growth))
    }

    fn new_campaign(out: &Path, manifest: Manifest, plan: Plan) -> Campaign {
        Campaign {
            root: out.to_path_buf(),
            manifest_json: canonical(&serde_json::to_value(&manifest).expect("serialises")),
            identity: manifest.identity(),
            manifest,
            plan,
            history: Vec::new(),
            rounds: targets::Rounds::default(),
            stream: StreamVersion::CURRENT,
        }
    }

    /// A manifest of another campaign (name, model or seed) is refused.
    fn refuse_other_identity(&self, manifest: &Manifest) -> Result<(), CampaignError> {
        let differs = history::identity_differences(&self.manifest, manifest);
        if differs.is_empty() {
            return Ok(());
        }
        Err(CampaignError::Refused(format!(
            "{} holds another campaign: {}; a campaign keeps its name, model and seed (use another --out)",
            self.root.display(),
            differs.join(", ")
        )))
    }

    /// Accept `manifest` as this campaign's latest (see `create_or_open`); with `apply` the
    /// caller holds the exclusive lock and `self` was opened under it.
    fn accept(
        mut self,
        manifest: Manifest,
        text: &[u8],
        apply: bool,
    ) -> Result<(Campaign, Growth), CampaignError> {
        self.refuse_other_identity(&manifest)?;
        let value = serde_json::to_value(&manifest).expect("manifest serialises");
        if canonical(&value) == self.manifest_json {
            if apply {
                self.repair_manifest_copy();
            }
            return Ok((self, Growth::default()));
        }
        let expansion = plan::expand(&manifest)
            .map_err(|errs| CampaignError::Manifest(ManifestErrors::of_pairs("manifest", errs)))?;
        let mut registry = self.plan.registry.clone();
        let runs = manifest.runs_per_point();
        let old_plan = &self.plan;
        let growth = registry
            .grow(
                &Asked {
                    model: manifest.model,
                    points: &expansion.points,
                    runs: &runs,
                },
                &|b, r| old_plan.seed(b, r),
            )
            .map_err(|errs| CampaignError::Refused(errs.join("; ")))?;
        let mut plan = Plan::new(&manifest, expansion, registry)?;
        plan.decided = self.rounds.replicas.clone();
        self.refuse_missing_columns(&plan, &growth)?;
        self.plan = plan;
        self.manifest = manifest;
        self.manifest_json = canonical(&value);
        if apply {
            self.record(text, growth.new_runs.len() as u64)?;
        }
        Ok((self, growth))
    }

    /// The new points' runs would fill columns (`Model::valued_columns`) that this campaign's
    /// tables, written by an earlier granular, do not have: refused before anything is
    /// written, every such column named (`store::schema` keeps one schema per table).
    fn refuse_missing_columns(&self, plan: &Plan, growth: &Growth) -> Result<(), CampaignError> {
        let data = self.data();
        let mut lacking: BTreeMap<(&str, &str), Vec<u32>> = BTreeMap::new();
        let mut schemas = BTreeMap::new();
        for &id in &growth.new_points {
            // `plan.points` is indexed by point_id.
            let Some(point) = plan.points.get(id as usize).filter(|p| p.point_id == id) else {
                continue;
            };
            for (table, column) in point.params.valued_columns() {
                if !schemas.contains_key(table) {
                    let files = data
                        .files(table)
                        .map_err(|e| CampaignError::Io(e.to_string()))?;
                    schemas.insert(table, crate::store::schema::table_schema(&files));
                }
                if let Some(Some(s)) = schemas.get(table) {
                    if s.index_of(column).is_err() {
                        lacking.entry((table, column)).or_default().push(id);
                    }
                }
            }
        }
        if lacking.is_empty() {
            return Ok(());
        }
        let what: Vec<String> = lacking
            .iter()
            .map(|((t, c), points)| {
                format!(
                    "the runs of point(s) {points:?} fill column {c:?} of table {t}, which this campaign's table (written by an earlier granular) does not have"
                )
            })
            .collect();
        Err(CampaignError::Refused(format!(
            "{}: {}; a table keeps its columns, so record these points in a new campaign (another --out)",
            self.root.display(),
            what.join("; ")
        )))
    }

    /// Write the accepted manifest into the history and campaign.json (the commit point: it
    /// alone makes the directory a campaign and holds the registry), then manifest.json.
    fn record(&mut self, text: &[u8], runs_added: u64) -> Result<(), CampaignError> {
        let entry = history::write(&self.root, self.history.len(), text, runs_added)?;
        self.history.push(entry);
        if let Err(e) = self.write_info() {
            self.history.pop();
            return Err(e);
        }
        fsutil::write_atomic(&self.root.join("manifest.json"), text)
            .map_err(|e| io_err(&self.root, e))
    }

    /// Write `campaign.json` (atomically: the commit point of the registry, the history and
    /// the rounds) from this campaign as it is in memory. The caller holds the exclusive lock.
    pub(crate) fn write_info(&self) -> Result<(), CampaignError> {
        let info = CampaignInfo {
            format_version: info_format(self.stream),
            code_version: CODE_VERSION.into(),
            name: self.manifest.name.clone(),
            n_runs: self.plan.n_runs(),
            manifest: serde_json::to_value(&self.manifest).expect("manifest serialises"),
            registry: Some(self.plan.registry.clone()),
            history: self.history.clone(),
            rounds: (self.rounds != targets::Rounds::default()).then(|| self.rounds.clone()),
            stream_version: self.stream,
        };
        let info_path = self.root.join("campaign.json");
        let bytes = serde_json::to_vec_pretty(&info).expect("info serialises");
        fsutil::write_atomic(&info_path, &bytes).map_err(|e| io_err(&info_path, e))
    }

    /// `manifest.json` is written after campaign.json: a crash between the two leaves the
    /// previous manifest there. Rewrite it from the history's latest entry if it differs
    /// (best effort: it is a copy for people, nothing reads it).
    pub(crate) fn repair_manifest_copy(&self) {
        let Some(latest) = self.history.last() else {
            return;
        };
        let copy = self.root.join("manifest.json");
        if let Ok(text) = std::fs::read(self.root.join(&latest.file)) {
            if std::fs::read(&copy).ok().as_deref() != Some(text.as_slice()) {
                let _ = fsutil::write_atomic(&copy, &text);
            }
        }
    }

    /// Open an existing campaign directory.
    pub fn open(root: &Path) -> Result<Campaign, CampaignError> {
        let info_path = root.join("campaign.json");
        let info = CampaignInfo::read(root)?;
        if info.format_version < FORMAT_VERSION {
            return Err(CampaignError::Refused(format!(
                "{}: a campaign directory of format version {} (an earlier granular); upgrade it in place with `granular upgrade {}`",
                root.display(),
                info.format_version,
                root.display()
            )));
        }
        if !is_current_format(info.format_version) {
            return Err(CampaignError::Refused(format!(
                "{}: format version {}, this granular reads {FORMAT_VERSION} and {STREAMS_FORMAT}: use the (newer) granular that wrote it",
                info_path.display(),
                info.format_version
            )));
        }
        if info.code_version != CODE_VERSION {
            tracing::warn!(was = %info.code_version, now = CODE_VERSION, "campaign was started by another code version");
        }
        let corrupt = |why: String| {
            CampaignError::Refused(format!(
                "{}: corrupt campaign file: {why}; restore it from a backup, or start over in another --out",
                info_path.display()
            ))
        };
        if info.format_version != info_format(info.stream_version) {
            return Err(corrupt(format!(
                "format version {} with random stream version {} (a campaign of stream version {} is of format {})",
                info.format_version,
                info.stream_version.number(),
                info.stream_version.number(),
                info_format(info.stream_version)
            )));
        }
        let registry = info
            .registry
            .ok_or_else(|| corrupt("no registry of points and runs".into()))?;
        let manifest_text = serde_json::to_string(&info.manifest).expect("value serialises");
        let file = info_path.display().to_string();
        let manifest = crate::manifest::validate::parse(&manifest_text, &file)?;
        let expansion = plan::expand(&manifest).map_err(|e| corrupt(format!("{e:?}")))?;
        let mut plan =
            Plan::new(&manifest, expansion, registry).map_err(|e| corrupt(e.to_string()))?;
        let rounds = info.rounds.unwrap_or_default();
        if rounds != targets::Rounds::default() && rounds.format != targets::ROUNDS_FORMAT {
            return Err(corrupt(format!(
                "rounds of format {}, this granular reads {}",
                rounds.format,
                targets::ROUNDS_FORMAT
            )));
        }
        plan.decided = rounds.replicas.clone();
        Ok(Campaign {
            rounds,
            root: root.to_path_buf(),
            identity: manifest.identity(),
            manifest,
            plan,
            manifest_json: canonical(&info.manifest),
            history: info.history,
            stream: info.stream_version,
        })
    }

    /// The stamp of the table files this campaign writes.
    pub fn stamp(&self) -> Stamp<'_> {
        Stamp {
            campaign: &self.identity,
            manifest: &self.manifest_json,
            commit: None,
        }
    }

    /// The campaign's tables.
    pub fn data(&self) -> Dataset {
        Dataset::new(&self.root, &self.identity, &self.manifest_json)
    }

    /// The campaign as its model sees it for summaries and figures: the points of the latest
    /// manifest, the runs it asks for per point; `done` maps the runs finished with status
    /// done to their replica numbers in the latest manifest ([`Campaign::done_replicas`]).
    pub fn view<'a>(
        &'a self,
        data: &'a Dataset,
        done: &'a BTreeMap<u64, u32>,
    ) -> CampaignView<'a, ModelParams> {
        self.view_of(data, done, true)
    }

    /// As [`Campaign::view`], with every registered point (the kinetic-theory tables have a
    /// prediction for every point, in the manifest or not).
    fn view_of<'a>(
        &'a self,
        data: &'a Dataset,
        done: &'a BTreeMap<u64, u32>,
        current_only: bool,
    ) -> CampaignView<'a, ModelParams> {
        let mut runs_done: BTreeMap<u32, u32> = BTreeMap::new();
        for r in done.keys() {
            *runs_done.entry(self.plan.run(*r).point_id).or_default() += 1;
        }
        let labels = self.labels();
        CampaignView {
            name: &self.manifest.name,
            points: self
                .plan
                .points
                .iter()
                .filter(|p| p.current || !current_only)
                .map(|p| {
                    let swept: Vec<(&str, &Value)> = self
                        .plan
                        .sweep_keys
                        .iter()
                        .map(String::as_str)
                        .zip(&p.values)
                        .collect();
                    PointView {
                        point_id: p.point_id,
                        params: &p.params,
                        label: labels.point_label(&swept),
                        swept,
                        runs_done: runs_done.get(&p.point_id).copied().unwrap_or(0),
                    }
                })
                .collect(),
            replicas: self.plan.runs_asked_per_point(),
            labels,
            done,
            data,
            sweep: tables::sweep_batch(&self.plan),
        }
    }

    /// The names on the figures: the latest manifest's `labels` over the model's physics
    /// names ([`crate::models::Labels`]).
    pub fn labels(&self) -> crate::models::Labels {
        crate::models::Labels::new(
            self.manifest.labels.clone(),
            self.plan.model.physics_names(),
        )
    }

    /// Every table of the campaign (the model's and `runs`, `points`).
    pub fn tables(&self) -> Vec<&'static str> {
        tables_of(&self.manifest, &self.plan)
    }

    /// One line on what a row of the table `name` is and what it holds: the campaign's own
    /// (`tables::description`), else the model's (`ModelKind::table_description`).
    pub fn table_description(&self, name: &str) -> Option<&'static str> {
        table_description(self.plan.model, name)
    }

    /// The manifest's derived quantities, compiled against the model's run tables (none
    /// without `derived`; the manifest was checked, so they compile).
    pub fn derived(&self) -> crate::derived::Quantities {
        crate::derived::compile(&self.manifest.derived, &self.plan.model.run_tables())
            .unwrap_or_default()
    }

    /// Write the derived quantities' tables (`derived`, `derived_summary`) of the view's
    /// runs, if the manifest declares any.
    fn write_derived(
        &self,
        view: &CampaignView<'_, ModelParams>,
    ) -> Result<(), crate::store::parquet_io::StoreError> {
        let q = self.derived();
        if q.is_empty() {
            return Ok(());
        }
        derived_tables::write(view, &q, &|r| self.plan.run(r).point_id)
    }

    /// The model's figures followed by those of the derived quantities.
    fn with_derived_figures(
        &self,
        view: &CampaignView<'_, ModelParams>,
        model: Option<Vec<(String, crate::plot::Figure)>>,
    ) -> Result<Option<Vec<(String, crate::plot::Figure)>>, crate::store::parquet_io::StoreError>
    {
        let q = self.derived();
        if q.is_empty() {
            return Ok(model);
        }
        let mut figs = model.unwrap_or_default();
        figs.extend(derived_tables::figures(view, &q)?);
        Ok(Some(figs))
    }

    /// Write the replica summaries of the runs finished so far.
    pub fn write_summaries(
        &self,
        finished: &BTreeMap<u64, RunStatus>,
    ) -> Result<(), crate::store::parquet_io::StoreError> {
        let done = self.done_replicas(finished);
        let data = self.data();
        let view = self.view(&data, &done);
        self.plan.model.write_summaries(&view)?;
        self.write_derived(&view)
    }

    /// The runs of the latest manifest finished with status done, with their replica numbers
    /// in it (`Plan::manifest_replica`): what a summary is of. Runs the latest manifest no
    /// longer asks for (fewer replicas, other seeds, points it no longer lists) keep their
    /// rows in the raw tables but are in no summary, so a summary equals that of a campaign
    /// started from the latest manifest.
    pub fn done_replicas(&self, finished: &BTreeMap<u64, RunStatus>) -> BTreeMap<u64, u32> {
        finished
            .iter()
            .filter(|(_, s)| **s == RunStatus::Done)
            .filter(|(r, _)| **r < self.plan.n_runs())
            .filter_map(|(r, _)| Some((*r, self.plan.manifest_replica(&self.plan.run(*r))?)))
            .collect()
    }

    /// The model's kinetic-theory tables (none for models without theory).
    pub fn theory_tables(&self) -> Vec<&'static str> {
        self.plan.theory_tables()
    }

    /// Write the kinetic-theory tables that do not exist yet.
    pub fn write_theory(&self) -> Result<(), crate::store::parquet_io::StoreError> {
        let data = self.data();
        let none = BTreeMap::new();
        self.plan
            .model
            .write_theory(&self.view_of(&data, &none, false))
    }

    /// The model's standard figures from the summary tables (and, for figures drawn from raw
    /// tables, the rows of the latest manifest's finished runs); `Ok(None)` if it has none.
    pub fn figures(
        &self,
    ) -> Result<Option<Vec<(String, crate::plot::Figure)>>, crate::store::parquet_io::StoreError>
    {
        let data = self.data();
        let ledger = ledger::read_ledger(&self.root).map_err(|e| {
            crate::store::parquet_io::StoreError::Corrupt(
                self.root.display().to_string(),
                e.to_string(),
            )
        })?;
        let finished = ledger::finished_runs(&ledger.commits);
        let done = self.done_replicas(&finished);
        let view = self.view(&data, &done);
        let figs = self.plan.model.figures(&view)?;
        let figs = self.with_derived_figures(&view, figs)?;
        Ok(self.with_target_figures(&finished, figs))
    }

    /// The model's figures of the runs finished so far (`finished`, from the ledger): the
    /// model's summaries are computed into a scratch directory under the system's temporary
    /// directory (removed afterwards) and the figures drawn from them, so nothing is written
    /// into the campaign. What the report shows of a campaign not finished yet.
    pub fn figures_so_far(
        &self,
        finished: &BTreeMap<u64, RunStatus>,
    ) -> Result<Option<Vec<(String, crate::plot::Figure)>>, crate::store::parquet_io::StoreError>
    {
        struct Scratch(PathBuf);
        impl Drop for Scratch {
            fn drop(&mut self) {
                let _ = std::fs::remove_dir_all(&self.0);
            }
        }
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0);
        let scratch = Scratch(
            std::env::temp_dir().join(format!("granular-summaries-{}-{nanos}", std::process::id())),
        );
        let done = self.done_replicas(finished);
        let data = self.data().overlay(&scratch.0);
        let view = self.view(&data, &done);
        self.plan.model.write_summaries(&view)?;
        self.write_derived(&view)?;
        let figs = self.plan.model.figures(&view)?;
        let figs = self.with_derived_figures(&view, figs)?;
        Ok(self.with_target_figures(finished, figs))
    }

    /// The figures followed by those of the error targets ([`targets::figures`]).
    fn with_target_figures(
        &self,
        finished: &BTreeMap<u64, RunStatus>,
        figs: Option<Vec<(String, crate::plot::Figure)>>,
    ) -> Option<Vec<(String, crate::plot::Figure)>> {
        let t = targets::figures(self, finished);
        if t.is_empty() {
            return figs;
        }
        let mut figs = figs.unwrap_or_default();
        figs.extend(t);
        Some(figs)
    }

    /// `granular analyze`: the model's analysis ([`crate::models::Model::analyze`]) of the
    /// runs of the latest manifest finished so far (as [`Campaign::figures`] sees them),
    /// written into `out` ([`Analysis::write`]). Refused for a model without analysis.
    pub fn analyze(&self, out: &Path, opts: &Options) -> Result<AnalysisReport, AnalysisError> {
        let data = self.data();
        let ledger = ledger::read_ledger(&self.root).map_err(|e| {
            crate::store::parquet_io::StoreError::Corrupt(
                self.root.display().to_string(),
                e.to_string(),
            )
        })?;
        let done = self.done_replicas(&ledger::finished_runs(&ledger.commits));
        let total = self.plan.current_runs().count() as u64;
        let mut a = Analysis::new(&self.manifest.name, opts, done.len() as u64, total);
        match self.plan.model.analyze(&self.view(&data, &done), &mut a) {
            None => Err(AnalysisError::NotAnalysable(format!(
                "campaign {:?} is of model {}, which has no analysis; `granular analyze` \
                 analyses campaigns of the models {}",
                self.manifest.name,
                self.manifest.model.as_str(),
                ModelKind::ALL
                    .iter()
                    .filter(|k| k.has_analysis())
                    .map(|k| k.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ))),
            Some(r) => {
                r?;
                a.write(out, self.stamp())
            }
        }
    }

    /// `DIR/analysis`: where `granular analyze` writes its tables and `figures/` by default,
    /// and where the report looks for them.
    pub fn analysis_dir(&self) -> PathBuf {
        self.root.join(ANALYSIS_DIR)
    }

    pub fn checkpoint_dir(&self) -> PathBuf {
        self.root.join("checkpoints")
    }

    /// Final states of finished runs (what a longer run of their point continues from).
    pub fn finals_dir(&self) -> PathBuf {
        self.root.join("finals")
    }
}

/// A new campaign's growth: every point and run.
fn everything(plan: &Plan) -> Growth {
    Growth {
        new_points: plan.points.iter().map(|p| p.point_id).collect(),
        new_runs: (0..plan.n_runs())
            .map(|r| {
                let s = plan.run(r);
                (s.point_id, s.replica, r)
            })
            .collect(),
        ..Growth::default()
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
    /// Keep each finished run's final state (`finals/`), so that a longer run continues it.
    pub keep_final_states: bool,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            threads: 0,
            checkpoint_every: Duration::from_secs(300),
            shard: Shard::ALL,
            interrupt: Arc::new(AtomicU8::new(0)),
            flush_every: Duration::from_secs(30),
            keep_final_states: true,
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
    /// A round of an error-target campaign decided (`targets`): what it added, or why the
    /// campaign ends.
    Round {
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

/// Every table a campaign of `manifest` with `plan` has ([`Campaign::tables`]).
pub fn tables_of(manifest: &Manifest, plan: &Plan) -> Vec<&'static str> {
    let points: Vec<&ModelParams> = plan.points.iter().map(|p| &p.params).collect();
    let mut t = vec![tables::RUNS, tables::POINTS, tables::REGISTERED_RUNS];
    t.extend(plan.model.tables(&points));
    if !manifest.derived.is_empty() {
        t.extend([derived_tables::DERIVED, derived_tables::DERIVED_SUMMARY]);
    }
    t
}

/// One line on what a row of the table `name` of a campaign of `model` is and what it holds:
/// the campaign's own (`tables::description`, `granular analyze`'s included), else the
/// model's (`ModelKind::table_description`).
pub fn table_description(model: ModelKind, name: &str) -> Option<&'static str> {
    tables::description(name).or_else(|| model.table_description(name))
}
