//! The command line: parses arguments, calls the library, reports. The only layer that
//! prints.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::Arc;
use std::time::Duration;

use clap::{Args, Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};

use crate::campaign::ledger::RunStatus;
use crate::campaign::plan::Shard;
use crate::campaign::{self, Campaign, CampaignError, Event, Outcome, Reporter, RunOptions};
use crate::exit_codes;

#[derive(Parser)]
#[command(
    name = "granular",
    version,
    about = "Ensembles of granular-gas simulations into Parquet tables"
)]
struct Cli {
    /// Log format on stderr.
    #[arg(long, value_enum, default_value_t = LogFormat::Text, global = true)]
    log_format: LogFormat,
    #[command(subcommand)]
    command: Command,
}

#[derive(Clone, Copy, ValueEnum)]
enum LogFormat {
    Text,
    Json,
}

#[derive(Subcommand)]
enum Command {
    /// Check a manifest; print every error with its JSON path (exit 2 if any).
    Validate { manifest: PathBuf },
    /// Run a campaign into a directory (continues it if the directory holds the same one).
    Run {
        manifest: PathBuf,
        /// Campaign directory.
        #[arg(long)]
        out: PathBuf,
        #[command(flatten)]
        runtime: Runtime,
    },
    /// Continue a campaign; finished runs are never redone.
    Resume {
        dir: PathBuf,
        #[command(flatten)]
        runtime: Runtime,
    },
    /// Done / running / pending / failed runs, per point, across all shards.
    Status {
        dir: PathBuf,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// Print the manifest's JSON Schema (also committed as schemas/manifest.schema.json).
    Schema,
    /// Write the kinetic-theory predictions of a manifest (tables dsmc_theory and
    /// dsmc_theory_point) into a campaign directory, without simulating.
    Theory {
        manifest: PathBuf,
        #[arg(long)]
        out: PathBuf,
    },
    /// Run a campaign as a SLURM job array (array task i = shard i+1 of N), with a
    /// compaction job chained by afterok; or resubmit its unfinished shards (`--missing DIR`).
    Submit {
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
        /// Array tasks running at once (the array's % throttle).
        #[arg(long)]
        tasks: Option<u32>,
        /// Runs per array task (more are packed per task if the array would exceed
        /// the cluster's MaxArraySize).
        #[arg(long)]
        per_task_runs: Option<u64>,
        /// Time limit of each task, e.g. 02:00:00.
        #[arg(long)]
        time: Option<String>,
        #[arg(long)]
        partition: Option<String>,
        /// Extra #SBATCH argument (repeatable), e.g. --sbatch-arg=--account=abc.
        #[arg(long = "sbatch-arg", allow_hyphen_values = true)]
        sbatch_arg: Vec<String>,
        /// Worker threads per task (--cpus-per-task).
        #[arg(long)]
        cpus_per_task: Option<u32>,
        /// Seconds between checkpoints of each running simulation in a task (default 300).
        #[arg(long)]
        checkpoint_every: Option<f64>,
        /// No compaction job after the array.
        #[arg(long)]
        no_compact: bool,
        /// Print the scripts and the sbatch commands; write and submit nothing.
        #[arg(long)]
        dry_run: bool,
    },
    /// Run one SLURM array task (used by the scripts `granular submit` writes).
    #[command(hide = true)]
    SlurmTask {
        dir: PathBuf,
        #[arg(long)]
        shards: u32,
        #[arg(long, default_value_t = 1)]
        threads: usize,
        #[arg(long, default_value_t = 300.0)]
        checkpoint_every: f64,
        /// Array index (default: $SLURM_ARRAY_TASK_ID).
        #[arg(long)]
        index: Option<u32>,
    },
    /// Merge a campaign's small Parquet parts into large files (readers never see missing or
    /// doubled rows) and fold its commit records into one ledger index.
    Compact {
        dir: PathBuf,
        /// Size of a merged file, e.g. 100MB, 1GB, 500kB.
        #[arg(long, default_value = "100MB", value_parser = parse_size)]
        target_size: u64,
    },
    /// Check every table file of a campaign (readable, this campaign's, right table and
    /// format) and that the runs table holds each committed run exactly once.
    Verify { dir: PathBuf },
    /// Draw the standard figures (PNG and SVG) of a campaign's summary tables.
    Plot {
        dir: PathBuf,
        /// Where to write the figures (default: DIR/figures).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Fit the thesis's observables of an rfm campaign (xi_m, zeta_m, D_f, alpha, (5.32),
    /// (4.25), ...) into the table analysis_fits, the figure data analysis_curves and figures.
    /// Uses the finished runs (warns if some are missing).
    Analyze {
        dir: PathBuf,
        /// Where to write analysis_fits.parquet, analysis_curves.parquet and figures/
        /// (default: DIR/analysis).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Smallest N of the velocity-moment exponent fits across N (the thesis drops N < 398).
        #[arg(long, default_value_t = 398.0)]
        n_min: f64,
        /// Count errors s = FACTOR sqrt(X) in the alpha windows (2 for the thesis's dagger entries).
        #[arg(long, default_value_t = 1.0)]
        count_error_factor: f64,
        /// Accept alpha when the reduced chi^2 is below this.
        #[arg(long, default_value_t = 1.2)]
        chi2_accept: f64,
        /// D_f of the fixed-D_f free-path fit (4.25).
        #[arg(long, default_value_t = 1.63)]
        fixed_df: f64,
        /// Write the tables only.
        #[arg(long)]
        no_figures: bool,
    },
}

#[derive(Args, Clone)]
struct Runtime {
    /// Worker threads (default: all cores).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Seconds between checkpoints of a running simulation.
    #[arg(long, default_value_t = 300.0)]
    checkpoint_every: f64,
    /// Run only shard I of N (1-based): runs with run_id % N == I - 1.
    #[arg(long, default_value = "1/1", value_parser = Shard::parse)]
    shard: Shard,
    /// Seconds between commits of finished runs to the tables.
    #[arg(long, default_value_t = 30.0)]
    flush_every: f64,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

pub fn main() -> i32 {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() {
                exit_codes::INVALID_INPUT
            } else {
                exit_codes::OK
            };
        }
    };
    init_tracing(cli.log_format);
    match cli.command {
        Command::Validate { manifest } => match crate::campaign::plan::load(&manifest) {
            Ok((m, plan)) => {
                println!(
                    "{}: valid: campaign {:?}, model {}, {} points x {} replicas = {} runs",
                    manifest.display(),
                    m.name,
                    m.model.as_str(),
                    plan.points.len(),
                    plan.replicas,
                    plan.n_runs()
                );
                exit_codes::OK
            }
            Err(e) => {
                eprint!("{e}");
                exit_codes::INVALID_INPUT
            }
        },
        Command::Theory { manifest, out } => match Campaign::create_or_open(&manifest, &out) {
            Ok(c) => match c.write_theory() {
                Ok(false) => {
                    eprintln!(
                        "error: model {} has no kinetic-theory tables",
                        c.plan.model.as_str()
                    );
                    exit_codes::INVALID_INPUT
                }
                Ok(true) => {
                    println!(
                        "wrote {}/tables/dsmc_theory and dsmc_theory_point ({} points)",
                        out.display(),
                        c.plan.points.len()
                    );
                    exit_codes::OK
                }
                Err(e) => {
                    eprintln!("error: {e}");
                    exit_codes::IO_ERROR
                }
            },
            Err(e) => report_error(e),
        },
        Command::Plot { dir, out } => match Campaign::open(&dir) {
            Ok(c) => {
                let out = out.unwrap_or_else(|| dir.join("figures"));
                match c.figures().map_err(|e| e.to_string()) {
                    Ok(None) => {
                        eprintln!(
                            "error: `granular plot` draws no figures of model {} (see `granular analyze`)",
                            c.plan.model.as_str()
                        );
                        return exit_codes::INVALID_INPUT;
                    }
                    Ok(Some(figs)) => match crate::plot::render(&figs, &out) {
                        Ok((files, failed)) => {
                            for f in failed {
                                tracing::warn!("{f}");
                            }
                            println!("wrote {} files to {}", files.len(), out.display());
                            exit_codes::OK
                        }
                        Err(e) => {
                            eprintln!("error: {e}");
                            exit_codes::IO_ERROR
                        }
                    },
                    Err(e) => {
                        eprintln!("error: {e}");
                        exit_codes::IO_ERROR
                    }
                }
            }
            Err(e) => report_error(e),
        },
        Command::Submit {
            target,
            out,
            missing,
            slurm: _,
            tasks,
            per_task_runs,
            time,
            partition,
            sbatch_arg,
            cpus_per_task,
            checkpoint_every,
            no_compact,
            dry_run,
        } => submit_command(SubmitArgs {
            target,
            out,
            missing,
            tasks,
            per_task_runs,
            time,
            partition,
            sbatch_arg,
            cpus_per_task,
            checkpoint_every,
            no_compact,
            dry_run,
        }),
        Command::SlurmTask {
            dir,
            shards,
            threads,
            checkpoint_every,
            index,
        } => {
            let index = match index.or_else(|| {
                std::env::var("SLURM_ARRAY_TASK_ID")
                    .ok()
                    .and_then(|v| v.parse().ok())
            }) {
                Some(i) if i < shards => i,
                other => {
                    eprintln!("error: slurm-task needs an array index below --shards {shards} (--index or SLURM_ARRAY_TASK_ID), got {other:?}");
                    return exit_codes::INVALID_INPUT;
                }
            };
            match Campaign::open(&dir) {
                Ok(c) => {
                    let rt = Runtime {
                        threads,
                        checkpoint_every,
                        shard: Shard {
                            index: index + 1,
                            count: shards,
                        },
                        flush_every: 30.0,
                        quiet: true,
                    };
                    match execute(&c, &rt) {
                        // Failed runs are finished runs (recorded in the runs table): the task
                        // succeeded, so the afterok compaction still runs.
                        exit_codes::RUNS_FAILED => exit_codes::OK,
                        code => code,
                    }
                }
                Err(e) => report_error(e),
            }
        }
        Command::Compact { dir, target_size } => match Campaign::open(&dir) {
            Ok(c) => {
                let opts = campaign::compact::CompactOptions {
                    target_bytes: target_size,
                };
                match campaign::compact::compact(&c, &opts) {
                    Ok(r) => {
                        for n in &r.notes {
                            tracing::warn!("{n}");
                        }
                        for t in &r.tables {
                            println!(
                                "{:<34} {:>6} -> {:>4} files  {:>10} rows  {:>12} -> {:>12} bytes  generation {}",
                                t.table, t.files_before, t.files_after, t.rows, t.bytes_before, t.bytes_after, t.generation
                            );
                        }
                        println!(
                            "ledger: {} commit record(s) folded into ledger/index.json",
                            r.commits_folded
                        );
                        exit_codes::OK
                    }
                    Err(e) => report_error(e),
                }
            }
            Err(e) => report_error(e),
        },
        Command::Verify { dir } => match Campaign::open(&dir) {
            Ok(c) => match campaign::verify::verify(&c) {
                Ok(r) => {
                    for (t, files, rows) in &r.tables {
                        println!("{t:<34} {files:>6} files {rows:>12} rows");
                    }
                    for p in &r.problems {
                        eprintln!("error: {p}");
                    }
                    if r.problems.is_empty() {
                        println!("{}: all table files check out; {} committed runs, each once in the runs table", dir.display(), r.committed_runs);
                        exit_codes::OK
                    } else {
                        eprintln!("{}: {} problem(s)", dir.display(), r.problems.len());
                        exit_codes::DIRECTORY_REFUSED
                    }
                }
                Err(e) => {
                    eprintln!("error: {e}");
                    exit_codes::DIRECTORY_REFUSED
                }
            },
            Err(e) => report_error(e),
        },
        Command::Analyze {
            dir,
            out,
            n_min,
            count_error_factor,
            chi2_accept,
            fixed_df,
            no_figures,
        } => match Campaign::open(&dir) {
            Ok(c) => {
                let out = out.unwrap_or_else(|| dir.join("analysis"));
                let opts = crate::analysis::Options {
                    n_min,
                    count_error_factor,
                    chi2_accept,
                    fixed_df,
                    figures: !no_figures,
                };
                analyze(&c, &out, &opts)
            }
            Err(e) => report_error(e),
        },
        Command::Schema => {
            println!(
                "{}",
                serde_json::to_string_pretty(&crate::manifest::json_schema()).expect("schema")
            );
            exit_codes::OK
        }
        Command::Run {
            manifest,
            out,
            runtime,
        } => match Campaign::create_or_open(&manifest, &out) {
            Ok(c) => execute(&c, &runtime),
            Err(e) => report_error(e),
        },
        Command::Resume { dir, runtime } => match Campaign::open(&dir) {
            Ok(c) => execute(&c, &runtime),
            Err(e) => report_error(e),
        },
        Command::Status { dir, json } => match Campaign::open(&dir) {
            Ok(c) => match campaign::status::status(&c) {
                Ok(s) => {
                    // Write errors (a closed pipe, `| head`) are not worth a panic.
                    use std::io::Write;
                    let mut out = std::io::stdout().lock();
                    if json {
                        let _ =
                            writeln!(out, "{}", serde_json::to_string_pretty(&s).expect("status"));
                    } else {
                        let _ = writeln!(
                            out,
                            "{}: {} runs: {} done, {} failed, {} running, {} pending ({} with checkpoints)",
                            s.name, s.runs, s.counts.done, s.counts.failed, s.counts.running, s.counts.pending, s.counts.checkpointed
                        );
                        for l in &s.live_shards {
                            let _ = writeln!(out, "  live shard {l}");
                        }
                        for sub in &s.slurm {
                            let queue = match &sub.queue {
                                Some(q) if q.is_empty() => "nothing queued".to_string(),
                                Some(q) => q
                                    .iter()
                                    .map(|(k, n)| format!("{k}: {n}"))
                                    .collect::<Vec<_>>()
                                    .join(", "),
                                None => "squeue not available".to_string(),
                            };
                            let _ = writeln!(
                                out,
                                "  slurm submission {}: array {} job {}, compaction job {} ({queue})",
                                sub.number,
                                sub.array,
                                sub.array_job.as_deref().unwrap_or("-"),
                                sub.compact_job.as_deref().unwrap_or("-")
                            );
                        }
                        for p in &s.points {
                            let _ = writeln!(
                                out,
                                "  point {:>4} {:<40} done {:>3}  failed {:>3}  running {:>3}  pending {:>3}",
                                p.point_id, p.point, p.counts.done, p.counts.failed, p.counts.running, p.counts.pending
                            );
                        }
                    }
                    exit_codes::OK
                }
                Err(e) => {
                    eprintln!("error: {e}");
                    exit_codes::DIRECTORY_REFUSED
                }
            },
            Err(e) => report_error(e),
        },
    }
}

fn analyze(c: &Campaign, out: &std::path::Path, opts: &crate::analysis::Options) -> i32 {
    use crate::analysis::AnalysisError;
    match crate::analysis::analyze(c, out, opts) {
        Ok(r) => {
            use std::io::Write;
            let mut o = std::io::stdout().lock();
            let _ = writeln!(
                o,
                "{}: {} fits from {} of {} runs; {} files in {}",
                c.manifest.name,
                r.fits.len(),
                r.runs_done,
                r.runs_total,
                r.files.len(),
                out.display()
            );
            for f in &r.fits {
                let err = f.error.map_or("".into(), |e| format!(" +- {e:.4}"));
                let chi = f
                    .chi2_reduced
                    .map_or("".into(), |x| format!("  chi2_r {x:.2}"));
                let reference = f
                    .reference
                    .map_or("".into(), |x| format!("  (reference {x:.4})"));
                let _ = writeln!(
                    o,
                    "  {:<22} {:<40} {:>10.4}{err}{chi}  n {}{reference}",
                    f.quantity, f.key, f.value, f.n_points
                );
            }
            exit_codes::OK
        }
        Err(AnalysisError::NotAnalysable(m)) => {
            eprintln!("error: {m}");
            exit_codes::DIRECTORY_REFUSED
        }
        Err(e) => {
            eprintln!("error: {e}");
            exit_codes::IO_ERROR
        }
    }
}

fn init_tracing(format: LogFormat) {
    let filter = tracing_subscriber::EnvFilter::try_from_env("GRANULAR_LOG")
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .with_ansi(ansi);
    let _ = match format {
        LogFormat::Text => builder.try_init(),
        LogFormat::Json => builder.json().try_init(),
    };
}

fn report_error(e: CampaignError) -> i32 {
    match e {
        CampaignError::Manifest(m) => {
            eprint!("{m}");
            exit_codes::INVALID_INPUT
        }
        CampaignError::Refused(m) => {
            eprintln!("error: {m}");
            exit_codes::DIRECTORY_REFUSED
        }
        CampaignError::Io(m) => {
            eprintln!("error: {m}");
            exit_codes::IO_ERROR
        }
        CampaignError::TooLarge(m) => {
            eprintln!("error: {m}");
            exit_codes::INVALID_INPUT
        }
    }
}

fn execute(c: &Campaign, rt: &Runtime) -> i32 {
    let interrupt = Arc::new(AtomicU8::new(0));
    {
        let flag = interrupt.clone();
        let _ = ctrlc::set_handler(move || {
            let n = flag.fetch_add(1, Ordering::SeqCst) + 1;
            if n >= 2 {
                eprintln!(
                    "\ninterrupted twice: exiting now (work since the last checkpoints is lost)"
                );
                std::process::exit(exit_codes::INTERRUPTED);
            }
            eprintln!("\ninterrupt: checkpointing running simulations and stopping (press Ctrl-C again to exit at once)");
        });
    }
    let opts = RunOptions {
        threads: rt.threads,
        checkpoint_every: Duration::from_secs_f64(rt.checkpoint_every.max(0.0)),
        shard: rt.shard,
        interrupt,
        flush_every: Duration::from_secs_f64(rt.flush_every.max(0.0)),
    };
    tracing::info!(campaign = %c.manifest.name, dir = %c.root.display(), shard = %rt.shard, "starting");
    let mut reporter = CliReporter::new(rt.quiet);
    let result = campaign::dispatch::run(c, &opts, &mut reporter);
    reporter.finish();
    match result {
        Ok(o) => summarise(c, &o),
        Err(e) => report_error(e),
    }
}

fn summarise(c: &Campaign, o: &Outcome) -> i32 {
    tracing::info!(
        done = o.done,
        failed = o.failed,
        remaining = o.remaining,
        complete = o.complete,
        "stopped"
    );
    if o.interrupted {
        eprintln!(
            "stopped with {} runs of this shard left; continue with: granular resume {}",
            o.remaining,
            c.root.display()
        );
        return exit_codes::INTERRUPTED;
    }
    if o.failed_in_shard > 0 {
        eprintln!(
            "{} run(s) failed; see the runs table (status = 'failed') for their reasons",
            o.failed_in_shard
        );
        return exit_codes::RUNS_FAILED;
    }
    exit_codes::OK
}

struct CliReporter {
    bar: Option<ProgressBar>,
    running: std::collections::BTreeMap<u64, f64>,
    finished: u64,
}

impl CliReporter {
    fn new(quiet: bool) -> Self {
        let bar = if quiet || !std::io::IsTerminal::is_terminal(&std::io::stderr()) {
            None
        } else {
            let b = ProgressBar::new(0);
            b.set_style(
                ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} runs ({percent}%) eta {eta} {msg}")
                    .expect("template"),
            );
            b.enable_steady_tick(Duration::from_millis(200));
            Some(b)
        };
        CliReporter {
            bar,
            running: Default::default(),
            finished: 0,
        }
    }

