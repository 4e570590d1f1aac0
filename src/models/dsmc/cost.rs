//! The cost model of a `dsmc` run (`Model::cost`): the CPU seconds one run of a point takes on
//! the reference machine, from its params alone (deterministic, so that decisions taken from
//! it are the same on every machine).
//!
//! A run's time goes into its trials (the engine's work units, `DsmcSim::advance`): every
//! trial draws a candidate pair and an acceptance uniform, and the accepted ones (the
//! collisions) update two velocities. The trials follow from the collisions, which follow
//! from the kinetic theory the model already has:
//!
//! - the collision rate at t = 0, R_0 = 1/2 sum_k N_k nu_k(0) (`theory::temperature::
//!   collision_frequencies`, Maxwellian, at the initial temperatures: the mean for an HCS
//!   start), and the cooling rate xi(0) (tau_0 = 2 / xi(0));
//! - constant restitution, Haff's law: nu(t) = nu(0) / (1 + t/tau_0), so the collisions over
//!   [0, t_end] are R_0 tau_0 ln(1 + t_end/tau_0) (R_0 t_end when nothing cools);
//!   viscoelastic: T ~ (1 + t/tau_v)^(-5/3) with tau_v = 5 / (3 xi(0)), so R_0 6 tau_v
//!   ((1 + t_end/tau_v)^(1/6) - 1);
//! - low-rank selection: about [`LOW_RANK_TRIALS_PER_COLLISION`] trials per collision;
//!   Bird's method: trials at the majorant rate N^2 2 pi b / V (b = max_s (sigma_s +
//!   sigma_max)^2 / 4 vmax_s, the engine's `bird_bound`, vmax_s the largest of N_s Maxwell
//!   speeds), which cools with the gas like the collision rate.
//!
//! Plus a pass over the particles at every output time and at the start.
//!
//! Calibration (2026-11, the 2-core development machine, release build, load ~0.8, one run
//! per core): `granular run jobs/table1-small.json` (N = 1.2e5, t_end = 100, eps 0.5 / 0.9),
//! wall seconds and trials of the `runs` table: low-rank 0.29 s / 3.52e6 trials, 0.58 s /
//! 6.84e6 (83-85 ns per trial, 2.9 and 2.65 trials per collision); Bird 3.35 s / 7.63e7,
//! 6.62 s / 1.375e8 (44-48 ns per trial). See scripts/cost-estimate-check.sh.

use super::params::{DsmcMethod, DsmcParams, InitialTemperature, Restitution};
use crate::dsmc::system::{theory_restitution, RestitutionModel};
use crate::theory::restitution::PairRestitution;
use crate::theory::temperature::{collision_frequencies, cooling_rates_with};
use crate::theory::Species;

/// CPU seconds per trial of the low-rank selection (reference machine).
pub const LOW_RANK_TRIAL_SECONDS: f64 = 84e-9;
/// Trials per collision of the low-rank selection (its majorant's acceptance is ~1/3).
pub const LOW_RANK_TRIALS_PER_COLLISION: f64 = 2.8;
/// CPU seconds per trial of Bird's method (reference machine).
pub const BIRD_TRIAL_SECONDS: f64 = 46e-9;
/// CPU seconds per particle and output time (the species' temperatures, MSDs, ... from the
/// velocities), and per particle at the start (the Maxwell velocities, the tables).
pub const OUTPUT_SECONDS_PER_PARTICLE: f64 = 3e-9;
pub const START_SECONDS_PER_PARTICLE: f64 = 1e-7;
/// CPU seconds of any run (the run's commit share, opening, checkpoints).
pub const RUN_OVERHEAD_SECONDS: f64 = 0.01;

