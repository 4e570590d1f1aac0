//! What a finished run hands to the table writer: its ids and its rows per table.

use arrow_array::RecordBatch;

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
