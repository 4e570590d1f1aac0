//! Ensemble summaries over replicas: `dsmc_species_summary` (mean and standard error of the
//! mean per point, time and species) and `dsmc_tamsd_summary` (the same per point, species and
//! lag). Derived data: rewritten whole, atomically, whenever the
//! campaign completes. Reads the raw table in chunks of points so memory stays bounded, and
//! sums in replica order so the result is bit-identical however the runs were scheduled.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

use arrow_array::cast::AsArray;
use arrow_array::types::{Float64Type, UInt32Type, UInt64Type};
use arrow_array::{ArrayRef, RecordBatch};
use arrow_schema::{DataType, Field, Schema};

use super::parquet_io::{self, StoreError};
use super::tables;
use crate::campaign::ledger::RunStatus;
use crate::campaign::Campaign;
use crate::fsutil;
pub use crate::math::stats::{mean_sem, replica_mean_sem};

/// Rows of the raw table held at once (per chunk of points).
const CHUNK_ROWS: u64 = 4_000_000;

/// Every batch of every part of `table` (only this campaign's parts; see
/// `parquet_io::read_campaign_file`).
pub fn campaign_batches(c: &Campaign, table: &str) -> Result<Vec<RecordBatch>, StoreError> {
    let mut out = Vec::new();
    for f in table_files(c, table)? {
        out.extend(parquet_io::read_campaign_file(&f, table, &c.manifest_json)?);
    }
    Ok(out)
}

pub fn table_files(c: &Campaign, table: &str) -> Result<Vec<PathBuf>, StoreError> {
    let dir = c.root.join("tables").join(table);
    let mut files: Vec<PathBuf> = match std::fs::read_dir(&dir) {
        Ok(it) => it
            .filter_map(|e| e.ok())
            .map(|e| e.path())
            .filter(|p| {
                let n = p
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default();
                !n.starts_with('.') && n.ends_with(".parquet")
            })
            .collect(),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
        Err(e) => return Err(StoreError::io(&dir, e)),
    };
    files.sort();
    Ok(files)
}

type Key = (u32, u64, u32); // point, t bits, species

pub fn write_summaries(
    c: &Campaign,
    finished: &BTreeMap<u64, RunStatus>,
) -> Result<(), StoreError> {
    match c.plan.model {
        crate::manifest::ModelKind::Dsmc => write_dsmc_summaries(c, finished),
        crate::manifest::ModelKind::Rfm => super::rfm_summary::write_rfm_summaries(c, finished),
        // The auxiliary models' tables carry their statistics over realisations per run; the
        // cascade's S(k) also gets a replica summary (fitted like the RFM's).
        crate::manifest::ModelKind::Bisection
        | crate::manifest::ModelKind::Cascade
        | crate::manifest::ModelKind::Spm => super::aux_summary::write_aux_summaries(c, finished),
    }
}

