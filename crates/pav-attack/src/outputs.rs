//! Which values of a detector graph a white box computes, and how the tensors its description
//! reads are put together from them.
//!
//! The loss reads some of a description's tensors (scores, objectness) with their gradient and,
//! under `loss.iou`, others (the boxes) forward only; the rest of the graph is pruned. A tensor
//! that the graph makes by concatenating pieces along its row's width (a box block beside a class
//! block, as Ultralytics' export writes them) is computed piece by piece: the pieces the loss
//! differentiates are seeded, those only read forward are computed without a gradient, and those
//! nothing reads are not computed at all (zeros in their place). The backward then never walks a
//! branch whose gradient is zero, whatever the model family.

use pav_detect::decode::{part_outputs, LayoutError, RawOutput};
use pav_detect::layout::{Arrange, Description, Role};
use pav_onnx::autodiff::{output_shapes, value_shapes, AutodiffError};
use pav_onnx::proto::{Attr, Model, ValueInfo, FLOAT};
use std::collections::HashMap;

/// Where one of the description's tensors comes from.
#[derive(Clone, Debug)]
enum Source {
    /// A graph output as it is.
    Whole(usize),
    /// A concatenation along one axis: per piece, the graph output that computes it (none: a
    /// piece nothing reads, zeros) and its size along the axis; `outer` and `inner` are the
    /// products of the dimensions before and after the axis.
    Pieces { outer: usize, inner: usize, pieces: Vec<(Option<usize>, usize)> },
}

/// The tensors a white box's description reads and the graph outputs that compute them.
#[derive(Clone, Debug)]
pub struct Plan {
    /// The description's tensors, names and shapes, in the graph's output order.
    pub tensors: Vec<(String, Vec<usize>)>,
    sources: Vec<Source>,
    /// The graph outputs, the differentiated ones first.
    pub graph_outputs: Vec<String>,
    /// How many graph outputs, from the first, are differentiated.
    pub seeded: usize,
}

/// Why the outputs cannot be planned.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// The graph's shapes.
    #[error("{0}")]
    Graph(#[from] AutodiffError),
    /// The description does not fit the outputs.
    #[error("{0}")]
    Layout(#[from] LayoutError),
}

/// A value the graph computes, what the loss does with it, and its size along a split axis.
type Piece = (String, Use, usize);

/// A tensor's split along an axis (the sizes before and after it; none: computed whole) and its
/// pieces.
type Split = (Option<(usize, usize)>, Vec<Piece>);

/// What the loss does with a value: differentiate it, read it forward only, or nothing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Use {
    None,
    Forward,
    Seeded,
}

/// Outputs of these names and shapes, without values: what a description is located among.
fn as_outputs(shapes: &[(String, Vec<i64>)]) -> Vec<RawOutput> {
    shapes
        .iter()
        .map(|(n, s)| RawOutput {
            name: n.clone(),
            shape: s.iter().map(|&v| v.max(0) as usize).collect(),
            data: Vec::new(),
        })
        .collect()
}

impl Plan {
    /// Plans `model` (its outputs are set to the plan's graph outputs and it is pruned) for a
    /// `side`² input, the description `d` of `classes` classes, boxes read under `boxes` and
    /// differentiated under `box_gradient`.
    pub fn new(
        model: &mut Model,
        d: &Description,
        side: usize,
        classes: usize,
        boxes: bool,
        box_gradient: bool,
    ) -> Result<Plan, PlanError> {
        let values = value_shapes(model, &[1, 3, side as i64, side as i64])?;
        let shapes = output_shapes(model, &values)?;
        let [box_outs, score_outs, obj_outs] = part_outputs(d, &as_outputs(&shapes), side, side, classes, boxes)?;
        let box_use = if box_gradient { Use::Seeded } else { Use::Forward };
        // Per graph output, the roles that read it and what the loss does with each.
        let roles = |k: usize| {
            let mut r = Vec::new();
            if score_outs.contains(&k) {
                r.push((Role::Scores, Use::Seeded));
            }
            if obj_outs.contains(&k) {
                r.push((Role::Objectness, Use::Seeded));
            }
            if box_outs.contains(&k) {
                r.push((Role::Boxes, box_use));
            }
            r
        };
        let (mut seeded, mut forward): (Vec<String>, Vec<String>) = (Vec::new(), Vec::new());
        // Per tensor: its split (outer and inner sizes) and pieces, to index once the seeded
        // outputs are all known.
        let mut planned: Vec<Split> = Vec::new();
        let mut tensors = Vec::new();
        for (k, (name, shape)) in shapes.iter().enumerate() {
            let read = roles(k);
            let Some(whole) = read.iter().map(|r| r.1).max() else { continue };
            let split = concat_pieces(model, &values, name, shape, d, &read, classes);
            let (axis, parts) = match split {
                Some((axis, pieces)) if pieces.iter().any(|p| p.1 != whole) => {
                    let outer = shape[..axis].iter().product::<i64>() as usize;
                    let inner = shape[axis + 1..].iter().product::<i64>() as usize;
                    (Some((outer, inner)), pieces)
                }
                _ => (None, vec![(name.clone(), whole, 0)]),
            };
            for (value, u, _) in &parts {
                match u {
                    Use::Seeded => seeded.push(value.clone()),
                    Use::Forward => forward.push(value.clone()),
                    Use::None => {}
                }
            }
            tensors.push((name.clone(), shape.iter().map(|&v| v.max(0) as usize).collect()));
            planned.push((axis, parts));
        }
        let index = |value: &str| {
            seeded
                .iter()
                .position(|v| v == value)
                .or_else(|| forward.iter().position(|v| v == value).map(|i| seeded.len() + i))
        };
        let sources = planned
            .iter()
            .map(|(axis, parts)| match axis {
                None => Source::Whole(index(&parts[0].0).expect("a tensor the loss reads is computed")),
                Some((outer, inner)) => Source::Pieces {
                    outer: *outer,
                    inner: *inner,
                    pieces: parts
                        .iter()
                        .map(|(v, u, size)| ((*u != Use::None).then(|| index(v)).flatten(), *size))
                        .collect(),
                },
            })
            .collect();
        let graph_outputs: Vec<String> = seeded.iter().chain(&forward).cloned().collect();
        model.outputs =
            graph_outputs.iter().map(|n| ValueInfo { name: n.clone(), elem_type: FLOAT, dims: vec![] }).collect();
        model.prune();
        Ok(Plan { tensors, sources, graph_outputs, seeded: seeded.len() })
    }

