//! `granular verify`: every committed file matches its commit's size and SHA-256 and every
//! rebuilt table its sidecar (a full scrub; `--quick`: sizes only), no part is without a
//! commit and no run in two (see `integrity`); every table file is readable, of this campaign,
//! table and format; uncommitted (`.pending`) parts of dead writers are reported; the `runs`
//! table holds every committed run exactly once (nothing lost, nothing doubled). Links where
//! granular keeps its own files are named (see `integrity`) and never followed: the tables
//! are read through granular's own generation links only, their regular files only.

use std::collections::BTreeMap;

use super::error::CampaignError;
use super::integrity::{self, Depth};
use super::{ledger, tables, Campaign};
use crate::fsutil::{Dir, Kind};
use crate::store::{layout, parquet_io};

#[derive(Debug, Default)]
pub struct VerifyReport {
    /// (table, files, rows)
    pub tables: Vec<(String, usize, u64)>,
    pub committed_runs: usize,
    /// Committed files checked against the ledger, and their bytes.
    pub files_checked: usize,
    pub bytes_checked: u64,
    pub problems: Vec<String>,
}

pub fn verify(c: &Campaign, depth: Depth) -> Result<VerifyReport, CampaignError> {
    let mut r = VerifyReport::default();
    let check = integrity::check(c, depth)?;
    if let Some(why) = &check.skipped {
        return Err(CampaignError::Refused(format!(
            "{}: not verified: {why}",
            c.root.display()
        )));
    }
    r.problems = check.problems();
    let finished = ledger::finished_runs(&check.commits);
    r.committed_runs = finished.len();
    r.files_checked = check.commits.iter().map(|c| c.files.len()).sum();
    r.bytes_checked = check
        .commits
        .iter()
        .flat_map(|c| c.files.iter().map(|f| f.bytes))
        .sum();
    if depth == Depth::Quick {
        return Ok(r);
    }
    let live = !ledger::live_locks(&c.root).is_empty();
    let run_counts = scan_tables(c, live, &mut r)?;
    runs_against_ledger(c, live, &finished, &run_counts, &mut r);
    Ok(r)
}

/// Every file of every table: readable, of this campaign, table and format (rows counted per
/// table into `r.tables`); uncommitted parts of stopped writers. How often each run appears
/// in the `runs` table.
fn scan_tables(
    c: &Campaign,
    live: bool,
    r: &mut VerifyReport,
) -> Result<BTreeMap<u64, u32>, CampaignError> {
    let io = |e: &dyn std::fmt::Display| CampaignError::Io(e.to_string());
    let mut run_counts: BTreeMap<u64, u32> = BTreeMap::new();
    let rd =
        Dir::open(&c.root).map_err(|e| CampaignError::Io(format!("{}: {e}", c.root.display())))?;
    for table in layout::table_names(&c.root).map_err(|e| io(&e))? {
        let dir = c.root.join("tables").join(&table);
        let mut files = 0;
        let mut rows = 0u64;
        let Some(d) = layout::open_table(&rd, &table).map_err(|e| io(&e))? else {
            continue;
        };
        let entries = d
            .entries()
            .map_err(|e| CampaignError::Io(format!("{}: {e}", dir.display())))?;
        for (name, kind) in entries {
            let path = dir.join(&name);
            if name.ends_with(".pending") {
                if !live {
                    r.problems.push(format!(
                        "{}: an uncommitted part of a stopped writer (`granular resume` removes or completes it)",
                        path.display()
                    ));
                }
                continue;
            }
            if name.starts_with('.') {
                continue;
            }
            if !name.ends_with(".parquet") || kind != Kind::File {
                continue; // reported by the integrity check
            }
            files += 1;
            let file = TableFile {
                c,
                d: &d,
                table: &table,
                name: &name,
                path: &path,
            };
            match file.inspect() {
                Ok(n) => rows += n,
                Err(e) => {
                    r.problems.push(e.to_string());
                    continue;
                }
            }
            if table == tables::RUNS {
                file.count_runs(&mut run_counts, &mut r.problems);
            }
        }
        r.tables.push((table, files, rows));
    }
    Ok(run_counts)
}

