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

pub use super::blocks::{HistRow, BLOCKS};
use super::freepath::{FreePathConfig, FreePathMomentRow};
use super::params::RfmConfig;
use super::sim::RfmSim;
use super::structure::{
    NeighbourAcc, NeighbourMomentRow, RadialAcc, RadialRow, SkAcc, SkRow, SkWork,
};
use super::structure::{NeighbourConfig, RadialConfig, SkConfig};
use crate::physics::{PhysicsError, SimError};

/// Bins of a velocity histogram (m/s); values outside are counted in two extra rows.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct HistogramConfig {
    /// [v_min, v_max] (m/s).
    pub range: [f64; 2],
    pub bins: u32,
}

/// An RFM run's own configuration: the simulator's and what is observed (the `rfm` model
/// resolves it from the manifest's parameters).
#[derive(Clone, Debug, PartialEq)]
pub struct RunConfig {
    pub sim: RfmConfig,
    /// Velocity moments <|v_c|^m>, m = 1..12.
    pub moments: bool,
    /// Histogram of the signed velocity components.
    pub histogram: Option<HistogramConfig>,
    /// 1D neighbour distances.
    pub neighbours: Option<NeighbourConfig>,
    /// 2D structure factor.
    pub structure_factor: Option<SkConfig>,
    /// 2D radial distribution.
    pub radial: Option<RadialConfig>,
    /// Snapshot times (s), unsorted; empty without snapshots.
    pub snapshot_times: Vec<f64>,
    /// Free paths and post-collision velocities (contact tracking), when either is observed.
    pub free_paths: Option<FreePathConfig>,
}

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

/// Accumulators (checkpointed with the run).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq, Default)]
pub struct Sampler {
    pub samples_total: u64,
    pub samples_done: u64,
    pub series: Vec<TimeRow>,
    pub moments: bool,
    /// Per sample: the sum of |v_c|^m over every particle's components (index m - 1), from 0;
    /// grouped into the blocks when the rows are made (`blocks`).
    pub moment_sums: Vec<[f64; MAX_ORDER]>,
    /// Values per sample (particles x dimension).
    pub moment_values: u64,
    pub hist: Option<HistogramConfig>,
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
    /// Same observables and settings (a checkpoint's sampler against a fresh one).
    fn same_shape(&self, o: &Sampler) -> bool {
        self.samples_total == o.samples_total && self.same_observables(o)
    }

    /// Same observables and settings, whatever the number of samples (a finished run's
    /// sampler against that of a longer run).
    fn same_observables(&self, o: &Sampler) -> bool {
        self.counts.len() == o.counts.len()
            && self.moments == o.moments
            && self.hist == o.hist
            && self.neighbours.as_ref().map(|a| (&a.cfg, a.counts.len()))
                == o.neighbours.as_ref().map(|a| (&a.cfg, a.counts.len()))
            && self.sk.as_ref().map(|a| (&a.cfg, a.n2.len()))
                == o.sk.as_ref().map(|a| (&a.cfg, a.n2.len()))
            && self.radial.as_ref().map(|a| &a.cfg) == o.radial.as_ref().map(|a| &a.cfg)
            && self.snap_times == o.snap_times
    }

