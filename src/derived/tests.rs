use std::collections::BTreeMap;
use std::sync::Arc;

use arrow_array::{ArrayRef, Float64Array, RecordBatch, StringArray, UInt32Array, UInt64Array};
use arrow_schema::{DataType, Field, Schema, SchemaRef};

use super::*;

fn species_schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        Field::new("run_id", DataType::UInt64, false),
        Field::new("point_id", DataType::UInt32, false),
        Field::new("t", DataType::Float64, false),
        Field::new("species", DataType::UInt32, false),
        Field::new("count", DataType::UInt64, false),
        Field::new("temperature", DataType::Float64, false),
        Field::new("msd", DataType::Float64, true),
    ]))
}

fn hist_schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        Field::new("run_id", DataType::UInt64, false),
        Field::new("point_id", DataType::UInt32, false),
        Field::new("kind", DataType::Utf8, false),
        Field::new("h", DataType::UInt32, false),
        Field::new("count", DataType::UInt64, false),
        Field::new("density", DataType::Float64, true),
    ]))
}

fn tables() -> Vec<(&'static str, SchemaRef)> {
    vec![("species", species_schema()), ("hist", hist_schema())]
}

/// Rows (run, t, species, temperature, msd).
fn species(rows: &[(u64, f64, u32, f64, Option<f64>)]) -> RecordBatch {
    let cols: Vec<ArrayRef> = vec![
        Arc::new(rows.iter().map(|r| r.0).collect::<UInt64Array>()),
        Arc::new(rows.iter().map(|_| 0u32).collect::<UInt32Array>()),
        Arc::new(rows.iter().map(|r| r.1).collect::<Float64Array>()),
        Arc::new(rows.iter().map(|r| r.2).collect::<UInt32Array>()),
        Arc::new(rows.iter().map(|_| 10u64).collect::<UInt64Array>()),
        Arc::new(rows.iter().map(|r| r.3).collect::<Float64Array>()),
        Arc::new(rows.iter().map(|r| r.4).collect::<Float64Array>()),
    ];
    RecordBatch::try_new(species_schema(), cols).unwrap()
}

fn hist(rows: &[(u64, &str, u32, Option<f64>)]) -> RecordBatch {
    let cols: Vec<ArrayRef> = vec![
        Arc::new(rows.iter().map(|r| r.0).collect::<UInt64Array>()),
        Arc::new(rows.iter().map(|_| 0u32).collect::<UInt32Array>()),
        Arc::new(rows.iter().map(|r| Some(r.1)).collect::<StringArray>()),
        Arc::new(rows.iter().map(|r| r.2).collect::<UInt32Array>()),
        Arc::new(rows.iter().map(|_| 1u64).collect::<UInt64Array>()),
        Arc::new(rows.iter().map(|r| r.3).collect::<Float64Array>()),
    ];
    RecordBatch::try_new(hist_schema(), cols).unwrap()
}

fn q(pairs: &[(&str, &str)]) -> BTreeMap<String, String> {
    pairs
        .iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect()
}

fn data() -> BTreeMap<&'static str, Vec<RecordBatch>> {
    let mut m = BTreeMap::new();
    m.insert(
        "species",
        vec![
            species(&[
                (1, 0.0, 0, 1.0, Some(0.0)),
                (1, 0.0, 1, 2.0, Some(0.0)),
                (1, 1.0, 0, 0.5, Some(3.0)),
                (1, 1.0, 1, 1.5, Some(6.0)),
            ]),
            species(&[
                (2, 0.0, 0, 4.0, None),
                (2, 0.0, 1, 2.0, None),
                (1, 2.0, 0, 0.25, Some(12.0)),
            ]),
        ],
    );
    m.insert(
        "hist",
        vec![hist(&[
            (1, "v", 3, Some(0.5)),
            (1, "v", 4, Some(0.7)),
            (1, "l", 3, Some(9.0)),
            (2, "v", 3, Some(0.25)),
        ])],
    );
    m
}

#[test]
fn a_ratio_is_a_time_series_at_the_times_both_have_a_row() {
    let qs = compile(
        &q(&[(
            "gamma",
            "temperature[species=1] / species.temperature[species=0]",
        )]),
        &tables(),
    )
    .unwrap();
    assert!(qs.list[0].is_series());
    assert_eq!(qs.tables().into_iter().collect::<Vec<_>>(), vec!["species"]);
    let v = qs.eval(&data()).unwrap();
    assert_eq!(v[&1][0], vec![(Some(0.0), 2.0), (Some(1.0), 3.0)]);
    assert_eq!(v[&2][0], vec![(Some(0.0), 0.5)]);
}

