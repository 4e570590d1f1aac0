//! What a manifest would do to a campaign directory, before any work (`granular plan`,
//! `run --dry-run`): the points and runs it adds, the runs it continues to a longer horizon,
//! what is kept, and an estimate of the cost from the wall time of the runs already done.

use std::collections::BTreeMap;

use serde::Serialize;

use super::ledger::{self, RunStatus};
use super::registry::Growth;
use super::tables::RUNS;
use super::{Campaign, CampaignError};
use crate::store::cols::{get_f64, get_str, get_u64};

/// The plan of a manifest against a campaign directory.
#[derive(Serialize, Clone, Debug, Default, PartialEq)]
pub struct Preview {
    /// The directory holds no campaign yet.
    pub new_campaign: bool,
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
    /// Registered points the manifest no longer lists (kept, with their finished runs).
    pub retired_points: Vec<u32>,
    /// Estimated CPU seconds of the runs to run (None without a finished run to go by).
    pub estimate_seconds: Option<f64>,
    /// How the estimate was made.
    pub estimate_basis: String,
    pub notes: Vec<String>,
    /// The runs to run, in run order.
    pub runs: Vec<PlannedRun>,
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

/// Preview `growth` (the result of `Campaign::prepare`) on campaign `c` (as it would be).
pub fn preview(
    c: &Campaign,
    growth: &Growth,
    new_campaign: bool,
) -> Result<Preview, CampaignError> {
    let finished = if new_campaign {
        BTreeMap::new()
    } else {
        ledger::finished_runs(&ledger::read_commits(&c.root).map_err(CampaignError::Refused)?)
    };
    let current: Vec<_> = c.plan.current_runs().collect();
    let kept = current
        .iter()
        .filter(|r| finished.contains_key(&r.run_id))
        .count() as u64;
    let new: std::collections::BTreeSet<u32> = growth.new_points.iter().copied().collect();
    let mut p = Preview {
        new_campaign,
        new_points: growth.new_points.clone(),
        points: growth
            .new_points
            .iter()
            .map(|&id| describe(c, id, &new, growth))
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
    let (seconds, basis) = estimate(c, &current, &finished, &walls);
    p.estimate_seconds = seconds;
    p.estimate_basis = basis;
    Ok(p)
}

/// A new point: the registered point it continues or is closest to (fewest differing params,
/// the first among equals), and the differences.
fn describe(
    c: &Campaign,
    id: u32,
    new: &std::collections::BTreeSet<u32>,
    growth: &Growth,
) -> NewPoint {
    let reg = &c.plan.registry.points;
    let continues = growth
        .continued
        .iter()
        .find(|(run, _)| c.plan.run(*run).point_id == id)
        .map(|(_, old)| c.plan.run(*old).point_id);
    let mine = flatten(&reg[id as usize].params);
    let differs_from = |other: u32| -> Vec<String> {
        let theirs = flatten(&reg[other as usize].params);
        let keys: std::collections::BTreeSet<&String> = mine.keys().chain(theirs.keys()).collect();
        keys.into_iter()
            .filter(|k| mine.get(*k) != theirs.get(*k))
            .map(|k| {
                let show = |v: Option<&String>| v.cloned().unwrap_or_else(|| "(none)".into());
                format!("{k}: {} -> {}", show(theirs.get(k)), show(mine.get(k)))
            })
            .collect()
    };
    let nearest = continues.or_else(|| {
        reg.iter()
            .filter(|p| !new.contains(&p.id))
            .take(NEAREST_SEARCH)
            .map(|p| (differs_from(p.id).len(), p.id))
            .min()
            .map(|(_, id)| id)
    });
    NewPoint {
        point_id: id,
        label: c.plan.label(id),
        nearest,
        differs: nearest.map(differs_from).unwrap_or_default(),
        continues,
    }
}

/// A JSON value as dotted keys and compact JSON leaves (arrays are leaves).
fn flatten(v: &serde_json::Value) -> BTreeMap<String, String> {
    fn walk(prefix: &str, v: &serde_json::Value, out: &mut BTreeMap<String, String>) {
        match v {
            serde_json::Value::Object(o) if !o.is_empty() => {
                for (k, x) in o {
                    let key = if prefix.is_empty() {
                        k.clone()
                    } else {
                        format!("{prefix}.{k}")
                    };
                    walk(&key, x, out);
                }
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
        let run = get_u64(&b, RUNS, "run_id").map_err(io)?;
        let status = get_str(&b, RUNS, "status").map_err(io)?;
        let wall = get_f64(&b, RUNS, "wall_seconds").map_err(io)?;
        for i in 0..b.num_rows() {
            if status.value(i) == "done" {
                out.insert(run.value(i), wall.value(i));
            }
        }
    }
    Ok(out)
}

/// CPU seconds of the unfinished current runs: each at the mean wall time of its point's done
/// runs, or of the point it continues, or of all done runs.
fn estimate(
    c: &Campaign,
    current: &[super::plan::RunSpec],
    finished: &BTreeMap<u64, RunStatus>,
    walls: &BTreeMap<u64, f64>,
) -> (Option<f64>, String) {
    if walls.is_empty() {
        return (None, "no finished run to estimate from".into());
    }
    let mut per_point: BTreeMap<u32, (f64, u32)> = BTreeMap::new();
    for (run, w) in walls {
        let e = per_point.entry(c.plan.run(*run).point_id).or_default();
        e.0 += w;
        e.1 += 1;
    }
    let all = walls.values().sum::<f64>() / walls.len() as f64;
    let mut total = 0.0;
    for r in current.iter().filter(|r| !finished.contains_key(&r.run_id)) {
        let point = r
            .continues
            .map(|old| c.plan.run(old).point_id)
            .unwrap_or(r.point_id);
        total += per_point.get(&point).map_or(all, |(s, n)| s / *n as f64);
    }
    (
        Some(total),
        format!(
            "mean wall time of the {} finished run(s) of the same point (or of all: {all:.3} s); a continued run counted as a whole one, an upper bound",
            walls.len()
        ),
    )
}
