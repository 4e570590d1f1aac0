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

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use arrow_array::RecordBatch;

use super::history;
use super::ledger::{self, ExclusiveLock, Purpose};
use super::plan::{self, canonical, Plan};
use super::registry::{Registry, RunBlock, SeedSource};
use super::tables::{self, POINTS, RUNS};
use super::{integrity, io_err, CampaignError, CampaignInfo};
use crate::fsutil;
use crate::manifest::RunsPerPoint;
use crate::store::checksum::{self, FileSum};
use crate::store::dataset::Dataset;
use crate::store::layout::{self, TableDir};
use crate::store::parquet_io::{self, Stamp};
use crate::store::{FORMAT_VERSION, LEDGER_FORMAT};
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
    // Not a campaign: refused before anything (the lock) is written. A directory of this
    // format has nothing to upgrade and nothing is written, but while another process holds it
    // (a shard runs, a compaction) that is said (exit 3), as for any other directory.
    let format = CampaignInfo::read(root)?.format_version;
    if super::is_current_format(format) {
        return already_current(root, format);
    }
    // Decided under the lock on what is read under it (a shard running, another upgrade).
    let _lock =
        ExclusiveLock::acquire(root, Purpose::Upgrade).map_err(|e| e.context("cannot upgrade"))?;
    let info = CampaignInfo::read(root)?;
    let mut report = UpgradeReport {
        from: info.format_version,
        to: FORMAT_VERSION,
        steps: Vec::new(),
    };
    match info.format_version {
        v if super::is_current_format(v) => {
            report.to = v;
            return Ok(report);
        }
        1 | 2 => {}
        v => {
            return Err(CampaignError::Refused(format!(
                "{}: format version {v}, which this granular ({FORMAT_VERSION}) cannot upgrade",
                info_path.display()
            )))
        }
    }
    report.steps.extend(recover_ledger1(root)?);
    let manifest_text = serde_json::to_string(&info.manifest).expect("value serialises");
    let manifest =
        crate::manifest::validate::parse(&manifest_text, &info_path.display().to_string())?;
    let manifest_json = canonical(&info.manifest);
    let identity = manifest.identity();
    let stamp = Stamp {
        campaign: &identity,
        manifest: &manifest_json,
        commit: None,
    };
    let data = Dataset::new(root, &identity, &manifest_json);
    let next_info = if info.format_version == 1 {
        upgrade_format1(
            root,
            &info_path,
            &info,
            &manifest,
            manifest_text,
            stamp,
            &data,
            &mut report,
        )?
    } else {
        CampaignInfo {
            format_version: FORMAT_VERSION,
            code_version: CODE_VERSION.into(),
            ..info.clone()
        }
    };
    report.steps.extend(checksum_ledger(root)?);
    report.steps.push(sidecars(root)?);
    commit_info(root, &next_info, &mut report)?;
    log(root, &report)?;
    Ok(report)
}

/// A directory already of this format: nothing to do, but refused (exit 3) while another
/// process holds it (a shard runs, a compaction), as for any other directory.
fn already_current(root: &Path, format: u32) -> Result<UpgradeReport, CampaignError> {
    if let Some(l) = ledger::live_locks(root).into_iter().find(|l| !l.is_ours()) {
        return Err(CampaignError::Refused(format!(
            "cannot upgrade: {} is in use: {} is being run by {}",
            root.display(),
            l.doing(),
            l.by()
        )));
    }
    Ok(UpgradeReport {
        from: format,
        to: format,
        steps: Vec::new(),
    })
}

