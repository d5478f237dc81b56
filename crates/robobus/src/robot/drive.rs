//! Velocity and effort on a robot's joints: the limits and ramps of each target, the
//! frames that carry them (WHJ speed and current servo frames, wCK wheel commands), and
//! the checked switch of a joint's interface.

use robobus_wck::{Rotation, WheelSpeed};
use robobus_whj::WorkMode;
use robobus_whj::units::{Current, TargetSpeed};

use super::guard::Sensed;
use super::hardware::{Device, Hardware, sensed_of};
use super::interface::{Interface, wheel_command};
use super::{ActuatorError, Duration, LimitEvent, LimitKind, RateLimiter, RobotError, whj_to_rad};
use crate::actuator::rpm_to_rad_s;

/// A joint counts as at rest for an interface switch below this measured speed, rad/s
/// (about 3 °/s: a joint held in place reads a little noise).
pub(super) const AT_REST_RAD_S: f64 = 0.05;

/// One joint's velocity or effort for this cycle, after its limits: what goes on the wire.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Out {
    /// A WHJ speed servo frame, RPM at the device.
    Speed(TargetSpeed),
    /// A WHJ current servo frame, mA at the device.
    Current(f64),
    /// A wCK wheel command.
    Wheel(Rotation, WheelSpeed),
}

fn approach(from: f64, to: f64, step: f64) -> f64 {
    if (to - from).abs() <= step {
        to
    } else {
        from + step.copysign(to - from)
    }
}

impl Hardware {
    /// Joint `index`'s angle now (rad): a WHJ joint's telemetry under 100 ms old, else a
    /// read.
    pub(super) fn angle_now(&mut self, index: usize) -> Result<f64, RobotError> {
        if let Some(Device::Whj { bus, id, map, .. }) = self.joints.get(index).map(|j| j.device)
            && let Some(slot) = self.whj.get(bus)
        {
            let telemetry = slot.bus.telemetry();
            let t = telemetry.joint(id);
            if let (Some(p), Some(at)) = (t.position, t.updated)
                && slot.bus.now().saturating_duration_since(at) < Duration::from_millis(100)
            {
                return Ok(whj_to_rad(map, p));
            }
        }
        Ok(self.actuator(index)?.position()?)
    }

    /// Checks a velocity (rad/s) or effort (N·m) target of joint `index` against what its
    /// device can do: a `Target` error naming the joint, the value and the range, else
    /// `Ok`. Sends nothing.
    pub(super) fn check_target(
        &self,
        index: usize,
        interface: Interface,
        value: f64,
    ) -> Result<(), RobotError> {
        let Some(joint) = self.joints.get(index) else {
            return Ok(());
        };
        let refuse = |expected: String| RobotError::Target {
            joint: joint.name.clone(),
            interface,
            value,
            expected,
        };
        if !value.is_finite() {
            return Err(refuse("a finite number".into()));
        }
        let d = &joint.drive;
        match interface {
            Interface::Position => {}
            Interface::Velocity => {
                let v = value.clamp(
                    -joint.limits.max_velocity_rad_s,
                    joint.limits.max_velocity_rad_s,
                );
                if let Some(wheel) = &d.wheel
                    && wheel.level(v).is_none()
                {
                    let top = wheel.top();
                    return Err(refuse(format!(
                        "-{top:.3}..={top:.3} rad/s, what the wCK servo's wheel levels 0..=15 \
                         turn it at (wheel_speeds)"
                    )));
                }
                if let Some(peak) = d.peak_rad_s
                    && v.abs() > peak + 1e-9
                {
                    return Err(refuse(format!(
                        "-{peak:.4}..={peak:.4} rad/s, the joint model's peak output speed"
                    )));
                }
            }
            Interface::Effort => {
                if let Some(scale) = d.effort_scale
                    && value.clamp(-d.max_effort, d.max_effort).abs() > scale.peak_nm + 1e-9
                {
                    let peak = scale.peak_nm;
                    return Err(refuse(format!(
                        "-{peak}..={peak} N·m, the joint model's peak torque"
                    )));
                }
            }
        }
        Ok(())
    }

