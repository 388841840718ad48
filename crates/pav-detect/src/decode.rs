//! Raw model outputs → scored proposals in frame pixels, for each supported output layout.

use super::config::{BoxFrame, OutputLayout};
use super::layout::{sigmoid, Activation, Arrange, CellOrder, Centre, Description, Encoding, Role};
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

fn find<'a>(outs: &'a [RawOutput], name: &str) -> Result<&'a RawOutput, LayoutError> {
    outs.iter().find(|o| o.name == name).ok_or_else(|| {
        LayoutError(format!(
            "model has no output `{name}` (outputs: {})",
            outs.iter().map(|o| o.name.as_str()).collect::<Vec<_>>().join(", ")
        ))
    })
}

/// The model's outputs with their shapes, for messages.
fn listing(outs: &[RawOutput]) -> String {
    outs.iter().map(|o| format!("`{}` {:?}", o.name, o.shape)).collect::<Vec<_>>().join(", ")
}

/// One part's tensor for one level (or for every row), read by row and value.
struct View<'a> {
    data: &'a [f32],
    /// Its output's position among the decoded outputs.
    output: usize,
    rows: usize,
    width: usize,
    arrange: Arrange,
    /// Cells of a `planes` map.
    plane: usize,
}

impl View<'_> {
    #[inline]
    fn at(&self, r: usize, f: usize) -> f32 {
        self.data[self.index(r, f)]
    }

    /// Where value `f` of row `r` sits in the output's data.
    #[inline]
    fn index(&self, r: usize, f: usize) -> usize {
        match self.arrange {
            Arrange::Rows => r * self.width + f,
            Arrange::Columns => f * self.rows + r,
            Arrange::Planes => ((r / self.plane) * self.width + f) * self.plane + r % self.plane,
        }
    }

    /// Appends values `f .. f + n` of row `r` to `out`.
    #[inline]
    fn gather(&self, r: usize, f: usize, n: usize, out: &mut Vec<f32>) {
        match self.arrange {
            Arrange::Rows => out.extend_from_slice(&self.data[r * self.width + f..r * self.width + f + n]),
            Arrange::Columns => out.extend(self.data[f * self.rows + r..].iter().step_by(self.rows).take(n)),
            Arrange::Planes => {
                let base = (r / self.plane) * self.width * self.plane + r % self.plane;
                out.extend(self.data[base + f * self.plane..].iter().step_by(self.plane).take(n))
            }
        }
    }
}

/// The rows, row width and (for `planes`) grid `(h, w)` of an output read as `arrange`, after
/// leading batch dimensions of 1; None when its rank does not fit.
fn read_as(o: &RawOutput, arrange: Arrange, width: usize) -> Option<(usize, usize, (usize, usize))> {
    let rank = if arrange == Arrange::Planes { 3 } else { 2 };
    let mut s = o.shape.as_slice();
    if width == 1 && arrange == Arrange::Rows && s.last() == Some(&1) && s.len() > 1 {
        s = &s[..s.len() - 1];
    }
    let single = width == 1 && arrange == Arrange::Rows;
    while s.len() > rank && s[0] == 1 || single && s.len() > 1 && s[0] == 1 {
        s = &s[1..];
    }
    match (arrange, s) {
        (Arrange::Rows, [r]) if single => Some((*r, 1, (0, 0))),
        (Arrange::Rows, [r, w]) => Some((*r, *w, (0, 0))),
        // A grid of rows `[H, W, C]` (channels last): a row per cell.
        (Arrange::Rows, [h, gw, w]) if !single => Some((h * gw, *w, (0, 0))),
        (Arrange::Columns, [w, r]) => Some((*r, *w, (0, 0))),
        (Arrange::Planes, [c, h, w]) if width > 0 && c % width == 0 => Some((c / width * h * w, width, (*h, *w))),
        _ => None,
    }
}

/// One grid level as decoded: cells, steps in input pixels, anchors.
struct Grid {
    gw: usize,
    gh: usize,
    sx: f32,
    sy: f32,
    anchors: Vec<[f32; 2]>,
    /// Whether a cell's anchors share one row of the tensors (`order = "in-row"`).
    in_row: bool,
}

impl Grid {
    fn anchors(&self) -> usize {
        self.anchors.len().max(1)
    }

    /// Its proposals.
    fn rows(&self) -> usize {
        self.gw * self.gh * self.anchors()
    }

    /// Its rows in the tensors: a row per cell when its anchors share one.
    fn tensor_rows(&self) -> usize {
        if self.in_row {
            self.gw * self.gh
        } else {
            self.rows()
        }
    }
}

