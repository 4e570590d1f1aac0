use super::*;
use crate::rfm::neighbours::min_image;
use crate::rng::RunRng;

fn uniform_2d(rng: &mut RunRng, n: usize, l: f64) -> Vec<f64> {
    (0..2 * n).map(|_| rng.f64() * l).collect()
}

/// Evenly spaced rods: every h-th neighbour separation is h L'/N (to round-off), all in one
/// bin (L'/N = 0.011 is not a bin edge), and the moments are its powers.
#[test]
fn neighbour_distances_of_even_spacing() {
    let (n, d, lr) = (50usize, 3e-3, 0.55);
    let l = lr + n as f64 * d;
    let x: Vec<f64> = (0..n).map(|i| (i as f64 + 0.5) * l / n as f64).collect();
    let cfg = NeighbourConfig {
        h_max: 4,
        lo: 1e-7,
        hi: lr,
        bins_per_decade: 20,
    };
    let mut acc = NeighbourAcc::new(cfg);
    for _ in 0..BLOCKS {
        acc.add(&x, l, d);
    }
    let (hist, moments) = acc.rows(BLOCKS as u64);
    for h in 1..=4u32 {
        let want = h as f64 * lr / n as f64;
        for r in neighbour_separations(&x, l, d, h as usize) {
            assert!((r - want).abs() <= 1e-13 * want, "h {h}: {r} vs {want}");
        }
        let rows: Vec<_> = hist.iter().filter(|r| r.h == h && r.count > 0).collect();
        assert_eq!(rows.len(), 1, "h {h}: one occupied bin");
        assert_eq!(rows[0].count, (n * BLOCKS) as u64);
        assert!(rows[0].lo <= want && want < rows[0].hi);
        for m in moments.iter().filter(|r| r.h == h) {
            let w = want.powi(m.order as i32);
            assert!((m.value - w).abs() <= 1e-11 * w, "h {h} m {}", m.order);
            assert!(m.sem.unwrap() <= 1e-12 * w);
        }
    }
}

/// Log-spaced bins: bins_per_decade per decade, edges exact powers, every value in the bin
/// whose edges bracket it.
#[test]
fn neighbour_bins_are_log_spaced() {
    let cfg = NeighbourConfig {
        h_max: 1,
        lo: 1e-6,
        hi: 1.0,
        bins_per_decade: 10,
    };
    let acc = NeighbourAcc::new(cfg);
    assert_eq!(acc.bins(), 60);
    for (j, e) in acc.edges.iter().enumerate() {
        let want = 10f64.powf(-6.0 + j as f64 / 10.0);
        assert!((e / want - 1.0).abs() < 1e-12);
    }
    let mut rng = RunRng::new(5);
    for _ in 0..10_000 {
        let r = 10f64.powf(-7.0 + 8.0 * rng.f64());
        let j = acc.bin(r);
        if r < 1e-6 {
            assert_eq!(j, 60);
        } else if r >= 1.0 {
            assert_eq!(j, 61);
        } else {
            assert!(acc.edges[j] <= r && r < acc.edges[j + 1], "{r} in bin {j}");
        }
    }
}

/// Random gaps: the histogram holds every separation, <R_h> = h L'/N exactly (the gaps sum
/// to L'), and each moment lies between the histogram's lower and upper bin-edge bounds.
#[test]
fn neighbour_moments_agree_with_histogram() {
    let (n, d, lr) = (200usize, 3e-3, 1.0);
    let l = lr + n as f64 * d;
    let mut rng = RunRng::new(11);
    let cfg = NeighbourConfig {
        h_max: 3,
        lo: 1e-9,
        hi: lr,
        bins_per_decade: 50,
    };
    let mut acc = NeighbourAcc::new(cfg);
    let snaps = 20;
    for _ in 0..snaps {
        // Gaps: exponential (the ideal gas of reduced points), scaled to sum to L'.
        let g: Vec<f64> = (0..n).map(|_| -(1.0 - rng.f64()).ln()).collect();
        let sum: f64 = g.iter().sum();
        let mut x = Vec::with_capacity(n);
        let mut pos = 0.1;
        for gi in &g {
            x.push(pos);
            pos += gi / sum * lr + d;
        }
        acc.add(&x, l, d);
    }
    let (hist, moments) = acc.rows(snaps as u64);
    for h in 1..=3u32 {
        let rows: Vec<_> = hist.iter().filter(|r| r.h == h).collect();
        let total: u64 = rows.iter().map(|r| r.count).sum();
        assert_eq!(total, (n * snaps) as u64);
        let out: u64 = rows
            .iter()
            .filter(|r| r.density.is_none())
            .map(|r| r.count)
            .sum();
        assert_eq!(out, 0, "h {h}: all separations in range");
        let integral: f64 = rows
            .iter()
            .filter_map(|r| r.density.map(|p| p * (r.hi - r.lo)))
            .sum();
        assert!((integral - 1.0).abs() < 1e-12);
        let mean = moments.iter().find(|m| m.h == h && m.order == 1).unwrap();
        let want = h as f64 * lr / n as f64;
        assert!(
            (mean.value - want).abs() < 1e-10 * want,
            "h {h}: {} vs {want}",
            mean.value
        );
        for m in moments.iter().filter(|m| m.h == h) {
            let p = m.order as i32;
            let lo: f64 = rows
                .iter()
                .filter(|r| r.density.is_some())
                .map(|r| r.count as f64 * r.lo.powi(p))
                .sum::<f64>()
                / total as f64;
            let hi: f64 = rows
                .iter()
                .filter(|r| r.density.is_some())
                .map(|r| r.count as f64 * r.hi.powi(p))
                .sum::<f64>()
                / total as f64;
            assert!(
                lo <= m.value && m.value <= hi,
                "h {h} m {p}: {} not in [{lo}, {hi}]",
                m.value
            );
            // 50 bins per decade: the bounds differ by a factor 10^(m/50) at most.
            assert!(hi / lo <= 10f64.powf(p as f64 / 50.0) * (1.0 + 1e-12));
        }
    }
}

