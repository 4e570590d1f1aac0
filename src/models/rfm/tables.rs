//! The tables of the `rfm` model: names, and a run's rows in Arrow form (the summaries are
//! in [`super::summary`]).

use arrow_array::RecordBatch;
use arrow_schema::DataType;

use crate::models::{run_batch, RunIds};
use crate::rfm::observe::RfmOutput;
use crate::store::cols::{f64s, field, field_opt, opt_f64s, strs, u32s, u64s};

pub const RFM_TIMESERIES: &str = "rfm_timeseries";
pub const RFM_MOMENTS: &str = "rfm_moments";
pub const RFM_HISTOGRAMS: &str = "rfm_histograms";
pub const RFM_TIMESERIES_SUMMARY: &str = "rfm_timeseries_summary";
pub const RFM_MOMENTS_SUMMARY: &str = "rfm_moments_summary";
pub const RFM_HISTOGRAMS_SUMMARY: &str = "rfm_histograms_summary";
pub const RFM_NEIGHBOUR_MOMENTS: &str = "rfm_neighbour_moments";
pub const RFM_NEIGHBOUR_MOMENTS_SUMMARY: &str = "rfm_neighbour_moments_summary";
pub const RFM_STRUCTURE_FACTOR: &str = "rfm_structure_factor";
pub const RFM_STRUCTURE_FACTOR_SUMMARY: &str = "rfm_structure_factor_summary";
pub const RFM_RADIAL: &str = "rfm_radial_distribution";
pub const RFM_RADIAL_SUMMARY: &str = "rfm_radial_distribution_summary";
pub const RFM_TEMPERATURE_BLOCKS: &str = "rfm_temperature_blocks";
pub const RFM_SNAPSHOTS: &str = "rfm_snapshots";
pub const RFM_FREE_PATH_MOMENTS: &str = "rfm_free_path_moments";
pub const RFM_FREE_PATH_MOMENTS_SUMMARY: &str = "rfm_free_path_moments_summary";

use DataType::{Float64 as F64, UInt32 as U32, UInt64 as U64, Utf8};

/// A run's rows as (table, batch), the tables without rows left out.
pub fn batches(ids: RunIds, o: &RfmOutput) -> Vec<(&'static str, RecordBatch)> {
    let mut out = Vec::new();
    let mut push = |table, rows: usize, batch: fn(RunIds, &RfmOutput) -> RecordBatch| {
        if rows > 0 {
            out.push((table, batch(ids, o)));
        }
    };
    push(RFM_TIMESERIES, o.timeseries.len(), timeseries);
    push(RFM_MOMENTS, o.moments.len(), moments);
    push(RFM_HISTOGRAMS, o.histograms.len(), histograms);
    push(
        RFM_NEIGHBOUR_MOMENTS,
        o.neighbour_moments.len(),
        neighbour_moments,
    );
    push(
        RFM_STRUCTURE_FACTOR,
        o.structure_factor.len(),
        structure_factor,
    );
    push(RFM_RADIAL, o.radial.len(), radial);
    push(
        RFM_TEMPERATURE_BLOCKS,
        o.temperature_blocks.len(),
        temperature_blocks,
    );
    push(RFM_SNAPSHOTS, o.snapshots.len(), snapshots);
    push(
        RFM_FREE_PATH_MOMENTS,
        o.free_path_moments.len(),
        free_path_moments,
    );
    out
}

fn timeseries(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let v = &o.timeseries;
    run_batch(
        ids,
        v.len(),
        vec![field("t", F64), field("temperature", F64)],
        vec![f64s(v, |r| r.t), f64s(v, |r| r.temperature)],
    )
}

fn moments(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let v = &o.moments;
    run_batch(
        ids,
        v.len(),
        vec![
            field("order", U32),
            field("value", F64),
            field_opt("sem", F64),
        ],
        vec![
            u32s(v, |r| r.order),
            f64s(v, |r| r.value),
            opt_f64s(v, |r| r.sem),
        ],
    )
}

fn histograms(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let v = &o.histograms;
    run_batch(
        ids,
        v.len(),
        vec![
            field("kind", Utf8),
            field("h", U32),
            field("lo", F64),
            field("hi", F64),
            field("count", U64),
            field_opt("density", F64),
        ],
        vec![
            strs(v, |r| r.kind.as_str()),
            u32s(v, |r| r.h),
            f64s(v, |r| r.lo),
            f64s(v, |r| r.hi),
            u64s(v, |r| r.count),
            opt_f64s(v, |r| r.density),
        ],
    )
}

fn neighbour_moments(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let v = &o.neighbour_moments;
    run_batch(
        ids,
        v.len(),
        vec![
            field("h", U32),
            field("order", U32),
            field("value", F64),
            field_opt("sem", F64),
        ],
        vec![
            u32s(v, |r| r.h),
            u32s(v, |r| r.order),
            f64s(v, |r| r.value),
            opt_f64s(v, |r| r.sem),
        ],
    )
}

fn structure_factor(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let v = &o.structure_factor;
    run_batch(
        ids,
        v.len(),
        vec![
            field("n2", U64),
            field("k", F64),
            field("n_vectors", U64),
            field("s", F64),
            field_opt("sem", F64),
        ],
        vec![
            u64s(v, |r| r.n2),
            f64s(v, |r| r.k),
            u64s(v, |r| r.n_vectors),
            f64s(v, |r| r.s),
            opt_f64s(v, |r| r.sem),
        ],
    )
}

fn radial(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let v = &o.radial;
    run_batch(
        ids,
        v.len(),
        vec![
            field("r_lo", F64),
            field("r_hi", F64),
            field("count", U64),
            field("g", F64),
            field_opt("g_sem", F64),
            field("c", F64),
        ],
        vec![
            f64s(v, |r| r.r_lo),
            f64s(v, |r| r.r_hi),
            u64s(v, |r| r.count),
            f64s(v, |r| r.g),
            opt_f64s(v, |r| r.g_sem),
            f64s(v, |r| r.c),
        ],
    )
}

fn temperature_blocks(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let v = &o.temperature_blocks;
    run_batch(
        ids,
        v.len(),
        vec![
            field("block", U32),
            field("t_from", F64),
            field("t_to", F64),
            field("n_samples", U32),
            field("temperature", F64),
        ],
        vec![
            u32s(v, |r| r.block),
            f64s(v, |r| r.t_from),
            f64s(v, |r| r.t_to),
            u32s(v, |r| r.n_samples),
            f64s(v, |r| r.temperature),
        ],
    )
}

fn snapshots(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let v = &o.snapshots;
    run_batch(
        ids,
        v.len(),
        vec![
            field("t", F64),
            field("particle", U32),
            field("x", F64),
            field_opt("y", F64),
            field("vx", F64),
            field_opt("vy", F64),
        ],
        vec![
            f64s(v, |r| r.t),
            u32s(v, |r| r.particle),
            f64s(v, |r| r.x),
            opt_f64s(v, |r| r.y),
            f64s(v, |r| r.vx),
            opt_f64s(v, |r| r.vy),
        ],
    )
}

fn free_path_moments(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let v = &o.free_path_moments;
    run_batch(
        ids,
        v.len(),
        vec![
            field("order", U32),
            field("value", F64),
            field_opt("sem", F64),
            field("n_paths", U64),
        ],
        vec![
            u32s(v, |r| r.order),
            f64s(v, |r| r.value),
            opt_f64s(v, |r| r.sem),
            u64s(v, |r| r.n_paths),
        ],
    )
}
