//! Error targets: a campaign whose manifest has `target` runs its points' pilot replicas
//! (`min_replicas`), then in rounds estimates each point's variance of every targeted derived
//! quantity and its cost per run, and adds replicas where they are needed, until every target
//! is met or `max_replicas`/`max_core_hours` stops it.
//!
//! **Deterministic and durable.** A round is decided only when every run the campaign asks
//! for is committed, from those runs' committed rows alone (replica order), under the
//! campaign's exclusive lock on `campaign.json` as read under it; the decision (the runs it
//! adds to the registry, and the record of what it saw) is written with `campaign.json`
//! atomically. So the replicas decided and every table are the same whatever the thread
//! count, the sharding, an interruption (kill -9 at any moment: an unwritten decision is
//! taken again, identically, from the same rows) or the machine. The shard's loop over the
//! rounds is `campaign::rounds`. The costs are the models'
//! estimates ([`crate::models::ModelParams::cost`], a function of the params), never a clock.
//!
//! **The rule.** For a point with n values of a quantity (sample standard deviation s), the
//! goal g (`sem_abs`, `sem_rel` x |mean|, the smaller where both are given) is met when
//! s / sqrt(n) <= g; the replicas it implies are n* = ceil(s^2 / g^2). An unmet point goes to
//! n*, at least n + ceil(n / 10) (no tail of rounds adding one replica each), at most 4 n (while
//! the variance is known from few replicas, an estimate too high is not followed at once) and
//! `max_replicas`. Under a budget, the
//! replicas that fit are given one at a time to the point where one more replica reduces the
//! error (in units of its goal) most per estimated core-second.

use std::collections::{BTreeMap, BTreeSet};

use serde::{Deserialize, Serialize};

use super::ledger::RunStatus;
use super::registry::Growth;
use super::{Campaign, CampaignError};
use crate::derived::{self, Quantities, Series};
use crate::manifest::{Target, TargetTime};

/// Layout version of the [`Rounds`] record in `campaign.json`.
pub const ROUNDS_FORMAT: u32 = 1;

/// Growth of an unmet point per round, at most (times its replicas).
const MAX_GROWTH_PER_ROUND: u32 = 4;
/// Growth of an unmet point per round, at least (a fraction of its replicas, and 1).
const MIN_GROWTH_PER_ROUND: f64 = 0.1;

/// The rounds of an error-target campaign, in `campaign.json`.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq, Default)]
pub struct Rounds {
    pub format: u32,
    /// The replicas decided per point (a point not here has the pilot).
    pub replicas: BTreeMap<u32, u32>,
    /// Every decision, in order.
    pub decisions: Vec<Decision>,
}

/// One decision: what the committed runs showed, and what was added.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct Decision {
    /// 1 for the decision after the pilot.
    pub round: u32,
    /// Runs registered by this decision.
    pub runs_added: u64,
    /// Their estimated cost (core-seconds of the models' cost estimates).
    pub core_seconds_added: f64,
    /// Estimated core-seconds of every run the campaign asks for after this decision.
    pub core_seconds_total: f64,
    pub points: Vec<PointState>,
    /// `continue`, `met` (every target met), `stopped` (some not met, and nothing added).
    pub verdict: Verdict,
    /// Why it stopped, or what it added, in words.
    pub why: String,
}

#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    Continue,
    Met,
    Stopped,
}

/// A point's targets as its committed runs show them.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct PointState {
    pub point_id: u32,
    /// Replicas asked when seen; `next`: after the decision.
    pub replicas: u32,
    pub next: u32,
    /// Estimated core-seconds of one run.
    pub cost: f64,
    pub targets: Vec<TargetState>,
}

/// One target of one point: at the output time where it is furthest from its goal.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct TargetState {
    /// Index into the manifest's `target`.
    pub target: usize,
    pub quantity: String,
    /// The time (None: a quantity without time).
    pub t: Option<f64>,
    /// Values (replicas with a value there).
    pub n: u32,
    pub mean: Option<f64>,
    pub sem: Option<f64>,
    /// The standard error asked for (None: not known yet, e.g. `sem_rel` of no value).
    pub goal: Option<f64>,
    pub met: bool,
    /// Replicas the variance implies (None with fewer than 2 values).
    pub needed: Option<u32>,
    /// Why it cannot be judged (no value, a run whose quantity could not be evaluated).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub problem: Option<String>,
}