fn write_dsmc_summaries(
    c: &Campaign,
    finished: &BTreeMap<u64, RunStatus>,
) -> Result<(), StoreError> {
    let files = table_files(c, tables::DSMC_SPECIES)?;
    let replicas = c.plan.replicas as u64;
    let rows_per_point: u64 = c
        .plan
        .points
        .iter()
        .map(|p| match &p.params {
            crate::plan::ModelParams::Dsmc(d) => {
                let species = crate::dsmc::DsmcSystem::from_params(d)
                    .map(|s| s.species.len())
                    .unwrap_or(1) as u64;
                species * d.output_times.resolve(d.t_end).len() as u64 * replicas
            }
            _ => 1,
        })
        .max()
        .unwrap_or(1)
        .max(1);
    let points_per_chunk = (CHUNK_ROWS / rows_per_point).max(1) as u32;
    let n_points = c.plan.points.len() as u32;

    let theory = read_theory(c)?;
    let mut out = SummaryColumns::default();
    let mut p0 = 0u32;
    while p0 < n_points {
        let p1 = (p0 + points_per_chunk).min(n_points);
        // (point, t, species) -> [(replica, temperature, msd)]
        let mut acc: BTreeMap<Key, Vec<(u32, f64, Option<f64>)>> = BTreeMap::new();
        for f in &files {
            for b in parquet_io::read_campaign_file(f, tables::DSMC_SPECIES, &c.manifest_json)? {
                let col = |name: &str| {
                    b.column_by_name(name).cloned().ok_or_else(|| {
                        StoreError::Corrupt(
                            f.display().to_string(),
                            format!("has no column {name}"),
                        )
                    })
                };
                let run = col("run_id")?;
                let point = col("point_id")?;
                let t = col("t")?;
                let sp = col("species")?;
                let temp = col("temperature")?;
                let msd = col("msd")?;
                let (run, point, t, sp, temp, msd) = (
                    run.as_primitive::<UInt64Type>(),
                    point.as_primitive::<UInt32Type>(),
                    t.as_primitive::<Float64Type>(),
                    sp.as_primitive::<UInt32Type>(),
                    temp.as_primitive::<Float64Type>(),
                    msd.as_primitive::<Float64Type>(),
                );
                for i in 0..b.num_rows() {
                    let p = point.value(i);
                    if p < p0 || p >= p1 || finished.get(&run.value(i)) != Some(&RunStatus::Done) {
                        continue;
                    }
                    let m = if arrow_array::Array::is_null(msd, i) {
                        None
                    } else {
                        Some(msd.value(i))
                    };
                    acc.entry((p, t.value(i).to_bits(), sp.value(i)))
                        .or_default()
                        .push(((run.value(i) % replicas) as u32, temp.value(i), m));
                }
            }
        }
        // Points whose replicas are not all finished (failed ones excluded) are summarised
        // over the replicas that succeeded.
        let mut order: Vec<Key> = acc.keys().copied().collect();
        order.sort_by(|a, b| {
            (a.0, f64::from_bits(a.1), a.2)
                .partial_cmp(&(b.0, f64::from_bits(b.1), b.2))
                .expect("finite times")
        });
        for key in order {
            let mut v = acc.remove(&key).expect("key");
            v.sort_by_key(|x| x.0);
            v.dedup_by_key(|x| x.0);
            let temps: Vec<f64> = v.iter().map(|x| x.1).collect();
            let (tm, ts) = mean_sem(&temps);
            let msds: Vec<f64> = v.iter().filter_map(|x| x.2).collect();
            let (mm, ms) = if msds.len() == v.len() && !msds.is_empty() {
                let (m, s) = mean_sem(&msds);
                (Some(m), s)
            } else {
                (None, None)
            };
            let th = theory.get(&key).copied();
            out.push(
                key.0,
                f64::from_bits(key.1),
                key.2,
                v.len() as u32,
                tm,
                ts,
                mm,
                ms,
                th,
            );
        }
        p0 = p1;
    }
    write_whole(
        c,
        tables::DSMC_SPECIES_SUMMARY,
        "summary.parquet",
        &out.finish(),
    )?;
    if c.observes_tamsd() {
        write_tamsd_summary(c, finished)?;
    }
    Ok(())
}

/// Write `tables/<table>/<name>` atomically (the whole table in one file).
pub(crate) fn write_whole(
    c: &Campaign,
    table: &str,
    name: &str,
    batch: &RecordBatch,
) -> Result<(), StoreError> {
    let path = c.root.join("tables").join(table).join(name);
    crate::store::layout::ensure_table_dir(&c.root, table).map_err(|e| StoreError::io(&path, e))?;
    let tmp = fsutil::temp_path(&path);
    if let Err(e) = parquet_io::write_file(&tmp, batch, table, &c.manifest_json) {
        let _ = std::fs::remove_file(&tmp);
        return Err(e);
    }
    std::fs::rename(&tmp, &path).map_err(|e| StoreError::io(&path, e))?;
    fsutil::sync_dir(path.parent().expect("dir")).map_err(|e| StoreError::io(&path, e))
}

type TamsdKey = (u32, u32, u64); // point, species, lag bits

