//! The differentiable-render half of PAV-Camou: a rasterized G-buffer per pose (computed once),
//! the texture gather with its exact adjoint, and the dual-render mask.

pub mod bake;
pub mod fill;
pub mod mask;
pub mod raster;
pub mod shade;
pub mod texture;
