//! The plan: a validated manifest expanded into sweep points and runs with stable ids and
//! seeds; loading a manifest with all three stages of validation ([`load`], [`parse`]).
//!
//! Points are the cartesian product of the sweep lists (first key outermost) and are numbered
//! `point_id = 0..`; each point has `replicas` runs, `run_id = point_id * replicas + replica`.
//! A run's seed derives from the campaign seed and the run's *identity* (model, swept values,
//! replica), not from its position, so it is the same whatever the thread count or shard.

use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha20Rng;
use serde_json::Value;

pub use crate::manifest::sweep::canonical;
use crate::manifest::sweep::{path_exists, pointer_escape, set_path, sweep_key_errors};
use crate::manifest::validate::{self, params_schema_errors};
use crate::manifest::validate::{ManifestError, ManifestErrors};
use crate::manifest::Manifest;
use crate::models::{ModelKind, ModelParams};

#[derive(Clone, Debug)]
pub struct Point {
    pub point_id: u32,
    /// The swept values of this point, one per sweep key (in `Plan::sweep_keys` order).
    pub values: Vec<Value>,
    pub params: ModelParams,
}

#[derive(Clone, Debug)]
pub struct Plan {
    pub model: ModelKind,
    pub campaign_seed: u64,
    pub replicas: u32,
    /// Dotted sweep paths into `params`, in manifest order.
    pub sweep_keys: Vec<String>,
    pub points: Vec<Point>,
}

/// One run of the campaign.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RunSpec {
    pub run_id: u64,
    pub point_id: u32,
    pub replica: u32,
    pub seed: u64,
}

/// A deterministic subset of runs: `index` in 1..=`count`; run r belongs to shard
/// `r % count + 1`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: u32,
    pub count: u32,
}

impl Shard {
    pub const ALL: Shard = Shard { index: 1, count: 1 };

    pub fn parse(s: &str) -> Result<Shard, String> {
        let (a, b) = s
            .split_once('/')
            .ok_or_else(|| format!("expected I/N, got {s:?}"))?;
        let index: u32 = a
            .trim()
            .parse()
            .map_err(|_| format!("expected I/N with integers, got {s:?}"))?;
        let count: u32 = b
            .trim()
            .parse()
            .map_err(|_| format!("expected I/N with integers, got {s:?}"))?;
        if count == 0 || index == 0 || index > count {
            return Err(format!("expected 1 <= I <= N in I/N, got {s:?}"));
        }
        Ok(Shard { index, count })
    }

    pub fn contains(&self, run_id: u64) -> bool {
        run_id % self.count as u64 == (self.index - 1) as u64
    }

    /// A file-name-safe tag, e.g. `s1of4`.
    pub fn tag(&self) -> String {
        format!("s{}of{}", self.index, self.count)
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl Plan {
    pub fn n_runs(&self) -> u64 {
        self.points.len() as u64 * self.replicas as u64
    }

    pub fn run(&self, run_id: u64) -> RunSpec {
        let point_id = (run_id / self.replicas as u64) as u32;
        let replica = self.replica_of(run_id);
        let point = &self.points[point_id as usize];
        RunSpec {
            run_id,
            point_id,
            replica,
            seed: derive_seed(
                self.campaign_seed,
                self.model,
                &self.sweep_keys,
                &point.values,
                replica,
            ),
        }
    }

    /// The model's kinetic-theory tables for these points (none for models without theory).
    pub fn theory_tables(&self) -> Vec<&'static str> {
        let points: Vec<&ModelParams> = self.points.iter().map(|p| &p.params).collect();
        self.model.theory_tables(&points)
    }

    /// The replica number of a run.
    pub fn replica_of(&self, run_id: u64) -> u32 {
        (run_id % self.replicas as u64) as u32
    }

    /// The swept values of a point, `key=value, ...` (empty without a sweep).
    pub fn label(&self, point_id: u32) -> String {
        self.sweep_keys
            .iter()
            .zip(&self.point(point_id).values)
            .map(|(k, v)| format!("{k}={v}"))
            .collect::<Vec<_>>()
            .join(", ")
    }

    pub fn point(&self, point_id: u32) -> &Point {
        &self.points[point_id as usize]
    }

    /// Column name of a swept parameter: its path with `.` replaced by `_`.
    pub fn sweep_column(key: &str) -> String {
        key.replace('.', "_")
    }
}

/// FNV-1a, 64 bit: a stable hash of identity bytes (not for security).
fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf29ce484222325;
    for b in bytes {
        h ^= *b as u64;
        h = h.wrapping_mul(0x100000001b3);
    }
    h
}

