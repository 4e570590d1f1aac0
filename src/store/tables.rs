//! Table schemas and row buffers: typed columns, one builder per table.

use std::sync::Arc;

use arrow_array::builder::{
    BooleanBuilder, Float64Builder, Int64Builder, StringBuilder, UInt32Builder, UInt64Builder,
};
use arrow_array::{ArrayRef, RecordBatch};
use arrow_schema::{DataType, Field, Schema};
use serde_json::Value;

use crate::dsmc::{SpeciesRow, TamsdRow};
use crate::plan::{canonical, Plan};

pub const RUNS: &str = "runs";
pub const POINTS: &str = "points";
pub const DSMC_SPECIES: &str = "dsmc_species";
pub const DSMC_SPECIES_SUMMARY: &str = "dsmc_species_summary";
pub const DSMC_TAMSD: &str = "dsmc_tamsd";
pub const DSMC_TAMSD_SUMMARY: &str = "dsmc_tamsd_summary";

/// How a swept parameter is stored: as a typed column, never as a string of a number.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SweepKind {
    Int,
    Float,
    Bool,
    Str,
    /// Objects, arrays or mixed types: canonical JSON text.
    Json,
}

#[derive(Clone, Debug)]
pub struct SweepColumn {
    pub name: String,
    pub kind: SweepKind,
}

/// The typed sweep columns of a plan.
pub fn sweep_columns(plan: &Plan) -> Vec<SweepColumn> {
    plan.sweep_keys
        .iter()
        .enumerate()
        .map(|(j, key)| {
            let vals: Vec<&Value> = plan.points.iter().map(|p| &p.values[j]).collect();
            let kind = if vals.iter().all(|v| v.is_i64() || v.is_u64()) {
                SweepKind::Int
            } else if vals.iter().all(|v| v.is_number()) {
                SweepKind::Float
            } else if vals.iter().all(|v| v.is_boolean()) {
                SweepKind::Bool
            } else if vals.iter().all(|v| v.is_string()) {
                SweepKind::Str
            } else {
                SweepKind::Json
            };
            SweepColumn {
                name: Plan::sweep_column(key),
                kind,
            }
        })
        .collect()
}

fn sweep_fields(cols: &[SweepColumn]) -> Vec<Field> {
    cols.iter()
        .map(|c| {
            let dt = match c.kind {
                SweepKind::Int => DataType::Int64,
                SweepKind::Float => DataType::Float64,
                SweepKind::Bool => DataType::Boolean,
                SweepKind::Str | SweepKind::Json => DataType::Utf8,
            };
            Field::new(&c.name, dt, false)
        })
        .collect()
}

fn sweep_arrays(cols: &[SweepColumn], values: &[&[Value]]) -> Vec<ArrayRef> {
    cols.iter()
        .enumerate()
        .map(|(j, c)| -> ArrayRef {
            match c.kind {
                SweepKind::Int => {
                    let mut b = Int64Builder::new();
                    values.iter().for_each(|v| {
                        b.append_value(v[j].as_i64().unwrap_or(v[j].as_u64().unwrap_or(0) as i64))
                    });
                    Arc::new(b.finish())
                }
                SweepKind::Float => {
                    let mut b = Float64Builder::new();
                    values
                        .iter()
                        .for_each(|v| b.append_value(v[j].as_f64().unwrap_or(f64::NAN)));
                    Arc::new(b.finish())
                }
                SweepKind::Bool => {
                    let mut b = BooleanBuilder::new();
                    values
                        .iter()
                        .for_each(|v| b.append_value(v[j].as_bool().unwrap_or(false)));
                    Arc::new(b.finish())
                }
                SweepKind::Str => {
                    let mut b = StringBuilder::new();
                    values
                        .iter()
                        .for_each(|v| b.append_value(v[j].as_str().unwrap_or("")));
                    Arc::new(b.finish())
                }
                SweepKind::Json => {
                    let mut b = StringBuilder::new();
                    values.iter().for_each(|v| b.append_value(canonical(&v[j])));
                    Arc::new(b.finish())
                }
            }
        })
        .collect()
}

