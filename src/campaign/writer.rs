//! The single table writer of a shard: buffers finished runs, then flushes them as one
//! commit (pending parts -> commit record -> rename; see `ledger`).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use super::ledger::{self, Commit, CommittedRun, RunStatus};
use super::worker::{RunEnd, RunResult};
use super::Campaign;
use crate::fsutil;
use crate::plan::canonical;
use crate::store::parquet_io::{self, StoreError};
use crate::store::tables::{self, RunRow, SpeciesBuffer, SweepColumn, TamsdBuffer};
use crate::store::{checkpoint, FORMAT_VERSION};

/// Flush when this many rows are buffered, whatever the time.
const FLUSH_ROWS: usize = 1_000_000;

pub struct Writer<'c> {
    c: &'c Campaign,
    tag: String,
    seq: u64,
    cols: Vec<SweepColumn>,
    runs: Vec<RunRow>,
    species: SpeciesBuffer,
    tamsd: TamsdBuffer,
    rfm: tables::RfmBuffer,
    aux: crate::store::aux_tables::AuxBuffer,
    since: Option<Instant>,
}

impl<'c> Writer<'c> {
    pub fn new(c: &'c Campaign, tag: &str) -> Result<Self, StoreError> {
        let mut names = vec![tables::RUNS, tables::POINTS];
        match c.plan.model {
            crate::manifest::ModelKind::Dsmc => names.extend([
                tables::DSMC_SPECIES,
                tables::DSMC_SPECIES_SUMMARY,
                tables::DSMC_THEORY,
                tables::DSMC_THEORY_POINT,
            ]),
            crate::manifest::ModelKind::Rfm => names.extend(c.rfm_tables()),
            crate::manifest::ModelKind::Bisection
            | crate::manifest::ModelKind::Cascade
            | crate::manifest::ModelKind::Spm => {
                names.extend(crate::store::aux_tables::aux_tables(&c.plan))
            }
        }
        // Tables of an observable exist only when it is recorded (an empty dataset directory
        // is an error for DuckDB's globs).
        if c.observes_tamsd() {
            names.extend([
                tables::DSMC_TAMSD,
                tables::DSMC_TAMSD_SUMMARY,
                tables::DSMC_THEORY_TAMSD,
            ]);
        }
        for t in names {
            crate::store::layout::ensure_table_dir(&c.root, t)
                .map_err(|e| StoreError::io(&c.root.join("tables").join(t), e))?;
        }
        let d = ledger::ledger_dir(&c.root, tag);
        fsutil::create_dir_durable(&d).map_err(|e| StoreError::io(&d, e))?;
        Ok(Writer {
            c,
            tag: tag.to_string(),
            seq: ledger::next_seq(&c.root, tag),
            cols: tables::sweep_columns(&c.plan),
            runs: Vec::new(),
            species: SpeciesBuffer::default(),
            tamsd: TamsdBuffer::default(),
            rfm: tables::RfmBuffer::default(),
            aux: Default::default(),
            since: None,
        })
    }

    /// Write the `points` table once (it depends only on the manifest).
    pub fn ensure_points(&self) -> Result<(), StoreError> {
        let path = self
            .c
            .root
            .join("tables")
            .join(tables::POINTS)
            .join("points.parquet");
        if path.exists() {
            return Ok(());
        }
        let params: Vec<String> = self
            .c
            .plan
            .points
            .iter()
            .map(|p| canonical(&p.params.to_value()))
            .collect();
        let batch = tables::points_batch(&self.c.plan, &self.cols, &params);
        let tmp = fsutil::temp_path(&path);
        parquet_io::write_file(&tmp, &batch, tables::POINTS, &self.c.manifest_json)?;
        std::fs::rename(&tmp, &path).map_err(|e| StoreError::io(&path, e))?;
        fsutil::sync_dir(path.parent().expect("dir")).map_err(|e| StoreError::io(&path, e))
    }

    /// Write the kinetic-theory tables once (they depend only on the manifest).
    pub fn ensure_theory(&self) -> Result<(), StoreError> {
        write_theory(self.c)
    }

