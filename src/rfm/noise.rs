//! The random force (spec 1.3): per step and particle a velocity kick with independent
//! N(0, 2 D h / M^2) components (the impulse eta h of (2.16)/(2.23) divided by M), made
//! symmetric so that the kicks of a step sum to zero in every component (2.18); total
//! momentum then stays at its initial value (zero) up to round-off, in 1D and in 2D
//! (spec 6.9).
//!
//! Normals come in bulk from the run's ChaCha8 stream ([`crate::rng::RunRng`]) by a
//! 256-layer ziggurat written over the raw 64-bit words (exact: a ziggurat sample is an
//! exact normal up to the rounding of its 53-bit uniform; the tables are solved to
//! round-off at start-up). A step draws all its normals at once, so the stream position between
//! steps is a function of the step count alone (checkpoints restore it exactly).

use std::sync::OnceLock;

use super::drift::largest;
use crate::rng::stream::{fill_counter, WordStream};

/// Layers of the normal ziggurat (the layer index is the low 8 bits of a word, the sign
/// bit 8, the value bits 11-63).
const LAYERS: usize = 256;
const SIGN_BIT: u64 = LAYERS as u64;

/// Ziggurat tables for the half-normal density f(x) = exp(-x^2/2) (Marsaglia & Tsang 2000)
/// with `LAYERS` layers of equal area `v`: `x[0] = v / f(r)` (the base strip, whose part
/// beyond `x[1] = r` stands for the tail), `x[i]` decreasing to `x[LAYERS] = 0`, and
/// `f[i] = f(x[i])`. `r` is solved (bisection on the top layer's area) so that all layers
/// have area `v` to round-off; so the method is exact.
struct Zig {
    /// `x[i] * 2^-53`: the candidate of layer i is `(w >> 11) * xs[i]`, uniform on [0, x[i]).
    xs: [f64; LAYERS],
    x: [f64; LAYERS + 1],
    f: [f64; LAYERS + 1],
    r: f64,
}

impl Zig {
    fn new() -> Self {
        let (r, x) = crate::rng::normal::ziggurat_layers();
        let f = std::array::from_fn(|i| (-0.5 * x[i] * x[i]).exp());
        let scale = 1.0 / (1u64 << 53) as f64;
        Zig {
            xs: std::array::from_fn(|i| x[i] * scale),
            x,
            f,
            r,
        }
    }

    fn get() -> &'static Zig {
        static Z: OnceLock<Zig> = OnceLock::new();
        Z.get_or_init(Zig::new)
    }

    /// The candidate of word `w` (layer: bits 0-7; sign: bit 8; value: bits 11-63) and
    /// whether it lies inside its layer's inner rectangle (then it is the sample; else,
    /// probability ~1.4%, [`normal_slow`](Self::normal_slow) finishes it).
    #[inline(always)]
    fn candidate(&self, w: u64) -> (f64, bool) {
        let i = (w & (LAYERS as u64 - 1)) as usize;
        let x = (w >> 11) as f64 * self.xs[i];
        (signed(x, w), x < self.x[i + 1])
    }

    /// The wedges, the tail, and rejections (which restart with a fresh word).
    #[cold]
    #[inline(never)]
    fn normal_slow(&self, rng: &mut WordStream, mut w: u64) -> f64 {
        let mut i = (w & (LAYERS as u64 - 1)) as usize;
        let mut x = (w >> 11) as f64 * self.xs[i];
        loop {
            if i == 0 {
                // Tail beyond r (Marsaglia 1964).
                loop {
                    let a = -rng.f64_open0().ln() / self.r;
                    let b = -rng.f64_open0().ln();
                    if 2.0 * b > a * a {
                        return signed(self.r + a, w);
                    }
                }
            }
            let y = self.f[i] + (self.f[i + 1] - self.f[i]) * rng.f64();
            if y < (-0.5 * x * x).exp() {
                return signed(x, w);
            }
            w = rng.u64();
            i = (w & (LAYERS as u64 - 1)) as usize;
            x = (w >> 11) as f64 * self.xs[i];
            if x < self.x[i + 1] {
                return signed(x, w);
            }
        }
    }
}

/// `x >= 0` with the sign bit `SIGN_BIT` of `w`.
#[inline(always)]
fn signed(x: f64, w: u64) -> f64 {
    f64::from_bits(x.to_bits() | ((w & SIGN_BIT) << (63 - SIGN_BIT.trailing_zeros())))
}

/// Fill `out` with independent standard normals (256-layer ziggurat): one 64-bit word
/// each, in order, then more words for the ~1.4% of candidates outside their inner
/// rectangle, in order of their slot. `words` and `rejected` are scratch space.
pub fn fill_normals_with(
    rng: &mut WordStream,
    out: &mut [f64],
    words: &mut Vec<u64>,
    rejected: &mut Vec<u32>,
) {
    let n = out.len();
    words.resize(n, 0);
    rejected.resize(n, 0);
    rng.fill(words);
    let z = Zig::get();
    // Branch-free pass: every slot gets its candidate; slots to finish are listed.
    let mut cnt = 0;
    for (j, (o, &w)) in out.iter_mut().zip(words.iter()).enumerate() {
        let (x, ok) = z.candidate(w);
        *o = x;
        rejected[cnt] = j as u32;
        cnt += !ok as usize;
    }
    for &j in &rejected[..cnt] {
        out[j as usize] = z.normal_slow(rng, words[j as usize]);
    }
}

/// [`fill_normals_with`] with its own scratch space.
pub fn fill_normals(rng: &mut WordStream, out: &mut [f64]) {
    fill_normals_with(rng, out, &mut Vec::new(), &mut Vec::new());
}

/// Particles per work block of the version-2 kicks: the step's slots are cut into blocks of
/// `KICK_BLOCK * D` slots (the last one shorter), fixed by N alone, whose sums are combined
/// in block order. A multiple of 256, so every block starts on a ChaCha8 chunk (16 blocks of 8
/// words, 2 slots per word) for D = 1 and 2.
pub const KICK_BLOCK: usize = 2048;

/// Particles per work block of stream version 4's kicks (normals addressed by storage slot):
/// finer blocks, so that a run's threads share its particles more evenly (N = 27 000 is 13.2
/// blocks of 2 048, 52.7 of 512). Also a multiple of 256.
pub const SLOT_KICK_BLOCK: usize = 512;

/// Bit that marks a continuation stream in stream version 2.
const CONTINUATION: u64 = 1 << 63;

