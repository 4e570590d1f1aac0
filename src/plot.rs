//! The one figure renderer (PNG and SVG, plotters, the embedded DejaVu Sans font): figures of
//! series of (x, y, error) points, drawn as markers with error bars or as lines, on any
//! combination of linear and logarithmic axes (a log axis is drawn as log10 of the data on a
//! linear chart, its ticks labelled with the original values); or a heatmap: a grid of values
//! (rows x columns, labelled) as coloured cells on a diverging scale clamped at +-`limit`, with
//! a colour bar. What a figure shows is the business of its model (`models::<model>::figures`)
//! or of the analysis.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

static FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

/// One curve: (x, y, error) points.
#[derive(Clone, Debug, Default)]
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64, f64)>,
    /// Drawn as a line (theory, fit) rather than markers with error bars.
    pub line: bool,
}

/// A figure: its series, labels and axis types.
#[derive(Clone, Debug)]
pub struct Figure {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
    pub log_x: bool,
    pub log_y: bool,
    /// Legend rows from the bottom of the legend column (growing curves) rather than the top.
    pub legend_low: bool,
    /// Series from this index on are reference lines (theory, guides) with their own colours
    /// rather than fits drawn in the colour of the data before them.
    pub references_from: Option<usize>,
    /// Drawn as this heatmap (`series` and the axis types unused): `x_label` describes the
    /// columns, `y_label` the rows.
    pub heatmap: Option<Heatmap>,
}

/// A grid of values drawn as coloured cells: blue (negative) - white (0) - red (positive),
/// clamped at +-`limit`; missing values grey. Row labels on the left (top row first), column
/// labels below (thinned when they would overlap), a colour bar on the right, and the values
/// written in the cells when the grid is small enough to read them. The figure grows taller
/// with the rows (at least `HEAT_MIN_ROW` pixels each) and wider with the columns.
#[derive(Clone, Debug, Default)]
pub struct Heatmap {
    pub rows: Vec<String>,
    pub cols: Vec<String>,
    /// `values[row][col]`.
    pub values: Vec<Vec<Option<f64>>>,
    /// The colour scale runs over [-limit, limit]; values beyond take the end colours.
    pub limit: f64,
    /// What the colour bar measures.
    pub scale_label: String,
}

impl Figure {
    /// A figure with linear axes and the legend in the upper right.
    pub fn new(title: String, x_label: &str, y_label: &str, series: Vec<Series>) -> Self {
        Figure {
            title,
            x_label: x_label.into(),
            y_label: y_label.into(),
            series,
            log_x: false,
            log_y: false,
            legend_low: false,
            references_from: None,
            heatmap: None,
        }
    }

    /// A heatmap figure: `x_label` describes the columns, `y_label` the rows.
    pub fn heatmap(title: String, x_label: &str, y_label: &str, heatmap: Heatmap) -> Self {
        Figure {
            heatmap: Some(heatmap),
            ..Figure::new(title, x_label, y_label, Vec::new())
        }
    }

    /// The figure's size in pixels: `SIZE`, or for a heatmap as tall and wide as its grid
    /// needs.
    pub fn size(&self) -> (u32, u32) {
        match &self.heatmap {
            Some(h) => heat_layout(&self.title, h).size,
            None => SIZE,
        }
    }
}

/// `fig` on log-log axes.
pub fn loglog(fig: Figure) -> Figure {
    Figure {
        log_x: true,
        log_y: true,
        ..fig
    }
}

/// `fig` on linear axes.
pub fn linear(fig: Figure) -> Figure {
    Figure {
        log_x: false,
        log_y: false,
        ..fig
    }
}

/// `fig` with a logarithmic y axis.
pub fn semilog_y(fig: Figure) -> Figure {
    Figure {
        log_x: false,
        log_y: true,
        ..fig
    }
}

impl Figure {
    /// Mark the series from index `i` on as reference lines.
    pub fn with_references_from(mut self, i: usize) -> Self {
        self.references_from = Some(i);
        self
    }
}

/// A colour bar's tick text: plain numbers in [1e-2, 1e4), powers of ten outside.
fn tick(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if (1e-2..1e4).contains(&a) {
        let s = format!("{:.3}", v);
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{v:.0e}")
    }
}

/// `v` written as briefly as it is known to within `tol`: plain (`0.25`, `1200`) when its
/// size is in [1e-3, 1e5), else `2.5e-4` / `3e6`.
fn number(v: f64, tol: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return if v == 0.0 { "0".into() } else { format!("{v}") };
    }
    let a = v.abs();
    if (1e-3..1e5).contains(&a) {
        for d in 0..=15usize {
            let s = format!("{v:.d$}");
            if (s.parse::<f64>().unwrap_or(f64::NAN) - v).abs() <= tol {
                return s;
            }
        }
    }
    for p in 0..=15usize {
        let s = format!("{v:.p$e}");
        if (s.parse::<f64>().unwrap_or(f64::NAN) - v).abs() <= tol {
            return s;
        }
    }
    format!("{v:e}")
}

/// Ticks of one axis: where they go on the chart (log10 of the value on a log axis) and
/// their labels, distinct.
#[derive(Clone, Debug, PartialEq)]
pub struct Ticks {
    pub at: Vec<f64>,
    pub labels: Vec<String>,
}

/// The steps of a linear axis: 1, 2, 2.5 and 5 x 10^k.
const STEPS: [f64; 4] = [1.0, 2.0, 2.5, 5.0];

/// Round values in [a, b] a `STEPS` step apart, at most 7 of them (at least 2 when the
/// range holds two round values at all); the step.
fn round_values(a: f64, b: f64) -> (Vec<f64>, f64) {
    let (a, b) = if a <= b { (a, b) } else { (b, a) };
    let w = if b > a { b - a } else { a.abs().max(1.0) };
    let mut best: Option<(Vec<f64>, f64)> = None;
    let e0 = (w / 9.0).log10().floor() as i32;
    'search: for e in e0..=e0 + 2 {
        for m in STEPS {
            let step = m * 10f64.powi(e);
            let (i0, i1) = ((a / step).ceil() as i64, (b / step).floor() as i64);
            if i1 - i0 + 1 <= 7 {
                let v: Vec<f64> = (i0..=i1).map(|i| i as f64 * step).collect();
                best = Some((v, step));
                break 'search;
            }
        }
    }
    best.unwrap_or_else(|| (vec![a, b], w))
}

