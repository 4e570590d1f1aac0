//! The plan: a validated manifest expanded into sweep points and runs with stable ids and
//! seeds; a manifest file or text validated (`manifest::check`, the one validation
//! pass) and planned as a new campaign ([`load`], [`parse`]).
//!
//! Points are the cartesian product of the sweep lists (first key outermost) and are numbered
//! `point_id = 0..`; each point has `replicas` runs, `run_id = point_id * replicas + replica`.
//! A run's seed derives from the campaign seed and the run's *identity* (model, swept values,
//! replica), not from its position, so it is the same whatever the thread count or shard.

use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha20Rng;
use serde_json::Value;

use super::error::CampaignError;
use super::registry::{run_identity, Asked, Registry, RunBlock, SeedSource};
pub use crate::manifest::expand::{expand, Expansion};
pub use crate::manifest::sweep::canonical;
use crate::manifest::validate;
use crate::manifest::validate::ManifestErrors;
use crate::manifest::{Manifest, RunsPerPoint};
use crate::models::{ModelKind, ModelParams};

/// A point of the campaign (registered by this or an earlier manifest).
#[derive(Clone, Debug)]
pub struct Point {
    pub point_id: u32,
    /// The swept values of this point, one per sweep key of the latest manifest (in
    /// `Plan::sweep_keys` order): the value at the key's path in its params (null where its
    /// params have none).
    pub values: Vec<Value>,
    pub params: ModelParams,
    /// Whether the latest manifest asks for this point.
    pub current: bool,
    /// Hash of the runs' identity (model, params without the horizon keys) for their seeds.
    identity: [u64; 2],
}

/// Every point and run of a campaign, and what its latest manifest asks for.
#[derive(Clone, Debug)]
pub struct Plan {
    pub model: ModelKind,
    pub campaign_seed: u64,
    /// The runs each point of the latest manifest asks for.
    pub runs_per_point: RunsPerPoint,
    /// Dotted sweep paths into `params`, in the latest manifest's order.
    pub sweep_keys: Vec<String>,
    /// Every registered point, indexed by `point_id`.
    pub points: Vec<Point>,
    pub registry: Registry,
    /// A campaign with error targets: the replicas its rounds have decided per point (a
    /// point not in it has the pilot, `runs_per_point`); empty otherwise.
    pub decided: std::collections::BTreeMap<u32, u32>,
}

/// One run of the campaign.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RunSpec {
    pub run_id: u64,
    pub point_id: u32,
    pub replica: u32,
    pub seed: u64,
    /// The finished run this one continues from its final state (a longer horizon).
    pub continues: Option<u64>,
}

/// A deterministic subset of runs: `index` in 1..=`count`; run r belongs to shard
/// `r % count + 1`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: u32,
    pub count: u32,
}

impl Shard {
    pub const ALL: Shard = Shard { index: 1, count: 1 };

    /// `I/N` (the `--shard` flag): anything else is invalid input.
    pub fn parse(s: &str) -> Result<Shard, CampaignError> {
        let bad = |m: String| CampaignError::Invalid(m);
        let (a, b) = s
            .split_once('/')
            .ok_or_else(|| bad(format!("expected I/N, got {s:?}")))?;
        let index: u32 = a
            .trim()
            .parse()
            .map_err(|_| bad(format!("expected I/N with integers, got {s:?}")))?;
        let count: u32 = b
            .trim()
            .parse()
            .map_err(|_| bad(format!("expected I/N with integers, got {s:?}")))?;
        if count == 0 || index == 0 || index > count {
            return Err(bad(format!("expected 1 <= I <= N in I/N, got {s:?}")));
        }
        Ok(Shard { index, count })
    }

    pub fn contains(&self, run_id: u64) -> bool {
        run_id % self.count as u64 == (self.index - 1) as u64
    }

