//! The one motion limiter: a set-point that follows a (possibly changing) target with
//! limited speed and acceleration, never steps past the target and lands exactly on it.
//!
//! [`robot::RateLimiter`](crate::robot::RateLimiter) (radians, a robot file's joint
//! limits) and [`whj::Profile`](crate::whj::Profile) (degrees, a WHJ move's limits) are
//! this limiter in their units. Beside it, [`Tracking`]: how closely a joint followed
//! what it was asked for.
//!
//! The rule, per step of `dt` seconds with speed limit `v` and acceleration limit `a`
//! (`dv = a·dt`, the largest speed change per step):
//!
//! 1. **Land** when the target is reachable this step within both limits (the step's
//!    speed is at most `v` and `dv`, and at most `dv` away from the current speed): the
//!    set-point is the target, the speed 0.
//! 2. Otherwise aim for the fastest speed that can still stop on the target in whole
//!    steps, each `dv` slower than the one before (the discrete braking curve: moving
//!    `u·dv` now and braking after covers `dv·dt·(n+1)·(u − n/2)`, `n = ⌊u⌋`), no faster
//!    than `v` and than reaching the target this step; change the speed by at most `dv`.
//! 3. **Never step past the target**: a step that would reach or pass it stops on it
//!    (only ever a slow-down; with a target that stays put the braking curve makes this
//!    an exact landing by rule 1 instead).

/// A speed- and acceleration-limited set-point, in whatever unit its caller uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limiter {
    position: f64,
    speed: f64,
}

impl Limiter {
    /// A limiter at rest at `position`.
    pub const fn new(position: f64) -> Self {
        Self {
            position,
            speed: 0.0,
        }
    }

    /// A limiter at `position` moving at `speed` (units per second).
    pub const fn moving(position: f64, speed: f64) -> Self {
        Self { position, speed }
    }

    /// The current set-point.
    pub const fn position(&self) -> f64 {
        self.position
    }

    /// The current set-point speed, units per second.
    pub const fn speed(&self) -> f64 {
        self.speed
    }

    /// Whether the set-point rests at `target`.
    #[allow(clippy::float_cmp)] // the limiter lands exactly on the target
    pub fn at_rest(&self, target: f64) -> bool {
        self.position == target && self.speed == 0.0
    }

    /// Advances by `dt` seconds toward `target` with speed at most `max_speed` and
    /// acceleration at most `max_accel` (units per second, per second²) and returns the
    /// new set-point. A non-finite or non-positive `dt`, target or limit changes nothing.
    pub fn step(&mut self, target: f64, dt: f64, max_speed: f64, max_accel: f64) -> f64 {
        let positive = |x: f64| x.is_finite() && x > 0.0;
        if !(positive(dt) && positive(max_speed) && positive(max_accel) && target.is_finite()) {
            return self.position;
        }
        let dv = max_accel * dt;
        let error = target - self.position;
        let landing = error / dt;
        // (A rounding error's worth of slack, so that a landing is not missed by 1 ulp.)
        let slack = 1.0 + 1e-9;
        if landing.abs() <= max_speed.min(dv) * slack && (landing - self.speed).abs() <= dv * slack
        {
            self.land(target);
            return target;
        }
        // The braking curve in steps: distance to go in units of dv·dt.
        let to_go = error.abs() / (dv * dt);
        let n = (((1.0 + 8.0 * to_go).sqrt() - 1.0) / 2.0).floor();
        let braking = dv * (to_go / (n + 1.0) + n / 2.0);
        let wanted = error.signum() * max_speed.min(braking).min(error.abs() / dt);
        let speed =
            (self.speed + (wanted - self.speed).clamp(-dv, dv)).clamp(-max_speed, max_speed);
        let next = self.position + speed * dt;
        if (target - next) * error <= 0.0 {
            self.land(target);
            return target;
        }
        self.position = next;
        self.speed = speed;
        next
    }

    const fn land(&mut self, target: f64) {
        self.position = target;
        self.speed = 0.0;
    }
}

