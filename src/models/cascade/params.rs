//! The `params` of a `cascade` manifest (spec `rfm.md` 3.4): serde types, their resolution
//! into the simulator's configuration (`config()`) and the cross-field rules the schema cannot
//! express (`check()`).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::aux_models::cascade::{CascadeConfig, PlacementConfig, Variant};
use crate::models::{MAX_RUN_WORK, SCALE_MAX, SCALE_MIN};
use crate::rfm::params::THESIS_RADIUS;

type Errors = Vec<(String, String)>;

/// Most cells of the placement's grid (24 bytes each: 2.4 GB).
const MAX_PLACEMENT_CELLS: f64 = 1e8;

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
        let mut scale = |key: &str, v: f64| {
            if !(SCALE_MIN..=SCALE_MAX).contains(&v) {
                errors.push((
                    format!("{path}/{key}"),
                    format!("{v:e} is outside [{SCALE_MIN:e}, {SCALE_MAX:e}], the physical scales granular takes (30 orders of magnitude either side of 1, in any units)"),
                ));
            }
        };
        scale("box_length", self.box_length);
        if let Some(p) = &self.placement {
            scale("placement/radius", p.radius);
        }
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
            // The placement's cell grid, (L / (2 radius))^2 cells (a tiny radius or a huge box
            // made the run's allocation fail, or its index overflow).
            let cells = (l / (2.0 * p.radius)).floor().powi(2);
            if !(cells <= MAX_PLACEMENT_CELLS) {
                errors.push((
                    format!("{path}/placement/radius"),
                    format!(
                        "a radius {:e} in a box of {l:e} gives a cell grid of (L / (2 radius))^2 = {cells:.2e} cells, more than the limit of {MAX_PLACEMENT_CELLS:e} (the discs would cover a fraction {phi:.1e} of the box): a larger radius or a smaller box_length",
                        p.radius
                    ),
                ));
            }
        }
        // 30 4^level work units per realisation (the field, its FFT, the shells), 16 per
        // placement attempt.
        let work = self.realisations as f64 * 30.0 * 4f64.powi(self.level as i32)
            + self
                .placement
                .as_ref()
                .map_or(0.0, |p| 16.0 * p.max_attempts as f64);
        if work > MAX_RUN_WORK {
            errors.push((
                format!("{path}/realisations"),
                format!(
                    "{} realisations of a 2^{} x 2^{} grid (and the placement's max_attempts) are {work:.2e} work units, more than the limit of {MAX_RUN_WORK:e} per run (~10^7 CPU s): fewer realisations per run (more replicas instead), fewer max_attempts",
                    self.realisations, self.level, self.level
                ),
            ));
        }
    }
}
