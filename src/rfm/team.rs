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
//! The protocol. A pass's jobs are grouped into at most 65 535 units (a unit: one job, or
//! a contiguous run of jobs), the units cut into one contiguous part per member:
//! - part k's remaining units are one atomic word: the pass's number (high 32 bits), the
//!   next unit from the front and the end (16 bits each). The driver writes every part's
//!   word and the pass's work (a reference to a closure on its stack), then the pass's
//!   number in the word the helpers watch, with `Release`;
//! - member m (the driver is member 0) runs its own part's units from the front, one
//!   compare-and-swap each (the same thread gets the same units pass after pass: its
//!   particles stay in its core's cache); then it takes the other parts' remaining units
//!   from their ends (a part whose member is late or absent, or slower this pass), so no
//!   thread idles while another has more than one unit left, and a pass never waits for a
//!   helper that has not started;
//! - a unit is claimed by a compare-and-swap that fails if the word holds another pass, and
//!   the work is read only after a claim: a late helper can never run a unit of the wrong
//!   pass, nor read work that is gone;
//! - the driver returns when every unit is done (each member adds the units it ran to the
//!   count once, after the last of them has run), so the work outlives every use of it.
//!
//! Which thread runs a unit never changes its result (each job writes only its own data),
//! so a run is the same bits with a team, with `rayon::join` or on one thread. A panic in a
//! unit is carried to the driver and resumed there after the pass.

use std::any::Any;
use std::cell::Cell;
use std::panic::{catch_unwind, resume_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicPtr, AtomicU64, AtomicUsize, Ordering};
use std::sync::Mutex;

/// The most threads in a team; larger pools step with `rayon::join` per pass.
pub const MAX_TEAM: usize = 1024;

/// The most units of a pass (16 bits of a part's word each for its front and end).
const MAX_UNITS: usize = u16::MAX as usize;

/// Spins (`spin_loop` hints) before a waiting thread starts yielding its core instead.
const SPINS: u32 = 1 << 14;
/// Yields after the spins before a waiting thread sleeps [`NAP`] at a time (a long serial
/// stretch of the driver, or more threads than cores: then the waiting threads give their
/// cores back).
const YIELDS: u32 = 256;
const NAP: std::time::Duration = std::time::Duration::from_micros(50);

/// Wait for `ready`: spin, then yield, then nap.
#[inline]
fn wait_until(mut ready: impl FnMut() -> bool) {
    let mut k = 0u32;
    while !ready() {
        if k < SPINS {
            std::hint::spin_loop();
        } else if k < SPINS + YIELDS {
            std::thread::yield_now();
        } else {
            std::thread::sleep(NAP);
        }
        k = k.saturating_add(1);
    }
}

thread_local! {
    /// The team this thread drives (null: none).
    static TEAM: Cell<*const Shared> = const { Cell::new(std::ptr::null()) };
    /// Whether this thread is running a team's unit (a `run_parts` inside a unit runs
    /// serially: a nested pass would overwrite the pass in flight).
    static IN_PART: Cell<bool> = const { Cell::new(false) };
    /// The next pass number of the team this thread drives (never 0, the pass number of a
    /// new team; it runs on across teams, which changes nothing).
    static DRIVING: Cell<u32> = const { Cell::new(1) };
}

/// An atomic on a cache line of its own (the helpers spin on `pass`; `done` is added to by
/// each member once a pass).
#[repr(align(128))]
struct Padded<T>(T);

/// One pass's work: unit u is `f(u)`.
struct Work<'a> {
    f: &'a (dyn Fn(usize) + Sync),
}

struct Shared {
    size: usize,
    /// The current pass's number (0: none yet).
    pass: Padded<AtomicU64>,
    /// Each member's part: pass << 32 | front << 16 | end (units front..end left).
    parts: Box<[Padded<AtomicU64>]>,
    /// The current pass's work (a `Work` on the driver's stack, valid until `done`
    /// reaches the pass's units).
    work: AtomicPtr<()>,
    done: Padded<AtomicUsize>,
    stop: AtomicBool,
    /// The driver's index in its rayon pool (None: not a pool thread).
    driver: Option<usize>,
    panic: Mutex<Option<Box<dyn Any + Send>>>,
}

