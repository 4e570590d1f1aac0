//! One home per model. Each model's folder holds everything that is particular to it: its
//! manifest `params` (serde types, cross-field checks, the conversion into its simulator's own
//! configuration), the Arrow form of its rows, its replica summaries, its kinetic-theory tables
//! and its figures. The simulators themselves (`dsmc`, `rfm`, `aux_models`) know nothing of
//! manifests, tables or campaigns; the campaign knows no particular model.
//!
//! A model is a type implementing [`Model`]; the closed list of models is the one
//! [`models!`] invocation below, which generates [`ModelKind`] (the manifest's `model`),
//! [`ModelParams`] (a point's typed parameters) and [`Engine`] (a running simulation) and
//! the dispatch from each to the model's implementation. Adding a model adds a folder here and
//! one line to that list (see ARCHITECTURE.md, "Add a model").

pub mod bisection;
pub mod cascade;
pub mod dsmc;
pub mod rfm;
pub mod spm;

use schemars::JsonSchema;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::analysis::{Analysis, AnalysisError};
use crate::physics::PhysicsError;
use crate::plot::Figure;
use crate::rng::StreamVersion;
use crate::store::parquet_io::StoreError;

mod checks;
mod overlay;
mod rows;
mod view;
pub use checks::*;
pub use overlay::*;
pub use rows::*;
pub use view::*;

/// The params of model `M` among `points`.
fn typed<'p, M: Registered>(points: &[&'p ModelParams]) -> Vec<&'p M::Params> {
    points.iter().filter_map(|p| M::params(p)).collect()
}

/// The estimated cost of one point's kinetic-theory step: CPU seconds and peak bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TheoryEstimate {
    pub seconds: f64,
    pub bytes: f64,
}

/// Why a model's run cannot start, restore or continue. A run that cannot start is recorded
/// as failed; a state that does not restore or continue makes it run from t = 0, with a
/// warning (`campaign::worker`): never the process's exit.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    /// The params do not make the simulator's configuration.
    #[error("{0}")]
    Params(String),
    /// The simulator refused the configuration or the state.
    #[error(transparent)]
    Sim(#[from] crate::physics::SimError),
    /// The model keeps no final states.
    #[error("the model cannot continue a finished run")]
    NoContinuation,
}

impl crate::exit_codes::Classed for ModelError {
    fn class(&self) -> crate::exit_codes::ExitClass {
        crate::exit_codes::ExitClass::RunFailed
    }
}

/// Everything granular needs of a model.
pub trait Model {
    /// The manifest's `params` of this model (`deny_unknown_fields` serde types; the JSON
    /// Schema is generated from them).
    type Params: Serialize
        + DeserializeOwned
        + JsonSchema
        + Clone
        + std::fmt::Debug
        + PartialEq
        + Send
        + Sync;
    /// One run's simulation.
    type Sim: Simulation;

    /// Layout version of the simulation's checkpoint payload; bump it when the state changes
    /// (a checkpoint of another layout is then not restored, and the run starts over).
    const STATE_FORMAT: &'static str;
    /// Small valid `params`: a run of well under a second that still takes at least 4 chunks
    /// of 2000 work units (every model runs through the generic tests with them, restored at
    /// a random chunk).
    const EXAMPLE: &'static str;

