//! The `params` of an `spm` manifest (spec `rfm.md` 3.2): serde types, their resolution into
//! the simulator's configuration (`config()`) and the cross-field rules the schema cannot
//! express (`check()`).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::models::{check_velocity_range, MAX_RUN_WORK, SCALE_MAX, SCALE_MIN};

use crate::aux_models::spm::{FreePath, SpmConfig};
use crate::rfm::params::{THESIS_MASS, THESIS_NOISE};

type Errors = Vec<(String, String)>;

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

fn one() -> f64 {
    1.0
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

    /// Cross-field rules, every error at its JSON path below `path`: the scales and the work of
    /// a run, the free-path law, the velocity histogram, the fit windows.
    pub fn check(&self, path: &str, errors: &mut Errors) {
        self.check_run_size(path, errors);
        let fp = format!("{path}/free_path");
        match &self.free_path {
            FreePathSpec::Fixed { .. } => {}
            FreePathSpec::Fitted {
                c,
                fractal_dimension: d,
                range,
            } => check_fitted_free_path(&fp, *c, *d, *range, errors),
            FreePathSpec::Table {
                edges,
                density,
                fractal_dimension,
                ..
            } => check_free_path_table(&fp, edges, density, *fractal_dimension, errors),
        }
        if let Some(h) = &self.velocity_histogram {
            check_velocity_range(h.range, format!("{path}/velocity_histogram/range"), errors);
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

    /// The mass and noise within the physical scales; `dt` at least 1e-6, and the walks of a
    /// run (~1/dt steps each) within [`MAX_RUN_WORK`].
    fn check_run_size(&self, path: &str, errors: &mut Errors) {
        for (key, v) in [("mass", self.mass), ("noise_strength", self.noise_strength)] {
            if !(SCALE_MIN..=SCALE_MAX).contains(&v) {
                errors.push((
                    format!("{path}/{key}"),
                    format!("{v:e} is outside [{SCALE_MIN:e}, {SCALE_MAX:e}], the physical scales granular takes (30 orders of magnitude either side of 1, in any units)"),
                ));
            }
        }
        if self.dt < 1e-6 {
            errors.push((
                format!("{path}/dt"),
                format!(
                    "must be at least 1e-6 (a walk takes ~1/dt steps), got {}",
                    self.dt
                ),
            ));
        } else {
            let work = self.walks as f64 / self.dt;
            if work > MAX_RUN_WORK {
                errors.push((
                    format!("{path}/walks"),
                    format!(
                        "{} walks of ~1/dt = {:.0} steps are ~{work:.2e} work units, more than the limit of {MAX_RUN_WORK:e} per run (~10^7 CPU s): fewer walks per run (more replicas instead)",
                        self.walks,
                        1.0 / self.dt
                    ),
                ));
            }
        }
    }
}

/// The fitted free-path law (4.25) at `fp`: a fractal dimension in (1, 2), a range of
/// probability at least 1e-6.
fn check_fitted_free_path(fp: &str, c: f64, d: f64, range: Option<[f64; 2]>, errors: &mut Errors) {
    if !(d > 1.0 && d < 2.0) {
        errors.push((
            format!("{fp}/fitted/fractal_dimension"),
            format!("must lie in (1, 2), got {d}"),
        ));
    } else if let Some([a, b]) = range {
        let beta = d - 1.0;
        let mass = (-c * a.max(0.0).powf(beta)).exp() - (-c * b.powf(beta)).exp();
        if !(a >= 0.0 && a < b) {
            errors.push((
                format!("{fp}/fitted/range"),
                format!("expected [l_min, l_max] with 0 <= l_min < l_max, got [{a}, {b}]"),
            ));
        } else if !(mass > 1e-6) {
            errors.push((
                format!("{fp}/fitted/range"),
                format!("holds a probability {mass:.1e} of (4.25); at least 1e-6 is needed"),
            ));
        }
    }
}

/// A tabulated free-path law at `fp`: one more edge than densities, finite increasing edges,
/// finite non-negative densities (one positive), a fractal dimension in (1, 2).
fn check_free_path_table(
    fp: &str,
    edges: &[f64],
    density: &[f64],
    fractal_dimension: Option<f64>,
    errors: &mut Errors,
) {
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
        if !(d > 1.0 && d < 2.0) {
            errors.push((
                format!("{p}/fractal_dimension"),
                format!("must lie in (1, 2), got {d}"),
            ));
        }
    }
}
