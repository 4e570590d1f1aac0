//! What a campaign asks of the machine: the memory of its largest run (each model estimates it
//! from its parameters) against the machine's memory. A run that cannot fit is refused before
//! anything is written; more runs at once than the free memory holds are run fewer at a time.

use super::error::CampaignError;
use super::plan::Plan;

/// The machine's memory (bytes), from `/proc/meminfo`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Memory {
    pub total: u64,
    pub available: u64,
}

impl Memory {
    /// This machine's memory; None where it cannot be read (then nothing is checked).
    pub fn of_this_machine() -> Option<Memory> {
        let text = std::fs::read_to_string("/proc/meminfo").ok()?;
        let field = |name: &str| -> Option<u64> {
            let line = text.lines().find(|l| l.starts_with(name))?;
            let kb: u64 = line[name.len()..]
                .trim()
                .trim_end_matches("kB")
                .trim()
                .parse()
                .ok()?;
            Some(kb * 1024)
        };
        let total = field("MemTotal:")?;
        Some(Memory {
            total,
            available: field("MemAvailable:").unwrap_or(total),
        })
    }
}

/// The point with the largest estimated memory per run, and that estimate.
pub fn largest_run(plan: &Plan) -> Option<(u32, u64)> {
    plan.points
        .iter()
        .map(|p| (p.point_id, p.params.memory()))
        .max_by_key(|x| x.1)
}

/// Bytes as "1.2 GB".
pub fn human(bytes: u64) -> String {
    let b = bytes as f64;
    match b {
        b if b >= 1e12 => format!("{:.1} TB", b / 1e12),
        b if b >= 1e9 => format!("{:.1} GB", b / 1e9),
        b if b >= 1e6 => format!("{:.0} MB", b / 1e6),
        b => format!("{:.0} kB", b / 1e3),
    }
}

/// Refuse a plan whose largest run needs more memory than the machine has (invalid input:
/// `CampaignError::TooLarge`).
pub fn check(plan: &Plan, mem: Memory) -> Result<(), CampaignError> {
    match largest_run(plan) {
        Some((point, need)) if need > mem.total => Err(CampaignError::TooLarge(format!(
            "a run of point {point}{} needs about {} of memory (estimated from its parameters), \
             more than this machine's {}; make the runs smaller or run them on a larger machine",
            describe(plan, point),
            human(need),
            human(mem.total)
        ))),
        _ => Ok(()),
    }
}

fn describe(plan: &Plan, point: u32) -> String {
    let label = plan.label(point);
    if label.is_empty() {
        String::new()
    } else {
        format!(" ({label})")
    }
}

/// How many runs may run at once: `threads`, or fewer if that many of the largest runs would
/// not fit in the free memory (with a message saying so).
pub fn threads_within(plan: &Plan, threads: usize, mem: Memory) -> (usize, Option<String>) {
    let Some((_, need)) = largest_run(plan) else {
        return (threads, None);
    };
    let fit = (mem.available / need.max(1)).max(1) as usize;
    if fit >= threads {
        return (threads, None);
    }
    (
        fit,
        Some(format!(
            "running {fit} run(s) at a time instead of {threads}: each may need about {} and \
             {} of memory is free",
            human(need),
            human(mem.available)
        )),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    // Short runs: memory, not work (`MAX_RUN_WORK`), is what refuses the largest.
    fn plan(n: u64) -> Plan {
        let m = format!(
            r#"{{"name": "m", "model": "rfm", "seed": 1,
                "params": {{"dim": 2, "n_particles": {n}, "packing_fraction": 0.3,
                            "warmup": 0.001, "duration": 0.1}}}}"#
        );
        crate::campaign::plan::parse(&m, "m").unwrap().1
    }

    #[test]
    fn a_run_larger_than_the_machine_is_refused_and_threads_shrink_to_fit() {
        let gb = 1u64 << 30;
        let mem = Memory {
            total: 16 * gb,
            available: 8 * gb,
        };
        let huge = plan(1_000_000_000);
        let e = check(&huge, mem).unwrap_err();
        assert!(matches!(e, CampaignError::TooLarge(_)), "{e}");
        let e = e.to_string();
        assert!(e.contains("point 0") && e.contains("GB"), "{e}");
        let small = plan(1000);
        assert!(check(&small, mem).is_ok());
        assert_eq!(threads_within(&small, 4, mem), (4, None));
        // ~ 2.2 GB per run (1e7 2D particles): 3 fit in 8 GB.
        let mid = plan(10_000_000);
        let (t, note) = threads_within(&mid, 8, mem);
        let need = largest_run(&mid).unwrap().1;
        assert_eq!(t as u64, 8 * gb / need);
        assert!(t < 8 && note.is_some());
    }
}
