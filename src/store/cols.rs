//! Arrow columns: a table's columns declared once each, name and values together
//! (`table(&rows, |c| vec![c.f64("t", |r| r.t), ...])`), or built from a field of every row
//! (`cols::f64s(&rows, |r| r.t)`); and read back by name with their type checked
//! (`cols::get_f64(&batch, "t")`), so a table file that lacks a column, or has it with another
//! type, is an error that names the column, never a panic.

use std::sync::Arc;

use arrow_array::cast::AsArray;
use arrow_array::types::{Float64Type, UInt32Type, UInt64Type};
use arrow_array::{
    Array, ArrayRef, BooleanArray, Float64Array, RecordBatch, StringArray, UInt32Array, UInt64Array,
};
use arrow_schema::{DataType, Field, Schema};

use super::parquet_io::StoreError;

pub fn f64s<T>(v: &[T], f: impl Fn(&T) -> f64) -> ArrayRef {
    Arc::new(v.iter().map(f).collect::<Float64Array>())
}
pub fn opt_f64s<T>(v: &[T], f: impl Fn(&T) -> Option<f64>) -> ArrayRef {
    Arc::new(v.iter().map(f).collect::<Float64Array>())
}
pub fn u32s<T>(v: &[T], f: impl Fn(&T) -> u32) -> ArrayRef {
    Arc::new(v.iter().map(f).collect::<UInt32Array>())
}
pub fn u64s<T>(v: &[T], f: impl Fn(&T) -> u64) -> ArrayRef {
    Arc::new(v.iter().map(f).collect::<UInt64Array>())
}
pub fn opt_u64s<T>(v: &[T], f: impl Fn(&T) -> Option<u64>) -> ArrayRef {
    Arc::new(v.iter().map(f).collect::<UInt64Array>())
}
pub fn strs<T>(v: &[T], f: impl Fn(&T) -> &str) -> ArrayRef {
    Arc::new(v.iter().map(|r| Some(f(r))).collect::<StringArray>())
}

/// How a column's values are made from the rows.
type Values<'a, T> = Box<dyn Fn(&[T]) -> ArrayRef + 'a>;

/// One column of a table of rows `T`: its name, whether it may hold nulls, and its values.
pub struct Column<'a, T> {
    name: &'static str,
    nullable: bool,
    values: Values<'a, T>,
}

impl<'a, T> Column<'a, T> {
    fn new(name: &'static str, nullable: bool, values: impl Fn(&[T]) -> ArrayRef + 'a) -> Self {
        Column {
            name,
            nullable,
            values: Box::new(values),
        }
    }
}

/// The column constructors of a table of rows `T` (it fixes `T` for their closures).
pub struct Columns<T>(std::marker::PhantomData<fn(&T)>);

impl<T> Columns<T> {
    pub fn f64<'a>(&self, name: &'static str, f: impl Fn(&T) -> f64 + 'a) -> Column<'a, T> {
        Column::new(name, false, move |v| f64s(v, &f))
    }
    pub fn opt_f64<'a>(
        &self,
        name: &'static str,
        f: impl Fn(&T) -> Option<f64> + 'a,
    ) -> Column<'a, T> {
        Column::new(name, true, move |v| opt_f64s(v, &f))
    }
    pub fn u32<'a>(&self, name: &'static str, f: impl Fn(&T) -> u32 + 'a) -> Column<'a, T> {
        Column::new(name, false, move |v| u32s(v, &f))
    }
    pub fn u64<'a>(&self, name: &'static str, f: impl Fn(&T) -> u64 + 'a) -> Column<'a, T> {
        Column::new(name, false, move |v| u64s(v, &f))
    }
    pub fn opt_u64<'a>(
        &self,
        name: &'static str,
        f: impl Fn(&T) -> Option<u64> + 'a,
    ) -> Column<'a, T> {
        Column::new(name, true, move |v| opt_u64s(v, &f))
    }
    pub fn str<'a>(&self, name: &'static str, f: impl Fn(&T) -> &str + 'a) -> Column<'a, T> {
        Column::new(name, false, move |v| strs(v, &f))
    }
    pub fn opt_str<'a>(
        &self,
        name: &'static str,
        f: impl Fn(&T) -> Option<&str> + 'a,
    ) -> Column<'a, T> {
        Column::new(name, true, move |v| {
            Arc::new(v.iter().map(&f).collect::<StringArray>())
        })
    }
    pub fn bool<'a>(&self, name: &'static str, f: impl Fn(&T) -> bool + 'a) -> Column<'a, T> {
        Column::new(name, false, move |v| {
            Arc::new(v.iter().map(|r| Some(f(r))).collect::<BooleanArray>())
        })
    }
    /// The same text in every row.
    pub fn const_str<'a>(&self, name: &'static str, value: &'a str) -> Column<'a, T> {
        Column::new(name, false, move |v| {
            Arc::new(v.iter().map(|_| Some(value)).collect::<StringArray>())
        })
    }
    /// A column built from all the rows at once (a list column, say).
    pub fn array<'a>(
        &self,
        name: &'static str,
        nullable: bool,
        f: impl Fn(&[T]) -> ArrayRef + 'a,
    ) -> Column<'a, T> {
        Column::new(name, nullable, f)
    }
}