/// The blocked recurrence sums equal the direct sums with trigonometry, shell by shell.
#[test]
fn structure_factor_matches_direct_sum() {
    let (n, l) = (137usize, 1.3);
    let mut rng = RunRng::new(3);
    let cfg = SkConfig {
        n_max: 9.5,
        every: 1,
    };
    let mut acc = SkAcc::new(cfg.clone());
    let mut w = acc.work();
    // Positions partly outside [0, L) (as the 2D engine's are between list builds).
    let mut x = uniform_2d(&mut rng, n, l);
    for (i, a) in x.iter_mut().enumerate() {
        if i % 7 == 0 {
            *a -= 0.01;
        }
    }
    acc.add(&mut w, &x, l);
    let rows = acc.rows(n, l, 1);
    let cut = cfg.n2_cut() as i64;
    let m = (cfg.n_max as i64) + 1;
    let mut direct: std::collections::BTreeMap<u64, (f64, u64)> = Default::default();
    for nx in -m..=m {
        for ny in -m..=m {
            let n2 = nx * nx + ny * ny;
            if n2 == 0 || n2 > cut {
                continue;
            }
            let (mut re, mut im) = (0.0, 0.0);
            for j in 0..n {
                let ph =
                    2.0 * std::f64::consts::PI * (nx as f64 * x[2 * j] + ny as f64 * x[2 * j + 1])
                        / l;
                re += ph.cos();
                im -= ph.sin();
            }
            let e = direct.entry(n2 as u64).or_default();
            e.0 += (re * re + im * im) / n as f64;
            e.1 += 1;
        }
    }
    assert_eq!(rows.len(), direct.len());
    for r in &rows {
        let (sum, count) = direct[&r.n2];
        assert_eq!(r.n_vectors, count, "shell {}", r.n2);
        let want = sum / count as f64;
        assert!(
            (r.s - want).abs() < 1e-10 * want.max(1.0),
            "shell {}: {} vs {want}",
            r.n2,
            r.s
        );
        assert!((r.k - 2.0 * std::f64::consts::PI * (r.n2 as f64).sqrt() / l).abs() < 1e-12);
    }
    // Shells 1, 2, 4, 5 have 4, 4, 4, 8 vectors.
    let nv: Vec<(u64, u64)> = rows.iter().take(4).map(|r| (r.n2, r.n_vectors)).collect();
    assert_eq!(nv, vec![(1, 4), (2, 4), (4, 4), (5, 8)]);
}

/// Uniform random positions (ideal gas): S(k) = 1 within the noise at every k. Each computed
/// vector gives |rho_k|^2/N ~ Exp(1) (one of each +-k pair is independent), so a group of m
/// vector-snapshots has mean 1 +- 1/sqrt(m); groups of shells with m >= 1000 must lie within
/// 5 sigma, and the block errors must match the scatter.
#[test]
fn structure_factor_of_ideal_gas_is_one() {
    let (n, l) = (1000usize, 0.2);
    let mut rng = RunRng::new(17);
    let mut acc = SkAcc::new(SkConfig {
        n_max: 60.0,
        every: 1,
    });
    let mut w = acc.work();
    let snaps = 10;
    for _ in 0..snaps {
        let x = uniform_2d(&mut rng, n, l);
        acc.add(&mut w, &x, l);
    }
    let rows = acc.rows(n, l, snaps as u64);
    let (mut sum, mut m, mut groups, mut worst) = (0.0, 0.0, 0, 0.0f64);
    let mut all = (0.0, 0.0);
    for r in &rows {
        let k = (r.n_vectors / 2 * snaps as u64) as f64;
        sum += r.s * k;
        m += k;
        all.0 += r.s * k;
        all.1 += k;
        if m >= 1000.0 {
            let z = (sum / m - 1.0) * m.sqrt();
            worst = worst.max(z.abs());
            groups += 1;
            sum = 0.0;
            m = 0.0;
        }
    }
    let z_all = (all.0 / all.1 - 1.0) * all.1.sqrt();
    eprintln!(
        "ideal S(k): {} shells, {groups} groups, worst |z| {worst:.2}, overall mean {:.5} (z {z_all:.2})",
        rows.len(),
        all.0 / all.1
    );
    assert!(groups >= 10);
    assert!(worst < 5.0, "worst group {worst} sigma");
    assert!(z_all.abs() < 5.0);
    // Block errors: sem ~ 1/sqrt(vectors x snapshots) on average.
    let ratio: f64 = rows
        .iter()
        .map(|r| r.sem.unwrap() * ((r.n_vectors / 2 * snaps as u64) as f64).sqrt())
        .sum::<f64>()
        / rows.len() as f64;
    assert!((0.6..1.2).contains(&ratio), "sem x sqrt(m) = {ratio}");
}

