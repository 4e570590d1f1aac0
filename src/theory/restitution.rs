//! Restitution as the theory sees it, and the pair collision integrals that depend on it:
//! the cooling rates xi_ki (15), (A7) and the inverse velocity-correlation times
//! tau_v,ki^-1 (11), (A6) of species k due to species i.
//!
//! # Collision integrals
//!
//! Species k and i have Maxwellian velocity distributions at temperatures T_k, T_i (g2 = 1).
//! The relative velocity g = v_k - v_i is then Gaussian with variance u^2 per component,
//!
//! ```text
//! u^2 = T_k/m_k + T_i/m_i = (T_k m_i + T_i m_k) / (m_i m_k),
//! ```
//!
//! and E[v_k | g] = (T_k/m_k)/u^2 g. A collision with unit vector e and g_n = g.e > 0 changes
//! v_k by dv_k = -mu_i (1 + eps(g_n)) g_n e, mu_i = m_i/(m_i + m_k) (spec 2, (41)). The
//! collision integrals are
//!
//! ```text
//! xi_ki = -(2/(3 n_k T_k)) n_k n_i sigma_ki^2 int dv_k dv_i f_k f_i int_{g.e>0} de g_n
//!         [m_k (v_k + dv_k)^2/2 - m_k v_k^2/2]
//! nu^v_ki = (m_k/(3 T_k)) n_i sigma_ki^2 int dv_k dv_i f_k f_i int_{g.e>0} de g_n (-v_k . dv_k)
//! ```
//!
//! (f normalised to 1; nu^v_ki is the rate at which collisions with species i relax a tagged
//! k particle's velocity, <v_k . dv_k>/<v_k^2>). With the Gaussian g and E[v_k | g], the
//! integrals over e (4 pi, one normal direction) and over the tangential components of g
//! leave one integral over the flux-weighted distribution of the normal impact speed,
//!
//! `<G> = 2 int_0^inf z^3 exp(-z^2) G(sqrt(2) u z) dz`  (g_n = sqrt(2) u z, `<1>` = 1),
//!
//! and with P_ki = (8 sqrt(2 pi)/3) n_i sigma_ki^2 u mu_i and
//! Gam_ki = (T_k m_i + T_i m_k) / (T_k (m_i + m_k)) = m_k mu_i u^2 / T_k:
//!
//! ```text
//! xi_ki        = P_ki [ <1 + eps> - (Gam_ki/2) <(1 + eps)^2> ]            (15), (A7)
//! nu^v_ki      = P_ki <1 + eps> / 2
//! tau_v,ki^-1  = nu^v_ki - xi_ki/2 = P_ki (Gam_ki/4) <(1 + eps)^2>         (11), (A6)
//! nu_ki        = 2 sqrt(2 pi) n_i sigma_ki^2 u   (collision frequency of a k particle with i)
//! ```
//!
//! For constant eps these are exactly (15) and (11). With eps = 1 + sum_j h_j x^j,
//! x = (A kappa^(2/5))^(1/2) g_n^(1/10), one has <x^n> = 2 B_n with the paper's B_n, and the
//! two lines become the paper's (A7) and (A6) term by term (see [`xi_pair_series`]).
//!
//! Note: the paper's (11) is not the bare velocity-relaxation rate nu^v_ki but nu^v_ki minus
//! half the cooling rate (the form of the textbook self-diffusion coefficient,
//! D ∝ 1/(1 + eps)^2 for one species); the identity holds for any eps(g_n), which is how (11)
//! is generalised here, consistently with the paper's (A6).
//!
//! For velocity-dependent eps the averages are computed by adaptive Gauss-Legendre quadrature
//! over z in [0, 9.5] (the neglected tail is < 1e-33 of the total), to ~1e-13 relative.

use super::species::Species;
use crate::math::quad::{adaptive, gamma};
use std::f64::consts::PI;
use std::fmt;
use std::sync::Arc;

/// eps_ki(g_n) for species pair (k, i) at normal impact speed g_n = |g . e| >= 0.
pub trait PairEps: Send + Sync {
    fn eps(&self, k: usize, i: usize, g_n: f64) -> f64;
}

impl<F: Fn(usize, usize, f64) -> f64 + Send + Sync> PairEps for F {
    fn eps(&self, k: usize, i: usize, g_n: f64) -> f64 {
        self(k, i, g_n)
    }
}

/// eps(g_n) of one pair.
pub type EpsFn = Box<dyn Fn(f64) -> f64 + Send + Sync>;

/// Restitution coefficients of every species pair, as the theory needs them.
#[derive(Clone)]
pub enum PairRestitution {
    /// One constant eps for every pair.
    Constant(f64),
    /// Constant eps_ki per pair (a symmetric M x M matrix).
    ConstantPairs(Vec<Vec<f64>>),
    /// eps_ki(g_n) depending on the normal impact speed (symmetric in k, i).
    VelocityDependent(Arc<dyn PairEps>),
    /// eps_ki(g_n) = f(a_ki g_n^p), one function f for every pair (the viscoelastic form,
    /// p = 1/5): evaluated like `VelocityDependent`, but the Maxwell averages are tabulated once
    /// (see [`ScaledEps`]), which makes many species and long integrations cheap.
    Scaled(Arc<ScaledEps>),
}

