//! The tracer limit of a binary mixture (section II.F, (29)-(35)): gas species 1 (mass m_1,
//! diameter sigma_1, density n_1) and intruders 2 with n_2 -> 0, mu = m_2/m_1. g2 = 1.
//!
//! The gas cools by Haff's law with tau_0 (29); its velocity correlation time is (30) and its
//! MSD (31). The intruder's MSD is (22) with tau_v,2(0) from (32)-(33); its temperature ratio
//! gamma_21 = T_2/T_1 follows from xi_21(gamma) = xi_11 (equal cooling rates with n_2 = 0):
//! [`gamma21_exact`]. The paper's explicit heavy-intruder formula (34)-(35) is
//! [`gamma21_heavy`]; as printed, (35) has sigma_12^2/sigma_2^2 where the mu >> 1 expansion of
//! xi_21 = xi_11 gives sigma_1^2/sigma_12^2 ([`B35::Derived`]); both are provided. Either way
//! (34) needs b < 1, which fails for the paper's Fig 5 (mu = 100, same material): there
//! T_2/T_1 = 412.93 >> mu and the mu >> 1 expansion (gamma/mu -> 0) does not apply.

use super::diffusion::tau_c;
use super::restitution::{pair_rates, PairRestitution};
use super::species::Species;
use crate::math::quad::phi;

/// tau_0 (29) = 6 tau_c(0) / (1 - eps_11^2).
pub fn tau0_tracer(eps11: f64, tau_c0: f64) -> f64 {
    6.0 * tau_c0 / (1.0 - eps11 * eps11)
}

/// tau_v,1 (30) = 6 tau_c / (1 + eps_11)^2.
pub fn tau_v1_tracer(eps11: f64, tau_c: f64) -> f64 {
    6.0 * tau_c / ((1.0 + eps11) * (1.0 + eps11))
}

/// The gas MSD (31): 36 D_1(0) tau_c(0) [ln(1 + t/tau_0)/(1 - eps^2)
/// + ((1 + t/tau_0)^(-(1+eps)^2/(1-eps^2)) - 1)/(1 + eps)^2], tau_0 from (29).
pub fn msd_gas_tracer(d1_0: f64, tau_c0: f64, eps: f64, t: f64) -> f64 {
    let tau0 = tau0_tracer(eps, tau_c0);
    let x = (t / tau0).ln_1p();
    let e2 = 1.0 - eps * eps;
    let p2 = (1.0 + eps) * (1.0 + eps);
    // The bracket x/e2 + (exp(-p2 x/e2) - 1)/p2 written stably as phi(p2 x/e2)/p2,
    // phi(y) = y - 1 + e^-y (no cancellation at small t).
    36.0 * d1_0 * tau_c0 * phi(p2 / e2 * x) / p2
}

/// tau_hat_v,21 (33): 6 sigma_1^2 (1 + mu)^2 gamma_21 sqrt(mu) /
/// (sqrt(2) sigma_12^2 (mu + gamma_21)^(3/2) (1 + eps_12)^2).
pub fn tau_v2_hat(mu: f64, gamma21: f64, sigma1: f64, sigma12: f64, eps12: f64) -> f64 {
    6.0 * sigma1 * sigma1 * (1.0 + mu).powi(2) * gamma21 * mu.sqrt()
        / (2f64.sqrt() * sigma12 * sigma12 * (mu + gamma21).powf(1.5) * (1.0 + eps12).powi(2))
}

/// tau_v,2(0) (32) = tau_c(0) tau_hat_v,21.
pub fn tau_v2_tracer(
    tau_c0: f64,
    mu: f64,
    gamma21: f64,
    sigma1: f64,
    sigma12: f64,
    eps12: f64,
) -> f64 {
    tau_c0 * tau_v2_hat(mu, gamma21, sigma1, sigma12, eps12)
}

/// Which b to use in (34).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum B35 {
    /// (35) as printed: b = mu/(2 sqrt 2) (1 - eps_11^2)/(1 + eps_12) sigma_12^2/sigma_2^2.
    Printed,
    /// From the mu >> 1 limit of xi_21 = xi_11 with (15):
    /// b = mu/(2 sqrt 2) (1 - eps_11^2)/(1 + eps_12) sigma_1^2/sigma_12^2.
    Derived,
}

