//! A stiff ODE integrator for the theory: the 3-stage Radau IIA collocation method (order 5,
//! L-stable, stiffly accurate) with simplified Newton iterations. As in Hairer & Wanner's
//! RADAU5, the 3n x 3n Newton system (I - h A (x) J) dZ = -R is decoupled by the eigenvectors
//! of A^-1 (one real eigenvalue gamma, a complex pair alpha +- i beta) into one real n x n and
//! one complex n x n system, (gamma/h - J) and ((alpha - i beta)/h - J), about 5x cheaper to
//! factorise. Step-size control by step doubling (one step of h against two of h/2; the two
//! half steps are kept); steps cut short to land on a requested output that are at most half
//! the controller's proposal are taken as single steps (predicted error < 2% of the tolerance).
//! Quadrature components (q' = g(s, y), g independent of q) ride along with the same stages and
//! take part in the error control. The integrator lands exactly on every requested abscissa.

#![allow(clippy::needless_range_loop)] // index loops read best in dense linear algebra

/// Why [`integrate`] stopped: unsorted abscissae, too many steps, a step size underflow.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct OdeError(pub String);

/// An ODE system y' = f(s, y) with optional quadrature components q' = g(s, y).
pub(crate) trait OdeSystem {
    /// Dimension of y.
    fn dim(&self) -> usize;
    /// Dimension of q (0 when there is none).
    fn quad_dim(&self) -> usize {
        0
    }
    fn rhs(&self, s: f64, y: &[f64], dy: &mut [f64]);
    /// Row-major n x n Jacobian df/dy; the default uses forward differences.
    fn jacobian(&self, s: f64, y: &[f64], jac: &mut [f64]) {
        let n = self.dim();
        let mut f0 = vec![0.0; n];
        let mut f1 = vec![0.0; n];
        self.rhs(s, y, &mut f0);
        let mut yp = y.to_vec();
        for j in 0..n {
            let d = 1e-7 * y[j].abs().max(1.0);
            yp[j] = y[j] + d;
            self.rhs(s, &yp, &mut f1);
            yp[j] = y[j];
            for i in 0..n {
                jac[i * n + j] = (f1[i] - f0[i]) / d;
            }
        }
    }
    fn quad(&self, _s: f64, _y: &[f64], _dq: &mut [f64]) {}
}

/// Error weights: |err_y| <= atol_y + rtol_y |y|, |err_q| <= atol_q + rtol_q |q|.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Tolerances {
    pub atol_y: f64,
    pub rtol_y: f64,
    pub atol_q: f64,
    pub rtol_q: f64,
}

/// The 3-stage Radau IIA tableau and the eigen-decomposition of A^-1:
/// T^-1 A^-1 T = [[gamma, 0, 0], [0, alpha, beta], [0, -beta, alpha]].
struct Tableau {
    a: [[f64; 3]; 3],
    c: [f64; 3],
    /// T (columns: real eigenvector, real and imaginary parts of the complex one).
    t: [[f64; 3]; 3],
    /// T^-1 A^-1.
    tinv_ainv: [[f64; 3]; 3],
    gamma: f64,
    alpha: f64,
    beta: f64,
}

fn inv3(m: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let (a, b) = ((j + 1) % 3, (j + 2) % 3);
            let (c, d) = ((i + 1) % 3, (i + 2) % 3);
            r[i][j] = (m[a][c] * m[b][d] - m[a][d] * m[b][c]) / det;
        }
    }
    r
}

fn mul3(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    r
}

