//! Loading a manifest with every error reported at once, each with its JSON path.
//!
//! Three stages: (1) JSON syntax (a key given twice in one object is an error there: serde_json
//! would keep the last one silently); (2) the generated JSON Schema (unknown keys, types, ranges),
//! where a failed `oneOf` is narrowed to the variant the user evidently meant; (3) checks the
//! schema cannot express (cross-field rules, sweep paths, duplicate points), run on the base
//! parameters, on every sweep value and on every point of the sweep. Where stage 2 finds errors
//! in `params`, stage 3 still runs on the manifest with those members left out ([`pruned`]), and
//! its errors unrelated to them are reported too ([`super::check`], the one pass): every error at
//! once, each once (an error of the base params is not repeated at each sweep value).

use std::fmt;
use std::path::Path;

use jsonschema::error::ValidationErrorKind;
use jsonschema::ValidationError;
use serde_json::Value;

use super::forms;
use super::sweep::sweep_key_errors;
use super::{json_schema, Manifest, ModelKind};

/// One problem in a manifest.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ManifestError {
    /// JSON pointer of the offending value (`/params/restitution/constant`).
    pub path: String,
    pub message: String,
}

/// Every problem found in one manifest file.
#[derive(Debug, Clone)]
pub struct ManifestErrors {
    pub file: String,
    pub errors: Vec<ManifestError>,
}

impl fmt::Display for ManifestErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.errors.len();
        writeln!(
            f,
            "{}: invalid manifest ({n} error{})",
            self.file,
            if n == 1 { "" } else { "s" }
        )?;
        for e in &self.errors {
            let path = if e.path.is_empty() { "/" } else { &e.path };
            writeln!(f, "  at {path}: {}", e.message)?;
        }
        Ok(())
    }
}

impl std::error::Error for ManifestErrors {}

impl ManifestErrors {
    /// The problems of `file`, each reported once.
    pub fn new(file: &str, mut errors: Vec<ManifestError>) -> Self {
        dedup(&mut errors);
        ManifestErrors {
            file: file.to_string(),
            errors,
        }
    }

    /// The problems of `file` given as (JSON pointer, message) pairs, each reported once.
    pub fn of_pairs(file: &str, errors: Vec<(String, String)>) -> Self {
        Self::new(
            file,
            errors
                .into_iter()
                .map(|(path, message)| ManifestError { path, message })
                .collect(),
        )
    }

    /// One problem of the manifest as a whole (no JSON path).
    pub fn whole(file: &str, message: String) -> Self {
        Self::of_pairs(file, vec![(String::new(), message)])
    }
}

/// The largest manifest file read (16 MiB): a manifest is a few kilobytes, a sweep of the
/// largest size allowed (`manifest::expand::MAX_POINTS`) a few megabytes at most.
pub const MAX_MANIFEST_BYTES: u64 = 16 << 20;

/// The text of a manifest file (an unreadable file, one larger than [`MAX_MANIFEST_BYTES`] or
/// one that is not UTF-8 is a manifest error at `/`). At most `MAX_MANIFEST_BYTES + 1` bytes
/// are read, so `/dev/zero` or a huge file is refused at once.
pub fn read(path: &Path) -> Result<String, ManifestErrors> {
    use std::io::Read;
    let fail = |message: String| {
        ManifestErrors::new(
            &path.display().to_string(),
            vec![ManifestError {
                path: String::new(),
                message,
            }],
        )
    };
    let file = std::fs::File::open(path).map_err(|e| fail(format!("cannot read the file: {e}")))?;
    let mut bytes = Vec::new();
    file.take(MAX_MANIFEST_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| fail(format!("cannot read the file: {e}")))?;
    if bytes.len() as u64 > MAX_MANIFEST_BYTES {
        return Err(fail(format!(
            "the file is larger than {} MiB, the limit of a manifest",
            MAX_MANIFEST_BYTES >> 20
        )));
    }
    String::from_utf8(bytes).map_err(|e| {
        fail(format!(
            "not UTF-8 text (invalid byte at offset {})",
            e.utf8_error().valid_up_to()
        ))
    })
}

