//! Structure observables of the RFM (spec 2.6-2.8), accumulated at the snapshots:
//!
//! - [`NeighbourAcc`] (1D): h-th neighbour separations in reduced coordinates (3.17)/(3.23),
//!   R_{i,i+h} = |x_{i+h} - x_i - h d| on the ring (x_{i+N} = x_i + L; the absolute value
//!   handles soft overlaps, spec 2.6), histograms G_h(R) with log-spaced bins and the moments
//!   <R^m>, m = 1..9 (3.18), with 10-block standard errors.
//! - [`SkAcc`] (2D): S(k) = <|rho_k|^2>/N (4.2), rho_k = sum_j exp(-i k.x_j), on the lattice
//!   k = 2 pi (n_x, n_y)/L, 0 < |n| <= n_max, averaged over the snapshots and exactly over each
//!   shell |n|^2 = n_x^2 + n_y^2 (4.3). rho_{-k} = conj(rho_k), so one vector of each +-k pair
//!   is computed (the shell mean is the same). The phases are per-axis powers of
//!   exp(-2 pi i x/L) built by recurrence once per particle and snapshot; the sums are blocked
//!   dot products over particles, O(N n_k) multiply-adds without trigonometry.
//! - [`RadialAcc`] (2D): g(R) from all pairs (minimum image) with R < R_max <= L/2, normalised
//!   by the ideal-gas count N(N-1)/2 x pi (R_hi^2 - R_lo^2)/L^2 (the exact annulus area, so a
//!   uniform gas gives 1; (4.10) normalises by N^2/2 and gives (N-1)/N), and the cumulative
//!   count C(R) (4.15): the mean number of other particles within R of a particle.

use serde::{Deserialize, Serialize};

use super::blocks::block_sem;
use super::blocks::{block_of, HistRow, BLOCKS};

/// Highest moment <R^m> of the neighbour separations.
pub const NEIGHBOUR_ORDERS: usize = 9;

// ----------------------------------------------------------------------------------------
// 1D neighbour separations

/// Resolved settings of the neighbour-distance observable.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct NeighbourConfig {
    /// Orders h = 1..h_max.
    pub h_max: u32,
    /// Range [lo, hi) of the log-spaced bins (m).
    pub lo: f64,
    pub hi: f64,
    pub bins_per_decade: u32,
}

impl NeighbourConfig {
    /// Bin edges lo 10^(j/b), j = 0..nb-1, then hi (the last bin may be narrower).
    pub fn edges(&self) -> Vec<f64> {
        let b = self.bins_per_decade as f64;
        let nb = ((b * (self.hi / self.lo).log10()) - 1e-9).ceil().max(1.0) as usize;
        let mut e: Vec<f64> = (0..nb)
            .map(|j| self.lo * 10f64.powf(j as f64 / b))
            .collect();
        e.push(self.hi);
        e
    }
}

/// `rfm_neighbour_moments` row.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct NeighbourMomentRow {
    pub h: u32,
    pub order: u32,
    pub value: f64,
    pub sem: Option<f64>,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct NeighbourAcc {
    pub cfg: NeighbourConfig,
    pub edges: Vec<f64>,
    /// Per h (index h - 1): bins + 2 counts (below, above).
    pub counts: Vec<u64>,
    /// Per sample and h (index sample * h_max + h - 1): the sums of R^m (index m - 1) over
    /// the sample's separations, from 0; grouped into the blocks by `rows`.
    pub sample_sums: Vec<[f64; NEIGHBOUR_ORDERS]>,
    /// Separations per sample and h (same index).
    pub sample_counts: Vec<u64>,
}

/// The h-th neighbour separations R_{i,i+h}, i = 0..N-1, of ordered ring positions `x`
/// (unwrapped, x_{i+N} = x_i + L), rods of width `d`: |x_{i+h} - x_i - h d|.
pub fn neighbour_separations(
    x: &[f64],
    l: f64,
    d: f64,
    h: usize,
) -> impl Iterator<Item = f64> + '_ {
    let n = x.len();
    let hd = h as f64 * d;
    (0..n).map(move |i| {
        let j = i + h;
        let (xj, w) = if j < n { (x[j], 0.0) } else { (x[j - n], l) };
        (xj + w - x[i] - hd).abs()
    })
}

