//! Manifest types of the auxiliary models (spec `rfm.md` section 3): `bisection`, `cascade`
//! and `spm`. Each resolves to the simulator's configuration (`config()`); `check()` holds
//! the cross-field rules the schema cannot express.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::aux_models::bisection::{BisectionConfig, Split};
use crate::aux_models::cascade::{CascadeConfig, PlacementConfig, Variant};
use crate::aux_models::spm::{FreePath, SpmConfig};
use crate::rfm::params::{THESIS_MASS, THESIS_NOISE, THESIS_RADIUS};

type Errors = Vec<(String, String)>;

// ----------------------------------------------------------------------------------------
// bisection

/// Multiplicative bisection of [0, 1] (spec 3.1).
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BisectionParams {
    /// Level n: 2^n partitions (N = 2^n; the thesis compares n = 9 with 1D RFM at N = 512).
    #[schemars(range(min = 1, max = 22))]
    pub level: u32,
    /// Independent partitions per run.
    #[schemars(range(min = 2))]
    pub realisations: u64,
    /// The split distribution U_0(a): `"uniform"` (default) or
    /// `{"concave": {"exponent": A}}` with U_0 ~ a^{-A} + (1-a)^{-A}, 0 <= A < 1.
    #[serde(default)]
    pub split: SplitSpec,
    /// Log-spaced histogram of the lengths.
    #[serde(default)]
    pub histogram: BisectionHistogram,
    /// Moments <x^m>, m = 1..orders (default 6).
    #[serde(default = "six")]
    #[schemars(range(min = 1, max = 20))]
    pub moment_orders: u32,
}

#[derive(Serialize, Deserialize, JsonSchema, Clone, Copy, Debug, PartialEq, Default)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum SplitSpec {
    /// U_0(a) = 1.
    #[default]
    Uniform,
    /// U_0(a) = (1-A)/2 (a^{-A} + (1-a)^{-A}).
    Concave {
        /// A in [0, 1).
        #[schemars(range(min = 0))]
        exponent: f64,
    },
}

#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BisectionHistogram {
    /// Lower edge x_min of the log-spaced bins (lengths below are counted in the row
    /// [0, x_min)); default: the power of ten below exp(-(n + 10 sqrt(n) + 10)).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub x_min: Option<f64>,
    /// Bins per decade, default 10.
    #[serde(default = "ten")]
    #[schemars(range(min = 1, max = 1000))]
    pub bins_per_decade: u32,
}

impl Default for BisectionHistogram {
    fn default() -> Self {
        BisectionHistogram {
            x_min: None,
            bins_per_decade: ten(),
        }
    }
}

fn six() -> u32 {
    6
}
fn ten() -> u32 {
    10
}

impl BisectionParams {
    pub fn config(&self) -> BisectionConfig {
        let n = self.level as f64;
        let x_min = self.histogram.x_min.unwrap_or_else(|| {
            10f64.powf(((-(n + 10.0 * n.sqrt() + 10.0)) / std::f64::consts::LN_10).floor())
        });
        BisectionConfig {
            level: self.level,
            realisations: self.realisations,
            split: match self.split {
                SplitSpec::Uniform => Split::Uniform,
                SplitSpec::Concave { exponent } => Split::Concave { exponent },
            },
            x_min,
            bins_per_decade: self.histogram.bins_per_decade,
            orders: self.moment_orders,
        }
    }

    pub fn check(&self, path: &str, errors: &mut Errors) {
        if let SplitSpec::Concave { exponent } = self.split {
            if !(0.0..1.0).contains(&exponent) {
                errors.push((
                    format!("{path}/split/concave/exponent"),
                    format!(
                        "must lie in [0, 1) (U_0 is normalisable only for A < 1), got {exponent}"
                    ),
                ));
            }
        }
        if let Some(x) = self.histogram.x_min {
            if x >= 1.0 {
                errors.push((
                    format!("{path}/histogram/x_min"),
                    format!("must be below 1, got {x}"),
                ));
            }
        }
    }
}

