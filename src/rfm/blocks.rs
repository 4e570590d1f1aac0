//! What the RFM observables share: the block protocol of their errors (the sampled time cut
//! into `BLOCKS` consecutive blocks, spec 2.2) and the histogram row.

use serde::{Deserialize, Serialize};

use crate::math::stats::mean_sem;

/// Number of blocks the sampled time is cut into for standard errors.
pub const BLOCKS: usize = 10;

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
