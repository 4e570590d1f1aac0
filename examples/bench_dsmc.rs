//! Single-threaded DSMC timing of the paper's Table I set-up (or a scaled one).
//!
//! `cargo run --release --example bench_dsmc -- [low_rank|bird] [N1] [t_end] [eps] [seed] [msd|nomsd] [refresh_every] [theta]`
//! prints wall time, trials, collisions, rates and sum m v^2 at t_end.

use std::time::Instant;

use granular::dsmc::DsmcSim;
use granular::models::dsmc::DsmcParams;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let get = |i: usize, d: &str| args.get(i).cloned().unwrap_or_else(|| d.to_string());
    let method = get(0, "low_rank");
    let n1: u64 = get(1, "1000000").parse().expect("N1");
    let t_end: f64 = get(2, "100").parse().expect("t_end");
    let eps: f64 = get(3, "0.5").parse().expect("eps");
    let seed: u64 = get(4, "1").parse().expect("seed");
    let msd = get(5, "nomsd") == "msd";
    let refresh: f64 = get(6, "1").parse().expect("refresh_every");
    let theta: f64 = get(7, "3").parse().expect("theta");
    let params: DsmcParams = serde_json::from_value(serde_json::json!({
        "method": method,
        "species": {"power_law": {"n1": 0.1, "N1": n1, "theta": theta}},
        "restitution": {"constant": eps},
        "t_end": t_end,
        "observables": if msd { vec!["msd"] } else { vec![] },
        "refresh_every": refresh,
    }))
    .expect("params");
    let sys = params.system().expect("system");
    let (m, n) = (sys.species.len(), sys.n_particles());
    let t0 = Instant::now();
    let mut sim = DsmcSim::new(sys, seed);
    let setup = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    while !sim.advance(u64::MAX).expect("physics") {}
    let wall = t1.elapsed().as_secs_f64();
    let st = &sim.st;
    println!(
        "method={method} N1={n1} species={m} N={n} t_end={t_end} eps={eps} seed={seed} msd={msd}\n\
         setup_s={setup:.3} wall_s={wall:.3} trials={} collisions={} acceptance={:.4} bound_raises={}\n\
         trials_per_s={:.3e} collisions_per_s={:.3e} ns_per_trial={:.1} sum_mv2={:.2}",
        st.trials,
        st.collisions,
        st.collisions as f64 / st.trials as f64,
        st.bound_raises,
        st.trials as f64 / wall,
        st.collisions as f64 / wall,
        wall * 1e9 / st.trials as f64,
        sim.sum_mv2()
    );
}
