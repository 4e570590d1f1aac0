//! The standard figures of an RFM campaign, from its replica summaries (only the observables
//! the campaign has): the points overlaid, at most [`crate::models::OVERLAY_MAX`] per figure
//! (more are split over several figures):
//!
//! - `temperature`: T(t) (2.19), replica mean and standard error (at most 300 times shown);
//! - `velocity-moments`: <|v_c|^m> / (G_m <v_c^2>^(m/2)) against m, the moments over those of a
//!   Gaussian with the same variance (G_m = 2^(m/2) Gamma((m+1)/2)/sqrt(pi); reference line 1);
//! - `velocity-distribution` (log y): P(v) of the velocity components, with the Gaussian of
//!   variance <T>/d (the time-averaged measured temperature) as a line in each point's colour;
//!   `post-collision-velocity-distribution`, `free-path-distribution` (log-log) and the 1D
//!   `neighbour-distance-distribution` G_1(R) (log-log) likewise, without a line. The
//!   histogram summaries pool the replicas' counts, so their error bars are the thesis's
//!   counting errors sqrt(X_j)/(N_s dv) (A.4)-(A.6), not a replica spread;
//! - `structure-factor`: S(k) (log-log; beyond `models::MAX_LOG_ROWS` shells averaged in 50
//!   bins per decade of k for display), reference S = 1 (uncorrelated positions, and the
//!   large-k limit);
//! - `radial-distribution`: g(R), reference g = 1 (uniform gas).
//!
//! The fits of `granular analyze` are not drawn here but by [`super::analysis`], into
//! `DIR/analysis`, which the report embeds as files.

use std::collections::BTreeMap;

use arrow_array::RecordBatch;

use super::params::RfmParams;
use super::tables::*;
use crate::models::{log_binned, overlay_figures, CampaignView, Overlay, PointCurve, Rows};
use crate::plot::{Figure, Series};
use crate::store::parquet_io::StoreError;

type View<'a, 'b> = &'a CampaignView<'b, RfmParams>;

/// (x, y, error) rows per point, sorted by x.
pub(crate) type PerPoint = BTreeMap<u32, Vec<(f64, f64, f64)>>;

/// Display bins per decade of k of a point with more than `models::MAX_LOG_ROWS` shells.
const SHELLS_PER_DECADE: f64 = 50.0;

/// Most times of a temperature series shown (evenly thinned beyond).
const MAX_TIMES: usize = 300;