impl NeighbourAcc {
    pub fn new(cfg: NeighbourConfig) -> Self {
        let edges = cfg.edges();
        let bins = edges.len() - 1;
        let hm = cfg.h_max as usize;
        NeighbourAcc {
            counts: vec![0; hm * (bins + 2)],
            sample_sums: Vec::new(),
            sample_counts: Vec::new(),
            edges,
            cfg,
        }
    }

    pub fn bins(&self) -> usize {
        self.edges.len() - 1
    }

    /// Samples added.
    pub fn samples(&self) -> u64 {
        (self.sample_sums.len() / (self.cfg.h_max as usize).max(1)) as u64
    }

    fn bin(&self, r: f64) -> usize {
        let nb = self.bins();
        let e = &self.edges;
        if r < e[0] {
            return nb;
        }
        if r >= e[nb] {
            return nb + 1;
        }
        let b = self.cfg.bins_per_decade as f64;
        let mut j = ((b * (r / e[0]).log10()).max(0.0) as usize).min(nb - 1);
        while j > 0 && r < e[j] {
            j -= 1;
        }
        while j + 1 < nb && r >= e[j + 1] {
            j += 1;
        }
        j
    }

    /// One snapshot of 1D positions (ordered, unwrapped), box length `l`, rod width `d`.
    pub fn add(&mut self, x: &[f64], l: f64, d: f64) {
        let nb = self.bins();
        for h in 1..=self.cfg.h_max as usize {
            let mut sums = [0.0; NEIGHBOUR_ORDERS];
            let mut count = 0u64;
            for r in neighbour_separations(x, l, d, h) {
                let idx = self.bin(r);
                self.counts[(h - 1) * (nb + 2) + idx] += 1;
                let mut pw = 1.0;
                for s in sums.iter_mut() {
                    pw *= r;
                    *s += pw;
                }
                count += 1;
            }
            self.sample_sums.push(sums);
            self.sample_counts.push(count);
        }
    }

    /// Histogram rows (kind "neighbour_distance") and moment rows, the errors from the blocks
    /// of a run of `samples` samples.
    pub fn rows(&self, samples: u64) -> (Vec<HistRow>, Vec<NeighbourMomentRow>) {
        let hm = (self.cfg.h_max as usize).max(1);
        let nb = self.bins();
        let mut hist = Vec::new();
        let mut moments = Vec::new();
        for h in 1..=self.cfg.h_max as usize {
            let c = &self.counts[(h - 1) * (nb + 2)..h * (nb + 2)];
            let total: u64 = c.iter().sum();
            let row = |lo: f64, hi: f64, count: u64, density: Option<f64>| HistRow {
                kind: "neighbour_distance".into(),
                h: h as u32,
                lo,
                hi,
                count,
                density,
            };
            for j in 0..nb {
                let (lo, hi) = (self.edges[j], self.edges[j + 1]);
                hist.push(row(
                    lo,
                    hi,
                    c[j],
                    Some(c[j] as f64 / (total.max(1) as f64 * (hi - lo))),
                ));
            }
            hist.push(row(f64::NEG_INFINITY, self.edges[0], c[nb], None));
            hist.push(row(self.edges[nb], f64::INFINITY, c[nb + 1], None));
            let mut bs = vec![[0.0; NEIGHBOUR_ORDERS]; BLOCKS];
            let mut bc = vec![0u64; BLOCKS];
            for (j, (sums, &count)) in self
                .sample_sums
                .iter()
                .zip(&self.sample_counts)
                .skip(h - 1)
                .step_by(hm)
                .enumerate()
            {
                let b = block_of(j as u64, samples);
                for (a, x) in bs[b].iter_mut().zip(sums) {
                    *a += x;
                }
                bc[b] += count;
            }
            let n: u64 = bc.iter().sum();
            for m in 0..NEIGHBOUR_ORDERS {
                let value = bs.iter().map(|b| b[m]).sum::<f64>() / n.max(1) as f64;
                let blocks: Vec<f64> = bs
                    .iter()
                    .zip(&bc)
                    .filter(|(_, &c)| c > 0)
                    .map(|(b, &c)| b[m] / c as f64)
                    .collect();
                moments.push(NeighbourMomentRow {
                    h: h as u32,
                    order: m as u32 + 1,
                    value,
                    sem: block_sem(&blocks),
                });
            }
        }
        (hist, moments)
    }
}