/// The collisions and trials one run of `p` is expected to make (None where the species or
/// the theory cannot be had: refused elsewhere).
pub fn work(p: &DsmcParams) -> Option<(f64, f64)> {
    let (species, volume) = p.resolved_species().ok()?;
    if species.is_empty() || !(volume > 0.0 && volume.is_finite()) {
        return None;
    }
    let th: Vec<Species> = species
        .iter()
        .map(|s| Species::new(s.mass, s.diameter, s.count as f64 / volume))
        .collect();
    let t0: Vec<f64> = match p.initial_temperature {
        InitialTemperature::Hcs { mean } => vec![mean; species.len()],
        InitialTemperature::Value(_) => species.iter().map(|s| s.initial_temperature).collect(),
    };
    let nu = collision_frequencies(&th, &t0);
    let counts: Vec<f64> = species.iter().map(|s| s.count as f64).collect();
    let n: f64 = counts.iter().sum();
    let rate0 = 0.5 * counts.iter().zip(&nu).map(|(c, v)| c * v).sum::<f64>();
    let r = match &p.restitution {
        Restitution::Constant(e) => PairRestitution::Constant(*e),
        Restitution::Viscoelastic(v) => theory_restitution(
            &RestitutionModel::Viscoelastic { a_kappa: v.a_kappa },
            &species,
        ),
    };
    let xi = cooling_rates_with(&th, &t0, &r);
    let xi0 = counts.iter().zip(&xi).map(|(c, x)| c * x).sum::<f64>() / n;
    let t_end = p.t_end;
    // The collision rate integrated over [0, t_end], in units of the initial rate.
    let span = if !(xi0 > 0.0 && xi0.is_finite()) || xi0 * t_end < 1e-9 {
        t_end
    } else if matches!(p.restitution, Restitution::Constant(_)) {
        let tau0 = 2.0 / xi0;
        tau0 * (t_end / tau0).ln_1p()
    } else {
        let tau = 5.0 / (3.0 * xi0);
        6.0 * tau * ((1.0 + t_end / tau).powf(1.0 / 6.0) - 1.0)
    };
    let collisions = rate0 * span;
    let trials = match p.method {
        DsmcMethod::LowRank => LOW_RANK_TRIALS_PER_COLLISION * collisions,
        DsmcMethod::Bird => {
            let sigma_max = species.iter().map(|s| s.diameter).fold(0.0, f64::max);
            let bound = species
                .iter()
                .zip(&t0)
                .map(|(s, t)| {
                    let c = 0.25 * (s.diameter + sigma_max) * (s.diameter + sigma_max);
                    c * (t / s.mass).sqrt() * largest_maxwell(s.count as f64)
                })
                .fold(0.0, f64::max);
            let trial_rate0 = n * n * 2.0 * bound * std::f64::consts::PI / volume;
            trial_rate0 * span
        }
    };
    (collisions.is_finite() && trials.is_finite()).then_some((collisions, trials))
}

/// The largest of `n` Maxwell speeds in units of sqrt(T/m): x with n P(|v| > x) = 1,
/// P(|v| > x) ~ sqrt(2/pi) x exp(-x^2/2).
fn largest_maxwell(n: f64) -> f64 {
    let n = n.max(2.0);
    let mut x: f64 = 2.0;
    for _ in 0..8 {
        x = (2.0 * (n * (2.0 / std::f64::consts::PI).sqrt() * x).ln())
            .max(1.0)
            .sqrt();
    }
    x
}

