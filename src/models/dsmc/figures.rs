//! The standard figures of a DSMC campaign, from its summary and theory tables: per point,
//! T_k(t) and <R_k^2(t)> on log-log axes (ensemble mean with standard-error bars, theory lines
//! where a `dsmc_theory` table exists), and for polydisperse points T_k and <R_k^2>/<R_1^2>
//! against k at the last time (the paper's Figs 4 and 6), with the observable
//! `velocity_distribution` a2_k(t) and the scaled-speed density at the last histogram time
//! against the Maxwellian and its first Sonine correction; before them the campaign-wide
//! figures of [`super::overview`] (deviation maps, figures across the sweep). Figure names are
//! file names and HTML ids: made safe and unique here.

use std::collections::BTreeMap;

use super::params::DsmcParams;
use super::tables::{
    DsmcSpeciesSummaryCols, DsmcSpeedHistogramSummaryCols, DsmcTheoryCols, DSMC_SPECIES_SUMMARY,
    DSMC_SPEED_HISTOGRAM_SUMMARY, DSMC_THEORY,
};
use crate::models::CampaignView;
use crate::plot::{Figure, Series};
use crate::store::parquet_io::StoreError;

type View<'a, 'b> = &'a CampaignView<'b, DsmcParams>;

/// point -> species -> rows, each list sorted by time.
type ByPoint<T> = BTreeMap<u32, BTreeMap<u32, Vec<T>>>;

/// A summary row of a species at a time (a missing sem is 0).
#[derive(Clone, Copy, Debug, PartialEq)]
struct SummaryPoint {
    t: f64,
    temperature: f64,
    temperature_sem: f64,
    msd: Option<f64>,
    msd_sem: f64,
    /// (mean, sem) where observed.
    a2: Option<(f64, f64)>,
}

/// The summary rows per point and species.
fn read_summary(c: View) -> Result<ByPoint<SummaryPoint>, StoreError> {
    let mut out: ByPoint<SummaryPoint> = BTreeMap::new();
    for f in c.data.files(DSMC_SPECIES_SUMMARY)? {
        let name = f.display().to_string();
        for b in c.data.read_file(&f, DSMC_SPECIES_SUMMARY)? {
            // a2 is absent from a summary written before the observable existed.
            let cols = DsmcSpeciesSummaryCols::read(&b, &name)?;
            for i in 0..cols.len() {
                let r = cols.row(i);
                out.entry(r.point_id)
                    .or_default()
                    .entry(r.species)
                    .or_default()
                    .push(SummaryPoint {
                        t: r.t,
                        temperature: r.temperature_mean,
                        temperature_sem: r.temperature_sem.unwrap_or(0.0),
                        msd: r.msd_mean,
                        msd_sem: r.msd_sem.unwrap_or(0.0),
                        a2: r.a2_mean.map(|m| (m, r.a2_sem.unwrap_or(0.0))),
                    });
            }
        }
    }
    sort_by_time(&mut out, |r| r.t);
    Ok(out)
}

/// A theory row of a species at a time.
#[derive(Clone, Copy, Debug, PartialEq)]
struct TheoryPoint {
    t: f64,
    temperature: f64,
    msd: Option<f64>,
    temperature_sonine: Option<f64>,
    msd_sonine: Option<f64>,
    a2: Option<f64>,
}

/// The theory rows per point and species, if the campaign has a readable `dsmc_theory` table
/// (the Sonine columns and a2 where the table has them).
fn read_theory(c: View) -> ByPoint<TheoryPoint> {
    let mut out: ByPoint<TheoryPoint> = BTreeMap::new();
    let batches = c.data.read(DSMC_THEORY).unwrap_or_default();
    for b in batches {
        let Ok(cols) = DsmcTheoryCols::read(&b, DSMC_THEORY) else {
            continue;
        };
        for i in 0..cols.len() {
            let r = cols.row(i);
            out.entry(r.point_id)
                .or_default()
                .entry(r.species)
                .or_default()
                .push(TheoryPoint {
                    t: r.t,
                    temperature: r.temperature,
                    msd: r.msd,
                    temperature_sonine: r.temperature_sonine,
                    msd_sonine: r.msd_sonine,
                    a2: r.a2,
                });
        }
    }
    sort_by_time(&mut out, |r| r.t);
    out
}

