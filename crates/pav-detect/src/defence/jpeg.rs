//! JPEG re-compression (Dziugaite et al., Das et al.): the input encoded as a baseline JPEG and
//! decoded again by OpenCV (libjpeg, 4:2:0 chroma). The white box runs the same codec on the
//! input rounded to levels and passes the gradient straight through (the default).

use super::{DefenceError, DefenceUnit};
use pav_core::image::Frame;

/// JPEG re-compression at quality `q` (1–100).
#[derive(Clone, Debug, serde::Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Jpeg {
    /// Quality.
    pub q: u32,
}

/// A JPEG encoder or decoder refused the image.
#[cfg(feature = "video")]
#[derive(Debug, thiserror::Error)]
#[error("JPEG re-compression at quality {quality}: {source}")]
pub struct JpegError {
    /// The quality asked for.
    pub quality: u8,
    /// OpenCV's error.
    pub source: opencv::Error,
}

impl DefenceUnit for Jpeg {
    fn check(&self, _: usize, _: usize) -> Result<(), String> {
        if !(1..=100).contains(&self.q) {
            return Err(format!("q = {} must be a quality from 1 to 100", self.q));
        }
        if cfg!(not(feature = "video")) {
            return Err("the JPEG defence needs pav built with the `video` feature".into());
        }
        Ok(())
    }

    fn label(&self) -> String {
        format!("jpeg{}", self.q)
    }

    #[cfg(feature = "video")]
    fn apply(&self, img: &mut Frame, _: u64) -> Result<(), DefenceError> {
        use opencv::core::{Mat, Vector};
        use opencv::prelude::*;
        let quality = self.q as u8;
        let run = || -> opencv::Result<Vec<u8>> {
            let flat = Mat::from_slice(&img.bgr)?;
            let src = flat.reshape(3, img.height as i32)?;
            let mut buf = Vector::<u8>::new();
            let params = Vector::from_slice(&[opencv::imgcodecs::IMWRITE_JPEG_QUALITY, quality as i32]);
            opencv::imgcodecs::imencode(".jpg", &src, &mut buf, &params)?;
            let out = opencv::imgcodecs::imdecode(&buf, opencv::imgcodecs::IMREAD_COLOR)?;
            Ok(out.data_bytes()?.to_vec())
        };
        img.bgr = run().map_err(|source| JpegError { quality, source })?;
        Ok(())
    }

    #[cfg(not(feature = "video"))]
    fn apply(&self, _: &mut Frame, _: u64) -> Result<(), DefenceError> {
        Err(DefenceError::NoJpeg)
    }
}
