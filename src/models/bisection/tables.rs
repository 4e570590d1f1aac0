//! The tables of the `bisection` model: the length histogram and the moments of each run
//! (each run already averages many realisations, so there is no replica summary).

use arrow_array::RecordBatch;
use arrow_schema::DataType;

use crate::aux_models::bisection::{HistRow, MomentRow};
use crate::models::{run_batch, RunIds};
use crate::store::cols::{f64s, field, field_opt, opt_f64s, u32s, u64s};

pub const BISECTION_HISTOGRAM: &str = "bisection_histogram";
pub const BISECTION_MOMENTS: &str = "bisection_moments";

use DataType::{Float64 as F64, UInt32 as U32, UInt64 as U64};

pub fn histogram_batch(ids: RunIds, v: &[HistRow]) -> RecordBatch {
    run_batch(
        ids,
        v.len(),
        vec![
            field("x_lo", F64),
            field("x_hi", F64),
            field("count", U64),
            field("density", F64),
            field_opt("density_sem", F64),
            field_opt("density_exact", F64),
        ],
        vec![
            f64s(v, |r| r.x_lo),
            f64s(v, |r| r.x_hi),
            u64s(v, |r| r.count),
            f64s(v, |r| r.density),
            opt_f64s(v, |r| r.density_sem),
            opt_f64s(v, |r| r.density_exact),
        ],
    )
}

pub fn moments_batch(ids: RunIds, realisations: u64, v: &[MomentRow]) -> RecordBatch {
    run_batch(
        ids,
        v.len(),
        vec![
            field("order", U32),
            field("n_realisations", U64),
            field("mean", F64),
            field_opt("sem", F64),
            field("exact", F64),
            field_opt("z", F64),
            field("zeta_exact", F64),
        ],
        vec![
            u32s(v, |r| r.order),
            u64s(v, |_| realisations),
            f64s(v, |r| r.mean),
            opt_f64s(v, |r| r.sem),
            f64s(v, |r| r.exact),
            opt_f64s(v, |r| r.z),
            f64s(v, |r| r.zeta_exact),
        ],
    )
}
