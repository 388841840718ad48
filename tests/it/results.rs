//! Results as data (`pav_core::results`): every results block in README.md and docs/ is what the
//! generator writes from results/ now; a number edited by hand fails that check, and a table
//! whose config changed (in its values, not its comments) is marked stale with the command that
//! reruns it.

use crate::common;

use pav::results::{documents, moved, regenerate, ResultFile, Shape, DIR};
use std::path::Path;

#[test]
fn every_results_block_is_what_the_generator_writes() {
    common::real_data();
    let root = common::repo();
    let differ = regenerate(&root, false).unwrap();
    let names: Vec<String> = differ.iter().map(|(p, _)| p.display().to_string()).collect();
    assert!(names.is_empty(), "run `pav results write`: these differ from results/: {names:?}");
    // Every results file is shown somewhere, and parses.
    let docs: String = documents(&root).iter().map(|p| std::fs::read_to_string(p).unwrap()).collect();
    let files = common::files_with_extension(&root.join(DIR), "json");
    assert!(!files.is_empty());
    for f in files {
        let name = f.file_stem().unwrap().to_string_lossy().into_owned();
        let r = ResultFile::load(&root, &name).unwrap();
        assert!(!r.rows.is_empty() && r.rows.iter().all(|row| row.len() == r.columns.len()), "{name}");
        assert!(docs.contains(&format!("<!-- results:{name} -->")), "results/{name}.json is shown nowhere");
    }
}

/// A copy of the repository's documents and results under a temporary root, with `configs`
/// copied (so that it can be changed) and the other inputs linked.
fn copy_root() -> tempfile::TempDir {
    let root = common::repo();
    let tmp = tempfile::tempdir().unwrap();
    for d in ["docs", DIR, "configs"] {
        copy_dir(&root.join(d), &tmp.path().join(d));
    }
    std::fs::copy(root.join("README.md"), tmp.path().join("README.md")).unwrap();
    for d in ["fixtures", ".deps", "data", "bench"] {
        std::os::unix::fs::symlink(root.join(d), tmp.path().join(d)).unwrap();
    }
    tmp
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap().flatten() {
        let (p, dest) = (e.path(), to.join(e.file_name()));
        if p.is_dir() {
            copy_dir(&p, &dest);
        } else {
            std::fs::copy(&p, &dest).unwrap();
        }
    }
}

#[test]
fn a_number_edited_by_hand_fails_the_check() {
    common::real_data();
    let tmp = copy_root();
    assert!(regenerate(tmp.path(), false).unwrap().is_empty(), "the copy matches before the edit");
    let readme = tmp.path().join("README.md");
    let text = std::fs::read_to_string(&readme).unwrap();
    let start = text.find("<!-- results:main-job -->").expect("the main job's table");
    // The first A_physical cell of the table, changed by one tenth.
    let row = start + text[start..].find("\n| ").unwrap() + 1;
    let row = row + text[row..].find('\n').unwrap() + 1; // past the heading
    let row = row + text[row..].find('\n').unwrap() + 1; // past the rule
    let line = &text[row..row + text[row..].find('\n').unwrap()];
    let edited = line.replacen(".", ",", 1).replacen(",", ".0", 1);
    assert_ne!(line, edited);
    std::fs::write(&readme, text.replacen(line, &edited, 1)).unwrap();
    let differ = regenerate(tmp.path(), false).unwrap();
    assert_eq!(differ.len(), 1, "{differ:?}");
    assert!(differ[0].0.ends_with("README.md") && differ[0].1.contains(line), "the generator writes the number back");
}

#[test]
fn a_changed_config_marks_its_table_stale() {
    common::real_data();
    let tmp = copy_root();
    let config = tmp.path().join("configs/detectors/yolox_nano.toml");
    let mut text = std::fs::read_to_string(&config).unwrap();
    // A comment is not a change of the config.
    text.push_str("# a note\n");
    std::fs::write(&config, &text).unwrap();
    assert!(regenerate(tmp.path(), false).unwrap().is_empty(), "a comment made the table stale");
    text.push_str("nms_iou = 0.6\n");
    std::fs::write(&config, text).unwrap();
    let differ = regenerate(tmp.path(), false).unwrap();
    let (doc, new) = differ.iter().find(|(p, _)| p.ends_with("README.md")).expect("the README's main-job table");
    let r = ResultFile::load(tmp.path(), "main-job").unwrap();
    assert!(
        new.contains(&format!("**Stale since commit {}**: configs/detectors/yolox_nano.toml changed", r.commit))
            && new.contains(&format!("Rerun `{}`", r.command)),
        "{}:\n{new}",
        doc.display()
    );
    // Written, the mark stays until the run is recorded again; the check then passes on it.
    regenerate(tmp.path(), true).unwrap();
    assert!(regenerate(tmp.path(), false).unwrap().is_empty());
}

