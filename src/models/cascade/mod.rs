//! The `cascade` model: multiplicative cascades on a 2^n x 2^n grid (spec `rfm.md` 3.4, thesis
//! ch. 6), S(k) by FFT, the D_f fit, and the particle placement of F 6.3; [`analysis`]: its
//! D_f fits of `granular analyze`.

pub mod analysis;
pub mod figures;
pub mod params;
pub mod summary;
pub mod tables;

use crate::aux_models::cascade::{CascadeOutput, CascadeRun};
use crate::models::{
    AnalyzeFn, CampaignView, Model, ModelError, ParamErrors, RunIds, RunRows, Simulation,
};
use crate::physics::PhysicsError;
use crate::plot::Figure;
use crate::rng::StreamVersion;
use crate::store::parquet_io::StoreError;
pub use params::CascadeParams;
use tables::*;

/// The `cascade` model.
pub struct Cascade;

impl Model for Cascade {
    type Params = CascadeParams;
    type Sim = CascadeRun;

    const STATE_FORMAT: &'static str = "cascade/1";
    const EXAMPLE: &'static str = r#"{
        "level": 5, "box_length": 0.2, "variant": "ucp", "realisations": 6,
        "k_max": 16, "fit_range": [1, 8],
        "placement": {"n_particles": 100, "radius": 1.5e-3, "k_max": 20}
    }"#;

    fn check(p: &CascadeParams, path: &str, errors: &mut ParamErrors) {
        p.check(path, errors)
    }

    /// The field, its FFT (complex) and the S(k) sums on the 2^n x 2^n grid, and the placed
    /// discs with their cell grid.
    /// The realisations' work units and the placement at [`WORK_UNIT_SECONDS`], [`PLACEMENT_SECONDS_PER_DISC`].
    fn cost(p: &CascadeParams) -> f64 {
        // 30 4^level work units per realisation (the field and its spectrum), and the
        // placement's discs.
        let field = p.realisations as f64 * 30.0 * 4f64.powi(p.level as i32) * WORK_UNIT_SECONDS;
        let discs = p.placement.as_ref().map_or(0.0, |pl| pl.n_particles as f64);
        RUN_OVERHEAD_SECONDS + field + discs * PLACEMENT_SECONDS_PER_DISC
    }

    fn memory(p: &CascadeParams) -> u64 {
        let side = 1u64.checked_shl(p.level).unwrap_or(u64::MAX);
        let cells = side.saturating_mul(side);
        let discs = p.placement.as_ref().map_or(0, |pl| pl.n_particles);
        cells
            .saturating_mul(8 + 8 + 16 + 16)
            .saturating_add(discs.saturating_mul(64))
            .saturating_add(8 << 20)
    }

    fn start(
        p: &CascadeParams,
        seed: u64,
        _stream: StreamVersion,
    ) -> Result<CascadeRun, ModelError> {
        Ok(CascadeRun::new(p.config(), seed))
    }

    fn restore(p: &CascadeParams, state: &[u8]) -> Result<CascadeRun, ModelError> {
        Ok(CascadeRun::from_state_bytes(p.config(), state)?)
    }

    fn finish(run: CascadeRun, ids: RunIds) -> RunRows {
        let trials = run.done();
        // A failed placement is reported by `advance`, so finish sees none.
        let out = run.finish().unwrap_or(CascadeOutput {
            structure_factor: Vec::new(),
            fits: Vec::new(),
            placement: Vec::new(),
        });
        let mut tables = Vec::new();
        if !out.structure_factor.is_empty() {
            tables.push((
                CASCADE_STRUCTURE_FACTOR,
                structure_factor_batch(ids, &out.structure_factor),
            ));
        }
        if !out.fits.is_empty() {
            tables.push((CASCADE_FIT, fit_batch(ids, &out.fits)));
        }
        if !out.placement.is_empty() {
            tables.push((CASCADE_PLACEMENT, placement_batch(ids, &out.placement)));
        }
        RunRows {
            collisions: 0,
            trials,
            tables,
        }
    }

    /// The run tables a derived quantity may read (all of them, whatever the observables).
    fn run_tables() -> Vec<(&'static str, arrow_schema::SchemaRef)> {
        vec![
            (
                CascadeStructureFactor::TABLE,
                CascadeStructureFactor::schema(),
            ),
            (CascadeFit::TABLE, CascadeFit::schema()),
            (CascadePlacement::TABLE, CascadePlacement::schema()),
        ]
    }

    fn tables(points: &[&CascadeParams]) -> Vec<&'static str> {
        let mut v = vec![
            CASCADE_STRUCTURE_FACTOR,
            CASCADE_STRUCTURE_FACTOR_SUMMARY,
            CASCADE_FIT,
        ];
        if points.iter().any(|p| p.placement.is_some()) {
            v.push(CASCADE_PLACEMENT);
        }
        v
    }

    fn table_description(name: &str) -> Option<&'static str> {
        tables::description(name)
    }

    fn write_summaries(c: &CampaignView<'_, CascadeParams>) -> Result<(), StoreError> {
        summary::write(c)
    }

    fn figures(
        c: &CampaignView<'_, CascadeParams>,
    ) -> Result<Option<Vec<(String, Figure)>>, StoreError> {
        figures::figures(c).map(Some)
    }

    fn analysis() -> Option<AnalyzeFn<CascadeParams>> {
        Some(analysis::analyze)
    }
}

