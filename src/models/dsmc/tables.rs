//! The tables of the `dsmc` model: names and the Arrow form of a run's rows (`dsmc_species`,
//! `dsmc_tamsd`) and of the kinetic theory (`dsmc_theory`, `dsmc_theory_point`,
//! `dsmc_theory_tamsd`). The summaries are in [`super::summary`].

use std::sync::Arc;

use arrow_array::builder::{Float64Builder, ListBuilder};
use arrow_array::{ArrayRef, RecordBatch};
use arrow_schema::{DataType, Field, Schema};

use crate::dsmc::predict::{TamsdTheoryRow, TheoryRow};
use crate::dsmc::{SpeciesRow, TamsdRow};
use crate::models::{run_batch, RunIds};
use crate::store::cols::{f64s, field, field_opt, opt_f64s, u32s, u64s};

pub const DSMC_SPECIES: &str = "dsmc_species";
pub const DSMC_SPECIES_SUMMARY: &str = "dsmc_species_summary";
pub const DSMC_TAMSD: &str = "dsmc_tamsd";
pub const DSMC_TAMSD_SUMMARY: &str = "dsmc_tamsd_summary";
pub const DSMC_THEORY: &str = "dsmc_theory";
pub const DSMC_THEORY_TAMSD: &str = "dsmc_theory_tamsd";
pub const DSMC_THEORY_POINT: &str = "dsmc_theory_point";

use DataType::{Float64 as F64, UInt32 as U32, UInt64 as U64};

/// `dsmc_species`: per output time and species.
pub fn species_batch(ids: RunIds, rows: &[SpeciesRow]) -> RecordBatch {
    run_batch(
        ids,
        rows.len(),
        vec![
            field("t", F64),
            field("species", U32),
            field("mass", F64),
            field("diameter", F64),
            field("count", U64),
            field("temperature", F64),
            field_opt("msd", F64),
            field("collisions", U64),
        ],
        vec![
            f64s(rows, |r| r.t),
            u32s(rows, |r| r.species),
            f64s(rows, |r| r.mass),
            f64s(rows, |r| r.diameter),
            u64s(rows, |r| r.count),
            f64s(rows, |r| r.temperature),
            opt_f64s(rows, |r| r.msd),
            u64s(rows, |r| r.collisions),
        ],
    )
}

/// `dsmc_tamsd`: per species and lag.
pub fn tamsd_batch(ids: RunIds, rows: &[TamsdRow]) -> RecordBatch {
    run_batch(
        ids,
        rows.len(),
        vec![
            field("species", U32),
            field("lag", F64),
            field("tamsd", F64),
            field("t_total", F64),
        ],
        vec![
            u32s(rows, |r| r.species),
            f64s(rows, |r| r.lag),
            f64s(rows, |r| r.tamsd),
            f64s(rows, |r| r.t_total),
        ],
    )
}

fn batch(fields: Vec<Field>, arrays: Vec<ArrayRef>) -> RecordBatch {
    RecordBatch::try_new(Arc::new(Schema::new(fields)), arrays).expect("batch matches its schema")
}

/// `dsmc_theory`: the kinetic-theory prediction per point, time and species.
pub fn theory_batch(rows: &[(u32, TheoryRow)]) -> RecordBatch {
    batch(
        vec![
            field("point_id", U32),
            field("t", F64),
            field("species", U32),
            field("temperature", F64),
            field_opt("msd", F64),
            field("tau_v", F64),
        ],
        vec![
            u32s(rows, |r| r.0),
            f64s(rows, |r| r.1.t),
            u32s(rows, |r| r.1.species),
            f64s(rows, |r| r.1.temperature),
            opt_f64s(rows, |r| r.1.msd),
            f64s(rows, |r| r.1.tau_v),
        ],
    )
}

/// `dsmc_theory_tamsd`: the TAMSD (27) per point, species and lag (measured over [0, t_end]).
pub fn theory_tamsd_batch(rows: &[(u32, TamsdTheoryRow)]) -> RecordBatch {
    batch(
        vec![
            field("point_id", U32),
            field("species", U32),
            field("lag", F64),
            field("tamsd", F64),
        ],
        vec![
            u32s(rows, |r| r.0),
            u32s(rows, |r| r.1.species),
            f64s(rows, |r| r.1.lag),
            f64s(rows, |r| r.1.tamsd),
        ],
    )
}

/// `dsmc_theory_point`: per point, tau_0 (21) and the initial temperatures actually used.
pub fn theory_point_batch(points: &[(u32, f64, Vec<f64>)]) -> RecordBatch {
    let mut temps = ListBuilder::new(Float64Builder::new());
    for (_, _, t) in points {
        temps.values().append_slice(t);
        temps.append(true);
    }
    let temps = temps.finish();
    batch(
        vec![
            field("point_id", U32),
            field("tau_0", F64),
            field(
                "initial_temperatures",
                arrow_array::Array::data_type(&temps).clone(),
            ),
        ],
        vec![
            u32s(points, |p| p.0),
            f64s(points, |p| p.1),
            Arc::new(temps),
        ],
    )
}
