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

use std::collections::BTreeMap;
use std::sync::Arc;

use arrow_array::{ArrayRef, RecordBatch, UInt32Array, UInt64Array};
use arrow_schema::{DataType, Field, Schema};
use schemars::JsonSchema;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::analysis::{Analysis, AnalysisError};
use crate::physics::PhysicsError;
use crate::plot::{Figure, Series};
use crate::store::cols::{Column, Columns};
use crate::store::dataset::Dataset;
use crate::store::parquet_io::StoreError;

/// Work per `advance` call: ~10 ms of trials, so interruption and checkpoints are prompt.
pub const WORK_CHUNK: u64 = 1 << 20;

/// Problems in a model's params: (JSON pointer, message).
pub type ParamErrors = Vec<(String, String)>;

/// Check a velocity range [v_min, v_max] (finite, v_min < v_max) at JSON pointer `at`.
pub fn check_velocity_range(range: [f64; 2], at: String, errors: &mut ParamErrors) {
    if !(range[0] < range[1] && range[0].is_finite() && range[1].is_finite()) {
        errors.push((
            at,
            format!("expected [v_min, v_max] with v_min < v_max, got {range:?}"),
        ));
    }
}

/// The most memory one run may need, as its model estimates it from its parameters (1 TiB):
/// a manifest asking for more is invalid on any machine (a typo, most likely). `run` also
/// refuses a run that does not fit in this machine's memory (`campaign::resources`).
pub const MAX_RUN_MEMORY: u64 = 1 << 40;

/// The window of every dimensional input of a model (masses, diameters, temperatures,
/// number densities, lengths, forces): 30 orders of magnitude either side of 1. Any physical
/// system in sensible units lies well inside (SI grains of nanometres to metres, reduced
/// units ~1); within it every product the engines and the theory form (n sigma^2 sqrt(T/m) t,
/// the energy of 2^32 particles, a temperature cooled by 1e-60 over 1e30 collision times, v^4
/// for a2, a spring force over a mass) stays far inside a double's range (1e+-308). Beyond
/// it, e.g. a DSMC `n1` of 1e308, the collision rate overflows.
pub const SCALE_MIN: f64 = 1e-30;
/// See [`SCALE_MIN`].
pub const SCALE_MAX: f64 = 1e30;

/// The most work one run may do, in its model's work units (the `runs` table's `trials`:
/// RFM particle steps, bisection and cascade grid cells, SPM walk steps, ...), as its
/// model's `check` counts it from the parameters: 10^15, about 10^7 CPU seconds (four months)
/// at the ~10^8 units per second of a `WORK_CHUNK` in ~10 ms. A run of more would never end
/// (`realisations` 1.8e19 was accepted and ran for ever).
pub const MAX_RUN_WORK: f64 = 1e15;

/// `value` deserialised as `T`; an error names the JSON pointer of the offending value (below
/// `path`), e.g. `/seed` for `"seed": 42.0`, which the schema takes for an integer.
pub fn from_value_at<T: DeserializeOwned>(value: Value, path: &str) -> Result<T, (String, String)> {
    serde_path_to_error::deserialize(value).map_err(|e| {
        let mut at = path.to_string();
        for seg in e.path().iter() {
            use serde_path_to_error::Segment;
            match seg {
                Segment::Seq { index } => at.push_str(&format!("/{index}")),
                Segment::Map { key } | Segment::Enum { variant: key } => {
                    at.push('/');
                    at.push_str(&key.replace('~', "~0").replace('/', "~1"));
                }
                Segment::Unknown => {}
            }
        }
        let mut message = e.inner().to_string();
        // serde_json appends " at line L column C", meaningless for a value.
        if let Some(i) = message.find(" at line ") {
            message.truncate(i);
        }
        if message.starts_with("invalid type: floating point") {
            message.push_str(" (an integer is written without a decimal point or exponent)");
        }
        (at, message)
    })
}

