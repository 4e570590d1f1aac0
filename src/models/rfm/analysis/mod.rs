//! `granular analyze` of an rfm campaign: the thesis's fits across points (spec 2.4-2.10),
//! from the run-level tables of the finished runs to the rows of `analysis_fits` and
//! `analysis_curves` and the figures of an [`Analysis`].
//!
//! Physics in pure, unit-tested functions: [`multiscaling`] (xi_m, zeta_m, collapse),
//! [`fractal`] (the k_D / L_Eff window of D_f from S(k), n_bar of n(R)), [`tails`] (alpha
//! windows, crossover (5.32), Moon plot), [`free_path`] ((4.25)), with the least squares of
//! `math::fit` and the power laws of `math::power`. This module reads the tables (the rows
//! of the finished runs: `CampaignView::read_done`), groups points (1D: by everything but N),
//! calls them and records the results; the parameters are the points' typed [`RfmParams`].
//! A fit whose window is outside its law's validity (the spec's) is flagged on its row
//! (`FitRow::outside`: xi_m and lambda below the thesis's N cut, the 2D structure fits in a box
//! below L_min, the free-path fits below 5 L_min); the shared `analysis` adds the statistical
//! flags (too few points, a zero error, chi2_r above its 99.9 % quantile) and warns.

pub mod fractal;
pub mod free_path;
pub mod multiscaling;
pub mod tails;

use std::collections::BTreeMap;
use std::ops::{Deref, DerefMut};

use super::tables as rt;
use super::{Rfm, RfmParams};
use crate::analysis::{
    fig, line, num, replica_stat, slug, Analysis, AnalysisError, FitRow, Options,
};
use crate::math::power;
use crate::models::{CampaignView, Model};
use crate::plot::{self, Series};
use crate::store::parquet_io::StoreError;

/// Per run: a value and its own (block) error.
type PerRun = Vec<(f64, Option<f64>)>;
/// Histogram bins by the bits of their lower edge: (lo, hi, count).
type Bins = BTreeMap<u64, (f64, f64, f64)>;

/// Per-point data of an RFM campaign, from the finished runs.
#[derive(Default)]
struct RfmData {
    /// (point, order) -> [(value, block sem)] per run.
    moments: BTreeMap<(u32, u32), PerRun>,
    /// (point, order) of h = 1.
    neighbour: BTreeMap<(u32, u32), PerRun>,
    /// (point, kind) -> lo bits -> (lo, hi, count) summed over runs (h = 0 / 1 only).
    hist: BTreeMap<(u32, String), Bins>,
    /// (point, n2) -> (k, [S per run]).
    sk: BTreeMap<(u32, u64), (f64, PerRun)>,
    /// (point, r_lo bits) -> (r_lo, r_hi, [C per run]).
    radial: BTreeMap<(u32, u64), (f64, f64, PerRun)>,
}

fn load_rfm(c: &CampaignView<'_, RfmParams>) -> Result<RfmData, StoreError> {
    let mut d = RfmData::default();
    let t = rt::RFM_MOMENTS;
    for b in c.read_done(t)? {
        for r in rt::RfmMoments::read_rows(&b, t)? {
            d.moments
                .entry((r.point_id, r.order))
                .or_default()
                .push((r.value, r.sem));
        }
    }
    let t = rt::RFM_NEIGHBOUR_MOMENTS;
    for b in c.read_done(t)? {
        for r in rt::RfmNeighbourMoments::read_rows(&b, t)? {
            if r.h == 1 {
                d.neighbour
                    .entry((r.point_id, r.order))
                    .or_default()
                    .push((r.value, r.sem));
            }
        }
    }
    let t = rt::RFM_HISTOGRAMS;
    for b in c.read_done(t)? {
        let rt::RfmHistogramsCols {
            point_id: p,
            kind,
            h,
            lo,
            hi,
            count: n,
            ..
        } = rt::RfmHistogramsCols::read(&b, t)?;
        for i in 0..b.num_rows() {
            if h.value(i) > 1 {
                continue;
            }
            let e = d
                .hist
                .entry((p.value(i), kind.value(i).to_string()))
                .or_default()
                .entry(lo.value(i).to_bits())
                .or_insert((lo.value(i), hi.value(i), 0.0));
            e.2 += n.value(i) as f64;
        }
    }
    let t = rt::RFM_STRUCTURE_FACTOR;
    for b in c.read_done(t)? {
        for r in rt::RfmStructureFactor::read_rows(&b, t)? {
            let e = d.sk.entry((r.point_id, r.n2)).or_insert((r.k, Vec::new()));
            e.1.push((r.s, r.sem));
        }
    }
    let t = rt::RFM_RADIAL;
    for b in c.read_done(t)? {
        for r in rt::RfmRadial::read_rows(&b, t)? {
            let e = d.radial.entry((r.point_id, r.r_lo.to_bits())).or_insert((
                r.r_lo,
                r.r_hi,
                Vec::new(),
            ));
            e.2.push((r.c, None));
        }
    }
    Ok(d)
}

