//! The tables of the `cascade` model: S(k) of each run (`cascade_structure_factor`, with its
//! replica summary in [`super::summary`]), the D_f fits (`cascade_fit`) and the placed discs
//! (`cascade_placement`).

use arrow_array::RecordBatch;

use crate::aux_models::cascade::{FitRow, PlacementRow, SkRow};
use crate::models::{run_batch, RunIds};

pub const CASCADE_STRUCTURE_FACTOR: &str = "cascade_structure_factor";
pub const CASCADE_STRUCTURE_FACTOR_SUMMARY: &str = "cascade_structure_factor_summary";
pub const CASCADE_FIT: &str = "cascade_fit";
pub const CASCADE_PLACEMENT: &str = "cascade_placement";

pub fn structure_factor_batch(ids: RunIds, v: &[SkRow]) -> RecordBatch {
    run_batch(ids, v, |c| {
        vec![
            c.str("source", |r| &r.source),
            c.u64("n2", |r| r.n2),
            c.f64("k", |r| r.k),
            c.u64("n_vectors", |r| r.n_vectors),
            c.u64("n_realisations", |r| r.n_realisations),
            c.f64("s_mean", |r| r.s_mean),
            c.opt_f64("s_sem", |r| r.s_sem),
        ]
    })
}

pub fn fit_batch(ids: RunIds, v: &[FitRow]) -> RecordBatch {
    run_batch(ids, v, |c| {
        vec![
            c.str("source", |r| &r.source),
            c.str("variant", |r| &r.variant),
            c.u32("level", |r| r.level),
            c.f64("k_lo", |r| r.k_lo),
            c.f64("k_hi", |r| r.k_hi),
            c.u32("n_shells", |r| r.n_shells),
            c.opt_f64("d_f", |r| r.d_f),
            c.opt_f64("d_f_err", |r| r.d_f_err),
            c.opt_f64("amplitude", |r| r.amplitude),
            c.opt_f64("chi2_red", |r| r.chi2_red),
            c.opt_f64("d_f_thesis", |r| r.d_f_thesis),
            c.opt_f64("d_f_thesis_err", |r| r.d_f_thesis_err),
            c.f64("weight_sum_mean", |r| r.weight_sum_mean),
            c.opt_f64("weight_sum_sem", |r| r.weight_sum_sem),
            c.opt_u64("attempts", |r| r.attempts),
        ]
    })
}

pub fn placement_batch(ids: RunIds, v: &[PlacementRow]) -> RecordBatch {
    run_batch(ids, v, |c| {
        vec![
            c.u32("particle", |r| r.particle),
            c.f64("x", |r| r.x),
            c.f64("y", |r| r.y),
        ]
    })
}
