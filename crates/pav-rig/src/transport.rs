//! The wire to the turntable as a trait: lines out, lines in stamped with their arrival, so the
//! client runs the same over a serial port, a pseudo-terminal or an in-memory simulator.

use serialport::{ClearBuffer, SerialPort};
use std::io::{ErrorKind, Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, TryRecvError};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Why the wire failed.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// It could not be opened.
    #[error("cannot open turntable port {path}: {source}{}", open_hint(source))]
    Open {
        /// What was opened.
        path: String,
        /// Why not.
        source: std::io::Error,
    },
    /// It went away (cable pulled, device reset, simulator unplugged).
    #[error("{0}")]
    Closed(String),
}

/// The fix for a port that cannot be opened, where the reason says what it is.
fn open_hint(e: &std::io::Error) -> &'static str {
    match e.kind() {
        // Debian gives serial devices to the `dialout` group.
        ErrorKind::PermissionDenied => {
            " (your user may not open serial devices: `sudo usermod -aG dialout $USER`, then log in again)"
        }
        _ => "",
    }
}

/// A line-oriented wire to the turntable. Deadlines and arrival stamps are instants of the
/// clock the wire runs on: the system clock for a port, the simulation's for a simulator.
pub trait Transport: Send {
    /// What it is connected to, for messages (a port path).
    fn name(&self) -> &str;
    /// Sends bytes as they are.
    fn write(&mut self, bytes: &[u8]) -> Result<(), LinkError>;
    /// Next line (without its terminator, trimmed) and the instant it arrived, or `None` when
    /// `deadline` passes first. A past deadline still returns a line already waiting.
    fn read_line(&mut self, deadline: Instant) -> Result<Option<(String, Instant)>, LinkError>;
    /// Drops everything received but not yet read.
    fn discard_input(&mut self);
    /// Closes the wire and opens it again (after a USB re-enumeration or a cable glitch).
    fn reopen(&mut self) -> Result<(), LinkError>;
}

/// Splits received bytes into lines; a line this long is noise and is dropped rather than grown
/// without bound.
#[derive(Default)]
pub(crate) struct Lines {
    partial: Vec<u8>,
}

impl Lines {
    /// Adds `bytes`; returns every line they complete.
    pub(crate) fn push(&mut self, bytes: &[u8]) -> Vec<String> {
        self.partial.extend_from_slice(bytes);
        let mut out = Vec::new();
        while let Some(i) = self.partial.iter().position(|&b| b == b'\n') {
            let line: Vec<u8> = self.partial.drain(..=i).collect();
            out.push(String::from_utf8_lossy(&line).trim().to_string());
        }
        if self.partial.len() > 4096 {
            self.partial.clear();
        }
        out
    }

    /// Forgets a partial line.
    pub(crate) fn clear(&mut self) {
        self.partial.clear();
    }
}

/// The USB serial ports (`/dev/ttyACM*`, where a Pico's USB-CDC appears, and `/dev/ttyUSB*`,
/// a USB-serial adapter's), sorted: the ports a turntable can be on. The legacy `/dev/ttyS*`
/// are left out, since a machine has them whether or not anything is plugged in.
pub fn usb_serial_ports() -> Vec<std::path::PathBuf> {
    let mut found: Vec<std::path::PathBuf> = std::fs::read_dir("/dev")
        .into_iter()
        .flatten()
        .flatten()
        .filter(|e| e.file_name().to_str().is_some_and(|n| n.starts_with("ttyACM") || n.starts_with("ttyUSB")))
        .map(|e| e.path())
        .collect();
    found.sort();
    found
}

/// A serial port (or a pseudo-terminal) on the system clock.
pub struct SerialTransport {
    /// `None` only while reopening (the old port must close before the device can be reopened).
    port: Option<Box<dyn SerialPort>>,
    /// Lines stamped with their arrival time by the reader thread.
    lines: Option<Reader>,
    path: String,
    baud: u32,
}