    /// The description's tensors without values: what its parts are located among.
    pub fn located(&self) -> Vec<RawOutput> {
        self.raw(self.tensors.iter().map(|_| Vec::new()).collect())
    }

    /// The description's tensors holding `data` (one per tensor, as [`Plan::assemble`] gives them).
    pub fn raw(&self, data: Vec<Vec<f32>>) -> Vec<RawOutput> {
        self.tensors
            .iter()
            .zip(data)
            .map(|((name, shape), data)| RawOutput { name: name.clone(), shape: shape.clone(), data })
            .collect()
    }

    /// The description's tensors from the graph outputs `outs` (in [`Plan::graph_outputs`] order).
    pub fn assemble(&self, mut outs: Vec<Vec<f32>>) -> Vec<Vec<f32>> {
        self.sources
            .iter()
            .zip(&self.tensors)
            .map(|(s, (_, shape))| match s {
                Source::Whole(k) => std::mem::take(&mut outs[*k]),
                Source::Pieces { outer, inner, pieces } => {
                    let mut t = Vec::with_capacity(shape.iter().product());
                    for o in 0..*outer {
                        for (src, size) in pieces {
                            let n = size * inner;
                            match src {
                                Some(k) => t.extend_from_slice(&outs[*k][o * n..(o + 1) * n]),
                                None => t.resize(t.len() + n, 0.0),
                            }
                        }
                    }
                    t
                }
            })
            .collect()
    }

    /// The gradients of the seeded graph outputs from those of the description's tensors.
    pub fn scatter(&self, mut grads: Vec<Vec<f32>>) -> Vec<Vec<f32>> {
        let mut seeded: Vec<Vec<f32>> = vec![Vec::new(); self.seeded];
        for (t, s) in self.sources.iter().enumerate() {
            match s {
                Source::Whole(k) if *k < self.seeded => seeded[*k] = std::mem::take(&mut grads[t]),
                Source::Whole(_) => {}
                Source::Pieces { outer, inner, pieces } => {
                    let width: usize = pieces.iter().map(|p| p.1).sum();
                    let mut at = 0;
                    for (src, size) in pieces {
                        if let Some(k) = src.filter(|k| *k < self.seeded) {
                            let n = size * inner;
                            seeded[k] = (0..*outer)
                                .flat_map(|o| grads[t][o * width * inner + at * inner..][..n].iter().copied())
                                .collect();
                        }
                        at += size;
                    }
                }
            }
        }
        seeded
    }
}

/// When graph output `name` (of `shape`) is a Concat along the width of the rows its readers
/// take it as, each piece's value, what the loss does with it, and its size along that axis,
/// with the axis; `values` are the graph's value shapes.
fn concat_pieces(
    model: &Model,
    values: &HashMap<String, Vec<i64>>,
    name: &str,
    shape: &[i64],
    d: &Description,
    read: &[(Role, Use)],
    classes: usize,
) -> Option<(usize, Vec<Piece>)> {
    let node = model.nodes.iter().find(|n| n.outputs.first().is_some_and(|o| o == name) && n.op_type == "Concat")?;
    let rank = shape.len() as i64;
    let axis = node.attrs.iter().find(|(k, _)| k == "axis").and_then(|(_, a)| match a {
        Attr::Int(v) => Some(if *v < 0 { v + rank } else { *v } as usize),
        _ => None,
    })?;
    // The row's width axis, as every part that reads the tensor arranges it.
    let arranged: Vec<Arrange> = read.iter().map(|(r, _)| d.part(*r).arrange).collect();
    let width_axis = match arranged.first()? {
        Arrange::Rows => shape.len().checked_sub(1)?,
        Arrange::Columns => shape.len().checked_sub(2)?,
        Arrange::Planes => return None,
    };
    if axis != width_axis || arranged.iter().any(|a| *a != arranged[0]) {
        return None;
    }
    // A piece the nodes do not compute (a constant) leaves the output whole.
    let sizes: Vec<usize> =
        node.inputs.iter().map(|v| values.get(v)?.get(axis).map(|&s| s as usize)).collect::<Option<_>>()?;
    let mut at = 0;
    let pieces = node
        .inputs
        .iter()
        .zip(&sizes)
        .map(|(v, &size)| {
            let range = at..at + size;
            at += size;
            let u = read
                .iter()
                .filter(|(r, _)| d.columns(*r, classes).iter().any(|c| range.contains(c)))
                .map(|r| r.1)
                .max()
                .unwrap_or(Use::None);
            (v.clone(), u, size)
        })
        .collect();
    (at as i64 == shape[axis]).then_some((axis, pieces))
}
