//! The tables and figures of the manifest's derived quantities (`derived`), written with the
//! model's summaries and, like them, rewritten whole from the committed rows of the latest
//! manifest's finished runs (so they are the same whatever the threads, shards, kills):
//!
//! - `derived`: per finished run, `run_id`, `point_id`, the point's sweep columns, `replica`,
//!   `t` (null for a quantity of one value per run) and one column per quantity (name order),
//!   null where the run's quantity cannot be evaluated (warned, naming run and quantity);
//! - `derived_summary`: per point and t, `NAME_mean`, `NAME_sem` (null with one replica) and
//!   `NAME_n` over the replicas (in replica order).
//!
//! The campaign knows no particular model: the run tables come from `ModelKind::run_tables`,
//! their rows from the `CampaignView`.

use std::cmp::Ordering;
use std::collections::BTreeMap;
use std::sync::Arc;

use arrow_array::cast::AsArray;
use arrow_array::types::{Float64Type, UInt32Type};
use arrow_array::{Array, ArrayRef, Float64Array, RecordBatch, UInt32Array, UInt64Array};
use arrow_schema::{DataType, Field, Schema};

use crate::derived::{Quantities, Series};
use crate::models::{overlay_figures, CampaignView, ModelParams, Overlay, PointCurve};
use crate::plot::Figure;
use crate::store::parquet_io::StoreError;

/// Per finished run, the derived quantities' values.
pub const DERIVED: &str = "derived";
/// Per point and t, mean, sem and n of each derived quantity over the replicas.
pub const DERIVED_SUMMARY: &str = "derived_summary";

