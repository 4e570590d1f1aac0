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

use crate::manifest::sweep::{canonical, canonical_without};
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
    format!(
        "{}\u{1f}{}",
        model.as_str(),
        canonical_without(params, model.horizon())
    )
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
    /// refused, and so are more than [`MAX_HORIZON_VARIANTS`] points of one run identity
    /// (every error is returned).
    ///
    /// Linear in the points (and runs) of the registry and the manifest: the points are found
    /// by their canonical params, the blocks by their point, and a new point is compared (by
    /// the model's `carry_over`) only with the registered points of its run identity, at most
    /// [`MAX_HORIZON_VARIANTS`], each parsed once.
    pub fn grow(
        &mut self,
        asked: &Asked,
        seed_of: &dyn Fn(&RunBlock, u32) -> u64,
    ) -> Result<Growth, Vec<String>> {
        let mut growth = Growth::default();
        let mut refused = Vec::new();
        let mut asked_ids = BTreeSet::new();
        let mut index: HashMap<String, u32> = self
            .points
            .iter()
            .map(|p| (canonical(&p.params), p.id))
            .collect();
        let mut horizons = Horizons::of(&self.points, asked.model);
        let mut blocks_of: HashMap<u32, Vec<usize>> = HashMap::new();
        for (i, b) in self.blocks.iter().enumerate() {
            blocks_of.entry(b.point).or_default().push(i);
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
                let placed =
                    horizons.place(&self.points, id, &value, params, &mut refused, &mut growth);
                let Some(continues) = placed else {
                    self.grow_point(
                        id,
                        true,
                        asked.runs,
                        None,
                        seed_of,
                        &mut growth,
                        &mut blocks_of,
                    );
                    continue;
                };
                shorter = continues;
            }
            if let RunsPerPoint::Replicas(r) = asked.runs {
                if let Some(why) = self.given_as_replicas(id, is_new, shorter, *r, &blocks_of) {
                    refused.push(why);
                    continue;
                }
            }
            self.grow_point(
                id,
                is_new,
                asked.runs,
                shorter,
                seed_of,
                &mut growth,
                &mut blocks_of,
            );
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

    /// With `replicas`, why point `id` is refused when replica places below `r` of it
    /// (registered before: not `is_new`) or of the point it continues (`shorter`) hold runs of
    /// given seeds: they would count as its replicas.
    fn given_as_replicas(
        &self,
        id: u32,
        is_new: bool,
        shorter: Option<u32>,
        r: u32,
        blocks_of: &HashMap<u32, Vec<usize>>,
    ) -> Option<String> {
        let mut given: Vec<u32> = Vec::new();
        for p in [(!is_new).then_some(id), shorter].into_iter().flatten() {
            given.extend(self.given_below(p, r, blocks_of));
        }
        if given.is_empty() {
            return None;
        }
        given.sort_unstable();
        given.dedup();
        Some(format!(
            "point {id} holds runs of given seeds at replica place(s) {given:?}: with \
             `replicas` they would count as its replicas, which a campaign started \
             from this manifest would not have (its seeds derive from the campaign \
             seed); keep `seeds` for this campaign, or use another --out"
        ))
    }

    /// Register the runs point `id` is asked for and does not have. A point that continues a
    /// shorter one takes, for each replica (or given seed) the shorter has, that run's seed.
    /// `blocks_of` indexes the blocks by point (kept up to date).
    #[allow(clippy::too_many_arguments)]
    fn grow_point(
        &mut self,
        id: u32,
        is_new: bool,
        runs: &RunsPerPoint,
        continues: Option<u32>,
        seed_of: &dyn Fn(&RunBlock, u32) -> u64,
        growth: &mut Growth,
        blocks_of: &mut HashMap<u32, Vec<usize>>,
    ) {
        let blocks = &self.blocks;
        let of = |point: u32| -> Vec<&RunBlock> {
            blocks_of
                .get(&point)
                .map(|v| v.iter().map(|&i| &blocks[i]).collect())
                .unwrap_or_default()
        };
        let replicas_of = |point: u32| -> BTreeMap<u32, u64> {
            of(point)
                .into_iter()
                .flat_map(|b| {
                    (0..b.count)
                        .map(move |i| (b.first_replica + i, seed_of(b, b.first_replica + i)))
                })
                .collect()
        };
        // A point registered now has no runs yet.
        let have = if is_new {
            BTreeMap::new()
        } else {
            replicas_of(id)
        };
        let old = continues.map(replicas_of).unwrap_or_default();
        let old_blocks: Vec<&RunBlock> = continues.map(of).unwrap_or_default();
        // The old run's seed source, for a replica the shorter point has.
        let inherited = |replica: u32| -> Option<SeedSource> {
            let b = old_blocks
                .iter()
                .find(|b| replica >= b.first_replica && replica < b.first_replica + b.count)?;
            Some(match &b.seeds {
                SeedSource::Given(s) => {
                    SeedSource::Given(vec![s[(replica - b.first_replica) as usize]])
                }
                other => other.clone(),
            })
        };
        let wanted = wanted_runs(runs, &have, &old, &inherited);
        let new_blocks = wanted_blocks(id, wanted, continues);
        let old_runs: Vec<(u32, u32, u64)> = continues
            .map(|o| {
                of(o)
                    .into_iter()
                    .map(|b| (b.first_replica, b.count, b.first_run))
                    .collect()
            })
            .unwrap_or_default();
        let continued = continued_runs(self.n_runs(), &new_blocks, &old_runs);
        for b in new_blocks {
            blocks_of.entry(id).or_default().push(self.blocks.len());
            self.push_block(b, growth);
        }
        growth.continued.extend(continued);
    }

    /// The replica places below `r` of `point` that hold runs of given seeds.
    fn given_below(&self, point: u32, r: u32, blocks_of: &HashMap<u32, Vec<usize>>) -> Vec<u32> {
        blocks_of
            .get(&point)
            .into_iter()
            .flatten()
            .map(|&i| &self.blocks[i])
            .filter(|b| matches!(b.seeds, SeedSource::Given(_)))
            .flat_map(|b| b.first_replica..b.first_replica + b.count)
            .filter(|x| *x < r)
            .collect()
    }

    /// Register replicas `0..upto` of `point` that it lacks (a round of an error-target
    /// campaign), after every existing run, with derived seeds (`SeedSource::Params`) and the
    /// point's continuation (a longer point continues the same replicas of the shorter one
    /// where that has them). The runs registered, in order, into `growth`.
    pub fn add_replicas(&mut self, point: u32, upto: u32, growth: &mut Growth) {
        let continues = self.blocks_of(point).find_map(|b| b.continues);
        let mut r = 0;
        while r < upto {
            if self.run_of(point, r).is_some() {
                r += 1;
                continue;
            }
            let first = r;
            while r < upto && self.run_of(point, r).is_none() {
                r += 1;
            }
            self.push_block(
                RunBlock {
                    point,
                    first_run: 0,
                    first_replica: first,
                    count: r - first,
                    seeds: SeedSource::Params,
                    continues,
                },
                growth,
            );
        }
    }

    /// The run of `point` with replica `replica`.
    pub fn run_of(&self, point: u32, replica: u32) -> Option<u64> {
        self.blocks_of(point)
            .find(|b| replica >= b.first_replica && replica < b.first_replica + b.count)
            .map(|b| b.first_run + (replica - b.first_replica) as u64)
    }
}