/// A recipe frozen under another name while its old path takes another recipe: the tables its
/// runs made go stale, until `moved` records the new path, which it does only when the new file
/// holds the values the runs read.
#[test]
fn a_config_moved_unchanged_keeps_its_tables_fresh() {
    common::real_data();
    let tmp = copy_root();
    let (old, new) = ("configs/optimize/quick.toml", "configs/optimize/frozen.toml");
    let at = |p: &str| tmp.path().join(p);
    std::fs::copy(at(old), at(new)).unwrap();
    std::fs::write(at(old), "extends = \"frozen.toml\"\n[optimizer]\nlr = 0.02\n").unwrap();
    let arm = "configs/studies/lofo/without-yolox_nano.toml";
    let text = std::fs::read_to_string(at(arm)).unwrap();
    assert!(text.contains("../../optimize/quick.toml"), "the arm extends the recipe");
    std::fs::write(at(arm), text.replace("../../optimize/quick.toml", "../../optimize/frozen.toml")).unwrap();
    let lofo = || regenerate(tmp.path(), false).unwrap().into_iter().find(|(p, _)| p.ends_with("docs/reports/lofo.md"));
    let (_, stale) = lofo().expect("the move makes lofo.md's tables stale");
    assert!(stale.contains(&format!("{old} changed")) && stale.contains(&format!("{arm} changed")), "{stale}");

    // A frozen copy whose values differ is refused, naming the table, and nothing is written.
    std::fs::write(at(new), std::fs::read_to_string(at(new)).unwrap() + "[loss]\nbeta = 2.0\n").unwrap();
    let before = std::fs::read_to_string(at("results/lofo.json")).unwrap();
    let e = moved(tmp.path(), old, new).unwrap_err().to_string();
    assert!(e.contains(&format!("{new} is not {old}")) && e.starts_with("results/"), "{e}");
    assert_eq!(std::fs::read_to_string(at("results/lofo.json")).unwrap(), before);

    std::fs::copy(common::repo().join(old), at(new)).unwrap();
    // The other arms still extend the old path, which holds another recipe now: refused too.
    let e = moved(tmp.path(), old, new).unwrap_err().to_string();
    assert!(e.contains(&format!("still extends {old}")), "{e}");
    // Every config that extends the recipe, the scaled recipes beside it included.
    for f in common::files_with_extension(&at("configs"), "toml") {
        let text = std::fs::read_to_string(&f).unwrap();
        let text = text.replace("/optimize/quick.toml\"", "/optimize/frozen.toml\"");
        std::fs::write(&f, text.replace("extends = \"quick.toml\"", "extends = \"frozen.toml\"")).unwrap();
    }
    let changed = moved(tmp.path(), old, new).unwrap();
    let lofo_json = changed.iter().find(|(n, _)| n == "lofo").expect("results/lofo.json read the recipe");
    assert!(lofo_json.1.contains(&format!("{arm} extends {new}")), "{lofo_json:?}");
    regenerate(tmp.path(), true).unwrap();
    for d in documents(tmp.path()) {
        let t = std::fs::read_to_string(&d).unwrap();
        assert!(!t.contains(&format!("{old} changed")) && !t.contains(&format!("{arm} changed")), "{}", d.display());
    }
    // A cell that named the recipe names it where it is now.
    let transfer = ResultFile::load(tmp.path(), "transfer").unwrap();
    assert!(transfer.rows.iter().flatten().any(|c| c.contains(new)) && !transfer.inputs.contains_key(old));
}

