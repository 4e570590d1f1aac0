//! A Random Force Model run with its observables (spec section 2): warm-up, then snapshots
//! every `sample_every` steps during `duration`, each feeding the requested accumulators. No
//! observable work happens between samples.
//!
//! - temperature (2.19) time series, always;
//! - velocity moments <|v_c|^m>, m = 1..12, of the velocity components in the centre-of-mass
//!   frame (pooled components, spec 2.2), with standard errors from 10 consecutive blocks of the
//!   sampled time (the thesis's block protocol, spec 2.2);
//! - histogram of the signed velocity components (spec 2.3), counts kept;
//! - structure ([`super::structure`]): 1D neighbour distances (spec 2.6), 2D S(k) (2.7),
//!   2D g(R) and C(R) (2.8).

use serde::{Deserialize, Serialize};

use super::freepath::FreePathMomentRow;
use super::structure::{
    NeighbourAcc, NeighbourMomentRow, RadialAcc, RadialRow, SkAcc, SkRow, SkWork,
};
use super::{RfmConfig, RfmSim};
use crate::manifest::rfm::{HistogramSpec, RfmObservable, RfmParams};

/// Number of blocks the sampled time is cut into for standard errors.
pub const BLOCKS: usize = 10;
/// Highest velocity moment recorded.
pub const MAX_ORDER: usize = 12;

/// `rfm_timeseries` row.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct TimeRow {
    pub t: f64,
    pub temperature: f64,
}

/// `rfm_moments` row.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct MomentRow {
    pub order: u32,
    pub value: f64,
    pub sem: Option<f64>,
}

/// `rfm_histograms` row.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct HistRow {
    pub kind: String,
    /// Neighbour order for neighbour-distance histograms; 0 otherwise.
    pub h: u32,
    pub lo: f64,
    pub hi: f64,
    pub count: u64,
    /// count / (total count x bin width); null for the out-of-range rows.
    pub density: Option<f64>,
}

/// Accumulators (checkpointed with the run).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq, Default)]
pub struct Sampler {
    pub samples_total: u64,
    pub samples_done: u64,
    pub series: Vec<TimeRow>,
    pub moments: bool,
    /// Per block: sums of |v_c|^m (index m - 1) and the number of values.
    pub block_sums: Vec<[f64; MAX_ORDER]>,
    pub block_counts: Vec<u64>,
    pub hist: Option<HistogramSpec>,
    /// bins + 2 (below, above).
    pub counts: Vec<u64>,
    /// 1D neighbour distances.
    pub neighbours: Option<NeighbourAcc>,
    /// 2D structure factor.
    pub sk: Option<SkAcc>,
    /// 2D radial distribution.
    pub radial: Option<RadialAcc>,
    /// Requested snapshot times (sorted) and how many were taken.
    pub snap_times: Vec<f64>,
    pub snap_next: usize,
    pub snapshots: Vec<SnapshotRow>,
}

/// `rfm_snapshots` row: one particle at one snapshot.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct SnapshotRow {
    pub t: f64,
    pub particle: u32,
    pub x: f64,
    pub y: Option<f64>,
    pub vx: f64,
    pub vy: Option<f64>,
}

/// `rfm_temperature_blocks` row: the time average (2.20) of T over one of the 10 blocks.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct TemperatureBlockRow {
    pub block: u32,
    pub t_from: f64,
    pub t_to: f64,
    pub n_samples: u32,
    pub temperature: f64,
}

impl Sampler {
    /// The block of the current sample.
    fn block(&self) -> usize {
        ((self.samples_done as usize * BLOCKS) / self.samples_total.max(1) as usize).min(BLOCKS - 1)
    }

    /// Same observables and settings (a checkpoint's sampler against a fresh one).
    fn same_shape(&self, o: &Sampler) -> bool {
        self.samples_total == o.samples_total
            && self.counts.len() == o.counts.len()
            && self.moments == o.moments
            && self.hist == o.hist
            && self.neighbours.as_ref().map(|a| (&a.cfg, a.counts.len()))
                == o.neighbours.as_ref().map(|a| (&a.cfg, a.counts.len()))
            && self.sk.as_ref().map(|a| (&a.cfg, a.block_sums.len()))
                == o.sk.as_ref().map(|a| (&a.cfg, a.block_sums.len()))
            && self.radial.as_ref().map(|a| (&a.cfg, a.counts.len()))
                == o.radial.as_ref().map(|a| (&a.cfg, a.counts.len()))
            && self.snap_times == o.snap_times
    }
}

/// The state of an RFM run beside the simulator's.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
struct RunState {
    sim: Vec<u8>,
    sampler: Sampler,
}

