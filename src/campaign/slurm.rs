//! `granular submit --slurm`: a campaign as a SLURM job array. SLURM places the work;
//! granular only shards it. Array task `i` runs shard `i+1` of `N` (`--shard (i+1)/N`, runs with
//! `run_id % N == i`), which is idempotent: finished runs are skipped, running ones resume from
//! their checkpoints, the shard lock refuses a second process. A compaction job follows the
//! array with `afterok`.
//!
//! **Error targets** (a manifest with `target`): the rounds run as chained arrays. Each array
//! (the pilot first) is followed by a ROUND job (`--dependency=afterany:<array>`: a failed
//! task does not stall the campaign) that runs `granular slurm-round DIR --submission K`
//! ([`round_step`]): it decides the next round ([`crate::campaign::targets::decide_round`],
//! under the campaign's lock, from the committed runs only) and, when runs were added,
//! submits the next array of the shards with pending runs (the same layout `N` and options)
//! and the next round job after it; when the runs asked for are not all committed it
//! resubmits their shards once more, then gives up (its message in the job's log, in the
//! record and in `status`); when every target is met or the campaign stopped, it submits the
//! compaction job (if asked for) and records the verdict. At most [`MAX_ROUNDS`] rounds. The
//! decisions come from the committed runs alone, so the tables are those of a local `run`.
//!
//! Files (under the campaign directory):
//! ```text
//! slurm/submission.json         the shard layout, the options, every submission's job ids
//! slurm/array-<k>.sh            the k-th array script (readable, resubmittable with sbatch)
//! slurm/compact-<k>.sh          its compaction job (error targets: after the final round)
//! slurm/round-<k>.sh            error targets: the round job after array k
//! slurm/logs/<job>_<task>.out   task output
//! ```
//! The commands `sbatch`, `squeue` and `scontrol` can be replaced through the environment
//! variables `GRANULAR_SBATCH`, `GRANULAR_SQUEUE` and `GRANULAR_SCONTROL` (tests, wrappers).
//!
//! No data becomes shell text: every path or value a script holds is quoted for whoever reads
//! that line, bash ([`shell_quote`]: POSIX single quotes) or sbatch ([`sbatch_arg`]: sbatch's
//! own quoting of `#SBATCH` lines), and one that no quoting can carry is refused
//! ([`check_dir`], [`check_value`]): a line break or NUL anywhere, and on `#SBATCH` lines the
//! separator of a heterogeneous job (`hetjob`, `packjob`); in the directory also a
//! backslash, which makes SLURM strip every backslash from the log path and expand none of its
//! `%` patterns. A `%` of the directory is written `%%` in `--output` (SLURM's escape).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

use serde::{Deserialize, Serialize};

use super::ledger;
use super::{Campaign, CampaignError};
use crate::fsutil;
use crate::store::SUBMISSION_FORMAT;

pub const SUBMISSION_KIND: &str = "granular.slurm_submission";

/// SLURM's default `MaxArraySize` (indices 0..=1000).
pub const DEFAULT_MAX_ARRAY_SIZE: u64 = 1001;

/// Rounds a chain of round jobs decides at most (it never loops).
pub const MAX_ROUNDS: u32 = 100;

/// Arrays a round job submits for one round: the round's array and one resubmission of the
/// shards whose runs were not committed.
pub const ATTEMPTS_PER_ROUND: u32 = 2;

/// The options of `granular submit` (all but the first submission's may be overridden by
/// `--missing`).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct SlurmOptions {
    /// Array tasks running at once (the `%` throttle).
    pub throttle: u32,
    /// Runs per array task (before packing to respect MaxArraySize).
    pub per_task_runs: u64,
    /// `--time` of each task (and of the compaction job).
    pub time: String,
    pub partition: Option<String>,
    /// Extra `#SBATCH` arguments, verbatim.
    pub sbatch_args: Vec<String>,
    /// Worker threads per task (`--cpus-per-task`).
    pub cpus_per_task: u32,
    /// Seconds between checkpoints of a running simulation in a task (what a node failure,
    /// SIGKILL without the SIGTERM of a time limit or scancel, can lose).
    #[serde(default = "default_checkpoint_every")]
    pub checkpoint_every: f64,
    /// Chain a `granular compact` job after the array (afterok).
    pub compact: bool,
}

fn default_checkpoint_every() -> f64 {
    300.0
}

/// One `sbatch` of an array (and its compaction job).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct Submission {
    pub number: u32,
    /// Relative to the campaign directory.
    pub script: String,
    /// The `--array` value, throttle included.
    pub array: String,
    pub array_job: Option<String>,
    pub compact_script: Option<String>,
    pub compact_job: Option<String>,
    /// Array indices (shard index - 1) of this submission.
    pub indices: Vec<u64>,
    /// Error targets: the round whose runs this array runs (1: the pilot; its round job takes
    /// decision `round`), and which try of that round it is (1, or 2 for the resubmission of
    /// shards whose runs were not committed). None without targets (and in older records).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub round: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attempt: Option<u32>,
    /// Error targets: the round job chained after the array (afterany).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub round_script: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub round_job: Option<String>,
}

/// How the chain of round jobs ended (error targets).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct RoundsOutcome {
    /// The submission whose round job ended the chain.
    pub submission: u32,
    /// The round it decided.
    pub round: u32,
    /// `met`, `stopped` (the campaign's verdict) or `gave_up` (the chain stopped: runs not
    /// committed after a resubmission, [`MAX_ROUNDS`], an error).
    pub verdict: String,
    pub message: String,
}

/// `slurm/submission.json`.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct SubmissionRecord {
    pub format_version: u32,
    pub kind: String,
    /// N of the shard layout `--shard I/N`; fixed by the first submission.
    pub shards: u64,
    pub runs_per_shard: u64,
    pub options: SlurmOptions,
    /// The granular binary the scripts run.
    pub binary: String,
    pub submissions: Vec<Submission>,
    /// Error targets: how the chain of round jobs ended (None while it goes on; cleared by a
    /// new submission).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub outcome: Option<RoundsOutcome>,
}

/// What `submit` did or would do.
#[derive(Debug, Clone)]
pub struct Plan {
    pub record: SubmissionRecord,
    pub script: String,
    pub compact_script: Option<String>,
    /// Error targets: the round job's script (instead of the compaction's).
    pub round_script: Option<String>,
    pub indices: Vec<u64>,
    pub notes: Vec<String>,
    /// Array jobs of earlier submissions with tasks still queued or running.
    pub still_queued_arrays: Vec<String>,
}

