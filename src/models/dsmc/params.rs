//! The `params` of a `dsmc` manifest (spec `dsmc.md`): serde types that mirror the JSON,
//! their cross-field rules (`check`), and their resolution into the engine's configuration
//! ([`DsmcParams::system`]).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::dsmc::predict::SONINE_MAX_SPECIES;
use crate::dsmc::system::{
    grid_time, power_law_species, theory_restitution, Method, RestitutionModel, SpeciesInfo,
    TamsdPlan, VdistPlan, MAX_PARTICLES,
};
use crate::dsmc::{DsmcSystem, Observed, RowValue, RowValueSet, SpeciesRow};
use crate::models::{ModelError, ParamErrors, SCALE_MAX, SCALE_MIN};
use crate::theory::cost::{self, Cost, Workload};

/// Parameters of a DSMC run (homogeneous cooling state of a polydisperse granular gas).
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DsmcParams {
    /// Collision-pair selection: `low_rank` (rank-3 species selection) or `bird` (uniform pairs).
    pub method: DsmcMethod,
    /// The species: a power law (the paper's polydisperse case) or an explicit list.
    pub species: SpeciesSpec,
    /// System volume V (explicit species list only; give this or `number_density`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub volume: Option<f64>,
    /// Total number density N/V (explicit species list only; give this or `volume`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub number_density: Option<f64>,
    /// Restitution coefficient model.
    pub restitution: Restitution,
    /// Initial temperature of every species without its own `temperature` (default 1), or
    /// `{"hcs": {"mean": T}}`: every species at its homogeneous-cooling-state temperature with
    /// number-weighted mean T (paper eq. 25).
    #[serde(default)]
    pub initial_temperature: InitialTemperature,
    /// End time of the run (> 0).
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub t_end: f64,
    /// Times at which the state is reported (t = 0 and t_end are always reported).
    #[serde(default)]
    pub output_times: OutputTimes,
    /// Observables beyond the always-recorded temperature: `msd` enables displacement
    /// bookkeeping (memory and time); `tamsd` records tracer trajectories for the time-averaged
    /// MSD (needs the `tamsd` object); `velocity_distribution` records the Sonine coefficient
    /// a2 and scaled-speed histograms (settings in the optional `velocity_distribution`
    /// object); `temperature` may be listed for clarity.
    #[serde(default)]
    pub observables: Vec<DsmcObservable>,
    /// Settings of the time-averaged MSD (required with, and only with, the observable `tamsd`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tamsd: Option<TamsdSpec>,
    /// Settings of the velocity distribution (only with the observable
    /// `velocity_distribution`; defaults when absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity_distribution: Option<VdistSpec>,
    /// Recompute the exact speed bounds (and rebuild the selection tables) every this many
    /// collisions per particle (default 1, i.e. every ~N collisions).
    #[serde(default = "one")]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub refresh_every: f64,
}

fn one() -> f64 {
    1.0
}

/// A number (the same temperature for every species) or `{"hcs": {"mean": T}}`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum InitialTemperature {
    Value(f64),
    /// Homogeneous cooling state with number-weighted mean temperature `mean`.
    Hcs {
        mean: f64,
    },
}

impl Default for InitialTemperature {
    fn default() -> Self {
        InitialTemperature::Value(1.0)
    }
}

impl Serialize for InitialTemperature {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            InitialTemperature::Value(v) => s.serialize_f64(*v),
            InitialTemperature::Hcs { mean } => {
                serde_json::json!({"hcs": {"mean": mean}}).serialize(s)
            }
        }
    }
}

impl<'de> Deserialize<'de> for InitialTemperature {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let v = serde_json::Value::deserialize(d)?;
        if let Some(x) = v.as_f64() {
            return Ok(InitialTemperature::Value(x));
        }
        let mean = v
            .as_object()
            .filter(|o| o.len() == 1)
            .and_then(|o| o.get("hcs"))
            .and_then(|h| h.as_object())
            .filter(|h| h.len() == 1)
            .and_then(|h| h.get("mean"))
            .and_then(|m| m.as_f64())
            .ok_or_else(|| {
                D::Error::custom("expected a number or {\"hcs\": {\"mean\": number}}")
            })?;
        Ok(InitialTemperature::Hcs { mean })
    }
}

impl JsonSchema for InitialTemperature {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "InitialTemperature".into()
    }

    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({
            "description": "A temperature > 0 for every species, or {\"hcs\": {\"mean\": T}}: the homogeneous cooling state with number-weighted mean temperature T.",
            "oneOf": [
                {"type": "number", "exclusiveMinimum": 0},
                {
                    "type": "object",
                    "properties": {"hcs": {
                        "type": "object",
                        "properties": {"mean": {"type": "number", "exclusiveMinimum": 0}},
                        "required": ["mean"],
                        "additionalProperties": false
                    }},
                    "required": ["hcs"],
                    "additionalProperties": false
                }
            ]
        })
    }
}

/// DSMC method.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Copy, Debug, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum DsmcMethod {
    /// The paper's low-rank method (section III.A): species pairs from a rank-3 majorant.
    LowRank,
    /// Bird's method (section III.B): uniform ordered pairs, one global majorant.
    Bird,
}

impl DsmcMethod {
    /// The engine's method.
    pub fn engine(self) -> Method {
        match self {
            DsmcMethod::LowRank => Method::LowRank,
            DsmcMethod::Bird => Method::Bird,
        }
    }

    pub fn as_str(self) -> &'static str {
        match self {
            DsmcMethod::LowRank => "low_rank",
            DsmcMethod::Bird => "bird",
        }
    }
}

/// How the species are given.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum SpeciesSpec {
    /// N_k = round(N1 k^-theta) for every k with N_k >= 1; m_k = k, sigma_k = k^(1/3);
    /// V = N1 / n1.
    PowerLaw(PowerLaw),
    /// Explicit species; needs `volume` or `number_density` in params.
    List(Vec<SpeciesEntry>),
}

/// The paper's polydisperse size distribution.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PowerLaw {
    /// Monomer number density n_1 (sets V = N1/n1).
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub n1: f64,
    /// Number of monomers N_1.
    #[serde(rename = "N1")]
    #[schemars(range(min = 1))]
    pub n1_count: u64,
    /// Exponent theta of N_k = round(N1 k^-theta).
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub theta: f64,
}

