//! A robot's hardware behind its lock: the buses, each joint's device and limits, the
//! robot's clock (its buses' clocks), the watchdog's shared state, and reading and
//! sending in joint units.

mod protection;

use super::guard::Sensed;
use super::interface::{EffortScale, Interface, WheelSpeeds};
use super::{
    ActuatorError, Arc, AtomicBool, CurrentScale, Duration, DynByteLink, Instant, Joint, JointBus,
    JointId, JointLimits, JointMap, Mutex, MutexGuard, Ordering, PoisonError, Position,
    RateLimiter, RobotError, SafeDevice, SafeState, SafeStopReport, ServoId, ServoLoop, StopCause,
    TorqueLevel, WckBus, WckScale, WckServos, WhjJoints, whj_to_rad,
};
use crate::actuator::{Actuator, WckActuator, WhjActuator, rpm_to_rad_s, whj_position};

/// What a WHJ servo frame answered, in the joint frame (`map`; its current in A with the
/// model's `scale`).
pub(super) fn sensed_of(
    fb: &robobus_whj::ServoFeedback,
    map: JointMap,
    scale: CurrentScale,
) -> Sensed {
    #[allow(clippy::cast_precision_loss)] // |mA| < 2^31
    let current_a = fb.current.milliamps(scale) as f64 / 1e3;
    Sensed {
        position_rad: whj_to_rad(map, fb.position),
        speed_rad_s: map.speed_to_joint(rpm_to_rad_s(fb.speed.rpm())),
        current_a,
    }
}

// ----- internals -----------------------------------------------------------------------

pub(super) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

#[derive(Debug)]
pub(super) struct WckSlot {
    pub(super) name: String,
    pub(super) bus: WckBus<DynByteLink>,
    pub(super) torque: TorqueLevel,
    pub(super) safe: SafeState,
    /// The bus clock's instant at the robot's time zero.
    pub(super) origin: Instant,
}

#[derive(Debug)]
pub(super) struct WhjSlot {
    pub(super) name: String,
    pub(super) bus: Arc<JointBus>,
    pub(super) safe: SafeState,
    /// The bus clock's instant at the robot's time zero.
    pub(super) origin: Instant,
}

#[derive(Debug, Clone, Copy)]
pub(super) enum Device {
    Wck {
        bus: usize,
        id: ServoId,
        scale: WckScale,
    },
    Whj {
        bus: usize,
        id: JointId,
        map: JointMap,
        current: CurrentScale,
    },
}

#[derive(Debug)]
pub(super) struct JointSlot {
    pub(super) name: String,
    pub(super) device: Device,
    pub(super) limits: JointLimits,
    pub(super) limiter: RateLimiter,
    /// Its interfaces (the file's) and the one it is commanded in now.
    pub(super) drive: Drive,
}

/// A joint's interfaces, the one in use, and the set-points and limits of velocity and
/// effort (joint frame).
#[derive(Debug, Clone)]
pub(super) struct Drive {
    pub(super) interfaces: Vec<Interface>,
    pub(super) active: Interface,
    /// The velocity set-point, rad/s, before a wCK level's quantisation.
    pub(super) velocity: f64,
    /// The effort set-point, N·m.
    pub(super) effort: f64,
    /// `max_effort`, N·m (0 without effort).
    pub(super) max_effort: f64,
    /// `max_effort_rate` (or its default), N·m/s.
    pub(super) effort_rate: f64,
    /// wCK: what the wheel levels turn it at.
    pub(super) wheel: Option<WheelSpeeds>,
    /// WHJ with effort: its model's torque constant and peak torque.
    pub(super) effort_scale: Option<EffortScale>,
    /// WHJ: its model's peak output speed, rad/s, when the model is known.
    pub(super) peak_rad_s: Option<f64>,
}

impl Drive {
    /// At rest on its position interface.
    pub(super) fn resting(&mut self) {
        self.active = Interface::Position;
        self.velocity = 0.0;
        self.effort = 0.0;
    }
}

#[derive(Debug)]
pub(super) struct Hardware {
    pub(super) wck: Vec<WckSlot>,
    pub(super) whj: Vec<WhjSlot>,
    pub(super) joints: Vec<JointSlot>,
    /// When the previous command cycle ran (or the robot opened / resumed), robot clock.
    pub(super) last_cycle: Instant,
    /// The robot clock's time zero: the `origin` of its first bus (wCK buses first).
    pub(super) origin: Instant,
    /// The host's protection of the robot's commands.
    pub(super) guard: super::guard::Guard,
}

