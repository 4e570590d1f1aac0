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
use crate::models::RunKeyCols;
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
            let runs = RunKeyCols::read(&b, table)?.run_id;
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
        let cols = RfmTimeseriesCols::read(&b, RFM_TIMESERIES)?;
        for (i, r) in rep.iter().enumerate() {
            if let Some(r) = r {
                ts.entry((cols.point_id.value(i), cols.t.value(i).to_bits()))
                    .or_default()
                    .push((*r, cols.temperature.value(i)));
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
        RfmTimeseriesSummary::batch(
            &rows
                .iter()
                .map(|r| RfmTimeseriesSummary {
                    point_id: r.0 .0,
                    t: f64::from_bits(r.0 .1),
                    n_replicas: r.1 .0,
                    temperature_mean: r.1 .1,
                    temperature_sem: r.1 .2,
                })
                .collect::<Vec<_>>(),
        ),
    )
}

/// (point, order) -> mean and sem of the runs' velocity moments.
fn moments(c: View) -> Result<(), StoreError> {
    let mut mo: BTreeMap<(u32, u32), Vec<(u64, f64)>> = BTreeMap::new();
    for (b, rep) in done_batches(c, RFM_MOMENTS)? {
        let cols = RfmMomentsCols::read(&b, RFM_MOMENTS)?;
        for (i, r) in rep.iter().enumerate() {
            if let Some(r) = r {
                mo.entry((cols.point_id.value(i), cols.order.value(i)))
                    .or_default()
                    .push((*r, cols.value.value(i)));
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
        RfmMomentsSummary::batch(
            &rows
                .iter()
                .map(|r| RfmMomentsSummary {
                    point_id: r.0 .0,
                    order: r.0 .1,
                    n_replicas: r.1 .0,
                    mean: r.1 .1,
                    sem: r.1 .2,
                })
                .collect::<Vec<_>>(),
        ),
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
        let RfmHistogramsCols {
            point_id: p,
            kind,
            h,
            lo,
            hi,
            count: n,
            ..
        } = RfmHistogramsCols::read(&b, t)?;
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
        RfmHistogramsSummary::batch(
            &rows
                .iter()
                .map(|r| RfmHistogramsSummary {
                    point_id: r.0 .0,
                    kind: r.0 .1.clone(),
                    h: r.0 .2,
                    lo: f64::from_bits(r.0 .3),
                    hi: r.1 .0,
                    count: r.1 .1,
                    density: density(&r.0, &r.1),
                })
                .collect::<Vec<_>>(),
        ),
    )
}

/// (point, order) -> mean and sem of the runs' <l^m>, free paths summed.
fn free_path_moments(c: View) -> Result<(), StoreError> {
    let t = RFM_FREE_PATH_MOMENTS;
    let mut g: Groups<(u32, u32)> = BTreeMap::new();
    for (b, rep) in done_batches(c, t)? {
        let RfmFreePathMomentsCols {
            point_id: p,
            order: o,
            value: v,
            n_paths: n,
            ..
        } = RfmFreePathMomentsCols::read(&b, t)?;
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
        RfmFreePathMomentsSummary::batch(
            &rows
                .iter()
                .map(|r| RfmFreePathMomentsSummary {
                    point_id: r.0 .0,
                    order: r.0 .1,
                    n_replicas: r.1 .0,
                    mean: r.1 .1[0].0,
                    sem: r.1 .1[0].1,
                    n_paths: r.2,
                })
                .collect::<Vec<_>>(),
        ),
    )
}

/// (point, h, order) -> mean and sem of the runs' neighbour-distance moments.
fn neighbour_moments(c: View) -> Result<(), StoreError> {
    let t = RFM_NEIGHBOUR_MOMENTS;
    let mut g: Groups<(u32, u32, u32)> = BTreeMap::new();
    for (b, rep) in done_batches(c, t)? {
        let RfmNeighbourMomentsCols {
            point_id: p,
            h,
            order: o,
            value: v,
            ..
        } = RfmNeighbourMomentsCols::read(&b, t)?;
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
        RfmNeighbourMomentsSummary::batch(
            &rows
                .iter()
                .map(|r| RfmNeighbourMomentsSummary {
                    point_id: r.0 .0,
                    h: r.0 .1,
                    order: r.0 .2,
                    n_replicas: r.1 .0,
                    mean: r.1 .1[0].0,
                    sem: r.1 .1[0].1,
                })
                .collect::<Vec<_>>(),
        ),
    )
}

/// (point, shell n2) -> k, n_vectors, mean and sem of the runs' S(k).
fn structure_factor(c: View) -> Result<(), StoreError> {
    let t = RFM_STRUCTURE_FACTOR;
    // (point, n2) -> values [k, n_vectors, s].
    let mut g: Groups<(u32, u64)> = BTreeMap::new();
    for (b, rep) in done_batches(c, t)? {
        let RfmStructureFactorCols {
            point_id: p,
            n2,
            k,
            n_vectors: nv,
            s,
            ..
        } = RfmStructureFactorCols::read(&b, t)?;
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
        RfmStructureFactorSummary::batch(
            &rows
                .iter()
                .map(|r| RfmStructureFactorSummary {
                    point_id: r.0 .0,
                    n2: r.0 .1,
                    k: r.1 .1[0].0,
                    n_vectors: r.1 .1[1].0 as u64,
                    n_replicas: r.1 .0,
                    s_mean: r.1 .1[2].0,
                    s_sem: r.1 .1[2].1,
                })
                .collect::<Vec<_>>(),
        ),
    )
}

/// (point, bin) -> pair counts summed, mean and sem of the runs' g(R) and C(R).
fn radial(c: View) -> Result<(), StoreError> {
    let t = RFM_RADIAL;
    // (point, r_lo bits) -> values [r_lo, r_hi, count, g, c]; r_lo >= 0, so its bits order
    // like the values.
    let mut g: Groups<(u32, u64)> = BTreeMap::new();
    for (b, rep) in done_batches(c, t)? {
        let RfmRadialCols {
            point_id: p,
            r_lo: lo,
            r_hi: hi,
            count: n,
            g: gv,
            c: cv,
            ..
        } = RfmRadialCols::read(&b, t)?;
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
        RfmRadialSummary::batch(
            &rows
                .iter()
                .map(|r| RfmRadialSummary {
                    point_id: r.0 .0,
                    r_lo: r.2 .1[0].0,
                    r_hi: r.2 .1[1].0,
                    n_replicas: r.2 .0,
                    count: r.1,
                    g_mean: r.2 .1[3].0,
                    g_sem: r.2 .1[3].1,
                    c_mean: r.2 .1[4].0,
                    c_sem: r.2 .1[4].1,
                })
                .collect::<Vec<_>>(),
        ),
    )
}
