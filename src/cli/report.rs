//! `granular report DIR [--out FILE]`: one self-contained HTML page of a campaign (finished
//! or not): progress per point, failed runs, the standard figures as inline SVG, what
//! `granular analyze` wrote (tables and figures), the manifest and its history.

use std::path::PathBuf;

use super::{fail, report_error};
use crate::campaign::Campaign;
use crate::exit_codes;

#[derive(clap::Args)]
pub struct Args {
    dir: PathBuf,
    /// Where to write the page (default: DIR/report.html).
    #[arg(long)]
    out: Option<PathBuf>,
}

pub fn run(a: Args) -> i32 {
    let c = match Campaign::open(&a.dir) {
        Ok(c) => c,
        Err(e) => return report_error(e),
    };
    let r = match crate::report::build(&c) {
        Ok(r) => r,
        Err(e) => return report_error(e),
    };
    for n in &r.notes {
        tracing::warn!("{n}");
    }
    let out = a.out.unwrap_or_else(|| a.dir.join("report.html"));
    if let Err(e) = crate::fsutil::write_atomic(&out, r.html.as_bytes()) {
        return fail(exit_codes::IO_ERROR, format!("{}: {e}", out.display()));
    }
    let analysis = if r.analysis_figures > 0 {
        format!(", {} analysis figures", r.analysis_figures)
    } else {
        String::new()
    };
    outln!(
        "wrote {} ({} figures{analysis}, {} bytes)",
        out.display(),
        r.figures,
        r.html.len()
    );
    exit_codes::OK
}
