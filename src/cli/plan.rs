//! `granular plan MANIFEST --out DIR [--json]` (and `run --dry-run`): what running the manifest
//! into DIR would do, written nowhere: new points and runs, runs continued to a longer horizon,
//! runs kept, points no longer listed, and the estimated cost.

use std::path::{Path, PathBuf};

use super::report_error;
use crate::campaign::preview::{preview, Preview};
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
}

pub fn run(a: Args) -> i32 {
    show(&a.manifest, &a.out, a.json)
}

/// Print the plan of `manifest` into `out`; nothing is written.
pub(super) fn show(manifest: &Path, out: &Path, json: bool) -> i32 {
    let new_campaign = !out.join("campaign.json").exists();
    let (c, growth) = match Campaign::prepare(manifest, out, false) {
        Ok(x) => x,
        Err(e) => return report_error(e),
    };
    let p = match preview(&c, &growth, new_campaign) {
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
    for np in &p.points {
        s.push_str(&format!("  new point {:>4} {}", np.point_id, np.label));
        if let Some(near) = np.nearest {
            let verb = if np.continues.is_some() {
                "continues"
            } else {
                "differs from"
            };
            let mut d = np.differs.clone();
            if d.len() > 4 {
                let n = d.len() - 3;
                d.truncate(3);
                d.push(format!("{n} more"));
            }
            s.push_str(&format!(" ({verb} point {near}: {})", d.join("; ")));
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
    if !p.retired_points.is_empty() {
        s.push_str(&format!(
            "  {} point(s) no longer in the manifest (kept, with their finished runs): {:?}\n",
            p.retired_points.len(),
            p.retired_points
        ));
    }
    if p.theory.points > 0 {
        s.push_str(&format!(
            "  kinetic theory of the new points (before the runs): {}\n",
            p.theory.text()
        ));
    }
    match p.estimate_seconds {
        Some(t) => s.push_str(&format!(
            "  estimate: {t:.1} CPU s ({})\n",
            p.estimate_basis
        )),
        None => s.push_str(&format!("  estimate: none ({})\n", p.estimate_basis)),
    }
    for n in &p.notes {
        s.push_str(&format!("  note: {n}\n"));
    }
    s
}