/// The ticks of a linear axis over [a, b]: round values (`round_values`), labelled with one
/// number of decimals for the axis (as many as tell them apart), or as `2.5e-4` where long.
pub fn linear_ticks(a: f64, b: f64) -> Ticks {
    let (at, step) = round_values(a, b);
    let tol = step * 1e-6;
    let at: Vec<f64> = at
        .into_iter()
        .map(|v| if v.abs() < tol { 0.0 } else { v })
        .collect();
    let big = at.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let plain = (1e-3..1e5).contains(&big);
    let labels = if plain {
        let d = (0..=15usize)
            .find(|d| {
                at.iter().all(|v| {
                    (format!("{v:.d$}").parse::<f64>().unwrap_or(f64::NAN) - v).abs() <= tol
                })
            })
            .unwrap_or(15);
        at.iter()
            .map(|v| {
                let s = format!("{v:.d$}");
                if s.trim_start_matches('-')
                    .chars()
                    .all(|c| c == '0' || c == '.')
                {
                    "0".into()
                } else {
                    s
                }
            })
            .collect()
    } else {
        at.iter().map(|&v| number(v, tol)).collect()
    };
    distinct(Ticks { at, labels })
}

/// The ticks of a logarithmic axis over log10 values [a, b]: decades (every k-th when the
/// range spans many), or 1-2-5 x 10^k, or 1..9 x 10^k, whichever first gives at least 3
/// within the range, else round values as on a linear axis; labelled `0.01`, `0.1`, `1`,
/// `10`, or `1e-4` / `2e5` outside [1e-3, 1e5).
pub fn log_ticks(a: f64, b: f64) -> Ticks {
    let (a, b) = if a <= b { (a, b) } else { (b, a) };
    let span = b - a;
    let (k0, k1) = (a.floor() as i32 - 1, b.ceil() as i32 + 1);
    let within = |mantissas: &[f64], every: i32| -> Vec<f64> {
        let mut v = Vec::new();
        for k in k0..=k1 {
            if k.rem_euclid(every) != 0 {
                continue;
            }
            for m in mantissas {
                let x = m * 10f64.powi(k);
                let l = x.log10();
                if l >= a - 1e-9 && l <= b + 1e-9 {
                    v.push(x);
                }
            }
        }
        v
    };
    let mut choice: Option<Vec<f64>> = None;
    if span > 2.5 {
        let every = ((span / 8.0).ceil() as i32).max(1);
        choice = Some(within(&[1.0], every));
    } else {
        for m in [
            &[1.0, 2.0, 5.0][..],
            &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0][..],
        ] {
            let v = within(m, 1);
            if v.len() >= 3 {
                choice = Some(v);
                break;
            }
        }
    }
    let values = match choice {
        Some(v) if v.len() >= 2 => v,
        _ => {
            let (v, step) = round_values(10f64.powf(a), 10f64.powf(b));
            let v: Vec<f64> = v.into_iter().filter(|x| *x > 0.0).collect();
            let labels = v.iter().map(|&x| number(x, step * 1e-6)).collect();
            return distinct(Ticks {
                at: v.iter().map(|x| x.log10()).collect(),
                labels,
            });
        }
    };
    let labels = values.iter().map(|&x| number(x, x * 1e-9)).collect();
    distinct(Ticks {
        at: values.iter().map(|x| x.log10()).collect(),
        labels,
    })
}

/// `t` with any tick whose label repeats an earlier one's left out (a safety net: the
/// labels above are exact to their round values, so this leaves them as they are).
fn distinct(t: Ticks) -> Ticks {
    let mut seen = std::collections::BTreeSet::new();
    let (mut at, mut labels) = (Vec::new(), Vec::new());
    for (x, l) in t.at.into_iter().zip(t.labels) {
        if seen.insert(l.clone()) {
            at.push(x);
            labels.push(l);
        }
    }
    Ticks { at, labels }
}

/// The lines of `text` broken at spaces so that each is at most `max` characters (a word
/// longer than that broken inside).
pub fn wrap(text: &str, max: usize) -> Vec<String> {
    let max = max.max(8);
    let mut lines: Vec<String> = Vec::new();
    let mut cur = String::new();
    for word in text.split(' ') {
        let mut word = word.to_string();
        loop {
            let (n, w) = (cur.chars().count(), word.chars().count());
            if n > 0 && n + 1 + w <= max {
                cur.push(' ');
                cur.push_str(&word);
                break;
            } else if n == 0 && w <= max {
                cur = word;
                break;
            } else if n > 0 {
                lines.push(std::mem::take(&mut cur));
            } else {
                let head: String = word.chars().take(max).collect();
                word = word.chars().skip(max).collect();
                lines.push(head);
            }
        }
    }
    if !cur.is_empty() || lines.is_empty() {
        lines.push(cur);
    }
    lines
}

/// An upper estimate of the width in pixels of `chars` characters of DejaVu Sans at font
/// size `px` (its widest common glyphs are about 0.6 of the size).
fn text_width(chars: usize, px: u32) -> u32 {
    (chars as f64 * px as f64 * 0.62).ceil() as u32
}

/// The colour map of every figure: 24 well-separated colours (Glasbey-like, dark enough on
/// white), so that species 1 and 10 (or any two of the first 24 series) never share a colour;
/// series beyond 24 cycle.
pub const PALETTE: [(u8, u8, u8); 24] = [
    (31, 119, 180),  // blue
    (214, 39, 40),   // red
    (44, 160, 44),   // green
    (255, 127, 14),  // orange
    (148, 103, 189), // purple
    (140, 86, 75),   // brown
    (227, 119, 194), // pink
    (23, 190, 207),  // cyan
    (188, 189, 34),  // olive
    (0, 0, 0),       // black
    (0, 0, 128),     // navy
    (128, 0, 0),     // maroon
    (0, 128, 128),   // teal
    (255, 90, 90),   // salmon
    (128, 128, 0),   // dark olive
    (240, 50, 230),  // magenta
    (70, 240, 240),  // light cyan
    (170, 60, 0),    // rust
    (145, 30, 180),  // violet
    (0, 200, 120),   // jade
    (160, 160, 160), // grey
    (0, 90, 50),     // dark green
    (255, 200, 0),   // gold
    (90, 60, 160),   // indigo
];

