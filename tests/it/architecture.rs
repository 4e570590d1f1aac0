//! The shape of the code: the `crate::` and `super::` paths of every source file under `src/`
//! form the import graph; it must have no circles (between files, and between the top-level
//! modules), and no arrow that crosses a layer the wrong way:
//!
//! - the simulators (`dsmc`, `rfm`, `aux_models`, `physics`, and any new top-level module not
//!   listed as another layer) import no manifest, store, campaign, model home, command line,
//!   analysis or figures: a simulator hands rows and checkpoint bytes to whoever drives it;
//! - `derived` (the derived quantities' expressions) imports nothing but itself and `math`:
//!   no campaign, model, manifest, store or command line (it sees schemas and batches);
//! - `theory` imports nothing but itself and `math`; `math` nothing but itself; the basic
//!   utilities (`rng`, `fsutil`, `memory`, `exit_codes`) import no other layer;
//! - `store` imports no physics, theory, model, manifest or campaign: it knows no physics;
//! - `campaign` names no particular model: it imports `models` (the closed list and its
//!   interface), never `models::<model>` or a simulator;
//! - a model's home (`models::<model>`) imports no other model's home, no campaign, manifest
//!   or command line (it may use the shared part of the analysis, `analysis`, as it uses
//!   `plot`: its own analysis lives in it);
//! - `analysis` (what every model's analysis shares: options, fit and curve rows, their
//!   writing) imports no model (neither `models` nor a home), campaign, manifest, command
//!   line, report, server or simulator;
//! - `manifest` imports no campaign, store, simulator or model home (only the list of models);
//! - `plot` (the renderer) imports nothing of the crate;
//! - `report` (the HTML page) imports the campaign, store and plot, no model home, simulator,
//!   theory, command line or analysis;
//! - `serve` (the HTTP dashboard) imports the report, the campaign and the basic utilities:
//!   no model home, simulator, theory, command line or analysis.
//!
//! Test code (`#[cfg(test)]` modules, `tests.rs` files) is not part of the architecture and is
//! skipped; doc comments and comments are skipped. A path is resolved to the longest module
//! (file) it names, so `crate::store::cols::get_f64` is an arrow to `store::cols`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Module path ("campaign::plan", "" for the crate root) of a source file.
fn module_of(src: &Path, file: &Path) -> String {
    let rel = file.strip_prefix(src).expect("under src");
    let mut parts: Vec<String> = rel
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    let last = parts.pop().expect("file name");
    let stem = last.trim_end_matches(".rs");
    if stem != "mod" && stem != "lib" {
        parts.push(stem.to_string());
    }
    parts.join("::")
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).expect("readable src") {
        let p = e.expect("entry").path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The file's code without comments and without `#[cfg(test)]` items.
fn code_of(text: &str) -> String {
    let mut out = String::new();
    let mut skip_depth: Option<i64> = None;
    let mut depth = 0i64;
    let mut pending_cfg_test = false;
    for line in text.lines() {
        let code = match line.find("//") {
            Some(i) => &line[..i],
            None => line,
        };
        let trimmed = code.trim();
        if trimmed.starts_with("#[cfg(test)]") {
            pending_cfg_test = true;
            continue;
        }
        let opens = code.matches('{').count() as i64;
        let closes = code.matches('}').count() as i64;
        if pending_cfg_test && skip_depth.is_none() {
            pending_cfg_test = false;
            if trimmed.ends_with(';') {
                continue; // `mod tests;`: a file of its own, skipped as tests.rs
            }
            skip_depth = Some(depth);
        }
        depth += opens - closes;
        if let Some(d) = skip_depth {
            if depth <= d && (opens > 0 || closes > 0) {
                skip_depth = None;
            }
            continue;
        }
        out.push_str(code);
        out.push('\n');
    }
    out
}

/// Expand a use tree (`a::{b, c::{d, self}}`) into full paths.
fn expand_tree(prefix: &str, tree: &str, out: &mut Vec<String>) {
    let tree = tree.trim();
    if let Some(open) = tree.find('{') {
        let head = tree[..open].trim().trim_end_matches("::");
        let inner = &tree[open + 1..tree.rfind('}').unwrap_or(tree.len())];
        let base = join(prefix, head);
        let mut level = 0;
        let mut start = 0;
        for (i, ch) in inner.char_indices() {
            match ch {
                '{' => level += 1,
                '}' => level -= 1,
                ',' if level == 0 => {
                    expand_tree(&base, &inner[start..i], out);
                    start = i + 1;
                }
                _ => {}
            }
        }
        expand_tree(&base, &inner[start..], out);
    } else {
        let item = tree.split(" as ").next().unwrap_or("").trim();
        if item.is_empty() {
            return;
        }
        if item == "self" {
            out.push(prefix.to_string());
        } else {
            out.push(join(prefix, item));
        }
    }
}

fn join(a: &str, b: &str) -> String {
    match (a.is_empty(), b.is_empty()) {
        (true, _) => b.to_string(),
        (_, true) => a.to_string(),
        _ => format!("{a}::{b}"),
    }
}

/// Paths named by a file: `use` trees and inline `crate::` paths, `super::` resolved.
fn paths_of(module: &str, is_mod_file: bool, code: &str) -> Vec<String> {
    // `super` of a file module a::b is a; of a mod.rs module a it is a's parent.
    let parent = |m: &str| {
        m.rsplit_once("::")
            .map_or(String::new(), |x| x.0.to_string())
    };
    let here = module.to_string();
    let sup = parent(&here);
    let resolve = |p: &str| -> Option<String> {
        if let Some(rest) = p.strip_prefix("crate::") {
            Some(rest.to_string())
        } else if let Some(rest) = p.strip_prefix("super::") {
            let mut base = sup.clone();
            let mut rest = rest;
            while let Some(r) = rest.strip_prefix("super::") {
                base = parent(&base);
                rest = r;
            }
            Some(join(&base, rest))
        } else if let Some(rest) = p.strip_prefix("self::") {
            Some(join(&here, rest))
        } else {
            // A child module declared in this file (`use ledger::X` in a mod.rs).
            Some(join(&here, p)).filter(|_| is_mod_file || module.is_empty())
        }
    };
    let mut out = Vec::new();
    // use statements (may span lines): collect from `use ` to `;`.
    let flat = code.replace('\n', " ");
    for stmt in flat.split(';') {
        let s = stmt.trim();
        let s = s
            .strip_prefix("pub(crate) ")
            .or(s.strip_prefix("pub "))
            .unwrap_or(s);
        let Some(tree) = s.trim().strip_prefix("use ") else {
            // an item may follow a `}` on the same statement chunk
            if let Some(i) = s.rfind("use ") {
                let before = &s[..i];
                if before.trim_end().ends_with('}') || before.trim_end().ends_with('{') {
                    let mut v = Vec::new();
                    expand_tree("", &s[i + 4..], &mut v);
                    out.extend(v.iter().filter_map(|p| resolve(p)));
                }
            }
            continue;
        };
        let mut v = Vec::new();
        expand_tree("", tree, &mut v);
        out.extend(v.iter().filter_map(|p| resolve(p)));
    }
    // inline `crate::a::b` paths
    let bytes = flat.as_bytes();
    let mut i = 0;
    while let Some(j) = flat[i..].find("crate::") {
        let start = i + j;
        let ok_before =
            start == 0 || !(bytes[start - 1].is_ascii_alphanumeric() || bytes[start - 1] == b'_');
        let mut end = start + "crate::".len();
        while end < bytes.len()
            && (bytes[end].is_ascii_alphanumeric() || bytes[end] == b'_' || bytes[end] == b':')
        {
            end += 1;
        }
        if ok_before {
            out.push(
                flat[start + "crate::".len()..end]
                    .trim_end_matches(':')
                    .to_string(),
            );
        }
        i = end;
    }
    out
}

/// The longest module of `modules` that `path` names (or None for an external path).
fn target(path: &str, modules: &BTreeSet<String>) -> Option<String> {
    let parts: Vec<&str> = path.split("::").collect();
    for n in (1..=parts.len()).rev() {
        let m = parts[..n].join("::");
        if modules.contains(&m) {
            return Some(m);
        }
    }
    None
}

struct Graph {
    /// module -> modules it imports (files, not itself).
    edges: BTreeMap<String, BTreeSet<String>>,
}

fn graph() -> Graph {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let src = root.join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.retain(|f| {
        let name = f.file_name().unwrap().to_string_lossy();
        name != "tests.rs" && name != "main.rs"
    });
    let modules: BTreeSet<String> = files.iter().map(|f| module_of(&src, f)).collect();
    let mut edges = BTreeMap::new();
    for f in &files {
        let m = module_of(&src, f);
        let name = f.file_name().unwrap().to_string_lossy();
        let is_mod = name == "mod.rs" || name == "lib.rs";
        let text = std::fs::read_to_string(f).expect("readable");
        let mut to = BTreeSet::new();
        for p in paths_of(&m, is_mod, &code_of(&text)) {
            if let Some(t) = target(&p, &modules) {
                if t != m {
                    to.insert(t);
                }
            }
        }
        edges.insert(m, to);
    }
    Graph { edges }
}

/// Strongly connected components with more than one member (Tarjan).
fn circles(edges: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    struct T<'a> {
        e: &'a BTreeMap<String, BTreeSet<String>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on: BTreeSet<&'a str>,
        next: usize,
        out: Vec<Vec<String>>,
    }
    fn visit<'a>(t: &mut T<'a>, v: &'a str) {
        t.index.insert(v, t.next);
        t.low.insert(v, t.next);
        t.next += 1;
        t.stack.push(v);
        t.on.insert(v);
        if let Some(ws) = t.e.get(v) {
            for w in ws {
                let w = w.as_str();
                if !t.index.contains_key(w) {
                    visit(t, w);
                    let lw = t.low[w];
                    let lv = t.low[v];
                    t.low.insert(v, lv.min(lw));
                } else if t.on.contains(w) {
                    let iw = t.index[w];
                    let lv = t.low[v];
                    t.low.insert(v, lv.min(iw));
                }
            }
        }
        if t.low[v] == t.index[v] {
            let mut comp = Vec::new();
            while let Some(w) = t.stack.pop() {
                t.on.remove(w);
                comp.push(w.to_string());
                if w == v {
                    break;
                }
            }
            if comp.len() > 1 {
                comp.sort();
                t.out.push(comp);
            }
        }
    }
    let mut t = T {
        e: edges,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on: BTreeSet::new(),
        next: 0,
        out: Vec::new(),
    };
    for v in edges.keys() {
        if !t.index.contains_key(v.as_str()) {
            visit(&mut t, v);
        }
    }
    t.out
}

