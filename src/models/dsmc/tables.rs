//! The tables of the `dsmc` model, each declared once ([`crate::declare_table!`]: names,
//! Arrow types, nullability, columns older files lack): a run's rows (`dsmc_species`,
//! `dsmc_tamsd`, `dsmc_speed_histogram`), the kinetic theory (`dsmc_theory`,
//! `dsmc_theory_point`, `dsmc_theory_tamsd`) and the replica summaries (`*_summary`, written
//! by [`super::summary`]). Writers and readers use these declarations only.

use crate::declare_table;
use crate::dsmc::predict::{TamsdTheoryRow, TheoryRow};
use crate::dsmc::{HistRow, RowValue, SpeciesRow, TamsdRow};
use crate::models::RunIds;
use crate::store::typed::{Absent, ListF64, OptF64, F64, U32, U64};
use arrow_array::RecordBatch;

pub const DSMC_SPECIES: &str = DsmcSpecies::TABLE;
pub const DSMC_SPECIES_SUMMARY: &str = DsmcSpeciesSummary::TABLE;
pub const DSMC_TAMSD: &str = DsmcTamsd::TABLE;
pub const DSMC_TAMSD_SUMMARY: &str = DsmcTamsdSummary::TABLE;
pub const DSMC_SPEED_HISTOGRAM: &str = DsmcSpeedHistogram::TABLE;
pub const DSMC_SPEED_HISTOGRAM_SUMMARY: &str = DsmcSpeedHistogramSummary::TABLE;
pub const DSMC_THEORY: &str = DsmcTheory::TABLE;
pub const DSMC_THEORY_TAMSD: &str = DsmcTheoryTamsd::TABLE;
pub const DSMC_THEORY_POINT: &str = DsmcTheoryPoint::TABLE;

/// One line on what a row of the table `name` is and what it holds (`granular tables`);
/// `None` for a name that is not one of this model's tables.
pub fn description(name: &str) -> Option<&'static str> {
    Some(match name {
        DSMC_SPECIES => "one row per finished run, output time and species: mass, diameter, count, temperature, msd, collisions, a2",
        DSMC_SPECIES_SUMMARY => "one row per point, output time and species: mean and standard error over replicas of temperature, msd, a2, beside the kinetic theory and the deviations from it",
        DSMC_TAMSD => "one row per run, species and lag: the time-averaged mean-squared displacement",
        DSMC_TAMSD_SUMMARY => "one row per point, species and lag: the TAMSD's mean and standard error over replicas, beside theory",
        DSMC_SPEED_HISTOGRAM => "one row per run, histogram time, species and bin of the scaled speed: count and density",
        DSMC_SPEED_HISTOGRAM_SUMMARY => "one row per point, histogram time, species and bin: the density's mean and standard error over replicas",
        DSMC_THEORY => "one row per point, time and species: the kinetic-theory temperature, msd, tau_v and Sonine a2 and temperature",
        DSMC_THEORY_TAMSD => "one row per point, species and lag: the kinetic-theory TAMSD (eq. 27)",
        DSMC_THEORY_POINT => "one row per point: tau_0 and the initial temperatures the theory used",
        _ => return None,
    })
}

declare_table! {
    /// `dsmc_species`: per run, output time and species. The columns of an optional
    /// observable are nullable (null where it is not recorded) and `Absent` where tables
    /// written before the observable existed lack them (`a2`, issue 16).
    pub struct DsmcSpecies in "dsmc_species", read as DsmcSpeciesCols {
        run_id: U64,
        point_id: U32,
        t: F64,
        species: U32,
        mass: F64,
        diameter: F64,
        count: U64,
        temperature: F64,
        msd: OptF64,
        collisions: U64,
        a2: Absent<OptF64>,
    }
}

