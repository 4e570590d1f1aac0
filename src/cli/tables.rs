//! `granular tables DIR [--json]`: the campaign's tables, for programs and people: each table's
//! name, what a row is, whether it is written, the directory to read (its generation link
//! resolved inside the campaign directory, never followed out of it), its files, rows (from the
//! Parquet footers only) and columns.

use std::io::Write;
use std::path::PathBuf;

use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use serde_json::{json, Value};

use super::report_error;
use crate::campaign::integrity::{self, Depth};
use crate::campaign::Campaign;
use crate::exit_codes;
use crate::fsutil::{Dir, Kind};
use crate::store::layout::{generation_of, GEN_DIR};

#[derive(clap::Args)]
pub struct Args {
    dir: PathBuf,
    /// Print one JSON object on stdout: {"dir", "name", "model", "tables": [{"name",
    /// "description", "written", "path" (relative to DIR; null when not written or refused),
    /// "files", "rows", "columns": [{"name", "type"}], "error" (only where the table cannot
    /// be read: a link out of DIR, an unreadable file)}]}.
    #[arg(long)]
    json: bool,
}

/// One table as listed.
struct Entry {
    name: String,
    description: &'static str,
    /// The directory (or file) to read, relative to the campaign directory.
    path: Option<String>,
    files: u64,
    rows: u64,
    columns: Vec<(String, String)>,
    error: Option<String>,
}

impl Entry {
    fn new(name: &str, description: &'static str) -> Entry {
        Entry {
            name: name.to_string(),
            description,
            path: None,
            files: 0,
            rows: 0,
            columns: Vec::new(),
            error: None,
        }
    }

    fn written(&self) -> bool {
        self.files > 0
    }

    fn to_json(&self) -> Value {
        let columns: Vec<Value> = self
            .columns
            .iter()
            .map(|(n, t)| json!({"name": n, "type": t}))
            .collect();
        let mut v = json!({
            "name": self.name,
            "description": self.description,
            "written": self.written(),
            "path": self.path,
            "files": self.files,
            "rows": self.rows,
            "columns": columns,
        });
        if let Some(e) = &self.error {
            v["error"] = json!(e);
        }
        v
    }
}

pub fn run(a: Args) -> i32 {
    let c = match Campaign::open(&a.dir) {
        Ok(c) => c,
        Err(e) => return report_error(e),
    };
    // The quick check `status` makes (presence and sizes against the ledger).
    let found = match integrity::check(&c, Depth::Quick) {
        Ok(f) => f,
        Err(e) => return report_error(e),
    };
    let entries = match list(&c) {
        Ok(v) => v,
        Err(e) => {
            return super::fail(
                exit_codes::IO_ERROR,
                format_args!("{}: {e}", a.dir.display()),
            )
        }
    };
    let mut out = super::Stdout;
    let _ = if a.json {
        let tables: Vec<Value> = entries.iter().map(Entry::to_json).collect();
        writeln!(
            out,
            "{}",
            json!({
                "dir": a.dir.display().to_string(),
                "name": c.manifest.name,
                "model": c.plan.model.as_str(),
                "tables": tables,
            })
        )
    } else {
        write_text(&mut out, &entries)
    };
    if found.clean() {
        return exit_codes::OK;
    }
    super::refuse_damage(&a.dir, &found.problems())
}

/// Every table the campaign has (`Campaign::tables`) and those of `granular analyze` in
/// `DIR/analysis/` when it wrote them.
fn list(c: &Campaign) -> std::io::Result<Vec<Entry>> {
    let root = Dir::open(&c.root)?;
    let describe = |name: &str| c.table_description(name).unwrap_or("");
    let tables = root.sub("tables");
    let mut out = Vec::new();
    for name in c.tables() {
        let mut e = Entry::new(name, describe(name));
        match &tables {
            Ok(Some(t)) => table_dir(t, &mut e),
            Ok(None) => {}
            Err(why) => e.error = Some(format!("tables: {why}; not followed")),
        }
        out.push(e);
    }
    let analysis = crate::campaign::ANALYSIS_DIR;
    let adir = root.sub(analysis);
    for name in [
        crate::analysis::ANALYSIS_FITS,
        crate::analysis::ANALYSIS_CURVES,
    ] {
        let file = format!("{name}.parquet");
        let mut e = Entry::new(name, describe(name));
        match &adir {
            Ok(None) => continue,
            Ok(Some(d)) => match d.kind(&file)? {
                None => continue,
                Some(Kind::File) => {
                    e.path = Some(format!("{analysis}/{file}"));
                    count_file(d, &file, &mut e);
                }
                Some(k) => {
                    e.error = Some(format!(
                        "{analysis}/{file}: {}; not read",
                        d.describe(&file, k)
                    ))
                }
            },
            Err(why) => e.error = Some(format!("{analysis}: {why}; not followed")),
        }
        out.push(e);
    }
    Ok(out)
}