/// 64-bit words per continuation refill (one ChaCha8 chunk of 16 blocks).
const CONT_WORDS: usize = 128;

/// Stream version 2's continuation words of one work block (see [`Kicks::kick_counter`]):
/// ChaCha8 with the run's key and stream `(step mod 2^63) | 2^63`, 64-bit words from block
/// `b 2^40` on (work block b), generated a chunk at a time.
struct Continuation {
    stream: u64,
    next_block: u64,
    buf: [u64; CONT_WORDS],
    idx: usize,
}

impl Continuation {
    fn new(step: u64, work_block: u64) -> Self {
        Continuation {
            stream: (step & !CONTINUATION) | CONTINUATION,
            next_block: work_block << 40,
            buf: [0; CONT_WORDS],
            idx: CONT_WORDS,
        }
    }

    #[inline(always)]
    fn next(&mut self, key: &[u32; 8]) -> u64 {
        if self.idx == CONT_WORDS {
            fill_counter(key, self.stream, self.next_block, &mut self.buf);
            self.next_block += (CONT_WORDS / 8) as u64;
            self.idx = 0;
        }
        let w = self.buf[self.idx];
        self.idx += 1;
        w
    }
}

/// Add `sigma z` to the velocities `v` (slot `i D + k` of `zs` to component k of particle i)
/// and return the sum of the z per component (eight partial sums in slot order, lane j
/// holding component j % D, then the lanes in order: independent dependency chains, fixed
/// order) and the largest |v|^2 after. The kick loop of both stream versions.
#[inline(always)]
fn add_kicks<const D: usize>(v: &mut [[f64; D]], zs: &[f64], sigma: f64) -> ([f64; D], f64) {
    let mut lanes = Lanes::new();
    lanes.add::<D>(v.as_flattened_mut(), zs, sigma);
    lanes.finish()
}

/// The running sums and maxima of [`add_kicks`]: eight lanes, lane j taking slot j mod 8.
struct Lanes {
    acc: [f64; 8],
    mx: [f64; 8],
}

impl Lanes {
    const W: usize = 8;

    fn new() -> Self {
        Lanes {
            acc: [0.0; 8],
            mx: [0.0; 8],
        }
    }

    /// Kick the slots `vf` (flattened velocities, whole particles) by `sigma zs`. Every call
    /// but the last must have a multiple of 8 slots (the slots continue the lanes); the last
    /// one's leftover particles go to lanes 0..D as in one call over all slots.
    #[inline(always)]
    fn add<const D: usize>(&mut self, vf: &mut [f64], zs: &[f64], sigma: f64) {
        self.add_with::<D, false>(vf, zs, sigma)
    }

    /// [`add`](Self::add); with `AVX2` (only where the CPU has it, from code compiled with
    /// it) the whole groups of 8 slots of 2D particles go four lanes per register: the same
    /// IEEE operations per lane (|v|^2 as x^2 + y^2 by a horizontal add; the maxima kept in
    /// another lane order, which a maximum does not see).
    #[inline(always)]
    fn add_with<const D: usize, const AVX2: bool>(
        &mut self,
        vf: &mut [f64],
        zs: &[f64],
        sigma: f64,
    ) {
        let n = vf.len().min(zs.len());
        let (vf, zs) = (&mut vf[..n], &zs[..n]);
        let mut done = 0;
        #[cfg(target_arch = "x86_64")]
        if AVX2 && D == 2 {
            // SAFETY: AVX2 is there (the caller's promise); D == 2.
            done = unsafe { self.groups2_avx2::<false, D>(vf, zs, sigma, &mut Drift::none()) };
        }
        self.add_rest::<D>(vf, zs, sigma, done);
    }

    /// [`add_with`](Self::add_with) with each particle drifted first (`d`: its positions
    /// and references, slot for slot with `vf`), as [`super::drift`] drifts them: v -= c,
    /// x += v h, and the displacement squared since the list build into `d.m`; the same
    /// operations per particle as the drift pass followed by the kick, so the same bits.
    #[inline(always)]
    fn drift_add_with<const D: usize, const AVX2: bool>(
        &mut self,
        d: &mut Drift<'_, D>,
        vf: &mut [f64],
        zs: &[f64],
        sigma: f64,
    ) {
        let n = vf.len();
        assert!(zs.len() == n && d.x.len() == n && d.r.len() == n && n % D == 0);
        let mut done = 0;
        #[cfg(target_arch = "x86_64")]
        if AVX2 && D == 2 {
            // SAFETY: AVX2 is there (the caller's promise); D == 2; the slices have length n.
            done = unsafe { self.groups2_avx2::<true, D>(vf, zs, sigma, d) };
        }
        for p in (done..n).step_by(D) {
            let d2 = super::drift::drift_one(
                (&mut d.x[p..p + D]).try_into().expect("D components"),
                (&mut vf[p..p + D]).try_into().expect("D components"),
                d.r[p..p + D].try_into().expect("D components"),
                d.c,
                d.h,
            );
            if d2 > d.m[0] {
                d.m[0] = d2;
            }
        }
        self.add_rest::<D>(vf, zs, sigma, done);
    }

