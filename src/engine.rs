//! The closed set of simulators a campaign drives, behind one small interface: start or
//! restore, advance in bounded chunks, checkpoint, finish with rows.

use crate::aux_models::bisection::BisectionRun;
use crate::aux_models::cascade::{CascadeOutput, CascadeRun};
use crate::aux_models::spm::SpmRun;
use crate::aux_models::AuxOutput;
use crate::dsmc::{DsmcSim, DsmcSystem, PhysicsError, SpeciesRow, TamsdRow};
use crate::plan::ModelParams;
use crate::rfm::observe::{RfmOutput, RfmRun};

/// Layout version of the RFM checkpoint payload.
pub const RFM_STATE_FORMAT: &str = "rfm/4";
/// Layout versions of the auxiliary models' checkpoint payloads.
pub const BISECTION_STATE_FORMAT: &str = "bisection/1";
pub const CASCADE_STATE_FORMAT: &str = "cascade/1";
pub const SPM_STATE_FORMAT: &str = "spm/1";

/// Rows and counters a finished run hands to the writer.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunOutput {
    pub dsmc_species: Vec<SpeciesRow>,
    /// Time-averaged MSD per species and lag (empty unless `tamsd` is observed).
    pub dsmc_tamsd: Vec<TamsdRow>,
    /// The rows of a Random Force Model run.
    pub rfm: Option<RfmOutput>,
    /// The rows of an auxiliary-model run (bisection, cascade, spm).
    pub aux: Option<AuxOutput>,
    /// DSMC: accepted collisions; others: 0.
    pub collisions: u64,
    /// DSMC: trials; RFM: time steps; bisection and cascade: realisations; SPM: walk steps.
    pub trials: u64,
}

pub enum Engine {
    Dsmc(Box<DsmcSim>),
    Rfm(Box<RfmRun>),
    Bisection(Box<BisectionRun>),
    Cascade(Box<CascadeRun>),
    Spm(Box<SpmRun>),
}

impl Engine {
    pub fn start(params: &ModelParams, seed: u64) -> Result<Engine, String> {
        match params {
            ModelParams::Dsmc(p) => Ok(Engine::Dsmc(Box::new(DsmcSim::new(
                DsmcSystem::from_params(p)?,
                seed,
            )))),
            ModelParams::Rfm(p) => Ok(Engine::Rfm(Box::new(RfmRun::new(p, seed)?))),
            ModelParams::Bisection(p) => Ok(Engine::Bisection(Box::new(BisectionRun::new(
                p.config(),
                seed,
            )))),
            ModelParams::Cascade(p) => {
                Ok(Engine::Cascade(Box::new(CascadeRun::new(p.config(), seed))))
            }
            ModelParams::Spm(p) => Ok(Engine::Spm(Box::new(SpmRun::new(p.config(), seed)))),
        }
    }

    pub fn restore(params: &ModelParams, bytes: &[u8]) -> Result<Engine, String> {
        match params {
            ModelParams::Dsmc(p) => Ok(Engine::Dsmc(Box::new(DsmcSim::from_state_bytes(
                DsmcSystem::from_params(p)?,
                bytes,
            )?))),
            ModelParams::Rfm(p) => Ok(Engine::Rfm(Box::new(RfmRun::from_state_bytes(p, bytes)?))),
            ModelParams::Bisection(p) => Ok(Engine::Bisection(Box::new(
                BisectionRun::from_state_bytes(p.config(), bytes)?,
            ))),
            ModelParams::Cascade(p) => Ok(Engine::Cascade(Box::new(CascadeRun::from_state_bytes(
                p.config(),
                bytes,
            )?))),
            ModelParams::Spm(p) => Ok(Engine::Spm(Box::new(SpmRun::from_state_bytes(
                p.config(),
                bytes,
            )?))),
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
            Engine::Bisection(r) => Ok(r.advance((work / r.work_per_realisation()).max(1))),
            Engine::Cascade(r) => {
                let done = r.advance(work);
                match r.failed() {
                    Some(reason) => Err(PhysicsError {
                        t: r.done() as f64,
                        reason: reason.to_string(),
                    }),
                    None => Ok(done),
                }
            }
            Engine::Spm(r) => Ok(r.advance(work)),
        }
    }

