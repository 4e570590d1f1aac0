//! The tables of the `rfm` model, each declared once ([`crate::declare_table!`]): a run's
//! rows and the replica summaries (written by [`super::summary`]). Writers and readers use
//! these declarations only.

use arrow_array::RecordBatch;

use crate::declare_table;
use crate::models::RunIds;
use crate::rfm::observe::RfmOutput;
use crate::store::typed::{OptF64, Str, F64, U32, U64};

pub const RFM_TIMESERIES: &str = RfmTimeseries::TABLE;
pub const RFM_MOMENTS: &str = RfmMoments::TABLE;
pub const RFM_HISTOGRAMS: &str = RfmHistograms::TABLE;
pub const RFM_TIMESERIES_SUMMARY: &str = RfmTimeseriesSummary::TABLE;
pub const RFM_MOMENTS_SUMMARY: &str = RfmMomentsSummary::TABLE;
pub const RFM_HISTOGRAMS_SUMMARY: &str = RfmHistogramsSummary::TABLE;
pub const RFM_NEIGHBOUR_MOMENTS: &str = RfmNeighbourMoments::TABLE;
pub const RFM_NEIGHBOUR_MOMENTS_SUMMARY: &str = RfmNeighbourMomentsSummary::TABLE;
pub const RFM_STRUCTURE_FACTOR: &str = RfmStructureFactor::TABLE;
pub const RFM_STRUCTURE_FACTOR_SUMMARY: &str = RfmStructureFactorSummary::TABLE;
pub const RFM_RADIAL: &str = RfmRadial::TABLE;
pub const RFM_RADIAL_SUMMARY: &str = RfmRadialSummary::TABLE;
pub const RFM_TEMPERATURE_BLOCKS: &str = RfmTemperatureBlocks::TABLE;
pub const RFM_SNAPSHOTS: &str = RfmSnapshots::TABLE;
pub const RFM_FREE_PATH_MOMENTS: &str = RfmFreePathMoments::TABLE;
pub const RFM_FREE_PATH_MOMENTS_SUMMARY: &str = RfmFreePathMomentsSummary::TABLE;

/// One line on what a row of the table `name` is and what it holds (`granular tables`);
/// `None` for a name that is not one of this model's tables.
pub fn description(name: &str) -> Option<&'static str> {
    Some(match name {
        RFM_TIMESERIES => "one row per run and sample time: the temperature",
        RFM_TIMESERIES_SUMMARY => "one row per point and sample time: the temperature's mean and standard error over replicas",
        RFM_TEMPERATURE_BLOCKS => "one row per run and block (0..9): the block's time span and mean temperature",
        RFM_SNAPSHOTS => "one row per run, snapshot time and particle: positions and velocities",
        RFM_MOMENTS => "one row per run and order (1..12): the velocity moment <|v_c|^m> and its 10-block error",
        RFM_MOMENTS_SUMMARY => "one row per point and order: the velocity moments' mean and standard error over replicas",
        RFM_HISTOGRAMS => "one row per run, histogram kind (velocity, neighbour distance, free path, post-collision velocity), h and bin: count and density",
        RFM_HISTOGRAMS_SUMMARY => "one row per point, histogram kind, h and bin: the density's mean and standard error over replicas",
        RFM_NEIGHBOUR_MOMENTS => "one row per run, neighbour h and order: the moment <R^m> of the neighbour distance and its error",
        RFM_NEIGHBOUR_MOMENTS_SUMMARY => "one row per point, neighbour h and order: the neighbour-distance moments' mean and standard error over replicas",
        RFM_STRUCTURE_FACTOR => "one row per run and k shell (n2): the structure factor S(k) and its error",
        RFM_STRUCTURE_FACTOR_SUMMARY => "one row per point and k shell: S(k)'s mean and standard error over replicas",
        RFM_RADIAL => "one row per run and distance bin: pair count, g(r) and C(r)",
        RFM_RADIAL_SUMMARY => "one row per point and distance bin: g(r)'s and C(r)'s mean and standard error over replicas",
        RFM_FREE_PATH_MOMENTS => "one row per run and order: the free-path moments and the number of paths",
        RFM_FREE_PATH_MOMENTS_SUMMARY => "one row per point and order: the free-path moments' mean and standard error over replicas",
        _ => return None,
    })
}

declare_table! {
    /// `rfm_timeseries`: the temperature per output time (per run).
    pub struct RfmTimeseries in "rfm_timeseries", read as RfmTimeseriesCols {
        run_id: U64,
        point_id: U32,
        t: F64,
        temperature: F64,
    }
}

