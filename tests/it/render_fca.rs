//! The renderer against real FCA data: the Audi e-tron seen through the FCA camera convention
//! must overlap the car masks FCA rendered for its CARLA test samples.

use crate::common;

use pav::dataset::fca::CarlaSample;
use pav::geometry::camera::fca;
use pav::geometry::mesh::Mesh;
use pav::render::raster::{GBuffer, EMPTY};

/// IoU of the mesh's silhouette with FCA's car mask for each of the ten test samples.
fn silhouette_ious(shared: &std::path::Path, mut mesh: Mesh) -> Vec<f32> {
    mesh.normalize_bbox();
    let mut ious = Vec::new();
    for n in 12501..=12510 {
        let s = CarlaSample::load(&shared.join(format!("fca/carla_dataset/test/data{n}.npz"))).unwrap();
        let g = GBuffer::render(&mesh, &fca(s.cam_trans, s.veh_trans), 608);
        let mask = image::open(shared.join(format!("fca/carla_dataset/masks/data{n}.png"))).unwrap().to_luma8();
        let (mut inter, mut union) = (0u32, 0u32);
        for (i, px) in mask.pixels().enumerate() {
            let (a, b) = (g.face[i] != EMPTY, px[0] > 127);
            inter += (a && b) as u32;
            union += (a || b) as u32;
        }
        ious.push(inter as f32 / union as f32);
    }
    ious
}

#[test]
fn audi_silhouettes_overlap_the_fca_masks() {
    let shared = common::shared_data();
    let mesh = Mesh::load_obj(&shared.join("fca/audi_et_te.obj")).unwrap();
    assert_eq!((mesh.positions.len(), mesh.faces.len()), (13449, 23145));
    let ious = silhouette_ious(&shared, mesh);
    eprintln!("silhouette IoU per sample: {ious:.3?}");
    // Stated bound: every sample ≥ 0.90 (measured 0.93–0.95 with the fitted origin lift; 0.78–0.91
    // without it).
    assert!(ious.iter().all(|v| *v >= 0.90), "{ious:?}");
}

/// The optimizer textures RAUCA-E2E's re-unwrapped e-tron (metres, centred, its own UVs): after
/// neural_renderer's normalization it must be the very same shape as FCA's mesh.
#[test]
fn uv_mapped_etron_is_the_fca_audi() {
    let shared = common::shared_data();
    let fca_mesh = Mesh::load_obj(&shared.join("fca/audi_et_te.obj")).unwrap();
    let etron = Mesh::load_obj(&shared.join("rauca-e2e/pytorch3d_Etron.obj")).unwrap();
    assert_eq!(etron.faces.len(), fca_mesh.faces.len());
    let (a, b) = (silhouette_ious(&shared, fca_mesh), silhouette_ious(&shared, etron));
    for (x, y) in a.iter().zip(&b) {
        assert!((x - y).abs() < 2e-3, "FCA mesh {a:?} vs e-tron {b:?}");
    }
}

/// `mesh.parts` (configs/studies/half.toml: doors and roof-like faces) cuts the e-tron's body
/// region down to a strict subset that every FCA view still sees.
#[test]
fn a_parts_region_is_a_visible_subset_of_the_body() {
    use pav::attack::config::OptimizeConfig;
    use pav::attack::setup::Setup;
    common::shared_data();
    let load = |name: &str| {
        let cfg = OptimizeConfig::load(&common::repo().join("configs").join(name)).unwrap();
        Setup::load(&cfg, Some(128)).unwrap_or_else(|e| panic!("{name}: {e}"))
    };
    let (full, half) = (load("optimize/paper.toml"), load("studies/half.toml"));
    assert!(half.region.iter().zip(&full.region).all(|(h, f)| *h <= *f), "not a subset");
    let share = half.region_values.len() as f64 / full.region_values.len() as f64;
    // Measured: 0.75 (the bumpers, the fender ends and the front and rear faces drop out).
    assert!((0.5..0.9).contains(&share), "{share}");
    assert!(half.train.iter().chain(&half.test).all(|v| !v.active.is_empty()));
}

/// The silhouette cannot tell a camera from its mirror image (the car is symmetric outside), so
/// the handedness is checked on what is not symmetric: the e-tron's steering wheel. The mesh is
/// left-hand drive with +X forward (the low hood end), so the wheel sits at +Y; data12501's camera
/// stands on the car's left in CARLA (offset against the vehicle's right vector), so its eye must
/// be at +Y, on the wheel's side, and the front must still come out on the image's left as in the
/// photo.
#[test]
fn the_camera_stands_on_the_side_the_photo_shows() {
    let shared = common::shared_data();
    let mesh = Mesh::load_obj(&shared.join("fca/audi_et_te.obj")).unwrap();
    let exterior: std::collections::HashSet<usize> = std::fs::read_to_string(shared.join("fca/exterior_face.txt"))
        .unwrap()
        .split_whitespace()
        .map(|t| t.parse::<usize>().unwrap() - 1)
        .collect();
    // Interior faces just behind the windshield's foot (x 30–45 in the OBJ's units).
    let (mut left, mut right) = (0, 0);
    for f in (0..mesh.faces.len()).filter(|f| !exterior.contains(f)) {
        let c = mesh.face_centroid(f);
        if (30.0..45.0).contains(&c[0]) {
            if c[1] > 0.0 {
                left += 1
            } else {
                right += 1
            }
        }
    }
    // Measured: 801 vs 236; everywhere else inside the car the halves match within 20 %.
    assert!(left > 3 * right, "dashboard faces at +Y {left}, at −Y {right}");
    let s = CarlaSample::load(&shared.join("fca/carla_dataset/test/data12501.npz")).unwrap();
    let yaw = s.veh_trans[1][1].to_radians();
    let carla_right = [-yaw.sin(), yaw.cos()];
    assert!(
        s.cam_trans[0][0] * carla_right[0] + s.cam_trans[0][1] * carla_right[1] < -1.0,
        "data12501 looks at the left"
    );
    let mut normalized = mesh.clone();
    normalized.normalize_bbox();
    let cam = fca(s.cam_trans, s.veh_trans);
    assert!(cam.eye[1] > 0.5, "eye {:?}", cam.eye);
    let (nlo, nhi) = normalized.bounds();
    let front = [nhi[0], 0.0, 0.5 * (nlo[2] + nhi[2])];
    let back = [nlo[0], 0.0, 0.5 * (nlo[2] + nhi[2])];
    let (pf, pb) = (cam.to_pixel(cam.to_view(front), 608), cam.to_pixel(cam.to_view(back), 608));
    assert!(pf[0] < 304.0 && pb[0] > 304.0, "front at {pf:?}, back at {pb:?}");
}
