//! `granular validate MANIFEST`: check a manifest, print every error with its JSON path
//! (`--json`: one JSON object on stdout, for programs).

use std::path::PathBuf;

use serde_json::{json, Value};

use crate::campaign::resources;
use crate::exit_codes;
use crate::manifest::validate::ManifestErrors;

#[derive(clap::Args)]
pub struct Args {
    manifest: PathBuf,
    /// Print one JSON object on stdout instead of text: {"file", "valid", "errors": [{"path",
    /// "message"}], "warnings": [...]} and, when valid, "campaign": {"name", "model",
    /// "points", "runs"}. Exit codes as without it.
    #[arg(long)]
    json: bool,
}

pub fn run(a: Args) -> i32 {
    let file = a.manifest.display().to_string();
    match crate::campaign::plan::load(&a.manifest) {
        Ok((m, plan)) => {
            if !a.json {
                outln!(
                    "{file}: valid: campaign {:?}, model {}, {} points x {} = {} runs",
                    m.name,
                    m.model.as_str(),
                    plan.points.len(),
                    plan.runs_per_point_text(),
                    plan.n_runs()
                );
            }
            if m.has_targets() && !a.json {
                outln!(
                    "  error targets: {}; the {} replicas per point are the pilot, more are added in rounds until every target is met (at most {} per point{})",
                    m.target
                        .iter()
                        .map(crate::campaign::targets::describe)
                        .collect::<Vec<_>>()
                        .join("; "),
                    m.min_replicas(),
                    m.max_replicas(),
                    m.max_core_hours
                        .map_or(String::new(), |h| format!(", {h} core-hours in all"))
                );
            }
            let mut warnings = Vec::new();
            let theory = crate::campaign::preview::theory_work(
                &plan,
                plan.points.iter().map(|p| p.point_id),
            );
            if let Some(w) = theory.warning() {
                tracing::warn!("{w}");
                warnings.push(w);
            }
            // Valid anywhere, but say so if this machine cannot run it (`run` refuses it).
            if let Some(mem) = resources::Memory::of_this_machine() {
                if let Err(why) = resources::check(&plan, mem) {
                    let w = format!("not on this machine: {why}");
                    tracing::warn!("{w}");
                    warnings.push(w);
                }
            }
            if a.json {
                print_json(&json!({
                    "file": file,
                    "valid": true,
                    "errors": [],
                    "warnings": warnings,
                    "campaign": {
                        "name": m.name,
                        "model": m.model.as_str(),
                        "points": plan.points.len(),
                        "runs": plan.n_runs(),
                    },
                }));
            }
            exit_codes::OK
        }
        Err(e) => {
            if a.json {
                print_json(&invalid_json(&e));
            } else {
                eprint!("{e}");
            }
            exit_codes::INVALID_INPUT
        }
    }
}

/// The JSON of an invalid manifest: every error with its JSON pointer ("/" for the manifest
/// as a whole, as the text says).
fn invalid_json(e: &ManifestErrors) -> Value {
    let errors: Vec<Value> = e
        .errors
        .iter()
        .map(|x| {
            let path = if x.path.is_empty() { "/" } else { &x.path };
            json!({"path": path, "message": x.message})
        })
        .collect();
    json!({"file": e.file, "valid": false, "errors": errors, "warnings": []})
}

fn print_json(v: &Value) {
    outln!("{v}");
}
