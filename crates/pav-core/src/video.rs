//! Video files: decoding into BGR frames through OpenCV (with a prefetching decoder thread), and
//! encoding through an `ffmpeg` child process that outlives a crash; errors name the file and
//! keep the cause.

use crate::image::Frame;
use opencv::core::Mat;
use opencv::prelude::*;
use opencv::videoio::{self, VideoCapture};
use std::path::{Path, PathBuf};

/// Errors opening, decoding or encoding a video.
#[derive(Debug, thiserror::Error)]
pub enum VideoError {
    /// The file does not exist.
    #[error("video {0} does not exist")]
    Missing(PathBuf),
    /// OpenCV failed while opening the file.
    #[error("video {path} cannot be opened: {source}")]
    Open {
        /// Video path.
        path: PathBuf,
        /// OpenCV's error.
        source: opencv::Error,
    },
    /// An image file is missing or not one OpenCV reads.
    #[error("image {0} cannot be read (missing, or not a format OpenCV reads)")]
    Image(PathBuf),
    /// OpenCV opened nothing (corrupt, truncated before the index, or unsupported).
    #[error("video {path} cannot be opened: not a readable video (corrupt, truncated or unsupported format)")]
    Unreadable {
        /// Video path.
        path: PathBuf,
    },
    /// Decoding failed mid-stream.
    #[error("video {path}: decoding failed at frame {frame}: {source}")]
    Decode {
        /// Video path.
        path: PathBuf,
        /// Frame index that failed.
        frame: usize,
        /// Why.
        source: MatError,
    },
    /// The encoder could not be started for this file and codec.
    #[error("cannot write {path} with codec {codec}: {reason}")]
    Encoder {
        /// Video path.
        path: PathBuf,
        /// FourCC.
        codec: String,
        /// Why.
        reason: String,
    },
    /// Writing or closing the file failed.
    #[error("writing {path}: {reason}")]
    Write {
        /// Video path.
        path: PathBuf,
        /// Why, with the encoder's last words when it gave any.
        reason: String,
    },
}

/// Errors converting between OpenCV matrices and [`Frame`]s.
#[derive(Debug, thiserror::Error)]
pub enum MatError {
    /// OpenCV itself failed.
    #[error(transparent)]
    OpenCv(#[from] opencv::Error),
    /// A pixel type other than 8-bit BGR or grey.
    #[error("unsupported pixel type {0} (need 8-bit BGR)")]
    PixelType(i32),
}

/// Stream properties as the container declares them.
#[derive(Clone, Debug, PartialEq)]
pub struct VideoInfo {
    /// Frames per second (30 when the container does not say).
    pub fps: f64,
    /// Frame count the container declares (may be an estimate; 0 if unknown).
    pub declared_frames: usize,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
}

/// Sequential reader of BGR frames.
pub struct VideoReader {
    cap: VideoCapture,
    path: PathBuf,
    info: VideoInfo,
    next: usize,
    mat: Mat,
}

impl VideoReader {
    /// Opens `path`; fails on a missing file or one OpenCV cannot decode.
    pub fn open(path: &Path) -> Result<Self, VideoError> {
        if !path.exists() {
            return Err(VideoError::Missing(path.into()));
        }
        let cap = VideoCapture::from_file(path.as_os_str(), videoio::CAP_FFMPEG)
            .map_err(|source| VideoError::Open { path: path.into(), source })?;
        if !cap.is_opened().unwrap_or(false) {
            return Err(VideoError::Unreadable { path: path.into() });
        }
        let prop = |p| cap.get(p).unwrap_or(0.0);
        let fps = prop(videoio::CAP_PROP_FPS);
        let info = VideoInfo {
            fps: if fps.is_finite() && fps > 0.0 { fps } else { 30.0 },
            declared_frames: prop(videoio::CAP_PROP_FRAME_COUNT).max(0.0) as usize,
            width: prop(videoio::CAP_PROP_FRAME_WIDTH) as usize,
            height: prop(videoio::CAP_PROP_FRAME_HEIGHT) as usize,
        };
        Ok(VideoReader { cap, path: path.into(), info, next: 0, mat: Mat::default() })
    }

    /// The declared stream properties.
    pub fn info(&self) -> &VideoInfo {
        &self.info
    }

    /// Skips one frame without converting it; `false` at end of stream.
    pub fn skip(&mut self) -> Result<bool, VideoError> {
        let ok = self.cap.grab().map_err(|e| self.decode_err(e.into()))?;
        if ok {
            self.next += 1;
        }
        Ok(ok)
    }

