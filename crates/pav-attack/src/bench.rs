//! What the white-box step costs in time (`pav bench-step`): the detector's forward with the loss,
//! and forward + backward to its input, at several network input sizes.

use super::loss::{DetectionLoss, ProposalSet, Reduce};
use super::whitebox::{WhiteBox, WhiteBoxError, WhiteBoxOptions};
use pav_core::progress::Progress;
use pav_detect::config::DetectorConfig;
use std::time::Instant;

/// Median milliseconds of the white-box step at one composite size.
#[derive(Clone, Debug, serde::Serialize)]
pub struct StepTiming {
    /// Which implementation ran it.
    pub backend: String,
    /// Network input side (the composite has the same size).
    pub size: usize,
    /// Threads the backend may use (0 = its default).
    pub threads: usize,
    /// Timed repetitions (after warm-up).
    pub repeats: usize,
    /// Forward and loss, no gradient.
    pub forward_ms: f64,
    /// Forward, loss and the input gradient.
    pub forward_backward_ms: f64,
    /// Of which the forward part of the gradient step.
    pub step_forward_ms: f64,
    /// Of which the backward part.
    pub step_backward_ms: f64,
    /// The loss: `mean` (the paper's), `log_max+iou` (RAUCA-E2E's, boxes read every step) or
    /// `log_max+iou+box` (that weight differentiated through the boxes).
    pub loss: String,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// A smooth test composite, so the timing does not depend on data files.
fn composite(size: usize) -> Vec<f32> {
    (0..size * size * 3)
        .map(|i| {
            let (y, x, c) = (i / (size * 3), (i / 3) % size, i % 3);
            0.5 + 0.4 * ((x as f32 * 0.05 + c as f32).sin() * (y as f32 * 0.03).cos())
        })
        .collect()
}

/// How [`time_step`] runs.
#[derive(Clone, Copy, Debug)]
pub struct StepBench {
    /// Threads (0 = the runtime's default).
    pub threads: usize,
    /// Timed repetitions after 3 warm-up runs.
    pub repeats: usize,
    /// Differentiate the float surrogate of a dynamically quantized model.
    pub surrogate: bool,
    /// RAUCA-E2E's loss with the IoU weight (the box outputs read every step) instead of the
    /// paper's means.
    pub iou: bool,
    /// With `iou`, differentiate the weight through the boxes (`loss.box_gradient`).
    pub box_gradient: bool,
}

/// Times the white-box step of `detector` with its network at each of `sizes` as `b` says; each
/// size's result is a note on `progress`.
pub fn time_step(
    detector: &DetectorConfig,
    sizes: &[usize],
    b: StepBench,
    progress: &dyn Progress,
) -> Result<Vec<StepTiming>, WhiteBoxError> {
    let StepBench { threads, repeats, surrogate, iou, box_gradient } = b;
    let box_gradient = iou && box_gradient;
    let mut rows = Vec::new();
    for &size in sizes {
        let loss = DetectionLoss {
            box_threshold: 0.05,
            target: detector.target_classes.clone(),
            reduce: if iou { Reduce::LogMax } else { Reduce::Mean },
            proposals: ProposalSet::ArgMax,
            iou,
            box_gradient,
        };
        let o = WhiteBoxOptions { composite: size, input: Some(size), threads, surrogate };
        let wb = WhiteBox::with_options(detector, loss, o)?;
        let img = composite(size);
        // The central half of the composite stands for the car.
        let s = size as f32;
        let car = iou.then_some([0.25 * s, 0.25 * s, 0.75 * s, 0.75 * s]);
        for _ in 0..3 {
            wb.loss_and_grad(&img, size, 1.0, car)?;
        }
        let (mut fwd, mut step, mut sf, mut sb) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for _ in 0..repeats.max(1) {
            let t = Instant::now();
            wb.loss(&img, size)?;
            fwd.push(t.elapsed().as_secs_f64() * 1e3);
            let t = Instant::now();
            let g = wb.loss_and_grad(&img, size, 1.0, car)?;
            step.push(t.elapsed().as_secs_f64() * 1e3);
            sf.push(g.forward_ms);
            sb.push(g.backward_ms);
        }
        let row = StepTiming {
            backend: "pav (ONNX Runtime gradient graphs)".into(),
            size,
            threads,
            repeats: repeats.max(1),
            forward_ms: median(fwd),
            forward_backward_ms: median(step),
            step_forward_ms: median(sf),
            step_backward_ms: median(sb),
            loss: match (iou, box_gradient) {
                (false, _) => "mean",
                (true, false) => "log_max+iou",
                (true, true) => "log_max+iou+box",
            }
            .into(),
        };
        progress.note(&format!(
            "{size}²: forward {:.1} ms, forward + backward {:.1} ms ({:.1} + {:.1})",
            row.forward_ms, row.forward_backward_ms, row.step_forward_ms, row.step_backward_ms
        ));
        rows.push(row);
    }
    Ok(rows)
}