    /// The top-level `params` keys that decide only how long a run goes on or what it reports
    /// on its way, never its trajectory: they are left out of the run's seed, so a longer run
    /// of the same point has the seeds of the shorter one and can continue it. None by default.
    const HORIZON: &'static [&'static str] = &[];

    /// The cross-field rules the JSON Schema cannot express; errors at JSON pointers below
    /// `path`.
    fn check(p: &Self::Params, path: &str, errors: &mut ParamErrors);
    /// An estimate of the memory (bytes) one run of these parameters holds at its peak.
    fn memory(p: &Self::Params) -> u64;
    /// A new run of seed `seed` drawing as the campaign's random stream version `stream`
    /// prescribes (a model whose draws no version changes ignores it).
    fn start(p: &Self::Params, seed: u64, stream: StreamVersion) -> Result<Self::Sim, ModelError>;
    /// Continue from `Simulation::state_bytes` (of layout `STATE_FORMAT`).
    fn restore(p: &Self::Params, state: &[u8]) -> Result<Self::Sim, ModelError>;
    /// The rows of a finished run.
    fn finish(sim: Self::Sim, ids: RunIds) -> RunRows;
    /// What becomes of the finished runs of `old` when a manifest asks for `new`, two params
    /// that differ only in `HORIZON` keys.
    fn carry_over(_old: &Self::Params, _new: &Self::Params) -> CarryOver {
        CarryOver::Rerun("the model cannot continue a finished run".into())
    }
    /// The state a finished run keeps so that it can be continued (`None`: it cannot be), as
    /// the parts whose concatenation it is (so that a large state is written without being
    /// copied into one buffer). Its layout belongs to `STATE_FORMAT`: bump that when it
    /// changes.
    fn final_state(_sim: &mut Self::Sim) -> Option<Vec<Vec<u8>>> {
        None
    }
    /// A run of `new` continuing, bit for bit as a run made straight to the new end, from a
    /// finished run's `final_state` (of a point that `carry_over` said `Continue` for).
    fn continue_from(_new: &Self::Params, _state: &[u8]) -> Result<Self::Sim, ModelError> {
        Err(ModelError::NoContinuation)
    }
    /// Every table a campaign of these points has (raw, summaries, theory), in the order the
    /// parts of a commit are written.
    fn tables(points: &[&Self::Params]) -> Vec<&'static str>;
    /// One line on what a row of the model's table `name` is and what it holds (`granular
    /// tables`); `None` for a name that is not one of its tables.
    fn table_description(name: &str) -> Option<&'static str>;
    /// The columns of its run tables, as (table, column), that a run of `p` fills with values
    /// although runs of other params leave them null (optional observables). A campaign
    /// written by an earlier granular may lack them: growth that would need one there is
    /// refused (`store::schema`). None by default.
    fn valued_columns(_p: &Self::Params) -> Vec<(&'static str, &'static str)> {
        Vec::new()
    }
    /// The physics name figures give a sweep key or column (`species.list.1.mass` -> `m_2`),
    /// where the manifest's `labels` name none; `None`: the key as it is (the default).
    fn physics_name(_key: &str) -> Option<String> {
        None
    }
    /// Every run table the model can write (name and Arrow schema, from its declarations),
    /// whatever the observables: what a derived quantity of the manifest may read. None by
    /// default (no derived quantity).
    fn run_tables() -> Vec<(&'static str, arrow_schema::SchemaRef)> {
        Vec::new()
    }
    /// The CPU seconds one run of `p` is expected to take on the reference machine (the
    /// model's cost model from its parameters: DSMC particles x collisions x time, MD
    /// particles x steps, ...; a deterministic function of `p`, so that decisions taken from
    /// it are the same on every machine). 1 by default.
    fn cost(_p: &Self::Params) -> f64 {
        1.0
    }
    /// The model's kinetic-theory tables (they depend only on the manifest); none by default.
    fn theory_tables(_points: &[&Self::Params]) -> Vec<&'static str> {
        Vec::new()
    }
    /// An estimate of the kinetic-theory step of one point of these params (what
    /// `write_theory` computes for it); zero for a model without theory.
    fn theory_estimate(_p: &Self::Params) -> TheoryEstimate {
        TheoryEstimate::default()
    }
    /// Write those of the theory tables that do not exist yet.
    fn write_theory(_c: &CampaignView<'_, Self::Params>) -> Result<(), StoreError> {
        Ok(())
    }
    /// Write the replica summaries (the campaign calls it once every run is finished).
    fn write_summaries(_c: &CampaignView<'_, Self::Params>) -> Result<(), StoreError> {
        Ok(())
    }
    /// The standard figures (name, figure) from the summary tables (or the run tables of a
    /// model without summaries), typically built with [`overlay_figures`]; `None` if the
    /// model has none.
    fn figures(
        _c: &CampaignView<'_, Self::Params>,
    ) -> Result<Option<Vec<(String, Figure)>>, StoreError> {
        Ok(None)
    }
    /// `granular analyze`: the function that records the model's fits across points (rows of
    /// `analysis_fits`, figures and their data) into an [`Analysis`], from the finished runs
    /// of the view, beginning with [`Analysis::start`]; `None` (the default): the model has
    /// no analysis.
    fn analysis() -> Option<AnalyzeFn<Self::Params>> {
        None
    }
}

