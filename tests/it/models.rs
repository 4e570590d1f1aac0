//! The tests every model of the closed list (`ModelKind::ALL`) inherits, run on its example
//! params (`Model::EXAMPLE`), so a new model is covered the moment it is registered:
//!
//! - checkpoint and restore: a run advanced in small chunks, serialised at a (fixed-seed)
//!   random chunk, dropped and restored from those bytes, then continued, gives bitwise the
//!   rows of the straight run, and the restored engine serialises to the same bytes;
//! - a tiny campaign (2 replicas) of the model through the campaign engine: every table the
//!   model lists exists, is read back by the generic reader (`store::dataset`) with rows in it,
//!   and `verify` finds no problem.

use std::collections::BTreeMap;

use arrow_array::RecordBatch;
use serde_json::{json, Value};

use granular::campaign::{dispatch, verify, Campaign, RunOptions, Silent};
use granular::models::{Engine, ModelKind, ModelParams, RunIds};
use granular::rng::StreamVersion;

use super::util::{heavy, Lcg};

/// The example params of `kind`, validated through the manifest loader.
fn example(kind: ModelKind) -> (Value, ModelParams) {
    let params: Value = serde_json::from_str(kind.example()).expect("example params are JSON");
    let m = json!({"name": "example", "model": kind.as_str(), "seed": 7, "params": params});
    let (_, plan) = granular::campaign::plan::parse(&m.to_string(), kind.as_str())
        .unwrap_or_else(|e| panic!("the example of {} is invalid: {e}", kind.as_str()));
    (params, plan.points[0].params.clone())
}

const IDS: RunIds = RunIds {
    run_id: 3,
    point_id: 0,
};

/// Run to the end in chunks of `work`; after chunk `restore_at` (if any) serialise, drop and
/// restore. Returns the rows and the number of chunks.
fn run(
    p: &ModelParams,
    seed: u64,
    work: u64,
    restore_at: Option<usize>,
) -> (Vec<(&'static str, RecordBatch)>, u64, u64, usize) {
    let mut e: Engine = p.start(seed, StreamVersion::CURRENT).expect("starts");
    let mut chunks = 0;
    while !e.advance(work).expect("no physics failure") {
        chunks += 1;
        assert!(chunks < 1_000_000, "the run does not finish");
        if Some(chunks) == restore_at {
            let bytes = e.state_bytes();
            let t = e.time();
            drop(e);
            e = p.restore(&bytes).expect("restores its own checkpoint");
            assert_eq!(e.time().to_bits(), t.to_bits(), "time across a restore");
            assert!(
                e.state_bytes() == bytes,
                "state bytes change across a restore"
            );
        }
    }
    let rows = e.finish(IDS);
    (rows.tables, rows.collisions, rows.trials, chunks + 1)
}

#[test]
fn every_model_restores_bitwise_from_a_checkpoint_at_a_random_point() {
    let _g = heavy();
    let mut rng = Lcg(0x5eed_1234);
    for &kind in ModelKind::ALL {
        let (_, p) = example(kind);
        // Small chunks, so that the run has many restore points.
        let work = 2_000;
        let (straight, collisions, trials, chunks) = run(&p, 11, work, None);
        assert!(
            chunks >= 4,
            "{}: the example run takes {chunks} chunks of {work}; too few to restore mid-run",
            kind.as_str()
        );
        assert!(!straight.is_empty(), "{}: no rows", kind.as_str());
        for _ in 0..3 {
            let at = 1 + (rng.next_f64() * (chunks - 2) as f64) as usize;
            let (restored, c2, t2, _) = run(&p, 11, work, Some(at));
            assert_eq!(
                (collisions, trials),
                (c2, t2),
                "{}: counters after a restore at chunk {at} of {chunks}",
                kind.as_str()
            );
            assert!(
                restored == straight,
                "{}: rows after a restore at chunk {at} of {chunks} differ from the straight run",
                kind.as_str()
            );
        }
        // The chunk size does not change the rows either.
        let (other, ..) = run(&p, 11, 7_919, None);
        assert!(
            other == straight,
            "{}: chunking changes the rows",
            kind.as_str()
        );
    }
}

#[test]
fn every_model_runs_a_campaign_whose_tables_the_generic_reader_reads() {
    let _g = heavy();
    for &kind in ModelKind::ALL {
        let (params, _) = example(kind);
        let dir = tempfile::tempdir().unwrap();
        let manifest = dir.path().join("m.json");
        let m = json!({
            "name": format!("generic-{}", kind.as_str()),
            "model": kind.as_str(),
            "seed": 3,
            "replicas": 2,
            "params": params,
        });
        std::fs::write(&manifest, m.to_string()).unwrap();
        let out = dir.path().join("out");
        let c = Campaign::create_or_open(&manifest, &out).expect("campaign");
        let opts = RunOptions {
            threads: 2,
            ..RunOptions::default()
        };
        let o = dispatch::run(&c, &opts, &mut Silent).expect("runs");
        assert!(o.complete && o.failed == 0, "{}: {o:?}", kind.as_str());
        let data = c.data();
        let mut rows = BTreeMap::new();
        for t in c.tables() {
            assert!(data.dir(t).is_dir(), "{}: table {t} missing", kind.as_str());
            let n: usize = data
                .read(t)
                .unwrap_or_else(|e| panic!("{}: {t}: {e}", kind.as_str()))
                .iter()
                .map(|b| b.num_rows())
                .sum();
            assert!(n > 0, "{}: table {t} has no rows", kind.as_str());
            rows.insert(t, n);
        }
        assert_eq!(rows["runs"], 2, "{}: {rows:?}", kind.as_str());
        let v = verify::verify(&c, granular::campaign::integrity::Depth::Full).expect("verify");
        assert!(v.problems.is_empty(), "{}: {:?}", kind.as_str(), v.problems);
    }
}
