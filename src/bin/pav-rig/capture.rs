//! `pav-rig capture`.

use crate::common::{ctrl_c_flag, Bar};
use crate::port::{connect, only_one, parse_signed_seconds, PortArgs, SimTime};
use anyhow::{bail, Context, Result};
use pav::rig::capture::{capture, CaptureOptions};
use pav::rig::controls::{lock_all, read_back, Control};
use pav::rig::source::open_source;
use pav::scene::rig::RigConfig;
use pav::scene::turntable::CarScene;
use pav::scene::views::ViewsConfig;
use std::collections::BTreeMap;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    port: PortArgs,
    /// Frame source: `v4l2:/dev/videoN`, `file:VIDEO`, `gst-test` or `sim` (needs --port sim; the
    /// capture then runs in simulated time, the same video on a busy machine as on an idle one)
    /// [default: the one V4L2 camera there is; with several, pav lists them and asks].
    #[arg(long)]
    camera: Option<String>,
    /// Output video; the sidecar goes beside it as NAME.angles.csv.
    #[arg(long, short = 'o')]
    out: PathBuf,
    /// Seconds per revolution [default: the rig's table, else 28 s].
    #[arg(long, value_parser = parse_signed_seconds, allow_hyphen_values = true)]
    period: Option<f64>,
    /// Revolutions to record.
    #[arg(long, default_value_t = 1)]
    turns: u32,
    /// Do not home before recording.
    #[arg(long)]
    no_home: bool,
    /// Requested camera width [default: the rig's, else 1280].
    #[arg(long)]
    width: Option<usize>,
    /// Requested camera height [default: the rig's, else 720].
    #[arg(long)]
    height: Option<usize>,
    /// Requested camera frame rate [default: the rig's, else 30].
    #[arg(long)]
    fps: Option<f64>,
    /// The rig this capture films (configs/rig/*.toml): recorded in run.toml, so the capture and
    /// its simulation (`pav views turntable --rig`) name the same shot; it sets the frame size,
    /// frame rate and period not given. With `--camera sim`, the simulated camera films the
    /// rig's model.
    #[arg(long, conflicts_with = "car", value_parser = pav::data::arg_path)]
    rig: Option<PathBuf>,
    /// With --rig: the camera position, 1-based, of the rig's heights or elevations.
    #[arg(long, requires = "rig", default_value_t = 1)]
    placement: usize,
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
    /// With --car or --rig and --camera sim: the model's paint (e.g. an optimized texture.png)
    /// instead of the config's.
    #[arg(long, value_parser = pav::data::arg_path)]
    texture: Option<PathBuf>,
    /// With --car: the camera's elevation (the paper's polar angle, 0 or 20) instead of the config's first.
    #[arg(long, requires = "car", allow_hyphen_values = true)]
    elevation: Option<f32>,
    /// Lock the exposure time at this value (× 100 µs, V4L2's unit), automatic exposure off,
    /// before the table turns [default: the rig's `[camera.controls]`]. `pav-rig camera list`
    /// shows the camera's ranges.
    #[arg(long)]
    exposure: Option<i64>,
    /// Lock the gain (the camera's units), automatic gain off.
    #[arg(long)]
    gain: Option<i64>,
    /// Lock the white balance (kelvin), automatic white balance off.
    #[arg(long)]
    white_balance: Option<i64>,
    /// Lock the focus (the camera's units), autofocus off.
    #[arg(long)]
    focus: Option<i64>,
    /// Record a control the camera lacks or refuses as left automatic (a warning in run.toml)
    /// instead of failing.
    #[arg(long)]
    allow_auto: bool,
}

/// The controls to lock: the flags, else the rig's `[camera.controls]`.
fn wanted(a: &Args, rig: Option<&RigConfig>) -> BTreeMap<Control, i64> {
    let from_rig = rig.map(|r| r.camera.controls.clone()).unwrap_or_default();
    [
        (Control::Exposure, a.exposure.or(from_rig.exposure)),
        (Control::Gain, a.gain.or(from_rig.gain)),
        (Control::WhiteBalance, a.white_balance.or(from_rig.white_balance)),
        (Control::Focus, a.focus.or(from_rig.focus)),
    ]
    .into_iter()
    .filter_map(|(c, v)| v.map(|v| (c, v)))
    .collect()
}

