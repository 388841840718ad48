//! `pav adv-train` on real data: the tuned YOLOX-Nano differs from the downloaded one only in
//! the head's objectness and car units, finds RAUCA-E2E's camouflage on held-out photos where
//! the plain model does not, raises few cars on those photos with their car painted out, and a
//! rebuild whose sha256 is not the recipe's fails with the model kept. Bad recipes are refused.

use crate::common;
use crate::common::pav;

use pav_onnx::proto::{InitData, Model};
use std::collections::HashMap;
use std::path::Path;

/// A recipe in `dir` as the shipped one, with `steps` and `extra` lines (absolute paths, since
/// it does not sit in `configs/`).
fn recipe(dir: &Path, detector: &str, steps: usize, extra: &str) -> std::path::PathBuf {
    let c = common::repo().join("configs");
    let p = dir.join("recipe.toml");
    std::fs::write(
        &p,
        format!(
            "detector = {:?}\nviews = {:?}\ntrain_textures = [\"data:rauca-e2e/RAUCA_E2E.png\"]\nrandom_seeds = [1, 2]\n\
             test_textures = [\"data:rauca-e2e/RAUCA_E2E.png\"]\ntest_random_seeds = [11]\nsteps = {steps}\nlr = 0.01\nl2 = 1.0\n{extra}",
            c.join("detectors").join(detector).display().to_string(),
            c.join("studies/print-base.toml").display().to_string(),
        ),
    )
    .unwrap();
    p
}

fn floats(m: &Model) -> HashMap<String, Vec<f32>> {
    m.initializers
        .iter()
        .filter_map(|i| match &i.data {
            InitData::F32(v) => Some((i.name.clone(), v.clone())),
            _ => None,
        })
        .collect()
}

#[test]
fn the_tuned_head_finds_the_camouflaged_car_and_hardly_a_car_where_there_is_none() {
    common::shared_data();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let r = recipe(tmp.path(), "yolox_nano.toml", 120, "sha256 = \"00\"\n");
    let o = pav().arg("adv-train").arg(&r).arg("-o").arg(&out).output().unwrap();
    let text = common::output_text(&o);
    // The recipe's sha256 is not this model's: the run fails, says so, and keeps the model.
    assert!(!o.status.success(), "{text}");
    assert!(text.contains("the rebuilt model's sha256 is") && text.contains("the recipe's 00"), "{text}");
    let tuned = Model::from_bytes(&std::fs::read(out.join("yolox_nano_advtrain.onnx")).unwrap()).unwrap();
    let plain =
        Model::from_bytes(&std::fs::read(common::shared_data().join("models-yolox/yolox_nano.onnx")).unwrap()).unwrap();
    assert_eq!(tuned.nodes.len(), plain.nodes.len());
    let (t, p) = (floats(&tuned), floats(&plain));
    assert_eq!(t.len(), p.len());
    // Three levels × (class weights, class bias, objectness weights, objectness bias).
    let changed: Vec<&String> = p.keys().filter(|k| t[*k] != p[*k]).collect();
    assert_eq!(changed.len(), 12, "{changed:?}");
    for k in changed {
        let (a, b) = (&t[k], &p[k]);
        let rows = if a.len() % 80 == 0 { 80 } else { 1 };
        let width = a.len() / rows;
        for r in 0..rows {
            let same = a[r * width..(r + 1) * width] == b[r * width..(r + 1) * width];
            // COCO's car is class 2: no other class row moves.
            assert_eq!(same, rows == 80 && r != 2, "{k} row {r}");
        }
    }
    // Held-out photos, before and after (view, texture, file, before, after).
    let csv = std::fs::read_to_string(out.join("advtrain.csv")).unwrap();
    let mean = |texture: &str, col: usize| {
        let v: Vec<f64> = csv
            .lines()
            .skip(1)
            .map(|l| l.split(',').collect::<Vec<_>>())
            .filter(|f| f[1] == format!("{texture:?}"))
            .map(|f| f[col].parse().unwrap())
            .collect();
        assert_eq!(v.len(), 5, "{texture}: {csv}");
        v.iter().sum::<f64>() / v.len() as f64
    };
    let (b, a) = (mean("rauca-e2e", 3), mean("rauca-e2e", 4));
    eprintln!("RAUCA-E2E on held-out photos: {b:.3} → {a:.3}");
    assert!(b < 0.35 && a > b + 0.25, "{b} → {a}");
    let (b, a) = (mean("original", 3), mean("original", 4));
    assert!(a >= b - 0.02, "the clean car: {b} → {a}");
    let no_car: Vec<f64> =
        csv.lines().filter(|l| l.contains("no car")).map(|l| l.rsplit(',').next().unwrap().parse().unwrap()).collect();
    let mean_no_car = no_car.iter().sum::<f64>() / no_car.len() as f64;
    eprintln!("photos without their car after tuning: {no_car:?}");
    assert_eq!(no_car.len(), 5);
    assert!(mean_no_car < 0.3, "the tuned head sees cars where there are none: {no_car:?}");
    assert!(no_car.iter().filter(|&&s| s >= 0.5).count() <= 1, "{no_car:?}");
    // Its detector config loads and names the tuned model.
    let cfg = pav::detect::config::DetectorConfig::load(&out.join("yolox_nano_advtrain.toml")).unwrap();
    assert_eq!(cfg.name, "yolox_nano+advtrain");
    assert_eq!(cfg.model, out.join("yolox_nano_advtrain.onnx"));
    assert!(common::run_record(&out.join("run.toml")).to_string().contains("sha256"));
}

#[test]
fn recipes_that_cannot_train_are_refused() {
    common::shared_data();
    let tmp = tempfile::tempdir().unwrap();
    let r = recipe(tmp.path(), "yolov3-tiny.toml", 10, "");
    let o = pav().arg("adv-train").arg(&r).arg("-o").arg(tmp.path().join("o")).output().unwrap();
    let text = common::output_text(&o);
    assert!(!o.status.success() && text.contains("is not a YOLOX detector (layout yolox)"), "{text}");
    let r = recipe(tmp.path(), "yolox_nano.toml", 0, "");
    let o = pav().arg("adv-train").arg(&r).arg("-o").arg(tmp.path().join("o")).output().unwrap();
    let text = common::output_text(&o);
    assert!(!o.status.success() && text.contains("steps 0 must be ≥ 1"), "{text}");
}
