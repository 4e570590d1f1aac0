//! Physics of the DSMC simulators: Haff's law, bitwise checkpoint/restore, conservation laws,
//! agreement of the low-rank and Bird methods, and the time-averaged MSD (recording on its
//! grid, no effect on the trajectory, ergodicity of the elastic gas). Every statistical check uses fixed seeds;
//! its tolerance and the noise it is derived from are stated at the check.

use serde_json::{json, Value};

use granular::dsmc::{DsmcSim, SpeciesRow, TamsdRow};
use granular::models::dsmc::DsmcParams;
use granular::models::{Engine, ModelParams};
use granular::physics::PhysicsError;
use granular::rng::StreamVersion;
use granular::theory::temperature::{haff, tau0};
use granular::theory::Species;

use super::util::heavy;

/// Validated DSMC params from a JSON `params` object (through the manifest loader, so every
/// set-up used here is one a user could write).
fn dsmc_params(params: Value) -> DsmcParams {
    let m = json!({"name": "physics-test", "model": "dsmc", "seed": 1, "params": params});
    let (_, plan) =
        granular::campaign::plan::parse(&m.to_string(), "inline").unwrap_or_else(|e| panic!("{e}"));
    let ModelParams::Dsmc(p) = plan.points[0].params.clone() else {
        panic!("dsmc params")
    };
    p
}

fn model(params: Value) -> ModelParams {
    ModelParams::Dsmc(dsmc_params(params))
}

/// The rows and counters of a finished DSMC run (what its `dsmc_species`, `dsmc_tamsd` and
/// `runs` rows hold).
#[derive(Debug, Clone, PartialEq)]
struct RunOutput {
    dsmc_species: Vec<SpeciesRow>,
    dsmc_tamsd: Vec<TamsdRow>,
    collisions: u64,
    trials: u64,
}

/// The output of a finished engine (a DSMC one).
fn finish(e: Engine) -> RunOutput {
    let Engine::Dsmc(mut sim) = e else {
        unreachable!("DSMC test")
    };
    RunOutput {
        dsmc_tamsd: sim.tamsd_rows(),
        dsmc_species: sim.take_rows(),
        collisions: sim.st.collisions,
        trials: sim.st.trials,
    }
}

/// Run to the end in memory.
fn run_in_memory(params: &ModelParams, seed: u64) -> Result<RunOutput, PhysicsError> {
    let mut e = params
        .start(seed, StreamVersion::CURRENT)
        .map_err(|e| PhysicsError {
            t: 0.0,
            reason: e.to_string(),
        })?;
    while !e.advance(u64::MAX)? {}
    Ok(finish(e))
}