// ----------------------------------------------------------------------------------------
// 2D structure factor

/// Resolved settings of the structure factor.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct SkConfig {
    /// Lattice vectors with 0 < |n|^2 <= floor(n_max^2), k = 2 pi n / L.
    pub n_max: f64,
    /// Evaluated at every `every`-th snapshot.
    pub every: u32,
}

impl SkConfig {
    pub fn n2_cut(&self) -> u64 {
        (self.n_max * self.n_max).floor() as u64
    }
}

fn isqrt(v: u64) -> u64 {
    let mut r = (v as f64).sqrt() as u64;
    while r * r > v {
        r -= 1;
    }
    while (r + 1) * (r + 1) <= v {
        r += 1;
    }
    r
}

/// `rfm_structure_factor` row.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct SkRow {
    /// Shell |n|^2 = n_x^2 + n_y^2 (exact).
    pub n2: u64,
    /// |k| = 2 pi sqrt(n2) / L (1/m).
    pub k: f64,
    /// Lattice vectors in the shell (both signs of each +-k pair).
    pub n_vectors: u64,
    pub s: f64,
    pub sem: Option<f64>,
}

/// Particles per block of the phase tables.
const CHUNK: usize = 64;

/// The lattice and scratch buffers of the S(k) sums (derived, not checkpointed).
pub struct SkWork {
    nmax: usize,
    /// Largest n_y >= 0 per n_x with n_x^2 + n_y^2 <= cut.
    mmax: Vec<usize>,
    /// Shell index of each computed vector, in the order of the sums.
    shell_of: Vec<u32>,
    rho_re: Vec<f64>,
    rho_im: Vec<f64>,
    xr: Vec<[f64; CHUNK]>,
    xi: Vec<[f64; CHUNK]>,
    yr: Vec<[f64; CHUNK]>,
    yi: Vec<[f64; CHUNK]>,
}

