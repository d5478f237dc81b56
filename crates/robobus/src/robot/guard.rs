//! The host's protection of a robot's own commands ([`Robot::command`](super::Robot::command),
//! [`command_velocity`](super::Robot::command_velocity),
//! [`command_effort`](super::Robot::command_effort): a program's loop, such as a Python
//! one): the one monitor of [`crate::ops::protect`], as `robot.play` uses it.
//!
//! Each WHJ joint's servo frame answers with its feedback: where the joint was when the
//! frame came (against the set-point of the command before), its speed and its current;
//! every [`TEMPERATURE_EVERY`] (robot clock) its temperature is read too. Those are the
//! readings, and only those: nothing older is fed. A joint on position is fed with
//! [`Monitor::feed`], one on velocity or effort with [`Monitor::feed_driven`]. A wCK
//! servo's synchronized move has no reply: every [`WCK_READ_EVERY`] (the servos' reads
//! spread over that period, round-robin) a status read after the command gives its load
//! (as a current, [`protect::wck_load_a`]) and position, its speed the change since the
//! read before, fed with the wCK limits sized to that period (no temperature).
//!
//! A stop brings the joint that tripped to rest through the one guard: on velocity or
//! effort a zero target and back to position mode, then disabled where every product of
//! its model has a pin brake (holding would keep it pushing or heating), else held where
//! it stands ([`SafeState::Hold`](super::SafeState::Hold)); a wCK servo passive, or its bus's break where that is
//! the bus's safe state (never held: it would keep pushing). It latches: every later command (and interface
//! switch) is refused, nothing sent, until [`Robot::clear_protection`](super::Robot::clear_protection).

use std::time::{Duration, Instant};

use robobus_whj::units::Model;

use super::RobotError;
use super::interface::Interface;
use crate::ops::protect::{self, Action, Drive, Fault, Limits, Monitor, Reading};

/// How often a commanded WHJ joint's temperature is read (a status query after its
/// command), robot clock.
pub const TEMPERATURE_EVERY: Duration = Duration::from_millis(250);

/// How often each of a robot's wCK servos is read for the protection while it is
/// commanded (a status read after a command: its synchronized move has no reply), robot
/// clock; the servos' reads are spread over the period, round-robin.
pub const WCK_READ_EVERY: Duration = Duration::from_millis(250);

/// What one command's frame answered for a joint (joint frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Sensed {
    /// Where it was when the frame came, rad.
    pub(super) position_rad: f64,
    /// Its speed, rad/s.
    pub(super) speed_rad_s: f64,
    /// Its current, A.
    pub(super) current_a: f64,
}

/// The protection of a robot's joints (joint order).
#[derive(Debug)]
pub(super) struct Guard {
    /// Whether commands are watched ([`Robot::set_protection`](super::Robot::set_protection)).
    pub(super) on: bool,
    monitor: Monitor,
    limits: Vec<Limits>,
    models: Vec<Option<Model>>,
    /// Each joint's set-point of the command before, in its interface's unit (rad, rad/s,
    /// N·m); `None` before its first command on that interface.
    before: Vec<Option<f64>>,
    next_temperature: Vec<Option<Instant>>,
    /// A wCK servo's next status read.
    next_wck: Vec<Option<Instant>>,
    /// A wCK servo's last status read: when, where (rad) and whether at the end of its
    /// range (its speed is the change between two reads).
    pub(super) wck_last: Vec<Option<(Instant, f64, bool)>>,
    /// The stop that latched, by joint.
    pub(super) stopped: Vec<Option<Fault>>,
    /// The events so far (at most [`protect::MAX_EVENTS`]; the oldest dropped).
    pub(super) events: Vec<Fault>,
}

impl Guard {
    /// The guard of joints `(name, limits, model)`, its times counted from `start`.
    pub(super) fn new(start: Instant, joints: Vec<(String, Limits, Option<Model>)>) -> Self {
        let n = joints.len();
        let limits: Vec<Limits> = joints.iter().map(|j| j.1).collect();
        let models = joints.iter().map(|j| j.2).collect();
        Self {
            on: true,
            monitor: Monitor::new(start, joints.into_iter().map(|j| (j.0, j.1)).collect()),
            limits,
            models,
            before: vec![None; n],
            next_temperature: vec![None; n],
            next_wck: vec![None; n],
            wck_last: vec![None; n],
            stopped: vec![None; n],
            events: Vec::new(),
        }
    }

    /// Joint `index`'s watch afresh (a switch of its interface, a resume, a clear).
    pub(super) fn restart(&mut self, index: usize) {
        if let Some(l) = self.limits.get(index) {
            self.monitor.set_limits(index, *l);
        }
        if let Some(b) = self.before.get_mut(index) {
            *b = None;
        }
        if let Some(w) = self.wck_last.get_mut(index) {
            *w = None;
        }
    }

    /// Every joint's watch afresh.
    pub(super) fn restart_all(&mut self) {
        for i in 0..self.limits.len() {
            self.restart(i);
        }
    }

