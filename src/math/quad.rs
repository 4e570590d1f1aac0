//! Numerical building blocks of the theory, written here (no dependencies): Gauss-Legendre
//! rules, an adaptive Gauss-Legendre integrator, composite rules on geometric panels, the Gamma
//! function, and small numerically stable helpers.

use std::f64::consts::PI;
use std::sync::OnceLock;

/// Nodes and weights of the `n`-point Gauss-Legendre rule on [-1, 1] (Newton iteration on the
/// Legendre polynomial; nodes and weights to machine precision).
pub fn gauss_legendre(n: usize) -> (Vec<f64>, Vec<f64>) {
    assert!(n >= 1, "a Gauss-Legendre rule needs at least one node");
    let mut x = vec![0.0; n];
    let mut w = vec![0.0; n];
    let nf = n as f64;
    for i in 0..n.div_ceil(2) {
        // Initial guess (Tricomi), then Newton.
        let mut z = (PI * (i as f64 + 0.75) / (nf + 0.5)).cos();
        let mut dp = 0.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, z);
            for j in 2..=n {
                let jf = j as f64;
                let p2 = ((2.0 * jf - 1.0) * z * p1 - (jf - 1.0) * p0) / jf;
                p0 = p1;
                p1 = p2;
            }
            // p1 = P_n(z), p0 = P_{n-1}(z).
            dp = nf * (z * p1 - p0) / (z * z - 1.0);
            let dz = p1 / dp;
            z -= dz;
            if dz.abs() <= 1e-16 * z.abs().max(1e-3) {
                break;
            }
        }
        x[i] = -z;
        x[n - 1 - i] = z;
        let wi = 2.0 / ((1.0 - z * z) * dp * dp);
        w[i] = wi;
        w[n - 1 - i] = wi;
    }
    if n % 2 == 1 {
        x[n / 2] = 0.0;
    }
    (x, w)
}

/// The cached 10-point rule used by the adaptive integrator.
fn gl10() -> &'static (Vec<f64>, Vec<f64>) {
    static R: OnceLock<(Vec<f64>, Vec<f64>)> = OnceLock::new();
    R.get_or_init(|| gauss_legendre(10))
}

/// The cached 16-point rule used by the composite (panel) quadratures.
pub(crate) fn gl16() -> &'static (Vec<f64>, Vec<f64>) {
    static R: OnceLock<(Vec<f64>, Vec<f64>)> = OnceLock::new();
    R.get_or_init(|| gauss_legendre(16))
}

fn gl_panel<const D: usize>(f: &mut impl FnMut(f64) -> [f64; D], a: f64, b: f64) -> [f64; D] {
    let (x, w) = gl10();
    let (mid, half) = (0.5 * (a + b), 0.5 * (b - a));
    let mut s = [0.0; D];
    for (xi, wi) in x.iter().zip(w) {
        let v = f(mid + half * xi);
        for c in 0..D {
            s[c] += wi * v[c];
        }
    }
    for c in s.iter_mut() {
        *c *= half;
    }
    s
}

