//! What every simulator shares with whoever drives it: the deterministic physics failure.
//! (The simulators themselves are `dsmc`, `rfm` and `aux_models`; they import neither the
//! manifest nor the store nor the campaign.)

/// A deterministic physics failure (the same seed fails the same way): what went wrong and
/// the simulated time (auxiliary models: realisations or walks done) at which it did.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{reason} at t = {t}")]
pub struct PhysicsError {
    pub t: f64,
    pub reason: String,
}
