//! `granular compact`: merge a campaign's many small Parquet parts into few large files and
//! fold the commit records into one ledger index, without a reader ever seeing missing or
//! doubled rows.
//!
//! Per table (see `store::layout`): the next generation directory is built beside the current
//! one (hard links to the files kept, merged files written and fsynced), checked (row counts
//! equal), then published by renaming a new symlink over `tables/<t>`. A crash before the
//! rename leaves the old generation in place (the half-built one is removed by the next
//! compaction); after it, the new one is complete. The previous generation is kept for readers
//! that listed it just before the switch; older ones are deleted.
//!
//! Runs only while no shard runs (`ledger::CompactLock`), after `ledger::recover`.

use std::fs;
use std::path::{Path, PathBuf};

use super::ledger::{self, CompactLock};
use super::{Campaign, CampaignError};
use crate::fsutil;
use crate::store::layout::{self, TableDir};
use crate::store::parquet_io;

/// Default size of a merged file.
pub const DEFAULT_TARGET_BYTES: u64 = 100 * 1024 * 1024;

#[derive(Debug, Clone)]
pub struct CompactOptions {
    /// Merge files until a merged file reaches about this size.
    pub target_bytes: u64,
}

impl Default for CompactOptions {
    fn default() -> Self {
        CompactOptions {
            target_bytes: DEFAULT_TARGET_BYTES,
        }
    }
}

/// What happened to one table.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TableReport {
    pub table: String,
    pub files_before: usize,
    pub files_after: usize,
    pub rows: u64,
    pub bytes_before: u64,
    pub bytes_after: u64,
    /// The generation now published (unchanged tables keep theirs).
    pub generation: u64,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, Default)]
pub struct CompactReport {
    pub tables: Vec<TableReport>,
    /// Commit records folded into `ledger/index.json` (and removed).
    pub commits_folded: usize,
    pub notes: Vec<String>,
}

struct Part {
    path: PathBuf,
    name: String,
    bytes: u64,
    rows: u64,
    /// Arrow schema without metadata, to merge only files of one schema.
    schema: arrow_schema::SchemaRef,
}

fn io(p: &Path, e: impl std::fmt::Display) -> CampaignError {
    CampaignError::Io(format!("{}: {e}", p.display()))
}

/// Compact every table of the campaign and fold its ledger.
pub fn compact(c: &Campaign, opts: &CompactOptions) -> Result<CompactReport, CampaignError> {
    let _lock = CompactLock::acquire(&c.root).map_err(CampaignError::Refused)?;
    let mut report = CompactReport {
        notes: ledger::recover(&c.root, ledger::COMPACT_TAG).map_err(CampaignError::Io)?,
        ..Default::default()
    };
    for table in layout::table_names(&c.root).map_err(|e| io(&c.root.join("tables"), e))? {
        if let Some(t) = compact_table(c, &table, opts, &mut report.notes)? {
            report.tables.push(t);
        }
    }
    report.commits_folded = ledger::fold_into_index(&c.root).map_err(CampaignError::Io)?;
    Ok(report)
}

fn list_parts(c: &Campaign, table: &str, dir: &Path) -> Result<Vec<Part>, CampaignError> {
    let mut parts = Vec::new();
    for e in fs::read_dir(dir).map_err(|e| io(dir, e))? {
        let e = e.map_err(|e| io(dir, e))?;
        let name = e.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') || !name.ends_with(".parquet") {
            continue;
        }
        let path = e.path();
        let bytes = e.metadata().map_err(|e| io(&path, e))?.len();
        let (info, builder) = parquet_io::inspect(&path).map_err(|e| {
            CampaignError::Refused(format!("{e}; move it out of the table to compact"))
        })?;
        parquet_io::check_part(&path, &info, table, Some(&c.identity)).map_err(|e| {
            CampaignError::Refused(format!("{e}; move it out of the table to compact"))
        })?;
        let schema = std::sync::Arc::new(
            builder
                .schema()
                .as_ref()
                .clone()
                .with_metadata(std::collections::HashMap::new()),
        );
        parts.push(Part {
            path,
            name,
            bytes,
            rows: info.rows,
            schema,
        });
    }
    parts.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(parts)
}

