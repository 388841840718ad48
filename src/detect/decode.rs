//! Raw model outputs → scored proposals in frame pixels, for each supported output layout.

use super::config::{BoxFrame, Column, OutputLayout};
use super::nms::nms;
use super::preprocess::InputMap;
use super::{BBox, Detection, TargetScore};

/// A model output tensor converted to f32 (labels included), with its shape.
#[derive(Clone, Debug)]
pub struct RawOutput {
    /// Output name.
    pub name: String,
    /// Dimensions.
    pub shape: Vec<usize>,
    /// Row-major values.
    pub data: Vec<f32>,
}

/// Every proposal of one frame: a box and a final score per class.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Proposals {
    /// Number of classes (row length of `scores`).
    pub num_classes: usize,
    /// Boxes in frame pixels.
    pub boxes: Vec<BBox>,
    /// `boxes.len() × num_classes` scores (objectness × class probability where both exist).
    pub scores: Vec<f32>,
}

impl Proposals {
    fn with_capacity(num_classes: usize, n: usize) -> Self {
        Proposals { num_classes, boxes: Vec::with_capacity(n), scores: Vec::with_capacity(n * num_classes) }
    }

    /// Number of proposals.
    pub fn len(&self) -> usize {
        self.boxes.len()
    }

    /// Whether there are no proposals.
    pub fn is_empty(&self) -> bool {
        self.boxes.is_empty()
    }

    /// Class scores of proposal `i`.
    pub fn row(&self, i: usize) -> &[f32] {
        &self.scores[i * self.num_classes..(i + 1) * self.num_classes]
    }

    /// The highest score any proposal gives one of `classes`, with its box.
    pub fn best(&self, classes: &[usize]) -> Option<TargetScore> {
        let mut best: Option<TargetScore> = None;
        for (i, b) in self.boxes.iter().enumerate() {
            let row = self.row(i);
            for &c in classes {
                let s = row.get(c).copied().unwrap_or(0.0);
                if best.is_none_or(|t| s > t.score) {
                    best = Some(TargetScore { score: s, bbox: *b, class_id: c });
                }
            }
        }
        best
    }

    /// Target-class detections: each proposal scored by its best target class (not its arg-max
    /// class, so a car also rated "truck" still counts as a car), kept from `min_score`, NMS at `iou`.
    pub fn target_detections(&self, classes: &[usize], min_score: f32, iou: f32) -> Vec<Detection> {
        let mut out = Vec::new();
        for (i, b) in self.boxes.iter().enumerate() {
            let row = self.row(i);
            if let Some((c, s)) =
                classes.iter().filter_map(|&c| row.get(c).map(|s| (c, *s))).max_by(|a, b| a.1.total_cmp(&b.1))
            {
                if s >= min_score {
                    out.push(Detection { class_id: c, score: s, bbox: *b });
                }
            }
        }
        nms(out, iou)
    }

    /// Arg-max class detections with score ≥ `min_score`, after per-class NMS at `iou`.
    pub fn detections(&self, min_score: f32, iou: f32) -> Vec<Detection> {
        let mut out = Vec::new();
        for (i, b) in self.boxes.iter().enumerate() {
            let row = self.row(i);
            let (c, &s) = row.iter().enumerate().fold((0, &f32::NEG_INFINITY), |a, x| if x.1 > a.1 { x } else { a });
            if s >= min_score {
                out.push(Detection { class_id: c, score: s, bbox: *b });
            }
        }
        nms(out, iou)
    }
}

/// Raw outputs that do not fit the configured layout (a missing output, a wrong shape).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct LayoutError(pub String);

fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

fn find<'a>(outs: &'a [RawOutput], name: Option<&str>) -> Result<&'a RawOutput, LayoutError> {
    match name {
        Some(n) => outs.iter().find(|o| o.name == n).ok_or_else(|| {
            LayoutError(format!(
                "model has no output `{n}` (outputs: {})",
                outs.iter().map(|o| o.name.as_str()).collect::<Vec<_>>().join(", ")
            ))
        }),
        None => outs.first().ok_or_else(|| LayoutError("model produced no outputs".into())),
    }
}

/// Drops leading size-1 dimensions beyond `rank` (batch 1) and checks the rank.
fn squeeze<'a>(o: &'a RawOutput, rank: usize, what: &str) -> Result<&'a [usize], LayoutError> {
    let mut s = o.shape.as_slice();
    while s.len() > rank && s[0] == 1 {
        s = &s[1..];
    }
    if s.len() != rank {
        return Err(LayoutError(format!(
            "output `{}` has shape {:?}, the {what} layout needs rank {rank} (batch 1)",
            o.name, o.shape
        )));
    }
    Ok(s)
}

