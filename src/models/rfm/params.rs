//! The `params` of an `rfm` manifest: soft-sphere MD of the Random Force Model (spec
//! `rfm.md`). Defaults are the thesis's (spec 1.1); SI units. Serde types that mirror the
//! JSON, their cross-field rules (`check`), and their resolution into the run's own
//! configuration ([`RfmParams::run_config`]).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::models::{check_velocity_range, MAX_RUN_WORK, SCALE_MAX, SCALE_MIN};

use crate::rfm::freepath::FreePathConfig;
use crate::rfm::observe::{HistogramConfig, RunConfig};
use crate::rfm::params::{
    InitialLayout, RfmConfig, THESIS_MASS, THESIS_NOISE, THESIS_RADIUS, THESIS_SPRING,
};
use crate::rfm::structure::{NeighbourConfig, RadialConfig, SkConfig};

/// Parameters of a Random Force Model run.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RfmParams {
    /// 1 (rods on a ring) or 2 (discs in a periodic square).
    #[schemars(range(min = 1, max = 2))]
    pub dim: u32,
    #[schemars(range(min = 2))]
    pub n_particles: u64,
    /// Box side L (m); give exactly one of `box_length`, `packing_fraction` (2D),
    /// `reduced_length` (1D).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub box_length: Option<f64>,
    /// 2D packing fraction phi = N pi r^2 / L^2.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub packing_fraction: Option<f64>,
    /// 1D reduced length L' = L - N d (m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub reduced_length: Option<f64>,
    /// Radius r (m), default 1.5e-3.
    #[serde(default = "radius")]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub radius: f64,
    /// Mass M (kg), default 3.53e-5.
    #[serde(default = "mass")]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub mass: f64,
    /// Spring constant k_s (kg s^-2), default 5e5.
    #[serde(default = "spring")]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub spring_constant: f64,
    /// Noise strength D (N^2 s): <eta eta> = 2 D delta(t) per component; default 1e-8.
    #[serde(default = "noise")]
    #[schemars(range(min = 0))]
    pub noise_strength: f64,
    /// Normal restitution eps_n in (0, 1], default 0.6.
    #[serde(default = "eps_default")]
    #[schemars(extend("exclusiveMinimum" = 0), range(max = 1))]
    pub restitution_normal: f64,
    /// Tangential restitution eps_t in (0, 1] (2D), default 1 = no tangential dissipation. The
    /// thesis's model gives a binary contact the tangential restitution eps_t^(w0/w_d).
    #[serde(default = "one")]
    #[schemars(extend("exclusiveMinimum" = 0), range(max = 1))]
    pub restitution_tangential: f64,
    /// Optional sliding friction coefficient mu (2D).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(range(min = 0))]
    pub mu: Option<f64>,
    /// Time step (s); default the largest power of ten <= t_c/10 (1e-6 s for the thesis's
    /// parameters).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub dt: Option<f64>,
    /// Simulated time before sampling (s), default 1.
    #[serde(default = "one")]
    #[schemars(range(min = 0))]
    pub warmup: f64,
    /// Simulated time sampled after the warm-up (s), default 1.
    #[serde(default = "one")]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub duration: f64,
    /// Steps between samples (snapshots), default 1000.
    #[serde(default = "thousand")]
    #[schemars(range(min = 1))]
    pub sample_every: u64,
    /// Initial layout: `uniform` (default), `square` or `hexagonal` (2D).
    #[serde(default)]
    pub initial_layout: Layout,
    /// Observables beyond the always-recorded temperature time series.
    #[serde(default)]
    pub observables: Vec<RfmObservable>,
    /// Histogram of the signed velocity components (with `velocity_histogram`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity_histogram: Option<HistogramSpec>,
    /// Settings of the 1D neighbour distances (with `neighbour_distances`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub neighbour_distances: Option<NeighbourSpec>,
    /// Settings of the 2D structure factor (with `structure_factor`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub structure_factor: Option<StructureFactorSpec>,
    /// Settings of the 2D radial distribution (with `radial_distribution`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radial_distribution: Option<RadialSpec>,
    /// Times of the configuration snapshots (with `snapshot`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub snapshot: Option<SnapshotSpec>,
    /// Bins of the free-path histogram (with `free_paths`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub free_paths: Option<FreePathSpec>,
    /// Bins of the post-collision velocity histogram (with `post_collision_velocity`); default
    /// the `velocity_histogram` settings, else [-5, 5] m/s in 2000 bins.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub post_collision_velocity: Option<HistogramSpec>,
}