impl Shared {
    /// Claim a unit of part `k` of pass `pass`, from its front (its member) or from its end
    /// (another thread): the unit, or None when the part has none left (or holds another
    /// pass).
    #[inline]
    fn claim(&self, pass: u32, k: usize, front: bool) -> Option<usize> {
        let word = &self.parts[k].0;
        let mut w = word.load(Ordering::Acquire);
        loop {
            let (f, e) = ((w >> 16) & 0xffff, w & 0xffff);
            if (w >> 32) as u32 != pass || f >= e {
                return None;
            }
            let (next, unit) = if front {
                (w + (1 << 16), f)
            } else {
                (w - 1, e - 1)
            };
            match word.compare_exchange_weak(w, next, Ordering::AcqRel, Ordering::Acquire) {
                Ok(_) => return Some(unit as usize),
                Err(now) => w = now,
            }
        }
    }

    /// Run unit `u` (claimed by this thread; the caller counts it done).
    fn run(&self, u: usize) {
        // Valid: unit u is claimed and not done, so the driver is still in its pass.
        let work = unsafe { &*(self.work.load(Ordering::Acquire) as *const Work<'_>) };
        let outer = IN_PART.with(|f| f.replace(true));
        let r = catch_unwind(AssertUnwindSafe(|| (work.f)(u)));
        IN_PART.with(|f| f.set(outer));
        if let Err(p) = r {
            let mut slot = self.panic.lock().unwrap_or_else(|e| e.into_inner());
            slot.get_or_insert(p);
        }
    }

    /// Member `m`'s share of pass `pass`: its own part from the front, then the other
    /// parts' remaining units from their ends (the next member's first). The units it ran
    /// are counted done at the end, in one addition (an addition per unit moved the shared
    /// counter's cache line between the cores ~40 times a step). A member preempted after
    /// its last unit holds the pass back until it adds; the window is a few claim attempts.
    fn work_on(&self, pass: u32, m: usize) {
        let mut ran = 0;
        while let Some(u) = self.claim(pass, m, true) {
            self.run(u);
            ran += 1;
        }
        for i in 1..self.size {
            let k = (m + i) % self.size;
            while let Some(u) = self.claim(pass, k, false) {
                self.run(u);
                ran += 1;
            }
        }
        if ran > 0 {
            self.done.0.fetch_add(ran, Ordering::Release);
        }
    }

    /// A helper's loop (member `m`): each new pass until the session stops.
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
        let mut last = 0u32;
        loop {
            let mut pass = 0;
            wait_until(|| {
                pass = self.pass.0.load(Ordering::Acquire) as u32;
                pass != last || self.stop.load(Ordering::Acquire)
            });
            if pass == last {
                return;
            }
            last = pass;
            self.work_on(pass, m);
        }
    }

    /// The driver's pass number `pass` of `units` units of `f` (at most [`MAX_UNITS`]), all
    /// done when it returns.
    fn pass(&self, pass: u32, units: usize, f: &(dyn Fn(usize) + Sync)) {
        debug_assert!(units <= MAX_UNITS && pass != 0);
        let work = Work { f };
        self.work
            .store(&work as *const Work<'_> as *mut (), Ordering::Relaxed);
        self.done.0.store(0, Ordering::Relaxed);
        let n = self.size;
        for (k, p) in self.parts.iter().enumerate() {
            let (f, e) = ((k * units / n) as u64, ((k + 1) * units / n) as u64);
            p.0.store((pass as u64) << 32 | f << 16 | e, Ordering::Relaxed);
        }
        self.pass.0.store(pass as u64, Ordering::Release);
        self.work_on(pass, 0);
        wait_until(|| self.done.0.load(Ordering::Acquire) >= units);
        let p = self.panic.lock().unwrap_or_else(|e| e.into_inner()).take();
        if let Some(p) = p {
            resume_unwind(p);
        }
    }
}

/// Run `body` with a team of the current rayon pool's threads when `par` and the pool has
/// 2 to [`MAX_TEAM`] threads (and this thread drives no team yet): its
/// [`run_parts`] calls then run on the team. Helpers that never get a thread (the pool
/// busy with other runs) cost nothing: the driver does their parts. A helper stays with
/// the team until `body` returns (one `advance` call), also when it was taken by a thread
/// waiting in a `rayon::join` of another run (outside a team: a run's start): that run
/// then waits for this one's call to end. `body` makes no rayon call of its own (all its
/// parallel work goes through [`run_parts`]).
pub(super) fn with_team<R>(par: bool, body: impl FnOnce() -> R) -> R {
    let size = rayon::current_num_threads();
    if !par || size <= 1 || size > MAX_TEAM || !TEAM.with(|t| t.get().is_null()) {
        return body();
    }
    let shared = Shared {
        size,
        // Pass 0: none yet (every part empty).
        pass: Padded(AtomicU64::new(0)),
        parts: (0..size).map(|_| Padded(AtomicU64::new(0))).collect(),
        work: AtomicPtr::new(std::ptr::null_mut()),
        done: Padded(AtomicUsize::new(0)),
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
        let r = catch_unwind(AssertUnwindSafe(body));
        TEAM.with(|t| t.set(std::ptr::null()));
        sh.stop.store(true, Ordering::Release);
        match r {
            Ok(r) => r,
            Err(p) => resume_unwind(p),
        }
    })
}

/// Run `f` on every job: on this thread's team when it drives one (the jobs cut into one
/// contiguous part per member, run k on member k, the ends of slower parts taken by the
/// threads done with theirs), else cut into `parts` contiguous runs of about equal length,
/// the first run on the calling thread and the others handed out by `rayon::join`
/// (`parts` <= 1: all on this thread). Either way a step's
/// passes give each thread the same range of blocks step after step (its particles and
/// pairs stay in its core's cache; rayon's adaptive splitting handed them to a different
/// thread in each pass). Which thread runs a job never changes its result.
pub(super) fn run_parts<J: Send>(jobs: &mut [J], parts: usize, f: &(impl Fn(&mut J) + Sync)) {
    // Inside a team's unit too: serially (on this thread, as its unit).
    if parts <= 1 || jobs.len() <= 1 || IN_PART.with(|f| f.get()) {
        for j in jobs.iter_mut() {
            f(j);
        }
        return;
    }
    let team = TEAM.with(|t| t.get());
    if !team.is_null() {
        // Valid: set only for the extent of the team's session on this thread.
        let team = unsafe { &*team };
        let n = jobs.len();
        let units = n.min(MAX_UNITS);
        let base = SendPtr(jobs.as_mut_ptr());
        let unit = |u: usize| {
            let base = &base;
            for i in u * n / units..(u + 1) * n / units {
                // Valid: the units are disjoint ranges of `jobs`, each run by one thread
                // once (the team's claim), within this call (J: Send).
                f(unsafe { &mut *base.0.add(i) });
            }
        };
        let pass = DRIVING.with(|d| {
            let p = d.get();
            d.set(if p == u32::MAX { 1 } else { p + 1 });
            p
        });
        team.pass(pass, units, &unit);
        return;
    }
    let lo = parts / 2;
    let mid = jobs.len() * lo / parts;
    let (a, b) = jobs.split_at_mut(mid);
    rayon::join(|| run_parts(a, lo, f), || run_parts(b, parts - lo, f));
}

/// A job array's base shared with the team (each unit's jobs used by one thread).
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

