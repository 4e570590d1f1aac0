//! `granular compact DIR [--target-size SIZE]`: merge small Parquet parts into large files
//! and fold the ledger.

use std::path::PathBuf;

use super::{flags, report_error};
use crate::campaign::{self, Campaign};
use crate::exit_codes;

#[derive(clap::Args)]
pub struct Args {
    dir: PathBuf,
    /// Size of a merged file, e.g. 100MB, 1GB, 500kB (1 B to 1 TiB).
    #[arg(long, value_name = "SIZE", default_value = "100MB", allow_hyphen_values = true,
          value_parser = flags::size)]
    target_size: u64,
}

pub fn run(a: Args) -> i32 {
    let c = match Campaign::open(&a.dir) {
        Ok(c) => c,
        Err(e) => return report_error(e),
    };
    let opts = campaign::compact::CompactOptions {
        target_bytes: a.target_size,
    };
    let r = match campaign::compact::compact(&c, &opts) {
        Ok(r) => r,
        Err(e) => return report_error(e),
    };
    for n in &r.notes {
        tracing::warn!("{n}");
    }
    for t in &r.tables {
        outln!(
            "{:<34} {:>6} -> {:>4} files  {:>10} rows  {:>12} -> {:>12} bytes  generation {}",
            t.table,
            t.files_before,
            t.files_after,
            t.rows,
            t.bytes_before,
            t.bytes_after,
            t.generation
        );
    }
    outln!(
        "ledger: {} commit record(s) folded into ledger/index.json",
        r.commits_folded
    );
    exit_codes::OK
}
