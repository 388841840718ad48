//! Blender Cycles as a subprocess: one job (a mesh, its material, an environment and many
//! cameras) per Blender process, since Blender takes about 2.5 s to start.

use pav_core::geometry::camera::Camera;
use serde::Serialize;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// The Blender script, shipped inside the binary so it cannot drift from the code that calls it.
pub const SCRIPT: &str = include_str!("blender_views.py");

/// Why Blender did not render a job.
#[derive(Debug, thiserror::Error)]
pub enum BlenderError {
    /// Blender is not installed.
    #[error("blender not found ({0}): run scripts/setup.sh, which installs Debian's `blender` package")]
    NotFound(String),
    /// Blender stopped with an error.
    #[error("blender failed (exit {code:?}) rendering {what}; its last output:\n{tail}")]
    Failed {
        /// What it was rendering.
        what: String,
        /// Exit code.
        code: Option<i32>,
        /// The end of its output.
        tail: String,
    },
    /// The job's files could not be written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> BlenderError + '_ {
    move |source| BlenderError::Io { path: path.into(), source }
}

/// What Blender renders in a job.
#[derive(Clone, Copy, Debug, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Textured paint lit by the environment.
    Pbr,
    /// The texture as emission, unlit.
    Emission,
    /// The interpolated UV as a raw 16-bit colour (R = u, G = v), alpha = coverage.
    Uv,
}

/// One view as the script reads it.
#[derive(Clone, Debug, Serialize)]
pub struct JobView {
    /// Name printed back when done.
    pub name: String,
    /// pav's view axes (rows: X left, Y up, Z forward).
    pub axes: [[f32; 3]; 3],
    /// Eye position.
    pub eye: [f32; 3],
    /// Field of view, degrees.
    pub fov_deg: f32,
    /// Output PNG.
    pub out: PathBuf,
    /// Degrees the environment turns about pav's +Y with the camera (0: it stays put).
    pub env_turn_deg: f32,
}

impl JobView {
    /// The job entry for `camera`, written to `out`.
    pub fn new(name: &str, camera: &Camera, out: PathBuf) -> JobView {
        JobView {
            name: name.into(),
            axes: camera.axes,
            eye: camera.eye,
            fov_deg: camera.fov_deg,
            out,
            env_turn_deg: 0.0,
        }
    }
}

/// A turntable top.
#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
pub struct TableTop {
    /// Radius, in the mesh's units.
    pub radius: f32,
    /// Colour, sRGB in [0, 1].
    pub colour: [f32; 3],
}

/// One Blender process's work.
#[derive(Clone, Debug, Serialize)]
pub struct Job {
    /// What to render.
    pub mode: Mode,
    /// OBJ in pav's world frame.
    pub mesh: PathBuf,
    /// Texture (pbr and emission modes).
    pub texture: Option<PathBuf>,
    /// Its size (for pav's texel convention).
    pub tex_size: [usize; 2],
    /// Image side.
    pub size: usize,
    /// Samples per pixel.
    pub samples: u32,
    /// Environment map (pbr mode).
    pub environment: Option<PathBuf>,
    /// Its strength.
    pub env_strength: f64,
    /// A shadow-catcher ground (pbr mode).
    pub shadows: bool,
    /// Ground height (pav's lowest y).
    pub ground_y: f32,
    /// Ground side.
    pub ground_size: f32,
    /// Paint: metallic, roughness, clear coat.
    pub metallic: f32,
    /// Paint roughness.
    pub roughness: f32,
    /// Paint clear coat.
    pub clearcoat: f32,
    /// Specular level of the paint.
    pub specular: f32,
    /// What camera rays see where they hit no geometry (sRGB in [0, 1]); the environment then
    /// only lights the scene. None: the environment is seen.
    pub backdrop: Option<[f32; 3]>,
    /// Render only the centre this many rows of the square image (a landscape frame cut from
    /// it), so rows the frame drops cost nothing.
    pub rows: Option<usize>,
    /// A turntable top under the car (a matte disc at the ground height that catches the
    /// car's shadow and turns with it).
    pub table: Option<TableTop>,
    /// "Linear" or "Closest" texture lookups.
    pub interpolation: String,
    /// Raw 16-bit RGBA out, no view transform, every sample at its pixel's centre (for codes
    /// compared value by value; the uv mode always is).
    pub raw: bool,
    /// A transparent film: 8-bit RGBA out, the car opaque and its caught shadow as alpha over
    /// transparent black, for laying over a background plate.
    pub transparent: bool,
    /// Views.
    pub views: Vec<JobView>,
}