/// Restitution of the form eps_ki(g_n) = f(a_ki g_n^p).
///
/// The flux-weighted averages then depend on the pair and the temperatures only through
/// x = a_ki (sqrt(2) u)^p: `<(1 + eps)^m> = Phi_m(x) = 2 int z^3 exp(-z^2) (1 + f(x z^p))^m dz`.
/// Phi_1, Phi_2 are computed by the adaptive quadrature on a uniform grid in ln x (step 1/128,
/// ln x in [-40, 12], built lazily in chunks of 64 nodes where needed) and interpolated with
/// 8-point Lagrange polynomials: relative error < 1e-12 for a smooth f, ~1e-9 for a piecewise
/// linear f with knots every 0.05 in beta (Phi is smooth in ln x even where f is only
/// piecewise smooth, but only on the scale ~0.07 in ln x over which the average over z
/// smooths it). Below the grid Phi is extrapolated as Phi(0) + c x^q from its first nodes (f
/// must leave f(0) as a power of its argument, as the viscoelastic F does); above it the
/// quadrature is used directly.
pub struct ScaledEps {
    a: Vec<Vec<f64>>,
    p: f64,
    f: Box<dyn Fn(f64) -> f64 + Send + Sync>,
    chunks: Vec<std::sync::OnceLock<Vec<[f64; 2]>>>,
}

const LNX_LO: f64 = -40.0;
const LNX_HI: f64 = 12.0;
const LNX_PER_UNIT: usize = 128;
const CHUNK: usize = 64;

impl ScaledEps {
    /// eps_ki(g_n) = f(`a[k][i]` g_n^p).
    pub fn new(a: Vec<Vec<f64>>, p: f64, f: impl Fn(f64) -> f64 + Send + Sync + 'static) -> Self {
        let n = ((LNX_HI - LNX_LO) as usize) * LNX_PER_UNIT + 1;
        ScaledEps {
            a,
            p,
            f: Box::new(f),
            chunks: (0..n.div_ceil(CHUNK))
                .map(|_| std::sync::OnceLock::new())
                .collect(),
        }
    }

    /// eps of pair (k, i) at normal impact speed g_n.
    pub fn eps(&self, k: usize, i: usize, g_n: f64) -> f64 {
        (self.f)(self.a[k][i] * g_n.powf(self.p))
    }

    /// (Phi_1(x), Phi_2(x)) by quadrature.
    pub fn phi_direct(&self, x: f64) -> (f64, f64) {
        flux_averages(|z| (self.f)(x * z.powf(self.p)))
    }

    fn node(&self, j: usize) -> [f64; 2] {
        let c = self.chunks[j / CHUNK].get_or_init(|| {
            (0..CHUNK)
                .map(|o| {
                    let l = LNX_LO + ((j / CHUNK) * CHUNK + o) as f64 / LNX_PER_UNIT as f64;
                    let (a, b) = self.phi_direct(l.exp());
                    [a, b]
                })
                .collect()
        });
        c[j % CHUNK]
    }

    /// (Phi_1(x), Phi_2(x)), interpolated in ln x where tabulated; below the table
    /// (x < e^-40, 1 - eps ~ 1e-17 for the viscoelastic F) extrapolated from it.
    pub fn phi(&self, x: f64) -> (f64, f64) {
        if x <= 0.0 {
            let e = (self.f)(0.0);
            return (1.0 + e, (1.0 + e) * (1.0 + e));
        }
        let r = (x.ln() - LNX_LO) * LNX_PER_UNIT as f64;
        let n = ((LNX_HI - LNX_LO) as usize) * LNX_PER_UNIT + 1;
        if r < 3.0 {
            return self.phi_below(x);
        }
        if r > (n - 5) as f64 || r.is_nan() {
            return self.phi_direct(x);
        }
        let j0 = r.floor() as usize - 3;
        let mut out = [0.0; 2];
        for a in 0..8 {
            let mut w = 1.0;
            for b in 0..8 {
                if a != b {
                    w *= (r - (j0 + b) as f64) / (a as f64 - b as f64);
                }
            }
            let v = self.node(j0 + a);
            out[0] += w * v[0];
            out[1] += w * v[1];
        }
        (out[0], out[1])
    }

    /// Below the table: Phi_m(x) = Phi_m(0) + c_m x^q_m, with c_m and q_m from the first two
    /// usable nodes (x_3 = e^(-40 + 3/128), x_4). For an f that leaves f(0) as a power of its
    /// argument (the viscoelastic F = 1 - C1 beta + ...: q = 1) this is the leading term of
    /// Phi's expansion; there the correction is below 1e-17 of Phi(0), a double's rounding.
    /// (The quadrature there, at every rate evaluation of a nearly elastic gas, made its
    /// theory take minutes.)
    fn phi_below(&self, x: f64) -> (f64, f64) {
        let e0 = (self.f)(0.0);
        let p0 = [1.0 + e0, (1.0 + e0) * (1.0 + e0)];
        let (a, b) = (self.node(3), self.node(4));
        let dl = 1.0 / LNX_PER_UNIT as f64;
        let l3 = LNX_LO + 3.0 * dl;
        let mut out = [0.0; 2];
        for c in 0..2 {
            let (da, db) = (a[c] - p0[c], b[c] - p0[c]);
            let q = if da != 0.0 && db != 0.0 && (da > 0.0) == (db > 0.0) {
                ((db / da).ln() / dl).clamp(0.05, 20.0)
            } else {
                1.0
            };
            out[c] = p0[c] + da * (q * (x.ln() - l3)).exp();
        }
        (out[0], out[1])
    }

    /// (<1 + eps>, <(1 + eps)^2>) of pair (k, i) at relative-velocity scale u.
    pub fn averages(&self, k: usize, i: usize, u: f64) -> (f64, f64) {
        self.phi(self.a[k][i] * (2f64.sqrt() * u).powf(self.p))
    }
}