fn sort_by_time<T>(by_point: &mut ByPoint<T>, t: impl Fn(&T) -> f64) {
    for sp in by_point.values_mut() {
        for rows in sp.values_mut() {
            rows.sort_by(|a, b| t(a).total_cmp(&t(b)));
        }
    }
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

/// The standard figures of a campaign (data only; `plot::render` draws them).
pub fn figures(c: View) -> Result<Vec<(String, Figure)>, StoreError> {
    let summary = read_summary(c)?;
    let theory = read_theory(c);
    let hist = if super::observes_vdist(&c.points.iter().map(|p| p.params).collect::<Vec<_>>()) {
        read_hist(c)?
    } else {
        Default::default()
    };
    let mut figs = super::overview::figures(c)?;
    for (&point, species) in &summary {
        let desc = c
            .points
            .iter()
            .find(|p| p.point_id == point)
            .map(|p| p.label.clone())
            .unwrap_or_default();
        let title = |what: &str| {
            if desc.is_empty() {
                format!("{} - {what}", c.name)
            } else {
                format!("{} [{desc}] - {what}", c.name)
            }
        };
        figs.extend(time_figures(point, species, theory.get(&point), &title));
        if let Some(th) = theory.get(&point) {
            figs.extend(ratio_figures(point, species, th, &title));
        }
        if species.len() > 3 {
            figs.extend(vs_k_figures(point, species, &title));
        }
        let a2 = measured_a2(species);
        if !a2.is_empty() {
            let a2_theory = theory.get(&point).map(theory_a2);
            figs.extend(a2_figure(point, &a2, a2_theory.as_ref(), &title));
            if let Some(h) = hist.get(&point) {
                figs.extend(speed_figure(point, h, &a2, a2_theory.as_ref(), &title));
            }
        }
    }
    let mut names: Vec<String> = figs.iter().map(|f| f.0.clone()).collect();
    super::overview::safe_unique_names(&mut names);
    for (f, n) in figs.iter_mut().zip(names) {
        f.0 = n;
    }
    Ok(figs)
}

/// T_k(t) and <R_k^2(t)> of the shown species, with the theory lines.
fn time_figures(
    point: u32,
    species: &BTreeMap<u32, Vec<SummaryPoint>>,
    th: Option<&BTreeMap<u32, Vec<TheoryPoint>>>,
    title: &dyn Fn(&str) -> String,
) -> Vec<(String, Figure)> {
    let all: Vec<u32> = species.keys().copied().collect();
    let shown = shown_species(&all);
    let mut temp = Vec::new();
    let mut msd = Vec::new();
    for k in &shown {
        let (t, m) = measured_time_series(*k, &species[k]);
        temp.push(t);
        msd.extend(m);
        if let Some(tr) = th.and_then(|m| m.get(k)) {
            temp.extend(theory_temperature_series(*k, tr));
            // Theory MSD lines only once some shown species has measured MSD.
            if !msd.is_empty() {
                msd.extend(theory_msd_series(*k, tr));
            }
        }
    }
    time_figure_pair(point, temp, msd, title)
}

/// The measured series of species `k` (times t > 0): T_k with its sem, and <R_k^2> with its
/// sem (positive values only) where the rows have MSD.
fn measured_time_series(k: u32, rows: &[SummaryPoint]) -> (Series, Option<Series>) {
    let temp = Series {
        label: format!("T_{k} (DSMC)"),
        points: rows
            .iter()
            .filter(|r| r.t > 0.0)
            .map(|r| (r.t, r.temperature, r.temperature_sem))
            .collect(),
        line: false,
    };
    let msd = rows.iter().any(|r| r.msd.is_some()).then(|| Series {
        label: format!("<R_{k}^2> (DSMC)"),
        points: rows
            .iter()
            .filter(|r| r.t > 0.0 && r.msd.is_some_and(|m| m > 0.0))
            .map(|r| (r.t, r.msd.unwrap_or(0.0), r.msd_sem))
            .collect(),
        line: false,
    });
    (temp, msd)
}

/// The theory lines of T_k(t) of species `k` (times t > 0): the Maxwellian one, and the
/// Sonine one (positive values) where the theory rows have it.
fn theory_temperature_series(k: u32, tr: &[TheoryPoint]) -> Vec<Series> {
    let mut out = vec![Series {
        label: format!("T_{k} (theory)"),
        points: tr
            .iter()
            .filter(|r| r.t > 0.0)
            .map(|r| (r.t, r.temperature, 0.0))
            .collect(),
        line: true,
    }];
    if tr.iter().any(|r| r.temperature_sonine.is_some()) {
        out.push(Series {
            label: format!("T_{k} (Sonine)"),
            points: tr
                .iter()
                .filter(|r| r.t > 0.0 && r.temperature_sonine.is_some_and(|x| x > 0.0))
                .map(|r| (r.t, r.temperature_sonine.unwrap_or(0.0), 0.0))
                .collect(),
            line: true,
        });
    }
    out
}

/// The theory lines of <R_k^2(t)> of species `k` (times t > 0, positive values): none where
/// the theory rows have no MSD, else the Maxwellian one and the Sonine one where they have it.
fn theory_msd_series(k: u32, tr: &[TheoryPoint]) -> Vec<Series> {
    let mut out = Vec::new();
    if !tr.iter().any(|r| r.msd.is_some()) {
        return out;
    }
    out.push(Series {
        label: format!("<R_{k}^2> (theory)"),
        points: tr
            .iter()
            .filter(|r| r.t > 0.0 && r.msd.is_some_and(|m| m > 0.0))
            .map(|r| (r.t, r.msd.unwrap_or(0.0), 0.0))
            .collect(),
        line: true,
    });
    if tr.iter().any(|r| r.msd_sonine.is_some()) {
        out.push(Series {
            label: format!("<R_{k}^2> (Sonine)"),
            points: tr
                .iter()
                .filter(|r| r.t > 0.0 && r.msd_sonine.is_some_and(|m| m > 0.0))
                .map(|r| (r.t, r.msd_sonine.unwrap_or(0.0), 0.0))
                .collect(),
            line: true,
        });
    }
    out
}

/// The log-log figures `point-<point>-temperature` of `temp` and, when there is any,
/// `point-<point>-msd` of `msd` (legend at the bottom: growing curves).
fn time_figure_pair(
    point: u32,
    temp: Vec<Series>,
    msd: Vec<Series>,
    title: &dyn Fn(&str) -> String,
) -> Vec<(String, Figure)> {
    let mut figs = vec![(
        format!("point-{point:04}-temperature"),
        Figure {
            title: title("temperatures"),
            x_label: "time t".into(),
            y_label: "temperature T_k".into(),
            series: temp,
            log_x: true,
            log_y: true,
            legend_low: false,
            references_from: None,
            heatmap: None,
        },
    )];
    if !msd.is_empty() {
        figs.push((
            format!("point-{point:04}-msd"),
            Figure {
                title: title("mean-squared displacement"),
                x_label: "time t".into(),
                y_label: "MSD <R_k^2(t)>".into(),
                series: msd,
                log_x: true,
                log_y: true,
                legend_low: true,
                references_from: None,
                heatmap: None,
            },
        ));
    }
    figs
}

/// The measurement over each theory against time, T_k and MSD_k: DSMC / Maxwellian and
/// DSMC / first Sonine with the sem as error bars and a line at 1, so the two theories'
/// errors can be told apart (on the log axes of T_k(t) they are a few % of many decades).
/// Only where the theory table has Sonine columns.
fn ratio_figures(
    point: u32,
    species: &BTreeMap<u32, Vec<SummaryPoint>>,
    th: &BTreeMap<u32, Vec<TheoryPoint>>,
    title: &dyn Fn(&str) -> String,
) -> Vec<(String, Figure)> {
    let all: Vec<u32> = species.keys().copied().collect();
    let shown = shown_species(&all);
    let mut figs = Vec::new();
    // (what, id, label, measured (value, sem), Maxwellian, Sonine)
    type Pick = fn(&SummaryPoint) -> Option<(f64, f64)>;
    type PickTh = fn(&TheoryPoint) -> Option<f64>;
    let kinds: [(&str, &str, &str, Pick, PickTh, PickTh); 2] = [
        (
            "temperature",
            "temperature-vs-theory",
            "T_{k}",
            |r| Some((r.temperature, r.temperature_sem)),
            |t| Some(t.temperature),
            |t| t.temperature_sonine,
        ),
        (
            "MSD",
            "msd-vs-theory",
            "MSD_{k}",
            |r| r.msd.map(|m| (m, r.msd_sem)),
            |t| t.msd,
            |t| t.msd_sonine,
        ),
    ];
    for (what, id, sym, pick, maxwell, sonine) in kinds {
        let mut series = Vec::new();
        let (mut t0, mut t1) = (f64::INFINITY, 0.0f64);
        for k in &shown {
            let Some(tr) = th.get(k) else { continue };
            let at = |t: f64| tr.iter().find(|r| r.t == t);
            for (name, f) in [("Maxwell", maxwell), ("Sonine", sonine)] {
                let points: Vec<(f64, f64, f64)> = species[k]
                    .iter()
                    .filter(|r| r.t > 0.0)
                    .filter_map(|r| {
                        let (v, e) = pick(r)?;
                        let x = f(at(r.t)?)?;
                        (x > 0.0).then(|| (r.t, v / x, e / x))
                    })
                    .collect();
                if name == "Sonine" && points.is_empty() {
                    return figs;
                }
                for p in &points {
                    t0 = t0.min(p.0);
                    t1 = t1.max(p.0);
                }
                series.push(Series {
                    label: format!("{} / {name}", sym.replace("{k}", &k.to_string())),
                    points,
                    line: false,
                });
            }
        }
        if series.iter().all(|s| s.points.is_empty()) {
            continue;
        }
        let n_data = series.len();
        if t0 < t1 {
            series.push(Series {
                label: "1".into(),
                points: vec![(t0, 1.0, 0.0), (t1, 1.0, 0.0)],
                line: true,
            });
        }
        let fig = Figure {
            log_x: true,
            ..Figure::new(
                title(&format!(
                    "{what}: DSMC over the Maxwellian and the Sonine theory"
                )),
                "time t",
                "DSMC / theory",
                series,
            )
        }
        .with_references_from(n_data);
        figs.push((format!("point-{point:04}-{id}"), fig));
    }
    figs
}

/// T_k and <R_k^2>/<R_1^2> against k at the last time (the paper's Figs 4 and 6).
fn vs_k_figures(
    point: u32,
    species: &BTreeMap<u32, Vec<SummaryPoint>>,
    title: &dyn Fn(&str) -> String,
) -> Vec<(String, Figure)> {
    let all: Vec<u32> = species.keys().copied().collect();
    let mut figs = Vec::new();
    let last = species
        .values()
        .filter_map(|rows| rows.last().map(|r| r.t))
        .fold(0.0, f64::max);
    let at_last = |k: &u32| species[k].iter().find(|r| r.t == last).copied();
    let tk: Vec<(f64, f64, f64)> = all
        .iter()
        .filter_map(|k| at_last(k).map(|r| (*k as f64, r.temperature, r.temperature_sem)))
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
            log_y: true,
            legend_low: true,
            references_from: None,
            heatmap: None,
        },
    ));
    if let Some(r1) = at_last(&1).and_then(|r| r.msd) {
        let ratio: Vec<(f64, f64, f64)> = all
            .iter()
            .filter_map(|k| {
                at_last(k).and_then(|r| r.msd.map(|m| (*k as f64, m / r1, r.msd_sem / r1)))
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
                log_y: true,
                legend_low: false,
                references_from: None,
                heatmap: None,
            },
        ));
    }
    figs
}

