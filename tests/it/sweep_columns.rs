//! Every summary table carries its point's sweep columns right after `point_id` (same names,
//! types and values as in `points`), so a summary is read without a join: a DSMC campaign
//! with a 2-key sweep (both summaries, the TAMSD one included), a 1D RFM campaign with a
//! 2-key sweep (every 1D summary), a 2D RFM campaign (S(k) and g(R) summaries) and a cascade
//! campaign.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

use serde_json::{json, Value};

use super::util::{heavy, log_text, read_all, run_granular, write_json, Cell};

/// Run manifest `m` into `dir/<name>`; the summary tables there must be `expected`, each with
/// the sweep columns `sweep` (names in order) filled per point as in `points`.
fn check(dir: &Path, name: &str, m: &Value, sweep: &[&str], expected: &[&str]) {
    let path = dir.join(format!("{name}.json"));
    write_json(&path, m);
    let out = dir.join(name);
    let log = dir.join(format!("{name}.log"));
    let code = run_granular(
        &[
            "run",
            path.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--quiet",
        ],
        &log,
        Duration::from_secs(300),
    );
    assert_eq!(code, Some(0), "{name}: {}", log_text(&log));
    let tables = read_all(&out);

    let points = &tables["points"];
    let names: Vec<&str> = points.columns.iter().map(|(c, _)| c.as_str()).collect();
    let mut want = vec!["point_id"];
    want.extend(sweep);
    want.extend(["params", "in_manifest"]);
    assert_eq!(names, want, "{name}: points columns");
    let pid = points.col("point_id");
    let by_point: BTreeMap<u64, Vec<Cell>> = points
        .rows
        .iter()
        .map(|r| {
            let vals = sweep.iter().map(|c| r[points.col(c)].clone()).collect();
            (r[pid].as_u64(), vals)
        })
        .collect();
    assert!(by_point.len() >= 2, "{name}: a sweep of several points");

    let summaries: Vec<&str> = tables
        .keys()
        .map(String::as_str)
        .filter(|t| t.ends_with("_summary"))
        .collect();
    assert_eq!(summaries, expected, "{name}: summary tables");
    for t in summaries {
        let s = &tables[t];
        assert!(!s.rows.is_empty(), "{name}: {t} has rows");
        let head: Vec<(String, _)> = s.columns[..1 + sweep.len()].to_vec();
        let want: Vec<(String, _)> = points.columns[..1 + sweep.len()].to_vec();
        assert_eq!(
            head, want,
            "{name}: {t} starts with point_id and the sweep columns"
        );
        for c in sweep {
            assert_eq!(
                s.columns.iter().filter(|(n, _)| n == c).count(),
                1,
                "{name}: {t}.{c} once"
            );
        }
        let mut seen = std::collections::BTreeSet::new();
        for r in &s.rows {
            let p = r[0].as_u64();
            seen.insert(p);
            let got: Vec<Cell> = (1..=sweep.len()).map(|j| r[j].clone()).collect();
            assert_eq!(got, by_point[&p], "{name}: {t}, point {p}");
        }
        assert_eq!(seen.len(), by_point.len(), "{name}: {t} has every point");
    }
}

#[test]
fn summaries_carry_the_sweep_columns() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    check(
        d,
        "dsmc",
        &json!({
            "name": "sweepcols-dsmc", "model": "dsmc", "seed": 3, "replicas": 2,
            "params": {
                "method": "low_rank",
                "species": {"list": [
                    {"mass": 1, "diameter": 1, "count": 2000, "temperature": 1.0},
                    {"mass": 4, "diameter": 2, "count": 200, "temperature": 1.0}
                ]},
                "volume": 20000,
                "restitution": {"constant": 0.5},
                "t_end": 10,
                "output_times": {"log": {"from": 0.1, "to": 10, "per_decade": 2}},
                "observables": ["temperature", "msd", "tamsd"],
                "tamsd": {"lags": [1, 3], "tracers": 10, "grid": 10}
            },
            "sweep": {"method": ["low_rank", "bird"], "restitution.constant": [0.5, 0.8]}
        }),
        &["method", "restitution_constant"],
        &["dsmc_species_summary", "dsmc_tamsd_summary"],
    );
    check(
        d,
        "rfm1d",
        &json!({
            "name": "sweepcols-rfm1d", "model": "rfm", "seed": 5, "replicas": 2,
            "params": {
                "dim": 1, "n_particles": 20, "reduced_length": 1.0,
                "restitution_normal": 0.5, "warmup": 0.05, "duration": 0.1,
                "sample_every": 1000,
                "observables": ["velocity_moments", "velocity_histogram",
                                "neighbour_distances", "free_paths"]
            },
            "sweep": {"restitution_normal": [0.3, 0.9], "n_particles": [10, 20]}
        }),
        &["restitution_normal", "n_particles"],
        &[
            "rfm_free_path_moments_summary",
            "rfm_histograms_summary",
            "rfm_moments_summary",
            "rfm_neighbour_moments_summary",
            "rfm_timeseries_summary",
        ],
    );
    check(
        d,
        "rfm2d",
        &json!({
            "name": "sweepcols-rfm2d", "model": "rfm", "seed": 7, "replicas": 2,
            "params": {
                "dim": 2, "n_particles": 60, "packing_fraction": 0.2,
                "restitution_normal": 0.6, "warmup": 0.005, "duration": 0.02,
                "sample_every": 1000,
                "observables": ["structure_factor", "radial_distribution"],
                "structure_factor": {"k_max": 10}
            },
            "sweep": {"restitution_normal": [0.3, 0.9]}
        }),
        &["restitution_normal"],
        &[
            "rfm_radial_distribution_summary",
            "rfm_structure_factor_summary",
            "rfm_timeseries_summary",
        ],
    );
    check(
        d,
        "cascade",
        &json!({
            "name": "sweepcols-cascade", "model": "cascade", "seed": 2, "replicas": 2,
            "params": {"level": 4, "variant": "ucp", "realisations": 10, "box_length": 1.0},
            "sweep": {"variant": ["ucp", "meakin1"], "realisations": [10, 12]}
        }),
        &["variant", "realisations"],
        &["cascade_structure_factor_summary"],
    );
}
