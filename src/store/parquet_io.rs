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
    let schema = schema_with_metadata(batch.schema().as_ref(), table, manifest_json);
    let batch = batch
        .clone()
        .with_schema(schema.clone())
        .map_err(|e| StoreError::Arrow(e.to_string()))?;
    let file = File::create(tmp).map_err(|e| StoreError::io(tmp, e))?;
    let mut w = ArrowWriter::try_new(file, schema, Some(writer_properties(table, manifest_json)))
        .map_err(|e| StoreError::Parquet(tmp.display().to_string(), e.to_string()))?;
    w.write(&batch)
        .map_err(|e| StoreError::Parquet(tmp.display().to_string(), e.to_string()))?;
    let file = w
        .into_inner()
        .map_err(|e| StoreError::Parquet(tmp.display().to_string(), e.to_string()))?;
    file.sync_all().map_err(|e| StoreError::io(tmp, e))?;
    Ok(())
}

/// Read every batch of a table file, checking that it is one of ours and of this format.
pub fn read_file(path: &Path, table: &str) -> Result<Vec<RecordBatch>, StoreError> {
    let file = File::open(path).map_err(|e| StoreError::io(path, e))?;
    let builder = ParquetRecordBatchReaderBuilder::try_new(file).map_err(|e| {
        StoreError::Corrupt(
            path.display().to_string(),
            format!("not a readable Parquet file: {e}"),
        )
    })?;
    let kv = builder
        .metadata()
        .file_metadata()
        .key_value_metadata()
        .cloned()
        .unwrap_or_default();
    let get = |k: &str| kv.iter().find(|x| x.key == k).and_then(|x| x.value.clone());
    match get("granular.table") {
        Some(t) if t == table => {}
        Some(t) => {
            return Err(StoreError::Corrupt(
                path.display().to_string(),
                format!("holds table {t:?}, expected {table:?}"),
            ))
        }
        None => {
            return Err(StoreError::Corrupt(
                path.display().to_string(),
                "is not a granular table file".into(),
            ))
        }
    }
    match get("granular.format_version").and_then(|v| v.parse::<u32>().ok()) {
        Some(FORMAT_VERSION) => {}
        other => {
            return Err(StoreError::Corrupt(
                path.display().to_string(),
                format!("has format version {other:?}; this granular reads {FORMAT_VERSION}"),
            ))
        }
    }
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