/// (t, a2 mean, a2 sem) per species where a2 is observed (none: no `velocity_distribution`).
fn measured_a2(species: &BTreeMap<u32, Vec<SummaryPoint>>) -> BTreeMap<u32, Vec<(f64, f64, f64)>> {
    species
        .iter()
        .map(|(&k, rows)| {
            let a2: Vec<(f64, f64, f64)> = rows
                .iter()
                .filter_map(|r| r.a2.map(|(m, e)| (r.t, m, e)))
                .collect();
            (k, a2)
        })
        .filter(|(_, a2)| !a2.is_empty())
        .collect()
}

/// (t, a2) per species from the theory rows that have one.
fn theory_a2(th: &BTreeMap<u32, Vec<TheoryPoint>>) -> BTreeMap<u32, Vec<(f64, f64)>> {
    th.iter()
        .map(|(&k, rows)| {
            let a2: Vec<(f64, f64)> = rows.iter().filter_map(|r| r.a2.map(|a| (r.t, a))).collect();
            (k, a2)
        })
        .filter(|(_, a2)| !a2.is_empty())
        .collect()
}

/// A histogram summary row of a species (a missing sem is 0).
#[derive(Clone, Copy, Debug, PartialEq)]
struct HistPoint {
    t: f64,
    c_lo: f64,
    c_hi: f64,
    density: f64,
    density_sem: f64,
}