/// A benchmark's table is its committed CSV made wide (one column per tool, the fastest of the
/// repeated rounds) with ratios between columns; taken again from the CSV it gives the recorded
/// rows, and a rerun that rewrites the CSV marks it stale.
#[test]
fn a_benchmark_table_is_its_csv_pivoted_and_goes_stale_with_it() {
    common::real_data();
    let root = common::repo();
    let recorded = ResultFile::load(&root, "evaluate-vs-python").unwrap();
    let csv = root.join("bench/vs_python_turntable.csv");
    let mut run = pav::provenance::Run::start().inputs([csv.as_path()]);
    run.command = vec![recorded.command.clone()];
    let fresh = ResultFile::from_run(&run, &csv, &recorded.shape(), &recorded.title, &root).unwrap();
    assert_eq!(fresh.rows, recorded.rows);
    assert_eq!(fresh.inputs, recorded.inputs);
    // The cells by hand: the fastest of each tool's rounds, and pav's over Python's.
    let text = std::fs::read_to_string(&csv).unwrap();
    let fastest = |tool: &str, det: &str| {
        text.lines()
            .filter_map(|l| {
                let f: Vec<&str> = l.split(',').collect();
                (f[0] == tool && f[1] == det).then(|| f[3].parse::<f64>().unwrap())
            })
            .fold(f64::INFINITY, f64::min)
    };
    let row = fresh.rows.iter().find(|r| r[0] == "yolox_nano").unwrap();
    let (py, pav) = (fastest("python", "yolox_nano"), fastest("pav", "yolox_nano"));
    assert_eq!(row[1], format!("{py:.2}"));
    assert_eq!(row[2], format!("{pav:.2}"));
    assert_eq!(row[4], format!("{:.2}", pav / py));
    // A bad pivot is refused with the columns there are.
    let bad = Shape { pivot: Some("tool=seconds".into()), ..recorded.shape() };
    let e = ResultFile::from_run(&run, &csv, &bad, "t", &root).unwrap_err().to_string();
    assert!(e.contains("no column `seconds`") && e.contains("wall_s"), "{e}");
    // Rewritten by a rerun, the CSV makes its table stale.
    let tmp = copy_root();
    std::fs::remove_file(tmp.path().join("bench")).unwrap();
    copy_dir(&root.join("bench"), &tmp.path().join("bench"));
    std::fs::write(tmp.path().join("bench/vs_python_turntable.csv"), text.replacen("20.467", "19.9", 1)).unwrap();
    let differ = regenerate(tmp.path(), false).unwrap();
    let (_, new) = differ.iter().find(|(p, _)| p.ends_with("docs/reports/speed.md")).expect("speed.md's table");
    assert!(new.contains("bench/vs_python_turntable.csv changed"), "{new}");
}

fn pav_in(dir: &Path) -> std::process::Command {
    let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_pav"));
    c.current_dir(dir).env("RUST_BACKTRACE", "0");
    c
}

/// A table one script made from several runs records every run's inputs (and is refused
/// without the script to rerun); its plot is drawn from the recorded cells, one colour per
/// series, and a column it does not have is refused by name.
#[test]
fn a_table_from_several_runs_keeps_their_inputs_and_plots_its_cells() {
    common::real_data();
    let tmp = copy_root();
    let root = tmp.path();
    let (a, b) = (root.join("out/a"), root.join("out/b"));
    for (dir, config) in [(&a, "configs/views/fidelity/cycles4.toml"), (&b, "configs/views/fidelity/rasterizer.toml")] {
        std::fs::create_dir_all(dir).unwrap();
        pav::provenance::Run::start().config(&root.join(config)).write(&dir.join("run.toml")).unwrap();
    }
    let table = root.join("out/cost.csv");
    std::fs::write(
        &table,
        "level,s,family,d,lo,hi\nc4,1.5,x,0.01,-0.01,0.02\nr,0.05,x,0.03,0.02,0.04\nc4,1.5,y,-0.02,-0.03,-0.01\n",
    )
    .unwrap();
    let add = |extra: &[&str]| {
        let mut c = pav_in(root);
        c.args(["results", "add", "cost", "--run", "out/a", "--run", "out/b", "--table", "out/cost.csv"])
            .args(["--columns", "level,s=s/view:2,family,d=difference:+3,lo+hi=interval:+3", "--title", "Cost"])
            .args(extra);
        c.output().unwrap()
    };
    let o = add(&[]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("needs --command"));
    let o = add(&["--command", "bash docs/reports/scripts/fidelity.sh"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let file = ResultFile::load(root, "cost").unwrap();
    assert_eq!(file.command, "bash docs/reports/scripts/fidelity.sh");
    for config in ["configs/views/fidelity/cycles4.toml", "configs/views/fidelity/rasterizer.toml"] {
        assert!(file.inputs.contains_key(config), "{:?}", file.inputs.keys());
    }
    assert_eq!(file.rows[1], ["r", "0.05", "x", "+0.030", "[+0.020, +0.040]"]);
    let png = root.join("cost.png");
    let plot = |x: &str| {
        pav_in(root)
            .args(["results", "plot", "cost", "--x", x, "--y", "difference", "--interval", "interval"])
            .args(["--series", "family", "--label", "level", "--log-x", "-o"])
            .arg(&png)
            .output()
            .unwrap()
    };
    let o = plot("s/view");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let img = image::open(&png).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (900, 560));
    // The first two colours of the palette: one per family.
    for colour in [[31u8, 119, 180], [214, 39, 40]] {
        assert!(img.pixels().filter(|p| p.0 == colour).count() > 50, "{colour:?} not drawn");
    }
    let o = plot("seconds");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("no column `seconds`") && err.contains("s/view"), "{err}");
}