/// The rows of one species, in time order.
fn species_rows(out: &RunOutput, species: u32) -> Vec<&SpeciesRow> {
    let mut v: Vec<&SpeciesRow> = out
        .dsmc_species
        .iter()
        .filter(|r| r.species == species)
        .collect();
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
    let tau = tau0(
        &[Species {
            mass: 1.0,
            diameter: 1.0,
            density: n,
        }],
        &[1.0],
        eps,
    );
    // The textbook value: tau_0 = 2 / xi(0), xi = (4/3) sqrt(pi) n sigma^2 sqrt(T/m) (1 - eps^2).
    let textbook = 2.0 / (4.0 / 3.0 * std::f64::consts::PI.sqrt() * n * (1.0 - eps * eps));
    assert!(
        (tau - textbook).abs() < 1e-12 * textbook,
        "tau0 = {tau}, textbook {textbook}"
    );
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
    assert!(
        rows.len() >= 20,
        "{method}: only {} output rows",
        rows.len()
    );
    assert_eq!(rows[0].t, 0.0);
    assert_eq!(rows.last().unwrap().t, t_end);
    let t0 = rows[0].temperature;
    assert!(
        (t0 - 1.0).abs() < 1e-12,
        "{method}: initial temperature {t0}"
    );
    let mut bad = Vec::new();
    let mut worst: f64 = 0.0;
    for r in &rows {
        let want = haff(r.t, tau);
        let dev = r.temperature / t0 / want - 1.0;
        worst = worst.max(dev.abs());
        if dev.abs() > 0.02 {
            bad.push(format!(
                "  t = {:.3} (t/tau0 = {:.3}): T/T0 = {:.5}, Haff {:.5} ({:+.2}%)",
                r.t,
                r.t / tau,
                r.temperature / t0,
                want,
                100.0 * dev
            ));
        }
    }
    assert!(
        bad.is_empty(),
        "{method}, N = {count}: T(t)/T(0) departs from Haff's law by more than 2%:\n{}",
        bad.join("\n")
    );
    eprintln!(
        "haff {method}: N = {count}, {} output times, worst deviation {:.3}%, {} collisions",
        rows.len(),
        100.0 * worst,
        out.collisions
    );
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
        .map(|r| {
            (
                r.t.to_bits(),
                r.species,
                r.mass.to_bits(),
                r.diameter.to_bits(),
                r.count,
                r.temperature.to_bits(),
                r.msd.map(f64::to_bits),
                r.collisions,
            )
        })
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
fn chunked(
    params: &ModelParams,
    seed: u64,
    chunk: u64,
    restore_at: &dyn Fn(usize) -> bool,
    peek_at: &dyn Fn(usize) -> bool,
) -> Finished {
    let mut e = params.start(seed, StreamVersion::CURRENT).unwrap();
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
            e = params.restore(&bytes).unwrap();
            assert_eq!(e.time().to_bits(), t.to_bits());
            // The restored engine serialises to the same bytes (nothing lost or re-derived
            // differently).
            assert!(
                e.state_bytes() == bytes,
                "state bytes change across a restore (chunk {chunks})"
            );
        } else if peek_at(chunks) {
            let _ = e.state_bytes();
        }
    }
    let state = e.state_bytes();
    let bound_raises = match &e {
        Engine::Dsmc(sim) => sim.st.bound_raises,
        _ => unreachable!("DSMC test"),
    };
    Finished {
        out: finish(e),
        state,
        chunks,
        bound_raises,
    }
}

/// TAMSD rows as bit patterns.
fn tamsd_bits(rows: &[TamsdRow]) -> Vec<(u32, u64, u64, u64)> {
    rows.iter()
        .map(|r| {
            (
                r.species,
                r.lag.to_bits(),
                r.tamsd.to_bits(),
                r.t_total.to_bits(),
            )
        })
        .collect()
}

/// The restore tests' set-up: polydisperse (20 species) and strongly inelastic, so speed
/// bounds are raised and refreshed (both change the selection tables a restore must rebuild
/// identically). With `tamsd`: 30 tracers per species (212 in all) on a grid of 400 steps
/// (step 0.05), so grid times fall between most collisions' chunks and checkpoints.
fn restore_params(method: &str, observables: &[&str], tamsd: Value) -> Value {
    let mut p = json!({
        "method": method,
        "species": {"power_law": {"n1": 0.1, "N1": 4000, "theta": 3}},
        "restitution": {"constant": 0.5},
        "t_end": 20.0,
        "output_times": {"log": {"from": 0.01, "to": 20.0, "per_decade": 6}},
        "observables": observables,
        "refresh_every": 0.7
    });
    if observables.contains(&"tamsd") {
        p["tamsd"] = tamsd;
    }
    p
}

fn default_tamsd() -> Value {
    json!({"lags": [0.05, 1.0, 5.0, 15.0], "tracers": 30, "grid": 400})
}