impl TargetState {
    /// sem / goal (1 = just met); None where either is unknown.
    pub fn ratio(&self) -> Option<f64> {
        match (self.sem, self.goal) {
            (Some(s), Some(g)) if g > 0.0 => Some(s / g),
            _ => None,
        }
    }
}

/// The derived quantities of a campaign, compiled against its model's run tables (the
/// manifest was validated with them, so an error here is a corrupt campaign).
pub fn quantities(c: &Campaign) -> Result<Quantities, CampaignError> {
    derived::compile(&c.manifest.derived, &c.plan.model.run_tables()).map_err(|errs| {
        CampaignError::Refused(format!(
            "{}: the campaign's derived quantities do not compile: {errs:?}",
            c.root.display()
        ))
    })
}

/// Per current point, per target, the state its finished runs show (`finished`: the
/// ledger's finished runs). Runs not finished count as not there.
pub fn evaluate(
    c: &Campaign,
    finished: &BTreeMap<u64, RunStatus>,
) -> Result<Vec<PointState>, CampaignError> {
    let m = &c.manifest;
    let q = quantities(c)?;
    // The finished (done) current runs, by point, in replica order: what the summaries are of.
    let done = c.done_replicas(finished);
    let mut runs_of: BTreeMap<u32, Vec<(u32, u64)>> = BTreeMap::new();
    for (&run, &replica) in &done {
        runs_of
            .entry(c.plan.run(run).point_id)
            .or_default()
            .push((replica, run));
    }
    for runs in runs_of.values_mut() {
        runs.sort_unstable();
    }
    let data = c.data();
    let values = super::derived_tables::values(&c.view(&data, &done), &q)
        .map_err(|e| CampaignError::Io(e.to_string()))?;
    let index: BTreeMap<&str, usize> = q
        .list
        .iter()
        .enumerate()
        .map(|(i, x)| (x.name.as_str(), i))
        .collect();
    let mut out = Vec::new();
    for p in c.plan.points.iter().filter(|p| p.current) {
        let replicas = c.plan.replicas_of(p.point_id).unwrap_or(0);
        let runs = runs_of.get(&p.point_id).cloned().unwrap_or_default();
        let targets = m
            .target
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let k = index.get(t.quantity.as_str()).copied();
                let results: Vec<&Result<Series, derived::EvalError>> = runs
                    .iter()
                    .filter_map(|(_, run)| values.get(run))
                    .filter_map(|per_q| k.and_then(|k| per_q.get(k)))
                    .collect();
                let series: Vec<&Series> = results.iter().filter_map(|r| r.as_ref().ok()).collect();
                let mut s = target_state(i, t, &series);
                // A run whose quantity cannot be evaluated: the target cannot be judged.
                if let Some(Err(e)) = results.iter().find(|r| r.is_err()) {
                    s.problem = Some(e.to_string());
                    s.met = false;
                }
                s
            })
            .collect();
        out.push(PointState {
            point_id: p.point_id,
            replicas,
            next: replicas,
            cost: p.params.cost(),
            targets,
        });
    }
    Ok(out)
}

/// The values of each run at the target's times, grouped by time (in replica order).
fn at_times(t: &Target, series: &[&Series]) -> Vec<(Option<f64>, Vec<f64>)> {
    let mut by_time: BTreeMap<Option<u64>, (Option<f64>, Vec<f64>)> = BTreeMap::new();
    for s in series {
        let chosen: Vec<&(Option<f64>, f64)> = match t.t {
            TargetTime::TEnd => s.last().into_iter().collect(),
            TargetTime::At(x) => s
                .iter()
                .filter(|(tt, _)| tt.is_some_and(|tt| same_time(tt, x)))
                .collect(),
            TargetTime::After(x) => s
                .iter()
                .filter(|(tt, _)| tt.is_none_or(|tt| tt >= x || same_time(tt, x)))
                .collect(),
        };
        for (tt, v) in chosen {
            // Times of replicas of one point are the same bits; a total order on them.
            let key = tt.map(|x| x.to_bits() ^ (((x.to_bits() as i64) >> 63) as u64 >> 1));
            by_time.entry(key).or_insert((*tt, Vec::new())).1.push(*v);
        }
    }
    by_time.into_values().collect()
}

