//! Time-averaged MSD in the HCS (section II.E, (26)-(28)):
//!
//! ```text
//! <delta_k^2(Delta)> = <delta_0^2(Delta)> + Xi(Delta)                                  (27)
//! <delta_0^2> = 6 D_k(0) tau_0 / (t - Delta) [(t + tau_0) ln(t + tau_0)
//!     - (Delta + tau_0) ln(Delta + tau_0) - (t - Delta + tau_0) ln(t - Delta + tau_0) + tau_0 ln tau_0]
//! Xi(Delta) = 6 D_k(0) tau_v,k(0) / (t - Delta) int_0^(t-Delta) [(1 + Delta/(t' + tau_0))^-beta_k - 1] dt'
//! ```
//!
//! with beta_k = tau_0/tau_v,k(0); t is the measurement time, Delta the lag. (27) is the time
//! average over t' of the HCS increment <[R(t'+Delta) - R(t')]^2> = 6 D tau_0 ln((t'+Delta+tau_0)/
//! (t'+tau_0)) + 6 D tau_v ((1 + Delta/(t'+tau_0))^-beta - 1), i.e. (4) started at t'.
//!
//! Numerics: the bracket of <delta_0^2> is a second difference of x ln x; it is evaluated as
//! tau_0 [(T'+tau_0) ln1p(Delta/(T'+tau_0)) - tau_0 ln1p(Delta/tau_0) + Delta ln1p(T'/(tau_0+Delta))],
//! T' = t - Delta, and by quadrature of tau_0 ln1p(Delta/(t'+tau_0)) when tau_0 > 1e6 T'
//! (including tau_0 = infinity, eps = 1, where the integrand is Delta). Xi is integrated with
//! composite 16-point Gauss-Legendre on panels graded geometrically from both ends (smallest
//! panel min(tau_0, Delta, tau_v)/4), the integrand written as expm1(-tau_0 ln1p(Delta/(t'+tau_0))/tau_v).

use super::diffusion::{diffusion_coefficients, tau_v};
use super::restitution::PairRestitution;
use super::species::Species;
use super::temperature::tau0_with;
use crate::math::quad::graded_integral;

/// tau_0 ln(1 + Delta/(x + tau_0)), with its limit Delta for tau_0 = infinity.
fn l_of(tau0: f64, delta: f64, x: f64) -> f64 {
    if tau0.is_infinite() {
        delta
    } else {
        tau0 * (delta / (x + tau0)).ln_1p()
    }
}

/// The first term of (27), <delta_0^2(Delta)>, evaluated stably (see the module docs).
pub fn tamsd_first_term(d0: f64, tau0: f64, t: f64, delta: f64) -> f64 {
    assert!(delta > 0.0 && delta < t, "need 0 < Delta < t");
    let tp = t - delta;
    let j = if tau0.is_finite() && tau0 <= 1e6 * tp {
        tau0 * ((tp + tau0) * (delta / (tp + tau0)).ln_1p() - tau0 * (delta / tau0).ln_1p()
            + delta * (tp / (tau0 + delta)).ln_1p())
    } else {
        let h = tau0.min(delta).min(tp) / 4.0;
        graded_integral(|x| l_of(tau0, delta, x), 0.0, tp, h)
    };
    6.0 * d0 * j / tp
}

/// The first term of (27) written literally as printed (for checks; cancels badly when
/// Delta << t or tau_0 >> t).
pub fn tamsd_first_term_literal(d0: f64, tau0: f64, t: f64, delta: f64) -> f64 {
    let f = |x: f64| x * x.ln();
    6.0 * d0 * tau0 / (t - delta) * (f(t + tau0) - f(delta + tau0) - f(t - delta + tau0) + f(tau0))
}

/// Xi(Delta) of (27) by numerical integration (see the module docs).
pub fn xi_term(d0: f64, tau_v0: f64, tau0: f64, t: f64, delta: f64) -> f64 {
    assert!(delta > 0.0 && delta < t, "need 0 < Delta < t");
    let tp = t - delta;
    let h = tau0.min(delta).min(tau_v0).min(tp) / 4.0;
    let integral = graded_integral(|x| (-l_of(tau0, delta, x) / tau_v0).exp_m1(), 0.0, tp, h);
    6.0 * d0 * tau_v0 * integral / tp
}