/// One species of an explicit list.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SpeciesEntry {
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub mass: f64,
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub diameter: f64,
    #[schemars(range(min = 1))]
    pub count: u64,
    /// Initial temperature of this species (overrides `initial_temperature`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub temperature: Option<f64>,
}

/// Restitution coefficient model.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Restitution {
    /// A constant coefficient eps in [0, 1] for every pair.
    Constant(#[schemars(range(min = 0, max = 1))] f64),
    /// Viscoelastic spheres (paper Appendix A): eps depends on the normal impact speed g_n
    /// through beta = A kappa_ki^(2/5) g_n^(1/5), from the exact contact ODE.
    Viscoelastic(Viscoelastic),
}

/// Parameters of viscoelastic restitution.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Viscoelastic {
    /// A kappa^(2/5) of the reference pair m = 1, sigma = 1 (the paper's monomer pair; Figs 7-8
    /// use 0.09). Other pairs scale with kappa_ki ~ sqrt(sigma_eff)/m_eff (A3-A5), all
    /// species being of the same material.
    #[schemars(range(min = 0))]
    pub a_kappa: f64,
}

/// Output times: a log grid, a list, or both (merged).
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq, Default)]
#[serde(deny_unknown_fields)]
pub struct OutputTimes {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub log: Option<LogTimes>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub list: Option<Vec<f64>>,
}

/// `per_decade` log-spaced times from `from` up to `to` (`to` itself when it is on the grid).
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LogTimes {
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub from: f64,
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub to: f64,
    #[schemars(range(min = 1, max = 1000))]
    pub per_decade: u32,
}

/// DSMC observables.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Copy, Debug, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum DsmcObservable {
    /// Species temperatures T_k = m_k <v^2>/3 (always recorded).
    Temperature,
    /// Partial mean-squared displacements <R_k^2(t)> (displacement bookkeeping).
    Msd,
    /// Time-averaged MSD (26) of tracer particles at the lags of the `tamsd` object
    /// (displacement bookkeeping, plus the tracers' trajectories on a uniform grid).
    Tamsd,
    /// The Sonine coefficient a2_k = 3 <v^4>_k / (5 <v^2>_k^2) - 1 at every output time and
    /// the histogram of the scaled speed c = v / sqrt(2 T_k / m_k) at chosen output times
    /// (settings in the `velocity_distribution` object). Draws no random numbers.
    VelocityDistribution,
}

impl DsmcObservable {
    /// The per-row value of `dsmc_species` it records at every output time, if any (its
    /// computation and column name are in [`crate::dsmc::row_values`]).
    pub fn row_value(self) -> Option<RowValue> {
        match self {
            DsmcObservable::VelocityDistribution => Some(RowValue::A2),
            DsmcObservable::Temperature | DsmcObservable::Msd | DsmcObservable::Tamsd => None,
        }
    }
}

/// Settings of the observable `velocity_distribution`.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct VdistSpec {
    /// Output times at which the scaled-speed histogram is recorded (each must be an output
    /// time); default: t_end only. a2 is recorded at every output time.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(extend("items" = {"type": "number", "minimum": 0}))]
    pub times: Option<Vec<f64>>,
    /// Number of bins of the histogram on [0, c_max) (default 60).
    #[serde(default = "default_bins")]
    #[schemars(range(min = 1, max = 10000))]
    pub bins: u32,
    /// Upper end of the histogram's scaled speeds (default 4); faster particles are not
    /// counted.
    #[serde(default = "default_c_max")]
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub c_max: f64,
}

impl Default for VdistSpec {
    fn default() -> Self {
        VdistSpec {
            times: None,
            bins: default_bins(),
            c_max: default_c_max(),
        }
    }
}

fn default_bins() -> u32 {
    60
}

fn default_c_max() -> f64 {
    4.0
}

/// Most histogram bins.
pub const MAX_BINS: u32 = 10_000;

impl VdistSpec {
    /// The histogram times resolved against the output times `outputs` (sorted): each given
    /// time mapped to the output time it matches (relative 1e-12), sorted, de-duplicated;
    /// `outputs`' last (t_end) by default. Err(index) for a time that is no output time.
    pub fn resolve_times(&self, outputs: &[f64]) -> Result<Vec<f64>, usize> {
        let Some(times) = &self.times else {
            return Ok(outputs.last().copied().into_iter().collect());
        };
        let mut out = Vec::new();
        for (i, &t) in times.iter().enumerate() {
            let m = outputs
                .iter()
                .copied()
                .find(|&o| (o - t).abs() <= 1e-12 * o.abs().max(1e-300))
                .ok_or(i)?;
            out.push(m);
        }
        out.sort_by(f64::total_cmp);
        out.dedup();
        Ok(out)
    }
}

/// Time-averaged MSD (paper eq. 26): the displacements of `tracers` particles per species are
/// recorded on the uniform grid t_j = j t_end / grid, j = 0..grid; at the end of the run the
/// mean over tracers and over j of |R(t_j + Delta) - R(t_j)|^2 is reported for every lag.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TamsdSpec {
    /// Lags Delta (0 < Delta < t_end). Each is rounded to the nearest positive multiple of the
    /// grid step t_end / grid (at least one step); lags equal after rounding are merged.
    #[schemars(length(min = 1), extend("items" = {"type": "number", "exclusiveMinimum": 0}))]
    pub lags: Vec<f64>,
    /// Tracers per species (default 100): the first `tracers` particles of each species
    /// (particles are exchangeable); a species with fewer particles uses all of them.
    #[serde(default = "default_tracers")]
    #[schemars(range(min = 1))]
    pub tracers: u64,
    /// Number of uniform intervals of [0, t_end] on which the tracers' displacements are
    /// recorded (default 10000); the grid step is t_end / grid.
    #[serde(default = "default_grid")]
    #[schemars(range(min = 1))]
    pub grid: u64,
}

fn default_tracers() -> u64 {
    100
}

fn default_grid() -> u64 {
    10_000
}

/// Most doubles the tracer trajectories of one run may hold (tracers x 3 x (grid + 1)):
/// 1.6 GB.
pub const TAMSD_MAX_DOUBLES: f64 = 2e8;