fn same_time(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(f64::MIN_POSITIVE)
}

/// One target's state from the series of a point's runs (replica order).
fn target_state(i: usize, t: &Target, series: &[&Series]) -> TargetState {
    let mut worst: Option<TargetState> = None;
    for (time, values) in at_times(t, series) {
        let n = values.len() as u32;
        let (mean, sem) = crate::math::stats::mean_sem(&values);
        let mean = (n > 0).then_some(mean);
        let goal = goal_of(t, mean);
        let met = matches!((sem, goal), (Some(s), Some(g)) if s <= g);
        let needed = match (sem, goal) {
            (Some(s), Some(g)) if g > 0.0 => {
                let var = s * s * n as f64;
                Some(((var / (g * g)).ceil().min(u32::MAX as f64) as u32).max(2))
            }
            _ => None,
        };
        let state = TargetState {
            target: i,
            quantity: t.quantity.clone(),
            t: time,
            n,
            mean,
            sem,
            goal,
            met,
            needed,
            problem: None,
        };
        let worse = match &worst {
            None => true,
            Some(w) => badness(&state) > badness(w),
        };
        if worse {
            worst = Some(state);
        }
    }
    worst.unwrap_or(TargetState {
        target: i,
        quantity: t.quantity.clone(),
        t: None,
        n: 0,
        mean: None,
        sem: None,
        goal: None,
        met: false,
        needed: None,
        problem: Some(match t.t {
            TargetTime::At(x) => format!("no value at t = {x} (not an output time?)"),
            _ => "no value yet".into(),
        }),
    })
}

/// How far a state is from its goal (unknown counts as furthest).
fn badness(s: &TargetState) -> f64 {
    match (s.ratio(), s.needed) {
        (Some(r), _) => r,
        _ => f64::INFINITY,
    }
}

