//! Manifest types of the `rfm` model: soft-sphere MD of the Random Force Model (spec
//! `rfm.md`). Defaults are the thesis's (spec 1.1); SI units.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::rfm::params::{
    InitialLayout, RfmConfig, THESIS_MASS, THESIS_NOISE, THESIS_RADIUS, THESIS_SPRING,
};

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

    /// Checks the schema cannot express; `path` is the JSON pointer of this object.
    pub fn check(&self, path: &str, errors: &mut Vec<(String, String)>) {
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
            if !(h.range[0] < h.range[1] && h.range[0].is_finite() && h.range[1].is_finite()) {
                errors.push((
                    format!("{path}/velocity_histogram/range"),
                    format!(
                        "expected [v_min, v_max] with v_min < v_max, got {:?}",
                        h.range
                    ),
                ));
            }
        }
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
