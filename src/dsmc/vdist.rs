//! The velocity distribution of a species (observable `velocity_distribution`): the Sonine
//! coefficient a2 = 3 <v^4> / (5 <v^2>^2) - 1 and the histogram of the scaled speed
//! c = |v| / sqrt(2 T_k / m_k). Velocities in the lab frame, as the temperature
//! T_k = m_k <v^2>_k / 3 (the total momentum is conserved and starts at ~0), so a Maxwellian
//! gives a2 = 0. Pure functions of the velocities: no random numbers.

/// a2 of `n` velocities with sums `v2` = sum |v|^2 and `v4` = sum |v|^4: 3 n v4 / (5 v2^2) - 1;
/// None when not defined (no particle, all at rest, not finite).
pub fn sonine_a2(n: u64, v2: f64, v4: f64) -> Option<f64> {
    let a2 = 3.0 * n as f64 * v4 / (5.0 * v2 * v2) - 1.0;
    (n > 0 && v2 > 0.0 && a2.is_finite()).then_some(a2)
}

/// Counts of the scaled speeds c = |v| / `scale` in `bins` bins of width c_max / bins on
/// [0, c_max) (speeds at or beyond c_max are not counted).
pub fn speed_histogram(vel: &[[f64; 3]], scale: f64, bins: u32, c_max: f64) -> Vec<u64> {
    let mut counts = vec![0u64; bins as usize];
    let per = bins as f64 / (c_max * scale);
    for v in vel {
        let x = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt() * per;
        if x < bins as f64 {
            counts[x as usize] += 1;
        }
    }
    counts
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Speeds 1, 1 and 3 (in several directions): <v^2> = 11/3, <v^4> = 83/3, so
    /// a2 = 3 (83/3) / (5 (11/3)^2) - 1 = 747/605 - 1; the sums of |v|^2, |v|^4 are frame
    /// sums of the 3-vectors.
    #[test]
    fn a2_of_a_known_set() {
        let vel = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [1.0, 2.0, 2.0]];
        let v2: f64 = vel
            .iter()
            .map(|v| v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
            .sum();
        let v4: f64 = vel
            .iter()
            .map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).powi(2))
            .sum();
        assert_eq!((v2, v4), (11.0, 83.0));
        let a2 = sonine_a2(3, v2, v4).unwrap();
        assert!((a2 - (747.0 / 605.0 - 1.0)).abs() < 1e-15, "{a2}");
        // Every speed equal: <v^4> = <v^2>^2, a2 = 3/5 - 1.
        assert!((sonine_a2(2, 2.0, 2.0).unwrap() + 0.4).abs() < 1e-15);
        assert_eq!(sonine_a2(0, 0.0, 0.0), None);
        assert_eq!(sonine_a2(4, 0.0, 0.0), None);
    }

    /// Bins of width c_max / bins; the lower edge is in the bin, c_max and beyond are not
    /// counted; the scale divides the speed.
    #[test]
    fn histogram_bins() {
        let vel = [
            [0.0, 0.0, 0.0],
            [0.5, 0.0, 0.0],
            [0.0, 0.99, 0.0],
            [0.0, 0.0, 1.0],
            [3.0, 4.0, 0.0],
            [7.9, 0.0, 0.0],
            [8.0, 0.0, 0.0],
            [9.0, 0.0, 0.0],
        ];
        // scale 2: c = 0, 0.25, 0.495, 0.5, 2.5, 3.95, 4, 4.5; bins of 0.5 on [0, 4).
        assert_eq!(
            speed_histogram(&vel, 2.0, 8, 4.0),
            vec![3, 1, 0, 0, 0, 1, 0, 1]
        );
        assert_eq!(speed_histogram(&vel, 1.0, 1, 100.0), vec![8]);
    }
}