/// A part's tensors: one per level, or one for every row.
fn locate<'a>(
    d: &Description,
    role: Role,
    outs: &'a [RawOutput],
    grids: &[Grid],
    classes: usize,
) -> Result<Vec<View<'a>>, LayoutError> {
    let p = d.part(role);
    let width = d.width(role, classes);
    let t = role.table();
    let what = |rows: Option<usize>| {
        let r = rows.map_or("R".to_string(), |r| r.to_string());
        match p.arrange {
            Arrange::Rows => format!("[{r}, {width}]"),
            Arrange::Columns => format!("[{width}, {r}]"),
            Arrange::Planes => format!("[{} anchors × {width}, H, W] maps", r),
        }
    };
    // The output read as the part's arrangement, when its width and rows are the part's.
    let fits = |o: &RawOutput, rows: Option<usize>| {
        read_as(o, p.arrange, width).filter(|(r, w, _)| *w == width && rows.is_none_or(|n| n == *r))
    };
    let view = |o: &'a RawOutput, rows: Option<usize>| -> Result<View<'a>, LayoutError> {
        let Some((r, w, (gh, gw))) = fits(o, rows) else {
            return Err(LayoutError(format!(
                "[{t}] needs output `{}` as {}; it is {:?} (outputs: {})",
                o.name,
                what(rows),
                o.shape,
                listing(outs)
            )));
        };
        let output = outs.iter().position(|x| std::ptr::eq(x, o)).unwrap_or(0);
        Ok(View { data: &o.data, output, rows: r, width: w, arrange: p.arrange, plane: gh * gw })
    };
    let pick = |rows: Option<usize>, level: Option<usize>| -> Result<View<'a>, LayoutError> {
        let fit: Vec<&RawOutput> = outs.iter().filter(|o| fits(o, rows).is_some()).collect();
        let at = level.map(|l| format!(" for level {}", l + 1)).unwrap_or_default();
        match fit.as_slice() {
            [o] => view(o, rows),
            [] => Err(LayoutError(format!(
                "[{t}]{at} needs an output shaped {}; the model's outputs are {}",
                what(rows),
                listing(outs)
            ))),
            many => Err(LayoutError(format!(
                "[{t}]{at}: outputs {} all fit {}; name one with `output`",
                many.iter().map(|o| format!("`{}`", o.name)).collect::<Vec<_>>().join(", "),
                what(rows)
            ))),
        }
    };
    if p.per_level {
        let planes = p.arrange == Arrange::Planes;
        grids
            .iter()
            .enumerate()
            .map(|(l, g)| {
                let rows = (!planes || d.levels[l].stride.is_some()).then(|| g.tensor_rows());
                match p.output.get(l) {
                    Some(n) => view(find(outs, n)?, rows),
                    None => pick(rows, Some(l)),
                }
            })
            .collect()
    } else {
        let rows = (!grids.is_empty()).then(|| grids.iter().map(Grid::tensor_rows).sum());
        Ok(vec![match p.output.first() {
            Some(n) => view(find(outs, n)?, rows)?,
            None => pick(rows, None)?,
        }])
    }
}

/// The levels' grids: from their strides, or from the boxes' maps for a `planes` level without.
fn grids(
    d: &Description,
    outs: &[RawOutput],
    input_w: usize,
    input_h: usize,
    classes: usize,
) -> Result<Vec<Grid>, LayoutError> {
    d.levels
        .iter()
        .enumerate()
        .map(|(l, level)| {
            let (gw, gh, sx, sy) = match level.stride {
                Some(st) => (input_w / st, input_h / st, st as f32, st as f32),
                None => {
                    let width = d.width(Role::Boxes, classes);
                    let name = d.boxes.output.get(l).map(String::as_str).unwrap_or("");
                    let o = find(outs, name)?;
                    let Some((_, _, (gh, gw))) = read_as(o, Arrange::Planes, width).filter(|(r, _, (gh, gw))| *r == gh * gw * level.anchors.len().max(1)) else {
                        return Err(LayoutError(format!(
                            "output `{}` has shape {:?}; level {} needs {} anchors × {width} channels over an H × W grid",
                            o.name,
                            o.shape,
                            l + 1,
                            level.anchors.len().max(1)
                        )));
                    };
                    (gw, gh, input_w as f32 / gw as f32, input_h as f32 / gh as f32)
                }
            };
            Ok(Grid { gw, gh, sx, sy, anchors: level.anchors.clone(), in_row: d.order == CellOrder::InRow })
        })
        .collect()
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
    decode_described(&layout.describe(num_classes), outs, input_w, input_h, num_classes, map)
}

/// A part's view for level `l` and the row in it of the level's first row (`start` in a tensor
/// of every level).
fn level_view<'v, 'o>(views: &'v [View<'o>], l: usize, start: usize) -> (&'v View<'o>, usize) {
    if views.len() == 1 {
        (&views[0], start)
    } else {
        (&views[l], 0)
    }
}

/// Where a row's box is anchored: its cell, the grid's step, its anchor and the cell's point.
struct Anchor {
    gx: f32,
    gy: f32,
    sx: f32,
    sy: f32,
    aw: f32,
    ah: f32,
    cx0: f32,
    cy0: f32,
    /// Its row among the level's rows of the tensors, and its place among the anchors of that
    /// row (0 unless the cell's anchors share a row).
    row: usize,
    slot: usize,
}

impl Anchor {
    /// Proposal `lr` of level `g`.
    fn of(d: &Description, g: &Grid, lr: usize) -> Self {
        let (cells, na) = (g.gw * g.gh, g.anchors());
        let (a, cell) = match d.order {
            CellOrder::AnchorCell => (lr / cells, lr % cells),
            CellOrder::CellAnchor | CellOrder::InRow => (lr % na, lr / na),
        };
        let (gx, gy) = ((cell % g.gw) as f32, (cell / g.gw) as f32);
        let [aw, ah] = g.anchors.get(a).copied().unwrap_or([g.sx, g.sy]);
        let (cx0, cy0) = match d.centre {
            Centre::Cell => ((gx + 0.5) * g.sx, (gy + 0.5) * g.sy),
            Centre::Pixel => (gx * g.sx + (g.sx - 1.0) / 2.0, gy * g.sy + (g.sy - 1.0) / 2.0),
        };
        let (row, slot) = if g.in_row { (cell, a) } else { (lr, 0) };
        Anchor { gx, gy, sx: g.sx, sy: g.sy, aw, ah, cx0, cy0, row, slot }
    }
}

/// What a box reads, as (output, index in its data, ∂[x1, y1, x2, y2] of the frame box).
pub type BoxTerm = (usize, usize, [f32; 4]);

/// How a description's boxes are read.
struct BoxReader {
    enc: Encoding,
    cols: [usize; 4],
    column: usize,
    /// Columns from one anchor's box to the next's in a shared row.
    anchor_step: usize,
    /// The encoding's own functions are already applied.
    activated: bool,
    /// The input's width and height, which `tanh-share` sizes are shares of.
    input: [f32; 2],
    bins: usize,
    var: [f32; 2],
    norm: [f32; 2],
    /// The input's size, when boxes are clipped to it.
    clip: Option<[f32; 2]>,
    to_frame: InputMap,
}

