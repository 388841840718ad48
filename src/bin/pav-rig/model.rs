//! `pav-rig model`.

use anyhow::{bail, Context, Result};
use clap::Subcommand;
use pav_onnx::darknet::to_onnx::convert;
use pav_onnx::proto::Model;
use pav_onnx::surrogate::dequantize;
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum Cmd {
    /// What an ONNX detector takes and gives: inputs and outputs (names, types, declared shapes
    /// and the shapes of one run on a blank image), opset and operators, a guess at its output
    /// layout, and a detector-config skeleton to complete.
    #[command(after_help = "Examples:
  pav-rig model inspect data:models-yolox/yolox_nano.onnx --size 416
  pav-rig model inspect data:models-yolox/yolox_nano.onnx -o my_detector.toml
  pav-rig model inspect data:models-picodet/picodet_xs_320_lcnet_postprocessed.onnx --values")]
    Inspect {
        /// The ONNX model (`data:NAME` for a manifest entry).
        #[arg(value_parser = pav::data::arg_path)]
        model: PathBuf,
        /// Image side for the run when the model's input size is symbolic.
        #[arg(long, default_value_t = 640)]
        size: usize,
        /// Read the file only; do not run it with ONNX Runtime.
        #[arg(long)]
        no_run: bool,
        /// Write the skeleton config here instead of printing it.
        #[arg(long, short = 'o')]
        out: Option<PathBuf>,
        /// Also list every value the graph computes, with its operator and shape in one run: the
        /// names a description may give inside the graph (the scores a post-processor reads).
        #[arg(long, conflicts_with = "no_run")]
        values: bool,
    },
    /// Try a finished detector config on images with a car: every detection above a score, the
    /// target's best, and each image with its boxes drawn (targets green, others orange), so that a
    /// wrong channel order, scale or layout shows at once.
    #[command(after_help = "Examples:
  pav-rig model check --config configs/detectors/yolox_nano.toml fixtures/turntable.mp4#0 -o out/check")]
    Check {
        /// The detector config.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Image files (any format OpenCV reads), FCA `.npz` samples, or `VIDEO#K` for frame K;
        /// `data:NAME` for a manifest entry. Without --config, the first argument is the config.
        #[arg(required = true, value_name = "IMAGES")]
        images: Vec<String>,
        /// List detections from this score.
        #[arg(long, default_value_t = 0.25)]
        min_score: f32,
        /// Folder for the images with their boxes drawn (`<name>.png`).
        #[arg(long, short = 'o')]
        out: Option<PathBuf>,
    },
    /// Convert a darknet cfg + weights (YOLOv3/YOLOv3-tiny) to an ONNX graph with raw head outputs.
    #[command(after_help = "Examples:
  pav-rig model darknet2onnx --cfg yolov3-tiny.cfg --weights yolov3-tiny.weights -o yolov3-tiny.onnx")]
    Darknet2onnx {
        /// Darknet .cfg file.
        #[arg(long)]
        cfg: PathBuf,
        /// Darknet .weights file.
        #[arg(long)]
        weights: PathBuf,
        /// Output .onnx path.
        #[arg(long, short = 'o')]
        out: PathBuf,
    },
    /// Write the float surrogate of a dynamically quantized ONNX model (ConvInteger and MatMulInteger
    /// chains become float Convs and MatMuls with dequantized weights): not the evaluated model.
    #[command(after_help = "Examples:
  pav-rig model surrogate data:models-yolov8n/yolov8n_int8.onnx -o yolov8n_float.onnx")]
    Surrogate {
        /// The quantized model, e.g. yolov8n_int8.onnx (`data:NAME` for a manifest entry).
        #[arg(value_parser = pav::data::arg_path)]
        model: PathBuf,
        /// Output .onnx path.
        #[arg(short, long)]
        out: PathBuf,
    },
}

pub fn run(c: &Cmd) -> Result<()> {
    match c {
        Cmd::Inspect { model, size, no_run, out, values } => inspect(model, *size, *no_run, *values, out.as_deref())?,
        Cmd::Check { config, images, min_score, out } => {
            let (config, images) = match config {
                Some(c) => (c.clone(), &images[..]),
                None if images.len() >= 2 => (PathBuf::from(&images[0]), &images[1..]),
                None => bail!("model check needs --config DETECTOR.toml and at least one image"),
            };
            check(&config, images, *min_score, out.as_deref())?
        }
        Cmd::Darknet2onnx { cfg, weights, out } => {
            let r = convert(cfg, weights, out)?;
            eprintln!(
                "wrote {} ({} layers, {} heads, {:.1} MB)",
                out.display(),
                r.layers,
                r.heads,
                r.bytes as f64 / 1e6
            );
        }
        Cmd::Surrogate { model, out } => {
            let bytes = std::fs::read(model).with_context(|| format!("reading {}", model.display()))?;
            let m = Model::from_bytes(&bytes).with_context(|| format!("parsing {}", model.display()))?;
            let (s, r) = dequantize(&m).with_context(|| model.display().to_string())?;
            let b = s.to_bytes();
            std::fs::write(out, &b).with_context(|| format!("writing {}", out.display()))?;
            eprintln!(
                "wrote {} ({} quantized convolutions and {} matrix products made float, {} nodes removed, {:.1} MB): a surrogate, not the evaluated model",
                out.display(),
                r.convs,
                r.matmuls,
                r.nodes_removed,
                b.len() as f64 / 1e6
            );
        }
    }
    Ok(())
}

