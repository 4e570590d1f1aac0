//! A campaign's tables as the storage sees them: a directory per table under `tables/`
//! (see [`super::layout`]), each file stamped with the campaign's identity (name, model,
//! seed) and the manifest it was written under, and read back only if it is this campaign's
//! and this table's.

use std::path::{Path, PathBuf};

use arrow_array::RecordBatch;

use super::checksum;
use super::layout;
use super::parquet_io::{self, Stamp, StoreError};
use crate::fsutil;

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

    /// The table's visible Parquet files, sorted (hidden and pending files excluded; a
    /// missing directory has none).
    pub fn files(&self, table: &str) -> Result<Vec<PathBuf>, StoreError> {
        let dir = self.dir(table);
        let mut files: Vec<PathBuf> = match std::fs::read_dir(&dir) {
            Ok(it) => it
                .filter_map(|e| e.ok())
                .map(|e| e.path())
                .filter(|p| {
                    let n = p
                        .file_name()
                        .map(|n| n.to_string_lossy().into_owned())
                        .unwrap_or_default();
                    !n.starts_with('.') && n.ends_with(".parquet")
                })
                .collect(),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
            Err(e) => return Err(StoreError::io(&dir, e)),
        };
        files.sort();
        Ok(files)
    }

    /// Every batch of one file of `table`, checked to be this campaign's.
    pub fn read_file(&self, path: &Path, table: &str) -> Result<Vec<RecordBatch>, StoreError> {
        parquet_io::read_campaign_file(path, table, &self.identity)
    }

    /// Every batch of every file of `table`.
    pub fn read(&self, table: &str) -> Result<Vec<RecordBatch>, StoreError> {
        let mut out = Vec::new();
        for f in self.files(table)? {
            out.extend(self.read_file(&f, table)?);
        }
        Ok(out)
    }

    /// Whether `tables/<table>/<name>` exists.
    pub fn has(&self, table: &str, name: &str) -> bool {
        self.dir(table).join(name).exists()
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