/// The TAMSD (27) of a species with D_k(0) = `d0`, tau_v,k(0) = `tau_v0` in an HCS with
/// relaxation time `tau0` (infinity: no cooling), measured over [0, t] at lag `delta`.
/// Not a number where the HCS has no such time scales (tau_0 or tau_v,k(0) not positive: a
/// start far from the HCS where a species heats up): (27) does not apply there.
pub fn tamsd_hcs(d0: f64, tau_v0: f64, tau0: f64, t: f64, delta: f64) -> f64 {
    if !(tau0 > 0.0 && tau_v0 > 0.0) {
        return f64::NAN;
    }
    tamsd_first_term(d0, tau0, t, delta) + xi_term(d0, tau_v0, tau0, t, delta)
}

/// The asymptotic form (28) for tau_0 << Delta << t: 6 D_k(0) tau_0 Delta / t (ln(t/Delta) + 1).
pub fn tamsd_asymptotic(d0: f64, tau0: f64, t: f64, delta: f64) -> f64 {
    6.0 * d0 * tau0 * delta / t * ((t / delta).ln() + 1.0)
}

/// TAMSD (27) of species `k` at lags `deltas`, for a start in the HCS at temperatures `t0`
/// (D_k(0), tau_v,k(0), tau_0 from (8), (10)-(11), (21)).
pub fn tamsd_hcs_species(
    species: &[Species],
    restitution: &PairRestitution,
    t0: &[f64],
    k: usize,
    t: f64,
    deltas: &[f64],
) -> Vec<f64> {
    let d = diffusion_coefficients(species, t0, restitution)[k];
    let tv = tau_v(species, t0, restitution)[k];
    let tau0 = tau0_with(species, t0, restitution);
    deltas
        .iter()
        .map(|&dl| tamsd_hcs(d, tv, tau0, t, dl))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_hcs_time_scale_gives_no_tamsd() {
        // A heated species (tau_0 or tau_v <= 0) is outside (27): NaN, never a hang.
        assert!(tamsd_hcs(1.0, 1.0, -5.0, 100.0, 3.0).is_nan());
        assert!(tamsd_hcs(1.0, 0.0, 5.0, 100.0, 3.0).is_nan());
        assert!(tamsd_hcs(1.0, 1.0, 5.0, 100.0, 3.0).is_finite());
    }
    use crate::theory::hcs::hcs_temperatures;
    use crate::theory::msd::msd_hcs;

    fn fig5() -> (Vec<Species>, PairRestitution, Vec<f64>) {
        let s = vec![
            Species {
                mass: 1.0,
                diameter: 1.0,
                density: 0.1,
            },
            Species {
                mass: 100.0,
                diameter: 100f64.cbrt(),
                density: 0.0,
            },
        ];
        let r = PairRestitution::Constant(0.5);
        let t = hcs_temperatures(&s, &r, 1.0).unwrap();
        (s, r, t)
    }

    /// Delta -> 0: the TAMSD vanishes like Delta^2 with the time-averaged ballistic prefactor,
    /// TAMSD/Delta^2 -> 3 T_k(0)/m_k tau_0/(t + tau_0) (1e-5 relative at Delta =
    /// 1e-6 min(tau_v, tau_0); the next-order term is -O(Delta/tau_0 + Delta/tau_v)).
    #[test]
    fn small_lag_limit() {
        let (s, r, t0) = fig5();
        let tau0 = tau0_with(&s, &t0, &r);
        let tv = tau_v(&s, &t0, &r);
        let t = 1e4;
        for k in 0..2 {
            let dl = 1e-6 * tv[k].min(tau0);
            let got = tamsd_hcs_species(&s, &r, &t0, k, t, &[dl])[0];
            let want = 3.0 * t0[k] / s[k].mass * tau0 / (t + tau0) * dl * dl;
            eprintln!(
                "species {k}: TAMSD({dl:.3e}) = {got:.6e}, ballistic limit {want:.6e} ({:+.2e})",
                got / want - 1.0
            );
            assert!((got / want - 1.0).abs() < 1e-5, "{got} vs {want}");
            assert!(got < 1e-10 * tamsd_hcs_species(&s, &r, &t0, k, t, &[0.5 * t])[0]);
        }
    }

    /// eps = 1 (no cooling, tau_0 = infinity): the TAMSD equals the MSD (22) at the lag
    /// (ergodic), to 1e-10, for lags from 1e-3 tau_v to 0.9 t.
    #[test]
    fn elastic_tamsd_equals_msd() {
        let s = vec![
            Species {
                mass: 1.0,
                diameter: 1.0,
                density: 0.1,
            },
            Species {
                mass: 100.0,
                diameter: 100f64.cbrt(),
                density: 0.05,
            },
        ];
        let r = PairRestitution::Constant(1.0);
        let t0 = hcs_temperatures(&s, &r, 1.0).unwrap();
        assert!(
            (t0[1] / t0[0] - 1.0).abs() < 1e-14,
            "elastic HCS is equipartition"
        );
        let tau0 = tau0_with(&s, &t0, &r);
        assert!(tau0.is_infinite());
        let d = diffusion_coefficients(&s, &t0, &r);
        let tv = tau_v(&s, &t0, &r);
        let t = 1e5;
        for k in 0..2 {
            for dl in [1e-3 * tv[k], tv[k], 30.0 * tv[k], 0.9 * t] {
                let a = tamsd_hcs(d[k], tv[k], tau0, t, dl);
                let b = msd_hcs(d[k], tv[k], tau0, dl);
                assert!((a / b - 1.0).abs() < 1e-10, "k {k} Delta {dl}: {a} vs {b}");
            }
        }
    }

    /// The stable first term equals the literal (27) where the latter is well conditioned
    /// (1e-9), and the full (27) equals a direct numerical time average of the HCS increment
    /// (1e-9); the first term tends to (28) for tau_0 << Delta << t (1e-5 at tau_0/Delta = 1e-6,
    /// Delta/t = 1e-6).
    #[test]
    fn closed_form_and_time_average() {
        let (d, tv, tau0) = (0.9, 12.0, 11.3);
        for (t, dl) in [(100.0, 10.0), (1e4, 50.0), (1e5, 3e4)] {
            let a = tamsd_first_term(d, tau0, t, dl);
            let b = tamsd_first_term_literal(d, tau0, t, dl);
            assert!((a / b - 1.0).abs() < 1e-9, "{a} {b}");
            let beta = tau0 / tv;
            let inc = |x: f64| {
                6.0 * d * tau0 * ((x + dl + tau0) / (x + tau0)).ln()
                    + 6.0 * d * tv * ((1.0 + dl / (x + tau0)).powf(-beta) - 1.0)
            };
            let avg = graded_integral(inc, 0.0, t - dl, 0.1) / (t - dl);
            let full = tamsd_hcs(d, tv, tau0, t, dl);
            assert!((full / avg - 1.0).abs() < 1e-9, "{full} vs {avg}");
        }
        // (28) is the asymptote of the first term <delta_0^2> (as the paper states); Xi cancels
        // its logarithm (late increments are ballistic), so the full (27) is much smaller.
        let (t, dl, tau0) = (1e12, 1e6, 1.0);
        let ratio = tamsd_first_term(d, tau0, t, dl) / tamsd_asymptotic(d, tau0, t, dl);
        let full = tamsd_hcs(d, 0.5, tau0, t, dl) / tamsd_asymptotic(d, tau0, t, dl);
        eprintln!("tau0 = 1, Delta = 1e6, t = 1e12: <delta_0^2>/(28) = {ratio:.8}, full (27)/(28) = {full:.4e}");
        assert!((ratio - 1.0).abs() < 1e-5, "{ratio}");
    }
}
