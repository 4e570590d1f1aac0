//! `granular report`: one self-contained HTML page of a campaign, finished or not: the
//! campaign (name, model, code version, the latest manifest, its history), the progress per
//! point (`campaign::status`), the failed runs with their reasons (the `runs` table), and the
//! model's standard figures as inline SVG (`Campaign::figures`, drawn by `plot::svg_string`),
//! and what `granular analyze` left in the campaign directory ([`analysis`]: its tables and
//! figures, read as files).
//!
//! Inline CSS, no script, no external reference: the page opens offline after a copy
//! (`granular serve` adds its live script to the page it serves, not to this one). Every
//! string read from the campaign (manifest, names, labels, reasons) is HTML-escaped here;
//! the SVG text is escaped by the renderer. This module builds the text; the command line
//! writes it.

mod analysis;

use std::collections::BTreeMap;
use std::fmt::Write as _;

use crate::campaign::history::{self, Accepted};
use crate::campaign::ledger::{finished_runs, Ledger, RunStatus};
use crate::campaign::status::{self, CampaignStatus, Counts};
use crate::campaign::tables::{RunsTableCols, RUNS};
use crate::campaign::{Campaign, CampaignError, CampaignInfo};
use crate::plot;
use crate::store::cols::opt;
use crate::store::parquet_io::StoreError;

/// A built report.
pub struct Report {
    pub html: String,
    /// Figures embedded (the model's standard figures).
    pub figures: usize,
    /// Figures of `granular analyze` embedded (from `DIR/analysis/figures`).
    pub analysis_figures: usize,
    /// What could not be shown (a figure that could not be drawn, an unreadable table), also
    /// noted in the page.
    pub notes: Vec<String>,
}

/// One failed run, from the `runs` table.
#[derive(Clone, Debug, PartialEq)]
pub struct Failure {
    pub run_id: u64,
    pub point_id: u32,
    pub seed: u64,
    pub reason: Option<String>,
    pub t_failed: Option<f64>,
}