/// Physical description of an RFM point, used as `key`: 1D "eps=0.5,L'=1[,N=398]";
/// 2D "phi=0.53,L=0.2,eps_n=0.1,eps_t=0.1[,N=3000]"; plus swept keys not covered by these.
fn rfm_key(c: &CampaignView<'_, RfmParams>, point: u32, p: &RfmParams, with_n: bool) -> String {
    let cfg = p.config();
    let mut parts = Vec::new();
    if p.dim == 1 {
        parts.push(format!("eps={}", num(p.restitution_normal)));
        parts.push(format!(
            "L'={}",
            num(cfg.box_length() - cfg.n_particles as f64 * cfg.diameter())
        ));
    } else {
        parts.push(format!("phi={}", num(cfg.fill_fraction())));
        parts.push(format!("L={}", num(cfg.box_length())));
        parts.push(format!("eps_n={}", num(p.restitution_normal)));
        parts.push(format!("eps_t={}", num(p.restitution_tangential)));
    }
    if with_n {
        parts.push(format!("N={}", p.n_particles));
    }
    let covered = [
        "n_particles",
        "restitution_normal",
        "restitution_tangential",
        "packing_fraction",
        "box_length",
        "reduced_length",
    ];
    let swept = c.points.iter().find(|x| x.point_id == point);
    for (k, v) in swept.map_or(&[][..], |x| &x.swept[..]) {
        if !covered.contains(k) {
            let v = match v {
                serde_json::Value::String(s) => s.clone(),
                other => other.to_string(),
            };
            parts.push(format!("{k}={v}"));
        }
    }
    parts.join(",")
}

/// The campaign's analysis and its context, as the fits below use them.
struct Ctx<'a, 'v> {
    c: &'a CampaignView<'v, RfmParams>,
    a: &'a mut Analysis,
}

impl Deref for Ctx<'_, '_> {
    type Target = Analysis;
    fn deref(&self) -> &Analysis {
        self.a
    }
}

impl DerefMut for Ctx<'_, '_> {
    fn deref_mut(&mut self) -> &mut Analysis {
        self.a
    }
}

/// The analysis of an rfm campaign (see the module's documentation): the points with
/// finished runs, every run-level table the manifest asks for present.
pub fn analyze(c: &CampaignView<'_, RfmParams>, a: &mut Analysis) -> Result<(), AnalysisError> {
    a.start()?;
    // Every run-level table the manifest asks for must exist.
    let points: Vec<&RfmParams> = c.points.iter().map(|p| p.params).collect();
    for t in Rfm::tables(&points) {
        if t.ends_with("_summary") || t == rt::RFM_SNAPSHOTS {
            continue;
        }
        if !c.data.dir(t).is_dir() {
            return Err(AnalysisError::NotAnalysable(format!(
                "table {t} is missing"
            )));
        }
    }
    let data = load_rfm(c)?;
    let rfm: Vec<(u32, &RfmParams)> = c
        .points
        .iter()
        .filter(|p| p.runs_done > 0)
        .map(|p| (p.point_id, p.params))
        .collect();
    let mut ctx = Ctx { c, a };
    let ctx = &mut ctx;
    multiscaling_fits(ctx, &rfm, &data);
    bisection_comparison(ctx, &rfm, &data);
    structure_fits(ctx, &rfm, &data);
    tail_fits(ctx, &rfm, &data);
    free_path_fits(ctx, &rfm, &data);
    Ok(())
}

/// 1D: xi_m from <|v|^m> vs N and zeta_m from <R^m> vs N, per group of points that differ
/// only in N; the collapse of F 3.3.
fn multiscaling_fits(ctx: &mut Ctx, rfm: &[(u32, &RfmParams)], d: &RfmData) {
    // Group the 1D points by their key without N.
    let mut groups: BTreeMap<String, Vec<(u32, &RfmParams)>> = BTreeMap::new();
    for &(p, r) in rfm {
        if r.dim == 1 {
            groups
                .entry(rfm_key(ctx.c, p, r, false))
                .or_default()
                .push((p, r));
        }
    }
    let mut figs = MultiscalingFigures::default();
    for (key, pts) in &groups {
        let distinct_n: std::collections::BTreeSet<u64> =
            pts.iter().map(|p| p.1.n_particles).collect();
        if distinct_n.len() < 2 {
            continue;
        }
        for (table, sym) in [(&d.moments, "xi"), (&d.neighbour, "zeta")] {
            let per_m = exponents(ctx, key, pts, table, sym, &mut figs);
            if !per_m.is_empty() {
                let s = Series {
                    label: key.clone(),
                    points: per_m,
                    line: false,
                };
                if sym == "xi" {
                    figs.xim.push(s);
                } else {
                    figs.zeta.push(s);
                }
            }
        }
    }
    figs.draw(ctx);
}

/// The series of the multiscaling figures, gathered over the groups of points.
#[derive(Default)]
struct MultiscalingFigures {
    /// <v^2> against N with the fitted lines (F 3.1).
    v2: Vec<Series>,
    /// N -> (1 - eps^2, collapsed <v^2>, error) (F 3.3).
    collapse: BTreeMap<u64, Vec<(f64, f64, f64)>>,
    /// xi_m / m and zeta_m / m against m, per group.
    xim: Vec<Series>,
    zeta: Vec<Series>,
}