fn record_path(root: &Path) -> PathBuf {
    root.join("slurm").join("submission.json")
}

/// The campaign's submission record, if it has one: corrupt or of another format is
/// refused, unreadable is I/O.
pub fn read_record(root: &Path) -> Result<Option<SubmissionRecord>, CampaignError> {
    let p = record_path(root);
    let text = match std::fs::read_to_string(&p) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(CampaignError::at(&p, e)),
    };
    let r: SubmissionRecord = serde_json::from_str(&text).map_err(|e| {
        CampaignError::Refused(format!("{}: corrupt submission record: {e}", p.display()))
    })?;
    if r.kind != SUBMISSION_KIND || r.format_version != SUBMISSION_FORMAT {
        return Err(CampaignError::Refused(format!(
            "{}: not a submission record of format {SUBMISSION_FORMAT}",
            p.display()
        )));
    }
    Ok(Some(r))
}

/// Check a SLURM time limit: `M`, `M:S`, `H:M:S`, `D-H`, `D-H:M`, `D-H:M:S`.
pub fn check_time(t: &str) -> Result<(), CampaignError> {
    let num = |s: &str| !s.is_empty() && s.len() <= 4 && s.bytes().all(|b| b.is_ascii_digit());
    let (days, rest) = match t.split_once('-') {
        Some((d, r)) => (Some(d), r),
        None => (None, t),
    };
    let parts: Vec<&str> = rest.split(':').collect();
    let ok = days.is_none_or(num)
        && parts.iter().all(|p| num(p))
        && match days {
            Some(_) => (1..=3).contains(&parts.len()),
            None => (1..=3).contains(&parts.len()),
        };
    if ok {
        Ok(())
    } else {
        Err(CampaignError::Invalid(format!(
            "--time {t:?}: expected a SLURM time limit (MM, MM:SS, HH:MM:SS, D-HH, D-HH:MM or D-HH:MM:SS)"
        )))
    }
}

/// `0-4,7,9-12` from sorted indices.
pub fn ranges(indices: &[u64]) -> String {
    let mut out: Vec<String> = Vec::new();
    let mut i = 0;
    while i < indices.len() {
        let mut j = i;
        while j + 1 < indices.len() && indices[j + 1] == indices[j] + 1 {
            j += 1;
        }
        out.push(if i == j {
            indices[i].to_string()
        } else {
            format!("{}-{}", indices[i], indices[j])
        });
        i = j + 1;
    }
    out.join(",")
}

/// Shards (N) and runs per shard for `n_runs` runs, `per_task` runs per task and at most
/// `max_array` array indices: packs more runs per task when the array would be too large.
pub fn layout(n_runs: u64, per_task: u64, max_array: u64) -> (u64, u64) {
    let per_task = per_task.max(1);
    let mut shards = n_runs.div_ceil(per_task).max(1);
    let mut per = per_task;
    if shards > max_array {
        per = n_runs.div_ceil(max_array);
        shards = n_runs.div_ceil(per);
    }
    (shards, per)
}

fn tool(var: &str, default: &str) -> String {
    std::env::var(var).unwrap_or_else(|_| default.to_string())
}

/// `MaxArraySize` of the cluster (`scontrol show config`), or SLURM's default.
pub fn max_array_size() -> (u64, Option<String>) {
    let out = Command::new(tool("GRANULAR_SCONTROL", "scontrol"))
        .args(["show", "config"])
        .output();
    match out {
        Ok(o) if o.status.success() => {
            let text = String::from_utf8_lossy(&o.stdout);
            for line in text.lines() {
                let mut it = line.splitn(2, '=');
                if it.next().map(str::trim) == Some("MaxArraySize") {
                    if let Some(v) = it.next().and_then(|v| v.trim().parse::<u64>().ok()) {
                        return (v.max(1), None);
                    }
                }
            }
            (
                DEFAULT_MAX_ARRAY_SIZE,
                Some("scontrol show config has no MaxArraySize; assuming 1001".into()),
            )
        }
        _ => (
            DEFAULT_MAX_ARRAY_SIZE,
            Some("scontrol not available; assuming MaxArraySize = 1001".into()),
        ),
    }
}

/// `s` as one word for a POSIX shell: in single quotes, each `'` written `'\''`. Every string
/// is safe so (a line break inside the quotes is part of the word; [`check_value`] refuses
/// them anyway).
pub fn shell_quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', "'\\''"))
}

/// `s` as one argument of an `#SBATCH` line, as sbatch reads those (`_get_argument` in SLURM's
/// `src/sbatch/opt.c`): an unquoted argument ends at white space, an unquoted `#` starts a
/// comment, `'` and `"` quote, a backslash escapes the next character inside quotes too, and a
/// leading `:` is fatal. So a word of safe characters stays bare, any other is put in double
/// quotes with `\`, `"` and `#` escaped by a backslash (older sbatch versions knew only double
/// quotes and ended an argument at `#` even inside them; they read this the same).
/// `s` must have passed [`check_value`] (no line break or NUL).
pub fn sbatch_arg(s: &str) -> String {
    let safe = |b: u8| b.is_ascii_alphanumeric() || b"-_.,:=/+@%".contains(&b);
    if !s.is_empty() && !s.starts_with(':') && s.bytes().all(safe) {
        return s.to_string();
    }
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for ch in s.chars() {
        if matches!(ch, '\\' | '"' | '#') {
            out.push('\\');
        }
        out.push(ch);
    }
    out.push('"');
    out
}

/// What cannot be said on any line of a script: a line break ends the line (an `#SBATCH`
/// directive or a comment, whatever the quoting) and NUL ends the text for sbatch.
fn line_breaks(s: &str) -> Option<&'static str> {
    if s.contains('\n') {
        Some("a line break (\\n)")
    } else if s.contains('\r') {
        Some("a carriage return (\\r)")
    } else if s.contains('\0') {
        Some("a NUL character")
    } else {
        None
    }
}

/// The separator of a heterogeneous job's components on `#SBATCH` lines: an argument `hetjob`
/// (or its old name `packjob`) for sbatch 22.05 (checked); older versions took any line that
/// contains `packjob`, in any case and quoted or not, for one (`strcasestr(line, "packjob")`
/// in their `_opt_batch_script`).
/// Refused wherever they stand in a value, in either spelling.
fn hetjob_word(s: &str) -> Option<&'static str> {
    let lower = s.to_ascii_lowercase();
    ["hetjob", "packjob"]
        .into_iter()
        .find(|w| lower.contains(w))
}

