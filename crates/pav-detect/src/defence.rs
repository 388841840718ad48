//! Input-transform defences: what a defended detector does to its input image before the model
//! sees it (median smoothing, bit-depth squeezing, JPEG, cutout, Gaussian noise). They act on the
//! model's 8-bit input (after the resize and padding), as Xu et al.'s squeezers act on a
//! classifier's input, so a defence's strength does not depend on the video's resolution.

use pav_core::image::filter;
use pav_core::image::Frame;
use pav_core::rng::{fnv1a, Rng};
use pav_onnx::proto::Model;
use serde::Deserialize;

/// One input transform, as a detector config's `[[defence]]` entry or a `--defence` spec names it.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Defence {
    /// Spatial smoothing: the median of each `k × k` window (`k` odd, at least 3).
    Median {
        /// Window side.
        k: usize,
    },
    /// Feature squeezing by bit depth: `2^b` levels per channel (`b` from 1 to 8).
    Bits {
        /// Bits kept.
        b: u32,
    },
    /// JPEG re-compression at quality `q` (1–100).
    Jpeg {
        /// Quality.
        q: u32,
    },
    /// Cutout: `n` squares of side `s` input pixels, centres drawn per image, filled with `fill`.
    Cutout {
        /// Squares per image.
        n: usize,
        /// Their side in input pixels.
        s: usize,
        /// Grey level they are filled with (0–255).
        #[serde(default = "mid_grey")]
        fill: u8,
        /// Seed of the draws (mixed with the image, so a frame always gets the same squares).
        #[serde(default)]
        seed: u64,
    },
    /// Gaussian noise of standard deviation `sigma` levels (0–255 scale).
    Noise {
        /// Standard deviation in levels.
        sigma: f32,
        /// Seed of the draws (mixed with the image, as for cutout).
        #[serde(default)]
        seed: u64,
    },
    /// Feature norm clipping, in the model: after each tensor of `layers`, feature vectors longer
    /// than `level` times the map's mean norm are scaled down to it (Yu et al. 2021 use level 1).
    /// Rewritten into the graph when it loads; an int8 model is clipped on its float surrogate.
    Clip {
        /// Tensor names (node outputs) to clip after.
        layers: Vec<String>,
        /// Bound as a multiple of the mean feature norm.
        #[serde(default = "unit_level")]
        level: f32,
    },
}

fn unit_level() -> f32 {
    1.0
}

fn mid_grey() -> u8 {
    127
}

/// A defence that cannot be built or run.
#[derive(Debug, thiserror::Error)]
pub enum DefenceError {
    /// A `--defence` spec or `[[defence]]` entry is malformed or out of range.
    #[error("defence `{spec}`: {msg}")]
    Invalid {
        /// The spec or entry as written.
        spec: String,
        /// What is wrong.
        msg: String,
    },
    /// JPEG re-compression failed.
    #[cfg(feature = "video")]
    #[error(transparent)]
    Jpeg(#[from] filter::JpegError),
    /// JPEG re-compression needs OpenCV.
    #[cfg(not(feature = "video"))]
    #[error("the JPEG defence needs pav built with the `video` feature")]
    NoJpeg,
}

impl Defence {
    /// Parses one `--defence` item, `NAME` or `NAME:KEY=VALUE,...` (`median:k=3`, `jpeg:q=75`,
    /// `cutout:n=2,s=40`).
    pub fn parse(spec: &str) -> Result<Defence, DefenceError> {
        let invalid = |msg: String| DefenceError::Invalid { spec: spec.to_string(), msg };
        let (kind, params) = spec.split_once(':').unwrap_or((spec, ""));
        let mut table = toml::Table::new();
        table.insert("kind".into(), toml::Value::String(kind.trim().to_string()));
        for kv in split_params(params).into_iter().filter(|p| !p.trim().is_empty()) {
            let (k, v) = kv.split_once('=').ok_or_else(|| invalid(format!("`{kv}` is not KEY=VALUE")))?;
            let value: toml::Value = toml::from_str::<toml::Table>(&format!("v = {}", v.trim()))
                .ok()
                .and_then(|mut t| t.remove("v"))
                .ok_or_else(|| invalid(format!("`{}` is not a number", v.trim())))?;
            table.insert(k.trim().to_string(), value);
        }
        let d = Defence::deserialize(toml::Value::Table(table)).map_err(|e| invalid(e.message().to_string()))?;
        d.check(usize::MAX, usize::MAX).map_err(invalid)?;
        Ok(d)
    }