    /// Joint `index`'s velocity or effort for this cycle, `dt_s` after the last: clamped
    /// to its `max_velocity` / `max_effort`, ramped at its `max_acceleration` /
    /// `max_effort_rate`, and (a WHJ joint) never towards a soft limit faster than it can
    /// stop there at `max_acceleration` (an effort towards a limit it stands on is
    /// dropped). A joint the host's protection derates for heat keeps its share of
    /// `max_velocity` / `max_effort`. Returns the frame and the value it carries in the
    /// joint's unit (a wCK speed at its wheel level); records the set-point and every
    /// limit that acted.
    pub(super) fn plan(
        &mut self,
        index: usize,
        interface: Interface,
        target: f64,
        dt_s: f64,
        limited: &mut Vec<LimitEvent>,
    ) -> Result<(Out, f64), RobotError> {
        let whj_angle = match self.joints.get(index).map(|j| j.device) {
            Some(Device::Whj { .. }) => Some(self.angle_now(index)?),
            _ => None,
        };
        let Some(joint) = self.joints.get_mut(index) else {
            return Err(RobotError::NoSuchJoint {
                index,
                names: String::new(),
            });
        };
        let mut event = |kind, requested: f64, result: f64| {
            if (requested - result).abs() > 1e-12 {
                limited.push(LimitEvent {
                    joint: joint.name.clone(),
                    interface,
                    kind,
                    requested_rad: requested,
                    limited_rad: result,
                });
            }
        };
        let (limits, share) = (joint.limits, self.guard.share(index));
        let d = &mut joint.drive;
        let (most, rate, previous) = match interface {
            Interface::Velocity => (
                limits.max_velocity_rad_s * share,
                limits.max_acceleration_rad_s2,
                d.velocity,
            ),
            _ => (d.max_effort * share, d.effort_rate, d.effort),
        };
        let clamped = target.clamp(-most, most);
        event(LimitKind::Motion, target, clamped);
        let ramped = approach(previous, clamped, rate * dt_s);
        event(LimitKind::Motion, clamped, ramped);
        let mut set = ramped;
        if let Some(at) = whj_angle {
            // The room to the limit ahead, less what the joint covers at its last
            // set-point before this one takes effect (the angle read is a cycle old).
            let room = if set > 0.0 {
                limits.max_rad - at
            } else {
                at - limits.min_rad
            };
            let room = (room - previous.abs() * dt_s).max(0.0);
            let bounded = match interface {
                Interface::Velocity => {
                    let stop = (2.0 * limits.max_acceleration_rad_s2 * room).sqrt();
                    set.clamp(-stop, stop)
                }
                _ if room <= 0.0 => 0.0,
                _ => set,
            };
            event(LimitKind::Position, set, bounded);
            set = bounded;
        }
        match interface {
            Interface::Velocity => d.velocity = set,
            _ => d.effort = set,
        }
        let device_sign = |reversed: bool| if reversed { -1.0 } else { 1.0 };
        let (wheel, effort_scale) = (d.wheel.clone(), d.effort_scale);
        let name = joint.name.clone();
        match (joint.device, interface) {
            (Device::Wck { scale, .. }, Interface::Velocity) => {
                let wheel = wheel.ok_or_else(|| missing(&name, interface))?;
                let (level, speed) = wheel.level(set).unwrap_or((0, 0.0));
                let (rotation, level) =
                    wheel_command(level, speed * device_sign(scale.map.reversed));
                let level = level.ok_or_else(|| missing(&name, interface))?;
                Ok((Out::Wheel(rotation, level), speed))
            }
            (Device::Whj { map, .. }, Interface::Velocity) => {
                let rpm = set * device_sign(map.reversed) * 60.0 / core::f64::consts::TAU;
                let target = TargetSpeed::from_rpm(rpm).map_err(|_| RobotError::Target {
                    joint: name.clone(),
                    interface,
                    value: set,
                    expected: "a speed the speed register holds".into(),
                })?;
                let sent_rad_s = rpm_to_rad_s(target.rpm()) * device_sign(map.reversed);
                Ok((Out::Speed(target), sent_rad_s))
            }
            (Device::Whj { map, current, .. }, Interface::Effort) => {
                let k = effort_scale.ok_or_else(|| missing(&name, interface))?;
                let ma = set / k.nm_per_a * 1e3 * device_sign(map.reversed);
                let counts =
                    Current::from_milliamps(ma, current).map_err(|_| RobotError::Target {
                        joint: name.clone(),
                        interface,
                        value: set,
                        expected: "a current the current register holds".into(),
                    })?;
                #[allow(clippy::cast_precision_loss)] // |mA| < 2^31
                let sent_ma = counts.milliamps(current) as f64;
                Ok((
                    Out::Current(sent_ma),
                    sent_ma / 1e3 * k.nm_per_a * device_sign(map.reversed),
                ))
            }
            _ => Err(missing(&name, interface)),
        }
    }

