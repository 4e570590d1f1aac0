//! Figures (PNG and SVG) from a campaign's tables: per point, T_k(t) and <R_k^2(t)> on log-log
//! axes (ensemble mean with standard-error bars, theory lines where a `dsmc_theory` table
//! exists), and for polydisperse points T_k and <R_k^2>/<R_1^2> against k at the last time
//! (the paper's Figs 4 and 6).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use arrow_array::cast::AsArray;
use arrow_array::types::{Float64Type, UInt32Type};
use arrow_array::Array;
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::campaign::Campaign;
use crate::store::parquet_io::{self, StoreError};
use crate::store::summary::table_files;
use crate::store::tables;

pub(crate) static FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

/// One curve: (x, y, error) points.
#[derive(Clone, Debug, Default)]
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64, f64)>,
    /// Drawn as a line (theory) rather than markers with error bars.
    pub line: bool,
}

/// A log-log figure.
#[derive(Clone, Debug)]
pub struct Figure {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
    pub log_x: bool,
    /// Legend in the lower right (growing curves) rather than the upper right.
    pub legend_low: bool,
}

#[derive(Default)]
struct SummaryRows {
    // point -> species -> [(t, T mean, T sem, msd mean, msd sem)]
    by_point: BTreeMap<u32, BTreeMap<u32, Vec<(f64, f64, f64, Option<f64>, f64)>>>,
}

fn read_summary(c: &Campaign) -> Result<SummaryRows, StoreError> {
    let mut out = SummaryRows::default();
    for f in table_files(c, tables::DSMC_SPECIES_SUMMARY)? {
        for b in parquet_io::read_file(&f, tables::DSMC_SPECIES_SUMMARY)? {
            let get = |n: &str| {
                b.column_by_name(n).cloned().ok_or_else(|| {
                    StoreError::Corrupt(f.display().to_string(), format!("has no column {n}"))
                })
            };
            let (p, t, s, tm, ts, mm, ms) = (
                get("point_id")?,
                get("t")?,
                get("species")?,
                get("temperature_mean")?,
                get("temperature_sem")?,
                get("msd_mean")?,
                get("msd_sem")?,
            );
            let (p, t, s) = (
                p.as_primitive::<UInt32Type>(),
                t.as_primitive::<Float64Type>(),
                s.as_primitive::<UInt32Type>(),
            );
            let (tm, ts, mm, ms) = (
                tm.as_primitive::<Float64Type>(),
                ts.as_primitive::<Float64Type>(),
                mm.as_primitive::<Float64Type>(),
                ms.as_primitive::<Float64Type>(),
            );
            for i in 0..b.num_rows() {
                let sem =
                    |a: &arrow_array::Float64Array| if a.is_null(i) { 0.0 } else { a.value(i) };
                let msd = if mm.is_null(i) {
                    None
                } else {
                    Some(mm.value(i))
                };
                out.by_point
                    .entry(p.value(i))
                    .or_default()
                    .entry(s.value(i))
                    .or_default()
                    .push((t.value(i), tm.value(i), sem(ts), msd, sem(ms)));
            }
        }
    }
    for sp in out.by_point.values_mut() {
        for rows in sp.values_mut() {
            rows.sort_by(|a, b| a.0.total_cmp(&b.0));
        }
    }
    Ok(out)
}

/// Theory rows (point -> species -> [(t, T, msd)]) if the campaign has a `dsmc_theory` table.
fn read_theory(c: &Campaign) -> BTreeMap<u32, BTreeMap<u32, Vec<(f64, f64, Option<f64>)>>> {
    let mut out: BTreeMap<u32, BTreeMap<u32, Vec<(f64, f64, Option<f64>)>>> = BTreeMap::new();
    let Ok(files) = table_files(c, "dsmc_theory") else {
        return out;
    };
    for f in files {
        let Ok(batches) = parquet_io::read_file(&f, "dsmc_theory") else {
            continue;
        };
        for b in batches {
            let (Some(p), Some(t), Some(s), Some(tt), Some(m)) = (
                b.column_by_name("point_id"),
                b.column_by_name("t"),
                b.column_by_name("species"),
                b.column_by_name("temperature"),
                b.column_by_name("msd"),
            ) else {
                continue;
            };
            let (p, t, s, tt, m) = (
                p.as_primitive::<UInt32Type>(),
                t.as_primitive::<Float64Type>(),
                s.as_primitive::<UInt32Type>(),
                tt.as_primitive::<Float64Type>(),
                m.as_primitive::<Float64Type>(),
            );
            for i in 0..b.num_rows() {
                let msd = if m.is_null(i) { None } else { Some(m.value(i)) };
                out.entry(p.value(i))
                    .or_default()
                    .entry(s.value(i))
                    .or_default()
                    .push((t.value(i), tt.value(i), msd));
            }
        }
    }
    for sp in out.values_mut() {
        for rows in sp.values_mut() {
            rows.sort_by(|a, b| a.0.total_cmp(&b.0));
        }
    }
    out
}

