//! The library's layers (see `src/lib.rs`). The workspace's crates are the layers: a crate's
//! manifest may not name a pav crate of a higher layer, nor a job another job. The compiler keeps
//! the crates from forming a cycle; inside a crate it allows what this test refuses: every
//! `crate::`, `super::` and `pav_…::` path in the crates' sources (the binaries aside) is an edge
//! from one module to another, no module re-exports another top-level module's items, and
//! neither the top-level modules (pav-core's are the base layer's) nor the files form a cycle.

use crate::common;
use crate::common::{code_of, functions};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

const LAYERS: [&[&str]; 4] = [
    &[
        "onnx", "run", "stop", "colour", "durable", "extends", "path", "image", "video", "geometry", "rng", "sidecar",
        "step", "table", "plot", "progress",
    ],
    &["print", "render", "scene", "dataset", "detect", "uv"],
    &["attack", "eval", "rig"],
    &["studies", "results", "cluster", "doctor", "reference"],
];
/// Layer whose modules must not use each other.
const JOBS: usize = 2;

type Module = Vec<String>;

/// One reference from the file of module `from` to the path `to`.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct Edge {
    from: Module,
    to: Module,
    reexport: bool,
}

fn layer(top: &str) -> Option<usize> {
    LAYERS.iter().position(|l| l.contains(&top))
}

/// The module a file under `src/` defines.
fn module_of(rel: &Path) -> Module {
    let mut m: Module = rel.with_extension("").iter().map(|s| s.to_string_lossy().into_owned()).collect();
    if m.last().is_some_and(|l| l == "mod" || l == "lib") {
        m.pop();
    }
    m
}

/// Drops `//` comments (doc comments included) so paths named in prose are not edges.
fn strip_comments(text: &str) -> String {
    text.lines().map(|l| l.find("//").map_or(l, |i| &l[..i])).collect::<Vec<_>>().join("\n")
}