/// A model's analysis (see [`Model::analysis`]).
pub type AnalyzeFn<P> = fn(&CampaignView<'_, P>, &mut Analysis) -> Result<(), AnalysisError>;

/// A running simulation as the campaign drives it: in bounded chunks, checkpointed between
/// them.
pub trait Simulation: Send {
    /// Advance by about `work` units (DSMC trials, RFM particle-steps, ...); `Ok(true)` when
    /// the run is complete. Chunking never changes the result.
    fn advance(&mut self, work: u64) -> Result<bool, PhysicsError>;
    /// Fraction of the run done, in [0, 1].
    fn progress(&self) -> f64;
    /// Simulated time reached (auxiliary models: realisations or walks done).
    fn time(&self) -> f64;
    /// Everything the run needs to continue bit for bit.
    fn state_bytes(&mut self) -> Vec<u8>;
    /// Whether the run draws as random stream version `stream` prescribes: a run restored from
    /// a checkpoint or continued from a final state that another campaign wrote may not (a
    /// model whose draws no version changes always does).
    fn draws_as(&self, _stream: StreamVersion) -> bool {
        true
    }
}

/// What becomes of the finished runs of a point when the manifest asks for the same point with
/// another horizon (`Model::HORIZON`: `t_end`, `duration`, ...).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum CarryOver {
    /// Longer: each run continues from its final state to the new end.
    Continue,
    /// Longer, but the runs cannot be continued (why): they are run again from the start.
    Rerun(String),
    /// Shorter than the runs already made (why): refused.
    Shorter(String),
}

impl<'a> CampaignView<'a, ModelParams> {
    fn typed<M: Registered>(&self) -> CampaignView<'a, M::Params> {
        CampaignView {
            name: self.name,
            points: self
                .points
                .iter()
                .filter_map(|p| {
                    M::params(p.params).map(|params| PointView {
                        point_id: p.point_id,
                        params,
                        label: p.label.clone(),
                        swept: p.swept.clone(),
                        runs_done: p.runs_done,
                    })
                })
                .collect(),
            replicas: self.replicas,
            labels: self.labels.clone(),
            done: self.done,
            data: self.data,
            sweep: self.sweep.clone(),
        }
    }
}

/// What the registry adds to a model: its place in the closed enums.
trait Registered: Model {
    fn params(p: &ModelParams) -> Option<&Self::Params>;
}

