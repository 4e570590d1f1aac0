//! `granular report`: one self-contained HTML file of a campaign: its name, per-point
//! progress, one inline SVG per standard figure (as many as `granular plot` draws), nothing
//! fetched from the network, manifest strings escaped; a half-finished campaign (one shard
//! of two) is reported with its pending runs and without figures; a directory that is not a
//! campaign is refused (exit 3).

use std::path::Path;
use std::time::Duration;

use serde_json::{json, Value};

use super::util::s;
use super::util::{heavy, log_text, run_capture, run_granular, snapshot, write_json};

const LIMIT: Duration = Duration::from_secs(300);

/// 2 points x 2 replicas of a small power-law DSMC campaign (well under a second), its
/// description carrying markup that must come out escaped.
fn manifest() -> Value {
    json!({
        "name": "report-test",
        "description": "<script>alert('x')</script> & more",
        "model": "dsmc",
        "seed": 7,
        "replicas": 2,
        "params": {
            "method": "low_rank",
            "species": {"power_law": {"n1": 0.1, "N1": 2000, "theta": 3}},
            "restitution": {"constant": 0.7},
            "t_end": 10.0,
            "output_times": {"list": [0.5, 1.0, 5.0, 10.0]},
            "observables": ["temperature", "msd"]
        },
        "sweep": {"restitution.constant": [0.7, 0.9]}
    })
}

/// Sources or links to the network, scripts, stylesheets or imports.
fn external_references(html: &str) -> Vec<String> {
    let lower = html.to_ascii_lowercase();
    let mut found = Vec::new();
    for bad in [
        "src=\"http",
        "src='http",
        "href=\"http",
        "href='http",
        "src=\"//",
        "href=\"//",
        "<script",
        "<link",
        "<iframe",
        "@import",
        "url(",
    ] {
        if lower.contains(bad) {
            found.push(bad.to_string());
        }
    }
    found
}

fn run_report(dir: &Path, out: Option<&Path>, log: &Path) -> (Option<i32>, String) {
    let mut args = vec!["report", s(dir)];
    if let Some(o) = out {
        args.extend(["--out", s(o)]);
    }
    run_capture(&args, log)
}

#[test]
fn report_of_a_finished_campaign() {
    let _g = heavy();
    let tmp = tempfile::tempdir().unwrap();
    let (m, c, log) = (
        tmp.path().join("m.json"),
        tmp.path().join("c"),
        tmp.path().join("log"),
    );
    write_json(&m, &manifest());
    let code = run_granular(&["run", s(&m), "--out", s(&c), "--quiet"], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));

    let (code, out) = run_report(&c, None, &log);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let file = c.join("report.html");
    assert!(out.contains("report.html"), "{out}");
    let html = std::fs::read_to_string(&file).expect("report.html written");
    assert!(html.starts_with("<!DOCTYPE html>"));
    assert!(html.trim_end().ends_with("</html>"));
    assert!(html.contains("report-test"));

    // One inline SVG per figure, as many as `granular plot` draws.
    let code = run_granular(
        &["plot", s(&c), "--out", s(&tmp.path().join("figs"))],
        &log,
        LIMIT,
    );
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let svg_files = std::fs::read_dir(tmp.path().join("figs"))
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "svg")
        })
        .count();
    assert!(svg_files >= 2, "{svg_files} figures");
    assert_eq!(
        html.matches("<svg").count(),
        svg_files,
        "one <svg> per figure"
    );
    assert_eq!(html.matches("</svg>").count(), svg_files);
    assert_eq!(html.matches("<figure").count(), svg_files);
    assert!(out.contains(&format!("{svg_files} figures")), "{out}");

    // Per-point progress: both points, all done.
    assert!(html.contains("constant=0.7"), "point label missing");
    assert!(html.contains("constant=0.9"), "point label missing");
    assert!(html.contains("4: 4 done, 0 failed, 0 running, 0 pending"));
    assert!(html.contains("Failed runs"));
    // The headline: the state first, and the sections.
    assert!(
        text(&html).contains(
            "dsmc · 2 points · 4 of 4 runs done · 0 failed · 0 running · 0 pending · complete"
        ),
        "headline missing"
    );
    assert!(html.contains(&format!("<a href=\"#figures\">Figures ({svg_files})</a>")));

    // Self-contained, escaped.
    assert_eq!(external_references(&html), Vec::<String>::new());
    assert!(!html.contains("alert('x')"), "description not escaped");
    assert!(html.contains("&lt;script&gt;alert(&#39;x&#39;)&lt;/script&gt; &amp; more"));

    // --out elsewhere; the same page but for its time stamp.
    let other = tmp.path().join("r.html");
    let (code, _) = run_report(&c, Some(&other), &log);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    assert!(std::fs::read_to_string(&other).unwrap().contains("<svg"));

    // A bare file name: written in the working directory (its parent is the empty path).
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_granular"))
        .args(["report", s(&c), "--out", "bare.html"])
        .current_dir(tmp.path())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{out:?}");
    assert!(std::fs::read_to_string(tmp.path().join("bare.html"))
        .unwrap()
        .contains("<svg"));

    // Not a campaign directory: refused (3); an --out that cannot be written: I/O (4).
    let (code, _) = run_report(tmp.path(), None, &log);
    assert_eq!(code, Some(3), "log:\n{}", log_text(&log));
    let (code, _) = run_report(&c, Some(&tmp.path().join("no/such/dir/r.html")), &log);
    assert_eq!(code, Some(4), "log:\n{}", log_text(&log));
}

