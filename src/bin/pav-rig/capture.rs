//! `pav-rig capture`.

use crate::common::{ctrl_c_flag, Bar};
use crate::port::{connect, parse_signed_seconds, PortArgs};
use anyhow::{bail, Context, Result};
use pav::rig::capture::{capture, CaptureOptions};
use pav::rig::source::open_source;
use pav::scene::turntable::CarScene;
use pav::scene::views::ViewsConfig;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    port: PortArgs,
    /// Frame source: `v4l2:/dev/video0`, `file:VIDEO`, `gst-test` or `sim` (needs --port sim).
    #[arg(long, default_value = "v4l2:/dev/video0")]
    camera: String,
    /// Output video; the sidecar goes beside it as NAME.angles.csv.
    #[arg(long, short = 'o')]
    out: PathBuf,
    /// Seconds per revolution.
    #[arg(long, default_value = "28s", value_parser = parse_signed_seconds, allow_hyphen_values = true)]
    period: f64,
    /// Revolutions to record.
    #[arg(long, default_value_t = 1)]
    turns: u32,
    /// Do not home before recording.
    #[arg(long)]
    no_home: bool,
    /// Requested camera width.
    #[arg(long, default_value_t = 1280)]
    width: usize,
    /// Requested camera height.
    #[arg(long, default_value_t = 720)]
    height: usize,
    /// Requested camera frame rate.
    #[arg(long, default_value_t = 30.0)]
    fps: f64,
    /// Video codec FourCC (avc1 = H.264, mp4v = MPEG-4 part 2).
    #[arg(long, default_value = "avc1")]
    codec: String,
    /// Fail (keeping the files) when the angles cannot be bounded to within this many degrees.
    #[arg(long, default_value_t = 0.5)]
    max_angle_error: f64,
    /// With `--camera sim`: film the car of this views config (e.g. configs/views/turntable.toml)
    /// on the simulated table, drawn live by pav's rasterizer, instead of a marked disc.
    #[arg(long, value_parser = pav::data::arg_path)]
    car: Option<PathBuf>,
    /// With --car: its paint (e.g. an optimized texture.png) instead of the config's.
    #[arg(long, requires = "car", value_parser = pav::data::arg_path)]
    texture: Option<PathBuf>,
    /// With --car: the camera's elevation (the paper's polar angle, 0 or 20) instead of the config's first.
    #[arg(long, requires = "car", allow_hyphen_values = true)]
    elevation: Option<f32>,
}

pub fn run(a: &Args) -> Result<()> {
    let codec: Vec<char> = a.codec.chars().collect();
    let [c0, c1, c2, c3] = codec[..] else {
        bail!("--codec must be a 4-character FourCC like avc1, got `{}`", a.codec)
    };
    if !(a.max_angle_error.is_finite() && a.max_angle_error > 0.0) {
        bail!("--max-angle-error must be a positive number of degrees, not {}", a.max_angle_error);
    }
    if a.camera == "sim" && a.port.port != "sim" {
        bail!("--camera sim films the simulated turntable: use it with --port sim");
    }
    let car = match &a.car {
        Some(cfg) => {
            let views = ViewsConfig::load(cfg)?;
            Some(CarScene::new(&views, a.texture.as_deref(), a.elevation)?)
        }
        None => None,
    };
    let (sim, mut table) = connect(&a.port)?;
    let mut cam = open_source(&a.camera, sim.as_ref().map(|s| s.truth()), car, (a.width, a.height), a.fps)?;
    let (w, h) = cam.size();
    eprintln!("camera: {} {w}x{h} at {:.1} fps", cam.describe(), cam.fps());
    let opts = CaptureOptions {
        period_s: a.period,
        turns: a.turns,
        home: !a.no_home,
        fourcc: [c0, c1, c2, c3],
        max_angle_error_deg: a.max_angle_error,
        ..CaptureOptions::new(&a.out)
    };
    let mut record = pav::provenance::Run::start()
        .setting("port", &a.port.port)
        .setting("camera", cam.describe())
        .setting("size", format!("{w}x{h}"))
        .setting("fps", cam.fps())
        .setting("period_s", a.period)
        .setting("turns", a.turns)
        .setting("max_angle_error_deg", a.max_angle_error)
        .tool("ffmpeg", pav::video::ffmpeg_version());
    let record_path = a.out.with_extension("run.toml");
    let write =
        |r: &pav::provenance::Run| r.write(&record_path).with_context(|| format!("writing {}", record_path.display()));
    write(&record)?;
    let stop = ctrl_c_flag()?;
    let result = capture(&mut table, cam.as_mut(), &opts, &Bar::default(), &stop);
    match &result {
        Ok(sum) => {
            record.result("frames", sum.frames);
            record.result("angle_bound_deg", sum.angle_bound_deg.map_or("none".into(), |b| format!("{b:.4}")));
            record.result("round_trip_ms", sum.round_trip_ms.map_or("none".into(), |r| format!("{r:.3}")));
            record.result("reports_discarded", sum.reports_discarded);
        }
        Err(e) => record.result("error", e),
    }
    write(&record)?;
    let sum = result?;
    println!(
        "recorded {} frames ({} with angles between reports), table ended at {:.3}°",
        sum.frames,
        sum.interpolated,
        sum.final_deg.unwrap_or(f64::NAN)
    );
    if let (Some(b), Some(rtt)) = (sum.angle_bound_deg, sum.round_trip_ms) {
        println!("every angle within ±{b:.3}° (fastest round trip to the table {rtt:.2} ms)");
    }
    if sum.reports_discarded > 0 {
        println!("{} angle report(s) refused: the commanded spin cannot have produced them", sum.reports_discarded);
    }
    if sum.done_lost {
        println!("the table's `done` was lost on the line; its end position came from a status report");
    }
    println!("video   {}\nsidecar {}", sum.video.display(), sum.sidecar.display());
    Ok(())
}