declare_table! {
    /// `rfm_moments`: the velocity moments over the sampled steady state (per run).
    pub struct RfmMoments in "rfm_moments", read as RfmMomentsCols {
        run_id: U64,
        point_id: U32,
        order: U32,
        value: F64,
        sem: OptF64,
    }
}

declare_table! {
    /// `rfm_histograms`: the histograms per kind (`v`, `v0`, `l`) and h (per run).
    pub struct RfmHistograms in "rfm_histograms", read as RfmHistogramsCols {
        run_id: U64,
        point_id: U32,
        kind: Str,
        h: U32,
        lo: F64,
        hi: F64,
        count: U64,
        density: OptF64,
    }
}

declare_table! {
    /// `rfm_neighbour_moments`: the moments of the h-th neighbour distance (per run).
    pub struct RfmNeighbourMoments in "rfm_neighbour_moments", read as RfmNeighbourMomentsCols {
        run_id: U64,
        point_id: U32,
        h: U32,
        order: U32,
        value: F64,
        sem: OptF64,
    }
}

declare_table! {
    /// `rfm_structure_factor`: S(k) per shell n2 (per run).
    pub struct RfmStructureFactor in "rfm_structure_factor", read as RfmStructureFactorCols {
        run_id: U64,
        point_id: U32,
        n2: U64,
        k: F64,
        n_vectors: U64,
        s: F64,
        sem: OptF64,
    }
}

declare_table! {
    /// `rfm_radial_distribution`: g(R) and C(R) per bin (per run).
    pub struct RfmRadial in "rfm_radial_distribution", read as RfmRadialCols {
        run_id: U64,
        point_id: U32,
        r_lo: F64,
        r_hi: F64,
        count: U64,
        g: F64,
        g_sem: OptF64,
        c: F64,
    }
}

declare_table! {
    /// `rfm_temperature_blocks`: the temperature per block of the sampled time (per run).
    pub struct RfmTemperatureBlocks in "rfm_temperature_blocks", read as RfmTemperatureBlocksCols {
        run_id: U64,
        point_id: U32,
        block: U32,
        t_from: F64,
        t_to: F64,
        n_samples: U32,
        temperature: F64,
    }
}

declare_table! {
    /// `rfm_snapshots`: positions and velocities at the snapshot times (per run).
    pub struct RfmSnapshots in "rfm_snapshots", read as RfmSnapshotsCols {
        run_id: U64,
        point_id: U32,
        t: F64,
        particle: U32,
        x: F64,
        y: OptF64,
        vx: F64,
        vy: OptF64,
    }
}

declare_table! {
    /// `rfm_free_path_moments`: the moments <l^m> of the free paths (per run).
    pub struct RfmFreePathMoments in "rfm_free_path_moments", read as RfmFreePathMomentsCols {
        run_id: U64,
        point_id: U32,
        order: U32,
        value: F64,
        sem: OptF64,
        n_paths: U64,
    }
}

declare_table! {
    /// `rfm_timeseries_summary`: temperature mean and sem over the replicas per point and time.
    pub struct RfmTimeseriesSummary in "rfm_timeseries_summary", read as RfmTimeseriesSummaryCols {
        point_id: U32,
        t: F64,
        n_replicas: U32,
        temperature_mean: F64,
        temperature_sem: OptF64,
    }
}

declare_table! {
    /// `rfm_moments_summary`: mean and sem of the runs' velocity moments per point and order.
    pub struct RfmMomentsSummary in "rfm_moments_summary", read as RfmMomentsSummaryCols {
        point_id: U32,
        order: U32,
        n_replicas: U32,
        mean: F64,
        sem: OptF64,
    }
}

declare_table! {
    /// `rfm_histograms_summary`: counts summed over the replicas per point, kind, h and bin, density of the pooled counts.
    pub struct RfmHistogramsSummary in "rfm_histograms_summary", read as RfmHistogramsSummaryCols {
        point_id: U32,
        kind: Str,
        h: U32,
        lo: F64,
        hi: F64,
        count: U64,
        density: OptF64,
    }
}

declare_table! {
    /// `rfm_free_path_moments_summary`: mean and sem of the runs' <l^m> per point and order, paths summed.
    pub struct RfmFreePathMomentsSummary in "rfm_free_path_moments_summary", read as RfmFreePathMomentsSummaryCols {
        point_id: U32,
        order: U32,
        n_replicas: U32,
        mean: F64,
        sem: OptF64,
        n_paths: U64,
    }
}

declare_table! {
    /// `rfm_neighbour_moments_summary`: mean and sem of the runs' neighbour-distance moments per point, h and order.
    pub struct RfmNeighbourMomentsSummary in "rfm_neighbour_moments_summary", read as RfmNeighbourMomentsSummaryCols {
        point_id: U32,
        h: U32,
        order: U32,
        n_replicas: U32,
        mean: F64,
        sem: OptF64,
    }
}

