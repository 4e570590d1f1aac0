//! The tables of the `cascade` model: S(k) of each run (`cascade_structure_factor`, with its
//! replica summary in [`super::summary`]), the D_f fits (`cascade_fit`) and the placed discs
//! (`cascade_placement`).

use arrow_array::RecordBatch;
use arrow_schema::DataType;

use crate::aux_models::cascade::{FitRow, PlacementRow, SkRow};
use crate::models::{run_batch, RunIds};
use crate::store::cols::{f64s, field, field_opt, opt_f64s, opt_u64s, strs, u32s, u64s};

pub const CASCADE_STRUCTURE_FACTOR: &str = "cascade_structure_factor";
pub const CASCADE_STRUCTURE_FACTOR_SUMMARY: &str = "cascade_structure_factor_summary";
pub const CASCADE_FIT: &str = "cascade_fit";
pub const CASCADE_PLACEMENT: &str = "cascade_placement";

use DataType::{Float64 as F64, UInt32 as U32, UInt64 as U64, Utf8};

pub fn structure_factor_batch(ids: RunIds, v: &[SkRow]) -> RecordBatch {
    run_batch(
        ids,
        v.len(),
        vec![
            field("source", Utf8),
            field("n2", U64),
            field("k", F64),
            field("n_vectors", U64),
            field("n_realisations", U64),
            field("s_mean", F64),
            field_opt("s_sem", F64),
        ],
        vec![
            strs(v, |r| &r.source),
            u64s(v, |r| r.n2),
            f64s(v, |r| r.k),
            u64s(v, |r| r.n_vectors),
            u64s(v, |r| r.n_realisations),
            f64s(v, |r| r.s_mean),
            opt_f64s(v, |r| r.s_sem),
        ],
    )
}

pub fn fit_batch(ids: RunIds, v: &[FitRow]) -> RecordBatch {
    run_batch(
        ids,
        v.len(),
        vec![
            field("source", Utf8),
            field("variant", Utf8),
            field("level", U32),
            field("k_lo", F64),
            field("k_hi", F64),
            field("n_shells", U32),
            field_opt("d_f", F64),
            field_opt("d_f_err", F64),
            field_opt("amplitude", F64),
            field_opt("chi2_red", F64),
            field_opt("d_f_thesis", F64),
            field_opt("d_f_thesis_err", F64),
            field("weight_sum_mean", F64),
            field_opt("weight_sum_sem", F64),
            field_opt("attempts", U64),
        ],
        vec![
            strs(v, |r| &r.source),
            strs(v, |r| &r.variant),
            u32s(v, |r| r.level),
            f64s(v, |r| r.k_lo),
            f64s(v, |r| r.k_hi),
            u32s(v, |r| r.n_shells),
            opt_f64s(v, |r| r.d_f),
            opt_f64s(v, |r| r.d_f_err),
            opt_f64s(v, |r| r.amplitude),
            opt_f64s(v, |r| r.chi2_red),
            opt_f64s(v, |r| r.d_f_thesis),
            opt_f64s(v, |r| r.d_f_thesis_err),
            f64s(v, |r| r.weight_sum_mean),
            opt_f64s(v, |r| r.weight_sum_sem),
            opt_u64s(v, |r| r.attempts),
        ],
    )
}

pub fn placement_batch(ids: RunIds, v: &[PlacementRow]) -> RecordBatch {
    run_batch(
        ids,
        v.len(),
        vec![field("particle", U32), field("x", F64), field("y", F64)],
        vec![u32s(v, |r| r.particle), f64s(v, |r| r.x), f64s(v, |r| r.y)],
    )
}
