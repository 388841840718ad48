//! The device state machine driven like firmware: bytes in at given times, lines out.

use proptest::prelude::*;
use turntable_proto::text::Milli;
use turntable_proto::{Command, Config, Device, Frame, Reply, Sink, State};

#[derive(Default)]
struct Lines(Vec<String>);
impl Sink for Lines {
    fn send(&mut self, line: &str) {
        self.0.push(line.to_string());
    }
}

struct Rig {
    dev: Device,
    out: Lines,
    now: u64,
}

impl Rig {
    fn new() -> Self {
        let mut out = Lines::default();
        let mut dev = Device::new(Config::default(), 0);
        dev.reset(0, &mut out);
        Rig { dev, out, now: 0 }
    }
    fn send(&mut self, line: &str) -> Vec<String> {
        let start = self.out.0.len();
        for b in line.bytes().chain(std::iter::once(b'\n')) {
            self.dev.feed(b, self.now, &mut self.out);
        }
        self.out.0[start..].to_vec()
    }
    fn byte(&mut self, b: u8) -> Vec<String> {
        let start = self.out.0.len();
        self.dev.feed(b, self.now, &mut self.out);
        self.out.0[start..].to_vec()
    }
    /// Advances time in `step_us` increments, polling each time, until `done` or `limit_us`.
    fn run_until_done(&mut self, step_us: u64, limit_us: u64) -> Vec<String> {
        let start = self.out.0.len();
        let end = self.now + limit_us;
        while self.now < end {
            self.now += step_us;
            self.dev.poll(self.now, &mut self.out);
            if self.out.0[start..].iter().any(|l| l.starts_with("done")) {
                break;
            }
        }
        self.out.0[start..].to_vec()
    }
}

fn done_pos(lines: &[String]) -> i64 {
    match lines.iter().rev().find_map(|l| Reply::parse(l)) {
        Some(Reply::Done { pos, .. }) => pos,
        other => panic!("no done: {other:?} in {lines:?}"),
    }
}

#[test]
fn banner_then_ping() {
    let mut r = Rig::new();
    assert_eq!(r.out.0[0], "pav-turntable 0.1.0 usteps=3200 proto=1");
    assert_eq!(r.send("N1 PING"), ["ok N1"]);
}

#[test]
fn thousand_revolutions_end_exactly_on_zero() {
    let mut r = Rig::new();
    assert_eq!(r.send("N1 REPORT 0"), ["ok N1"]);
    assert_eq!(r.send("N2 SPIN 28 1000"), ["ok N2"]);
    let out = r.run_until_done(250_000, 29_000 * 1_000_000);
    assert_eq!(done_pos(&out), 1000 * 3200);
    assert!(out.iter().any(|l| l == "busy N2"));
    // Homing from a whole number of turns does not move and restarts the count at 0.
    assert_eq!(r.send("N3 HOME"), ["ok N3"]);
    assert_eq!(done_pos(&r.run_until_done(1000, 1_000_000)), 0);
    assert_eq!(r.dev.physical_position(r.now), 1000 * 3200);
}

#[test]
fn spin_reports_track_the_angle_at_the_commanded_rate() {
    let mut r = Rig::new();
    r.send("REPORT 100");
    r.send("SPIN 28 1");
    let out = r.run_until_done(10_000, 40_000_000);
    let samples: Vec<(u64, i64)> = out
        .iter()
        .filter_map(|l| match Reply::parse(l) {
            Some(Reply::Angle { t_ms, pos }) => Some((t_ms, pos)),
            _ => None,
        })
        .collect();
    assert!(samples.len() > 250, "{} samples", samples.len());
    assert!(samples.windows(2).all(|w| w[1].0 > w[0].0 && w[1].1 >= w[0].1));
    // Mid-revolution: 3200 usteps per 28 s, minus the lag of the ramp (v·t_acc/2, t_acc = v/a).
    let (t, p) = samples.iter().find(|s| s.0 >= 14_000).copied().unwrap();
    let v = 3200.0 / 28.0;
    let expect = v * (t as f64 / 1000.0 - v / 6400.0 / 2.0);
    assert!((p as f64 - expect).abs() < 1.0, "t={t} pos={p} expected {expect:.2}");
    assert_eq!(samples.last().unwrap().1, 3200);
}

