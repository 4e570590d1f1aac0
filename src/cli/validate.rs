//! `granular validate MANIFEST`: check a manifest, print every error with its JSON path.

use std::path::PathBuf;

use crate::campaign::resources;
use crate::exit_codes;

#[derive(clap::Args)]
pub struct Args {
    manifest: PathBuf,
}

pub fn run(a: Args) -> i32 {
    match crate::campaign::plan::load(&a.manifest) {
        Ok((m, plan)) => {
            outln!(
                "{}: valid: campaign {:?}, model {}, {} points x {} = {} runs",
                a.manifest.display(),
                m.name,
                m.model.as_str(),
                plan.points.len(),
                plan.runs_per_point_text(),
                plan.n_runs()
            );
            if m.has_targets() {
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
            let theory = crate::campaign::preview::theory_work(
                &plan,
                plan.points.iter().map(|p| p.point_id),
            );
            if let Some(w) = theory.warning() {
                tracing::warn!("{w}");
            }
            // Valid anywhere, but say so if this machine cannot run it (`run` refuses it).
            if let Some(mem) = resources::Memory::of_this_machine() {
                if let Err(why) = resources::check(&plan, mem) {
                    tracing::warn!("not on this machine: {why}");
                }
            }
            exit_codes::OK
        }
        Err(e) => {
            eprint!("{e}");
            exit_codes::INVALID_INPUT
        }
    }
}
