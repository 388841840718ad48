//! `pav eval-digital`: the paper's Table 2 on composites. Every view is composited with each
//! texture (lit, no EoT), quantized to 8 bits as a saved image would be, and scored by every
//! ONNX detector; the white-box model is marked.

use super::outputs::{composite, eval_scene};
use super::setup::Setup;
use super::view::View;
use crate::detect::{Detector, Frame};
use crate::eval::digital::{ap50, asr, ImageDetections};
use crate::render::texture::to_u8;

/// Lowest car score kept for P@0.5 (COCO evaluations keep low-scoring boxes for the PR curve).
pub const AP_MIN_SCORE: f32 = 0.05;
/// NMS IoU for the car detections.
pub const NMS_IOU: f32 = 0.5;

/// One cell of the table.
#[derive(Clone, Debug, serde::Serialize)]
pub struct DigitalRow {
    /// Detector name.
    pub detector: String,
    /// Whether the texture was optimized against this detector.
    pub white_box: bool,
    /// Texture condition.
    pub texture: String,
    /// "train", "test" or "all".
    pub split: String,
    /// Images.
    pub images: usize,
    /// ASR at `threshold`.
    pub asr: f64,
    /// Car AP at IoU 0.5 (NaN without ground truth).
    pub p50: f64,
    /// Mean over images of the best car score (0 when no box): the attack's effect below the threshold.
    pub mean_score: f64,
    /// Score threshold of the ASR.
    pub threshold: f32,
}

/// The composite of `view` with `tex` (or the photo itself) as an 8-bit BGR frame.
fn frame(view: &View, tex: Option<&[f32]>, setup: &Setup) -> Frame {
    let img = match tex {
        Some(t) => composite(view, t, &eval_scene(setup)),
        None => view.photo.clone(),
    };
    Frame {
        width: view.size,
        height: view.size,
        bgr: img.chunks(3).flat_map(|c| [to_u8(c[2]), to_u8(c[1]), to_u8(c[0])]).collect(),
    }
}

/// The car detections of every detector on `view` composited with `tex` (`None` = the photo).
pub fn detect_view(
    view: &View,
    tex: Option<&[f32]>,
    setup: &Setup,
    detectors: &mut [Box<dyn Detector>],
) -> Result<Vec<ImageDetections>, crate::detect::DetectError> {
    let f = frame(view, tex, setup);
    let mut out = Vec::with_capacity(detectors.len());
    for det in detectors.iter_mut() {
        let p = det.propose(&f)?;
        let cars = p
            .target_detections(det.target_classes(), AP_MIN_SCORE, NMS_IOU)
            .into_iter()
            .map(|x| (x.score, x.bbox))
            .collect();
        out.push(ImageDetections { gt: setup.boxes.get(&view.name).copied(), cars });
    }
    Ok(out)
}

/// One cell from the detections of its images; `None` when there are none.
pub fn aggregate(
    detector: &str,
    white_box: bool,
    texture: &str,
    split: &str,
    ims: &[ImageDetections],
    threshold: f32,
) -> Option<DigitalRow> {
    let a = asr(ims, threshold)?;
    Some(DigitalRow {
        detector: detector.to_string(),
        white_box,
        texture: texture.to_string(),
        split: split.into(),
        images: ims.len(),
        asr: a,
        p50: ap50(ims).unwrap_or(f64::NAN),
        mean_score: ims.iter().map(|i| i.best_score() as f64).sum::<f64>() / ims.len() as f64,
        threshold,
    })
}

/// Scores every (detector, texture, split) of `setup`; `textures` pairs a name with a texture
/// (`None` = the unmodified photo).
pub fn evaluate(
    setup: &Setup,
    detectors: &mut [Box<dyn Detector>],
    textures: &[(String, Option<Vec<f32>>)],
    threshold: f32,
    white_box: &str,
    mut progress: impl FnMut(),
) -> Result<Vec<DigitalRow>, crate::detect::DetectError> {
    let mut rows = Vec::new();
    for (tname, tex) in textures {
        let mut per: Vec<Vec<(&'static str, ImageDetections)>> = vec![Vec::new(); detectors.len()];
        for (split, views) in [("train", &setup.train), ("test", &setup.test)] {
            for v in views.iter() {
                for (d, im) in detect_view(v, tex.as_deref(), setup, detectors)?.into_iter().enumerate() {
                    per[d].push((split, im));
                }
                progress();
            }
        }
        for (d, det) in detectors.iter().enumerate() {
            for split in ["train", "test", "all"] {
                let ims: Vec<ImageDetections> =
                    per[d].iter().filter(|(s, _)| split == "all" || *s == split).map(|(_, i)| i.clone()).collect();
                rows.extend(aggregate(det.name(), det.name() == white_box, tname, split, &ims, threshold));
            }
        }
    }
    Ok(rows)
}

/// The table in the paper's shape: detectors down, textures across, "ASR / P@0.5" in percent,
/// white-box cells starred; one table per split.
pub fn markdown(rows: &[DigitalRow], split: &str) -> String {
    table(rows, split, |r, star| format!("{:.1}{star} / {:.1}{star}", 100.0 * r.asr, 100.0 * r.p50))
}

/// The same table with the mean best car score per cell: the attack's effect below the threshold.
pub fn markdown_scores(rows: &[DigitalRow], split: &str) -> String {
    table(rows, split, |r, star| format!("{:.3}{star}", r.mean_score))
}

fn table(rows: &[DigitalRow], split: &str, cell: impl Fn(&DigitalRow, &str) -> String) -> String {
    let textures = crate::eval::report::unique(rows.iter().map(|r| r.texture.clone()));
    let detectors = crate::eval::report::unique(rows.iter().map(|r| (r.detector.clone(), r.white_box)));
    let mut s = format!("| detector | {} |\n|---|{}\n", textures.join(" | "), "---|".repeat(textures.len()));
    for (d, wb) in &detectors {
        s.push_str(&format!("| {d}{} |", if *wb { " (white-box)" } else { "" }));
        for t in &textures {
            match rows.iter().find(|r| &r.detector == d && &r.texture == t && r.split == split) {
                Some(r) => {
                    s.push_str(&format!(" {} |", cell(r, if r.white_box && t != "original" { "*" } else { "" })))
                }
                None => s.push_str(" – |"),
            }
        }
        s.push('\n');
    }
    s
}