/// Bytes in words: `1.5 GB` (powers of 1000, as the memory messages of `resources`).
pub fn bytes_text(b: u64) -> String {
    let b = b as f64;
    if b >= 1e12 {
        format!("{:.1} TB", b / 1e12)
    } else if b >= 1e9 {
        format!("{:.1} GB", b / 1e9)
    } else {
        format!("{:.1} MB", b / 1e6)
    }
}

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
    fn start(p: &Self::Params, seed: u64) -> Result<Self::Sim, String>;
    /// Continue from `Simulation::state_bytes` (of layout `STATE_FORMAT`).
    fn restore(p: &Self::Params, state: &[u8]) -> Result<Self::Sim, String>;
    /// The rows of a finished run.
    fn finish(sim: Self::Sim, ids: RunIds) -> RunRows;
    /// What becomes of the finished runs of `old` when a manifest asks for `new`, two params
    /// that differ only in `HORIZON` keys.
    fn carry_over(_old: &Self::Params, _new: &Self::Params) -> CarryOver {
        CarryOver::Rerun("the model cannot continue a finished run".into())
    }
    /// The state a finished run keeps so that it can be continued (`None`: it cannot be). Its
    /// layout belongs to `STATE_FORMAT`: bump that when it changes.
    fn final_state(_sim: &mut Self::Sim) -> Option<Vec<u8>> {
        None
    }
    /// A run of `new` continuing, bit for bit as a run made straight to the new end, from a
    /// finished run's `final_state` (of a point that `carry_over` said `Continue` for).
    fn continue_from(_new: &Self::Params, _state: &[u8]) -> Result<Self::Sim, String> {
        Err("the model cannot continue a finished run".into())
    }
    /// Every table a campaign of these points has (raw, summaries, theory), in the order the
    /// parts of a commit are written.
    fn tables(points: &[&Self::Params]) -> Vec<&'static str>;
    /// The columns of its run tables, as (table, column), that a run of `p` fills with values
    /// although runs of other params leave them null (optional observables). A campaign
    /// written by an earlier granular may lack them: growth that would need one there is
    /// refused (`store::schema`). None by default.
    fn valued_columns(_p: &Self::Params) -> Vec<(&'static str, &'static str)> {
        Vec::new()
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

/// The identity of a run in its rows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RunIds {
    pub run_id: u64,
    pub point_id: u32,
}

/// What a finished run hands to the table writer.
#[derive(Debug, Default)]
pub struct RunRows {
    /// The `runs` table's `collisions`: accepted collisions (DSMC), else 0.
    pub collisions: u64,
    /// The `runs` table's `trials`, the model's count of work done (each model's `finish`
    /// says what: DSMC trials, RFM time steps, bisection and cascade realisations, SPM walk
    /// steps).
    pub trials: u64,
    /// The rows per table, each batch led by `run_id` and `point_id`.
    pub tables: Vec<(&'static str, RecordBatch)>,
}

/// One batch of a run's rows: `run_id` and `point_id`, then the model's columns.
pub fn run_batch<'a, T>(
    ids: RunIds,
    rows: &[T],
    columns: impl FnOnce(Columns<T>) -> Vec<Column<'a, T>>,
) -> RecordBatch {
    let n = rows.len();
    let (fields, cols) = crate::store::cols::build(rows, columns);
    let mut all = vec![
        Field::new("run_id", DataType::UInt64, false),
        Field::new("point_id", DataType::UInt32, false),
    ];
    all.extend(fields);
    let mut arrays: Vec<ArrayRef> = vec![
        Arc::new(UInt64Array::from(vec![ids.run_id; n])),
        Arc::new(UInt32Array::from(vec![ids.point_id; n])),
    ];
    arrays.extend(cols);
    RecordBatch::try_new(Arc::new(Schema::new(all)), arrays).expect("batch matches its schema")
}

/// A campaign as a model sees it: its points with their parameters, its finished runs, its
/// tables. `P` is the model's `Params` (or [`ModelParams`] before dispatch).
pub struct CampaignView<'a, P> {
    /// The campaign's name (figure titles).
    pub name: &'a str,
    pub points: Vec<PointView<'a, P>>,
    /// Replicas per point (an upper bound on the runs per point).
    pub replicas: u32,
    /// The runs finished with status done, and their replica numbers.
    pub done: &'a BTreeMap<u64, u32>,
    pub data: &'a Dataset,
    /// The swept parameters of every point: `point_id` and the `points` table's sweep
    /// columns (same names and types), one row per point; see [`CampaignView::write_summary`].
    pub sweep: RecordBatch,
}

impl<P> CampaignView<'_, P> {
    /// Write a replica summary whole (`tables/<table>/summary.parquet`): `batch`, whose rows
    /// each name their point in a `point_id` column, with the point's sweep columns right
    /// after `point_id` (so a summary is read without a join with `points`). Every summary
    /// goes through here; the model names no sweep key.
    pub fn write_summary(&self, table: &str, batch: &RecordBatch) -> Result<(), StoreError> {
        let batch = crate::store::cols::join_after_key(batch, table, "point_id", &self.sweep)?;
        self.data.write_whole(table, "summary.parquet", &batch)
    }
}