/// t as an ordered key (`None` first, then increasing t).
#[derive(Debug, Clone, Copy)]
struct T(Option<f64>);
impl PartialEq for T {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == Ordering::Equal
    }
}
impl Eq for T {}
impl PartialOrd for T {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for T {
    fn cmp(&self, o: &Self) -> Ordering {
        match (self.0, o.0) {
            (None, None) => Ordering::Equal,
            (None, Some(_)) => Ordering::Less,
            (Some(_), None) => Ordering::Greater,
            (Some(a), Some(b)) => a.total_cmp(&b),
        }
    }
}

/// The quantities of every finished run of the view (`view.done`), each quantity of each run
/// on its own (an error of one leaves the others): what the tables are written from and what
/// the error targets judge.
pub fn values(
    view: &CampaignView<'_, ModelParams>,
    q: &Quantities,
) -> Result<BTreeMap<u64, Vec<Result<Series, crate::derived::EvalError>>>, StoreError> {
    let mut rows: BTreeMap<&str, Vec<RecordBatch>> = BTreeMap::new();
    for t in q.tables() {
        rows.insert(t, view.read_done(t)?);
    }
    let runs: Vec<u64> = view.done.keys().copied().collect();
    Ok(q.eval_each(&rows, Some(&runs)))
}

/// Write `derived` and `derived_summary` of the view's finished runs (`view.done`; `point_of`
/// gives a run's point).
pub fn write(
    view: &CampaignView<'_, ModelParams>,
    q: &Quantities,
    point_of: &dyn Fn(u64) -> u32,
) -> Result<(), StoreError> {
    let values = values(view, q)?;
    // Per run: its series per quantity (None where it could not be evaluated).
    let mut per_run: BTreeMap<u64, Vec<Option<Series>>> = BTreeMap::new();
    for (run, qs) in values {
        let v = qs
            .into_iter()
            .map(|r| match r {
                Ok(s) => Some(s),
                Err(e) => {
                    tracing::warn!(run_id = e.run_id, quantity = %e.quantity, "{e}; left null");
                    None
                }
            })
            .collect();
        per_run.insert(run, v);
    }
    let nq = q.list.len();

    // derived: per run, the union of its quantities' times.
    let (mut run_c, mut point_c, mut rep_c, mut t_c) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut val_c: Vec<Vec<Option<f64>>> = vec![Vec::new(); nq];
    // summary: (point, t) -> per quantity (replica, value).
    let mut acc: BTreeMap<(u32, T), Vec<Vec<(u32, f64)>>> = BTreeMap::new();
    for (run, series) in &per_run {
        let point = point_of(*run);
        let replica = view.done[run];
        let mut at: BTreeMap<T, Vec<Option<f64>>> = BTreeMap::new();
        for (i, s) in series.iter().enumerate() {
            for (t, x) in s.iter().flatten() {
                at.entry(T(*t)).or_insert_with(|| vec![None; nq])[i] = Some(*x);
                acc.entry((point, T(*t)))
                    .or_insert_with(|| vec![Vec::new(); nq])[i]
                    .push((replica, *x));
            }
        }
        if at.is_empty() {
            at.insert(T(None), vec![None; nq]);
        }
        for (t, v) in at {
            run_c.push(*run);
            point_c.push(point);
            rep_c.push(replica);
            t_c.push(t.0);
            for (c, x) in val_c.iter_mut().zip(v) {
                c.push(x);
            }
        }
    }
    let mut fields = vec![
        Field::new("run_id", DataType::UInt64, false),
        Field::new("point_id", DataType::UInt32, false),
        Field::new("replica", DataType::UInt32, false),
        Field::new("t", DataType::Float64, true),
    ];
    let mut cols: Vec<ArrayRef> = vec![
        Arc::new(UInt64Array::from(run_c)),
        Arc::new(UInt32Array::from(point_c)),
        Arc::new(UInt32Array::from(rep_c)),
        Arc::new(Float64Array::from(t_c)),
    ];
    for (qu, c) in q.list.iter().zip(val_c) {
        fields.push(Field::new(&qu.name, DataType::Float64, true));
        cols.push(Arc::new(Float64Array::from(c)));
    }
    let batch = RecordBatch::try_new(Arc::new(Schema::new(fields)), cols)
        .map_err(|e| StoreError::Arrow(format!("{DERIVED}: {e}")))?;
    view.write_summary(DERIVED, &batch)?;

    // derived_summary.
    let mut fields = vec![
        Field::new("point_id", DataType::UInt32, false),
        Field::new("t", DataType::Float64, true),
    ];
    let points: Vec<u32> = acc.keys().map(|k| k.0).collect();
    let ts: Vec<Option<f64>> = acc.keys().map(|k| k.1 .0).collect();
    let mut cols: Vec<ArrayRef> = vec![
        Arc::new(UInt32Array::from(points)),
        Arc::new(Float64Array::from(ts)),
    ];
    for (i, qu) in q.list.iter().enumerate() {
        let (mut m, mut s, mut n) = (Vec::new(), Vec::new(), Vec::new());
        for v in acc.values() {
            if v[i].is_empty() {
                m.push(None);
                s.push(None);
                n.push(0u32);
            } else {
                let (k, mean, sem) = crate::math::stats::replica_mean_sem(v[i].clone());
                m.push(Some(mean));
                s.push(sem);
                n.push(k);
            }
        }
        fields.push(Field::new(
            format!("{}_mean", qu.name),
            DataType::Float64,
            true,
        ));
        fields.push(Field::new(
            format!("{}_sem", qu.name),
            DataType::Float64,
            true,
        ));
        fields.push(Field::new(
            format!("{}_n", qu.name),
            DataType::UInt32,
            false,
        ));
        cols.push(Arc::new(Float64Array::from(m)));
        cols.push(Arc::new(Float64Array::from(s)));
        cols.push(Arc::new(UInt32Array::from(n)));
    }
    let batch = RecordBatch::try_new(Arc::new(Schema::new(fields)), cols)
        .map_err(|e| StoreError::Arrow(format!("{DERIVED_SUMMARY}: {e}")))?;
    view.write_summary(DERIVED_SUMMARY, &batch)
}

/// A numeric column's values as f64 (None for another type or a null).
fn f64s(a: &dyn Array) -> Vec<Option<f64>> {
    match a.data_type() {
        DataType::Float64 => a.as_primitive::<Float64Type>().iter().collect(),
        DataType::Float32 => a
            .as_primitive::<arrow_array::types::Float32Type>()
            .iter()
            .map(|v| v.map(f64::from))
            .collect(),
        DataType::UInt32 => a
            .as_primitive::<UInt32Type>()
            .iter()
            .map(|v| v.map(f64::from))
            .collect(),
        DataType::UInt64 => a
            .as_primitive::<arrow_array::types::UInt64Type>()
            .iter()
            .map(|v| v.map(|x| x as f64))
            .collect(),
        DataType::Int64 => a
            .as_primitive::<arrow_array::types::Int64Type>()
            .iter()
            .map(|v| v.map(|x| x as f64))
            .collect(),
        _ => vec![None; a.len()],
    }
}

/// The figures of the derived quantities from `derived_summary`: per quantity, mean +- sem
/// against t (one series per point) for a time series, against the first sweep key (or the
/// point id) for a quantity of one value per run.
pub fn figures(
    view: &CampaignView<'_, ModelParams>,
    q: &Quantities,
) -> Result<Vec<(String, Figure)>, StoreError> {
    let batches = view.data.read(DERIVED_SUMMARY)?;
    // First sweep key's values per point (numeric), from the sweep batch.
    let sweep_x: Option<(String, BTreeMap<u32, f64>)> = (view.sweep.num_columns() > 1)
        .then(|| {
            let name = view.sweep.schema().field(1).name().clone();
            let ids = view.sweep.column(0).as_primitive::<UInt32Type>();
            let xs = f64s(view.sweep.column(1).as_ref());
            let m: BTreeMap<u32, f64> = ids
                .iter()
                .zip(xs)
                .filter_map(|(p, x)| Some((p?, x?)))
                .collect();
            (m.len() == view.sweep.num_rows()).then_some((view.labels.name(&name), m))
        })
        .flatten();
    let mut out = Vec::new();
    for qu in &q.list {
        // (point, t, mean, sem)
        let mut rows: Vec<(u32, Option<f64>, f64, f64)> = Vec::new();
        for b in &batches {
            let (Some(p), Some(t), Some(m), Some(s)) = (
                b.column_by_name("point_id"),
                b.column_by_name("t"),
                b.column_by_name(&format!("{}_mean", qu.name)),
                b.column_by_name(&format!("{}_sem", qu.name)),
            ) else {
                continue;
            };
            let p = f64s(p.as_ref());
            let (t, m, s) = (f64s(t.as_ref()), f64s(m.as_ref()), f64s(s.as_ref()));
            for i in 0..b.num_rows() {
                if let (Some(p), Some(m)) = (p[i], m[i]) {
                    rows.push((p as u32, t[i], m, s[i].unwrap_or(0.0)));
                }
            }
        }
        let id = format!("derived-{}", qu.name);
        let y_name = view.labels.name(&qu.name);
        let y_label = y_name.as_str();
        if qu.is_series() {
            let mut by_point: BTreeMap<u32, Vec<(f64, f64, f64)>> = BTreeMap::new();
            for (p, t, m, s) in rows {
                if let Some(t) = t {
                    by_point.entry(p).or_default().push((t, m, s));
                }
            }
            let curves = by_point
                .into_iter()
                .map(|(p, data)| PointCurve {
                    point: p,
                    label: view.point_label(p),
                    data,
                    line: None,
                })
                .collect();
            let what = format!("derived {} = {}", qu.name, qu.text);
            let o = Overlay {
                id: &id,
                what: &what,
                x_label: "t",
                y_label,
                log_x: false,
                log_y: false,
                legend_low: false,
            };
            out.extend(overlay_figures(view.name, &o, curves, &|_, _| Vec::new()));
        } else {
            let (x_label, data): (String, Vec<(f64, f64, f64)>) = match &sweep_x {
                Some((name, xs)) => (
                    name.clone(),
                    rows.iter()
                        .filter_map(|(p, _, m, s)| Some((*xs.get(p)?, *m, *s)))
                        .collect(),
                ),
                None => (
                    "point_id".into(),
                    rows.iter()
                        .map(|(p, _, m, s)| (f64::from(*p), *m, *s))
                        .collect(),
                ),
            };
            if data.is_empty() {
                continue;
            }
            let fig = Figure::new(
                format!("{} - derived {} = {}", view.name, qu.name, qu.text),
                &x_label,
                y_label,
                vec![crate::plot::Series {
                    label: format!("{} (mean +- sem)", qu.name),
                    points: data,
                    line: false,
                }],
            );
            out.push((id, fig));
        }
    }
    Ok(out)
}
