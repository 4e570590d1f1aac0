//! `granular analyze`, the part every model's analysis shares: the options, the rows of the
//! table `analysis_fits` (one row per fitted quantity) and of the table `analysis_curves`
//! (the data behind every figure: measured points, fitted lines), the figures (PNG + SVG),
//! and their writing into the output directory.
//!
//! The fits themselves are each model's (`Model::analyze` in its home: the RFM's in
//! `models::rfm::analysis`, the cascade's in `models::cascade::analysis`); they fill an
//! [`Analysis`], which [`Analysis::write`] writes. This module knows no model and no
//! campaign: it imports only `math`, `plot`, `store` and `fsutil`.
//!
//! Only finished runs are analysed, so a campaign that is still running (or was interrupted)
//! is analysed as far as it got, with a warning ([`Analysis::start`]). Replica statistics are
//! recomputed from the run-level tables ([`replica_stat`]; the `*_summary` tables exist only
//! once a campaign is complete): the mean over replicas with its standard error, or with one
//! replica the run's own block error where the table has one.

use std::path::{Path, PathBuf};

use std::sync::Arc;

use arrow_array::{ArrayRef, RecordBatch, StringArray};

use crate::math::stats::mean_sem;
use crate::plot::{self, Figure, Series};
use crate::store::cols::table;
use crate::store::parquet_io::{self, Stamp, StoreError};

/// The fits table.
pub const ANALYSIS_FITS: &str = "analysis_fits";
/// The figure data table.
pub const ANALYSIS_CURVES: &str = "analysis_curves";

/// Settings of the analysis (defaults: the thesis's choices).
#[derive(Clone, Debug)]
pub struct Options {
    /// Smallest N of the exponent fits across N (the thesis drops N < 398 for xi_2).
    pub n_min: f64,
    /// Count errors s_i = factor sqrt(X_i) of the alpha windows (2 for the thesis's dagger
    /// entries of T 5.1).
    pub count_error_factor: f64,
    /// Acceptance chi_r^2 of the alpha windows (1.2; 1.3 for T A.1's dagger entries).
    pub chi2_accept: f64,
    /// D_f used in the fixed-D_f free-path fit (thesis 1.63).
    pub fixed_df: f64,
    /// Draw figures.
    pub figures: bool,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            n_min: 398.0,
            count_error_factor: 1.0,
            chi2_accept: 1.2,
            fixed_df: 1.63,
            figures: true,
        }
    }
}

/// One row of `analysis_fits`.
#[derive(Clone, Debug, PartialEq)]
pub struct FitRow {
    pub quantity: String,
    pub key: String,
    pub value: f64,
    pub error: Option<f64>,
    pub chi2_reduced: Option<f64>,
    pub n_points: u32,
    pub window: String,
    /// A reference value where one exists (zeta_m: the uniform bisection ln(1+m)/ln 2).
    pub reference: Option<f64>,
    /// Free parameters of the fit the row comes from (2 for a power law, the default; 0 for
    /// a number that is no fit): what the statistical checks of [`FitRow::flags`] count
    /// against. Not a column.
    pub n_params: u32,
    /// Why the row is not a result (empty: it is). Set by [`Analysis::write`] from the
    /// fit's statistics ([`statistical_flags`]) and the model's own checks of the window
    /// ([`FitRow::outside`]). The column `quality` is [`FitRow::quality`].
    pub flags: Vec<Flag>,
}

/// Why a fit is not a result: its kind, a short form (the summary's mark), the full reason
/// (the `quality` column) and what to do (the warning).
#[derive(Clone, Debug, PartialEq)]
pub struct Flag {
    pub kind: FlagKind,
    pub short: String,
    pub reason: String,
    pub advice: String,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlagKind {
    /// chi^2_r above the 99.9 % quantile of chi^2(dof)/dof: the law does not describe the data.
    PoorFit,
    /// The window is outside the law's validity, or too small to judge the fit.
    Window,
}

impl FlagKind {
    /// The name in the `quality` column.
    pub fn name(self) -> &'static str {
        match self {
            FlagKind::PoorFit => "poor_fit",
            FlagKind::Window => "window",
        }
    }
    /// The name in the printed summary.
    pub fn words(self) -> &'static str {
        match self {
            FlagKind::PoorFit => "poor fit",
            FlagKind::Window => "window",
        }
    }
}