    fn update(&mut self) {
        if let Some(b) = &self.bar {
            let partial: f64 = self.running.values().sum();
            // Position in thousandths of runs so running work shows.
            b.set_position(self.finished * 1000 + (partial * 1000.0) as u64);
            b.set_message(format!("{} running", self.running.len()));
        }
    }

    fn finish(&mut self) {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
    }
}

impl Reporter for CliReporter {
    fn event(&mut self, e: &Event) {
        match e {
            Event::Plan {
                total,
                already,
                pending,
            } => {
                tracing::info!(total, already_finished = already, pending, "shard plan");
                if let Some(b) = &self.bar {
                    b.set_length(pending * 1000);
                    b.set_style(
                        ProgressStyle::with_template(
                            "{spinner} [{elapsed_precise}] {bar:40} {percent}% eta {eta} {msg}",
                        )
                        .expect("template"),
                    );
                }
            }
            Event::Started {
                run_id,
                resumed_from,
            } => {
                tracing::debug!(run_id, ?resumed_from, "run started");
                self.running.insert(*run_id, 0.0);
            }
            Event::Progress { run_id, fraction } => {
                self.running.insert(*run_id, *fraction);
            }
            Event::Checkpointed { run_id, t } => tracing::debug!(run_id, t, "checkpoint written"),
            Event::Finished {
                run_id,
                seed,
                status,
                reason,
                t,
                wall_seconds,
            } => {
                self.running.remove(run_id);
                self.finished += 1;
                match status {
                    RunStatus::Done => tracing::debug!(run_id, wall_seconds, "run done"),
                    RunStatus::Failed => {
                        let msg = format!(
                            "run {run_id} (seed {seed}) failed at t = {t}: {}",
                            reason.as_deref().unwrap_or("")
                        );
                        match &self.bar {
                            Some(b) => b.suspend(|| tracing::error!("{msg}")),
                            None => tracing::error!("{msg}"),
                        }
                    }
                }
            }
            Event::Interrupted { run_id } => {
                self.running.remove(run_id);
                tracing::info!(run_id, "run checkpointed and stopped");
            }
            Event::Committed { runs, seq } => tracing::debug!(runs, seq, "committed"),
            Event::Warning { message } => match &self.bar {
                Some(b) => b.suspend(|| tracing::warn!("{message}")),
                None => tracing::warn!("{message}"),
            },
        }
        self.update();
    }
}