/// Colour `i` of the colour map (cycling past its end).
pub fn colour(i: usize) -> (u8, u8, u8) {
    PALETTE[i % PALETTE.len()]
}

fn rgb(i: usize) -> RGBColor {
    let (r, g, b) = colour(i);
    RGBColor(r, g, b)
}

/// Height of one legend row.
const LEGEND_ROW: i32 = 18;
/// Longest legend label drawn, in characters (longer ones end with `...`).
const LEGEND_CHARS: usize = 40;
/// Font sizes of the title, the tick labels, the axis names and the legend.
const TITLE_PX: u32 = 18;
const TICK_PX: u32 = 14;
const DESC_PX: u32 = 16;
const LEGEND_PX: u32 = 12;
/// Height of one title line.
const TITLE_LINE: i32 = 22;

/// The legend's labels as drawn (at most `LEGEND_CHARS` characters).
fn legend_text(label: &str) -> String {
    shorten(label, LEGEND_CHARS)
}

/// Width of the legend column: as wide as its longest label needs (none without labels),
/// at most 40 % of the figure.
fn legend_width(fig: &Figure, series: &[Vec<Drawn>], width: u32) -> u32 {
    let longest = fig
        .series
        .iter()
        .zip(series)
        .filter(|(s, d)| !d.is_empty() && !s.label.is_empty())
        .map(|(s, _)| legend_text(&s.label).chars().count())
        .max();
    match longest {
        None => 0,
        Some(n) => (32 + text_width(n, LEGEND_PX) + 10).min(width * 2 / 5),
    }
}

fn tr(v: f64, log: bool) -> Option<f64> {
    if log {
        (v > 0.0 && v.is_finite()).then(|| v.log10())
    } else {
        v.is_finite().then_some(v)
    }
}

/// Why a figure could not be drawn or written. The renderer imports nothing of the crate, so
/// its exit class is said where the command line meets it (`cli`: I/O).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlotError {
    /// The figure cannot be drawn (no data on its axes, a backend failure).
    #[error("{0}")]
    Draw(String),
    /// The directory of the figures cannot be made.
    #[error("{0}")]
    Io(String),
}

/// A chart axis: f64 values over a range, ticked and labelled as its `Ticks` say.
struct Axis {
    range: std::ops::Range<f64>,
    ticks: Ticks,
}

impl Ranged for Axis {
    type ValueType = f64;
    type FormatOption = plotters::coord::ranged1d::NoDefaultFormatting;
    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        let (a, b) = (self.range.start, self.range.end);
        let f = if b > a { (value - a) / (b - a) } else { 0.5 };
        limit.0 + (f * (limit.1 - limit.0) as f64).round() as i32
    }
    fn key_points<Hint: plotters::coord::ranged1d::KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            Vec::new()
        } else {
            self.ticks.at.clone()
        }
    }
    fn range(&self) -> std::ops::Range<f64> {
        self.range.clone()
    }
}

impl plotters::coord::ranged1d::ValueFormatter<f64> for Axis {
    fn format(v: &f64) -> String {
        number(*v, v.abs() * 1e-6)
    }
    fn format_ext(&self, v: &f64) -> String {
        self.ticks
            .at
            .iter()
            .zip(&self.ticks.labels)
            .min_by(|a, b| (a.0 - v).abs().total_cmp(&(b.0 - v).abs()))
            .map(|(_, l)| l.clone())
            .unwrap_or_else(|| Self::format(v))
    }
}

/// A point as drawn: (x, y, y_lo, y_hi) on the chart's axes (log10 of the data on a log axis).
type Drawn = (f64, f64, f64, f64);

/// Draws a figure: a heatmap, or the wrapped title on top, the series on their axes (round
/// ticks, see `linear_ticks` and `log_ticks`) and the legend in a column beside them as wide
/// as its labels need.
fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, fig: &Figure) -> Result<(), PlotError> {
    use plotters::style::text_anchor::{HPos, VPos};
    if let Some(h) = &fig.heatmap {
        return draw_heatmap(root, fig, h).map_err(|x| PlotError::Draw(x.to_string()));
    }
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| PlotError::Draw(x.to_string());
    root.fill(&WHITE).map_err(e)?;
    let series = transformed_series(fig);
    let ((x0, x1), (y0, y1)) = data_ranges(&series, fig.log_y)?;
    let (width, _) = root.dim_in_pixel();
    let title = wrap(
        &fig.title,
        ((width - 24) / text_width(1, TITLE_PX)) as usize,
    );
    let title_font = ("sans-serif", TITLE_PX).into_font().color(&BLACK);
    for (i, line) in title.iter().enumerate() {
        root.draw(&Text::new(
            line.clone(),
            (width as i32 / 2, 8 + i as i32 * TITLE_LINE),
            title_font.clone().pos(anchor(HPos::Center, VPos::Top)),
        ))
        .map_err(e)?;
    }
    let top = 12 + title.len() as u32 * TITLE_LINE as u32;
    let (_, body) = root.split_vertically(top);
    let legend_w = legend_width(fig, &series, width);
    let (plot_area, legend_area) = body.split_horizontally(width - legend_w);
    let xt = if fig.log_x {
        log_ticks(x0, x1)
    } else {
        linear_ticks(x0, x1)
    };
    let yt = if fig.log_y {
        log_ticks(y0, y1)
    } else {
        linear_ticks(y0, y1)
    };
    let widest = |t: &Ticks| {
        t.labels
            .iter()
            .map(|l| l.chars().count())
            .max()
            .unwrap_or(1)
    };
    let y_area = text_width(widest(&yt), TICK_PX) + 12 + DESC_PX + 10;
    // Room right of the plot for half the last x label.
    let right = (text_width(widest(&xt), TICK_PX) / 2 + 6).max(16);
    let mut chart = ChartBuilder::on(&plot_area)
        .margin_top(10)
        .margin_bottom(8)
        .margin_left(8)
        .margin_right(right)
        .x_label_area_size(TICK_PX + 12 + DESC_PX + 14)
        .y_label_area_size(y_area)
        .build_cartesian_2d(
            Axis {
                range: x0..x1,
                ticks: xt,
            },
            Axis {
                range: y0..y1,
                ticks: yt,
            },
        )
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc(&fig.x_label)
        .y_desc(&fig.y_label)
        .label_style(("sans-serif", TICK_PX))
        .axis_desc_style(("sans-serif", DESC_PX))
        .draw()
        .map_err(e)?;
    let legend = draw_curves(&mut chart, fig, &series).map_err(e)?;
    draw_legend(&legend_area, &legend, fig.legend_low).map_err(e)?;
    root.present().map_err(e)?;
    Ok(())
}

