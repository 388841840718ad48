//! Frame sources for capture: a V4L2 camera, a video file, GStreamer's live test source, and a
//! simulated camera that films the simulated turntable.

use super::clock::{Clock, SystemClock};
use super::controls::{CameraControls, Control, SimControls};
use super::sim::Truth;
use super::v4l2::V4l2Controls;
use opencv::core::{Mat, Point, Scalar};
use opencv::prelude::*;
use opencv::{imgproc, videoio};
use pav_core::image::Frame;
use pav_core::video::{frame_to_mat, mat_to_frame, MatError, VideoError, VideoReader};
use pav_scene::turntable::CarScene;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Errors from a frame source.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    /// No such device.
    #[error("no V4L2 camera at {0}: this machine has no such video device (see `ls /dev/video*`); use --camera file:VIDEO, gst-test or sim")]
    NoDevice(PathBuf),
    /// A `--camera` value that names no source.
    #[error("{0}")]
    Spec(String),
    /// The source exists but could not be opened.
    #[error("cannot open {source_name}: {source}")]
    Open {
        /// Source description.
        source_name: String,
        /// Why.
        source: SourceFault,
    },
    /// Reading a frame failed.
    #[error("{source_name}: frame {frame}: {source}")]
    Read {
        /// Source description.
        source_name: String,
        /// Frame index that failed.
        frame: usize,
        /// Why.
        source: SourceFault,
    },
}

