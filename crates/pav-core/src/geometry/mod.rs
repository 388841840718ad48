//! Geometry: meshes (OBJ) and cameras (PyTorch3D / CARLA pose conventions).

pub mod camera;
pub mod linalg;
pub mod mesh;
pub mod parts;
pub mod uv;
pub mod vec3;