    pub fn progress(&self) -> f64 {
        match self {
            Engine::Dsmc(s) => s.progress(),
            Engine::Rfm(r) => r.progress(),
            Engine::Bisection(r) => r.progress(),
            Engine::Cascade(r) => r.progress(),
            Engine::Spm(r) => r.progress(),
        }
    }

    /// Simulated time reached (auxiliary models: realisations or walks done).
    pub fn time(&self) -> f64 {
        match self {
            Engine::Dsmc(s) => s.time(),
            Engine::Rfm(r) => r.sim.time(),
            Engine::Bisection(r) => r.done() as f64,
            Engine::Cascade(r) => r.done() as f64,
            Engine::Spm(r) => r.done() as f64,
        }
    }

    /// Layout version of `state_bytes`; bump when the state struct changes.
    pub fn state_format(&self) -> &'static str {
        match self {
            Engine::Dsmc(_) => crate::dsmc::STATE_FORMAT,
            Engine::Rfm(_) => RFM_STATE_FORMAT,
            Engine::Bisection(_) => BISECTION_STATE_FORMAT,
            Engine::Cascade(_) => CASCADE_STATE_FORMAT,
            Engine::Spm(_) => SPM_STATE_FORMAT,
        }
    }

    /// The state format a checkpoint of this model must have.
    pub fn expected_state_format(params: &ModelParams) -> &'static str {
        match params {
            ModelParams::Dsmc(_) => crate::dsmc::STATE_FORMAT,
            ModelParams::Rfm(_) => RFM_STATE_FORMAT,
            ModelParams::Bisection(_) => BISECTION_STATE_FORMAT,
            ModelParams::Cascade(_) => CASCADE_STATE_FORMAT,
            ModelParams::Spm(_) => SPM_STATE_FORMAT,
        }
    }

    pub fn state_bytes(&mut self) -> Vec<u8> {
        match self {
            Engine::Dsmc(s) => s.state_bytes(),
            Engine::Rfm(r) => r.state_bytes(),
            Engine::Bisection(r) => r.state_bytes(),
            Engine::Cascade(r) => r.state_bytes(),
            Engine::Spm(r) => r.state_bytes(),
        }
    }

    pub fn finish(self) -> RunOutput {
        match self {
            Engine::Dsmc(mut s) => RunOutput {
                dsmc_tamsd: s.tamsd_rows(),
                dsmc_species: s.take_rows(),
                rfm: None,
                aux: None,
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
            Engine::Bisection(r) => {
                let out = r.finish();
                RunOutput {
                    trials: out.realisations,
                    aux: Some(AuxOutput::Bisection(out)),
                    ..RunOutput::default()
                }
            }
            Engine::Cascade(r) => {
                let trials = r.done();
                // A failed placement is reported by `advance`, so finish sees none.
                let out = r.finish().unwrap_or(CascadeOutput {
                    structure_factor: Vec::new(),
                    fits: Vec::new(),
                    placement: Vec::new(),
                });
                RunOutput {
                    trials,
                    aux: Some(AuxOutput::Cascade(out)),
                    ..RunOutput::default()
                }
            }
            Engine::Spm(r) => {
                let out = r.finish();
                RunOutput {
                    trials: out.summary.samples / 2,
                    aux: Some(AuxOutput::Spm(out)),
                    ..RunOutput::default()
                }
            }
        }
    }
}

/// Work per `advance` call: ~10 ms of trials, so interruption and checkpoints are prompt.
pub const WORK_CHUNK: u64 = 1 << 20;
