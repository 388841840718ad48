//! `pav-rig bench-rig`: command round-trip latency and capture angle-sync error, as CSV.

use super::capture::{capture, CaptureOptions};
use super::sim::{SimOptions, SimTurntable};
use super::source::SimCamera;
use super::turntable::{Turntable, TurntableError};
use pav_core::progress::{Progress, Silent};
use pav_core::table::{write_csv, TableError};
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

/// Why a rig benchmark failed.
#[derive(Debug, thiserror::Error)]
pub enum RigBenchError {
    /// The simulator did not start.
    #[error("starting the simulated turntable: {0}")]
    Simulator(#[source] super::sim::SimError),
    /// The table.
    #[error(transparent)]
    Turntable(#[from] TurntableError),
    /// The capture.
    #[error(transparent)]
    Capture(#[from] super::capture::CaptureError),
    /// Its sidecar.
    #[error(transparent)]
    Sidecar(#[from] pav_core::sidecar::SidecarError),
    /// Writing the CSVs.
    #[error(transparent)]
    Table(#[from] TableError),
    /// A scratch or output folder.
    #[error("{path}: {source}")]
    Io {
        /// The folder.
        path: std::path::PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The capture recorded nothing.
    #[error("the capture at time scale {0} recorded no frames")]
    NoFrames(f64),
}

type Result<T> = std::result::Result<T, RigBenchError>;

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
    let sim =
        SimTurntable::spawn(SimOptions { time_scale, ..SimOptions::default() }).map_err(RigBenchError::Simulator)?;
    let mut table = Turntable::open(&sim.path().to_string_lossy(), 115_200, Duration::from_millis(500))?;
    let mut cam = SimCamera::new(sim.truth(), 160, 120, fps);
    let video = dir.join(format!("sync_x{time_scale}.mp4"));
    let opts = CaptureOptions { fourcc: ['m', 'p', '4', 'v'], ..CaptureOptions::new(video.clone()) };
    capture(&mut table, &mut cam, &opts, &Silent, &AtomicBool::new(false))?;
    let rows = pav_core::sidecar::read(&pav_core::sidecar::sidecar_path(&video))?;
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
        max_deg: *err.last().ok_or(RigBenchError::NoFrames(time_scale))?,
    })
}

/// `pav-rig bench-rig`: PING latency over `n` round trips on the simulator and on each of `ports`,
/// and the angle-sync error of a simulated 28 s turn at each of `time_scales`; writes
/// `rig_latency.csv` and `rig_angle_sync.csv` into `out`. Each result is a note on `progress`.
pub fn bench_rig(
    ports: &[String],
    n: usize,
    time_scales: &[f64],
    out: &Path,
    progress: &dyn Progress,
) -> Result<(Vec<Latency>, Vec<AngleSync>)> {
    let mkdir = |d: &Path| std::fs::create_dir_all(d).map_err(|source| RigBenchError::Io { path: d.into(), source });
    mkdir(out)?;
    let mut lat = Vec::new();
    let sim = SimTurntable::spawn(SimOptions::default()).map_err(RigBenchError::Simulator)?;
    let mut t = Turntable::open(&sim.path().to_string_lossy(), 115_200, Duration::from_secs(1))?;
    lat.push(latency(&mut t, "sim (pty)", n)?);
    for p in ports {
        let mut t = Turntable::open(p, 115_200, Duration::from_secs(1))?;
        lat.push(latency(&mut t, p, n)?);
    }
    for l in &lat {
        progress.note(&format!(
            "{}: median {:.0} µs, p99 {:.0} µs, max {:.0} µs over {}",
            l.link, l.median_us, l.p99_us, l.max_us, l.n
        ));
    }
    let tmp = std::env::temp_dir().join(format!("pav-bench-rig-{}", std::process::id()));
    mkdir(&tmp)?;
    let mut sync = Vec::new();
    for &s in time_scales {
        progress.note(&format!("capturing a simulated 28 s turn at x{s} ({:.1} s)", 28.0 / s));
        let r = angle_sync(s, 30.0, &tmp)?;
        progress.note(&format!(
            "  {} frames: median {:.3}°, p95 {:.3}°, max {:.3}°",
            r.frames, r.median_deg, r.p95_deg, r.max_deg
        ));
        sync.push(r);
    }
    let _ = std::fs::remove_dir_all(&tmp);
    write_csv(&out.join("rig_latency.csv"), &lat)?;
    write_csv(&out.join("rig_angle_sync.csv"), &sync)?;
    Ok((lat, sync))
}