impl fmt::Debug for PairRestitution {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PairRestitution::Constant(e) => write!(f, "Constant({e})"),
            PairRestitution::ConstantPairs(m) => write!(f, "ConstantPairs({m:?})"),
            PairRestitution::VelocityDependent(_) => write!(f, "VelocityDependent(..)"),
            PairRestitution::Scaled(s) => write!(f, "Scaled {{ a: {:?}, p: {} }}", s.a, s.p),
        }
    }
}

impl PairRestitution {
    /// Velocity-dependent restitution from a function (k, i, g_n) -> eps.
    pub fn velocity_dependent(
        f: impl Fn(usize, usize, f64) -> f64 + Send + Sync + 'static,
    ) -> Self {
        PairRestitution::VelocityDependent(Arc::new(f))
    }

    /// Velocity-dependent restitution from one function of g_n per pair (`table[k][i]`).
    pub fn per_pair(table: Vec<Vec<EpsFn>>) -> Self {
        PairRestitution::velocity_dependent(move |k, i, g| (table[k][i])(g))
    }

    /// Viscoelastic restitution (Appendix A, spec 2): eps_ki(g_n) = f(beta) with
    /// beta = A kappa_ki^(2/5) g_n^(1/5), A kappa_ki^(2/5) from [`a_kappa_pairs`] (the value for
    /// the pair (0, 0) is `a_kappa_00`). `f` is the dimensionless restitution function F(beta)
    /// of the contact model (F(beta) = 1 - 1.15344 beta + ... for small beta).
    pub fn viscoelastic(
        species: &[Species],
        a_kappa_00: f64,
        f: impl Fn(f64) -> f64 + Send + Sync + 'static,
    ) -> Self {
        PairRestitution::scaled(a_kappa_pairs(species, a_kappa_00), 0.2, f)
    }

    /// eps_ki(g_n) = f(`a[k][i]` g_n^p).(see [`ScaledEps`]); viscoelastic: p = 1/5,
    /// `a[k][i]` = A kappa_ki^(2/5), f = F(beta).
    pub fn scaled(
        a: Vec<Vec<f64>>,
        p: f64,
        f: impl Fn(f64) -> f64 + Send + Sync + 'static,
    ) -> Self {
        PairRestitution::Scaled(Arc::new(ScaledEps::new(a, p, f)))
    }

    /// eps_ki(g_n) for any restitution.
    pub fn eps(&self, k: usize, i: usize, g_n: f64) -> f64 {
        match self {
            PairRestitution::VelocityDependent(f) => f.eps(k, i, g_n),
            PairRestitution::Scaled(s) => s.eps(k, i, g_n),
            _ => self.constant(k, i).unwrap(),
        }
    }

    /// The truncated series (A1): eps_ki = 1 + sum_{j>=1} h_j (A kappa_ki^(2/5))^(j/2) g_n^(j/10)
    /// (`h[0]` is h_1), A kappa_ki^(2/5) from [`a_kappa_pairs`].
    pub fn series(species: &[Species], a_kappa_00: f64, h: Vec<f64>) -> Self {
        let ak = a_kappa_pairs(species, a_kappa_00);
        PairRestitution::velocity_dependent(move |k, i, g| series_eps(&h, ak[k][i], g))
    }

    /// True when eps does not depend on the impact speed (an exact HCS then exists).
    pub fn is_constant(&self) -> bool {
        matches!(
            self,
            PairRestitution::Constant(_) | PairRestitution::ConstantPairs(_)
        )
    }

    /// The constant eps_ki, None for velocity-dependent restitution.
    pub fn constant(&self, k: usize, i: usize) -> Option<f64> {
        match self {
            PairRestitution::Constant(e) => Some(*e),
            PairRestitution::ConstantPairs(m) => Some(m[k][i]),
            PairRestitution::VelocityDependent(_) | PairRestitution::Scaled(_) => None,
        }
    }

    /// The flux-weighted Maxwell averages (<1 + eps>, <(1 + eps)^2>) for pair (k, i) at
    /// relative-velocity scale u (see the module docs).
    pub fn averages(&self, k: usize, i: usize, u: f64) -> (f64, f64) {
        match self {
            PairRestitution::VelocityDependent(f) => maxwell_averages(|g| f.eps(k, i, g), u),
            PairRestitution::Scaled(s) => s.averages(k, i, u),
            _ => {
                let e = self.constant(k, i).unwrap();
                (1.0 + e, (1.0 + e) * (1.0 + e))
            }
        }
    }
}

/// (<1 + eps>, <(1 + eps)^2>) over the flux-weighted normal-speed distribution
/// 2 z^3 exp(-z^2) dz, g_n = sqrt(2) u z, by adaptive quadrature (~1e-13 relative).
pub fn maxwell_averages(eps: impl Fn(f64) -> f64, u: f64) -> (f64, f64) {
    let scale = 2f64.sqrt() * u;
    flux_averages(|z| eps(scale * z))
}

/// 2 int_0^9.5 z^3 exp(-z^2) (1 + e(z))^m dz for m = 1, 2 (adaptive, ~1e-13 relative).
fn flux_averages(e: impl Fn(f64) -> f64) -> (f64, f64) {
    let mut f = |z: f64| {
        let w = 2.0 * z * z * z * (-z * z).exp();
        let e1 = 1.0 + e(z);
        [w * e1, w * e1 * e1]
    };
    let r = adaptive(
        &mut f,
        &[0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.5, 9.5],
        1e-13,
        1e-300,
    );
    (r[0], r[1])
}

