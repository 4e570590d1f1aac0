//! One schema per table. A table's columns are fixed by the files it already has: a campaign
//! written by an earlier granular keeps its columns when a newer one resumes or grows it, so
//! that DuckDB, Polars and pyarrow read its directory as one table (pyarrow would otherwise
//! silently take the first file's columns, Polars would refuse the mix).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow_array::{new_null_array, ArrayRef, RecordBatch};
use arrow_schema::{Schema, SchemaRef};

use super::parquet_io::{self, StoreError};

/// The columns of a table file (its footer only), without the file's metadata.
pub fn file_schema(path: &Path) -> Result<SchemaRef, StoreError> {
    let (_, builder) = parquet_io::inspect(path)?;
    let s = builder.schema();
    Ok(Arc::new(Schema::new(s.fields().clone())))
}

/// The columns of a table: those of the first of its `files` whose footer reads (every file
/// of a table has them; a damaged one is the integrity checks' business, not this), or None
/// when none does.
pub fn table_schema(files: &[PathBuf]) -> Option<SchemaRef> {
    files.iter().find_map(|f| file_schema(f).ok())
}

/// `batch` in the columns of `established` (a table's existing files), in their order:
/// - a column the batch lacks is filled with nulls (it must be nullable there);
/// - a column the table lacks is dropped when it holds only nulls (nothing is lost);
/// - a column with values the table cannot hold, or of another type, is an error naming the
///   table and the column: the rows are never written with a column silently missing.
pub fn conform(
    batch: &RecordBatch,
    established: &Schema,
    table: &str,
) -> Result<RecordBatch, StoreError> {
    if batch.schema().fields() == established.fields() {
        return Ok(batch.clone());
    }
    let mut errors = Vec::new();
    let mut columns: Vec<ArrayRef> = Vec::with_capacity(established.fields().len());
    for f in established.fields() {
        match batch.schema().index_of(f.name()) {
            Ok(i) => {
                let col = batch.column(i);
                if col.data_type() != f.data_type() {
                    errors.push(format!(
                        "column {:?} is {} in this table's files, {} in the new rows",
                        f.name(),
                        f.data_type(),
                        col.data_type()
                    ));
                }
                columns.push(col.clone());
            }
            Err(_) if f.is_nullable() => {
                columns.push(new_null_array(f.data_type(), batch.num_rows()))
            }
            Err(_) => errors.push(format!(
                "column {:?} (not nullable) is missing from the new rows",
                f.name()
            )),
        }
    }
    for (i, f) in batch.schema().fields().iter().enumerate() {
        let col = batch.column(i);
        if established.index_of(f.name()).is_err() && col.null_count() != col.len() {
            errors.push(format!(
                "the new rows have values in column {:?}, which this table's files (written by an \
                 earlier granular) do not have; record it in a new campaign (another --out)",
                f.name()
            ));
        }
    }
    if !errors.is_empty() {
        return Err(StoreError::Corrupt(
            format!("table {table}:"),
            errors.join("; "),
        ));
    }
    RecordBatch::try_new(Arc::new(established.clone()), columns)
        .map_err(|e| StoreError::Arrow(format!("table {table}: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use arrow_array::{Array, Float64Array, UInt32Array};
    use arrow_schema::{DataType, Field};

    fn batch(cols: Vec<(&str, ArrayRef)>) -> RecordBatch {
        let fields: Vec<Field> = cols
            .iter()
            .map(|(n, a)| Field::new(*n, a.data_type().clone(), true))
            .collect();
        RecordBatch::try_new(
            Arc::new(Schema::new(fields)),
            cols.into_iter().map(|c| c.1).collect(),
        )
        .unwrap()
    }

    fn old_schema() -> Schema {
        Schema::new(vec![
            Field::new("run_id", DataType::UInt32, true),
            Field::new("temperature", DataType::Float64, true),
        ])
    }

    #[test]
    fn a_null_new_column_is_dropped_and_the_order_kept() {
        let b = batch(vec![
            (
                "temperature",
                Arc::new(Float64Array::from(vec![1.0, 2.0])) as ArrayRef,
            ),
            ("a2", Arc::new(Float64Array::from(vec![None, None]))),
            ("run_id", Arc::new(UInt32Array::from(vec![3, 4]))),
        ]);
        let c = conform(&b, &old_schema(), "t").unwrap();
        assert_eq!(c.schema().fields(), old_schema().fields());
        assert_eq!(
            c.column(0)
                .as_any()
                .downcast_ref::<UInt32Array>()
                .unwrap()
                .value(1),
            4
        );
        assert_eq!(
            c.column(1)
                .as_any()
                .downcast_ref::<Float64Array>()
                .unwrap()
                .value(0),
            1.0
        );
    }

    #[test]
    fn a_new_column_with_values_is_an_error_naming_it() {
        let b = batch(vec![
            ("run_id", Arc::new(UInt32Array::from(vec![3])) as ArrayRef),
            ("temperature", Arc::new(Float64Array::from(vec![1.0]))),
            ("a2", Arc::new(Float64Array::from(vec![Some(0.1)]))),
        ]);
        let e = conform(&b, &old_schema(), "dsmc_species")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("table dsmc_species") && e.contains("\"a2\""),
            "{e}"
        );
    }

    #[test]
    fn a_missing_nullable_column_is_filled_with_nulls_and_a_type_change_refused() {
        let b = batch(vec![(
            "run_id",
            Arc::new(UInt32Array::from(vec![3, 4])) as ArrayRef,
        )]);
        let c = conform(&b, &old_schema(), "t").unwrap();
        assert_eq!(c.column(1).null_count(), 2);
        let b = batch(vec![
            (
                "run_id",
                Arc::new(Float64Array::from(vec![3.0])) as ArrayRef,
            ),
            ("temperature", Arc::new(Float64Array::from(vec![1.0]))),
        ]);
        let e = conform(&b, &old_schema(), "t").unwrap_err().to_string();
        assert!(e.contains("\"run_id\" is UInt32"), "{e}");
    }
}