    /// 2000 passes of lengths 1..=37 over the same jobs, each job adding 1 per pass that
    /// covers it, and a nested `run_parts` inside every part (run serially there) adding
    /// 10: any part run twice or skipped, or a nested pass that disturbed the outer one,
    /// changes a count.
    fn passes() -> Vec<u64> {
        let mut jobs: Vec<(u64, [u64; 2])> = vec![(0, [0; 2]); 37];
        for pass in 0..2000usize {
            let len = 1 + pass % 37;
            run_parts(
                &mut jobs[..len],
                rayon::current_num_threads(),
                &|j: &mut (u64, [u64; 2])| {
                    j.0 += 1;
                    run_parts(&mut j.1, rayon::current_num_threads(), &|x: &mut u64| {
                        *x += 5
                    });
                },
            );
        }
        let want: Vec<u64> = (0..37)
            .map(|i| (0..2000).filter(|p| i < 1 + p % 37).count() as u64)
            .collect();
        assert_eq!(jobs.iter().map(|j| j.0).collect::<Vec<_>>(), want);
        for j in &jobs {
            assert_eq!(j.1, [5 * j.0; 2]);
        }
        jobs.iter().map(|j| j.0).collect()
    }

    /// Every job runs exactly once per pass ([`passes`]) on pools of 1, 2, 3 and 5 threads,
    /// with and without a team, with the pass number wrapping past u32::MAX in the middle.
    #[test]
    fn every_job_runs_once_per_pass() {
        for k in [1, 2, 3, 5] {
            pool(k).install(|| {
                for par in [false, true] {
                    DRIVING.with(|d| d.set(u32::MAX - 1000));
                    with_team(par, || {
                        // A team exactly when asked for on a pool of several threads.
                        assert_eq!(TEAM.with(|t| !t.get().is_null()), par && k > 1);
                        passes();
                    });
                }
            });
        }
    }