/// The closed list of models: `Variant = "name" => type`, with the doc comment that the
/// manifest's JSON Schema shows for the name.
macro_rules! models {
    ($($(#[doc = $doc:literal])* $variant:ident = $name:literal => $model:ty),+ $(,)?) => {
        /// The simulators `granular` knows.
        #[derive(Serialize, Deserialize, JsonSchema, Clone, Copy, Debug, PartialEq, Eq)]
        pub enum ModelKind {
            $($(#[doc = $doc])* #[serde(rename = $name)] $variant,)+
        }

        /// The parameters of one sweep point, typed by model.
        #[derive(Clone, Debug, PartialEq)]
        pub enum ModelParams {
            $($variant(<$model as Model>::Params),)+
        }

        /// A running simulation, typed by model.
        pub enum Engine {
            $($variant(Box<<$model as Model>::Sim>),)+
        }

        $(impl Registered for $model {
            fn params(p: &ModelParams) -> Option<&Self::Params> {
                #[allow(unreachable_patterns)]
                match p {
                    ModelParams::$variant(x) => Some(x),
                    _ => None,
                }
            }
        })+

        impl ModelKind {
            /// Every model, in the order of the list.
            pub const ALL: &'static [ModelKind] = &[$(ModelKind::$variant),+];

            pub fn as_str(self) -> &'static str {
                match self {
                    $(ModelKind::$variant => $name,)+
                }
            }

            /// The JSON Schema of the model's `params`, as a subschema of `generator`.
            pub fn params_subschema(
                self,
                generator: &mut schemars::SchemaGenerator,
            ) -> schemars::Schema {
                match self {
                    $(ModelKind::$variant => {
                        generator.subschema_for::<<$model as Model>::Params>()
                    })+
                }
            }

            /// The JSON Schema of the model's `params`, standalone.
            pub fn params_schema(self) -> Value {
                let mut generator =
                    schemars::generate::SchemaSettings::draft2020_12().into_generator();
                match self {
                    $(ModelKind::$variant => generator
                        .root_schema_for::<<$model as Model>::Params>()
                        .to_value(),)+
                }
            }

            /// Typed params from JSON (already checked against the schema), with the model's
            /// cross-field checks; problems are pushed onto `errors`.
            pub fn params_from(
                self,
                value: &Value,
                path: &str,
                errors: &mut ParamErrors,
            ) -> Option<ModelParams> {
                match self {
                    $(ModelKind::$variant => {
                        match from_value_at::<<$model as Model>::Params>(numbers_by_value(value.clone()), path) {
                            Ok(p) => {
                                let before = errors.len();
                                <$model as Model>::check(&p, path, errors);
                                // The estimate is meaningful (and cheap) only for checked params.
                                if errors.len() == before {
                                    let memory = <$model as Model>::memory(&p);
                                    if memory > MAX_RUN_MEMORY {
                                        errors.push((path.to_string(), format!(
                                            "a run needs about {} of memory (estimated from its parameters), more than the limit of {} TiB per run",
                                            bytes_text(memory), MAX_RUN_MEMORY >> 40
                                        )));
                                    }
                                }
                                Some(ModelParams::$variant(p))
                            }
                            Err(e) => {
                                errors.push(e);
                                None
                            }
                        }
                    })+
                }
            }

            /// Every table of a campaign of this model with these points.
            pub fn tables(self, points: &[&ModelParams]) -> Vec<&'static str> {
                match self {
                    $(ModelKind::$variant => <$model as Model>::tables(&typed::<$model>(points)),)+
                }
            }

            /// See [`Model::table_description`].
            pub fn table_description(self, name: &str) -> Option<&'static str> {
                match self {
                    $(ModelKind::$variant => <$model as Model>::table_description(name),)+
                }
            }

            /// The model's [`Model::physics_name`].
            pub fn physics_names(self) -> fn(&str) -> Option<String> {
                match self {
                    $(ModelKind::$variant => <$model as Model>::physics_name,)+
                }
            }

            /// See [`Model::run_tables`].
            pub fn run_tables(self) -> Vec<(&'static str, arrow_schema::SchemaRef)> {
                match self {
                    $(ModelKind::$variant => <$model as Model>::run_tables(),)+
                }
            }

            /// See [`Model::theory_tables`].
            pub fn theory_tables(self, points: &[&ModelParams]) -> Vec<&'static str> {
                match self {
                    $(ModelKind::$variant => {
                        <$model as Model>::theory_tables(&typed::<$model>(points))
                    })+
                }
            }

            /// See [`Model::write_theory`].
            pub fn write_theory(self, c: &CampaignView<'_, ModelParams>) -> Result<(), StoreError> {
                match self {
                    $(ModelKind::$variant => <$model as Model>::write_theory(&c.typed::<$model>()),)+
                }
            }

            /// See [`Model::write_summaries`].
            pub fn write_summaries(self, c: &CampaignView<'_, ModelParams>) -> Result<(), StoreError> {
                match self {
                    $(ModelKind::$variant => {
                        <$model as Model>::write_summaries(&c.typed::<$model>())
                    })+
                }
            }

            /// See [`Model::figures`].
            pub fn figures(
                self,
                c: &CampaignView<'_, ModelParams>,
            ) -> Result<Option<Vec<(String, Figure)>>, StoreError> {
                match self {
                    $(ModelKind::$variant => <$model as Model>::figures(&c.typed::<$model>()),)+
                }
            }

            /// The model's analysis of `c` into `a` (see [`Model::analysis`]); `None` if it
            /// has none.
            pub fn analyze(
                self,
                c: &CampaignView<'_, ModelParams>,
                a: &mut Analysis,
            ) -> Option<Result<(), AnalysisError>> {
                match self {
                    $(ModelKind::$variant => {
                        <$model as Model>::analysis().map(|f| f(&c.typed::<$model>(), a))
                    })+
                }
            }

            /// Whether the model has an analysis (see [`Model::analysis`]).
            pub fn has_analysis(self) -> bool {
                match self {
                    $(ModelKind::$variant => <$model as Model>::analysis().is_some(),)+
                }
            }

            /// See [`Model::HORIZON`].
            pub fn horizon(self) -> &'static [&'static str] {
                match self {
                    $(ModelKind::$variant => <$model as Model>::HORIZON,)+
                }
            }

            /// The example params of the model (see [`Model::EXAMPLE`]).
            pub fn example(self) -> &'static str {
                match self {
                    $(ModelKind::$variant => <$model as Model>::EXAMPLE,)+
                }
            }
        }

        impl ModelParams {
            pub fn kind(&self) -> ModelKind {
                match self {
                    $(ModelParams::$variant(_) => ModelKind::$variant,)+
                }
            }

            /// The params as JSON (the `points` table).
            pub fn to_value(&self) -> Value {
                match self {
                    $(ModelParams::$variant(p) => serde_json::to_value(p),)+
                }
                .expect("params serialise")
            }

            /// See [`Model::memory`].
            pub fn memory(&self) -> u64 {
                match self {
                    $(ModelParams::$variant(p) => <$model as Model>::memory(p),)+
                }
            }

            /// See [`Model::cost`].
            pub fn cost(&self) -> f64 {
                match self {
                    $(ModelParams::$variant(p) => <$model as Model>::cost(p),)+
                }
            }

            /// See [`Model::theory_estimate`].
            pub fn theory_estimate(&self) -> TheoryEstimate {
                match self {
                    $(ModelParams::$variant(p) => <$model as Model>::theory_estimate(p),)+
                }
            }

            /// See [`Model::valued_columns`].
            pub fn valued_columns(&self) -> Vec<(&'static str, &'static str)> {
                match self {
                    $(ModelParams::$variant(p) => <$model as Model>::valued_columns(p),)+
                }
            }

            /// The layout a checkpoint of this model must have.
            pub fn state_format(&self) -> &'static str {
                match self {
                    $(ModelParams::$variant(_) => <$model as Model>::STATE_FORMAT,)+
                }
            }

            /// See [`Model::start`].
            pub fn start(&self, seed: u64, stream: StreamVersion) -> Result<Engine, ModelError> {
                match self {
                    $(ModelParams::$variant(p) => {
                        Ok(Engine::$variant(Box::new(<$model as Model>::start(p, seed, stream)?)))
                    })+
                }
            }

            /// See [`Model::carry_over`] (params of another model: a rerun).
            pub fn carry_over(&self, new: &ModelParams) -> CarryOver {
                match (self, new) {
                    $((ModelParams::$variant(old), ModelParams::$variant(new)) => {
                        <$model as Model>::carry_over(old, new)
                    })+
                    #[allow(unreachable_patterns)]
                    _ => CarryOver::Rerun("another model".into()),
                }
            }

            /// See [`Model::continue_from`].
            pub fn continue_from(&self, state: &[u8]) -> Result<Engine, ModelError> {
                match self {
                    $(ModelParams::$variant(p) => Ok(Engine::$variant(Box::new(
                        <$model as Model>::continue_from(p, state)?,
                    ))),)+
                }
            }

            pub fn restore(&self, state: &[u8]) -> Result<Engine, ModelError> {
                match self {
                    $(ModelParams::$variant(p) => {
                        Ok(Engine::$variant(Box::new(<$model as Model>::restore(p, state)?)))
                    })+
                }
            }
        }

        impl Engine {
            // Each call dispatched statically to the concrete simulator (no `dyn Simulation`).

            /// See [`Simulation::advance`].
            pub fn advance(&mut self, work: u64) -> Result<bool, PhysicsError> {
                match self {
                    $(Engine::$variant(s) => Simulation::advance(s.as_mut(), work),)+
                }
            }

            pub fn progress(&self) -> f64 {
                match self {
                    $(Engine::$variant(s) => Simulation::progress(s.as_ref()),)+
                }
            }

            pub fn time(&self) -> f64 {
                match self {
                    $(Engine::$variant(s) => Simulation::time(s.as_ref()),)+
                }
            }

            pub fn state_bytes(&mut self) -> Vec<u8> {
                match self {
                    $(Engine::$variant(s) => Simulation::state_bytes(s.as_mut()),)+
                }
            }

            /// See [`Simulation::draws_as`].
            pub fn draws_as(&self, stream: StreamVersion) -> bool {
                match self {
                    $(Engine::$variant(s) => Simulation::draws_as(s.as_ref(), stream),)+
                }
            }

            /// See [`Model::final_state`].
            pub fn final_state(&mut self) -> Option<Vec<Vec<u8>>> {
                match self {
                    $(Engine::$variant(s) => <$model as Model>::final_state(s),)+
                }
            }

            /// The rows of the finished run.
            pub fn finish(self, ids: RunIds) -> RunRows {
                match self {
                    $(Engine::$variant(s) => <$model as Model>::finish(*s, ids),)+
                }
            }
        }
    };
}

