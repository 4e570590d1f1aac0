//! The tables of the `dsmc` model: names and the Arrow form of a run's rows (`dsmc_species`,
//! `dsmc_tamsd`) and of the kinetic theory (`dsmc_theory`, `dsmc_theory_point`,
//! `dsmc_theory_tamsd`). The summaries are in [`super::summary`].

use std::sync::Arc;

use arrow_array::builder::{Float64Builder, ListBuilder};
use arrow_array::{ArrayRef, RecordBatch};

use crate::dsmc::predict::{TamsdTheoryRow, TheoryRow};
use crate::dsmc::{HistRow, RowValue, SpeciesRow, TamsdRow};
use crate::models::{run_batch, RunIds};
use crate::store::cols::table;

pub const DSMC_SPECIES: &str = "dsmc_species";
pub const DSMC_SPECIES_SUMMARY: &str = "dsmc_species_summary";
pub const DSMC_TAMSD: &str = "dsmc_tamsd";
pub const DSMC_TAMSD_SUMMARY: &str = "dsmc_tamsd_summary";
pub const DSMC_SPEED_HISTOGRAM: &str = "dsmc_speed_histogram";
pub const DSMC_SPEED_HISTOGRAM_SUMMARY: &str = "dsmc_speed_histogram_summary";
pub const DSMC_THEORY: &str = "dsmc_theory";
pub const DSMC_THEORY_TAMSD: &str = "dsmc_theory_tamsd";
pub const DSMC_THEORY_POINT: &str = "dsmc_theory_point";

/// `dsmc_species`: per output time and species.
pub fn species_batch(ids: RunIds, rows: &[SpeciesRow]) -> RecordBatch {
    run_batch(ids, rows, |c| {
        vec![
            c.f64("t", |r| r.t),
            c.u32("species", |r| r.species),
            c.f64("mass", |r| r.mass),
            c.f64("diameter", |r| r.diameter),
            c.u64("count", |r| r.count),
            c.f64("temperature", |r| r.temperature),
            c.opt_f64("msd", |r| r.msd),
            c.u64("collisions", |r| r.collisions),
            c.opt_f64("a2", |r| r.value(RowValue::A2)),
        ]
    })
}

/// `dsmc_speed_histogram`: per histogram time, species and bin.
pub fn hist_batch(ids: RunIds, rows: &[HistRow]) -> RecordBatch {
    run_batch(ids, rows, |c| {
        vec![
            c.f64("t", |r| r.t),
            c.u32("species", |r| r.species),
            c.u32("bin", |r| r.bin),
            c.f64("c_lo", |r| r.c_lo),
            c.f64("c_hi", |r| r.c_hi),
            c.u64("count", |r| r.count),
            c.f64("density", |r| r.density),
        ]
    })
}

/// `dsmc_tamsd`: per species and lag.
pub fn tamsd_batch(ids: RunIds, rows: &[TamsdRow]) -> RecordBatch {
    run_batch(ids, rows, |c| {
        vec![
            c.u32("species", |r| r.species),
            c.f64("lag", |r| r.lag),
            c.f64("tamsd", |r| r.tamsd),
            c.f64("t_total", |r| r.t_total),
        ]
    })
}

/// `dsmc_theory`: the kinetic-theory prediction per point, time and species.
pub fn theory_batch(rows: &[(u32, TheoryRow)]) -> RecordBatch {
    table(rows, |c| {
        vec![
            c.u32("point_id", |r| r.0),
            c.f64("t", |r| r.1.t),
            c.u32("species", |r| r.1.species),
            c.f64("temperature", |r| r.1.temperature),
            c.opt_f64("msd", |r| r.1.msd),
            c.f64("tau_v", |r| r.1.tau_v),
            c.opt_f64("a2", |r| r.1.a2),
            c.opt_f64("temperature_sonine", |r| r.1.temperature_sonine),
            c.opt_f64("msd_sonine", |r| r.1.msd_sonine),
        ]
    })
}

/// `dsmc_theory_tamsd`: the TAMSD (27) per point, species and lag (measured over [0, t_end]).
pub fn theory_tamsd_batch(rows: &[(u32, TamsdTheoryRow)]) -> RecordBatch {
    table(rows, |c| {
        vec![
            c.u32("point_id", |r| r.0),
            c.u32("species", |r| r.1.species),
            c.f64("lag", |r| r.1.lag),
            c.f64("tamsd", |r| r.1.tamsd),
        ]
    })
}

/// `dsmc_theory_point`: per point, tau_0 (21) and the initial temperatures actually used.
pub fn theory_point_batch(points: &[(u32, f64, Vec<f64>)]) -> RecordBatch {
    let temperatures = |v: &[(u32, f64, Vec<f64>)]| -> ArrayRef {
        let mut temps = ListBuilder::new(Float64Builder::new());
        for (_, _, t) in v {
            temps.values().append_slice(t);
            temps.append(true);
        }
        Arc::new(temps.finish())
    };
    table(points, |c| {
        vec![
            c.u32("point_id", |p| p.0),
            c.f64("tau_0", |p| p.1),
            c.array("initial_temperatures", false, temperatures),
        ]
    })
}
