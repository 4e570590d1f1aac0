//! The plan: a validated manifest expanded into sweep points and runs with stable ids and
//! seeds.
//!
//! Points are the cartesian product of the sweep lists (first key outermost) and are numbered
//! `point_id = 0..`; each point has `replicas` runs, `run_id = point_id * replicas + replica`.
//! A run's seed derives from the campaign seed and the run's *identity* (model, swept values,
//! replica), not from its position, so it is the same whatever the thread count or shard.

use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha20Rng;
use serde_json::{Map, Value};

use crate::manifest::dsmc::DsmcParams;
use crate::manifest::validate::params_schema_errors;
use crate::manifest::{Manifest, ModelKind};

/// Resolved parameters of one point, typed per model.
#[derive(Clone, Debug, PartialEq)]
pub enum ModelParams {
    Dsmc(DsmcParams),
    Rfm(crate::manifest::rfm::RfmParams),
    Bisection(crate::manifest::aux_models::BisectionParams),
    Cascade(crate::manifest::aux_models::CascadeParams),
    Spm(crate::manifest::aux_models::SpmParams),
}

impl ModelParams {
    /// The params as canonical JSON (the `points` table).
    pub fn to_value(&self) -> Value {
        match self {
            ModelParams::Dsmc(p) => serde_json::to_value(p),
            ModelParams::Rfm(p) => serde_json::to_value(p),
            ModelParams::Bisection(p) => serde_json::to_value(p),
            ModelParams::Cascade(p) => serde_json::to_value(p),
            ModelParams::Spm(p) => serde_json::to_value(p),
        }
        .expect("params serialise")
    }
}

/// Deserialize typed params and run their `check`.
fn typed_as<T: serde::de::DeserializeOwned>(
    params: &Value,
    prefix: &str,
    errors: &mut Vec<(String, String)>,
    check: impl Fn(&T, &str, &mut Vec<(String, String)>),
    wrap: impl Fn(T) -> ModelParams,
) -> Option<ModelParams> {
    match serde_json::from_value::<T>(params.clone()) {
        Ok(p) => {
            check(&p, prefix, errors);
            Some(wrap(p))
        }
        Err(e) => {
            errors.push((prefix.to_string(), e.to_string()));
            None
        }
    }
}

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
        let replica = (run_id % self.replicas as u64) as u32;
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

    pub fn point(&self, point_id: u32) -> &Point {
        &self.points[point_id as usize]
    }

    /// Column name of a swept parameter: its path with `.` replaced by `_`.
    pub fn sweep_column(key: &str) -> String {
        key.replace('.', "_")
    }
}

/// Recursively sorted-key JSON, the canonical form used for identities and comparisons.
pub fn canonical(v: &Value) -> String {
    fn sort(v: &Value) -> Value {
        match v {
            Value::Object(m) => {
                let mut keys: Vec<_> = m.keys().collect();
                keys.sort();
                let mut out = Map::new();
                for k in keys {
                    out.insert(k.clone(), sort(&m[k]));
                }
                Value::Object(out)
            }
            Value::Array(a) => Value::Array(a.iter().map(sort).collect()),
            other => other.clone(),
        }
    }
    sort(v).to_string()
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

fn pointer_escape(key: &str) -> String {
    key.replace('~', "~0").replace('/', "~1")
}

/// Set `params[path]` (dotted) to `value`; the path must already exist.
/// One step of a dotted path: an object key, or an array index when the value is an array
/// (`species.list.0.count`).
fn step<'v>(cur: &'v Value, part: &str) -> Option<&'v Value> {
    match cur {
        Value::Object(o) => o.get(part),
        Value::Array(a) => part.parse::<usize>().ok().and_then(|i| a.get(i)),
        _ => None,
    }
}

fn step_mut<'v>(cur: &'v mut Value, part: &str) -> Option<&'v mut Value> {
    match cur {
        Value::Object(o) => o.get_mut(part),
        Value::Array(a) => part.parse::<usize>().ok().and_then(move |i| a.get_mut(i)),
        _ => None,
    }
}