/// The speed-histogram summary per point and species, sorted by time then bin.
fn read_hist(c: View) -> Result<ByPoint<HistPoint>, StoreError> {
    let mut out: ByPoint<HistPoint> = BTreeMap::new();
    for f in c.data.files(DSMC_SPEED_HISTOGRAM_SUMMARY)? {
        let name = f.display().to_string();
        for b in c.data.read_file(&f, DSMC_SPEED_HISTOGRAM_SUMMARY)? {
            let cols = DsmcSpeedHistogramSummaryCols::read(&b, &name)?;
            for i in 0..cols.len() {
                let r = cols.row(i);
                out.entry(r.point_id)
                    .or_default()
                    .entry(r.species)
                    .or_default()
                    .push(HistPoint {
                        t: r.t,
                        c_lo: r.c_lo,
                        c_hi: r.c_hi,
                        density: r.density_mean,
                        density_sem: r.density_sem.unwrap_or(0.0),
                    });
            }
        }
    }
    for sp in out.values_mut() {
        for rows in sp.values_mut() {
            rows.sort_by(|a, b| a.t.total_cmp(&b.t).then(a.c_lo.total_cmp(&b.c_lo)));
        }
    }
    Ok(out)
}

/// a2_k(t) with error bars, and the theory's a2 where `dsmc_theory` has it, else the
/// Maxwellian's 0.
fn a2_figure(
    point: u32,
    a2: &BTreeMap<u32, Vec<(f64, f64, f64)>>,
    th: Option<&BTreeMap<u32, Vec<(f64, f64)>>>,
    title: &dyn Fn(&str) -> String,
) -> Vec<(String, Figure)> {
    let all: Vec<u32> = a2.keys().copied().collect();
    let shown = shown_species(&all);
    let mut series: Vec<Series> = shown
        .iter()
        .map(|k| Series {
            label: format!("a2_{k} (DSMC)"),
            points: a2[k].iter().filter(|r| r.0 > 0.0).copied().collect(),
            line: false,
        })
        .collect();
    let n_data = series.len();
    let (t0, t1) = a2
        .values()
        .flatten()
        .filter(|r| r.0 > 0.0)
        .fold((f64::INFINITY, 0.0f64), |(a, b), r| {
            (a.min(r.0), b.max(r.0))
        });
    let mut theory = false;
    for k in &shown {
        if let Some(tr) = th.and_then(|m| m.get(k)) {
            theory = true;
            series.push(Series {
                label: format!("a2_{k} (theory)"),
                points: tr
                    .iter()
                    .filter(|r| r.0 > 0.0)
                    .map(|r| (r.0, r.1, 0.0))
                    .collect(),
                line: true,
            });
        }
    }
    if !theory && t0 < t1 {
        series.push(Series {
            label: "0 (Maxwellian)".into(),
            points: vec![(t0, 0.0, 0.0), (t1, 0.0, 0.0)],
            line: true,
        });
    }
    let fig = Figure {
        log_x: true,
        ..Figure::new(title("Sonine coefficient a2"), "time t", "a2_k", series)
    }
    .with_references_from(n_data);
    vec![(format!("point-{point:04}-a2"), fig)]
}