    /// Checks the parameters' ranges for a `width × height` input.
    pub fn check(&self, width: usize, height: usize) -> Result<(), String> {
        match *self {
            Defence::Median { k } if k < 3 || k % 2 == 0 => Err(format!("k = {k} must be odd and at least 3")),
            Defence::Median { k } if k > width.min(height) => {
                Err(format!("k = {k} is wider than the {width}x{height} input"))
            }
            Defence::Bits { b } if !(1..=8).contains(&b) => Err(format!("b = {b} must be 1 to 8 bits")),
            Defence::Jpeg { q } if !(1..=100).contains(&q) => Err(format!("q = {q} must be a quality from 1 to 100")),
            Defence::Jpeg { .. } if cfg!(not(feature = "video")) => {
                Err("the JPEG defence needs pav built with the `video` feature".into())
            }
            Defence::Cutout { n, s, .. } if n == 0 || s == 0 => Err(format!("n = {n} and s = {s} must be positive")),
            Defence::Cutout { s, .. } if s > width.max(height) => {
                Err(format!("s = {s} is larger than the {width}x{height} input"))
            }
            Defence::Noise { sigma, .. } if !(sigma.is_finite() && sigma > 0.0 && sigma <= 255.0) => {
                Err(format!("sigma = {sigma} must be a level in (0, 255]"))
            }
            Defence::Clip { ref layers, .. } if layers.is_empty() => Err("layers names no tensor to clip after".into()),
            Defence::Clip { level, .. } if level.is_nan() || level <= 0.0 => {
                Err(format!("level = {level} must be positive (inf: no clipping)"))
            }
            _ => Ok(()),
        }
    }

    /// A short label for names and reports: `median3`, `bits5`, `jpeg75`, `cutout2x40`, `noise8`.
    pub fn label(&self) -> String {
        let seeded = |seed: u64| if seed == 0 { String::new() } else { format!("s{seed}") };
        match self {
            Defence::Median { k } => format!("median{k}"),
            Defence::Bits { b } => format!("bits{b}"),
            Defence::Jpeg { q } => format!("jpeg{q}"),
            Defence::Cutout { n, s, seed, .. } => format!("cutout{n}x{s}{}", seeded(*seed)),
            Defence::Noise { sigma, seed } => format!("noise{sigma}{}", seeded(*seed)),
            Defence::Clip { level, .. } => format!("clip{level}"),
        }
    }

    /// Whether the transform draws random numbers (a fresh draw per image).
    pub fn random(&self) -> bool {
        matches!(self, Defence::Cutout { .. } | Defence::Noise { .. })
    }

    /// Whether it transforms the input image (else it changes the model: [`clip_graph`]).
    pub fn on_input(&self) -> bool {
        !matches!(self, Defence::Clip { .. })
    }

