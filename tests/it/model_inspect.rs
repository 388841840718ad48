//! `pav-rig model inspect` on every detector in the data set: the four pav decodes are guessed as
//! their shipped configs' layouts and their skeletons load as detector configs, NanoDet's GFL head
//! too; PicoDet's in-graph NMS is guessed as `rows` with its scale-factor input, and `--values`
//! lists the values inside its graph that a white box reads; a non-model is a clear error. `pav-rig model check` tells a finished config from a wrong one on real images.

use crate::common;

use pav::detect::config::OutputLayout;

fn inspect(model: &str, out: &std::path::Path) -> (bool, String) {
    let o = common::pav_rig().args(["model", "inspect", model, "-o"]).arg(out).output().unwrap();
    (o.status.success(), common::output_text(&o))
}

fn kind(l: &OutputLayout) -> &'static str {
    match l {
        OutputLayout::Darknet { .. } => "darknet",
        OutputLayout::Yolox { .. } => "yolox",
        OutputLayout::Ultralytics { .. } => "ultralytics",
        OutputLayout::Detr { .. } => "detr",
        OutputLayout::Gfl { .. } => "gfl",
        OutputLayout::Rows { .. } => "rows",
        OutputLayout::Custom(_) => "custom",
    }
}

#[test]
fn known_layouts_are_guessed_and_their_skeletons_load() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    for (config, model, layout) in [
        ("yolox_nano", "data:models-yolox/yolox_nano.onnx", "yolox"),
        ("yolov8n_int8", "data:models-yolov8n/yolov8n_int8.onnx", "ultralytics"),
        ("deimv2_atto_int8", "data:models-deimv2/deimv2_atto_coco_int8.onnx", "detr"),
    ] {
        let out = tmp.path().join(format!("{config}.toml"));
        let (ok, text) = inspect(model, &out);
        assert!(ok, "{text}");
        assert!(text.contains(&format!("layout: {layout} (")), "{config}: {text}");
        let shipped = pav::detect::DetectorConfig::load(&common::detector_config(config)).unwrap();
        assert_eq!(kind(&shipped.output), layout);
        // The skeleton names the model by its store path: it loads as a config of that layout,
        // with the shipped config's input size.
        let skeleton = pav::detect::DetectorConfig::load(&out).unwrap_or_else(|e| panic!("{config}: {e}"));
        assert_eq!(kind(&skeleton.output), layout);
        assert_eq!((skeleton.input.width, skeleton.input.height), (shipped.input.width, shipped.input.height));
    }
    // YOLOv3-tiny's heads are symbolic in the file; the run at --size gives their grids.
    let (ok, text) = inspect(".deps/models/yolov3-tiny/yolov3-tiny.onnx", &tmp.path().join("tiny.toml"));
    assert!(ok && text.contains("layout: darknet (2 [1, 3·(5+80), H, W] heads"), "{text}");
    assert!(text.contains("ran [1, 255, 20, 20]"), "{text}");
}

#[test]
fn gfl_and_in_graph_nms_are_guessed_and_bad_files_refused() {
    common::shared_data();
    let tmp = tempfile::tempdir().unwrap();
    let (ok, text) = inspect("data:models-nanodet/nanodet_m_416.onnx", &tmp.path().join("n.toml"));
    assert!(ok && text.contains("layout: gfl (") && text.contains("GFL head"), "{text}");
    let skeleton = pav::detect::DetectorConfig::load(&tmp.path().join("n.toml")).unwrap();
    assert!(matches!(skeleton.output, OutputLayout::Gfl { bins: 8, .. }), "{:?}", skeleton.output);
    assert!(text.contains("ran [1, 2704, 32]") && text.contains("ran [1, 169, 80]"), "{text}");
    // PicoDet's graph, int32 constants and all, read by pav's reader: its operators name the NMS.
    let (ok, text) = inspect("data:models-picodet/picodet_xs_320_lcnet_postprocessed.onnx", &tmp.path().join("p.toml"));
    assert!(ok && text.contains("NonMaxSuppression 1") && text.contains("NMS inside the graph"), "{text}");
    assert!(text.contains("scale_factor"), "{text}");
    // Its skeleton loads: rows in image pixels, the scale factor fed as an extra input.
    let skeleton = pav::detect::DetectorConfig::load(&tmp.path().join("p.toml")).unwrap();
    assert!(
        matches!(skeleton.output, OutputLayout::Rows { frame: pav::detect::config::BoxFrame::Image, .. }),
        "{:?}",
        skeleton.output
    );
    assert_eq!(skeleton.input.extra.len(), 1, "{:?}", skeleton.input.extra);
    // `--values` lists what the shipped config names inside the graph for its white box: the
    // class-major scores and the boxes the NMS reads, with their shapes.
    let o = common::pav_rig()
        .args(["model", "inspect", "data:models-picodet/picodet_xs_320_lcnet_postprocessed.onnx", "--values"])
        .output()
        .unwrap();
    let text = common::output_text(&o);
    let line = |v: &str| text.lines().find(|l| l.split_whitespace().nth(1) == Some(v)).unwrap_or_default().to_string();
    assert!(o.status.success() && line("concat_4.tmp_0").ends_with("[1, 80, 2125]"), "{}", line("concat_4.tmp_0"));
    assert!(line("tmp_17").ends_with("[1, 2125, 4]"), "{}", line("tmp_17"));
    // And the white box's refusal of final rows names the keys that give it a gradient.
    let rows = OutputLayout::Rows {
        output: None,
        columns: pav::detect::config::Column::xyxy_rows(),
        frame: Default::default(),
        scores: None,
        boxes: None,
    };
    let why = rows.gradient(80).unwrap_err();
    assert!(why.contains("set `scores`") && why.contains("--values"), "{why}");
    let junk = tmp.path().join("junk.onnx");
    std::fs::write(&junk, b"not a model").unwrap();
    let (ok, text) = inspect(junk.to_str().unwrap(), &tmp.path().join("j.toml"));
    assert!(!ok && text.contains("junk.onnx"), "{text}");
}

