//! Derived quantities: expressions over the columns of a model's run tables, evaluated per
//! run from that run's rows (manifest `derived`). Pure: knows no campaign, no model, no file;
//! it sees table names, Arrow schemas and record batches (Arrow and evalexpr only).
//!
//! The language (README, "Derived quantities"): a reference to a column of a run table
//! (`temperature`, `dsmc_species.temperature` where a bare name is ambiguous) with selectors
//! on other columns of its table (`temperature[species=1]`, `density[kind='v', h=3]`);
//! reductions of one reference over all the run's selected rows (`mean`, `sum`, `min`, `max`,
//! `first`, `last` by t, `slope` against t, `count`); everything else is evalexpr's
//! (arithmetic, `^`, `sqrt`, `ln`, `exp`, `abs`, ...). [`parse::rewrite`] replaces each
//! reference and reduction by a generated variable and evalexpr's operator tree is built once
//! here; [`Quantities::eval`] binds the variables to a run's values (f64) and evaluates it.
//!
//! Time: a quantity with a reference (not reduced) to a table with a `t` column is a time
//! series, evaluated at each t where every such reference has exactly one row; otherwise it
//! is one value per run (t = None), and a reference to a table without `t` must select
//! exactly one row.

mod parse;

use std::cmp::Ordering;
use std::collections::{BTreeMap, BTreeSet};

use arrow_array::cast::AsArray;
use arrow_array::types::{
    Float32Type, Float64Type, Int16Type, Int32Type, Int64Type, Int8Type, UInt16Type, UInt32Type,
    UInt64Type, UInt8Type,
};
use arrow_array::{Array, RecordBatch};
use arrow_schema::{DataType, SchemaRef};
use evalexpr::{ContextWithMutableVariables, DefaultNumericTypes, HashMapContext, Node, Value};

pub use parse::Reduction;
use parse::{Lit, Piece};

/// A derived quantity's values of one run: (t, value) in increasing t; a quantity read from
/// tables without a `t` column has one value with t = None.
pub type Series = Vec<(Option<f64>, f64)>;

/// An error evaluating a quantity on a run's rows (a null value, a selection that matches
/// no row or several, a non-finite result): names the quantity, the run and the table.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("derived quantity {quantity:?}, run {run_id}: {message}")]
pub struct EvalError {
    pub quantity: String,
    pub run_id: u64,
    pub message: String,
}

/// The longest expression accepted (bytes).
pub const MAX_EXPRESSION_BYTES: usize = 4096;
/// The deepest nesting of brackets accepted.
pub const MAX_NESTING: i64 = 64;

/// Column names a quantity may not take: the key columns of the `derived` tables.
pub const RESERVED: &[&str] = &["run_id", "point_id", "replica", "t"];

/// How a column's values compare with a selector's literal.
#[derive(Debug, Clone, Copy, PartialEq)]
enum ColKind {
    Unsigned,
    Signed,
    Float,
    Text,
    Other,
}

fn kind_of(t: &DataType) -> ColKind {
    match t {
        DataType::UInt8 | DataType::UInt16 | DataType::UInt32 | DataType::UInt64 => {
            ColKind::Unsigned
        }
        DataType::Int8 | DataType::Int16 | DataType::Int32 | DataType::Int64 => ColKind::Signed,
        DataType::Float32 | DataType::Float64 => ColKind::Float,
        DataType::Utf8 | DataType::LargeUtf8 => ColKind::Text,
        _ => ColKind::Other,
    }
}

/// A selector, its literal typed as its column.
#[derive(Debug, Clone, PartialEq)]
enum SelVal {
    U(u64),
    I(i64),
    F(f64),
    S(String),
}

/// A resolved reference: a column of one run table, with selectors.
#[derive(Debug, Clone)]
struct ColRef {
    table: &'static str,
    column: String,
    selectors: Vec<(String, SelVal)>,
    has_t: bool,
    text: String,
}

#[derive(Debug, Clone)]
enum Input {
    Ref(ColRef),
    Reduce(Reduction, ColRef),
}

impl Input {
    fn col(&self) -> &ColRef {
        match self {
            Input::Ref(c) | Input::Reduce(_, c) => c,
        }
    }
}