/// b of (35) (g2 = 1).
pub fn b35(
    mu: f64,
    eps11: f64,
    eps12: f64,
    sigma1: f64,
    sigma2: f64,
    sigma12: f64,
    which: B35,
) -> f64 {
    let geo = match which {
        B35::Printed => sigma12 * sigma12 / (sigma2 * sigma2),
        B35::Derived => sigma1 * sigma1 / (sigma12 * sigma12),
    };
    mu / (2.0 * 2f64.sqrt()) * (1.0 - eps11 * eps11) / (1.0 + eps12) * geo
}

/// gamma_21 (34) = (1 + eps_12) / (2 (1 - b)) for mu >> 1; None when b >= 1 (no positive
/// solution: the expansion does not apply).
pub fn gamma21_heavy(
    mu: f64,
    eps11: f64,
    eps12: f64,
    sigma1: f64,
    sigma2: f64,
    sigma12: f64,
    which: B35,
) -> Option<f64> {
    let b = b35(mu, eps11, eps12, sigma1, sigma2, sigma12, which);
    (b < 1.0).then(|| (1.0 + eps12) / (2.0 * (1.0 - b)))
}

/// The exact tracer-limit temperature ratio gamma_21 = T_2/T_1 (Maxwellian theory, n_2 = 0):
/// the root of xi_21(T_1, gamma T_1) = xi_11(T_1) with (15) (bisection on ln gamma to
/// machine precision). `gas` carries n_1; the intruder's density is ignored.
pub fn gamma21_exact(gas: &Species, intruder: &Species, eps11: f64, eps12: f64) -> f64 {
    let t1 = 1.0;
    let r = PairRestitution::ConstantPairs(vec![vec![eps11, eps12], vec![eps12, eps11]]);
    let xi11 = pair_rates(gas, 0, t1, gas, 0, t1, &r).xi;
    // xi_21 - xi_11 increases with gamma (hotter intruders cool faster).
    let f = |lg: f64| pair_rates(intruder, 1, t1 * lg.exp(), gas, 0, t1, &r).xi - xi11;
    let (mut lo, mut hi) = (-60.0f64, 60.0f64);
    assert!(f(lo) < 0.0 && f(hi) > 0.0, "no tracer HCS");
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if f(mid) < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo < 1e-15 {
            break;
        }
    }
    (0.5 * (lo + hi)).exp()
}