impl TamsdSpec {
    /// The lags in grid steps for a run of length `t_end`: each rounded to the nearest
    /// multiple of t_end / grid (at least one step), sorted, duplicates merged. Steps >= `grid`
    /// (a lag that rounds to t_end) are kept here; `DsmcParams::check` rejects them.
    pub fn resolve(&self, t_end: f64) -> Vec<u64> {
        let step = t_end / self.grid as f64;
        let mut steps: Vec<u64> = self
            .lags
            .iter()
            .map(|&l| {
                let x = (l / step).round();
                if x.is_finite() && x >= 1.0 {
                    x.min(u64::MAX as f64) as u64
                } else {
                    1
                }
            })
            .collect();
        steps.sort_unstable();
        steps.dedup();
        steps
    }

    /// The time of grid point `j` of a run of length `t_end`: j t_end / grid (t_end exactly
    /// for j = grid).
    pub fn grid_time(&self, t_end: f64, j: u64) -> f64 {
        grid_time(t_end, self.grid, j)
    }
}

/// Most output times a run may report (t = 0 and t_end included): the paper's figures use
/// tens, a log grid of 1000 per decade over 100 decades is 10^5.
pub const MAX_OUTPUT_TIMES: u64 = 100_000;

/// Most species a run may have (the engine's limit: a power law with a small theta gives
/// many).
pub const MAX_SPECIES: usize = 1_000_000;

/// Largest `t_end` in collision times, t_end n sigma_max^2 sqrt(T_max / m_min) (the
/// collision rate of the fastest, largest pair, up to a factor ~7): by then a gas that cools
/// at all has cooled by a factor ~1e-60 (the paper's longest runs are ~1e9 collision times);
/// far beyond, its temperature leaves the range of a double and the theory cannot follow it.
pub const MAX_COLLISION_TIMES: f64 = 1e30;

/// Largest ratio of two species' initial temperatures (the paper's starts are equal
/// temperatures or the HCS, ratios ~400; the theory's ODE fails from ~1e6 on).
pub const MAX_TEMPERATURE_RATIO: f64 = 1e4;

/// Fewest collisions per particle between two refreshes of the speed bounds (each costs
/// O(N)).
pub const MIN_REFRESH_EVERY: f64 = 0.01;

/// Largest beta = A kappa^(2/5) g_n^(1/5) of viscoelastic restitution at the thermal impact
/// speeds: eps(1000) ~ 1e-5 (the grains stick), the end of the range where the tabulated
/// eps(beta) is checked against the contact ODE; the theory's tabulated Maxwell averages go to
/// beta ~ 1.6e5, so a run's pairs stay inside them.
pub const MAX_THERMAL_BETA: f64 = 1e3;

/// Most CPU seconds the kinetic theory of one point may take, as `theory::cost` estimates it
/// (~3 hours: ~2 000 species, or ~1 000 with msd).
pub const MAX_THEORY_SECONDS: f64 = 1e4;

/// Most bytes the kinetic theory of one point may hold, as estimated (32 GB).
pub const MAX_THEORY_BYTES: f64 = 32e9;

impl OutputTimes {
    /// An upper bound on the number of times [`OutputTimes::resolve`] gives (0, t_end, the log
    /// grid, the list), computed without listing them (saturating).
    pub fn count_bound(&self) -> u64 {
        let mut n: u64 = 2;
        if let Some(log) = &self.log {
            let span = (log.to.log10() - log.from.log10()) * log.per_decade as f64 + 1e-9;
            if span >= 0.0 {
                n = n.saturating_add(if span.is_finite() && span < 1e18 {
                    span.floor() as u64 + 1
                } else {
                    u64::MAX
                });
            } else {
                n = n.saturating_add(1);
            }
        }
        if let Some(list) = &self.list {
            n = n.saturating_add(list.len() as u64);
        }
        n
    }

    /// The sorted, de-duplicated output times, with 0 and `t_end` included.
    pub fn resolve(&self, t_end: f64) -> Vec<f64> {
        let mut times = vec![0.0, t_end];
        if let Some(log) = &self.log {
            let step = 1.0 / log.per_decade as f64;
            let (a, b) = (log.from.log10(), log.to.log10());
            let n = ((b - a) / step + 1e-9).floor() as i64;
            for j in 0..=n.max(0) {
                times.push(10f64.powf(a + j as f64 * step));
            }
        }
        if let Some(list) = &self.list {
            times.extend(list.iter().copied());
        }
        times.retain(|t| *t <= t_end);
        times.sort_by(f64::total_cmp);
        times.dedup_by(|a, b| (*a - *b).abs() <= 1e-12 * b.abs().max(1e-300));
        times
    }
}

impl DsmcParams {
    /// The engine's configuration of a run with these parameters (species resolved, the HCS
    /// temperatures computed, output times and TAMSD lags resolved).
    pub fn system(&self) -> Result<DsmcSystem, ModelError> {
        let p = self;
        let (mut species, volume) = p.resolved_species()?;
        let restitution = match &p.restitution {
            Restitution::Constant(e) => RestitutionModel::Constant(*e),
            Restitution::Viscoelastic(v) => RestitutionModel::Viscoelastic { a_kappa: v.a_kappa },
        };
        if let InitialTemperature::Hcs { mean } = p.initial_temperature {
            hcs_start_temperatures(&mut species, volume, &restitution, mean)?;
        }
        let tamsd = p.tamsd_plan(&species);
        let output_times = p.output_times.resolve(p.t_end);
        let vdist = p.vdist_plan(&output_times)?;
        Ok(DsmcSystem {
            method: p.method.engine(),
            species,
            volume,
            restitution,
            t_end: p.t_end,
            output_times,
            observe: Observed {
                msd: p.wants_msd(),
                tamsd,
                vdist,
                values: p.row_values(),
            },
            refresh_every: p.refresh_every,
            rate_scale: std::f64::consts::PI / (4.0 * volume),
        })
    }