/// A table recorded after a config's comment was edited is still kept by the config's values:
/// the values come from the commit the run was made at, when it holds what the run read, so
/// the table is fresh until a value changes.
#[test]
fn a_comment_edited_before_recording_keeps_the_table_fresh() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    let git = |args: &[&str]| {
        let out = pav::provenance::git(root, &[&["-c", "user.name=t", "-c", "user.email=t@t"], args].concat()).unwrap();
        String::from_utf8_lossy(&out).trim().to_string()
    };
    let config = root.join("configs/recipe.toml");
    std::fs::create_dir_all(config.parent().unwrap()).unwrap();
    std::fs::write(&config, "# about 3 h\n[optimizer]\nlr = 0.01\n").unwrap();
    git(&["init", "-q"]);
    git(&["add", "."]);
    git(&["commit", "-qm", "recipe"]);
    let mut run = pav::provenance::Run::start().config(&config);
    run.git_commit = git(&["rev-parse", "HEAD"]);
    run.command = vec!["pav optimize --config configs/recipe.toml".into()];
    let csv = root.join("table.csv");
    std::fs::write(&csv, "x,y\n1,2\n").unwrap();
    let shape = Shape { columns: vec!["x".into(), "y".into()], rows_where: vec![], pivot: None };
    let record = |run: &pav::provenance::Run| ResultFile::from_run(run, &csv, &shape, "t", root).unwrap();
    let as_run = record(&run);
    assert!(as_run.inputs["configs/recipe.toml"].starts_with("toml:"));
    std::fs::write(&config, "# see the report\n[optimizer]\nlr = 0.01\n").unwrap();
    let later = record(&run);
    assert_eq!(later.inputs, as_run.inputs, "the edited comment changed the recorded config");
    assert!(later.stale(root).is_empty(), "{:?}", later.stale(root));
    // A value changed since the run is not hidden: the table is stale.
    std::fs::write(&config, "[optimizer]\nlr = 0.02\n").unwrap();
    assert_eq!(record(&run).stale(root), ["configs/recipe.toml changed"]);
    // A table from several runs takes each config at the commit of the run that read it.
    std::fs::write(&config, "# about 3 h\n[optimizer]\nlr = 0.01\n").unwrap();
    let other = root.join("configs/other.toml");
    std::fs::write(&other, "# one seed\nseeds = [0]\n").unwrap();
    git(&["add", "."]);
    git(&["commit", "-qm", "other"]);
    let mut second = pav::provenance::Run::start().config(&other);
    second.git_commit = git(&["rev-parse", "HEAD"]);
    std::fs::write(&other, "# one seed, see the report\nseeds = [0]\n").unwrap();
    let both = ResultFile::from_runs(&run, &[second], &csv, &shape, "t", root).unwrap();
    assert!(both.inputs["configs/other.toml"].starts_with("toml:"), "{:?}", both.inputs);
    assert!(both.stale(root).is_empty(), "{:?}", both.stale(root));
    // Without the run's commit (outside git, or another history) the bytes decide, as before.
    run.git_commit = "0000000000000000000000000000000000000000".into();
    std::fs::write(&config, "# see the report\n[optimizer]\nlr = 0.01\n").unwrap();
    assert!(!record(&run).inputs["configs/recipe.toml"].starts_with("toml:"));
}