    /// Applies the transform to `img`; `draw` seeds the random ones for this image. A model-side
    /// defence leaves the image alone: the graph carries it.
    pub fn apply(&self, img: &mut Frame, draw: u64) -> Result<(), DefenceError> {
        match *self {
            Defence::Median { k } => filter::median(img, k),
            Defence::Bits { b } => filter::reduce_bits(img, b),
            #[cfg(feature = "video")]
            Defence::Jpeg { q } => filter::jpeg(img, q as u8)?,
            #[cfg(not(feature = "video"))]
            Defence::Jpeg { .. } => return Err(DefenceError::NoJpeg),
            Defence::Cutout { n, s, fill, seed } => {
                let holes = filter::cutout_holes(img.width, img.height, n, s, &mut Rng::new(seed ^ draw));
                filter::erase(img, &holes, fill)
            }
            Defence::Noise { sigma, seed } => filter::gaussian_noise(img, sigma, &mut Rng::new(seed ^ draw)),
            Defence::Clip { .. } => {}
        }
        Ok(())
    }
}

/// Parses a `--defence` value: one defence or a chain joined by `+` (`median:k=3+jpeg:q=75`),
/// applied left to right.
pub fn parse_chain(spec: &str) -> Result<Vec<Defence>, DefenceError> {
    if spec.trim().is_empty() {
        return Err(DefenceError::Invalid { spec: spec.into(), msg: "names no defence".into() });
    }
    spec.split('+').map(|s| Defence::parse(s.trim())).collect()
}

/// The chain's label, its defences' labels joined by `+`.
pub fn chain_label(chain: &[Defence]) -> String {
    chain.iter().map(Defence::label).collect::<Vec<_>>().join("+")
}

/// The labels of several chains, as a run records them (`median3;jpeg75`).
pub fn chains_label(chains: &[Vec<Defence>]) -> String {
    chains.iter().map(|c| chain_label(c)).collect::<Vec<_>>().join(";")
}

/// Applies `chain` to `img` in order. Random defences draw from their seed mixed with a hash of
/// the image as it reaches them, so a frame gets the same draw whatever order or thread scores it.
pub fn apply_chain(chain: &[Defence], img: &mut Frame) -> Result<(), DefenceError> {
    for d in chain {
        let draw = if d.random() { fnv1a(img.bgr.iter().map(|&b| b as u64)) } else { 0 };
        d.apply(img, draw)?;
    }
    Ok(())
}

/// Rewrites the model-side defences of `defences` (feature norm clipping) into `model`.
pub fn clip_graph(model: &mut Model, defences: &[Defence]) -> Result<(), pav_onnx::OnnxError> {
    for d in defences {
        if let Defence::Clip { layers, level } = d {
            for l in layers {
                pav_onnx::rewrite::clip_feature_norms(model, l, *level)?;
            }
        }
    }
    Ok(())
}

/// `params` split at the commas outside brackets and quotes (`layers=["a","b"],level=1`).
fn split_params(params: &str) -> Vec<&str> {
    let (mut out, mut start, mut depth, mut quoted) = (Vec::new(), 0, 0i32, false);
    for (i, c) in params.char_indices() {
        match c {
            '"' | '\'' => quoted = !quoted,
            '[' if !quoted => depth += 1,
            ']' if !quoted => depth -= 1,
            ',' if !quoted && depth == 0 => {
                out.push(&params[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    out.push(&params[start..]);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_into_defences_with_defaults_and_labels() {
        assert_eq!(parse_chain("median:k=3").unwrap(), vec![Defence::Median { k: 3 }]);
        let c = parse_chain("bits:b=5 + jpeg:q=75+cutout:n=2,s=40+noise:sigma=8.5,seed=3").unwrap();
        assert_eq!(
            c,
            vec![
                Defence::Bits { b: 5 },
                Defence::Jpeg { q: 75 },
                Defence::Cutout { n: 2, s: 40, fill: 127, seed: 0 },
                Defence::Noise { sigma: 8.5, seed: 3 }
            ]
        );
        assert_eq!(chain_label(&c), "bits5+jpeg75+cutout2x40+noise8.5s3");
        let clip = parse_chain(r#"clip:layers=["781", "a,b"],level=0.5"#).unwrap();
        assert_eq!(clip, vec![Defence::Clip { layers: vec!["781".into(), "a,b".into()], level: 0.5 }]);
        assert_eq!(parse_chain("clip:layers=['x'],level=inf").unwrap()[0].label(), "clipinf");
        assert!(!clip[0].on_input() && c.iter().all(Defence::on_input));
    }

    #[test]
    fn bad_specs_name_the_problem() {
        let err = |s: &str| parse_chain(s).unwrap_err().to_string();
        for (spec, says) in [
            ("blur:k=3", "unknown variant `blur`"),
            ("median:k=4", "k = 4 must be odd"),
            ("median:k=1", "k = 1 must be odd and at least 3"),
            ("median", "missing field `k`"),
            ("median:k=3,r=2", "unknown field `r`"),
            ("median:k", "`k` is not KEY=VALUE"),
            ("median:k=three", "`three` is not a number"),
            ("jpeg:q=0", "q = 0 must be a quality from 1 to 100"),
            ("jpeg:q=101", "q = 101"),
            ("bits:b=0", "b = 0 must be 1 to 8"),
            ("bits:b=9", "b = 9"),
            ("cutout:n=0,s=4", "must be positive"),
            ("cutout:n=1,s=4,fill=300", "u8"),
            ("noise:sigma=-1", "sigma = -1"),
            ("clip:layers=[]", "layers names no tensor"),
            ("clip:layers=['x'],level=0", "level = 0 must be positive"),
            ("clip:layers=['x'],level=nan", "level = NaN must be positive"),
            ("clip:layers=781", "expected a sequence"),
            ("", "names no defence"),
        ] {
            let e = err(spec);
            assert!(e.contains(says), "{spec}: {e}");
        }
        assert!(Defence::Median { k: 5 }.check(4, 8).unwrap_err().contains("wider than the 4x8 input"));
    }

    #[test]
    fn random_defences_draw_per_image_and_repeat_on_the_same_image() {
        let img = |v: u8| Frame { width: 32, height: 32, bgr: vec![v; 32 * 32 * 3] };
        let chain = parse_chain("cutout:n=1,s=8,fill=0").unwrap();
        let run = |mut f: Frame| {
            apply_chain(&chain, &mut f).unwrap();
            f.bgr.iter().position(|&v| v == 0).unwrap()
        };
        assert_eq!(run(img(200)), run(img(200)));
        let spots: std::collections::BTreeSet<usize> = (100..120).map(|v| run(img(v))).collect();
        assert!(spots.len() > 10, "{spots:?}");
    }
}
