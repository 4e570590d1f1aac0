//! The standard figures of a bisection campaign, from the run tables (each run already
//! averages its realisations; the replicas of a point are averaged here, the error
//! sqrt(sum sem_r^2)/n from the runs' realisation-to-realisation errors): the points
//! overlaid, at most [`crate::models::OVERLAY_MAX`] per figure:
//!
//! - `length-distribution` (log-log): P_n(x) of the partition lengths (markers), with the exact
//!   bin average of P_n(x) = (-ln x)^(n-1)/(n-1)! (3.36) as a line where the split is uniform;
//! - `moments` (log y): <x^m> against m, with the exact <a^m>^n (3.37) as a line.

use std::collections::BTreeMap;

use arrow_array::RecordBatch;

use super::params::{BisectionParams, SplitSpec};
use super::tables::{BisectionHistogram, BisectionMoments, BISECTION_HISTOGRAM, BISECTION_MOMENTS};
use crate::math::stats::mean_sem;
use crate::models::{overlay_figures, CampaignView, Overlay, PointCurve};
use crate::plot::Figure;
use crate::store::parquet_io::StoreError;

/// One run's row: (x, value, sem, exact).
type RunRow = (f64, f64, Option<f64>, Option<f64>);

/// point -> run -> rows (a run counted once: the first file holding a run id wins).
pub(crate) type Runs = BTreeMap<u32, BTreeMap<u64, Vec<RunRow>>>;

/// `bisection_histogram`: (geometric bin centre, density, sem, exact) per point and run; the
/// row below the first bin ([0, x_min)) is left out.
pub(crate) fn read_histogram(files: &[Vec<RecordBatch>]) -> Result<Runs, StoreError> {
    let t = BISECTION_HISTOGRAM;
    let mut out = Runs::new();
    let mut seen: BTreeMap<(u32, u64), usize> = BTreeMap::new();
    for (fi, b) in files
        .iter()
        .enumerate()
        .flat_map(|(fi, f)| f.iter().map(move |b| (fi, b)))
    {
        for r in BisectionHistogram::read_rows(b, t)? {
            if *seen.entry((r.point_id, r.run_id)).or_insert(fi) != fi || r.x_lo <= 0.0 {
                continue;
            }
            out.entry(r.point_id)
                .or_default()
                .entry(r.run_id)
                .or_default()
                .push((
                    (r.x_lo * r.x_hi).sqrt(),
                    r.density,
                    r.density_sem,
                    r.density_exact,
                ));
        }
    }
    Ok(out)
}

/// `bisection_moments`: (order, mean, sem, exact) per point and run.
pub(crate) fn read_moments(files: &[Vec<RecordBatch>]) -> Result<Runs, StoreError> {
    let t = BISECTION_MOMENTS;
    let mut out = Runs::new();
    let mut seen: BTreeMap<(u32, u64), usize> = BTreeMap::new();
    for (fi, b) in files
        .iter()
        .enumerate()
        .flat_map(|(fi, f)| f.iter().map(move |b| (fi, b)))
    {
        for r in BisectionMoments::read_rows(b, t)? {
            if *seen.entry((r.point_id, r.run_id)).or_insert(fi) != fi {
                continue;
            }
            out.entry(r.point_id)
                .or_default()
                .entry(r.run_id)
                .or_default()
                .push((r.order as f64, r.mean, r.sem, Some(r.exact)));
        }
    }
    Ok(out)
}

/// A point's runs combined: per x, the mean over the runs and its error (sqrt(sum sem^2)/n,
/// or the runs' spread where a run has no error), and the exact values (of the first run).
/// Values that are not positive are left out (log axes).
pub(crate) type Combined = (Vec<(f64, f64, f64)>, Vec<(f64, f64, f64)>);

pub(crate) fn combine(runs: &BTreeMap<u64, Vec<RunRow>>) -> Combined {
    let mut by_x: BTreeMap<u64, Vec<RunRow>> = BTreeMap::new();
    for rows in runs.values() {
        for r in rows {
            by_x.entry(r.0.to_bits()).or_default().push(*r);
        }
    }
    let (mut data, mut exact) = (Vec::new(), Vec::new());
    for rows in by_x.values() {
        let x = rows[0].0;
        let n = rows.len() as f64;
        let values: Vec<f64> = rows.iter().map(|r| r.1).collect();
        let mean = values.iter().sum::<f64>() / n;
        let err = rows
            .iter()
            .map(|r| r.2.map(|s| s * s))
            .sum::<Option<f64>>()
            .map(|s2| s2.sqrt() / n)
            .or_else(|| mean_sem(&values).1)
            .unwrap_or(0.0);
        if mean > 0.0 {
            data.push((x, mean, err));
        }
        if let Some(e) = rows[0].3.filter(|&e| e > 0.0) {
            exact.push((x, e, 0.0));
        }
    }
    data.sort_by(|a, b| a.0.total_cmp(&b.0));
    exact.sort_by(|a, b| a.0.total_cmp(&b.0));
    (data, exact)
}

