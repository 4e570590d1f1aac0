//! Derived quantities (manifest `derived`, issue 24 item 1): bad expressions refused by
//! `validate` and `run` with their paths (exit 2, every error, nothing written); a 2-species
//! DSMC campaign whose `derived` table equals T_2/T_1 computed here from `dsmc_species` and
//! whose `derived_summary` equals the replicas' mean and sem computed here; reductions (slope,
//! count); the same tables whatever the thread count; the figures; an RFM quantity
//! `mean(rfm_temperature_blocks.temperature)`; a selection matching several rows left null
//! with a warning, the campaign finishing.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

use serde_json::{json, Value};

use super::util::{
    heavy, log_text, read_all, run_capture, run_granular, s, write_json, Cell, Table,
};

fn f(c: &Cell) -> Option<f64> {
    match c {
        Cell::F(b) => Some(f64::from_bits(*b)),
        Cell::Null => None,
        other => panic!("expected a float, got {other}"),
    }
}

/// Mean and sem as `math::stats::mean_sem` (two passes), in the order given.
fn mean_sem(x: &[f64]) -> (f64, Option<f64>) {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    if x.len() < 2 {
        return (mean, None);
    }
    let var = x.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n - 1.0);
    (mean, Some((var / n).sqrt()))
}

fn run(dir: &Path, name: &str, m: &Value, extra: &[&str]) -> std::path::PathBuf {
    let path = dir.join(format!("{name}.json"));
    write_json(&path, m);
    let out = dir.join(name);
    let log = dir.join(format!("{name}.log"));
    let mut args = vec!["run", s(&path), "--out", s(&out), "--quiet"];
    args.extend(extra);
    let code = run_granular(&args, &log, Duration::from_secs(300));
    assert_eq!(code, Some(0), "{name}: {}", log_text(&log));
    out
}

fn dsmc_manifest() -> Value {
    json!({
        "name": "derived-dsmc", "model": "dsmc", "seed": 11, "replicas": 3,
        "params": {
            "method": "low_rank",
            "species": {"list": [
                {"mass": 1, "diameter": 1, "count": 600, "temperature": 1.0},
                {"mass": 4, "diameter": 1, "count": 300, "temperature": 1.0}
            ]},
            "volume": 6000,
            "restitution": {"constant": 0.8},
            "t_end": 5,
            "output_times": {"log": {"from": 0.1, "to": 5, "per_decade": 3}},
            "observables": ["temperature", "msd"]
        },
        "sweep": {"restitution.constant": [0.8, 0.6]},
        "derived": {
            "gamma": "temperature[species=2] / temperature[species=1]",
            "d1": "slope(msd[species=1]) / 6",
            "n1": "count(dsmc_species.count[species=1])"
        }
    })
}

#[test]
fn bad_expressions_are_refused_with_their_paths_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let mut m = dsmc_manifest();
    m["derived"] = json!({
        "a_typo": "temprature[species=1]",
        "b_ambiguous": "count",
        "c_selector": "temperature[specis=1]",
        "d_reduction": "mean(temperature[species=1] * 2)",
        "e_function": "foo(temperature[species=1])",
        "f_syntax": "temperature[species=1] +",
        "g_table": "dsmc_nothing.temperature",
        "ok": "temperature[species=2] / temperature[species=1]"
    });
    let path = dir.path().join("bad.json");
    write_json(&path, &m);
    let log = dir.path().join("bad.log");
    let (code, _) = run_capture(&["validate", s(&path)], &log);
    let text = log_text(&log);
    assert_eq!(code, Some(2), "{text}");
    for (p, what) in [
        ("/derived/a_typo", "unknown column `temprature`"),
        ("/derived/b_ambiguous", "ambiguous column `count`"),
        ("/derived/c_selector", "selector on unknown column `specis`"),
        ("/derived/d_reduction", "single column reference"),
        ("/derived/e_function", "unknown function `foo`"),
        ("/derived/f_syntax", "expected 2 arguments"),
        ("/derived/g_table", "unknown table `dsmc_nothing`"),
    ] {
        assert!(
            text.lines().any(|l| l.contains(p) && l.contains(what)),
            "{p}: {what} in\n{text}"
        );
    }
    assert!(!text.contains("/derived/ok"), "{text}");
    // `run` refuses it the same way before anything is written.
    let out = dir.path().join("out");
    let (code, _) = run_capture(&["run", s(&path), "--out", s(&out), "--quiet"], &log);
    assert_eq!(code, Some(2), "{}", log_text(&log));
    assert!(!out.exists(), "nothing written");
}

