//! The cost model of an `rfm` run (`Model::cost`): CPU seconds on the reference machine from
//! the params alone. The MD's work is particle-steps (the engine's work units,
//! `RfmRun::advance`): N x (warm-up + sampled steps), each a force evaluation over the
//! neighbour lists, the noise and the integration; the samples add a pass over the
//! particles (and the structure factor, when recorded, one per k vector and evaluation).
//!
//! Calibration (2026-11, the 2-core development machine, release build):
//! `granular run jobs/rfm2d-steady.json` (N = 2000 discs in 2D, 8e5 steps, a sample every
//! 1000 steps): 119 s of user time for its 4 runs, 18.6 ns per particle-step; the probe of
//! `granular plan` (its cheapest run for about a second) set against table1-small's, back to
//! back at load ~6: rfm2d-steady 1.77 and rfm1d-xi2-small 1.83 with 2e-8 and 1e-8 s per
//! particle-step, table1-small 1.95 and 1.86 (whose DSMC constants come from its runs at load
//! ~0.8). See scripts/cost-estimate-check.sh.

use super::params::{RfmObservable, RfmParams};

/// CPU seconds per particle-step in 2D and in 1D (reference machine).
pub const PARTICLE_STEP_SECONDS_2D: f64 = 1.9e-8;
pub const PARTICLE_STEP_SECONDS_1D: f64 = 1.0e-8;
/// CPU seconds per particle and sample (temperature, moments, histograms).
pub const SAMPLE_SECONDS_PER_PARTICLE: f64 = 2e-8;
/// CPU seconds per particle and k vector (a complex multiply-add) of a structure-factor
/// evaluation.
pub const STRUCTURE_FACTOR_SECONDS: f64 = 5e-9;
/// CPU seconds of any run (its start, its commit share).
pub const RUN_OVERHEAD_SECONDS: f64 = 0.01;

/// The particle-steps of one run of `p`.
pub fn particle_steps(p: &RfmParams) -> f64 {
    let c = p.config();
    let steps = c.warmup_steps().saturating_add(c.duration_steps()) as f64;
    p.n_particles as f64 * steps
}

/// CPU seconds of one run of `p` on the reference machine.
pub fn seconds(p: &RfmParams) -> f64 {
    let c = p.config();
    let per_step = if p.dim >= 2 {
        PARTICLE_STEP_SECONDS_2D
    } else {
        PARTICLE_STEP_SECONDS_1D
    };
    let n = p.n_particles as f64;
    let samples = (c.duration_steps() / c.sample_every.max(1)) as f64;
    let mut s = RUN_OVERHEAD_SECONDS + per_step * particle_steps(p);
    s += samples * n * SAMPLE_SECONDS_PER_PARTICLE;
    if p.wants(RfmObservable::StructureFactor) {
        // N (pi/2) k_max^2 complex multiply-adds per evaluation (see `StructureFactorSpec`);
        // the default k_max: 20 L / (2 pi d).
        let sf = p.structure_factor.clone().unwrap_or_default();
        let k_max = sf.k_max.unwrap_or_else(|| {
            (20.0 * c.box_length() / (2.0 * std::f64::consts::PI * c.diameter())).floor()
        });
        let evals = samples / sf.every.max(1) as f64;
        s += evals * n * std::f64::consts::FRAC_PI_2 * k_max * k_max * STRUCTURE_FACTOR_SECONDS;
    }
    if s.is_finite() {
        s
    } else {
        f64::MAX
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(n: u64, warmup: f64, duration: f64) -> RfmParams {
        serde_json::from_value(serde_json::json!({
            "dim": 2, "n_particles": n, "packing_fraction": 0.3,
            "dt": 1e-6, "warmup": warmup, "duration": duration, "sample_every": 100,
            "observables": ["temperature"]
        }))
        .unwrap()
    }

    /// The cost grows with the particles and the steps (warm-up and sampled), ~ linearly.
    #[test]
    fn cost_is_monotone_in_particles_and_steps() {
        let base = seconds(&params(1000, 0.01, 0.01));
        assert!(seconds(&params(2000, 0.01, 0.01)) > 1.9 * base - RUN_OVERHEAD_SECONDS);
        assert!(seconds(&params(1000, 0.02, 0.01)) > base);
        assert!(seconds(&params(1000, 0.01, 0.02)) > base);
        assert_eq!(particle_steps(&params(1000, 0.01, 0.02)), 1000.0 * 30_000.0);
    }
}
