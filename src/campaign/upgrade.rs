//! `granular upgrade DIR`: a campaign directory of an earlier format, upgraded in place to this
//! granular's, atomically, and logged in `upgrade.log`. Every other command refuses an older
//! directory and names this one.
//!
//! Format 1 -> 2 (no shard may run; half-done commits of stopped shards are recovered first):
//! 1. the registry of points and runs is built from the frozen manifest in sweep order
//!    (`run_id = point_id * replicas + replica`, as format 1 numbered them), every run keeping
//!    its seed of format 1 (`SeedSource::Swept`), so its checkpoints and rows stay its own;
//! 2. the `runs` table is rewritten in today's columns (without its sweep columns, with a null
//!    `continued_from`) into a new generation (same part names, so the commit records still
//!    name them; published by one rename of its link);
//! 3. the `points` table is rewritten with every point, the sweep columns and `in_manifest`;
//! 4. the frozen manifest becomes the first entry of the history (`manifests/0.json`);
//! 5. `campaign.json` of format 2 is written (the commit point: before it the directory is of
//!    format 1 and the upgrade can be run again; every step is idempotent).

use std::fs;
use std::path::Path;

use arrow_array::RecordBatch;

use super::history::{self, Accepted};
use super::ledger::{self, CompactLock};
use super::plan::{self, canonical, Plan};
use super::registry::{Registry, RunBlock, SeedSource};
use super::tables::{self, POINTS, RUNS};
use super::{io_err, CampaignError, CampaignInfo};
use crate::fsutil;
use crate::manifest::RunsPerPoint;
use crate::store::dataset::Dataset;
use crate::store::layout::{self, TableDir};
use crate::store::parquet_io::{self, Stamp};
use crate::store::FORMAT_VERSION;
use crate::CODE_VERSION;

/// What an upgrade did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct UpgradeReport {
    pub from: u32,
    pub to: u32,
    /// One line per step.
    pub steps: Vec<String>,
}

/// Upgrade the campaign directory `root` to this granular's format (nothing to do if it is).
pub fn upgrade(root: &Path) -> Result<UpgradeReport, CampaignError> {
    let info_path = root.join("campaign.json");
    let info = CampaignInfo::read(root)?;
    let mut report = UpgradeReport {
        from: info.format_version,
        to: FORMAT_VERSION,
        steps: Vec::new(),
    };
    match info.format_version {
        FORMAT_VERSION => return Ok(report),
        1 => {}
        v => {
            return Err(CampaignError::Refused(format!(
                "{}: format version {v}, which this granular ({FORMAT_VERSION}) cannot upgrade",
                info_path.display()
            )))
        }
    }
    let _lock = CompactLock::acquire(root)
        .map_err(|e| CampaignError::Refused(format!("cannot upgrade: {e}")))?;
    report
        .steps
        .extend(ledger::recover(root, ledger::COMPACT_TAG).map_err(CampaignError::Io)?);
    let manifest_text = serde_json::to_string(&info.manifest).expect("value serialises");
    let manifest =
        crate::manifest::validate::parse(&manifest_text, &info_path.display().to_string())?;
    let expansion = plan::expand(&manifest).map_err(|errs| {
        CampaignError::Refused(format!(
            "{}: frozen manifest: {errs:?}",
            info_path.display()
        ))
    })?;
    let registry = format1_registry(&manifest, &expansion);
    let n_runs = registry.n_runs();
    let keys = expansion.sweep_keys.clone();
    let plan = Plan::new(&manifest, expansion, registry).map_err(CampaignError::Refused)?;
    report.steps.push(format!(
        "registry: {} points, {n_runs} runs, each keeping its seed of format 1",
        plan.points.len()
    ));
    let manifest_json = canonical(&info.manifest);
    let identity = manifest.identity();
    let stamp = Stamp {
        campaign: &identity,
        manifest: &manifest_json,
    };
    let sweep_cols: Vec<String> = keys.iter().map(|k| Plan::sweep_column(k)).collect();
    report.steps.push(rewrite_runs(root, &sweep_cols, stamp)?);
    let data = Dataset::new(root, &identity, &manifest_json);
    data.write_whole(POINTS, "points.parquet", &tables::points_batch(&plan))
        .map_err(|e| CampaignError::Io(e.to_string()))?;
    report.steps.push(format!(
        "points: rewritten ({} points, in_manifest)",
        plan.points.len()
    ));
    let given = fs::read(root.join("manifest.json")).unwrap_or_else(|_| manifest_text.into_bytes());
    let mut first = history::write(root, 0, &given, n_runs).map_err(CampaignError::Io)?;
    first.accepted = created(&info_path);
    report.steps.push(format!(
        "history: the frozen manifest kept as {}",
        first.file
    ));
    write_info(root, &info, plan.registry, first)?;
    report.steps.push(format!(
        "campaign.json: format {} -> {FORMAT_VERSION}",
        report.from
    ));
    log(root, &report)?;
    Ok(report)
}

/// The registry of a campaign of format 1: its points in sweep order, each with its replicas
/// and the seeds they had.
fn format1_registry(m: &crate::manifest::Manifest, e: &plan::Expansion) -> Registry {
    let replicas = match m.runs_per_point() {
        RunsPerPoint::Replicas(r) => r,
        RunsPerPoint::Seeds(s) => s.len() as u32,
    };
    let mut r = Registry::default();
    for (i, (params, values)) in e.points.iter().zip(&e.values).enumerate() {
        r.points.push(super::registry::RegPoint {
            id: i as u32,
            params: params.to_value(),
        });
        r.blocks.push(RunBlock {
            point: i as u32,
            first_run: i as u64 * replicas as u64,
            first_replica: 0,
            count: replicas,
            seeds: SeedSource::Swept {
                keys: e.sweep_keys.clone(),
                values: values.clone(),
            },
            continues: None,
        });
    }
    r
}

