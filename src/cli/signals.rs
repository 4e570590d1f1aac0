//! Ctrl-C / SIGTERM, for every command. Until a simulation has started (loading and
//! validating the manifest, planning, the theory step, and every command but the running of
//! runs, `serve` included) the first signal exits at once with 130: every file is written atomically (to a
//! temporary name, then renamed), so nothing is left half-written, and there is nothing to
//! checkpoint. Once `run`/`resume`/`slurm-task` has started a simulation, the first signal sets
//! the interrupt flag that the workers and the dispatcher watch (checkpoint and stop, exit
//! 130), the second exits at once.

use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};
use std::sync::{Arc, OnceLock};

use crate::exit_codes;

static FLAG: OnceLock<Arc<AtomicU8>> = OnceLock::new();
static RUNS_STARTED: AtomicBool = AtomicBool::new(false);

/// Install the handler (once, at start-up).
pub fn install() {
    let flag = interrupt_flag();
    let _ = ctrlc::set_handler(move || {
        if !RUNS_STARTED.load(Ordering::SeqCst) {
            eprintln!("\ninterrupted before any simulation started: stopping");
            std::process::exit(exit_codes::INTERRUPTED);
        }
        let n = flag.fetch_add(1, Ordering::SeqCst) + 1;
        if n >= 2 {
            eprintln!("\ninterrupted twice: exiting now (work since the last checkpoints is lost)");
            std::process::exit(exit_codes::INTERRUPTED);
        }
        eprintln!("\ninterrupt: checkpointing running simulations and stopping (press Ctrl-C again to exit at once)");
    });
}

/// The interrupt flag the run options carry: 0 = run, >= 1 = checkpoint and stop.
pub fn interrupt_flag() -> Arc<AtomicU8> {
    FLAG.get_or_init(|| Arc::new(AtomicU8::new(0))).clone()
}

/// A simulation has started: from now on a signal checkpoints and stops.
pub fn runs_started() {
    RUNS_STARTED.store(true, Ordering::SeqCst);
}
