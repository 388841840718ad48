//! The camera settings a capture locks: exposure, gain, white balance and focus, each set with its
//! automatic mode off before the table turns and read back after it, so that the image does not
//! follow the car as it turns and `run.toml` says what the camera held. The controls sit behind
//! a trait: a V4L2 camera (`v4l2`) and a simulated camera with the same controls
//! ([`SimControls`]) implement it, and the locking logic is tested on the simulated one.

use std::collections::BTreeMap;

/// A camera setting a capture can lock.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Control {
    /// Exposure time, in V4L2's units of 100 µs.
    Exposure,
    /// Analogue gain, in the camera's units.
    Gain,
    /// White balance as a colour temperature, kelvin.
    WhiteBalance,
    /// Focus position, in the camera's units.
    Focus,
}

impl Control {
    /// Every control, in the order they are locked.
    pub const ALL: [Control; 4] = [Control::Exposure, Control::Gain, Control::WhiteBalance, Control::Focus];

    /// Its name in flags, configs and `run.toml`.
    pub fn name(self) -> &'static str {
        match self {
            Control::Exposure => "exposure",
            Control::Gain => "gain",
            Control::WhiteBalance => "white_balance",
            Control::Focus => "focus",
        }
    }

    /// Its unit, for listings.
    pub fn unit(self) -> &'static str {
        match self {
            Control::Exposure => "× 100 µs",
            Control::WhiteBalance => "K",
            Control::Gain | Control::Focus => "camera units",
        }
    }
}

/// One control as the camera offers it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Offer {
    /// Which control.
    pub control: Control,
    /// Smallest value.
    pub min: i64,
    /// Largest value.
    pub max: i64,
    /// Step between values.
    pub step: i64,
    /// The camera's default.
    pub default: i64,
    /// Its value now.
    pub value: i64,
    /// Whether its automatic mode is on (none: the camera has no automatic mode for it).
    pub auto: Option<bool>,
}

impl std::fmt::Display for Offer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let auto = match self.auto {
            Some(true) => ", automatic",
            Some(false) => ", manual",
            None => "",
        };
        write!(
            f,
            "{:<14} {}–{} step {} ({}), default {}, now {}{auto}",
            self.control.name(),
            self.min,
            self.max,
            self.step,
            self.control.unit(),
            self.default,
            self.value
        )
    }
}

/// Why a control could not be locked or read.
#[derive(Debug, thiserror::Error)]
pub enum ControlError {
    /// The camera has no such control.
    #[error("{camera} has no {} control (it offers: {offered}); pass --allow-auto to record it as left automatic", control.name())]
    Missing {
        /// The camera.
        camera: String,
        /// The control asked for.
        control: Control,
        /// The controls it has.
        offered: String,
    },
    /// A value outside what the camera takes.
    #[error("{camera} takes {} from {min} to {max} in steps of {step} ({}), not {value}; pass --allow-auto to record it as left automatic", control.name(), control.unit())]
    Refused {
        /// The camera.
        camera: String,
        /// The control.
        control: Control,
        /// The value asked for.
        value: i64,
        /// Smallest value.
        min: i64,
        /// Largest value.
        max: i64,
        /// Step.
        step: i64,
    },
    /// The camera would not leave its automatic mode, or did not keep the value.
    #[error("{camera} did not lock {}: {why}; pass --allow-auto to record it as left automatic", control.name())]
    NotLocked {
        /// The camera.
        camera: String,
        /// The control.
        control: Control,
        /// What happened.
        why: String,
    },
    /// The device failed.
    #[error("{camera}: {what}: {source}")]
    Device {
        /// The camera.
        camera: String,
        /// What was being done.
        what: String,
        /// Why.
        source: std::io::Error,
    },
}

/// A camera's controls.
pub trait CameraControls {
    /// The camera, for messages.
    fn camera(&self) -> String;
    /// The controls of [`Control::ALL`] it has, with their ranges and values.
    fn offers(&self) -> Result<Vec<Offer>, ControlError>;
    /// The formats it delivers, one line each, for listings.
    fn formats(&self) -> Result<Vec<String>, ControlError>;
    /// Turns `control`'s automatic mode off (where it has one) and sets it to `value`, which
    /// [`lock_all`] has checked against the offer.
    fn set_manual(&mut self, control: Control, value: i64) -> Result<(), ControlError>;
    /// The value it holds now.
    fn read(&self, control: Control) -> Result<i64, ControlError>;
}