fn tableau() -> Tableau {
    let r6 = 6f64.sqrt();
    let a = [
        [
            (88.0 - 7.0 * r6) / 360.0,
            (296.0 - 169.0 * r6) / 1800.0,
            (-2.0 + 3.0 * r6) / 225.0,
        ],
        [
            (296.0 + 169.0 * r6) / 1800.0,
            (88.0 + 7.0 * r6) / 360.0,
            (-2.0 - 3.0 * r6) / 225.0,
        ],
        [(16.0 - r6) / 36.0, (16.0 + r6) / 36.0, 1.0 / 9.0],
    ];
    let c = [(4.0 - r6) / 10.0, (4.0 + r6) / 10.0, 1.0];
    let ai = inv3(&a);
    // Characteristic polynomial l^3 - p2 l^2 + p1 l - p0.
    let p2 = ai[0][0] + ai[1][1] + ai[2][2];
    let p1 = ai[0][0] * ai[1][1] - ai[0][1] * ai[1][0] + ai[0][0] * ai[2][2] - ai[0][2] * ai[2][0]
        + ai[1][1] * ai[2][2]
        - ai[1][2] * ai[2][1];
    let p0 = 1.0
        / (a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
            - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]));
    let mut gamma = 3.6;
    for _ in 0..100 {
        let f = ((gamma - p2) * gamma + p1) * gamma - p0;
        let df = (3.0 * gamma - 2.0 * p2) * gamma + p1;
        let d = f / df;
        gamma -= d;
        if d.abs() < 1e-16 * gamma {
            break;
        }
    }
    // Remaining quadratic l^2 - (p2 - gamma) l + p0/gamma.
    let alpha = 0.5 * (p2 - gamma);
    let beta = (p0 / gamma - alpha * alpha).sqrt();
    // Real eigenvector: cross product of two rows of A^-1 - gamma I.
    let row = |i: usize, lr: f64| -> [f64; 3] {
        let mut r = ai[i];
        r[i] -= lr;
        r
    };
    let cross = |x: [f64; 3], y: [f64; 3]| {
        [
            x[1] * y[2] - x[2] * y[1],
            x[2] * y[0] - x[0] * y[2],
            x[0] * y[1] - x[1] * y[0],
        ]
    };
    let v1 = cross(row(0, gamma), row(1, gamma));
    // Complex eigenvector for alpha + i beta: complex cross product of two rows of
    // A^-1 - (alpha + i beta) I (rows have real part row(i, alpha), imaginary part -beta e_i).
    let (r0, r1) = (row(0, alpha), row(1, alpha));
    let i0 = [-beta, 0.0, 0.0];
    let i1 = [0.0, -beta, 0.0];
    let cc = |xr: [f64; 3], xi: [f64; 3], yr: [f64; 3], yi: [f64; 3]| -> ([f64; 3], [f64; 3]) {
        let mut re = [0.0; 3];
        let mut im = [0.0; 3];
        for k in 0..3 {
            let (p, q) = ((k + 1) % 3, (k + 2) % 3);
            // x_p y_q - x_q y_p with complex entries.
            re[k] = xr[p] * yr[q] - xi[p] * yi[q] - (xr[q] * yr[p] - xi[q] * yi[p]);
            im[k] = xr[p] * yi[q] + xi[p] * yr[q] - (xr[q] * yi[p] + xi[q] * yr[p]);
        }
        (re, im)
    };
    let (u, w) = cc(r0, i0, r1, i1);
    let t = [
        [v1[0], u[0], w[0]],
        [v1[1], u[1], w[1]],
        [v1[2], u[2], w[2]],
    ];
    let tinv_ainv = mul3(&inv3(&t), &ai);
    Tableau {
        a,
        c,
        t,
        tinv_ainv,
        gamma,
        alpha,
        beta,
    }
}

/// Dense LU factorisation with partial pivoting (row-major, in place).
pub(crate) struct Lu {
    n: usize,
    a: Vec<f64>,
    piv: Vec<usize>,
}

// Where the CPU has AVX2 the factorisations take their AVX2 copies: the same code compiled
// for 256-bit vectors, whose row updates do per element the same multiplications and
// subtractions in the same order (no fused multiply-add: that is the `fma` feature, not
// enabled), so the same bits (test `factorisations_are_the_portable_bits`).

impl Lu {
    /// Factorises the row-major n x n matrix `a`; None when it is singular.
    pub(crate) fn new(n: usize, a: Vec<f64>) -> Option<Lu> {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2.
            return unsafe { Self::new_avx2(n, a) };
        }
        Self::factor(n, a)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn new_avx2(n: usize, a: Vec<f64>) -> Option<Lu> {
        Self::factor(n, a)
    }

