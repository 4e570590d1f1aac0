//! The binary inelastic collision (41) and the inter-centre unit vector e.

use crate::rng::RunRng;

/// Orthonormal basis (p, q) perpendicular to the unit vector n (Duff et al., JCGT 2017).
#[inline(always)]
pub fn basis(n: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let sign = 1f64.copysign(n[2]);
    let a = -1.0 / (sign + n[2]);
    let b = n[0] * n[1] * a;
    (
        [1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]],
        [b, sign + n[1] * n[1] * a, -n[1]],
    )
}

/// A uniform direction in the plane: (cos phi, sin phi), by rejection from the square.
#[inline(always)]
pub fn azimuth(rng: &mut RunRng) -> (f64, f64) {
    loop {
        let w = rng.u64();
        let x = ((w >> 32) as f64 + 0.5) * (2.0 / 4294967296.0) - 1.0;
        let y = ((w & 0xffff_ffff) as f64 + 0.5) * (2.0 / 4294967296.0) - 1.0;
        let r2 = x * x + y * y;
        if r2 <= 1.0 {
            let inv = 1.0 / r2.sqrt();
            return (x * inv, y * inv);
        }
    }
}

/// The impulse direction for a pair already accepted with probability proportional to |g|
/// (the "|g| first" variant): the collision-weighted density of cos(theta) = g.e/|g| on the
/// hemisphere is 2 cos(theta). Malley's method draws it without trigonometry or
/// normalisation: a point (x, y) uniform in the unit disk (by rejection from the square)
/// lifted to the hemisphere, e = x p + y q + z n with z = sqrt(1 - x^2 - y^2) = cos(theta)
/// and (p, q, n = g/|g|) orthonormal. Returns w = (g.e) e and g.e = |g| z; the basis is
/// built from g unnormalised ([`basis`] times |g|), so the only divisions are in it.
#[inline(always)]
pub fn impact_impulse(g: [f64; 3], g2: f64, rng: &mut RunRng) -> ([f64; 3], f64) {
    let gn = g2.sqrt();
    let (x, y) = loop {
        let w = rng.u64();
        let x = ((w >> 32) as f64 + 0.5) * (2.0 / 4294967296.0) - 1.0;
        let y = ((w & 0xffff_ffff) as f64 + 0.5) * (2.0 / 4294967296.0) - 1.0;
        if x * x + y * y < 1.0 {
            break (x, y);
        }
    };
    let z = (1.0 - x * x - y * y).sqrt();
    // |g| times Duff et al.'s basis of n = g / |g|.
    let s = 1f64.copysign(g[2]);
    let a = -1.0 / (s * gn + g[2]);
    let b = g[0] * g[1] * a;
    let p = [gn + s * g[0] * g[0] * a, s * b, -s * g[0]];
    let q = [b, s * gn + g[1] * g[1] * a, -g[1]];
    let w = [
        z * (x * p[0] + y * q[0] + z * g[0]),
        z * (x * p[1] + y * q[1] + z * g[1]),
        z * (x * p[2] + y * q[2] + z * g[2]),
    ];
    (w, gn * z)
}

/// Apply (41) with the impulse w = (g.e) e: v_a -= m_b/(m_a+m_b) (1+eps) w,
/// v_b += m_a/(m_a+m_b) (1+eps) w.
#[inline(always)]
pub fn collide_impulse(
    va: &mut [f64; 3],
    vb: &mut [f64; 3],
    ma: f64,
    mb: f64,
    eps: f64,
    w: [f64; 3],
) {
    let j = (1.0 + eps) / (ma + mb);
    let (ja, jb) = (mb * j, ma * j);
    for d in 0..3 {
        va[d] -= ja * w[d];
        vb[d] += jb * w[d];
    }
}

/// A uniform direction on the unit sphere.
#[inline(always)]
pub fn uniform_direction(rng: &mut RunRng) -> [f64; 3] {
    let z = 2.0 * rng.f64() - 1.0;
    let s = (1.0 - z * z).max(0.0).sqrt();
    let (c, sn) = azimuth(rng);
    [s * c, s * sn, z]
}

