//! What users look for first in a project: its licences, a citation file that validates against
//! the Citation File Format's schema, references that name every repository the data comes from,
//! and documentation whose relative links and heading anchors all resolve.

use crate::common;
use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};

/// The lines of `md` outside fenced code blocks (the fences themselves left out).
fn outside_fences(md: &str) -> impl Iterator<Item = &str> {
    let mut fence = false;
    md.lines().filter(move |line| {
        if line.trim_start().starts_with("```") {
            fence = !fence;
            return false;
        }
        !fence
    })
}

/// The lines of `md` outside fenced code blocks, with inline code spans blanked.
fn prose(md: &str) -> Vec<String> {
    let mut out = Vec::new();
    for line in outside_fences(md) {
        // A span opens and closes with the same run of backticks.
        let (mut s, mut rest) = (String::new(), line);
        while let Some(i) = rest.find('`') {
            s.push_str(&rest[..i]);
            let run = rest[i..].chars().take_while(|c| *c == '`').count();
            let after = &rest[i + run..];
            match after.find(&"`".repeat(run)) {
                Some(j) => rest = &after[j + run..],
                None => {
                    rest = after;
                    break;
                }
            }
        }
        s.push_str(rest);
        out.push(s);
    }
    out
}

/// GitHub's anchor for a heading: lower case, punctuation dropped, spaces as hyphens.
fn slug(heading: &str) -> String {
    let text: String = heading.replace('`', "");
    // Links keep their text only.
    let mut plain = String::new();
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        if c == ']' && chars.peek() == Some(&'(') {
            for d in chars.by_ref() {
                if d == ')' {
                    break;
                }
            }
        } else if c != '[' {
            plain.push(c);
        }
    }
    plain
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || *c == ' ' || *c == '-' || *c == '_')
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// Every anchor a Markdown file defines: its headings' slugs (repeats numbered as GitHub does)
/// and the `id`s of its `<a id="…">` tags.
fn anchors(md: &str) -> BTreeSet<String> {
    let mut seen: HashMap<String, usize> = HashMap::new();
    let mut out = BTreeSet::new();
    for line in outside_fences(md) {
        if let Some(h) = line.strip_prefix('#') {
            let base = slug(h.trim_start_matches('#'));
            let n = seen.entry(base.clone()).or_insert(0);
            out.insert(if *n == 0 { base.clone() } else { format!("{base}-{n}") });
            *n += 1;
        }
        let mut rest = line;
        while let Some(i) = rest.find("<a id=\"") {
            let after = &rest[i + 7..];
            let end = after.find('"').unwrap_or(after.len());
            out.insert(after[..end].to_string());
            rest = &after[end..];
        }
    }
    out
}

/// The targets of the inline links and images in `md`: `[text](target)`, `![alt](target)`.
fn links(md: &str) -> Vec<String> {
    let mut out = Vec::new();
    for line in prose(md) {
        let mut rest = line.as_str();
        while let Some(i) = rest.find("](") {
            let after = &rest[i + 2..];
            // Targets hold no spaces; a title after one is dropped.
            let end = after.find(')').unwrap_or(after.len());
            out.push(after[..end].split_whitespace().next().unwrap_or("").to_string());
            rest = &after[end..];
        }
    }
    out
}

