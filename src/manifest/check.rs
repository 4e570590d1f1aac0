//! The one validation pass of a manifest: stages 1 and 2 ([`super::validate`]: JSON syntax and
//! the schema), then stage 3 ([`super::expand`]: the checks the schema cannot express, the
//! models' own checks among them), every error at once, each once, with its JSON path.
//! `validate`, `plan`, `run`, `theory`, `submit` and growth all go through [`check`].

use super::expand::{expand, Expansion};
use super::validate::{parse, pruned, ManifestError, ManifestErrors};
use super::Manifest;

/// The one validation pass of a manifest, shared by `validate`, `plan`, `run` and every
/// command that reads a manifest: stages 1 and 2 ([`parse`]), then stage 3 (the checks the
/// schema cannot express, [`super::expand::expand`]); where stage 2 finds errors in `params`,
/// stage 3 runs beside it ([`with_checks_beside`]). Every error at once, each once, with its
/// JSON path; on success the manifest and its sweep expanded into typed points.
pub fn check(text: &str, file: &str) -> Result<(Manifest, Expansion), ManifestErrors> {
    let manifest = parse(text, file).map_err(|e| with_checks_beside(text, e))?;
    let expansion = expand(&manifest).map_err(|errs| ManifestErrors::of_pairs(file, errs))?;
    Ok((manifest, expansion))
}

/// Whether `message` names `key` as a whole word (`t_end (1)`, `` `t_end` ``, `"t_end"`; not
/// `t_end_max`).
fn names_word(message: &str, key: &str) -> bool {
    let ident = |c: char| c.is_ascii_alphanumeric() || c == '_';
    !key.is_empty()
        && message.match_indices(key).any(|(i, _)| {
            !message[..i].chars().next_back().is_some_and(ident)
                && !message[i + key.len()..].chars().next().is_some_and(ident)
        })
}

/// Every error at once: where the schema found errors in `params`, the checks it cannot
/// express (cross-field rules, sweep values, limits, the model's checks) run on the manifest
/// with the offending members left out (`validate::pruned`), and those of their errors that
/// have nothing to do with a member left out (not at, in or above it, not in a sweep of it,
/// not naming it) are reported beside the schema's. Before, a bad observable hid that
/// `volume` and `number_density` were both given until it was fixed.
fn with_checks_beside(text: &str, e: ManifestErrors) -> ManifestErrors {
    let Some((m, left_out)) = pruned(text, &e.errors) else {
        return e;
    };
    let Err(more) = expand(&m) else {
        return e;
    };
    let related = |path: &str, message: &str| {
        left_out.iter().any(|out| {
            let key = out.rsplit('/').next().unwrap_or(out);
            let swept = path.strip_prefix("/sweep/").map(|k| {
                let k = k.split('/').next().unwrap_or(k);
                format!("/params/{}", k.replace('.', "/"))
            });
            let near = |p: &str| {
                p == out || p.starts_with(&format!("{out}/")) || out.starts_with(&format!("{p}/"))
            };
            near(path)
                || swept.is_some_and(|p| near(&p))
                || names_word(message, key)
                || message.contains(out.as_str())
        })
    };
    let mut errors = e.errors;
    errors.extend(
        more.into_iter()
            .filter(|(path, message)| !related(path, message))
            .map(|(path, message)| ManifestError { path, message }),
    );
    ManifestErrors::new(&e.file, errors)
}
