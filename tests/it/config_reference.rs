//! The config-key reference (docs/reference/config-*.md) against the configs the project ships:
//! every key of every config file is documented on its kind's page, under its table. The pages
//! are written from the config types (`pav reference`; docs.rs checks they are what the binary
//! writes now), so a key the loaders take that the types' schema does not show fails here.

use super::common;
use std::collections::{BTreeMap, BTreeSet};

/// A page's documented keys: table path (`""` for the top level, `output.boxes`, …) → keys.
type Keys = BTreeMap<String, BTreeSet<String>>;

/// The keys of a page, read from its headers (`` ## `[a.b]` ``, `` ## `[[a]]` with `kind = …` ``)
/// and the first column of the table under each.
fn documented(page: &str) -> Keys {
    let mut keys = Keys::new();
    let mut table = None;
    for line in page.lines() {
        if let Some(h) = line.strip_prefix("## ") {
            table = if h == "Top level" {
                Some(String::new())
            } else if h.starts_with('`') {
                let t =
                    h.trim_start_matches('`').split('`').next().unwrap_or("").trim_matches(|c| c == '[' || c == ']');
                // One form of a union: its header names the key that picks it.
                if let Some((_, tag)) = h.split_once(" with `") {
                    let tag = tag.split(" = ").next().unwrap_or("").to_string();
                    keys.entry(t.to_string()).or_default().insert(tag);
                }
                Some(t.to_string())
            } else {
                None
            };
        } else if let (Some(t), Some(row)) = (&table, line.strip_prefix("| `")) {
            let key = row.split('`').next().unwrap().to_string();
            keys.entry(t.clone()).or_default().insert(key);
        }
    }
    keys
}

/// Every (table path, key) of a TOML table, arrays of tables by their path.
fn used(prefix: &str, t: &toml::Table, out: &mut Vec<(String, String)>) {
    for (k, v) in t {
        out.push((prefix.to_string(), k.clone()));
        let path = if prefix.is_empty() { k.clone() } else { format!("{prefix}.{k}") };
        match v {
            toml::Value::Table(inner) => used(&path, inner, out),
            toml::Value::Array(items) => {
                for i in items {
                    if let toml::Value::Table(inner) = i {
                        used(&path, inner, out);
                    }
                }
            }
            _ => {}
        }
    }
}

/// The keys of `t` that `page` does not document (`extends` is every extensible kind's).
fn undocumented(t: &toml::Table, page: &Keys) -> Vec<String> {
    let mut all = Vec::new();
    used("", t, &mut all);
    all.into_iter()
        .filter(|(table, key)| !(table.is_empty() && key == "extends"))
        .filter(|(table, key)| !page.get(table).is_some_and(|k| k.contains(key)))
        .map(|(table, key)| if table.is_empty() { key } else { format!("{table}.{key}") })
        .collect()
}

#[test]
fn every_key_of_every_shipped_config_is_on_its_kinds_reference_page() {
    let repo = common::repo();
    let pages: BTreeMap<&str, Keys> = ["optimize", "scene", "views", "rig", "detector"]
        .into_iter()
        .map(|k| {
            let text = std::fs::read_to_string(repo.join(format!("docs/reference/config-{k}.md"))).unwrap();
            (k, documented(&text))
        })
        .collect();
    assert!(pages["detector"]["input"].contains("channels") && pages["optimize"]["white_box"].contains("detector"));
    // The folders that hold one kind; the others (studies) hold several, each file one of them.
    let kinds_of = |rel: &str| -> Vec<&str> {
        match rel.split('/').nth(1).unwrap_or("") {
            "detectors" | "detectors-wide" | "defences" => vec!["detector"],
            "scenes" => vec!["scene"],
            "rig" => vec!["rig"],
            "optimize" => vec!["optimize"],
            "views" => vec!["views", "rig"],
            _ => vec!["optimize", "views", "rig", "detector", "scene"],
        }
    };
    let files = common::files_with_extension(&repo.join("configs"), "toml");
    let (mut checked, mut wrong) = (0, Vec::new());
    for f in &files {
        let rel = f.strip_prefix(&repo).unwrap().to_string_lossy().into_owned();
        // Adversarial training's study configs are the study's own, not a user's job's.
        if rel.starts_with("configs/advtrain/") {
            continue;
        }
        let t: toml::Table = toml::from_str(&std::fs::read_to_string(f).unwrap()).unwrap();
        let misses: Vec<(&str, Vec<String>)> =
            kinds_of(&rel).into_iter().map(|k| (k, undocumented(&t, &pages[k]))).collect();
        if !misses.iter().any(|(_, m)| m.is_empty()) {
            let best = misses.iter().min_by_key(|(_, m)| m.len()).unwrap();
            wrong.push(format!("{rel}: not on config-{}.md: {:?}", best.0, best.1));
        }
        checked += 1;
    }
    assert!(checked > 100, "{checked} configs");
    assert!(wrong.is_empty(), "keys the reference does not document:\n{}", wrong.join("\n"));
}

/// The reader of the pages finds a key that is there and misses one that is not, at its table.
#[test]
fn a_key_outside_its_table_is_undocumented() {
    let page = documented("## Top level\n\n| key |\n|---|\n| `mesh` | x |\n\n## `[mesh]`\n\n| `obj` | string |\n\n## `[[white_box]]` with `kind = \"a\"`\n\n| `k` | integer |\n");
    let t: toml::Table =
        toml::from_str("extends = \"b.toml\"\nobj = 1\n[mesh]\nobj = \"x\"\nk = 2\n[[white_box]]\nk = 1\n").unwrap();
    assert_eq!(undocumented(&t, &page), vec!["mesh.k", "obj", "white_box"]);
    let t: toml::Table = toml::from_str("[[white_box]]\nkind = \"a\"\nk = 1\nq = 2\n").unwrap();
    assert_eq!(undocumented(&t, &page), vec!["white_box", "white_box.q"], "the tag is documented by its header");
}
