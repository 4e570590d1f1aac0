//! The documentation holds together: every relative link and `#anchor` in README.md and
//! docs/*.md resolves (a file or directory of the repository; an anchor of a heading of the
//! target Markdown file, by GitHub's rules), and every property name of the manifest's JSON
//! Schema is mentioned in docs/manifest.md; docs/tutorial.md's manifest is its job and
//! `granular validate` prints what the tutorial shows. These tests take milliseconds.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Component, Path, PathBuf};

use super::util::repo_root;

/// GitHub's anchor of a heading: lowercase, every character that is not a letter, a digit,
/// `-`, `_` or a space dropped, each space replaced by `-` (github-slugger).
fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || *c == '-' || *c == '_' || *c == ' ')
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// The lines of a Markdown text outside fenced code blocks, with their line numbers (from 1).
fn prose_lines(text: &str) -> Vec<(usize, &str)> {
    let mut fenced = false;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if !fenced {
            out.push((i + 1, line));
        }
    }
    out
}

/// The anchors of a Markdown text's headings (duplicates get `-1`, `-2`, ... as on GitHub).
fn anchors(text: &str) -> BTreeSet<String> {
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    let mut out = BTreeSet::new();
    for (_, line) in prose_lines(text) {
        let hashes = line.chars().take_while(|c| *c == '#').count();
        if (1..=6).contains(&hashes) && line[hashes..].starts_with(' ') {
            let base = slug(&line[hashes..]);
            let n = seen.entry(base.clone()).or_insert(0);
            out.insert(if *n == 0 {
                base.clone()
            } else {
                format!("{base}-{n}")
            });
            *n += 1;
        }
    }
    out
}

/// A line without its inline code spans (text between backticks).
fn without_code_spans(line: &str) -> String {
    let mut out = String::new();
    let mut in_code = false;
    for c in line.chars() {
        if c == '`' {
            in_code = !in_code;
        } else if !in_code {
            out.push(c);
        }
    }
    out
}

/// The targets of the inline links `[text](target)` of a Markdown text, with line numbers.
fn link_targets(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    for (n, line) in prose_lines(text) {
        let line = without_code_spans(line);
        let mut rest = line.as_str();
        while let Some(i) = rest.find("](") {
            let after = &rest[i + 2..];
            let end = after.find(')').unwrap_or(after.len());
            let target = after[..end].split_whitespace().next().unwrap_or("");
            out.push((n, target.to_string()));
            rest = &after[end..];
        }
    }
    out
}

/// `path` with `.` and `..` folded, or None if it climbs above its root.
fn normalise(path: &Path) -> Option<PathBuf> {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                if !out.pop() {
                    return None;
                }
            }
            Component::Normal(x) => out.push(x),
            _ => return None,
        }
    }
    Some(out)
}

/// Every broken relative link of the Markdown files `files` (paths relative to `root`), as
/// "FILE:LINE: TARGET: why".
fn broken_links(root: &Path, files: &[PathBuf]) -> Vec<String> {
    let mut broken = Vec::new();
    for file in files {
        let text = fs::read_to_string(root.join(file))
            .unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        for (line, target) in link_targets(&text) {
            let at = format!("{}:{line}: {target}", file.display());
            if target.is_empty() {
                broken.push(format!("{at}: an empty link"));
                continue;
            }
            if target.contains("://") || target.starts_with("mailto:") {
                continue;
            }
            let (path, anchor) = match target.split_once('#') {
                Some((p, a)) => (p, Some(a)),
                None => (target.as_str(), None),
            };
            let dest = if path.is_empty() {
                file.clone()
            } else {
                match normalise(&file.parent().unwrap_or(Path::new("")).join(path)) {
                    Some(p) => p,
                    None => {
                        broken.push(format!("{at}: leaves the repository"));
                        continue;
                    }
                }
            };
            if !root.join(&dest).exists() {
                broken.push(format!("{at}: {} does not exist", dest.display()));
                continue;
            }
            if let Some(anchor) = anchor {
                if dest.extension().is_none_or(|x| x != "md") {
                    broken.push(format!("{at}: an anchor into a file that is not Markdown"));
                    continue;
                }
                let dest_text = fs::read_to_string(root.join(&dest)).unwrap();
                if !anchors(&dest_text).contains(anchor) {
                    broken.push(format!(
                        "{at}: no heading of {} has the anchor #{anchor}",
                        dest.display()
                    ));
                }
            }
        }
    }
    broken
}