fn check(config: &std::path::Path, images: &[String], min_score: f32, out: Option<&std::path::Path>) -> Result<()> {
    use pav::detect::check::{annotate, check, drawn_name, read_input};
    use pav::detect::Detector;
    if !(0.0..=1.0).contains(&min_score) {
        anyhow::bail!("--min-score {min_score} must be within [0, 1]");
    }
    let cfg = pav::detect::DetectorConfig::load(config)?;
    let names = cfg.class_names.clone();
    let mut det = pav::detect::onnx::OnnxDetector::new(cfg, 0)?;
    let target = det.target_label();
    if let Some(o) = out {
        std::fs::create_dir_all(o).with_context(|| format!("creating {}", o.display()))?;
    }
    let (mut missed, mut warned, mut refused) = (0, 0, 0);
    for spec in images {
        let frame = read_input(spec)?;
        let c = check(&mut det, &frame, min_score)?;
        outln!("{spec} ({}x{}):", frame.width, frame.height);
        for d in &c.detections {
            let b = d.bbox;
            let star = if det.target_classes().contains(&d.class_id) { " *" } else { "" };
            outln!(
                "  {:<14} {:.3}  [{:.0}, {:.0}, {:.0}, {:.0}]{star}",
                names[d.class_id],
                d.score,
                b[0],
                b[1],
                b[2],
                b[3]
            );
        }
        match c.best {
            Some(b) if b.score >= min_score => outln!(
                "  best {target}: {:.3} at [{:.0}, {:.0}, {:.0}, {:.0}]",
                b.score,
                b.bbox[0],
                b.bbox[1],
                b.bbox[2],
                b.bbox[3]
            ),
            best => {
                missed += 1;
                outln!("  no {target} from {min_score} (best {:.3})", best.map_or(0.0, |b| b.score));
            }
        }
        if let Some(r) = &c.refused {
            outln!("  error: {r}");
        }
        for w in &c.warnings {
            outln!("  warning: {w}");
        }
        (warned, refused) = (warned + !c.warnings.is_empty() as usize, refused + c.refused.is_some() as usize);
        if let Some(o) = out {
            let path = o.join(drawn_name(spec));
            annotate(&frame, &c.detections, det.target_classes()).save_png(&path)?;
            outln!("  wrote {}", path.display());
        }
    }
    for line in pav::detect::check::closing(refused, warned, missed, images.len(), &target) {
        outln!("\n{line}");
    }
    if refused > 0 {
        anyhow::bail!("the description of {} gives scores outside [0, 1]", config.display());
    }
    Ok(())
}

fn inspect(
    model: &std::path::Path,
    size: usize,
    no_run: bool,
    values: bool,
    out: Option<&std::path::Path>,
) -> Result<()> {
    use pav::detect::inspect::{from_session, inspect_file, probe};
    let mut insp = match inspect_file(model) {
        Ok(i) => i,
        // A graph pav's reader does not parse may still load in ONNX Runtime.
        Err(e) if !no_run => {
            eprintln!("{e}; reading its inputs and outputs through ONNX Runtime instead");
            from_session(model)?
        }
        Err(e) => anyhow::bail!(e),
    };
    let side = insp.fixed_side().unwrap_or(size);
    if !no_run {
        probe(model, &mut insp, side)?;
    }
    let opset = if insp.opset > 0 { insp.opset.to_string() } else { "unknown".into() };
    outln!(
        "{}: opset {opset}{}{}",
        model.display(),
        insp.domains.iter().map(|(d, v)| format!(", {d} {v}")).collect::<String>(),
        if insp.producer.is_empty() { String::new() } else { format!(", exported by {}", insp.producer) }
    );
    let dims = |d: &[String]| format!("[{}]", d.join(", "));
    for (what, ports) in [("input", &insp.inputs), ("output", &insp.outputs)] {
        for p in ports.iter() {
            let ran = p.ran.as_ref().map(|r| format!(", ran {:?}", r)).unwrap_or_default();
            outln!("  {what:6} {:28} {:8} {}{ran}", p.name, p.dtype, dims(&p.declared));
        }
    }
    let ops: Vec<String> = insp.ops.iter().map(|(o, n)| format!("{o} {n}")).collect();
    outln!("  operators: {}", ops.join(", "));
    if values {
        for v in pav::detect::inspect::values(model, &insp, side)? {
            outln!("  value  {:28} {:12} {:?}", v.name, v.op, v.shape);
        }
    }
    let guess = insp.guess(side);
    outln!("layout: {} ({})", guess.layout.unwrap_or("none of pav's"), guess.why);
    let stem = model.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "model".into());
    let skeleton = insp.skeleton(&stem, &model.display().to_string(), side, &guess);
    match out {
        Some(o) => {
            std::fs::write(o, &skeleton).with_context(|| format!("writing {}", o.display()))?;
            outln!("wrote {} (complete the values marked CHECK)", o.display());
        }
        None => outln!("\n{skeleton}"),
    }
    Ok(())
}
