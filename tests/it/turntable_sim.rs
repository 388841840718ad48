//! The host client against the simulated turntable (the firmware's protocol logic on a pty):
//! real motions, and every injected fault ending in a clear error or a recovery, never a hang.

use pav::rig::sim::{Faults, SimOptions, SimTurntable};
use pav::rig::turntable::{TableEvent, Turntable, TurntableError};
use std::time::{Duration, Instant};
use turntable_proto::text::Milli;
use turntable_proto::{Alarm, Command, ErrorCode, State};

fn sim(time_scale: f64, faults: Faults) -> SimTurntable {
    SimTurntable::spawn(SimOptions { time_scale, faults, ..SimOptions::default() }).unwrap()
}

fn connect(s: &SimTurntable, timeout_ms: u64) -> Turntable {
    Turntable::open(&s.path().to_string_lossy(), 115_200, Duration::from_millis(timeout_ms)).unwrap()
}

#[test]
fn moves_and_spins_end_exactly_where_commanded() {
    let s = sim(20.0, Faults::default());
    let mut t = connect(&s, 500);
    assert_eq!((t.usteps_per_rev(), t.firmware()), (3200, "0.2.0"));
    let st = t.status().unwrap();
    assert_eq!((st.state, st.pos), (State::Idle, 0));
    let seq = t.command(Command::MoveTo(Milli(90_000))).unwrap();
    assert_eq!(t.wait_done(seq, Duration::from_secs(2)).unwrap(), 800);
    assert!((s.truth().angle_at(Instant::now()) - 90.0).abs() < 1e-9);
    // One revolution at 28 s (1.4 s of wall time at 20x), with angle reports on the way.
    let seq = t.command(Command::Spin { period_s: Milli(28_000), turns: 1 }).unwrap();
    let t0 = Instant::now();
    let mut reports = 0;
    let end = loop {
        match t.next_event(Duration::from_secs(2)).unwrap() {
            Some(TableEvent::Angle { pos, .. }) => {
                assert!((800..=4000).contains(&pos));
                reports += 1;
            }
            Some(TableEvent::Done { seq: Some(q), pos }) if q == seq => break pos,
            other => panic!("unexpected {other:?}"),
        }
    };
    assert_eq!(end, 4000);
    let wall = t0.elapsed().as_secs_f64();
    assert!((1.3..2.5).contains(&wall), "one turn took {wall} s of wall time");
    assert!(reports > 20, "{reports} angle reports");
    let seq = t.command(Command::Home).unwrap();
    assert_eq!(t.wait_done(seq, Duration::from_secs(2)).unwrap(), 0);
}

#[test]
fn stall_alarm_locks_until_unlock() {
    let s = sim(20.0, Faults { stall_after: Some(Duration::from_millis(500)), ..Faults::default() });
    let mut t = connect(&s, 500);
    let seq = t.command(Command::Spin { period_s: Milli(28_000), turns: 2 }).unwrap();
    match t.wait_done(seq, Duration::from_secs(2)) {
        Err(TurntableError::Alarm(Alarm::Stall)) => {}
        other => panic!("expected a stall alarm, got {other:?}"),
    }
    match t.command(Command::MoveBy(Milli(10_000))) {
        Err(TurntableError::Refused { code: ErrorCode::Locked, msg, .. }) => assert_eq!(msg, "motor stall"),
        other => panic!("expected locked, got {other:?}"),
    }
    assert_eq!(t.status().unwrap().alarm, Some(Alarm::Stall));
    t.command(Command::Unlock).unwrap();
    let seq = t.command(Command::MoveBy(Milli(-10_000))).unwrap();
    t.wait_done(seq, Duration::from_secs(2)).unwrap();
}

#[test]
fn noisy_lines_are_survived_by_resync_and_retries() {
    let s = sim(1.0, Faults { drop_byte: 0.01, garbage_line: 0.2, ..Faults::default() });
    let mut t = connect(&s, 150);
    let t0 = Instant::now();
    let mut ok = 0;
    for _ in 0..40 {
        if t.command_retry(Command::Ping, 5).is_ok() {
            ok += 1;
        }
    }
    assert!(ok >= 38, "only {ok}/40 pings got through");
    assert!(t.garbage_lines > 0, "garbage was injected but never seen");
    assert!(t0.elapsed() < Duration::from_secs(30));
}

