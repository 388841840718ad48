//! An output layout as a description: which outputs hold a model's boxes, scores, objectness and
//! labels, how its boxes are encoded, whether its scores are activated, and the grid its rows
//! follow. The named layouts (`darknet`, `yolox`, `ultralytics`, `gfl`, `rows`, `detr`) are
//! presets of it (`OutputLayout::describe`); `layout = "custom"` writes one out.

use serde::{Deserialize, Deserializer};

/// Which pixels boxes are in.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum BoxFrame {
    /// The model's input (mapped back through the resize and padding).
    #[default]
    Input,
    /// The frame itself (the graph mapped them back, e.g. with a `scale_yx` extra input).
    Image,
}

/// How a part's tensor holds its proposals.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Arrange {
    /// `[.., R, W]`: a row of W values per proposal (a rank-1 `[R]` when W is 1).
    #[default]
    Rows,
    /// `[.., W, R]`: a column per proposal (Ultralytics).
    Columns,
    /// `[.., A·W, H, W']`: per grid level, A anchors' W channels as maps (darknet heads); the
    /// level's grid is read from the map when it gives no stride.
    Planes,
}

/// The order of one level's rows.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum CellOrder {
    /// Anchor by anchor, each a whole grid row-major (YOLOv5's and darknet's order).
    #[default]
    AnchorCell,
    /// Cell by cell row-major, each cell's anchors together (SSD's order).
    CellAnchor,
    /// Cell by cell row-major, one row per cell holding every anchor's values side by side
    /// (YOLO-FastestV2): a part's anchors are its `anchor_step` columns apart.
    InRow,
}

/// Where a grid cell's point is, for encodings measured from it.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Centre {
    /// `(x + 0.5)·stride`: the cell's centre.
    #[default]
    Cell,
    /// `x·stride + (stride − 1)/2`: the centre of the cell's pixels (NanoDet).
    Pixel,
}

/// How a box's four values become corners, in input pixels. `(gx, gy)` is the row's cell,
/// `s` its level's stride, `(aw, ah)` its anchor (the stride for an anchor-free grid), `c` the
/// cell's point (see [`Centre`]), σ the logistic sigmoid.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Encoding {
    /// Corners `x1, y1, x2, y2`.
    Xyxy,
    /// Centre and size `cx, cy, w, h`.
    Cxcywh,
    /// YOLOX: `cx = (v0 + gx)·s`, `w = e^v2·aw`.
    Grid,
    /// Darknet YOLOv3: `cx = (σ(v0) + gx)·s`, `w = e^v2·aw`.
    Darknet,
    /// YOLOv5's raw heads: `cx = (2σ(v0) − 0.5 + gx)·s`, `w = (2σ(v2))²·aw`.
    Yolov5,
    /// Distances from the cell's point to the left, top, right and bottom sides, in strides.
    Ltrb,
    /// As `ltrb`, each distance a distribution over `bins` (softmax, expectation; GFL).
    LtrbBins,
    /// FastestDet: `cx = (gx + tanh(v0))·s`, `w = σ(v2)·W`: centre offsets through tanh from the
    /// cell's corner, sizes as shares of the input's width W and height through a sigmoid.
    TanhShare,
    /// SSD: offsets from a prior box (centre `c`, size `aw, ah`) scaled by `variances`:
    /// `cx = c + v0·var0·aw`, `w = aw·e^(v2·var1)`.
    Prior,
}

impl Encoding {
    /// Its boxes are relative to a grid cell, so a description lists `[[output.levels]]`.
    pub const fn needs_grid(self) -> bool {
        use Encoding::*;
        match self {
            Grid | Darknet | Yolov5 | Ltrb | LtrbBins | Prior | TanhShare => true,
            Xyxy | Cxcywh => false,
        }
    }

    /// Its sizes scale an anchor (or a prior), so every level lists `anchors`.
    pub const fn needs_anchors(self) -> bool {
        use Encoding::*;
        match self {
            Darknet | Yolov5 | Prior => true,
            Xyxy | Cxcywh | Grid | Ltrb | LtrbBins | TanhShare => false,
        }
    }