/// Stages 1 and 2: JSON syntax and the generated schema (with the sweep's key checks, so all
/// are reported together); `file` names the text in errors.
pub fn parse(text: &str, file: &str) -> Result<Manifest, ManifestErrors> {
    let fail = |errors: Vec<ManifestError>| ManifestErrors::new(file, errors);
    // A UTF-8 byte-order mark (some Windows editors write one) is not JSON: skip it.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let value: Value = serde_json::from_str(text).map_err(|e| {
        fail(vec![ManifestError {
            path: String::new(),
            message: format!(
                "not valid JSON: {e} (line {}, column {})",
                e.line(),
                e.column()
            ),
        }])
    })?;
    let duplicates = duplicate_keys(text);
    if !duplicates.is_empty() {
        return Err(fail(duplicates));
    }
    let mut errors = manifest_schema_errors(&value);
    if !errors.is_empty() {
        if let (Some(params), Some(sweep)) = (
            value.get("params"),
            value.get("sweep").and_then(|s| s.as_object()),
        ) {
            let more = sweep_key_errors(params, sweep);
            errors.extend(
                more.into_iter()
                    .map(|(path, message)| ManifestError { path, message }),
            );
        }
        return Err(fail(errors));
    }
    // The schema takes 42.0 for an integer (JSON Schema does), and so does granular: a number
    // is its value (`envelope_by_value`); serde's errors say where.
    crate::models::from_value_at(envelope_by_value(value), "")
        .map_err(|(path, message)| fail(vec![ManifestError { path, message }]))
}

/// `value` (a manifest) with its whole numbers written as integers
/// ([`crate::models::numbers_by_value`]: `"seed": 42.0` is 42), except in `params` and `sweep`,
/// which are kept as written (the campaign's copy of the manifest; the models read each
/// number of them by value).
fn envelope_by_value(mut value: Value) -> Value {
    if let Value::Object(m) = &mut value {
        for (k, v) in m.iter_mut() {
            if k != "params" && k != "sweep" {
                *v = crate::models::numbers_by_value(std::mem::take(v));
            }
        }
    }
    value
}

/// The manifest of `text` (valid JSON) with the members of `params` that `errors` (the schema's)
/// (or `labels`) point into left out, so that the checks the schema cannot express can still run beside its
/// errors ("every error at once"), and the JSON pointers of the members left out. A member of
/// `params` that the schema requires (missing, or left out here) is put back as a stand-in made
/// from the schema ([`stand_in`]) and counted as left out, so the errors of its absence are the
/// schema's alone. `None` where that cannot be: an error outside `params` and `labels`, a
/// required member deeper than `params` itself. At most [`PRUNE_ROUNDS`] rounds of leaving out
/// and checking the schema again.
pub fn pruned(text: &str, errors: &[ManifestError]) -> Option<(Manifest, Vec<String>)> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut value: Value = serde_json::from_str(text).ok()?;
    let mut left_out: Vec<String> = Vec::new();
    let mut errors = errors.to_vec();
    let (schema, _) = manifest_validator();
    for _ in 0..PRUNE_ROUNDS {
        for e in &errors {
            if let Some(key) = required_key(&e.message).filter(|_| e.path == "/params") {
                let member = format!("/params/{}", key.replace('~', "~0").replace('/', "~1"));
                let stand_in = stand_in(schema, &value, &key)?;
                value
                    .pointer_mut("/params")?
                    .as_object_mut()?
                    .insert(key, stand_in);
                if !left_out.contains(&member) {
                    left_out.push(member);
                }
                continue;
            }
            let member = member_of(&value, &e.path)?;
            // A bad name in `labels` is left out like a bad member of `params`.
            if !member.starts_with("/params/") && !member.starts_with("/labels/") {
                return None;
            }
            if value.pointer(&member).is_some() {
                remove_at(&mut value, &member)?;
                left_out.push(member);
            }
        }
        errors = manifest_schema_errors(&value);
        if errors.is_empty() {
            let m = crate::models::from_value_at(envelope_by_value(value), "").ok()?;
            return Some((m, left_out));
        }
    }
    None
}