// ----------------------------------------------------------------------------------------
// cascade

/// Multiplicative cascade on a 2^n x 2^n grid (spec 3.4).
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CascadeParams {
    /// Level n: 2^n x 2^n cells (production n = 8).
    #[serde(default = "eight")]
    #[schemars(range(min = 2, max = 11))]
    pub level: u32,
    /// Box side L (m), default 1 (the thesis's S(k) runs; 0.2 for the placement of F 6.3).
    #[serde(default = "one")]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub box_length: f64,
    /// The process (T 6.1).
    pub variant: CascadeVariant,
    /// Independent fields averaged in S(k) (spec [REC] >= 200).
    #[schemars(range(min = 2))]
    pub realisations: u64,
    /// Largest |k| of S(k) in units of 2 pi / L (lattice vectors with p^2 + q^2 <= k_max^2);
    /// default and maximum 2^{n-1} (the grid's Nyquist limit).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(range(min = 1))]
    pub k_max: Option<f64>,
    /// Shell range [lo, hi] of the fit S = A k^{-D_f} in units of 2 pi / L; default
    /// [1, 2^{n-3}] (spec 3.4 [REC]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit_range: Option<[f64; 2]>,
    /// Particle placement in the field (F 6.3); omitted: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub placement: Option<PlacementSpec>,
}

#[derive(Serialize, Deserialize, JsonSchema, Clone, Copy, Debug, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum CascadeVariant {
    /// a ~ U(0,1), normalised by the sum of the four (conserves the weight).
    Ucp,
    /// a ~ U(0,1), not normalised.
    UnonCp,
    /// a ~ U(0, 1/2) on the diagonal children, 1 - a on the others, A = 2.
    Symmetrised,
    /// (0.001, 0.15, 0.32, 0.53) permuted at random at every split.
    Meakin1,
    /// (0.02, 0.32, 0.32, 0.34).
    Meakin2,
    /// (0.18, 0.21, 0.29, 0.31).
    Meakin3,
    /// (0.07, 0.26, 0.32, 0.36).
    Meakin4,
}

/// Placement of discs with the field as acceptance probability (F 6.3).
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PlacementSpec {
    /// Number of discs (F 6.3: 2500 in L = 0.2 m).
    #[schemars(range(min = 1))]
    pub n_particles: u64,
    /// Disc radius (m), default 1.5e-3.
    #[serde(default = "radius")]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub radius: f64,
    /// Give up (the run fails) after this many attempts, default 10^9.
    #[serde(default = "billion")]
    #[schemars(range(min = 1))]
    pub max_attempts: u64,
    /// Largest |k| of the placed discs' S(k) (units of 2 pi / L), default floor(20 L /
    /// (2 pi d)) as the RFM S(k).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(range(min = 1))]
    pub k_max: Option<f64>,
}

fn eight() -> u32 {
    8
}
fn one() -> f64 {
    1.0
}
fn radius() -> f64 {
    THESIS_RADIUS
}
fn billion() -> u64 {
    1_000_000_000
}

impl CascadeParams {
    pub fn config(&self) -> CascadeConfig {
        let nyq = (1u64 << (self.level - 1)) as f64;
        let hi = (1u64 << self.level.saturating_sub(3)) as f64;
        CascadeConfig {
            level: self.level,
            box_length: self.box_length,
            variant: match self.variant {
                CascadeVariant::Ucp => Variant::Ucp,
                CascadeVariant::UnonCp => Variant::UnonCp,
                CascadeVariant::Symmetrised => Variant::Symmetrised,
                CascadeVariant::Meakin1 => Variant::Meakin(1),
                CascadeVariant::Meakin2 => Variant::Meakin(2),
                CascadeVariant::Meakin3 => Variant::Meakin(3),
                CascadeVariant::Meakin4 => Variant::Meakin(4),
            },
            realisations: self.realisations,
            k_max: self.k_max.unwrap_or(nyq),
            fit_range: self.fit_range.unwrap_or([1.0, hi.max(2.0)]),
            placement: self.placement.as_ref().map(|p| PlacementConfig {
                n_particles: p.n_particles,
                radius: p.radius,
                max_attempts: p.max_attempts,
                k_max: p.k_max.unwrap_or_else(|| {
                    (20.0 * self.box_length / (2.0 * std::f64::consts::PI * 2.0 * p.radius))
                        .floor()
                        .max(1.0)
                }),
            }),
        }
    }

