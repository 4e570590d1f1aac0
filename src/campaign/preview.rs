//! What a manifest would do to a campaign directory, before any work (`granular plan`,
//! `run --dry-run`): the points and runs it adds, the runs it continues to a longer horizon,
//! what is kept, and an estimate of the cost: the models' cost model (`ModelParams::cost`,
//! CPU seconds on the reference machine) calibrated to this machine ([`Calibration`]: from
//! the campaign's finished runs, else a short probe run, else the reference as it is), as
//! core-hours and as wall time at the threads given ([`Estimate`]).

use std::collections::{BTreeMap, BTreeSet, HashMap};

use serde::Serialize;

use super::ledger::{self, RunStatus};
use super::plan::Plan;
use super::registry::Growth;
use super::tables::{RunsTableCols, RUNS};
use super::{Campaign, CampaignError};
use crate::models::{ModelParams, WORK_CHUNK};

/// The plan of a manifest against a campaign directory.
#[derive(Serialize, Clone, Debug, Default, PartialEq)]
pub struct Preview {
    /// The directory holds no campaign yet.
    pub new_campaign: bool,
    /// How the runs draw their random numbers: a new campaign's is this granular's current
    /// version, a campaign's own is kept when it grows.
    pub stream_version: crate::rng::StreamVersion,
    /// Points the manifest adds (ids).
    pub new_points: Vec<u32>,
    /// The same, described.
    pub points: Vec<NewPoint>,
    /// Runs the manifest adds: new points' runs, new replicas of existing points.
    pub new_runs: u64,
    /// Of those, new replicas (or seeds) of points that existed.
    pub new_replicas: u64,
    /// Of those, runs that continue a finished run from its final state (a longer horizon).
    pub continued_runs: u64,
    /// Runs the latest manifest asks for that are finished (kept, never redone).
    pub kept_runs: u64,
    /// Runs the latest manifest asks for that are not finished (new ones included).
    pub to_run: u64,
    /// Registered points the manifest no longer lists (kept, with their finished runs): those
    /// leaving now ([`Preview::leaving_points`]) and those earlier manifests left.
    pub retired_points: Vec<u32>,
    /// Points of the campaign's latest manifest that this one no longer lists (they stay in
    /// the campaign: see [`LEAVING_MEANS`]).
    pub leaving_points: Vec<LeavingPoint>,
    /// Runs of the campaign's latest manifest that this one no longer asks for at points it
    /// still lists (replicas beyond its count, seeds it no longer lists), per point.
    pub leaving_runs: Vec<LeavingRuns>,
    /// The expected cost of the runs this manifest adds (new points' and new replicas' runs,
    /// continued runs as the part beyond the run they continue) and of the new points'
    /// theory: the new work, beside `estimate` (every run still to run).
    pub new_work: Estimate,
    /// The kinetic theory of the new points (computed before the runs), as the model
    /// estimates it from their params.
    pub theory: TheoryWork,
    /// The cost of the runs to run (and of the new points' theory), calibrated to this
    /// machine.
    pub estimate: Estimate,
    /// With error targets: the pilot and what the rounds may add.
    pub targets: Option<TargetPilot>,
    pub notes: Vec<String>,
    /// The runs to run, in run order.
    pub runs: Vec<PlannedRun>,
}

/// The kinetic-theory step of some points, as their model estimates it
/// (`ModelParams::theory_estimate`; none for models without theory).
#[derive(Serialize, Clone, Debug, Default, PartialEq)]
pub struct TheoryWork {
    /// Points with a theory to compute.
    pub points: u64,
    /// Estimated CPU seconds in all.
    pub seconds: f64,
    /// The point of the largest estimate: id, CPU seconds, peak bytes.
    pub largest: Option<(u32, f64, f64)>,
}

/// The kinetic theory of more CPU seconds than this, or of a point of more bytes than
/// [`THEORY_WARN_BYTES`], is worth a warning (`validate`, `plan`, `run`).
pub const THEORY_WARN_SECONDS: f64 = 60.0;
/// See [`THEORY_WARN_SECONDS`].
pub const THEORY_WARN_BYTES: f64 = 2e9;

/// The estimated kinetic theory of `points` of `plan`.
pub fn theory_work(plan: &Plan, points: impl IntoIterator<Item = u32>) -> TheoryWork {
    let mut w = TheoryWork::default();
    for id in points {
        let Some(p) = plan.points.get(id as usize) else {
            continue;
        };
        let e = p.params.theory_estimate();
        if e.seconds <= 0.0 {
            continue;
        }
        w.points += 1;
        w.seconds += e.seconds;
        if w.largest.is_none_or(|(_, s, _)| e.seconds > s) {
            w.largest = Some((id, e.seconds, e.bytes));
        }
    }
    w
}

impl TheoryWork {
    /// `~12 CPU s for 3 point(s) (largest: point 2, ~10 CPU s, ~1.2 GB)`.
    pub fn text(&self) -> String {
        let gb = |b: f64| crate::models::bytes_text(b.min(u64::MAX as f64) as u64);
        let mut s = format!(
            "~{} CPU s for {} point(s)",
            seconds_text(self.seconds),
            self.points
        );
        match self.largest {
            Some((id, secs, bytes)) if self.points > 1 => s.push_str(&format!(
                " (largest: point {id}, ~{} CPU s, ~{})",
                seconds_text(secs),
                gb(bytes)
            )),
            Some((_, _, bytes)) => s.push_str(&format!(" (~{})", gb(bytes))),
            None => {}
        }
        s
    }