fn check_restore_bitwise(method: &str, observables: &[&str]) {
    let msd = observables.contains(&"msd");
    let tamsd = observables.contains(&"tamsd");
    let params = model(restore_params(method, observables, default_tamsd()));
    let seed = 0x5eed;
    let reference = run_in_memory(&params, seed).unwrap();
    // ~5 collisions per particle: ~7 bound refreshes (every 0.7 N collisions) and many raises.
    assert!(
        reference.collisions > 15_000,
        "{method}: too few collisions ({}) to test anything",
        reference.collisions
    );
    assert!(
        reference
            .dsmc_species
            .iter()
            .all(|r| r.msd.is_some() == msd),
        "{method}: msd column"
    );
    // Every species at 4 lags.
    let n_species = reference.dsmc_species.iter().filter(|r| r.t == 0.0).count();
    assert_eq!(
        reference.dsmc_tamsd.len(),
        if tamsd { n_species * 4 } else { 0 },
        "{method}: tamsd rows"
    );
    // ~13 chunks: a chunk is a number of trials, so chunk ends fall at arbitrary moments.
    let chunk = reference.trials / 12 + 1;
    let never = |_: usize| false;
    let straight = chunked(&params, seed, chunk, &never, &never);
    assert!(
        straight.chunks >= 10,
        "{method}: only {} chunks",
        straight.chunks
    );
    // Low-rank per-species bounds are raised often (a species' fastest particle speeds up in
    // a collision); Bird's single bound, set by the largest diameter, rarely is in a cooling gas.
    if method == "low_rank" {
        assert!(
            straight.bound_raises > 0,
            "{method}: no speed bound was raised; the test misses that path"
        );
    }
    let what = format!("{method}, observables {observables:?}");
    // Chunking itself changes nothing.
    assert_eq!(
        row_bits(&straight.out.dsmc_species),
        row_bits(&reference.dsmc_species),
        "{what}: chunked run differs from one call"
    );
    assert_eq!(
        tamsd_bits(&straight.out.dsmc_tamsd),
        tamsd_bits(&reference.dsmc_tamsd),
        "{what}: chunked run's tamsd differs"
    );
    assert_eq!(
        (straight.out.collisions, straight.out.trials),
        (reference.collisions, reference.trials),
        "{what}"
    );

    let n = straight.chunks;
    type When = Box<dyn Fn(usize) -> bool>;
    let variants: Vec<(String, When, When)> = vec![
        (
            format!("restore after chunk {}", n / 2),
            Box::new(move |j| j == n / 2),
            Box::new(never),
        ),
        (
            "restore after chunk 1".into(),
            Box::new(|j| j == 1),
            Box::new(never),
        ),
        (
            "restore after every 2nd chunk".into(),
            Box::new(|j| j % 2 == 0),
            Box::new(never),
        ),
        (
            "serialise after every chunk, no restore".into(),
            Box::new(never),
            Box::new(|_| true),
        ),
    ];
    for (name, restore_at, peek_at) in variants {
        let got = chunked(&params, seed, chunk, &*restore_at, &*peek_at);
        assert_eq!(got.chunks, straight.chunks, "{what}, {name}: chunk count");
        assert_eq!(
            row_bits(&got.out.dsmc_species),
            row_bits(&straight.out.dsmc_species),
            "{what}, {name}: rows differ"
        );
        assert_eq!(
            tamsd_bits(&got.out.dsmc_tamsd),
            tamsd_bits(&straight.out.dsmc_tamsd),
            "{what}, {name}: tamsd rows differ"
        );
        assert_eq!(
            (got.out.collisions, got.out.trials),
            (straight.out.collisions, straight.out.trials),
            "{what}, {name}: counters differ"
        );
        assert!(
            got.state == straight.state,
            "{what}, {name}: final state bytes differ"
        );
    }
    // A different seed gives a different run (so the equalities above are not vacuous).
    let other = run_in_memory(&params, seed + 1).unwrap();
    assert_ne!(
        row_bits(&other.dsmc_species),
        row_bits(&reference.dsmc_species),
        "{what}: seed has no effect"
    );
    if tamsd {
        assert_ne!(
            tamsd_bits(&other.dsmc_tamsd),
            tamsd_bits(&reference.dsmc_tamsd),
            "{what}: seed has no effect on tamsd"
        );
    }
}

#[test]
fn restore_is_bitwise_low_rank() {
    let _g = heavy();
    check_restore_bitwise("low_rank", &[]);
    check_restore_bitwise("low_rank", &["temperature", "msd"]);
    check_restore_bitwise("low_rank", &["msd", "tamsd"]);
}

