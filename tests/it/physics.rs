//! Physics of the DSMC simulators: Haff's law, bitwise checkpoint/restore, conservation laws,
//! and agreement of the low-rank and Bird methods. Every statistical check uses fixed seeds;
//! its tolerance and the noise it is derived from are stated at the check.

use serde_json::{json, Value};

use granular::campaign::run_in_memory;
use granular::dsmc::{DsmcSim, DsmcSystem, SpeciesRow};
use granular::engine::{Engine, RunOutput};
use granular::manifest::dsmc::DsmcParams;
use granular::plan::ModelParams;
use granular::theory::temperature::{haff, tau0, Species};

use super::util::heavy;

/// Validated DSMC params from a JSON `params` object (through the manifest loader, so every
/// set-up used here is one a user could write).
fn dsmc_params(params: Value) -> DsmcParams {
    let m = json!({"name": "physics-test", "model": "dsmc", "seed": 1, "params": params});
    let (_, plan) = granular::manifest::parse_manifest(&m.to_string(), "inline").unwrap_or_else(|e| panic!("{e}"));
    let ModelParams::Dsmc(p) = plan.points[0].params.clone();
    p
}

fn model(params: Value) -> ModelParams {
    ModelParams::Dsmc(dsmc_params(params))
}

/// The rows of one species, in time order.
fn species_rows(out: &RunOutput, species: u32) -> Vec<&SpeciesRow> {
    let mut v: Vec<&SpeciesRow> = out.dsmc_species.iter().filter(|r| r.species == species).collect();
    v.sort_by(|a, b| a.t.total_cmp(&b.t));
    v
}

// ---------------------------------------------------------------------------------------
// (a) Haff's law
// ---------------------------------------------------------------------------------------

/// One species (m = 1, sigma = 1, n = 0.1, eps = 0.9) cools as T(t)/T(0) = (1 + t/tau_0)^-2.
///
/// Tolerance 2% (relative, at every output time up to 4 tau_0, where T has fallen 25-fold).
/// Expected deviations: (i) noise: T is a mean over N = 1e5 particles and the cooling
/// rate fluctuates with it, both ~ 1/sqrt(N) = 0.3%; (ii) physics: Haff's law assumes a
/// Maxwellian, while the homogeneous cooling state has a Sonine coefficient
/// a2 = 16 (1-eps)(1-2 eps^2) / (81 - 17 eps + 30 eps^2 (1-eps)) = -0.015 at eps = 0.9, which
/// changes the cooling rate by a factor 1 + 3 a2 / 16 = 0.997, i.e. T by ~0.5% at 4 tau_0.
/// 2% is thus ~2.5x the largest expected deviation, while a wrong collision rate or
/// restitution (e.g. a factor 2 in the rate, or eps^2 for eps) is off by tens of percent.
fn check_haff(method: &str, count: u64, seed: u64) {
    let (n, eps) = (0.1, 0.9);
    let tau = tau0(&[Species { mass: 1.0, diameter: 1.0, density: n }], &[1.0], eps);
    // The textbook value: tau_0 = 2 / xi(0), xi = (4/3) sqrt(pi) n sigma^2 sqrt(T/m) (1 - eps^2).
    let textbook = 2.0 / (4.0 / 3.0 * std::f64::consts::PI.sqrt() * n * (1.0 - eps * eps));
    assert!((tau - textbook).abs() < 1e-12 * textbook, "tau0 = {tau}, textbook {textbook}");
    let t_end = 4.0 * tau;
    let params = model(json!({
        "method": method,
        "species": {"list": [{"mass": 1, "diameter": 1, "count": count}]},
        "number_density": n,
        "restitution": {"constant": eps},
        "t_end": t_end,
        "output_times": {"log": {"from": tau / 100.0, "to": t_end, "per_decade": 8}}
    }));
    let out = run_in_memory(&params, seed).unwrap_or_else(|e| panic!("{method}: {e}"));
    let rows = species_rows(&out, 1);
    assert!(rows.len() >= 20, "{method}: only {} output rows", rows.len());
    assert_eq!(rows[0].t, 0.0);
    assert_eq!(rows.last().unwrap().t, t_end);
    let t0 = rows[0].temperature;
    assert!((t0 - 1.0).abs() < 1e-12, "{method}: initial temperature {t0}");
    let mut bad = Vec::new();
    let mut worst: f64 = 0.0;
    for r in &rows {
        let want = haff(r.t, tau);
        let dev = r.temperature / t0 / want - 1.0;
        worst = worst.max(dev.abs());
        if dev.abs() > 0.02 {
            bad.push(format!("  t = {:.3} (t/tau0 = {:.3}): T/T0 = {:.5}, Haff {:.5} ({:+.2}%)", r.t, r.t / tau, r.temperature / t0, want, 100.0 * dev));
        }
    }
    assert!(bad.is_empty(), "{method}, N = {count}: T(t)/T(0) departs from Haff's law by more than 2%:\n{}", bad.join("\n"));
    eprintln!("haff {method}: N = {count}, {} output times, worst deviation {:.3}%, {} collisions", rows.len(), 100.0 * worst, out.collisions);
}

