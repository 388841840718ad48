//! `pav uv check` and `pav uv adjust`.

use anyhow::Result;
use clap::Subcommand;
use pav::attack::uv::{adjust_patch, check, AdjustMode, UvCheck};
use std::path::{Path, PathBuf};

#[derive(Subcommand)]
pub enum Cmd {
    /// Per-face stretch/compression of the optimizable patch: CSV, summary and heat maps
    /// (grey = none, purple = stretched, red = compressed, as MAYA shows them).
    #[command(after_help = "Examples:
  pav uv check -o out/uv")]
    Check {
        /// OBJ mesh with UVs.
        #[arg(long, value_parser = pav::data::arg_path, default_value = "data:pav-camou/xfl_yxz.obj")]
        mesh: PathBuf,
        /// UV map whose pure-white texels mark the optimizable patch.
        #[arg(long, value_parser = pav::data::arg_path, default_value = "data:pav-camou/half.png")]
        mask: PathBuf,
        /// Output directory.
        #[arg(long, short = 'o', default_value = "out/uv")]
        out: PathBuf,
    },
    /// Re-flatten the optimizable patch automatically at one common texel density; writes the
    /// adjusted OBJ, its UV mask, and before/after heat maps.
    #[command(after_help = "Examples:
  pav uv adjust -o out/uv_adjusted")]
    Adjust {
        /// OBJ mesh with UVs.
        #[arg(long, value_parser = pav::data::arg_path, default_value = "data:pav-camou/xfl_yxz.obj")]
        mesh: PathBuf,
        /// UV map whose pure-white texels mark the optimizable patch.
        #[arg(long, value_parser = pav::data::arg_path, default_value = "data:pav-camou/half.png")]
        mask: PathBuf,
        /// charts: cut by the 3D surface (a door is one piece) and pack into the free texels;
        /// islands: LSCM per original UV island, kept inside its original box.
        #[arg(long, value_enum, default_value_t = Mode::Charts)]
        mode: Mode,
        /// Charts: largest angle between a face's normal and its chart's seed normal.
        #[arg(long, default_value_t = 45.0)]
        max_angle: f64,
        /// Output directory.
        #[arg(long, short = 'o', default_value = "out/uv_adjusted")]
        out: PathBuf,
    },
}

/// How `pav uv adjust` re-flattens the patch.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Mode {
    /// 3D charts packed into the free texels.
    Charts,
    /// Original UV islands, each kept in its box.
    Islands,
}

fn print_check(r: &UvCheck, out: &Path) {
    outln!(
        "{} patch faces: area-weighted mean |log2 stretch| {:.3} (1.0 = a factor of 2), 95th-percentile anisotropy {:.2}",
        r.faces, r.mean_abs_log2_stretch, r.p95_anisotropy
    );
    eprintln!("wrote {}/uv_distortion.csv, uv_heat_uv.png, uv_heat_mesh.png", out.display());
}

pub fn run(c: &Cmd) -> Result<()> {
    match c {
        Cmd::Check { mesh, mask, out } => print_check(&check(mesh, mask, out)?, out),
        Cmd::Adjust { mesh, mask, mode, max_angle, out } => {
            let mode = match mode {
                Mode::Charts => AdjustMode::Charts { max_angle_deg: *max_angle },
                Mode::Islands => AdjustMode::Islands,
            };
            let r = adjust_patch(mesh, mask, mode, out)?;
            print_check(&r.written[0], &out.join("after"));
            print_check(&r.written[1], &out.join("before"));
            let pieces = r.charts.map_or(String::new(), |(charts, joined, flipped)| {
                format!("; {charts} charts (one joins up to {joined} original UV islands), {flipped} folded faces")
            });
            outln!(
                "adjusted {} faces: mean |log2 stretch| {:.3} -> {:.3}, 95th-percentile anisotropy {:.2} -> {:.2}; texel density {:.0} % of the original{pieces}",
                r.before.faces,
                r.before.mean_abs_log2_stretch,
                r.after.mean_abs_log2_stretch,
                r.before.p95_anisotropy,
                r.after.p95_anisotropy,
                100.0 * r.density
            );
            eprintln!("wrote {}/adjusted.obj, adjusted_mask.png, before/ and after/", out.display());
        }
    }
    Ok(())
}