/// Expands a use tree such as `crate::a::{b, c::{d, e}}` into its leaf paths.
fn expand(tree: &str) -> Vec<String> {
    let tree = tree.trim();
    let Some(open) = tree.find('{') else { return vec![tree.to_string()] };
    let prefix = &tree[..open];
    let inner = &tree[open + 1..tree.rfind('}').unwrap_or(tree.len())];
    let (mut parts, mut depth, mut start) = (Vec::new(), 0, 0);
    for (i, c) in inner.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(&inner[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&inner[start..]);
    parts.iter().filter(|p| !p.trim().is_empty()).flat_map(|p| expand(&format!("{prefix}{}", p.trim()))).collect()
}

/// Resolves `crate::…` / `super::…` / `pav_x::…` written in `module` of the crate whose root is
/// the module `root` to an absolute path; `in_tests` when it sits inside the file's inline
/// `mod tests`, where `super` is the file's own module.
fn resolve(path: &str, module: &Module, root: &Module, in_tests: bool) -> Option<Module> {
    let segs: Vec<&str> = path.split("::").map(str::trim).collect();
    let (mut base, rest) = match segs[0] {
        "crate" => (root.clone(), &segs[1..]),
        "pav_core" => (Vec::new(), &segs[1..]),
        s if s.starts_with("pav_") => (vec![s["pav_".len()..].to_string()], &segs[1..]),
        "super" => {
            let mut b = module.clone();
            if !in_tests {
                b.pop();
            }
            let mut r = &segs[1..];
            while r.first() == Some(&"super") {
                b.pop();
                r = &r[1..];
            }
            (b, r)
        }
        _ => return None,
    };
    for s in rest {
        let s = s.split(" as ").next().unwrap_or(s).trim();
        if s == "self" || s == "*" || s.is_empty() {
            continue;
        }
        base.push(s.to_string());
    }
    Some(base)
}

/// The module a crate's root stands for: pav-core's modules are top-level, pav-x's root is
/// module `x`, and pav's own root re-exports them all.
fn crate_root(name: &str) -> Module {
    match name.strip_prefix("pav-") {
        Some("core") | None => Vec::new(),
        Some(m) => vec![m.to_string()],
    }
}

/// Every edge in the files under each crate's `src`, with the set of modules that have a file.
fn edges(crates: &[(Module, std::path::PathBuf)]) -> (Vec<Edge>, BTreeSet<Module>) {
    let (mut out, mut modules) = (Vec::new(), BTreeSet::new());
    for (root, src) in crates {
        let (e, m) = crate_edges(root, src);
        out.extend(e);
        modules.extend(m);
    }
    (out, modules)
}

/// The edges of one crate whose root is module `root`.
fn crate_edges(root: &Module, src: &Path) -> (Vec<Edge>, BTreeSet<Module>) {
    // The binaries are not modules of the library.
    let files: Vec<PathBuf> =
        common::files_with_extension(src, "rs").into_iter().filter(|f| !f.starts_with(src.join("bin"))).collect();
    let module_at =
        |f: &Path| -> Module { root.iter().cloned().chain(module_of(f.strip_prefix(src).unwrap())).collect() };
    let modules: BTreeSet<Module> = files.iter().map(|f| module_at(f)).collect();
    let path_re = |text: &str| -> Vec<(usize, String)> {
        // Inline paths: `crate::a::b`, `super::x` or `pav_x::y` outside `use` statements.
        let mut out = Vec::new();
        let b = text.as_bytes();
        for key in ["crate::", "super::", "pav_"] {
            let mut at = 0;
            while let Some(i) = text[at..].find(key) {
                let s = at + i;
                at = s + key.len();
                if s > 0 && (b[s - 1].is_ascii_alphanumeric() || b[s - 1] == b'_' || b[s - 1] == b':') {
                    continue;
                }
                let end = text[s..]
                    .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == ':'))
                    .map_or(text.len(), |e| s + e);
                if key == "pav_" && !text[s..end].contains("::") {
                    continue; // a name such as `pav_version`, not a crate path
                }
                out.push((s, text[s..end].trim_end_matches(':').to_string()));
            }
        }
        out
    };
    let mut out = Vec::new();
    for f in &files {
        let module = module_at(f);
        let text = strip_comments(&std::fs::read_to_string(f).unwrap());
        let tests_at = text.find("mod tests {").unwrap_or(usize::MAX);
        let mut in_use = Vec::new();
        let mut at = 0;
        while let Some(i) = text[at..].find("use ") {
            let s = at + i;
            let end = s + text[s..].find(';').unwrap_or(text.len() - s);
            at = end;
            let word_start = s == 0 || !text.as_bytes()[s - 1].is_ascii_alphanumeric();
            let tree = text[s + 4..end].trim();
            if !word_start || !(tree.starts_with("crate") || tree.starts_with("super") || tree.starts_with("pav_")) {
                continue;
            }
            in_use.push(s..end);
            let reexport = text[..s].trim_end().ends_with("pub") || text[..s].trim_end().ends_with(')');
            for p in expand(tree) {
                if let Some(to) = resolve(&p, &module, root, s > tests_at) {
                    out.push(Edge { from: module.clone(), to, reexport });
                }
            }
        }
        for (pos, p) in path_re(&text) {
            if in_use.iter().any(|r| r.contains(&pos)) {
                continue;
            }
            if let Some(to) = resolve(&p, &module, root, pos > tests_at) {
                out.push(Edge { from: module.clone(), to, reexport: false });
            }
        }
    }
    (out, modules)
}

/// The longest prefix of `path` that is a module with a file.
fn file_module(path: &Module, modules: &BTreeSet<Module>) -> Module {
    (0..=path.len()).rev().map(|n| path[..n].to_vec()).find(|p| modules.contains(p)).unwrap_or_default()
}