fn sorted(mut m: PerPoint) -> PerPoint {
    for v in m.values_mut() {
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    m
}

/// `rfm_timeseries_summary`: (t, temperature mean, sem) per point.
pub(crate) fn timeseries(batches: &[RecordBatch]) -> Result<PerPoint, StoreError> {
    let t = RFM_TIMESERIES_SUMMARY;
    let mut out = PerPoint::new();
    for b in batches {
        for r in RfmTimeseriesSummary::read_rows(b, t)? {
            out.entry(r.point_id).or_default().push((
                r.t,
                r.temperature_mean,
                r.temperature_sem.unwrap_or(0.0),
            ));
        }
    }
    Ok(sorted(out))
}

/// At most `max` rows of `v`, evenly spaced, the first and last kept.
pub(crate) fn thin<T: Copy>(v: &[T], max: usize) -> Vec<T> {
    if v.len() <= max || max < 2 {
        return v.to_vec();
    }
    (0..max).map(|i| v[i * (v.len() - 1) / (max - 1)]).collect()
}

/// `rfm_moments_summary`: (order, mean, sem) per point.
pub(crate) fn moments(batches: &[RecordBatch]) -> Result<PerPoint, StoreError> {
    let t = RFM_MOMENTS_SUMMARY;
    let mut out = PerPoint::new();
    for b in batches {
        for r in RfmMomentsSummary::read_rows(b, t)? {
            out.entry(r.point_id)
                .or_default()
                .push((r.order as f64, r.mean, r.sem.unwrap_or(0.0)));
        }
    }
    Ok(sorted(out))
}

/// E|z|^m / sigma^m of a Gaussian: 2^(m/2) Gamma((m+1)/2) / sqrt(pi).
pub(crate) fn gaussian_abs_moment(m: u32) -> f64 {
    // Gamma((m+1)/2) by the recurrence from Gamma(1/2) = sqrt(pi) or Gamma(1) = 1.
    let mut g = if m.is_multiple_of(2) {
        std::f64::consts::PI.sqrt()
    } else {
        1.0
    };
    let mut a = if m.is_multiple_of(2) { 0.5 } else { 1.0 };
    while a + 1e-9 < (m as f64 + 1.0) / 2.0 {
        g *= a;
        a += 1.0;
    }
    2f64.powf(m as f64 / 2.0) * g / std::f64::consts::PI.sqrt()
}

/// The moments over the Gaussian's of the same <v^2>: (m, ratio, error), the error
/// propagated from both moments' errors as if independent (an upper bound: they correlate).
pub(crate) fn moment_ratios(rows: &[(f64, f64, f64)]) -> Vec<(f64, f64, f64)> {
    let Some(&(_, v2, e2)) = rows.iter().find(|r| r.0 == 2.0) else {
        return Vec::new();
    };
    if v2 <= 0.0 {
        return Vec::new();
    }
    rows.iter()
        .filter(|r| r.1 > 0.0)
        .map(|&(m, mean, err)| {
            let ratio = mean / (gaussian_abs_moment(m as u32) * v2.powf(m / 2.0));
            let rel = if m == 2.0 {
                err / mean
            } else {
                ((err / mean).powi(2) + (m / 2.0 * e2 / v2).powi(2)).sqrt()
            };
            (m, ratio, ratio * rel)
        })
        .collect()
}

/// (point, kind, h) -> (x, density, counting error) of `rfm_histograms_summary`; `log_bins`:
/// x is the geometric centre of a bin, else the middle. The rows outside the range (infinite
/// edges, no density) and empty bins are left out.
pub(crate) type Histograms = BTreeMap<(u32, String, u32), Vec<(f64, f64, f64)>>;

pub(crate) fn histograms(batches: &[RecordBatch]) -> Result<Histograms, StoreError> {
    let t = RFM_HISTOGRAMS_SUMMARY;
    let mut out = Histograms::new();
    for b in batches {
        let cols = RfmHistogramsSummaryCols::read(b, t)?;
        let kind = cols.kind;
        for i in 0..cols.len() {
            let (a, z, count) = (cols.lo.value(i), cols.hi.value(i), cols.count.value(i));
            let Some(dens) = cols.row(i).density else {
                continue;
            };
            if !(a.is_finite() && z.is_finite()) || count == 0 || dens <= 0.0 {
                continue;
            }
            let log_bins = matches!(kind.value(i), "free_path" | "neighbour_distance");
            let x = if log_bins && a > 0.0 {
                (a * z).sqrt()
            } else {
                0.5 * (a + z)
            };
            out.entry((
                cols.point_id.value(i),
                kind.value(i).to_string(),
                cols.h.value(i),
            ))
            .or_default()
            .push((x, dens, dens / (count as f64).sqrt()));
        }
    }
    for v in out.values_mut() {
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    Ok(out)
}

/// The Gaussian density of variance `var` at the x of `rows`, down to a tenth of the
/// smallest density shown (so that its far tail does not stretch the log axis).
pub(crate) fn gaussian_line(rows: &[(f64, f64, f64)], var: f64) -> Vec<(f64, f64, f64)> {
    if var <= 0.0 || !var.is_finite() {
        return Vec::new();
    }
    let floor = rows.iter().map(|r| r.1).fold(f64::INFINITY, f64::min) / 10.0;
    let norm = (2.0 * std::f64::consts::PI * var).sqrt();
    rows.iter()
        .map(|r| (r.0, (-r.0 * r.0 / (2.0 * var)).exp() / norm, 0.0))
        .filter(|p| p.1 >= floor)
        .collect()
}

/// `rfm_structure_factor_summary`: (k, S mean, sem) per point.
pub(crate) fn structure_factor(batches: &[RecordBatch]) -> Result<PerPoint, StoreError> {
    let t = RFM_STRUCTURE_FACTOR_SUMMARY;
    let mut out = PerPoint::new();
    for b in batches {
        for r in RfmStructureFactorSummary::read_rows(b, t)? {
            out.entry(r.point_id)
                .or_default()
                .push((r.k, r.s_mean, r.s_sem.unwrap_or(0.0)));
        }
    }
    Ok(sorted(out))
}

/// `rfm_radial_distribution_summary`: (bin middle R, g mean, sem) per point.
pub(crate) fn radial(batches: &[RecordBatch]) -> Result<PerPoint, StoreError> {
    let t = RFM_RADIAL_SUMMARY;
    let mut out = PerPoint::new();
    for b in batches {
        for r in RfmRadialSummary::read_rows(b, t)? {
            out.entry(r.point_id).or_default().push((
                0.5 * (r.r_lo + r.r_hi),
                r.g_mean,
                r.g_sem.unwrap_or(0.0),
            ));
        }
    }
    Ok(sorted(out))
}

/// A horizontal reference line at `y` over [x0, x1].
fn level(label: &str, y: f64, x0: f64, x1: f64) -> Vec<Series> {
    if x0.is_nan() || x1.is_nan() || x0 > x1 {
        return Vec::new();
    }
    vec![Series {
        label: label.into(),
        points: vec![(x0, y, 0.0), (x1, y, 0.0)],
        line: true,
    }]
}

fn curves(c: View, data: &PerPoint, line: &LineOf) -> Vec<PointCurve> {
    data.iter()
        .map(|(&p, rows)| PointCurve {
            point: p,
            label: c.point_label(p),
            data: rows.clone(),
            line: line(p, rows).filter(|l| !l.1.is_empty()),
        })
        .collect()
}

/// A point's line (label, rows) from its data.
type LineOf<'a> = dyn Fn(u32, &[(f64, f64, f64)]) -> Option<(String, Rows)> + 'a;

const NO_LINE: &LineOf<'static> = &|_, _| None;
const NO_REFS: &dyn Fn(f64, f64) -> Vec<Series> = &|_, _| Vec::new();

/// The figures of a campaign's points, as `Vec<(id, figure)>`.
type Figs = Vec<(String, Figure)>;

/// An overlay's description with a legend at the top.
fn overlay<'a>(
    id: &'a str,
    what: &'a str,
    x_label: &'a str,
    y_label: &'a str,
    (log_x, log_y): (bool, bool),
) -> Overlay<'a> {
    Overlay {
        id,
        what,
        x_label,
        y_label,
        log_x,
        log_y,
        legend_low: false,
    }
}

