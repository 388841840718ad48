//! Where the car boxes of held-out views sit, which P@0.5 and the mean best car score read
//! differently: AP ranks every car box from score 0.05 over all images, so a texture that leaves
//! a low-scoring box on the car in every view keeps AP high, and one that leaves boxes off the
//! car (IoU < 0.5) or none lowers it. These tables say which of the two a texture does.

use super::per_view::ScoredView;
use super::table2::AP_MIN_SCORE;
use pav_detect::nms::iou;
use pav_eval::digital::ImageDetections;
use std::collections::HashMap;

/// IoU with the ground truth from which a car box counts as a hit for P@0.5.
pub const HIT_IOU: f32 = 0.5;

/// One car box (score ≥ `table2::AP_MIN_SCORE`, after NMS) on a held-out view.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct BoxRecord {
    /// Fold index.
    pub fold: usize,
    /// View name.
    pub view: String,
    /// Texture name.
    pub texture: String,
    /// Random seed (0 for the others).
    pub seed: u64,
    /// Detector name.
    pub detector: String,
    /// Car score.
    pub score: f32,
    /// IoU with the view's ground-truth box (NaN without one).
    pub iou: f32,
    /// Box, pixels: left.
    pub x0: f32,
    /// Top.
    pub y0: f32,
    /// Right.
    pub x1: f32,
    /// Bottom.
    pub y1: f32,
}

/// The rows of `im`'s car boxes.
pub fn box_records(
    fold: usize,
    view: &str,
    texture: &str,
    seed: u64,
    detector: &str,
    im: &ImageDetections,
) -> Vec<BoxRecord> {
    im.cars
        .iter()
        .map(|(score, b)| BoxRecord {
            fold,
            view: view.to_string(),
            texture: texture.to_string(),
            seed,
            detector: detector.to_string(),
            score: *score,
            iou: im.gt.map_or(f32::NAN, |g| iou(b, &g)),
            x0: b[0],
            y0: b[1],
            x1: b[2],
            y1: b[3],
        })
        .collect()
}

/// The best score of a car box on the car in `im` (IoU ≥ [`HIT_IOU`] with its ground truth; 0
/// without one, or without a ground truth): the car's own box.
pub fn own_box_score(im: &ImageDetections) -> f32 {
    let Some(g) = im.gt else { return 0.0 };
    im.cars.iter().filter(|(_, b)| iou(b, &g) >= HIT_IOU).map(|c| c.0).fold(0.0, f32::max)
}

/// `records` with each view's score replaced by the best score of a box of `boxes` on the car
/// (IoU ≥ [`HIT_IOU`]; 0 without one): the car's own box, the hit P@0.5 counts.
pub fn own_box_records(records: &[ScoredView], boxes: &[BoxRecord]) -> Vec<ScoredView> {
    let mut best: HashMap<(usize, &str, &str, u64, &str), f32> = HashMap::new();
    for b in boxes.iter().filter(|b| b.iou >= HIT_IOU) {
        let e = best.entry((b.fold, &b.view, &b.texture, b.seed, &b.detector)).or_insert(0.0);
        *e = e.max(b.score);
    }
    records
        .iter()
        .map(|r| {
            let key = (r.fold, r.view.as_str(), r.texture.as_str(), r.seed, r.detector.as_str());
            ScoredView { score: best.get(&key).copied().unwrap_or(0.0), ..r.clone() }
        })
        .collect()
}

/// What a texture leaves of the car boxes on one detector's held-out images (those with a
/// ground-truth box; random textures count each seed as an image).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BoxAnatomy {
    /// Detector.
    pub detector: String,
    /// Texture.
    pub texture: String,
    /// Images with a ground-truth box.
    pub images: usize,
    /// Share of images with a car box on the car (IoU ≥ 0.5) at any score from 0.05.
    pub on_car: f64,
    /// Mean over images of the best score of a box on the car (0 where there is none).
    pub on_score: f64,
    /// Share of images whose best car box is off the car (IoU < 0.5).
    pub best_off: f64,
    /// Mean number of car boxes off the car per image.
    pub off_boxes: f64,
    /// Mean over images of the best score of a box off the car (0 where there is none).
    pub off_score: f64,
}

