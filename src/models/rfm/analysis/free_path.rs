//! Free paths (thesis sec. 4.3, spec 2.9): the tail form (4.25)
//! P_l(l) = A_0 exp(-C l^(D_f - 1)) l^(D_f - 2), fitted to the long-l tail "where P_l < 1"
//! (P_l in m^-1, spec 6.19) beyond the maximum of P_l, on ln P_l with sigma = 1/sqrt(X).
//! Either A_0, C, D_f free (D_f from the paths, compare with S(k)) or D_f fixed (the thesis's
//! C = 78 / 121 / 179 use D_f = 1.63).

use crate::math::fit::{self, Fit};

/// One free-path bin: centre (geometric for log bins), density (m^-1), count.
#[derive(Clone, Copy, Debug)]
pub struct PathBin {
    pub l: f64,
    pub density: f64,
    pub count: f64,
}

/// ln P_l of (4.25) with params [ln A_0, C, D_f].
pub fn ln_tail(p: &[f64], l: f64) -> f64 {
    p[0] - p[1] * l.powf(p[2] - 1.0) + (p[2] - 2.0) * l.ln()
}

/// The tail bins: beyond the maximum of P_l, P_l < p_max, count >= min_count.
pub fn tail(bins: &[PathBin], p_max: f64, min_count: f64) -> Vec<PathBin> {
    let Some(peak) = bins
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.density.total_cmp(&b.1.density))
        .map(|x| x.0)
    else {
        return Vec::new();
    };
    bins[peak..]
        .iter()
        .filter(|b| b.density > 0.0 && b.density < p_max && b.count >= min_count)
        .copied()
        .collect()
}

/// Fit (4.25) to the tail; with `fixed_df` the params are [ln A_0, C] (D_f fixed), else
/// [ln A_0, C, D_f].
pub fn fit_tail(bins: &[PathBin], fixed_df: Option<f64>) -> Option<Fit> {
    let n_par = if fixed_df.is_some() { 2 } else { 3 };
    if bins.len() < n_par + 2 {
        return None;
    }
    let l: Vec<f64> = bins.iter().map(|b| b.l).collect();
    let y: Vec<f64> = bins.iter().map(|b| b.density.ln()).collect();
    let s: Vec<f64> = bins.iter().map(|b| 1.0 / b.count.sqrt()).collect();
    // Start: D_f = 1.63 (or the fixed one), ln A_0 and C from the straight line
    // ln P - (D_f - 2) ln l = ln A_0 - C l^(D_f - 1).
    let df0 = fixed_df.unwrap_or(1.63);
    let u: Vec<f64> = l.iter().map(|l| l.powf(df0 - 1.0)).collect();
    let z: Vec<f64> = l
        .iter()
        .zip(&y)
        .map(|(l, y)| y - (df0 - 2.0) * l.ln())
        .collect();
    let start = fit::linear(&u, &z, Some(&s))?;
    let (la, c) = (start.params[0], -start.params[1]);
    match fixed_df {
        Some(df) => {
            let m = move |p: &[f64], l: f64| ln_tail(&[p[0], p[1], df], l);
            fit::levenberg_marquardt(&m, &l, &y, Some(&s), &[la, c])
        }
        None => fit::levenberg_marquardt(&ln_tail, &l, &y, Some(&s), &[la, c, df0]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::fit::tests::sd;
    use crate::rng::RunRng;

    /// Expected counts of (4.25) in log bins with Poisson-like noise: D_f and C recovered
    /// within their errors, and the errors match the scatter over seeds.
    #[test]
    fn tail_fit_recovers_df_and_c() {
        let truth = [273.0f64.ln(), 121.0, 1.63];
        let edges: Vec<f64> = (0..=80)
            .map(|j| 1e-4 * 10f64.powf(j as f64 / 20.0))
            .collect();
        // Expected counts K P_l(l) dl: ~1e5 at l = 1e-3 m down to a few at l = 0.03 m.
        let k = 1e6;
        let (mut dfs, mut errs, mut cs, mut cerrs) = (vec![], vec![], vec![], vec![]);
        for seed in 0..100 {
            let mut rng = RunRng::new(400 + seed);
            let bins: Vec<PathBin> = edges
                .windows(2)
                .map(|e| {
                    let l = (e[0] * e[1]).sqrt();
                    let mu = k * ln_tail(&truth, l).exp() * (e[1] - e[0]);
                    let count = (mu + mu.sqrt() * rng.normal()).round().max(0.0);
                    PathBin {
                        l,
                        density: count / (k * (e[1] - e[0])),
                        count,
                    }
                })
                .collect();
            let t = tail(&bins, f64::INFINITY, 10.0);
            let f = fit_tail(&t, None).unwrap();
            dfs.push(f.params[2]);
            errs.push(f.errors[2]);
            let g = fit_tail(&t, Some(1.63)).unwrap();
            cs.push(g.params[1]);
            cerrs.push(g.errors[1]);
        }
        let mean = dfs.iter().sum::<f64>() / dfs.len() as f64;
        let err = errs.iter().sum::<f64>() / errs.len() as f64;
        assert!(
            (mean - 1.63).abs() < 4.0 * err / 10.0,
            "D_f {mean} +- {err}"
        );
        assert!((sd(&dfs) / err - 1.0).abs() < 0.25, "{} vs {err}", sd(&dfs));
        let cm = cs.iter().sum::<f64>() / cs.len() as f64;
        let ce = cerrs.iter().sum::<f64>() / cerrs.len() as f64;
        assert!((cm - 121.0).abs() < 4.0 * ce / 10.0, "C {cm} +- {ce}");
        assert!((sd(&cs) / ce - 1.0).abs() < 0.25);
    }
}
