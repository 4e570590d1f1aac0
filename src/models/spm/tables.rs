//! The tables of the `spm` model: the velocity histogram of each run and its one-row summary
//! (fits against the predicted tail).

use arrow_array::RecordBatch;
use arrow_schema::DataType;

use crate::aux_models::spm::{HistRow, SummaryRow};
use crate::models::{run_batch, RunIds};
use crate::store::cols::{f64s, field, field_opt, opt_f64s, strs, u64s};

pub const SPM_VELOCITY_HISTOGRAM: &str = "spm_velocity_histogram";
pub const SPM_SUMMARY: &str = "spm_summary";

use DataType::{Float64 as F64, UInt64 as U64, Utf8};

pub fn histogram_batch(ids: RunIds, v: &[HistRow]) -> RecordBatch {
    run_batch(
        ids,
        v.len(),
        vec![
            field("v_lo", F64),
            field("v_hi", F64),
            field_opt("v_scaled_lo", F64),
            field_opt("v_scaled_hi", F64),
            field("count", U64),
            field("density", F64),
            field("density_walk", F64),
        ],
        vec![
            f64s(v, |r| r.v_lo),
            f64s(v, |r| r.v_hi),
            opt_f64s(v, |r| r.v_scaled_lo),
            opt_f64s(v, |r| r.v_scaled_hi),
            u64s(v, |r| r.count),
            f64s(v, |r| r.density),
            f64s(v, |r| r.density_walk),
        ],
    )
}

pub fn summary_batch(ids: RunIds, r: &SummaryRow) -> RecordBatch {
    let v = std::slice::from_ref(r);
    let f = |name| field(name, F64);
    let o = |name| field_opt(name, F64);
    run_batch(
        ids,
        1,
        vec![
            field("mode", Utf8),
            field("walks", U64),
            field("samples", U64),
            field("samples_outside", U64),
            f("mean_free_path"),
            f("mean_walk_time"),
            o("v_l"),
            o("tau_l"),
            o("gaussian_coefficient"),
            o("gaussian_coefficient_err"),
            f("gaussian_coefficient_thesis"),
            o("gaussian_tail_si"),
            o("gaussian_tail_si_thesis"),
            o("d_f"),
            o("c"),
            f("b"),
            o("alpha_predicted"),
            o("k_predicted"),
            o("h_predicted"),
            o("alpha_measured"),
            o("k_measured"),
            o("alpha_measured_h"),
            o("k_measured_h"),
            o("tail_v_lo"),
            o("tail_v_hi"),
        ],
        vec![
            strs(v, |r| &r.mode),
            u64s(v, |r| r.walks),
            u64s(v, |r| r.samples),
            u64s(v, |r| r.samples_outside),
            f64s(v, |r| r.mean_free_path),
            f64s(v, |r| r.mean_walk_time),
            opt_f64s(v, |r| r.v_l),
            opt_f64s(v, |r| r.tau_l),
            opt_f64s(v, |r| r.gaussian_coefficient),
            opt_f64s(v, |r| r.gaussian_coefficient_err),
            f64s(v, |r| r.gaussian_coefficient_thesis),
            opt_f64s(v, |r| r.gaussian_tail_si),
            opt_f64s(v, |r| r.gaussian_tail_si_thesis),
            opt_f64s(v, |r| r.d_f),
            opt_f64s(v, |r| r.c),
            f64s(v, |r| r.b),
            opt_f64s(v, |r| r.alpha_predicted),
            opt_f64s(v, |r| r.k_predicted),
            opt_f64s(v, |r| r.h_predicted),
            opt_f64s(v, |r| r.alpha_measured),
            opt_f64s(v, |r| r.k_measured),
            opt_f64s(v, |r| r.alpha_measured_h),
            opt_f64s(v, |r| r.k_measured_h),
            opt_f64s(v, |r| r.tail_v_lo),
            opt_f64s(v, |r| r.tail_v_hi),
        ],
    )
}