    /// A warning when the theory is long or large (see [`THEORY_WARN_SECONDS`]).
    pub fn warning(&self) -> Option<String> {
        let bytes = self.largest.map_or(0.0, |(_, _, b)| b);
        (self.seconds > THEORY_WARN_SECONDS || bytes > THEORY_WARN_BYTES).then(|| {
            format!(
                "the kinetic theory, computed before the runs, is estimated at {}",
                self.text()
            )
        })
    }
}

fn seconds_text(s: f64) -> String {
    if s >= 100.0 {
        format!("{s:.0}")
    } else if s >= 1.0 {
        format!("{s:.1}")
    } else {
        format!("{s:.2}")
    }
}

/// A point a manifest adds.
#[derive(Serialize, Clone, Debug, Default, PartialEq)]
pub struct NewPoint {
    pub point_id: u32,
    /// Its swept values (`key=value, ...`).
    pub label: String,
    /// The registered point it is closest to (the one it continues, if any), and how the
    /// params differ from that point's (`key: old -> new`, dotted keys).
    pub nearest: Option<u32>,
    pub differs: Vec<String>,
    /// The point whose finished runs its runs continue (a longer horizon).
    pub continues: Option<u32>,
}

/// What happens to the points and runs that leave the manifest, in words (`plan` prints
/// it): what the campaign does with runs its latest manifest does not ask for.
pub const LEAVING_MEANS: &str = "they stay in the campaign, nothing is deleted: finished runs keep their rows in the tables, unfinished ones are not run (status counts them as dropped), summaries and figures cover only the manifest's runs, and a later manifest that lists them again takes them back with their finished runs";

/// A point of the campaign's latest manifest that the new manifest no longer lists.
#[derive(Serialize, Clone, Debug, Default, PartialEq)]
pub struct LeavingPoint {
    pub point_id: u32,
    /// Its swept values in the campaign's latest manifest (`key=value, ...`).
    pub label: String,
    /// The runs the campaign's latest manifest asked of it, and how many are finished.
    pub runs: u64,
    pub finished: u64,
    /// The nearest point of the new manifest (see `plan`'s distance) and how it differs from
    /// the leaving point (`key: leaving -> nearest`).
    pub nearest: Option<u32>,
    pub differs: Vec<String>,
    /// The new point (a longer horizon) whose runs continue its finished runs.
    pub continued_by: Option<u32>,
}

/// Runs of a point still in the manifest that it no longer asks for.
#[derive(Serialize, Clone, Debug, Default, PartialEq)]
pub struct LeavingRuns {
    pub point_id: u32,
    pub label: String,
    /// Their replica numbers and run ids, in run order, and how many are finished.
    pub replicas: Vec<u32>,
    pub run_ids: Vec<u64>,
    pub finished: u64,
}

/// A run to run.
#[derive(Serialize, Clone, Debug, PartialEq)]
pub struct PlannedRun {
    pub run_id: u64,
    pub point_id: u32,
    pub replica: u32,
    pub seed: u64,
    /// The finished run it continues from its final state.
    pub continues: Option<u64>,
}

/// At most this many registered points are searched for a new point's nearest one.
const NEAREST_SEARCH: usize = 2000;

/// How the cost estimate is made: the worker threads the runs would have, and whether a
/// short probe run may calibrate the cost model when the campaign has no finished run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EstimateOptions {
    /// Worker threads (at least 1).
    pub threads: usize,
    pub probe: bool,
}