/// Why `value` (named `what` in the messages: a flag and its value) cannot be written into a
/// SLURM script, if it cannot; `directive`: on an `#SBATCH` line.
pub fn check_value(what: &str, value: &str, directive: bool) -> Vec<String> {
    let mut out = Vec::new();
    if let Some(c) = line_breaks(value) {
        out.push(format!(
            "{what} {value:?}: contains {c}, which no line of the SLURM scripts can hold"
        ));
    }
    if directive {
        if let Some(w) = hetjob_word(value) {
            out.push(format!(
                "{what} {value:?}: contains {w:?}, which sbatch may take on an #SBATCH line for the separator of a heterogeneous job's components"
            ));
        }
    }
    out
}

/// The campaign directory as the scripts name it (the logs' `#SBATCH --output`, the commands
/// they run), or every reason it cannot be named there (`what`: how the user gave it, e.g.
/// `--out`): not UTF-8, a line break or NUL, a backslash (SLURM strips the backslashes of an
/// output path and then expands none of its `%` patterns), `hetjob`/`packjob`.
pub fn check_dir<'a>(what: &str, root: &'a Path) -> Result<&'a str, Vec<String>> {
    let Some(text) = root.to_str() else {
        return Err(vec![format!(
            "{what} {root:?}: not UTF-8; the SLURM scripts name the campaign directory in UTF-8 text"
        )]);
    };
    let mut out = check_value(what, text, true);
    if text.contains('\\') {
        out.push(format!(
            "{what} {text:?}: contains a backslash; SLURM would strip it from the task logs' path (#SBATCH --output) and then expand none of %A, %a, %j there"
        ));
    }
    if out.is_empty() {
        Ok(text)
    } else {
        Err(out)
    }
}

/// Every value of `o` that cannot be written into the scripts (their `#SBATCH` lines).
pub fn check_options(o: &SlurmOptions) -> Vec<String> {
    let mut out = Vec::new();
    if let Some(p) = &o.partition {
        out.extend(check_value("--partition", p, true));
    }
    for a in &o.sbatch_args {
        out.extend(check_value("--sbatch-arg", a, true));
    }
    out
}

/// `granular-<name>`: the campaign name with every character but ASCII letters, digits, `-`
/// and `_` made `_` (names are so already: the manifest's schema), at most 40 of them, and
/// `hetjob`/`packjob` broken by a `_` ([`hetjob_word`]).
fn job_name(name: &str) -> String {
    let n: String = name
        .chars()
        .map(|ch| {
            if ch.is_ascii_alphanumeric() || ch == '-' || ch == '_' {
                ch
            } else {
                '_'
            }
        })
        .take(40)
        .collect();
    let mut out = String::from("granular-");
    let mut rest = n.as_str();
    while !rest.is_empty() {
        let lower = rest.to_ascii_lowercase();
        if lower.starts_with("hetjob") || lower.starts_with("packjob") {
            let cut = if lower.starts_with("het") { 3 } else { 4 };
            out.push_str(&rest[..cut]);
            out.push('_');
            rest = &rest[cut..];
        } else {
            out.push_str(&rest[..1]);
            rest = &rest[1..];
        }
    }
    out
}

/// `#SBATCH --output=<dir>/slurm/logs/<pattern>`: the directory's `%` written `%%`, so that
/// SLURM expands only `pattern`.
fn output_directive(dir: &str, pattern: &str) -> String {
    format!(
        "#SBATCH {}\n",
        sbatch_arg(&format!(
            "--output={}/slurm/logs/{pattern}",
            dir.replace('%', "%%")
        ))
    )
}

/// The `#SBATCH` lines of the user's options (partition, extra arguments: one argument each).
fn option_directives(o: &SlurmOptions) -> String {
    let mut s = String::new();
    if let Some(p) = &o.partition {
        s.push_str(&format!(
            "#SBATCH {}\n",
            sbatch_arg(&format!("--partition={p}"))
        ));
    }
    for a in &o.sbatch_args {
        s.push_str(&format!("#SBATCH {}\n", sbatch_arg(a)));
    }
    s
}

/// The array script of submission `number`; `root` and the options have passed
/// [`check_dir`], [`check_value`] and [`check_options`] (see [`plan`]).
fn array_script(
    c: &Campaign,
    root: &str,
    rec: &SubmissionRecord,
    array: &str,
    number: u32,
) -> String {
    let o = &rec.options;
    let mut s = String::new();
    s.push_str("#!/bin/bash\n");
    s.push_str(&format!(
        "# granular campaign {:?}: {} runs as {} shards of about {} runs (array task i = shard i+1/{}).\n",
        c.manifest.name,
        c.plan.n_runs(),
        rec.shards,
        rec.runs_per_shard,
        rec.shards
    ));
    s.push_str(&format!(
        "# Submission {number}, written by `granular submit`. Resubmitting this script is safe:\n\
         # finished runs are skipped and running ones resume from their checkpoints.\n\
         # Unfinished work only: granular submit --missing {}\n",
        shell_quote(root)
    ));
    s.push_str(&format!(
        "#SBATCH --job-name={}\n",
        job_name(&c.manifest.name)
    ));
    s.push_str(&format!("#SBATCH --array={array}\n"));
    s.push_str(&format!("#SBATCH --time={}\n", sbatch_arg(&o.time)));
    s.push_str(&format!("#SBATCH --cpus-per-task={}\n", o.cpus_per_task));
    s.push_str("#SBATCH --ntasks=1\n");
    s.push_str(&output_directive(root, "%A_%a.out"));
    s.push_str("#SBATCH --open-mode=append\n");
    s.push_str(&option_directives(o));
    s.push_str("set -u\n");
    s.push_str(&format!(
        "exec {} slurm-task {} --shards {} --threads \"${{SLURM_CPUS_PER_TASK:-{}}}\" --checkpoint-every {}\n",
        shell_quote(&rec.binary),
        shell_quote(root),
        rec.shards,
        o.cpus_per_task,
        o.checkpoint_every
    ));
    s
}