/// Free-path lengths l (m), log-spaced bins.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FreePathSpec {
    /// [l_min, l_max] (m) of the log-spaced bins, default [1e-6 l_0, 100 l_0] with the
    /// mean-field mean free path l_0 = L^2/(2 d N) (2D, spec 1.8) or L'/N (1D, the mean gap);
    /// values outside are counted in two extra rows.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub range: Option<[f64; 2]>,
    /// Bins per decade, default 20.
    #[serde(default = "twenty")]
    #[schemars(range(min = 1, max = 100000))]
    pub bins_per_decade: u32,
}

impl Default for FreePathSpec {
    fn default() -> Self {
        FreePathSpec {
            range: None,
            bins_per_decade: twenty(),
        }
    }
}

/// Snapshots of every particle's position and velocity.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SnapshotSpec {
    /// Simulated times (s) in [warmup, warmup + duration]; each snapshot is taken at the first
    /// sample time at or after it (samples are every `sample_every` steps).
    #[schemars(length(min = 1))]
    pub times: Vec<f64>,
}

fn radius() -> f64 {
    THESIS_RADIUS
}
fn mass() -> f64 {
    THESIS_MASS
}
fn spring() -> f64 {
    THESIS_SPRING
}
fn noise() -> f64 {
    THESIS_NOISE
}
fn eps_default() -> f64 {
    0.6
}
fn one() -> f64 {
    1.0
}
fn thousand() -> u64 {
    1000
}

#[derive(Serialize, Deserialize, JsonSchema, Clone, Copy, Debug, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum Layout {
    /// 2D: random non-overlapping positions; 1D: evenly spaced.
    #[default]
    Uniform,
    /// 2D: square bed of touching discs.
    Square,
    /// 2D: hexagonal bed.
    Hexagonal,
}

/// RFM observables.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Copy, Debug, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum RfmObservable {
    /// T(t) (2.19) at every sample (always recorded).
    Temperature,
    /// <|v_c|^m>, m = 1..12, of the velocity components in the centre-of-mass frame, with
    /// standard errors from 10 blocks of the sampled time.
    VelocityMoments,
    /// Histogram of the signed velocity components (see `velocity_histogram`).
    VelocityHistogram,
    /// 1D: h-th neighbour separations in reduced coordinates (spec 2.6), histograms with
    /// log-spaced bins and moments <R^m>, m = 1..9 (see `neighbour_distances`).
    NeighbourDistances,
    /// 2D: structure factor S(k) on the k lattice, exact shells (spec 2.7; see
    /// `structure_factor`).
    StructureFactor,
    /// 2D: radial distribution g(R) and cumulative count C(R) (spec 2.8; see
    /// `radial_distribution`).
    RadialDistribution,
    /// Positions and velocities of every particle at given times (see `snapshot`).
    Snapshot,
    /// Free paths l = |r(t_0 + tau) - r(t_0)| between a particle's contact count dropping to 0
    /// and rising again (spec 2.9), evaluated every step; the paths that end (arrive at the next
    /// contact) within the sampled window; histogram with log-spaced bins and <l^m>, m = 1..4
    /// (see `free_paths`).
    FreePaths,
    /// Velocity components just after a collision (at the instant the contact count drops to
    /// 0, spec 2.3), signed, lab frame, within the sampled window (see
    /// `post_collision_velocity`).
    PostCollisionVelocity,
}

