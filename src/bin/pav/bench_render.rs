//! `pav bench-render`.

use crate::common::Bar;
use anyhow::{Context, Result};
use pav::geometry::mesh::Mesh;
use pav::render::bench::time_stages;
use pav::table::write_csv;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// OBJ mesh with UVs.
    #[arg(long, value_parser = pav::data::arg_path, default_value = "data:pav-camou/xfl_yxz.obj")]
    mesh: PathBuf,
    /// Image sizes.
    #[arg(long, value_delimiter = ',', default_value = "416,800")]
    sizes: Vec<usize>,
    /// Views (orbit azimuths) per size.
    #[arg(long, default_value_t = 8)]
    views: usize,
    /// Output CSV.
    #[arg(long, short = 'o', default_value = "out/bench/render.csv")]
    out: PathBuf,
}

pub fn run(a: &Args) -> Result<()> {
    let mut m = Mesh::load_obj(&a.mesh)?;
    m.normalize();
    let rows = time_stages(&m, &a.sizes, a.views, &Bar::default());
    if let Some(d) = a.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
    }
    write_csv(&a.out, &rows)?;
    eprintln!("wrote {}", a.out.display());
    Ok(())
}