/// The run's seed: ChaCha20 keyed by (campaign seed, hash of the run's identity).
pub fn derive_seed(
    campaign_seed: u64,
    model: ModelKind,
    keys: &[String],
    values: &[Value],
    replica: u32,
) -> u64 {
    let mut identity = String::from(model.as_str());
    for (k, v) in keys.iter().zip(values) {
        identity.push('\u{1f}');
        identity.push_str(k);
        identity.push('=');
        identity.push_str(&canonical(v));
    }
    identity.push_str(&format!("\u{1f}replica={replica}"));
    let mut key = [0u8; 32];
    key[..8].copy_from_slice(&campaign_seed.to_le_bytes());
    key[8..16].copy_from_slice(&fnv1a(identity.as_bytes()).to_le_bytes());
    key[16..24].copy_from_slice(b"granular");
    ChaCha20Rng::from_seed(key).next_u64()
}

/// Read and validate a manifest file: JSON syntax, schema, then the expanded sweep.
pub fn load(path: &std::path::Path) -> Result<(Manifest, Plan), ManifestErrors> {
    let file = path.display().to_string();
    let text = validate::read(path)?;
    parse(&text, &file)
}

/// Validate manifest text; `file` names it in errors.
pub fn parse(text: &str, file: &str) -> Result<(Manifest, Plan), ManifestErrors> {
    let manifest = validate::parse(text, file)?;
    match expand(&manifest) {
        Ok(plan) => Ok((manifest, plan)),
        Err(errs) => Err(ManifestErrors::new(
            file,
            errs.into_iter()
                .map(|(path, message)| ManifestError { path, message })
                .collect(),
        )),
    }
}

fn typed(
    model: ModelKind,
    params: &Value,
    prefix: &str,
    errors: &mut Vec<(String, String)>,
) -> Option<ModelParams> {
    let schema_errs = params_schema_errors(model, params, prefix);
    if !schema_errs.is_empty() {
        errors.extend(schema_errs.into_iter().map(|e| (e.path, e.message)));
        return None;
    }
    model.params_from(params, prefix, errors)
}

