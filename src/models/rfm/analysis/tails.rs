//! Velocity tails (thesis App. A.3, ch. 5, spec 2.3-2.5): the accepted-alpha window of the
//! stretched-exponential fit A_0 exp(-B_0 |v|^alpha) to histogram counts (A.7)-(A.8), the
//! crossover function (5.32) with v_r and v_c, and the "Moon plot" (5.6).
//!
//! Histograms are of signed velocity components; they are folded to |v| (the 1D thesis
//! histograms are of |v|, spec 6.12; in 2D both components are pooled and folded [REC]).

use crate::math::fit::{self, Fit};

/// One bin of a folded histogram: |v| at the bin centre, its count and width.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FoldedBin {
    pub v: f64,
    pub count: f64,
    pub width: f64,
}

/// Fold signed bins (lo, hi, count) to |v|: bins whose |centre| agree within a quarter bin
/// width are merged (a symmetric range pairs every bin with its mirror). Bins with infinite
/// edges (the out-of-range rows) are dropped.
pub fn fold(bins: &[(f64, f64, f64)]) -> Vec<FoldedBin> {
    let mut b: Vec<FoldedBin> = bins
        .iter()
        .filter(|(lo, hi, _)| lo.is_finite() && hi.is_finite() && hi > lo)
        .map(|&(lo, hi, c)| FoldedBin {
            v: (0.5 * (lo + hi)).abs(),
            count: c,
            width: hi - lo,
        })
        .collect();
    b.sort_by(|x, y| x.v.total_cmp(&y.v));
    let mut out: Vec<FoldedBin> = Vec::with_capacity(b.len());
    for x in b {
        match out.last_mut() {
            Some(l) if (x.v - l.v).abs() < 0.25 * x.width.min(l.width) => l.count += x.count,
            _ => out.push(x),
        }
    }
    out
}

/// Settings of the accepted-alpha procedure.
#[derive(Clone, Copy, Debug)]
pub struct AlphaRule {
    /// Bins with count_lo <= X <= count_hi: 1D (A.3) 50..5000, 2D (5.1.1) 50..50000.
    pub count_lo: f64,
    pub count_hi: f64,
    /// s_i = factor sqrt(X_i): 1 (2 for the thesis's dagger entries).
    pub factor: f64,
    /// Accept alpha if chi_r^2 < chi2_max (1.2).
    pub chi2_max: f64,
    /// The alpha grid: from, to, step.
    pub grid: (f64, f64, f64),
}

impl AlphaRule {
    pub fn thesis(dim: u32) -> Self {
        AlphaRule {
            count_lo: 50.0,
            count_hi: if dim == 1 { 5000.0 } else { 50000.0 },
            factor: 1.0,
            chi2_max: 1.2,
            grid: (0.3, 2.5, 0.01),
        }
    }
}

/// The outcome of the alpha scan.
#[derive(Clone, Debug)]
pub struct AlphaWindow {
    /// Smallest and largest accepted alpha (`None`: no alpha reached chi_r^2 < chi2_max).
    pub accepted: Option<(f64, f64)>,
    pub best_alpha: f64,
    pub best_chi2_reduced: f64,
    pub n_bins: usize,
    /// |v| range of the bins used.
    pub v_lo: f64,
    pub v_hi: f64,
}

impl AlphaWindow {
    /// The thesis's "centre +- half-width" of the accepted range (half a grid step when one
    /// alpha is accepted).
    pub fn centre_half_width(&self, step: f64) -> Option<(f64, f64)> {
        self.accepted
            .map(|(a, b)| (0.5 * (a + b), (0.5 * (b - a)).max(0.5 * step)))
    }
}

/// The tail bins of the procedure: beyond the histogram's maximum, with counts in the window.
pub fn tail_bins(folded: &[FoldedBin], count_lo: f64, count_hi: f64) -> Vec<FoldedBin> {
    let Some(peak) = folded
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.count.total_cmp(&b.1.count))
        .map(|x| x.0)
    else {
        return Vec::new();
    };
    folded[peak..]
        .iter()
        .filter(|b| b.count >= count_lo && b.count <= count_hi)
        .copied()
        .collect()
}

