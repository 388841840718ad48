//! Physically based training and test views rendered by Blender Cycles, run headless.
//!
//! pav computes every camera itself ([`pav_core::geometry::camera`]) and hands Blender the mesh
//! already in its own world frame, so the two renderers share one camera convention by
//! construction; [`super::align`] checks that they agree to the pixel. A config lists the mesh,
//! the pose grid, the environments and the effects; only listed effects are simulated.
//!
//! ```toml
//! [mesh]
//! obj = "data:pav-camou/xfl_yxz.obj"
//! normalize = "pav"            # PAV-Camou's (vertex mean, max-abs) or "bbox" (FCA/DAS)
//! up = "+y"                    # the file's up axis; pav's world is +Y up
//! texture = "paint.png"        # body texture; default: the mesh's first map_Kd
//!
//! [render]
//! size = 416
//! samples = 32
//! effects = ["shadows"]        # "shadows" (a shadow-catcher ground), "reflections" (clear coat)
//!
//! [[environments]]             # a Blender studio light by name, or an .exr/.hdr path
//! name = "city"
//!
//! [[poses]]                    # distances in normalized mesh units, angles in degrees
//! distances = [2.2]
//! elevations = [10, 30]
//! azimuth_step = 90            # or azimuths = [...]
//!
//! [plates]                     # and/or: the car over real photos with their car painted out
//! photos = ["data:fca/carla_dataset/train/data1.npz"]
//! camera = "fca"               # the convention that fits the mesh to the photos' CARLA poses
//! turns = [-30, 0, 30]         # the car turned in place on the plate's ground, degrees
//! distances = [1.0, 1.4]       # and moved away along it (× the camera's distance; default [1])
//! ```
//!
//! A grid or the plates may name `environments = ["courtyard"]`: only those of the config's
//! environments draw it (by default all do), so one config mixes kinds of views.
//!
//! A plate view is Cycles' car with its caught shadow on a transparent film (`<name>_car.png`),
//! laid over the photo's [`pav_render::bake::Plate`] at the photo's own camera with the car
//! turned, so background, camera and ground are real and only the car is rendered. The
//! environment then only lights the car; the photo's own car shadow stays on the plate.

use super::blender::BlenderError;
use pav_core::geometry::mesh::MeshError;
use pav_run::shard::ShardError;
use std::path::{Path, PathBuf};

mod config;
mod manifest;
mod merge;
mod poses;
mod render;

// The siblings' `pub(super)` helpers (rotate, takes, append_row, …) come through these globs too.
pub use config::*;
pub use manifest::*;
pub use merge::*;
pub use render::*;

/// Where Debian's `blender` package puts its HDR environments.
pub const STUDIO_LIGHTS: &str = "/usr/share/blender/datafiles/studiolights/world";

/// The studio lights Blender ships, by name.
pub const STUDIO_LIGHT_NAMES: &[&str] =
    &["city", "courtyard", "forest", "interior", "night", "studio", "sunrise", "sunset"];

