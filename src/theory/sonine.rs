//! Beyond the Maxwellian: the first Sonine approximation for constant restitution (hard
//! spheres, 3D, dilute, g2 = 1).
//!
//! Each species has f_k(v) = f_M,k(v) [1 + a2_k S2(c_k^2)], c_k^2 = m_k v^2 / (2 T_k),
//! S2(x) = x^2/2 - 5x/2 + 15/8, so a2_k = <c_k^4> / (15/4) - 1 (the kurtosis excess).
//!
//! # One species (van Noije & Ernst 1998; Brilliantov & Poeschel, Kinetic Theory of
//! Granular Gases, ch. 7)
//! - a2 = 16 (1 - e)(1 - 2e^2) / (81 - 17e + 30 e^2 (1 - e)) ([`a2_one_species`]),
//! - zeta = zeta_M (1 + 3 a2 / 16), zeta_M = (4/3) sqrt(pi) n sigma^2 sqrt(T/m) (1 - e^2),
//! - Haff's law T(t) = T0 / (1 + t/tau)^2 with tau = 2 / zeta(T0).
//!
//! # Mixtures (the route of Garzo & Dufty, PRE 60, 5706 (1999), evaluated numerically)
//! With J_ki[psi] = n_i sigma_ki^2 int dv1 dv2 f_k(v1) f_i(v2) / (n_k n_i)
//! int_{g.s > 0} ds (g.s) [psi(v1') - psi(v1)], v1' = v1 - m_i/(m_k + m_i) (1 + e_ki)(g.s) s,
//! g = v1 - v2 (the change of <psi> per particle of species k by collisions with species i),
//! and theta_k = T_k / m_k:
//! - cooling rate (dT_k/dt = -zeta_k T_k): zeta_k = -(1 / (3 theta_k)) sum_i J_ki[v^2];
//! - fourth moment, <v^4>_k = 15 theta_k^2 (1 + a2_k), stationary a2_k (the HCS):
//!   sum_i J_ki[v^4] = 10 theta_k (1 + a2_k) sum_i J_ki[v^2].
//!
//! Both J are linearised in the a2 (the products a2_k a2_i dropped), and the fourth-moment
//! equation too (a2_k J_ki[v^2] kept only at a2 = 0), as Garzo & Dufty do: at given
//! temperatures the a2_k solve a linear M x M system ([`a2_at`]); the cooling rates are then
//! linear in them. For one species this reproduces the van Noije-Ernst a2 and
//! zeta_M (1 + 3 a2/16) exactly (tests).
//!
//! The collision moments are computed by exact quadrature, deterministic: v1 = beta g + W,
//! beta = theta_1/(theta_1 + theta_2), splits the two Maxwellians into independent Gaussians
//! g (variance theta_1 + theta_2) and W (variance theta_1 theta_2/(theta_1 + theta_2)); the
//! integrand is a polynomial in W (degree <= 8: 5-point Gauss-Hermite per axis), in the
//! components of s on the half sphere (Gauss-Legendre in cos, uniform in the azimuth) and,
//! after the change u = g^2 / (2 (theta_1 + theta_2)), in u (Gauss-Laguerre), so every rule is
//! exact up to round-off.
//!
//! # Temperature histories
//! [`hcs_temperatures_sonine`] solves zeta_1 = zeta_2 = ... (mean temperature given);
//! [`evolve_temperatures_sonine`] integrates dT_k/dt = -zeta_k T_k with the a2_k slaved to the
//! instantaneous temperatures (the stationary solution of the fourth-moment equations at each
//! instant, exact in the HCS; the relaxation of a2 itself, a few collision times, is not
//! modelled). Constant restitution only (per pair allowed).
//!
//! # Velocity correlation time and MSD
//! The paper's (11) is tau_v,ki^-1 = nu^v_ki - xi_ki/2 (see [`super::restitution`]): nu^v_ki
//! = <-v_k . dv_k>/<v_k^2> is the rate at which collisions with species i decorrelate a
//! tagged k particle's velocity, averaged over the velocity distributions, and xi_ki/2 the
//! part of it that only follows the cooling. Its a2 correction is taken by the same route
//! (route (a), the velocity-autocorrelation one of the paper and of Brilliantov & Poeschel,
//! PRE 61, 1716 (2000)): both terms averaged over f_M,k (1 + a2_k S2) f_M,i (1 + a2_i S2),
//! linear in the a2, by the exact quadrature ([`tau_v_inv_pairs_sonine`], R_ki in
//! `pair_moments`). Pointwise R + J[v^2]/2 = mu_i^2 (1 + e)^2 (g.s)^2/2, so tau_v,ki^-1 sees the
//! distributions only through <|g|^3>, whence the closed form (tested)
//! tau_v,ki^-1 = (11) [1 + (3/8) (a2_k theta_k^2 + a2_i theta_i^2)/(theta_k + theta_i)^2]
//! ([`tau_v_sonine_factor`]); one species: (11) (1 + 3 a2/16) = the Maxwellian rate times the
//! same factor as zeta (<v1 . g |g|> = <|g|^3>/2 for identical species).
//!
//! Route (b), not taken: the Chapman-Enskog first Sonine tracer/self-diffusion coefficient
//! (Garzo & Montanero, PRE 69, 021301 (2004); Garzo & Vega Reyes 2009) has
//! D = (T/m) / (nu_D - zeta/2) with the trial function f_M,k v: only the gas's a2 enters
//! nu_D, and for one species nu_D = nu^v_M (1 - a2/32) (the -1/32 of the 3/16 split
//! 7/32 + (-1/32) between tagged and gas, tested), while zeta keeps (1 + 3 a2/16). The
//! paper's tau_v is the velocity decorrelation time of (4)-(6), so route (a) is the one that
//! is consistent with it. The two differ by O(a2): for one species with e = 0.5
//! (a2 = 0.0525) tau_v^-1 is (11) times 1.0098 by (a), 0.9945 by (b).
//!
//! [`msd_sonine`]: (4)-(6) with D_k = T_k tau_v,k / m_k along the Sonine temperature history
//! ([`evolve_temperatures_sonine`]) with these tau_v,k (a2 slaved to the temperatures).

