//! Time as an input: the rig reads and waits on a [`Clock`], the system's on a real rig and a
//! simulated one in tests, where waiting moves time on at once and nothing depends on how
//! busy the machine is.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Where the rig reads the time and waits.
pub trait Clock: Send + Sync {
    /// The current instant.
    fn now(&self) -> Instant;
    /// Returns at `t` or later.
    fn sleep_until(&self, t: Instant);
    /// Time since `t` (zero for an instant to come).
    fn since(&self, t: Instant) -> Duration {
        self.now().saturating_duration_since(t)
    }
}

/// The machine's monotonic clock; waiting sleeps the thread.
#[derive(Clone, Copy, Debug, Default)]
pub struct SystemClock;

impl Clock for SystemClock {
    fn now(&self) -> Instant {
        Instant::now()
    }
    fn sleep_until(&self, t: Instant) {
        let now = Instant::now();
        if t > now {
            std::thread::sleep(t - now);
        }
    }
}

/// A clock that stands still until someone waits on it; waiting jumps to the instant waited
/// for. Instants are those of the system clock when it was made, plus the time simulated since.
#[derive(Debug)]
pub struct SimClock {
    base: Instant,
    nanos: AtomicU64,
}

impl Default for SimClock {
    fn default() -> Self {
        SimClock::new()
    }
}

impl SimClock {
    /// A clock at the present instant.
    pub fn new() -> Self {
        SimClock { base: Instant::now(), nanos: AtomicU64::new(0) }
    }

    /// Time simulated since the clock was made.
    pub fn elapsed(&self) -> Duration {
        Duration::from_nanos(self.nanos.load(Ordering::SeqCst))
    }
}

impl Clock for SimClock {
    fn now(&self) -> Instant {
        self.base + self.elapsed()
    }
    fn sleep_until(&self, t: Instant) {
        let n = u64::try_from(t.saturating_duration_since(self.base).as_nanos()).unwrap_or(u64::MAX);
        // Never backwards: two waiters on one clock leave it at the later instant.
        self.nanos.fetch_max(n, Ordering::SeqCst);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_simulated_clock_moves_only_when_waited_on_and_never_back() {
        let c = SimClock::new();
        let t0 = c.now();
        std::thread::sleep(Duration::from_millis(5));
        assert_eq!(c.now(), t0, "wall time passed, simulated time did not");
        c.sleep_until(t0 + Duration::from_secs(3600));
        assert_eq!(c.since(t0), Duration::from_secs(3600));
        c.sleep_until(t0 + Duration::from_secs(1));
        assert_eq!(c.elapsed(), Duration::from_secs(3600));
        assert_eq!(c.since(t0 + Duration::from_secs(7200)), Duration::ZERO);
    }
}