/// Scan alpha over the grid, fitting A_0, B_0 for each (chi^2 on counts), and report the
/// accepted range. `None` with fewer than 4 tail bins.
pub fn alpha_window(folded: &[FoldedBin], rule: &AlphaRule) -> Option<AlphaWindow> {
    let tail = tail_bins(folded, rule.count_lo, rule.count_hi);
    if tail.len() < 4 {
        return None;
    }
    let v: Vec<f64> = tail.iter().map(|b| b.v).collect();
    let c: Vec<f64> = tail.iter().map(|b| b.count).collect();
    let (from, to, step) = rule.grid;
    let n_steps = ((to - from) / step).round() as usize;
    let mut best = (f64::NAN, f64::INFINITY);
    let mut accepted: Option<(f64, f64)> = None;
    for j in 0..=n_steps {
        let alpha = from + j as f64 * step;
        let Some(f) = fit::stretched_exp_counts(&v, &c, alpha, rule.factor) else {
            continue;
        };
        let chi = f.chi2_reduced.unwrap_or(f64::INFINITY);
        if chi < best.1 {
            best = (alpha, chi);
        }
        if chi < rule.chi2_max {
            accepted = Some(accepted.map_or((alpha, alpha), |(a, _)| (a, alpha)));
        }
    }
    if !best.1.is_finite() {
        return None;
    }
    Some(AlphaWindow {
        accepted,
        best_alpha: best.0,
        best_chi2_reduced: best.1,
        n_bins: tail.len(),
        v_lo: v[0],
        v_hi: v[v.len() - 1],
    })
}

/// The fit of A_0 exp(-B_0 |v|^alpha) to the tail bins at a given alpha (e.g. alpha = 1 for
/// the asymptotic amplitude A_0 of the Moon plot).
pub fn tail_fit(folded: &[FoldedBin], rule: &AlphaRule, alpha: f64) -> Option<Fit> {
    let tail = tail_bins(folded, rule.count_lo, rule.count_hi);
    if tail.len() < 3 {
        return None;
    }
    let v: Vec<f64> = tail.iter().map(|b| b.v).collect();
    let c: Vec<f64> = tail.iter().map(|b| b.count).collect();
    fit::stretched_exp_counts(&v, &c, alpha, rule.factor)
}

/// rms of the velocity component from the folded histogram (bin centres).
pub fn v_rms(folded: &[FoldedBin]) -> f64 {
    let n: f64 = folded.iter().map(|b| b.count).sum();
    (folded.iter().map(|b| b.count * b.v * b.v).sum::<f64>() / n).sqrt()
}

/// Density of one signed component at the folded bins: count / (2 N_total width) (both
/// signs folded into one bin; `total` counts every signed value including out-of-range ones).
pub fn density(b: &FoldedBin, total: f64) -> f64 {
    b.count / (2.0 * total * b.width)
}

/// The crossover function (5.32) with alpha = 1: ln P = ln A - (v/v_r)^2 / (1 + |v/v_c|).
pub fn crossover_ln(p: &[f64], v: f64) -> f64 {
    p[0] - (v / p[1]).powi(2) / (1.0 + (v / p[2]).abs())
}

/// Fitted (5.32): A, v_r, v_c with errors.
#[derive(Clone, Debug)]
pub struct Crossover {
    pub fit: Fit,
}

impl Crossover {
    pub fn v_r(&self) -> (f64, f64) {
        (self.fit.params[1].abs(), self.fit.errors[1])
    }
    pub fn v_c(&self) -> (f64, f64) {
        (self.fit.params[2].abs(), self.fit.errors[2])
    }
    /// P(v_c)/P(0) = exp(-(v_c/v_r)^2 / 2).
    pub fn ratio_at_v_c(&self) -> f64 {
        let (r, c) = (self.v_r().0, self.v_c().0);
        (-(c / r).powi(2) / 2.0).exp()
    }
}

