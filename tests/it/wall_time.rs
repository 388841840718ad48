//! Every integration test that waits on wall time is listed in docs/testing.md ("Tests that wait
//! on wall time") with the reason a busy host does not fail it, and every test listed there
//! exists. A test waits on wall time when it, or a function of its own file that it calls, uses
//! one of [`MARKERS`]: the host clock, a sleep, a timed receive, a turntable or camera that runs
//! in real time, or a `pav-rig` capture or simulator.

use crate::common;
use std::collections::{BTreeMap, BTreeSet};

/// What makes a function wait on the host's clock.
const MARKERS: &[&str] = &[
    "Instant::now",
    "thread::sleep",
    "recv_timeout",
    "wait_for_sidecar_rows",
    "SimTurntable::spawn",
    "Turntable::open",
    "gst_test",
    "\"capture\"",
    "\"simulate\"",
    "\"--port\"",
];

/// The section of docs/testing.md that lists them.
const SECTION: &str = "## Tests that wait on wall time";

/// The functions of a test file (by [`common::functions`]): name, whether it is a `#[test]`,
/// and its text.
fn functions(src: &str) -> Vec<(String, bool, String)> {
    let lines: Vec<&str> = src.lines().collect();
    common::functions(src)
        .into_iter()
        .map(|(name, first, n)| {
            // Attributes and doc comments above the signature; `#[test]` is among them for a test.
            let above = lines[..first - 1].iter().rev().map(|l| l.trim());
            let is_test = above.take_while(|l| l.starts_with("#[") || l.starts_with("///")).any(|l| l == "#[test]");
            (name, is_test, lines[first - 1..first - 1 + n].join("\n"))
        })
        .collect()
}

/// The tests of one file that wait on wall time, directly or through the file's own functions.
fn timed_tests(src: &str) -> BTreeSet<String> {
    let fns = functions(src);
    let mut timed: BTreeSet<&str> =
        fns.iter().filter(|(_, _, body)| MARKERS.iter().any(|m| body.contains(m))).map(|f| f.0.as_str()).collect();
    loop {
        let calls = |body: &str, callee: &str| {
            body.match_indices(&format!("{callee}(")).any(|(at, _)| {
                body[..at].chars().next_back().is_none_or(|c| !(c.is_alphanumeric() || c == '_' || c == '.'))
            })
        };
        let more: Vec<&str> = fns
            .iter()
            .filter(|(name, _, body)| {
                !timed.contains(name.as_str())
                    && timed.iter().any(|t| calls(body.split_once('\n').map_or("", |b| b.1), t))
            })
            .map(|f| f.0.as_str())
            .collect();
        if more.is_empty() {
            break;
        }
        timed.extend(more);
    }
    fns.iter().filter(|(name, is_test, _)| *is_test && timed.contains(name.as_str())).map(|f| f.0.clone()).collect()
}

/// Every `module::test` named in backticks in the section.
fn listed(section: &str) -> BTreeSet<String> {
    section
        .split('`')
        .skip(1)
        .step_by(2)
        .filter(|s| {
            let mut parts = s.split("::");
            matches!((parts.next(), parts.next(), parts.next()), (Some(m), Some(t), None)
                if !m.is_empty() && !t.is_empty() && s.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_' || c == ':'))
        })
        .map(str::to_string)
        .collect()
}

#[test]
fn every_test_that_waits_on_wall_time_is_listed_with_its_reason() {
    let root = common::repo();
    let doc = std::fs::read_to_string(root.join("docs/testing.md")).unwrap();
    let at = doc.find(SECTION).unwrap_or_else(|| panic!("docs/testing.md has no section {SECTION:?}"));
    let section = &doc[at..];
    let section = &section[..section[SECTION.len()..].find("\n## ").map_or(section.len(), |e| e + SECTION.len())];
    let names = listed(section);

    let mut tests: BTreeMap<String, bool> = BTreeMap::new();
    for entry in std::fs::read_dir(root.join("tests/it")).unwrap() {
        let path = entry.unwrap().path();
        let module = path.file_stem().unwrap().to_string_lossy().to_string();
        if path.extension().is_none_or(|e| e != "rs") || ["main", "wall_time"].contains(&module.as_str()) {
            continue;
        }
        let src = std::fs::read_to_string(&path).unwrap();
        let timed = timed_tests(&src);
        for (name, is_test, _) in functions(&src) {
            if is_test {
                tests.insert(format!("{module}::{name}"), timed.contains(&name));
            }
        }
    }
    let unlisted: Vec<&String> =
        tests.iter().filter(|(n, timed)| **timed && !names.contains(*n)).map(|t| t.0).collect();
    assert!(
        unlisted.is_empty(),
        "these tests wait on wall time and docs/testing.md ({SECTION:?}) does not say why a busy host does not fail them: {unlisted:?}"
    );
    let unknown: Vec<&String> = names.iter().filter(|n| !tests.contains_key(*n)).collect();
    assert!(unknown.is_empty(), "docs/testing.md lists tests that tests/it does not have: {unknown:?}");
    assert!(tests.values().filter(|t| **t).count() >= 20, "the scan found too few timed tests to be reading the files");
}

#[test]
fn the_scan_follows_a_wait_into_the_helpers_a_test_calls() {
    let src = r#"
fn boot() -> u32 {
    std::thread::sleep(d);
    1
}

fn via_boot() {
    let _ = boot();
}

/// A test.
#[test]
fn waits_through_two_helpers() {
    via_boot();
}

fn one_liner() -> u32 { 3 }

#[test]
fn does_not_wait() {
    let reboot = 2;
    let _ = not_boot(reboot);
}

#[test]
#[ignore = "a reason"]
fn waits_itself() {
    let t = std::time::Instant::now();
}
"#;
    let timed = timed_tests(src);
    assert_eq!(timed.into_iter().collect::<Vec<_>>(), ["waits_itself", "waits_through_two_helpers"]);
    let doc = "| `a::b` | x |\n`not a name`, `c::d::e`, `e::f` and `Type::new` `ab_c::x1`";
    assert_eq!(listed(doc).into_iter().collect::<Vec<_>>(), ["a::b", "ab_c::x1", "e::f"]);
}