/// The standard error a target asks for, given the mean.
fn goal_of(t: &Target, mean: Option<f64>) -> Option<f64> {
    let rel = match (t.sem_rel, mean) {
        (Some(r), Some(m)) => Some(r * m.abs()),
        (Some(_), None) => return None,
        (None, _) => None,
    };
    match (rel, t.sem_abs) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

/// The decision of a round from the states of every current point: replicas per point
/// (changed ones only) and the record.
pub fn decide(
    m: &crate::manifest::Manifest,
    mut points: Vec<PointState>,
    spent_core_seconds: f64,
) -> (BTreeMap<u32, u32>, Decision) {
    let max = m.max_replicas();
    let mut stops: Vec<String> = Vec::new();
    // What each unmet point would like.
    let mut want: BTreeMap<u32, u32> = BTreeMap::new();
    for p in &points {
        let unmet: Vec<&TargetState> = p.targets.iter().filter(|t| !t.met).collect();
        if unmet.is_empty() {
            continue;
        }
        if let Some(t) = unmet.iter().find(|t| t.problem.is_some()) {
            stops.push(format!(
                "point {}: {} cannot be judged: {}",
                p.point_id,
                t.quantity,
                t.problem.as_deref().unwrap_or_default()
            ));
            continue;
        }
        if unmet.iter().any(|t| t.n < 2 || t.needed.is_none()) {
            if unmet.iter().any(|t| t.n + 1 < p.replicas) {
                stops.push(format!(
                    "point {}: fewer than 2 values from {} replicas (runs failed?)",
                    p.point_id, p.replicas
                ));
                continue;
            }
            // A quantity of zero mean with only `sem_rel`, or one value: one more round.
            want.insert(p.point_id, (p.replicas + 1).min(max));
        } else {
            let needed = unmet
                .iter()
                .filter_map(|t| t.needed)
                .max()
                .unwrap_or(p.replicas + 1);
            let least =
                p.replicas + ((MIN_GROWTH_PER_ROUND * p.replicas as f64).ceil() as u32).max(1);
            let next = needed
                .max(least)
                .min(p.replicas.saturating_mul(MAX_GROWTH_PER_ROUND))
                .min(max);
            want.insert(p.point_id, next);
        }
        if p.replicas >= max {
            want.remove(&p.point_id);
            stops.push(format!(
                "point {}: max_replicas ({max}) reached",
                p.point_id
            ));
        }
    }
    // The budget: what fits, given to the best error reduction per core-second.
    let mut next: BTreeMap<u32, u32> = points.iter().map(|p| (p.point_id, p.replicas)).collect();
    let budget = m.max_core_hours.map(|h| h * 3600.0);
    let cost_of: BTreeMap<u32, f64> = points.iter().map(|p| (p.point_id, p.cost)).collect();
    let wanted: f64 = want
        .iter()
        .map(|(p, n)| (n - next[p]) as f64 * cost_of[p])
        .sum();
    match budget {
        Some(b) if spent_core_seconds + wanted > b => {
            let mut left = b - spent_core_seconds;
            let spread: BTreeMap<u32, f64> = points
                .iter()
                .map(|p| {
                    let r = p
                        .targets
                        .iter()
                        .filter_map(|t| t.ratio().map(|r| r * (t.n as f64).sqrt()))
                        .fold(0.0, f64::max);
                    (p.point_id, r)
                })
                .collect();
            loop {
                let best = want
                    .iter()
                    .filter(|(p, n)| next[p] < **n && cost_of[p] <= left)
                    .map(|(p, _)| {
                        let k = next[p] as f64;
                        let gain = spread[p] * (1.0 / k.sqrt() - 1.0 / (k + 1.0).sqrt());
                        (*p, gain / cost_of[p].max(1e-12))
                    })
                    .fold(None, |acc: Option<(u32, f64)>, x| match acc {
                        Some(a) if a.1 >= x.1 => Some(a),
                        _ => Some(x),
                    });
                let Some((p, _)) = best else { break };
                *next.get_mut(&p).unwrap() += 1;
                left -= cost_of[&p];
            }
            for (p, n) in &want {
                if next[p] < *n {
                    stops.push(format!(
                        "point {p}: max_core_hours ({}) does not allow {} more replica(s)",
                        m.max_core_hours.unwrap_or_default(),
                        n - next[p]
                    ));
                }
            }
        }
        _ => {
            for (p, n) in &want {
                next.insert(*p, *n);
            }
        }
    }
    let mut changed = BTreeMap::new();
    let mut runs_added = 0u64;
    let mut added = 0.0;
    for p in points.iter_mut() {
        p.next = next[&p.point_id];
        if p.next > p.replicas {
            changed.insert(p.point_id, p.next);
            runs_added += (p.next - p.replicas) as u64;
            added += (p.next - p.replicas) as f64 * p.cost;
        }
    }
    let all_met = points.iter().all(|p| p.targets.iter().all(|t| t.met));
    let (verdict, why) = if runs_added > 0 {
        let per: Vec<String> = changed
            .iter()
            .map(|(p, n)| format!("point {p}: {} -> {n}", next_before(&points, *p)))
            .collect();
        let short = if stops.is_empty() {
            String::new()
        } else {
            format!("; short of what the variances ask: {}", stops.join("; "))
        };
        (
            Verdict::Continue,
            format!("{runs_added} replica(s) added ({}){short}", per.join(", ")),
        )
    } else if all_met {
        (Verdict::Met, "every target is met".to_string())
    } else {
        (Verdict::Stopped, stops.join("; "))
    };
    let decision = Decision {
        round: 0,
        runs_added,
        core_seconds_added: added,
        core_seconds_total: spent_core_seconds + added,
        points,
        verdict,
        why,
    };
    (changed, decision)
}

fn next_before(points: &[PointState], p: u32) -> u32 {
    points
        .iter()
        .find(|x| x.point_id == p)
        .map_or(0, |x| x.replicas)
}

/// Estimated core-seconds of every run the campaign asks for now.
pub fn asked_core_seconds(c: &Campaign) -> f64 {
    c.plan
        .points
        .iter()
        .filter(|p| p.current)
        .map(|p| c.plan.replicas_of(p.point_id).unwrap_or(0) as f64 * p.params.cost())
        .sum()
}

/// What deciding a round did.
#[derive(Debug, Clone, PartialEq)]
pub enum Decided {
    /// Runs were added (the campaign asks for more): run them.
    More(u64),
    /// Nothing more to run: every target met, or stopped (the decision says why).
    Final(Verdict, String),
    /// The runs asked for are not all committed yet (other shards' runs).
    Incomplete,
}

/// Decide the next round of the campaign at `c.root`, under its exclusive lock on the
/// campaign as read under it (see the module). Nothing is written when the decision equals
/// the latest recorded one.
pub fn decide_round(c: &Campaign) -> Result<Decided, CampaignError> {
    let _lock = super::ledger::ExclusiveLock::acquire(&c.root, super::ledger::Purpose::Round)
        .map_err(|e| e.context("cannot decide the next round of replicas"))?;
    super::test_hook::pause("round-locked");
    let mut c = Campaign::open(&c.root)?;
    if !c.manifest.has_targets() {
        return Ok(Decided::Final(Verdict::Met, "no targets".into()));
    }
    let ledger = super::ledger::read_ledger(&c.root)?;
    let finished = super::ledger::finished_runs(&ledger.commits);
    if !c
        .plan
        .current_runs()
        .all(|r| finished.contains_key(&r.run_id))
    {
        return Ok(Decided::Incomplete);
    }
    let states = evaluate(&c, &finished)?;
    let spent = asked_core_seconds(&c);
    let (changed, mut decision) = decide(&c.manifest, states, spent);
    decision.round = c.rounds.decisions.len() as u32 + 1;
    if changed.is_empty() {
        let same = c.rounds.decisions.last().is_some_and(|d| {
            d.verdict == decision.verdict && d.why == decision.why && d.points == decision.points
        });
        let out = Decided::Final(decision.verdict, decision.why.clone());
        if !same {
            c.rounds.format = ROUNDS_FORMAT;
            c.rounds.decisions.push(decision);
            c.write_info()?;
        }
        return Ok(out);
    }
    let mut growth = Growth::default();
    let mut registry = c.plan.registry.clone();
    for (&p, &n) in &changed {
        registry.add_replicas(p, n, &mut growth);
    }
    c.rounds.format = ROUNDS_FORMAT;
    c.rounds.replicas.extend(changed);
    c.rounds.decisions.push(decision);
    c.plan.registry = registry;
    c.plan.decided = c.rounds.replicas.clone();
    super::test_hook::pause("round-decided");
    c.write_info()?;
    Ok(Decided::More(growth.new_runs.len() as u64))
}

/// Where a target campaign stands (for `status`, the report and the live page).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct TargetsStatus {
    /// Rounds decided so far.
    pub rounds: u32,
    /// The latest decision's verdict and why (None before the first decision).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<Verdict>,
    #[serde(default)]
    pub why: String,
    /// Per current point and target, from the runs committed so far.
    pub rows: Vec<TargetRow>,
    /// Estimated core-seconds (the models' cost estimates) of the runs done, and of the runs
    /// still expected (asked and not done, and those the variances imply beyond them).
    pub core_seconds_done: f64,
    pub core_seconds_left: f64,
    /// Replicas asked of the current points, and the fewest that the variances seen so far
    /// imply (per point the most any of its targets needs, at least `min_replicas`).
    pub replicas_asked: u64,
    pub replicas_implied: u64,
    /// Can the committed rows be read? (why not, else None).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub problem: Option<String>,
}

