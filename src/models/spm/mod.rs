//! The `spm` model: the single particle model (spec `rfm.md` 3.2): Q(v, l) at a fixed free
//! path, or P(v) with free paths drawn from (4.25) or a table; the predicted tail exponent.

pub mod figures;
pub mod params;
pub mod tables;

use crate::aux_models::spm::SpmRun;
use crate::models::{CampaignView, Model, ModelError, ParamErrors, RunIds, RunRows, Simulation};
use crate::physics::PhysicsError;
use crate::plot::Figure;
use crate::store::parquet_io::StoreError;
pub use params::SpmParams;
use tables::*;

/// The `spm` model.
pub struct Spm;

impl Model for Spm {
    type Params = SpmParams;
    type Sim = SpmRun;

    const STATE_FORMAT: &'static str = "spm/1";
    const EXAMPLE: &'static str = r#"{
        "walks": 40, "dt": 1e-3,
        "free_path": {"fitted": {"c": 121, "fractal_dimension": 1.63, "range": [1e-6, 0.1]}},
        "velocity_histogram": {"range": [-2, 2], "bins": 100}
    }"#;

    fn check(p: &SpmParams, path: &str, errors: &mut ParamErrors) {
        p.check(path, errors)
    }

    /// The velocity histogram (counts, time and walk weights) and the free-path table.
    fn memory(p: &SpmParams) -> u64 {
        let bins = p
            .velocity_histogram
            .as_ref()
            .map_or(2000, |h| h.bins as u64);
        bins.saturating_mul(8 * 6).saturating_add(8 << 20)
    }

    fn start(p: &SpmParams, seed: u64) -> Result<SpmRun, ModelError> {
        Ok(SpmRun::new(p.config(), seed))
    }

    fn restore(p: &SpmParams, state: &[u8]) -> Result<SpmRun, ModelError> {
        Ok(SpmRun::from_state_bytes(p.config(), state)?)
    }

    fn finish(run: SpmRun, ids: RunIds) -> RunRows {
        let out = run.finish();
        let mut tables = Vec::new();
        if !out.histogram.is_empty() {
            tables.push((SPM_VELOCITY_HISTOGRAM, histogram_batch(ids, &out.histogram)));
        }
        tables.push((SPM_SUMMARY, summary_batch(ids, &out.summary)));
        RunRows {
            collisions: 0,
            trials: out.summary.samples / 2,
            tables,
        }
    }

    /// The run tables a derived quantity may read (all of them, whatever the observables).
    fn run_tables() -> Vec<(&'static str, arrow_schema::SchemaRef)> {
        vec![
            (SpmVelocityHistogram::TABLE, SpmVelocityHistogram::schema()),
            (SpmSummary::TABLE, SpmSummary::schema()),
        ]
    }

    fn tables(_points: &[&SpmParams]) -> Vec<&'static str> {
        vec![SPM_VELOCITY_HISTOGRAM, SPM_SUMMARY]
    }

    fn figures(
        c: &CampaignView<'_, SpmParams>,
    ) -> Result<Option<Vec<(String, Figure)>>, StoreError> {
        figures::figures(c).map(Some)
    }
}

impl Simulation for SpmRun {
    /// `work` Euler steps of whole walks.
    fn advance(&mut self, work: u64) -> Result<bool, PhysicsError> {
        Ok(SpmRun::advance(self, work))
    }
    fn progress(&self) -> f64 {
        SpmRun::progress(self)
    }
    fn time(&self) -> f64 {
        self.done() as f64
    }
    fn state_bytes(&mut self) -> Vec<u8> {
        SpmRun::state_bytes(self)
    }
}
