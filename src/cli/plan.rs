//! `granular plan MANIFEST --out DIR [--json]` (and `run --dry-run`): what running the manifest
//! into DIR would do, written nowhere: new points and runs, runs continued to a longer horizon,
//! runs kept, points no longer listed, and the estimated cost (core-hours, and wall time at
//! `--threads`), from the models' cost model calibrated on the campaign's finished runs or a
//! probe run (`--no-probe`: as it is).

use std::path::{Path, PathBuf};

use super::report_error;
use crate::campaign::preview::{preview, EstimateOptions, Preview};
use crate::campaign::Campaign;
use crate::exit_codes;

#[derive(clap::Args)]
pub struct Args {
    manifest: PathBuf,
    /// Campaign directory (existing or not).
    #[arg(long)]
    out: PathBuf,
    /// Machine-readable output.
    #[arg(long)]
    json: bool,
    /// Worker threads the wall time is estimated for (0 = all cores, the default of `run`).
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = super::flags::threads, default_value_t = 0)]
    threads: usize,
    /// Without finished runs to calibrate the cost model on, take it as it is (the
    /// reference machine) instead of timing a probe run of about a second.
    #[arg(long)]
    no_probe: bool,
}

pub fn run(a: Args) -> i32 {
    let opts = EstimateOptions {
        threads: resolve_threads(a.threads),
        probe: !a.no_probe,
    };
    show(&a.manifest, &a.out, a.json, opts)
}

/// `--threads N` as the runs would have it: 0 is every core.
pub(super) fn resolve_threads(n: usize) -> usize {
    if n == 0 {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    } else {
        n
    }
}

/// Print the plan of `manifest` into `out`; nothing is written.
pub(super) fn show(manifest: &Path, out: &Path, json: bool, opts: EstimateOptions) -> i32 {
    let new_campaign = !out.join("campaign.json").exists();
    let (c, growth) = match Campaign::prepare(manifest, out, false) {
        Ok(x) => x,
        Err(e) => return report_error(e),
    };
    let p = match preview(&c, &growth, new_campaign, opts) {
        Ok(p) => p,
        Err(e) => return report_error(e),
    };
    if let Some(w) = p.theory.warning() {
        tracing::warn!("{w}");
    }
    if json {
        outln!(
            "{}",
            serde_json::to_string_pretty(&p).expect("preview serialises")
        );
    } else {
        out!("{}", text(&c, out, &p));
    }
    exit_codes::OK
}

fn text(c: &Campaign, out: &Path, p: &Preview) -> String {
    let mut s = if p.new_campaign {
        format!(
            "{}: a new campaign {:?}: {} points, {} runs\n",
            out.display(),
            c.manifest.name,
            p.new_points.len(),
            p.new_runs
        )
    } else {
        format!(
            "{}: campaign {:?} grows by {} point(s) and {} run(s)\n",
            out.display(),
            c.manifest.name,
            p.new_points.len(),
            p.new_runs
        )
    };
    s.push_str(&format!(
        "  random stream: {}\n",
        crate::campaign::status::describe_stream(p.stream_version)
    ));
    for np in &p.points {
        s.push_str(&format!("  new point {:>4} {}", np.point_id, np.label));
        if let Some(near) = np.nearest {
            let verb = if np.continues.is_some() {
                "continues"
            } else {
                "differs from"
            };
            s.push_str(&format!(" ({verb} point {near}: {})", short(&np.differs)));
        }
        s.push('\n');
    }
    let on_new = p.new_runs - p.new_replicas;
    s.push_str(&format!(
        "  new runs: {} ({on_new} of new points, {} new replicas of existing points)\n",
        p.new_runs, p.new_replicas
    ));
    if p.continued_runs > 0 {
        s.push_str(&format!(
            "  {} run(s) continue a finished run from its final state to the longer horizon\n",
            p.continued_runs
        ));
    }
    s.push_str(&format!(
        "  runs the manifest asks for: {} finished (kept), {} to run\n",
        p.kept_runs, p.to_run
    ));
    leaving_text(p, &mut s);
    if p.theory.points > 0 {
        s.push_str(&format!(
            "  kinetic theory of the new points (before the runs): {}\n",
            p.theory.text()
        ));
    }
    let e = &p.estimate;
    s.push_str(&format!(
        "  estimate: {} runs, {}\n  calibration: {} ({})\n",
        e.runs,
        e.text(),
        e.calibration.source,
        e.calibration.detail
    ));
    if !p.new_campaign && p.new_runs > 0 {
        let n = &p.new_work;
        s.push_str(&format!(
            "  expected time of the new work ({} run(s) added{}): {}\n",
            n.runs,
            if p.continued_runs > 0 {
                format!(", {} continuing finished runs", p.continued_runs)
            } else {
                String::new()
            },
            n.text()
        ));
    }
    if let Some(t) = &p.targets {
        s.push_str(&format!(
            "  error targets: the pilot of {} replica(s) per point is the {} run(s) above (~{:.2e} core-hours); the replicas beyond it are decided in rounds from the pilot's variances, up to {} per point ({} runs, ~{:.2e} core-hours at most{})\n",
            t.min_replicas,
            t.pilot_runs,
            t.pilot_core_hours,
            t.max_replicas,
            t.max_runs,
            t.max_core_hours,
            t.budget_core_hours
                .map_or(String::new(), |b| format!("; budget max_core_hours {b}"))
        ));
        for e in &t.expected {
            s.push_str(&format!(
                "  error targets: point {:>4} {:<30} {} replica(s) asked, {} expected from the variances seen (~{:.2e} core-hours left)\n",
                e.point_id, e.point, e.replicas, e.expected, e.core_hours_left
            ));
        }
    }
    for n in &p.notes {
        s.push_str(&format!("  note: {n}\n"));
    }
    s
}

