//! Shared helpers: the binary, the heavy-test lock, child processes with timeouts, and
//! reading whole Parquet tables into comparable rows.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant, SystemTime};

use arrow_array::cast::AsArray;
use arrow_array::types::{Float64Type, Int32Type, Int64Type, UInt32Type, UInt64Type};
use arrow_array::{Array, ArrayRef, RecordBatchReader};
use arrow_schema::DataType;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use serde_json::Value;

/// The `granular` binary built for this test run.
pub fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_granular")
}

/// The repository root (schemas/, jobs/, tests/manifests/).
pub fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

static HEAVY: Mutex<()> = Mutex::new(());

/// Serialises the CPU-heavy tests (the test harness runs tests on parallel threads).
/// Never call a function that takes this lock while holding it.
pub fn heavy() -> MutexGuard<'static, ()> {
    HEAVY.lock().unwrap_or_else(|e| e.into_inner())
}

/// A `granular` command with its output appended to `log` (kept for failure messages).
pub fn granular(args: &[&str], log: &Path) -> Command {
    let mut c = Command::new(bin());
    c.args(args).stdin(Stdio::null());
    let f = fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(log)
        .expect("open log");
    c.stdout(f.try_clone().expect("dup log")).stderr(f);
    c
}

pub fn log_text(log: &Path) -> String {
    fs::read_to_string(log).unwrap_or_default()
}

/// Wait for a child, killing it (and failing) after `limit`.
pub fn wait_limited(child: &mut Child, limit: Duration, what: &str, log: &Path) -> ExitStatus {
    let start = Instant::now();
    loop {
        if let Some(s) = child.try_wait().expect("try_wait") {
            return s;
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "{what}: still running after {limit:?}; killed it. Log:\n{}",
                log_text(log)
            );
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Run `granular args` to the end (at most `limit`), returning its exit code (None if killed
/// by a signal).
pub fn run_granular(args: &[&str], log: &Path, limit: Duration) -> Option<i32> {
    let mut child = granular(args, log).spawn().expect("spawn granular");
    wait_limited(
        &mut child,
        limit,
        &format!("granular {}", args.join(" ")),
        log,
    )
    .code()
}

/// Run `granular args` capturing stdout (stderr goes to `log`); returns (code, stdout).
pub fn run_capture(args: &[&str], log: &Path) -> (Option<i32>, String) {
    let f = fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(log)
        .expect("open log");
    let out = Command::new(bin())
        .args(args)
        .stdin(Stdio::null())
        .stderr(f)
        .output()
        .expect("run granular");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
    )
}

/// A fixed-seed 64-bit LCG (Knuth's MMIX constants): reproducible "random" moments.
pub struct Lcg(pub u64);

impl Lcg {
    /// Uniform in [0, 1) from the top 53 bits.
    pub fn next_f64(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Every file under `dir` with its bytes and modification time.
pub fn snapshot(dir: &Path) -> BTreeMap<PathBuf, (Vec<u8>, SystemTime)> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in fs::read_dir(&d).expect("read_dir") {
            let p = e.expect("entry").path();
            let md = fs::symlink_metadata(&p).expect("metadata");
            if md.is_dir() {
                out.insert(p.clone(), (Vec::new(), md.modified().expect("mtime")));
                stack.push(p);
            } else if md.file_type().is_symlink() {
                // A table's link to its current generation: its target is its content.
                let target = fs::read_link(&p).expect("read_link");
                out.insert(
                    p.clone(),
                    (
                        target.to_string_lossy().as_bytes().to_vec(),
                        md.modified().expect("mtime"),
                    ),
                );
            } else {
                out.insert(
                    p.clone(),
                    (fs::read(&p).expect("read"), md.modified().expect("mtime")),
                );
            }
        }
    }
    out
}

/// One value of a table, comparable bit for bit (floats by their bits).
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Cell {
    Null,
    Bool(bool),
    U(u64),
    I(i64),
    F(u64),
    S(String),
}

impl fmt::Display for Cell {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Cell::Null => write!(f, "null"),
            Cell::Bool(b) => write!(f, "{b}"),
            Cell::U(v) => write!(f, "{v}"),
            Cell::I(v) => write!(f, "{v}"),
            Cell::F(bits) => write!(f, "{:e} (bits {bits:#018x})", f64::from_bits(*bits)),
            Cell::S(s) => write!(f, "{s:?}"),
        }
    }
}

