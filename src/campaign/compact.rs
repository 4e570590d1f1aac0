//! `granular compact`: merge a campaign's many small Parquet parts into few large files and
//! fold the commit records into one ledger index, without a reader of a generation ever
//! seeing missing or doubled rows.
//!
//! Merging follows the commits: consecutive commits are binned up to the target size (all
//! their tables together), and a bin becomes one group of the index with one merged file per
//! table, `part-c<k>-<bin>.parquet` (compaction k), holding exactly the rows of the bin's runs;
//! a commit of at least half the target stays alone, its files kept. So a damaged file only
//! ever costs the runs of its group (see `integrity`).
//!
//! Per table that changes (see `store::layout`): the next generation directory is built beside
//! the current one (hard links to the files kept, merged files written, hashed and fsynced),
//! and checked (row counts equal). Then the journal `ledger/compaction.json` (the new index and
//! the generations to publish) is written atomically: the commit point. Then each generation
//! is published by renaming a new symlink over `tables/<t>`, the index is written and the
//! folded commit records deleted (`ledger::complete_compaction`). A crash before the journal
//! leaves everything as it was (half-built generations are removed by the next compaction);
//! after it, `ledger::recover` finishes the job. A generation's files never change; the
//! previous generation is kept for readers that resolved the link to it just before the
//! switch, older ones are deleted. (A reader through the link itself may list the old
//! generation and look its files up in the new one: DuckDB's glob and pyarrow's dataset
//! discovery then skip the vanished files silently, so docs/operations.md tells readers to
//! resolve the link once.)
//!
//! Runs only while no shard runs (`ledger::ExclusiveLock`), after `ledger::recover`, on a
//! campaign whose every file checks out (a full scrub; damage is refused, exit 3, and
//! `granular resume` heals it; a link where granular keeps its own file or directory is
//! damage). Every directory is opened without following a link (`fsutil::Dir`; the tables
//! through their generation links only), so that nothing is read, written or removed outside
//! the campaign directory, even if a link is swapped in while it runs.

use std::path::{Path, PathBuf};

use std::collections::BTreeMap;

use super::ledger::{self, ExclusiveLock, PartCommit, Purpose};
use super::{integrity, Campaign, CampaignError};
use crate::fsutil::{self, Dir, Kind};
use crate::store::checksum::FileSum;
use crate::store::layout::{self, TableDir};
use crate::store::parquet_io::{self, Stamp};
use crate::store::LEDGER_FORMAT;

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
    rows: u64,
    /// Arrow schema without metadata, to merge only files of one schema.
    schema: arrow_schema::SchemaRef,
}

fn io(p: &Path, e: impl std::fmt::Display) -> CampaignError {
    CampaignError::Io(format!("{}: {e}", p.display()))
}

/// An error of a primitive of `fsutil::Dir` at `p`: something that is not granular's own is
/// refused (it names itself), anything else is an I/O error.
fn fs_err(p: &Path, e: std::io::Error) -> CampaignError {
    match fsutil::not_own(&e) {
        Some(n) => CampaignError::Refused(n.to_string()),
        None => io(p, e),
    }
}

/// The regular file `rel` of the campaign directory (as `layout::open_file`).
fn open_rel(c: &Campaign, rd: &Dir, rel: &str) -> Result<std::fs::File, CampaignError> {
    let path = c.root.join(rel);
    layout::open_file(rd, rel)
        .map_err(|e| fs_err(&path, e))?
        .ok_or_else(|| io(&path, "gone"))
}