/// One control of a capture: the value asked for, the value the camera held (after locking, and
/// again after the turn), or why it was left automatic.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Locked {
    /// The control.
    pub control: Control,
    /// The value asked for.
    pub set: i64,
    /// The value read back, when it could be.
    pub read: Option<i64>,
    /// Why it was left automatic (`--allow-auto`), or why its read-back differs.
    pub warning: Option<String>,
}

impl Locked {
    /// The `run.toml` entries of this control: `<name>_set`, `<name>_read` and a warning.
    pub fn entries(&self) -> Vec<(String, String)> {
        let n = self.control.name();
        let mut v = vec![(format!("{n}_set"), self.set.to_string())];
        v.push((format!("{n}_read"), self.read.map_or("none".into(), |r| r.to_string())));
        if let Some(w) = &self.warning {
            v.push((format!("{n}_warning"), w.clone()));
        }
        v
    }
}

/// Locks each of `wanted` on `cam`, in [`Control::ALL`]'s order: checked against what the camera
/// offers, set with its automatic mode off, and read back. A control the camera lacks, a value
/// it does not take, or a lock it does not keep fails, naming the control and what the camera
/// offers; with `allow_auto` it is recorded as left automatic instead.
pub fn lock_all(
    cam: &mut dyn CameraControls,
    wanted: &BTreeMap<Control, i64>,
    allow_auto: bool,
) -> Result<Vec<Locked>, ControlError> {
    let offers = if wanted.is_empty() { Vec::new() } else { cam.offers()? };
    let mut out = Vec::new();
    for (&control, &value) in wanted {
        let attempt = (|| {
            let Some(o) = offers.iter().find(|o| o.control == control) else {
                let offered = offers.iter().map(|o| o.control.name()).collect::<Vec<_>>().join(", ");
                let offered =
                    if offered.is_empty() { "none of exposure, gain, white_balance, focus".into() } else { offered };
                return Err(ControlError::Missing { camera: cam.camera(), control, offered });
            };
            let step = o.step.max(1);
            if value < o.min || value > o.max || (value - o.min) % step != 0 {
                return Err(ControlError::Refused {
                    camera: cam.camera(),
                    control,
                    value,
                    min: o.min,
                    max: o.max,
                    step,
                });
            }
            cam.set_manual(control, value)?;
            let read = cam.read(control)?;
            if read != value {
                let why = format!("set to {value}, it reads {read}");
                return Err(ControlError::NotLocked { camera: cam.camera(), control, why });
            }
            Ok(read)
        })();
        match attempt {
            Ok(read) => out.push(Locked { control, set: value, read: Some(read), warning: None }),
            Err(e @ ControlError::Device { .. }) => return Err(e),
            Err(e) if allow_auto => {
                out.push(Locked { control, set: value, read: None, warning: Some(format!("left automatic: {e}")) })
            }
            Err(e) => return Err(e),
        }
    }
    Ok(out)
}

/// Reads back every control that was locked (after the turn): a camera that let one wander
/// gets a warning naming both values.
pub fn read_back(cam: &dyn CameraControls, locked: &mut [Locked]) {
    for l in locked.iter_mut().filter(|l| l.warning.is_none()) {
        match cam.read(l.control) {
            Ok(v) => {
                if v != l.set {
                    l.warning = Some(format!("set to {}, read {v} after the turn", l.set));
                }
                l.read = Some(v);
            }
            Err(e) => l.warning = Some(format!("not read back after the turn: {e}")),
        }
    }
}

/// A simulated camera's controls: a webcam's ranges, every control automatic until locked. It
/// can lack a control, or keep one automatic whatever is asked, to test the refusals.
#[derive(Clone, Debug)]
pub struct SimControls {
    offers: Vec<Offer>,
    /// Controls whose automatic mode cannot be turned off.
    stuck: Vec<Control>,
}

impl Default for SimControls {
    fn default() -> Self {
        let offer = |control, min, max, step, default| Offer {
            control,
            min,
            max,
            step,
            default,
            value: default,
            auto: Some(true),
        };
        SimControls {
            offers: vec![
                offer(Control::Exposure, 3, 2047, 1, 250),
                offer(Control::Gain, 0, 255, 1, 0),
                offer(Control::WhiteBalance, 2800, 6500, 10, 4600),
                offer(Control::Focus, 0, 250, 5, 0),
            ],
            stuck: Vec::new(),
        }
    }
}

impl SimControls {
    /// The same camera without `control`.
    pub fn without(mut self, control: Control) -> Self {
        self.offers.retain(|o| o.control != control);
        self
    }

    /// The same camera, whose `control` stays automatic (its value moves on its own).
    pub fn stuck(mut self, control: Control) -> Self {
        self.stuck.push(control);
        self
    }