/// The computed half of the lattice in summation order: n_x = 0: n_y = 1..m(0); n_x > 0:
/// n_y = 0, then +n_y, -n_y for n_y = 1..m(n_x).
fn half_lattice(cut: u64) -> (usize, Vec<usize>, Vec<u64>) {
    let nmax = isqrt(cut) as usize;
    let mmax: Vec<usize> = (0..=nmax)
        .map(|nx| isqrt(cut - (nx * nx) as u64) as usize)
        .collect();
    let mut n2 = Vec::new();
    for (nx, &m) in mmax.iter().enumerate() {
        let start = usize::from(nx == 0);
        for ny in start..=m {
            let v = (nx * nx + ny * ny) as u64;
            n2.push(v);
            if nx > 0 && ny > 0 {
                n2.push(v);
            }
        }
    }
    (nmax, mmax, n2)
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct SkAcc {
    pub cfg: SkConfig,
    /// Shells (ascending |n|^2) and their full vector counts.
    pub n2: Vec<u64>,
    pub n_vectors: Vec<u64>,
    /// Per evaluation and shell (index evaluation * shells + shell): the sum of |rho_k|^2 over
    /// the computed vectors of the shell, from 0; grouped into the blocks by `rows`
    /// (evaluation e is sample e x `every`).
    pub eval_sums: Vec<f64>,
}

impl SkAcc {
    pub fn new(cfg: SkConfig) -> Self {
        let (_, _, vn2) = half_lattice(cfg.n2_cut());
        let mut n2 = vn2.clone();
        n2.sort_unstable();
        n2.dedup();
        let mut n_vectors = vec![0u64; n2.len()];
        for v in &vn2 {
            let s = n2.binary_search(v).expect("shell");
            n_vectors[s] += 2;
        }
        SkAcc {
            eval_sums: Vec::new(),
            n2,
            n_vectors,
            cfg,
        }
    }

    pub fn work(&self) -> SkWork {
        let (nmax, mmax, vn2) = half_lattice(self.cfg.n2_cut());
        let shell_of = vn2
            .iter()
            .map(|v| self.n2.binary_search(v).expect("shell") as u32)
            .collect();
        let nv = vn2.len();
        SkWork {
            nmax,
            mmax,
            shell_of,
            rho_re: vec![0.0; nv],
            rho_im: vec![0.0; nv],
            xr: vec![[0.0; CHUNK]; nmax + 1],
            xi: vec![[0.0; CHUNK]; nmax + 1],
            yr: vec![[0.0; CHUNK]; nmax + 1],
            yi: vec![[0.0; CHUNK]; nmax + 1],
        }
    }

    /// Number of computed (half-lattice) vectors.
    pub fn computed_vectors(&self) -> u64 {
        self.n_vectors.iter().sum::<u64>() / 2
    }

    /// Evaluations done.
    pub fn evals(&self) -> u64 {
        (self.eval_sums.len() / self.n2.len().max(1)) as u64
    }

    /// One snapshot of 2D positions (flat, particle-major), box side `l`.
    pub fn add(&mut self, w: &mut SkWork, x: &[f64], l: f64) {
        rho_k(w, x, l);
        let ns = self.n2.len();
        let start = self.eval_sums.len();
        self.eval_sums.resize(start + ns, 0.0);
        let sums = &mut self.eval_sums[start..];
        for ((re, im), &s) in w.rho_re.iter().zip(&w.rho_im).zip(&w.shell_of) {
            sums[s as usize] += re * re + im * im;
        }
    }

    /// Rows (one per shell); `n` particles, box side `l`, the errors from the blocks of a run
    /// of `samples` samples.
    pub fn rows(&self, n: usize, l: f64, samples: u64) -> Vec<SkRow> {
        let ns = self.n2.len();
        let mut block_sums = vec![0.0; ns * BLOCKS];
        let mut block_evals = vec![0u64; BLOCKS];
        for (e, sums) in self.eval_sums.chunks_exact(ns.max(1)).enumerate() {
            let b = block_of(e as u64 * self.cfg.every as u64, samples);
            for (a, x) in block_sums[b * ns..(b + 1) * ns].iter_mut().zip(sums) {
                *a += x;
            }
            block_evals[b] += 1;
        }
        let evals: u64 = block_evals.iter().sum();
        (0..ns)
            .map(|s| {
                let half = (self.n_vectors[s] / 2) as f64;
                let norm = |e: u64| half * e as f64 * n as f64;
                let total: f64 = (0..BLOCKS).map(|b| block_sums[b * ns + s]).sum();
                let blocks: Vec<f64> = (0..BLOCKS)
                    .filter(|&b| block_evals[b] > 0)
                    .map(|b| block_sums[b * ns + s] / norm(block_evals[b]))
                    .collect();
                SkRow {
                    n2: self.n2[s],
                    k: 2.0 * std::f64::consts::PI * (self.n2[s] as f64).sqrt() / l,
                    n_vectors: self.n_vectors[s],
                    s: total / norm(evals.max(1)),
                    sem: block_sem(&blocks),
                }
            })
            .collect()
    }
}

/// The four partial sums of a complex product over one chunk: sum ar br, ai bi, ar bi, ai br.
#[inline(always)]
fn dot4(
    ar: &[f64; CHUNK],
    ai: &[f64; CHUNK],
    br: &[f64; CHUNK],
    bi: &[f64; CHUNK],
) -> (f64, f64, f64, f64) {
    const LANES: usize = 4;
    let (mut s1, mut s2, mut s3, mut s4) = ([0.0; LANES], [0.0; LANES], [0.0; LANES], [0.0; LANES]);
    for k in (0..CHUNK).step_by(LANES) {
        for q in 0..LANES {
            let (a, b, c, d) = (ar[k + q], ai[k + q], br[k + q], bi[k + q]);
            s1[q] += a * c;
            s2[q] += b * d;
            s3[q] += a * d;
            s4[q] += b * c;
        }
    }
    let r = |s: [f64; LANES]| (s[0] + s[1]) + (s[2] + s[3]);
    (r(s1), r(s2), r(s3), r(s4))
}

/// rho_k for the computed half lattice into `w.rho_re`, `w.rho_im`.
fn rho_k(w: &mut SkWork, x: &[f64], l: f64) {
    w.rho_re.fill(0.0);
    w.rho_im.fill(0.0);
    let tau = 2.0 * std::f64::consts::PI / l;
    for chunk in x.chunks(2 * CHUNK) {
        let c = chunk.len() / 2;
        // Per-axis phase powers exp(-i n theta), n = 0..nmax, by recurrence; padding zero in
        // x (so the padded products vanish).
        for j in 0..CHUNK {
            let (ex, ey) = if j < c {
                let (sx, cx) = (tau * chunk[2 * j]).sin_cos();
                let (sy, cy) = (tau * chunk[2 * j + 1]).sin_cos();
                ((cx, -sx), (cy, -sy))
            } else {
                ((0.0, 0.0), (0.0, 0.0))
            };
            let pad = if j < c { 1.0 } else { 0.0 };
            w.xr[0][j] = pad;
            w.xi[0][j] = 0.0;
            w.yr[0][j] = 1.0;
            w.yi[0][j] = 0.0;
            for n in 1..=w.nmax {
                let (pr, pi) = (w.xr[n - 1][j], w.xi[n - 1][j]);
                w.xr[n][j] = pr * ex.0 - pi * ex.1;
                w.xi[n][j] = pr * ex.1 + pi * ex.0;
                let (pr, pi) = (w.yr[n - 1][j], w.yi[n - 1][j]);
                w.yr[n][j] = pr * ey.0 - pi * ey.1;
                w.yi[n][j] = pr * ey.1 + pi * ey.0;
            }
        }
        let mut idx = 0;
        for nx in 0..=w.nmax {
            let (ar, ai) = (&w.xr[nx], &w.xi[nx]);
            for ny in usize::from(nx == 0)..=w.mmax[nx] {
                let (s1, s2, s3, s4) = dot4(ar, ai, &w.yr[ny], &w.yi[ny]);
                w.rho_re[idx] += s1 - s2;
                w.rho_im[idx] += s3 + s4;
                idx += 1;
                if nx > 0 && ny > 0 {
                    w.rho_re[idx] += s1 + s2;
                    w.rho_im[idx] += s4 - s3;
                    idx += 1;
                }
            }
        }
    }
}

// ----------------------------------------------------------------------------------------
// 2D radial distribution

/// Resolved settings of g(R).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct RadialConfig {
    /// Largest separation R_max <= L/2 (m) and number of bins of width R_max / bins.
    pub r_max: f64,
    pub bins: u32,
    /// Evaluated at every `every`-th snapshot.
    pub every: u32,
    /// N and L (normalisation).
    pub n: u64,
    pub l: f64,
}

