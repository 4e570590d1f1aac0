//! Flags shared by several commands and the parsers that validate every numeric flag when
//! the command line is parsed: a bad value is a clap error (exit 2, the flag named, nothing
//! written), so no command ever sees NaN, an infinity, a negative or an absurd number.

use std::time::Duration;

use clap::Args;

use crate::campaign::plan::Shard;
use crate::exit_codes::{Classed, ExitClass};

/// Default of `--checkpoint-every` (seconds), for `run`, `resume`, `slurm-task` and `submit`.
pub const DEFAULT_CHECKPOINT_EVERY: f64 = 300.0;
/// Default of `--flush-every` (seconds).
pub const DEFAULT_FLUSH_EVERY: f64 = 30.0;
/// Largest accepted number of seconds (about 116 days).
pub const MAX_SECONDS: f64 = 1e7;
/// Largest accepted `--threads` (and `submit --cpus-per-task`).
pub const MAX_THREADS: usize = 1024;
/// `--threads` above this many per available core is clamped (with a warning).
pub const THREADS_PER_CORE: usize = 4;
/// SLURM's largest `MaxArraySize`: bounds `--tasks`, `--shards` and `--index`.
pub const MAX_ARRAY: u64 = 4_000_001;
/// Largest `submit --per-task-runs`.
pub const MAX_PER_TASK_RUNS: u64 = 1_000_000_000;
/// Largest `compact --target-size` (1 TiB).
pub const MAX_TARGET_SIZE: u64 = 1 << 40;

/// Runtime flags of `run` and `resume`.
#[derive(Args, Clone, Debug)]
pub struct Runtime {
    #[command(flatten)]
    pub exec: Execution,
    /// Run only shard I of N (1-based): runs with run_id % N == I - 1.
    #[arg(long, value_name = "I/N", default_value = "1/1", allow_hyphen_values = true,
          value_parser = Shard::parse)]
    pub shard: Shard,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Besides the logs, write the progress to stderr as one JSON object per line, for
    /// programs: {"progress": {"total", "finished", "failed", "running", "fraction"}} (total:
    /// the runs this session plans, anew for each round of error targets; finished: done +
    /// failed of them; fraction: (finished + running runs' fractions) / total, 1 when total is
    /// 0). A line at the plan, at each finished run, at most every 0.25 s while runs progress,
    /// and a last one at the end. No progress bar is drawn.
    #[arg(long)]
    pub progress_json: bool,
}

/// How a shard is executed: flags of `run`, `resume` and the hidden `slurm-task`.
#[derive(Args, Clone, Debug)]
pub struct Execution {
    /// Worker threads (0 = all cores, the default of run and resume; at most 1024; more than 4
    /// per available core are reduced to that).
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = threads)]
    pub threads: Option<usize>,
    #[command(flatten)]
    pub checkpoint: CheckpointEvery,
    /// Seconds between commits of finished runs to the tables (0 = at once; at most 1e7).
    #[arg(long, value_name = "SECONDS", default_value_t = DEFAULT_FLUSH_EVERY,
          allow_hyphen_values = true, value_parser = flush_seconds)]
    pub flush_every: f64,
    /// Keep no final states of finished runs (`finals/`): a longer `t_end` then runs them again
    /// from t = 0 instead of continuing them.
    #[arg(long)]
    pub no_final_states: bool,
}

/// `--checkpoint-every`, the one declaration for every command that has it.
#[derive(Args, Clone, Debug)]
pub struct CheckpointEvery {
    #[arg(long = "checkpoint-every", value_name = "SECONDS", allow_hyphen_values = true,
          value_parser = checkpoint_seconds, help = checkpoint_help())]
    pub given: Option<f64>,
}

fn checkpoint_help() -> String {
    format!(
        "Seconds between checkpoints of each running simulation (> 0, at most 1e7; default \
         {DEFAULT_CHECKPOINT_EVERY})"
    )
}

impl CheckpointEvery {
    /// The value given, or the default.
    pub fn seconds(&self) -> f64 {
        self.given.unwrap_or(DEFAULT_CHECKPOINT_EVERY)
    }
}

impl Execution {
    /// The worker thread count to ask the library for: `--threads` (or `default`), reduced
    /// to `THREADS_PER_CORE` per available core with a warning; 0 stays 0 (all cores).
    pub fn threads(&self, default: usize) -> usize {
        let asked = self.threads.unwrap_or(default);
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let most = cores.saturating_mul(THREADS_PER_CORE).min(MAX_THREADS);
        if asked > most {
            tracing::warn!(
                "--threads {asked}: more than {THREADS_PER_CORE} per available core ({cores}); using {most}"
            );
            return most;
        }
        asked
    }

