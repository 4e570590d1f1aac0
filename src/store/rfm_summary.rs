//! Ensemble summaries of RFM campaigns over replicas (runs with `status = 'done'`), summed in
//! replica order: `rfm_timeseries_summary` (point, t: temperature mean and sem),
//! `rfm_moments_summary` (point, order: mean and sem of the runs' moments) and
//! `rfm_histograms_summary` (point, kind, h, bin: counts summed, pooled density),
//! `rfm_neighbour_moments_summary` (point, h, order: mean and sem of the runs' moments),
//! `rfm_free_path_moments_summary` (point, order: mean and sem of the runs' <l^m>, paths
//! summed),
//! `rfm_structure_factor_summary` (point, shell: mean and sem of the runs' S(k)) and
//! `rfm_radial_distribution_summary` (point, bin: pair counts summed, mean and sem of g and C).

use std::collections::BTreeMap;
use std::sync::Arc;

use arrow_array::cast::AsArray;
use arrow_array::types::{Float64Type, UInt32Type, UInt64Type};
use arrow_array::{ArrayRef, RecordBatch};
use arrow_schema::{DataType, Field, Schema};

use super::parquet_io::StoreError;
use super::summary::{campaign_batches as batches, mean_sem, replica_mean_sem, write_whole};
use super::tables;
use super::tables::cols;
use crate::campaign::ledger::RunStatus;
use crate::campaign::Campaign;

fn col<'a>(b: &'a RecordBatch, name: &str) -> Result<&'a ArrayRef, StoreError> {
    b.column_by_name(name)
        .ok_or_else(|| StoreError::Corrupt(name.into(), "missing column".into()))
}

/// Per key: the replicas' values (each a fixed-length vector), sorted by replica.
type Groups<K> = BTreeMap<K, Vec<(u64, Vec<f64>)>>;

/// Mean and sem over replicas of each value column of a group (for columns that are the
/// same in every replica, such as k or r_lo, the first replica's value is used).
fn stats(mut v: Vec<(u64, Vec<f64>)>) -> (u32, Vec<(f64, Option<f64>)>) {
    v.sort_by_key(|x| x.0);
    let n = v.len() as u32;
    let cols = v.first().map_or(0, |x| x.1.len());
    let out = (0..cols)
        .map(|j| {
            let xs: Vec<f64> = v.iter().map(|x| x.1[j]).collect();
            if xs.iter().all(|&a| a.to_bits() == xs[0].to_bits()) {
                (xs[0], Some(0.0).filter(|_| xs.len() >= 2))
            } else {
                mean_sem(&xs)
            }
        })
        .collect();
    (n, out)
}

fn f64s(v: impl IntoIterator<Item = f64>) -> ArrayRef {
    Arc::new(v.into_iter().collect::<arrow_array::Float64Array>())
}
fn opt_f64s(v: impl IntoIterator<Item = Option<f64>>) -> ArrayRef {
    Arc::new(v.into_iter().collect::<arrow_array::Float64Array>())
}
fn u32s(v: impl IntoIterator<Item = u32>) -> ArrayRef {
    Arc::new(v.into_iter().collect::<arrow_array::UInt32Array>())
}
fn u64s(v: impl IntoIterator<Item = u64>) -> ArrayRef {
    Arc::new(v.into_iter().collect::<arrow_array::UInt64Array>())
}

