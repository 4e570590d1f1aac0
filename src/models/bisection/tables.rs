//! The tables of the `bisection` model: the length histogram and the moments of each run
//! (each run already averages many realisations, so there is no replica summary).

use arrow_array::RecordBatch;

use crate::aux_models::bisection::{HistRow, MomentRow};
use crate::models::{run_batch, RunIds};

pub const BISECTION_HISTOGRAM: &str = "bisection_histogram";
pub const BISECTION_MOMENTS: &str = "bisection_moments";

pub fn histogram_batch(ids: RunIds, v: &[HistRow]) -> RecordBatch {
    run_batch(ids, v, |c| {
        vec![
            c.f64("x_lo", |r| r.x_lo),
            c.f64("x_hi", |r| r.x_hi),
            c.u64("count", |r| r.count),
            c.f64("density", |r| r.density),
            c.opt_f64("density_sem", |r| r.density_sem),
            c.opt_f64("density_exact", |r| r.density_exact),
        ]
    })
}

pub fn moments_batch(ids: RunIds, realisations: u64, v: &[MomentRow]) -> RecordBatch {
    run_batch(ids, v, |c| {
        vec![
            c.u32("order", |r| r.order),
            c.u64("n_realisations", |_| realisations),
            c.f64("mean", |r| r.mean),
            c.opt_f64("sem", |r| r.sem),
            c.f64("exact", |r| r.exact),
            c.opt_f64("z", |r| r.z),
            c.f64("zeta_exact", |r| r.zeta_exact),
        ]
    })
}
