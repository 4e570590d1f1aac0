//! A campaign's tables as the storage sees them: a directory per table under `tables/`
//! (see [`super::layout`]), each file stamped with the campaign's identity (name, model,
//! seed) and the manifest it was written under, and read back only if it is this campaign's
//! and this table's. A table is read only through granular's own generation link, and only
//! its regular files: a link out of the campaign directory is never followed (an error naming
//! it; `campaign::integrity` names it as damage and `granular resume` sets it aside).

use std::path::{Path, PathBuf};

use arrow_array::RecordBatch;

use super::checksum;
use super::layout;
use super::parquet_io::{self, Stamp, StoreError};
use crate::fsutil::{self, Dir, Kind};

/// How many times [`Dataset::read`] lists a table again when one of its files vanished
/// while it was read (20 ms, 40 ms, ... 640 ms apart: a compaction's switch takes
/// milliseconds).
pub const VANISHED_RETRIES: u32 = 5;

/// The tables of one campaign directory.
#[derive(Clone, Debug)]
pub struct Dataset {
    root: PathBuf,
    identity: String,
    manifest: String,
    /// Where tables written whole go instead of `root` (see [`Dataset::overlay`]).
    scratch: Option<PathBuf>,
}

impl Dataset {
    /// The tables under `root/tables` of the campaign whose identity is `identity`; files
    /// written are stamped with `manifest` (canonical JSON).
    pub fn new(root: &Path, identity: &str, manifest: &str) -> Self {
        Dataset {
            root: root.to_path_buf(),
            identity: identity.to_string(),
            manifest: manifest.to_string(),
            scratch: None,
        }
    }

    /// The same tables, but every table written whole goes to `scratch/tables` and is read
    /// back from there; the other tables are read from the campaign. What a report of an
    /// unfinished campaign uses to compute summaries of the runs finished so far without
    /// writing into the campaign directory.
    pub fn overlay(&self, scratch: &Path) -> Self {
        Dataset {
            scratch: Some(scratch.to_path_buf()),
            ..self.clone()
        }
    }

    /// The directory tables are written to: the scratch directory of an overlay, else the
    /// campaign's.
    fn write_root(&self) -> &Path {
        self.scratch.as_deref().unwrap_or(&self.root)
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The stamp of the files this dataset writes.
    pub fn stamp(&self) -> Stamp<'_> {
        Stamp {
            campaign: &self.identity,
            manifest: &self.manifest,
            commit: None,
        }
    }

    /// `root/tables/<table>` (through the table's generation link); for an overlay, the
    /// scratch directory's when the table was written there.
    pub fn dir(&self, table: &str) -> PathBuf {
        if let Some(s) = &self.scratch {
            let d = s.join("tables").join(table);
            if std::fs::symlink_metadata(&d).is_ok() {
                return d;
            }
        }
        self.root.join("tables").join(table)
    }

    /// Create the table's directory (where it is written) if it does not exist.
    pub fn ensure(&self, table: &str) -> Result<(), StoreError> {
        let root = self.write_root();
        layout::ensure_table_dir(root, table)
            .map(|_| ())
            .map_err(|e| StoreError::io(&root.join("tables").join(table), e))
    }

    /// The table's directory, opened as [`layout::open_table`] does (`None`: it has none).
    fn open_dir(&self, table: &str) -> Result<Option<Dir>, StoreError> {
        let dir = self.dir(table);
        // `dir` is `<root>/tables/<table>`: the root the table is read from.
        let root = dir.parent().and_then(|t| t.parent()).unwrap_or(&self.root);
        let rd = match Dir::open(root) {
            Ok(d) => d,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(StoreError::io(root, e)),
        };
        layout::open_table(&rd, table).map_err(|e| parquet_io::open_error(&dir, e))
    }

    /// The table's visible Parquet files, sorted (hidden and pending files excluded; a
    /// missing directory has none). Only regular files are listed; a table directory that is
    /// not granular's own (a link out) is an error naming it.
    pub fn files(&self, table: &str) -> Result<Vec<PathBuf>, StoreError> {
        let dir = self.dir(table);
        let Some(d) = self.open_dir(table)? else {
            return Ok(Vec::new());
        };
        let entries = d.entries().map_err(|e| StoreError::io(&dir, e))?;
        Ok(entries
            .into_iter()
            .filter(|(n, k)| *k == Kind::File && !n.starts_with('.') && n.ends_with(".parquet"))
            .map(|(n, _)| dir.join(n))
            .collect())
    }

    /// Every batch of one file of `table`, checked to be this campaign's.
    pub fn read_file(&self, path: &Path, table: &str) -> Result<Vec<RecordBatch>, StoreError> {
        parquet_io::read_campaign_file(path, table, &self.identity)
    }

    /// Every batch of every file of `table`. A file that vanishes between the listing and its
    /// reading (a `granular compact` in another process replaced the table's generation: the
    /// same rows in other files) makes the table be listed and read again, up to
    /// [`VANISHED_RETRIES`] times (found by the race drill: a `plan` beside a compaction
    /// failed with exit 4).
    pub fn read(&self, table: &str) -> Result<Vec<RecordBatch>, StoreError> {
        let mut attempt = 0;
        loop {
            match self.read_listed(table) {
                Err(StoreError::Io { source, .. })
                    if source.kind() == std::io::ErrorKind::NotFound
                        && attempt < VANISHED_RETRIES =>
                {
                    attempt += 1;
                    std::thread::sleep(std::time::Duration::from_millis(20 << attempt));
                }
                r => return r,
            }
        }
    }

    fn read_listed(&self, table: &str) -> Result<Vec<RecordBatch>, StoreError> {
        let mut out = Vec::new();
        for f in self.files(table)? {
            out.extend(self.read_file(&f, table)?);
        }
        Ok(out)
    }

    /// Whether `tables/<table>/<name>` exists (a regular file of granular's own table
    /// directory).
    pub fn has(&self, table: &str, name: &str) -> bool {
        matches!(self.open_dir(table), Ok(Some(d)) if d.kind(name).ok().flatten() == Some(Kind::File))
    }

    /// Write `tables/<table>/<name>` atomically (write, fsync, its checksum sidecar, rename,
    /// fsync the directory): a whole table in one file, replacing an earlier one. Such tables
    /// are rebuilt from others (points, theory, summaries); the sidecar lets a check tell a
    /// damaged one (see `checksum`).
    pub fn write_whole(
        &self,
        table: &str,
        name: &str,
        batch: &RecordBatch,
    ) -> Result<(), StoreError> {
        self.ensure(table)?;
        let path = self.write_root().join("tables").join(table).join(name);
        let tmp = fsutil::temp_path(&path);
        let w = parquet_io::write_file(&tmp, batch, table, self.stamp())?;
        if let Err(e) = checksum::write_sidecar(self.write_root(), table, name, w.bytes, &w.sha256)
        {
            let _ = std::fs::remove_file(&tmp);
            return Err(StoreError::io(&path, e));
        }
        std::fs::rename(&tmp, &path).map_err(|e| StoreError::io(&path, e))?;
        fsutil::sync_dir(path.parent().expect("dir")).map_err(|e| StoreError::io(&path, e))
    }
}