#[test]
fn slow_or_hung_device_times_out_and_disconnect_is_reported() {
    let s = sim(1.0, Faults { delay: Duration::from_millis(400), ..Faults::default() });
    let r = Turntable::open(&s.path().to_string_lossy(), 115_200, Duration::from_millis(100));
    assert!(matches!(r, Err(TurntableError::NoDevice { .. })), "{:?}", r.err());

    let s = sim(1.0, Faults { hang_after: Some(Duration::from_millis(300)), ..Faults::default() });
    let mut t = connect(&s, 200);
    std::thread::sleep(Duration::from_millis(400));
    let t0 = Instant::now();
    let e = t.command(Command::Ping).unwrap_err();
    assert!(matches!(e, TurntableError::Timeout { .. }), "{e}");
    assert!(e.to_string().contains("did not answer `PING`"), "{e}");
    assert!(t0.elapsed() < Duration::from_secs(2));

    let s = sim(1.0, Faults { disconnect_after: Some(Duration::from_millis(300)), ..Faults::default() });
    let mut t = connect(&s, 200);
    std::thread::sleep(Duration::from_millis(500));
    assert!(!s.is_running());
    let t0 = Instant::now();
    let e = t.command(Command::Ping).unwrap_err();
    assert!(matches!(e, TurntableError::Disconnected(_) | TurntableError::Timeout { .. }), "{e}");
    assert!(t0.elapsed() < Duration::from_secs(2));
}

#[test]
fn reconnect_handshakes_again() {
    let s = sim(1.0, Faults::default());
    let mut t = connect(&s, 300);
    t.reconnect(3, Duration::from_millis(50)).unwrap();
    assert_eq!(t.status().unwrap().state, State::Idle);
    let e = Turntable::open("/dev/does-not-exist", 115_200, Duration::from_millis(100)).err().unwrap();
    assert!(e.to_string().contains("cannot open turntable port /dev/does-not-exist"), "{e}");
}

/// A protocol-1 turntable on a pty, as firmware 0.1.0 answered: XOR checksums it cannot match
/// against a CRC, bare replies, a bare banner on `INFO`.
fn protocol_1_device() -> (std::thread::JoinHandle<()>, String) {
    use serialport::{SerialPort, TTYPort};
    use std::io::{Read, Write};
    let (mut master, slave) = TTYPort::pair().unwrap();
    let path = slave.name().unwrap();
    master.set_timeout(Duration::from_millis(20)).unwrap();
    let h = std::thread::spawn(move || {
        let _slave = slave;
        let (mut line, mut buf, t0) = (Vec::new(), [0u8; 64], Instant::now());
        while t0.elapsed() < Duration::from_secs(5) {
            let n = master.read(&mut buf).unwrap_or(0);
            for &b in &buf[..n] {
                if b != b'\n' {
                    line.push(b);
                    continue;
                }
                let l = String::from_utf8_lossy(&line).to_string();
                line.clear();
                let seq = l.split_whitespace().next().filter(|w| w.starts_with('N')).map(|w| format!(" {w}"));
                let reply = match (l.trim(), seq) {
                    ("INFO", _) => "pav-turntable 0.1.0 usteps=3200 proto=1\nok\n".to_string(),
                    (_, Some(s)) if l.contains('*') => format!("error:3{s} bad checksum\n"),
                    _ => "ok\n".to_string(),
                };
                let _ = master.write_all(reply.as_bytes());
            }
        }
    });
    (h, path)
}

#[test]
fn a_protocol_1_turntable_is_named_not_timed_out() {
    let (_dev, path) = protocol_1_device();
    let e = Turntable::open(&path, 115_200, Duration::from_millis(200)).err().expect("protocol 1 refused");
    assert!(matches!(e, TurntableError::Protocol { found: 1, need: 2, .. }), "{e}");
    assert!(e.to_string().contains("speaks protocol 1 and this pav speaks 2"), "{e}");
}

