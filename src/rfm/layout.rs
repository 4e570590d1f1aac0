//! The uniform initial layout (spec 1.9): random sequential addition (RSA) of N points, fast
//! and on several threads, with exactly the points and the stream position of the plain rule.
//!
//! The rule (stream versions 1 and 2 alike): try t draws the point (u l, u' l) from two
//! consecutive words of the run's stream (each as `RunRng::f64`, accepted or not) and keeps
//! it if it overlaps no point kept before it: no kept point q in the 3x3 coarse cells (side
//! >= sp) around it with `min_image` distance^2 < sp^2. After the last point the stream stands
//! just after its try; more than 10 000 N + 100 000 tries is the "too dense" error.
//!
//! How it is made fast, without changing a bit of that:
//! - the tries are taken in batches (4096 tries, doubled while few are kept, up to 2^18); a
//!   batch's words are made in bulk straight from the counter-based ChaCha8 block function
//!   (`rng::stream::WordStream` at the word's position), in chunks, on the current rayon pool
//!   from `sim::PARALLEL_MIN_PARTICLES` points, and the stream is then moved past the batch (or to
//!   just after the last point's try) without drawing the words again;
//! - each chunk pre-tests its tries against the points kept before the batch: first a bitmap
//!   of fine cells (side ~sp/6) each lying wholly, with a margin, inside the exclusion disk
//!   (radius sp) of some kept point — a try in such a cell is rejected at once (the full test
//!   would find that point: its distance is below sp (1 - 1e-9), far beyond round-off) — then
//!   the full test; a try rejected there would be rejected by the plain rule too;
//! - the survivors, in try order, are tested on one thread against the points kept earlier in
//!   the same batch only (the same pair test on the same 3x3 cells), and kept or not.
//!
//! The kept points, their order and the stream's position are those of the plain rule for any
//! thread count and batch schedule (`tests::same_as_plain_rsa`, against the old code kept as
//! the test-only reference).

use rayon::prelude::*;

use super::neighbours::min_image;
use crate::physics::SimError;
use crate::rng::stream::WordStream;
use crate::rng::{unit_f64, RngPosition, RunRng};

/// Tries of the first batch (and the least of any).
const RSA_BATCH: usize = 4096;
/// The most tries of a batch (late in the filling, when nearly every try is rejected).
const RSA_BATCH_MAX: usize = 1 << 18;
/// Tries per chunk of a batch's pre-test (a unit of parallel work).
const RSA_CHUNK: usize = 2048;
/// Tries whose words a chunk makes at a time.
const RSA_WORDS: usize = 256;
/// Fine cells per coarse cell side of the coverage bitmap (fine side ~ sp / 6).
const FINE_PER_COARSE: usize = 6;
/// The relative safety margin of the coverage bitmap (round-off is ~1e-15).
const COVER_MARGIN: f64 = 1e-9;