/// Compact every table of the campaign and fold its ledger.
pub fn compact(c: &Campaign, opts: &CompactOptions) -> Result<CompactReport, CampaignError> {
    let _lock = ExclusiveLock::acquire(&c.root, Purpose::Compaction)?;
    // Decided on the campaign as read under the lock.
    let fresh = Campaign::open(&c.root)?;
    let c = &fresh;
    let mut report = CompactReport {
        notes: ledger::recover(&c.root, ledger::COMPACT_TAG)?,
        ..Default::default()
    };
    refuse_damage(c)?;
    let ledger = ledger::read_ledger(&c.root)?;
    let old_index = ledger.index.clone().unwrap_or_default();
    let units = ledger.commits;
    let rd = Dir::open(&c.root).map_err(|e| io(&c.root, e))?;
    let parts = read_parts(c, &rd, &units)?;
    let groups = plan_bins(&units, &parts, opts.target_bytes);
    let merging = groups.iter().any(|g| g.len() > 1);
    let k = compaction_number(&units, &old_index);
    let mut merge = Merge {
        c,
        rd: &rd,
        units: &units,
        parts: &parts,
        shard: format!("c{k}"),
        gens: BTreeMap::new(),
        merged_away: BTreeMap::new(),
        notes: &mut report.notes,
    };
    let mut new_groups = Vec::new();
    for (bin, g) in groups.iter().enumerate() {
        new_groups.push(if g.len() == 1 {
            ledger::Group::of(&units[g[0]])
        } else {
            merge.merge_bin(bin, g)?
        });
    }
    merge.link_kept_files()?;
    let Merge { gens, .. } = merge;
    let (journal, records) = journal(&units, &old_index, new_groups, &gens, merging.then_some(k));
    // The commit point.
    let jp = ledger::journal_path(&c.root);
    fsutil::write_atomic(
        &jp,
        &serde_json::to_vec(&journal).expect("journal serialises"),
    )
    .map_err(|e| io(&jp, e))?;
    ledger::complete_compaction(&c.root, &journal)?;
    report.commits_folded = records;
    remove_older_generations(c, &rd, &gens)?;
    let tables = c.root.join("tables");
    for table in layout::table_names(&c.root).map_err(|e| io(&tables, e))? {
        report
            .tables
            .push(table_report(c, &rd, &table, gens.get(&table))?);
    }
    Ok(report)
}

/// A compaction runs only on a campaign whose every file checks out (a full scrub).
fn refuse_damage(c: &Campaign) -> Result<(), CampaignError> {
    let check = integrity::check(c, integrity::Depth::Full)?;
    if !check.clean() {
        return Err(CampaignError::Refused(format!(
            "{}; nothing compacted. `granular resume {}` heals it (runs whose rows are damaged are run again)",
            check.problems().join("; "),
            c.root.display()
        )));
    }
    Ok(())
}

/// The table a committed file (`tables/<t>/<name>`) belongs to.
fn table_of(f: &FileSum) -> String {
    integrity::table_and_name(&f.path).0.to_string()
}

/// Schemas and row counts of every committed part, by path.
fn read_parts(
    c: &Campaign,
    rd: &Dir,
    units: &[ledger::Commit],
) -> Result<BTreeMap<String, Part>, CampaignError> {
    let mut parts: BTreeMap<String, Part> = BTreeMap::new();
    for u in units {
        for f in &u.files {
            let path = c.root.join(&f.path);
            let table = table_of(f);
            let file = open_rel(c, rd, &f.path)?;
            parts.insert(f.path.clone(), read_part(c, &table, file, &path)?);
        }
    }
    Ok(parts)
}

/// The commits binned (see `bins`) by their total sizes and each table's schema.
fn plan_bins(
    units: &[ledger::Commit],
    parts: &BTreeMap<String, Part>,
    target: u64,
) -> Vec<Vec<usize>> {
    let sizes: Vec<u64> = units
        .iter()
        .map(|u| u.files.iter().map(|f| f.bytes).sum())
        .collect();
    let schemas: Vec<BTreeMap<String, arrow_schema::SchemaRef>> = units
        .iter()
        .map(|u| {
            u.files
                .iter()
                .map(|f| (table_of(f), parts[&f.path].schema.clone()))
                .collect()
        })
        .collect();
    bins(&sizes, &schemas, target)
}