    /// Decodes the next frame; `None` at end of stream.
    pub fn read(&mut self) -> Result<Option<(usize, Frame)>, VideoError> {
        if !self.cap.read(&mut self.mat).map_err(|e| self.decode_err(e.into()))? || self.mat.empty() {
            return Ok(None);
        }
        let idx = self.next;
        self.next += 1;
        let frame = mat_to_frame(&self.mat).map_err(|e| self.decode_err(e))?;
        Ok(Some((idx, frame)))
    }

    fn decode_err(&self, source: MatError) -> VideoError {
        VideoError::Decode { path: self.path.clone(), frame: self.next, source }
    }
}

/// OpenCV's version, which decodes every video (for `run.toml`).
pub fn opencv_version() -> Option<String> {
    opencv::core::get_version_string().ok()
}

/// Reads an image file (any format OpenCV reads: PNG, JPEG, TIFF, ...) as a [`Frame`].
pub fn read_image(path: &Path) -> Result<Frame, VideoError> {
    let m =
        opencv::imgcodecs::imread(path, opencv::imgcodecs::IMREAD_COLOR).map_err(|_| VideoError::Image(path.into()))?;
    if m.empty() {
        return Err(VideoError::Image(path.into()));
    }
    mat_to_frame(&m).map_err(|source| VideoError::Decode { path: path.into(), frame: 0, source })
}

/// Copies an 8-bit BGR (or grey) OpenCV matrix into a [`Frame`].
pub fn mat_to_frame(m: &Mat) -> Result<Frame, MatError> {
    let (w, h) = (m.cols() as usize, m.rows() as usize);
    let bgr = match m.typ() {
        t if t == opencv::core::CV_8UC3 => contiguous(m)?.to_vec(),
        t if t == opencv::core::CV_8UC1 => contiguous(m)?.iter().flat_map(|&g| [g, g, g]).collect(),
        t => return Err(MatError::PixelType(t)),
    };
    Ok(Frame { width: w, height: h, bgr })
}

fn contiguous(m: &Mat) -> opencv::Result<std::borrow::Cow<'_, [u8]>> {
    if m.is_continuous() {
        Ok(std::borrow::Cow::Borrowed(m.data_bytes()?))
    } else {
        let owned = m.try_clone()?;
        Ok(std::borrow::Cow::Owned(owned.data_bytes()?.to_vec()))
    }
}

/// Wraps a [`Frame`] as an OpenCV BGR matrix (copying).
pub fn frame_to_mat(f: &Frame) -> opencv::Result<Mat> {
    let flat = Mat::from_slice(&f.bgr)?;
    let m = flat.reshape(3, f.height as i32)?;
    m.try_clone()
}

/// Encodes frames into a video file as they come, through an `ffmpeg` child process fed raw
/// BGR frames on a pipe.
///
/// The child is what makes a recording survive its recorder: when pav dies, even by SIGKILL,
/// the pipe closes and ffmpeg finalizes the file with every frame it was given. The child runs
/// in its own process group, so a terminal's Ctrl-C reaches only pav, which then closes the file
/// itself. MP4 and MOV files are written fragmented with a key frame every second, so even a
/// killed ffmpeg leaves a file playable up to its last whole second.
pub struct VideoWriter {
    child: std::process::Child,
    /// Frames on their way to ffmpeg: a feeder thread writes them to its pipe, so a slow encoder
    /// (a loaded host) holds up this queue, not the caller's camera loop.
    frames: Option<std::sync::mpsc::SyncSender<Vec<u8>>>,
    feeder: Option<std::thread::JoinHandle<Result<(), String>>>,
    stderr: Option<std::thread::JoinHandle<String>>,
    path: PathBuf,
    size: (usize, usize),
}

/// ffmpeg encoder arguments for a FourCC.
fn encoder_args(fourcc: &str) -> Option<&'static [&'static str]> {
    Some(match fourcc {
        "avc1" | "h264" | "H264" | "x264" | "X264" => {
            &["-c:v", "libx264", "-preset", "veryfast", "-crf", "18", "-pix_fmt", "yuv420p"]
        }
        "mp4v" | "MP4V" | "FMP4" | "XVID" | "DIVX" => &["-c:v", "mpeg4", "-q:v", "3"],
        "MJPG" | "mjpg" => &["-c:v", "mjpeg", "-q:v", "3"],
        _ => return None,
    })
}

impl VideoWriter {
    /// Creates `path` for `width × height` frames at `fps` with codec `fourcc` (`avc1` = H.264,
    /// `mp4v` = MPEG-4 part 2, `MJPG`).
    pub fn create(path: &Path, fourcc: [char; 4], fps: f64, size: (usize, usize)) -> Result<Self, VideoError> {
        let codec: String = fourcc.iter().collect();
        let enc = encoder_args(&codec).ok_or_else(|| VideoError::Encoder {
            path: path.into(),
            codec: codec.clone(),
            reason: "unknown codec: use avc1 (H.264), mp4v (MPEG-4 part 2) or MJPG".into(),
        })?;
        Self::spawn(path, &codec, &enc.iter().map(|s| s.to_string()).collect::<Vec<_>>(), fps, size)
    }

