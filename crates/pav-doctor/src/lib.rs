//! What this machine has for pav's jobs: ONNX Runtime, OpenCV, ffmpeg, Blender, the data store,
//! the print profile, the shipped detectors, serial ports and cameras. Each check says what it
//! found, or what is missing and the one command or setting that fixes it, and whether the main
//! job (`pav-rig evaluate` on the bundled clip) needs it.
#![warn(missing_docs)]

use pav_rig::controls::CameraControls;
use pav_run::data::manifest::Manifest;
use pav_run::data::store::{EntryState, Store};
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

/// Where a check stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Standing {
    /// Found and working.
    Ok,
    /// Needed by some job and not found, or broken.
    Missing,
    /// Hardware that is simply not plugged in here (a serial port, a camera): the simulated
    /// turntable and camera stand in.
    Absent,
}

/// One piece of the machine, checked.
#[derive(Clone, Debug)]
pub struct Finding {
    /// What was checked ("ONNX Runtime").
    pub piece: &'static str,
    /// Where it stands.
    pub status: Standing,
    /// What was found, or why not.
    pub found: String,
    /// The command or setting that fixes it, when it is not [`Standing::Ok`].
    pub fix: Option<String>,
    /// Whether the main job needs it.
    pub main_job: bool,
}

impl Finding {
    fn ok(piece: &'static str, found: String, main_job: bool) -> Finding {
        Finding { piece, status: Standing::Ok, found, fix: None, main_job }
    }

    fn missing(piece: &'static str, found: String, fix: String, main_job: bool) -> Finding {
        Finding { piece, status: Standing::Missing, found, fix: Some(fix), main_job }
    }

    /// Hardware no job needs here: the simulated one stands in.
    fn absent(piece: &'static str, found: &str, fix: &str) -> Finding {
        Finding { piece, status: Standing::Absent, found: found.into(), fix: Some(fix.into()), main_job: false }
    }
}

/// Every check, in the order of the jobs: what the main job needs first, then rendering,
/// printing and the rig. `detectors` is the folder of detector configs to load.
pub fn checks(detectors: &Path) -> Vec<Finding> {
    vec![
        onnx_runtime(),
        opencv(),
        data_store(),
        shipped_detectors(detectors),
        ffmpeg(),
        blender(),
        print_profile(),
        serial_ports(),
        cameras(),
    ]
}

/// Whether every check the main job needs is [`Standing::Ok`].
pub fn main_job_can_run(checks: &[Finding]) -> bool {
    checks.iter().filter(|c| c.main_job).all(|c| c.status == Standing::Ok)
}

/// ONNX Runtime's shared library, loaded.
pub fn onnx_runtime() -> Finding {
    const PIECE: &str = "ONNX Runtime";
    let fix = "run scripts/setup.sh, or set ORT_DYLIB_PATH to a libonnxruntime.so (PyPI onnxruntime 1.31.1)";
    match pav_onnx::runtime::runtime() {
        Ok(_) => Finding::ok(PIECE, pav_onnx::runtime::runtime_version().unwrap_or_default(), true),
        Err(e) => Finding::missing(PIECE, e.to_string(), fix.into(), true),
    }
}

/// OpenCV, linked into pav (a build without it does not start): its version and the two
/// modules the colour charts need.
pub fn opencv() -> Finding {
    const PIECE: &str = "OpenCV";
    let version = pav_core::video::opencv_version().unwrap_or_else(|| "unknown version".into());
    let info = opencv::core::get_build_information().unwrap_or_default();
    let lacking: Vec<&str> = ["aruco", "mcc"].into_iter().filter(|m| !info.contains(m)).collect();
    if lacking.is_empty() {
        Finding::ok(PIECE, format!("{version} (aruco, mcc)"), true)
    } else {
        // The main job does not read colour charts: only `pav print calibrate` needs them.
        let fix = "install Debian's libopencv-contrib-dev, as scripts/setup.sh does";
        Finding::missing(PIECE, format!("{version} without {}", lacking.join(", ")), fix.into(), false)
    }
}

/// The data store: every manifest entry present with its size and sha256.
pub fn data_store() -> Finding {
    const PIECE: &str = "data store";
    let store = Store::from_env();
    let (mut missing, mut corrupt) = (Vec::new(), Vec::new());
    let entries = &Manifest::builtin().entries;
    for e in entries {
        match store.state(e, true) {
            EntryState::Present => {}
            EntryState::Missing => missing.push(e.name.as_str()),
            EntryState::Corrupt(_) => corrupt.push(e.name.as_str()),
        }
    }
    let root = store.root.display();
    if missing.is_empty() && corrupt.is_empty() {
        return Finding::ok(PIECE, format!("{root}: all {} files, checksums match", entries.len()), false);
    }
    let first = |names: &[&str]| names.first().map_or(String::new(), |n| format!(", e.g. {n}"));
    Finding::missing(
        PIECE,
        format!(
            "{root}: {} of {} missing{}, {} corrupt{}",
            missing.len(),
            entries.len(),
            first(&missing),
            corrupt.len(),
            first(&corrupt)
        ),
        "pav data fetch (or pav data fetch --mirror DIR from a copy)".into(),
        false,
    )
}