/// Preview `growth` (the result of `Campaign::prepare`) on campaign `c` (as it would be).
pub fn preview(
    c: &Campaign,
    growth: &Growth,
    new_campaign: bool,
    opts: EstimateOptions,
) -> Result<Preview, CampaignError> {
    let finished = if new_campaign {
        BTreeMap::new()
    } else {
        ledger::finished_runs(&ledger::read_commits(&c.root)?)
    };
    let current: Vec<_> = c.plan.current_runs().collect();
    let kept = current
        .iter()
        .filter(|r| finished.contains_key(&r.run_id))
        .count() as u64;
    let new: std::collections::BTreeSet<u32> = growth.new_points.iter().copied().collect();
    // The point each new point continues (the first continued run of it names it).
    let mut continues: HashMap<u32, u32> = HashMap::new();
    for (run, old) in &growth.continued {
        continues
            .entry(c.plan.run(*run).point_id)
            .or_insert_with(|| c.plan.run(*old).point_id);
    }
    let nearest = Nearest::new(
        c.plan
            .registry
            .points
            .iter()
            .filter(|p| !new.contains(&p.id))
            .take(NEAREST_SEARCH)
            .map(|p| (p.id, flatten(&p.params))),
    );
    let mut p = Preview {
        new_campaign,
        stream_version: c.stream,
        new_points: growth.new_points.clone(),
        points: growth
            .new_points
            .iter()
            .map(|&id| describe(c, id, continues.get(&id).copied(), &nearest))
            .collect(),
        new_runs: growth.new_runs.len() as u64,
        new_replicas: growth
            .new_runs
            .iter()
            .filter(|(point, _, _)| !new.contains(point))
            .count() as u64,
        continued_runs: growth.continued.len() as u64,
        kept_runs: kept,
        to_run: current.len() as u64 - kept,
        retired_points: growth.retired_points.clone(),
        theory: theory_work(&c.plan, growth.new_points.iter().copied()),
        notes: growth.notes.clone(),
        ..Preview::default()
    };
    p.runs = current
        .iter()
        .filter(|r| !finished.contains_key(&r.run_id))
        .map(|r| PlannedRun {
            run_id: r.run_id,
            point_id: r.point_id,
            replica: r.replica,
            seed: r.seed,
            continues: r.continues,
        })
        .collect();
    let walls = if new_campaign {
        BTreeMap::new()
    } else {
        done_walls(c)?
    };
    let work = runs_work(c, &current, &finished);
    let calibration = if !walls.is_empty() {
        from_finished_runs(c, &walls)
    } else if opts.probe {
        probe(&work, c.stream)
    } else {
        Calibration::reference("--no-probe and no finished run")
    };
    p.estimate = estimate_costs(
        work.iter().map(|(w, n)| (w.cost(), *n)),
        &p.theory,
        opts.threads,
        calibration,
    );
    let added: BTreeSet<u64> = growth.new_runs.iter().map(|(_, _, r)| *r).collect();
    let added: Vec<_> = current
        .iter()
        .filter(|r| added.contains(&r.run_id))
        .copied()
        .collect();
    p.new_work = estimate_costs(
        runs_work(c, &added, &finished)
            .iter()
            .map(|(w, n)| (w.cost(), *n)),
        &p.theory,
        opts.threads,
        p.estimate.calibration.clone(),
    );
    if !new_campaign {
        leaving(c, growth, &finished, &mut p)?;
    }
    if c.manifest.has_targets() {
        let per_point = c.manifest.min_replicas();
        let most = c.manifest.max_replicas();
        // Each current point at most `max_replicas` runs in all.
        let mut points: BTreeMap<u32, f64> = BTreeMap::new();
        for r in &current {
            points
                .entry(r.point_id)
                .or_insert_with(|| c.plan.points[r.point_id as usize].params.cost());
        }
        let factor = p.estimate.calibration.factor;
        let full: f64 = points.values().map(|s| s * most as f64 * factor).sum();
        // Where runs are finished: the replicas each point's variances imply, and their cost.
        let expected = if finished.is_empty() {
            Vec::new()
        } else {
            super::targets::status(c, &finished)
                .map(|t| {
                    let mut per: BTreeMap<u32, ExpectedReplicas> = BTreeMap::new();
                    for r in &t.rows {
                        let e = per.entry(r.point_id).or_insert(ExpectedReplicas {
                            point_id: r.point_id,
                            point: r.point.clone(),
                            replicas: r.replicas,
                            expected: r.expected,
                            core_hours_left: 0.0,
                        });
                        e.expected = e.expected.max(r.expected);
                    }
                    for e in per.values_mut() {
                        let done = c
                            .plan
                            .current_runs()
                            .filter(|r| {
                                r.point_id == e.point_id && finished.contains_key(&r.run_id)
                            })
                            .count() as u32;
                        e.core_hours_left = e.expected.saturating_sub(done) as f64
                            * points.get(&e.point_id).copied().unwrap_or(0.0)
                            * factor
                            / 3600.0;
                    }
                    per.into_values().collect()
                })
                .unwrap_or_default()
        };
        p.targets = Some(TargetPilot {
            expected,
            min_replicas: per_point,
            max_replicas: most,
            pilot_runs: p.estimate.runs,
            pilot_core_hours: p.estimate.core_hours,
            max_runs: points.len() as u64 * most as u64,
            max_core_hours: full / 3600.0,
            budget_core_hours: c.manifest.max_core_hours,
        });
    }
    Ok(p)
}

/// The points and runs of the campaign's latest manifest (the campaign as it is on disk)
/// that the new manifest (`c`, the campaign as it would be) no longer asks for.
fn leaving(
    c: &Campaign,
    growth: &Growth,
    finished: &BTreeMap<u64, RunStatus>,
    p: &mut Preview,
) -> Result<(), CampaignError> {
    let before = Campaign::open(&c.root)?;
    let reg = &c.plan.registry.points;
    let mut continued_by: HashMap<u32, u32> = HashMap::new();
    for (run, old) in &growth.continued {
        continued_by
            .entry(c.plan.run(*old).point_id)
            .or_insert_with(|| c.plan.run(*run).point_id);
    }
    let mut points: BTreeMap<u32, LeavingPoint> = BTreeMap::new();
    let mut runs: BTreeMap<u32, LeavingRuns> = BTreeMap::new();
    for r in before.plan.current_runs() {
        let now = c.plan.point(r.point_id);
        let done = u64::from(finished.contains_key(&r.run_id));
        if !now.current {
            let lp = points.entry(r.point_id).or_insert_with(|| LeavingPoint {
                point_id: r.point_id,
                label: before.plan.label(r.point_id),
                continued_by: continued_by.get(&r.point_id).copied(),
                ..LeavingPoint::default()
            });
            lp.runs += 1;
            lp.finished += done;
        } else if !c.plan.is_current(&c.plan.run(r.run_id)) {
            let lr = runs.entry(r.point_id).or_insert_with(|| LeavingRuns {
                point_id: r.point_id,
                label: c.plan.label(r.point_id),
                ..LeavingRuns::default()
            });
            lr.replicas.push(r.replica);
            lr.run_ids.push(r.run_id);
            lr.finished += done;
        }
    }
    if !points.is_empty() {
        let nearest = Nearest::new(
            c.plan
                .points
                .iter()
                .filter(|q| q.current)
                .take(NEAREST_SEARCH)
                .map(|q| (q.point_id, flatten(&reg[q.point_id as usize].params))),
        );
        for lp in points.values_mut() {
            let mine = flatten(&reg[lp.point_id as usize].params);
            lp.nearest = nearest.find(&mine);
            lp.differs = lp
                .nearest
                .map(|n| differences(&mine, &flatten(&reg[n as usize].params)))
                .unwrap_or_default();
        }
    }
    p.leaving_points = points.into_values().collect();
    p.leaving_runs = runs.into_values().collect();
    Ok(())
}

