//! 2D structure of the RFM (thesis ch. 4, spec 2.7-2.8): the window of the fractal-dimension
//! fit of S(k) = A k^-D_f (4.4) over the dissipative range, by the k_D / L_Eff rule
//! (4.5)-(4.9), and the mean-field count n_bar of n(R) = C(R) - n_bar ~ R^D_f (4.17). The power
//! laws themselves are fitted by `math::power`.

use std::f64::consts::PI;

/// k_D (4.5) with l_0 from (4.7): (2 - eps_n^2 - eps_t^2) phi / (pi d). (The /8 form of the
/// thesis's tables, spec 6.18.)
pub fn k_dissipative(eps_n: f64, eps_t: f64, phi: f64, d: f64) -> f64 {
    (2.0 - eps_n * eps_n - eps_t * eps_t) * phi / (PI * d)
}

/// L_min = 2 pi / k_D (4.6).
pub fn l_min(k_d: f64) -> f64 {
    2.0 * PI / k_d
}

/// L_Eff = 2 sqrt 2 L_min (4.9): the five lowest shells lie below k_D.
pub fn l_eff(k_d: f64) -> f64 {
    2.0 * std::f64::consts::SQRT_2 * l_min(k_d)
}

/// The upper end k' of the D_f fit (sec. 4.1.2-4.1.4): k_D if L > L_Eff, else 2 k_D.
pub fn fit_cutoff(k_d: f64, box_length: f64) -> (f64, &'static str) {
    if box_length > l_eff(k_d) {
        (k_d, "k < k_D (L > L_Eff)")
    } else {
        (2.0 * k_d, "k < 2 k_D (L <= L_Eff)")
    }
}

/// The mean-field count n_bar = (N - 1) pi R^2 / L^2 (spec 2.8 [REC]).
pub fn mean_field_count(r: f64, n: f64, box_length: f64) -> f64 {
    (n - 1.0) * PI * r * r / (box_length * box_length)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::fit::tests::sd;
    use crate::math::power::{decay_exponent, Sample};
    use crate::rng::RunRng;

    #[test]
    fn window_rule_matches_thesis_tables() {
        // T 4.1 (eps = 0.1): phi = 0.530 -> k_D d = 0.334, L_Eff = 0.16; phi = 0.177 ->
        // 0.112, 0.48 (printed truncated).
        let d = 3e-3;
        let kd = k_dissipative(0.1, 0.1, 0.530, d);
        assert!((kd * d - 0.334).abs() < 5e-4);
        assert!((l_eff(kd) - 0.16).abs() < 0.01);
        assert_eq!(fit_cutoff(kd, 0.2).0, kd);
        let kd = k_dissipative(0.1, 0.1, 0.177, d);
        assert!((kd * d - 0.112).abs() < 5e-4);
        assert!((l_eff(kd) - 0.48).abs() < 0.01);
        assert_eq!(fit_cutoff(kd, 0.4).0, 2.0 * kd);
        // T 4.2 eps_n = 0.4, eps_t = 1: 0.142, 0.37.
        let kd = k_dissipative(0.4, 1.0, 0.530, d);
        assert!((kd * d - 0.142).abs() < 5e-4);
        assert!((l_eff(kd) - 0.37).abs() < 0.01);
    }

    /// S(k) = A k^-1.63 on the lattice shells of L = 0.2 with 5 % noise plus the
    /// elastic/contact range above k_D that the window must exclude.
    #[test]
    fn df_from_synthetic_structure_factor() {
        let (l, d) = (0.2, 3e-3);
        let kd = k_dissipative(0.1, 0.1, 0.530, d);
        let mut shells: Vec<i64> = (0..30)
            .flat_map(|a: i64| (0..30).map(move |b: i64| a * a + b * b))
            .filter(|&s| s > 0 && s < 400)
            .collect();
        shells.sort_unstable();
        shells.dedup();
        let (mut est, mut errs) = (vec![], vec![]);
        for seed in 0..300 {
            let mut rng = RunRng::new(31 + seed);
            let pts: Vec<Sample> = shells
                .iter()
                .map(|&s| {
                    let k = 2.0 * PI / l * (s as f64).sqrt();
                    let t = if k < kd { 0.05 * k.powf(-1.63) } else { 1.0 };
                    Sample {
                        x: k,
                        y: t * (1.0 + 0.05 * rng.normal()),
                        err: Some(0.05 * t),
                    }
                })
                .collect();
            let (kp, _) = fit_cutoff(kd, l);
            let f = decay_exponent(&pts, 0.0, kp).unwrap();
            assert_eq!(f.fit.n_points, 7, "shells 1, 2, 4, 5, 8, 9, 10 below k_D");
            est.push(f.exponent);
            errs.push(f.error);
        }
        let mean = est.iter().sum::<f64>() / est.len() as f64;
        let err = errs.iter().sum::<f64>() / errs.len() as f64;
        assert!(
            (mean - 1.63).abs() < 4.0 * err / (est.len() as f64).sqrt(),
            "{mean}"
        );
        assert!((sd(&est) / err - 1.0).abs() < 0.2);
    }

    #[test]
    fn mean_field_count_is_the_ideal_gas_count() {
        // The count of the exponent is in `math::power` (`cumulative_count_exponent`).
        assert!((mean_field_count(1.0, 101.0, 10.0) - PI).abs() < 1e-12);
    }
}