    /// A file-name-safe tag, e.g. `s1of4`.
    pub fn tag(&self) -> String {
        format!("s{}of{}", self.index, self.count)
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl Plan {
    /// The plan of a campaign whose registry is `registry` and latest manifest expanded to
    /// `current` (the points it asks for, registered).
    /// A registered point that does not parse is refused (a corrupt registry).
    pub fn new(
        m: &Manifest,
        expansion: Expansion,
        registry: Registry,
    ) -> Result<Plan, CampaignError> {
        let current: std::collections::BTreeSet<String> = expansion
            .points
            .iter()
            .map(|p| canonical(&p.to_value()))
            .collect();
        let mut points = Vec::with_capacity(registry.points.len());
        for rp in &registry.points {
            let mut errs = Vec::new();
            let params = m
                .model
                .params_from(&rp.params, "", &mut errs)
                .ok_or_else(|| {
                    CampaignError::Refused(format!(
                        "registered point {} does not parse: {errs:?}",
                        rp.id
                    ))
                })?;
            let value = params.to_value();
            let values = expansion
                .sweep_keys
                .iter()
                .map(|k| value_at(&value, k))
                .collect();
            points.push(Point {
                point_id: rp.id,
                values,
                current: current.contains(&canonical(&value)),
                identity: identity_hash(&run_identity(m.model, &value)),
                params,
            });
        }
        Ok(Plan {
            model: m.model,
            campaign_seed: m.seed,
            runs_per_point: m.runs_per_point(),
            sweep_keys: expansion.sweep_keys,
            points,
            registry,
            decided: Default::default(),
        })
    }

    pub fn n_runs(&self) -> u64 {
        self.registry.n_runs()
    }

    /// What the latest manifest asks per point, in words (`2 replicas`, `3 seeds`).
    pub fn runs_per_point_text(&self) -> String {
        match &self.runs_per_point {
            RunsPerPoint::Replicas(r) => format!("{r} replicas"),
            RunsPerPoint::Seeds(s) => format!("{} seeds", s.len()),
        }
    }

    /// The block holding run `run_id`.
    fn block(&self, run_id: u64) -> &RunBlock {
        let blocks = &self.registry.blocks;
        let i = blocks.partition_point(|b| b.first_run <= run_id) - 1;
        &blocks[i]
    }

    pub fn run(&self, run_id: u64) -> RunSpec {
        let b = self.block(run_id);
        let replica = b.first_replica + (run_id - b.first_run) as u32;
        RunSpec {
            run_id,
            point_id: b.point,
            replica,
            seed: self.seed(b, replica),
            continues: b
                .continues
                .and_then(|old| self.registry.run_of(old, replica)),
        }
    }

    /// The seed of replica `replica` of block `b`.
    pub fn seed(&self, b: &RunBlock, replica: u32) -> u64 {
        match &b.seeds {
            SeedSource::Params => derive_seed(
                self.campaign_seed,
                self.points[b.point as usize].identity,
                replica,
            ),
            SeedSource::Swept { keys, values } => {
                derive_seed_swept(self.campaign_seed, self.model, keys, values, replica)
            }
            SeedSource::Given(s) => s[(replica - b.first_replica) as usize],
        }
    }

    /// The replicas asked of a point with `replicas` (or error targets: the pilot, or what the
    /// rounds decided), None with `seeds`.
    pub fn replicas_of(&self, point_id: u32) -> Option<u32> {
        match &self.runs_per_point {
            RunsPerPoint::Replicas(n) => {
                Some(self.decided.get(&point_id).copied().unwrap_or(*n).max(*n))
            }
            RunsPerPoint::Seeds(_) => None,
        }
    }

    /// Whether the latest manifest asks for this run.
    pub fn is_current(&self, r: &RunSpec) -> bool {
        self.points[r.point_id as usize].current
            && match &self.runs_per_point {
                RunsPerPoint::Replicas(_) => r.replica < self.replicas_of(r.point_id).unwrap_or(0),
                RunsPerPoint::Seeds(s) => s.contains(&r.seed),
            }
    }

    /// The run's replica number in the latest manifest (None if it does not ask for the run):
    /// its replica with `replicas`, its seed's place in the list with `seeds`, as in a campaign
    /// started from the latest manifest.
    pub fn manifest_replica(&self, r: &RunSpec) -> Option<u32> {
        if !self.points[r.point_id as usize].current {
            return None;
        }
        match &self.runs_per_point {
            RunsPerPoint::Replicas(_) => {
                (r.replica < self.replicas_of(r.point_id).unwrap_or(0)).then_some(r.replica)
            }
            RunsPerPoint::Seeds(s) => s.iter().position(|x| *x == r.seed).map(|i| i as u32),
        }
    }

    /// The runs the latest manifest asks for per point (`replicas`, or the number of `seeds`).
    /// (With error targets: the most any current point has.)
    pub fn runs_asked_per_point(&self) -> u32 {
        match &self.runs_per_point {
            RunsPerPoint::Replicas(n) => self
                .points
                .iter()
                .filter(|p| p.current)
                .filter_map(|p| self.replicas_of(p.point_id))
                .max()
                .unwrap_or(*n),
            RunsPerPoint::Seeds(s) => s.len() as u32,
        }
    }

    /// Every run the latest manifest asks for, in run order.
    pub fn current_runs(&self) -> impl Iterator<Item = RunSpec> + '_ {
        (0..self.n_runs())
            .map(|r| self.run(r))
            .filter(|r| self.is_current(r))
    }

    /// The model's kinetic-theory tables for these points (none for models without theory).
    pub fn theory_tables(&self) -> Vec<&'static str> {
        let points: Vec<&ModelParams> = self.points.iter().map(|p| &p.params).collect();
        self.model.theory_tables(&points)
    }

