//! What the RFM observables share: the block protocol of their errors (the sampled time cut
//! into `BLOCKS` consecutive blocks, spec 2.2) and the histogram row.
//!
//! The accumulators keep their sums per sample (each sample's, or sample interval's, from 0)
//! and group them into the blocks only when the rows are made, with the run's final number of
//! samples: so a run continued to a longer duration puts every sample into the block a run made
//! straight to that duration puts it in, and both give the same rows bit for bit.

use serde::{Deserialize, Serialize};

use crate::math::stats::mean_sem;

/// Number of blocks the sampled time is cut into for standard errors.
pub const BLOCKS: usize = 10;

/// The block of sample `j` (from 0) of a run of `total` samples: the sampled time cut into
/// `BLOCKS` consecutive blocks of (nearly) equal numbers of samples.
pub fn block_of(j: u64, total: u64) -> usize {
    ((j as u128 * BLOCKS as u128 / total.max(1) as u128) as usize).min(BLOCKS - 1)
}

/// Per block, the sums of the per-sample sums `log` (sample j's at `log[j]`), added in sample
/// order, and the number of samples.
pub fn group<const K: usize>(log: &[[f64; K]], total: u64) -> (Vec<[f64; K]>, Vec<u64>) {
    let mut sums = vec![[0.0; K]; BLOCKS];
    let mut n = vec![0u64; BLOCKS];
    for (j, s) in log.iter().enumerate() {
        let b = block_of(j as u64, total);
        for (a, x) in sums[b].iter_mut().zip(s) {
            *a += x;
        }
        n[b] += 1;
    }
    (sums, n)
}

/// Standard error of the mean of block means (None with fewer than 2 blocks).
pub fn block_sem(blocks: &[f64]) -> Option<f64> {
    mean_sem(blocks).1
}

/// `rfm_histograms` row.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct HistRow {
    pub kind: String,
    /// Neighbour order for neighbour-distance histograms; 0 otherwise.
    pub h: u32,
    pub lo: f64,
    pub hi: f64,
    pub count: u64,
    /// count / (total count x bin width); null for the out-of-range rows.
    pub density: Option<f64>,
}
