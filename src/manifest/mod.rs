//! The JSON manifest's envelope: serde types that mirror the file exactly
//! (`deny_unknown_fields`, no `untagged`/`flatten`), the JSON Schema generated from them with
//! each model's `params` schema (from `models`), and the one validation pass
//! ([`check`]: JSON syntax, the schema, then the checks the schema cannot express on
//! the expanded sweep ([`expand`]), every error at once with its JSON path). `campaign::plan`
//! numbers and seeds the points of a valid manifest; it checks nothing of the manifest.

pub mod check;
pub mod expand;
pub mod forms;
pub mod sweep;
pub mod validate;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

pub use crate::models::ModelKind;

/// Manifest format version written into frozen copies; bump on incompatible changes.
pub const MANIFEST_FORMAT: u32 = 1;

/// A campaign manifest: a model, its parameters and a sweep over them.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// Campaign name (letters, digits, `.`, `_`, `-`).
    #[schemars(regex(pattern = r"^[A-Za-z0-9._-]+$"), length(min = 1, max = 128))]
    pub name: String,
    /// Free text describing the campaign (ignored by the engine).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// The simulator.
    pub model: ModelKind,
    /// Campaign seed; every run's seed derives from it and the run's identity.
    pub seed: u64,
    /// Independent runs (seeds) per sweep point (default 1; not with `seeds`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(with = "u32", range(min = 1))]
    pub replicas: Option<u32>,
    /// The runs' seeds, given: each point runs one replica per listed seed (in place of
    /// `replicas`; a run of any campaign's `runs` table can so be run again bit for bit).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(with = "Vec<u64>", length(min = 1))]
    pub seeds: Option<Vec<u64>>,
    /// Model parameters (see the model's parameter schema).
    pub params: Map<String, Value>,
    /// Sweep: dotted paths into `params` -> lists of values. The campaign is the cartesian
    /// product of the lists (first key outermost), times `replicas` seeds per point.
    #[serde(default)]
    #[schemars(with = "std::collections::BTreeMap<String, SweepValues>")]
    pub sweep: Map<String, Value>,
    /// Derived quantities: a name (letters, digits, `_`) -> an expression over the columns of
    /// the model's run tables, computed per run from that run's rows (`derived`: one column
    /// per quantity; `derived_summary`: mean, standard error and n over the replicas), e.g.
    /// `"gamma": "temperature[species=2] / temperature[species=1]"`. See README "Derived
    /// quantities".
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub derived: std::collections::BTreeMap<String, String>,
    /// Error targets on derived quantities: replicas are added in rounds until every target
    /// is met (or `max_replicas`/`max_core_hours` stops it). Not with `replicas` or `seeds`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub target: Vec<Target>,
    /// With `target`: the pilot replicas of every point (default 4, at least 2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(with = "u32", range(min = 2))]
    pub min_replicas: Option<u32>,
    /// With `target`: the most replicas of any point (default 10000).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(with = "u32", range(min = 2))]
    pub max_replicas: Option<u32>,
    /// With `target`: the campaign's budget in estimated core-hours (the models' cost
    /// estimates): no round is started that would exceed it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(with = "f64", range(min = 0.0))]
    pub max_core_hours: Option<f64>,
    /// Names on the figures (`plot`, `report`): a sweep key, a parameter path, a derived
    /// quantity or a column of the model's run tables -> the name its axes, legends and
    /// titles show, e.g. `"species.list.1.mass": "m_2/m_1"` (1 to 60 characters). Over the
    /// models' physics defaults (`m_2`, `ε`, `φ`, ...); like `description`, it changes no run.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    #[schemars(with = "std::collections::BTreeMap<String, LabelText>")]
    pub labels: std::collections::BTreeMap<String, String>,
}