    /// The whole groups of 8 slots (four 2D particles) of [`add_with`](Self::add_with) with
    /// AVX2, four lanes per register: the same IEEE operations per lane (|v|^2 as x^2 + y^2
    /// by a horizontal add; the maxima kept in another lane order, which a maximum does not
    /// see). With `DRIFT` each group is first drifted as `drift::drift2_avx2` drifts it (its
    /// maxima into `d.m`'s lanes). Returns the slots done.
    ///
    /// # Safety
    /// AVX2; D == 2 (`vf`, `zs` and, with `DRIFT`, `d.x` and `d.r` at least as long as
    /// `vf`).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn groups2_avx2<const DRIFT: bool, const D: usize>(
        &mut self,
        vf: &mut [f64],
        zs: &[f64],
        sigma: f64,
        d: &mut Drift<'_, D>,
    ) -> usize {
        use std::arch::x86_64::*;
        const W: usize = Lanes::W;
        let n = vf.len().min(zs.len());
        if DRIFT {
            assert!(d.x.len() >= n && d.r.len() >= n);
        }
        let mut done = 0;
        let (a, m) = (self.acc.as_mut_ptr(), self.mx.as_mut_ptr());
        let (mut acc0, mut acc1) = (_mm256_loadu_pd(a), _mm256_loadu_pd(a.add(4)));
        let (mut mx0, mut mx1) = (_mm256_loadu_pd(m), _mm256_loadu_pd(m.add(4)));
        let mut md = _mm256_loadu_pd(d.m.as_ptr());
        let s = _mm256_set1_pd(sigma);
        let (c0, c1) = if D == 2 {
            (d.c[0], d.c[D - 1])
        } else {
            (0.0, 0.0)
        };
        let cv = _mm256_setr_pd(c0, c1, c0, c1);
        let hv = _mm256_set1_pd(d.h);
        let (vp, zp) = (vf.as_mut_ptr(), zs.as_ptr());
        let (xp, rp) = (d.x.as_mut_ptr(), d.r.as_ptr());
        while done + W <= n {
            let z0 = _mm256_loadu_pd(zp.add(done));
            let z1 = _mm256_loadu_pd(zp.add(done + 4));
            acc0 = _mm256_add_pd(acc0, z0);
            acc1 = _mm256_add_pd(acc1, z1);
            let (v0, v1) = if DRIFT {
                let [v0, v1, d2] = super::drift::drift_round(xp, vp, rp, done, cv, hv);
                md = _mm256_max_pd(d2, md);
                (v0, v1)
            } else {
                (
                    _mm256_loadu_pd(vp.add(done)),
                    _mm256_loadu_pd(vp.add(done + 4)),
                )
            };
            let v0 = _mm256_add_pd(v0, _mm256_mul_pd(s, z0));
            let v1 = _mm256_add_pd(v1, _mm256_mul_pd(s, z1));
            _mm256_storeu_pd(vp.add(done), v0);
            _mm256_storeu_pd(vp.add(done + 4), v1);
            // Particles 0, 2, 1, 3 of the group: x^2 + y^2.
            let a2 = _mm256_hadd_pd(_mm256_mul_pd(v0, v0), _mm256_mul_pd(v1, v1));
            // max(a2, mx) is `a2 > mx ? a2 : mx`, the scalar test.
            if done & W == 0 {
                mx0 = _mm256_max_pd(a2, mx0);
            } else {
                mx1 = _mm256_max_pd(a2, mx1);
            }
            done += W;
        }
        _mm256_storeu_pd(a, acc0);
        _mm256_storeu_pd(a.add(4), acc1);
        _mm256_storeu_pd(m, mx0);
        _mm256_storeu_pd(m.add(4), mx1);
        _mm256_storeu_pd(d.m.as_mut_ptr(), md);
        done
    }

    /// The slots from `done` on of [`add_with`](Self::add_with), one at a time.
    #[inline(always)]
    fn add_rest<const D: usize>(&mut self, vf: &mut [f64], zs: &[f64], sigma: f64, done: usize) {
        const W: usize = Lanes::W;
        let n = vf.len().min(zs.len());
        let (vf, zs) = (&mut vf[..n], &zs[..n]);
        let (acc, mx) = (&mut self.acc, &mut self.mx);
        let mut vc = vf[done..].chunks_exact_mut(W);
        let mut zc = zs[done..].chunks_exact(W);
        for (vv, zz) in (&mut vc).zip(&mut zc) {
            for j in 0..W {
                acc[j] += zz[j];
                vv[j] += sigma * zz[j];
            }
            for p in 0..W / D {
                let mut a2 = 0.0;
                for k in 0..D {
                    a2 += vv[p * D + k] * vv[p * D + k];
                }
                if a2 > mx[p] {
                    mx[p] = a2;
                }
            }
        }
        for (vv, zz) in vc
            .into_remainder()
            .chunks_exact_mut(D)
            .zip(zc.remainder().chunks_exact(D))
        {
            let mut a2 = 0.0;
            for k in 0..D {
                acc[k] += zz[k];
                vv[k] += sigma * zz[k];
                a2 += vv[k] * vv[k];
            }
            if a2 > mx[0] {
                mx[0] = a2;
            }
        }
    }

    /// The sums of [`add_with`](Self::add_with) alone (the same lanes in the same order, so
    /// the same bits): for normals that are kicked later, in another order.
    #[inline(always)]
    fn add_sums<const D: usize>(&mut self, zs: &[f64]) {
        const W: usize = Lanes::W;
        let acc = &mut self.acc;
        let mut zc = zs.chunks_exact(W);
        for zz in &mut zc {
            for j in 0..W {
                acc[j] += zz[j];
            }
        }
        for zz in zc.remainder().chunks_exact(D) {
            for k in 0..D {
                acc[k] += zz[k];
            }
        }
    }

    /// The sum of the z per component (lanes in order) and the largest |v|^2.
    fn finish<const D: usize>(&self) -> ([f64; D], f64) {
        let mut sum = [0.0; D];
        for j in 0..Self::W {
            sum[j % D] += self.acc[j];
        }
        let m = self
            .mx
            .iter()
            .fold(0.0, |a: f64, &b| if b > a { b } else { a });
        (sum, m)
    }
}

/// The drift that [`Lanes::drift_add_with`] does before its kicks: positions `x` and
/// references `r` (flat, slot for slot with the velocities), the shift `c` and step `h`,
/// and the largest displacement squared so far in four lanes (from 0; the remainder's
/// particles in lane 0), folded as `drift::drift2_avx2` folds its lanes.
struct Drift<'a, const D: usize> {
    x: &'a mut [f64],
    r: &'a [f64],
    c: [f64; D],
    h: f64,
    m: [f64; 4],
}

impl<const D: usize> Drift<'_, D> {
    /// No drift (for [`Lanes::groups2_avx2`] without one).
    #[cfg(target_arch = "x86_64")]
    fn none() -> Self {
        Drift {
            x: &mut [],
            r: &[],
            c: [0.0; D],
            h: 0.0,
            m: [0.0; 4],
        }
    }
}

/// Slots per chunk of the fused version-2 kick: one ChaCha8 chunk (16 blocks of 8 words, two
/// slots per word).
const CHUNK_SLOTS: usize = 256;

/// One chunk's words and normals (3 KiB, in L1 throughout).
#[repr(C, align(64))]
struct Chunk {
    words: [u64; CHUNK_SLOTS / 2],
    z: [f64; CHUNK_SLOTS],
}

/// The drift that a work block's kick can make first ([`kick_block_counter`]): the block's
/// positions `x` and references `r` (particle for particle with its velocities), the shift
/// `c` and the step `h`.
struct BlockDrift<'a, const D: usize> {
    x: &'a mut [[f64; D]],
    r: &'a [[f64; D]],
    c: [f64; D],
    h: f64,
}