/// The fields and arrays of the columns `columns` declares over `rows`, in order.
pub fn build<'a, T>(
    rows: &[T],
    columns: impl FnOnce(Columns<T>) -> Vec<Column<'a, T>>,
) -> (Vec<Field>, Vec<ArrayRef>) {
    columns(Columns(std::marker::PhantomData))
        .into_iter()
        .map(|c| {
            let a = (c.values)(rows);
            (Field::new(c.name, a.data_type().clone(), c.nullable), a)
        })
        .unzip()
}

/// A batch of `rows` with the columns `columns` declares:
/// `table(&rows, |c| vec![c.f64("t", |r| r.t), c.opt_f64("msd", |r| r.msd)])`.
pub fn table<'a, T>(
    rows: &[T],
    columns: impl FnOnce(Columns<T>) -> Vec<Column<'a, T>>,
) -> RecordBatch {
    let (fields, arrays) = build(rows, columns);
    RecordBatch::try_new(Arc::new(Schema::new(fields)), arrays).expect("columns of equal length")
}

/// A non-nullable field (nullable with `field_opt`).
pub fn field(name: &str, t: DataType) -> Field {
    Field::new(name, t, false)
}
pub fn field_opt(name: &str, t: DataType) -> Field {
    Field::new(name, t, true)
}

/// The column `name` of a batch read from a table file.
pub fn get<'a>(b: &'a RecordBatch, table: &str, name: &str) -> Result<&'a ArrayRef, StoreError> {
    b.column_by_name(name)
        .ok_or_else(|| StoreError::Corrupt(table.into(), format!("has no column {name}")))
}

fn typed<'a>(
    b: &'a RecordBatch,
    table: &str,
    name: &str,
    want: DataType,
) -> Result<&'a ArrayRef, StoreError> {
    let c = get(b, table, name)?;
    if c.data_type() != &want {
        return Err(StoreError::Corrupt(
            table.into(),
            format!("column {name} is {}, expected {want}", c.data_type()),
        ));
    }
    Ok(c)
}

pub fn get_f64<'a>(
    b: &'a RecordBatch,
    table: &str,
    name: &str,
) -> Result<&'a Float64Array, StoreError> {
    Ok(typed(b, table, name, DataType::Float64)?.as_primitive::<Float64Type>())
}
pub fn get_u32<'a>(
    b: &'a RecordBatch,
    table: &str,
    name: &str,
) -> Result<&'a UInt32Array, StoreError> {
    Ok(typed(b, table, name, DataType::UInt32)?.as_primitive::<UInt32Type>())
}
pub fn get_u64<'a>(
    b: &'a RecordBatch,
    table: &str,
    name: &str,
) -> Result<&'a UInt64Array, StoreError> {
    Ok(typed(b, table, name, DataType::UInt64)?.as_primitive::<UInt64Type>())
}
pub fn get_str<'a>(
    b: &'a RecordBatch,
    table: &str,
    name: &str,
) -> Result<&'a StringArray, StoreError> {
    Ok(typed(b, table, name, DataType::Utf8)?.as_string::<i32>())
}