/// An error target on a derived quantity.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Target {
    /// A derived quantity (a key of `derived`).
    pub quantity: String,
    /// Where the target holds: `"t_end"` (the last output time, the default; a quantity
    /// without time: its one value), `{"at": t}` (the output time t), `{"after": t0}` (every
    /// output time at or after t0).
    #[serde(default, skip_serializing_if = "TargetTime::is_end")]
    pub t: TargetTime,
    /// The goal for the standard error of the mean over the replicas, relative to |mean|.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(with = "f64", range(min = 0.0))]
    pub sem_rel: Option<f64>,
    /// The goal for the standard error of the mean, absolute.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(with = "f64", range(min = 0.0))]
    pub sem_abs: Option<f64>,
}

/// Where a target holds.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Copy, Debug, PartialEq, Default)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum TargetTime {
    /// The last output time.
    #[default]
    TEnd,
    /// The output time t.
    At(f64),
    /// Every output time at or after t0.
    After(f64),
}

impl TargetTime {
    pub fn is_end(&self) -> bool {
        matches!(self, TargetTime::TEnd)
    }
}

/// Default pilot replicas of a target campaign.
pub const DEFAULT_MIN_REPLICAS: u32 = 4;
/// Default most replicas per point of a target campaign.
pub const DEFAULT_MAX_REPLICAS: u32 = 10_000;

/// A non-empty list of values for one swept parameter.
#[derive(JsonSchema)]
#[allow(dead_code)]
struct SweepValues(#[schemars(length(min = 1))] Vec<Value>);

/// A figure name given in `labels`.
#[derive(JsonSchema)]
#[allow(dead_code)]
struct LabelText(#[schemars(length(min = 1, max = 60))] String);

impl Manifest {
    /// The runs each point asks for: `replicas` (default 1) or the given `seeds`.
    /// With `target`: `min_replicas` (the pilot), the rounds add more per point.
    pub fn runs_per_point(&self) -> RunsPerPoint {
        match &self.seeds {
            Some(s) => RunsPerPoint::Seeds(s.clone()),
            None if self.has_targets() => RunsPerPoint::Replicas(self.min_replicas()),
            None => RunsPerPoint::Replicas(self.replicas.unwrap_or(1)),
        }
    }

    /// Whether the campaign adds replicas in rounds until its error targets are met.
    pub fn has_targets(&self) -> bool {
        !self.target.is_empty()
    }

    /// The pilot replicas of a target campaign.
    pub fn min_replicas(&self) -> u32 {
        self.min_replicas.unwrap_or(DEFAULT_MIN_REPLICAS)
    }

    /// The most replicas per point of a target campaign.
    pub fn max_replicas(&self) -> u32 {
        self.max_replicas.unwrap_or(DEFAULT_MAX_REPLICAS)
    }

    /// The campaign's identity: what a campaign directory keeps for ever (name, model, seed),
    /// as canonical JSON; every table file carries it.
    pub fn identity(&self) -> String {
        sweep::canonical(&serde_json::json!({
            "name": self.name,
            "model": self.model.as_str(),
            "seed": self.seed,
        }))
    }
}

/// The runs of each point: a number of replicas with derived seeds, or the given seeds.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RunsPerPoint {
    Replicas(u32),
    Seeds(Vec<u64>),
}

/// The manifest's JSON Schema (draft 2020-12), generated from the Rust types: the envelope
/// with `params` typed per model through `if`/`then`.
pub fn json_schema() -> Value {
    let mut generator = schemars::generate::SchemaSettings::draft2020_12().into_generator();
    let root = generator.root_schema_for::<Manifest>();
    let branches: Vec<Value> = ModelKind::ALL
        .iter()
        .map(|m| {
            let params = m.params_subschema(&mut generator).to_value();
            serde_json::json!({
                "if": {"properties": {"model": {"const": m.as_str()}}, "required": ["model"]},
                "then": {"properties": {"params": params}}
            })
        })
        .collect();
    let mut root = root.to_value();
    let defs = generator.take_definitions(true);
    let obj = root.as_object_mut().expect("schema is an object");
    let root_defs = obj
        .entry("$defs")
        .or_insert_with(|| Value::Object(Map::new()));
    for (k, v) in defs {
        root_defs.as_object_mut().expect("$defs").insert(k, v);
    }
    obj.insert("allOf".into(), Value::Array(branches));
    root
}