/// Each broken relative link or anchor of the Markdown files under `root`, as `file: target`,
/// and every local path the links reach.
fn check_links(root: &Path) -> (Vec<String>, BTreeSet<PathBuf>) {
    let (mut broken, mut reached) = (Vec::new(), BTreeSet::new());
    let mut cache: HashMap<PathBuf, BTreeSet<String>> = HashMap::new();
    for file in common::doc_files(root) {
        let md = std::fs::read_to_string(&file).unwrap();
        let rel = file.strip_prefix(root).unwrap().display().to_string();
        for target in links(&md) {
            if target.contains("://") || target.starts_with("mailto:") || target.is_empty() {
                continue;
            }
            let (path, anchor) = target.split_once('#').unwrap_or((&target, ""));
            let dest = if path.is_empty() { file.clone() } else { file.parent().unwrap().join(path) };
            if !dest.exists() {
                broken.push(format!("{rel}: {target} (no such file)"));
                continue;
            }
            let dest = dest.canonicalize().unwrap();
            reached.insert(dest.clone());
            if anchor.is_empty() || dest.extension().is_none_or(|x| x != "md") {
                continue;
            }
            let known = cache.entry(dest.clone()).or_insert_with(|| anchors(&std::fs::read_to_string(&dest).unwrap()));
            if !known.contains(anchor) {
                broken.push(format!("{rel}: {target} (no such heading)"));
            }
        }
    }
    (broken, reached)
}

/// Copies `from` (a file or a folder) to `to`.
fn copy(from: &Path, to: &Path) {
    if from.is_dir() {
        std::fs::create_dir_all(to).unwrap();
        for e in std::fs::read_dir(from).unwrap().flatten() {
            copy(&e.path(), &to.join(e.file_name()));
        }
    } else {
        std::fs::create_dir_all(to.parent().unwrap()).unwrap();
        std::fs::copy(from, to).unwrap();
    }
}

#[test]
fn every_relative_link_and_heading_anchor_resolves() {
    let root = common::repo().canonicalize().unwrap();
    let (broken, reached) = check_links(&root);
    assert!(broken.is_empty(), "broken links:\n  {}", broken.join("\n  "));
    // The reader sees the links that must be there.
    for must in ["docs/references.md", "docs/method.md", "LICENSE-MIT", "CITATION.cff", "docs/quickstart_polar.png"] {
        assert!(reached.contains(&root.join(must)), "no link to {must} found: the link reader is broken");
    }
    assert!(reached.len() > 30, "only {} link targets found", reached.len());
}

#[test]
fn a_link_broken_on_purpose_is_caught() {
    let root = common::repo().canonicalize().unwrap();
    let (_, reached) = check_links(&root);
    // A copy of the documents and everything they link to checks clean before it is broken.
    let tmp = tempfile::tempdir().unwrap();
    let copy_root = tmp.path();
    for f in common::doc_files(&root).iter().chain(&reached) {
        copy(f, &copy_root.join(f.strip_prefix(&root).unwrap()));
    }
    assert!(check_links(copy_root).0.is_empty(), "the copy should check clean: {:?}", check_links(copy_root).0);
    let readme = copy_root.join("README.md");
    let text = std::fs::read_to_string(&readme).unwrap();
    let text = text.replacen("(docs/references.md)", "(docs/referencs.md)", 1);
    let text = text.replacen("(docs/method.md#glossary)", "(docs/method.md#glossry)", 1);
    std::fs::write(&readme, text).unwrap();
    let (broken, _) = check_links(copy_root);
    assert_eq!(
        broken,
        [
            "README.md: docs/referencs.md (no such file)".to_string(),
            "README.md: docs/method.md#glossry (no such heading)".to_string()
        ]
    );
}

#[test]
fn headings_give_githubs_anchors() {
    assert_eq!(slug(" The rig (`pav-rig`)"), "the-rig-pav-rig");
    assert_eq!(slug(" Quick start: from texture to A_physical"), "quick-start-from-texture-to-a_physical");
    assert_eq!(slug(" [PAV-Camou](x.md) and P@0.5"), "pav-camou-and-p05");
    let a = anchors("# A\n## A\n```\n# not a heading\n```\n- <a id=\"white-box\"></a>**white box**\n");
    assert_eq!(a.into_iter().collect::<Vec<_>>(), ["a", "a-1", "white-box"]);
    assert_eq!(links("see [x](a.md#b) and `[y](no.md)` and ![i](p.png \"t\")"), ["a.md#b", "p.png"]);
}