/// The pair rates of species k due to species i, in the Maxwellian approximation (g2 = 1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairRates {
    /// xi_ki (15) / (A7).
    pub xi: f64,
    /// tau_v,ki^-1 (11) / (A6).
    pub tau_v_inv: f64,
    /// nu_ki: collisions per unit time of one k particle with i particles.
    pub collision_rate: f64,
}

/// sigma_ki, mu_i = m_i/(m_i+m_k), u^2 and Gam_ki for the pair (k, i).
pub(crate) fn pair_geometry(sk: &Species, tk: f64, si: &Species, ti: f64) -> (f64, f64, f64, f64) {
    let sigma = 0.5 * (sk.diameter + si.diameter);
    let mu = si.mass / (si.mass + sk.mass);
    let u2 = tk / sk.mass + ti / si.mass;
    let gam = (tk * si.mass + ti * sk.mass) / (tk * (si.mass + sk.mass));
    (sigma, mu, u2, gam)
}

/// xi_ki, tau_v,ki^-1 and nu_ki for species k (index `k`, temperature `tk`) colliding with
/// species i, restitution `r` (see the module docs for the integrals).
pub fn pair_rates(
    sk: &Species,
    k: usize,
    tk: f64,
    si: &Species,
    i: usize,
    ti: f64,
    r: &PairRestitution,
) -> PairRates {
    let (sigma, mu, u2, gam) = pair_geometry(sk, tk, si, ti);
    let u = u2.sqrt();
    let (a1, a2) = r.averages(k, i, u);
    let p = 8.0 / 3.0 * (2.0 * PI).sqrt() * si.density * sigma * sigma * u * mu;
    PairRates {
        xi: p * (a1 - 0.5 * gam * a2),
        tau_v_inv: p * 0.25 * gam * a2,
        collision_rate: 2.0 * (2.0 * PI).sqrt() * si.density * sigma * sigma * u,
    }
}

/// Per-pair constants for fast repeated evaluation of the rates at changing temperatures
/// (the ODE right-hand sides); same formulas as [`pair_rates`].
pub(crate) struct PairTable<'a> {
    m: usize,
    species: &'a [Species],
    r: &'a PairRestitution,
    /// (8 sqrt(2 pi)/3) n_i sigma_ki^2, mu_i, and the constant (a1, a2) when eps is constant.
    pre: Vec<(f64, f64, f64, f64)>,
    /// m_k mu_i per pair (the first product of gamma's numerator, so the same bits).
    mk_mu: Vec<f64>,
    /// The columns of `pre` as separate arrays (p0, mu, a1, a2), row-major k * m + i, when
    /// every pair's eps is constant (empty otherwise): the loop of
    /// [`PairTable::cooling_rates`] over them has no branch and vectorises (sqrt and divide
    /// are correctly rounded in every lane, so the same bits).
    soa: [Vec<f64>; 4],
}

impl<'a> PairTable<'a> {
    pub(crate) fn new(species: &'a [Species], r: &'a PairRestitution) -> Self {
        let m = species.len();
        let mut pre = Vec::with_capacity(m * m);
        for k in 0..m {
            for i in 0..m {
                let (sk, si) = (&species[k], &species[i]);
                let sigma = 0.5 * (sk.diameter + si.diameter);
                let p0 = 8.0 / 3.0 * (2.0 * PI).sqrt() * si.density * sigma * sigma;
                let mu = si.mass / (si.mass + sk.mass);
                let (a1, a2) = match r.constant(k, i) {
                    Some(e) => (1.0 + e, (1.0 + e) * (1.0 + e)),
                    None => (f64::NAN, f64::NAN),
                };
                pre.push((p0, mu, a1, a2));
            }
        }
        let mk_mu = (0..m * m)
            .map(|ki| species[ki / m].mass * pre[ki].1)
            .collect();
        let soa = if pre.iter().all(|p| !p.2.is_nan()) {
            [
                pre.iter().map(|p| p.0).collect(),
                pre.iter().map(|p| p.1).collect(),
                pre.iter().map(|p| p.2).collect(),
                pre.iter().map(|p| p.3).collect(),
            ]
        } else {
            Default::default()
        };
        PairTable {
            m,
            species,
            r,
            pre,
            mk_mu,
            soa,
        }
    }

    /// T_j / m_j of every species: the terms of u^2 that [`PairTable::rates_tm`] takes, each
    /// divided once per right-hand side instead of once per pair.
    pub(crate) fn t_over_m(&self, t: &[f64]) -> Vec<f64> {
        t.iter()
            .zip(self.species)
            .map(|(t, s)| t / s.mass)
            .collect()
    }

    /// [`PairTable::rates`] with `tmk` = tk / m_k and `tmi` = ti / m_i given: the same
    /// operations in the same order, so the same bits.
    #[inline(always)]
    pub(crate) fn rates_tm(&self, k: usize, tk: f64, tmk: f64, i: usize, tmi: f64) -> (f64, f64) {
        let ki = k * self.m + i;
        let (p0, mu, a1, a2) = self.pre[ki];
        let u2 = tmk + tmi;
        let u = u2.sqrt();
        let (a1, a2) = if a1.is_nan() {
            self.r.averages(k, i, u)
        } else {
            (a1, a2)
        };
        let gam = self.mk_mu[ki] * u2 / tk;
        let p = p0 * u * mu;
        (p * (a1 - 0.5 * gam * a2), p * 0.25 * gam * a2)
    }