    pub fn check(&self, path: &str, errors: &mut Errors) {
        let nyq = (1u64 << (self.level - 1)) as f64;
        if let Some(k) = self.k_max {
            if k > nyq {
                errors.push((
                    format!("{path}/k_max"),
                    format!(
                        "must be at most 2^(level-1) = {nyq} (the grid's Nyquist limit), got {k}"
                    ),
                ));
            }
        }
        let c = self.config();
        let [lo, hi] = c.fit_range;
        if !(lo >= 1.0 && lo < hi && hi <= c.k_max) {
            errors.push((
                format!("{path}/fit_range"),
                format!(
                    "expected [lo, hi] with 1 <= lo < hi <= k_max = {} (units of 2 pi / L), got [{lo}, {hi}]",
                    c.k_max
                ),
            ));
        }
        if let Some(p) = &self.placement {
            let l = self.box_length;
            let phi = p.n_particles as f64 * std::f64::consts::PI * p.radius * p.radius / (l * l);
            if 2.0 * p.radius > 0.5 * l {
                errors.push((
                    format!("{path}/placement/radius"),
                    format!(
                        "the diameter {} must be at most L/2 = {}",
                        2.0 * p.radius,
                        0.5 * l
                    ),
                ));
            } else if phi > 0.5 {
                errors.push((
                    format!("{path}/placement/n_particles"),
                    format!("{} discs give a packing fraction {phi:.3}; random placement jams near 0.55, at most 0.5 is allowed", p.n_particles),
                ));
            }
            if let Some(k) = p.k_max {
                if k > 5000.0 {
                    errors.push((
                        format!("{path}/placement/k_max"),
                        format!("at most 5000 (units of 2 pi / L), got {k}"),
                    ));
                }
            }
        }
    }
}

// ----------------------------------------------------------------------------------------
// spm

/// Single particle model (spec 3.2).
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SpmParams {
    /// Mass M (kg), default 3.53e-5.
    #[serde(default = "mass")]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub mass: f64,
    /// Noise strength D (N^2 s), default 1e-8.
    #[serde(default = "noise")]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub noise_strength: f64,
    /// Euler step in the walk's scaled time tau_l = (l^2 M^2/D)^{1/3}, default 5e-4.
    #[serde(default = "dt")]
    #[schemars(extend("exclusiveMinimum" = 0), range(max = 0.1))]
    pub dt: f64,
    /// Walks per run.
    #[schemars(range(min = 1))]
    pub walks: u64,
    /// The free path l: `{"fixed": {"length": l}}` (gives Q(v, l)), `{"fitted": {"c": C,
    /// "fractal_dimension": D_f}}` ((4.25)) or `{"table": {"edges": [...], "density": [...]}}`.
    pub free_path: FreePathSpec,
    /// Histogram of the velocity components (m/s); default +-8 v_l of a typical l in 2000
    /// bins.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity_histogram: Option<SpmHistogram>,
    /// Window of |v|/v_l of the Gaussian-tail fit of Q(v, l) (fixed l), default [2.5, 4.5] (the
    /// local coefficient still grows slowly with |v|; the far tail is what (5.12) describes).
    #[serde(default = "gaussian_fit")]
    pub gaussian_fit: [f64; 2],
    /// Window of P(v)/P_max of the stretched-exponential tail fit, default [1e-5, 1e-2].
    #[serde(default = "tail_fit")]
    pub tail_fit: [f64; 2],
}

