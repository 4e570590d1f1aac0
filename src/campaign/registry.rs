//! The campaign's registry: every point and run it has ever had, with ids that never change.
//!
//! A manifest asks for points (its sweep) and runs per point (`replicas` or `seeds`). The first
//! manifest registers its points in sweep order (`point_id` 0, 1, ...) and their runs point by
//! point (`run_id = point_id * replicas + replica`, as before growth existed). A grown manifest
//! (more replicas, more sweep values, a new sweep key, another fixed value, a longer run)
//! registers only what is new, after what exists: a point is the same point when its full
//! params are (canonical JSON), a run the same run when its point and replica are (or, with
//! given seeds, its point and seed). Nothing is ever removed: points and runs that a later
//! manifest no longer asks for stay, finished, in the tables.
//!
//! Runs are kept in blocks (a point's replicas `first_replica..first_replica + count` with ids
//! `first_run..`), each with the source of its seeds (`SeedSource`). A block may continue the
//! runs of another point (`continues`): the same point with a longer horizon, whose finished
//! runs carry over (`CarryOver::Continue`) from their final states.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::manifest::sweep::canonical;
use crate::manifest::RunsPerPoint;
use crate::models::{CarryOver, ModelKind, ModelParams};

/// Where the seeds of a block's runs come from.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(rename_all = "snake_case")]
pub enum SeedSource {
    /// `plan::derive_seed`: the campaign seed, the model, the point's params without the
    /// model's horizon keys, and the replica.
    Params,
    /// The derivation of campaign directories of format 1 (before growth): the model, the sweep
    /// keys and the point's values at the time, and the replica.
    Swept {
        keys: Vec<String>,
        values: Vec<Value>,
    },
    /// Given by the manifest (`seeds`): the i-th run of the block has the i-th seed.
    Given(Vec<u64>),
}

/// A registered point: its id and full params (what identifies it).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct RegPoint {
    pub id: u32,
    pub params: Value,
}

/// Runs `first_run..first_run + count` of point `point`, replicas `first_replica..`.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct RunBlock {
    pub point: u32,
    pub first_run: u64,
    pub first_replica: u32,
    pub count: u32,
    pub seeds: SeedSource,
    /// The point whose finished runs (same replicas) these runs continue.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub continues: Option<u32>,
}

/// Every point and run of a campaign.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq, Default)]
pub struct Registry {
    pub points: Vec<RegPoint>,
    pub blocks: Vec<RunBlock>,
}

/// A manifest's points (full params, typed) and the runs it asks for per point.
pub struct Asked<'a> {
    pub model: ModelKind,
    pub points: &'a [ModelParams],
    pub runs: &'a RunsPerPoint,
}

/// What a manifest adds to a registry.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Growth {
    /// Points registered now (ids).
    pub new_points: Vec<u32>,
    /// Runs registered now: (point, replica, run_id).
    pub new_runs: Vec<(u32, u32, u64)>,
    /// Of those, runs continuing a finished run of a shorter point: (run_id, run it continues).
    pub continued: Vec<(u64, u64)>,
    /// Registered points the manifest does not ask for.
    pub retired_points: Vec<u32>,
    /// Notes (points of a longer horizon that are run again from the start, and why).
    pub notes: Vec<String>,
}

impl Growth {
    pub fn is_empty(&self) -> bool {
        self.new_points.is_empty() && self.new_runs.is_empty()
    }
}

/// The identity of a point's runs: its model and params without the horizon keys.
pub fn run_identity(model: ModelKind, params: &Value) -> String {
    let mut p = params.clone();
    if let Some(o) = p.as_object_mut() {
        for k in model.horizon() {
            o.remove(*k);
        }
    }
    format!("{}\u{1f}{}", model.as_str(), canonical(&p))
}

impl Registry {
    pub fn n_runs(&self) -> u64 {
        self.blocks
            .last()
            .map_or(0, |b| b.first_run + b.count as u64)
    }

    /// The point with these full params.
    pub fn find(&self, params: &Value) -> Option<u32> {
        let key = canonical(params);
        self.points
            .iter()
            .find(|p| canonical(&p.params) == key)
            .map(|p| p.id)
    }

    /// The blocks of a point.
    pub fn blocks_of(&self, point: u32) -> impl Iterator<Item = &RunBlock> {
        self.blocks.iter().filter(move |b| b.point == point)
    }