impl RfmObservable {
    /// The manifest name.
    pub fn name(self) -> &'static str {
        match self {
            RfmObservable::Temperature => "temperature",
            RfmObservable::VelocityMoments => "velocity_moments",
            RfmObservable::VelocityHistogram => "velocity_histogram",
            RfmObservable::NeighbourDistances => "neighbour_distances",
            RfmObservable::StructureFactor => "structure_factor",
            RfmObservable::RadialDistribution => "radial_distribution",
            RfmObservable::Snapshot => "snapshot",
            RfmObservable::FreePaths => "free_paths",
            RfmObservable::PostCollisionVelocity => "post_collision_velocity",
        }
    }
}

/// 1D neighbour distances R_{i,i+h} = |x_{i+h} - x_i - h d| (m), h = 1..h_max.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct NeighbourSpec {
    /// Highest neighbour order (every h = 1..h_max is recorded), default 3; below N.
    #[serde(default = "three")]
    #[schemars(range(min = 1))]
    pub h_max: u32,
    /// [R_min, R_max] (m) of the log-spaced bins, default [1e-7, L']; values outside are
    /// counted in two extra rows.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub range: Option<[f64; 2]>,
    /// Bins per decade, default 20.
    #[serde(default = "twenty")]
    #[schemars(range(min = 1, max = 100000))]
    pub bins_per_decade: u32,
}

/// 2D structure factor on the lattice k = 2 pi (n_x, n_y) / L.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct StructureFactorSpec {
    /// Largest |k| in units of 2 pi / L: the lattice vectors with 0 < n_x^2 + n_y^2 <=
    /// floor(k_max^2). Default: k d <= 20, i.e. floor(20 L / (2 pi d)) (the contact peaks at
    /// k d ~ 2 pi, 4 pi, 6 pi are included). Cost per evaluation ~ N (pi/2) k_max^2
    /// complex multiply-adds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(range(min = 1))]
    pub k_max: Option<f64>,
    /// Evaluate at every `every`-th snapshot (default 1).
    #[serde(default = "one_u32")]
    #[schemars(range(min = 1))]
    pub every: u32,
}

/// 2D radial distribution g(R), 0 <= R < R_max, equal bins.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RadialSpec {
    /// R_max (m), at most L/2; default L/2.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub r_max: Option<f64>,
    /// Number of bins; default ceil(R_max / (d/20)) (spec 2.8: dR ~ d/20).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(range(min = 1, max = 10000000))]
    pub bins: Option<u32>,
    /// Evaluate at every `every`-th snapshot (default 1).
    #[serde(default = "one_u32")]
    #[schemars(range(min = 1))]
    pub every: u32,
}

impl Default for NeighbourSpec {
    fn default() -> Self {
        NeighbourSpec {
            h_max: three(),
            range: None,
            bins_per_decade: twenty(),
        }
    }
}

impl Default for StructureFactorSpec {
    fn default() -> Self {
        StructureFactorSpec {
            k_max: None,
            every: 1,
        }
    }
}

impl Default for RadialSpec {
    fn default() -> Self {
        RadialSpec {
            r_max: None,
            bins: None,
            every: 1,
        }
    }
}

/// Default lower end of the neighbour-distance bins (m), spec 2.6 [REC].
pub const NEIGHBOUR_R_MIN: f64 = 1e-7;
/// Default largest k d of the structure factor.
pub const SK_KD_MAX: f64 = 20.0;
/// Default bins per diameter of g(R) (dR = d/20, spec 2.8).
pub const RADIAL_BINS_PER_DIAMETER: f64 = 20.0;

fn three() -> u32 {
    3
}
fn twenty() -> u32 {
    20
}
fn one_u32() -> u32 {
    1
}

/// Bins of the velocity histogram (m/s); values outside are counted in two extra rows.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct HistogramSpec {
    /// [v_min, v_max] (m/s), default [-5, 5].
    #[serde(default = "default_range")]
    pub range: [f64; 2],
    /// Number of bins, default 2000.
    #[serde(default = "default_bins")]
    #[schemars(range(min = 1, max = 10000000))]
    pub bins: u32,
}

fn default_range() -> [f64; 2] {
    [-5.0, 5.0]
}
fn default_bins() -> u32 {
    2000
}

impl Default for HistogramSpec {
    fn default() -> Self {
        HistogramSpec {
            range: default_range(),
            bins: default_bins(),
        }
    }
}

