//! The standard figures of a cascade campaign: the points overlaid, at most
//! [`crate::models::OVERLAY_MAX`] per figure:
//!
//! - `structure-factor` (log-log): S(k) (6.5) of the weight field, replica mean and error
//!   (`cascade_structure_factor_summary`; beyond `models::MAX_LOG_ROWS` shells averaged in 50
//!   bins per decade of k for display), with the fitted A k^-D_f over its fit window as a
//!   line in the point's colour (`cascade_fit`, D_f and ln A averaged over the replicas; D_f in
//!   the legend);
//! - `placement-structure-factor`: the same for the placed discs (source `placement`);
//! - `placement-<point>` (at most [`MAX_PLACEMENTS`] points): the placed discs of the point's
//!   first replica (F 6.3).

use std::collections::BTreeMap;

use arrow_array::RecordBatch;

use super::params::CascadeParams;
use super::tables::{
    CascadeFit, CascadePlacementCols, CascadeStructureFactorSummary, CASCADE_FIT,
    CASCADE_PLACEMENT, CASCADE_STRUCTURE_FACTOR_SUMMARY,
};
use crate::models::{log_binned, overlay_figures, CampaignView, Overlay, PointCurve, Rows};
use crate::plot::{Figure, Series};
use crate::store::parquet_io::StoreError;

/// Display bins per decade of k of a point with more than `models::MAX_LOG_ROWS` shells.
const SHELLS_PER_DECADE: f64 = 50.0;

/// Most points whose placed discs are drawn.
pub const MAX_PLACEMENTS: usize = 4;

/// (point, source) -> (k, S mean, error), sorted by k.
pub(crate) type Sk = BTreeMap<(u32, String), Vec<(f64, f64, f64)>>;

pub(crate) fn read_summary(batches: &[RecordBatch]) -> Result<Sk, StoreError> {
    let t = CASCADE_STRUCTURE_FACTOR_SUMMARY;
    let mut out = Sk::new();
    for b in batches {
        for r in CascadeStructureFactorSummary::read_rows(b, t)? {
            out.entry((r.point_id, r.source)).or_default().push((
                r.k,
                r.s_mean,
                r.s_sem.unwrap_or(0.0),
            ));
        }
    }
    for v in out.values_mut() {
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        // Shells where S vanishes to rounding (the symmetrised process at some k) would
        // stretch the log axis over 30 decades: left out.
        let max = v.iter().map(|r| r.1).fold(0.0, f64::max);
        v.retain(|r| r.1 > ROUNDING * max);
    }
    Ok(out)
}

/// S(k) below this fraction of the series' largest value is rounding, not data.
const ROUNDING: f64 = 1e-15;

/// A fit averaged over the replicas: (D_f, A, k_lo, k_hi).
pub(crate) type Fit = (f64, f64, f64, f64);

/// (point, source) -> the runs' fits averaged (D_f and ln A; the window of the first run).
pub(crate) fn read_fits(
    batches: &[RecordBatch],
) -> Result<BTreeMap<(u32, String), Fit>, StoreError> {
    let t = CASCADE_FIT;
    // (point, source) -> run -> (d_f, amplitude, k_lo, k_hi)
    let mut runs: BTreeMap<(u32, String), BTreeMap<u64, Fit>> = BTreeMap::new();
    for b in batches {
        for r in CascadeFit::read_rows(b, t)? {
            let (Some(df), Some(a)) = (r.d_f, r.amplitude) else {
                continue;
            };
            if a > 0.0 {
                runs.entry((r.point_id, r.source))
                    .or_default()
                    .entry(r.run_id)
                    .or_insert((df, a, r.k_lo, r.k_hi));
            }
        }
    }
    Ok(runs
        .into_iter()
        .map(|(key, fits)| {
            let n = fits.len() as f64;
            let first = *fits.values().next().expect("a run");
            let df = fits.values().map(|f| f.0).sum::<f64>() / n;
            let ln_a = fits.values().map(|f| f.1.ln()).sum::<f64>() / n;
            (key, (df, ln_a.exp(), first.2, first.3))
        })
        .collect())
}

/// A k^-D_f at the k of `rows` inside the fit window.
pub(crate) fn fit_line(rows: &[(f64, f64, f64)], fit: &Fit) -> Vec<(f64, f64, f64)> {
    let (df, a, lo, hi) = *fit;
    rows.iter()
        .filter(|r| r.0 >= lo * (1.0 - 1e-9) && r.0 <= hi * (1.0 + 1e-9))
        .map(|r| (r.0, a * r.0.powf(-df), 0.0))
        .collect()
}

fn label(c: &CampaignView<'_, CascadeParams>, p: u32) -> String {
    c.points
        .iter()
        .find(|v| v.point_id == p)
        .map(|v| {
            let variant = serde_json::to_value(v.params.variant)
                .ok()
                .and_then(|x| x.as_str().map(str::to_string))
                .unwrap_or_default();
            format!("{variant}, n={}", v.params.level)
        })
        .unwrap_or_else(|| c.point_label(p))
}