#[test]
fn haff_law_low_rank() {
    let _g = heavy();
    check_haff("low_rank", 100_000, 11);
}

#[test]
fn haff_law_bird() {
    let _g = heavy();
    check_haff("bird", 100_000, 12);
}

// ---------------------------------------------------------------------------------------
// (b) checkpoint / restore is bitwise
// ---------------------------------------------------------------------------------------

/// Rows as bit patterns, so that equality is bitwise (and -0.0 != 0.0, NaN == NaN).
type RowBits = (u64, u32, u64, u64, u64, u64, Option<u64>, u64);

fn row_bits(rows: &[SpeciesRow]) -> Vec<RowBits> {
    rows.iter()
        .map(|r| (r.t.to_bits(), r.species, r.mass.to_bits(), r.diameter.to_bits(), r.count, r.temperature.to_bits(), r.msd.map(f64::to_bits), r.collisions))
        .collect()
}

struct Finished {
    out: RunOutput,
    state: Vec<u8>,
    chunks: usize,
    bound_raises: u64,
}

/// Run in chunks of `chunk` trials. After chunk j (1-based), if `restore_at(j)`: serialise,
/// drop the engine and continue from `Engine::restore`; if `peek_at(j)`: serialise and
/// continue with the same engine (what a campaign checkpoint does).
fn chunked(params: &ModelParams, seed: u64, chunk: u64, restore_at: &dyn Fn(usize) -> bool, peek_at: &dyn Fn(usize) -> bool) -> Finished {
    let mut e = Engine::start(params, seed).unwrap();
    let mut chunks = 0;
    loop {
        let done = e.advance(chunk).unwrap();
        chunks += 1;
        if done {
            break;
        }
        assert!(chunks < 100_000, "run does not finish");
        if restore_at(chunks) {
            let bytes = e.state_bytes();
            let t = e.time();
            drop(e);
            e = Engine::restore(params, &bytes).unwrap();
            assert_eq!(e.time().to_bits(), t.to_bits());
            // The restored engine serialises to the same bytes (nothing lost or re-derived
            // differently).
            assert!(e.state_bytes() == bytes, "state bytes change across a restore (chunk {chunks})");
        } else if peek_at(chunks) {
            let _ = e.state_bytes();
        }
    }
    let state = e.state_bytes();
    let bound_raises = match &e {
        Engine::Dsmc(sim) => sim.st.bound_raises,
    };
    Finished { out: e.finish(), state, chunks, bound_raises }
}

