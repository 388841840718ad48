//! One meaning per name: no public type, enum, trait or alias name is defined twice in the
//! workspace's crates and the firmware's protocol crate, so that a name read anywhere in the code
//! (or in an error, a doc, a test) means one thing. The few right exceptions are listed with why.

use crate::common;
use std::collections::BTreeMap;
use std::path::Path;

/// Names defined twice on purpose: (name, why).
const ALLOWED: &[(&str, &str)] = &[(
    "Frame",
    "firmware/proto's `Frame` is a serial frame on the wire and pav-core's an image; the protocol crate is no_std, \
     shared with the firmware, depends on nothing of pav, and no module uses both",
)];

/// Each public type name defined in `text` (`pub struct`, `pub enum`, `pub trait`, `pub type` at
/// the start of a line).
fn defined(text: &str) -> Vec<String> {
    text.lines()
        .filter_map(|l| {
            let l = l.trim_start();
            ["pub struct ", "pub enum ", "pub trait ", "pub type "]
                .iter()
                .find_map(|k| l.strip_prefix(k))
                .map(|rest| rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect::<String>())
        })
        .filter(|n| n.chars().next().is_some_and(char::is_uppercase))
        .collect()
}

/// Every public type name of the workspace's library sources → the files defining it.
fn names(repo: &Path) -> BTreeMap<String, Vec<String>> {
    let mut files = Vec::new();
    for e in std::fs::read_dir(repo.join("crates")).unwrap() {
        files.extend(common::files_with_extension(&e.unwrap().path().join("src"), "rs"));
    }
    files.extend(common::files_with_extension(&repo.join("firmware/proto/src"), "rs"));
    let mut out: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for f in files {
        let rel = f.strip_prefix(repo).unwrap().display().to_string();
        for n in defined(&std::fs::read_to_string(&f).unwrap()) {
            out.entry(n).or_default().push(rel.clone());
        }
    }
    out
}

#[test]
fn no_public_type_name_is_defined_twice() {
    let all = names(&common::repo());
    assert!(all.len() > 300 && all.contains_key("DetectorConfig") && all.contains_key("Command"), "{}", all.len());
    let twice: Vec<String> = all
        .iter()
        .filter(|(n, at)| at.len() > 1 && !ALLOWED.iter().any(|(a, _)| a == n))
        .map(|(n, at)| format!("{n}: {}", at.join(", ")))
        .collect();
    assert!(
        twice.is_empty(),
        "public type names defined more than once (rename one, or allow it here with why):\n{}",
        twice.join("\n")
    );
    // Every allowed name is still defined twice: an exception that no longer applies goes.
    for (n, _) in ALLOWED {
        assert!(all.get(*n).is_some_and(|at| at.len() > 1), "{n} is allowed twice but is not");
    }
}

/// The reader finds each kind of definition, and nothing in a comment or a private type.
#[test]
fn the_name_reader_finds_public_types_only() {
    let text = "pub struct A {\n  pub enum B<T> {\npub trait C: D {\npub type E = u8;\nstruct F;\n// pub struct G\npub fn h() {}\n";
    assert_eq!(defined(text), ["A", "B", "C", "E"]);
}
