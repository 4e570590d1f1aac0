//! The single table writer of a shard: buffers the rows of finished runs (in the tables their
//! model names) and flushes them as one commit (pending parts -> commit record -> rename; see
//! `ledger`). It knows tables by name only, never a model.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use arrow_array::RecordBatch;
use arrow_schema::SchemaRef;

use super::ledger::{self, Commit, CommittedRun, PartCommit, RunStatus};
use super::tables::{self, RunRow};
use super::worker::{RunEnd, RunResult};
use super::Campaign;
use crate::fsutil;
use crate::store::checksum::FileSum;
use crate::store::parquet_io::{self, Stamp, StoreError};
use crate::store::{checkpoint, schema, FORMAT_VERSION, LEDGER_FORMAT};

/// Flush when this many rows are buffered, whatever the time.
const FLUSH_ROWS: usize = 1_000_000;

pub struct Writer<'c> {
    c: &'c Campaign,
    tag: String,
    seq: u64,
    /// The campaign's tables, in the order parts are written.
    order: Vec<&'static str>,
    runs: Vec<RunRow>,
    /// Buffered rows per table.
    rows: BTreeMap<&'static str, Vec<RecordBatch>>,
    buffered: usize,
    since: Option<Instant>,
    /// The columns of each table that already has files (fixed by its first file: a campaign
    /// of an earlier granular keeps its columns; see `store::schema`).
    schemas: BTreeMap<String, SchemaRef>,
}

impl<'c> Writer<'c> {
    pub fn new(c: &'c Campaign, tag: &str) -> Result<Self, StoreError> {
        let order = c.tables();
        let data = c.data();
        for t in &order {
            data.ensure(t)?;
        }
        let d = ledger::ledger_dir(&c.root, tag);
        fsutil::create_dir_durable(&d).map_err(|e| StoreError::io(&d, e))?;
        Ok(Writer {
            c,
            tag: tag.to_string(),
            seq: ledger::next_seq(&c.root, tag),
            order,
            runs: Vec::new(),
            rows: BTreeMap::new(),
            buffered: 0,
            since: None,
            schemas: BTreeMap::new(),
        })
    }

    /// Write the `points` and `registered_runs` tables unless they are those of the latest
    /// manifest and registry (they depend only on them; rewritten whole, atomically, when they
    /// change).
    pub fn ensure_points(&self) -> Result<(), StoreError> {
        let data = self.c.data();
        let current = |table: &str, file: &str, rows: u64| {
            let path = data.dir(table).join(file);
            path.exists()
                && parquet_io::inspect(&path).ok().is_some_and(|(info, _)| {
                    info.format_version == Some(FORMAT_VERSION)
                        && info.manifest.as_deref() == Some(self.c.manifest_json.as_str())
                        && info.rows == rows
                })
        };
        if !current(
            tables::POINTS,
            "points.parquet",
            self.c.plan.points.len() as u64,
        ) {
            data.write_whole(
                tables::POINTS,
                "points.parquet",
                &tables::points_batch(&self.c.plan),
            )?;
        }
        if !current(
            tables::REGISTERED_RUNS,
            "registered_runs.parquet",
            self.c.plan.n_runs(),
        ) {
            data.write_whole(
                tables::REGISTERED_RUNS,
                "registered_runs.parquet",
                &tables::registered_runs_batch(&self.c.plan),
            )?;
        }
        Ok(())
    }

    /// Write the model's kinetic-theory tables once (they depend only on the manifest).
    pub fn ensure_theory(&self) -> Result<(), StoreError> {
        self.c.write_theory()
    }

