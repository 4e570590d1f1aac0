//! Replica summary of the auxiliary models: `cascade_structure_factor_summary` (point, source,
//! shell): the mean over the finished replicas of each run's S(k) (runs of a point have the
//! same number of realisations), with the standard error propagated from the runs' own
//! (realisation-to-realisation) errors, sqrt(sum sem_r^2) / n, so it exists with one replica
//! too (runs without an error, the placement's single configuration, use the replicas'
//! spread instead). Columns as `rfm_structure_factor_summary` plus `source` and `n_realisations`.
//! Rewritten whole and atomically when the campaign completes; summed in replica order.

use std::collections::BTreeMap;

use super::params::CascadeParams;
use super::tables::{
    CascadeStructureFactorCols, CascadeStructureFactorSummary, CASCADE_STRUCTURE_FACTOR,
    CASCADE_STRUCTURE_FACTOR_SUMMARY,
};
use crate::math::stats::mean_sem;
use crate::models::CampaignView;
use crate::store::parquet_io::StoreError;

/// One run's shell: (replica, k, n_vectors, n_realisations, s_mean, s_sem).
type Shell = (u64, f64, u64, u64, f64, Option<f64>);

pub fn write(c: &CampaignView<'_, CascadeParams>) -> Result<(), StoreError> {
    let t = CASCADE_STRUCTURE_FACTOR;
    let mut g: BTreeMap<(u32, String, u64), Vec<Shell>> = BTreeMap::new();
    for f in c.data.files(t)? {
        let name = f.display().to_string();
        for b in c.data.read_file(&f, t)? {
            let cols = CascadeStructureFactorCols::read(&b, &name)?;
            for i in 0..cols.len() {
                let Some(&replica) = c.done.get(&cols.run_id.value(i)) else {
                    continue;
                };
                let r = cols.row(i);
                g.entry((r.point_id, r.source, r.n2)).or_default().push((
                    replica as u64,
                    r.k,
                    r.n_vectors,
                    r.n_realisations,
                    r.s_mean,
                    r.s_sem,
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
                .or_else(|| mean_sem(&xs).1);
            let real: u64 = v.iter().map(|x| x.3).sum();
            (key, v[0].1, v[0].2, v.len() as u32, real, mean, sem)
        })
        .collect();
    let rows: Vec<CascadeStructureFactorSummary> = rows
        .into_iter()
        .map(|r| CascadeStructureFactorSummary {
            point_id: r.0 .0,
            source: r.0 .1,
            n2: r.0 .2,
            k: r.1,
            n_vectors: r.2,
            n_replicas: r.3,
            n_realisations: r.4,
            s_mean: r.5,
            s_sem: r.6,
        })
        .collect();
    let batch = CascadeStructureFactorSummary::batch(&rows);
    c.write_summary(CASCADE_STRUCTURE_FACTOR_SUMMARY, &batch)
}
