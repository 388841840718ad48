//! The differentiable-render half of PAV-Camou: a rasterized G-buffer per pose (computed once),
//! the texture gather with its exact adjoint, shading, the dual-render mask and the composite;
//! plus hole filling and appearance baking for synthetic views, previews, and a benchmark.
#![warn(missing_docs)]

pub mod bake;
pub mod bench;
pub mod fill;
pub mod mask;
pub mod preview;
pub mod raster;
pub mod shade;
pub mod texture;
