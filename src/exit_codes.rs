//! Process exit codes (documented in the README).

/// Everything asked for finished.
pub const OK: i32 = 0;
/// The campaign finished, but at least one run failed (NaN, bound violated, ...).
pub const RUNS_FAILED: i32 = 1;
/// The manifest or the command line is invalid; nothing was written.
pub const INVALID_INPUT: i32 = 2;
/// The output directory holds another campaign, is locked by a live process, or is corrupt;
/// `serve`: the address is in use.
pub const DIRECTORY_REFUSED: i32 = 3;
/// An I/O or internal error stopped the campaign (disk full, permissions, ...).
pub const IO_ERROR: i32 = 4;
/// Stopped by Ctrl-C / SIGTERM after checkpointing; `granular resume` continues.
pub const INTERRUPTED: i32 = 130;

/// The class of a failure: every error of the library says its class (`class()`, the
/// [`Classed`] trait), and the command line turns the class into the exit code above, in one
/// place (`cli::exit_code`), never by reading the message.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExitClass {
    /// A run failed: the run is recorded as failed and the campaign goes on (exit 1 at its end).
    RunFailed,
    /// The manifest, the command line or another input is invalid, or a run would not fit in
    /// the machine's memory; nothing was written (exit 2).
    InvalidInput,
    /// The directory is refused: another campaign or format, locked by a live process, a
    /// manifest it refuses, corrupt, or tables that do not match the ledger (exit 3).
    Refused,
    /// An I/O or internal error: disk full, read-only, permissions, also at a lock (exit 4).
    Io,
}

/// An error that says its [`ExitClass`].
pub trait Classed: std::fmt::Display {
    fn class(&self) -> ExitClass;
}
