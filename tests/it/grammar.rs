//! One command grammar (docs/design.md, "The command grammar"): every subcommand of both
//! binaries names each concept the one way, and the old spellings of renamed flags still parse,
//! so that the commands recorded in results files and reports still run.

use crate::common;
use crate::common::cli::{self, Opt};

/// Names a concept had before it had one: the help of no command shows them.
const SECOND_NAMES: &[(&str, &str)] = &[
    ("--detector", "--detectors"),
    ("--rotation-period", "--period"),
    ("--angle-bins", "--sectors"),
    ("--print-profile", "--profile"),
    ("--page", "--paper"),
];

/// Positional arguments that name a config: `--config` names it on every command.
const CONFIG_POSITIONALS: &[&str] = &["CONFIG", "CONFIGS", "RECIPE"];

/// Old spellings that stay accepted, hidden: (binary, subcommand, arguments).
const OLD_SPELLINGS: &[(&str, &[&str], &[&str])] = &[
    ("pav-rig", &["evaluate"], &["--detector", "configs/detectors"]),
    ("pav-rig", &["evaluate"], &["--rotation-period", "28"]),
    ("pav-rig", &["evaluate"], &["--angle-bins", "8"]),
    ("pav-rig", &["bench"], &["--detector", "configs/detectors"]),
    ("pav", &["bench-step"], &["--detector", "configs/detectors/yolox_nano.toml"]),
    ("pav", &["eval-digital"], &["--print-profile", "printer.icc"]),
    ("pav", &["crossval"], &["--print-profile", "printer.icc"]),
    ("pav", &["print", "chart"], &["--page", "210x297"]),
    ("pav", &["print", "calibrate"], &["--reference", "values.csv"]),
    ("pav", &["views", "render"], &["configs/views/ci.toml"]),
    ("pav", &["views", "turntable"], &["configs/views/turntable.toml"]),
    ("pav", &["lofo"], &["a.toml", "b.toml"]),
    ("pav", &["adv-train"], &["configs/advtrain/yolox_nano.toml"]),
    ("pav-rig", &["model", "check"], &["my_detector.toml", "car.png"]),
];

/// Values every command that has the option must take: one spelling of a concept's value
/// works wherever the concept does.
const VALUES: &[(&str, &[&str])] =
    &[("--period", &["28s", "28"]), ("--scale", &["20", "1:20"]), ("--paper", &["a4", "210x297"])];

/// What one command's help breaks of the grammar, for the command `name`.
fn breaches(name: &str, help: &str) -> Vec<String> {
    let opts = cli::options(help);
    let mut out = Vec::new();
    let find = |long: &str| opts.iter().find(|o| o.long == long);
    for (second, one) in SECOND_NAMES {
        if find(second).is_some() {
            out.push(format!("{name}: {second} is the second name of {one}"));
        }
    }
    for (long, short) in [("--detectors", "-d"), ("--out", "-o")] {
        if let Some(Opt { short: s, .. }) = find(long) {
            if s.as_deref() != Some(short) {
                out.push(format!("{name}: {long} without {short}"));
            }
        }
    }
    for (long, meaning) in [("--reference", "texture"), ("--profile", "ICC")] {
        if let Some(o) = find(long).filter(|o| !o.text.contains(meaning)) {
            out.push(format!("{name}: {long} means something else than a {meaning} here: {}", o.text));
        }
    }
    for p in cli::positionals(help) {
        if CONFIG_POSITIONALS.contains(&p.as_str()) {
            out.push(format!("{name}: the config is a positional <{p}>, not --config"));
        }
    }
    out
}

#[test]
fn every_command_names_each_concept_one_way() {
    let mut seen = 0;
    let mut bad = Vec::new();
    for bin in ["pav", "pav-rig"] {
        for sub in cli::every_command(bin) {
            let help = cli::help(bin, &sub);
            let name = format!("{bin} {}", sub.join(" "));
            bad.extend(breaches(&name, &help));
            for (long, values) in VALUES {
                if cli::options(&help).iter().any(|o| o.long == *long) {
                    for v in *values {
                        if let Err(e) = cli::parses(bin, &sub, &[long, v]) {
                            bad.push(format!("{name} {long} {v}: {e}"));
                        }
                    }
                }
            }
            seen += 1;
        }
    }
    // Both binaries' commands, subcommands included: a walk that found few checked little.
    assert!(seen > 45, "only {seen} commands found");
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

#[test]
fn the_grammar_check_catches_a_second_name_a_bare_flag_and_a_positional_config() {
    let help = "Usage: x [OPTIONS] <CONFIG>\n\nArguments:\n  <CONFIG>  The config\n\nOptions:\n      \
                --detectors <D>  Detector configs\n      --page <P>  Page\n      --reference <R>  CIELAB values\n  \
                -h, --help  Print help\n";
    let found = breaches("x", help);
    for needle in ["--page is the second name", "--detectors without -d", "--reference means", "positional <CONFIG>"] {
        assert!(found.iter().any(|f| f.contains(needle)), "{needle} not caught: {found:?}");
    }
}

#[test]
fn every_old_spelling_still_parses() {
    let mut bad = Vec::new();
    for (bin, sub, args) in OLD_SPELLINGS {
        let sub: Vec<String> = sub.iter().map(|s| s.to_string()).collect();
        if let Err(e) = cli::parses(bin, &sub, args) {
            bad.push(format!("{bin} {} {}: {e}", sub.join(" "), args.join(" ")));
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
    // The check itself: a spelling no command ever had is refused.
    assert!(cli::parses("pav-rig", &["evaluate".into()], &["--angle-bin", "8"]).is_err());
}

/// Every command's help ends with examples, each a command line of that command which clap
/// takes as written (checked with `--help` in front of anything after `--`, so none runs).
#[test]
fn every_command_ends_its_help_with_examples_that_parse() {
    common::real_data(); // examples name `data:` entries
    let mut bad = Vec::new();
    let mut seen = 0;
    for bin in ["pav", "pav-rig"] {
        for sub in cli::every_command(bin).into_iter().filter(|s| !s.is_empty()) {
            let name = format!("{bin} {}", sub.join(" "));
            let examples = cli::examples(&cli::help(bin, &sub));
            if examples.is_empty() {
                bad.push(format!("{name}: no examples"));
            }
            for line in examples {
                let words = cli::words(&line);
                // An option before the subcommand (`turntable --port P status`) may sit between.
                let path: Vec<&String> = words.iter().skip(1).filter(|w| sub.contains(w)).collect();
                if words.first().map(String::as_str) != Some(bin) || path.len() < sub.len() {
                    bad.push(format!("{name}: the example `{line}` is not a `{name}` command"));
                    continue;
                }
                let args: Vec<&str> = words[1..].iter().map(String::as_str).collect();
                if let Err(e) = cli::parses(bin, &[], &args) {
                    bad.push(format!("{name}: `{line}`: {e}"));
                }
                seen += 1;
            }
        }
    }
    assert!(seen > 50, "only {seen} examples found");
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}