/// The `github:OWNER/REPO` sources of the manifest that `references` does not name.
fn unreferenced(manifest: &str, references: &str) -> Vec<String> {
    let repos: BTreeSet<String> = manifest
        .lines()
        .filter(|l| !l.starts_with('#'))
        .filter_map(|l| l.split('\t').nth(3))
        .filter_map(|s| s.strip_prefix("github:"))
        .map(|s| s.split('@').next().unwrap_or(s).to_string())
        .collect();
    repos.into_iter().filter(|r| !references.contains(&format!("github.com/{r}"))).collect()
}

#[test]
fn the_references_name_every_repository_the_data_comes_from() {
    let repo = common::repo();
    let manifest = std::fs::read_to_string(repo.join("data/manifest.tsv")).unwrap();
    let references = std::fs::read_to_string(repo.join("docs/references.md")).unwrap();
    assert!(manifest.lines().filter(|l| l.contains("\tgithub:")).count() > 50, "the manifest reader is broken");
    let missing = unreferenced(&manifest, &references);
    assert!(missing.is_empty(), "repositories in data/manifest.tsv missing from docs/references.md: {missing:?}");
    let fake = format!("{manifest}x\tabc\tMIT\tgithub:someone/elsewhere@0123:f.onnx\ta file\n");
    assert_eq!(unreferenced(&fake, &references), ["someone/elsewhere"]);
    // Every method the README names by its short name has an entry.
    for entry in ["pav-camou", "fca", "rauca-e2e", "das", "carla", "yolox", "deimv2", "nanodet", "pp-picodet", "yolov3"]
    {
        assert!(anchors(&references).contains(entry), "docs/references.md has no entry #{entry}");
    }
}

#[test]
fn the_licences_and_the_citation_file_are_valid() {
    let repo = common::repo();
    let read = |f: &str| std::fs::read_to_string(repo.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
    assert!(read("Cargo.toml").contains("license = \"MIT OR Apache-2.0\""));
    assert!(read("LICENSE-MIT").contains("Permission is hereby granted, free of charge"));
    let apache = read("LICENSE-APACHE");
    assert!(apache.contains("Apache License") && apache.contains("Version 2.0, January 2004"));
    assert!(apache.contains("END OF TERMS AND CONDITIONS"));
    let cffconvert = repo.join(".deps/venv/bin/cffconvert");
    assert!(cffconvert.exists(), "{} is missing: run scripts/setup.sh", cffconvert.display());
    let validate =
        |path: &Path| std::process::Command::new(&cffconvert).args(["--validate", "-i"]).arg(path).output().unwrap();
    let ok = validate(&repo.join("CITATION.cff"));
    assert!(ok.status.success(), "CITATION.cff: {}", common::output_text(&ok));
    assert!(String::from_utf8_lossy(&ok.stdout).contains("valid according to schema version 1.2.0"));
    // The check can fail: a copy without its authors is refused.
    let tmp = tempfile::tempdir().unwrap();
    let bad = tmp.path().join("CITATION.cff");
    let text = read("CITATION.cff");
    let without: Vec<&str> =
        text.lines().filter(|l| !l.starts_with("authors:") && !l.contains("the pav contributors")).collect();
    std::fs::write(&bad, without.join("\n")).unwrap();
    let refused = validate(&bad);
    assert!(!refused.status.success());
    assert!(common::output_text(&refused).contains("'authors' is a required property"));
}

#[test]
fn the_readme_has_what_users_look_for_first() {
    let readme = std::fs::read_to_string(common::repo().join("README.md")).unwrap();
    let headings = anchors(&readme);
    for h in ["prerequisites", "troubleshooting", "references"] {
        assert!(headings.contains(h), "README.md has no section #{h}");
    }
    // Prerequisites come before the set-up commands they are for.
    let (pre, cmd) = (readme.find("### Prerequisites").unwrap(), readme.find("bash scripts/setup.sh &&").unwrap());
    assert!(pre < cmd);
}