/// `cx, cy, w, h` as corners, with the corners' derivatives by the four values when each of
/// `dc` is the derivative of `cx, cy, w, h` by the one value it reads.
fn corners(c: [f32; 4], dc: [f32; 4]) -> (BBox, [[f32; 4]; 4]) {
    let [cx, cy, w, h] = c;
    let b = [cx - w / 2.0, cy - h / 2.0, cx + w / 2.0, cy + h / 2.0];
    let [a, e, f, g] = dc;
    (b, [[a, 0.0, a, 0.0], [0.0, e, 0.0, e], [-f / 2.0, 0.0, f / 2.0, 0.0], [0.0, -g / 2.0, 0.0, g / 2.0]])
}

/// Corners read one value each, scaled by `d`.
fn diagonal(b: BBox, d: [f32; 4]) -> (BBox, [[f32; 4]; 4]) {
    let mut j = [[0f32; 4]; 4];
    (0..4).for_each(|k| j[k][k] = d[k]);
    (b, j)
}

impl BoxReader {
    fn new(d: &Description, input_w: usize, input_h: usize, map: &InputMap) -> Self {
        let b = &d.boxes;
        let (w, h) = (input_w as f32, input_h as f32);
        BoxReader {
            enc: b.encoding.unwrap_or(Encoding::Xyxy),
            cols: b.coords.unwrap_or([b.column, b.column + 1, b.column + 2, b.column + 3]),
            column: b.column,
            anchor_step: b.anchor_step,
            activated: b.activated,
            input: [w, h],
            bins: b.bins.unwrap_or(0),
            var: b.variances.unwrap_or([1.0, 1.0]),
            norm: if b.normalized { [w, h] } else { [1.0, 1.0] },
            clip: b.clip.then_some([w, h]),
            // Boxes the graph mapped back itself are only clipped to the frame.
            to_frame: match b.frame {
                BoxFrame::Input => *map,
                BoxFrame::Image => InputMap { scale_x: 1.0, scale_y: 1.0, pad_x: 0.0, pad_y: 0.0, ..*map },
            },
        }
    }

    /// Row `r` of `v`'s box in frame pixels; with `jac`, every value it reads is pushed with the
    /// box's derivative by it.
    fn read(&self, v: &View, r: usize, a: &Anchor, jac: Option<&mut Vec<BoxTerm>>) -> BBox {
        let shift = a.slot * self.anchor_step;
        let val = |k: usize| v.at(r, self.cols[k] + shift);
        // The encoding's sigmoid and tanh with their derivatives, or nothing when the graph
        // applied them.
        let sig = |x: f32| if self.activated { (x, 1.0) } else { (sigmoid(x), sigmoid(x) * (1.0 - sigmoid(x))) };
        let tanh = |x: f32| if self.activated { (x, 1.0) } else { (x.tanh(), 1.0 - x.tanh() * x.tanh()) };
        let [nx, ny] = self.norm;
        let [var_c, var_s] = self.var;
        let (bx, dv) = match self.enc {
            Encoding::Xyxy => diagonal([val(0) * nx, val(1) * ny, val(2) * nx, val(3) * ny], [nx, ny, nx, ny]),
            Encoding::Cxcywh => corners([val(0) * nx, val(1) * ny, val(2) * nx, val(3) * ny], [nx, ny, nx, ny]),
            Encoding::Grid => {
                let (w, h) = (val(2).exp() * a.aw, val(3).exp() * a.ah);
                corners([(val(0) + a.gx) * a.sx, (val(1) + a.gy) * a.sy, w, h], [a.sx, a.sy, w, h])
            }
            Encoding::Darknet => {
                let ((s0, d0), (s1, d1)) = (sig(val(0)), sig(val(1)));
                let (w, h) = (val(2).exp() * a.aw, val(3).exp() * a.ah);
                let d = [d0 * a.sx, d1 * a.sy, w, h];
                corners([(s0 + a.gx) * a.sx, (s1 + a.gy) * a.sy, w, h], d)
            }
            Encoding::TanhShare => {
                let ((t0, d0), (t1, d1)) = (tanh(val(0)), tanh(val(1)));
                let ((s2, d2), (s3, d3)) = (sig(val(2)), sig(val(3)));
                let [iw, ih] = self.input;
                let c = [(a.gx + t0) * a.sx, (a.gy + t1) * a.sy, s2 * iw, s3 * ih];
                corners(c, [d0 * a.sx, d1 * a.sy, d2 * iw, d3 * ih])
            }
            Encoding::Yolov5 => {
                let (s, ds) = ([0, 1, 2, 3].map(|k| sig(val(k)).0), [0, 1, 2, 3].map(|k| sig(val(k)).1));
                let c = [
                    (s[0] * 2.0 - 0.5 + a.gx) * a.sx,
                    (s[1] * 2.0 - 0.5 + a.gy) * a.sy,
                    (s[2] * 2.0).powi(2) * a.aw,
                    (s[3] * 2.0).powi(2) * a.ah,
                ];
                // d(2σ)²/dv = 8σ·σ'.
                let d = [2.0 * ds[0] * a.sx, 2.0 * ds[1] * a.sy, 8.0 * s[2] * ds[2] * a.aw, 8.0 * s[3] * ds[3] * a.ah];
                corners(c, d)
            }
            Encoding::Ltrb => diagonal(
                [a.cx0 - val(0) * a.sx, a.cy0 - val(1) * a.sy, a.cx0 + val(2) * a.sx, a.cy0 + val(3) * a.sy],
                [-a.sx, -a.sy, a.sx, a.sy],
            ),
            Encoding::LtrbBins => return self.read_bins(v, r, a, jac),
            Encoding::Prior => {
                let (w, h) = (a.aw * (val(2) * var_s).exp(), a.ah * (val(3) * var_s).exp());
                let c = [a.cx0 + val(0) * var_c * a.aw, a.cy0 + val(1) * var_c * a.ah, w, h];
                corners(c, [var_c * a.aw, var_c * a.ah, w * var_s, h * var_s])
            }
        };
        let (b, keep) = self.finish(bx);
        if let Some(jac) = jac {
            for (k, d) in dv.iter().enumerate() {
                jac.push((v.output, v.index(r, self.cols[k] + shift), [0, 1, 2, 3].map(|j| d[j] * keep[j])));
            }
        }
        b
    }