/// The key of a schema error `"KEY" is a required property`.
fn required_key(message: &str) -> Option<String> {
    let quoted = message.strip_suffix(" is a required property")?;
    serde_json::from_str::<String>(quoted).ok()
}

/// A value for the required member `key` of the manifest's `params`, made from the model's
/// params schema ([`forms::example`]: its required members only, numbers in range), so that
/// the checks the schema cannot express run on the rest; `None` for an unknown model or key.
fn stand_in(schema: &Value, manifest: &Value, key: &str) -> Option<Value> {
    let model = manifest.get("model")?.as_str()?;
    let branch = schema.get("allOf")?.as_array()?.iter().find(|b| {
        b.pointer("/if/properties/model/const")
            .and_then(Value::as_str)
            == Some(model)
    })?;
    let params = forms::resolve(schema, branch.pointer("/then/properties/params")?);
    let member = params.get("properties")?.get(key)?;
    Some(forms::example(schema, member, None))
}

/// How many times [`pruned`] leaves members out and checks again.
const PRUNE_ROUNDS: usize = 4;

/// The pointer of the object member that `path` is or lies in (an array element is left out
/// with its whole array: indices of the others stay as the user wrote them).
fn member_of(value: &Value, path: &str) -> Option<String> {
    let segments: Vec<&str> = path.split('/').skip(1).collect();
    for end in (1..=segments.len()).rev() {
        let parent = if end == 1 {
            String::new()
        } else {
            format!("/{}", segments[..end - 1].join("/"))
        };
        if value.pointer(&parent).is_some_and(Value::is_object) {
            return Some(format!("/{}", segments[..end].join("/")));
        }
    }
    None
}

/// Remove the object member at `pointer`.
fn remove_at(value: &mut Value, pointer: &str) -> Option<()> {
    let (parent, key) = pointer.rsplit_once('/')?;
    let key = key.replace("~1", "/").replace("~0", "~");
    value.pointer_mut(parent)?.as_object_mut()?.remove(&key)?;
    Some(())
}

/// Every key given more than once in one object of `text` (valid JSON), as an error at the
/// object's JSON pointer (`at /params/restitution: duplicate key "constant"`), in document
/// order (each (object, key) once: [`ManifestErrors::new`]). A second pass over the text with serde_json's streaming
/// deserializer (its recursion limit included) that keeps only the keys of the objects open.
fn duplicate_keys(text: &str) -> Vec<ManifestError> {
    let mut scan = KeyScan {
        path: String::new(),
        found: Vec::new(),
    };
    let mut de = serde_json::Deserializer::from_str(text);
    // The text parsed as a `Value` already: this pass cannot fail on its syntax.
    if serde::de::DeserializeSeed::deserialize(&mut scan, &mut de).is_err() {
        return Vec::new();
    }
    scan.found
}

/// The state of [`duplicate_keys`]: the JSON pointer of the value being read, what was found.
struct KeyScan {
    path: String,
    found: Vec<ManifestError>,
}

impl<'de> serde::de::DeserializeSeed<'de> for &mut KeyScan {
    type Value = ();

    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> serde::de::Visitor<'de> for &mut KeyScan {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("any JSON value")
    }

    fn visit_bool<E>(self, _: bool) -> Result<(), E> {
        Ok(())
    }

    fn visit_i64<E>(self, _: i64) -> Result<(), E> {
        Ok(())
    }

    fn visit_u64<E>(self, _: u64) -> Result<(), E> {
        Ok(())
    }

    fn visit_f64<E>(self, _: f64) -> Result<(), E> {
        Ok(())
    }

    fn visit_str<E>(self, _: &str) -> Result<(), E> {
        Ok(())
    }

    fn visit_unit<E>(self) -> Result<(), E> {
        Ok(())
    }

    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let len = self.path.len();
        let mut i = 0usize;
        loop {
            use std::fmt::Write;
            let _ = write!(self.path, "/{i}");
            let more = seq.next_element_seed(&mut *self)?.is_some();
            self.path.truncate(len);
            if !more {
                return Ok(());
            }
            i += 1;
        }
    }

    fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        let len = self.path.len();
        let mut keys = std::collections::HashSet::new();
        while let Some(key) = map.next_key::<String>()? {
            self.path.push('/');
            self.path.push_str(&super::sweep::pointer_escape(&key));
            map.next_value_seed(&mut *self)?;
            self.path.truncate(len);
            if keys.contains(&key) {
                self.found.push(ManifestError {
                    path: self.path.clone(),
                    message: format!("duplicate key {key:?} (a key may appear once in an object)"),
                });
            } else {
                keys.insert(key);
            }
        }
        Ok(())
    }
}

