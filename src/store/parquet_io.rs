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

use super::FORMAT_VERSION;
use crate::CODE_VERSION;

/// Key-value metadata of every table file.
pub fn file_metadata(table: &str, manifest_json: &str) -> Vec<(String, String)> {
    vec![
        ("granular.format_version".into(), FORMAT_VERSION.to_string()),
        ("granular.table".into(), table.into()),
        ("granular.code_version".into(), CODE_VERSION.into()),
        ("granular.manifest".into(), manifest_json.into()),
    ]
}

/// The writer properties of every table file.
pub fn writer_properties(table: &str, manifest_json: &str) -> WriterProperties {
    WriterProperties::builder()
        .set_compression(Compression::ZSTD(
            ZstdLevel::try_new(3).expect("valid level"),
        ))
        .set_created_by(CODE_VERSION.to_string())
        .set_key_value_metadata(Some(
            file_metadata(table, manifest_json)
                .into_iter()
                .map(|(k, v)| KeyValue::new(k, v))
                .collect(),
        ))
        .set_max_row_group_row_count(Some(256 * 1024))
        .build()
}

/// The schema with the same metadata (pyarrow shows `schema.metadata`).
pub fn schema_with_metadata(schema: &Schema, table: &str, manifest_json: &str) -> Arc<Schema> {
    let md: HashMap<String, String> = file_metadata(table, manifest_json).into_iter().collect();
    Arc::new(schema.clone().with_metadata(md))
}

/// Write `batch` as a Parquet file at `tmp` (fsynced). The caller renames it into place.
pub fn write_file(
    tmp: &Path,
    batch: &RecordBatch,
    table: &str,
    manifest_json: &str,
) -> Result<(), StoreError> {
    write_batches(tmp, std::slice::from_ref(batch), table, manifest_json)
}

/// Write `batches` (one schema) as one Parquet file at `tmp` (fsynced). On failure (a full
/// disk, say) the partial file is removed.
pub fn write_batches(
    tmp: &Path,
    batches: &[RecordBatch],
    table: &str,
    manifest_json: &str,
) -> Result<(), StoreError> {
    let r = write_batches_inner(tmp, batches, table, manifest_json);
    if r.is_err() {
        let _ = std::fs::remove_file(tmp);
    }
    r
}

fn write_batches_inner(
    tmp: &Path,
    batches: &[RecordBatch],
    table: &str,
    manifest_json: &str,
) -> Result<(), StoreError> {
    let Some(first) = batches.first() else {
        return Err(StoreError::Arrow(format!(
            "{}: no batches to write",
            tmp.display()
        )));
    };
    let schema = schema_with_metadata(first.schema().as_ref(), table, manifest_json);
    let file = File::create(tmp).map_err(|e| StoreError::io(tmp, e))?;
    let mut w = ArrowWriter::try_new(
        file,
        schema.clone(),
        Some(writer_properties(table, manifest_json)),
    )
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
    file.sync_all().map_err(|e| StoreError::io(tmp, e))?;
    Ok(())
}

/// What a table file says about itself (footer only; the data pages are not read).
#[derive(Debug, Clone, PartialEq)]
pub struct PartInfo {
    pub table: String,
    pub format_version: Option<u32>,
    /// Canonical JSON of the campaign manifest the file was written for.
    pub manifest: Option<String>,
    pub code_version: Option<String>,
    pub rows: u64,
}

/// Open a table file and read its footer: a truncated file, a file that is not Parquet, or a
/// Parquet file not written by granular is an error naming the file.
pub fn inspect(
    path: &Path,
) -> Result<(PartInfo, ParquetRecordBatchReaderBuilder<File>), StoreError> {
    let file = File::open(path).map_err(|e| StoreError::io(path, e))?;
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
    let info = PartInfo {
        table,
        format_version: get("granular.format_version").and_then(|v| v.parse().ok()),
        manifest: get("granular.manifest"),
        code_version: get("granular.code_version"),
        rows: builder.metadata().file_metadata().num_rows().max(0) as u64,
    };
    Ok((info, builder))
}

/// Check a file's footer against the expected table (and campaign, when given).
pub fn check_part(
    path: &Path,
    info: &PartInfo,
    table: &str,
    manifest_json: Option<&str>,
) -> Result<(), StoreError> {
    let bad = |why: String| Err(StoreError::Corrupt(path.display().to_string(), why));
    if info.table != table {
        return bad(format!("holds table {:?}, expected {table:?}", info.table));
    }
    if info.format_version != Some(FORMAT_VERSION) {
        return bad(format!(
            "has format version {:?}; this granular reads {FORMAT_VERSION}",
            info.format_version
        ));
    }
    if let Some(m) = manifest_json {
        if info.manifest.as_deref() != Some(m) {
            return bad(
                "belongs to another campaign (its granular.manifest differs from campaign.json)"
                    .into(),
            );
        }
    }
    Ok(())
}

/// Read every batch of a table file of the campaign whose canonical manifest is
/// `manifest_json`: a file of another table, format or campaign is an error, never data.
pub fn read_campaign_file(
    path: &Path,
    table: &str,
    manifest_json: &str,
) -> Result<Vec<RecordBatch>, StoreError> {
    read_checked(path, table, Some(manifest_json))
}

/// Read every batch of a table file, checking that it is one of ours and of this format.
pub fn read_file(path: &Path, table: &str) -> Result<Vec<RecordBatch>, StoreError> {
    read_checked(path, table, None)
}

fn read_checked(
    path: &Path,
    table: &str,
    manifest_json: Option<&str>,
) -> Result<Vec<RecordBatch>, StoreError> {
    let (info, builder) = inspect(path)?;
    check_part(path, &info, table, manifest_json)?;
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
