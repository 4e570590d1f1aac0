//! Multiplicative bisection (fracture) of [0, 1] (spec 3.1, thesis sec. 3.4).
//!
//! Level 0 is the interval [0, 1]; level n -> n + 1 splits every interval of length x into
//! a x and (1 - a) x with a ~ U_0(a) i.i.d. per interval, so after n levels the 2^n lengths are
//! products of n draws (3.28). Splits:
//!
//! - uniform, U_0 = 1: P_n(x) = (-ln x)^{n-1}/(n-1)! (3.36), <x^m> = (1+m)^{-n} (3.37);
//! - concave, U_0(a) = (1-A)/2 (a^{-A} + (1-a)^{-A}), 0 < A < 1 (spec 3.1 [REC]): an equal
//!   mixture of the densities (1-A) a^{-A} and its mirror, sampled exactly by inversion
//!   (a = u^{1/(1-A)}, mirrored with probability 1/2); <a^m> = (1-A)/2 (1/(m+1-A) +
//!   B(m+1, 1-A)) and <x^m> = <a^m>^n exactly. No closed form for P_n.
//!
//! A run draws `realisations` independent partitions. Per realisation it histograms the 2^n
//! lengths (log-spaced bins) and averages x^m over them; the table values are means over the
//! realisations with standard errors from the realisation-to-realisation spread (the lengths
//! of one realisation are correlated: they sum to 1).

use serde::{Deserialize, Serialize};

use crate::physics::SimError;
use crate::rng::{RngPosition, RunRng};

/// Resolved settings of a bisection run.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct BisectionConfig {
    pub level: u32,
    pub realisations: u64,
    pub split: Split,
    /// Lower edge of the log-spaced bins (the bin [0, x_min) is the first row).
    pub x_min: f64,
    pub bins_per_decade: u32,
    /// Moments m = 1..=orders.
    pub orders: u32,
}

#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub enum Split {
    Uniform,
    Concave { exponent: f64 },
}

impl Split {
    /// <a^m> of one split.
    pub fn moment(self, m: u32) -> f64 {
        match self {
            Split::Uniform => 1.0 / (1.0 + m as f64),
            Split::Concave { exponent: a } => {
                // B(m+1, 1-A) = m! / prod_{j=1}^{m+1} (j - A)
                let mut beta = 1.0;
                for j in 1..=m {
                    beta *= j as f64 / (j as f64 - a);
                }
                beta /= m as f64 + 1.0 - a;
                0.5 * (1.0 - a) * (1.0 / (m as f64 + 1.0 - a) + beta)
            }
        }
    }

    #[inline]
    fn draw(self, rng: &mut RunRng) -> f64 {
        match self {
            Split::Uniform => rng.f64_open0(),
            Split::Concave { exponent } => {
                let mirror = rng.u64() >> 63 == 1;
                let a = rng.f64_open0().powf(1.0 / (1.0 - exponent));
                if mirror {
                    1.0 - a
                } else {
                    a
                }
            }
        }
    }
}

/// Regularised upper incomplete gamma Q(n, u) = e^{-u} sum_{k<n} u^k/k! for integer n >= 1:
/// the probability that a uniform-bisection length at level n is below x = e^{-u}.
pub fn uniform_cdf(n: u32, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let u = -x.ln();
    let lu = u.ln();
    let mut lfact = 0.0;
    let mut s = 0.0;
    for k in 0..n {
        if k > 0 {
            lfact += (k as f64).ln();
        }
        s += (-u + k as f64 * lu - lfact).exp();
    }
    s.min(1.0)
}

/// Exact density (3.36) P_n(x) = (-ln x)^{n-1}/(n-1)! of the uniform bisection.
pub fn uniform_density(n: u32, x: f64) -> f64 {
    let mut f = 1.0;
    for k in 1..n {
        f *= k as f64;
    }
    (-x.ln()).powi(n as i32 - 1) / f
}

/// `bisection_histogram` row.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct HistRow {
    pub x_lo: f64,
    pub x_hi: f64,
    /// Lengths in the bin over all realisations.
    pub count: u64,
    /// Probability density of a length per unit x (mean over realisations).
    pub density: f64,
    pub density_sem: Option<f64>,
    /// Exact bin average of P_n(x) (uniform split).
    pub density_exact: Option<f64>,
}