fn write_structure_summaries(
    c: &Campaign,
    present: &[&str],
    replicas: u64,
    done: &dyn Fn(u64) -> bool,
) -> Result<(), StoreError> {
    if present.contains(&tables::RFM_FREE_PATH_MOMENTS) {
        let mut g: Groups<(u32, u32)> = BTreeMap::new();
        for b in batches(c, tables::RFM_FREE_PATH_MOMENTS)? {
            let (r, p, o, v, n) = (
                col(&b, "run_id")?.as_primitive::<UInt64Type>(),
                col(&b, "point_id")?.as_primitive::<UInt32Type>(),
                col(&b, "order")?.as_primitive::<UInt32Type>(),
                col(&b, "value")?.as_primitive::<Float64Type>(),
                col(&b, "n_paths")?.as_primitive::<UInt64Type>(),
            );
            for i in 0..b.num_rows() {
                if done(r.value(i)) {
                    g.entry((p.value(i), o.value(i)))
                        .or_default()
                        .push((r.value(i) % replicas, vec![v.value(i), n.value(i) as f64]));
                }
            }
        }
        let rows: Vec<_> = g
            .into_iter()
            .map(|(k, v)| {
                let paths: f64 = v.iter().map(|x| x.1[1]).sum();
                (k, stats(v), paths as u64)
            })
            .collect();
        let batch = RecordBatch::try_new(
            Arc::new(Schema::new(vec![
                Field::new("point_id", DataType::UInt32, false),
                Field::new("order", DataType::UInt32, false),
                Field::new("n_replicas", DataType::UInt32, false),
                Field::new("mean", DataType::Float64, false),
                Field::new("sem", DataType::Float64, true),
                Field::new("n_paths", DataType::UInt64, false),
            ])),
            vec![
                u32s(rows.iter().map(|r| r.0 .0)),
                u32s(rows.iter().map(|r| r.0 .1)),
                u32s(rows.iter().map(|r| r.1 .0)),
                f64s(rows.iter().map(|r| r.1 .1[0].0)),
                opt_f64s(rows.iter().map(|r| r.1 .1[0].1)),
                u64s(rows.iter().map(|r| r.2)),
            ],
        )
        .expect("free-path moments summary");
        write_whole(
            c,
            tables::RFM_FREE_PATH_MOMENTS_SUMMARY,
            "summary.parquet",
            &batch,
        )?;
    }
    if present.contains(&tables::RFM_NEIGHBOUR_MOMENTS) {
        let mut g: Groups<(u32, u32, u32)> = BTreeMap::new();
        for b in batches(c, tables::RFM_NEIGHBOUR_MOMENTS)? {
            let (r, p, h, o, v) = (
                col(&b, "run_id")?.as_primitive::<UInt64Type>(),
                col(&b, "point_id")?.as_primitive::<UInt32Type>(),
                col(&b, "h")?.as_primitive::<UInt32Type>(),
                col(&b, "order")?.as_primitive::<UInt32Type>(),
                col(&b, "value")?.as_primitive::<Float64Type>(),
            );
            for i in 0..b.num_rows() {
                if done(r.value(i)) {
                    g.entry((p.value(i), h.value(i), o.value(i)))
                        .or_default()
                        .push((r.value(i) % replicas, vec![v.value(i)]));
                }
            }
        }
        let rows: Vec<_> = g.into_iter().map(|(k, v)| (k, stats(v))).collect();
        let batch = RecordBatch::try_new(
            Arc::new(Schema::new(vec![
                Field::new("point_id", DataType::UInt32, false),
                Field::new("h", DataType::UInt32, false),
                Field::new("order", DataType::UInt32, false),
                Field::new("n_replicas", DataType::UInt32, false),
                Field::new("mean", DataType::Float64, false),
                Field::new("sem", DataType::Float64, true),
            ])),
            vec![
                u32s(rows.iter().map(|r| r.0 .0)),
                u32s(rows.iter().map(|r| r.0 .1)),
                u32s(rows.iter().map(|r| r.0 .2)),
                u32s(rows.iter().map(|r| r.1 .0)),
                f64s(rows.iter().map(|r| r.1 .1[0].0)),
                opt_f64s(rows.iter().map(|r| r.1 .1[0].1)),
            ],
        )
        .expect("neighbour moments summary");
        write_whole(
            c,
            tables::RFM_NEIGHBOUR_MOMENTS_SUMMARY,
            "summary.parquet",
            &batch,
        )?;
    }

    if present.contains(&tables::RFM_STRUCTURE_FACTOR) {
        // (point, n2) -> values [k, n_vectors, s].
        let mut g: Groups<(u32, u64)> = BTreeMap::new();
        for b in batches(c, tables::RFM_STRUCTURE_FACTOR)? {
            let (r, p, n2, k, nv, s) = (
                col(&b, "run_id")?.as_primitive::<UInt64Type>(),
                col(&b, "point_id")?.as_primitive::<UInt32Type>(),
                col(&b, "n2")?.as_primitive::<UInt64Type>(),
                col(&b, "k")?.as_primitive::<Float64Type>(),
                col(&b, "n_vectors")?.as_primitive::<UInt64Type>(),
                col(&b, "s")?.as_primitive::<Float64Type>(),
            );
            for i in 0..b.num_rows() {
                if done(r.value(i)) {
                    g.entry((p.value(i), n2.value(i))).or_default().push((
                        r.value(i) % replicas,
                        vec![k.value(i), nv.value(i) as f64, s.value(i)],
                    ));
                }
            }
        }
        let rows: Vec<_> = g.into_iter().map(|(k, v)| (k, stats(v))).collect();
        let batch = RecordBatch::try_new(
            Arc::new(Schema::new(vec![
                Field::new("point_id", DataType::UInt32, false),
                Field::new("n2", DataType::UInt64, false),
                Field::new("k", DataType::Float64, false),
                Field::new("n_vectors", DataType::UInt64, false),
                Field::new("n_replicas", DataType::UInt32, false),
                Field::new("s_mean", DataType::Float64, false),
                Field::new("s_sem", DataType::Float64, true),
            ])),
            vec![
                u32s(rows.iter().map(|r| r.0 .0)),
                u64s(rows.iter().map(|r| r.0 .1)),
                f64s(rows.iter().map(|r| r.1 .1[0].0)),
                u64s(rows.iter().map(|r| r.1 .1[1].0 as u64)),
                u32s(rows.iter().map(|r| r.1 .0)),
                f64s(rows.iter().map(|r| r.1 .1[2].0)),
                opt_f64s(rows.iter().map(|r| r.1 .1[2].1)),
            ],
        )
        .expect("structure factor summary");
        write_whole(
            c,
            tables::RFM_STRUCTURE_FACTOR_SUMMARY,
            "summary.parquet",
            &batch,
        )?;
    }

    if present.contains(&tables::RFM_RADIAL) {
        // (point, bin index from r_lo order) -> values [r_lo, r_hi, count, g, c].
        let mut g: Groups<(u32, u64)> = BTreeMap::new();
        for b in batches(c, tables::RFM_RADIAL)? {
            let (r, p, lo, hi, n, gv, cv) = (
                col(&b, "run_id")?.as_primitive::<UInt64Type>(),
                col(&b, "point_id")?.as_primitive::<UInt32Type>(),
                col(&b, "r_lo")?.as_primitive::<Float64Type>(),
                col(&b, "r_hi")?.as_primitive::<Float64Type>(),
                col(&b, "count")?.as_primitive::<UInt64Type>(),
                col(&b, "g")?.as_primitive::<Float64Type>(),
                col(&b, "c")?.as_primitive::<Float64Type>(),
            );
            for i in 0..b.num_rows() {
                if done(r.value(i)) {
                    // r_lo >= 0, so its bits order like the values.
                    g.entry((p.value(i), lo.value(i).to_bits()))
                        .or_default()
                        .push((
                            r.value(i) % replicas,
                            vec![
                                lo.value(i),
                                hi.value(i),
                                n.value(i) as f64,
                                gv.value(i),
                                cv.value(i),
                            ],
                        ));
                }
            }
        }
        let rows: Vec<_> = g
            .into_iter()
            .map(|(k, v)| {
                let total: u64 = v.iter().map(|x| x.1[2] as u64).sum();
                (k, total, stats(v))
            })
            .collect();
        let batch = RecordBatch::try_new(
            Arc::new(Schema::new(vec![
                Field::new("point_id", DataType::UInt32, false),
                Field::new("r_lo", DataType::Float64, false),
                Field::new("r_hi", DataType::Float64, false),
                Field::new("n_replicas", DataType::UInt32, false),
                Field::new("count", DataType::UInt64, false),
                Field::new("g_mean", DataType::Float64, false),
                Field::new("g_sem", DataType::Float64, true),
                Field::new("c_mean", DataType::Float64, false),
                Field::new("c_sem", DataType::Float64, true),
            ])),
            vec![
                u32s(rows.iter().map(|r| r.0 .0)),
                f64s(rows.iter().map(|r| r.2 .1[0].0)),
                f64s(rows.iter().map(|r| r.2 .1[1].0)),
                u32s(rows.iter().map(|r| r.2 .0)),
                u64s(rows.iter().map(|r| r.1)),
                f64s(rows.iter().map(|r| r.2 .1[3].0)),
                opt_f64s(rows.iter().map(|r| r.2 .1[3].1)),
                f64s(rows.iter().map(|r| r.2 .1[4].0)),
                opt_f64s(rows.iter().map(|r| r.2 .1[4].1)),
            ],
        )
        .expect("radial distribution summary");
        write_whole(c, tables::RFM_RADIAL_SUMMARY, "summary.parquet", &batch)?;
    }
    Ok(())
}