fn compact_script(c: &Campaign, root: &str, rec: &SubmissionRecord) -> String {
    let o = &rec.options;
    let mut s = String::new();
    s.push_str("#!/bin/bash\n");
    s.push_str(&format!(
        "# granular campaign {:?}: merge the table parts after the array (afterok).\n",
        c.manifest.name
    ));
    s.push_str(&format!(
        "#SBATCH --job-name={}-compact\n",
        job_name(&c.manifest.name)
    ));
    // Removed by SLURM when a task of the array fails (then `submit --missing` chains a new one).
    s.push_str("#SBATCH --kill-on-invalid-dep=yes\n");
    s.push_str(&format!("#SBATCH --time={}\n", sbatch_arg(&o.time)));
    s.push_str("#SBATCH --ntasks=1\n");
    s.push_str(&output_directive(root, "compact-%j.out"));
    s.push_str(&option_directives(o));
    s.push_str(&format!(
        "exec {} compact {}\n",
        shell_quote(&rec.binary),
        shell_quote(root)
    ));
    s
}

/// The round job after array `number` (error targets): decides the next round and submits
/// what follows (`granular slurm-round`, [`round_step`]).
fn round_script(c: &Campaign, root: &str, rec: &SubmissionRecord, number: u32) -> String {
    let o = &rec.options;
    let mut s = String::new();
    s.push_str("#!/bin/bash\n");
    s.push_str(&format!(
        "# granular campaign {:?}: the round after array {number} (afterany): decide the next\n\
         # round of replicas from the committed runs and submit its array and round job, or the\n\
         # compaction once every target is met or the campaign stopped.\n",
        c.manifest.name
    ));
    s.push_str(&format!(
        "#SBATCH --job-name={}-round\n",
        job_name(&c.manifest.name)
    ));
    s.push_str(&format!("#SBATCH --time={}\n", sbatch_arg(&o.time)));
    s.push_str("#SBATCH --ntasks=1\n");
    s.push_str(&output_directive(root, "round-%j.out"));
    s.push_str("#SBATCH --open-mode=append\n");
    s.push_str(&option_directives(o));
    s.push_str("set -u\n");
    s.push_str(&format!(
        "exec {} slurm-round {} --submission {number}\n",
        shell_quote(&rec.binary),
        shell_quote(root)
    ));
    s
}

/// One line of `squeue -h -r -o "%F %K %T"`: array job id, task index (or the range spec of a
/// pending remainder, "3-9%2"; "N/A" for a plain job), state.
struct Queued {
    job: String,
    index: String,
    state: String,
}

/// The queued and running jobs among `jobs` (array tasks one per line); `None` when squeue
/// cannot be asked. squeue fails for job ids it no longer knows: then none of them is queued.
fn squeue(jobs: &[String]) -> Option<Vec<Queued>> {
    if jobs.is_empty() {
        return Some(Vec::new());
    }
    let out = Command::new(tool("GRANULAR_SQUEUE", "squeue"))
        .args(["-h", "-r", "-o", "%F %K %T", "-j", &jobs.join(",")])
        .output()
        .ok()?;
    if !out.status.success() {
        return String::from_utf8_lossy(&out.stderr)
            .contains("Invalid job id")
            .then(Vec::new);
    }
    Some(
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .filter_map(|line| {
                let mut f = line.split_whitespace();
                let q = Queued {
                    job: f.next()?.to_string(),
                    index: f.next()?.to_string(),
                    state: f.next()?.to_string(),
                };
                jobs.contains(&q.job).then_some(q)
            })
            .collect(),
    )
}

/// Array tasks of earlier submissions still queued or running, by array index, and the array
/// jobs they belong to; `None` when squeue cannot be asked.
fn queued_indices(rec: &SubmissionRecord) -> Option<(BTreeSet<u64>, BTreeSet<String>)> {
    let jobs: Vec<String> = rec
        .submissions
        .iter()
        .filter_map(|s| s.array_job.clone())
        .collect();
    let mut set = BTreeSet::new();
    let mut arrays = BTreeSet::new();
    for q in squeue(&jobs)? {
        arrays.insert(q.job);
        let spec = q.index.split('%').next().unwrap_or("");
        for part in spec.split(',') {
            match part.split_once('-') {
                Some((a, b)) => {
                    if let (Ok(a), Ok(b)) = (a.parse::<u64>(), b.parse::<u64>()) {
                        set.extend(a..=b);
                    }
                }
                None => {
                    if let Ok(i) = part.parse::<u64>() {
                        set.insert(i);
                    }
                }
            }
        }
    }
    Some((set, arrays))
}

/// A submission as `granular status` shows it.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct SubmissionStatus {
    pub number: u32,
    pub array: String,
    pub array_job: Option<String>,
    pub compact_job: Option<String>,
    /// Error targets: the round this array runs, which try of it, its round job.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub round: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attempt: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub round_job: Option<String>,
    /// Error targets, on the submission whose round job ended the chain: how it ended.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub outcome: Option<RoundsOutcome>,
    /// SLURM states of this submission's jobs now (`squeue`), e.g. {"RUNNING": 2, "PENDING": 5};
    /// `None` when squeue could not be asked.
    pub queue: Option<std::collections::BTreeMap<String, u64>>,
}

impl SubmissionStatus {
    /// "array A job J, compaction job C (STATE: n, ...)", as `status` and `report` show it.
    pub fn describe(&self) -> String {
        let queue = match &self.queue {
            Some(q) if q.is_empty() => "nothing queued".to_string(),
            Some(q) => q
                .iter()
                .map(|(k, n)| format!("{k}: {n}"))
                .collect::<Vec<_>>()
                .join(", "),
            None => "squeue not available".to_string(),
        };
        let round = match (self.round, self.attempt) {
            (Some(r), Some(a)) if a > 1 => format!("round {r} (try {a}): "),
            (Some(r), _) => format!("round {r}: "),
            _ => String::new(),
        };
        let round_job = match &self.round_job {
            Some(j) => format!(", round job {j}"),
            None if self.round.is_some() => ", round job -".to_string(),
            None => String::new(),
        };
        let outcome = match &self.outcome {
            Some(o) if o.verdict == "gave_up" => {
                format!(
                    "; the round jobs gave up at round {}: {}",
                    o.round, o.message
                )
            }
            Some(o) => format!(
                "; targets {} after round {}: {}",
                if o.verdict == "met" { "met" } else { "stopped" },
                o.round,
                o.message
            ),
            None => String::new(),
        };
        format!(
            "{round}array {} job {}{round_job}, compaction job {} ({queue}){outcome}",
            self.array,
            self.array_job.as_deref().unwrap_or("-"),
            self.compact_job.as_deref().unwrap_or("-")
        )
    }
}