// ----- the robot's clock ---------------------------------------------------------------

impl Hardware {
    /// Whether any bus runs on the wall clock (time passes by itself; the watchdog needs a
    /// thread), or the robot has no bus.
    pub(super) fn wall_time(&self) -> bool {
        (self.wck.is_empty() && self.whj.is_empty())
            || self.wck.iter().any(|s| !s.bus.link().virtual_time())
            || self.whj.iter().any(|s| !s.bus.virtual_time())
    }

    /// The robot's clock now: its buses' clock. On the wall clock that is the wall clock
    /// (read from the first bus); a bus on a virtual clock (a simulator's) moves only when
    /// it is driven, each on its own, so the robot keeps them together: its time is the
    /// furthest any bus has gone since the robot's zero, and every virtual bus behind it is
    /// brought up to it first.
    pub(super) fn now(&mut self) -> Instant {
        if self.wall_time() {
            return self.wck.first().map_or_else(
                || self.whj.first().map_or_else(Instant::now, |s| s.bus.now()),
                |s| s.bus.now(),
            );
        }
        let elapsed = self
            .wck
            .iter()
            .map(|s| s.bus.now().saturating_duration_since(s.origin))
            .chain(
                self.whj
                    .iter()
                    .map(|s| s.bus.now().saturating_duration_since(s.origin)),
            )
            .max()
            .unwrap_or_default();
        self.advance_to(self.origin + elapsed);
        self.origin + elapsed
    }

    /// Brings every bus on a virtual clock to `at` (robot clock); a bus already there, or
    /// on the wall clock, is left alone.
    pub(super) fn advance_to(&mut self, at: Instant) {
        let since_zero = at.saturating_duration_since(self.origin);
        for s in &mut self.wck {
            let there = s.origin + since_zero;
            if s.bus.link().virtual_time() && s.bus.now() < there {
                s.bus.sleep_until(there);
            }
        }
        for s in &self.whj {
            let there = s.origin + since_zero;
            if s.bus.virtual_time() && s.bus.now() < there {
                s.bus.sleep_until(there);
            }
        }
    }
}

#[derive(Debug)]
pub(super) struct Shared {
    pub(super) hw: Mutex<Hardware>,
    /// The last successful command (robot clock); `None` until the first (watchdog
    /// disarmed).
    pub(super) last_command: Mutex<Option<Instant>>,
    pub(super) stopped: Mutex<Option<SafeStopReport>>,
    pub(super) quit: AtomicBool,
    pub(super) timeout: Duration,
}

impl Shared {
    /// Puts every bus in its safe state (once; a second call returns the first report).
    pub(super) fn safe_stop(&self, cause: StopCause) -> SafeStopReport {
        let mut hw = lock(&self.hw);
        self.safe_stop_locked(&mut hw, cause)
    }

    /// [`safe_stop`](Self::safe_stop) with the hardware already locked.
    fn safe_stop_locked(&self, hw: &mut Hardware, cause: StopCause) -> SafeStopReport {
        let mut stopped = lock(&self.stopped);
        if let Some(report) = stopped.as_ref() {
            return report.clone();
        }
        let started = hw.now();
        let errors = hw.apply_safe_states();
        let report = SafeStopReport {
            cause,
            started,
            applied_in: hw.now().saturating_duration_since(started),
            errors,
        };
        if !report.errors.is_empty() {
            tracing::warn!(errors = ?report.errors, "safe stop incomplete");
        }
        *stopped = Some(report.clone());
        *lock(&self.last_command) = None;
        report
    }

    /// The robot clock now, with the watchdog served: when it is armed and the last
    /// command is a timeout or more ago, the safe stop ([`StopCause::Watchdog`]) runs
    /// first. Every call into the robot comes through here, and so does the watchdog
    /// thread of a robot on the wall clock.
    pub(super) fn tick(&self, hw: &mut Hardware) -> Instant {
        let now = hw.now();
        let last = *lock(&self.last_command);
        if let Some(last) = last {
            let since = now.saturating_duration_since(last);
            if since >= self.timeout && lock(&self.stopped).is_none() {
                tracing::warn!(?since, "watchdog: control loop stalled, safe stop");
                self.safe_stop_locked(
                    hw,
                    StopCause::Watchdog {
                        since_command: since,
                    },
                );
                return hw.now();
            }
        }
        now
    }

