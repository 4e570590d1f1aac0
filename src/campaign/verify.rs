//! `granular verify`: every committed file matches its commit's size and SHA-256 and every
//! rebuilt table its sidecar (a full scrub; `--quick`: sizes only), no part is without a
//! commit and no run in two (see `integrity`); every table file is readable, of this campaign,
//! table and format; uncommitted (`.pending`) parts of dead writers are reported; the `runs`
//! table holds every committed run exactly once (nothing lost, nothing doubled). Links where
//! granular keeps its own files are named (see `integrity`) and never followed: the tables
//! are read through granular's own generation links only, their regular files only.

use std::collections::BTreeMap;

use arrow_array::cast::AsArray;
use arrow_array::types::UInt64Type;

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

pub fn verify(c: &Campaign, depth: Depth) -> Result<VerifyReport, String> {
    let mut r = VerifyReport::default();
    let check = integrity::check(c, depth)?;
    if let Some(why) = &check.skipped {
        return Err(format!("{}: not verified: {why}", c.root.display()));
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
    let mut run_counts: BTreeMap<u64, u32> = BTreeMap::new();
    let rd = Dir::open(&c.root).map_err(|e| format!("{}: {e}", c.root.display()))?;
    for table in layout::table_names(&c.root).map_err(|e| e.to_string())? {
        let dir = c.root.join("tables").join(&table);
        let mut files = 0;
        let mut rows = 0u64;
        let Some(d) = layout::open_table(&rd, &table).map_err(|e| e.to_string())? else {
            continue;
        };
        let entries = d.entries().map_err(|e| format!("{}: {e}", dir.display()))?;
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
            let open = || -> Result<std::fs::File, parquet_io::StoreError> {
                d.open_file(&name)
                    .map_err(|e| parquet_io::open_error(&path, e))?
                    .ok_or_else(|| {
                        parquet_io::StoreError::io(&path, std::io::ErrorKind::NotFound.into())
                    })
            };
            let checked = open()
                .and_then(|f| parquet_io::inspect_file(f, &path))
                .and_then(|(info, _)| {
                    parquet_io::check_part(&path, &info, &table, Some(&c.identity))?;
                    Ok(info)
                });
            match checked {
                Ok(info) => rows += info.rows,
                Err(e) => {
                    r.problems.push(e.to_string());
                    continue;
                }
            }
            if table == tables::RUNS {
                match open()
                    .and_then(|f| parquet_io::read_campaign_opened(f, &path, &table, &c.identity))
                {
                    Ok(batches) => {
                        for b in batches {
                            let Some(col) = b.column_by_name("run_id") else {
                                r.problems
                                    .push(format!("{}: no run_id column", path.display()));
                                break;
                            };
                            let Some(ids) = col.as_primitive_opt::<UInt64Type>() else {
                                r.problems.push(format!(
                                    "{}: run_id is not an unsigned 64-bit column",
                                    path.display()
                                ));
                                break;
                            };
                            for id in ids.iter().flatten() {
                                *run_counts.entry(id).or_default() += 1;
                            }
                        }
                    }
                    Err(e) => r.problems.push(e.to_string()),
                }
            }
        }
        r.tables.push((table, files, rows));
    }
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
    Ok(r)
}
