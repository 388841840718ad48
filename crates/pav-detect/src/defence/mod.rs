//! Input-transform defences: what a defended detector does to its input image before the model
//! sees it (median smoothing, bit-depth squeezing, JPEG, cutout, Gaussian noise), and the one
//! defence inside the model (feature norm clipping). They act on the model's 8-bit input (after
//! the resize and padding), as Xu et al.'s squeezers act on a classifier's input, so a defence's
//! strength does not depend on the video's resolution.
//!
//! Each defence is one unit in one file, as ART's preprocessors are: its parameters (its
//! `[[defence]]` keys), their check, its label, its 8-bit transform and its float forward with
//! the backward the white box differentiates through ([`DefenceUnit`]). The backward is exact where
//! the defence is differentiable (median smoothing routes each gradient to the sample it picked;
//! cutout stops it in the squares) and straight through where it is not (BPDA: Athalye et al.
//! 2018), which is the default. Random defences draw afresh for every image, so training through
//! them is Expectation over Transformation. A new defence is a file and one line in
//! [`defences!`]'s list.

mod bits;
mod clip;
mod cutout;
mod jpeg;
mod median;
mod noise;

pub use bits::Bits;
pub use clip::Clip;
pub use cutout::Cutout;
pub use jpeg::Jpeg;
#[cfg(feature = "video")]
pub use jpeg::JpegError;
pub use median::Median;
pub use noise::Noise;

use pav_core::image::Frame;
use pav_core::rng::fnv1a;
use pav_onnx::proto::Model;
use serde::Deserialize;

/// What one defence is and does.
pub trait DefenceUnit {
    /// Checks the parameters' ranges for a `width × height` input.
    fn check(&self, width: usize, height: usize) -> Result<(), String>;

    /// A short label for names and reports: `median3`, `bits5`, `jpeg75`, `cutout2x40`, `noise8`.
    fn label(&self) -> String;

    /// Whether the transform draws random numbers (a fresh draw per image).
    fn random(&self) -> bool {
        false
    }

    /// Whether it transforms the input image (else it changes the model: [`DefenceUnit::rewrite`]).
    fn on_input(&self) -> bool {
        true
    }

    /// The transform on an 8-bit frame; `draw` seeds a random one for this image.
    fn apply(&self, img: &mut Frame, draw: u64) -> Result<(), DefenceError>;

    /// The transform on the white box's float input, three planes of `side × side` values in
    /// [0, 1] (R, G, B), and what its backward needs. By default the 8-bit transform on the input
    /// rounded to levels, the gradient passed straight through.
    fn forward(&self, x: &mut [f32], side: usize, draw: u64) -> Result<Gradient, DefenceError> {
        let mut f = to_frame(x, side);
        self.apply(&mut f, draw)?;
        from_frame(&f, x);
        Ok(Gradient::Straight)
    }

    /// Rewrites a model-side defence into the graph; an input defence leaves it.
    fn rewrite(&self, _model: &mut Model) -> Result<(), pav_onnx::OnnxError> {
        Ok(())
    }
}

/// The defences, each a [`DefenceUnit`] in its own file: one line each makes a `kind` of a detector
/// config's `[[defence]]` and of `--defence`.
macro_rules! defences {
    ($($variant:ident($unit:ty),)*) => {
        /// One defence, as a detector config's `[[defence]]` entry or a `--defence` spec names it
        /// (`kind` picks it).
        #[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
        #[serde(tag = "kind", rename_all = "snake_case")]
        pub enum Defence {
            $(
                #[allow(missing_docs)]
                $variant($unit),
            )*
        }

        impl Defence {
            /// The defence as its unit.
            pub fn unit(&self) -> &dyn DefenceUnit {
                match self {
                    $(Defence::$variant(d) => d,)*
                }
            }
        }
    };
}