/// One version-2 work block: particles `v` (the first is particle `p0`) of step `step` get
/// `sigma z`; returns the sum of their z per component (eight partial sums in slot order,
/// lane j holding component j % D, then the lanes in order) and the largest |v|^2 after.
///
/// One fused pass, a ChaCha8 chunk (256 slots) at a time: its words, their candidates, its
/// slow slots finished in slot order from the block's continuation, and the kicks, all in
/// L1 (the same operations in the same order as words, candidates, slow slots and kicks
/// over the whole block: bit-identical, `fused_kicks_match_the_reference`). AVX2 when the
/// CPU has it.
///
/// With `drift`, each particle is first drifted just before its kick (x += (v - c) h,
/// v -= c, as the drift pass does it: one pass over the particles instead of two, the same
/// bits), and the largest displacement squared from the references (0 if none is larger,
/// as `drift::drift_block` from 0 gives it) comes back too; else that is 0.
fn kick_block_counter<const D: usize>(
    key: &[u32; 8],
    step: u64,
    b: usize,
    p0: usize,
    v: &mut [[f64; D]],
    sigma: f64,
    drift: Option<BlockDrift<'_, D>>,
) -> (([f64; D], f64), f64) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2.
            return unsafe { kick_block_avx2(key, step, b, p0, v, sigma, drift) };
        }
    }
    kick_block_body::<D, false>(key, step, b, p0, v, sigma, drift)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn kick_block_avx2<const D: usize>(
    key: &[u32; 8],
    step: u64,
    b: usize,
    p0: usize,
    v: &mut [[f64; D]],
    sigma: f64,
    drift: Option<BlockDrift<'_, D>>,
) -> (([f64; D], f64), f64) {
    kick_block_body::<D, true>(key, step, b, p0, v, sigma, drift)
}

#[inline(always)]
fn kick_block_body<const D: usize, const AVX2: bool>(
    key: &[u32; 8],
    step: u64,
    b: usize,
    p0: usize,
    v: &mut [[f64; D]],
    sigma: f64,
    drift: Option<BlockDrift<'_, D>>,
) -> (([f64; D], f64), f64) {
    let mut lanes = Lanes::new();
    let mut m = [0.0; 4];
    let vf = v.as_flattened_mut();
    match drift {
        None => block_normals::<D, AVX2, false>(key, step, b, p0, vf, &mut |vc, z| {
            lanes.add_with::<D, AVX2>(vc, z, sigma)
        }),
        Some(BlockDrift { x, r, c, h }) => {
            assert!(x.len() == vf.len() / D && r.len() == x.len());
            let (xf, rf) = (x.as_flattened_mut(), r.as_flattened());
            let mut at = 0;
            block_normals::<D, AVX2, false>(key, step, b, p0, vf, &mut |vc, z| {
                let n = vc.len();
                let mut d = Drift {
                    x: &mut xf[at..at + n],
                    r: &rf[at..at + n],
                    c,
                    h,
                    m,
                };
                lanes.drift_add_with::<D, AVX2>(&mut d, vc, z, sigma);
                m = d.m;
                at += n;
            });
        }
    }
    (lanes.finish(), largest(&m))
}

/// The normals of one version-2 work block (block `b`, its first particle `p0`), a ChaCha8
/// chunk (256 slots) at a time: its words, their candidates, its slow slots finished in slot
/// order from the block's continuation (the continuation of work block `b`); `sink` gets each chunk's slots of `out` (whole particles)
/// with their normals (with `INTO_OUT` the normals are written into `out` itself, and
/// `sink` gets an empty slice and them).
#[inline(always)]
fn block_normals<const D: usize, const AVX2: bool, const INTO_OUT: bool>(
    key: &[u32; 8],
    step: u64,
    b: usize,
    p0: usize,
    out: &mut [f64],
    sink: &mut impl FnMut(&mut [f64], &[f64]),
) {
    const { assert!(D >= 1 && CHUNK_SLOTS % D == 0 && 16 % D == 0) };
    let first = (p0 * D) as u64;
    // Two slots per 64-bit word: slot j's candidate is half j % 2 of word j / 2.
    debug_assert_eq!(first % 16, 0);
    let mut block = first / 16;
    let stream = step & !CONTINUATION;
    // The slow slots, in slot order, read the work block's continuation words in turn.
    let mut cont = Continuation::new(step, b as u64);
    let mut c = Chunk {
        words: [0; CHUNK_SLOTS / 2],
        z: [0.0; CHUNK_SLOTS],
    };
    let mut masks = [0u64; 4];
    for vc in out.chunks_mut(CHUNK_SLOTS) {
        fill_counter(key, stream, block, &mut c.words);
        block += (CHUNK_SLOTS / 16) as u64;
        if INTO_OUT {
            // The normals are the output itself.
            chunk_normals::<AVX2>(key, &c.words, vc, &mut masks, &mut cont);
            sink(&mut [], vc);
        } else {
            let z = &mut c.z[..vc.len()];
            chunk_normals::<AVX2>(key, &c.words, z, &mut masks, &mut cont);
            sink(vc, z);
        }
    }
}

/// One chunk's normals `z` from its words: the candidates, then the slow slots finished in
/// slot order from the continuation `cont`.
#[inline(always)]
fn chunk_normals<const AVX2: bool>(
    key: &[u32; 8],
    words: &[u64; CHUNK_SLOTS / 2],
    z: &mut [f64],
    masks: &mut [u64; 4],
    cont: &mut Continuation,
) {
    crate::rng::normal::chunk_candidates::<AVX2>(words, z, masks);
    for (q, &m) in masks.iter().enumerate() {
        let mut m = m;
        while m != 0 {
            let j = 64 * q + m.trailing_zeros() as usize;
            let half = (words[j / 2] >> (32 * (j % 2))) as u32;
            z[j] = crate::rng::normal::finish_slow(half, &mut || cont.next(key));
            m &= m - 1;
        }
    }
}

/// Work block `b`'s normals of step `step` into `z` (its D slots per particle, in slot
/// order) and their sum per component as [`kick_block_counter`] sums them.
fn normals_block_counter<const D: usize>(
    key: &[u32; 8],
    step: u64,
    b: usize,
    p0: usize,
    z: &mut [f64],
) -> [f64; D] {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2.
            return unsafe { normals_block_avx2::<D>(key, step, b, p0, z) };
        }
    }
    normals_block_body::<D, false>(key, step, b, p0, z)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn normals_block_avx2<const D: usize>(
    key: &[u32; 8],
    step: u64,
    b: usize,
    p0: usize,
    z: &mut [f64],
) -> [f64; D] {
    normals_block_body::<D, true>(key, step, b, p0, z)
}