/// The submissions of a campaign with their jobs' current SLURM states.
pub fn submission_status(root: &Path) -> Result<Vec<SubmissionStatus>, CampaignError> {
    let Some(rec) = read_record(root)? else {
        return Ok(Vec::new());
    };
    let ids: Vec<String> = rec
        .submissions
        .iter()
        .flat_map(|s| {
            [
                s.array_job.clone(),
                s.compact_job.clone(),
                s.round_job.clone(),
            ]
        })
        .flatten()
        .collect();
    let states = squeue(&ids);
    Ok(rec
        .submissions
        .iter()
        .map(|s| SubmissionStatus {
            number: s.number,
            array: s.array.clone(),
            array_job: s.array_job.clone(),
            compact_job: s.compact_job.clone(),
            round: s.round,
            attempt: s.attempt,
            round_job: s.round_job.clone(),
            outcome: rec.outcome.clone().filter(|o| o.submission == s.number),
            queue: states.as_ref().map(|st| {
                let mut m = std::collections::BTreeMap::new();
                for q in st {
                    let what = if Some(&q.job) == s.array_job.as_ref() {
                        "tasks"
                    } else if Some(&q.job) == s.compact_job.as_ref() {
                        "compaction"
                    } else if Some(&q.job) == s.round_job.as_ref() {
                        "round"
                    } else {
                        continue;
                    };
                    *m.entry(format!("{what} {}", q.state)).or_insert(0) += 1;
                }
                m
            }),
        })
        .collect())
}

/// Work out a submission: all shards for the first one, the shards with unfinished runs that
/// no live task is working on for `--missing`.
pub fn plan(
    c: &Campaign,
    root: &Path,
    options: Option<SlurmOptions>,
    missing: bool,
    binary: &str,
    max_array: u64,
) -> Result<Plan, CampaignError> {
    let existing = read_record(root)?;
    let mut notes = Vec::new();
    let rec = match (&existing, missing) {
        (Some(_), false) => return Err(already_submitted(root)),
        (None, true) => return Err(never_submitted(root)),
        (Some(r), true) => resubmission(r, options, binary),
        (None, false) => first_submission(c, options, binary, max_array, &mut notes),
    };
    check_time(&rec.options.time).map_err(|e| CampaignError::Refused(e.to_string()))?;
    // What the scripts would hold (the CLI refuses bad flags before this; here the options of
    // an earlier submission read back from its record, and the directory it was given).
    let dir = scriptable_dir(root, &rec)?;
    let (indices, still_queued_arrays) = if !missing {
        ((0..rec.shards).collect(), Vec::new())
    } else {
        missing_shards(c, root, &rec, &mut notes)?
    };
    // Error targets: this array runs the round after the decisions so far (a new try).
    let round = c
        .manifest
        .has_targets()
        .then(|| (c.rounds.decisions.len() as u32 + 1, 1));
    Ok(assemble(
        c,
        dir,
        rec,
        indices,
        still_queued_arrays,
        notes,
        round,
    ))
}

/// The plan of the next submission of `rec` (its scripts and record entry) for the shards
/// `indices`; `round`: (round, try) of an error-target campaign, whose array is followed by a
/// round job instead of the compaction. `dir` has passed [`scriptable_dir`].
fn assemble(
    c: &Campaign,
    dir: &str,
    mut rec: SubmissionRecord,
    indices: Vec<u64>,
    still_queued_arrays: Vec<String>,
    notes: Vec<String>,
    round: Option<(u32, u32)>,
) -> Plan {
    let number = rec.submissions.len() as u32 + 1;
    let array = format!("{}%{}", ranges(&indices), rec.options.throttle.max(1));
    let script = array_script(c, dir, &rec, &array, number);
    let compact = (rec.options.compact && round.is_none()).then(|| compact_script(c, dir, &rec));
    let round_text = round.map(|_| round_script(c, dir, &rec, number));
    rec.outcome = None;
    rec.submissions.push(Submission {
        number,
        script: format!("slurm/array-{number:03}.sh"),
        array,
        array_job: None,
        compact_script: compact
            .as_ref()
            .map(|_| format!("slurm/compact-{number:03}.sh")),
        compact_job: None,
        indices: indices.clone(),
        round: round.map(|r| r.0),
        attempt: round.map(|r| r.1),
        round_script: round_text
            .as_ref()
            .map(|_| format!("slurm/round-{number:03}.sh")),
        round_job: None,
    });
    Plan {
        record: rec,
        script,
        compact_script: compact,
        round_script: round_text,
        indices,
        notes,
        still_queued_arrays,
    }
}

fn already_submitted(root: &Path) -> CampaignError {
    CampaignError::Refused(format!(
        "{} was already submitted to SLURM (slurm/submission.json); resubmit unfinished work with `granular submit --missing {}`, or submit a grown manifest",
        root.display(),
        root.display()
    ))
}

fn never_submitted(root: &Path) -> CampaignError {
    CampaignError::Refused(format!(
        "{} has no SLURM submission (slurm/submission.json); submit it first with `granular submit MANIFEST --out {} --slurm ...`",
        root.display(),
        root.display()
    ))
}

/// The record of an earlier submission for `--missing`: its layout, with the options given
/// now (if any) and this binary.
fn resubmission(
    earlier: &SubmissionRecord,
    options: Option<SlurmOptions>,
    binary: &str,
) -> SubmissionRecord {
    let mut r = earlier.clone();
    if let Some(o) = options {
        r.options = o;
    }
    r.binary = binary.to_string();
    r
}

/// The record of a first submission: runs packed into shards under `max_array` tasks (a note
/// if more runs per task than asked).
fn first_submission(
    c: &Campaign,
    options: Option<SlurmOptions>,
    binary: &str,
    max_array: u64,
    notes: &mut Vec<String>,
) -> SubmissionRecord {
    let o = options.expect("options of a first submission");
    let (shards, per) = layout(c.plan.n_runs(), o.per_task_runs, max_array);
    if per != o.per_task_runs.max(1) {
        notes.push(format!(
            "{} runs at {} per task would need {} array tasks, more than MaxArraySize = {max_array}: packed {per} runs per task into {shards} tasks",
            c.plan.n_runs(),
            o.per_task_runs,
            c.plan.n_runs().div_ceil(o.per_task_runs.max(1)),
        ));
    }
    SubmissionRecord {
        format_version: SUBMISSION_FORMAT,
        kind: SUBMISSION_KIND.into(),
        shards,
        runs_per_shard: per,
        options: o,
        binary: binary.to_string(),
        submissions: Vec::new(),
        outcome: None,
    }
}