/// The set-point a joint may be sent when it was last measured at `measured`: `set_point`
/// itself when it lies within `step_limit` of it, else the nearest point that does (a
/// joint refuses, and latches an error for, a target too far from where it *is*, not from
/// its previous target). The one rule of the WHJ cyclic loop and of planned move / wave
/// streams; a non-finite or negative `step_limit` changes nothing.
#[must_use]
pub fn within_step(set_point: f64, measured: f64, step_limit: f64) -> f64 {
    if !(step_limit.is_finite() && step_limit >= 0.0 && measured.is_finite()) {
        return set_point;
    }
    set_point.clamp(measured - step_limit, measured + step_limit)
}

/// How closely a joint followed what it was asked for: the RMS and the largest of
/// |measured − wanted| over the samples compared. The one measure of every report that
/// says how a joint tracked: a WHJ wave's
/// ([`WaveReport::tracking_rms`](crate::ops::whj::WaveReport::tracking_rms)), `robot.play`'s
/// and `robot.teleop`'s rows (`tracking_rms_deg`, `tracking_max_deg`) and the demo's arm.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Tracking {
    sum_sq: f64,
    max: f64,
    samples: u64,
}

impl Tracking {
    /// Compares one measurement with what was wanted.
    pub fn add(&mut self, measured: f64, wanted: f64) {
        let e = (measured - wanted).abs();
        self.sum_sq += e * e;
        self.max = self.max.max(e);
        self.samples += 1;
    }

    /// Samples compared.
    pub const fn samples(&self) -> u64 {
        self.samples
    }

    /// The RMS error (`None` before the first sample).
    pub fn rms(&self) -> Option<f64> {
        #[allow(clippy::cast_precision_loss)] // counts far below 2^52
        (self.samples > 0).then(|| (self.sum_sq / self.samples as f64).sqrt())
    }

    /// The largest error (`None` before the first sample).
    pub fn max(&self) -> Option<f64> {
        (self.samples > 0).then_some(self.max)
    }
}

