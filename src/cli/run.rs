//! `granular run MANIFEST --out DIR` and `granular resume DIR`: execute (this shard of) a
//! campaign with the progress bar and the final summary (Ctrl-C/SIGTERM: `signals`); also
//! used by `slurm-task`.

use std::path::PathBuf;

use super::flags::{Execution, Runtime};
use super::report_error;
use super::reporter::CliReporter;
use crate::campaign::plan::Shard;
use crate::campaign::{self, Campaign, Outcome, RunOptions};
use crate::exit_codes;

#[derive(clap::Args)]
pub struct RunArgs {
    manifest: PathBuf,
    /// Campaign directory.
    #[arg(long)]
    out: PathBuf,
    /// Print what would run (as `granular plan`) and write nothing.
    #[arg(long)]
    dry_run: bool,
    #[command(flatten)]
    runtime: Runtime,
}

#[derive(clap::Args)]
pub struct ResumeArgs {
    dir: PathBuf,
    #[command(flatten)]
    runtime: Runtime,
}

/// `run`: create (or continue) the campaign, then execute it.
pub fn run(a: RunArgs) -> i32 {
    if a.dry_run {
        let opts = crate::campaign::preview::EstimateOptions {
            threads: super::plan::resolve_threads(a.runtime.exec.threads(0)),
            probe: true,
        };
        return super::plan::show(&a.manifest, &a.out, false, opts);
    }
    let opts = options(&a.runtime.exec, 0, a.runtime.shard);
    let existed = a.out.join("campaign.json").exists();
    match Campaign::prepare(&a.manifest, &a.out, true) {
        Ok((c, growth)) => {
            if existed && !growth.is_empty() {
                tracing::info!(
                    new_points = growth.new_points.len(),
                    new_runs = growth.new_runs.len(),
                    continued = growth.continued.len(),
                    "campaign grown (see `granular status`)"
                );
            }
            for n in &growth.notes {
                tracing::warn!("{n}");
            }
            execute(&c, opts, a.runtime.quiet, a.runtime.progress_json, true)
        }
        Err(e) => report_error(e),
    }
}

/// `resume`: execute the campaign of an existing directory.
pub fn resume(a: ResumeArgs) -> i32 {
    let opts = options(&a.runtime.exec, 0, a.runtime.shard);
    match Campaign::open(&a.dir) {
        Ok(c) => {
            crate::campaign::test_hook::pause("resume-opened");
            execute(&c, opts, a.runtime.quiet, a.runtime.progress_json, true)
        }
        Err(e) => report_error(e),
    }
}

/// The library's run options from the flags (`default_threads` if `--threads` is not given).
pub(super) fn options(exec: &Execution, default_threads: usize, shard: Shard) -> RunOptions {
    RunOptions {
        threads: exec.threads(default_threads),
        checkpoint_every: exec.checkpoint_every(),
        shard,
        interrupt: super::signals::interrupt_flag(),
        flush_every: exec.flush_every(),
        keep_final_states: !exec.no_final_states,
    }
}

/// Run the shard `opts.shard` of `c` to its end or an interruption, with the rounds of an
/// error-target campaign where `decide` (`campaign::rounds::run`); the exit code.
/// `quiet`: no progress bar; `progress_json`: the progress as JSON lines on stderr (and no bar).
pub(super) fn execute(
    c: &Campaign,
    opts: RunOptions,
    quiet: bool,
    progress_json: bool,
    decide: bool,
) -> i32 {
    tracing::info!(campaign = %c.manifest.name, dir = %c.root.display(), shard = %opts.shard, "starting");
    let mut reporter = CliReporter::new(quiet, progress_json);
    let result = campaign::rounds::run(c, &opts, &mut reporter, decide);
    reporter.finish();
    match result {
        Ok(o) => summarise(c, &o),
        Err(e) => report_error(e),
    }
}

fn summarise(c: &Campaign, o: &Outcome) -> i32 {
    tracing::info!(
        done = o.done,
        failed = o.failed,
        remaining = o.remaining,
        complete = o.complete,
        "stopped"
    );
    if o.interrupted {
        eprintln!(
            "stopped with {} runs of this shard left; continue with: granular resume {}",
            o.remaining,
            c.root.display()
        );
        return exit_codes::INTERRUPTED;
    }
    if o.remaining > 0 {
        // Not interrupted and yet not done (the library gives an error for this; a result
        // that says otherwise must not pass as success).
        eprintln!(
            "error: {} run(s) of this shard are unfinished; continue with: granular resume {}",
            o.remaining,
            c.root.display()
        );
        return exit_codes::IO_ERROR;
    }
    if o.failed_in_shard > 0 {
        eprintln!(
            "{} run(s) failed; see the runs table (status = 'failed') for their reasons",
            o.failed_in_shard
        );
        return exit_codes::RUNS_FAILED;
    }
    exit_codes::OK
}