#[inline(always)]
fn normals_block_body<const D: usize, const AVX2: bool>(
    key: &[u32; 8],
    step: u64,
    b: usize,
    p0: usize,
    z: &mut [f64],
) -> [f64; D] {
    let mut lanes = Lanes::new();
    block_normals::<D, AVX2, true>(key, step, b, p0, z, &mut |_, zn| lanes.add_sums::<D>(zn));
    lanes.finish::<D>().0
}

/// How many particles ahead [`kick_gathered`] asks for its normals.
pub(super) const GATHER_AHEAD: usize = 16;

/// Kick particles `v` by `sigma z[id D + k]` (particle `id` = `ids[i]` of the normals `z` in
/// slot order, component k): the same operations per particle as [`Lanes::add_with`]
/// (v + sigma z, then |v|^2 as 0 + x^2 + y^2); returns the largest |v|^2 after, which no
/// order of the particles changes. (The drift pass of a run stored by cell kicks inside its
/// drift loop, `sim::drift_kick_block`, with these operations; this loop serves the first kick
/// of an `advance` call and CPUs without AVX2.)
fn kick_gathered<const D: usize>(v: &mut [[f64; D]], ids: &[u32], z: &[f64], sigma: f64) -> f64 {
    let mut m: f64 = 0.0;
    for (i, (vv, &id)) in v.iter_mut().zip(ids).enumerate() {
        #[cfg(target_arch = "x86_64")]
        if let Some(&ahead) = ids.get(i + GATHER_AHEAD) {
            // SAFETY: a prefetch never faults; the address is inside z for a valid id.
            unsafe {
                use std::arch::x86_64::*;
                _mm_prefetch::<_MM_HINT_T0>(
                    z.as_ptr().wrapping_add(ahead as usize * D) as *const i8
                );
            }
        }
        let zz = &z[id as usize * D..id as usize * D + D];
        let mut a2 = 0.0;
        for k in 0..D {
            vv[k] += sigma * zz[k];
            a2 += vv[k] * vv[k];
        }
        if a2 > m {
            m = a2;
        }
    }
    m
}

/// Generates the symmetrised kicks of one step.
pub struct Kicks {
    /// Standard deviation sqrt(2 D h) / M of one component.
    pub sigma: f64,
    buf: Vec<f64>,
    words: Vec<u64>,
    rejected: Vec<u32>,
    /// Stream version 2: the ChaCha8 key of the run's seed.
    key: [u32; 8],
    /// Particles per work block of the counter-addressed kicks: [`KICK_BLOCK`], or
    /// [`SLOT_KICK_BLOCK`] for stream version 4.
    block: usize,
}

impl Kicks {
    pub fn new(noise_strength: f64, mass: f64, h: f64) -> Self {
        Kicks {
            sigma: (2.0 * noise_strength * h).sqrt() / mass,
            buf: Vec::new(),
            words: Vec::new(),
            rejected: Vec::new(),
            key: crate::rng::stream::key_of(0),
            block: KICK_BLOCK,
        }
    }

    /// Cut the counter-addressed kicks into work blocks of `block` particles (a multiple of
    /// 256, a ChaCha8 chunk's slots; part of the stream's definition).
    pub fn set_block(&mut self, block: usize) {
        assert!(
            block > 0 && block.is_multiple_of(CHUNK_SLOTS),
            "work block of {block} particles"
        );
        self.block = block;
    }

    /// Key the version-2 noise by the run's seed.
    pub fn set_seed(&mut self, seed: u64) {
        self.key = crate::rng::stream::key_of(seed);
    }

    /// Stream version 2: [`kick`](Self::kick) with counter-addressed normals. The normal of
    /// step `step` (the number of steps before it) and slot `j = i D + k` (particle i,
    /// component k) is a function of (seed, step, j) alone:
    ///
    /// - its candidate is the 32-bit half `j % 2` (0: low) of 64-bit word `j / 2` of ChaCha8
    ///   with the key of the seed ([`crate::rng::stream::key_of`]) and stream `step mod 2^63`
    ///   (top bit clear), read from block 0 (`fill_counter(key, step, 0, ..)[j / 2]`); the
    ///   256-layer ziggurat on 32 bits of [`crate::rng::normal`] maps it (two normals per
    ///   word: half the generator's work of version 1's one word per normal);
    /// - when the candidate falls outside its layer's inner rectangle (~1.5 %), the wedge,
    ///   tail and rejection words ([`crate::rng::normal::finish_slow`]) come from the
    ///   continuation of the slot's work block b (particles `b B ..`, B = [`KICK_BLOCK`], or
    ///   [`SLOT_KICK_BLOCK`] with stream version 4's [`set_block`](Self::set_block)): ChaCha8 with
    ///   the same key and stream `(step mod 2^63) | 2^63` (top bit set), 64-bit words from
    ///   block `b 2^40` on, taken in turn by the block's slow slots in slot order.
    ///
    /// Candidate and continuation streams differ in their top bit, steps in the rest; within
    /// a continuation stream work block b owns blocks `b 2^40 .. (b + 1) 2^40` (2^43 words;
    /// work blocks below 2^24, i.e. N < 2^35 with blocks of 2048, 2^33 with 512), so no two work blocks or steps share a word,
    /// and within a work block the words are taken in slot order (fixed by N, never by the
    /// thread count). The sum of the
    /// normals (for the symmetrisation) is taken per work block of B particles
    /// and combined in block order: a function of N, never of the thread count. With
    /// `parallel`, the blocks run on the current rayon pool or team (same result).
    pub fn kick_counter<const D: usize>(
        &mut self,
        step: u64,
        v: &mut [[f64; D]],
        parallel: bool,
    ) -> ([f64; D], f64) {
        let n = v.len();
        let nb = n.div_ceil(self.block);
        let k = self.counter_blocks();
        let mut res = vec![([0.0; D], 0.0); nb];
        let mut jobs: Vec<_> = v
            .chunks_mut(self.block)
            .zip(res.iter_mut())
            .enumerate()
            .collect();
        let parts = if parallel {
            rayon::current_num_threads()
        } else {
            1
        };
        super::team::run_parts(&mut jobs, parts, &|(b, (vb, r))| **r = k.kick(step, *b, vb));
        k.combine(res.into_iter(), n)
    }

    /// Whether the model has noise at all.
    pub fn active(&self) -> bool {
        self.sigma > 0.0
    }