fn check_restore_bitwise(method: &str, msd: bool) {
    let observables: Vec<&str> = if msd { vec!["temperature", "msd"] } else { vec![] };
    // Polydisperse (16 species) and strongly inelastic, so speed bounds are raised and
    // refreshed (both change the selection tables a restore must rebuild identically).
    let params = model(json!({
        "method": method,
        "species": {"power_law": {"n1": 0.1, "N1": 4000, "theta": 3}},
        "restitution": {"constant": 0.5},
        "t_end": 20.0,
        "output_times": {"log": {"from": 0.01, "to": 20.0, "per_decade": 6}},
        "observables": observables,
        "refresh_every": 0.7
    }));
    let seed = 0x5eed;
    let reference = run_in_memory(&params, seed).unwrap();
    // ~5 collisions per particle: ~7 bound refreshes (every 0.7 N collisions) and many raises.
    assert!(reference.collisions > 15_000, "{method}: too few collisions ({}) to test anything", reference.collisions);
    assert_eq!(reference.dsmc_species.iter().all(|r| r.msd.is_some()), msd);
    // ~13 chunks: a chunk is a number of trials, so chunk ends fall at arbitrary moments.
    let chunk = reference.trials / 12 + 1;
    let never = |_: usize| false;
    let straight = chunked(&params, seed, chunk, &never, &never);
    assert!(straight.chunks >= 10, "{method}: only {} chunks", straight.chunks);
    // Low-rank per-species bounds are raised often (a species' fastest particle speeds up in
    // a collision); Bird's single bound, set by the largest diameter, rarely is in a cooling gas.
    if method == "low_rank" {
        assert!(straight.bound_raises > 0, "{method}: no speed bound was raised; the test misses that path");
    }
    let what = format!("{method}, msd = {msd}");
    // Chunking itself changes nothing.
    assert_eq!(row_bits(&straight.out.dsmc_species), row_bits(&reference.dsmc_species), "{what}: chunked run differs from one call");
    assert_eq!((straight.out.collisions, straight.out.trials), (reference.collisions, reference.trials), "{what}");

    let n = straight.chunks;
    type When = Box<dyn Fn(usize) -> bool>;
    let variants: Vec<(String, When, When)> = vec![
        (format!("restore after chunk {}", n / 2), Box::new(move |j| j == n / 2), Box::new(never)),
        ("restore after chunk 1".into(), Box::new(|j| j == 1), Box::new(never)),
        ("restore after every 2nd chunk".into(), Box::new(|j| j % 2 == 0), Box::new(never)),
        ("serialise after every chunk, no restore".into(), Box::new(never), Box::new(|_| true)),
    ];
    for (name, restore_at, peek_at) in variants {
        let got = chunked(&params, seed, chunk, &*restore_at, &*peek_at);
        assert_eq!(got.chunks, straight.chunks, "{what}, {name}: chunk count");
        assert_eq!(row_bits(&got.out.dsmc_species), row_bits(&straight.out.dsmc_species), "{what}, {name}: rows differ");
        assert_eq!((got.out.collisions, got.out.trials), (straight.out.collisions, straight.out.trials), "{what}, {name}: counters differ");
        assert!(got.state == straight.state, "{what}, {name}: final state bytes differ");
    }
    // A different seed gives a different run (so the equalities above are not vacuous).
    let other = run_in_memory(&params, seed + 1).unwrap();
    assert_ne!(row_bits(&other.dsmc_species), row_bits(&reference.dsmc_species), "{what}: seed has no effect");
}

#[test]
fn restore_is_bitwise_low_rank() {
    let _g = heavy();
    check_restore_bitwise("low_rank", false);
    check_restore_bitwise("low_rank", true);
}

#[test]
fn restore_is_bitwise_bird() {
    let _g = heavy();
    check_restore_bitwise("bird", false);
    check_restore_bitwise("bird", true);
}

/// A checkpoint of another run (other species) is refused, not misread.
#[test]
fn restore_refuses_a_foreign_state() {
    let a = model(json!({"method": "low_rank", "species": {"power_law": {"n1": 0.1, "N1": 300, "theta": 3}}, "restitution": {"constant": 0.5}, "t_end": 1.0}));
    let b = model(json!({"method": "low_rank", "species": {"power_law": {"n1": 0.1, "N1": 400, "theta": 3}}, "restitution": {"constant": 0.5}, "t_end": 1.0}));
    let mut e = Engine::start(&a, 1).unwrap();
    e.advance(1000).unwrap();
    let bytes = e.state_bytes();
    assert!(Engine::restore(&b, &bytes).is_err(), "restored a state of 300-monomer run into a 400-monomer run");
    assert!(Engine::restore(&a, &bytes[..bytes.len() / 2]).is_err(), "restored a truncated state");
    assert!(Engine::restore(&a, &bytes).is_ok());
}