    /// A GFL box: each side's distance the expectation of a softmax over `bins` values.
    fn read_bins(&self, v: &View, r: usize, a: &Anchor, jac: Option<&mut Vec<BoxTerm>>) -> BBox {
        let bins = self.bins;
        let mut dist = [0f32; 4];
        // Per side: the softmax and its expectation, for the derivative step·p_k·(k − E).
        let mut soft: Vec<(Vec<f32>, f32)> = Vec::new();
        let column = self.column + a.slot * self.anchor_step;
        for (side, out) in dist.iter_mut().enumerate() {
            let at = |k: usize| v.at(r, column + side * bins + k);
            // Already a distribution when the graph applied the softmax.
            let (e, z): (Vec<f32>, f32) = if self.activated {
                ((0..bins).map(at).collect(), 1.0)
            } else {
                let m = (0..bins).map(at).fold(f32::NEG_INFINITY, f32::max);
                let e: Vec<f32> = (0..bins).map(|k| (at(k) - m).exp()).collect();
                let z = e.iter().sum();
                (e, z)
            };
            let step = if side % 2 == 0 { a.sx } else { a.sy };
            let mean = e.iter().enumerate().map(|(k, v)| k as f32 * v).sum::<f32>() / z;
            *out = mean * step;
            if jac.is_some() {
                soft.push((e.iter().map(|e| e / z).collect(), mean));
            }
        }
        let (b, keep) = self.finish([a.cx0 - dist[0], a.cy0 - dist[1], a.cx0 + dist[2], a.cy0 + dist[3]]);
        if let Some(jac) = jac {
            for (side, (p, mean)) in soft.iter().enumerate() {
                let step = if side % 2 == 0 { a.sx } else { a.sy };
                let sign = if side < 2 { -1.0 } else { 1.0 };
                for (k, p) in p.iter().enumerate() {
                    let mut d = [0f32; 4];
                    // ∂E/∂p_k = k for a given distribution; through a softmax, p_k·(k − E).
                    let dk = if self.activated { k as f32 } else { p * (k as f32 - mean) };
                    d[side] = sign * step * dk * keep[side];
                    jac.push((v.output, v.index(r, column + side * bins + k), d));
                }
            }
        }
        b
    }

    /// The box clipped and mapped to the frame, and each corner's derivative through both (0
    /// where a corner was clamped).
    fn finish(&self, mut bx: BBox) -> (BBox, [f32; 4]) {
        let mut keep = [1f32; 4];
        if let Some([w, h]) = self.clip {
            for (k, c) in bx.iter_mut().enumerate() {
                let top = if k % 2 == 0 { w } else { h };
                if !(0.0..=top).contains(c) {
                    keep[k] = 0.0;
                }
                *c = c.clamp(0.0, top);
            }
        }
        let (b, d) = self.to_frame.to_frame_with_grad(bx);
        (b, [0, 1, 2, 3].map(|k| keep[k] * d[k]))
    }
}

/// Each box of [`decode`] (in its order) with its derivative by every raw value it is decoded
/// from: the exact backward of the boxes, for losses that move them.
pub fn box_jacobians(
    layout: &OutputLayout,
    outs: &[RawOutput],
    input_w: usize,
    input_h: usize,
    num_classes: usize,
    map: &InputMap,
) -> Result<Vec<(BBox, Vec<BoxTerm>)>, LayoutError> {
    box_jacobians_described(&layout.describe(num_classes), outs, input_w, input_h, num_classes, map)
}

/// [`box_jacobians`] under a [`Description`].
pub fn box_jacobians_described(
    d: &Description,
    outs: &[RawOutput],
    input_w: usize,
    input_h: usize,
    classes: usize,
    map: &InputMap,
) -> Result<Vec<(BBox, Vec<BoxTerm>)>, LayoutError> {
    let mut terms = Vec::new();
    let p = decode_rows(d, outs, input_w, input_h, classes, map, Some(&mut terms))?;
    Ok(p.boxes.into_iter().zip(terms).collect())
}

/// Decodes `outs` under a [`Description`].
pub fn decode_described(
    d: &Description,
    outs: &[RawOutput],
    input_w: usize,
    input_h: usize,
    classes: usize,
    map: &InputMap,
) -> Result<Proposals, LayoutError> {
    decode_rows(d, outs, input_w, input_h, classes, map, None)
}

/// A description's parts found among the outputs, with the grid their rows follow.
struct Located<'a> {
    levels: Vec<Grid>,
    boxes: Vec<View<'a>>,
    scores: Vec<View<'a>>,
    objectness: Option<Vec<View<'a>>>,
    labels: Option<Vec<View<'a>>>,
    /// Proposals over every level.
    total: usize,
}

/// One proposal: its anchor and, per part, the view and row that hold its values.
struct RowAt<'v, 'a> {
    anchor: Anchor,
    boxes: Option<(&'v View<'a>, usize)>,
    scores: (&'v View<'a>, usize),
    objectness: Option<(&'v View<'a>, usize)>,
    labels: Option<(&'v View<'a>, usize)>,
}

