//! A V4L2 camera's controls through the `v4l` crate (safe bindings to the kernel's ioctls): its
//! ranges and values (`VIDIOC_QUERYCTRL`, `VIDIOC_G_CTRL`), its formats, and the locking of
//! exposure, gain, white balance and focus with their automatic modes off. Frames still come
//! through OpenCV (`source`); the controls are set on the same device node, which V4L2 allows.

use super::controls::{CameraControls, Control, ControlError, Offer};
use std::path::{Path, PathBuf};
use v4l::control::{Control as V4lControl, Value};
use v4l::video::Capture;
use v4l::Device;

/// A control's value and its automatic mode: (value id, automatic-mode id, the automatic mode's
/// manual value). Exposure's automatic mode is a menu where 1 is manual; the others are
/// booleans.
fn ids(c: Control) -> (u32, u32, i64) {
    match c {
        Control::Exposure => (0x009a_0902, 0x009a_0901, 1),
        Control::Gain => (0x0098_0913, 0x0098_0912, 0),
        Control::WhiteBalance => (0x0098_091a, 0x0098_090c, 0),
        Control::Focus => (0x009a_090a, 0x009a_090c, 0),
    }
}

/// The video devices (`/dev/videoN`, in N's order) that capture frames: a webcam's metadata
/// node, which shares its name pattern, is left out.
pub fn capture_devices() -> Vec<PathBuf> {
    let mut found: Vec<(u32, PathBuf)> = std::fs::read_dir("/dev")
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().into_string().ok()?;
            let n = name.strip_prefix("video")?.parse().ok()?;
            Some((n, e.path()))
        })
        .filter(|(_, p)| {
            Device::with_path(p)
                .and_then(|d| d.query_caps())
                .is_ok_and(|c| c.capabilities.contains(v4l::capability::Flags::VIDEO_CAPTURE))
        })
        .collect();
    found.sort();
    found.into_iter().map(|(_, p)| p).collect()
}

/// A V4L2 device's controls.
pub struct V4l2Controls {
    dev: Device,
    path: PathBuf,
}

impl V4l2Controls {
    /// Opens the controls of the camera at `path` (`/dev/video0`).
    pub fn open(path: &Path) -> Result<Self, ControlError> {
        let camera = format!("V4L2 camera {}", path.display());
        let dev = Device::with_path(path).map_err(|source| ControlError::Device {
            camera,
            what: "opening its controls".into(),
            source,
        })?;
        Ok(V4l2Controls { dev, path: path.into() })
    }

    fn device_error(&self, what: String) -> impl Fn(std::io::Error) -> ControlError + '_ {
        move |source| ControlError::Device { camera: self.camera(), what: what.clone(), source }
    }

    fn value(&self, id: u32) -> Result<i64, std::io::Error> {
        Ok(match self.dev.control(id)?.value {
            Value::Integer(v) => v,
            Value::Boolean(b) => i64::from(b),
            _ => 0,
        })
    }
}

impl CameraControls for V4l2Controls {
    fn camera(&self) -> String {
        format!("V4L2 camera {}", self.path.display())
    }

    fn offers(&self) -> Result<Vec<Offer>, ControlError> {
        let all = self.dev.query_controls().map_err(self.device_error("listing its controls".into()))?;
        let mut out = Vec::new();
        for control in Control::ALL {
            let (id, auto_id, manual) = ids(control);
            let Some(d) = all.iter().find(|d| d.id == id) else { continue };
            let value = self.value(id).map_err(self.device_error(format!("reading {}", control.name())))?;
            let auto = match all.iter().any(|d| d.id == auto_id) {
                true => {
                    Some(self.value(auto_id).map_err(self.device_error("reading an automatic mode".into()))? != manual)
                }
                false => None,
            };
            out.push(Offer {
                control,
                min: d.minimum,
                max: d.maximum,
                step: d.step as i64,
                default: d.default,
                value,
                auto,
            });
        }
        Ok(out)
    }

    fn formats(&self) -> Result<Vec<String>, ControlError> {
        let formats = self.dev.enum_formats().map_err(self.device_error("listing its formats".into()))?;
        let mut out = Vec::new();
        for f in formats {
            let sizes = self.dev.enum_framesizes(f.fourcc).unwrap_or_default();
            let sizes: Vec<String> = sizes
                .into_iter()
                .flat_map(|s| s.size.to_discrete())
                .map(|d| format!("{}x{}", d.width, d.height))
                .collect();
            out.push(format!("{} ({}): {}", f.fourcc, f.description, sizes.join(", ")));
        }
        Ok(out)
    }

    fn set_manual(&mut self, control: Control, value: i64) -> Result<(), ControlError> {
        let (id, auto_id, manual) = ids(control);
        let has_auto = self.dev.query_controls().map(|all| all.iter().any(|d| d.id == auto_id)).unwrap_or(false);
        if has_auto {
            let v = if control == Control::Exposure { Value::Integer(manual) } else { Value::Boolean(manual != 0) };
            self.dev.set_control(V4lControl { id: auto_id, value: v }).map_err(|source| ControlError::NotLocked {
                camera: self.camera(),
                control,
                why: format!("turning its automatic mode off failed: {source}"),
            })?;
        }
        self.dev.set_control(V4lControl { id, value: Value::Integer(value) }).map_err(|source| {
            ControlError::NotLocked { camera: self.camera(), control, why: format!("setting {value} failed: {source}") }
        })
    }

    fn read(&self, control: Control) -> Result<i64, ControlError> {
        self.value(ids(control).0).map_err(self.device_error(format!("reading {}", control.name())))
    }
}
