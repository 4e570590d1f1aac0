//! Sample statistics: the mean and its standard error, from the values (two passes) or from
//! running sums (one pass, for accumulators that are checkpointed as sums).

/// Mean and standard error of the mean of `x` (two passes; None for fewer than two values).
pub fn mean_sem(x: &[f64]) -> (f64, Option<f64>) {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    if x.len() < 2 {
        return (mean, None);
    }
    let var = x.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n - 1.0);
    (mean, Some((var / n).sqrt()))
}

/// Mean and standard error of the mean from a count, sum and sum of squares (None for fewer
/// than two values; NaN mean for none).
pub fn mean_sem_from_sums(n: u64, sum: f64, sum2: f64) -> (f64, Option<f64>) {
    if n == 0 {
        return (f64::NAN, None);
    }
    let nf = n as f64;
    let mean = sum / nf;
    if n < 2 {
        return (mean, None);
    }
    let var = ((sum2 - nf * mean * mean) / (nf - 1.0)).max(0.0);
    (mean, Some((var / nf).sqrt()))
}

/// (replicas, mean, sem) of (replica, value) pairs, summed in replica order so the result does
/// not depend on the order in which runs finished; a replica counts once.
pub fn replica_mean_sem<R: Ord + Copy>(mut v: Vec<(R, f64)>) -> (u32, f64, Option<f64>) {
    v.sort_by_key(|x| x.0);
    v.dedup_by_key(|x| x.0);
    let xs: Vec<f64> = v.iter().map(|x| x.1).collect();
    let (mean, sem) = mean_sem(&xs);
    (xs.len() as u32, mean, sem)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_forms_agree_and_replicas_count_once() {
        let x = [1.0, 2.0, 4.0, 7.0];
        let (m, s) = mean_sem(&x);
        let (sum, sum2) = (x.iter().sum(), x.iter().map(|v| v * v).sum());
        let (m2, s2) = mean_sem_from_sums(4, sum, sum2);
        assert_eq!(m, 3.5);
        // var = (6.25 + 2.25 + 0.25 + 12.25) / 3 = 7, sem = sqrt(7/4)
        assert!((s.unwrap() - (7.0f64 / 4.0).sqrt()).abs() < 1e-15);
        assert!((m2 - m).abs() < 1e-15 && (s2.unwrap() - s.unwrap()).abs() < 1e-12);
        assert_eq!(mean_sem(&[5.0]), (5.0, None));
        assert!(mean_sem_from_sums(0, 0.0, 0.0).0.is_nan());
        let (n, mean, _) = replica_mean_sem(vec![(2u32, 4.0), (0, 1.0), (2, 4.0), (1, 2.0)]);
        assert_eq!((n, mean), (3, 7.0 / 3.0));
    }
}
