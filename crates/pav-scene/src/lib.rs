//! Scene configs: which effects the optimization simulates. Only what a scene lists is computed:
//! no `[lighting]` table means an unlit (albedo) render, and an empty `effects` list means no EoT.
//!
//! ```toml
//! [lighting]            # Phong with one white directional light (PyTorch3D's SoftPhong)
//! ambient = 0.7
//! diffuse = 0.4
//! specular = 0.2
//! direction = [1.0, 1.0, 1.0]
//!
//! [[effects]]           # applied in this order to the textured render, then clamped to [0, 1]
//! kind = "contrast"     # x · U(min, max)
//! min = 0.8
//! max = 1.2
//! per = "pixel"         # or "image": one draw for the whole render
//!
//! [[effects]]           # the whole composite rescaled by U(min, max) at a random place
//! kind = "zoom"         # (after the pixel effects): the car nearer or farther
//! min = 0.7
//! max = 1.1
//! ```
#![warn(missing_docs)]

pub mod align;
pub mod blender;
pub mod camera_effects;
pub mod eot;
pub mod rig;
pub mod turntable;
pub mod views;
pub mod zoom;

use pav_render::shade::Lights;
use serde::Deserialize;
use std::path::Path;

/// How often an effect's random factor is drawn.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Per {
    /// One draw per pixel and channel (the authors' EoT).
    #[default]
    Pixel,
    /// One draw per render.
    Image,
}

/// One EoT effect on the textured render `I_d`.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum Effect {
    /// Multiply by U(min, max).
    Contrast {
        /// Smallest factor.
        min: f32,
        /// Largest factor.
        max: f32,
        /// Draw granularity.
        #[serde(default)]
        per: Per,
    },
    /// Add U(min, max).
    Brightness {
        /// Smallest offset.
        min: f32,
        /// Largest offset.
        max: f32,
        /// Draw granularity.
        #[serde(default)]
        per: Per,
    },
    /// Add amplitude · U(−1, 1) per pixel and channel.
    Noise {
        /// Noise amplitude.
        amplitude: f32,
    },
    /// Rescale the whole composite by U(min, max) at a random place (`scene::zoom`): the car
    /// nearer or farther. Applied after the pixel effects, whatever its place in the list.
    Zoom {
        /// Smallest factor (> 0).
        min: f32,
        /// Largest factor.
        max: f32,
    },
}

/// A scene: lighting of the textured render and the EoT effects.
#[derive(Clone, Debug, Default, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Phong lighting (the renderer's light set, read as is); `None` renders the albedo.
    pub lighting: Option<Lights>,
    /// EoT effects in order.
    #[serde(default)]
    pub effects: Vec<Effect>,
}

/// Errors reading a scene.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// Unreadable file.
    #[error("cannot read scene {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// Not valid TOML for a scene.
    #[error("scene {path}: {source}")]
    Parse {
        /// The file.
        path: String,
        /// The parser's error.
        source: toml::de::Error,
    },
    /// A value is out of range.
    #[error("scene {path}: {msg}")]
    Invalid {
        /// The file.
        path: String,
        /// What is wrong.
        msg: String,
    },
}

impl Scene {
    /// Reads and checks a scene TOML.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let text = std::fs::read_to_string(path)
            .map_err(|source| SceneError::Io { path: path.display().to_string(), source })?;
        Scene::parse(&text, &path.display().to_string())
    }

    /// Parses and checks a scene from TOML text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Scene, SceneError> {
        let bad = |msg: String| SceneError::Invalid { path: origin.into(), msg };
        let s: Scene = toml::from_str(text).map_err(|source| SceneError::Parse { path: origin.into(), source })?;
        for (i, e) in s.effects.iter().enumerate() {
            let ok = match *e {
                Effect::Contrast { min, max, .. } => min.is_finite() && max.is_finite() && 0.0 <= min && min <= max,
                Effect::Brightness { min, max, .. } => min.is_finite() && max.is_finite() && min <= max,
                Effect::Noise { amplitude } => amplitude.is_finite() && amplitude >= 0.0,
                Effect::Zoom { min, max } => {
                    min.is_finite() && max.is_finite() && 0.0 < min && min <= max && max <= 4.0
                }
            };
            if !ok {
                return Err(bad(format!(
                    "effect {} ({e:?}) needs finite values with min ≤ max (contrast ≥ 0, zoom in (0, 4])",
                    i + 1
                )));
            }
        }
        if let Some(l) = &s.lighting {
            let v = [l.ambient, l.diffuse, l.specular, l.shininess];
            if v.iter().any(|x| !x.is_finite() || *x < 0.0) || l.direction.iter().all(|x| *x == 0.0) {
                return Err(bad(format!("lighting {l:?}: intensities must be finite and ≥ 0, direction non-zero")));
            }
        }
        Ok(s)
    }

    /// The effect names in order, for logs ("none" when empty).
    pub fn describe(&self) -> String {
        let mut parts: Vec<String> = Vec::new();
        if self.lighting.is_some() {
            parts.push("phong".into());
        }
        for e in &self.effects {
            parts.push(
                match e {
                    Effect::Contrast { .. } => "contrast",
                    Effect::Brightness { .. } => "brightness",
                    Effect::Noise { .. } => "noise",
                    Effect::Zoom { .. } => "zoom",
                }
                .into(),
            );
        }
        if parts.is_empty() {
            "none".into()
        } else {
            parts.join("+")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_authors_eot_and_rejects_bad_values() {
        let s = Scene::parse(
            r#"
            [lighting]
            ambient = 0.7
            diffuse = 0.4
            specular = 0.2
            direction = [1.0, 1.0, 1.0]
            [[effects]]
            kind = "contrast"
            min = 0.8
            max = 1.2
            [[effects]]
            kind = "brightness"
            min = -0.1
            max = 0.1
            per = "image"
            [[effects]]
            kind = "noise"
            amplitude = 0.1
            "#,
            "t",
        )
        .unwrap();
        assert_eq!(s.effects.len(), 3);
        assert_eq!(s.effects[0], Effect::Contrast { min: 0.8, max: 1.2, per: Per::Pixel });
        assert_eq!(s.describe(), "phong+contrast+brightness+noise");
        assert_eq!(Scene::parse("", "t").unwrap().describe(), "none");
        let e = Scene::parse("[[effects]]\nkind = \"contrast\"\nmin = 1.2\nmax = 0.8\n", "s.toml").unwrap_err();
        assert!(e.to_string().contains("scene s.toml: effect 1"), "{e}");
        let e = Scene::parse("[[effects]]\nkind = \"zoom\"\nmin = 0.0\nmax = 1.0\n", "s.toml").unwrap_err();
        assert!(e.to_string().contains("zoom in (0, 4]"), "{e}");
        let e = Scene::parse("[[effects]]\nkind = \"blur\"\n", "s.toml").unwrap_err();
        assert!(e.to_string().contains("blur"), "{e}");
    }
}