/// Adaptive Gauss-Legendre integration of a vector-valued `f` over the panels given by the
/// sorted `breaks`. Each panel's 10-point value is compared with the sum over its two halves;
/// a panel is accepted when they differ by less than its share (proportional to its length) of
/// `rel_tol * |I|` (component-wise, `I` the current estimate of the whole integral) or of
/// `abs_tol`, or at rounding level; otherwise both halves are refined. The accepted value is the
/// refined one, so the error is typically far below the tolerance for smooth integrands;
/// integrable algebraic end-point singularities (e.g. x^0.2) are handled by bisection.
pub fn adaptive<const D: usize>(
    f: &mut impl FnMut(f64) -> [f64; D],
    breaks: &[f64],
    rel_tol: f64,
    abs_tol: f64,
) -> [f64; D] {
    assert!(breaks.len() >= 2);
    let length = breaks[breaks.len() - 1] - breaks[0];
    let mut stack: Vec<(f64, f64, [f64; D], u32)> = Vec::new();
    let mut total = [0.0; D];
    for p in breaks.windows(2) {
        let v = gl_panel(f, p[0], p[1]);
        for c in 0..D {
            total[c] += v[c];
        }
        stack.push((p[0], p[1], v, 0));
    }
    let mut result = [0.0; D];
    while let Some((a, b, whole, depth)) = stack.pop() {
        let m = 0.5 * (a + b);
        let left = gl_panel(f, a, m);
        let right = gl_panel(f, m, b);
        let share = (b - a) / length;
        let mut ok = true;
        for c in 0..D {
            let fine = left[c] + right[c];
            let err = (fine - whole[c]).abs();
            let allowed = (rel_tol * total[c].abs()).max(abs_tol) * share;
            if err > allowed && err > 64.0 * f64::EPSILON * (left[c].abs() + right[c].abs()) {
                ok = false;
            }
        }
        if ok || depth >= 48 {
            for c in 0..D {
                result[c] += left[c] + right[c];
                total[c] += left[c] + right[c] - whole[c];
            }
        } else {
            stack.push((a, m, left, depth + 1));
            stack.push((m, b, right, depth + 1));
        }
    }
    result
}

/// Composite 16-point Gauss-Legendre nodes and weights over the panels between consecutive
/// `breaks` (sorted; zero-length panels are skipped). Returns (nodes, weights).
pub fn composite_nodes(breaks: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let (x, w) = gl16();
    let mut nodes = Vec::with_capacity(breaks.len() * x.len());
    let mut weights = Vec::with_capacity(breaks.len() * x.len());
    for p in breaks.windows(2) {
        let (a, b) = (p[0], p[1]);
        if b <= a {
            continue;
        }
        let (mid, half) = (0.5 * (a + b), 0.5 * (b - a));
        for (xi, wi) in x.iter().zip(w) {
            nodes.push(mid + half * xi);
            weights.push(half * wi);
        }
    }
    (nodes, weights)
}

/// Breakpoints on [a, b] (a < b) graded geometrically towards `a`: a, a + h, a + 2h, a + 4h, ...,
/// b with the first panel of length `h` (ratio 2), or just [a, b] when h >= b - a.
/// A first panel that is not a positive finite length (a degenerate time scale of the caller)
/// would never reach `b`: then the one panel [a, b].
pub fn graded_from(a: f64, b: f64, h: f64) -> Vec<f64> {
    let mut v = vec![a];
    let mut d = if h > 0.0 && h.is_finite() { h } else { b - a };
    while a + d < b {
        v.push(a + d);
        d *= 2.0;
    }
    v.push(b);
    v
}

/// Integral of `f` over [a, b] by composite 16-point Gauss-Legendre on panels graded
/// geometrically (ratio 2) away from both ends, the smallest panels of length `h`: accurate for
/// integrands that are smooth on the scale of the distance to either end and of `h`.
pub fn graded_integral(f: impl Fn(f64) -> f64, a: f64, b: f64, h: f64) -> f64 {
    if b <= a {
        return 0.0;
    }
    let mid = 0.5 * (a + b);
    let mut breaks = graded_from(a, mid, h);
    let right: Vec<f64> = graded_from(-b, -mid, h)
        .into_iter()
        .map(|x| -x)
        .rev()
        .collect();
    breaks.pop();
    breaks.extend(right);
    let (nodes, weights) = composite_nodes(&breaks);
    nodes.iter().zip(&weights).map(|(&x, &w)| w * f(x)).sum()
}

/// Gamma(x) for x > 0 (Lanczos, g = 7, 9 terms; relative accuracy ~1e-15).
pub fn gamma(x: f64) -> f64 {
    const G: f64 = 7.0;
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        return PI / ((PI * x).sin() * gamma(1.0 - x));
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + G + 0.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    (2.0 * PI).sqrt() * t.powf(x + 0.5) * (-t).exp() * a
}

