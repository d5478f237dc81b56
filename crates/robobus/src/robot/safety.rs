//! Host-side motion limits: soft position limits, then speed and acceleration limits
//! on the stream of targets.

use crate::actuator::JointLimits;

/// Which limit changed a target.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LimitKind {
    /// The soft position limits (`limits = [min, max]`).
    Position,
    /// The speed or acceleration limit (`max_velocity`, `max_acceleration`): the target
    /// is approached gradually.
    Motion,
    /// The device's per-command step limit (WHJ: set-points further than 80 % of
    /// [`JointBusConfig::step_limit_deg`](crate::whj::JointBusConfig::step_limit_deg)
    /// from the measured angle would be refused): the set-point waits for the joint.
    Step,
}

/// A target changed by a limit: reported by [`Robot::command`](super::Robot::command).
#[derive(Debug, Clone, PartialEq)]
pub struct LimitEvent {
    /// The joint.
    pub joint: String,
    /// Which limit acted.
    pub kind: LimitKind,
    /// The target asked for, rad.
    pub requested_rad: f64,
    /// The target after this limit, rad.
    pub limited_rad: f64,
}

/// Speed- and acceleration-limited following of a target (one per joint).
///
/// Each step moves the set-point towards the target with a speed that never exceeds
/// `max_velocity_rad_s`, never changes by more than `max_acceleration_rad_s2 × dt`, and
/// is small enough to stop at the target with that deceleration (no overshoot).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateLimiter {
    position_rad: f64,
    velocity_rad_s: f64,
}

impl RateLimiter {
    /// A limiter at rest at `position_rad`.
    pub const fn new(position_rad: f64) -> Self {
        Self {
            position_rad,
            velocity_rad_s: 0.0,
        }
    }

    /// The current set-point, rad.
    pub const fn position_rad(&self) -> f64 {
        self.position_rad
    }

    /// The current set-point speed, rad/s.
    pub const fn velocity_rad_s(&self) -> f64 {
        self.velocity_rad_s
    }

    /// Advances by `dt_s` seconds towards `target_rad` and returns the new set-point.
    pub fn step(&mut self, target_rad: f64, dt_s: f64, limits: &JointLimits) -> f64 {
        if dt_s <= 0.0 || !dt_s.is_finite() {
            return self.position_rad;
        }
        let vmax = limits.max_velocity_rad_s;
        let amax = limits.max_acceleration_rad_s2;
        let error = target_rad - self.position_rad;
        // Speed that reaches the target this step, capped by the speed limit and by
        // what can still be braked to zero at the target.
        let braking = (2.0 * amax * error.abs()).sqrt();
        let wanted = error.signum() * (error.abs() / dt_s).min(vmax).min(braking);
        let dv = (wanted - self.velocity_rad_s).clamp(-amax * dt_s, amax * dt_s);
        let mut velocity = (self.velocity_rad_s + dv).clamp(-vmax, vmax);
        let mut next = self.position_rad + velocity * dt_s;
        // Never step past the target.
        if (target_rad - next) * error <= 0.0 {
            // Arrived: stop there (only ever a slow-down, as the braking curve above
            // keeps the speed at arrival small).
            next = target_rad;
            velocity = 0.0;
        }
        self.position_rad = next;
        self.velocity_rad_s = velocity;
        next
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const fn limits(v: f64, a: f64) -> JointLimits {
        JointLimits {
            min_rad: -10.0,
            max_rad: 10.0,
            max_velocity_rad_s: v,
            max_acceleration_rad_s2: a,
        }
    }

    #[test]
    fn reaches_a_far_target_at_the_speed_limit_and_stops_there() {
        let l = limits(1.0, 5.0);
        let mut r = RateLimiter::new(0.0);
        let dt = 0.01;
        let mut peak = 0.0_f64;
        let mut steps = 0;
        while (r.position_rad() - 2.0).abs() > 1e-9 && steps < 10_000 {
            r.step(2.0, dt, &l);
            peak = peak.max(r.velocity_rad_s());
            steps += 1;
        }
        assert!((r.position_rad() - 2.0).abs() < 1e-9);
        assert!(
            (peak - 1.0).abs() < 1e-9,
            "cruises at the limit, peak {peak}"
        );
        // 2 rad at 1 rad/s plus accelerating / braking at 5 rad/s²: about 2.2 s.
        assert!((200..=240).contains(&steps), "{steps} steps");
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        #[test]
        fn never_exceeds_the_speed_or_acceleration_limit(
            start in -3.0..3.0_f64,
            targets in proptest::collection::vec(-3.0..3.0_f64, 1..80),
            v in 0.1..5.0_f64,
            a in 0.5..50.0_f64,
            dt in 0.001..0.05_f64,
        ) {
            let l = limits(v, a);
            let mut r = RateLimiter::new(start);
            let mut prev_v = 0.0;
            for t in targets {
                let before = r.position_rad();
                let after = r.step(t, dt, &l);
                let speed = (after - before) / dt;
                prop_assert!(speed.abs() <= v * (1.0 + 1e-9), "speed {speed} > {v}");
                // Acceleration is bounded, except the final snap onto the target,
                // which only ever slows down.
                let acc = (r.velocity_rad_s() - prev_v) / dt;
                prop_assert!(
                    acc.abs() <= a * (1.0 + 1e-9) || r.velocity_rad_s().abs() <= prev_v.abs() + 1e-12,
                    "accel {acc} > {a}"
                );
                prev_v = r.velocity_rad_s();
            }
        }
    }
}