/// The directory of table `e.name` under the opened `tables/`: a plain directory, or
/// granular's generation link (its target must read `.gen/<table>.<n>`, opened as such under
/// `tables/` without following any other link); anything else is an error, never followed.
fn table_dir(tables: &Dir, e: &mut Entry) {
    let name = e.name.clone();
    let opened = match tables.kind(&name) {
        Ok(None) => return,
        Ok(Some(Kind::Dir)) => tables
            .sub(&name)
            .map(|d| d.map(|d| (d, format!("tables/{name}")))),
        Ok(Some(Kind::Link)) => match tables.read_link(&name) {
            Ok(target) => match generation_of(&name, &target) {
                Some((_, gen)) => tables.sub(GEN_DIR).and_then(|g| match g {
                    Some(g) => Ok(g.sub(&gen)?.map(|d| (d, format!("tables/{GEN_DIR}/{gen}")))),
                    None => Ok(None),
                }),
                None => {
                    e.error = Some(format!(
                        "tables/{name} is a symbolic link to {}, not to a generation of the table ({GEN_DIR}/{name}.<n>); not followed",
                        target.display()
                    ));
                    return;
                }
            },
            Err(why) => Err(why),
        },
        Ok(Some(k)) => {
            e.error = Some(format!(
                "tables/{name} is {}, not a table directory",
                tables.describe(&name, k)
            ));
            return;
        }
        Err(why) => Err(why),
    };
    let (dir, path) = match opened {
        Ok(Some(x)) => x,
        // A generation link whose generation is not there: nothing to read.
        Ok(None) => return,
        Err(why) => {
            e.error = Some(format!("tables/{name}: {why}; not followed"));
            return;
        }
    };
    e.path = Some(path);
    let files = match dir.entries() {
        Ok(v) => v,
        Err(why) => {
            e.error = Some(format!("tables/{name}: {why}"));
            return;
        }
    };
    for (f, k) in files {
        if k == Kind::File && !f.starts_with('.') && f.ends_with(".parquet") {
            count_file(&dir, &f, e);
        }
    }
}

/// Add the Parquet file `name` of `dir` to `e`: one file, its footer's row count, and the
/// columns of the first file (its Arrow schema). Only the footer is read.
fn count_file(dir: &Dir, name: &str, e: &mut Entry) {
    let read = || -> Result<(u64, Vec<(String, String)>), String> {
        let f = dir
            .open_file(name)
            .map_err(|why| why.to_string())?
            .ok_or_else(|| "gone".to_string())?;
        let b = ParquetRecordBatchReaderBuilder::try_new(f).map_err(|why| why.to_string())?;
        let rows = b.metadata().file_metadata().num_rows().max(0) as u64;
        let columns = b
            .schema()
            .fields()
            .iter()
            .map(|f| (f.name().clone(), f.data_type().to_string()))
            .collect();
        Ok((rows, columns))
    };
    match read() {
        Ok((rows, columns)) => {
            e.files += 1;
            e.rows += rows;
            if e.columns.is_empty() {
                e.columns = columns;
            }
        }
        Err(why) => {
            let at = e.path.as_deref().unwrap_or("");
            let msg = format!("{at}/{name}: not a readable Parquet file: {why}");
            e.error.get_or_insert(msg);
        }
    }
}

fn write_text(out: &mut impl Write, entries: &[Entry]) -> std::io::Result<()> {
    let w = entries
        .iter()
        .map(|e| e.name.len())
        .max()
        .unwrap_or(4)
        .max(5);
    let rows: Vec<String> = entries
        .iter()
        .map(|e| {
            if e.path.is_none() && e.error.is_some() {
                "-".into()
            } else {
                e.rows.to_string()
            }
        })
        .collect();
    let rw = rows.iter().map(String::len).max().unwrap_or(4).max(4);
    writeln!(
        out,
        "{:<w$}  {:>rw$}  {:>5}  description",
        "table", "rows", "files"
    )?;
    for (e, r) in entries.iter().zip(&rows) {
        let files = if e.path.is_none() && e.error.is_some() {
            "-".to_string()
        } else {
            e.files.to_string()
        };
        let what = match &e.error {
            Some(err) => format!("error: {err}"),
            None if !e.written() => format!("(not written) {}", e.description),
            None => e.description.to_string(),
        };
        writeln!(out, "{:<w$}  {r:>rw$}  {files:>5}  {what}", e.name)?;
    }
    Ok(())
}