/// A thread that reads the port and stamps every line with the instant it arrived, so the
/// host-to-device clock mapping does not depend on how often the caller polls.
struct Reader {
    rx: Receiver<Result<(String, Instant), String>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Reader {
    fn spawn(mut port: Box<dyn SerialPort>, path: String) -> Self {
        let (tx, rx) = mpsc::channel();
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let thread = std::thread::Builder::new()
            .name("turntable-rx".into())
            .spawn(move || {
                let mut lines = Lines::default();
                let mut buf = [0u8; 256];
                while !flag.load(Ordering::Relaxed) {
                    match port.read(&mut buf) {
                        Ok(0) => {
                            let _ = tx.send(Err(format!("{path} closed")));
                            return;
                        }
                        Ok(n) => {
                            let at = Instant::now();
                            for line in lines.push(&buf[..n]) {
                                if tx.send(Ok((line, at))).is_err() {
                                    return;
                                }
                            }
                        }
                        Err(e)
                            if matches!(
                                e.kind(),
                                ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted
                            ) => {}
                        Err(e) => {
                            let _ = tx.send(Err(format!("{path}: {e}")));
                            return;
                        }
                    }
                }
            })
            .expect("spawning the serial reader thread");
        Reader { rx, stop, thread: Some(thread) }
    }
}

impl Drop for Reader {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl SerialTransport {
    /// Opens `path` at `baud`.
    pub fn open(path: &str, baud: u32) -> Result<Self, LinkError> {
        let mut t = SerialTransport { port: None, lines: None, path: path.into(), baud };
        t.connect()?;
        Ok(t)
    }

    fn connect(&mut self) -> Result<(), LinkError> {
        let open = |e: serialport::Error| LinkError::Open { path: self.path.clone(), source: e.into() };
        let port = serialport::new(&self.path, self.baud).timeout(Duration::from_millis(20)).open().map_err(open)?;
        let reader = port.try_clone().map_err(open)?;
        self.lines = Some(Reader::spawn(reader, self.path.clone()));
        self.port = Some(port);
        Ok(())
    }

    fn gone(&self) -> LinkError {
        LinkError::Closed(format!("{} is not open", self.path))
    }
}

impl Transport for SerialTransport {
    fn name(&self) -> &str {
        &self.path
    }

    fn write(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        let gone = self.gone();
        let p = self.port.as_mut().ok_or(gone)?;
        p.write_all(bytes).and_then(|_| p.flush()).map_err(|e| LinkError::Closed(format!("{}: {e}", self.path)))
    }

    fn read_line(&mut self, deadline: Instant) -> Result<Option<(String, Instant)>, LinkError> {
        let stopped = || LinkError::Closed(format!("{}: reader stopped", self.path));
        let r = self.lines.as_ref().ok_or_else(|| self.gone())?;
        let got = match r.rx.try_recv() {
            Ok(x) => Some(x),
            Err(TryRecvError::Disconnected) => return Err(stopped()),
            Err(TryRecvError::Empty) => match r.rx.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
                Ok(x) => Some(x),
                Err(RecvTimeoutError::Timeout) => None,
                Err(RecvTimeoutError::Disconnected) => return Err(stopped()),
            },
        };
        match got {
            None => Ok(None),
            Some(Ok(line)) => Ok(Some(line)),
            Some(Err(msg)) => Err(LinkError::Closed(msg)),
        }
    }

    fn discard_input(&mut self) {
        if let Some(p) = self.port.as_mut() {
            let _ = p.clear(ClearBuffer::Input);
        }
        if let Some(r) = &self.lines {
            while let Ok(Ok(_)) = r.rx.try_recv() {}
        }
    }

    fn reopen(&mut self) -> Result<(), LinkError> {
        self.lines = None;
        self.port = None;
        self.connect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_split_across_reads_and_noise_without_an_end_is_dropped() {
        let mut l = Lines::default();
        assert!(l.push(b"ok N1*1").is_empty());
        assert_eq!(l.push(b"234\r\n@5 6\n"), vec!["ok N1*1234".to_string(), "@5 6".to_string()]);
        assert!(l.push(&[b'x'; 5000]).is_empty());
        assert_eq!(l.push(b"done\n"), vec!["done".to_string()]);
    }

    #[test]
    fn a_port_the_user_may_not_open_names_the_dialout_group() {
        let open =
            |kind| LinkError::Open { path: "/dev/ttyACM0".into(), source: std::io::Error::from(kind) }.to_string();
        assert!(
            open(ErrorKind::PermissionDenied).contains("usermod -aG dialout"),
            "{}",
            open(ErrorKind::PermissionDenied)
        );
        assert!(!open(ErrorKind::NotFound).contains("dialout"));
    }
}