impl RfmParams {
    pub fn wants(&self, o: RfmObservable) -> bool {
        self.observables.contains(&o)
    }

    /// An estimate of the bytes a run holds at its peak: per particle the positions,
    /// velocities, reference positions, noise and forces, neighbour and cell lists, contact
    /// and free-path bookkeeping, and the checkpoint's copy of the state; plus the observables'
    /// accumulators (histograms, S(k) sums, g(R) bins, snapshots).
    pub fn memory_estimate(&self) -> u64 {
        let n = self.n_particles;
        let d = self.dim.clamp(1, 2) as u64;
        let per_particle = 8 * d * 10 + 160;
        let mut bytes = n.saturating_mul(per_particle);
        let hist = |bins: u32| (bins as u64 + 2) * 8 * 2;
        if let Some(h) = &self.velocity_histogram {
            bytes = bytes.saturating_add(hist(h.bins));
        }
        if let Some(h) = &self.post_collision_velocity {
            bytes = bytes.saturating_add(hist(h.bins));
        }
        let cfg = self.config();
        if cfg.validate().is_ok() {
            // The accumulators keep their sums per sample (or evaluation) until the end.
            let samples = cfg.duration_steps() / cfg.sample_every.max(1);
            let evals = |every: u32| samples.div_ceil(every.max(1) as u64);
            // The temperature series.
            bytes = bytes.saturating_add(samples.saturating_mul(16));
            if self.wants(RfmObservable::VelocityMoments) {
                bytes = bytes.saturating_add(samples.saturating_mul(8 * 12));
            }
            if let Some(nc) = self.neighbour_config() {
                let per = (nc.h_max as u64).saturating_mul(8 * 10);
                bytes = bytes.saturating_add(samples.saturating_mul(per));
            }
            if let Some(sk) = self.structure_factor_config() {
                // Half the lattice vectors in |n| <= n_max, their phase sums; one sum per
                // shell (at most n_max^2 + 1 shells) per evaluation.
                let vectors = (std::f64::consts::PI * sk.n_max * sk.n_max / 2.0).ceil() as u64;
                let shells = ((sk.n_max * sk.n_max).min(1e12) as u64 + 1).min(vectors.max(1));
                bytes = bytes
                    .saturating_add(vectors.saturating_mul(8 * 16))
                    .saturating_add(evals(sk.every).saturating_mul(shells).saturating_mul(8));
            }
            if let Some(r) = self.radial_config() {
                let per = (r.bins as u64).saturating_mul(8);
                bytes = bytes
                    .saturating_add(per.saturating_mul(14))
                    .saturating_add(evals(r.every).saturating_mul(per));
            }
            if let Some(f) = self.free_path_config() {
                bytes = bytes
                    .saturating_add(n.saturating_mul(48))
                    .saturating_add((f.bins().min(1e12) as u64).saturating_mul(16))
                    .saturating_add(samples.saturating_mul(40));
            }
        }
        if let Some(s) = &self.snapshot {
            bytes =
                bytes.saturating_add((s.times.len() as u64).saturating_mul(n).saturating_mul(48));
        }
        bytes.saturating_add(8 << 20)
    }

    /// The run's configuration: the simulator's and what it observes, defaults resolved.
    pub fn run_config(&self) -> RunConfig {
        RunConfig {
            sim: self.config(),
            moments: self.wants(RfmObservable::VelocityMoments),
            histogram: self.wants(RfmObservable::VelocityHistogram).then(|| {
                let h = self.velocity_histogram.clone().unwrap_or_default();
                HistogramConfig {
                    range: h.range,
                    bins: h.bins,
                }
            }),
            neighbours: self.neighbour_config(),
            structure_factor: self.structure_factor_config(),
            radial: self.radial_config(),
            snapshot_times: if self.wants(RfmObservable::Snapshot) {
                self.snapshot
                    .as_ref()
                    .map(|s| s.times.clone())
                    .unwrap_or_default()
            } else {
                Vec::new()
            },
            free_paths: self.free_path_config(),
        }
    }

