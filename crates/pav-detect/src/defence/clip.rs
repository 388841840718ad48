//! Feature norm clipping (Yu et al. 2021), a defence inside the model: it leaves the input alone
//! and is rewritten into the graph when the model loads (`pav_onnx::rewrite::clip_feature_norms`).

use super::{DefenceError, DefenceUnit};
use pav_core::image::Frame;
use pav_onnx::proto::Model;

/// Feature norm clipping, in the model: after each tensor of `layers`, feature vectors longer
/// than `level` times the map's mean norm are scaled down to it (Yu et al. 2021 use level 1).
/// Rewritten into the graph when it loads; an int8 model is clipped on its float surrogate.
#[derive(Clone, Debug, serde::Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Clip {
    /// Tensor names (node outputs) to clip after.
    pub layers: Vec<String>,
    /// Bound as a multiple of the mean feature norm.
    #[serde(default = "unit_level")]
    pub level: f32,
}

fn unit_level() -> f32 {
    1.0
}

impl DefenceUnit for Clip {
    fn check(&self, _: usize, _: usize) -> Result<(), String> {
        if self.layers.is_empty() {
            return Err("layers names no tensor to clip after".into());
        }
        if self.level.is_nan() || self.level <= 0.0 {
            return Err(format!("level = {} must be positive (inf: no clipping)", self.level));
        }
        Ok(())
    }

    fn label(&self) -> String {
        format!("clip{}", self.level)
    }

    fn on_input(&self) -> bool {
        false
    }

    fn apply(&self, _: &mut Frame, _: u64) -> Result<(), DefenceError> {
        Ok(())
    }

    fn rewrite(&self, model: &mut Model) -> Result<(), pav_onnx::OnnxError> {
        for l in &self.layers {
            pav_onnx::rewrite::clip_feature_norms(model, l, self.level)?;
        }
        Ok(())
    }
}
