//! Table directories as generations behind a symbolic link, so that `granular compact` can
//! replace a table's set of part files in one atomic step:
//!
//! ```text
//! tables/runs -> .gen/runs.00000003          (relative symlink; readers glob tables/runs/*.parquet)
//! tables/.gen/runs.00000003/part-*.parquet   (the current generation)
//! tables/.gen/runs.00000002/...              (the previous one, kept for readers in flight)
//! ```
//!
//! Writers add files through the link (`tables/runs/part-...`), so they always write into the
//! current generation. A compaction builds the next generation beside it (hard links for the
//! files it keeps, new merged files) and renames a new link over `tables/runs`: a reader that
//! lists the directory sees the old set or the new set, never a mixture. Renaming a symlink
//! over another is atomic on local filesystems and on NFS. Hidden names (`.gen`) are skipped by
//! DuckDB/Polars globs of `tables/<t>/*.parquet` and by pyarrow datasets.

use std::fs;
use std::io;
use std::path::{Path, PathBuf};

use crate::fsutil;

/// Directory of the generations, inside `tables/`.
pub const GEN_DIR: &str = ".gen";

/// The generation directory's name of `table` at generation `gen`.
pub fn generation_name(table: &str, gen: u64) -> String {
    format!("{table}.{gen:08}")
}

/// Create `tables/<table>` as a link to generation 0 unless the table exists (as a link, or
/// as a plain directory made by an older granular). Safe to call from several processes.
pub fn ensure_table_dir(root: &Path, table: &str) -> io::Result<PathBuf> {
    let tables = root.join("tables");
    let link = tables.join(table);
    if fs::symlink_metadata(&link).is_ok() {
        return Ok(link);
    }
    let name = generation_name(table, 0);
    let gen = tables.join(GEN_DIR).join(&name);
    fsutil::create_dir_durable(&gen)?;
    match std::os::unix::fs::symlink(Path::new(GEN_DIR).join(&name), &link) {
        Ok(()) => fsutil::sync_dir(&tables)?,
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {}
        Err(e) => return Err(e),
    }
    Ok(link)
}

/// Where a table's files are now.
#[derive(Debug, Clone, PartialEq)]
pub enum TableDir {
    /// `tables/<t>` links to generation `gen` at `dir`.
    Generation { gen: u64, dir: PathBuf },
    /// `tables/<t>` is a plain directory (made before generations existed).
    Plain(PathBuf),
}

pub fn table_dir(root: &Path, table: &str) -> io::Result<TableDir> {
    let tables = root.join("tables");
    let link = tables.join(table);
    let meta = fs::symlink_metadata(&link)?;
    if !meta.file_type().is_symlink() {
        return Ok(TableDir::Plain(link));
    }
    let target = fs::read_link(&link)?;
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let gen = name
        .strip_prefix(&format!("{table}."))
        .and_then(|g| g.parse::<u64>().ok())
        .ok_or_else(|| {
            io::Error::new(
                io::ErrorKind::InvalidData,
                format!(
                    "{} links to {}, not to a generation of table {table}",
                    link.display(),
                    target.display()
                ),
            )
        })?;
    Ok(TableDir::Generation {
        gen,
        dir: tables.join(GEN_DIR).join(name),
    })
}

/// The tables of a campaign: the names in `tables/` that are not hidden.
pub fn table_names(root: &Path) -> io::Result<Vec<String>> {
    let mut v: Vec<String> = match fs::read_dir(root.join("tables")) {
        Ok(it) => it
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| !n.starts_with('.'))
            .collect(),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Vec::new(),
        Err(e) => return Err(e),
    };
    v.sort();
    Ok(v)
}

/// Make generation `gen` (a complete directory under `.gen`) the table's current one: a new
/// link is written beside `tables/<t>` and renamed over it (the atomic step).
pub fn publish_generation(root: &Path, table: &str, gen: u64) -> io::Result<()> {
    let tables = root.join("tables");
    let name = generation_name(table, gen);
    let tmp = fsutil::temp_path(&tables.join(table));
    std::os::unix::fs::symlink(Path::new(GEN_DIR).join(&name), &tmp)?;
    if let Err(e) = fs::rename(&tmp, tables.join(table)) {
        let _ = fs::remove_file(&tmp);
        return Err(e);
    }
    fsutil::sync_dir(&tables)
}

/// Turn a plain table directory into generation 0 behind a link. Not atomic for readers: for
/// an instant `tables/<t>` does not exist (a reader then fails to find the table; it never sees
/// partial data). New campaigns never need this.
pub fn migrate_plain(root: &Path, table: &str) -> io::Result<()> {
    let tables = root.join("tables");
    let gens = tables.join(GEN_DIR);
    fsutil::create_dir_durable(&gens)?;
    let name = generation_name(table, 0);
    fs::rename(tables.join(table), gens.join(&name))?;
    std::os::unix::fs::symlink(Path::new(GEN_DIR).join(&name), tables.join(table))?;
    fsutil::sync_dir(&gens)?;
    fsutil::sync_dir(&tables)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ensure_creates_a_link_to_generation_zero_once() {
        let d = tempfile::tempdir().unwrap();
        let link = ensure_table_dir(d.path(), "runs").unwrap();
        fs::write(link.join("a.parquet"), b"x").unwrap();
        ensure_table_dir(d.path(), "runs").unwrap();
        assert_eq!(
            table_dir(d.path(), "runs").unwrap(),
            TableDir::Generation {
                gen: 0,
                dir: d.path().join("tables/.gen/runs.00000000")
            }
        );
        assert!(d
            .path()
            .join("tables/.gen/runs.00000000/a.parquet")
            .exists());
        assert_eq!(table_names(d.path()).unwrap(), vec!["runs".to_string()]);
    }

    #[test]
    fn publish_switches_the_link_and_migrate_converts_a_plain_directory() {
        let d = tempfile::tempdir().unwrap();
        ensure_table_dir(d.path(), "runs").unwrap();
        let g1 = d.path().join("tables/.gen/runs.00000001");
        fs::create_dir_all(&g1).unwrap();
        fs::write(g1.join("b.parquet"), b"y").unwrap();
        publish_generation(d.path(), "runs", 1).unwrap();
        assert!(d.path().join("tables/runs/b.parquet").exists());
        assert!(!d.path().join("tables/runs/a.parquet").exists());

        fs::create_dir_all(d.path().join("tables/old")).unwrap();
        fs::write(d.path().join("tables/old/c.parquet"), b"z").unwrap();
        assert!(matches!(
            table_dir(d.path(), "old").unwrap(),
            TableDir::Plain(_)
        ));
        migrate_plain(d.path(), "old").unwrap();
        assert!(d.path().join("tables/old/c.parquet").exists());
        assert!(matches!(
            table_dir(d.path(), "old").unwrap(),
            TableDir::Generation { gen: 0, .. }
        ));
    }

    #[test]
    fn a_foreign_link_is_an_error() {
        let d = tempfile::tempdir().unwrap();
        fs::create_dir_all(d.path().join("tables/elsewhere")).unwrap();
        std::os::unix::fs::symlink("elsewhere", d.path().join("tables/runs")).unwrap();
        let e = table_dir(d.path(), "runs").unwrap_err();
        assert!(e.to_string().contains("not to a generation"), "{e}");
    }
}