/// The points of each series transformed onto the chart's axes, with their error bars'
/// ends (on a log y axis the lower end at least 1e-3 of the value); points a log axis
/// cannot show are left out.
fn transformed_series(fig: &Figure) -> Vec<Vec<Drawn>> {
    let p = fig;
    fig.series
        .iter()
        .map(|s| {
            s.points
                .iter()
                .filter_map(|&(x, y, err)| {
                    let (tx, ty) = (tr(x, p.log_x)?, tr(y, p.log_y)?);
                    let lo = tr(
                        (y - err).max(if p.log_y { y * 1e-3 } else { f64::MIN }),
                        p.log_y,
                    )
                    .unwrap_or(ty);
                    let hi = tr(y + err, p.log_y).unwrap_or(ty);
                    Some((tx, ty, lo, hi))
                })
                .collect()
        })
        .collect()
}

/// The x and y ranges of the chart: the transformed points with their error bars (on a log
/// axis at most a decade beyond their point), padded by 5% on each side (a single value by
/// half of itself, at least 0.05); an error when there is nothing to draw.
fn data_ranges(series: &[Vec<Drawn>], log_y: bool) -> Result<((f64, f64), (f64, f64)), PlotError> {
    let all: Vec<&Drawn> = series.iter().flatten().collect();
    if all.is_empty() {
        return Err(PlotError::Draw("no data to plot".into()));
    }
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for q in &all {
        x0 = x0.min(q.0);
        x1 = x1.max(q.0);
        // Error bars inside the plot (on a log axis at most a decade beyond their point).
        let (lo, hi) = if log_y {
            (q.2.max(q.1 - 1.0), q.3.min(q.1 + 1.0))
        } else {
            (q.2, q.3)
        };
        y0 = y0.min(q.1).min(lo);
        y1 = y1.max(q.1).max(hi);
    }
    let pad = |a: f64, b: f64| {
        let w = if b > a {
            0.05 * (b - a)
        } else {
            0.5 * a.abs().max(0.1)
        };
        (a - w, b + w)
    };
    Ok((pad(x0, x1), pad(y0, y1)))
}

/// Draws each non-empty series on the chart, as a line or as markers with error bars, in
/// its colour (a line right after a data series, not a reference, takes that series'
/// colour); returns the legend's entries (label, colour, drawn as a line) of the labelled.
fn draw_curves<'f, DB: DrawingBackend>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<Axis, Axis>>,
    fig: &'f Figure,
    series: &[Vec<Drawn>],
) -> Result<Vec<(&'f str, RGBColor, bool)>, DrawingAreaErrorKind<DB::ErrorType>> {
    let p = fig;
    let mut colour_index = 0usize;
    let mut legend: Vec<(&str, RGBColor, bool)> = Vec::new();
    for (j, (s, data)) in fig.series.iter().zip(series).enumerate() {
        if data.is_empty() {
            continue;
        }
        // A fitted line takes the colour of the data series just before it.
        let reference = p.references_from.is_some_and(|r| j >= r);
        let follows_data = s.line && !reference && j > 0 && !fig.series[j - 1].line;
        if !follows_data && j > 0 {
            colour_index += 1;
        }
        let colour = rgb(colour_index);
        if s.line {
            chart.draw_series(LineSeries::new(
                data.iter().map(|q| (q.0, q.1)),
                colour.stroke_width(2),
            ))?;
        } else {
            chart.draw_series(
                data.iter()
                    .filter(|q| q.3 > q.2)
                    .map(|q| ErrorBar::new_vertical(q.0, q.2, q.1, q.3, colour.filled(), 4)),
            )?;
            chart.draw_series(
                data.iter()
                    .map(|q| Circle::new((q.0, q.1), 2, colour.filled())),
            )?;
        }
        if !s.label.is_empty() {
            legend.push((&s.label, colour, s.line));
        }
    }
    Ok(legend)
}

/// The diverging colour of `v` on a scale clamped at +-`limit`: white at 0, blue (33, 102,
/// 172) at -limit and below, red (178, 24, 43) at +limit and above (ColorBrewer RdBu ends).
pub fn diverging(v: f64, limit: f64) -> (u8, u8, u8) {
    let s = if limit > 0.0 && v.is_finite() {
        (v / limit).clamp(-1.0, 1.0)
    } else if v.is_nan() {
        0.0
    } else {
        v.signum()
    };
    let end = if s < 0.0 {
        (33, 102, 172)
    } else {
        (178, 24, 43)
    };
    let a = s.abs();
    let mix = |w: u8| (255.0 + (w as f64 - 255.0) * a).round() as u8;
    (mix(end.0), mix(end.1), mix(end.2))
}