    /// When the watchdog fires unless a command comes first (robot clock); `None` while
    /// it is disarmed.
    pub(super) fn watchdog_due(&self) -> Option<Instant> {
        lock(&self.last_command).map(|last| last + self.timeout)
    }

    /// The watchdog thread of a robot on the wall clock: every few milliseconds, unless a
    /// call into the robot holds it (and serves the watchdog itself), a [`tick`](Self::tick).
    pub(super) fn watchdog(&self) {
        let poll = (self.timeout / 10).clamp(Duration::from_micros(500), Duration::from_millis(5));
        while !self.quit.load(Ordering::Acquire) {
            std::thread::sleep(poll);
            if lock(&self.last_command).is_none() {
                continue;
            }
            let mut hw = match self.hw.try_lock() {
                Ok(hw) => hw,
                Err(std::sync::TryLockError::Poisoned(p)) => p.into_inner(),
                Err(std::sync::TryLockError::WouldBlock) => continue,
            };
            self.tick(&mut hw);
        }
    }
}

impl Hardware {
    /// Every bus to its safe state through [`SafeState::apply`] (the operations' safe stop
    /// too); the failures, each naming its joint (or the bus, for the wCK break).
    pub(super) fn apply_safe_states(&mut self) -> Vec<String> {
        let mut errors = Vec::new();
        let name_of = |joints: &[JointSlot], device: SafeDevice| -> Option<String> {
            joints
                .iter()
                .find(|j| match (j.device, device) {
                    (Device::Wck { id, .. }, SafeDevice::Servo(s)) => id.get() == s,
                    (Device::Whj { id, .. }, SafeDevice::Joint(s)) => id.get() == s,
                    _ => false,
                })
                .map(|j| j.name.clone())
        };
        for (b, slot) in self.wck.iter_mut().enumerate() {
            let ids: Vec<ServoId> = self
                .joints
                .iter()
                .filter_map(|j| match j.device {
                    Device::Wck { bus, id, .. } if bus == b => Some(id),
                    _ => None,
                })
                .collect();
            let failed = slot.safe.apply(&mut WckServos {
                bus: &mut slot.bus,
                ids: &ids,
                torque: slot.torque,
            });
            for f in failed {
                let name =
                    name_of(&self.joints, f.device).unwrap_or_else(|| format!("bus {}", slot.name));
                errors.push(format!("{name}: {}: {}", slot.safe.keyword(), f.error));
            }
        }
        for (b, slot) in self.whj.iter().enumerate() {
            // Each joint is held in the loop it runs (a hold in speed or current mode is a
            // zero target).
            for (interface, servo) in [
                (Interface::Position, ServoLoop::Position),
                (Interface::Velocity, ServoLoop::Speed),
                (Interface::Effort, ServoLoop::Current),
            ] {
                let handles: Vec<Joint<'_>> = self
                    .joints
                    .iter()
                    .filter(|j| j.drive.active == interface)
                    .filter_map(|j| match j.device {
                        Device::Whj { bus, id, .. } if bus == b => {
                            Some(slot.bus.joint_unchecked(id))
                        }
                        _ => None,
                    })
                    .collect();
                if handles.is_empty() {
                    continue;
                }
                let failed = slot.safe.apply(&mut WhjJoints {
                    joints: &handles,
                    servo,
                });
                for f in failed {
                    let name = name_of(&self.joints, f.device)
                        .unwrap_or_else(|| format!("bus {}", slot.name));
                    errors.push(format!("{name}: {}: {}", slot.safe.keyword(), f.error));
                }
            }
        }
        for joint in &mut self.joints {
            joint.drive.velocity = 0.0;
            joint.drive.effort = 0.0;
        }
        errors
    }

