//! The drift of the RFM step (spec 1.4): x += (v - c) h with the symmetrising shift c
//! subtracted from the velocities, and the largest displacement squared since the
//! neighbour list's build, which decides the next rebuild. The loops here, portable and AVX2,
//! perform the same IEEE operations per particle, so any of them gives the same bits;
//! [`super::sim`] runs them in its drift pass, [`super::noise`] inside its kick's loop.

/// The drift x += (v - c) h of particles `x`, `v` (references `r`), and the largest
/// displacement squared since the list build, at least `m0`: four particles at a time
/// (independent maxima; a maximum is exact, so any cut into blocks gives the same value).
pub(super) fn drift_block<const D: usize>(
    x: &mut [[f64; D]],
    v: &mut [[f64; D]],
    r: &[[f64; D]],
    c: [f64; D],
    h: f64,
    m0: f64,
) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if D == 2
        && x.len() == v.len()
        && x.len() == r.len()
        && std::arch::is_x86_feature_detected!("avx2")
    {
        let c: &[f64] = &c;
        // SAFETY: AVX2 is available (checked just above); the three slices have equal lengths.
        return unsafe {
            drift2_avx2(
                x.as_flattened_mut(),
                v.as_flattened_mut(),
                r.as_flattened(),
                [c[0], c[1]],
                h,
                m0,
            )
        };
    }
    drift_portable(x, v, r, c, h, m0)
}

/// [`drift_block`] on any CPU (and the reference of its AVX2 path).
pub(super) fn drift_portable<const D: usize>(
    x: &mut [[f64; D]],
    v: &mut [[f64; D]],
    r: &[[f64; D]],
    c: [f64; D],
    h: f64,
    m0: f64,
) -> f64 {
    let mut m = [m0; 4];
    let mut xs = x.chunks_exact_mut(4);
    let mut vs = v.chunks_exact_mut(4);
    let mut rs = r.chunks_exact(4);
    for ((x4, v4), r4) in (&mut xs).zip(&mut vs).zip(&mut rs) {
        for p in 0..4 {
            let d2 = drift_one(&mut x4[p], &mut v4[p], &r4[p], c, h);
            if d2 > m[p] {
                m[p] = d2;
            }
        }
    }
    for ((x, v), r) in xs
        .into_remainder()
        .iter_mut()
        .zip(vs.into_remainder().iter_mut())
        .zip(rs.remainder())
    {
        let d2 = drift_one(x, v, r, c, h);
        if d2 > m[0] {
            m[0] = d2;
        }
    }
    largest(&m)
}

/// The drift of one particle, v -= c then x += v h, and its displacement squared since the
/// list build (0 + dx^2 + dy^2 ...): the operations every drift loop does per particle.
#[inline(always)]
pub(super) fn drift_one<const D: usize>(
    x: &mut [f64; D],
    v: &mut [f64; D],
    r: &[f64; D],
    c: [f64; D],
    h: f64,
) -> f64 {
    let mut d2 = 0.0;
    for k in 0..D {
        let vk = v[k] - c[k];
        v[k] = vk;
        x[k] += vk * h;
        let dd = x[k] - r[k];
        d2 += dd * dd;
    }
    d2
}

/// The largest of four lane maxima and 0 (a NaN lane never wins).
#[inline(always)]
pub(super) fn largest(lanes: &[f64; 4]) -> f64 {
    lanes
        .iter()
        .fold(0.0, |a: f64, &b| if b > a { b } else { a })
}

