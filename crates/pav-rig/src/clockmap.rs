//! The device clock on the host's time line, from one-way messages: each arrives at host time
//! `h` carrying device time `d`, and latency only ever delays arrivals.
//!
//! With the device clock modelled as `d = rate·h_sent + c`, every arrival lies on or below that
//! line, and the messages that travelled fastest touch it. The line is therefore fitted as the
//! upper envelope of the points, not through them: of all lines above every point, the one
//! closest to them on average (Moon, Skelly and Towsley's linear-programming skew estimate). It
//! passes through the edge of the upper convex hull that spans the mean arrival time. Least
//! squares instead fits the mean latency, whose spread grows with host load; the envelope needs
//! only a few fast messages near either end, which even a busy host delivers. The rate is then
//! refined on a long baseline (the fastest message of the first third against the fastest of the
//! last third), since the hull edge at the mean can be short.

/// `d = rate·h + c`: device seconds at host second `h`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClockMap {
    /// Device seconds per host second.
    pub rate: f64,
    /// Device seconds at host second 0.
    pub c: f64,
}

impl ClockMap {
    /// Device time at host time `h`.
    pub fn device(&self, h: f64) -> f64 {
        self.rate * h + self.c
    }

    /// The upper-envelope fit of arrivals `(host s, device s)` in arrival order (host time never
    /// decreasing); `None` until they span two distinct host times with the device clock moving
    /// forward.
    pub fn fit(arrivals: &[(f64, f64)]) -> Option<ClockMap> {
        let hull = upper_hull(arrivals);
        let mean = arrivals.iter().map(|p| p.0).sum::<f64>() / arrivals.len().max(1) as f64;
        if hull.len() < 2 {
            return None;
        }
        let i = hull.partition_point(|p| p.0 <= mean).clamp(1, hull.len() - 1);
        let (a, b) = (hull[i - 1], hull[i]);
        let mut rate = (b.1 - a.1) / (b.0 - a.0);
        if !(rate > 0.0 && rate.is_finite()) {
            return None;
        }
        // The hull edge at the mean can be short (two fast reports close together), and a
        // short baseline turns a millisecond of latency into a visible rate error. Refine the
        // rate on a long baseline: the fastest report of the first third against the fastest
        // of the last third, twice (each pick depends on the rate a little).
        let (h0, h1) = (hull[0].0, hull[hull.len() - 1].0);
        let third = (h1 - h0) / 3.0;
        for _ in 0..2 {
            let fastest = |lo: f64, hi: f64| {
                arrivals
                    .iter()
                    .filter(|p| p.0 >= lo && p.0 <= hi)
                    .max_by(|p, q| (p.1 - rate * p.0).total_cmp(&(q.1 - rate * q.0)))
                    .copied()
            };
            let (Some(p), Some(q)) = (fastest(h0, h0 + third), fastest(h1 - third, h1)) else { break };
            let r = (q.1 - p.1) / (q.0 - p.0);
            if q.0 - p.0 > 0.0 && r > 0.0 && r.is_finite() {
                rate = r;
            }
        }
        // Latency only delays: the line touches the fastest report of all.
        let c = arrivals.iter().map(|p| p.1 - rate * p.0).fold(f64::NEG_INFINITY, f64::max);
        Some(ClockMap { rate, c })
    }
}

/// Every clock line `d = rate·h + c` that the observations allow, without assuming which
/// messages travelled fastest: a one-way arrival at host `h` of device time `d` says
/// `d ≤ rate·h + c` (it was sent no later than it arrived), a round trip sent at host `s` whose
/// reply was made by device time `d` says `rate·s + c ≤ d`. Together they cut a convex polygon
/// out of the (rate, c) plane; the device time at a host time is known to the range of
/// `rate·h + c` over it. [`ClockMap::fit`] picks one line; this says how wrong any pick can be,
/// including a rate misjudged because one part of a spin was read later than another.
#[derive(Clone, Debug)]
pub struct ClockRange {
    /// Lines `c ≥ d − rate·h`, reduced to the upper hull of the points `(h, d)` (the others
    /// never bind for a positive rate).
    lower: Vec<(f64, f64)>,
    /// Lines `c ≤ d − rate·s`, as `(s, d)`.
    upper: Vec<(f64, f64)>,
}