#[test]
fn report_of_a_half_finished_campaign() {
    let _g = heavy();
    let tmp = tempfile::tempdir().unwrap();
    let (m, c, log) = (
        tmp.path().join("m.json"),
        tmp.path().join("c"),
        tmp.path().join("log"),
    );
    write_json(&m, &manifest());
    let code = run_granular(
        &["run", s(&m), "--out", s(&c), "--shard", "1/2", "--quiet"],
        &log,
        LIMIT,
    );
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    // Reported from outside: the campaign directory is not touched (the summaries of the
    // runs finished so far are computed in a scratch directory).
    let before = snapshot(&c);
    let page = tmp.path().join("half.html");
    let (code, _) = run_report(&c, Some(&page), &log);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    assert_eq!(snapshot(&c), before, "report wrote into the campaign");
    let html = std::fs::read_to_string(&page).expect("report written");
    // Shard 1 of 2 ran the even run ids: 2 done, 2 pending; no summary tables yet, so the
    // figures are of the 2 runs finished so far (one per point).
    assert!(
        html.contains("4: 2 done, 0 failed, 0 running, 2 pending"),
        "progress missing"
    );
    assert!(html.contains("Figures of the 2 runs finished so far (of 4)"));
    assert!(text(&html)
        .contains("2 of 4 runs done · 0 failed · 0 running · 2 pending · stopped, unfinished"));
    // Where it ran: shard 1 of 2, one commit of its 2 runs, stopped; a time estimate for the
    // 2 pending runs from the finished runs' wall times.
    assert!(
        html.contains("<tr><td>s1of2</td><td class=\"n\">1</td><td class=\"n\">2</td><td class=\"n\">0</td><td>stopped</td></tr>"),
        "shards table missing"
    );
    assert!(
        html.contains("for the 2 unfinished runs"),
        "no time estimate"
    );
    let half_figures = figure_ids(&html);
    assert!(half_figures.len() >= 2, "{half_figures:?}");
    assert_eq!(external_references(&html), Vec::<String>::new());

    // Finished: the figures come from the campaign's summary tables, as many as before.
    let code = run_granular(&["resume", s(&c), "--quiet"], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let (code, _) = run_report(&c, Some(&page), &log);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let html = std::fs::read_to_string(&page).unwrap();
    assert!(!html.contains("finished so far"));
    // The same figures, and the deviation maps, which need a standard error: the half
    // campaign had one replica per point.
    let full = figure_ids(&html);
    let added: Vec<&String> = full.difference(&half_figures).collect();
    assert!(
        half_figures.is_subset(&full),
        "{half_figures:?} vs {full:?}"
    );
    assert_eq!(
        added,
        ["fig-deviation-msd", "fig-deviation-temperature"],
        "{full:?}"
    );
}

/// The page's text without its tags.
fn text(html: &str) -> String {
    let mut out = String::with_capacity(html.len());
    let mut in_tag = false;
    for ch in html.chars() {
        match ch {
            '<' => in_tag = true,
            '>' => in_tag = false,
            c if !in_tag => out.push(c),
            _ => {}
        }
    }
    out
}

/// The ids of the page's figures.
fn figure_ids(html: &str) -> std::collections::BTreeSet<String> {
    html.split("<figure id=\"")
        .skip(1)
        .map(|r| r[..r.find('"').unwrap()].to_string())
        .collect()
}

/// A DSMC sweep of two numeric keys (2 x 2 points, 2 replicas, well under a second): the
/// report opens its figures with the deviation maps (points x species, at the last output
/// time) and the figures across each sweep key (one series per value of the other key, the
/// theory as a line), under the ids `granular plot` uses as file names (PNG and SVG).
#[test]
fn report_maps_deviations_and_plots_across_the_sweep() {
    let _g = heavy();
    let tmp = tempfile::tempdir().unwrap();
    let (m, c, log) = (
        tmp.path().join("m.json"),
        tmp.path().join("c"),
        tmp.path().join("log"),
    );
    let mut manifest = manifest();
    manifest["params"]["initial_temperature"] = json!(1.0);
    manifest["sweep"] = json!({
        "restitution.constant": [0.7, 0.9],
        "initial_temperature": [1.0, 2.0]
    });
    write_json(&m, &manifest);
    let code = run_granular(&["run", s(&m), "--out", s(&c), "--quiet"], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let (code, _) = run_report(&c, None, &log);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    let html = std::fs::read_to_string(c.join("report.html")).expect("report.html written");

    let ids = [
        "deviation-temperature",
        "deviation-msd",
        "sweep-restitution_constant-temperature-k1",
        "sweep-restitution_constant-msd-k1",
        "sweep-initial_temperature-temperature-k1",
        "sweep-initial_temperature-msd-k1",
    ];
    for id in ids {
        assert!(
            html.contains(&format!("<figure id=\"fig-{id}\">")),
            "figure {id} missing"
        );
    }
    // Before the per-point figures; the map's rows are the points, its caption says when.
    let first_point = html
        .find("fig-point-0000-temperature")
        .expect("point figures");
    assert!(html.find("fig-deviation-temperature").unwrap() < first_point);
    assert!(html.contains("at the last output time, in sems"));
    for p in 0..4 {
        assert!(
            html.contains(&format!("\n{p}: ")),
            "map row of point {p} missing"
        );
    }
    // Series named by the other key's values (its physics name: issue 26, `labels`), each
    // with its theory line.
    assert!(html.contains("\nT(0)=2\n"), "series of the other key");
    assert!(html.contains("\nT(0)=1\n"));
    assert!(html.contains("\ntheory\n"));
    assert!(html.contains("\nε=0.9\n"));

    let figs = tmp.path().join("figs");
    let code = run_granular(&["plot", s(&c), "--out", s(&figs)], &log, LIMIT);
    assert_eq!(code, Some(0), "log:\n{}", log_text(&log));
    for id in ids {
        for ext in ["png", "svg"] {
            assert!(
                figs.join(format!("{id}.{ext}")).is_file(),
                "{id}.{ext} missing"
            );
        }
    }
}