/// The compaction number: above every `c<k>` shard seen (a rebuilt ledger may hold some).
fn compaction_number(units: &[ledger::Commit], old_index: &ledger::LedgerIndex) -> u64 {
    units
        .iter()
        .filter_map(|u| u.shard.strip_prefix('c')?.parse::<u64>().ok())
        .chain([old_index.compactions])
        .max()
        .unwrap_or(0)
        + 1
}

/// The tables of a bin's commits in order of first appearance, `runs` first.
fn tables_of_bin(units: &[ledger::Commit], g: &[usize]) -> Vec<String> {
    let mut tables: Vec<String> = Vec::new();
    for &u in g {
        for f in &units[u].files {
            let t = table_of(f);
            if !tables.contains(&t) {
                tables.push(t);
            }
        }
    }
    if let Some(i) = tables.iter().position(|t| t == super::tables::RUNS) {
        let r = tables.remove(i);
        tables.insert(0, r);
    }
    tables
}

/// The merging of the bins into the next generation of each table they touch.
struct Merge<'a> {
    c: &'a Campaign,
    rd: &'a Dir,
    units: &'a [ledger::Commit],
    parts: &'a BTreeMap<String, Part>,
    /// `c<k>`, the shard of the merged groups.
    shard: String,
    /// table -> (current generation, its directory, next generation's directory)
    gens: BTreeMap<String, (u64, Dir, Dir)>,
    /// table -> the names of its files merged into a new one.
    merged_away: BTreeMap<String, Vec<String>>,
    notes: &'a mut Vec<String>,
}

