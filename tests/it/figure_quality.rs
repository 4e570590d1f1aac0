//! Every figure of every job in `jobs/` is readable: each job runs (as it is when it takes
//! seconds, else a reduced copy: fewer replicas and particles, a shorter duration, loose
//! targets; the same figures), `granular plot` draws its figures, and in each SVG the tick
//! labels of an axis are distinct and every text lies inside the image (its extent estimated
//! from its font size, characters x 0.6, anchor and rotation as plotters writes them).

use std::collections::BTreeMap;
use std::time::Duration;

use serde_json::Value;

use super::util::s;
use super::util::{heavy, log_text, repo_root, run_granular, write_json};

const LIMIT: Duration = Duration::from_secs(120);

/// A copy of `job` that runs in seconds and draws the same figures.
fn reduced(mut job: Value) -> Value {
    let model = job["model"].as_str().unwrap_or("").to_string();
    let m = job.as_object_mut().unwrap();
    if let Some(r) = m.get("replicas").and_then(Value::as_u64) {
        m.insert("replicas".into(), r.min(2).into());
    }
    if m.contains_key("min_replicas") {
        m.insert("min_replicas".into(), 2.into());
    }
    if m.contains_key("max_replicas") {
        m.insert("max_replicas".into(), 4.into());
    }
    if let Some(Value::Array(targets)) = m.get_mut("target") {
        for t in targets {
            for k in ["sem_rel", "sem_abs", "sem"] {
                if t.get(k).is_some() {
                    t[k] = 1e9.into();
                }
            }
        }
    }
    let p = &mut m.get_mut("params").unwrap();
    match model.as_str() {
        "dsmc" => {
            // A horizon of at most 100 (mean free times of order 1): the output times, the
            // TAMSD lags and grid within it.
            if let Some(t) = p
                .get("t_end")
                .and_then(Value::as_f64)
                .filter(|t| *t > 100.0)
            {
                let end = 100.0_f64.min(t);
                p["t_end"] = end.into();
                if let Some(o) = p.get_mut("output_times") {
                    if let Some(l) = o.get_mut("log") {
                        if l["to"].as_f64().is_some_and(|to| to > end) {
                            l["to"] = end.into();
                        }
                    }
                    if let Some(Value::Array(list)) = o.get_mut("list") {
                        list.retain(|v| v.as_f64().is_some_and(|v| v <= end));
                    }
                }
                if let Some(tm) = p.get_mut("tamsd").filter(|v| v.is_object()) {
                    if let Some(Value::Array(lags)) = tm.get_mut("lags") {
                        lags.retain(|v| v.as_f64().is_some_and(|v| v < end / 2.0));
                    }
                    if tm["grid"].as_u64().is_some_and(|g| g > 1000) {
                        tm["grid"] = 1000.into();
                    }
                }
            }
            // A power law of at most N1 = 1000 particles of the lightest species (fewer species).
            if let Some(pl) = p
                .get_mut("species")
                .and_then(|s| s.get_mut("power_law"))
                .filter(|v| v.is_object())
            {
                if pl["N1"].as_u64().is_some_and(|n| n > 1000) {
                    pl["N1"] = 1000.into();
                }
                return job;
            }
            // At most ~600 particles, at the same densities.
            // (`get_mut`: indexing a `Value` mutably would insert what is missing.)
            let Some(list) = p
                .get_mut("species")
                .and_then(|s| s.get_mut("list"))
                .and_then(Value::as_array_mut)
            else {
                return job;
            };
            let total: f64 = list.iter().map(|s| s["count"].as_f64().unwrap()).sum();
            let f = (600.0 / total).min(1.0);
            for s in list.iter_mut() {
                let c = s["count"].as_f64().unwrap();
                // At least 2 of a species, not more: a tracer species kept rare (paper-fig5's
                // 10 heavy in 100 000 become 2 in 600; 50 would make a mixture whose light
                // species heats up, where the TAMSD theory of the HCS does not apply).
                s["count"] = ((c * f).round() as u64).max(2).into();
            }
            if let Some(v) = p["volume"].as_f64() {
                p["volume"] = (v * f).into();
            }
        }
        "rfm" => {
            if let Some(n) = p["n_particles"].as_u64() {
                p["n_particles"] = n.min(60).into();
            }
            // 60 discs at the thesis's 0.53 are too dense for the random layout in so small a box.
            if p["packing_fraction"].as_f64().is_some_and(|f| f > 0.45) {
                p["packing_fraction"] = 0.4.into();
            }
            let dt = p["dt"].as_f64().unwrap_or(1e-6);
            if let Some(d) = p["duration"].as_f64() {
                let d = d.min(0.01);
                p["duration"] = d.into();
                // At least 20 samples.
                let most = ((d / dt / 20.0).floor() as u64).max(1);
                if let Some(e) = p["sample_every"].as_u64() {
                    p["sample_every"] = e.min(most).into();
                }
            }
            if let Some(w) = p["warmup"].as_f64() {
                p["warmup"] = w.min(0.002).into();
            }
            for k in ["structure_factor", "radial_distribution"] {
                if p[k].get("every").is_some() {
                    p[k]["every"] = 1.into();
                }
            }
            if let Some(Value::Array(ns)) =
                job.get_mut("sweep").and_then(|s| s.get_mut("n_particles"))
            {
                let n = ns.len().min(3);
                *ns = (0..n).map(|i| Value::from(40 + 10 * i as u64)).collect();
            }
        }
        "bisection" => {
            if p["realisations"].as_u64().is_some_and(|r| r > 2000) {
                p["realisations"] = 2000.into();
            }
        }
        "spm" => {
            if p["walks"].as_u64().is_some_and(|w| w > 2000) {
                p["walks"] = 2000.into();
            }
        }
        _ => {}
    }
    job
}