/// tau0 * ln(1 + t/tau0), the reduced time of a Haff cooling (18) up to tau_c(0); its limit t
/// for tau0 = infinity (no cooling).
pub fn tau_ln1p(tau0: f64, t: f64) -> f64 {
    if tau0.is_infinite() {
        t
    } else {
        tau0 * (t / tau0).ln_1p()
    }
}

/// phi(x) = x - 1 + exp(-x), accurate also for small x (where it is ~x^2/2).
pub fn phi(x: f64) -> f64 {
    if x.abs() < 0.1 {
        // Taylor series: sum_{j>=2} (-x)^j / j!.
        let mut term = x * x / 2.0;
        let mut s: f64 = 0.0;
        let mut j = 2.0;
        while term.abs() > 1e-18 * s.abs().max(1e-300) && j < 30.0 {
            s += term;
            j += 1.0;
            term *= -x / j;
        }
        s
    } else {
        x + (-x).exp_m1()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn graded_breaks_end_for_a_degenerate_first_panel() {
        // Before: h <= 0 never reached b (a vector grown until memory ran out).
        for h in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert_eq!(graded_from(0.0, 3.0, h), vec![0.0, 3.0], "h = {h}");
        }
        assert_eq!(graded_from(0.0, 3.0, 1.0), vec![0.0, 1.0, 2.0, 3.0]);
    }

    /// Gauss-Legendre: weights sum to 2, exact for x^(2n-1), known 3-point nodes (1e-15).
    #[test]
    fn gauss_legendre_rules() {
        for n in [1usize, 2, 3, 7, 10, 16, 40] {
            let (x, w) = gauss_legendre(n);
            let sw: f64 = w.iter().sum();
            assert!((sw - 2.0).abs() < 1e-14, "n={n} sum w = {sw}");
            let p = 2 * n - 2;
            let got: f64 = x.iter().zip(&w).map(|(x, w)| w * x.powi(p as i32)).sum();
            let want = 2.0 / (p as f64 + 1.0);
            assert!((got - want).abs() < 1e-14, "n={n}: {got} vs {want}");
        }
        let (x, _) = gauss_legendre(3);
        assert!((x[2] - 0.6f64.sqrt()).abs() < 1e-15);
    }

    /// Adaptive rule: integral of x^0.2 e^{-x^2} x^3 over [0, 10] vs Gamma (1e-13 relative);
    /// Gamma(x) vs known values (1e-14).
    #[test]
    fn adaptive_and_gamma() {
        let got = adaptive(
            &mut |x: f64| [x.powf(3.2) * (-x * x).exp()],
            &[0.0, 10.0],
            1e-14,
            0.0,
        )[0];
        let want = 0.5 * gamma(2.1);
        assert!((got / want - 1.0).abs() < 1e-13, "{got} vs {want}");
        assert!((gamma(5.0) - 24.0).abs() < 24.0 * 1e-14);
        assert!((gamma(0.5) - PI.sqrt()).abs() < 1e-14);
        assert!((gamma(1.5) - 0.5 * PI.sqrt()).abs() < 1e-14);
        assert!((gamma(0.05) - 19.470_085_311_255_51).abs() < 19.47 * 1e-13);
    }

    #[test]
    fn stable_helpers() {
        for x in [1e-9f64, 1e-4, 0.05, 0.0999, 0.1, 0.5, 3.0, 50.0] {
            let direct = x - 1.0 + (-x).exp();
            let want = if x < 1e-3 {
                x * x / 2.0 - x * x * x / 6.0 + x.powi(4) / 24.0
            } else {
                direct
            };
            assert!(
                (phi(x) / want - 1.0).abs() < 1e-12,
                "{x}: {} vs {want}",
                phi(x)
            );
        }
        assert_eq!(tau_ln1p(f64::INFINITY, 3.0), 3.0);
        let g = graded_integral(|x| 1.0 / (1.0 + x), 0.0, 1e9, 1e-3);
        assert!((g / (1e9f64).ln_1p() - 1.0).abs() < 1e-13, "{g}");
    }
}