use super::msd::{msd_from_history, HistoryPoint};
use super::restitution::PairRestitution;
use super::species::Species;
use super::temperature::{
    check_input, check_times, checked_time_scale, integrate_from_start, time_scale,
};
use super::{ensure, TheoryError};
use crate::math::ode::{Lu, OdeSystem, Tolerances};
use crate::math::quad::gauss_legendre;
use std::f64::consts::PI;
use std::sync::OnceLock;

/// van Noije & Ernst's a2 of one species with constant restitution `e`.
pub fn a2_one_species(e: f64) -> f64 {
    16.0 * (1.0 - e) * (1.0 - 2.0 * e * e) / (81.0 - 17.0 * e + 30.0 * e * e * (1.0 - e))
}

/// Cooling rate of one species in the first Sonine approximation:
/// (4/3) sqrt(pi) n sigma^2 sqrt(T/m) (1 - e^2) (1 + 3 a2/16).
pub fn cooling_rate_one_species(s: &Species, t: f64, e: f64) -> f64 {
    4.0 / 3.0
        * PI.sqrt()
        * s.density
        * s.diameter
        * s.diameter
        * (t / s.mass).sqrt()
        * (1.0 - e * e)
        * (1.0 + 3.0 * a2_one_species(e) / 16.0)
}

struct Rules {
    /// Gauss-Hermite for a standard normal variable: (nodes, weights summing to 1).
    herm: Vec<(f64, f64)>,
    /// Gauss-Laguerre (weight e^-u on [0, inf)).
    lag: Vec<(f64, f64)>,
    /// Half sphere: (sin alpha cos phi, sin alpha sin phi, cos alpha, weight).
    sphere: Vec<[f64; 4]>,
}

fn rules() -> &'static Rules {
    static R: OnceLock<Rules> = OnceLock::new();
    R.get_or_init(|| {
        // Probabilists' Hermite He_5 = x^5 - 10x^3 + 15x: roots 0, +-sqrt(5 +- sqrt(10)),
        // weights 5! / (25 He_4(x)^2), He_4 = x^4 - 6x^2 + 3.
        let mut herm = Vec::new();
        let r = 10f64.sqrt();
        for x in [
            -(5.0 + r).sqrt(),
            -(5.0 - r).sqrt(),
            0.0,
            (5.0 - r).sqrt(),
            (5.0 + r).sqrt(),
        ] {
            let he4 = x.powi(4) - 6.0 * x * x + 3.0;
            herm.push((x, 120.0 / (25.0 * he4 * he4)));
        }
        let lag = gauss_laguerre(5);
        let (x, w) = gauss_legendre(6);
        let nphi = 8;
        let mut sphere = Vec::new();
        for (xc, wc) in x.iter().zip(&w) {
            let c = 0.5 * (xc + 1.0);
            let sa = (1.0 - c * c).sqrt();
            for j in 0..nphi {
                let phi = 2.0 * PI * (j as f64 + 0.5) / nphi as f64;
                sphere.push([
                    sa * phi.cos(),
                    sa * phi.sin(),
                    c,
                    0.5 * wc * 2.0 * PI / nphi as f64,
                ]);
            }
        }
        Rules { herm, lag, sphere }
    })
}

/// `n`-point Gauss-Laguerre rule (weight e^-u): Newton on the three-term recurrence.
fn gauss_laguerre(n: usize) -> Vec<(f64, f64)> {
    let mut out: Vec<(f64, f64)> = Vec::with_capacity(n);
    let nf = n as f64;
    let mut z = 0.0;
    for i in 0..n {
        z = match i {
            0 => 3.0 / (1.0 + 2.4 * nf),
            1 => z + 15.0 / (1.0 + 2.5 * nf),
            _ => {
                let ai = (i - 1) as f64;
                z + (1.0 + 2.55 * ai) / (1.9 * ai) * (z - out[i - 2].0)
            }
        };
        let (mut pp, mut p2) = (0.0, 0.0);
        for _ in 0..200 {
            let (mut p1, mut q) = (1.0, 0.0);
            for j in 1..=n {
                let p3 = q;
                q = p1;
                let jf = j as f64;
                p1 = ((2.0 * jf - 1.0 - z) * q - (jf - 1.0) * p3) / jf;
            }
            p2 = q;
            pp = (nf * p1 - nf * p2) / z;
            let dz = p1 / pp;
            z -= dz;
            if dz.abs() <= 1e-15 * z {
                break;
            }
        }
        out.push((z, -1.0 / (pp * nf * p2)));
    }
    out
}

/// Collision moments of species k (mass `mk`, theta1 = T_k/m_k) with species i (mass `mi`,
/// theta2), per unit n_i sigma_ki^2: `[psi][c]` with psi = v^2, v^4 (J_ki[psi]) and the
/// velocity-relaxation moment R_ki = <-v1 . dv1> (index 2), and c the coefficient of 1, a2_k,
/// a2_i (J = c0 + a2_k c1 + a2_i c2).
fn pair_moments(mk: f64, th1: f64, mi: f64, th2: f64, e: f64) -> [[f64; 3]; 3] {
    let rl = rules();
    let s2 = th1 + th2;
    let beta = th1 / s2;
    let sw = (th1 * th2 / s2).sqrt();
    let mu = mi / (mk + mi) * (1.0 + e);
    let mut acc = [[0.0; 3]; 3];
    for &(u, wu) in &rl.lag {
        let g = (2.0 * s2 * u).sqrt();
        // (2/sqrt(pi)) w sqrt(u) F(g): the density of g folded in.
        let wg = 2.0 / PI.sqrt() * wu * u.sqrt();
        for &(x, wx) in &rl.herm {
            for &(y, wy) in &rl.herm {
                for &(zz, wz) in &rl.herm {
                    let w = [sw * x, sw * y, sw * zz];
                    let v1 = [w[0], w[1], w[2] + beta * g];
                    let v2 = [w[0], w[1], w[2] + (beta - 1.0) * g];
                    let v1sq = v1[0] * v1[0] + v1[1] * v1[1] + v1[2] * v1[2];
                    let v2sq = v2[0] * v2[0] + v2[1] * v2[1] + v2[2] * v2[2];
                    let c1 = v1sq / (2.0 * th1);
                    let c2 = v2sq / (2.0 * th2);
                    let sk = 0.5 * c1 * c1 - 2.5 * c1 + 1.875;
                    let si = 0.5 * c2 * c2 - 2.5 * c2 + 1.875;
                    let wv = wg * wx * wy * wz;
                    let (mut d2, mut d4, mut d1) = (0.0, 0.0, 0.0);
                    for sp in &rl.sphere {
                        let gs = g * sp[2];
                        let v1s = v1[0] * sp[0] + v1[1] * sp[1] + v1[2] * sp[2];
                        let k = mu * gs;
                        // v1' = v1 - k s: |v1'|^2 = v1^2 - 2k (v1.s) + k^2.
                        let vp = v1sq - 2.0 * k * v1s + k * k;
                        let ws = sp[3] * gs;
                        d2 += ws * (vp - v1sq);
                        d4 += ws * (vp * vp - v1sq * v1sq);
                        // -v1 . dv1 = k (v1.s).
                        d1 += ws * k * v1s;
                    }
                    for (p, d) in [(0, d2), (1, d4), (2, d1)] {
                        acc[p][0] += wv * d;
                        acc[p][1] += wv * d * sk;
                        acc[p][2] += wv * d * si;
                    }
                }
            }
        }
    }
    acc
}

