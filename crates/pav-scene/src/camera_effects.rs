//! What a rig's camera does to a rendered frame, the same for both simulated turntables: the room
//! seen behind the model (table top or backdrop, with its depth), and the camera effects a rig
//! lists (defocus, motion blur, sensor noise; the codec is the video writer's). Each effect runs
//! only when the rig lists it, on a square render of the frame's larger side before it is cut
//! to the frame, with the model's depth from pav's rasterizer (the same camera as Blender's).

use super::rig::{CameraEffect, RigConfig, Shot};
use pav_core::geometry::camera::Camera;
use pav_core::geometry::mesh::Mesh;
use pav_core::image::Frame;
use pav_core::rng::Rng;
use pav_render::raster::{GBuffer, EMPTY};

/// What a pixel's ray meets when it misses the model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Behind {
    /// The table top, at this view depth (normalized units).
    Table(f32),
    /// The backdrop, at this view depth.
    Backdrop(f32),
}

/// The view-space ray through pixel centre `(x, y)` of a `side × side` render: `(x', y', 1)`,
/// so a hit's parameter along it is its view depth.
fn ray(cam: &Camera, side: usize, x: usize, y: usize) -> [f32; 3] {
    let t = (cam.fov_deg.to_radians() / 2.0).tan();
    let s = side as f32 / 2.0;
    let vx = (1.0 - (x as f32 + 0.5) / s) * t;
    let vy = (1.0 - (y as f32 + 0.5) / s) * t;
    let a = cam.axes;
    [0, 1, 2].map(|k| a[0][k] * vx + a[1][k] * vy + a[2][k])
}

/// What pixel `(x, y)` sees behind the model: the table top where its ray meets the disc, else
/// the backdrop, a wall square to the camera's horizontal direction behind the table's axis.
pub fn behind(rig: &RigConfig, shot: &Shot, cam: &Camera, side: usize, x: usize, y: usize) -> Behind {
    let d = ray(cam, side, x, y);
    let e = cam.eye;
    let u = shot.units_per_m;
    if d[1] < 0.0 {
        let s = (shot.ground_y - e[1]) / d[1];
        let (px, pz) = (e[0] + s * d[0], e[2] + s * d[2]);
        let r = rig.table.radius_m as f32 * u;
        if px * px + pz * pz <= r * r {
            return Behind::Table(s);
        }
    }
    let h = (e[0] * e[0] + e[2] * e[2]).sqrt().max(1e-6);
    let f = [-e[0] / h, -e[2] / h];
    let along = (d[0] * f[0] + d[2] * f[1]).max(1e-3);
    Behind::Backdrop((h + rig.room.backdrop_m as f32 * u) / along)
}

/// Per pixel of a `side × side` render: the view depth in metres, of the model where `g`
/// covers it, else of what lies behind it.
pub fn depth_m(rig: &RigConfig, shot: &Shot, cam: &Camera, g: &GBuffer) -> Vec<f32> {
    let side = g.size;
    let u = shot.units_per_m;
    (0..side * side)
        .map(|i| {
            let z = if g.face[i] == EMPTY {
                match behind(rig, shot, cam, side, i % side, i / side) {
                    Behind::Table(z) | Behind::Backdrop(z) => z,
                }
            } else {
                g.depth[i]
            };
            z / u
        })
        .collect()
}

/// Thin-lens circle of confusion, diameter in pixels of a frame `width` wide, of a point at
/// view depth `z_m` when the lens focuses at `focus_m`.
pub fn circle_of_confusion_px(rig: &RigConfig, focus_m: f64, z_m: f64, width: usize) -> f64 {
    let (Some(f_mm), Some([sw, _])) = (rig.camera.focal_mm, rig.camera.sensor_mm) else { return 0.0 };
    let (f, s, z) = (f_mm, focus_m * 1000.0, z_m * 1000.0);
    let c_mm = f * f / (rig.camera.f_number * (s - f)) * (z - s).abs() / z;
    c_mm / sw * width as f64
}

/// Bilinear sample of channel `c` of a `side × side` RGB image at `(x, y)` (pixel centres at
/// half-integers), clamped to the edge.
fn sample(rgb: &[f32], side: usize, x: f32, y: f32, c: usize) -> f32 {
    let (x, y) = ((x - 0.5).clamp(0.0, side as f32 - 1.0), (y - 0.5).clamp(0.0, side as f32 - 1.0));
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(side - 1), (y0 + 1).min(side - 1));
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let at = |x: usize, y: usize| rgb[3 * (y * side + x) + c];
    (at(x0, y0) * (1.0 - fx) + at(x1, y0) * fx) * (1.0 - fy) + (at(x0, y1) * (1.0 - fx) + at(x1, y1) * fx) * fy
}