/// `dsmc_species` rows of one run: (t, species) -> temperature / msd.
fn species_of(sp: &Table, run: u64) -> BTreeMap<(u64, u64), (f64, Option<f64>)> {
    let (r, t, k, temp, msd) = (
        sp.col("run_id"),
        sp.col("t"),
        sp.col("species"),
        sp.col("temperature"),
        sp.col("msd"),
    );
    sp.rows
        .iter()
        .filter(|row| row[r].as_u64() == run)
        .map(|row| {
            let Cell::F(tb) = row[t] else { panic!() };
            (
                (tb, row[k].as_u64()),
                (f(&row[temp]).unwrap(), f(&row[msd])),
            )
        })
        .collect()
}

#[test]
fn dsmc_gamma_equals_the_ratio_of_the_species_temperatures() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let out = run(dir.path(), "dsmc", &dsmc_manifest(), &["--threads", "2"]);
    let tables = read_all(&out);
    let sp = &tables["dsmc_species"];
    let d = &tables["derived"];
    let names: Vec<&str> = d.columns.iter().map(|(c, _)| c.as_str()).collect();
    assert_eq!(
        names,
        [
            "run_id",
            "point_id",
            "restitution_constant",
            "replica",
            "t",
            "d1",
            "gamma",
            "n1"
        ]
    );
    let runs: std::collections::BTreeSet<u64> =
        d.column("run_id").iter().map(|c| c.as_u64()).collect();
    assert_eq!(runs.len(), 6, "every run");
    let (cr, ct, cg, cd, cn) = (
        d.col("run_id"),
        d.col("t"),
        d.col("gamma"),
        d.col("d1"),
        d.col("n1"),
    );
    // Per point and t: (replica, gamma); per point: (replica, d1).
    let mut gammas: BTreeMap<(u64, u64), Vec<(u64, f64)>> = BTreeMap::new();
    let mut checked = 0;
    for run in &runs {
        let rows = species_of(sp, *run);
        let mine: Vec<&Vec<Cell>> = d.rows.iter().filter(|r| r[cr].as_u64() == *run).collect();
        let times: Vec<u64> = rows
            .keys()
            .map(|k| k.0)
            .filter(|_| true)
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .collect();
        // One row with t null (the scalar quantities), then one per output time.
        assert_eq!(mine.len(), times.len() + 1, "run {run}");
        let scalar = mine
            .iter()
            .find(|r| r[ct] == Cell::Null)
            .expect("a row with t null");
        assert_eq!(f(&scalar[cg]), None);
        assert_eq!(
            f(&scalar[cn]),
            Some(times.len() as f64),
            "count of species-1 rows"
        );
        // slope of msd[species=1] against t, least squares, / 6.
        let pts: Vec<(f64, f64)> = times
            .iter()
            .map(|t| (f64::from_bits(*t), rows[&(*t, 1)].1.unwrap()))
            .collect();
        let n = pts.len() as f64;
        let (mt, my) = (
            pts.iter().map(|p| p.0).sum::<f64>() / n,
            pts.iter().map(|p| p.1).sum::<f64>() / n,
        );
        let sxx: f64 = pts.iter().map(|p| (p.0 - mt) * (p.0 - mt)).sum();
        let sxy: f64 = pts.iter().map(|p| (p.0 - mt) * (p.1 - my)).sum();
        assert_eq!(f(&scalar[cd]), Some(sxy / sxx / 6.0), "run {run}: d1");
        let point = scalar[d.col("point_id")].as_u64();
        let replica = scalar[d.col("replica")].as_u64();
        for r in &mine {
            let Cell::F(tb) = r[ct] else { continue };
            let want = rows[&(tb, 2)].0 / rows[&(tb, 1)].0;
            assert_eq!(
                f(&r[cg]),
                Some(want),
                "run {run}, t = {}",
                f64::from_bits(tb)
            );
            assert_eq!(f(&r[cd]), None);
            gammas.entry((point, tb)).or_default().push((replica, want));
            checked += 1;
        }
    }
    assert!(checked >= 12, "{checked} values checked");

    let sm = &tables["derived_summary"];
    let names: Vec<&str> = sm.columns.iter().map(|(c, _)| c.as_str()).collect();
    assert_eq!(
        names,
        [
            "point_id",
            "restitution_constant",
            "t",
            "d1_mean",
            "d1_sem",
            "d1_n",
            "gamma_mean",
            "gamma_sem",
            "gamma_n",
            "n1_mean",
            "n1_sem",
            "n1_n"
        ]
    );
    let mut seen = 0;
    for r in &sm.rows {
        let Cell::F(tb) = r[sm.col("t")] else {
            continue;
        };
        let p = r[sm.col("point_id")].as_u64();
        let mut v = gammas[&(p, tb)].clone();
        v.sort_by_key(|x| x.0);
        let x: Vec<f64> = v.iter().map(|x| x.1).collect();
        let (mean, sem) = mean_sem(&x);
        assert_eq!(f(&r[sm.col("gamma_mean")]), Some(mean));
        assert_eq!(f(&r[sm.col("gamma_sem")]), sem);
        assert_eq!(r[sm.col("gamma_n")], Cell::U(3));
        assert_eq!(r[sm.col("d1_n")], Cell::U(0));
        seen += 1;
    }
    assert_eq!(seen, gammas.len(), "a summary row per point and time");

    // The same tables with one thread.
    let one = run(dir.path(), "dsmc1", &dsmc_manifest(), &["--threads", "1"]);
    let t1 = read_all(&one);
    for t in ["derived", "derived_summary"] {
        assert_eq!(t1[t].rows, tables[t].rows, "{t}: --threads 1 and 2");
    }

    // The figures: gamma and d1 (and n1) beside the model's.
    let figs = dir.path().join("figs");
    let log = dir.path().join("plot.log");
    let (code, _) = run_capture(&["plot", s(&out), "--out", s(&figs)], &log);
    assert_eq!(code, Some(0), "{}", log_text(&log));
    for id in ["derived-gamma", "derived-d1", "derived-n1"] {
        assert!(figs.join(format!("{id}.svg")).exists(), "{id}.svg");
    }
}