#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SpmHistogram {
    /// [v_min, v_max] (m/s).
    pub range: [f64; 2],
    /// Number of bins, default 2000.
    #[serde(default = "bins")]
    #[schemars(range(min = 10, max = 1000000))]
    pub bins: u32,
}

#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum FreePathSpec {
    /// Every walk has the same free path (Q(v, l), sec. 5.3.1).
    Fixed {
        /// l (m); F 5.11: 0.0036.
        #[schemars(extend("exclusiveMinimum" = 0))]
        length: f64,
    },
    /// (4.25): P_l ~ exp(-C l^{D_f-1}) l^{D_f-2} (sec. 5.3.3: L = 0.6 m, eps = 0.1, D_f = 1.63;
    /// C = 78 / 121 / 179 m^-(D_f-1) at phi = 0.353 / 0.530 / 0.619).
    Fitted {
        #[schemars(extend("exclusiveMinimum" = 0))]
        c: f64,
        /// D_f in (1, 2).
        fractal_dimension: f64,
        /// Optional truncation [l_min, l_max] (m).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        range: Option<[f64; 2]>,
    },
    /// A tabulated, piecewise-constant P_l: bin edges (m, increasing) and densities (m^-1),
    /// e.g. `lo`/`hi`/`density` of an RFM campaign's `rfm_histograms_summary` rows with
    /// kind = "free_path" (drop the out-of-range rows).
    Table {
        #[schemars(length(min = 2))]
        edges: Vec<f64>,
        #[schemars(length(min = 1))]
        density: Vec<f64>,
        /// D_f for the predicted alpha; omitted: fitted with C to the table's tail.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        fractal_dimension: Option<f64>,
        /// Tail bins of that fit: density below this (m^-1), beyond the mode; default 1 (spec
        /// 2.9, "where P < 1").
        #[serde(default = "one")]
        #[schemars(extend("exclusiveMinimum" = 0))]
        fit_below: f64,
    },
}

fn mass() -> f64 {
    THESIS_MASS
}
fn noise() -> f64 {
    THESIS_NOISE
}
fn dt() -> f64 {
    5e-4
}
fn bins() -> u32 {
    2000
}
fn gaussian_fit() -> [f64; 2] {
    [2.5, 4.5]
}
fn tail_fit() -> [f64; 2] {
    [1e-5, 1e-2]
}

impl SpmParams {
    fn free_path(&self) -> FreePath {
        match &self.free_path {
            FreePathSpec::Fixed { length } => FreePath::Fixed { length: *length },
            FreePathSpec::Fitted {
                c,
                fractal_dimension,
                range,
            } => FreePath::Fitted {
                c: *c,
                d_f: *fractal_dimension,
                range: *range,
            },
            FreePathSpec::Table {
                edges,
                density,
                fractal_dimension,
                fit_below,
            } => FreePath::Table {
                edges: edges.clone(),
                density: density.clone(),
                d_f: *fractal_dimension,
                fit_below: *fit_below,
            },
        }
    }

    /// A typical large free path for the default histogram range.
    fn l_ref(&self) -> f64 {
        match &self.free_path {
            FreePathSpec::Fixed { length } => *length,
            FreePathSpec::Fitted {
                c,
                fractal_dimension,
                range,
            } => {
                let l = (10.0 / c).powf(1.0 / (fractal_dimension - 1.0).max(1e-3));
                match range {
                    Some([_, hi]) => l.min(*hi),
                    None => l,
                }
            }
            FreePathSpec::Table { edges, density, .. } => {
                let k = density.iter().rposition(|d| *d > 0.0).unwrap_or(0);
                edges.get(k + 1).copied().unwrap_or(1.0)
            }
        }
    }

