//! The host's protection as the robot's devices meet it (see `robot/guard.rs`): a
//! wCK servo's reading when its status read is due, and a stop through the one guard.

use std::time::Instant;

use super::{Device, Hardware};
use crate::ops::protect::{self, Fault};
use crate::robot::guard::Sensed;
use crate::robot::interface::Interface;
use crate::robot::{
    ActuatorError, Position, RateLimiter, RobotError, SafeState, ServoId, ServoLoop, WckServos,
    WhjJoints,
};

impl Hardware {
    /// Wck servo `index`'s reading for the protection at `now`, when its status read is
    /// due (see [`WCK_READ_EVERY`](crate::robot::WCK_READ_EVERY)): where it is, its load as a current
    /// ([`protect::wck_load_a`]) and its speed since the read before; `None` for a WHJ
    /// joint or when not due. A servo that does not answer is the error.
    pub(in crate::robot) fn wck_reading(
        &mut self,
        index: usize,
        now: Instant,
    ) -> Result<Option<Sensed>, RobotError> {
        let Some(joint) = self.joints.get(index) else {
            return Ok(None);
        };
        let Device::Wck { bus, id, scale } = joint.device else {
            return Ok(None);
        };
        let wck: Vec<usize> = self
            .joints
            .iter()
            .enumerate()
            .filter(|(_, j)| matches!(j.device, Device::Wck { .. }))
            .map(|(i, _)| i)
            .collect();
        let rank = wck.iter().position(|&i| i == index).unwrap_or(0);
        if !self.guard.wck_due(index, now, (rank, wck.len())) {
            return Ok(None);
        }
        let Some(slot) = self.wck.get_mut(bus) else {
            return Ok(None);
        };
        let status = slot
            .bus
            .servo(id)
            .status()
            .map_err(|source| ActuatorError::Wck {
                joint: joint.name.clone(),
                source: Box::new(source),
            })?;
        let rad = scale.to_rad(status.position);
        let edge = status.position == Position::MIN || status.position == Position::MAX;
        let last = self.guard.wck_last.get_mut(index);
        let speed_rad_s = last
            .as_ref()
            .and_then(|l| **l)
            .and_then(|(t, before, was_edge)| {
                let dt = now.saturating_duration_since(t).as_secs_f64();
                let changed = (rad - before).abs() > 1e-9;
                // A reading at the end of the range says nothing of the speed.
                (dt > 0.0 && !(changed && (edge || was_edge))).then(|| (rad - before) / dt)
            });
        if let Some(l) = last {
            *l = Some((now, rad, edge));
        }
        let wheel = self
            .joints
            .get(index)
            .is_some_and(|j| j.drive.active == Interface::Velocity);
        // A wheel's first read, with no speed yet, is where its next is measured from.
        if wheel && speed_rad_s.is_none() {
            return Ok(None);
        }
        Ok(Some(Sensed {
            position_rad: rad,
            speed_rad_s: speed_rad_s.unwrap_or(0.0),
            current_a: protect::wck_load_a(status.load.get()),
        }))
    }

    /// Brings joint `index`, which tripped, to rest through the one guard (see the
    /// [module](self)); what it did, for the error's text.
    pub(in crate::robot) fn protection_stop(&mut self, index: usize) -> String {
        let model = self.guard.model(index);
        let Some(joint) = self.joints.get(index) else {
            return String::new();
        };
        let (bus, id) = match joint.device {
            Device::Whj { bus, id, .. } => (bus, id),
            Device::Wck { bus, id, .. } => return self.wck_protection_stop(index, bus, id),
        };
        let name = joint.name.clone();
        if joint.drive.active != Interface::Position {
            // A zero target, then back on position (the joint takes its angle as its
            // target).
            let _ = self.switch(index, Interface::Position);
        }
        let (state, what) = if protect::torque_off_is_safe(model) {
            (
                SafeState::Disable,
                "its drive disabled (its brake holds it: holding would keep it pushing or \
                 heating)",
            )
        } else {
            (SafeState::Hold, "held where it stands")
        };
        let Some(slot) = self.whj.get(bus) else {
            return String::new();
        };
        let handle = [slot.bus.joint_unchecked(id)];
        let failed = state.apply(&mut WhjJoints {
            joints: &handle,
            servo: ServoLoop::Position,
        });
        if let Some(j) = self.joints.get_mut(index) {
            j.drive.resting();
        }
        match failed.first() {
            None => what.to_owned(),
            Some(f) => {
                tracing::warn!(joint = %name, "protection stop incomplete: {}", f.error);
                format!(
                    "it did not reach its safe state ({}): {}",
                    state.keyword(),
                    f.error
                )
            }
        }
    }

    /// Brings wCK servo `index` (`id` on bus `bus`), which tripped, to rest: a wheel
    /// back on position (level 0), then the bus's safe state if it is the break (every
    /// module), else the servo passive; never held (holding would keep it pushing).
    fn wck_protection_stop(&mut self, index: usize, bus: usize, id: ServoId) -> String {
        if self
            .joints
            .get(index)
            .is_some_and(|j| j.drive.active != Interface::Position)
        {
            let _ = self.switch(index, Interface::Position);
        }
        let Some(slot) = self.wck.get_mut(bus) else {
            return String::new();
        };
        let (state, what) = if slot.safe == SafeState::Break {
            (SafeState::Break, "its bus's break (every module)")
        } else {
            (
                SafeState::Passive,
                "passive (its torque off: holding would keep it pushing)",
            )
        };
        let failed = state.apply(&mut WckServos {
            bus: &mut slot.bus,
            ids: &[id],
            torque: slot.torque,
        });
        if let Some(j) = self.joints.get_mut(index) {
            j.drive.resting();
        }
        match failed.first() {
            None => what.to_owned(),
            Some(f) => {
                tracing::warn!(servo = id.get(), "protection stop incomplete: {}", f.error);
                format!(
                    "it did not reach its safe state ({}): {}",
                    state.keyword(),
                    f.error
                )
            }
        }
    }

    /// Brings back the joints the protection stopped: on position, a WHJ joint enabled,
    /// its speed limiting restarted at its measured angle, its watch afresh; the stops
    /// they had.
    pub(in crate::robot) fn clear_protection(&mut self) -> Result<Vec<Fault>, RobotError> {
        let stopped: Vec<(usize, Fault)> = self
            .guard
            .stopped
            .iter()
            .enumerate()
            .filter_map(|(i, f)| f.clone().map(|f| (i, f)))
            .collect();
        if stopped.is_empty() {
            return Ok(Vec::new());
        }
        self.enable_whj()?;
        for &(i, _) in &stopped {
            let at = self.actuator(i)?.position()?;
            if let Some(j) = self.joints.get_mut(i) {
                j.limiter = RateLimiter::new(at);
            }
            if let Some(s) = self.guard.stopped.get_mut(i) {
                *s = None;
            }
            self.guard.restart(i);
        }
        Ok(stopped.into_iter().map(|(_, f)| f).collect())
    }
}