/// The standard figures of a campaign (data only; `plot` draws them).
/// The physics name of an rfm sweep key on the figures (legends `name=value`): `N`, `φ`
/// (packing fraction), `L`, `L'` (reduced length), `r` (radius), `m`, `k` (spring constant), `D` (noise strength),
/// `ε_n`, `ε_t`, `μ`, `Δt`, `d`; other keys as they are (`None`).
pub fn physics_name(key: &str) -> Option<String> {
    let name = match key.replace('.', "_").as_str() {
        "n_particles" => "N",
        "packing_fraction" => "φ",
        "box_length" => "L",
        "reduced_length" => "L'",
        "radius" => "r",
        "mass" => "m",
        "spring_constant" => "k",
        "noise_strength" => "D",
        "restitution_normal" => "ε_n",
        "restitution_tangential" => "ε_t",
        "mu" => "μ",
        "dt" => "Δt",
        "dim" => "d",
        "warmup" => "t_warmup",
        "duration" => "t_run",
        _ => return None,
    };
    Some(name.to_string())
}

pub fn figures(c: View) -> Result<Vec<(String, Figure)>, StoreError> {
    let mut figs = Vec::new();
    let ts = timeseries(&c.data.read(RFM_TIMESERIES_SUMMARY)?)?;
    // <T> per point: the mean of the series (what the Gaussian references use).
    let mean_t: BTreeMap<u32, f64> = ts
        .iter()
        .filter(|(_, v)| !v.is_empty())
        .map(|(&p, v)| (p, v.iter().map(|r| r.1).sum::<f64>() / v.len() as f64))
        .collect();
    figs.extend(temperature_figures(c, &ts));
    figs.extend(moment_figures(c)?);
    figs.extend(histogram_figures(c, &mean_t)?);
    figs.extend(structure_figures(c)?);
    Ok(figs)
}

