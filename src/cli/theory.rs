//! `granular theory MANIFEST --out DIR`: the kinetic-theory tables of a manifest, without
//! simulating.

use std::path::PathBuf;

use super::{fail, failed, report_error};
use crate::campaign::ledger::{ExclusiveLock, Purpose};
use crate::campaign::Campaign;
use crate::exit_codes;

#[derive(clap::Args)]
pub struct Args {
    manifest: PathBuf,
    #[arg(long)]
    out: PathBuf,
}

pub fn run(a: Args) -> i32 {
    // A model without theory is refused before anything is written.
    match crate::campaign::plan::load(&a.manifest) {
        Ok((m, plan)) if plan.theory_tables().is_empty() => {
            return fail(
                exit_codes::INVALID_INPUT,
                format!(
                    "{}: model {} has no kinetic-theory tables",
                    a.manifest.display(),
                    m.model.as_str()
                ),
            )
        }
        Ok(_) => {}
        Err(e) => return report_error(e.into()),
    }
    let c = match Campaign::create_or_open(&a.manifest, &a.out) {
        Ok(c) => c,
        Err(e) => return report_error(e),
    };
    // Written under the exclusive lock, for the campaign as read under it.
    let _lock = match ExclusiveLock::acquire(&c.root, Purpose::Theory) {
        Ok(l) => l,
        Err(e) => return report_error(e.into()),
    };
    let c = match Campaign::open(&c.root) {
        Ok(c) => c,
        Err(e) => return report_error(e),
    };
    match c.write_theory() {
        Ok(()) => {
            outln!(
                "wrote {}/tables/{} ({} points)",
                a.out.display(),
                c.theory_tables().join(", "),
                c.plan.points.len()
            );
            exit_codes::OK
        }
        Err(e) => failed(&e),
    }
}
