//! The `params` of a `bisection` manifest (spec `rfm.md` 3.1): serde types, their
//! resolution into the simulator's configuration (`config()`) and the cross-field rules the
//! schema cannot express (`check()`).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::aux_models::bisection::{BisectionConfig, Split};
use crate::models::MAX_RUN_WORK;

type Errors = Vec<(String, String)>;

/// Most histogram bins (x_min to 1 at bins_per_decade).
const MAX_BINS: f64 = 1e6;

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
            } else {
                // The log bins from x_min to 1 (5e-324 gave infinitely many: the run's
                // allocation failed).
                let bins = self.histogram.bins_per_decade as f64 * (1.0 / x).log10();
                if !(bins <= MAX_BINS) {
                    errors.push((
                        format!("{path}/histogram/x_min"),
                        format!(
                            "{x:e} gives {bins:.3e} bins ({} per decade down from 1), more than the limit of {MAX_BINS:e}",
                            self.histogram.bins_per_decade
                        ),
                    ));
                }
            }
        }
        // 2^(level+1) work units per realisation (the partition and its histogram).
        let work = self.realisations as f64 * 2f64.powi(self.level as i32 + 1);
        if work > MAX_RUN_WORK {
            errors.push((
                format!("{path}/realisations"),
                format!(
                    "{} realisations of 2^{} intervals are {work:.2e} work units, more than the limit of {MAX_RUN_WORK:e} per run (~10^7 CPU s): fewer realisations per run (more replicas instead)",
                    self.realisations, self.level
                ),
            ));
        }
    }
}
