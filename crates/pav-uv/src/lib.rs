//! UV maps made printable: the optimizable patch re-flattened island by island at one texel
//! density ([`adjust`]), or cut into charts by its 3D surface and packed ([`charts`]). The
//! optimizer adjusts a mesh's map with them before it trains (`pav uv`).
#![warn(missing_docs)]

pub mod adjust;
pub mod charts;
