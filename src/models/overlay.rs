//! The figures every model draws alike: points overlaid on one figure (at most
//! [`OVERLAY_MAX`] each), rows thinned on a log grid.

use crate::plot::{Figure, Series};

/// Most points one overlay figure shows (one data series each, with its line): more are split
/// over several figures of as even a size as possible, so a 30-point campaign gives 3 figures
/// of 10 points per observable.
pub const OVERLAY_MAX: usize = 12;

/// `items` (in point order) split into the groups of the overlay figures (at most
/// [`OVERLAY_MAX`] each, sizes differing by at most one).
pub fn overlay_groups<T>(items: Vec<T>) -> Vec<Vec<T>> {
    let n = items.len().div_ceil(OVERLAY_MAX);
    let mut out: Vec<Vec<T>> = (0..n).map(|_| Vec::new()).collect();
    let len = items.len();
    for (i, x) in items.into_iter().enumerate() {
        out[i * n / len.max(1)].push(x);
    }
    out
}

/// Most (x, y, error) rows of a log-x series drawn as they are: S(k) of a large system has
/// thousands of shells, which [`log_binned`] averages for display.
pub const MAX_LOG_ROWS: usize = 400;

/// `rows` (sorted by x > 0) averaged in bins of `per_decade` per decade of x when there are
/// more than [`MAX_LOG_ROWS`]: per bin the geometric mean of x, the mean of y and
/// sqrt(sum err^2)/n (the rows' errors as independent); fewer rows are returned as they are.
pub fn log_binned(rows: &[(f64, f64, f64)], per_decade: f64) -> Vec<(f64, f64, f64)> {
    if rows.len() <= MAX_LOG_ROWS {
        return rows.to_vec();
    }
    let mut out = Vec::new();
    let mut bin: Vec<(f64, f64, f64)> = Vec::new();
    let key = |x: f64| (x.log10() * per_decade).floor() as i64;
    for &r in rows.iter().filter(|r| r.0 > 0.0) {
        if bin.last().is_some_and(|b| key(b.0) != key(r.0)) {
            out.push(average(&bin));
            bin.clear();
        }
        bin.push(r);
    }
    if !bin.is_empty() {
        out.push(average(&bin));
    }
    out
}

fn average(bin: &[(f64, f64, f64)]) -> (f64, f64, f64) {
    let n = bin.len() as f64;
    (
        (bin.iter().map(|r| r.0.ln()).sum::<f64>() / n).exp(),
        bin.iter().map(|r| r.1).sum::<f64>() / n,
        bin.iter().map(|r| r.2 * r.2).sum::<f64>().sqrt() / n,
    )
}

/// One observable drawn as overlay figures, one series per point.
pub struct Overlay<'a> {
    /// Figure id (`<id>`, or `<id>-<g>of<n>` when split).
    pub id: &'a str,
    /// Title after the campaign's name.
    pub what: &'a str,
    pub x_label: &'a str,
    pub y_label: &'a str,
    pub log_x: bool,
    pub log_y: bool,
    pub legend_low: bool,
}

/// (x, y, error) rows of a figure's series.
pub type Rows = Vec<(f64, f64, f64)>;

/// One point's curve of an [`Overlay`]: its (x, y, error) data, drawn as markers with error
/// bars, and an optional line drawn after it in its colour (exact result, theory, fit).
pub struct PointCurve {
    pub point: u32,
    pub label: String,
    pub data: Rows,
    /// (legend label, rows) of the line.
    pub line: Option<(String, Rows)>,
}

/// The figures of an overlay: the curves split by [`overlay_groups`], each figure followed by
/// the reference lines `refs` (own colours; each clipped to the figure's x range). No curve, no
/// figure.
pub fn overlay_figures(
    campaign: &str,
    o: &Overlay,
    curves: Vec<PointCurve>,
    refs: &dyn Fn(f64, f64) -> Vec<Series>,
) -> Vec<(String, Figure)> {
    let curves: Vec<PointCurve> = curves.into_iter().filter(|c| !c.data.is_empty()).collect();
    let groups = overlay_groups(curves);
    let n = groups.len();
    let mut out = Vec::new();
    for (g, group) in groups.into_iter().enumerate() {
        let (id, what) = if n == 1 {
            (o.id.to_string(), o.what.to_string())
        } else {
            let (a, b) = (group[0].point, group[group.len() - 1].point);
            (
                format!("{}-{}of{n}", o.id, g + 1),
                format!("{} (points {a}-{b})", o.what),
            )
        };
        let (mut x0, mut x1) = (f64::INFINITY, f64::NEG_INFINITY);
        let mut series = Vec::new();
        for c in group {
            for p in &c.data {
                if !o.log_x || p.0 > 0.0 {
                    x0 = x0.min(p.0);
                    x1 = x1.max(p.0);
                }
            }
            series.push(Series {
                label: c.label,
                points: c.data,
                line: false,
            });
            if let Some((label, points)) = c.line {
                series.push(Series {
                    label,
                    points,
                    line: true,
                });
            }
        }
        let first_ref = series.len();
        series.extend(refs(x0, x1));
        let mut fig = Figure::new(format!("{campaign} - {what}"), o.x_label, o.y_label, series);
        fig.log_x = o.log_x;
        fig.log_y = o.log_y;
        fig.legend_low = o.legend_low;
        if fig.series.len() > first_ref {
            fig = fig.with_references_from(first_ref);
        }
        out.push((id, fig));
    }
    out
}
