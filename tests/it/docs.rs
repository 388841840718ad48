//! The documentation as a user reads it: every code fence in README.md and docs/ is closed, every
//! `pav` / `pav-rig` command in a shell block names a real subcommand and real options, and the
//! README's main job and quick start run as written and leave what they promise.

use crate::common;
use crate::common::cli::{self, help, subcommands, words};

use std::path::Path;
use std::process::{Command, Output};

/// A fenced code block: its info string, its first line's number, its text.
struct Block {
    info: String,
    line: usize,
    text: String,
}

/// The fenced blocks of `md`; an unclosed fence is an error naming its line.
fn blocks(md: &str) -> Result<Vec<Block>, String> {
    let mut out = Vec::new();
    let mut open: Option<(String, String, usize, String)> = None;
    for (i, line) in md.lines().enumerate() {
        let t = line.trim_start();
        match &mut open {
            None => {
                if let Some(info) = t.strip_prefix("```") {
                    let indent = line[..line.len() - t.len()].to_string();
                    open = Some((info.trim().to_string(), indent, i + 1, String::new()));
                }
            }
            Some((info, _, start, text)) => {
                if t.trim_end() == "```" {
                    out.push(Block { info: info.clone(), line: *start, text: std::mem::take(text) });
                    open = None;
                } else {
                    text.push_str(line);
                    text.push('\n');
                }
            }
        }
    }
    match open {
        Some((_, _, start, _)) => Err(format!("the fence opened on line {start} is never closed")),
        None => Ok(out),
    }
}

#[test]
fn every_fence_in_the_docs_is_closed() {
    let bad: Vec<String> = common::doc_files(&common::repo())
        .iter()
        .filter_map(|f| blocks(&std::fs::read_to_string(f).unwrap()).err().map(|e| format!("{}: {e}", f.display())))
        .collect();
    assert!(bad.is_empty(), "{}", bad.join("\n"));
    // The check itself: a file with an odd fence fails it.
    assert!(blocks("text\n```sh\npav data list\n").is_err());
    assert_eq!(blocks("```sh\na\n```\n```toml\nb = 1\n```\n").unwrap().len(), 2);
}

/// One `pav`/`pav-rig` invocation found in a shell block: binary, the words after it, where.
#[derive(Debug)]
struct Invocation {
    bin: &'static str,
    words: Vec<String>,
    at: String,
    /// Prose may name a command group (`pav views`) without a subcommand.
    partial: bool,
}

/// Whether a word names the pav or pav-rig binary (bare, or a build's path).
fn is_pav(x: &str) -> bool {
    let name = x.rsplit('/').next().unwrap_or(x);
    (name == "pav" || name == "pav-rig") && (x == name || x.contains("release/"))
}

/// The pav and pav-rig commands of every shell block of `md` (`file` names it in messages).
fn invocations(file: &str, md: &str) -> Vec<Invocation> {
    let mut out = Vec::new();
    for b in blocks(md).unwrap_or_default() {
        let lang = b.info.split_whitespace().next().unwrap_or("");
        if !matches!(lang, "sh" | "bash" | "console") {
            continue;
        }
        // Continuation lines joined, comments dropped.
        let joined = b.text.replace("\\\n", " ");
        for (k, line) in joined.lines().enumerate() {
            let line = line.split(" #").next().unwrap_or("");
            if line.trim_start().starts_with('#') {
                continue;
            }
            for seg in line.split(['|', ';', '&', '(', ')', '$']) {
                let w = words(seg);
                let Some(pos) = w.iter().enumerate().position(|(i, x)| {
                    // In command position: first, after variable assignments or a wrapper, or
                    // as cargo's `--bin` (so `[ $n = pav ]` is no command).
                    let placed =
                        w[..i].iter().all(|p| p.contains('=') || matches!(p.as_str(), "time" | "nohup" | "exec"))
                            || (i > 0 && w[i - 1] == "--bin");
                    placed && is_pav(x)
                }) else {
                    continue;
                };
                let bin = if w[pos].ends_with("pav-rig") { "pav-rig" } else { "pav" };
                let args = if pos > 0 && w[pos - 1] == "--bin" {
                    // `cargo run --release --bin pav-rig -- evaluate …`; a `cargo build` runs nothing.
                    match w.iter().position(|x| x == "--") {
                        Some(dd) => w[dd + 1..].to_vec(),
                        None => continue,
                    }
                } else {
                    w[pos + 1..].to_vec()
                };
                let at = format!("{file}:{}", b.line + k);
                // `pav cluster slurm … -- target/release/pav crossval …` wraps a second command.
                match args.iter().position(|x| x == "--").filter(|&dd| args.get(dd + 1).is_some_and(|x| is_pav(x))) {
                    Some(dd) => {
                        let inner = if args[dd + 1].ends_with("pav-rig") { "pav-rig" } else { "pav" };
                        out.push(Invocation { bin, words: args[..dd].to_vec(), at: at.clone(), partial: false });
                        out.push(Invocation { bin: inner, words: args[dd + 2..].to_vec(), at, partial: false });
                    }
                    None => out.push(Invocation { bin, words: args, at, partial: false }),
                }
            }
        }
    }
    out
}