impl Merge<'_> {
    /// One merged file per table of bin number `bin` (commits `g`), and the group they form.
    fn merge_bin(&mut self, bin: usize, g: &[usize]) -> Result<ledger::Group, CampaignError> {
        let seq = bin as u64 + 1; // sequence numbers start at 1, as a shard's do
        let tables_of_bin = tables_of_bin(self.units, g);
        let part_commit = serde_json::to_string(&PartCommit {
            shard: self.shard.clone(),
            seq,
            tables: tables_of_bin.clone(),
        })
        .expect("part commit serialises");
        let mut files = Vec::new();
        for table in &tables_of_bin {
            self.start_generation(table)?;
            files.push(self.merge_table(table, g, seq, &part_commit)?);
        }
        let mut runs: Vec<ledger::CommittedRun> =
            g.iter().flat_map(|&u| self.units[u].runs.clone()).collect();
        runs.sort_by_key(|r| r.run_id);
        Ok(ledger::Group::of(&ledger::Commit {
            format_version: LEDGER_FORMAT,
            shard: self.shard.clone(),
            seq,
            runs,
            files,
            in_index: false,
        }))
    }

    /// The next generation's directory of `table`, made empty the first time a bin needs it.
    fn start_generation(&mut self, table: &str) -> Result<(), CampaignError> {
        if self.gens.contains_key(table) {
            return Ok(());
        }
        let c = self.c;
        let tables = c.root.join("tables");
        let (gen, dir, all) = prepare_generation(c, self.rd, table, self.notes)?;
        let name = layout::generation_name(table, gen + 1);
        let path = gens_dir(&tables).join(&name);
        all.remove_tree(&name).map_err(|e| fs_err(&path, e))?;
        let next = all.create_dir(&name).map_err(|e| fs_err(&path, e))?;
        self.gens.insert(table.to_string(), (gen, dir, next));
        Ok(())
    }

    /// The rows of `table` of the bin's commits `g`, written as one file into the table's next
    /// generation and checked (row count); its entry in the group's commit.
    fn merge_table(
        &mut self,
        table: &str,
        g: &[usize],
        seq: u64,
        part_commit: &str,
    ) -> Result<FileSum, CampaignError> {
        let c = self.c;
        let mut batches = Vec::new();
        let mut want = 0u64;
        for &u in g {
            for f in self.units[u].files.iter().filter(|f| table_of(f) == *table) {
                let path = c.root.join(&f.path);
                let file = open_rel(c, self.rd, &f.path)?;
                batches.extend(
                    parquet_io::read_campaign_opened(file, &path, table, &c.identity)
                        .map_err(|e| CampaignError::Io(e.to_string()))?,
                );
                want += self.parts[&f.path].rows;
                self.merged_away
                    .entry(table.to_string())
                    .or_default()
                    .push(integrity::table_and_name(&f.path).1.to_string());
            }
        }
        let (_, _, next) = &self.gens[table];
        let name = format!("part-{}-{seq:08}.parquet", self.shard);
        // The new generation's directory, made above inside `.gen` (never a link).
        let out = next.path().join(&name);
        let stamp = Stamp {
            commit: Some(part_commit),
            ..c.stamp()
        };
        let w = parquet_io::write_batches(&out, &batches, table, stamp)
            .map_err(|e| CampaignError::Io(e.to_string()))?;
        let (info, _) = parquet_io::inspect(&out).map_err(|e| CampaignError::Io(e.to_string()))?;
        if info.rows != want {
            return Err(CampaignError::Io(format!(
                "{}: merged file has {} rows, its parts {want}; nothing published",
                out.display(),
                info.rows
            )));
        }
        Ok(FileSum {
            path: format!("tables/{table}/{name}"),
            bytes: w.bytes,
            sha256: w.sha256,
        })
    }

    /// The kept files of each changed table (every visible file not merged away), hard-linked
    /// (or copied) into its next generation, which is then synced.
    fn link_kept_files(&self) -> Result<(), CampaignError> {
        for (table, (_, dir, next)) in &self.gens {
            let away = self.merged_away.get(table).cloned().unwrap_or_default();
            for (name, kind) in dir.entries().map_err(|e| io(dir.path(), e))? {
                let keep = !name.starts_with('.') && !away.contains(&name);
                if !keep || next.kind(&name).map_err(|e| io(next.path(), e))?.is_some() {
                    continue;
                }
                let to = next.path().join(&name);
                if kind != Kind::File {
                    // The scrub found none: one came while we worked. Not followed, not kept.
                    return Err(CampaignError::Refused(format!(
                        "{}: {}, where granular keeps its own files (not followed); nothing published",
                        dir.path().join(&name).display(),
                        dir.describe(&name, kind)
                    )));
                }
                dir.hard_link(&name, next, &name)
                    .or_else(|_| dir.copy_file(&name, next, &name))
                    .map_err(|err| fs_err(&to, err))?;
            }
            next.sync().map_err(|e| io(next.path(), e))?;
        }
        Ok(())
    }
}

/// The compaction's journal: the new index (the commit records not yet in the index folded,
/// `compactions` raised to `merged` when a bin was merged) and the generations to publish;
/// with the number of records folded.
fn journal(
    units: &[ledger::Commit],
    old_index: &ledger::LedgerIndex,
    groups: Vec<ledger::Group>,
    gens: &BTreeMap<String, (u64, Dir, Dir)>,
    merged: Option<u64>,
) -> (ledger::Journal, usize) {
    let mut folded = old_index.folded.clone();
    let mut records = 0;
    for u in units.iter().filter(|u| !u.in_index) {
        let e = folded.entry(u.shard.clone()).or_insert(0);
        *e = (*e).max(u.seq);
        records += 1;
    }
    let index = ledger::LedgerIndex {
        format_version: LEDGER_FORMAT,
        kind: ledger::INDEX_KIND.into(),
        folded,
        compactions: merged.unwrap_or(old_index.compactions),
        groups,
    };
    let journal = ledger::Journal {
        format_version: LEDGER_FORMAT,
        kind: ledger::JOURNAL_KIND.into(),
        publish: gens
            .iter()
            .map(|(t, (g, _, _))| (t.clone(), g + 1))
            .collect(),
        index,
    };
    (journal, records)
}