/// A new point: the registered point it continues or is closest to (see [`Nearest`]), and
/// the differences.
fn describe(c: &Campaign, id: u32, continues: Option<u32>, nearest: &Nearest) -> NewPoint {
    let reg = &c.plan.registry.points;
    let mine = flatten(&reg[id as usize].params);
    let nearest = continues.or_else(|| nearest.find(&mine));
    NewPoint {
        point_id: id,
        label: c.plan.label(id),
        nearest,
        differs: nearest
            .map(|other| differences(&flatten(&reg[other as usize].params), &mine))
            .unwrap_or_default(),
        continues,
    }
}

/// The leaves where `to` differs from `from`, `key: from -> to` (dotted paths with list
/// indices, `(absent)` where one side has no such key), in key order.
pub(crate) fn differences(
    from: &BTreeMap<String, String>,
    to: &BTreeMap<String, String>,
) -> Vec<String> {
    let keys: BTreeSet<&String> = from.keys().chain(to.keys()).collect();
    let show = |v: Option<&String>| v.cloned().unwrap_or_else(|| "(absent)".into());
    keys.into_iter()
        .filter(|k| from.get(*k) != to.get(*k))
        .map(|k| format!("{k}: {} -> {}", show(from.get(k)), show(to.get(k))))
        .collect()
}

/// The relative difference of two leaves (compact JSON): |a - b| / max(|a|, |b|) where both
/// are numbers, 0 otherwise (or where both are 0).
fn relative(a: Option<f64>, b: Option<f64>) -> f64 {
    match (a, b) {
        (Some(a), Some(b)) => {
            let m = a.abs().max(b.abs());
            if m > 0.0 && m.is_finite() {
                (a - b).abs() / m
            } else {
                0.0
            }
        }
        _ => 0.0,
    }
}

/// A leaf's number, if it is one (compact JSON: a string leaf is quoted, so never parses).
fn number(leaf: &str) -> Option<f64> {
    leaf.parse::<f64>().ok().filter(|x| x.is_finite())
}

/// The distance between two points' flattened params, the smaller the nearer: first the
/// number of differing leaf keys (a key on one side only counts), then the sum over the
/// differing leaves that are numbers on both sides of |a - b| / max(|a|, |b|). ([`Nearest`]
/// ranks by it; the tests compare the two.)
#[cfg(test)]
fn distance(a: &BTreeMap<String, String>, b: &BTreeMap<String, String>) -> (usize, f64) {
    let keys: BTreeSet<&String> = a.keys().chain(b.keys()).collect();
    let mut d = (0usize, 0.0f64);
    for k in keys {
        let (x, y) = (a.get(k), b.get(k));
        if x != y {
            d.0 += 1;
            d.1 += relative(x.and_then(|s| number(s)), y.and_then(|s| number(s)));
        }
    }
    d
}

/// The search for a point's nearest registered point over the candidates (the first
/// [`NEAREST_SEARCH`] registered points that are not new): the smallest [`distance`] (the
/// fewest differing leaf keys, then the smallest sum of relative numeric differences), the
/// smallest point id among equals. Built once per preview so that a plan of many new points
/// stays linear in them. Each candidate's values are interned per key; only the keys whose
/// values vary among the candidates can tell them apart (the others add the same to every
/// distance), and the candidates at distance 0 or 1 of a point on those keys are found by
/// hashing (the usual case: a sweep grown by a value or a key); otherwise the candidates are
/// scanned.
struct Nearest {
    ids: Vec<u32>,
    /// Every key of a candidate, and per key its values' numbers (0: no value).
    keys: HashMap<String, (usize, HashMap<String, u32>)>,
    /// Per varying key (in `varying` order), the number of each value number (index 0: none).
    numbers: Vec<Vec<Option<f64>>>,
    /// Per candidate, the value numbers of the varying keys (in `varying` order).
    rows: Vec<Vec<u32>>,
    /// The keys whose values vary among the candidates (indices into the key numbering).
    varying: Vec<usize>,
    /// The smallest candidate index per exact row, and every candidate per (masked key, row
    /// with that key's value replaced by `MASKED`).
    exact: HashMap<Vec<u32>, usize>,
    masked: HashMap<(usize, Vec<u32>), Vec<usize>>,
}

const MASKED: u32 = u32::MAX - 1;
const UNSEEN: u32 = u32::MAX;

