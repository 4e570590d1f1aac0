//! What a finished run hands to the table writer: its ids and its rows per table.

use std::sync::Arc;

use arrow_array::{ArrayRef, RecordBatch, UInt32Array, UInt64Array};
use arrow_schema::{DataType, Field, Schema};

use crate::store::cols::{Column, Columns};

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
