//! `pav render`.

use anyhow::{bail, Context, Result};
use pav::dataset::fca::CarlaSample;
use pav::geometry::camera::{pav_camou, spherical, Camera};
use pav::geometry::mesh::Mesh;
use pav::image::{save_rgb, Rgb};
use pav::render::preview::textured;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// OBJ mesh with UVs.
    #[arg(long, value_parser = pav::data::arg_path, default_value = "data:pav-camou/xfl_yxz.obj")]
    mesh: PathBuf,
    /// UV texture (default: the body material's map_Kd).
    #[arg(long, value_parser = pav::data::arg_path)]
    texture: Option<PathBuf>,
    /// Camera from a CARLA npz sample's cam_trans (PAV-Camou convention).
    #[arg(long, conflicts_with = "orbit", value_parser = pav::data::arg_path)]
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
}

fn camera(a: &Args) -> Result<Camera> {
    Ok(match (&a.pose, &a.orbit) {
        (Some(p), _) => {
            let s = CarlaSample::load(p)?;
            pav_camou(s.cam_trans, s.veh_trans[1][1])
        }
        (None, Some(o)) => {
            let v: Vec<f32> = o
                .split(',')
                .map(|s| s.trim().parse())
                .collect::<Result<_, _>>()
                .with_context(|| format!("--orbit `{o}`: expected dist,elev,azim"))?;
            let [d, e, az] = v[..] else { bail!("--orbit `{o}`: expected three numbers dist,elev,azim") };
            Camera::look_at(spherical(d, e, az), [0.0; 3], [0.0, 1.0, 0.0], 60.0)
        }
        (None, None) => Camera::look_at(spherical(2.2, 20.0, 45.0), [0.0; 3], [0.0, 1.0, 0.0], 60.0),
    })
}

pub fn run(a: &Args) -> Result<()> {
    let mut m = Mesh::load_obj(&a.mesh)?;
    m.normalize();
    let tex_path = match &a.texture {
        Some(t) => t.clone(),
        None => m
            .materials
            .iter()
            .find_map(|x| x.map_kd.clone())
            .context("the mesh names no map_Kd texture: pass --texture")?,
    };
    let tex = Rgb::load(&tex_path)?;
    let r = textured(&m, &tex, &camera(a)?, a.size);
    if let Some(d) = a.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
    }
    save_rgb(&a.out, a.size, a.size, &r.rgb)?;
    let mask_path =
        a.out.with_file_name(format!("{}_mask.png", a.out.file_stem().unwrap_or_default().to_string_lossy()));
    let mask_rgb: Vec<f32> = r.mask.iter().flat_map(|v| [*v; 3]).collect();
    save_rgb(&mask_path, a.size, a.size, &mask_rgb)?;
    eprintln!(
        "car covers {:.1} % of the image; wrote {} and {}",
        100.0 * r.coverage,
        a.out.display(),
        mask_path.display()
    );
    Ok(())
}