impl FitRow {
    /// The fit has `k` free parameters (default 2).
    pub fn params(&mut self, k: u32) -> &mut Self {
        self.n_params = k;
        self
    }

    /// The fit's window is outside its law's validity: `short` for the summary's mark,
    /// `reason` for the `quality` column, `advice` (what to do) for the warning.
    pub fn outside(
        &mut self,
        short: impl Into<String>,
        reason: impl Into<String>,
        advice: impl Into<String>,
    ) -> &mut Self {
        self.flags.push(Flag {
            kind: FlagKind::Window,
            short: short.into(),
            reason: reason.into(),
            advice: advice.into(),
        });
        self
    }

    /// The `quality` column: "ok", or the flags' `kind: reason`, joined by "; ".
    pub fn quality(&self) -> String {
        if self.flags.is_empty() {
            return "ok".into();
        }
        self.flags
            .iter()
            .map(|f| format!("{}: {}", f.kind.name(), f.reason))
            .collect::<Vec<_>>()
            .join("; ")
    }

    /// The summary's mark of a flagged row (`[poor fit: chi2_r 10465]`), empty if none.
    pub fn mark(&self) -> String {
        if self.flags.is_empty() {
            return String::new();
        }
        let m: Vec<String> = self
            .flags
            .iter()
            .map(|f| format!("{}: {}", f.kind.words(), f.short))
            .collect();
        format!("[{}]", m.join("; "))
    }
}

/// z of the standard normal's 99.9 % quantile (one-sided p = 0.001).
const Z_999: f64 = 3.090_232_306_167_813;

/// The largest acceptable reduced chi^2 of a fit with `dof` degrees of freedom: the 99.9 %
/// quantile of chi^2(dof)/dof, so a correct model with correct errors exceeds it with
/// probability 0.001. Computed with the Wilson-Hilferty approximation, (chi^2/k)^(1/3)
/// normal with mean 1 - 2/(9k) and variance 2/(9k): above the exact quantile by 3 % at
/// k = 1 (11.16 for 10.83), 1.2 % at 5, 0.6 % at 10, 0.04 % at 100 (a slightly lenient
/// threshold). `None` for dof 0 (nothing to judge).
pub fn chi2_reduced_limit(dof: u32) -> Option<f64> {
    if dof == 0 {
        return None;
    }
    let v = 2.0 / (9.0 * dof as f64);
    Some((1.0 - v + Z_999 * v.sqrt()).powi(3))
}

/// The flags a fit earns by its statistics alone, knowing no law: fewer points than
/// parameters + 2 (no residual freedom to judge it), a standard error of exactly 0, a
/// reduced chi^2 above [`chi2_reduced_limit`]. None for a row that is no fit (0 parameters).
pub fn statistical_flags(row: &FitRow) -> Vec<Flag> {
    let mut v = Vec::new();
    let k = row.n_params;
    if k == 0 {
        return v;
    }
    if row.n_points < k + 2 {
        v.push(Flag {
            kind: FlagKind::Window,
            short: format!("{} points", row.n_points),
            reason: format!(
                "{} points for {k} parameters (fewer than {}: no residual freedom to judge the fit)",
                row.n_points,
                k + 2
            ),
            advice: "widen the window or add points (more N values, a larger box, longer \
                     sampling)"
                .into(),
        });
    } else if row.error == Some(0.0) {
        v.push(Flag {
            kind: FlagKind::Window,
            short: "error 0".into(),
            reason: "standard error exactly 0 (a fit with no residual freedom)".into(),
            advice: "widen the window or add points".into(),
        });
    }
    let dof = row.n_points.saturating_sub(k);
    if let (Some(chi), Some(limit)) = (row.chi2_reduced, chi2_reduced_limit(dof)) {
        if chi > limit {
            v.push(Flag {
                kind: FlagKind::PoorFit,
                short: format!("chi2_r {}", num_sig(chi)),
                reason: format!(
                    "chi2_r {} > {limit:.3} (p < 0.001 for {dof} dof)",
                    num_sig(chi)
                ),
                advice: "the law does not describe these data in this window: the window may \
                         be outside the law's range; check the parameters against the \
                         thesis's (docs: Analysis) or change the window"
                    .into(),
            });
        }
    }
    v
}

