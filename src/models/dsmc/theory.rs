//! The kinetic-theory tables of a DSMC campaign (`dsmc_theory`, `dsmc_theory_point`,
//! `dsmc_theory_tamsd`): the predictions of every point, computed in parallel. A point's
//! predictions depend only on its params, so they are written once: the first manifest's
//! points in one file per table, the points a grown manifest adds in files of their own
//! (`theory-<first point>.parquet`, ...). Files are never rewritten; a campaign directory of
//! an older version gains the tables it lacks. `dsmc_theory_point` (one row per point) says
//! which points are covered, and is written last.

use std::collections::BTreeSet;

use rayon::prelude::*;

use super::params::DsmcParams;
use super::tables::*;
use crate::dsmc::predict::{predict, Prediction, TamsdTheoryRow, TheoryRow};
use crate::models::CampaignView;
use crate::store::parquet_io::StoreError;

const THEORY_FILE: &str = "theory.parquet";
const POINT_FILE: &str = "theory_point.parquet";
const TAMSD_FILE: &str = "theory_tamsd.parquet";

/// Write the theory rows of the points that have none yet (of every point, for a table that
/// has no file at all).
pub fn write(c: &CampaignView<'_, DsmcParams>) -> Result<(), StoreError> {
    let covered = covered_points(c)?;
    let all: Vec<&DsmcParams> = c.points.iter().map(|p| p.params).collect();
    let mut tables = vec![DSMC_THEORY];
    if super::observes_tamsd(&all) {
        tables.push(DSMC_THEORY_TAMSD);
    }
    // Last: its rows say which points are done.
    tables.push(DSMC_THEORY_POINT);
    // The points each table needs.
    let mut needs: Vec<(&str, BTreeSet<u32>)> = Vec::new();
    for table in tables {
        let whole = table != DSMC_THEORY_POINT && c.data.files(table)?.is_empty();
        let ids: BTreeSet<u32> = c
            .points
            .iter()
            .map(|p| p.point_id)
            .filter(|id| whole || !covered.contains(id))
            .collect();
        if !ids.is_empty() {
            needs.push((table, ids));
        }
    }
    let wanted: BTreeSet<u32> = needs
        .iter()
        .flat_map(|(_, ids)| ids.iter().copied())
        .collect();
    // Say so before a long theory (validate and plan warn too).
    let (secs, bytes) = c
        .points
        .iter()
        .filter(|p| wanted.contains(&p.point_id))
        .filter_map(|p| p.params.theory_cost())
        .fold((0.0, 0.0f64), |(s, b), x| (s + x.seconds, b.max(x.bytes)));
    if secs > 60.0 || bytes > 2e9 {
        tracing::warn!(
            "kinetic theory of {} point(s): estimated ~{secs:.0} CPU s (the largest ~{}), before the runs start",
            wanted.len(),
            crate::models::bytes_text(bytes.min(u64::MAX as f64) as u64)
        );
    }
    let preds: Vec<(u32, Prediction)> = c
        .points
        .par_iter()
        .filter(|p| wanted.contains(&p.point_id))
        .map(|p| {
            p.params
                .system()
                .map_err(|e| e.to_string())
                .and_then(|sys| predict(&sys).map_err(|e| e.to_string()))
                .map(|pred| (p.point_id, pred))
                .map_err(|e| {
                    StoreError::Corrupt(
                        DSMC_THEORY.into(),
                        format!(
                            "cannot be computed for point {}{}: {e}",
                            p.point_id,
                            if p.label.is_empty() {
                                String::new()
                            } else {
                                format!(" ({})", p.label)
                            }
                        ),
                    )
                })
        })
        .collect::<Result<_, _>>()?;
    for (id, pred) in &preds {
        for note in &pred.notes {
            tracing::warn!("{DSMC_THEORY}, point {id}: {note}");
        }
    }
    for (table, ids) in needs {
        let first = *ids.first().expect("not empty");
        let preds = preds.iter().filter(|(p, _)| ids.contains(p));
        let batch = match table {
            DSMC_THEORY => {
                let rows: Vec<(u32, TheoryRow)> = preds
                    .flat_map(|(p, pr)| pr.rows.iter().map(move |r| (*p, r.clone())))
                    .collect();
                same_columns(c, DSMC_THEORY, theory_batch(&rows))?
            }
            DSMC_THEORY_POINT => {
                let points: Vec<(u32, f64, Vec<f64>)> = preds
                    .map(|(p, pr)| (*p, pr.tau0, pr.initial_temperatures.clone()))
                    .collect();
                theory_point_batch(&points)
            }
            _ => {
                let rows: Vec<(u32, TamsdTheoryRow)> = preds
                    .flat_map(|(p, pr)| pr.tamsd.iter().map(move |r| (*p, r.clone())))
                    .collect();
                theory_tamsd_batch(&rows)
            }
        };
        c.data
            .write_whole(table, &file_name(table, first), &batch)?;
    }
    Ok(())
}

/// The file of `table` holding the points from `first` on: the first manifest's points have
/// the table's original file name.
fn file_name(table: &str, first: u32) -> String {
    let base = match table {
        DSMC_THEORY => THEORY_FILE,
        DSMC_THEORY_POINT => POINT_FILE,
        _ => TAMSD_FILE,
    };
    match first {
        0 => base.to_string(),
        _ => format!("{}-{first:08}.parquet", base.trim_end_matches(".parquet")),
    }
}

/// The points `dsmc_theory_point` has rows for.
fn covered_points(c: &CampaignView<'_, DsmcParams>) -> Result<BTreeSet<u32>, StoreError> {
    let mut out = BTreeSet::new();
    for b in c.data.read(DSMC_THEORY_POINT)? {
        let ids = DsmcTheoryPointCols::read(&b, DSMC_THEORY_POINT)?.point_id;
        out.extend(ids.iter().flatten());
    }
    Ok(out)
}

/// `batch` with only the columns of the table's existing files (`store::schema::table_schema`,
/// read from a footer), so that a campaign whose theory was written by an older version
/// (without the Sonine columns) keeps one schema per table when it grows: its summaries then
/// have nulls there.
fn same_columns(
    c: &CampaignView<'_, DsmcParams>,
    table: &str,
    batch: arrow_array::RecordBatch,
) -> Result<arrow_array::RecordBatch, StoreError> {
    let Some(old) = crate::store::schema::table_schema(&c.data.files(table)?) else {
        return Ok(batch);
    };
    let keep: Vec<usize> = (0..batch.num_columns())
        .filter(|&i| old.index_of(batch.schema().field(i).name()).is_ok())
        .collect();
    if keep.len() == batch.num_columns() {
        return Ok(batch);
    }
    batch
        .project(&keep)
        .map_err(|e| StoreError::Corrupt(table.into(), e.to_string()))
}
