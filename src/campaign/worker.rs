//! One run on a worker thread: restore it from its checkpoint, or continue the run it
//! extends from that run's final state, or start it; advance in bounded chunks, checkpoint
//! every `checkpoint_every` and on interruption, keep its final state at the end, report by
//! events.

use std::sync::atomic::Ordering;
use std::sync::mpsc::Sender;
use std::time::Instant;

use super::ledger::RunStatus;
use super::plan::RunSpec;
use super::{Campaign, Event, RunOptions};
use crate::models::{Engine, ModelError, ModelParams, RunIds, RunRows, WORK_CHUNK};
use crate::store::checkpoint::{self, CheckpointHeader};
use crate::CODE_VERSION;

#[derive(Debug)]
pub enum RunEnd {
    Done(RunRows),
    /// A deterministic physics failure.
    Failed {
        reason: String,
        t: f64,
    },
    Interrupted,
}

#[derive(Debug)]
pub struct RunResult {
    pub spec: RunSpec,
    pub end: RunEnd,
    pub wall_seconds: f64,
    /// The run it continued from its final state (None: it ran from t = 0).
    pub continued_from: Option<u64>,
}

type Tx = Sender<(Event, Option<RunResult>)>;

pub fn run_one(c: &Campaign, spec: &RunSpec, opts: &RunOptions, tx: &mut Tx) {
    if opts.interrupt.load(Ordering::Relaxed) > 0 {
        return;
    }
    let started = Instant::now();
    let params = &c.plan.point(spec.point_id).params;
    let dir = c.checkpoint_dir();
    let warn = |tx: &mut Tx, message: String| {
        let _ = tx.send((Event::Warning { message }, None));
    };
    let (engine, from) = match restore(&dir, c.stream, spec, params, tx, &warn) {
        Some((e, h)) => (
            e,
            From::Checkpoint {
                wall: h.wall_seconds,
                t: h.t,
                continued_from: h.continued_from,
            },
        ),
        None => match start(c, spec, params, tx, &warn) {
            Ok(started) => started,
            Err(e) => {
                let reason = e.to_string();
                return finish(tx, spec, RunEnd::Failed { reason, t: 0.0 }, 0.0, None, None);
            }
        },
    };
    let (wall_before, resumed_from, continued_from) = match from {
        From::Start => (0.0, None, None),
        From::Checkpoint {
            wall,
            t,
            continued_from,
        } => (wall, Some(t), continued_from),
        From::Final { wall, t } => (wall, Some(t), spec.continues),
    };
    let _ = tx.send((
        Event::Started {
            run_id: spec.run_id,
            resumed_from,
        },
        None,
    ));
    let mut run = Running {
        spec,
        params,
        dir: &dir,
        engine,
        started,
        wall_before,
        last_ckpt_t: resumed_from,
        continued_from,
    };
    match run.advance_to_end(opts, tx) {
        Some(RunEnd::Interrupted) => {
            let _ = tx.send((
                Event::Interrupted {
                    run_id: spec.run_id,
                },
                None,
            ));
        }
        Some(end) => finish(tx, spec, end, run.wall(), None, continued_from),
        None => {
            let t = run.engine.time();
            let wall = run.wall();
            if opts.keep_final_states {
                if let Err(e) = run.keep_final(c) {
                    warn(
                        tx,
                        format!(
                            "run {}: final state not kept ({e}); a longer run of its point will \
                             run it again from t = 0",
                            spec.run_id
                        ),
                    );
                }
            }
            let ids = RunIds {
                run_id: spec.run_id,
                point_id: spec.point_id,
            };
            finish(
                tx,
                spec,
                RunEnd::Done(run.engine.finish(ids)),
                wall,
                Some(t),
                continued_from,
            )
        }
    }
}

/// Where a run's engine came from.
enum From {
    /// t = 0.
    Start,
    /// Its own checkpoint: the wall time spent and the simulated time reached before, and
    /// the run it had continued.
    Checkpoint {
        wall: f64,
        t: f64,
        continued_from: Option<u64>,
    },
    /// The final state of the run it continues: that run's wall time and end.
    Final { wall: f64, t: f64 },
}