    /// The simulator's configuration.
    pub fn config(&self) -> RfmConfig {
        RfmConfig {
            dim: self.dim,
            n_particles: self.n_particles as usize,
            box_length: self.box_length,
            packing_fraction: self.packing_fraction,
            reduced_length: self.reduced_length,
            radius: self.radius,
            mass: self.mass,
            spring_constant: self.spring_constant,
            noise_strength: self.noise_strength,
            restitution_normal: self.restitution_normal,
            restitution_tangential: self.restitution_tangential,
            friction: self.mu,
            dt: self.dt,
            warmup: self.warmup,
            duration: self.duration,
            sample_every: self.sample_every,
            initial_layout: match self.initial_layout {
                Layout::Uniform => InitialLayout::Uniform,
                Layout::Square => InitialLayout::Square,
                Layout::Hexagonal => InitialLayout::Hexagonal,
            },
        }
    }

    /// Resolved neighbour-distance settings, when the observable is requested.
    pub fn neighbour_config(&self) -> Option<NeighbourConfig> {
        if !self.wants(RfmObservable::NeighbourDistances) {
            return None;
        }
        let spec = self.neighbour_distances.clone().unwrap_or_default();
        let cfg = self.config();
        let reduced = cfg.box_length() - cfg.n_particles as f64 * cfg.diameter();
        let [lo, hi] = spec.range.unwrap_or([NEIGHBOUR_R_MIN, reduced]);
        Some(NeighbourConfig {
            h_max: spec.h_max,
            lo,
            hi,
            bins_per_decade: spec.bins_per_decade,
        })
    }

    /// Mean-field mean free path l_0 (m): 2D L^2/(2 d N) (spec 1.8, (4.7)); 1D the mean gap
    /// L'/N.
    pub fn mean_free_path(&self) -> f64 {
        let cfg = self.config();
        let (l, d, n) = (cfg.box_length(), cfg.diameter(), cfg.n_particles as f64);
        if self.dim == 1 {
            (l - n * d) / n
        } else {
            l * l / (2.0 * d * n)
        }
    }

    /// Resolved free-path / post-collision velocity settings, when either is requested.
    pub fn free_path_config(&self) -> Option<FreePathConfig> {
        let paths = self.wants(RfmObservable::FreePaths);
        let vel = self.wants(RfmObservable::PostCollisionVelocity);
        if !paths && !vel {
            return None;
        }
        let spec = self.free_paths.clone().unwrap_or_default();
        let l0 = self.mean_free_path();
        let [lo, hi] = spec.range.unwrap_or([1e-6 * l0, 100.0 * l0]);
        let velocity = vel.then(|| {
            let h = self
                .post_collision_velocity
                .clone()
                .or_else(|| self.velocity_histogram.clone())
                .unwrap_or_default();
            (h.range, h.bins)
        });
        let cfg = self.config();
        Some(FreePathConfig {
            paths,
            lo,
            hi,
            bins_per_decade: spec.bins_per_decade,
            velocity,
            from_step: cfg.warmup_steps(),
            sample_every: cfg.sample_every,
        })
    }

    /// Cross-field rules of the free-path observables.
    fn check_free_paths(&self, path: &str, errors: &mut Vec<(String, String)>) {
        for (given, o, key) in [
            (
                self.free_paths.is_some(),
                RfmObservable::FreePaths,
                "free_paths",
            ),
            (
                self.post_collision_velocity.is_some(),
                RfmObservable::PostCollisionVelocity,
                "post_collision_velocity",
            ),
        ] {
            if given && !self.wants(o) {
                errors.push((
                    format!("{path}/{key}"),
                    format!("given without the observable \"{key}\""),
                ));
            }
        }
        if let Some(h) = &self.post_collision_velocity {
            check_velocity_range(
                h.range,
                format!("{path}/post_collision_velocity/range"),
                errors,
            );
        }
        if self.config().validate().is_err() {
            return;
        }
        if let (Some(fc), true) = (
            self.free_path_config(),
            self.wants(RfmObservable::FreePaths),
        ) {
            if !(fc.lo > 0.0 && fc.lo < fc.hi && fc.hi.is_finite()) {
                errors.push((
                    format!("{path}/free_paths/range"),
                    format!(
                        "expected [l_min, l_max] with 0 < l_min < l_max (m), got [{}, {}]",
                        fc.lo, fc.hi
                    ),
                ));
            } else if fc.bins() > 1e7 {
                errors.push((
                    format!("{path}/free_paths"),
                    format!("{} bins is more than 10^7", fc.bins()),
                ));
            }
        }
    }