/// Steps 1-4 of format 1 -> 2: the registry built from the frozen manifest, the `runs` and
/// `points` tables rewritten, the frozen manifest kept as the first history entry; returns the
/// `campaign.json` of this format to write (step 5), each step logged in `report`.
#[allow(clippy::too_many_arguments)]
fn upgrade_format1(
    root: &Path,
    info_path: &Path,
    info: &CampaignInfo,
    manifest: &crate::manifest::Manifest,
    manifest_text: String,
    stamp: Stamp,
    data: &Dataset,
    report: &mut UpgradeReport,
) -> Result<CampaignInfo, CampaignError> {
    let expansion = plan::expand(manifest).map_err(|errs| {
        CampaignError::Refused(format!(
            "{}: frozen manifest: {errs:?}",
            info_path.display()
        ))
    })?;
    let registry = format1_registry(manifest, &expansion);
    let n_runs = registry.n_runs();
    let keys = expansion.sweep_keys.clone();
    let plan = Plan::new(manifest, expansion, registry)?;
    report.steps.push(format!(
        "registry: {} points, {n_runs} runs, each keeping its seed of format 1",
        plan.points.len()
    ));
    let sweep_cols: Vec<String> = keys.iter().map(|k| Plan::sweep_column(k)).collect();
    report.steps.push(rewrite_runs(root, &sweep_cols, stamp)?);
    data.write_whole(POINTS, "points.parquet", &tables::points_batch(&plan))
        .map_err(|e| CampaignError::Io(e.to_string()))?;
    report.steps.push(format!(
        "points: rewritten ({} points, in_manifest)",
        plan.points.len()
    ));
    let given = fs::read(root.join("manifest.json")).unwrap_or_else(|_| manifest_text.into_bytes());
    let mut first = history::write(root, 0, &given, n_runs)?;
    first.accepted = created(info_path);
    report.steps.push(format!(
        "history: the frozen manifest kept as {}",
        first.file
    ));
    Ok(CampaignInfo {
        format_version: FORMAT_VERSION,
        code_version: CODE_VERSION.into(),
        name: info.name.clone(),
        n_runs: plan.registry.n_runs(),
        manifest: info.manifest.clone(),
        registry: Some(plan.registry),
        history: vec![first],
        rounds: None,
        stream_version: info.stream_version,
    })
}

/// Step 5, the commit point: `campaign.json` of this format written atomically.
fn commit_info(
    root: &Path,
    next_info: &CampaignInfo,
    report: &mut UpgradeReport,
) -> Result<(), CampaignError> {
    let path = root.join("campaign.json");
    fsutil::write_atomic(
        &path,
        &serde_json::to_vec_pretty(next_info).expect("serialises"),
    )
    .map_err(|e| io_err(&path, e))?;
    report.steps.push(format!(
        "campaign.json: format {} -> {FORMAT_VERSION}",
        report.from
    ));
    Ok(())
}

/// A commit record of ledger format 1 (files without sizes or checksums), or one this upgrade
/// already rewrote (it may have stopped half-way).
#[derive(serde::Deserialize)]
struct AnyCommit {
    shard: String,
    seq: u64,
    runs: Vec<ledger::CommittedRun>,
    files: Vec<AnyFile>,
}

#[derive(serde::Deserialize)]
#[serde(untagged)]
enum AnyFile {
    Path(String),
    Sum(FileSum),
}

impl AnyFile {
    fn path(&self) -> &str {
        match self {
            AnyFile::Path(p) => p,
            AnyFile::Sum(s) => &s.path,
        }
    }
}

/// Every commit record of the ledger (format 1 or 2), with its path.
fn old_records(root: &Path) -> Result<Vec<(PathBuf, AnyCommit)>, CampaignError> {
    let mut out = Vec::new();
    for t in ledger::shard_dirs(root) {
        let files = ledger::commit_files(&t)?;
        for (_, f) in files {
            let text = fs::read(&f).map_err(|e| io_err(&f, e))?;
            let c: AnyCommit = serde_json::from_slice(&text).map_err(|e| {
                CampaignError::Refused(format!(
                    "{}: corrupt commit record ({e}); move it away and upgrade again (its runs will run again)",
                    f.display()
                ))
            })?;
            out.push((f, c));
        }
    }
    Ok(out)
}

