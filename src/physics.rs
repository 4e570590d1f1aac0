//! What every simulator shares with whoever drives it: the deterministic physics failure.
//! (The simulators themselves are `dsmc`, `rfm` and `aux_models`; they import neither the
//! manifest nor the store nor the campaign.)

use crate::exit_codes::{Classed, ExitClass};

/// A deterministic physics failure (the same seed fails the same way): what went wrong and
/// the simulated time (auxiliary models: realisations or walks done) at which it did.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{reason} at t = {t}")]
pub struct PhysicsError {
    pub t: f64,
    pub reason: String,
}

/// Why a simulation cannot be built or restored. A run that cannot start is recorded as
/// failed; state bytes that do not restore it (a checkpoint) make it run again from t = 0,
/// with a warning: never the process's exit.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    /// The configuration does not make a simulation (`new`): the run fails.
    #[error("{0}")]
    Config(String),
    /// State bytes (a checkpoint, a final state) that do not restore or continue this
    /// simulation: damaged, of another configuration, or not continuable to the new end.
    #[error("{0}")]
    State(String),
    /// A finished run's failure (`finish` of a run that failed).
    #[error("{0}")]
    Failed(String),
}

impl Classed for SimError {
    fn class(&self) -> ExitClass {
        ExitClass::RunFailed
    }
}

/// A message of a state function (`from_state_bytes`, `continue_from`): a [`SimError::State`].
impl From<String> for SimError {
    fn from(m: String) -> Self {
        SimError::State(m)
    }
}

/// See `From<String>`.
impl From<&str> for SimError {
    fn from(m: &str) -> Self {
        SimError::State(m.to_string())
    }
}