    /// The logs hold one entry per sample (or evaluation) done.
    fn logs_consistent(&self) -> bool {
        let done = self.samples_done;
        let evals = |every: u32| done.div_ceil(every.max(1) as u64);
        (!self.moments || self.moment_sums.len() as u64 == done)
            && self.series.len() as u64 == done
            && self.neighbours.as_ref().is_none_or(|a| a.samples() == done)
            && self
                .sk
                .as_ref()
                .is_none_or(|a| a.evals() == evals(a.cfg.every))
            && self
                .radial
                .as_ref()
                .is_none_or(|a| a.evals() == evals(a.cfg.every))
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

/// The rows made of a finished run's accumulators (`RfmRun::finish`).
impl Sampler {
    /// Block means (2.20) of the temperature series, in the moments' blocks (`BLOCKS` blocks
    /// of the planned samples; empty blocks left out).
    fn temperature_block_rows(&self) -> Vec<TemperatureBlockRow> {
        let s = self;
        let mut temperature_blocks = Vec::new();
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
        temperature_blocks
    }

    /// The moments <|v_c|^m>, m = 1..=`MAX_ORDER`, over every sampled component, with the
    /// sem of their block means (at least two blocks); none without the moments observable.
    fn moment_rows(&self) -> Vec<MomentRow> {
        let s = self;
        let mut moments = Vec::new();
        if s.moments {
            let (block_sums, block_samples) = super::blocks::group(&s.moment_sums, s.samples_total);
            let block_counts: Vec<u64> =
                block_samples.iter().map(|n| n * s.moment_values).collect();
            let total: u64 = block_counts.iter().sum();
            for m in 0..MAX_ORDER {
                let value = block_sums.iter().map(|b| b[m]).sum::<f64>() / total.max(1) as f64;
                let blocks: Vec<f64> = block_sums
                    .iter()
                    .zip(&block_counts)
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
        moments
    }

    /// The velocity-component histogram's rows (densities over every count), then its two
    /// out-of-range rows (below, above; no density); none without the histogram observable.
    fn velocity_histogram_rows(&self) -> Vec<HistRow> {
        let s = self;
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
        histograms
    }
}

impl RfmRun {
    fn sampler_for(rc: &RunConfig) -> Sampler {
        let total = rc.sim.duration_steps() / rc.sim.sample_every;
        let hist = rc.histogram.clone();
        let mut snap_times = rc.snapshot_times.clone();
        snap_times.sort_by(f64::total_cmp);
        Sampler {
            samples_total: total,
            samples_done: 0,
            series: Vec::new(),
            moments: rc.moments,
            moment_sums: Vec::new(),
            moment_values: (rc.sim.n_particles * rc.sim.dim as usize) as u64,
            counts: hist
                .as_ref()
                .map(|h| vec![0; h.bins as usize + 2])
                .unwrap_or_default(),
            hist,
            neighbours: rc.neighbours.clone().map(NeighbourAcc::new),
            sk: rc.structure_factor.clone().map(SkAcc::new),
            radial: rc.radial.clone().map(RadialAcc::new),
            snap_times,
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

    pub fn new(rc: &RunConfig, seed: u64) -> Result<Self, SimError> {
        Self::with_stream(rc, seed, crate::rng::StreamVersion::V1)
    }

    /// A new run drawing as random stream version `stream` prescribes
    /// ([`RfmSim::with_stream`]).
    pub fn with_stream(
        rc: &RunConfig,
        seed: u64,
        stream: crate::rng::StreamVersion,
    ) -> Result<Self, SimError> {
        let sampler = Self::sampler_for(rc);
        let mut sim = RfmSim::with_stream(rc.sim.clone(), seed, stream)?;
        if let Some(fc) = &rc.free_paths {
            sim.track_free_paths(fc.clone());
        }
        Ok(Self::assemble(sim, sampler, &rc.sim))
    }

    pub fn state_bytes(&self) -> Vec<u8> {
        let st = RunState {
            sim: self.sim.state_bytes(),
            sampler: self.sampler.clone(),
        };
        postcard::to_stdvec(&st).expect("state serialises")
    }

    pub fn from_state_bytes(rc: &RunConfig, bytes: &[u8]) -> Result<Self, SimError> {
        let st: RunState = postcard::from_bytes(bytes)
            .map_err(|e| format!("checkpoint payload does not decode: {e}"))?;
        let fresh = Self::sampler_for(rc);
        if !fresh.same_shape(&st.sampler) || !st.sampler.logs_consistent() {
            return Err("checkpoint does not match the run's observables".into());
        }
        let sim = RfmSim::from_state_bytes(rc.sim.clone(), &st.sim)?;
        if sim.free_path_config() != rc.free_paths.as_ref() {
            return Err("checkpoint does not match the run's observables".into());
        }
        Ok(Self::assemble(sim, st.sampler, &rc.sim))
    }

    /// A finished run's state, which a longer run continues (`continue_from`); None before the
    /// end.
    pub fn final_state(&self) -> Option<Vec<u8>> {
        self.is_done().then(|| self.state_bytes())
    }

    /// The run `rc` (a longer duration) continued from a finished run's `final_state`: the
    /// samples taken stay, the blocks are formed from them with the new number of samples at
    /// the end, and the simulation goes on; bit for bit the run made straight to the new end.
    pub fn continue_from(rc: &RunConfig, bytes: &[u8]) -> Result<Self, SimError> {
        let st: RunState =
            postcard::from_bytes(bytes).map_err(|e| format!("final state does not decode: {e}"))?;
        let fresh = Self::sampler_for(rc);
        let mut sampler = st.sampler;
        if !fresh.same_observables(&sampler) || !sampler.logs_consistent() {
            return Err("final state does not match the run's observables".into());
        }
        if sampler.samples_done != sampler.samples_total {
            return Err("final state is not that of a finished run".into());
        }
        if fresh.samples_total < sampler.samples_total {
            return Err(SimError::State(format!(
                "{} samples, fewer than the finished run's {}",
                fresh.samples_total, sampler.samples_total
            )));
        }
        let sim = RfmSim::from_state_bytes(rc.sim.clone(), &st.sim)?;
        if sim.free_path_config() != rc.free_paths.as_ref() {
            return Err("final state does not match the run's observables".into());
        }
        sampler.samples_total = fresh.samples_total;
        Ok(Self::assemble(sim, sampler, &rc.sim))
    }

    pub fn is_done(&self) -> bool {
        self.sampler.samples_done >= self.sampler.samples_total
    }

    pub fn progress(&self) -> f64 {
        let total = self.warmup_steps + self.sampler.samples_total * self.sample_every;
        (self.sim.step() as f64 / total.max(1) as f64).min(1.0)
    }

    /// Advance by at most `max_steps` steps, sampling on the way; true when done.
    pub fn advance(&mut self, max_steps: u64) -> Result<bool, PhysicsError> {
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

    fn sample(&mut self) -> Result<(), PhysicsError> {
        let t = self.sim.time();
        let temperature = self.sim.temperature();
        if !temperature.is_finite() {
            return Err(PhysicsError {
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
            let mut sums = [0.0; MAX_ORDER];
            for p in v.chunks_exact(d) {
                for c in 0..d {
                    let x = p[c] - mean[c];
                    if s.moments {
                        let a = x.abs();
                        let mut pw = 1.0;
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
                s.moment_sums.push(sums);
            }
        }
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
                a.add(&x, l, d);
            }
            if let (Some(a), true) = (&mut s.sk, sk_now) {
                let w = self.sk_work.as_mut().expect("S(k) scratch");
                a.add(w, &x, l);
            }
            if let (Some(a), true) = (&mut s.radial, radial_now) {
                a.add(&mut self.pair_buf, &x);
            }
        }
        s.samples_done += 1;
        Ok(())
    }

    /// The rows of a finished run.
    pub fn finish(self) -> RfmOutput {
        let s = self.sampler;
        let temperature_blocks = s.temperature_block_rows();
        let moments = s.moment_rows();
        let mut histograms = s.velocity_histogram_rows();
        let mut neighbour_moments = Vec::new();
        if let Some(a) = &s.neighbours {
            let (h, m) = a.rows(s.samples_total);
            histograms.extend(h);
            neighbour_moments = m;
        }
        let (fp_hist, free_path_moments) = self.sim.free_path_rows(s.samples_total);
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
                .map(|a| a.rows(cfg.n_particles, cfg.box_length(), s.samples_total))
                .unwrap_or_default(),
            radial: s
                .radial
                .as_ref()
                .map(|a| a.rows(s.samples_total))
                .unwrap_or_default(),
            temperature_blocks,
            snapshots: s.snapshots,
            free_path_moments,
        }
    }
}
