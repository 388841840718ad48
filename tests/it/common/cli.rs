//! The binaries' command lines as clap shows them: each subcommand's help, its options and
//! arguments, and whether clap takes a flag it does not show (a hidden old spelling).

use std::process::Command;

/// The binary `bin` (`pav` or `pav-rig`).
pub fn bin_path(bin: &str) -> &'static str {
    match bin {
        "pav" => env!("CARGO_BIN_EXE_pav"),
        "pav-rig" => env!("CARGO_BIN_EXE_pav-rig"),
        other => panic!("no binary {other}"),
    }
}

/// `--help` of `bin` with the subcommand path `sub`.
pub fn help(bin: &str, sub: &[String]) -> String {
    let o = Command::new(bin_path(bin)).args(sub).arg("--help").env("RUST_BACKTRACE", "0").output().unwrap();
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The headings the binaries list subcommands under: the user's jobs first, then the project's
/// studies and tooling.
pub const SUBCOMMAND_HEADINGS: &[&str] = &["Commands:", "Jobs:", "Studies:", "Project tooling:"];

/// The subcommands a help text lists, under every heading (clap's own `help` left out).
pub fn subcommands(help: &str) -> Vec<String> {
    SUBCOMMAND_HEADINGS
        .iter()
        .flat_map(|h| section(help, h))
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .collect()
}

/// The example command lines a help text ends with (under `Examples:`).
pub fn examples(help: &str) -> Vec<String> {
    section(help, "Examples:").into_iter().map(|l| l.trim().to_string()).collect()
}

/// The lines of a help section that name an item (two spaces in, then the item).
fn section<'a>(help: &'a str, heading: &str) -> Vec<&'a str> {
    let Some(i) = help.find(&format!("{heading}\n")) else { return Vec::new() };
    help[i..]
        .lines()
        .skip(1)
        .take_while(|l| l.is_empty() || l.starts_with("  "))
        .filter(|l| l.starts_with("  ") && !l.starts_with("   ") && l.split_whitespace().next() != Some("help"))
        .collect()
}

/// One option as the help shows it.
#[derive(Clone, Debug, PartialEq)]
pub struct Opt {
    /// `--name`.
    pub long: String,
    /// `-x`, if it has one.
    pub short: Option<String>,
    /// Its value's name (`<DIR>`), if it takes one.
    pub value: Option<String>,
    /// Its help line(s), for a reader of the failure.
    pub text: String,
}

/// The options a help text lists, `--help` and `--version` left out.
pub fn options(help: &str) -> Vec<Opt> {
    let Some(i) = help.find("Options:\n") else { return Vec::new() };
    let lines: Vec<&str> = help[i..].lines().skip(1).collect();
    let mut out: Vec<Opt> = Vec::new();
    for l in lines {
        let t = l.trim_start();
        let indent = l.len() - t.len();
        if (2..=6).contains(&indent) && t.starts_with('-') {
            let mut words = t.split_whitespace();
            let mut short = None;
            let mut long = words.next().unwrap_or("").trim_end_matches(',').to_string();
            if !long.starts_with("--") {
                short = Some(long);
                long = words.next().unwrap_or("").to_string();
            }
            let value = words.next().filter(|w| w.starts_with('<')).map(str::to_string);
            let text = t.to_string();
            if long != "--help" && long != "--version" {
                out.push(Opt { long, short, value, text });
            }
        } else if let Some(last) = out.last_mut() {
            last.text.push(' ');
            last.text.push_str(t);
        }
    }
    out
}

/// The positional arguments a help text lists (`<VIDEOS>...` as `VIDEOS`).
pub fn positionals(help: &str) -> Vec<String> {
    section(help, "Arguments:")
        .into_iter()
        .filter_map(|l| l.split_whitespace().next())
        .map(|w| w.trim_start_matches(['<', '[']).split(['>', ']']).next().unwrap_or("").to_string())
        .collect()
}

/// Every subcommand path of `bin`, parents before children, leaves included.
pub fn every_command(bin: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let mut todo = vec![Vec::new()];
    while let Some(sub) = todo.pop() {
        for s in subcommands(&help(bin, &sub)).into_iter().rev() {
            let mut child = sub.clone();
            child.push(s);
            todo.push(child);
        }
        out.push(sub);
    }
    out
}

/// Whether clap takes `args` on `bin sub…` up to the point of help: every flag known (shown or a
/// hidden old spelling) and every value it parses accepted. `--help` ends the options (before a
/// bare `--`, whose words are another command's), so arguments a command requires may be left
/// out and nothing runs.
pub fn parses(bin: &str, sub: &[String], args: &[&str]) -> Result<(), String> {
    let cut = args.iter().position(|a| *a == "--").unwrap_or(args.len());
    let o = Command::new(bin_path(bin))
        .args(sub)
        .args(&args[..cut])
        .arg("--help")
        .args(&args[cut..])
        .env("RUST_BACKTRACE", "0")
        .output()
        .unwrap();
    if o.status.success() {
        Ok(())
    } else {
        Err(String::from_utf8_lossy(&o.stderr).lines().next().unwrap_or("").to_string())
    }
}

/// Whether `bin sub…` knows the flag `flag` at all, shown or hidden.
pub fn knows(bin: &str, sub: &[String], flag: &str) -> bool {
    let o = Command::new(bin_path(bin)).args(sub).arg(flag).env("RUST_BACKTRACE", "0").output().unwrap();
    !String::from_utf8_lossy(&o.stderr).contains(&format!("unexpected argument '{flag}'"))
}

/// Splits a shell line into words, keeping quoted strings whole (quotes dropped).
pub fn words(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut quote = None;
    let mut any = false;
    for ch in line.chars() {
        match (quote, ch) {
            (None, '"' | '\'') => {
                quote = Some(ch);
                any = true;
            }
            (Some(q), c) if c == q => quote = None,
            (None, c) if c.is_whitespace() => {
                if any {
                    out.push(std::mem::take(&mut cur));
                }
                any = false;
            }
            (_, c) => {
                cur.push(c);
                any = true;
            }
        }
    }
    if any {
        out.push(cur);
    }
    out
}