    /// It applies a sigmoid, tanh or softmax of its own, which `activated = true` says the graph
    /// already applied.
    pub const fn activates(self) -> bool {
        use Encoding::*;
        match self {
            Darknet | Yolov5 | TanhShare | LtrbBins => true,
            Xyxy | Cxcywh | Grid | Ltrb | Prior => false,
        }
    }
}

/// The function a model's scores still need.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Activation {
    /// Already probabilities.
    #[default]
    None,
    /// Logits, one sigmoid each.
    Sigmoid,
    /// Logits, one softmax over the row's class columns (with a background column when named).
    Softmax,
}

/// The logistic function.
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

impl Activation {
    /// One value through the activation (`softmax` works on whole rows, so it passes values on).
    pub fn apply(self, x: f32) -> f32 {
        match self {
            Activation::Sigmoid => sigmoid(x),
            Activation::None | Activation::Softmax => x,
        }
    }
}

/// One grid level.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Level {
    /// Input pixels per cell; read from the map for `planes` tensors when absent.
    #[serde(default)]
    pub stride: Option<usize>,
    /// Anchor or prior sizes `[w, h]` in input pixels; none for an anchor-free grid.
    #[serde(default)]
    pub anchors: Vec<[f32; 2]>,
}

/// Where one part of the proposals (boxes, scores, objectness, labels) lies, and how to read it.
#[derive(Clone, Debug, Default, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct OutputPart {
    /// Output names: one, or one per level with `per_level`; matched by shape when empty.
    #[serde(default, deserialize_with = "one_or_many")]
    pub output: Vec<String>,
    /// The first of the part's values in each row.
    #[serde(default)]
    pub column: usize,
    /// The values in each of the tensor's rows; parts without one that name the same outputs
    /// share a tensor as wide as their columns reach.
    #[serde(default)]
    pub width: Option<usize>,
    /// How the tensor holds its proposals.
    #[serde(default)]
    pub arrange: Arrange,
    /// One tensor per grid level instead of one for all.
    #[serde(default)]
    pub per_level: bool,
    /// Boxes: the encoding.
    #[serde(default)]
    pub encoding: Option<Encoding>,
    /// Boxes: the columns of the four values when they are not side by side from `column`
    /// (TensorFlow's SSD exports give `ty, tx, th, tw`: `coords = [1, 0, 3, 2]`).
    #[serde(default)]
    pub coords: Option<[usize; 4]>,
    /// Boxes, `ltrb-bins`: bins per side.
    #[serde(default)]
    pub bins: Option<usize>,
    /// Boxes, `prior`: the centre and size variances.
    #[serde(default)]
    pub variances: Option<[f32; 2]>,
    /// Boxes: values as shares of the input's width and height instead of pixels.
    #[serde(default)]
    pub normalized: bool,
    /// Boxes: clipped to the input before they are mapped back.
    #[serde(default)]
    pub clip: bool,
    /// Boxes: which pixels the corners are in.
    #[serde(default)]
    pub frame: BoxFrame,
    /// Scores and objectness: the function they still need.
    #[serde(default)]
    pub activation: Activation,
    /// Scores: the column (counted from `column`) of a background class the model adds before
    /// the others; dropped after the activation.
    #[serde(default)]
    pub background: Option<usize>,
    /// With `order = "in-row"`: the columns from one anchor's values to the next's in a cell's
    /// row; 0 (the default) for one block the cell's anchors share.
    #[serde(default)]
    pub anchor_step: usize,
    /// Boxes: the encoding's own functions (the sigmoids of `darknet`, `yolov5` and
    /// `tanh-share`, its tanh, the softmax of `ltrb-bins`) are already applied in the graph.
    #[serde(default)]
    pub activated: bool,
    /// Scores and objectness: the power each enters the detection score with, `obj^p · cls^q`
    /// (FastestDet's 0.6 and 0.4); 1 when absent.
    #[serde(default)]
    pub power: Option<f32>,
}

