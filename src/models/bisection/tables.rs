//! The tables of the `bisection` model, each declared once ([`crate::declare_table!`]): the
//! length histogram and the moments of each run (each run already averages many
//! realisations, so there is no replica summary).

use arrow_array::RecordBatch;

use crate::aux_models::bisection::{HistRow, MomentRow};
use crate::declare_table;
use crate::models::RunIds;
use crate::store::typed::{OptF64, F64, U32, U64};

pub const BISECTION_HISTOGRAM: &str = BisectionHistogram::TABLE;
pub const BISECTION_MOMENTS: &str = BisectionMoments::TABLE;

/// One line on what a row of the table `name` is and what it holds (`granular tables`);
/// `None` for a name that is not one of this model's tables.
pub fn description(name: &str) -> Option<&'static str> {
    Some(match name {
        BISECTION_HISTOGRAM => "one row per run and length bin [x_lo, x_hi): count and density of the lengths over the run's realisations, its error and the exact density",
        BISECTION_MOMENTS => "one row per run and order m: the moment <x^m> over realisations, its error, the exact value and z",
        _ => return None,
    })
}

declare_table! {
    /// `bisection_histogram`: the density of the lengths per bin (per run).
    pub struct BisectionHistogram in "bisection_histogram", read as BisectionHistogramCols {
        run_id: U64,
        point_id: U32,
        x_lo: F64,
        x_hi: F64,
        count: U64,
        density: F64,
        density_sem: OptF64,
        density_exact: OptF64,
    }
}

declare_table! {
    /// `bisection_moments`: <x^m> per order with the exact results (per run).
    pub struct BisectionMoments in "bisection_moments", read as BisectionMomentsCols {
        run_id: U64,
        point_id: U32,
        order: U32,
        n_realisations: U64,
        mean: F64,
        sem: OptF64,
        exact: F64,
        z: OptF64,
        zeta_exact: F64,
    }
}

pub fn histogram_batch(ids: RunIds, v: &[HistRow]) -> RecordBatch {
    let rows: Vec<BisectionHistogram> = v
        .iter()
        .map(|r| BisectionHistogram {
            run_id: ids.run_id,
            point_id: ids.point_id,
            x_lo: r.x_lo,
            x_hi: r.x_hi,
            count: r.count,
            density: r.density,
            density_sem: r.density_sem,
            density_exact: r.density_exact,
        })
        .collect();
    BisectionHistogram::batch(&rows)
}

pub fn moments_batch(ids: RunIds, realisations: u64, v: &[MomentRow]) -> RecordBatch {
    let rows: Vec<BisectionMoments> = v
        .iter()
        .map(|r| BisectionMoments {
            run_id: ids.run_id,
            point_id: ids.point_id,
            order: r.order,
            n_realisations: realisations,
            mean: r.mean,
            sem: r.sem,
            exact: r.exact,
            z: r.z,
            zeta_exact: r.zeta_exact,
        })
        .collect();
    BisectionMoments::batch(&rows)
}