    /// The species (each starting at its own temperature, else the initial one: the mean of
    /// an HCS start) and the volume, from the power law or the list (with `volume` or
    /// `number_density`); refused beyond `MAX_PARTICLES` particles.
    pub(super) fn resolved_species(&self) -> Result<(Vec<SpeciesInfo>, f64), ModelError> {
        let p = self;
        let base_t = match p.initial_temperature {
            InitialTemperature::Value(t) => t,
            InitialTemperature::Hcs { mean } => mean,
        };
        let (species, volume) = match &p.species {
            SpeciesSpec::PowerLaw(pl) => (
                power_law_species(pl.n1_count, pl.theta, base_t)?,
                pl.n1_count as f64 / pl.n1,
            ),
            SpeciesSpec::List(list) => {
                let species: Vec<SpeciesInfo> = list
                    .iter()
                    .map(|s| SpeciesInfo {
                        mass: s.mass,
                        diameter: s.diameter,
                        count: s.count,
                        initial_temperature: s.temperature.unwrap_or(base_t),
                    })
                    .collect();
                let n: u64 = species.iter().fold(0u64, |a, s| a.saturating_add(s.count));
                let volume = match (p.volume, p.number_density) {
                    (Some(v), _) => v,
                    (None, Some(d)) => n as f64 / d,
                    (None, None) => {
                        return Err(ModelError::Params(
                            "species.list needs volume or number_density".into(),
                        ))
                    }
                };
                (species, volume)
            }
        };
        let n: u64 = species.iter().fold(0u64, |a, s| a.saturating_add(s.count));
        if n > MAX_PARTICLES {
            return Err(ModelError::Params(format!(
                "{n} particles is more than the supported {MAX_PARTICLES}"
            )));
        }
        Ok((species, volume))
    }

    /// The TAMSD plan (grid, tracers per species, lags on the grid below it), when a TAMSD is
    /// asked for.
    fn tamsd_plan(&self, species: &[SpeciesInfo]) -> Option<TamsdPlan> {
        let p = self;
        match (&p.tamsd, p.wants_tamsd()) {
            (Some(tm), true) => {
                let lag_steps: Vec<u64> = tm
                    .resolve(p.t_end)
                    .into_iter()
                    .filter(|&l| l < tm.grid)
                    .collect();
                Some(TamsdPlan {
                    grid: tm.grid,
                    tracers: species
                        .iter()
                        .map(|s| s.count.min(tm.tracers) as usize)
                        .collect(),
                    lags: lag_steps
                        .iter()
                        .map(|&l| grid_time(p.t_end, tm.grid, l))
                        .collect(),
                    lag_steps,
                })
            }
            _ => None,
        }
    }

    /// The velocity-distribution plan, when one is asked for: its times (each one of the
    /// `output_times`, else refused), bins and range.
    fn vdist_plan(&self, output_times: &[f64]) -> Result<Option<VdistPlan>, ModelError> {
        if !self.wants_vdist() {
            return Ok(None);
        }
        let spec = self.velocity_distribution.clone().unwrap_or_default();
        let times = spec.resolve_times(output_times).map_err(|i| {
            ModelError::Params(format!(
                "velocity_distribution.times[{i}] is not an output time"
            ))
        })?;
        Ok(Some(VdistPlan {
            times,
            bins: spec.bins,
            c_max: spec.c_max,
        }))
    }

    /// An estimate of the bytes a run holds at its peak: the particle arrays (velocities,
    /// and displacements, particle ids, Bird's speed weights when used), the TAMSD tracks and
    /// the recorded rows, twice (a checkpoint serialises the state once more), plus the
    /// per-species tables.
    pub fn memory_estimate(&self) -> u64 {
        // Beyond 10^6 species the run is refused elsewhere; count none.
        let counts = self.species_counts().unwrap_or_default();
        let n = counts.iter().fold(0u64, |a, c| a.saturating_add(*c));
        let low_rank = self.method == DsmcMethod::LowRank;
        let disp = self.wants_msd() || self.wants_tamsd();
        let per_particle = 24
            + if disp { 32 } else { 0 }
            + if low_rank && self.wants_tamsd() { 4 } else { 0 }
            + if low_rank { 0 } else { 4 };
        let tracks = match (&self.tamsd, self.wants_tamsd()) {
            (Some(tm), true) => counts
                .iter()
                .map(|c| (*c).min(tm.tracers))
                .fold(0u64, |a, c| a.saturating_add(c))
                .saturating_mul(tm.grid.saturating_add(1))
                .saturating_mul(24),
            _ => 0,
        };
        let m = counts.len() as u64;
        let hist = if self.wants_vdist() {
            let spec = self.velocity_distribution.clone().unwrap_or_default();
            let times = spec.times.as_ref().map_or(1, |t| t.len()) as u64;
            m.saturating_mul(times)
                .saturating_mul(spec.bins as u64)
                .saturating_mul(56)
        } else {
            0
        };
        // A row holds a slot for every per-row value (88 bytes with a2 alone).
        let row_bytes = std::mem::size_of::<SpeciesRow>() as u64;
        let rows = m
            .saturating_mul(self.output_times.count_bound())
            .saturating_mul(row_bytes)
            .saturating_add(hist);
        n.saturating_mul(per_particle)
            .saturating_add(tracks)
            .saturating_add(rows)
            .saturating_mul(2)
            .saturating_add(m.saturating_mul(256))
            .saturating_add(8 << 20)
    }

    pub fn wants_msd(&self) -> bool {
        self.observables.contains(&DsmcObservable::Msd)
    }

    pub fn wants_tamsd(&self) -> bool {
        self.observables.contains(&DsmcObservable::Tamsd)
    }

    /// The per-row values of `dsmc_species` a run records (see [`DsmcObservable::row_value`]).
    pub fn row_values(&self) -> RowValueSet {
        self.observables
            .iter()
            .filter_map(|o| o.row_value())
            .collect()
    }

    pub fn wants_vdist(&self) -> bool {
        self.observables
            .contains(&DsmcObservable::VelocityDistribution)
    }

    /// The histogram times of a run (empty without the observable, or where a time is no
    /// output time, which `check` refuses).
    pub fn vdist_times(&self) -> Vec<f64> {
        if !self.wants_vdist() {
            return Vec::new();
        }
        self.velocity_distribution
            .clone()
            .unwrap_or_default()
            .resolve_times(&self.output_times.resolve(self.t_end))
            .unwrap_or_default()
    }

    /// Particle counts N_k as [`DsmcParams::system`] resolves them, without solving any
    /// theory (None for a power law with more than 1e6 species, which `system` refuses).
    pub fn species_counts(&self) -> Option<Vec<u64>> {
        match &self.species {
            SpeciesSpec::PowerLaw(pl) => power_law_species(pl.n1_count, pl.theta, 1.0)
                .ok()
                .map(|s| s.iter().map(|x| x.count).collect()),
            SpeciesSpec::List(list) => Some(list.iter().map(|s| s.count).collect()),
        }
    }

