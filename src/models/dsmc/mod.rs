//! The `dsmc` model: DSMC of the homogeneous cooling state of a polydisperse granular gas
//! (spec `dsmc.md`), with the kinetic theory beside every measurement.
//!
//! - [`params`]: the manifest's `params` and their resolution into a [`DsmcSystem`];
//! - [`tables`]: `dsmc_species`, `dsmc_tamsd`, `dsmc_speed_histogram` and the theory tables
//!   in Arrow form;
//! - [`summary`]: `dsmc_species_summary`, `dsmc_tamsd_summary` and
//!   `dsmc_speed_histogram_summary` over replicas;
//! - [`theory`]: the theory tables of a campaign (predictions of every point in parallel);
//! - [`figures`]: T_k(t), MSD_k(t), T_k and MSD ratios against k, after the campaign-wide
//!   figures of [`overview`]: deviation maps (points x species, in sems) and T_k, MSD_k at
//!   t_end against each numeric sweep key.

pub mod cost;
pub mod figures;
pub mod overview;
pub mod params;
pub mod summary;
pub mod tables;
pub mod theory;

use crate::dsmc::DsmcSim;
use crate::models::{
    CampaignView, CarryOver, Model, ModelError, ParamErrors, RunIds, RunRows, Simulation,
    TheoryEstimate,
};
use crate::physics::PhysicsError;
use crate::plot::Figure;
use crate::rng::StreamVersion;
use crate::store::parquet_io::StoreError;
pub use params::DsmcParams;
use tables::*;

/// The `dsmc` model.
pub struct Dsmc;

impl Model for Dsmc {
    type Params = DsmcParams;
    type Sim = DsmcSim;