pub struct RfmRun {
    pub sim: RfmSim,
    pub sampler: Sampler,
    warmup_steps: u64,
    sample_every: u64,
    /// Scratch of the S(k) sums (derived from the settings, not checkpointed).
    sk_work: Option<SkWork>,
    /// Scratch of the g(R) pair loop.
    pair_buf: Vec<f64>,
}

/// The run's output rows.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RfmOutput {
    pub timeseries: Vec<TimeRow>,
    pub moments: Vec<MomentRow>,
    pub histograms: Vec<HistRow>,
    pub neighbour_moments: Vec<NeighbourMomentRow>,
    pub structure_factor: Vec<SkRow>,
    pub radial: Vec<RadialRow>,
    pub temperature_blocks: Vec<TemperatureBlockRow>,
    pub snapshots: Vec<SnapshotRow>,
    pub free_path_moments: Vec<FreePathMomentRow>,
}

impl RfmRun {
    fn sampler_for(p: &RfmParams, cfg: &RfmConfig) -> Sampler {
        let total = cfg.duration_steps() / cfg.sample_every;
        let hist = p
            .wants(RfmObservable::VelocityHistogram)
            .then(|| p.velocity_histogram.clone().unwrap_or_default());
        Sampler {
            samples_total: total,
            samples_done: 0,
            series: Vec::new(),
            moments: p.wants(RfmObservable::VelocityMoments),
            block_sums: vec![[0.0; MAX_ORDER]; BLOCKS],
            block_counts: vec![0; BLOCKS],
            counts: hist
                .as_ref()
                .map(|h| vec![0; h.bins as usize + 2])
                .unwrap_or_default(),
            hist,
            neighbours: p.neighbour_config().map(NeighbourAcc::new),
            sk: p.structure_factor_config().map(SkAcc::new),
            radial: p.radial_config().map(RadialAcc::new),
            snap_times: p
                .wants(RfmObservable::Snapshot)
                .then(|| {
                    let mut t = p
                        .snapshot
                        .as_ref()
                        .map(|s| s.times.clone())
                        .unwrap_or_default();
                    t.sort_by(f64::total_cmp);
                    t
                })
                .unwrap_or_default(),
            snap_next: 0,
            snapshots: Vec::new(),
        }
    }

    fn assemble(sim: RfmSim, sampler: Sampler, cfg: &RfmConfig) -> Self {
        RfmRun {
            sim,
            sk_work: sampler.sk.as_ref().map(SkAcc::work),
            sampler,
            warmup_steps: cfg.warmup_steps(),
            sample_every: cfg.sample_every,
            pair_buf: Vec::new(),
        }
    }

    pub fn new(p: &RfmParams, seed: u64) -> Result<Self, String> {
        let cfg = p.config();
        let sampler = Self::sampler_for(p, &cfg);
        let mut sim = RfmSim::new(cfg.clone(), seed)?;
        if let Some(fc) = p.free_path_config() {
            sim.track_free_paths(fc);
        }
        Ok(Self::assemble(sim, sampler, &cfg))
    }

    pub fn state_bytes(&self) -> Vec<u8> {
        let st = RunState {
            sim: self.sim.state_bytes(),
            sampler: self.sampler.clone(),
        };
        postcard::to_stdvec(&st).expect("state serialises")
    }

    pub fn from_state_bytes(p: &RfmParams, bytes: &[u8]) -> Result<Self, String> {
        let st: RunState = postcard::from_bytes(bytes)
            .map_err(|e| format!("checkpoint payload does not decode: {e}"))?;
        let cfg = p.config();
        let fresh = Self::sampler_for(p, &cfg);
        if !fresh.same_shape(&st.sampler) {
            return Err("checkpoint does not match the run's observables".into());
        }
        let sim = RfmSim::from_state_bytes(cfg.clone(), &st.sim)?;
        if sim.free_path_config() != p.free_path_config().as_ref() {
            return Err("checkpoint does not match the run's observables".into());
        }
        Ok(Self::assemble(sim, st.sampler, &cfg))
    }

    pub fn is_done(&self) -> bool {
        self.sampler.samples_done >= self.sampler.samples_total
    }

    pub fn progress(&self) -> f64 {
        let total = self.warmup_steps + self.sampler.samples_total * self.sample_every;
        (self.sim.step() as f64 / total.max(1) as f64).min(1.0)
    }

    /// Advance by at most `max_steps` steps, sampling on the way; true when done.
    pub fn advance(&mut self, max_steps: u64) -> Result<bool, crate::dsmc::PhysicsError> {
        let mut left = max_steps.max(1);
        while !self.is_done() && left > 0 {
            let next_sample =
                self.warmup_steps + (self.sampler.samples_done + 1) * self.sample_every;
            let n = (next_sample - self.sim.step()).min(left);
            self.sim.advance(n);
            left -= n;
            if self.sim.step() == next_sample {
                self.sample()?;
            }
        }
        Ok(self.is_done())
    }