// ---------------------------------------------------------------------------------------
// (c) conservation laws
// ---------------------------------------------------------------------------------------

/// sum_k m_k sum_{particles of k} |v| (the scale of momentum round-off).
fn sum_m_abs_v(sim: &DsmcSim) -> f64 {
    let mut start = 0;
    let mut s = 0.0;
    for sp in &sim.sys.species {
        let end = start + sp.count as usize;
        for v in &sim.st.vel[start..end] {
            s += sp.mass * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        }
        start = end;
    }
    assert_eq!(start, sim.st.vel.len());
    s
}

/// Total momentum stays zero and sum m v^2 never increases (is conserved for eps = 1).
///
/// Momentum bound: |P| <= 1e-10 * S, S = the largest sum m|v| seen so far. A collision
/// conserves m_a v_a + m_b v_b up to a few ulp (2.2e-16 relative) of the pair's momenta, so
/// after C ~ 1e4-1e5 collisions the error is at most ~ C * 1e-15 * max m|v| (worst case, all
/// errors aligned) ~ 1e-10 max m|v|, while S ~ N * mean m|v| with N ~ 6000: the bound is
/// at least 100 times the worst-case round-off (observed: ~1e-16 S). A wrong impulse split
/// (m_a for m_b in (41)) gives |P| ~ 0.1 S.
/// Energy: sum m v^2 may not rise by more than 1e-12 relative between checks (round-off is
/// ~1e-14 relative after 1e5 collisions); with eps = 1 it must stay within 1e-9 of its start.
fn check_conservation(method: &str, eps: f64) {
    let params = dsmc_params(json!({
        "method": method,
        "species": {"power_law": {"n1": 0.1, "N1": 5000, "theta": 3}},
        "restitution": {"constant": eps},
        "t_end": 30.0
    }));
    let sys = DsmcSystem::from_params(&params).unwrap();
    assert!(sys.species.len() >= 10);
    let mut sim = DsmcSim::new(sys, 77);
    let e0 = sim.sum_mv2();
    let mut e_prev = e0;
    let mut scale = sum_m_abs_v(&sim);
    let mut checks = 0;
    let (mut worst_p, mut worst_e): (f64, f64) = (0.0, 0.0);
    loop {
        let p = sim.momentum();
        let pn = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        scale = scale.max(sum_m_abs_v(&sim));
        worst_p = worst_p.max(pn / scale);
        assert!(pn <= 1e-10 * scale, "{method}, eps = {eps}: |P| = {pn:e} > 1e-10 * {scale:e} at t = {}", sim.st.t);
        let e = sim.sum_mv2();
        assert!(e <= e_prev * (1.0 + 1e-12), "{method}, eps = {eps}: sum m v^2 rose from {e_prev:e} to {e:e} at t = {}", sim.st.t);
        if eps == 1.0 {
            assert!((e - e0).abs() <= 1e-9 * e0, "{method}, eps = 1: sum m v^2 = {e:e}, started at {e0:e} (t = {})", sim.st.t);
        }
        worst_e = worst_e.max((e - e0).abs() / e0);
        e_prev = e;
        checks += 1;
        if sim.advance(2_000).unwrap() {
            break;
        }
    }
    let (p, e) = (sim.momentum(), sim.sum_mv2());
    let pn = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    assert!(pn <= 1e-10 * scale, "{method}, eps = {eps}: final |P| = {pn:e}");
    assert!(e <= e_prev * (1.0 + 1e-12));
    assert!(checks >= 20, "{method}: only {checks} checks");
    let n = sim.sys.n_particles() as u64;
    // Enough collisions that the checks mean something (every particle collides several
    // times: ~5 collisions per particle for eps = 0, ~25 for eps = 1, at t = 30).
    assert!(sim.st.collisions > 2 * n, "{method}, eps = {eps}: only {} collisions", sim.st.collisions);
    eprintln!("{method}, eps = {eps}: {checks} checks, {} collisions, max |P| / sum m|v| = {worst_p:.1e}, max |E - E0| / E0 = {worst_e:.1e}", sim.st.collisions);
    if eps < 1.0 {
        assert!(e < 0.7 * e0, "{method}, eps = {eps}: the gas did not cool ({e:e} vs {e0:e})");
    } else {
        assert!((e - e0).abs() <= 1e-9 * e0);
    }
}

