//! One run on a worker thread: start or restore from its checkpoint, advance in bounded
//! chunks, checkpoint every `checkpoint_every` and on interruption, report by events.

use std::sync::atomic::Ordering;
use std::sync::mpsc::Sender;
use std::time::Instant;

use super::ledger::RunStatus;
use super::plan::RunSpec;
use super::{Campaign, Event, RunOptions};
use crate::models::{Engine, ModelParams, RunIds, RunRows, WORK_CHUNK};
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
    let (engine, wall_before, resumed_from) = match restore(&dir, spec, params, tx, &warn) {
        Some((e, wall, t)) => (e, wall, Some(t)),
        None => match params.start(spec.seed) {
            Ok(e) => (e, 0.0, None),
            Err(reason) => return finish(tx, spec, RunEnd::Failed { reason, t: 0.0 }, 0.0, None),
        },
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
        Some(end) => finish(tx, spec, end, run.wall(), None),
        None => {
            let t = run.engine.time();
            let wall = run.wall();
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
            )
        }
    }
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
}

impl Running<'_> {
    fn wall(&self) -> f64 {
        self.wall_before + self.started.elapsed().as_secs_f64()
    }

    fn save(&mut self) -> Result<(), String> {
        let header = CheckpointHeader {
            run_id: self.spec.run_id,
            seed: self.spec.seed,
            code_version: CODE_VERSION.into(),
            state_format: self.params.state_format().into(),
            wall_seconds: self.wall(),
            t: self.engine.time(),
        };
        let payload = self.engine.state_bytes();
        checkpoint::write(self.dir, &header, &payload).map_err(|e| e.to_string())?;
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
    spec: &RunSpec,
    params: &ModelParams,
    tx: &mut Tx,
    warn: &dyn Fn(&mut Tx, String),
) -> Option<(Engine, f64, f64)> {
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
        params.restore(&loaded.payload)
    } else {
        Err(format!(
            "state format {:?}, this granular writes {:?}",
            loaded.header.state_format,
            params.state_format()
        ))
    };
    match restored {
        Ok(e) => Some((e, loaded.header.wall_seconds, loaded.header.t)),
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

fn finish(tx: &mut Tx, spec: &RunSpec, end: RunEnd, wall_seconds: f64, t: Option<f64>) {
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
        }),
    ));
}

impl RunResult {
    pub fn is_final(&self) -> bool {
        matches!(self.end, RunEnd::Done(_) | RunEnd::Failed { .. })
    }
}