/// One compiled derived quantity.
#[derive(Debug, Clone)]
pub struct Quantity {
    pub name: String,
    /// The expression as the manifest gives it.
    pub text: String,
    /// evalexpr's operator tree of the rewritten text (variables `__q<i>`).
    tree: Node<DefaultNumericTypes>,
    /// What variable `__q<i>` stands for.
    inputs: Vec<Input>,
}

impl Quantity {
    /// Whether the quantity is a time series (a reference, not reduced, to a table with `t`).
    pub fn is_series(&self) -> bool {
        self.inputs
            .iter()
            .any(|i| matches!(i, Input::Ref(c) if c.has_t))
    }
}

/// The manifest's derived quantities, compiled, in name order.
#[derive(Debug, Clone, Default)]
pub struct Quantities {
    pub list: Vec<Quantity>,
}

/// Levenshtein distance (the order of "did you mean" candidates).
fn distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut cur = vec![i + 1];
        for (j, cb) in b.iter().enumerate() {
            cur.push(
                (prev[j] + usize::from(ca != *cb))
                    .min(prev[j + 1] + 1)
                    .min(cur[j] + 1),
            );
        }
        prev = cur;
    }
    prev[b.len()]
}

/// `candidates` nearest `to` first, at most 12, as text.
fn nearest<'a>(to: &str, candidates: impl IntoIterator<Item = &'a str>) -> String {
    let mut c: Vec<&str> = candidates
        .into_iter()
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    c.sort_by_key(|x| (distance(x, to), *x));
    let more = c.len().saturating_sub(12);
    c.truncate(12);
    let mut s = c.join(", ");
    if more > 0 {
        s.push_str(&format!(", ... ({more} more)"));
    }
    s
}

/// A selector's literal typed as the column `kind`.
fn typed_literal(lit: &Lit, kind: ColKind) -> Result<SelVal, String> {
    match (lit, kind) {
        (Lit::Str(s), ColKind::Text) => Ok(SelVal::S(s.clone())),
        (Lit::Num(n), ColKind::Unsigned) => n
            .parse::<u64>()
            .map(SelVal::U)
            .map_err(|_| format!("expected a non-negative integer, got {n}")),
        (Lit::Num(n), ColKind::Signed) => n
            .parse::<i64>()
            .map(SelVal::I)
            .map_err(|_| format!("expected an integer, got {n}")),
        (Lit::Num(n), ColKind::Float) => n
            .parse::<f64>()
            .map(SelVal::F)
            .map_err(|_| format!("expected a number, got {n}")),
        (Lit::Num(n), ColKind::Text) => Err(format!("expected a quoted string, got {n}")),
        (Lit::Str(s), ColKind::Unsigned | ColKind::Signed | ColKind::Float) => {
            Err(format!("expected a number, got the string {s:?}"))
        }
        (_, ColKind::Other) => Err("a column of this type cannot be selected on".into()),
    }
}