    /// The seed of replica `r` of a block, or None for a derived seed (`Params`, `Swept`).
    pub fn given_seed(b: &RunBlock, replica: u32) -> Option<u64> {
        match &b.seeds {
            SeedSource::Given(s) => s.get((replica - b.first_replica) as usize).copied(),
            _ => None,
        }
    }

    fn push_block(&mut self, mut b: RunBlock, growth: &mut Growth) {
        b.first_run = self.n_runs();
        for i in 0..b.count {
            growth
                .new_runs
                .push((b.point, b.first_replica + i, b.first_run + i as u64));
        }
        self.blocks.push(b);
    }

    /// Register what `asked` adds: new points, and per point the runs it asks for that do not
    /// exist. `seed_of` gives a registered run's seed (to match given seeds).
    /// A point whose horizon is shorter than a registered point's of the same run identity is
    /// refused (every error is returned).
    pub fn grow(
        &mut self,
        asked: &Asked,
        seed_of: &dyn Fn(&RunBlock, u32) -> u64,
    ) -> Result<Growth, Vec<String>> {
        let mut growth = Growth::default();
        let mut refused = Vec::new();
        let mut asked_ids = BTreeSet::new();
        let before: Vec<RegPoint> = self.points.clone();
        // Indices, so that a manifest of many points registers in O(n log n): the points by
        // their canonical params, those registered before by their run identity.
        let mut index: HashMap<String, u32> = self
            .points
            .iter()
            .map(|p| (canonical(&p.params), p.id))
            .collect();
        let mut by_identity: HashMap<String, Vec<usize>> = HashMap::new();
        for (i, p) in before.iter().enumerate() {
            by_identity
                .entry(run_identity(asked.model, &p.params))
                .or_default()
                .push(i);
        }
        for params in asked.points {
            let value = params.to_value();
            let key = canonical(&value);
            let (id, is_new) = match index.get(&key) {
                Some(&id) => (id, false),
                None => {
                    let id = self.points.len() as u32;
                    self.points.push(RegPoint {
                        id,
                        params: value.clone(),
                    });
                    index.insert(key, id);
                    growth.new_points.push(id);
                    (id, true)
                }
            };
            asked_ids.insert(id);
            // A longer run of a point registered before: its runs continue (or rerun) those.
            let mut shorter = None;
            if is_new {
                let same: Vec<RegPoint> = by_identity
                    .get(&run_identity(asked.model, &value))
                    .map(|ids| ids.iter().map(|&i| before[i].clone()).collect())
                    .unwrap_or_default();
                refused.extend(shorter_than_before(&same, asked.model, params));
                shorter = self.shorter_point(&same, asked.model, params, &mut growth);
            }
            if let RunsPerPoint::Replicas(r) = asked.runs {
                let mut given: Vec<u32> = Vec::new();
                for p in [(!is_new).then_some(id), shorter].into_iter().flatten() {
                    given.extend(self.given_below(p, *r));
                }
                if !given.is_empty() {
                    given.sort_unstable();
                    given.dedup();
                    refused.push(format!(
                        "point {id} holds runs of given seeds at replica place(s) {given:?}: with \
                         `replicas` they would count as its replicas, which a campaign started \
                         from this manifest would not have (its seeds derive from the campaign \
                         seed); keep `seeds` for this campaign, or use another --out"
                    ));
                    continue;
                }
            }
            self.grow_point(id, is_new, asked.runs, shorter, seed_of, &mut growth);
        }
        if !refused.is_empty() {
            return Err(refused);
        }
        growth.retired_points = self
            .points
            .iter()
            .map(|p| p.id)
            .filter(|id| !asked_ids.contains(id))
            .collect();
        Ok(growth)
    }

    /// A registered point with the same run identity as `params` (differing only in the
    /// horizon) whose runs carry over; notes a rerun.
    fn shorter_point(
        &self,
        before: &[RegPoint],
        model: ModelKind,
        params: &ModelParams,
        growth: &mut Growth,
    ) -> Option<u32> {
        let identity = run_identity(model, &params.to_value());
        let mut candidates: Vec<(u32, ModelParams)> = before
            .iter()
            .filter(|p| run_identity(model, &p.params) == identity)
            .filter_map(|p| {
                let mut errs = Vec::new();
                model
                    .params_from(&p.params, "", &mut errs)
                    .map(|typed| (p.id, typed))
            })
            .filter(|(_, old)| old.carry_over(params) == CarryOver::Continue)
            .collect();
        // The longest of them (the last registered among equals).
        candidates.sort_by_key(|c| c.0);
        if let Some((id, _)) = candidates.pop() {
            return Some(id);
        }
        for p in before
            .iter()
            .filter(|p| run_identity(model, &p.params) == identity)
        {
            let mut errs = Vec::new();
            if let Some(old) = model.params_from(&p.params, "", &mut errs) {
                if let CarryOver::Rerun(why) = old.carry_over(params) {
                    growth.notes.push(format!(
                        "point {} is run again from the start for the new horizon: {why}",
                        p.id
                    ));
                }
            }
        }
        None
    }