impl Job {
    /// A job with pav's defaults for `mode` on `mesh_obj` (whose lowest point is `ground_y`).
    pub fn new(mode: Mode, mesh_obj: PathBuf, size: usize, samples: u32, ground_y: f32) -> Job {
        Job {
            mode,
            mesh: mesh_obj,
            texture: None,
            tex_size: [1, 1],
            size,
            samples,
            environment: None,
            env_strength: 1.0,
            shadows: false,
            ground_y,
            ground_size: 40.0,
            metallic: 0.0,
            roughness: 1.0,
            clearcoat: 0.0,
            specular: 0.5,
            backdrop: None,
            table: None,
            rows: None,
            interpolation: "Linear".into(),
            raw: false,
            transparent: false,
            views: Vec::new(),
        }
    }
}

/// The last lines of an output stream, for an error message.
#[derive(Default)]
struct Tail(std::collections::VecDeque<String>);

impl Tail {
    fn push(&mut self, line: String) {
        self.0.push_back(line);
        if self.0.len() > 20 {
            self.0.pop_front();
        }
    }
}

/// The Blender executable.
pub struct Blender(PathBuf);

impl Blender {
    /// `blender` on the PATH (or `$PAV_BLENDER`), checked by running `blender --version`.
    pub fn find() -> Result<Blender, BlenderError> {
        let exe = std::env::var_os("PAV_BLENDER").map_or_else(|| PathBuf::from("blender"), PathBuf::from);
        match Command::new(&exe).arg("--version").stdout(Stdio::null()).stderr(Stdio::null()).status() {
            Ok(s) if s.success() => Ok(Blender(exe)),
            Ok(s) => Err(BlenderError::NotFound(format!("`{} --version` exited with {s}", exe.display()))),
            Err(e) => Err(BlenderError::NotFound(format!("{}: {e}", exe.display()))),
        }
    }

    /// The first line of `blender --version` (for `run.toml`).
    pub fn version(&self) -> Option<String> {
        pav_run::provenance::tool_version(&self.0.display().to_string(), &["--version"])
    }

    /// Whether this Blender was built with Cycles, the engine pav's views render with (on the
    /// CPU: the views script sets it), as Blender's Python reports it; `None` when Blender does
    /// not answer.
    pub fn has_cycles(&self) -> Option<bool> {
        let expr = "import bpy; print('PAV-CYCLES', bpy.app.build_options.cycles)";
        let out = Command::new(&self.0)
            .args(["-b", "--factory-startup", "-noaudio", "--python-expr", expr])
            .stderr(Stdio::null())
            .output()
            .ok()?;
        let text = String::from_utf8_lossy(&out.stdout);
        text.lines().find_map(|l| l.strip_prefix("PAV-CYCLES ")).map(|v| v.trim() == "True")
    }

    /// Runs `job` in one Blender process (files in `work`); `done(name, seconds)` is called as
    /// each view is written.
    pub fn run(&self, job: &Job, work: &Path, mut done: impl FnMut(&str, f64)) -> Result<(), BlenderError> {
        std::fs::create_dir_all(work).map_err(io(work))?;
        let script = work.join("blender_views.py");
        std::fs::write(&script, SCRIPT).map_err(io(&script))?;
        let job_path = work.join(format!("job-{}.json", std::process::id()));
        let json = serde_json::to_string_pretty(job).expect("a job serializes");
        std::fs::write(&job_path, json).map_err(io(&job_path))?;
        let mut child = Command::new(&self.0)
            .args(["-b", "--factory-startup", "-noaudio", "-P"])
            .arg(&script)
            .arg("--")
            .arg(&job_path)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| BlenderError::NotFound(format!("{}: {e}", self.0.display())))?;
        let stderr = child.stderr.take().expect("piped");
        let err_thread = std::thread::spawn(move || {
            let mut tail = Tail::default();
            BufReader::new(stderr).lines().map_while(Result::ok).for_each(|l| tail.push(l));
            tail
        });
        let mut tail = Tail::default();
        for l in BufReader::new(child.stdout.take().expect("piped")).lines().map_while(Result::ok) {
            if let Some(rest) = l.strip_prefix("pav-view ") {
                if let Some((name, secs)) = rest.rsplit_once(' ') {
                    done(name, secs.parse().unwrap_or(f64::NAN));
                    continue;
                }
            }
            tail.push(l);
        }
        let status = child.wait().map_err(io(&self.0))?;
        let _ = std::fs::remove_file(&job_path);
        if !status.success() {
            let mut t: Vec<String> = tail.0.into_iter().collect();
            t.extend(err_thread.join().unwrap_or_default().0);
            return Err(BlenderError::Failed {
                what: format!("{} views", job.views.len()),
                code: status.code(),
                tail: t.join("\n"),
            });
        }
        Ok(())
    }
}