    /// Resolved structure-factor settings, when the observable is requested.
    pub fn structure_factor_config(&self) -> Option<SkConfig> {
        if !self.wants(RfmObservable::StructureFactor) {
            return None;
        }
        let spec = self.structure_factor.clone().unwrap_or_default();
        let cfg = self.config();
        let n_max = spec.k_max.unwrap_or_else(|| {
            (SK_KD_MAX * cfg.box_length() / (2.0 * std::f64::consts::PI * cfg.diameter()))
                .floor()
                .max(1.0)
        });
        Some(SkConfig {
            n_max,
            every: spec.every,
        })
    }

    /// Resolved g(R) settings, when the observable is requested.
    pub fn radial_config(&self) -> Option<RadialConfig> {
        if !self.wants(RfmObservable::RadialDistribution) {
            return None;
        }
        let spec = self.radial_distribution.clone().unwrap_or_default();
        let cfg = self.config();
        let l = cfg.box_length();
        let r_max = spec.r_max.unwrap_or(0.5 * l);
        let bins = spec.bins.unwrap_or_else(|| {
            (r_max / (cfg.diameter() / RADIAL_BINS_PER_DIAMETER))
                .ceil()
                .clamp(1.0, 1e7) as u32
        });
        Some(RadialConfig {
            r_max,
            bins,
            every: spec.every,
            n: self.n_particles,
            l,
        })
    }

    /// Cross-field rules of the snapshot observable.
    fn check_snapshot(&self, path: &str, errors: &mut Vec<(String, String)>) {
        match (&self.snapshot, self.wants(RfmObservable::Snapshot)) {
            (Some(_), false) => errors.push((
                format!("{path}/snapshot"),
                "given without the observable \"snapshot\"".into(),
            )),
            (None, true) => errors.push((
                format!("{path}/snapshot"),
                "expected {\"times\": [..]} with the observable \"snapshot\"".into(),
            )),
            (Some(s), true) => {
                let (a, b) = (self.warmup, self.warmup + self.duration);
                for (i, t) in s.times.iter().enumerate() {
                    if !(*t >= a && *t <= b) {
                        errors.push((format!("{path}/snapshot/times/{i}"), format!("expected a time in [warmup, warmup + duration] = [{a}, {b}], got {t}")));
                    }
                }
            }
            (None, false) => {}
        }
    }

    /// Cross-field rules of the structure observables: each in its dimension and given with
    /// its object; then (on a sound configuration) each object's own limits.
    fn check_structure(&self, path: &str, errors: &mut Vec<(String, String)>) {
        self.check_structure_observables(path, errors);
        let cfg = self.config();
        if cfg.validate().is_err() {
            return;
        }
        let samples = cfg.duration_steps() / self.sample_every;
        self.check_neighbour_distances(path, errors);
        self.check_structure_factor(path, samples, errors);
        self.check_radial_distribution(path, samples, errors);
    }

    /// Each structure observable in the dimension it is made for, and each of their objects
    /// given only with its observable.
    fn check_structure_observables(&self, path: &str, errors: &mut Vec<(String, String)>) {
        use RfmObservable as O;
        for (i, o) in self.observables.iter().enumerate() {
            let need = match o {
                O::NeighbourDistances => 1,
                O::StructureFactor | O::RadialDistribution => 2,
                _ => continue,
            };
            if self.dim != need {
                errors.push((
                    format!("{path}/observables/{i}"),
                    format!(
                        "\"{}\" is a {need}D observable (dim is {})",
                        o.name(),
                        self.dim
                    ),
                ));
            }
        }
        for (given, o, key) in [
            (
                self.neighbour_distances.is_some(),
                O::NeighbourDistances,
                "neighbour_distances",
            ),
            (
                self.structure_factor.is_some(),
                O::StructureFactor,
                "structure_factor",
            ),
            (
                self.radial_distribution.is_some(),
                O::RadialDistribution,
                "radial_distribution",
            ),
        ] {
            if given && !self.wants(o) {
                errors.push((
                    format!("{path}/{key}"),
                    format!("given without the observable \"{key}\""),
                ));
            }
        }
    }