    fn sample(&mut self) -> Result<(), crate::dsmc::PhysicsError> {
        let t = self.sim.time();
        let temperature = self.sim.temperature();
        if !temperature.is_finite() {
            return Err(crate::dsmc::PhysicsError {
                t,
                reason: "non-finite velocities".into(),
            });
        }
        let s = &mut self.sampler;
        s.series.push(TimeRow { t, temperature });
        if s.snap_next < s.snap_times.len() && s.snap_times[s.snap_next] <= t * (1.0 + 1e-12) {
            while s.snap_next < s.snap_times.len() && s.snap_times[s.snap_next] <= t * (1.0 + 1e-12)
            {
                s.snap_next += 1;
            }
            let (x, v) = (self.sim.positions(), self.sim.velocities());
            let d = self.sim.config().dim as usize;
            for (i, (p, u)) in x.chunks_exact(d).zip(v.chunks_exact(d)).enumerate() {
                s.snapshots.push(SnapshotRow {
                    t,
                    particle: i as u32,
                    x: p[0],
                    y: (d == 2).then(|| p[1]),
                    vx: u[0],
                    vy: (d == 2).then(|| u[1]),
                });
            }
        }
        if s.moments || s.hist.is_some() {
            let v = self.sim.velocities();
            let d = self.sim.config().dim as usize;
            let n = v.len() / d;
            let mut mean = [0.0; 2];
            for p in v.chunks_exact(d) {
                for c in 0..d {
                    mean[c] += p[c];
                }
            }
            for m in mean.iter_mut().take(d) {
                *m /= n as f64;
            }
            let block = s.block();
            for p in v.chunks_exact(d) {
                for c in 0..d {
                    let x = p[c] - mean[c];
                    if s.moments {
                        let a = x.abs();
                        let mut pw = 1.0;
                        let sums = &mut s.block_sums[block];
                        for sm in sums.iter_mut() {
                            pw *= a;
                            *sm += pw;
                        }
                    }
                    if let Some(h) = &s.hist {
                        let (lo, hi) = (h.range[0], h.range[1]);
                        let idx = if x < lo {
                            h.bins as usize
                        } else if x >= hi {
                            h.bins as usize + 1
                        } else {
                            (((x - lo) / (hi - lo) * h.bins as f64) as usize)
                                .min(h.bins as usize - 1)
                        };
                        s.counts[idx] += 1;
                    }
                }
            }
            if s.moments {
                s.block_counts[block] += (n * d) as u64;
            }
        }
        let block = s.block();
        // S(k) and g(R) at every `every`-th snapshot.
        let sk_now =
            s.sk.as_ref()
                .is_some_and(|a| s.samples_done.is_multiple_of(a.cfg.every as u64));
        let radial_now = s
            .radial
            .as_ref()
            .is_some_and(|a| s.samples_done.is_multiple_of(a.cfg.every as u64));
        let want_x = s.neighbours.is_some() || sk_now || radial_now;
        if want_x {
            let x = self.sim.positions();
            let cfg = self.sim.config();
            let (l, d) = (cfg.box_length(), cfg.diameter());
            if let Some(a) = &mut s.neighbours {
                a.add(&x, l, d, block);
            }
            if let (Some(a), true) = (&mut s.sk, sk_now) {
                let w = self.sk_work.as_mut().expect("S(k) scratch");
                a.add(w, &x, l, block);
            }
            if let (Some(a), true) = (&mut s.radial, radial_now) {
                a.add(&mut self.pair_buf, &x, block);
            }
        }
        s.samples_done += 1;
        Ok(())
    }