#[test]
fn restore_is_bitwise_bird() {
    let _g = heavy();
    check_restore_bitwise("bird", &[]);
    check_restore_bitwise("bird", &["temperature", "msd"]);
    check_restore_bitwise("bird", &["tamsd"]);
}

/// A checkpoint of another run (other species) is refused, not misread.
#[test]
fn restore_refuses_a_foreign_state() {
    let a = model(
        json!({"method": "low_rank", "species": {"power_law": {"n1": 0.1, "N1": 300, "theta": 3}}, "restitution": {"constant": 0.5}, "t_end": 1.0}),
    );
    let b = model(
        json!({"method": "low_rank", "species": {"power_law": {"n1": 0.1, "N1": 400, "theta": 3}}, "restitution": {"constant": 0.5}, "t_end": 1.0}),
    );
    let mut e = a.start(1, StreamVersion::CURRENT).unwrap();
    e.advance(1000).unwrap();
    let bytes = e.state_bytes();
    assert!(
        b.restore(&bytes).is_err(),
        "restored a state of 300-monomer run into a 400-monomer run"
    );
    assert!(
        a.restore(&bytes[..bytes.len() / 2]).is_err(),
        "restored a truncated state"
    );
    assert!(a.restore(&bytes).is_ok());
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
    let sys = params.system().unwrap();
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
        assert!(
            pn <= 1e-10 * scale,
            "{method}, eps = {eps}: |P| = {pn:e} > 1e-10 * {scale:e} at t = {}",
            sim.st.t
        );
        let e = sim.sum_mv2();
        assert!(
            e <= e_prev * (1.0 + 1e-12),
            "{method}, eps = {eps}: sum m v^2 rose from {e_prev:e} to {e:e} at t = {}",
            sim.st.t
        );
        if eps == 1.0 {
            assert!(
                (e - e0).abs() <= 1e-9 * e0,
                "{method}, eps = 1: sum m v^2 = {e:e}, started at {e0:e} (t = {})",
                sim.st.t
            );
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
    assert!(
        pn <= 1e-10 * scale,
        "{method}, eps = {eps}: final |P| = {pn:e}"
    );
    assert!(e <= e_prev * (1.0 + 1e-12));
    assert!(checks >= 20, "{method}: only {checks} checks");
    let n = sim.sys.n_particles() as u64;
    // Enough collisions that the checks mean something (every particle collides several
    // times: ~5 collisions per particle for eps = 0, ~25 for eps = 1, at t = 30).
    assert!(
        sim.st.collisions > 2 * n,
        "{method}, eps = {eps}: only {} collisions",
        sim.st.collisions
    );
    eprintln!("{method}, eps = {eps}: {checks} checks, {} collisions, max |P| / sum m|v| = {worst_p:.1e}, max |E - E0| / E0 = {worst_e:.1e}", sim.st.collisions);
    if eps < 1.0 {
        assert!(
            e < 0.7 * e0,
            "{method}, eps = {eps}: the gas did not cool ({e:e} vs {e0:e})"
        );
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
        _ => unreachable!("DSMC test"),
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
    for (name, pick) in [
        ("total collisions", 0usize),
        ("species-1 temperature at t_end", 1),
    ] {
        let x: Vec<f64> = lr
            .iter()
            .map(|v| if pick == 0 { v.0 } else { v.1 })
            .collect();
        let y: Vec<f64> = bird
            .iter()
            .map(|v| if pick == 0 { v.0 } else { v.1 })
            .collect();
        let (mx, sx) = mean_sem(&x);
        let (my, sy) = mean_sem(&y);
        let combined = (sx * sx + sy * sy).sqrt();
        let z = (mx - my) / combined;
        report.push(format!("  {name}: low_rank {mx:.6e} +- {sx:.2e}, bird {my:.6e} +- {sy:.2e}, difference {z:+.2} combined SE"));
        assert!(
            combined > 0.0 && combined < 0.05 * mx.abs(),
            "{name}: degenerate standard error {combined:e}"
        );
        ok &= z.abs() < 4.0;
    }
    eprintln!("low_rank vs bird:\n{}", report.join("\n"));
    assert!(
        ok,
        "low-rank and Bird disagree by more than 4 combined standard errors:\n{}",
        report.join("\n")
    );
}

// ---------------------------------------------------------------------------------------
// (e) the time-averaged MSD
// ---------------------------------------------------------------------------------------

/// Grid times are handled exactly like output times: with every particle a tracer and output
/// times on the grid, the mean of |R(t_j)|^2 over a species' recorded tracer positions is the
/// `msd` row at t_j (the same extrapolation of the same state; bit for bit for Bird, to 1e-12
/// for low-rank, whose particles change places between speed groups so that the row sums
/// them in another order than the tracers). A grid point recorded after the collision that
/// follows it, or at a neighbouring grid time, would differ in most digits.
#[test]
fn tamsd_grid_records_the_state_like_outputs() {
    let _g = heavy();
    for method in ["low_rank", "bird"] {
        // 10 species, N_1 = 1000: `tracers` = 1000 makes every particle a tracer. Grid step
        // 20/400 = 0.05; every output time is a grid time.
        let params = dsmc_params(json!({
            "method": method,
            "species": {"power_law": {"n1": 0.1, "N1": 1000, "theta": 3}},
            "restitution": {"constant": 0.5},
            "t_end": 20.0,
            "output_times": {"list": [0.05, 0.1, 1.0, 2.35, 7.5, 19.95]},
            "observables": ["msd", "tamsd"],
            "tamsd": {"lags": [1.0], "tracers": 1000, "grid": 400}
        }));
        let sys = params.system().unwrap();
        let mut sim = DsmcSim::new(sys, 31);
        while !sim.advance(100_000).unwrap() {}
        let plan = sim.sys.observe.tamsd.clone().expect("tamsd plan");
        let nt = plan.n_tracers();
        assert_eq!(
            nt,
            sim.sys.n_particles(),
            "{method}: every particle is a tracer"
        );
        assert_eq!(
            sim.st.tracks.len(),
            nt * 401,
            "{method}: one position per tracer and grid point"
        );
        assert!(
            sim.st.collisions > 3 * nt as u64,
            "{method}: only {} collisions",
            sim.st.collisions
        );
        let rows = sim.take_rows();
        assert_eq!(rows.len(), 8 * sim.sys.species.len(), "{method}: rows");
        let mut compared = 0;
        for r in &rows {
            let j = (r.t / 0.05).round() as usize;
            assert_eq!(
                plan.time(20.0, j as u64).to_bits(),
                r.t.to_bits(),
                "{method}: output time {} is not grid time {j}",
                r.t
            );
            let s = r.species as usize - 1;
            let start: usize = sim.sys.species[..s].iter().map(|x| x.count as usize).sum();
            let count = sim.sys.species[s].count as usize;
            let mut r2 = 0.0;
            for p in &sim.st.tracks[j * nt + start..j * nt + start + count] {
                r2 += p[0] * p[0] + p[1] * p[1] + p[2] * p[2];
            }
            let from_tracks = r2 / count as f64;
            let msd = r.msd.expect("msd");
            let same = if method == "bird" {
                from_tracks.to_bits() == msd.to_bits()
            } else {
                (from_tracks - msd).abs() <= 1e-12 * msd.abs()
            };
            assert!(
                same,
                "{method}: species {} at t = {}: tracks give {from_tracks:e}, msd row {msd:e}",
                r.species, r.t
            );
            compared += 1;
        }
        eprintln!("{method}: {compared} msd rows equal the tracer positions of their grid point, bit for bit");
    }
}

/// Recording the TAMSD draws no random numbers and does not feed back: with the same seed,
/// the `dsmc_species` rows (temperatures, collision counts, and the MSD where it is
/// observed) and the run's counters are bitwise the same with and without `tamsd`, and with
/// other grids, tracer counts and lags; rows of a lag do not depend on the other lags.
#[test]
fn tamsd_does_not_change_the_trajectory() {
    let _g = heavy();
    for method in ["low_rank", "bird"] {
        let run = |obs: &[&str], tamsd: Value| {
            run_in_memory(&model(restore_params(method, obs, tamsd)), 0xface).unwrap()
        };
        let without_msd = |rows: &[SpeciesRow]| -> Vec<RowBits> {
            row_bits(rows)
                .into_iter()
                .map(|r| (r.0, r.1, r.2, r.3, r.4, r.5, None, r.7))
                .collect()
        };
        let plain = run(&[], Value::Null);
        let msd = run(&["msd"], Value::Null);
        let a = run(
            &["tamsd"],
            json!({"lags": [1.0, 5.0], "tracers": 30, "grid": 400}),
        );
        let b = run(
            &["tamsd"],
            json!({"lags": [0.05, 1.0, 5.0, 15.0], "tracers": 30, "grid": 400}),
        );
        let c = run(
            &["msd", "tamsd"],
            json!({"lags": [1.0], "tracers": 1000, "grid": 1000}),
        );
        let d = run(
            &["temperature", "tamsd"],
            json!({"lags": [3.0], "tracers": 1, "grid": 7}),
        );
        assert!(
            plain.dsmc_species.iter().all(|r| r.msd.is_none())
                && a.dsmc_species.iter().all(|r| r.msd.is_none())
        );
        for (name, out) in [
            ("msd", &msd),
            ("tamsd grid 400", &a),
            ("tamsd 4 lags", &b),
            ("msd + tamsd grid 1000", &c),
            ("tamsd grid 7", &d),
        ] {
            assert_eq!(
                without_msd(&out.dsmc_species),
                without_msd(&plain.dsmc_species),
                "{method}: {name} changes the species rows"
            );
            assert_eq!(
                (out.collisions, out.trials),
                (plain.collisions, plain.trials),
                "{method}: {name} changes the counters"
            );
        }
        assert_eq!(
            row_bits(&c.dsmc_species),
            row_bits(&msd.dsmc_species),
            "{method}: tamsd changes the msd column"
        );
        let n_species = plain.dsmc_species.iter().filter(|r| r.t == 0.0).count();
        assert_eq!(a.dsmc_tamsd.len(), n_species * 2);
        let common: Vec<TamsdRow> = b
            .dsmc_tamsd
            .iter()
            .filter(|r| r.lag == 1.0 || r.lag == 5.0)
            .cloned()
            .collect();
        assert_eq!(
            tamsd_bits(&a.dsmc_tamsd),
            tamsd_bits(&common),
            "{method}: a lag's rows depend on the other lags"
        );
        eprintln!(
            "{method}: species rows and counters identical with and without tamsd ({} collisions)",
            plain.collisions
        );
    }
}

/// Ergodicity of the elastic gas: with eps = 1 and a Maxwellian start (the equilibrium of
/// the elastic DSMC: temperature constant, increments stationary), the time-averaged MSD (26)
/// at lag Delta has the expectation of the ensemble MSD <R^2(Delta)>, on the grid as well.
///
/// One species, N = 20 000, n = 0.1 (tau_v = D m / T ~ 2.1), t_end = 200, 1000 tracers on a
/// grid of 2000 steps, lags 0.5, 2, 10, 50 (from ballistic to diffusive); the ensemble MSD is
/// the `msd` row at t = Delta (all N particles). Per replica r, d_r = TAMSD_r / MSD_r - 1;
/// over 8 independent replicas the test requires |mean d| <= 4 SE(d) (the standard error
/// measured from the replicas' scatter; for the mean of 8 values, |t_7| > 4 has probability
/// 0.5%), and SE(d) < 1.5%, so that a bias of 6% or more (a lag off by one grid step at
/// Delta = 0.5 is ~40%) cannot pass. Expected scatter of d_r: the TAMSD of N_tr Gaussian
/// tracers has relative variance ~ 4 Delta / (9 t N_tr) (1% at Delta = 50) and the ensemble
/// MSD 2 / (3 N) (0.6%).
#[test]
fn tamsd_equals_msd_in_elastic_equilibrium() {
    use granular::theory::diffusion::{diffusion_coefficients, tau_v};
    use granular::theory::msd::msd_hcs;
    use granular::theory::PairRestitution;
    let _g = heavy();
    let lags: [f64; 4] = [0.5, 2.0, 10.0, 50.0];
    let (n_particles, tracers, t_end) = (20_000.0, 1000.0, 200.0);
    let params = model(json!({
        "method": "low_rank",
        "species": {"list": [{"mass": 1, "diameter": 1, "count": 20000}]},
        "number_density": 0.1,
        "restitution": {"constant": 1.0},
        "t_end": t_end,
        "output_times": {"list": lags},
        "observables": ["msd", "tamsd"],
        "tamsd": {"lags": lags, "tracers": 1000, "grid": 2000}
    }));
    let one = |seed: u64| -> Vec<(f64, f64)> {
        let out = run_in_memory(&params, seed).unwrap();
        assert_eq!(out.dsmc_tamsd.len(), lags.len());
        lags.iter()
            .map(|&lag| {
                let ta = out
                    .dsmc_tamsd
                    .iter()
                    .find(|r| r.lag.to_bits() == lag.to_bits())
                    .unwrap_or_else(|| panic!("no tamsd row at lag {lag}"));
                assert_eq!(ta.t_total, t_end);
                let msd = out
                    .dsmc_species
                    .iter()
                    .find(|r| r.t.to_bits() == lag.to_bits())
                    .and_then(|r| r.msd)
                    .expect("msd row");
                (ta.tamsd, msd)
            })
            .collect()
    };
    let seeds: Vec<u64> = (0..8).map(|i| 7000 + i).collect();
    let per_seed: Vec<Vec<(f64, f64)>> = std::thread::scope(|s| {
        let h = s.spawn(|| seeds[..4].iter().map(|&x| one(x)).collect::<Vec<_>>());
        let rest: Vec<Vec<(f64, f64)>> = seeds[4..].iter().map(|&x| one(x)).collect();
        let mut v = h.join().unwrap();
        v.extend(rest);
        v
    });
    let species = [Species {
        mass: 1.0,
        diameter: 1.0,
        density: 0.1,
    }];
    let r = PairRestitution::Constant(1.0);
    let (d0, tv) = (
        diffusion_coefficients(&species, &[1.0], &r)[0],
        tau_v(&species, &[1.0], &r)[0],
    );
    let mut report = Vec::new();
    let mut ok = true;
    for (i, &lag) in lags.iter().enumerate() {
        let d: Vec<f64> = per_seed.iter().map(|v| v[i].0 / v[i].1 - 1.0).collect();
        let (m, se) = mean_sem(&d);
        let sd = se * (d.len() as f64).sqrt();
        let expected_sd = (4.0 * lag / (9.0 * t_end * tracers) + 2.0 / (3.0 * n_particles)).sqrt();
        let tamsd_mean = per_seed.iter().map(|v| v[i].0).sum::<f64>() / d.len() as f64;
        let theory = msd_hcs(d0, tv, f64::INFINITY, lag);
        report.push(format!(
            "  Delta = {lag:>4}: TAMSD/MSD - 1 = {:+.3}% +- {:.3}% ({:+.2} SE; per-replica sd {:.2}%, expected ~{:.2}%); TAMSD {tamsd_mean:.4e}, theory (22) {theory:.4e} ({:+.1}%)",
            100.0 * m,
            100.0 * se,
            m / se,
            100.0 * sd,
            100.0 * expected_sd,
            100.0 * (tamsd_mean / theory - 1.0)
        ));
        ok &= se > 0.0 && se < 0.015 && m.abs() <= 4.0 * se;
    }
    eprintln!("elastic gas, 8 replicas:\n{}", report.join("\n"));
    assert!(ok, "TAMSD and ensemble MSD differ by more than 4 standard errors (or the test cannot resolve 6%):\n{}", report.join("\n"));
}
