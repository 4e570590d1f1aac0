//! One RFM run on 1 and 2 threads (rayon pools), stream versions 1, 2 and 4 (3 draws as 2 in
//! the RFM; 4 stores the particles by cell and addresses the noise by slot): particle-steps per
//! second of a 2D run at the thesis density of `thesis-df-large` (phi = 0.53,
//! eps_n = eps_t = 0.1, dt = 1e-6 s), N = 27 000 by default; checks the two thread counts
//! end in the same state. Prints the start-up (the initial layout's random sequential
//! addition, the wall seconds of `RfmSim::with_stream`) apart from the stepping.
//! Run: `cargo run --release --example bench_rfm_threads [N] [steps]`.

use std::time::Instant;

use granular::rfm::{RfmConfig, RfmSim};
use granular::rng::StreamVersion;

fn main() {
    let mut args = std::env::args().skip(1);
    let n: usize = args.next().map(|a| a.parse().expect("N")).unwrap_or(27_000);
    let steps: u64 = args
        .next()
        .map(|a| a.parse().expect("steps"))
        .unwrap_or(2000);
    let cfg = RfmConfig {
        n_particles: n,
        box_length: None,
        packing_fraction: Some(0.53),
        restitution_normal: 0.1,
        restitution_tangential: 0.1,
        dt: Some(1e-6),
        ..RfmConfig::default()
    };
    for (name, stream) in [
        ("v1", StreamVersion::V1),
        ("v2", StreamVersion::V2),
        ("v4", StreamVersion::V4),
    ] {
        let mut states = Vec::new();
        for threads in [1usize, 2] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("pool");
            let (start, rate, bytes) = pool.install(|| {
                let t0 = Instant::now();
                let mut sim = RfmSim::with_stream(cfg.clone(), 1, stream).expect("config");
                let start = t0.elapsed().as_secs_f64();
                sim.advance(steps / 4);
                let t0 = Instant::now();
                sim.advance(steps);
                let s = t0.elapsed().as_secs_f64();
                (start, n as f64 * steps as f64 / s, sim.state_bytes())
            });
            println!(
                "{name} N={n} threads={threads}: start-up (initial layout) {start:.3} s, \
                 stepping {rate:.3e} particle-steps/s"
            );
            states.push(bytes);
        }
        println!(
            "{name}: 1 and 2 threads identical: {}",
            states[0] == states[1]
        );
    }
}