impl Cell {
    pub fn as_u64(&self) -> u64 {
        match self {
            Cell::U(v) => *v,
            other => panic!("expected an unsigned integer, got {other}"),
        }
    }
    pub fn as_str(&self) -> &str {
        match self {
            Cell::S(s) => s,
            other => panic!("expected a string, got {other}"),
        }
    }
}

fn cells(col: &ArrayRef) -> Vec<Cell> {
    let n = col.len();
    let cell = |i: usize, f: &dyn Fn(usize) -> Cell| if col.is_null(i) { Cell::Null } else { f(i) };
    match col.data_type() {
        DataType::UInt32 => {
            let a = col.as_primitive::<UInt32Type>();
            (0..n)
                .map(|i| cell(i, &|i| Cell::U(a.value(i) as u64)))
                .collect()
        }
        DataType::UInt64 => {
            let a = col.as_primitive::<UInt64Type>();
            (0..n).map(|i| cell(i, &|i| Cell::U(a.value(i)))).collect()
        }
        DataType::Int32 => {
            let a = col.as_primitive::<Int32Type>();
            (0..n)
                .map(|i| cell(i, &|i| Cell::I(a.value(i) as i64)))
                .collect()
        }
        DataType::Int64 => {
            let a = col.as_primitive::<Int64Type>();
            (0..n).map(|i| cell(i, &|i| Cell::I(a.value(i)))).collect()
        }
        DataType::Float64 => {
            let a = col.as_primitive::<Float64Type>();
            (0..n)
                .map(|i| cell(i, &|i| Cell::F(a.value(i).to_bits())))
                .collect()
        }
        DataType::Utf8 => {
            let a = col.as_string::<i32>();
            (0..n)
                .map(|i| cell(i, &|i| Cell::S(a.value(i).to_string())))
                .collect()
        }
        DataType::Boolean => {
            let a = col.as_boolean();
            (0..n)
                .map(|i| cell(i, &|i| Cell::Bool(a.value(i))))
                .collect()
        }
        DataType::List(_) => {
            // A list of doubles: compared through the bit patterns of its elements.
            let a = col.as_list::<i32>();
            (0..n)
                .map(|i| {
                    cell(i, &|i| {
                        let v = a.value(i);
                        let bits: Vec<u64> = v
                            .as_primitive::<Float64Type>()
                            .values()
                            .iter()
                            .map(|x| x.to_bits())
                            .collect();
                        Cell::S(format!("{bits:?}"))
                    })
                })
                .collect()
        }
        other => panic!("column type {other} not handled by the test helper"),
    }
}

/// A whole table: every visible part file concatenated.
#[derive(Clone, Debug)]
pub struct Table {
    pub name: String,
    pub columns: Vec<(String, DataType)>,
    pub rows: Vec<Vec<Cell>>,
    pub files: Vec<String>,
}

impl Table {
    pub fn col(&self, name: &str) -> usize {
        self.columns
            .iter()
            .position(|(c, _)| c == name)
            .unwrap_or_else(|| panic!("table {} has no column {name}", self.name))
    }

    /// The values of one column, in row order.
    pub fn column(&self, name: &str) -> Vec<&Cell> {
        let j = self.col(name);
        self.rows.iter().map(|r| &r[j]).collect()
    }