/// A point's legend label from its parameters: level and split.
fn label(p: &BisectionParams) -> String {
    match p.split {
        SplitSpec::Uniform => format!("n={}, uniform", p.level),
        SplitSpec::Concave { exponent } => format!("n={}, concave A={exponent}", p.level),
    }
}

fn curves(
    c: &CampaignView<'_, BisectionParams>,
    runs: &Runs,
    exact_label: &str,
) -> Vec<PointCurve> {
    runs.iter()
        .map(|(&p, r)| {
            let (data, exact) = combine(r);
            let label = c
                .points
                .iter()
                .find(|v| v.point_id == p)
                .map(|v| label(v.params))
                .unwrap_or_else(|| c.point_label(p));
            PointCurve {
                point: p,
                label,
                data,
                line: (!exact.is_empty()).then(|| (exact_label.to_string(), exact)),
            }
        })
        .collect()
}

/// The batches of every file of `table`, file by file, with the rows of the runs the view
/// describes (the latest manifest's).
fn read_files(
    c: &CampaignView<'_, BisectionParams>,
    table: &str,
) -> Result<Vec<Vec<RecordBatch>>, StoreError> {
    c.data
        .files(table)?
        .iter()
        .map(|f| {
            c.data
                .read_file(f, table)?
                .iter()
                .map(|b| c.keep_done(b, table))
                .collect()
        })
        .collect()
}

/// The standard figures of a campaign (data only; `plot` draws them).
pub fn figures(c: &CampaignView<'_, BisectionParams>) -> Result<Vec<(String, Figure)>, StoreError> {
    let mut figs = Vec::new();
    let hist = read_histogram(&read_files(c, BISECTION_HISTOGRAM)?)?;
    figs.extend(overlay_figures(
        c.name,
        &Overlay {
            id: "length-distribution",
            what: "partition lengths P_n(x) (lines: exact, uniform split)",
            x_label: "length x",
            y_label: "P_n(x)",
            log_x: true,
            log_y: true,
            legend_low: false,
        },
        curves(c, &hist, ""),
        &|_, _| Vec::new(),
    ));
    let mo = read_moments(&read_files(c, BISECTION_MOMENTS)?)?;
    figs.extend(overlay_figures(
        c.name,
        &Overlay {
            id: "moments",
            what: "moments <x^m> (lines: exact <a^m>^n)",
            x_label: "order m",
            y_label: "<x^m>",
            log_x: false,
            log_y: true,
            legend_low: false,
        },
        curves(c, &mo, ""),
        &|_, _| Vec::new(),
    ));
    Ok(figs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replicas_averaged_with_propagated_errors() {
        type Row = (u64, u32, f64, f64, f64, Option<f64>, Option<f64>);
        let rows: Vec<Row> = vec![
            (0, 0, 0.0, 1e-3, 5.0, None, None),
            (0, 0, 1e-3, 1e-2, 2.0, Some(0.3), Some(2.1)),
            (1, 0, 1e-3, 1e-2, 4.0, Some(0.4), Some(2.1)),
            (2, 1, 0.1, 1.0, 1.0, None, None),
            (3, 1, 0.1, 1.0, 3.0, None, None),
        ];
        let rows: Vec<BisectionHistogram> = rows
            .iter()
            .map(|r| BisectionHistogram {
                run_id: r.0,
                point_id: r.1,
                x_lo: r.2,
                x_hi: r.3,
                count: 1,
                density: r.4,
                density_sem: r.5,
                density_exact: r.6,
            })
            .collect();
        let b = BisectionHistogram::batch(&rows);
        // A run's rows split over batches of one file all count; the same run in a second
        // file (a doubled run) counts once.
        let (head, tail) = (b.slice(0, 1), b.slice(1, 4));
        let runs = read_histogram(&[vec![head, tail], vec![b]]).unwrap();
        assert_eq!(runs[&0].len(), 2);
        assert_eq!(runs[&0][&0].len(), 1, "the [0, x_min) row is left out");
        let (data, exact) = combine(&runs[&0]);
        assert_eq!(data.len(), 1);
        let x = (1e-3f64 * 1e-2).sqrt();
        assert!((data[0].0 - x).abs() < 1e-15);
        assert_eq!(data[0].1, 3.0);
        assert!((data[0].2 - 0.25).abs() < 1e-12, "sqrt(0.09 + 0.16)/2");
        assert_eq!(exact, vec![(data[0].0, 2.1, 0.0)]);
        // Without run errors: the spread of the replicas; no exact line.
        let (data, exact) = combine(&runs[&1]);
        assert_eq!((data[0].1, data[0].2), (2.0, 1.0));
        assert!(exact.is_empty());
    }
}