/// What the observations say about the device time at one host time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DeviceTime {
    /// It lies in `[lo, hi]` device seconds.
    Within(f64, f64),
    /// No positive-rate line sits below every upper and above every lower constraint: the
    /// constraints miss each other by at least this many device seconds.
    Contradiction(f64),
    /// Some side is unconstrained (no round trip, no arrival, or none late enough to bound
    /// the rate).
    Unbounded,
}

/// The upper convex hull of `(h, d)` points in host-time order, by Andrew's monotone chain; of
/// points at one host time only the latest device time counts (lines read together: the last
/// one sent waited least). Raising a point in place leaves no hull vertex out, which is all
/// [`ClockRange`] needs of it.
fn upper_hull(in_order: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut hull: Vec<(f64, f64)> = Vec::new();
    for &(h, d) in in_order {
        if let Some(last) = hull.last_mut() {
            if h <= last.0 {
                last.1 = last.1.max(d);
                continue;
            }
        }
        while hull.len() >= 2 {
            let (o, a) = (hull[hull.len() - 2], hull[hull.len() - 1]);
            if (a.0 - o.0) * (d - o.1) - (a.1 - o.1) * (h - o.0) >= 0.0 {
                hull.pop();
            } else {
                break;
            }
        }
        hull.push((h, d));
    }
    hull
}

/// Slack for rounding when testing a vertex against the constraints, device seconds.
const VERTEX_TOL: f64 = 1e-9;

impl ClockRange {
    /// From arrivals `(host s, device s)` (device time at or before sending) and round trips
    /// `(host s sent, device s)` (device time at or after the reply was made).
    pub fn new(arrivals: &[(f64, f64)], upper: &[(f64, f64)]) -> ClockRange {
        // Round trips' replies come after the reports in the caller's list: sort by host time.
        let mut sorted = arrivals.to_vec();
        sorted.sort_by(|p, q| p.0.total_cmp(&q.0));
        ClockRange { lower: upper_hull(&sorted), upper: upper.to_vec() }
    }

    /// Lowest `c` the arrivals allow at `rate`.
    fn floor(&self, rate: f64) -> f64 {
        self.lower.iter().map(|p| p.1 - rate * p.0).fold(f64::NEG_INFINITY, f64::max)
    }

    /// Highest `c` the round trips allow at `rate`.
    fn ceiling(&self, rate: f64) -> f64 {
        self.upper.iter().map(|p| p.1 - rate * p.0).fold(f64::INFINITY, f64::min)
    }

    /// Rates where the polygon can have a corner: rate 0, and where two constraint lines
    /// cross at a positive rate.
    fn corner_rates(&self) -> Vec<f64> {
        let lines: Vec<(f64, f64)> = self.lower.iter().chain(&self.upper).copied().collect();
        let mut rates = vec![0.0];
        for (i, a) in lines.iter().enumerate() {
            for b in &lines[i + 1..] {
                let r = (a.1 - b.1) / (a.0 - b.0);
                if r > 0.0 && r.is_finite() {
                    rates.push(r);
                }
            }
        }
        rates
    }