/// README.md and every docs/*.md, relative to the repository root.
fn doc_files(root: &Path) -> Vec<PathBuf> {
    let mut files = vec![PathBuf::from("README.md")];
    let mut docs: Vec<PathBuf> = fs::read_dir(root.join("docs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .map(|p| PathBuf::from("docs").join(p.file_name().unwrap()))
        .collect();
    docs.sort();
    files.extend(docs);
    files
}

#[test]
fn github_anchors_follow_githubs_rules() {
    assert_eq!(slug(" Clusters (SLURM)"), "clusters-slurm");
    assert_eq!(
        slug(" Auxiliary models: `bisection`, `cascade`, `spm` (spec `rfm.md` sec. 3)"),
        "auxiliary-models-bisection-cascade-spm-spec-rfmmd-sec-3"
    );
    assert_eq!(
        slug(" Report (`granular report`)"),
        "report-granular-report"
    );
    let a = anchors("# A\n\n## Two  words\n```\n# not a heading\n```\n## A\n");
    let want: BTreeSet<String> = ["a", "two--words", "a-1"].map(String::from).into();
    assert_eq!(a, want);
}

/// The checker itself finds what is broken: a missing file, a missing anchor (in the same
/// file and in another), a link out of the repository; and passes good links.
#[test]
fn the_link_checker_finds_broken_links() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    fs::create_dir(root.join("docs")).unwrap();
    fs::write(
        root.join("README.md"),
        "# Top\n\n## Quick start\n\nSee [a](docs/a.md#part-one), [b](#quick-start), \
         [web](https://example.org/x#y), `[code](#nowhere)`.\n\
         Broken: [c](docs/missing.md), [d](#no-such-heading), [e](docs/a.md#part-two),\n\
         [f](../outside.md), [g](README.md#top)\n```\n[fenced](#nowhere)\n```\n",
    )
    .unwrap();
    fs::write(
        root.join("docs/a.md"),
        "# A\n\n## Part one\n\n[back](../README.md#quick-start) [bad](../README.md#part-one)\n",
    )
    .unwrap();
    let broken = broken_links(root, &doc_files(root));
    let targets: Vec<&str> = broken
        .iter()
        .map(|b| b.split(": ").nth(1).unwrap())
        .collect();
    assert_eq!(
        targets,
        [
            "docs/missing.md",
            "#no-such-heading",
            "docs/a.md#part-two",
            "../outside.md",
            "../README.md#part-one"
        ],
        "{broken:#?}"
    );
}

#[test]
fn every_relative_link_and_anchor_in_the_docs_resolves() {
    let root = repo_root();
    let files = doc_files(&root);
    assert!(files.len() >= 7, "README.md and docs/*.md: {files:?}");
    let broken = broken_links(&root, &files);
    assert!(
        broken.is_empty(),
        "broken links in README.md / docs/*.md (anchors: GitHub's rules, lowercase, spaces -> '-', punctuation dropped):\n{}",
        broken.join("\n")
    );
}
/// Property names of the schema that docs/manifest.md need not mention, each with its reason.
/// (None today: add `("name", "why")` only for a key that is deliberately undocumented.)
const UNDOCUMENTED_KEYS: &[(&str, &str)] = &[];

/// Every property name of every object in `v` (under `properties`, at any depth: `$defs`,
/// `oneOf`, `anyOf`, `items`, ...).
fn property_names(v: &serde_json::Value, out: &mut BTreeSet<String>) {
    match v {
        serde_json::Value::Object(m) => {
            for (k, x) in m {
                if k == "properties" {
                    if let Some(p) = x.as_object() {
                        out.extend(p.keys().cloned());
                    }
                }
                property_names(x, out);
            }
        }
        serde_json::Value::Array(a) => a.iter().for_each(|x| property_names(x, out)),
        _ => {}
    }
}

/// The names of `schema` that `doc` does not mention as `` `name` `` or as a JSON key
/// `"name"` (in an example or a form such as `{"constant": eps}`).
fn undocumented(schema: &serde_json::Value, doc: &str) -> Vec<String> {
    let mut names = BTreeSet::new();
    property_names(schema, &mut names);
    names
        .into_iter()
        .filter(|n| !UNDOCUMENTED_KEYS.iter().any(|(k, _)| k == n))
        .filter(|n| !doc.contains(&format!("`{n}`")) && !doc.contains(&format!("\"{n}\"")))
        .collect()
}

#[test]
fn the_manifest_reference_mentions_every_schema_property() {
    let root = repo_root();
    let schema: serde_json::Value = serde_json::from_str(
        &fs::read_to_string(root.join("schemas/manifest.schema.json")).unwrap(),
    )
    .unwrap();
    let doc = fs::read_to_string(root.join("docs/manifest.md")).unwrap();
    let mut names = BTreeSet::new();
    property_names(&schema, &mut names);
    // The walk reaches into $defs and oneOf: keys that only appear there are found.
    for deep in [
        "power_law",
        "N1",
        "a_kappa",
        "per_decade",
        "sem_rel",
        "h_max",
    ] {
        assert!(names.contains(deep), "the schema walk missed {deep}");
    }
    let missing = undocumented(&schema, &doc);
    assert!(
        missing.is_empty(),
        "property names of schemas/manifest.schema.json not mentioned in docs/manifest.md (as `name` or \"name\"): {missing:?}; document them there (or list a reason in UNDOCUMENTED_KEYS)"
    );
    // And the check can fail: a key the document does not have is reported.
    let mut grown = schema.clone();
    grown["properties"]["a_key_nobody_documented"] = serde_json::json!({"type": "string"});
    assert_eq!(undocumented(&grown, &doc), ["a_key_nobody_documented"]);
    for (k, why) in UNDOCUMENTED_KEYS {
        assert!(
            names.contains(*k),
            "UNDOCUMENTED_KEYS lists {k} ({why}), which the schema does not have"
        );
    }
}

/// The fenced blocks of a Markdown text: (info string, body).
fn fenced_blocks(text: &str) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let mut open: Option<(String, String)> = None;
    for line in text.lines() {
        match (&mut open, line.strip_prefix("```")) {
            (None, Some(info)) => open = Some((info.trim().to_string(), String::new())),
            (Some(_), Some(_)) => out.push(open.take().unwrap()),
            (Some((_, body)), None) => {
                body.push_str(line);
                body.push('\n');
            }
            (None, None) => {}
        }
    }
    assert!(open.is_none(), "a fenced block is not closed");
    out
}