/// `temperature`: T(t) of each point, at most `MAX_TIMES` times shown.
fn temperature_figures(c: View, ts: &PerPoint) -> Figs {
    let shown: PerPoint = ts.iter().map(|(&p, v)| (p, thin(v, MAX_TIMES))).collect();
    overlay_figures(
        c.name,
        &overlay(
            "temperature",
            "granular temperature T(t)",
            "time t (s)",
            "T (m^2/s^2)",
            (false, false),
        ),
        curves(c, &shown, NO_LINE),
        NO_REFS,
    )
}

/// `velocity-moments`: the moments over the Gaussian's against m, reference line 1.
fn moment_figures(c: View) -> Result<Figs, StoreError> {
    let mo = moments(&c.data.read(RFM_MOMENTS_SUMMARY)?)?;
    let ratios: PerPoint = mo.iter().map(|(&p, v)| (p, moment_ratios(v))).collect();
    Ok(overlay_figures(
        c.name,
        &overlay(
            "velocity-moments",
            "velocity moments over the Gaussian's",
            "order m",
            "<|v|^m> / (G_m <v^2>^(m/2))",
            (false, true),
        ),
        curves(c, &ratios, NO_LINE),
        &|x0, x1| level("Gaussian", 1.0, x0, x1),
    ))
}

/// The figures of the histogram summary: P(v) with the Gaussian of variance <T>/d (`mean_t`:
/// <T> per point), P(v_0), P_l(l) and G_1(R).
fn histogram_figures(c: View, mean_t: &BTreeMap<u32, f64>) -> Result<Figs, StoreError> {
    let name = c.name;
    let mut figs = Vec::new();
    let hist = histograms(&c.data.read(RFM_HISTOGRAMS_SUMMARY)?)?;
    let kind = |k: &str, h: u32| -> PerPoint {
        hist.iter()
            .filter(|((_, kind, hh), _)| kind == k && *hh == h)
            .map(|((p, _, _), v)| (*p, v.clone()))
            .collect()
    };
    let dim: BTreeMap<u32, f64> = c
        .points
        .iter()
        .map(|p| (p.point_id, p.params.dim as f64))
        .collect();
    let gauss = |p: u32, rows: &[(f64, f64, f64)]| {
        let var = mean_t.get(&p)? / dim.get(&p)?;
        Some((String::new(), gaussian_line(rows, var)))
    };
    figs.extend(overlay_figures(
        name,
        &overlay(
            "velocity-distribution",
            "P(v) of the velocity components (lines: Gaussian at <T>)",
            "v (m/s)",
            "P(v) (s/m)",
            (false, true),
        ),
        curves(c, &kind("velocity", 0), &gauss),
        NO_REFS,
    ));
    // The other histograms, drawn without a line: (kind, histogram, id, title, x, y, log x).
    let plain = [
        (
            "post_collision_velocity",
            0,
            "post-collision-velocity-distribution",
            "post-collision velocity P(v_0)",
            "v_0 (m/s)",
            "P(v_0) (s/m)",
            false,
        ),
        (
            "free_path",
            0,
            "free-path-distribution",
            "free paths P_l(l)",
            "l (m)",
            "P_l (1/m)",
            true,
        ),
        (
            "neighbour_distance",
            1,
            "neighbour-distance-distribution",
            "nearest-neighbour distances G_1(R)",
            "R (m, reduced)",
            "G_1(R) (1/m)",
            true,
        ),
    ];
    for (k, h, id, what, x_label, y_label, log_x) in plain {
        figs.extend(overlay_figures(
            name,
            &overlay(id, what, x_label, y_label, (log_x, true)),
            curves(c, &kind(k, h), NO_LINE),
            NO_REFS,
        ));
    }
    Ok(figs)
}