/// One row of the `runs` table.
#[derive(Clone, Debug, PartialEq)]
pub struct RunRow {
    pub run_id: u64,
    pub point_id: u32,
    pub replica: u32,
    pub seed: u64,
    /// "done" or "failed".
    pub status: String,
    pub reason: Option<String>,
    /// Simulated time at which a failed run stopped.
    pub t_failed: Option<f64>,
    pub wall_seconds: f64,
    pub collisions: u64,
    pub trials: u64,
}

pub fn runs_batch(plan: &Plan, cols: &[SweepColumn], rows: &[RunRow]) -> RecordBatch {
    let mut fields = vec![
        Field::new("run_id", DataType::UInt64, false),
        Field::new("point_id", DataType::UInt32, false),
        Field::new("replica", DataType::UInt32, false),
        Field::new("seed", DataType::UInt64, false),
    ];
    fields.extend(sweep_fields(cols));
    fields.extend([
        Field::new("status", DataType::Utf8, false),
        Field::new("reason", DataType::Utf8, true),
        Field::new("t_failed", DataType::Float64, true),
        Field::new("wall_seconds", DataType::Float64, false),
        Field::new("collisions", DataType::UInt64, false),
        Field::new("trials", DataType::UInt64, false),
        Field::new("code_version", DataType::Utf8, false),
    ]);
    let mut arrays: Vec<ArrayRef> = vec![
        Arc::new(
            rows.iter()
                .map(|r| r.run_id)
                .collect::<arrow_array::UInt64Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.point_id)
                .collect::<arrow_array::UInt32Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.replica)
                .collect::<arrow_array::UInt32Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.seed)
                .collect::<arrow_array::UInt64Array>(),
        ),
    ];
    let values: Vec<&[Value]> = rows
        .iter()
        .map(|r| plan.point(r.point_id).values.as_slice())
        .collect();
    arrays.extend(sweep_arrays(cols, &values));
    arrays.extend::<[ArrayRef; 7]>([
        Arc::new(
            rows.iter()
                .map(|r| Some(r.status.as_str()))
                .collect::<arrow_array::StringArray>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.reason.as_deref())
                .collect::<arrow_array::StringArray>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.t_failed)
                .collect::<arrow_array::Float64Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.wall_seconds)
                .collect::<arrow_array::Float64Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.collisions)
                .collect::<arrow_array::UInt64Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.trials)
                .collect::<arrow_array::UInt64Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|_| Some(crate::CODE_VERSION))
                .collect::<arrow_array::StringArray>(),
        ),
    ]);
    RecordBatch::try_new(Arc::new(Schema::new(fields)), arrays)
        .expect("runs batch matches its schema")
}

/// The `points` table: one row per sweep point with its swept values and full params.
pub fn points_batch(plan: &Plan, cols: &[SweepColumn], params_json: &[String]) -> RecordBatch {
    let mut fields = vec![Field::new("point_id", DataType::UInt32, false)];
    fields.extend(sweep_fields(cols));
    fields.push(Field::new("params", DataType::Utf8, false));
    let mut arrays: Vec<ArrayRef> = vec![Arc::new(
        plan.points
            .iter()
            .map(|p| p.point_id)
            .collect::<arrow_array::UInt32Array>(),
    )];
    let values: Vec<&[Value]> = plan.points.iter().map(|p| p.values.as_slice()).collect();
    arrays.extend(sweep_arrays(cols, &values));
    arrays.push(Arc::new(
        params_json
            .iter()
            .map(|s| Some(s.as_str()))
            .collect::<arrow_array::StringArray>(),
    ));
    RecordBatch::try_new(Arc::new(Schema::new(fields)), arrays)
        .expect("points batch matches its schema")
}

/// Buffered `dsmc_species` rows.
#[derive(Default)]
pub struct SpeciesBuffer {
    run_id: UInt64Builder,
    point_id: UInt32Builder,
    t: Float64Builder,
    species: UInt32Builder,
    mass: Float64Builder,
    diameter: Float64Builder,
    count: UInt64Builder,
    temperature: Float64Builder,
    msd: Float64Builder,
    collisions: UInt64Builder,
    pub rows: usize,
}