/// One Parquet file of a table, opened without following a link.
struct TableFile<'a> {
    c: &'a Campaign,
    d: &'a Dir,
    table: &'a str,
    name: &'a str,
    path: &'a std::path::Path,
}

impl TableFile<'_> {
    fn open(&self) -> Result<std::fs::File, parquet_io::StoreError> {
        self.d
            .open_file(self.name)
            .map_err(|e| parquet_io::open_error(self.path, e))?
            .ok_or_else(|| {
                parquet_io::StoreError::io(self.path, std::io::ErrorKind::NotFound.into())
            })
    }

    /// Its rows, if it is readable and of this campaign, table and format.
    fn inspect(&self) -> Result<u64, parquet_io::StoreError> {
        let (info, _) = parquet_io::inspect_file(self.open()?, self.path)?;
        parquet_io::check_part(self.path, &info, self.table, Some(&self.c.identity))?;
        Ok(info.rows)
    }

    /// Count the runs of a `runs` file into `run_counts`; what cannot be read into
    /// `problems`.
    fn count_runs(&self, run_counts: &mut BTreeMap<u64, u32>, problems: &mut Vec<String>) {
        let read = self.open().and_then(|f| {
            parquet_io::read_campaign_opened(f, self.path, self.table, &self.c.identity)
        });
        let batches = match read {
            Ok(b) => b,
            Err(e) => return problems.push(e.to_string()),
        };
        for b in batches {
            let ids = match tables::RunsTableCols::read(&b, &self.path.display().to_string()) {
                Ok(cols) => cols.run_id,
                Err(e) => {
                    problems.push(e.to_string());
                    break;
                }
            };
            for id in ids.iter().flatten() {
                *run_counts.entry(id).or_default() += 1;
            }
        }
    }
}

/// The `runs` table against the ledger: no run twice, no committed run missing, no run
/// outside every commit record.
fn runs_against_ledger(
    c: &Campaign,
    live: bool,
    finished: &BTreeMap<u64, ledger::RunStatus>,
    run_counts: &BTreeMap<u64, u32>,
    r: &mut VerifyReport,
) {
    let doubled: Vec<u64> = run_counts
        .iter()
        .filter(|(_, &n)| n > 1)
        .map(|(&id, _)| id)
        .collect();
    let missing: Vec<u64> = finished
        .keys()
        .filter(|id| !run_counts.contains_key(id))
        .copied()
        .collect();
    // Runs of the table not in the ledger as read at the start: a live writer may have
    // committed them since (its record comes before its parts); read the ledger again.
    let again = if live && run_counts.keys().any(|id| !finished.contains_key(id)) {
        ledger::read_ledger(&c.root)
            .map(|l| ledger::finished_runs(&l.commits))
            .ok()
    } else {
        None
    };
    let extra: Vec<u64> = run_counts
        .keys()
        .filter(|id| !finished.contains_key(id))
        .filter(|id| !again.as_ref().is_some_and(|a| a.contains_key(id)))
        .copied()
        .collect();
    let show = |v: &[u64]| {
        let s: Vec<String> = v.iter().take(10).map(|x| x.to_string()).collect();
        format!(
            "{}{}",
            s.join(", "),
            if v.len() > 10 { ", ..." } else { "" }
        )
    };
    if !doubled.is_empty() {
        r.problems.push(format!(
            "runs table: {} run(s) appear more than once: {}",
            doubled.len(),
            show(&doubled)
        ));
    }
    if !missing.is_empty() {
        r.problems.push(format!(
            "runs table: {} committed run(s) missing: {}",
            missing.len(),
            show(&missing)
        ));
    }
    if !extra.is_empty() {
        r.problems.push(format!(
            "runs table: {} run(s) not in any commit record: {}",
            extra.len(),
            show(&extra)
        ));
    }
}
