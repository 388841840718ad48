//! `pav lofo` as a user runs it, on FCA's photos at one short epoch: each arm leaves out one
//! family and is scored by it, paired against RAUCA-E2E's texture and random blocks over seeds and
//! views; shards and a merge give what one process gives, and a finished unit is not trained, nor
//! a scored arm scored, again.

use crate::common;
use crate::common::pav;

use std::path::Path;

/// A recipe on half.toml's region training against `boxes`, two photos, one epoch.
fn arm(dir: &Path, name: &str, boxes: &[&str]) -> std::path::PathBuf {
    let repo = common::repo();
    let list: Vec<String> = boxes
        .iter()
        .map(|b| format!("  {{ detector = \"{}\" }},", repo.join("configs/detectors").join(b).display()))
        .collect();
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(
        &path,
        format!(
            "extends = \"{}\"\nwhite_box = [\n{}\n]\n\n[views]\ntrain = [\"data:fca/carla_dataset/test/data12501.npz\", \"data:fca/carla_dataset/test/data12503.npz\"]\n\n[optimizer]\nepochs = 1\n",
            repo.join("configs/studies/half.toml").display(),
            list.join("\n")
        ),
    )
    .unwrap();
    path
}

#[test]
fn each_family_left_out_scores_its_arm_and_shards_give_the_whole_run() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let a = arm(tmp.path(), "a", &["yolov3-tiny.toml"]);
    let b = arm(tmp.path(), "b", &["yolox_nano.toml"]);
    let held = tmp.path().join("held.toml");
    std::fs::write(
        &held,
        format!(
            "extends = \"{}\"\n\n[views]\ntest = [\"data:fca/carla_dataset/test/data12502.npz\", \"data:fca/carla_dataset/test/data12504.npz\", \"data:fca/carla_dataset/test/data12506.npz\"]\n",
            common::repo().join("configs/studies/half.toml").display()
        ),
    )
    .unwrap();
    let run = |out: &Path, extra: &[&str]| {
        let o = pav()
            .arg("lofo")
            .args([&a, &b])
            .args(["--seeds", "0,1", "--random-seeds", "1", "--heldout"])
            .arg(&held)
            .arg("-o")
            .arg(out)
            .args(extra)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", common::output_text(&o));
        common::output_text(&o)
    };
    let whole = tmp.path().join("whole");
    run(&whole, &[]);
    let csv = std::fs::read_to_string(whole.join("lofo.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv.lines().skip(1).map(|l| l.split(',').collect()).collect();
    // Arm a trains against YOLOv3-tiny and is scored by YOLOX-Nano, b the other way round; each
    // against RAUCA-E2E's texture and both kinds of random blocks, over 2 seeds × 3 photos.
    let pairs: Vec<(&str, &str)> = rows.iter().map(|r| (r[0], r[1])).collect();
    assert_eq!(
        pairs,
        [
            ("yolox_nano", "random"),
            ("yolox_nano", "random32"),
            ("yolox_nano", "rauca-e2e"),
            ("yolov3-tiny", "random"),
            ("yolov3-tiny", "random32"),
            ("yolov3-tiny", "rauca-e2e"),
        ],
        "{csv}"
    );
    for r in &rows {
        let x: Vec<f64> = r[2..].iter().map(|v| v.parse().unwrap()).collect();
        let (score, other, diff, lo, hi) = (x[0], x[1], x[4], x[5], x[6]);
        assert!((diff - (score - other)).abs() < 1e-9 && lo <= diff && diff <= hi, "{r:?}");
        assert!(x[8] <= diff && diff <= x[9], "the mean lies between the seeds' means: {r:?}");
        assert_eq!((r[12], r[13]), ("2", "3"), "{r:?}");
    }
    // Each arm's scores are those of eval-digital on the held-out photos by the family left out.
    let views = std::fs::read_to_string(whole.join("without-yolox_nano/heldout/digital_views.csv")).unwrap();
    assert!(views.lines().skip(1).all(|l| l.contains(",yolox_nano,")), "{views}");
    assert!(whole.join("without-yolox_nano/seed1/texture.png").is_file());
    // Run again: nothing is trained or scored again, and the table is the same.
    let stamp = |p: &Path| std::fs::metadata(p).unwrap().modified().unwrap();
    let texture = whole.join("without-yolov3-tiny/seed0/texture.png");
    let scores = whole.join("without-yolov3-tiny/heldout/digital_views.csv");
    let before = (stamp(&texture), stamp(&scores));
    let text = run(&whole, &[]);
    assert_eq!((stamp(&texture), stamp(&scores)), before);
    assert!(text.contains("without-yolov3-tiny: held-out scores kept from an earlier run"), "{text}");
    assert_eq!(std::fs::read_to_string(whole.join("lofo.csv")).unwrap(), csv);
    // Another held-out set is scored anew (a fourth photo), the trained textures kept.
    let three = std::fs::read_to_string(&held).unwrap();
    std::fs::write(
        &held,
        three.replace("data12506.npz\"]", "data12506.npz\", \"data:fca/carla_dataset/test/data12508.npz\"]"),
    )
    .unwrap();
    let text = run(&whole, &[]);
    assert!(!text.contains("kept from an earlier run") && stamp(&scores) != before.1, "{text}");
    assert_eq!(stamp(&texture), before.0);
    let again = std::fs::read_to_string(whole.join("lofo.csv")).unwrap();
    assert!(again.lines().skip(1).all(|l| l.ends_with(",2,4")), "{again}");
    std::fs::write(&held, three).unwrap();
    // Two shards and their merge: the same table.
    let cut = tmp.path().join("cut");
    run(&cut, &["--shard", "1/2"]);
    run(&cut, &["--shard", "2/2"]);
    assert!(cut.join("shard-2-of-2/without-yolov3-tiny/seed1/texture.png").is_file());
    run(&cut, &["--merge"]);
    assert_eq!(std::fs::read_to_string(cut.join("lofo.csv")).unwrap(), csv);
    // An arm that leaves out no family, or two, is refused by name.
    let both = arm(tmp.path(), "both", &["yolov3-tiny.toml", "yolox_nano.toml"]);
    let o = pav().arg("lofo").args([&a, &both]).arg("--heldout").arg(&held).output().unwrap();
    let text = common::output_text(&o);
    assert!(
        !o.status.success() && text.contains("both.toml: an arm leaves out exactly one") && text.contains("none"),
        "{text}"
    );
}

/// The scoring behind eval-digital and every arm's held-out table deals the views out among one
/// set of detectors per core: the records are those of a single set, bit for bit and in order.
#[test]
fn scoring_on_several_workers_gives_the_records_of_one() {
    use pav::attack::config::OptimizeConfig;
    use pav::attack::setup::Setup;
    use pav::studies::table2::{score_textures, Condition};
    common::real_data();
    let mut cfg = OptimizeConfig::load(&common::repo().join("configs/optimize/paper.toml")).unwrap();
    cfg.views.train.truncate(3);
    cfg.views.test.truncate(2);
    let setup = Setup::load_photos(&cfg, None).unwrap();
    let detectors = ["yolov3-tiny", "yolox_nano"].map(common::detector_config);
    let conditions = [
        Condition { name: "original".into(), seed: 0, texture: None },
        Condition { name: "random".into(), seed: 1, texture: Some(setup.random_texture(setup.random_block(), 1)) },
    ];
    let none = |_: &str| Vec::new();
    let run = |workers: usize| {
        let mut sets: Vec<_> =
            (0..workers).map(|_| pav::detect::load::load_detectors(&detectors, &[], &[], 1).unwrap()).collect();
        score_textures(&setup, &mut sets, &conditions, 0.5, &none, &pav::progress::Silent).unwrap()
    };
    let (rows1, one) = run(1);
    let (rows3, three) = run(3);
    assert_eq!(one.len(), 2 * 5 * 2);
    let key = |r: &pav::studies::per_view::ScoredView| {
        (r.view.clone(), r.texture.clone(), r.detector.clone(), r.score.to_bits())
    };
    assert_eq!(one.iter().map(key).collect::<Vec<_>>(), three.iter().map(key).collect::<Vec<_>>());
    let cell = |r: &pav::studies::table2::DigitalRow| {
        (r.texture.clone(), r.detector.clone(), r.split.clone(), r.mean_score.to_bits())
    };
    assert_eq!(rows1.iter().map(cell).collect::<Vec<_>>(), rows3.iter().map(cell).collect::<Vec<_>>());
}
