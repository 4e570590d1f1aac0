//! The `rfm` model: soft-sphere molecular dynamics of the Random Force Model in 1D and 2D with
//! the observables of Bray's thesis (spec `rfm.md`).
//!
//! - [`params`]: the manifest's `params` and their resolution into the run's configuration;
//! - [`tables`]: the run-level tables in Arrow form;
//! - [`summary`]: the replica summaries;
//! - [`figures`]: the standard figures from the summaries;
//! - [`analysis`]: the thesis's fits across points (`granular analyze`).

pub mod analysis;
pub mod cost;
pub mod figures;
pub mod params;
pub mod summary;
pub mod tables;
#[cfg(test)]
mod tests;

use crate::models::{
    AnalyzeFn, CampaignView, CarryOver, Model, ModelError, ParamErrors, RunIds, RunRows, Simulation,
};
use crate::physics::PhysicsError;
use crate::plot::Figure;
use crate::rfm::observe::RfmRun;
use crate::rng::StreamVersion;
use crate::store::parquet_io::StoreError;
pub use params::{RfmObservable, RfmParams};
use tables::*;

/// Layout version of the RFM checkpoint payload and final state (5: the blocked accumulators
/// keep per-sample sums, grouped into blocks at the end).
pub const STATE_FORMAT: &str = "rfm/5";

/// The `rfm` model.
pub struct Rfm;

impl Model for Rfm {
    type Params = RfmParams;
    type Sim = RfmRun;