    pub fn checkpoint_every(&self) -> Duration {
        duration(self.checkpoint.seconds())
    }

    pub fn flush_every(&self) -> Duration {
        duration(self.flush_every)
    }
}

/// A parsed number of seconds (finite, >= 0, <= `MAX_SECONDS`) as a `Duration`.
fn duration(seconds: f64) -> Duration {
    Duration::try_from_secs_f64(seconds.clamp(0.0, MAX_SECONDS)).unwrap_or(Duration::ZERO)
}

/// A flag's value that is not what it should be (clap prints it with the flag's name): invalid
/// input.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct FlagError(pub String);

impl Classed for FlagError {
    fn class(&self) -> ExitClass {
        ExitClass::InvalidInput
    }
}

/// A float in a range; `what` says what was expected.
fn float_in(s: &str, ok: impl Fn(f64) -> bool, what: &str) -> Result<f64, FlagError> {
    match s.parse::<f64>() {
        Ok(x) if x.is_finite() && ok(x) => Ok(x),
        _ => Err(FlagError(format!("expected {what}"))),
    }
}

/// An unsigned integer in `lo..=hi`; `what` says what it counts.
fn int_in(s: &str, lo: u64, hi: u64, what: &str) -> Result<u64, FlagError> {
    match s.parse::<u64>() {
        Ok(x) if (lo..=hi).contains(&x) => Ok(x),
        _ => Err(FlagError(format!(
            "expected {what}, an integer from {lo} to {hi}"
        ))),
    }
}

/// `--checkpoint-every`: seconds, > 0 and <= 1e7.
pub fn checkpoint_seconds(s: &str) -> Result<f64, FlagError> {
    float_in(
        s,
        |x| x > 0.0 && x <= MAX_SECONDS,
        "a number of seconds > 0 and <= 1e7",
    )
}

/// `--flush-every`: seconds, >= 0 (0 = commit every finished run at once) and <= 1e7.
pub fn flush_seconds(s: &str) -> Result<f64, FlagError> {
    float_in(
        s,
        |x| (0.0..=MAX_SECONDS).contains(&x),
        "a number of seconds from 0 to 1e7",
    )
}

/// `--threads`: 0 (all cores) to 1024.
pub fn threads(s: &str) -> Result<usize, FlagError> {
    int_in(s, 0, MAX_THREADS as u64, "worker threads (0 = all cores)").map(|n| n as usize)
}

/// `submit --cpus-per-task`: 1 to 1024.
pub fn cpus(s: &str) -> Result<u32, FlagError> {
    int_in(s, 1, MAX_THREADS as u64, "CPUs per task").map(|n| n as u32)
}

/// `submit --tasks`: 1 to SLURM's largest array.
pub fn tasks(s: &str) -> Result<u32, FlagError> {
    int_in(s, 1, MAX_ARRAY, "a number of array tasks").map(|n| n as u32)
}

/// `slurm-task --shards`: 1 to SLURM's largest array.
pub fn shards(s: &str) -> Result<u32, FlagError> {
    int_in(s, 1, MAX_ARRAY, "a number of shards").map(|n| n as u32)
}

/// `slurm-task --index`: 0 to SLURM's largest array index.
pub fn array_index(s: &str) -> Result<u32, FlagError> {
    int_in(s, 0, MAX_ARRAY - 1, "an array index").map(|n| n as u32)
}

/// `submit --per-task-runs`: 1 to 1e9.
pub fn per_task_runs(s: &str) -> Result<u64, FlagError> {
    int_in(s, 1, MAX_PER_TASK_RUNS, "runs per task")
}

/// `submit --time`: a SLURM time limit (the library's check and message).
pub fn slurm_time(s: &str) -> Result<String, FlagError> {
    crate::campaign::slurm::check_time(s)
        .map(|()| s.to_string())
        .map_err(|e| FlagError(e.to_string()))
}

/// `analyze --n-min`: 0 to 1e9 particles.
pub fn n_min(s: &str) -> Result<f64, FlagError> {
    float_in(
        s,
        |x| (0.0..=1e9).contains(&x),
        "a particle number from 0 to 1e9",
    )
}

/// `analyze --count-error-factor`: > 0 and <= 100.
pub fn count_error_factor(s: &str) -> Result<f64, FlagError> {
    float_in(s, |x| x > 0.0 && x <= 100.0, "a factor > 0 and <= 100")
}

