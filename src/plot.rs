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
    /// Legend in the lower right (growing curves) rather than the upper right.
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

const COLORS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(23, 190, 207),
    RGBColor(140, 86, 75),
    RGBColor(127, 127, 127),
];

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
    let mut chart = ChartBuilder::on(&root)
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
        let colour = COLORS[colour_index % COLORS.len()];
        if s.line {
            chart
                .draw_series(LineSeries::new(
                    data.iter().map(|q| (q.0, q.1)),
                    colour.stroke_width(2),
                ))
                .map_err(e)?
                .label(&s.label)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
                });
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
                .map_err(e)?
                .label(&s.label)
                .legend(move |(x, y)| Circle::new((x + 9, y), 3, colour.filled()));
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 12))
        .position(if fig.legend_low {
            SeriesLabelPosition::LowerRight
        } else {
            SeriesLabelPosition::UpperRight
        })
        .draw()
        .map_err(e)?;
    root.present().map_err(e)?;
    Ok(())
}

/// Write `name.png` and `name.svg` of every figure into `dir`. Returns the files written and
/// one message per figure that could not be drawn (e.g. no positive data on a log axis).
pub fn render(
    figs: &[(String, Figure)],
    dir: &Path,
) -> Result<(Vec<PathBuf>, Vec<String>), String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    let (mut out, mut failed) = (Vec::new(), Vec::new());
    for (name, p) in figs {
        let png = dir.join(format!("{name}.png"));
        let svg = dir.join(format!("{name}.svg"));
        let r = draw(BitMapBackend::new(&png, (900, 650)).into_drawing_area(), p)
            .and_then(|_| draw(SVGBackend::new(&svg, (900, 650)).into_drawing_area(), p));
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
