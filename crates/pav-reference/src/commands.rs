//! The reference pages of a binary's commands, written from its clap definition, so that the
//! pages cannot drift from what the binary takes: one Markdown page per command with its
//! synopsis, arguments, options and their defaults, examples and the commands beside it.

use std::fmt::Write as _;
use std::path::Path;

/// The page file of the command at `path` (`["pav", "views", "render"]` → `pav-views-render.md`).
fn file(path: &[String]) -> String {
    format!("{}.md", path.join("-"))
}

/// One line of help text, its line breaks joined (a table cell holds one line).
fn cell(text: &str) -> String {
    // `<out>` in a help text is a placeholder, not an HTML tag; inside a code span it shows as is.
    let line = text.split_whitespace().collect::<Vec<_>>().join(" ").replace('|', "\\|");
    line.split('`')
        .enumerate()
        .map(|(k, part)| if k % 2 == 0 { part.replace('<', "&lt;").replace('>', "&gt;") } else { part.to_string() })
        .collect::<Vec<_>>()
        .join("`")
}

/// The examples a command's help ends with (after `Examples:`).
fn examples(cmd: &clap::Command) -> Vec<String> {
    let after = cmd.get_after_help().map(|a| a.to_string()).unwrap_or_default();
    match after.split_once("Examples:\n") {
        Some((_, ex)) => ex.lines().map(|l| l.trim().to_string()).filter(|l| !l.is_empty()).collect(),
        None => Vec::new(),
    }
}

/// The commands under `cmd` that get a page: all but clap's `help` and this generator, those
/// listed under a heading of their own in the help (studies, tooling) included.
fn listed(cmd: &clap::Command) -> Vec<String> {
    cmd.get_subcommands().map(|s| s.get_name().to_string()).filter(|n| n != "help" && n != "reference").collect()
}

/// An argument as the synopsis shows it: `-o, --out <OUT>` or `<VIDEOS>...`.
fn shown(a: &clap::Arg) -> String {
    let value = a
        .get_value_names()
        .map(|v| v.iter().map(|n| format!("<{n}>")).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|| format!("<{}>", a.get_id().as_str().to_uppercase()));
    if a.is_positional() {
        return value;
    }
    let mut s = String::new();
    if let Some(c) = a.get_short() {
        let _ = write!(s, "-{c}, ");
    }
    if let Some(l) = a.get_long() {
        let _ = write!(s, "--{l}");
    }
    if a.get_action().takes_values() {
        let _ = write!(s, " {value}");
    }
    s
}

/// The page of `cmd`, reached by `path`; `siblings` are the other commands under its parent.
fn page(cmd: &mut clap::Command, path: &[String], siblings: &[String]) -> String {
    let mut md = format!("# {}\n\n", path.join(" "));
    let about = cmd.get_long_about().or(cmd.get_about()).map(|a| a.to_string()).unwrap_or_default();
    let _ = writeln!(md, "{}\n", about.trim());
    let usage = cmd.render_usage().to_string();
    let usage = usage.trim_start_matches("Usage:").trim();
    let _ = writeln!(md, "```text\n{usage}\n```\n");
    let subs = listed(cmd);
    if !subs.is_empty() {
        let _ = writeln!(md, "## Commands\n\n| command | what it does |\n|---|---|");
        for name in subs {
            let s = cmd.find_subcommand(&name).expect("a listed subcommand");
            let mut p = path.to_vec();
            p.push(name.clone());
            let about = s.get_about().map(|a| a.to_string()).unwrap_or_default();
            let _ = writeln!(md, "| [`{}`]({}) | {} |", p.join(" "), file(&p), cell(&about));
        }
        md.push('\n');
    }
    let args: Vec<&clap::Arg> = cmd
        .get_arguments()
        .filter(|a| !a.is_hide_set() && !matches!(a.get_id().as_str(), "help" | "version"))
        .collect();
    for (title, positional) in [("Arguments", true), ("Options", false)] {
        let these: Vec<&&clap::Arg> = args.iter().filter(|a| a.is_positional() == positional).collect();
        if these.is_empty() {
            continue;
        }
        let _ = writeln!(md, "## {title}\n\n| | default | meaning |\n|---|---|---|");
        for a in these {
            let help = a.get_long_help().or(a.get_help()).map(|h| h.to_string()).unwrap_or_default();
            let default: Vec<String> =
                a.get_default_values().iter().map(|v| v.to_string_lossy().into_owned()).collect();
            // A switch's `false` is no default worth a cell.
            let default = if default.is_empty() || !a.get_action().takes_values() {
                String::new()
            } else {
                format!("`{}`", default.join(","))
            };
            let required = if a.is_required_set() { " (required)" } else { "" };
            let _ = writeln!(md, "| `{}`{required} | {default} | {} |", shown(a), cell(&help));
        }
        md.push('\n');
    }
    let ex = examples(cmd);
    if !ex.is_empty() {
        let _ = writeln!(md, "## Examples\n\n```sh\n{}\n```\n", ex.join("\n"));
    }
    if !siblings.is_empty() {
        let links: Vec<String> = siblings
            .iter()
            .map(|s| {
                let mut p = path[..path.len() - 1].to_vec();
                p.push(s.clone());
                format!("[`{}`]({})", p.join(" "), file(&p))
            })
            .collect();
        let parent = &path[..path.len() - 1];
        let _ = writeln!(md, "## See also\n\n[`{}`]({}) · {}", parent.join(" "), file(parent), links.join(" · "));
    }
    md.trim_end().to_string() + "\n"
}

/// Writes the page of `cmd` and of every command under it into `dir`; returns the files.
pub fn write(cmd: &mut clap::Command, dir: &Path) -> Result<Vec<String>, crate::ReferenceError> {
    std::fs::create_dir_all(dir).map_err(|source| crate::ReferenceError::Write { path: dir.to_path_buf(), source })?;
    cmd.build();
    let mut written = Vec::new();
    walk(cmd, &[cmd.get_name().to_string()], &[], dir, &mut written)?;
    Ok(written)
}

fn walk(
    cmd: &mut clap::Command,
    path: &[String],
    siblings: &[String],
    dir: &Path,
    out: &mut Vec<String>,
) -> Result<(), crate::ReferenceError> {
    let name = file(path);
    let at = dir.join(&name);
    std::fs::write(&at, page(cmd, path, siblings))
        .map_err(|source| crate::ReferenceError::Write { path: at, source })?;
    out.push(name);
    let names = listed(cmd);
    for n in &names {
        let others: Vec<String> = names.iter().filter(|o| *o != n).cloned().collect();
        let mut p = path.to_vec();
        p.push(n.clone());
        let sub = cmd.find_subcommand_mut(n).expect("a listed subcommand");
        walk(sub, &p, &others, dir, out)?;
    }
    Ok(())
}