/// Fit (5.32) to the whole folded P(v): least squares on ln P (spec 2.5 [REC]) with
/// sigma_ln P = 1/sqrt(X) over the bins with X >= `min_count`.
pub fn crossover_fit(folded: &[FoldedBin], total: f64, min_count: f64) -> Option<Crossover> {
    let used: Vec<&FoldedBin> = folded.iter().filter(|b| b.count >= min_count).collect();
    if used.len() < 5 {
        return None;
    }
    let v: Vec<f64> = used.iter().map(|b| b.v).collect();
    let lp: Vec<f64> = used.iter().map(|b| density(b, total).ln()).collect();
    let s: Vec<f64> = used.iter().map(|b| 1.0 / b.count.sqrt()).collect();
    let rms = v_rms(folded);
    let p0 = [lp[0], std::f64::consts::SQRT_2 * rms, 2.0 * rms];
    let f = fit::levenberg_marquardt(&crossover_ln, &v, &lp, Some(&s), &p0)?;
    Some(Crossover { fit: f })
}

/// One Moon-plot point (5.6): x = ln(v/v_rms), y = -ln(-ln(P/P')), with its error from the
/// counts (sigma_y = 1/(sqrt(X) |ln(P/P')|)).
#[derive(Clone, Copy, Debug)]
pub struct MoonPoint {
    pub x: f64,
    pub y: f64,
    pub err: f64,
}

/// Moon-plot points of the bins with 0 < P < P' and X >= `min_count`.
pub fn moon_points(
    folded: &[FoldedBin],
    total: f64,
    v_rms: f64,
    p_ref: f64,
    min_count: f64,
) -> Vec<MoonPoint> {
    folded
        .iter()
        .filter(|b| b.count >= min_count && b.v > 0.0)
        .filter_map(|b| {
            let p = density(b, total);
            let l = -(p / p_ref).ln();
            (l > 0.0).then(|| MoonPoint {
                x: (b.v / v_rms).ln(),
                y: -l.ln(),
                err: 1.0 / (b.count.sqrt() * l),
            })
        })
        .collect()
}

