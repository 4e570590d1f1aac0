//! CPU seconds of the kinetic-theory temperature ODE (13) of the paper's Table I low-rank run
//! (power law N_1 = 1e6, theta = 3: 126 species, n_1 = 0.1, eps = 0.5, T(0) = 1, outputs log
//! from 0.1 to 100 at 4 per decade), as `dsmc::predict` computes it beside the run (the
//! temperatures, then tau_v at each output), and of the Fig 1 binary up to t = 1e9.
//! Run: `cargo run --release --example bench_theory [repeats]`; the best of the repeats is shown.

use std::time::Instant;

use granular::theory::{diffusion, temperature, PairRestitution, Species};

fn best(label: &str, reps: usize, mut f: impl FnMut() -> f64) {
    let mut t = f64::INFINITY;
    let mut check = 0.0;
    for _ in 0..reps {
        let t0 = Instant::now();
        check = f();
        t = t.min(t0.elapsed().as_secs_f64());
    }
    println!("{label:<44} {:8.4} s  (checksum {check:.17e})", t);
}

fn main() {
    let reps: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(5);
    let (n1, theta, dens1) = (1e6f64, 3.0f64, 0.1f64);
    let volume = n1 / dens1;
    let mut table1 = Vec::new();
    for k in 1u64.. {
        let count = (n1 * (k as f64).powf(-theta)).round();
        if count < 1.0 {
            break;
        }
        table1.push(Species::new(k as f64, (k as f64).cbrt(), count / volume));
    }
    let times: Vec<f64> = (0..=12)
        .map(|j| 10f64.powf(-1.0 + j as f64 / 4.0))
        .collect();
    let r = PairRestitution::Constant(0.5);
    let t0 = vec![1.0; table1.len()];
    best(
        &format!("Table I ({} species), T_k and tau_v", table1.len()),
        reps,
        || {
            let temps = temperature::evolve_temperatures(&table1, &r, &t0, &times).unwrap();
            let mut c = 0.0;
            for t in &temps {
                c += diffusion::tau_v(&table1, t, &r).iter().sum::<f64>();
                c += t.iter().sum::<f64>();
            }
            c
        },
    );
    let binary = [Species::new(1.0, 1.0, 0.1), Species::new(100.0, 1.0, 0.1)];
    let times: Vec<f64> = (0..=40)
        .map(|j| 10f64.powf(-1.0 + j as f64 / 4.0))
        .collect();
    best("Fig 1 binary to t = 1e9", reps, || {
        temperature::evolve_temperatures(&binary, &r, &[1.0, 1.0], &times)
            .unwrap()
            .iter()
            .flatten()
            .sum()
    });
}
