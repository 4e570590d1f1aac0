//! Running a campaign's shard: lock, recover, plan the pending runs, drive them on a rayon
//! pool while one dispatcher (the calling thread) owns the campaign state, fans events out to
//! the reporter and feeds the single table writer; summaries once every run is finished.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::RecvTimeoutError;
use std::time::{Duration, Instant};

use super::integrity;
use super::ledger::{self, RunStatus, ShardLock, Upkeep};
use super::plan::RunSpec;
use super::resources::{self, Memory};
use super::worker::{self, RunResult};
use super::{
    io_err, status, writer, Campaign, CampaignError, Event, Outcome, Reporter, RunOptions,
};
use crate::fsutil;

/// Rounds of a shard's loop (run the pending runs, heal, summarise) before giving up: damage
/// that keeps coming back, or runs that keep being undone, is a failing disk or another
/// process at odds with this one, not something to loop on.
const MAX_ROUNDS: u32 = 3;

/// Run (or continue) the pending runs of `opts.shard`.
///
/// Everything is decided under the shard's lock, on the campaign as read under it: `c` is
/// only where the campaign is; its manifest and registry are read again once the lock is
/// held (a growth accepted since `c` was opened is run, not overwritten by a stale plan:
/// growth needs the exclusive lock, which no shard holds while another shard runs).
pub fn run(
    c: &Campaign,
    opts: &RunOptions,
    reporter: &mut dyn Reporter,
) -> Result<Outcome, CampaignError> {
    let _lock = ShardLock::acquire(&c.root, opts.shard)?;
    super::test_hook::pause("shard-locked");
    let fresh = reopen(c, reporter)?;
    let c = &fresh;
    let memory = Memory::of_this_machine();
    if let Some(mem) = memory {
        resources::check(&c.plan, mem)?;
    }
    c.repair_manifest_copy();
    let tag = opts.shard.tag();
    recover_and_heal(c, &tag, reporter)?;
    let ckpt_dir = c.checkpoint_dir();
    fsutil::create_dir_durable(&ckpt_dir).map_err(|e| io_err(&ckpt_dir, e))?;
    let threads = worker_threads(c, opts, memory, reporter);
    let mut outcome = Outcome::default();
    let mut rounds = 0;
    loop {
        // The runs of this shard that the latest manifest asks for.
        let mine: Vec<RunSpec> = c
            .plan
            .current_runs()
            .filter(|r| opts.shard.contains(r.run_id))
            .collect();
        outcome = run_pending(c, opts, &tag, &mine, threads, outcome, reporter)?;
        // The ledger as it is now; a record damaged meanwhile is healed below.
        let ledger = ledger::read_ledger(&c.root)?;
        let finished = ledger::finished_runs(&ledger.commits);
        tally(&mut outcome, &mine, &finished);
        if outcome.interrupted {
            return Ok(outcome);
        }
        let _upkeep = Upkeep::acquire(&c.root)?;
        if outcome.remaining > 0 || ledger.damaged() {
            // Not interrupted, every pending run ended, and yet runs of this shard are not
            // finished: their commits were lost meanwhile (a record deleted or damaged, runs
            // undone by another process's healing). Heal, and run them again.
            rounds += 1;
            if rounds >= MAX_ROUNDS {
                return Err(CampaignError::Io(format!(
                    "{}: {} run(s) of shard {} are still unfinished after {rounds} rounds (their commits keep being lost); check the disk and the processes writing to the campaign, then `granular resume`",
                    c.root.display(),
                    outcome.remaining,
                    opts.shard
                )));
            }
            reporter.event(&Event::Warning {
                message: format!(
                    "{} run(s) of this shard are not in the ledger any more{}; healing and running them again",
                    outcome.remaining,
                    if ledger.damaged() { " (the ledger was damaged meanwhile)" } else { "" }
                ),
            });
            heal(c, integrity::Depth::Quick, &tag, reporter)?;
            continue;
        }
        if !c
            .plan
            .current_runs()
            .all(|r| finished.contains_key(&r.run_id))
        {
            // Other shards' runs are left: the shard that finishes last writes the summaries.
            return Ok(outcome);
        }
        if scrub_and_summarise(c, &tag, reporter)? {
            outcome.complete = true;
            return Ok(outcome);
        }
        rounds += 1;
        if rounds >= MAX_ROUNDS {
            return Err(CampaignError::Io(format!(
                "{}: the tables were found damaged again after {rounds} rounds of healing; check the disk",
                c.root.display()
            )));
        }
    }
}

