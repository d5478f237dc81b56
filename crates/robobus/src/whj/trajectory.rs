//! Smooth set-point generation: a speed- and acceleration-limited profile that turns a
//! target (however far away) into small position steps, so a joint never sees a step
//! beyond its 10° protection (error 0x4000, §6.6).

use core::time::Duration;

use crate::motion;

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

/// How many points [`Profile::plan_checked`] computes between two calls of its check
/// (a few milliseconds of planning at most).
pub(crate) const PLAN_CHECK_EVERY: usize = 4096;

/// An online speed / acceleration-limited profile in degrees: the one motion limiter,
/// [`motion::Limiter`], with a move's [`MotionLimits`].
///
/// Each [`Profile::step`] moves the set-point toward the (possibly changing) target with
/// |speed| ≤ `max_speed_deg_s` and |speed change| ≤ `max_accel_deg_s2 · dt`, braking in
/// time to stop at the target (a trapezoidal profile when the target stays put); it never
/// steps past the target and lands exactly on it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Profile {
    limiter: motion::Limiter,
    limits: MotionLimits,
}

impl Profile {
    /// A profile at rest at `position_deg`.
    pub const fn new(position_deg: f64, limits: MotionLimits) -> Self {
        Self {
            limiter: motion::Limiter::new(position_deg),
            limits,
        }
    }

    /// The current set-point, degrees.
    pub const fn position(&self) -> f64 {
        self.limiter.position()
    }

    /// The current set-point speed, degrees per second.
    pub const fn speed(&self) -> f64 {
        self.limiter.speed()
    }

    /// Whether the set-point rests at `target_deg`.
    pub fn at_rest(&self, target_deg: f64) -> bool {
        self.limiter.at_rest(target_deg)
    }

    /// Restarts the profile at rest at `position_deg` (e.g. from a measured position).
    pub const fn reset(&mut self, position_deg: f64) {
        self.limiter = motion::Limiter::new(position_deg);
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
        Self::plan_checked(from_deg, to_deg, limits, max_points, || {
            Ok::<(), std::convert::Infallible>(())
        })
        .unwrap_or_else(|never| match never {})
    }

    /// [`Profile::plan`], calling `check` before every 4096th point (the first one too):
    /// its error ends the planning (a run stopped while its long move was being planned).
    ///
    /// # Errors
    ///
    /// The first error `check` returns.
    pub fn plan_checked<E>(
        from_deg: f64,
        to_deg: f64,
        limits: MotionLimits,
        max_points: usize,
        mut check: impl FnMut() -> Result<(), E>,
    ) -> Result<Option<Vec<f64>>, E> {
        let dt = limits.period.as_secs_f64();
        let mut p = Self::new(from_deg, limits);
        let mut points = Vec::new();
        loop {
            if points.len() >= max_points {
                return Ok(None);
            }
            if points.len() % PLAN_CHECK_EVERY == 0 {
                check()?;
            }
            points.push(p.step(to_deg, dt));
            if p.at_rest(to_deg) {
                return Ok(Some(points));
            }
        }
    }

    /// Advances by `dt` seconds toward `target_deg` and returns the new set-point.
    pub fn step(&mut self, target_deg: f64, dt: f64) -> f64 {
        self.limiter.step(
            target_deg,
            dt,
            self.limits.max_speed_deg_s,
            self.limits.max_accel_deg_s2,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_far_move_is_planned_as_a_trapezoid_ending_exactly_on_the_target() {
        let limits = MotionLimits::default();
        let points = Profile::plan(0.0, 90.0, limits, 10_000).unwrap();
        // 0.6 °/s more per 5 ms step: 50 steps up to 30 °/s (3.825°), 49 down (3.675°),
        // and the other 82.5° at 0.15° a step: 550 steps.
        assert_eq!(points.len(), 50 + 550 + 49);
        assert_eq!(points.last(), Some(&90.0));
        let mut last = 0.0;
        for &x in &points {
            assert!(x >= last && x - last <= 0.15 + 1e-9, "{last} -> {x}");
            last = x;
        }
        assert_eq!(Profile::plan(0.0, 90.0, limits, 648), None);
    }
}
