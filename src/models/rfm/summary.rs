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

use arrow_array::RecordBatch;

use super::params::RfmParams;
use super::tables::*;
use crate::math::stats::{mean_sem, replica_mean_sem};
use crate::models::CampaignView;
use crate::store::cols::{get_f64, get_str, get_u32, get_u64, table};
use crate::store::parquet_io::StoreError;

type View<'a, 'b> = &'a CampaignView<'b, RfmParams>;

/// Write the summaries of the raw tables the campaign has.
pub fn write(c: View, present: &[&str]) -> Result<(), StoreError> {
    timeseries(c)?;
    type Summary = fn(View) -> Result<(), StoreError>;
    let summaries: [(&str, Summary); 6] = [
        (RFM_MOMENTS, moments),
        (RFM_HISTOGRAMS, histograms),
        (RFM_FREE_PATH_MOMENTS, free_path_moments),
        (RFM_NEIGHBOUR_MOMENTS, neighbour_moments),
        (RFM_STRUCTURE_FACTOR, structure_factor),
        (RFM_RADIAL, radial),
    ];
    for (raw, summarise) in summaries {
        if present.contains(&raw) {
            summarise(c)?;
        }
    }
    Ok(())
}

/// Per key: the replicas' values (each a fixed-length vector).
type Groups<K> = BTreeMap<K, Vec<(u64, Vec<f64>)>>;

/// A batch with the replica of each row (None: the run is not done).
type DoneBatch = (RecordBatch, Vec<Option<u64>>);

/// Every batch of `table` with the replicas of its rows.
fn done_batches(c: View, table: &str) -> Result<Vec<DoneBatch>, StoreError> {
    c.data
        .read(table)?
        .into_iter()
        .map(|b| {
            let runs = get_u64(&b, table, "run_id")?;
            let replicas = runs
                .iter()
                .map(|r| r.and_then(|r| c.done.get(&r)).map(|&x| x as u64))
                .collect();
            Ok((b, replicas))
        })
        .collect()
}

/// Mean and sem over replicas of each value column of a group, in replica order (for columns
/// that are the same in every replica, such as k or r_lo, the first replica's value is used).
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

fn write_summary(c: View, name: &str, batch: RecordBatch) -> Result<(), StoreError> {
    c.write_summary(name, &batch)
}

/// (point, t) -> temperature mean and sem over replicas.
fn timeseries(c: View) -> Result<(), StoreError> {
    let mut ts: BTreeMap<(u32, u64), Vec<(u64, f64)>> = BTreeMap::new();
    for (b, rep) in done_batches(c, RFM_TIMESERIES)? {
        let p = get_u32(&b, RFM_TIMESERIES, "point_id")?;
        let t = get_f64(&b, RFM_TIMESERIES, "t")?;
        let v = get_f64(&b, RFM_TIMESERIES, "temperature")?;
        for (i, r) in rep.iter().enumerate() {
            if let Some(r) = r {
                ts.entry((p.value(i), t.value(i).to_bits()))
                    .or_default()
                    .push((*r, v.value(i)));
            }
        }
    }
    let mut keys: Vec<(u32, u64)> = ts.keys().copied().collect();
    keys.sort_by(|a, b| {
        (a.0, f64::from_bits(a.1))
            .partial_cmp(&(b.0, f64::from_bits(b.1)))
            .expect("finite")
    });
    let rows: Vec<_> = keys
        .into_iter()
        .map(|k| (k, replica_mean_sem(ts.remove(&k).expect("key"))))
        .collect();
    write_summary(
        c,
        RFM_TIMESERIES_SUMMARY,
        table(&rows, |col| {
            vec![
                col.u32("point_id", |r| r.0 .0),
                col.f64("t", |r| f64::from_bits(r.0 .1)),
                col.u32("n_replicas", |r| r.1 .0),
                col.f64("temperature_mean", |r| r.1 .1),
                col.opt_f64("temperature_sem", |r| r.1 .2),
            ]
        }),
    )
}