/// Per pair (k, i): n_i sigma_ki^2 times [`pair_moments`].
fn moments(species: &[Species], t: &[f64], eps: &[Vec<f64>]) -> Vec<Vec<[[f64; 3]; 3]>> {
    let m = species.len();
    (0..m)
        .map(|k| {
            (0..m)
                .map(|i| {
                    let (sk, si) = (&species[k], &species[i]);
                    let sig = 0.5 * (sk.diameter + si.diameter);
                    let f = si.density * sig * sig;
                    if f == 0.0 {
                        return [[0.0; 3]; 3];
                    }
                    let mut j =
                        pair_moments(sk.mass, t[k] / sk.mass, si.mass, t[i] / si.mass, eps[k][i]);
                    for row in j.iter_mut() {
                        for v in row.iter_mut() {
                            *v *= f;
                        }
                    }
                    j
                })
                .collect()
        })
        .collect()
}

/// The constant restitution of every pair, or None (velocity-dependent restitution).
pub fn constant_pairs(m: usize, r: &PairRestitution) -> Option<Vec<Vec<f64>>> {
    (0..m)
        .map(|k| (0..m).map(|i| r.constant(k, i)).collect())
        .collect()
}

/// The a2_k (stationary fourth-moment equations, linearised) and the cooling rates zeta_k at
/// temperatures `t`: `(a2, zeta)`.
pub fn a2_at(species: &[Species], t: &[f64], eps: &[Vec<f64>]) -> (Vec<f64>, Vec<f64>) {
    let j = moments(species, t, eps);
    let a2 = a2_from(species, t, &j);
    let zeta = zeta_from(species, t, &j, &a2);
    (a2, zeta)
}

/// The linearised stationary fourth-moment equations solved for the a2_k (NaN where the
/// system is singular or not finite).
fn a2_from(species: &[Species], t: &[f64], j: &[Vec<[[f64; 3]; 3]>]) -> Vec<f64> {
    let m = species.len();
    let mut a = vec![0.0; m * m];
    let mut b = vec![0.0; m];
    for k in 0..m {
        let th = t[k] / species[k].mass;
        let j20: f64 = (0..m).map(|i| j[k][i][0][0]).sum();
        let j40: f64 = (0..m).map(|i| j[k][i][1][0]).sum();
        b[k] = -(j40 - 10.0 * th * j20);
        a[k * m + k] -= 10.0 * th * j20;
        for i in 0..m {
            let p = &j[k][i];
            a[k * m + k] += p[1][1] - 10.0 * th * p[0][1];
            a[k * m + i] += p[1][2] - 10.0 * th * p[0][2];
        }
        if a[k * m + k] == 0.0 {
            // No collisions at all (zero densities): Maxwellian.
            a[k * m + k] = 1.0;
            b[k] = 0.0;
        }
    }
    match Lu::new(m, a) {
        Some(lu) => lu.solve(&mut b),
        // No finite solution: NaN, which the callers' checks and the ODE's step control
        // turn into an error.
        None => b.iter_mut().for_each(|v| *v = f64::NAN),
    }
    b
}

/// zeta_k = -(1/(3 theta_k)) sum_i J_ki[v^2] at the given a2.
fn zeta_from(species: &[Species], t: &[f64], j: &[Vec<[[f64; 3]; 3]>], a2: &[f64]) -> Vec<f64> {
    let m = species.len();
    (0..m)
        .map(|k| {
            let th = t[k] / species[k].mass;
            let j2: f64 = (0..m)
                .map(|i| {
                    let p = &j[k][i][0];
                    p[0] + a2[k] * p[1] + a2[i] * p[2]
                })
                .sum();
            -j2 / (3.0 * th)
        })
        .collect()
}

/// tau_v,ki^-1 = nu^v_ki - xi_ki/2 = (R_ki + J_ki[v^2]/2) / (3 theta_k) at the given a2.
fn tau_v_inv_from(
    species: &[Species],
    t: &[f64],
    j: &[Vec<[[f64; 3]; 3]>],
    a2: &[f64],
) -> Vec<Vec<f64>> {
    let m = species.len();
    (0..m)
        .map(|k| {
            let th = t[k] / species[k].mass;
            (0..m)
                .map(|i| {
                    let (r, j2) = (&j[k][i][2], &j[k][i][0]);
                    let lin = |p: &[f64; 3]| p[0] + a2[k] * p[1] + a2[i] * p[2];
                    (lin(r) + 0.5 * lin(j2)) / (3.0 * th)
                })
                .collect()
        })
        .collect()
}

/// The a2-corrected tau_v,ki^-1 (route (a) of the module docs: the paper's (11),
/// nu^v_ki - xi_ki/2, averaged over f_M,k (1 + a2_k S2) f_M,i (1 + a2_i S2), linear in the
/// a2) at temperatures `t` and the given `a2`: `result[k][i]`, by the exact quadrature.
pub fn tau_v_inv_pairs_sonine(
    species: &[Species],
    t: &[f64],
    eps: &[Vec<f64>],
    a2: &[f64],
) -> Vec<Vec<f64>> {
    tau_v_inv_from(species, t, &moments(species, t, eps), a2)
}

