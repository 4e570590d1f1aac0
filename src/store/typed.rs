//! Typed tables: a table declared once ([`declare_table!`]), its name and each column's name
//! (= the Rust field's), Arrow type and nullability, and whether older files may lack it.
//! From the declaration come the writer (`Row::batch(&rows)`, the Parquet schema in the
//! declared order) and the typed readers (`Cols::read(&batch, file)?`: the columns as typed
//! arrays in named fields, `cols.temperature.value(i)`; `Row::read_rows`: rows as structs),
//! so a renamed column is a compile error wherever it is written or read, and a file that
//! lacks a column, or has it with another type, is a [`StoreError`] naming the file and every
//! such column, never a panic.
//!
//! The column kinds are the marker types of this module: [`F64`], [`OptF64`] (nullable),
//! [`U32`], [`OptU32`], [`U64`], [`OptU64`], [`Str`], [`OptStr`], [`Bool`], [`ListF64`]; and
//! [`Absent<K>`] around a nullable kind for a column that files written before it existed
//! lack (read as `None`; written always).
//!
//! ```ignore
//! declare_table! {
//!     /// `dsmc_species`: per output time and species.
//!     pub struct DsmcSpecies in "dsmc_species", read as DsmcSpeciesCols {
//!         run_id: U64,
//!         t: F64,
//!         msd: OptF64,
//!         a2: Absent<OptF64>,
//!     }
//! }
//! ```
//!
//! Storage knows no physics: the declarations are in each model's home (`tables.rs`).

use std::sync::Arc;

use arrow_array::builder::{Float64Builder, ListBuilder};
use arrow_array::cast::AsArray;
use arrow_array::types::{Float64Type, UInt32Type, UInt64Type};
use arrow_array::{
    Array, ArrayRef, BooleanArray, Float64Array, ListArray, RecordBatch, StringArray, UInt32Array,
    UInt64Array,
};
use arrow_schema::{DataType, Field};

pub use super::parquet_io::StoreError;

/// A column kind: the Arrow type of a column, its nullability, the Rust value of one row and
/// the typed array it is read as.
pub trait Kind {
    /// One row's value.
    type Value;
    /// The column as read: a typed array (an `Option` of one for [`Absent`]).
    type Array<'a>: Copy;
    const NULLABLE: bool;
    fn data_type() -> DataType;
    /// The array of the values, in order.
    fn build<'r>(values: impl Iterator<Item = &'r Self::Value>) -> ArrayRef
    where
        Self::Value: 'r;
    /// The column `name` of `b`; the error is the text after the file's name.
    fn read<'a>(b: &'a RecordBatch, name: &str) -> Result<Self::Array<'a>, ColumnProblem>;
    /// Row `i` of a column as read.
    fn get(a: Self::Array<'_>, i: usize) -> Self::Value;
}

/// The column `name` of `b`, of type `want`.
fn column<'a>(
    b: &'a RecordBatch,
    name: &str,
    want: &DataType,
) -> Result<&'a ArrayRef, ColumnProblem> {
    let c = b
        .column_by_name(name)
        .ok_or_else(|| ColumnProblem(format!("has no column {name}")))?;
    if c.data_type() != want {
        return Err(ColumnProblem(format!(
            "column {name} is {}, expected {want}",
            c.data_type()
        )));
    }
    Ok(c)
}

