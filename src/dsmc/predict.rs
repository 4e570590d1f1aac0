//! Kinetic theory beside a DSMC run (spec section 6): the predictions for the run's own
//! species, restitution and initial temperatures, at its output times. The DSMC and the
//! theory share the pair scaling of the restitution (`system::theory_restitution`).

use super::system::{theory_restitution, DsmcSystem};
use crate::theory::{diffusion, msd, sonine, tamsd, temperature, Species, TheoryError};

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
    /// The species' a2 in the Sonine HCS (`theory::sonine`); None unless the restitution is
    /// constant.
    pub a2: Option<f64>,
    /// T_k(t) with the a2-corrected cooling rates (first Sonine approximation, a2 slaved to
    /// the instantaneous temperatures); None unless the restitution is constant.
    pub temperature_sonine: Option<f64>,
    /// <R_k^2(t)> in the first Sonine approximation (`sonine::msd_sonine`: the Sonine
    /// temperature history and the a2-corrected tau_v); None unless MSD is recorded and the
    /// Sonine theory is given (constant restitution, at most `SONINE_MAX_SPECIES` species).
    pub msd_sonine: Option<f64>,
}

/// One row of `dsmc_theory_tamsd`: the TAMSD (27) of a species at a lag, for t = t_end.
#[derive(Clone, Debug, PartialEq)]
pub struct TamsdTheoryRow {
    pub species: u32,
    /// The lag as the run reports it (a multiple of the grid step).
    pub lag: f64,
    pub tamsd: f64,
}

/// The predictions for one point.
#[derive(Clone, Debug, PartialEq)]
pub struct Prediction {
    /// tau_0 (21) at the initial temperatures (2 / xi(0), number-weighted; exact in the HCS).
    pub tau0: f64,
    pub initial_temperatures: Vec<f64>,
    pub rows: Vec<TheoryRow>,
    /// The TAMSD (27) per species and lag (empty unless `tamsd` is observed).
    pub tamsd: Vec<TamsdTheoryRow>,
    /// Why optional columns are null (the Sonine ones where that theory fails).
    pub notes: Vec<String>,
}

pub fn theory_species(sys: &DsmcSystem) -> Vec<Species> {
    sys.species
        .iter()
        .map(|s| Species::new(s.mass, s.diameter, s.count as f64 / sys.volume))
        .collect()
}

/// The most species for which the Sonine columns are computed (null beyond).
pub const SONINE_MAX_SPECIES: usize = 4;

/// Predict T_k(t), <R_k^2(t)> and tau_v,k(t) at the system's output times; an error (never a
/// panic) where the theory cannot be computed for this system.
pub fn predict(sys: &DsmcSystem) -> Result<Prediction, TheoryError> {
    let species = theory_species(sys);
    let r = theory_restitution(&sys.restitution, &sys.species);
    let t0: Vec<f64> = sys.species.iter().map(|s| s.initial_temperature).collect();
    let times = &sys.output_times;
    let temps = temperature::evolve_temperatures(&species, &r, &t0, times)?;
    // The Sonine theory costs O(M^3) collision-moment quadratures per ODE step: given for
    // up to SONINE_MAX_SPECIES species only.
    // They are columns beyond the paper: where they cannot be computed (e.g. a mixture
    // without a homogeneous cooling state, which exists only up to a critical mass ratio),
    // they are null and the reason is noted, while the Maxwellian theory stands.
    let small = species.len() <= SONINE_MAX_SPECIES;
    let mut notes = Vec::new();
    let mut sonine_or_note = |what: &str, r: Result<Option<Vec<Vec<f64>>>, TheoryError>| match r {
        Ok(v) => v,
        Err(e) => {
            notes.push(format!("the Sonine {what} is not given: {e}"));
            None
        }
    };
    let a2 = if small {
        sonine_or_note(
            "a2",
            sonine::hcs_temperatures_sonine(&species, &r, 1.0).map(|x| x.map(|(_, a2)| vec![a2])),
        )
        .and_then(|mut v| v.pop())
    } else {
        None
    };
    let sonine_temps = if small {
        sonine_or_note(
            "temperature",
            sonine::evolve_temperatures_sonine(&species, &r, &t0, times),
        )
    } else {
        None
    };
    let msds_sonine = if small && sys.observe.msd {
        sonine_or_note("MSD", sonine::msd_sonine(&species, &r, &t0, times))
    } else {
        None
    };
    let msds = if sys.observe.msd {
        Some(msd::msd_numeric(&species, &r, &t0, times)?)
    } else {
        None
    };
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
                a2: a2.as_ref().map(|a| a[k]),
                temperature_sonine: sonine_temps.as_ref().map(|s| s[j][k]),
                msd_sonine: msds_sonine.as_ref().map(|m| m[j][k]),
            });
        }
    }
    let tamsd = match &sys.observe.tamsd {
        Some(plan) => predict_tamsd(&species, &r, &t0, sys.t_end, &plan.lags),
        None => Vec::new(),
    };
    let tau0 = temperature::tau0_with(&species, &t0, &r);
    let finite = |v: f64| !v.is_nan();
    if !(finite(tau0)
        && rows
            .iter()
            .all(|r| finite(r.temperature) && finite(r.tau_v))
        && tamsd.iter().all(|r| finite(r.tamsd)))
    {
        return Err(TheoryError::new(
            "the predictions are not numbers (NaN): the system is beyond what the theory can compute",
        ));
    }
    Ok(Prediction {
        tau0,
        initial_temperatures: t0,
        rows,
        tamsd,
        notes,
    })
}