/// Rewrite every part of `runs` without the sweep columns, into a new generation with the same
/// file names, and publish it.
fn rewrite_runs(root: &Path, sweep_cols: &[String], stamp: Stamp) -> Result<String, CampaignError> {
    let tables = root.join("tables");
    let io = |p: &Path, e: std::io::Error| io_err(p, e);
    if fs::symlink_metadata(tables.join(RUNS)).is_err() {
        return Ok("runs: no table yet".into());
    }
    let (gen, dir) = match layout::table_dir(root, RUNS).map_err(|e| io(&tables, e))? {
        TableDir::Generation { gen, dir } => (gen, dir),
        TableDir::Plain(_) => {
            layout::migrate_plain(root, RUNS).map_err(|e| io(&tables.join(RUNS), e))?;
            (
                0,
                tables
                    .join(layout::GEN_DIR)
                    .join(layout::generation_name(RUNS, 0)),
            )
        }
    };
    let next = gen + 1;
    let ndir = tables
        .join(layout::GEN_DIR)
        .join(layout::generation_name(RUNS, next));
    if ndir.exists() {
        fs::remove_dir_all(&ndir).map_err(|e| io(&ndir, e))?;
    }
    fsutil::create_dir_durable(&ndir).map_err(|e| io(&ndir, e))?;
    let mut files = 0;
    for e in fs::read_dir(&dir).map_err(|e| io(&dir, e))? {
        let path = e.map_err(|e| io(&dir, e))?.path();
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if name.starts_with('.') || !name.ends_with(".parquet") {
            continue;
        }
        let batches = parquet_io::read_campaign_file(&path, RUNS, stamp.campaign)
            .map_err(|e| CampaignError::Io(e.to_string()))?;
        let batches = batches
            .iter()
            .map(to_current_runs)
            .collect::<Result<Vec<RecordBatch>, String>>()
            .map_err(|e| CampaignError::Io(format!("{}: {e}", path.display())))?;
        let out = ndir.join(&name);
        if batches.is_empty() {
            continue;
        }
        parquet_io::write_batches(&out, &batches, RUNS, stamp)
            .map_err(|e| CampaignError::Io(e.to_string()))?;
        files += 1;
    }
    fsutil::sync_dir(&ndir).map_err(|e| io(&ndir, e))?;
    layout::publish_generation(root, RUNS, next).map_err(|e| io(&tables, e))?;
    Ok(format!(
        "runs: {files} file(s) rewritten without the sweep columns {sweep_cols:?}, with a null continued_from (generation {next})"
    ))
}

/// A format-1 `runs` batch in the columns of today's `runs` table: the sweep columns left out
/// (they are in `points` now), the columns format 1 did not have (`continued_from`) null.
fn to_current_runs(b: &RecordBatch) -> Result<RecordBatch, String> {
    let target = tables::runs_batch(&[]).schema();
    let n = b.num_rows();
    let mut columns = Vec::with_capacity(target.fields().len());
    for f in target.fields() {
        match b.column_by_name(f.name()) {
            Some(c) if c.data_type() == f.data_type() => columns.push(c.clone()),
            Some(c) => {
                return Err(format!(
                    "column {} is {}, expected {}",
                    f.name(),
                    c.data_type(),
                    f.data_type()
                ))
            }
            None if f.is_nullable() => columns.push(arrow_array::new_null_array(f.data_type(), n)),
            None => return Err(format!("no column {}", f.name())),
        }
    }
    RecordBatch::try_new(target, columns).map_err(|e| e.to_string())
}

/// When the campaign was created (campaign.json's modification time, as near as is known).
fn created(info_path: &Path) -> String {
    fs::metadata(info_path)
        .and_then(|m| m.modified())
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map(|d| history::utc(d.as_secs()))
        .unwrap_or_else(history::utc_now)
}

fn write_info(
    root: &Path,
    old: &CampaignInfo,
    registry: Registry,
    first: Accepted,
) -> Result<(), CampaignError> {
    let info = CampaignInfo {
        format_version: FORMAT_VERSION,
        code_version: CODE_VERSION.into(),
        name: old.name.clone(),
        n_runs: registry.n_runs(),
        manifest: old.manifest.clone(),
        registry: Some(registry),
        history: vec![first],
    };
    let path = root.join("campaign.json");
    fsutil::write_atomic(
        &path,
        &serde_json::to_vec_pretty(&info).expect("serialises"),
    )
    .map_err(|e| io_err(&path, e))
}

/// Append the upgrade to `upgrade.log` (one line per step, with the time and the version).
fn log(root: &Path, r: &UpgradeReport) -> Result<(), CampaignError> {
    use std::io::Write;
    let path = root.join("upgrade.log");
    let mut f = fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .map_err(|e| io_err(&path, e))?;
    let mut text = format!(
        "{} {CODE_VERSION}: format {} -> {}\n",
        history::utc_now(),
        r.from,
        r.to
    );
    for s in &r.steps {
        text.push_str(&format!("  {s}\n"));
    }
    f.write_all(text.as_bytes())
        .and_then(|_| f.sync_all())
        .map_err(|e| io_err(&path, e))
}
