//! Free paths (spec 2.9) and post-collision velocities (spec 2.3, F 5.9), from contact counts.
//!
//! Definition (soft spheres, spec 2.9 [REC]): particle i's contact count c_i(t) is the number
//! of pairs currently overlapping, maintained from the pair propagator's exact in-step contact
//! start and end times ([`super::integrate::NormalStep`]). When c_i drops to 0 (at time t_0)
//! a free path starts: its start position r_i(t_0) (unwrapped across the periodic boundaries)
//! is kept, and the velocity at that instant is the post-collision velocity v_0. When c_i rises
//! from 0 (at t_0 + tau) the path ends with length l = |r_i(t_0 + tau) - r_i(t_0)| (2D:
//! Euclidean). Re-collisions with the same partner count; particles that stay in contact
//! record nothing.
//!
//! Which paths count: those that **end within the sampled window** [warmup, warmup + duration]
//! (arrivals at the next collision, spec 2.9's "upon arrival"), whatever their start: the
//! tracking runs from the first step, so a path that started during the warm-up is complete;
//! each particle's first path starts at the end of its first contact, and a path still open
//! when the run ends is dropped. Counting by arrival time is unbiased in a steady state;
//! requiring the start in the window as well (spec 2.9's "drop the first incomplete path")
//! would under-count paths longer than the time left in the window, a bias of order
//! (mean free time)/duration. Post-collision velocities are recorded at every path start
//! (contact end) within the window: each component (2D: v_x and v_y), signed, lab frame (the
//! total momentum is zero).
//!
//! In-step positions: before a contact starts at t_on the particle is in free flight from the
//! kicked state, r(t_on) = x0 + v_k t_on; after a contact ends at t_off it is free until the
//! step's end, r(t_off) = x1 - v1 (h - t_off), v(t_off) = v1. Both are exact unless the same
//! particle has another contact change later in the same step (then the path is shorter than
//! v h ~ 1e-6 m anyway). When the superposition of pair flows leaves a pair that ended a step
//! in contact apart at the next step's start (or the reverse), the change is dated at that
//! step's start.

use serde::{Deserialize, Serialize};

use super::blocks::{block_of, block_sem, HistRow, BLOCKS};

/// Highest moment <l^m> recorded.
pub const FREE_PATH_ORDERS: usize = 4;

/// Resolved settings.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct FreePathConfig {
    /// Record the free paths (histogram and moments).
    pub paths: bool,
    /// Log-spaced bins of l (m): [lo, hi), `bins_per_decade`.
    pub lo: f64,
    pub hi: f64,
    pub bins_per_decade: u32,
    /// Post-collision velocity histogram ([v_min, v_max], bins); None: not recorded.
    pub velocity: Option<([f64; 2], u32)>,
    /// First step of the sampled window, and the steps between samples: a path ending at
    /// step `from_step + k sample_every + r` (0 <= r < sample_every) belongs to sample interval
    /// k, and its block is that of sample k.
    pub from_step: u64,
    pub sample_every: u64,
}

impl FreePathConfig {
    /// Number of log-spaced bins (ceil(bins_per_decade x decades), at least 1).
    pub fn bins(&self) -> f64 {
        let b = self.bins_per_decade as f64;
        ((b * (self.hi / self.lo).log10()) - 1e-9).ceil().max(1.0)
    }

    /// Bin edges lo 10^(j/b), j = 0..nb-1, then hi.
    pub fn edges(&self) -> Vec<f64> {
        let b = self.bins_per_decade as f64;
        let nb = self.bins() as usize;
        let mut e: Vec<f64> = (0..nb)
            .map(|j| self.lo * 10f64.powf(j as f64 / b))
            .collect();
        e.push(self.hi);
        e
    }
}

/// `rfm_free_path_moments` row.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct FreePathMomentRow {
    pub order: u32,
    /// <l^m> (m^m).
    pub value: f64,
    /// From the 10 blocks of the sampled window (paths binned by the sample interval of their
    /// end).
    pub sem: Option<f64>,
    pub n_paths: u64,
}

