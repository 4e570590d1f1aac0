//! Ctrl-C / SIGTERM, for every command. Until a simulation has started (loading and
//! validating the manifest, planning, the theory step, and every command but the running of
//! runs, `serve` included) the first signal exits at once with 130: every file is written atomically (to a
//! temporary name, then renamed), so nothing is left half-written, and there is nothing to
//! checkpoint. Once `run`/`resume`/`slurm-task` has started a simulation, the first signal sets
//! the interrupt flag that the workers and the dispatcher watch (checkpoint and stop, exit
//! 130), the second exits at once. Every message names the signal (SIGINT or SIGTERM: a small
//! handler of our own notes it, then calls the `ctrlc` crate's); `serve` says that it stopped.

use std::sync::atomic::{AtomicBool, AtomicI32, AtomicU8, AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};

use crate::exit_codes;

static FLAG: OnceLock<Arc<AtomicU8>> = OnceLock::new();
static RUNS_STARTED: AtomicBool = AtomicBool::new(false);
/// The last signal received (0: none noted).
static LAST_SIGNAL: AtomicI32 = AtomicI32::new(0);
/// The handlers `ctrlc` installed for SIGINT and SIGTERM, which [`note`] calls.
static PREVIOUS: [AtomicUsize; 2] = [AtomicUsize::new(0), AtomicUsize::new(0)];
/// The command that runs, where its stop message names it (`serve`).
static COMMAND: OnceLock<&'static str> = OnceLock::new();

/// Install the handler (once, at start-up).
pub fn install() {
    let flag = interrupt_flag();
    let _ = ctrlc::set_handler(move || {
        let signal = signal_name(LAST_SIGNAL.load(Ordering::SeqCst));
        if !RUNS_STARTED.load(Ordering::SeqCst) {
            match COMMAND.get() {
                Some(cmd) => eprintln!("\ngranular {cmd}: stopped by {signal}"),
                None => eprintln!(
                    "\nstopped by {signal}: interrupted before any simulation started (nothing is half-written; run the same command again to do it)"
                ),
            }
            std::process::exit(exit_codes::INTERRUPTED);
        }
        let n = flag.fetch_add(1, Ordering::SeqCst) + 1;
        if n >= 2 {
            eprintln!("\ninterrupted twice ({signal}): exiting now (work since the last checkpoints is lost; `granular resume DIR` continues from them)");
            std::process::exit(exit_codes::INTERRUPTED);
        }
        eprintln!("\ninterrupt: checkpointing running simulations and stopping after {signal} (press Ctrl-C again to exit at once; `granular resume DIR` continues)");
    });
    for (i, sig) in [libc::SIGINT, libc::SIGTERM].into_iter().enumerate() {
        // SAFETY: sigaction with valid pointers; `note` only stores atomics and calls the
        // handler that was installed (async-signal-safe as `ctrlc`'s is: it writes to a pipe).
        unsafe {
            let mut old: libc::sigaction = std::mem::zeroed();
            if libc::sigaction(sig, std::ptr::null(), &mut old) != 0
                || old.sa_flags & libc::SA_SIGINFO != 0
                || old.sa_sigaction == libc::SIG_DFL
                || old.sa_sigaction == libc::SIG_IGN
            {
                continue;
            }
            PREVIOUS[i].store(old.sa_sigaction, Ordering::SeqCst);
            let mut new = old;
            new.sa_sigaction = note as extern "C" fn(libc::c_int) as usize;
            libc::sigaction(sig, &new, std::ptr::null_mut());
        }
    }
}

/// The signal handler: note the signal, then call `ctrlc`'s.
extern "C" fn note(sig: libc::c_int) {
    LAST_SIGNAL.store(sig, Ordering::SeqCst);
    let i = usize::from(sig == libc::SIGTERM);
    let prev = PREVIOUS[i].load(Ordering::SeqCst);
    if prev != 0 {
        // SAFETY: `prev` is the plain (not SA_SIGINFO) handler read by `install`.
        let f: extern "C" fn(libc::c_int) = unsafe { std::mem::transmute(prev) };
        f(sig);
    }
}

fn signal_name(sig: i32) -> &'static str {
    match sig {
        libc::SIGINT => "SIGINT (Ctrl-C)",
        libc::SIGTERM => "SIGTERM",
        _ => "a signal (SIGINT or SIGTERM)",
    }
}

/// The command that runs names itself in its stop message (`granular serve: stopped by
/// SIGTERM`); only commands that write nothing (`serve`).
pub fn command(name: &'static str) {
    let _ = COMMAND.set(name);
}

/// The interrupt flag the run options carry: 0 = run, >= 1 = checkpoint and stop.
pub fn interrupt_flag() -> Arc<AtomicU8> {
    FLAG.get_or_init(|| Arc::new(AtomicU8::new(0))).clone()
}

/// A simulation has started: from now on a signal checkpoints and stops.
pub fn runs_started() {
    RUNS_STARTED.store(true, Ordering::SeqCst);
}