/// The uniform layout of `n` points in the periodic square of side `l`, no two closer than
/// `sp` (flat positions), drawn from `rng` as the plain rule does.
///
/// `par`: make the words and pre-test on the current rayon pool (the caller decides; the
/// result is the same either way).
pub(super) fn uniform(
    n: usize,
    l: f64,
    sp: f64,
    rng: &mut RunRng,
    par: bool,
) -> Result<Vec<f64>, SimError> {
    let mut x: Vec<f64> = Vec::with_capacity(2 * n);
    if n == 0 {
        return Ok(x);
    }
    let grid = Grid::new(n, l, sp);
    let mut cells: Vec<Vec<u32>> = vec![Vec::new(); grid.nc * grid.nc];
    let mut cover = Cover::new(&grid, n, l, sp);
    let max_tries = 10_000 * n as u64 + 100_000;
    let mut tries = 0u64;
    let mut batch = RSA_BATCH;
    let seed = rng.position().seed;
    loop {
        if tries >= max_tries {
            return Err("packing_fraction: too dense for the uniform (random) layout".into());
        }
        let b = (batch as u64).min(max_tries - tries) as usize;
        // The stream's position (32-bit words) at the batch's first try.
        let start = rng.position();
        let p0 = start.filled_at + 2 * start.idx as u128;
        let base = x.len() / 2;
        let chunks = b.div_ceil(RSA_CHUNK);
        let pretest = |c: usize| -> Vec<(u32, [f64; 2])> {
            let t0 = c * RSA_CHUNK;
            let t1 = (t0 + RSA_CHUNK).min(b);
            let mut ws = WordStream::at(&RngPosition {
                seed,
                filled_at: p0 + 4 * t0 as u128,
                idx: 0,
            });
            let mut w = [0u64; 2 * RSA_WORDS];
            let mut out = Vec::new();
            let mut t = t0;
            while t < t1 {
                let k = (t1 - t).min(RSA_WORDS);
                ws.fill(&mut w[..2 * k]);
                for (i, pair) in w[..2 * k].chunks_exact(2).enumerate() {
                    let p = [unit_f64(pair[0]) * l, unit_f64(pair[1]) * l];
                    if cover.covered(p) || grid.overlaps(p, &cells, &x, 0) {
                        continue;
                    }
                    out.push(((t + i) as u32, p));
                }
                t += k;
            }
            out
        };
        let found: Vec<Vec<(u32, [f64; 2])>> = if par {
            (0..chunks).into_par_iter().map(pretest).collect()
        } else {
            (0..chunks).map(pretest).collect()
        };
        for &(t, p) in found.iter().flatten() {
            if grid.overlaps(p, &cells, &x, base) {
                continue;
            }
            cells[grid.cell(p)].push((x.len() / 2) as u32);
            x.extend_from_slice(&p);
            cover.mark(p);
            if x.len() == 2 * n {
                // The last point: leave the stream just after its try.
                rng.skip(2 * (t as u64 + 1));
                return Ok(x);
            }
        }
        tries += b as u64;
        rng.skip(2 * b as u64);
        if x.len() / 2 - base < b / 64 {
            batch = (2 * batch).min(RSA_BATCH_MAX);
        }
    }
}

/// The coarse cells of the plain rule (side >= sp).
struct Grid {
    nc: usize,
    side: f64,
    l: f64,
    sp: f64,
}

impl Grid {
    fn new(n: usize, l: f64, sp: f64) -> Self {
        let nc = ((l / sp).floor() as usize)
            .min((2.0 * (n as f64).sqrt()) as usize)
            .max(1);
        Grid {
            nc,
            side: l / nc as f64,
            l,
            sp,
        }
    }

    #[inline(always)]
    fn cell_xy(&self, p: [f64; 2]) -> (usize, usize) {
        let cx = ((p[0] / self.side) as usize).min(self.nc - 1);
        let cy = ((p[1] / self.side) as usize).min(self.nc - 1);
        (cx, cy)
    }

    #[inline(always)]
    fn cell(&self, p: [f64; 2]) -> usize {
        let (cx, cy) = self.cell_xy(p);
        cy * self.nc + cx
    }

    /// The plain rule's overlap test, against the kept points numbered `from` or later (each
    /// cell lists its points in increasing order).
    #[inline(always)]
    fn overlaps(&self, p: [f64; 2], cells: &[Vec<u32>], x: &[f64], from: usize) -> bool {
        let (cx, cy) = self.cell_xy(p);
        let nc = self.nc as isize;
        let (l, sp) = (self.l, self.sp);
        for dy in -1isize..=1 {
            let iy = (cy as isize + dy).rem_euclid(nc) as usize;
            for dx in -1isize..=1 {
                let ix = (cx as isize + dx).rem_euclid(nc) as usize;
                for &q in cells[iy * self.nc + ix].iter().rev() {
                    let q = q as usize;
                    if q < from {
                        break;
                    }
                    let rx = min_image(p[0] - x[2 * q], l);
                    let ry = min_image(p[1] - x[2 * q + 1], l);
                    if rx * rx + ry * ry < sp * sp {
                        return true;
                    }
                }
            }
        }
        false
    }
}

/// Fine cells wholly inside some kept point's exclusion disk (a bitmap).
struct Cover {
    /// Fine cells per side (0: no bitmap).
    nf: usize,
    fs: f64,
    inv_fs: f64,
    bits: Vec<u64>,
    /// (sp (1 - margin))^2.
    r2: f64,
    sp: f64,
}