    const STATE_FORMAT: &'static str = crate::dsmc::STATE_FORMAT;
    const EXAMPLE: &'static str = r#"{
        "method": "low_rank",
        "species": {"list": [{"mass": 1, "diameter": 1, "count": 400},
                             {"mass": 10, "diameter": 2, "count": 40}]},
        "number_density": 0.1,
        "restitution": {"constant": 0.7},
        "t_end": 20.0,
        "output_times": {"log": {"from": 0.1, "to": 20, "per_decade": 3}},
        "observables": ["temperature", "msd", "tamsd"],
        "tamsd": {"lags": [1, 4], "tracers": 10, "grid": 40}
    }"#;

    /// The end and the output times: a longer run of a point continues the shorter one.
    const HORIZON: &'static [&'static str] = &["t_end", "output_times"];

    fn check(p: &DsmcParams, path: &str, errors: &mut ParamErrors) {
        p.check(path, errors)
    }

    fn memory(p: &DsmcParams) -> u64 {
        p.memory_estimate()
    }

    fn start(p: &DsmcParams, seed: u64, stream: StreamVersion) -> Result<DsmcSim, ModelError> {
        Ok(DsmcSim::with_stream(p.system()?, seed, stream))
    }

    fn restore(p: &DsmcParams, state: &[u8]) -> Result<DsmcSim, ModelError> {
        let sys = p.system()?;
        Ok(DsmcSim::from_state_bytes(sys, state)?)
    }

    fn carry_over(old: &DsmcParams, new: &DsmcParams) -> CarryOver {
        if new.t_end < old.t_end {
            return CarryOver::Shorter(format!(
                "t_end {} is before the runs' end {}",
                new.t_end, old.t_end
            ));
        }
        if new.t_end == old.t_end {
            return CarryOver::Rerun("the same t_end with other output times".into());
        }
        if new.wants_tamsd() {
            return CarryOver::Rerun(
                "the time-averaged MSD is recorded on a grid that spans [0, t_end]".into(),
            );
        }
        let (a, b) = (
            old.output_times.resolve(old.t_end),
            new.output_times.resolve(new.t_end),
        );
        // The continued run keeps the shorter run's histograms: they must be the longer
        // run's up to the old end.
        let (ha, hb) = (old.vdist_times(), new.vdist_times());
        let hb_before: Vec<f64> = hb.into_iter().filter(|&t| t <= old.t_end).collect();
        if ha != hb_before {
            return CarryOver::Rerun(
                "the speed histograms' times up to the old end differ (by default only t_end has one)"
                    .into(),
            );
        }
        match crate::dsmc::continuable(old.t_end, &a, new.t_end, &b) {
            Ok(()) => CarryOver::Continue,
            Err(why) => CarryOver::Rerun(why.to_string()),
        }
    }

    fn final_state(sim: &mut DsmcSim) -> Option<Vec<Vec<u8>>> {
        sim.final_state_parts().map(Vec::from)
    }

    fn continue_from(p: &DsmcParams, state: &[u8]) -> Result<DsmcSim, ModelError> {
        let sys = p.system()?;
        Ok(DsmcSim::continue_from(sys, state)?)
    }

    fn finish(mut sim: DsmcSim, ids: RunIds) -> RunRows {
        let tamsd = sim.tamsd_rows();
        let species = sim.take_rows();
        let hist = sim.take_hist();
        let mut tables = vec![(DSMC_SPECIES, species_batch(ids, &species))];
        if !hist.is_empty() {
            tables.push((DSMC_SPEED_HISTOGRAM, hist_batch(ids, &hist)));
        }
        if !tamsd.is_empty() {
            tables.push((DSMC_TAMSD, tamsd_batch(ids, &tamsd)));
        }
        RunRows {
            collisions: sim.st.collisions,
            trials: sim.st.trials,
            tables,
        }
    }

    /// The per-row values of `dsmc_species` the point records (`a2`: granular before issue 16
    /// wrote the table without it).
    fn valued_columns(p: &DsmcParams) -> Vec<(&'static str, &'static str)> {
        p.row_values()
            .iter()
            .map(|v| (DSMC_SPECIES, v.column()))
            .collect()
    }

    /// The run tables a derived quantity may read (all of them, whatever the observables).
    fn run_tables() -> Vec<(&'static str, arrow_schema::SchemaRef)> {
        vec![
            (DsmcSpecies::TABLE, DsmcSpecies::schema()),
            (DsmcTamsd::TABLE, DsmcTamsd::schema()),
            (DsmcSpeedHistogram::TABLE, DsmcSpeedHistogram::schema()),
        ]
    }

    fn tables(points: &[&DsmcParams]) -> Vec<&'static str> {
        let mut t = vec![
            DSMC_SPECIES,
            DSMC_SPECIES_SUMMARY,
            DSMC_THEORY,
            DSMC_THEORY_POINT,
        ];
        // Tables of an observable exist only when it is recorded (an empty dataset directory
        // is an error for DuckDB's globs).
        if observes_tamsd(points) {
            t.extend([DSMC_TAMSD, DSMC_TAMSD_SUMMARY, DSMC_THEORY_TAMSD]);
        }
        if observes_vdist(points) {
            t.extend([DSMC_SPEED_HISTOGRAM, DSMC_SPEED_HISTOGRAM_SUMMARY]);
        }
        t
    }

    fn table_description(name: &str) -> Option<&'static str> {
        tables::description(name)
    }

    fn theory_tables(points: &[&DsmcParams]) -> Vec<&'static str> {
        let mut t = vec![DSMC_THEORY, DSMC_THEORY_POINT];
        if observes_tamsd(points) {
            t.push(DSMC_THEORY_TAMSD);
        }
        t
    }

    fn cost(p: &DsmcParams) -> f64 {
        cost::seconds(p)
    }

    fn theory_estimate(p: &DsmcParams) -> TheoryEstimate {
        p.theory_cost()
            .map_or_else(TheoryEstimate::default, |c| TheoryEstimate {
                seconds: c.seconds,
                bytes: c.bytes,
            })
    }

    fn write_theory(c: &CampaignView<'_, DsmcParams>) -> Result<(), StoreError> {
        theory::write(c)
    }

    fn write_summaries(c: &CampaignView<'_, DsmcParams>) -> Result<(), StoreError> {
        summary::write(c)
    }

    fn physics_name(key: &str) -> Option<String> {
        Some(overview::physics_name(key))
    }

    fn figures(
        c: &CampaignView<'_, DsmcParams>,
    ) -> Result<Option<Vec<(String, Figure)>>, StoreError> {
        figures::figures(c).map(Some)
    }
}

