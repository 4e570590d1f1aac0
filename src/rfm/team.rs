//! The threads of one run's steps: a team of the current rayon pool's threads that stays
//! together for an `advance` call, so that a step's passes start and end without rayon's
//! sleep and wake-up.
//!
//! A 2D run of N = 27 000 on 2 threads makes two parallel passes per step (~45 us each on
//! each thread). With `rayon::join` per pass, the thread that finished first went to sleep
//! in about a quarter of the passes and had to be woken by a system call, and the other
//! thread took ~2 us to steal its half: ~100 ms of a 2.2 s run. In a team the helpers spin
//! (then yield) on a shared word between passes, and the caller (the driver) publishes each
//! pass in that word.
//!
//! The protocol, with a pass cut into `parts` parts (at most the team's size, at most
//! [`MAX_TEAM`]):
//! - one atomic word holds the pass's number (high 32 bits) and a bit per part (low 32
//!   bits, set: taken). The driver writes the pass's work (a reference to a closure on its
//!   stack) and then the word with no part taken, with `Release`;
//! - a thread takes part k by a compare-and-swap of the word that sets bit k, which fails
//!   if the word holds another pass: only then does it read the work, so a late helper can
//!   never run a part of the wrong pass, nor read work that is gone;
//! - member m takes part m first (the same thread gets the same part pass after pass: its
//!   particles stay in its core's cache), then any part still free; the driver does the
//!   same with part 0, so a pass never waits for a helper that has not started;
//! - the driver returns when every part is done (each part counted after it has run), so
//!   the work outlives every use of it.
//!
//! Which thread runs a part never changes its result, so a run is the same bits with a
//! team, with `rayon::join` or on one thread. A panic in a part is carried to the driver
//! and resumed there after the pass.

use std::any::Any;
use std::cell::Cell;
use std::panic::{catch_unwind, resume_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicPtr, AtomicU64, AtomicUsize, Ordering};
use std::sync::Mutex;

/// The most threads in a team (a bit of the shared word per part).
pub const MAX_TEAM: usize = 32;

/// Spins (`spin_loop` hints) before a waiting thread starts yielding its core instead.
const SPINS: u32 = 1 << 14;

thread_local! {
    /// The team this thread drives (null: none).
    static TEAM: Cell<*const Shared> = const { Cell::new(std::ptr::null()) };
}

/// One pass's work: part k is `f(k)`, for k < `parts`.
struct Work<'a> {
    f: &'a (dyn Fn(usize) + Sync),
}

struct Shared {
    size: usize,
    /// Pass number << 32 | the parts taken (bits of parts beyond the pass's are set).
    word: AtomicU64,
    /// The current pass's work (a `Work` on the driver's stack, valid until `done`
    /// reaches the pass's parts).
    work: AtomicPtr<()>,
    done: AtomicUsize,
    stop: AtomicBool,
    /// The driver's index in its rayon pool (None: not a pool thread).
    driver: Option<usize>,
    panic: Mutex<Option<Box<dyn Any + Send>>>,
}

impl Shared {
    /// Take part `k` of pass `pass`: whether this thread got it.
    fn take(&self, pass: u32, k: usize) -> bool {
        let bit = 1u64 << k;
        let mut w = self.word.load(Ordering::Acquire);
        loop {
            if (w >> 32) as u32 != pass || w & bit != 0 {
                return false;
            }
            match self
                .word
                .compare_exchange_weak(w, w | bit, Ordering::AcqRel, Ordering::Acquire)
            {
                Ok(_) => return true,
                Err(now) => w = now,
            }
        }
    }

