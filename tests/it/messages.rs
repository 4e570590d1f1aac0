//! Messages that teach (issue 26): a value of the wrong form is answered with every allowed
//! form, each with an example made from the schema (at every `oneOf`/`anyOf` of the schema,
//! and in a manifest: restitution, species, initial_temperature, a target's `t`, a sweep
//! value); one number rule (`2`, `2.0` and `2e0` are the same parameter value: same points,
//! seeds and tables); `serve` stopped by SIGTERM/SIGINT says so (exit 130); refusals end with
//! what to do next.

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{json, Value};

use granular::manifest::{forms, json_schema, validate};

use super::util::{
    assert_same_current, bin, heavy, log_text, run_capture, run_granular, s, write_json,
};

const LIMIT: Duration = Duration::from_secs(120);

/// Every `oneOf`/`anyOf` of the manifest's schema (JSON pointer, the node holding it).
fn alternative_nodes(v: &Value, at: String, out: &mut Vec<(String, Value)>) {
    match v {
        Value::Object(m) => {
            if m.contains_key("oneOf") || m.contains_key("anyOf") {
                out.push((at.clone(), v.clone()));
            }
            for (k, x) in m {
                alternative_nodes(x, format!("{at}/{k}"), out);
            }
        }
        Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                alternative_nodes(x, format!("{at}/{i}"), out);
            }
        }
        _ => {}
    }
}

/// At every `oneOf`/`anyOf` of the schema, a value of none of the forms (`true`, `12345`) is
/// one error naming every form by its example, and each example is a value of its form (so
/// the examples cannot drift from what is accepted).
#[test]
fn every_alternative_names_each_form_with_a_valid_example() {
    let root = json_schema();
    let mut nodes = Vec::new();
    alternative_nodes(&root, String::new(), &mut nodes);
    assert!(nodes.len() >= 20, "found {} alternatives", nodes.len());
    let defs = root["$defs"].clone();
    let mut checked = 0;
    for (at, node) in nodes {
        let key = if node.get("oneOf").is_some() {
            "oneOf"
        } else {
            "anyOf"
        };
        let alternatives = node[key].as_array().unwrap().clone();
        let mut schema = node.clone();
        schema["$defs"] = defs.clone();
        for wrong in [json!(true), json!([[1]])] {
            let errors = validate::schema_errors(&schema, &wrong, "");
            assert_eq!(errors.len(), 1, "{at} with {wrong}: {errors:?}");
            let message = &errors[0].message;
            let named = forms::describe(&schema, &alternatives, &wrong);
            assert_eq!(named.len(), alternatives.len(), "{at}");
            for form in &named {
                assert!(
                    message.contains(form.as_str()),
                    "{at}: {form} not in {message:?}"
                );
            }
        }
        for alt in &alternatives {
            let ex = forms::example(&schema, alt, None);
            let mut one = alt.clone();
            one["$defs"] = defs.clone();
            let errs = validate::schema_errors(&one, &ex, "");
            assert!(
                errs.is_empty(),
                "{at}: the example {ex} of {alt} is refused: {errs:?}"
            );
        }
        checked += 1;
    }
    assert!(checked >= 20);
}

/// A small valid DSMC manifest (two points, well under a second).
fn dsmc(params: Value, sweep: Value) -> Value {
    let mut p = json!({
        "method": "low_rank",
        "species": {"list": [{"mass": 1.0, "diameter": 1.0, "count": 60},
                              {"mass": 2.0, "diameter": 1.0, "count": 60}]},
        "volume": 1000.0,
        "restitution": {"constant": 0.8},
        "t_end": 2.0,
        "initial_temperature": 1.0,
        "output_times": {"list": [1.0, 2.0]},
        "observables": ["temperature"]
    });
    for (k, v) in params.as_object().unwrap() {
        p[k] = v.clone();
    }
    json!({"name": "msg", "model": "dsmc", "seed": 5, "replicas": 2, "params": p, "sweep": sweep})
}

fn errors_of(m: &Value) -> String {
    match granular::campaign::plan::parse(&m.to_string(), "m.json") {
        Ok(_) => panic!("accepted: {m}"),
        Err(e) => e.to_string(),
    }
}

