//! The DSMC observable `velocity_distribution` end to end: a tiny campaign whose sweep turns
//! it on and off has `a2` in `dsmc_species` exactly where it is observed (null elsewhere),
//! `a2_mean` in the summary, `dsmc_speed_histogram` at t_end only (the default) for the
//! observing points, and its replica summary with the sweep columns; `granular report` has
//! the a2 and speed-distribution figures of the observing points.

use std::collections::BTreeSet;
use std::time::Duration;

use serde_json::json;

use super::util::{heavy, log_text, read_all, run_capture, run_granular, write_json, Cell};

#[test]
fn velocity_distribution_tables() {
    let _g = heavy();
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let m = json!({
        "name": "vdist-it", "model": "dsmc", "seed": 4, "replicas": 2,
        "params": {
            "method": "low_rank",
            "species": {"list": [{"mass": 1, "diameter": 1, "count": 300},
                                 {"mass": 4, "diameter": 2, "count": 60}]},
            "volume": 3000, "restitution": {"constant": 0.6}, "t_end": 4,
            "output_times": {"list": [1, 2]},
            "observables": ["velocity_distribution"]
        },
        "sweep": {"observables": [["temperature"], ["velocity_distribution"]],
                  "method": ["low_rank", "bird"]}
    });
    let path = d.join("m.json");
    write_json(&path, &m);
    let out = d.join("c");
    let log = d.join("log");
    let code = run_granular(
        &[
            "run",
            path.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--quiet",
        ],
        &log,
        Duration::from_secs(120),
    );
    assert_eq!(code, Some(0), "{}", log_text(&log));
    let t = read_all(&out);

    // The observing points, from their params.
    let points = &t["points"];
    let (pid, params) = (points.col("point_id"), points.col("params"));
    let observing: BTreeSet<u64> = points
        .rows
        .iter()
        .filter(|r| r[params].as_str().contains("velocity_distribution"))
        .map(|r| r[pid].as_u64())
        .collect();
    assert_eq!((points.rows.len(), observing.len()), (4, 2));

    let sp = &t["dsmc_species"];
    let (p, a2, time) = (sp.col("point_id"), sp.col("a2"), sp.col("t"));
    assert_eq!(
        sp.rows.len(),
        4 * 2 * 4 * 2,
        "points x replicas x times x species"
    );
    for r in &sp.rows {
        let observed = observing.contains(&r[p].as_u64());
        match &r[a2] {
            Cell::Null => assert!(!observed, "a2 null at an observing point: {:?}", r),
            Cell::F(bits) => {
                assert!(observed, "a2 at a point without the observable");
                let v = f64::from_bits(*bits);
                // The start is Maxwellian (a2 ~ 0 within ~ 1/sqrt(N)); later small.
                assert!(v.abs() < 0.5, "a2 = {v} at t = {}", r[time]);
            }
            other => panic!("a2 is a double, got {other}"),
        }
    }
    let ss = &t["dsmc_species_summary"];
    let (p, am, asem) = (ss.col("point_id"), ss.col("a2_mean"), ss.col("a2_sem"));
    for r in &ss.rows {
        let observed = observing.contains(&r[p].as_u64());
        assert_eq!(r[am] != Cell::Null, observed);
        assert_eq!(r[asem] != Cell::Null, observed, "two replicas: a sem");
    }

    let h = &t["dsmc_speed_histogram"];
    let (p, ht, bin, dens) = (
        h.col("point_id"),
        h.col("t"),
        h.col("bin"),
        h.col("density"),
    );
    assert_eq!(
        h.rows.len(),
        2 * 2 * 2 * 60,
        "observing points x replicas x species x bins"
    );
    for r in &h.rows {
        assert!(observing.contains(&r[p].as_u64()));
        assert_eq!(
            r[ht],
            Cell::F(4f64.to_bits()),
            "histograms at t_end only by default"
        );
        assert!(r[bin].as_u64() < 60);
        assert!(matches!(r[dens], Cell::F(_)));
    }
    let hs = &t["dsmc_speed_histogram_summary"];
    let names: Vec<&str> = hs.columns.iter().map(|(c, _)| c.as_str()).collect();
    assert_eq!(
        names,
        [
            "point_id",
            "observables",
            "method",
            "t",
            "species",
            "bin",
            "c_lo",
            "c_hi",
            "n_replicas",
            "density_mean",
            "density_sem"
        ]
    );
    assert_eq!(hs.rows.len(), 2 * 2 * 60);
    let n = hs.col("n_replicas");
    assert!(hs.rows.iter().all(|r| r[n] == Cell::U(2)));

    // The report draws a2(t) and the speed distribution of the observing points only.
    let (code, _) = run_capture(&["report", out.to_str().unwrap()], &log);
    assert_eq!(code, Some(0), "{}", log_text(&log));
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    for p in 0..4u64 {
        for what in ["a2", "speed-distribution"] {
            let id = format!("<figure id=\"fig-point-{p:04}-{what}\"");
            assert_eq!(html.contains(&id), observing.contains(&p), "{id}");
        }
    }
}