models! {
    /// Direct simulation Monte Carlo of a polydisperse granular gas (homogeneous cooling).
    Dsmc = "dsmc" => dsmc::Dsmc,
    /// Soft-sphere molecular dynamics of the Random Force Model (driven granular gas, 1D/2D).
    Rfm = "rfm" => rfm::Rfm,
    /// Multiplicative bisection of [0, 1] (thesis sec. 3.4; spec 3.1).
    Bisection = "bisection" => bisection::Bisection,
    /// Multiplicative cascade on a 2^n x 2^n grid, S(k), D_f, particle placement (ch. 6).
    Cascade = "cascade" => cascade::Cascade,
    /// Single particle model: Q(v, l) and P(v) from a free-path distribution (sec. 5.2-5.3).
    Spm = "spm" => spm::Spm,
}

/// Run one simulation to its end in memory, without a campaign directory (tests, benches),
/// drawing as random stream version `stream`.
pub fn run_in_memory(
    params: &ModelParams,
    seed: u64,
    stream: StreamVersion,
    ids: RunIds,
) -> Result<RunRows, PhysicsError> {
    let mut e = params.start(seed, stream).map_err(|e| PhysicsError {
        t: 0.0,
        reason: e.to_string(),
    })?;
    while !e.advance(u64::MAX)? {}
    Ok(e.finish(ids))
}