#[test]
fn rfm_block_temperature_and_an_ambiguous_selection_left_null() {
    let _g = heavy();
    let dir = tempfile::tempdir().unwrap();
    let m = json!({
        "name": "derived-rfm", "model": "rfm", "seed": 5, "replicas": 2,
        "params": {
            "dim": 1, "n_particles": 20, "reduced_length": 1.0,
            "restitution_normal": 0.5, "warmup": 0.05, "duration": 0.1,
            "sample_every": 1000,
            "observables": ["velocity_moments"]
        },
        "derived": {
            "t_steady": "mean(rfm_temperature_blocks.temperature)",
            "kurtosis": "rfm_moments.value[order=4] / rfm_moments.value[order=2]^2",
            "several": "rfm_temperature_blocks.temperature"
        }
    });
    let out = run(dir.path(), "rfm", &m, &[]);
    let log = log_text(&dir.path().join("rfm.log"));
    let tables = read_all(&out);
    let blocks = &tables["rfm_temperature_blocks"];
    let moments = &tables["rfm_moments"];
    let d = &tables["derived"];
    assert_eq!(d.rows.len(), 2, "one row per run (all scalar)");
    for r in &d.rows {
        let run = r[d.col("run_id")].as_u64();
        assert_eq!(r[d.col("t")], Cell::Null);
        let temps: Vec<f64> = blocks
            .rows
            .iter()
            .filter(|b| b[blocks.col("run_id")].as_u64() == run)
            .map(|b| f(&b[blocks.col("temperature")]).unwrap())
            .collect();
        assert!(temps.len() >= 2, "several blocks: {temps:?}");
        let want = temps.iter().sum::<f64>() / temps.len() as f64;
        assert_eq!(f(&r[d.col("t_steady")]), Some(want), "run {run}");
        let moment = |o: u64| {
            moments
                .rows
                .iter()
                .find(|m| {
                    m[moments.col("run_id")].as_u64() == run
                        && m[moments.col("order")].as_u64() == o
                })
                .map(|m| f(&m[moments.col("value")]).unwrap())
                .unwrap()
        };
        let k = f(&r[d.col("kurtosis")]).unwrap();
        let want = moment(4) / moment(2).powf(2.0);
        assert!(
            (k - want).abs() <= 1e-12 * want.abs(),
            "run {run}: {k} vs {want}"
        );
        // A reference to a table without t selecting several rows: null, warned.
        assert_eq!(r[d.col("several")], Cell::Null);
        assert!(
            log.contains(&format!("run {run}"))
                && log.contains("matches")
                && log.contains("several"),
            "warned: {log}"
        );
    }
    let sm = &tables["derived_summary"];
    assert_eq!(sm.rows.len(), 1);
    assert_eq!(sm.rows[0][sm.col("several_n")], Cell::U(0));
    assert_eq!(sm.rows[0][sm.col("t_steady_n")], Cell::U(2));
}