/// Why `inv` does not match the binaries' options, if it does not.
fn check(inv: &Invocation, cache: &mut std::collections::HashMap<(String, Vec<String>), String>) -> Option<String> {
    let mut sub: Vec<String> = Vec::new();
    let mut get = |sub: &Vec<String>| {
        cache.entry((inv.bin.to_string(), sub.clone())).or_insert_with(|| help(inv.bin, sub)).clone()
    };
    let mut text = get(&sub);
    let mut rest = inv.words.as_slice();
    loop {
        let subs = subcommands(&text);
        if subs.is_empty() {
            break;
        }
        match rest.first() {
            // A listed subcommand, or one the help hides (`pav reference`) that still has help.
            Some(w)
                if subs.contains(w) || cli::parses(inv.bin, &[sub.clone(), vec![w.clone()]].concat(), &[]).is_ok() =>
            {
                sub.push(w.clone());
                rest = &rest[1..];
                text = get(&sub);
            }
            // An option of this level before the subcommand (`turntable --port P status`), and
            // its value when the help shows one.
            Some(w) if w.starts_with('-') && text.contains(&format!("{w} ")) => {
                let takes_value = text.contains(&format!("{w} <"));
                rest = &rest[if takes_value { 2 } else { 1 }.min(rest.len())..];
            }
            Some(w) if w.starts_with('-') && sub.is_empty() => break,
            Some(w) => return Some(format!("{}: `{} {w}` is not a subcommand ({})", inv.at, inv.bin, subs.join(", "))),
            None if inv.partial => break,
            None => return Some(format!("{}: `{}` needs a subcommand", inv.at, inv.bin)),
        }
    }
    for w in rest {
        let flag = w.split('=').next().unwrap_or(w);
        // A flag the help does not show may be an old spelling clap still takes.
        let known = if flag.starts_with("--") && flag.len() > 2 {
            text.contains(&format!("{flag} "))
                || text.contains(&format!("{flag}\n"))
                || text.contains(&format!("{flag},"))
                || cli::knows(inv.bin, &sub, flag)
        } else if flag.len() == 2
            && flag.starts_with('-')
            && flag != "--"
            && !flag[1..].starts_with(|c: char| c.is_ascii_digit())
        {
            text.contains(&format!("{flag},")) || text.contains(&format!("{flag} "))
        } else {
            true
        };
        if !known {
            return Some(format!("{}: `{} {}` has no option {flag}", inv.at, inv.bin, sub.join(" ")));
        }
    }
    None
}