    /// (xi_ki, tau_v,ki^-1): the reference form of [`PairTable::rates_tm`] (the tests check
    /// that both give the same bits).
    #[cfg(test)]
    pub(crate) fn rates(&self, k: usize, tk: f64, i: usize, ti: f64) -> (f64, f64) {
        let (p0, mu, a1, a2) = self.pre[k * self.m + i];
        let (mk, mi) = (self.species[k].mass, self.species[i].mass);
        let u2 = tk / mk + ti / mi;
        let u = u2.sqrt();
        let (a1, a2) = if a1.is_nan() {
            self.r.averages(k, i, u)
        } else {
            (a1, a2)
        };
        let gam = mk * mu * u2 / tk;
        let p = p0 * u * mu;
        (p * (a1 - 0.5 * gam * a2), p * 0.25 * gam * a2)
    }

    /// xi_k (14) of every species: the sums of [`PairTable::rates_tm`]'s xi_ki over i in
    /// order. With constant restitution the pair terms of a row are computed first, in one
    /// branch-free loop (the same operations, so the same bits), then summed in the same order.
    pub(crate) fn cooling_rates(&self, t: &[f64]) -> Vec<f64> {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2.
            return unsafe { self.cooling_rates_avx2(t) };
        }
        self.cooling_rates_portable(t)
    }

    /// [`cooling_rates`](Self::cooling_rates) compiled for 256-bit vectors: per element the
    /// same operations in the same order (no fused multiply-add), so the same bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn cooling_rates_avx2(&self, t: &[f64]) -> Vec<f64> {
        self.cooling_rates_portable(t)
    }

    #[inline(always)]
    fn cooling_rates_portable(&self, t: &[f64]) -> Vec<f64> {
        let tm = self.t_over_m(t);
        let m = self.m;
        if !self.soa[0].is_empty() {
            let [p0s, mus, a1s, a2s] = &self.soa;
            // Four rows at a time: their terms, then their sums side by side (four
            // independent chains of additions, each in the order of `Iterator::sum`, from its
            // starting value: the same bits).
            let zero: f64 = std::iter::empty::<f64>().sum();
            let mut terms = vec![0.0; 4 * m];
            let mut xi = vec![0.0; m];
            for k0 in (0..m).step_by(4) {
                let rows = (m - k0).min(4);
                for (r, buf) in terms.chunks_exact_mut(m).take(rows).enumerate() {
                    let k = k0 + r;
                    let (tk, tmk) = (t[k], tm[k]);
                    let row = k * m..(k + 1) * m;
                    let pairs = p0s[row.clone()]
                        .iter()
                        .zip(&mus[row.clone()])
                        .zip(&a1s[row.clone()])
                        .zip(&a2s[row.clone()])
                        .zip(&self.mk_mu[row])
                        .zip(&tm[..m]);
                    for (x, (((((&p0, &mu), &a1), &a2), &kmu), &tmi)) in buf.iter_mut().zip(pairs) {
                        let u2 = tmk + tmi;
                        let u = u2.sqrt();
                        let gam = kmu * u2 / tk;
                        let p = p0 * u * mu;
                        *x = p * (a1 - 0.5 * gam * a2);
                    }
                }
                if rows == 4 {
                    let (b01, b23) = terms.split_at(2 * m);
                    let (b0, b1) = b01.split_at(m);
                    let (b2, b3) = b23.split_at(m);
                    let mut acc = [zero; 4];
                    for (((x0, x1), x2), x3) in b0.iter().zip(b1).zip(b2).zip(b3) {
                        acc[0] += x0;
                        acc[1] += x1;
                        acc[2] += x2;
                        acc[3] += x3;
                    }
                    xi[k0..k0 + 4].copy_from_slice(&acc);
                } else {
                    for (r, buf) in terms.chunks_exact(m).take(rows).enumerate() {
                        xi[k0 + r] = buf.iter().sum();
                    }
                }
            }
            return xi;
        }
        (0..self.m)
            .map(|k| {
                (0..self.m)
                    .map(|i| self.rates_tm(k, t[k], tm[k], i, tm[i]).0)
                    .sum()
            })
            .collect()
    }

    /// tau_v,k (10) of every species.
    pub(crate) fn tau_v(&self, t: &[f64]) -> Vec<f64> {
        let tm = self.t_over_m(t);
        (0..self.m)
            .map(|k| {
                1.0 / (0..self.m)
                    .map(|i| self.rates_tm(k, t[k], tm[k], i, tm[i]).1)
                    .sum::<f64>()
            })
            .collect()
    }
}

/// A kappa_ki^(2/5) for every pair: kappa_ki ∝ sqrt(sigma_eff)/m_eff (A3)-(A5),
/// sigma_eff = sigma_k sigma_i/(sigma_k + sigma_i), m_eff = m_k m_i/(m_k + m_i), scaled so that
/// the pair (0, 0) has `a_kappa_00` (the paper's Figs 7-8: 0.09 for the monomer pair).
pub fn a_kappa_pairs(species: &[Species], a_kappa_00: f64) -> Vec<Vec<f64>> {
    let kappa = |a: &Species, b: &Species| {
        let se = a.diameter * b.diameter / (a.diameter + b.diameter);
        let me = a.mass * b.mass / (a.mass + b.mass);
        se.sqrt() / me
    };
    let k00 = kappa(&species[0], &species[0]);
    species
        .iter()
        .map(|a| {
            species
                .iter()
                .map(|b| a_kappa_00 * (kappa(a, b) / k00).powf(0.4))
                .collect()
        })
        .collect()
}

/// eps of the series (A1) with coefficients h = [h_1, h_2, ...] at A kappa^(2/5) = `ak`.
pub fn series_eps(h: &[f64], ak: f64, g_n: f64) -> f64 {
    let x = ak.sqrt() * g_n.powf(0.1);
    let mut e = 1.0;
    let mut p = 1.0;
    for hj in h {
        p *= x;
        e += hj * p;
    }
    e
}