/// `rfm_radial_distribution` row.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct RadialRow {
    pub r_lo: f64,
    pub r_hi: f64,
    /// Pairs with r_lo <= R < r_hi, summed over the evaluated snapshots.
    pub count: u64,
    pub g: f64,
    pub g_sem: Option<f64>,
    /// C(r_hi): mean number of other particles within r_hi of a particle.
    pub c: f64,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct RadialAcc {
    pub cfg: RadialConfig,
    /// Per evaluation and bin (index evaluation * bins + bin): pair counts; grouped into the
    /// blocks by `rows` (evaluation e is sample e x `every`).
    pub counts: Vec<u64>,
}

impl RadialAcc {
    pub fn new(cfg: RadialConfig) -> Self {
        RadialAcc {
            counts: Vec::new(),
            cfg,
        }
    }

    /// Evaluations done.
    pub fn evals(&self) -> u64 {
        (self.counts.len() / (self.cfg.bins as usize).max(1)) as u64
    }

    /// One snapshot of 2D positions (flat); `buf` is scratch.
    pub fn add(&mut self, buf: &mut Vec<f64>, x: &[f64]) {
        let l = self.cfg.l;
        let n = x.len() / 2;
        let bins = self.cfg.bins as usize;
        // Wrapped into [0, L): then every difference lies in (-L, L) and one shift gives the
        // minimum image.
        let wrap = |a: f64| super::neighbours::wrap(a, l);
        let xs: Vec<f64> = (0..n).map(|i| wrap(x[2 * i])).collect();
        let ys: Vec<f64> = (0..n).map(|i| wrap(x[2 * i + 1])).collect();
        let half = 0.5 * l;
        let r2max = self.cfg.r_max * self.cfg.r_max;
        let inv_dr = bins as f64 / self.cfg.r_max;
        let start = self.counts.len();
        self.counts.resize(start + bins, 0);
        let counts = &mut self.counts[start..];
        buf.resize(n, 0.0);
        for i in 0..n {
            let (xi, yi) = (xs[i], ys[i]);
            let r2s = &mut buf[i + 1..n];
            for ((r2, &xj), &yj) in r2s.iter_mut().zip(&xs[i + 1..]).zip(&ys[i + 1..]) {
                let mut dx = xj - xi;
                dx += if dx > half { -l } else { 0.0 };
                dx += if dx < -half { l } else { 0.0 };
                let mut dy = yj - yi;
                dy += if dy > half { -l } else { 0.0 };
                dy += if dy < -half { l } else { 0.0 };
                *r2 = dx * dx + dy * dy;
            }
            for &r2 in r2s.iter() {
                if r2 < r2max {
                    let b = ((r2.sqrt() * inv_dr) as usize).min(bins - 1);
                    counts[b] += 1;
                }
            }
        }
    }