fn check(config: &std::path::Path, images: &[&str], out: &std::path::Path) -> (bool, String) {
    let o = common::pav_rig().args(["model", "check"]).arg(config).args(images).arg("-o").arg(out).output().unwrap();
    (o.status.success(), common::output_text(&o))
}

/// `model check` on a photo and a turntable frame: the right config finds the car and draws it; a
/// config with a wrong scale (inputs in [0, 1] for a model that reads 0–255) finds none and says
/// what to check; a wrong box encoding is warned of and a score column outside [0, 1] refused; an
/// unreadable image is named.
#[test]
fn check_shows_a_wrong_config_at_once() {
    let data = common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let photo = data.join("fca/carla_dataset/test/data12501.npz").display().to_string();
    let frame = "fixtures/turntable.mp4#0";
    let good = common::detector_config("yolox_nano");
    let (ok, text) = check(&good, &[&photo, frame], &tmp.path().join("good"));
    assert!(ok, "{text}");
    let best: Vec<f32> = text
        .lines()
        .filter_map(|l| l.trim().strip_prefix("best car: "))
        .map(|l| l.split_whitespace().next().unwrap().parse().unwrap())
        .collect();
    assert!(best.len() == 2 && best.iter().all(|s| *s > 0.5), "{text}");
    assert!(text.contains(" car ") && text.contains(" *"), "target detections are starred:\n{text}");
    for png in ["data12501.png", "turntable_0.png"] {
        let img = pav::image::Rgb::load(&tmp.path().join("good").join(png)).unwrap();
        // The car's box is drawn in green.
        let green = img.rgb.chunks_exact(3).filter(|p| p[0] < 0.3 && p[1] > 0.7 && p[2] < 0.3).count();
        assert!(green > 100, "{png}: {green} green pixels");
    }
    let wrong = tmp.path().join("wrong.toml");
    std::fs::write(
        &wrong,
        format!("extends = {:?}\nname = \"wrong\"\n[input]\nscale = 0.00392156862745098\n", good.display().to_string()),
    )
    .unwrap();
    let (ok, text) = check(&wrong, &[&photo, frame], &tmp.path().join("wrong"));
    assert!(ok, "{text}");
    assert!(text.contains("no car on 2 of 2 images") && text.contains("check the config's channels, scale"), "{text}");
    // A right config gives nothing a right description cannot; YOLOX-Nano's rows read with
    // the wrong box encoding give confident boxes of a few pixels or none (a warning), with the
    // wrong objectness column scores outside [0, 1] (an error): each is named.
    let (_, text) = check(&good, &[&photo, frame], &tmp.path().join("good"));
    assert!(!text.contains("warning:"), "{text}");
    let shipped = std::fs::read_to_string(&good).unwrap();
    let inputs = shipped.split("[output]").next().unwrap();
    let custom = |name: &str, encoding: &str, objectness: usize| {
        let path = tmp.path().join(format!("{name}.toml"));
        let levels = "[[output.levels]]\nstride = 8\n[[output.levels]]\nstride = 16\n[[output.levels]]\nstride = 32\n";
        std::fs::write(
            &path,
            format!(
                "{inputs}[output]\nlayout = \"custom\"\n{levels}[output.boxes]\nencoding = \"{encoding}\"\n[output.objectness]\ncolumn = {objectness}\n[output.scores]\ncolumn = 5\n[classes]\nnames = \"coco80\"\ntarget = [\"car\"]\n"
            ),
        )
        .unwrap();
        path
    };
    let (ok, text) = check(&custom("encoding", "xyxy", 4), &[&photo, frame], &tmp.path().join("e"));
    assert!(ok && text.contains("the box encoding or the columns' order is likely wrong"), "{text}");
    assert!(text.contains("2 of 2 images gave boxes a right description is unlikely to give"), "{text}");
    let (ok, text) = check(&custom("objectness", "grid", 2), &[&photo, frame], &tmp.path().join("o"));
    assert!(!ok && text.contains("error: scores run from"), "{text}");
    assert!(text.contains("outside [0, 1]: the layout reads a column that is not a probability"), "{text}");
    assert!(text.contains("2 of 2 images gave scores outside [0, 1]: the description is wrong"), "{text}");
    let (ok, text) = check(&good, &["no/such.jpg"], &tmp.path().join("x"));
    assert!(!ok && text.contains("no/such.jpg") && text.contains("cannot be read"), "{text}");
}