/// The points registered before a growth by run identity (their typed params parsed when
/// first needed), and how many points of each identity the manifest adds.
struct Horizons {
    model: ModelKind,
    by_identity: HashMap<String, Vec<usize>>,
    typed_before: Vec<Option<Option<ModelParams>>>,
    added_per_identity: HashMap<String, u32>,
}

impl Horizons {
    fn of(points: &[RegPoint], model: ModelKind) -> Self {
        let mut by_identity: HashMap<String, Vec<usize>> = HashMap::new();
        for (i, p) in points.iter().enumerate() {
            by_identity
                .entry(run_identity(model, &p.params))
                .or_default()
                .push(i);
        }
        Horizons {
            model,
            by_identity,
            typed_before: vec![None; points.len()],
            added_per_identity: HashMap::new(),
        }
    }

    /// The new point `id` (`value`, typed `params`) among the registered `points` of its run
    /// identity: None when it is beyond [`MAX_HORIZON_VARIANTS`] of them (refused once per
    /// identity, when the limit is first passed); else the shorter point it continues, if
    /// any (a registered point that ran longer is refused).
    fn place(
        &mut self,
        points: &[RegPoint],
        id: u32,
        value: &Value,
        params: &ModelParams,
        refused: &mut Vec<String>,
        growth: &mut Growth,
    ) -> Option<Option<u32>> {
        let identity = run_identity(self.model, value);
        let same: &[usize] = self
            .by_identity
            .get(&identity)
            .map_or(&[], |v| v.as_slice());
        let added = self.added_per_identity.entry(identity).or_default();
        *added += 1;
        let variants = same.len() as u64 + *added as u64;
        if variants > MAX_HORIZON_VARIANTS as u64 {
            // Reported once per identity, when the limit is first passed.
            if variants == MAX_HORIZON_VARIANTS as u64 + 1 {
                refused.push(format!(
                    "more than {MAX_HORIZON_VARIANTS} points differ only in {} (the first new one is point {id}), the limit: they are one trajectory cut at different ends (the same seeds); ask for more output times of fewer points instead",
                    horizon_text(self.model)
                ));
            }
            return None;
        }
        for &i in same {
            if self.typed_before[i].is_none() {
                let mut errs = Vec::new();
                self.typed_before[i] =
                    Some(self.model.params_from(&points[i].params, "", &mut errs));
            }
        }
        let olds: Vec<(u32, &ModelParams)> = same
            .iter()
            .filter_map(|&i| {
                self.typed_before[i]
                    .as_ref()
                    .and_then(|t| t.as_ref())
                    .map(|t| (points[i].id, t))
            })
            .collect();
        refused.extend(shorter_than_before(&olds, params));
        Some(shorter_point(&olds, params, growth))
    }
}

