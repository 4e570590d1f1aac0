//! `granular theory MANIFEST --out DIR`: the kinetic-theory tables of a manifest, without
//! simulating.

use std::path::PathBuf;

use super::{fail, report_error};
use crate::campaign::Campaign;
use crate::exit_codes;

#[derive(clap::Args)]
pub struct Args {
    manifest: PathBuf,
    #[arg(long)]
    out: PathBuf,
}

pub fn run(a: Args) -> i32 {
    let c = match Campaign::create_or_open(&a.manifest, &a.out) {
        Ok(c) => c,
        Err(e) => return report_error(e),
    };
    match crate::campaign::writer::write_theory(&c) {
        Ok(()) => {
            println!(
                "wrote {}/tables/dsmc_theory and dsmc_theory_point ({} points)",
                a.out.display(),
                c.plan.points.len()
            );
            exit_codes::OK
        }
        Err(e) => fail(exit_codes::IO_ERROR, e),
    }
}