    /// Add one step's kicks `sigma z` to the velocities `v` (N particles of D components;
    /// the normals are drawn particle by particle, components innermost) *without* the
    /// symmetrisation, and return `(c, m)`: the common shift `c = sigma mean(z)` that the
    /// caller must still subtract from every velocity (the symmetrised kick is
    /// `sigma (z - mean(z))`), and the largest |v|^2 of the unshifted kicked velocities.
    /// Pair flows depend on velocity differences only, so the caller may defer the shift.
    pub fn kick<const D: usize>(
        &mut self,
        rng: &mut WordStream,
        v: &mut [[f64; D]],
    ) -> ([f64; D], f64) {
        let n = v.len();
        self.buf.resize(n * D, 0.0);
        fill_normals_with(rng, &mut self.buf, &mut self.words, &mut self.rejected);
        let s = self.sigma;
        let (sum, m) = add_kicks(v, &self.buf, s);
        (std::array::from_fn(|k| s * (sum[k] / n as f64)), m)
    }
}

/// Stream version 2's kicks for a caller that runs the work blocks itself (the RFM step's
/// fused drift and kick pass): the same blocks, the same sums combined in the same order as
/// [`Kicks::kick_counter`], so the same bits.
pub(super) struct CounterBlocks<'a> {
    key: &'a [u32; 8],
    sigma: f64,
    block: usize,
}

impl CounterBlocks<'_> {
    /// Standard deviation of one component of a kick.
    pub(super) fn sigma(&self) -> f64 {
        self.sigma
    }

    /// Particles per work block (block b holds particles `b block ..`).
    pub(super) fn block(&self) -> usize {
        self.block
    }
}

impl Kicks {
    /// The work blocks of [`Kicks::kick_counter`], for a caller that runs them itself (and
    /// for `kick_counter`, so both combine the blocks the same way).
    pub(super) fn counter_blocks(&self) -> CounterBlocks<'_> {
        CounterBlocks {
            key: &self.key,
            sigma: self.sigma,
            block: self.block,
        }
    }
}

