//! Small least-squares fits shared by the auxiliary models.

/// Weighted least squares of y = a + b x (weights w = 1/sigma^2). Returns
/// `(a, b, sigma_a, sigma_b, chi2_reduced)`; the sigmas are the formal ones (not rescaled by
/// chi^2). None with fewer than 3 points or a degenerate design.
pub fn wls_line(x: &[f64], y: &[f64], w: &[f64]) -> Option<(f64, f64, f64, f64, f64)> {
    let n = x.len();
    if n < 3 {
        return None;
    }
    let (mut s, mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for i in 0..n {
        s += w[i];
        sx += w[i] * x[i];
        sy += w[i] * y[i];
        sxx += w[i] * x[i] * x[i];
        sxy += w[i] * x[i] * y[i];
    }
    let det = s * sxx - sx * sx;
    if !(det > 0.0) || !det.is_finite() {
        return None;
    }
    let a = (sxx * sy - sx * sxy) / det;
    let b = (s * sxy - sx * sy) / det;
    let chi2: f64 = (0..n).map(|i| w[i] * (y[i] - a - b * x[i]).powi(2)).sum();
    Some((
        a,
        b,
        (sxx / det).sqrt(),
        (s / det).sqrt(),
        chi2 / (n as f64 - 2.0),
    ))
}

/// Stretched exponential ln P = a - K |v|^alpha fitted by a scan of alpha (step 0.001 over
/// [alpha_lo, alpha_hi]) with a weighted linear fit of (a, K) at each alpha; returns
/// `(alpha, K, chi2_reduced)` at the smallest chi^2.
pub fn stretched_exponential(
    v: &[f64],
    ln_p: &[f64],
    w: &[f64],
    alpha_lo: f64,
    alpha_hi: f64,
) -> Option<(f64, f64, f64)> {
    let steps = ((alpha_hi - alpha_lo) / 1e-3).round() as usize;
    let mut best: Option<(f64, f64, f64)> = None;
    let mut xs = vec![0.0; v.len()];
    for s in 0..=steps {
        let alpha = alpha_lo + s as f64 * 1e-3;
        for (x, vi) in xs.iter_mut().zip(v) {
            *x = vi.abs().powf(alpha);
        }
        if let Some((_, b, _, _, chi2)) = wls_line(&xs, ln_p, w) {
            if best.is_none_or(|bb| chi2 < bb.2) {
                best = Some((alpha, -b, chi2));
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_recovers_slope_and_stretched_exponent() {
        let x: Vec<f64> = (0..20).map(|i| i as f64 * 0.1).collect();
        let y: Vec<f64> = x.iter().map(|x| 2.0 - 1.5 * x).collect();
        let w = vec![1.0; x.len()];
        let (a, b, _, _, chi2) = wls_line(&x, &y, &w).unwrap();
        assert!((a - 2.0).abs() < 1e-12 && (b + 1.5).abs() < 1e-12 && chi2 < 1e-20);
        let v: Vec<f64> = (1..40).map(|i| i as f64 * 0.05).collect();
        let lp: Vec<f64> = v.iter().map(|v| 0.3 - 4.0 * v.powf(1.2)).collect();
        let (alpha, k, _) = stretched_exponential(&v, &lp, &vec![1.0; v.len()], 0.5, 2.0).unwrap();
        assert!(
            (alpha - 1.2).abs() < 1.5e-3 && (k - 4.0).abs() < 0.02,
            "{alpha} {k}"
        );
    }
}