/// CPU seconds of one run of `p` on the reference machine (see the module's doc).
pub fn seconds(p: &DsmcParams) -> f64 {
    let n = p
        .species_counts()
        .map_or(0.0, |c| c.iter().map(|&x| x as f64).sum());
    let per_trial = match p.method {
        DsmcMethod::LowRank => LOW_RANK_TRIAL_SECONDS,
        DsmcMethod::Bird => BIRD_TRIAL_SECONDS,
    };
    let trials = work(p).map_or(0.0, |(_, t)| t);
    let outputs = p.output_times.count_bound() as f64;
    RUN_OVERHEAD_SECONDS
        + per_trial * trials
        + n * (START_SECONDS_PER_PARTICLE + OUTPUT_SECONDS_PER_PARTICLE * outputs)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(method: &str, n1: u64, eps: f64, t_end: f64) -> DsmcParams {
        serde_json::from_value(serde_json::json!({
            "method": method,
            "species": {"power_law": {"n1": 0.1, "N1": n1, "theta": 3}},
            "restitution": {"constant": eps},
            "initial_temperature": 1.0,
            "t_end": t_end,
            "output_times": {"log": {"from": 0.01, "to": t_end, "per_decade": 10}},
            "observables": ["temperature", "msd"]
        }))
        .unwrap()
    }

    /// The collisions and trials of table1-small's points (jobs/table1-small.json, the
    /// `runs` table of a campaign of it: 1.206e6 / 2.58e6 collisions, 3.52e6 / 6.84e6
    /// low-rank trials, 7.6e7 / 1.37e8 Bird trials at eps 0.5 / 0.9) within 30 %.
    #[test]
    fn work_is_that_of_table1_small() {
        let near = |got: f64, want: f64| {
            assert!(
                (got / want - 1.0).abs() < 0.3,
                "estimated {got:e}, measured {want:e}"
            )
        };
        let (c, t) = work(&params("low_rank", 100_000, 0.5, 100.0)).unwrap();
        near(c, 1.206e6);
        near(t, 3.52e6);
        let (c, t) = work(&params("low_rank", 100_000, 0.9, 100.0)).unwrap();
        near(c, 2.58e6);
        near(t, 6.84e6);
        near(work(&params("bird", 100_000, 0.5, 100.0)).unwrap().1, 7.6e7);
        near(
            work(&params("bird", 100_000, 0.9, 100.0)).unwrap().1,
            1.37e8,
        );
    }

    fn mixture(method: &str, n: u64, eps: f64, t_end: f64) -> DsmcParams {
        serde_json::from_value(serde_json::json!({
            "method": method,
            "species": {"list": [{"mass": 1, "diameter": 1, "count": n},
                                 {"mass": 4, "diameter": 1.5, "count": n / 10}]},
            "number_density": 0.1,
            "restitution": {"constant": eps},
            "t_end": t_end,
            "output_times": {"log": {"from": 0.1, "to": t_end, "per_decade": 5}},
            "observables": ["temperature"]
        }))
        .unwrap()
    }

    /// The cost grows with the particles (10x at a fixed density: ~10x), with t_end (the
    /// collisions), with the restitution (less dissipation: more collisions) and is larger
    /// for Bird's method.
    #[test]
    fn cost_is_monotone() {
        let s = |m: &str, n: u64, e: f64, t: f64| seconds(&mixture(m, n, e, t));
        let base = s("low_rank", 10_000, 0.5, 100.0);
        let ten = s("low_rank", 100_000, 0.5, 100.0);
        let r = (ten - RUN_OVERHEAD_SECONDS) / (base - RUN_OVERHEAD_SECONDS);
        assert!(r > 9.0 && r < 11.0, "{base} {ten}");
        assert!(s("low_rank", 10_000, 0.5, 1000.0) > base);
        assert!(s("low_rank", 10_000, 0.5, 10.0) < base);
        assert!(s("low_rank", 10_000, 0.9, 100.0) > base);
        assert!(s("bird", 10_000, 0.5, 100.0) > base);
        // The collisions scale with N and grow (logarithmically, Haff) with t_end.
        let c = |n: u64, e: f64, t: f64| work(&mixture("low_rank", n, e, t)).unwrap().0;
        assert!((c(100_000, 0.5, 100.0) / c(10_000, 0.5, 100.0) - 10.0).abs() < 0.1);
        assert!(c(10_000, 0.5, 1000.0) > 1.3 * c(10_000, 0.5, 100.0));
        // Elastic: nothing cools, the collisions grow linearly with t_end.
        assert!((c(10_000, 1.0, 20.0) / c(10_000, 1.0, 10.0) - 2.0).abs() < 1e-9);
    }
}