/// The campaign `c` opened again under the shard's lock (a warning if another command changed
/// its manifest or registry since `c` was read).
fn reopen(c: &Campaign, reporter: &mut dyn Reporter) -> Result<Campaign, CampaignError> {
    let fresh = Campaign::open(&c.root)?;
    if fresh.manifest_json != c.manifest_json || fresh.plan.registry != c.plan.registry {
        reporter.event(&Event::Warning {
            message: format!(
                "{}: the campaign was changed by another command since this one read it; running its latest manifest ({})",
                c.root.display(),
                fresh
                    .history
                    .last()
                    .map(|h| h.file.as_str())
                    .unwrap_or("campaign.json")
            ),
        });
    }
    Ok(fresh)
}

/// Dead shards' commits and damage, one shard process at a time: recover the ledger, then
/// heal the tables against it (sizes), before anything is planned.
fn recover_and_heal(
    c: &Campaign,
    tag: &str,
    reporter: &mut dyn Reporter,
) -> Result<(), CampaignError> {
    let _upkeep = Upkeep::acquire(&c.root)?;
    for note in ledger::recover(&c.root, tag)? {
        reporter.event(&Event::Warning { message: note });
    }
    heal(c, integrity::Depth::Quick, tag, reporter)?;
    Ok(())
}

/// One round: the runs of `mine` not finished in the ledger, run on `threads` workers and
/// committed; `outcome` with their counts added.
fn run_pending(
    c: &Campaign,
    opts: &RunOptions,
    tag: &str,
    mine: &[RunSpec],
    threads: usize,
    outcome: Outcome,
    reporter: &mut dyn Reporter,
) -> Result<Outcome, CampaignError> {
    let io = |e: crate::store::parquet_io::StoreError| CampaignError::Io(e.to_string());
    let finished = finished_runs(c)?;
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
    let writer = writer::Writer::new(c, tag).map_err(io)?;
    {
        // The tables written whole (points, registered runs, theory) are rewritten by one
        // shard process at a time, never while another heals.
        let _upkeep = Upkeep::acquire(&c.root)?;
        writer.ensure_points().map_err(io)?;
        writer.ensure_theory().map_err(io)?;
    }
    let mut d = Dispatcher {
        c,
        opts,
        tag,
        reporter: &mut *reporter,
        writer,
        outcome,
        fatal: None,
        running: Default::default(),
        last_heartbeat: Instant::now() - Duration::from_secs(60),
    };
    d.drive(&pending, threads)?;
    let Dispatcher {
        mut writer,
        mut outcome,
        reporter: rep,
        ..
    } = d;
    if let Some((runs, seq)) = writer
        .flush()
        .map_err(|e| CampaignError::Io(format!("writing the tables failed: {e}")))?
    {
        rep.event(&Event::Committed { runs, seq });
    }
    status::remove_heartbeat(&c.root, tag);
    if opts.interrupt.load(Ordering::SeqCst) > 0 {
        outcome.interrupted = true;
    }
    Ok(outcome)
}

/// The runs of `mine` left unfinished, and failed, in the ledger's `finished`; a shard with
/// nothing left is not interrupted.
fn tally(outcome: &mut Outcome, mine: &[RunSpec], finished: &BTreeMap<u64, RunStatus>) {
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
}

/// Every run is finished: scrub every file before the summaries read them (damage found now
/// is healed and its runs run again: false), then write the summaries of the ledger as it is
/// now (read under the upkeep lock, after the scrub); true if they still hold once written.
fn scrub_and_summarise(
    c: &Campaign,
    tag: &str,
    reporter: &mut dyn Reporter,
) -> Result<bool, CampaignError> {
    let acted = heal(c, integrity::Depth::Full, tag, reporter)?;
    if acted != 0 {
        return Ok(false);
    }
    let finished = finished_runs(c)?;
    if !c
        .plan
        .current_runs()
        .all(|r| finished.contains_key(&r.run_id))
    {
        return Ok(false);
    }
    c.write_summaries(&finished)
        .map_err(|e| CampaignError::Io(e.to_string()))?;
    let after = finished_runs(c)?;
    Ok(c.done_replicas(&after) == c.done_replicas(&finished))
}

fn finished_runs(c: &Campaign) -> Result<BTreeMap<u64, RunStatus>, CampaignError> {
    Ok(ledger::finished_runs(&ledger::read_commits(&c.root)?))
}