/// `structure-factor` S(k) (log-binned for display, reference S = 1) and
/// `radial-distribution` g(R) (reference g = 1).
fn structure_figures(c: View) -> Result<Figs, StoreError> {
    let name = c.name;
    let mut figs = Vec::new();
    let sk = structure_factor(&c.data.read(RFM_STRUCTURE_FACTOR_SUMMARY)?)?;
    let sk_shown: PerPoint = sk
        .iter()
        .map(|(&p, v)| (p, log_binned(v, SHELLS_PER_DECADE)))
        .collect();
    figs.extend(overlay_figures(
        name,
        &overlay(
            "structure-factor",
            "structure factor S(k)",
            "k (1/m)",
            "S(k)",
            (true, true),
        ),
        curves(c, &sk_shown, NO_LINE),
        &|x0, x1| level("S = 1", 1.0, x0, x1),
    ));

    let g = radial(&c.data.read(RFM_RADIAL_SUMMARY)?)?;
    figs.extend(overlay_figures(
        name,
        &overlay(
            "radial-distribution",
            "radial distribution g(R)",
            "R (m)",
            "g(R)",
            (false, false),
        ),
        curves(c, &g, NO_LINE),
        &|x0, x1| level("g = 1", 1.0, x0, x1),
    ));
    Ok(figs)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::{overlay_groups, OVERLAY_MAX};
    use crate::store::cols::table;

    /// (point, t, mean, sem) rows as `rfm_timeseries_summary`.
    fn ts_batch(rows: &[(u32, f64, f64, Option<f64>)]) -> RecordBatch {
        table(rows, |c| {
            vec![
                c.u32("point_id", |r| r.0),
                c.f64("t", |r| r.1),
                c.u32("n_replicas", |_| 2),
                c.f64("temperature_mean", |r| r.2),
                c.opt_f64("temperature_sem", |r| r.3),
            ]
        })
    }

    #[test]
    fn temperature_series_per_point_sorted_by_time() {
        let b = ts_batch(&[
            (1, 0.2, 3.0, Some(0.1)),
            (0, 0.1, 1.0, None),
            (1, 0.1, 2.0, Some(0.2)),
        ]);
        let s = timeseries(&[b]).unwrap();
        assert_eq!(s[&0], vec![(0.1, 1.0, 0.0)]);
        assert_eq!(s[&1], vec![(0.1, 2.0, 0.2), (0.2, 3.0, 0.1)]);
        // A table without the column is an error naming it, not an empty figure.
        let bad = table(&[(0u32, 1.0)], |c| {
            vec![c.u32("point_id", |r| r.0), c.f64("t", |r| r.1)]
        });
        assert!(timeseries(&[bad]).is_err());
    }

    #[test]
    fn many_shells_averaged_in_log_bins() {
        use crate::models::{log_binned, MAX_LOG_ROWS};
        let few: Vec<(f64, f64, f64)> = (1..=10).map(|i| (i as f64, 1.0, 0.1)).collect();
        assert_eq!(log_binned(&few, 10.0), few);
        // 1000 rows on k = 1..1000, 10 bins per decade: [1, 10^0.1) holds k = 1 alone,
        // [10^0.1, 10^0.2) and [10^0.2, 10^0.3) hold nothing (no bin drawn), [10^2.9, 10^3)
        // holds 795..999 (205 rows), [10^3, 10^3.1) k = 1000: 28 bins.
        let many: Vec<(f64, f64, f64)> = (1..=1000).map(|i| (i as f64, 2.0, 0.5)).collect();
        assert!(many.len() > MAX_LOG_ROWS);
        let b = log_binned(&many, 10.0);
        assert_eq!(b.len(), 28);
        assert_eq!(b[0], (1.0, 2.0, 0.5));
        assert!((b[27].0 - 1000.0).abs() < 1e-9 && (b[27].1, b[27].2) == (2.0, 0.5));
        let tail = b[26];
        assert_eq!(tail.1, 2.0);
        assert!((tail.2 - 0.5 / 205f64.sqrt()).abs() < 1e-12, "{tail:?}");
        assert!(tail.0 > 795.0 && tail.0 < 999.0);
        assert!(b.windows(2).all(|w| w[0].0 < w[1].0));
    }

    #[test]
    fn thinning_keeps_the_ends() {
        let v: Vec<u32> = (0..1000).collect();
        let t = thin(&v, 300);
        assert_eq!(t.len(), 300);
        assert_eq!((t[0], t[299]), (0, 999));
        assert!(t.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(thin(&v[..10], 300), v[..10].to_vec());
    }

    #[test]
    fn gaussian_moments_and_ratios() {
        // E|z| = sqrt(2/pi), E z^2 = 1, E|z|^3 = 2 sqrt(2/pi), E z^4 = 3, E z^6 = 15.
        let s = (2.0 / std::f64::consts::PI).sqrt();
        for (m, want) in [
            (1, s),
            (2, 1.0),
            (3, 2.0 * s),
            (4, 3.0),
            (6, 15.0),
            (12, 10395.0),
        ] {
            let g = gaussian_abs_moment(m);
            assert!((g - want).abs() < 1e-12 * want, "m={m}: {g} vs {want}");
        }
        // The moments of a Gaussian of variance 0.5 have ratio 1; a heavier 4th moment shows.
        let var: f64 = 0.5;
        let rows: Vec<(f64, f64, f64)> = (1..=4)
            .map(|m| {
                let k = if m == 4 { 1.5 } else { 1.0 };
                (
                    m as f64,
                    k * gaussian_abs_moment(m) * var.powf(m as f64 / 2.0),
                    0.01,
                )
            })
            .collect();
        let r = moment_ratios(&rows);
        assert_eq!(r.len(), 4);
        for (m, ratio, err) in &r {
            let want = if *m == 4.0 { 1.5 } else { 1.0 };
            assert!((ratio - want).abs() < 1e-12, "m={m}: {ratio}");
            assert!(*err > 0.0);
        }
        // No second moment, no ratios.
        assert!(moment_ratios(&rows[2..]).is_empty());
    }

    #[test]
    fn histogram_rows_become_densities_with_counting_errors() {
        type Row = (u32, &'static str, u32, f64, f64, u64, Option<f64>);
        let rows: Vec<Row> = vec![
            (0, "velocity", 0, -1.0, 0.0, 4, Some(0.4)),
            (0, "velocity", 0, 0.0, 1.0, 0, Some(0.0)),
            (0, "velocity", 0, f64::NEG_INFINITY, -1.0, 3, None),
            (0, "free_path", 0, 1e-3, 1e-2, 100, Some(2.0)),
            (2, "neighbour_distance", 1, 0.1, 0.4, 9, Some(1.0)),
        ];
        let b = table(&rows, |c| {
            vec![
                c.u32("point_id", |r| r.0),
                c.str("kind", |r| r.1),
                c.u32("h", |r| r.2),
                c.f64("lo", |r| r.3),
                c.f64("hi", |r| r.4),
                c.u64("count", |r| r.5),
                c.opt_f64("density", |r| r.6),
            ]
        });
        let h = histograms(&[b]).unwrap();
        assert_eq!(h.len(), 3);
        // Middle of a linear bin, error density / sqrt(count); empty and overflow bins gone.
        assert_eq!(h[&(0, "velocity".into(), 0)], vec![(-0.5, 0.4, 0.2)]);
        // Geometric centre of a log bin.
        let fp = &h[&(0, "free_path".into(), 0)][0];
        assert!((fp.0 - 1e-3 * 10f64.sqrt()).abs() < 1e-15);
        assert!((fp.2 - 0.2).abs() < 1e-15);
        let nd = &h[&(2, "neighbour_distance".into(), 1)][0];
        assert!((nd.0 - 0.2).abs() < 1e-15 && (nd.2 - 1.0 / 3.0).abs() < 1e-15);
    }

    #[test]
    fn gaussian_reference_is_normalised_and_clipped() {
        let rows: Vec<(f64, f64, f64)> = (-400..400)
            .map(|i| (i as f64 * 0.01 + 0.005, 1e-12, 0.0))
            .collect();
        let g = gaussian_line(&rows, 0.25);
        let integral: f64 = g.iter().map(|p| p.1 * 0.01).sum();
        assert!((integral - 1.0).abs() < 1e-6, "{integral}");
        // Nothing below a tenth of the smallest density shown.
        let rows: Vec<(f64, f64, f64)> = rows.iter().map(|r| (r.0, 1e-3, 0.0)).collect();
        let clipped = gaussian_line(&rows, 0.01);
        assert!(clipped.iter().all(|p| p.1 >= 1e-4));
        assert!(clipped.len() < rows.len());
        assert!(gaussian_line(&rows, 0.0).is_empty());
    }

    #[test]
    fn overlays_are_bounded() {
        for (n, groups, largest) in [
            (1, 1, 1),
            (12, 1, 12),
            (13, 2, 7),
            (30, 3, 10),
            (150, 13, 12),
        ] {
            let g = overlay_groups((0..n).collect::<Vec<u32>>());
            assert_eq!(g.len(), groups, "{n} points");
            assert_eq!(g.iter().map(|x| x.len()).max(), Some(largest));
            assert!(g.iter().all(|x| !x.is_empty() && x.len() <= OVERLAY_MAX));
            let flat: Vec<u32> = g.into_iter().flatten().collect();
            assert_eq!(flat, (0..n).collect::<Vec<u32>>(), "order kept");
        }
        assert!(overlay_groups(Vec::<u32>::new()).is_empty());
        let curve = |p: u32| PointCurve {
            point: p,
            label: format!("p{p}"),
            data: vec![(1.0, 2.0, 0.1), (2.0, 3.0, 0.1)],
            line: Some((String::new(), vec![(1.0, 2.0, 0.0)])),
        };
        let o = Overlay {
            id: "x",
            what: "w",
            x_label: "a",
            y_label: "b",
            log_x: true,
            log_y: false,
            legend_low: false,
        };
        let one = overlay_figures("c", &o, vec![curve(0)], &|x0, x1| level("ref", 1.0, x0, x1));
        assert_eq!(one.len(), 1);
        assert_eq!(one[0].0, "x");
        let f = &one[0].1;
        // data, its line, then the reference from the x range of the data.
        assert_eq!(f.series.len(), 3);
        assert_eq!(f.references_from, Some(2));
        assert_eq!(f.series[2].points, vec![(1.0, 1.0, 0.0), (2.0, 1.0, 0.0)]);
        let many = overlay_figures("c", &o, (0..30).map(curve).collect(), NO_REFS);
        let ids: Vec<&str> = many.iter().map(|f| f.0.as_str()).collect();
        assert_eq!(ids, ["x-1of3", "x-2of3", "x-3of3"]);
        assert!(
            many[1].1.title.contains("points 10-19"),
            "{}",
            many[1].1.title
        );
        assert_eq!(many[0].1.series.len(), 20);
        // Empty curves make no figure.
        let empty = PointCurve {
            data: Vec::new(),
            ..curve(0)
        };
        assert!(overlay_figures("c", &o, vec![empty], NO_REFS).is_empty());
    }
}