    /// Rows sorted by `keys`; an error names every duplicated key.
    pub fn sorted_by(&self, keys: &[&str]) -> Result<Vec<Vec<Cell>>, String> {
        let idx: Vec<usize> = keys.iter().map(|k| self.col(k)).collect();
        let key = |r: &Vec<Cell>| idx.iter().map(|&j| r[j].clone()).collect::<Vec<_>>();
        let mut rows = self.rows.clone();
        rows.sort_by_key(|r| key(r));
        let mut dups = Vec::new();
        for w in rows.windows(2) {
            if key(&w[0]) == key(&w[1]) {
                dups.push(
                    key(&w[0])
                        .iter()
                        .map(|c| c.to_string())
                        .collect::<Vec<_>>()
                        .join(", "),
                );
            }
        }
        if dups.is_empty() {
            Ok(rows)
        } else {
            dups.truncate(10);
            Err(format!(
                "table {}: duplicated keys ({}) = [{}]",
                self.name,
                keys.join(", "),
                dups.join("], [")
            ))
        }
    }
}

/// Read `<dir>/tables/<table>/*.parquet` (hidden files excluded) with the arrow reader.
/// A table without files is an error, except for the tables in [`MAY_BE_EMPTY`], which are
/// then read as no columns and no rows.
pub fn read_table(dir: &Path, table: &str) -> Table {
    let tdir = dir.join("tables").join(table);
    if !tdir.exists() && OPTIONAL.contains(&table) {
        return Table {
            name: table.to_string(),
            columns: Vec::new(),
            rows: Vec::new(),
            files: Vec::new(),
        };
    }
    let mut files: Vec<PathBuf> = fs::read_dir(&tdir)
        .unwrap_or_else(|e| panic!("{}: {e}", tdir.display()))
        .map(|e| e.expect("entry").path())
        .filter(|p| {
            let n = p.file_name().unwrap().to_string_lossy().into_owned();
            !n.starts_with('.') && n.ends_with(".parquet")
        })
        .collect();
    files.sort();
    assert!(
        !files.is_empty() || MAY_BE_EMPTY.contains(&table),
        "{}: no table files",
        tdir.display()
    );
    let mut t = Table {
        name: table.to_string(),
        columns: Vec::new(),
        rows: Vec::new(),
        files: Vec::new(),
    };
    for (fi, f) in files.iter().enumerate() {
        let file = fs::File::open(f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        let reader = ParquetRecordBatchReaderBuilder::try_new(file)
            .unwrap_or_else(|e| panic!("{}: not readable Parquet: {e}", f.display()))
            .build()
            .unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        let schema = reader.schema();
        let cols: Vec<(String, DataType)> = schema
            .fields()
            .iter()
            .map(|f| (f.name().clone(), f.data_type().clone()))
            .collect();
        if fi == 0 {
            t.columns = cols;
        } else {
            assert_eq!(
                t.columns,
                cols,
                "{}: columns differ from the table's first part file",
                f.display()
            );
        }
        for batch in reader {
            let batch = batch.unwrap_or_else(|e| panic!("{}: {e}", f.display()));
            let columns: Vec<Vec<Cell>> = batch.columns().iter().map(cells).collect();
            for i in 0..batch.num_rows() {
                t.rows.push(columns.iter().map(|c| c[i].clone()).collect());
            }
        }
        t.files
            .push(f.file_name().unwrap().to_string_lossy().into_owned());
    }
    t
}

/// The tables of a campaign and the key columns that identify a row.
pub const TABLES: [(&str, &[&str]); 12] = [
    ("runs", &["run_id"]),
    ("registered_runs", &["run_id"]),
    ("dsmc_species", &["run_id", "t", "species"]),
    ("dsmc_species_summary", &["point_id", "t", "species"]),
    ("dsmc_tamsd", &["run_id", "species", "lag"]),
    ("dsmc_tamsd_summary", &["point_id", "species", "lag"]),
    ("points", &["point_id"]),
    ("dsmc_theory", &["point_id", "t", "species"]),
    ("dsmc_theory_point", &["point_id"]),
    ("dsmc_theory_tamsd", &["point_id", "species", "lag"]),
    ("derived", &["run_id", "t"]),
    ("derived_summary", &["point_id", "t"]),
];

/// Tables that have no part file in a campaign that does not record them (`dsmc_tamsd`
/// without the observable `tamsd`).
pub const MAY_BE_EMPTY: [&str; 1] = ["dsmc_tamsd"];

/// Tables that exist only when their observable is recorded (absent = empty).
pub const OPTIONAL: [&str; 5] = [
    "dsmc_tamsd",
    "dsmc_tamsd_summary",
    "dsmc_theory_tamsd",
    "derived",
    "derived_summary",
];

pub type Tables = BTreeMap<String, Table>;

/// Every table of a finished campaign directory; fails if a table directory is unknown to
/// this test (so a new table cannot silently escape the comparisons).
pub fn read_tables(dir: &Path) -> Tables {
    let present: BTreeSet<String> = fs::read_dir(dir.join("tables"))
        .expect("tables dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .filter(|n| !n.starts_with('.'))
        .collect();
    let known: BTreeSet<String> = TABLES.iter().map(|(t, _)| t.to_string()).collect();
    let required: BTreeSet<String> = known
        .iter()
        .filter(|t| !OPTIONAL.contains(&t.as_str()))
        .cloned()
        .collect();
    assert!(
        present.is_subset(&known) && required.is_subset(&present),
        "{}: unexpected set of tables: {present:?}",
        dir.display()
    );
    TABLES
        .iter()
        .map(|(t, _)| (t.to_string(), read_table(dir, t)))
        .collect()
}

/// Columns excluded from bit-equality: `runs.wall_seconds` measures elapsed time (it differs
/// between any two executions, and includes the time of killed attempts), not results.
pub const NONDETERMINISTIC: [(&str, &str); 1] = [("runs", "wall_seconds")];

/// Compare two campaigns' tables bit for bit (rows sorted by key, no duplicated keys),
/// except the columns in `ignore` as (table, column). Returns every difference found.
pub fn table_differences(a: &Tables, b: &Tables, ignore: &[(&str, &str)]) -> Vec<String> {
    let mut diffs = Vec::new();
    for (name, keys) in TABLES {
        let (ta, tb) = (&a[name], &b[name]);
        if ta.columns != tb.columns {
            diffs.push(format!(
                "{name}: columns differ:\n  {:?}\n  {:?}",
                ta.columns, tb.columns
            ));
            continue;
        }
        if ta.columns.is_empty() {
            // Both without part files (see `MAY_BE_EMPTY`).
            continue;
        }
        let (ra, rb) = match (ta.sorted_by(keys), tb.sorted_by(keys)) {
            (Ok(ra), Ok(rb)) => (ra, rb),
            (ea, eb) => {
                diffs.extend(ea.err().map(|e| format!("first: {e}")));
                diffs.extend(eb.err().map(|e| format!("second: {e}")));
                continue;
            }
        };
        if ra.len() != rb.len() {
            diffs.push(format!("{name}: {} rows vs {} rows", ra.len(), rb.len()));
            continue;
        }
        let skip: Vec<bool> = ta
            .columns
            .iter()
            .map(|(c, _)| ignore.contains(&(name, c.as_str())))
            .collect();
        let key_idx: Vec<usize> = keys.iter().map(|k| ta.col(k)).collect();
        let mut n = 0;
        for (x, y) in ra.iter().zip(&rb) {
            if key_idx.iter().any(|&j| x[j] != y[j]) {
                n += 1;
                if n <= 10 {
                    let kx: Vec<String> = key_idx.iter().map(|&j| x[j].to_string()).collect();
                    let ky: Vec<String> = key_idx.iter().map(|&j| y[j].to_string()).collect();
                    diffs.push(format!(
                        "{name}: row keys differ: ({}) vs ({})",
                        kx.join(", "),
                        ky.join(", ")
                    ));
                }
                continue;
            }
            for (j, (cx, cy)) in x.iter().zip(y).enumerate() {
                if !skip[j] && cx != cy {
                    n += 1;
                    if n <= 10 {
                        let key: Vec<String> = keys
                            .iter()
                            .map(|k| format!("{k}={}", x[ta.col(k)]))
                            .collect();
                        diffs.push(format!(
                            "{name} [{}] column {}: {cx} vs {cy}",
                            key.join(", "),
                            ta.columns[j].0
                        ));
                    }
                }
            }
        }
        if n > 10 {
            diffs.push(format!("{name}: ... {} differing values in all", n));
        }
    }
    diffs
}

pub fn assert_tables_identical(a: &Tables, b: &Tables, what: &str) {
    let diffs = table_differences(a, b, &NONDETERMINISTIC);
    assert!(
        diffs.is_empty(),
        "{what}: tables differ ({} differences):\n{}",
        diffs.len(),
        diffs.join("\n")
    );
}

/// `granular status DIR --json`, parsed.
pub fn status_json(dir: &Path, log: &Path) -> Value {
    let (code, out) = run_capture(&["status", dir.to_str().unwrap(), "--json"], log);
    assert_eq!(
        code,
        Some(0),
        "granular status {} --json failed; log:\n{}",
        dir.display(),
        log_text(log)
    );
    serde_json::from_str(&out).unwrap_or_else(|e| panic!("status --json is not JSON ({e}):\n{out}"))
}

pub fn write_json(path: &Path, v: &Value) {
    fs::write(path, serde_json::to_string_pretty(v).unwrap()).expect("write json");
}

/// Every table of a campaign directory (every visible Parquet file of `tables/<t>`).
pub fn read_all(dir: &Path) -> BTreeMap<String, Table> {
    fs::read_dir(dir.join("tables"))
        .expect("tables dir")
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| !n.starts_with('.'))
        .map(|t| (t.clone(), read_table(dir, &t)))
        .collect()
}

/// The rows of every table for the points and runs the latest manifest asks for
/// (`in_manifest` of `points` and `registered_runs`), with `point_id` replaced by the point's
/// params and `run_id` by params and the run's replica in the latest manifest (ids depend on
/// the order in which a campaign grew; params and that replica do not), `runs.wall_seconds`,
/// `runs.continued_from` and the registry's numbering (`runs.replica`,
/// `registered_runs.replica`, `.continues`) blanked, rows sorted: comparable between a grown
/// campaign and one started from its final manifest.
pub fn current_view(
    t: &BTreeMap<String, Table>,
) -> BTreeMap<String, (Vec<String>, Vec<Vec<Cell>>)> {
    let points = &t["points"];
    let (pid, params, cur) = (
        points.col("point_id"),
        points.col("params"),
        points.col("in_manifest"),
    );
    let point: BTreeMap<u64, (Cell, bool)> = points
        .rows
        .iter()
        .map(|r| {
            (
                r[pid].as_u64(),
                (r[params].clone(), r[cur] == Cell::Bool(true)),
            )
        })
        .collect();
    // run_id -> (key "params replica r", in the latest manifest), from `registered_runs` (the
    // replica in the latest manifest) or, in a campaign of an earlier granular without it,
    // from `runs` (its replica; every run of a current point counted).
    let reg = t.get("registered_runs");
    let run: BTreeMap<u64, (Cell, bool)> = match reg {
        Some(reg) => {
            let (rid, rpoint, rcur, rrep) = (
                reg.col("run_id"),
                reg.col("point_id"),
                reg.col("in_manifest"),
                reg.col("manifest_replica"),
            );
            reg.rows
                .iter()
                .map(|r| {
                    let p = point[&r[rpoint].as_u64()].0.as_str().to_string();
                    (
                        r[rid].as_u64(),
                        (
                            Cell::S(format!("{p} replica {}", r[rrep])),
                            r[rcur] == Cell::Bool(true),
                        ),
                    )
                })
                .collect()
        }
        None => {
            let runs = &t["runs"];
            let (rid, rpoint, rrep) = (
                runs.col("run_id"),
                runs.col("point_id"),
                runs.col("replica"),
            );
            runs.rows
                .iter()
                .map(|r| {
                    let p = point[&r[rpoint].as_u64()].0.as_str().to_string();
                    (
                        r[rid].as_u64(),
                        (Cell::S(format!("{p} replica {}", r[rrep])), true),
                    )
                })
                .collect()
        }
    };
    t.iter()
        .map(|(name, table)| {
            let names: Vec<String> = table.columns.iter().map(|c| c.0.clone()).collect();
            let col = |c: &str| names.iter().position(|n| n == c);
            let (p, r) = (col("point_id"), col("run_id"));
            // Clock readings and the registry's own numbering (which depends on how the
            // campaign grew) are left out.
            let blanked: &[&str] = match (name.as_str(), reg.is_some()) {
                ("runs", true) => &["wall_seconds", "continued_from", "replica"],
                ("runs", false) => &["wall_seconds", "continued_from"],
                ("registered_runs", _) => &["replica", "continues"],
                _ => &[],
            };
            let blank: Vec<usize> = blanked.iter().filter_map(|c| col(c)).collect();
            let mut rows: Vec<Vec<Cell>> = table
                .rows
                .iter()
                .filter(|row| p.is_none_or(|j| point[&row[j].as_u64()].1))
                .filter(|row| r.is_none_or(|j| run[&row[j].as_u64()].1))
                .map(|row| {
                    let mut row = row.clone();
                    if let Some(j) = r {
                        row[j] = run[&row[j].as_u64()].0.clone();
                    }
                    if let Some(j) = p {
                        row[j] = point[&row[j].as_u64()].0.clone();
                    }
                    for &j in &blank {
                        row[j] = Cell::Null;
                    }
                    row
                })
                .collect();
            rows.sort();
            (name.clone(), (names, rows))
        })
        .collect()
}

/// Assert two campaigns' current views equal, naming the first differences.
pub fn assert_same_current(a: &Path, b: &Path, what: &str) {
    assert_same_current_except(a, b, what, &[]);
}

/// [`assert_same_current`] with the columns named `drop` left out of every table (columns
/// that a campaign written by an older version legitimately lacks or has null).
pub fn assert_same_current_except(a: &Path, b: &Path, what: &str, drop: &[&str]) {
    let strip = |mut v: BTreeMap<String, (Vec<String>, Vec<Vec<Cell>>)>| {
        for (cols, rows) in v.values_mut() {
            let keep: Vec<usize> = (0..cols.len())
                .filter(|&i| !drop.contains(&cols[i].as_str()))
                .collect();
            *cols = keep.iter().map(|&i| cols[i].clone()).collect();
            for r in rows.iter_mut() {
                *r = keep.iter().map(|&i| r[i].clone()).collect();
            }
        }
        v
    };
    let (va, vb) = (
        strip(current_view(&read_all(a))),
        strip(current_view(&read_all(b))),
    );
    assert_eq!(
        va.keys().collect::<Vec<_>>(),
        vb.keys().collect::<Vec<_>>(),
        "{what}: different tables"
    );
    for (name, (ca, ra)) in &va {
        let (cb, rb) = &vb[name];
        assert_eq!(ca, cb, "{what}: {name}: columns differ");
        assert_eq!(ra.len(), rb.len(), "{what}: {name}: row counts differ");
        if let Some(i) = (0..ra.len()).find(|&i| ra[i] != rb[i]) {
            let show = |r: &Vec<Cell>| {
                r.iter()
                    .map(|c| c.to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            panic!(
                "{what}: {name}: rows differ (first of {} sorted rows, index {i}):\n  {}\n  {}",
                ra.len(),
                show(&ra[i]),
                show(&rb[i])
            );
        }
    }
}

/// A path as the `&str` of a command-line argument.
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `cp -a from to`.
pub fn copy_dir(from: &Path, to: &Path) {
    let ok = Command::new("cp")
        .args(["-a", s(from), s(to)])
        .status()
        .unwrap();
    assert!(ok.success());
}

/// The pid of a process that has ended (its locks and temporaries look stale).
pub fn dead_pid() -> u32 {
    let mut c = Command::new("true").spawn().expect("spawn true");
    c.wait().unwrap();
    c.id()
}