/// `dsmc_tamsd_summary`: mean and standard error over the finished replicas of each (point,
/// species, lag), with the theory (27) joined; in chunks of points, summed in replica order.
fn write_tamsd_summary(
    c: &Campaign,
    finished: &BTreeMap<u64, RunStatus>,
) -> Result<(), StoreError> {
    let files = table_files(c, tables::DSMC_TAMSD)?;
    let replicas = c.plan.replicas as u64;
    let rows_per_point: u64 = c
        .plan
        .points
        .iter()
        .map(|p| match &p.params {
            crate::plan::ModelParams::Dsmc(d) => match (&d.tamsd, d.wants_tamsd()) {
                (Some(tm), true) => {
                    let species = crate::dsmc::DsmcSystem::from_params(d)
                        .map(|s| s.species.len())
                        .unwrap_or(1) as u64;
                    species * tm.lags.len() as u64 * replicas
                }
                _ => 0,
            },
            _ => 0,
        })
        .max()
        .unwrap_or(1)
        .max(1);
    let points_per_chunk = (CHUNK_ROWS / rows_per_point).max(1) as u32;
    let n_points = c.plan.points.len() as u32;
    let theory = read_tamsd_theory(c)?;
    let mut cols = TamsdSummaryColumns::default();
    let mut p0 = 0u32;
    while p0 < n_points && !files.is_empty() {
        let p1 = (p0 + points_per_chunk).min(n_points);
        // (point, species, lag) -> [(replica, tamsd)]
        let mut acc: BTreeMap<TamsdKey, Vec<(u32, f64)>> = BTreeMap::new();
        for f in &files {
            for b in parquet_io::read_campaign_file(f, tables::DSMC_TAMSD, &c.manifest_json)? {
                let col = |name: &str| {
                    b.column_by_name(name).cloned().ok_or_else(|| {
                        StoreError::Corrupt(
                            f.display().to_string(),
                            format!("has no column {name}"),
                        )
                    })
                };
                let (run, point, sp, lag, val) = (
                    col("run_id")?,
                    col("point_id")?,
                    col("species")?,
                    col("lag")?,
                    col("tamsd")?,
                );
                let (run, point, sp, lag, val) = (
                    run.as_primitive::<UInt64Type>(),
                    point.as_primitive::<UInt32Type>(),
                    sp.as_primitive::<UInt32Type>(),
                    lag.as_primitive::<Float64Type>(),
                    val.as_primitive::<Float64Type>(),
                );
                for i in 0..b.num_rows() {
                    let p = point.value(i);
                    if p < p0 || p >= p1 || finished.get(&run.value(i)) != Some(&RunStatus::Done) {
                        continue;
                    }
                    acc.entry((p, sp.value(i), lag.value(i).to_bits()))
                        .or_default()
                        .push(((run.value(i) % replicas) as u32, val.value(i)));
                }
            }
        }
        let mut order: Vec<TamsdKey> = acc.keys().copied().collect();
        order.sort_by(|a, b| {
            (a.0, a.1, f64::from_bits(a.2))
                .partial_cmp(&(b.0, b.1, f64::from_bits(b.2)))
                .expect("finite lags")
        });
        for key in order {
            let (n, mean, sem) = replica_mean_sem(acc.remove(&key).expect("key"));
            cols.point.push(key.0);
            cols.species.push(key.1);
            cols.lag.push(f64::from_bits(key.2));
            cols.n.push(n);
            cols.mean.push(mean);
            cols.sem.push(sem);
            cols.theory.push(theory.get(&key).copied());
        }
        p0 = p1;
    }
    write_whole(
        c,
        tables::DSMC_TAMSD_SUMMARY,
        "summary.parquet",
        &cols.finish(),
    )
}