/// Slope of the Moon plot over x >= x_min (the tail: x_min = ln 2, v > 2 v_rms where the
/// Gaussian core ends, sec. 5.1.1); a straight line of slope -alpha means exp(-K v^alpha).
pub fn moon_slope(points: &[MoonPoint], x_min: f64) -> Option<Fit> {
    let p: Vec<&MoonPoint> = points.iter().filter(|p| p.x >= x_min).collect();
    if p.len() < 3 {
        return None;
    }
    fit::linear(
        &p.iter().map(|p| p.x).collect::<Vec<_>>(),
        &p.iter().map(|p| p.y).collect::<Vec<_>>(),
        Some(&p.iter().map(|p| p.err).collect::<Vec<_>>()),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::RunRng;

    /// A signed histogram of n_total draws from P(v) ~ exp(-|v/s|^alpha) (expected counts
    /// with Gaussian noise of width sqrt(count), fine for the counts >= 50 that are fitted).
    fn synthetic(alpha: f64, seed: u64, n_total: f64) -> (Vec<FoldedBin>, f64) {
        let (w, s) = (0.01, 0.3);
        let mut rng = RunRng::new(seed);
        let edges: Vec<f64> = (-600..=600).map(|j| j as f64 * w).collect();
        let dens = |v: f64| (-(v / s).abs().powf(alpha)).exp();
        let norm: f64 = edges
            .windows(2)
            .map(|e| dens(0.5 * (e[0] + e[1])) * w)
            .sum();
        let bins: Vec<(f64, f64, f64)> = edges
            .windows(2)
            .map(|e| {
                let mu = n_total * dens(0.5 * (e[0] + e[1])) * w / norm;
                (e[0], e[1], (mu + mu.sqrt() * rng.normal()).round().max(0.0))
            })
            .collect();
        let total = bins.iter().map(|b| b.2).sum();
        (fold(&bins), total)
    }

    #[test]
    fn folding_pairs_mirror_bins() {
        let bins = [
            (-0.2, -0.1, 3.0),
            (-0.1, 0.0, 5.0),
            (0.0, 0.1, 7.0),
            (0.1, 0.2, 11.0),
            (0.2, f64::INFINITY, 100.0),
        ];
        let f = fold(&bins);
        assert_eq!(f.len(), 2);
        assert_eq!(f[0].count, 12.0);
        assert_eq!(f[1].count, 14.0);
    }

    /// The accepted window is a chi_r^2 < 1.2 cut, so it contains the true alpha only with
    /// the probability of that cut (most of the time for ~20 bins); the best alpha is close
    /// to the truth and the window excludes clearly wrong alphas.
    #[test]
    fn alpha_window_contains_truth() {
        let rule = AlphaRule {
            grid: (0.5, 2.5, 0.02),
            ..AlphaRule::thesis(2)
        };
        for alpha in [1.0, 1.5, 2.0] {
            let (mut hit, mut best) = (0, vec![]);
            for seed in 0..20u64 {
                let (h, _) = synthetic(alpha, 100 * seed + (alpha * 10.0) as u64, 2e7);
                let w = alpha_window(&h, &rule).unwrap();
                if let Some((lo, hi)) = w.accepted {
                    if lo <= alpha + 0.011 && alpha <= hi + 0.011 {
                        hit += 1;
                    }
                    assert!(hi - lo < 0.8, "{alpha}: [{lo}, {hi}] too wide");
                    assert!(
                        (0.5 * (lo + hi) - alpha).abs() < 0.3,
                        "{alpha}: [{lo}, {hi}]"
                    );
                }
                best.push(w.best_alpha);
            }
            assert!(hit >= 10, "{alpha}: truth accepted in {hit} of 20");
            let mean = best.iter().sum::<f64>() / best.len() as f64;
            assert!((mean - alpha).abs() < 0.05, "{alpha}: mean best {mean}");
        }
    }

    #[test]
    fn crossover_recovers_parameters() {
        // Expected counts of (5.32) itself: the fit returns v_r, v_c.
        let (vr, vc, w, n) = (0.17, 0.26, 0.005, 1e8);
        let p = |v: f64| crossover_ln(&[0.0, vr, vc], v).exp();
        let norm: f64 = (0..400).map(|j| 2.0 * p((j as f64 + 0.5) * w) * w).sum();
        let mut rng = RunRng::new(8);
        let folded: Vec<FoldedBin> = (0..400)
            .map(|j| {
                let v = (j as f64 + 0.5) * w;
                let mu = 2.0 * n * p(v) * w / norm;
                FoldedBin {
                    v,
                    count: (mu + mu.sqrt() * rng.normal()).round().max(0.0),
                    width: w,
                }
            })
            .collect();
        let c = crossover_fit(&folded, n, 20.0).unwrap();
        let ((r, re), (cc, ce)) = (c.v_r(), c.v_c());
        assert!(
            (r - vr).abs() < 4.0 * re && re < 0.01 * vr,
            "v_r {r} +- {re}"
        );
        assert!(
            (cc - vc).abs() < 4.0 * ce && ce < 0.05 * vc,
            "v_c {cc} +- {ce}"
        );
        assert!((c.ratio_at_v_c() - (-(vc / vr).powi(2) / 2.0).exp()).abs() < 0.02);
        let chi = c.fit.chi2_reduced.unwrap();
        assert!(chi < 1.5, "chi2_r {chi}");
    }

    #[test]
    fn moon_slope_is_minus_alpha() {
        let (h, total) = synthetic(1.2, 11, 5e7);
        let rms = v_rms(&h);
        // P' = the exact amplitude of the density makes the plot straight everywhere.
        let p0 = density(&h[0], total);
        let pts = moon_points(&h, total, rms, p0 * 1.0005, 50.0);
        let f = moon_slope(&pts, 2f64.ln()).unwrap();
        assert!((f.params[1] + 1.2).abs() < 0.05, "slope {}", f.params[1]);
    }
}
