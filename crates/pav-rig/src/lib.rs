//! The physical rig: turntable client, simulated turntable, frame sources and capture sessions.
#![warn(missing_docs)]

pub mod bench;
pub mod capture;
pub mod clock;
pub mod clockmap;
pub mod controls;
pub mod sim;
pub mod source;
pub mod transport;
pub mod turntable;
pub mod v4l2;