impl Cover {
    fn new(grid: &Grid, n: usize, l: f64, sp: f64) -> Self {
        // At most ~64 N bits; none for boxes too few cells across to be worth it.
        let mut nf = grid.nc * FINE_PER_COARSE;
        let cap = ((64.0 * n as f64).sqrt() as usize).max(1);
        if nf > cap {
            nf = cap;
        }
        if nf < 8 || nf > 1 << 20 {
            return Cover {
                nf: 0,
                fs: 0.0,
                inv_fs: 0.0,
                bits: Vec::new(),
                r2: 0.0,
                sp,
            };
        }
        let fs = l / nf as f64;
        let r = sp * (1.0 - COVER_MARGIN);
        Cover {
            nf,
            fs,
            inv_fs: 1.0 / fs,
            bits: vec![0; (nf * nf).div_ceil(64)],
            r2: r * r,
            sp,
        }
    }

    /// Whether `p` lies in a covered fine cell: then the plain rule rejects it.
    #[inline(always)]
    fn covered(&self, p: [f64; 2]) -> bool {
        if self.nf == 0 {
            return false;
        }
        let fx = ((p[0] * self.inv_fs) as usize).min(self.nf - 1);
        let fy = ((p[1] * self.inv_fs) as usize).min(self.nf - 1);
        let i = fy * self.nf + fx;
        (self.bits[i >> 6] >> (i & 63)) & 1 == 1
    }