/// A run that has no checkpoint: it continues the run `spec.continues` from its final state
/// when that exists and can be continued (else it starts from t = 0, with a warning), or it
/// starts from t = 0.
fn start(
    c: &Campaign,
    spec: &RunSpec,
    params: &ModelParams,
    tx: &mut Tx,
    warn: &dyn Fn(&mut Tx, String),
) -> Result<(Engine, From), ModelError> {
    if let Some(old) = spec.continues {
        let why = match checkpoint::load_final(&c.finals_dir(), old, spec.seed) {
            Ok(Some((h, payload))) if h.state_format == params.state_format() => {
                match params.continue_from(&payload) {
                    Ok(e) if !e.draws_as(c.stream) => format!(
                        "its final state does not draw as the campaign's random stream \
                         (version {})",
                        c.stream.number()
                    ),
                    Ok(e) => {
                        let from = From::Final {
                            wall: h.wall_seconds,
                            t: h.t,
                        };
                        return Ok((e, from));
                    }
                    Err(e) => e.to_string(),
                }
            }
            Ok(Some((h, _))) => format!(
                "its state format is {:?}, this granular writes {:?}",
                h.state_format,
                params.state_format()
            ),
            Ok(None) => "it has no final state".into(),
            Err(e) => e.to_string(),
        };
        warn(
            tx,
            format!(
                "run {}: cannot continue run {old} ({why}); running it from t = 0",
                spec.run_id
            ),
        );
    }
    Ok((params.start(spec.seed, c.stream)?, From::Start))
}

/// A run on its worker: the engine and what its checkpoints need.
struct Running<'a> {
    spec: &'a RunSpec,
    params: &'a ModelParams,
    dir: &'a std::path::Path,
    engine: Engine,
    started: Instant,
    /// Wall time spent before this session (from the checkpoint resumed).
    wall_before: f64,
    /// Simulated time of the last checkpoint written (or resumed from).
    last_ckpt_t: Option<f64>,
    /// The run it continued from its final state.
    continued_from: Option<u64>,
}

impl Running<'_> {
    fn wall(&self) -> f64 {
        self.wall_before + self.started.elapsed().as_secs_f64()
    }

    /// Write the finished run's final state, if its model keeps one.
    fn keep_final(&mut self, c: &Campaign) -> std::io::Result<()> {
        let Some(parts) = self.engine.final_state() else {
            return Ok(());
        };
        let header = self.header();
        checkpoint::write_final(&c.finals_dir(), &header, &parts)
    }

    /// The header of the run's checkpoint or final state, as of now.
    fn header(&self) -> CheckpointHeader {
        CheckpointHeader {
            run_id: self.spec.run_id,
            seed: self.spec.seed,
            code_version: CODE_VERSION.into(),
            state_format: self.params.state_format().into(),
            wall_seconds: self.wall(),
            t: self.engine.time(),
            continued_from: self.continued_from,
        }
    }

    fn save(&mut self) -> std::io::Result<()> {
        let header = self.header();
        let payload = self.engine.state_bytes();
        checkpoint::write(self.dir, &header, &payload)?;
        self.last_ckpt_t = Some(header.t);
        Ok(())
    }

    /// Advance in chunks, checkpointing every `checkpoint_every` and on interrupt, reporting
    /// progress; None when the run is complete, else how it ended (interrupted after its
    /// checkpoint, or failed).
    fn advance_to_end(&mut self, opts: &RunOptions, tx: &mut Tx) -> Option<RunEnd> {
        let run_id = self.spec.run_id;
        let mut last_ckpt = Instant::now();
        let mut last_progress = Instant::now();
        loop {
            if opts.interrupt.load(Ordering::Relaxed) > 0 {
                if let Err(e) = self.save() {
                    let message = format!("run {run_id}: checkpoint failed: {e}");
                    let _ = tx.send((Event::Warning { message }, None));
                }
                return Some(RunEnd::Interrupted);
            }
            match self.engine.advance(WORK_CHUNK) {
                Ok(true) => return None,
                Ok(false) => {}
                Err(pe) => {
                    let reason = format!(
                        "{} (run {run_id}, seed {}, last checkpoint at t = {})",
                        pe.reason,
                        self.spec.seed,
                        self.last_ckpt_t
                            .map(|t| t.to_string())
                            .unwrap_or_else(|| "none".into())
                    );
                    return Some(RunEnd::Failed { reason, t: pe.t });
                }
            }
            if last_ckpt.elapsed() >= opts.checkpoint_every {
                let event = match self.save() {
                    Err(e) => Event::Warning {
                        message: format!("run {run_id}: checkpoint failed: {e}"),
                    },
                    Ok(()) => Event::Checkpointed {
                        run_id,
                        t: self.engine.time(),
                    },
                };
                let _ = tx.send((event, None));
                last_ckpt = Instant::now();
            }
            if last_progress.elapsed().as_millis() >= 250 {
                last_progress = Instant::now();
                let fraction = self.engine.progress();
                let _ = tx.send((Event::Progress { run_id, fraction }, None));
            }
        }
    }
}