/// The campaign directory as the scripts would hold it, once it, the binary and the options
/// are known to be scriptable (every reason they are not, at once).
fn scriptable_dir<'a>(root: &'a Path, rec: &SubmissionRecord) -> Result<&'a str, CampaignError> {
    let (dir, mut refused) = match check_dir("the campaign directory", root) {
        Ok(d) => (Some(d), Vec::new()),
        Err(e) => (None, e),
    };
    refused.extend(check_value("the granular binary", &rec.binary, false));
    refused.extend(check_options(&rec.options));
    match dir {
        Some(d) if refused.is_empty() => Ok(d),
        _ => Err(CampaignError::Refused(format!(
            "cannot write the SLURM scripts: {}",
            refused.join("; ")
        ))),
    }
}

/// For `--missing`: the shards with unfinished runs that neither a live shard lock nor
/// `squeue` shows at work (a note names those left out), and the arrays of earlier
/// submissions still queued or running.
fn missing_shards(
    c: &Campaign,
    root: &Path,
    rec: &SubmissionRecord,
    notes: &mut Vec<String>,
) -> Result<(Vec<u64>, Vec<String>), CampaignError> {
    let n = rec.shards;
    let mut still_queued_arrays = Vec::new();
    let commits = ledger::read_commits(root)?;
    let finished = ledger::finished_runs(&commits);
    let mut unfinished = BTreeSet::new();
    for r in c.plan.current_runs() {
        if !finished.contains_key(&r.run_id) {
            unfinished.insert(r.run_id % n);
        }
    }
    let live = live_shards(root, n);
    let queued = match queued_indices(rec) {
        Some((q, arrays)) => {
            still_queued_arrays = arrays.into_iter().collect();
            q
        }
        None => {
            notes.push("squeue not available: only shard locks tell which tasks still run".into());
            BTreeSet::new()
        }
    };
    let busy: Vec<u64> = unfinished
        .iter()
        .filter(|i| live.contains(i) || queued.contains(i))
        .copied()
        .collect();
    if !busy.is_empty() {
        notes.push(format!(
            "{} shard(s) with unfinished runs are still queued or running and are not resubmitted: {}",
            busy.len(),
            ranges(&busy)
        ));
    }
    let indices = unfinished
        .into_iter()
        .filter(|i| !busy.contains(i))
        .collect();
    Ok((indices, still_queued_arrays))
}

/// The (0-based) shards of an `n`-shard layout whose lock a live process holds.
fn live_shards(root: &Path, n: u64) -> BTreeSet<u64> {
    ledger::live_locks(root)
        .into_iter()
        .filter(|l| l.shard_count as u64 == n && l.shard_tag != ledger::COMPACT_TAG)
        .filter_map(|l| {
            l.shard
                .split('/')
                .next()
                .and_then(|i| i.parse::<u64>().ok())
                .map(|i| i - 1)
        })
        .collect()
}

fn sbatch(args: &[&str]) -> Result<String, CampaignError> {
    let cmd = tool("GRANULAR_SBATCH", "sbatch");
    let out = Command::new(&cmd)
        .args(args)
        .output()
        .map_err(|e| CampaignError::Io(format!("cannot run {cmd}: {e}")))?;
    if !out.status.success() {
        return Err(CampaignError::Io(format!(
            "{cmd} {} failed ({}): {}",
            args.join(" "),
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        )));
    }
    let text = String::from_utf8_lossy(&out.stdout);
    // --parsable prints "jobid" or "jobid;cluster".
    let id = text.trim().split(';').next().unwrap_or("").to_string();
    if id.is_empty() || !id.bytes().all(|b| b.is_ascii_digit()) {
        return Err(CampaignError::Io(format!(
            "{cmd} printed {text:?}, expected a job id"
        )));
    }
    Ok(id)
}

/// Write the scripts and the record, then submit the array and its compaction job.
pub fn submit(root: &Path, mut p: Plan) -> Result<Plan, CampaignError> {
    let io = |path: &Path, e: std::io::Error| CampaignError::Io(format!("{}: {e}", path.display()));
    let logs = root.join("slurm").join("logs");
    fsutil::create_dir_durable(&logs).map_err(|e| io(&logs, e))?;
    let sub = p.record.submissions.last().cloned().expect("a submission");
    let script_path = root.join(&sub.script);
    fsutil::write_atomic(&script_path, p.script.as_bytes()).map_err(|e| io(&script_path, e))?;
    for (rel, text) in [
        (&sub.compact_script, &p.compact_script),
        (&sub.round_script, &p.round_script),
    ] {
        if let (Some(rel), Some(text)) = (rel, text) {
            let path = root.join(rel);
            fsutil::write_atomic(&path, text.as_bytes()).map_err(|e| io(&path, e))?;
        }
    }
    let save = |rec: &SubmissionRecord| save_record(root, rec);
    if p.indices.is_empty() {
        return Ok(p);
    }
    let array_job = sbatch(&["--parsable", &script_path.display().to_string()])?;
    p.record.submissions.last_mut().expect("sub").array_job = Some(array_job.clone());
    save(&p.record)?;
    if let Some(rel) = &sub.compact_script {
        // After this array succeeds, and after earlier arrays still queued or running end.
        let mut dep = format!("--dependency=afterok:{array_job}");
        for j in &p.still_queued_arrays {
            dep.push_str(&format!(",afterany:{j}"));
        }
        let path = root.join(rel).display().to_string();
        let job = sbatch(&["--parsable", &dep, &path])?;
        p.record.submissions.last_mut().expect("sub").compact_job = Some(job);
        save(&p.record)?;
    }
    if let Some(rel) = &sub.round_script {
        // After every task of this array ends, whatever its state (the round job looks at
        // what was committed), and after earlier arrays still queued or running.
        let mut dep = format!("--dependency=afterany:{array_job}");
        for j in &p.still_queued_arrays {
            dep.push_str(&format!(",afterany:{j}"));
        }
        let path = root.join(rel).display().to_string();
        let job = sbatch(&["--parsable", &dep, &path])?;
        p.record.submissions.last_mut().expect("sub").round_job = Some(job);
        save(&p.record)?;
    }
    Ok(p)
}

