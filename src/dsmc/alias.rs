//! Walker/Vose alias tables: O(1) sampling from a discrete distribution with one 64-bit word
//! (the index from the high half of `x * n`, the coin from the low half).

use serde::{Deserialize, Serialize};

#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct Alias {
    /// Acceptance threshold of each slot, scaled to 2^64.
    threshold: Vec<u64>,
    alias: Vec<u32>,
    total: f64,
}

impl Alias {
    pub fn new(weights: &[f64]) -> Self {
        let mut a = Alias::default();
        a.rebuild(weights);
        a
    }

    /// Sum of the weights the table was built from.
    #[inline]
    pub fn total(&self) -> f64 {
        self.total
    }

    pub fn len(&self) -> usize {
        self.alias.len()
    }

    pub fn is_empty(&self) -> bool {
        self.alias.is_empty()
    }

    /// Rebuild in place (Vose's method; deterministic).
    pub fn rebuild(&mut self, weights: &[f64]) {
        let n = weights.len();
        self.threshold.clear();
        self.alias.clear();
        self.threshold.resize(n, u64::MAX);
        self.alias.extend(0..n as u32);
        let total: f64 = weights.iter().sum();
        self.total = total;
        if n == 0 || total <= 0.0 || !total.is_finite() {
            return;
        }
        let scale = n as f64 / total;
        let mut q: Vec<f64> = weights.iter().map(|w| w * scale).collect();
        let mut small = Vec::with_capacity(n);
        let mut large = Vec::with_capacity(n);
        for (i, &x) in q.iter().enumerate() {
            if x < 1.0 {
                small.push(i)
            } else {
                large.push(i)
            }
        }
        while let (Some(&s), Some(&l)) = (small.last(), large.last()) {
            small.pop();
            self.threshold[s] = to_threshold(q[s]);
            self.alias[s] = l as u32;
            q[l] = (q[l] + q[s]) - 1.0;
            if q[l] < 1.0 {
                large.pop();
                small.push(l);
            }
        }
        // Left-overs are 1 up to rounding.
        for i in small.into_iter().chain(large) {
            self.threshold[i] = u64::MAX;
        }
    }

    #[inline(always)]
    pub fn sample(&self, x: u64) -> usize {
        let n = self.alias.len();
        let m = x as u128 * n as u128;
        let idx = (m >> 64) as usize;
        let frac = m as u64;
        // SAFETY: idx < n because x < 2^64.
        let (thr, alias) = unsafe {
            (
                *self.threshold.get_unchecked(idx),
                *self.alias.get_unchecked(idx) as usize,
            )
        };
        // Branch-free select (the coin is unpredictable).
        let take_alias = ((frac >= thr) as usize).wrapping_neg();
        idx ^ ((idx ^ alias) & take_alias)
    }
}

/// Alias tables of equal length end to end, so that a draw from any of them is one lookup:
/// table t's slots are `t n..(t + 1) n`, and [`sample`](Self::sample) from `base = t n` is
/// [`Alias::sample`] of table t (the same index for the same word).
#[derive(Clone, Debug, Default)]
pub struct AliasStack {
    threshold: Vec<u64>,
    alias: Vec<u32>,
    n: u64,
}

impl AliasStack {
    /// The tables end to end; None unless they all have the same, nonzero length.
    pub fn new(tables: &[Alias]) -> Option<Self> {
        let n = tables.first()?.len();
        if n == 0 || tables.iter().any(|t| t.len() != n) {
            return None;
        }
        Some(AliasStack {
            threshold: tables
                .iter()
                .flat_map(|t| t.threshold.iter().copied())
                .collect(),
            alias: tables
                .iter()
                .flat_map(|t| t.alias.iter().copied())
                .collect(),
            n: n as u64,
        })
    }

    /// The length of each table.
    pub fn table_len(&self) -> usize {
        self.n as usize
    }

    /// The sample of the table starting at slot `base` (a multiple of the table length).
    #[inline(always)]
    pub fn sample(&self, base: usize, x: u64) -> usize {
        debug_assert!(base.is_multiple_of(self.n as usize) && base < self.alias.len());
        let m = x as u128 * self.n as u128;
        let idx = (m >> 64) as usize;
        let frac = m as u64;
        // SAFETY: idx < n because x < 2^64, and base + n <= len (checked in debug builds).
        let (thr, alias) = unsafe {
            (
                *self.threshold.get_unchecked(base + idx),
                *self.alias.get_unchecked(base + idx) as usize,
            )
        };
        let take_alias = ((frac >= thr) as usize).wrapping_neg();
        idx ^ ((idx ^ alias) & take_alias)
    }
}

fn to_threshold(p: f64) -> u64 {
    if p >= 1.0 {
        u64::MAX
    } else if p <= 0.0 {
        0
    } else {
        (p * 18446744073709551616.0) as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::RunRng;

    /// A stack of tables samples as each of its tables, word for word; tables of unequal
    /// length do not stack.
    #[test]
    fn stacked_tables_sample_as_their_tables() {
        let tables = [
            Alias::new(&[1.0, 0.0, 3.0, 0.5]),
            Alias::new(&[0.2, 0.2, 5.0, 1e-9]),
            Alias::new(&[0.0, 0.0, 0.0, 1.0]),
        ];
        let stack = AliasStack::new(&tables).unwrap();
        assert_eq!(stack.table_len(), 4);
        let mut rng = RunRng::new(11);
        for _ in 0..100_000 {
            let x = rng.u64();
            for (t, table) in tables.iter().enumerate() {
                assert_eq!(stack.sample(4 * t, x), table.sample(x));
            }
        }
        assert!(AliasStack::new(&[Alias::new(&[1.0]), Alias::new(&[1.0, 2.0])]).is_none());
        assert!(AliasStack::new(&[]).is_none());
    }

    /// Frequencies from 1e6 draws match the weights within 5 binomial standard deviations.
    #[test]
    fn frequencies_match_weights() {
        let w = [1.0, 0.0, 3.0, 0.5, 10.0, 1e-3, 2.5];
        let a = Alias::new(&w);
        let total: f64 = w.iter().sum();
        let mut rng = RunRng::new(3);
        let n = 1_000_000;
        let mut counts = [0u64; 7];
        for _ in 0..n {
            counts[a.sample(rng.u64())] += 1;
        }
        for (i, &c) in counts.iter().enumerate() {
            let p = w[i] / total;
            let sd = (n as f64 * p * (1.0 - p)).sqrt();
            assert!(
                (c as f64 - n as f64 * p).abs() <= 5.0 * sd + 1e-9,
                "slot {i}: {c} vs {}",
                n as f64 * p
            );
        }
        assert_eq!(counts[1], 0);
    }
}
