//! Velocity correlation times and diffusion coefficients (section II.A): the mean collision
//! time tau_c (7), tau_v,k = (sum_i tau_v,ki^-1)^-1 (10) with (11) (or its velocity-dependent
//! generalisation, see [`super::restitution`]), the HCS form (24), and D_k = T_k tau_v,k / m_k
//! (8). g2 = 1.

use super::restitution::{pair_rates, PairRestitution};
use super::species::Species;
use std::f64::consts::PI;

/// tau_c (7): 1 / (4 n_1 sigma_1^2 sqrt(pi T_1 / m_1)) of the reference species `s1` at
/// temperature `t1`.
pub fn tau_c(s1: &Species, t1: f64) -> f64 {
    1.0 / (4.0 * s1.density * s1.diameter * s1.diameter * (PI * t1 / s1.mass).sqrt())
}

/// tau_v,ki^-1 (11) for every pair: `result[k][i]`.
pub fn tau_v_inv_pairs(species: &[Species], t: &[f64], r: &PairRestitution) -> Vec<Vec<f64>> {
    let m = species.len();
    (0..m)
        .map(|k| {
            (0..m)
                .map(|i| pair_rates(&species[k], k, t[k], &species[i], i, t[i], r).tau_v_inv)
                .collect()
        })
        .collect()
}

/// tau_v,k (10)-(11) of every species at temperatures `t`.
pub fn tau_v(species: &[Species], t: &[f64], r: &PairRestitution) -> Vec<f64> {
    tau_v_inv_pairs(species, t, r)
        .iter()
        .map(|row| 1.0 / row.iter().sum::<f64>())
        .collect()
}

/// tau_v,k(0) by the paper's HCS form (24) (constant eps_ki), literally transcribed:
/// tau_v,k^-1 = (2 sqrt(2 pi T_k)/3) sum_i n_i sigma_ki^2 m_i/sqrt(m_i m_k)
/// (m_i + gamma_ik m_k)^(3/2)/(m_i + m_k)^2 (1 + eps_ki)^2, gamma_ik = T_i/T_k.
pub fn tau_v_24(species: &[Species], t: &[f64], r: &PairRestitution) -> Vec<f64> {
    let m = species.len();
    (0..m)
        .map(|k| {
            let s: f64 = (0..m)
                .map(|i| {
                    let e = r.constant(k, i).expect("(24) needs constant restitution");
                    let (sk, si) = (&species[k], &species[i]);
                    let (mk, mi) = (sk.mass, si.mass);
                    let g = t[i] / t[k];
                    let sig = 0.5 * (sk.diameter + si.diameter);
                    si.density * sig * sig * mi / (mi * mk).sqrt() * (mi + g * mk).powf(1.5)
                        / ((mi + mk) * (mi + mk))
                        * (1.0 + e)
                        * (1.0 + e)
                })
                .sum();
            1.0 / (2.0 * (2.0 * PI * t[k]).sqrt() / 3.0 * s)
        })
        .collect()
}

/// D_k (8) = T_k tau_v,k / m_k at temperatures `t`.
pub fn diffusion_coefficients(species: &[Species], t: &[f64], r: &PairRestitution) -> Vec<f64> {
    tau_v(species, t, r)
        .iter()
        .zip(species)
        .zip(t)
        .map(|((tv, s), tk)| tk * tv / s.mass)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::theory::hcs::hcs_temperatures;

    /// (24) equals (10)-(11) at the HCS of the Fig 3 mixture (1e-13); one species: tau_v =
    /// 6 tau_c/(1+eps)^2 (30) (1e-14).
    #[test]
    fn tau_v_forms_agree() {
        let s: Vec<Species> = [1.0, 100.0, 500.0]
            .iter()
            .map(|&m: &f64| Species {
                mass: m,
                diameter: m.cbrt(),
                density: 0.1,
            })
            .collect();
        let r = PairRestitution::Constant(0.5);
        let t = hcs_temperatures(&s, &r, 1.0).unwrap();
        let a = tau_v(&s, &t, &r);
        let b = tau_v_24(&s, &t, &r);
        for k in 0..3 {
            assert!((a[k] / b[k] - 1.0).abs() < 1e-13, "{a:?} {b:?}");
        }
        let one = [Species {
            mass: 2.0,
            diameter: 1.3,
            density: 0.2,
        }];
        let tv = tau_v(&one, &[0.7], &PairRestitution::Constant(0.8))[0];
        let want = 6.0 * tau_c(&one[0], 0.7) / (1.8 * 1.8);
        assert!((tv / want - 1.0).abs() < 1e-14);
    }
}