#[test]
fn reductions_and_selectors_on_strings() {
    let qs = compile(
        &q(&[
            ("d", "slope(msd[species=0]) / 6"),
            ("m", "mean(temperature[species=0])"),
            ("s", "sum(temperature)"),
            ("lo", "min(temperature) + max(temperature) * 0"),
            (
                "f",
                "first(temperature[species=0]) - last(temperature[species=0])",
            ),
            ("c", "count(hist.kind[kind='v'])"),
            ("h", "density[kind='v', h=3] ^ 2 + sqrt(4) + 1/2"),
        ]),
        &tables(),
    )
    .unwrap();
    let v = qs.eval_each(&data(), Some(&[1]));
    let r = &v[&1];
    let val = |i: usize| r[i].as_ref().unwrap()[0].1;
    // names in order: c, d, f, h, lo, m, s
    assert_eq!(val(0), 2.0);
    // msd of species 0 at t = 0, 1, 2: 0, 3, 12: slope 6.
    assert_eq!(val(1), 1.0);
    assert_eq!(val(2), 1.0 - 0.25);
    assert_eq!(val(3), 0.25 + 2.0 + 0.5);
    assert_eq!(val(4), 0.25);
    assert_eq!(val(5), (1.0 + 0.5 + 0.25) / 3.0);
    assert_eq!(val(6), 1.0 + 2.0 + 0.5 + 1.5 + 0.25);
    assert!(r.iter().all(|x| x.as_ref().unwrap()[0].0.is_none()));
}

#[test]
fn eval_errors_name_quantity_run_and_what_is_missing() {
    let qs = compile(
        &q(&[
            ("two", "temperature * 1"),
            ("nul", "mean(msd)"),
            ("none", "density[kind='x', h=3]"),
            ("inf", "mean(temperature) / 0"),
        ]),
        &tables(),
    )
    .unwrap();
    let v = qs.eval_each(&data(), None);
    assert_eq!(v.keys().copied().collect::<Vec<_>>(), vec![1, 2]);
    let e = |run: u64, i: usize| v[&run][i].clone().unwrap_err();
    // names in order: inf, none, nul, two
    assert!(
        e(1, 0).message.contains("not a finite number"),
        "{:?}",
        e(1, 0)
    );
    assert!(
        e(1, 1).message.contains("no row of hist matches"),
        "{:?}",
        e(1, 1)
    );
    assert!(
        e(2, 2).message.contains("species.msd is null"),
        "{:?}",
        e(2, 2)
    );
    let two = e(1, 3);
    assert_eq!((two.quantity.as_str(), two.run_id), ("two", 1));
    assert!(
        two.message.contains("matches 2 rows of species at t = 0"),
        "{two}"
    );
    assert!(qs.eval(&data()).is_err());
}

#[test]
fn compile_refuses_everything_at_once_with_paths() {
    let e = compile(
        &q(&[
            ("a", "temprature[species=1]"),
            ("b", "count"),
            ("c", "species.kind"),
            ("d", "hist.kind"),
            ("e", "temperature[specie=1] + temperature[species='x']"),
            ("f", "mean(temperature + 1)"),
            ("g", "foo(temperature)"),
            ("h", "temperature +"),
            ("i", "nosuch.temperature"),
            ("t", "temperature"),
        ]),
        &tables(),
    )
    .unwrap_err();
    let at = |p: &str| -> Vec<&str> {
        e.iter()
            .filter(|x| x.0 == format!("/derived/{p}"))
            .map(|x| x.1.as_str())
            .collect()
    };
    assert!(
        at("a")[0].contains("unknown column `temprature`")
            && at("a")[0].contains("expected one of temperature"),
        "{e:?}"
    );
    assert!(
        at("b")[0].contains("ambiguous column `count`") && at("b")[0].contains("species, hist"),
        "{e:?}"
    );
    assert!(
        at("c")[0].contains("unknown column `kind` of table species"),
        "{e:?}"
    );
    assert!(at("d")[0].contains("not a number"), "{e:?}");
    assert!(
        at("e")[0].contains("unknown column `specie`")
            && at("e")[1].contains("expected a number, got the string"),
        "{e:?}"
    );
    assert!(at("f")[0].contains("single column reference"), "{e:?}");
    assert!(at("g")[0].contains("unknown function `foo`"), "{e:?}");
    assert!(at("h")[0].contains("expected 2 arguments"), "{e:?}");
    assert!(at("i")[0].contains("unknown table `nosuch`"), "{e:?}");
    assert!(
        at("t")[0].contains("is a column of the derived tables"),
        "{e:?}"
    );
}

#[test]
fn huge_or_deeply_nested_expressions_are_refused_not_overflowing_the_stack() {
    let deep = format!(
        "{}temperature[species=1]{}",
        "(".repeat(100_000),
        ")".repeat(100_000)
    );
    let long = vec!["temperature[species=1]"; 400].join(" + ");
    let e = compile(&q(&[("deep", &deep), ("long", &long)]), &tables()).unwrap_err();
    assert_eq!(e.len(), 2, "{e:?}");
    assert!(
        e.iter()
            .all(|x| x.1.contains("at most 4096 bytes and 64 levels")),
        "{e:?}"
    );
    let ok = format!("{}temperature[species=1]{}", "(".repeat(60), ")".repeat(60));
    assert!(compile(&q(&[("ok", &ok)]), &tables()).is_ok());
}