impl<'a> Located<'a> {
    /// Finds the parts of `d` among `outs` (the boxes only `with_boxes`) and checks that they
    /// agree on the rows.
    fn new(
        d: &Description,
        outs: &'a [RawOutput],
        input_w: usize,
        input_h: usize,
        classes: usize,
        with_boxes: bool,
    ) -> Result<Self, LayoutError> {
        let grids = grids(d, outs, input_w, input_h, classes)?;
        let boxes = if with_boxes { locate(d, Role::Boxes, outs, &grids, classes)? } else { Vec::new() };
        let scores = locate(d, Role::Scores, outs, &grids, classes)?;
        let objectness =
            d.objectness.as_ref().map(|_| locate(d, Role::Objectness, outs, &grids, classes)).transpose()?;
        let labels = d.labels.as_ref().map(|_| locate(d, Role::Labels, outs, &grids, classes)).transpose()?;
        // Without a grid, every part must hold as many rows as the boxes (the scores without).
        let first = boxes.first().unwrap_or(&scores[0]);
        let rows = if grids.is_empty() { first.rows } else { grids.iter().map(Grid::tensor_rows).sum() };
        for (role, v) in
            [(Role::Scores, Some(&scores)), (Role::Objectness, objectness.as_ref()), (Role::Labels, labels.as_ref())]
        {
            if let Some(v) = v.filter(|v| v.len() == 1 && v[0].rows != rows) {
                return Err(LayoutError(format!(
                    "[{}] holds {} rows, [output.{}] {rows} (outputs: {})",
                    role.table(),
                    v[0].rows,
                    if with_boxes { "boxes" } else { "scores" },
                    listing(outs)
                )));
            }
        }
        let levels = if grids.is_empty() {
            vec![Grid { gw: rows, gh: 1, sx: 1.0, sy: 1.0, anchors: Vec::new(), in_row: false }]
        } else {
            grids
        };
        let total = levels.iter().map(Grid::rows).sum();
        Ok(Located { levels, boxes, scores, objectness, labels, total })
    }

    /// Calls `f` with every proposal in order.
    fn each<'v>(
        &'v self,
        d: &Description,
        mut f: impl FnMut(RowAt<'v, 'a>) -> Result<(), LayoutError>,
    ) -> Result<(), LayoutError> {
        let mut start = 0;
        for (l, g) in self.levels.iter().enumerate() {
            for lr in 0..g.rows() {
                let anchor = Anchor::of(d, g, lr);
                let at = |views| {
                    let (v, o) = level_view(views, l, start);
                    (v, o + anchor.row)
                };
                let row = RowAt {
                    boxes: (!self.boxes.is_empty()).then(|| at(&self.boxes)),
                    scores: at(&self.scores),
                    objectness: self.objectness.as_deref().map(at),
                    labels: self.labels.as_deref().map(at),
                    anchor,
                };
                f(row)?;
            }
            start += g.tensor_rows();
        }
        Ok(())
    }
}

/// How a description turns one proposal's raw values into class scores, for a white box that
/// reads the same values with their derivatives ([`score_sites`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ScoreRule {
    /// Class score columns, the background's included.
    pub width: usize,
    /// The background column, dropped after the activation.
    pub background: Option<usize>,
    /// The function the class values still need.
    pub activation: Activation,
    /// The objectness's function, when the model has one.
    pub objectness: Option<Activation>,
    /// The powers of objectness and class score in the detection score, `obj^p · cls^q`.
    pub powers: [f32; 2],
}

/// Where one proposal's score values sit: each as (output, index in its data).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ScoreSite {
    /// The objectness value, when the model has one.
    pub objectness: Option<(usize, usize)>,
    /// The output, the index of the first class column, and the step from one column to the next.
    pub scores: (usize, usize, usize),
}

impl ScoreRule {
    /// The column (from the first score column) of class `k`: past a background column, one on.
    pub fn column(&self, k: usize) -> usize {
        match self.background {
            Some(bg) if k >= bg => k + 1,
            _ => k,
        }
    }

    /// The rule of `d` for `classes` classes.
    pub fn of(d: &Description, classes: usize) -> Self {
        let power = |p: Option<f32>| p.unwrap_or(1.0);
        ScoreRule {
            width: d.count(Role::Scores, classes),
            background: d.scores.background,
            activation: d.scores.activation,
            objectness: d.objectness.as_ref().map(|o| o.activation),
            powers: [power(d.objectness.as_ref().and_then(|o| o.power)), power(d.scores.power)],
        }
    }
}

/// Where every proposal of [`decode_described`]'s order reads its scores, for outputs of the
/// given names and shapes (their data is not read). Final detections (labels) are refused: their
/// scores passed through the graph's post-processor.
pub fn score_sites(
    d: &Description,
    outs: &[RawOutput],
    input_w: usize,
    input_h: usize,
    classes: usize,
) -> Result<Vec<ScoreSite>, LayoutError> {
    if d.labels.is_some() {
        return Err(LayoutError("final detections (labels) have no score sites".into()));
    }
    let at = Located::new(d, outs, input_w, input_h, classes, false)?;
    let mut sites = Vec::with_capacity(at.total);
    let (s, o) = (&d.scores, d.objectness.as_ref());
    at.each(d, |r| {
        let (v, row) = r.scores;
        let first = v.index(row, s.column + r.anchor.slot * s.anchor_step);
        let step = v.index(row, s.column + 1).wrapping_sub(v.index(row, s.column));
        let objectness =
            r.objectness.zip(o).map(|((v, row), p)| (v.output, v.index(row, p.column + r.anchor.slot * p.anchor_step)));
        sites.push(ScoreSite { objectness, scores: (v.output, first, step) });
        Ok(())
    })?;
    Ok(sites)
}

/// Which outputs (positions in `outs`) each part of `d` reads: boxes (only `with_boxes`),
/// scores, objectness.
pub fn part_outputs(
    d: &Description,
    outs: &[RawOutput],
    input_w: usize,
    input_h: usize,
    classes: usize,
    with_boxes: bool,
) -> Result<[Vec<usize>; 3], LayoutError> {
    let at = Located::new(d, outs, input_w, input_h, classes, with_boxes)?;
    let of = |v: &[View]| {
        let mut o: Vec<usize> = v.iter().map(|v| v.output).collect();
        o.dedup();
        o
    };
    Ok([of(&at.boxes), of(&at.scores), at.objectness.as_deref().map(of).unwrap_or_default()])
}

