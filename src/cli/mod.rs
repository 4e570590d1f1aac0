//! The command line: parses arguments, calls the library, reports. The only layer that
//! prints.
//!
//! One file per command (as in ripgrep and cargo-nextest), each owning its clap `Args` and a
//! `run(args) -> i32` that returns the exit code; `flags` holds the flags several commands
//! share and the parsers that validate every numeric flag at parse time; `reporter` the
//! progress bar; `signals` the Ctrl-C/SIGTERM handler. This file holds the parser, the
//! dispatch, the tracing set-up, the mapping of library errors to exit codes and the printing
//! of results (`outln!`, `out!`: a closed standard output ends printing quietly).

/// `println!` for a command's results on standard output, through [`print_out`]: no panic on
/// a closed pipe (`granular plan M --json | head -1`).
macro_rules! outln {
    ($($arg:tt)*) => {
        $crate::cli::print_out(format_args!($($arg)*), true)
    };
}

/// `print!` for a command's results on standard output, through [`print_out`].
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::cli::print_out(format_args!($($arg)*), false)
    };
}

mod analyze;
mod compact;
mod flags;
mod plan;
mod plot;
mod report;
mod reporter;
mod run;
mod schema;
mod serve;
mod signals;
mod slurm_round;
mod slurm_task;
mod status;
mod submit;
mod tables;
mod theory;
mod upgrade;
mod validate;
mod verify;

use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};

use clap::{Parser, Subcommand, ValueEnum};

use crate::analysis::AnalysisError;
use crate::campaign::CampaignError;
use crate::exit_codes::{self, Classed, ExitClass};
use crate::plot::PlotError;
use crate::store::parquet_io::StoreError;

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
    Validate(validate::Args),
    /// Run a campaign into a directory: a new one, or more of the campaign there (a grown
    /// manifest: more replicas, sweep values, longer runs; finished runs are never redone).
    Run(run::RunArgs),
    /// What running a manifest into a directory would do (new points and runs, continued and
    /// kept runs, an estimate of the cost); writes nothing.
    Plan(plan::Args),
    /// Continue a campaign; finished runs are never redone.
    Resume(run::ResumeArgs),
    /// Done / running / pending / failed runs, per point, across all shards.
    Status(status::Args),
    /// The campaign's tables, for programs and people: name, what a row is, the directory to
    /// read (generation links resolved inside DIR, never followed out of it), files, rows
    /// (from the Parquet footers) and columns (--json). Damage: exit 3, as `status`.
    Tables(tables::Args),
    /// Print the manifest's JSON Schema (also committed as schemas/manifest.schema.json).
    Schema(schema::Args),
    /// Write the kinetic-theory predictions of a manifest (tables dsmc_theory and
    /// dsmc_theory_point) into a campaign directory, without simulating.
    Theory(theory::Args),
    /// Run a campaign as a SLURM job array (array task i = shard i+1 of N), with a
    /// compaction job chained by afterok; or resubmit its unfinished shards (`--missing DIR`).
    Submit(submit::Args),
    /// Run one SLURM array task (used by the scripts `granular submit` writes).
    #[command(hide = true)]
    SlurmTask(slurm_task::Args),
    /// Decide the next round of an error-target campaign under SLURM and submit what follows
    /// (used by the round scripts `granular submit` writes).
    #[command(hide = true)]
    SlurmRound(slurm_round::Args),
    /// Merge a campaign's small Parquet parts into large files, published as a new generation
    /// of each table, and fold its commit records into one ledger index.
    Compact(compact::Args),
    /// Check every table file of a campaign (readable, this campaign's, right table and
    /// format) and that the runs table holds each committed run exactly once.
    Verify(verify::Args),
    /// Draw the standard figures (PNG and SVG) of a campaign's summary tables.
    Plot(plot::Args),
    /// Write one self-contained HTML page of a campaign (progress per point, failed runs,
    /// the standard figures as inline SVG, the manifest and its history); works on an
    /// unfinished campaign.
    Report(report::Args),
    /// A live dashboard of a campaign over HTTP, read-only: the report page updating while
    /// runs finish (on any shard or SLURM task), /api/status (the JSON of `status --json`),
    /// the table files for download. Binds 127.0.0.1:8080 unless --addr says otherwise.
    Serve(serve::Args),
    /// Upgrade a campaign directory written by an earlier granular, in place (logged).
    Upgrade(upgrade::Args),
    /// Fit the thesis's observables of an rfm campaign (xi_m, zeta_m, D_f, alpha, (5.32),
    /// (4.25), ...) or a cascade campaign (D_f) into the table analysis_fits, the figure data analysis_curves and figures.
    /// Uses the finished runs (warns if some are missing).
    Analyze(analyze::Args),
}