fn one_or_many<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<String>, D::Error> {
    #[derive(Deserialize, serde::Serialize, schemars::JsonSchema)]
    #[serde(untagged)]
    enum OneOrMany {
        One(String),
        Many(Vec<String>),
    }
    Ok(match OneOrMany::deserialize(d)? {
        OneOrMany::One(s) => vec![s],
        OneOrMany::Many(v) => v,
    })
}

/// A whole output layout: proposals on an optional grid, each with a box, class scores, and
/// optionally an objectness (multiplying the scores) or a label (final detections: the score
/// is the labelled class's, rows with a label outside the classes are padding).
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Description {
    /// Grid levels in row order; none when rows are not on a grid.
    #[serde(default)]
    pub levels: Vec<Level>,
    /// The order of each level's rows.
    #[serde(default)]
    pub order: CellOrder,
    /// Where a cell's point is.
    #[serde(default)]
    pub centre: Centre,
    /// The boxes.
    pub boxes: OutputPart,
    /// The class scores (one column with `labels`).
    pub scores: OutputPart,
    /// An objectness multiplying every class score.
    #[serde(default)]
    pub objectness: Option<OutputPart>,
    /// Each row's class, for final detections.
    #[serde(default)]
    pub labels: Option<OutputPart>,
    /// The values before the graph's own post-processor (its top-k or NMS), described the same
    /// way: what a white box differentiates when the outputs are final detections.
    #[serde(default)]
    pub raw: Option<Box<Description>>,
}

/// Which part of a [`Description`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// [`Description::boxes`].
    Boxes,
    /// [`Description::scores`].
    Scores,
    /// [`Description::objectness`].
    Objectness,
    /// [`Description::labels`].
    Labels,
}

impl Role {
    /// Its TOML table.
    pub fn table(self) -> &'static str {
        match self {
            Role::Boxes => "output.boxes",
            Role::Scores => "output.scores",
            Role::Objectness => "output.objectness",
            Role::Labels => "output.labels",
        }
    }
}

impl Description {
    /// No levels and no parts read yet: the start of a description written in code.
    pub fn empty() -> Description {
        Description {
            levels: Vec::new(),
            order: CellOrder::AnchorCell,
            centre: Centre::Cell,
            boxes: OutputPart::default(),
            scores: OutputPart::default(),
            objectness: None,
            labels: None,
            raw: None,
        }
    }

    /// The parts present, with their roles.
    pub fn parts(&self) -> Vec<(Role, &OutputPart)> {
        let mut v = vec![(Role::Boxes, &self.boxes), (Role::Scores, &self.scores)];
        v.extend(self.objectness.as_ref().map(|p| (Role::Objectness, p)));
        v.extend(self.labels.as_ref().map(|p| (Role::Labels, p)));
        v
    }

    /// How many values of each row a part reads, for `classes` classes.
    pub fn count(&self, role: Role, classes: usize) -> usize {
        match role {
            Role::Boxes if self.boxes.encoding == Some(Encoding::LtrbBins) => 4 * self.boxes.bins.unwrap_or(0),
            Role::Boxes => 4,
            Role::Scores if self.labels.is_some() => 1,
            Role::Scores => classes + usize::from(self.scores.background.is_some()),
            Role::Objectness | Role::Labels => 1,
        }
    }

    /// Anchors whose values share one row: each level's anchors with `order = "in-row"`, else 1.
    pub fn anchors_per_row(&self) -> usize {
        match self.order {
            CellOrder::InRow => self.levels.iter().map(|l| l.anchors.len().max(1)).max().unwrap_or(1),
            _ => 1,
        }
    }

    /// The last column (exclusive) a part reads.
    pub fn reach(&self, role: Role, classes: usize) -> usize {
        let p = self.part(role);
        let last = (self.anchors_per_row() - 1) * p.anchor_step;
        last + match (role, p.coords) {
            (Role::Boxes, Some(c)) => c.iter().max().map_or(0, |m| m + 1),
            _ => p.column + self.count(role, classes),
        }
    }

