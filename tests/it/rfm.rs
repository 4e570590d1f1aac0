//! The `rfm` model through the whole engine: a small 2D campaign runs, its tables are
//! consistent, and an interrupted (SIGKILL) campaign resumes to identical tables; a small 1D
//! campaign writes the neighbour-distance tables.

use std::time::Duration;

use serde_json::json;

use super::util::{granular, heavy, log_text, read_table, run_granular, wait_limited, write_json};

fn manifest() -> serde_json::Value {
    json!({
        "name": "rfm-it",
        "model": "rfm",
        "seed": 77,
        "replicas": 2,
        "params": {
            "dim": 2,
            "n_particles": 400,
            "packing_fraction": 0.3,
            "restitution_normal": 0.6,
            "restitution_tangential": 0.6,
            "warmup": 0.05,
            "duration": 0.1,
            "sample_every": 1000,
            "observables": ["velocity_moments", "velocity_histogram", "structure_factor", "radial_distribution", "free_paths", "post_collision_velocity"],
            "velocity_histogram": {"range": [-3, 3], "bins": 300},
            "structure_factor": {"k_max": 30, "every": 5},
            "free_paths": {"range": [1e-7, 0.1], "bins_per_decade": 10}
        },
        "sweep": {"restitution_normal": [0.3, 0.9]}
    })
}

const TABLES: [(&str, &[&str]); 14] = [
    ("runs", &["run_id"]),
    ("rfm_temperature_blocks", &["run_id", "block"]),
    ("rfm_timeseries", &["run_id", "t"]),
    ("rfm_moments", &["run_id", "order"]),
    ("rfm_histograms", &["run_id", "kind", "lo"]),
    ("rfm_free_path_moments", &["run_id", "order"]),
    ("rfm_structure_factor", &["run_id", "n2"]),
    ("rfm_radial_distribution", &["run_id", "r_lo"]),
    ("rfm_timeseries_summary", &["point_id", "t"]),
    ("rfm_moments_summary", &["point_id", "order"]),
    ("rfm_histograms_summary", &["point_id", "kind", "lo"]),
    ("rfm_free_path_moments_summary", &["point_id", "order"]),
    ("rfm_structure_factor_summary", &["point_id", "n2"]),
    ("rfm_radial_distribution_summary", &["point_id", "r_lo"]),
];

/// Number of shells n_x^2 + n_y^2 = s, 0 < s <= cut.
fn shells(cut: i64) -> usize {
    let m = (cut as f64).sqrt() as i64 + 1;
    let mut v: Vec<i64> = (-m..=m)
        .flat_map(|a| (-m..=m).map(move |b| a * a + b * b))
        .filter(|&s| s > 0 && s <= cut)
        .collect();
    v.sort_unstable();
    v.dedup();
    v.len()
}