/// Write `slurm/submission.json` atomically.
fn save_record(root: &Path, rec: &SubmissionRecord) -> Result<(), CampaignError> {
    let rp = record_path(root);
    fsutil::write_atomic(&rp, &serde_json::to_vec_pretty(rec).expect("record"))
        .map_err(|e| CampaignError::Io(format!("{}: {e}", rp.display())))
}

/// What a round job did ([`round_step`]).
#[derive(Debug, Clone)]
pub enum RoundStep {
    /// A later submission exists (e.g. `submit --missing`): its round job decides; nothing done.
    Superseded(u32),
    /// The next array and its round job were submitted: the runs added by decision `round`
    /// (`added` of them), or (`added` = 0) the resubmission of shards whose runs of the
    /// round were not committed.
    Submitted { round: u32, added: u64, plan: Plan },
    /// Every target met, or the campaign stopped: the verdict, and the compaction job if one
    /// was submitted.
    Final {
        outcome: RoundsOutcome,
        compact_job: Option<String>,
    },
    /// The chain stopped (recorded in the outcome): the runs asked for are not all committed
    /// after a resubmission, or [`MAX_ROUNDS`] rounds were decided.
    GaveUp(RoundsOutcome),
}

/// The round job of submission `number` of the campaign at `root` (`granular slurm-round`):
/// decide the next round and submit what follows (see the module). Errors are recorded in
/// the record's outcome (as a give-up) too, so that `status` shows them.
pub fn round_step(root: &Path, number: u32) -> Result<RoundStep, CampaignError> {
    let rec = read_record(root)?.ok_or_else(|| never_submitted(root))?;
    let Some(sub) = rec.submissions.iter().find(|s| s.number == number).cloned() else {
        return Err(CampaignError::Invalid(format!(
            "{}: no submission {number} in slurm/submission.json",
            root.display()
        )));
    };
    let last = rec.submissions.last().map_or(0, |s| s.number);
    if last != number {
        return Ok(RoundStep::Superseded(last));
    }
    let round = sub.round.unwrap_or(1);
    let attempt = sub.attempt.unwrap_or(1);
    match round_step_inner(root, rec.clone(), &sub, round, attempt) {
        Err(e) => {
            let mut rec = rec;
            rec.outcome = Some(RoundsOutcome {
                submission: number,
                round,
                verdict: "gave_up".into(),
                message: format!("the round job of submission {number} failed: {e}"),
            });
            // The error is what matters; a record that cannot be written is said in the log.
            if let Err(w) = save_record(root, &rec) {
                tracing::warn!("{w}");
            }
            Err(e)
        }
        ok => ok,
    }
}

fn round_step_inner(
    root: &Path,
    mut rec: SubmissionRecord,
    sub: &Submission,
    round: u32,
    attempt: u32,
) -> Result<RoundStep, CampaignError> {
    let c = Campaign::open(root)?;
    if !c.manifest.has_targets() {
        return Err(CampaignError::Refused(format!(
            "{}: the campaign has no error targets; its arrays need no round job",
            root.display()
        )));
    }
    check_time(&rec.options.time).map_err(|e| CampaignError::Refused(e.to_string()))?;
    let dir = scriptable_dir(root, &rec)?.to_string();
    let give_up =
        |rec: &mut SubmissionRecord, message: String| -> Result<RoundStep, CampaignError> {
            let o = RoundsOutcome {
                submission: sub.number,
                round,
                verdict: "gave_up".into(),
                message,
            };
            rec.outcome = Some(o.clone());
            save_record(root, rec)?;
            Ok(RoundStep::GaveUp(o))
        };
    let decided = super::targets::decide_round(&c)?;
    let c = Campaign::open(root)?;
    let (next_round, next_attempt, added) = match decided {
        super::targets::Decided::Final(verdict, why) => {
            let verdict = serde_json::to_value(verdict)
                .ok()
                .and_then(|v| v.as_str().map(str::to_string))
                .unwrap_or_default();
            let o = RoundsOutcome {
                submission: sub.number,
                round: c.rounds.decisions.len() as u32,
                verdict,
                message: why,
            };
            let mut compact_job = None;
            if rec.options.compact {
                let rel = format!("slurm/compact-{:03}.sh", sub.number);
                let path = root.join(&rel);
                let text = compact_script(&c, &dir, &rec);
                fsutil::write_atomic(&path, text.as_bytes())
                    .map_err(|e| CampaignError::Io(format!("{}: {e}", path.display())))?;
                let job = sbatch(&["--parsable", &path.display().to_string()])?;
                let s = rec.submissions.last_mut().expect("sub");
                s.compact_script = Some(rel);
                s.compact_job = Some(job.clone());
                compact_job = Some(job);
            }
            rec.outcome = Some(o.clone());
            save_record(root, &rec)?;
            return Ok(RoundStep::Final {
                outcome: o,
                compact_job,
            });
        }
        super::targets::Decided::More(n) => {
            let decided = c.rounds.decisions.len() as u32;
            if decided >= MAX_ROUNDS {
                return give_up(
                    &mut rec,
                    format!(
                        "{decided} rounds decided, the most a chain of round jobs takes ({MAX_ROUNDS}); the {n} run(s) of round {} are registered but not submitted: `granular submit --missing {}` goes on",
                        decided + 1,
                        root.display()
                    ),
                );
            }
            (decided + 1, 1, n)
        }
        super::targets::Decided::Incomplete => {
            if attempt >= ATTEMPTS_PER_ROUND {
                let pending = pending_shards(&c, rec.shards)?;
                return give_up(
                    &mut rec,
                    format!(
                        "round {round}: runs asked for are still not committed after {attempt} array submissions (shard indices {}); see the task logs in slurm/logs/ and the runs table, then `granular submit --missing {}`",
                        ranges(&pending),
                        root.display()
                    ),
                );
            }
            (round, attempt + 1, 0)
        }
    };
    let mut notes = Vec::new();
    let (indices, still) = missing_shards(&c, root, &rec, &mut notes)?;
    for n in &notes {
        tracing::warn!("{n}");
    }
    if indices.is_empty() {
        return give_up(
            &mut rec,
            format!(
                "round {next_round}: the shards with pending runs are all queued or running elsewhere ({}); `granular submit --missing {}` once they end",
                notes.join("; "),
                root.display()
            ),
        );
    }
    let plan = assemble(
        &c,
        &dir,
        rec,
        indices,
        still,
        notes,
        Some((next_round, next_attempt)),
    );
    let plan = submit(root, plan)?;
    Ok(RoundStep::Submitted {
        round: next_round,
        added,
        plan,
    })
}