/// The TAMSD (27) of every species at the lags `lags`, measured over [0, t_end].
///
/// (27) is the time average of the MSD increment of a gas that is in its homogeneous cooling
/// state from t = 0 on (with D_k(0), tau_v,k(0) and tau_0 at the initial temperatures `t0`);
/// for a run that starts elsewhere (e.g. every species at the same temperature while the HCS
/// has T_k != T_1) it is that of the HCS with the run's initial temperatures, not a prediction
/// of the transient. This is `tamsd::tamsd_hcs_species` for every species, with D_k(0),
/// tau_v,k(0) and tau_0 computed once for all species (each costs O(M^2) pair integrals).
pub fn predict_tamsd(
    species: &[Species],
    r: &crate::theory::PairRestitution,
    t0: &[f64],
    t_end: f64,
    lags: &[f64],
) -> Vec<TamsdTheoryRow> {
    let d = diffusion::diffusion_coefficients(species, t0, r);
    let tv = diffusion::tau_v(species, t0, r);
    let tau0 = temperature::tau0_with(species, t0, r);
    let mut rows = Vec::with_capacity(species.len() * lags.len());
    for k in 0..species.len() {
        for &lag in lags {
            rows.push(TamsdTheoryRow {
                species: k as u32 + 1,
                lag,
                tamsd: tamsd::tamsd_hcs(d[k], tv[k], tau0, t_end, lag),
            });
        }
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::theory::PairRestitution;

    fn system(species: &[(f64, f64, u64)], volume: f64) -> DsmcSystem {
        DsmcSystem {
            method: crate::dsmc::system::Method::LowRank,
            species: species
                .iter()
                .map(
                    |&(mass, diameter, count)| crate::dsmc::system::SpeciesInfo {
                        mass,
                        diameter,
                        count,
                        initial_temperature: 1.0,
                    },
                )
                .collect(),
            volume,
            restitution: crate::dsmc::system::RestitutionModel::Constant(0.7),
            t_end: 10.0,
            output_times: vec![0.0, 1.0, 10.0],
            observe: crate::dsmc::Observed {
                msd: true,
                ..Default::default()
            },
            refresh_every: 1.0,
            rate_scale: std::f64::consts::PI / (4.0 * volume),
        }
    }

    /// The theory of a system it cannot compute is an error (before: a panic in the
    /// temperature ODE, "step size underflow", for a density of 1e308), and where only the
    /// Sonine columns fail (a mass ratio of 1000 at equal diameters: no homogeneous cooling
    /// state) those are null with a note (before: a panic, "HCS iteration did not converge").
    #[test]
    fn failures_are_errors_and_the_sonine_columns_optional() {
        let e = predict(&system(&[(1.0, 1.0, 100)], 1e-306)).unwrap_err();
        assert!(e.to_string().contains("collision frequency"), "{e}");
        let p = predict(&system(&[(1.0, 1.0, 100), (1000.0, 1.0, 100)], 2000.0)).unwrap();
        assert!(p.rows.iter().all(|r| r.a2.is_none()), "{:?}", p.rows[0]);
        assert!(p.rows.iter().all(|r| r.temperature.is_finite()));
        assert!(p.rows.iter().all(|r| r.msd.is_some_and(f64::is_finite)));
        assert!(
            p.notes.iter().any(|n| n.contains("Sonine a2")),
            "{:?}",
            p.notes
        );
        let fine = predict(&system(&[(1.0, 1.0, 100), (2.0, 1.2, 100)], 2000.0)).unwrap();
        assert!(fine.notes.is_empty() && fine.rows.iter().all(|r| r.a2.is_some()));
    }

    /// `predict_tamsd` is `tamsd_hcs_species` for every species (k 0-based there), bit for bit.
    #[test]
    fn predict_tamsd_is_tamsd_hcs_species() {
        let s = vec![
            Species::new(1.0, 1.0, 0.1),
            Species::new(8.0, 2.0, 0.01),
            Species::new(100.0, 100f64.cbrt(), 1e-5),
        ];
        let r = PairRestitution::Constant(0.7);
        let t0 = [1.0, 3.0, 50.0];
        let lags = [0.5, 7.0, 300.0];
        let rows = predict_tamsd(&s, &r, &t0, 1000.0, &lags);
        assert_eq!(rows.len(), 9);
        for k in 0..3 {
            let want = tamsd::tamsd_hcs_species(&s, &r, &t0, k, 1000.0, &lags);
            for (j, w) in want.iter().enumerate() {
                let row = &rows[k * 3 + j];
                assert_eq!(
                    (row.species, row.lag.to_bits(), row.tamsd.to_bits()),
                    (k as u32 + 1, lags[j].to_bits(), w.to_bits())
                );
            }
        }
    }
}