/// The closed form of [`tau_v_inv_pairs_sonine`] relative to the Maxwellian (11):
/// tau_v,ki^-1 depends on the pair distribution only through <|g|^3>, and
/// E[S2(c_k^2) | g] = (theta_k/(theta_k + theta_i))^2 S2(g^2/(2 (theta_k + theta_i))), so
/// tau_v,ki^-1 = tau_v,ki^-1(Maxwell) [1 + (3/8) (a2_k theta_k^2 + a2_i theta_i^2) /
/// (theta_k + theta_i)^2]; one species: 1 + 3 a2/16.
pub fn tau_v_sonine_factor(th_k: f64, th_i: f64, a2_k: f64, a2_i: f64) -> f64 {
    let s = th_k + th_i;
    1.0 + 0.375 * (a2_k * th_k * th_k + a2_i * th_i * th_i) / (s * s)
}

/// tau_v,k in the first Sonine approximation at temperatures `t`, with the a2_k slaved to
/// them (as [`a2_at`]): `(a2, tau_v)`.
pub fn tau_v_sonine(species: &[Species], t: &[f64], eps: &[Vec<f64>]) -> (Vec<f64>, Vec<f64>) {
    let j = moments(species, t, eps);
    let a2 = a2_from(species, t, &j);
    let tv = tau_v_inv_from(species, t, &j, &a2)
        .iter()
        .map(|row| 1.0 / row.iter().sum::<f64>())
        .collect();
    (a2, tv)
}

/// The Sonine HCS: temperatures with equal cooling rates zeta_k (a2-corrected) and
/// number-weighted mean `mean`, and the a2_k there: `(T, a2)`. Newton on ln(T_k/T_1) from the
/// Maxwellian HCS. None for velocity-dependent restitution.
///
/// # Errors
/// Those of [`super::hcs::hcs_temperatures`], and if Newton does not converge.
pub fn hcs_temperatures_sonine(
    species: &[Species],
    r: &PairRestitution,
    mean: f64,
) -> Result<Option<(Vec<f64>, Vec<f64>)>, TheoryError> {
    let m = species.len();
    let Some(eps) = constant_pairs(m, r) else {
        return Ok(None);
    };
    let n: f64 = species.iter().map(|s| s.density).sum();
    let norm = |t: &mut Vec<f64>| {
        let e: f64 = species
            .iter()
            .zip(t.iter())
            .map(|(s, t)| s.density * t)
            .sum();
        let f = mean * n / e;
        t.iter_mut().for_each(|v| *v *= f);
    };
    let mut t = super::hcs::hcs_temperatures(species, r, mean)?;
    let resid = |t: &[f64]| -> Vec<f64> {
        let (_, z) = a2_at(species, t, &eps);
        let ts = time_scale(species, t);
        (1..m).map(|k| ts * (z[k] - z[0])).collect()
    };
    let mut converged = m == 1;
    for _ in 0..50 {
        if converged {
            break;
        }
        let f = resid(&t);
        if f.iter().all(|v| v.abs() < 1e-13) {
            converged = true;
            break;
        }
        let d = 1e-7;
        let mut jac = vec![0.0; (m - 1) * (m - 1)];
        for j in 1..m {
            let mut tp = t.clone();
            tp[j] *= f64::exp(d);
            let fp = resid(&tp);
            for k in 0..m - 1 {
                jac[k * (m - 1) + j - 1] = (fp[k] - f[k]) / d;
            }
        }
        let mut step: Vec<f64> = f.iter().map(|v| -v).collect();
        Lu::new(m - 1, jac)
            .ok_or_else(|| TheoryError::new("the Sonine HCS Jacobian is singular (or not finite)"))?
            .solve(&mut step);
        let big = step.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let sc = if big > 0.5 { 0.5 / big } else { 1.0 };
        for j in 1..m {
            t[j] *= (sc * step[j - 1]).exp();
        }
        norm(&mut t);
        if big < 1e-12 {
            converged = true;
        }
    }
    ensure(converged, || {
        "the Sonine HCS iteration did not converge".into()
    })?;
    norm(&mut t);
    let (a2, _) = a2_at(species, &t, &eps);
    ensure(t.iter().chain(&a2).all(|v| v.is_finite()), || {
        "the Sonine HCS is not finite".into()
    })?;
    Ok(Some((t, a2)))
}

struct SonineOde<'a> {
    species: &'a [Species],
    eps: Vec<Vec<f64>>,
    t_s: f64,
    /// a2 = 0 throughout (the Maxwellian theory through the same machinery; for tests).
    maxwell: bool,
    /// ln T_k(0), when the reduced times (6) ride along as quadrature components.
    y0: Option<Vec<f64>>,
}

impl SonineOde<'_> {
    /// (a2, zeta) at temperatures `t`.
    fn rates(&self, t: &[f64]) -> (Vec<f64>, Vec<f64>) {
        if self.maxwell {
            let j = moments(self.species, t, &self.eps);
            let a2 = vec![0.0; t.len()];
            let z = zeta_from(self.species, t, &j, &a2);
            (a2, z)
        } else {
            a2_at(self.species, t, &self.eps)
        }
    }
}

impl OdeSystem for SonineOde<'_> {
    fn dim(&self) -> usize {
        self.species.len()
    }
    fn quad_dim(&self) -> usize {
        self.y0.as_ref().map_or(0, |y| y.len())
    }
    fn rhs(&self, s: f64, y: &[f64], dy: &mut [f64]) {
        let t: Vec<f64> = y.iter().map(|v| v.exp()).collect();
        let (_, z) = self.rates(&t);
        let dtds = self.t_s * s.exp();
        for k in 0..y.len() {
            dy[k] = -z[k] * dtds;
        }
    }
    fn quad(&self, s: f64, y: &[f64], dq: &mut [f64]) {
        let y0 = self.y0.as_ref().expect("quadrature components");
        let dtds = self.t_s * s.exp();
        for k in 0..y.len() {
            dq[k] = (0.5 * (y[k] - y0[k])).exp() * dtds;
        }
    }
}