    pub fn add(&mut self, r: RunResult) {
        let continued_from = r.continued_from;
        let (status, reason, t_failed, collisions, trials) = match r.end {
            RunEnd::Done(out) => {
                for (table, batch) in out.tables {
                    self.buffered += batch.num_rows();
                    self.rows.entry(table).or_default().push(batch);
                }
                (RunStatus::Done, None, None, out.collisions, out.trials)
            }
            RunEnd::Failed { reason, t } => (RunStatus::Failed, Some(reason), Some(t), 0, 0),
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
            continued_from,
        });
        self.since.get_or_insert_with(Instant::now);
    }

    pub fn due(&self, every: Duration) -> bool {
        !self.runs.is_empty()
            && (self.buffered >= FLUSH_ROWS || self.since.is_some_and(|s| s.elapsed() >= every))
    }

    fn part(&self, table: &str) -> (String, PathBuf) {
        let rel = ledger::part_rel(table, &self.tag, self.seq);
        let abs = self.c.root.join(&rel);
        (rel, abs)
    }

    /// The buffered parts, `runs` first, then the model's tables in their order. The buffers
    /// are kept until the commit succeeds: a failed flush leaves them whole, so that a later
    /// one commits every run with its rows, never a run without them.
    fn batches(&self) -> Vec<(&'static str, Vec<RecordBatch>)> {
        let mut out = vec![(tables::RUNS, vec![tables::runs_batch(&self.runs)])];
        for t in &self.order {
            if let Some(b) = self.rows.get(t) {
                out.push((*t, b.clone()));
            }
        }
        // Rows of a table the campaign does not list (a model bug) are written too, last,
        // rather than lost.
        out.extend(
            self.rows
                .iter()
                .filter(|(t, _)| !self.order.contains(t))
                .map(|(t, b)| (*t, b.clone())),
        );
        out
    }

    /// `batches` in the columns their tables already have (an error names a column whose
    /// values a table of an earlier granular cannot hold; nothing is written then).
    fn conformed(
        &mut self,
        batches: Vec<(&'static str, Vec<RecordBatch>)>,
    ) -> Result<Vec<(&'static str, Vec<RecordBatch>)>, StoreError> {
        let mut out = Vec::with_capacity(batches.len());
        for (table, parts) in batches {
            if !self.schemas.contains_key(table) {
                if let Some(s) = schema::table_schema(&self.c.data().files(table)?) {
                    self.schemas.insert(table.to_string(), s);
                }
            }
            let parts = match self.schemas.get(table) {
                Some(s) => parts
                    .iter()
                    .map(|b| schema::conform(b, s, table))
                    .collect::<Result<Vec<_>, _>>()?,
                None => parts,
            };
            out.push((table, parts));
        }
        Ok(out)
    }

    /// Commit the buffered runs; returns (runs committed, commit seq).
    pub fn flush(&mut self) -> Result<Option<(usize, u64)>, StoreError> {
        if self.runs.is_empty() {
            return Ok(None);
        }
        let batches = self.batches();
        let batches = self.conformed(batches)?;
        // Every part says in its footer which commit it belongs to and which tables that
        // commit wrote, so that a lost commit record can be rebuilt from the parts.
        let part_commit = serde_json::to_string(&PartCommit {
            shard: self.tag.clone(),
            seq: self.seq,
            tables: batches.iter().map(|(t, _)| t.to_string()).collect(),
        })
        .expect("part commit serialises");
        let stamp = Stamp {
            commit: Some(&part_commit),
            ..self.c.stamp()
        };
        // 1. pending parts
        let mut files = Vec::new();
        let mut sums = Vec::new();
        let mut written = Vec::new();
        for (table, parts) in &batches {
            let (rel, abs) = self.part(table);
            let pending = ledger::pending_path(&abs);
            match parquet_io::write_batches(&pending, parts, table, stamp) {
                Ok(w) => sums.push(FileSum {
                    path: rel.clone(),
                    bytes: w.bytes,
                    sha256: w.sha256,
                }),
                Err(e) => {
                    for p in &written {
                        let _ = std::fs::remove_file(p);
                    }
                    return Err(e);
                }
            }
            written.push(pending);
            files.push((rel, abs));
        }
        // 2. the commit record (the commit point)
        let commit = Commit {
            format_version: LEDGER_FORMAT,
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
            files: sums,
            in_index: false,
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
        // 4. checkpoints of committed runs are no longer needed, nor the final states of the
        //    runs they continued (their own replace them)
        let dir = self.c.checkpoint_dir();
        let finals = self.c.finals_dir();
        for r in &self.runs {
            checkpoint::remove(&dir, r.run_id);
            if let (Some(old), "done") = (r.continued_from, r.status.as_str()) {
                checkpoint::remove_final(&finals, old);
            }
        }
        let n = self.runs.len();
        let seq = self.seq;
        self.rows.clear();
        self.buffered = 0;
        self.runs.clear();
        self.since = None;
        self.seq += 1;
        Ok(Some((n, seq)))
    }
}
