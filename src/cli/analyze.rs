//! `granular analyze DIR [--out ADIR]`: the thesis's fits of a campaign, by its model
//! (`Campaign::analyze`: rfm, cascade).

use std::io::Write;
use std::path::{Path, PathBuf};

use super::{exit_code, fail, failed, flags, report_error};
use crate::analysis::{AnalysisError, Options};
use crate::campaign::Campaign;
use crate::exit_codes;
use crate::exit_codes::Classed;

#[derive(clap::Args)]
pub struct Args {
    dir: PathBuf,
    /// Where to write analysis_fits.parquet, analysis_curves.parquet and figures/
    /// (default: DIR/analysis).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Smallest N of the velocity-moment exponent fits across N (the thesis drops N < 398);
    /// 0 to 1e9.
    #[arg(long, value_name = "N", default_value_t = Options::default().n_min, allow_hyphen_values = true,
          value_parser = flags::n_min)]
    n_min: f64,
    /// Count errors s = FACTOR sqrt(X) in the alpha windows (2 for the thesis's dagger
    /// entries); > 0 and <= 100.
    #[arg(long, value_name = "FACTOR", default_value_t = Options::default().count_error_factor, allow_hyphen_values = true,
          value_parser = flags::count_error_factor)]
    count_error_factor: f64,
    /// Accept alpha when the reduced chi^2 is below this (> 0 and <= 1000).
    #[arg(long, value_name = "CHI2", default_value_t = Options::default().chi2_accept, allow_hyphen_values = true,
          value_parser = flags::chi2_accept)]
    chi2_accept: f64,
    /// D_f of the fixed-D_f free-path fit (4.25) (> 0 and <= 2).
    #[arg(long, value_name = "D_F", default_value_t = Options::default().fixed_df, allow_hyphen_values = true,
          value_parser = flags::fixed_df)]
    fixed_df: f64,
    /// Write the tables only.
    #[arg(long)]
    no_figures: bool,
}

pub fn run(a: Args) -> i32 {
    let c = match Campaign::open(&a.dir) {
        Ok(c) => c,
        Err(e) => return report_error(e),
    };
    if let Err(code) = super::tables_checked(&c, crate::campaign::integrity::Depth::Full) {
        return code;
    }
    let out = a.out.unwrap_or_else(|| c.analysis_dir());
    let opts = Options {
        n_min: a.n_min,
        count_error_factor: a.count_error_factor,
        chi2_accept: a.chi2_accept,
        fixed_df: a.fixed_df,
        figures: !a.no_figures,
    };
    match c.analyze(&out, &opts) {
        Ok(r) => {
            print_fits(&c, &out, &r);
            exit_codes::OK
        }
        Err(e @ AnalysisError::NotAnalysable(_)) => {
            fail(exit_code(e.class()), format!("{}: {e}", c.root.display()))
        }
        Err(e) => failed(&e),
    }
}

fn print_fits(c: &Campaign, out: &Path, r: &crate::analysis::Report) {
    // Write errors (a closed pipe, `| head`) are not worth a panic.
    let mut o = std::io::stdout().lock();
    let flagged = r.fits.iter().filter(|f| !f.flags.is_empty()).count();
    let flagged = if flagged > 0 {
        format!(" ({flagged} flagged [..]: not results, see the warnings)")
    } else {
        String::new()
    };
    let _ = writeln!(
        o,
        "{}: {} fits{flagged} from {} of {} runs; {} files in {}",
        c.manifest.name,
        r.fits.len(),
        r.runs_done,
        r.runs_total,
        r.files.len(),
        out.display()
    );
    for f in &r.fits {
        let err = f.error.map_or("".into(), |e| format!(" +- {e:.4}"));
        let chi = f
            .chi2_reduced
            .map_or("".into(), |x| format!("  chi2_r {x:.2}"));
        let reference = f
            .reference
            .map_or("".into(), |x| format!("  (reference {x:.4})"));
        // A flagged fit is marked (`[poor fit: chi2_r 10465]`): it is not a result.
        let mark = f.mark();
        let mark = if mark.is_empty() {
            mark
        } else {
            format!("  {mark}")
        };
        let _ = writeln!(
            o,
            "  {:<22} {:<40} {:>10.4}{err}{chi}  n {}{reference}{mark}",
            f.quantity, f.key, f.value, f.n_points
        );
    }
}