defences! {
    Median(Median),
    Bits(Bits),
    Jpeg(Jpeg),
    Cutout(Cutout),
    Noise(Noise),
    Clip(Clip),
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
    Jpeg(#[from] JpegError),
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
        self.unit().check(width, height)
    }

    /// A short label for names and reports: `median3`, `bits5`, `jpeg75`, `cutout2x40`, `noise8`.
    pub fn label(&self) -> String {
        self.unit().label()
    }

    /// Whether the transform draws random numbers (a fresh draw per image).
    pub fn random(&self) -> bool {
        self.unit().random()
    }

    /// Whether it transforms the input image (else it changes the model: [`clip_graph`]).
    pub fn on_input(&self) -> bool {
        self.unit().on_input()
    }

    /// Applies the transform to `img`; `draw` seeds the random ones for this image. A model-side
    /// defence leaves the image alone: the graph carries it.
    pub fn apply(&self, img: &mut Frame, draw: u64) -> Result<(), DefenceError> {
        self.unit().apply(img, draw)
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
    defences.iter().try_for_each(|d| d.unit().rewrite(model))
}

/// What a defence's backward needs from its forward.
#[derive(Clone, Debug)]
pub enum Gradient {
    /// The gradient passes unchanged.
    Straight,
    /// Each output sample's gradient goes to the input sample it copied.
    Gather(Vec<u32>),
    /// The gradient stops where the mask is set (one mask for the three planes).
    Stop(Vec<bool>),
}

/// What a chain's backward needs from its forward, one entry per input defence.
#[derive(Clone, Debug, Default)]
pub struct Tape(Vec<Gradient>);

/// Applies the input defences of `chain` to `x`, three planes of `side × side` values in [0, 1]
/// (R, G, B), in order; model-side defences are skipped (the graph carries them). Random
/// defences draw from `draw`, else from a hash of the input as it reaches them.
pub fn forward(chain: &[Defence], x: &mut [f32], side: usize, draw: Option<u64>) -> Result<Tape, DefenceError> {
    let mut tape = Tape::default();
    for d in chain.iter().filter(|d| d.on_input()) {
        let draw = if d.random() { draw.unwrap_or_else(|| fnv1a(x.iter().map(|v| v.to_bits() as u64))) } else { 0 };
        tape.0.push(d.unit().forward(x, side, draw)?);
    }
    Ok(tape)
}

/// The gradient with respect to the chain's input from the gradient `g` of its output.
pub fn backward(tape: &Tape, g: &mut Vec<f32>) {
    for step in tape.0.iter().rev() {
        match step {
            Gradient::Straight => {}
            Gradient::Gather(from) => {
                let mut out = vec![0f32; g.len()];
                for (i, &j) in from.iter().enumerate() {
                    out[j as usize] += g[i];
                }
                *g = out;
            }
            Gradient::Stop(mask) => {
                for plane in g.chunks_exact_mut(mask.len()) {
                    plane.iter_mut().zip(mask).filter(|(_, m)| **m).for_each(|(v, _)| *v = 0.0);
                }
            }
        }
    }
}

/// Planar RGB in [0, 1] as an 8-bit BGR frame.
fn to_frame(x: &[f32], side: usize) -> Frame {
    let plane = side * side;
    let bgr = (0..plane).flat_map(|i| [2, 1, 0].map(|c| (x[c * plane + i] * 255.0).round().clamp(0.0, 255.0) as u8));
    Frame { width: side, height: side, bgr: bgr.collect() }
}

/// An 8-bit BGR frame back into planar RGB in [0, 1].
fn from_frame(f: &Frame, x: &mut [f32]) {
    let plane = f.width * f.height;
    for (i, px) in f.bgr.chunks_exact(3).enumerate() {
        for (c, &v) in [2, 1, 0].iter().zip(px) {
            x[c * plane + i] = v as f32 / 255.0;
        }
    }
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
    use pav_core::rng::Rng;

    #[test]
    fn specs_parse_into_defences_with_defaults_and_labels() {
        assert_eq!(parse_chain("median:k=3").unwrap(), vec![Defence::Median(Median { k: 3 })]);
        let c = parse_chain("bits:b=5 + jpeg:q=75+cutout:n=2,s=40+noise:sigma=8.5,seed=3").unwrap();
        assert_eq!(
            c,
            vec![
                Defence::Bits(Bits { b: 5 }),
                Defence::Jpeg(Jpeg { q: 75 }),
                Defence::Cutout(Cutout { n: 2, s: 40, fill: 127, seed: 0 }),
                Defence::Noise(Noise { sigma: 8.5, seed: 3 })
            ]
        );
        assert_eq!(chain_label(&c), "bits5+jpeg75+cutout2x40+noise8.5s3");
        let clip = parse_chain(r#"clip:layers=["781", "a,b"],level=0.5"#).unwrap();
        assert_eq!(clip, vec![Defence::Clip(Clip { layers: vec!["781".into(), "a,b".into()], level: 0.5 })]);
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
        assert!(Defence::Median(Median { k: 5 }).check(4, 8).unwrap_err().contains("wider than the 4x8 input"));
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

    fn planes(side: usize, seed: u64) -> Vec<f32> {
        let mut rng = Rng::new(seed);
        (0..3 * side * side).map(|_| rng.unit()).collect()
    }

    /// Σ w·defended(x) and its gradient, against central differences (median smoothing and
    /// cutout are piecewise linear: away from ties, the differences are exact).
    #[test]
    fn median_and_cutout_backward_match_finite_differences() {
        let side = 9;
        for chain in [
            vec![Defence::Median(Median { k: 3 })],
            vec![Defence::Cutout(Cutout { n: 2, s: 4, fill: 127, seed: 1 })],
            vec![Defence::Median(Median { k: 5 }), Defence::Cutout(Cutout { n: 1, s: 3, fill: 0, seed: 2 })],
        ] {
            let x = planes(side, 3);
            let w = planes(side, 4);
            // The draw held fixed: the derivative of one sampled transformation.
            let run = |x: &[f32]| -> (Vec<f32>, Tape) {
                let mut y = x.to_vec();
                let t = forward(&chain, &mut y, side, Some(7)).unwrap();
                (y, t)
            };
            let f = |x: &[f32]| -> f64 { run(x).0.iter().zip(&w).map(|(a, b)| *a as f64 * *b as f64).sum() };
            let tape = run(&x).1;
            let mut g = w.clone();
            backward(&tape, &mut g);
            let eps = 1e-3f32;
            let mut checked = 0;
            for i in (0..x.len()).step_by(7) {
                let (mut p, mut q) = (x.clone(), x.clone());
                p[i] += eps;
                q[i] -= eps;
                let same = |t: Tape| format!("{t:?}") == format!("{tape:?}");
                if !same(run(&p).1) || !same(run(&q).1) {
                    continue; // another sample became a median: not this point's derivative
                }
                let fd = (f(&p) - f(&q)) / (2.0 * eps as f64);
                assert!((fd as f32 - g[i]).abs() < 1e-3, "{chain:?} sample {i}: {} vs {fd}", g[i]);
                checked += 1;
            }
            assert!(checked > 20, "{chain:?}: only {checked} samples kept their draw and medians");
        }
    }

    #[cfg(feature = "video")]
    #[test]
    fn straight_through_defences_pass_the_gradient_and_change_the_forward() {
        let side = 16;
        let x = planes(side, 5);
        for d in [
            Defence::Bits(Bits { b: 2 }),
            Defence::Jpeg(Jpeg { q: 20 }),
            Defence::Noise(Noise { sigma: 10.0, seed: 0 }),
        ] {
            let mut y = x.clone();
            let tape = forward(std::slice::from_ref(&d), &mut y, side, None).unwrap();
            assert!(y.iter().zip(&x).any(|(a, b)| (a - b).abs() > 0.01), "{d:?} changed nothing");
            let mut g = x.clone();
            backward(&tape, &mut g);
            assert_eq!(g, x);
        }
    }
}
