//! Tables of the auxiliary models (`bisection`, `cascade`, `spm`): names, Arrow schemas and
//! the row buffer of the writer. Every measurement has its exact or asymptotic theory beside
//! it (columns `*_exact`, `*_thesis`, `*_predicted`).

use std::sync::Arc;

use arrow_array::{ArrayRef, RecordBatch};
use arrow_schema::{DataType, Field, Schema};

use super::tables::cols::{f64s, opt_f64s, opt_u64s, strs, u32s, u64s};
use crate::aux_models::{bisection, cascade, spm, AuxOutput};
use crate::manifest::ModelKind;
use crate::plan::{ModelParams, Plan};

pub const BISECTION_HISTOGRAM: &str = "bisection_histogram";
pub const BISECTION_MOMENTS: &str = "bisection_moments";
pub const CASCADE_STRUCTURE_FACTOR: &str = "cascade_structure_factor";
pub const CASCADE_STRUCTURE_FACTOR_SUMMARY: &str = "cascade_structure_factor_summary";
pub const CASCADE_FIT: &str = "cascade_fit";
pub const CASCADE_PLACEMENT: &str = "cascade_placement";
pub const SPM_VELOCITY_HISTOGRAM: &str = "spm_velocity_histogram";
pub const SPM_SUMMARY: &str = "spm_summary";

/// The tables a campaign of an auxiliary model has (none for other models).
pub fn aux_tables(plan: &Plan) -> Vec<&'static str> {
    match plan.model {
        ModelKind::Bisection => vec![BISECTION_HISTOGRAM, BISECTION_MOMENTS],
        ModelKind::Cascade => {
            let mut v = vec![
                CASCADE_STRUCTURE_FACTOR,
                CASCADE_STRUCTURE_FACTOR_SUMMARY,
                CASCADE_FIT,
            ];
            if plan
                .points
                .iter()
                .any(|p| matches!(&p.params, ModelParams::Cascade(c) if c.placement.is_some()))
            {
                v.push(CASCADE_PLACEMENT);
            }
            v
        }
        ModelKind::Spm => vec![SPM_VELOCITY_HISTOGRAM, SPM_SUMMARY],
        ModelKind::Dsmc | ModelKind::Rfm => Vec::new(),
    }
}

type Ids = (u64, u32);

/// Buffered rows of the auxiliary tables (the summary is written by `store::aux_summary`).
#[derive(Default)]
pub struct AuxBuffer {
    bis_hist: Vec<(Ids, bisection::HistRow)>,
    bis_mom: Vec<(Ids, u64, bisection::MomentRow)>,
    sk: Vec<(Ids, cascade::SkRow)>,
    fit: Vec<(Ids, cascade::FitRow)>,
    place: Vec<(Ids, cascade::PlacementRow)>,
    spm_hist: Vec<(Ids, spm::HistRow)>,
    spm_sum: Vec<(Ids, spm::SummaryRow)>,
}

fn f(name: &str, t: DataType, nullable: bool) -> Field {
    Field::new(name, t, nullable)
}

/// One batch: run_id, point_id, then `fields` with `cols`.
fn batch<T>(
    rows: &[T],
    ids: impl Fn(&T) -> Ids,
    fields: Vec<Field>,
    cols: Vec<ArrayRef>,
) -> RecordBatch {
    let mut all = vec![
        f("run_id", DataType::UInt64, false),
        f("point_id", DataType::UInt32, false),
    ];
    all.extend(fields);
    let mut arrays = vec![u64s(rows, |r| ids(r).0), u32s(rows, |r| ids(r).1)];
    arrays.extend(cols);
    RecordBatch::try_new(Arc::new(Schema::new(all)), arrays).expect("batch matches its schema")
}

impl AuxBuffer {
    pub fn push(&mut self, run_id: u64, point_id: u32, out: &AuxOutput) {
        let id = (run_id, point_id);
        match out {
            AuxOutput::Bisection(o) => {
                self.bis_hist
                    .extend(o.histogram.iter().map(|r| (id, r.clone())));
                self.bis_mom
                    .extend(o.moments.iter().map(|r| (id, o.realisations, r.clone())));
            }
            AuxOutput::Cascade(o) => {
                self.sk
                    .extend(o.structure_factor.iter().map(|r| (id, r.clone())));
                self.fit.extend(o.fits.iter().map(|r| (id, r.clone())));
                self.place
                    .extend(o.placement.iter().map(|r| (id, r.clone())));
            }
            AuxOutput::Spm(o) => {
                self.spm_hist
                    .extend(o.histogram.iter().map(|r| (id, r.clone())));
                self.spm_sum.push((id, o.summary.clone()));
            }
        }
    }