#[test]
fn estop_locks_until_unlock_and_busy_refuses_a_second_move() {
    let mut r = Rig::new();
    r.send("N1 SPIN 10");
    r.now += 2_000_000;
    assert_eq!(r.send("N2 MOVE 90"), ["error:6 N2 moving: wait for done or STOP"]);
    let held = r.dev.position(r.now);
    assert_eq!(r.byte(b'!'), ["ALARM:3 emergency stop"]);
    r.now += 1_000_000;
    assert_eq!(r.dev.position(r.now), held, "e-stop halts at once");
    assert_eq!(r.send("N3 MOVE 90"), ["error:5 N3 emergency stop"]);
    assert_eq!(r.byte(b'?'), [format!("<Alarm:3 pos={held} t=3000>")]);
    // Reset keeps the lock.
    r.byte(0x18);
    assert_eq!(r.send("N4 MOVEBY 1"), ["error:5 N4 emergency stop"]);
    assert_eq!(r.send("N5 UNLOCK"), ["ok N5"]);
    assert_eq!(r.send("N6 MOVE 90"), ["ok N6"]);
    assert_eq!(done_pos(&r.run_until_done(1000, 10_000_000)), 800);
}

#[test]
fn stop_ramps_down_and_reports_done() {
    let mut r = Rig::new();
    r.send("N1 SPIN 28");
    r.now += 5_000_000;
    let at = r.dev.position(r.now);
    assert_eq!(r.send("N2 STOP"), ["ok N2"]);
    let pos = done_pos(&r.run_until_done(1000, 1_000_000));
    assert!(pos >= at && pos - at < 10, "stopped at {pos}, was at {at}");
    assert_eq!(r.dev.state(), State::Idle);
}

#[test]
fn line_errors_are_answered_once_with_their_sequence() {
    let mut r = Rig::new();
    assert_eq!(r.send("N9 MOVE 90*0"), ["error:3 N9 bad checksum"]);
    assert_eq!(r.send("N10 JUMP"), ["error:1 N10 unknown command"]);
    assert_eq!(r.send(&"X".repeat(300)), ["error:4 line too long"]);
    let f = Frame { seq: Some(11), cmd: Command::MoveBy(Milli(45_000)) };
    assert_eq!(r.send(f.encode(true).as_str()), ["ok N11"]);
}

proptest! {
    /// Relative moves of any size and sign, each run to completion, end exactly on their sum.
    #[test]
    fn moves_accumulate_without_drift(deltas in proptest::collection::vec(-720_000i64..720_000, 1..12)) {
        let mut r = Rig::new();
        let mut expect = 0i64;
        for (i, d) in deltas.iter().enumerate() {
            let line = Frame { seq: Some(i as u32), cmd: Command::MoveBy(Milli(*d)) }.encode(i % 2 == 0);
            prop_assert_eq!(r.send(line.as_str()), vec![format!("ok N{i}")]);
            let n = *d as i128 * 3200;
            expect += (if n >= 0 { (n + 180_000) / 360_000 } else { (n - 180_000) / 360_000 }) as i64;
            let out = r.run_until_done(20_000, 100_000_000);
            prop_assert_eq!(done_pos(&out), expect);
        }
    }

    /// Any bytes at any times: never panics, every reply parses, and every completed line
    /// (newline outside a real-time byte) gets exactly one ok/error.
    #[test]
    fn arbitrary_input_is_answered_and_bounded(bytes in proptest::collection::vec(any::<u8>(), 0..600), gaps in proptest::collection::vec(0u64..50_000, 600)) {
        let mut out = Lines::default();
        let mut dev = Device::new(Config::default(), 0);
        let mut now = 0;
        let mut newlines = 0;
        let mut pending = false;
        for (i, &b) in bytes.iter().enumerate() {
            now += gaps[i];
            dev.feed(b, now, &mut out);
            dev.poll(now, &mut out);
            match b {
                b'\n' => { if pending { newlines += 1; } pending = false; }
                0x18 => pending = false,
                b'\r' | b'!' | b'?' => {}
                _ => pending = true,
            }
        }
        for l in &out.0 {
            prop_assert!(Reply::parse(l).is_some(), "unparseable reply {:?}", l);
        }
        let answers = out.0.iter().filter(|l| l.starts_with("ok") || l.starts_with("error:")).count();
        // Blank lines are ignored; whitespace-only lines count as "pending" here but get no answer.
        prop_assert!(answers <= newlines);
    }
}
