//! The tables of the `cascade` model, each declared once ([`crate::declare_table!`]): S(k) of
//! each run (`cascade_structure_factor`, with its replica summary written by
//! [`super::summary`]), the D_f fits (`cascade_fit`) and the placed discs
//! (`cascade_placement`).

use arrow_array::RecordBatch;

use crate::aux_models::cascade::{FitRow, PlacementRow, SkRow};
use crate::declare_table;
use crate::models::RunIds;
use crate::store::typed::{OptF64, OptU64, Str, F64, U32, U64};

pub const CASCADE_STRUCTURE_FACTOR: &str = CascadeStructureFactor::TABLE;
pub const CASCADE_STRUCTURE_FACTOR_SUMMARY: &str = CascadeStructureFactorSummary::TABLE;
pub const CASCADE_FIT: &str = CascadeFit::TABLE;
pub const CASCADE_PLACEMENT: &str = CascadePlacement::TABLE;

/// One line on what a row of the table `name` is and what it holds (`granular tables`);
/// `None` for a name that is not one of this model's tables.
pub fn description(name: &str) -> Option<&'static str> {
    Some(match name {
        CASCADE_STRUCTURE_FACTOR => "one row per run, source and k shell: the structure factor S(k) over realisations and its error",
        CASCADE_STRUCTURE_FACTOR_SUMMARY => "one row per point, source and k shell: S(k) over the finished replicas and its error",
        CASCADE_FIT => "one row per run, source and fit variant: the fractal dimension D_f with its error, k window and chi2, beside the thesis's",
        CASCADE_PLACEMENT => "one row per run and placed disc: its position x, y",
        _ => return None,
    })
}

declare_table! {
    /// `cascade_structure_factor`: S(k) per source and shell (per run).
    pub struct CascadeStructureFactor in "cascade_structure_factor",
        read as CascadeStructureFactorCols {
        run_id: U64,
        point_id: U32,
        source: Str,
        n2: U64,
        k: F64,
        n_vectors: U64,
        n_realisations: U64,
        s_mean: F64,
        s_sem: OptF64,
    }
}

declare_table! {
    /// `cascade_structure_factor_summary`: S(k) over the finished replicas per point, source
    /// and shell (errors propagated from the runs').
    pub struct CascadeStructureFactorSummary in "cascade_structure_factor_summary",
        read as CascadeStructureFactorSummaryCols {
        point_id: U32,
        source: Str,
        n2: U64,
        k: F64,
        n_vectors: U64,
        n_replicas: U32,
        n_realisations: U64,
        s_mean: F64,
        s_sem: OptF64,
    }
}

declare_table! {
    /// `cascade_fit`: the D_f fits per source and variant (per run).
    pub struct CascadeFit in "cascade_fit", read as CascadeFitCols {
        run_id: U64,
        point_id: U32,
        source: Str,
        variant: Str,
        level: U32,
        k_lo: F64,
        k_hi: F64,
        n_shells: U32,
        d_f: OptF64,
        d_f_err: OptF64,
        amplitude: OptF64,
        chi2_red: OptF64,
        d_f_thesis: OptF64,
        d_f_thesis_err: OptF64,
        weight_sum_mean: F64,
        weight_sum_sem: OptF64,
        attempts: OptU64,
    }
}

declare_table! {
    /// `cascade_placement`: the placed discs (per run).
    pub struct CascadePlacement in "cascade_placement", read as CascadePlacementCols {
        run_id: U64,
        point_id: U32,
        particle: U32,
        x: F64,
        y: F64,
    }
}

pub fn structure_factor_batch(ids: RunIds, v: &[SkRow]) -> RecordBatch {
    let rows: Vec<CascadeStructureFactor> = v
        .iter()
        .map(|r| CascadeStructureFactor {
            run_id: ids.run_id,
            point_id: ids.point_id,
            source: r.source.clone(),
            n2: r.n2,
            k: r.k,
            n_vectors: r.n_vectors,
            n_realisations: r.n_realisations,
            s_mean: r.s_mean,
            s_sem: r.s_sem,
        })
        .collect();
    CascadeStructureFactor::batch(&rows)
}

pub fn fit_batch(ids: RunIds, v: &[FitRow]) -> RecordBatch {
    let rows: Vec<CascadeFit> = v
        .iter()
        .map(|r| CascadeFit {
            run_id: ids.run_id,
            point_id: ids.point_id,
            source: r.source.clone(),
            variant: r.variant.clone(),
            level: r.level,
            k_lo: r.k_lo,
            k_hi: r.k_hi,
            n_shells: r.n_shells,
            d_f: r.d_f,
            d_f_err: r.d_f_err,
            amplitude: r.amplitude,
            chi2_red: r.chi2_red,
            d_f_thesis: r.d_f_thesis,
            d_f_thesis_err: r.d_f_thesis_err,
            weight_sum_mean: r.weight_sum_mean,
            weight_sum_sem: r.weight_sum_sem,
            attempts: r.attempts,
        })
        .collect();
    CascadeFit::batch(&rows)
}

pub fn placement_batch(ids: RunIds, v: &[PlacementRow]) -> RecordBatch {
    let rows: Vec<CascadePlacement> = v
        .iter()
        .map(|r| CascadePlacement {
            run_id: ids.run_id,
            point_id: ids.point_id,
            particle: r.particle,
            x: r.x,
            y: r.y,
        })
        .collect();
    CascadePlacement::batch(&rows)
}