impl SpeciesBuffer {
    pub fn push(&mut self, run_id: u64, point_id: u32, rows: &[SpeciesRow]) {
        for r in rows {
            self.run_id.append_value(run_id);
            self.point_id.append_value(point_id);
            self.t.append_value(r.t);
            self.species.append_value(r.species);
            self.mass.append_value(r.mass);
            self.diameter.append_value(r.diameter);
            self.count.append_value(r.count);
            self.temperature.append_value(r.temperature);
            self.msd.append_option(r.msd);
            self.collisions.append_value(r.collisions);
        }
        self.rows += rows.len();
    }

    pub fn schema() -> Schema {
        Schema::new(vec![
            Field::new("run_id", DataType::UInt64, false),
            Field::new("point_id", DataType::UInt32, false),
            Field::new("t", DataType::Float64, false),
            Field::new("species", DataType::UInt32, false),
            Field::new("mass", DataType::Float64, false),
            Field::new("diameter", DataType::Float64, false),
            Field::new("count", DataType::UInt64, false),
            Field::new("temperature", DataType::Float64, false),
            Field::new("msd", DataType::Float64, true),
            Field::new("collisions", DataType::UInt64, false),
        ])
    }

    pub fn finish(&mut self) -> RecordBatch {
        self.rows = 0;
        let arrays: Vec<ArrayRef> = vec![
            Arc::new(self.run_id.finish()),
            Arc::new(self.point_id.finish()),
            Arc::new(self.t.finish()),
            Arc::new(self.species.finish()),
            Arc::new(self.mass.finish()),
            Arc::new(self.diameter.finish()),
            Arc::new(self.count.finish()),
            Arc::new(self.temperature.finish()),
            Arc::new(self.msd.finish()),
            Arc::new(self.collisions.finish()),
        ];
        RecordBatch::try_new(Arc::new(Self::schema()), arrays)
            .expect("species batch matches its schema")
    }
}

/// Buffered `dsmc_tamsd` rows.
#[derive(Default)]
pub struct TamsdBuffer {
    run_id: UInt64Builder,
    point_id: UInt32Builder,
    species: UInt32Builder,
    lag: Float64Builder,
    tamsd: Float64Builder,
    t_total: Float64Builder,
    pub rows: usize,
}

impl TamsdBuffer {
    pub fn push(&mut self, run_id: u64, point_id: u32, rows: &[TamsdRow]) {
        for r in rows {
            self.run_id.append_value(run_id);
            self.point_id.append_value(point_id);
            self.species.append_value(r.species);
            self.lag.append_value(r.lag);
            self.tamsd.append_value(r.tamsd);
            self.t_total.append_value(r.t_total);
        }
        self.rows += rows.len();
    }

    pub fn schema() -> Schema {
        Schema::new(vec![
            Field::new("run_id", DataType::UInt64, false),
            Field::new("point_id", DataType::UInt32, false),
            Field::new("species", DataType::UInt32, false),
            Field::new("lag", DataType::Float64, false),
            Field::new("tamsd", DataType::Float64, false),
            Field::new("t_total", DataType::Float64, false),
        ])
    }

    pub fn finish(&mut self) -> RecordBatch {
        self.rows = 0;
        let arrays: Vec<ArrayRef> = vec![
            Arc::new(self.run_id.finish()),
            Arc::new(self.point_id.finish()),
            Arc::new(self.species.finish()),
            Arc::new(self.lag.finish()),
            Arc::new(self.tamsd.finish()),
            Arc::new(self.t_total.finish()),
        ];
        RecordBatch::try_new(Arc::new(Self::schema()), arrays)
            .expect("tamsd batch matches its schema")
    }
}

pub const DSMC_THEORY: &str = "dsmc_theory";
pub const DSMC_THEORY_TAMSD: &str = "dsmc_theory_tamsd";
pub const DSMC_THEORY_POINT: &str = "dsmc_theory_point";