macro_rules! primitive_kinds {
    ($($kind:ident, $opt:ident, $native:ty, $array:ty, $arrow:ty, $dt:expr;)*) => {$(
        #[doc = concat!("A non-nullable `", stringify!($native), "` column.")]
        pub struct $kind;
        #[doc = concat!("A nullable `", stringify!($native), "` column.")]
        pub struct $opt;
        impl Kind for $kind {
            type Value = $native;
            type Array<'a> = &'a $array;
            const NULLABLE: bool = false;
            fn data_type() -> DataType {
                $dt
            }
            fn build<'r>(values: impl Iterator<Item = &'r $native>) -> ArrayRef {
                Arc::new(values.copied().collect::<$array>())
            }
            fn read<'a>(b: &'a RecordBatch, name: &str) -> Result<&'a $array, ColumnProblem> {
                Ok(column(b, name, &$dt)?.as_primitive::<$arrow>())
            }
            fn get(a: &$array, i: usize) -> $native {
                a.value(i)
            }
        }
        impl Kind for $opt {
            type Value = Option<$native>;
            type Array<'a> = &'a $array;
            const NULLABLE: bool = true;
            fn data_type() -> DataType {
                $dt
            }
            fn build<'r>(values: impl Iterator<Item = &'r Option<$native>>) -> ArrayRef {
                Arc::new(values.copied().collect::<$array>())
            }
            fn read<'a>(b: &'a RecordBatch, name: &str) -> Result<&'a $array, ColumnProblem> {
                Ok(column(b, name, &$dt)?.as_primitive::<$arrow>())
            }
            fn get(a: &$array, i: usize) -> Option<$native> {
                (!a.is_null(i)).then(|| a.value(i))
            }
        }
        impl Nullable for $opt {}
    )*};
}

primitive_kinds! {
    F64, OptF64, f64, Float64Array, Float64Type, DataType::Float64;
    U32, OptU32, u32, UInt32Array, UInt32Type, DataType::UInt32;
    U64, OptU64, u64, UInt64Array, UInt64Type, DataType::UInt64;
}

/// A non-nullable text column.
pub struct Str;
/// A nullable text column.
pub struct OptStr;
/// A non-nullable boolean column.
pub struct Bool;
/// A non-nullable list of `f64` column (nullable items, as Arrow's `ListBuilder` makes them).
pub struct ListF64;

impl Kind for Str {
    type Value = String;
    type Array<'a> = &'a StringArray;
    const NULLABLE: bool = false;
    fn data_type() -> DataType {
        DataType::Utf8
    }
    fn build<'r>(values: impl Iterator<Item = &'r String>) -> ArrayRef {
        Arc::new(values.map(|s| Some(s.as_str())).collect::<StringArray>())
    }
    fn read<'a>(b: &'a RecordBatch, name: &str) -> Result<&'a StringArray, ColumnProblem> {
        Ok(column(b, name, &DataType::Utf8)?.as_string::<i32>())
    }
    fn get(a: &StringArray, i: usize) -> String {
        a.value(i).to_string()
    }
}

impl Kind for OptStr {
    type Value = Option<String>;
    type Array<'a> = &'a StringArray;
    const NULLABLE: bool = true;
    fn data_type() -> DataType {
        DataType::Utf8
    }
    fn build<'r>(values: impl Iterator<Item = &'r Option<String>>) -> ArrayRef {
        Arc::new(values.map(|s| s.as_deref()).collect::<StringArray>())
    }
    fn read<'a>(b: &'a RecordBatch, name: &str) -> Result<&'a StringArray, ColumnProblem> {
        Ok(column(b, name, &DataType::Utf8)?.as_string::<i32>())
    }
    fn get(a: &StringArray, i: usize) -> Option<String> {
        (!a.is_null(i)).then(|| a.value(i).to_string())
    }
}
impl Nullable for OptStr {}

impl Kind for Bool {
    type Value = bool;
    type Array<'a> = &'a BooleanArray;
    const NULLABLE: bool = false;
    fn data_type() -> DataType {
        DataType::Boolean
    }
    fn build<'r>(values: impl Iterator<Item = &'r bool>) -> ArrayRef {
        Arc::new(values.map(|b| Some(*b)).collect::<BooleanArray>())
    }
    fn read<'a>(b: &'a RecordBatch, name: &str) -> Result<&'a BooleanArray, ColumnProblem> {
        Ok(column(b, name, &DataType::Boolean)?.as_boolean())
    }
    fn get(a: &BooleanArray, i: usize) -> bool {
        a.value(i)
    }
}