/// The exponents `sym`_m (xi: velocity moments, zeta: neighbour distances) of one group of
/// points against N, each a fit row; returns (m, exponent / m, error / m) per order.
fn exponents(
    ctx: &mut Ctx,
    key: &str,
    pts: &[(u32, &RfmParams)],
    table: &BTreeMap<(u32, u32), PerRun>,
    sym: &str,
    figs: &mut MultiscalingFigures,
) -> Vec<(f64, f64, f64)> {
    let orders: std::collections::BTreeSet<u32> = table
        .keys()
        .filter(|(p, _)| pts.iter().any(|x| x.0 == *p))
        .map(|k| k.1)
        .collect();
    let mut per_m = Vec::new();
    for m in orders {
        let at_n: Vec<multiscaling::MomentAtN> = pts
            .iter()
            .filter_map(|(p, r)| {
                table.get(&(*p, m)).map(|v| {
                    let (value, sem) = replica_stat(v);
                    multiscaling::MomentAtN {
                        n: r.n_particles as f64,
                        value,
                        sem,
                    }
                })
            })
            .collect();
        // The thesis's N cut (for velocity moments); keep at least 3 points.
        let cut = if sym == "xi" { ctx.opts.n_min } else { 0.0 };
        let above = at_n.iter().filter(|x| x.n >= cut).count();
        let (cut, note) = if above >= 3 || cut == 0.0 {
            (cut, String::new())
        } else {
            (
                0.0,
                format!(" (only {above} points with N >= {cut}: all N used)"),
            )
        };
        if !note.is_empty() && m == 2 {
            ctx.warn(format!("{key}: xi_2{note}"));
        }
        let Some(f) = multiscaling::exponent_vs_n(&at_n, cut) else {
            continue;
        };
        let reference = (sym == "zeta").then(|| multiscaling::bisection_zeta(m));
        let weighted = if f.fit.chi2_reduced.is_some() {
            "weighted"
        } else {
            "unweighted"
        };
        let row = ctx.fit(
            format!("{sym}_{m}"),
            key,
            f.exponent,
            Some(f.error),
            f.fit.chi2_reduced,
            f.fit.n_points,
            format!(
                "N in [{}, {}], {weighted}{note}",
                f.n_lo as u64, f.n_hi as u64
            ),
            reference,
        );
        if sym == "xi" {
            below_thesis_n(row, f.n_lo);
        }
        per_m.push((m as f64, f.exponent / m as f64, f.error / m as f64));
        if sym == "xi" && m == 2 {
            lambda_and_collapse(ctx, key, pts[0].1, &f, &at_n, figs);
        }
    }
    per_m
}

/// From the xi_2 fit of a group: lambda(eps) of (3.8) (the amplitude over (D L'/M^2)^(2/3)),
/// the <v^2>(N) series with its line, and the group's points of the collapse (F 3.3).
fn lambda_and_collapse(
    ctx: &mut Ctx,
    key: &str,
    r: &RfmParams,
    f: &multiscaling::ExponentFit,
    at_n: &[multiscaling::MomentAtN],
    figs: &mut MultiscalingFigures,
) {
    let cfg = r.config();
    let lr = cfg.box_length() - cfg.n_particles as f64 * cfg.diameter();
    let scale = (r.noise_strength * lr / (r.mass * r.mass)).powf(2.0 / 3.0);
    let lambda = f.ln_amplitude.exp() / scale;
    let lam_err = lambda * f.fit.errors[0];
    let row = ctx.fit(
        "lambda",
        key,
        lambda,
        Some(lam_err),
        f.fit.chi2_reduced,
        f.fit.n_points,
        format!(
            "<v^2> = (D L'/M^2)^(2/3) lambda N^-xi_2, N >= {}",
            f.n_lo as u64
        ),
        None,
    );
    below_thesis_n(row, f.n_lo);
    figs.v2.push(Series {
        label: key.to_string(),
        points: at_n
            .iter()
            .map(|x| (x.n, x.value, x.sem.unwrap_or(0.0)))
            .collect(),
        line: false,
    });
    let (la, xi) = (f.ln_amplitude, f.exponent);
    figs.v2
        .push(line(format!("N^-{:.3}", xi), f.n_lo, f.n_hi, move |n| {
            (la - xi * n.ln()).exp()
        }));
    for x in at_n {
        let y = multiscaling::collapse_value(x.value, x.n, xi, r.noise_strength, lr, r.mass);
        let e = y * x.sem.unwrap_or(0.0) / x.value;
        figs.collapse.entry(x.n as u64).or_default().push((
            1.0 - r.restitution_normal.powi(2),
            y,
            e,
        ));
    }
}