    /// The rows of a finished run.
    pub fn finish(self) -> RfmOutput {
        let s = self.sampler;
        // Block means (2.20) of the temperature series, in the moments' blocks.
        let mut temperature_blocks = Vec::new();
        {
            let total = s.samples_total.max(1) as usize;
            let mut acc: Vec<(f64, f64, u32, f64)> = vec![(f64::NAN, f64::NAN, 0, 0.0); BLOCKS];
            for (j, r) in s.series.iter().enumerate() {
                let b = ((j * BLOCKS) / total).min(BLOCKS - 1);
                let a = &mut acc[b];
                if a.2 == 0 {
                    a.0 = r.t;
                }
                a.1 = r.t;
                a.2 += 1;
                a.3 += r.temperature;
            }
            for (b, a) in acc.into_iter().enumerate() {
                if a.2 > 0 {
                    temperature_blocks.push(TemperatureBlockRow {
                        block: b as u32,
                        t_from: a.0,
                        t_to: a.1,
                        n_samples: a.2,
                        temperature: a.3 / a.2 as f64,
                    });
                }
            }
        }
        let mut moments = Vec::new();
        if s.moments {
            let total: u64 = s.block_counts.iter().sum();
            for m in 0..MAX_ORDER {
                let value = s.block_sums.iter().map(|b| b[m]).sum::<f64>() / total.max(1) as f64;
                let blocks: Vec<f64> = s
                    .block_sums
                    .iter()
                    .zip(&s.block_counts)
                    .filter(|(_, &c)| c > 0)
                    .map(|(b, &c)| b[m] / c as f64)
                    .collect();
                let sem = (blocks.len() >= 2).then(|| {
                    let k = blocks.len() as f64;
                    let mean = blocks.iter().sum::<f64>() / k;
                    (blocks.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (k - 1.0) / k)
                        .sqrt()
                });
                moments.push(MomentRow {
                    order: m as u32 + 1,
                    value,
                    sem,
                });
            }
        }
        let mut histograms = Vec::new();
        if let Some(h) = &s.hist {
            let total: u64 = s.counts.iter().sum();
            let width = (h.range[1] - h.range[0]) / h.bins as f64;
            for j in 0..h.bins as usize {
                let lo = h.range[0] + j as f64 * width;
                histograms.push(HistRow {
                    kind: "velocity".into(),
                    h: 0,
                    lo,
                    hi: lo + width,
                    count: s.counts[j],
                    density: Some(s.counts[j] as f64 / (total.max(1) as f64 * width)),
                });
            }
            histograms.push(HistRow {
                kind: "velocity".into(),
                h: 0,
                lo: f64::NEG_INFINITY,
                hi: h.range[0],
                count: s.counts[h.bins as usize],
                density: None,
            });
            histograms.push(HistRow {
                kind: "velocity".into(),
                h: 0,
                lo: h.range[1],
                hi: f64::INFINITY,
                count: s.counts[h.bins as usize + 1],
                density: None,
            });
        }
        let mut neighbour_moments = Vec::new();
        if let Some(a) = &s.neighbours {
            let (h, m) = a.rows();
            histograms.extend(h);
            neighbour_moments = m;
        }
        let (fp_hist, free_path_moments) = self.sim.free_path_rows();
        histograms.extend(fp_hist);
        let cfg = self.sim.config();
        RfmOutput {
            timeseries: s.series,
            moments,
            histograms,
            neighbour_moments,
            structure_factor: s
                .sk
                .as_ref()
                .map(|a| a.rows(cfg.n_particles, cfg.box_length()))
                .unwrap_or_default(),
            radial: s.radial.as_ref().map(|a| a.rows()).unwrap_or_default(),
            temperature_blocks,
            snapshots: s.snapshots,
            free_path_moments,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(dim: u32) -> RfmParams {
        let mut v = serde_json::json!({
            "dim": dim,
            "n_particles": 300,
            "warmup": 0.01,
            "duration": 0.03,
            "sample_every": 500,
            "observables": ["velocity_moments", "velocity_histogram"],
            "velocity_histogram": {"range": [-2, 2], "bins": 200}
        });
        if dim == 2 {
            v["packing_fraction"] = serde_json::json!(0.3);
            v["restitution_tangential"] = serde_json::json!(0.6);
        } else {
            v["reduced_length"] = serde_json::json!(0.5);
        }
        serde_json::from_value(v).unwrap()
    }

    /// `params` with every structure observable of the dimension on, and the free paths and
    /// post-collision velocities.
    fn params_all(dim: u32) -> RfmParams {
        let mut p = params(dim);
        p.observables.push(RfmObservable::FreePaths);
        p.observables.push(RfmObservable::PostCollisionVelocity);
        if dim == 1 {
            p.observables.push(RfmObservable::NeighbourDistances);
            p.neighbour_distances = Some(crate::manifest::rfm::NeighbourSpec {
                h_max: 4,
                range: Some([1e-8, 0.5]),
                bins_per_decade: 10,
            });
        } else {
            p.observables.push(RfmObservable::StructureFactor);
            p.observables.push(RfmObservable::RadialDistribution);
            p.structure_factor = Some(crate::manifest::rfm::StructureFactorSpec {
                k_max: Some(25.0),
                every: 2,
            });
        }
        p
    }

    /// A run restored from a checkpoint taken at any point continues bit for bit: the same
    /// rows as the uninterrupted run (warm-up, mid-sampling, state after a sample).
    #[test]
    fn restore_is_bitwise() {
        for dim in [1, 2] {
            let p = params_all(dim);
            let mut errors = Vec::new();
            p.check("", &mut errors);
            assert!(errors.is_empty(), "{errors:?}");
            let mut a = RfmRun::new(&p, 9).unwrap();
            while !a.advance(777).unwrap() {}
            let want = a.finish();
            for cut in [5_000u64, 10_000, 10_500, 17_321] {
                let mut b = RfmRun::new(&p, 9).unwrap();
                b.advance(cut).unwrap();
                let bytes = b.state_bytes();
                let mut c = RfmRun::from_state_bytes(&p, &bytes).unwrap();
                while !c.advance(1000).unwrap() {}
                assert_eq!(c.finish(), want, "dim {dim}, restored at step {cut}");
            }
            if dim == 1 {
                assert_eq!(want.neighbour_moments.len(), 4 * 9);
                assert!(want
                    .histograms
                    .iter()
                    .any(|h| h.kind == "neighbour_distance"));
            } else {
                assert!(!want.structure_factor.is_empty() && !want.radial.is_empty());
            }
            let n_paths = want.free_path_moments[0].n_paths;
            let n_v: u64 = want
                .histograms
                .iter()
                .filter(|h| h.kind == "post_collision_velocity")
                .map(|h| h.count)
                .sum();
            eprintln!("dim {dim}: {n_paths} free paths, {n_v} post-collision components");
            assert!(n_paths > 100 && n_v > 100 * dim as u64);
            // A checkpoint of other observables is refused.
            let b = RfmRun::new(&p, 9).unwrap();
            assert!(RfmRun::from_state_bytes(&params(dim), &b.state_bytes()).is_err());
        }
    }

    /// 1D engine (eps = 0.6, N = 300, L' = 0.5): the neighbour histograms hold N separations
    /// per h and snapshot, <R_h> = h L'/N (the gaps sum to L'; soft overlaps counted with
    /// |.| add a little), and the moments are non-degenerate (<R^2> >= <R>^2).
    #[test]
    fn neighbour_distances_in_the_engine() {
        let p = params_all(1);
        let mut r = RfmRun::new(&p, 5).unwrap();
        while !r.advance(u64::MAX).unwrap() {}
        let samples = r.sampler.samples_total;
        let out = r.finish();
        for h in 1..=4u32 {
            let total: u64 = out
                .histograms
                .iter()
                .filter(|x| x.kind == "neighbour_distance" && x.h == h)
                .map(|x| x.count)
                .sum();
            assert_eq!(total, samples * 300);
            let m: Vec<&_> = out.neighbour_moments.iter().filter(|x| x.h == h).collect();
            let want = h as f64 * 0.5 / 300.0;
            let rel = m[0].value / want - 1.0;
            eprintln!(
                "1D: <R_{h}> / (h L'/N) - 1 = {rel:.2e}, sem {:.2e}",
                m[0].sem.unwrap()
            );
            // sum_i (x_{i+h} - x_i - h d) = h L' exactly on the ring, and |.| >= .: so
            // <R_h> >= h L'/N up to rounding (1e-12), and soft overlaps are rare and small.
            assert!((-1e-12..1e-4).contains(&rel), "h {h}: {rel}");
            assert!(m[1].value >= m[0].value * m[0].value);
        }
    }

    fn elastic_gas() -> RfmParams {
        serde_json::from_value(serde_json::json!({
            "dim": 2,
            "n_particles": 500,
            "packing_fraction": 0.05,
            "restitution_normal": 1.0,
            "warmup": 0.05,
            "duration": 0.1,
            "sample_every": 5000,
            "observables": ["structure_factor", "radial_distribution"],
            "radial_distribution": {"bins": 400}
        }))
        .unwrap()
    }

    /// The elastic dilute gas (eps_n = eps_t = 1, phi = 0.05, N = 500, 20 snapshots): S(k) -> 1
    /// at large k (k d in [10, 20]: mean within 0.01, every window of width 1 in k d within
    /// 0.05), and g(R) = 0 inside the core (R < 0.95 d), -> 1 at large R (R in [3 d, L/2]: mean
    /// within 0.02, every 20-bin window within 0.1), C(R) -> the ideal (N-1) pi R^2/L^2.
    #[test]
    fn elastic_gas_structure() {
        let p = elastic_gas();
        let cfg = p.config();
        let (d, l) = (cfg.diameter(), cfg.box_length());
        let mut r = RfmRun::new(&p, 21).unwrap();
        let t0 = std::time::Instant::now();
        while !r.advance(u64::MAX).unwrap() {}
        let out = r.finish();
        eprintln!("elastic gas run: {:.2} s", t0.elapsed().as_secs_f64());
        let sk = &out.structure_factor;
        assert!(sk.last().unwrap().k * d <= 20.0 && sk.last().unwrap().k * d > 19.9);
        let window = |lo: f64, hi: f64| {
            let (s, w) = sk
                .iter()
                .filter(|x| x.k * d >= lo && x.k * d < hi)
                .fold((0.0, 0.0), |a, x| {
                    (a.0 + x.s * x.n_vectors as f64, a.1 + x.n_vectors as f64)
                });
            s / w
        };
        let large = window(10.0, 20.0);
        eprintln!(
            "elastic gas: S(k d in [10, 20]) = {large:.4}, S(first shell) = {:.3}",
            sk[0].s
        );
        assert!((large - 1.0).abs() < 0.01, "{large}");
        for j in 5..20 {
            let s = window(j as f64, j as f64 + 1.0);
            assert!((s - 1.0).abs() < 0.05, "k d in [{j}, {}]: {s}", j + 1);
        }
        let g = &out.radial;
        assert!(g.iter().filter(|x| x.r_hi < 0.95 * d).all(|x| x.count == 0));
        let far: Vec<_> = g.iter().filter(|x| x.r_lo >= 3.0 * d).collect();
        let mean = far.iter().map(|x| x.g).sum::<f64>() / far.len() as f64;
        eprintln!(
            "elastic gas: g(R >= 3d) = {mean:.4}, contact g = {:.3}",
            g.iter().find(|x| x.r_lo >= d).unwrap().g
        );
        assert!((mean - 1.0).abs() < 0.02, "{mean}");
        for w in far.chunks(20) {
            let m = w.iter().map(|x| x.g).sum::<f64>() / w.len() as f64;
            assert!((m - 1.0).abs() < 0.1, "g near R = {}: {m}", w[0].r_lo);
        }
        let last = g.last().unwrap();
        let ideal = 499.0 * std::f64::consts::PI * last.r_hi.powi(2) / (l * l);
        assert!(
            (last.c / ideal - 1.0).abs() < 0.01,
            "C(L/2) = {} vs {ideal}",
            last.c
        );
    }

    /// Dilute elastic gas (2D, eps_n = eps_t = 1, phi = 0.01, N = 1000, L = 0.84 m): the mean
    /// free path against kinetic theory l_kin = 1/(2 sqrt(2) n d) = pi d/(8 sqrt(2) phi)
    /// (Maxwellian, relative-speed factor sqrt 2), with the Enskog contact value of the pair
    /// correlation chi = (1 - 7 phi/16)/(1 - phi)^2 = 1.016 as the finite-density correction:
    /// expect <l> = l_kin/chi. Started from the random layout with Maxwellian velocities
    /// (2 m/s per component) and weak noise (D = 1e-10: the velocity diffuses by < 0.2% over a
    /// free time, so flights are straight), 0.2 s (~6 mean free times) to relax and to open
    /// every particle's path history (with a shorter warm-up the first blocks under-count
    /// long paths: 0.05 s gave block means rising from 0.057 to 0.08 m), paths arriving in the
    /// next 0.3 s (~9 mean free times, ~9000 paths). Tolerance 3 sem (10 blocks) + 1% (Enskog is itself
    /// approximate at this order; soft contacts).
    #[test]
    fn dilute_gas_mean_free_path() {
        let cfg = RfmConfig {
            n_particles: 1000,
            box_length: None,
            packing_fraction: Some(0.01),
            noise_strength: 1e-10,
            restitution_normal: 1.0,
            restitution_tangential: 1.0,
            warmup: 0.2,
            duration: 0.3,
            ..RfmConfig::default()
        };
        let x = RfmSim::new(cfg.clone(), 13).unwrap().positions();
        let mut rng = crate::rng::RunRng::new(14);
        let mut v: Vec<f64> = (0..2000).map(|_| 2.0 * rng.normal()).collect();
        for k in 0..2 {
            let m = v.iter().skip(k).step_by(2).sum::<f64>() / 1000.0;
            for a in v.iter_mut().skip(k).step_by(2) {
                *a -= m;
            }
        }
        let mut sim = RfmSim::from_parts(cfg.clone(), 15, x, v).unwrap();
        let (warm, window) = (cfg.warmup_steps(), cfg.duration_steps());
        sim.track_free_paths(crate::rfm::freepath::FreePathConfig {
            paths: true,
            lo: 1e-6,
            hi: 10.0,
            bins_per_decade: 20,
            velocity: Some(([-10.0, 10.0], 200)),
            from_step: warm,
            window_steps: window,
        });
        let d = cfg.diameter();
        let phi = 0.01;
        let l_kin = std::f64::consts::PI * d / (8.0 * 2f64.sqrt() * phi);
        let chi = (1.0 - 7.0 * phi / 16.0) / (1.0 - phi).powi(2);
        let t0 = std::time::Instant::now();
        sim.advance(warm + window);
        let (hist, m) = sim.free_path_rows();
        let acc = sim.free_path_acc().unwrap();
        eprintln!(
            "dilute gas: block means {:?}",
            acc.block_sums
                .iter()
                .zip(&acc.block_counts)
                .map(|(s, &c)| format!("{:.4} ({c})", s[0] / c as f64))
                .collect::<Vec<_>>()
        );
        let (mean, sem) = (m[0].value, m[0].sem.unwrap());
        let want = l_kin / chi;
        eprintln!(
            "dilute gas ({:.1} s, T = {:.3} m^2/s^2): <l> = {mean:.5} +- {sem:.5} m over {} paths; \
             l_kin = {l_kin:.5}, l_kin/chi = {want:.5}, ratio {:.4}; <l^2>/(2<l>^2) = {:.4}",
            t0.elapsed().as_secs_f64(),
            sim.temperature(),
            m[0].n_paths,
            mean / want,
            m[1].value / (2.0 * mean * mean)
        );
        assert!(m[0].n_paths > 5000);
        assert!(
            (mean - want).abs() < 3.0 * sem + 0.01 * want,
            "<l> = {mean} +- {sem}, want {want}"
        );
        // Post-collision velocities: two components per path start in the window, zero mean.
        let pcv: Vec<&HistRow> = hist
            .iter()
            .filter(|h| h.kind == "post_collision_velocity" && h.density.is_some())
            .collect();
        let n: u64 = pcv.iter().map(|h| h.count).sum();
        let mean_v = pcv
            .iter()
            .map(|h| 0.5 * (h.lo + h.hi) * h.count as f64)
            .sum::<f64>()
            / n as f64;
        eprintln!("dilute gas: {n} post-collision components, mean {mean_v:.4} m/s");
        assert!(n > 10000 && mean_v.abs() < 0.1);
    }

    /// The tables agree with each other exactly: the time average of T (2.19), which sums the
    /// components, equals D <v_c^2> from the moments (the same snapshots); the histogram holds
    /// every component of every snapshot and its densities integrate to the in-range fraction.
    #[test]
    fn observables_are_consistent() {
        for dim in [1u32, 2] {
            let p = params(dim);
            let mut r = RfmRun::new(&p, 3).unwrap();
            while !r.advance(u64::MAX).unwrap() {}
            let samples = r.sampler.samples_total;
            let out = r.finish();
            assert_eq!(out.timeseries.len() as u64, samples);
            let t_mean = out.timeseries.iter().map(|x| x.temperature).sum::<f64>() / samples as f64;
            let m2 = out.moments[1].value;
            assert!(
                (t_mean - dim as f64 * m2).abs() < 1e-12 * t_mean,
                "dim {dim}: {t_mean} vs {}",
                dim as f64 * m2
            );
            let total: u64 = out.histograms.iter().map(|h| h.count).sum();
            assert_eq!(total, samples * 300 * dim as u64);
            let inside: f64 = out
                .histograms
                .iter()
                .filter_map(|h| h.density.map(|d| d * (h.hi - h.lo)))
                .sum();
            let outside: u64 = out
                .histograms
                .iter()
                .filter(|h| h.density.is_none())
                .map(|h| h.count)
                .sum();
            assert!((inside - (total - outside) as f64 / total as f64).abs() < 1e-12);
            // Moments grow like a (non-degenerate) distribution: <|v|^2> >= <|v|>^2.
            assert!(out.moments[1].value >= out.moments[0].value.powi(2));
        }
    }
}

#[cfg(test)]
mod snapshot_tests {
    use super::*;

    fn params(dim: u32, times: &[f64]) -> RfmParams {
        let mut v = serde_json::json!({
            "dim": dim,
            "n_particles": 200,
            "warmup": 0.01,
            "duration": 0.02,
            "sample_every": 500,
            "observables": ["snapshot"],
            "snapshot": {"times": times}
        });
        if dim == 2 {
            v["packing_fraction"] = serde_json::json!(0.3);
        } else {
            v["reduced_length"] = serde_json::json!(0.5);
        }
        serde_json::from_value(v).unwrap()
    }

    /// Each requested time gives one snapshot of every particle at the first sample at or
    /// after it; the snapshot's velocities give exactly the temperature (2.19) recorded at that
    /// sample; the block means (2.20) average back to the mean of the series.
    #[test]
    fn snapshots_and_block_means() {
        for dim in [1u32, 2] {
            let p = params(dim, &[0.0153, 0.01, 0.03]);
            let mut r = RfmRun::new(&p, 5).unwrap();
            while !r.advance(u64::MAX).unwrap() {}
            let out = r.finish();
            let ts: Vec<f64> = {
                let mut t: Vec<f64> = out.snapshots.iter().map(|s| s.t).collect();
                t.dedup();
                t
            };
            assert_eq!(ts.len(), 3, "dim {dim}: {ts:?}");
            assert_eq!(out.snapshots.len(), 3 * 200);
            // 0.01 is before the first sample (0.0105): snapped to it; 0.0153 -> 0.0155.
            assert!(
                (ts[0] - 0.0105).abs() < 1e-12
                    && (ts[1] - 0.0155).abs() < 1e-12
                    && (ts[2] - 0.03).abs() < 1e-12,
                "{ts:?}"
            );
            for &t in &ts {
                let rows: Vec<&SnapshotRow> = out.snapshots.iter().filter(|s| s.t == t).collect();
                let n = rows.len() as f64;
                let (mx, my) = (
                    rows.iter().map(|s| s.vx).sum::<f64>() / n,
                    rows.iter().map(|s| s.vy.unwrap_or(0.0)).sum::<f64>() / n,
                );
                let temp = rows
                    .iter()
                    .map(|s| (s.vx - mx).powi(2) + (s.vy.unwrap_or(0.0) - my).powi(2))
                    .sum::<f64>()
                    / n;
                let want = out
                    .timeseries
                    .iter()
                    .find(|r| r.t == t)
                    .unwrap()
                    .temperature;
                assert!(
                    (temp - want).abs() <= 1e-12 * want,
                    "dim {dim} t {t}: {temp} vs {want}"
                );
            }
            let total: u32 = out.temperature_blocks.iter().map(|b| b.n_samples).sum();
            assert_eq!(total as usize, out.timeseries.len());
            assert_eq!(out.temperature_blocks.len(), BLOCKS);
            let weighted = out
                .temperature_blocks
                .iter()
                .map(|b| b.temperature * b.n_samples as f64)
                .sum::<f64>()
                / total as f64;
            let mean = out.timeseries.iter().map(|r| r.temperature).sum::<f64>() / total as f64;
            assert!((weighted - mean).abs() < 1e-12 * mean);
        }
    }

    /// Free-path settings: without their observables, bad ranges (JSON paths); both
    /// observables are valid in 1D and 2D, and the defaults follow l_0 (spec 1.8).
    #[test]
    fn free_path_settings_are_validated() {
        for dim in [1u32, 2] {
            let mut p = params(dim, &[0.015]);
            p.free_paths = Some(crate::manifest::rfm::FreePathSpec {
                range: Some([1e-3, 1e-4]),
                bins_per_decade: 10,
            });
            p.post_collision_velocity = Some(HistogramSpec {
                range: [1.0, -1.0],
                bins: 10,
            });
            let mut errors = Vec::new();
            p.check("/params", &mut errors);
            let paths: Vec<&str> = errors.iter().map(|e| e.0.as_str()).collect();
            assert!(
                paths.contains(&"/params/free_paths")
                    && paths.contains(&"/params/post_collision_velocity")
                    && paths.contains(&"/params/post_collision_velocity/range"),
                "{errors:?}"
            );
            p.observables.push(RfmObservable::FreePaths);
            p.observables.push(RfmObservable::PostCollisionVelocity);
            let mut errors = Vec::new();
            p.check("/params", &mut errors);
            let paths: Vec<&str> = errors.iter().map(|e| e.0.as_str()).collect();
            assert_eq!(
                paths,
                [
                    "/params/post_collision_velocity/range",
                    "/params/free_paths/range"
                ],
                "{errors:?}"
            );
            p.free_paths = None;
            p.post_collision_velocity = None;
            let mut errors = Vec::new();
            p.check("/params", &mut errors);
            assert!(errors.is_empty(), "dim {dim}: {errors:?}");
            let fc = p.free_path_config().unwrap();
            let l0 = p.mean_free_path();
            assert!(
                (fc.lo / (1e-6 * l0) - 1.0).abs() < 1e-12
                    && (fc.hi / (100.0 * l0) - 1.0).abs() < 1e-12
            );
            assert_eq!(fc.velocity, Some(([-5.0, 5.0], 2000)));
            assert_eq!(fc.from_step, 10_000);
        }
    }

    #[test]
    fn snapshot_times_outside_the_sampled_window_are_errors() {
        let p = params(2, &[0.005, 0.04]);
        let mut errors = Vec::new();
        p.check("/params", &mut errors);
        let paths: Vec<&str> = errors.iter().map(|e| e.0.as_str()).collect();
        assert!(
            paths.contains(&"/params/snapshot/times/0")
                && paths.contains(&"/params/snapshot/times/1"),
            "{errors:?}"
        );
    }
}