fn cycle<N: Ord + Clone + std::fmt::Debug>(graph: &BTreeMap<N, BTreeSet<N>>) -> Option<Vec<N>> {
    fn visit<N: Ord + Clone>(
        n: &N,
        g: &BTreeMap<N, BTreeSet<N>>,
        state: &mut BTreeMap<N, u8>,
        path: &mut Vec<N>,
    ) -> Option<Vec<N>> {
        match state.get(n) {
            Some(2) => return None,
            Some(1) => {
                let i = path.iter().position(|p| p == n).unwrap();
                return Some(path[i..].to_vec());
            }
            _ => {}
        }
        state.insert(n.clone(), 1);
        path.push(n.clone());
        for m in g.get(n).into_iter().flatten() {
            if let Some(c) = visit(m, g, state, path) {
                return Some(c);
            }
        }
        path.pop();
        state.insert(n.clone(), 2);
        None
    }
    let mut state = BTreeMap::new();
    graph.keys().find_map(|n| visit(n, graph, &mut state, &mut Vec::new()))
}

/// Every broken rule, as a sentence.
fn violations(edges: &[Edge], modules: &BTreeSet<Module>) -> Vec<String> {
    let mut bad = BTreeSet::new();
    let mut tops: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let mut files: BTreeMap<Module, BTreeSet<Module>> = BTreeMap::new();
    for e in edges {
        let (Some(a), Some(b)) = (e.from.first(), e.to.first()) else { continue };
        let (from, to) = (e.from.join("::"), e.to.join("::"));
        match (layer(a), layer(b)) {
            (None, _) => {
                bad.insert(format!("`{a}` is in no layer: add it to src/lib.rs's table and tests/it/layers.rs"));
            }
            (_, None) => {
                bad.insert(format!("{from} uses `{b}`, which is in no layer"));
            }
            (Some(la), Some(lb)) if lb > la => {
                bad.insert(format!("{from} (layer {la}) uses {to} (layer {lb}): an edge up"));
            }
            (Some(la), Some(lb)) if la == JOBS && lb == JOBS && a != b => {
                bad.insert(format!("{from} uses {to}: one job uses another; combine them in studies"));
            }
            _ => {}
        }
        if a != b {
            if e.reexport {
                bad.insert(format!("{from} re-exports {to} from another module: use it from where it lives"));
            }
            tops.entry(a.clone()).or_default().insert(b.clone());
        }
        let (fa, fb) = (file_module(&e.from, modules), file_module(&e.to, modules));
        let related = fa.starts_with(&fb) || fb.starts_with(&fa);
        if !related {
            files.entry(fa).or_default().insert(fb);
        }
    }
    if let Some(c) = cycle(&tops) {
        bad.insert(format!("top-level modules form a cycle: {}", c.join(" → ")));
    }
    if let Some(c) = cycle(&files) {
        let names: Vec<String> = c.iter().map(|m| m.join("::")).collect();
        bad.insert(format!("files form a cycle: {}", names.join(" → ")));
    }
    bad.into_iter().collect()
}

/// The layer of a workspace crate: pav-core and pav-onnx are the base, pav-x sits where module
/// `x` does, and pav itself, the binaries, sits above them all.
fn crate_layer(name: &str) -> Option<usize> {
    match name {
        "pav" => Some(LAYERS.len()),
        "pav-core" => Some(0),
        _ => layer(name.strip_prefix("pav-")?),
    }
}

/// (crate, the pav crate its manifest's `[dependencies]` names) for each workspace manifest.
fn manifest_edges(repo: &Path) -> Vec<(String, String)> {
    let mut manifests = vec![repo.join("Cargo.toml")];
    for e in std::fs::read_dir(repo.join("crates")).unwrap().flatten() {
        manifests.push(e.path().join("Cargo.toml"));
    }
    let mut out = Vec::new();
    for m in manifests {
        let text = std::fs::read_to_string(&m).unwrap();
        let name = text
            .lines()
            .find_map(|l| l.strip_prefix("name = \""))
            .map(|n| n.trim_end_matches('"').to_string())
            .unwrap();
        let mut section = "";
        for l in text.lines().map(str::trim) {
            if l.starts_with('[') {
                section = l;
            } else if section == "[dependencies]" {
                let dep = l.split(['=', '.', ' ']).next().unwrap_or("");
                if dep.starts_with("pav-") || dep == "pav" {
                    out.push((name.clone(), dep.to_string()));
                }
            }
        }
    }
    out
}

