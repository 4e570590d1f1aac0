//! Replica summary of the auxiliary models: `cascade_structure_factor_summary` (point, source,
//! shell): the mean over the finished replicas of each run's S(k) (runs of a point have the
//! same number of realisations), with the standard error propagated from the runs' own
//! (realisation-to-realisation) errors, sqrt(sum sem_r^2) / n, so it exists with one replica
//! too (runs without an error, the placement's single configuration, use the replicas'
//! spread instead). Columns as `rfm_structure_factor_summary` plus `source` and `n_realisations`.
//! Rewritten whole and atomically when the campaign completes; summed in replica order.

use std::collections::BTreeMap;
use std::sync::Arc;

use arrow_array::cast::AsArray;
use arrow_array::types::{Float64Type, UInt32Type, UInt64Type};
use arrow_array::{Array, RecordBatch};
use arrow_schema::{DataType, Field, Schema};

use super::aux_tables::{CASCADE_STRUCTURE_FACTOR, CASCADE_STRUCTURE_FACTOR_SUMMARY};
use super::parquet_io::{self, StoreError};
use super::summary::{table_files, write_whole};
use super::tables::cols;
use crate::campaign::ledger::RunStatus;
use crate::campaign::Campaign;
use crate::manifest::ModelKind;

/// One run's shell: (replica, k, n_vectors, n_realisations, s_mean, s_sem).
type Shell = (u64, f64, u64, u64, f64, Option<f64>);

pub fn write_aux_summaries(
    c: &Campaign,
    finished: &BTreeMap<u64, RunStatus>,
) -> Result<(), StoreError> {
    if c.plan.model != ModelKind::Cascade {
        return Ok(());
    }
    let replicas = c.plan.replicas as u64;
    let done = |run: u64| finished.get(&run) == Some(&RunStatus::Done);
    let mut g: BTreeMap<(u32, String, u64), Vec<Shell>> = BTreeMap::new();
    for f in table_files(c, CASCADE_STRUCTURE_FACTOR)? {
        for b in parquet_io::read_campaign_file(&f, CASCADE_STRUCTURE_FACTOR, &c.manifest_json)? {
            let col = |name: &str| {
                b.column_by_name(name).cloned().ok_or_else(|| {
                    StoreError::Corrupt(f.display().to_string(), format!("has no column {name}"))
                })
            };
            let (r, p, src, n2, k, nv, nr, s, se) = (
                col("run_id")?,
                col("point_id")?,
                col("source")?,
                col("n2")?,
                col("k")?,
                col("n_vectors")?,
                col("n_realisations")?,
                col("s_mean")?,
                col("s_sem")?,
            );
            let (r, p, src, n2, k, nv, nr, s, sea) = (
                r.as_primitive::<UInt64Type>(),
                p.as_primitive::<UInt32Type>(),
                src.as_string::<i32>(),
                n2.as_primitive::<UInt64Type>(),
                k.as_primitive::<Float64Type>(),
                nv.as_primitive::<UInt64Type>(),
                nr.as_primitive::<UInt64Type>(),
                s.as_primitive::<Float64Type>(),
                se.as_primitive::<Float64Type>(),
            );
            for i in 0..b.num_rows() {
                if !done(r.value(i)) {
                    continue;
                }
                let sem = (!sea.is_null(i)).then(|| sea.value(i));
                g.entry((p.value(i), src.value(i).to_string(), n2.value(i)))
                    .or_default()
                    .push((
                        r.value(i) % replicas,
                        k.value(i),
                        nv.value(i),
                        nr.value(i),
                        s.value(i),
                        sem,
                    ));
            }
        }
    }
    let rows: Vec<_> = g
        .into_iter()
        .map(|(key, mut v)| {
            v.sort_by_key(|x| x.0);
            v.dedup_by_key(|x| x.0);
            let n = v.len() as f64;
            let mean = v.iter().map(|x| x.4).sum::<f64>() / n;
            let xs: Vec<f64> = v.iter().map(|x| x.4).collect();
            let sem = v
                .iter()
                .map(|x| x.5.map(|s| s * s))
                .sum::<Option<f64>>()
                .map(|s2| s2.sqrt() / n)
                .or_else(|| super::summary::mean_sem(&xs).1);
            let real: u64 = v.iter().map(|x| x.3).sum();
            (key, v[0].1, v[0].2, v.len() as u32, real, mean, sem)
        })
        .collect();
    let batch = RecordBatch::try_new(
        Arc::new(Schema::new(vec![
            Field::new("point_id", DataType::UInt32, false),
            Field::new("source", DataType::Utf8, false),
            Field::new("n2", DataType::UInt64, false),
            Field::new("k", DataType::Float64, false),
            Field::new("n_vectors", DataType::UInt64, false),
            Field::new("n_replicas", DataType::UInt32, false),
            Field::new("n_realisations", DataType::UInt64, false),
            Field::new("s_mean", DataType::Float64, false),
            Field::new("s_sem", DataType::Float64, true),
        ])),
        vec![
            cols::u32s(&rows, |r| r.0 .0),
            cols::strs(&rows, |r| r.0 .1.as_str()),
            cols::u64s(&rows, |r| r.0 .2),
            cols::f64s(&rows, |r| r.1),
            cols::u64s(&rows, |r| r.2),
            cols::u32s(&rows, |r| r.3),
            cols::u64s(&rows, |r| r.4),
            cols::f64s(&rows, |r| r.5),
            cols::opt_f64s(&rows, |r| r.6),
        ],
    )
    .expect("cascade structure factor summary");
    write_whole(
        c,
        CASCADE_STRUCTURE_FACTOR_SUMMARY,
        "summary.parquet",
        &batch,
    )
}