/// Decodes `outs` under `layout` for an input of `input_w × input_h`, mapping boxes by `map`.
pub fn decode(
    layout: &OutputLayout,
    outs: &[RawOutput],
    input_w: usize,
    input_h: usize,
    num_classes: usize,
    map: &InputMap,
) -> Result<Proposals, LayoutError> {
    let mut p;
    match layout {
        OutputLayout::Darknet { heads } => {
            p = Proposals::with_capacity(num_classes, 0);
            for head in heads {
                let o = find(outs, Some(&head.output))?;
                let s = squeeze(o, 3, "darknet")?;
                let (ch, gh, gw) = (s[0], s[1], s[2]);
                let na = head.anchors.len();
                if ch != na * (5 + num_classes) {
                    return Err(LayoutError(format!(
                        "output `{}` has {ch} channels; {na} anchors × (5 + {num_classes} classes) = {} expected",
                        o.name,
                        na * (5 + num_classes)
                    )));
                }
                let (sx, sy) = (input_w as f32 / gw as f32, input_h as f32 / gh as f32);
                let plane = gh * gw;
                for (a, anchor) in head.anchors.iter().enumerate() {
                    let base = a * (5 + num_classes) * plane;
                    for y in 0..gh {
                        for x in 0..gw {
                            let at = |k: usize| o.data[base + k * plane + y * gw + x];
                            let cx = (sigmoid(at(0)) + x as f32) * sx;
                            let cy = (sigmoid(at(1)) + y as f32) * sy;
                            let w = at(2).exp() * anchor[0];
                            let h = at(3).exp() * anchor[1];
                            let obj = sigmoid(at(4));
                            p.boxes.push(map.to_frame([cx - w / 2.0, cy - h / 2.0, cx + w / 2.0, cy + h / 2.0]));
                            p.scores.extend((0..num_classes).map(|c| obj * sigmoid(at(5 + c))));
                        }
                    }
                }
            }
        }
        OutputLayout::Yolox { output, strides } => {
            let o = find(outs, output.as_deref())?;
            let s = squeeze(o, 2, "yolox")?;
            let (rows, cols) = (s[0], s[1]);
            let expect_rows: usize = strides.iter().map(|st| (input_h / st) * (input_w / st)).sum();
            if cols != 5 + num_classes || rows != expect_rows {
                return Err(LayoutError(format!(
                    "output `{}` is {rows}×{cols}; yolox with strides {strides:?} at {input_w}×{input_h} and {num_classes} classes needs {expect_rows}×{}",
                    o.name,
                    5 + num_classes
                )));
            }
            p = Proposals::with_capacity(num_classes, rows);
            let mut r = 0;
            for &st in strides {
                for gy in 0..input_h / st {
                    for gx in 0..input_w / st {
                        let v = &o.data[r * cols..(r + 1) * cols];
                        let cx = (v[0] + gx as f32) * st as f32;
                        let cy = (v[1] + gy as f32) * st as f32;
                        let (w, h) = (v[2].exp() * st as f32, v[3].exp() * st as f32);
                        p.boxes.push(map.to_frame([cx - w / 2.0, cy - h / 2.0, cx + w / 2.0, cy + h / 2.0]));
                        p.scores.extend(v[5..].iter().map(|c| c * v[4]));
                        r += 1;
                    }
                }
            }
        }
        OutputLayout::Gfl { strides, bins } => {
            let shapes = || outs.iter().map(|o| format!("{} {:?}", o.name, o.shape)).collect::<Vec<_>>().join(", ");
            // Each level's maps, found by their row count and width.
            let level = |rows: usize, width: usize| {
                outs.iter().find(|o| {
                    let s = &o.shape;
                    s.len() >= 2
                        && s[s.len() - 2] == rows
                        && s[s.len() - 1] == width
                        && s[..s.len() - 2].iter().all(|d| *d == 1)
                })
            };
            let total: usize = strides.iter().map(|st| (input_h / st) * (input_w / st)).sum();
            p = Proposals::with_capacity(num_classes, total);
            for &st in strides {
                let (gw, gh) = (input_w / st, input_h / st);
                let rows = gw * gh;
                let (Some(cls), Some(reg)) = (level(rows, num_classes), level(rows, 4 * bins)) else {
                    return Err(LayoutError(format!(
                        "gfl at {input_w}×{input_h}: stride {st} needs a [1, {rows}, {num_classes}] class map and a [1, {rows}, {}] box map; the model's outputs are {}",
                        4 * bins,
                        shapes()
                    )));
                };
                let half = (st as f32 - 1.0) / 2.0;
                for r in 0..rows {
                    let (cx, cy) = ((r % gw * st) as f32 + half, (r / gw * st) as f32 + half);
                    let mut d = [0f32; 4];
                    for (side, dist) in d.iter_mut().enumerate() {
                        let logits = &reg.data[(r * 4 + side) * bins..(r * 4 + side + 1) * bins];
                        let m = logits.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
                        let e: Vec<f32> = logits.iter().map(|v| (v - m).exp()).collect();
                        let z: f32 = e.iter().sum();
                        *dist = e.iter().enumerate().map(|(k, v)| k as f32 * v).sum::<f32>() / z * st as f32;
                    }
                    let clip = |v: f32, hi: usize| v.clamp(0.0, hi as f32);
                    p.boxes.push(map.to_frame([
                        clip(cx - d[0], input_w),
                        clip(cy - d[1], input_h),
                        clip(cx + d[2], input_w),
                        clip(cy + d[3], input_h),
                    ]));
                    p.scores.extend_from_slice(&cls.data[r * num_classes..(r + 1) * num_classes]);
                }
            }
        }
        OutputLayout::Ultralytics { output } => {
            let o = find(outs, output.as_deref())?;
            let s = squeeze(o, 2, "ultralytics")?;
            let (feat, n) = (s[0], s[1]);
            if feat != 4 + num_classes {
                return Err(LayoutError(format!(
                    "output `{}` is {feat}×{n}; ultralytics with {num_classes} classes needs {}×N (cx, cy, w, h, classes)",
                    o.name,
                    4 + num_classes
                )));
            }
            p = Proposals::with_capacity(num_classes, n);
            let at = |f: usize, i: usize| o.data[f * n + i];
            for i in 0..n {
                let (cx, cy, w, h) = (at(0, i), at(1, i), at(2, i), at(3, i));
                p.boxes.push(map.to_frame([cx - w / 2.0, cy - h / 2.0, cx + w / 2.0, cy + h / 2.0]));
                p.scores.extend((0..num_classes).map(|c| at(4 + c, i)));
            }
        }
        OutputLayout::Rows { output, columns, frame, .. } => {
            let width = columns.len();
            let o = match output {
                Some(_) => find(outs, output.as_deref())?,
                None => outs.iter().find(|o| squeeze(o, 2, "rows").is_ok_and(|s| s[1] == width)).ok_or_else(|| {
                    LayoutError(format!(
                        "no output holds rows of {width} columns (outputs: {})",
                        outs.iter().map(|o| format!("`{}` {:?}", o.name, o.shape)).collect::<Vec<_>>().join(", ")
                    ))
                })?,
            };
            let s = squeeze(o, 2, "rows")?;
            if s[1] != width {
                return Err(LayoutError(format!(
                    "output `{}` has rows of {} values, the config names {width} columns",
                    o.name, s[1]
                )));
            }
            let col = |c: Column| columns.iter().position(|k| *k == c).unwrap_or(0);
            let (ci, si) = (col(Column::Class), col(Column::Score));
            let corners = [Column::X1, Column::Y1, Column::X2, Column::Y2].map(col);
            // Boxes the graph mapped back itself are only clipped to the frame.
            let to_frame = match frame {
                BoxFrame::Input => *map,
                BoxFrame::Image => InputMap { scale_x: 1.0, scale_y: 1.0, pad_x: 0.0, pad_y: 0.0, ..*map },
            };
            p = Proposals::with_capacity(num_classes, s[0]);
            for r in o.data.chunks_exact(width) {
                let class = r[ci];
                // Exports pad to a fixed row count with class −1.
                if class < 0.0 || class as usize >= num_classes {
                    continue;
                }
                p.boxes.push(to_frame.to_frame(corners.map(|c| r[c])));
                let mut row = vec![0f32; num_classes];
                row[class as usize] = r[si];
                p.scores.extend(row);
            }
        }
        OutputLayout::Detr { labels, boxes, scores, .. } => {
            let (l, b, sc) = (find(outs, Some(labels))?, find(outs, Some(boxes))?, find(outs, Some(scores))?);
            let q = squeeze(l, 1, "detr")?[0];
            let bs = squeeze(b, 2, "detr")?;
            let ss = squeeze(sc, 1, "detr")?;
            if bs != [q, 4] || ss != [q] {
                return Err(LayoutError(format!(
                    "detr outputs disagree: labels {:?}, boxes {:?}, scores {:?} (need [Q], [Q,4], [Q])",
                    l.shape, b.shape, sc.shape
                )));
            }
            p = Proposals::with_capacity(num_classes, q);
            for i in 0..q {
                let label = l.data[i];
                let mut row = vec![0f32; num_classes];
                if label >= 0.0 && (label as usize) < num_classes {
                    row[label as usize] = sc.data[i];
                }
                let bb = &b.data[i * 4..i * 4 + 4];
                p.boxes.push(map.to_frame([bb[0], bb[1], bb[2], bb[3]]));
                p.scores.extend(row);
            }
        }
    }
    if let Some(bad) = p.scores.iter().position(|s| !s.is_finite()) {
        return Err(LayoutError(format!(
            "non-finite score at proposal {} class {}",
            bad / num_classes.max(1),
            bad % num_classes.max(1)
        )));
    }
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::config::HeadConfig;

    const ID: InputMap = InputMap { scale_x: 1.0, scale_y: 1.0, pad_x: 0.0, pad_y: 0.0, frame_w: 1e6, frame_h: 1e6 };

    fn logit(p: f32) -> f32 {
        (p / (1.0 - p)).ln()
    }

    #[test]
    fn darknet_head_decodes_one_anchor_cell() {
        // 1 anchor, 2 classes, 2x2 grid at 64x64 input (stride 32); cell (x=1, y=0) holds the object.
        let (na, nc, g) = (1, 2, 2);
        let mut data = vec![-20f32; na * (5 + nc) * g * g];
        let set = |d: &mut Vec<f32>, k: usize, v: f32| d[k * 4 + 1] = v;
        set(&mut data, 0, 0.0); // sigmoid 0.5 -> cx = (0.5+1)*32 = 48
        set(&mut data, 1, 0.0); // cy = 16
        set(&mut data, 2, 0.0); // w = anchor 10
        set(&mut data, 3, (2.0f32).ln()); // h = 2*anchor 7 = 14
        set(&mut data, 4, logit(0.8));
        set(&mut data, 6, logit(0.5));
        let outs = [RawOutput { name: "h".into(), shape: vec![1, 7, 2, 2], data }];
        let layout =
            OutputLayout::Darknet { heads: vec![HeadConfig { output: "h".into(), anchors: vec![[10.0, 7.0]] }] };
        let p = decode(&layout, &outs, 64, 64, nc, &ID).unwrap();
        assert_eq!(p.len(), 4);
        let t = p.best(&[1]).unwrap();
        assert!((t.score - 0.4).abs() < 1e-5);
        let expect = [43.0, 9.0, 53.0, 23.0];
        assert!(t.bbox.iter().zip(expect).all(|(a, b)| (a - b).abs() < 1e-4), "{:?}", t.bbox);
    }

    #[test]
    fn yolox_rows_follow_grid_order_and_multiply_objectness() {
        // 8x8 input, strides [4, 8] -> 4 + 1 rows, 1 class.
        let mut data = vec![0f32; 5 * 6];
        let r = 3; // stride 4, gx=1, gy=1
        data[r * 6..r * 6 + 6].copy_from_slice(&[0.5, 0.5, 0.0, 0.0, 0.9, 0.5]);
        let outs = [RawOutput { name: "o".into(), shape: vec![1, 5, 6], data }];
        let p = decode(&OutputLayout::Yolox { output: None, strides: vec![4, 8] }, &outs, 8, 8, 1, &ID).unwrap();
        let t = p.best(&[0]).unwrap();
        assert!((t.score - 0.45).abs() < 1e-6);
        assert_eq!(t.bbox, [4.0, 4.0, 8.0, 8.0]);
        let wrong = decode(&OutputLayout::Yolox { output: None, strides: vec![8] }, &outs, 8, 8, 1, &ID).unwrap_err();
        assert!(wrong.to_string().contains("needs 1×6"), "{wrong}");
    }

    #[test]
    fn gfl_takes_the_expected_distance_from_the_cell_centre_and_matches_outputs_by_shape() {
        // One 2×2 level of stride 4 at 8×8, one class, 2 bins: every side's distribution puts
        // weight 0.5 on bins 0 and 1, so each distance is 0.5 × 4 = 2.
        let reg = RawOutput { name: "795".into(), shape: vec![1, 4, 8], data: vec![0.0; 32] };
        let cls = RawOutput { name: "792".into(), shape: vec![1, 4, 1], data: vec![0.1, 0.9, 0.2, 0.3] };
        let l = OutputLayout::Gfl { strides: vec![4], bins: 2 };
        let p = decode(&l, &[reg.clone(), cls.clone()], 8, 8, 1, &ID).unwrap();
        let t = p.best(&[0]).unwrap();
        assert!((t.score - 0.9).abs() < 1e-6);
        // Cell (1, 0): centre (4 + 1.5, 1.5); the box clipped at the top.
        assert_eq!(t.bbox, [3.5, 0.0, 7.5, 3.5]);
        let wrong = decode(&OutputLayout::Gfl { strides: vec![4], bins: 4 }, &[reg, cls], 8, 8, 1, &ID).unwrap_err();
        assert!(
            wrong.to_string().contains("[1, 4, 16] box map") && wrong.to_string().contains("795 [1, 4, 8]"),
            "{wrong}"
        );
    }

    #[test]
    fn ultralytics_is_feature_major_and_detr_keeps_label() {
        // 2 proposals, 2 classes: layout [4+2, 2]
        let data = vec![10., 20., 10., 20., 4., 4., 4., 4., 0.1, 0.7, 0.3, 0.2];
        let outs = [RawOutput { name: "o".into(), shape: vec![1, 6, 2], data }];
        let p = decode(&OutputLayout::Ultralytics { output: None }, &outs, 32, 32, 2, &ID).unwrap();
        assert_eq!(p.best(&[0]).unwrap().score, 0.7);
        assert_eq!(p.best(&[0]).unwrap().bbox, [18.0, 18.0, 22.0, 22.0]);
        let outs = [
            RawOutput { name: "l".into(), shape: vec![1, 2], data: vec![1.0, 0.0] },
            RawOutput { name: "b".into(), shape: vec![1, 2, 4], data: vec![0., 0., 1., 1., 2., 2., 3., 3.] },
            RawOutput { name: "s".into(), shape: vec![1, 2], data: vec![0.9, 0.2] },
        ];
        let l = OutputLayout::Detr {
            labels: "l".into(),
            boxes: "b".into(),
            scores: "s".into(),
            size_input: None,
            logits: None,
            pred_boxes: None,
        };
        let p = decode(&l, &outs, 32, 32, 2, &ID).unwrap();
        assert_eq!(p.best(&[1]).unwrap().score, 0.9);
        assert_eq!(p.best(&[0]).unwrap().bbox, [2.0, 2.0, 3.0, 3.0]);
    }

    #[test]
    fn rows_skip_empty_ones_and_map_boxes_by_their_frame() {
        // PicoDet's order (class, score, box), padded with a class −1 row, behind a count output.
        let outs = vec![
            RawOutput { name: "n".into(), shape: vec![1], data: vec![2.0] },
            RawOutput {
                name: "r".into(),
                shape: vec![3, 6],
                data: vec![1.0, 0.8, 4.0, 4.0, 8.0, 8.0, 0.0, 0.6, 0.0, 0.0, 2.0, 2.0, -1.0, 0.9, 0.0, 0.0, 1.0, 1.0],
            },
        ];
        let half = InputMap { scale_x: 0.5, scale_y: 0.5, pad_x: 0.0, pad_y: 0.0, frame_w: 100.0, frame_h: 100.0 };
        let layout = |frame| OutputLayout::Rows {
            output: None,
            columns: crate::detect::config::Column::xyxy_rows(),
            frame,
            scores: None,
            boxes: None,
        };
        let p = decode(&layout(BoxFrame::Input), &outs, 32, 32, 2, &half).unwrap();
        assert_eq!(p.len(), 2);
        assert_eq!(p.best(&[1]).unwrap().bbox, [8.0, 8.0, 16.0, 16.0]);
        assert_eq!(p.best(&[0]).unwrap().score, 0.6);
        let p = decode(&layout(BoxFrame::Image), &outs, 32, 32, 2, &half).unwrap();
        assert_eq!(p.best(&[1]).unwrap().bbox, [4.0, 4.0, 8.0, 8.0]);
        // Rows of another width are refused by name.
        let l = OutputLayout::Rows {
            output: Some("r".into()),
            columns: vec![Column::Class; 7],
            frame: BoxFrame::Input,
            scores: None,
            boxes: None,
        };
        assert!(decode(&l, &outs, 32, 32, 2, &half).unwrap_err().to_string().contains("7 columns"));
    }

    #[test]
    fn empty_proposals_have_no_best_and_no_detections() {
        let p = Proposals::with_capacity(80, 0);
        assert!(p.best(&[2]).is_none());
        assert!(p.detections(0.0, 0.5).is_empty());
    }
}