/// T_k at the sorted `times` from `t0` at t = 0, with the a2-corrected cooling rates (a2
/// slaved to the instantaneous temperatures, see the module docs): `result[j][k]`, or None for
/// velocity-dependent restitution. Accuracy ~1e-8 relative.
pub fn evolve_temperatures_sonine(
    species: &[Species],
    r: &PairRestitution,
    t0: &[f64],
    times: &[f64],
) -> Result<Option<Vec<Vec<f64>>>, TheoryError> {
    check_input(species, t0)?;
    check_times(times)?;
    let Some(eps) = constant_pairs(species.len(), r) else {
        return Ok(None);
    };
    let t_s = checked_time_scale(species, t0)?;
    let sys = SonineOde {
        species,
        eps,
        t_s,
        maxwell: false,
        y0: None,
    };
    let y0: Vec<f64> = t0.iter().map(|t| t.ln()).collect();
    let s_out: Vec<f64> = times.iter().map(|t| (t / t_s).ln_1p()).collect();
    let tols = Tolerances {
        atol_y: 1e-9,
        rtol_y: 0.0,
        atol_q: 0.0,
        rtol_q: 0.0,
    };
    let res = integrate_from_start(&sys, &y0, &[], &s_out, tols)
        .map_err(|e| TheoryError(format!("the Sonine temperature ODE failed: {e}")))?;
    let out: Vec<Vec<f64>> = res
        .into_iter()
        .map(|(y, _)| y.iter().map(|v| v.exp()).collect())
        .collect();
    ensure(
        out.iter().flatten().all(|v| v.is_finite() && *v > 0.0),
        || "the Sonine temperatures leave the range of a double".into(),
    )?;
    Ok(Some(out))
}

/// The largest step of the history grid in s = ln(1 + t/t_s) (see [`msd_sonine`]).
const HISTORY_STEP: f64 = 0.05;

/// The Sonine temperature history on a grid in s = ln(1 + t/t_s), interpolated in between:
/// ln T_k and the reduced times by cubic Hermite with their exact derivatives (from the
/// cooling rates at the grid points), the ratio tau_v,k(Sonine)/tau_v,k(Maxwell, same T) by
/// cubic Hermite with three-point slopes. The grid is uniform (step [`HISTORY_STEP`]) and
/// halved geometrically towards s = 0 down to a quarter of the first output's s, so the
/// interpolation error is relative at short times too.
struct SonineHistory<'a> {
    species: &'a [Species],
    r: &'a PairRestitution,
    t_s: f64,
    s: Vec<f64>,
    /// Per grid point: ln T_k, d ln T_k/ds, reduced times, their derivatives, tau_v ratios.
    y: Vec<Vec<f64>>,
    dy: Vec<Vec<f64>>,
    q: Vec<Vec<f64>>,
    dq: Vec<Vec<f64>>,
    c: Vec<Vec<f64>>,
    dc: Vec<Vec<f64>>,
}

fn hermite(h: f64, x: f64, y0: f64, d0: f64, y1: f64, d1: f64) -> f64 {
    let x2 = x * x;
    let x3 = x2 * x;
    (2.0 * x3 - 3.0 * x2 + 1.0) * y0
        + (x3 - 2.0 * x2 + x) * h * d0
        + (-2.0 * x3 + 3.0 * x2) * y1
        + (x3 - x2) * h * d1
}

impl<'a> SonineHistory<'a> {
    fn new(
        species: &'a [Species],
        r: &'a PairRestitution,
        eps: Vec<Vec<f64>>,
        t0: &[f64],
        times: &[f64],
        maxwell: bool,
    ) -> Result<Self, TheoryError> {
        check_input(species, t0)?;
        check_times(times)?;
        let m = species.len();
        let t_s = checked_time_scale(species, t0)?;
        let t_max = times.iter().cloned().fold(0.0, f64::max);
        let t_min = times
            .iter()
            .cloned()
            .filter(|&t| t > 0.0)
            .fold(f64::INFINITY, f64::min);
        let s_max = (t_max / t_s).ln_1p().max(HISTORY_STEP);
        let n = (s_max / HISTORY_STEP).ceil() as usize;
        let h = s_max / n as f64;
        let s_min = if t_min.is_finite() {
            0.25 * (t_min / t_s).ln_1p()
        } else {
            h
        };
        let mut grid: Vec<f64> = (0..=n).map(|j| j as f64 * h).collect();
        grid[n] = s_max;
        let mut d = 0.5 * h;
        for _ in 0..60 {
            if d < s_min {
                break;
            }
            grid.push(d);
            d *= 0.5;
        }
        grid.sort_by(f64::total_cmp);
        let y0: Vec<f64> = t0.iter().map(|t| t.ln()).collect();
        let sys = SonineOde {
            species,
            eps,
            t_s,
            maxwell,
            y0: Some(y0.clone()),
        };
        let tols = Tolerances {
            atol_y: 1e-10,
            rtol_y: 0.0,
            atol_q: 1e-10 * t_s,
            rtol_q: 1e-10,
        };
        let res = integrate_from_start(&sys, &y0, &vec![0.0; m], &grid, tols)
            .map_err(|e| TheoryError(format!("the Sonine temperature ODE failed: {e}")))?;
        let mut out = SonineHistory {
            species,
            r,
            t_s,
            s: grid.clone(),
            y: Vec::new(),
            dy: Vec::new(),
            q: Vec::new(),
            dq: Vec::new(),
            c: Vec::new(),
            dc: Vec::new(),
        };
        for (&s, (y, q)) in grid.iter().zip(res) {
            let t: Vec<f64> = y.iter().map(|v| v.exp()).collect();
            let dtds = t_s * s.exp();
            let j = moments(species, &t, &sys.eps);
            let a2 = if maxwell {
                vec![0.0; m]
            } else {
                a2_from(species, &t, &j)
            };
            let z = zeta_from(species, &t, &j, &a2);
            let tv_inv = tau_v_inv_from(species, &t, &j, &a2);
            let tv_m = super::diffusion::tau_v(species, &t, r);
            out.dy.push(z.iter().map(|z| -z * dtds).collect());
            out.dq.push(
                (0..m)
                    .map(|k| (0.5 * (y[k] - y0[k])).exp() * dtds)
                    .collect(),
            );
            out.c.push(
                (0..m)
                    .map(|k| 1.0 / tv_inv[k].iter().sum::<f64>() / tv_m[k])
                    .collect(),
            );
            out.y.push(y);
            out.q.push(q);
        }
        // Three-point slopes of the tau_v ratios (one-sided at the ends).
        let g = out.s.len();
        for j in 0..g {
            let (a, b) = (j.saturating_sub(1), (j + 1).min(g - 1));
            let slope: Vec<f64> = (0..m)
                .map(|k| {
                    if a == j || b == j {
                        (out.c[b][k] - out.c[a][k]) / (out.s[b] - out.s[a])
                    } else {
                        let (h0, h1) = (out.s[j] - out.s[a], out.s[b] - out.s[j]);
                        let (d0, d1) = (
                            (out.c[j][k] - out.c[a][k]) / h0,
                            (out.c[b][k] - out.c[j][k]) / h1,
                        );
                        (h1 * d0 + h0 * d1) / (h0 + h1)
                    }
                })
                .collect();
            out.dc.push(slope);
        }
        Ok(out)
    }