/// The tracer-limit quantities for gas at temperature T_1(0) = `t1`: (gamma_21, tau_c(0),
/// tau_0 (29), tau_v,1(0) (30), tau_v,2(0) (32)-(33) with the exact gamma_21).
pub fn tracer_hcs(
    gas: &Species,
    intruder: &Species,
    eps11: f64,
    eps12: f64,
    t1: f64,
) -> (f64, f64, f64, f64, f64) {
    let gamma = gamma21_exact(gas, intruder, eps11, eps12);
    let tc = tau_c(gas, t1);
    let mu = intruder.mass / gas.mass;
    let s12 = 0.5 * (gas.diameter + intruder.diameter);
    (
        gamma,
        tc,
        tau0_tracer(eps11, tc),
        tau_v1_tracer(eps11, tc),
        tau_v2_tracer(tc, mu, gamma, gas.diameter, s12, eps12),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::theory::diffusion::tau_v;
    use crate::theory::hcs::hcs_temperatures;
    use crate::theory::temperature::tau0_with;

    /// Fig 5: n_1 = 0.1, T_1 = 1, m_2 = 100, sigma_2 = 100^(1/3), eps = 0.5. Paper:
    /// T_2 = 412.93, tau_0 = 11.3, tau_v,2 = 1212. Exact tracer HCS: T_2 to 2e-5 relative;
    /// tau_0 (29) to 0.05 (3 printed digits); tau_v,2 (32)-(33) to 0.5 (4 printed digits);
    /// the general theory with n_2 = 0 gives the same tau_0 and tau_v,2 (1e-10).
    /// (34)-(35) give no positive gamma here (b > 1 in both forms), as asserted.
    #[test]
    fn fig5_tracer() {
        let gas = Species {
            mass: 1.0,
            diameter: 1.0,
            density: 0.1,
        };
        let intruder = Species {
            mass: 100.0,
            diameter: 100f64.cbrt(),
            density: 0.0,
        };
        let (gamma, tc, tau0, tv1, tv2) = tracer_hcs(&gas, &intruder, 0.5, 0.5, 1.0);
        let s12 = 0.5 * (1.0 + intruder.diameter);
        let bp = b35(100.0, 0.5, 0.5, 1.0, intruder.diameter, s12, B35::Printed);
        let bd = b35(100.0, 0.5, 0.5, 1.0, intruder.diameter, s12, B35::Derived);
        eprintln!("fig5: gamma_21 = {gamma:.5} ({:+.2e} vs 412.93), tau_c = {tc:.6}, tau0 = {tau0:.5} ({:+.2e} vs 11.3), tau_v1 = {tv1:.5}, tau_v2 = {tv2:.3} ({:+.2e} vs 1212)", gamma / 412.93 - 1.0, tau0 / 11.3 - 1.0, tv2 / 1212.0 - 1.0);
        eprintln!(
            "fig5: (35) printed b = {bp:.4}, derived b = {bd:.4}: (34) gives {:?} / {:?}",
            gamma21_heavy(100.0, 0.5, 0.5, 1.0, intruder.diameter, s12, B35::Printed),
            gamma21_heavy(100.0, 0.5, 0.5, 1.0, intruder.diameter, s12, B35::Derived)
        );
        assert!((gamma / 412.93 - 1.0).abs() < 2e-5);
        assert!((tau0 - 11.3).abs() < 0.05);
        assert!((tv2 - 1212.0).abs() < 0.5);
        assert!(
            gamma21_heavy(100.0, 0.5, 0.5, 1.0, intruder.diameter, s12, B35::Printed).is_none()
        );
        assert!(
            gamma21_heavy(100.0, 0.5, 0.5, 1.0, intruder.diameter, s12, B35::Derived).is_none()
        );
        // General theory with n_2 = 0.
        let s = [gas, intruder];
        let r = PairRestitution::Constant(0.5);
        let t = hcs_temperatures(&s, &r, 1.0).unwrap(); // mean over n: T_1 = 1
        assert!((t[0] - 1.0).abs() < 1e-14);
        assert!((t[1] / gamma - 1.0).abs() < 1e-10);
        let tv = tau_v(&s, &t, &r);
        assert!((tau0_with(&s, &t, &r) / tau0 - 1.0).abs() < 1e-10);
        assert!((tv[0] / tv1 - 1.0).abs() < 1e-12);
        assert!((tv[1] / tv2 - 1.0).abs() < 1e-10);
    }

    /// Where the heavy-intruder expansion applies (mu = 1e6, sigma_2 = 3, eps_11 = 0.999995,
    /// eps_12 = 0.8: b = 0.49, gamma = 1.77, gamma/mu ~ 2e-6), (34) with the derived b matches
    /// the exact ratio to 1e-4 relative (neglected terms O(gamma/mu), O(1/mu)); with the printed
    /// b (sigma_12^2/sigma_2^2 instead of sigma_1^2/sigma_12^2) it is off by a factor ~2.
    #[test]
    fn heavy_intruder_34() {
        let mu = 1e6;
        let gas = Species {
            mass: 1.0,
            diameter: 1.0,
            density: 0.1,
        };
        let intruder = Species {
            mass: mu,
            diameter: 3.0,
            density: 0.0,
        };
        let (e11, e12) = (0.999995, 0.8);
        let exact = gamma21_exact(&gas, &intruder, e11, e12);
        let d = gamma21_heavy(mu, e11, e12, 1.0, 3.0, 2.0, B35::Derived).unwrap();
        let p = gamma21_heavy(mu, e11, e12, 1.0, 3.0, 2.0, B35::Printed);
        eprintln!("heavy intruder mu = {mu}: exact gamma {exact:.6}, (34) with derived b {d:.6} ({:+.2e}), with printed b {p:?}", d / exact - 1.0);
        assert!((d / exact - 1.0).abs() < 1e-4, "{d} vs {exact}");
        assert!((p.unwrap() / exact - 1.0).abs() > 0.5);
    }
}