#[test]
fn conservation_laws() {
    let _g = heavy();
    for method in ["low_rank", "bird"] {
        for eps in [0.0, 0.5, 1.0] {
            check_conservation(method, eps);
        }
    }
}

// ---------------------------------------------------------------------------------------
// (d) the low-rank and Bird methods simulate the same process
// ---------------------------------------------------------------------------------------

fn mean_sem(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let m = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / (n - 1.0);
    (m, (var / n).sqrt())
}

/// (total collisions, species-1 temperature at t_end) of each seed, two threads.
fn ensemble(params: &ModelParams, seeds: &[u64]) -> Vec<(f64, f64)> {
    let t_end = match params {
        ModelParams::Dsmc(p) => p.t_end,
    };
    let one = |seed: u64| {
        let out = run_in_memory(params, seed).unwrap();
        let last = species_rows(&out, 1).last().copied().cloned().unwrap();
        assert_eq!(last.t, t_end);
        (out.collisions as f64, last.temperature)
    };
    let half = seeds.len() / 2;
    std::thread::scope(|s| {
        let h = s.spawn(|| seeds[..half].iter().map(|&x| one(x)).collect::<Vec<_>>());
        let mut rest: Vec<(f64, f64)> = seeds[half..].iter().map(|&x| one(x)).collect();
        let mut v = h.join().unwrap();
        v.append(&mut rest);
        v
    })
}

/// Same set-up, independent seeds: the mean total number of collisions and the mean
/// species-1 temperature at t_end agree within 4 combined standard errors,
/// 4 sqrt(sem_lr^2 + sem_bird^2), the standard errors estimated from 10 replicas per method.
/// (For two means with ~18 degrees of freedom, |t| > 4 has probability < 1e-3.) Both
/// quantities would move by many standard errors with a wrong rate or acceptance in one
/// method: the standard error of the mean collision count is < 0.1% of it, that of the
/// temperature ~0.2%.
#[test]
fn low_rank_and_bird_agree() {
    let _g = heavy();
    let base = |method: &str| {
        model(json!({
            "method": method,
            "species": {"power_law": {"n1": 0.1, "N1": 20000, "theta": 3}},
            "restitution": {"constant": 0.5},
            "t_end": 20.0
        }))
    };
    let seeds: Vec<u64> = (0..10).map(|i| 1000 + i).collect();
    let lr = ensemble(&base("low_rank"), &seeds);
    let bird_seeds: Vec<u64> = seeds.iter().map(|s| s + 500).collect();
    let bird = ensemble(&base("bird"), &bird_seeds);
    let mut report = Vec::new();
    let mut ok = true;
    for (name, pick) in [("total collisions", 0usize), ("species-1 temperature at t_end", 1)] {
        let x: Vec<f64> = lr.iter().map(|v| if pick == 0 { v.0 } else { v.1 }).collect();
        let y: Vec<f64> = bird.iter().map(|v| if pick == 0 { v.0 } else { v.1 }).collect();
        let (mx, sx) = mean_sem(&x);
        let (my, sy) = mean_sem(&y);
        let combined = (sx * sx + sy * sy).sqrt();
        let z = (mx - my) / combined;
        report.push(format!("  {name}: low_rank {mx:.6e} +- {sx:.2e}, bird {my:.6e} +- {sy:.2e}, difference {z:+.2} combined SE"));
        assert!(combined > 0.0 && combined < 0.05 * mx.abs(), "{name}: degenerate standard error {combined:e}");
        ok &= z.abs() < 4.0;
    }
    eprintln!("low_rank vs bird:\n{}", report.join("\n"));
    assert!(ok, "low-rank and Bird disagree by more than 4 combined standard errors:\n{}", report.join("\n"));
}
