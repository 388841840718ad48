//! `pav-rig model`.

use anyhow::Context;
use anyhow::Result;
use clap::Subcommand;
use pav::detect::darknet::to_onnx::convert;
use pav::detect::onnx_proto::Model;
use pav::detect::surrogate::dequantize;
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum Cmd {
    /// Convert a darknet cfg + weights (YOLOv3/YOLOv3-tiny) to an ONNX graph with raw head outputs.
    Darknet2onnx {
        /// Darknet .cfg file.
        #[arg(long)]
        cfg: PathBuf,
        /// Darknet .weights file.
        #[arg(long)]
        weights: PathBuf,
        /// Output .onnx path.
        #[arg(long)]
        out: PathBuf,
    },
    /// Write the float surrogate of a dynamically quantized ONNX model (ConvInteger and MatMulInteger
    /// chains become float Convs and MatMuls with dequantized weights): not the evaluated model.
    Surrogate {
        /// The quantized model, e.g. yolov8n_int8.onnx.
        model: PathBuf,
        /// Output .onnx path.
        #[arg(short, long)]
        out: PathBuf,
    },
}

pub fn run(c: &Cmd) -> Result<()> {
    match c {
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
