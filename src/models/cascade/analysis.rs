//! `granular analyze` of a cascade campaign: D_f per point from the finished runs' S(k)
//! (`cascade_structure_factor`), keyed by the variant, level and box, over 2 pi/L <= k <= 2 pi
//! 2^(n-3)/L (spec 3.4 [REC]: below the cell-scale periodic features), n = the point's
//! `level`, L its `box_length` (the typed [`CascadeParams`]); a row of `analysis_fits` and a
//! figure each.

use std::collections::BTreeMap;

use super::params::CascadeParams;
use super::tables::{CascadeStructureFactor, CASCADE_STRUCTURE_FACTOR};
use crate::analysis::{fig, line, num, slug, Analysis, AnalysisError};
use crate::math::power::{self, Sample};
use crate::models::CampaignView;
use crate::plot::{self, Series};

pub fn analyze(c: &CampaignView<'_, CascadeParams>, a: &mut Analysis) -> Result<(), AnalysisError> {
    a.start()?;
    let t = CASCADE_STRUCTURE_FACTOR;
    let mut by_point: BTreeMap<u32, Vec<Sample>> = BTreeMap::new();
    for b in c.read_done(t)? {
        for r in CascadeStructureFactor::read_rows(&b, t)? {
            by_point.entry(r.point_id).or_default().push(Sample {
                x: r.k,
                y: r.s_mean,
                err: r.s_sem,
            });
        }
    }
    if by_point.is_empty() {
        a.warn(format!("table {t} has no rows"));
    }
    for (p, pts) in by_point {
        let Some(point) = c.points.iter().find(|x| x.point_id == p) else {
            continue;
        };
        let params = point.params;
        // The variant as the manifest names it.
        let variant = match serde_json::to_value(params.variant) {
            Ok(serde_json::Value::String(s)) => s,
            other => format!("{other:?}"),
        };
        fit_point(a, &pts, &variant, params.level as f64, params.box_length);
    }
    Ok(())
}

/// D_f of one point's S(k) (`levels` n, box side `l`), its fit row and figure.
fn fit_point(a: &mut Analysis, pts: &[Sample], variant: &str, levels: f64, l: f64) {
    let key = format!("variant={variant},n={},L={}", num(levels), num(l));
    let two_pi = 2.0 * std::f64::consts::PI;
    let (k_lo, k_hi) = (
        two_pi / l * (1.0 - 1e-9),
        two_pi * 2f64.powf(levels - 3.0) / l * (1.0 + 1e-9),
    );
    let window = format!(
        "k L / 2 pi in [1, {}] (2 pi/L <= k <= 2 pi 2^(n-3)/L)",
        num(2f64.powf(levels - 3.0))
    );
    // The window's upper end is inclusive here.
    match power::decay_exponent(pts, k_lo, k_hi) {
        Some(f) => {
            a.fit(
                "D_f_cascade",
                &key,
                f.exponent,
                Some(f.error),
                f.fit.chi2_reduced,
                f.fit.n_points,
                window,
                None,
            );
            let (la, df) = (f.ln_amplitude, f.exponent);
            let series = vec![
                Series {
                    label: "S(k)".into(),
                    points: pts
                        .iter()
                        .filter(|s| s.y > 0.0)
                        .map(|s| (s.x, s.y, s.err.unwrap_or(0.0)))
                        .collect(),
                    line: false,
                },
                line(format!("k^-{df:.2}"), f.x_lo, f.x_hi, move |k| {
                    (la - df * k.ln()).exp()
                }),
            ];
            let fg = fig(
                a.title(&format!("cascade S(k) [{key}]")),
                "k (1/m)",
                "S(k)",
                series,
            );
            a.figure(format!("cascade-sk-{}", slug(&key)), plot::loglog(fg));
        }
        None => a.warn(format!(
            "{key}: fewer than two cascade S(k) points in {window}"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::Options;

    /// S = 2 k^-1.6 on the lattice shells of n = 8, L = 1 m (the test of the analysis of a
    /// cascade_structure_factor table that `tests/it/analyze.rs` made before the fit moved
    /// here): D_f = 1.6 exactly, every shell of k L / 2 pi <= 2^(8-3) in the window.
    #[test]
    fn df_of_a_power_law_structure_factor() {
        let mut shells: Vec<i64> = (0..=40i64)
            .flat_map(|a| (0..=40i64).map(move |b| a * a + b * b))
            .filter(|&s| s > 0 && s <= 1600)
            .collect();
        shells.sort_unstable();
        shells.dedup();
        let pts: Vec<Sample> = shells
            .iter()
            .map(|&s| {
                let k = 2.0 * std::f64::consts::PI * (s as f64).sqrt();
                let y = 2.0 * k.powf(-1.6);
                Sample {
                    x: k,
                    y,
                    err: Some(0.01 * y),
                }
            })
            .collect();
        let mut a = Analysis::new("c", &Options::default(), 1, 1);
        fit_point(&mut a, &pts, "ucp", 8.0, 1.0);
        let fits = &a.report.fits;
        assert_eq!(fits.len(), 1);
        let cas = &fits[0];
        assert_eq!(cas.quantity, "D_f_cascade");
        assert!((cas.value - 1.6).abs() < 1e-9, "cascade D_f {}", cas.value);
        assert!(cas.key.starts_with("variant="), "{}", cas.key);
        assert_eq!(cas.key, "variant=ucp,n=8,L=1");
        // Shells n^2 = a^2 + b^2 in (0, 1024]: every one is in the window.
        let in_window = (0..=32i64)
            .flat_map(|a| (0..=32i64).map(move |b| a * a + b * b))
            .filter(|&s| s > 0 && s <= 1024)
            .collect::<std::collections::BTreeSet<_>>()
            .len();
        assert_eq!(cas.n_points as usize, in_window);
    }
}
