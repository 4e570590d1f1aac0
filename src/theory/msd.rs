//! Mean-squared displacements (section II.A, II.C): the partial MSD (4) with the reduced times
//! (5)-(6) for any temperature history, its HCS closed form (22) and long-time limit (23), and
//! the total MSD (3).
//!
//! # Numerical integration of (4)
//!
//! <R_k^2(t)> = 6 int_0^t D_k(t1) [1 - exp(-(tau_k(t) - tau_k(t1)) / tau_hat_v,k(t1))] dt1,
//! tau_hat_v,k = tau_v,k sqrt(T_k/T_k(0)) / tau_c(0) (5), d tau_k = sqrt(T_k/T_k(0)) dt / tau_c(0)
//! (6); tau_c(0) cancels in the ratio, so the reduced times are integrated without it, as
//! quadrature components of the temperature ODE (see [`super::temperature::evolve`]).
//! The t1-integral uses composite 16-point Gauss-Legendre panels: a global grid uniform in
//! s = ln(1 + t1/t_s) (step 0.5; geometric at late times, uniform at early ones), merged with
//! panels graded geometrically (ratio 2) towards t1 = t from a width tau_v/16 (the velocity
//! memory at t, where the integrand's kernel varies fastest). T_k and tau_k at every node come
//! from one implicit integration that lands on each node. Accuracy ~1e-9 relative.

use super::diffusion::{diffusion_coefficients, tau_v};
use super::restitution::{PairRestitution, PairTable};
use super::species::Species;
use super::temperature::{check_input, check_times, checked_time_scale, evolve, tau0_with};
use super::{ensure, TheoryError};
use crate::math::quad::{composite_nodes, phi, tau_ln1p};

/// (22): 6 D_k(0) tau_0 ln(1 + t/tau_0) + 6 D_k(0) tau_v,k(0) ((1 + t/tau_0)^-beta_k - 1),
/// beta_k = tau_0/tau_v,k(0), evaluated stably as 6 D tau_v phi(L/tau_v) with
/// L = tau_0 ln(1 + t/tau_0) and phi(x) = x - 1 + e^-x. tau0 = infinity (no cooling, eps = 1)
/// gives the elastic 6 D t - 6 D tau_v (1 - e^(-t/tau_v)).
pub fn msd_hcs(d0: f64, tau_v0: f64, tau0: f64, t: f64) -> f64 {
    6.0 * d0 * tau_v0 * phi(tau_ln1p(tau0, t) / tau_v0)
}

/// (22) written literally as in the paper (for checks; cancels badly at small t).
pub fn msd_hcs_literal(d0: f64, tau_v0: f64, tau0: f64, t: f64) -> f64 {
    let beta = tau0 / tau_v0;
    6.0 * d0 * tau0 * (1.0 + t / tau0).ln()
        + 6.0 * d0 * tau_v0 * ((1.0 + t / tau0).powf(-beta) - 1.0)
}

/// The long-time limit (23): 6 D_k(0) tau_0 ln(1 + t/tau_0).
pub fn msd_hcs_long(d0: f64, tau0: f64, t: f64) -> f64 {
    6.0 * d0 * tau_ln1p(tau0, t)
}

/// Partial MSDs (22) of every species for a start in the HCS at temperatures `t0`:
/// `result[j][k]` = `<R_k^2(times[j])>`, with D_k(0), tau_v,k(0) from (8), (10)-(11) and tau_0 (21).
pub fn msd_hcs_species(
    species: &[Species],
    restitution: &PairRestitution,
    t0: &[f64],
    times: &[f64],
) -> Vec<Vec<f64>> {
    let d = diffusion_coefficients(species, t0, restitution);
    let tv = tau_v(species, t0, restitution);
    let tau0 = tau0_with(species, t0, restitution);
    times
        .iter()
        .map(|&t| {
            (0..species.len())
                .map(|k| msd_hcs(d[k], tv[k], tau0, t))
                .collect()
        })
        .collect()
}