    /// The share of its `max_velocity` / `max_effort` joint `index` keeps (its `derate`
    /// while derated for heat, else 1).
    pub(super) fn share(&self, index: usize) -> f64 {
        if self.on {
            self.monitor.speed_share(index)
        } else {
            1.0
        }
    }

    /// The first latched stop, refusing a command.
    pub(super) fn refusal(&self) -> Option<RobotError> {
        self.stopped
            .iter()
            .flatten()
            .next()
            .map(|f| RobotError::ProtectionStopped {
                fault: Box::new(f.clone()),
            })
    }

    /// Whether joint `index`'s temperature is due at `now` (and, if so, the next one
    /// scheduled).
    pub(super) fn temperature_due(&mut self, index: usize, now: Instant) -> bool {
        if !self.on
            || self.limits.get(index).is_none_or(|l| {
                l.temperature_warn_c.is_none()
                    && l.temperature_derate_c.is_none()
                    && l.temperature_stop_c.is_none()
            })
        {
            return false;
        }
        let Some(next) = self.next_temperature.get_mut(index) else {
            return false;
        };
        if next.is_some_and(|t| now < t) {
            return false;
        }
        *next = Some(now + TEMPERATURE_EVERY);
        true
    }

    /// Whether wCK servo `index` (the `rank`-th of `count` wCK servos) is due for a
    /// status read at `now` (and, if so, the next one scheduled): every
    /// [`WCK_READ_EVERY`], the first reads spread over that period by rank, and never
    /// when nothing of its limits needs a reading.
    pub(super) fn wck_due(
        &mut self,
        index: usize,
        now: Instant,
        (rank, count): (usize, usize),
    ) -> bool {
        if !self.on
            || self.limits.get(index).is_none_or(|l| {
                l.stall_current_a.is_none()
                    && l.collision_current_jump_a.is_none()
                    && l.collision_error_jump_deg.is_none()
            })
        {
            return false;
        }
        let Some(next) = self.next_wck.get_mut(index) else {
            return false;
        };
        match *next {
            None => {
                let spread = u32::try_from(count.max(1)).unwrap_or(u32::MAX);
                let rank = u32::try_from(rank).unwrap_or(0);
                let first = now + WCK_READ_EVERY * rank / spread;
                *next = Some(first);
                if now < first {
                    return false;
                }
            }
            Some(t) if now < t => return false,
            Some(_) => {}
        }
        *next = Some(now + WCK_READ_EVERY);
        true
    }

    /// Feeds joint `index`'s answer at `at` (`sensed`, a `temperature_c` if read) while it
    /// is on `interface` with set-point `set` now (and `max_velocity` `max_rad_s`); the
    /// stop it makes, if any. The set-point is kept for the next reading.
    #[allow(clippy::too_many_arguments)] // one reading's parts
    pub(super) fn feed(
        &mut self,
        index: usize,
        at: Instant,
        interface: Interface,
        sensed: Option<Sensed>,
        temperature_c: Option<f64>,
        (set, max_rad_s): (f64, f64),
    ) -> Option<Fault> {
        let before = self.before.get_mut(index).and_then(|b| b.replace(set));
        if !self.on || (sensed.is_none() && temperature_c.is_none()) {
            return None;
        }
        let position_deg = sensed.map(|s| s.position_rad.to_degrees());
        let reading = Reading {
            current_a: sensed.map(|s| s.current_a),
            temperature_c,
            position_deg,
            ..Reading::at(at)
        };
        let faults = match interface {
            Interface::Position => {
                let target_deg = before.map(f64::to_degrees);
                let reading = Reading {
                    error_deg: position_deg.zip(target_deg).map(|(p, t)| (p - t).abs()),
                    target_deg,
                    ..reading
                };
                self.monitor.feed(index, &reading)
            }
            Interface::Velocity => self.monitor.feed_driven(
                index,
                &reading,
                sensed.map(|s| s.speed_rad_s.to_degrees()),
                Drive::Velocity {
                    commanded_deg_s: before.unwrap_or(0.0).to_degrees(),
                },
            ),
            Interface::Effort => self.monitor.feed_driven(
                index,
                &reading,
                sensed.map(|s| s.speed_rad_s.to_degrees()),
                Drive::Effort {
                    max_deg_s: max_rad_s.to_degrees(),
                },
            ),
        };
        let mut stop = None;
        for f in faults {
            tracing::warn!("{f}");
            if f.action == Action::Stop {
                stop = Some(f.clone());
            }
            if self.events.len() >= protect::MAX_EVENTS {
                self.events.remove(0);
            }
            self.events.push(f);
        }
        if let (Some(f), Some(slot)) = (&stop, self.stopped.get_mut(index)) {
            *slot = Some(f.clone());
        }
        stop
    }

    /// Joint `index`'s model (`None`: a wCK servo, or not known).
    pub(super) fn model(&self, index: usize) -> Option<Model> {
        self.models.get(index).copied().flatten()
    }
}