/// Expand the sweep; every problem is returned as (JSON pointer, message).
pub fn expand(m: &Manifest) -> Result<Plan, Vec<(String, String)>> {
    let mut errors = Vec::new();
    let base = Value::Object(m.params.clone());
    let base_typed = typed(m.model, &base, "/params", &mut errors);

    let keys: Vec<String> = m.sweep.keys().cloned().collect();
    errors.extend(sweep_key_errors(&base, &m.sweep));
    let mut lists: Vec<Vec<Value>> = Vec::new();
    for key in &keys {
        let kp = format!("/sweep/{}", pointer_escape(key));
        let parts: Vec<&str> = key.split('.').collect();
        let ok = path_exists(&base, &parts);
        let list = m.sweep[key].as_array().cloned().unwrap_or_default();
        // Each value alone must make valid params; report at the sweep value.
        if ok && base_typed.is_some() {
            for (i, v) in list.iter().enumerate() {
                let mut p = base.clone();
                set_path(&mut p, &parts, v.clone());
                let mut errs = Vec::new();
                typed(m.model, &p, "/params", &mut errs);
                let at = format!(
                    "/params/{}",
                    parts
                        .iter()
                        .map(|s| pointer_escape(s))
                        .collect::<Vec<_>>()
                        .join("/")
                );
                for (path, msg) in errs {
                    let mapped = match path.strip_prefix(&at) {
                        Some(rest) => format!("{kp}/{i}{rest}"),
                        None => format!("{kp}/{i}"),
                    };
                    let msg = if path.starts_with(&at) {
                        msg
                    } else {
                        format!("with this value, {path}: {msg}")
                    };
                    errors.push((mapped, msg));
                }
            }
        }
        lists.push(list);
    }
    if !errors.is_empty() || base_typed.is_none() {
        return Err(errors);
    }

    // Cartesian product, first key outermost.
    let n_points: usize = lists.iter().map(|l| l.len()).product();
    if n_points as u64 * m.replicas as u64 > u32::MAX as u64 {
        return Err(vec![(
            "/sweep".into(),
            format!(
                "{} runs is more than this version supports",
                n_points as u64 * m.replicas as u64
            ),
        )]);
    }
    let mut points = Vec::with_capacity(n_points);
    for point_id in 0..n_points {
        let mut rem = point_id;
        let mut idx = vec![0usize; lists.len()];
        for (j, l) in lists.iter().enumerate().rev() {
            idx[j] = rem % l.len();
            rem /= l.len();
        }
        let values: Vec<Value> = idx
            .iter()
            .enumerate()
            .map(|(j, &i)| lists[j][i].clone())
            .collect();
        let params = if keys.is_empty() {
            base_typed.clone()
        } else {
            let mut p = base.clone();
            for (key, v) in keys.iter().zip(&values) {
                let parts: Vec<&str> = key.split('.').collect();
                set_path(&mut p, &parts, v.clone());
            }
            let mut errs = Vec::new();
            let t = typed(m.model, &p, "/params", &mut errs);
            for (path, msg) in errs {
                let desc: Vec<String> = keys
                    .iter()
                    .zip(&values)
                    .map(|(k, v)| format!("{k}={v}"))
                    .collect();
                errors.push((path, format!("{msg} (at sweep point {})", desc.join(", "))));
            }
            t
        };
        if let Some(params) = params {
            points.push(Point {
                point_id: point_id as u32,
                values,
                params,
            });
        }
    }
    if !errors.is_empty() {
        return Err(errors);
    }
    Ok(Plan {
        model: m.model,
        campaign_seed: m.seed,
        replicas: m.replicas,
        sweep_keys: keys,
        points,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn manifest(sweep: &str) -> String {
        format!(
            r#"{{"name": "t", "model": "dsmc", "seed": 5, "replicas": 2,
            "params": {{"method": "low_rank", "species": {{"list": [{{"mass": 1, "diameter": 1, "count": 10}}]}},
                       "volume": 100, "restitution": {{"constant": 0.5}}, "t_end": 1}},
            "sweep": {sweep}}}"#
        )
    }

    /// A run's seed depends on its identity (swept values, replica), not on its position: adding
    /// a value to a sweep list leaves the seeds of existing points unchanged.
    #[test]
    fn seeds_follow_identity_not_position() {
        let (_, a) = parse(&manifest(r#"{"restitution.constant": [0.5, 0.9]}"#), "a").unwrap();
        let (_, b) = parse(
            &manifest(r#"{"restitution.constant": [0.1, 0.5, 0.9]}"#),
            "b",
        )
        .unwrap();
        assert_eq!(a.n_runs(), 4);
        assert_eq!(b.n_runs(), 6);
        // eps = 0.5 is point 0 in a, point 1 in b.
        assert_eq!(a.run(0).seed, b.run(2).seed);
        assert_eq!(a.run(1).seed, b.run(3).seed);
        assert_ne!(a.run(0).seed, a.run(1).seed);
        assert_ne!(a.run(0).seed, a.run(2).seed);
    }

    #[test]
    fn product_order_first_key_outermost() {
        let (_, p) = parse(
            &manifest(
                r#"{"method": ["low_rank", "bird"], "restitution.constant": [0.5, 0.9, 1.0]}"#,
            ),
            "m",
        )
        .unwrap();
        assert_eq!(p.points.len(), 6);
        assert_eq!(
            p.points[1].values,
            vec![serde_json::json!("low_rank"), serde_json::json!(0.9)]
        );
        assert_eq!(
            p.points[3].values,
            vec![serde_json::json!("bird"), serde_json::json!(0.5)]
        );
        let ModelParams::Dsmc(d) = &p.points[3].params else {
            panic!("dsmc params")
        };
        assert_eq!(d.method, crate::models::dsmc::params::DsmcMethod::Bird);
    }

    #[test]
    fn shards_partition_the_runs() {
        let parts: Vec<Shard> = (1..=3).map(|i| Shard { index: i, count: 3 }).collect();
        for r in 0..100u64 {
            assert_eq!(parts.iter().filter(|s| s.contains(r)).count(), 1);
        }
        assert!(Shard::parse("0/2").is_err());
        assert!(Shard::parse("3/2").is_err());
        assert_eq!(Shard::parse("2/4").unwrap(), Shard { index: 2, count: 4 });
    }
}