/// Every detector config in `dir` loads, its model with it.
pub fn shipped_detectors(dir: &Path) -> Finding {
    const PIECE: &str = "detectors";
    match pav_detect::load::load_detectors(&[dir.to_path_buf()], &[], &[], 1) {
        Ok(d) => {
            let names: Vec<String> = d.iter().map(|d| d.name().to_string()).collect();
            Finding::ok(PIECE, format!("{}: {} load ({})", dir.display(), names.len(), names.join(", ")), true)
        }
        Err(e) => Finding::missing(
            PIECE,
            format!("{}: {e}", dir.display()),
            "fix the pieces above (ONNX Runtime, the data store), then run scripts/setup.sh for YOLOv3-tiny".into(),
            true,
        ),
    }
}

/// ffmpeg, which writes every video pav makes.
pub fn ffmpeg() -> Finding {
    const PIECE: &str = "ffmpeg";
    match pav_run::provenance::tool_version("ffmpeg", &["-version"]) {
        Some(v) => Finding::ok(PIECE, v, false),
        None => Finding::missing(PIECE, "not on the PATH".into(), "apt-get install ffmpeg".into(), false),
    }
}

/// Blender, which renders the physically based views.
pub fn blender() -> Finding {
    const PIECE: &str = "Blender";
    match pav_scene::blender::Blender::find() {
        Ok(b) => {
            let version = b.version().unwrap_or_else(|| "found".into());
            match b.has_cycles() {
                Some(true) => {
                    Finding::ok(PIECE, format!("{version} (Cycles, on the CPU as pav's views render)"), false)
                }
                Some(false) => Finding::missing(
                    PIECE,
                    format!("{version} without Cycles"),
                    "apt-get install blender (Debian's build has Cycles), or set PAV_BLENDER to one that has".into(),
                    false,
                ),
                None => Finding::missing(
                    PIECE,
                    format!("{version}, but its Python did not answer"),
                    "run `blender -b --factory-startup` to see why, or set PAV_BLENDER to another Blender".into(),
                    false,
                ),
            }
        }
        Err(e) => Finding::missing(
            PIECE,
            e.to_string(),
            "apt-get install blender (3.4, as scripts/setup.sh does), or set PAV_BLENDER to its executable".into(),
            false,
        ),
    }
}

/// LittleCMS and the default CMYK profile the print channel proofs through.
pub fn print_profile() -> Finding {
    const PIECE: &str = "print profile";
    let v = lcms2::version();
    let lcms = format!("LittleCMS {}.{}", v / 1000, (v % 1000) / 10);
    let profile = Path::new(pav_print::proof::DEFAULT_PROFILE);
    if profile.is_file() {
        Finding::ok(PIECE, format!("{lcms}; {}", profile.display()), false)
    } else {
        Finding::missing(
            PIECE,
            format!("{lcms}; no {}", profile.display()),
            "apt-get install libgs-common, or give your printer's profile with --profile".into(),
            false,
        )
    }
}

/// Whether a user (`uid`, in `groups`) may read and write a file of `mode` owned by `owner` and
/// `group`: what opening a serial port for the turntable needs.
pub fn may_read_write(mode: u32, owner: u32, group: u32, uid: u32, groups: &[u32]) -> bool {
    let rw = |shift: u32| (mode >> shift) & 0o6 == 0o6;
    uid == 0 || (uid == owner && rw(6)) || (groups.contains(&group) && rw(3)) || rw(0)
}

/// This process's effective user and its groups.
fn user() -> (u32, Vec<u32>) {
    // SAFETY: getegid, geteuid and getgroups only read the process's credentials; getgroups
    // writes at most `n` ids into a buffer of `n`.
    unsafe {
        let n = libc::getgroups(0, std::ptr::null_mut());
        let mut groups = vec![0 as libc::gid_t; n.max(0) as usize];
        let got = libc::getgroups(n, groups.as_mut_ptr());
        groups.truncate(got.max(0) as usize);
        groups.push(libc::getegid());
        (libc::geteuid(), groups)
    }
}

/// The name of group `gid` from /etc/group, for the fix.
fn group_name(gid: u32) -> String {
    std::fs::read_to_string("/etc/group")
        .unwrap_or_default()
        .lines()
        .find_map(|l| {
            let f: Vec<&str> = l.split(':').collect();
            (f.len() > 2 && f[2] == gid.to_string()).then(|| f[0].to_string())
        })
        .unwrap_or_else(|| gid.to_string())
}