    /// Creates `path` as H.264 at a constant `kbps` (a phone's or webcam's recording: the
    /// codec's losses at the capture's bitrate), not the near-lossless quality of [`Self::create`].
    pub fn create_at_bitrate(path: &Path, fps: f64, size: (usize, usize), kbps: f64) -> Result<Self, VideoError> {
        if !(kbps.is_finite() && kbps > 0.0) {
            return Err(VideoError::Encoder {
                path: path.into(),
                codec: "avc1".into(),
                reason: format!("a bitrate of {kbps} kbit/s is no bitrate"),
            });
        }
        let k = format!("{}k", kbps.round().max(1.0));
        let buf = format!("{}k", (2.0 * kbps).round().max(1.0));
        let enc: Vec<String> = ["-c:v", "libx264", "-preset", "veryfast", "-b:v", &k, "-maxrate", &k, "-bufsize", &buf]
            .into_iter()
            .chain(["-pix_fmt", "yuv420p"])
            .map(String::from)
            .collect();
        Self::spawn(path, "avc1", &enc, fps, size)
    }

    fn spawn(
        path: &Path,
        codec: &str,
        enc: &[String],
        fps: f64,
        (width, height): (usize, usize),
    ) -> Result<Self, VideoError> {
        use std::os::unix::process::CommandExt;
        use std::process::{Command, Stdio};
        let refuse = |reason: String| VideoError::Encoder { path: path.into(), codec: codec.into(), reason };
        if !(fps.is_finite() && fps > 0.0) || width == 0 || height == 0 {
            return Err(refuse(format!("{width}x{height} at {fps} fps is no video")));
        }
        let gop = (fps.round() as usize).max(1).to_string();
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
        let mut cmd = Command::new("ffmpeg");
        cmd.args(["-hide_banner", "-loglevel", "error", "-nostats", "-y", "-f", "rawvideo", "-pix_fmt", "bgr24"])
            .args(["-s", &format!("{width}x{height}"), "-r", &fps.to_string(), "-i", "pipe:0"])
            .args(enc)
            .args(["-g", &gop]);
        if matches!(ext.as_str(), "mp4" | "mov" | "m4v") {
            cmd.args(["-movflags", "+frag_keyframe+empty_moov+default_base_moof"]);
        }
        // Descriptors pav opened without close-on-exec (a serial port, a pseudo-terminal) would
        // otherwise live on in ffmpeg: a port that cannot hang up, a device held after pav exits.
        // SAFETY: the closure runs between fork and exec and only calls fcntl and syscall,
        // which are async-signal-safe; it allocates nothing.
        unsafe {
            cmd.pre_exec(|| {
                const CLOSE_RANGE_CLOEXEC: libc::c_uint = 1 << 2;
                if libc::syscall(libc::SYS_close_range, 3 as libc::c_uint, libc::c_uint::MAX, CLOSE_RANGE_CLOEXEC) != 0
                {
                    for fd in 3..4096 {
                        libc::fcntl(fd, libc::F_SETFD, libc::FD_CLOEXEC);
                    }
                }
                Ok(())
            });
        }
        let mut child = cmd
            .arg(path)
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .process_group(0)
            .spawn()
            .map_err(|e| refuse(format!("cannot run ffmpeg ({e}); scripts/setup.sh installs it")))?;
        let mut stdin = child.stdin.take().expect("stdin was piped");
        // Two seconds of frames may wait for the encoder before the caller does.
        let (tx, rx) = std::sync::mpsc::sync_channel::<Vec<u8>>((fps.round() as usize * 2).max(4));
        let feeder = std::thread::spawn(move || {
            for frame in rx {
                std::io::Write::write_all(&mut stdin, &frame).map_err(|e| e.to_string())?;
            }
            Ok(())
        });
        let mut err = child.stderr.take().expect("stderr was piped");
        let stderr = std::thread::spawn(move || {
            let mut s = String::new();
            let _ = std::io::Read::read_to_string(&mut err, &mut s);
            s
        });
        Ok(VideoWriter {
            child,
            frames: Some(tx),
            feeder: Some(feeder),
            stderr: Some(stderr),
            path: path.into(),
            size: (width, height),
        })
    }