    /// Rows (one per bin), the errors from the blocks of a run of `samples` samples.
    pub fn rows(&self, samples: u64) -> Vec<RadialRow> {
        let bins = self.cfg.bins as usize;
        let mut block_counts = vec![0u64; bins * BLOCKS];
        let mut block_evals = vec![0u64; BLOCKS];
        for (e, c) in self.counts.chunks_exact(bins.max(1)).enumerate() {
            let b = block_of(e as u64 * self.cfg.every as u64, samples);
            for (a, x) in block_counts[b * bins..(b + 1) * bins].iter_mut().zip(c) {
                *a += x;
            }
            block_evals[b] += 1;
        }
        let (n, l) = (self.cfg.n as f64, self.cfg.l);
        let dr = self.cfg.r_max / bins as f64;
        let evals: u64 = block_evals.iter().sum();
        let pairs = 0.5 * n * (n - 1.0);
        let mut cum = 0u64;
        (0..bins)
            .map(|j| {
                let (r_lo, r_hi) = (j as f64 * dr, (j + 1) as f64 * dr);
                let ideal = pairs * std::f64::consts::PI * (r_hi * r_hi - r_lo * r_lo) / (l * l);
                let count: u64 = (0..BLOCKS).map(|b| block_counts[b * bins + j]).sum();
                cum += count;
                let blocks: Vec<f64> = (0..BLOCKS)
                    .filter(|&b| block_evals[b] > 0)
                    .map(|b| block_counts[b * bins + j] as f64 / (ideal * block_evals[b] as f64))
                    .collect();
                RadialRow {
                    r_lo,
                    r_hi,
                    count,
                    g: count as f64 / (ideal * evals.max(1) as f64),
                    g_sem: block_sem(&blocks),
                    c: 2.0 * cum as f64 / (n * evals.max(1) as f64),
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests;