declare_table! {
    /// `rfm_structure_factor_summary`: mean and sem of the runs' S(k) per point and shell.
    pub struct RfmStructureFactorSummary in "rfm_structure_factor_summary", read as RfmStructureFactorSummaryCols {
        point_id: U32,
        n2: U64,
        k: F64,
        n_vectors: U64,
        n_replicas: U32,
        s_mean: F64,
        s_sem: OptF64,
    }
}

declare_table! {
    /// `rfm_radial_distribution_summary`: pair counts summed, mean and sem of g(R) and C(R) per point and bin.
    pub struct RfmRadialSummary in "rfm_radial_distribution_summary", read as RfmRadialSummaryCols {
        point_id: U32,
        r_lo: F64,
        r_hi: F64,
        n_replicas: U32,
        count: U64,
        g_mean: F64,
        g_sem: OptF64,
        c_mean: F64,
        c_sem: OptF64,
    }
}

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
    let rows: Vec<RfmTimeseries> = o
        .timeseries
        .iter()
        .map(|r| RfmTimeseries {
            run_id: ids.run_id,
            point_id: ids.point_id,
            t: r.t,
            temperature: r.temperature,
        })
        .collect();
    RfmTimeseries::batch(&rows)
}

fn moments(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let rows: Vec<RfmMoments> = o
        .moments
        .iter()
        .map(|r| RfmMoments {
            run_id: ids.run_id,
            point_id: ids.point_id,
            order: r.order,
            value: r.value,
            sem: r.sem,
        })
        .collect();
    RfmMoments::batch(&rows)
}

fn histograms(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let rows: Vec<RfmHistograms> = o
        .histograms
        .iter()
        .map(|r| RfmHistograms {
            run_id: ids.run_id,
            point_id: ids.point_id,
            kind: r.kind.clone(),
            h: r.h,
            lo: r.lo,
            hi: r.hi,
            count: r.count,
            density: r.density,
        })
        .collect();
    RfmHistograms::batch(&rows)
}

fn neighbour_moments(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let rows: Vec<RfmNeighbourMoments> = o
        .neighbour_moments
        .iter()
        .map(|r| RfmNeighbourMoments {
            run_id: ids.run_id,
            point_id: ids.point_id,
            h: r.h,
            order: r.order,
            value: r.value,
            sem: r.sem,
        })
        .collect();
    RfmNeighbourMoments::batch(&rows)
}

fn structure_factor(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let rows: Vec<RfmStructureFactor> = o
        .structure_factor
        .iter()
        .map(|r| RfmStructureFactor {
            run_id: ids.run_id,
            point_id: ids.point_id,
            n2: r.n2,
            k: r.k,
            n_vectors: r.n_vectors,
            s: r.s,
            sem: r.sem,
        })
        .collect();
    RfmStructureFactor::batch(&rows)
}

fn radial(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let rows: Vec<RfmRadial> = o
        .radial
        .iter()
        .map(|r| RfmRadial {
            run_id: ids.run_id,
            point_id: ids.point_id,
            r_lo: r.r_lo,
            r_hi: r.r_hi,
            count: r.count,
            g: r.g,
            g_sem: r.g_sem,
            c: r.c,
        })
        .collect();
    RfmRadial::batch(&rows)
}

fn temperature_blocks(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let rows: Vec<RfmTemperatureBlocks> = o
        .temperature_blocks
        .iter()
        .map(|r| RfmTemperatureBlocks {
            run_id: ids.run_id,
            point_id: ids.point_id,
            block: r.block,
            t_from: r.t_from,
            t_to: r.t_to,
            n_samples: r.n_samples,
            temperature: r.temperature,
        })
        .collect();
    RfmTemperatureBlocks::batch(&rows)
}

fn snapshots(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let rows: Vec<RfmSnapshots> = o
        .snapshots
        .iter()
        .map(|r| RfmSnapshots {
            run_id: ids.run_id,
            point_id: ids.point_id,
            t: r.t,
            particle: r.particle,
            x: r.x,
            y: r.y,
            vx: r.vx,
            vy: r.vy,
        })
        .collect();
    RfmSnapshots::batch(&rows)
}

fn free_path_moments(ids: RunIds, o: &RfmOutput) -> RecordBatch {
    let rows: Vec<RfmFreePathMoments> = o
        .free_path_moments
        .iter()
        .map(|r| RfmFreePathMoments {
            run_id: ids.run_id,
            point_id: ids.point_id,
            order: r.order,
            value: r.value,
            sem: r.sem,
            n_paths: r.n_paths,
        })
        .collect();
    RfmFreePathMoments::batch(&rows)
}