/// Parse the command line, set up logging and run the command; returns the exit code.
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
    signals::install();
    let code = match cli.command {
        Command::Validate(a) => validate::run(a),
        Command::Run(a) => run::run(a),
        Command::Plan(a) => plan::run(a),
        Command::Upgrade(a) => upgrade::run(a),
        Command::Resume(a) => run::resume(a),
        Command::Status(a) => status::run(a),
        Command::Tables(a) => tables::run(a),
        Command::Schema(a) => schema::run(a),
        Command::Theory(a) => theory::run(a),
        Command::Submit(a) => submit::run(a),
        Command::SlurmTask(a) => slurm_task::run(a),
        Command::SlurmRound(a) => slurm_round::run(a),
        Command::Compact(a) => compact::run(a),
        Command::Verify(a) => verify::run(a),
        Command::Plot(a) => plot::run(a),
        Command::Report(a) => report::run(a),
        Command::Serve(a) => serve::run(a),
        Command::Analyze(a) => analyze::run(a),
    };
    flush_out();
    if STDOUT_FAILED.load(Ordering::Relaxed) && code == exit_codes::OK {
        exit_codes::IO_ERROR
    } else {
        code
    }
}

/// Standard output stopped taking what the command prints (a closed pipe or a write error):
/// nothing more is written to it.
static STDOUT_GONE: AtomicBool = AtomicBool::new(false);
/// ... and not because its reader went away: the command's success becomes exit 4.
static STDOUT_FAILED: AtomicBool = AtomicBool::new(false);

/// Print a command's results on standard output (`outln!`, `out!`). A reader that went away
/// (`granular plan M --json | head -1`: EPIPE; Rust ignores SIGPIPE, so the process is not
/// killed, which `serve`'s sockets need) is no error: printing stops quietly and the command
/// ends as it would have, with its own exit code (0 when all went well). Any other write error
/// (a full disk) is reported once on stderr and turns exit 0 into 4 (`main`).
pub(crate) fn print_out(args: std::fmt::Arguments<'_>, newline: bool) {
    if STDOUT_GONE.load(Ordering::Relaxed) {
        return;
    }
    let mut o = std::io::stdout().lock();
    let mut r = o.write_fmt(args);
    if newline && r.is_ok() {
        r = o.write_all(b"\n");
    }
    if let Err(e) = r {
        stdout_failed(e);
    }
}

/// What is still buffered for standard output, written before the exit code is decided.
fn flush_out() {
    if !STDOUT_GONE.load(Ordering::Relaxed) {
        if let Err(e) = std::io::stdout().flush() {
            stdout_failed(e);
        }
    }
}

fn stdout_failed(e: std::io::Error) {
    STDOUT_GONE.store(true, Ordering::Relaxed);
    if e.kind() != std::io::ErrorKind::BrokenPipe {
        STDOUT_FAILED.store(true, Ordering::Relaxed);
        let _ = writeln!(
            std::io::stderr(),
            "error: cannot write to standard output: {e}"
        );
    }
}

/// Standard output as an `io::Write` for code that writes in pieces (`status`): every write
/// goes through [`print_out`] and so never fails.
pub(crate) struct Stdout;

impl Write for Stdout {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.write_all(buf)?;
        Ok(buf.len())
    }

    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        if !STDOUT_GONE.load(Ordering::Relaxed) {
            if let Err(e) = std::io::stdout().lock().write_all(buf) {
                stdout_failed(e);
            }
        }
        Ok(())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
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

/// The tables checked against the ledger before a command reads them (`integrity::check`);
/// damage is printed and refused (exit 3) with the command that heals it.
pub(crate) fn tables_checked(
    c: &crate::campaign::Campaign,
    depth: crate::campaign::integrity::Depth,
) -> Result<(), i32> {
    let found = crate::campaign::integrity::check(c, depth).map_err(report_error)?;
    if found.clean() {
        return Ok(());
    }
    Err(refuse_damage(&c.root, &found.problems()))
}

/// Name each problem the integrity check found in `dir` and refuse it (exit 3), naming
/// `granular resume DIR`, which heals it: `status`, `tables`, `plot`, `analyze`.
pub(crate) fn refuse_damage(dir: &std::path::Path, problems: &[String]) -> i32 {
    for p in problems {
        eprintln!("error: damage: {p}");
    }
    fail(
        exit_codes::DIRECTORY_REFUSED,
        format!(
            "{}: the tables do not match the ledger; `granular resume {}` heals it (runs whose rows are damaged run again)",
            dir.display(),
            dir.display()
        ),
    )
}