/// The run's engine restored from its newest usable checkpoint, with the wall time spent and
/// the simulated time reached before; None (after warnings) when there is none.
fn restore(
    dir: &std::path::Path,
    stream: crate::rng::StreamVersion,
    spec: &RunSpec,
    params: &ModelParams,
    tx: &mut Tx,
    warn: &dyn Fn(&mut Tx, String),
) -> Option<(Engine, CheckpointHeader)> {
    let loaded = match checkpoint::load(dir, spec.run_id, spec.seed) {
        Ok(Some(loaded)) => loaded,
        Ok(None) => return None,
        Err(problems) => {
            let why = problems.join("; ");
            warn(
                tx,
                format!(
                    "run {}: no usable checkpoint ({why}); restarting from t = 0",
                    spec.run_id
                ),
            );
            return None;
        }
    };
    for s in loaded.skipped {
        warn(
            tx,
            format!("run {}: skipped a bad checkpoint: {s}", spec.run_id),
        );
    }
    let restored = if loaded.header.state_format == params.state_format() {
        params
            .restore(&loaded.payload)
            .map_err(|e| e.to_string())
            .and_then(|e| {
                if e.draws_as(stream) {
                    Ok(e)
                } else {
                    Err(format!(
                        "it does not draw as the campaign's random stream (version {})",
                        stream.number()
                    ))
                }
            })
    } else {
        Err(format!(
            "state format {:?}, this granular writes {:?}",
            loaded.header.state_format,
            params.state_format()
        ))
    };
    match restored {
        Ok(e) => Some((e, loaded.header)),
        Err(e) => {
            warn(
                tx,
                format!(
                    "run {}: checkpoint unusable ({e}); restarting from t = 0",
                    spec.run_id
                ),
            );
            None
        }
    }
}

fn finish(
    tx: &mut Tx,
    spec: &RunSpec,
    end: RunEnd,
    wall_seconds: f64,
    t: Option<f64>,
    continued_from: Option<u64>,
) {
    let (status, reason, t) = match &end {
        RunEnd::Done(_) => (RunStatus::Done, None, t.unwrap_or(0.0)),
        RunEnd::Failed { reason, t } => (RunStatus::Failed, Some(reason.clone()), *t),
        RunEnd::Interrupted => unreachable!("interrupted runs are not finished"),
    };
    let event = Event::Finished {
        run_id: spec.run_id,
        seed: spec.seed,
        status,
        reason,
        t,
        wall_seconds,
    };
    let _ = tx.send((
        event,
        Some(RunResult {
            spec: *spec,
            end,
            wall_seconds,
            continued_from,
        }),
    ));
}

impl RunResult {
    pub fn is_final(&self) -> bool {
        matches!(self.end, RunEnd::Done(_) | RunEnd::Failed { .. })
    }
}