/// The USB serial ports a turntable can be on, and whether this user may open each.
pub fn serial_ports() -> Finding {
    let (uid, groups) = user();
    ports_check(&pav_rig::transport::usb_serial_ports(), uid, &groups)
}

/// [`serial_ports`] for the given port files and user.
pub fn ports_check(ports: &[PathBuf], uid: u32, groups: &[u32]) -> Finding {
    const PIECE: &str = "serial ports";
    if ports.is_empty() {
        return Finding::absent(PIECE, "none plugged in", "plug the turntable's USB in; `--port sim` simulates one");
    }
    let mut denied = Vec::new();
    for p in ports {
        if let Ok(m) = std::fs::metadata(p) {
            if !may_read_write(m.mode(), m.uid(), m.gid(), uid, groups) {
                denied.push((p, group_name(m.gid())));
            }
        }
    }
    let list = ports.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ");
    match denied.first() {
        None => Finding::ok(PIECE, list, false),
        Some((p, group)) => Finding::missing(
            PIECE,
            format!("{list}; this user may not open {}", p.display()),
            format!("sudo usermod -aG {group} $USER, then log in again"),
            false,
        ),
    }
}

/// The V4L2 cameras and the controls a capture can lock on each.
pub fn cameras() -> Finding {
    const PIECE: &str = "cameras";
    let found = pav_rig::v4l2::capture_devices();
    if found.is_empty() {
        return Finding::absent(PIECE, "no V4L2 camera", "plug a camera in; `--camera sim` simulates one");
    }
    let shown: Vec<String> = found
        .iter()
        .map(|p| {
            let controls = pav_rig::v4l2::V4l2Controls::open(p)
                .and_then(|c| c.offers())
                .map(|o| o.iter().map(|o| o.control.name()).collect::<Vec<_>>().join(", "))
                .unwrap_or_else(|e| format!("controls unreadable: {e}"));
            format!("{} ({})", p.display(), if controls.is_empty() { "nothing to lock".into() } else { controls })
        })
        .collect();
    Finding::ok(PIECE, shown.join("; "), false)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_port_opens_for_its_owner_its_group_or_everyone_as_its_mode_says() {
        let dialout = 20;
        // crw-rw---- root:dialout, as Debian makes /dev/ttyACM0.
        assert!(!may_read_write(0o660, 0, dialout, 1000, &[1000]), "outside dialout");
        assert!(may_read_write(0o660, 0, dialout, 1000, &[1000, dialout]), "in dialout");
        assert!(may_read_write(0o660, 0, dialout, 0, &[0]), "root");
        assert!(may_read_write(0o600, 1000, dialout, 1000, &[1000]), "its owner");
        assert!(!may_read_write(0o640, 0, dialout, 1000, &[dialout]), "the group may only read");
        assert!(may_read_write(0o666, 0, dialout, 1000, &[1000]), "everyone");
    }

    #[test]
    fn a_port_a_user_may_not_open_is_named_with_its_group_and_no_port_is_absent() {
        let tmp = tempfile::tempdir().unwrap();
        let port = tmp.path().join("ttyACM9");
        std::fs::write(&port, b"").unwrap();
        std::fs::set_permissions(&port, std::os::unix::fs::PermissionsExt::from_mode(0o660)).unwrap();
        let m = std::fs::metadata(&port).unwrap();
        // A user outside the port's group: refused, and told which group to join.
        let c = ports_check(std::slice::from_ref(&port), m.uid() + 4242, &[m.gid() + 4242]);
        assert_eq!(c.status, Standing::Missing, "{c:?}");
        assert!(c.found.contains("may not open") && c.found.contains("ttyACM9"), "{c:?}");
        assert!(c.fix.as_deref().unwrap().contains(&format!("usermod -aG {} ", group_name(m.gid()))), "{c:?}");
        // One in it may.
        let ok = ports_check(std::slice::from_ref(&port), m.uid() + 4242, &[m.gid()]);
        assert_eq!(ok.status, Standing::Ok, "{ok:?}");
        let none = ports_check(&[], 1000, &[1000]);
        assert_eq!(none.status, Standing::Absent);
        assert!(none.fix.unwrap().contains("--port sim"));
    }

    #[test]
    fn the_main_job_runs_only_when_every_piece_it_needs_is_there() {
        let c = |status, main_job| Finding { piece: "x", status, found: String::new(), fix: None, main_job };
        assert!(main_job_can_run(&[c(Standing::Ok, true), c(Standing::Missing, false), c(Standing::Absent, false)]));
        assert!(!main_job_can_run(&[c(Standing::Ok, true), c(Standing::Missing, true)]));
    }
}