/// The runs a point is asked for and does not `have` (replica -> seed), as (replica, seed
/// source, continued): a replica (or given seed) that the shorter point it continues has
/// (`old`) takes that run's seed source (`inherited`); a new given seed takes the next
/// replica place after every one taken. In replica order.
fn wanted_runs(
    runs: &RunsPerPoint,
    have: &BTreeMap<u32, u64>,
    old: &BTreeMap<u32, u64>,
    inherited: &dyn Fn(u32) -> Option<SeedSource>,
) -> Vec<(u32, SeedSource, bool)> {
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
            // The first replica with each seed, as a search in replica order finds it.
            let mut by_seed: HashMap<u64, u32> = HashMap::new();
            for (&r, &seed) in old {
                by_seed.entry(seed).or_insert(r);
            }
            let mut next = taken.iter().next_back().map_or(0, |r| r + 1);
            for s in seeds.iter().filter(|s| !known.contains(s)) {
                match by_seed
                    .get(s)
                    .and_then(|&r| inherited(r).map(|src| (r, src)))
                {
                    Some((r, src)) => wanted.push((r, src, true)),
                    None => {
                        wanted.push((next, SeedSource::Given(vec![*s]), false));
                        next += 1;
                    }
                }
            }
            wanted.sort_by_key(|w| w.0);
        }
    }
    wanted
}

/// The new blocks of point `id` for its `wanted` runs: consecutive replicas of one kind
/// (seed source, continuing `continues` or not) form one block (`first_run` set when pushed).
fn wanted_blocks(
    id: u32,
    wanted: Vec<(u32, SeedSource, bool)>,
    continues: Option<u32>,
) -> Vec<RunBlock> {
    let mut new_blocks: Vec<RunBlock> = Vec::new();
    for (replica, seeds, cont) in wanted {
        let cont = cont.then_some(continues).flatten();
        match new_blocks.last_mut() {
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
            _ => new_blocks.push(RunBlock {
                point: id,
                first_run: 0,
                first_replica: replica,
                count: 1,
                seeds,
                continues: cont,
            }),
        }
    }
    new_blocks
}

/// (new run, the old run it continues) of `new_blocks`, numbered from run `first` on, whose
/// replica the continued point ran (`old_runs`: its blocks' first replica, count, first run).
fn continued_runs(
    mut first: u64,
    new_blocks: &[RunBlock],
    old_runs: &[(u32, u32, u64)],
) -> Vec<(u64, u64)> {
    let old_run = |replica: u32| {
        old_runs
            .iter()
            .find(|(first, count, _)| replica >= *first && replica < first + count)
            .map(|(first, _, run)| run + (replica - first) as u64)
    };
    let mut continued = Vec::new();
    for b in new_blocks {
        if b.continues.is_some() {
            for i in 0..b.count {
                if let Some(r) = old_run(b.first_replica + i) {
                    continued.push((first + i as u64, r));
                }
            }
        }
        first += b.count as u64;
    }
    continued
}