/// Species shown in time plots: all of up to 6, else a log-spaced selection.
fn shown_species(all: &[u32]) -> Vec<u32> {
    if all.len() <= 6 {
        return all.to_vec();
    }
    let mut pick: Vec<u32> = [1u32, 2, 3, 5, 10, 20, 50, 100, 200, 500]
        .iter()
        .copied()
        .filter(|k| all.contains(k))
        .collect();
    pick.truncate(6);
    pick
}

/// Build the standard figures of a campaign (data only; see [`render`]).
pub fn figures(c: &Campaign) -> Result<Vec<(String, Figure)>, StoreError> {
    let summary = read_summary(c)?;
    let theory = read_theory(c);
    let mut figs = Vec::new();
    for (&point, species) in &summary.by_point {
        let desc = c
            .plan
            .sweep_keys
            .iter()
            .zip(&c.plan.point(point).values)
            .map(|(k, v)| format!("{k}={v}"))
            .collect::<Vec<_>>()
            .join(", ");
        let title = |what: &str| {
            if desc.is_empty() {
                format!("{} - {what}", c.manifest.name)
            } else {
                format!("{} [{desc}] - {what}", c.manifest.name)
            }
        };
        let all: Vec<u32> = species.keys().copied().collect();
        let shown = shown_species(&all);
        let th = theory.get(&point);
        let mut temp = Vec::new();
        let mut msd = Vec::new();
        for k in &shown {
            let rows = &species[k];
            temp.push(Series {
                label: format!("T_{k} (DSMC)"),
                points: rows
                    .iter()
                    .filter(|r| r.0 > 0.0)
                    .map(|r| (r.0, r.1, r.2))
                    .collect(),
                line: false,
            });
            if rows.iter().any(|r| r.3.is_some()) {
                msd.push(Series {
                    label: format!("<R_{k}^2> (DSMC)"),
                    points: rows
                        .iter()
                        .filter(|r| r.0 > 0.0 && r.3.is_some_and(|m| m > 0.0))
                        .map(|r| (r.0, r.3.unwrap_or(0.0), r.4))
                        .collect(),
                    line: false,
                });
            }
            if let Some(tr) = th.and_then(|m| m.get(k)) {
                temp.push(Series {
                    label: format!("T_{k} (theory)"),
                    points: tr
                        .iter()
                        .filter(|r| r.0 > 0.0)
                        .map(|r| (r.0, r.1, 0.0))
                        .collect(),
                    line: true,
                });
                if tr.iter().any(|r| r.2.is_some()) && !msd.is_empty() {
                    msd.push(Series {
                        label: format!("<R_{k}^2> (theory)"),
                        points: tr
                            .iter()
                            .filter(|r| r.0 > 0.0 && r.2.is_some_and(|m| m > 0.0))
                            .map(|r| (r.0, r.2.unwrap_or(0.0), 0.0))
                            .collect(),
                        line: true,
                    });
                }
            }
        }
        figs.push((
            format!("point-{point:04}-temperature"),
            Figure {
                title: title("temperatures"),
                x_label: "time t".into(),
                y_label: "temperature T_k".into(),
                series: temp,
                log_x: true,
                legend_low: false,
            },
        ));
        if !msd.is_empty() {
            figs.push((
                format!("point-{point:04}-msd"),
                Figure {
                    title: title("mean-squared displacement"),
                    x_label: "time t".into(),
                    y_label: "MSD <R_k^2(t)>".into(),
                    series: msd,
                    log_x: true,
                    legend_low: true,
                },
            ));
        }
        if all.len() > 3 {
            let last = species
                .values()
                .filter_map(|rows| rows.last().map(|r| r.0))
                .fold(0.0, f64::max);
            let at_last = |k: &u32| species[k].iter().find(|r| r.0 == last).copied();
            let tk: Vec<(f64, f64, f64)> = all
                .iter()
                .filter_map(|k| at_last(k).map(|r| (*k as f64, r.1, r.2)))
                .collect();
            figs.push((
                format!("point-{point:04}-temperature-vs-k"),
                Figure {
                    title: title(&format!("T_k at t = {last}")),
                    x_label: "species k = m_k/m_1".into(),
                    y_label: "temperature T_k".into(),
                    series: vec![Series {
                        label: "DSMC".into(),
                        points: tk,
                        line: false,
                    }],
                    log_x: true,
                    legend_low: true,
                },
            ));
            if let Some(r1) = at_last(&1).and_then(|r| r.3) {
                let ratio: Vec<(f64, f64, f64)> = all
                    .iter()
                    .filter_map(|k| {
                        at_last(k).and_then(|r| r.3.map(|m| (*k as f64, m / r1, r.4 / r1)))
                    })
                    .collect();
                figs.push((
                    format!("point-{point:04}-msd-ratio-vs-k"),
                    Figure {
                        title: title(&format!("MSD ratios at t = {last}")),
                        x_label: "species k = m_k/m_1".into(),
                        y_label: "<R_k^2> / <R_1^2>".into(),
                        series: vec![Series {
                            label: "DSMC".into(),
                            points: ratio,
                            line: false,
                        }],
                        log_x: true,
                        legend_low: false,
                    },
                ));
            }
        }
    }
    Ok(figs)
}

