//! Smooth set-point generation: a speed- and acceleration-limited profile that turns a
//! target (however far away) into small position steps, so a joint never sees a step
//! beyond its 10° protection (error 0x4000, §6.6).

use core::time::Duration;

/// Limits of a move, and how it is streamed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionLimits {
    /// Largest set-point speed, degrees per second (default 30 °/s = 5 RPM).
    pub max_speed_deg_s: f64,
    /// Largest set-point acceleration, degrees per second² (default 120 °/s²).
    pub max_accel_deg_s2: f64,
    /// Time between two set-points (default 5 ms; the joint needs ≥ 100 Hz anyway).
    pub period: Duration,
    /// How close, degrees, the actual position must come to finish a move (default 0.1°).
    pub tolerance_deg: f64,
    /// How long after the profile ends the joint may take to arrive (default 2 s).
    pub settle_timeout: Duration,
}

impl Default for MotionLimits {
    fn default() -> Self {
        Self {
            max_speed_deg_s: 30.0,
            max_accel_deg_s2: 120.0,
            period: Duration::from_millis(5),
            tolerance_deg: 0.1,
            settle_timeout: Duration::from_secs(2),
        }
    }
}

impl MotionLimits {
    /// Checks that every limit is positive and finite.
    pub fn validate(&self) -> Result<(), String> {
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(self.max_speed_deg_s) {
            return Err(format!(
                "max speed {} °/s must be positive and finite",
                self.max_speed_deg_s
            ));
        }
        if !positive(self.max_accel_deg_s2) {
            return Err(format!(
                "max acceleration {} °/s² must be positive and finite",
                self.max_accel_deg_s2
            ));
        }
        if self.period.is_zero() || self.period > Duration::from_millis(100) {
            return Err(format!(
                "set-point period {:?} out of range (allowed: more than 0, at most 100 ms)",
                self.period
            ));
        }
        if !(self.tolerance_deg.is_finite() && self.tolerance_deg >= 0.0) {
            return Err(format!(
                "tolerance {} ° must be finite and not negative",
                self.tolerance_deg
            ));
        }
        Ok(())
    }
}

/// An online speed / acceleration-limited profile in degrees.
///
/// Each [`Profile::step`] moves the set-point toward the (possibly changing) target with
/// |speed| ≤ `max_speed_deg_s` and |speed change| ≤ `max_accel_deg_s2 · dt`, braking in
/// time to stop at the target (a trapezoidal profile when the target stays put).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Profile {
    position: f64,
    speed: f64,
    limits: MotionLimits,
}

impl Profile {
    /// A profile at rest at `position_deg`.
    pub const fn new(position_deg: f64, limits: MotionLimits) -> Self {
        Self {
            position: position_deg,
            speed: 0.0,
            limits,
        }
    }

    /// The current set-point, degrees.
    pub const fn position(&self) -> f64 {
        self.position
    }

    /// The current set-point speed, degrees per second.
    pub const fn speed(&self) -> f64 {
        self.speed
    }

    /// Whether the set-point rests at `target_deg`.
    #[allow(clippy::float_cmp)] // the profile lands exactly on the target
    pub fn at_rest(&self, target_deg: f64) -> bool {
        self.position == target_deg && self.speed == 0.0
    }

    /// Restarts the profile at rest at `position_deg` (e.g. from a measured position).
    pub const fn reset(&mut self, position_deg: f64) {
        self.position = position_deg;
        self.speed = 0.0;
    }

    /// Every set-point of a move from rest at `from_deg` to rest at `to_deg`, one per
    /// `limits.period`, the last exactly on the target: the plan a move streams (its dry
    /// run prints the same points). At most `max_points` points: `None` when the move would
    /// need more (a tiny speed over a long way).
    pub fn plan(
        from_deg: f64,
        to_deg: f64,
        limits: MotionLimits,
        max_points: usize,
    ) -> Option<Vec<f64>> {
        let dt = limits.period.as_secs_f64();
        let mut p = Self::new(from_deg, limits);
        let mut points = Vec::new();
        loop {
            if points.len() >= max_points {
                return None;
            }
            points.push(p.step(to_deg, dt));
            if p.at_rest(to_deg) {
                return Some(points);
            }
        }
    }

    /// Advances by `dt` seconds toward `target_deg` and returns the new set-point.
    pub fn step(&mut self, target_deg: f64, dt: f64) -> f64 {
        if !(dt.is_finite() && dt > 0.0 && target_deg.is_finite()) {
            return self.position;
        }
        let a = self.limits.max_accel_deg_s2;
        let vmax = self.limits.max_speed_deg_s;
        let dv = a * dt;
        let error = target_deg - self.position;
        // Close enough to land this step without breaking the limits: land.
        if error.abs() <= vmax * dt
            && (error / dt - self.speed).abs() <= dv
            && (error / dt).abs() <= dv
        {
            self.position = target_deg;
            self.speed = 0.0;
            return self.position;
        }
        // The fastest speed from which the target can still be reached braking at the
        // acceleration limit, no faster than the limit, and no further than one step.
        let braking = (2.0 * a * error.abs()).sqrt();
        let wanted = error.signum() * vmax.min(braking).min(error.abs() / dt);
        self.speed += (wanted - self.speed).clamp(-dv, dv);
        self.position += self.speed * dt;
        self.position
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn reaches_a_far_target_with_limited_speed_and_steps() {
        let limits = MotionLimits::default();
        let mut p = Profile::new(0.0, limits);
        let dt = 0.005;
        let mut last = 0.0;
        let mut steps = 0;
        while !p.at_rest(90.0) {
            let x = p.step(90.0, dt);
            assert!((x - last).abs() <= limits.max_speed_deg_s * dt + 1e-9);
            last = x;
            steps += 1;
            assert!(steps < 10_000, "never arrived");
        }
        // 90° at 30 °/s with 0.25 s ramps: about 3.25 s.
        let t = f64::from(steps) * dt;
        assert!((3.2..3.5).contains(&t), "took {t} s");
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]
        #[test]
        fn respects_limits_and_arrives(
            start in -400.0f64..400.0,
            target in -400.0f64..400.0,
            speed in 1.0f64..200.0,
            accel in 5.0f64..2000.0,
            period_us in 500u64..20_000,
        ) {
            let limits = MotionLimits {
                max_speed_deg_s: speed,
                max_accel_deg_s2: accel,
                period: Duration::from_micros(period_us),
                ..MotionLimits::default()
            };
            let dt = limits.period.as_secs_f64();
            let mut p = Profile::new(start, limits);
            let mut prev_v = 0.0;
            let mut prev_x = start;
            // Generous bound on the duration: distance / speed + ramps.
            let bound = ((target - start).abs() / speed + 2.0 * speed / accel) / dt * 1.01 + 50.0;
            let mut n = 0.0;
            while !p.at_rest(target) {
                let x = p.step(target, dt);
                let v = (x - prev_x) / dt;
                prop_assert!(v.abs() <= speed * (1.0 + 1e-9) + 1e-9, "speed {v}");
                prop_assert!((v - prev_v).abs() <= accel * dt * (1.0 + 1e-9) + 1e-9, "accel step {} > {}", (v - prev_v).abs(), accel * dt);
                prop_assert!((x - prev_x).abs() < 10.0);
                prev_v = v;
                prev_x = x;
                n += 1.0;
                prop_assert!(n <= bound, "not there after {n} steps");
            }
        }
    }
}
