//! Integer-microstep motion: trapezoidal moves, constant-rate spins and controlled stops.
//!
//! Positions are `i64` microsteps and times `u64` microseconds; every profile ends exactly on its
//! target, so thousands of turns accumulate no error.

const US: i128 = 1_000_000;

/// A motion from rest to rest (or to a controlled stop), as a function of time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Profile {
    start_us: u64,
    from: i64,
    /// +1 or −1.
    dir: i64,
    /// Total distance, microsteps (≥ 0).
    dist: i64,
    /// Cruise speed in thousandths of a microstep per second, so 28 s/turn is not rounded to
    /// whole microsteps/s (which would put a revolution 0.25 % off).
    vm: i64,
    /// Acceleration, microsteps/s² (> 0).
    a: i64,
    t_acc_us: u64,
    t_cruise_us: u64,
    t_dec_us: u64,
    d_acc: i64,
    d_dec: i64,
}

/// Distance a·t²/2 covered from rest in `t_us`, floored to whole microsteps.
fn dist_at(a: i64, t_us: u64) -> i64 {
    let t = t_us as i128;
    (a as i128 * t * t / (2 * US * US)) as i64
}

/// The same distance rounded up: subtracted from the end it floors the position like the other phases.
fn dist_at_ceil(a: i64, t_us: u64) -> i64 {
    let t = t_us as i128;
    let d = 2 * US * US;
    ((a as i128 * t * t + d - 1) / d) as i64
}

impl Profile {
    /// A rest-to-rest move from `from` to `to` limited by `vmax` and `accel`, starting at `start_us`.
    pub fn new(from: i64, to: i64, vmax: i64, accel: i64, start_us: u64) -> Self {
        Self::with_milli_speed(from, to, vmax.max(1).saturating_mul(1000), accel, start_us)
    }

    /// As [`Profile::new`] with the speed limit in thousandths of a microstep per second.
    pub fn with_milli_speed(from: i64, to: i64, vmax_milli: i64, accel: i64, start_us: u64) -> Self {
        let (vmax_milli, a) = (vmax_milli.max(1), accel.max(1));
        let dist = (to - from).abs();
        let dir = if to >= from { 1 } else { -1 };
        if dist == 0 {
            return Profile {
                start_us,
                from,
                dir,
                dist,
                vm: 1,
                a,
                t_acc_us: 0,
                t_cruise_us: 0,
                t_dec_us: 0,
                d_acc: 0,
                d_dec: 0,
            };
        }
        // Peak speed: vmax, or √(a·d) when the move is too short to reach it (triangle).
        let vm = vmax_milli.min(((a as i128 * dist as i128 * 1_000_000) as u128).isqrt() as i64).max(1);
        let t_acc_us = (vm as i128 * 1000 / a as i128) as u64;
        let d_acc = dist_at(a, t_acc_us).min(dist / 2);
        let cruise = dist - 2 * d_acc;
        let t_cruise_us = ((cruise as i128 * US * 1000 + vm as i128 - 1) / vm as i128) as u64;
        Profile { start_us, from, dir, dist, vm, a, t_acc_us, t_cruise_us, t_dec_us: t_acc_us, d_acc, d_dec: d_acc }
    }

    /// A constant-rate spin of `turns` revolutions (`u64::MAX`-like distance when `turns` is 0),
    /// ramping at `accel` to `usteps_per_rev / period`.
    pub fn spin(from: i64, usteps_per_rev: u32, period_ms: i64, turns: u32, accel: i64, start_us: u64) -> Self {
        let rev = usteps_per_rev as i64;
        let vm = ((rev as i128 * 1_000_000) / period_ms.unsigned_abs() as i128).max(1) as i64;
        // "Endless" is 2^40 turns away: centuries at any speed the rig can reach.
        let n = if turns == 0 { 1i64 << 40 } else { turns as i64 };
        let to = from + period_ms.signum() * n * rev;
        Self::with_milli_speed(from, to, vm, accel, start_us)
    }

    /// Final position.
    pub fn target(&self) -> i64 {
        self.from + self.dir * self.dist
    }

    /// Time the profile reaches its target.
    pub fn end_us(&self) -> u64 {
        self.start_us + self.t_acc_us + self.t_cruise_us + self.t_dec_us
    }

    /// Position at time `t_us` (clamped to the start and the target).
    pub fn position_at(&self, t_us: u64) -> i64 {
        let t = t_us.saturating_sub(self.start_us);
        let s = if t >= self.t_acc_us + self.t_cruise_us + self.t_dec_us {
            self.dist
        } else if t < self.t_acc_us {
            // Accelerating from rest (stop profiles have no acceleration phase).
            dist_at(self.a, t)
        } else if t < self.t_acc_us + self.t_cruise_us {
            // The cruise time is rounded up, so cap it where the ramp down begins.
            (self.d_acc + ((t - self.t_acc_us) as i128 * self.vm as i128 / (US * 1000)) as i64)
                .min(self.dist - self.d_dec)
        } else {
            // Decelerating: mirror of the ramp, counted back from the end.
            let left = self.t_acc_us + self.t_cruise_us + self.t_dec_us - t;
            self.dist - dist_at_ceil(self.a, left).min(self.d_dec)
        };
        self.from + self.dir * s.clamp(0, self.dist)
    }

