//! Host-side motion limits: soft position limits, then speed and acceleration limits
//! on the stream of targets.

use super::Interface;
use crate::actuator::JointLimits;
use crate::motion;

/// Which limit changed a target.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LimitKind {
    /// The soft position limits (`limits = [min, max]`). A WHJ joint commanded in velocity
    /// never heads for a limit faster than it can stop there at `max_acceleration`, and an
    /// effort pushing it past a limit it stands on is dropped.
    Position,
    /// The speed or acceleration limit (`max_velocity`, `max_acceleration`): the target
    /// is approached gradually. In velocity: the speed is clamped to `max_velocity` and
    /// ramped at `max_acceleration`; in effort: clamped to `max_effort` and ramped at
    /// `max_effort_rate`.
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
    /// The interface of the target: its unit (rad, rad/s, N·m).
    pub interface: Interface,
    /// Which limit acted.
    pub kind: LimitKind,
    /// The target asked for, in the interface's unit (rad for a position).
    pub requested_rad: f64,
    /// The target after this limit, in the interface's unit.
    pub limited_rad: f64,
}

/// Speed- and acceleration-limited following of a target (one per joint): the one
/// motion limiter, [`motion::Limiter`], in radians with a joint's limits.
///
/// Each step moves the set-point towards the target with a speed that never exceeds
/// `max_velocity_rad_s`, never changes by more than `max_acceleration_rad_s2 × dt`, and
/// is small enough to stop at the target with that deceleration; it never steps past
/// the target and lands exactly on it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateLimiter(motion::Limiter);

impl RateLimiter {
    /// A limiter at rest at `position_rad`.
    pub const fn new(position_rad: f64) -> Self {
        Self(motion::Limiter::new(position_rad))
    }

    /// The current set-point, rad.
    pub const fn position_rad(&self) -> f64 {
        self.0.position()
    }

    /// The current set-point speed, rad/s.
    pub const fn velocity_rad_s(&self) -> f64 {
        self.0.speed()
    }

    /// Advances by `dt_s` seconds towards `target_rad` and returns the new set-point.
    pub fn step(&mut self, target_rad: f64, dt_s: f64, limits: &JointLimits) -> f64 {
        self.0.step(
            target_rad,
            dt_s,
            limits.max_velocity_rad_s,
            limits.max_acceleration_rad_s2,
        )
    }
}

#[cfg(test)]
#[allow(clippy::float_cmp)] // the limiter lands exactly on the target
mod tests {
    use super::*;

    #[test]
    fn reaches_a_far_target_at_the_speed_limit_and_stops_exactly_there() {
        let l = JointLimits {
            min_rad: -10.0,
            max_rad: 10.0,
            max_velocity_rad_s: 1.0,
            max_acceleration_rad_s2: 5.0,
        };
        let mut r = RateLimiter::new(0.0);
        let mut peak = 0.0_f64;
        let mut steps = 0;
        while !(r.position_rad() == 2.0 && r.velocity_rad_s() == 0.0) {
            let before = r.position_rad();
            assert!(r.step(2.0, 0.01, &l) <= 2.0, "passed the target");
            peak = peak.max((r.position_rad() - before) / 0.01);
            steps += 1;
            assert!(steps < 1000, "never arrived");
        }
        assert!(
            (peak - 1.0).abs() < 1e-9,
            "cruises at the limit, peak {peak}"
        );
        // 0.05 rad/s more per 10 ms step: 20 steps up to 1 rad/s (0.105 rad), 19 down
        // (0.095 rad), and the other 1.8 rad at 0.01 rad a step: 180 steps.
        assert_eq!(steps, 20 + 180 + 19);
    }
}
