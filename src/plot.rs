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

/// Axis tick text: plain numbers in [1e-2, 1e4), powers of ten outside.
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

/// Width of the legend column to the right of the plot area (the legend never covers data).
const LEGEND_WIDTH: u32 = 210;
/// Height of one legend row.
const LEGEND_ROW: i32 = 18;
/// Longest legend label drawn, in characters (longer ones end with `...`).
const LEGEND_CHARS: usize = 28;

fn tr(v: f64, log: bool) -> Option<f64> {
    if log {
        (v > 0.0 && v.is_finite()).then(|| v.log10())
    } else {
        v.is_finite().then_some(v)
    }
}

/// Label of a log-axis tick at log10 value `v`: three significant digits.
fn log_tick(v: f64) -> String {
    let r = 10f64.powf(v);
    if !(1e-2..1e4).contains(&r) {
        return format!("{r:.1e}");
    }
    let decimals = (2 - v.floor() as i32).max(0) as usize;
    let s = format!("{r:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
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

/// A point as drawn: (x, y, y_lo, y_hi) on the chart's axes (log10 of the data on a log axis).
type Drawn = (f64, f64, f64, f64);

/// Draws a figure: a heatmap, or the series on their axes and the legend beside them.
fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, fig: &Figure) -> Result<(), PlotError> {
    if let Some(h) = &fig.heatmap {
        return draw_heatmap(root, fig, h).map_err(|x| PlotError::Draw(x.to_string()));
    }
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| PlotError::Draw(x.to_string());
    root.fill(&WHITE).map_err(e)?;
    let series = transformed_series(fig);
    let ((x0, x1), (y0, y1)) = data_ranges(&series, fig.log_y)?;
    let (width, _) = root.dim_in_pixel();
    let (plot_area, legend_area) = root.split_horizontally(width.saturating_sub(LEGEND_WIDTH));
    let mut chart = ChartBuilder::on(&plot_area)
        .caption(&fig.title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(e)?;
    let (lx, ly) = (fig.log_x, fig.log_y);
    // A linear tick at zero computed as a sum of steps may come out as -1e-17: it is 0.
    let (sx, sy) = ((x1 - x0).abs() * 1e-9, (y1 - y0).abs() * 1e-9);
    let snap = |v: f64, eps: f64| if v.abs() < eps { 0.0 } else { v };
    let fx = move |v: &f64| if lx { log_tick(*v) } else { tick(snap(*v, sx)) };
    let fy = move |v: &f64| if ly { log_tick(*v) } else { tick(snap(*v, sy)) };
    chart
        .configure_mesh()
        .x_desc(&fig.x_label)
        .y_desc(&fig.y_label)
        .label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 16))
        .x_labels(8)
        .y_labels(8)
        .x_label_formatter(&fx)
        .y_label_formatter(&fy)
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
    chart: &mut ChartContext<
        '_,
        DB,
        Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
    >,
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
    let (top, bottom) = (40, h as i32 - 50);
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
        let text: String = if label.chars().count() > LEGEND_CHARS {
            let t: String = label.chars().take(LEGEND_CHARS - 3).collect();
            format!("{t}...")
        } else {
            label.to_string()
        };
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