    /// n sigma_max^2 sqrt(T_max / m_min) at t = 0 for species counts `counts`: an order of
    /// magnitude of the fastest collision rate (the HCS start counts at its mean temperature).
    /// None where it is not a positive finite number.
    fn collision_rate(&self, counts: &[u64]) -> Option<f64> {
        let n: f64 = counts.iter().map(|&c| c as f64).sum();
        let base_t = match self.initial_temperature {
            InitialTemperature::Value(t) => t,
            InitialTemperature::Hcs { mean } => mean,
        };
        let (volume, sigma_max, t_max, m_min) = match &self.species {
            SpeciesSpec::PowerLaw(pl) => (
                pl.n1_count as f64 / pl.n1,
                (counts.len() as f64).cbrt(),
                base_t,
                1.0,
            ),
            SpeciesSpec::List(list) => {
                let volume = match (self.volume, self.number_density) {
                    (Some(v), _) => v,
                    (None, Some(d)) => n / d,
                    (None, None) => return None,
                };
                let fold = |f: fn(&SpeciesEntry) -> f64, g: fn(f64, f64) -> f64, z: f64| {
                    list.iter().map(f).fold(z, g)
                };
                (
                    volume,
                    fold(|s| s.diameter, f64::max, 0.0),
                    list.iter()
                        .map(|s| s.temperature.unwrap_or(base_t))
                        .fold(0.0, f64::max),
                    fold(|s| s.mass, f64::min, f64::INFINITY),
                )
            }
        };
        let rate = n / volume * sigma_max * sigma_max * (t_max / m_min).sqrt();
        (rate.is_finite() && rate > 0.0).then_some(rate)
    }

    /// Checks that the schema cannot express; `path` is the JSON pointer of this object.
    ///
    /// One group of params after another, each adding its errors (at paths relative to the
    /// params) in this order: species and the volume, particle counts, t_end, output times,
    /// observables, velocity distribution, TAMSD, then the physical scales and, where they are
    /// sound, the restitution and the cost of the kinetic theory.
    pub fn check(&self, path: &str, errors: &mut Vec<(String, String)>) {
        let mut found = ParamErrors::new();
        self.check_species(&mut found);
        // The engine's own limits (`DsmcParams::system`), so that `validate` refuses what a
        // run would fail on.
        let counts = self.species_counts();
        self.check_particle_counts(counts.as_deref(), &mut found);
        self.check_t_end(counts.as_deref(), &mut found);
        let n_times = self.check_output_times(&mut found);
        self.check_observables(&mut found);
        self.check_velocity_distribution(&mut found);
        self.check_tamsd(counts.as_deref(), &mut found);
        // The physical scales, then (where they are sound) what the restitution and the
        // kinetic theory of the point would cost.
        if self.check_scales(counts.as_deref(), &mut found) {
            self.check_restitution(counts.as_deref(), &mut found);
            if n_times <= MAX_OUTPUT_TIMES {
                self.check_theory_cost(self.species_paths().0, counts.as_deref(), &mut found);
            }
        }
        errors.extend(found.into_iter().map(|(p, m)| (format!("{path}{p}"), m)));
    }

    /// The JSON paths that name the species, and the particle counts, of this point.
    fn species_paths(&self) -> (&'static str, &'static str) {
        match &self.species {
            SpeciesSpec::PowerLaw(_) => ("/species/power_law/theta", "/species/power_law/N1"),
            SpeciesSpec::List(_) => ("/species/list", "/species/list"),
        }
    }

    /// The species and how the volume is given: `volume`/`number_density` never with a power
    /// law, one of them with a list; a list of at least one species and two particles, without
    /// temperatures of their own under an HCS start.
    fn check_species(&self, errors: &mut ParamErrors) {
        let mut err = |p: &str, m: String| errors.push((p.to_string(), m));
        match &self.species {
            SpeciesSpec::PowerLaw(_) => {
                if self.volume.is_some() {
                    err(
                        "/volume",
                        "must not be given with species.power_law (V = N1/n1)".into(),
                    );
                }
                if self.number_density.is_some() {
                    err(
                        "/number_density",
                        "must not be given with species.power_law (V = N1/n1)".into(),
                    );
                }
            }
            SpeciesSpec::List(list) => {
                if matches!(self.initial_temperature, InitialTemperature::Hcs { .. }) {
                    for (i, s) in list.iter().enumerate() {
                        if s.temperature.is_some() {
                            err(&format!("/species/list/{i}/temperature"), "must not be given with initial_temperature.hcs (the HCS sets every species' temperature)".into());
                        }
                    }
                }
                if list.is_empty() {
                    err("/species/list", "expected at least one species".into());
                }
                match (self.volume, self.number_density) {
                    (None, None) => err(
                        "",
                        "expected `volume` or `number_density` with species.list".into(),
                    ),
                    (Some(_), Some(_)) => err(
                        "/number_density",
                        "give either `volume` or `number_density`, not both".into(),
                    ),
                    _ => {}
                }
                let total: u64 = list.iter().fold(0u64, |a, s| a.saturating_add(s.count));
                if !list.is_empty() && total < 2 {
                    err(
                        "/species/list",
                        "expected at least 2 particles in total".into(),
                    );
                }
            }
        }
    }

    /// The species and particles a run can hold: at most [`MAX_SPECIES`] species (`counts` is
    /// None beyond), at least 2 particles of a power law, at most [`MAX_PARTICLES`].
    fn check_particle_counts(&self, counts: Option<&[u64]>, errors: &mut ParamErrors) {
        let mut err = |p: &str, m: String| errors.push((p.to_string(), m));
        let (species_at, particles_at) = self.species_paths();
        match counts {
            None => err(
                species_at,
                format!(
                    "the power law gives more than {MAX_SPECIES} species (N_k = round(N1 k^-theta) >= 1), the limit of a run: raise theta or lower N1"
                ),
            ),
            Some(c) => {
                let n = c.iter().fold(0u64, |a, x| a.saturating_add(*x));
                if n < 2 && matches!(self.species, SpeciesSpec::PowerLaw(_)) {
                    err(
                        particles_at,
                        format!("the power law gives {n} particle(s) (N_k = round(N1 k^-theta)), expected at least 2 (a single particle never collides)"),
                    );
                }
                if n > MAX_PARTICLES {
                    err(
                        particles_at,
                        format!(
                            "{n} particles in total, more than the limit of {MAX_PARTICLES} (2^32 - 2) per run"
                        ),
                    );
                }
            }
        }
    }

