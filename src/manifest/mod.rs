//! The JSON manifest's envelope: serde types that mirror the file exactly
//! (`deny_unknown_fields`, no `untagged`/`flatten`), the JSON Schema generated from them with
//! each model's `params` schema (from `models`), and the one validation pass
//! ([`check`]: JSON syntax, the schema, then the checks the schema cannot express on
//! the expanded sweep ([`expand`]), every error at once with its JSON path). `campaign::plan`
//! numbers and seeds the points of a valid manifest; it checks nothing of the manifest.

pub mod check;
pub mod expand;
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
}

/// A non-empty list of values for one swept parameter.
#[derive(JsonSchema)]
#[allow(dead_code)]
struct SweepValues(#[schemars(length(min = 1))] Vec<Value>);

impl Manifest {
    /// The runs each point asks for: `replicas` (default 1) or the given `seeds`.
    pub fn runs_per_point(&self) -> RunsPerPoint {
        match &self.seeds {
            Some(s) => RunsPerPoint::Seeds(s.clone()),
            None => RunsPerPoint::Replicas(self.replicas.unwrap_or(1)),
        }
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
