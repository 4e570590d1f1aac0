//! `granular submit`: run a campaign as a SLURM job array with a compaction job chained by
//! afterok (`MANIFEST --out DIR`), or resubmit its unfinished shards (`--missing DIR`);
//! `--dry-run` prints the scripts and writes nothing. A campaign with error targets gets a
//! round job chained by afterany instead (`slurm-round`: the rounds as chained arrays, the
//! compaction after the last).

use std::path::{Path, PathBuf};

use super::flags::{self, CheckpointEvery};
use super::{fail, report_error};
use crate::campaign::slurm::{self, SlurmOptions};
use crate::campaign::Campaign;
use crate::exit_codes;

#[derive(clap::Args)]
pub struct Args {
    /// The manifest (a first submission, with --out) or, with --missing, the campaign
    /// directory.
    target: PathBuf,
    /// Campaign directory of a first submission.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Resubmit only the shards with unfinished runs that no task is working on.
    #[arg(long)]
    missing: bool,
    /// Submit to SLURM (the only scheduler; accepted for clarity).
    #[arg(long)]
    slurm: bool,
    /// Array tasks running at once (the array's % throttle; 1 to 4000001).
    #[arg(long, allow_hyphen_values = true, value_parser = flags::tasks)]
    tasks: Option<u32>,
    /// Runs per array task (1 to 1e9; more are packed per task if the array would exceed
    /// the cluster's MaxArraySize).
    #[arg(long, allow_hyphen_values = true, value_parser = flags::per_task_runs)]
    per_task_runs: Option<u64>,
    /// Time limit of each task, e.g. 02:00:00 (SLURM's MM, MM:SS, HH:MM:SS, D-HH, D-HH:MM,
    /// D-HH:MM:SS; 0 = no limit).
    #[arg(long, allow_hyphen_values = true, value_parser = flags::slurm_time)]
    time: Option<String>,
    #[arg(long)]
    partition: Option<String>,
    /// Extra #SBATCH argument (repeatable), e.g. --sbatch-arg=--account=abc.
    #[arg(long = "sbatch-arg", allow_hyphen_values = true)]
    sbatch_arg: Vec<String>,
    /// Worker threads per task (--cpus-per-task; 1 to 1024).
    #[arg(long, allow_hyphen_values = true, value_parser = flags::cpus)]
    cpus_per_task: Option<u32>,
    #[command(flatten)]
    checkpoint: CheckpointEvery,
    /// No compaction job after the array.
    #[arg(long)]
    no_compact: bool,
    /// Print the scripts and the sbatch commands; write and submit nothing.
    #[arg(long)]
    dry_run: bool,
}

/// The exit code of a step that stopped the command (its message is printed).
type Stop = i32;

pub fn run(a: Args) -> i32 {
    match submit(&a) {
        Ok(code) | Err(code) => code,
    }
}

fn submit(a: &Args) -> Result<i32, Stop> {
    let binary = binary()?;
    refuse_unscriptable(a, &binary)?;
    // The campaign (created unless --dry-run) and its absolute directory.
    // A grown manifest of a submitted campaign resubmits its new and longer runs (as
    // `--missing` does the unfinished ones).
    let (c, root, grown) = if a.missing {
        let (c, root) = existing_campaign(a)?;
        (c, root, false)
    } else {
        new_campaign(a)?
    };
    let resubmit = a.missing || grown;
    let previous = slurm::read_record(&root).map_err(report_error)?;
    let options = options(a, resubmit, previous.map(|r| r.options));
    let (max_array, note) = slurm::max_array_size();
    if let Some(n) = note {
        tracing::info!("{n}");
    }
    let plan =
        slurm::plan(&c, &root, options, resubmit, &binary, max_array).map_err(report_error)?;
    for n in &plan.notes {
        tracing::warn!("{n}");
    }
    if plan.indices.is_empty() {
        outln!(
            "{}: nothing to submit: every shard is finished, queued or running",
            root.display()
        );
    } else if a.dry_run {
        print_dry_run(&root, &plan);
    } else {
        let p = slurm::submit(&root, plan).map_err(report_error)?;
        print_submitted(&root, &p);
    }
    Ok(exit_codes::OK)
}