impl MultiscalingFigures {
    fn draw(self, ctx: &mut Ctx) {
        if !self.v2.is_empty() {
            let f = fig(
                ctx.title("<v^2> vs N (3.8)"),
                "N",
                "<v^2> (m^2/s^2)",
                self.v2,
            );
            ctx.figure("xi2-fit".into(), plot::loglog(f));
        }
        if !self.xim.is_empty() {
            let mut s = self.xim;
            let r = s.len();
            s.push(Series {
                label: "mean field 1/3".into(),
                points: vec![(1.0, 1.0 / 3.0, 0.0), (12.0, 1.0 / 3.0, 0.0)],
                line: true,
            });
            let f = fig(ctx.title("xi_m / m (3.14)"), "m", "xi_m / m", s);
            ctx.figure("xi-m".into(), plot::linear(f).with_references_from(r));
        }
        if !self.zeta.is_empty() {
            let mut s = self.zeta;
            let r = s.len();
            s.push(Series {
                label: "uniform bisection ln(1+m)/(m ln 2)".into(),
                points: (1..=9)
                    .map(|m| (m as f64, multiscaling::bisection_zeta(m) / m as f64, 0.0))
                    .collect(),
                line: true,
            });
            let f = fig(ctx.title("zeta_m / m (3.20)"), "m", "zeta_m / m", s);
            ctx.figure("zeta-m".into(), plot::linear(f).with_references_from(r));
        }
        if !self.collapse.is_empty() {
            let s = self
                .collapse
                .into_iter()
                .map(|(n, mut v)| {
                    v.sort_by(|a, b| a.0.total_cmp(&b.0));
                    Series {
                        label: format!("N = {n}"),
                        points: v,
                        line: false,
                    }
                })
                .collect();
            let f = fig(
                ctx.title("collapse (F 3.3)"),
                "1 - eps^2",
                "<v^2> N^xi_2 (D L'/M^2)^(-2/3)",
                s,
            );
            ctx.figure("collapse".into(), plot::loglog(f));
        }
    }
}

/// 1D: G_1(R; N) (neighbour-distance histogram, h = 1) beside the uniform bisection P_n(x),
/// n = log2 N, with x = R/L' (F 3.16; no fit parameter). Figure and curves only.
fn bisection_comparison(ctx: &mut Ctx, rfm: &[(u32, &RfmParams)], d: &RfmData) {
    for &(p, r) in rfm {
        if r.dim != 1 {
            continue;
        }
        let Some(bins) = d.hist.get(&(p, "neighbour_distance".to_string())) else {
            continue;
        };
        let cfg = r.config();
        let lr = cfg.box_length() - cfg.n_particles as f64 * cfg.diameter();
        let total: f64 = bins.values().map(|b| b.2).sum();
        let n = (r.n_particles as f64).log2();
        let data: Vec<(f64, f64, f64)> = bins
            .values()
            .filter(|b| b.0 > 0.0 && b.1.is_finite() && b.1 > b.0 && b.2 > 0.0)
            .map(|&(lo, hi, c)| {
                // G_1 as a density of x = R / L'.
                let dens = c / (total * (hi - lo)) * lr;
                ((lo * hi).sqrt() / lr, dens, dens / c.sqrt())
            })
            .collect();
        if data.is_empty() {
            continue;
        }
        let key = rfm_key(ctx.c, p, r, true);
        // rms of ln(G_1 / P_n) over the well-sampled bins (X >= 10 <=> sigma <= 0.32 dens).
        let logs: Vec<f64> = data
            .iter()
            .filter(|q| q.2 <= 0.32 * q.1 && q.0 < 1.0)
            .map(|q| (q.1 / multiscaling::bisection_density(q.0, n)).ln())
            .filter(|v| v.is_finite())
            .collect();
        if !logs.is_empty() {
            let rms = (logs.iter().map(|v| v * v).sum::<f64>() / logs.len() as f64).sqrt();
            ctx.fit(
                "G_1_vs_bisection_rms_log_ratio",
                &key,
                rms,
                None,
                None,
                logs.len(),
                format!(
                    "rms of ln(G_1(R; N) / P_n(R/L')), n = log2 N = {n:.3}, bins with X >= 10 \
                     (no fit parameter; 0 = identical)"
                ),
                Some(0.0),
            )
            .params(0);
        }
        let (x0, x1) = (data[0].0, data[data.len() - 1].0.min(0.999));
        let series = vec![
            Series {
                label: "G_1(R; N), x = R/L'".into(),
                points: data,
                line: false,
            },
            line(
                format!("uniform bisection P_n(x), n = log2 N = {n:.2}"),
                x0,
                x1,
                move |x| multiscaling::bisection_density(x, n),
            ),
        ];
        let fg = fig(
            ctx.title(&format!("G_1 vs bisection (F 3.16) [{key}]")),
            "x = R / L'",
            "density",
            series,
        );
        ctx.figure(
            format!("g1-bisection-{}", slug(&key)),
            plot::loglog(fg).with_references_from(1),
        );
    }
}

/// 2D: D_f from S(k) with the k_D/L_Eff window; C(R) and n(R) power laws.
fn structure_fits(ctx: &mut Ctx, rfm: &[(u32, &RfmParams)], d: &RfmData) {
    for &(p, r) in rfm {
        if r.dim == 2 {
            let key = rfm_key(ctx.c, p, r, true);
            structure_factor_fit(ctx, &key, p, r, d);
            cumulative_count_fits(ctx, &key, p, r, d);
        }
    }
}