#[test]
fn a_lost_done_is_recovered_from_the_status() {
    // Every motion's last report and `done` are lost on the line, as a failed CRC drops them.
    let s = sim(20.0, Faults { lose_end: true, ..Faults::default() });
    let mut t = connect(&s, 300);
    let seq = t.command(Command::MoveTo(Milli(90_000))).unwrap();
    let t0 = Instant::now();
    assert_eq!(t.wait_done(seq, Duration::from_secs(3)).unwrap(), 800);
    // Asked after a third of the no-progress limit, not failed after all of it.
    assert!(t0.elapsed() < Duration::from_secs(2), "{:?}", t0.elapsed());
    let seq = t.command(Command::MoveBy(Milli(-45_000))).unwrap();
    assert_eq!(t.wait_done(seq, Duration::from_secs(3)).unwrap(), 400);
}

#[test]
fn a_motion_whose_ok_is_lost_is_taken_not_sent_twice() {
    // A lost `ok` used to fail a capture before it began ("did not answer SPIN within 500ms"),
    // though the table was turning. Drop every byte of the device's `ok` lines after the first
    // few: the status then shows the table moving, and the motion's `done` ends the wait.
    let s = SimTurntable::spawn(SimOptions {
        time_scale: 10.0,
        faults: Faults { lose_ok_after: Some(2), ..Faults::default() },
        ..SimOptions::default()
    })
    .unwrap();
    let mut t = Turntable::open(&s.path().to_string_lossy(), 115_200, Duration::from_millis(300)).unwrap();
    t.command(Command::Ping).unwrap();
    let seq = t.start_motion(Command::MoveBy(Milli(90_000))).unwrap();
    let pos = t.wait_done(seq, Duration::from_secs(3)).unwrap();
    assert_eq!(t.degrees(pos), 90.0);
    // A motion over before its status could be asked is confirmed by its own `done`.
    let seq = t.start_motion(Command::MoveBy(Milli(0))).unwrap();
    assert_eq!(t.wait_done(seq, Duration::from_secs(3)).unwrap(), pos);
}

#[test]
fn in_simulated_time_a_hang_costs_exactly_its_timeouts_and_an_unplugged_table_stays_gone() {
    use pav::rig::clock::{Clock, SimClock};
    use pav::rig::sim::SimTransport;
    use std::sync::Arc;
    let clock = Arc::new(SimClock::new());
    let connect = |faults: Faults| {
        let link = SimTransport::new(SimOptions { faults, ..SimOptions::default() }, clock.clone()).unwrap();
        Turntable::connect(Box::new(link), clock.clone(), Duration::from_millis(200)).unwrap()
    };
    // A hung firmware: the command and the resynchronising ping each wait their 200 ms.
    let mut t = connect(Faults { hang_after: Some(Duration::from_secs(1)), ..Faults::default() });
    let seq = t.command(Command::MoveTo(Milli(90_000))).unwrap();
    assert_eq!(t.wait_done(seq, Duration::from_secs(2)).unwrap(), 800);
    clock.sleep_until(clock.now() + Duration::from_secs(1));
    let t0 = clock.now();
    let e = t.command(Command::Ping).unwrap_err();
    assert!(matches!(e, TurntableError::Timeout { .. }), "{e}");
    assert_eq!(clock.since(t0), Duration::from_millis(400));

    let mut t = connect(Faults { disconnect_after: Some(Duration::from_millis(300)), ..Faults::default() });
    clock.sleep_until(clock.now() + Duration::from_millis(300));
    let e = t.command(Command::Ping).unwrap_err();
    assert!(matches!(e, TurntableError::Disconnected(_)), "{e}");
    let e = t.reconnect(3, Duration::from_millis(50)).unwrap_err();
    assert!(e.to_string().contains("simulated turntable was unplugged"), "{e}");
}
