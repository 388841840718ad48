//! Arguments both binaries parse alike: durations, configs, and the grouping of their
//! subcommands in the help.

/// A number of seconds written `28s` or `28`, finite and not zero.
pub fn seconds_value(s: &str) -> Result<f64, String> {
    let v: f64 = s.trim().trim_end_matches('s').parse().map_err(|_| format!("`{s}` is not a duration like 28s"))?;
    if v.is_finite() && v != 0.0 {
        Ok(v)
    } else {
        Err(format!("a period is a non-zero number of seconds, not {s}"))
    }
}

/// A positive duration like `28s` or `28`: `--period` wherever a turn's length is given.
pub fn parse_seconds(s: &str) -> Result<f64, String> {
    seconds_value(s).and_then(|v| if v > 0.0 { Ok(v) } else { Err(format!("a period is positive here, not {s}")) })
}

/// The config a command follows: `--config FILE`, or the first argument where a command took it
/// there before `--config` was everywhere (clap lets through exactly one of the two).
#[allow(dead_code)] // pav's commands only; pav-rig's `model check` sorts its arguments itself
pub fn config_path<'a>(
    flag: &'a Option<std::path::PathBuf>,
    positional: &'a Option<std::path::PathBuf>,
) -> &'a std::path::Path {
    flag.as_deref().or(positional.as_deref()).expect("clap requires --config or the positional config")
}

/// `cmd` with the subcommands of each `(heading, names)` group listed under that heading after
/// the user's jobs instead of among them (clap has one list of subcommands; these are hidden
/// from it and listed again, with their one-line help, below it). They run as before; a name
/// this build lacks (a feature left out) is skipped.
pub fn grouped(mut cmd: clap::Command, groups: &[(&str, &[&str])]) -> clap::Command {
    let mut text = String::new();
    for (heading, names) in groups {
        let names: Vec<&str> = names.iter().copied().filter(|n| cmd.find_subcommand(n).is_some()).collect();
        if names.is_empty() {
            continue;
        }
        let width = names.iter().map(|n| n.len()).max().unwrap_or(0);
        text.push_str(&format!("{heading}:\n"));
        for name in names {
            let about =
                cmd.find_subcommand(name).and_then(|s| s.get_about()).map(|a| a.to_string()).unwrap_or_default();
            text.push_str(&format!("  {name:width$}  {about}\n"));
            cmd = cmd.mut_subcommand(name, |s| s.hide(true));
        }
        text.push('\n');
    }
    cmd.after_help(text.trim_end().to_string())
}