/// Check the tables against the ledger and heal what is found (each action a warning);
/// returns how many actions were taken (runs undone, tables set aside: another round writes
/// them again).
fn heal(
    c: &Campaign,
    depth: integrity::Depth,
    tag: &str,
    reporter: &mut dyn Reporter,
) -> Result<usize, CampaignError> {
    let found = integrity::check(c, depth)?;
    if found.clean() {
        return Ok(0);
    }
    for p in found.problems() {
        reporter.event(&Event::Warning {
            message: format!("damage: {p}"),
        });
    }
    let healed = integrity::heal(c, &found, tag)?;
    for a in &healed.actions {
        reporter.event(&Event::Warning {
            message: format!("healed: {a}"),
        });
    }
    if let Some(q) = &healed.quarantine {
        reporter.event(&Event::Warning {
            message: format!(
                "what was set aside is in {} (actions.log says what and why); delete it when done",
                q.display()
            ),
        });
    }
    // Whatever is still wrong must be a running shard's (left for later), or healing failed.
    let again = integrity::check(c, integrity::Depth::Quick)?;
    if !again.clean() {
        let message = format!(
            "{}: damage left: {}",
            c.root.display(),
            again.problems().join("; ")
        );
        if again.live.iter().all(|t| t == tag) {
            return Err(CampaignError::Refused(message));
        }
        reporter.event(&Event::Warning { message });
    }
    Ok(healed.actions.len())
}

/// Worker threads: `--threads` (0: every core), fewer if the free memory holds fewer runs.
fn worker_threads(
    c: &Campaign,
    opts: &RunOptions,
    memory: Option<Memory>,
    reporter: &mut dyn Reporter,
) -> usize {
    let threads = if opts.threads == 0 {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
    } else {
        opts.threads
    };
    let Some(mem) = memory else {
        return threads;
    };
    let (fit, note) = resources::threads_within(&c.plan, threads, mem);
    if let Some(message) = note {
        reporter.event(&Event::Warning { message });
    }
    fit
}

/// The dispatcher's state: it owns the writer and the outcome, and hears every event.
struct Dispatcher<'a, 'r> {
    c: &'a Campaign,
    opts: &'a RunOptions,
    tag: &'a str,
    reporter: &'r mut dyn Reporter,
    writer: writer::Writer<'a>,
    outcome: Outcome,
    /// The first write failure; the workers are stopped and nothing more is committed.
    fatal: Option<CampaignError>,
    running: BTreeSet<u64>,
    last_heartbeat: Instant,
}

impl Dispatcher<'_, '_> {
    /// Run `pending` on `threads` workers (each takes the next pending run in plan order) and
    /// handle their events on this thread until all are done or stopped.
    fn drive(&mut self, pending: &[RunSpec], threads: usize) -> Result<(), CampaignError> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|i| format!("granular-worker-{i}"))
            .build()
            .map_err(|e| {
                CampaignError::Io(format!("cannot start {threads} worker threads: {e}"))
            })?;
        let (tx, rx) = std::sync::mpsc::channel::<(Event, Option<RunResult>)>();
        let (c, opts) = (self.c, self.opts);
        std::thread::scope(|scope| {
            let tx_workers = tx.clone();
            let pool = &pool;
            scope.spawn(move || {
                let next = AtomicUsize::new(0);
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
                match rx.recv_timeout(Duration::from_millis(200)) {
                    Ok((event, result)) => self.handle(event, result),
                    Err(RecvTimeoutError::Timeout) => {}
                    Err(RecvTimeoutError::Disconnected) => break,
                }
                self.tick();
            }
        });
        match self.fatal.take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    /// One event: counts, the reporter, and the finished run's rows to the writer.
    fn handle(&mut self, event: Event, result: Option<RunResult>) {
        match &event {
            Event::Started { run_id, .. } => {
                self.running.insert(*run_id);
            }
            Event::Finished { run_id, status, .. } => {
                self.running.remove(run_id);
                match status {
                    RunStatus::Done => self.outcome.done += 1,
                    RunStatus::Failed => self.outcome.failed += 1,
                }
            }
            Event::Interrupted { run_id } => {
                self.running.remove(run_id);
                self.outcome.interrupted = true;
            }
            _ => {}
        }
        self.reporter.event(&event);
        if let (Some(r), None) = (result, &self.fatal) {
            self.writer.add(r);
        }
    }

    /// Commit when due (a failure stops the workers: they checkpoint, nothing of this batch is
    /// committed) and write the heartbeat every 2 s.
    fn tick(&mut self) {
        if self.fatal.is_none() && self.writer.due(self.opts.flush_every) {
            match self.writer.flush() {
                Ok(Some((runs, seq))) => {
                    self.reporter.event(&Event::Committed { runs, seq });
                    super::test_hook::pause("committed");
                }
                Ok(None) => {}
                Err(e) => {
                    self.opts.interrupt.fetch_max(1, Ordering::SeqCst);
                    self.fatal = Some(CampaignError::Io(format!("writing the tables failed: {e}")));
                }
            }
        }
        if self.last_heartbeat.elapsed() > Duration::from_secs(2) {
            self.last_heartbeat = Instant::now();
            let _ = status::write_heartbeat(&self.c.root, self.tag, &self.running);
        }
    }
}
