//! PBR view sets: images with camera poses, read from the FCA/DAS/PAV npz format.
#![warn(missing_docs)]

pub mod fca;
pub mod npz;