/// A `<text>` element: its attributes and its text.
struct Text {
    attr: BTreeMap<String, String>,
    text: String,
}

/// The `<text>` elements of an SVG document as plotters writes them.
fn texts(svg: &str) -> Vec<Text> {
    let mut out = Vec::new();
    for part in svg.split("<text ").skip(1) {
        let (head, rest) = part.split_once('>').unwrap();
        let body = rest.split("</text>").next().unwrap();
        let mut attr = BTreeMap::new();
        for a in head.split("\" ") {
            if let Some((k, v)) = a.split_once("=\"") {
                attr.insert(k.trim().to_string(), v.trim_end_matches('"').to_string());
            }
        }
        let text = body
            .trim()
            .replace("&lt;", "<")
            .replace("&gt;", ">")
            .replace("&quot;", "\"")
            .replace("&#39;", "'")
            .replace("&amp;", "&");
        out.push(Text { attr, text });
    }
    out
}

fn num(t: &Text, k: &str) -> f64 {
    t.attr.get(k).and_then(|v| v.parse().ok()).unwrap_or(0.0)
}

/// The estimated box (x0, y0, x1, y1) of a text: width chars x size x 0.6, height its size,
/// placed by its anchor and `dy`, rotated as its `transform` says.
fn extent(t: &Text) -> (f64, f64, f64, f64) {
    let (x, y, size) = (num(t, "x"), num(t, "y"), num(t, "font-size"));
    let w = t.text.chars().count() as f64 * size * 0.6;
    let (l, r) = match t.attr.get("text-anchor").map(String::as_str) {
        Some("middle") => (-w / 2.0, w / 2.0),
        Some("end") => (-w, 0.0),
        _ => (0.0, w),
    };
    let (top, bottom) = match t.attr.get("dy").map(String::as_str) {
        Some("0.76em") => (0.0, size),
        Some("-0.5ex") => (-size, 0.0),
        Some("0.5ex") => (-size / 2.0, size / 2.0),
        _ => (-size, 0.2 * size),
    };
    let rot = t
        .attr
        .get("transform")
        .and_then(|s| s.strip_prefix("rotate("))
        .and_then(|s| s.split(',').next())
        .and_then(|a| a.trim().parse::<f64>().ok())
        .unwrap_or(0.0);
    let (c, sn) = (rot.to_radians().cos(), rot.to_radians().sin());
    let corners = [(l, top), (r, top), (l, bottom), (r, bottom)];
    let pts: Vec<(f64, f64)> = corners
        .iter()
        .map(|&(u, v)| (x + u * c - v * sn, y + u * sn + v * c))
        .collect();
    let f = |g: fn(f64, f64) -> f64, i: bool| {
        pts.iter()
            .map(|p| if i { p.1 } else { p.0 })
            .reduce(g)
            .unwrap()
    };
    (
        f(f64::min, false),
        f(f64::min, true),
        f(f64::max, false),
        f(f64::max, true),
    )
}

