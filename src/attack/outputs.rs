//! What a run leaves behind besides the checkpoint: the texture PNG, loss and score curves, a
//! before/after preview of every view, and the white-box scores per view.

use super::optimize::StepLog;
use super::setup::Setup;
use super::view::View;
use super::whitebox::WhiteBox;
pub use crate::render::texture::save_rgb;
use crate::rng::Rng;
use crate::scene::Scene;
use std::path::Path;

/// The deterministic evaluation scene: the run's lighting, no EoT.
pub fn eval_scene(setup: &Setup) -> Scene {
    Scene { lighting: setup.scene.lighting, effects: Vec::new() }
}

/// A composite without EoT (clamped to [0, 1]).
pub fn composite(view: &View, tex: &[f32], scene: &Scene) -> Vec<f32> {
    view.render(tex, scene, &mut Rng::new(0)).0
}

/// White-box score of one view under three textures.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ViewScore {
    /// "train" or "test".
    pub split: &'static str,
    /// View name.
    pub view: String,
    /// Car score on the unmodified photo.
    pub original: f32,
    /// Car score with the initial texture.
    pub initial: f32,
    /// Car score with the optimized texture.
    pub optimized: f32,
}

/// Scores every view of `setup` with the white-box model.
pub fn score_views(setup: &Setup, wb: &WhiteBox, initial: &[f32], optimized: &[f32]) -> Result<Vec<ViewScore>, String> {
    let scene = eval_scene(setup);
    let mut out = Vec::new();
    for (split, views) in [("train", &setup.train), ("test", &setup.test)] {
        for v in views.iter() {
            let s = |img: &[f32]| wb.evaluate(img, v.size).map(|l| l.max_score).map_err(|e| e.to_string());
            out.push(ViewScore {
                split,
                view: v.name.clone(),
                original: s(&v.photo)?,
                initial: s(&composite(v, initial, &scene))?,
                optimized: s(&composite(v, optimized, &scene))?,
            });
        }
    }
    Ok(out)
}

/// A grid of (photo | composite) pairs at half size, four views per row.
pub fn preview(path: &Path, views: &[&View], tex: &[f32], scene: &Scene) -> Result<(), String> {
    let Some(first) = views.first() else { return Ok(()) };
    let s = first.size / 2;
    let cols = 4.min(views.len());
    let rows = views.len().div_ceil(cols);
    let (w, h) = (cols * 2 * s, rows * s);
    let mut img = vec![1f32; w * h * 3];
    for (k, v) in views.iter().enumerate() {
        let (ox, oy) = ((k % cols) * 2 * s, (k / cols) * s);
        for (j, src) in [v.photo.clone(), composite(v, tex, scene)].iter().enumerate() {
            for y in 0..s.min(v.size / 2) {
                for x in 0..s.min(v.size / 2) {
                    for c in 0..3 {
                        let at = |dy: usize, dx: usize| src[((2 * y + dy) * v.size + 2 * x + dx) * 3 + c];
                        img[((oy + y) * w + ox + j * s + x) * 3 + c] =
                            (at(0, 0) + at(0, 1) + at(1, 0) + at(1, 1)) / 4.0;
                    }
                }
            }
        }
    }
    save_rgb(path, w, h, &img)
}

/// Loss terms and the car score over steps.
pub fn plot_log(path: &Path, log: &[StepLog], window: usize) -> Result<(), String> {
    let pts = |f: &dyn Fn(&StepLog) -> f64| log.iter().map(|r| (r.step as f64, f(r))).collect::<Vec<_>>();
    let series = vec![
        ("L = L1 + β·L2 + γ·Ls".to_string(), pts(&|r| r.total)),
        ("L1 (mean objectness)".to_string(), pts(&|r| r.l1 as f64)),
        ("L2 (mean car confidence)".to_string(), pts(&|r| r.l2 as f64)),
        ("car score under EoT (dashed: 0.5)".to_string(), pts(&|r| r.max_score as f64)),
    ];
    crate::eval::plot::loss_curve(
        path,
        "PAV-Camou optimization (faint: per step; bold: running mean)",
        &series,
        window,
        Some(0.5),
    )
    .map_err(|e| e.to_string())
}