/// Every manifest edge that goes up a layer or from one job to another.
fn manifest_violations(deps: &[(String, String)]) -> Vec<String> {
    let mut bad = Vec::new();
    for (a, b) in deps {
        match (crate_layer(a), crate_layer(b)) {
            (Some(la), Some(lb)) if lb > la => {
                bad.push(format!("{a} (layer {la}) depends on {b} (layer {lb}): an edge up"))
            }
            (Some(la), Some(lb)) if la == JOBS && lb == JOBS => {
                bad.push(format!("{a} depends on {b}: one job uses another; combine them in studies"))
            }
            (None, _) | (_, None) => bad.push(format!("{a} → {b}: a crate in no layer; add it to tests/it/layers.rs")),
            _ => {}
        }
    }
    bad
}

#[test]
fn the_crates_keep_their_layers() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let deps = manifest_edges(repo);
    let has = |a: &str, b: &str| deps.iter().any(|(x, y)| x == a && y == b);
    for (a, b) in [("pav-attack", "pav-render"), ("pav-studies", "pav-eval"), ("pav-rig", "pav-core")] {
        assert!(has(a, b), "no dependency {a} → {b} found: the manifest reader is broken");
    }
    let bad = manifest_violations(&deps);
    assert!(bad.is_empty(), "layer rules broken:\n  {}", bad.join("\n  "));
    let d = |a: &str, b: &str| (a.to_string(), b.to_string());
    assert!(manifest_violations(&[d("pav-render", "pav-attack")])[0].contains("an edge up"));
    assert!(manifest_violations(&[d("pav-eval", "pav-rig")])[0].contains("one job uses another"));
    assert!(manifest_violations(&[d("pav-scene", "pav-render")]).is_empty());
}

#[test]
fn the_library_keeps_its_layers() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut crates = vec![(Vec::new(), repo.join("src"))];
    for e in std::fs::read_dir(repo.join("crates")).unwrap().flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if name != "pav-onnx" {
            crates.push((crate_root(&name), e.path().join("src")));
        }
    }
    let (edges, modules) = edges(&crates);
    // The parser sees the edges that must exist, so an empty result means something.
    let has = |a: &str, b: &str| edges.iter().any(|e| e.from.first().is_some_and(|x| x == a) && e.to[0] == b);
    for (a, b) in [("attack", "render"), ("studies", "attack"), ("studies", "eval"), ("rig", "video")] {
        assert!(has(a, b), "no edge {a} → {b} found: the parser is broken");
    }
    assert!(edges.len() > 300, "only {} edges found", edges.len());
    let bad = violations(&edges, &modules);
    assert!(bad.is_empty(), "layer rules broken:\n  {}", bad.join("\n  "));
}

#[test]
fn each_rule_catches_its_breach() {
    let m = |s: &str| s.split("::").map(String::from).collect::<Module>();
    let modules: BTreeSet<Module> =
        ["render", "render::a", "attack", "attack::x", "eval", "eval::y", "image", "image::p", "image::q"]
            .iter()
            .map(|s| m(s))
            .collect();
    let e = |from: &str, to: &str, reexport| Edge { from: m(from), to: m(to), reexport };
    let rules = [
        (e("render::a", "attack::x::f", false), "an edge up"),
        (e("attack::x", "eval::y::g", false), "one job uses another"),
        (e("attack::x", "render::a::T", true), "re-exports"),
        (e("nowhere::z", "image::p", false), "in no layer"),
    ];
    for (edge, want) in rules {
        let v = violations(std::slice::from_ref(&edge), &modules);
        assert!(v.iter().any(|s| s.contains(want)), "{edge:?} gave {v:?}");
    }
    let ring = [e("image::p", "image::q::f", false), e("image::q", "image::p::g", false)];
    assert!(violations(&ring, &modules).iter().any(|s| s.contains("files form a cycle")));
    // A child using its parent's items, and a parent declaring its children, are not cycles.
    let family = [e("image::p", "image::Frame", false), e("image", "image::p::f", false)];
    assert!(violations(&family, &modules).is_empty());
    assert_eq!(expand("crate::a::{b, c::{d, e as f}}"), ["crate::a::b", "crate::a::c::d", "crate::a::c::e as f"]);
}