/// One round of [`drift2_avx2`]: particles k/2 .. k/2 + 4 of the flat slices drifted (x
/// stored, the drifted velocities returned, not stored), and their displacements squared
/// `[d0, d2, d1, d3]` (in the lanes of `hadd`).
///
/// # Safety
/// AVX2 (the caller's target feature: this is inlined into it); elements k .. k + 8 in
/// bounds of all three.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn drift_round(
    xp: *mut f64,
    vp: *const f64,
    rp: *const f64,
    k: usize,
    cv: std::arch::x86_64::__m256d,
    hv: std::arch::x86_64::__m256d,
) -> [std::arch::x86_64::__m256d; 3] {
    use std::arch::x86_64::*;
    let v0 = _mm256_sub_pd(_mm256_loadu_pd(vp.add(k)), cv);
    let v1 = _mm256_sub_pd(_mm256_loadu_pd(vp.add(k + 4)), cv);
    let x0 = _mm256_add_pd(_mm256_loadu_pd(xp.add(k)), _mm256_mul_pd(v0, hv));
    let x1 = _mm256_add_pd(_mm256_loadu_pd(xp.add(k + 4)), _mm256_mul_pd(v1, hv));
    _mm256_storeu_pd(xp.add(k), x0);
    _mm256_storeu_pd(xp.add(k + 4), x1);
    let d0 = _mm256_sub_pd(x0, _mm256_loadu_pd(rp.add(k)));
    let d1 = _mm256_sub_pd(x1, _mm256_loadu_pd(rp.add(k + 4)));
    // [dx0^2 + dy0^2, dx2^2 + dy2^2, dx1^2 + dy1^2, dx3^2 + dy3^2]
    let d2 = _mm256_hadd_pd(_mm256_mul_pd(d0, d0), _mm256_mul_pd(d1, d1));
    [v0, v1, d2]
}

/// Particle `k / 2` of the flat x, y slices drifted one at a time ([`drift_one`]): the
/// remainder of the AVX2 loops.
#[inline(always)]
pub(super) fn drift_one_flat(
    x: &mut [f64],
    v: &mut [f64],
    r: &[f64],
    k: usize,
    c: [f64; 2],
    h: f64,
) -> f64 {
    let (x, v, r) = (&mut x[k..k + 2], &mut v[k..k + 2], &r[k..k + 2]);
    drift_one(
        x.try_into().expect("two components"),
        v.try_into().expect("two components"),
        r.try_into().expect("two components"),
        c,
        h,
    )
}

/// The 1D drift x += (v - c) h.
pub(super) fn drift_1d<const D: usize>(
    x: &mut [[f64; D]],
    v: &mut [[f64; D]],
    c: [f64; D],
    h: f64,
) {
    for (x, v) in x.iter_mut().zip(v.iter_mut()) {
        for k in 0..D {
            let vk = v[k] - c[k];
            v[k] = vk;
            x[k] += vk * h;
        }
    }
}

/// [`drift_block`] in 2D with AVX2 (flat x, y pairs, all of the same length): two particles per
/// register, the same IEEE operations per component as the portable loop (v - c, then
/// x + (v h) as a product and a sum, never fused; d2 = dx^2 + dy^2, one rounded sum as
/// 0 + dx^2 + dy^2 gives), so the same positions and velocities bit for bit. The maxima: per
/// lane `max_pd(d2, m)`, which is `if d2 > m { m = d2 }` exactly (a NaN d2 never replaces m, a
/// NaN m stays), folded as the portable loop folds its lanes; which lane sees which particle
/// does not matter, since every lane starts at `m0` and the fold takes the largest non-NaN.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn drift2_avx2(
    x: &mut [f64],
    v: &mut [f64],
    r: &[f64],
    c: [f64; 2],
    h: f64,
    m0: f64,
) -> f64 {
    use std::arch::x86_64::*;
    let len = x.len();
    assert!(v.len() == len && r.len() == len && len % 2 == 0);
    let (xp, vp, rp) = (x.as_mut_ptr(), v.as_mut_ptr(), r.as_ptr());
    let cv = _mm256_setr_pd(c[0], c[1], c[0], c[1]);
    let hv = _mm256_set1_pd(h);
    let mut m = _mm256_set1_pd(m0);
    let mut k = 0;
    // Four particles (eight numbers) at a time.
    while k + 8 <= len {
        let [v0, v1, d2] = drift_round(xp, vp, rp, k, cv, hv);
        _mm256_storeu_pd(vp.add(k), v0);
        _mm256_storeu_pd(vp.add(k + 4), v1);
        m = _mm256_max_pd(d2, m);
        k += 8;
    }
    let mut lanes = [0.0f64; 4];
    _mm256_storeu_pd(lanes.as_mut_ptr(), m);
    // The rest, one particle at a time into lane 0 (as the portable loop's remainder).
    while k < len {
        let d2 = drift_one_flat(x, v, r, k, c, h);
        if d2 > lanes[0] {
            lanes[0] = d2;
        }
        k += 2;
    }
    largest(&lanes)
}