/// A chi^2 for messages: 4 significant digits (integers from 1000 on, an exponent from 1e6).
fn num_sig(v: f64) -> String {
    let a = v.abs();
    if !v.is_finite() || a >= 1e6 {
        return format!("{v:.3e}");
    }
    if a >= 1000.0 {
        return format!("{v:.0}");
    }
    let decimals = if a > 0.0 {
        (3 - a.log10().floor() as i32).clamp(0, 6) as usize
    } else {
        0
    };
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// One row of `analysis_curves`.
#[derive(Clone, Debug)]
pub struct CurveRow {
    pub figure: String,
    pub series: String,
    pub x: f64,
    pub y: f64,
    pub error: Option<f64>,
}

/// What an analysis produced.
#[derive(Default)]
pub struct Report {
    pub fits: Vec<FitRow>,
    pub curves: Vec<CurveRow>,
    pub warnings: Vec<String>,
    pub files: Vec<PathBuf>,
    /// Finished (done) runs used, and runs in the campaign.
    pub runs_done: u64,
    pub runs_total: u64,
}

#[derive(Debug, thiserror::Error)]
pub enum AnalysisError {
    /// The campaign cannot be analysed (another model, no finished runs, missing tables).
    #[error("{0}")]
    NotAnalysable(String),
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error("{0}")]
    Io(String),
}

/// Mean and standard error over replicas; with one replica its own error (if any).
pub fn replica_stat(v: &[(f64, Option<f64>)]) -> (f64, Option<f64>) {
    match v.len() {
        0 => (f64::NAN, None),
        1 => v[0],
        n => {
            let xs: Vec<f64> = v.iter().map(|x| x.0).collect();
            let (m, s) = mean_sem(&xs);
            debug_assert_eq!(xs.len(), n);
            (m, s)
        }
    }
}

/// Short number text for keys: up to 4 significant digits.
pub fn num(v: f64) -> String {
    let s = format!("{:.4}", v);
    let s = s.trim_end_matches('0').trim_end_matches('.').to_string();
    if s.is_empty() || s == "-" {
        "0".into()
    } else {
        s
    }
}

/// File-name-safe version of a key.
pub fn slug(key: &str) -> String {
    key.chars()
        .map(|ch| {
            if ch.is_ascii_alphanumeric() || ch == '.' || ch == '-' {
                ch
            } else {
                '_'
            }
        })
        .collect()
}

/// An analysis in progress: what a model's `analyze` fills (fits, figures and their data,
/// warnings), then [`Analysis::write`] writes.
pub struct Analysis {
    /// The campaign's name (figure titles, the tables' `campaign` column).
    name: String,
    pub opts: Options,
    pub report: Report,
    figs: Vec<(String, Figure)>,
}

impl Analysis {
    /// A new analysis of campaign `name`, of which `runs_done` of `runs_total` runs are
    /// finished.
    pub fn new(name: &str, opts: &Options, runs_done: u64, runs_total: u64) -> Self {
        Analysis {
            name: name.to_string(),
            opts: opts.clone(),
            report: Report {
                runs_done,
                runs_total,
                ..Default::default()
            },
            figs: Vec::new(),
        }
    }

    /// Where every model's analysis begins: refused without a finished run, a warning when
    /// only some are finished.
    pub fn start(&mut self) -> Result<(), AnalysisError> {
        let (done, total) = (self.report.runs_done, self.report.runs_total);
        if done == 0 {
            return Err(AnalysisError::NotAnalysable(
                "no finished runs yet; nothing to analyse".into(),
            ));
        }
        if done < total {
            self.warn(format!(
                "only {done} of {total} runs are finished (done); analysing those"
            ));
        }
        Ok(())
    }