impl<P> CampaignView<'_, P> {
    /// The batches of a raw table (one row per run and more, with a `run_id` column) holding
    /// only the rows of the runs this view describes (`done`: the latest manifest's finished
    /// runs), as every figure drawn from a raw table must: rows of runs the latest manifest no
    /// longer asks for stay in the table but in no figure.
    pub fn read_done(&self, table: &str) -> Result<Vec<RecordBatch>, StoreError> {
        self.data
            .read(table)?
            .iter()
            .map(|b| self.keep_done(b, table))
            .collect()
    }

    /// The rows of `b` (of `table`, with a `run_id` column) of the runs in `done`.
    pub fn keep_done(&self, b: &RecordBatch, table: &str) -> Result<RecordBatch, StoreError> {
        let runs = crate::store::cols::get_u64(b, table, "run_id")?;
        let keep: arrow_array::BooleanArray = runs
            .iter()
            .map(|r| Some(r.is_some_and(|r| self.done.contains_key(&r))))
            .collect();
        arrow_select::filter::filter_record_batch(b, &keep)
            .map_err(|e| StoreError::Arrow(format!("{table}: {e}")))
    }
}

impl<P> CampaignView<'_, P> {
    /// The legend label of a point: its swept values (quotes dropped), `point <id>` without a
    /// sweep.
    pub fn point_label(&self, point: u32) -> String {
        let label = self
            .points
            .iter()
            .find(|p| p.point_id == point)
            .map(|p| p.label.replace('"', ""))
            .unwrap_or_default();
        if label.is_empty() {
            format!("point {point}")
        } else {
            label
        }
    }
}

/// Most points one overlay figure shows (one data series each, with its line): more are split
/// over several figures of as even a size as possible, so a 30-point campaign gives 3 figures
/// of 10 points per observable.
pub const OVERLAY_MAX: usize = 12;

/// `items` (in point order) split into the groups of the overlay figures (at most
/// [`OVERLAY_MAX`] each, sizes differing by at most one).
pub fn overlay_groups<T>(items: Vec<T>) -> Vec<Vec<T>> {
    let n = items.len().div_ceil(OVERLAY_MAX);
    let mut out: Vec<Vec<T>> = (0..n).map(|_| Vec::new()).collect();
    let len = items.len();
    for (i, x) in items.into_iter().enumerate() {
        out[i * n / len.max(1)].push(x);
    }
    out
}

/// Most (x, y, error) rows of a log-x series drawn as they are: S(k) of a large system has
/// thousands of shells, which [`log_binned`] averages for display.
pub const MAX_LOG_ROWS: usize = 400;

/// `rows` (sorted by x > 0) averaged in bins of `per_decade` per decade of x when there are
/// more than [`MAX_LOG_ROWS`]: per bin the geometric mean of x, the mean of y and
/// sqrt(sum err^2)/n (the rows' errors as independent); fewer rows are returned as they are.
pub fn log_binned(rows: &[(f64, f64, f64)], per_decade: f64) -> Vec<(f64, f64, f64)> {
    if rows.len() <= MAX_LOG_ROWS {
        return rows.to_vec();
    }
    let mut out = Vec::new();
    let mut bin: Vec<(f64, f64, f64)> = Vec::new();
    let key = |x: f64| (x.log10() * per_decade).floor() as i64;
    for &r in rows.iter().filter(|r| r.0 > 0.0) {
        if bin.last().is_some_and(|b| key(b.0) != key(r.0)) {
            out.push(average(&bin));
            bin.clear();
        }
        bin.push(r);
    }
    if !bin.is_empty() {
        out.push(average(&bin));
    }
    out
}

fn average(bin: &[(f64, f64, f64)]) -> (f64, f64, f64) {
    let n = bin.len() as f64;
    (
        (bin.iter().map(|r| r.0.ln()).sum::<f64>() / n).exp(),
        bin.iter().map(|r| r.1).sum::<f64>() / n,
        bin.iter().map(|r| r.2 * r.2).sum::<f64>().sqrt() / n,
    )
}