/// Apply (41): v_a -= m_b/(m_a+m_b) (1+eps) (g.e) e, v_b += m_a/(m_a+m_b) (1+eps) (g.e) e,
/// with g = v_a - v_b and `gne` = g.e.
#[inline(always)]
pub fn collide(
    va: &mut [f64; 3],
    vb: &mut [f64; 3],
    ma: f64,
    mb: f64,
    eps: f64,
    e: [f64; 3],
    gne: f64,
) {
    let j = (1.0 + eps) * gne / (ma + mb);
    let (ja, jb) = (mb * j, ma * j);
    for d in 0..3 {
        va[d] -= ja * e[d];
        vb[d] += jb * e[d];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
        a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    }

    #[test]
    fn basis_is_orthonormal() {
        let mut rng = RunRng::new(1);
        for _ in 0..1000 {
            let n = uniform_direction(&mut rng);
            let (p, q) = basis(n);
            for (a, b, want) in [
                (n, p, 0.0),
                (n, q, 0.0),
                (p, q, 0.0),
                (p, p, 1.0),
                (q, q, 1.0),
            ] {
                assert!((dot(a, b) - want).abs() < 1e-12);
            }
        }
    }

    /// Normal relative velocity is reversed and scaled by eps; momentum is conserved.
    #[test]
    fn collision_rule() {
        let mut rng = RunRng::new(2);
        for &eps in &[0.0, 0.3, 1.0] {
            let mut va = [1.0, -2.0, 0.5];
            let mut vb = [-0.3, 0.7, 2.0];
            let (ma, mb) = (1.0, 7.0);
            let g = [va[0] - vb[0], va[1] - vb[1], va[2] - vb[2]];
            let (w, gne) = impact_impulse(g, dot(g, g), &mut rng);
            let e = [w[0] / gne, w[1] / gne, w[2] / gne];
            assert!(gne > 0.0 && (dot(g, e) - gne).abs() < 1e-12);
            assert!((dot(e, e) - 1.0).abs() < 1e-12, "e is a unit vector");
            let p0: Vec<f64> = (0..3).map(|d| ma * va[d] + mb * vb[d]).collect();
            collide_impulse(&mut va, &mut vb, ma, mb, eps, w);
            let g2 = [va[0] - vb[0], va[1] - vb[1], va[2] - vb[2]];
            assert!((dot(g2, e) + eps * gne).abs() < 1e-12);
            for d in 0..3 {
                assert!((ma * va[d] + mb * vb[d] - p0[d]).abs() < 1e-12);
            }
        }
    }

    /// cos(theta) with density 2 cos(theta) has mean 2/3 and variance 1/18; 1e5 samples give
    /// a standard error of ~7e-4 (5 of them allowed). The azimuth is uniform: the mean of
    /// e.p and of e.q is 0 (variance (1 - <cos^2>)/2 = 1/4 each), for g along each axis sign.
    #[test]
    fn impact_angle_distribution() {
        let mut rng = RunRng::new(5);
        for g in [[0.3, -1.0, 2.0], [0.0, 0.0, -1.5], [1e-3, 2.0, 1e-9]] {
            let gn = dot(g, g).sqrt();
            let n = [g[0] / gn, g[1] / gn, g[2] / gn];
            let (p, q) = basis(n);
            let count = 100_000;
            let (mut c, mut ep, mut eq) = (0.0, 0.0, 0.0);
            for _ in 0..count {
                let (w, gne) = impact_impulse(g, dot(g, g), &mut rng);
                let e = [w[0] / gne, w[1] / gne, w[2] / gne];
                assert!((dot(e, e) - 1.0).abs() < 1e-12);
                c += gne / gn;
                ep += dot(e, p);
                eq += dot(e, q);
            }
            let k = count as f64;
            let (c, ep, eq) = (c / k, ep / k, eq / k);
            assert!(
                (c - 2.0 / 3.0).abs() < 5.0 * (1.0 / 18.0 / k).sqrt(),
                "{g:?}: {c}"
            );
            for m in [ep, eq] {
                assert!(m.abs() < 5.0 * (0.25 / k).sqrt(), "{g:?}: azimuth mean {m}");
            }
        }
    }
}