/// The (0-based) shards of an `n`-shard layout with runs asked for and not finished.
fn pending_shards(c: &Campaign, n: u64) -> Result<Vec<u64>, CampaignError> {
    let finished = ledger::finished_runs(&ledger::read_commits(&c.root)?);
    let set: BTreeSet<u64> = c
        .plan
        .current_runs()
        .filter(|r| !finished.contains_key(&r.run_id))
        .map(|r| r.run_id % n)
        .collect();
    Ok(set.into_iter().collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_compress_consecutive_indices() {
        assert_eq!(ranges(&[0, 1, 2, 3, 4, 7, 9, 10, 11, 12]), "0-4,7,9-12");
        assert_eq!(ranges(&[5]), "5");
        assert_eq!(ranges(&[]), "");
    }

    #[test]
    fn layout_packs_runs_to_respect_max_array_size() {
        assert_eq!(layout(1280, 20, 1001), (64, 20));
        assert_eq!(layout(1281, 20, 1001), (65, 20));
        // 100 000 runs at 20 per task would be 5000 tasks: packed to 100 per task.
        assert_eq!(layout(100_000, 20, 1001), (1000, 100));
        assert_eq!(layout(100_001, 20, 1001), (1001, 100));
        assert_eq!(layout(3, 20, 1001), (1, 20));
        assert!(layout(100_001, 20, 1001).0 <= 1001);
    }

    /// sbatch's reading of an `#SBATCH` argument (`_get_argument`, SLURM 17.11 on): quotes,
    /// backslash escapes (inside quotes too), white space and `#` ending an unquoted argument.
    fn sbatch_reads(line: &str) -> Vec<String> {
        let mut args = Vec::new();
        let mut chars = line.chars().peekable();
        loop {
            while chars.peek().is_some_and(|c| c.is_whitespace()) {
                chars.next();
            }
            if chars.peek().is_none_or(|&c| c == '#') {
                return args;
            }
            let (mut arg, mut quote, mut escape) = (String::new(), None, false);
            while let Some(&c) = chars.peek() {
                if quote.is_none() && c.is_whitespace() {
                    break;
                }
                chars.next();
                if escape {
                    escape = false;
                } else if c == '\\' {
                    escape = true;
                    continue;
                } else if let Some(q) = quote {
                    if c == q {
                        quote = None;
                        continue;
                    }
                } else if c == '"' || c == '\'' {
                    quote = Some(c);
                    continue;
                } else if c == '#' {
                    break;
                }
                arg.push(c);
            }
            assert!(quote.is_none(), "unmatched quote in {line:?}");
            args.push(arg);
        }
    }

    #[test]
    fn sbatch_arguments_are_read_back_unchanged() {
        for s in [
            "--partition=short",
            "--account=a b",
            "--comment=it's \"quoted\" # not a comment",
            "--output=/x/a\\b $(id) `id`; %A",
            ":colon",
            "\ttab",
        ] {
            let line = sbatch_arg(s);
            assert_eq!(sbatch_reads(&line), vec![s.to_string()], "{s:?} as {line}");
        }
        assert_eq!(sbatch_arg("--time=02:00:00"), "--time=02:00:00");
    }

    #[test]
    fn unscriptable_values_are_named() {
        let e = check_value("--partition", "a\nb", true);
        assert!(e.len() == 1 && e[0].contains("--partition \"a\\nb\": contains a line break"));
        assert_eq!(check_value("--sbatch-arg", "x\r", false).len(), 1);
        assert_eq!(check_value("--sbatch-arg", "x\0", false).len(), 1);
        assert!(check_value("--sbatch-arg", "--x=HetJob", true)[0].contains("\"hetjob\""));
        assert!(check_value("the granular binary", "/hetjob/granular", false).is_empty());
        assert!(check_value("--partition", "a b'\"$(x)", true).is_empty());
        let ok = Path::new("/a b/'q'/\"dq\"/$(x)/`y`/;/#/%A");
        assert_eq!(check_dir("--out", ok), Ok(ok.to_str().unwrap()));
        let bad = check_dir("--out", Path::new("/a\\b/PackJob\n")).unwrap_err();
        assert_eq!(bad.len(), 3, "{bad:?}");
        use std::os::unix::ffi::OsStrExt;
        let latin1 = Path::new(std::ffi::OsStr::from_bytes(b"/caf\xe9"));
        assert!(check_dir("DIR", latin1).unwrap_err()[0].contains("not UTF-8"));
    }

    #[test]
    fn job_names_are_plain_words() {
        assert_eq!(job_name("x.y-z_1"), "granular-x_y-z_1");
        assert_eq!(job_name("HetJob-packjobs"), "granular-Het_Job-pack_jobs");
        assert!(check_value("", &job_name("hetjobhetjob"), true).is_empty());
    }

    /// A record written before error targets (no round fields, no outcome) still reads, and
    /// writes back without them.
    #[test]
    fn records_of_earlier_versions_read() {
        let old = r#"{"format_version": 1, "kind": "granular.slurm_submission", "shards": 3,
            "runs_per_shard": 4, "options": {"throttle": 2, "per_task_runs": 4,
            "time": "00:05:00", "partition": null, "sbatch_args": [], "cpus_per_task": 1,
            "checkpoint_every": 300.0, "compact": true}, "binary": "/g",
            "submissions": [{"number": 1, "script": "slurm/array-001.sh", "array": "0-2%2",
            "array_job": "101", "compact_script": "slurm/compact-001.sh",
            "compact_job": "102", "indices": [0, 1, 2]}]}"#;
        let r: SubmissionRecord = serde_json::from_str(old).expect("reads");
        assert_eq!(r.submissions[0].round, None);
        assert_eq!(r.submissions[0].round_job, None);
        assert_eq!(r.outcome, None);
        let back = serde_json::to_string(&r).unwrap();
        assert!(
            !back.contains("round") && !back.contains("outcome"),
            "{back}"
        );
    }

    #[test]
    fn time_limits() {
        for ok in ["30", "90:00", "02:00:00", "1-12", "1-12:30", "2-00:00:00"] {
            assert!(check_time(ok).is_ok(), "{ok}");
        }
        for bad in ["", "2h", "1:2:3:4", "-1", "1-", "a:00"] {
            assert!(check_time(bad).is_err(), "{bad}");
        }
    }
}