/// Blurs each pixel over a disc of its circle of confusion (a gather: every pixel averages
/// its own disc, so the blur follows the depth under it). The disc is sampled on rings,
/// bilinearly, so a circle smaller than a pixel still blurs by its share.
fn defocus(rgb: &mut [f32], side: usize, coc_px: &[f32]) {
    let src = rgb.to_vec();
    for i in 0..side * side {
        let r = (coc_px[i] / 2.0).min(24.0);
        if r < 0.05 {
            continue;
        }
        let (cx, cy) = ((i % side) as f32 + 0.5, (i / side) as f32 + 0.5);
        let rings = r.ceil() as usize;
        let mut acc = [0.0f32; 3];
        let mut w = 0.0;
        let mut add = |x: f32, y: f32, weight: f32| {
            for (c, a) in acc.iter_mut().enumerate() {
                *a += weight * sample(&src, side, x, y, c);
            }
            w += weight;
        };
        // The centre stands for the disc inside the first ring's half radius.
        let first = r / rings as f32;
        add(cx, cy, std::f32::consts::PI * (first / 2.0).powi(2));
        for k in 1..=rings {
            let rho = r * k as f32 / rings as f32;
            let n = 6 * k;
            // Each ring stands for the annulus around it, shared among its samples.
            let (inner, outer) = (rho - first / 2.0, (rho + first / 2.0).min(r));
            let weight = std::f32::consts::PI * (outer * outer - inner * inner) / n as f32;
            for j in 0..n {
                let t = std::f32::consts::TAU * j as f32 / n as f32;
                add(cx + rho * t.cos(), cy + rho * t.sin(), weight);
            }
        }
        for c in 0..3 {
            rgb[3 * i + c] = acc[c] / w;
        }
    }
}

/// Averages each model pixel along the path its surface point travels on screen while the
/// table turns by `turn_rad` during the exposure (centred on the frame's instant).
fn motion_blur(rgb: &mut [f32], g: &GBuffer, cam: &Camera, turn_rad: f32) {
    let side = g.size;
    let src = rgb.to_vec();
    let (sn, cs) = turn_rad.sin_cos();
    for i in 0..side * side {
        if g.face[i] == EMPTY {
            continue;
        }
        let (x, y) = (i % side, i / side);
        // The pixel's ray reaches the surface at its view depth.
        let (d, z) = (ray(cam, side, x, y), g.depth[i]);
        let p = [0, 1, 2].map(|k| cam.eye[k] + z * d[k]);
        // The table's axis is pav's +Y through the origin.
        let q = [p[0] * cs + p[2] * sn, p[1], -p[0] * sn + p[2] * cs];
        let [qx, qy] = cam.to_pixel(cam.to_view(q), side);
        let (dx, dy) = (qx - (x as f32 + 0.5), qy - (y as f32 + 0.5));
        let len = (dx * dx + dy * dy).sqrt();
        if len < 0.25 {
            continue;
        }
        let taps = (2.0 * len).ceil() as usize + 1;
        let mut acc = [0.0f32; 3];
        for k in 0..taps {
            let f = k as f32 / (taps - 1) as f32 - 0.5;
            for (c, a) in acc.iter_mut().enumerate() {
                *a += sample(&src, side, x as f32 + 0.5 + f * dx, y as f32 + 0.5 + f * dy, c);
            }
        }
        for c in 0..3 {
            rgb[3 * i + c] = acc[c] / taps as f32;
        }
    }
}

/// The camera's development of a square RGB render in [0, 1] of the model at `cam` (side `side`)
/// into a `size` frame, in the order a camera works: the optics the rig lists, the cut to the
/// frame, the automatic exposure (when listed, and `auto_exposure`: a real camera's locked
/// exposure has none), the sensor noise drawn from `seed` ([`noise_seed`]). Both simulated
/// turntables develop their frames here, so an effect added to it reaches both; the codec is
/// the video writer's ([`codec_kbps`]).
#[allow(clippy::too_many_arguments)]
pub fn develop(
    rig: &RigConfig,
    shot: &Shot,
    mesh: &Mesh,
    cam: &Camera,
    rgb: &mut [f32],
    side: usize,
    size: (usize, usize),
    auto_exposure: bool,
    seed: u64,
) -> Frame {
    apply_optics(rig, shot, mesh, cam, rgb, side);
    let mut frame = cut(rgb, side, size);
    if auto_exposure {
        apply_auto_exposure(rig, &mut frame);
    }
    apply_noise(rig, &mut frame, seed);
    frame
}