    /// Record one row of `analysis_fits` (non-finite errors and chi^2 as null).
    #[allow(clippy::too_many_arguments)]
    pub fn fit(
        &mut self,
        quantity: impl Into<String>,
        key: &str,
        value: f64,
        error: Option<f64>,
        chi2_reduced: Option<f64>,
        n_points: usize,
        window: impl Into<String>,
        reference: Option<f64>,
    ) -> &mut FitRow {
        self.report.fits.push(FitRow {
            quantity: quantity.into(),
            key: key.into(),
            value,
            error: error.filter(|e| e.is_finite()),
            chi2_reduced: chi2_reduced.filter(|e| e.is_finite()),
            n_points: n_points as u32,
            window: window.into(),
            reference,
            n_params: 2,
            flags: Vec::new(),
        });
        let last = self.report.fits.len() - 1;
        &mut self.report.fits[last]
    }

    /// Judge every fit ([`statistical_flags`] after the model's own flags) and warn once per
    /// flagged fit, naming the quantity, the reasons and what to do.
    fn judge(&mut self) {
        let mut warnings = Vec::new();
        for f in &mut self.report.fits {
            let stats = statistical_flags(f);
            f.flags.extend(stats);
            if f.flags.is_empty() {
                continue;
            }
            let mut advice: Vec<&str> = Vec::new();
            for fl in &f.flags {
                if !advice.contains(&fl.advice.as_str()) {
                    advice.push(&fl.advice);
                }
            }
            warnings.push(format!(
                "{} [{}] = {} is flagged, not a result: {}. What to do: {}",
                f.quantity,
                f.key,
                num(f.value),
                f.quality(),
                advice.join("; ")
            ));
        }
        for w in warnings {
            self.warn(w);
        }
    }
    pub fn warn(&mut self, w: String) {
        tracing::warn!("{w}");
        self.report.warnings.push(w);
    }
    /// Record a figure and its data in `analysis_curves`.
    pub fn figure(&mut self, name: String, plot: Figure) {
        for s in &plot.series {
            for p in &s.points {
                self.report.curves.push(CurveRow {
                    figure: name.clone(),
                    series: s.label.clone(),
                    x: p.0,
                    y: p.1,
                    error: (p.2 > 0.0).then_some(p.2),
                });
            }
        }
        self.figs.push((name, plot));
    }

    /// A figure's title: the campaign's name, then `what`.
    pub fn title(&self, what: &str) -> String {
        format!("{} - {what}", self.name)
    }

    /// Write the tables `analysis_fits.parquet` and `analysis_curves.parquet` into `out`
    /// (atomically, stamped with `stamp`) and, unless the options say otherwise, the figures
    /// under `out/figures`; the report lists the files.
    pub fn write(mut self, out: &Path, stamp: Stamp<'_>) -> Result<Report, AnalysisError> {
        if self.report.fits.is_empty() {
            self.warn(
                "no fit was possible (too few points or observables; see the warnings above)"
                    .into(),
            );
        }
        self.judge();
        std::fs::create_dir_all(out)
            .map_err(|e| AnalysisError::Io(format!("{}: {e}", out.display())))?;
        let fits = fits_batch(&self.name, &self.report.fits);
        write_table(out, ANALYSIS_FITS, &fits, stamp)?;
        self.report
            .files
            .push(out.join(format!("{ANALYSIS_FITS}.parquet")));
        let curves = curves_batch(&self.name, &self.report.curves);
        write_table(out, ANALYSIS_CURVES, &curves, stamp)?;
        self.report
            .files
            .push(out.join(format!("{ANALYSIS_CURVES}.parquet")));
        if self.opts.figures && !self.figs.is_empty() {
            let dir = out.join("figures");
            let (files, failed) =
                plot::render(&self.figs, &dir).map_err(|e| AnalysisError::Io(e.to_string()))?;
            self.report.files.extend(files);
            for f in failed {
                self.warn(f);
            }
        }
        Ok(self.report)
    }
}