/// HTML-escape `s` for text and attribute values.
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for ch in s.chars() {
        match ch {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// What the report takes from the `runs` table: the failed runs, and per point the wall time
/// of its finished runs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RunsRead {
    /// The failed runs, by run id.
    pub failures: Vec<Failure>,
    /// point -> (sum of `wall_seconds` of its done runs, their number).
    pub wall: BTreeMap<u32, (f64, u64)>,
}

/// Read the `runs` table (each run counted once, as the ledger's first commit has it).
pub fn read_runs(c: &Campaign) -> Result<RunsRead, StoreError> {
    let data = c.data();
    let mut out = RunsRead::default();
    let mut seen = std::collections::BTreeSet::new();
    for f in data.files(RUNS)? {
        let name = f.display().to_string();
        for b in data.read_file(&f, RUNS)? {
            let cols = RunsTableCols::read(&b, &name).map(|c| {
                let t = c.t_failed;
                (
                    c.run_id,
                    c.point_id,
                    c.seed,
                    c.status,
                    c.reason,
                    t,
                    c.wall_seconds,
                )
            });
            let (run, point, seed, st, reason, t, wall) = cols?;
            for i in 0..b.num_rows() {
                if !seen.insert(run.value(i)) {
                    continue;
                }
                match st.value(i) {
                    "failed" => out.failures.push(Failure {
                        run_id: run.value(i),
                        point_id: point.value(i),
                        seed: seed.value(i),
                        reason: (!arrow_array::Array::is_null(reason, i))
                            .then(|| reason.value(i).to_string()),
                        t_failed: opt(t, i),
                    }),
                    "done" => {
                        let e = out.wall.entry(point.value(i)).or_default();
                        e.0 += wall.value(i);
                        e.1 += 1;
                    }
                    _ => {}
                }
            }
        }
    }
    out.failures.sort_by_key(|f| f.run_id);
    Ok(out)
}

/// A duration for people: `3 ms`, `0.8 s`, `42 s`, `3 min 20 s`, `5 h 12 min`, `2 d 4 h`.
pub fn duration_text(secs: f64) -> String {
    if !secs.is_finite() || secs < 0.0 {
        return "?".into();
    }
    let s = secs.round() as u64;
    if secs < 0.1 {
        format!("{:.0} ms", secs * 1e3)
    } else if secs < 10.0 {
        format!("{secs:.1} s")
    } else if s < 60 {
        format!("{s} s")
    } else if s < 3600 {
        format!("{} min {} s", s / 60, s % 60)
    } else if s < 86_400 {
        format!("{} h {} min", s / 3600, (s % 3600) / 60)
    } else {
        format!("{} d {} h", s / 86_400, (s % 86_400) / 3600)
    }
}

/// The estimated time left of the unfinished runs of the points (pending and running, each
/// at its point's mean wall time of finished runs, or the campaign's mean where the point has
/// none): (per point, total CPU seconds), `None` where nothing has finished to estimate from.
pub fn time_left(
    points: &[status::PointStatus],
    wall: &BTreeMap<u32, (f64, u64)>,
) -> (BTreeMap<u32, f64>, Option<f64>) {
    let (sum, n) = wall
        .values()
        .fold((0.0, 0u64), |(s, k), (ws, wn)| (s + ws, k + wn));
    let overall = (n > 0).then(|| sum / n as f64);
    let mut per = BTreeMap::new();
    let mut total = 0.0;
    for p in points {
        let left = p.counts.pending + p.counts.running;
        if left == 0 {
            continue;
        }
        let mean = match wall.get(&p.point_id) {
            Some((s, k)) if *k > 0 => Some(s / *k as f64),
            _ => overall,
        };
        if let Some(m) = mean {
            per.insert(p.point_id, m * left as f64);
            total += m * left as f64;
        }
    }
    (per, overall.map(|_| total))
}

const CSS: &str = "body{font-family:sans-serif;margin:2em auto;max-width:1100px;padding:0 1em;color:#222;line-height:1.4}
h1{margin-bottom:0}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:2em}
table{border-collapse:collapse;margin:.5em 0;display:block;overflow-x:auto;max-width:100%}td,th{border:1px solid #ccc;padding:.2em .5em;text-align:left;vertical-align:top}
td.n{text-align:right;font-variant-numeric:tabular-nums}
tr.flagged td{background:#fff1e0}tr.flagged td.q{color:#b00;font-weight:bold}
pre{background:#f6f6f6;border:1px solid #ddd;padding:.6em;overflow:auto;max-height:40em}
.bar{display:flex;width:120px;height:12px;border:1px solid #999;background:#eee}
.bar span{display:block;height:100%}
.done{background:#2ca02c}.failed{background:#d62728}.running{background:#ff7f0e}.pending{background:#c7c7c7}.dropped{background:#f2e6ff}
.key span{display:inline-block;width:12px;height:12px;margin:0 .3em 0 1em;vertical-align:middle}
.note{color:#8a4b00}.damage{color:#b00}
figure{margin:1em 0}figure svg{max-width:100%;height:auto;border:1px solid #eee}
figcaption{font-size:90%;color:#555}
.headline{font-size:110%;background:#f3f6fa;border:1px solid #d0d8e4;padding:.4em .7em}
nav{margin:.5em 0 1em}nav a{color:#1f5fa8}
";

/// The report of `c`.
pub fn build(c: &Campaign) -> Result<Report, CampaignError> {
    let st = status::status(c)?;
    let info = CampaignInfo::read(&c.root)?;
    let mut notes = Vec::new();
    let mut h = String::new();
    let name = escape(&c.manifest.name);
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>granular report: {name}</title>\n<style>\n{CSS}</style>\n</head>\n<body>\n\
         <h1>Campaign {name}</h1>\n"
    );
    // The commits, read once: where the campaign ran, and which runs the figures of an
    // unfinished campaign are of.
    let ledger = crate::campaign::ledger::read_ledger(&c.root);
    let runs = read_runs(c);
    if let Err(e) = &runs {
        notes.push(format!("the runs table could not be read: {e}"));
    }
    let head_at = h.len();
    // Each section in a `<section id="sec-...">`, so that a live page (`granular serve`) can
    // swap it for a newer one.
    h.push_str("<section id=\"sec-campaign\">\n");
    section_campaign(&mut h, c, &info, &st);
    h.push_str("</section>\n<section id=\"sec-progress\">\n");
    section_progress(&mut h, &st, runs.as_ref().ok());
    h.push_str(&cost_paragraph(c, runs.as_ref().ok()));

    if let Some(t) = &st.targets {
        h.push_str("</section>\n<section id=\"sec-targets\">\n");
        section_targets(&mut h, c, &st, t, runs.as_ref().ok());
    }
    h.push_str("</section>\n<section id=\"sec-shards\">\n");
    section_shards(&mut h, &ledger, &st, &mut notes);
    h.push_str("</section>\n<section id=\"sec-failures\">\n");
    section_failures(&mut h, c, &runs);
    h.push_str("</section>\n<section id=\"sec-figures\">\n");
    let figures = section_figures(&mut h, c, &ledger, &st, &mut notes);
    h.push_str("</section>\n<section id=\"sec-analysis\">\n");
    let analysis_figures = analysis::section(&mut h, c, &mut notes);
    h.push_str("</section>\n<section id=\"sec-manifest\">\n");
    section_manifest(&mut h, &info);
    h.push_str("</section>\n");
    h.insert_str(
        head_at,
        &format!(
            "<section id=\"sec-headline\">\n{}</section>\n",
            headline(c, &st, figures, !notes.is_empty())
        ),
    );
    if !notes.is_empty() {
        h.push_str("<h2 id=\"notes\">Notes</h2>\n<ul>\n");
        for n in &notes {
            let _ = writeln!(h, "<li class=\"note\">{}</li>", escape(n));
        }
        h.push_str("</ul>\n");
    }
    let _ = write!(
        h,
        "<hr><p><small>Written by {} at {}.</small></p>\n</body>\n</html>\n",
        escape(crate::CODE_VERSION),
        history::utc_now()
    );
    Ok(Report {
        html: h,
        figures,
        analysis_figures,
        notes,
    })
}

/// What a reader sees first: the state of the campaign in one line, and the sections.
fn headline(c: &Campaign, st: &CampaignStatus, figures: usize, notes: bool) -> String {
    let k = &st.current;
    let state = if !st.damage.is_empty() {
        "<span class=\"damage\">damaged: granular resume heals it</span>"
    } else if k.done + k.failed >= st.current_runs {
        "complete"
    } else if k.running > 0 || !st.live_shards.is_empty() {
        "running"
    } else {
        "stopped, unfinished"
    };
    // The counts and the state in spans of their own: the live page (`serve`) updates them.
    let points = st.points.iter().filter(|p| p.in_manifest).count();
    let mut s = format!(
        "<p class=\"headline\" id=\"headline\">{} · {points} point{} · <b><span id=\"hl-done\">{}</span> of \
         <span id=\"hl-runs\">{}</span> runs done</b> · <span id=\"hl-failed\">{}</span> failed · \
         <span id=\"hl-running\">{}</span> running · <span id=\"hl-pending\">{}</span> pending · \
         <span id=\"hl-state\">{state}</span></p>\n",
        escape(c.plan.model.as_str()),
        if points == 1 { "" } else { "s" },
        k.done,
        st.current_runs,
        k.failed,
        k.running,
        k.pending,
    );
    s.push_str(
        "<nav><a href=\"#campaign\">Campaign</a> · <a href=\"#progress\">Progress</a> · \
         <a href=\"#shards\">Where it ran</a> · <a href=\"#failures\">Failed runs</a> · ",
    );
    let _ = write!(s, "<a href=\"#figures\">Figures ({figures})</a> · ");
    if c.analysis_dir().is_dir() {
        s.push_str("<a href=\"#analysis\">Analysis</a> · ");
    }
    s.push_str("<a href=\"#manifest\">Manifest</a>");
    if notes {
        s.push_str(" · <a href=\"#notes\">Notes</a>");
    }
    s.push_str("</nav>\n");
    s
}

fn row(h: &mut String, key: &str, value: &str) {
    let _ = writeln!(h, "<tr><th>{key}</th><td>{value}</td></tr>");
}

fn section_campaign(h: &mut String, c: &Campaign, info: &CampaignInfo, st: &CampaignStatus) {
    h.push_str("<h2 id=\"campaign\">Campaign</h2>\n<table>\n");
    row(h, "name", &escape(&c.manifest.name));
    row(h, "model", &escape(c.plan.model.as_str()));
    if let Some(d) = &c.manifest.description {
        row(h, "description", &escape(d));
    }
    row(h, "seed", &c.manifest.seed.to_string());
    row(h, "directory", &escape(&c.root.display().to_string()));
    let code = if info.code_version == crate::CODE_VERSION {
        escape(&info.code_version)
    } else {
        format!(
            "{} (this report: {})",
            escape(&info.code_version),
            escape(crate::CODE_VERSION)
        )
    };
    row(h, "code version", &code);
    row(h, "format version", &info.format_version.to_string());
    row(
        h,
        "random stream",
        &escape(&crate::campaign::status::describe_stream(c.stream)),
    );
    row(
        h,
        "points",
        &format!(
            "{} ({} in the latest manifest)",
            st.points.len(),
            st.points.iter().filter(|p| p.in_manifest).count()
        ),
    );
    let _ = writeln!(
        h,
        "<tr><th>runs</th><td id=\"campaign-runs\">{}</td></tr>",
        counts_text(st.runs, &st.counts)
    );
    if st.manifests > 1 || st.current_runs != st.runs {
        let _ = writeln!(
            h,
            "<tr><th>runs of the latest manifest</th><td id=\"campaign-current\">{}</td></tr>",
            counts_text(st.current_runs, &st.current)
        );
    }
    h.push_str("</table>\n");
    if !st.damage.is_empty() {
        h.push_str(
            "<p class=\"damage\">The tables do not match the ledger (<code>granular resume</code> heals it):</p>\n<ul>\n",
        );
        for d in &st.damage {
            let _ = writeln!(h, "<li class=\"damage\">{}</li>", escape(d));
        }
        h.push_str("</ul>\n");
    }
}

fn counts_text(n: u64, k: &Counts) -> String {
    let mut s = format!(
        "{n}: {} done, {} failed, {} running, {} pending ({} with checkpoints)",
        k.done, k.failed, k.running, k.pending, k.checkpointed
    );
    if k.dropped > 0 {
        let _ = write!(s, ", {} dropped", k.dropped);
    }
    s
}

/// A stacked bar of the counts (widths in percent of the point's runs).
fn bar(k: &Counts) -> String {
    let n = k.done + k.failed + k.running + k.pending + k.dropped;
    if n == 0 {
        return String::new();
    }
    let mut s = String::from("<div class=\"bar\">");
    for (class, v) in [
        ("done", k.done),
        ("failed", k.failed),
        ("running", k.running),
        ("pending", k.pending),
        ("dropped", k.dropped),
    ] {
        if v > 0 {
            let _ = write!(
                s,
                "<span class=\"{class}\" style=\"width:{:.2}%\" title=\"{v} {class}\"></span>",
                100.0 * v as f64 / n as f64
            );
        }
    }
    s.push_str("</div>");
    s
}

/// Rows of the per-point progress table at most (a larger campaign's points beyond are
/// counted in the campaign line and `granular status --json`).
pub const MAX_POINT_ROWS: usize = 2000;

/// The cost model against what the finished runs took: `<p id="progress-cost">estimated X
/// core-hours, took Y (ratio R)</p>` (the models' `cost` at the reference machine, summed over
/// the finished runs, against their wall seconds in the `runs` table); empty before a run has
/// finished.
fn cost_paragraph(c: &Campaign, runs: Option<&RunsRead>) -> String {
    let Some(r) = runs.filter(|r| !r.wall.is_empty()) else {
        return String::new();
    };
    let (mut estimated, mut took, mut n) = (0.0, 0.0, 0);
    for (point, (wall, count)) in &r.wall {
        let Some(p) = c.plan.points.get(*point as usize) else {
            continue;
        };
        estimated += p.params.cost() * *count as f64;
        took += wall;
        n += count;
    }
    let text = format!(
        "Cost: the {n} finished run(s) were estimated at {:.3e} core-hours (the cost model at its reference machine), took {:.3e} (ratio {:.2}).",
        estimated / 3600.0,
        took / 3600.0,
        if estimated > 0.0 { took / estimated } else { f64::NAN }
    );
    format!("<p id=\"progress-cost\">{}</p>\n", escape(&text))
}

fn section_progress(h: &mut String, st: &CampaignStatus, runs: Option<&RunsRead>) {
    h.push_str("<h2 id=\"progress\">Progress</h2>\n");
    let _ = writeln!(
        h,
        "<p id=\"progress-counts\">{}</p>",
        counts_text(st.runs, &st.counts)
    );
    let empty = BTreeMap::new();
    let wall = runs.map(|r| &r.wall).unwrap_or(&empty);
    let (left, total_left) = time_left(&st.points, wall);
    let spent: f64 = wall.values().fold(0.0, |a, (s, _)| a + s);
    let mut times = if wall.is_empty() {
        "No run has finished yet.".to_string()
    } else {
        format!(
            "The finished runs took {} of run time (wall time of each run, summed).",
            duration_text(spent)
        )
    };
    match total_left {
        Some(t) if t > 0.0 => {
            let _ = write!(
                times,
                " Estimated time left: {} of CPU time for the {} unfinished runs (each at its \
                 point's mean wall time of finished runs)",
                duration_text(t),
                st.counts.pending + st.counts.running
            );
            if st.counts.running > 0 {
                let _ = write!(
                    times,
                    ", about {} of wall time at the {} runs running now",
                    duration_text(t / st.counts.running as f64),
                    st.counts.running
                );
            }
            times.push('.');
        }
        Some(_) => {}
        None => times.push_str(" No time left can be estimated before a run has finished."),
    }
    let _ = writeln!(h, "<p id=\"progress-times\">{}</p>", escape(&times));
    h.push_str(
        "<p class=\"key\"><span class=\"done\"></span>done<span class=\"failed\"></span>failed\
         <span class=\"running\"></span>running<span class=\"pending\"></span>pending\
         <span class=\"dropped\"></span>dropped (no longer asked for)</p>\n",
    );
    h.push_str(
        "<table id=\"progress-table\">\n<tr><th>point</th><th>parameters</th><th></th><th>done</th><th>failed</th>\
         <th>running</th><th>pending</th><th>dropped</th><th title=\"pending or running runs with a checkpoint\">ckpt</th>\
         <th title=\"wall time of the finished runs, summed\">wall</th><th title=\"estimated: the unfinished runs at the point's mean wall time\">left</th>\
         <th title=\"whether the latest manifest asks for the point\">asked</th></tr>\n",
    );
    for p in st.points.iter().take(MAX_POINT_ROWS) {
        let k = &p.counts;
        let spent = wall
            .get(&p.point_id)
            .map(|(s, _)| duration_text(*s))
            .unwrap_or_default();
        let left = left
            .get(&p.point_id)
            .map(|t| duration_text(*t))
            .unwrap_or_default();
        let _ = writeln!(
            h,
            "<tr data-point=\"{}\"><td class=\"n\">{}</td><td>{}</td><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
             <td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
             <td class=\"n\">{}</td><td class=\"n\">{}</td><td>{}</td></tr>",
            p.point_id,
            p.point_id,
            escape(&p.point),
            bar(k),
            k.done,
            k.failed,
            k.running,
            k.pending,
            k.dropped,
            k.checkpointed,
            spent,
            left,
            if p.in_manifest { "yes" } else { "no" }
        );
    }
    h.push_str("</table>\n");
    if st.points.len() > MAX_POINT_ROWS {
        let _ = writeln!(
            h,
            "<p class=\"note\">The first {MAX_POINT_ROWS} of {} points; every point's counts: \
             <code>granular status --json</code>.</p>",
            st.points.len()
        );
    }
}

/// A number in a table cell: 4 significant digits, `-` where unknown.
fn num_cell(x: Option<f64>) -> String {
    match x {
        Some(v) if v == 0.0 => "0".into(),
        Some(v) if v.is_finite() => {
            let e = v.abs().log10().floor() as i32;
            if (-3..5).contains(&e) {
                format!("{v:.*}", (3 - e).max(0) as usize)
            } else {
                format!("{v:.3e}")
            }
        }
        _ => "-".into(),
    }
}

/// A campaign with error targets: the latest verdict and why, the rounds decided, per target
/// and point the error now against its goal and the replicas done, asked and expected, the
/// estimated core-hours done and left and the time left at the rate the finished runs took.
fn section_targets(
    h: &mut String,
    c: &Campaign,
    st: &CampaignStatus,
    t: &crate::campaign::targets::TargetsStatus,
    runs: Option<&RunsRead>,
) {
    use crate::campaign::targets::Verdict;
    h.push_str("<h2 id=\"targets\">Error targets</h2>\n");
    let verdict = match t.verdict {
        None => "no round decided yet: the pilot replicas are running".to_string(),
        Some(Verdict::Met) => "met".to_string(),
        Some(Verdict::Continue) => "not met yet, more replicas asked".to_string(),
        Some(Verdict::Stopped) => "stopped, not every target met".to_string(),
    };
    let _ = writeln!(
        h,
        "<p id=\"targets-verdict\">{} round{} decided; verdict: <b>{}</b>{}</p>",
        t.rounds,
        if t.rounds == 1 { "" } else { "s" },
        escape(&verdict),
        if t.why.is_empty() {
            String::new()
        } else {
            format!(": {}", escape(&t.why))
        }
    );
    if let Some(p) = &t.problem {
        let _ = writeln!(
            h,
            "<p class=\"note\" id=\"targets-problem\">The targets cannot be judged: {}</p>",
            escape(p)
        );
    }
    // The rounds decided (campaign.json).
    if !c.rounds.decisions.is_empty() {
        h.push_str(
            "<table id=\"targets-rounds\">\n<tr><th>round</th><th>runs added</th>\
             <th title=\"the models' cost estimates\">est. core-hours added</th>\
             <th title=\"of every run asked for after the decision\">est. core-hours asked</th>\
             <th>verdict</th><th>why</th></tr>\n",
        );
        for d in &c.rounds.decisions {
            let _ = writeln!(
                h,
                "<tr><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{:.4}</td>\
                 <td class=\"n\">{:.4}</td><td>{}</td><td>{}</td></tr>",
                d.round,
                d.runs_added,
                d.core_seconds_added / 3600.0,
                d.core_seconds_total / 3600.0,
                escape(&format!("{:?}", d.verdict).to_lowercase()),
                escape(&d.why)
            );
        }
        h.push_str("</table>\n");
    }
    // Per target and point.
    h.push_str(
        "<table id=\"targets-table\">\n<tr><th>point</th><th>parameters</th><th>target</th>\
         <th title=\"replicas with a value / asked now / expected in the end (from the variance)\">n done / asked / expected</th>\
         <th>mean</th><th>sem</th><th>goal</th><th>sem / goal</th><th>met</th></tr>\n",
    );
    for r in t.rows.iter().take(MAX_POINT_ROWS) {
        let s = &r.state;
        let met = match (&s.problem, s.met) {
            (Some(p), _) => format!("no ({})", escape(p)),
            (None, true) => "yes".into(),
            (None, false) => "no".into(),
        };
        let _ = writeln!(
            h,
            "<tr data-target-point=\"{}\" data-target=\"{}\"><td class=\"n\">{}</td><td>{}</td><td>{}</td>\
             <td class=\"n\">{} / {} / {}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
             <td class=\"n\">{}</td><td class=\"n\">{}</td><td>{}</td></tr>",
            r.point_id,
            s.target,
            r.point_id,
            escape(&r.point),
            escape(&r.target),
            s.n,
            r.replicas,
            r.expected,
            num_cell(s.mean),
            num_cell(s.sem),
            num_cell(s.goal),
            num_cell(s.ratio()),
            met
        );
    }
    h.push_str("</table>\n");
    if t.rows.len() > MAX_POINT_ROWS {
        let _ = writeln!(
            h,
            "<p class=\"note\">The first {MAX_POINT_ROWS} of {} rows; every row: \
             <code>granular status --json</code>.</p>",
            t.rows.len()
        );
    }
    let _ = writeln!(
        h,
        "<p id=\"targets-replicas\">Replicas: {} asked; the variances seen so far imply at least {} \
         ({:.2}x the minimum).</p>",
        t.replicas_asked,
        t.replicas_implied,
        t.replicas_asked as f64 / t.replicas_implied.max(1) as f64
    );
    // The time left: the estimated core-seconds left at the rate the finished runs took
    // (their wall seconds per estimated core-second).
    let wall: f64 = runs
        .map(|r| r.wall.values().map(|(s, _)| s).sum())
        .unwrap_or(0.0);
    let mut times = format!(
        "Estimated core-hours (the models' cost estimates): {:.4} done, {:.4} left.",
        t.core_seconds_done / 3600.0,
        t.core_seconds_left / 3600.0
    );
    if t.core_seconds_left <= 0.0 {
        times.push_str(" Nothing is left to run.");
    } else if wall > 0.0 && t.core_seconds_done > 0.0 {
        let rate = wall / t.core_seconds_done;
        let cpu = rate * t.core_seconds_left;
        let _ = write!(
            times,
            " Time left at this campaign's measured rate ({rate:.3} s of run time per estimated \
             core-second, from the finished runs): {} of run time",
            duration_text(cpu)
        );
        if st.counts.running > 0 {
            let _ = write!(
                times,
                ", about {} of wall time at the {} runs running now",
                duration_text(cpu / st.counts.running as f64),
                st.counts.running
            );
        } else {
            times.push_str(", to be divided by the runs that run at once (threads x shards)");
        }
        times.push_str(
            "; it assumes the runs left cost as the models estimate, relative to those done, \
             and that the replicas expected are those the variances seen so far imply.",
        );
    } else {
        times.push_str(" No time left can be estimated before a run has finished.");
    }
    let _ = writeln!(h, "<p id=\"targets-times\">{}</p>", escape(&times));
    h.push_str(
        "<p>The figure <code>targets-error</code> (under Figures) shows each point's error \
         against its goal over the estimated core-seconds spent on it, per round, with the \
         1/sqrt(n) line through its latest state.</p>\n",
    );
}

/// The ledger's tag (`s1of2`) of a live shard as `status` lists it (`1/2 (pid 17 on host)`).
fn shard_tag(live: &str) -> String {
    let shard = live.split(' ').next().unwrap_or("");
    match shard.split_once('/') {
        Some((i, n)) => format!("s{i}of{n}"),
        None => shard.to_string(),
    }
}

/// Where the campaign ran: its shards (from the ledger's commits: commits, runs committed;
/// live shards from their locks) and SLURM submissions.
fn section_shards(
    h: &mut String,
    ledger: &Result<Ledger, CampaignError>,
    st: &CampaignStatus,
    notes: &mut Vec<String>,
) {
    h.push_str("<h2 id=\"shards\">Where it ran</h2>\n");
    let ledger = match ledger {
        Ok(l) => l,
        Err(e) => {
            let n = format!("the ledger could not be read: {e}");
            let _ = writeln!(h, "<p class=\"note\">{}</p>", escape(&n));
            notes.push(n);
            return;
        }
    };
    // shard -> (commits, done, failed)
    let mut shards: BTreeMap<String, (u64, u64, u64)> = BTreeMap::new();
    for cm in &ledger.commits {
        let e = shards.entry(cm.shard.clone()).or_default();
        e.0 += 1;
        for r in &cm.runs {
            if r.status == RunStatus::Done {
                e.1 += 1;
            } else {
                e.2 += 1;
            }
        }
    }
    if shards.is_empty() && st.live_shards.is_empty() {
        h.push_str("<p>No run committed yet.</p>\n");
    } else {
        h.push_str(
            "<table id=\"shards-table\">\n<tr><th>shard</th><th>commits</th><th>runs done</th><th>runs failed</th><th>now</th></tr>\n",
        );
        for (tag, (commits, done, failed)) in &shards {
            let live: Vec<&String> = st
                .live_shards
                .iter()
                .filter(|l| shard_tag(l) == *tag)
                .collect();
            let now = if live.is_empty() {
                "stopped".to_string()
            } else {
                live.iter()
                    .map(|l| format!("running: {}", escape(l)))
                    .collect::<Vec<_>>()
                    .join("<br>")
            };
            let _ = writeln!(
                h,
                "<tr><td>{}</td><td class=\"n\">{commits}</td><td class=\"n\">{done}</td><td class=\"n\">{failed}</td><td>{now}</td></tr>",
                escape(tag)
            );
        }
        for l in &st.live_shards {
            let tag = shard_tag(l);
            if !shards.contains_key(&tag) {
                let _ = writeln!(
                    h,
                    "<tr><td>{}</td><td class=\"n\">0</td><td class=\"n\">0</td><td class=\"n\">0</td><td>running: {}</td></tr>",
                    escape(&tag),
                    escape(l)
                );
            }
        }
        h.push_str("</table>\n");
    }
    if st.slurm.is_empty() {
        h.push_str("<p>No SLURM submission (<code>granular submit --slurm</code>).</p>\n");
    } else {
        h.push_str("<table id=\"slurm-table\">\n<tr><th>SLURM submission</th><th>jobs</th></tr>\n");
        for sub in &st.slurm {
            let _ = writeln!(
                h,
                "<tr><td class=\"n\">{}</td><td>{}</td></tr>",
                sub.number,
                escape(&sub.describe())
            );
        }
        h.push_str("</table>\n");
    }
}

fn section_failures(h: &mut String, c: &Campaign, runs: &Result<RunsRead, StoreError>) {
    h.push_str("<h2 id=\"failures\">Failed runs</h2>\n");
    let fails = match runs {
        Ok(r) => &r.failures,
        Err(e) => {
            let _ = writeln!(
                h,
                "<p class=\"note\">the runs table could not be read: {}</p>",
                escape(&e.to_string())
            );
            return;
        }
    };
    write_failures(h, fails, &|p| {
        if (p as usize) < c.plan.points.len() {
            c.plan.label(p)
        } else {
            String::new()
        }
    });
}

/// The table of failed runs (`label`: a point's swept values).
fn write_failures(h: &mut String, fails: &[Failure], label: &dyn Fn(u32) -> String) {
    if fails.is_empty() {
        h.push_str("<p>None.</p>\n");
        return;
    }
    h.push_str(
        "<table>\n<tr><th>run</th><th>point</th><th>parameters</th><th>seed</th><th>t_failed</th><th>reason</th></tr>\n",
    );
    for f in fails {
        let _ = writeln!(
            h,
            "<tr><td class=\"n\">{}</td><td class=\"n\">{}</td><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td>{}</td></tr>",
            f.run_id,
            f.point_id,
            escape(&label(f.point_id)),
            f.seed,
            f.t_failed.map(|t| format!("{t}")).unwrap_or_default(),
            escape(f.reason.as_deref().unwrap_or(""))
        );
    }
    h.push_str("</table>\n");
}

/// The SVG of a figure without what an inline `<svg>` in HTML does not need.
fn inline_svg(svg: &str) -> &str {
    let s = svg.trim();
    match (s.find("<svg"), s.starts_with("<?xml")) {
        (Some(i), true) => &s[i..],
        _ => s,
    }
}

fn section_figures(
    h: &mut String,
    c: &Campaign,
    ledger: &Result<Ledger, CampaignError>,
    st: &CampaignStatus,
    notes: &mut Vec<String>,
) -> usize {
    h.push_str("<h2 id=\"figures\">Figures</h2>\n");
    // Until every run the latest manifest asks for has finished, the campaign's summary
    // tables are missing (or of fewer runs): the figures are of the runs finished so far,
    // their summaries computed for this page only.
    let unfinished = st.current.done + st.current.failed < st.current_runs;
    let outside =
        (st.counts.done + st.counts.failed).saturating_sub(st.current.done + st.current.failed);
    if outside > 0 {
        let _ = writeln!(
            h,
            "<p class=\"note\" id=\"figures-outside\">The summaries and figures describe the runs \
             of the latest manifest only: {outside} finished run{} it no longer asks for (fewer \
             replicas, other seeds, points it no longer lists) keep their rows in the raw tables \
             (<code>registered_runs.in_manifest</code> is false for them) and are left out.</p>",
            if outside == 1 { "" } else { "s" }
        );
    }
    let figs = if unfinished && st.current.done > 0 {
        match ledger {
            Ok(l) => {
                let _ = writeln!(
                    h,
                    "<p class=\"note\" id=\"figures-so-far\">Figures of the {} runs finished so far \
                     (of {}): their summaries are computed for this page; the campaign's summary \
                     tables are written when every run has finished.</p>",
                    st.current.done, st.current_runs
                );
                c.figures_so_far(&finished_runs(&l.commits))
                    .map_err(|e| e.to_string())
            }
            Err(e) => Err(e.to_string()),
        }
    } else {
        c.figures().map_err(|e| e.to_string())
    };
    let figs = match figs {
        Ok(Some(f)) => f,
        Ok(None) => {
            let _ = writeln!(
                h,
                "<p>Model {} has no standard figures.</p>",
                escape(c.plan.model.as_str())
            );
            return 0;
        }
        Err(e) => {
            let n = format!("the figures could not be made: {e}");
            let _ = writeln!(h, "<p class=\"note\">{}</p>", escape(&n));
            notes.push(n);
            return 0;
        }
    };
    if figs.is_empty() {
        h.push_str(if unfinished {
            "<p>No figures yet: the summary tables are written when every run of the latest manifest has finished.</p>\n"
        } else {
            "<p>No figures: the summary tables hold no data.</p>\n"
        });
        return 0;
    }
    let mut drawn = 0;
    for (name, fig) in &figs {
        match plot::svg_string(fig) {
            Ok(svg) => {
                let _ = writeln!(
                    h,
                    "<figure id=\"fig-{id}\">\n{}\n<figcaption>{id}: {}</figcaption>\n</figure>",
                    inline_svg(&svg),
                    escape(&fig.title),
                    id = escape(name)
                );
                drawn += 1;
            }
            Err(e) => {
                let n = format!("figure {name}: {e}");
                let _ = writeln!(h, "<p class=\"note\">{}</p>", escape(&n));
                notes.push(n);
            }
        }
    }
    drawn
}

fn section_manifest(h: &mut String, info: &CampaignInfo) {
    h.push_str("<h2 id=\"manifest\">Latest manifest</h2>\n");
    let text = serde_json::to_string_pretty(&info.manifest).unwrap_or_default();
    let _ = writeln!(h, "<pre>{}</pre>", escape(&text));
    h.push_str("<h2 id=\"history\">Manifest history</h2>\n");
    if info.history.is_empty() {
        h.push_str("<p>No history recorded.</p>\n");
        return;
    }
    h.push_str("<table>\n<tr><th>#</th><th>file</th><th>accepted</th><th>runs added</th></tr>\n");
    for (
        k,
        Accepted {
            file,
            accepted,
            runs_added,
        },
    ) in info.history.iter().enumerate()
    {
        let _ = writeln!(
            h,
            "<tr><td class=\"n\">{}</td><td>{}</td><td>{}</td><td class=\"n\">{}</td></tr>",
            k + 1,
            escape(file),
            escape(accepted),
            runs_added
        );
    }
    h.push_str("</table>\n");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escapes_markup() {
        assert_eq!(
            escape("<script>alert('x') & \"y\"</script>"),
            "&lt;script&gt;alert(&#39;x&#39;) &amp; &quot;y&quot;&lt;/script&gt;"
        );
    }

    #[test]
    fn failed_runs_listed_escaped() {
        let mut h = String::new();
        write_failures(&mut h, &[], &|_| String::new());
        assert!(h.contains("None."));
        let mut h = String::new();
        let f = Failure {
            run_id: 17,
            point_id: 3,
            seed: 123456789,
            reason: Some("kinetic energy increased <script>".into()),
            t_failed: Some(2.5),
        };
        write_failures(&mut h, &[f], &|p| format!("eps=<{p}>"));
        for want in [
            "17",
            "123456789",
            "2.5",
            "eps=&lt;3&gt;",
            "increased &lt;script&gt;",
        ] {
            assert!(h.contains(want), "{want} missing: {h}");
        }
        assert!(!h.contains("<script>"));
    }

    #[test]
    fn live_shards_named_by_their_ledger_tag() {
        assert_eq!(shard_tag("1/2 (pid 17 on host)"), "s1of2");
        assert_eq!(shard_tag("12/100 (pid 1 on h)"), "s12of100");
    }

    #[test]
    fn durations_read_as_people_write_them() {
        assert_eq!(duration_text(0.0031), "3 ms");
        assert_eq!(duration_text(0.84), "0.8 s");
        assert_eq!(duration_text(42.4), "42 s");
        assert_eq!(duration_text(200.0), "3 min 20 s");
        assert_eq!(duration_text(5.0 * 3600.0 + 12.0 * 60.0), "5 h 12 min");
        assert_eq!(duration_text(2.0 * 86_400.0 + 4.0 * 3600.0), "2 d 4 h");
        assert_eq!(duration_text(f64::NAN), "?");
    }

    #[test]
    fn time_left_from_each_points_mean() {
        let point = |id: u32, pending: u64, running: u64| status::PointStatus {
            point_id: id,
            point: String::new(),
            in_manifest: true,
            counts: Counts {
                pending,
                running,
                ..Counts::default()
            },
        };
        // Point 0: 2 done in 10 s (5 s each), 3 left -> 15 s; point 1: none done, 1 left ->
        // the campaign's mean, (10 + 20) / 4 = 7.5 s; point 2: 2 done in 20 s, nothing left.
        let wall = BTreeMap::from([(0, (10.0, 2)), (2, (20.0, 2))]);
        let pts = [point(0, 2, 1), point(1, 1, 0), point(2, 0, 0)];
        let (per, total) = time_left(&pts, &wall);
        assert_eq!(per, BTreeMap::from([(0, 15.0), (1, 7.5)]));
        assert_eq!(total, Some(22.5));
        // Nothing finished: no estimate.
        let (per, total) = time_left(&pts, &BTreeMap::new());
        assert!(per.is_empty());
        assert_eq!(total, None);
    }

    #[test]
    fn svg_prolog_removed() {
        assert_eq!(
            inline_svg("<?xml version=\"1.0\"?>\n<svg a>x</svg>\n"),
            "<svg a>x</svg>"
        );
        assert_eq!(inline_svg("<svg>x</svg>"), "<svg>x</svg>");
    }

    #[test]
    fn table_numbers_to_four_significant_digits() {
        assert_eq!(num_cell(Some(1.12104)), "1.121");
        assert_eq!(num_cell(Some(0.0010983)), "0.001098");
        assert_eq!(num_cell(Some(-12345.6)), "-12346");
        assert_eq!(num_cell(Some(123456.0)), "1.235e5");
        assert_eq!(num_cell(Some(2.5e-5)), "2.500e-5");
        assert_eq!(num_cell(Some(0.0)), "0");
        assert_eq!(num_cell(Some(f64::NAN)), "-");
        assert_eq!(num_cell(None), "-");
    }
}
