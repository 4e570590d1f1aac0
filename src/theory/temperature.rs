//! Species cooling rates (14-15) and the homogeneous cooling state's tau_0 (21), for
//! constant restitution and g2 = 1.

/// One species as the theory sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Species {
    pub mass: f64,
    pub diameter: f64,
    /// Number density n_k.
    pub density: f64,
}

/// xi_ki of (15): the cooling of species k by collisions with species i.
pub fn xi_pair(k: &Species, tk: f64, i: &Species, ti: f64, eps: f64) -> f64 {
    let sigma = 0.5 * (k.diameter + i.diameter);
    let (mk, mi) = (k.mass, i.mass);
    let root = ((tk * mi + ti * mk) / (mi * mk)).sqrt();
    8.0 / 3.0 * (2.0 * std::f64::consts::PI).sqrt() * i.density * sigma * sigma * root * (1.0 + eps) * (mi / (mi + mk))
        * (1.0 - 0.5 * (1.0 + eps) * (ti * mk + tk * mi) / (tk * (mi + mk)))
}

/// xi_k of (14) for every species at temperatures `t`.
pub fn cooling_rates(species: &[Species], t: &[f64], eps: f64) -> Vec<f64> {
    (0..species.len())
        .map(|k| (0..species.len()).map(|i| xi_pair(&species[k], t[k], &species[i], t[i], eps)).sum())
        .collect()
}

/// tau_0 of (21), 2 / xi_k(0), for a start in the homogeneous cooling state (all xi_k equal;
/// the number-weighted mean of the xi_k is used, which is exact there).
pub fn tau0(species: &[Species], t0: &[f64], eps: f64) -> f64 {
    let xi = cooling_rates(species, t0, eps);
    let n: f64 = species.iter().map(|s| s.density).sum();
    let mean: f64 = species.iter().zip(&xi).map(|(s, x)| s.density * x).sum::<f64>() / n;
    2.0 / mean
}

/// Haff's law (17): T(t) / T(0) = (1 + t/tau_0)^-2.
pub fn haff(t: f64, tau0: f64) -> f64 {
    (1.0 + t / tau0).powi(-2)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One species: xi = (4/3) sqrt(pi) n sigma^2 sqrt(T/m) (1 - eps^2), the textbook value.
    #[test]
    fn single_species_cooling_rate() {
        let s = Species { mass: 2.0, diameter: 1.5, density: 0.1 };
        let (t, eps) = (3.0, 0.7);
        let want = 4.0 / 3.0 * std::f64::consts::PI.sqrt() * 0.1 * 1.5 * 1.5 * (t / 2.0f64).sqrt() * (1.0 - eps * eps);
        let got = cooling_rates(&[s], &[t], eps)[0];
        assert!((got - want).abs() < 1e-12 * want, "{got} vs {want}");
    }

    /// The paper's Fig 2 mixture at its printed HCS temperatures has tau_0 = 19.258.
    #[test]
    fn fig2_tau0() {
        let s1 = Species { mass: 1.0, diameter: 1.0, density: 0.1 };
        let s2 = Species { mass: 100.0, diameter: 100f64.cbrt(), density: 0.001 };
        let xi = cooling_rates(&[s1, s2], &[0.554, 45.58755], 0.5);
        // In the HCS both species cool at the same rate (to the printed digits).
        assert!((xi[0] - xi[1]).abs() < 2e-3 * xi[0], "{xi:?}");
        let tau = 2.0 / xi[0];
        assert!((tau - 19.258).abs() < 0.02, "{tau}");
    }
}
