//! The JSON manifest: serde types that mirror the file exactly (`deny_unknown_fields`, no
//! `untagged`/`flatten`), the JSON Schema generated from them, and loading with validation
//! that reports every error at once with its JSON path ([`validate`]).

pub mod aux_models;
pub mod dsmc;
pub mod rfm;
pub mod validate;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

pub use validate::{load_manifest, parse_manifest, ManifestError, ManifestErrors};

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
    /// Independent runs (seeds) per sweep point.
    #[serde(default = "default_replicas")]
    #[schemars(range(min = 1))]
    pub replicas: u32,
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

fn default_replicas() -> u32 {
    1
}

/// The simulators `granular` knows.
#[derive(Serialize, Deserialize, JsonSchema, Clone, Copy, Debug, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ModelKind {
    /// Direct simulation Monte Carlo of a polydisperse granular gas (homogeneous cooling).
    Dsmc,
    /// Soft-sphere molecular dynamics of the Random Force Model (driven granular gas, 1D/2D).
    Rfm,
    /// Multiplicative bisection of [0, 1] (thesis sec. 3.4; spec 3.1).
    Bisection,
    /// Multiplicative cascade on a 2^n x 2^n grid, S(k), D_f, particle placement (ch. 6).
    Cascade,
    /// Single particle model: Q(v, l) and P(v) from a free-path distribution (sec. 5.2-5.3).
    Spm,
}

impl ModelKind {
    pub fn as_str(self) -> &'static str {
        match self {
            ModelKind::Dsmc => "dsmc",
            ModelKind::Rfm => "rfm",
            ModelKind::Bisection => "bisection",
            ModelKind::Cascade => "cascade",
            ModelKind::Spm => "spm",
        }
    }
}

/// The manifest's JSON Schema (draft 2020-12), generated from the Rust types: the envelope
/// with `params` typed per model through `if`/`then`.
pub fn json_schema() -> Value {
    let mut generator = schemars::generate::SchemaSettings::draft2020_12().into_generator();
    let root = generator.root_schema_for::<Manifest>();
    let dsmc_ref = generator.subschema_for::<dsmc::DsmcParams>();
    let rfm_ref = generator.subschema_for::<rfm::RfmParams>();
    let bisection_ref = generator.subschema_for::<aux_models::BisectionParams>();
    let cascade_ref = generator.subschema_for::<aux_models::CascadeParams>();
    let spm_ref = generator.subschema_for::<aux_models::SpmParams>();
    let mut root = root.to_value();
    let defs = generator.take_definitions(true);
    let obj = root.as_object_mut().expect("schema is an object");
    let root_defs = obj
        .entry("$defs")
        .or_insert_with(|| Value::Object(Map::new()));
    for (k, v) in defs {
        root_defs.as_object_mut().expect("$defs").insert(k, v);
    }
    obj.insert(
        "allOf".into(),
        serde_json::json!([
            {
                "if": {"properties": {"model": {"const": "dsmc"}}, "required": ["model"]},
                "then": {"properties": {"params": dsmc_ref.to_value()}}
            },
            {
                "if": {"properties": {"model": {"const": "rfm"}}, "required": ["model"]},
                "then": {"properties": {"params": rfm_ref.to_value()}}
            },
            {
                "if": {"properties": {"model": {"const": "bisection"}}, "required": ["model"]},
                "then": {"properties": {"params": bisection_ref.to_value()}}
            },
            {
                "if": {"properties": {"model": {"const": "cascade"}}, "required": ["model"]},
                "then": {"properties": {"params": cascade_ref.to_value()}}
            },
            {
                "if": {"properties": {"model": {"const": "spm"}}, "required": ["model"]},
                "then": {"properties": {"params": spm_ref.to_value()}}
            }
        ]),
    );
    root
}

/// The schema of one model's `params` object, standalone (with its `$defs`).
pub fn params_schema(model: ModelKind) -> Value {
    let mut generator = schemars::generate::SchemaSettings::draft2020_12().into_generator();
    let root = match model {
        ModelKind::Dsmc => generator.root_schema_for::<dsmc::DsmcParams>(),
        ModelKind::Rfm => generator.root_schema_for::<rfm::RfmParams>(),
        ModelKind::Bisection => generator.root_schema_for::<aux_models::BisectionParams>(),
        ModelKind::Cascade => generator.root_schema_for::<aux_models::CascadeParams>(),
        ModelKind::Spm => generator.root_schema_for::<aux_models::SpmParams>(),
    };
    root.to_value()
}
