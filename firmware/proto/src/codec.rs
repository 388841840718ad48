//! Byte stream → lines and real-time bytes, with a bounded buffer.

/// Real-time bytes that act immediately, even in the middle of a line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Realtime {
    /// `!`: emergency stop.
    EStop,
    /// `?`: status report.
    Status,
    /// 0x18 (Ctrl-X): soft reset.
    Reset,
}

impl Realtime {
    /// The byte that encodes it.
    pub const fn byte(self) -> u8 {
        match self {
            Realtime::EStop => b'!',
            Realtime::Status => b'?',
            Realtime::Reset => 0x18,
        }
    }
}

/// What a byte completed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Event {
    /// A full line is ready in [`LineCodec::line`].
    Line,
    /// A real-time byte arrived.
    Realtime(Realtime),
    /// A line ended that was longer than the buffer; it was dropped.
    Overflow,
    /// A line ended that held non-printable bytes; it was dropped.
    Garbage,
}

/// Accumulates bytes into lines of at most `N` bytes; never allocates, never grows.
pub struct LineCodec<const N: usize> {
    buf: [u8; N],
    len: usize,
    overflow: bool,
    garbage: bool,
    ready: bool,
}

impl<const N: usize> Default for LineCodec<N> {
    fn default() -> Self {
        LineCodec { buf: [0; N], len: 0, overflow: false, garbage: false, ready: false }
    }
}

impl<const N: usize> LineCodec<N> {
    /// Feeds one byte; returns what it completed, if anything.
    pub fn push(&mut self, b: u8) -> Option<Event> {
        if self.ready {
            self.ready = false;
            self.len = 0;
        }
        match b {
            b'!' => Some(Event::Realtime(Realtime::EStop)),
            b'?' => Some(Event::Realtime(Realtime::Status)),
            0x18 => {
                self.len = 0;
                self.overflow = false;
                self.garbage = false;
                Some(Event::Realtime(Realtime::Reset))
            }
            b'\r' => None,
            b'\n' => {
                let ev = if self.overflow {
                    Event::Overflow
                } else if self.garbage {
                    Event::Garbage
                } else {
                    self.ready = true;
                    Event::Line
                };
                if !self.ready {
                    self.len = 0;
                }
                self.overflow = false;
                self.garbage = false;
                Some(ev)
            }
            _ => {
                if !(0x20..0x7f).contains(&b) && b != b'\t' {
                    self.garbage = true;
                } else if self.len < N {
                    self.buf[self.len] = b;
                    self.len += 1;
                } else {
                    self.overflow = true;
                }
                None
            }
        }
    }

    /// The line completed by the last [`Event::Line`], trimmed.
    pub fn line(&self) -> &str {
        if !self.ready {
            return "";
        }
        core::str::from_utf8(&self.buf[..self.len]).unwrap_or("").trim()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feed<const N: usize>(c: &mut LineCodec<N>, s: &[u8]) -> Option<Event> {
        s.iter().filter_map(|&b| c.push(b)).last()
    }

    #[test]
    fn lines_realtime_overflow_garbage() {
        let mut c: LineCodec<8> = LineCodec::default();
        assert_eq!(feed(&mut c, b"STATUS\r\n"), Some(Event::Line));
        assert_eq!(c.line(), "STATUS");
        // `!` inside a line acts at once and does not become part of it.
        assert_eq!(c.push(b'M'), None);
        assert_eq!(c.push(b'!'), Some(Event::Realtime(Realtime::EStop)));
        assert_eq!(feed(&mut c, b"OVE\n"), Some(Event::Line));
        assert_eq!(c.line(), "MOVE");
        assert_eq!(feed(&mut c, b"MOVE 123456789\n"), Some(Event::Overflow));
        assert_eq!(feed(&mut c, b"OK\n"), Some(Event::Line));
        assert_eq!(c.line(), "OK");
        assert_eq!(feed(&mut c, b"A\xffB\n"), Some(Event::Garbage));
        assert_eq!(feed(&mut c, b"HALF\x18HOME\n"), Some(Event::Line));
        assert_eq!(c.line(), "HOME");
    }
}