/// `dsmc_theory`: the kinetic-theory prediction per point, time and species.
pub fn theory_batch(rows: &[(u32, crate::dsmc::predict::TheoryRow)]) -> RecordBatch {
    let schema = Schema::new(vec![
        Field::new("point_id", DataType::UInt32, false),
        Field::new("t", DataType::Float64, false),
        Field::new("species", DataType::UInt32, false),
        Field::new("temperature", DataType::Float64, false),
        Field::new("msd", DataType::Float64, true),
        Field::new("tau_v", DataType::Float64, false),
    ]);
    let arrays: Vec<ArrayRef> = vec![
        Arc::new(
            rows.iter()
                .map(|r| r.0)
                .collect::<arrow_array::UInt32Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.1.t)
                .collect::<arrow_array::Float64Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.1.species)
                .collect::<arrow_array::UInt32Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.1.temperature)
                .collect::<arrow_array::Float64Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.1.msd)
                .collect::<arrow_array::Float64Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.1.tau_v)
                .collect::<arrow_array::Float64Array>(),
        ),
    ];
    RecordBatch::try_new(Arc::new(schema), arrays).expect("theory batch matches its schema")
}

/// `dsmc_theory_tamsd`: the TAMSD (27) per point, species and lag (measured over [0, t_end]).
pub fn theory_tamsd_batch(rows: &[(u32, crate::dsmc::predict::TamsdTheoryRow)]) -> RecordBatch {
    let schema = Schema::new(vec![
        Field::new("point_id", DataType::UInt32, false),
        Field::new("species", DataType::UInt32, false),
        Field::new("lag", DataType::Float64, false),
        Field::new("tamsd", DataType::Float64, false),
    ]);
    let arrays: Vec<ArrayRef> = vec![
        Arc::new(
            rows.iter()
                .map(|r| r.0)
                .collect::<arrow_array::UInt32Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.1.species)
                .collect::<arrow_array::UInt32Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.1.lag)
                .collect::<arrow_array::Float64Array>(),
        ),
        Arc::new(
            rows.iter()
                .map(|r| r.1.tamsd)
                .collect::<arrow_array::Float64Array>(),
        ),
    ];
    RecordBatch::try_new(Arc::new(schema), arrays).expect("theory tamsd batch matches its schema")
}

/// `dsmc_theory_point`: per point, tau_0 (21) and the initial temperatures actually used.
pub fn theory_point_batch(points: &[(u32, f64, Vec<f64>)]) -> RecordBatch {
    use arrow_array::builder::ListBuilder;
    let mut temps = ListBuilder::new(Float64Builder::new());
    for (_, _, t) in points {
        temps.values().append_slice(t);
        temps.append(true);
    }
    let temps = temps.finish();
    let schema = Schema::new(vec![
        Field::new("point_id", DataType::UInt32, false),
        Field::new("tau_0", DataType::Float64, false),
        Field::new(
            "initial_temperatures",
            arrow_array::Array::data_type(&temps).clone(),
            false,
        ),
    ]);
    let arrays: Vec<ArrayRef> = vec![
        Arc::new(
            points
                .iter()
                .map(|p| p.0)
                .collect::<arrow_array::UInt32Array>(),
        ),
        Arc::new(
            points
                .iter()
                .map(|p| p.1)
                .collect::<arrow_array::Float64Array>(),
        ),
        Arc::new(temps),
    ];
    RecordBatch::try_new(Arc::new(schema), arrays).expect("theory point batch matches its schema")
}

