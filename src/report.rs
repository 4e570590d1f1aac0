//! `granular report`: one self-contained HTML page of a campaign, finished or not: the
//! campaign (name, model, code version, the latest manifest, its history), the progress per
//! point (`campaign::status`), the failed runs with their reasons (the `runs` table), and the
//! model's standard figures as inline SVG (`Campaign::figures`, drawn by `plot::svg_string`),
//! and what `granular analyze` left in the campaign directory ([`analysis`]: its tables and
//! figures, read as files).
//!
//! Inline CSS, no script, no external reference: the page opens offline after a copy. Every
//! string read from the campaign (manifest, names, labels, reasons) is HTML-escaped here;
//! the SVG text is escaped by the renderer. This module builds the text; the command line
//! writes it.

mod analysis;

use std::fmt::Write as _;

use crate::campaign::history::{self, Accepted};
use crate::campaign::status::{self, CampaignStatus, Counts};
use crate::campaign::tables::RUNS;
use crate::campaign::{Campaign, CampaignInfo};
use crate::plot;
use crate::store::cols::{get_f64, get_str, get_u32, get_u64, opt};

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

/// The failed runs of the `runs` table, by run id.
pub fn failures(c: &Campaign) -> Result<Vec<Failure>, String> {
    let data = c.data();
    let mut out = Vec::new();
    for f in data.files(RUNS).map_err(|e| e.to_string())? {
        let name = f.display().to_string();
        for b in data.read_file(&f, RUNS).map_err(|e| e.to_string())? {
            let cols = (|| {
                Ok::<_, crate::store::parquet_io::StoreError>((
                    get_u64(&b, &name, "run_id")?,
                    get_u32(&b, &name, "point_id")?,
                    get_u64(&b, &name, "seed")?,
                    get_str(&b, &name, "status")?,
                    get_str(&b, &name, "reason")?,
                    get_f64(&b, &name, "t_failed")?,
                ))
            })();
            let (run, point, seed, st, reason, t) = cols.map_err(|e| e.to_string())?;
            for i in 0..b.num_rows() {
                if st.value(i) != "failed" {
                    continue;
                }
                out.push(Failure {
                    run_id: run.value(i),
                    point_id: point.value(i),
                    seed: seed.value(i),
                    reason: (!arrow_array::Array::is_null(reason, i))
                        .then(|| reason.value(i).to_string()),
                    t_failed: opt(t, i),
                });
            }
        }
    }
    out.sort_by_key(|f| f.run_id);
    out.dedup_by_key(|f| f.run_id);
    Ok(out)
}

const CSS: &str = "body{font-family:sans-serif;margin:2em auto;max-width:1000px;color:#222;line-height:1.4}
h1{margin-bottom:0}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:2em}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:.2em .5em;text-align:left;vertical-align:top}
td.n{text-align:right;font-variant-numeric:tabular-nums}
pre{background:#f6f6f6;border:1px solid #ddd;padding:.6em;overflow:auto;max-height:40em}
.bar{display:flex;width:200px;height:12px;border:1px solid #999;background:#eee}
.bar span{display:block;height:100%}
.done{background:#2ca02c}.failed{background:#d62728}.running{background:#ff7f0e}.pending{background:#c7c7c7}.dropped{background:#f2e6ff}
.key span{display:inline-block;width:12px;height:12px;margin:0 .3em 0 1em;vertical-align:middle}
.note{color:#8a4b00}.damage{color:#b00}
figure{margin:1em 0}figure svg{max-width:100%;height:auto;border:1px solid #eee}
figcaption{font-size:90%;color:#555}
";

/// The report of `c`.
pub fn build(c: &Campaign) -> Result<Report, String> {
    let st = status::status(c)?;
    let info = CampaignInfo::read(&c.root).map_err(|e| e.to_string())?;
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
    section_campaign(&mut h, c, &info, &st);
    section_progress(&mut h, &st);
    section_failures(&mut h, c, &mut notes);
    let figures = section_figures(&mut h, c, &st, &mut notes);
    let analysis_figures = analysis::section(&mut h, c, &mut notes);
    section_manifest(&mut h, &info);
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
        "points",
        &format!(
            "{} ({} in the latest manifest)",
            st.points.len(),
            st.points.iter().filter(|p| p.in_manifest).count()
        ),
    );
    row(h, "runs", &counts_text(st.runs, &st.counts));
    if st.manifests > 1 || st.current_runs != st.runs {
        row(
            h,
            "runs of the latest manifest",
            &counts_text(st.current_runs, &st.current),
        );
    }
    let live = if st.live_shards.is_empty() {
        "none".to_string()
    } else {
        st.live_shards
            .iter()
            .map(|l| escape(l))
            .collect::<Vec<_>>()
            .join("<br>")
    };
    row(h, "live shards", &live);
    for sub in &st.slurm {
        row(
            h,
            &format!("slurm submission {}", sub.number),
            &escape(&sub.describe()),
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

fn section_progress(h: &mut String, st: &CampaignStatus) {
    h.push_str("<h2 id=\"progress\">Progress</h2>\n");
    let _ = writeln!(h, "<p>{}</p>", counts_text(st.runs, &st.counts));
    h.push_str(
        "<p class=\"key\"><span class=\"done\"></span>done<span class=\"failed\"></span>failed\
         <span class=\"running\"></span>running<span class=\"pending\"></span>pending\
         <span class=\"dropped\"></span>dropped (no longer asked for)</p>\n",
    );
    h.push_str(
        "<table>\n<tr><th>point</th><th>parameters</th><th></th><th>done</th><th>failed</th>\
         <th>running</th><th>pending</th><th>dropped</th><th>checkpointed</th><th>in latest manifest</th></tr>\n",
    );
    for p in &st.points {
        let k = &p.counts;
        let _ = writeln!(
            h,
            "<tr><td class=\"n\">{}</td><td>{}</td><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
             <td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td>{}</td></tr>",
            p.point_id,
            escape(&p.point),
            bar(k),
            k.done,
            k.failed,
            k.running,
            k.pending,
            k.dropped,
            k.checkpointed,
            if p.in_manifest { "yes" } else { "no" }
        );
    }
    h.push_str("</table>\n");
}

fn section_failures(h: &mut String, c: &Campaign, notes: &mut Vec<String>) {
    h.push_str("<h2 id=\"failures\">Failed runs</h2>\n");
    let fails = match failures(c) {
        Ok(f) => f,
        Err(e) => {
            let n = format!("the runs table could not be read: {e}");
            let _ = writeln!(h, "<p class=\"note\">{}</p>", escape(&n));
            notes.push(n);
            return;
        }
    };
    write_failures(h, &fails, &|p| {
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
    st: &CampaignStatus,
    notes: &mut Vec<String>,
) -> usize {
    h.push_str("<h2 id=\"figures\">Figures</h2>\n");
    let figs = match c.figures() {
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
        let unfinished = st.current.done + st.current.failed < st.current_runs;
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
    fn svg_prolog_removed() {
        assert_eq!(
            inline_svg("<?xml version=\"1.0\"?>\n<svg a>x</svg>\n"),
            "<svg a>x</svg>"
        );
        assert_eq!(inline_svg("<svg>x</svg>"), "<svg>x</svg>");
    }
}
