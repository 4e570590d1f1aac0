//! The campaign's own tables, whatever the model: `runs` (one row per finished run) and
//! `points` (one row per registered point, with the swept parameters of the latest manifest as
//! typed columns and whether it still asks for the point); and those sweep columns by point
//! (`sweep_batch`), which every summary table carries too.

use std::sync::Arc;

use arrow_array::builder::{BooleanBuilder, Float64Builder, Int64Builder, StringBuilder};
use arrow_array::{ArrayRef, RecordBatch};
use arrow_schema::{DataType, Field, Schema};
use serde_json::Value;

use super::plan::{canonical, Plan};
use crate::declare_table;
use crate::store::cols::table;
use crate::store::typed::{Absent, OptF64, OptStr, OptU64, Str, F64, U32, U64};

pub const RUNS: &str = RunsTable::TABLE;
pub const POINTS: &str = "points";
pub const REGISTERED_RUNS: &str = "registered_runs";

/// One line on what a row of each of the campaign's own tables is and what it holds (those of
/// every model, and of `granular analyze`), for `granular tables`; `None` for another name
/// (a model's tables are described by the model: `ModelKind::table_description`).
pub fn description(name: &str) -> Option<&'static str> {
    Some(match name {
        RUNS => "one row per finished run: point, replica, seed, done or failed (and why), wall seconds, work counts, the run it continued",
        POINTS => "one row per point the campaign has ever had: its sweep values as typed columns, complete params as JSON, whether the latest manifest asks for it",
        REGISTERED_RUNS => "one row per run ever registered, finished or not: point, replica, seed, the run it continues, whether (and as which replica) the latest manifest asks for it",
        super::derived_tables::DERIVED => "one row per finished run (and time): the manifest's derived quantities",
        super::derived_tables::DERIVED_SUMMARY => "one row per point (and time): each derived quantity's mean, standard error and n over replicas",
        crate::analysis::ANALYSIS_FITS => "one row per quantity fitted by `granular analyze` (and key): value, error, reduced chi2, points and window, reference, quality",
        crate::analysis::ANALYSIS_CURVES => "one row per point of a curve `granular analyze` drew: figure, series, x, y, error",
        _ => return None,
    })
}

/// How a swept parameter is stored: as a typed column, never as a string of a number.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SweepKind {
    Int,
    Float,
    Bool,
    Str,
    /// Objects, arrays or mixed types: canonical JSON text.
    Json,
}

#[derive(Clone, Debug)]
pub struct SweepColumn {
    pub name: String,
    pub kind: SweepKind,
}

/// The typed sweep columns of a plan (points without a value at a key hold null there).
pub fn sweep_columns(plan: &Plan) -> Vec<SweepColumn> {
    plan.sweep_keys
        .iter()
        .enumerate()
        .map(|(j, key)| {
            let vals: Vec<&Value> = plan
                .points
                .iter()
                .map(|p| &p.values[j])
                .filter(|v| !v.is_null())
                .collect();
            let kind = if vals.iter().all(|v| v.is_i64() || v.is_u64()) {
                SweepKind::Int
            } else if vals.iter().all(|v| v.is_number()) {
                SweepKind::Float
            } else if vals.iter().all(|v| v.is_boolean()) {
                SweepKind::Bool
            } else if vals.iter().all(|v| v.is_string()) {
                SweepKind::Str
            } else {
                SweepKind::Json
            };
            SweepColumn {
                name: Plan::sweep_column(key),
                kind,
            }
        })
        .collect()
}

fn sweep_fields(cols: &[SweepColumn]) -> Vec<Field> {
    cols.iter()
        .map(|c| {
            let dt = match c.kind {
                SweepKind::Int => DataType::Int64,
                SweepKind::Float => DataType::Float64,
                SweepKind::Bool => DataType::Boolean,
                SweepKind::Str | SweepKind::Json => DataType::Utf8,
            };
            Field::new(&c.name, dt, true)
        })
        .collect()
}

fn sweep_arrays(cols: &[SweepColumn], values: &[&[Value]]) -> Vec<ArrayRef> {
    cols.iter()
        .enumerate()
        .map(|(j, c)| -> ArrayRef {
            let at =
                |v: &&[Value]| -> Option<Value> { Some(v[j].clone()).filter(|x| !x.is_null()) };
            match c.kind {
                SweepKind::Int => {
                    let mut b = Int64Builder::new();
                    values.iter().for_each(|v| {
                        b.append_option(
                            at(v).map(|x| x.as_i64().unwrap_or(x.as_u64().unwrap_or(0) as i64)),
                        )
                    });
                    Arc::new(b.finish())
                }
                SweepKind::Float => {
                    let mut b = Float64Builder::new();
                    values.iter().for_each(|v| {
                        b.append_option(at(v).map(|x| x.as_f64().unwrap_or(f64::NAN)))
                    });
                    Arc::new(b.finish())
                }
                SweepKind::Bool => {
                    let mut b = BooleanBuilder::new();
                    values
                        .iter()
                        .for_each(|v| b.append_option(at(v).map(|x| x.as_bool().unwrap_or(false))));
                    Arc::new(b.finish())
                }
                SweepKind::Str => {
                    let mut b = StringBuilder::new();
                    values.iter().for_each(|v| {
                        b.append_option(at(v).map(|x| x.as_str().unwrap_or("").to_string()))
                    });
                    Arc::new(b.finish())
                }
                SweepKind::Json => {
                    let mut b = StringBuilder::new();
                    values
                        .iter()
                        .for_each(|v| b.append_option(at(v).map(|x| canonical(&x))));
                    Arc::new(b.finish())
                }
            }
        })
        .collect()
}

