//! The committed JSON Schema must be what the code generates, and the committed job
//! manifests must validate.

use std::fs;

use super::util::repo_root;

const REGENERATE: &str = "cargo run --release -- schema > schemas/manifest.schema.json";

#[test]
fn committed_schema_matches_generated() {
    let path = repo_root().join("schemas/manifest.schema.json");
    let committed = fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("{}: {e}; regenerate with `{REGENERATE}`", path.display()));
    // Exactly what `granular schema` prints (println!: pretty JSON and a newline).
    let generated = format!(
        "{}\n",
        serde_json::to_string_pretty(&granular::manifest::json_schema()).unwrap()
    );
    if committed != generated {
        let first = committed
            .lines()
            .zip(generated.lines())
            .position(|(a, b)| a != b)
            .unwrap_or(committed.lines().count().min(generated.lines().count()));
        panic!(
            "schemas/manifest.schema.json is out of date with the manifest types (first difference at line {}:\n  committed: {:?}\n  generated: {:?});\nregenerate it with `{REGENERATE}`",
            first + 1,
            committed.lines().nth(first).unwrap_or("<end of file>"),
            generated.lines().nth(first).unwrap_or("<end of file>"),
        );
    }
}

/// The committed schema (what editors and other tools use) compiles as draft 2020-12 and
/// accepts every good manifest and every job, and rejects a manifest with an unknown key.
#[test]
fn committed_schema_accepts_good_manifests() {
    let path = repo_root().join("schemas/manifest.schema.json");
    let schema: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(&path).unwrap()).unwrap();
    let validator = jsonschema::validator_for(&schema)
        .unwrap_or_else(|e| panic!("{}: does not compile: {e}", path.display()));
    let mut files = Vec::new();
    for dir in ["tests/manifests/good", "jobs"] {
        for e in fs::read_dir(repo_root().join(dir)).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "json") {
                files.push(p);
            }
        }
    }
    assert!(files.len() >= 4);
    for p in &files {
        let v: serde_json::Value = serde_json::from_str(&fs::read_to_string(p).unwrap()).unwrap();
        let errs: Vec<String> = validator
            .iter_errors(&v)
            .map(|e| format!("{}: {e}", e.instance_path()))
            .collect();
        assert!(
            errs.is_empty(),
            "{} fails the committed schema:\n{}",
            p.display(),
            errs.join("\n")
        );
    }
    let bad = repo_root().join("tests/manifests/bad/unknown_keys.json");
    let v: serde_json::Value = serde_json::from_str(&fs::read_to_string(&bad).unwrap()).unwrap();
    assert!(
        !validator.is_valid(&v),
        "{} passes the committed schema",
        bad.display()
    );
}

#[test]
fn job_manifests_validate() {
    let dir = repo_root().join("jobs");
    let mut files: Vec<_> = fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no jobs/*.json");
    let failures: Vec<String> = files
        .iter()
        .filter_map(|f| {
            granular::campaign::plan::load(f)
                .err()
                .map(|e| e.to_string())
        })
        .collect();
    assert!(
        failures.is_empty(),
        "job manifests do not validate:\n{}",
        failures.join("\n")
    );
}
