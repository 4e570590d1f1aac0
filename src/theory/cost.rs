//! What the kinetic-theory step of one system costs, estimated from its size without solving
//! anything: CPU seconds and peak bytes, so that a manifest whose theory could not finish is
//! refused (or warned about) before anything runs.
//!
//! The work (see [`super::temperature::evolve`], [`super::msd::msd_numeric`],
//! [`super::sonine`]):
//! - the temperature ODE (13): implicit Radau IIA steps in log time, each with M^2 pair rates
//!   (a Jacobian, Newton iterations) and two dense M x M factorisations (real and complex,
//!   ~M^3); a few hundred steps, plus one landing on each output time;
//! - with `msd`, the quadrature of (4): the ODE lands on every quadrature node, ~100 per
//!   output time (more the longer the run in collision times), each a short step with its
//!   factorisations and a tau_v (M^2);
//! - velocity-dependent restitution: each pair rate interpolates the tabulated Maxwell
//!   averages (~17 times a constant eps's);
//! - the Sonine columns (constant restitution, at most 4 species): per ODE step and output,
//!   M^2 collision-moment quadratures (~30 000 terms each);
//! - the TAMSD (27): a quadrature per species and lag;
//! - an HCS start: a Newton iteration like ~40 ODE steps.
//!
//! The constants are fitted to measured CPU times (release build, one core of a 2-core
//! x86-64 VM; M from 1 to 400, 10 to 2 200 output times, spans of 10^2 to 10^25 collision
//! times, constant and viscoelastic restitution, with and without `msd`): the estimate is
//! within a factor ~2 of those measurements. It is an order of magnitude, for limits and
//! warnings, not a schedule.

/// The size of one system's theory.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Workload {
    /// Number of species M.
    pub species: usize,
    /// Number of output times (0 and t_end included).
    pub times: usize,
    /// ln(1 + t_end / t_c), t_c the shortest collision time at the start: the span of the
    /// ODE's log-time variable (~20 for 10^9 collision times).
    pub span: f64,
    /// The MSD (4) is computed.
    pub msd: bool,
    /// The restitution depends on the impact speed (tabulated Maxwell averages).
    pub velocity_dependent: bool,
    /// The Sonine columns are computed (constant restitution, few species).
    pub sonine: bool,
    /// The start is the HCS (a Newton iteration first).
    pub hcs: bool,
    /// Number of TAMSD lags (0 without).
    pub tamsd_lags: usize,
}

/// The estimate: CPU seconds and peak bytes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cost {
    pub seconds: f64,
    pub bytes: f64,
}

/// Seconds per unit of M^2 (pair rates) per ODE step or landing.
const PAIR_SECONDS: f64 = 9.3e-8;
/// The factorisations' share: M^2 (1 + M / LU_CROSSOVER) per step.
const LU_CROSSOVER: f64 = 200.0;
/// A velocity-dependent pair rate costs this many constant ones (tabulated averages).
const VELOCITY_DEPENDENT: f64 = 17.0;

/// The estimated cost of the theory of `w` (see the module docs).
pub fn estimate(w: &Workload) -> Cost {
    let m = w.species as f64;
    let n = w.times as f64;
    // ln(1 + x) of a double is below 710.
    let span = if w.span.is_nan() {
        1000.0
    } else {
        w.span.clamp(0.0, 1000.0)
    };
    let pairs = if w.velocity_dependent {
        VELOCITY_DEPENDENT
    } else {
        1.0
    };
    // Per ODE step: the pair rates and the factorisations.
    let step = m * m * (pairs + m / LU_CROSSOVER);
    let hcs = if w.hcs { 40.0 } else { 0.0 };
    let mut seconds = (300.0 + 5.0 * span + n + hcs) * PAIR_SECONDS * step + n * 2e-5;
    let nodes_per_time = 0.6 + 0.018 * span;
    if w.msd {
        seconds += n * (6.4e-4 + 1.3e-5 * step) * nodes_per_time + 9e-5 * step;
    }
    if w.sonine {
        let msd = if w.msd { 0.022 * span + 6e-4 * n } else { 0.0 };
        seconds += m * m * (0.1 + 0.003 * span + 1.9e-3 * n + msd);
    }
    seconds += m * w.tamsd_lags as f64 * 5e-6;
    // Dense matrices (Jacobian, two real and two complex factorisations, ...), the rows, and
    // with `msd` the history at every quadrature node (T_k, tau_k, tau_v,k, D_k, tau_hat_k).
    let mut bytes = 80.0 * m * m + 200.0 * n * m + (4 << 20) as f64;
    if w.msd {
        bytes += n * 145.0 * nodes_per_time * (40.0 * m + 150.0);
    }
    Cost { seconds, bytes }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn w(species: usize, times: usize, msd: bool) -> Workload {
        Workload {
            species,
            times,
            span: 22.0,
            msd,
            velocity_dependent: false,
            sonine: false,
            hcs: false,
            tamsd_lags: 0,
        }
    }

    /// The estimate grows with every part of the work: ~M^3 in the species, linearly in the
    /// output times (much faster with `msd`), with velocity-dependent restitution; measured
    /// points are matched within a factor 2.
    #[test]
    fn estimates_follow_the_measured_costs() {
        let s = |x: Workload| estimate(&x).seconds;
        // Measured (CPU s): M = 400, 25 outputs: 18.6; M = 200 with msd: 29 to 35;
        // M = 50 with msd, 2 203 outputs: 91.
        for (x, measured) in [
            (w(400, 25, false), 18.6),
            (w(200, 25, true), 32.0),
            (w(50, 2203, true), 91.0),
            (w(100, 25, false), 0.65),
        ] {
            let e = s(x);
            assert!(
                e / measured < 2.0 && measured / e < 2.0,
                "{x:?}: estimate {e} s, measured {measured} s"
            );
        }
        assert!(s(w(2000, 25, false)) > 100.0 * s(w(200, 25, false)));
        assert!(s(w(50, 10_000, true)) > 10.0 * s(w(50, 1000, false)));
        let mut v = w(50, 25, false);
        v.velocity_dependent = true;
        assert!(s(v) > 10.0 * s(w(50, 25, false)));
        // Any size gives a number (no overflow to NaN).
        let huge = estimate(&Workload {
            span: f64::INFINITY,
            ..w(usize::MAX, usize::MAX, true)
        });
        assert!(huge.seconds > 1e30 && huge.bytes > 1e30);
    }
}