    /// `neighbour_distances` (1D): `h_max` below the particle count, a sound range, at most
    /// 10^7 bins.
    fn check_neighbour_distances(&self, path: &str, errors: &mut Vec<(String, String)>) {
        if let (Some(nc), 1) = (self.neighbour_config(), self.dim) {
            let p = format!("{path}/neighbour_distances");
            if nc.h_max as u64 >= self.n_particles {
                errors.push((
                    format!("{p}/h_max"),
                    format!(
                        "must be below n_particles ({}), got {}",
                        self.n_particles, nc.h_max
                    ),
                ));
            }
            if !(nc.lo > 0.0 && nc.lo < nc.hi && nc.hi.is_finite()) {
                errors.push((
                    format!("{p}/range"),
                    format!(
                        "expected [R_min, R_max] with 0 < R_min < R_max (m), got [{}, {}]",
                        nc.lo, nc.hi
                    ),
                ));
            } else {
                // Counted as `NeighbourConfig::edges` would make them, without making them (a
                // range of 1e300 decades made validate's allocation fail).
                let bins = ((nc.bins_per_decade as f64 * (nc.hi / nc.lo).log10()) - 1e-9)
                    .ceil()
                    .max(1.0);
                if !(bins * nc.h_max as f64 <= 1e7) {
                    errors.push((
                        p.clone(),
                        format!("{bins:.0} bins x h_max {} is more than 10^7 bins", nc.h_max),
                    ));
                }
            }
        }
    }

    /// `structure_factor` (2D): `k_max` in [1, 5000], evaluated in each of the 10 blocks of
    /// the `samples`.
    fn check_structure_factor(&self, path: &str, samples: u64, errors: &mut Vec<(String, String)>) {
        if let (Some(sk), 2) = (self.structure_factor_config(), self.dim) {
            let p = format!("{path}/structure_factor");
            if !(sk.n_max.is_finite() && sk.n_max >= 1.0) {
                errors.push((
                    format!("{p}/k_max"),
                    format!("must be at least 1 (units of 2 pi / L), got {}", sk.n_max),
                ));
            } else if sk.n_max > 5000.0 {
                errors.push((
                    format!("{p}/k_max"),
                    format!(
                        "{} (units of 2 pi / L) gives ~{:.1e} lattice vectors; at most 5000",
                        sk.n_max,
                        std::f64::consts::PI * sk.n_max * sk.n_max
                    ),
                ));
            }
            if samples >= 10 && sk.every as u64 > samples / 10 {
                errors.push((
                    format!("{p}/every"),
                    format!(
                        "must be at most samples / 10 = {} so that each of the 10 blocks has an evaluation, got {}",
                        samples / 10,
                        sk.every
                    ),
                ));
            }
        }
    }

    /// `radial_distribution` (2D): `r_max` in (0, L/2], evaluated in each of the 10 blocks of
    /// the `samples`.
    fn check_radial_distribution(
        &self,
        path: &str,
        samples: u64,
        errors: &mut Vec<(String, String)>,
    ) {
        if let (Some(rc), 2) = (self.radial_config(), self.dim) {
            let p = format!("{path}/radial_distribution");
            if !(rc.r_max > 0.0 && rc.r_max <= 0.5 * rc.l * (1.0 + 1e-12)) {
                errors.push((
                    format!("{p}/r_max"),
                    format!(
                        "must lie in (0, L/2] = (0, {}] (m), got {}",
                        0.5 * rc.l,
                        rc.r_max
                    ),
                ));
            }
            if samples >= 10 && rc.every as u64 > samples / 10 {
                errors.push((
                    format!("{p}/every"),
                    format!(
                        "must be at most samples / 10 = {} so that each of the 10 blocks has an evaluation, got {}",
                        samples / 10,
                        rc.every
                    ),
                ));
            }
        }
    }