    /// Whether `control` is locked (its automatic mode off).
    pub fn is_locked(&self, control: Control) -> bool {
        self.offers.iter().any(|o| o.control == control && o.auto == Some(false))
    }
}

impl CameraControls for SimControls {
    fn camera(&self) -> String {
        "the simulated camera".into()
    }

    fn offers(&self) -> Result<Vec<Offer>, ControlError> {
        Ok(self.offers.clone())
    }

    fn formats(&self) -> Result<Vec<String>, ControlError> {
        Ok(vec!["BGR3 (24-bit BGR): any size, any frame rate".into()])
    }

    fn set_manual(&mut self, control: Control, value: i64) -> Result<(), ControlError> {
        let stuck = self.stuck.contains(&control);
        let o = self.offers.iter_mut().find(|o| o.control == control).ok_or_else(|| ControlError::Device {
            camera: "the simulated camera".into(),
            what: format!("setting {}", control.name()),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "no such control"),
        })?;
        if stuck {
            // An automatic mode that will not turn off: the camera picks its own value.
            o.value = o.default + o.step;
        } else {
            o.auto = Some(false);
            o.value = value;
        }
        Ok(())
    }

    fn read(&self, control: Control) -> Result<i64, ControlError> {
        self.offers.iter().find(|o| o.control == control).map(|o| o.value).ok_or_else(|| ControlError::Device {
            camera: self.camera(),
            what: format!("reading {}", control.name()),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "no such control"),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wanted(v: &[(Control, i64)]) -> BTreeMap<Control, i64> {
        v.iter().copied().collect()
    }

    #[test]
    fn locks_read_back_and_refusals_on_the_simulated_camera() {
        let mut cam = SimControls::default();
        let w = wanted(&[(Control::Exposure, 120), (Control::WhiteBalance, 4000), (Control::Focus, 30)]);
        let mut locked = lock_all(&mut cam, &w, false).unwrap();
        assert_eq!(
            locked.iter().map(|l| (l.control, l.set, l.read)).collect::<Vec<_>>(),
            [
                (Control::Exposure, 120, Some(120)),
                (Control::WhiteBalance, 4000, Some(4000)),
                (Control::Focus, 30, Some(30)),
            ]
        );
        assert!(cam.is_locked(Control::Exposure) && !cam.is_locked(Control::Gain));
        read_back(&cam, &mut locked);
        assert!(locked.iter().all(|l| l.warning.is_none()));
        assert_eq!(
            locked[0].entries(),
            [("exposure_set".into(), "120".into()), ("exposure_read".into(), "120".into())]
        );

        // A control the camera lacks names it and what the camera has.
        let e = lock_all(&mut SimControls::default().without(Control::Focus), &w, false).unwrap_err().to_string();
        assert!(e.contains("no focus control") && e.contains("exposure, gain, white_balance"), "{e}");
        // A value off the range or off the step names the range.
        let e = lock_all(&mut SimControls::default(), &wanted(&[(Control::WhiteBalance, 4005)]), false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("from 2800 to 6500 in steps of 10") && e.contains("not 4005"), "{e}");
        // A lock the camera does not keep.
        let e = lock_all(&mut SimControls::default().stuck(Control::Gain), &wanted(&[(Control::Gain, 10)]), false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("did not lock gain") && e.contains("it reads 1"), "{e}");
        // With allow_auto each becomes a recorded warning and the others still lock.
        let mut cam = SimControls::default().without(Control::Focus);
        let locked = lock_all(&mut cam, &w, true).unwrap();
        assert_eq!(locked.iter().filter(|l| l.warning.is_some()).count(), 1);
        let focus = locked.iter().find(|l| l.control == Control::Focus).unwrap();
        assert!(focus.read.is_none() && focus.warning.as_ref().unwrap().starts_with("left automatic"));
        assert!(focus.entries().iter().any(|(k, v)| k == "focus_warning" && v.contains("no focus control")));
        assert!(cam.is_locked(Control::Exposure));
    }

    #[test]
    fn a_value_that_wanders_during_the_turn_is_flagged_on_read_back() {
        let mut cam = SimControls::default();
        let mut locked = lock_all(&mut cam, &wanted(&[(Control::Gain, 40)]), false).unwrap();
        cam.offers.iter_mut().find(|o| o.control == Control::Gain).unwrap().value = 44;
        read_back(&cam, &mut locked);
        assert_eq!(locked[0].read, Some(44));
        assert_eq!(locked[0].warning.as_deref(), Some("set to 40, read 44 after the turn"));
    }
}