/// At most this many leaving points (and points with leaving runs) are printed one a line;
/// `--json` lists them all.
const LEAVING_LINES: usize = 12;

/// The points and runs that leave the manifest, and what that means for them; the points
/// that earlier manifests left.
fn leaving_text(p: &Preview, s: &mut String) {
    let (lp, lr) = (&p.leaving_points, &p.leaving_runs);
    if !lp.is_empty() || !lr.is_empty() {
        let runs: u64 = lp.iter().map(|x| x.runs).sum::<u64>()
            + lr.iter().map(|x| x.run_ids.len() as u64).sum::<u64>();
        let done: u64 =
            lp.iter().map(|x| x.finished).sum::<u64>() + lr.iter().map(|x| x.finished).sum::<u64>();
        s.push_str(&format!(
            "  leaving the manifest: {} point(s) and {} run(s) of points it keeps ({runs} run(s), {done} finished); {}\n",
            lp.len(),
            lr.iter().map(|x| x.run_ids.len()).sum::<usize>(),
            crate::campaign::preview::LEAVING_MEANS
        ));
    }
    for x in lp.iter().take(LEAVING_LINES) {
        s.push_str(&format!(
            "  leaving point {:>4} {} ({} run(s), {} finished",
            x.point_id, x.label, x.runs, x.finished
        ));
        if let Some(n) = x.continued_by {
            s.push_str(&format!("; continued by point {n}"));
        } else if let Some(n) = x.nearest {
            s.push_str(&format!("; nearest kept point {n}: {}", short(&x.differs)));
        }
        s.push_str(")\n");
    }
    if lp.len() > LEAVING_LINES {
        s.push_str(&format!(
            "  ... and {} more leaving point(s) (--json lists them all)\n",
            lp.len() - LEAVING_LINES
        ));
    }
    for x in lr.iter().take(LEAVING_LINES) {
        s.push_str(&format!(
            "  leaving runs of point {:>4} {}: replica(s) {} (run(s) {}; {} finished)\n",
            x.point_id,
            x.label,
            list(&x.replicas),
            list(&x.run_ids),
            x.finished
        ));
    }
    if lr.len() > LEAVING_LINES {
        s.push_str(&format!(
            "  ... and {} more point(s) with leaving runs (--json lists them all)\n",
            lr.len() - LEAVING_LINES
        ));
    }
    let leaving: std::collections::BTreeSet<u32> = lp.iter().map(|x| x.point_id).collect();
    let earlier: Vec<u32> = p
        .retired_points
        .iter()
        .copied()
        .filter(|id| !leaving.contains(id))
        .collect();
    if !earlier.is_empty() {
        s.push_str(&format!(
            "  {} point(s) that earlier manifests left, not in this one either (kept): {}\n",
            earlier.len(),
            list(&earlier)
        ));
    }
}

/// At most 3 differences, then how many more.
fn short(d: &[String]) -> String {
    let mut d = d.to_vec();
    if d.len() > 4 {
        let n = d.len() - 3;
        d.truncate(3);
        d.push(format!("{n} more"));
    }
    d.join("; ")
}

/// `0, 1, 2` or, for more than 8, the first 6 and how many more.
fn list<T: std::fmt::Display>(xs: &[T]) -> String {
    let mut out: Vec<String> = xs
        .iter()
        .take(if xs.len() > 8 { 6 } else { 8 })
        .map(|x| x.to_string())
        .collect();
    if xs.len() > 8 {
        out.push(format!("... ({} more)", xs.len() - 6));
    }
    out.join(", ")
}