/// D_f from the point's S(k) below the fit cut-off k' (k_D, L_Eff; 4.5-4.9), and its figure.
fn structure_factor_fit(ctx: &mut Ctx, key: &str, p: u32, r: &RfmParams, d: &RfmData) {
    let cfg = r.config();
    let (l, dd, phi) = (cfg.box_length(), cfg.diameter(), cfg.fill_fraction());
    let shells: Vec<power::Sample> =
        d.sk.range((p, 0)..(p, u64::MAX))
            .map(|(_, (k, v))| {
                let (s, e) = replica_stat(v);
                power::Sample {
                    x: *k,
                    y: s,
                    err: e,
                }
            })
            .collect();
    if !shells.is_empty() {
        let kd = fractal::k_dissipative(r.restitution_normal, r.restitution_tangential, phi, dd);
        let (kp, rule) = fractal::fit_cutoff(kd, l);
        let window = format!(
            "{rule}: k d < {:.4} (k_D d = {:.4}, L_Eff = {:.3} m)",
            kp * dd,
            kd * dd,
            fractal::l_eff(kd)
        );
        match power::decay_exponent(&shells, 0.0, kp) {
            Some(f) => {
                let row = ctx.fit(
                    "D_f_structure_factor",
                    key,
                    f.exponent,
                    Some(f.error),
                    f.fit.chi2_reduced,
                    f.fit.n_points,
                    window,
                    None,
                );
                below_l_min(row, r);
                let data: Vec<(f64, f64, f64)> = shells
                    .iter()
                    .filter(|s| s.y > 0.0 && s.x * dd <= 25.0)
                    .map(|s| (s.x * dd, s.y, s.err.unwrap_or(0.0)))
                    .collect();
                let (la, df) = (f.ln_amplitude, f.exponent);
                let series = vec![
                    Series {
                        label: "S(k)".into(),
                        points: data,
                        line: false,
                    },
                    line(
                        format!("k^-{df:.2} (fit, k d < {:.3})", kp * dd),
                        f.x_lo * dd,
                        kp * dd,
                        move |x| (la - df * (x / dd).ln()).exp(),
                    ),
                ];
                let fg = fig(ctx.title(&format!("S(k) [{key}]")), "k d", "S(k)", series);
                ctx.figure(format!("sk-{}", slug(key)), plot::loglog(fg));
            }
            None => ctx.warn(format!(
                "{key}: fewer than two S(k) shells below k' (k' d = {:.4}, first shell k d = \
                 {:.4}): no D_f; a larger box is needed",
                kp * dd,
                2.0 * std::f64::consts::PI / l * dd
            )),
        }
    }
}

/// C(R) and n(R) = C(R) - n_bar at R = r_hi of each bin, their power laws over the window
/// [2 d, L/4] [REC], and their figure.
fn cumulative_count_fits(ctx: &mut Ctx, key: &str, p: u32, r: &RfmParams, d: &RfmData) {
    let cfg = r.config();
    let (l, dd) = (cfg.box_length(), cfg.diameter());
    let rows: Vec<(f64, f64, Option<f64>)> = d
        .radial
        .range((p, 0)..(p, u64::MAX))
        .map(|(_, (_, hi, v))| {
            let (m, s) = replica_stat(v);
            (*hi, m, s)
        })
        .collect();
    if rows.is_empty() {
        return;
    }
    {
        let n = r.n_particles as f64;
        let r_: Vec<f64> = rows.iter().map(|x| x.0).collect();
        let cv: Vec<f64> = rows.iter().map(|x| x.1).collect();
        let ce: Vec<Option<f64>> = rows.iter().map(|x| x.2).collect();
        let nv: Vec<f64> = rows
            .iter()
            .map(|x| x.1 - fractal::mean_field_count(x.0, n, l))
            .collect();
        let (lo, hi) = (2.0 * dd, 0.25 * l);
        let window = format!("R in [2 d, L/4] = [{lo:.4}, {hi:.4}] m");
        let mut series = vec![Series {
            label: "C(R)".into(),
            points: r_
                .iter()
                .zip(&cv)
                .map(|(a, b)| (*a / dd, *b, 0.0))
                .collect(),
            line: false,
        }];
        if let Some(f) = power::growth_exponent(&r_, &cv, &ce, lo, hi) {
            let row = ctx.fit(
                "C_R_exponent",
                key,
                f.exponent,
                Some(f.error),
                f.fit.chi2_reduced,
                f.fit.n_points,
                window.clone(),
                None,
            );
            below_l_min(row, r);
        }
        series.push(Series {
            label: "n(R) = C(R) - n_bar".into(),
            points: r_
                .iter()
                .zip(&nv)
                .filter(|(_, v)| **v > 0.0)
                .map(|(a, b)| (*a / dd, *b, 0.0))
                .collect(),
            line: false,
        });
        match power::growth_exponent(&r_, &nv, &ce, lo, hi) {
            Some(f) => {
                let row = ctx.fit(
                    "D_f_n_R",
                    key,
                    f.exponent,
                    Some(f.error),
                    f.fit.chi2_reduced,
                    f.fit.n_points,
                    window,
                    None,
                );
                below_l_min(row, r);
                let (la, e) = (f.ln_amplitude, f.exponent);
                series.push(line(
                    format!("n(R) ~ R^{e:.2}"),
                    f.x_lo / dd,
                    f.x_hi / dd,
                    move |x| (la + e * (x * dd).ln()).exp(),
                ));
            }
            None => ctx.warn(format!("{key}: n(R) has no positive values in {window}")),
        }
        let fg = fig(
            ctx.title(&format!("C(R), n(R) [{key}]")),
            "R / d",
            "count within R",
            series,
        );
        ctx.figure(format!("cr-{}", slug(key)), plot::loglog(fg));
    }
}