/// The text of `md` outside its fenced blocks.
fn prose(md: &str) -> String {
    let mut out = String::new();
    let mut fenced = false;
    for line in md.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if !fenced {
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

/// The pav and pav-rig commands quoted inline in the prose of `md` (`` `pav …` ``, a span may
/// run over a line break), each with the prose line it starts on.
fn inline_invocations(file: &str, md: &str) -> Vec<Invocation> {
    let text = prose(md);
    let mut out = Vec::new();
    let mut at = 0;
    for (k, part) in text.split('`').enumerate() {
        let line = text[..at].matches('\n').count() + 1;
        at += part.len() + 1;
        if k % 2 == 0 {
            continue;
        }
        for seg in part.split("&&").flat_map(|s| s.split([';', '|'])) {
            let w = words(&seg.replace('\n', " "));
            // A bare `pav` names the binary, not a command.
            let Some(first) = w.first().filter(|x| is_pav(x) && w.len() > 1) else { continue };
            let bin = if first.ends_with("pav-rig") { "pav-rig" } else { "pav" };
            out.push(Invocation {
                bin,
                words: w[1..].to_vec(),
                at: format!("{file}: prose line {line}"),
                partial: true,
            });
        }
    }
    out
}

/// The pav and pav-rig commands of every "Made by" line of `md`: the commands results were made
/// with, each a whole command line.
fn made_by(file: &str, md: &str) -> Vec<Invocation> {
    let mut out = Vec::new();
    for line in md.lines().filter(|l| l.starts_with("*Made by `")) {
        let cmd = line["*Made by `".len()..].split('`').next().unwrap_or("");
        for seg in cmd.split("&&").flat_map(|s| s.split(';')) {
            let w = words(seg);
            let Some(first) = w.first().filter(|x| is_pav(x)) else { continue };
            let bin = if first.ends_with("pav-rig") { "pav-rig" } else { "pav" };
            out.push(Invocation {
                bin,
                words: w[1..].to_vec(),
                at: format!("{file}: `{}`", seg.trim()),
                partial: false,
            });
        }
    }
    out
}

/// Inline commands name real subcommands and options (old spellings included), and every command
/// a "Made by" line records is one clap takes whole, as it was run.
#[test]
fn every_inline_and_made_by_command_is_a_real_invocation() {
    common::real_data(); // recorded commands name `data:` entries
    let (mut inline, mut recorded) = (Vec::new(), Vec::new());
    for f in common::doc_files(&common::repo()) {
        let rel = f.strip_prefix(common::repo()).unwrap().display().to_string();
        let text = std::fs::read_to_string(&f).unwrap();
        inline.extend(inline_invocations(&rel, &text));
        recorded.extend(made_by(&rel, &text));
    }
    assert!(inline.len() > 100 && recorded.len() >= 8, "{} inline, {} recorded", inline.len(), recorded.len());
    let mut cache = std::collections::HashMap::new();
    let mut bad: Vec<String> = inline.iter().filter_map(|i| check(i, &mut cache)).collect();
    for inv in &recorded {
        let args: Vec<&str> = inv.words.iter().map(String::as_str).collect();
        if let Err(e) = cli::parses(inv.bin, &[], &args) {
            bad.push(format!("{}: {e}", inv.at));
        }
    }
    assert!(bad.is_empty(), "{} commands that are not real:\n{}", bad.len(), bad.join("\n"));
    // The checks themselves: a made-up flag inline and a made-up subcommand recorded are caught.
    let fake = inline_invocations("x", "Run `pav optimize --no-such-flag` first.\n");
    assert!(check(&fake[0], &mut cache).is_some_and(|e| e.contains("--no-such-flag")));
    let fake = made_by("x", "*Made by `pav optimise --config c.toml` at commit 0.*\n");
    assert!(cli::parses("pav", &[], &fake[0].words.iter().map(String::as_str).collect::<Vec<_>>()).is_err());
}

#[test]
fn every_documented_command_names_real_subcommands_and_options() {
    let mut all = Vec::new();
    for f in common::doc_files(&common::repo()) {
        let rel = f.strip_prefix(common::repo()).unwrap().display().to_string();
        all.extend(invocations(&rel, &std::fs::read_to_string(&f).unwrap()));
    }
    // The README alone documents dozens; a parser that found none would check nothing.
    assert!(all.len() > 40, "only {} commands found", all.len());
    let mut cache = std::collections::HashMap::new();
    let bad: Vec<String> = all.iter().filter_map(|i| check(i, &mut cache)).collect();
    assert!(bad.is_empty(), "{} stale commands:\n{}", bad.len(), bad.join("\n"));
    // The check itself: a made-up option and a made-up subcommand are caught.
    let fake = invocations("x", "```sh\npav optimize --config c.toml --no-such-flag\npav-rig evalute v.mp4\n```\n");
    assert_eq!(fake.len(), 2);
    assert!(check(&fake[0], &mut cache).is_some_and(|e| e.contains("--no-such-flag")));
    assert!(check(&fake[1], &mut cache).is_some_and(|e| e.contains("evalute")));
}

/// The README's shell blocks under `heading` that are meant to run (not `sh no-run`).
fn runnable(readme: &str, heading: &str) -> String {
    let start = readme.find(heading).unwrap_or_else(|| panic!("README has no `{heading}`"));
    let end = readme[start + heading.len()..].find("\n## ").map_or(readme.len(), |e| start + heading.len() + e);
    blocks(&readme[start..end])
        .unwrap()
        .into_iter()
        .filter(|b| b.info == "sh")
        .map(|b| b.text)
        .collect::<Vec<_>>()
        .join("\n")
}

/// A scratch folder that looks like the repository to a user's relative paths.
fn scratch() -> tempfile::TempDir {
    let tmp = tempfile::tempdir().unwrap();
    for d in ["configs", "fixtures", "data"] {
        std::os::unix::fs::symlink(common::repo().join(d), tmp.path().join(d)).unwrap();
    }
    tmp
}

fn run_script(dir: &Path, script: &str) -> Output {
    let bins = Path::new(env!("CARGO_BIN_EXE_pav")).parent().unwrap().to_path_buf();
    let path = format!("{}:{}", bins.display(), std::env::var("PATH").unwrap_or_default());
    Command::new("bash")
        .args(["-euo", "pipefail", "-c", script])
        .current_dir(dir)
        .env("PATH", path)
        .env("RUST_BACKTRACE", "0")
        .output()
        .unwrap()
}

/// summary.csv's rows as maps from column to value.
fn summary(path: &Path) -> Vec<std::collections::HashMap<String, String>> {
    let mut rd = csv::Reader::from_path(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let head = rd.headers().unwrap().clone();
    rd.records()
        .map(|r| head.iter().zip(r.unwrap().iter()).map(|(h, v)| (h.to_string(), v.to_string())).collect())
        .collect()
}

const DETECTORS: [&str; 4] = ["deimv2_atto_int8", "yolov3-tiny", "yolov8n_int8", "yolox_nano"];

/// Every detector has a row for `video` whose A_physical is a share.
fn assert_scored(rows: &[std::collections::HashMap<String, String>], video: &str, ctx: &str) {
    for d in DETECTORS {
        let r = rows
            .iter()
            .find(|r| r.get("video").is_some_and(|v| v == video) && r.get("detector").is_some_and(|x| x == d))
            .unwrap_or_else(|| panic!("no {video} row for {d}: {ctx}"));
        let a: f64 = r["a_physical"].parse().unwrap_or_else(|_| panic!("{r:?}"));
        assert!((0.0..=1.0).contains(&a), "{r:?}");
        assert!(r["frames"].parse::<usize>().unwrap() > 0, "{r:?}");
    }
}

/// The README's main job (the set-up command's second half) on the turntable fixture.
#[test]
fn the_main_job_scores_the_turntable_fixture() {
    common::real_data();
    let readme = std::fs::read_to_string(common::repo().join("README.md")).unwrap();
    let line = readme
        .lines()
        .find(|l| l.starts_with("bash scripts/setup.sh && cargo run"))
        .expect("the README's main-job command");
    let job = line.split_once("-- ").unwrap().1;
    let tmp = scratch();
    let o = run_script(tmp.path(), &format!("pav-rig {job}"));
    assert!(o.status.success(), "{}", common::output_text(&o));
    let out = tmp.path().join("out/evaluate");
    let video = Path::new(job.split_whitespace().nth(1).unwrap()).file_stem().unwrap().to_str().unwrap().to_string();
    assert_scored(&summary(&out.join("summary.csv")), &video, &common::output_text(&o));
    // The README's first figure and its table are this run's, as it writes them today. Another
    // CPU may move a score in its last digits, and a dot by a fraction of a pixel: the figure
    // must match pixel for pixel but for a few edge pixels (an older clip moves hundreds).
    let (fresh, shown) = (
        pav::image::Rgb::load(&out.join(format!("polar_{video}.png"))).unwrap(),
        pav::image::Rgb::load(&common::repo().join("docs/quickstart_polar.png")).unwrap(),
    );
    assert_eq!((fresh.width, fresh.height), (shown.width, shown.height));
    let differ = fresh
        .rgb
        .chunks(3)
        .zip(shown.rgb.chunks(3))
        .filter(|(a, b)| a.iter().zip(*b).any(|(x, y)| (x - y).abs() > 8.0 / 255.0))
        .count();
    eprintln!("main job figure: {differ} pixels differ from docs/quickstart_polar.png");
    assert!(
        differ * 1000 < fresh.width * fresh.height,
        "docs/quickstart_polar.png is not what the main job draws now ({differ} pixels differ): copy out/evaluate/polar_{video}.png over it"
    );
    let recorded = pav::results::ResultFile::load(&common::repo(), "main-job").unwrap();
    let run = pav::provenance::Run::read(&out.join("run.toml")).unwrap();
    let fresh = pav::results::ResultFile::from_run(
        &run,
        &out.join("summary.csv"),
        &recorded.shape(),
        &recorded.title,
        tmp.path(),
    )
    .unwrap();
    assert_eq!(fresh.rows, recorded.rows, "results/main-job.json is not what the main job gives now");
    assert_eq!(fresh.command, recorded.command);
}

/// The quick start, then printing and applying its texture, block by block as the README has
/// them, in a scratch folder.
#[test]
fn the_quick_start_runs_as_written() {
    common::real_data();
    let readme = std::fs::read_to_string(common::repo().join("README.md")).unwrap();
    let script = runnable(&readme, "## Quick start") + "\n" + &runnable(&readme, "## Print and apply");
    assert!(script.contains("pav optimize") && script.contains("pav-rig evaluate"), "{script}");
    let tmp = scratch();
    let o = run_script(tmp.path(), &script);
    assert!(o.status.success(), "{}", common::output_text(&o));
    let out = tmp.path().join("out");
    // What the README says each step leaves.
    for f in ["paper/texture.png", "paper/texture_print.png", "paper/preview.png", "paper/loss.png", "paper/run.toml"] {
        assert!(out.join(f).is_file(), "{f} missing: {}", common::output_text(&o));
    }
    assert!(out.join("digital/run.toml").is_file());
    for v in ["original", "camo"] {
        // A 7 s turn at 10 fps, every frame filmed in simulated time however busy the machine.
        assert!(common::decoded_frames(&out.join(format!("sim/{v}.mp4"))).unwrap() >= 70, "{v}");
        assert!(out.join(format!("sim/{v}.angles.csv")).is_file());
    }
    let eval = out.join("sim/eval");
    let rows = summary(&eval.join("summary.csv"));
    assert_scored(&rows, "original", &common::output_text(&o));
    assert_scored(&rows, "camouflaged", &common::output_text(&o));
    for f in ["summary.md", "accuracy.png", "polar_original.png", "polar_camouflaged.png"] {
        assert!(eval.join(f).is_file(), "{f} missing");
    }
    // The print step: the proof, a texture trained through the printer with its proof, both
    // scored as printed, and the chart with its layout and colours.
    for f in
        ["paper/proof.png", "paper-printed/texture_proof.png", "chart/chart.png", "chart/chart.toml", "chart/chart.csv"]
    {
        assert!(out.join(f).is_file(), "{f} missing: {}", common::output_text(&o));
    }
    let digital = std::fs::read_to_string(out.join("digital-printed/digital.md")).unwrap();
    assert!(digital.contains("paper-printed"), "{digital}");
    let record = std::fs::read_to_string(out.join("digital-printed/run.toml")).unwrap();
    assert!(record.contains("print = \"true\""), "{record}");
    // Print and apply: the pieces on A4 pages, where each goes, what to paint by hand.
    for f in [
        "pieces/pieces.pdf",
        "pieces/placement.pdf",
        "pieces/pages/page-1.png",
        "pieces/pieces.csv",
        "pieces/by_hand.csv",
        "pieces/run.toml",
    ] {
        assert!(out.join(f).is_file(), "{f} missing: {}", common::output_text(&o));
    }
}

/// docs/detectors.md's worked example of attacking a described detector, as written: its config
/// blocks saved under the names their first lines give, its shell blocks run in order.
#[test]
fn attacking_your_own_detector_runs_as_written() {
    common::real_data();
    let doc = std::fs::read_to_string(common::repo().join("docs/detectors.md")).unwrap();
    let start = doc.find("## Attacking your own detector").expect("the section");
    let end = doc[start + 3..].find("\n## ").map_or(doc.len(), |e| start + 3 + e);
    let tmp = scratch();
    let mut script = String::new();
    let mut files = Vec::new();
    for b in blocks(&doc[start..end]).unwrap() {
        match b.info.as_str() {
            "toml" => {
                let name = b.text.lines().next().and_then(|l| l.strip_prefix("# ")).expect("a file name on line one");
                std::fs::write(tmp.path().join(name), &b.text).unwrap();
                files.push(name.to_string());
            }
            "sh" => script.push_str(&b.text),
            other => panic!("a `{other}` block on line {}", b.line),
        }
    }
    assert_eq!(files, ["my_detector.toml", "my_attack.toml"]);
    let o = run_script(tmp.path(), &script);
    assert!(o.status.success(), "{}", common::output_text(&o));
    let text = common::output_text(&o);
    assert!(text.contains("best car"), "model check shows the car: {text}");
    let out = tmp.path().join("out/my_attack");
    let detectors = std::fs::read_to_string(out.join("loss_detectors.csv")).unwrap();
    assert!(detectors.lines().skip(1).all(|l| l.split(',').nth(1) == Some("my_detector")), "{detectors}");
    // The described detector's car score on the training views, before and after.
    let rows = summary(&out.join("scores.csv"));
    let train: Vec<_> = rows.iter().filter(|r| r["split"] == "train").collect();
    let mean = |k: &str| train.iter().map(|r| r[k].parse::<f64>().unwrap()).sum::<f64>() / train.len() as f64;
    let (before, after) = (mean("initial"), mean("optimized"));
    eprintln!("my_detector on {} training views: {before:.3} → {after:.3}", train.len());
    assert!(train.len() == 6 && after < 0.5 * before, "{before} → {after}");
}

/// The README is a manual a person reads in minutes: at most 300 lines, none over 300
/// characters, and its status is generated (the reference, the schema and the results live in
/// docs/).
#[test]
fn the_readme_is_a_short_manual() {
    let readme = std::fs::read_to_string(common::repo().join("README.md")).unwrap();
    let n = readme.lines().count();
    assert!(n <= 300, "README.md has {n} lines: move reference and results to docs/");
    let long: Vec<usize> =
        readme.lines().enumerate().filter(|(_, l)| l.chars().count() > 300).map(|(i, _)| i + 1).collect();
    assert!(long.is_empty(), "README.md lines over 300 characters: {long:?}");
    assert!(
        readme.contains("<!-- verdict:") && readme.contains("Nothing has been printed and filmed"),
        "the status box"
    );
}

/// docs/reference/ is what the binaries write of themselves: a page per command, no page
/// missing, stale or left over.
#[test]
fn the_reference_pages_are_what_the_binaries_write() {
    let tmp = tempfile::tempdir().unwrap();
    for bin in [common::pav(), common::pav_rig()] {
        let mut bin = bin;
        let o = bin.arg("reference").arg("-o").arg(tmp.path()).output().unwrap();
        assert!(o.status.success(), "{}", common::output_text(&o));
    }
    let names = |dir: &Path| {
        let mut v: Vec<String> =
            std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        v.sort();
        v
    };
    let shipped = common::repo().join("docs/reference");
    let fix = "run `target/release/pav reference && target/release/pav-rig reference` after `rm -r docs/reference`";
    assert_eq!(names(tmp.path()), names(&shipped), "{fix}");
    assert!(names(&shipped).len() > 50, "a page per command");
    for n in names(tmp.path()) {
        let (fresh, kept) =
            (std::fs::read_to_string(tmp.path().join(&n)).unwrap(), std::fs::read_to_string(shipped.join(&n)).unwrap());
        assert!(fresh == kept, "docs/reference/{n} is not what the binary writes now: {fix}");
    }
}

/// Reports are short papers: none runs past 400 lines (the history of how the work went stays in
/// git).
#[test]
fn every_report_is_400_lines_or_fewer() {
    let reports = common::files_with_extension(&common::repo().join("docs/reports"), "md");
    assert!(reports.len() >= 8, "{reports:?}");
    let long: Vec<String> = reports
        .iter()
        .map(|p| (p, std::fs::read_to_string(p).unwrap().lines().count()))
        .filter(|(_, n)| *n > 400)
        .map(|(p, n)| format!("{}: {n} lines", p.display()))
        .collect();
    assert!(long.is_empty(), "{long:?}");
}