/// Recovery of a ledger of format 1: the parts of every record renamed into place, pending
/// parts no record names deleted (what `ledger::recover` did for format 1).
fn recover_ledger1(root: &Path) -> Result<Vec<String>, CampaignError> {
    let mut notes = Vec::new();
    let records = old_records(root)?;
    let mut referenced = std::collections::HashSet::new();
    for (_, c) in &records {
        for f in &c.files {
            let fin = root.join(f.path());
            let pend = ledger::pending_path(&fin);
            referenced.insert(pend.clone());
            if !fin.exists() && pend.exists() {
                fs::rename(&pend, &fin).map_err(|e| io_err(&pend, e))?;
                notes.push(format!("completed the commit of {}", fin.display()));
            }
        }
    }
    for table in layout::table_names(root).map_err(|e| io_err(root, e))? {
        let dir = root.join("tables").join(&table);
        let Ok(it) = fs::read_dir(&dir) else { continue };
        for e in it.filter_map(|e| e.ok()) {
            let name = e.file_name().to_string_lossy().into_owned();
            if name.ends_with(".pending") && !referenced.contains(&e.path()) {
                fs::remove_file(e.path()).map_err(|err| io_err(&e.path(), err))?;
                notes.push(format!(
                    "discarded the uncommitted part {}",
                    e.path().display()
                ));
            }
        }
    }
    Ok(notes)
}

fn sum_of(root: &Path, rel: &str, missing: &mut Vec<String>) -> Result<FileSum, CampaignError> {
    let path = root.join(rel);
    match checksum::sum_file(&path) {
        Ok((bytes, sha256)) => Ok(FileSum {
            path: rel.into(),
            bytes,
            sha256,
        }),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            missing.push(rel.into());
            // Recorded as it is: missing (the next `resume` runs its commit's runs again).
            Ok(FileSum {
                path: rel.into(),
                bytes: u64::MAX,
                sha256: String::new(),
            })
        }
        Err(e) => Err(io_err(&path, e)),
    }
}

/// Ledger format 1 -> 2: every commit record and the index rewritten with the size and
/// SHA-256 of each committed file (the files as they are now are taken to be right). The
/// index of format 1 (runs only) becomes one group of every committed part that no record
/// names.
fn checksum_ledger(root: &Path) -> Result<Vec<String>, CampaignError> {
    let mut steps = Vec::new();
    let mut missing = Vec::new();
    let records = old_records(root)?;
    let mut named = std::collections::HashSet::new();
    for (path, c) in &records {
        let mut files = Vec::new();
        for f in &c.files {
            named.insert(f.path().to_string());
            files.push(sum_of(root, f.path(), &mut missing)?);
        }
        let commit = ledger::Commit {
            format_version: LEDGER_FORMAT,
            shard: c.shard.clone(),
            seq: c.seq,
            runs: c.runs.clone(),
            files,
            in_index: false,
        };
        fsutil::write_atomic(
            path,
            &serde_json::to_vec(&commit).expect("commit serialises"),
        )
        .map_err(|e| io_err(path, e))?;
    }
    steps.push(format!(
        "ledger: {} commit record(s) rewritten with the size and SHA-256 of their files (format 2)",
        records.len()
    ));
    let ip = ledger::index_path(root);
    if let Ok(text) = fs::read(&ip) {
        #[derive(serde::Deserialize)]
        struct Index1 {
            format_version: u32,
            folded: BTreeMap<String, u64>,
            #[serde(default)]
            done: Vec<(u64, u64)>,
            #[serde(default)]
            failed: Vec<u64>,
        }
        let v: serde_json::Value = serde_json::from_slice(&text).map_err(|e| {
            CampaignError::Refused(format!("{}: corrupt ledger index: {e}", ip.display()))
        })?;
        if v["format_version"] != serde_json::json!(LEDGER_FORMAT) {
            let ix: Index1 = serde_json::from_value(v).map_err(|e| {
                CampaignError::Refused(format!("{}: corrupt ledger index: {e}", ip.display()))
            })?;
            let _ = ix.format_version;
            let mut files = Vec::new();
            for table in layout::table_names(root).map_err(|e| io_err(root, e))? {
                let dir = root.join("tables").join(&table);
                let mut names: Vec<String> = fs::read_dir(&dir)
                    .map_err(|e| io_err(&dir, e))?
                    .filter_map(|e| e.ok())
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .filter(|n| integrity::is_part_name(n))
                    .collect();
                names.sort();
                for n in names {
                    let rel = format!("tables/{table}/{n}");
                    if !named.contains(&rel) {
                        files.push(sum_of(root, &rel, &mut missing)?);
                    }
                }
            }
            let n = files.len();
            let index = ledger::LedgerIndex {
                format_version: LEDGER_FORMAT,
                kind: ledger::INDEX_KIND.into(),
                folded: ix.folded,
                compactions: 0,
                groups: vec![ledger::Group {
                    shard: "index".into(),
                    seq: 0,
                    done: ix.done,
                    failed: ix.failed,
                    files,
                }],
            };
            ledger::write_index(root, &index)?;
            steps.push(format!(
                "ledger index: its runs and the {n} compacted file(s) no record names, with their sizes and SHA-256, as one group (format 2)"
            ));
        }
    }
    if !missing.is_empty() {
        steps.push(format!(
            "ledger: {} committed file(s) missing, recorded as such (`granular resume` runs their runs again): {}",
            missing.len(),
            missing.join(", ")
        ));
    }
    Ok(steps)
}