impl CounterBlocks<'_> {
    /// Work block `b` (particles `v`, the first being particle `b block`) of step
    /// `step`, as [`Kicks::kick_counter`] kicks it: its sum of z per component and the
    /// largest |v|^2 after.
    pub(super) fn kick<const D: usize>(
        &self,
        step: u64,
        b: usize,
        v: &mut [[f64; D]],
    ) -> ([f64; D], f64) {
        kick_block_counter(self.key, step, b, b * self.block, v, self.sigma, None).0
    }

    /// [`kick`](Self::kick) with each particle of the block drifted just before its kick
    /// (positions `x`, references `r`, shift `c`, step `h`: the drift pass's operations):
    /// the kick's result and the largest displacement squared (from 0), the bits of
    /// `drift::drift_block` and then `kick`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn drift_kick<const D: usize>(
        &self,
        step: u64,
        b: usize,
        x: &mut [[f64; D]],
        v: &mut [[f64; D]],
        r: &[[f64; D]],
        c: [f64; D],
        h: f64,
    ) -> (([f64; D], f64), f64) {
        let drift = Some(BlockDrift { x, r, c, h });
        kick_block_counter(self.key, step, b, b * self.block, v, self.sigma, drift)
    }

    /// Work block `b`'s normals of step `step` (slots `b block D ..`) into `z`, and
    /// their sum per component as [`kick`](Self::kick) takes it: for runs that keep their
    /// particles in another order than their slots.
    pub(super) fn normals<const D: usize>(&self, step: u64, b: usize, z: &mut [f64]) -> [f64; D] {
        normals_block_counter::<D>(self.key, step, b, b * self.block, z)
    }

    /// Kick particles `v`, particle i taking the normals of slot particle `ids[i]` from `z`
    /// (all of a step's normals, in slot order): the largest |v|^2 after.
    pub(super) fn kick_gathered<const D: usize>(
        &self,
        v: &mut [[f64; D]],
        ids: &[u32],
        z: &[f64],
    ) -> f64 {
        kick_gathered(v, ids, z, self.sigma)
    }

    /// The blocks' results, in block order, combined as [`Kicks::kick_counter`] combines
    /// them: the shift c of N = `n` particles and the largest |v|^2.
    pub(super) fn combine<const D: usize>(
        &self,
        res: impl Iterator<Item = ([f64; D], f64)>,
        n: usize,
    ) -> ([f64; D], f64) {
        let mut sum = [0.0; D];
        let mut m: f64 = 0.0;
        for (bs, bm) in res {
            for k in 0..D {
                sum[k] += bs[k];
            }
            if bm > m {
                m = bm;
            }
        }
        (std::array::from_fn(|k| self.sigma * (sum[k] / n as f64)), m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Stream version 2's work block written out the straightforward way (545c337's order of
    /// operations, one slot at a time): all of the block's words, each slot's normal by
    /// `finish_slow` (which draws words only for slow slots), the continuation's words from
    /// one `fill_counter` of its stream, then the kick loop with its eight lanes. Also
    /// returns the number of slow slots and of those in the tail layer (layer 0).
    fn reference_block<const D: usize>(
        key: &[u32; 8],
        step: u64,
        b: usize,
        p0: usize,
        v: &mut [[f64; D]],
        sigma: f64,
    ) -> (([f64; D], f64), usize, usize) {
        let vf = v.as_flattened_mut();
        let n = vf.len();
        let mut words = vec![0u64; n.div_ceil(2)];
        fill_counter(key, step & !CONTINUATION, (p0 * D / 16) as u64, &mut words);
        let mut more = vec![0u64; 4096];
        fill_counter(key, step | CONTINUATION, (b as u64) << 40, &mut more);
        let mut taken = 0;
        let (mut slow, mut tail) = (0, 0);
        let z: Vec<f64> = (0..n)
            .map(|j| {
                let h = (words[j / 2] >> (32 * (j % 2))) as u32;
                let before = taken;
                let z = crate::rng::normal::finish_slow(h, &mut || {
                    taken += 1;
                    more[taken - 1]
                });
                if taken > before {
                    slow += 1;
                    tail += (h & 255 == 0) as usize;
                }
                z
            })
            .collect();
        let mut acc = [0.0; 8];
        let mut mx = [0.0; 8];
        for (i, zz) in z.iter().enumerate() {
            let lane = if i < n - n % 8 { i % 8 } else { i % D };
            acc[lane] += zz;
            vf[i] += sigma * zz;
            if i % D == D - 1 {
                let p = i / D;
                let a2 = (0..D).fold(0.0, |a, k| a + vf[p * D + k] * vf[p * D + k]);
                let l = if i < n - n % 8 { p % (8 / D) } else { 0 };
                if a2 > mx[l] {
                    mx[l] = a2;
                }
            }
        }
        let mut sum = [0.0; D];
        for j in 0..8 {
            sum[j % D] += acc[j];
        }
        let m = mx.iter().fold(0.0, |a: f64, &b| if b > a { b } else { a });
        ((sum, m), slow, tail)
    }

    /// The fused kick (the path this CPU takes, and the portable one), and the normals made
    /// ahead and kicked onto particles in another storage order, give the reference's
    /// bits: velocities, sums and maximum, in 1D and 2D, for whole work blocks and short last
    /// ones (lengths not a multiple of 8, of a chunk, of a word), steps with and without the
    /// top bit, several seeds and work blocks, work blocks of `block` particles (stream
    /// versions 2 and 4); slow and tail slots occur.
    fn fused_matches<const D: usize>(
        seed: u64,
        step: u64,
        block: usize,
        b: usize,
        n: usize,
    ) -> (usize, usize) {
        let p0 = b * block;
        let key = crate::rng::stream::key_of(seed);
        let mut r = crate::rng::RunRng::new(seed ^ step);
        let v0: Vec<[f64; D]> = (0..n)
            .map(|_| std::array::from_fn(|_| r.f64() - 0.5))
            .collect();
        let sigma = 0.37;
        let mut want = v0.clone();
        let (wr, slow, tail) = reference_block(&key, step, b, p0, &mut want, sigma);
        let bits =
            |v: &[[f64; D]]| -> Vec<u64> { v.as_flattened().iter().map(|x| x.to_bits()).collect() };
        let same = |(s, m): ([f64; D], f64), what: &str| {
            let (ws, wm) = wr;
            for k in 0..D {
                assert_eq!(s[k].to_bits(), ws[k].to_bits(), "{what}: sum {k}");
            }
            assert_eq!(m.to_bits(), wm.to_bits(), "{what}: max");
        };
        let what = format!("D {D} seed {seed} step {step} block {b} of {block} n {n}");
        let mut got = v0.clone();
        same(
            kick_block_counter(&key, step, b, p0, &mut got, sigma, None).0,
            &what,
        );
        assert!(bits(&got) == bits(&want), "{what}: velocities");
        let mut got = v0.clone();
        same(
            kick_block_body::<D, false>(&key, step, b, p0, &mut got, sigma, None).0,
            &what,
        );
        assert!(bits(&got) == bits(&want), "{what}: portable velocities");
        // The normals made ahead into a buffer (slot order) and kicked onto particles stored
        // in slot order and in reverse order: the same velocities, sums and maximum.
        let k = CounterBlocks {
            key: &key,
            sigma,
            block,
        };
        let mut z = vec![0.0; n * D];
        for avx2 in [true, false] {
            z.fill(f64::NAN);
            let sums = if avx2 {
                k.normals::<D>(step, b, &mut z)
            } else {
                normals_block_body::<D, false>(&key, step, b, p0, &mut z)
            };
            for reversed in [false, true] {
                let ids: Vec<u32> = if reversed {
                    (0..n as u32).rev().collect()
                } else {
                    (0..n as u32).collect()
                };
                let mut got: Vec<[f64; D]> = ids.iter().map(|&p| v0[p as usize]).collect();
                let m = k.kick_gathered(&mut got, &ids, &z);
                same(
                    (sums, m),
                    &format!("{what} buffered (avx2 {avx2}, reversed {reversed})"),
                );
                let mut by_id = got.clone();
                for (t, &p) in ids.iter().enumerate() {
                    by_id[p as usize] = got[t];
                }
                assert!(bits(&by_id) == bits(&want), "{what}: buffered velocities");
            }
        }
        // The drift pass's drift and then the kick, in one pass (`drift_kick`, AVX2 where
        // the CPU has it, and portable): the same positions, velocities, sums, maximum |v|^2
        // and largest displacement squared.
        let x0: Vec<[f64; D]> = (0..n).map(|_| std::array::from_fn(|_| r.f64())).collect();
        let xr: Vec<[f64; D]> = (0..n).map(|_| std::array::from_fn(|_| r.f64())).collect();
        let c: [f64; D] = std::array::from_fn(|k| 0.01 * (k as f64 + 1.0));
        let h = 0.37;
        let (mut wx, mut wv) = (x0.clone(), v0.clone());
        let wm = super::super::drift::drift_block(&mut wx, &mut wv, &xr, c, h, 0.0);
        let (wk, _, _) = reference_block(&key, step, b, p0, &mut wv, sigma);
        for avx2 in [true, false] {
            let (mut gx, mut gv) = (x0.clone(), v0.clone());
            let (gk, gm) = if avx2 {
                k.drift_kick(step, b, &mut gx, &mut gv, &xr, c, h)
            } else {
                let drift = Some(BlockDrift {
                    x: &mut gx,
                    r: &xr,
                    c,
                    h,
                });
                kick_block_body::<D, false>(&key, step, b, p0, &mut gv, sigma, drift)
            };
            let what = format!("{what} drift and kick (avx2 {avx2})");
            assert!(bits(&gx) == bits(&wx), "{what}: positions");
            assert!(bits(&gv) == bits(&wv), "{what}: velocities");
            for kk in 0..D {
                assert_eq!(gk.0[kk].to_bits(), wk.0[kk].to_bits(), "{what}: sum {kk}");
            }
            assert_eq!(gk.1.to_bits(), wk.1.to_bits(), "{what}: max |v|^2");
            assert_eq!(gm.to_bits(), wm.to_bits(), "{what}: largest displacement");
        }
        (slow, tail)
    }

    /// An id past the normals panics (the index; the AVX2 drift-and-kick pass checks its
    /// rounds, `sim::tests::drift_and_kick_refuse_an_id_past_the_normals`).
    #[test]
    fn gathered_kick_refuses_an_id_past_the_normals() {
        let ids = [0u32, 1, 2, 3, 4, 5, 8, 6];
        let z = vec![1.0; 16];
        let mut v = vec![[0.0f64; 2]; 8];
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            kick_gathered(&mut v, &ids, &z, 1.0)
        }));
        assert!(r.is_err(), "an id past the normals must panic");
    }

    #[test]
    fn fused_kicks_match_the_reference() {
        let (mut slow, mut tail) = (0, 0);
        for seed in [0u64, 5, 0xdead_beef] {
            for step in [0u64, 1, 977, (1 << 63) + 3, u64::MAX] {
                for block in [KICK_BLOCK, SLOT_KICK_BLOCK] {
                    for (b, n) in [
                        (0, block),
                        (3, block),
                        (1, 1),
                        (2, 7),
                        (0, 129),
                        (5, 1000),
                        (1, 2047),
                    ] {
                        let n = if n > block { block - 1 } else { n };
                        let (s, t) = fused_matches::<2>(seed, step, block, b, n);
                        slow += s;
                        tail += t;
                        let (s, t) = fused_matches::<1>(seed, step, block, b, n);
                        slow += s;
                        tail += t;
                    }
                }
            }
        }
        eprintln!("slow slots {slow}, of them tail {tail}");
        assert!(slow > 1000 && tail > 3, "slow {slow}, tail {tail}");
    }

    /// `Kicks::kick_counter` over several work blocks (a short last one) on one thread and on
    /// a 3-thread pool is the reference's blocks combined in block order, for work blocks of
    /// stream version 2 and of version 4.
    #[test]
    fn kick_counter_is_the_reference_blocks_in_order() {
        for block in [KICK_BLOCK, SLOT_KICK_BLOCK] {
            kick_counter_is_the_reference(block);
        }
    }

    fn kick_counter_is_the_reference(block: usize) {
        let n = 3 * block + 777;
        let mut k = Kicks::new(0.5, 1.0, 0.3);
        k.set_seed(11);
        k.set_block(block);
        let key = crate::rng::stream::key_of(11);
        let mut r = crate::rng::RunRng::new(3);
        let v0: Vec<[f64; 2]> = (0..n).map(|_| [r.f64(), -r.f64()]).collect();
        let mut want = v0.clone();
        let mut sum = [0.0; 2];
        let mut m: f64 = 0.0;
        for (b, vb) in want.chunks_mut(block).enumerate() {
            let ((s, bm), _, _) = reference_block(&key, 42, b, b * block, vb, k.sigma);
            sum[0] += s[0];
            sum[1] += s[1];
            m = m.max(bm);
        }
        let shift = [k.sigma * (sum[0] / n as f64), k.sigma * (sum[1] / n as f64)];
        let mut got = v0.clone();
        let (c, gm) = k.kick_counter(42, &mut got, false);
        assert_eq!(c.map(f64::to_bits), shift.map(f64::to_bits));
        assert_eq!(gm.to_bits(), m.to_bits());
        assert!(got == want);
        let mut par = v0.clone();
        let (c, gm) = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .unwrap()
            .install(|| k.kick_counter(42, &mut par, true));
        assert_eq!(c.map(f64::to_bits), shift.map(f64::to_bits));
        assert_eq!(gm.to_bits(), m.to_bits());
        assert!(par == want);
    }

    /// Mean, variance and fourth moment of 1e6 bulk normals within 5 standard errors
    /// (SE: 1e-3, 1.41e-3 and 9.8e-3 for 3).
    #[test]
    fn bulk_normals_have_normal_moments() {
        let mut rng = WordStream::from_rng(&crate::rng::RunRng::new(5));
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
        // Beyond the ziggurat's base strip (r = 3.654): P(|z| > 3.7) = 2.1564e-4, SE 1.47e-5.
        let far = b.iter().filter(|z| z.abs() > 3.7).count() as f64 / n;
        assert!((far - 2.1564e-4).abs() < 5.0 * 1.47e-5, "{far}");
    }

    /// Stream version 2's kicks (sigma = 1, zero velocities: v = z): 1e6 normals (2 steps of
    /// 250 000 2D particles) have normal moments and tails within 5 standard errors (as
    /// above; the tails need the slots' continuation words); slot j at steps 0 and 1, and
    /// neighbouring slots, are uncorrelated within 5 sigma (SE 1/sqrt(n)); the blocks on a
    /// 3-thread pool give the same bits as on one thread.
    /// The same for stream version 4's work blocks.
    #[test]
    fn counter_normals_have_normal_moments_and_are_independent() {
        for block in [KICK_BLOCK, SLOT_KICK_BLOCK] {
            counter_normals_are_normal(block);
        }
    }

    fn counter_normals_are_normal(block: usize) {
        let n = 250_000;
        let mut k = Kicks::new(0.5, 1.0, 1.0);
        assert_eq!(k.sigma, 1.0);
        k.set_seed(5);
        k.set_block(block);
        let mut z = [vec![[0.0; 2]; n], vec![[0.0; 2]; n]];
        for (s, zs) in z.iter_mut().enumerate() {
            k.kick_counter(s as u64, zs, false);
        }
        let mut par = vec![[0.0; 2]; n];
        rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .unwrap()
            .install(|| k.kick_counter(1, &mut par, true));
        assert!(par == z[1]);
        let b: Vec<f64> = z
            .iter()
            .flat_map(|s| s.as_flattened().iter().copied())
            .collect();
        let m = b.len() as f64;
        let m1 = b.iter().sum::<f64>() / m;
        let m2 = b.iter().map(|z| z * z).sum::<f64>() / m;
        let m4 = b.iter().map(|z| z.powi(4)).sum::<f64>() / m;
        assert!(m1.abs() < 5e-3, "{m1}");
        assert!((m2 - 1.0).abs() < 5.0 * 1.414e-3, "{m2}");
        assert!((m4 - 3.0).abs() < 5.0 * 9.8e-3, "{m4}");
        let tail = b.iter().filter(|z| z.abs() > 3.0).count() as f64 / m;
        assert!((tail - 2.6998e-3).abs() < 5.0 * 5.2e-5, "{tail}");
        let far = b.iter().filter(|z| z.abs() > 3.7).count() as f64 / m;
        assert!((far - 2.1564e-4).abs() < 5.0 * 1.47e-5, "{far}");
        let (a0, a1) = (z[0].as_flattened(), z[1].as_flattened());
        let slots = a0.len() as f64;
        let steps = a0.iter().zip(a1).map(|(x, y)| x * y).sum::<f64>() / slots;
        let nb = a0.windows(2).map(|w| w[0] * w[1]).sum::<f64>() / (slots - 1.0);
        let se = 1.0 / slots.sqrt();
        assert!(steps.abs() < 5.0 * se, "steps {steps}");
        assert!(nb.abs() < 5.0 * se, "neighbours {nb}");
    }
}
