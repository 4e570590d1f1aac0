//! The tables of the `spm` model, each declared once ([`crate::declare_table!`]): the
//! velocity histogram of each run and its one-row summary (fits against the predicted tail).

use arrow_array::RecordBatch;

use crate::aux_models::spm::{HistRow, SummaryRow};
use crate::declare_table;
use crate::models::RunIds;
use crate::store::typed::{OptF64, Str, F64, U32, U64};

pub const SPM_VELOCITY_HISTOGRAM: &str = SpmVelocityHistogram::TABLE;
pub const SPM_SUMMARY: &str = SpmSummary::TABLE;

/// One line on what a row of the table `name` is and what it holds (`granular tables`);
/// `None` for a name that is not one of this model's tables.
pub fn description(name: &str) -> Option<&'static str> {
    Some(match name {
        SPM_VELOCITY_HISTOGRAM => "one row per run and velocity bin: the time- and walk-weighted density P(v)",
        SPM_SUMMARY => "one row per run: walks, samples, mean free path, the Gaussian tail fit and alpha, K, H predicted and measured",
        _ => return None,
    })
}

declare_table! {
    /// `spm_velocity_histogram`: time- and walk-weighted densities per velocity bin (per run).
    pub struct SpmVelocityHistogram in "spm_velocity_histogram", read as SpmVelocityHistogramCols {
        run_id: U64,
        point_id: U32,
        v_lo: F64,
        v_hi: F64,
        v_scaled_lo: OptF64,
        v_scaled_hi: OptF64,
        count: U64,
        density: F64,
        density_walk: F64,
    }
}

declare_table! {
    /// `spm_summary`: one row per run, the fits against the predicted tail.
    pub struct SpmSummary in "spm_summary", read as SpmSummaryCols {
        run_id: U64,
        point_id: U32,
        mode: Str,
        walks: U64,
        samples: U64,
        samples_outside: U64,
        mean_free_path: F64,
        mean_walk_time: F64,
        v_l: OptF64,
        tau_l: OptF64,
        gaussian_coefficient: OptF64,
        gaussian_coefficient_err: OptF64,
        gaussian_coefficient_thesis: F64,
        gaussian_tail_si: OptF64,
        gaussian_tail_si_thesis: OptF64,
        d_f: OptF64,
        c: OptF64,
        b: F64,
        alpha_predicted: OptF64,
        k_predicted: OptF64,
        h_predicted: OptF64,
        alpha_measured: OptF64,
        k_measured: OptF64,
        alpha_measured_h: OptF64,
        k_measured_h: OptF64,
        tail_v_lo: OptF64,
        tail_v_hi: OptF64,
    }
}

pub fn histogram_batch(ids: RunIds, v: &[HistRow]) -> RecordBatch {
    let rows: Vec<SpmVelocityHistogram> = v
        .iter()
        .map(|r| SpmVelocityHistogram {
            run_id: ids.run_id,
            point_id: ids.point_id,
            v_lo: r.v_lo,
            v_hi: r.v_hi,
            v_scaled_lo: r.v_scaled_lo,
            v_scaled_hi: r.v_scaled_hi,
            count: r.count,
            density: r.density,
            density_walk: r.density_walk,
        })
        .collect();
    SpmVelocityHistogram::batch(&rows)
}

pub fn summary_batch(ids: RunIds, r: &SummaryRow) -> RecordBatch {
    SpmSummary::batch(&[SpmSummary {
        run_id: ids.run_id,
        point_id: ids.point_id,
        mode: r.mode.clone(),
        walks: r.walks,
        samples: r.samples,
        samples_outside: r.samples_outside,
        mean_free_path: r.mean_free_path,
        mean_walk_time: r.mean_walk_time,
        v_l: r.v_l,
        tau_l: r.tau_l,
        gaussian_coefficient: r.gaussian_coefficient,
        gaussian_coefficient_err: r.gaussian_coefficient_err,
        gaussian_coefficient_thesis: r.gaussian_coefficient_thesis,
        gaussian_tail_si: r.gaussian_tail_si,
        gaussian_tail_si_thesis: r.gaussian_tail_si_thesis,
        d_f: r.d_f,
        c: r.c,
        b: r.b,
        alpha_predicted: r.alpha_predicted,
        k_predicted: r.k_predicted,
        h_predicted: r.h_predicted,
        alpha_measured: r.alpha_measured,
        k_measured: r.k_measured,
        alpha_measured_h: r.alpha_measured_h,
        k_measured_h: r.k_measured_h,
        tail_v_lo: r.tail_v_lo,
        tail_v_hi: r.tail_v_hi,
    }])
}
