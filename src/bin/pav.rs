//! `pav`: the texture side of PAV-Camou — rendering (and, as it lands, optimization).

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use pav::dataset::fca::CarlaSample;
use pav::geometry::camera::{pav_camou, spherical, Camera};
use pav::geometry::mesh::Mesh;
use pav::render::raster::GBuffer;
use pav::render::texture::{Gather, Texture};
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "pav",
    version,
    about = "PAV-Camou texture tools: render the textured car"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Render the mesh with its UV texture (flat, unlit) and the textured-region mask as PNGs.
    Render {
        /// OBJ mesh with UVs.
        #[arg(long, default_value = "../shared/data/pav-camou/xfl_yxz.obj")]
        mesh: PathBuf,
        /// UV texture (default: the body material's map_Kd).
        #[arg(long)]
        texture: Option<PathBuf>,
        /// Camera from a CARLA npz sample's cam_trans (PAV-Camou convention).
        #[arg(long, conflicts_with = "orbit")]
        pose: Option<PathBuf>,
        /// Camera at "dist,elev,azim" (normalized units, degrees) looking at the origin.
        #[arg(long)]
        orbit: Option<String>,
        /// Image side in pixels.
        #[arg(long, default_value_t = 800)]
        size: usize,
        /// Output PNG; the mask goes beside it as NAME_mask.png.
        #[arg(long, short = 'o', default_value = "out/render.png")]
        out: PathBuf,
    },
}

fn save_rgb(path: &std::path::Path, size: usize, rgb: &[f32]) -> Result<()> {
    let bytes: Vec<u8> = rgb
        .iter()
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    image::RgbImage::from_raw(size as u32, size as u32, bytes)
        .context("image buffer size")?
        .save(path)
        .with_context(|| format!("writing {}", path.display()))
}

fn main() -> Result<()> {
    let Cmd::Render {
        mesh,
        texture,
        pose,
        orbit,
        size,
        out,
    } = Cli::parse().cmd;
    let mut m = Mesh::load_obj(&mesh)?;
    m.normalize();
    let tex_path = match texture {
        Some(t) => t,
        None => m
            .materials
            .iter()
            .find_map(|x| x.map_kd.clone())
            .context("the mesh names no map_Kd texture: pass --texture")?,
    };
    let tex = Texture::load(&tex_path).map_err(anyhow::Error::msg)?;
    let cam: Camera = match (pose, orbit) {
        (Some(p), _) => {
            let s = CarlaSample::load(&p)?;
            pav_camou(s.cam_trans, s.veh_trans[1][1])
        }
        (None, Some(o)) => {
            let v: Vec<f32> = o
                .split(',')
                .map(|s| s.trim().parse())
                .collect::<Result<_, _>>()
                .with_context(|| format!("--orbit `{o}`: expected dist,elev,azim"))?;
            let [d, e, a] = v[..] else {
                bail!("--orbit `{o}`: expected three numbers dist,elev,azim")
            };
            Camera::look_at(spherical(d, e, a), [0.0; 3], [0.0, 1.0, 0.0], 60.0)
        }
        (None, None) => {
            Camera::look_at(spherical(2.2, 20.0, 45.0), [0.0; 3], [0.0, 1.0, 0.0], 60.0)
        }
    };
    let g = GBuffer::render(&m, &cam, size);
    let gather = Gather::new(g.uv_samples(&m), tex.width, tex.height);
    let mut rgb = vec![1.0f32; size * size * 3];
    gather.apply(&tex.rgb, 3, &mut rgb);
    let white: Vec<f32> = tex
        .rgb
        .chunks(3)
        .map(|c| {
            if c.iter().all(|v| *v == 1.0) {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    let mut mask = vec![0.0f32; size * size];
    gather.apply(&white, 1, &mut mask);
    if let Some(d) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d)?;
    }
    save_rgb(&out, size, &rgb)?;
    let mask_path = out.with_file_name(format!(
        "{}_mask.png",
        out.file_stem().unwrap_or_default().to_string_lossy()
    ));
    let mask_rgb: Vec<f32> = mask.iter().flat_map(|v| [*v; 3]).collect();
    save_rgb(&mask_path, size, &mask_rgb)?;
    eprintln!(
        "car covers {:.1} % of the image; wrote {} and {}",
        100.0 * g.coverage(),
        out.display(),
        mask_path.display()
    );
    Ok(())
}