/// Theory (27) by (point, species, lag bits), if the table exists.
fn read_tamsd_theory(c: &Campaign) -> Result<BTreeMap<TamsdKey, f64>, StoreError> {
    let mut out = BTreeMap::new();
    for f in table_files(c, tables::DSMC_THEORY_TAMSD)? {
        for b in parquet_io::read_campaign_file(&f, tables::DSMC_THEORY_TAMSD, &c.manifest_json)? {
            let col = |name: &str| {
                b.column_by_name(name).cloned().ok_or_else(|| {
                    StoreError::Corrupt(f.display().to_string(), format!("has no column {name}"))
                })
            };
            let (p, s, l, v) = (
                col("point_id")?,
                col("species")?,
                col("lag")?,
                col("tamsd")?,
            );
            let (p, s, l, v) = (
                p.as_primitive::<UInt32Type>(),
                s.as_primitive::<UInt32Type>(),
                l.as_primitive::<Float64Type>(),
                v.as_primitive::<Float64Type>(),
            );
            for i in 0..b.num_rows() {
                out.insert((p.value(i), s.value(i), l.value(i).to_bits()), v.value(i));
            }
        }
    }
    Ok(out)
}

#[derive(Default)]
struct TamsdSummaryColumns {
    point: Vec<u32>,
    species: Vec<u32>,
    lag: Vec<f64>,
    n: Vec<u32>,
    mean: Vec<f64>,
    sem: Vec<Option<f64>>,
    theory: Vec<Option<f64>>,
}

impl TamsdSummaryColumns {
    fn finish(self) -> RecordBatch {
        let schema = Schema::new(vec![
            Field::new("point_id", DataType::UInt32, false),
            Field::new("species", DataType::UInt32, false),
            Field::new("lag", DataType::Float64, false),
            Field::new("n_replicas", DataType::UInt32, false),
            Field::new("tamsd_mean", DataType::Float64, false),
            Field::new("tamsd_sem", DataType::Float64, true),
            Field::new("tamsd_theory", DataType::Float64, true),
        ]);
        let arrays: Vec<ArrayRef> = vec![
            Arc::new(arrow_array::UInt32Array::from(self.point)),
            Arc::new(arrow_array::UInt32Array::from(self.species)),
            Arc::new(arrow_array::Float64Array::from(self.lag)),
            Arc::new(arrow_array::UInt32Array::from(self.n)),
            Arc::new(arrow_array::Float64Array::from(self.mean)),
            Arc::new(arrow_array::Float64Array::from(self.sem)),
            Arc::new(arrow_array::Float64Array::from(self.theory)),
        ];
        RecordBatch::try_new(Arc::new(schema), arrays)
            .expect("tamsd summary batch matches its schema")
    }
}

#[derive(Default)]
struct SummaryColumns {
    point: Vec<u32>,
    t: Vec<f64>,
    species: Vec<u32>,
    n: Vec<u32>,
    tm: Vec<f64>,
    ts: Vec<Option<f64>>,
    mm: Vec<Option<f64>>,
    ms: Vec<Option<f64>>,
    t_th: Vec<Option<f64>>,
    m_th: Vec<Option<f64>>,
}

/// (mean - theory) / sem and (mean - theory) / theory.
fn deviations(
    mean: Option<f64>,
    sem: Option<f64>,
    theory: Option<f64>,
) -> (Option<f64>, Option<f64>) {
    match (mean, theory) {
        (Some(m), Some(t)) => (
            sem.filter(|s| *s > 0.0).map(|s| (m - t) / s),
            (t != 0.0).then(|| (m - t) / t),
        ),
        _ => (None, None),
    }
}