/// Whether any point records the time-averaged MSD (then, and only then, the campaign has
/// the `dsmc_tamsd*` tables).
pub fn observes_tamsd(points: &[&DsmcParams]) -> bool {
    points.iter().any(|p| p.wants_tamsd())
}

/// Whether any point records the velocity distribution (then, and only then, the campaign
/// has the `dsmc_speed_histogram*` tables).
pub fn observes_vdist(points: &[&DsmcParams]) -> bool {
    points.iter().any(|p| p.wants_vdist())
}

impl Simulation for DsmcSim {
    fn advance(&mut self, work: u64) -> Result<bool, PhysicsError> {
        DsmcSim::advance(self, work)
    }
    fn progress(&self) -> f64 {
        DsmcSim::progress(self)
    }
    fn time(&self) -> f64 {
        DsmcSim::time(self)
    }
    fn state_bytes(&mut self) -> Vec<u8> {
        DsmcSim::state_bytes(self)
    }
    /// The version decides the generator of the words (its checkpoints record which).
    fn draws_as(&self, stream: StreamVersion) -> bool {
        self.generator() == stream.dsmc_generator()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dsmc::{RowValue, SpeciesRow};

    /// The example's params with these observables.
    fn params(observables: &str) -> DsmcParams {
        let mut v: serde_json::Value = serde_json::from_str(Dsmc::EXAMPLE).expect("example");
        v["observables"] = serde_json::from_str(observables).expect("observables");
        serde_json::from_value(v).expect("params")
    }

    /// The valued columns are those of the observables' per-row values: `a2` with
    /// `velocity_distribution` (in any position of the list), none without.
    /// A restored run draws as the stream version it was started on, and only as the
    /// versions with the same generator (1 and 2: ChaCha8; 3: AES-128-CTR).
    #[test]
    fn restored_runs_draw_as_their_stream() {
        let p = params(r#"["temperature"]"#);
        for (started, same) in [
            (StreamVersion::V1, [true, true, false]),
            (StreamVersion::V2, [true, true, false]),
            (StreamVersion::V3, [false, false, true]),
        ] {
            let mut sim = Dsmc::start(&p, 5, started).unwrap();
            sim.advance(1_000).unwrap();
            let restored = Dsmc::restore(&p, &Simulation::state_bytes(&mut sim)).unwrap();
            for (v, want) in [StreamVersion::V1, StreamVersion::V2, StreamVersion::V3]
                .into_iter()
                .zip(same)
            {
                assert_eq!(
                    restored.draws_as(v),
                    want,
                    "started {started:?}, asked {v:?}"
                );
            }
        }
    }

    #[test]
    fn valued_columns_follow_the_observables() {
        assert!(Dsmc::valued_columns(&params(r#"["msd", "tamsd"]"#)).is_empty());
        assert_eq!(
            Dsmc::valued_columns(&params(r#"["msd", "velocity_distribution"]"#)),
            vec![(DSMC_SPECIES, "a2")]
        );
    }

    /// Every per-row value of the library has its column in `dsmc_species`, a nullable
    /// double filled from the row's value (a value added without its column fails here).
    #[test]
    fn every_row_value_has_its_column() {
        let mut row = SpeciesRow {
            t: 0.0,
            species: 1,
            mass: 1.0,
            diameter: 1.0,
            count: 1,
            temperature: 1.0,
            msd: None,
            values: Default::default(),
            collisions: 0,
        };
        let library = RowValue::ALL.iter().filter(|v| **v != RowValue::Probe);
        for (i, v) in library.clone().enumerate() {
            row.values.set(*v, Some(i as f64 + 0.5));
        }
        let batch = tables::species_batch(
            RunIds {
                run_id: 1,
                point_id: 1,
            },
            &[row],
        );
        for (i, v) in library.enumerate() {
            let (_, field) = batch
                .schema()
                .column_with_name(v.column())
                .map(|(j, f)| (j, f.clone()))
                .unwrap_or_else(|| panic!("no column {} in dsmc_species", v.column()));
            assert!(field.is_nullable());
            let col = batch
                .column_by_name(v.column())
                .unwrap()
                .as_any()
                .downcast_ref::<arrow_array::Float64Array>()
                .expect("a double column")
                .value(0);
            assert_eq!(col, i as f64 + 0.5, "{}", v.column());
        }
    }
}