/// The part of docs/tutorial.md that needs no Python (scripts/tutorial_test.py, run by
/// scripts/tests.sh, runs all of it): the manifest it shows is `jobs/tutorial-mixture.json`,
/// and its first command, `granular validate`, prints what the tutorial shows.
#[test]
fn the_tutorials_manifest_is_the_job_and_validates_as_shown() {
    let root = repo_root();
    let text = fs::read_to_string(root.join("docs/tutorial.md")).unwrap();
    let blocks = fenced_blocks(&text);
    let job = "jobs/tutorial-mixture.json";
    let shown: Vec<&String> = blocks
        .iter()
        .filter(|(info, _)| info == &format!("json file={job}"))
        .map(|(_, body)| body)
        .collect();
    assert_eq!(shown.len(), 1, "docs/tutorial.md must show {job} once");
    let shown: serde_json::Value = serde_json::from_str(shown[0]).unwrap();
    let file: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(root.join(job)).unwrap()).unwrap();
    assert_eq!(shown, file, "the manifest in docs/tutorial.md is not {job}");

    let i = blocks
        .iter()
        .position(|(info, _)| info == "sh run")
        .expect("docs/tutorial.md has no `sh run` block");
    let command: Vec<&str> = blocks[i].1.split_whitespace().collect();
    assert_eq!(command[..2], ["granular", "validate"], "{command:?}");
    let (info, expected) = &blocks[i + 1];
    assert_eq!(
        info, "text output",
        "the validate block's output is not shown"
    );
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log");
    let args: Vec<String> = command[1..]
        .iter()
        .map(|a| {
            if a.ends_with(".json") {
                root.join(a).display().to_string()
            } else {
                a.to_string()
            }
        })
        .collect();
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let (code, out) = super::util::run_capture(&args, &log);
    assert_eq!(code, Some(0), "{out}{}", super::util::log_text(&log));
    let root_prefix = format!("{}/", root.display());
    let out = out.replace(&root_prefix, "");
    for line in expected.lines().filter(|l| !l.trim().is_empty()) {
        assert!(
            out.lines().any(|o| o.trim() == line.trim()),
            "docs/tutorial.md shows `{line}`, granular printed:\n{out}"
        );
    }
}