impl Nearest {
    fn new(candidates: impl Iterator<Item = (u32, BTreeMap<String, String>)>) -> Nearest {
        let mut keys: HashMap<String, (usize, HashMap<String, u32>)> = HashMap::new();
        let mut ids = Vec::new();
        let mut full: Vec<Vec<(usize, u32)>> = Vec::new();
        for (id, flat) in candidates {
            ids.push(id);
            let mut row = Vec::with_capacity(flat.len());
            for (k, v) in flat {
                let n = keys.len();
                let (ki, values) = keys.entry(k).or_insert_with(|| (n, HashMap::new()));
                let next = values.len() as u32 + 1;
                let vi = *values.entry(v).or_insert(next);
                row.push((*ki, vi));
            }
            full.push(row);
        }
        let n_keys = keys.len();
        let dense: Vec<Vec<u32>> = full
            .iter()
            .map(|row| {
                let mut d = vec![0u32; n_keys];
                for &(k, v) in row {
                    d[k] = v;
                }
                d
            })
            .collect();
        // In key order, so that the sums of relative differences are made in one order.
        let mut names: Vec<(&str, usize)> =
            keys.iter().map(|(k, (i, _))| (k.as_str(), *i)).collect();
        names.sort_unstable();
        let varying: Vec<usize> = names
            .iter()
            .map(|(_, k)| *k)
            .filter(|&k| {
                let first = dense.first().map_or(0, |d| d[k]);
                dense.iter().any(|d| d[k] != first)
            })
            .collect();
        // The numbers of the values of each key, by value number.
        let mut by_key: Vec<Vec<Option<f64>>> = vec![Vec::new(); n_keys];
        for (ki, values) in keys.values() {
            let mut nums = vec![None; values.len() + 1];
            for (v, vi) in values {
                nums[*vi as usize] = number(v);
            }
            by_key[*ki] = nums;
        }
        let numbers: Vec<Vec<Option<f64>>> = varying
            .iter()
            .map(|&k| std::mem::take(&mut by_key[k]))
            .collect();
        let rows: Vec<Vec<u32>> = dense
            .iter()
            .map(|d| varying.iter().map(|&k| d[k]).collect())
            .collect();
        let mut exact = HashMap::new();
        let mut masked: HashMap<(usize, Vec<u32>), Vec<usize>> = HashMap::new();
        for (c, row) in rows.iter().enumerate() {
            exact.entry(row.clone()).or_insert(c);
            for j in 0..row.len() {
                let mut m = row.clone();
                m[j] = MASKED;
                masked.entry((j, m)).or_default().push(c);
            }
        }
        Nearest {
            ids,
            keys,
            numbers,
            rows,
            varying,
            exact,
            masked,
        }
    }

    /// The nearest candidate to a point with flattened params `flat` (None without
    /// candidates).
    fn find(&self, flat: &BTreeMap<String, String>) -> Option<u32> {
        if self.ids.is_empty() {
            return None;
        }
        // The point's value number per key (UNSEEN: a value no candidate has there).
        let mut mine = vec![0u32; self.keys.len()];
        let mut mine_num: Vec<Option<f64>> = vec![None; self.keys.len()];
        for (k, v) in flat {
            if let Some((ki, values)) = self.keys.get(k) {
                mine[*ki] = values.get(v).copied().unwrap_or(UNSEEN);
                mine_num[*ki] = number(v);
            }
        }
        let row: Vec<u32> = self.varying.iter().map(|&k| mine[k]).collect();
        let nums: Vec<Option<f64>> = self.varying.iter().map(|&k| mine_num[k]).collect();
        if let Some(&c) = self.exact.get(&row) {
            return Some(self.ids[c]);
        }
        // The relative difference of candidate `c` from the point on varying key `j`.
        let rel = |c: usize, j: usize| relative(self.numbers[j][self.rows[c][j] as usize], nums[j]);
        let better = |a: (usize, f64, u32), b: (usize, f64, u32)| {
            a.0.cmp(&b.0)
                .then(a.1.total_cmp(&b.1))
                .then(a.2.cmp(&b.2))
                .is_lt()
        };
        let mut best: Option<(usize, f64, u32)> = None;
        for j in 0..row.len() {
            let mut m = row.clone();
            m[j] = MASKED;
            for &c in self.masked.get(&(j, m)).into_iter().flatten() {
                let d = (1, rel(c, j), self.ids[c]);
                if best.is_none_or(|b| better(d, b)) {
                    best = Some(d);
                }
            }
        }
        if let Some((_, _, id)) = best {
            return Some(id);
        }
        // Every candidate is at distance >= 2: scan them all.
        for (c, r) in self.rows.iter().enumerate() {
            let mut d = (0usize, 0.0f64, self.ids[c]);
            for (j, (a, b)) in r.iter().zip(&row).enumerate() {
                if a != b {
                    d.0 += 1;
                    d.1 += rel(c, j);
                }
            }
            if best.is_none_or(|b| better(d, b)) {
                best = Some(d);
            }
        }
        best.map(|(_, _, id)| id)
    }
}

/// A number as a reader writes it: a whole number without `.0` (`16`, not the `16.0` of a
/// float), others as JSON has them (`0.5`, `1e-7`).
fn number_text(n: &serde_json::Number) -> String {
    match n.as_f64() {
        Some(x) if n.is_f64() && x.fract() == 0.0 && x.abs() < 1e15 => format!("{}", x as i64),
        _ => n.to_string(),
    }
}

/// A JSON value as dotted keys (list elements by their index, from 0:
/// `species.list.1.mass`) and compact JSON leaves (numbers, strings, booleans, null, empty
/// lists and objects; whole numbers without `.0`: [`number_text`]).
pub(crate) fn flatten(v: &serde_json::Value) -> BTreeMap<String, String> {
    fn walk(prefix: &str, v: &serde_json::Value, out: &mut BTreeMap<String, String>) {
        let key = |k: &str| {
            if prefix.is_empty() {
                k.to_string()
            } else {
                format!("{prefix}.{k}")
            }
        };
        match v {
            serde_json::Value::Object(o) if !o.is_empty() => {
                for (k, x) in o {
                    walk(&key(k), x, out);
                }
            }
            serde_json::Value::Array(a) if !a.is_empty() => {
                for (i, x) in a.iter().enumerate() {
                    walk(&key(&i.to_string()), x, out);
                }
            }
            serde_json::Value::Number(n) => {
                out.insert(prefix.to_string(), number_text(n));
            }
            leaf => {
                out.insert(prefix.to_string(), leaf.to_string());
            }
        }
    }
    let mut out = BTreeMap::new();
    walk("", v, &mut out);
    out
}

