//! `granular verify DIR`: check every table file and that each committed run is in the
//! runs table exactly once.

use std::path::PathBuf;

use super::{fail, report_error};
use crate::campaign::{self, Campaign};
use crate::exit_codes;

#[derive(clap::Args)]
pub struct Args {
    dir: PathBuf,
}

pub fn run(a: Args) -> i32 {
    let c = match Campaign::open(&a.dir) {
        Ok(c) => c,
        Err(e) => return report_error(e),
    };
    let r = match campaign::verify::verify(&c) {
        Ok(r) => r,
        Err(e) => return fail(exit_codes::DIRECTORY_REFUSED, e),
    };
    for (t, files, rows) in &r.tables {
        println!("{t:<34} {files:>6} files {rows:>12} rows");
    }
    for p in &r.problems {
        eprintln!("error: {p}");
    }
    if r.problems.is_empty() {
        println!(
            "{}: all table files check out; {} committed runs, each once in the runs table",
            a.dir.display(),
            r.committed_runs
        );
        exit_codes::OK
    } else {
        eprintln!("{}: {} problem(s)", a.dir.display(), r.problems.len());
        exit_codes::DIRECTORY_REFUSED
    }
}
