//! The standard figures of a DSMC campaign, from its summary and theory tables: per point,
//! T_k(t) and <R_k^2(t)> on log-log axes (ensemble mean with standard-error bars, theory lines
//! where a `dsmc_theory` table exists), and for polydisperse points T_k and <R_k^2>/<R_1^2>
//! against k at the last time (the paper's Figs 4 and 6); before them the campaign-wide
//! figures of [`super::overview`] (deviation maps, figures across the sweep). Figure names are
//! file names and HTML ids: made safe and unique here.

use std::collections::BTreeMap;

use super::params::DsmcParams;
use super::tables::{DSMC_SPECIES_SUMMARY, DSMC_THEORY};
use crate::models::CampaignView;
use crate::plot::{Figure, Series};
use crate::store::cols::{get_f64, get_u32, opt};
use crate::store::parquet_io::StoreError;

type View<'a, 'b> = &'a CampaignView<'b, DsmcParams>;

/// point -> species -> rows, each list sorted by time.
type ByPoint<T> = BTreeMap<u32, BTreeMap<u32, Vec<T>>>;

/// A summary row: (t, T mean, T sem, msd mean, msd sem).
type SummaryPoint = (f64, f64, f64, Option<f64>, f64);

/// The summary rows per point and species.
fn read_summary(c: View) -> Result<ByPoint<SummaryPoint>, StoreError> {
    let mut out: ByPoint<SummaryPoint> = BTreeMap::new();
    for f in c.data.files(DSMC_SPECIES_SUMMARY)? {
        let name = f.display().to_string();
        for b in c.data.read_file(&f, DSMC_SPECIES_SUMMARY)? {
            let p = get_u32(&b, &name, "point_id")?;
            let t = get_f64(&b, &name, "t")?;
            let s = get_u32(&b, &name, "species")?;
            let tm = get_f64(&b, &name, "temperature_mean")?;
            let ts = get_f64(&b, &name, "temperature_sem")?;
            let mm = get_f64(&b, &name, "msd_mean")?;
            let ms = get_f64(&b, &name, "msd_sem")?;
            for i in 0..b.num_rows() {
                let sem = |a| opt(a, i).unwrap_or(0.0);
                out.entry(p.value(i))
                    .or_default()
                    .entry(s.value(i))
                    .or_default()
                    .push((t.value(i), tm.value(i), sem(ts), opt(mm, i), sem(ms)));
            }
        }
    }
    sort_by_time(&mut out, |r| r.0);
    Ok(out)
}

/// (t, T, msd) per point and species, if the campaign has a readable `dsmc_theory` table.
fn read_theory(c: View) -> ByPoint<(f64, f64, Option<f64>)> {
    let mut out: ByPoint<(f64, f64, Option<f64>)> = BTreeMap::new();
    let batches = c.data.read(DSMC_THEORY).unwrap_or_default();
    for b in batches {
        let cols = (|| {
            Ok::<_, StoreError>((
                get_u32(&b, DSMC_THEORY, "point_id")?,
                get_f64(&b, DSMC_THEORY, "t")?,
                get_u32(&b, DSMC_THEORY, "species")?,
                get_f64(&b, DSMC_THEORY, "temperature")?,
                get_f64(&b, DSMC_THEORY, "msd")?,
            ))
        })();
        let Ok((p, t, s, tt, m)) = cols else {
            continue;
        };
        for i in 0..b.num_rows() {
            out.entry(p.value(i))
                .or_default()
                .entry(s.value(i))
                .or_default()
                .push((t.value(i), tt.value(i), opt(m, i)));
        }
    }
    sort_by_time(&mut out, |r| r.0);
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
        if species.len() > 3 {
            figs.extend(vs_k_figures(point, species, &title));
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
    th: Option<&BTreeMap<u32, Vec<(f64, f64, Option<f64>)>>>,
    title: &dyn Fn(&str) -> String,
) -> Vec<(String, Figure)> {
    let all: Vec<u32> = species.keys().copied().collect();
    let shown = shown_species(&all);
    let mut figs = Vec::new();
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
            log_y: true,
            legend_low: false,
            references_from: None,
            heatmap: None,
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
                log_y: true,
                legend_low: true,
                references_from: None,
                heatmap: None,
            },
        ));
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
            log_y: true,
            legend_low: true,
            references_from: None,
            heatmap: None,
        },
    ));
    if let Some(r1) = at_last(&1).and_then(|r| r.3) {
        let ratio: Vec<(f64, f64, f64)> = all
            .iter()
            .filter_map(|k| at_last(k).and_then(|r| r.3.map(|m| (*k as f64, m / r1, r.4 / r1))))
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
