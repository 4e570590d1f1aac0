//! The progress bar and the log lines of a running campaign: `CliReporter` receives the
//! campaign's events (`campaign::Reporter`).

use std::time::Duration;

use indicatif::{ProgressBar, ProgressStyle};

use crate::campaign::ledger::RunStatus;
use crate::campaign::{Event, Reporter};

/// Progress bar (on a terminal, unless `--quiet`) and log lines of a campaign's events.
pub struct CliReporter {
    bar: Option<ProgressBar>,
    running: std::collections::BTreeMap<u64, f64>,
    finished: u64,
}

impl CliReporter {
    pub fn new(quiet: bool) -> Self {
        let bar = if quiet || !std::io::IsTerminal::is_terminal(&std::io::stderr()) {
            None
        } else {
            let b = ProgressBar::new(0);
            b.set_style(
                ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} runs ({percent}%) eta {eta} {msg}")
                    .expect("template"),
            );
            b.enable_steady_tick(Duration::from_millis(200));
            Some(b)
        };
        CliReporter {
            bar,
            running: Default::default(),
            finished: 0,
        }
    }

    fn update(&mut self) {
        if let Some(b) = &self.bar {
            let partial: f64 = self.running.values().sum();
            // Position in thousandths of runs so running work shows.
            b.set_position(self.finished * 1000 + (partial * 1000.0) as u64);
            b.set_message(format!("{} running", self.running.len()));
        }
    }

    pub fn finish(&mut self) {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
    }
}

impl Reporter for CliReporter {
    fn event(&mut self, e: &Event) {
        match e {
            Event::Plan {
                total,
                already,
                pending,
            } => {
                tracing::info!(total, already_finished = already, pending, "shard plan");
                // Each round of an error-target campaign plans anew.
                self.finished = 0;
                if let Some(b) = &self.bar {
                    b.set_length(pending * 1000);
                    b.set_style(
                        ProgressStyle::with_template(
                            "{spinner} [{elapsed_precise}] {bar:40} {percent}% eta {eta} {msg}",
                        )
                        .expect("template"),
                    );
                }
            }
            Event::Started {
                run_id,
                resumed_from,
            } => {
                // From now on Ctrl-C / SIGTERM checkpoints and stops.
                super::signals::runs_started();
                tracing::debug!(run_id, ?resumed_from, "run started");
                self.running.insert(*run_id, 0.0);
            }
            Event::Progress { run_id, fraction } => {
                self.running.insert(*run_id, *fraction);
            }
            Event::Checkpointed { run_id, t } => tracing::debug!(run_id, t, "checkpoint written"),
            Event::Finished {
                run_id,
                seed,
                status,
                reason,
                t,
                wall_seconds,
            } => {
                self.running.remove(run_id);
                self.finished += 1;
                match status {
                    RunStatus::Done => tracing::debug!(run_id, wall_seconds, "run done"),
                    RunStatus::Failed => {
                        let msg = format!(
                            "run {run_id} (seed {seed}) failed at t = {t}: {}",
                            reason.as_deref().unwrap_or("")
                        );
                        match &self.bar {
                            Some(b) => b.suspend(|| tracing::error!("{msg}")),
                            None => tracing::error!("{msg}"),
                        }
                    }
                }
            }
            Event::Interrupted { run_id } => {
                self.running.remove(run_id);
                tracing::info!(run_id, "run checkpointed and stopped");
            }
            Event::Committed { runs, seq } => tracing::debug!(runs, seq, "committed"),
            Event::Round { message } => match &self.bar {
                Some(b) => b.suspend(|| tracing::info!("{message}")),
                None => tracing::info!("{message}"),
            },
            Event::Warning { message } => match &self.bar {
                Some(b) => b.suspend(|| tracing::warn!("{message}")),
                None => tracing::warn!("{message}"),
            },
        }
        self.update();
    }
}
