//! The third stage of the one validation pass ([`super::validate::check`]): the checks the
//! JSON Schema cannot express, on the typed manifest. The limits of a manifest (points, runs),
//! `replicas` against `seeds`, then each model's own checks (through
//! `ModelKind::params_from`: `Model::check` in the model's home) on the base parameters, on every
//! sweep value alone and on every point of the sweep, every error with its JSON path, each once.
//! Its result, the [`Expansion`], is what `campaign::plan` numbers and seeds.

use std::collections::HashSet;

use serde_json::Value;

use super::sweep::{path_exists, pointer_escape, set_path, sweep_key_errors};
use super::validate::params_schema_errors;
use super::{Manifest, RunsPerPoint};
use crate::models::{ModelKind, ModelParams};

/// A manifest's points in sweep order (first key outermost), typed and checked.
#[derive(Clone, Debug)]
pub struct Expansion {
    /// Dotted sweep paths into `params`, in manifest order.
    pub sweep_keys: Vec<String>,
    pub points: Vec<ModelParams>,
    /// Each point's swept values, as the sweep lists give them.
    pub values: Vec<Vec<Value>>,
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
pub fn expand(m: &Manifest) -> Result<Expansion, Vec<(String, String)>> {
    let mut errors = runs_errors(m);
    let base = Value::Object(m.params.clone());
    let mut base_errors = Vec::new();
    let base_typed = typed(m.model, &base, "/params", &mut base_errors);
    // An error of the base params is reported once, not again with each sweep value.
    let of_base: HashSet<(String, String)> = base_errors.iter().cloned().collect();
    errors.extend(base_errors);

    let keys: Vec<String> = m.sweep.keys().cloned().collect();
    errors.extend(sweep_key_errors(&base, &m.sweep));
    let lists: Vec<Vec<Value>> = keys
        .iter()
        .map(|k| m.sweep[k].as_array().cloned().unwrap_or_default())
        .collect();
    // The size of the campaign, from the list lengths: nothing is expanded beyond the limits,
    // and the values of a sweep too large are not checked one by one.
    let size = size_errors(m, &lists);
    let too_large = !size.is_empty();
    errors.extend(size);
    if base_typed.is_some() && !too_large {
        for (key, list) in keys.iter().zip(&lists) {
            errors.extend(sweep_value_errors(m, &base, key, list, &of_base));
        }
    }
    let Some(base_typed) = base_typed.filter(|_| errors.is_empty()) else {
        return Err(errors);
    };
    let (points, swept) = cartesian_product(m, &base, base_typed, &keys, &lists, &mut errors);
    if !errors.is_empty() {
        return Err(errors);
    }
    Ok(Expansion {
        sweep_keys: keys,
        points,
        values: swept,
    })
}

/// The sweep values of `key` each checked alone on the base params (the key's path must exist
/// there), every error reported at the sweep value, less those of the base params (`of_base`).
fn sweep_value_errors(
    m: &Manifest,
    base: &Value,
    key: &str,
    list: &[Value],
    of_base: &HashSet<(String, String)>,
) -> Vec<(String, String)> {
    let mut errors = Vec::new();
    let kp = format!("/sweep/{}", pointer_escape(key));
    let parts: Vec<&str> = key.split('.').collect();
    if !path_exists(base, &parts) {
        return errors;
    }
    // Each value alone must make valid params; report at the sweep value.
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
            if of_base.contains(&(path.clone(), msg.clone())) {
                continue;
            }
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
    errors
}

/// The cartesian product of the sweep `lists`, first key outermost: each point's typed params
/// and swept values (the base params alone when nothing is swept). A point whose params do not
/// check is left out, its errors pushed to `errors` with the point named.
fn cartesian_product(
    m: &Manifest,
    base: &Value,
    base_typed: ModelParams,
    keys: &[String],
    lists: &[Vec<Value>],
    errors: &mut Vec<(String, String)>,
) -> (Vec<ModelParams>, Vec<Vec<Value>>) {
    let n_points: usize = lists.iter().map(|l| l.len()).product();
    let mut points = Vec::with_capacity(n_points);
    let mut swept = Vec::with_capacity(n_points);
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
            Some(base_typed.clone())
        } else {
            point_params(m, base, keys, &values, errors)
        };
        if let Some(params) = params {
            points.push(params);
            swept.push(values);
        }
    }
    (points, swept)
}

/// The typed params of one sweep point (the base params with the point's `values` set at the
/// `keys`), or `None` with its errors pushed to `errors`, each naming the point.
fn point_params(
    m: &Manifest,
    base: &Value,
    keys: &[String],
    values: &[Value],
    errors: &mut Vec<(String, String)>,
) -> Option<ModelParams> {
    let mut p = base.clone();
    for (key, v) in keys.iter().zip(values) {
        let parts: Vec<&str> = key.split('.').collect();
        set_path(&mut p, &parts, v.clone());
    }
    let mut errs = Vec::new();
    let t = typed(m.model, &p, "/params", &mut errs);
    for (path, msg) in errs {
        let desc: Vec<String> = keys
            .iter()
            .zip(values)
            .map(|(k, v)| format!("{k}={v}"))
            .collect();
        errors.push((path, format!("{msg} (at sweep point {})", desc.join(", "))));
    }
    t
}