/// Wall seconds of the done runs, by run id.
fn done_walls(c: &Campaign) -> Result<BTreeMap<u64, f64>, CampaignError> {
    let mut out = BTreeMap::new();
    let data = c.data();
    let batches = data
        .read(RUNS)
        .map_err(|e| CampaignError::Io(e.to_string()))?;
    for b in batches {
        let io = |e: crate::store::parquet_io::StoreError| CampaignError::Io(e.to_string());
        let RunsTableCols {
            run_id: run,
            status,
            wall_seconds: wall,
            ..
        } = RunsTableCols::read(&b, RUNS).map_err(io)?;
        for i in 0..b.num_rows() {
            if status.value(i) == "done" {
                out.insert(run.value(i), wall.value(i));
            }
        }
    }
    Ok(out)
}

/// With error targets: the runs of the pilot (`min_replicas` per point) are what the
/// estimate counts; the replicas beyond it are decided in rounds from the pilot's variances,
/// up to `max_replicas` per point (and `max_core_hours`).
#[derive(Serialize, Clone, Debug, PartialEq)]
pub struct TargetPilot {
    pub min_replicas: u32,
    pub max_replicas: u32,
    pub pilot_runs: u64,
    pub pilot_core_hours: f64,
    /// Every current point at `max_replicas`: the most the rounds can reach.
    pub max_runs: u64,
    pub max_core_hours: f64,
    /// The manifest's budget.
    pub budget_core_hours: Option<f64>,
    /// Of a campaign with finished runs: per point, the replicas its variances imply (see
    /// `targets::status`) and the core-hours of the runs still to do for them.
    pub expected: Vec<ExpectedReplicas>,
}

/// A point of a target campaign: the replicas asked now and expected in the end.
#[derive(Serialize, Clone, Debug, PartialEq)]
pub struct ExpectedReplicas {
    pub point_id: u32,
    pub point: String,
    pub replicas: u32,
    pub expected: u32,
    pub core_hours_left: f64,
}

/// How the cost model's reference seconds become this machine's: seconds here per
/// reference second, and where that factor comes from.
#[derive(Serialize, Clone, Debug, PartialEq)]
pub struct Calibration {
    /// `finished runs`, `probe` or `reference`.
    pub source: String,
    /// Seconds on this machine per cost-model (reference) second.
    pub factor: f64,
    /// What it was made from, in words.
    pub detail: String,
}

impl Default for Calibration {
    fn default() -> Self {
        Calibration::reference("")
    }
}

impl Calibration {
    /// The cost model as it is (factor 1), for the reason `why`.
    pub fn reference(why: &str) -> Calibration {
        Calibration {
            source: "reference".into(),
            factor: 1.0,
            detail: format!("the cost model's reference machine as it is ({why})"),
        }
    }
}

/// The expected cost of some runs: core-seconds and wall seconds on this machine.
#[derive(Serialize, Clone, Debug, Default, PartialEq)]
pub struct Estimate {
    /// Runs counted.
    pub runs: u64,
    /// Their CPU seconds by the cost model (reference machine): the sum of
    /// `ModelParams::cost` (a continued run: the part beyond the run it continues).
    pub reference_core_seconds: f64,
    /// The same on this machine (times the calibration factor), and in core-hours.
    pub core_seconds: f64,
    pub core_hours: f64,
    /// The longest run here (seconds).
    pub longest_run_seconds: f64,
    /// The new points' kinetic theory (CPU seconds, this machine as the reference).
    pub theory_seconds: f64,
    /// Worker threads the wall time is for.
    pub threads: usize,
    /// Expected wall seconds: the theory (spread over the threads, at least its largest
    /// point), then the runs (max(core_seconds / threads, longest run)), then the campaign's
    /// finish (summaries, figures) at [`FINISH_SECONDS_PER_RUN`] per run.
    pub wall_seconds: f64,
    pub calibration: Calibration,
}

/// Wall seconds per run of the campaign's finish after the last run (summaries, figures,
/// compaction; measured with scripts/cost-estimate-check.sh, 2026-11, 2 cores).
pub const FINISH_SECONDS_PER_RUN: f64 = 0.05;

/// The estimate of `runs` (params, how many runs of them) and of the new points' `theory`,
/// at `threads` worker threads, calibrated by `calibration`: what `plan` prints, and what a
/// scheduler may call for any list of runs.
pub fn estimate<'a>(
    runs: impl IntoIterator<Item = (&'a ModelParams, u64)>,
    theory: &TheoryWork,
    threads: usize,
    calibration: Calibration,
) -> Estimate {
    estimate_costs(
        runs.into_iter().map(|(p, n)| (p.cost(), n)),
        theory,
        threads,
        calibration,
    )
}