fn top(m: &str) -> &str {
    m.split("::").next().unwrap_or("")
}

/// The home of a model (`models::dsmc`), if `m` lies in one.
fn model_home(m: &str) -> Option<String> {
    let mut p = m.split("::");
    (p.next() == Some("models"))
        .then(|| p.next().filter(|x| !MODELS_SHARED.contains(x)))
        .flatten()
        .map(|x| format!("models::{x}"))
}

/// The parts of `models` that every model shares (split from the registry file, re-exported by
/// it): no model's home, and they import none.
const MODELS_SHARED: &[&str] = &["checks", "overlay", "rows", "view"];

/// Whether `m` is one of [`MODELS_SHARED`].
fn models_shared(m: &str) -> bool {
    let mut p = m.split("::");
    p.next() == Some("models") && p.next().is_some_and(|x| MODELS_SHARED.contains(&x))
}

/// Top-level modules that are not simulators; every other one is (`dsmc`, `rfm`,
/// `aux_models`, `physics`, and any new one: a new top-level module is held to the
/// simulators' rules unless it is added here).
const NOT_SIMULATORS: &[&str] = &[
    "",
    "cli",
    "campaign",
    "manifest",
    "models",
    "store",
    "plot",
    "report",
    "serve",
    "analysis",
    "theory",
    "derived",
    "math",
    "rng",
    "fsutil",
    "memory",
    "exit_codes",
];

