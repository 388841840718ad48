//! Geometry: meshes (OBJ) and cameras (PyTorch3D / CARLA pose conventions).

pub mod camera;
pub mod mesh;
pub mod uv;
pub mod uv_adjust;