/// Errors making views.
#[derive(Debug, thiserror::Error)]
pub enum ViewsError {
    /// The config file could not be read or parsed.
    #[error("{path}: {msg}")]
    Config {
        /// Config file.
        path: PathBuf,
        /// What is wrong.
        msg: String,
    },
    /// The mesh could not be used.
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// Blender could not render.
    #[error(transparent)]
    Blender(#[from] BlenderError),
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// An image could not be written.
    #[error(transparent)]
    Image(#[from] pav_core::image::ImageError),
    /// A turntable video could not be written.
    #[cfg(feature = "video")]
    #[error(transparent)]
    Video(#[from] pav_core::video::VideoError),
    /// Its angle sidecar could not be written.
    #[error(transparent)]
    Sidecar(#[from] pav_core::sidecar::SidecarError),
    /// Shards of a view set that cannot be joined.
    #[error(transparent)]
    Shard(#[from] ShardError),
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> ViewsError + '_ {
    move |source| ViewsError::Io { path: path.into(), source }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pav_core::geometry::camera::CameraConvention;
    use std::collections::HashSet;

    /// The workspace root, where `configs/` lives.
    fn repo() -> &'static Path {
        Path::new(env!("CARGO_MANIFEST_DIR")).parent().and_then(Path::parent).unwrap()
    }

    fn shipped(name: &str) -> ViewsConfig {
        ViewsConfig::load(&repo().join("configs/views").join(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
    }

    #[test]
    fn shipped_configs_give_the_views_they_promise() {
        assert_eq!(shipped("ci.toml").views().len(), 6);
        assert_eq!(shipped("etron-64.toml").views().len(), 64);
        // Plates: 2 environments × 11 photos × 5 turns, each at its photo's camera.
        let plates = shipped("etron-plates.toml");
        let views = plates.views();
        assert_eq!(views.len(), 110);
        assert!(views.iter().all(|v| v.plate.is_some()));
        let (a, b) = (&views[0].camera, &plates.plate_camera(0, -40.0, 1.0));
        assert_eq!((a.eye, a.axes), (b.eye, b.axes));
        // The paper's grid: 4 distances × (3 elevations × 20 azimuths + 2 × 8) per environment.
        let grid = shipped("paper-grid.toml");
        assert_eq!(grid.views().len(), 304 * grid.environments.len());
        let v = &grid.views()[0];
        // A camera on the grid looks at the target from its distance.
        let d = v.camera.to_view(v.target);
        assert!(d[0].abs() < 1e-4 && d[1].abs() < 1e-4 && (d[2] - v.pose[0]).abs() < 1e-4, "{d:?}");
    }

    #[test]
    fn grids_and_plates_draw_only_the_environments_they_name() {
        let scale = shipped("scale.toml");
        let views = scale.views();
        // 2 environments × 3 distances × 4 elevations × 36 azimuths; 4 × 6 photos × 3 × 31 turns.
        assert_eq!(views.len(), 864 + 2232);
        let env = |v: &View| scale.environment_name(v.environment);
        assert!(views
            .iter()
            .filter(|v| v.plate.is_none())
            .all(|v| ["courtyard", "interior"].contains(&env(v).as_str())));
        assert_eq!(views.iter().filter(|v| v.plate.is_some() && env(v) == "city").count(), 558);
        // No view of the held-out set is among them.
        let held: HashSet<String> = shipped("heldout.toml").views().into_iter().map(|v| v.name).collect();
        assert!(views.iter().all(|v| !held.contains(&v.name)));
        let mut typo = scale.clone();
        typo.poses[0].environments = vec!["courtyrd".into()];
        let e = typo.check().unwrap_err();
        assert!(e.contains("poses #1: environment `courtyrd` is not among"), "{e}");
        let mut idle = scale.clone();
        idle.plates.as_mut().unwrap().environments = vec!["courtyard".into()];
        let e = idle.check().unwrap_err();
        assert!(e.contains("environment `city` draws no view"), "{e}");
    }

    #[test]
    fn a_manifest_from_before_the_plate_column_reads_and_is_brought_up_to_date() {
        let dir = tempfile::tempdir().unwrap();
        let old_header = MANIFEST_HEADER.trim_end_matches(",plate");
        let row = "v1,city,views/v1.png,views/v1_mask.png,2.2,15,0,0,1,2,0,0,0,0,1,0,60,64,4,1.5";
        let manifest = dir.path().join("manifest.csv");
        std::fs::write(&manifest, format!("{old_header}\n{row}\n")).unwrap();
        std::fs::create_dir_all(dir.path().join("views")).unwrap();
        std::fs::write(dir.path().join("views/v1.png"), b"").unwrap();
        let done = rendered(&manifest, dir.path()).unwrap();
        assert!(done.contains("v1"));
        let text = std::fs::read_to_string(&manifest).unwrap();
        assert_eq!(text.lines().next(), Some(MANIFEST_HEADER));
        let rows = read_manifest(&manifest).unwrap();
        assert_eq!((rows.len(), rows[0].plate.as_str(), rows[0].seconds), (1, "", 1.5));
    }

    #[test]
    fn a_view_set_whose_render_did_not_finish_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("views.toml"), "obj = \"m.obj\"\nnormalize = \"bbox\"\nup = \"+y\"\n").unwrap();
        let row = "v1,city,views/v1.png,views/v1_mask.png,2.2,15,0,0,1,2,0,0,0,0,1,0,60,64,4,1.5,";
        std::fs::write(manifest_path(dir.path()), format!("{MANIFEST_HEADER}\n{row}\n")).unwrap();
        assert_eq!(read_view_set(dir.path()).unwrap().1.len(), 1);
        // A stopped render leaves its marker: the one view written is not the set.
        std::fs::write(dir.path().join(UNFINISHED), "").unwrap();
        let e = read_view_set(dir.path()).unwrap_err().to_string();
        assert!(e.contains("has not finished") && e.contains("rerun"), "{e}");
    }

    #[test]
    fn plates_without_turns_or_unread_poses_are_refused() {
        let text = |turns: &str| {
            format!(
                "[mesh]\nobj = \"m.obj\"\n[render]\nsize = 64\nsamples = 1\n[[environments]]\nname = \"city\"\n\
                 [plates]\nphotos = [\"a.npz\"]\ncamera = \"fca\"\nturns = [{turns}]\n"
            )
        };
        let no_turns: ViewsConfig = toml::from_str(&text("")).unwrap();
        assert!(no_turns.check().unwrap_err().contains("one turn"));
        // Parsed but not loaded: the photos' poses were never read.
        let unread: ViewsConfig = toml::from_str(&text("0")).unwrap();
        assert!(unread.check().unwrap_err().contains("poses are not read"));
        let missing = tempfile::tempdir().unwrap();
        let path = missing.path().join("v.toml");
        std::fs::write(&path, text("0").replace("m.obj", "/dev/null")).unwrap();
        let e = ViewsConfig::load(&path).unwrap_err().to_string();
        assert!(e.contains("a.npz"), "{e}");
    }

    #[test]
    fn moved_plates_are_named_apart_and_drawn_from_the_same_camera() {
        let moved = shipped("etron-plates-moved.toml");
        let views = moved.views();
        // 2 environments × 11 photos × 2 distances × 3 turns.
        assert_eq!(views.len(), 132);
        assert_eq!(views.iter().map(|v| &v.name).collect::<HashSet<_>>().len(), 132);
        let v = views.iter().find(|v| v.name == "city_data12501_t+40_d1.40").expect("named by distance");
        let c = moved.plate_camera(1, 40.0, 1.4);
        assert_eq!((v.camera.eye, v.camera.axes), (c.eye, c.axes));
        // Moved away, the eye is farther and the camera still looks where the photo's did.
        let (near, far) = (moved.plate_camera(1, 40.0, 1.0), moved.plate_camera(1, 40.0, 1.4));
        let norm = |e: [f32; 3]| e.iter().map(|x| x * x).sum::<f32>().sqrt();
        assert!(norm(far.eye) > 1.3 * norm(near.eye));
        assert!(far.axes.iter().flatten().zip(near.axes.iter().flatten()).all(|(a, b)| (a - b).abs() < 1e-6));
        // Distance 1 keeps the names of etron-plates-wide.toml, so that folder is not redrawn.
        let mut one = moved.clone();
        one.plates.as_mut().unwrap().distances = vec![1.0];
        assert!(one
            .views()
            .iter()
            .all(|v| v.name.ends_with("_t-40") || v.name.ends_with("_t+0") || v.name.ends_with("_t+40")));
        // Factors out of range, or a convention whose camera cannot follow a moved car, are refused.
        for (d, conv, says) in
            [(0.5, CameraConvention::Fca, "0.7 to 3"), (1.4, CameraConvention::PavCamou, "need camera")]
        {
            let mut c = moved.clone();
            let pl = c.plates.as_mut().unwrap();
            (pl.distances, pl.camera) = (vec![d], conv);
            let e = c.check().unwrap_err();
            assert!(e.contains(says), "{e}");
        }
    }

    #[test]
    fn up_rotations_are_proper_and_bring_the_axis_up() {
        for (up, axis) in [
            ("+y", [0.0, 1.0, 0.0]),
            ("-y", [0.0, -1.0, 0.0]),
            ("+z", [0.0, 0.0, 1.0]),
            ("-z", [0.0, 0.0, -1.0]),
            ("+x", [1.0, 0.0, 0.0]),
            ("-x", [-1.0, 0.0, 0.0]),
        ] {
            let r = up_rotation(up).unwrap();
            let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
                - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
                + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
            assert_eq!(det, 1.0, "{up} mirrors");
            let y: Vec<f32> = (0..3).map(|k| r[k][0] * axis[0] + r[k][1] * axis[1] + r[k][2] * axis[2]).collect();
            assert_eq!(y, [0.0, 1.0, 0.0], "{up}");
            assert_eq!(unrotate(&r, [0.0, 1.0, 0.0]), axis, "{up}");
        }
        assert!(up_rotation("up").is_err());
    }
}
