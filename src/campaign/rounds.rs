//! The rounds of an error-target campaign, run: the shard's loop of `run`/`resume` (the
//! decisions themselves are `campaign::targets`). Apart from `targets` so that the rule and
//! its records (which `status` shows) import nothing of the dispatcher.

use super::targets::{decide_round, Decided, Verdict};
use super::{Campaign, CampaignError};

/// How long a shard that finished its runs of a round waits before it looks again whether
/// the other shards have finished theirs.
const WAIT: std::time::Duration = std::time::Duration::from_millis(500);

/// Run this shard of the campaign with its rounds (without targets: `dispatch::run`).
///
/// After the shard's runs, once every run the campaign asks for is committed, the next round
/// is decided ([`decide_round`]) and its runs of this shard are run, until every target is
/// met or the campaign stops. A shard that finishes its runs of a round before the others
/// waits while another shard runs, and leaves the round to the others when none runs (it is
/// then decided by the last shard to finish, or by `resume`). With `decide` false (the tasks
/// of a SLURM array: the chained round job decides) the shard runs its runs and returns.
pub fn run(
    c: &Campaign,
    opts: &super::RunOptions,
    reporter: &mut dyn super::Reporter,
    decide: bool,
) -> Result<super::Outcome, CampaignError> {
    let mut total = super::Outcome::default();
    let mut current: Option<Campaign> = None;
    loop {
        let o = dispatch_when_free(current.as_ref().unwrap_or(c), opts, reporter)?;
        total.done += o.done;
        total.failed += o.failed;
        total.failed_in_shard = o.failed_in_shard;
        total.remaining = o.remaining;
        total.interrupted = o.interrupted;
        total.complete = o.complete;
        if !decide || o.interrupted || o.remaining > 0 {
            return Ok(total);
        }
        let mut idle = 0;
        loop {
            if opts.interrupt.load(std::sync::atomic::Ordering::Relaxed) > 0 {
                total.interrupted = true;
                return Ok(total);
            }
            let fresh = Campaign::open(&c.root)?;
            if !fresh.manifest.has_targets() {
                return Ok(total);
            }
            match decide_round(&fresh) {
                Ok(Decided::More(n)) => {
                    let d = Campaign::open(&c.root)?;
                    let round = d.rounds.decisions.len();
                    let why = d
                        .rounds
                        .decisions
                        .last()
                        .map(|d| d.why.clone())
                        .unwrap_or_default();
                    reporter.event(&super::Event::Round {
                        message: format!("round {}: {n} run(s) added: {why}", round + 1),
                    });
                    total.complete = false;
                    current = Some(d);
                    break;
                }
                Ok(Decided::Final(verdict, why)) => {
                    reporter.event(&super::Event::Round {
                        message: match verdict {
                            Verdict::Met => format!("targets: {why}"),
                            _ => format!("targets not all met, stopped: {why}"),
                        },
                    });
                    return Ok(total);
                }
                Ok(Decided::Incomplete) => {
                    // This shard's runs of a round decided by another shard (read after the
                    // decision's lock): run them.
                    let now = Campaign::open(&c.root)?;
                    if mine_pending(&now, opts.shard)? {
                        current = Some(now);
                        break;
                    }
                    // Another shard runs the rest: wait for it. A shard between its runs and
                    // a decision holds no lock for a moment: none seen twice in a row, this
                    // shard leaves the round to the others.
                    if others_running(c) {
                        idle = 0;
                    } else {
                        idle += 1;
                        if idle >= 2 {
                            reporter.event(&super::Event::Round {
                                message: "this shard's runs of the round are done; the round is decided when the other shards' runs are (by the last shard to finish, or `granular resume`)".into(),
                            });
                            return Ok(total);
                        }
                    }
                    std::thread::sleep(WAIT);
                }
                Err(CampaignError::Refused(m)) if others_running(c) || round_being_decided(c) => {
                    idle = 0;
                    tracing::debug!("waiting to decide the round: {m}");
                    std::thread::sleep(WAIT);
                }
                Err(e) => return Err(e),
            }
        }
    }
}

/// `dispatch::run`, waiting while another process decides a round (its exclusive lock keeps
/// shards out for a moment).
fn dispatch_when_free(
    c: &Campaign,
    opts: &super::RunOptions,
    reporter: &mut dyn super::Reporter,
) -> Result<super::Outcome, CampaignError> {
    let mut tries = 0;
    loop {
        match super::dispatch::run(c, opts, reporter) {
            Err(CampaignError::Refused(_)) if round_being_decided(c) && tries < 600 => {
                tries += 1;
                std::thread::sleep(WAIT / 5);
            }
            r => return r,
        }
    }
}

/// Whether runs of `shard` that the campaign asks for are not finished.
fn mine_pending(c: &Campaign, shard: super::plan::Shard) -> Result<bool, CampaignError> {
    let ledger = super::ledger::read_ledger(&c.root)?;
    let finished = super::ledger::finished_runs(&ledger.commits);
    Ok(c.plan
        .current_runs()
        .any(|r| shard.contains(r.run_id) && !finished.contains_key(&r.run_id)))
}

/// Whether a shard process (another than this one) holds its lock.
fn others_running(c: &Campaign) -> bool {
    let me = std::process::id();
    super::ledger::live_locks(&c.root)
        .iter()
        .any(|l| !l.is_exclusive() && l.pid != me)
}

/// Whether a process decides a round now.
fn round_being_decided(c: &Campaign) -> bool {
    super::ledger::live_locks(&c.root)
        .iter()
        .any(|l| l.is_exclusive() && l.purpose == Some(super::ledger::Purpose::Round))
}
