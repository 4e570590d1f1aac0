//! The standard figures of an SPM campaign, from the run tables: the points overlaid, at most
//! [`crate::models::OVERLAY_MAX`] per figure, log y so that the tails show:
//!
//! - `velocity-distribution`: the time-weighted P(v) (Q(v, l) for a fixed free path) of the
//!   velocity components, with the measured tail exponent (and the predicted one, (5.29))
//!   from `spm_summary` in the legend (`α=measured/predicted`);
//! - `velocity-distribution-walk`: the same with every walk weighted equally ((5.10) as
//!   written, spec 6.5).
//!
//! The replicas of a point are averaged; the error bars are their spread with two replicas or
//! more, else the counting error density / sqrt(count) of the one run.

use std::collections::BTreeMap;

use arrow_array::RecordBatch;

use super::params::{FreePathSpec, SpmParams};
use super::tables::{SpmSummaryCols, SpmVelocityHistogram, SPM_SUMMARY, SPM_VELOCITY_HISTOGRAM};
use crate::math::stats::mean_sem;
use crate::models::{overlay_figures, CampaignView, Overlay, PointCurve};
use crate::plot::Figure;
use crate::store::parquet_io::StoreError;

/// One run's bin: (v centre, count, time-weighted density, walk-weighted density).
type Bin = (f64, u64, f64, f64);

/// point -> run -> bins.
pub(crate) type Runs = BTreeMap<u32, BTreeMap<u64, Vec<Bin>>>;

pub(crate) fn read_histogram(batches: &[RecordBatch]) -> Result<Runs, StoreError> {
    let t = SPM_VELOCITY_HISTOGRAM;
    let mut out = Runs::new();
    for b in batches {
        for r in SpmVelocityHistogram::read_rows(b, t)? {
            out.entry(r.point_id)
                .or_default()
                .entry(r.run_id)
                .or_default()
                .push((0.5 * (r.v_lo + r.v_hi), r.count, r.density, r.density_walk));
        }
    }
    Ok(out)
}

/// A point's runs combined into (v, density, error) of the time-weighted (`walk` false) or
/// walk-weighted density; empty bins left out.
pub(crate) fn combine(runs: &BTreeMap<u64, Vec<Bin>>, walk: bool) -> Vec<(f64, f64, f64)> {
    let mut by_v: BTreeMap<u64, Vec<Bin>> = BTreeMap::new();
    for bins in runs.values() {
        for b in bins {
            by_v.entry(b.0.to_bits()).or_default().push(*b);
        }
    }
    let mut out: Vec<(f64, f64, f64)> = by_v
        .values()
        .filter_map(|bins| {
            let d: Vec<f64> = bins.iter().map(|b| if walk { b.3 } else { b.2 }).collect();
            let count: u64 = bins.iter().map(|b| b.1).sum();
            let (mean, sem) = mean_sem(&d);
            let err = match sem {
                Some(s) if bins.len() >= 2 => s,
                _ => mean / (count.max(1) as f64).sqrt(),
            };
            (count > 0 && mean > 0.0).then_some((bins[0].0, mean, err))
        })
        .collect();
    out.sort_by(|a, b| a.0.total_cmp(&b.0));
    out
}

/// (alpha measured, alpha predicted).
type Alphas = (Option<f64>, Option<f64>);

/// (point) -> (alpha measured, alpha predicted) of the first run of `spm_summary`.
fn read_alphas(batches: &[RecordBatch]) -> Result<BTreeMap<u32, Alphas>, StoreError> {
    let t = SPM_SUMMARY;
    let mut first: BTreeMap<u32, (u64, Option<f64>, Option<f64>)> = BTreeMap::new();
    for b in batches {
        let cols = SpmSummaryCols::read(b, t)?;
        for i in 0..cols.len() {
            let e = first
                .entry(cols.point_id.value(i))
                .or_insert((u64::MAX, None, None));
            let r = cols.row(i);
            if r.run_id < e.0 {
                *e = (r.run_id, r.alpha_measured, r.alpha_predicted);
            }
        }
    }
    Ok(first.into_iter().map(|(p, e)| (p, (e.1, e.2))).collect())
}

/// A point's legend label from its parameters.
fn label(p: &SpmParams) -> String {
    match &p.free_path {
        FreePathSpec::Fixed { length } => format!("l={length} m"),
        FreePathSpec::Fitted {
            c,
            fractal_dimension,
            ..
        } => format!("C={c} D_f={fractal_dimension}"),
        FreePathSpec::Table { edges, .. } => format!("table of {} bins", edges.len() - 1),
    }
}

/// The standard figures of a campaign (data only; `plot` draws them).
pub fn figures(c: &CampaignView<'_, SpmParams>) -> Result<Vec<(String, Figure)>, StoreError> {
    let runs = read_histogram(&c.read_done(SPM_VELOCITY_HISTOGRAM)?)?;
    let alphas = read_alphas(&c.read_done(SPM_SUMMARY)?)?;
    let point_label = |p: u32| {
        let mut l = c
            .points
            .iter()
            .find(|v| v.point_id == p)
            .map(|v| label(v.params))
            .unwrap_or_else(|| c.point_label(p));
        if let Some((Some(m), pred)) = alphas.get(&p) {
            l = match pred {
                Some(pr) => format!("\u{3b1}={m:.2}/{pr:.2} {l}"),
                None => format!("\u{3b1}={m:.2} {l}"),
            };
        }
        l
    };
    let mut figs = Vec::new();
    for (walk, id, what) in [
        (
            false,
            "velocity-distribution",
            "P(v), time-weighted (legend: tail alpha measured/predicted)",
        ),
        (
            true,
            "velocity-distribution-walk",
            "P(v), every walk weighted equally",
        ),
    ] {
        let curves = runs
            .iter()
            .map(|(&p, r)| PointCurve {
                point: p,
                label: point_label(p),
                data: combine(r, walk),
                line: None,
            })
            .collect();
        figs.extend(overlay_figures(
            c.name,
            &Overlay {
                id,
                what,
                x_label: "v (m/s)",
                y_label: "P(v) (s/m)",
                log_x: false,
                log_y: true,
                legend_low: false,
            },
            curves,
            &|_, _| Vec::new(),
        ));
    }
    Ok(figs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replicas_averaged_spread_or_counting_errors() {
        let mut runs: BTreeMap<u64, Vec<Bin>> = BTreeMap::new();
        runs.insert(0, vec![(-0.5, 4, 1.0, 2.0), (0.5, 0, 0.0, 0.0)]);
        // One run: the counting error.
        assert_eq!(combine(&runs, false), vec![(-0.5, 1.0, 0.5)]);
        assert_eq!(combine(&runs, true), vec![(-0.5, 2.0, 1.0)]);
        // Two runs: their mean and its standard error.
        runs.insert(1, vec![(-0.5, 4, 3.0, 2.0), (0.5, 1, 0.5, 0.5)]);
        let two = combine(&runs, false);
        assert_eq!(two.len(), 2);
        assert_eq!((two[0].1, two[0].2), (2.0, 1.0));
        assert_eq!((two[1].0, two[1].1), (0.5, 0.25));
    }
}