/// Most sweep points a manifest may ask for (the thesis's largest sweep has 154).
pub const MAX_POINTS: u64 = 100_000;

/// Most runs a manifest may ask for (points x replicas or seeds); `scripts/bench-scale.sh`
/// makes 10^5.
pub const MAX_RUNS: u64 = 10_000_000;

/// The points (the product of the sweep lists' lengths) and runs (times the replicas or seeds)
/// against [`MAX_POINTS`] and [`MAX_RUNS`], in saturating arithmetic.
fn size_errors(m: &Manifest, lists: &[Vec<Value>]) -> Vec<(String, String)> {
    let mut errors = Vec::new();
    let points = lists
        .iter()
        .fold(1u64, |a, l| a.saturating_mul(l.len() as u64));
    let (per_point, per_at, per_what) = match m.runs_per_point() {
        RunsPerPoint::Replicas(r) => (r as u64, "/replicas", "replicas"),
        RunsPerPoint::Seeds(s) => (s.len() as u64, "/seeds", "seeds"),
    };
    let product = || {
        lists
            .iter()
            .map(|l| l.len().to_string())
            .collect::<Vec<_>>()
            .join(" x ")
    };
    if points > MAX_POINTS {
        errors.push((
            "/sweep".into(),
            format!(
                "{points} points ({} values), more than the limit of {MAX_POINTS} points per manifest",
                product()
            ),
        ));
    }
    let runs = points.saturating_mul(per_point);
    if runs > MAX_RUNS {
        errors.push((
            per_at.into(),
            format!(
                "{runs} runs ({points} point{} x {per_point} {per_what}), more than the limit of {MAX_RUNS} runs per manifest",
                if points == 1 { "" } else { "s" }
            ),
        ));
    }
    errors
}

/// `replicas` and `seeds` exclude each other; given seeds are distinct.
fn runs_errors(m: &Manifest) -> Vec<(String, String)> {
    let mut errors = Vec::new();
    if m.replicas.is_some() && m.seeds.is_some() {
        errors.push((
            "/seeds".into(),
            "give `replicas` or `seeds`, not both".into(),
        ));
    }
    if let Some(seeds) = &m.seeds {
        for (i, s) in seeds.iter().enumerate() {
            if seeds[..i].contains(s) {
                errors.push((
                    format!("/seeds/{i}"),
                    format!("duplicate seed {s} (would make the same run twice)"),
                ));
            }
        }
    }
    errors.extend(target_errors(m));
    errors.extend(label_errors(m));
    // The derived quantities' expressions, against the model's run tables.
    if let Err(e) = crate::derived::compile(&m.derived, &m.model.run_tables()) {
        errors.extend(e);
    }
    errors
}

/// The names a key of `labels` may give: the sweep keys (as paths and as their column names),
/// every path into `params` (list indices from 0), the derived quantities and the columns of
/// the model's run tables.
pub fn label_targets(m: &Manifest) -> Vec<String> {
    fn paths(v: &Value, prefix: &str, out: &mut Vec<String>) {
        let children: Vec<(String, &Value)> = match v {
            Value::Object(o) => o.iter().map(|(k, v)| (k.clone(), v)).collect(),
            Value::Array(a) => a
                .iter()
                .enumerate()
                .map(|(i, v)| (i.to_string(), v))
                .collect(),
            _ => return,
        };
        for (k, v) in children {
            let p = if prefix.is_empty() {
                k
            } else {
                format!("{prefix}.{k}")
            };
            out.push(p.clone());
            paths(v, &p, out);
        }
    }
    let mut out: Vec<String> = Vec::new();
    for k in m.sweep.keys() {
        out.push(k.clone());
        out.push(k.replace('.', "_"));
    }
    paths(&Value::Object(m.params.clone()), "", &mut out);
    out.extend(m.derived.keys().cloned());
    for (_, schema) in m.model.run_tables() {
        out.extend(schema.fields().iter().map(|f| f.name().clone()));
    }
    let mut seen = HashSet::new();
    out.retain(|n| seen.insert(n.clone()));
    out
}

/// The edit distance of two names (characters).
fn distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = (prev + usize::from(ca != *cb)).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}