impl Kind for ListF64 {
    type Value = Vec<f64>;
    type Array<'a> = &'a ListArray;
    const NULLABLE: bool = false;
    fn data_type() -> DataType {
        DataType::List(Arc::new(Field::new_list_field(DataType::Float64, true)))
    }
    fn build<'r>(values: impl Iterator<Item = &'r Vec<f64>>) -> ArrayRef {
        let mut b = ListBuilder::new(Float64Builder::new());
        for v in values {
            b.values().append_slice(v);
            b.append(true);
        }
        Arc::new(b.finish())
    }
    fn read<'a>(b: &'a RecordBatch, name: &str) -> Result<&'a ListArray, ColumnProblem> {
        let a = column(b, name, &Self::data_type())?;
        Ok(a.as_list::<i32>())
    }
    fn get(a: &ListArray, i: usize) -> Vec<f64> {
        let v = a.value(i);
        v.as_primitive::<Float64Type>().iter().flatten().collect()
    }
}

/// A nullable kind (the ones [`Absent`] may wrap: an absent column reads as nulls).
pub trait Nullable: Kind {}

/// A nullable column that files written before it existed lack: read as `None` (the typed
/// array is `Option<..>`, each row's value `None`); written always, as `K`.
pub struct Absent<K>(std::marker::PhantomData<K>);

impl<K: Nullable> Kind for Absent<K>
where
    K::Value: Default,
{
    type Value = K::Value;
    type Array<'a> = Option<K::Array<'a>>;
    const NULLABLE: bool = K::NULLABLE;
    fn data_type() -> DataType {
        K::data_type()
    }
    fn build<'r>(values: impl Iterator<Item = &'r K::Value>) -> ArrayRef
    where
        K::Value: 'r,
    {
        K::build(values)
    }
    fn read<'a>(b: &'a RecordBatch, name: &str) -> Result<Option<K::Array<'a>>, ColumnProblem> {
        match b.column_by_name(name) {
            None => Ok(None),
            Some(_) => K::read(b, name).map(Some),
        }
    }
    fn get(a: Self::Array<'_>, i: usize) -> K::Value {
        a.map(|a| K::get(a, i)).unwrap_or_default()
    }
}

/// What is wrong with one column of a batch (the text after the file's name).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ColumnProblem(pub String);

/// The error of reading a batch of `file` whose columns `problems` describe.
pub fn columns_error(file: &str, problems: Vec<ColumnProblem>) -> StoreError {
    let texts: Vec<String> = problems.into_iter().map(|p| p.0).collect();
    StoreError::Corrupt(file.to_string(), texts.join("; "))
}

/// Whether `name` is one of `columns` (a `const fn`: [`declare_table!`]'s `column`).
pub const fn contains(columns: &[&str], name: &str) -> bool {
    let mut i = 0;
    while i < columns.len() {
        let c = columns[i].as_bytes();
        let n = name.as_bytes();
        if c.len() == n.len() {
            let mut j = 0;
            while j < c.len() && c[j] == n[j] {
                j += 1;
            }
            if j == c.len() {
                return true;
            }
        }
        i += 1;
    }
    false
}

