//! The allowed forms of a value with alternatives (a `oneOf`/`anyOf` of the generated schema),
//! each as an example made from the schema itself, so that a message naming them cannot drift
//! from what is accepted: `0.8 is not one of the allowed forms: {"constant": 0.8},
//! {"viscoelastic": {"A": 1.0, ...}}`.

use serde_json::{Map, Value};

/// The alternatives of the `oneOf`/`anyOf` at `keyword_path` (an error's schema path, through
/// `$ref`s, ending in `/oneOf` or `/anyOf`) of `root`.
pub fn alternatives_at<'a>(root: &'a Value, keyword_path: &str) -> Option<&'a Vec<Value>> {
    let mut node = root;
    for seg in keyword_path.split('/').skip(1) {
        let seg = seg.replace("~1", "/").replace("~0", "~");
        if seg == "$ref" {
            let target = node.get("$ref")?.as_str()?.strip_prefix('#')?;
            node = root.pointer(target)?;
            continue;
        }
        node = match node {
            Value::Object(m) => m.get(&seg)?,
            Value::Array(a) => a.get(seg.parse::<usize>().ok()?)?,
            _ => return None,
        };
    }
    node.as_array()
}

/// `schema` with its `$ref` (a local `#/...` pointer) followed, repeatedly.
pub fn resolve<'a>(root: &'a Value, mut schema: &'a Value) -> &'a Value {
    for _ in 0..16 {
        match schema
            .get("$ref")
            .and_then(Value::as_str)
            .and_then(|r| r.strip_prefix('#'))
            .and_then(|p| root.pointer(p))
        {
            Some(target) => schema = target,
            None => break,
        }
    }
    schema
}

/// A value of `schema` (its required members only): the given value `got` where `got` fits a
/// number's range (alone or as the one member of a one-key object: `{"constant": 0.8}` for
/// 0.8), otherwise one made from the schema (`const`, the first of an `enum`, a number in
/// range, ...); `null` where the schema says nothing (an open value).
pub fn example(root: &Value, schema: &Value, got: Option<&Value>) -> Value {
    example_at(root, schema, got, 0)
}

fn example_at(root: &Value, schema: &Value, got: Option<&Value>, depth: usize) -> Value {
    let s = resolve(root, schema);
    if depth > 12 {
        return Value::Null;
    }
    if let Some(c) = s.get("const") {
        return c.clone();
    }
    if let Some(first) = s
        .get("enum")
        .and_then(Value::as_array)
        .and_then(|e| e.first())
    {
        return first.clone();
    }
    for key in ["oneOf", "anyOf", "allOf"] {
        if let Some(alts) = s.get(key).and_then(Value::as_array) {
            // The first alternative that is not `null` (an optional member).
            if let Some(a) = alts
                .iter()
                .find(|a| resolve(root, a).get("type") != Some(&Value::from("null")))
            {
                return example_at(root, a, got, depth + 1);
            }
        }
    }
    let ty = match s.get("type") {
        Some(Value::String(t)) => t.as_str(),
        Some(Value::Array(ts)) => ts
            .iter()
            .filter_map(Value::as_str)
            .find(|t| *t != "null")
            .unwrap_or("null"),
        _ if s.get("properties").is_some() => "object",
        _ => "",
    };
    match ty {
        "number" | "integer" => number(s, ty == "integer", got),
        "boolean" => Value::Bool(true),
        "null" => Value::Null,
        "string" => Value::String(string(s)),
        "array" => {
            let item = s
                .get("items")
                .map(|i| example_at(root, i, None, depth + 1))
                .unwrap_or(Value::Null);
            let n = s
                .get("minItems")
                .and_then(Value::as_u64)
                .unwrap_or(1)
                .max(1);
            Value::Array(vec![item; n.min(4) as usize])
        }
        "object" => {
            let props = s.get("properties").and_then(Value::as_object);
            let required: Vec<&str> = s
                .get("required")
                .and_then(Value::as_array)
                .map(|r| r.iter().filter_map(Value::as_str).collect())
                .unwrap_or_default();
            let mut out = Map::new();
            let one = required.len() == 1;
            for key in required {
                let sub = props.and_then(|p| p.get(key)).unwrap_or(&Value::Null);
                // The given number goes into the one member of a one-key object where that
                // member is a number (`{"constant": 0.8}`), nowhere deeper.
                let is_number = matches!(
                    resolve(root, sub).get("type").and_then(Value::as_str),
                    Some("number" | "integer")
                );
                let inner = if one && is_number { got } else { None };
                out.insert(key.to_string(), example_at(root, sub, inner, depth + 1));
            }
            Value::Object(out)
        }
        _ => Value::Null,
    }
}