    /// The replica number of a run.
    pub fn replica_of(&self, run_id: u64) -> u32 {
        let b = self.block(run_id);
        b.first_replica + (run_id - b.first_run) as u32
    }

    /// The swept values of a point, `key=value, ...` (empty without a sweep).
    pub fn label(&self, point_id: u32) -> String {
        self.sweep_keys
            .iter()
            .zip(&self.point(point_id).values)
            .map(|(k, v)| format!("{k}={v}"))
            .collect::<Vec<_>>()
            .join(", ")
    }

    pub fn point(&self, point_id: u32) -> &Point {
        &self.points[point_id as usize]
    }

    /// Column name of a swept parameter: its path with `.` replaced by `_`.
    pub fn sweep_column(key: &str) -> String {
        key.replace('.', "_")
    }
}

/// The value at a dotted sweep path of params (null where there is none).
fn value_at(params: &Value, key: &str) -> Value {
    let mut cur = params;
    for part in key.split('.') {
        let next = match cur {
            Value::Object(o) => o.get(part),
            Value::Array(a) => part.parse::<usize>().ok().and_then(|i| a.get(i)),
            _ => None,
        };
        match next {
            Some(n) => cur = n,
            None => return Value::Null,
        }
    }
    cur.clone()
}

/// FNV-1a, 64 bit, from `basis`: a stable hash of identity bytes (not for security).
fn fnv1a(bytes: &[u8], basis: u64) -> u64 {
    let mut h: u64 = basis;
    for b in bytes {
        h ^= *b as u64;
        h = h.wrapping_mul(0x100000001b3);
    }
    h
}

/// A 128-bit hash of a run identity (two FNV-1a of different bases).
fn identity_hash(identity: &str) -> [u64; 2] {
    [
        fnv1a(identity.as_bytes(), 0xcbf29ce484222325),
        fnv1a(identity.as_bytes(), 0x84222325cbf29ce4),
    ]
}

/// A run's seed: the first word of ChaCha20 keyed by the campaign seed, the hash of the run's
/// identity (model and params without the horizon keys: `registry::run_identity`) and the
/// replica. It depends on nothing else: not on the run's id, the sweep's order, the thread
/// count or the shard.
pub fn derive_seed(campaign_seed: u64, identity: [u64; 2], replica: u32) -> u64 {
    let mut key = [0u8; 32];
    key[..8].copy_from_slice(&campaign_seed.to_le_bytes());
    key[8..16].copy_from_slice(&identity[0].to_le_bytes());
    key[16..24].copy_from_slice(&identity[1].to_le_bytes());
    key[24..28].copy_from_slice(&replica.to_le_bytes());
    key[28..32].copy_from_slice(b"grn2");
    ChaCha20Rng::from_seed(key).next_u64()
}

/// The seeds of campaign directories of format 1: ChaCha20 keyed by (campaign seed, FNV-1a of
/// `model ␟ key=canonical(value) ... ␟ replica=r`, `"granular"`), the swept keys and values of
/// the point at the time. Runs registered then keep them.
pub fn derive_seed_swept(
    campaign_seed: u64,
    model: ModelKind,
    keys: &[String],
    values: &[Value],
    replica: u32,
) -> u64 {
    let mut identity = String::from(model.as_str());
    for (k, v) in keys.iter().zip(values) {
        identity.push('\u{1f}');
        identity.push_str(k);
        identity.push('=');
        identity.push_str(&canonical(v));
    }
    identity.push_str(&format!("\u{1f}replica={replica}"));
    let mut key = [0u8; 32];
    key[..8].copy_from_slice(&campaign_seed.to_le_bytes());
    key[8..16].copy_from_slice(&fnv1a(identity.as_bytes(), 0xcbf29ce484222325).to_le_bytes());
    key[16..24].copy_from_slice(b"granular");
    ChaCha20Rng::from_seed(key).next_u64()
}