    #[inline(always)]
    fn factor(n: usize, mut a: Vec<f64>) -> Option<Lu> {
        debug_assert_eq!(a.len(), n * n, "Lu::new: an n x n matrix");
        let mut piv = vec![0; n];
        for k in 0..n {
            let mut p = k;
            let mut best = a[k * n + k].abs();
            for i in k + 1..n {
                let v = a[i * n + k].abs();
                if v > best {
                    best = v;
                    p = i;
                }
            }
            if best == 0.0 || !best.is_finite() {
                return None;
            }
            piv[k] = p;
            if p != k {
                for j in 0..n {
                    a.swap(k * n + j, p * n + j);
                }
            }
            let d = a[k * n + k];
            // Rows k+1.. minus l times row k: slices without bounds checks, so the update
            // vectorises (the same operations on each element, so the same bits).
            let (top, below) = a.split_at_mut((k + 1) * n);
            let row_k = &top[k * n + k + 1..];
            for row in below.chunks_exact_mut(n) {
                let l = row[k] / d;
                row[k] = l;
                if l != 0.0 {
                    for (x, &u) in row[k + 1..].iter_mut().zip(row_k) {
                        *x -= l * u;
                    }
                }
            }
        }
        Some(Lu { n, a, piv })
    }

    /// Solves A x = b in place.
    pub(crate) fn solve(&self, b: &mut [f64]) {
        let n = self.n;
        for k in 0..n {
            b.swap(k, self.piv[k]);
        }
        for i in 0..n {
            let mut s = b[i];
            for (a, x) in self.a[i * n..i * n + i].iter().zip(&b[..i]) {
                s -= a * x;
            }
            b[i] = s;
        }
        for i in (0..n).rev() {
            let mut s = b[i];
            for (a, x) in self.a[i * n + i + 1..(i + 1) * n].iter().zip(&b[i + 1..]) {
                s -= a * x;
            }
            b[i] = s / self.a[i * n + i];
        }
    }
}

/// Dense complex LU with partial pivoting (separate real and imaginary parts, row-major).
struct CLu {
    n: usize,
    re: Vec<f64>,
    im: Vec<f64>,
    piv: Vec<usize>,
}

impl CLu {
    fn new(n: usize, re: Vec<f64>, im: Vec<f64>) -> Option<CLu> {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2.
            return unsafe { Self::new_avx2(n, re, im) };
        }
        Self::factor(n, re, im)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn new_avx2(n: usize, re: Vec<f64>, im: Vec<f64>) -> Option<CLu> {
        Self::factor(n, re, im)
    }

    #[inline(always)]
    fn factor(n: usize, mut re: Vec<f64>, mut im: Vec<f64>) -> Option<CLu> {
        debug_assert!(
            re.len() == n * n && im.len() == n * n,
            "CLu::new: n x n matrices"
        );
        let mut piv = vec![0; n];
        for k in 0..n {
            let mut p = k;
            let mut best = re[k * n + k].hypot(im[k * n + k]);
            for i in k + 1..n {
                let v = re[i * n + k].hypot(im[i * n + k]);
                if v > best {
                    best = v;
                    p = i;
                }
            }
            if best == 0.0 || !best.is_finite() {
                return None;
            }
            piv[k] = p;
            if p != k {
                for j in 0..n {
                    re.swap(k * n + j, p * n + j);
                    im.swap(k * n + j, p * n + j);
                }
            }
            let (dr, di) = (re[k * n + k], im[k * n + k]);
            let dd = dr * dr + di * di;
            // As in Lu::new: slices, so the row update vectorises (the same bits).
            let (re_top, re_below) = re.split_at_mut((k + 1) * n);
            let (im_top, im_below) = im.split_at_mut((k + 1) * n);
            let (re_k, im_k) = (&re_top[k * n + k + 1..], &im_top[k * n + k + 1..]);
            for (rr, ri) in re_below
                .chunks_exact_mut(n)
                .zip(im_below.chunks_exact_mut(n))
            {
                let (xr, xi) = (rr[k], ri[k]);
                // l = x / d
                let lr = (xr * dr + xi * di) / dd;
                let li = (xi * dr - xr * di) / dd;
                rr[k] = lr;
                ri[k] = li;
                if lr != 0.0 || li != 0.0 {
                    let row = rr[k + 1..].iter_mut().zip(ri[k + 1..].iter_mut());
                    for ((x, y), (&ur, &ui)) in row.zip(re_k.iter().zip(im_k)) {
                        *x -= lr * ur - li * ui;
                        *y -= lr * ui + li * ur;
                    }
                }
            }
        }
        Some(CLu { n, re, im, piv })
    }

