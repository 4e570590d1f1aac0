//! The thesis's auxiliary models (spec `rfm.md` section 3), each a small stand-alone
//! simulator driven by one [`RunRng`](crate::rng::RunRng) stream, resumable between
//! realisations/walks, with the exact or asymptotic theory beside each measurement:
//!
//! - [`bisection`]: multiplicative bisection (fracture) of [0, 1] to level n (spec 3.1):
//!   histogram of the partition lengths against the exact P_n(x) (3.36), moments against
//!   <a^m>^n ((3.37) for the uniform split).
//! - [`cascade`]: the multiplicative cascade on a 2^n x 2^n grid (spec 3.4, T 6.1), S(k) of the
//!   weight field by 2D FFT with exact shell averaging on the lattice of (4.3), the power-law fit
//!   of D_f, and the particle placement of F 6.3.
//! - [`spm`]: the single particle model (spec 3.2): Q(v, l) at fixed l, or P(v) with l drawn
//!   from the fitted (4.25) or a tabulated P_l; predicted tail exponent (5.28)-(5.29).
//!
//! Pure physics: imports neither `campaign` nor `store`.

pub mod bisection;
pub mod cascade;
pub mod spm;
