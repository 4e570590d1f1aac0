//! Parquet files: one function builds the writer properties (compression, created_by,
//! key-value metadata); parts are written to a hidden temporary name, fsynced and renamed.

use std::collections::HashMap;
use std::fs::File;
use std::path::Path;
use std::sync::Arc;

use arrow_array::RecordBatch;
use arrow_schema::Schema;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::arrow::ArrowWriter;
use parquet::basic::{Compression, ZstdLevel};
use parquet::file::metadata::KeyValue;
use parquet::file::properties::WriterProperties;

use super::checksum::HashingWriter;
use super::FORMAT_VERSION;
use crate::CODE_VERSION;

/// Formats of table files this granular reads (format 1's tables are format 2's, but for
/// the sweep columns of `runs`, which an upgrade removes; format 3's are format 2's, with the
/// commit in a part's footer).
pub const READABLE_FORMATS: [u32; 3] = [1, 2, FORMAT_VERSION];

/// Whose a table file is: the campaign's identity (name, model, seed: what a campaign keeps
/// for ever) and the manifest it was written under (provenance).
#[derive(Clone, Copy, Debug)]
pub struct Stamp<'a> {
    pub campaign: &'a str,
    pub manifest: &'a str,
    /// For a committed part: its commit (shard, sequence number, the commit's tables, as
    /// JSON), from which a lost ledger is rebuilt (see `campaign::integrity`).
    pub commit: Option<&'a str>,
}

/// Key-value metadata of every table file.
pub fn file_metadata(table: &str, stamp: Stamp) -> Vec<(String, String)> {
    let mut v: Vec<(String, String)> = vec![
        ("granular.format_version".into(), FORMAT_VERSION.to_string()),
        ("granular.table".into(), table.into()),
        ("granular.code_version".into(), CODE_VERSION.into()),
        ("granular.campaign".into(), stamp.campaign.into()),
        ("granular.manifest".into(), stamp.manifest.into()),
    ];
    if let Some(commit) = stamp.commit {
        v.push(("granular.commit".into(), commit.into()));
    }
    v
}

/// Tables of at most this many values (rows x columns, over all batches) are written
/// uncompressed. Below it zstd saves nothing (its frames make a file of a few hundred values
/// larger: a 40-value `registered_runs` 3 589 bytes with zstd, 3 297 without), and every
/// column chunk made its own zstd compression and decompression contexts, each asking the
/// CPU for its features (`cpuid`: ~8 us in a virtual machine, ~50 us a column): ~2 ms of a
/// small MD run's 25.
pub const UNCOMPRESSED_MAX_VALUES: usize = 2048;

/// How a table file of `values` values (rows x columns) is compressed: zstd level 3, or none
/// for a small one ([`UNCOMPRESSED_MAX_VALUES`]). Decided by the content alone, so the same
/// rows make the same file.
pub fn compression_for(values: usize) -> Compression {
    if values <= UNCOMPRESSED_MAX_VALUES {
        Compression::UNCOMPRESSED
    } else {
        Compression::ZSTD(ZstdLevel::try_new(3).expect("valid level"))
    }
}

/// The writer properties of every table file, for a file of `values` values.
pub fn writer_properties(table: &str, stamp: Stamp, values: usize) -> WriterProperties {
    WriterProperties::builder()
        .set_compression(compression_for(values))
        .set_created_by(CODE_VERSION.to_string())
        .set_key_value_metadata(Some(
            file_metadata(table, stamp)
                .into_iter()
                .map(|(k, v)| KeyValue::new(k, v))
                .collect(),
        ))
        .set_max_row_group_row_count(Some(256 * 1024))
        .build()
}

/// The schema with the same metadata (pyarrow shows `schema.metadata`).
pub fn schema_with_metadata(schema: &Schema, table: &str, stamp: Stamp) -> Arc<Schema> {
    let md: HashMap<String, String> = file_metadata(table, stamp).into_iter().collect();
    Arc::new(schema.clone().with_metadata(md))
}

/// Size and SHA-256 of a file just written.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Written {
    pub bytes: u64,
    pub sha256: String,
}

/// Write `batch` as a Parquet file at `tmp` (fsynced). The caller renames it into place.
pub fn write_file(
    tmp: &Path,
    batch: &RecordBatch,
    table: &str,
    stamp: Stamp,
) -> Result<Written, StoreError> {
    write_batches(tmp, std::slice::from_ref(batch), table, stamp)
}

/// Write `batches` (one schema) as one Parquet file at `tmp` (fsynced), hashing it as it is
/// written. On failure (a full disk, say) the partial file is removed.
pub fn write_batches(
    tmp: &Path,
    batches: &[RecordBatch],
    table: &str,
    stamp: Stamp,
) -> Result<Written, StoreError> {
    let r = write_batches_inner(tmp, batches, table, stamp);
    if r.is_err() {
        let _ = std::fs::remove_file(tmp);
    }
    r
}