pub const RFM_TIMESERIES: &str = "rfm_timeseries";
pub const RFM_MOMENTS: &str = "rfm_moments";
pub const RFM_HISTOGRAMS: &str = "rfm_histograms";
pub const RFM_TIMESERIES_SUMMARY: &str = "rfm_timeseries_summary";
pub const RFM_MOMENTS_SUMMARY: &str = "rfm_moments_summary";
pub const RFM_HISTOGRAMS_SUMMARY: &str = "rfm_histograms_summary";
pub const RFM_NEIGHBOUR_MOMENTS: &str = "rfm_neighbour_moments";
pub const RFM_NEIGHBOUR_MOMENTS_SUMMARY: &str = "rfm_neighbour_moments_summary";
pub const RFM_STRUCTURE_FACTOR: &str = "rfm_structure_factor";
pub const RFM_STRUCTURE_FACTOR_SUMMARY: &str = "rfm_structure_factor_summary";
pub const RFM_RADIAL: &str = "rfm_radial_distribution";
pub const RFM_RADIAL_SUMMARY: &str = "rfm_radial_distribution_summary";
pub const RFM_TEMPERATURE_BLOCKS: &str = "rfm_temperature_blocks";
pub const RFM_SNAPSHOTS: &str = "rfm_snapshots";
pub const RFM_FREE_PATH_MOMENTS: &str = "rfm_free_path_moments";
pub const RFM_FREE_PATH_MOMENTS_SUMMARY: &str = "rfm_free_path_moments_summary";

/// Buffered rows of the RFM tables.
#[derive(Default)]
pub struct RfmBuffer {
    pub series: Vec<(u64, u32, crate::rfm::observe::TimeRow)>,
    pub moments: Vec<(u64, u32, crate::rfm::observe::MomentRow)>,
    pub hist: Vec<(u64, u32, crate::rfm::observe::HistRow)>,
    pub neighbour_moments: Vec<(u64, u32, crate::rfm::structure::NeighbourMomentRow)>,
    pub sk: Vec<(u64, u32, crate::rfm::structure::SkRow)>,
    pub radial: Vec<(u64, u32, crate::rfm::structure::RadialRow)>,
    pub tblocks: Vec<(u64, u32, crate::rfm::observe::TemperatureBlockRow)>,
    pub snaps: Vec<(u64, u32, crate::rfm::observe::SnapshotRow)>,
    pub free_path_moments: Vec<(u64, u32, crate::rfm::freepath::FreePathMomentRow)>,
}

fn f64_col<T>(v: &[T], f: impl Fn(&T) -> f64) -> ArrayRef {
    Arc::new(v.iter().map(f).collect::<arrow_array::Float64Array>())
}
fn opt_f64_col<T>(v: &[T], f: impl Fn(&T) -> Option<f64>) -> ArrayRef {
    Arc::new(v.iter().map(f).collect::<arrow_array::Float64Array>())
}
fn u32_col<T>(v: &[T], f: impl Fn(&T) -> u32) -> ArrayRef {
    Arc::new(v.iter().map(f).collect::<arrow_array::UInt32Array>())
}
fn u64_col<T>(v: &[T], f: impl Fn(&T) -> u64) -> ArrayRef {
    Arc::new(v.iter().map(f).collect::<arrow_array::UInt64Array>())
}

impl RfmBuffer {
    pub fn push(&mut self, run_id: u64, point_id: u32, out: &crate::rfm::observe::RfmOutput) {
        self.series
            .extend(out.timeseries.iter().map(|r| (run_id, point_id, r.clone())));
        self.moments
            .extend(out.moments.iter().map(|r| (run_id, point_id, r.clone())));
        self.hist
            .extend(out.histograms.iter().map(|r| (run_id, point_id, r.clone())));
        self.neighbour_moments.extend(
            out.neighbour_moments
                .iter()
                .map(|r| (run_id, point_id, r.clone())),
        );
        self.sk.extend(
            out.structure_factor
                .iter()
                .map(|r| (run_id, point_id, r.clone())),
        );
        self.radial
            .extend(out.radial.iter().map(|r| (run_id, point_id, r.clone())));
        self.tblocks.extend(
            out.temperature_blocks
                .iter()
                .map(|r| (run_id, point_id, r.clone())),
        );
        self.snaps
            .extend(out.snapshots.iter().map(|r| (run_id, point_id, r.clone())));
        self.free_path_moments.extend(
            out.free_path_moments
                .iter()
                .map(|r| (run_id, point_id, r.clone())),
        );
    }

