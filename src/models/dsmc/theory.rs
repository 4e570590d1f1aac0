//! The kinetic-theory tables of a DSMC campaign (`dsmc_theory`, `dsmc_theory_point`,
//! `dsmc_theory_tamsd`): the predictions of every point, computed in parallel. They depend
//! only on the manifest, so each is written once; a campaign directory of an older version
//! gains the tables it lacks, and existing ones are never rewritten.

use rayon::prelude::*;

use super::params::DsmcParams;
use super::tables::*;
use crate::dsmc::predict::{predict, Prediction, TamsdTheoryRow, TheoryRow};
use crate::models::CampaignView;
use crate::store::parquet_io::StoreError;

const THEORY_FILE: &str = "theory.parquet";
const POINT_FILE: &str = "theory_point.parquet";
const TAMSD_FILE: &str = "theory_tamsd.parquet";

/// Write the theory tables that do not exist yet.
pub fn write(c: &CampaignView<'_, DsmcParams>) -> Result<(), StoreError> {
    let points: Vec<&DsmcParams> = c.points.iter().map(|p| p.params).collect();
    let with_tamsd = super::observes_tamsd(&points);
    let mut missing = vec![(DSMC_THEORY, THEORY_FILE), (DSMC_THEORY_POINT, POINT_FILE)];
    if with_tamsd {
        missing.push((DSMC_THEORY_TAMSD, TAMSD_FILE));
    }
    missing.retain(|(t, f)| !c.data.has(t, f));
    if missing.is_empty() {
        return Ok(());
    }
    for (t, _) in &missing {
        c.data.ensure(t)?;
    }
    let preds: Vec<(u32, Prediction)> = c
        .points
        .par_iter()
        .filter_map(|p| {
            p.params
                .system()
                .ok()
                .map(|sys| (p.point_id, predict(&sys)))
        })
        .collect();
    for (table, file) in missing {
        let batch = match table {
            DSMC_THEORY => {
                let rows: Vec<(u32, TheoryRow)> = preds
                    .iter()
                    .flat_map(|(p, pr)| pr.rows.iter().map(move |r| (*p, r.clone())))
                    .collect();
                theory_batch(&rows)
            }
            DSMC_THEORY_POINT => {
                let points: Vec<(u32, f64, Vec<f64>)> = preds
                    .iter()
                    .map(|(p, pr)| (*p, pr.tau0, pr.initial_temperatures.clone()))
                    .collect();
                theory_point_batch(&points)
            }
            _ => {
                let rows: Vec<(u32, TamsdTheoryRow)> = preds
                    .iter()
                    .flat_map(|(p, pr)| pr.tamsd.iter().map(move |r| (*p, r.clone())))
                    .collect();
                theory_tamsd_batch(&rows)
            }
        };
        c.data.write_whole(table, file, &batch)?;
    }
    Ok(())
}