/// (point, order) -> mean and sem of the runs' velocity moments.
fn moments(c: View) -> Result<(), StoreError> {
    let mut mo: BTreeMap<(u32, u32), Vec<(u64, f64)>> = BTreeMap::new();
    for (b, rep) in done_batches(c, RFM_MOMENTS)? {
        let p = get_u32(&b, RFM_MOMENTS, "point_id")?;
        let o = get_u32(&b, RFM_MOMENTS, "order")?;
        let v = get_f64(&b, RFM_MOMENTS, "value")?;
        for (i, r) in rep.iter().enumerate() {
            if let Some(r) = r {
                mo.entry((p.value(i), o.value(i)))
                    .or_default()
                    .push((*r, v.value(i)));
            }
        }
    }
    let rows: Vec<_> = mo
        .into_iter()
        .map(|(k, v)| (k, replica_mean_sem(v)))
        .collect();
    write_summary(
        c,
        RFM_MOMENTS_SUMMARY,
        table(&rows, |col| {
            vec![
                col.u32("point_id", |r| r.0 .0),
                col.u32("order", |r| r.0 .1),
                col.u32("n_replicas", |r| r.1 .0),
                col.f64("mean", |r| r.1 .1),
                col.opt_f64("sem", |r| r.1 .2),
            ]
        }),
    )
}