/// Validate a model's params object (after sweep substitution) against its schema; paths are
/// prefixed with `prefix`.
pub fn params_schema_errors(model: ModelKind, params: &Value, prefix: &str) -> Vec<ManifestError> {
    thread_local! {
        static VALIDATORS: std::cell::RefCell<Vec<(ModelKind, jsonschema::Validator, Value)>> = const { std::cell::RefCell::new(Vec::new()) };
    }
    VALIDATORS.with(|cell| {
        let mut cache = cell.borrow_mut();
        if !cache.iter().any(|(m, ..)| *m == model) {
            let schema = model.params_schema();
            let v = jsonschema::validator_for(&schema).expect("generated schema compiles");
            cache.push((model, v, schema));
        }
        let (_, validator, schema) = cache.iter().find(|(m, ..)| *m == model).expect("cached");
        collect(validator.iter_errors(params), prefix, schema)
    })
}

/// The manifest's JSON Schema ([`json_schema`]) and its compiled validator, made once per
/// process: generating and compiling it took a few milliseconds, and `granular run` parses
/// its manifest more than once (`campaign::plan::parse`, `Campaign::open`).
fn manifest_validator() -> &'static (Value, jsonschema::Validator) {
    static VALIDATOR: std::sync::OnceLock<(Value, jsonschema::Validator)> =
        std::sync::OnceLock::new();
    VALIDATOR.get_or_init(|| {
        let schema = json_schema();
        let validator = jsonschema::validator_for(&schema).expect("generated schema compiles");
        (schema, validator)
    })
}

/// [`schema_errors`] of `instance` against the manifest's schema, with the validator made once.
fn manifest_schema_errors(instance: &Value) -> Vec<ManifestError> {
    let (schema, validator) = manifest_validator();
    collect(validator.iter_errors(instance), "", schema)
}

/// The errors of `instance` against `schema` (a whole schema: its `$defs` resolve), each
/// explained as in a manifest's errors, paths prefixed with `prefix`.
pub fn schema_errors(schema: &Value, instance: &Value, prefix: &str) -> Vec<ManifestError> {
    let validator = jsonschema::validator_for(schema).expect("generated schema compiles");
    collect(validator.iter_errors(instance), prefix, schema)
}

fn collect<'a>(
    iter: impl Iterator<Item = ValidationError<'a>>,
    prefix: &str,
    root: &Value,
) -> Vec<ManifestError> {
    let mut out = Vec::new();
    for e in iter {
        explain(&e, prefix, root, &mut out);
    }
    dedup(&mut out);
    out
}

fn dedup(errors: &mut Vec<ManifestError>) {
    let mut seen = std::collections::HashSet::new();
    errors.retain(|e| seen.insert((e.path.clone(), e.message.clone())));
}

