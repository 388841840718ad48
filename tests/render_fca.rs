//! The renderer against real FCA data: the Audi e-tron seen through the FCA camera convention
//! must overlap the car masks FCA rendered for its CARLA test samples.

mod common;

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

/// `mesh.parts` (configs/optimize/half.toml: doors and roof-like faces) cuts the e-tron's body
/// region down to a strict subset that every FCA view still sees.
#[test]
fn a_parts_region_is_a_visible_subset_of_the_body() {
    use pav::attack::config::OptimizeConfig;
    use pav::attack::setup::Setup;
    common::shared_data();
    let load = |name: &str| {
        let cfg = OptimizeConfig::load(&common::repo().join("configs/optimize").join(name)).unwrap();
        Setup::load(&cfg, Some(128)).unwrap_or_else(|e| panic!("{name}: {e}"))
    };
    let (full, half) = (load("paper.toml"), load("half.toml"));
    assert!(half.region.iter().zip(&full.region).all(|(h, f)| *h <= *f), "not a subset");
    let share = half.region_values.len() as f64 / full.region_values.len() as f64;
    // Measured: 0.75 (the bumpers, the fender ends and the front and rear faces drop out).
    assert!((0.5..0.9).contains(&share), "{share}");
    assert!(half.train.iter().chain(&half.test).all(|v| !v.active.is_empty()));
}