/// A_n = 4 h_n + sum_{j+l=n} h_j h_l, n = 1..2J, for h = [h_1..h_J] (Appendix A).
pub fn series_a(h: &[f64]) -> Vec<f64> {
    let jn = h.len();
    let mut a = vec![0.0; 2 * jn];
    for n in 1..=2 * jn {
        let mut v = if n <= jn { 4.0 * h[n - 1] } else { 0.0 };
        for j in 1..n {
            let l = n - j;
            if j <= jn && l <= jn {
                v += h[j - 1] * h[l - 1];
            }
        }
        a[n - 1] = v;
    }
    a
}

/// B_n of Appendix A: (A kappa^(2/5))^(n/2) (2 u^2)^(n/20) ((20 + n) n / 800) Gamma(n/20),
/// u^2 = (T_k m_i + T_i m_k)/(m_i m_k). (It equals <x^n>/2 with the flux-weighted average.)
pub fn series_b(n: usize, ak: f64, u2: f64) -> f64 {
    let nf = n as f64;
    ak.powf(nf / 2.0) * (2.0 * u2).powf(nf / 20.0) * ((20.0 + nf) * nf / 800.0) * gamma(nf / 20.0)
}

/// xi_ki of (A7) for the series restitution (A1) (coefficients `h`, A kappa_ki^(2/5) = `ak`):
/// (16/3) sqrt(2 pi) n_i sigma_ki^2 u mu_i [1 - Gam + sum_n B_n (h_n - Gam A_n / 2)].
pub fn xi_pair_series(sk: &Species, tk: f64, si: &Species, ti: f64, ak: f64, h: &[f64]) -> f64 {
    let (sigma, mu, u2, gam) = pair_geometry(sk, tk, si, ti);
    let a = series_a(h);
    let mut s = 1.0 - gam;
    for n in 1..=a.len() {
        let hn = if n <= h.len() { h[n - 1] } else { 0.0 };
        s += series_b(n, ak, u2) * (hn - 0.5 * gam * a[n - 1]);
    }
    16.0 / 3.0 * (2.0 * PI).sqrt() * si.density * sigma * sigma * u2.sqrt() * mu * s
}

