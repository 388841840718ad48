//! Input gradients on ONNX Runtime: the two graphs of [`differentiate`] in two sessions. The
//! forward's saved tensors stay in ONNX Runtime's memory and feed the backward by reference.

use crate::autodiff::{grad_name, Differentiated};
use crate::runtime::{session_builder, session_err};
use crate::OnnxError;
use ort::session::Session;
use ort::value::{DynValue, Tensor};

#[cfg(doc)]
use crate::autodiff::differentiate;

/// A differentiable model: forward to the outputs, backward to the input gradient.
pub struct GradSession {
    name: String,
    d: Differentiated,
    forward: Session,
    backward: Session,
}

/// What a forward pass leaves for its backward pass.
pub struct Pass {
    saved: Vec<(String, DynValue)>,
    input: Option<DynValue>,
}

/// ONNX Runtime adds a custom-op domain to a process-wide schema map when a session that uses it
/// is created, checking first whether it is there: two such sessions created at once can both
/// find it missing, and the second then fails ("the domain is already exist"; seen once in a
/// fresh clone's test run, where test threads build white boxes side by side).
static REGISTERING_PAV_OPS: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn session(name: &str, bytes: &[u8], threads: usize, pav_ops: bool, what: &'static str) -> Result<Session, OnnxError> {
    let mut b = session_builder(name, threads)?
        // Two sessions take turns on the same cores: a spinning idle pool would steal them (measured:
        // a 416² YOLOv3-tiny step 190 → 117 ms on 2 cores).
        .with_intra_op_spinning(false)
        .map_err(session_err(name, "turning spinning off"))?;
    if !pav_ops {
        return b.commit_from_memory(bytes).map_err(session_err(name, what));
    }
    let domain = crate::gradops::domain().map_err(session_err(name, "creating pav's operators"))?;
    b = b.with_operators(domain).map_err(session_err(name, "registering pav's operators"))?;
    let _one_at_a_time = REGISTERING_PAV_OPS.lock().unwrap_or_else(|e| e.into_inner());
    b.commit_from_memory(bytes).map_err(session_err(name, what))
}

impl GradSession {
    /// Loads both graphs of `d` for the model `name` with `threads` intra-op threads each (0 = the
    /// runtime's default).
    pub fn new(name: &str, d: Differentiated, threads: usize) -> Result<Self, OnnxError> {
        let forward = session(name, &d.forward.to_bytes(), threads, false, "loading the forward graph")?;
        let fused = !d.backward.domains.is_empty();
        let backward = session(name, &d.backward.to_bytes(), threads, fused, "loading the gradient graph")?;
        Ok(GradSession { name: name.into(), d, forward, backward })
    }

    /// Runs the model on `input` (of the graphs' input shape); returns each output's values in the
    /// graph's order (the differentiated outputs, then the forward-only ones) and what the
    /// backward needs.
    pub fn forward(&mut self, input: Vec<f32>) -> Result<(Vec<Vec<f32>>, Pass), OnnxError> {
        let shape: Vec<usize> = self.d.input_shape.iter().map(|&v| v as usize).collect();
        let name = self.name.clone();
        let err = |what| session_err(&name, what);
        let x = Tensor::from_array((shape, input)).map_err(err("preparing the input"))?.into_dyn();
        let mut outs = self.forward.run(vec![(self.d.input.clone(), &x)]).map_err(err("the forward pass"))?;
        let mut values = Vec::with_capacity(self.d.outputs.len() + self.d.forward_only.len());
        for (o, _) in self.d.outputs.iter().chain(&self.d.forward_only) {
            let v = outs.get(o).ok_or_else(|| err("reading the outputs")(ort::Error::new(format!("no output {o}"))))?;
            values.push(v.try_extract_tensor::<f32>().map_err(err("reading the outputs"))?.1.to_vec());
        }
        let mut saved = Vec::with_capacity(self.d.saved.len());
        for s in &self.d.saved {
            let v = outs
                .remove(s)
                .ok_or_else(|| err("reading a saved tensor")(ort::Error::new(format!("no output {s}"))))?;
            saved.push((s.clone(), v));
        }
        Ok((values, Pass { saved, input: self.d.saves_input.then_some(x) }))
    }

    /// The gradient of the input from `grads`, the gradients of the outputs (in the graph's order).
    pub fn backward(&mut self, pass: &Pass, grads: Vec<Vec<f32>>) -> Result<Vec<f32>, OnnxError> {
        if grads.len() != self.d.outputs.len() {
            return Err(OnnxError::Request {
                model: self.name.clone(),
                msg: format!("{} output gradients for {} outputs", grads.len(), self.d.outputs.len()),
            });
        }
        let mut seeds = Vec::with_capacity(grads.len());
        for ((o, s), g) in self.d.outputs.iter().zip(grads) {
            let shape: Vec<usize> = s.iter().map(|&v| v as usize).collect();
            seeds.push((
                grad_name(o),
                Tensor::from_array((shape, g)).map_err(session_err(&self.name, "preparing a gradient"))?.into_dyn(),
            ));
        }
        let mut feed: Vec<(String, ort::session::SessionInputValue<'_>)> = Vec::new();
        for (n, v) in &pass.saved {
            feed.push((n.clone(), v.into()));
        }
        if let Some(x) = &pass.input {
            feed.push((self.d.input.clone(), x.into()));
        }
        for (n, v) in &seeds {
            feed.push((n.clone(), v.into()));
        }
        let name = self.name.clone();
        let err = |what| session_err(&name, what);
        let outs = self.backward.run(feed).map_err(err("the backward pass"))?;
        let g = &outs[0];
        Ok(g.try_extract_tensor::<f32>().map_err(err("reading the input gradient"))?.1.to_vec())
    }
}