/// Group consecutive small parts of one schema into bins of about `target` bytes; parts of
/// at least half the target stay alone.
fn bins(parts: &[Part], target: u64) -> Vec<Vec<usize>> {
    let mut out: Vec<Vec<usize>> = Vec::new();
    let mut cur: Vec<usize> = Vec::new();
    let mut size = 0u64;
    for (i, p) in parts.iter().enumerate() {
        let big = p.bytes >= target / 2;
        let same_schema = cur.first().is_none_or(|&j| parts[j].schema == p.schema);
        if (big || !same_schema || size + p.bytes > target) && !cur.is_empty() {
            out.push(std::mem::take(&mut cur));
            size = 0;
        }
        if big {
            out.push(vec![i]);
        } else {
            cur.push(i);
            size += p.bytes;
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

fn compact_table(
    c: &Campaign,
    table: &str,
    opts: &CompactOptions,
    notes: &mut Vec<String>,
) -> Result<Option<TableReport>, CampaignError> {
    let tables = c.root.join("tables");
    let (gen, dir) = match layout::table_dir(&c.root, table).map_err(|e| io(&tables, e))? {
        TableDir::Generation { gen, dir } => (gen, dir),
        TableDir::Plain(_) => {
            layout::migrate_plain(&c.root, table).map_err(|e| io(&tables.join(table), e))?;
            notes.push(format!(
                "{table}: moved to the generation layout (made by an older granular)"
            ));
            (
                0,
                tables
                    .join(layout::GEN_DIR)
                    .join(layout::generation_name(table, 0)),
            )
        }
    };
    let gens = tables.join(layout::GEN_DIR);
    // Generations other than the current and the previous one: old or half-built.
    if let Ok(it) = fs::read_dir(&gens) {
        for e in it.filter_map(|e| e.ok()) {
            let name = e.file_name().to_string_lossy().into_owned();
            let Some(g) = name
                .strip_prefix(&format!("{table}."))
                .and_then(|g| g.parse::<u64>().ok())
            else {
                continue;
            };
            if g != gen && g + 1 != gen {
                fs::remove_dir_all(e.path()).map_err(|err| io(&e.path(), err))?;
            }
        }
    }
    let parts = list_parts(c, table, &dir)?;
    let rows: u64 = parts.iter().map(|p| p.rows).sum();
    let bytes_before: u64 = parts.iter().map(|p| p.bytes).sum();
    let groups = bins(&parts, opts.target_bytes);
    if groups.iter().all(|g| g.len() < 2) {
        return Ok(Some(TableReport {
            table: table.into(),
            files_before: parts.len(),
            files_after: parts.len(),
            rows,
            bytes_before,
            bytes_after: bytes_before,
            generation: gen,
        }));
    }
    let next = gen + 1;
    let ndir = gens.join(layout::generation_name(table, next));
    fsutil::create_dir_durable(&ndir).map_err(|e| io(&ndir, e))?;
    let mut merged = 0usize;
    for g in &groups {
        if g.len() == 1 {
            let p = &parts[g[0]];
            let to = ndir.join(&p.name);
            fs::hard_link(&p.path, &to)
                .or_else(|_| fs::copy(&p.path, &to).map(|_| ()))
                .map_err(|e| io(&to, e))?;
            continue;
        }
        let mut batches = Vec::new();
        let mut want = 0u64;
        for &i in g {
            batches.extend(
                parquet_io::read_campaign_file(&parts[i].path, table, &c.identity)
                    .map_err(|e| CampaignError::Io(e.to_string()))?,
            );
            want += parts[i].rows;
        }
        let out = ndir.join(format!("compact-{next:08}-{merged:05}.parquet"));
        merged += 1;
        parquet_io::write_batches(&out, &batches, table, c.stamp())
            .map_err(|e| CampaignError::Io(e.to_string()))?;
        let (info, _) = parquet_io::inspect(&out).map_err(|e| CampaignError::Io(e.to_string()))?;
        if info.rows != want {
            return Err(CampaignError::Io(format!(
                "{}: merged file has {} rows, its parts {want}; nothing published",
                out.display(),
                info.rows
            )));
        }
    }
    fsutil::sync_dir(&ndir).map_err(|e| io(&ndir, e))?;
    let after = list_parts(c, table, &ndir)?;
    let rows_after: u64 = after.iter().map(|p| p.rows).sum();
    if rows_after != rows {
        return Err(CampaignError::Io(format!(
            "{}: {rows_after} rows in the new generation, {rows} in the current one; nothing published",
            ndir.display()
        )));
    }
    layout::publish_generation(&c.root, table, next).map_err(|e| io(&tables.join(table), e))?;
    // The generation before the previous one can go now.
    if gen > 0 {
        let old = gens.join(layout::generation_name(table, gen - 1));
        if old.exists() {
            fs::remove_dir_all(&old).map_err(|e| io(&old, e))?;
        }
    }
    Ok(Some(TableReport {
        table: table.into(),
        files_before: parts.len(),
        files_after: after.len(),
        rows,
        bytes_before,
        bytes_after: after.iter().map(|p| p.bytes).sum(),
        generation: next,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn part(name: &str, bytes: u64, schema: &arrow_schema::SchemaRef) -> Part {
        Part {
            path: PathBuf::from(name),
            name: name.into(),
            bytes,
            rows: 1,
            schema: schema.clone(),
        }
    }

    #[test]
    fn bins_group_small_parts_and_leave_big_ones() {
        use arrow_schema::{DataType, Field, Schema};
        let a = std::sync::Arc::new(Schema::new(vec![Field::new("x", DataType::Int64, false)]));
        let b = std::sync::Arc::new(Schema::new(vec![Field::new("y", DataType::Int64, false)]));
        let parts = vec![
            part("p0", 30, &a),
            part("p1", 30, &a),
            part("p2", 30, &a),
            part("p3", 60, &a), // >= target/2: alone
            part("p4", 10, &a),
            part("p5", 10, &b), // another schema: a new bin
            part("p6", 10, &b),
        ];
        assert_eq!(
            bins(&parts, 100),
            vec![vec![0, 1, 2], vec![3], vec![4], vec![5, 6]]
        );
        assert_eq!(
            bins(&parts, 50),
            vec![vec![0], vec![1], vec![2], vec![3], vec![4], vec![5, 6]]
        );
    }
}