/// The standard figures of a campaign (data only; `plot` draws them).
pub fn figures(c: &CampaignView<'_, CascadeParams>) -> Result<Vec<(String, Figure)>, StoreError> {
    let sk = read_summary(&c.data.read(CASCADE_STRUCTURE_FACTOR_SUMMARY)?)?;
    let fits = read_fits(&c.read_done(CASCADE_FIT)?)?;
    let mut figs = Vec::new();
    for (source, id, what) in [
        (
            "field",
            "structure-factor",
            "S(k) of the weight field (lines: fits A k^-D_f)",
        ),
        (
            "placement",
            "placement-structure-factor",
            "S(k) of the placed discs (lines: fits A k^-D_f)",
        ),
    ] {
        let curves = sk
            .iter()
            .filter(|((_, s), _)| s == source)
            .map(|((p, s), rows)| {
                let fit = fits.get(&(*p, s.clone()));
                let mut label = label(c, *p);
                if let Some(f) = fit {
                    label = format!("D_f={:.2}, {label}", f.0);
                }
                let shown = log_binned(rows, SHELLS_PER_DECADE);
                PointCurve {
                    point: *p,
                    label,
                    line: fit
                        .map(|f| (String::new(), fit_line(&shown, f)))
                        .filter(|l| !l.1.is_empty()),
                    data: shown,
                }
            })
            .collect();
        figs.extend(overlay_figures(
            c.name,
            &Overlay {
                id,
                what,
                x_label: "k (1/m)",
                y_label: "S(k)",
                log_x: true,
                log_y: true,
                legend_low: false,
            },
            curves,
            &|_, _| Vec::new(),
        ));
    }
    figs.extend(placements(c)?);
    Ok(figs)
}

/// The placed discs of the first replica of the first points that have them.
fn placements(c: &CampaignView<'_, CascadeParams>) -> Result<Vec<(String, Figure)>, StoreError> {
    let t = CASCADE_PLACEMENT;
    // point -> (first run, its discs)
    let mut first: BTreeMap<u32, (u64, Rows)> = BTreeMap::new();
    for b in c.read_done(t)? {
        let CascadePlacementCols {
            run_id: r,
            point_id: p,
            x,
            y,
            ..
        } = CascadePlacementCols::read(&b, t)?;
        for i in 0..b.num_rows() {
            let e = first.entry(p.value(i)).or_insert((r.value(i), Vec::new()));
            if r.value(i) < e.0 {
                *e = (r.value(i), Vec::new());
            }
            if r.value(i) == e.0 {
                e.1.push((x.value(i), y.value(i), 0.0));
            }
        }
    }
    Ok(first
        .into_iter()
        .take(MAX_PLACEMENTS)
        .map(|(p, (run, discs))| {
            let n = discs.len();
            let mut fig = Figure::new(
                format!("{} - placed discs, run {run} ({n} discs)", c.name),
                "x (m)",
                "y (m)",
                vec![Series {
                    label: label(c, p),
                    points: discs,
                    line: false,
                }],
            );
            fig.log_x = false;
            (format!("placement-{p:04}"), fig)
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fits_averaged_over_replicas_and_drawn_in_their_window() {
        type Row = (u64, u32, &'static str, f64, f64, Option<f64>, Option<f64>);
        let rows: Vec<Row> = vec![
            (0, 0, "field", 2.0, 8.0, Some(1.5), Some(2.0)),
            (1, 0, "field", 2.0, 8.0, Some(1.7), Some(8.0)),
            (2, 1, "field", 2.0, 8.0, None, None),
            (0, 0, "placement", 2.0, 8.0, Some(0.1), Some(1.0)),
        ];
        let rows: Vec<CascadeFit> = rows
            .iter()
            .map(|r| CascadeFit {
                run_id: r.0,
                point_id: r.1,
                source: r.2.into(),
                variant: "v".into(),
                level: 3,
                k_lo: r.3,
                k_hi: r.4,
                n_shells: 4,
                d_f: r.5,
                d_f_err: None,
                amplitude: r.6,
                chi2_red: None,
                d_f_thesis: None,
                d_f_thesis_err: None,
                weight_sum_mean: 1.0,
                weight_sum_sem: None,
                attempts: None,
            })
            .collect();
        let b = CascadeFit::batch(&rows);
        let f = read_fits(&[b]).unwrap();
        assert_eq!(f.len(), 2, "a failed fit (no D_f) has no line");
        let (df, a, lo, hi) = f[&(0, "field".to_string())];
        assert!((df - 1.6).abs() < 1e-12);
        assert!((a - 4.0).abs() < 1e-12, "geometric mean of 2 and 8");
        assert_eq!((lo, hi), (2.0, 8.0));
        let data: Vec<(f64, f64, f64)> = [1.0, 2.0, 4.0, 8.0, 16.0]
            .iter()
            .map(|&k| (k, 1.0, 0.1))
            .collect();
        let line = fit_line(&data, &(2.0, 4.0, 2.0, 8.0));
        assert_eq!(
            line,
            vec![(2.0, 1.0, 0.0), (4.0, 0.25, 0.0), (8.0, 0.0625, 0.0)]
        );
    }

    #[test]
    fn summary_rows_per_point_and_source() {
        type Row = (u32, &'static str, f64, f64, Option<f64>);
        let rows: Vec<Row> = vec![
            (0, "field", 2.0, 5.0, Some(0.5)),
            (0, "field", 1.0, 9.0, None),
            (0, "placement", 1.0, 0.8, Some(0.1)),
            (0, "placement", 3.0, 1e-20, Some(1e-21)),
        ];
        let rows: Vec<CascadeStructureFactorSummary> = rows
            .iter()
            .map(|r| CascadeStructureFactorSummary {
                point_id: r.0,
                source: r.1.into(),
                n2: 1,
                k: r.2,
                n_vectors: 4,
                n_replicas: 1,
                n_realisations: 1,
                s_mean: r.3,
                s_sem: r.4,
            })
            .collect();
        let b = CascadeStructureFactorSummary::batch(&rows);
        let s = read_summary(&[b]).unwrap();
        assert_eq!(
            s[&(0, "field".to_string())],
            vec![(1.0, 9.0, 0.0), (2.0, 5.0, 0.5)]
        );
        assert_eq!(
            s[&(0, "placement".to_string())],
            vec![(1.0, 0.8, 0.1)],
            "a rounding-level S left out"
        );
    }
}
