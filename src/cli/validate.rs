//! `granular validate MANIFEST`: check a manifest, print every error with its JSON path.

use std::path::PathBuf;

use crate::exit_codes;

#[derive(clap::Args)]
pub struct Args {
    manifest: PathBuf,
}

pub fn run(a: Args) -> i32 {
    match crate::campaign::plan::load(&a.manifest) {
        Ok((m, plan)) => {
            println!(
                "{}: valid: campaign {:?}, model {}, {} points x {} replicas = {} runs",
                a.manifest.display(),
                m.name,
                m.model.as_str(),
                plan.points.len(),
                plan.replicas,
                plan.n_runs()
            );
            exit_codes::OK
        }
        Err(e) => {
            eprint!("{e}");
            exit_codes::INVALID_INPUT
        }
    }
}
