//! The closed set of simulators a campaign drives, behind one small interface: start or
//! restore, advance in bounded chunks, checkpoint, finish with rows.

use crate::dsmc::{DsmcSim, DsmcSystem, PhysicsError, SpeciesRow, TamsdRow};
use crate::plan::ModelParams;

/// Rows and counters a finished run hands to the writer.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunOutput {
    pub dsmc_species: Vec<SpeciesRow>,
    /// Time-averaged MSD per species and lag (empty unless `tamsd` is observed).
    pub dsmc_tamsd: Vec<TamsdRow>,
    pub collisions: u64,
    pub trials: u64,
}

pub enum Engine {
    Dsmc(Box<DsmcSim>),
}

impl Engine {
    pub fn start(params: &ModelParams, seed: u64) -> Result<Engine, String> {
        match params {
            ModelParams::Dsmc(p) => Ok(Engine::Dsmc(Box::new(DsmcSim::new(
                DsmcSystem::from_params(p)?,
                seed,
            )))),
        }
    }

    pub fn restore(params: &ModelParams, bytes: &[u8]) -> Result<Engine, String> {
        match params {
            ModelParams::Dsmc(p) => Ok(Engine::Dsmc(Box::new(DsmcSim::from_state_bytes(
                DsmcSystem::from_params(p)?,
                bytes,
            )?))),
        }
    }

    /// Advance by a bounded amount of work; `Ok(true)` when the run is complete.
    pub fn advance(&mut self, work: u64) -> Result<bool, PhysicsError> {
        match self {
            Engine::Dsmc(s) => s.advance(work),
        }
    }

    pub fn progress(&self) -> f64 {
        match self {
            Engine::Dsmc(s) => s.progress(),
        }
    }

    /// Simulated time reached.
    pub fn time(&self) -> f64 {
        match self {
            Engine::Dsmc(s) => s.st.t,
        }
    }

    /// Layout version of `state_bytes`; bump when the state struct changes.
    pub fn state_format(&self) -> &'static str {
        match self {
            Engine::Dsmc(_) => crate::dsmc::STATE_FORMAT,
        }
    }

    pub fn state_bytes(&mut self) -> Vec<u8> {
        match self {
            Engine::Dsmc(s) => s.state_bytes(),
        }
    }

    pub fn finish(self) -> RunOutput {
        match self {
            Engine::Dsmc(mut s) => RunOutput {
                dsmc_tamsd: s.tamsd_rows(),
                dsmc_species: s.take_rows(),
                collisions: s.st.collisions,
                trials: s.st.trials,
            },
        }
    }
}

/// Work per `advance` call: ~10 ms of trials, so interruption and checkpoints are prompt.
pub const WORK_CHUNK: u64 = 1 << 20;