    fn solve(&self, br: &mut [f64], bi: &mut [f64]) {
        let n = self.n;
        for k in 0..n {
            br.swap(k, self.piv[k]);
            bi.swap(k, self.piv[k]);
        }
        for i in 0..n {
            let (mut sr, mut si) = (br[i], bi[i]);
            let l = self.re[i * n..i * n + i]
                .iter()
                .zip(&self.im[i * n..i * n + i]);
            for ((&lr, &li), (&xr, &xi)) in l.zip(br[..i].iter().zip(&bi[..i])) {
                sr -= lr * xr - li * xi;
                si -= lr * xi + li * xr;
            }
            br[i] = sr;
            bi[i] = si;
        }
        for i in (0..n).rev() {
            let (mut sr, mut si) = (br[i], bi[i]);
            let row = i * n + i + 1..(i + 1) * n;
            let u = self.re[row.clone()].iter().zip(&self.im[row]);
            for ((&ur, &ui), (&xr, &xi)) in u.zip(br[i + 1..].iter().zip(&bi[i + 1..])) {
                sr -= ur * xr - ui * xi;
                si -= ur * xi + ui * xr;
            }
            let (dr, di) = (self.re[i * n + i], self.im[i * n + i]);
            let dd = dr * dr + di * di;
            br[i] = (sr * dr + si * di) / dd;
            bi[i] = (si * dr - sr * di) / dd;
        }
    }
}

/// The factorised Newton matrices of one step size h: (gamma/h - J) and ((alpha - i beta)/h - J).
struct StepLu {
    h: f64,
    real: Lu,
    cplx: CLu,
}

impl StepLu {
    fn new(tab: &Tableau, jac: &[f64], n: usize, h: f64) -> Option<StepLu> {
        let mut m = vec![0.0; n * n];
        let mut mr = vec![0.0; n * n];
        let mut mi = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                m[i * n + j] = -jac[i * n + j];
                mr[i * n + j] = -jac[i * n + j];
            }
            m[i * n + i] += tab.gamma / h;
            mr[i * n + i] += tab.alpha / h;
            mi[i * n + i] = -tab.beta / h;
        }
        Some(StepLu {
            h,
            real: Lu::new(n, m)?,
            cplx: CLu::new(n, mr, mi)?,
        })
    }

    /// Solves (I - h A (x) J) dz = rhs (3n, stage-major) in place.
    fn solve(&self, tab: &Tableau, n: usize, rhs: &mut [f64]) {
        let h = self.h;
        let mut w = vec![0.0; 3 * n];
        for p in 0..3 {
            for i in 0..n {
                w[p * n + i] = (0..3)
                    .map(|q| tab.tinv_ainv[p][q] * rhs[q * n + i])
                    .sum::<f64>()
                    / h;
            }
        }
        let (w1, rest) = w.split_at_mut(n);
        let (w2, w3) = rest.split_at_mut(n);
        self.real.solve(w1);
        self.cplx.solve(w2, w3);
        for p in 0..3 {
            for i in 0..n {
                rhs[p * n + i] = (0..3).map(|q| tab.t[p][q] * w[q * n + i]).sum();
            }
        }
    }
}

struct StepOut {
    y: Vec<f64>,
    q: Vec<f64>,
}