/// Velocity tails: alpha window, crossover (5.32), Moon plot (5.6); with several points, the
/// inverse-variance mean of their accepted alphas (the thesis's summary of T 5.1, 1.163 +-
/// 0.017 over its bold entries).
fn tail_fits(ctx: &mut Ctx, rfm: &[(u32, &RfmParams)], d: &RfmData) {
    tail_fits_per_point(ctx, rfm, d);
    let alphas: Vec<(f64, f64)> = ctx
        .report
        .fits
        .iter()
        .filter(|f| f.quantity == "alpha")
        .filter_map(|f| f.error.map(|e| (f.value, e)))
        .collect();
    if alphas.len() >= 2 {
        let (v, e): (Vec<f64>, Vec<f64>) = alphas.iter().copied().unzip();
        if let Some((m, err, chi)) = crate::math::fit::weighted_mean(&v, &e) {
            ctx.fit(
                "alpha_weighted_mean",
                "all points with an accepted alpha",
                m,
                Some(err),
                chi,
                v.len(),
                "inverse-variance mean of the accepted ranges (centre, half-width)",
                None,
            )
            .params(1);
        }
    }
}

fn tail_fits_per_point(ctx: &mut Ctx, rfm: &[(u32, &RfmParams)], d: &RfmData) {
    for &(p, r) in rfm {
        let Some(bins) = d.hist.get(&(p, "velocity".to_string())) else {
            continue;
        };
        let key = rfm_key(ctx.c, p, r, true);
        let total: f64 = bins.values().map(|b| b.2).sum();
        let raw: Vec<(f64, f64, f64)> = bins.values().copied().collect();
        let folded = tails::fold(&raw);
        if folded.is_empty() || total <= 0.0 {
            continue;
        }
        let mut rule = tails::AlphaRule::thesis(r.dim);
        rule.factor = ctx.opts.count_error_factor;
        rule.chi2_max = ctx.opts.chi2_accept;
        alpha_fits(ctx, &key, &folded, &rule);
        let rms = tails::v_rms(&folded);
        velocity_distribution(ctx, &key, &folded, total, rms);
        moon_plot(ctx, &key, &folded, total, rms, &rule);
    }
}

/// The accepted alpha window of the tail (A.3, 5.1.1) and the best alpha.
fn alpha_fits(ctx: &mut Ctx, key: &str, folded: &[tails::FoldedBin], rule: &tails::AlphaRule) {
    let step = rule.grid.2;
    let window = |w: &tails::AlphaWindow| {
        format!(
            "counts in [{}, {}], |v| in [{:.3}, {:.3}] m/s, s = {} sqrt(X), chi_r^2 < {}",
            rule.count_lo, rule.count_hi, w.v_lo, w.v_hi, rule.factor, rule.chi2_max
        )
    };
    match tails::alpha_window(folded, rule) {
        Some(w) => {
            match w.centre_half_width(step) {
                Some((c, h)) => {
                    ctx.fit(
                        "alpha",
                        key,
                        c,
                        Some(h),
                        Some(w.best_chi2_reduced),
                        w.n_bins,
                        format!("accepted range (centre +- half-width); {}", window(&w)),
                        None,
                    );
                }
                None => ctx.warn(format!(
                    "{key}: no alpha has chi_r^2 < {} (best alpha {:.2}, chi_r^2 {:.2})",
                    rule.chi2_max, w.best_alpha, w.best_chi2_reduced
                )),
            }
            ctx.fit(
                "alpha_best",
                key,
                w.best_alpha,
                None,
                Some(w.best_chi2_reduced),
                w.n_bins,
                format!("smallest chi_r^2 on the grid (step {step}); {}", window(&w)),
                None,
            );
        }
        None => ctx.warn(format!(
            "{key}: fewer than 4 tail bins with counts in [{}, {}]: no alpha window (more \
             samples needed)",
            rule.count_lo, rule.count_hi
        )),
    }
}

/// P(v) against v / v_rms with the crossover fit (5.32).
fn velocity_distribution(
    ctx: &mut Ctx,
    key: &str,
    folded: &[tails::FoldedBin],
    total: f64,
    rms: f64,
) {
    let p_v: Vec<(f64, f64, f64)> = folded
        .iter()
        .filter(|b| b.count > 0.0)
        .map(|b| {
            let dens = tails::density(b, total);
            (b.v / rms, dens, dens / b.count.sqrt())
        })
        .collect();
    let mut pv_series = vec![Series {
        label: "P(v)".into(),
        points: p_v,
        line: false,
    }];
    // The crossover function (5.32), alpha = 1.
    if let Some(cr) = tails::crossover_fit(folded, total, 10.0) {
        let ((vr, vre), (vc, vce)) = (cr.v_r(), cr.v_c());
        let chi = cr.fit.chi2_reduced;
        let n = cr.fit.n_points;
        let w = "(5.32), alpha = 1, ln P, bins with X >= 10";
        // (5.32) has three free parameters (A, v_r, v_c); every row below is of that fit.
        ctx.fit("v_r", key, vr, Some(vre), chi, n, w, None)
            .params(3);
        ctx.fit("v_c", key, vc, Some(vce), chi, n, w, None)
            .params(3);
        let ratio = vc / vr;
        let ratio_err = ratio * ((vre / vr).powi(2) + (vce / vc).powi(2)).sqrt();
        ctx.fit("v_c/v_r", key, ratio, Some(ratio_err), chi, n, w, None)
            .params(3);
        ctx.fit("P(v_c)/P(0)", key, cr.ratio_at_v_c(), None, chi, n, w, None)
            .params(3);
        ctx.fit("v_A", key, vr * vr / vc, None, chi, n, "v_r^2 / v_c", None)
            .params(3);
        let params = cr.fit.params.clone();
        let vmax = folded
            .iter()
            .filter(|b| b.count >= 10.0)
            .map(|b| b.v)
            .fold(0.0, f64::max);
        pv_series.push(Series {
            label: format!("(5.32): v_r = {vr:.3}, v_c = {vc:.3} m/s"),
            points: (1..=80)
                .map(|j| {
                    let v = vmax * j as f64 / 80.0;
                    (v / rms, tails::crossover_ln(&params, v).exp(), 0.0)
                })
                .collect(),
            line: true,
        });
    } else {
        ctx.warn(format!("{key}: the crossover fit (5.32) did not converge"));
    }
    let fg = fig(
        ctx.title(&format!("P(v) [{key}]")),
        "v / v_rms",
        "P(v)",
        pv_series,
    );
    ctx.figure(format!("pv-{}", slug(key)), plot::semilog_y(fg));
}

