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