/// One Radau IIA step of size lu.h from (s, y0, q0); None when Newton does not converge.
fn radau_step<S: OdeSystem>(
    sys: &S,
    tab: &Tableau,
    lu: &StepLu,
    s: f64,
    y0: &[f64],
    q0: &[f64],
    w: &[f64],
) -> Option<StepOut> {
    let n = sys.dim();
    let nq = sys.quad_dim();
    let m = 3 * n;
    let h = lu.h;
    let mut z = vec![0.0; m];
    let mut f = vec![0.0; m];
    let mut yst = vec![0.0; n];
    let mut prev = f64::INFINITY;
    let mut converged = false;
    for _iter in 0..20 {
        for st in 0..3 {
            for i in 0..n {
                yst[i] = y0[i] + z[st * n + i];
            }
            sys.rhs(s + tab.c[st] * h, &yst, &mut f[st * n..(st + 1) * n]);
        }
        if f.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let mut r = vec![0.0; m];
        for bi in 0..3 {
            for i in 0..n {
                let mut acc = z[bi * n + i];
                for bj in 0..3 {
                    acc -= h * tab.a[bi][bj] * f[bj * n + i];
                }
                r[bi * n + i] = -acc;
            }
        }
        lu.solve(tab, n, &mut r);
        let mut norm: f64 = 0.0;
        for st in 0..3 {
            for i in 0..n {
                z[st * n + i] += r[st * n + i];
                norm = norm.max((r[st * n + i] / w[i]).abs());
            }
        }
        if !norm.is_finite() {
            return None;
        }
        // Converged when the remaining error, estimated from the contraction rate theta as
        // theta/(1 - theta) |dZ|, is below 1e-3 of the tolerance (1e-4 after one iteration).
        let theta = if prev < f64::INFINITY {
            norm / prev
        } else {
            1.0
        };
        if norm <= 1e-4 || (theta < 0.9 && theta / (1.0 - theta) * norm <= 1e-3) {
            converged = true;
            break;
        }
        if norm > 0.9 * prev && prev < f64::INFINITY && norm > 1e-1 {
            return None;
        }
        prev = norm;
    }
    if !converged {
        return None;
    }
    let mut y = y0.to_vec();
    for i in 0..n {
        y[i] += z[2 * n + i];
    }
    let mut q = q0.to_vec();
    if nq > 0 {
        let mut g = vec![0.0; nq];
        for st in 0..3 {
            for i in 0..n {
                yst[i] = y0[i] + z[st * n + i];
            }
            sys.quad(s + tab.c[st] * h, &yst, &mut g);
            for (qi, gi) in q.iter_mut().zip(&g) {
                *qi += h * tab.a[2][st] * gi;
            }
        }
    }
    if y.iter().chain(q.iter()).any(|v| !v.is_finite()) {
        return None;
    }
    Some(StepOut { y, q })
}

/// (y, q) at one output abscissa.
pub(crate) type Solution = (Vec<f64>, Vec<f64>);