/// This executable's absolute path, for the scripts.
fn binary() -> Result<String, Stop> {
    std::env::current_exe()
        .and_then(|p| p.canonicalize())
        .map(|p| p.display().to_string())
        .map_err(|e| {
            fail(
                exit_codes::INVALID_INPUT,
                format!("cannot locate the granular binary: {e}"),
            )
        })
}

/// Every path and value the scripts would hold that no quoting can carry (see
/// `campaign::slurm`: a line break, NUL, a backslash in the directory, `hetjob`/`packjob` on an
/// `#SBATCH` line), refused at once with exit 2 before anything is created or written. The
/// options of an earlier submission that are not given again are checked by `slurm::plan`.
fn refuse_unscriptable(a: &Args, binary: &str) -> Result<(), Stop> {
    let dir = if a.missing {
        Some(("DIR", &a.target))
    } else {
        a.out.as_ref().map(|o| ("--out", o))
    };
    let mut problems = Vec::new();
    if let Some((what, dir)) = dir {
        if let Err(e) = slurm::check_dir(what, &script_root(dir)) {
            problems.extend(e);
        }
    }
    problems.extend(slurm::check_value("the granular binary", binary, false));
    if let Some(p) = &a.partition {
        problems.extend(slurm::check_value("--partition", p, true));
    }
    for arg in &a.sbatch_arg {
        problems.extend(slurm::check_value("--sbatch-arg", arg, true));
    }
    if problems.is_empty() {
        return Ok(());
    }
    for p in &problems[..problems.len() - 1] {
        fail(exit_codes::INVALID_INPUT, p);
    }
    Err(fail(
        exit_codes::INVALID_INPUT,
        &problems[problems.len() - 1],
    ))
}

/// The campaign directory `dir` as the scripts will name it, before it exists: canonical (as
/// `submit` makes it once created) where it exists, else its deepest existing ancestor's
/// canonical path with the rest appended.
fn script_root(dir: &Path) -> PathBuf {
    let abs = std::path::absolute(dir).unwrap_or_else(|_| dir.to_path_buf());
    let mut base = abs.as_path();
    let mut rest = Vec::new();
    loop {
        if let Ok(c) = base.canonicalize() {
            return rest.iter().rev().fold(c, |p, name| p.join(name));
        }
        match (base.parent(), base.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name);
                base = parent;
            }
            _ => return abs,
        }
    }
}

/// `--missing DIR`: the campaign in `target`.
fn existing_campaign(a: &Args) -> Result<(Campaign, PathBuf), Stop> {
    if a.out.is_some() {
        return Err(fail(
            exit_codes::INVALID_INPUT,
            "--missing takes the campaign directory as its argument, not --out",
        ));
    }
    let c = Campaign::open(&a.target).map_err(report_error)?;
    let root = a.target.canonicalize().unwrap_or(a.target.clone());
    Ok((c, root))
}

/// A submission of manifest `target` in `--out`: a first one, or a grown manifest of a
/// campaign submitted before (then true); the campaign is created or grown, or only planned in
/// memory with `--dry-run`.
fn new_campaign(a: &Args) -> Result<(Campaign, PathBuf, bool), Stop> {
    let Some(out) = a.out.clone() else {
        return Err(fail(
            exit_codes::INVALID_INPUT,
            "a first submission needs --out DIR (or use --missing DIR)",
        ));
    };
    let submitted = out.join("slurm").join("submission.json").exists();
    let missing_flags: Vec<&str> = [
        ("--time", a.time.is_none()),
        ("--tasks", a.tasks.is_none()),
        ("--per-task-runs", a.per_task_runs.is_none()),
    ]
    .into_iter()
    .filter_map(|(flag, absent)| absent.then_some(flag))
    .collect();
    if !missing_flags.is_empty() && !submitted {
        return Err(fail(
            exit_codes::INVALID_INPUT,
            format!("a first submission needs {}", missing_flags.join(", ")),
        ));
    }
    let existed = out.join("campaign.json").exists();
    let (c, growth) = Campaign::prepare(&a.target, &out, !a.dry_run).map_err(report_error)?;
    let root = if a.dry_run {
        script_root(&out)
    } else {
        out.canonicalize().unwrap_or(out)
    };
    Ok((c, root, existed && submitted && !growth.is_empty()))
}