    /// `t_end`: finite, and at most [`MAX_COLLISION_TIMES`] collision times.
    fn check_t_end(&self, counts: Option<&[u64]>, errors: &mut ParamErrors) {
        let mut err = |p: &str, m: String| errors.push((p.to_string(), m));
        if !self.t_end.is_finite() {
            err(
                "/t_end",
                format!("expected a finite time > 0, got {}", self.t_end),
            );
        } else if let Some(rate) = counts.and_then(|c| self.collision_rate(c)) {
            let times = self.t_end * rate;
            if times > MAX_COLLISION_TIMES {
                err(
                    "/t_end",
                    format!(
                        "{:e} is {times:.2e} collision times (t_end n sigma_max^2 sqrt(T_max/m_min)), more than the limit of {MAX_COLLISION_TIMES:e}: the gas would cool beyond what the theory (and a double) can follow",
                        self.t_end
                    ),
                );
            }
        }
    }

    /// The output times: at most [`MAX_OUTPUT_TIMES`], the log grid and the list within
    /// [0, t_end]; returns the bound of their number.
    fn check_output_times(&self, errors: &mut ParamErrors) -> u64 {
        let mut err = |p: &str, m: String| errors.push((p.to_string(), m));
        let n_times = self.output_times.count_bound();
        if n_times > MAX_OUTPUT_TIMES {
            err(
                "/output_times",
                format!(
                    "gives {} output times per run, more than the limit of {MAX_OUTPUT_TIMES}: fewer per_decade, a later `from` or a shorter list",
                    if n_times == u64::MAX { "about infinitely many".to_string() } else { n_times.to_string() }
                ),
            );
        }
        if let Some(log) = &self.output_times.log {
            if log.to < log.from {
                err(
                    "/output_times/log/to",
                    format!("expected to >= from ({}), got {}", log.from, log.to),
                );
            }
            if log.to > self.t_end * (1.0 + 1e-12) {
                err(
                    "/output_times/log/to",
                    format!("expected a time <= t_end ({}), got {}", self.t_end, log.to),
                );
            }
        }
        if let Some(list) = &self.output_times.list {
            for (i, t) in list.iter().enumerate() {
                if !(*t >= 0.0 && *t <= self.t_end * (1.0 + 1e-12)) {
                    err(
                        &format!("/output_times/list/{i}"),
                        format!("expected a time in [0, t_end = {}], got {t}", self.t_end),
                    );
                }
            }
        }
        n_times
    }

    /// The observables: no duplicates, `tamsd` only with its `tamsd` object.
    fn check_observables(&self, errors: &mut ParamErrors) {
        let mut err = |p: &str, m: String| errors.push((p.to_string(), m));
        let mut seen = Vec::new();
        for (i, o) in self.observables.iter().enumerate() {
            if seen.contains(o) {
                err(
                    &format!("/observables/{i}"),
                    format!("duplicate observable {o:?}"),
                );
            }
            if *o == DsmcObservable::Tamsd && self.tamsd.is_none() && !seen.contains(o) {
                err(
                    &format!("/observables/{i}"),
                    "observable `tamsd` needs a `tamsd` object with its `lags`".into(),
                );
            }
            seen.push(*o);
        }
    }

    /// `velocity_distribution`: only with its observable; its bins, `c_max`, and times that
    /// are output times.
    fn check_velocity_distribution(&self, errors: &mut ParamErrors) {
        let mut err = |p: &str, m: String| errors.push((p.to_string(), m));
        let Some(vd) = &self.velocity_distribution else {
            return;
        };
        if !self.wants_vdist() {
            err(
                "/velocity_distribution",
                "given, but `velocity_distribution` is not in `observables`".into(),
            );
        }
        if !(1..=MAX_BINS).contains(&vd.bins) {
            err(
                "/velocity_distribution/bins",
                format!("expected 1..={MAX_BINS} bins, got {}", vd.bins),
            );
        }
        if !(vd.c_max.is_finite() && vd.c_max > 0.0) {
            err(
                "/velocity_distribution/c_max",
                format!("expected a finite c_max > 0, got {}", vd.c_max),
            );
        }
        if let Some(times) = &vd.times {
            if self.output_times.count_bound() <= MAX_OUTPUT_TIMES {
                let outputs = self.output_times.resolve(self.t_end);
                for (i, &t) in times.iter().enumerate() {
                    let one = VdistSpec {
                        times: Some(vec![t]),
                        ..VdistSpec::default()
                    };
                    if one.resolve_times(&outputs).is_err() {
                        err(
                            &format!("/velocity_distribution/times/{i}"),
                            format!(
                                "{t} is not an output time (0, t_end, the log grid or the list)"
                            ),
                        );
                    }
                }
            }
        }
    }

    /// `tamsd`: only with its observable; lags inside (0, t_end) that do not round to t_end on
    /// its grid; trajectories of at most [`TAMSD_MAX_DOUBLES`] doubles.
    fn check_tamsd(&self, counts: Option<&[u64]>, errors: &mut ParamErrors) {
        let mut err = |p: &str, m: String| errors.push((p.to_string(), m));
        let Some(tm) = &self.tamsd else {
            return;
        };
        if !self.wants_tamsd() {
            err(
                "/tamsd",
                "given, but `tamsd` is not in `observables`".into(),
            );
        }
        let step = self.t_end / tm.grid as f64;
        for (i, &lag) in tm.lags.iter().enumerate() {
            if !(lag > 0.0 && lag < self.t_end) {
                err(
                    &format!("/tamsd/lags/{i}"),
                    format!("expected a lag in (0, t_end = {}), got {lag}", self.t_end),
                );
            } else if (lag / step).round() >= tm.grid as f64 {
                err(
                    &format!("/tamsd/lags/{i}"),
                    format!("lag {lag} rounds to t_end on the grid of step t_end / grid = {step}: expected a lag < t_end - step / 2"),
                );
            }
        }
        if let Some(counts) = counts {
            let tracers: u64 = counts
                .iter()
                .fold(0u64, |a, &n| a.saturating_add(n.min(tm.tracers)));
            let doubles = tracers as f64 * 3.0 * (tm.grid as f64 + 1.0);
            if doubles > TAMSD_MAX_DOUBLES {
                err(
                    "/tamsd",
                    format!(
                        "{tracers} tracers x 3 x (grid + 1 = {}) = {doubles:.3e} doubles of trajectories, more than the limit {TAMSD_MAX_DOUBLES:e} (1.6 GB): lower `tracers` or `grid`",
                        tm.grid as f64 + 1.0
                    ),
                );
            }
        }
    }