    /// Every column of a row that a part reads, the anchors sharing the row included.
    pub fn columns(&self, role: Role, classes: usize) -> Vec<usize> {
        let p = self.part(role);
        let base: Vec<usize> = match (role, p.coords) {
            (Role::Boxes, Some(c)) => c.to_vec(),
            _ => (p.column..p.column + self.count(role, classes)).collect(),
        };
        (0..self.anchors_per_row()).flat_map(|a| base.iter().map(move |c| c + a * p.anchor_step)).collect()
    }

    /// The description a white box differentiates: [`Description::raw`] when there is one.
    pub fn gradient(&self) -> Result<&Description, String> {
        let d = self.raw.as_deref().unwrap_or(self);
        if d.labels.is_some() {
            return Err("the outputs are final detections (labels), which have no gradient: describe the values before the post-processor as [output.raw]".into());
        }
        Ok(d)
    }

    /// The row width of a part's tensor: its own `width`, else as far as the columns of the
    /// parts without a width that name the same outputs reach.
    pub fn width(&self, role: Role, classes: usize) -> usize {
        let p = self.part(role);
        p.width.unwrap_or_else(|| {
            self.parts()
                .into_iter()
                .filter(|(_, q)| q.width.is_none() && q.output == p.output && q.per_level == p.per_level)
                .map(|(r, _)| self.reach(r, classes))
                .max()
                .unwrap_or(0)
        })
    }

    /// The part of a role (the description must have it).
    pub fn part(&self, role: Role) -> &OutputPart {
        match role {
            Role::Boxes => &self.boxes,
            Role::Scores => &self.scores,
            Role::Objectness => self.objectness.as_ref().unwrap_or(&self.scores),
            Role::Labels => self.labels.as_ref().unwrap_or(&self.scores),
        }
    }

