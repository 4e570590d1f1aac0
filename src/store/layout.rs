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

use std::io;
use std::path::{Component, Path, PathBuf};

use crate::fsutil::{self, Dir, Kind, NotOwn};

/// Directory of the generations, inside `tables/`.
pub const GEN_DIR: &str = ".gen";

/// The generation directory's name of `table` at generation `gen`.
pub fn generation_name(table: &str, gen: u64) -> String {
    format!("{table}.{gen:08}")
}

/// The generation a link `tables/<table>` names, with its directory's name, if it names one
/// of `table` as granular writes them: exactly `.gen/<table>.<digits>` (relative, inside
/// `tables/`). Any other target is not granular's link.
pub fn generation_of(table: &str, target: &Path) -> Option<(u64, String)> {
    let mut c = target.components();
    let (Some(Component::Normal(a)), Some(Component::Normal(b)), None) =
        (c.next(), c.next(), c.next())
    else {
        return None;
    };
    if a != GEN_DIR {
        return None;
    }
    let name = b.to_str()?;
    let digits = name.strip_prefix(table)?.strip_prefix('.')?;
    if digits.is_empty() || !digits.bytes().all(|x| x.is_ascii_digit()) {
        return None;
    }
    Some((digits.parse().ok()?, name.to_string()))
}

/// The refusal of a link `tables/<table>` that is not granular's generation link.
fn foreign_link(tables: &Dir, table: &str, target: &Path) -> io::Error {
    NotOwn {
        path: tables.path().join(table),
        found: format!(
            "a symbolic link to {}, not to a generation of table {table} ({GEN_DIR}/{table}.<n>)",
            target.display()
        ),
        expected: "table directory",
    }
    .into_io()
}

/// The table directory `table` of the opened `tables/`: a plain directory, or granular's
/// link to a generation (`.gen/<table>.<n>`, itself and `.gen` opened without following
/// links), named `tables/<table>` in messages. `None` if there is none, or the generation
/// it links to is not there; any other link, or a file, is refused ([`NotOwn`]). The only
/// link granular follows, and only inside the campaign directory.
pub fn open_table_at(tables: &Dir, table: &str) -> io::Result<Option<Dir>> {
    match tables.kind(table)? {
        None => Ok(None),
        Some(Kind::Dir) => tables.sub(table),
        Some(Kind::Link) => {
            let target = tables.read_link(table)?;
            let Some((_, name)) = generation_of(table, &target) else {
                return Err(foreign_link(tables, table, &target));
            };
            let Some(gens) = tables.sub(GEN_DIR)? else {
                return Ok(None);
            };
            Ok(gens.sub(&name)?.map(|d| d.named(tables.path().join(table))))
        }
        Some(k) => Err(tables.not_own(table, k, "table directory")),
    }
}

/// The table directory `tables/<table>` of the campaign directory `root` (see
/// [`open_table_at`]); `None` if there is none.
pub fn open_table(root: &Dir, table: &str) -> io::Result<Option<Dir>> {
    match root.sub("tables")? {
        Some(tables) => open_table_at(&tables, table),
        None => Ok(None),
    }
}

/// Whether `rel` names a file of a table as commits record them: `tables/<table>/<name>`, plain
/// names (none empty, `.`, `..` or hidden). A record naming anything else is not granular's.
pub fn is_table_file(rel: &str) -> bool {
    let parts: Vec<&str> = rel.split('/').collect();
    parts.len() == 3
        && parts[0] == "tables"
        && parts[1..]
            .iter()
            .all(|p| !p.is_empty() && !p.starts_with('.') && !p.contains('\0'))
}

/// `rel` (a path relative to the campaign directory) split into its directory and its last
/// name.
pub fn split(rel: &str) -> (&str, &str) {
    rel.rsplit_once('/').unwrap_or(("", rel))
}

/// The directory `rel` of the campaign directory `root`, walked without following any link
/// but a table's generation link (`tables/<t>/...`: [`open_table_at`]); `None` if something
/// on the way is missing, a [`NotOwn`] refusal if something on the way is not granular's own.
pub fn walk(root: &Dir, rel: &str) -> io::Result<Option<Dir>> {
    let parts: Vec<&str> = rel.split('/').filter(|p| !p.is_empty()).collect();
    match parts.as_slice() {
        ["tables", t, rest @ ..] if !t.starts_with('.') => {
            let Some(mut d) = open_table(root, t)? else {
                return Ok(None);
            };
            for p in rest {
                match d.sub(p)? {
                    Some(x) => d = x,
                    None => return Ok(None),
                }
            }
            Ok(Some(d))
        }
        _ => root.walk(rel),
    }
}

/// The regular file `rel` of the campaign directory `root`, opened for reading as by
/// [`walk`] and `O_NOFOLLOW`; `None` if it is not there.
pub fn open_file(root: &Dir, rel: &str) -> io::Result<Option<std::fs::File>> {
    let (parent, name) = split(rel);
    match walk(root, parent)? {
        Some(d) => d.open_file(name),
        None => Ok(None),
    }
}