fn write_batches_inner(
    tmp: &Path,
    batches: &[RecordBatch],
    table: &str,
    stamp: Stamp,
) -> Result<Written, StoreError> {
    let Some(first) = batches.first() else {
        return Err(StoreError::Arrow(format!(
            "{}: no batches to write",
            tmp.display()
        )));
    };
    let schema = schema_with_metadata(first.schema().as_ref(), table, stamp);
    let file = HashingWriter::new(File::create(tmp).map_err(|e| StoreError::io(tmp, e))?);
    let values = batches
        .iter()
        .map(|b| b.num_rows().saturating_mul(b.num_columns()))
        .fold(0usize, usize::saturating_add);
    let props = writer_properties(table, stamp, values);
    let mut w = ArrowWriter::try_new(file, schema.clone(), Some(props))
        .map_err(|e| StoreError::Parquet(tmp.display().to_string(), e.to_string()))?;
    for batch in batches {
        let batch = batch
            .clone()
            .with_schema(schema.clone())
            .map_err(|e| StoreError::Arrow(e.to_string()))?;
        w.write(&batch)
            .map_err(|e| StoreError::Parquet(tmp.display().to_string(), e.to_string()))?;
    }
    let file = w
        .into_inner()
        .map_err(|e| StoreError::Parquet(tmp.display().to_string(), e.to_string()))?;
    let (file, bytes, sha256) = file.finish();
    file.sync_all().map_err(|e| StoreError::io(tmp, e))?;
    Ok(Written { bytes, sha256 })
}

/// What a table file says about itself (footer only; the data pages are not read).
#[derive(Debug, Clone, PartialEq)]
pub struct PartInfo {
    pub table: String,
    pub format_version: Option<u32>,
    /// The identity of the campaign the file was written for (name, model, seed: canonical
    /// JSON), from `granular.campaign`, or for files of format 1 from their manifest.
    pub campaign: Option<String>,
    /// Canonical JSON of the manifest the file was written under.
    pub manifest: Option<String>,
    pub code_version: Option<String>,
    /// The commit a committed part was written by (`granular.commit`, JSON), if recorded.
    pub commit: Option<String>,
    pub rows: u64,
}

/// Open a table file and read its footer: a truncated file, a file that is not Parquet, or a
/// Parquet file not written by granular is an error naming the file. A symbolic link at
/// `path` is not followed (nor is anything but a regular file opened): an error naming it.
pub fn inspect(
    path: &Path,
) -> Result<(PartInfo, ParquetRecordBatchReaderBuilder<File>), StoreError> {
    let file = crate::fsutil::open_regular(path).map_err(|e| open_error(path, e))?;
    inspect_file(file, path)
}

/// The error of a table file that could not be opened: one that is not granular's own (a
/// link, not followed) says so.
pub fn open_error(path: &Path, e: std::io::Error) -> StoreError {
    match crate::fsutil::not_own(&e) {
        Some(n) => StoreError::Corrupt(n.path.display().to_string(), format!("is {}", n.what())),
        None => StoreError::io(path, e),
    }
}

/// [`inspect`] of a file opened already (`path` names it in errors).
pub fn inspect_file(
    file: File,
    path: &Path,
) -> Result<(PartInfo, ParquetRecordBatchReaderBuilder<File>), StoreError> {
    let builder = ParquetRecordBatchReaderBuilder::try_new(file).map_err(|e| {
        StoreError::Corrupt(
            path.display().to_string(),
            format!("not a readable Parquet file (truncated or foreign?): {e}"),
        )
    })?;
    let kv = builder
        .metadata()
        .file_metadata()
        .key_value_metadata()
        .cloned()
        .unwrap_or_default();
    let get = |k: &str| kv.iter().find(|x| x.key == k).and_then(|x| x.value.clone());
    let Some(table) = get("granular.table") else {
        return Err(StoreError::Corrupt(
            path.display().to_string(),
            "is not a granular table file (no granular.table metadata)".into(),
        ));
    };
    let manifest = get("granular.manifest");
    let info = PartInfo {
        table,
        format_version: get("granular.format_version").and_then(|v| v.parse().ok()),
        campaign: get("granular.campaign").or_else(|| manifest.as_deref().and_then(identity_of)),
        manifest,
        code_version: get("granular.code_version"),
        commit: get("granular.commit"),
        rows: builder.metadata().file_metadata().num_rows().max(0) as u64,
    };
    Ok((info, builder))
}

/// A campaign's identity (name, model, seed as canonical JSON) from its manifest's JSON.
pub fn identity_of(manifest_json: &str) -> Option<String> {
    let m: serde_json::Value = serde_json::from_str(manifest_json).ok()?;
    let id = serde_json::json!({
        "model": m.get("model")?,
        "name": m.get("name")?,
        "seed": m.get("seed")?,
    });
    Some(id.to_string())
}

