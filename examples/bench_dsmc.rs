//! Single-threaded DSMC timing of the paper's Table I set-up (or a scaled one).
//!
//! `cargo run --release --example bench_dsmc -- [low_rank|bird] [N1] [t_end] [eps] [seed] [msd|nomsd] [refresh_every] [theta]`
//! prints wall time, trials, collisions, rates and sum m v^2 at t_end.
//!
//! `cargo run --release --example bench_dsmc -- floors [N]` measures what bounds a low-rank
//! trial from below on this machine, for N particles' velocities (default 1 202 031, Table I):
//! the run's generator (`RunRng`, ChaCha8: 64-bit words per second; a trial takes five), the
//! latency of a dependent random access into an array of N velocity records (a pointer chase,
//! in huge-page-advised memory as the simulation's), and the throughput of independent random
//! record reads with the simulation's software prefetch a batch ahead (two per trial).

use std::time::Instant;

use granular::dsmc::DsmcSim;
use granular::models::dsmc::DsmcParams;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let get = |i: usize, d: &str| args.get(i).cloned().unwrap_or_else(|| d.to_string());
    if get(0, "") == "floors" {
        floors(get(1, "1202031").parse().expect("N"));
        return;
    }
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
    let mut sim = DsmcSim::with_stream(sys, seed, granular::rng::StreamVersion::CURRENT);
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

/// CPU seconds of this thread (Linux; wall seconds elsewhere): the floors are CPU rates, as
/// the peers' side-by-side figures, so that a shared machine's load does not enter them.
fn cpu_s() -> f64 {
    #[cfg(target_os = "linux")]
    {
        let mut ts = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: clock_gettime writes the timespec it is given.
        unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
        ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
    }
    #[cfg(not(target_os = "linux"))]
    {
        use std::sync::OnceLock;
        static T0: OnceLock<Instant> = OnceLock::new();
        T0.get_or_init(Instant::now).elapsed().as_secs_f64()
    }
}

/// The floors of a low-rank trial (see the module docs), per CPU second.
fn floors(n: usize) {
    use granular::rng::RunRng;
    // Generator: 64-bit words per second, through the windows the hot loop reads.
    let mut rng = RunRng::new(1);
    let words = 200_000_000u64;
    let t = cpu_s();
    let mut acc = 0u64;
    for _ in 0..words / 5 {
        let w = rng.window(5);
        acc ^= w[0] ^ w[1] ^ w[2] ^ w[3] ^ w[4];
        rng.consume(5);
    }
    let rng_s = cpu_s() - t;
    // Records of 24 bytes as the velocities; each holds in its first word the index of the
    // next record of one random cycle over all N (Sattolo's algorithm).
    let mut next: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        let j = rng.below(i);
        next.swap(i, j);
    }
    let mut rec = granular::memory::huge_vec(n, [0.0f64; 3]);
    for (i, r) in rec.iter_mut().enumerate() {
        r[0] = f64::from_bits(next[i] as u64);
    }
    let hops = 20_000_000usize.min(50 * n);
    let t = cpu_s();
    let mut p = 0usize;
    for _ in 0..hops {
        p = rec[p][0].to_bits() as usize;
    }
    let chase_s = cpu_s() - t;
    // Independent random reads, prefetched a batch of 32 pairs ahead as the trials are.
    let reads = 40_000_000usize;
    let idx: Vec<u32> = (0..1 << 20).map(|_| rng.below(n) as u32).collect();
    let mask = idx.len() - 1;
    let t = cpu_s();
    let mut sum = 0.0;
    for k in 0..reads {
        let ahead = idx[(k + 64) & mask] as usize;
        let q = rec.as_ptr().wrapping_add(ahead) as *const i8;
        #[cfg(target_arch = "x86_64")]
        // SAFETY: a prefetch is a hint; the address lies in `rec`.
        unsafe {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T1};
            _mm_prefetch(q, _MM_HINT_T1);
            _mm_prefetch(q.wrapping_add(23), _MM_HINT_T1);
        }
        let r = &rec[idx[k & mask] as usize];
        sum += r[1] + r[2];
    }
    let read_s = cpu_s() - t;
    println!(
        "floors N={n} ({} MB of records)\n\
         rng_words_per_s={:.3e} (5 words per trial: {:.3e} trials/s)\n\
         chase_ns={:.1} (dependent random access)\n\
         prefetched_reads_per_s={:.3e} (2 per trial: {:.3e} trials/s)  [{acc:x} {p} {sum}]",
        n * 24 / 1_000_000,
        words as f64 / rng_s,
        words as f64 / rng_s / 5.0,
        chase_s * 1e9 / hops as f64,
        reads as f64 / read_s,
        reads as f64 / read_s / 2.0,
    );
}