/// The submission's options: the flags of a first submission; for a resubmission (`--missing`,
/// a grown manifest), the previous submission's options with the flags given overriding them
/// (None without one).
fn options(a: &Args, resubmit: bool, previous: Option<SlurmOptions>) -> Option<SlurmOptions> {
    if resubmit {
        return previous.map(|mut o| {
            if let Some(t) = a.tasks {
                o.throttle = t;
            }
            if let Some(t) = &a.time {
                o.time = t.clone();
            }
            if a.partition.is_some() {
                o.partition = a.partition.clone();
            }
            if !a.sbatch_arg.is_empty() {
                o.sbatch_args = a.sbatch_arg.clone();
            }
            if let Some(n) = a.cpus_per_task {
                o.cpus_per_task = n;
            }
            if let Some(x) = a.checkpoint.given {
                o.checkpoint_every = x;
            }
            if a.no_compact {
                o.compact = false;
            }
            o
        });
    }
    Some(SlurmOptions {
        throttle: a.tasks.unwrap_or(1),
        per_task_runs: a.per_task_runs.unwrap_or(1),
        time: a.time.clone().unwrap_or_default(),
        partition: a.partition.clone(),
        sbatch_args: a.sbatch_arg.clone(),
        cpus_per_task: a.cpus_per_task.unwrap_or(1),
        checkpoint_every: a.checkpoint.seconds(),
        compact: !a.no_compact,
    })
}

/// `--dry-run`: the scripts and the sbatch commands that would run (their paths quoted for the
/// shell, as the scripts quote them).
fn print_dry_run(root: &Path, plan: &slurm::Plan) {
    let sub = plan.record.submissions.last().expect("submission");
    let path = |rel: &str| slurm::shell_quote(&root.join(rel).to_string_lossy());
    outln!(
        "# {} (would be written to {})",
        sub.script,
        path(&sub.script)
    );
    out!("{}", plan.script);
    for (rel, text) in [
        (&sub.compact_script, &plan.compact_script),
        (&sub.round_script, &plan.round_script),
    ] {
        if let (Some(rel), Some(text)) = (rel, text) {
            outln!("# {rel}");
            out!("{text}");
        }
    }
    outln!("# would run: sbatch --parsable {}", path(&sub.script));
    if let Some(rel) = &sub.compact_script {
        outln!(
            "# then: sbatch --parsable --dependency=afterok:<array job id> {}",
            path(rel)
        );
    }
    if let Some(rel) = &sub.round_script {
        outln!(
            "# then: sbatch --parsable --dependency=afterany:<array job id> {}",
            path(rel)
        );
    }
}

fn print_submitted(root: &Path, p: &slurm::Plan) {
    let s = p.record.submissions.last().expect("submission");
    outln!(
        "submitted {} array task(s) ({} shards of about {} runs, array {}) as job {}{}",
        p.indices.len(),
        p.record.shards,
        p.record.runs_per_shard,
        s.array,
        s.array_job.as_deref().unwrap_or("?"),
        s.compact_job
            .as_deref()
            .map(|j| format!(", compaction job {j} (afterok)"))
            .or_else(|| s.round_job.as_deref().map(|j| format!(
                ", round {} job {j} (afterany; it submits the next round's array, and the compaction after the last)",
                s.round.unwrap_or(1)
            )))
            .unwrap_or_default()
    );
    outln!("script: {}", root.join(&s.script).display());
}
