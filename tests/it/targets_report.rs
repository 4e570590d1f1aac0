//! Error targets seen converging (issue 24, item 5): the report of a target campaign has its
//! `sec-targets` section (verdict, rounds, per target and point n / asked / expected, sem
//! against goal, met), the figure `targets-error` is drawn by `granular plot` and embedded in
//! the report, and a campaign without targets has neither.

use std::fs;
use std::path::Path;
use std::time::Duration;

use serde_json::{json, Value};

use super::util::{heavy, log_text, run_capture, run_granular, s, status_json, write_json};

const LIMIT: Duration = Duration::from_secs(300);

/// The binary mixture of tests/it/targets.rs (two points; a 0.5 % target on gamma needs a
/// round or two after the 4 pilot replicas), or without its target.
fn manifest(with_target: bool) -> Value {
    let mut m = super::targets::manifest(super::targets::gamma_target());
    m["name"] = json!("targets-report-test");
    if !with_target {
        let o = m.as_object_mut().unwrap();
        o.remove("target");
        o.remove("min_replicas");
        o.remove("max_replicas");
        o.insert("replicas".into(), json!(2));
    }
    m
}

fn svgs(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".svg"))
        .collect();
    v.sort();
    v
}

/// The text of `html` between `<section id="ID">` and its `</section>`.
fn section<'a>(html: &'a str, id: &str) -> Option<&'a str> {
    let start = html.find(&format!("<section id=\"{id}\">"))?;
    let end = html[start..].find("</section>")?;
    Some(&html[start..start + end])
}

#[test]
fn report_and_figure_of_a_target_campaign() {
    let _g = heavy();
    let tmp = tempfile::tempdir().unwrap();
    let (m, c, log) = (
        tmp.path().join("m.json"),
        tmp.path().join("c"),
        tmp.path().join("log"),
    );
    write_json(&m, &manifest(true));
    let code = run_granular(
        &["run", s(&m), "--out", s(&c), "--threads", "2", "--quiet"],
        &log,
        LIMIT,
    );
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let st = status_json(&c, &log);
    let t = &st["targets"];
    assert_eq!(t["verdict"], "met", "{t:#}");
    let rounds = t["rounds"].as_u64().unwrap();
    assert!(rounds >= 2, "the pilot alone met it: {t:#}");

    let (code, _) = run_capture(&["report", s(&c)], &log);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let html = fs::read_to_string(c.join("report.html")).unwrap();
    let sec = section(&html, "sec-targets").expect("a sec-targets section");
    // After the progress section, before the figures.
    let at = |id: &str| html.find(&format!("<section id=\"{id}\">")).unwrap();
    assert!(at("sec-progress") < at("sec-targets") && at("sec-targets") < at("sec-figures"));
    assert!(sec.contains("verdict: <b>met</b>"), "{sec}");
    assert!(sec.contains(&format!("{rounds} rounds decided")), "{sec}");
    // One row per decided round.
    let rtable = &sec[sec.find("id=\"targets-rounds\"").expect("rounds table")..];
    let rtable = &rtable[..rtable.find("</table>").unwrap()];
    assert_eq!(rtable.matches("<tr><td").count() as u64, rounds, "{rtable}");
    // Per point: its n done / asked / expected (as status has them), and met.
    let rows = t["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 2, "{t:#}");
    for r in rows {
        let p = r["point_id"].as_u64().unwrap();
        let tag = format!("<tr data-target-point=\"{p}\" data-target=\"0\">");
        let row = &sec[sec
            .find(&tag)
            .unwrap_or_else(|| panic!("no row {tag}: {sec}"))..];
        let row = &row[..row.find("</tr>").unwrap()];
        let n = format!(
            "{} / {} / {}",
            r["n"].as_u64().unwrap(),
            r["replicas"].as_u64().unwrap(),
            r["expected"].as_u64().unwrap()
        );
        assert!(row.contains(&n), "{n} not in {row}");
        assert!(r["n"].as_u64().unwrap() > 4, "{r:#}");
        assert!(row.contains("<td>yes</td>"), "{row}");
        assert!(row.contains(r["point"].as_str().unwrap()), "{row}");
    }
    assert!(sec.contains("id=\"targets-replicas\""), "{sec}");
    assert!(sec.contains("Nothing is left to run."), "{sec}");

    // The figure: drawn by `granular plot`, embedded in the report, the same each time.
    let figs = tmp.path().join("figs");
    let code = run_granular(&["plot", s(&c), "--out", s(&figs)], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    assert!(
        svgs(&figs).contains(&"targets-error.svg".to_string()),
        "{:?}",
        svgs(&figs)
    );
    assert!(html.contains("<figure id=\"fig-targets-error\">"));
    let svg = fs::read_to_string(figs.join("targets-error.svg")).unwrap();
    assert!(svg.contains("sem / goal"), "axis label missing");
    assert!(
        svg.contains("constant=0.6") && svg.contains("constant=0.8"),
        "legend"
    );
    let again = tmp.path().join("figs2");
    let code = run_granular(&["plot", s(&c), "--out", s(&again)], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    assert_eq!(
        svg,
        fs::read_to_string(again.join("targets-error.svg")).unwrap(),
        "the figure is deterministic"
    );
}

#[test]
fn no_targets_section_or_figure_without_targets() {
    let _g = heavy();
    let tmp = tempfile::tempdir().unwrap();
    let (m, c, log) = (
        tmp.path().join("m.json"),
        tmp.path().join("c"),
        tmp.path().join("log"),
    );
    write_json(&m, &manifest(false));
    let code = run_granular(&["run", s(&m), "--out", s(&c), "--quiet"], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let (code, _) = run_capture(&["report", s(&c)], &log);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let html = fs::read_to_string(c.join("report.html")).unwrap();
    assert!(section(&html, "sec-progress").is_some());
    assert!(section(&html, "sec-targets").is_none());
    assert!(!html.contains("targets-error"));
    let figs = tmp.path().join("figs");
    let code = run_granular(&["plot", s(&c), "--out", s(&figs)], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    assert!(!svgs(&figs).iter().any(|f| f.starts_with("targets")));
}