/// The total MSD (3): sum_k n_k <R_k^2> / n, from the partial MSDs `partial` (one per species).
pub fn msd_total(species: &[Species], partial: &[f64]) -> f64 {
    let n: f64 = species.iter().map(|s| s.density).sum();
    species
        .iter()
        .zip(partial)
        .map(|(s, r)| s.density * r)
        .sum::<f64>()
        / n
}

/// Partial MSDs (4) for any temperature history: the temperatures start at `t0` (t = 0) and
/// follow (13)-(15) (or their velocity-dependent form), `result[j][k]` = `<R_k^2(times[j])>`.
/// `times` sorted, >= 0, any range (e.g. up to 1e9). See the module docs for the method.
///
/// # Errors
/// See [`super::temperature::evolve`].
pub fn msd_numeric(
    species: &[Species],
    restitution: &PairRestitution,
    t0: &[f64],
    times: &[f64],
) -> Result<Vec<Vec<f64>>, TheoryError> {
    let table = PairTable::new(species, restitution);
    msd_from_history(species, t0, times, |ts: &[f64], nodes: bool| {
        Ok(evolve(species, restitution, t0, ts, nodes, 1e-11)?
            .into_iter()
            .map(|st| {
                let tv = if nodes {
                    table.tau_v(&st.temperatures)
                } else {
                    tau_v(species, &st.temperatures, restitution)
                };
                HistoryPoint {
                    temperatures: st.temperatures,
                    reduced_times: st.reduced_times,
                    tau_v: tv,
                }
            })
            .collect())
    })
}

/// What (4)-(6) need of a temperature history at one time t: T_k(t), the reduced times
/// int_0^t sqrt(T_k(t')/T_k(0)) dt' (= tau_k(t) tau_c(0)) and tau_v,k(t).
#[derive(Clone, Debug, PartialEq)]
pub struct HistoryPoint {
    pub temperatures: Vec<f64>,
    pub reduced_times: Vec<f64>,
    pub tau_v: Vec<f64>,
}