    pub fn rows(&self) -> usize {
        self.series.len()
            + self.moments.len()
            + self.hist.len()
            + self.neighbour_moments.len()
            + self.sk.len()
            + self.radial.len()
            + self.tblocks.len()
            + self.snaps.len()
            + self.free_path_moments.len()
    }

    /// The non-empty tables as (name, batch); empties the buffer.
    pub fn finish(&mut self) -> Vec<(&'static str, RecordBatch)> {
        let mut out = Vec::new();
        let ids = |v: &[(u64, u32)]| -> Vec<ArrayRef> {
            vec![
                Arc::new(v.iter().map(|r| r.0).collect::<arrow_array::UInt64Array>()),
                Arc::new(v.iter().map(|r| r.1).collect::<arrow_array::UInt32Array>()),
            ]
        };
        let id_fields = || {
            vec![
                Field::new("run_id", DataType::UInt64, false),
                Field::new("point_id", DataType::UInt32, false),
            ]
        };
        if !self.series.is_empty() {
            let mut f = id_fields();
            f.extend([
                Field::new("t", DataType::Float64, false),
                Field::new("temperature", DataType::Float64, false),
            ]);
            let mut a = ids(&self.series.iter().map(|r| (r.0, r.1)).collect::<Vec<_>>());
            a.push(Arc::new(
                self.series
                    .iter()
                    .map(|r| r.2.t)
                    .collect::<arrow_array::Float64Array>(),
            ));
            a.push(Arc::new(
                self.series
                    .iter()
                    .map(|r| r.2.temperature)
                    .collect::<arrow_array::Float64Array>(),
            ));
            out.push((
                RFM_TIMESERIES,
                RecordBatch::try_new(Arc::new(Schema::new(f)), a).expect("timeseries batch"),
            ));
        }
        if !self.moments.is_empty() {
            let mut f = id_fields();
            f.extend([
                Field::new("order", DataType::UInt32, false),
                Field::new("value", DataType::Float64, false),
                Field::new("sem", DataType::Float64, true),
            ]);
            let mut a = ids(&self.moments.iter().map(|r| (r.0, r.1)).collect::<Vec<_>>());
            a.push(Arc::new(
                self.moments
                    .iter()
                    .map(|r| r.2.order)
                    .collect::<arrow_array::UInt32Array>(),
            ));
            a.push(Arc::new(
                self.moments
                    .iter()
                    .map(|r| r.2.value)
                    .collect::<arrow_array::Float64Array>(),
            ));
            a.push(Arc::new(
                self.moments
                    .iter()
                    .map(|r| r.2.sem)
                    .collect::<arrow_array::Float64Array>(),
            ));
            out.push((
                RFM_MOMENTS,
                RecordBatch::try_new(Arc::new(Schema::new(f)), a).expect("moments batch"),
            ));
        }
        if !self.hist.is_empty() {
            let mut f = id_fields();
            f.extend([
                Field::new("kind", DataType::Utf8, false),
                Field::new("h", DataType::UInt32, false),
                Field::new("lo", DataType::Float64, false),
                Field::new("hi", DataType::Float64, false),
                Field::new("count", DataType::UInt64, false),
                Field::new("density", DataType::Float64, true),
            ]);
            let mut a = ids(&self.hist.iter().map(|r| (r.0, r.1)).collect::<Vec<_>>());
            a.push(Arc::new(
                self.hist
                    .iter()
                    .map(|r| Some(r.2.kind.as_str()))
                    .collect::<arrow_array::StringArray>(),
            ));
            a.push(Arc::new(
                self.hist
                    .iter()
                    .map(|r| r.2.h)
                    .collect::<arrow_array::UInt32Array>(),
            ));
            a.push(Arc::new(
                self.hist
                    .iter()
                    .map(|r| r.2.lo)
                    .collect::<arrow_array::Float64Array>(),
            ));
            a.push(Arc::new(
                self.hist
                    .iter()
                    .map(|r| r.2.hi)
                    .collect::<arrow_array::Float64Array>(),
            ));
            a.push(Arc::new(
                self.hist
                    .iter()
                    .map(|r| r.2.count)
                    .collect::<arrow_array::UInt64Array>(),
            ));
            a.push(Arc::new(
                self.hist
                    .iter()
                    .map(|r| r.2.density)
                    .collect::<arrow_array::Float64Array>(),
            ));
            out.push((
                RFM_HISTOGRAMS,
                RecordBatch::try_new(Arc::new(Schema::new(f)), a).expect("histogram batch"),
            ));
        }
        if !self.neighbour_moments.is_empty() {
            let v = &self.neighbour_moments;
            let mut f = id_fields();
            f.extend([
                Field::new("h", DataType::UInt32, false),
                Field::new("order", DataType::UInt32, false),
                Field::new("value", DataType::Float64, false),
                Field::new("sem", DataType::Float64, true),
            ]);
            let mut a = ids(&v.iter().map(|r| (r.0, r.1)).collect::<Vec<_>>());
            a.push(u32_col(v, |r| r.2.h));
            a.push(u32_col(v, |r| r.2.order));
            a.push(f64_col(v, |r| r.2.value));
            a.push(opt_f64_col(v, |r| r.2.sem));
            out.push((
                RFM_NEIGHBOUR_MOMENTS,
                RecordBatch::try_new(Arc::new(Schema::new(f)), a).expect("neighbour moments"),
            ));
        }
        if !self.sk.is_empty() {
            let v = &self.sk;
            let mut f = id_fields();
            f.extend([
                Field::new("n2", DataType::UInt64, false),
                Field::new("k", DataType::Float64, false),
                Field::new("n_vectors", DataType::UInt64, false),
                Field::new("s", DataType::Float64, false),
                Field::new("sem", DataType::Float64, true),
            ]);
            let mut a = ids(&v.iter().map(|r| (r.0, r.1)).collect::<Vec<_>>());
            a.push(u64_col(v, |r| r.2.n2));
            a.push(f64_col(v, |r| r.2.k));
            a.push(u64_col(v, |r| r.2.n_vectors));
            a.push(f64_col(v, |r| r.2.s));
            a.push(opt_f64_col(v, |r| r.2.sem));
            out.push((
                RFM_STRUCTURE_FACTOR,
                RecordBatch::try_new(Arc::new(Schema::new(f)), a).expect("structure factor"),
            ));
        }
        if !self.radial.is_empty() {
            let v = &self.radial;
            let mut f = id_fields();
            f.extend([
                Field::new("r_lo", DataType::Float64, false),
                Field::new("r_hi", DataType::Float64, false),
                Field::new("count", DataType::UInt64, false),
                Field::new("g", DataType::Float64, false),
                Field::new("g_sem", DataType::Float64, true),
                Field::new("c", DataType::Float64, false),
            ]);
            let mut a = ids(&v.iter().map(|r| (r.0, r.1)).collect::<Vec<_>>());
            a.push(f64_col(v, |r| r.2.r_lo));
            a.push(f64_col(v, |r| r.2.r_hi));
            a.push(u64_col(v, |r| r.2.count));
            a.push(f64_col(v, |r| r.2.g));
            a.push(opt_f64_col(v, |r| r.2.g_sem));
            a.push(f64_col(v, |r| r.2.c));
            out.push((
                RFM_RADIAL,
                RecordBatch::try_new(Arc::new(Schema::new(f)), a).expect("radial distribution"),
            ));
        }
        if !self.tblocks.is_empty() {
            let v = &self.tblocks;
            let mut f = id_fields();
            f.extend([
                Field::new("block", DataType::UInt32, false),
                Field::new("t_from", DataType::Float64, false),
                Field::new("t_to", DataType::Float64, false),
                Field::new("n_samples", DataType::UInt32, false),
                Field::new("temperature", DataType::Float64, false),
            ]);
            let mut a = ids(&v.iter().map(|r| (r.0, r.1)).collect::<Vec<_>>());
            a.push(u32_col(v, |r| r.2.block));
            a.push(f64_col(v, |r| r.2.t_from));
            a.push(f64_col(v, |r| r.2.t_to));
            a.push(u32_col(v, |r| r.2.n_samples));
            a.push(f64_col(v, |r| r.2.temperature));
            out.push((
                RFM_TEMPERATURE_BLOCKS,
                RecordBatch::try_new(Arc::new(Schema::new(f)), a).expect("temperature blocks"),
            ));
        }
        if !self.snaps.is_empty() {
            let v = &self.snaps;
            let mut f = id_fields();
            f.extend([
                Field::new("t", DataType::Float64, false),
                Field::new("particle", DataType::UInt32, false),
                Field::new("x", DataType::Float64, false),
                Field::new("y", DataType::Float64, true),
                Field::new("vx", DataType::Float64, false),
                Field::new("vy", DataType::Float64, true),
            ]);
            let mut a = ids(&v.iter().map(|r| (r.0, r.1)).collect::<Vec<_>>());
            a.push(f64_col(v, |r| r.2.t));
            a.push(u32_col(v, |r| r.2.particle));
            a.push(f64_col(v, |r| r.2.x));
            a.push(opt_f64_col(v, |r| r.2.y));
            a.push(f64_col(v, |r| r.2.vx));
            a.push(opt_f64_col(v, |r| r.2.vy));
            out.push((
                RFM_SNAPSHOTS,
                RecordBatch::try_new(Arc::new(Schema::new(f)), a).expect("snapshots"),
            ));
        }
        if !self.free_path_moments.is_empty() {
            let v = &self.free_path_moments;
            let mut f = id_fields();
            f.extend([
                Field::new("order", DataType::UInt32, false),
                Field::new("value", DataType::Float64, false),
                Field::new("sem", DataType::Float64, true),
                Field::new("n_paths", DataType::UInt64, false),
            ]);
            let mut a = ids(&v.iter().map(|r| (r.0, r.1)).collect::<Vec<_>>());
            a.push(u32_col(v, |r| r.2.order));
            a.push(f64_col(v, |r| r.2.value));
            a.push(opt_f64_col(v, |r| r.2.sem));
            a.push(u64_col(v, |r| r.2.n_paths));
            out.push((
                RFM_FREE_PATH_MOMENTS,
                RecordBatch::try_new(Arc::new(Schema::new(f)), a).expect("free-path moments"),
            ));
        }
        self.free_path_moments.clear();
        self.series.clear();
        self.moments.clear();
        self.hist.clear();
        self.neighbour_moments.clear();
        self.sk.clear();
        self.radial.clear();
        self.tblocks.clear();
        self.snaps.clear();
        out
    }
}