/// What is wrong with one SVG figure: tick labels repeated on an axis (the texts of the
/// tick-label font on one vertical line, anchored at their end, or on one horizontal line,
/// centred), texts outside the image.
fn problems(name: &str, svg: &str) -> Vec<String> {
    let attr = |k: &str| {
        let i = svg.find(&format!("{k}=\"")).unwrap() + k.len() + 2;
        svg[i..i + svg[i..].find('"').unwrap()]
            .parse::<f64>()
            .unwrap()
    };
    let (w, h) = (attr("width"), attr("height"));
    let all = texts(svg);
    let mut out = Vec::new();
    for t in &all {
        let (x0, y0, x1, y1) = extent(t);
        if x0 < -0.5 || y0 < -0.5 || x1 > w + 0.5 || y1 > h + 0.5 {
            out.push(format!(
                "{name}: text {:?} at ({x0:.0}, {y0:.0})-({x1:.0}, {y1:.0}) outside the {w}x{h} image",
                t.text
            ));
        }
    }
    // The tick labels: the most common font size among texts anchored at their end.
    let mut axes: BTreeMap<(String, String, i64), Vec<&str>> = BTreeMap::new();
    for t in &all {
        if t.attr.contains_key("transform") {
            continue;
        }
        let size = t.attr.get("font-size").cloned().unwrap_or_default();
        match t.attr.get("text-anchor").map(String::as_str) {
            Some("end") => axes
                .entry(("y".into(), size, num(t, "x") as i64))
                .or_default()
                .push(&t.text),
            Some("middle") if t.attr.get("dy").map(String::as_str) == Some("0.76em") => axes
                .entry(("x".into(), size, num(t, "y") as i64))
                .or_default()
                .push(&t.text),
            _ => {}
        }
    }
    for ((axis, size, at), labels) in axes {
        let mut seen = std::collections::BTreeSet::new();
        for l in &labels {
            if !seen.insert(*l) {
                out.push(format!(
                    "{name}: the {axis} axis (font {size}, at {at}) repeats the tick label {l:?}: {labels:?}"
                ));
                break;
            }
        }
    }
    out
}

#[test]
fn every_figure_of_every_job_is_readable() {
    let _g = heavy();
    let tmp = tempfile::tempdir().unwrap();
    let mut jobs: Vec<_> = std::fs::read_dir(repo_root().join("jobs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .collect();
    jobs.sort();
    let mut bad = Vec::new();
    let mut figures = 0;
    for job in &jobs {
        let stem = job.file_stem().unwrap().to_string_lossy().into_owned();
        let v: Value = serde_json::from_str(&std::fs::read_to_string(job).unwrap()).unwrap();
        let dir = tmp.path().join(&stem);
        std::fs::create_dir_all(&dir).unwrap();
        let (m, c, log, figs) = (
            dir.join("m.json"),
            dir.join("c"),
            dir.join("log"),
            dir.join("f"),
        );
        write_json(&m, &reduced(v));
        let code = run_granular(&["run", s(&m), "--out", s(&c), "--quiet"], &log, LIMIT);
        assert_eq!(code, Some(0), "{stem}: log:\n{}", log_text(&log));
        let code = run_granular(&["plot", s(&c), "--out", s(&figs)], &log, LIMIT);
        assert_eq!(code, Some(0), "{stem}: log:\n{}", log_text(&log));
        for f in std::fs::read_dir(&figs).unwrap() {
            let p = f.unwrap().path();
            if p.extension().is_some_and(|x| x == "svg") {
                figures += 1;
                let svg = std::fs::read_to_string(&p).unwrap();
                bad.extend(problems(
                    &format!("{stem}/{}", p.file_name().unwrap().to_string_lossy()),
                    &svg,
                ));
            }
        }
    }
    assert!(figures > 50, "only {figures} figures drawn");
    assert!(
        bad.is_empty(),
        "{} problems:\n{}",
        bad.len(),
        bad.join("\n")
    );
}

/// The checks themselves: a repeated tick label and a text out of the image are found.
#[test]
fn the_checks_find_repeats_and_clipped_text() {
    let svg = "<svg width=\"100\" height=\"50\">\n\
        <text x=\"40\" y=\"10\" dy=\"0.5ex\" text-anchor=\"end\" font-size=\"10\">\n2e-3\n</text>\n\
        <text x=\"40\" y=\"20\" dy=\"0.5ex\" text-anchor=\"end\" font-size=\"10\">\n2e-3\n</text>\n\
        <text x=\"50\" y=\"0\" dy=\"0.76em\" text-anchor=\"middle\" font-size=\"10\">\na long title here\n</text>\n</svg>";
    let p = problems("t", svg);
    assert!(
        p.iter()
            .any(|x| x.contains("repeats the tick label \"2e-3\"")),
        "{p:?}"
    );
    assert!(
        p.iter()
            .any(|x| x.contains("\"a long title here\"") && x.contains("outside")),
        "{p:?}"
    );
    let ok = svg
        .replace(
            ">\n2e-3\n</text>\n<text x=\"40\" y=\"20\"",
            ">\n1e-3\n</text>\n<text x=\"40\" y=\"20\"",
        )
        .replace("a long title here", "short");
    assert!(problems("t", &ok).is_empty(), "{:?}", problems("t", &ok));
}