/// `"restitution": 0.8` names `{"constant": 0.8}` (before: "0.8 matches none of the allowed
/// forms"), and so for the species, the initial temperature, a target's time and a sweep value.
#[test]
fn a_wrong_form_names_the_allowed_forms() {
    let mut m = dsmc(
        json!({"restitution": 0.8, "species": 5, "initial_temperature": "hot"}),
        json!({}),
    );
    m["derived"] = json!({"T": "temperature[species=1]"});
    m["target"] = json!([{"quantity": "T", "t": 3, "sem_rel": 0.1}]);
    m.as_object_mut().unwrap().remove("replicas");
    let text = errors_of(&m);
    for want in [
        r#"at /params/restitution: 0.8 is not one of the allowed forms: {"constant": 0.8}, {"viscoelastic": "#,
        r#"at /params/species: 5 is not one of the allowed forms: {"power_law": "#,
        r#"{"list": [{"#,
        r#"at /params/initial_temperature: "hot" is not one of the allowed forms: 1.0, {"hcs": {"mean": "#,
        r#"at /target/0/t: 3 is not one of the allowed forms: "t_end", {"at": 3}, {"after": 3}"#,
    ] {
        assert!(text.contains(want), "{want:?} not in\n{text}");
    }
    let text = errors_of(&dsmc(
        json!({}),
        json!({"restitution": [{"constant": 0.5}, 0.9]}),
    ));
    assert!(
        text.contains(
            r#"0.9 is not one of the allowed forms: {"constant": 0.9}, {"viscoelastic": "#
        ),
        "{text}"
    );
}

/// The number rule: a number is its value. Manifests that differ only in `2` / `2.0` / `2e0`
/// (in params, in a sweep list, in a species list, a whole-number key such as `count` or
/// `seed` written `60.0`) have the same points (ids, swept values, params), and their tiny
/// runs the same tables (seeds included).
#[test]
fn a_number_is_its_value() {
    let _g = heavy();
    let a = dsmc(
        json!({"initial_temperature": 2.0, "t_end": 2.0,
               "species": {"list": [{"mass": 2.0, "diameter": 1.0, "count": 60},
                                   {"mass": 4.0, "diameter": 1.0, "count": 60}]}}),
        json!({"restitution.constant": [0.5, 1.0], "species.list.1.mass": [4.0, 8.0]}),
    );
    let b_text = a
        .to_string()
        .replace("\"initial_temperature\":2.0", "\"initial_temperature\":2")
        .replace("\"t_end\":2.0", "\"t_end\":2e0")
        .replace("{\"mass\":2.0", "{\"mass\":2")
        .replace("{\"mass\":4.0", "{\"mass\":4")
        .replace("[0.5,1.0]", "[0.5,1]")
        .replace("[4.0,8.0]", "[4,8e0]")
        // Whole-number keys too (before: "invalid type: floating point `60.0`, expected u64").
        .replace("\"count\":60", "\"count\":60.0")
        .replace("\"seed\":5", "\"seed\":5e0");
    assert!(
        b_text.contains("\"count\":60.0") && b_text.contains("\"seed\":5e0"),
        "{b_text}"
    );
    assert!(
        !b_text.contains("\"mass\":2.0") && b_text.contains("[4,8e0]"),
        "{b_text}"
    );
    let (_, pa) = granular::campaign::plan::parse(&a.to_string(), "a.json").unwrap();
    let (_, pb) = granular::campaign::plan::parse(&b_text, "b.json").unwrap();
    let view = |p: &granular::campaign::plan::Plan| -> Vec<(u32, String, String)> {
        p.points
            .iter()
            .map(|x| {
                (
                    x.point_id,
                    Value::Array(x.values.clone()).to_string(),
                    granular::manifest::sweep::canonical(&x.params.to_value()),
                )
            })
            .collect()
    };
    assert_eq!(view(&pa), view(&pb));
    assert_eq!(pa.points.len(), 4);
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    write_json(&d.join("a.json"), &a);
    std::fs::write(d.join("b.json"), &b_text).unwrap();
    for x in ["a", "b"] {
        let m = d.join(format!("{x}.json"));
        let out = d.join(x);
        let log = d.join(format!("{x}.log"));
        let code = run_granular(&["run", s(&m), "--out", s(&out), "--quiet"], &log, LIMIT);
        assert_eq!(code, Some(0), "{}", log_text(&log));
    }
    assert_same_current(&d.join("a"), &d.join("b"), "2 vs 2.0");
}

