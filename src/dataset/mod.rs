//! PBR view sets: images with camera poses, read from the FCA/DAS/PAV npz format.

pub mod fca;
pub mod npz;