pub fn write_rfm_summaries(
    c: &Campaign,
    finished: &BTreeMap<u64, RunStatus>,
) -> Result<(), StoreError> {
    let replicas = c.plan.replicas as u64;
    let done = |run: u64| finished.get(&run) == Some(&RunStatus::Done);
    let present = c.rfm_tables();

    // Time series: (point, t bits) -> [(replica, T)].
    let mut ts: BTreeMap<(u32, u64), Vec<(u64, f64)>> = BTreeMap::new();
    for b in batches(c, tables::RFM_TIMESERIES)? {
        let (r, p, t, v) = (
            col(&b, "run_id")?.as_primitive::<UInt64Type>(),
            col(&b, "point_id")?.as_primitive::<UInt32Type>(),
            col(&b, "t")?.as_primitive::<Float64Type>(),
            col(&b, "temperature")?.as_primitive::<Float64Type>(),
        );
        for i in 0..b.num_rows() {
            if done(r.value(i)) {
                ts.entry((p.value(i), t.value(i).to_bits()))
                    .or_default()
                    .push((r.value(i) % replicas, v.value(i)));
            }
        }
    }
    let mut keys: Vec<(u32, u64)> = ts.keys().copied().collect();
    keys.sort_by(|a, b| {
        (a.0, f64::from_bits(a.1))
            .partial_cmp(&(b.0, f64::from_bits(b.1)))
            .expect("finite")
    });
    let (mut pc, mut tc, mut nc, mut mc, mut sc) = (vec![], vec![], vec![], vec![], vec![]);
    for k in keys {
        let (n, m, s) = replica_mean_sem(ts.remove(&k).expect("key"));
        pc.push(k.0);
        tc.push(f64::from_bits(k.1));
        nc.push(n);
        mc.push(m);
        sc.push(s);
    }
    let batch = RecordBatch::try_new(
        Arc::new(Schema::new(vec![
            Field::new("point_id", DataType::UInt32, false),
            Field::new("t", DataType::Float64, false),
            Field::new("n_replicas", DataType::UInt32, false),
            Field::new("temperature_mean", DataType::Float64, false),
            Field::new("temperature_sem", DataType::Float64, true),
        ])),
        vec![
            Arc::new(arrow_array::UInt32Array::from(pc)),
            Arc::new(arrow_array::Float64Array::from(tc)),
            Arc::new(arrow_array::UInt32Array::from(nc)),
            Arc::new(arrow_array::Float64Array::from(mc)),
            Arc::new(arrow_array::Float64Array::from(sc)),
        ],
    )
    .expect("timeseries summary");
    write_whole(c, tables::RFM_TIMESERIES_SUMMARY, "summary.parquet", &batch)?;

    if present.contains(&tables::RFM_MOMENTS) {
        let mut mo: BTreeMap<(u32, u32), Vec<(u64, f64)>> = BTreeMap::new();
        for b in batches(c, tables::RFM_MOMENTS)? {
            let (r, p, o, v) = (
                col(&b, "run_id")?.as_primitive::<UInt64Type>(),
                col(&b, "point_id")?.as_primitive::<UInt32Type>(),
                col(&b, "order")?.as_primitive::<UInt32Type>(),
                col(&b, "value")?.as_primitive::<Float64Type>(),
            );
            for i in 0..b.num_rows() {
                if done(r.value(i)) {
                    mo.entry((p.value(i), o.value(i)))
                        .or_default()
                        .push((r.value(i) % replicas, v.value(i)));
                }
            }
        }
        let (mut pc, mut oc, mut nc, mut mc, mut sc) = (vec![], vec![], vec![], vec![], vec![]);
        for (k, v) in mo {
            let (n, m, s) = replica_mean_sem(v);
            pc.push(k.0);
            oc.push(k.1);
            nc.push(n);
            mc.push(m);
            sc.push(s);
        }
        let batch = RecordBatch::try_new(
            Arc::new(Schema::new(vec![
                Field::new("point_id", DataType::UInt32, false),
                Field::new("order", DataType::UInt32, false),
                Field::new("n_replicas", DataType::UInt32, false),
                Field::new("mean", DataType::Float64, false),
                Field::new("sem", DataType::Float64, true),
            ])),
            vec![
                Arc::new(arrow_array::UInt32Array::from(pc)),
                Arc::new(arrow_array::UInt32Array::from(oc)),
                Arc::new(arrow_array::UInt32Array::from(nc)),
                Arc::new(arrow_array::Float64Array::from(mc)),
                Arc::new(arrow_array::Float64Array::from(sc)),
            ],
        )
        .expect("moments summary");
        write_whole(c, tables::RFM_MOMENTS_SUMMARY, "summary.parquet", &batch)?;
    }

    if present.contains(&tables::RFM_HISTOGRAMS) {
        // (point, kind, h, lo bits) -> (hi, summed count); totals per (point, kind, h).
        type HKey = (u32, String, u32, u64);
        let mut bins: BTreeMap<HKey, (f64, u64)> = BTreeMap::new();
        let mut totals: BTreeMap<(u32, String, u32), u64> = BTreeMap::new();
        for b in batches(c, tables::RFM_HISTOGRAMS)? {
            let (r, p, kind, h, lo, hi, n) = (
                col(&b, "run_id")?.as_primitive::<UInt64Type>(),
                col(&b, "point_id")?.as_primitive::<UInt32Type>(),
                col(&b, "kind")?.as_string::<i32>(),
                col(&b, "h")?.as_primitive::<UInt32Type>(),
                col(&b, "lo")?.as_primitive::<Float64Type>(),
                col(&b, "hi")?.as_primitive::<Float64Type>(),
                col(&b, "count")?.as_primitive::<UInt64Type>(),
            );
            for i in 0..b.num_rows() {
                if !done(r.value(i)) {
                    continue;
                }
                let k = (
                    p.value(i),
                    kind.value(i).to_string(),
                    h.value(i),
                    lo.value(i).to_bits(),
                );
                let e = bins.entry(k).or_insert((hi.value(i), 0));
                e.1 += n.value(i);
                *totals
                    .entry((p.value(i), kind.value(i).to_string(), h.value(i)))
                    .or_default() += n.value(i);
            }
        }
        let mut rows: Vec<(HKey, (f64, u64))> = bins.into_iter().collect();
        rows.sort_by(|a, b| {
            (a.0 .0, &a.0 .1, a.0 .2, f64::from_bits(a.0 .3))
                .partial_cmp(&(b.0 .0, &b.0 .1, b.0 .2, f64::from_bits(b.0 .3)))
                .expect("ordered")
        });
        let density = |k: &HKey, v: &(f64, u64)| {
            let lo = f64::from_bits(k.3);
            let width = v.0 - lo;
            let total = totals[&(k.0, k.1.clone(), k.2)];
            (width.is_finite() && total > 0).then(|| v.1 as f64 / (total as f64 * width))
        };
        let batch = RecordBatch::try_new(
            Arc::new(Schema::new(vec![
                Field::new("point_id", DataType::UInt32, false),
                Field::new("kind", DataType::Utf8, false),
                Field::new("h", DataType::UInt32, false),
                Field::new("lo", DataType::Float64, false),
                Field::new("hi", DataType::Float64, false),
                Field::new("count", DataType::UInt64, false),
                Field::new("density", DataType::Float64, true),
            ])),
            vec![
                cols::u32s(&rows, |r| r.0 .0),
                cols::strs(&rows, |r| r.0 .1.as_str()),
                cols::u32s(&rows, |r| r.0 .2),
                cols::f64s(&rows, |r| f64::from_bits(r.0 .3)),
                cols::f64s(&rows, |r| r.1 .0),
                cols::u64s(&rows, |r| r.1 .1),
                cols::opt_f64s(&rows, |r| density(&r.0, &r.1)),
            ],
        )
        .expect("histogram summary");
        write_whole(c, tables::RFM_HISTOGRAMS_SUMMARY, "summary.parquet", &batch)?;
    }
    write_structure_summaries(c, &present, replicas, &done)
}