/// `granular serve` stopped by SIGTERM or SIGINT says `granular serve: stopped by SIGTERM`
/// (before: "interrupted before any simulation started") and exits with 130.
#[test]
fn serve_stopped_by_a_signal_says_so() {
    let _g = heavy();
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let (m, c, log) = (d.join("m.json"), d.join("c"), d.join("run.log"));
    write_json(&m, &dsmc(json!({}), json!({})));
    assert_eq!(
        run_granular(&["run", s(&m), "--out", s(&c), "--quiet"], &log, LIMIT),
        Some(0),
        "{}",
        log_text(&log)
    );
    for (signal, name) in [(libc::SIGTERM, "SIGTERM"), (libc::SIGINT, "SIGINT")] {
        let mut child = Command::new(bin())
            .args(["serve", s(&c), "--addr", "127.0.0.1:0"])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // Serving once the address is printed (the handler is installed before).
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        assert!(line.starts_with("serving "), "{line:?}");
        // SAFETY: a signal to the child process spawned above.
        assert_eq!(unsafe { libc::kill(child.id() as libc::pid_t, signal) }, 0);
        let start = Instant::now();
        let status = loop {
            if let Some(st) = child.try_wait().unwrap() {
                break st;
            }
            if start.elapsed() > Duration::from_secs(60) {
                let _ = child.kill();
                panic!("serve still running 60 s after {name}");
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        let mut err = String::new();
        std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
        assert_eq!(status.code(), Some(130), "{name}: {err}");
        assert!(
            err.contains(&format!("granular serve: stopped by {name}")),
            "{name}: {err}"
        );
        assert!(!err.contains("before any simulation"), "{err}");
    }
}

/// A handful of refusals end with the next step: a directory that is no campaign (give
/// another --out), a damaged campaign.json (restore it or start over), a wrong form (the
/// forms), an unknown model (the models).
#[test]
fn refusals_say_what_to_do_next() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let m = d.join("m.json");
    write_json(&m, &dsmc(json!({}), json!({})));
    let not_campaign = d.join("docs");
    std::fs::create_dir(&not_campaign).unwrap();
    std::fs::write(not_campaign.join("notes.txt"), "mine").unwrap();
    let log = d.join("1.log");
    let (code, _) = run_capture(&["run", s(&m), "--out", s(&not_campaign)], &log);
    assert_eq!(code, Some(3));
    assert!(
        log_text(&log).contains("give a new or empty directory with --out"),
        "{}",
        log_text(&log)
    );

    let damaged = d.join("damaged");
    std::fs::create_dir(&damaged).unwrap();
    std::fs::write(damaged.join("campaign.json"), "{not json").unwrap();
    let log = d.join("2.log");
    let (code, _) = run_capture(&["status", s(&damaged)], &log);
    assert_eq!(code, Some(3), "{}", log_text(&log));
    assert!(
        log_text(&log).contains("restore it from a backup"),
        "{}",
        log_text(&log)
    );

    // A directory that is not a campaign, given to a command that reads one.
    let empty = d.join("empty");
    std::fs::create_dir(&empty).unwrap();
    let log = d.join("4.log");
    let (code, _) = run_capture(&["status", s(&empty)], &log);
    assert_eq!(code, Some(3), "{}", log_text(&log));
    assert!(
        log_text(&log).contains("give the directory that `granular run MANIFEST --out DIR` wrote"),
        "{}",
        log_text(&log)
    );

    let mut bad = dsmc(json!({"restitution": 0.8}), json!({}));
    bad["model"] = json!("dsmcc");
    write_json(&m, &bad);
    let log = d.join("3.log");
    let (code, _) = run_capture(&["validate", s(&m)], &log);
    assert_eq!(code, Some(2));
    let text = log_text(&log);
    assert!(
        text.contains(
            r#"expected "dsmc" or "rfm" or "bisection" or "cascade" or "spm", got "dsmcc""#
        ),
        "{text}"
    );
}
