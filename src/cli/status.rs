//! `granular status DIR [--json]`: done / failed / running / pending runs, per point, across
//! all shards.

use std::io::Write;
use std::path::PathBuf;

use super::report_error;
use crate::campaign::status::CampaignStatus;
use crate::campaign::{self, Campaign};
use crate::exit_codes;

#[derive(clap::Args)]
pub struct Args {
    dir: PathBuf,
    /// Machine-readable output.
    #[arg(long)]
    json: bool,
}

pub fn run(a: Args) -> i32 {
    let c = match Campaign::open(&a.dir) {
        Ok(c) => c,
        Err(e) => return report_error(e),
    };
    let s = match campaign::status::status(&c) {
        Ok(s) => s,
        Err(e) => return report_error(e),
    };
    // A closed pipe (`| head`) ends the printing quietly (super::print_out).
    let mut out = super::Stdout;
    let _ = if a.json {
        writeln!(out, "{}", campaign::status::to_json(&s))
    } else {
        write_text(&mut out, &s)
    };
    if s.damage.is_empty() {
        return exit_codes::OK;
    }
    super::refuse_damage(&a.dir, &s.damage)
}

fn write_text(out: &mut impl Write, s: &CampaignStatus) -> std::io::Result<()> {
    writeln!(
        out,
        "{}: {} runs: {} done, {} failed, {} running, {} pending ({} with checkpoints)",
        s.name,
        s.runs,
        s.counts.done,
        s.counts.failed,
        s.counts.running,
        s.counts.pending,
        s.counts.checkpointed
    )?;
    writeln!(
        out,
        "  random stream: {}",
        campaign::status::describe_stream(s.stream_version)
    )?;
    if s.manifests > 1 || s.current_runs != s.runs {
        let c = &s.current;
        writeln!(
            out,
            "  latest manifest (of {} accepted): {} runs: {} done, {} failed, {} running, {} pending",
            s.manifests, s.current_runs, c.done, c.failed, c.running, c.pending
        )?;
    }
    for l in &s.live_shards {
        writeln!(out, "  live shard {l}")?;
    }
    for sub in &s.slurm {
        writeln!(out, "  slurm submission {}: {}", sub.number, sub.describe())?;
    }
    for p in &s.points {
        write!(
            out,
            "  point {:>4} {:<40} done {:>3}  failed {:>3}  running {:>3}  pending {:>3}",
            p.point_id, p.point, p.counts.done, p.counts.failed, p.counts.running, p.counts.pending
        )?;
        if !p.in_manifest {
            write!(out, "  (not in the latest manifest)")?;
        }
        if p.counts.dropped > 0 {
            write!(
                out,
                "  ({} unfinished, no longer asked for)",
                p.counts.dropped
            )?;
        }
        writeln!(out)?;
    }
    if let Some(t) = &s.targets {
        write_targets(out, t)?;
    }
    Ok(())
}

/// Per target and point: the error now against the goal, replicas done and expected.
fn write_targets(
    out: &mut impl Write,
    t: &campaign::targets::TargetsStatus,
) -> std::io::Result<()> {
    let verdict = match t.verdict {
        None => "pilot replicas running".to_string(),
        Some(v) => format!("{v:?}").to_lowercase(),
    };
    writeln!(
        out,
        "  targets: {} round(s) decided, {verdict}{}",
        t.rounds,
        if t.why.is_empty() {
            String::new()
        } else {
            format!(": {}", t.why)
        }
    )?;
    if let Some(p) = &t.problem {
        writeln!(out, "  targets cannot be judged: {p}")?;
    }
    for r in &t.rows {
        let num = |x: Option<f64>| x.map_or("-".to_string(), |x| format!("{x:.4e}"));
        writeln!(
            out,
            "  point {:>4} {:<30} {}: n {:>4}/{:<4} (expected {:>4})  mean {}  sem {}  goal {}  {}{}",
            r.point_id,
            r.point,
            r.target,
            r.state.n,
            r.replicas,
            r.expected,
            num(r.state.mean),
            num(r.state.sem),
            num(r.state.goal),
            if r.state.met { "met" } else { "not met" },
            r.state
                .problem
                .as_deref()
                .map(|p| format!(" ({p})"))
                .unwrap_or_default()
        )?;
    }
    writeln!(
        out,
        "  replicas: {} asked; the variances seen imply at least {} ({:.2}x)",
        t.replicas_asked,
        t.replicas_implied,
        t.replicas_asked as f64 / t.replicas_implied.max(1) as f64
    )?;
    writeln!(
        out,
        "  estimated core-hours: {:.3} done, {:.3} left (the models' cost estimates)",
        t.core_seconds_done / 3600.0,
        t.core_seconds_left / 3600.0
    )
}
