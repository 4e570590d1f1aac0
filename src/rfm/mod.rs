//! The Random Force Model (RFM) of a randomly driven granular fluid (Bray 2009; spec
//! `rfm.md` section 1): identical soft discs (2D) or rods on a ring (1D) with linear
//! spring-dashpot contacts, each kicked by independent white noise, in a periodic box.
//!
//! - [`params`]: [`RfmConfig`] with the thesis defaults and the derived quantities
//!   (gamma_n (2.6), gamma_t (2.12), contact time, box length, default dt), validation.
//! - [`contact`]: the contact law (normal spring-dashpot, tangential dashpot, Coulomb cap).
//! - [`integrate`]: the integrator: random kick, then the exact flow of every contact over
//!   the step (closed-form damped oscillator with the exact in-step start and end times),
//!   superposed over pairs.
//! - [`drift`]: the drift x += (v - c) h and the largest displacement since the list build.
//! - [`noise`]: bulk normals and the symmetrised kicks (variance 2 D dt / M^2 per component).
//! - [`neighbours`]: 1D ring neighbours; 2D cell-built Verlet lists with a skin.
//! - [`sim`]: [`RfmSim`], the state, initial layouts, checkpoints. Stream version 2
//!   ([`RfmSim::with_stream`]) draws the noise counter-addressed by (step, slot)
//!   ([`noise::Kicks::kick_counter`]); from [`sim::PARALLEL_MIN_PARTICLES`] particles a step
//!   runs its kicks, pair pass and drift in work blocks of fixed size on the current rayon
//!   pool, with sums and pair corrections in an order fixed by N: identical output for any
//!   thread count (version 1 draws its noise sequentially, the rest in blocks likewise).
//! - [`observe`]: warm-up, snapshots and the accumulators of a run; [`structure`]: 1D
//!   neighbour distances, 2D S(k), g(R) and C(R); [`freepath`]: free paths and
//!   post-collision velocities from per-particle contact counts (tracked inside the step).
//!
//! No rotation, no gravity (spec 1.2). The physics never imports the campaign or the store.
//!
//! # Effective restitution of the integrator
//!
//! Two discs (thesis M, k_s, r), head-on, relative speed 1 m/s, no noise, 50 contact-start
//! phases evenly spread over a step (test `sim::tests::restitution_table`): the exact pair
//! flow gives the nominal eps to round-off at every dt below half the contact time:
//!
//! | dt (s) | eps = 0.1: mean (range) | 0.3 | 0.6 | 0.9 |
//! |---|---|---|---|---|
//! | 1e-7 | 0.100000000000 (0.099999999985-0.100000000012) | 0.300000000000 (0.299999999986-0.300000000012) | 0.600000000003 (0.599999999991-0.600000000024) | 0.899999999998 (0.899999999980-0.900000000016) |
//! | 1e-6 | 0.100000000000 (0.099999999994-0.100000000004) | 0.300000000000 (0.299999999997-0.300000000004) | 0.600000000000 (0.599999999994-0.600000000004) | 0.900000000000 (0.899999999993-0.900000000005) |
//! | 2e-6 | 0.100000000000 (0.099999999997-0.100000000003) | 0.300000000000 (0.299999999998-0.300000000002) | 0.600000000000 (0.599999999997-0.600000000003) | 0.900000000000 (0.899999999994-0.900000000004) |
//! | 5e-6 | 0.100000000000 (0.099999999998-0.100000000003) | 0.300000000000 (0.299999999998-0.300000000001) | 0.600000000000 (0.599999999998-0.600000000002) | 0.900000000000 (0.899999999997-0.900000000003) |
//!
//! The residue (< 3e-11 relative) is the round-off of the overlap, a difference of positions
//! of order 0.05 m; it grows mildly with the number of steps per contact.
//!
//! (For comparison, LAMMPS gran/hooke at dt = 1e-6: 0.597 for 0.6 with phases 0.582-0.620,
//! 0.084 for 0.1 with 0.074-0.093.) The tangential relative velocity of a binary contact is
//! multiplied by eps_t^(omega_0/omega_d) (the thesis's force law with its undamped-time
//! calibration (2.12), spec 6.7), e.g. 0.058 for nominal eps_n = eps_t = 0.1 and 0.591 for
//! 0.6; [`RfmConfig::effective_tangential_restitution`] gives it.

pub mod blocks;
pub mod contact;
mod drift;
pub mod freepath;
pub mod integrate;
mod layout;
pub mod neighbours;
pub mod noise;
pub mod observe;
pub mod params;
pub mod sim;
pub mod structure;
mod team;

pub use params::{InitialLayout, RfmConfig};
pub use sim::{RfmSim, RfmState};
