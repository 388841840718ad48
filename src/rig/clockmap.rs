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

    /// The upper-envelope fit of arrivals `(host s, device s)` in arrival order; `None` until
    /// they span two distinct host times with the device clock moving forward.
    pub fn fit(arrivals: &[(f64, f64)]) -> Option<ClockMap> {
        // Upper hull by Andrew's monotone chain; equal arrival times keep the latest device time
        // (lines read together: the last one sent waited least).
        let mut hull: Vec<(f64, f64)> = Vec::new();
        let (mut sum_h, mut n) = (0.0, 0usize);
        for &(h, d) in arrivals {
            sum_h += h;
            n += 1;
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
        if hull.len() < 2 {
            return None;
        }
        let mean = sum_h / n as f64;
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