/// Why the arrow `from -> to` is forbidden, if it is.
fn forbidden(from: &str, to: &str) -> Option<&'static str> {
    let (f, t) = (top(from), top(to));
    let sim = |x: &str| !NOT_SIMULATORS.contains(&x);
    if sim(f)
        && matches!(
            t,
            "manifest" | "store" | "campaign" | "models" | "cli" | "analysis" | "plot"
        )
    {
        return Some("a simulator imports no manifest, store, campaign, model home, CLI or figure");
    }
    if f == "theory" && !matches!(t, "theory" | "math") {
        return Some("theory imports nothing but theory and math");
    }
    if f == "derived" && !matches!(t, "derived" | "math") {
        return Some(
            "derived quantities are pure: derived imports nothing but itself and math (Arrow and \
             evalexpr from outside)",
        );
    }
    if f == "math" && t != "math" {
        return Some("math imports nothing but math");
    }
    if matches!(f, "rng" | "fsutil" | "memory" | "exit_codes") && t != f && !t.is_empty() {
        return Some("the basic utilities (rng, fsutil, memory, exit_codes) import no other layer");
    }
    if f == "store" && (sim(t) || matches!(t, "theory" | "models" | "manifest" | "campaign")) {
        return Some("store knows no physics, model, manifest or campaign");
    }
    if f == "campaign" && (sim(t) || t == "theory" || model_home(to).is_some()) {
        return Some("the campaign names no particular model or simulator");
    }
    if models_shared(from) && model_home(to).is_some() {
        return Some("the models' shared parts import no model's home");
    }
    if let Some(home) = model_home(from) {
        if model_home(to).is_some_and(|h| h != home) {
            return Some("a model's home imports no other model's home");
        }
        if matches!(t, "campaign" | "manifest" | "cli") {
            return Some("a model's home imports no campaign, manifest or CLI");
        }
    }
    if f == "analysis"
        && (sim(t)
            || matches!(
                t,
                "models" | "campaign" | "manifest" | "cli" | "report" | "serve"
            ))
    {
        return Some(
            "the analysis's shared part imports no model, campaign, manifest, CLI, report or \
             simulator: each model's analysis lives in its home",
        );
    }
    if f == "manifest" && (sim(t) || matches!(t, "campaign" | "store") || model_home(to).is_some())
    {
        return Some("the manifest imports only the list of models");
    }
    if f == "report"
        && (sim(t) || matches!(t, "theory" | "cli" | "analysis") || model_home(to).is_some())
    {
        return Some(
            "the report reads the campaign and draws with plot: no model home or simulator",
        );
    }
    if f == "serve"
        && (sim(t)
            || matches!(t, "theory" | "cli" | "analysis" | "models")
            || model_home(to).is_some())
    {
        return Some("the server shows the report and the campaign's files: no model or simulator");
    }
    if f == "plot" && t != "plot" {
        return Some("the renderer imports nothing of the crate");
    }
    None
}