/// `analyze --chi2-accept`: > 0 and <= 1000.
pub fn chi2_accept(s: &str) -> Result<f64, FlagError> {
    float_in(
        s,
        |x| x > 0.0 && x <= 1000.0,
        "a reduced chi^2 > 0 and <= 1000",
    )
}

/// `analyze --fixed-df`: a fractal dimension > 0 and <= 2.
pub fn fixed_df(s: &str) -> Result<f64, FlagError> {
    float_in(
        s,
        |x| x > 0.0 && x <= 2.0,
        "a fractal dimension > 0 and <= 2",
    )
}

/// `compact --target-size`: `100MB`, `1GB`, `500kB`, `4096` (bytes; powers of 1024), from 1 B
/// to 1 TiB.
pub fn size(s: &str) -> Result<u64, FlagError> {
    let t = s.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let x: f64 = num
        .parse()
        .map_err(|_| FlagError(format!("{s:?}: expected a size such as 100MB")))?;
    let mult = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1u64,
        "k" | "kb" | "kib" => 1 << 10,
        "m" | "mb" | "mib" => 1 << 20,
        "g" | "gb" | "gib" => 1 << 30,
        u => {
            return Err(FlagError(format!(
                "{s:?}: unknown unit {u:?} (use B, kB, MB or GB)"
            )))
        }
    };
    let bytes = x * mult as f64;
    if !(bytes.is_finite() && bytes <= MAX_TARGET_SIZE as f64) {
        return Err(FlagError(format!("{s:?}: expected at most 1 TiB (1024GB)")));
    }
    let v = bytes as u64;
    if v == 0 {
        return Err(FlagError(format!("{s:?}: must be positive")));
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    const BAD_NUMBERS: [&str; 7] = [
        "nan",
        "inf",
        "-inf",
        "-1",
        "1e300",
        "18446744073709551616",
        "abc",
    ];

    #[test]
    fn every_parser_refuses_non_finite_negative_and_huge_values() {
        for s in BAD_NUMBERS {
            assert!(checkpoint_seconds(s).is_err(), "{s}");
            assert!(flush_seconds(s).is_err(), "{s}");
            assert!(threads(s).is_err(), "{s}");
            assert!(cpus(s).is_err(), "{s}");
            assert!(tasks(s).is_err(), "{s}");
            assert!(shards(s).is_err(), "{s}");
            assert!(array_index(s).is_err(), "{s}");
            assert!(per_task_runs(s).is_err(), "{s}");
            assert!(slurm_time(s).is_err(), "{s}");
            assert!(n_min(s).is_err(), "{s}");
            assert!(count_error_factor(s).is_err(), "{s}");
            assert!(chi2_accept(s).is_err(), "{s}");
            assert!(fixed_df(s).is_err(), "{s}");
            assert!(size(s).is_err(), "{s}");
        }
    }

    #[test]
    fn bounds() {
        assert!(checkpoint_seconds("0").is_err());
        assert_eq!(checkpoint_seconds("0.5"), Ok(0.5));
        assert_eq!(checkpoint_seconds("1e7"), Ok(1e7));
        assert!(checkpoint_seconds("1.0000001e7").is_err());
        assert_eq!(flush_seconds("0"), Ok(0.0));
        assert_eq!(threads("0"), Ok(0));
        assert_eq!(threads("1024"), Ok(1024));
        assert!(threads("1025").is_err());
        assert!(cpus("0").is_err());
        assert!(tasks("0").is_err());
        assert!(shards("0").is_err());
        assert_eq!(array_index("0"), Ok(0));
        assert_eq!(tasks("4000001"), Ok(4_000_001));
        assert!(shards("4000002").is_err());
        assert!(per_task_runs("0").is_err());
        assert!(fixed_df("2.5").is_err());
        assert_eq!(fixed_df("1.63"), Ok(1.63));
        assert_eq!(n_min("0"), Ok(0.0));
        assert_eq!(size("100MB"), Ok(100 << 20));
        assert_eq!(size("1024GB"), Ok(1 << 40));
        assert!(size("1025GB").is_err());
        assert!(size("0.1").is_err());
        assert!(size("0").is_err());
        assert_eq!(slurm_time("02:00:00"), Ok("02:00:00".into()));
        assert!(slurm_time("2h").is_err());
    }

    #[test]
    fn durations_never_panic() {
        for x in [0.0, 1e-300, 0.1, DEFAULT_CHECKPOINT_EVERY, MAX_SECONDS] {
            assert_eq!(duration(x), Duration::from_secs_f64(x));
        }
        assert_eq!(duration(f64::NAN), Duration::ZERO);
        assert_eq!(duration(-1.0), Duration::ZERO);
    }
}
