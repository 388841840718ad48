//! Video files through OpenCV: decoding into BGR frames (with a prefetching decoder thread) and
//! encoding frames, with errors that name the file and keep OpenCV's cause.

use crate::image::Frame;
use opencv::core::{Mat, Size};
use opencv::prelude::*;
use opencv::videoio::{self, VideoCapture, CAP_FFMPEG};
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
    /// The encoder could not be created for this file and codec.
    #[error("OpenCV cannot write {path} with codec {codec}")]
    Encoder {
        /// Video path.
        path: PathBuf,
        /// FourCC.
        codec: String,
        /// OpenCV's error, when it gave one.
        source: Option<opencv::Error>,
    },
    /// Writing or closing the file failed.
    #[error("writing {path}: {source}")]
    Write {
        /// Video path.
        path: PathBuf,
        /// Why.
        source: MatError,
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

/// Encodes frames into a video file as they come (OpenCV's FFmpeg backend).
pub struct VideoWriter {
    inner: videoio::VideoWriter,
    path: PathBuf,
}

impl VideoWriter {
    /// Creates `path` for `width × height` frames at `fps` with codec `fourcc` (e.g. `avc1`).
    pub fn create(
        path: &Path,
        fourcc: [char; 4],
        fps: f64,
        (width, height): (usize, usize),
    ) -> Result<Self, VideoError> {
        let encoder = |source| VideoError::Encoder { path: path.into(), codec: fourcc.iter().collect(), source };
        let [a, b, c, d] = fourcc;
        let code = videoio::VideoWriter::fourcc(a, b, c, d).map_err(|e| encoder(Some(e)))?;
        let size = Size::new(width as i32, height as i32);
        let inner = videoio::VideoWriter::new_with_backend(&*path.to_string_lossy(), CAP_FFMPEG, code, fps, size, true)
            .map_err(|e| encoder(Some(e)))?;
        if !inner.is_opened().unwrap_or(false) {
            return Err(encoder(None));
        }
        Ok(VideoWriter { inner, path: path.into() })
    }

    /// Appends one frame.
    pub fn write(&mut self, f: &Frame) -> Result<(), VideoError> {
        let write_err = |source: MatError| VideoError::Write { path: self.path.clone(), source };
        let m = frame_to_mat(f).map_err(|e| write_err(e.into()))?;
        self.inner.write(&m).map_err(|e| write_err(e.into()))
    }

    /// Finalizes the file (the container's index is written here).
    pub fn finish(mut self) -> Result<(), VideoError> {
        self.inner.release().map_err(|e| VideoError::Write { path: self.path.clone(), source: e.into() })
    }
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
