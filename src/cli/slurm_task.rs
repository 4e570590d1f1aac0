//! `granular slurm-task DIR --shards N [--index I] [--threads C] [--checkpoint-every S]`
//! (hidden): one SLURM array task, i.e. shard I+1 of N. The array scripts that `submit`
//! writes (`campaign::slurm`) call it, those of earlier submissions included: its flags
//! must keep parsing.

use std::path::PathBuf;

use super::flags::{self, Execution};
use super::{fail, report_error, run};
use crate::campaign::plan::Shard;
use crate::campaign::Campaign;
use crate::exit_codes;

#[derive(clap::Args)]
pub struct Args {
    dir: PathBuf,
    /// Number of shards (array tasks of the submission).
    #[arg(long, allow_hyphen_values = true, value_parser = flags::shards)]
    pub(super) shards: u32,
    /// Array index (default: $SLURM_ARRAY_TASK_ID).
    #[arg(long, allow_hyphen_values = true, value_parser = flags::array_index)]
    pub(super) index: Option<u32>,
    #[command(flatten)]
    pub(super) exec: Execution,
}

pub fn run(a: Args) -> i32 {
    let index = match a.index.or_else(|| {
        std::env::var("SLURM_ARRAY_TASK_ID")
            .ok()
            .and_then(|v| v.parse().ok())
    }) {
        Some(i) if i < a.shards => i,
        other => {
            return fail(
                exit_codes::INVALID_INPUT,
                format!(
                    "slurm-task needs an array index below --shards {} (--index or SLURM_ARRAY_TASK_ID), got {other:?}",
                    a.shards
                ),
            )
        }
    };
    let shard = Shard {
        index: index + 1,
        count: a.shards,
    };
    let opts = run::options(&a.exec, 1, shard);
    match Campaign::open(&a.dir) {
        Ok(c) => match run::execute(&c, opts, true, false, false) {
            // Failed runs are finished runs (recorded in the runs table): the task
            // succeeded, so the afterok compaction still runs.
            exit_codes::RUNS_FAILED => exit_codes::OK,
            code => code,
        },
        Err(e) => report_error(e),
    }
}