/// The Moon plot (5.6) with P' = P(0) and P' = A_0 (the exponential tail's amplitude), its
/// slopes, and reference lines of slope alpha_T.
fn moon_plot(
    ctx: &mut Ctx,
    key: &str,
    folded: &[tails::FoldedBin],
    total: f64,
    rms: f64,
    rule: &tails::AlphaRule,
) {
    // Moon plot with P' = P(0) and P' = A_0 (exponential tail amplitude).
    let p0 = tails::density(&folded[0], total);
    let mut moon = Vec::new();
    let mut refs = vec![("P(0)", p0)];
    if let Some(f) = tails::tail_fit(folded, rule, 1.0) {
        let width = folded[0].width;
        refs.push(("A_0", f.params[0] / (2.0 * total * width)));
        ctx.fit(
            "A_0/P(0)",
            key,
            f.params[0] / (2.0 * total * width) / p0,
            None,
            f.chi2_reduced,
            f.n_points,
            "exponential tail fit (alpha = 1) over the alpha window",
            None,
        );
    }
    for (name, pref) in refs {
        let pts = tails::moon_points(folded, total, rms, pref, 10.0);
        if let Some(f) = tails::moon_slope(&pts, 2f64.ln()) {
            ctx.fit(
                format!("moon_slope_{}", if name == "P(0)" { "P0" } else { "A0" }),
                key,
                f.params[1],
                Some(f.errors[1]),
                f.chi2_reduced,
                f.n_points,
                format!("Moon plot (5.6) with P' = {name}, v > 2 v_rms, X >= 10"),
                None,
            );
        }
        moon.push(Series {
            label: format!("P' = {name}"),
            points: pts.iter().map(|m| (m.x, m.y, m.err)).collect(),
            line: false,
        });
    }
    // Reference lines f = -alpha_T x + C through the first tail point.
    let r = moon.len();
    if let Some(first) = moon
        .first()
        .and_then(|s| s.points.iter().find(|p| p.0 >= 2f64.ln()))
    {
        let (x0, y0) = (first.0, first.1);
        let x1 = moon[0].points.iter().map(|p| p.0).fold(x0, f64::max);
        for a in [2.0, 1.5, 1.16, 1.0] {
            moon.push(Series {
                label: format!("alpha_T = {a}"),
                points: vec![(x0, y0, 0.0), (x1, y0 - a * (x1 - x0), 0.0)],
                line: true,
            });
        }
    }
    let fg = fig(
        ctx.title(&format!("Moon plot [{key}]")),
        "ln(v / v_rms)",
        "-ln(-ln(P / P'))",
        moon,
    );
    ctx.figure(
        format!("moon-{}", slug(key)),
        plot::linear(fg).with_references_from(r),
    );
}