/// Axis tick text: plain numbers in [1e-2, 1e4), powers of ten outside.
pub(crate) fn tick(v: f64) -> String {
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

pub(crate) const COLORS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(23, 190, 207),
    RGBColor(140, 86, 75),
    RGBColor(127, 127, 127),
];

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, fig: &Figure) -> Result<(), String> {
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| x.to_string();
    root.fill(&WHITE).map_err(e)?;
    let pts: Vec<(f64, f64)> = fig
        .series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| (p.0, p.1)))
        .filter(|p| p.0 > 0.0 && p.1 > 0.0 && p.0.is_finite() && p.1.is_finite())
        .collect();
    if pts.is_empty() {
        return Err("no positive data to plot".into());
    }
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for (x, y) in &pts {
        x0 = x0.min(*x);
        x1 = x1.max(*x);
        y0 = y0.min(*y);
        y1 = y1.max(*y);
    }
    let (x0, x1) = if x1 > x0 {
        (x0 / 1.3, x1 * 1.3)
    } else {
        (x0 / 2.0, x0 * 2.0)
    };
    let (y0, y1) = if y1 > y0 {
        (y0 / 1.5, y1 * 1.5)
    } else {
        (y0 / 2.0, y0 * 2.0)
    };
    let mut chart = ChartBuilder::on(&root)
        .caption(&fig.title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc(&fig.x_label)
        .y_desc(&fig.y_label)
        .label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 16))
        .x_labels(8)
        .y_labels(8)
        .x_label_formatter(&|v| tick(*v))
        .y_label_formatter(&|v| tick(*v))
        .draw()
        .map_err(e)?;
    for (j, s) in fig.series.iter().enumerate() {
        // A theory line takes the colour of the DSMC series just before it.
        let colour = COLORS[(if s.line && j > 0 { j - 1 } else { j }) % COLORS.len()];
        let data: Vec<(f64, f64, f64)> = s
            .points
            .iter()
            .copied()
            .filter(|p| p.0 > 0.0 && p.1 > 0.0)
            .collect();
        if s.line {
            chart
                .draw_series(LineSeries::new(
                    data.iter().map(|p| (p.0, p.1)),
                    colour.stroke_width(2),
                ))
                .map_err(e)?
                .label(&s.label)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
                });
        } else {
            chart
                .draw_series(data.iter().map(|p| {
                    let lo = (p.1 - p.2).max(p.1 * 1e-3);
                    ErrorBar::new_vertical(p.0, lo, p.1, p.1 + p.2, colour.filled(), 6)
                }))
                .map_err(e)?;
            chart
                .draw_series(
                    data.iter()
                        .map(|p| Circle::new((p.0, p.1), 3, colour.filled())),
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
        .label_font(("sans-serif", 13))
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

/// Write `name.png` and `name.svg` for every figure into `dir`; returns the files written.
pub fn render(figs: &[(String, Figure)], dir: &Path) -> Result<Vec<PathBuf>, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    let mut out = Vec::new();
    for (name, fig) in figs {
        let png = dir.join(format!("{name}.png"));
        draw(
            BitMapBackend::new(&png, (900, 650)).into_drawing_area(),
            fig,
        )
        .map_err(|e| format!("{}: {e}", png.display()))?;
        let svg = dir.join(format!("{name}.svg"));
        draw(SVGBackend::new(&svg, (900, 650)).into_drawing_area(), fig)
            .map_err(|e| format!("{}: {e}", svg.display()))?;
        out.push(png);
        out.push(svg);
    }
    Ok(out)
}
