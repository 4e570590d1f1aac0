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