/// [`estimate`] from the runs' reference costs (CPU seconds, how many runs of each).
pub fn estimate_costs(
    runs: impl IntoIterator<Item = (f64, u64)>,
    theory: &TheoryWork,
    threads: usize,
    calibration: Calibration,
) -> Estimate {
    let threads = threads.max(1);
    let mut e = Estimate {
        threads,
        theory_seconds: theory.seconds,
        ..Estimate::default()
    };
    let factor = calibration.factor;
    for (s, n) in runs {
        let s = if s.is_finite() { s.max(0.0) } else { f64::MAX };
        e.runs += n;
        e.reference_core_seconds += s * n as f64;
        if n > 0 {
            e.longest_run_seconds = e.longest_run_seconds.max(s * factor);
        }
    }
    e.core_seconds = e.reference_core_seconds * factor;
    e.core_hours = e.core_seconds / 3600.0;
    let largest_theory = theory.largest.map_or(0.0, |(_, s, _)| s);
    let theory_wall = (theory.seconds / threads as f64).max(largest_theory);
    let runs_wall = (e.core_seconds / threads as f64).max(e.longest_run_seconds);
    e.wall_seconds = theory_wall + runs_wall + FINISH_SECONDS_PER_RUN * e.runs as f64;
    e.calibration = calibration;
    e
}

impl Estimate {
    /// `~0.0081 core-hours (29 core-s), ~15 s wall at 2 threads`.
    pub fn text(&self) -> String {
        format!(
            "~{:.2e} core-hours ({} core-s), ~{} s wall at {} thread(s)",
            self.core_hours,
            seconds_text(self.core_seconds),
            seconds_text(self.wall_seconds),
            self.threads
        )
    }
}

/// The unfinished current runs, as (params, count) with the params they run: a run that
/// continues a finished one counts as the part beyond it (its cost less that of the run it
/// continues), as params of a shorter horizon.
fn runs_work<'c>(
    c: &'c Campaign,
    current: &[super::plan::RunSpec],
    finished: &BTreeMap<u64, RunStatus>,
) -> Vec<(Continued<'c>, u64)> {
    let mut per: BTreeMap<(u32, Option<u32>), u64> = BTreeMap::new();
    for r in current.iter().filter(|r| !finished.contains_key(&r.run_id)) {
        let from = r.continues.map(|old| c.plan.run(old).point_id);
        *per.entry((r.point_id, from)).or_default() += 1;
    }
    per.into_iter()
        .map(|((point, from), n)| {
            (
                Continued {
                    params: &c.plan.points[point as usize].params,
                    from: from.map(|f| &c.plan.points[f as usize].params),
                },
                n,
            )
        })
        .collect()
}

/// A run's params and, when it continues a finished run, that run's.
#[derive(Clone, Copy)]
struct Continued<'c> {
    params: &'c ModelParams,
    from: Option<&'c ModelParams>,
}

impl Continued<'_> {
    fn cost(&self) -> f64 {
        let full = self.params.cost();
        self.from.map_or(full, |f| (full - f.cost()).max(0.0))
    }
}

/// The median over the finished runs (those that ran from t = 0) of wall seconds / cost.
fn from_finished_runs(c: &Campaign, walls: &BTreeMap<u64, f64>) -> Calibration {
    // Each point's cost once (a campaign may have many runs per point).
    let mut costs: HashMap<u32, f64> = HashMap::new();
    let mut ratios: Vec<f64> = walls
        .iter()
        .filter(|(run, _)| c.plan.run(**run).continues.is_none())
        .filter_map(|(run, w)| {
            let point = c.plan.run(*run).point_id;
            let cost = *costs
                .entry(point)
                .or_insert_with(|| c.plan.points[point as usize].params.cost());
            (cost > 0.0 && w.is_finite() && *w > 0.0).then(|| w / cost)
        })
        .collect();
    if ratios.is_empty() {
        return Calibration::reference("no finished run from t = 0 to calibrate on");
    }
    ratios.sort_by(f64::total_cmp);
    let m = ratios.len();
    let median = if m % 2 == 1 {
        ratios[m / 2]
    } else {
        0.5 * (ratios[m / 2 - 1] + ratios[m / 2])
    };
    Calibration {
        source: "finished runs".into(),
        factor: median,
        detail: format!(
            "median of measured / estimated wall seconds over the {m} finished run(s): {median:.3}"
        ),
    }
}

/// The longest a probe runs (wall seconds).
pub const PROBE_SECONDS: f64 = 1.0;

