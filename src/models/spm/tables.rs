//! The tables of the `spm` model: the velocity histogram of each run and its one-row summary
//! (fits against the predicted tail).

use arrow_array::RecordBatch;

use crate::aux_models::spm::{HistRow, SummaryRow};
use crate::models::{run_batch, RunIds};

pub const SPM_VELOCITY_HISTOGRAM: &str = "spm_velocity_histogram";
pub const SPM_SUMMARY: &str = "spm_summary";

pub fn histogram_batch(ids: RunIds, v: &[HistRow]) -> RecordBatch {
    run_batch(ids, v, |c| {
        vec![
            c.f64("v_lo", |r| r.v_lo),
            c.f64("v_hi", |r| r.v_hi),
            c.opt_f64("v_scaled_lo", |r| r.v_scaled_lo),
            c.opt_f64("v_scaled_hi", |r| r.v_scaled_hi),
            c.u64("count", |r| r.count),
            c.f64("density", |r| r.density),
            c.f64("density_walk", |r| r.density_walk),
        ]
    })
}

pub fn summary_batch(ids: RunIds, r: &SummaryRow) -> RecordBatch {
    let v = std::slice::from_ref(r);
    run_batch(ids, v, |c| {
        vec![
            c.str("mode", |r| &r.mode),
            c.u64("walks", |r| r.walks),
            c.u64("samples", |r| r.samples),
            c.u64("samples_outside", |r| r.samples_outside),
            c.f64("mean_free_path", |r| r.mean_free_path),
            c.f64("mean_walk_time", |r| r.mean_walk_time),
            c.opt_f64("v_l", |r| r.v_l),
            c.opt_f64("tau_l", |r| r.tau_l),
            c.opt_f64("gaussian_coefficient", |r| r.gaussian_coefficient),
            c.opt_f64("gaussian_coefficient_err", |r| r.gaussian_coefficient_err),
            c.f64("gaussian_coefficient_thesis", |r| {
                r.gaussian_coefficient_thesis
            }),
            c.opt_f64("gaussian_tail_si", |r| r.gaussian_tail_si),
            c.opt_f64("gaussian_tail_si_thesis", |r| r.gaussian_tail_si_thesis),
            c.opt_f64("d_f", |r| r.d_f),
            c.opt_f64("c", |r| r.c),
            c.f64("b", |r| r.b),
            c.opt_f64("alpha_predicted", |r| r.alpha_predicted),
            c.opt_f64("k_predicted", |r| r.k_predicted),
            c.opt_f64("h_predicted", |r| r.h_predicted),
            c.opt_f64("alpha_measured", |r| r.alpha_measured),
            c.opt_f64("k_measured", |r| r.k_measured),
            c.opt_f64("alpha_measured_h", |r| r.alpha_measured_h),
            c.opt_f64("k_measured_h", |r| r.k_measured_h),
            c.opt_f64("tail_v_lo", |r| r.tail_v_lo),
            c.opt_f64("tail_v_hi", |r| r.tail_v_hi),
        ]
    })
}