/// g(R) counts every pair once with the minimum image (against a brute-force count with
/// positions outside the box), g = 1 within the noise for uniform positions, and C(R) is the
/// ideal (N - 1) pi R^2 / L^2.
#[test]
fn radial_distribution_of_ideal_gas() {
    let (n, l) = (800usize, 0.3);
    let cfg = RadialConfig {
        r_max: 0.5 * l,
        bins: 60,
        every: 1,
        n: n as u64,
        l,
    };
    let mut acc = RadialAcc::new(cfg.clone());
    let mut rng = RunRng::new(23);
    let mut buf = Vec::new();
    let snaps = 10;
    let mut brute = vec![0u64; 60];
    for b in 0..snaps {
        let mut x = uniform_2d(&mut rng, n, l);
        for (i, a) in x.iter_mut().enumerate() {
            match i % 5 {
                0 => *a += l,
                1 => *a -= 0.003,
                _ => {}
            }
        }
        acc.add(&mut buf, &x);
        if b == 0 {
            for i in 0..n {
                for j in i + 1..n {
                    let dx = min_image(x[2 * i] - x[2 * j], l);
                    let dy = min_image(x[2 * i + 1] - x[2 * j + 1], l);
                    let r = (dx * dx + dy * dy).sqrt();
                    if r < cfg.r_max {
                        brute[((r / cfg.r_max * 60.0) as usize).min(59)] += 1;
                    }
                }
            }
            assert_eq!(&acc.counts[..60], &brute[..], "pair counts vs brute force");
        }
    }
    let rows = acc.rows(snaps as u64);
    let pairs = 0.5 * (n * (n - 1)) as f64;
    let mut worst = 0.0f64;
    for r in &rows {
        let ideal = pairs * std::f64::consts::PI * (r.r_hi.powi(2) - r.r_lo.powi(2)) / (l * l)
            * snaps as f64;
        let z = (r.count as f64 - ideal) / ideal.sqrt();
        worst = worst.max(z.abs());
        assert!((r.g - r.count as f64 / ideal).abs() < 1e-12);
        let c_ideal = (n - 1) as f64 * std::f64::consts::PI * r.r_hi.powi(2) / (l * l);
        assert!(
            (r.c / c_ideal - 1.0).abs() < 0.05 + 5.0 / (c_ideal * (n * snaps) as f64).sqrt(),
            "C({}) = {} vs {c_ideal}",
            r.r_hi,
            r.c
        );
    }
    let last = rows.last().unwrap();
    let c_ideal = (n - 1) as f64 * std::f64::consts::PI / 4.0;
    eprintln!(
        "ideal g(R): worst |z| {worst:.2}; C(L/2) = {:.3} vs {c_ideal:.3}",
        last.c
    );
    assert!(worst < 5.0, "worst bin {worst} sigma");
    assert!((last.c / c_ideal - 1.0).abs() < 0.01);
}

/// Timing (ignored): one S(k) and one g(R) evaluation for the thesis's phi = 0.530 system
/// (N = 3000, L = 0.2 m, default k_max = 212, R_max = L/2).
#[test]
#[ignore]
fn timing_thesis_system() {
    let (n, l) = (3000usize, 0.2);
    let mut rng = RunRng::new(1);
    let x = uniform_2d(&mut rng, n, l);
    let mut acc = SkAcc::new(SkConfig {
        n_max: 212.0,
        every: 1,
    });
    let mut w = acc.work();
    let t = std::time::Instant::now();
    for _ in 0..3 {
        acc.add(&mut w, &x, l);
    }
    let dt = t.elapsed().as_secs_f64() / 3.0;
    let macs = acc.computed_vectors() as f64 * n as f64;
    eprintln!(
        "S(k): {} vectors ({} computed), {} shells: {dt:.3} s per evaluation, {:.2e} complex multiply-adds/s",
        acc.computed_vectors() * 2,
        acc.computed_vectors(),
        acc.n2.len(),
        macs / dt
    );
    let mut g = RadialAcc::new(RadialConfig {
        r_max: 0.1,
        bins: 667,
        every: 1,
        n: n as u64,
        l,
    });
    let mut buf = Vec::new();
    let t = std::time::Instant::now();
    for _ in 0..3 {
        g.add(&mut buf, &x);
    }
    let dt = t.elapsed().as_secs_f64() / 3.0;
    eprintln!(
        "g(R): {dt:.4} s per evaluation, {:.2e} pairs/s",
        0.5 * (n * n) as f64 / dt
    );
}