    /// Sends the planned velocity and effort `outs` (joint index, frame): each wCK wheel
    /// command in turn, then per WHJ bus its speed and current servo frames in one
    /// pipelined batch ([`JointBus::servo_many`](crate::whj::JointBus::servo_many)); what
    /// each WHJ joint's frame answered, in the order of `outs`. The first failure (wCK
    /// first, then by bus and joint order) is the error.
    pub(super) fn send_outs(
        &mut self,
        outs: &[(usize, Out)],
    ) -> Result<Vec<Option<Sensed>>, RobotError> {
        let mut sensed = vec![None; outs.len()];
        for &(index, out) in outs {
            let (Some(joint), Out::Wheel(rotation, level)) = (self.joints.get(index), out) else {
                continue;
            };
            if let Device::Wck { bus, id, .. } = joint.device {
                let name = joint.name.clone();
                if let Some(slot) = self.wck.get_mut(bus) {
                    slot.bus
                        .servo(id)
                        .wheel(rotation, level)
                        .map_err(|e| wck_error(&name, e))?;
                }
            }
        }
        for (b, slot) in self.whj.iter().enumerate() {
            // This bus's frames: (position in `outs`, joint name, the frame).
            let mut batch = Vec::new();
            for (k, &(index, out)) in outs.iter().enumerate() {
                let Some(joint) = self.joints.get(index) else {
                    continue;
                };
                let Device::Whj {
                    bus, id, current, ..
                } = joint.device
                else {
                    continue;
                };
                if bus != b {
                    continue;
                }
                let frame = match out {
                    Out::Speed(target) => robobus_whj::Request::SpeedServo { joint: id, target },
                    Out::Current(ma) => robobus_whj::Request::CurrentServo {
                        joint: id,
                        target: Current::from_milliamps(ma, current).map_err(|source| {
                            whj_error(
                                &joint.name,
                                crate::whj::WhjError::Unit { joint: id, source },
                            )
                        })?,
                    },
                    Out::Wheel(..) => continue,
                };
                batch.push((k, index, frame));
            }
            if batch.is_empty() {
                continue;
            }
            let name = |index: usize| self.joints.get(index).map_or("", |j| j.name.as_str());
            let frames: Vec<_> = batch.iter().map(|b| b.2).collect();
            let answers = slot
                .bus
                .servo_many(&frames)
                .map_err(|e| whj_error(name(batch.first().map_or(0, |b| b.1)), e))?;
            for (&(k, index, _), answer) in batch.iter().zip(answers) {
                let fb = answer.map_err(|e| whj_error(name(index), e))?;
                if let (Some(s), Some(Device::Whj { map, current, .. })) =
                    (sensed.get_mut(k), self.joints.get(index).map(|j| j.device))
                {
                    *s = Some(sensed_of(&fb, map, current));
                }
            }
        }
        Ok(sensed)
    }

    /// Why joint `index` may not switch its interface now: it is moving (its set-point is
    /// not at rest, or a WHJ joint's measured speed is not). Reads a WHJ joint's speed.
    pub(super) fn moving(&mut self, index: usize) -> Result<Option<String>, RobotError> {
        let Some(joint) = self.joints.get(index) else {
            return Ok(None);
        };
        let d = &joint.drive;
        let set = match d.active {
            Interface::Position => joint.limiter.velocity_rad_s(),
            Interface::Velocity => d.velocity,
            Interface::Effort => d.effort,
        };
        if set != 0.0 {
            return Ok(Some(format!(
                "its {} set-point is {set} {}, not 0: command it to rest first",
                d.active,
                match d.active {
                    Interface::Position => "rad/s",
                    other => other.unit(),
                }
            )));
        }
        if let Device::Whj { bus, id, map, .. } = joint.device
            && let Some(slot) = self.whj.get(bus)
        {
            let name = joint.name.clone();
            let rpm = slot
                .bus
                .joint_unchecked(id)
                .speed()
                .map_err(|e| whj_error(&name, e))?
                .rpm();
            let speed = map.speed_to_joint(rpm_to_rad_s(rpm));
            if speed.abs() > AT_REST_RAD_S {
                return Ok(Some(format!(
                    "it turns at {speed:.3} rad/s (at rest below {AT_REST_RAD_S} rad/s)"
                )));
            }
        }
        Ok(None)
    }

