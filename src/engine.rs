//! The closed set of simulators a campaign drives, behind one small interface: start or
//! restore, advance in bounded chunks, checkpoint, finish with rows.

use crate::dsmc::{DsmcSim, DsmcSystem, PhysicsError, SpeciesRow, TamsdRow};
use crate::plan::ModelParams;
use crate::rfm::observe::{RfmOutput, RfmRun};

/// Layout version of the RFM checkpoint payload.
pub const RFM_STATE_FORMAT: &str = "rfm/4";

/// Rows and counters a finished run hands to the writer.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunOutput {
    pub dsmc_species: Vec<SpeciesRow>,
    /// Time-averaged MSD per species and lag (empty unless `tamsd` is observed).
    pub dsmc_tamsd: Vec<TamsdRow>,
    /// The rows of a Random Force Model run.
    pub rfm: Option<RfmOutput>,
    /// DSMC: accepted collisions; RFM: 0.
    pub collisions: u64,
    /// DSMC: trials; RFM: time steps.
    pub trials: u64,
}

pub enum Engine {
    Dsmc(Box<DsmcSim>),
    Rfm(Box<RfmRun>),
}

impl Engine {
    pub fn start(params: &ModelParams, seed: u64) -> Result<Engine, String> {
        match params {
            ModelParams::Dsmc(p) => Ok(Engine::Dsmc(Box::new(DsmcSim::new(
                DsmcSystem::from_params(p)?,
                seed,
            )))),
            ModelParams::Rfm(p) => Ok(Engine::Rfm(Box::new(RfmRun::new(p, seed)?))),
        }
    }

    pub fn restore(params: &ModelParams, bytes: &[u8]) -> Result<Engine, String> {
        match params {
            ModelParams::Dsmc(p) => Ok(Engine::Dsmc(Box::new(DsmcSim::from_state_bytes(
                DsmcSystem::from_params(p)?,
                bytes,
            )?))),
            ModelParams::Rfm(p) => Ok(Engine::Rfm(Box::new(RfmRun::from_state_bytes(p, bytes)?))),
        }
    }

    /// Advance by a bounded amount of work (DSMC trials; RFM particle-steps); `Ok(true)`
    /// when the run is complete.
    pub fn advance(&mut self, work: u64) -> Result<bool, PhysicsError> {
        match self {
            Engine::Dsmc(s) => s.advance(work),
            Engine::Rfm(r) => {
                let n = r.sim.config().n_particles.max(1) as u64;
                r.advance((work / n).max(1))
            }
        }
    }

    pub fn progress(&self) -> f64 {
        match self {
            Engine::Dsmc(s) => s.progress(),
            Engine::Rfm(r) => r.progress(),
        }
    }

    /// Simulated time reached.
    pub fn time(&self) -> f64 {
        match self {
            Engine::Dsmc(s) => s.st.t,
            Engine::Rfm(r) => r.sim.time(),
        }
    }

    /// Layout version of `state_bytes`; bump when the state struct changes.
    pub fn state_format(&self) -> &'static str {
        match self {
            Engine::Dsmc(_) => crate::dsmc::STATE_FORMAT,
            Engine::Rfm(_) => RFM_STATE_FORMAT,
        }
    }

    /// The state format a checkpoint of this model must have.
    pub fn expected_state_format(params: &ModelParams) -> &'static str {
        match params {
            ModelParams::Dsmc(_) => crate::dsmc::STATE_FORMAT,
            ModelParams::Rfm(_) => RFM_STATE_FORMAT,
        }
    }

    pub fn state_bytes(&mut self) -> Vec<u8> {
        match self {
            Engine::Dsmc(s) => s.state_bytes(),
            Engine::Rfm(r) => r.state_bytes(),
        }
    }

    pub fn finish(self) -> RunOutput {
        match self {
            Engine::Dsmc(mut s) => RunOutput {
                dsmc_tamsd: s.tamsd_rows(),
                dsmc_species: s.take_rows(),
                rfm: None,
                collisions: s.st.collisions,
                trials: s.st.trials,
            },
            Engine::Rfm(r) => {
                let steps = r.sim.step();
                RunOutput {
                    rfm: Some(r.finish()),
                    trials: steps,
                    ..RunOutput::default()
                }
            }
        }
    }
}

/// Work per `advance` call: ~10 ms of trials, so interruption and checkpoints are prompt.
pub const WORK_CHUNK: u64 = 1 << 20;