/// [`BoxAnatomy`] of `ims`; None when none has a ground-truth box.
pub fn anatomy(detector: &str, texture: &str, ims: &[ImageDetections]) -> Option<BoxAnatomy> {
    let with_gt: Vec<(&ImageDetections, [f32; 4])> = ims.iter().filter_map(|i| i.gt.map(|g| (i, g))).collect();
    if with_gt.is_empty() {
        return None;
    }
    let n = with_gt.len() as f64;
    let (mut on_car, mut on_score, mut best_off, mut off_boxes, mut off_score) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (im, g) in &with_gt {
        let best = |on: bool| {
            im.cars
                .iter()
                .filter(|(_, b)| (iou(b, g) >= HIT_IOU) == on)
                .map(|c| c.0 as f64)
                .fold(None, |m: Option<f64>, s| Some(m.map_or(s, |m| m.max(s))))
        };
        let (on, off) = (best(true), best(false));
        on_car += on.is_some() as u8 as f64;
        on_score += on.unwrap_or(0.0);
        off_score += off.unwrap_or(0.0);
        best_off += (off.unwrap_or(0.0) > on.unwrap_or(0.0)) as u8 as f64;
        off_boxes += im.cars.iter().filter(|(_, b)| iou(b, g) < HIT_IOU).count() as f64;
    }
    Some(BoxAnatomy {
        detector: detector.to_string(),
        texture: texture.to_string(),
        images: with_gt.len(),
        on_car: on_car / n,
        on_score: on_score / n,
        best_off: best_off / n,
        off_boxes: off_boxes / n,
        off_score: off_score / n,
    })
}

/// The mean of anatomies of one detector (runs of one config), under the texture name `texture`.
pub fn mean_anatomy(texture: &str, a: &[&BoxAnatomy]) -> Option<BoxAnatomy> {
    let first = a.first()?;
    let n = a.len() as f64;
    let m = |f: fn(&BoxAnatomy) -> f64| a.iter().map(|x| f(x)).sum::<f64>() / n;
    Some(BoxAnatomy {
        detector: first.detector.clone(),
        texture: texture.to_string(),
        images: a.iter().map(|x| x.images).sum(),
        on_car: m(|x| x.on_car),
        on_score: m(|x| x.on_score),
        best_off: m(|x| x.best_off),
        off_boxes: m(|x| x.off_boxes),
        off_score: m(|x| x.off_score),
    })
}

/// The Markdown section of an anatomy `table`, with `note` (how the report pooled it) after
/// the explanation both reports share.
pub fn anatomy_section(table: &str, note: &str) -> String {
    format!(
        "\n## Where the car boxes sit on held-out views (what P@0.5 reads)\n\nP@0.5 ranks every car box from score {AP_MIN_SCORE} over all held-out views: a box on the car (IoU ≥ {HIT_IOU}) counts as a hit however low its score, and one off the car as a false positive. A texture lowers P@0.5 by leaving no box on the car, or boxes off the car that outrank the hits; it lowers the mean best car score by lowering scores. {note}\n\n{table}"
    )
}

/// The Markdown section of the paired differences `table` over the car's own box.
pub fn own_box_section(table: &str) -> String {
    format!(
        "\n## The car's own box, paired over held-out views\n\nPer view, the best score of a car box on the car (IoU ≥ {HIT_IOU}; 0 where none is left from score {AP_MIN_SCORE}): the hits P@0.5 counts, without the background's boxes that the mean best car score also takes. Optimized − other, mean [95 % paired-bootstrap interval]; below zero, the optimized texture leaves less of the car's own box.\n\n{table}"
    )
}

/// The anatomies as a Markdown table, a row per detector and texture.
pub fn markdown_anatomy(a: &[BoxAnatomy]) -> String {
    let mut s = String::from(
        "| detector | texture | images | on the car (%) | best score on the car | best box off the car (%) | boxes off the car per image | best score off the car |\n|---|---|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in a {
        s.push_str(&format!(
            "| {} | {} | {} | {:.0} | {:.3} | {:.0} | {:.2} | {:.3} |\n",
            r.detector,
            r.texture,
            r.images,
            100.0 * r.on_car,
            r.on_score,
            100.0 * r.best_off,
            r.off_boxes,
            r.off_score
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn anatomy_separates_boxes_on_and_off_the_car() {
        let g = [0.0, 0.0, 10.0, 10.0];
        let off = [20.0, 20.0, 30.0, 30.0];
        let ims = [
            // A low box on the car and a higher one off it.
            ImageDetections { gt: Some(g), cars: vec![(0.1, g), (0.3, off)] },
            // Nothing.
            ImageDetections { gt: Some(g), cars: vec![] },
            // No ground truth: not counted.
            ImageDetections { gt: None, cars: vec![(0.9, g)] },
            // On the car only.
            ImageDetections { gt: Some(g), cars: vec![(0.5, [1.0, 0.0, 10.0, 10.0])] },
        ];
        let a = anatomy("d", "t", &ims).unwrap();
        assert_eq!(a.images, 3);
        assert!((a.on_car - 2.0 / 3.0).abs() < 1e-12);
        assert!((a.on_score - 0.6 / 3.0).abs() < 1e-6);
        assert!((a.best_off - 1.0 / 3.0).abs() < 1e-12);
        assert!((a.off_boxes - 1.0 / 3.0).abs() < 1e-12);
        assert!((a.off_score - 0.3 / 3.0).abs() < 1e-6);
        assert!(anatomy("d", "t", &ims[2..3]).is_none());
        let rows = box_records(0, "v", "t", 0, "d", &ims[0]);
        assert_eq!(rows.len(), 2);
        assert_eq!((rows[0].iou, rows[1].iou), (1.0, 0.0));
    }
}