    /// Switches joint `index` to `to` and leaves it safe there: a WHJ joint's work mode
    /// changes (the joint takes its angle as the position target and zero speed and
    /// current, §6.2) and a zero speed or current target follows; a wCK servo enters
    /// wheel mode at level 0 (stopped) or leaves it with a move to where it stands. A joint
    /// entering position restarts its speed limiting at its angle.
    pub(super) fn switch(&mut self, index: usize, to: Interface) -> Result<(), RobotError> {
        let Some(joint) = self.joints.get(index) else {
            return Ok(());
        };
        let name = joint.name.clone();
        match joint.device {
            Device::Whj { bus, id, .. } => {
                if let Some(slot) = self.whj.get(bus) {
                    let j = slot.bus.joint_unchecked(id);
                    let mode = match to {
                        Interface::Position => WorkMode::Position,
                        Interface::Velocity => WorkMode::Speed,
                        Interface::Effort => WorkMode::Current,
                    };
                    let done = j.set_mode(mode).and_then(|()| match to {
                        Interface::Position => Ok(()),
                        Interface::Velocity => j.command_speed(TargetSpeed(0)).map(drop),
                        Interface::Effort => j.command_current(0.0).map(drop),
                    });
                    done.map_err(|e| whj_error(&name, e))?;
                }
            }
            Device::Wck { bus, id, .. } => {
                if let Some(slot) = self.wck.get_mut(bus) {
                    let torque = slot.torque;
                    let mut servo = slot.bus.servo(id);
                    let done = match to {
                        Interface::Velocity => {
                            servo.wheel(Rotation::Ccw, WheelSpeed::MIN).map(drop)
                        }
                        _ => servo
                            .status()
                            .and_then(|s| servo.move_to(torque, s.position).map(drop)),
                    };
                    done.map_err(|e| wck_error(&name, e))?;
                }
            }
        }
        let at = if to == Interface::Position {
            Some(self.actuator(index)?.position()?)
        } else {
            None
        };
        if let Some(joint) = self.joints.get_mut(index) {
            joint.drive.resting();
            joint.drive.active = to;
            if let Some(at) = at {
                joint.limiter = RateLimiter::new(at);
            }
        }
        self.guard.restart(index);
        Ok(())
    }

    /// Every joint back on its position interface (after a safe stop): a WHJ joint not in
    /// position mode is switched to it (what [`enable_whj`](Self::enable_whj) then enables).
    pub(super) fn back_to_position(&mut self) -> Result<(), RobotError> {
        for joint in &mut self.joints {
            if joint.drive.active != Interface::Position
                && let Device::Whj { bus, id, .. } = joint.device
                && let Some(slot) = self.whj.get(bus)
            {
                slot.bus
                    .joint_unchecked(id)
                    .set_mode(WorkMode::Position)
                    .map_err(|e| whj_error(&joint.name, e))?;
            }
            joint.drive.resting();
        }
        Ok(())
    }
}

fn missing(joint: &str, interface: Interface) -> RobotError {
    RobotError::Target {
        joint: joint.to_owned(),
        interface,
        value: 0.0,
        expected: "an interface the joint has".into(),
    }
}

fn wck_error(joint: &str, source: crate::wck::WckError) -> RobotError {
    ActuatorError::Wck {
        joint: joint.to_owned(),
        source: Box::new(source),
    }
    .into()
}

fn whj_error(joint: &str, source: crate::whj::WhjError) -> RobotError {
    ActuatorError::Whj {
        joint: joint.to_owned(),
        source: Box::new(source),
    }
    .into()
}