/// The checkpointed part: per-particle contact state, open paths and the accumulators.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct FreePathAcc {
    pub cfg: FreePathConfig,
    pub dim: u32,
    pub edges: Vec<f64>,
    /// Per particle: c_i > 0 at the end of the last step.
    pub in_contact: Vec<bool>,
    /// Per particle: a path is open (the particle has had a contact and is free since).
    pub open: Vec<bool>,
    /// Per particle: start of the open path (dim entries; the simulator's coordinates,
    /// shifted with the particle when the 2D positions are re-wrapped).
    pub start: Vec<f64>,
    /// Free-path counts: bins + 2 (below, above).
    pub l_counts: Vec<u64>,
    /// Post-collision velocity counts: bins + 2 (below, above).
    pub v_counts: Vec<u64>,
    /// Per sample interval: the sums of l^m (index m - 1) of the paths ending in it, from 0,
    /// and their number; grouped into the blocks by `rows`.
    pub interval_sums: Vec<[f64; FREE_PATH_ORDERS]>,
    pub interval_counts: Vec<u64>,
}

impl FreePathAcc {
    pub fn new(cfg: FreePathConfig, n: usize, dim: u32) -> Self {
        let edges = if cfg.paths { cfg.edges() } else { Vec::new() };
        FreePathAcc {
            l_counts: if cfg.paths {
                vec![0; edges.len() + 1]
            } else {
                Vec::new()
            },
            v_counts: cfg
                .velocity
                .map(|(_, b)| vec![0; b as usize + 2])
                .unwrap_or_default(),
            edges,
            dim,
            in_contact: vec![false; n],
            open: vec![false; n],
            start: vec![0.0; n * dim as usize],
            interval_sums: Vec::new(),
            interval_counts: Vec::new(),
            cfg,
        }
    }

