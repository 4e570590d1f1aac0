//! The progress bar and the log lines of a running campaign: `CliReporter` receives the
//! campaign's events (`campaign::Reporter`). With `--progress-json`, the progress as one JSON
//! object per line on stderr instead of the bar (`JsonProgress`).

use std::io::Write;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};

use crate::campaign::ledger::RunStatus;
use crate::campaign::{Event, Reporter};

/// Progress bar (on a terminal, unless `--quiet`) and log lines of a campaign's events.
pub struct CliReporter {
    bar: Option<ProgressBar>,
    running: std::collections::BTreeMap<u64, f64>,
    finished: u64,
    json: Option<JsonProgress>,
}

/// What `--progress-json` writes: the runs this session plans (`Event::Plan`'s pending; a new
/// plan, each round of an error-target campaign, starts the counts anew), how many of them
/// finished and failed, and when the last line went out (lines of progress within a run at
/// most every [`JSON_EVERY`]).
struct JsonProgress {
    planned: bool,
    total: u64,
    failed: u64,
    last: Option<Instant>,
}

/// The least time between two lines of `--progress-json` written for runs' progress (a plan,
/// a finished run and the end always get theirs).
const JSON_EVERY: Duration = Duration::from_millis(250);

impl CliReporter {
    /// `quiet`: no progress bar; `progress_json`: the progress as JSON lines on stderr, and no
    /// bar.
    pub fn new(quiet: bool, progress_json: bool) -> Self {
        let bar = if quiet || progress_json || !std::io::IsTerminal::is_terminal(&std::io::stderr())
        {
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
            json: progress_json.then_some(JsonProgress {
                planned: false,
                total: 0,
                failed: 0,
                last: None,
            }),
        }
    }

    /// Write one line of `--progress-json` (whole, in one write of the locked stderr, so that
    /// it never interleaves with a log line); `force`: whatever the time since the last.
    fn json_line(&mut self, force: bool) {
        let Some(j) = &mut self.json else { return };
        if !j.planned {
            return;
        }
        let now = Instant::now();
        if !force && j.last.is_some_and(|l| now.duration_since(l) < JSON_EVERY) {
            return;
        }
        j.last = Some(now);
        let partial: f64 = self.running.values().sum();
        let fraction = if j.total == 0 {
            1.0
        } else {
            ((self.finished as f64 + partial) / j.total as f64).clamp(0.0, 1.0)
        };
        let mut line = serde_json::json!({"progress": {
            "total": j.total,
            "finished": self.finished,
            "failed": j.failed,
            "running": self.running.len(),
            "fraction": fraction,
        }})
        .to_string();
        line.push('\n');
        let _ = std::io::stderr().lock().write_all(line.as_bytes());
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
        // The last line (after a plan: a campaign refused before it has none).
        self.json_line(true);
        self.json = None;
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
                if let Some(j) = &mut self.json {
                    j.planned = true;
                    j.total = *pending;
                    j.failed = 0;
                }
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
                if let (Some(j), RunStatus::Failed) = (&mut self.json, status) {
                    j.failed += 1;
                }
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
        match e {
            Event::Plan { .. } | Event::Finished { .. } => self.json_line(true),
            Event::Progress { .. } => self.json_line(false),
            _ => {}
        }
    }
}
