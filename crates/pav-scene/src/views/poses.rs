//! Which views a config makes: the pose grids and plates of each environment, in a fixed order.

use super::*;
use pav_core::geometry::camera::{moved_away, spherical, Camera};

impl ViewsConfig {
    /// Whether environment `name` draws any view (a grid or the plates take it).
    pub(super) fn draws(&self, name: &str) -> bool {
        self.poses.iter().any(|g| takes(&g.environments, name))
            || self.plates.as_ref().is_some_and(|p| takes(&p.environments, name))
    }

    /// Every view of the config, in a fixed order: environments, then grids, distances,
    /// elevations, azimuths.
    pub fn views(&self) -> Vec<View> {
        let mut out = Vec::new();
        for ei in 0..self.environments.len() {
            let env_name = self.environment_name(ei);
            for g in self.poses.iter().filter(|g| takes(&g.environments, &env_name)) {
                let mut az = g.azimuths.clone();
                if let Some(step) = g.azimuth_step {
                    az.extend((0..).map(|k| k as f32 * step).take_while(|a| *a < 360.0 - 1e-3));
                }
                for &d in &g.distances {
                    for &e in &g.elevations {
                        for &a in &az {
                            let name = format!("{env_name}_d{d:.2}_e{e:.0}_a{a:05.1}");
                            let eye = spherical(d, e, a);
                            let eye = [eye[0] + g.target[0], eye[1] + g.target[1], eye[2] + g.target[2]];
                            let camera = Camera::look_at(eye, g.target, [0.0, 1.0, 0.0], g.fov_deg);
                            let env_turn_deg = if self.render.turntable { a } else { 0.0 };
                            out.push(View {
                                name,
                                environment: ei,
                                pose: [d, e, a],
                                target: g.target,
                                camera,
                                env_turn_deg,
                                plate: None,
                            });
                        }
                    }
                }
            }
            out.extend(self.plate_views(ei));
        }
        out
    }

    /// The camera of plate `pi` with the car turned by `turn` degrees and moved away to
    /// `distance` times its distance, in pav's frame.
    pub fn plate_camera(&self, pi: usize, turn: f32, distance: f32) -> Camera {
        let pl = self.plates.as_ref().expect("plate_camera needs plates");
        let r = up_rotation(&self.mesh.up).expect("checked by load");
        let [cam, veh] = pl.poses[pi];
        let c = pl.camera.camera(moved_away(cam, distance as f64), veh, turn as f64);
        Camera { axes: c.axes.map(|a| rotate(&r, a)), eye: rotate(&r, c.eye), ..c }
    }

    /// The plate views in environment `ei`: every photo, every turn and distance, at the photo's
    /// camera. A view at distance 1 keeps the name it had before distances existed, so renders resume.
    fn plate_views(&self, ei: usize) -> Vec<View> {
        let Some(pl) = &self.plates else { return Vec::new() };
        let env_name = self.environment_name(ei);
        if !takes(&pl.environments, &env_name) {
            return Vec::new();
        }
        let mut out = Vec::new();
        for (pi, photo) in pl.photos.iter().enumerate() {
            let stem = photo.file_stem().map_or_else(|| format!("plate{pi}"), |s| s.to_string_lossy().into());
            for (&dist, &turn) in pl.distances.iter().flat_map(|d| pl.turns.iter().map(move |t| (d, t))) {
                let camera = self.plate_camera(pi, turn, dist);
                let e = camera.eye;
                let d = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt();
                // A look-at point on the optical axis, as far as the car's centre.
                let target = [0, 1, 2].map(|k| e[k] + camera.axes[2][k] * d);
                out.push(View {
                    name: if dist == 1.0 {
                        format!("{env_name}_{stem}_t{turn:+.0}")
                    } else {
                        format!("{env_name}_{stem}_t{turn:+.0}_d{dist:.2}")
                    },
                    environment: ei,
                    pose: [d, (e[1] / d).asin().to_degrees(), e[0].atan2(e[2]).to_degrees().rem_euclid(360.0)],
                    target,
                    camera,
                    env_turn_deg: 0.0,
                    plate: Some(pi),
                });
            }
        }
        out
    }
}
