//! The one figure renderer (PNG and SVG, plotters, the embedded DejaVu Sans font): figures of
//! series of (x, y, error) points, drawn as markers with error bars or as lines, on any
//! combination of linear and logarithmic axes (a log axis is drawn as log10 of the data on a
//! linear chart, its ticks labelled with the original values). What a figure shows is the
//! business of its model (`models::<model>::figures`) or of the analysis.

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

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, fig: &Figure) -> Result<(), String> {
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| x.to_string();
    let p = fig;
    root.fill(&WHITE).map_err(e)?;
    // Transformed (x, y, y_lo, y_hi) per series.
    let series: Vec<Vec<(f64, f64, f64, f64)>> = fig
        .series
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
        .collect();
    let all: Vec<&(f64, f64, f64, f64)> = series.iter().flatten().collect();
    if all.is_empty() {
        return Err("no data to plot".into());
    }
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for q in &all {
        x0 = x0.min(q.0);
        x1 = x1.max(q.0);
        y0 = y0.min(q.1);
        y1 = y1.max(q.1);
    }
    let pad = |a: f64, b: f64| {
        let w = if b > a {
            0.05 * (b - a)
        } else {
            0.5 * a.abs().max(0.1)
        };
        (a - w, b + w)
    };
    let ((x0, x1), (y0, y1)) = (pad(x0, x1), pad(y0, y1));
    let (width, _) = root.dim_in_pixel();
    let (plot_area, legend_area) = root.split_horizontally(width.saturating_sub(LEGEND_WIDTH));
    let mut chart = ChartBuilder::on(&plot_area)
        .caption(&fig.title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(e)?;
    let (lx, ly) = (p.log_x, p.log_y);
    let fx = move |v: &f64| if lx { log_tick(*v) } else { tick(*v) };
    let fy = move |v: &f64| if ly { log_tick(*v) } else { tick(*v) };
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
    let mut colour_index = 0usize;
    // (label, colour, drawn as a line) of each series drawn, for the legend.
    let mut legend: Vec<(&str, RGBColor, bool)> = Vec::new();
    for (j, (s, data)) in fig.series.iter().zip(&series).enumerate() {
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
            chart
                .draw_series(LineSeries::new(
                    data.iter().map(|q| (q.0, q.1)),
                    colour.stroke_width(2),
                ))
                .map_err(e)?;
        } else {
            chart
                .draw_series(
                    data.iter()
                        .filter(|q| q.3 > q.2)
                        .map(|q| ErrorBar::new_vertical(q.0, q.2, q.1, q.3, colour.filled(), 4)),
                )
                .map_err(e)?;
            chart
                .draw_series(
                    data.iter()
                        .map(|q| Circle::new((q.0, q.1), 2, colour.filled())),
                )
                .map_err(e)?;
        }
        if !s.label.is_empty() {
            legend.push((&s.label, colour, s.line));
        }
    }
    draw_legend(&legend_area, &legend, fig.legend_low).map_err(e)?;
    root.present().map_err(e)?;
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

/// The size of every figure, in pixels.
const SIZE: (u32, u32) = (900, 650);

fn register_font() {
    let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
}

/// `fig` as an SVG document in memory (`<svg ...>...</svg>`, text as `<text>` elements, no
/// external references): what `render` writes to `name.svg`.
pub fn svg_string(fig: &Figure) -> Result<String, String> {
    register_font();
    let mut out = String::new();
    draw(
        SVGBackend::with_string(&mut out, SIZE).into_drawing_area(),
        fig,
    )?;
    Ok(out)
}

/// Write `name.png` and `name.svg` of every figure into `dir`. Returns the files written and
/// one message per figure that could not be drawn (e.g. no positive data on a log axis).
pub fn render(
    figs: &[(String, Figure)],
    dir: &Path,
) -> Result<(Vec<PathBuf>, Vec<String>), String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    register_font();
    let (mut out, mut failed) = (Vec::new(), Vec::new());
    for (name, p) in figs {
        let png = dir.join(format!("{name}.png"));
        let svg = dir.join(format!("{name}.svg"));
        let r = draw(BitMapBackend::new(&png, SIZE).into_drawing_area(), p)
            .and_then(|_| draw(SVGBackend::new(&svg, SIZE).into_drawing_area(), p));
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
}
