//! The tables of the `rfm` model: names, and a run's rows in Arrow form (the summaries are
//! in [`super::summary`]).

use arrow_array::RecordBatch;

use crate::models::{run_batch, RunIds};
use crate::rfm::observe::RfmOutput;

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
    run_batch(ids, v, |c| {
        vec![c.f64("t", |r| r.t), c.f64("temperature", |r| r.temperature)]
    })
}

fn moments(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let v = &o.moments;
    run_batch(ids, v, |c| {
        vec![
            c.u32("order", |r| r.order),
            c.f64("value", |r| r.value),
            c.opt_f64("sem", |r| r.sem),
        ]
    })
}

fn histograms(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let v = &o.histograms;
    run_batch(ids, v, |c| {
        vec![
            c.str("kind", |r| r.kind.as_str()),
            c.u32("h", |r| r.h),
            c.f64("lo", |r| r.lo),
            c.f64("hi", |r| r.hi),
            c.u64("count", |r| r.count),
            c.opt_f64("density", |r| r.density),
        ]
    })
}

fn neighbour_moments(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let v = &o.neighbour_moments;
    run_batch(ids, v, |c| {
        vec![
            c.u32("h", |r| r.h),
            c.u32("order", |r| r.order),
            c.f64("value", |r| r.value),
            c.opt_f64("sem", |r| r.sem),
        ]
    })
}

fn structure_factor(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let v = &o.structure_factor;
    run_batch(ids, v, |c| {
        vec![
            c.u64("n2", |r| r.n2),
            c.f64("k", |r| r.k),
            c.u64("n_vectors", |r| r.n_vectors),
            c.f64("s", |r| r.s),
            c.opt_f64("sem", |r| r.sem),
        ]
    })
}

fn radial(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let v = &o.radial;
    run_batch(ids, v, |c| {
        vec![
            c.f64("r_lo", |r| r.r_lo),
            c.f64("r_hi", |r| r.r_hi),
            c.u64("count", |r| r.count),
            c.f64("g", |r| r.g),
            c.opt_f64("g_sem", |r| r.g_sem),
            c.f64("c", |r| r.c),
        ]
    })
}

fn temperature_blocks(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let v = &o.temperature_blocks;
    run_batch(ids, v, |c| {
        vec![
            c.u32("block", |r| r.block),
            c.f64("t_from", |r| r.t_from),
            c.f64("t_to", |r| r.t_to),
            c.u32("n_samples", |r| r.n_samples),
            c.f64("temperature", |r| r.temperature),
        ]
    })
}

fn snapshots(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let v = &o.snapshots;
    run_batch(ids, v, |c| {
        vec![
            c.f64("t", |r| r.t),
            c.u32("particle", |r| r.particle),
            c.f64("x", |r| r.x),
            c.opt_f64("y", |r| r.y),
            c.f64("vx", |r| r.vx),
            c.opt_f64("vy", |r| r.vy),
        ]
    })
}

fn free_path_moments(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let v = &o.free_path_moments;
    run_batch(ids, v, |c| {
        vec![
            c.u32("order", |r| r.order),
            c.f64("value", |r| r.value),
            c.opt_f64("sem", |r| r.sem),
            c.u64("n_paths", |r| r.n_paths),
        ]
    })
}