#[test]
fn no_import_circles() {
    let g = graph();
    assert!(
        g.edges.len() > 50,
        "the source tree was not read ({} modules)",
        g.edges.len()
    );
    let files = circles(&g.edges);
    let mut tops: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (m, to) in &g.edges {
        let e = tops.entry(top(m).to_string()).or_default();
        for t in to {
            if top(t) != top(m) && !top(t).is_empty() {
                e.insert(top(t).to_string());
            }
        }
    }
    let modules = circles(&tops);
    assert!(
        files.is_empty() && modules.is_empty(),
        "import circles between files: {files:?}; between top-level modules: {modules:?}"
    );
}

#[test]
fn no_forbidden_arrows() {
    let g = graph();
    let mut bad = Vec::new();
    for (m, to) in &g.edges {
        for t in to {
            if let Some(why) = forbidden(m, t) {
                bad.push(format!("{m} -> {t}: {why}"));
            }
        }
    }
    assert!(bad.is_empty(), "forbidden arrows:\n{}", bad.join("\n"));
}

/// What in a file's code builds or runs a manifest check outside the one validation pass
/// (`manifest::check`: stages 1-2 in `manifest::validate`, 3 in `manifest::expand`): a `ManifestError` made
/// by hand, or a call of the pass's checks. Every manifest error is found in `src/manifest/`
/// (and in each model's `check`, which the pass calls through `ModelKind::params_from`).
fn validation_outside(code: &str) -> Vec<&'static str> {
    [
        "ManifestError {",
        "params_schema_errors(",
        "sweep_key_errors(",
        "size_errors(",
        "runs_errors(",
        "with_checks_beside(",
    ]
    .into_iter()
    .filter(|k| code.contains(k))
    .collect()
}