    pub fn add(&mut self, r: RunResult) {
        let (status, reason, t_failed, collisions, trials) = match &r.end {
            RunEnd::Done(out) => {
                self.species
                    .push(r.spec.run_id, r.spec.point_id, &out.dsmc_species);
                self.tamsd
                    .push(r.spec.run_id, r.spec.point_id, &out.dsmc_tamsd);
                if let Some(rfm) = &out.rfm {
                    self.rfm.push(r.spec.run_id, r.spec.point_id, rfm);
                }
                if let Some(aux) = &out.aux {
                    self.aux.push(r.spec.run_id, r.spec.point_id, aux);
                }
                (RunStatus::Done, None, None, out.collisions, out.trials)
            }
            RunEnd::Failed { reason, t } => {
                (RunStatus::Failed, Some(reason.clone()), Some(*t), 0, 0)
            }
            RunEnd::Interrupted => return,
        };
        self.runs.push(RunRow {
            run_id: r.spec.run_id,
            point_id: r.spec.point_id,
            replica: r.spec.replica,
            seed: r.spec.seed,
            status: match status {
                RunStatus::Done => "done".into(),
                RunStatus::Failed => "failed".into(),
            },
            reason,
            t_failed,
            wall_seconds: r.wall_seconds,
            collisions,
            trials,
        });
        self.since.get_or_insert_with(Instant::now);
    }

    pub fn due(&self, every: Duration) -> bool {
        !self.runs.is_empty()
            && (self.species.rows + self.tamsd.rows + self.rfm.rows() + self.aux.rows()
                >= FLUSH_ROWS
                || self.since.is_some_and(|s| s.elapsed() >= every))
    }

    fn part(&self, table: &str) -> (String, PathBuf) {
        let rel = format!("tables/{table}/part-{}-{:08}.parquet", self.tag, self.seq);
        let abs = self.c.root.join(&rel);
        (rel, abs)
    }

    /// Commit the buffered runs; returns (runs committed, commit seq).
    pub fn flush(&mut self) -> Result<Option<(usize, u64)>, StoreError> {
        if self.runs.is_empty() {
            return Ok(None);
        }
        let mut files = Vec::new();
        let mut batches = vec![(
            tables::RUNS,
            tables::runs_batch(&self.c.plan, &self.cols, &self.runs),
        )];
        if self.species.rows > 0 {
            batches.push((tables::DSMC_SPECIES, self.species.finish()));
        }
        if self.tamsd.rows > 0 {
            batches.push((tables::DSMC_TAMSD, self.tamsd.finish()));
        }
        batches.extend(self.rfm.finish());
        batches.extend(self.aux.finish());
        // 1. pending parts
        let mut written = Vec::new();
        for (table, batch) in &batches {
            let (rel, abs) = self.part(table);
            let pending = ledger::pending_path(&abs);
            if let Err(e) = parquet_io::write_file(&pending, batch, table, &self.c.manifest_json) {
                let _ = std::fs::remove_file(&pending);
                for p in &written {
                    let _ = std::fs::remove_file(p);
                }
                return Err(e);
            }
            written.push(pending);
            files.push((rel, abs));
        }
        // 2. the commit record (the commit point)
        let commit = Commit {
            format_version: FORMAT_VERSION,
            shard: self.tag.clone(),
            seq: self.seq,
            runs: self
                .runs
                .iter()
                .map(|r| CommittedRun {
                    run_id: r.run_id,
                    status: if r.status == "done" {
                        RunStatus::Done
                    } else {
                        RunStatus::Failed
                    },
                })
                .collect(),
            files: files.iter().map(|(rel, _)| rel.clone()).collect(),
        };
        let cpath = ledger::commit_path(&self.c.root, &self.tag, self.seq);
        if let Err(e) = fsutil::write_atomic(
            &cpath,
            &serde_json::to_vec(&commit).expect("commit serialises"),
        ) {
            for p in &written {
                let _ = std::fs::remove_file(p);
            }
            return Err(StoreError::io(&cpath, e));
        }
        // 3. make the parts visible
        for (_, abs) in &files {
            std::fs::rename(ledger::pending_path(abs), abs).map_err(|e| StoreError::io(abs, e))?;
        }
        for (table, _) in &batches {
            let d = self.c.root.join("tables").join(table);
            fsutil::sync_dir(&d).map_err(|e| StoreError::io(&d, e))?;
        }
        // 4. checkpoints of committed runs are no longer needed
        let dir = self.c.checkpoint_dir();
        for r in &self.runs {
            checkpoint::remove(&dir, r.run_id);
        }
        let n = self.runs.len();
        let seq = self.seq;
        self.runs.clear();
        self.since = None;
        self.seq += 1;
        Ok(Some((n, seq)))
    }
}