/// `bisection_moments` row.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct MomentRow {
    pub order: u32,
    /// <x^m> over the lengths, mean over realisations.
    pub mean: f64,
    pub sem: Option<f64>,
    /// <a^m>^n.
    pub exact: f64,
    /// zeta_m = -log2 <a^m> (so <x^m> = N^{-zeta_m}, N = 2^n; ln(1+m)/ln 2 for uniform).
    pub zeta_exact: f64,
    /// (mean - exact) / sem.
    pub z: Option<f64>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct BisectionOutput {
    pub realisations: u64,
    pub histogram: Vec<HistRow>,
    pub moments: Vec<MomentRow>,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
struct State {
    cfg: BisectionConfig,
    rng: RngPosition,
    done: u64,
    /// Per bin (0: below x_min): sum over realisations of the count, and of its square.
    count_sum: Vec<f64>,
    count_sum2: Vec<f64>,
    /// Per order: sum over realisations of the realisation mean of x^m, and of its square.
    mom_sum: Vec<f64>,
    mom_sum2: Vec<f64>,
}

pub struct BisectionRun {
    st: State,
    rng: RunRng,
    edges: Vec<f64>,
    lengths: Vec<f64>,
    counts: Vec<u32>,
}

impl BisectionConfig {
    /// Bin edges: 0, x_min 10^{j/b} (j = 0..nb-1), 1.
    pub fn edges(&self) -> Vec<f64> {
        let b = self.bins_per_decade as f64;
        let nb = ((b * (1.0 / self.x_min).log10()) - 1e-9).ceil().max(1.0) as usize;
        let mut e = vec![0.0];
        e.extend((0..nb).map(|j| self.x_min * 10f64.powf(j as f64 / b)));
        e.push(1.0);
        e
    }
}

impl BisectionRun {
    pub fn new(cfg: BisectionConfig, seed: u64) -> Self {
        let edges = cfg.edges();
        let nb = edges.len() - 1;
        let m = cfg.orders as usize;
        let st = State {
            rng: RunRng::new(seed).position(),
            done: 0,
            count_sum: vec![0.0; nb],
            count_sum2: vec![0.0; nb],
            mom_sum: vec![0.0; m],
            mom_sum2: vec![0.0; m],
            cfg,
        };
        Self::from_state(st, edges)
    }

    fn from_state(st: State, edges: Vec<f64>) -> Self {
        BisectionRun {
            rng: RunRng::restore(&st.rng),
            lengths: vec![0.0; 1usize << st.cfg.level],
            counts: vec![0; edges.len() - 1],
            edges,
            st,
        }
    }

    pub fn state_bytes(&mut self) -> Vec<u8> {
        self.st.rng = self.rng.position();
        postcard::to_stdvec(&self.st).expect("state serialises")
    }

    pub fn from_state_bytes(cfg: BisectionConfig, bytes: &[u8]) -> Result<Self, SimError> {
        let st: State = postcard::from_bytes(bytes)
            .map_err(|e| format!("checkpoint payload does not decode: {e}"))?;
        if st.cfg != cfg {
            return Err("checkpoint does not match the run's bisection parameters".into());
        }
        let edges = cfg.edges();
        Ok(Self::from_state(st, edges))
    }

    pub fn progress(&self) -> f64 {
        self.st.done as f64 / self.st.cfg.realisations.max(1) as f64
    }

    /// Realisations done (the model's "time").
    pub fn done(&self) -> u64 {
        self.st.done
    }

    /// Work units of one realisation (random draws).
    pub fn work_per_realisation(&self) -> u64 {
        2u64 << self.st.cfg.level
    }

    /// One partition of [0, 1] to the configured level into `out` (length 2^level).
    pub fn partition(split: Split, level: u32, rng: &mut RunRng, out: &mut [f64]) {
        out[0] = 1.0;
        for lev in 0..level {
            let len = 1usize << lev;
            for i in (0..len).rev() {
                let x = out[i];
                let a = split.draw(rng);
                out[2 * i] = x * a;
                out[2 * i + 1] = x * (1.0 - a);
            }
        }
    }

    fn bin(&self, x: f64) -> usize {
        let e = &self.edges;
        let nb = e.len() - 1;
        if x < e[1] {
            return 0;
        }
        let b = self.st.cfg.bins_per_decade as f64;
        let mut j = ((b * (x / e[1]).log10()).max(0.0) as usize + 1).min(nb - 1);
        while j > 1 && x < e[j] {
            j -= 1;
        }
        while j + 1 < nb && x >= e[j + 1] {
            j += 1;
        }
        j
    }

    /// Up to `realisations` more realisations; true when the run is complete.
    pub fn advance(&mut self, realisations: u64) -> bool {
        let cfg = self.st.cfg.clone();
        let n_len = self.lengths.len() as f64;
        let mut k = 0;
        while self.st.done < cfg.realisations && k < realisations {
            let mut lengths = std::mem::take(&mut self.lengths);
            Self::partition(cfg.split, cfg.level, &mut self.rng, &mut lengths);
            self.counts.fill(0);
            let mut mom = vec![0.0; cfg.orders as usize];
            for &x in &lengths {
                let b = self.bin(x);
                self.counts[b] += 1;
                let mut p = 1.0;
                for m in mom.iter_mut() {
                    p *= x;
                    *m += p;
                }
            }
            self.lengths = lengths;
            for (j, &c) in self.counts.iter().enumerate() {
                let c = c as f64;
                self.st.count_sum[j] += c;
                self.st.count_sum2[j] += c * c;
            }
            for (j, m) in mom.iter().enumerate() {
                let m = m / n_len;
                self.st.mom_sum[j] += m;
                self.st.mom_sum2[j] += m * m;
            }
            self.st.done += 1;
            k += 1;
        }
        self.st.done >= cfg.realisations
    }

    pub fn finish(self) -> BisectionOutput {
        let cfg = &self.st.cfg;
        let r = self.st.done;
        let n_len = (1u64 << cfg.level) as f64;
        let histogram = (0..self.edges.len() - 1)
            .map(|j| {
                let (lo, hi) = (self.edges[j], self.edges[j + 1]);
                let w = hi - lo;
                let (mean, sem) = crate::math::stats::mean_sem_from_sums(
                    r,
                    self.st.count_sum[j],
                    self.st.count_sum2[j],
                );
                HistRow {
                    x_lo: lo,
                    x_hi: hi,
                    count: self.st.count_sum[j] as u64,
                    density: mean / (n_len * w),
                    density_sem: sem.map(|s| s / (n_len * w)),
                    density_exact: matches!(cfg.split, Split::Uniform)
                        .then(|| (uniform_cdf(cfg.level, hi) - uniform_cdf(cfg.level, lo)) / w),
                }
            })
            .collect();
        let moments = (1..=cfg.orders)
            .map(|m| {
                let j = (m - 1) as usize;
                let (mean, sem) = crate::math::stats::mean_sem_from_sums(
                    r,
                    self.st.mom_sum[j],
                    self.st.mom_sum2[j],
                );
                let am = cfg.split.moment(m);
                let exact = am.powi(cfg.level as i32);
                MomentRow {
                    order: m,
                    mean,
                    sem,
                    exact,
                    zeta_exact: -am.log2(),
                    z: sem.filter(|s| *s > 0.0).map(|s| (mean - exact) / s),
                }
            })
            .collect();
        BisectionOutput {
            realisations: r,
            histogram,
            moments,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(split: Split, level: u32, realisations: u64) -> BisectionConfig {
        BisectionConfig {
            level,
            realisations,
            split,
            x_min: 1e-12,
            bins_per_decade: 5,
            orders: 6,
        }
    }

    #[test]
    fn partitions_sum_to_one_and_cdf_matches_density() {
        let mut rng = RunRng::new(3);
        let mut out = vec![0.0; 1 << 9];
        for split in [Split::Uniform, Split::Concave { exponent: 0.3 }] {
            BisectionRun::partition(split, 9, &mut rng, &mut out);
            let s: f64 = out.iter().sum();
            assert!((s - 1.0).abs() < 1e-12, "{s}");
            assert!(out.iter().all(|x| *x >= 0.0));
        }
        // d/dx Q(n, -ln x) = P_n(x), checked by central differences.
        for n in [1, 2, 5, 9] {
            for x in [1e-6, 1e-3, 0.1, 0.5, 0.9] {
                let h = 1e-6 * x;
                let d = (uniform_cdf(n, x + h) - uniform_cdf(n, x - h)) / (2.0 * h);
                let p = uniform_density(n, x);
                assert!(
                    (d - p).abs() < 1e-5 * p.max(1e-3),
                    "n {n} x {x}: {d} vs {p}"
                );
            }
        }
        // The concave moments reduce to 1/(1+m) at A = 0 and <a> = 1/2 by symmetry.
        for m in 1..6 {
            let c = Split::Concave { exponent: 0.0 }.moment(m);
            assert!((c - 1.0 / (1.0 + m as f64)).abs() < 1e-14);
        }
        assert!((Split::Concave { exponent: 0.3 }.moment(1) - 0.5).abs() < 1e-14);
    }

    #[test]
    fn chunking_and_restore_are_invisible() {
        let c = cfg(Split::Concave { exponent: 0.2 }, 6, 50);
        let mut a = BisectionRun::new(c.clone(), 11);
        while !a.advance(1000) {}
        let mut b = BisectionRun::new(c.clone(), 11);
        b.advance(7);
        let bytes = b.state_bytes();
        let mut b = BisectionRun::from_state_bytes(c, &bytes).unwrap();
        while !b.advance(3) {}
        assert_eq!(a.finish(), b.finish());
    }
}