/// Free paths: the tail fit (4.25).
fn free_path_fits(ctx: &mut Ctx, rfm: &[(u32, &RfmParams)], d: &RfmData) {
    for &(p, r) in rfm {
        let Some(bins) = d.hist.get(&(p, "free_path".to_string())) else {
            continue;
        };
        let key = rfm_key(ctx.c, p, r, true);
        let total: f64 = bins.values().map(|b| b.2).sum();
        let pb: Vec<free_path::PathBin> = bins
            .values()
            .filter(|b| b.0 > 0.0 && b.1.is_finite() && b.1 > b.0)
            .map(|&(lo, hi, n)| free_path::PathBin {
                l: (lo * hi).sqrt(),
                density: n / (total * (hi - lo)),
                count: n,
            })
            .collect();
        let tail = free_path::tail(&pb, 1.0, 10.0);
        let window = |t: &[free_path::PathBin]| {
            format!(
                "P_l < 1 m^-1 beyond its maximum, X >= 10: l in [{:.3e}, {:.3e}] m",
                t.first().map_or(f64::NAN, |b| b.l),
                t.last().map_or(f64::NAN, |b| b.l)
            )
        };
        let mut series = vec![Series {
            label: "P_l(l)".into(),
            points: pb
                .iter()
                .filter(|b| b.count > 0.0)
                .map(|b| (b.l, b.density, b.density / b.count.sqrt()))
                .collect(),
            line: false,
        }];
        match free_path::fit_tail(&tail, None) {
            Some(f) => {
                let w = window(&tail);
                // (4.25): A_0, C, D_f free.
                let row = ctx.fit(
                    "free_path_D_f",
                    &key,
                    f.params[2],
                    Some(f.errors[2]),
                    f.chi2_reduced,
                    f.n_points,
                    w.clone(),
                    None,
                );
                free_path_box(row.params(3), r);
                let row = ctx.fit(
                    "free_path_C",
                    &key,
                    f.params[1],
                    Some(f.errors[1]),
                    f.chi2_reduced,
                    f.n_points,
                    w,
                    None,
                );
                free_path_box(row.params(3), r);
                let params = f.params.clone();
                let (l0, l1) = (tail[0].l, tail[tail.len() - 1].l);
                series.push(line(
                    format!("(4.25): D_f = {:.2}, C = {:.3}", params[2], params[1]),
                    l0,
                    l1,
                    move |l| free_path::ln_tail(&params, l).exp(),
                ));
            }
            None => ctx.warn(format!(
                "{key}: free-path tail fit (4.25) impossible ({} tail bins)",
                tail.len()
            )),
        }
        let df = ctx.opts.fixed_df;
        if let Some(f) = free_path::fit_tail(&tail, Some(df)) {
            let row = ctx.fit(
                "free_path_C_fixed_D_f",
                &key,
                f.params[1],
                Some(f.errors[1]),
                f.chi2_reduced,
                f.n_points,
                format!("D_f = {df} fixed; {}", window(&tail)),
                None,
            );
            free_path_box(row, r);
        }
        let fg = fig(
            ctx.title(&format!("free paths [{key}]")),
            "l (m)",
            "P_l (1/m)",
            series,
        );
        ctx.figure(format!("free-path-{}", slug(&key)), plot::loglog(fg));
    }
}

/// xi_m and lambda over N below the thesis's cut (N >= 398, [`Options::default`]'s
/// `n_min`): the thesis drops smaller N for their large long-lived fluctuations (sec. 3.1.3;
/// spec 2.10), so (3.8)/(3.13) are not taken to hold there.
fn below_thesis_n(row: &mut FitRow, n_lo: f64) {
    let cut = Options::default().n_min;
    if n_lo < cut {
        row.outside(
            format!("N from {}", n_lo as u64),
            format!(
                "N from {} < {cut}: below the thesis's N cut, where <|v|^m> has large \
                 long-lived fluctuations (sec. 3.1.3)",
                n_lo as u64
            ),
            format!(
                "run at least 3 values of N >= {cut} (--n-min {cut}, the default, then \
                 uses only them)"
            ),
        );
    }
}

/// The lengths (4.5)-(4.9) of a 2D point: (L, k_D, L_min = 2 pi/k_D, L_Eff).
fn dissipative_lengths(r: &RfmParams) -> (f64, f64, f64, f64) {
    let cfg = r.config();
    let kd = fractal::k_dissipative(
        r.restitution_normal,
        r.restitution_tangential,
        cfg.fill_fraction(),
        cfg.diameter(),
    );
    (cfg.box_length(), kd, fractal::l_min(kd), fractal::l_eff(kd))
}

/// A 2D structure fit (S(k) (4.4), C(R) (4.16), n(R) (4.17)) in a box smaller than
/// L_min = 2 pi/k_D: its lowest shell 2 pi/L is already beyond k_D, so the dissipative
/// regime where the power law holds (k < k_D, spec 2.7; in real space its Hankel
/// transform, spec 2.7-2.8) has no range in the box.
fn below_l_min(row: &mut FitRow, r: &RfmParams) {
    if r.dim != 2 {
        return;
    }
    let (l, kd, l_min, l_eff) = dissipative_lengths(r);
    if l < l_min {
        row.outside(
            "L < L_min",
            format!(
                "box L = {l:.4} m < L_min = 2 pi/k_D = {l_min:.4} m (k_D = {kd:.4} 1/m, \
                 (4.5)-(4.8)): no k < k_D in the box, where the clustering power law holds"
            ),
            format!(
                "use a box larger than L_Eff = {l_eff:.4} m (more particles at this \
                 packing fraction), or check eps_n, eps_t and phi against the thesis's \
                 (sec. 4.1)"
            ),
        );
    }
}

/// A 2D free-path fit (4.25) in a box smaller than 5 L_min: the thesis sees the tail
/// still change with L below L_c ~ 0.4 m ~ 5 L_min at phi = 0.353 (sec. 4.3; spec 2.9).
fn free_path_box(row: &mut FitRow, r: &RfmParams) {
    if r.dim != 2 {
        return;
    }
    let (l, _, l_min, _) = dissipative_lengths(r);
    if l < 5.0 * l_min {
        row.outside(
            "L < 5 L_min",
            format!(
                "box L = {l:.4} m < 5 L_min = {:.4} m: the free-path tail still changes \
                 with L there (sec. 4.3)",
                5.0 * l_min
            ),
            format!(
                "use a box of at least 5 L_min = {:.4} m, or read the tail as finite-size",
                5.0 * l_min
            ),
        );
    }
}
