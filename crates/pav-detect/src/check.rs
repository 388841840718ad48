//! A finished detector config tried on images: every detection above a score, the target's best,
//! and the picture with its boxes drawn, so that a wrong channel order, scale or layout shows at
//! once (`pav-rig model check`).

use super::decode::Proposals;
use super::onnx::OnnxDetector;
use super::{DetectError, Detection, Detector, TargetScore};
use pav_core::image::{draw_box, Frame};
use pav_dataset::fca::CarlaSample;
use std::path::Path;

/// An image that cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum CheckError {
    /// The file is missing or not an image, npz sample or video frame pav reads.
    #[error("{path}: {msg}")]
    Image {
        /// The argument as given.
        path: String,
        /// Why.
        msg: String,
    },
    /// The detector failed on it.
    #[error(transparent)]
    Detect(#[from] DetectError),
}

/// What a detector finds in one image.
#[derive(Clone, Debug)]
pub struct Checked {
    /// Every detection above the score asked for, best first (after NMS).
    pub detections: Vec<Detection>,
    /// The best box of the target classes, at any score.
    pub best: Option<TargetScore>,
    /// Scores outside [0, 1]: the description is wrong, and nothing it scores can be trusted.
    pub refused: Option<String>,
    /// What a right description is unlikely to give (a confident best box without area, a few
    /// pixels across or off the frame): each a sign that the layout reads the wrong columns or
    /// encoding.
    pub warnings: Vec<String>,
}

/// Reads `spec`: an image file (any format OpenCV reads), an FCA `.npz` sample, or frame K of a
/// video as `VIDEO#K`.
pub fn read_input(spec: &str) -> Result<Frame, CheckError> {
    let bad = |msg: String| CheckError::Image { path: spec.to_string(), msg };
    // A data store entry (`data:NAME`) is fetched or found where the store keeps it.
    let local = |p: &str| pav_run::data::resolve(Path::new("."), Path::new(p)).map_err(|e| bad(e.to_string()));
    if let Some((video, k)) = spec.rsplit_once('#') {
        let k: usize = k.parse().map_err(|_| bad(format!("`{k}` is not a frame number")))?;
        let mut rd = pav_core::video::VideoReader::open(&local(video)?).map_err(|e| bad(e.to_string()))?;
        while let Some((i, f)) = rd.read().map_err(|e| bad(e.to_string()))? {
            if i == k {
                return Ok(f);
            }
        }
        return Err(bad(format!("the video has no frame {k}")));
    }
    let path = local(spec)?;
    if path.extension().is_some_and(|e| e == "npz") {
        return CarlaSample::load(&path).map(|s| s.image).map_err(|e| bad(e.to_string()));
    }
    pav_core::video::read_image(&path).map_err(|e| bad(e.to_string()))
}

/// Runs `det` on `frame`: detections from `min_score` after the config's NMS, and the target's best.
pub fn check(det: &mut OnnxDetector, frame: &Frame, min_score: f32) -> Result<Checked, DetectError> {
    let props = det.propose(frame)?;
    let mut detections = props.detections(min_score, det.nms_iou());
    detections.sort_by(|a, b| b.score.total_cmp(&a.score));
    let best = props.best(det.target_classes());
    let refused = scores_out_of_range(&props);
    let warnings =
        best.as_ref().and_then(|b| box_doubt(b.bbox, b.score, frame.width, frame.height)).into_iter().collect();
    Ok(Checked { best, detections, refused, warnings })
}

/// Why the scores of `props` cannot come from a right description: some lie outside [0, 1]
/// (a little past 1 is rounding in an exported sigmoid or softmax). `model check` and `evaluate`
/// both refuse such a description.
pub fn scores_out_of_range(props: &Proposals) -> Option<String> {
    let (lo, hi) = props.scores.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), &v| (l.min(v), h.max(v)));
    (!props.scores.is_empty() && (hi > 1.001 || lo < -0.001 || !(hi.is_finite() && lo.is_finite()))).then(|| {
        format!(
            "scores run from {lo:.3} to {hi:.3}, outside [0, 1]: the layout reads a column that is not a probability (a box coordinate, or logits that need their activation)"
        )
    })
}

/// Why a best box `[x1, y1, x2, y2]` at `score` on a `width` × `height` frame is unlikely from a
/// right description: it has no area; it is a few pixels across at a confident score; or it lies
/// mostly off the frame.
pub fn box_doubt(bbox: [f32; 4], score: f32, width: usize, height: usize) -> Option<String> {
    let [x1, y1, x2, y2] = bbox;
    let (w, h) = (x2 - x1, y2 - y1);
    let shown = format!("[{x1:.0}, {y1:.0}, {x2:.0}, {y2:.0}]");
    if !(w >= 1.0 && h >= 1.0) {
        return Some(format!(
            "the best box, {shown}, has no area: the box encoding or the columns' order is likely wrong"
        ));
    }
    if score >= 0.5 && w.min(h) < (0.01 * width.min(height) as f32).max(4.0) {
        return Some(format!(
            "the best box, {shown}, is a few pixels across at a score of {score:.2}: the box encoding or the columns' order is likely wrong"
        ));
    }
    let (fw, fh) = (width as f32, height as f32);
    let inside = (x2.min(fw) - x1.max(0.0)).max(0.0) * (y2.min(fh) - y1.max(0.0)).max(0.0);
    (inside < 0.5 * w * h).then(|| {
        format!(
            "the best box, {shown}, lies mostly off the {width}x{height} frame: the box encoding, its frame (input or image pixels) or the resize is likely wrong"
        )
    })
}

/// The closing lines of `model check` over `images`: how many were refused, how many gave
/// boxes a right description is unlikely to give, and how many showed no target.
pub fn closing(refused: usize, warned: usize, missed: usize, images: usize, target: &str) -> Vec<String> {
    let mut out = Vec::new();
    if refused > 0 {
        out.push(format!(
            "{refused} of {images} images gave scores outside [0, 1]: the description is wrong (see above)"
        ));
    }
    if warned > 0 {
        out.push(format!(
            "{warned} of {images} images gave boxes a right description is unlikely to give: see the warnings above"
        ));
    }
    if missed > 0 {
        out.push(format!(
            "no {target} on {missed} of {images} images: if they show one, check the config's channels, scale, mean/std, resize and align, and its output layout"
        ));
    }
    out
}

/// The file an image given as `spec` is drawn into: its stem as a PNG, frame K of a video
/// (`VIDEO#K`) as `VIDEO_K.png`.
pub fn drawn_name(spec: &str) -> String {
    let (file, frame) = spec.rsplit_once('#').map_or((spec, None), |(f, k)| (f, Some(k)));
    let stem = Path::new(file).file_stem().map_or_else(|| "image".into(), |s| s.to_string_lossy().into_owned());
    match frame {
        Some(k) => format!("{stem}_{k}.png"),
        None => format!("{stem}.png"),
    }
}

/// `frame` with each detection's box drawn: the target classes in green, the others in orange.
pub fn annotate(frame: &Frame, detections: &[Detection], targets: &[usize]) -> Frame {
    let mut out = frame.clone();
    let thick = (frame.width.max(frame.height) / 300).max(2);
    // Others first, so a target's box stays on top where they overlap.
    for target in [false, true] {
        for d in detections.iter().filter(|d| targets.contains(&d.class_id) == target) {
            draw_box(&mut out, d.bbox, if target { [60, 200, 60] } else { [0, 140, 255] }, thick);
        }
    }
    out
}