    pub fn rows(&self) -> usize {
        self.bis_hist.len()
            + self.bis_mom.len()
            + self.sk.len()
            + self.fit.len()
            + self.place.len()
            + self.spm_hist.len()
            + self.spm_sum.len()
    }

    /// The non-empty tables as (name, batch); empties the buffer.
    pub fn finish(&mut self) -> Vec<(&'static str, RecordBatch)> {
        use DataType::{Float64 as F64, UInt32 as U32, UInt64 as U64, Utf8};
        let mut out = Vec::new();
        if !self.bis_hist.is_empty() {
            let v = &self.bis_hist;
            out.push((
                BISECTION_HISTOGRAM,
                batch(
                    v,
                    |r| r.0,
                    vec![
                        f("x_lo", F64, false),
                        f("x_hi", F64, false),
                        f("count", U64, false),
                        f("density", F64, false),
                        f("density_sem", F64, true),
                        f("density_exact", F64, true),
                    ],
                    vec![
                        f64s(v, |r| r.1.x_lo),
                        f64s(v, |r| r.1.x_hi),
                        u64s(v, |r| r.1.count),
                        f64s(v, |r| r.1.density),
                        opt_f64s(v, |r| r.1.density_sem),
                        opt_f64s(v, |r| r.1.density_exact),
                    ],
                ),
            ));
        }
        if !self.bis_mom.is_empty() {
            let v = &self.bis_mom;
            out.push((
                BISECTION_MOMENTS,
                batch(
                    v,
                    |r| r.0,
                    vec![
                        f("order", U32, false),
                        f("n_realisations", U64, false),
                        f("mean", F64, false),
                        f("sem", F64, true),
                        f("exact", F64, false),
                        f("z", F64, true),
                        f("zeta_exact", F64, false),
                    ],
                    vec![
                        u32s(v, |r| r.2.order),
                        u64s(v, |r| r.1),
                        f64s(v, |r| r.2.mean),
                        opt_f64s(v, |r| r.2.sem),
                        f64s(v, |r| r.2.exact),
                        opt_f64s(v, |r| r.2.z),
                        f64s(v, |r| r.2.zeta_exact),
                    ],
                ),
            ));
        }
        if !self.sk.is_empty() {
            let v = &self.sk;
            out.push((
                CASCADE_STRUCTURE_FACTOR,
                batch(
                    v,
                    |r| r.0,
                    vec![
                        f("source", Utf8, false),
                        f("n2", U64, false),
                        f("k", F64, false),
                        f("n_vectors", U64, false),
                        f("n_realisations", U64, false),
                        f("s_mean", F64, false),
                        f("s_sem", F64, true),
                    ],
                    vec![
                        strs(v, |r| &r.1.source),
                        u64s(v, |r| r.1.n2),
                        f64s(v, |r| r.1.k),
                        u64s(v, |r| r.1.n_vectors),
                        u64s(v, |r| r.1.n_realisations),
                        f64s(v, |r| r.1.s_mean),
                        opt_f64s(v, |r| r.1.s_sem),
                    ],
                ),
            ));
        }
        if !self.fit.is_empty() {
            let v = &self.fit;
            out.push((
                CASCADE_FIT,
                batch(
                    v,
                    |r| r.0,
                    vec![
                        f("source", Utf8, false),
                        f("variant", Utf8, false),
                        f("level", U32, false),
                        f("k_lo", F64, false),
                        f("k_hi", F64, false),
                        f("n_shells", U32, false),
                        f("d_f", F64, true),
                        f("d_f_err", F64, true),
                        f("amplitude", F64, true),
                        f("chi2_red", F64, true),
                        f("d_f_thesis", F64, true),
                        f("d_f_thesis_err", F64, true),
                        f("weight_sum_mean", F64, false),
                        f("weight_sum_sem", F64, true),
                        f("attempts", U64, true),
                    ],
                    vec![
                        strs(v, |r| &r.1.source),
                        strs(v, |r| &r.1.variant),
                        u32s(v, |r| r.1.level),
                        f64s(v, |r| r.1.k_lo),
                        f64s(v, |r| r.1.k_hi),
                        u32s(v, |r| r.1.n_shells),
                        opt_f64s(v, |r| r.1.d_f),
                        opt_f64s(v, |r| r.1.d_f_err),
                        opt_f64s(v, |r| r.1.amplitude),
                        opt_f64s(v, |r| r.1.chi2_red),
                        opt_f64s(v, |r| r.1.d_f_thesis),
                        opt_f64s(v, |r| r.1.d_f_thesis_err),
                        f64s(v, |r| r.1.weight_sum_mean),
                        opt_f64s(v, |r| r.1.weight_sum_sem),
                        opt_u64s(v, |r| r.1.attempts),
                    ],
                ),
            ));
        }
        if !self.place.is_empty() {
            let v = &self.place;
            out.push((
                CASCADE_PLACEMENT,
                batch(
                    v,
                    |r| r.0,
                    vec![
                        f("particle", U32, false),
                        f("x", F64, false),
                        f("y", F64, false),
                    ],
                    vec![
                        u32s(v, |r| r.1.particle),
                        f64s(v, |r| r.1.x),
                        f64s(v, |r| r.1.y),
                    ],
                ),
            ));
        }
        if !self.spm_hist.is_empty() {
            let v = &self.spm_hist;
            out.push((
                SPM_VELOCITY_HISTOGRAM,
                batch(
                    v,
                    |r| r.0,
                    vec![
                        f("v_lo", F64, false),
                        f("v_hi", F64, false),
                        f("v_scaled_lo", F64, true),
                        f("v_scaled_hi", F64, true),
                        f("count", U64, false),
                        f("density", F64, false),
                        f("density_walk", F64, false),
                    ],
                    vec![
                        f64s(v, |r| r.1.v_lo),
                        f64s(v, |r| r.1.v_hi),
                        opt_f64s(v, |r| r.1.v_scaled_lo),
                        opt_f64s(v, |r| r.1.v_scaled_hi),
                        u64s(v, |r| r.1.count),
                        f64s(v, |r| r.1.density),
                        f64s(v, |r| r.1.density_walk),
                    ],
                ),
            ));
        }
        if !self.spm_sum.is_empty() {
            let v = &self.spm_sum;
            out.push((
                SPM_SUMMARY,
                batch(
                    v,
                    |r| r.0,
                    vec![
                        f("mode", Utf8, false),
                        f("walks", U64, false),
                        f("samples", U64, false),
                        f("samples_outside", U64, false),
                        f("mean_free_path", F64, false),
                        f("mean_walk_time", F64, false),
                        f("v_l", F64, true),
                        f("tau_l", F64, true),
                        f("gaussian_coefficient", F64, true),
                        f("gaussian_coefficient_err", F64, true),
                        f("gaussian_coefficient_thesis", F64, false),
                        f("gaussian_tail_si", F64, true),
                        f("gaussian_tail_si_thesis", F64, true),
                        f("d_f", F64, true),
                        f("c", F64, true),
                        f("b", F64, false),
                        f("alpha_predicted", F64, true),
                        f("k_predicted", F64, true),
                        f("h_predicted", F64, true),
                        f("alpha_measured", F64, true),
                        f("k_measured", F64, true),
                        f("alpha_measured_h", F64, true),
                        f("k_measured_h", F64, true),
                        f("tail_v_lo", F64, true),
                        f("tail_v_hi", F64, true),
                    ],
                    vec![
                        strs(v, |r| &r.1.mode),
                        u64s(v, |r| r.1.walks),
                        u64s(v, |r| r.1.samples),
                        u64s(v, |r| r.1.samples_outside),
                        f64s(v, |r| r.1.mean_free_path),
                        f64s(v, |r| r.1.mean_walk_time),
                        opt_f64s(v, |r| r.1.v_l),
                        opt_f64s(v, |r| r.1.tau_l),
                        opt_f64s(v, |r| r.1.gaussian_coefficient),
                        opt_f64s(v, |r| r.1.gaussian_coefficient_err),
                        f64s(v, |r| r.1.gaussian_coefficient_thesis),
                        opt_f64s(v, |r| r.1.gaussian_tail_si),
                        opt_f64s(v, |r| r.1.gaussian_tail_si_thesis),
                        opt_f64s(v, |r| r.1.d_f),
                        opt_f64s(v, |r| r.1.c),
                        f64s(v, |r| r.1.b),
                        opt_f64s(v, |r| r.1.alpha_predicted),
                        opt_f64s(v, |r| r.1.k_predicted),
                        opt_f64s(v, |r| r.1.h_predicted),
                        opt_f64s(v, |r| r.1.alpha_measured),
                        opt_f64s(v, |r| r.1.k_measured),
                        opt_f64s(v, |r| r.1.alpha_measured_h),
                        opt_f64s(v, |r| r.1.k_measured_h),
                        opt_f64s(v, |r| r.1.tail_v_lo),
                        opt_f64s(v, |r| r.1.tail_v_hi),
                    ],
                ),
            ));
        }
        *self = AuxBuffer::default();
        out
    }
}
