//! Kinetic theory of polydisperse granular gases (Bodrova & Osinsky 2024, section II and
//! Appendix A): pure functions, usable without simulating. Maxwellian velocity distributions,
//! g2 = 1 (dilute). Equation numbers (n) are the paper's.
//!
//! # Public API
//!
//! Species and restitution
//! - [`Species`] `{ mass, diameter, density }` (sigma_ki = (sigma_k + sigma_i)/2).
//! - [`PairRestitution`]: `Constant(eps)`, `ConstantPairs(eps_ki)`,
//!   `VelocityDependent(Arc<dyn PairEps>)` with eps_ki(g_n) of the normal impact speed,
//!   `Scaled(Arc<ScaledEps>)` for eps_ki = f(a_ki g_n^p) (Maxwell averages tabulated once:
//!   use it for viscoelastic restitution, ~100x faster than an equivalent closure);
//!   constructors `velocity_dependent(|k, i, g_n| ..)`, `per_pair(..)`, `scaled(a, p, f)`,
//!   `viscoelastic(species, a_kappa_00, F)` (= `scaled(a_kappa_pairs(..), 0.2, F)`,
//!   eps = F(A kappa_ki^(2/5) g_n^(1/5))), `series(species, a_kappa_00, h)` (A1); `eps(k, i, g_n)`,
//!   `averages(k, i, u)`, `constant(k, i)`, `is_constant()`.
//! - [`restitution::pair_rates`]`(s_k, k, T_k, s_i, i, T_i, &r) -> PairRates { xi, tau_v_inv,
//!   collision_rate }`: xi_ki (15)/(A7) and tau_v,ki^-1 (11)/(A6), by exact quadrature over the
//!   Maxwellian impact speeds for velocity-dependent eps; [`restitution::maxwell_averages`].
//! - Appendix A series: [`restitution::xi_pair_series`] (A7),
//!   [`restitution::tau_v_inv_pair_series`] (A6), `series_a`, `series_b`, `a_kappa_pairs`.
//!
//! Temperatures ([`temperature`])
//! - `xi_pair(k, T_k, i, T_i, eps)` (15), `cooling_rates(species, T, eps)` (14),
//!   `cooling_rates_with(species, T, &r)`, `tau0(species, T0, eps)` / `tau0_with(.., &r)` (21),
//!   `haff(t, tau0)` (17), `collision_frequencies`, `time_scale`.
//! - `evolve_temperatures(species, &r, T0, times) -> Result<Vec<Vec<f64>>>` (13)-(15) for
//!   any number of species from any start, t up to 1e9 and beyond (implicit Radau IIA in log
//!   time); `evolve(.., with_reduced_time, tol) -> Result<Vec<TemperatureState>>` also gives
//!   the reduced times (6).
//!
//! Homogeneous cooling state ([`hcs`])
//! - `hcs_temperatures(species, &r, mean) -> Result<Vec<f64>>` (equal xi_k, number-weighted mean (25);
//!   for velocity-dependent eps: the instantaneous equal-cooling-rate state),
//!   `hcs_ratios(species, &r)` (T_k/T_1), `hcs_tau0(species, &r, mean)` (21),
//!   `xi_hat(species, T0, &r)` (20), `hcs_residual`.
//!
//! Diffusion ([`diffusion`])
//! - `tau_c(s_1, T_1)` (7), `tau_v(species, T, &r)` (10)-(11), `tau_v_inv_pairs` (11),
//!   `tau_v_24(species, T0, &r)` (24), `diffusion_coefficients(species, T, &r)` (8).
//!
//! MSD ([`msd`])
//! - `msd_hcs(D0, tau_v0, tau0, t)` (22) (stable; tau0 = inf: elastic), `msd_hcs_literal`,
//!   `msd_hcs_long(D0, tau0, t)` (23), `msd_hcs_species(species, &r, T0, times)`,
//!   `msd_numeric(species, &r, T0, times) -> Result<Vec<Vec<f64>>>` ((4)-(6) for any temperature
//!   history, any restitution), `msd_total(species, partial)` (3);
//!   `msd_from_history(species, T0, times, history)` ((4)-(6) for a given history of T_k,
//!   reduced times and tau_v,k: `HistoryPoint`).
//!
//! First Sonine approximation ([`sonine`], constant restitution)
//! - `a2_one_species`, `cooling_rate_one_species`, `a2_at`, `hcs_temperatures_sonine`,
//!   `evolve_temperatures_sonine`; `tau_v_inv_pairs_sonine`, `tau_v_sonine`,
//!   `tau_v_sonine_factor` (the a2-corrected (11)), `msd_sonine` ((4)-(6) along the Sonine
//!   history with the a2-corrected tau_v).
//!
//! Tracer limit ([`tracer`]), n_2 -> 0
//! - `tau0_tracer` (29), `tau_v1_tracer` (30), `msd_gas_tracer` (31), `tau_v2_tracer` (32),
//!   `tau_v2_hat` (33), `gamma21_heavy(.., B35::{Printed, Derived})` and `b35` (34)-(35),
//!   `gamma21_exact` (exact Maxwellian tracer HCS), `tracer_hcs`.
//!
//! Time-averaged MSD ([`tamsd`])
//! - `tamsd_hcs(D0, tau_v0, tau0, t, Delta)` (27) = `tamsd_first_term` + `xi_term` (Xi by
//!   quadrature), `tamsd_first_term_literal`, `tamsd_asymptotic` (28), `tamsd_hcs_species`.
//!
//! Cost ([`cost`])
//! - `estimate(&Workload) -> Cost { seconds, bytes }`: the CPU time and memory of one system's
//!   theory from its size (species, output times, span in collision times, msd, restitution),
//!   without solving anything.
//!
//! Errors: every solver returns [`TheoryError`] (invalid input, an ODE or iteration that fails)
//! instead of panicking.
//!
//! Numerics ([`quad`]): Gauss-Legendre rules, adaptive Gauss-Legendre, graded composite rules,
//! Gamma(x). The stiff ODE integrator and LU live in the private `ode` module.
//!
//! # Notes on the paper (each checked by a test)
//! - Fig 2: the HCS at mean T = 1 is T = (0.554070, 45.59302), ratio 82.2875, tau_0 = 19.2562.
//!   The printed T_2 = 45.58755 is the rounded T_1 = 0.554 times the ratio 82.288, and the
//!   printed tau_0 = 19.258 is 2/xi at those rounded temperatures.
//! - Fig 3: the printed T = (0.048, 1.1, 1.845) are the HCS at mean exactly 1, rounded
//!   (0.048152, 1.10659, 1.845261); tau_0 = 1.8368 there, printed 1.83 (truncated).
//! - Fig 5: the exact tracer HCS (n_2 = 0) gives T_2/T_1 = 412.928, tau_0 (29) = 11.284,
//!   tau_v,2 (32)-(33) = 1212.02, as printed. (35) as printed has sigma_12^2/sigma_2^2 where the
//!   mu >> 1 expansion gives sigma_1^2/sigma_12^2; with either, b > 1 for Fig 5, so (34) does
//!   not apply there (T_2/T_1 = 4.1 mu is not << mu).
//! - (28) is the asymptote of the first term of (27) only: Xi cancels its logarithm.
//! - (11) equals the velocity-relaxation rate of a tagged particle minus half the cooling rate.

pub mod cost;
pub mod diffusion;
pub mod hcs;
pub mod msd;
pub mod restitution;
pub mod sonine;
pub mod species;
pub mod tamsd;
pub mod temperature;
pub mod tracer;

pub use restitution::{PairEps, PairRates, PairRestitution, ScaledEps};
pub use species::Species;

/// Why a prediction could not be made: input the theory cannot take (no species, a
/// non-positive or non-finite mass, diameter, density, temperature or time) or numerics that
/// failed (an ODE whose step size underflows, a singular linear system, an iteration that does
/// not converge, a rate that overflows). Every function of this module that solves something
/// returns it instead of panicking, so a caller can name the point it failed for.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct TheoryError(pub String);

impl TheoryError {
    pub fn new(message: impl Into<String>) -> Self {
        TheoryError(message.into())
    }
}

/// `Ok(())` when `ok`, else the error `message()`.
pub(crate) fn ensure(ok: bool, message: impl FnOnce() -> String) -> Result<(), TheoryError> {
    if ok {
        Ok(())
    } else {
        Err(TheoryError(message()))
    }
}