    fn bin(&self, r: f64) -> usize {
        let e = &self.edges;
        let nb = e.len() - 1;
        if !(r >= e[0]) {
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

    /// A path of particle i starts at `pos` with velocity `vel` (in the window: `rec`).
    fn begin(&mut self, i: usize, pos: &[f64], vel: &[f64], rec: bool) {
        self.open[i] = true;
        let d = pos.len();
        self.start[i * d..(i + 1) * d].copy_from_slice(pos);
        if !rec {
            return;
        }
        if let Some(([lo, hi], bins)) = self.cfg.velocity {
            for &x in vel {
                let idx = if !(x >= lo) {
                    bins as usize
                } else if x >= hi {
                    bins as usize + 1
                } else {
                    (((x - lo) / (hi - lo) * bins as f64) as usize).min(bins as usize - 1)
                };
                self.v_counts[idx] += 1;
            }
        }
    }

    /// The open path of particle i (if any) ends at `pos`; recorded when `interval` is Some
    /// (the end lies in the window).
    fn end(&mut self, i: usize, pos: &[f64], interval: Option<usize>) {
        let Some(k) = interval else {
            self.open[i] = false;
            return;
        };
        if !std::mem::replace(&mut self.open[i], false) || !self.cfg.paths {
            return;
        }
        let d = pos.len();
        let l = pos
            .iter()
            .zip(&self.start[i * d..(i + 1) * d])
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt();
        let idx = self.bin(l);
        self.l_counts[idx] += 1;
        if self.interval_sums.len() <= k {
            self.interval_sums.resize(k + 1, [0.0; FREE_PATH_ORDERS]);
            self.interval_counts.resize(k + 1, 0);
        }
        let mut pw = 1.0;
        for s in self.interval_sums[k].iter_mut() {
            pw *= l;
            *s += pw;
        }
        self.interval_counts[k] += 1;
    }

    /// Histogram rows (kinds "free_path" and "post_collision_velocity") and moment rows, the
    /// errors from the blocks of a run of `samples` samples.
    pub fn rows(&self, samples: u64) -> (Vec<HistRow>, Vec<FreePathMomentRow>) {
        let mut hist = Vec::new();
        let mut moments = Vec::new();
        let row = |kind: &str, lo: f64, hi: f64, count: u64, density: Option<f64>| HistRow {
            kind: kind.into(),
            h: 0,
            lo,
            hi,
            count,
            density,
        };
        if self.cfg.paths {
            let nb = self.edges.len() - 1;
            let total: u64 = self.l_counts.iter().sum();
            for j in 0..nb {
                let (lo, hi) = (self.edges[j], self.edges[j + 1]);
                let c = self.l_counts[j];
                hist.push(row(
                    "free_path",
                    lo,
                    hi,
                    c,
                    Some(c as f64 / (total.max(1) as f64 * (hi - lo))),
                ));
            }
            hist.push(row(
                "free_path",
                0.0,
                self.edges[0],
                self.l_counts[nb],
                None,
            ));
            hist.push(row(
                "free_path",
                self.edges[nb],
                f64::INFINITY,
                self.l_counts[nb + 1],
                None,
            ));
            let mut block_sums = vec![[0.0; FREE_PATH_ORDERS]; BLOCKS];
            let mut block_counts = vec![0u64; BLOCKS];
            for (k, (sums, &c)) in self
                .interval_sums
                .iter()
                .zip(&self.interval_counts)
                .enumerate()
            {
                let b = block_of(k as u64, samples);
                for (a, x) in block_sums[b].iter_mut().zip(sums) {
                    *a += x;
                }
                block_counts[b] += c;
            }
            let n: u64 = block_counts.iter().sum();
            for m in 0..FREE_PATH_ORDERS {
                let value = block_sums.iter().map(|b| b[m]).sum::<f64>() / n.max(1) as f64;
                let blocks: Vec<f64> = block_sums
                    .iter()
                    .zip(&block_counts)
                    .filter(|(_, &c)| c > 0)
                    .map(|(b, &c)| b[m] / c as f64)
                    .collect();
                moments.push(FreePathMomentRow {
                    order: m as u32 + 1,
                    value,
                    sem: block_sem(&blocks),
                    n_paths: n,
                });
            }
        }
        if let Some(([lo, hi], bins)) = self.cfg.velocity {
            let total: u64 = self.v_counts.iter().sum();
            let width = (hi - lo) / bins as f64;
            for j in 0..bins as usize {
                let a = lo + j as f64 * width;
                let c = self.v_counts[j];
                hist.push(row(
                    "post_collision_velocity",
                    a,
                    a + width,
                    c,
                    Some(c as f64 / (total.max(1) as f64 * width)),
                ));
            }
            let nb = bins as usize;
            hist.push(row(
                "post_collision_velocity",
                f64::NEG_INFINITY,
                lo,
                self.v_counts[nb],
                None,
            ));
            hist.push(row(
                "post_collision_velocity",
                hi,
                f64::INFINITY,
                self.v_counts[nb + 1],
                None,
            ));
        }
        (hist, moments)
    }
}

/// One pair's contact interval within the step, seen from one particle, with that particle's
/// kicked state (position at the step start, free-flight velocity).
#[derive(Clone, Copy, Debug)]
pub struct Ev<const D: usize> {
    pub i: u32,
    pub t_on: f64,
    pub t_off: f64,
    pub x0: [f64; D],
    pub vf: [f64; D],
}

/// The tracker inside the simulation core: the checkpointed [`FreePathAcc`] and scratch.
pub struct FreePaths<const D: usize> {
    pub acc: FreePathAcc,
    /// This step's contact intervals (two per contacting pair).
    pub ev: Vec<Ev<D>>,
    /// The symmetrising shift of this step's kick (free-flight velocity = v - c).
    pub c: [f64; D],
    /// Particles in contact at the end of the last step (derived from `acc.in_contact`).
    busy: Vec<u32>,
    busy_next: Vec<u32>,
    /// Step stamp of the particles seen this step.
    stamp: Vec<u64>,
    ch: Vec<(f64, i32)>,
}

impl<const D: usize> FreePaths<D> {
    pub fn new(acc: FreePathAcc) -> Self {
        let n = acc.in_contact.len();
        let busy = (0..n as u32)
            .filter(|&i| acc.in_contact[i as usize])
            .collect();
        FreePaths {
            acc,
            ev: Vec::new(),
            c: [0.0; D],
            busy,
            busy_next: Vec::new(),
            stamp: vec![u64::MAX; n],
            ch: Vec::new(),
        }
    }

    /// Record one contacting pair's interval for both partners (kicked state, before the
    /// step's corrections): the particles stored at indices `i` and `j` of `x` and `v`,
    /// which hold particle `ids[i]` and `ids[j]` (particles stored out of order; `ids` empty:
    /// particle i at index i).
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn push(
        &mut self,
        i: usize,
        j: usize,
        t_on: f64,
        t_off: f64,
        x: &[[f64; D]],
        v: &[[f64; D]],
        ids: &[u32],
    ) {
        for s in [i, j] {
            self.ev.push(Ev {
                i: if ids.is_empty() { s as u32 } else { ids[s] },
                t_on,
                t_off,
                x0: x[s],
                vf: std::array::from_fn(|k| v[s][k] - self.c[k]),
            });
        }
    }

    /// After the step (positions `x`, velocities `v` at its end, particle i stored at index
    /// `at[i]`, or at i with `at` empty; `step` = index of the step just done, length `h`):
    /// walk each touched particle's contact count through the step, in particle order.
    pub fn post(&mut self, x: &[[f64; D]], v: &[[f64; D]], at: &[u32], h: f64, step: u64) {
        let slot = |i: usize| if at.is_empty() { i } else { at[i] as usize };
        let cfg = &self.acc.cfg;
        let rec = step >= cfg.from_step;
        let interval = rec.then(|| ((step - cfg.from_step) / cfg.sample_every.max(1)) as usize);
        let mut ev = std::mem::take(&mut self.ev);
        ev.sort_unstable_by(|a, b| a.i.cmp(&b.i).then(a.t_on.total_cmp(&b.t_on)));
        let mut next = std::mem::take(&mut self.busy_next);
        next.clear();
        let mut ch = std::mem::take(&mut self.ch);
        let mut k = 0;
        while k < ev.len() {
            let i = ev[k].i as usize;
            let mut e = k;
            ch.clear();
            ch.push((0.0, 0));
            while e < ev.len() && ev[e].i as usize == i {
                ch.push((ev[e].t_on, 1));
                if ev[e].t_off < h {
                    ch.push((ev[e].t_off, -1));
                }
                e += 1;
            }
            // Starts before ends at equal times (no spurious transition).
            ch.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(b.1.cmp(&a.1)));
            let (x0, vf) = (ev[k].x0, ev[k].vf);
            let mut state = self.acc.in_contact[i];
            let mut cnt = 0i32;
            let mut p = 0;
            while p < ch.len() {
                let t = ch[p].0;
                while p < ch.len() && ch[p].0 == t {
                    cnt += ch[p].1;
                    p += 1;
                }
                let now = cnt > 0;
                if now != state {
                    if now {
                        let pos: [f64; D] = std::array::from_fn(|q| x0[q] + vf[q] * t);
                        self.acc.end(i, &pos, interval);
                    } else {
                        let s = slot(i);
                        let pos: [f64; D] = std::array::from_fn(|q| x[s][q] - v[s][q] * (h - t));
                        self.acc.begin(i, &pos, &v[s], rec);
                    }
                    state = now;
                }
            }
            self.acc.in_contact[i] = state;
            self.stamp[i] = step;
            if state {
                next.push(i as u32);
            }
            k = e;
        }
        // In contact at the last step's end, no contact at all in this one: free from t = 0.
        for &i in &self.busy {
            let i = i as usize;
            if self.stamp[i] != step {
                self.acc.in_contact[i] = false;
                let s = slot(i);
                let pos: [f64; D] = std::array::from_fn(|q| x[s][q] - v[s][q] * h);
                self.acc.begin(i, &pos, &v[s], rec);
            }
        }
        self.busy_next = std::mem::replace(&mut self.busy, next);
        ev.clear();
        self.ev = ev;
        self.ch = ch;
    }

    /// The positions of particle i (its number, not its storage index) moved by `shift` (2D
    /// re-wrap): move its open start too.
    #[inline]
    pub fn shift(&mut self, i: usize, k: usize, shift: f64) {
        if self.acc.open[i] {
            self.acc.start[i * D + k] += shift;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rfm::{RfmConfig, RfmSim};

    fn config(paths: bool, velocity: Option<([f64; 2], u32)>, lo: f64, hi: f64) -> FreePathConfig {
        FreePathConfig {
            paths,
            lo,
            hi,
            bins_per_decade: 20,
            velocity,
            from_step: 0,
            sample_every: 100_000,
        }
    }

    /// Two discs head-on (no noise, eps_n = 0.6, eps_t = 1), 0.5 m/s each: one collision, the
    /// post-collision velocity histogram (bins 1e-6 m/s) holds exactly v_x = -0.3 and +0.3
    /// and v_y = 0 twice, the exact post-collision velocities -eps v.
    #[test]
    fn head_on_post_collision_velocities() {
        let cfg = RfmConfig {
            n_particles: 2,
            box_length: Some(0.1),
            noise_strength: 0.0,
            restitution_tangential: 1.0,
            ..RfmConfig::default()
        };
        let mut sim = RfmSim::from_parts(
            cfg,
            1,
            vec![0.04, 0.05, 0.06, 0.05],
            vec![0.5, 0.0, -0.5, 0.0],
        )
        .unwrap();
        let bins = 2_000_000;
        sim.track_free_paths(config(true, Some(([-1.0, 1.0], bins)), 1e-6, 1.0));
        sim.advance(50_000);
        let v = sim.velocities();
        eprintln!("head-on: post-collision v_x = {:.15} {:.15}", v[0], v[2]);
        assert!((v[0] + 0.3).abs() < 1e-10 && (v[2] - 0.3).abs() < 1e-10);
        let (hist, moments) = sim.free_path_rows(1);
        let pcv: Vec<&HistRow> = hist
            .iter()
            .filter(|h| h.kind == "post_collision_velocity" && h.count > 0)
            .collect();
        let total: u64 = pcv.iter().map(|h| h.count).sum();
        assert_eq!(total, 4);
        for (want, n) in [(-0.3, 1), (0.0, 2), (0.3, 1)] {
            let row = pcv
                .iter()
                .find(|h| h.lo <= want + 1e-9 && want - 1e-9 < h.hi)
                .unwrap_or_else(|| panic!("no count near {want}: {pcv:?}"));
            assert_eq!(row.count, n, "{want}");
            assert!(row.hi - row.lo < 1.1e-6);
        }
        // One collision, no path completed yet.
        assert_eq!(moments[0].n_paths, 0);
    }

    /// 1D, two rods on a ring (L' = 0.01 m, eps = 0.9, no noise, v = 0.7 and -0.3 m/s): the
    /// free paths are the gaps travelled between consecutive contacts. Direct construction:
    /// after each contact the relative velocity reverses times eps about the centre-of-mass
    /// velocity V; the next contact (the other side of the ring) closes the reduced gap L' at
    /// the relative speed |g|, so each rod travels |v_i| L'/|g|. The recorded paths (count and
    /// <l^m>, m = 1..4) match the construction to 1e-9 relative.
    #[test]
    fn ring_pair_paths_match_direct_construction() {
        let eps = 0.9;
        let lr = 0.01;
        let cfg = RfmConfig {
            noise_strength: 0.0,
            reduced_length: Some(lr),
            ..RfmConfig::thesis_1d(2, eps)
        };
        let l = cfg.box_length();
        let d = cfg.diameter();
        let (v0, v1) = (0.7, -0.3);
        let x = vec![0.25 * l, 0.25 * l + d + 0.004];
        let mut sim = RfmSim::from_parts(cfg.clone(), 1, x.clone(), vec![v0, v1]).unwrap();
        sim.track_free_paths(config(true, None, 1e-9, 1.0));
        // Construction: event times (contact durations ~2e-5 s neglected in choosing the end).
        let vc = 0.5 * (v0 + v1);
        let mut g = v0 - v1; // closing speed of the first contact
        let mut t = 0.004 / g;
        let mut paths: Vec<f64> = Vec::new();
        let t_end = 0.1;
        loop {
            g *= eps; // relative speed after the contact
            let (a, b) = (vc - 0.5 * g, vc + 0.5 * g);
            let tau = lr / g;
            if t + tau > t_end {
                assert!(t + tau - t_end > 1e-3 && t_end - t > 1e-3, "end too close");
                break;
            }
            t += tau;
            paths.push(a.abs() * tau);
            paths.push(b.abs() * tau);
        }
        sim.advance((t_end / cfg.dt()).round() as u64);
        let (_, moments) = sim.free_path_rows(1);
        assert_eq!(moments[0].n_paths as usize, paths.len());
        for m in 1..=4 {
            let want = paths.iter().map(|l| l.powi(m)).sum::<f64>() / paths.len() as f64;
            let got = moments[m as usize - 1].value;
            eprintln!("1D ring pair: <l^{m}> = {got:.12e} vs construction {want:.12e}");
            assert!((got / want - 1.0).abs() < 1e-9, "m {m}: {got} vs {want}");
        }
    }
}
