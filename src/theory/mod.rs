//! Kinetic theory of polydisperse granular gases (Bodrova & Osinsky 2024, section II and
//! Appendix A): pure functions, usable without simulating. Maxwellian velocity distributions,
//! g2 = 1 (dilute). Equation numbers (n) are the paper's.
//!
//! # Public API
//!
//! Species and restitution
//! - [`Species`] `{ mass, diameter, density }` (sigma_ki = (sigma_k + sigma_i)/2).
//! - [`PairRestitution`]: `Constant(eps)`, `ConstantPairs(eps_ki)`,
//!   `VelocityDependent(Arc<dyn PairEps>)` with eps_ki(g_n) of the normal impact speed;
//!   constructors `velocity_dependent(|k, i, g_n| ..)`, `per_pair(..)`,
//!   `viscoelastic(species, a_kappa_00, F)` (eps = F(A kappa_ki^(2/5) g_n^(1/5))),
//!   `series(species, a_kappa_00, h)` (A1).
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
//! - `evolve_temperatures(species, &r, T0, times) -> Vec<Vec<f64>>` (13)-(15) for any number of
//!   species from any start, t up to 1e9 and beyond (implicit Radau IIA in log time);
//!   `evolve(.., with_reduced_time, tol) -> Vec<TemperatureState>` also gives the reduced
//!   times (6).
//!
//! Homogeneous cooling state ([`hcs`])
//! - `hcs_temperatures(species, &r, mean) -> Vec<f64>` (equal xi_k, number-weighted mean (25);
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
//!   `msd_numeric(species, &r, T0, times) -> Vec<Vec<f64>>` ((4)-(6) for any temperature
//!   history, any restitution), `msd_total(species, partial)` (3).
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
//! Numerics ([`quad`]): Gauss-Legendre rules, adaptive Gauss-Legendre, graded composite rules,
//! Gamma(x). The stiff ODE integrator and LU live in the private `ode` module.

pub mod diffusion;
pub mod hcs;
pub mod msd;
mod ode;
pub mod quad;
pub mod restitution;
pub mod tamsd;
pub mod temperature;
pub mod tracer;

pub use restitution::{PairEps, PairRates, PairRestitution};
pub use temperature::Species;
