//! Derived quantities: expressions over the columns of a model's run tables, evaluated per
//! run from that run's rows (manifest `derived`). Pure: knows no campaign, no model, no file;
//! it sees table names, Arrow schemas and record batches.
//!
//! STUB (API fixed for the helpers of issue 24; the bodies are filled in on branch `derived`).

use std::collections::{BTreeMap, BTreeSet};

use arrow_array::RecordBatch;
use arrow_schema::SchemaRef;

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

/// One compiled derived quantity.
#[derive(Debug, Clone)]
pub struct Quantity {
    pub name: String,
    /// The expression as the manifest gives it.
    pub text: String,
}

/// The manifest's derived quantities, compiled, in name order.
#[derive(Debug, Clone, Default)]
pub struct Quantities {
    pub list: Vec<Quantity>,
}

/// Compile every quantity of `derived` (name -> expression) against the model's run tables
/// (`tables`: name and Arrow schema of every run table the model can write). Every problem
/// at once as (JSON pointer `/derived/NAME`, message).
pub fn compile(
    derived: &BTreeMap<String, String>,
    tables: &[(&'static str, SchemaRef)],
) -> Result<Quantities, Vec<(String, String)>> {
    let _ = tables;
    Ok(Quantities {
        list: derived
            .iter()
            .map(|(n, t)| Quantity {
                name: n.clone(),
                text: t.clone(),
            })
            .collect(),
    })
}

impl Quantities {
    pub fn is_empty(&self) -> bool {
        self.list.is_empty()
    }

    /// The run tables the quantities read.
    pub fn tables(&self) -> BTreeSet<&'static str> {
        BTreeSet::new()
    }

    /// Evaluate every quantity on the rows of `rows` (table -> batches holding the rows of
    /// one or more runs, each batch with a `run_id` column): per run (ascending run_id), one
    /// `Series` per quantity in `list` order.
    pub fn eval(
        &self,
        rows: &BTreeMap<&str, Vec<RecordBatch>>,
    ) -> Result<BTreeMap<u64, Vec<Series>>, EvalError> {
        let _ = rows;
        unimplemented!("derived::Quantities::eval (branch `derived`)")
    }
}