/// Value `i` of a nullable column.
pub fn opt<T: arrow_array::ArrowPrimitiveType>(
    a: &arrow_array::PrimitiveArray<T>,
    i: usize,
) -> Option<T::Native> {
    (!a.is_null(i)).then(|| a.value(i))
}

/// `batch` with the columns of `lookup` joined onto its rows by the `UInt32` column `key` (a
/// many-to-one join: `lookup` holds one row per key), placed right after `key`, in `lookup`'s
/// order. A row whose key `lookup` lacks gets nulls there (the joined fields are nullable). A
/// column of `lookup` whose name `batch` already has is left out: the batch's own column
/// stays. `table` names the batch in errors.
pub fn join_after_key(
    batch: &RecordBatch,
    table: &str,
    key: &str,
    lookup: &RecordBatch,
) -> Result<RecordBatch, StoreError> {
    let keys = get_u32(batch, table, key)?;
    let lookup_keys = get_u32(lookup, "lookup", key)?;
    let row_of: std::collections::HashMap<u32, u32> = lookup_keys
        .iter()
        .enumerate()
        .filter_map(|(i, k)| k.map(|k| (k, i as u32)))
        .collect();
    let rows: UInt32Array = keys
        .iter()
        .map(|k| k.and_then(|k| row_of.get(&k).copied()))
        .collect();
    let schema = batch.schema();
    let at = schema.index_of(key).expect("get_u32 found it") + 1;
    let mut fields: Vec<Field> = schema.fields()[..at]
        .iter()
        .map(|f| f.as_ref().clone())
        .collect();
    let mut arrays: Vec<ArrayRef> = batch.columns()[..at].to_vec();
    let lookup_schema = lookup.schema();
    for (f, a) in lookup_schema.fields().iter().zip(lookup.columns()) {
        if f.name() == key || schema.column_with_name(f.name()).is_some() {
            continue;
        }
        let joined = arrow_select::take::take(a.as_ref(), &rows, None)
            .map_err(|e| StoreError::Arrow(e.to_string()))?;
        fields.push(f.as_ref().clone().with_nullable(true));
        arrays.push(joined);
    }
    fields.extend(schema.fields()[at..].iter().map(|f| f.as_ref().clone()));
    arrays.extend(batch.columns()[at..].iter().cloned());
    RecordBatch::try_new(Arc::new(Schema::new(fields)), arrays)
        .map_err(|e| StoreError::Arrow(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn join_after_key_places_lookup_columns_after_the_key() {
        let rows = [(2u32, 0.5), (0, 1.5), (2, 2.5), (7, 3.5)];
        let batch = table(&rows, |c| {
            vec![c.u32("point_id", |r| r.0), c.f64("x", |r| r.1)]
        });
        let points = [(0u32, "a", 10.0), (2, "b", 20.0)];
        let lookup = table(&points, |c| {
            vec![
                c.u32("point_id", |r| r.0),
                c.str("method", |r| r.1),
                c.f64("x", |r| r.2),
            ]
        });
        let out = join_after_key(&batch, "t", "point_id", &lookup).unwrap();
        let names: Vec<&str> = out
            .schema_ref()
            .fields()
            .iter()
            .map(|f| f.name().as_str())
            .collect();
        // `x` of the batch stays; the lookup's `x` is left out.
        assert_eq!(names, ["point_id", "method", "x"]);
        let m = get_str(&out, "t", "method").unwrap();
        let got: Vec<Option<&str>> = m.iter().collect();
        assert_eq!(got, [Some("b"), Some("a"), Some("b"), None]);
        assert_eq!(
            get_f64(&out, "t", "x").unwrap().values(),
            &[0.5, 1.5, 2.5, 3.5]
        );
        assert!(join_after_key(&lookup, "t", "run_id", &lookup).is_err());
    }
}