    /// Every dimensional input within [`SCALE_MIN`, `SCALE_MAX`] (errors at paths relative to
    /// the params); true when all are.
    fn check_scales(&self, counts: Option<&[u64]>, errors: &mut ParamErrors) -> bool {
        let before = errors.len();
        let mut scale = |at: String, what: &str, v: f64| {
            if !(SCALE_MIN..=SCALE_MAX).contains(&v) {
                errors.push((
                    at,
                    format!(
                        "{what} {v:e} is outside [{SCALE_MIN:e}, {SCALE_MAX:e}], the physical scales granular takes (30 orders of magnitude either side of 1, in any units): beyond them collision rates, energies or cooled temperatures leave the range of a double"
                    ),
                ));
            }
        };
        match self.initial_temperature {
            InitialTemperature::Value(t) => scale("/initial_temperature".into(), "temperature", t),
            InitialTemperature::Hcs { mean } => scale(
                "/initial_temperature/hcs/mean".into(),
                "mean temperature",
                mean,
            ),
        }
        let n: f64 = counts.map_or(0.0, |c| c.iter().map(|&x| x as f64).sum());
        match &self.species {
            SpeciesSpec::PowerLaw(pl) => {
                scale("/species/power_law/n1".into(), "number density n1", pl.n1);
                if (SCALE_MIN..=SCALE_MAX).contains(&pl.n1) && n > 0.0 {
                    scale(
                        "/species/power_law/n1".into(),
                        "the total number density n1 N / N1",
                        pl.n1 * n / pl.n1_count as f64,
                    );
                }
            }
            SpeciesSpec::List(list) => {
                for (i, sp) in list.iter().enumerate() {
                    scale(format!("/species/list/{i}/mass"), "mass", sp.mass);
                    scale(
                        format!("/species/list/{i}/diameter"),
                        "diameter",
                        sp.diameter,
                    );
                    if let Some(t) = sp.temperature {
                        scale(format!("/species/list/{i}/temperature"), "temperature", t);
                    }
                }
                match (self.volume, self.number_density) {
                    (Some(v), None) if n > 0.0 => {
                        scale("/volume".into(), "the number density N / V", n / v)
                    }
                    (None, Some(d)) => scale("/number_density".into(), "number density", d),
                    _ => {}
                }
                self.check_temperature_spread(list, errors);
            }
        }
        if !(self.refresh_every >= MIN_REFRESH_EVERY && self.refresh_every <= SCALE_MAX) {
            errors.push((
                "/refresh_every".into(),
                format!(
                    "{:e} is outside [{MIN_REFRESH_EVERY}, {SCALE_MAX:e}]: each refresh costs O(N), so more than {} per N collisions would dominate the run",
                    self.refresh_every,
                    1.0 / MIN_REFRESH_EVERY
                ),
            ));
        }
        errors.len() == before
    }

    /// The spread of the initial temperatures of a species list: at most
    /// [`MAX_TEMPERATURE_RATIO`] (the error at the temperature of a species that sets it).
    fn check_temperature_spread(&self, list: &[SpeciesEntry], errors: &mut ParamErrors) {
        let temps: Vec<(f64, Option<usize>)> = list
            .iter()
            .enumerate()
            .map(|(i, sp)| match (sp.temperature, self.initial_temperature) {
                (Some(t), _) => (t, Some(i)),
                (None, InitialTemperature::Value(t)) => (t, None),
                (None, InitialTemperature::Hcs { mean }) => (mean, None),
            })
            .collect();
        let hi = temps.iter().copied().max_by(|a, b| a.0.total_cmp(&b.0));
        let lo = temps.iter().copied().min_by(|a, b| a.0.total_cmp(&b.0));
        if let (Some((t_hi, i_hi)), Some((t_lo, i_lo))) = (hi, lo) {
            let ratio = t_hi / t_lo;
            if ratio > MAX_TEMPERATURE_RATIO {
                let name = |i: Option<usize>| match i {
                    Some(i) => format!("species {}", i + 1),
                    None => "initial_temperature".into(),
                };
                let at = match (i_hi, i_lo) {
                    (Some(i), _) | (None, Some(i)) => {
                        format!("/species/list/{i}/temperature")
                    }
                    (None, None) => "/initial_temperature".into(),
                };
                errors.push((
                    at,
                    format!(
                        "the initial temperatures span a factor {ratio:.2e} ({t_hi:e} of {} to {t_lo:e} of {}), more than the limit of {MAX_TEMPERATURE_RATIO:e}: so far from equipartition the first collisions equalise them within a fraction of a collision time, faster than the theory's temperature ODE can follow",
                        name(i_hi),
                        name(i_lo)
                    ),
                ));
            }
        }
    }

    /// Viscoelastic restitution: beta = A kappa_ki^(2/5) g_n^(1/5) at the thermal impact
    /// speeds at most [`MAX_THERMAL_BETA`] (see [`DsmcParams::thermal_beta`]).
    fn check_restitution(&self, counts: Option<&[u64]>, errors: &mut ParamErrors) {
        let Restitution::Viscoelastic(v) = &self.restitution else {
            return;
        };
        let Some(beta) = counts.and_then(|c| self.thermal_beta(c, v.a_kappa)) else {
            return;
        };
        if !(beta <= MAX_THERMAL_BETA) {
            errors.push((
                "/restitution/viscoelastic/a_kappa".into(),
                format!(
                    "{:e} gives beta = A kappa^(2/5) g_n^(1/5) up to {beta:.3e} at the thermal impact speeds, more than the limit of {MAX_THERMAL_BETA:e}: eps(beta) < 1e-4 there (the grains stick), beyond the viscoelastic model (small deformations) and its tabulated eps",
                    v.a_kappa
                ),
            ));
        }
    }