/// The optical effects the rig lists, on a square RGB render in [0, 1] of the model at `cam`
/// (defocus, then motion blur); unlisted ones leave it untouched.
pub fn apply_optics(rig: &RigConfig, shot: &Shot, mesh: &Mesh, cam: &Camera, rgb: &mut [f32], side: usize) {
    let defocus_on = rig.has(CameraEffect::Defocus);
    let blur_on = rig.has(CameraEffect::MotionBlur);
    if !(defocus_on || blur_on) {
        return;
    }
    let g = GBuffer::render(mesh, cam, side);
    if defocus_on {
        let to_target = pav_core::geometry::vec3::sub(shot.target, cam.eye);
        let focus = rig.camera.focus_m.unwrap_or_else(|| {
            f64::from(pav_core::geometry::vec3::dot(to_target, to_target).sqrt() / shot.units_per_m)
        });
        let coc: Vec<f32> = depth_m(rig, shot, cam, &g)
            .iter()
            .map(|&z| circle_of_confusion_px(rig, focus, f64::from(z), shot.size.0) as f32)
            .collect();
        defocus(rgb, side, &coc);
    }
    if blur_on {
        let turn = (std::f64::consts::TAU * rig.camera.exposure_s / rig.table.period_s) as f32;
        motion_blur(rgb, &g, cam, turn);
    }
}

/// The centre `width × height` of a square RGB render in [0, 1], as an 8-bit BGR frame.
pub fn cut(rgb: &[f32], side: usize, (width, height): (usize, usize)) -> Frame {
    let (x0, y0) = ((side - width) / 2, (side - height) / 2);
    let mut bgr = Vec::with_capacity(width * height * 3);
    for y in y0..y0 + height {
        for x in x0..x0 + width {
            let p = &rgb[3 * (y * side + x)..3 * (y * side + x) + 3];
            bgr.extend([pav_core::image::to_u8(p[2]), pav_core::image::to_u8(p[1]), pav_core::image::to_u8(p[0])]);
        }
    }
    Frame { width, height, bgr }
}

/// An automatic exposure on an 8-bit frame when the rig lists it: every level scaled by
/// `(128 / m)^s`, `m` the mean level of the frame's central half (centre-weighted metering, as
/// webcams meter, where the car stands) and `s` the rig's `camera.auto_exposure`, so that a
/// frame the car darkens is brightened, background and all, as a webcam's exposure follows the
/// car. Applied before the sensor noise, as an exposure change is.
pub fn apply_auto_exposure(rig: &RigConfig, frame: &mut Frame) {
    if !rig.has(CameraEffect::AutoExposure) || frame.bgr.is_empty() {
        return;
    }
    let (w, h) = (frame.width, frame.height);
    let (mut sum, mut n) = (0f64, 0usize);
    for y in h / 4..(3 * h / 4).max(h / 4 + 1) {
        for v in &frame.bgr[(y * w + w / 4) * 3..(y * w + (3 * w / 4).max(w / 4 + 1)) * 3] {
            sum += f64::from(*v);
            n += 1;
        }
    }
    let mean = sum / n.max(1) as f64;
    let gain = (128.0 / mean.max(1.0)).powf(rig.camera.auto_exposure) as f32;
    for v in &mut frame.bgr {
        *v = (f32::from(*v) * gain).round().clamp(0.0, 255.0) as u8;
    }
}

/// Sensor noise on an 8-bit frame when the rig lists it: a level `v` gets Gaussian noise of
/// variance `read² + shot_gain · v`, drawn from `seed` (the frame's index keeps frames apart).
pub fn apply_noise(rig: &RigConfig, frame: &mut Frame, seed: u64) {
    if !rig.has(CameraEffect::Noise) {
        return;
    }
    let mut rng = Rng::new(seed);
    let (r2, k) = ((rig.camera.read_noise * rig.camera.read_noise) as f32, rig.camera.shot_gain as f32);
    for v in &mut frame.bgr {
        let x = f32::from(*v);
        *v = (x + (r2 + k * x).sqrt() * rng.normal()).round().clamp(0.0, 255.0) as u8;
    }
}

/// The noise draw of the frame at table angle `angle_deg` (in [0, 360)) from camera elevation
/// `elevation_deg`: the same frame gets the same noise from either back-end.
pub fn noise_seed(angle_deg: f32, elevation_deg: f32) -> u64 {
    pav_core::rng::fnv1a([u64::from(angle_deg.to_bits()), u64::from(elevation_deg.to_bits())])
}

/// The H.264 bitrate for the simulated frames when the rig lists the codec: the capture's
/// bits per pixel at the simulation's size, kbit/s.
pub fn codec_kbps(rig: &RigConfig) -> Option<f64> {
    rig.has(CameraEffect::Codec).then(|| {
        let (w, h) = rig.frame_size();
        rig.camera.bitrate_kbps * (w * h) as f64 / (rig.camera.width * rig.camera.height) as f64
    })
}