/// Turn one schema error into messages; a failed `oneOf` is narrowed to the variant whose tag
/// the instance carries, so `{"constant": 2}` reports the range, not "no variant matched";
/// where none is evidently meant, the message names every allowed form with an example made
/// from the schema (`root`, that of the validator: [`super::forms`]).
fn explain(e: &ValidationError<'_>, prefix: &str, root: &Value, out: &mut Vec<ManifestError>) {
    let path = format!("{prefix}{}", e.instance_path().as_str());
    match e.kind() {
        ValidationErrorKind::OneOfNotValid { context } | ValidationErrorKind::AnyOf { context } => {
            let here = e.instance_path().as_str();
            // A variant "matches the tag" when it has no complaint about the value's kind
            // (a missing tag key / wrong type / const / enum) at this very location; its other
            // errors (unknown keys, ranges, nested problems) are the ones to report.
            let shape_error = |errs: &Vec<ValidationError<'static>>| {
                errs.iter().any(|x| {
                    x.instance_path().as_str() == here
                        && matches!(
                            x.kind(),
                            ValidationErrorKind::Required { .. }
                                | ValidationErrorKind::Type { .. }
                                | ValidationErrorKind::Constant { .. }
                                | ValidationErrorKind::Enum { .. }
                        )
                })
            };
            let candidates: Vec<_> = context.iter().filter(|errs| !shape_error(errs)).collect();
            if candidates.len() == 1 {
                for x in candidates[0] {
                    explain(x, prefix, root, out);
                }
                return;
            }
            let got = short(e.instance());
            if let Some(alternatives) = forms::alternatives_at(root, e.schema_path().as_str()) {
                let forms = forms::describe(root, alternatives, e.instance());
                let all_constants = alternatives
                    .iter()
                    .all(|a| a.get("const").is_some() || a.get("enum").is_some());
                let message = if all_constants {
                    format!("expected {}, got {got}", forms.join(" or "))
                } else {
                    format!(
                        "{got} is not one of the allowed forms: {}",
                        forms.join(", ")
                    )
                };
                out.push(ManifestError { path, message });
                return;
            }
            let mut options = Vec::new();
            for errs in context {
                for x in errs {
                    if x.instance_path().as_str() != here {
                        continue;
                    }
                    match x.kind() {
                        ValidationErrorKind::Required { property } => {
                            options.push(format!("an object {{{property}: ...}}"))
                        }
                        ValidationErrorKind::Constant { expected_value } => {
                            options.push(expected_value.to_string())
                        }
                        ValidationErrorKind::Enum { options: o } => {
                            if let Some(list) = o.as_array() {
                                options.extend(list.iter().map(|v| v.to_string()));
                            }
                        }
                        _ => {}
                    }
                }
            }
            options.dedup();
            let message = if options.is_empty() {
                format!("{got} matches none of the allowed forms")
            } else {
                format!("expected {}, got {got}", options.join(" or "))
            };
            out.push(ManifestError { path, message });
        }
        ValidationErrorKind::AdditionalProperties { unexpected } => {
            for key in unexpected {
                out.push(ManifestError {
                    path: format!("{path}/{}", key.replace('~', "~0").replace('/', "~1")),
                    message: format!("unknown key {key:?}"),
                });
            }
        }
        _ => out.push(ManifestError {
            path,
            message: e.to_string(),
        }),
    }
}

fn short(v: &Value) -> String {
    let s = v.to_string();
    if s.len() > 80 {
        format!("{}...", &s[..77])
    } else {
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Duplicates at their object's pointer (escaped: `~0`, `~1`), inside arrays, each (object,
    /// key) once after `ManifestErrors::new`; equal keys in different objects are no duplicate.
    #[test]
    fn duplicate_keys_at_their_objects() {
        let text = r#"{"a": 1, "x/y~z": {"k": [{"q": 1, "q": 2, "q": 3}], "k": 2},
                       "b": {"a": 1}, "a": [2]}"#;
        let found = ManifestErrors::new("m", duplicate_keys(text)).errors;
        let got: Vec<(&str, &str)> = found
            .iter()
            .map(|e| (e.path.as_str(), e.message.as_str()))
            .collect();
        let msg = |k: &str| format!("duplicate key {k:?} (a key may appear once in an object)");
        let (q, k, a) = (msg("q"), msg("k"), msg("a"));
        assert_eq!(
            got,
            vec![
                ("/x~1y~0z/k/0", q.as_str()),
                ("/x~1y~0z", k.as_str()),
                ("", a.as_str())
            ]
        );
        assert!(duplicate_keys(r#"{"a": {"a": {"a": [1, {"a": 2}]}}}"#).is_empty());
    }
}