    /// An upper bound of beta = A kappa_ki^(2/5) (sqrt(2) u_ki)^(1/5) over the species pairs at
    /// t = 0 (u_ki^2 = T_k/m_k + T_i/m_i, the thermal relative speed; the HCS start at its
    /// mean temperature): with sigma_eff <= sigma_max/2, m_eff >= m_min/2 (of any pair),
    /// A kappa_ki^(2/5) <= a_kappa sigma_max^(1/5) m_min^(-2/5), and u_ki^2 <= 2 T_max/m_min.
    /// The gas cools, so beta falls during a run. None without species.
    pub fn thermal_beta(&self, counts: &[u64], a_kappa: f64) -> Option<f64> {
        let base_t = match self.initial_temperature {
            InitialTemperature::Value(t) => t,
            InitialTemperature::Hcs { mean } => mean,
        };
        let (sigma_max, m_min, t_max) = match &self.species {
            SpeciesSpec::PowerLaw(_) => ((counts.len() as f64).cbrt(), 1.0, base_t),
            SpeciesSpec::List(list) => (
                list.iter().map(|s| s.diameter).fold(0.0, f64::max),
                list.iter().map(|s| s.mass).fold(f64::INFINITY, f64::min),
                list.iter()
                    .map(|s| s.temperature.unwrap_or(base_t))
                    .fold(0.0, f64::max),
            ),
        };
        if counts.is_empty() || !(m_min > 0.0 && m_min.is_finite()) {
            return None;
        }
        let u = (2.0 * t_max / m_min).sqrt();
        Some(
            a_kappa
                * sigma_max.powf(0.2)
                * m_min.powf(-0.4)
                * (std::f64::consts::SQRT_2 * u).powf(0.2),
        )
    }

    /// What the kinetic theory of this point costs (`theory::cost`), from its size: species,
    /// output times, the span in collision times, msd, restitution, start, TAMSD lags. None
    /// where the species or the collision rate cannot be had (refused elsewhere).
    pub fn theory_cost(&self) -> Option<Cost> {
        let counts = self.species_counts()?;
        let rate = self.collision_rate(&counts)?;
        Some(cost::estimate(&self.workload(counts.len(), rate)))
    }

    fn workload(&self, species: usize, rate: f64) -> Workload {
        let constant = matches!(self.restitution, Restitution::Constant(_));
        Workload {
            species,
            times: self.output_times.count_bound().min(usize::MAX as u64) as usize,
            span: (self.t_end * rate).ln_1p(),
            msd: self.wants_msd(),
            velocity_dependent: !constant,
            sonine: constant && species <= SONINE_MAX_SPECIES,
            hcs: matches!(self.initial_temperature, InitialTemperature::Hcs { .. }),
            tamsd_lags: match (&self.tamsd, self.wants_tamsd()) {
                (Some(tm), true) => tm.lags.len(),
                _ => 0,
            },
        }
    }

    /// The kinetic theory's estimated cost against [`MAX_THEORY_SECONDS`] and
    /// [`MAX_THEORY_BYTES`]; the error names the species (`species_at`) when they alone
    /// exceed a limit, else the output times (with `msd`, each costs a quadrature of the
    /// temperature history).
    fn check_theory_cost(
        &self,
        species_at: &str,
        counts: Option<&[u64]>,
        errors: &mut ParamErrors,
    ) {
        let Some(counts) = counts else {
            return;
        };
        let Some(rate) = self.collision_rate(counts) else {
            return;
        };
        let w = self.workload(counts.len(), rate);
        let c = cost::estimate(&w);
        if c.seconds <= MAX_THEORY_SECONDS && c.bytes <= MAX_THEORY_BYTES {
            return;
        }
        let bare = cost::estimate(&Workload {
            times: 2,
            msd: false,
            tamsd_lags: 0,
            ..w
        });
        let at = if bare.seconds > MAX_THEORY_SECONDS || bare.bytes > MAX_THEORY_BYTES {
            species_at
        } else if w.tamsd_lags > 0 && !w.msd {
            "/tamsd/lags"
        } else {
            "/output_times"
        };
        errors.push((
            at.into(),
            format!(
                "the kinetic theory of this point would take ~{:.1e} CPU s and ~{} ({} species, {} output times{}{}, {:.0} e-folds of collision times), more than the limit of {MAX_THEORY_SECONDS:e} s and {}: fewer species (a larger theta, a shorter list), fewer output times{}",
                c.seconds,
                crate::models::bytes_text(c.bytes.min(u64::MAX as f64) as u64),
                w.species,
                w.times,
                if w.msd { ", msd" } else { "" },
                if w.velocity_dependent { ", viscoelastic" } else { "" },
                w.span,
                crate::models::bytes_text(MAX_THEORY_BYTES as u64),
                if w.msd { " or without msd" } else { "" }
            ),
        ));
    }
}

/// An HCS start: every species' initial temperature set to its share in the homogeneous
/// cooling state of mean temperature `mean` (refused where none is found).
fn hcs_start_temperatures(
    species: &mut [SpeciesInfo],
    volume: f64,
    restitution: &RestitutionModel,
    mean: f64,
) -> Result<(), ModelError> {
    let th: Vec<crate::theory::Species> = species
        .iter()
        .map(|s| crate::theory::Species::new(s.mass, s.diameter, s.count as f64 / volume))
        .collect();
    let r = theory_restitution(restitution, species);
    let t0 = crate::theory::hcs::hcs_temperatures(&th, &r, mean)
        .map_err(|e| ModelError::Params(format!("no homogeneous cooling state found: {e}")))?;
    for (s, t) in species.iter_mut().zip(t0) {
        if !(t.is_finite() && t > 0.0) {
            return Err(ModelError::Params(format!(
                "no homogeneous cooling state found (temperature {t})"
            )));
        }
        s.initial_temperature = t;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Lags are rounded to the nearest multiple of the grid step (at least one step), sorted,
    /// merged; grid times are j t_end / grid with t_end exact at the end.
    #[test]
    fn tamsd_lags_round_to_the_grid() {
        let tm = TamsdSpec {
            lags: vec![10.0, 0.01, 2.4, 2.6, 3.0, 0.7, 99.4],
            tracers: 1,
            grid: 50,
        };
        // step 100 / 50 = 2
        assert_eq!(tm.resolve(100.0), vec![1, 2, 5, 50]);
        assert_eq!(tm.grid_time(100.0, 50), 100.0);
        assert_eq!(tm.grid_time(100.0, 5), 10.0);
        let t_end = 0.3;
        let tm = TamsdSpec {
            lags: vec![0.1],
            tracers: 1,
            grid: 3,
        };
        assert_eq!(tm.grid_time(t_end, 3).to_bits(), t_end.to_bits());
        assert_eq!(tm.resolve(t_end), vec![1]);
    }
}