#[test]
fn rfm_campaign_runs_and_resumes_identically() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let m = dir.path().join("m.json");
    write_json(&m, &manifest());
    let log = dir.path().join("log.txt");
    let (a, b) = (dir.path().join("A"), dir.path().join("B"));
    let code = run_granular(
        &[
            "run",
            m.to_str().unwrap(),
            "--out",
            a.to_str().unwrap(),
            "--threads",
            "2",
            "--quiet",
        ],
        &log,
        Duration::from_secs(300),
    );
    assert_eq!(code, Some(0), "{}", log_text(&log));

    // Row counts: 4 runs; 100 samples per run (0.1 s / (1e-6 s x 1000)); 12 moments; 302
    // velocity bins, as many post-collision velocity bins (its default is the velocity
    // histogram's), 60 + 2 free-path bins (6 decades x 10).
    let runs = read_table(&a, "runs");
    assert_eq!(runs.rows.len(), 4);
    assert_eq!(read_table(&a, "rfm_timeseries").rows.len(), 4 * 100);
    assert_eq!(read_table(&a, "rfm_moments").rows.len(), 4 * 12);
    let hist = read_table(&a, "rfm_histograms");
    assert_eq!(hist.rows.len(), 4 * (302 + 302 + 62));
    let kinds = hist.column("kind");
    let counts = hist.column("count");
    let of_kind = |k: &str| -> u64 {
        kinds
            .iter()
            .zip(&counts)
            .filter(|(c, _)| c.as_str() == k)
            .map(|(_, n)| n.as_u64())
            .sum()
    };
    // Every path start (contact end) in the window gives 2 components; every recorded path
    // ends with a contact start, so the counts are of the same order.
    let (n_paths, n_v) = (of_kind("free_path"), of_kind("post_collision_velocity"));
    eprintln!("rfm campaign: {n_paths} free paths, {n_v} post-collision components");
    assert!(n_paths > 1000 && n_v % 2 == 0 && n_v / 2 > n_paths / 2 && n_v / 2 < 2 * n_paths);
    let fpm = read_table(&a, "rfm_free_path_moments");
    assert_eq!(fpm.rows.len(), 4 * 4);
    let total: u64 = fpm
        .column("n_paths")
        .iter()
        .zip(fpm.column("order"))
        .filter(|(_, o)| o.as_u64() == 1)
        .map(|(n, _)| n.as_u64())
        .sum();
    assert_eq!(total, n_paths, "moments and histogram hold the same paths");
    assert_eq!(
        read_table(&a, "rfm_free_path_moments_summary").rows.len(),
        2 * 4
    );
    assert_eq!(read_table(&a, "rfm_moments_summary").rows.len(), 2 * 12);
    // S(k): one row per shell |n|^2 <= 30^2; g(R): default R_max = L/2 in bins of d/20.
    let n_shells = shells(900);
    assert_eq!(
        read_table(&a, "rfm_structure_factor").rows.len(),
        4 * n_shells
    );
    assert_eq!(
        read_table(&a, "rfm_structure_factor_summary").rows.len(),
        2 * n_shells
    );
    let l = (400.0 * std::f64::consts::PI * 1.5e-3f64.powi(2) / 0.3).sqrt();
    let bins = (0.5 * l / (3e-3 / 20.0)).ceil() as usize;
    assert_eq!(
        read_table(&a, "rfm_radial_distribution").rows.len(),
        4 * bins
    );
    let gs = read_table(&a, "rfm_radial_distribution_summary");
    assert_eq!(gs.rows.len(), 2 * bins);
    assert!(gs.column("n_replicas").iter().all(|c| c.as_u64() == 2));

    // Interrupted twice with SIGKILL and resumed: the same tables, bit for bit.
    for delay in [300u64, 700] {
        let mut child = granular(
            &[
                "run",
                m.to_str().unwrap(),
                "--out",
                b.to_str().unwrap(),
                "--threads",
                "2",
                "--quiet",
                "--checkpoint-every",
                "0.05",
                "--flush-every",
                "0.1",
            ],
            &log,
        )
        .spawn()
        .unwrap();
        std::thread::sleep(Duration::from_millis(delay));
        let _ = child.kill();
        let _ = wait_limited(&mut child, Duration::from_secs(30), "killed rfm run", &log);
    }
    let code = run_granular(
        &["resume", b.to_str().unwrap(), "--threads", "1", "--quiet"],
        &log,
        Duration::from_secs(300),
    );
    assert_eq!(code, Some(0), "{}", log_text(&log));
    for (table, keys) in TABLES {
        let (ta, tb) = (read_table(&a, table), read_table(&b, table));
        let ignore: &[&str] = if table == "runs" {
            &["wall_seconds"]
        } else {
            &[]
        };
        let (ra, rb) = (ta.sorted_by(keys).unwrap(), tb.sorted_by(keys).unwrap());
        assert_eq!(ta.columns, tb.columns, "{table}");
        assert_eq!(ra.len(), rb.len(), "{table}: row counts");
        for (x, y) in ra.iter().zip(&rb) {
            for (j, (name, _)) in ta.columns.iter().enumerate() {
                if !ignore.contains(&name.as_str()) {
                    assert_eq!(x[j], y[j], "{table}.{name} differs after kill + resume");
                }
            }
        }
    }
}

/// A 1D campaign with neighbour distances: histograms per h (log bins + 2 out-of-range rows)
/// in `rfm_histograms`, 9 moments per h in `rfm_neighbour_moments` and its summary.
#[test]
fn rfm_1d_neighbour_tables() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let m = dir.path().join("m.json");
    write_json(
        &m,
        &json!({
            "name": "rfm-1d-it",
            "model": "rfm",
            "seed": 5,
            "replicas": 2,
            "params": {
                "dim": 1,
                "n_particles": 200,
                "reduced_length": 0.5,
                "warmup": 0.02,
                "duration": 0.05,
                "sample_every": 1000,
                "observables": ["neighbour_distances"],
                "neighbour_distances": {"h_max": 2, "range": [1e-7, 0.5], "bins_per_decade": 10}
            }
        }),
    );
    let log = dir.path().join("log.txt");
    let a = dir.path().join("A");
    let code = run_granular(
        &[
            "run",
            m.to_str().unwrap(),
            "--out",
            a.to_str().unwrap(),
            "--threads",
            "2",
            "--quiet",
        ],
        &log,
        Duration::from_secs(300),
    );
    assert_eq!(code, Some(0), "{}", log_text(&log));
    // log10(0.5 / 1e-7) = 6.7 decades -> 67 bins, + 2 out-of-range rows, per h = 1, 2.
    let hist = read_table(&a, "rfm_histograms");
    assert_eq!(hist.rows.len(), 2 * 2 * 69);
    assert!(hist
        .column("kind")
        .iter()
        .all(|c| c.as_str() == "neighbour_distance"));
    let total: u64 = hist.column("count").iter().map(|c| c.as_u64()).sum();
    assert_eq!(
        total,
        2 * 2 * 50 * 200,
        "N separations per h, snapshot and run"
    );
    assert_eq!(
        read_table(&a, "rfm_neighbour_moments").rows.len(),
        2 * 2 * 9
    );
    let s = read_table(&a, "rfm_neighbour_moments_summary");
    assert_eq!(s.rows.len(), 2 * 9);
    assert_eq!(read_table(&a, "rfm_histograms_summary").rows.len(), 2 * 69);
}