/// [`decode_described`], and with `jac` each box's derivatives by the values it reads, one list
/// per box.
fn decode_rows(
    d: &Description,
    outs: &[RawOutput],
    input_w: usize,
    input_h: usize,
    classes: usize,
    map: &InputMap,
    mut jac: Option<&mut Vec<Vec<BoxTerm>>>,
) -> Result<Proposals, LayoutError> {
    let at = Located::new(d, outs, input_w, input_h, classes, true)?;
    let reader = BoxReader::new(d, input_w, input_h, map);
    let s = &d.scores;
    let rule = ScoreRule::of(d, classes);
    let width = rule.width;
    let mut p = Proposals::with_capacity(classes, at.total);
    let mut logits = Vec::with_capacity(width);
    let (label_col, label_step) = d.labels.as_ref().map_or((0, 0), |p| (p.column, p.anchor_step));
    let (obj_col, obj_step) = d.objectness.as_ref().map_or((0, 0), |p| (p.column, p.anchor_step));
    let [obj_power, cls_power] = rule.powers;
    at.each(d, |r| {
        let slot = r.anchor.slot;
        let label = match r.labels {
            Some((v, row)) => {
                let label = v.at(row, label_col + slot * label_step);
                // Exports pad to a fixed row count with class −1.
                if label < 0.0 || label as usize >= classes {
                    return Ok(());
                }
                Some(label as usize)
            }
            None => None,
        };
        let terms = jac.as_deref_mut().map(|j| {
            j.push(Vec::new());
            j.last_mut().expect("just pushed")
        });
        let (bv, br) = r.boxes.expect("located with the boxes");
        p.boxes.push(reader.read(bv, br, &r.anchor, terms));
        let (sv, sr) = r.scores;
        let column = s.column + slot * s.anchor_step;
        if let Some(label) = label {
            let mut row = vec![0f32; classes];
            row[label] = s.activation.apply(sv.at(sr, column));
            p.scores.extend(row);
            return Ok(());
        }
        let from = p.scores.len();
        if s.activation == Activation::Softmax {
            logits.clear();
            sv.gather(sr, column, width, &mut logits);
            let m = logits.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
            let z: f32 = logits.iter().map(|x| (x - m).exp()).sum();
            let bg = s.background;
            p.scores.extend(logits.iter().enumerate().filter(|(k, _)| Some(*k) != bg).map(|(_, x)| (x - m).exp() / z));
        } else {
            match s.background {
                Some(bg) => {
                    sv.gather(sr, column, bg, &mut p.scores);
                    sv.gather(sr, column + bg + 1, width - bg - 1, &mut p.scores);
                }
                None => sv.gather(sr, column, width, &mut p.scores),
            }
        }
        let row = &mut p.scores[from..];
        if s.activation == Activation::Sigmoid {
            row.iter_mut().for_each(|x| *x = sigmoid(*x));
        }
        if cls_power != 1.0 {
            row.iter_mut().for_each(|x| *x = x.max(0.0).powf(cls_power));
        }
        if let Some((v, orow)) = r.objectness {
            let o = d
                .objectness
                .as_ref()
                .map_or(Activation::None, |p| p.activation)
                .apply(v.at(orow, obj_col + slot * obj_step));
            let o = if obj_power != 1.0 { o.max(0.0).powf(obj_power) } else { o };
            row.iter_mut().for_each(|x| *x *= o);
        }
        Ok(())
    })?;
    if let Some(bad) = p.scores.iter().position(|s| !s.is_finite()) {
        return Err(LayoutError(format!(
            "non-finite score at proposal {} class {}",
            bad / classes.max(1),
            bad % classes.max(1)
        )));
    }
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{Column, HeadConfig};

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
        assert!(wrong.to_string().contains("shaped [1, 6]") && wrong.to_string().contains("`o` [1, 5, 6]"), "{wrong}");
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
            wrong.to_string().contains("shaped [4, 16]") && wrong.to_string().contains("`795` [1, 4, 8]"),
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
            columns: crate::config::Column::xyxy_rows(),
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
        assert!(decode(&l, &outs, 32, 32, 2, &half).unwrap_err().to_string().contains("`r` as [R, 7]"));
    }

    fn described(toml: &str) -> OutputLayout {
        let d: Description = toml::from_str(toml).unwrap();
        d.validate(2).unwrap();
        OutputLayout::Custom(Box::new(d))
    }

    #[test]
    fn anchor_rows_flattened_with_activated_values_match_the_darknet_heads_they_come_from() {
        // Two levels (strides 16 and 32 at 32²) of two anchors, two classes: darknet planes, and
        // the same numbers decoded, flattened to rows (cx, cy, w, h, obj, classes) anchor by
        // anchor, as YOLOv5's export writes them.
        let (nc, anchors) = (2, [[[4.0, 6.0], [9.0, 5.0]], [[12.0, 20.0], [30.0, 24.0]]]);
        let heads: Vec<RawOutput> = [2usize, 1]
            .iter()
            .enumerate()
            .map(|(l, &g)| RawOutput {
                name: format!("h{l}"),
                shape: vec![1, 2 * (5 + nc), g, g],
                data: (0..2 * (5 + nc) * g * g).map(|k| ((k * 7 + l * 3) % 11) as f32 / 5.0 - 1.0).collect(),
            })
            .collect();
        let dark = OutputLayout::Darknet {
            heads: (0..2).map(|l| HeadConfig { output: format!("h{l}"), anchors: anchors[l].to_vec() }).collect(),
        };
        let want = decode(&dark, &heads, 32, 32, nc, &ID).unwrap();
        let mut rows = Vec::new();
        for (l, h) in heads.iter().enumerate() {
            let (g, st) = (h.shape[2], 32.0 / h.shape[2] as f32);
            for (a, [aw, ah]) in anchors[l].iter().enumerate() {
                for cell in 0..g * g {
                    let at = |k: usize| h.data[(a * (5 + nc) + k) * g * g + cell];
                    let (gx, gy) = ((cell % g) as f32, (cell / g) as f32);
                    rows.extend([
                        (sigmoid(at(0)) + gx) * st,
                        (sigmoid(at(1)) + gy) * st,
                        at(2).exp() * aw,
                        at(3).exp() * ah,
                    ]);
                    rows.extend((4..5 + nc).map(|k| sigmoid(at(k))));
                }
            }
        }
        let flat = [RawOutput { name: "output".into(), shape: vec![1, 10, 5 + nc], data: rows }];
        let got = decode(
            &described("[boxes]\nencoding = 'cxcywh'\n[objectness]\ncolumn = 4\n[scores]\ncolumn = 5\n"),
            &flat,
            32,
            32,
            nc,
            &ID,
        )
        .unwrap();
        assert_eq!(got.len(), 10);
        for i in 0..10 {
            let (a, b) = (got.boxes[i], want.boxes[i]);
            assert!(a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-5), "{i}: {a:?} vs {b:?}");
            assert!(got.row(i).iter().zip(want.row(i)).all(|(x, y)| (x - y).abs() < 1e-6), "{i}");
        }
        // The raw heads as one described layout (planes, darknet encoding) give the preset's
        // numbers bit for bit.
        let planes = "[[levels]]\nanchors = [[4, 6], [9, 5]]\n[[levels]]\nanchors = [[12, 20], [30, 24]]\n[boxes]\noutput = ['h0', 'h1']\narrange = 'planes'\nper_level = true\nencoding = 'darknet'\n[objectness]\noutput = ['h0', 'h1']\narrange = 'planes'\nper_level = true\ncolumn = 4\nactivation = 'sigmoid'\n[scores]\noutput = ['h0', 'h1']\narrange = 'planes'\nper_level = true\ncolumn = 5\nactivation = 'sigmoid'\n";
        assert_eq!(decode(&described(planes), &heads, 32, 32, nc, &ID).unwrap(), want);
    }

    #[test]
    fn ssd_priors_cell_by_cell_with_softmax_and_a_background_column() {
        // One level of stride 16 at 32² (2×2 cells), two priors per cell, cell by cell; boxes in
        // TensorFlow's order (ty, tx, th, tw); scores softmax over background + 2 classes.
        let mut boxes = vec![0f32; 8 * 4];
        let mut scores = vec![0f32; 8 * 3];
        // Row 5 = cell 2 (x 0, y 1), prior 1 (20 × 10): shifted right by 0.5 of its width, twice
        // as tall.
        boxes[5 * 4..5 * 4 + 4].copy_from_slice(&[0.0, 0.5 / 0.1, (2f32).ln() / 0.2, 0.0]);
        scores[5 * 3..5 * 3 + 3].copy_from_slice(&[0.0, (3f32).ln(), 0.0]);
        let outs = [
            RawOutput { name: "scores".into(), shape: vec![1, 8, 3], data: scores },
            RawOutput { name: "boxes".into(), shape: vec![1, 8, 4], data: boxes },
        ];
        let l = described(
            "order = 'cell-anchor'\n[[levels]]\nstride = 16\nanchors = [[10, 10], [20, 10]]\n[boxes]\nwidth = 4\nencoding = 'prior'\ncoords = [1, 0, 3, 2]\nvariances = [0.1, 0.2]\n[scores]\nwidth = 3\nactivation = 'softmax'\nbackground = 0\n",
        );
        let p = decode(&l, &outs, 32, 32, 2, &ID).unwrap();
        assert_eq!((p.len(), p.num_classes), (8, 2));
        // Softmax of (0, ln 3, 0): 3/5 for class 0, 1/5 for class 1; the background dropped.
        assert!((p.row(5)[0] - 0.6).abs() < 1e-6 && (p.row(5)[1] - 0.2).abs() < 1e-6, "{:?}", p.row(5));
        // Prior centre (8, 24), size 20 × 10 → centre (18, 24), size 20 × 20.
        let b = p.boxes[5];
        assert!(b.iter().zip([8.0, 14.0, 28.0, 34.0]).all(|(x, y)| (x - y).abs() < 1e-4), "{b:?}");
        assert!((p.row(0)[0] - 1.0 / 3.0).abs() < 1e-6);
        // A grid the scores do not fit is refused with the model's outputs.
        let wrong = described("order = 'cell-anchor'\n[[levels]]\nstride = 8\nanchors = [[10, 10], [20, 10]]\n[boxes]\nwidth = 4\nencoding = 'prior'\nvariances = [0.1, 0.2]\n[scores]\nwidth = 3\nactivation = 'softmax'\nbackground = 0\n");
        let e = decode(&wrong, &outs, 32, 32, 2, &ID).unwrap_err().to_string();
        assert!(e.contains("[32, 4]") && e.contains("`boxes` [1, 8, 4]"), "{e}");
    }

    #[test]
    fn point_distances_normalized_corners_and_labelled_rows_decode_as_described() {
        // ltrb: distances in strides from the cell centre; stride 16, cell (1, 0) → centre (24, 8).
        let outs =
            [RawOutput { name: "o".into(), shape: vec![1, 4, 6], data: [[0.5, 0.5, 0.5, 0.5, 0.9, 0.1]; 4].concat() }];
        let l = described("[[levels]]\nstride = 16\n[boxes]\nencoding = 'ltrb'\n[scores]\ncolumn = 4\n");
        let p = decode(&l, &outs, 32, 32, 2, &ID).unwrap();
        assert_eq!(p.boxes[1], [16.0, 0.0, 32.0, 16.0]);
        assert_eq!(p.row(1), [0.9, 0.1]);
        // Normalized corners, a label column, a score: final detections, padding skipped.
        let outs = [
            RawOutput { name: "det".into(), shape: vec![1, 2, 4], data: vec![0.25, 0.5, 0.5, 1.0, 0.0, 0.0, 1.0, 1.0] },
            RawOutput { name: "cls".into(), shape: vec![1, 2], data: vec![1.0, -1.0] },
            RawOutput { name: "conf".into(), shape: vec![1, 2, 1], data: vec![0.7, 0.9] },
        ];
        let l = described(
            "[boxes]\noutput = 'det'\nencoding = 'xyxy'\nnormalized = true\n[scores]\noutput = 'conf'\n[labels]\noutput = 'cls'\n",
        );
        let p = decode(&l, &outs, 32, 16, 2, &ID).unwrap();
        assert_eq!(p.len(), 1);
        assert_eq!((p.boxes[0], p.row(0)), ([8.0, 8.0, 16.0, 16.0], &[0.0, 0.7][..]));
        // Unnamed outputs that fit a part equally are refused, not guessed.
        let l = described("[boxes]\noutput = 'det'\nencoding = 'xyxy'\n[scores]\n[labels]\noutput = 'cls'\n");
        let e = decode(&l, &outs, 32, 16, 2, &ID).unwrap_err().to_string();
        assert!(e.contains("`cls`, `conf` all fit") && e.contains("name one"), "{e}");
    }

    /// Every value from a seeded stream in [−1.5, 1.5).
    fn values(n: usize, seed: u64) -> Vec<f32> {
        let mut x = seed;
        (0..n)
            .map(|_| {
                x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((x >> 40) as f32 / (1u64 << 24) as f32) * 3.0 - 1.5
            })
            .collect()
    }

    /// The boxes' Jacobians against central differences of the decoder, and their boxes against
    /// the decoder's, for every box encoding, through a scaled and padded map to the frame.
    #[test]
    fn box_jacobians_match_central_differences_for_every_encoding() {
        let map = InputMap { scale_x: 2.0, scale_y: 1.5, pad_x: 3.0, pad_y: 0.0, frame_w: 1e4, frame_h: 1e4 };
        let out = |name: &str, shape: Vec<usize>, seed| {
            let n = shape.iter().product();
            RawOutput { name: name.into(), shape, data: values(n, seed) }
        };
        let darknet = OutputLayout::Darknet {
            heads: vec![HeadConfig { output: "h".into(), anchors: vec![[40.0, 30.0], [12.0, 20.0]] }],
        };
        let planes = |enc: &str| {
            described(&format!("[[levels]]\nanchors = [[40, 30], [12, 20]]\n[boxes]\noutput = ['h']\narrange = 'planes'\nper_level = true\nencoding = '{enc}'\n[objectness]\noutput = ['h']\narrange = 'planes'\nper_level = true\ncolumn = 4\nactivation = 'sigmoid'\n[scores]\noutput = ['h']\narrange = 'planes'\nper_level = true\ncolumn = 5\nactivation = 'sigmoid'\n"))
        };
        let prior = described("order = 'cell-anchor'\n[[levels]]\nstride = 16\nanchors = [[10, 10], [20, 10]]\n[boxes]\noutput = ['b']\nwidth = 4\nencoding = 'prior'\ncoords = [1, 0, 3, 2]\nvariances = [0.1, 0.2]\n[scores]\noutput = ['s']\nwidth = 3\nactivation = 'softmax'\nbackground = 0\n");
        let cases: Vec<(&str, OutputLayout, Vec<RawOutput>, usize, usize)> = vec![
            ("darknet", darknet, vec![out("h", vec![1, 14, 3, 3], 1)], 96, 2),
            ("yolov5", planes("yolov5"), vec![out("h", vec![1, 14, 3, 3], 2)], 96, 2),
            (
                "grid (yolox)",
                OutputLayout::Yolox { output: None, strides: vec![4, 8] },
                vec![out("o", vec![1, 20, 7], 3)],
                16,
                2,
            ),
            (
                "ltrb bins (gfl)",
                OutputLayout::Gfl { strides: vec![4], bins: 4 },
                vec![out("r", vec![1, 4, 16], 4), out("c", vec![1, 4, 2], 5)],
                8,
                2,
            ),
            (
                "cxcywh (ultralytics)",
                OutputLayout::Ultralytics { output: None },
                vec![out("o", vec![1, 6, 5], 6)],
                32,
                2,
            ),
            ("prior (ssd)", prior, vec![out("s", vec![1, 8, 3], 7), out("b", vec![1, 8, 4], 8)], 32, 2),
            (
                "ltrb",
                described("[[levels]]\nstride = 16\n[boxes]\nencoding = 'ltrb'\n[scores]\ncolumn = 4\n"),
                vec![out("o", vec![1, 4, 6], 9)],
                32,
                2,
            ),
        ];
        for (what, layout, outs, side, classes) in cases {
            let jac = box_jacobians(&layout, &outs, side, side, classes, &map).unwrap();
            let boxes = decode(&layout, &outs, side, side, classes, &map).unwrap().boxes;
            assert_eq!(jac.iter().map(|j| j.0).collect::<Vec<_>>(), boxes, "{what}: the same boxes as decode");
            let mut checked = 0;
            for (i, (_, terms)) in jac.iter().enumerate() {
                for &(o, idx, d) in terms {
                    let h = 1e-2f32;
                    let at = |delta: f32| {
                        let mut moved = outs.clone();
                        moved[o].data[idx] += delta;
                        decode(&layout, &moved, side, side, classes, &map).unwrap().boxes[i]
                    };
                    let (up, down) = (at(h), at(-h));
                    for k in 0..4 {
                        // A corner the step clamps to the frame has no central difference.
                        if [up[k], down[k]].iter().any(|&c| c == 0.0 || c == 1e4) {
                            continue;
                        }
                        let fd = (up[k] - down[k]) / (2.0 * h);
                        assert!(
                            (fd - d[k]).abs() <= 2e-2 * (1.0 + d[k].abs()),
                            "{what}: box {i} corner {k} by value {idx}: {} vs {fd}",
                            d[k]
                        );
                    }
                    checked += 1;
                }
            }
            assert!(checked >= 4 * jac.len(), "{what}: {checked} values for {} boxes", jac.len());
            // Not vacuous: the boxes move with their values.
            assert!(
                jac.iter().flat_map(|j| &j.1).filter(|t| t.2.iter().any(|v| v.abs() > 0.1)).count() > jac.len(),
                "{what}"
            );
        }
    }

    #[test]
    fn empty_proposals_have_no_best_and_no_detections() {
        let p = Proposals::with_capacity(80, 0);
        assert!(p.best(&[2]).is_none());
        assert!(p.detections(0.0, 0.5).is_empty());
    }
}
