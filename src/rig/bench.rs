//! `pav-rig bench-rig`: command round-trip latency and capture angle-sync error, as CSV.

use super::camera::SimCamera;
use super::capture::{capture, CaptureOptions};
use super::sim::{SimOptions, SimTurntable};
use super::turntable::Turntable;
use anyhow::{Context, Result};
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};
use turntable_proto::Command;

/// Latency summary of one link.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Latency {
    /// Port or `sim`.
    pub link: String,
    /// Round trips measured.
    pub n: usize,
    /// Median, µs.
    pub median_us: f64,
    /// 99th percentile, µs.
    pub p99_us: f64,
    /// Worst, µs.
    pub max_us: f64,
}

/// Angle-sync error of one simulated capture.
#[derive(Clone, Debug, serde::Serialize)]
pub struct AngleSync {
    /// Simulated time speed-up (errors from host latency scale with it).
    pub time_scale: f64,
    /// Frames recorded.
    pub frames: usize,
    /// Median |sidecar − true angle|, degrees.
    pub median_deg: f64,
    /// 95th percentile, degrees.
    pub p95_deg: f64,
    /// Worst, degrees.
    pub max_deg: f64,
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

/// Times `n` PING round trips on an open turntable.
pub fn latency(table: &mut Turntable, link: &str, n: usize) -> Result<Latency> {
    let mut us = Vec::with_capacity(n);
    for _ in 0..n.max(1) {
        let t = Instant::now();
        table.command(Command::Ping)?;
        us.push(t.elapsed().as_secs_f64() * 1e6);
    }
    us.sort_by(f64::total_cmp);
    Ok(Latency {
        link: link.into(),
        n: us.len(),
        median_us: percentile(&us, 0.5),
        p99_us: percentile(&us, 0.99),
        max_us: *us.last().expect("n ≥ 1"),
    })
}

/// Captures one simulated revolution and compares every sidecar angle with the simulator's truth.
pub fn angle_sync(time_scale: f64, fps: f64, dir: &Path) -> Result<AngleSync> {
    let sim = SimTurntable::spawn(SimOptions { time_scale, ..SimOptions::default() })?;
    let mut table = Turntable::open(&sim.path().to_string_lossy(), 115_200, Duration::from_millis(500))?;
    let mut cam = SimCamera::new(sim.truth(), 160, 120, fps);
    let video = dir.join(format!("sync_x{time_scale}.mp4"));
    let opts = CaptureOptions { fourcc: ['m', 'p', '4', 'v'], ..CaptureOptions::new(video.clone()) };
    capture(&mut table, &mut cam, &opts, &AtomicBool::new(false))?;
    let rows = crate::sidecar::read(&crate::sidecar::sidecar_path(&video))?;
    let mut err: Vec<f64> = rows
        .iter()
        .zip(&cam.true_angles)
        .map(|(r, t)| ((r.angle_deg - t + 540.0).rem_euclid(360.0) - 180.0).abs())
        .collect();
    err.sort_by(f64::total_cmp);
    Ok(AngleSync {
        time_scale,
        frames: err.len(),
        median_deg: percentile(&err, 0.5),
        p95_deg: percentile(&err, 0.95),
        max_deg: *err.last().context("no frames")?,
    })
}
