//! `pav-rig camera`.

use anyhow::{Context, Result};
use pav::rig::controls::{CameraControls, SimControls};
use pav::rig::v4l2::V4l2Controls;
use std::path::Path;

#[derive(clap::Subcommand)]
pub enum Cmd {
    /// A camera's exposure, gain, white balance and focus controls (ranges, values, automatic
    /// modes) and its formats: what `pav-rig capture --exposure …` can lock.
    #[command(after_help = "Examples:
  pav-rig camera list /dev/video0
  pav-rig camera list sim")]
    List {
        /// `/dev/videoN` (or `v4l2:/dev/videoN`), or `sim` for the simulated camera.
        device: String,
    },
}

pub fn run(c: &Cmd) -> Result<()> {
    let Cmd::List { device } = c;
    let cam: Box<dyn CameraControls> = match device.as_str() {
        "sim" => Box::new(SimControls::default()),
        d => {
            let path = Path::new(d.strip_prefix("v4l2:").unwrap_or(d));
            if !path.exists() {
                anyhow::bail!(
                    "no video device at {}: this machine has no such camera (see `ls /dev/video*`), or use `sim`",
                    path.display()
                );
            }
            Box::new(V4l2Controls::open(path)?)
        }
    };
    let offers = cam.offers().context("listing the controls")?;
    outln!("{}", cam.camera());
    outln!("controls:");
    if offers.is_empty() {
        outln!("  none of exposure, gain, white balance, focus");
    }
    for o in &offers {
        outln!("  {o}");
    }
    outln!("formats:");
    for f in cam.formats().context("listing the formats")? {
        outln!("  {f}");
    }
    Ok(())
}