/// One observable drawn as overlay figures, one series per point.
pub struct Overlay<'a> {
    /// Figure id (`<id>`, or `<id>-<g>of<n>` when split).
    pub id: &'a str,
    /// Title after the campaign's name.
    pub what: &'a str,
    pub x_label: &'a str,
    pub y_label: &'a str,
    pub log_x: bool,
    pub log_y: bool,
    pub legend_low: bool,
}

/// (x, y, error) rows of a figure's series.
pub type Rows = Vec<(f64, f64, f64)>;

/// One point's curve of an [`Overlay`]: its (x, y, error) data, drawn as markers with error
/// bars, and an optional line drawn after it in its colour (exact result, theory, fit).
pub struct PointCurve {
    pub point: u32,
    pub label: String,
    pub data: Rows,
    /// (legend label, rows) of the line.
    pub line: Option<(String, Rows)>,
}

/// The figures of an overlay: the curves split by [`overlay_groups`], each figure followed by
/// the reference lines `refs` (own colours; each clipped to the figure's x range). No curve, no
/// figure.
pub fn overlay_figures(
    campaign: &str,
    o: &Overlay,
    curves: Vec<PointCurve>,
    refs: &dyn Fn(f64, f64) -> Vec<Series>,
) -> Vec<(String, Figure)> {
    let curves: Vec<PointCurve> = curves.into_iter().filter(|c| !c.data.is_empty()).collect();
    let groups = overlay_groups(curves);
    let n = groups.len();
    let mut out = Vec::new();
    for (g, group) in groups.into_iter().enumerate() {
        let (id, what) = if n == 1 {
            (o.id.to_string(), o.what.to_string())
        } else {
            let (a, b) = (group[0].point, group[group.len() - 1].point);
            (
                format!("{}-{}of{n}", o.id, g + 1),
                format!("{} (points {a}-{b})", o.what),
            )
        };
        let (mut x0, mut x1) = (f64::INFINITY, f64::NEG_INFINITY);
        let mut series = Vec::new();
        for c in group {
            for p in &c.data {
                if !o.log_x || p.0 > 0.0 {
                    x0 = x0.min(p.0);
                    x1 = x1.max(p.0);
                }
            }
            series.push(Series {
                label: c.label,
                points: c.data,
                line: false,
            });
            if let Some((label, points)) = c.line {
                series.push(Series {
                    label,
                    points,
                    line: true,
                });
            }
        }
        let first_ref = series.len();
        series.extend(refs(x0, x1));
        let mut fig = Figure::new(format!("{campaign} - {what}"), o.x_label, o.y_label, series);
        fig.log_x = o.log_x;
        fig.log_y = o.log_y;
        fig.legend_low = o.legend_low;
        if fig.series.len() > first_ref {
            fig = fig.with_references_from(first_ref);
        }
        out.push((id, fig));
    }
    out
}

/// One sweep point of a [`CampaignView`].
pub struct PointView<'a, P> {
    pub point_id: u32,
    pub params: &'a P,
    /// The swept values, `key=value, ...` (empty without a sweep).
    pub label: String,
    /// The swept values: each sweep key (a dotted path into `params`) with the point's value
    /// there, in the manifest's order (empty without a sweep).
    pub swept: Vec<(&'a str, &'a Value)>,
    /// How many of the view's finished runs (`CampaignView::done`) are of this point.
    pub runs_done: u32,
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
                        match from_value_at::<<$model as Model>::Params>(value.clone(), path) {
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

            pub fn start(&self, seed: u64) -> Result<Engine, String> {
                match self {
                    $(ModelParams::$variant(p) => {
                        Ok(Engine::$variant(Box::new(<$model as Model>::start(p, seed)?)))
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
            pub fn continue_from(&self, state: &[u8]) -> Result<Engine, String> {
                match self {
                    $(ModelParams::$variant(p) => Ok(Engine::$variant(Box::new(
                        <$model as Model>::continue_from(p, state)?,
                    ))),)+
                }
            }

            pub fn restore(&self, state: &[u8]) -> Result<Engine, String> {
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

            /// See [`Model::final_state`].
            pub fn final_state(&mut self) -> Option<Vec<u8>> {
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

/// Run one simulation to its end in memory, without a campaign directory (tests, benches).
pub fn run_in_memory(
    params: &ModelParams,
    seed: u64,
    ids: RunIds,
) -> Result<RunRows, PhysicsError> {
    let mut e = params
        .start(seed)
        .map_err(|reason| PhysicsError { t: 0.0, reason })?;
    while !e.advance(u64::MAX)? {}
    Ok(e.finish(ids))
}