    const STATE_FORMAT: &'static str = STATE_FORMAT;
    const EXAMPLE: &'static str = r#"{
        "dim": 2, "n_particles": 60, "packing_fraction": 0.3,
        "warmup": 0.002, "duration": 0.01, "sample_every": 500,
        "observables": ["temperature", "velocity_moments", "velocity_histogram",
                        "structure_factor", "radial_distribution", "free_paths",
                        "post_collision_velocity", "snapshot"],
        "velocity_histogram": {"range": [-2, 2], "bins": 40},
        "structure_factor": {"k_max": 5, "every": 2},
        "radial_distribution": {"bins": 20, "every": 2},
        "snapshot": {"times": [0.005]}
    }"#;

    /// The sampled time: a longer run of a point has the seed of the shorter one and continues
    /// it (the blocks of the errors are formed at the end, from per-sample sums).
    const HORIZON: &'static [&'static str] = &["duration"];

    fn check(p: &RfmParams, path: &str, errors: &mut ParamErrors) {
        p.check(path, errors)
    }

    fn cost(p: &RfmParams) -> f64 {
        cost::seconds(p)
    }

    fn memory(p: &RfmParams) -> u64 {
        p.memory_estimate()
    }

    fn start(p: &RfmParams, seed: u64, stream: StreamVersion) -> Result<RfmRun, ModelError> {
        Ok(RfmRun::with_stream(&p.run_config(), seed, stream)?)
    }

    fn restore(p: &RfmParams, state: &[u8]) -> Result<RfmRun, ModelError> {
        Ok(RfmRun::from_state_bytes(&p.run_config(), state)?)
    }

    fn carry_over(old: &RfmParams, new: &RfmParams) -> CarryOver {
        if new.duration < old.duration {
            CarryOver::Shorter(format!(
                "duration {} is shorter than the runs' {}",
                new.duration, old.duration
            ))
        } else {
            CarryOver::Continue
        }
    }

    fn final_state(run: &mut RfmRun) -> Option<Vec<Vec<u8>>> {
        run.final_state().map(|s| vec![s])
    }

    fn continue_from(p: &RfmParams, state: &[u8]) -> Result<RfmRun, ModelError> {
        Ok(RfmRun::continue_from(&p.run_config(), state)?)
    }

    fn finish(run: RfmRun, ids: RunIds) -> RunRows {
        let steps = run.sim.step();
        RunRows {
            collisions: 0,
            trials: steps,
            tables: batches(ids, &run.finish()),
        }
    }

    /// The run tables a derived quantity may read (all of them, whatever the observables).
    fn run_tables() -> Vec<(&'static str, arrow_schema::SchemaRef)> {
        vec![
            (RfmTimeseries::TABLE, RfmTimeseries::schema()),
            (RfmMoments::TABLE, RfmMoments::schema()),
            (RfmHistograms::TABLE, RfmHistograms::schema()),
            (RfmNeighbourMoments::TABLE, RfmNeighbourMoments::schema()),
            (RfmStructureFactor::TABLE, RfmStructureFactor::schema()),
            (RfmRadial::TABLE, RfmRadial::schema()),
            (RfmTemperatureBlocks::TABLE, RfmTemperatureBlocks::schema()),
            (RfmSnapshots::TABLE, RfmSnapshots::schema()),
            (RfmFreePathMoments::TABLE, RfmFreePathMoments::schema()),
        ]
    }

    fn tables(points: &[&RfmParams]) -> Vec<&'static str> {
        use RfmObservable as O;
        let wants = |o: O| points.iter().any(|p| p.wants(o));
        let mut v = vec![
            RFM_TIMESERIES,
            RFM_TIMESERIES_SUMMARY,
            RFM_TEMPERATURE_BLOCKS,
        ];
        if wants(O::Snapshot) {
            v.push(RFM_SNAPSHOTS);
        }
        if wants(O::VelocityMoments) {
            v.extend([RFM_MOMENTS, RFM_MOMENTS_SUMMARY]);
        }
        if wants(O::VelocityHistogram)
            || wants(O::NeighbourDistances)
            || wants(O::FreePaths)
            || wants(O::PostCollisionVelocity)
        {
            v.extend([RFM_HISTOGRAMS, RFM_HISTOGRAMS_SUMMARY]);
        }
        if wants(O::NeighbourDistances) {
            v.extend([RFM_NEIGHBOUR_MOMENTS, RFM_NEIGHBOUR_MOMENTS_SUMMARY]);
        }
        if wants(O::StructureFactor) {
            v.extend([RFM_STRUCTURE_FACTOR, RFM_STRUCTURE_FACTOR_SUMMARY]);
        }
        if wants(O::RadialDistribution) {
            v.extend([RFM_RADIAL, RFM_RADIAL_SUMMARY]);
        }
        if wants(O::FreePaths) {
            v.extend([RFM_FREE_PATH_MOMENTS, RFM_FREE_PATH_MOMENTS_SUMMARY]);
        }
        v
    }

    fn table_description(name: &str) -> Option<&'static str> {
        tables::description(name)
    }

    fn write_summaries(c: &CampaignView<'_, RfmParams>) -> Result<(), StoreError> {
        let points: Vec<&RfmParams> = c.points.iter().map(|p| p.params).collect();
        summary::write(c, &Self::tables(&points))
    }

    fn physics_name(key: &str) -> Option<String> {
        figures::physics_name(key)
    }

    fn figures(
        c: &CampaignView<'_, RfmParams>,
    ) -> Result<Option<Vec<(String, Figure)>>, StoreError> {
        figures::figures(c).map(Some)
    }

    fn analysis() -> Option<AnalyzeFn<RfmParams>> {
        Some(analysis::analyze)
    }
}

impl Simulation for RfmRun {
    /// `work` particle-steps: work / N time steps (at least one).
    fn advance(&mut self, work: u64) -> Result<bool, PhysicsError> {
        let n = self.sim.config().n_particles.max(1) as u64;
        RfmRun::advance(self, (work / n).max(1))
    }
    fn progress(&self) -> f64 {
        RfmRun::progress(self)
    }
    fn time(&self) -> f64 {
        self.sim.time()
    }
    fn state_bytes(&mut self) -> Vec<u8> {
        RfmRun::state_bytes(self)
    }
    /// Its checkpoints record the version they draw as.
    fn draws_as(&self, stream: StreamVersion) -> bool {
        self.sim.stream_version() == stream
    }
}
