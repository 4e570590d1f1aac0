//! The `bisection` model: multiplicative bisection of [0, 1] (spec `rfm.md` 3.1), its length
//! histogram and moments beside the exact P_n and <a^m>^n.

pub mod figures;
pub mod params;
pub mod tables;

use crate::aux_models::bisection::BisectionRun;
use crate::models::{CampaignView, Model, ModelError, ParamErrors, RunIds, RunRows, Simulation};
use crate::physics::PhysicsError;
use crate::plot::Figure;
use crate::rng::StreamVersion;
use crate::store::parquet_io::StoreError;
pub use params::BisectionParams;
use tables::*;

/// The `bisection` model.
pub struct Bisection;

impl Model for Bisection {
    type Params = BisectionParams;
    type Sim = BisectionRun;

    const STATE_FORMAT: &'static str = "bisection/1";
    const EXAMPLE: &'static str =
        r#"{"level": 6, "realisations": 300, "split": {"concave": {"exponent": 0.5}}}"#;

    fn check(p: &BisectionParams, path: &str, errors: &mut ParamErrors) {
        p.check(path, errors)
    }

    /// The 2^n partition lengths of a realisation (twice: the working copy) and the histogram.
    /// The realisations' work units (2^(level+1) each) at [`WORK_UNIT_SECONDS`].
    fn cost(p: &BisectionParams) -> f64 {
        // 2^(level+1) work units per realisation (the partition and its histogram).
        RUN_OVERHEAD_SECONDS
            + p.realisations as f64 * 2f64.powi(p.level as i32 + 1) * WORK_UNIT_SECONDS
    }

    fn memory(p: &BisectionParams) -> u64 {
        let partitions = 1u64.checked_shl(p.level).unwrap_or(u64::MAX);
        partitions
            .saturating_mul(16)
            .saturating_add(1 << 20)
            .saturating_add(8 << 20)
    }

    fn start(
        p: &BisectionParams,
        seed: u64,
        _stream: StreamVersion,
    ) -> Result<BisectionRun, ModelError> {
        Ok(BisectionRun::new(p.config(), seed))
    }

    fn restore(p: &BisectionParams, state: &[u8]) -> Result<BisectionRun, ModelError> {
        Ok(BisectionRun::from_state_bytes(p.config(), state)?)
    }

    fn finish(run: BisectionRun, ids: RunIds) -> RunRows {
        let out = run.finish();
        let mut tables = Vec::new();
        if !out.histogram.is_empty() {
            tables.push((BISECTION_HISTOGRAM, histogram_batch(ids, &out.histogram)));
        }
        if !out.moments.is_empty() {
            tables.push((
                BISECTION_MOMENTS,
                moments_batch(ids, out.realisations, &out.moments),
            ));
        }
        RunRows {
            collisions: 0,
            trials: out.realisations,
            tables,
        }
    }

    /// The run tables a derived quantity may read (all of them, whatever the observables).
    fn run_tables() -> Vec<(&'static str, arrow_schema::SchemaRef)> {
        vec![
            (BisectionHistogram::TABLE, BisectionHistogram::schema()),
            (BisectionMoments::TABLE, BisectionMoments::schema()),
        ]
    }

    fn tables(_points: &[&BisectionParams]) -> Vec<&'static str> {
        vec![BISECTION_HISTOGRAM, BISECTION_MOMENTS]
    }

    fn table_description(name: &str) -> Option<&'static str> {
        tables::description(name)
    }

    fn figures(
        c: &CampaignView<'_, BisectionParams>,
    ) -> Result<Option<Vec<(String, Figure)>>, StoreError> {
        figures::figures(c).map(Some)
    }
}

impl Simulation for BisectionRun {
    /// `work` partition splits: whole realisations (at least one).
    fn advance(&mut self, work: u64) -> Result<bool, PhysicsError> {
        let n = (work / self.work_per_realisation()).max(1);
        Ok(BisectionRun::advance(self, n))
    }
    fn progress(&self) -> f64 {
        BisectionRun::progress(self)
    }
    fn time(&self) -> f64 {
        self.done() as f64
    }
    fn state_bytes(&mut self) -> Vec<u8> {
        BisectionRun::state_bytes(self)
    }
}

/// The cost model (`Model::cost`, reference machine): CPU seconds per work unit (2^(level+1)
/// per realisation; a work unit is a partition interval's draw, histogram bin and moments),
/// and of any run.
/// The probe: `granular plan JOB --threads 2` of a new directory times its cheapest run for
/// about a second; its factor (measured over estimated) set against table1-small's, measured
/// back to back (2026-11, the 2-core development machine at load ~6: table1-small 1.95 and
/// 1.86, whose DSMC constants come from its runs at load ~0.8): aux-bisection's probe 19.5 with 1.5e-9
/// s per unit, so ~10x that.
pub const WORK_UNIT_SECONDS: f64 = 1.5e-8;
pub const RUN_OVERHEAD_SECONDS: f64 = 0.01;

#[cfg(test)]
mod cost_tests {
    use super::*;

    fn example() -> BisectionParams {
        serde_json::from_str(Bisection::EXAMPLE).unwrap()
    }

    /// The cost model grows with the run's size.
    #[test]
    fn cost_grows_with_the_size() {
        // Realisations and level (2^(level+1) units each) multiply the cost.
        let mut p = example();
        let base = Bisection::cost(&p);
        p.realisations *= 10;
        let more = Bisection::cost(&p);
        assert!((more - RUN_OVERHEAD_SECONDS) / (base - RUN_OVERHEAD_SECONDS) > 9.99);
        p.level += 1;
        assert!(Bisection::cost(&p) > 1.99 * more - RUN_OVERHEAD_SECONDS);
    }
}