/// Colour of a missing value.
const HEAT_MISSING: RGBColor = RGBColor(215, 215, 215);
/// Smallest and largest cell height, in pixels.
const HEAT_MIN_ROW: u32 = 10;
const HEAT_MAX_ROW: u32 = 40;
/// Smallest cell width, in pixels (a wider grid makes a wider figure).
const HEAT_MIN_COL: u32 = 14;
/// Longest row label drawn, in characters (longer ones end with `...`).
const HEAT_ROW_CHARS: usize = 64;
/// Values are written in the cells only for grids of at most this many cells whose cells are
/// large enough to hold them.
const HEAT_MAX_CELL_LABELS: usize = 600;
/// Pixels above the grid (title), below it (column labels and their description), and to
/// its right (colour bar, its ticks and label).
const HEAT_TOP: u32 = 50;
const HEAT_BOTTOM: u32 = 70;
const HEAT_RIGHT: u32 = 130;

/// Where a heatmap's parts go.
struct HeatLayout {
    size: (u32, u32),
    /// Left edge of the grid (after the row description and labels).
    left: u32,
    cell: (u32, u32),
}

/// An upper bound of the width of `chars` characters at the 12- and 13-pixel fonts (DejaVu
/// Sans: about 6 pixels a character).
fn text_px(chars: usize) -> u32 {
    (chars as u32) * 7
}

fn heat_layout(title: &str, h: &Heatmap) -> HeatLayout {
    let (rows, cols) = (h.rows.len().max(1) as u32, h.cols.len().max(1) as u32);
    let label = h
        .rows
        .iter()
        .map(|r| r.chars().count().min(HEAT_ROW_CHARS))
        .max()
        .unwrap_or(0);
    let left = 40 + text_px(label);
    let avail = SIZE.0.saturating_sub(left + HEAT_RIGHT);
    let cw = (avail / cols).max(HEAT_MIN_COL).min(160);
    let ch =
        (SIZE.1.saturating_sub(HEAT_TOP + HEAT_BOTTOM) / rows).clamp(HEAT_MIN_ROW, HEAT_MAX_ROW);
    // Wide enough for the title (18-pixel font).
    let title_px = (title.chars().count() as u32 * 10 + 40).min(SIZE.0);
    let width = (left + cw * cols + HEAT_RIGHT)
        .max(title_px)
        .max(SIZE.0 / 2);
    let height = (HEAT_TOP + ch * rows + HEAT_BOTTOM).max(300);
    HeatLayout {
        size: (width, height),
        left,
        cell: (cw, ch),
    }
}

fn shorten(s: &str, max: usize) -> String {
    if s.chars().count() > max {
        let t: String = s.chars().take(max.saturating_sub(3)).collect();
        format!("{t}...")
    } else {
        s.to_string()
    }
}

/// A value as written in a cell: signed, one decimal (no decimals from 100 on).
fn cell_text(v: f64) -> String {
    if v.abs() >= 99.95 {
        format!("{v:+.0}")
    } else {
        format!("{v:+.1}")
    }
}

/// The grid of a heatmap in pixels: its top-left corner, a cell's size, rows and columns.
#[derive(Clone, Copy)]
struct HeatGrid {
    x0: i32,
    y0: i32,
    cw: i32,
    ch: i32,
    nr: i32,
    nc: i32,
}

/// A text position from its horizontal and vertical anchors.
fn anchor(
    hp: plotters::style::text_anchor::HPos,
    vp: plotters::style::text_anchor::VPos,
) -> plotters::style::text_anchor::Pos {
    plotters::style::text_anchor::Pos::new(hp, vp)
}

/// Draws a heatmap: the title, the cells, the labels and the colour bar (see
/// `heat_layout` for where each goes).
fn draw_heatmap<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    fig: &Figure,
    h: &Heatmap,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    use plotters::style::text_anchor::{HPos, VPos};
    let lay = heat_layout(&fig.title, h);
    let (w, _) = lay.size;
    let g = HeatGrid {
        x0: lay.left as i32,
        y0: HEAT_TOP as i32,
        cw: lay.cell.0 as i32,
        ch: lay.cell.1 as i32,
        nr: h.rows.len() as i32,
        nc: h.cols.len() as i32,
    };
    root.fill(&WHITE)?;
    root.draw(&Text::new(
        fig.title.clone(),
        (w as i32 / 2, 12),
        ("sans-serif", 18)
            .into_font()
            .color(&BLACK)
            .pos(anchor(HPos::Center, VPos::Top)),
    ))?;
    draw_heat_cells(&root, h, g)?;
    draw_heat_labels(&root, fig, h, g)?;
    draw_heat_colour_bar(&root, h, g)?;
    root.present()?;
    Ok(())
}

/// Draws the cells of a heatmap in their diverging colours (missing values grey), and their
/// values in them when the grid is small and its cells large enough.
fn draw_heat_cells<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    h: &Heatmap,
    g: HeatGrid,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    use plotters::style::text_anchor::{HPos, VPos};
    let HeatGrid {
        x0,
        y0,
        cw,
        ch,
        nr,
        nc,
    } = g;
    let cells = (nr * nc) as usize;
    let write_values = cells <= HEAT_MAX_CELL_LABELS && cw >= 34 && ch >= 14;
    let value_font = ("sans-serif", 11).into_font();
    for (i, row) in h.values.iter().enumerate().take(nr as usize) {
        for (j, v) in row.iter().enumerate().take(nc as usize) {
            let (cx, cy) = (x0 + j as i32 * cw, y0 + i as i32 * ch);
            let colour = match v {
                Some(v) => {
                    let (r, g, b) = diverging(*v, h.limit);
                    RGBColor(r, g, b)
                }
                None => HEAT_MISSING,
            };
            root.draw(&Rectangle::new(
                [(cx, cy), (cx + cw - 1, cy + ch - 1)],
                colour.filled(),
            ))?;
            if let (true, Some(v)) = (write_values, v) {
                let dark = h.limit > 0.0 && v.abs() / h.limit > 0.6;
                root.draw(&Text::new(
                    cell_text(*v),
                    (cx + cw / 2, cy + ch / 2),
                    value_font
                        .clone()
                        .color(if dark { &WHITE } else { &BLACK })
                        .pos(anchor(HPos::Center, VPos::Center)),
                ))?;
            }
        }
    }
    Ok(())
}