/// A number within the schema's range: `got` where it is one, else 1 or the nearest bound.
fn number(s: &Value, integer: bool, got: Option<&Value>) -> Value {
    let f = |k: &str| s.get(k).and_then(Value::as_f64);
    let (min, max) = (f("minimum"), f("maximum"));
    let (xmin, xmax) = (f("exclusiveMinimum"), f("exclusiveMaximum"));
    let fits = |x: f64| {
        min.is_none_or(|m| x >= m)
            && max.is_none_or(|m| x <= m)
            && xmin.is_none_or(|m| x > m)
            && xmax.is_none_or(|m| x < m)
            && (!integer || x.fract() == 0.0)
    };
    if let Some(g) = got.filter(|g| g.as_f64().is_some_and(fits)) {
        return g.clone();
    }
    let lo = min.or(xmin).unwrap_or(f64::NEG_INFINITY);
    let hi = max.or(xmax).unwrap_or(f64::INFINITY);
    let mut candidates = vec![1.0, 2.0, 0.5, 10.0, 0.0];
    if lo.is_finite() {
        candidates.extend([lo, lo + 1.0, lo.ceil()]);
    }
    if hi.is_finite() {
        candidates.extend([hi, (lo.max(0.0) + hi) / 2.0]);
    }
    let x = candidates.into_iter().find(|&x| fits(x)).unwrap_or(1.0);
    if integer {
        Value::from(x as i64)
    } else {
        Value::from(x)
    }
}

/// A string example: `"..."`, or one of the right length where the schema says one.
fn string(s: &Value) -> String {
    let min = s.get("minLength").and_then(Value::as_u64).unwrap_or(1);
    "x".repeat(min.clamp(1, 8) as usize)
}

/// `v` as compact JSON with `, ` and `: ` (as a person writes it), objects nested deeper than
/// `depth` written `{...}`.
pub fn render(v: &Value, depth: usize) -> String {
    match v {
        Value::Object(m) if depth == 0 && !m.is_empty() => "{...}".into(),
        Value::Object(m) => {
            let inner: Vec<String> = m
                .iter()
                .map(|(k, x)| format!("{}: {}", Value::from(k.as_str()), render(x, depth - 1)))
                .collect();
            format!("{{{}}}", inner.join(", "))
        }
        Value::Array(a) => {
            let inner: Vec<String> = a.iter().map(|x| render(x, depth)).collect();
            format!("[{}]", inner.join(", "))
        }
        other => other.to_string(),
    }
}

/// The allowed forms of `alternatives` as a person reads them: each form's example, written
/// in full where short, else with its inner objects as `{...}`; `null` (an optional member
/// left out) is named as `null`.
pub fn describe(root: &Value, alternatives: &[Value], got: &Value) -> Vec<String> {
    alternatives
        .iter()
        .map(|alt| {
            let ex = example(root, alt, Some(got));
            let full = render(&ex, usize::MAX / 2);
            if full.len() <= 72 {
                return full;
            }
            (1..4)
                .rev()
                .map(|d| render(&ex, d))
                .find(|r| r.len() <= 72)
                .unwrap_or_else(|| render(&ex, 1))
        })
        .collect()
}
