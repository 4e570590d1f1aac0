//! The command line: parses arguments, calls the library, reports. The only layer that
//! prints.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::Arc;
use std::time::Duration;

use clap::{Args, Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};

use crate::campaign::ledger::RunStatus;
use crate::campaign::{self, Campaign, CampaignError, Event, Outcome, Reporter, RunOptions};
use crate::exit_codes;
use crate::plan::Shard;

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
        Command::Validate { manifest } => match crate::manifest::load_manifest(&manifest) {
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
            Ok(c) => match crate::campaign::writer::write_theory(&c) {
                Ok(()) => {
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
                match crate::plot::figures(&c)
                    .map_err(|e| e.to_string())
                    .and_then(|f| crate::plot::render(&f, &out))
                {
                    Ok(files) => {
                        println!("wrote {} files to {}", files.len(), out.display());
                        exit_codes::OK
                    }
                    Err(e) => {
                        eprintln!("error: {e}");
                        exit_codes::IO_ERROR
                    }
                }
            }
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
    let result = campaign::run(c, &opts, &mut reporter);
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