/// Why `params` is refused: a registered point of the same run identity (`olds`: id and
/// typed params) ran longer.
fn shorter_than_before(olds: &[(u32, &ModelParams)], params: &ModelParams) -> Vec<String> {
    olds.iter()
        .filter_map(|(id, old)| match old.carry_over(params) {
            CarryOver::Shorter(why) => Some(format!(
                "point {id} has been run further: {why} (a campaign never shortens its runs; \
                 use another --out for shorter ones)"
            )),
            _ => None,
        })
        .collect()
}

/// Of the registered points of the same run identity as `params` (`olds`, differing only in
/// the horizon), the one whose runs carry over (the last registered among several); notes a
/// rerun of each that cannot be continued when none can.
fn shorter_point(
    olds: &[(u32, &ModelParams)],
    params: &ModelParams,
    growth: &mut Growth,
) -> Option<u32> {
    let verdicts: Vec<(u32, CarryOver)> = olds
        .iter()
        .map(|(id, old)| (*id, old.carry_over(params)))
        .collect();
    if let Some(id) = verdicts
        .iter()
        .filter(|(_, v)| *v == CarryOver::Continue)
        .map(|(id, _)| *id)
        .max()
    {
        return Some(id);
    }
    for (id, v) in verdicts {
        if let CarryOver::Rerun(why) = v {
            growth.notes.push(format!(
                "point {id} is run again from the start for the new horizon: {why}"
            ));
        }
    }
    None
}

/// The horizon keys of a model, in words (`t_end` and `output_times`).
fn horizon_text(model: ModelKind) -> String {
    let keys: Vec<String> = model.horizon().iter().map(|k| format!("`{k}`")).collect();
    match keys.len() {
        0 => "nothing".into(),
        1 => keys[0].clone(),
        n => format!("{} and {}", keys[..n - 1].join(", "), keys[n - 1]),
    }
}

/// Most points of a campaign that differ only in the model's horizon keys (`t_end`,
/// `output_times`, `duration`): each new one is compared with every registered one (does it
/// continue it, is it shorter?), so this bounds the work of growth per point; such points
/// are one trajectory cut at different ends (the same seeds), which more output times of one
/// point give at once.
pub const MAX_HORIZON_VARIANTS: u32 = 100;

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

    /// More than MAX_HORIZON_VARIANTS points of one run identity (a sweep of t_end) are
    /// refused, in a fresh registry and by growth (before: accepted, and growth compared every
    /// new point with every registered one: quadratic); as many with other identities are not.
    #[test]
    fn horizon_variants_are_bounded() {
        let n = MAX_HORIZON_VARIANTS as usize;
        let ends: Vec<ModelParams> = (0..=n)
            .map(|i| point(0.5, 10.0 + i as f64, &[1.0]))
            .collect();
        let asked = |points: &[ModelParams]| {
            let mut reg = Registry::default();
            let runs = RunsPerPoint::Replicas(1);
            let a = Asked {
                model: ModelKind::Dsmc,
                points,
                runs: &runs,
            };
            reg.grow(&a, &seed_of)
        };
        let err = asked(&ends).unwrap_err();
        assert!(
            err.len() == 1
                && err[0]
                    .contains("more than 100 points differ only in `t_end` and `output_times`"),
            "{err:?}"
        );
        assert!(asked(&ends[..n]).is_ok());
        let mut reg = Registry::default();
        grow(&mut reg, &ends[..n], RunsPerPoint::Replicas(1));
        let asked_more = Asked {
            model: ModelKind::Dsmc,
            points: &ends[n..],
            runs: &RunsPerPoint::Replicas(1),
        };
        assert!(reg.clone().grow(&asked_more, &seed_of).is_err());
        let eps: Vec<ModelParams> = (0..=n)
            .map(|i| point(0.1 + 0.001 * i as f64, 10.0, &[1.0]))
            .collect();
        assert!(asked(&eps).is_ok());
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
