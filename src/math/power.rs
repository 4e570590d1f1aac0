//! Power laws over a window of x: y = A x^-exponent (a decay, e.g. a structure factor
//! S(k) = A k^-D_f) or y = A x^exponent (a growth, e.g. a cumulative count C(R)), fitted by
//! [`fit::power_law`] on the positive values in the window, weighted by the errors when every
//! value there has one.

use crate::math::fit::{self, Fit};

/// One (x, y) value with its error, if any.
#[derive(Clone, Copy, Debug)]
pub struct Sample {
    pub x: f64,
    pub y: f64,
    pub err: Option<f64>,
}

/// A power-law exponent fit y = A x^(+-exponent) over a window.
#[derive(Clone, Debug)]
pub struct PowerFit {
    pub exponent: f64,
    pub error: f64,
    pub ln_amplitude: f64,
    pub fit: Fit,
    pub x_lo: f64,
    pub x_hi: f64,
}

fn power_fit(x: &[f64], y: &[f64], err: &[Option<f64>], sign: f64) -> Option<PowerFit> {
    if x.len() < 2 {
        return None;
    }
    let sig = fit::usable(err);
    let f = fit::power_law(x, y, sig.as_deref())?;
    Some(PowerFit {
        exponent: sign * f.params[1],
        error: f.errors[1],
        ln_amplitude: f.params[0],
        x_lo: x.iter().copied().fold(f64::INFINITY, f64::min),
        x_hi: x.iter().copied().fold(0.0, f64::max),
        fit: f,
    })
}

/// y = A x^-exponent fitted over x_lo <= x < x_hi (positive y only). `None` with fewer than
/// two values there.
pub fn decay_exponent(points: &[Sample], x_lo: f64, x_hi: f64) -> Option<PowerFit> {
    let w: Vec<&Sample> = points
        .iter()
        .filter(|p| p.x >= x_lo && p.x < x_hi && p.y > 0.0)
        .collect();
    let x: Vec<f64> = w.iter().map(|p| p.x).collect();
    let y: Vec<f64> = w.iter().map(|p| p.y).collect();
    let e: Vec<Option<f64>> = w.iter().map(|p| p.err).collect();
    power_fit(&x, &y, &e, -1.0)
}

/// y = A x^exponent over x_lo <= x <= x_hi (positive y only). `None` with fewer than two
/// values there.
pub fn growth_exponent(
    x: &[f64],
    y: &[f64],
    err: &[Option<f64>],
    x_lo: f64,
    x_hi: f64,
) -> Option<PowerFit> {
    let idx: Vec<usize> = (0..x.len())
        .filter(|&i| x[i] >= x_lo && x[i] <= x_hi && y[i] > 0.0)
        .collect();
    power_fit(
        &idx.iter().map(|&i| x[i]).collect::<Vec<_>>(),
        &idx.iter().map(|&i| y[i]).collect::<Vec<_>>(),
        &idx.iter().map(|&i| err[i]).collect::<Vec<_>>(),
        1.0,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cumulative_count_exponent() {
        let r: Vec<f64> = (1..100).map(|j| 1e-3 * j as f64).collect();
        let c: Vec<f64> = r.iter().map(|r| 3.0 * r.powf(1.6)).collect();
        let f = growth_exponent(&r, &c, &vec![None; r.len()], 0.0095, 0.0505).unwrap();
        assert!((f.exponent - 1.6).abs() < 1e-9);
        assert_eq!(f.fit.n_points, 41);
    }
}