/// One row of the `runs` table.
#[derive(Clone, Debug, PartialEq)]
pub struct RunRow {
    pub run_id: u64,
    pub point_id: u32,
    pub replica: u32,
    pub seed: u64,
    /// "done" or "failed".
    pub status: String,
    pub reason: Option<String>,
    /// Simulated time at which a failed run stopped.
    pub t_failed: Option<f64>,
    pub wall_seconds: f64,
    pub collisions: u64,
    pub trials: u64,
    /// The run this one continued from its final state (a longer horizon of its point).
    pub continued_from: Option<u64>,
}

declare_table! {
    /// `runs`: one row per finished run (its point's parameters are in `points`), as written
    /// and read ([`RunRow`] is what the writer is handed: the row without `code_version`).
    pub struct RunsTable in "runs", read as RunsTableCols {
        run_id: U64,
        point_id: U32,
        replica: U32,
        seed: U64,
        /// "done" or "failed".
        status: Str,
        reason: OptStr,
        t_failed: OptF64,
        wall_seconds: F64,
        collisions: U64,
        trials: U64,
        /// Null in the rows of format 1 (`granular upgrade`).
        continued_from: Absent<OptU64>,
        code_version: Str,
    }
}

/// `runs`: one row per finished run (its point's parameters are in `points`).
pub fn runs_batch(rows: &[RunRow]) -> RecordBatch {
    let rows: Vec<RunsTable> = rows
        .iter()
        .map(|r| RunsTable {
            run_id: r.run_id,
            point_id: r.point_id,
            replica: r.replica,
            seed: r.seed,
            status: r.status.clone(),
            reason: r.reason.clone(),
            t_failed: r.t_failed,
            wall_seconds: r.wall_seconds,
            collisions: r.collisions,
            trials: r.trials,
            continued_from: r.continued_from,
            code_version: crate::CODE_VERSION.to_string(),
        })
        .collect();
    RunsTable::batch(&rows)
}

/// `point_id` and the typed sweep columns of every registered point (the latest manifest's
/// keys): the head of the `points` table, and the columns every summary table carries after
/// its `point_id` (`CampaignView::write_summary`).
pub fn sweep_batch(plan: &Plan) -> RecordBatch {
    let cols = sweep_columns(plan);
    let mut fields = vec![Field::new("point_id", DataType::UInt32, false)];
    fields.extend(sweep_fields(&cols));
    let mut arrays: Vec<ArrayRef> = vec![Arc::new(
        plan.points
            .iter()
            .map(|p| p.point_id)
            .collect::<arrow_array::UInt32Array>(),
    )];
    let values: Vec<&[Value]> = plan.points.iter().map(|p| p.values.as_slice()).collect();
    arrays.extend(sweep_arrays(&cols, &values));
    RecordBatch::try_new(Arc::new(Schema::new(fields)), arrays)
        .expect("sweep batch matches its schema")
}

/// The `points` table: every registered point with its swept values (the latest manifest's
/// keys, [`sweep_batch`]), full params, and whether the latest manifest asks for it.
pub fn points_batch(plan: &Plan) -> RecordBatch {
    let head = sweep_batch(plan);
    let mut fields: Vec<Field> = head
        .schema()
        .fields()
        .iter()
        .map(|f| f.as_ref().clone())
        .collect();
    fields.push(Field::new("params", DataType::Utf8, false));
    fields.push(Field::new("in_manifest", DataType::Boolean, false));
    let mut arrays: Vec<ArrayRef> = head.columns().to_vec();
    arrays.push(Arc::new(
        plan.points
            .iter()
            .map(|p| Some(canonical(&p.params.to_value())))
            .collect::<arrow_array::StringArray>(),
    ));
    arrays.push(Arc::new(
        plan.points
            .iter()
            .map(|p| Some(p.current))
            .collect::<arrow_array::BooleanArray>(),
    ));
    RecordBatch::try_new(Arc::new(Schema::new(fields)), arrays)
        .expect("points batch matches its schema")
}

/// The `registered_runs` table: every run the campaign has registered (finished or not, asked
/// for by the latest manifest or not), with whether the latest manifest asks for it and its
/// replica number there (`Plan::manifest_replica`: what summaries number it by, as in a
/// campaign started from the latest manifest). Written whole, like `points`, when the registry
/// or the latest manifest changes.
pub fn registered_runs_batch(plan: &Plan) -> RecordBatch {
    let runs: Vec<(super::plan::RunSpec, Option<u32>)> = (0..plan.n_runs())
        .map(|r| {
            let spec = plan.run(r);
            (spec, plan.manifest_replica(&spec))
        })
        .collect();
    table(&runs, |c| {
        vec![
            c.u64("run_id", |r| r.0.run_id),
            c.u32("point_id", |r| r.0.point_id),
            c.u32("replica", |r| r.0.replica),
            c.u64("seed", |r| r.0.seed),
            c.opt_u64("continues", |r| r.0.continues),
            c.bool("in_manifest", |r| r.1.is_some()),
            c.array("manifest_replica", true, |rows| {
                Arc::new(
                    rows.iter()
                        .map(|r| r.1)
                        .collect::<arrow_array::UInt32Array>(),
                )
            }),
        ]
    })
}
