//! The `rfm` model through the whole engine: a small 2D campaign runs, its tables are
//! consistent, and an interrupted (SIGKILL) campaign resumes to identical tables.

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
            "observables": ["velocity_moments", "velocity_histogram"],
            "velocity_histogram": {"range": [-3, 3], "bins": 300}
        },
        "sweep": {"restitution_normal": [0.3, 0.9]}
    })
}

const TABLES: [(&str, &[&str]); 7] = [
    ("runs", &["run_id"]),
    ("rfm_timeseries", &["run_id", "t"]),
    ("rfm_moments", &["run_id", "order"]),
    ("rfm_histograms", &["run_id", "lo"]),
    ("rfm_timeseries_summary", &["point_id", "t"]),
    ("rfm_moments_summary", &["point_id", "order"]),
    ("rfm_histograms_summary", &["point_id", "lo"]),
];

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

    // Row counts: 4 runs; 100 samples per run (0.1 s / (1e-6 s x 1000)); 12 moments; 302 bins.
    let runs = read_table(&a, "runs");
    assert_eq!(runs.rows.len(), 4);
    assert_eq!(read_table(&a, "rfm_timeseries").rows.len(), 4 * 100);
    assert_eq!(read_table(&a, "rfm_moments").rows.len(), 4 * 12);
    assert_eq!(read_table(&a, "rfm_histograms").rows.len(), 4 * 302);
    assert_eq!(read_table(&a, "rfm_moments_summary").rows.len(), 2 * 12);

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