pub fn run(a: &Args) -> Result<()> {
    let codec: Vec<char> = a.codec.chars().collect();
    let [c0, c1, c2, c3] = codec[..] else {
        bail!("--codec must be a 4-character FourCC like avc1, got `{}`", a.codec)
    };
    if !(a.max_angle_error.is_finite() && a.max_angle_error > 0.0) {
        bail!("--max-angle-error must be a positive number of degrees, not {}", a.max_angle_error);
    }
    let camera = match &a.camera {
        Some(c) => c.clone(),
        None => format!(
            "v4l2:{}",
            only_one(
                "V4L2 camera",
                "--camera",
                pav::rig::v4l2::capture_devices(),
                "--camera file:VIDEO, gst-test or sim"
            )?
        ),
    };
    if camera == "sim" && !a.port.is_sim() {
        bail!("--camera sim films the simulated turntable: use it with --port sim");
    }
    let rig = a.rig.as_deref().map(RigConfig::load).transpose()?;
    if a.texture.is_some() && a.car.is_none() && !(rig.is_some() && camera == "sim") {
        bail!("--texture paints the simulated model: use it with --car, or with --rig and --camera sim");
    }
    let car = match (&a.car, &rig) {
        (Some(cfg), _) => {
            let views = ViewsConfig::load(cfg)?;
            Some(CarScene::new(&views, a.texture.as_deref(), a.elevation)?)
        }
        (None, Some(rig)) if camera == "sim" => {
            if a.placement == 0 {
                bail!("--placement counts from 1");
            }
            Some(CarScene::from_rig(rig, a.texture.as_deref(), a.placement - 1)?)
        }
        _ => None,
    };
    let size = (
        a.width.or(rig.as_ref().map(|r| r.camera.width)).unwrap_or(1280),
        a.height.or(rig.as_ref().map(|r| r.camera.height)).unwrap_or(720),
    );
    let fps = a.fps.or(rig.as_ref().map(|r| r.camera.fps)).unwrap_or(30.0);
    let period = a.period.or(rig.as_ref().map(|r| r.table.period_s)).unwrap_or(28.0);
    // A simulated camera filming the simulated table needs no wall clock: in simulated time each
    // frame is taken at its instant however long it takes to draw, so a busy machine films the
    // same video as an idle one.
    let time = if camera == "sim" { SimTime::Simulated } else { SimTime::Real };
    let mut connected = connect(&a.port, time)?;
    let mut cam = open_source(&camera, connected.truth.clone(), car, size, fps)?;
    let (w, h) = cam.size();
    eprintln!("camera: {} {w}x{h} at {:.1} fps", cam.describe(), cam.fps());
    let opts = CaptureOptions {
        period_s: period,
        turns: a.turns,
        home: !a.no_home,
        fourcc: [c0, c1, c2, c3],
        max_angle_error_deg: a.max_angle_error,
        ..CaptureOptions::new(&a.out)
    };
    let mut record = pav::provenance::Run::start()
        .setting("port", &connected.port)
        .setting("camera", cam.describe())
        .setting("size", format!("{w}x{h}"))
        .setting("fps", cam.fps())
        .setting("period_s", period)
        .setting("turns", a.turns)
        .setting("max_angle_error_deg", a.max_angle_error)
        .tool("ffmpeg", pav::provenance::tool_version("ffmpeg", &["-version"]));
    if time == SimTime::Simulated {
        record = record.setting("time", "simulated");
    }
    if let (Some(path), Some(rig)) = (&a.rig, &rig) {
        record = record.config(path).inputs(rig.inputs().iter().map(|p| p.as_path()));
        if camera == "sim" {
            record = record.setting("placement", a.placement);
        }
    }
    // Exposure, gain, white balance and focus locked before the table turns, so that the image
    // does not follow the car; each read back after the turn.
    let want = wanted(a, rig.as_ref());
    let mut locked = Vec::new();
    if !want.is_empty() {
        let what = cam.describe();
        let controls = cam
            .controls()
            .with_context(|| format!("{what} has no controls pav can set: lock them on a V4L2 camera"))?;
        locked = lock_all(controls, &want, a.allow_auto)?;
        for l in &locked {
            match &l.warning {
                Some(w) => eprintln!("warning: {w}"),
                None => eprintln!("locked {} at {}", l.control.name(), l.set),
            }
            record = record.setting(&format!("{}_set", l.control.name()), l.set);
        }
    } else if cam.controls().is_some() {
        eprintln!("exposure, gain, white balance and focus left automatic: lock them with --exposure, --gain, --white-balance, --focus (see `pav-rig camera list`)");
        record = record.setting("controls", "automatic");
    }
    let record_path = a.out.with_extension("run.toml");
    let write =
        |r: &pav::provenance::Run| r.write(&record_path).with_context(|| format!("writing {}", record_path.display()));
    write(&record)?;
    let stop = ctrl_c_flag()?;
    let result = capture(&mut connected.table, cam.as_mut(), &opts, &Bar::default(), &stop);
    if let Some(controls) = cam.controls().filter(|_| !locked.is_empty()) {
        read_back(controls, &mut locked);
    }
    for (k, v) in locked.iter().flat_map(|l| l.entries()) {
        record.result(&k, v);
    }
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
    outln!(
        "recorded {} frames ({} with angles between reports), table ended at {:.3}°",
        sum.frames,
        sum.interpolated,
        sum.final_deg.unwrap_or(f64::NAN)
    );
    if let (Some(b), Some(rtt)) = (sum.angle_bound_deg, sum.round_trip_ms) {
        outln!("every angle within ±{b:.3}° (fastest round trip to the table {rtt:.2} ms)");
    }
    if sum.reports_discarded > 0 {
        outln!("{} angle report(s) refused: the commanded spin cannot have produced them", sum.reports_discarded);
    }
    if sum.done_lost {
        outln!("the table's `done` was lost on the line; its end position came from a status report");
    }
    outln!("video   {}\nsidecar {}", sum.video.display(), sum.sidecar.display());
    Ok(())
}
