//! FCA/DAS CARLA samples: `img` (H×W×3 BGR), `veh_trans` and `cam_trans` (2×3 each).

use super::npz::{NpyData, Npz, NpzError};
use pav_core::image::Frame;
use std::path::{Path, PathBuf};

/// One CARLA view: the photo and the CARLA poses.
#[derive(Clone, Debug)]
pub struct CarlaSample {
    /// Source file.
    pub path: PathBuf,
    /// The PBR image.
    pub image: Frame,
    /// Vehicle [[x, y, z] m, [pitch, yaw, roll] deg] in the world.
    pub veh_trans: [[f64; 3]; 2],
    /// Camera [[dx, dy, dz] m offset in world axes, [pitch, yaw, roll] deg].
    pub cam_trans: [[f64; 3]; 2],
}

impl CarlaSample {
    /// Reads an FCA-format npz.
    pub fn load(path: &Path) -> Result<Self, NpzError> {
        let mut z = Npz::open(path)?;
        let bad = |name: &str, msg: String| NpzError::Array { path: path.into(), name: name.into(), msg };
        let img = z.array("img")?;
        let NpyData::U8(bgr) = img.data else {
            return Err(bad("img", "expected uint8".into()));
        };
        let [h, w, 3] = img.shape[..] else {
            return Err(bad("img", format!("expected H×W×3, got {:?}", img.shape)));
        };
        let mut pose = |name: &str| -> Result<[[f64; 3]; 2], NpzError> {
            let a = z.array(name)?;
            let v = a.to_f64();
            if v.len() != 6 || v.iter().any(|x| !x.is_finite()) {
                return Err(bad(name, format!("expected 2×3 finite values, got shape {:?}", a.shape)));
            }
            Ok([[v[0], v[1], v[2]], [v[3], v[4], v[5]]])
        };
        Ok(CarlaSample {
            path: path.into(),
            image: Frame { width: w, height: h, bgr },
            veh_trans: pose("veh_trans")?,
            cam_trans: pose("cam_trans")?,
        })
    }

    /// Camera azimuth around the car in degrees, [0, 360): camera yaw minus vehicle yaw.
    pub fn relative_azimuth_deg(&self) -> f64 {
        (self.cam_trans[1][1] - self.veh_trans[1][1]).rem_euclid(360.0)
    }
}
