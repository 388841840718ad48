//! The renderer against real FCA data: the Audi e-tron seen through the FCA camera convention
//! must overlap the car masks FCA rendered for its CARLA test samples.

mod common;

use pav::dataset::fca::CarlaSample;
use pav::geometry::camera::fca;
use pav::geometry::mesh::Mesh;
use pav::render::raster::{GBuffer, EMPTY};

#[test]
fn audi_silhouettes_overlap_the_fca_masks() {
    let Some(shared) = common::shared_data() else {
        return;
    };
    let mut mesh = Mesh::load_obj(&shared.join("fca/audi_et_te.obj")).unwrap();
    assert_eq!((mesh.positions.len(), mesh.faces.len()), (13449, 23145));
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
    eprintln!("silhouette IoU per sample: {ious:.3?}");
    // Stated bound: every sample ≥ 0.75 (measured 0.78–0.91). The remaining gap is mostly a
    // vertical offset of about 8 px whose source in FCA's renderer is not yet identified.
    assert!(ious.iter().all(|v| *v >= 0.75), "{ious:?}");
}