/// Column builders: one Arrow array from a field of every row (`cols::f64s(&rows, |r| r.t)`).
pub(crate) mod cols {
    use std::sync::Arc;

    use arrow_array::ArrayRef;

    pub(crate) fn f64s<T>(v: &[T], f: impl Fn(&T) -> f64) -> ArrayRef {
        Arc::new(v.iter().map(f).collect::<arrow_array::Float64Array>())
    }
    pub(crate) fn opt_f64s<T>(v: &[T], f: impl Fn(&T) -> Option<f64>) -> ArrayRef {
        Arc::new(v.iter().map(f).collect::<arrow_array::Float64Array>())
    }
    pub(crate) fn u32s<T>(v: &[T], f: impl Fn(&T) -> u32) -> ArrayRef {
        Arc::new(v.iter().map(f).collect::<arrow_array::UInt32Array>())
    }
    pub(crate) fn u64s<T>(v: &[T], f: impl Fn(&T) -> u64) -> ArrayRef {
        Arc::new(v.iter().map(f).collect::<arrow_array::UInt64Array>())
    }
    pub(crate) fn opt_u64s<T>(v: &[T], f: impl Fn(&T) -> Option<u64>) -> ArrayRef {
        Arc::new(v.iter().map(f).collect::<arrow_array::UInt64Array>())
    }
    pub(crate) fn strs<T>(v: &[T], f: impl Fn(&T) -> &str) -> ArrayRef {
        Arc::new(
            v.iter()
                .map(|r| Some(f(r)))
                .collect::<arrow_array::StringArray>(),
        )
    }
}