/// Draws a heatmap's row labels (right-aligned against the grid, smaller in small rows), its
/// column labels below the grid (every `step`-th one when they would overlap) and the two
/// axis descriptions.
fn draw_heat_labels<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    fig: &Figure,
    h: &Heatmap,
    g: HeatGrid,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    use plotters::style::text_anchor::{HPos, VPos};
    let HeatGrid {
        x0,
        y0,
        cw,
        ch,
        nr,
        nc,
    } = g;
    let row_font = ("sans-serif", (ch - 1).clamp(8, 13) as u32).into_font();
    for (i, label) in h.rows.iter().enumerate() {
        root.draw(&Text::new(
            shorten(label, HEAT_ROW_CHARS),
            (x0 - 6, y0 + i as i32 * ch + ch / 2),
            row_font
                .clone()
                .color(&BLACK)
                .pos(anchor(HPos::Right, VPos::Center)),
        ))?;
    }
    let col_font = ("sans-serif", 12).into_font();
    let widest = h
        .cols
        .iter()
        .map(|c| text_px(c.chars().count()) as i32 + 6)
        .max()
        .unwrap_or(1);
    let step = ((widest + cw - 1) / cw).max(1) as usize;
    let y1 = y0 + nr * ch;
    for (j, label) in h.cols.iter().enumerate() {
        if j % step != 0 {
            continue;
        }
        root.draw(&Text::new(
            label.clone(),
            (x0 + j as i32 * cw + cw / 2, y1 + 6),
            col_font
                .clone()
                .color(&BLACK)
                .pos(anchor(HPos::Center, VPos::Top)),
        ))?;
    }
    let desc = ("sans-serif", 16).into_font().color(&BLACK);
    root.draw(&Text::new(
        fig.x_label.clone(),
        (x0 + nc * cw / 2, y1 + 32),
        desc.clone().pos(anchor(HPos::Center, VPos::Top)),
    ))?;
    root.draw(&Text::new(
        fig.y_label.clone(),
        (14, y0 + nr * ch / 2),
        desc.clone()
            .transform(FontTransform::Rotate270)
            .pos(anchor(HPos::Center, VPos::Center)),
    ))?;
    Ok(())
}

/// Draws a heatmap's colour bar right of the grid: the scale from +limit (top) to -limit,
/// ticks at the ends, halves and 0, and the scale's label.
fn draw_heat_colour_bar<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    h: &Heatmap,
    g: HeatGrid,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    use plotters::style::text_anchor::{HPos, VPos};
    let HeatGrid {
        x0,
        y0,
        cw,
        ch,
        nr,
        nc,
    } = g;
    let bx = x0 + nc * cw + 20;
    let bh = (nr * ch).clamp(180, 360); // room for the rotated scale label
    let steps = 48;
    for k in 0..steps {
        let v = h.limit * (1.0 - 2.0 * (k as f64 + 0.5) / steps as f64);
        let (r, g, b) = diverging(v, h.limit);
        let (ya, yb) = (y0 + k * bh / steps, y0 + (k + 1) * bh / steps);
        root.draw(&Rectangle::new(
            [(bx, ya), (bx + 16, yb)],
            RGBColor(r, g, b).filled(),
        ))?;
    }
    root.draw(&Rectangle::new([(bx, y0), (bx + 16, y0 + bh)], BLACK))?;
    let tick_font = ("sans-serif", 12).into_font().color(&BLACK);
    for (f, prefix) in [
        (1.0, ">= "),
        (0.5, ""),
        (0.0, ""),
        (-0.5, ""),
        (-1.0, "<= "),
    ] {
        let y = y0 + ((1.0 - f) / 2.0 * bh as f64).round() as i32;
        root.draw(&PathElement::new(vec![(bx + 16, y), (bx + 20, y)], BLACK))?;
        root.draw(&Text::new(
            format!("{prefix}{}", tick(f * h.limit)),
            (bx + 23, y),
            tick_font.clone().pos(anchor(HPos::Left, VPos::Center)),
        ))?;
    }
    root.draw(&Text::new(
        h.scale_label.clone(),
        (bx + 80, y0 + bh / 2),
        ("sans-serif", 13)
            .into_font()
            .color(&BLACK)
            .transform(FontTransform::Rotate270)
            .pos(anchor(HPos::Center, VPos::Center)),
    ))?;
    Ok(())
}

/// The legend in its own column beside the plot area: one row per series (a line or a
/// marker in the series' colour, then its label), from the top, or from the bottom for
/// `low` (growing curves); rows that do not fit are counted in a last "+N more" row.
fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[(&str, RGBColor, bool)],
    low: bool,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    if entries.is_empty() {
        return Ok(());
    }
    let (_, h) = area.dim_in_pixel();
    let (top, bottom) = (10, h as i32 - 50);
    let fits = ((bottom - top) / LEGEND_ROW).max(1) as usize;
    let (shown, more) = if entries.len() > fits {
        (fits - 1, entries.len() - (fits - 1))
    } else {
        (entries.len(), 0)
    };
    let rows = shown + usize::from(more > 0);
    let first = if low {
        bottom - rows as i32 * LEGEND_ROW
    } else {
        top
    };
    let font = ("sans-serif", 12).into_font().color(&BLACK);
    for (i, (label, colour, line)) in entries[..shown].iter().enumerate() {
        let y = first + i as i32 * LEGEND_ROW + LEGEND_ROW / 2;
        if *line {
            area.draw(&PathElement::new(
                vec![(6, y), (26, y)],
                colour.stroke_width(2),
            ))?;
        } else {
            area.draw(&Circle::new((16, y), 3, colour.filled()))?;
        }
        let text = legend_text(label);
        area.draw(&Text::new(text, (32, y - 7), font.clone()))?;
    }
    if more > 0 {
        let y = first + shown as i32 * LEGEND_ROW + LEGEND_ROW / 2;
        area.draw(&Text::new(format!("+{more} more"), (32, y - 7), font))?;
    }
    Ok(())
}

/// The size of every figure but a heatmap, in pixels.
const SIZE: (u32, u32) = (900, 650);

fn register_font() {
    let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
}

