//! Replica summary of the auxiliary models: `cascade_structure_factor_summary` (point, source,
//! shell): the mean over the finished replicas of each run's S(k) (runs of a point have the
//! same number of realisations), with the standard error propagated from the runs' own
//! (realisation-to-realisation) errors, sqrt(sum sem_r^2) / n, so it exists with one replica
//! too (runs without an error, the placement's single configuration, use the replicas'
//! spread instead). Columns as `rfm_structure_factor_summary` plus `source` and `n_realisations`.
//! Rewritten whole and atomically when the campaign completes; summed in replica order.

use std::collections::BTreeMap;

use super::params::CascadeParams;
use super::tables::{CASCADE_STRUCTURE_FACTOR, CASCADE_STRUCTURE_FACTOR_SUMMARY};
use crate::math::stats::mean_sem;
use crate::models::CampaignView;
use crate::store::cols::{get_f64, get_str, get_u32, get_u64, opt, table};
use crate::store::parquet_io::StoreError;

/// One run's shell: (replica, k, n_vectors, n_realisations, s_mean, s_sem).
type Shell = (u64, f64, u64, u64, f64, Option<f64>);

pub fn write(c: &CampaignView<'_, CascadeParams>) -> Result<(), StoreError> {
    let t = CASCADE_STRUCTURE_FACTOR;
    let mut g: BTreeMap<(u32, String, u64), Vec<Shell>> = BTreeMap::new();
    for f in c.data.files(t)? {
        let name = f.display().to_string();
        for b in c.data.read_file(&f, t)? {
            let r = get_u64(&b, &name, "run_id")?;
            let p = get_u32(&b, &name, "point_id")?;
            let src = get_str(&b, &name, "source")?;
            let n2 = get_u64(&b, &name, "n2")?;
            let k = get_f64(&b, &name, "k")?;
            let nv = get_u64(&b, &name, "n_vectors")?;
            let nr = get_u64(&b, &name, "n_realisations")?;
            let s = get_f64(&b, &name, "s_mean")?;
            let se = get_f64(&b, &name, "s_sem")?;
            for i in 0..b.num_rows() {
                let Some(&replica) = c.done.get(&r.value(i)) else {
                    continue;
                };
                g.entry((p.value(i), src.value(i).to_string(), n2.value(i)))
                    .or_default()
                    .push((
                        replica as u64,
                        k.value(i),
                        nv.value(i),
                        nr.value(i),
                        s.value(i),
                        opt(se, i),
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
    let batch = table(&rows, |col| {
        vec![
            col.u32("point_id", |r| r.0 .0),
            col.str("source", |r| r.0 .1.as_str()),
            col.u64("n2", |r| r.0 .2),
            col.f64("k", |r| r.1),
            col.u64("n_vectors", |r| r.2),
            col.u32("n_replicas", |r| r.3),
            col.u64("n_realisations", |r| r.4),
            col.f64("s_mean", |r| r.5),
            col.opt_f64("s_sem", |r| r.6),
        ]
    });
    c.write_summary(CASCADE_STRUCTURE_FACTOR_SUMMARY, &batch)
}
