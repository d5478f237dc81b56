//! [`Blend::offer`]: a blend checked as the run would check a trajectory (the robot
//! file's limits, the step limits at the run's rate, the pre-flight on the simulator)
//! before the run's tick loop may take it; apart from the handle (`blend.rs`), which the
//! tick loop uses and this check flies.

use std::sync::Arc;

use super::Play;
use super::blend::{Blend, Commanded, lock, parse};
use super::group::{check_steps, groups};
use super::preflight;
use crate::ops::{Control, OpError};
use crate::robot::trajectory::Trajectory;
use crate::robot::trajectory::ros;
use crate::station::Station;

impl Blend {
    /// Checks `blended` (from [`Blend::blended`]) as the run `r` would check it, then
    /// offers it for `at`'s tick: the robot file's limits and `max_velocity`, the step
    /// limits at `r.rate_hz`, and the pre-flight on the simulator where it is on (of the
    /// rest of the run from its last tick to `at`'s, then `blended`, seeded with the
    /// joints as they are). `Ok(true)`: offered, the run takes it at that tick;
    /// `Ok(false)`: too late (the run passed that tick, or ended), nothing changed.
    ///
    /// # Errors
    ///
    /// What the run's own checks refuse a trajectory with (`OpError::Preflight` from the
    /// pre-flight); the run plays on as it was.
    pub fn offer(
        &self,
        station: &Station,
        r: &Play,
        at: &Commanded,
        blended: &Trajectory,
        control: &Control<'_>,
    ) -> Result<bool, OpError> {
        let config = station
            .robot()
            .cloned()
            .ok_or_else(super::super::no_robot)?;
        let index = blended
            .check(&config)
            .map_err(|e| OpError::invalid("trajectory", "(file)", e.to_string()))?;
        let (limits, rest, index_run, period_s) = {
            let g = lock(&self.inner);
            let Some(live) = g.live.as_ref().filter(|l| l.run == at.run) else {
                return Ok(false);
            };
            let course = live.course.with(g.offered.as_ref());
            let now = live.tick.unwrap_or(0);
            #[allow(clippy::cast_precision_loss)] // ticks of at most an hour
            let rest: Vec<(f64, Vec<f64>)> = (now..at.tick)
                .map(|k| {
                    let dt = (k - now) as f64 * live.period_s;
                    (dt, course.at(k as f64 * live.period_s))
                })
                .collect();
            (
                live.step_limits.clone(),
                rest,
                live.index.clone(),
                live.period_s,
            )
        };
        if index != index_run {
            return Ok(false);
        }
        check_steps(&limits, blended, &at.state.position_deg, 0.0, r.rate_hz)?;
        // The rest of the run up to the tick, then the blend: what the joints will be
        // sent from now on.
        #[allow(clippy::cast_precision_loss)] // ticks of at most an hour
        let offset = rest.len() as f64 * period_s;
        let mut rows = rest;
        rows.extend(
            ros::times(blended)
                .into_iter()
                .map(|t| (offset + t, blended.at(t))),
        );
        let composite = parse(&at.joints, &rows)?;
        let (real, _) = groups(station, &config, &composite, &index)?;
        preflight::fly(
            r,
            &config,
            (&composite, &index),
            &real,
            (composite.first(), 0.0),
            control,
        )?;
        let mut g = lock(&self.inner);
        let fits = g
            .live
            .as_ref()
            .is_some_and(|l| l.run == at.run && l.tick.is_none_or(|k| k < at.tick));
        if fits {
            g.offered = Some((at.tick, Arc::new(blended.clone()), at.t_s));
        }
        Ok(fits)
    }
}