/// The exit code of an error's class: the one place where errors become exit codes (README
/// "Exit codes").
pub(crate) fn exit_code(class: ExitClass) -> i32 {
    match class {
        ExitClass::RunFailed => exit_codes::RUNS_FAILED,
        ExitClass::InvalidInput => exit_codes::INVALID_INPUT,
        ExitClass::Refused => exit_codes::DIRECTORY_REFUSED,
        ExitClass::Io => exit_codes::IO_ERROR,
    }
}

/// The classes of the errors of the layers below that say none themselves (the renderer
/// imports nothing of the crate; the store's and the analysis's errors are classed here, next
/// to the one conversion to exit codes).
impl Classed for StoreError {
    fn class(&self) -> ExitClass {
        match self {
            // A table that is not what this campaign's table should be.
            StoreError::Corrupt(..) => ExitClass::Refused,
            StoreError::Io { .. } | StoreError::Parquet(..) | StoreError::Arrow(_) => ExitClass::Io,
        }
    }
}

impl Classed for PlotError {
    fn class(&self) -> ExitClass {
        ExitClass::Io
    }
}

impl Classed for AnalysisError {
    fn class(&self) -> ExitClass {
        match self {
            AnalysisError::NotAnalysable(_) => ExitClass::Refused,
            AnalysisError::Store(e) => e.class(),
            AnalysisError::Io(_) => ExitClass::Io,
        }
    }
}

/// Print a campaign error and return the exit code of its class (a manifest's errors are
/// printed as they are, one per line with its JSON pointer).
fn report_error(e: CampaignError) -> i32 {
    match &e {
        CampaignError::Manifest(m) => {
            eprint!("{m}");
            exit_code(e.class())
        }
        _ => failed(&e),
    }
}

/// Print `error: {e}` and return the exit code of its class.
fn failed(e: &dyn Classed) -> i32 {
    fail(exit_code(e.class()), e)
}

/// Print `error: {message}` and return `code`.
fn fail(code: i32, message: impl std::fmt::Display) -> i32 {
    eprintln!("error: {message}");
    code
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_command_line_is_consistent() {
        use clap::CommandFactory;
        Cli::command().debug_assert();
    }

    /// `granular serve DIR` listens on loopback unless told otherwise.
    #[test]
    fn serve_binds_loopback_by_default() {
        let cli = Cli::try_parse_from(["granular", "serve", "/c"]).expect("parses");
        let Command::Serve(a) = cli.command else {
            panic!("not serve")
        };
        assert!(a.addr.ip().is_loopback(), "{}", a.addr);
        let cli = Cli::try_parse_from(["granular", "serve", "/c", "--addr", "0.0.0.0:0"]);
        assert!(cli.is_ok());
        let err = Cli::try_parse_from(["granular", "serve", "/c", "--addr", "nowhere"])
            .err()
            .expect("refused");
        assert!(err.to_string().contains("--addr"), "{err}");
    }

    /// The invocation written into array scripts by `campaign::slurm` (earlier submissions
    /// included) still parses.
    #[test]
    fn slurm_script_invocation_parses() {
        let cli = Cli::try_parse_from([
            "granular",
            "slurm-task",
            "/c",
            "--shards",
            "7",
            "--threads",
            "4",
            "--checkpoint-every",
            "300",
        ])
        .expect("parses");
        let Command::SlurmTask(a) = cli.command else {
            panic!("not slurm-task")
        };
        assert_eq!((a.shards, a.index), (7, None));
        assert_eq!(a.exec.threads, Some(4));
        assert_eq!(a.exec.checkpoint.seconds(), 300.0);
    }

    /// The invocation written into round scripts (`campaign::slurm`) still parses; a
    /// submission number of 0 or none is refused.
    #[test]
    fn slurm_round_invocation_parses() {
        let cli = Cli::try_parse_from(["granular", "slurm-round", "/c", "--submission", "12"])
            .expect("parses");
        let Command::SlurmRound(a) = cli.command else {
            panic!("not slurm-round")
        };
        assert_eq!(a.submission, 12);
        for bad in [
            &["granular", "slurm-round", "/c", "--submission", "0"][..],
            &["granular", "slurm-round", "/c", "--submission", "-1"][..],
            &["granular", "slurm-round", "/c"][..],
        ] {
            assert!(Cli::try_parse_from(bad).is_err(), "{bad:?}");
        }
    }
}
