//! The physical rig: turntable client, simulated turntable, frame sources and capture sessions.

pub mod sim;
pub mod turntable;