/// tau_v,ki^-1 of (A6) for the series restitution (A1):
/// (8 sqrt(2 pi)/3) n_i sigma_ki^2 mu_i Gam u (1 + sum_n A_n B_n / 2).
pub fn tau_v_inv_pair_series(
    sk: &Species,
    tk: f64,
    si: &Species,
    ti: f64,
    ak: f64,
    h: &[f64],
) -> f64 {
    let (sigma, mu, u2, gam) = pair_geometry(sk, tk, si, ti);
    let a = series_a(h);
    let s: f64 = 1.0
        + 0.5
            * (1..=a.len())
                .map(|n| a[n - 1] * series_b(n, ak, u2))
                .sum::<f64>();
    8.0 / 3.0 * (2.0 * PI).sqrt() * si.density * sigma * sigma * mu * gam * u2.sqrt() * s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::theory::temperature::xi_pair;

    fn sp(m: f64, n: f64) -> Species {
        Species {
            mass: m,
            diameter: m.cbrt(),
            density: n,
        }
    }

    /// For constant eps the general pair rates are (15) and (11) (1e-14 relative), also when
    /// the constant is passed as a velocity-dependent function (quadrature, 1e-12).
    #[test]
    fn constant_reduces_to_15_and_11() {
        let (a, b) = (sp(1.0, 0.1), sp(37.0, 0.02));
        for (ta, tb, e) in [(1.0, 3.0, 0.5), (0.3, 20.0, 0.9), (2.0, 0.1, 0.0)] {
            let r = pair_rates(&a, 0, ta, &b, 1, tb, &PairRestitution::Constant(e));
            let want = xi_pair(&a, ta, &b, tb, e);
            assert!(
                (r.xi - want).abs() < 1e-14 * want.abs().max(1e-3),
                "{} vs {want}",
                r.xi
            );
            // (11) literally.
            let (mk, mi) = (a.mass, b.mass);
            let sigma = 0.5 * (a.diameter + b.diameter);
            let t11 = 8.0 * (2.0 * PI).sqrt() / 3.0 * b.density * sigma * sigma * mi / (mi + mk)
                * (ta * mi + tb * mk)
                / (ta * (mi + mk))
                * ((ta * mi + tb * mk) / (mi * mk)).sqrt()
                * (1.0 + e)
                * (1.0 + e)
                / 4.0;
            assert!(
                (r.tau_v_inv - t11).abs() < 1e-14 * t11,
                "{} vs {t11}",
                r.tau_v_inv
            );
            let rv = pair_rates(
                &a,
                0,
                ta,
                &b,
                1,
                tb,
                &PairRestitution::velocity_dependent(move |_, _, _| e),
            );
            assert!(
                (rv.xi - r.xi).abs() < 1e-12 * r.xi.abs().max(1e-3 * r.tau_v_inv),
                "{} vs {}",
                rv.xi,
                r.xi
            );
            assert!((rv.tau_v_inv / r.tau_v_inv - 1.0).abs() < 1e-12);
        }
    }

    /// `n` species of masses 1.37 k and number densities 0.1 k^-2.5 (k = 1..n) at temperatures
    /// spread over three decades: the mixtures of the bit-identity tests.
    fn spread_mixture(n: usize) -> (Vec<Species>, Vec<f64>) {
        let s = (1..=n)
            .map(|k| sp(k as f64 * 1.37, 0.1 / (k as f64).powf(2.5)))
            .collect();
        let t = (0..n)
            .map(|k| 0.013 * (1.0 + k as f64).powf(1.9) + 1e-3)
            .collect();
        (s, t)
    }

    /// The hot path of the ODEs (T/m divided once per species, m_k mu_i premultiplied) gives
    /// the same bits as the per-pair formula, constant and velocity-dependent, over a range
    /// of masses and temperatures (the theory tables must not move by one bit).
    #[test]
    fn rates_tm_is_bit_identical() {
        let (s, t) = spread_mixture(40);
        for r in [
            PairRestitution::Constant(0.5),
            PairRestitution::series(&s, 0.09, vec![0.0, -1.15344, 0.0, 0.79826]),
        ] {
            let table = PairTable::new(&s, &r);
            let tm = table.t_over_m(&t);
            for k in 0..s.len() {
                for i in 0..s.len() {
                    let want = table.rates(k, t[k], i, t[i]);
                    let got = table.rates_tm(k, t[k], tm[k], i, tm[i]);
                    assert_eq!(
                        (want.0.to_bits(), want.1.to_bits()),
                        (got.0.to_bits(), got.1.to_bits()),
                        "pair ({k}, {i})"
                    );
                }
            }
        }
    }

    /// The cooling rates of the ODEs' right-hand side (with constant restitution: the pair
    /// terms of a row in one branch-free loop, then summed) have the same bits as the sums of
    /// [`PairTable::rates`] over i in order, for one eps, per-pair eps and a series eps (the
    /// theory tables must not move by one bit).
    #[test]
    fn cooling_rates_are_bit_identical() {
        let (s, t) = spread_mixture(37);
        let pairs = (0..37)
            .map(|k| {
                (0..37)
                    .map(|i| 0.3 + 0.01 * ((k * 7 + i * 3) % 41) as f64)
                    .collect()
            })
            .collect();
        for r in [
            PairRestitution::Constant(0.5),
            PairRestitution::ConstantPairs(pairs),
            PairRestitution::series(&s, 0.09, vec![0.0, -1.15344, 0.0, 0.79826]),
        ] {
            let table = PairTable::new(&s, &r);
            // Where the CPU has AVX2 this is the AVX2 copy; the portable code must give the
            // same bits too.
            let got = table.cooling_rates(&t);
            let portable = table.cooling_rates_portable(&t);
            for k in 0..s.len() {
                let want: f64 = (0..s.len()).map(|i| table.rates(k, t[k], i, t[i]).0).sum();
                assert_eq!(want.to_bits(), got[k].to_bits(), "{r:?}: species {k}");
                assert_eq!(want.to_bits(), portable[k].to_bits(), "{r:?}: species {k}");
            }
        }
    }

    /// The fast per-pair table equals pair_rates (1e-14), constant and velocity-dependent.
    #[test]
    fn pair_table_matches() {
        let s = [sp(1.0, 0.1), sp(37.0, 0.02), sp(500.0, 0.3)];
        let t = [0.4, 7.0, 30.0];
        for r in [
            PairRestitution::Constant(0.7),
            PairRestitution::series(&s, 0.09, vec![0.0, -1.15344, 0.0, 0.79826]),
        ] {
            let table = PairTable::new(&s, &r);
            for k in 0..3 {
                for i in 0..3 {
                    let a = pair_rates(&s[k], k, t[k], &s[i], i, t[i], &r);
                    let (xi, tv) = table.rates(k, t[k], i, t[i]);
                    assert!(
                        (xi - a.xi).abs() <= 1e-14 * a.tau_v_inv.max(a.xi.abs()),
                        "{xi} {}",
                        a.xi
                    );
                    assert!((tv / a.tau_v_inv - 1.0).abs() < 1e-14);
                }
            }
        }
    }

    /// Appendix A: for the series restitution (A1) the exact quadrature equals the paper's
    /// (A6)-(A7) (1e-10 relative), with h_2 = -1.15344, h_4 = 0.79826 (Ramirez et al. 1999) and
    /// an odd term h_5 = 0.3, at A kappa^(2/5) = 0.09 for the monomer pair.
    #[test]
    fn series_a6_a7_equal_quadrature() {
        let species = [sp(1.0, 0.1), sp(100.0, 0.1), sp(500.0, 0.1)];
        let h = vec![0.0, -1.15344, 0.0, 0.79826, 0.3];
        let r = PairRestitution::series(&species, 0.09, h.clone());
        let ak = a_kappa_pairs(&species, 0.09);
        let temps = [0.7, 3.0, 12.0];
        let mut worst: f64 = 0.0;
        for k in 0..3 {
            for i in 0..3 {
                let q = pair_rates(&species[k], k, temps[k], &species[i], i, temps[i], &r);
                let xi = xi_pair_series(&species[k], temps[k], &species[i], temps[i], ak[k][i], &h);
                let tv = tau_v_inv_pair_series(
                    &species[k],
                    temps[k],
                    &species[i],
                    temps[i],
                    ak[k][i],
                    &h,
                );
                let scale = q.tau_v_inv; // xi may be near zero: compare on the rate scale
                worst = worst
                    .max((q.xi - xi).abs() / scale)
                    .max((q.tau_v_inv / tv - 1.0).abs());
            }
        }
        eprintln!("A6-A7 vs quadrature: worst relative deviation {worst:.2e}");
        assert!(worst < 1e-10, "{worst}");
    }

    /// The tabulated Scaled averages equal the direct quadrature for the viscoelastic form,
    /// over u from 1e-9 to 1e4 and three pairs: 1e-12 relative with a smooth F, 2e-9 with a
    /// piecewise linear F (40 knots; its Phi is smooth only on a scale ~0.07 in ln x). The
    /// viscoelastic constructor uses the table.
    #[test]
    fn scaled_table_matches_direct() {
        let species = [sp(1.0, 0.1), sp(100.0, 0.1), sp(1e4, 0.1)];
        let knots: Vec<f64> = (0..=40)
            .map(|j| (-0.05 * j as f64).exp() * (1.0 - 0.02 * j as f64))
            .collect();
        let kinked = move |b: f64| {
            let x = (b * 20.0).min(39.999);
            let j = x.floor() as usize;
            knots[j] + (x - j as f64) * (knots[j + 1] - knots[j])
        };
        let smooth = |b: f64| 1.0 / (1.0 + 1.15344 * b + 0.5 * b * b);
        let fs: [Box<dyn Fn(f64) -> f64 + Send + Sync>; 2] = [Box::new(smooth), Box::new(kinked)];
        let mut worst = [0.0f64; 2];
        for (fi, f) in fs.into_iter().enumerate() {
            let f = Arc::new(f);
            let f2 = f.clone();
            let ak = a_kappa_pairs(&species, 0.09);
            let ak2 = ak.clone();
            let scaled = PairRestitution::scaled(ak, 0.2, move |b| f(b));
            let direct =
                PairRestitution::velocity_dependent(move |k, i, g| f2(ak2[k][i] * g.powf(0.2)));
            for (k, i) in [(0, 0), (0, 2), (2, 1)] {
                for e in -18..=8 {
                    let u = 10f64.powf(e as f64 * 0.5);
                    let (a1, a2) = scaled.averages(k, i, u);
                    let (b1, b2) = direct.averages(k, i, u);
                    worst[fi] = worst[fi]
                        .max((a1 / b1 - 1.0).abs())
                        .max((a2 / b2 - 1.0).abs());
                }
            }
        }
        eprintln!("Scaled table vs direct quadrature: worst relative deviation {:.2e} (smooth F), {:.2e} (piecewise linear F)", worst[0], worst[1]);
        assert!(worst[0] < 1e-12, "{worst:?}");
        assert!(worst[1] < 2e-9, "{worst:?}");
        assert!(matches!(
            PairRestitution::viscoelastic(&species, 0.09, |b| 1.0 - b),
            PairRestitution::Scaled(_)
        ));
    }

    /// Below the table (x < e^-40) the averages are extrapolated from it, not integrated at
    /// each call (before, a nearly elastic gas, e.g. a_kappa = 5e-324, ran the quadrature, a
    /// few hundred evaluations of F, at every pair rate of its theory: ~10 times slower than
    /// a_kappa = 0.09), and equal the quadrature to 1e-14 for an F like the viscoelastic one
    /// (1 - C1 beta + ...) and one that leaves 1 as sqrt(beta).
    #[test]
    fn below_the_table_is_extrapolated_not_integrated() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let fs: [fn(f64) -> f64; 2] = [
            |b| 1.0 / (1.0 + 1.15344 * b + 0.5 * b * b),
            |b| 1.0 - b.sqrt().min(1.0),
        ];
        for f in fs {
            let calls = Arc::new(AtomicUsize::new(0));
            let counted = calls.clone();
            let s = ScaledEps::new(vec![vec![1.0]], 0.2, move |b| {
                counted.fetch_add(1, Ordering::Relaxed);
                f(b)
            });
            let xs = [
                (-40.1f64).exp(),
                (-45.0f64).exp(),
                1e-30,
                1e-100,
                1e-300,
                5e-324,
            ];
            // The first call tabulates the grid's first chunk.
            s.phi(xs[0]);
            let before = calls.load(Ordering::Relaxed);
            let got: Vec<(f64, f64)> = xs.iter().map(|&x| s.phi(x)).collect();
            let used = calls.load(Ordering::Relaxed) - before;
            assert!(
                used <= 2 * xs.len(),
                "{used} evaluations of F for {} x",
                xs.len()
            );
            for (&x, (a1, a2)) in xs.iter().zip(got) {
                let (b1, b2) = s.phi_direct(x);
                assert!(
                    (a1 / b1 - 1.0).abs() < 1e-14 && (a2 / b2 - 1.0).abs() < 1e-14,
                    "x = {x:e}: ({a1}, {a2}) vs ({b1}, {b2})"
                );
            }
        }
    }

    /// The flux-weighted average of a smooth eps(g) = exp(-g/3) against a closed form:
    /// <exp(-a z)> = 2 int z^3 e^{-z^2 - a z} dz (evaluated with a 2000-panel reference rule) to 1e-12.
    #[test]
    fn smooth_average_accuracy() {
        let u = 1.7;
        let (a1, _) = maxwell_averages(|g| (-g / 3.0).exp(), u);
        let a = 2f64.sqrt() * u / 3.0;
        let (x, w) = crate::math::quad::gauss_legendre(20);
        let mut reference = 0.0;
        for p in 0..2000 {
            let (lo, hi) = (p as f64 * 0.01, (p + 1) as f64 * 0.01);
            for (xi, wi) in x.iter().zip(&w) {
                let z = 0.5 * (lo + hi) + 0.5 * (hi - lo) * xi;
                reference += 0.5 * (hi - lo) * wi * 2.0 * z.powi(3) * (-z * z - a * z).exp();
            }
        }
        let want = 1.0 + reference;
        assert!((a1 / want - 1.0).abs() < 1e-12, "{a1} vs {want}");
    }
}
