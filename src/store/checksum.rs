//! Strong checksums of the files a campaign commits: SHA-256 (what `sha256sum` prints) and the
//! size, computed while a file is written (no second read) and checked by `granular verify`.
//!
//! Files written whole outside a commit (a table that is rebuilt from others: points, theory,
//! summaries) have their checksum in a sidecar, `sums/<table>/<name>.sum.json` beside
//! `tables/` (not inside it: a table's directory holds Parquet files only, so that
//! `polars.read_parquet(dir)` reads it), written after the file's bytes are durable and before
//! it is renamed into place.

use std::fs::File;
use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::fsutil::{self, Dir, Kind};

/// A file's size and SHA-256, as recorded in a commit or a sidecar.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq, Eq)]
pub struct FileSum {
    /// Relative to the campaign directory (commit records) or the file's name (sidecars).
    pub path: String,
    pub bytes: u64,
    /// Lower-case hex.
    pub sha256: String,
}

/// A writer that hashes and counts what passes through it.
pub struct HashingWriter<W: Write> {
    inner: W,
    hasher: Sha256,
    bytes: u64,
}

impl<W: Write> HashingWriter<W> {
    pub fn new(inner: W) -> Self {
        HashingWriter {
            inner,
            hasher: Sha256::new(),
            bytes: 0,
        }
    }

    /// The inner writer, the byte count and the hex digest of everything written.
    pub fn finish(self) -> (W, u64, String) {
        (self.inner, self.bytes, hex(&self.hasher.finalize()))
    }
}

impl<W: Write> Write for HashingWriter<W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.hasher.update(&buf[..n]);
        self.bytes += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

fn hex(d: &[u8]) -> String {
    use std::fmt::Write as _;
    let mut s = String::with_capacity(d.len() * 2);
    for b in d {
        let _ = write!(s, "{b:02x}");
    }
    s
}

/// Size and SHA-256 of the regular file at `path` (read whole; a link at `path` is refused,
/// not followed: `fsutil::open_regular`).
pub fn sum_file(path: &Path) -> io::Result<(u64, String)> {
    sum_reader(fsutil::open_regular(path)?)
}

/// Size and SHA-256 of everything `f` reads.
pub fn sum_reader(mut f: impl Read) -> io::Result<(u64, String)> {
    let mut h = Sha256::new();
    let mut buf = vec![0u8; 1 << 20];
    let mut bytes = 0u64;
    loop {
        let n = f.read(&mut buf)?;
        if n == 0 {
            break;
        }
        h.update(&buf[..n]);
        bytes += n as u64;
    }
    Ok((bytes, hex(&h.finalize())))
}

/// How a file compares with its record.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Mismatch {
    Missing,
    Size {
        found: u64,
    },
    Checksum {
        found: String,
    },
    /// Not a regular file of granular's own (a symbolic link, not followed): what is there.
    NotOwn(String),
}

impl std::fmt::Display for Mismatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Mismatch::Missing => write!(f, "missing"),
            Mismatch::Size { found } => write!(f, "{found} bytes"),
            Mismatch::Checksum { found } => write!(f, "SHA-256 {found}"),
            Mismatch::NotOwn(what) => write!(f, "{what}"),
        }
    }
}

/// Check the file at `path` against `rec`: its size only (`full` false) or its SHA-256 too.
/// A link at `path` is not followed: it is a mismatch ([`Mismatch::NotOwn`]).
pub fn check(path: &Path, rec: &FileSum, full: bool) -> io::Result<Option<Mismatch>> {
    match fsutil::open_regular(path) {
        Ok(f) => check_open(f, rec, full),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(Some(Mismatch::Missing)),
        Err(e) => match fsutil::not_own(&e) {
            Some(n) => Ok(Some(Mismatch::NotOwn(n.what()))),
            None => Err(e),
        },
    }
}

/// Check the opened file `f` against `rec` (see [`check`]).
pub fn check_open(f: File, rec: &FileSum, full: bool) -> io::Result<Option<Mismatch>> {
    let len = f.metadata()?.len();
    if len != rec.bytes {
        return Ok(Some(Mismatch::Size { found: len }));
    }
    if !full {
        return Ok(None);
    }
    let (_, sum) = sum_reader(f)?;
    Ok((sum != rec.sha256).then_some(Mismatch::Checksum { found: sum }))
}

/// The sidecar of the table file `tables/<table>/<name>` of the campaign at `root`:
/// `sums/<table>/<name>.sum.json`.
pub fn sidecar_path(root: &Path, table: &str, name: &str) -> PathBuf {
    root.join("sums")
        .join(table)
        .join(format!("{name}.sum.json"))
}

/// Version of the sidecar files.
pub const SIDECAR_FORMAT: u32 = 1;
const SIDECAR_KIND: &str = "granular.file_sum";

#[derive(Serialize, Deserialize)]
struct Sidecar {
    format_version: u32,
    kind: String,
    #[serde(flatten)]
    sum: FileSum,
}

/// Write the sidecar of `tables/<table>/<name>` (atomically; `sums/` and its directories
/// must be directories of granular's own: a link there is refused, nothing written through
/// it).
pub fn write_sidecar(
    root: &Path,
    table: &str,
    name: &str,
    bytes: u64,
    sha256: &str,
) -> io::Result<()> {
    let s = Sidecar {
        format_version: SIDECAR_FORMAT,
        kind: SIDECAR_KIND.into(),
        sum: FileSum {
            path: format!("tables/{table}/{name}"),
            bytes,
            sha256: sha256.into(),
        },
    };
    Dir::open(root)?
        .create_dir("sums")?
        .create_dir(table)?
        .write_atomic(
            &format!("{name}.sum.json"),
            &serde_json::to_vec(&s).expect("sidecar serialises"),
        )
}