declare_table! {
    /// `dsmc_speed_histogram`: per run, histogram time, species and bin.
    pub struct DsmcSpeedHistogram in "dsmc_speed_histogram", read as DsmcSpeedHistogramCols {
        run_id: U64,
        point_id: U32,
        t: F64,
        species: U32,
        bin: U32,
        c_lo: F64,
        c_hi: F64,
        count: U64,
        density: F64,
    }
}

declare_table! {
    /// `dsmc_tamsd`: per run, species and lag.
    pub struct DsmcTamsd in "dsmc_tamsd", read as DsmcTamsdCols {
        run_id: U64,
        point_id: U32,
        species: U32,
        lag: F64,
        tamsd: F64,
        t_total: F64,
    }
}

declare_table! {
    /// `dsmc_theory`: the kinetic-theory prediction per point, time and species (the Sonine
    /// columns and `a2` absent from theory files written before them).
    pub struct DsmcTheory in "dsmc_theory", read as DsmcTheoryCols {
        point_id: U32,
        t: F64,
        species: U32,
        temperature: F64,
        msd: OptF64,
        tau_v: F64,
        a2: Absent<OptF64>,
        temperature_sonine: Absent<OptF64>,
        msd_sonine: Absent<OptF64>,
    }
}

declare_table! {
    /// `dsmc_theory_tamsd`: the TAMSD (27) per point, species and lag (over [0, t_end]).
    pub struct DsmcTheoryTamsd in "dsmc_theory_tamsd", read as DsmcTheoryTamsdCols {
        point_id: U32,
        species: U32,
        lag: F64,
        tamsd: F64,
    }
}

declare_table! {
    /// `dsmc_theory_point`: per point, tau_0 (21) and the initial temperatures actually used.
    pub struct DsmcTheoryPoint in "dsmc_theory_point", read as DsmcTheoryPointCols {
        point_id: U32,
        tau_0: F64,
        initial_temperatures: ListF64,
    }
}

declare_table! {
    /// `dsmc_species_summary`: mean and sem over the replicas per point, time and species,
    /// with the theory and the deviations from it (the point's sweep columns follow
    /// `point_id` in the file: `CampaignView::write_summary`). The theory, deviation, Sonine
    /// and a2 columns may be absent (summaries written before them, or without theory).
    pub struct DsmcSpeciesSummary in "dsmc_species_summary", read as DsmcSpeciesSummaryCols {
        point_id: U32,
        t: F64,
        species: U32,
        n_replicas: U32,
        temperature_mean: F64,
        temperature_sem: OptF64,
        msd_mean: OptF64,
        msd_sem: OptF64,
        temperature_theory: Absent<OptF64>,
        msd_theory: Absent<OptF64>,
        temperature_dev_sigma: Absent<OptF64>,
        temperature_dev_rel: Absent<OptF64>,
        msd_dev_sigma: Absent<OptF64>,
        msd_dev_rel: Absent<OptF64>,
        temperature_sonine: Absent<OptF64>,
        temperature_sonine_dev_sigma: Absent<OptF64>,
        temperature_sonine_dev_rel: Absent<OptF64>,
        msd_sonine: Absent<OptF64>,
        msd_sonine_dev_sigma: Absent<OptF64>,
        msd_sonine_dev_rel: Absent<OptF64>,
        a2_mean: Absent<OptF64>,
        a2_sem: Absent<OptF64>,
        a2_theory: Absent<OptF64>,
    }
}

declare_table! {
    /// `dsmc_tamsd_summary`: mean and sem over the replicas per point, species and lag, with
    /// the theory (27).
    pub struct DsmcTamsdSummary in "dsmc_tamsd_summary", read as DsmcTamsdSummaryCols {
        point_id: U32,
        species: U32,
        lag: F64,
        n_replicas: U32,
        tamsd_mean: F64,
        tamsd_sem: OptF64,
        tamsd_theory: OptF64,
    }
}