/// Theory values (temperature, msd) by (point, t bits, species), if the table exists.
fn read_theory(c: &Campaign) -> Result<BTreeMap<Key, (f64, Option<f64>)>, StoreError> {
    let mut out = BTreeMap::new();
    for f in table_files(c, tables::DSMC_THEORY)? {
        for b in parquet_io::read_campaign_file(&f, tables::DSMC_THEORY, &c.manifest_json)? {
            let col = |name: &str| {
                b.column_by_name(name).cloned().ok_or_else(|| {
                    StoreError::Corrupt(f.display().to_string(), format!("has no column {name}"))
                })
            };
            let (p, t, s, tt, m) = (
                col("point_id")?,
                col("t")?,
                col("species")?,
                col("temperature")?,
                col("msd")?,
            );
            let (p, t, s, tt, m) = (
                p.as_primitive::<UInt32Type>(),
                t.as_primitive::<Float64Type>(),
                s.as_primitive::<UInt32Type>(),
                tt.as_primitive::<Float64Type>(),
                m.as_primitive::<Float64Type>(),
            );
            for i in 0..b.num_rows() {
                let msd = if arrow_array::Array::is_null(m, i) {
                    None
                } else {
                    Some(m.value(i))
                };
                out.insert(
                    (p.value(i), t.value(i).to_bits(), s.value(i)),
                    (tt.value(i), msd),
                );
            }
        }
    }
    Ok(out)
}

impl SummaryColumns {
    #[allow(clippy::too_many_arguments)]
    fn push(
        &mut self,
        p: u32,
        t: f64,
        s: u32,
        n: u32,
        tm: f64,
        ts: Option<f64>,
        mm: Option<f64>,
        ms: Option<f64>,
        th: Option<(f64, Option<f64>)>,
    ) {
        self.t_th.push(th.map(|x| x.0));
        self.m_th.push(th.and_then(|x| x.1));
        self.point.push(p);
        self.t.push(t);
        self.species.push(s);
        self.n.push(n);
        self.tm.push(tm);
        self.ts.push(ts);
        self.mm.push(mm);
        self.ms.push(ms);
    }

    fn finish(self) -> RecordBatch {
        let schema = Schema::new(vec![
            Field::new("point_id", DataType::UInt32, false),
            Field::new("t", DataType::Float64, false),
            Field::new("species", DataType::UInt32, false),
            Field::new("n_replicas", DataType::UInt32, false),
            Field::new("temperature_mean", DataType::Float64, false),
            Field::new("temperature_sem", DataType::Float64, true),
            Field::new("msd_mean", DataType::Float64, true),
            Field::new("msd_sem", DataType::Float64, true),
            Field::new("temperature_theory", DataType::Float64, true),
            Field::new("msd_theory", DataType::Float64, true),
            Field::new("temperature_dev_sigma", DataType::Float64, true),
            Field::new("temperature_dev_rel", DataType::Float64, true),
            Field::new("msd_dev_sigma", DataType::Float64, true),
            Field::new("msd_dev_rel", DataType::Float64, true),
        ]);
        let n = self.point.len();
        let (mut tds, mut tdr, mut mds, mut mdr) = (
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
        );
        for j in 0..n {
            let (a, b) = deviations(Some(self.tm[j]), self.ts[j], self.t_th[j]);
            tds.push(a);
            tdr.push(b);
            let (a, b) = deviations(self.mm[j], self.ms[j], self.m_th[j]);
            mds.push(a);
            mdr.push(b);
        }
        let arrays: Vec<ArrayRef> = vec![
            Arc::new(arrow_array::UInt32Array::from(self.point)),
            Arc::new(arrow_array::Float64Array::from(self.t)),
            Arc::new(arrow_array::UInt32Array::from(self.species)),
            Arc::new(arrow_array::UInt32Array::from(self.n)),
            Arc::new(arrow_array::Float64Array::from(self.tm)),
            Arc::new(arrow_array::Float64Array::from(self.ts)),
            Arc::new(arrow_array::Float64Array::from(self.mm)),
            Arc::new(arrow_array::Float64Array::from(self.ms)),
            Arc::new(arrow_array::Float64Array::from(self.t_th)),
            Arc::new(arrow_array::Float64Array::from(self.m_th)),
            Arc::new(arrow_array::Float64Array::from(tds)),
            Arc::new(arrow_array::Float64Array::from(tdr)),
            Arc::new(arrow_array::Float64Array::from(mds)),
            Arc::new(arrow_array::Float64Array::from(mdr)),
        ];
        RecordBatch::try_new(Arc::new(schema), arrays).expect("summary batch matches its schema")
    }
}