/// `100MB`, `1GB`, `500kB`, `4096` (bytes; powers of 1024).
fn parse_size(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let x: f64 = num
        .parse()
        .map_err(|_| format!("{s:?}: expected a size such as 100MB"))?;
    let mult = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1u64,
        "k" | "kb" | "kib" => 1 << 10,
        "m" | "mb" | "mib" => 1 << 20,
        "g" | "gb" | "gib" => 1 << 30,
        u => return Err(format!("{s:?}: unknown unit {u:?} (use B, kB, MB or GB)")),
    };
    let v = (x * mult as f64) as u64;
    if v == 0 {
        return Err(format!("{s:?}: must be positive"));
    }
    Ok(v)
}

struct SubmitArgs {
    target: PathBuf,
    out: Option<PathBuf>,
    missing: bool,
    tasks: Option<u32>,
    per_task_runs: Option<u64>,
    time: Option<String>,
    partition: Option<String>,
    sbatch_arg: Vec<String>,
    cpus_per_task: Option<u32>,
    checkpoint_every: Option<f64>,
    no_compact: bool,
    dry_run: bool,
}

fn submit_command(a: SubmitArgs) -> i32 {
    use campaign::slurm;
    let invalid = |m: String| {
        eprintln!("error: {m}");
        exit_codes::INVALID_INPUT
    };
    if let Some(t) = &a.time {
        if let Err(e) = slurm::check_time(t) {
            return invalid(e);
        }
    }
    if let Some(x) = a.checkpoint_every {
        if !(x.is_finite() && x > 0.0) {
            return invalid(format!(
                "--checkpoint-every {x}: expected a positive number of seconds"
            ));
        }
    }
    let binary = match std::env::current_exe().and_then(|p| p.canonicalize()) {
        Ok(p) => p.display().to_string(),
        Err(e) => return invalid(format!("cannot locate the granular binary: {e}")),
    };
    // The campaign (created unless --dry-run) and its absolute directory.
    let (c, root) = if a.missing {
        if a.out.is_some() {
            return invalid(
                "--missing takes the campaign directory as its argument, not --out".into(),
            );
        }
        match Campaign::open(&a.target) {
            Ok(c) => {
                let root = a.target.canonicalize().unwrap_or(a.target.clone());
                (c, root)
            }
            Err(e) => return report_error(e),
        }
    } else {
        let Some(out) = a.out.clone() else {
            return invalid("a first submission needs --out DIR (or use --missing DIR)".into());
        };
        let mut missing_flags = Vec::new();
        if a.time.is_none() {
            missing_flags.push("--time");
        }
        if a.tasks.is_none() {
            missing_flags.push("--tasks");
        }
        if a.per_task_runs.is_none() {
            missing_flags.push("--per-task-runs");
        }
        if !missing_flags.is_empty() {
            return invalid(format!(
                "a first submission needs {}",
                missing_flags.join(", ")
            ));
        }
        if a.dry_run {
            match crate::campaign::plan::load(&a.target) {
                Ok((manifest, plan)) => {
                    let value = serde_json::to_value(&manifest).expect("manifest serialises");
                    let c = Campaign {
                        root: out.clone(),
                        manifest,
                        plan,
                        manifest_json: crate::campaign::plan::canonical(&value),
                    };
                    let root = std::path::absolute(&out).unwrap_or(out);
                    (c, root)
                }
                Err(e) => return report_error(CampaignError::Manifest(e)),
            }
        } else {
            match Campaign::create_or_open(&a.target, &out) {
                Ok(c) => {
                    let root = out.canonicalize().unwrap_or(out);
                    (c, root)
                }
                Err(e) => return report_error(e),
            }
        }
    };
    let previous = match slurm::read_record(&root) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: {e}");
            return exit_codes::DIRECTORY_REFUSED;
        }
    };
    let base = previous.as_ref().map(|r| r.options.clone());
    let options = if a.missing && base.is_some() {
        let mut o = base.clone().expect("options");
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
        if let Some(x) = a.checkpoint_every {
            o.checkpoint_every = x;
        }
        if a.no_compact {
            o.compact = false;
        }
        Some(o)
    } else if a.missing {
        None
    } else {
        Some(slurm::SlurmOptions {
            throttle: a.tasks.unwrap_or(1),
            per_task_runs: a.per_task_runs.unwrap_or(1),
            time: a.time.clone().unwrap_or_default(),
            partition: a.partition.clone(),
            sbatch_args: a.sbatch_arg.clone(),
            cpus_per_task: a.cpus_per_task.unwrap_or(1),
            checkpoint_every: a.checkpoint_every.unwrap_or(300.0),
            compact: !a.no_compact,
        })
    };
    let (max_array, note) = slurm::max_array_size();
    if let Some(n) = note {
        tracing::info!("{n}");
    }
    let plan = match slurm::plan(&c, &root, options, a.missing, &binary, max_array) {
        Ok(p) => p,
        Err(e) => return report_error(e),
    };
    for n in &plan.notes {
        tracing::warn!("{n}");
    }
    let sub = plan.record.submissions.last().cloned().expect("submission");
    if plan.indices.is_empty() {
        println!(
            "{}: nothing to submit: every shard is finished, queued or running",
            root.display()
        );
        return exit_codes::OK;
    }
    if a.dry_run {
        println!(
            "# {} (would be written to {})",
            sub.script,
            root.join(&sub.script).display()
        );
        print!("{}", plan.script);
        if let (Some(rel), Some(text)) = (&sub.compact_script, &plan.compact_script) {
            println!("# {rel}");
            print!("{text}");
        }
        println!(
            "# would run: sbatch --parsable {}",
            root.join(&sub.script).display()
        );
        if let Some(rel) = &sub.compact_script {
            println!(
                "# then: sbatch --parsable --dependency=afterok:<array job id> {}",
                root.join(rel).display()
            );
        }
        return exit_codes::OK;
    }
    match slurm::submit(&root, plan) {
        Ok(p) => {
            let s = p.record.submissions.last().expect("submission");
            println!(
                "submitted {} array task(s) ({} shards of about {} runs, array {}) as job {}{}",
                p.indices.len(),
                p.record.shards,
                p.record.runs_per_shard,
                s.array,
                s.array_job.as_deref().unwrap_or("?"),
                s.compact_job
                    .as_deref()
                    .map(|j| format!(", compaction job {j} (afterok)"))
                    .unwrap_or_default()
            );
            println!("script: {}", root.join(&s.script).display());
            exit_codes::OK
        }
        Err(e) => report_error(e),
    }
}