/// One target of one point, now.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct TargetRow {
    pub point_id: u32,
    pub point: String,
    /// The target in words: `gamma at t_end: sem_rel 0.001`.
    pub target: String,
    #[serde(flatten)]
    pub state: TargetState,
    /// Replicas done (with a value), asked now, and expected in the end (from the variance).
    pub replicas: u32,
    pub expected: u32,
}

/// A target in words.
pub fn describe(t: &Target) -> String {
    let at = match t.t {
        TargetTime::TEnd => "t_end".to_string(),
        TargetTime::At(x) => format!("t = {x}"),
        TargetTime::After(x) => format!("every t >= {x}"),
    };
    let mut goals = Vec::new();
    if let Some(r) = t.sem_rel {
        goals.push(format!("sem_rel {r}"));
    }
    if let Some(a) = t.sem_abs {
        goals.push(format!("sem_abs {a}"));
    }
    format!("{} at {at}: {}", t.quantity, goals.join(", "))
}

/// The targets' status of `c` from its finished runs (None without targets).
pub fn status(c: &Campaign, finished: &BTreeMap<u64, RunStatus>) -> Option<TargetsStatus> {
    if !c.manifest.has_targets() {
        return None;
    }
    let last = c.rounds.decisions.last();
    let (states, problem) = match evaluate(c, finished) {
        Ok(s) => (s, None),
        Err(e) => (Vec::new(), Some(e.to_string())),
    };
    let max = c.manifest.max_replicas();
    let mut rows = Vec::new();
    let (mut asked, mut implied) = (0u64, 0u64);
    let mut done_cs = 0.0;
    let mut left_cs = 0.0;
    for p in &states {
        let done = c
            .plan
            .current_runs()
            .filter(|r| r.point_id == p.point_id && finished.contains_key(&r.run_id))
            .count() as u32;
        let expected = p
            .targets
            .iter()
            .filter_map(|t| if t.met { Some(p.replicas) } else { t.needed })
            .max()
            .unwrap_or(p.replicas)
            .clamp(p.replicas, max.max(p.replicas));
        asked += p.replicas as u64;
        implied += p
            .targets
            .iter()
            .filter_map(|t| t.needed)
            .max()
            .unwrap_or(p.replicas)
            .max(c.manifest.min_replicas()) as u64;
        done_cs += done as f64 * p.cost;
        left_cs += expected.saturating_sub(done) as f64 * p.cost;
        for t in &p.targets {
            rows.push(TargetRow {
                point_id: p.point_id,
                point: c.plan.label(p.point_id),
                target: describe(&c.manifest.target[t.target]),
                state: t.clone(),
                replicas: p.replicas,
                expected,
            });
        }
    }
    // Once decided final, nothing is left.
    if last.is_some_and(|d| d.verdict != Verdict::Continue)
        && c.plan
            .current_runs()
            .all(|r| finished.contains_key(&r.run_id))
    {
        left_cs = 0.0;
    }
    Some(TargetsStatus {
        rounds: c.rounds.decisions.len() as u32,
        verdict: last.map(|d| d.verdict),
        why: last.map(|d| d.why.clone()).unwrap_or_default(),
        rows,
        core_seconds_done: done_cs,
        core_seconds_left: left_cs,
        replicas_asked: asked,
        replicas_implied: implied,
        problem,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn manifest(extra: &str) -> crate::manifest::Manifest {
        let text = format!(
            r#"{{"name": "t", "model": "dsmc", "seed": 1, "params": {{}},
                "derived": {{"g": "temperature"}},
                "target": [{{"quantity": "g", "sem_rel": 0.01}}] {extra}}}"#
        );
        serde_json::from_str(&text).unwrap()
    }

    /// A point with `n` values of mean 1 and standard deviation `sd` (goal 0.01).
    fn point(id: u32, n: u32, sd: f64, cost: f64) -> PointState {
        let t = Target {
            quantity: "g".into(),
            t: TargetTime::TEnd,
            sem_rel: Some(0.01),
            sem_abs: None,
        };
        // Values 1 +- sd alternating: sample sd = sd * sqrt(n / (n - 1)) for even n.
        let values: Vec<(Option<f64>, f64)> = (0..n)
            .map(|i| (Some(1.0), if i % 2 == 0 { 1.0 + sd } else { 1.0 - sd }))
            .collect();
        let series: Vec<Series> = values.iter().map(|v| vec![*v]).collect();
        let refs: Vec<&Series> = series.iter().collect();
        PointState {
            point_id: id,
            replicas: n,
            next: n,
            cost,
            targets: vec![target_state(0, &t, &refs)],
        }
    }

    /// The replicas a point's variance implies: n* = ceil(s^2 / goal^2).
    #[test]
    fn a_target_state_implies_its_replicas() {
        let p = point(0, 8, 0.05, 1.0);
        let t = &p.targets[0];
        let s2 = 0.05f64.powi(2) * 8.0 / 7.0;
        assert_eq!(t.needed, Some((s2 / 1e-4).ceil() as u32));
        assert!(!t.met);
        let met = point(0, 8, 0.01, 1.0);
        assert!(met.targets[0].met, "{:?}", met.targets[0]);
    }

    /// An unmet point grows to n*, but at most 4x and at least +10 %; a met point not at all;
    /// at max_replicas it stops and says so.
    #[test]
    fn rounds_grow_within_their_bounds() {
        let m = manifest("");
        // n* = 29 from 8: 29 (< 32).
        let (changed, d) = decide(
            &m,
            vec![point(0, 8, 0.05, 1.0), point(1, 8, 0.005, 1.0)],
            0.0,
        );
        assert_eq!(changed.get(&0), Some(&29));
        assert_eq!(changed.get(&1), None, "a met point got more");
        assert_eq!(d.verdict, Verdict::Continue);
        // n* ~ 1143 from 8: 4x = 32.
        let (changed, _) = decide(&m, vec![point(0, 8, 0.3, 1.0)], 0.0);
        assert_eq!(changed.get(&0), Some(&32));
        // Just short of the goal at 100: +10 %.
        let (changed, _) = decide(&m, vec![point(0, 100, 0.1005, 1.0)], 0.0);
        assert_eq!(changed.get(&0), Some(&110));
        // At max_replicas: stopped, named.
        let capped = manifest(r#", "max_replicas": 8"#);
        let (changed, d) = decide(&capped, vec![point(0, 8, 0.05, 1.0)], 0.0);
        assert!(changed.is_empty());
        assert_eq!(d.verdict, Verdict::Stopped);
        assert!(d.why.contains("max_replicas (8) reached"), "{}", d.why);
        // Every target met.
        let (changed, d) = decide(&m, vec![point(0, 8, 0.001, 1.0)], 0.0);
        assert!(changed.is_empty());
        assert_eq!(d.verdict, Verdict::Met);
    }

    /// Under a budget, the replicas that fit go where one more buys the most error reduction
    /// per core-second: of two points equally far from their goal, the cheap one.
    #[test]
    fn a_budget_goes_to_the_cheapest_error_reduction() {
        // 0.01 core-hours = 36 core-s; point 0 costs 1 core-s a run, point 1 10.
        let m = manifest(r#", "max_core_hours": 0.01"#);
        let (changed, d) = decide(
            &m,
            vec![point(0, 8, 0.05, 1.0), point(1, 8, 0.05, 10.0)],
            0.0,
        );
        let added = |p: u32| changed.get(&p).map_or(0, |n| n - 8);
        assert!(
            added(0) as f64 + 10.0 * added(1) as f64 <= 36.0,
            "{changed:?}"
        );
        assert!(added(0) > added(1), "{changed:?}");
        assert!(d.why.contains("max_core_hours"), "{}", d.why);
        // Nothing fits: stopped, the budget named.
        let (changed, d) = decide(&m, vec![point(0, 8, 0.05, 100.0)], 0.0);
        assert!(changed.is_empty());
        assert_eq!(d.verdict, Verdict::Stopped);
        assert!(d.why.contains("max_core_hours"), "{}", d.why);
    }

    /// `after`: the time furthest from its goal counts.
    #[test]
    fn after_takes_the_worst_time() {
        let t = Target {
            quantity: "g".into(),
            t: TargetTime::After(1.0),
            sem_rel: Some(0.01),
            sem_abs: None,
        };
        let series: Vec<Series> = (0..6)
            .map(|i| {
                let d = if i % 2 == 0 { 1.0 } else { -1.0 };
                vec![
                    (Some(0.5), 1.0 + 0.5 * d),
                    (Some(1.0), 1.0 + 0.001 * d),
                    (Some(2.0), 1.0 + 0.05 * d),
                ]
            })
            .collect();
        let refs: Vec<&Series> = series.iter().collect();
        let s = target_state(0, &t, &refs);
        assert_eq!(s.t, Some(2.0), "{s:?}");
        assert!(!s.met);
    }
}

/// The figures of a target campaign (none without targets): per target, `targets-error`
/// (`targets-error-1`, `-2`, ... when there are several): the standard error against its goal
/// (sem / goal, log axis) over the estimated core-seconds spent on each point (its runs x the
/// model's cost estimate of one run, log axis), one series per point with a marker at each
/// round's decision (from the rounds' records in `campaign.json`) and one at the current state
/// (from the `finished` runs), the 1/sqrt(n) line through the point's last marker (the error
/// falls as 1/sqrt(core-seconds), reaching the goal where the line crosses 1), and the goal
/// y = 1. Deterministic: a function of the records and the committed rows only.
pub fn figures(
    c: &Campaign,
    finished: &BTreeMap<u64, RunStatus>,
) -> Vec<(String, crate::plot::Figure)> {
    use crate::plot::{loglog, Figure, Series as PlotSeries};
    if !c.manifest.has_targets() {
        return Vec::new();
    }
    // The current state (not drawn if its rows cannot be read: the records still are).
    let now = evaluate(c, finished).unwrap_or_default();
    let mut done_of: BTreeMap<u32, u32> = BTreeMap::new();
    for r in c.plan.current_runs() {
        if finished.contains_key(&r.run_id) {
            *done_of.entry(r.point_id).or_default() += 1;
        }
    }
    let points: BTreeSet<u32> = c.plan.current_runs().map(|r| r.point_id).collect();
    let several = c.manifest.target.len() > 1;
    let mut out = Vec::new();
    for (k, target) in c.manifest.target.iter().enumerate() {
        // Per point, its markers (x = core-seconds spent, y = sem / goal) in order.
        let marker = |p: &PointState, runs: u32| -> Option<(f64, f64)> {
            let t = p.targets.iter().find(|t| t.target == k)?;
            let (x, y) = (runs as f64 * p.cost, t.ratio()?);
            (x.is_finite() && x > 0.0 && y.is_finite() && y > 0.0).then_some((x, y))
        };
        let mut series = Vec::new();
        let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
        for &pid in &points {
            let mut marks: Vec<(f64, f64)> = c
                .rounds
                .decisions
                .iter()
                .filter_map(|d| d.points.iter().find(|p| p.point_id == pid))
                .filter_map(|p| marker(p, p.replicas))
                .collect();
            if let Some(p) = now.iter().find(|p| p.point_id == pid) {
                if let Some(m) = marker(p, done_of.get(&pid).copied().unwrap_or(0)) {
                    if marks.last() != Some(&m) {
                        marks.push(m);
                    }
                }
            }
            let mut line = Vec::new();
            if let Some(&(x0, y0)) = marks.last() {
                // sem = y0 sqrt(x0 / x): from the point's first marker to where it meets the
                // goal (at most 100 times further).
                let first = marks.iter().map(|m| m.0).fold(x0, f64::min);
                let end = (x0 * y0 * y0).clamp(x0, 100.0 * x0);
                let (xa, xb) = (first.min(x0 / 2.0), if end > x0 { end } else { 2.0 * x0 });
                line = [xa, xb]
                    .iter()
                    .map(|&x| (x, y0 * (x0 / x).sqrt(), 0.0))
                    .collect();
                for &(x, _, _) in &line {
                    lo = lo.min(x);
                    hi = hi.max(x);
                }
            }
            series.push(PlotSeries {
                label: c.plan.label(pid),
                points: marks.iter().map(|&(x, y)| (x, y, 0.0)).collect(),
                line: false,
            });
            series.push(PlotSeries {
                label: String::new(),
                points: line,
                line: true,
            });
        }
        if hi <= 0.0 {
            continue;
        }
        let refs = series.len();
        series.push(PlotSeries {
            label: "goal (sem = goal)".into(),
            points: vec![(lo, 1.0, 0.0), (hi, 1.0, 0.0)],
            line: true,
        });
        let fig = loglog(
            Figure::new(
                format!(
                    "error against the goal: {} (lines: sem ~ 1/sqrt(n))",
                    describe(target)
                ),
                "estimated core-seconds spent on the point",
                "sem / goal",
                series,
            )
            .with_references_from(refs),
        );
        let name = if several {
            format!("targets-error-{}", k + 1)
        } else {
            "targets-error".to_string()
        };
        out.push((name, fig));
    }
    out
}
