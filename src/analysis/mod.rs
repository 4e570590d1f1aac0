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

use arrow_array::RecordBatch;

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
    ) {
        self.report.fits.push(FitRow {
            quantity: quantity.into(),
            key: key.into(),
            value,
            error: error.filter(|e| e.is_finite()),
            chi2_reduced: chi2_reduced.filter(|e| e.is_finite()),
            n_points: n_points as u32,
            window: window.into(),
            reference,
        });
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
                "reference"
            ]
        );
    }
}