    /// Signed speed at `t_us`, microsteps/s (floored).
    pub fn speed_at(&self, t_us: u64) -> i64 {
        self.milli_speed_at(t_us) / 1000
    }

    /// Signed speed at `t_us` in thousandths of a microstep per second.
    pub fn milli_speed_at(&self, t_us: u64) -> i64 {
        let t = t_us.saturating_sub(self.start_us);
        let total = self.t_acc_us + self.t_cruise_us + self.t_dec_us;
        let v = if t >= total {
            0
        } else if t < self.t_acc_us {
            (self.a as i128 * t as i128 / 1000) as i64
        } else if t < self.t_acc_us + self.t_cruise_us {
            self.vm
        } else {
            (self.a as i128 * (total - t) as i128 / 1000) as i64
        };
        self.dir * v.min(self.vm)
    }

    /// The profile that decelerates from this one's state at `t_us` to a halt.
    pub fn stop_at(&self, t_us: u64) -> Profile {
        let pos = self.position_at(t_us);
        let vm = self.milli_speed_at(t_us).abs();
        if vm == 0 {
            return Profile::new(pos, pos, 1, self.a, t_us);
        }
        let t_dec_us = (vm as i128 * 1000 / self.a as i128) as u64;
        let d_dec = dist_at(self.a, t_dec_us);
        Profile {
            start_us: t_us,
            from: pos,
            dir: self.dir,
            dist: d_dec,
            vm,
            a: self.a,
            t_acc_us: 0,
            t_cruise_us: 0,
            t_dec_us,
            d_acc: 0,
            d_dec,
        }
    }
}

/// The axis: at rest at a position, or following a profile.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Motion {
    /// At rest.
    Idle(i64),
    /// Following a profile.
    Running(Profile),
}

impl Motion {
    /// Commanded position at `t_us`.
    pub fn position_at(&self, t_us: u64) -> i64 {
        match self {
            Motion::Idle(p) => *p,
            Motion::Running(p) => p.position_at(t_us),
        }
    }

    /// Whether a profile is still running at `t_us`.
    pub fn is_moving(&self, t_us: u64) -> bool {
        matches!(self, Motion::Running(p) if t_us < p.end_us())
    }

    /// Halts immediately where the profile is at `t_us` (emergency stop: no ramp).
    pub fn halt(&mut self, t_us: u64) {
        *self = Motion::Idle(self.position_at(t_us));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trapezoid_reaches_target_exactly_and_monotonically() {
        let p = Profile::new(0, 3200, 400, 800, 1_000);
        assert_eq!(p.position_at(0), 0);
        assert_eq!(p.position_at(p.end_us()), 3200);
        assert_eq!(p.position_at(u64::MAX), 3200);
        // 0.5 s ramp to 400 usteps/s covers 100 usteps; cruise 3000 usteps at 400/s = 7.5 s.
        assert_eq!(p.end_us(), 1_000 + 500_000 + 7_500_000 + 500_000);
        let mut last = 0;
        for t in (0..p.end_us()).step_by(997) {
            let x = p.position_at(t);
            assert!(x >= last && x - last <= 1, "jump at {t}: {last} -> {x}");
            last = x;
        }
    }

    #[test]
    fn short_moves_are_triangles_and_reverse_moves_work() {
        let p = Profile::new(100, 90, 10_000, 1_000, 0);
        assert_eq!(p.position_at(p.end_us()), 90);
        assert!(p.speed_at(p.end_us() / 2).abs() <= 100, "{}", p.speed_at(p.end_us() / 2));
        let z = Profile::new(5, 5, 100, 100, 0);
        assert_eq!((z.end_us(), z.position_at(10)), (0, 5));
    }

    #[test]
    fn stop_decelerates_without_overshooting_the_move() {
        let p = Profile::spin(0, 3200, 28_000, 0, 2_000, 0);
        let t = 5_000_000;
        let s = p.stop_at(t);
        let v = p.speed_at(t);
        assert_eq!(p.milli_speed_at(t), 3_200_000_000 / 28_000);
        assert_eq!(s.position_at(t), p.position_at(t));
        assert!(s.target() > p.position_at(t) && s.target() - p.position_at(t) <= v * v / (2 * 2000) + 1);
        assert_eq!(s.speed_at(s.end_us()), 0);
    }
}