    /// Mark the fine cells wholly within distance sp (1 - margin) of the kept point `q`, each
    /// cell widened by a margin of fs * 1e-9 (more than the round-off of a try's cell).
    fn mark(&mut self, q: [f64; 2]) {
        if self.nf == 0 {
            return;
        }
        let nf = self.nf as isize;
        let (fs, sp) = (self.fs, self.sp);
        let m = fs * COVER_MARGIN;
        let lo = |c: f64| ((c - sp) / fs).floor() as isize;
        let hi = |c: f64| ((c + sp) / fs).floor() as isize;
        // The farthest extent from `c` of the widened cell i along one axis.
        let far = |c: f64, i: isize| {
            let a = i as f64 * fs - m;
            let b = (i + 1) as f64 * fs + m;
            (c - a).abs().max((b - c).abs())
        };
        for j in lo(q[1])..=hi(q[1]) {
            let fy = far(q[1], j);
            let fy2 = fy * fy;
            if fy2 >= self.r2 {
                continue;
            }
            let row = j.rem_euclid(nf) as usize * self.nf;
            for i in lo(q[0])..=hi(q[0]) {
                let fx = far(q[0], i);
                if fx * fx + fy2 < self.r2 {
                    let k = row + i.rem_euclid(nf) as usize;
                    self.bits[k >> 6] |= 1 << (k & 63);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The uniform layout as 545c337 made it (one thread: its parallel pre-test changes
    /// nothing), the reference of `same_as_plain_rsa`.
    fn uniform_reference(
        n: usize,
        l: f64,
        sp: f64,
        rng: &mut RunRng,
    ) -> Result<Vec<f64>, SimError> {
        let mut x = Vec::with_capacity(2 * n);
        let nc = ((l / sp).floor() as usize)
            .min((2.0 * (n as f64).sqrt()) as usize)
            .max(1);
        let side = l / nc as f64;
        let mut cells: Vec<Vec<u32>> = vec![Vec::new(); nc * nc];
        let overlaps = |p: [f64; 2], cells: &[Vec<u32>], x: &[f64]| -> bool {
            let cx = ((p[0] / side) as usize).min(nc - 1);
            let cy = ((p[1] / side) as usize).min(nc - 1);
            for dy in -1isize..=1 {
                for dx in -1isize..=1 {
                    let ix = (cx as isize + dx).rem_euclid(nc as isize) as usize;
                    let iy = (cy as isize + dy).rem_euclid(nc as isize) as usize;
                    for &q in &cells[iy * nc + ix] {
                        let q = q as usize;
                        let rx = min_image(p[0] - x[2 * q], l);
                        let ry = min_image(p[1] - x[2 * q + 1], l);
                        if rx * rx + ry * ry < sp * sp {
                            return true;
                        }
                    }
                }
            }
            false
        };
        let mut tries = 0u64;
        let max_tries = 10_000 * n as u64 + 100_000;
        let mut cand: Vec<[f64; 2]> = Vec::with_capacity(RSA_BATCH);
        while x.len() < 2 * n {
            let start = rng.position();
            cand.clear();
            cand.extend((0..RSA_BATCH).map(|_| [rng.f64() * l, rng.f64() * l]));
            for (t, &p) in cand.iter().enumerate() {
                tries += 1;
                if tries > max_tries {
                    return Err(
                        "packing_fraction: too dense for the uniform (random) layout".into(),
                    );
                }
                if overlaps(p, &cells, &x) {
                    continue;
                }
                let cx = ((p[0] / side) as usize).min(nc - 1);
                let cy = ((p[1] / side) as usize).min(nc - 1);
                cells[cy * nc + cx].push((x.len() / 2) as u32);
                x.extend_from_slice(&p);
                if x.len() == 2 * n {
                    *rng = RunRng::restore(&start);
                    for _ in 0..2 * (t + 1) {
                        rng.u64();
                    }
                    break;
                }
            }
        }
        Ok(x)
    }

    /// Box side and exclusion distance of N unit-diameter discs at packing fraction phi.
    fn geometry(n: usize, phi: f64) -> (f64, f64) {
        let l = (n as f64 * std::f64::consts::PI / 4.0 / phi).sqrt();
        (l, 1.0 + 1e-3)
    }

    fn check(n: usize, phi: f64, seed: u64, skip: usize, threads: usize) {
        let (l, sp) = geometry(n, phi);
        let mut r0 = RunRng::new(seed);
        // Start at an odd place of the buffer (as after other draws).
        for _ in 0..skip {
            r0.u64();
        }
        let mut r1 = RunRng::restore(&r0.position());
        let want = uniform_reference(n, l, sp, &mut r0);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let got = pool.install(|| {
            let par =
                n >= crate::rfm::sim::PARALLEL_MIN_PARTICLES && rayon::current_num_threads() > 1;
            uniform(n, l, sp, &mut r1, par)
        });
        let (want, got) = match (want, got) {
            (Ok(w), Ok(g)) => (w, g),
            (Err(w), Err(g)) => {
                assert_eq!(w.to_string(), g.to_string());
                return;
            }
            (w, g) => panic!(
                "N={n} phi={phi} seed={seed}: {:?} vs {:?}",
                w.err(),
                g.err()
            ),
        };
        assert_eq!(want.len(), got.len(), "N={n} phi={phi} seed={seed}");
        let same = want
            .iter()
            .zip(&got)
            .all(|(a, b)| a.to_bits() == b.to_bits());
        assert!(
            same,
            "points differ: N={n} phi={phi} seed={seed} threads={threads}"
        );
        assert_eq!(
            r0.position(),
            r1.position(),
            "stream position: N={n} phi={phi}"
        );
        assert_eq!(r0.u64(), r1.u64());
    }

    /// The new placement against the old code: the same points in the same order and the
    /// stream left at the same position, on 1 and 2 threads.
    #[test]
    fn same_as_plain_rsa() {
        for &threads in &[1, 2] {
            for &n in &[1, 2, 7, 100, 1000] {
                for &phi in &[0.3, 0.5, 0.53] {
                    for seed in 0..3 {
                        check(n, phi, seed, seed as usize * 37, threads);
                    }
                }
            }
            for &phi in &[0.3, 0.5, 0.53] {
                check(5000, phi, 11, 3, threads);
            }
            check(27_000, 0.5, 5, 0, threads);
        }
        check(27_000, 0.53, 4301, 1, 2);
        check(27_000, 0.3, 9, 255, 2);
    }

    /// Too dense: the same error as before, after the same number of tries.
    #[test]
    fn too_dense_is_refused() {
        let (l, sp) = geometry(50, 0.8);
        let mut r = RunRng::new(1);
        let e = uniform(50, l, sp, &mut r, false).unwrap_err();
        assert_eq!(
            e.to_string(),
            "packing_fraction: too dense for the uniform (random) layout"
        );
    }
}