/// Every key of `labels` must name something of the manifest ([`label_targets`]); an unknown
/// key is reported at `/labels/KEY` with the nearest names it could be.
fn label_errors(m: &Manifest) -> Vec<(String, String)> {
    if m.labels.is_empty() {
        return Vec::new();
    }
    let known = label_targets(m);
    let mut errors = Vec::new();
    // A sweep key by its path and by its column name: one name, given once.
    let mut by_column: std::collections::BTreeMap<String, &String> = Default::default();
    for key in m.labels.keys() {
        if let Some(first) = by_column.insert(key.replace('.', "_"), key) {
            errors.push((
                format!("/labels/{}", pointer_escape(key)),
                format!("{key:?} and {first:?} name the same thing (a path and its column name): give one of them"),
            ));
        }
    }
    for key in m.labels.keys() {
        if known.iter().any(|k| k == key) {
            continue;
        }
        let mut near: Vec<(usize, &String)> = known.iter().map(|k| (distance(key, k), k)).collect();
        near.sort();
        let near: Vec<String> = near.iter().take(3).map(|(_, k)| format!("`{k}`")).collect();
        errors.push((
            format!("/labels/{}", pointer_escape(key)),
            format!(
                "{key:?} names nothing of this manifest: expected a sweep key, a path into `params` (list indices from 0), a derived quantity or a column of the model's run tables; nearest: {}",
                if near.is_empty() { "none".to_string() } else { near.join(", ") }
            ),
        ));
    }
    errors
}

/// A derived quantity's name: it becomes column names (`NAME`, `NAME_mean`, ...).
fn valid_derived_name(name: &str) -> bool {
    let mut chars = name.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
        && name.len() <= 64
}

/// `derived` names, `target` against `derived`, the replica bounds and what goes with a
/// target (not `replicas` or `seeds`), `min_replicas`/`max_replicas`/`max_core_hours`
/// only with a target.
fn target_errors(m: &Manifest) -> Vec<(String, String)> {
    let mut errors = Vec::new();
    for name in m.derived.keys() {
        if !valid_derived_name(name) {
            errors.push((
                format!("/derived/{}", super::sweep::pointer_escape(name)),
                format!("derived quantity name {name:?}: expected letters, digits and `_` (not starting with a digit, at most 64 characters)"),
            ));
        }
    }
    if m.target.is_empty() {
        for (key, given) in [
            ("min_replicas", m.min_replicas.is_some()),
            ("max_replicas", m.max_replicas.is_some()),
            ("max_core_hours", m.max_core_hours.is_some()),
        ] {
            if given {
                errors.push((
                    format!("/{key}"),
                    format!("`{key}` goes with `target` (error targets), which this manifest does not have"),
                ));
            }
        }
        return errors;
    }
    for (key, given) in [
        ("replicas", m.replicas.is_some()),
        ("seeds", m.seeds.is_some()),
    ] {
        if given {
            errors.push((
                format!("/{key}"),
                format!("a campaign with `target` decides its replicas (from `min_replicas` up to `max_replicas`); leave out `{key}`"),
            ));
        }
    }
    if m.min_replicas() > m.max_replicas() {
        errors.push((
            "/max_replicas".into(),
            format!(
                "max_replicas {} is below min_replicas {}",
                m.max_replicas(),
                m.min_replicas()
            ),
        ));
    }
    if let Some(h) = m.max_core_hours {
        if !(h.is_finite() && h > 0.0) {
            errors.push((
                "/max_core_hours".into(),
                format!("expected a positive number of core-hours, got {h}"),
            ));
        }
    }
    let mut seen = HashSet::new();
    for (i, t) in m.target.iter().enumerate() {
        let at = |k: &str| format!("/target/{i}/{k}");
        if !m.derived.contains_key(&t.quantity) {
            let known: Vec<&str> = m.derived.keys().map(String::as_str).collect();
            errors.push((
                at("quantity"),
                if known.is_empty() {
                    format!("unknown quantity {:?}: a target is set on a derived quantity, and `derived` declares none", t.quantity)
                } else {
                    format!("unknown quantity {:?}: expected one of the derived quantities {known:?}", t.quantity)
                },
            ));
        }
        if t.sem_rel.is_none() && t.sem_abs.is_none() {
            errors.push((
                format!("/target/{i}"),
                "give the goal: `sem_rel` (standard error relative to |mean|) or `sem_abs` (absolute), or both".into(),
            ));
        }
        for (k, v) in [("sem_rel", t.sem_rel), ("sem_abs", t.sem_abs)] {
            if let Some(v) = v {
                if !(v.is_finite() && v > 0.0) {
                    errors.push((at(k), format!("expected a positive number, got {v}")));
                }
            }
        }
        match t.t {
            crate::manifest::TargetTime::At(x) | crate::manifest::TargetTime::After(x)
                if !x.is_finite() =>
            {
                errors.push((at("t"), format!("expected a finite time, got {x}")));
            }
            _ => {}
        }
        let key = format!("{}\u{1f}{:?}", t.quantity, t.t);
        if !seen.insert(key) {
            errors.push((
                format!("/target/{i}"),
                format!("a second target on {:?} at the same time: give one, with both goals if need be", t.quantity),
            ));
        }
    }
    errors
}
