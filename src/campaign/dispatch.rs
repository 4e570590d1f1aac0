//! Running a campaign's shard: lock, recover, plan the pending runs, drive them on a rayon
//! pool while one dispatcher (the calling thread) owns the campaign state, fans events out to
//! the reporter and feeds the single table writer; summaries once every run is finished.

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use super::ledger::{self, RunStatus, ShardLock};
use super::plan::RunSpec;
use super::resources::{self, Memory};
use super::worker::{self, RunResult};
use super::{
    io_err, status, writer, Campaign, CampaignError, Event, Outcome, Reporter, RunOptions,
};
use crate::fsutil;

/// Run (or continue) the pending runs of `opts.shard`.
pub fn run(
    c: &Campaign,
    opts: &RunOptions,
    reporter: &mut dyn Reporter,
) -> Result<Outcome, CampaignError> {
    let memory = Memory::of_this_machine();
    if let Some(mem) = memory {
        resources::check(&c.plan, mem).map_err(CampaignError::TooLarge)?;
    }
    let _lock = ShardLock::acquire(&c.root, opts.shard).map_err(CampaignError::Refused)?;
    let tag = opts.shard.tag();
    for note in ledger::recover(&c.root, &tag).map_err(CampaignError::Io)? {
        reporter.event(&Event::Warning { message: note });
    }
    let commits = ledger::read_commits(&c.root).map_err(CampaignError::Refused)?;
    let finished = ledger::finished_runs(&commits);
    let mine: Vec<RunSpec> = (0..c.plan.n_runs())
        .filter(|r| opts.shard.contains(*r))
        .map(|r| c.plan.run(r))
        .collect();
    let pending: Vec<RunSpec> = mine
        .iter()
        .filter(|r| !finished.contains_key(&r.run_id))
        .copied()
        .collect();
    reporter.event(&Event::Plan {
        total: mine.len() as u64,
        already: (mine.len() - pending.len()) as u64,
        pending: pending.len() as u64,
    });

    let ckpt_dir = c.checkpoint_dir();
    fsutil::create_dir_durable(&ckpt_dir).map_err(|e| io_err(&ckpt_dir, e))?;
    let mut writer = writer::Writer::new(c, &tag).map_err(|e| CampaignError::Io(e.to_string()))?;
    writer
        .ensure_points()
        .map_err(|e| CampaignError::Io(e.to_string()))?;
    writer
        .ensure_theory()
        .map_err(|e| CampaignError::Io(e.to_string()))?;

    let threads = if opts.threads == 0 {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
    } else {
        opts.threads
    };
    let threads = match memory {
        Some(mem) => {
            let (fit, note) = resources::threads_within(&c.plan, threads, mem);
            if let Some(message) = note {
                reporter.event(&Event::Warning { message });
            }
            fit
        }
        None => threads,
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("granular-worker-{i}"))
        .build()
        .map_err(|e| CampaignError::Io(format!("cannot start {threads} worker threads: {e}")))?;

    let (tx, rx) = std::sync::mpsc::channel::<(Event, Option<RunResult>)>();
    let mut outcome = Outcome::default();
    let mut fatal: Option<CampaignError> = None;
    let mut last_heartbeat = Instant::now() - Duration::from_secs(60);
    let mut running: std::collections::BTreeSet<u64> = Default::default();
    std::thread::scope(|scope| {
        let tx_workers = tx.clone();
        let pending = &pending;
        let pool = &pool;
        scope.spawn(move || {
            // A shared queue: each worker takes the next pending run in plan order.
            let next = std::sync::atomic::AtomicUsize::new(0);
            let next = &next;
            pool.scope(|s| {
                for _ in 0..threads {
                    let mut tx = tx_workers.clone();
                    s.spawn(move |_| loop {
                        let j = next.fetch_add(1, Ordering::SeqCst);
                        let Some(spec) = pending.get(j) else { break };
                        worker::run_one(c, spec, opts, &mut tx);
                    });
                }
            });
            drop(tx_workers);
        });
        drop(tx);
        loop {
            let msg = rx.recv_timeout(Duration::from_millis(200));
            match msg {
                Ok((event, result)) => {
                    match &event {
                        Event::Started { run_id, .. } => {
                            running.insert(*run_id);
                        }
                        Event::Finished { run_id, status, .. } => {
                            running.remove(run_id);
                            match status {
                                RunStatus::Done => outcome.done += 1,
                                RunStatus::Failed => outcome.failed += 1,
                            }
                        }
                        Event::Interrupted { run_id } => {
                            running.remove(run_id);
                            outcome.interrupted = true;
                        }
                        _ => {}
                    }
                    reporter.event(&event);
                    if let Some(r) = result {
                        if fatal.is_none() {
                            writer.add(r);
                        }
                    }
                }
                Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
                Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => break,
            }
            if fatal.is_none() && writer.due(opts.flush_every) {
                match writer.flush() {
                    Ok(Some((runs, seq))) => reporter.event(&Event::Committed { runs, seq }),
                    Ok(None) => {}
                    Err(e) => {
                        // Stop the workers (they checkpoint); nothing of this batch is committed.
                        opts.interrupt.fetch_max(1, Ordering::SeqCst);
                        fatal = Some(CampaignError::Io(format!("writing the tables failed: {e}")));
                    }
                }
            }
            if last_heartbeat.elapsed() > Duration::from_secs(2) {
                last_heartbeat = Instant::now();
                let _ = status::write_heartbeat(&c.root, &tag, &running);
            }
        }
    });
    if let Some(e) = fatal {
        return Err(e);
    }
    match writer.flush() {
        Ok(Some((runs, seq))) => reporter.event(&Event::Committed { runs, seq }),
        Ok(None) => {}
        Err(e) => return Err(CampaignError::Io(format!("writing the tables failed: {e}"))),
    }
    status::remove_heartbeat(&c.root, &tag);
    if opts.interrupt.load(Ordering::SeqCst) > 0 {
        outcome.interrupted = true;
    }
    let commits = ledger::read_commits(&c.root).map_err(CampaignError::Refused)?;
    let finished = ledger::finished_runs(&commits);
    outcome.remaining = mine
        .iter()
        .filter(|r| !finished.contains_key(&r.run_id))
        .count() as u64;
    outcome.failed_in_shard = mine
        .iter()
        .filter(|r| finished.get(&r.run_id) == Some(&RunStatus::Failed))
        .count() as u64;
    if outcome.remaining == 0 {
        outcome.interrupted = false;
    }
    if finished.len() as u64 == c.plan.n_runs() {
        c.write_summaries(&finished)
            .map_err(|e| CampaignError::Io(e.to_string()))?;
        outcome.complete = true;
    }
    Ok(outcome)
}