/// A checksum sidecar for every file of a table written whole (points, theory, summaries).
fn sidecars(root: &Path) -> Result<String, CampaignError> {
    let mut n = 0;
    for table in layout::table_names(root).map_err(|e| io_err(root, e))? {
        let dir = root.join("tables").join(&table);
        let Ok(it) = fs::read_dir(&dir) else { continue };
        for e in it.filter_map(|e| e.ok()) {
            let name = e.file_name().to_string_lossy().into_owned();
            if name.starts_with('.')
                || !name.ends_with(".parquet")
                || integrity::is_part_name(&name)
            {
                continue;
            }
            let (bytes, sha) =
                checksum::sum_file(&e.path()).map_err(|err| io_err(&e.path(), err))?;
            checksum::write_sidecar(root, &table, &name, bytes, &sha)
                .map_err(|err| io_err(&e.path(), err))?;
            n += 1;
        }
    }
    Ok(format!(
        "rebuilt tables: a checksum sidecar for each of their {n} file(s)"
    ))
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
            .collect::<Result<Vec<RecordBatch>, CampaignError>>()
            .map_err(|e| e.context(path.display()))?;
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
fn to_current_runs(b: &RecordBatch) -> Result<RecordBatch, CampaignError> {
    let target = tables::runs_batch(&[]).schema();
    let n = b.num_rows();
    let mut columns = Vec::with_capacity(target.fields().len());
    for f in target.fields() {
        match b.column_by_name(f.name()) {
            Some(c) if c.data_type() == f.data_type() => columns.push(c.clone()),
            Some(c) => {
                return Err(CampaignError::Io(format!(
                    "column {} is {}, expected {}",
                    f.name(),
                    c.data_type(),
                    f.data_type()
                )))
            }
            None if f.is_nullable() => columns.push(arrow_array::new_null_array(f.data_type(), n)),
            None => return Err(CampaignError::Io(format!("no column {}", f.name()))),
        }
    }
    RecordBatch::try_new(target, columns).map_err(|e| CampaignError::Io(e.to_string()))
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

/// Append the upgrade to `upgrade.log` (one line per step, with the time and the version).
fn log(root: &Path, r: &UpgradeReport) -> Result<(), CampaignError> {
    use std::io::Write;
    let path = root.join("upgrade.log");
    let mut f = fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .map_err(|e| io_err(&path, e))?;
    let path_of_formats: Vec<String> = (r.from..=r.to).map(|v| v.to_string()).collect();
    let mut text = format!(
        "{} {CODE_VERSION}: format {}\n",
        history::utc_now(),
        path_of_formats.join(" -> ")
    );
    for s in &r.steps {
        text.push_str(&format!("  {s}\n"));
    }
    f.write_all(text.as_bytes())
        .and_then(|_| f.sync_all())
        .map_err(|e| io_err(&path, e))
}