/// The generation before the previous one of each changed table can go once the new one is
/// published.
fn remove_older_generations(
    c: &Campaign,
    rd: &Dir,
    gens: &BTreeMap<String, (u64, Dir, Dir)>,
) -> Result<(), CampaignError> {
    let tables = c.root.join("tables");
    if let Some(all) = rd
        .walk(&format!("tables/{}", layout::GEN_DIR))
        .map_err(|e| fs_err(&gens_dir(&tables), e))?
    {
        for (table, (gen, _, _)) in gens {
            if *gen > 0 {
                let name = layout::generation_name(table, gen - 1);
                all.remove_tree(&name)
                    .map_err(|e| fs_err(&gens_dir(&tables).join(&name), e))?;
            }
        }
    }
    Ok(())
}

fn gens_dir(tables: &Path) -> PathBuf {
    tables.join(layout::GEN_DIR)
}

fn read_part(
    c: &Campaign,
    table: &str,
    file: std::fs::File,
    path: &Path,
) -> Result<Part, CampaignError> {
    let (info, builder) = parquet_io::inspect_file(file, path).map_err(|e| {
        CampaignError::Refused(format!(
            "{e}; `granular resume {}` heals it",
            c.root.display()
        ))
    })?;
    parquet_io::check_part(path, &info, table, Some(&c.identity))
        .map_err(|e| CampaignError::Refused(format!("{e}; move it out of the table to compact")))?;
    let schema = std::sync::Arc::new(
        builder
            .schema()
            .as_ref()
            .clone()
            .with_metadata(std::collections::HashMap::new()),
    );
    Ok(Part {
        rows: info.rows,
        schema,
    })
}

/// The table's current generation, its directory, and `.gen` (a plain directory of an older
/// granular is moved to generation 0 first); generations other than the current and the
/// previous one (old, or half-built by a compaction that stopped) are removed, never
/// following a link.
fn prepare_generation(
    c: &Campaign,
    rd: &Dir,
    table: &str,
    notes: &mut Vec<String>,
) -> Result<(u64, Dir, Dir), CampaignError> {
    let tables = c.root.join("tables");
    let gen = match layout::table_dir(&c.root, table).map_err(|e| fs_err(&tables.join(table), e))? {
        TableDir::Generation { gen, .. } => gen,
        TableDir::Plain(_) => {
            layout::migrate_plain(&c.root, table).map_err(|e| fs_err(&tables.join(table), e))?;
            notes.push(format!(
                "{table}: moved to the generation layout (made by an older granular)"
            ));
            0
        }
    };
    let dir = layout::open_table(rd, table)
        .map_err(|e| fs_err(&tables.join(table), e))?
        .ok_or_else(|| io(&tables.join(table), "its generation is not there"))?;
    let all = rd
        .walk(&format!("tables/{}", layout::GEN_DIR))
        .map_err(|e| fs_err(&gens_dir(&tables), e))?
        .ok_or_else(|| io(&gens_dir(&tables), "not there"))?;
    for (name, _) in all.entries().map_err(|e| io(&gens_dir(&tables), e))? {
        let Some(g) = name
            .strip_prefix(&format!("{table}."))
            .and_then(|g| g.parse::<u64>().ok())
        else {
            continue;
        };
        if g != gen && g + 1 != gen {
            all.remove_tree(&name)
                .map_err(|e| fs_err(&gens_dir(&tables).join(&name), e))?;
        }
    }
    Ok((gen, dir, all))
}

