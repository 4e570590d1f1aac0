//! `granular plot DIR [--out FIGDIR]`: the standard figures of a campaign (its model's
//! `figures`: from the summary tables, or the run tables of the models without summaries).

use std::path::PathBuf;

use super::{fail, failed, report_error};
use crate::campaign::Campaign;
use crate::exit_codes;

#[derive(clap::Args)]
pub struct Args {
    dir: PathBuf,
    /// Where to write the figures (default: DIR/figures).
    #[arg(long)]
    out: Option<PathBuf>,
}

pub fn run(a: Args) -> i32 {
    let c = match Campaign::open(&a.dir) {
        Ok(c) => c,
        Err(e) => return report_error(e),
    };
    if let Err(code) = super::tables_checked(&c, crate::campaign::integrity::Depth::Quick) {
        return code;
    }
    let out = a.out.unwrap_or_else(|| a.dir.join("figures"));
    let figs = match c.figures() {
        Ok(Some(figs)) => figs,
        Ok(None) => {
            return fail(
                exit_codes::INVALID_INPUT,
                format!(
                    "`granular plot` draws no figures of model {}",
                    c.plan.model.as_str()
                ),
            )
        }
        Err(e) => return failed(&e),
    };
    match crate::plot::render(&figs, &out) {
        Ok((files, failed)) => {
            for f in failed {
                tracing::warn!("{f}");
            }
            outln!("wrote {} files to {}", files.len(), out.display());
            exit_codes::OK
        }
        Err(e) => failed(&e),
    }
}