/// Run the cheapest of the runs for at most [`PROBE_SECONDS`] (in chunks of `WORK_CHUNK`
/// work units) and compare its time with its cost: the factor is the elapsed seconds over
/// the cost of the part done (its `progress`; the whole cost if it finishes). Nothing is
/// written.
fn probe(work: &[(Continued<'_>, u64)], stream: crate::rng::StreamVersion) -> Calibration {
    let Some(cheapest) = work
        .iter()
        .map(|(w, _)| w.params)
        .min_by(|a, b| a.cost().total_cmp(&b.cost()))
    else {
        return Calibration::reference("no run to do, nothing to probe");
    };
    let cost = cheapest.cost();
    let started = std::time::Instant::now();
    let mut engine = match cheapest.start(PROBE_SEED, stream) {
        Ok(e) => e,
        Err(e) => return Calibration::reference(&format!("the probe run could not start: {e}")),
    };
    let mut done = false;
    while !done && started.elapsed().as_secs_f64() < PROBE_SECONDS {
        match engine.advance(WORK_CHUNK) {
            Ok(d) => done = d,
            Err(e) => {
                return Calibration::reference(&format!("the probe run failed: {e}"));
            }
        }
    }
    let elapsed = started.elapsed().as_secs_f64();
    let fraction = if done { 1.0 } else { engine.progress() };
    if !(fraction > 0.01 && cost > 0.0 && elapsed > 0.0) {
        return Calibration::reference(&format!(
            "the probe run did {:.1} % of its work in {elapsed:.2} s, too little to go by",
            100.0 * fraction
        ));
    }
    let factor = elapsed / (cost * fraction);
    Calibration {
        source: "probe".into(),
        factor,
        detail: format!(
            "a probe run of the cheapest point ({:.1} % of it{}, {elapsed:.2} s against {:.2} s estimated): {factor:.3}",
            100.0 * fraction,
            if done { ", all" } else { "" },
            cost * fraction
        ),
    }
}

/// The probe run's seed (any: its results are thrown away).
const PROBE_SEED: u64 = 0x5eed_c057;

#[cfg(test)]
mod tests {
    use super::*;

    /// The search by index finds the point the scan of every candidate by [`distance`] finds
    /// (the fewest differing keys, then the smallest sum of relative numeric differences, the
    /// smallest id among equals), for points at distance 0, 1, 2 and more on the varying keys,
    /// with keys missing on either side. (Values 0, 1, 2, 4: every relative difference and
    /// every sum of them is exact, so that ties are ties.)
    #[test]
    fn nearest_is_that_of_the_scan() {
        let mut seed = 7u64;
        let mut next = |n: u64| {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) % n
        };
        let mut point = |i: u64| -> BTreeMap<String, String> {
            let mut m = BTreeMap::new();
            m.insert("model".into(), "\"dsmc\"".into());
            for k in 0..5 {
                let v = next(3);
                if v < 2 || k == 0 {
                    m.insert(
                        format!("k{k}"),
                        format!("{}", [0, 1, 2, 4][next(4) as usize]),
                    );
                }
            }
            if i % 7 == 0 {
                m.insert("extra".into(), "1".into());
            }
            m
        };
        let candidates: Vec<(u32, BTreeMap<String, String>)> =
            (0..60).map(|i| (i as u32, point(i))).collect();
        let index = Nearest::new(candidates.clone().into_iter());
        let scan = |mine: &BTreeMap<String, String>| {
            candidates
                .iter()
                .map(|(id, theirs)| (distance(mine, theirs), *id))
                .min_by(|(a, i), (b, j)| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)).then(i.cmp(j)))
                .map(|(_, id)| id)
        };
        let mut by_relative = 0;
        for i in 0..400 {
            let p = point(1000 + i);
            let found = index.find(&p);
            assert_eq!(found, scan(&p), "{p:?}");
            // How often the relative differences decide (the fewest keys alone would not).
            let fewest = candidates
                .iter()
                .map(|(id, theirs)| (distance(&p, theirs).0, *id))
                .min()
                .map(|(_, id)| id);
            by_relative += usize::from(found != fewest);
        }
        assert!(
            by_relative > 20,
            "the relative differences decided {by_relative} times"
        );
        for (_, c) in &candidates {
            assert_eq!(index.find(c), scan(c));
        }
        assert_eq!(Nearest::new(std::iter::empty()).find(&point(0)), None);
    }

    /// Params flatten to dotted paths with list indices from 0; the differences name only
    /// the leaves that differ, `(absent)` for a key on one side only; the nearest of a mass
    /// sweep [2, 4, 8] to 16 is 8 (one leaf differs from each; 8 the least relatively),
    /// and of restitution [0.5, 0.9] to 0.8 is 0.9.
    #[test]
    fn differences_are_leaves_and_nearest_is_relative() {
        let p = |mass: f64, eps: f64| {
            flatten(&serde_json::json!({
                "species": {"list": [{"mass": 1, "count": 10}, {"mass": mass, "count": 5}]},
                "restitution": {"constant": eps}, "output_times": {"list": []}
            }))
        };
        assert_eq!(p(2.0, 0.5)["species.list.1.mass"], "2");
        assert_eq!(p(2.5, 0.5)["species.list.1.mass"], "2.5");
        assert_eq!(p(2.0, 0.5)["output_times.list"], "[]");
        assert_eq!(
            differences(&p(8.0, 0.5), &p(16.0, 0.5)),
            vec!["species.list.1.mass: 8 -> 16".to_string()]
        );
        let mut q = p(8.0, 0.5);
        q.insert("t_end".into(), "3".into());
        assert_eq!(
            differences(&p(8.0, 0.5), &q),
            vec!["t_end: (absent) -> 3".to_string()]
        );
        let masses = Nearest::new(
            [2.0, 4.0, 8.0]
                .iter()
                .enumerate()
                .map(|(i, m)| (i as u32, p(*m, 0.5))),
        );
        assert_eq!(masses.find(&p(16.0, 0.5)), Some(2));
        assert_eq!(masses.find(&p(3.0, 0.5)), Some(1));
        let eps = Nearest::new(
            [0.5, 0.9]
                .iter()
                .enumerate()
                .map(|(i, e)| (i as u32, p(2.0, *e))),
        );
        assert_eq!(eps.find(&p(2.0, 0.8)), Some(1));
        assert_eq!(eps.find(&p(2.0, 0.6)), Some(0));
        // Two leaves differ from each: the relative sums decide (8 and 0.9 nearer).
        let both = Nearest::new(
            [(2.0, 0.5), (8.0, 0.9)]
                .iter()
                .enumerate()
                .map(|(i, (m, e))| (i as u32, p(*m, *e))),
        );
        assert_eq!(both.find(&p(16.0, 0.8)), Some(1));
        assert_eq!(distance(&p(2.0, 0.5), &p(2.0, 0.5)), (0, 0.0));
    }
}