/// Declare a table once: `pub struct Row in "table_name", read as RowCols { field: Kind, .. }`
/// (see the module's documentation). It defines:
/// - `Row`, one row: a public field per column, of the kind's `Value` type;
/// - `Row::TABLE`, `Row::COLUMNS` (the names in order), `Row::fields()`, `Row::schema()`;
///   `Row::column("name")`, a `const fn` that fails to compile (in a `const` context) for a
///   name the table lacks;
/// - `Row::batch(&rows)`: the Arrow batch of rows, columns in the declared order;
/// - `RowCols<'a>`: the typed arrays of a batch as read, `RowCols::read(&batch, file)?`
///   (every missing or mistyped column named in one error), `len`, `row(i)`;
/// - `Row::read_rows(&batch, file)?`: the rows of a batch as structs.
#[macro_export]
macro_rules! declare_table {
    (
        $(#[$meta:meta])*
        $vis:vis struct $row:ident in $table:literal, read as $cols:ident {
            $( $(#[$fmeta:meta])* $field:ident : $kind:ty ),* $(,)?
        }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Debug, PartialEq)]
        $vis struct $row {
            $( $(#[$fmeta])* pub $field: <$kind as $crate::store::typed::Kind>::Value, )*
        }

        #[doc = concat!("The columns of a batch of `", $table, "` as typed arrays (see [`", stringify!($row), "`]).")]
        #[derive(Clone, Copy)]
        #[allow(dead_code)]
        $vis struct $cols<'a> {
            $( pub $field: <$kind as $crate::store::typed::Kind>::Array<'a>, )*
            rows: usize,
        }

        #[allow(dead_code)]
        impl $row {
            pub const TABLE: &'static str = $table;
            pub const COLUMNS: &'static [&'static str] = &[$(stringify!($field)),*];

            /// `name`, checked to be one of the table's columns (use in a `const`).
            pub const fn column(name: &'static str) -> &'static str {
                assert!(
                    $crate::store::typed::contains(Self::COLUMNS, name),
                    concat!("not a column of ", $table)
                );
                name
            }

            /// The table's fields, in order.
            pub fn fields() -> Vec<arrow_schema::Field> {
                vec![$(
                    arrow_schema::Field::new(
                        stringify!($field),
                        <$kind as $crate::store::typed::Kind>::data_type(),
                        <$kind as $crate::store::typed::Kind>::NULLABLE,
                    )
                ),*]
            }

            pub fn schema() -> arrow_schema::SchemaRef {
                std::sync::Arc::new(arrow_schema::Schema::new(Self::fields()))
            }

            /// The batch of `rows`, columns in the declared order.
            pub fn batch(rows: &[Self]) -> arrow_array::RecordBatch {
                let arrays: Vec<arrow_array::ArrayRef> = vec![$(
                    <$kind as $crate::store::typed::Kind>::build(rows.iter().map(|r| &r.$field))
                ),*];
                arrow_array::RecordBatch::try_new(Self::schema(), arrays)
                    .expect("the arrays are built from the declared kinds")
            }

            /// The rows of a batch read from `file`.
            pub fn read_rows(
                b: &arrow_array::RecordBatch,
                file: &str,
            ) -> Result<Vec<Self>, $crate::store::typed::StoreError> {
                let c = $cols::read(b, file)?;
                Ok((0..c.len()).map(|i| c.row(i)).collect())
            }
        }

        #[allow(dead_code)]
        impl<'a> $cols<'a> {
            /// The declared columns of `b` (a batch of `file`), each checked for its type; a
            /// missing or mistyped one is an error naming the file and every such column.
            pub fn read(
                b: &'a arrow_array::RecordBatch,
                file: &str,
            ) -> Result<Self, $crate::store::typed::StoreError> {
                let mut problems: Vec<$crate::store::typed::ColumnProblem> = Vec::new();
                $(
                    let $field = match <$kind as $crate::store::typed::Kind>::read(b, stringify!($field)) {
                        Ok(a) => Some(a),
                        Err(e) => {
                            problems.push(e);
                            None
                        }
                    };
                )*
                match ($($field,)*) {
                    ($(Some($field),)*) => Ok($cols { $($field,)* rows: b.num_rows() }),
                    _ => Err($crate::store::typed::columns_error(file, problems)),
                }
            }

            pub fn len(&self) -> usize {
                self.rows
            }

            pub fn is_empty(&self) -> bool {
                self.rows == 0
            }

            /// Row `i` as a struct.
            pub fn row(&self, i: usize) -> $row {
                $row {
                    $( $field: <$kind as $crate::store::typed::Kind>::get(self.$field, i), )*
                }
            }
        }
    };
}

#[cfg(test)]
mod tests {
    use super::*;
    use arrow_schema::Schema;

    crate::declare_table! {
        /// A table of every kind.
        struct Every in "every", read as EveryCols {
            id: U32,
            x: F64,
            y: OptF64,
            n: U64,
            m: OptU64,
            k: OptU32,
            name: Str,
            note: OptStr,
            ok: Bool,
            list: ListF64,
            late: Absent<OptF64>,
        }
    }

    fn rows() -> Vec<Every> {
        vec![
            Every {
                id: 3,
                x: 1.5,
                y: None,
                n: 7,
                m: Some(8),
                k: None,
                name: "a".into(),
                note: None,
                ok: true,
                list: vec![1.0, 2.0],
                late: Some(0.25),
            },
            Every {
                id: 4,
                x: -2.0,
                y: Some(0.5),
                n: 0,
                m: None,
                k: Some(9),
                name: "b".into(),
                note: Some("n".into()),
                ok: false,
                list: vec![],
                late: None,
            },
        ]
    }

    #[test]
    fn a_table_written_is_read_back() {
        let rows = rows();
        let b = Every::batch(&rows);
        let names: Vec<&str> = b
            .schema_ref()
            .fields()
            .iter()
            .map(|f| f.name().as_str())
            .collect();
        assert_eq!(names, Every::COLUMNS);
        assert_eq!(
            names,
            ["id", "x", "y", "n", "m", "k", "name", "note", "ok", "list", "late"]
        );
        let nullable: Vec<bool> = b
            .schema_ref()
            .fields()
            .iter()
            .map(|f| f.is_nullable())
            .collect();
        assert_eq!(
            nullable,
            [false, false, true, false, true, true, false, true, false, false, true]
        );
        // The list type is the one Arrow's builder makes (as the writers made it before).
        let mut lb = ListBuilder::new(Float64Builder::new());
        lb.append(true);
        assert_eq!(b.column(9).data_type(), lb.finish().data_type());
        let cols = EveryCols::read(&b, "f.parquet").unwrap();
        assert_eq!(cols.len(), 2);
        assert_eq!(cols.x.value(1), -2.0);
        assert_eq!(cols.name.value(0), "a");
        assert_eq!(Every::read_rows(&b, "f.parquet").unwrap(), rows);
        assert_eq!(Every::column("late"), "late");
    }

    #[test]
    fn a_column_older_files_lack_reads_as_none() {
        let b = Every::batch(&rows());
        let without = b.project(&(0..10).collect::<Vec<_>>()).unwrap();
        let cols = EveryCols::read(&without, "old.parquet").unwrap();
        assert!(cols.late.is_none());
        let read = Every::read_rows(&without, "old.parquet").unwrap();
        assert_eq!(read[0].late, None);
        assert_eq!(read[0].x, 1.5);
    }

    #[test]
    fn a_missing_column_is_an_error_naming_file_and_column() {
        let b = Every::batch(&rows());
        // Without `x` (1) and `name` (6).
        let keep: Vec<usize> = (0..11).filter(|i| *i != 1 && *i != 6).collect();
        let b = b.project(&keep).unwrap();
        let e = EveryCols::read(&b, "tables/every/p.parquet").err().unwrap();
        let text = e.to_string();
        assert_eq!(
            text,
            "tables/every/p.parquet has no column x; has no column name"
        );
    }

    #[test]
    fn a_column_of_another_type_is_an_error() {
        let b = Every::batch(&rows());
        let schema = b.schema();
        let mut fields: Vec<Field> = schema.fields().iter().map(|f| f.as_ref().clone()).collect();
        let mut arrays = b.columns().to_vec();
        // `x` as u64, and `late` (which may be absent, not mistyped) as text.
        fields[1] = Field::new("x", DataType::UInt64, false);
        arrays[1] = Arc::new(UInt64Array::from(vec![1u64, 2]));
        fields[10] = Field::new("late", DataType::Utf8, true);
        arrays[10] = Arc::new(StringArray::from(vec![Some("a"), None]));
        let bad = RecordBatch::try_new(Arc::new(Schema::new(fields)), arrays).unwrap();
        let e = Every::read_rows(&bad, "f.parquet")
            .err()
            .unwrap()
            .to_string();
        assert_eq!(
            e,
            "f.parquet column x is UInt64, expected Float64; column late is Utf8, expected Float64"
        );
    }
}