#[cfg(test)]
#[allow(clippy::float_cmp)] // the limiter lands exactly: exact values are the point
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Every set-point from rest at `from` to rest at `to`.
    fn run(from: f64, to: f64, dt: f64, v: f64, a: f64) -> Vec<f64> {
        let mut l = Limiter::new(from);
        let mut points = Vec::new();
        while !l.at_rest(to) {
            points.push(l.step(to, dt, v, a));
            assert!(points.len() < 100_000, "never arrived");
        }
        points
    }

    #[test]
    fn a_short_move_is_a_triangle_of_whole_speed_steps_landing_on_the_target() {
        // dv·dt = 1 (a = 1, dt = 1): 16 = 1+2+3+4+3+2+1 → speeds rise by 1 to 4 and fall.
        let points = run(0.0, 16.0, 1.0, 100.0, 1.0);
        assert_eq!(points, [1.0, 3.0, 6.0, 10.0, 13.0, 15.0, 16.0]);
    }

    #[test]
    fn a_distance_between_triangles_holds_the_top_speed_and_lands_without_a_jump() {
        // 12 = 1+2+3+3+2+1: the top speed is held one step, then the same ramp down.
        let points = run(0.0, 12.0, 1.0, 100.0, 1.0);
        assert_eq!(points, [1.0, 3.0, 6.0, 9.0, 11.0, 12.0]);
    }

    #[test]
    fn cruises_at_the_speed_limit_and_never_passes_the_target() {
        // v = 2 per step: 1, 2, 2, ..., then braking 1 and landing.
        let points = run(0.0, 9.0, 1.0, 2.0, 1.0);
        assert_eq!(points, [1.0, 3.0, 5.0, 7.0, 8.5, 9.0]);
    }

    #[test]
    fn a_target_that_jumps_behind_the_set_point_stops_it_on_the_target() {
        let mut l = Limiter::new(0.0);
        for _ in 0..5 {
            l.step(100.0, 1.0, 100.0, 1.0);
        }
        assert_eq!((l.position(), l.speed()), (15.0, 5.0));
        // The new target 16 is 1 ahead: reaching it needs slowing from 5 to 1 (more than
        // dv), so the step stops on it rather than past it.
        assert_eq!(l.step(16.0, 1.0, 100.0, 1.0), 16.0);
        assert!(l.at_rest(16.0));
    }

    #[test]
    fn bad_steps_change_nothing() {
        let mut l = Limiter::new(1.0);
        for (dt, v, a, t) in [
            (0.0, 1.0, 1.0, 2.0),
            (f64::NAN, 1.0, 1.0, 2.0),
            (1.0, 0.0, 1.0, 2.0),
            (1.0, 1.0, -1.0, 2.0),
            (1.0, 1.0, 1.0, f64::INFINITY),
        ] {
            assert_eq!(l.step(t, dt, v, a), 1.0);
        }
        assert!(l.at_rest(1.0));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]

        /// A target that stays put: speed and acceleration stay within their limits on
        /// every step (the landing too), the set-point never passes the target, and it
        /// arrives no later than a trapezoid of the limits allows (plus a step per ramp).
        #[test]
        fn a_fixed_target_is_reached_within_the_limits_without_overshoot(
            start in -400.0f64..400.0,
            target in -400.0f64..400.0,
            v in 1.0f64..200.0,
            a in 5.0f64..2000.0,
            dt in 0.0005f64..0.02,
        ) {
            let mut l = Limiter::new(start);
            let (mut prev_x, mut prev_v) = (start, 0.0);
            let dist = (target - start).abs();
            let bound = ((dist / v + v / a) / dt + 3.0).max(2.0 * (dist / (a * dt * dt)).sqrt() + 3.0);
            let mut n = 0.0;
            while !l.at_rest(target) {
                let x = l.step(target, dt, v, a);
                let speed = (x - prev_x) / dt;
                prop_assert!(speed.abs() <= v * (1.0 + 1e-9), "speed {speed} > {v}");
                // A relative 1e-4 of slack: over tens of thousands of steps the set-point
                // carries the rounding of |x|·ε per step, which the braking curve takes up
                // at the landing (seen: 9.4e-6 of dv after 22,404 steps of 0.5 ms to
                // -247.9°; proptest-regressions/motion.txt keeps the case).
                prop_assert!(
                    (speed - prev_v).abs() <= a * dt * (1.0 + 1e-4) + 1e-9,
                    "speed change {} > {}", (speed - prev_v).abs(), a * dt
                );
                prop_assert!((target - x) * (target - start) >= 0.0, "passed the target at {x}");
                (prev_x, prev_v) = (x, speed);
                n += 1.0;
                prop_assert!(n <= bound, "not there after {n} steps (bound {bound})");
            }
            // The landing's speed can brake to rest within one step.
            prop_assert!(prev_v.abs() <= a * dt * (1.0 + 1e-4) + 1e-9);
        }

        /// Any stream of targets: never faster than the speed limit, never past the target
        /// of the step, and the speed only grows by at most `dv` per step.
        #[test]
        fn a_changing_target_is_never_passed(
            start in -3.0f64..3.0,
            targets in proptest::collection::vec(-3.0f64..3.0, 1..80),
            v in 0.1f64..5.0,
            a in 0.5f64..50.0,
            dt in 0.001f64..0.05,
        ) {
            let mut l = Limiter::new(start);
            for t in targets {
                let (before, before_v) = (l.position(), l.speed());
                let after = l.step(t, dt, v, a);
                let speed = (after - before) / dt;
                prop_assert!(speed.abs() <= v * (1.0 + 1e-9), "speed {speed} > {v}");
                prop_assert!((t - after) * (t - before) >= 0.0, "passed {t}: {before} -> {after}");
                prop_assert!(
                    l.speed().abs() <= before_v.abs() + a * dt * (1.0 + 1e-9),
                    "speed grew from {before_v} to {}", l.speed()
                );
            }
        }
    }
}
