//! Sweep paths: dotted paths into a manifest's `params` (`"restitution.constant"`,
//! `"species.list.0.count"`), the checks of the sweep's keys and lists that need no typed
//! params, and the canonical JSON text used for identities and comparisons.

use serde_json::{Map, Value};

/// Recursively sorted-key JSON, the canonical form used for identities and comparisons
/// (compact, as `serde_json` writes it: run seeds hash this text, so it never changes).
pub fn canonical(v: &Value) -> String {
    canonical_without(v, &[])
}

/// [`canonical`] of `v` without the top-level keys `skip` (when `v` is an object), written
/// straight into one string: no sorted copy of the value is made, so a point of 10^5 species
/// costs one pass over its text.
pub fn canonical_without(v: &Value, skip: &[&str]) -> String {
    fn write(v: &Value, skip: &[&str], out: &mut Vec<u8>) {
        match v {
            Value::Object(m) => {
                let mut keys: Vec<&String> =
                    m.keys().filter(|k| !skip.contains(&k.as_str())).collect();
                keys.sort();
                out.push(b'{');
                for (i, k) in keys.into_iter().enumerate() {
                    if i > 0 {
                        out.push(b',');
                    }
                    leaf(k, out);
                    out.push(b':');
                    write(&m[k], &[], out);
                }
                out.push(b'}');
            }
            Value::Array(a) => {
                out.push(b'[');
                for (i, x) in a.iter().enumerate() {
                    if i > 0 {
                        out.push(b',');
                    }
                    write(x, &[], out);
                }
                out.push(b']');
            }
            other => leaf(other, out),
        }
    }
    // serde_json's compact writer, as `Value::to_string` uses it.
    fn leaf<T: serde::Serialize + ?Sized>(x: &T, out: &mut Vec<u8>) {
        serde_json::to_writer(out, x).expect("a JSON string or scalar serialises");
    }
    let mut out = Vec::new();
    write(v, skip, &mut out);
    String::from_utf8(out).expect("serde_json writes UTF-8")
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The text of the implementation before `canonical_without` (a sorted copy of the value,
    /// then `to_string`): seeds hash the canonical text, so it must not change by a byte.
    fn canonical_by_copy(v: &Value) -> String {
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

    #[test]
    fn canonical_text_is_that_of_a_sorted_copy() {
        let v: Value = serde_json::from_str(
            r#"{"z": 1, "a": {"y": [3, {"q": null, "b": true}], "x": "t\"e\\x\u00e9\n/"},
                "m": -0.0, "big": 18446744073709551615, "neg": -9223372036854775808,
                "f": 1e308, "g": 5e-324, "h": 0.1, "e": [], "o": {}, "\u0001k": "\u001f"}"#,
        )
        .unwrap();
        assert_eq!(canonical(&v), canonical_by_copy(&v));
        let mut without = v.clone();
        without.as_object_mut().unwrap().remove("a");
        without.as_object_mut().unwrap().remove("z");
        assert_eq!(
            canonical_without(&v, &["a", "z"]),
            canonical_by_copy(&without)
        );
        // Only the top level is filtered.
        let nested: Value = serde_json::from_str(r#"{"a": {"a": 1}, "b": 2}"#).unwrap();
        assert_eq!(canonical_without(&nested, &["b"]), r#"{"a":{"a":1}}"#);
        for s in ["1", "\"x\"", "[1,2]", "null", "true"] {
            let v: Value = serde_json::from_str(s).unwrap();
            assert_eq!(canonical(&v), canonical_by_copy(&v));
        }
    }
}