/// Create `tables/<table>` as a link to a new generation unless the table exists (as
/// granular's link, or as a plain directory made by an older granular). Safe to call from
/// several processes. The generation is 0, or, where generations of the table are left
/// (its link was set aside as damage), the newest of them if empty, else the next: a new
/// table never shows files it did not write. A link that is not granular's, `tables` or
/// `.gen` not granular's own directories, or a link to a generation that is not there, is
/// refused ([`NotOwn`]): nothing is created or written through a link.
pub fn ensure_table_dir(root: &Path, table: &str) -> io::Result<PathBuf> {
    fsutil::create_dir_durable(root)?;
    let rd = Dir::open(root)?;
    let tables = rd.create_dir("tables")?;
    let link = root.join("tables").join(table);
    let exists = |tables: &Dir| -> io::Result<bool> {
        if tables.kind(table)?.is_none() {
            return Ok(false);
        }
        match open_table_at(tables, table)? {
            Some(_) => Ok(true),
            None => Err(NotOwn {
                path: link.clone(),
                found: format!(
                    "{}, a generation that is not there",
                    tables.describe(table, Kind::Link)
                ),
                expected: "table directory",
            }
            .into_io()),
        }
    };
    if exists(&tables)? {
        return Ok(link);
    }
    let gens = tables.create_dir(GEN_DIR)?;
    let mut newest: Option<u64> = None;
    for (name, _) in gens.entries()? {
        if let Some(g) = name
            .strip_prefix(&format!("{table}."))
            .filter(|d| !d.is_empty() && d.bytes().all(|x| x.is_ascii_digit()))
            .and_then(|d| d.parse::<u64>().ok())
        {
            newest = Some(newest.map_or(g, |n: u64| n.max(g)));
        }
    }
    let gen = match newest {
        None => 0,
        Some(g) => {
            let empty = gens
                .sub(&generation_name(table, g))
                .ok()
                .flatten()
                .and_then(|d| d.entries().ok())
                .is_some_and(|e| e.is_empty());
            if empty {
                g
            } else {
                g + 1
            }
        }
    };
    let name = generation_name(table, gen);
    gens.create_dir(&name)?;
    match tables.symlink(&Path::new(GEN_DIR).join(&name), table) {
        Ok(()) => tables.sync()?,
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {
            exists(&tables)?;
        }
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

/// Where the table's files are (the generation its link names, which may be missing). A link
/// that is not granular's, or `tables` not granular's own directory, is refused ([`NotOwn`]).
pub fn table_dir(root: &Path, table: &str) -> io::Result<TableDir> {
    let link = root.join("tables").join(table);
    let tables = Dir::open(root)?
        .sub("tables")?
        .ok_or_else(|| io::Error::from_raw_os_error(libc::ENOENT))?;
    match tables.kind(table)? {
        None => Err(io::Error::from_raw_os_error(libc::ENOENT)),
        Some(Kind::Dir) => Ok(TableDir::Plain(link)),
        Some(Kind::Link) => {
            let target = tables.read_link(table)?;
            let (gen, name) = generation_of(table, &target)
                .ok_or_else(|| foreign_link(&tables, table, &target))?;
            Ok(TableDir::Generation {
                gen,
                dir: root.join("tables").join(GEN_DIR).join(name),
            })
        }
        Some(k) => Err(tables.not_own(table, k, "table directory")),
    }
}

/// The tables of a campaign: the names in `tables/` that are not hidden and are plain table
/// directories or granular's links to generations that are there. Anything else there (a
/// link out, a file) is not a table: `campaign::integrity` names it. None when `tables` is
/// missing or not granular's own directory.
pub fn table_names(root: &Path) -> io::Result<Vec<String>> {
    let rd = match Dir::open(root) {
        Ok(d) => d,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(e),
    };
    let tables = match rd.sub("tables") {
        Ok(Some(t)) => t,
        Ok(None) => return Ok(Vec::new()),
        Err(e) if fsutil::not_own(&e).is_some() => return Ok(Vec::new()),
        Err(e) => return Err(e),
    };
    let mut v = Vec::new();
    for (name, _) in tables.entries()? {
        if name.starts_with('.') {
            continue;
        }
        match open_table_at(&tables, &name) {
            Ok(Some(_)) => v.push(name),
            Ok(None) => {}
            Err(e) if fsutil::not_own(&e).is_some() => {}
            Err(e) => return Err(e),
        }
    }
    Ok(v)
}

/// Make generation `gen` (a complete directory under `.gen`) the table's current one: a new
/// link is written beside `tables/<t>` and renamed over it (the atomic step), in `tables`
/// opened without following a link.
pub fn publish_generation(root: &Path, table: &str, gen: u64) -> io::Result<()> {
    let tables = Dir::open(root)?
        .sub("tables")?
        .ok_or_else(|| io::Error::from_raw_os_error(libc::ENOENT))?;
    let name = generation_name(table, gen);
    let tmp = fsutil::temp_name(table);
    tables.symlink(&Path::new(GEN_DIR).join(&name), &tmp)?;
    if let Err(e) = tables.rename(&tmp, &tables, table) {
        let _ = tables.remove_file(&tmp);
        return Err(e);
    }
    tables.sync()
}

/// Turn a plain table directory into generation 0 behind a link. Not atomic for readers: for
/// an instant `tables/<t>` does not exist (a reader then fails to find the table; it never sees
/// partial data). New campaigns never need this.
pub fn migrate_plain(root: &Path, table: &str) -> io::Result<()> {
    let tables = Dir::open(root)?
        .sub("tables")?
        .ok_or_else(|| io::Error::from_raw_os_error(libc::ENOENT))?;
    match tables.kind(table)? {
        Some(Kind::Dir) => {}
        Some(k) => return Err(tables.not_own(table, k, "table directory")),
        None => return Err(io::Error::from_raw_os_error(libc::ENOENT)),
    }
    let gens = tables.create_dir(GEN_DIR)?;
    let name = generation_name(table, 0);
    if !tables.rename(table, &gens, &name)? {
        return Err(io::Error::from_raw_os_error(libc::ENOENT));
    }
    tables.symlink(&Path::new(GEN_DIR).join(&name), table)?;
    gens.sync()?;
    tables.sync()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fs;

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
    fn only_granulars_own_generation_links_are_followed() {
        let d = tempfile::tempdir().unwrap();
        let out = tempfile::tempdir().unwrap();
        std::fs::write(out.path().join("secret"), b"s").unwrap();
        ensure_table_dir(d.path(), "runs").unwrap();
        fs::create_dir_all(d.path().join("tables/.gen/x.00000001")).unwrap();
        std::os::unix::fs::symlink(out.path(), d.path().join("tables/evil")).unwrap();
        std::os::unix::fs::symlink(".gen/x.00000001", d.path().join("tables/x")).unwrap();
        std::os::unix::fs::symlink(".gen/gone.00000004", d.path().join("tables/gone")).unwrap();
        std::os::unix::fs::symlink("../../elsewhere", d.path().join("tables/up")).unwrap();
        let root = Dir::open(d.path()).unwrap();
        assert!(open_table(&root, "runs").unwrap().is_some());
        assert!(open_table(&root, "x").unwrap().is_some());
        assert!(open_table(&root, "gone").unwrap().is_none());
        for t in ["evil", "up"] {
            let e = open_table(&root, t).unwrap_err();
            assert!(fsutil::not_own(&e).is_some(), "{e}");
            assert!(e.to_string().contains("not to a generation"), "{e}");
            assert!(ensure_table_dir(d.path(), t).is_err());
        }
        assert!(ensure_table_dir(d.path(), "gone").is_err());
        assert_eq!(table_names(d.path()).unwrap(), vec!["runs", "x"]);
        assert!(walk(&root, "tables/evil/a").is_err());
        assert!(open_file(&root, "tables/evil/secret").is_err());
        // `.gen` a link out: nothing behind it is a table.
        fs::rename(d.path().join("tables/.gen"), d.path().join("gen-moved")).unwrap();
        std::os::unix::fs::symlink(d.path().join("gen-moved"), d.path().join("tables/.gen"))
            .unwrap();
        assert!(open_table(&root, "runs").is_err());
        assert!(table_names(d.path()).unwrap().is_empty());
        // `tables` a link out: no tables, nothing created through it.
        fs::rename(d.path().join("tables"), d.path().join("tables-moved")).unwrap();
        std::os::unix::fs::symlink(out.path(), d.path().join("tables")).unwrap();
        assert!(table_names(d.path()).unwrap().is_empty());
        assert!(ensure_table_dir(d.path(), "runs").is_err());
        assert_eq!(std::fs::read_dir(out.path()).unwrap().count(), 1);
    }

    #[test]
    fn a_table_whose_link_was_set_aside_gets_a_new_generation() {
        let d = tempfile::tempdir().unwrap();
        let link = ensure_table_dir(d.path(), "runs").unwrap();
        fs::write(link.join("a.parquet"), b"x").unwrap();
        fs::remove_file(d.path().join("tables/runs")).unwrap();
        ensure_table_dir(d.path(), "runs").unwrap();
        assert!(matches!(
            table_dir(d.path(), "runs").unwrap(),
            TableDir::Generation { gen: 1, .. }
        ));
        assert!(!d.path().join("tables/runs/a.parquet").exists());
        // An empty newest generation is used again.
        fs::remove_file(d.path().join("tables/runs")).unwrap();
        ensure_table_dir(d.path(), "runs").unwrap();
        assert!(matches!(
            table_dir(d.path(), "runs").unwrap(),
            TableDir::Generation { gen: 1, .. }
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