    fn at(&self, t: f64) -> HistoryPoint {
        let m = self.species.len();
        let s = (t / self.t_s).ln_1p();
        let g = self.s.len();
        let j = match self.s.binary_search_by(|x| x.total_cmp(&s)) {
            Ok(j) => j.min(g - 2),
            Err(j) => j.clamp(1, g - 1) - 1,
        };
        let h = self.s[j + 1] - self.s[j];
        let x = (s - self.s[j]) / h;
        let ip = |v: &[Vec<f64>], d: &[Vec<f64>], k: usize| {
            hermite(h, x, v[j][k], d[j][k], v[j + 1][k], d[j + 1][k])
        };
        let temperatures: Vec<f64> = (0..m).map(|k| ip(&self.y, &self.dy, k).exp()).collect();
        let reduced_times = (0..m).map(|k| ip(&self.q, &self.dq, k)).collect();
        let tv_m = super::diffusion::tau_v(self.species, &temperatures, self.r);
        let tau_v = (0..m).map(|k| ip(&self.c, &self.dc, k) * tv_m[k]).collect();
        HistoryPoint {
            temperatures,
            reduced_times,
            tau_v,
        }
    }
}

/// Partial MSDs (4)-(6) in the first Sonine approximation: along the Sonine temperature
/// history (a2-corrected cooling rates, a2 slaved to the temperatures, as
/// [`evolve_temperatures_sonine`]) with the a2-corrected tau_v,k of [`tau_v_sonine`];
/// `result[j][k]` = `<R_k^2(times[j])>`, or None for velocity-dependent restitution.
///
/// The quadrature is that of [`super::msd::msd_numeric`]; the history at its (many) nodes is
/// interpolated from a grid in s = ln(1 + t/t_s) with step <= 0.05 (see `SonineHistory`:
/// the collision moments are computed only at the grid points), ~1e-7 relative.
pub fn msd_sonine(
    species: &[Species],
    r: &PairRestitution,
    t0: &[f64],
    times: &[f64],
) -> Result<Option<Vec<Vec<f64>>>, TheoryError> {
    let Some(eps) = constant_pairs(species.len(), r) else {
        return Ok(None);
    };
    msd_sonine_with(species, r, eps, t0, times, false).map(Some)
}