    /// Two drivers on one pool of 2 (each may take the other's helper job while it waits
    /// in the join: the helper then returns at once), and a driver outside any pool (its
    /// helpers on the global pool): every count right, no hang.
    #[test]
    fn two_drivers_and_a_driver_outside_the_pool() {
        pool(2).install(|| {
            let (a, b) = rayon::join(|| with_team(true, passes), || with_team(true, passes));
            assert_eq!(a, b);
        });
        with_team(true, passes);
    }

    /// With a team on a pool of several threads, helpers do take parts (the team is not the
    /// driver alone).
    #[test]
    fn helpers_take_parts() {
        pool(3).install(|| {
            let me = rayon::current_thread_index();
            let others = AtomicUsize::new(0);
            with_team(true, || {
                let mut jobs = vec![0u8; 3];
                for _ in 0..2000 {
                    run_parts(&mut jobs, rayon::current_num_threads(), &|_: &mut u8| {
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
        });
    }

    /// A slow part's remaining units are taken from its end by the thread done with its
    /// own: the driver sleeps 30 ms in its first unit, and the helper, done with its part,
    /// runs the rest of the driver's (each job once: the counts).
    #[test]
    fn slow_parts_are_shared() {
        pool(2).install(|| {
            let me = rayon::current_thread_index();
            let mut jobs: Vec<(usize, Option<usize>, u32)> = (0..8).map(|i| (i, None, 0)).collect();
            with_team(true, || {
                run_parts(
                    &mut jobs,
                    rayon::current_num_threads(),
                    &|j: &mut (usize, Option<usize>, u32)| {
                        if j.0 == 0 {
                            std::thread::sleep(std::time::Duration::from_millis(30));
                        }
                        j.1 = rayon::current_thread_index();
                        j.2 += 1;
                    },
                );
            });
            assert!(jobs.iter().all(|j| j.2 == 1), "{jobs:?}");
            assert_eq!(jobs[0].1, me, "the driver's first unit");
            assert!(
                jobs[1..4].iter().all(|j| j.1 != me),
                "the driver's remaining units were not taken: {jobs:?}"
            );
        });
    }

    /// A part's panic, on whichever thread ran it, reaches the driver after the pass and
    /// leaves `with_team`; the pool then teams up again.
    #[test]
    fn a_part_panic_reaches_the_driver() {
        pool(3).install(|| {
            for _ in 0..20 {
                let r = catch_unwind(AssertUnwindSafe(|| {
                    with_team(true, || {
                        let mut jobs: Vec<usize> = (0..3).collect();
                        run_parts(&mut jobs, rayon::current_num_threads(), &|j: &mut usize| {
                            if *j == 2 {
                                panic!("part of job 2");
                            }
                        });
                    })
                }));
                let p = r.expect_err("the part's panic was lost");
                let msg = p
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                assert!(msg.contains("part of job 2"), "{msg}");
            }
            let mut jobs = vec![0u32; 3];
            with_team(true, || {
                for _ in 0..100 {
                    run_parts(&mut jobs, rayon::current_num_threads(), &|j: &mut u32| {
                        *j += 1
                    });
                }
            });
            assert_eq!(jobs, vec![100; 3]);
        });
    }
}