fn write_table(
    out: &Path,
    table: &str,
    batch: &RecordBatch,
    stamp: Stamp<'_>,
) -> Result<(), AnalysisError> {
    let path = out.join(format!("{table}.parquet"));
    let tmp = crate::fsutil::temp_path(&path);
    parquet_io::write_file(&tmp, batch, table, stamp)?;
    std::fs::rename(&tmp, &path)
        .map_err(|e| AnalysisError::Io(format!("{}: {e}", path.display())))?;
    crate::fsutil::sync_dir(out).map_err(|e| AnalysisError::Io(format!("{}: {e}", out.display())))
}

fn fits_batch(campaign: &str, rows: &[FitRow]) -> RecordBatch {
    table(rows, |c| {
        vec![
            c.const_str("campaign", campaign),
            c.str("quantity", |r| &r.quantity),
            c.str("key", |r| &r.key),
            c.f64("value", |r| r.value),
            c.opt_f64("error", |r| r.error),
            c.opt_f64("chi2_reduced", |r| r.chi2_reduced),
            c.u32("n_points", |r| r.n_points),
            c.str("window", |r| &r.window),
            c.opt_f64("reference", |r| r.reference),
            c.array("quality", false, |v: &[FitRow]| {
                Arc::new(v.iter().map(|r| Some(r.quality())).collect::<StringArray>()) as ArrayRef
            }),
        ]
    })
}

fn curves_batch(campaign: &str, rows: &[CurveRow]) -> RecordBatch {
    table(rows, |c| {
        vec![
            c.const_str("campaign", campaign),
            c.str("figure", |r| &r.figure),
            c.str("series", |r| &r.series),
            c.f64("x", |r| r.x),
            c.f64("y", |r| r.y),
            c.opt_f64("error", |r| r.error),
        ]
    })
}

/// A fitted power law drawn over [x0, x1] as a line series.
pub fn line(label: String, x0: f64, x1: f64, f: impl Fn(f64) -> f64) -> Series {
    let points = (0..=40)
        .map(|j| {
            let x = x0 * (x1 / x0).powf(j as f64 / 40.0);
            (x, f(x), 0.0)
        })
        .collect();
    Series {
        label,
        points,
        line: true,
    }
}