    /// The physical scales of the dimensional inputs (`models::SCALE_MIN`:
    /// 30 orders of magnitude either side of 1), and the run's work (particle steps) against
    /// `MAX_RUN_WORK`. A mass of 1e-308 or a noise of 1e308 made every run fail with
    /// non-finite velocities; a warm-up of 1e15 s never ended.
    fn check_scales(&self, path: &str, errors: &mut Vec<(String, String)>) {
        let mut scale = |key: &str, v: f64| {
            if !(SCALE_MIN..=SCALE_MAX).contains(&v) {
                errors.push((
                    format!("{path}/{key}"),
                    format!(
                        "{v:e} is outside [{SCALE_MIN:e}, {SCALE_MAX:e}], the physical scales granular takes (30 orders of magnitude either side of 1, in any units): beyond them forces, velocities or energies leave the range of a double"
                    ),
                ));
            }
        };
        scale("radius", self.radius);
        scale("mass", self.mass);
        scale("spring_constant", self.spring_constant);
        if self.noise_strength != 0.0 {
            scale("noise_strength", self.noise_strength);
        }
        if let Some(l) = self.box_length {
            scale("box_length", l);
        }
        if let Some(dt) = self.dt {
            scale("dt", dt);
        }
        let cfg = self.config();
        let dt = cfg.dt();
        if dt > 0.0 && dt.is_finite() {
            let steps = (self.warmup + self.duration) / dt;
            let work = steps * self.n_particles as f64;
            if !(work <= MAX_RUN_WORK) {
                errors.push((
                    format!("{path}/duration"),
                    format!(
                        "warmup + duration = {:e} s is {steps:.2e} steps of dt = {dt:e} s for {} particles, {work:.2e} particle steps, more than the limit of {MAX_RUN_WORK:e} per run (~10^7 CPU s)",
                        self.warmup + self.duration,
                        self.n_particles
                    ),
                ));
            }
        }
    }

    /// Checks the schema cannot express; `path` is the JSON pointer of this object.
    pub fn check(&self, path: &str, errors: &mut Vec<(String, String)>) {
        self.check_scales(path, errors);
        if let Err(es) = self.config().validate() {
            for e in es {
                let (field, msg) = e.split_once(": ").unwrap_or(("", e.as_str()));
                let field = match field {
                    "friction" => "mu",
                    f => f,
                };
                let p = if field.is_empty() {
                    path.to_string()
                } else {
                    format!("{path}/{field}")
                };
                errors.push((p, msg.to_string()));
            }
        }
        if self.dim == 1 && self.initial_layout != Layout::Uniform {
            errors.push((
                format!("{path}/initial_layout"),
                "1D runs start evenly spaced: only \"uniform\"".into(),
            ));
        }
        if self.velocity_histogram.is_some() && !self.wants(RfmObservable::VelocityHistogram) {
            errors.push((
                format!("{path}/velocity_histogram"),
                "given without the observable \"velocity_histogram\"".into(),
            ));
        }
        if let Some(h) = &self.velocity_histogram {
            check_velocity_range(h.range, format!("{path}/velocity_histogram/range"), errors);
        }
        self.check_structure(path, errors);
        self.check_snapshot(path, errors);
        self.check_free_paths(path, errors);
        let cfg = self.config();
        if cfg.validate().is_ok() {
            let samples = cfg.duration_steps() / self.sample_every;
            if samples < 10 {
                errors.push((
                    format!("{path}/duration"),
                    format!("gives {samples} samples (duration / (dt * sample_every)); at least 10 are needed for the block errors"),
                ));
            }
        }
        let mut seen = Vec::new();
        for (i, o) in self.observables.iter().enumerate() {
            if seen.contains(o) {
                errors.push((
                    format!("{path}/observables/{i}"),
                    format!("duplicate observable {o:?}"),
                ));
            }
            seen.push(*o);
        }
    }
}
