//! A campaign as a model sees it (summaries, figures, analysis): its points with their typed
//! parameters, its finished runs, its tables.

use std::collections::BTreeMap;

use arrow_array::RecordBatch;
use serde_json::Value;

use crate::declare_table;
use crate::store::dataset::Dataset;
use crate::store::parquet_io::StoreError;
use crate::store::typed::{U32, U64};

declare_table! {
    /// The key of every point's rows: [`CampaignView::sweep`] (`point_id`, then one column
    /// per sweep key) and every summary.
    pub struct SweepKey in "sweep", read as SweepKeyCols {
        point_id: U32,
    }
}

declare_table! {
    /// The key of every run table's rows (`run_id`, `point_id`, then the model's columns).
    pub struct RunKey in "run table", read as RunKeyCols {
        run_id: U64,
    }
}

/// A campaign as a model sees it: its points with their parameters, its finished runs, its
/// tables. `P` is the model's `Params` (or [`ModelParams`] before dispatch).
pub struct CampaignView<'a, P> {
    /// The campaign's name (figure titles).
    pub name: &'a str,
    pub points: Vec<PointView<'a, P>>,
    /// Replicas per point (an upper bound on the runs per point).
    pub replicas: u32,
    /// The names figures give sweep keys, derived quantities and columns.
    pub labels: Labels,
    /// The runs finished with status done, and their replica numbers.
    pub done: &'a BTreeMap<u64, u32>,
    pub data: &'a Dataset,
    /// The swept parameters of every point: `point_id` and the `points` table's sweep
    /// columns (same names and types), one row per point; see [`CampaignView::write_summary`].
    pub sweep: RecordBatch,
}

impl<P> CampaignView<'_, P> {
    /// Write a replica summary whole (`tables/<table>/summary.parquet`): `batch`, whose rows
    /// each name their point in a `point_id` column, with the point's sweep columns right
    /// after `point_id` (so a summary is read without a join with `points`). Every summary
    /// goes through here; the model names no sweep key.
    pub fn write_summary(&self, table: &str, batch: &RecordBatch) -> Result<(), StoreError> {
        const KEY: &str = SweepKey::column("point_id");
        let batch = crate::store::cols::join_after_key(batch, table, KEY, &self.sweep)?;
        self.data.write_whole(table, "summary.parquet", &batch)
    }
}

impl<P> CampaignView<'_, P> {
    /// The batches of a raw table (one row per run and more, with a `run_id` column) holding
    /// only the rows of the runs this view describes (`done`: the latest manifest's finished
    /// runs), as every figure drawn from a raw table must: rows of runs the latest manifest no
    /// longer asks for stay in the table but in no figure.
    pub fn read_done(&self, table: &str) -> Result<Vec<RecordBatch>, StoreError> {
        self.data
            .read(table)?
            .iter()
            .map(|b| self.keep_done(b, table))
            .collect()
    }

    /// The rows of `b` (of `table`, with a `run_id` column) of the runs in `done`.
    pub fn keep_done(&self, b: &RecordBatch, table: &str) -> Result<RecordBatch, StoreError> {
        let runs = RunKeyCols::read(b, table)?.run_id;
        let keep: arrow_array::BooleanArray = runs
            .iter()
            .map(|r| Some(r.is_some_and(|r| self.done.contains_key(&r))))
            .collect();
        arrow_select::filter::filter_record_batch(b, &keep)
            .map_err(|e| StoreError::Arrow(format!("{table}: {e}")))
    }
}

impl<P> CampaignView<'_, P> {
    /// The legend label of a point: its swept values (quotes dropped), `point <id>` without a
    /// sweep.
    pub fn point_label(&self, point: u32) -> String {
        let label = self
            .points
            .iter()
            .find(|p| p.point_id == point)
            .map(|p| p.label.replace('"', ""))
            .unwrap_or_default();
        if label.is_empty() {
            format!("point {point}")
        } else {
            label
        }
    }
}

/// The names on the figures: the manifest's `labels` (sweep key, parameter path, derived
/// quantity or column -> name) over the model's physics defaults (`Model::physics_name`).
/// A sweep key is found as its path (`species.list.1.mass`) and as its column name
/// (`species_list_1_mass`), whichever of the two the manifest's `labels` uses.
#[derive(Clone, Debug, Default)]
pub struct Labels {
    given: BTreeMap<String, String>,
    defaults: Option<fn(&str) -> Option<String>>,
}

impl Labels {
    pub fn new(given: BTreeMap<String, String>, defaults: fn(&str) -> Option<String>) -> Self {
        Labels {
            given,
            defaults: Some(defaults),
        }
    }

    /// The name given to `key` in the manifest's `labels`, if any.
    pub fn given(&self, key: &str) -> Option<&str> {
        if let Some(v) = self.given.get(key) {
            return Some(v);
        }
        let col = key.replace('.', "_");
        self.given
            .iter()
            .find(|(k, _)| k.replace('.', "_") == col)
            .map(|(_, v)| v.as_str())
    }

    /// The name of `key` on a figure: the manifest's label, else the model's physics name,
    /// else the key itself.
    pub fn name(&self, key: &str) -> String {
        if let Some(v) = self.given(key) {
            return v.to_string();
        }
        self.defaults
            .and_then(|f| f(key))
            .unwrap_or_else(|| key.to_string())
    }

    /// A point's legend: `name=value, ...` of its swept values (quotes dropped by the
    /// callers that show it).
    pub fn point_label(&self, swept: &[(&str, &Value)]) -> String {
        swept
            .iter()
            .map(|(k, v)| format!("{}={v}", self.name(k)))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// One sweep point of a [`CampaignView`].
pub struct PointView<'a, P> {
    pub point_id: u32,
    pub params: &'a P,
    /// The swept values, `key=value, ...` (empty without a sweep).
    pub label: String,
    /// The swept values: each sweep key (a dotted path into `params`) with the point's value
    /// there, in the manifest's order (empty without a sweep).
    pub swept: Vec<(&'a str, &'a Value)>,
    /// How many of the view's finished runs (`CampaignView::done`) are of this point.
    pub runs_done: u32,
}

#[cfg(test)]
mod labels_tests {
    use super::*;

    fn defaults(key: &str) -> Option<String> {
        (key == "packing_fraction").then(|| "φ".to_string())
    }

    #[test]
    fn given_names_over_the_models_defaults() {
        let given: BTreeMap<String, String> = [
            ("species.list.1.mass".to_string(), "mass ratio".to_string()),
            ("gamma".to_string(), "T_2/T_1".to_string()),
        ]
        .into();
        let l = Labels::new(given, defaults);
        // A sweep key by its path and by its column name.
        assert_eq!(l.name("species.list.1.mass"), "mass ratio");
        assert_eq!(l.name("species_list_1_mass"), "mass ratio");
        assert_eq!(l.name("gamma"), "T_2/T_1");
        assert_eq!(l.name("packing_fraction"), "φ");
        assert_eq!(l.name("dt"), "dt");
        let (a, b) = (Value::from(2), Value::from(0.1));
        assert_eq!(
            l.point_label(&[("species.list.1.mass", &a), ("packing_fraction", &b)]),
            "mass ratio=2, φ=0.1"
        );
        assert_eq!(
            Labels::default().name("packing_fraction"),
            "packing_fraction"
        );
    }
}
