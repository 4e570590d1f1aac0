//! Single-thread throughput of the RFM simulator in particle-steps per second.
//! 2D: the thesis system (N = 2000, L = 0.2 m, eps_n = eps_t = 0.6, dt = 1e-6 s);
//! 1D: N = 2000 on a ring of reduced length 1 m, eps = 0.6.
//! Each also with free-path / post-collision velocity tracking on (contact counts every step).
//! Run: `cargo run --release --example bench_rfm [steps]`.

use std::time::Instant;

use granular::rfm::freepath::FreePathConfig;
use granular::rfm::{RfmConfig, RfmSim};

fn time(label: &str, cfg: RfmConfig, steps: u64, free_paths: bool) {
    let n = cfg.n_particles as f64;
    let mut sim = RfmSim::new(cfg, 1).expect("valid config");
    if free_paths {
        sim.track_free_paths(FreePathConfig {
            paths: true,
            lo: 1e-9,
            hi: 1.0,
            bins_per_decade: 20,
            velocity: Some(([-5.0, 5.0], 2000)),
            from_step: 0,
            sample_every: steps,
        });
    }
    // Let the noise heat the system first (velocities, contacts and list rebuilds typical).
    sim.advance(steps / 4);
    let b0 = sim.list_builds();
    let t0 = Instant::now();
    sim.advance(steps);
    let s = t0.elapsed().as_secs_f64();
    println!(
        "{label}: {steps} steps in {s:.3} s = {:.3e} particle-steps/s (T = {:.4e} m^2/s^2, \
         {} list builds)",
        n * steps as f64 / s,
        sim.temperature(),
        sim.list_builds() - b0
    );
}

fn main() {
    let steps: u64 = std::env::args()
        .nth(1)
        .map(|a| a.parse().expect("steps"))
        .unwrap_or(100_000);
    for fp in [false, true] {
        let tag = if fp { " +free paths" } else { "" };
        time(
            &format!("2D N=2000 L=0.2 eps=0.6/0.6{tag}"),
            RfmConfig::default(),
            steps,
            fp,
        );
        time(
            &format!("1D N=2000 L'=1 eps=0.6{tag}"),
            RfmConfig::thesis_1d(2000, 0.6),
            steps,
            fp,
        );
    }
}