declare_table! {
    /// `dsmc_speed_histogram_summary`: mean and sem of the density over the replicas per
    /// point, time, species and bin.
    pub struct DsmcSpeedHistogramSummary in "dsmc_speed_histogram_summary",
        read as DsmcSpeedHistogramSummaryCols {
        point_id: U32,
        t: F64,
        species: U32,
        bin: U32,
        c_lo: F64,
        c_hi: F64,
        n_replicas: U32,
        density_mean: F64,
        density_sem: OptF64,
    }
}

/// `dsmc_species`: per output time and species.
pub fn species_batch(ids: RunIds, rows: &[SpeciesRow]) -> RecordBatch {
    let rows: Vec<DsmcSpecies> = rows
        .iter()
        .map(|r| DsmcSpecies {
            run_id: ids.run_id,
            point_id: ids.point_id,
            t: r.t,
            species: r.species,
            mass: r.mass,
            diameter: r.diameter,
            count: r.count,
            temperature: r.temperature,
            msd: r.msd,
            collisions: r.collisions,
            a2: r.value(RowValue::A2),
        })
        .collect();
    DsmcSpecies::batch(&rows)
}

/// `dsmc_speed_histogram`: per histogram time, species and bin.
pub fn hist_batch(ids: RunIds, rows: &[HistRow]) -> RecordBatch {
    let rows: Vec<DsmcSpeedHistogram> = rows
        .iter()
        .map(|r| DsmcSpeedHistogram {
            run_id: ids.run_id,
            point_id: ids.point_id,
            t: r.t,
            species: r.species,
            bin: r.bin,
            c_lo: r.c_lo,
            c_hi: r.c_hi,
            count: r.count,
            density: r.density,
        })
        .collect();
    DsmcSpeedHistogram::batch(&rows)
}

/// `dsmc_tamsd`: per species and lag.
pub fn tamsd_batch(ids: RunIds, rows: &[TamsdRow]) -> RecordBatch {
    let rows: Vec<DsmcTamsd> = rows
        .iter()
        .map(|r| DsmcTamsd {
            run_id: ids.run_id,
            point_id: ids.point_id,
            species: r.species,
            lag: r.lag,
            tamsd: r.tamsd,
            t_total: r.t_total,
        })
        .collect();
    DsmcTamsd::batch(&rows)
}

/// `dsmc_theory`: the kinetic-theory prediction per point, time and species.
pub fn theory_batch(rows: &[(u32, TheoryRow)]) -> RecordBatch {
    let rows: Vec<DsmcTheory> = rows
        .iter()
        .map(|(p, r)| DsmcTheory {
            point_id: *p,
            t: r.t,
            species: r.species,
            temperature: r.temperature,
            msd: r.msd,
            tau_v: r.tau_v,
            a2: r.a2,
            temperature_sonine: r.temperature_sonine,
            msd_sonine: r.msd_sonine,
        })
        .collect();
    DsmcTheory::batch(&rows)
}

/// `dsmc_theory_tamsd`: the TAMSD (27) per point, species and lag (measured over [0, t_end]).
pub fn theory_tamsd_batch(rows: &[(u32, TamsdTheoryRow)]) -> RecordBatch {
    let rows: Vec<DsmcTheoryTamsd> = rows
        .iter()
        .map(|(p, r)| DsmcTheoryTamsd {
            point_id: *p,
            species: r.species,
            lag: r.lag,
            tamsd: r.tamsd,
        })
        .collect();
    DsmcTheoryTamsd::batch(&rows)
}

/// `dsmc_theory_point`: per point, tau_0 (21) and the initial temperatures actually used.
pub fn theory_point_batch(points: &[(u32, f64, Vec<f64>)]) -> RecordBatch {
    let rows: Vec<DsmcTheoryPoint> = points
        .iter()
        .map(|(p, tau_0, t)| DsmcTheoryPoint {
            point_id: *p,
            tau_0: *tau_0,
            initial_temperatures: t.clone(),
        })
        .collect();
    DsmcTheoryPoint::batch(&rows)
}