fn msd_sonine_with(
    species: &[Species],
    r: &PairRestitution,
    eps: Vec<Vec<f64>>,
    t0: &[f64],
    times: &[f64],
    maxwell: bool,
) -> Result<Vec<Vec<f64>>, TheoryError> {
    if times.iter().all(|&t| t <= 0.0) {
        return Ok(vec![vec![0.0; species.len()]; times.len()]);
    }
    let hist = SonineHistory::new(species, r, eps, t0, times, maxwell)?;
    msd_from_history(species, t0, times, |ts: &[f64], _| {
        Ok(ts.iter().map(|&t| hist.at(t)).collect())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::theory::temperature::{cooling_rates_with, haff};

    fn one(e: f64) -> (Species, PairRestitution) {
        (Species::new(2.0, 1.5, 0.1), PairRestitution::Constant(e))
    }

    /// The quadrature rules are exact: Gaussian moments up to degree 8, Laguerre up to 9.
    #[test]
    fn rules_are_exact() {
        let r = rules();
        for (p, want) in [(0, 1.0), (2, 1.0), (4, 3.0), (6, 15.0), (8, 105.0)] {
            let got: f64 = r.herm.iter().map(|(x, w)| w * x.powi(p)).sum();
            assert!((got - want).abs() < 1e-12 * want, "{p}: {got}");
        }
        let mut fact = 1.0;
        for p in 0..10 {
            if p > 0 {
                fact *= p as f64;
            }
            let got: f64 = r.lag.iter().map(|(x, w)| w * x.powi(p)).sum();
            assert!((got / fact - 1.0).abs() < 1e-12, "{p}: {got}");
        }
        let area: f64 = r.sphere.iter().map(|s| s[3]).sum();
        assert!((area / (2.0 * PI) - 1.0).abs() < 1e-14);
    }

    /// With a2 = 0 the cooling rates are the Maxwellian ones of `cooling_rates_with`.
    #[test]
    fn maxwellian_part_matches() {
        let s = vec![Species::new(1.0, 1.0, 0.1), Species::new(100.0, 1.0, 0.01)];
        let t = [0.7, 30.0];
        let r = PairRestitution::Constant(0.6);
        let eps = constant_pairs(2, &r).unwrap();
        let j = moments(&s, &t, &eps);
        let xi = cooling_rates_with(&s, &t, &r);
        for k in 0..2 {
            let z0 = -(j[k][0][0][0] + j[k][1][0][0]) / (3.0 * t[k] / s[k].mass);
            assert!((z0 / xi[k] - 1.0).abs() < 1e-12, "{k}: {z0} vs {}", xi[k]);
        }
    }

    /// (c) The van Noije-Ernst formula by hand: e = 0.9: 16*0.1*(1-1.62)/(81-15.3+30*0.81*0.1)
    /// = -0.992/68.13; e = 0.5: 16*0.5*0.5/(81-8.5+3.75) = 4/76.25.
    #[test]
    fn a2_one_species_hand_values() {
        assert!((a2_one_species(0.9) - (-0.992 / 68.13)).abs() < 1e-15);
        assert!((a2_one_species(0.5) - 4.0 / 76.25).abs() < 1e-15);
        assert_eq!(a2_one_species(1.0), 0.0);
    }

    /// The numerical moments reproduce the one-species a2 and zeta_M (1 + 3 a2/16) (1e-10).
    #[test]
    fn one_species_numeric_is_van_noije_ernst() {
        for e in [0.1, 0.5, 0.7, 0.9, 0.99] {
            let (s, r) = one(e);
            let eps = constant_pairs(1, &r).unwrap();
            let (a2, z) = a2_at(&[s], &[1.3], &eps);
            let want = cooling_rate_one_species(&s, 1.3, e);
            eprintln!("e = {e}: a2 {:.12} (vNE {:.12})", a2[0], a2_one_species(e));
            assert!((a2[0] - a2_one_species(e)).abs() < 1e-10, "{e}: {a2:?}");
            assert!((z[0] / want - 1.0).abs() < 1e-10, "{e}: {z:?} vs {want}");
        }
    }

    /// (a) A mixture of identical species (split in unequal densities) is one species.
    #[test]
    fn identical_species_reduce_to_one() {
        let e = 0.5;
        let s = vec![Species::new(2.0, 1.5, 0.03), Species::new(2.0, 1.5, 0.07)];
        let r = PairRestitution::Constant(e);
        let (t, a2) = hcs_temperatures_sonine(&s, &r, 1.3).unwrap().unwrap();
        let want = cooling_rate_one_species(&Species::new(2.0, 1.5, 0.1), 1.3, e);
        let (_, z) = a2_at(&s, &t, &constant_pairs(2, &r).unwrap());
        for k in 0..2 {
            assert!((t[k] / 1.3 - 1.0).abs() < 1e-10, "{t:?}");
            assert!((a2[k] - a2_one_species(e)).abs() < 1e-10, "{a2:?}");
            assert!((z[k] / want - 1.0).abs() < 1e-10, "{z:?}");
        }
    }

    /// (b) Elastic, equal masses, equal temperatures: a2 = 0, even with unequal diameters
    /// and densities.
    #[test]
    fn elastic_equal_masses_a2_zero() {
        let s = vec![Species::new(1.0, 1.0, 0.1), Species::new(1.0, 2.0, 0.02)];
        let r = PairRestitution::Constant(1.0);
        let (a2, z) = a2_at(&s, &[1.0, 1.0], &constant_pairs(2, &r).unwrap());
        for k in 0..2 {
            assert!(a2[k].abs() < 1e-12, "{a2:?}");
            assert!(z[k].abs() < 1e-12, "{z:?}");
        }
    }

    /// One species from its own T0: Haff's law with tau = 2/zeta(T0) (1e-7).
    #[test]
    fn one_species_haff() {
        let (s, r) = one(0.5);
        let tau = 2.0 / cooling_rate_one_species(&s, 1.0, 0.5);
        let times = [0.0, 0.1 * tau, tau, 100.0 * tau, 1e6 * tau];
        let got = evolve_temperatures_sonine(&[s], &r, &[1.0], &times)
            .unwrap()
            .unwrap();
        for (t, g) in times.iter().zip(&got) {
            assert!((g[0] / haff(*t, tau) - 1.0).abs() < 1e-7, "{t}: {g:?}");
        }
    }

    /// The Fig 2 mixture: the Sonine HCS is stationary under the evolution, and velocity-
    /// dependent restitution gives None.
    #[test]
    fn mixture_hcs_stationary() {
        let s = vec![
            Species::new(1.0, 1.0, 0.1),
            Species::new(100.0, 100f64.cbrt(), 0.001),
        ];
        let r = PairRestitution::Constant(0.5);
        let (t0, a2) = hcs_temperatures_sonine(&s, &r, 1.0).unwrap().unwrap();
        let tm = super::super::hcs::hcs_temperatures(&s, &r, 1.0).unwrap();
        eprintln!("fig2 Sonine HCS {t0:?} (Maxwell {tm:?}), a2 {a2:?}");
        let times = [0.0, 10.0, 1000.0];
        let got = evolve_temperatures_sonine(&s, &r, &t0, &times)
            .unwrap()
            .unwrap();
        let ratio0 = t0[1] / t0[0];
        for g in &got {
            assert!((g[1] / g[0] / ratio0 - 1.0).abs() < 1e-6, "{g:?}");
        }
        let v = PairRestitution::velocity_dependent(|_, _, g: f64| 0.5 + 0.01 * g);
        assert!(hcs_temperatures_sonine(&s, &v, 1.0).unwrap().is_none());
    }

    /// The quadrature tau_v,ki^-1 with Sonine distributions equals the closed form
    /// Maxwell (11) x [1 + (3/8)(a2_k theta_k^2 + a2_i theta_i^2)/(theta_k + theta_i)^2] (1e-12),
    /// for unequal masses, diameters, temperatures, restitutions and arbitrary a2; with all
    /// a2 = 0 it is the Maxwellian (11) of `diffusion::tau_v_inv_pairs` (1e-12).
    #[test]
    fn tau_v_quadrature_is_closed_form() {
        use crate::theory::diffusion::tau_v_inv_pairs;
        let s = vec![
            Species::new(1.0, 1.0, 0.1),
            Species::new(7.0, 2.0, 0.02),
            Species::new(100.0, 100f64.cbrt(), 0.001),
        ];
        let eps = vec![
            vec![0.5, 0.7, 0.9],
            vec![0.7, 0.3, 0.8],
            vec![0.9, 0.8, 0.6],
        ];
        let r = PairRestitution::ConstantPairs(eps.clone());
        let t = [0.6, 3.0, 45.0];
        let a2 = [0.07, -0.03, 0.2];
        let maxw = tau_v_inv_pairs(&s, &t, &r);
        let got = tau_v_inv_pairs_sonine(&s, &t, &eps, &a2);
        let zero = tau_v_inv_pairs_sonine(&s, &t, &eps, &[0.0; 3]);
        for k in 0..3 {
            for i in 0..3 {
                let (thk, thi) = (t[k] / s[k].mass, t[i] / s[i].mass);
                let want = maxw[k][i] * tau_v_sonine_factor(thk, thi, a2[k], a2[i]);
                assert!((got[k][i] / want - 1.0).abs() < 1e-12, "{k}{i}: {got:?}");
                assert!((zero[k][i] / maxw[k][i] - 1.0).abs() < 1e-12, "{k}{i}");
            }
        }
    }

    /// Elastic, equal temperatures (equal masses: a2 = 0): tau_v_sonine is the Maxwellian
    /// tau_v of `theory::diffusion` (1e-10).
    #[test]
    fn tau_v_elastic_is_maxwellian() {
        use crate::theory::diffusion::tau_v;
        let s = vec![Species::new(1.0, 1.0, 0.1), Species::new(1.0, 2.0, 0.02)];
        let r = PairRestitution::Constant(1.0);
        let (a2, tv) = tau_v_sonine(&s, &[1.0, 1.0], &constant_pairs(2, &r).unwrap());
        let want = tau_v(&s, &[1.0, 1.0], &r);
        for k in 0..2 {
            assert!(a2[k].abs() < 1e-12, "{a2:?}");
            assert!((tv[k] / want[k] - 1.0).abs() < 1e-10, "{tv:?} {want:?}");
        }
    }

    /// One species: tau_v^-1 = tau_v,M^-1 (1 + 3 a2/16) with the van Noije-Ernst a2, and so
    /// is the bare velocity-relaxation rate nu^v alone (<v1 . g |g|> = <|g|^3>/2); 1e-10.
    /// The split of 3/16 between the tagged particle's a2 (7/32) and the gas's (-1/32): the
    /// latter alone is the Chapman-Enskog first Sonine nu_D (route (b) of the module docs).
    #[test]
    fn one_species_tau_v() {
        use crate::theory::diffusion::tau_v;
        for e in [0.1, 0.5, 0.9] {
            let (s, r) = one(e);
            let eps = constant_pairs(1, &r).unwrap();
            let (a2, tv) = tau_v_sonine(&[s], &[1.3], &eps);
            let a = a2_one_species(e);
            assert!((a2[0] - a).abs() < 1e-10);
            let want = tau_v(&[s], &[1.3], &r)[0] / (1.0 + 3.0 * a / 16.0);
            assert!((tv[0] / want - 1.0).abs() < 1e-10, "{e}: {tv:?} vs {want}");
            let p = moments(&[s], &[1.3], &eps)[0][0][2];
            assert!(((p[1] + p[2]) / p[0] - 3.0 / 16.0).abs() < 1e-12, "{p:?}");
            assert!((p[1] / p[0] - 7.0 / 32.0).abs() < 1e-12, "{p:?}");
            assert!((p[2] / p[0] + 1.0 / 32.0).abs() < 1e-12, "{p:?}");
        }
    }

    /// One species: msd_sonine is the closed form (22) with the Sonine D(0), tau_v(0) and
    /// tau_0 = 2/zeta(T0) (1e-6, t from 1e-3 to 1e6 tau_0).
    #[test]
    fn one_species_msd_closed_form() {
        use crate::theory::diffusion::tau_v;
        use crate::theory::msd::msd_hcs;
        for e in [0.3, 0.8] {
            let (s, r) = one(e);
            let t0 = 1.7;
            let a = a2_one_species(e);
            let tv0 = tau_v(&[s], &[t0], &r)[0] / (1.0 + 3.0 * a / 16.0);
            let d0 = t0 * tv0 / s.mass;
            let tau0 = 2.0 / cooling_rate_one_species(&s, t0, e);
            let times: Vec<f64> = [1e-3, 0.1, 1.0, 10.0, 1e3, 1e6]
                .iter()
                .map(|x| x * tau0)
                .collect();
            let got = msd_sonine(&[s], &r, &[t0], &times).unwrap().unwrap();
            for (t, g) in times.iter().zip(&got) {
                let want = msd_hcs(d0, tv0, tau0, *t);
                assert!((g[0] / want - 1.0).abs() < 1e-6, "{e} {t}: {g:?} vs {want}");
            }
        }
    }

    /// A mixture of identical species (unequal densities) is one species: its msd_sonine
    /// equals that of the merged species (1e-7), from a common start.
    #[test]
    fn identical_species_msd_is_one_species() {
        let r = PairRestitution::Constant(0.5);
        let s = vec![Species::new(2.0, 1.5, 0.03), Species::new(2.0, 1.5, 0.07)];
        let times = [0.01, 1.0, 30.0, 1e4];
        let two = msd_sonine(&s, &r, &[1.3, 1.3], &times).unwrap().unwrap();
        let one = msd_sonine(&[Species::new(2.0, 1.5, 0.1)], &r, &[1.3], &times)
            .unwrap()
            .unwrap();
        for (a, b) in two.iter().zip(&one) {
            for k in 0..2 {
                assert!((a[k] / b[0] - 1.0).abs() < 1e-7, "{a:?} {b:?}");
            }
        }
    }

    /// With all a2 = 0 the Sonine machinery (moments, history grid, interpolation) gives
    /// msd_numeric (1e-6): the Fig 1 binary from equipartition (a transient) and the Fig 2
    /// intruders in their HCS. Velocity-dependent restitution gives None.
    #[test]
    fn zero_a2_msd_is_msd_numeric() {
        use crate::theory::hcs::hcs_temperatures;
        use crate::theory::msd::msd_numeric;
        let r = PairRestitution::Constant(0.5);
        let fig1 = vec![Species::new(1.0, 1.0, 0.1), Species::new(100.0, 1.0, 0.1)];
        let fig2 = vec![
            Species::new(1.0, 1.0, 0.1),
            Species::new(100.0, 100f64.cbrt(), 0.001),
        ];
        let t2 = hcs_temperatures(&fig2, &r, 1.0).unwrap();
        let times = [0.01, 0.1, 1.0, 10.0, 100.0, 1e3, 1e4];
        for (s, t0) in [(fig1, vec![1.0, 1.0]), (fig2, t2)] {
            let eps = constant_pairs(2, &r).unwrap();
            let got = msd_sonine_with(&s, &r, eps, &t0, &times, true).unwrap();
            let want = msd_numeric(&s, &r, &t0, &times).unwrap();
            let mut worst: f64 = 0.0;
            for (g, w) in got.iter().zip(&want) {
                for k in 0..2 {
                    worst = worst.max((g[k] / w[k] - 1.0).abs());
                }
            }
            eprintln!("a2 = 0 Sonine MSD vs msd_numeric: worst {worst:.2e}");
            assert!(worst < 1e-6, "{worst}");
        }
        let v = PairRestitution::velocity_dependent(|_, _, g: f64| 0.5 + 0.01 * g);
        assert!(
            msd_sonine(&[Species::new(1.0, 1.0, 0.1)], &v, &[1.0], &[1.0])
                .unwrap()
                .is_none()
        );
    }
}