/// Partial MSDs (4) for the temperature history and velocity correlation times given by
/// `history(ts, nodes)` (the [`HistoryPoint`]s at the sorted times `ts`, starting at `t0` at
/// t = 0; it is called twice: at the output times, where only T_k and tau_v,k are used
/// (`nodes` false: the reduced times may be left empty), then at all quadrature nodes), with the
/// quadrature of [`msd_numeric`] (see the module docs): `result[j][k]` = `<R_k^2(times[j])>`.
/// `msd_numeric` is this with the Maxwellian history; `sonine::msd_sonine` with the Sonine one.
pub fn msd_from_history(
    species: &[Species],
    t0: &[f64],
    times: &[f64],
    history: impl Fn(&[f64], bool) -> Result<Vec<HistoryPoint>, TheoryError>,
) -> Result<Vec<Vec<f64>>, TheoryError> {
    check_input(species, t0)?;
    check_times(times)?;
    let m = species.len();
    let first = history(times, false)?;
    ensure(first.len() == times.len(), || {
        format!(
            "the history gave {} states for {} output times",
            first.len(),
            times.len()
        )
    })?;
    let t_s = checked_time_scale(species, t0)?;
    let t_max = times.iter().cloned().fold(0.0, f64::max);
    let ds = 0.5;
    let n_global = ((t_max / t_s).ln_1p() / ds).ceil() as usize + 1;
    let global: Vec<f64> = (0..=n_global)
        .map(|j| t_s * (j as f64 * ds).exp_m1())
        .collect();

    // Quadrature nodes and weights for each output time.
    let mut per_output: Vec<(Vec<f64>, Vec<f64>)> = Vec::with_capacity(times.len());
    for (j, &t) in times.iter().enumerate() {
        if t <= 0.0 {
            per_output.push((vec![], vec![]));
            continue;
        }
        let w = first[j]
            .tau_v
            .iter()
            .cloned()
            .fold(f64::INFINITY, f64::min)
            .min(t);
        ensure(w > 0.0 && w.is_finite(), || {
            format!(
                "the velocity correlation time at t = {t:e} is {w:e} (a finite time > 0 expected)"
            )
        })?;
        let mut b: Vec<f64> = global.iter().cloned().filter(|&x| x < t).collect();
        let mut d = w / 16.0;
        while t - d > 0.0 {
            b.push(t - d);
            d *= 2.0;
        }
        b.push(t);
        b.sort_by(f64::total_cmp);
        b.dedup_by(|a, bb| (*a - *bb).abs() <= 1e-13 * t);
        per_output.push(composite_nodes(&b));
    }

    // One history through all nodes (and the output times themselves).
    let mut all: Vec<f64> = times.to_vec();
    for (nodes, _) in &per_output {
        all.extend_from_slice(nodes);
    }
    all.sort_by(f64::total_cmp);
    all.dedup();
    let states = history(&all, true)?;
    ensure(states.len() == all.len(), || {
        format!(
            "the history gave {} states for {} times",
            states.len(),
            all.len()
        )
    })?;
    // Every node and output time is in `all` (it was built from them).
    let find = |t: f64| -> usize { all.binary_search_by(|x| x.total_cmp(&t)).unwrap_or(0) };
    // D_k, tau_hat_k (without tau_c(0)) and tau_k at each node.
    let mut node_d = vec![vec![0.0; m]; all.len()];
    let mut node_that = vec![vec![0.0; m]; all.len()];
    for (idx, st) in states.iter().enumerate() {
        let tv = &st.tau_v;
        for k in 0..m {
            node_d[idx][k] = st.temperatures[k] * tv[k] / species[k].mass;
            node_that[idx][k] = tv[k] * (st.temperatures[k] / t0[k]).sqrt();
        }
    }
    let out: Vec<Vec<f64>> = times
        .iter()
        .zip(&per_output)
        .map(|(&t, (nodes, weights))| {
            if t <= 0.0 {
                return vec![0.0; m];
            }
            let end = find(t);
            let tau_end = &states[end].reduced_times;
            (0..m)
                .map(|k| {
                    nodes
                        .iter()
                        .zip(weights)
                        .map(|(&x, &wgt)| {
                            let i = find(x);
                            let arg = (tau_end[k] - states[i].reduced_times[k]) / node_that[i][k];
                            wgt * 6.0 * node_d[i][k] * -(-arg).exp_m1()
                        })
                        .sum()
                })
                .collect()
        })
        .collect();
    ensure(out.iter().flatten().all(|v| v.is_finite()), || {
        "the mean-squared displacements are not finite numbers".into()
    })?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::theory::diffusion::tau_c;
    use crate::theory::hcs::hcs_temperatures;
    use crate::theory::tracer::msd_gas_tracer;

    fn same_material(masses: &[f64], dens: &[f64]) -> Vec<Species> {
        masses
            .iter()
            .zip(dens)
            .map(|(&m, &n)| Species {
                mass: m,
                diameter: m.cbrt(),
                density: n,
            })
            .collect()
    }

    /// In the HCS the numerical integration of (4) equals the closed form (22) to 1e-6
    /// relative for t from 1e-3 to 1e9 (Fig 2 and Fig 3 mixtures).
    #[test]
    fn numeric_4_equals_22_in_hcs() {
        let r = PairRestitution::Constant(0.5);
        for (masses, dens) in [
            (vec![1.0, 100.0], vec![0.1, 0.001]),
            (vec![1.0, 100.0, 500.0], vec![0.1, 0.1, 0.1]),
        ] {
            let s = same_material(&masses, &dens);
            let t0 = hcs_temperatures(&s, &r, 1.0).unwrap();
            let times = [0.0, 1e-3, 0.1, 1.0, 10.0, 100.0, 1e3, 1e5, 1e7, 1e9];
            let num = msd_numeric(&s, &r, &t0, &times).unwrap();
            let cf = msd_hcs_species(&s, &r, &t0, &times);
            let mut worst: f64 = 0.0;
            for j in 1..times.len() {
                for k in 0..s.len() {
                    worst = worst.max((num[j][k] / cf[j][k] - 1.0).abs());
                }
            }
            eprintln!("masses {masses:?}: (4) numeric vs (22): worst relative deviation {worst:.2e}; total MSD at 1e9 = {:.6e}", msd_total(&s, &num[times.len() - 1]));
            assert!(worst < 1e-6, "{worst}");
            assert_eq!(num[0], vec![0.0; s.len()]);
        }
    }

    /// The stable (22) equals the literal (22) where the latter is well conditioned (1e-12),
    /// and tends to (23) at long times.
    #[test]
    fn closed_form_variants() {
        let (d, tv, tau0) = (2.0, 3.0, 19.0);
        for t in [1.0, 10.0, 1e3, 1e6] {
            let a = msd_hcs(d, tv, tau0, t);
            let b = msd_hcs_literal(d, tv, tau0, t);
            assert!((a / b - 1.0).abs() < 1e-12, "{a} {b}");
        }
        let t = 1e12;
        assert!(
            (msd_hcs(d, tv, tau0, t) - msd_hcs_long(d, tau0, t) + 6.0 * d * tv).abs()
                < 1e-9 * msd_hcs(d, tv, tau0, t)
        );
    }

    /// The tracer-limit gas MSD (31) equals (22) for k = 1 (one species: D_1(0), tau_v,1(0),
    /// tau_0 from the general formulas), to 1e-12.
    #[test]
    fn tracer_31_equals_22() {
        for eps in [0.1, 0.5, 0.9] {
            let s = [Species {
                mass: 1.0,
                diameter: 1.0,
                density: 0.1,
            }];
            let r = PairRestitution::Constant(eps);
            let t0 = [1.0];
            let d1 = diffusion_coefficients(&s, &t0, &r)[0];
            let tc = tau_c(&s[0], 1.0);
            for t in [0.01, 1.0, 30.0, 1e4, 1e9] {
                let a = msd_hcs_species(&s, &r, &t0, &[t])[0][0];
                let b = msd_gas_tracer(d1, tc, eps, t);
                assert!((a / b - 1.0).abs() < 1e-12, "eps {eps} t {t}: {a} vs {b}");
            }
        }
    }

    /// Elastic mixture (eps = 1, no cooling) from equipartition: (4) numerically equals (22)
    /// with tau_0 = infinity, 6 D t - 6 D tau_v (1 - e^-t/tau_v) (1e-6).
    #[test]
    fn elastic_numeric() {
        let s = same_material(&[1.0, 100.0], &[0.1, 0.1]);
        let r = PairRestitution::Constant(1.0);
        let t0 = [1.0, 1.0];
        let times = [0.01, 1.0, 100.0, 1e4, 1e6];
        let num = msd_numeric(&s, &r, &t0, &times).unwrap();
        let cf = msd_hcs_species(&s, &r, &t0, &times);
        for j in 0..times.len() {
            for k in 0..2 {
                assert!(
                    (num[j][k] / cf[j][k] - 1.0).abs() < 1e-6,
                    "{} {}",
                    num[j][k],
                    cf[j][k]
                );
            }
        }
    }

    /// Fig 1 set-up (m = 1, 100, sigma = 1, n = 0.1 each, eps = 0.5) from equipartition (not
    /// an HCS): msd_numeric equals a brute-force evaluation of (4)-(6) (RK4 in t with step
    /// 2e-3 for T_k and tau_k, composite Simpson over t1 on the same grid) to 1e-7 relative.
    #[test]
    fn numeric_4_against_brute_force() {
        use crate::theory::temperature::cooling_rates_with;
        let s = vec![
            Species {
                mass: 1.0,
                diameter: 1.0,
                density: 0.1,
            },
            Species {
                mass: 100.0,
                diameter: 1.0,
                density: 0.1,
            },
        ];
        let r = PairRestitution::Constant(0.5);
        let t0 = [1.0, 1.0];
        let dt = 2e-3;
        let n_steps = 100_000; // t = 200
                               // State: ln T_1, ln T_2, tau_1, tau_2.
        let f = |y: &[f64; 4]| -> [f64; 4] {
            let t = [y[0].exp(), y[1].exp()];
            let xi = cooling_rates_with(&s, &t, &r);
            [-xi[0], -xi[1], (t[0] / t0[0]).sqrt(), (t[1] / t0[1]).sqrt()]
        };
        let mut y = [0.0, 0.0, 0.0, 0.0];
        let mut grid = vec![y];
        for _ in 0..n_steps {
            let k1 = f(&y);
            let a = |k: &[f64; 4], c: f64| -> [f64; 4] {
                [
                    y[0] + c * k[0],
                    y[1] + c * k[1],
                    y[2] + c * k[2],
                    y[3] + c * k[3],
                ]
            };
            let k2 = f(&a(&k1, 0.5 * dt));
            let k3 = f(&a(&k2, 0.5 * dt));
            let k4 = f(&a(&k3, dt));
            for i in 0..4 {
                y[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
            grid.push(y);
        }
        let dt_at: Vec<(Vec<f64>, Vec<f64>)> = grid
            .iter()
            .map(|g| {
                let t = [g[0].exp(), g[1].exp()];
                let tv = tau_v(&s, &t, &r);
                (
                    (0..2).map(|k| t[k] * tv[k] / s[k].mass).collect(),
                    (0..2).map(|k| tv[k] * (t[k] / t0[k]).sqrt()).collect(),
                )
            })
            .collect();
        let outs = [1000usize, 10_000, 50_000, 100_000];
        let times: Vec<f64> = outs.iter().map(|&j| j as f64 * dt).collect();
        let num = msd_numeric(&s, &r, &t0, &times).unwrap();
        let mut worst: f64 = 0.0;
        for (o, &j) in outs.iter().enumerate() {
            for k in 0..2 {
                let integrand = |i: usize| {
                    6.0 * dt_at[i].0[k]
                        * -(-(grid[j][2 + k] - grid[i][2 + k]) / dt_at[i].1[k]).exp_m1()
                };
                let mut sum = integrand(0) + integrand(j);
                for i in 1..j {
                    sum += if i % 2 == 1 { 4.0 } else { 2.0 } * integrand(i);
                }
                let brute = sum * dt / 3.0;
                worst = worst.max((num[o][k] / brute - 1.0).abs());
            }
        }
        eprintln!("Fig 1 binary from equipartition: (4) numeric vs brute force, worst relative deviation {worst:.2e}");
        assert!(worst < 1e-7, "{worst}");
    }

    /// Velocity-dependent (viscoelastic, Fig 7 binary: m = 1, 100, n = 0.1, sigma = m^(1/3),
    /// A kappa^(2/5) = 0.09, F(beta) = 1 - 1.15344 beta + 0.79826 beta^2) from equipartition:
    /// ballistic <R^2> ~ t^2 at short times and <R^2> ~ const + t^(1/6) at long times (paper,
    /// Fig 7): local exponent at t = 1e-4 within 1e-3 of 2; the growth exponent
    /// log10[(R^2(1e14) - R^2(1e13)) / (R^2(1e13) - R^2(1e12))] within 0.007 of 1/6. (The
    /// approach is slow, as the number of collisions grows only like t^(1/6): the same exponent
    /// is 0.150 / 0.135 (species 1 / 2) at 1e7..1e9 and 0.163 / 0.160 at 1e11..1e13.)
    #[test]
    #[allow(clippy::needless_range_loop)]
    fn viscoelastic_msd_exponents() {
        let s = same_material(&[1.0, 100.0], &[0.1, 0.1]);
        let r = PairRestitution::viscoelastic(&s, 0.09, |b| 1.0 - 1.15344 * b + 0.79826 * b * b);
        let times = [1e-4, 2e-4, 1e12, 1e13, 1e14];
        let start = std::time::Instant::now();
        let m = msd_numeric(&s, &r, &[1.0, 1.0], &times).unwrap();
        let el = start.elapsed().as_secs_f64();
        for k in 0..2 {
            let short = (m[1][k] / m[0][k]).ln() / 2f64.ln();
            let long = ((m[4][k] - m[3][k]) / (m[3][k] - m[2][k])).log10();
            eprintln!("viscoelastic species {k}: short-time exponent {short:.5}, long-time exponent {long:.4} ({el:.2} s)");
            assert!((short - 2.0).abs() < 1e-3);
            assert!((long - 1.0 / 6.0).abs() < 0.007, "{long}");
        }
    }
}