pub fn fig(title: String, x: &str, y: &str, series: Vec<Series>) -> Figure {
    Figure::new(title, x, y, series)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_and_slugs() {
        assert_eq!(num(0.53), "0.53");
        assert_eq!(num(0.1000001), "0.1");
        assert_eq!(num(3000.0), "3000");
        assert_eq!(slug("phi=0.53,L=0.2"), "phi_0.53_L_0.2");
        assert_eq!(replica_stat(&[(2.0, Some(0.1))]), (2.0, Some(0.1)));
        let (m, s) = replica_stat(&[(1.0, Some(9.0)), (3.0, None)]);
        assert_eq!(m, 2.0);
        assert!((s.unwrap() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn fits_table_schema() {
        let b = fits_batch(
            "c",
            &[FitRow {
                quantity: "xi_2".into(),
                key: "eps=0.1".into(),
                value: 0.53,
                error: Some(0.01),
                chi2_reduced: None,
                n_points: 5,
                window: "N in [398, 10000]".into(),
                reference: None,
                n_params: 2,
                flags: Vec::new(),
            }],
        );
        assert_eq!(b.num_rows(), 1);
        let names: Vec<&str> = b
            .schema_ref()
            .fields()
            .iter()
            .map(|f| f.name().as_str())
            .collect();
        assert_eq!(
            names,
            [
                "campaign",
                "quantity",
                "key",
                "value",
                "error",
                "chi2_reduced",
                "n_points",
                "window",
                "reference",
                "quality"
            ]
        );
        let q = b.column_by_name("quality").unwrap();
        let q = arrow_array::cast::AsArray::as_string::<i32>(q);
        assert_eq!(q.value(0), "ok");
    }

    /// The 99.9 % quantile of chi^2(k)/k against exact values (chi^2_0.999(k): 10.828 at 1,
    /// 20.515 at 5, 29.588 at 10, 149.449 at 100): Wilson-Hilferty's within 3.1 % at k = 1,
    /// 1.2 % at 5, 0.7 % at 10, 0.1 % at 100; it falls towards 1 as k grows; none for k = 0.
    #[test]
    fn chi2_limit_is_the_999_quantile() {
        assert_eq!(chi2_reduced_limit(0), None);
        for (k, exact) in [(1u32, 10.828), (5, 20.515), (10, 29.588), (100, 149.449)] {
            let got = chi2_reduced_limit(k).unwrap() * k as f64;
            let tol = match k {
                1 => 0.031,
                5 => 0.012,
                10 => 0.007,
                _ => 0.001,
            };
            assert!((got / exact - 1.0).abs() < tol, "k = {k}: {got} vs {exact}");
        }
        let l: Vec<f64> = [1, 2, 5, 20, 156, 10_000]
            .iter()
            .map(|&k| chi2_reduced_limit(k).unwrap())
            .collect();
        assert!(
            l.windows(2).all(|w| w[0] > w[1]) && l[5] > 1.0 && l[5] < 1.05,
            "{l:?}"
        );
    }

    fn row(n_points: u32, error: Option<f64>, chi: Option<f64>) -> FitRow {
        FitRow {
            quantity: "C_R_exponent".into(),
            key: "k".into(),
            value: 2.1411,
            error,
            chi2_reduced: chi,
            n_points,
            window: "w".into(),
            reference: None,
            n_params: 2,
            flags: Vec::new(),
        }
    }

    /// The fit (chi2_r 10465 over 7 points: 5 dof) is a poor fit; one at the 99.8 %
    /// quantile is not; too few points or an error of exactly 0 flag the window; a number
    /// that is no fit (0 parameters) is never judged; a model's own window flag comes first.
    #[test]
    fn fits_flagged_by_their_statistics() {
        let f = statistical_flags(&row(7, Some(0.01), Some(10465.0)));
        assert_eq!(f.len(), 1);
        assert_eq!(f[0].kind, FlagKind::PoorFit);
        assert_eq!(
            f[0].reason, "chi2_r 10465 > 4.150 (p < 0.001 for 5 dof)",
            "{f:?}"
        );
        assert_eq!(f[0].short, "chi2_r 10465");
        // chi^2_0.998(5) / 5 = 3.78: accepted.
        assert!(statistical_flags(&row(7, Some(0.01), Some(3.78))).is_empty());
        assert!(statistical_flags(&row(7, Some(0.01), None)).is_empty());
        let f = statistical_flags(&row(3, Some(0.01), None));
        assert_eq!((f.len(), f[0].kind), (1, FlagKind::Window));
        assert!(
            f[0].reason.starts_with("3 points for 2 parameters"),
            "{f:?}"
        );
        let f = statistical_flags(&row(10, Some(0.0), Some(1.0)));
        assert_eq!((f.len(), f[0].kind), (1, FlagKind::Window));
        assert!(f[0].reason.contains("exactly 0"), "{f:?}");
        let mut r = row(2, Some(0.0), Some(1e9));
        r.params(0);
        assert!(statistical_flags(&r).is_empty());
        let mut r = row(7, Some(0.01), Some(10465.0));
        r.outside("L < L_min", "L = 0.1 m < L_min = 1 m", "use a larger box");
        r.flags.extend(statistical_flags(&r));
        assert_eq!(
            r.quality(),
            "window: L = 0.1 m < L_min = 1 m; poor_fit: chi2_r 10465 > 4.150 (p < 0.001 for 5 dof)"
        );
        assert_eq!(r.mark(), "[window: L < L_min; poor fit: chi2_r 10465]");
        assert_eq!(row(7, None, None).quality(), "ok");
        assert_eq!(row(7, None, None).mark(), "");
    }
}