impl Simulation for CascadeRun {
    /// `work` grid cells' worth of realisations; a failed placement is a physics failure.
    fn advance(&mut self, work: u64) -> Result<bool, PhysicsError> {
        let done = CascadeRun::advance(self, work);
        match self.failed() {
            Some(reason) => Err(PhysicsError {
                t: self.done() as f64,
                reason: reason.to_string(),
            }),
            None => Ok(done),
        }
    }
    fn progress(&self) -> f64 {
        CascadeRun::progress(self)
    }
    fn time(&self) -> f64 {
        self.done() as f64
    }
    fn state_bytes(&mut self) -> Vec<u8> {
        CascadeRun::state_bytes(self)
    }
}

/// The cost model (`Model::cost`, reference machine): CPU seconds per work unit (30 4^level
/// per realisation; the engine's unit, ~1 ns), per placed disc (rejection sampling and
/// overlap checks; an order of magnitude: placing gets slower as the discs fill the box), and
/// of any run.
/// The probe: `granular plan JOB --threads 2` of a new directory times its cheapest run for
/// about a second; its factor (measured over estimated) set against table1-small's, measured
/// back to back (2026-11, the 2-core development machine at load ~6: table1-small 1.95 and
/// 1.86, whose DSMC constants come from its runs at load ~0.8): aux-cascade 1.57 with 1e-9 s per unit, so
/// 0.85e-9; aux-cascade-placement (200 realisations, 2500 discs) 2.61 with 2e-6 s per disc, so
/// ~5e-5 s per disc.
pub const WORK_UNIT_SECONDS: f64 = 0.85e-9;
pub const PLACEMENT_SECONDS_PER_DISC: f64 = 5e-5;
pub const RUN_OVERHEAD_SECONDS: f64 = 0.01;

#[cfg(test)]
mod cost_tests {
    use super::*;

    fn example() -> CascadeParams {
        serde_json::from_str(Cascade::EXAMPLE).unwrap()
    }

    /// The cost model grows with the run's size.
    #[test]
    fn cost_grows_with_the_size() {
        // Realisations, the level (4x per level) and the placed discs add to the cost.
        let mut p = example();
        let base = Cascade::cost(&p);
        p.realisations *= 2;
        let more = Cascade::cost(&p);
        assert!(more > base);
        p.level += 1;
        assert!(Cascade::cost(&p) > 3.0 * (more - RUN_OVERHEAD_SECONDS));
        let mut q = example();
        q.placement.as_mut().unwrap().n_particles *= 10;
        assert!(Cascade::cost(&q) > base);
    }
}
