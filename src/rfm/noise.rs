//! The random force (spec 1.3): per step and particle a velocity kick with independent
//! N(0, 2 D h / M^2) components (the impulse eta h of (2.16)/(2.23) divided by M), made
//! symmetric so that the kicks of a step sum to zero in every component (2.18); total
//! momentum then stays at its initial value (zero) up to round-off, in 1D and in 2D
//! (spec 6.9).
//!
//! Normals come in bulk from the run's ChaCha8 stream ([`crate::rng::RunRng`]) by the
//! ziggurat method (exact: a ziggurat sample is an exact normal up to the rounding of its
//! 53-bit uniform). A step draws all its normals at once, so the stream position between
//! steps is a function of the step count alone (checkpoints restore it exactly).

use crate::rng::RunRng;

/// Fill `out` with independent standard normals.
#[inline]
pub fn fill_normals(rng: &mut RunRng, out: &mut [f64]) {
    for z in out.iter_mut() {
        *z = rng.normal();
    }
}

/// Generates the symmetrised kicks of one step.
pub struct Kicks {
    /// Standard deviation sqrt(2 D h) / M of one component.
    pub sigma: f64,
    buf: Vec<f64>,
}

impl Kicks {
    pub fn new(noise_strength: f64, mass: f64, h: f64) -> Self {
        Kicks {
            sigma: (2.0 * noise_strength * h).sqrt() / mass,
            buf: Vec::new(),
        }
    }

    /// Whether the model has noise at all.
    pub fn active(&self) -> bool {
        self.sigma > 0.0
    }

    /// Add one step's symmetrised kicks to the velocities `v` (N particles of D components);
    /// the normals are drawn particle by particle, components innermost.
    pub fn apply<const D: usize>(&mut self, rng: &mut RunRng, v: &mut [[f64; D]]) {
        let n = v.len();
        self.buf.resize(n * D, 0.0);
        fill_normals(rng, &mut self.buf);
        let mut mean = [0.0; D];
        for (i, _) in v.iter().enumerate() {
            for k in 0..D {
                mean[k] += self.buf[i * D + k];
            }
        }
        let mut shift = [0.0; D];
        for k in 0..D {
            shift[k] = mean[k] / n as f64;
        }
        let s = self.sigma;
        for (vi, z) in v.iter_mut().zip(self.buf.chunks_exact(D)) {
            for k in 0..D {
                vi[k] += s * (z[k] - shift[k]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mean, variance and fourth moment of 1e6 bulk normals within 5 standard errors
    /// (SE: 1e-3, 1.41e-3 and 9.8e-3 for 3).
    #[test]
    fn bulk_normals_have_normal_moments() {
        let mut rng = RunRng::new(5);
        let mut b = vec![0.0; 1_000_000];
        fill_normals(&mut rng, &mut b);
        let n = b.len() as f64;
        let m1 = b.iter().sum::<f64>() / n;
        let m2 = b.iter().map(|z| z * z).sum::<f64>() / n;
        let m4 = b.iter().map(|z| z.powi(4)).sum::<f64>() / n;
        assert!(m1.abs() < 5e-3, "{m1}");
        assert!((m2 - 1.0).abs() < 5.0 * 1.414e-3, "{m2}");
        assert!((m4 - 3.0).abs() < 5.0 * 9.8e-3, "{m4}");
        // Tail: P(|z| > 3) = 2.6998e-3, SE 5.2e-5.
        let tail = b.iter().filter(|z| z.abs() > 3.0).count() as f64 / n;
        assert!((tail - 2.6998e-3).abs() < 5.0 * 5.2e-5, "{tail}");
    }
}