    /// Joint `index` as an [`Actuator`]: the one way the robot reads and commands a joint
    /// (a wCK servo at its bus's torque, a WHJ joint as connected).
    pub(super) fn actuator(&mut self, index: usize) -> Result<Box<dyn Actuator + '_>, RobotError> {
        let Some(joint) = self.joints.get(index) else {
            return Err(RobotError::NoSuchJoint {
                index,
                names: self
                    .joints
                    .iter()
                    .map(|j| j.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
            });
        };
        let name = joint.name.clone();
        Ok(match joint.device {
            Device::Wck { bus, id, scale } => {
                let slot = &mut self.wck[bus];
                Box::new(WckActuator::new(
                    name,
                    slot.bus.servo(id),
                    scale,
                    joint.limits,
                    slot.torque,
                ))
            }
            Device::Whj {
                bus,
                id,
                map,
                current,
            } => Box::new(self.whj_actuator(name, bus, id, map, joint.limits, current)),
        })
    }

    fn whj_actuator(
        &self,
        name: String,
        bus: usize,
        id: JointId,
        map: JointMap,
        limits: JointLimits,
        current: CurrentScale,
    ) -> WhjActuator<'_> {
        WhjActuator::prepared(
            name,
            self.whj[bus].bus.joint_unchecked(id),
            map,
            limits,
            current,
        )
    }

    /// Prepares every WHJ joint for position commands (a drive that is off: position
    /// mode, enable).
    pub(super) fn enable_whj(&self) -> Result<(), ActuatorError> {
        for joint in &self.joints {
            if let Device::Whj {
                bus,
                id,
                map,
                current,
            } = joint.device
            {
                self.whj_actuator(joint.name.clone(), bus, id, map, joint.limits, current)
                    .ensure_enabled()?;
            }
        }
        Ok(())
    }

    /// Restarts every joint's rate limiter at its measured angle.
    pub(super) fn reset_limiters(&mut self) -> Result<(), RobotError> {
        for i in 0..self.joints.len() {
            let at = self.actuator(i)?.position()?;
            if let Some(joint) = self.joints.get_mut(i) {
                joint.limiter = RateLimiter::new(at);
            }
        }
        self.last_cycle = self.now();
        Ok(())
    }

    /// For each WHJ joint, the set-points it accepts now (joint frame, rad): within 80 %
    /// of the bus's step limit of its measured angle (telemetry under 100 ms old, else a
    /// read); `None` for wCK joints.
    pub(super) fn step_reach(&mut self) -> Result<Vec<Option<(f64, f64)>>, RobotError> {
        let telemetry: Vec<_> = self.whj.iter().map(|s| s.bus.telemetry()).collect();
        let mut reach = Vec::with_capacity(self.joints.len());
        for i in 0..self.joints.len() {
            let Some(&JointSlot {
                device: Device::Whj { bus, id, map, .. },
                drive:
                    Drive {
                        active: Interface::Position,
                        ..
                    },
                ..
            }) = self.joints.get(i)
            else {
                reach.push(None);
                continue;
            };
            let (Some(slot), Some(t)) = (self.whj.get(bus), telemetry.get(bus)) else {
                reach.push(None);
                continue;
            };
            let t = t.joint(id);
            let fresh = match (t.position, t.updated) {
                (Some(p), Some(at))
                    if slot.bus.now().saturating_duration_since(at)
                        < Duration::from_millis(100) =>
                {
                    Some(whj_to_rad(map, p))
                }
                _ => None,
            };
            let step = 0.8 * slot.bus.config().step_limit_deg.to_radians();
            let at = match fresh {
                Some(at) => at,
                None => self.actuator(i)?.position()?,
            };
            reach.push(Some((at - step, at + step)));
        }
        Ok(reach)
    }

    /// Sends the position `setpoints` (rad, joint order, within the soft limits; `None`
    /// for a joint not commanded in position); returns what was sent at device
    /// resolution (0 where nothing was) and what each WHJ joint's servo frame answered.
    /// wCK: per bus one synchronized move when its IDs are exactly `0..n` (at the steps
    /// its servos' [`Actuator`]s would send), else each servo's own move; WHJ: each
    /// joint's position servo frame.
    pub(super) fn send(
        &mut self,
        setpoints: &[Option<f64>],
    ) -> Result<(Vec<f64>, Vec<Option<Sensed>>), RobotError> {
        let mut sent = vec![0.0; setpoints.len()];
        let mut sensed = vec![None; setpoints.len()];
        let mut singles = Vec::new();
        for (b, slot) in self.wck.iter_mut().enumerate() {
            let mut members: Vec<(usize, ServoId, Position)> = Vec::new();
            for (i, joint) in self.joints.iter().enumerate() {
                if let Device::Wck { bus, id, scale } = joint.device
                    && bus == b
                    && let Some(&Some(rad)) = setpoints.get(i)
                {
                    let position = scale
                        .position_within(rad, &joint.limits)
                        .ok_or_else(|| scale.range_error(&joint.name, rad))?;
                    members.push((i, id, position));
                }
            }
            members.sort_by_key(|m| m.1.get());
            let contiguous = members
                .iter()
                .enumerate()
                .all(|(k, m)| usize::from(m.1.get()) == k);
            if !contiguous || members.is_empty() {
                singles.extend(members.iter().map(|m| m.0));
                continue;
            }
            let positions: Vec<Position> = members.iter().map(|m| m.2).collect();
            slot.bus
                .sync_move(slot.torque, &positions)
                .map_err(|source| ActuatorError::Wck {
                    joint: format!("bus {} (synchronized move)", slot.name),
                    source: Box::new(source),
                })?;
            for &(i, _, position) in &members {
                if let (
                    Some(s),
                    Some(JointSlot {
                        device: Device::Wck { scale, .. },
                        ..
                    }),
                ) = (sent.get_mut(i), self.joints.get(i))
                {
                    *s = scale.to_rad(position);
                }
            }
        }
        for i in singles {
            let Some(&Some(rad)) = setpoints.get(i) else {
                continue;
            };
            let done = self.actuator(i)?.command_position(rad)?;
            if let Some(s) = sent.get_mut(i) {
                *s = done.sent_rad;
            }
        }
        for b in 0..self.whj.len() {
            self.send_whj_positions(b, setpoints, &mut sent, &mut sensed)?;
        }
        Ok((sent, sensed))
    }

    /// Sends WHJ bus `b`'s joints their position servo frames to `setpoints` (joint
    /// order, rad, clamped to their soft limits) in one pipelined batch, so that each
    /// reply's duplicate check overlaps the other joints' frames; records the angle
    /// sent (at device resolution) and what each frame answered. The first joint that
    /// failed (in joint order) is the error.
    fn send_whj_positions(
        &self,
        b: usize,
        setpoints: &[Option<f64>],
        sent: &mut [f64],
        sensed: &mut [Option<Sensed>],
    ) -> Result<(), RobotError> {
        let Some(slot) = self.whj.get(b) else {
            return Ok(());
        };
        let mut members = Vec::new();
        let mut frames = Vec::new();
        for (i, joint) in self.joints.iter().enumerate() {
            let (Device::Whj { bus, id, map, .. }, Some(&Some(rad))) =
                (joint.device, setpoints.get(i))
            else {
                continue;
            };
            if bus != b {
                continue;
            }
            let (target, _) = joint.limits.clamp(rad);
            let position = whj_position(&joint.name, map, target)?;
            members.push((i, position));
            frames.push(robobus_whj::Request::PositionServo {
                joint: id,
                target: position,
            });
        }
        if frames.is_empty() {
            return Ok(());
        }
        let whj = |i: usize, source| ActuatorError::Whj {
            joint: self
                .joints
                .get(i)
                .map_or_else(String::new, |j| j.name.clone()),
            source: Box::new(source),
        };
        let answers = match slot.bus.servo_many(&frames) {
            Ok(answers) => answers,
            Err(e) => {
                // A refusal names its joint; a failure of the bus is the first member's.
                let refused = match &e {
                    crate::whj::WhjError::StepTooLarge { joint, .. } => {
                        frames.iter().position(|f| f.joint() == Some(*joint))
                    }
                    _ => None,
                };
                let i = members.get(refused.unwrap_or(0)).map_or(0, |m| m.0);
                return Err(whj(i, e).into());
            }
        };
        for (&(i, position), answer) in members.iter().zip(answers) {
            let fb = answer.map_err(|e| whj(i, e))?;
            if let (Some(s), Some(j)) = (sent.get_mut(i), self.joints.get(i))
                && let Device::Whj { map, current, .. } = j.device
            {
                *s = whj_to_rad(map, position);
                if let Some(x) = sensed.get_mut(i) {
                    *x = Some(sensed_of(&fb, map, current));
                }
            }
        }
        Ok(())
    }
}
