//! `granular verify DIR`: check every table file and that each committed run is in the
//! runs table exactly once.

use std::path::PathBuf;

use super::report_error;
use crate::campaign::{self, Campaign};
use crate::exit_codes;

#[derive(clap::Args)]
pub struct Args {
    dir: PathBuf,
    /// Check presence and sizes only (no file is read): what `status` and `resume` check
    /// first. The default reads every file and checks its SHA-256.
    #[arg(long)]
    quick: bool,
}

pub fn run(a: Args) -> i32 {
    let c = match Campaign::open(&a.dir) {
        Ok(c) => c,
        Err(e) => return report_error(e),
    };
    let depth = if a.quick {
        campaign::integrity::Depth::Quick
    } else {
        campaign::integrity::Depth::Full
    };
    let t0 = std::time::Instant::now();
    let r = match campaign::verify::verify(&c, depth) {
        Ok(r) => r,
        Err(e) => return report_error(e),
    };
    for (t, files, rows) in &r.tables {
        outln!("{t:<34} {files:>6} files {rows:>12} rows");
    }
    for p in &r.problems {
        eprintln!("error: {p}");
    }
    if r.problems.is_empty() {
        outln!(
            "{}: all table files check out ({} committed files, {} bytes, {} in {:.2} s); {} committed runs{}",
            a.dir.display(),
            r.files_checked,
            r.bytes_checked,
            if a.quick { "sizes checked" } else { "SHA-256 checked" },
            t0.elapsed().as_secs_f64(),
            r.committed_runs,
            if a.quick { "" } else { ", each once in the runs table" }
        );
        exit_codes::OK
    } else {
        eprintln!(
            "{}: {} problem(s); `granular resume {}` heals them (runs whose rows are damaged run again)",
            a.dir.display(),
            r.problems.len(),
            a.dir.display()
        );
        exit_codes::DIRECTORY_REFUSED
    }
}
