//! `granular upgrade DIR`: upgrade a campaign directory of an earlier format in place.

use std::path::PathBuf;

use super::report_error;
use crate::campaign::upgrade::upgrade;
use crate::exit_codes;

#[derive(clap::Args)]
pub struct Args {
    dir: PathBuf,
}

pub fn run(a: Args) -> i32 {
    match upgrade(&a.dir) {
        Ok(r) if r.from == r.to => {
            outln!("{}: already of format {}", a.dir.display(), r.to);
            exit_codes::OK
        }
        Ok(r) => {
            outln!(
                "{}: upgraded from format {} to {} (logged in upgrade.log)",
                a.dir.display(),
                r.from,
                r.to
            );
            for s in &r.steps {
                outln!("  {s}");
            }
            exit_codes::OK
        }
        Err(e) => report_error(e),
    }
}