    /// Run part `k` (taken by this thread) and count it done.
    fn run(&self, k: usize) {
        // Valid: part k is taken and not done, so the driver is still in its pass.
        let work = unsafe { &*(self.work.load(Ordering::Acquire) as *const Work<'_>) };
        if let Err(p) = catch_unwind(AssertUnwindSafe(|| (work.f)(k))) {
            let mut slot = self.panic.lock().unwrap_or_else(|e| e.into_inner());
            slot.get_or_insert(p);
        }
        self.done.fetch_add(1, Ordering::Release);
    }

    /// Take and run part `first`, then every part of pass `pass` still free.
    fn work_on(&self, pass: u32, first: usize) {
        if first < self.size && self.take(pass, first) {
            self.run(first);
        }
        for k in 0..self.size {
            if self.take(pass, k) {
                self.run(k);
            }
        }
    }

    /// A helper's loop (member `m`): each new pass's parts until the session stops.
    fn helper(&self, m: usize) {
        // Never spin on the driver's own thread (it may run this job while it waits for
        // rayon work inside its session): the driver does the parts itself.
        if self.driver.is_some() && rayon::current_thread_index() == self.driver {
            return;
        }
        // Nor on a thread that drives a team of its own (it took this job while waiting for
        // rayon work in its session): two drivers spinning as each other's helpers would
        // wait for each other for ever.
        if TEAM.with(|t| !t.get().is_null()) {
            return;
        }
        let mut last: Option<u32> = None;
        loop {
            let mut spins = 0u32;
            let pass = loop {
                let w = self.word.load(Ordering::Acquire);
                let pass = (w >> 32) as u32;
                if last != Some(pass) {
                    break pass;
                }
                if self.stop.load(Ordering::Acquire) {
                    return;
                }
                if spins < SPINS {
                    spins += 1;
                    std::hint::spin_loop();
                } else {
                    std::thread::yield_now();
                }
            };
            last = Some(pass);
            self.work_on(pass, m);
        }
    }

    /// The driver's pass: `parts` parts of `f`, all done when it returns.
    fn pass(&self, pass: u32, parts: usize, f: &(dyn Fn(usize) + Sync)) {
        debug_assert!(parts >= 1 && parts <= self.size);
        let work = Work { f };
        self.work
            .store(&work as *const Work<'_> as *mut (), Ordering::Relaxed);
        self.done.store(0, Ordering::Relaxed);
        let free = if parts == 32 { 0 } else { u32::MAX << parts };
        self.word
            .store((pass as u64) << 32 | free as u64, Ordering::Release);
        self.work_on(pass, 0);
        let mut spins = 0u32;
        while self.done.load(Ordering::Acquire) < parts {
            if spins < SPINS {
                spins += 1;
                std::hint::spin_loop();
            } else {
                std::thread::yield_now();
            }
        }
        let p = self.panic.lock().unwrap_or_else(|e| e.into_inner()).take();
        if let Some(p) = p {
            resume_unwind(p);
        }
    }
}

/// Run `body` with a team of the current rayon pool's threads (at most [`MAX_TEAM`]) when
/// `par` and the pool has several threads (and this thread drives no team yet): its
/// [`run_parts`] calls then run on the team. Helpers that never get a thread (the pool
/// busy with other runs) cost nothing: the driver does their parts. A helper stays with
/// the team until `body` returns (one `advance` call), also when it was taken by a thread
/// waiting in a `rayon::join` of another run (outside a team: a run's start): that run
/// then waits for this one's call to end. `body` makes no rayon call of its own (all its
/// parallel work goes through [`run_parts`]).
pub(super) fn with_team<R>(par: bool, body: impl FnOnce() -> R) -> R {
    let size = rayon::current_num_threads().min(MAX_TEAM);
    if !par || size <= 1 || !TEAM.with(|t| t.get().is_null()) {
        return body();
    }
    let shared = Shared {
        size,
        // Pass 0: no work, every part taken.
        word: AtomicU64::new(u32::MAX as u64),
        work: AtomicPtr::new(std::ptr::null_mut()),
        done: AtomicUsize::new(0),
        stop: AtomicBool::new(false),
        driver: rayon::current_thread_index(),
        panic: Mutex::new(None),
    };
    rayon::in_place_scope(|s| {
        let sh = &shared;
        for m in 1..size {
            s.spawn(move |_| sh.helper(m));
        }
        TEAM.with(|t| t.set(sh as *const Shared));
        DRIVING.with(|d| d.set(1));
        let r = catch_unwind(AssertUnwindSafe(body));
        TEAM.with(|t| t.set(std::ptr::null()));
        sh.stop.store(true, Ordering::Release);
        match r {
            Ok(r) => r,
            Err(p) => resume_unwind(p),
        }
    })
}

thread_local! {
    /// The next pass's number of the team this thread drives.
    static DRIVING: Cell<u32> = const { Cell::new(1) };
}

/// The threads a pass is cut for: the team's size when this thread drives one, else the
/// current pool's.
pub(super) fn threads() -> usize {
    TEAM.with(|t| {
        let p = t.get();
        if p.is_null() {
            rayon::current_num_threads()
        } else {
            // Valid: set only for the extent of the team's session on this thread.
            unsafe { (*p).size }
        }
    })
}

/// Run `f` on every job, the jobs cut into `parts` contiguous runs of about equal length:
/// on this thread's team when it drives one (run k on member k), else the first run on
/// the calling thread and the others handed out by `rayon::join`. Either way a step's
/// passes give each thread the same range of blocks step after step (its particles and
/// pairs stay in its core's cache; rayon's adaptive splitting handed them to a different
/// thread in each pass). Which thread runs a job never changes its result.
pub(super) fn run_parts<J: Send>(jobs: &mut [J], parts: usize, f: &(impl Fn(&mut J) + Sync)) {
    if parts <= 1 || jobs.len() <= 1 {
        for j in jobs.iter_mut() {
            f(j);
        }
        return;
    }
    let team = TEAM.with(|t| t.get());
    if !team.is_null() {
        // Valid: set only for the extent of the team's session on this thread.
        let team = unsafe { &*team };
        let parts = parts.min(team.size).min(jobs.len());
        let n = jobs.len();
        let base = SendPtr(jobs.as_mut_ptr());
        let part = |k: usize| {
            let base = &base;
            for i in k * n / parts..(k + 1) * n / parts {
                // Valid: the parts are disjoint ranges of `jobs`, each run by one
                // thread once (the team's take), within this call (J: Send).
                f(unsafe { &mut *base.0.add(i) });
            }
        };
        let pass = DRIVING.with(|d| {
            let p = d.get();
            d.set(if p == u32::MAX { 1 } else { p + 1 });
            p
        });
        team.pass(pass, parts, &part);
        return;
    }
    let lo = parts / 2;
    let mid = jobs.len() * lo / parts;
    let (a, b) = jobs.split_at_mut(mid);
    rayon::join(|| run_parts(a, lo, f), || run_parts(b, parts - lo, f));
}

/// A job array's base shared with the team (each part's range used by one thread).
struct SendPtr<J>(*mut J);
unsafe impl<J: Send> Sync for SendPtr<J> {}

#[cfg(test)]
mod tests {
    use super::*;

    fn pool(k: usize) -> rayon::ThreadPool {
        rayon::ThreadPoolBuilder::new()
            .num_threads(k)
            .build()
            .unwrap()
    }

    /// Every job runs exactly once per pass, on any pool, with or without a team, over
    /// many passes of varying lengths (a part run twice or skipped would miscount).
    #[test]
    fn every_job_runs_once_per_pass() {
        for k in [1, 2, 3, 5] {
            pool(k).install(|| {
                for par in [false, true] {
                    with_team(par, || {
                        assert_eq!(threads(), k.min(MAX_TEAM));
                        let mut jobs: Vec<u64> = vec![0; 37];
                        for pass in 0..2000usize {
                            let len = 1 + pass % 37;
                            run_parts(&mut jobs[..len], threads(), &|j: &mut u64| *j += 1);
                        }
                        let want: Vec<u64> = (0..37)
                            .map(|i| (0..2000).filter(|p| i < 1 + p % 37).count() as u64)
                            .collect();
                        assert_eq!(jobs, want, "{k} threads, team {par}");
                    });
                }
            });
        }
    }

    /// With a team on a pool of several threads, helpers do take parts (the team is not the
    /// driver alone), and a part's panic reaches the driver after the pass.
    #[test]
    fn helpers_take_parts_and_panics_reach_the_driver() {
        pool(3).install(|| {
            let me = rayon::current_thread_index();
            let others = AtomicUsize::new(0);
            with_team(true, || {
                let mut jobs = vec![0u8; 3];
                for _ in 0..2000 {
                    run_parts(&mut jobs, threads(), &|_: &mut u8| {
                        if rayon::current_thread_index() != me {
                            others.fetch_add(1, Ordering::Relaxed);
                        }
                        std::thread::sleep(std::time::Duration::from_micros(20));
                    });
                }
            });
            assert!(
                others.load(Ordering::Relaxed) > 0,
                "no helper ever ran a part"
            );
            let r = catch_unwind(AssertUnwindSafe(|| {
                with_team(true, || {
                    let mut jobs = vec![0u8; 3];
                    run_parts(&mut jobs, threads(), &|j: &mut u8| {
                        *j += 1;
                        assert!(rayon::current_thread_index() == me, "a helper's part");
                    });
                })
            }));
            // Unless the driver ran all three parts itself, a helper's part panicked and
            // the panic came back here.
            if let Err(p) = r {
                let msg = p
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                assert!(msg.contains("a helper's part"), "{msg}");
            }
            // The same pool teams up again after the panic (no helper left behind).
            let mut jobs = vec![0u32; 3];
            with_team(true, || {
                for _ in 0..100 {
                    run_parts(&mut jobs, threads(), &|j: &mut u32| *j += 1);
                }
            });
            assert_eq!(jobs, vec![100; 3]);
        });
    }
}
