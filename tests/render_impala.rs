//! The renderer on the real PAV-Camou Impala: the OBJ loads as the manifest describes, the
//! authors' normalization holds, and a render from a real CARLA pose shows the car with its
//! textured region exactly where half.png puts it.

mod common;

use pav::dataset::fca::CarlaSample;
use pav::geometry::camera::pav_camou;
use pav::geometry::mesh::Mesh;
use pav::render::raster::{GBuffer, EMPTY};
use pav::render::texture::{Gather, Texture};

#[test]
fn impala_renders_with_its_textured_region() {
    let Some(shared) = common::shared_data() else {
        return;
    };
    let mut mesh = Mesh::load_obj(&shared.join("pav-camou/xfl_yxz.obj")).unwrap();
    assert_eq!(
        (
            mesh.positions.len(),
            mesh.uvs.len(),
            mesh.normals.len(),
            mesh.faces.len()
        ),
        (5409, 5409, 14577, 4859)
    );
    assert_eq!(mesh.materials.len(), 11);
    let body = mesh
        .materials
        .iter()
        .find(|m| m.name.ends_with("SG9"))
        .unwrap()
        .clone();
    assert_eq!(
        body.map_kd.as_ref().unwrap().file_name().unwrap(),
        "half.png"
    );
    mesh.normalize();
    let maxabs = mesh
        .positions
        .iter()
        .flatten()
        .fold(0f32, |a, v| a.max(v.abs()));
    assert!((maxabs - 1.0).abs() < 1e-6);
    let mean: f64 =
        mesh.positions.iter().map(|p| p[1] as f64).sum::<f64>() / mesh.positions.len() as f64;
    assert!(mean.abs() < 1e-5);

    // half.png: pure white = optimizable (24.8 % of the atlas per the manifest).
    let tex = Texture::load(&body.map_kd.clone().unwrap()).unwrap();
    let white: Vec<f32> = tex
        .rgb
        .chunks(3)
        .map(|c| {
            if c.iter().all(|v| *v == 1.0) {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    let share = white.iter().sum::<f32>() / white.len() as f32;
    assert!((share - 0.248).abs() < 0.001, "{share}");

    // A real CARLA pose (5 m, pitch −22.5°, side view) through the authors' camera convention.
    let s = CarlaSample::load(&shared.join("fca/carla_dataset/test/data12501.npz")).unwrap();
    let g = GBuffer::render(&mesh, &pav_camou(s.cam_trans, s.veh_trans[1][1]), 400);
    let cov = g.coverage();
    assert!((0.08..0.6).contains(&cov), "car covers {cov} of the image");
    let gather = Gather::new(g.uv_samples(&mesh), tex.width, tex.height);
    let mut m = vec![0.0; 400 * 400];
    gather.apply(&white, 1, &mut m);
    let textured = m.iter().filter(|v| **v > 0.5).count() as f32 / (400.0 * 400.0);
    assert!(
        textured > 0.02 && textured < cov,
        "textured share {textured} of the image, car {cov}"
    );
    // Textured pixels belong to the faces whose UV centroid lies in the white region
    // (281 faces per CONVENTIONS.md): a flipped or shifted UV mapping would break this.
    let centroid_white = |f: usize| {
        let c = mesh.face_uvs[f].iter().fold([0f32; 2], |a, &t| {
            [
                a[0] + mesh.uvs[t as usize][0] / 3.0,
                a[1] + mesh.uvs[t as usize][1] / 3.0,
            ]
        });
        let x = ((c[0].clamp(0.0, 1.0)) * (tex.width - 1) as f32).round() as usize;
        let y = ((1.0 - c[1].clamp(0.0, 1.0)) * (tex.height - 1) as f32).round() as usize;
        white[y * tex.width + x] == 1.0
    };
    assert_eq!(
        (0..mesh.faces.len()).filter(|&f| centroid_white(f)).count(),
        281
    );
    let (mut inside, mut total) = (0, 0);
    for (i, v) in m.iter().enumerate() {
        if *v > 0.5 && g.face[i] != EMPTY {
            total += 1;
            inside += centroid_white(g.face[i] as usize) as usize;
        }
    }
    assert!(
        inside as f32 / total as f32 > 0.95,
        "{inside}/{total} textured pixels on white-centroid faces"
    );
}