    /// Hands ffmpeg the frames still queued, ends its input and waits for it; its error output
    /// when it failed.
    fn close(&mut self) -> Result<(), String> {
        drop(self.frames.take());
        let fed = self.feeder.take().map_or(Ok(()), |h| h.join().unwrap_or_else(|_| Err("feeder panicked".into())));
        let status = self.child.wait().map_err(|e| format!("waiting for ffmpeg: {e}"))?;
        let said = self.stderr.take().and_then(|h| h.join().ok()).unwrap_or_default();
        match (status.success(), fed) {
            (true, Ok(())) => Ok(()),
            (_, Err(e)) => Err(format!("feeding ffmpeg: {e}; ffmpeg {status}: {}", said.trim())),
            (false, Ok(())) => Err(format!("ffmpeg {status}: {}", said.trim())),
        }
    }

    /// Appends one frame.
    pub fn write(&mut self, f: &Frame) -> Result<(), VideoError> {
        let fail = |reason: String| VideoError::Write { path: self.path.clone(), reason };
        if (f.width, f.height) != self.size {
            return Err(fail(format!("a {}x{} frame in a {}x{} video", f.width, f.height, self.size.0, self.size.1)));
        }
        let Some(frames) = self.frames.as_ref() else { return Err(fail("the file is closed".into())) };
        if frames.send(f.bgr.clone()).is_err() {
            // The feeder stopped: ffmpeg is gone; say why.
            let why = self.close().err().unwrap_or_else(|| "the encoder stopped".into());
            return Err(VideoError::Write { path: self.path.clone(), reason: why });
        }
        Ok(())
    }

    /// Finalizes the file: ffmpeg gets the end of its input and writes the container's index.
    pub fn finish(mut self) -> Result<(), VideoError> {
        self.close().map_err(|reason| VideoError::Write { path: self.path.clone(), reason })
    }
}

impl Drop for VideoWriter {
    fn drop(&mut self) {
        if self.frames.is_some() {
            let _ = self.close();
        }
    }
}

/// What the prefetching decoder hands over next.
pub enum Decoded<T = Frame> {
    /// A decoded frame with its index (or what the decoder thread made of it).
    Frame(usize, T),
    /// A frame skipped by the stride (grabbed, not converted).
    Skipped,
    /// End of stream.
    End,
    /// Decoding failed; nothing follows.
    Error(VideoError),
}

/// Decodes on a background thread a few frames ahead, so decoding overlaps inference; the
/// thread can also turn each frame into what its consumer needs (model inputs), off its thread.
pub struct Prefetch<T: Send + 'static = Frame> {
    rx: std::sync::mpsc::Receiver<Decoded<T>>,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Prefetch<Frame> {
    /// Starts decoding `reader`, converting the frames `keep` picks by index (the others are
    /// only skipped over), at most `depth` frames ahead.
    pub fn new(reader: VideoReader, keep: impl Fn(usize) -> bool + Send + 'static, depth: usize) -> Self {
        Prefetch::with(reader, keep, depth, |f| f)
    }
}

impl<T: Send + 'static> Prefetch<T> {
    /// As [`Prefetch::new`], handing over `make(frame)` for each kept frame.
    pub fn with(
        mut reader: VideoReader,
        keep: impl Fn(usize) -> bool + Send + 'static,
        depth: usize,
        make: impl Fn(Frame) -> T + Send + 'static,
    ) -> Self {
        let (tx, rx) = std::sync::mpsc::sync_channel(depth.max(1));
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let flag = stop.clone();
        let thread = std::thread::spawn(move || {
            let mut n = 0usize;
            while !flag.load(std::sync::atomic::Ordering::Relaxed) {
                let step = if keep(n) {
                    match reader.read() {
                        Ok(Some((i, f))) => Decoded::Frame(i, make(f)),
                        Ok(None) => Decoded::End,
                        Err(e) => Decoded::Error(e),
                    }
                } else {
                    match reader.skip() {
                        Ok(true) => Decoded::Skipped,
                        Ok(false) => Decoded::End,
                        Err(e) => Decoded::Error(e),
                    }
                };
                n += 1;
                let last = matches!(step, Decoded::End | Decoded::Error(_));
                if tx.send(step).is_err() || last {
                    return;
                }
            }
        });
        Prefetch { rx, stop, thread: Some(thread) }
    }

    /// The next step; `End` once the decoder thread has finished.
    pub fn next_step(&mut self) -> Decoded<T> {
        self.rx.recv().unwrap_or(Decoded::End)
    }
}

impl<T: Send + 'static> Drop for Prefetch<T> {
    fn drop(&mut self) {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        // Unblock a sender waiting on a full queue, then wait for the thread.
        while self.rx.try_recv().is_ok() {}
        if let Some(t) = self.thread.take() {
            while !t.is_finished() {
                while self.rx.try_recv().is_ok() {}
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
            let _ = t.join();
        }
    }
}
