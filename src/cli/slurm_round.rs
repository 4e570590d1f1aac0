//! `granular slurm-round DIR --submission K` (hidden): the round job of an error-target
//! campaign under SLURM, chained after array K (afterany). It decides the next round from the
//! committed runs and submits the next array and round job, or resubmits the shards whose runs
//! were not committed (once), or, once every target is met or the campaign stopped, the
//! compaction job (`campaign::slurm::round_step`). The round scripts that `submit` and earlier
//! round jobs write call it: its flags must keep parsing.

use std::path::PathBuf;

use super::{fail, report_error};
use crate::campaign::slurm::{self, RoundStep};
use crate::exit_codes;

#[derive(clap::Args)]
pub struct Args {
    dir: PathBuf,
    /// The submission whose array this round job follows (slurm/submission.json).
    #[arg(long, allow_hyphen_values = true, value_parser = clap::value_parser!(u32).range(1..))]
    pub(super) submission: u32,
}

pub fn run(a: Args) -> i32 {
    let root = a.dir.canonicalize().unwrap_or(a.dir.clone());
    match slurm::round_step(&root, a.submission) {
        Ok(RoundStep::Superseded(n)) => {
            outln!(
                "submission {} was followed by submission {n}; its round job decides",
                a.submission
            );
            exit_codes::OK
        }
        Ok(RoundStep::Submitted { round, added, plan }) => {
            let s = plan.record.submissions.last().expect("submission");
            let what = if added > 0 {
                format!("round {round}: {added} run(s) added")
            } else {
                format!(
                    "round {round}: runs not all committed; resubmitted (try {})",
                    s.attempt.unwrap_or(2)
                )
            };
            outln!(
                "{what}: submitted array {} as job {}, round job {} (afterany)",
                s.array,
                s.array_job.as_deref().unwrap_or("?"),
                s.round_job.as_deref().unwrap_or("?")
            );
            exit_codes::OK
        }
        Ok(RoundStep::Final {
            outcome,
            compact_job,
        }) => {
            outln!(
                "targets {} after round {}: {}{}",
                if outcome.verdict == "met" {
                    "met"
                } else {
                    "not all met, stopped"
                },
                outcome.round,
                outcome.message,
                compact_job
                    .map(|j| format!("; compaction job {j}"))
                    .unwrap_or_default()
            );
            exit_codes::OK
        }
        Ok(RoundStep::GaveUp(o)) => fail(
            exit_codes::RUNS_FAILED,
            format!("the round jobs give up: {}", o.message),
        ),
        Err(e) => report_error(e),
    }
}