    /// Checks what can be checked without the model; `classes` is the config's class count.
    pub fn validate(&self, classes: usize) -> Result<(), String> {
        let b = &self.boxes;
        let Some(enc) = b.encoding else {
            return Err(
                "[output.boxes] needs an `encoding`: xyxy, cxcywh, grid, darknet, yolov5, tanh-share, ltrb, ltrb-bins or prior"
                    .into(),
            );
        };
        let name = format!("{enc:?}").to_lowercase();
        if enc.needs_grid() && self.levels.is_empty() {
            return Err(format!("boxes encoded as `{name}` are relative to a grid: list its [[output.levels]]"));
        }
        if enc.needs_anchors() && self.levels.iter().any(|l| l.anchors.is_empty()) {
            return Err(format!("boxes encoded as `{name}` need `anchors` on every level"));
        }
        if self
            .levels
            .iter()
            .any(|l| l.stride == Some(0) || l.anchors.iter().flatten().any(|v| !(v.is_finite() && *v > 0.0)))
        {
            return Err("level strides and anchor sizes must be positive".into());
        }
        for (role, p) in self.parts() {
            let t = role.table();
            if p.arrange != Arrange::Planes && !self.levels.is_empty() && self.levels.iter().any(|l| l.stride.is_none())
            {
                return Err(format!("[{t}] is not arranged in planes, so every level needs a `stride`"));
            }
            if p.arrange == Arrange::Planes && (self.levels.is_empty() || !p.per_level) {
                return Err(format!("[{t}] arranged in planes needs `per_level = true` and [[output.levels]]"));
            }
            if p.per_level && self.levels.is_empty() {
                return Err(format!("[{t}] is per level but no [[output.levels]] are listed"));
            }
            if p.per_level && !p.output.is_empty() && p.output.len() != self.levels.len() {
                return Err(format!(
                    "[{t}] names {} outputs for {} levels: one per level, or none to match them by shape",
                    p.output.len(),
                    self.levels.len()
                ));
            }
            if !p.per_level && p.output.len() > 1 {
                return Err(format!(
                    "[{t}] names {} outputs: one, or one per level with `per_level = true`",
                    p.output.len()
                ));
            }
            if role != Role::Boxes
                && (p.encoding.is_some()
                    || p.coords.is_some()
                    || p.bins.is_some()
                    || p.variances.is_some()
                    || p.normalized
                    || p.clip
                    || p.frame != BoxFrame::Input)
            {
                return Err(format!("[{t}] has box keys (encoding, coords, bins, variances, normalized, clip, frame): they belong in [output.boxes]"));
            }
            if p.anchor_step > 0 && self.order != CellOrder::InRow {
                return Err(format!("[{t}] has `anchor_step`: it belongs to `order = \"in-row\"`"));
            }
            if self.order == CellOrder::InRow && p.arrange == Arrange::Planes {
                return Err(format!("[{t}] arranged in planes cannot hold several anchors in one row: use rows or columns with `order = \"in-row\"`"));
            }
            if role != Role::Boxes && p.activated {
                return Err(format!("[{t}] has `activated`: scores and objectness say so with `activation`"));
            }
            if let Some(q) = p.power {
                if !(matches!(role, Role::Scores | Role::Objectness) && q.is_finite() && q > 0.0) {
                    return Err(format!(
                        "[{t}] power = {q}: only scores and objectness take a power, and it must be positive"
                    ));
                }
            }
            if role != Role::Scores && p.background.is_some() {
                return Err(format!("[{t}] has `background`: it belongs in [output.scores]"));
            }
            if matches!(role, Role::Boxes | Role::Labels) && p.activation != Activation::None {
                return Err(format!("[{t}] has an `activation`: only scores and objectness take one"));
            }
            if role == Role::Objectness && p.activation == Activation::Softmax {
                return Err("an objectness takes `sigmoid` or no activation, not `softmax`".into());
            }
            let (reach, width) = (self.reach(role, classes), self.width(role, classes));
            if reach > width {
                return Err(format!("[{t}] reads columns up to {reach} of rows {width} wide"));
            }
        }
        if enc == Encoding::LtrbBins && b.bins.is_none_or(|n| n < 2) {
            return Err("boxes encoded as `ltrb-bins` need `bins` of at least 2".into());
        }
        if enc != Encoding::LtrbBins && b.bins.is_some() {
            return Err("`bins` belongs to the `ltrb-bins` encoding".into());
        }
        if b.activated && !enc.activates() {
            return Err(format!(
                "`activated` says the encoding's sigmoid, tanh or softmax is already applied; `{name}` applies none, so its values are read as they are"
            ));
        }
        if enc != Encoding::Prior && b.variances.is_some() {
            return Err("`variances` belong to the `prior` encoding".into());
        }
        if b.coords.is_some() && enc == Encoding::LtrbBins {
            return Err("`coords` name four single values; `ltrb-bins` reads 4 × bins side by side".into());
        }
        if let Some(bg) = self.scores.background {
            if self.labels.is_some() || bg > classes {
                return Err(format!(
                    "scores.background = {bg} must be one of the {} score columns, without labels",
                    classes + 1
                ));
            }
        }
        if self.labels.is_some() && (self.objectness.is_some() || self.scores.activation == Activation::Softmax) {
            return Err("final detections (labels) take one score column: no objectness, no softmax".into());
        }
        if self.scores.activation == Activation::Softmax && self.objectness.is_some() {
            return Err("softmax scores with an objectness: give the objectness its own sigmoid scores instead".into());
        }
        if self.labels.is_some() && self.scores.power.is_some() {
            return Err("final detections (labels) are scored by their score column: no power".into());
        }
        if let Some(raw) = &self.raw {
            if raw.labels.is_some() || raw.raw.is_some() {
                return Err(
                    "[output.raw] describes the values before the post-processor: no labels, no raw of its own".into(),
                );
            }
            raw.validate(classes).map_err(|e| format!("[output.raw]: {e}"))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn custom(body: &str) -> Result<Description, String> {
        let d: Description = toml::from_str(body).map_err(|e| e.to_string())?;
        d.validate(80).map(|_| d)
    }

    #[test]
    fn descriptions_that_cannot_work_are_refused_with_the_reason() {
        let ssd = "[[levels]]\nstride = 8\nanchors = [[10, 10]]\n[boxes]\nencoding = 'prior'\nvariances = [0.1, 0.2]\nwidth = 4\n[scores]\nactivation = 'softmax'\nbackground = 0\nwidth = 81\n";
        custom(ssd).unwrap();
        // Three anchors side by side in a row: boxes every 4 columns, objectness every 1.
        let in_row = "order = 'in-row'\n[[levels]]\nstride = 16\nanchors = [[8, 8], [16, 24], [24, 12]]\n[boxes]\nencoding = 'yolov5'\nactivated = true\nanchor_step = 4\n[objectness]\ncolumn = 12\nanchor_step = 1\n[scores]\ncolumn = 15\n";
        let d = custom(in_row).unwrap();
        assert_eq!(
            (d.anchors_per_row(), d.width(Role::Boxes, 80), d.columns(Role::Objectness, 80)),
            (3, 95, vec![12, 13, 14])
        );
        let cases = [
            ("[boxes]\n[scores]\n", "needs an `encoding`"),
            ("[boxes]\nencoding = 'grid'\n[scores]\ncolumn = 4\n", "list its [[output.levels]]"),
            (&ssd.replace("anchors = [[10, 10]]", ""), "need `anchors` on every level"),
            (&ssd.replace("stride = 8", ""), "needs a `stride`"),
            (&ssd.replace("background = 0", "background = 81"), "score columns"),
            (&ssd.replace("width = 81", "width = 80"), "columns up to 81 of rows 80 wide"),
            (
                &ssd.replace("activation = 'softmax'", "activation = 'softmax'\nencoding = 'xyxy'"),
                "belong in [output.boxes]",
            ),
            ("[boxes]\nencoding = 'ltrb-bins'\n[[levels]]\nstride = 8\n[scores]\ncolumn = 4\n", "bins"),
            ("[boxes]\nencoding = 'xyxy'\nper_level = true\n[scores]\ncolumn = 4\n", "no [[output.levels]]"),
            (
                "[boxes]\nencoding = 'xyxy'\n[scores]\ncolumn = 4\n[labels]\ncolumn = 5\n[objectness]\ncolumn = 6\n",
                "no objectness",
            ),
            ("[boxes]\nencoding = 'xyxy'\noutput = ['a', 'b']\n[scores]\ncolumn = 4\n", "one per level"),
            ("[boxes]\nencoding = 'xyxy'\nanchor_step = 4\n[scores]\ncolumn = 4\n", "belongs to `order = \"in-row\"`"),
            ("[boxes]\nencoding = 'cxcywh'\nactivated = true\n[scores]\ncolumn = 4\n", "`cxcywh` applies none"),
            ("[boxes]\nencoding = 'xyxy'\n[scores]\ncolumn = 4\nactivated = true\n", "say so with `activation`"),
            ("[boxes]\nencoding = 'xyxy'\n[scores]\ncolumn = 4\npower = 0\n", "must be positive"),
            (
                "order = 'in-row'\n[[levels]]\nanchors = [[1, 1]]\n[boxes]\narrange = 'planes'\nper_level = true\nencoding = 'darknet'\n[scores]\narrange = 'planes'\nper_level = true\ncolumn = 4\n",
                "cannot hold several anchors",
            ),
            ("[boxes]\nencoding = 'xyxy'\n[scores]\ncolumn = 4\n[raw.boxes]\nencoding = 'xyxy'\n[raw.scores]\ncolumn = 4\n[raw.labels]\ncolumn = 5\n", "[output.raw]"),
        ];
        for (body, want) in cases {
            let e = custom(body).unwrap_err();
            assert!(e.contains(want), "{body}\n→ {e}");
        }
    }
}