/// (point, kind, h, bin) -> counts summed over replicas, density of the pooled counts.
fn histograms(c: View) -> Result<(), StoreError> {
    // (point, kind, h, lo bits) -> (hi, summed count); totals per (point, kind, h).
    type HKey = (u32, String, u32, u64);
    let mut bins: BTreeMap<HKey, (f64, u64)> = BTreeMap::new();
    let mut totals: BTreeMap<(u32, String, u32), u64> = BTreeMap::new();
    let t = RFM_HISTOGRAMS;
    for (b, rep) in done_batches(c, t)? {
        let p = get_u32(&b, t, "point_id")?;
        let kind = get_str(&b, t, "kind")?;
        let h = get_u32(&b, t, "h")?;
        let lo = get_f64(&b, t, "lo")?;
        let hi = get_f64(&b, t, "hi")?;
        let n = get_u64(&b, t, "count")?;
        for (i, r) in rep.iter().enumerate() {
            if r.is_none() {
                continue;
            }
            let k = (
                p.value(i),
                kind.value(i).to_string(),
                h.value(i),
                lo.value(i).to_bits(),
            );
            bins.entry(k).or_insert((hi.value(i), 0)).1 += n.value(i);
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
    write_summary(
        c,
        RFM_HISTOGRAMS_SUMMARY,
        table(&rows, |col| {
            vec![
                col.u32("point_id", |r| r.0 .0),
                col.str("kind", |r| r.0 .1.as_str()),
                col.u32("h", |r| r.0 .2),
                col.f64("lo", |r| f64::from_bits(r.0 .3)),
                col.f64("hi", |r| r.1 .0),
                col.u64("count", |r| r.1 .1),
                col.opt_f64("density", |r| density(&r.0, &r.1)),
            ]
        }),
    )
}

/// (point, order) -> mean and sem of the runs' <l^m>, free paths summed.
fn free_path_moments(c: View) -> Result<(), StoreError> {
    let t = RFM_FREE_PATH_MOMENTS;
    let mut g: Groups<(u32, u32)> = BTreeMap::new();
    for (b, rep) in done_batches(c, t)? {
        let p = get_u32(&b, t, "point_id")?;
        let o = get_u32(&b, t, "order")?;
        let v = get_f64(&b, t, "value")?;
        let n = get_u64(&b, t, "n_paths")?;
        for (i, r) in rep.iter().enumerate() {
            if let Some(r) = r {
                g.entry((p.value(i), o.value(i)))
                    .or_default()
                    .push((*r, vec![v.value(i), n.value(i) as f64]));
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
    write_summary(
        c,
        RFM_FREE_PATH_MOMENTS_SUMMARY,
        table(&rows, |col| {
            vec![
                col.u32("point_id", |r| r.0 .0),
                col.u32("order", |r| r.0 .1),
                col.u32("n_replicas", |r| r.1 .0),
                col.f64("mean", |r| r.1 .1[0].0),
                col.opt_f64("sem", |r| r.1 .1[0].1),
                col.u64("n_paths", |r| r.2),
            ]
        }),
    )
}

/// (point, h, order) -> mean and sem of the runs' neighbour-distance moments.
fn neighbour_moments(c: View) -> Result<(), StoreError> {
    let t = RFM_NEIGHBOUR_MOMENTS;
    let mut g: Groups<(u32, u32, u32)> = BTreeMap::new();
    for (b, rep) in done_batches(c, t)? {
        let p = get_u32(&b, t, "point_id")?;
        let h = get_u32(&b, t, "h")?;
        let o = get_u32(&b, t, "order")?;
        let v = get_f64(&b, t, "value")?;
        for (i, r) in rep.iter().enumerate() {
            if let Some(r) = r {
                g.entry((p.value(i), h.value(i), o.value(i)))
                    .or_default()
                    .push((*r, vec![v.value(i)]));
            }
        }
    }
    let rows: Vec<_> = g.into_iter().map(|(k, v)| (k, stats(v))).collect();
    write_summary(
        c,
        RFM_NEIGHBOUR_MOMENTS_SUMMARY,
        table(&rows, |col| {
            vec![
                col.u32("point_id", |r| r.0 .0),
                col.u32("h", |r| r.0 .1),
                col.u32("order", |r| r.0 .2),
                col.u32("n_replicas", |r| r.1 .0),
                col.f64("mean", |r| r.1 .1[0].0),
                col.opt_f64("sem", |r| r.1 .1[0].1),
            ]
        }),
    )
}

/// (point, shell n2) -> k, n_vectors, mean and sem of the runs' S(k).
fn structure_factor(c: View) -> Result<(), StoreError> {
    let t = RFM_STRUCTURE_FACTOR;
    // (point, n2) -> values [k, n_vectors, s].
    let mut g: Groups<(u32, u64)> = BTreeMap::new();
    for (b, rep) in done_batches(c, t)? {
        let p = get_u32(&b, t, "point_id")?;
        let n2 = get_u64(&b, t, "n2")?;
        let k = get_f64(&b, t, "k")?;
        let nv = get_u64(&b, t, "n_vectors")?;
        let s = get_f64(&b, t, "s")?;
        for (i, r) in rep.iter().enumerate() {
            if let Some(r) = r {
                g.entry((p.value(i), n2.value(i)))
                    .or_default()
                    .push((*r, vec![k.value(i), nv.value(i) as f64, s.value(i)]));
            }
        }
    }
    let rows: Vec<_> = g.into_iter().map(|(k, v)| (k, stats(v))).collect();
    write_summary(
        c,
        RFM_STRUCTURE_FACTOR_SUMMARY,
        table(&rows, |col| {
            vec![
                col.u32("point_id", |r| r.0 .0),
                col.u64("n2", |r| r.0 .1),
                col.f64("k", |r| r.1 .1[0].0),
                col.u64("n_vectors", |r| r.1 .1[1].0 as u64),
                col.u32("n_replicas", |r| r.1 .0),
                col.f64("s_mean", |r| r.1 .1[2].0),
                col.opt_f64("s_sem", |r| r.1 .1[2].1),
            ]
        }),
    )
}

/// (point, bin) -> pair counts summed, mean and sem of the runs' g(R) and C(R).
fn radial(c: View) -> Result<(), StoreError> {
    let t = RFM_RADIAL;
    // (point, r_lo bits) -> values [r_lo, r_hi, count, g, c]; r_lo >= 0, so its bits order
    // like the values.
    let mut g: Groups<(u32, u64)> = BTreeMap::new();
    for (b, rep) in done_batches(c, t)? {
        let p = get_u32(&b, t, "point_id")?;
        let lo = get_f64(&b, t, "r_lo")?;
        let hi = get_f64(&b, t, "r_hi")?;
        let n = get_u64(&b, t, "count")?;
        let gv = get_f64(&b, t, "g")?;
        let cv = get_f64(&b, t, "c")?;
        for (i, r) in rep.iter().enumerate() {
            if let Some(r) = r {
                let values = vec![
                    lo.value(i),
                    hi.value(i),
                    n.value(i) as f64,
                    gv.value(i),
                    cv.value(i),
                ];
                g.entry((p.value(i), lo.value(i).to_bits()))
                    .or_default()
                    .push((*r, values));
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
    write_summary(
        c,
        RFM_RADIAL_SUMMARY,
        table(&rows, |col| {
            vec![
                col.u32("point_id", |r| r.0 .0),
                col.f64("r_lo", |r| r.2 .1[0].0),
                col.f64("r_hi", |r| r.2 .1[1].0),
                col.u32("n_replicas", |r| r.2 .0),
                col.u64("count", |r| r.1),
                col.f64("g_mean", |r| r.2 .1[3].0),
                col.opt_f64("g_sem", |r| r.2 .1[3].1),
                col.f64("c_mean", |r| r.2 .1[4].0),
                col.opt_f64("c_sem", |r| r.2 .1[4].1),
            ]
        }),
    )
}
