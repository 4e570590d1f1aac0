//! The campaign's own tables, whatever the model: `runs` (one row per finished run) and
//! `points` (one row per sweep point), with the swept parameters as typed columns.

use std::sync::Arc;

use arrow_array::builder::{BooleanBuilder, Float64Builder, Int64Builder, StringBuilder};
use arrow_array::{ArrayRef, RecordBatch};
use arrow_schema::{DataType, Field, Schema};
use serde_json::Value;

use super::plan::{canonical, Plan};

pub const RUNS: &str = "runs";
pub const POINTS: &str = "points";

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

/// The typed sweep columns of a plan.
pub fn sweep_columns(plan: &Plan) -> Vec<SweepColumn> {
    plan.sweep_keys
        .iter()
        .enumerate()
        .map(|(j, key)| {
            let vals: Vec<&Value> = plan.points.iter().map(|p| &p.values[j]).collect();
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
            Field::new(&c.name, dt, false)
        })
        .collect()
}

fn sweep_arrays(cols: &[SweepColumn], values: &[&[Value]]) -> Vec<ArrayRef> {
    cols.iter()
        .enumerate()
        .map(|(j, c)| -> ArrayRef {
            match c.kind {
                SweepKind::Int => {
                    let mut b = Int64Builder::new();
                    values.iter().for_each(|v| {
                        b.append_value(v[j].as_i64().unwrap_or(v[j].as_u64().unwrap_or(0) as i64))
                    });
                    Arc::new(b.finish())
                }
                SweepKind::Float => {
                    let mut b = Float64Builder::new();
                    values
                        .iter()
                        .for_each(|v| b.append_value(v[j].as_f64().unwrap_or(f64::NAN)));
                    Arc::new(b.finish())
                }
                SweepKind::Bool => {
                    let mut b = BooleanBuilder::new();
                    values
                        .iter()
                        .for_each(|v| b.append_value(v[j].as_bool().unwrap_or(false)));
                    Arc::new(b.finish())
                }
                SweepKind::Str => {
                    let mut b = StringBuilder::new();
                    values
                        .iter()
                        .for_each(|v| b.append_value(v[j].as_str().unwrap_or("")));
                    Arc::new(b.finish())
                }
                SweepKind::Json => {
                    let mut b = StringBuilder::new();
                    values.iter().for_each(|v| b.append_value(canonical(&v[j])));
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
}

pub fn runs_batch(plan: &Plan, cols: &[SweepColumn], rows: &[RunRow]) -> RecordBatch {
    let mut fields = vec![
        Field::new("run_id", DataType::UInt64, false),
        Field::new("point_id", DataType::UInt32, false),
        Field::new("replica", DataType::UInt32, false),
        Field::new("seed", DataType::UInt64, false),
    ];
    fields.extend(sweep_fields(cols));
    fields.extend([
        Field::new("status", DataType::Utf8, false),
        Field::new("reason", DataType::Utf8, true),
        Field::new("t_failed", DataType::Float64, true),
        Field::new("wall_seconds", DataType::Float64, false),
        Field::new("collisions", DataType::UInt64, false),
        Field::new("trials", DataType::UInt64, false),
        Field::new("code_version", DataType::Utf8, false),
    ]);
    let mut arrays: Vec<ArrayRef> = vec![
        Arc::new(
            rows.iter()
                .map(|r| r.run_id)
                .collect::<arrow_array::UInt64Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.point_id)
                .collect::<arrow_array::UInt32Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.replica)
                .collect::<arrow_array::UInt32Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.seed)
                .collect::<arrow_array::UInt64Array>(),
        ),
    ];
    let values: Vec<&[Value]> = rows
        .iter()
        .map(|r| plan.point(r.point_id).values.as_slice())
        .collect();
    arrays.extend(sweep_arrays(cols, &values));
    arrays.extend::<[ArrayRef; 7]>([
        Arc::new(
            rows.iter()
                .map(|r| Some(r.status.as_str()))
                .collect::<arrow_array::StringArray>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.reason.as_deref())
                .collect::<arrow_array::StringArray>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.t_failed)
                .collect::<arrow_array::Float64Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.wall_seconds)
                .collect::<arrow_array::Float64Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.collisions)
                .collect::<arrow_array::UInt64Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.trials)
                .collect::<arrow_array::UInt64Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|_| Some(crate::CODE_VERSION))
                .collect::<arrow_array::StringArray>(),
        ),
    ]);
    RecordBatch::try_new(Arc::new(Schema::new(fields)), arrays)
        .expect("runs batch matches its schema")
}

/// The `points` table: one row per sweep point with its swept values and full params.
pub fn points_batch(plan: &Plan, cols: &[SweepColumn], params_json: &[String]) -> RecordBatch {
    let mut fields = vec![Field::new("point_id", DataType::UInt32, false)];
    fields.extend(sweep_fields(cols));
    fields.push(Field::new("params", DataType::Utf8, false));
    let mut arrays: Vec<ArrayRef> = vec![Arc::new(
        plan.points
            .iter()
            .map(|p| p.point_id)
            .collect::<arrow_array::UInt32Array>(),
    )];
    let values: Vec<&[Value]> = plan.points.iter().map(|p| p.values.as_slice()).collect();
    arrays.extend(sweep_arrays(cols, &values));
    arrays.push(Arc::new(
        params_json
            .iter()
            .map(|s| Some(s.as_str()))
            .collect::<arrow_array::StringArray>(),
    ));
    RecordBatch::try_new(Arc::new(Schema::new(fields)), arrays)
        .expect("points batch matches its schema")
}