/// Compute the kinetic-theory predictions of every point (in parallel) and write
/// those of `dsmc_theory`, `dsmc_theory_point` and `dsmc_theory_tamsd` that do not exist yet
/// (a campaign directory of an older version gains the tables it lacks; existing ones are
/// never rewritten).
pub fn write_theory(c: &Campaign) -> Result<(), StoreError> {
    if c.plan.model != crate::manifest::ModelKind::Dsmc {
        return Ok(());
    }
    use rayon::prelude::*;
    let dir = c.root.join("tables");
    let theory = dir.join(tables::DSMC_THEORY).join("theory.parquet");
    let per_point = dir
        .join(tables::DSMC_THEORY_POINT)
        .join("theory_point.parquet");
    let tamsd = dir
        .join(tables::DSMC_THEORY_TAMSD)
        .join("theory_tamsd.parquet");
    let with_tamsd = c.observes_tamsd();
    if theory.exists() && per_point.exists() && (tamsd.exists() || !with_tamsd) {
        return Ok(());
    }
    let mut names = vec![tables::DSMC_THEORY, tables::DSMC_THEORY_POINT];
    if with_tamsd {
        names.push(tables::DSMC_THEORY_TAMSD);
    }
    for t in names {
        crate::store::layout::ensure_table_dir(&c.root, t)
            .map_err(|e| StoreError::io(&dir.join(t), e))?;
    }
    let preds: Vec<(u32, crate::dsmc::predict::Prediction)> = c
        .plan
        .points
        .par_iter()
        .filter_map(|p| match &p.params {
            crate::plan::ModelParams::Dsmc(d) => crate::dsmc::DsmcSystem::from_params(d)
                .ok()
                .map(|sys| (p.point_id, crate::dsmc::predict::predict(&sys))),
            _ => None,
        })
        .collect();
    let rows: Vec<(u32, crate::dsmc::predict::TheoryRow)> = preds
        .iter()
        .flat_map(|(p, pr)| pr.rows.iter().map(move |r| (*p, r.clone())))
        .collect();
    let tamsd_rows: Vec<(u32, crate::dsmc::predict::TamsdTheoryRow)> = preds
        .iter()
        .flat_map(|(p, pr)| pr.tamsd.iter().map(move |r| (*p, r.clone())))
        .collect();
    let points: Vec<(u32, f64, Vec<f64>)> = preds
        .iter()
        .map(|(p, pr)| (*p, pr.tau0, pr.initial_temperatures.clone()))
        .collect();
    for (path, batch, table) in [
        (&theory, tables::theory_batch(&rows), tables::DSMC_THEORY),
        (
            &per_point,
            tables::theory_point_batch(&points),
            tables::DSMC_THEORY_POINT,
        ),
        (
            &tamsd,
            tables::theory_tamsd_batch(&tamsd_rows),
            tables::DSMC_THEORY_TAMSD,
        ),
    ] {
        if path.exists() || (table == tables::DSMC_THEORY_TAMSD && !with_tamsd) {
            continue;
        }
        let tmp = fsutil::temp_path(path);
        parquet_io::write_file(&tmp, &batch, table, &c.manifest_json)?;
        std::fs::rename(&tmp, path).map_err(|e| StoreError::io(path, e))?;
        fsutil::sync_dir(path.parent().expect("dir")).map_err(|e| StoreError::io(path, e))?;
    }
    Ok(())
}