/// Read and validate a manifest file and plan a new campaign of it.
pub fn load(path: &std::path::Path) -> Result<(Manifest, Plan), ManifestErrors> {
    let file = path.display().to_string();
    let text = validate::read(path)?;
    parse(&text, &file)
}

/// Validate manifest text ([`crate::manifest::check`]: the one validation pass) and plan a new
/// campaign of it; `file` names it in errors.
pub fn parse(text: &str, file: &str) -> Result<(Manifest, Plan), ManifestErrors> {
    let (manifest, expansion) = crate::manifest::check::check(text, file)?;
    let plan =
        fresh(&manifest, expansion).map_err(|e| ManifestErrors::whole(file, e.to_string()))?;
    Ok((manifest, plan))
}

/// The plan of a new campaign of `m`: its points and runs registered in sweep order.
pub fn fresh(m: &Manifest, expansion: Expansion) -> Result<Plan, CampaignError> {
    let mut registry = Registry::default();
    let runs = m.runs_per_point();
    registry
        .grow(
            &Asked {
                model: m.model,
                points: &expansion.points,
                runs: &runs,
            },
            &|_, _| 0,
        )
        .map_err(|e| CampaignError::Invalid(e.join("; ")))?;
    Plan::new(m, expansion, registry)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn manifest(sweep: &str) -> String {
        format!(
            r#"{{"name": "t", "model": "dsmc", "seed": 5, "replicas": 2,
            "params": {{"method": "low_rank", "species": {{"list": [{{"mass": 1, "diameter": 1, "count": 10}}]}},
                       "volume": 100, "restitution": {{"constant": 0.5}}, "t_end": 1}},
            "sweep": {sweep}}}"#
        )
    }

    /// A run's seed depends on its identity (swept values, replica), not on its position: adding
    /// a value to a sweep list leaves the seeds of existing points unchanged.
    #[test]
    fn seeds_follow_identity_not_position() {
        let (_, a) = parse(&manifest(r#"{"restitution.constant": [0.5, 0.9]}"#), "a").unwrap();
        let (_, b) = parse(
            &manifest(r#"{"restitution.constant": [0.1, 0.5, 0.9]}"#),
            "b",
        )
        .unwrap();
        assert_eq!(a.n_runs(), 4);
        assert_eq!(b.n_runs(), 6);
        // eps = 0.5 is point 0 in a, point 1 in b.
        assert_eq!(a.run(0).seed, b.run(2).seed);
        assert_eq!(a.run(1).seed, b.run(3).seed);
        assert_ne!(a.run(0).seed, a.run(1).seed);
        assert_ne!(a.run(0).seed, a.run(2).seed);
    }

    #[test]
    fn product_order_first_key_outermost() {
        let (_, p) = parse(
            &manifest(
                r#"{"method": ["low_rank", "bird"], "restitution.constant": [0.5, 0.9, 1.0]}"#,
            ),
            "m",
        )
        .unwrap();
        assert_eq!(p.points.len(), 6);
        assert_eq!(
            p.points[1].values,
            vec![serde_json::json!("low_rank"), serde_json::json!(0.9)]
        );
        assert_eq!(
            p.points[3].values,
            vec![serde_json::json!("bird"), serde_json::json!(0.5)]
        );
        let ModelParams::Dsmc(d) = &p.points[3].params else {
            panic!("dsmc params")
        };
        assert_eq!(d.method, crate::models::dsmc::params::DsmcMethod::Bird);
    }

    #[test]
    fn shards_partition_the_runs() {
        let parts: Vec<Shard> = (1..=3).map(|i| Shard { index: i, count: 3 }).collect();
        for r in 0..100u64 {
            assert_eq!(parts.iter().filter(|s| s.contains(r)).count(), 1);
        }
        assert!(Shard::parse("0/2").is_err());
        assert!(Shard::parse("3/2").is_err());
        assert_eq!(Shard::parse("2/4").unwrap(), Shard { index: 2, count: 4 });
    }
}
