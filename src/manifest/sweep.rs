//! Sweep paths: dotted paths into a manifest's `params` (`"restitution.constant"`,
//! `"species.list.0.count"`), the checks of the sweep's keys and lists that need no typed
//! params, and the canonical JSON text used for identities and comparisons.

use serde_json::{Map, Value};

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

/// A key as one JSON-pointer token (`~` -> `~0`, `/` -> `~1`).
pub fn pointer_escape(key: &str) -> String {
    key.replace('~', "~0").replace('/', "~1")
}

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

/// Set `params[path]` (dotted) to `value`; the path must already exist.
pub fn set_path(params: &mut Value, path: &[&str], value: Value) -> bool {
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

pub fn path_exists(base: &Value, parts: &[&str]) -> bool {
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
        let mut seen = std::collections::HashSet::with_capacity(canon.len());
        for i in 0..canon.len() {
            if !seen.insert(&canon[i]) {
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