/// Integrates from s = 0 (state y0, q0) and returns (y, q) at each of the sorted abscissae
/// `s_out` (>= 0). `h0` is the first trial step.
pub(crate) fn integrate<S: OdeSystem>(
    sys: &S,
    y0: &[f64],
    q0: &[f64],
    s_out: &[f64],
    tol: Tolerances,
    h0: f64,
) -> Result<Vec<Solution>, OdeError> {
    let n = sys.dim();
    assert_eq!(y0.len(), n);
    assert_eq!(q0.len(), sys.quad_dim());
    let tab = tableau();
    let mut s = 0.0;
    let mut y = y0.to_vec();
    let mut q = q0.to_vec();
    let mut h_prop = h0;
    let mut jac = vec![0.0; n * n];
    let mut jac_s: Option<f64> = None;
    let mut out = Vec::with_capacity(s_out.len());
    let mut steps = 0usize;
    for &target in s_out {
        if target < s {
            return Err(OdeError(format!(
                "output abscissae must be sorted and >= 0 (got {target} after {s})"
            )));
        }
        while s < target {
            let remaining = target - s;
            let mut h = if remaining <= h_prop * 1.01 {
                remaining
            } else if remaining < 2.0 * h_prop {
                0.5 * remaining
            } else {
                h_prop
            };
            let w: Vec<f64> = y
                .iter()
                .map(|v| tol.atol_y + tol.rtol_y * v.abs())
                .collect();
            // A short step onto an output (predicted error below 2% of the tolerance) is taken
            // without an error estimate, reusing a recent Jacobian (simplified Newton).
            if remaining <= 0.5 * h_prop {
                if jac_s.is_none_or(|js| s - js > h_prop) {
                    sys.jacobian(s, &y, &mut jac);
                    jac_s = Some(s);
                }
                if let Some(st) = StepLu::new(&tab, &jac, n, remaining)
                    .and_then(|lu| radau_step(sys, &tab, &lu, s, &y, &q, &w))
                {
                    s = target;
                    y = st.y;
                    q = st.q;
                    continue;
                }
            }
            sys.jacobian(s, &y, &mut jac);
            jac_s = Some(s);
            loop {
                steps += 1;
                if steps > 10_000_000 {
                    return Err(OdeError("too many steps".into()));
                }
                if h < 1e-14 * s.abs().max(1.0) {
                    return Err(OdeError(format!("step size underflow at s = {s}")));
                }
                let last = h >= remaining;
                let (Some(lu_h), Some(lu_h2)) = (
                    StepLu::new(&tab, &jac, n, h),
                    StepLu::new(&tab, &jac, n, 0.5 * h),
                ) else {
                    h *= 0.25;
                    continue;
                };
                let big = radau_step(sys, &tab, &lu_h, s, &y, &q, &w);
                let half1 = big
                    .as_ref()
                    .and_then(|_| radau_step(sys, &tab, &lu_h2, s, &y, &q, &w));
                let half2 = half1
                    .as_ref()
                    .and_then(|m| radau_step(sys, &tab, &lu_h2, s + 0.5 * h, &m.y, &m.q, &w));
                let (Some(big), Some(small)) = (big, half2) else {
                    h *= 0.25;
                    continue;
                };
                let mut err: f64 = 0.0;
                for i in 0..n {
                    let wi = tol.atol_y + tol.rtol_y * y[i].abs().max(small.y[i].abs());
                    err = err.max(((small.y[i] - big.y[i]) / wi).abs());
                }
                for i in 0..q.len() {
                    let wi = tol.atol_q + tol.rtol_q * q[i].abs().max(small.q[i].abs());
                    err = err.max(((small.q[i] - big.q[i]) / wi).abs());
                }
                err /= 15.0;
                let factor = if err == 0.0 {
                    4.0
                } else {
                    (0.9 * err.powf(-1.0 / 6.0)).clamp(0.2, 4.0)
                };
                if err <= 1.0 {
                    s = if last { target } else { s + h };
                    y = small.y;
                    q = small.q;
                    // A step cut short to land on an output does not shrink the proposal.
                    if !(last && h < h_prop) || factor < 1.0 {
                        h_prop = h * factor;
                    }
                    break;
                }
                h *= factor.min(0.9);
            }
        }
        out.push((y.clone(), q.clone()));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The Radau IIA tableau satisfies the simplifying conditions C(3) (sum_j a_ij c_j^(q-1) =
    /// c_i^q / q) and B(5) (to 1e-15).
    #[test]
    fn radau_tableau_order_conditions() {
        let t = tableau();
        for i in 0..3 {
            for qq in 1..=3 {
                let lhs: f64 = (0..3).map(|j| t.a[i][j] * t.c[j].powi(qq - 1)).sum();
                let rhs = t.c[i].powi(qq) / qq as f64;
                assert!((lhs - rhs).abs() < 1e-15, "C({qq}) row {i}: {lhs} vs {rhs}");
            }
        }
        for qq in 1..=5 {
            let lhs: f64 = (0..3).map(|j| t.a[2][j] * t.c[j].powi(qq - 1)).sum();
            assert!((lhs - 1.0 / qq as f64).abs() < 1e-15, "B({qq})");
        }
    }

    /// The factorisations' AVX2 copies (taken by `new` where the CPU has AVX2) give the bits
    /// of the portable code: factors, pivots and solutions, real and complex, for sizes
    /// around the vector width, with pivoting (entries of mixed sign and scale) and a zero
    /// multiplier (a row already eliminated).
    #[test]
    fn factorisations_are_the_portable_bits() {
        // A fixed pseudo-random sequence (splitmix64), entries in [-1, 1) times 10^[-3, 3).
        let mut x: u64 = 0x9e37_79b9_7f4a_7c15;
        let mut next = move || {
            x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = x;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^= z >> 31;
            let u = (z >> 11) as f64 / (1u64 << 53) as f64;
            (2.0 * u - 1.0) * 10f64.powi((z % 6) as i32 - 3)
        };
        for n in [1, 2, 3, 4, 5, 7, 8, 9, 16, 17, 37] {
            let mut a: Vec<f64> = (0..n * n).map(|_| next()).collect();
            if n > 2 {
                // Row 2 starts with a zero below the first pivot: a zero multiplier.
                a[2 * n] = 0.0;
            }
            let b: Vec<f64> = (0..n).map(|_| next()).collect();
            let fast = Lu::new(n, a.clone()).unwrap();
            let slow = Lu::factor(n, a.clone()).unwrap();
            assert_eq!(fast.piv, slow.piv, "n = {n}");
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&fast.a), bits(&slow.a), "n = {n}");
            let (mut xf, mut xs) = (b.clone(), b.clone());
            fast.solve(&mut xf);
            slow.solve(&mut xs);
            assert_eq!(bits(&xf), bits(&xs), "n = {n}");
            // The solution solves the system (the factors are a factorisation).
            for i in 0..n {
                let r: f64 = (0..n).map(|j| a[i * n + j] * xf[j]).sum::<f64>() - b[i];
                assert!(r.abs() < 1e-6 * (1.0 + b[i].abs()), "n = {n}: residual {r}");
            }
            let im: Vec<f64> = (0..n * n).map(|_| next()).collect();
            let fast = CLu::new(n, a.clone(), im.clone()).unwrap();
            let slow = CLu::factor(n, a.clone(), im.clone()).unwrap();
            assert_eq!(fast.piv, slow.piv, "n = {n}");
            assert_eq!(bits(&fast.re), bits(&slow.re), "n = {n}");
            assert_eq!(bits(&fast.im), bits(&slow.im), "n = {n}");
            let bi: Vec<f64> = (0..n).map(|_| next()).collect();
            let (mut rf, mut if_) = (b.clone(), bi.clone());
            let (mut rs, mut is) = (b.clone(), bi.clone());
            fast.solve(&mut rf, &mut if_);
            slow.solve(&mut rs, &mut is);
            assert_eq!(bits(&rf), bits(&rs), "n = {n}");
            assert_eq!(bits(&if_), bits(&is), "n = {n}");
        }
    }

    /// T^-1 A^-1 T = [[gamma, 0, 0], [0, alpha, beta], [0, -beta, alpha]] (1e-12), with
    /// gamma = 3.6378342527444957 (RADAU5's constant).
    #[test]
    fn radau_eigen_decomposition() {
        let t = tableau();
        let lam = mul3(&t.tinv_ainv, &t.t);
        let want = [
            [t.gamma, 0.0, 0.0],
            [0.0, t.alpha, t.beta],
            [0.0, -t.beta, t.alpha],
        ];
        for i in 0..3 {
            for j in 0..3 {
                assert!((lam[i][j] - want[i][j]).abs() < 1e-12, "{lam:?}");
            }
        }
        assert!(
            (t.gamma - 3.637_834_252_744_496).abs() < 1e-13,
            "{}",
            t.gamma
        );
    }

    struct Stiff;
    impl OdeSystem for Stiff {
        fn dim(&self) -> usize {
            2
        }
        fn quad_dim(&self) -> usize {
            1
        }
        // y0' = -1e6 (y0 - cos s) - sin s, y1' = -y1: exact y0 = cos s, y1 = e^-s.
        fn rhs(&self, s: f64, y: &[f64], dy: &mut [f64]) {
            dy[0] = -1e6 * (y[0] - s.cos()) - s.sin();
            dy[1] = -y[1];
        }
        fn quad(&self, _s: f64, y: &[f64], dq: &mut [f64]) {
            dq[0] = y[1];
        }
    }

    /// A stiff test problem (stiffness 1e6) with a quadrature component, against the exact
    /// solution (1e-9).
    #[test]
    fn stiff_problem() {
        let tol = Tolerances {
            atol_y: 1e-11,
            rtol_y: 0.0,
            atol_q: 1e-11,
            rtol_q: 1e-11,
        };
        let outs = [0.0, 0.5, 1.0, 3.0, 10.0];
        let res = integrate(&Stiff, &[1.0, 1.0], &[0.0], &outs, tol, 1e-3).unwrap();
        for (s, (y, q)) in outs.iter().zip(&res) {
            assert!((y[0] - s.cos()).abs() < 1e-9, "{s}: {}", y[0]);
            assert!((y[1] - (-s).exp()).abs() < 1e-9, "{s}: {}", y[1]);
            assert!((q[0] - (1.0 - (-s).exp())).abs() < 1e-9, "{s}: {}", q[0]);
        }
    }
}