    /// Register the runs point `id` is asked for and does not have. A point that continues a
    /// shorter one takes, for each replica (or given seed) the shorter has, that run's seed.
    fn grow_point(
        &mut self,
        id: u32,
        is_new: bool,
        runs: &RunsPerPoint,
        continues: Option<u32>,
        seed_of: &dyn Fn(&RunBlock, u32) -> u64,
        growth: &mut Growth,
    ) {
        let replicas_of = |point: u32| -> BTreeMap<u32, u64> {
            self.blocks_of(point)
                .flat_map(|b| {
                    (0..b.count)
                        .map(move |i| (b.first_replica + i, seed_of(b, b.first_replica + i)))
                })
                .collect()
        };
        // A point registered now has no runs yet (no need to look through every block).
        let have = if is_new {
            BTreeMap::new()
        } else {
            replicas_of(id)
        };
        let old = continues.map(replicas_of).unwrap_or_default();
        // The old run's seed source, for a replica the shorter point has.
        let inherited = |replica: u32| -> Option<SeedSource> {
            let b = self
                .blocks_of(continues?)
                .find(|b| replica >= b.first_replica && replica < b.first_replica + b.count)?;
            Some(match &b.seeds {
                SeedSource::Given(s) => {
                    SeedSource::Given(vec![s[(replica - b.first_replica) as usize]])
                }
                other => other.clone(),
            })
        };
        // (replica, seed source, continued)
        let mut wanted: Vec<(u32, SeedSource, bool)> = Vec::new();
        match runs {
            RunsPerPoint::Replicas(r) => {
                for x in (0..*r).filter(|x| !have.contains_key(x)) {
                    match inherited(x) {
                        Some(src) => wanted.push((x, src, true)),
                        None => wanted.push((x, SeedSource::Params, false)),
                    }
                }
            }
            RunsPerPoint::Seeds(seeds) => {
                let known: BTreeSet<u64> = have.values().copied().collect();
                let mut taken: BTreeSet<u32> = have.keys().copied().collect();
                taken.extend(old.keys());
                let mut next = taken.iter().next_back().map_or(0, |r| r + 1);
                for s in seeds.iter().filter(|s| !known.contains(s)) {
                    match old.iter().find(|(_, seed)| *seed == s) {
                        Some((&r, _)) => wanted.push((r, inherited(r).expect("old run"), true)),
                        None => {
                            wanted.push((next, SeedSource::Given(vec![*s]), false));
                            next += 1;
                        }
                    }
                }
                wanted.sort_by_key(|w| w.0);
            }
        }
        // Consecutive replicas of one kind form one block.
        let mut blocks: Vec<RunBlock> = Vec::new();
        for (replica, seeds, cont) in wanted {
            let cont = cont.then_some(continues).flatten();
            match blocks.last_mut() {
                Some(b)
                    if b.first_replica + b.count == replica
                        && b.continues == cont
                        && mergeable(&b.seeds, &seeds) =>
                {
                    if let (SeedSource::Given(v), SeedSource::Given(w)) = (&mut b.seeds, &seeds) {
                        v.extend(w);
                    }
                    b.count += 1;
                }
                _ => blocks.push(RunBlock {
                    point: id,
                    first_run: 0,
                    first_replica: replica,
                    count: 1,
                    seeds,
                    continues: cont,
                }),
            }
        }
        for b in blocks {
            let (first_replica, count, cont) = (b.first_replica, b.count, b.continues);
            let first = self.n_runs();
            self.push_block(b, growth);
            if let Some(old) = cont {
                for i in 0..count {
                    if let Some(old_run) = self.run_of(old, first_replica + i) {
                        growth.continued.push((first + i as u64, old_run));
                    }
                }
            }
        }
    }

