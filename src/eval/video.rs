//! Video decoding (OpenCV) into BGR frames, with clear errors for missing or unreadable files.

use crate::detect::Frame;
use opencv::core::Mat;
use opencv::prelude::*;
use opencv::videoio::{self, VideoCapture};
use std::path::{Path, PathBuf};

/// Errors opening or decoding a video.
#[derive(Debug, thiserror::Error)]
pub enum VideoError {
    /// The file does not exist.
    #[error("video {0} does not exist")]
    Missing(PathBuf),
    /// OpenCV could not open it (corrupt, truncated before the index, or unsupported).
    #[error("video {path} cannot be opened: {why}")]
    Unreadable {
        /// Video path.
        path: PathBuf,
        /// Reason.
        why: String,
    },
    /// Decoding failed mid-stream.
    #[error("video {path}: decoding failed at frame {frame}: {why}")]
    Decode {
        /// Video path.
        path: PathBuf,
        /// Frame index that failed.
        frame: usize,
        /// Reason.
        why: String,
    },
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
        let unreadable = |why: String| VideoError::Unreadable { path: path.into(), why };
        let cap =
            VideoCapture::from_file(path.as_os_str(), videoio::CAP_FFMPEG).map_err(|e| unreadable(e.to_string()))?;
        if !cap.is_opened().unwrap_or(false) {
            return Err(unreadable("not a readable video (corrupt, truncated or unsupported format)".into()));
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
        let ok = self.cap.grab().map_err(|e| self.decode_err(e.to_string()))?;
        if ok {
            self.next += 1;
        }
        Ok(ok)
    }

    /// Decodes the next frame; `None` at end of stream.
    pub fn read(&mut self) -> Result<Option<(usize, Frame)>, VideoError> {
        if !self.cap.read(&mut self.mat).map_err(|e| self.decode_err(e.to_string()))? || self.mat.empty() {
            return Ok(None);
        }
        let idx = self.next;
        self.next += 1;
        let frame = mat_to_frame(&self.mat).map_err(|why| self.decode_err(why))?;
        Ok(Some((idx, frame)))
    }

    fn decode_err(&self, why: String) -> VideoError {
        VideoError::Decode { path: self.path.clone(), frame: self.next, why }
    }
}

/// Copies an 8-bit BGR (or grey) OpenCV matrix into a [`Frame`].
pub fn mat_to_frame(m: &Mat) -> Result<Frame, String> {
    let (w, h) = (m.cols() as usize, m.rows() as usize);
    let bgr = match m.typ() {
        t if t == opencv::core::CV_8UC3 => contiguous(m)?.to_vec(),
        t if t == opencv::core::CV_8UC1 => contiguous(m)?.iter().flat_map(|&g| [g, g, g]).collect(),
        t => return Err(format!("unsupported pixel type {t} (need 8-bit BGR)")),
    };
    Ok(Frame { width: w, height: h, bgr })
}

fn contiguous(m: &Mat) -> Result<std::borrow::Cow<'_, [u8]>, String> {
    if m.is_continuous() {
        Ok(std::borrow::Cow::Borrowed(m.data_bytes().map_err(|e| e.to_string())?))
    } else {
        let owned = m.try_clone().map_err(|e| e.to_string())?;
        Ok(std::borrow::Cow::Owned(owned.data_bytes().map_err(|e| e.to_string())?.to_vec()))
    }
}

/// Wraps a [`Frame`] as an OpenCV BGR matrix (copying).
pub fn frame_to_mat(f: &Frame) -> opencv::Result<Mat> {
    let flat = Mat::from_slice(&f.bgr)?;
    let m = flat.reshape(3, f.height as i32)?;
    m.try_clone()
}

/// What the prefetching decoder hands over next.
pub enum Step {
    /// A decoded frame with its index.
    Frame(usize, Frame),
    /// A frame skipped by the stride (grabbed, not converted).
    Skipped,
    /// End of stream.
    End,
    /// Decoding failed; nothing follows.
    Error(VideoError),
}

/// Decodes on a background thread a few frames ahead, so decoding overlaps inference.
pub struct Prefetch {
    rx: std::sync::mpsc::Receiver<Step>,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Prefetch {
    /// Starts decoding `reader`, converting every `stride`-th frame, at most `depth` frames ahead.
    pub fn new(mut reader: VideoReader, stride: usize, depth: usize) -> Self {
        let (tx, rx) = std::sync::mpsc::sync_channel(depth.max(1));
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let flag = stop.clone();
        let thread = std::thread::spawn(move || {
            let stride = stride.max(1);
            let mut n = 0usize;
            while !flag.load(std::sync::atomic::Ordering::Relaxed) {
                let step = if n % stride == 0 {
                    match reader.read() {
                        Ok(Some((i, f))) => Step::Frame(i, f),
                        Ok(None) => Step::End,
                        Err(e) => Step::Error(e),
                    }
                } else {
                    match reader.skip() {
                        Ok(true) => Step::Skipped,
                        Ok(false) => Step::End,
                        Err(e) => Step::Error(e),
                    }
                };
                n += 1;
                let last = matches!(step, Step::End | Step::Error(_));
                if tx.send(step).is_err() || last {
                    return;
                }
            }
        });
        Prefetch { rx, stop, thread: Some(thread) }
    }

    /// The next step; `End` once the decoder thread has finished.
    pub fn next_step(&mut self) -> Step {
        self.rx.recv().unwrap_or(Step::End)
    }
}

impl Drop for Prefetch {
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
