//! Kinetic theory beside a DSMC run (spec section 6): the predictions for the run's own
//! species, restitution and initial temperatures, at its output times. The DSMC and the
//! theory share the pair scaling of the restitution (`system::theory_restitution`).

use super::system::{theory_restitution, DsmcSystem};
use crate::theory::{diffusion, msd, temperature, Species};

/// One row of `dsmc_theory`.
#[derive(Clone, Debug, PartialEq)]
pub struct TheoryRow {
    pub t: f64,
    pub species: u32,
    pub temperature: f64,
    /// <R_k^2(t)> from (4) with the predicted temperature history; None unless MSD is recorded.
    pub msd: Option<f64>,
    /// Velocity correlation time tau_v,k(t) (10-11).
    pub tau_v: f64,
}

/// The predictions for one point.
#[derive(Clone, Debug, PartialEq)]
pub struct Prediction {
    /// tau_0 (21) at the initial temperatures (2 / xi(0), number-weighted; exact in the HCS).
    pub tau0: f64,
    pub initial_temperatures: Vec<f64>,
    pub rows: Vec<TheoryRow>,
}

pub fn theory_species(sys: &DsmcSystem) -> Vec<Species> {
    sys.species.iter().map(|s| Species::new(s.mass, s.diameter, s.count as f64 / sys.volume)).collect()
}

/// Predict T_k(t), <R_k^2(t)> and tau_v,k(t) at the system's output times.
pub fn predict(sys: &DsmcSystem) -> Prediction {
    let species = theory_species(sys);
    let r = theory_restitution(&sys.restitution, &sys.species);
    let t0: Vec<f64> = sys.species.iter().map(|s| s.initial_temperature).collect();
    let times = &sys.output_times;
    let temps = temperature::evolve_temperatures(&species, &r, &t0, times);
    let msds = if sys.msd { Some(msd::msd_numeric(&species, &r, &t0, times)) } else { None };
    let mut rows = Vec::with_capacity(times.len() * species.len());
    for (j, &t) in times.iter().enumerate() {
        let tv = diffusion::tau_v(&species, &temps[j], &r);
        for k in 0..species.len() {
            rows.push(TheoryRow {
                t,
                species: k as u32 + 1,
                temperature: temps[j][k],
                msd: msds.as_ref().map(|m| m[j][k]),
                tau_v: tv[k],
            });
        }
    }
    Prediction { tau0: temperature::tau0_with(&species, &t0, &r), initial_temperatures: t0, rows }
}