    /// The replica places below `r` of `point` that hold runs of given seeds.
    fn given_below(&self, point: u32, r: u32) -> Vec<u32> {
        self.blocks_of(point)
            .filter(|b| matches!(b.seeds, SeedSource::Given(_)))
            .flat_map(|b| b.first_replica..b.first_replica + b.count)
            .filter(|x| *x < r)
            .collect()
    }

    /// The run of `point` with replica `replica`.
    pub fn run_of(&self, point: u32, replica: u32) -> Option<u64> {
        self.blocks_of(point)
            .find(|b| replica >= b.first_replica && replica < b.first_replica + b.count)
            .map(|b| b.first_run + (replica - b.first_replica) as u64)
    }
}

/// Why `params` is refused: a registered point of the same run identity ran longer.
fn shorter_than_before(before: &[RegPoint], model: ModelKind, params: &ModelParams) -> Vec<String> {
    let identity = run_identity(model, &params.to_value());
    before
        .iter()
        .filter(|p| run_identity(model, &p.params) == identity)
        .filter_map(|p| {
            let mut errs = Vec::new();
            let old = model.params_from(&p.params, "", &mut errs)?;
            match old.carry_over(params) {
                CarryOver::Shorter(why) => Some(format!(
                    "point {} has been run further: {why} (a campaign never shortens its runs; \
                     use another --out for shorter ones)",
                    p.id
                )),
                _ => None,
            }
        })
        .collect()
}

