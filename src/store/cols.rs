//! Arrow columns of tables whose columns are not fixed (the `points` and `registered_runs`
//! tables with the sweep's columns, the analysis's tables, test fixtures): built from the rows,
//! name and values together (`table(&rows, |c| vec![c.f64("t", |r| r.t), ...])`), or from a
//! field of every row (`cols::f64s(&rows, |r| r.t)`); and the join of a summary with the
//! sweep columns. A table of fixed columns is declared once with [`crate::declare_table!`]
//! ([`super::typed`]), which writes it and reads it back by typed fields, never by name.

use std::sync::Arc;

use arrow_array::{
    Array, ArrayRef, BooleanArray, Float64Array, RecordBatch, StringArray, UInt32Array, UInt64Array,
};
use arrow_schema::{DataType, Field, Schema};

use super::parquet_io::StoreError;
use super::typed::{Kind, U32};

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
    let keys = U32::read(batch, key).map_err(|e| StoreError::Corrupt(table.into(), e.0))?;
    let lookup_keys =
        U32::read(lookup, key).map_err(|e| StoreError::Corrupt("lookup".into(), e.0))?;
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
    let at = schema.index_of(key).expect("U32::read found it") + 1;
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
    use arrow_array::cast::AsArray;
    use arrow_array::types::Float64Type;

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
        let m = out.column(1).as_string::<i32>();
        let got: Vec<Option<&str>> = m.iter().collect();
        assert_eq!(got, [Some("b"), Some("a"), Some("b"), None]);
        assert_eq!(
            out.column(2).as_primitive::<Float64Type>().values(),
            &[0.5, 1.5, 2.5, 3.5]
        );
        assert!(join_after_key(&lookup, "t", "run_id", &lookup).is_err());
    }
}
