//! Firmware in the loop: the turntable firmware built for QEMU's lm3s6965evb (the same protocol
//! logic as the RP2040 build) answers the host driver through `-serial pty`, and a capture
//! against it ties frames to angles that follow the commanded rotation.

mod common;

use pav::rig::capture::{capture, CaptureOptions};
use pav::rig::source::LiveCapture;
use pav::rig::turntable::{Event, Turntable};
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::AtomicBool;
use std::time::Duration;
use turntable_proto::text::Milli;

struct Qemu(Child);

impl Drop for Qemu {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Boots the firmware and returns QEMU with the pty path of the board's UART0.
fn boot() -> (Qemu, String) {
    let elf = common::repo().join("target/thumbv7m-none-eabi/release/turntable-fw-qemu");
    assert!(elf.exists(), "{} is missing: run scripts/setup.sh (it builds firmware/qemu)", elf.display());
    let child = Command::new("qemu-system-arm")
        .args(["-M", "lm3s6965evb", "-display", "none", "-monitor", "none", "-serial", "pty", "-kernel"])
        .arg(&elf)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("qemu-system-arm (installed by scripts/setup.sh)");
    let mut q = Qemu(child);
    // QEMU announces "char device redirected to /dev/pts/N (label serial0)" on stdout. Read it on
    // a thread so a QEMU that never says it fails the test instead of hanging it.
    let (tx, rx) = std::sync::mpsc::channel();
    for stream in
        [Box::new(q.0.stdout.take().unwrap()) as Box<dyn std::io::Read + Send>, Box::new(q.0.stderr.take().unwrap())]
    {
        let tx = tx.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(stream).lines().map_while(Result::ok) {
                let _ = tx.send(line);
            }
        });
    }
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    let mut seen = Vec::new();
    while let Ok(line) = rx.recv_timeout(deadline.saturating_duration_since(std::time::Instant::now())) {
        if let Some(rest) = line.split("redirected to ").nth(1) {
            return (q, rest.split_whitespace().next().unwrap().to_string());
        }
        seen.push(line);
    }
    panic!("QEMU did not report its serial pty within 10 s; it printed {seen:?}");
}

#[test]
fn host_driver_talks_to_the_firmware() {
    let (_q, pty) = boot();
    let mut t = Turntable::open(&pty, 115_200, Duration::from_secs(2)).unwrap();
    assert_eq!((t.firmware(), t.usteps_per_rev()), ("0.1.0-qemu", 3200));
    let seq = t.command(turntable_proto::Command::MoveTo(Milli(90_000))).unwrap();
    assert_eq!(t.wait_done(seq, Duration::from_secs(3)).unwrap(), 800);
    // Real time inside QEMU: a 2 s turn reports angles at the commanded rate.
    let seq = t.command(turntable_proto::Command::Spin { period_s: Milli(-2_000), turns: 1 }).unwrap();
    let mut samples = Vec::new();
    loop {
        match t.next_event(Duration::from_secs(3)).unwrap() {
            Some(Event::Angle { t_ms, pos, rx }) => samples.push((t_ms, pos, rx)),
            Some(Event::Done { seq: Some(s), pos }) if s == seq => {
                assert_eq!(pos, 800 - 3200);
                break;
            }
            other => panic!("unexpected {other:?}"),
        }
    }
    // Cruise only: the ramps (6400 usteps/s² to 1600 usteps/s) cover 200 usteps at each end.
    let mid: Vec<_> = samples.iter().filter(|s| s.1 < 500 && s.1 > -2100).collect();
    let (a, b) = (mid.first().unwrap(), mid.last().unwrap());
    let rate = (b.1 - a.1) as f64 / (b.0 - a.0) as f64 * 1000.0;
    assert!((rate + 1600.0).abs() < 16.0, "{rate} usteps/s, expected -1600");
    // The firmware's clock keeps time with the host's (it once ran 4 % fast on a wrong tick rate).
    let host_ms = b.2.duration_since(a.2).as_secs_f64() * 1000.0;
    let dev_ms = (b.0 - a.0) as f64;
    assert!((dev_ms / host_ms - 1.0).abs() < 0.01, "device {dev_ms} ms vs host {host_ms:.1} ms");
    assert_eq!(t.status().unwrap().pos, 800 - 3200);
    // The e-stop byte halts and locks the firmware too.
    let seq = t.command(turntable_proto::Command::Spin { period_s: Milli(2_000), turns: 0 }).unwrap();
    std::thread::sleep(Duration::from_millis(300));
    t.estop().unwrap();
    assert!(matches!(
        t.wait_done(seq, Duration::from_secs(2)),
        Err(pav::rig::turntable::TurntableError::Alarm(turntable_proto::Alarm::EStop))
    ));
    t.command(turntable_proto::Command::Unlock).unwrap();
}

#[test]
fn capture_against_the_firmware_follows_the_commanded_rotation() {
    let (_q, pty) = boot();
    let mut t = Turntable::open(&pty, 115_200, Duration::from_secs(2)).unwrap();
    let mut cam = LiveCapture::gst_test(160, 120, 30).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let video = tmp.path().join("qemu.mp4");
    let opts = CaptureOptions {
        period_s: 3.0,
        fourcc: ['m', 'p', '4', 'v'],
        no_progress: Duration::from_secs(2),
        ..CaptureOptions::new(video.clone())
    };
    let sum = capture(&mut t, &mut cam, &opts, &pav::progress::Silent, &AtomicBool::new(false)).unwrap();
    assert!((85..=98).contains(&sum.frames), "{} frames for a 3 s turn at 30 fps", sum.frames);
    let rows = pav::sidecar::read(&pav::sidecar::sidecar_path(&video)).unwrap();
    assert_eq!(rows.len(), sum.frames);
    // Truth is the commanded motion: 120°/s, reached after a 0.17 s ramp that covers 10° at each
    // end. Fit the start time on the cruise frames and check every one against that line.
    let unwrapped: Vec<(f64, f64)> = {
        let mut turns = 0.0;
        let mut prev = rows[0].angle_deg;
        rows.iter()
            .map(|r| {
                if r.angle_deg + 180.0 < prev {
                    turns += 360.0;
                }
                prev = r.angle_deg;
                (r.timestamp_s, r.angle_deg + turns)
            })
            .collect()
    };
    let cruise: Vec<&(f64, f64)> = unwrapped.iter().filter(|(_, a)| (12.0..348.0).contains(a)).collect();
    let t0 = cruise.iter().map(|(t, a)| t - a / 120.0).sum::<f64>() / cruise.len() as f64;
    let worst = cruise.iter().map(|(t, a)| (a - 120.0 * (t - t0)).abs()).fold(0.0, f64::max);
    eprintln!("QEMU capture: {} cruise frames, worst deviation {worst:.3}°", cruise.len());
    assert!(worst < 0.5, "worst deviation from the commanded rotation {worst:.3}°");
    assert!(cruise.len() > 75, "{}", cruise.len());
}