/// `fig` as an SVG document in memory (`<svg ...>...</svg>`, text as `<text>` elements, no
/// external references): what `render` writes to `name.svg`.
pub fn svg_string(fig: &Figure) -> Result<String, PlotError> {
    register_font();
    let mut out = String::new();
    draw(
        SVGBackend::with_string(&mut out, fig.size()).into_drawing_area(),
        fig,
    )?;
    Ok(out)
}

/// Write `name.png` and `name.svg` of every figure into `dir`. Returns the files written and
/// one message per figure that could not be drawn (e.g. no positive data on a log axis).
pub fn render(
    figs: &[(String, Figure)],
    dir: &Path,
) -> Result<(Vec<PathBuf>, Vec<String>), PlotError> {
    std::fs::create_dir_all(dir).map_err(|e| PlotError::Io(format!("{}: {e}", dir.display())))?;
    register_font();
    let (mut out, mut failed) = (Vec::new(), Vec::new());
    for (name, p) in figs {
        let png = dir.join(format!("{name}.png"));
        let svg = dir.join(format!("{name}.svg"));
        let size = p.size();
        let r = draw(BitMapBackend::new(&png, size).into_drawing_area(), p)
            .and_then(|_| draw(SVGBackend::new(&svg, size).into_drawing_area(), p));
        match r {
            Ok(()) => {
                out.push(png);
                out.push(svg);
            }
            Err(e) => failed.push(format!("figure {name}: {e}")),
        }
    }
    Ok((out, failed))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// At least 20 colours, pairwise well apart (so that T_1 and T_10 differ), none near
    /// the white background.
    #[test]
    fn colour_map_has_20_distinct_colours() {
        assert!(PALETTE.len() >= 20);
        let d = |a: (u8, u8, u8), b: (u8, u8, u8)| {
            let f = |x: u8, y: u8| (x as f64 - y as f64).powi(2);
            (f(a.0, b.0) + f(a.1, b.1) + f(a.2, b.2)).sqrt()
        };
        for i in 0..PALETTE.len() {
            assert!(d(colour(i), (255, 255, 255)) > 80.0, "colour {i} too pale");
            for j in 0..i {
                assert!(
                    d(colour(i), colour(j)) > 60.0,
                    "colours {j} and {i} too close: {:?} {:?}",
                    colour(j),
                    colour(i)
                );
            }
        }
        assert_ne!(colour(0), colour(9), "series 1 and 10 share a colour");
        assert_eq!(colour(PALETTE.len()), colour(0));
    }

    /// A figure renders to one self-contained SVG document, its legend labels escaped.
    #[test]
    fn figure_renders_to_an_svg_string() {
        let series = (0..12)
            .map(|k| Series {
                label: format!("k={k} <b>"),
                points: (1..5)
                    .map(|i| (i as f64, (i * (k + 1)) as f64, 0.1))
                    .collect(),
                line: k % 2 == 1,
            })
            .collect();
        let svg = svg_string(&loglog(Figure::new("T_k(t)".into(), "t", "T", series))).unwrap();
        assert!(svg.trim_start().starts_with("<svg"), "{}", &svg[..80]);
        assert!(svg.trim_end().ends_with("</svg>"));
        assert!(svg.contains("k=11 &lt;b&gt;"));
        assert!(!svg.contains("<b>"));
        assert!(!svg.contains("href"));
    }

    fn distinct_labels(t: &Ticks) -> bool {
        let set: std::collections::BTreeSet<_> = t.labels.iter().collect();
        set.len() == t.labels.len()
    }

    /// Linear ticks at 1, 2, 2.5, 5 x 10^k steps, 2 to 7 of them, labelled with one number
    /// of decimals that tells them apart (the issue's `2e-3, 2e-3, 1e-3` axis).
    #[test]
    fn linear_ticks_are_round_and_distinct() {
        let t = linear_ticks(0.00075, 0.00205);
        assert_eq!(
            t.labels,
            ["0.0008", "0.0010", "0.0012", "0.0014", "0.0016", "0.0018", "0.0020"]
        );
        let t = linear_ticks(0.2995, 0.3405);
        assert_eq!(t.labels, ["0.30", "0.31", "0.32", "0.33", "0.34"]);
        let t = linear_ticks(-1.0, 16.7);
        assert_eq!(t.labels, ["0", "2.5", "5.0", "7.5", "10.0", "12.5", "15.0"]);
        let t = linear_ticks(1.2e-6, 3.9e-6);
        assert_eq!(t.labels, ["1.5e-6", "2e-6", "2.5e-6", "3e-6", "3.5e-6"]);
        let t = linear_ticks(-0.3, 0.3);
        assert!(t.labels.contains(&"0".to_string()), "{t:?}");
        for (a, b) in [(0.991, 1.0047), (1e5, 3.3e5), (-7.0, -6.9999), (0.0, 1e-12)] {
            let t = linear_ticks(a, b);
            assert!(t.at.len() >= 2 && t.at.len() <= 7, "{a} {b}: {t:?}");
            assert!(distinct_labels(&t), "{a} {b}: {t:?}");
            for (x, l) in t.at.iter().zip(&t.labels) {
                let v: f64 = l.parse().unwrap();
                assert!(
                    (v - x).abs() <= (b - a).abs().max(1e-300) * 1e-5,
                    "{l} for {x}"
                );
            }
        }
    }

    /// Log ticks at 1-2-5 x 10^k (not 1.58, 2.51, 3.16), decades over wide ranges, labelled
    /// 0.01 .. 1000 plainly and 1e-4 beyond.
    #[test]
    fn log_ticks_are_one_two_five() {
        let l = |a: f64, b: f64| log_ticks(a.log10(), b.log10()).labels;
        assert_eq!(l(0.9, 5.5), ["1", "2", "5"]);
        assert_eq!(l(4.5, 22.0), ["5", "10", "20"]);
        assert_eq!(
            l(1e-3, 2e4),
            ["0.001", "0.01", "0.1", "1", "10", "100", "1000", "10000"]
        );
        assert_eq!(l(1e-5, 2e4), ["1e-4", "0.01", "1", "100", "10000"]);
        assert_eq!(
            l(1e-12, 1e12),
            ["1e-12", "1e-9", "1e-6", "0.001", "1", "1000", "1e6", "1e9", "1e12"]
        );
        // Less than a factor 2: round values as on a linear axis.
        let t = log_ticks(0.991f64.log10(), 1.0047f64.log10());
        assert!(t.at.len() >= 2 && distinct_labels(&t), "{t:?}");
        assert!(t.labels.iter().all(|x| x.len() <= 6), "{t:?}");
        for (x, lab) in t.at.iter().zip(&t.labels) {
            assert!((10f64.powf(*x) - lab.parse::<f64>().unwrap()).abs() < 1e-9);
        }
    }

    /// Titles wrap at spaces; a word longer than a line is cut.
    #[test]
    fn titles_wrap() {
        assert_eq!(wrap("a bb ccc dddd", 8), ["a bb ccc", "dddd"]);
        assert_eq!(wrap("abcdefghijk", 8), ["abcdefgh", "ijk"]);
        assert_eq!(wrap("", 8), [""]);
    }

    /// A long title is drawn on several lines, each inside the image.
    #[test]
    fn long_title_wraps_inside_the_image() {
        let title = "target-mixture [species.list.1.mass=2.0] - temperature: DSMC over the Maxwellian and the Sonine theory, and more words to need three lines of text at the least here";
        let fig = Figure::new(
            title.into(),
            "t",
            "T",
            vec![Series {
                label: "a".into(),
                points: vec![(1.0, 2.0, 0.1), (2.0, 3.0, 0.1)],
                line: false,
            }],
        );
        let svg = svg_string(&fig).unwrap();
        let lines = wrap(title, ((SIZE.0 - 24) / text_width(1, TITLE_PX)) as usize);
        assert!(lines.len() >= 2);
        for l in &lines {
            assert!(svg.contains(&format!(">\n{l}\n</text>")), "{l:?} missing");
            assert!(text_width(l.chars().count(), TITLE_PX) <= SIZE.0 - 24);
        }
    }

    fn grid(rows: usize, cols: usize) -> Figure {
        Figure::heatmap(
            "deviation".into(),
            "species",
            "point",
            Heatmap {
                rows: (0..rows).map(|i| format!("row <{i}>")).collect(),
                cols: (0..cols).map(|j| format!("c{j}")).collect(),
                values: (0..rows)
                    .map(|i| {
                        (0..cols)
                            .map(|j| (j != 1 || i != 0).then(|| (i * cols + j) as f64 - 2.2))
                            .collect()
                    })
                    .collect(),
                limit: 5.0,
                scale_label: "sigma".into(),
            },
        )
    }

    /// The diverging scale: white at 0, the end colours at and beyond +-limit, symmetric.
    #[test]
    fn diverging_scale_clamps_at_the_limit() {
        assert_eq!(diverging(0.0, 5.0), (255, 255, 255));
        assert_eq!(diverging(5.0, 5.0), (178, 24, 43));
        assert_eq!(diverging(50.0, 5.0), (178, 24, 43));
        assert_eq!(diverging(f64::INFINITY, 5.0), (178, 24, 43));
        assert_eq!(diverging(-5.0, 5.0), (33, 102, 172));
        assert_eq!(diverging(-1e9, 5.0), (33, 102, 172));
        let (half, less) = (diverging(2.5, 5.0), diverging(1.0, 5.0));
        assert!(half.1 < less.1 && less.1 < 255, "{half:?} {less:?}");
        assert_ne!(diverging(4.9, 5.0), diverging(5.0, 5.0));
    }

    /// A heatmap's SVG: one rect per cell (a 2 x 3 grid draws 5 more than a 1 x 1 one), the
    /// values written in the cells (a missing one not), labels escaped, both backends.
    #[test]
    fn heatmap_renders_cells_labels_and_colour_bar() {
        let small = svg_string(&grid(1, 1)).unwrap();
        let svg = svg_string(&grid(2, 3)).unwrap();
        assert_eq!(
            svg.matches("<rect").count(),
            small.matches("<rect").count() + 5
        );
        for v in ["-2.2", "+2.8", "+0.8"] {
            assert!(svg.contains(&format!(">\n{v}\n")), "{v} missing");
        }
        assert!(!svg.contains("-1.2"), "the missing cell has a value");
        assert!(svg.contains("row &lt;1&gt;"));
        assert!(svg.contains(">= 5") || svg.contains("&gt;= 5"));
        assert!(svg.contains("<= -5") || svg.contains("&lt;= -5"));
        // At a limit of 1, the cells 1.8 and 2.8 take the red end, -2.2 the blue one.
        let mut clamped = grid(2, 3);
        clamped.heatmap.as_mut().unwrap().limit = 1.0;
        let svg = svg_string(&clamped).unwrap().to_ascii_uppercase();
        assert_eq!(svg.matches("FILL=\"#B2182B\"").count(), 2);
        assert_eq!(svg.matches("FILL=\"#2166AC\"").count(), 1);
        let dir = tempfile::tempdir().unwrap();
        let (files, failed) = render(&[("map".into(), grid(3, 4))], dir.path()).unwrap();
        assert!(failed.is_empty(), "{failed:?}");
        assert_eq!(files.len(), 2);
    }

    /// Many rows: a tall figure (rows at least HEAT_MIN_ROW pixels), no values written in
    /// the cells, drawn in bounded time.
    #[test]
    fn large_heatmap_is_tall_and_unlabelled() {
        let fig = grid(300, 12);
        let (w, h) = fig.size();
        assert!(h >= 300 * HEAT_MIN_ROW, "{h}");
        assert!(w >= SIZE.0 / 2);
        let t = std::time::Instant::now();
        let svg = svg_string(&fig).unwrap();
        assert!(t.elapsed().as_secs_f64() < 10.0);
        assert!(svg.contains("row &lt;299&gt;"));
        assert!(
            !svg.contains("+3597"),
            "cell values written in a large grid"
        );
        assert_eq!(
            grid(2, 3).size().1,
            300.max(HEAT_TOP + 2 * HEAT_MAX_ROW + HEAT_BOTTOM)
        );
    }
}
