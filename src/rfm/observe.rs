//! A Random Force Model run with its observables (spec section 2): warm-up, then snapshots
//! every `sample_every` steps during `duration`, each feeding the requested accumulators. No
//! observable work happens between samples.
//!
//! - temperature (2.19) time series, always;
//! - velocity moments <|v_c|^m>, m = 1..12, of the velocity components in the centre-of-mass
//!   frame (pooled components, spec 2.2), with standard errors from 10 consecutive blocks of the
//!   sampled time (the thesis's block protocol, spec 2.2);
//! - histogram of the signed velocity components (spec 2.3), counts kept.

use serde::{Deserialize, Serialize};

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
}

/// The run's output rows.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RfmOutput {
    pub timeseries: Vec<TimeRow>,
    pub moments: Vec<MomentRow>,
    pub histograms: Vec<HistRow>,
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
        }
    }

    pub fn new(p: &RfmParams, seed: u64) -> Result<Self, String> {
        let cfg = p.config();
        let sampler = Self::sampler_for(p, &cfg);
        let (warmup_steps, sample_every) = (cfg.warmup_steps(), cfg.sample_every);
        Ok(RfmRun {
            sim: RfmSim::new(cfg, seed)?,
            sampler,
            warmup_steps,
            sample_every,
        })
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
        let (warmup_steps, sample_every) = (cfg.warmup_steps(), cfg.sample_every);
        let fresh = Self::sampler_for(p, &cfg);
        if fresh.samples_total != st.sampler.samples_total
            || fresh.counts.len() != st.sampler.counts.len()
            || fresh.moments != st.sampler.moments
        {
            return Err("checkpoint does not match the run's observables".into());
        }
        Ok(RfmRun {
            sim: RfmSim::from_state_bytes(cfg, &st.sim)?,
            sampler: st.sampler,
            warmup_steps,
            sample_every,
        })
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
            let block = ((s.samples_done as usize * BLOCKS) / s.samples_total.max(1) as usize)
                .min(BLOCKS - 1);
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
        s.samples_done += 1;
        Ok(())
    }

    /// The rows of a finished run.
    pub fn finish(self) -> RfmOutput {
        let s = self.sampler;
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
        RfmOutput {
            timeseries: s.series,
            moments,
            histograms,
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

    /// A run restored from a checkpoint taken at any point continues bit for bit: the same
    /// rows as the uninterrupted run (warm-up, mid-sampling, state after a sample).
    #[test]
    fn restore_is_bitwise() {
        for dim in [1, 2] {
            let p = params(dim);
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
        }
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
