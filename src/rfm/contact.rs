//! The contact law of two identical discs (spec 1.4): linear spring-dashpot in the normal
//! direction, a tangential dashpot when eps_t < 1, and an optional Coulomb cap mu.
//!
//! Conventions: `r = x_i - x_j` (minimum image), `rho = |r|`, `e = r / rho` (unit vector from
//! j to i), overlap `delta = d - rho`, relative velocity `g = v_i - v_j`, overlap rate
//! `u = d delta / dt = -(g . e)`. The force on i is `(k_s delta + gamma_n u) e`
//! (= (2.4) + (2.5)) plus `-gamma_t g_t` with `g_t = g - (g . e) e` (2.9), both only while
//! `delta > 0`; j receives the opposite force. So the overlap obeys the damped oscillator
//! `m_12 delta'' = -k_s delta - gamma_n delta'`, which [`crate::rfm::integrate`] solves
//! exactly over each step; [`force_on_i`] is the instantaneous law, used by tests and as the
//! reference definition.

/// Contact-law constants of identical particles.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactLaw {
    pub diameter: f64,
    pub spring: f64,
    pub gamma_n: f64,
    pub gamma_t: f64,
    /// Coulomb coefficient: |F_t| <= mu |F_n|.
    pub friction: Option<f64>,
}

impl ContactLaw {
    pub fn from_config(c: &super::RfmConfig) -> Self {
        ContactLaw {
            diameter: c.diameter(),
            spring: c.spring_constant,
            gamma_n: c.gamma_n(),
            gamma_t: if c.dim == 2 { c.gamma_t() } else { 0.0 },
            friction: c.friction,
        }
    }

    /// Whether a contact has any tangential force (a dashpot or sliding friction).
    pub fn tangential(&self) -> bool {
        self.gamma_t > 0.0 || self.friction.is_some_and(|mu| mu > 0.0)
    }
}

/// The instantaneous contact force on i (zero when `rho >= d`). With `friction` set the
/// tangential force is the dashpot's, capped at mu |F_n|; with `gamma_t = 0` and mu set it is
/// sliding friction `-mu |F_n| g_t/|g_t|` (2.7).
pub fn force_on_i<const D: usize>(law: &ContactLaw, r: [f64; D], g: [f64; D]) -> [f64; D] {
    let rho = r.iter().map(|a| a * a).sum::<f64>().sqrt();
    let mut f = [0.0; D];
    if rho >= law.diameter {
        return f;
    }
    let e: [f64; D] = std::array::from_fn(|k| r[k] / rho);
    let gn = (0..D).map(|k| g[k] * e[k]).sum::<f64>();
    let fn_ = law.spring * (law.diameter - rho) - law.gamma_n * gn;
    let gt: [f64; D] = std::array::from_fn(|k| g[k] - gn * e[k]);
    let gt_abs = gt.iter().map(|a| a * a).sum::<f64>().sqrt();
    let mut ft_scale = -law.gamma_t; // F_t = ft_scale * g_t
    if let Some(mu) = law.friction {
        if gt_abs > 0.0 {
            let cap = mu * fn_.abs() / gt_abs;
            ft_scale = if law.gamma_t > 0.0 {
                ft_scale.max(-cap)
            } else {
                -cap
            };
        }
    }
    for k in 0..D {
        f[k] = fn_ * e[k] + ft_scale * gt[k];
    }
    f
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Signs and magnitudes of the force law (exact arithmetic up to 1e-12 relative).
    #[test]
    fn force_law_signs() {
        let law = ContactLaw {
            diameter: 1.0,
            spring: 10.0,
            gamma_n: 2.0,
            gamma_t: 1.0,
            friction: None,
        };
        // i at +x of j, overlapping by 0.1, approaching (g = -1 along e): repulsive + damping.
        let f = force_on_i(&law, [0.9, 0.0], [-1.0, 0.5]);
        assert!((f[0] - (10.0 * 0.1 + 2.0)).abs() < 1e-12);
        assert!((f[1] + 0.5).abs() < 1e-12);
        assert_eq!(force_on_i(&law, [1.0, 0.0], [-1.0, 0.5]), [0.0, 0.0]);
        let capped = ContactLaw {
            friction: Some(0.1),
            ..law
        };
        let f = force_on_i(&capped, [0.9, 0.0], [-1.0, 0.5]);
        assert!((f[1] + 0.1 * 3.0).abs() < 1e-12);
    }
}
