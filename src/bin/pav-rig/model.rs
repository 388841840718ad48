//! `pav-rig model`.

use anyhow::Result;
use clap::Subcommand;
use pav::detect::darknet::to_onnx::convert;
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
}

pub fn run(c: &Cmd) -> Result<()> {
    let Cmd::Darknet2onnx { cfg, weights, out } = c;
    let r = convert(cfg, weights, out)?;
    eprintln!("wrote {} ({} layers, {} heads, {:.1} MB)", out.display(), r.layers, r.heads, r.bytes as f64 / 1e6);
    Ok(())
}