#[test]
fn validation_lives_in_one_place() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut bad = Vec::new();
    for f in &files {
        if f.starts_with(src.join("manifest")) {
            continue;
        }
        let text = std::fs::read_to_string(f).expect("readable source");
        for k in validation_outside(&code_of(&text)) {
            bad.push(format!("{}: {k}", f.display()));
        }
    }
    assert!(
        bad.is_empty(),
        "manifest checks outside the one validation pass (src/manifest/):\n{}",
        bad.join("\n")
    );
}

/// The checker itself: use trees, `super`, inline paths and test modules are read right, and a
/// planted circle and forbidden arrow are found.
#[test]
fn the_checker_sees_what_it_should() {
    let mut v = Vec::new();
    expand_tree(
        "",
        "crate::store::{cols::{self, get_f64}, Dataset as D}",
        &mut v,
    );
    assert_eq!(
        v,
        vec![
            "crate::store::cols",
            "crate::store::cols::get_f64",
            "crate::store::Dataset"
        ]
    );
    let code = code_of(
        "use super::ledger::Commit;\n// crate::cli::x\nfn f() { crate::plot::render(); }\n\
         #[cfg(test)]\nmod tests {\n    use crate::campaign::Campaign;\n}\nuse crate::math::fit;\n",
    );
    let p = paths_of("campaign::writer", false, &code);
    assert!(p.contains(&"campaign::ledger::Commit".to_string()), "{p:?}");
    assert!(p.contains(&"plot::render".to_string()), "{p:?}");
    assert!(p.contains(&"math::fit".to_string()), "{p:?}");
    assert!(
        !p.iter()
            .any(|x| x.starts_with("cli") || x.starts_with("campaign::Campaign")),
        "{p:?}"
    );
    let mut e: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    e.insert("a".into(), ["b".to_string()].into());
    e.insert("b".into(), ["c".to_string()].into());
    e.insert("c".into(), ["a".to_string()].into());
    assert_eq!(circles(&e), vec![vec!["a", "b", "c"]]);
    assert!(forbidden("dsmc::system", "models::dsmc::params").is_some());
    assert!(forbidden("store::dataset", "campaign").is_some());
    assert!(forbidden("campaign::writer", "models::rfm::tables").is_some());
    assert!(forbidden("campaign::writer", "models").is_none());
    assert!(forbidden("theory::hcs", "math::ode").is_none());
    assert!(forbidden("theory::hcs", "dsmc").is_some());
    assert!(forbidden("manifest::expand", "derived").is_none());
    assert!(forbidden("campaign::derived_tables", "derived").is_none());
    assert!(forbidden("derived", "store::dataset").is_some());
    assert!(forbidden("derived", "models").is_some());
    assert!(forbidden("derived::parse", "derived").is_none());
    assert!(forbidden("walk::sim", "store::dataset").is_some());
    assert!(forbidden("rng", "dsmc").is_some());
    assert!(forbidden("models::view", "models::rfm").is_some());
    assert!(forbidden("models::rfm", "models::view").is_none());
    assert!(model_home("models::checks").is_none());
    assert_eq!(
        model_home("models::rfm::analysis").as_deref(),
        Some("models::rfm")
    );
    assert!(forbidden("analysis", "models::rfm::params").is_some());
    assert!(forbidden("analysis", "models").is_some());
    assert!(forbidden("analysis", "campaign").is_some());
    assert!(forbidden("analysis", "math::fit").is_none());
    assert!(forbidden("models::rfm::analysis", "analysis").is_none());
    assert!(forbidden("models::rfm::analysis", "campaign::tables").is_some());
    assert!(forbidden("models::cascade::analysis", "models::rfm::analysis").is_some());
    assert_eq!(
        validation_outside("let e = ManifestError { path, message };"),
        vec!["ManifestError {"]
    );
    assert!(validation_outside(&code_of("// sweep_key_errors(p, s)\nfn f() {}\n")).is_empty());
}