/// What went wrong inside a frame source.
#[derive(Debug, thiserror::Error)]
pub enum SourceFault {
    /// OpenCV failed.
    #[error(transparent)]
    OpenCv(#[from] opencv::Error),
    /// A frame could not be converted.
    #[error(transparent)]
    Frame(#[from] MatError),
    /// The video file failed.
    #[error(transparent)]
    Video(#[from] VideoError),
    /// The stream ended or never started.
    #[error("{0}")]
    Stream(&'static str),
}

/// Opens the frame source that a `--camera` value names: `v4l2:/dev/videoN`, `file:VIDEO`,
/// `gst-test`, or `sim` (needs `sim`, the simulated table to film, and films `car` on it when
/// given), asking for `width × height`
/// at `fps` where the source takes requests.
pub fn open_source(
    spec: &str,
    sim: Option<Truth>,
    car: Option<CarScene>,
    (width, height): (usize, usize),
    fps: f64,
) -> Result<Box<dyn FrameSource>, CameraError> {
    if car.is_some() && spec != "sim" {
        return Err(CameraError::Spec("a simulated car is filmed by --camera sim only".into()));
    }
    Ok(match spec {
        "sim" => match sim {
            Some(truth) => {
                let cam = SimCamera::new(truth, width, height, fps);
                Box::new(match car {
                    Some(c) => cam.with_car(c),
                    None => cam,
                })
            }
            None => {
                return Err(CameraError::Spec(
                    "--camera sim films the simulated turntable: use it with --port sim".into(),
                ))
            }
        },
        "gst-test" => Box::new(LiveCapture::gst_test(width, height, fps.round() as u32)?),
        c if c.starts_with("v4l2:") => Box::new(LiveCapture::v4l2(Path::new(&c[5..]), width, height, fps)?),
        c if c.starts_with("file:") => Box::new(FileSource::open(Path::new(&c[5..]))?),
        c => {
            return Err(CameraError::Spec(format!(
                "unknown --camera `{c}`: use v4l2:/dev/videoN, file:VIDEO, gst-test or sim"
            )))
        }
    })
}

/// A stream of frames, each stamped with the host instant it was captured.
pub trait FrameSource {
    /// What it is, for messages.
    fn describe(&self) -> String;
    /// Frame size (width, height).
    fn size(&self) -> (usize, usize);
    /// Nominal frames per second.
    fn fps(&self) -> f64;
    /// Next frame and its capture instant; `None` when the source ends.
    fn grab(&mut self) -> Result<Option<(Frame, Instant)>, CameraError>;
    /// Its exposure, gain, white balance and focus, for a source that has them (a V4L2 camera,
    /// the simulated camera).
    fn controls(&mut self) -> Option<&mut dyn CameraControls> {
        None
    }
}

/// Waits on `clock` until `due`, then moves it one frame period on (never bursting to catch up).
fn pace(clock: &dyn Clock, due: &mut Instant, period: Duration) -> Instant {
    clock.sleep_until(*due);
    let at = clock.now();
    *due = (*due + period).max(at);
    at
}

/// A live OpenCV capture (V4L2 device or GStreamer pipeline).
pub struct LiveCapture {
    cap: videoio::VideoCapture,
    name: String,
    size: (usize, usize),
    fps: f64,
    mat: Mat,
    index: usize,
    /// Frames placed by their source timestamps; `None`: by the read instant.
    stamps: Option<SourceClock>,
    /// A V4L2 camera's controls (opened when asked for).
    controls: Option<V4l2Controls>,
    device: Option<PathBuf>,
}

impl LiveCapture {
    /// Opens a V4L2 device such as `/dev/video0`, asking for `width × height` at `fps`.
    pub fn v4l2(device: &Path, width: usize, height: usize, fps: f64) -> Result<Self, CameraError> {
        if !device.exists() {
            return Err(CameraError::NoDevice(device.into()));
        }
        let name = format!("V4L2 camera {}", device.display());
        let mut cap = videoio::VideoCapture::from_file(device.as_os_str(), videoio::CAP_V4L2)
            .map_err(|e| CameraError::Open { source_name: name.clone(), source: e.into() })?;
        for (prop, v) in [
            (videoio::CAP_PROP_FRAME_WIDTH, width as f64),
            (videoio::CAP_PROP_FRAME_HEIGHT, height as f64),
            (videoio::CAP_PROP_FPS, fps),
        ] {
            let _ = cap.set(prop, v);
        }
        let mut c = Self::wrap(cap, name)?;
        c.stamps = Some(SourceClock::default());
        c.device = Some(device.into());
        Ok(c)
    }

    /// GStreamer's `videotestsrc` as a live camera (moving test pattern), for rigs without a camera.
    pub fn gst_test(width: usize, height: usize, fps: u32) -> Result<Self, CameraError> {
        let pipeline = format!(
            "videotestsrc is-live=true pattern=ball ! video/x-raw,width={width},height={height},framerate={fps}/1 ! videoconvert ! video/x-raw,format=BGR ! appsink drop=false max-buffers=4"
        );
        let name = "GStreamer videotestsrc".to_string();
        let cap = videoio::VideoCapture::from_file(&pipeline, videoio::CAP_GSTREAMER)
            .map_err(|e| CameraError::Open { source_name: name.clone(), source: e.into() })?;
        Self::wrap(cap, name)
    }

    fn wrap(cap: videoio::VideoCapture, name: String) -> Result<Self, CameraError> {
        if !cap.is_opened().unwrap_or(false) {
            return Err(CameraError::Open {
                source_name: name,
                source: SourceFault::Stream("OpenCV could not start the stream"),
            });
        }
        let g = |p| cap.get(p).unwrap_or(0.0);
        let size = (g(videoio::CAP_PROP_FRAME_WIDTH) as usize, g(videoio::CAP_PROP_FRAME_HEIGHT) as usize);
        let fps = Some(g(videoio::CAP_PROP_FPS)).filter(|f| f.is_finite() && *f > 0.0).unwrap_or(30.0);
        Ok(LiveCapture {
            cap,
            name,
            size,
            fps,
            mat: Mat::default(),
            index: 0,
            stamps: None,
            controls: None,
            device: None,
        })
    }
}

/// Places frames on the host clock by the source's own timestamps (a V4L2 buffer's capture
/// time, which OpenCV reports as `CAP_PROP_POS_MSEC`) rather than by when they were read, which
/// a busy host or the driver's queue delays. OpenCV's GStreamer backend answers the same
/// property with a position query made at read time (measured: it follows the reads), so
/// GStreamer sources keep the read instant. The source clock is anchored to the host by the
/// frame read soonest after its timestamp (reading only ever comes later); without usable
/// timestamps, the read instant stands.
#[derive(Default)]
struct SourceClock {
    /// Smallest (read instant − source seconds) so far: the host instant of source time 0.
    origin: Option<Instant>,
    last_ts: Option<f64>,
}

impl SourceClock {
    /// The capture instant of a frame read at `read` with source timestamp `ts_s` seconds.
    fn stamp(&mut self, read: Instant, ts_s: f64) -> Instant {
        let usable = ts_s.is_finite() && ts_s > 0.0 && self.last_ts.is_none_or(|l| ts_s > l);
        if !usable {
            return read;
        }
        self.last_ts = Some(ts_s);
        let Some(back) = read.checked_sub(Duration::from_secs_f64(ts_s)) else { return read };
        let origin = self.origin.map_or(back, |o| o.min(back));
        self.origin = Some(origin);
        origin + Duration::from_secs_f64(ts_s)
    }
}

impl FrameSource for LiveCapture {
    fn describe(&self) -> String {
        self.name.clone()
    }
    fn size(&self) -> (usize, usize) {
        self.size
    }
    fn fps(&self) -> f64 {
        self.fps
    }
    fn grab(&mut self) -> Result<Option<(Frame, Instant)>, CameraError> {
        let err = |source: SourceFault| CameraError::Read { source_name: self.name.clone(), frame: self.index, source };
        let ok = self.cap.read(&mut self.mat).map_err(|e| err(e.into()))?;
        let read = Instant::now();
        if !ok || self.mat.empty() {
            return Err(err(SourceFault::Stream("the camera stopped delivering frames")));
        }
        let at = match self.stamps.as_mut() {
            Some(clock) => clock.stamp(read, self.cap.get(videoio::CAP_PROP_POS_MSEC).unwrap_or(f64::NAN) / 1000.0),
            None => read,
        };
        let f = mat_to_frame(&self.mat).map_err(|e| err(e.into()))?;
        self.index += 1;
        Ok(Some((f, at)))
    }
    fn controls(&mut self) -> Option<&mut dyn CameraControls> {
        // Opened on first use: a GStreamer source has none, and a camera whose controls cannot
        // be opened still captures (the lock then fails, naming the device).
        if self.controls.is_none() {
            self.controls = V4l2Controls::open(self.device.as_ref()?).ok();
        }
        self.controls.as_mut().map(|c| c as &mut dyn CameraControls)
    }
}

/// Replays a video file as if it were a live camera, at its own frame rate.
pub struct FileSource {
    reader: VideoReader,
    path: PathBuf,
    due: Instant,
    period: Duration,
}

impl FileSource {
    /// Opens `path`.
    pub fn open(path: &Path) -> Result<Self, CameraError> {
        let reader = VideoReader::open(path)
            .map_err(|e| CameraError::Open { source_name: path.display().to_string(), source: e.into() })?;
        let period = Duration::from_secs_f64(1.0 / reader.info().fps);
        Ok(FileSource { reader, path: path.into(), due: Instant::now(), period })
    }
}

impl FrameSource for FileSource {
    fn describe(&self) -> String {
        format!("video file {}", self.path.display())
    }
    fn size(&self) -> (usize, usize) {
        (self.reader.info().width, self.reader.info().height)
    }
    fn fps(&self) -> f64 {
        self.reader.info().fps
    }
    fn grab(&mut self) -> Result<Option<(Frame, Instant)>, CameraError> {
        let at = pace(&SystemClock, &mut self.due, self.period);
        match self.reader.read() {
            Ok(Some((_, f))) => Ok(Some((f, at))),
            Ok(None) => Ok(None),
            Err(e) => Err(CameraError::Read { source_name: self.describe(), frame: 0, source: e.into() }),
        }
    }
}

/// A camera filming the simulated turntable: a disc with a marker at the true angle, or, given a
/// [`CarScene`], the textured car turned by it. It runs on the table's clock.
pub struct SimCamera {
    truth: Truth,
    car: Option<CarScene>,
    size: (usize, usize),
    fps: f64,
    due: Instant,
    index: usize,
    /// True angle (degrees) at each frame's capture instant, for tests.
    pub true_angles: Vec<f64>,
    /// Fail with a read error at this frame (fault injection).
    pub fail_at: Option<usize>,
    /// Its exposure, gain, white balance and focus.
    pub controls: SimControls,
}

impl SimCamera {
    /// A `width × height` camera at `fps` watching the simulator's table.
    pub fn new(truth: Truth, width: usize, height: usize, fps: f64) -> Self {
        SimCamera {
            truth: truth.clone(),
            car: None,
            size: (width, height),
            fps,
            due: truth.clock().now(),
            index: 0,
            true_angles: Vec::new(),
            fail_at: None,
            controls: SimControls::default(),
        }
    }

    /// Films `car` on the table instead of the disc.
    pub fn with_car(mut self, car: CarScene) -> Self {
        self.car = Some(car);
        self
    }

    fn render(&self, angle: f64) -> opencv::Result<Mat> {
        let (w, h) = self.size;
        let mut m = frame_to_mat(&Frame { width: w, height: h, bgr: vec![40; w * h * 3] })?;
        let c = Point::new(w as i32 / 2, h as i32 / 2);
        let r = (w.min(h) as f64 * 0.4) as i32;
        imgproc::circle(&mut m, c, r, Scalar::new(90.0, 90.0, 90.0, 0.0), -1, imgproc::LINE_AA, 0)?;
        let t = angle.to_radians();
        let tip = Point::new(c.x + (r as f64 * t.sin()) as i32, c.y - (r as f64 * t.cos()) as i32);
        imgproc::line(&mut m, c, tip, Scalar::new(0.0, 200.0, 255.0, 0.0), 4, imgproc::LINE_AA, 0)?;
        let label = format!("frame {} angle {angle:.2}", self.index);
        imgproc::put_text(
            &mut m,
            &label,
            Point::new(10, 24),
            imgproc::FONT_HERSHEY_SIMPLEX,
            0.6,
            Scalar::all(255.0),
            1,
            imgproc::LINE_AA,
            false,
        )?;
        Ok(m)
    }
}

impl FrameSource for SimCamera {
    fn describe(&self) -> String {
        match &self.car {
            Some(c) => format!(
                "simulated camera (pav's rasterizer, car at distance {}, elevation {}°)",
                c.distance, c.elevation_deg
            ),
            None => "simulated camera".into(),
        }
    }
    fn size(&self) -> (usize, usize) {
        self.size
    }
    fn fps(&self) -> f64 {
        self.fps
    }
    fn grab(&mut self) -> Result<Option<(Frame, Instant)>, CameraError> {
        if self.fail_at == Some(self.index) {
            return Err(CameraError::Read {
                source_name: self.describe(),
                frame: self.index,
                source: SourceFault::Stream("injected camera failure"),
            });
        }
        let at = pace(self.truth.clock().as_ref(), &mut self.due, Duration::from_secs_f64(1.0 / self.fps));
        let angle = self.truth.angle_at(at);
        let err = |source: SourceFault| CameraError::Read {
            source_name: "simulated camera".into(),
            frame: self.index,
            source,
        };
        let f = match &self.car {
            // A locked exposure does not follow the car.
            Some(car) => {
                car.frame_exposed(angle as f32, self.size.0, self.size.1, !self.controls.is_locked(Control::Exposure))
            }
            None => {
                let m = self.render(angle).map_err(|e| err(e.into()))?;
                mat_to_frame(&m).map_err(|e| err(e.into()))?
            }
        };
        self.true_angles.push(angle);
        self.index += 1;
        Ok(Some((f, at)))
    }
    fn controls(&mut self) -> Option<&mut dyn CameraControls> {
        Some(&mut self.controls)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn source_timestamps_survive_a_burst_of_late_reads() {
        // Frames taken every 33.3 ms; the reader falls 120 ms behind after frame 3 and then
        // reads the queued frames back to back. Source time starts at 5 s (a kernel clock).
        let t0 = Instant::now();
        let mut clock = SourceClock::default();
        let mut read = t0;
        let mut stamps = Vec::new();
        for k in 0..12u32 {
            let taken = 5.0 + k as f64 / 30.0;
            read = read.max(t0 + Duration::from_secs_f64(k as f64 / 30.0 + 0.004)); // 4 ms to read
            if k == 4 {
                read += Duration::from_millis(120);
            }
            stamps.push(clock.stamp(read, taken));
            read += Duration::from_millis(1);
        }
        for (k, w) in stamps.windows(2).enumerate() {
            let gap = (w[1] - w[0]).as_secs_f64() * 1000.0;
            assert!((gap - 1000.0 / 30.0).abs() < 0.01, "frames {k}-{}: {gap} ms", k + 1);
        }
        // Anchored by the frames read soonest: 4 ms after they were taken.
        let lag = (stamps[0] - t0).as_secs_f64();
        assert!((lag - 0.004).abs() < 1e-6, "{lag}");
        // No usable timestamp (0, NaN, going back): the read instant stands.
        assert_eq!(clock.stamp(read, f64::NAN), read);
        assert_eq!(clock.stamp(read, 1.0), read);
    }
}