/// The directory `sums/<table>` of the campaign directory `root`, if it is granular's own.
fn sums_dir(root: &Path, table: &str) -> Option<Dir> {
    Dir::open(root).ok()?.walk(&format!("sums/{table}")).ok()?
}

/// The record in the sidecar of `tables/<table>/<name>`; `None` if there is none or it is not
/// readable (a file without a valid sidecar cannot be trusted; a link is not read).
pub fn read_sidecar(root: &Path, table: &str, name: &str) -> Option<FileSum> {
    let text = sums_dir(root, table)?
        .read(&format!("{name}.sum.json"))
        .ok()??;
    let s: Sidecar = serde_json::from_slice(&text).ok()?;
    (s.kind == SIDECAR_KIND && s.format_version == SIDECAR_FORMAT).then_some(s.sum)
}

/// Remove the sidecar of `tables/<table>/<name>` (a link there is removed itself); false if
/// there was none.
pub fn remove_sidecar(root: &Path, table: &str, name: &str) -> io::Result<bool> {
    match Dir::open(root)?.walk(&format!("sums/{table}"))? {
        Some(d) => d.remove_file(&format!("{name}.sum.json")),
        None => Ok(false),
    }
}

/// The table files that have a sidecar: (table, name). Links in `sums/` are not followed.
pub fn sidecars(root: &Path) -> Vec<(String, String)> {
    let mut v = Vec::new();
    let Some(sums) = Dir::open(root)
        .ok()
        .and_then(|d| d.sub("sums").ok().flatten())
    else {
        return v;
    };
    for (table, kind) in sums.entries().unwrap_or_default() {
        if kind != Kind::Dir {
            continue;
        }
        let Ok(Some(t)) = sums.sub(&table) else {
            continue;
        };
        for (n, kind) in t.entries().unwrap_or_default() {
            if kind != Kind::File {
                continue;
            }
            if let Some(name) = n.strip_suffix(".sum.json") {
                if !name.starts_with('.') {
                    v.push((table.clone(), name.to_string()));
                }
            }
        }
    }
    v.sort();
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sha256_of_known_input_and_hashing_writer_agree() {
        // FIPS 180-2 test vector.
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("abc");
        let mut w = HashingWriter::new(File::create(&p).unwrap());
        w.write_all(b"abc").unwrap();
        let (_, bytes, sum) = w.finish();
        assert_eq!(bytes, 3);
        assert_eq!(
            sum,
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        assert_eq!(sum_file(&p).unwrap(), (3, sum.clone()));
        let rec = FileSum {
            path: "abc".into(),
            bytes: 3,
            sha256: sum,
        };
        assert_eq!(check(&p, &rec, true).unwrap(), None);
        std::fs::write(&p, b"abd").unwrap();
        assert_eq!(
            check(&p, &rec, false).unwrap(),
            None,
            "same size: quick passes"
        );
        assert!(matches!(
            check(&p, &rec, true).unwrap(),
            Some(Mismatch::Checksum { .. })
        ));
        std::fs::write(&p, b"abcd").unwrap();
        assert_eq!(
            check(&p, &rec, false).unwrap(),
            Some(Mismatch::Size { found: 4 })
        );
        std::fs::remove_file(&p).unwrap();
        assert_eq!(check(&p, &rec, false).unwrap(), Some(Mismatch::Missing));
    }

    #[test]
    fn sidecars_round_trip_and_garbage_is_no_record() {
        let d = tempfile::tempdir().unwrap();
        write_sidecar(d.path(), "t", "summary.parquet", 10, "00ff").unwrap();
        let s = read_sidecar(d.path(), "t", "summary.parquet").unwrap();
        assert_eq!((s.bytes, s.sha256.as_str()), (10, "00ff"));
        assert_eq!(s.path, "tables/t/summary.parquet");
        assert_eq!(
            sidecars(d.path()),
            vec![("t".to_string(), "summary.parquet".to_string())]
        );
        std::fs::write(sidecar_path(d.path(), "t", "summary.parquet"), b"{not json").unwrap();
        assert_eq!(read_sidecar(d.path(), "t", "summary.parquet"), None);
        // A sidecar that is a link (to a valid one elsewhere) is not read, nor listed.
        let e = tempfile::tempdir().unwrap();
        write_sidecar(e.path(), "t", "x.parquet", 1, "00").unwrap();
        std::fs::remove_file(sidecar_path(d.path(), "t", "summary.parquet")).unwrap();
        std::os::unix::fs::symlink(
            sidecar_path(e.path(), "t", "x.parquet"),
            sidecar_path(d.path(), "t", "summary.parquet"),
        )
        .unwrap();
        assert_eq!(read_sidecar(d.path(), "t", "summary.parquet"), None);
        assert!(sidecars(d.path()).is_empty());
        // `sums` a link: nothing written through it.
        let f = tempfile::tempdir().unwrap();
        std::os::unix::fs::symlink(e.path().join("sums"), f.path().join("sums")).unwrap();
        assert!(write_sidecar(f.path(), "t", "y.parquet", 1, "00").is_err());
        assert!(!sidecar_path(e.path(), "t", "y.parquet").exists());
    }
}