    pub fn config(&self) -> SpmConfig {
        let mut c = SpmConfig {
            mass: self.mass,
            noise_strength: self.noise_strength,
            dt: self.dt,
            walks: self.walks,
            free_path: self.free_path(),
            range: [-1.0, 1.0],
            bins: bins(),
            gaussian_fit: self.gaussian_fit,
            tail_fit: self.tail_fit,
        };
        match &self.velocity_histogram {
            Some(h) => {
                c.range = h.range;
                c.bins = h.bins;
            }
            None => {
                let v = 8.0 * c.v_scale(self.l_ref());
                c.range = [-v, v];
            }
        }
        c
    }

    pub fn check(&self, path: &str, errors: &mut Errors) {
        if self.dt < 1e-6 {
            errors.push((
                format!("{path}/dt"),
                format!(
                    "must be at least 1e-6 (a walk takes ~1/dt steps), got {}",
                    self.dt
                ),
            ));
        }
        let fp = format!("{path}/free_path");
        match &self.free_path {
            FreePathSpec::Fixed { .. } => {}
            FreePathSpec::Fitted {
                c,
                fractal_dimension: d,
                range,
            } => {
                if !(*d > 1.0 && *d < 2.0) {
                    errors.push((
                        format!("{fp}/fitted/fractal_dimension"),
                        format!("must lie in (1, 2), got {d}"),
                    ));
                } else if let Some([a, b]) = range {
                    let beta = d - 1.0;
                    let mass = (-c * a.max(0.0).powf(beta)).exp() - (-c * b.powf(beta)).exp();
                    if !(*a >= 0.0 && a < b) {
                        errors.push((
                            format!("{fp}/fitted/range"),
                            format!(
                                "expected [l_min, l_max] with 0 <= l_min < l_max, got [{a}, {b}]"
                            ),
                        ));
                    } else if !(mass > 1e-6) {
                        errors.push((
                            format!("{fp}/fitted/range"),
                            format!(
                                "holds a probability {mass:.1e} of (4.25); at least 1e-6 is needed"
                            ),
                        ));
                    }
                }
            }
            FreePathSpec::Table {
                edges,
                density,
                fractal_dimension,
                ..
            } => {
                let p = format!("{fp}/table");
                if edges.len() != density.len() + 1 {
                    errors.push((
                        format!("{p}/edges"),
                        format!(
                            "expected one more edge than densities: {} edges, {} densities",
                            edges.len(),
                            density.len()
                        ),
                    ));
                }
                for (i, w) in edges.windows(2).enumerate() {
                    if !(w[0] >= 0.0 && w[0] < w[1] && w[1].is_finite()) {
                        errors.push((
                            format!("{p}/edges/{}", i + 1),
                            format!(
                                "edges must be finite, >= 0 and increasing, got {} after {}",
                                w[1], w[0]
                            ),
                        ));
                        break;
                    }
                }
                for (i, d) in density.iter().enumerate() {
                    if !(*d >= 0.0 && d.is_finite()) {
                        errors.push((
                            format!("{p}/density/{i}"),
                            format!("must be finite and >= 0, got {d}"),
                        ));
                    }
                }
                if !density.iter().any(|d| *d > 0.0) {
                    errors.push((format!("{p}/density"), "no positive density".into()));
                }
                if let Some(d) = fractal_dimension {
                    if !(*d > 1.0 && *d < 2.0) {
                        errors.push((
                            format!("{p}/fractal_dimension"),
                            format!("must lie in (1, 2), got {d}"),
                        ));
                    }
                }
            }
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
        for (key, w) in [
            ("gaussian_fit", self.gaussian_fit),
            ("tail_fit", self.tail_fit),
        ] {
            if !(w[0] > 0.0 && w[0] < w[1] && w[1].is_finite()) {
                errors.push((
                    format!("{path}/{key}"),
                    format!("expected [lo, hi] with 0 < lo < hi, got {w:?}"),
                ));
            }
        }
    }
}