fn table_report(
    c: &Campaign,
    rd: &Dir,
    table: &str,
    changed: Option<&(u64, Dir, Dir)>,
) -> Result<TableReport, CampaignError> {
    let stats = |d: &Dir| -> Result<(usize, u64, u64), CampaignError> {
        let (mut files, mut rows, mut bytes) = (0, 0, 0);
        for (name, kind) in d.entries().map_err(|e| io(d.path(), e))? {
            if name.starts_with('.') || !name.ends_with(".parquet") || kind != Kind::File {
                continue;
            }
            let path = d.path().join(&name);
            let Some(f) = d.open_file(&name).map_err(|e| fs_err(&path, e))? else {
                continue;
            };
            files += 1;
            bytes += f.metadata().map_err(|e| io(&path, e))?.len();
            rows += parquet_io::inspect_file(f, &path)
                .map(|(i, _)| i.rows)
                .map_err(|err| CampaignError::Io(err.to_string()))?;
        }
        Ok((files, rows, bytes))
    };
    let link = c.root.join("tables").join(table);
    let now = layout::open_table(rd, table)
        .map_err(|e| fs_err(&link, e))?
        .ok_or_else(|| io(&link, "not there"))?;
    let (files_after, rows, bytes_after) = stats(&now)?;
    let generation = match layout::table_dir(&c.root, table) {
        Ok(TableDir::Generation { gen, .. }) => gen,
        _ => 0,
    };
    let (files_before, bytes_before) = match changed {
        Some((_, old, _)) => {
            let (f, _, b) = stats(old)?;
            (f, b)
        }
        None => (files_after, bytes_after),
    };
    Ok(TableReport {
        table: table.into(),
        files_before,
        files_after,
        rows,
        bytes_before,
        bytes_after,
        generation,
    })
}

/// Group consecutive commits (their total sizes, and each table's schema) into bins of about
/// `target` bytes; a commit of at least half the target stays alone, and a bin holds one
/// schema per table.
fn bins(
    sizes: &[u64],
    schemas: &[BTreeMap<String, arrow_schema::SchemaRef>],
    target: u64,
) -> Vec<Vec<usize>> {
    let mut out: Vec<Vec<usize>> = Vec::new();
    let mut cur: Vec<usize> = Vec::new();
    let mut cur_schema: BTreeMap<String, arrow_schema::SchemaRef> = BTreeMap::new();
    let mut size = 0u64;
    for (i, &bytes) in sizes.iter().enumerate() {
        let big = bytes >= target / 2;
        let same_schema = schemas[i]
            .iter()
            .all(|(t, s)| cur_schema.get(t).is_none_or(|c| c == s));
        if (big || !same_schema || size + bytes > target) && !cur.is_empty() {
            out.push(std::mem::take(&mut cur));
            cur_schema.clear();
            size = 0;
        }
        if big {
            out.push(vec![i]);
        } else {
            cur.push(i);
            size += bytes;
            for (t, s) in &schemas[i] {
                cur_schema.entry(t.clone()).or_insert_with(|| s.clone());
            }
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bins_group_small_commits_and_leave_big_ones() {
        use arrow_schema::{DataType, Field, Schema};
        let a = std::sync::Arc::new(Schema::new(vec![Field::new("x", DataType::Int64, false)]));
        let b = std::sync::Arc::new(Schema::new(vec![Field::new("y", DataType::Int64, false)]));
        let of = |s: &arrow_schema::SchemaRef| BTreeMap::from([("t".to_string(), s.clone())]);
        let sizes = [30, 30, 30, 60, 10, 10, 10];
        // 60 >= target/2: alone; the fifth commit ends a bin, the sixth has another schema.
        let schemas = [of(&a), of(&a), of(&a), of(&a), of(&a), of(&b), of(&b)];
        assert_eq!(
            bins(&sizes, &schemas, 100),
            vec![vec![0, 1, 2], vec![3], vec![4], vec![5, 6]]
        );
        assert_eq!(
            bins(&sizes, &schemas, 50),
            vec![vec![0], vec![1], vec![2], vec![3], vec![4], vec![5, 6]]
        );
        // A table only some commits have does not split a bin.
        let mixed = [
            of(&a),
            BTreeMap::from([("t".to_string(), a.clone()), ("u".to_string(), b.clone())]),
        ];
        assert_eq!(bins(&[1, 1], &mixed, 100), vec![vec![0, 1]]);
    }
}
