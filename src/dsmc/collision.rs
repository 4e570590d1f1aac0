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

/// e for a pair already accepted with probability proportional to |g| (the "|g| first"
/// variant): the collision-weighted density of cos(theta) = g.e/|g| on the hemisphere is
/// 2 cos(theta), so cos(theta) = sqrt(U). Returns (e, g.e).
#[inline(always)]
pub fn impact_direction(g: [f64; 3], gn: f64, rng: &mut RunRng) -> ([f64; 3], f64) {
    let inv = 1.0 / gn;
    let n = [g[0] * inv, g[1] * inv, g[2] * inv];
    let u = rng.f64();
    let (ct, st) = (u.sqrt(), (1.0 - u).sqrt());
    let (cp, sp) = azimuth(rng);
    let (p, q) = basis(n);
    let e = [
        ct * n[0] + st * (cp * p[0] + sp * q[0]),
        ct * n[1] + st * (cp * p[1] + sp * q[1]),
        ct * n[2] + st * (cp * p[2] + sp * q[2]),
    ];
    (e, gn * ct)
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
            let gn = dot(g, g).sqrt();
            let (e, gne) = impact_direction(g, gn, &mut rng);
            assert!(gne > 0.0 && (dot(g, e) - gne).abs() < 1e-12);
            let p0: Vec<f64> = (0..3).map(|d| ma * va[d] + mb * vb[d]).collect();
            collide(&mut va, &mut vb, ma, mb, eps, e, gne);
            let g2 = [va[0] - vb[0], va[1] - vb[1], va[2] - vb[2]];
            assert!((dot(g2, e) + eps * gne).abs() < 1e-12);
            for d in 0..3 {
                assert!((ma * va[d] + mb * vb[d] - p0[d]).abs() < 1e-12);
            }
        }
    }

    /// cos(theta) = sqrt(U) has mean 2/3; 1e5 samples give a standard error of ~7e-4.
    #[test]
    fn impact_angle_distribution() {
        let mut rng = RunRng::new(5);
        let g = [0.3, -1.0, 2.0];
        let gn = dot(g, g).sqrt();
        let n = 100_000;
        let mean: f64 = (0..n)
            .map(|_| impact_direction(g, gn, &mut rng).1 / gn)
            .sum::<f64>()
            / n as f64;
        assert!(
            (mean - 2.0 / 3.0).abs() < 5.0 * (1.0f64 / 18.0 / n as f64).sqrt(),
            "{mean}"
        );
    }
}