fn set_path(params: &mut Value, path: &[&str], value: Value) -> bool {
    let mut cur = params;
    for (i, part) in path.iter().enumerate() {
        let Some(next) = step_mut(cur, part) else {
            return false;
        };
        if i + 1 == path.len() {
            *next = value;
            return true;
        }
        cur = next;
    }
    false
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
    match model {
        ModelKind::Dsmc => match serde_json::from_value::<DsmcParams>(params.clone()) {
            Ok(p) => {
                p.check(prefix, errors);
                Some(ModelParams::Dsmc(p))
            }
            Err(e) => {
                errors.push((prefix.to_string(), e.to_string()));
                None
            }
        },
        ModelKind::Rfm => {
            match serde_json::from_value::<crate::manifest::rfm::RfmParams>(params.clone()) {
                Ok(p) => {
                    p.check(prefix, errors);
                    Some(ModelParams::Rfm(p))
                }
                Err(e) => {
                    errors.push((prefix.to_string(), e.to_string()));
                    None
                }
            }
        }
        ModelKind::Bisection => typed_as(
            params,
            prefix,
            errors,
            crate::manifest::aux_models::BisectionParams::check,
            ModelParams::Bisection,
        ),
        ModelKind::Cascade => typed_as(
            params,
            prefix,
            errors,
            crate::manifest::aux_models::CascadeParams::check,
            ModelParams::Cascade,
        ),
        ModelKind::Spm => typed_as(
            params,
            prefix,
            errors,
            crate::manifest::aux_models::SpmParams::check,
            ModelParams::Spm,
        ),
    }
}

fn path_exists(base: &Value, parts: &[&str]) -> bool {
    let mut cur = base;
    for part in parts {
        match step(cur, part) {
            Some(next) => cur = next,
            None => return false,
        }
    }
    !parts.is_empty()
}

/// Checks of the sweep's keys and lists that need no typed params: paths exist in `params`,
/// no path inside another, lists non-empty, no duplicate values. Runs even when the schema
/// check failed, so these errors are reported together with the others.
pub fn sweep_key_errors(params: &Value, sweep: &Map<String, Value>) -> Vec<(String, String)> {
    let mut errors = Vec::new();
    for (key, list) in sweep {
        let kp = format!("/sweep/{}", pointer_escape(key));
        let parts: Vec<&str> = key.split('.').collect();
        if key.is_empty() || !path_exists(params, &parts) {
            errors.push((kp.clone(), format!("sweep path {key:?} does not exist in params (expected a dotted path to a value given in params, e.g. \"restitution.constant\" or \"species.list.0.count\")")));
        }
        for other in sweep.keys() {
            if other != key && other.starts_with(&format!("{key}.")) {
                errors.push((
                    kp.clone(),
                    format!("sweep paths {key:?} and {other:?} overlap"),
                ));
            }
        }
        let Some(list) = list.as_array() else {
            continue;
        };
        if list.is_empty() {
            errors.push((kp.clone(), "expected a non-empty list of values".into()));
        }
        let canon: Vec<String> = list.iter().map(canonical).collect();
        for i in 0..canon.len() {
            if canon[..i].contains(&canon[i]) {
                errors.push((
                    format!("{kp}/{i}"),
                    format!(
                        "duplicate sweep value {} (would make duplicate points)",
                        canon[i]
                    ),
                ));
            }
        }
    }
    errors
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
    use crate::manifest::parse_manifest;

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
        let (_, a) =
            parse_manifest(&manifest(r#"{"restitution.constant": [0.5, 0.9]}"#), "a").unwrap();
        let (_, b) = parse_manifest(
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
        let (_, p) = parse_manifest(
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
        assert_eq!(d.method, crate::manifest::dsmc::DsmcMethod::Bird);
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