    /// The device time at host time `h` over every consistent line.
    pub fn device_at(&self, h: f64) -> DeviceTime {
        if self.lower.is_empty() || self.upper.is_empty() {
            return DeviceTime::Unbounded;
        }
        let rates = self.corner_rates();
        let (mut lo, mut hi, mut any) = (f64::INFINITY, f64::NEG_INFINITY, false);
        for &r in &rates {
            let (f, c) = (self.floor(r), self.ceiling(r));
            if f <= c + VERTEX_TOL {
                any = true;
                lo = lo.min(r * h + f);
                hi = hi.max(r * h + c.max(f));
            }
        }
        if !any {
            // The gap ceiling − floor is concave in the rate, so its best is at a corner.
            let gap = rates.iter().map(|&r| self.floor(r) - self.ceiling(r)).fold(f64::INFINITY, f64::min);
            return DeviceTime::Contradiction(gap);
        }
        // As the rate grows the ceiling falls with the latest round trip and the floor with the
        // earliest arrival: the polygon closes only if that round trip was sent after it.
        let last_sent = self.upper.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
        if last_sent <= self.lower[0].0 {
            return DeviceTime::Unbounded;
        }
        DeviceTime::Within(lo, hi)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Arrivals of a device clock `rate·h + c` sent every 10 ms, delayed by `latency(k)` s, in
    /// order (a serial line is first in, first out).
    fn arrivals(rate: f64, c: f64, latency: impl Fn(usize) -> f64) -> Vec<(f64, f64)> {
        let mut last = f64::NEG_INFINITY;
        (0..500)
            .map(|k| {
                last = last.max(k as f64 * 0.01 + latency(k));
                (last, rate * k as f64 * 0.01 + c)
            })
            .collect()
    }

    #[test]
    fn the_envelope_ignores_heavy_tailed_latency() {
        // A loaded host: most messages wait 2–10 ms, one in 50 is read 200 ms late (a
        // descheduled reader; those behind it queue up), one in 25 is read within 0.2 ms.
        let lat = |k: usize| match k {
            _ if k % 25 == 3 => 0.0002,
            _ if k % 50 == 20 => 0.2,
            _ => 0.002 + ((k * 7919) % 61) as f64 / 61.0 * 0.008,
        };
        let pts = arrivals(1.04, 5.0, lat);
        let m = ClockMap::fit(&pts).unwrap();
        assert!((m.rate - 1.04).abs() < 2e-4, "rate {}", m.rate);
        assert!((m.device(2.0) - (1.04 * 2.0 + 5.0)).abs() < 5e-4, "{}", m.device(2.0));
        assert!(pts.iter().all(|&(h, d)| d <= m.device(h) + 1e-12), "a point above the line");
        // Least squares on the same points is off by far more than the envelope.
        let n = pts.len() as f64;
        let (mh, md) = (pts.iter().map(|p| p.0).sum::<f64>() / n, pts.iter().map(|p| p.1).sum::<f64>() / n);
        let ls = pts.iter().map(|p| (p.0 - mh) * (p.1 - md)).sum::<f64>()
            / pts.iter().map(|p| (p.0 - mh).powi(2)).sum::<f64>();
        assert!((ls - 1.04).abs() > 10.0 * (m.rate - 1.04).abs(), "least squares {ls}, envelope {}", m.rate);
    }

    #[test]
    fn the_range_is_every_line_between_arrivals_and_round_trips() {
        // Arrivals at host 0 and 10 s of device 0 and 10 s; replies sent then stamped 0.1 s later.
        let r = ClockRange::new(&[(0.0, 0.0), (10.0, 10.0)], &[(0.0, 0.1), (10.0, 10.1)]);
        // Between them the range is the stamps' slack; beyond them a rate of 0.99–1.01 opens it.
        let close = |t: DeviceTime, lo: f64, hi: f64| match t {
            DeviceTime::Within(a, b) => (a - lo).abs() < 1e-9 && (b - hi).abs() < 1e-9,
            _ => false,
        };
        assert!(close(r.device_at(5.0), 5.0, 5.1), "{:?}", r.device_at(5.0));
        assert!(close(r.device_at(20.0), 19.9, 20.2), "{:?}", r.device_at(20.0));
        // Round trips before the arrivals only: a clock of any speed could have sent them late.
        assert_eq!(ClockRange::new(&[(5.0, 5.0), (10.0, 10.0)], &[(0.0, 0.1)]).device_at(20.0), DeviceTime::Unbounded);
        assert_eq!(ClockRange::new(&[(5.0, 5.0)], &[]).device_at(5.0), DeviceTime::Unbounded);
        // A reply stamped before a report that arrived earlier was sent: 0.5 s apart.
        match ClockRange::new(&[(0.0, 1.0)], &[(0.0, 0.5)]).device_at(0.0) {
            DeviceTime::Contradiction(g) => assert!((g - 0.5).abs() < 1e-12, "{g}"),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn too_few_or_simultaneous_arrivals_give_no_fit() {
        assert_eq!(ClockMap::fit(&[]), None);
        assert_eq!(ClockMap::fit(&[(1.0, 2.0)]), None);
        assert_eq!(ClockMap::fit(&[(1.0, 2.0), (1.0, 2.5)]), None);
        let m = ClockMap::fit(&[(0.0, 1.0), (1.0, 3.0)]).unwrap();
        assert_eq!((m.rate, m.c), (2.0, 1.0));
        // A clock that runs backwards is no clock.
        assert_eq!(ClockMap::fit(&[(0.0, 3.0), (1.0, 1.0)]), None);
    }
}
