//! Criterion benchmarks of the DSMC trial loop at a size that fits in cache (N1 = 1e4,
//! 125-species-style power law truncated by N1) and of the campaign overhead per run.
//! The full Table I timing is `scripts/bench-dsmc.sh` (seconds per run, too long here).

use criterion::{criterion_group, criterion_main, Criterion};
use granular::dsmc::{DsmcSim, DsmcSystem};
use granular::models::dsmc::DsmcParams;

fn system(method: &str, n1: u64) -> DsmcSystem {
    let p: DsmcParams = serde_json::from_value(serde_json::json!({
        "method": method,
        "species": {"power_law": {"n1": 0.1, "N1": n1, "theta": 3}},
        "restitution": {"constant": 0.5},
        "t_end": 1.0e9,
    }))
    .expect("params");
    p.system().expect("system")
}

fn trials(c: &mut Criterion) {
    let mut g = c.benchmark_group("dsmc_1e5_trials");
    g.sample_size(20);
    for method in ["low_rank", "bird"] {
        let mut sim = DsmcSim::with_stream(
            system(method, 10_000),
            7,
            granular::rng::StreamVersion::CURRENT,
        );
        g.bench_function(method, |b| {
            b.iter(|| sim.advance(100_000).expect("physics"))
        });
    }
    g.finish();
}

criterion_group!(benches, trials);
criterion_main!(benches);