/// Resolve a reference against the run tables.
fn resolve(
    r: &parse::RefText,
    tables: &[(&'static str, SchemaRef)],
    numeric: bool,
) -> Result<ColRef, String> {
    let found: Vec<&(&'static str, SchemaRef)> = match &r.table {
        Some(t) => match tables.iter().find(|(n, _)| n == t) {
            Some(x) => vec![x],
            None => {
                return Err(if tables.is_empty() {
                    format!("unknown table `{t}`: this model declares no run table for derived quantities")
                } else {
                    format!(
                        "unknown table `{t}` in `{}`: expected one of {} (nearest first)",
                        r.text,
                        nearest(t, tables.iter().map(|(n, _)| *n))
                    )
                })
            }
        },
        None => tables
            .iter()
            .filter(|(_, s)| s.field_with_name(&r.column).is_ok())
            .collect(),
    };
    let (table, schema) = match found.as_slice() {
        [] if tables.is_empty() => {
            return Err(format!(
                "unknown column `{}`: this model declares no run table for derived quantities",
                r.column
            ))
        }
        [] => {
            let all = tables
                .iter()
                .flat_map(|(_, s)| s.fields().iter().map(|f| f.name().as_str()));
            return Err(format!(
                "unknown column `{}` in `{}`: expected one of {} (nearest first; columns of the run tables {})",
                r.column,
                r.text,
                nearest(&r.column, all),
                tables.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
            ));
        }
        [one] => (one.0, &one.1),
        many => {
            return Err(format!(
                "ambiguous column `{}` in `{}`: it is a column of the tables {}; write `TABLE.{}`",
                r.column,
                r.text,
                many.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", "),
                r.column
            ))
        }
    };
    let field = schema.field_with_name(&r.column).map_err(|_| {
        format!(
            "unknown column `{}` of table {table} in `{}`: expected one of {} (nearest first)",
            r.column,
            r.text,
            nearest(&r.column, schema.fields().iter().map(|f| f.name().as_str()))
        )
    })?;
    let k = kind_of(field.data_type());
    if numeric && !matches!(k, ColKind::Unsigned | ColKind::Signed | ColKind::Float) {
        return Err(format!(
            "column `{}` of table {table} is not a number ({}): it may be used only in a selector",
            r.column,
            field.data_type()
        ));
    }
    let mut selectors = Vec::new();
    let mut errors = Vec::new();
    for (c, lit) in &r.selectors {
        match schema.field_with_name(c) {
            Err(_) => errors.push(format!(
                "selector on unknown column `{c}` of table {table} in `{}`: expected one of {} (nearest first)",
                r.text,
                nearest(c, schema.fields().iter().map(|f| f.name().as_str()))
            )),
            Ok(f) => match typed_literal(lit, kind_of(f.data_type())) {
                Ok(v) => selectors.push((c.clone(), v)),
                Err(e) => errors.push(format!(
                    "selector `{c}` in `{}` ({table}.{c} is {}): {e}",
                    r.text,
                    f.data_type()
                )),
            },
        }
    }
    if !errors.is_empty() {
        return Err(errors.join("; "));
    }
    Ok(ColRef {
        table,
        column: r.column.clone(),
        selectors,
        has_t: schema.field_with_name("t").is_ok(),
        text: r.text.clone(),
    })
}

/// Compile one quantity: its messages if refused.
fn compile_one(
    name: &str,
    text: &str,
    tables: &[(&'static str, SchemaRef)],
) -> Result<Quantity, Vec<String>> {
    if RESERVED.contains(&name) {
        return Err(vec![format!(
            "`{name}` is a column of the derived tables: name the quantity otherwise (not one of {})",
            RESERVED.join(", ")
        )]);
    }
    // Bounded, so that no expression can exhaust the stack of evalexpr's recursive parser.
    let depth = text
        .chars()
        .scan(0i64, |d, c| {
            *d += match c {
                '(' | '[' => 1,
                ')' | ']' => -1,
                _ => 0,
            };
            Some(*d)
        })
        .max()
        .unwrap_or(0);
    if text.len() > MAX_EXPRESSION_BYTES || depth > MAX_NESTING {
        return Err(vec![format!(
            "an expression of {} bytes nested {depth} deep: at most {MAX_EXPRESSION_BYTES} bytes and {MAX_NESTING} levels of brackets",
            text.len()
        )]);
    }
    let (rewritten, pieces) = parse::rewrite(text)?;
    let mut errors = Vec::new();
    let mut inputs = Vec::new();
    for p in &pieces {
        match p {
            Piece::Ref(r) => match resolve(r, tables, true) {
                Ok(c) => inputs.push(Input::Ref(c)),
                Err(e) => errors.push(e),
            },
            Piece::Reduce(red, r) => match resolve(r, tables, *red != Reduction::Count) {
                Ok(c) => {
                    if matches!(red, Reduction::First | Reduction::Last | Reduction::Slope)
                        && !c.has_t
                    {
                        errors.push(format!(
                            "`{}({})`: table {} has no `t` column to order or fit against",
                            red.name(),
                            r.text,
                            c.table
                        ));
                    }
                    inputs.push(Input::Reduce(*red, c))
                }
                Err(e) => errors.push(e),
            },
        }
    }
    let tree = match evalexpr::build_operator_tree::<DefaultNumericTypes>(&rewritten) {
        Ok(t) => Some(t),
        Err(e) => {
            errors.push(format!("syntax error in `{text}`: {e}"));
            None
        }
    };
    if let (Some(tree), true) = (&tree, errors.is_empty()) {
        // A trial evaluation with every value 1: evalexpr's type errors (a string, a bool, a
        // function given the wrong arguments) are found here rather than at run time.
        let values = vec![1.0; inputs.len()];
        if let Err(e) = evaluate(tree, &values) {
            errors.push(format!("cannot evaluate `{text}`: {e}"));
        }
    }
    match tree {
        Some(tree) if errors.is_empty() => Ok(Quantity {
            name: name.to_string(),
            text: text.to_string(),
            tree,
            inputs,
        }),
        _ => Err(errors),
    }
}

/// The tree's value with `__q<i>` = `values[i]`.
fn evaluate(tree: &Node<DefaultNumericTypes>, values: &[f64]) -> Result<f64, String> {
    let mut ctx = HashMapContext::<DefaultNumericTypes>::new();
    for (i, v) in values.iter().enumerate() {
        ctx.set_value(parse::var(i), Value::Float(*v))
            .map_err(|e| e.to_string())?;
    }
    match tree.eval_with_context(&ctx) {
        Ok(Value::Float(x)) => Ok(x),
        Ok(Value::Int(x)) => Ok(x as f64),
        Ok(v) => Err(format!("the expression gives {v:?}, not a number")),
        Err(e) => Err(e.to_string()),
    }
}

/// Compile every quantity of `derived` (name -> expression) against the model's run tables
/// (`tables`: name and Arrow schema of every run table the model can write). Every problem
/// at once as (JSON pointer `/derived/NAME`, message).
pub fn compile(
    derived: &BTreeMap<String, String>,
    tables: &[(&'static str, SchemaRef)],
) -> Result<Quantities, Vec<(String, String)>> {
    let mut list = Vec::new();
    let mut errors = Vec::new();
    for (name, text) in derived {
        match compile_one(name, text, tables) {
            Ok(q) => list.push(q),
            Err(es) => {
                let at = format!("/derived/{}", pointer_escape(name));
                errors.extend(es.into_iter().map(|e| (at.clone(), e)));
            }
        }
    }
    if errors.is_empty() {
        Ok(Quantities { list })
    } else {
        Err(errors)
    }
}

/// A JSON pointer's token (RFC 6901).
fn pointer_escape(s: &str) -> String {
    s.replace('~', "~0").replace('/', "~1")
}

/// t as an ordered key (total order of f64).
#[derive(Debug, Clone, Copy)]
struct TKey(f64);
impl PartialEq for TKey {
    fn eq(&self, o: &Self) -> bool {
        self.0.total_cmp(&o.0) == Ordering::Equal
    }
}
impl Eq for TKey {}
impl PartialOrd for TKey {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for TKey {
    fn cmp(&self, o: &Self) -> Ordering {
        self.0.total_cmp(&o.0)
    }
}

/// The selected rows of one reference, per run: (t, value) in table order.
type Selected = BTreeMap<u64, Vec<(Option<f64>, Option<f64>)>>;

fn column_f64(a: &dyn Array) -> Option<Vec<Option<f64>>> {
    macro_rules! prim {
        ($t:ty) => {
            a.as_primitive::<$t>()
                .iter()
                .map(|v| v.map(|x| x as f64))
                .collect()
        };
    }
    Some(match a.data_type() {
        DataType::Float64 => a.as_primitive::<Float64Type>().iter().collect(),
        DataType::Float32 => prim!(Float32Type),
        DataType::UInt8 => prim!(UInt8Type),
        DataType::UInt16 => prim!(UInt16Type),
        DataType::UInt32 => prim!(UInt32Type),
        DataType::UInt64 => prim!(UInt64Type),
        DataType::Int8 => prim!(Int8Type),
        DataType::Int16 => prim!(Int16Type),
        DataType::Int32 => prim!(Int32Type),
        DataType::Int64 => prim!(Int64Type),
        _ => return None,
    })
}

fn column_u64(a: &dyn Array) -> Option<Vec<Option<u64>>> {
    macro_rules! prim {
        ($t:ty) => {
            a.as_primitive::<$t>()
                .iter()
                .map(|v| v.map(|x| x as u64))
                .collect()
        };
    }
    Some(match a.data_type() {
        DataType::UInt8 => prim!(UInt8Type),
        DataType::UInt16 => prim!(UInt16Type),
        DataType::UInt32 => prim!(UInt32Type),
        DataType::UInt64 => a.as_primitive::<UInt64Type>().iter().collect(),
        _ => return None,
    })
}

fn column_i64(a: &dyn Array) -> Option<Vec<Option<i64>>> {
    macro_rules! prim {
        ($t:ty) => {
            a.as_primitive::<$t>()
                .iter()
                .map(|v| v.map(|x| x as i64))
                .collect()
        };
    }
    Some(match a.data_type() {
        DataType::Int8 => prim!(Int8Type),
        DataType::Int16 => prim!(Int16Type),
        DataType::Int32 => prim!(Int32Type),
        DataType::Int64 => a.as_primitive::<Int64Type>().iter().collect(),
        _ => return None,
    })
}

/// Which rows of `b` a selector keeps (a column the batch lacks keeps none).
fn selector_mask(b: &RecordBatch, column: &str, v: &SelVal) -> Vec<bool> {
    let n = b.num_rows();
    let Some(a) = b.column_by_name(column) else {
        return vec![false; n];
    };
    let a = a.as_ref();
    let mask: Option<Vec<bool>> = match v {
        SelVal::U(x) => column_u64(a).map(|c| c.iter().map(|y| *y == Some(*x)).collect()),
        SelVal::I(x) => column_i64(a).map(|c| c.iter().map(|y| *y == Some(*x)).collect()),
        SelVal::F(x) => column_f64(a).map(|c| c.iter().map(|y| *y == Some(*x)).collect()),
        SelVal::S(x) => match a.data_type() {
            DataType::Utf8 => Some(
                a.as_string::<i32>()
                    .iter()
                    .map(|y| y == Some(x.as_str()))
                    .collect(),
            ),
            DataType::LargeUtf8 => Some(
                a.as_string::<i64>()
                    .iter()
                    .map(|y| y == Some(x.as_str()))
                    .collect(),
            ),
            _ => None,
        },
    };
    mask.unwrap_or_else(|| vec![false; n])
}

/// The selected rows of `c` in `batches`, per run.
fn select(c: &ColRef, batches: &[RecordBatch], out: &mut Selected) {
    for b in batches {
        let Some(runs) = b
            .column_by_name("run_id")
            .and_then(|a| column_u64(a.as_ref()))
        else {
            continue;
        };
        let n = b.num_rows();
        let mut keep = vec![true; n];
        for (col, v) in &c.selectors {
            for (k, m) in keep.iter_mut().zip(selector_mask(b, col, v)) {
                *k &= m;
            }
        }
        let values = b
            .column_by_name(&c.column)
            .and_then(|a| column_f64(a.as_ref()))
            .unwrap_or_else(|| vec![None; n]);
        let t = b
            .column_by_name("t")
            .filter(|_| c.has_t)
            .and_then(|a| column_f64(a.as_ref()));
        for i in 0..n {
            if let (true, Some(r)) = (keep[i], runs[i]) {
                out.entry(r)
                    .or_default()
                    .push((t.as_ref().and_then(|t| t[i]), values[i]));
            }
        }
    }
}

fn fmt_t(t: Option<f64>) -> String {
    t.map(|t| format!(" at t = {t}")).unwrap_or_default()
}

/// A reduction of one run's selected rows of `c`.
fn reduce(r: Reduction, c: &ColRef, rows: &[(Option<f64>, Option<f64>)]) -> Result<f64, String> {
    if r == Reduction::Count {
        return Ok(rows.len() as f64);
    }
    if rows.is_empty() {
        return Err(format!(
            "`{}({})`: no row of {} matches `{}`",
            r.name(),
            c.text,
            c.table,
            c.text
        ));
    }
    let mut v = Vec::with_capacity(rows.len());
    for (t, x) in rows {
        match x {
            Some(x) => v.push((t.unwrap_or(f64::NAN), *x)),
            None => {
                return Err(format!(
                    "`{}({})`: {}.{} is null{} (an observable not recorded in this run?)",
                    r.name(),
                    c.text,
                    c.table,
                    c.column,
                    fmt_t(*t)
                ))
            }
        }
    }
    let n = v.len() as f64;
    Ok(match r {
        Reduction::Mean => v.iter().map(|x| x.1).sum::<f64>() / n,
        Reduction::Sum => v.iter().map(|x| x.1).sum(),
        Reduction::Min => v.iter().map(|x| x.1).fold(f64::INFINITY, f64::min),
        Reduction::Max => v.iter().map(|x| x.1).fold(f64::NEG_INFINITY, f64::max),
        Reduction::First | Reduction::Last => {
            let pick = |a: f64, b: f64| {
                if r == Reduction::First {
                    a.total_cmp(&b)
                } else {
                    b.total_cmp(&a)
                }
            };
            let best = v
                .iter()
                .map(|x| x.0)
                .min_by(|a, b| pick(*a, *b))
                .expect("rows");
            let at: Vec<f64> = v
                .iter()
                .filter(|x| x.0.total_cmp(&best).is_eq())
                .map(|x| x.1)
                .collect();
            if at.len() > 1 {
                return Err(format!(
                    "`{}({})`: {} rows of {} at t = {best}: a selection must name one row per time (add selectors)",
                    r.name(),
                    c.text,
                    at.len(),
                    c.table
                ));
            }
            at[0]
        }
        Reduction::Slope => {
            let mt = v.iter().map(|x| x.0).sum::<f64>() / n;
            let my = v.iter().map(|x| x.1).sum::<f64>() / n;
            let sxx: f64 = v.iter().map(|x| (x.0 - mt) * (x.0 - mt)).sum();
            let sxy: f64 = v.iter().map(|x| (x.0 - mt) * (x.1 - my)).sum();
            if !(sxx > 0.0) {
                return Err(format!(
                    "`slope({})`: a slope needs rows at two times at least, found {} row(s) at one time",
                    c.text,
                    v.len()
                ));
            }
            sxy / sxx
        }
        Reduction::Count => unreachable!("counted above"),
    })
}

impl Quantity {
    /// The quantity's series of one run, from the selected rows of each input.
    fn eval_run(&self, sel: &[&[(Option<f64>, Option<f64>)]]) -> Result<Series, String> {
        let mut fixed = vec![0.0; self.inputs.len()];
        // Per time-dependent reference: its value at each t.
        let mut timed: Vec<(usize, BTreeMap<TKey, f64>)> = Vec::new();
        for (i, input) in self.inputs.iter().enumerate() {
            let rows = sel[i];
            match input {
                Input::Reduce(r, c) => fixed[i] = reduce(*r, c, rows)?,
                Input::Ref(c) if c.has_t => {
                    let mut at: BTreeMap<TKey, f64> = BTreeMap::new();
                    let mut several: BTreeMap<TKey, usize> = BTreeMap::new();
                    for (t, x) in rows {
                        let t = t.unwrap_or(f64::NAN);
                        let Some(x) = x else {
                            return Err(format!(
                                "{}.{} is null at t = {t} (an observable not recorded in this run?)",
                                c.table, c.column
                            ));
                        };
                        if at.insert(TKey(t), *x).is_some() {
                            *several.entry(TKey(t)).or_insert(1) += 1;
                        }
                    }
                    if let Some((t, k)) = several.iter().next() {
                        return Err(format!(
                            "`{}` matches {k} rows of {} at t = {}: a selection must name one row per time (add selectors)",
                            c.text, c.table, t.0
                        ));
                    }
                    timed.push((i, at));
                }
                Input::Ref(c) => match rows {
                    [(_, Some(x))] => fixed[i] = *x,
                    [(_, None)] => {
                        return Err(format!(
                            "{}.{} is null (an observable not recorded in this run?)",
                            c.table, c.column
                        ))
                    }
                    [] => {
                        return Err(format!("no row of {} matches `{}`", c.table, c.text));
                    }
                    many => {
                        return Err(format!(
                            "`{}` matches {} rows of {}: a selection must name exactly one row (add selectors)",
                            c.text,
                            many.len(),
                            c.table
                        ))
                    }
                },
            }
        }
        let check = |t: Option<f64>, x: f64| {
            if x.is_finite() {
                Ok((t, x))
            } else {
                Err(format!("the value{} is {x}, not a finite number", fmt_t(t)))
            }
        };
        if timed.is_empty() {
            return Ok(vec![check(None, evaluate(&self.tree, &fixed)?)?]);
        }
        let times: Vec<TKey> = timed[0]
            .1
            .keys()
            .filter(|t| timed.iter().all(|(_, m)| m.contains_key(t)))
            .copied()
            .collect();
        if times.is_empty() {
            let refs: Vec<&str> = timed
                .iter()
                .map(|(i, _)| self.inputs[*i].col().text.as_str())
                .collect();
            return Err(format!(
                "no time at which every reference ({}) has a row",
                refs.join(", ")
            ));
        }
        let mut out = Vec::with_capacity(times.len());
        for t in times {
            let mut values = fixed.clone();
            for (i, m) in &timed {
                values[*i] = m[&t];
            }
            out.push(check(Some(t.0), evaluate(&self.tree, &values)?)?);
        }
        Ok(out)
    }
}

impl Quantities {
    pub fn is_empty(&self) -> bool {
        self.list.is_empty()
    }

    /// The run tables the quantities read.
    pub fn tables(&self) -> BTreeSet<&'static str> {
        self.list
            .iter()
            .flat_map(|q| q.inputs.iter().map(|i| i.col().table))
            .collect()
    }

    /// Evaluate every quantity on the rows of `rows` (table -> batches holding the rows of
    /// one or more runs, each batch with a `run_id` column): per run (ascending run_id), one
    /// `Series` per quantity in `list` order.
    pub fn eval(
        &self,
        rows: &BTreeMap<&str, Vec<RecordBatch>>,
    ) -> Result<BTreeMap<u64, Vec<Series>>, EvalError> {
        self.eval_each(rows, None)
            .into_iter()
            .map(|(r, v)| Ok((r, v.into_iter().collect::<Result<Vec<_>, _>>()?)))
            .collect()
    }

    /// As [`Quantities::eval`], each quantity of each run on its own (an error of one leaves
    /// the others): for the runs `runs` if given (a run without rows gets its errors), else
    /// for every run with a row in a table the quantities read.
    pub fn eval_each(
        &self,
        rows: &BTreeMap<&str, Vec<RecordBatch>>,
        runs: Option<&[u64]>,
    ) -> BTreeMap<u64, Vec<Result<Series, EvalError>>> {
        let empty: Vec<RecordBatch> = Vec::new();
        // Every input's selected rows per run.
        let selected: Vec<Vec<Selected>> = self
            .list
            .iter()
            .map(|q| {
                q.inputs
                    .iter()
                    .map(|i| {
                        let c = i.col();
                        let mut s = Selected::new();
                        select(c, rows.get(c.table).unwrap_or(&empty), &mut s);
                        s
                    })
                    .collect()
            })
            .collect();
        let runs: BTreeSet<u64> = match runs {
            Some(r) => r.iter().copied().collect(),
            None => {
                let mut all = BTreeSet::new();
                for t in self.tables() {
                    for b in rows.get(t).unwrap_or(&empty) {
                        if let Some(r) = b
                            .column_by_name("run_id")
                            .and_then(|a| column_u64(a.as_ref()))
                        {
                            all.extend(r.into_iter().flatten());
                        }
                    }
                }
                all
            }
        };
        let none: Vec<(Option<f64>, Option<f64>)> = Vec::new();
        runs.into_iter()
            .map(|run| {
                let per_q = self
                    .list
                    .iter()
                    .zip(&selected)
                    .map(|(q, sel)| {
                        let sel: Vec<&[(Option<f64>, Option<f64>)]> = sel
                            .iter()
                            .map(|s| s.get(&run).unwrap_or(&none).as_slice())
                            .collect();
                        q.eval_run(&sel).map_err(|message| EvalError {
                            quantity: q.name.clone(),
                            run_id: run,
                            message,
                        })
                    })
                    .collect();
                (run, per_q)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests;