/// Check a file's footer against the expected table (and campaign identity, when given).
pub fn check_part(
    path: &Path,
    info: &PartInfo,
    table: &str,
    campaign: Option<&str>,
) -> Result<(), StoreError> {
    let bad = |why: String| Err(StoreError::Corrupt(path.display().to_string(), why));
    if info.table != table {
        return bad(format!("holds table {:?}, expected {table:?}", info.table));
    }
    if !info
        .format_version
        .is_some_and(|v| READABLE_FORMATS.contains(&v))
    {
        return bad(format!(
            "has format version {:?}; this granular reads {READABLE_FORMATS:?}",
            info.format_version
        ));
    }
    if let Some(id) = campaign {
        if info.campaign.as_deref() != Some(id) {
            return bad(format!(
                "belongs to another campaign ({}; this one is {id})",
                info.campaign.as_deref().unwrap_or("unknown")
            ));
        }
    }
    Ok(())
}

/// Read every batch of a table file of the campaign whose identity is `campaign`: a file of
/// another table, format or campaign is an error, never data.
pub fn read_campaign_file(
    path: &Path,
    table: &str,
    campaign: &str,
) -> Result<Vec<RecordBatch>, StoreError> {
    read_checked(path, table, Some(campaign))
}

/// Read every batch of a table file, checking that it is one of ours and of this format.
pub fn read_file(path: &Path, table: &str) -> Result<Vec<RecordBatch>, StoreError> {
    read_checked(path, table, None)
}

/// [`read_campaign_file`] of a file opened already (`path` names it in errors).
pub fn read_campaign_opened(
    file: File,
    path: &Path,
    table: &str,
    campaign: &str,
) -> Result<Vec<RecordBatch>, StoreError> {
    read_opened(inspect_file(file, path)?, path, table, Some(campaign))
}

fn read_checked(
    path: &Path,
    table: &str,
    campaign: Option<&str>,
) -> Result<Vec<RecordBatch>, StoreError> {
    read_opened(inspect(path)?, path, table, campaign)
}

fn read_opened(
    (info, builder): (PartInfo, ParquetRecordBatchReaderBuilder<File>),
    path: &Path,
    table: &str,
    campaign: Option<&str>,
) -> Result<Vec<RecordBatch>, StoreError> {
    check_part(path, &info, table, campaign)?;
    let reader = builder
        .build()
        .map_err(|e| StoreError::Corrupt(path.display().to_string(), e.to_string()))?;
    reader
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| StoreError::Corrupt(path.display().to_string(), e.to_string()))
}

#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("{path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("{0}: Parquet write failed: {1}")]
    Parquet(String, String),
    #[error("Arrow: {0}")]
    Arrow(String),
    #[error("{0} {1}")]
    Corrupt(String, String),
}

impl StoreError {
    pub fn io(path: &Path, source: std::io::Error) -> Self {
        StoreError::Io {
            path: path.display().to_string(),
            source,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arrow_array::{ArrayRef, Float64Array};
    use parquet::file::reader::{FileReader, SerializedFileReader};

    fn batch(rows: usize, columns: usize) -> RecordBatch {
        let cols: Vec<(String, ArrayRef)> = (0..columns)
            .map(|c| {
                let a: ArrayRef = Arc::new(Float64Array::from_iter_values(
                    (0..rows).map(|i| (i * columns + c) as f64 * 0.5),
                ));
                (format!("c{c}"), a)
            })
            .collect();
        RecordBatch::try_from_iter(cols).unwrap()
    }

    /// A table of at most `UNCOMPRESSED_MAX_VALUES` values (over all batches) is written
    /// uncompressed, one value more with zstd; both read back as written.
    #[test]
    fn small_tables_are_written_uncompressed() {
        let tmp = tempfile::tempdir().unwrap();
        let stamp = Stamp {
            campaign: "c",
            manifest: "m",
            commit: None,
        };
        let cols = 4;
        let at_limit = UNCOMPRESSED_MAX_VALUES / cols;
        for (batches, want) in [
            (vec![batch(at_limit, cols)], false),
            (vec![batch(at_limit - 1, cols), batch(1, cols)], false),
            (vec![batch(at_limit, cols), batch(1, cols)], true),
            (vec![batch(10 * at_limit, cols)], true),
        ] {
            let path = tmp.path().join("t.parquet");
            write_batches(&path, &batches, "t", stamp).unwrap();
            let r = SerializedFileReader::new(File::open(&path).unwrap()).unwrap();
            for rg in r.metadata().row_groups() {
                for c in rg.columns() {
                    let zstd = matches!(c.compression(), Compression::ZSTD(_));
                    assert_eq!(zstd, want, "{} rows: {:?}", rg.num_rows(), c.compression());
                    if !want {
                        assert_eq!(c.compression(), Compression::UNCOMPRESSED);
                    }
                }
            }
            let back = read_file(&path, "t").unwrap();
            let rows: usize = batches.iter().map(|b| b.num_rows()).sum();
            assert_eq!(back.iter().map(|b| b.num_rows()).sum::<usize>(), rows);
            let (a, b) = (
                arrow_select::concat::concat_batches(&batches[0].schema(), &batches).unwrap(),
                arrow_select::concat::concat_batches(&back[0].schema(), &back).unwrap(),
            );
            assert_eq!(a.columns(), b.columns());
        }
        assert!(matches!(compression_for(usize::MAX), Compression::ZSTD(_)));
    }
}