/// f_M(c) = 4/sqrt(pi) c^2 exp(-c^2), the Maxwellian density of the scaled speed.
pub fn maxwell_speed(c: f64) -> f64 {
    4.0 / std::f64::consts::PI.sqrt() * c * c * (-c * c).exp()
}

/// f_M(c) [1 + a2 S2(c^2)] with S2(x) = x^2/2 - 5x/2 + 15/8: the first Sonine correction.
pub fn sonine_speed(c: f64, a2: f64) -> f64 {
    let x = c * c;
    maxwell_speed(c) * (1.0 + a2 * (x * x / 2.0 - 2.5 * x + 15.0 / 8.0))
}

/// The scaled-speed density at the last histogram time (log y, so the tail shows) against
/// the Maxwellian and the first Sonine curve f_M (1 + a2 S2) with the theory's a2 (of up to 3
/// species; `dsmc_theory`'s a2 at the output time nearest to the histogram's). With one
/// species, or where the theory has no a2 (velocity-dependent restitution), the Sonine curve
/// with the measured a2 too (or instead): the shape a first Sonine correction can give.
fn speed_figure(
    point: u32,
    hist: &BTreeMap<u32, Vec<HistPoint>>,
    a2: &BTreeMap<u32, Vec<(f64, f64, f64)>>,
    th: Option<&BTreeMap<u32, Vec<(f64, f64)>>>,
    title: &dyn Fn(&str) -> String,
) -> Vec<(String, Figure)> {
    let all: Vec<u32> = hist.keys().copied().collect();
    let shown = shown_species(&all);
    let last = hist
        .values()
        .filter_map(|rows| rows.last().map(|r| r.t))
        .fold(0.0, f64::max);
    let c_max = hist.values().flatten().map(|r| r.c_hi).fold(0.0, f64::max);
    let mut series: Vec<Series> = shown
        .iter()
        .map(|k| Series {
            label: format!("species {k} (DSMC)"),
            points: hist[k]
                .iter()
                .filter(|r| r.t == last && r.density > 0.0)
                .map(|r| (0.5 * (r.c_lo + r.c_hi), r.density, r.density_sem))
                .collect(),
            line: false,
        })
        .collect();
    let n_data = series.len();
    let grid: Vec<f64> = (1..=200).map(|j| j as f64 * c_max / 200.0).collect();
    series.push(Series {
        label: "Maxwellian f_M(c)".into(),
        points: grid.iter().map(|&c| (c, maxwell_speed(c), 0.0)).collect(),
        line: true,
    });
    let curve = |label: String, a: f64| Series {
        label,
        points: grid
            .iter()
            .map(|&c| (c, sonine_speed(c, a), 0.0))
            .filter(|r| r.1 > 0.0)
            .collect(),
        line: true,
    };
    for k in shown.iter().take(3) {
        let theory = th
            .and_then(|m| m.get(k))
            .and_then(|r| {
                r.iter()
                    .min_by(|x, y| (x.0 - last).abs().total_cmp(&(y.0 - last).abs()))
            })
            .map(|r| r.1);
        if let Some(a) = theory {
            series.push(curve(format!("Sonine a2_{k}={a:.3} (theory)"), a));
        }
        if theory.is_some() && shown.len() > 1 {
            continue;
        }
        if let Some(&(_, a, _)) = a2.get(k).and_then(|r| r.iter().find(|r| r.0 == last)) {
            series.push(curve(format!("Sonine a2_{k}={a:.3} (DSMC)"), a));
        }
    }
    let fig = crate::plot::semilog_y(Figure::new(
        title(&format!(
            "scaled speed c = v / sqrt(2 T_k / m_k) at t = {last}"
        )),
        "scaled speed c",
        "density",
        series,
    ))
    .with_references_from(n_data);
    vec![(format!("point-{point:04}-speed-distribution"), fig)]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn summary_point(t: f64, tm: f64, ts: f64, msd: Option<f64>, ms: f64) -> SummaryPoint {
        SummaryPoint {
            t,
            temperature: tm,
            temperature_sem: ts,
            msd,
            msd_sem: ms,
            a2: None,
        }
    }

    fn theory_point(
        t: f64,
        temperature: f64,
        msd: Option<f64>,
        temperature_sonine: Option<f64>,
        msd_sonine: Option<f64>,
    ) -> TheoryPoint {
        TheoryPoint {
            t,
            temperature,
            msd,
            temperature_sonine,
            msd_sonine,
            a2: None,
        }
    }

    /// The ratio figures divide each measurement (and its sem) by the theory at the same
    /// time, one series per species and theory, and are absent without Sonine columns.
    #[test]
    fn ratio_figures_divide_by_each_theory() {
        let title = |w: &str| w.to_string();
        let species: BTreeMap<u32, Vec<SummaryPoint>> = BTreeMap::from([(
            1,
            vec![
                summary_point(1.0, 2.04, 0.02, Some(3.0), 0.3),
                summary_point(2.0, 1.1, 0.01, None, 0.0),
            ],
        )]);
        let th: BTreeMap<u32, Vec<TheoryPoint>> = BTreeMap::from([(
            1,
            vec![
                theory_point(1.0, 2.0, Some(2.0), Some(2.04), Some(3.0)),
                theory_point(2.0, 1.0, None, Some(1.0), None),
            ],
        )]);
        let figs = ratio_figures(0, &species, &th, &title);
        let names: Vec<&str> = figs.iter().map(|f| f.0.as_str()).collect();
        assert_eq!(
            names,
            [
                "point-0000-temperature-vs-theory",
                "point-0000-msd-vs-theory"
            ]
        );
        let t = &figs[0].1.series;
        assert_eq!(t[0].label, "T_1 / Maxwell");
        assert!((t[0].points[0].1 - 1.02).abs() < 1e-12 && (t[0].points[0].2 - 0.01).abs() < 1e-12);
        assert!((t[0].points[1].1 - 1.1).abs() < 1e-12);
        assert!((t[1].points[0].1 - 1.0).abs() < 1e-12 && (t[1].points[1].1 - 1.1).abs() < 1e-12);
        let m = &figs[1].1.series;
        let close = |a: &[(f64, f64, f64)], b: (f64, f64, f64)| {
            a.len() == 1
                && (a[0].0 - b.0).abs() < 1e-12
                && (a[0].1 - b.1).abs() < 1e-12
                && (a[0].2 - b.2).abs() < 1e-12
        };
        assert!(close(&m[0].points, (1.0, 1.5, 0.15)), "{:?}", m[0].points);
        assert!(close(&m[1].points, (1.0, 1.0, 0.1)), "{:?}", m[1].points);
        let maxwell_only: BTreeMap<u32, Vec<TheoryPoint>> =
            BTreeMap::from([(1, vec![theory_point(1.0, 2.0, Some(2.0), None, None)])]);
        assert!(ratio_figures(0, &species, &maxwell_only, &title).is_empty());
    }

    /// The Maxwellian of the scaled speed and its first Sonine correction are normalised (S2
    /// is orthogonal to the Maxwellian), and a2 = 0 gives the Maxwellian.
    #[test]
    fn speed_densities_are_normalised() {
        let dc = 1e-4;
        let int = |f: &dyn Fn(f64) -> f64| {
            (0..100_000)
                .map(|j| f((j as f64 + 0.5) * dc) * dc)
                .sum::<f64>()
        };
        assert!((int(&maxwell_speed) - 1.0).abs() < 1e-9);
        assert!((int(&|c| sonine_speed(c, 0.1)) - 1.0).abs() < 1e-9);
        assert_eq!(sonine_speed(1.3, 0.0), maxwell_speed(1.3));
    }
}