/// Whether a run of `b` can join a block of `a`.
fn mergeable(a: &SeedSource, b: &SeedSource) -> bool {
    match (a, b) {
        (SeedSource::Given(_), SeedSource::Given(_)) => true,
        (x, y) => x == y,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    /// A small DSMC point with restitution `eps`, end `t_end` (outputs 1 and the ends given).
    fn point(eps: f64, t_end: f64, outputs: &[f64]) -> ModelParams {
        let v = json!({
            "method": "low_rank",
            "species": {"power_law": {"n1": 0.1, "N1": 100, "theta": 3}},
            "restitution": {"constant": eps},
            "t_end": t_end,
            "output_times": {"list": outputs},
        });
        let mut errs = Vec::new();
        let p = ModelKind::Dsmc.params_from(&v, "", &mut errs);
        assert!(errs.is_empty(), "{errs:?}");
        p.unwrap()
    }

    /// Seeds as a plan would give them: given ones, else a stand-in derived from the block.
    fn seed_of(b: &RunBlock, r: u32) -> u64 {
        Registry::given_seed(b, r).unwrap_or(1000 * b.point as u64 + r as u64)
    }

    fn grow(reg: &mut Registry, points: &[ModelParams], runs: RunsPerPoint) -> Growth {
        let asked = Asked {
            model: ModelKind::Dsmc,
            points,
            runs: &runs,
        };
        reg.grow(&asked, &seed_of).unwrap()
    }

    /// Replicas then values: ids are appended, existing ones never change, the same manifest
    /// again adds nothing, and a point asked for again after a manifest without it is the
    /// same point (found by its params).
    #[test]
    fn growth_appends_and_keeps_ids() {
        let mut reg = Registry::default();
        let (a, b) = (point(0.5, 10.0, &[1.0]), point(0.7, 10.0, &[1.0]));
        let g = grow(&mut reg, &[a.clone(), b.clone()], RunsPerPoint::Replicas(2));
        assert_eq!((g.new_points.len(), g.new_runs.len()), (2, 4));
        // As format 1 numbered them: point_id * replicas + replica.
        assert_eq!(reg.run_of(1, 1), Some(3));
        let g = grow(&mut reg, &[a.clone(), b.clone()], RunsPerPoint::Replicas(3));
        assert_eq!(g.new_runs, vec![(0, 2, 4), (1, 2, 5)]);
        assert!(grow(&mut reg, &[a.clone(), b.clone()], RunsPerPoint::Replicas(3)).is_empty());
        // Fewer replicas: nothing new, nothing removed.
        assert!(grow(&mut reg, &[a.clone()], RunsPerPoint::Replicas(1)).is_empty());
        let g = grow(&mut reg, &[a.clone()], RunsPerPoint::Replicas(1));
        assert_eq!(g.retired_points, vec![1]);
        let c = point(0.9, 10.0, &[1.0]);
        let g = grow(&mut reg, &[c.clone(), b.clone()], RunsPerPoint::Replicas(3));
        assert_eq!(g.new_points, vec![2]);
        assert_eq!(g.new_runs, vec![(2, 0, 6), (2, 1, 7), (2, 2, 8)]);
        assert_eq!(g.retired_points, vec![0]);
        assert_eq!(reg.n_runs(), 9);
        assert_eq!(reg.find(&b.to_value()), Some(1));
    }

    /// Given seeds: a run is its point and seed; new seeds get the next replica numbers, the
    /// same seeds in another order add nothing.
    #[test]
    fn given_seeds() {
        let mut reg = Registry::default();
        let a = point(0.5, 10.0, &[1.0]);
        let g = grow(&mut reg, &[a.clone()], RunsPerPoint::Seeds(vec![5, 17]));
        assert_eq!(g.new_runs.len(), 2);
        assert!(grow(&mut reg, &[a.clone()], RunsPerPoint::Seeds(vec![17, 5])).is_empty());
        let g = grow(&mut reg, &[a.clone()], RunsPerPoint::Seeds(vec![5, 23, 17]));
        assert_eq!(g.new_runs, vec![(0, 2, 2)]);
        let seeds: Vec<u64> = reg
            .blocks
            .iter()
            .flat_map(|b| (0..b.count).map(move |i| seed_of(b, b.first_replica + i)))
            .collect();
        assert_eq!(seeds, vec![5, 17, 23]);
    }

    /// A longer t_end whose outputs begin with the old ones continues every run of the
    /// shorter point with its seed (given seeds by seed, replicas by replica; new replicas run
    /// from the start); other outputs before the old end rerun it (noted); a shorter t_end is
    /// refused.
    #[test]
    fn horizons() {
        let mut reg = Registry::default();
        let short = point(0.5, 10.0, &[1.0]);
        grow(&mut reg, &[short.clone()], RunsPerPoint::Replicas(2));
        let long = point(0.5, 20.0, &[1.0, 10.0]);
        let g = grow(&mut reg, &[long.clone()], RunsPerPoint::Replicas(3));
        assert_eq!(g.new_points, vec![1]);
        assert_eq!(g.continued, vec![(2, 0), (3, 1)]);
        assert_eq!(g.new_runs.len(), 3);
        let b = reg.blocks_of(1).collect::<Vec<_>>();
        // The continued replicas keep the shorter runs' seed source (derived from the params
        // without the horizon: the same seeds).
        assert_eq!(b[0].continues, Some(0));
        assert_eq!(b[0].seeds, reg.blocks_of(0).next().unwrap().seeds);
        assert_eq!(b.last().unwrap().continues, None);
        // Continuing again goes from the longest run.
        let longer = point(0.5, 40.0, &[1.0, 10.0, 20.0]);
        let g = grow(&mut reg, &[longer], RunsPerPoint::Replicas(3));
        assert_eq!(g.continued, vec![(5, 2), (6, 3), (7, 4)]);
        // Other outputs before the old end: a rerun, with a note.
        let other = point(0.5, 50.0, &[2.0]);
        let g = grow(&mut reg, &[other], RunsPerPoint::Replicas(1));
        assert!(g.continued.is_empty());
        assert!(
            g.notes
                .iter()
                .any(|n| n.contains("run again from the start")),
            "{:?}",
            g.notes
        );
        // Shorter than what exists: refused, nothing registered.
        let before = reg.clone();
        let shorter = point(0.5, 5.0, &[1.0]);
        let asked = Asked {
            model: ModelKind::Dsmc,
            points: std::slice::from_ref(&shorter),
            runs: &RunsPerPoint::Replicas(1),
        };
        let mut copy = reg.clone();
        let err = copy.grow(&asked, &seed_of).unwrap_err();
        assert!(err[0].contains("never shortens"), "{err:?}");
        assert_eq!(reg, before);
        // Given seeds continue by seed.
        let mut reg = Registry::default();
        grow(&mut reg, &[short], RunsPerPoint::Seeds(vec![7, 9]));
        let g = grow(&mut reg, &[long], RunsPerPoint::Seeds(vec![9, 11, 7]));
        assert_eq!(g.continued, vec![(2, 0), (3, 1)]);
        let seeds: Vec<u64> = reg
            .blocks_of(1)
            .flat_map(|b| (0..b.count).map(move |i| seed_of(b, b.first_replica + i)))
            .collect();
        assert_eq!(seeds, vec![7, 9, 11]);
    }
}