#[test]
fn src_holds_only_the_binaries_and_the_re_exports() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut entries: Vec<String> =
        std::fs::read_dir(&src).unwrap().flatten().map(|e| e.file_name().to_string_lossy().into_owned()).collect();
    entries.sort();
    assert_eq!(entries, ["bin", "lib.rs"], "src/ holds more than the binaries and lib.rs: move the logic to a crate");
    let lib = std::fs::read_to_string(src.join("lib.rs")).unwrap();
    let defined: Vec<String> = lib
        .lines()
        .map(code_of)
        .filter(|l| {
            ["fn ", "struct ", "enum ", "impl ", "mod ", "trait ", "static ", "const "].iter().any(|k| l.contains(k))
        })
        .collect();
    assert!(defined.is_empty(), "src/lib.rs defines more than re-exports: {defined:?}");
}

#[test]
fn binaries_are_thin_and_library_functions_short() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let fat: Vec<String> = common::files_with_extension(&repo.join("src/bin"), "rs")
        .iter()
        .map(|f| (f, std::fs::read_to_string(f).unwrap().lines().count()))
        .filter(|(_, n)| *n > 250)
        .map(|(f, n)| format!("{} ({n} lines)", f.strip_prefix(repo).unwrap().display()))
        .collect();
    assert!(fat.is_empty(), "binaries over 250 lines (clap and printing only; logic goes in the library): {fat:?}");
    let mut long = Vec::new();
    let mut seen = 0;
    for e in std::fs::read_dir(repo.join("crates")).unwrap().flatten() {
        for f in common::files_with_extension(&e.path().join("src"), "rs") {
            let text = std::fs::read_to_string(&f).unwrap();
            let fns = functions(&text);
            seen += fns.len();
            for (name, line, n) in fns.into_iter().filter(|f| f.2 > 200) {
                long.push(format!("{}:{line} {name} ({n} lines)", f.strip_prefix(repo).unwrap().display()));
            }
        }
    }
    assert!(seen > 1000, "only {seen} functions found: the reader is broken");
    assert!(long.is_empty(), "library functions over 200 lines (split them along their stages): {long:?}");
}

#[test]
fn the_function_reader_measures_bodies_and_skips_literals() {
    let body = "    let x = 1;\n".repeat(200);
    let text = format!("/// Doc.\npub(crate) fn long(a: &str) -> usize {{\n{body}    a.len()\n}}\n\nfn short() {{ let _ = \"{{\"; let _ = '}}'; }}\ntrait T {{\n    fn declared(&self);\n}}\n");
    let all = functions(&text);
    assert_eq!(all.iter().filter(|f| f.2 > 200).collect::<Vec<_>>(), [&("long".to_string(), 2, 203)]);
    assert_eq!(all.iter().map(|f| f.0.as_str()).collect::<Vec<_>>(), ["long", "short"], "{all:?}");
    assert_eq!(all[1].2, 1);
    assert_eq!(code_of("fn f<'a>(x: &'a str) { let c = '{'; } // }"), "fn f<'a>(x: &'a str) { let c = ; } ");
}

/// pav-attack reads a detector only through its description: its code (comments aside) names no
/// output layout and no model family.
#[test]
fn the_attack_names_no_detector_family() {
    let src = common::repo().join("crates/pav-attack/src");
    let files = common::files_with_extension(&src, "rs");
    assert!(files.len() > 10, "{} files under {}", files.len(), src.display());
    let mut found = Vec::new();
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        let code = text.split("#[cfg(test)]").next().unwrap_or_default();
        for (i, line) in code.lines().enumerate() {
            let line = line.split("//").next().unwrap_or_default().to_lowercase();
            for word in ["outputlayout", "darknet", "yolo", "ultralytics", "detr", "gfl", "nanodet", "picodet"] {
                if line.contains(word) {
                    found.push(format!("{}:{}: {word}", f.display(), i + 1));
                }
            }
        }
    }
    assert!(found.is_empty(), "per-family code in pav-attack:\n{}", found.join("\n"));
}
