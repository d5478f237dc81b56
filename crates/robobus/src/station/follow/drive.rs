//! Following velocity and effort commands on a station's robot file: what a ROS 2 forward
//! velocity or effort controller streams (`NS/joint_commands/velocity`,
//! `NS/joint_commands/effort` through the Zenoh bridge).
//!
//! Every joint starts on its position interface. A joint takes velocities or efforts only
//! once it was switched to that interface ([`Driver::switch`], what activating a
//! `ros2_control` controller that claims the joint's interface does): checked whole before
//! anything is sent (every name a joint of the file with that interface in its
//! `interfaces`, every joint at rest: its set-point zero and a WHJ joint's measured speed
//! under [`AT_REST_RAD_S`]), then a WHJ joint's work mode changes (speed or current, a zero
//! target after it; position: the joint holds the angle where it stands) and a wCK servo
//! enters wheel mode at level 0 or leaves it with a move to where it stands.
//!
//! A command ([`Driver::plan`]) is one value per joint on the interface, in the robot
//! file's order (rad/s or N·m, in the joint frame), refused whole before anything is sent:
//! a count other than those joints', a value that is not finite or lies past the joint's
//! `max_velocity` / `max_effort` or (a wCK servo) past what its top wheel level turns it at.
//! [`Driver::apply`] ramps each joint's set-point at its `max_acceleration` /
//! `max_effort_rate` over the time since its last command (at most [`MAX_DT`]), keeps a WHJ
//! joint from heading for a soft limit faster than it can stop there (an effort pushing it
//! past a limit it stands on is dropped), and sends a WHJ speed or current servo frame (the
//! current of the model's torque constant) or a wCK wheel command (the nearest level of
//! `wheel_speeds`); each joint has its own result.
//!
//! [`Driver::release`] is the watchdog's and the disarm's end: every joint on velocity or
//! effort gets a zero target and goes back to its position interface, held where it stands.
//!
//! The host's protection watches every WHJ joint on velocity or effort
//! ([`Monitor::feed_driven`], as `robot.play` of velocities or efforts does): each servo
//! frame's feedback (its speed and current, against the set-point of the command before)
//! and every 0.25 s its temperature, on the bus's clock. A stop brings the
//! joint that tripped to a zero target, back on position, then its safe stop (disabled
//! where its brake holds it, else held), fails its result naming the fault, and latches:
//! every later command is refused whole, nothing sent, until [`Driver::resume`]. A derated
//! joint's set-point is held to its `derate` share of `max_velocity` / `max_effort`. A wCK
//! wheel's command reply carries no load: every 0.25 s a status read gives its load (as a
//! current) and position, its speed the position's change since the read before, fed the
//! same way with the wCK limits sized to that period; its stop is a zero level, back on
//! position, then its bus's safe state, passive or the break (never held: a held servo
//! keeps pushing).

use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

use robobus_wck::{Rotation, ServoId, TorqueLevel, WheelSpeed};
use robobus_whj::units::{CurrentScale, TargetSpeed};
use robobus_whj::{JointId, WorkMode};
use serde::Serialize;

use crate::actuator::{JointMap, WckScale, rpm_to_rad_s};
use crate::ops::protect::{self, Action, Drive, Fault, MAX_EVENTS, Monitor, Reading};
use crate::ops::safe::WckServos;
use crate::ops::{DeviceResult, ErrorKind, Failure, Family, OpError, SafeState};
use crate::robot::{EffortScale, Interface, RobotConfig, WheelSpeeds};
use crate::station::Station;
use crate::station::jog::guard::{TEMPERATURE_EVERY, model, safe_stop, temperature_of};

/// A joint counts as at rest for a switch below this measured speed, rad/s (as
/// `Robot::set_interface` takes it).
pub const AT_REST_RAD_S: f64 = 0.05;

/// The longest time a set-point is ramped over between two commands (a stream's first
/// command after a pause ramps as if it came this long after the one before).
pub const MAX_DT: Duration = Duration::from_millis(100);

/// A joint as a velocity or effort command sees it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DriveJoint {
    /// Its name in the robot file.
    pub name: String,
    /// `wck` or `whj`.
    pub family: Family,
    /// The station's bus.
    pub bus: String,
    /// Servo or joint ID.
    pub id: u8,
    /// The interface it is on now.
    pub interface: Interface,
    /// The interfaces the robot file gives it.
    pub interfaces: Vec<Interface>,
}

#[derive(Debug, Clone)]
enum Units {
    Whj(JointMap),
    Wck(WckScale, Option<WheelSpeeds>),
}

#[derive(Debug, Clone)]
struct Joint {
    name: String,
    family: Family,
    bus: String,
    id: u8,
    interfaces: Vec<Interface>,
    limits: (f64, f64),
    max_velocity: f64,
    max_acceleration: f64,
    max_effort: f64,
    effort_rate: f64,
    units: Units,
}

/// What changes between commands, per joint.
#[derive(Debug, Clone, Copy)]
struct Slot {
    active: Interface,
    /// The set-point last sent, rad/s or N·m.
    set: f64,
    /// Where it last reported itself, rad.
    at: Option<f64>,
    last: Option<Instant>,
    /// A WHJ joint's current register scale and torque constant, once it identified.
    whj: Option<(CurrentScale, Option<EffortScale>)>,
    /// A WHJ joint's speed (°/s) and current (A) in its last feedback.
    speed_deg_s: Option<f64>,
    current_a: Option<f64>,
}

/// The host's protection of the joints on velocity or effort (see the
/// [module docs](self)).
#[derive(Debug, Default)]
struct Protection {
    /// Made at the first switch (on the bus's clock); each joint's limits set when it is
    /// switched, once its model is known.
    monitor: Option<Monitor>,
    models: Vec<Option<robobus_whj::units::Model>>,
    next_temperature: Vec<Option<Instant>>,
    /// The stop, once one came.
    stopped: Option<Fault>,
    /// Every event, the last [`MAX_EVENTS`].
    events: Vec<Fault>,
    /// A wCK wheel's last status read: when, where (joint degrees), and whether at the end
    /// of its range.
    wck_last: Vec<Option<(Instant, f64, bool)>>,
}

/// Follows velocity and effort commands (see the [module docs](self)).
#[derive(Debug)]
pub struct Driver {
    joints: Vec<Joint>,
    slots: Mutex<Vec<Slot>>,
    /// The robot file (the joints' protection).
    robot: RobotConfig,
    protection: Mutex<Protection>,
}

fn refused(what: &str, value: impl std::fmt::Display, expected: impl Into<String>) -> OpError {
    OpError::invalid(what, value, expected)
}

impl Driver {
    /// The driver of the station's robot file, every joint on its position interface.
    ///
    /// Errors: [`ErrorKind::BadInput`] when the station has no robot file.
    pub fn new(station: &Station) -> Result<Self, OpError> {
        let robot = station.robot().ok_or_else(|| {
            refused(
                "robot",
                "none",
                "velocity and effort commands need a robot file (--robot FILE)",
            )
        })?;
        Ok(Self::of(robot))
    }

    fn of(robot: &RobotConfig) -> Self {
        let joints: Vec<Joint> = robot
            .joints
            .iter()
            .map(|j| {
                let wck = robot.is_wck(j);
                Joint {
                    name: j.name.clone(),
                    family: if wck { Family::Wck } else { Family::Whj },
                    bus: j.bus.clone(),
                    id: j.id,
                    interfaces: j.interfaces(),
                    limits: (j.limits[0].min(j.limits[1]), j.limits[0].max(j.limits[1])),
                    max_velocity: j.max_velocity,
                    max_acceleration: j.max_acceleration,
                    max_effort: j.max_effort.unwrap_or(0.0),
                    effort_rate: j.effort_rate(),
                    units: if wck {
                        Units::Wck(j.wck_scale(), j.wheel_speeds.clone())
                    } else {
                        Units::Whj(j.map())
                    },
                }
            })
            .collect();
        let slots = vec![
            Slot {
                active: Interface::Position,
                set: 0.0,
                at: None,
                last: None,
                whj: None,
                speed_deg_s: None,
                current_a: None,
            };
            joints.len()
        ];
        let n = joints.len();
        Self {
            joints,
            slots: Mutex::new(slots),
            robot: robot.clone(),
            protection: Mutex::new(Protection {
                models: vec![None; n],
                next_temperature: vec![None; n],
                wck_last: vec![None; n],
                ..Protection::default()
            }),
        }
    }

    fn guard(&self) -> std::sync::MutexGuard<'_, Protection> {
        self.protection
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
    }

    /// The host's protection events so far (the last 256), in order.
    pub fn protection(&self) -> Vec<Fault> {
        self.guard().events.clone()
    }

    /// The protection stop that latched, if any.
    pub fn stopped(&self) -> Option<Fault> {
        self.guard().stopped.clone()
    }

    /// Takes commands again after a protection stop (the joints' watch starts afresh).
    pub fn resume(&self) {
        let mut p = self.guard();
        p.stopped = None;
        p.monitor = None;
        p.next_temperature.fill(None);
        p.wck_last.fill(None);
    }

    /// Watches joint `i`, just switched to `to` (a WHJ joint's model's limits and the
    /// file's; a wCK wheel's, sized to its status read every [`TEMPERATURE_EVERY`]).
    fn watch_switched(&self, station: &Station, index: usize, to: Interface) {
        let Some(joint) = self.joints.get(index) else {
            return;
        };
        let Some(config) = self.robot.joints.get(index) else {
            return;
        };
        if to == Interface::Position {
            return;
        }
        let (now, found) = if joint.family == Family::Wck {
            let Ok(port) = station.wck(Some(&joint.bus)) else {
                return;
            };
            let now = port.lock().now();
            (now, None)
        } else {
            let Ok(port) = station.whj(Some(&joint.bus)) else {
                return;
            };
            let now = port.bus().now();
            (now, model(station, joint.family, &joint.bus, joint.id))
        };
        let limits = if joint.family == Family::Wck {
            self.robot
                .protection_of(config, None)
                .for_reading_period(TEMPERATURE_EVERY)
        } else {
            self.robot.protection_of(config, found)
        };
        let mut guard = self.guard();
        let monitor = guard.monitor.get_or_insert_with(|| {
            Monitor::new(
                now,
                self.joints
                    .iter()
                    .map(|j| (j.name.clone(), protect::Limits::OFF))
                    .collect(),
            )
        });
        monitor.set_limits(index, limits);
        if let Some(slot) = guard.models.get_mut(index) {
            *slot = found;
        }
    }

    /// Feeds WHJ joint `i`'s feedback (answering the set-point `before`) to the
    /// protection; on a stop, brings it to its safe stop and returns the failure naming
    /// the fault.
    fn watch(
        &self,
        station: &Station,
        i: usize,
        slot: &mut Slot,
        interface: Interface,
        before: f64,
    ) -> Option<Failure> {
        let j = self.joints.get(i)?;
        if j.family == Family::Wck {
            return self.watch_wheel(station, i, slot, interface, before);
        }
        let now = station.whj(Some(&j.bus)).ok()?.bus().now();
        let mut p = self.guard();
        let due = p
            .next_temperature
            .get(i)
            .copied()
            .flatten()
            .is_none_or(|t| now >= t);
        let temperature_c = if due {
            if let Some(t) = p.next_temperature.get_mut(i) {
                *t = Some(now + TEMPERATURE_EVERY);
            }
            temperature_of(station, j.family, &j.bus, j.id)
        } else {
            None
        };
        let reading = Reading {
            position_deg: slot.at.map(f64::to_degrees),
            current_a: slot.current_a,
            temperature_c,
            ..Reading::at(now)
        };
        let drive = match interface {
            Interface::Velocity => Drive::Velocity {
                commanded_deg_s: before.to_degrees(),
            },
            _ => Drive::Effort {
                max_deg_s: j.max_velocity.to_degrees(),
            },
        };
        let faults = p
            .monitor
            .as_mut()?
            .feed_driven(i, &reading, slot.speed_deg_s, drive);
        let stop = Self::keep(&mut p, faults)?;
        let m = p.models.get(i).copied().flatten();
        drop(p);
        // A zero target, back on position, then the joint's safe stop.
        let _ = frames::send(station, j, slot, interface, 0.0);
        slot.set = 0.0;
        if let Err(e) = switch_one(station, j, slot, Interface::Position) {
            tracing::warn!(joint = %j.name, "could not go back to position: {e}");
        }
        let what = safe_stop(station, j.family, &j.bus, j.id, m);
        let what = what.strip_prefix("; ").unwrap_or(&what).to_owned();
        Some(Failure::of(ErrorKind::Device, &format!("{stop}; {what}")))
    }

    /// Keeps `faults` in the events (logged); the stop, latched, if one.
    fn keep(p: &mut Protection, faults: Vec<Fault>) -> Option<Fault> {
        let mut stop = None;
        for f in faults {
            tracing::warn!("{f}");
            if f.action == Action::Stop {
                stop = Some(f.clone());
            }
            if p.events.len() >= MAX_EVENTS {
                p.events.remove(0);
            }
            p.events.push(f);
        }
        let stop = stop?;
        p.stopped = Some(stop.clone());
        Some(stop)
    }

    /// Feeds wCK wheel `i`'s status read to the protection, every [`TEMPERATURE_EVERY`]
    /// on velocity (its wheel command's reply has no load); on a stop, a zero level, back
    /// on position, then its bus's safe state (passive, or the break), and the failure
    /// naming the fault.
    fn watch_wheel(
        &self,
        station: &Station,
        i: usize,
        slot: &mut Slot,
        interface: Interface,
        before: f64,
    ) -> Option<Failure> {
        let j = self.joints.get(i)?;
        let Units::Wck(scale, _) = &j.units else {
            return None;
        };
        if interface != Interface::Velocity {
            return None;
        }
        let port = station.wck(Some(&j.bus)).ok()?;
        let id = servo_id(j).ok()?;
        let now = port.lock().now();
        let mut p = self.guard();
        p.monitor.as_ref()?;
        let due = p
            .next_temperature
            .get(i)
            .copied()
            .flatten()
            .is_none_or(|t| now >= t);
        if !due {
            return None;
        }
        if let Some(t) = p.next_temperature.get_mut(i) {
            *t = Some(now + TEMPERATURE_EVERY);
        }
        // A silent servo is no reading (its commands fail on their own).
        let st = port.lock().servo(id).status().ok()?;
        let deg = scale.to_rad(st.position).to_degrees();
        let edge =
            st.position == robobus_wck::Position::MIN || st.position == robobus_wck::Position::MAX;
        let last = p.wck_last.get_mut(i)?;
        let speed = last.and_then(|(t, was, was_edge)| {
            let dt = now.saturating_duration_since(t).as_secs_f64();
            let changed = (deg - was).abs() > 1e-9;
            (dt > 0.0 && !(changed && (edge || was_edge))).then(|| (deg - was) / dt)
        });
        *last = Some((now, deg, edge));
        slot.at = Some(deg.to_radians());
        let reading = Reading {
            position_deg: Some(deg),
            current_a: Some(protect::wck_load_a(st.load.get())),
            ..Reading::at(now)
        };
        let drive = Drive::Velocity {
            commanded_deg_s: before.to_degrees(),
        };
        let faults = p.monitor.as_mut()?.feed_driven(i, &reading, speed, drive);
        let stop = Self::keep(&mut p, faults)?;
        drop(p);
        let _ = frames::send(station, j, slot, interface, 0.0);
        slot.set = 0.0;
        if let Err(e) = switch_one(station, j, slot, Interface::Position) {
            tracing::warn!(joint = %j.name, "could not go back to position: {e}");
        }
        let state = match self
            .robot
            .buses
            .get(&j.bus)
            .map(crate::robot::BusConfig::safe_state)
        {
            Some(SafeState::Break) => SafeState::Break,
            _ => SafeState::Passive,
        };
        let failed = state.apply(&mut WckServos {
            bus: &mut port.lock(),
            ids: &[id],
            torque: TorqueLevel::MIN,
        });
        let mut text = format!("{stop}; servo {} {}", id.get(), state.keyword());
        for f in failed {
            let _ =
                std::fmt::Write::write_fmt(&mut text, format_args!(" (not reached: {})", f.error));
        }
        Some(Failure::of(ErrorKind::Device, &text))
    }

    /// The share of its `max_velocity` / `max_effort` joint `i` keeps (a derated one).
    fn share(&self, i: usize) -> f64 {
        self.guard()
            .monitor
            .as_ref()
            .map_or(1.0, |m| m.speed_share(i))
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<Slot>> {
        self.slots.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Every joint, with the interface it is on (the file's order).
    pub fn joints(&self) -> Vec<DriveJoint> {
        let slots = self.lock();
        self.joints
            .iter()
            .zip(slots.iter())
            .map(|(j, s)| DriveJoint {
                name: j.name.clone(),
                family: j.family,
                bus: j.bus.clone(),
                id: j.id,
                interface: s.active,
                interfaces: j.interfaces.clone(),
            })
            .collect()
    }

    /// The joints on `interface`, in the file's order (the joints of its command).
    pub fn on(&self, interface: Interface) -> Vec<DriveJoint> {
        self.joints()
            .into_iter()
            .filter(|j| j.interface == interface)
            .collect()
    }

    /// Switches the joints named to `to` (see the [module docs](self)): checked whole
    /// first (a name not in the file or without the interface, a joint that moves:
    /// [`ErrorKind::BadInput`] or [`ErrorKind::Refused`], nothing sent); a joint already
    /// on `to` is left as it is. One result per joint named.
    ///
    /// # Errors
    ///
    /// The first check that fails, nothing sent.
    pub fn switch(
        &self,
        station: &Station,
        names: &[String],
        to: Interface,
    ) -> Result<Vec<DeviceResult<String, Interface>>, OpError> {
        let mut index = Vec::with_capacity(names.len());
        for n in names {
            let Some(i) = self.joints.iter().position(|j| &j.name == n) else {
                return Err(refused(
                    "joints",
                    n,
                    format!(
                        "a joint of the robot file: {}",
                        self.joints
                            .iter()
                            .map(|j| j.name.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ));
            };
            let j = &self.joints[i];
            if !j.interfaces.contains(&to) {
                return Err(refused(
                    &j.name,
                    to,
                    format!(
                        "an interface the robot file gives it: {}",
                        j.interfaces
                            .iter()
                            .map(|i| i.keyword())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ));
            }
            if !index.contains(&i) {
                index.push(i);
            }
        }
        let mut slots = self.lock();
        for &i in &index {
            let (j, s) = (&self.joints[i], slots[i]);
            if s.active == to {
                continue;
            }
            if s.set != 0.0 {
                return Err(OpError::Refused(format!(
                    "{}: its {} set-point is {} {}, not 0: command it to rest first; nothing \
                     was switched",
                    j.name,
                    s.active,
                    s.set,
                    s.active.unit()
                )));
            }
            if let Some(speed) = whj_speed(station, j)?
                && speed.abs() > AT_REST_RAD_S
            {
                return Err(OpError::Refused(format!(
                    "{}: it turns at {speed:.3} rad/s (at rest below {AT_REST_RAD_S} rad/s); \
                     nothing was switched",
                    j.name
                )));
            }
        }
        Ok(index
            .iter()
            .map(|&i| {
                let j = &self.joints[i];
                if slots[i].active == to {
                    return DeviceResult::ok(j.name.clone(), to);
                }
                match switch_one(station, j, &mut slots[i], to) {
                    Ok(()) => {
                        self.watch_switched(station, i, to);
                        DeviceResult::ok(j.name.clone(), to)
                    }
                    Err(e) => DeviceResult::failed(j.name.clone(), Failure::from(&e)),
                }
            })
            .collect())
    }

    /// Checks a whole command of `interface` (one value per joint on it, in the file's
    /// order) before anything is sent: the joints it goes to (file indices) and their
    /// values.
    ///
    /// # Errors
    ///
    /// [`ErrorKind::BadInput`] naming the value and its range (the count, a value not
    /// finite or past its limit); [`ErrorKind::Refused`] when no joint is on `interface`.
    pub fn plan(&self, interface: Interface, values: &[f64]) -> Result<Vec<(usize, f64)>, OpError> {
        if let Some(stop) = self.stopped() {
            return Err(OpError::Refused(format!(
                "protection stopped a driven joint ({stop}); nothing was sent: resume once \
                 the cause is cleared"
            )));
        }
        let on: Vec<usize> = {
            let slots = self.lock();
            (0..self.joints.len())
                .filter(|&i| slots[i].active == interface)
                .collect()
        };
        if on.is_empty() {
            return Err(OpError::Refused(format!(
                "no joint is on its {interface} interface: switch the joints first (NS/robobus/\
                 interface, {{\"interface\": \"{interface}\", \"joints\": [...]}}); nothing \
                 was sent"
            )));
        }
        if values.len() != on.len() {
            return Err(refused(
                "data",
                format!("{} values", values.len()),
                format!(
                    "one {interface} per joint on that interface: {} values, in the order {}",
                    on.len(),
                    on.iter()
                        .map(|&i| self.joints[i].name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            ));
        }
        on.into_iter()
            .zip(values)
            .map(|(i, &v)| {
                let j = &self.joints[i];
                let unit = interface.unit();
                let most = match interface {
                    Interface::Velocity => j.max_velocity,
                    _ => j.max_effort,
                };
                let top = match (&j.units, interface) {
                    (Units::Wck(_, Some(w)), Interface::Velocity) => {
                        (w.level(v).is_none()).then(|| w.top())
                    }
                    _ => None,
                };
                if !v.is_finite() || v.abs() > most {
                    let what = if interface == Interface::Velocity {
                        "max_velocity"
                    } else {
                        "max_effort"
                    };
                    return Err(refused(
                        &j.name,
                        format!("{v} {unit}"),
                        format!("a number within -{most}..={most} {unit} (its {what})"),
                    ));
                }
                if let Some(top) = top {
                    return Err(refused(
                        &j.name,
                        format!("{v} {unit}"),
                        format!(
                            "-{top:.3}..={top:.3} rad/s, what its top wheel level turns it at \
                             (wheel_speeds)"
                        ),
                    ));
                }
                Ok((i, v))
            })
            .collect()
    }

    /// Sends a planned command: each joint's set-point ramped and bounded (see the
    /// [module docs](self)), one result per joint: the value sent, at the device's
    /// resolution (rad/s or N·m).
    pub fn apply(
        &self,
        station: &Station,
        interface: Interface,
        plan: &[(usize, f64)],
    ) -> Vec<DeviceResult<String, f64>> {
        let mut slots = self.lock();
        let now = Instant::now();
        let mut rows: Vec<Option<DeviceResult<String, f64>>> = plan.iter().map(|_| None).collect();
        // The WHJ frames, sent per bus in one batch after the loop: (row, joint, set-point,
        // the set-point before, the frame, what it carries).
        let mut batch: Vec<(usize, usize, f64, f64, robobus_whj::Request, f64)> = Vec::new();
        for (k, &(i, target)) in plan.iter().enumerate() {
            let (Some(j), Some(slot), Some(row)) =
                (self.joints.get(i), slots.get_mut(i), rows.get_mut(k))
            else {
                continue;
            };
            if slot.active != interface {
                *row = Some(DeviceResult::failed(
                    j.name.clone(),
                    Failure::from(&OpError::Refused(format!(
                        "{}: on its {} interface, not {interface}",
                        j.name, slot.active
                    ))),
                ));
                continue;
            }
            let dt = slot
                .last
                .map_or(MAX_DT, |t| now.saturating_duration_since(t).min(MAX_DT))
                .as_secs_f64();
            // A derated joint keeps its share of its max_velocity / max_effort.
            let most = self.share(i)
                * match interface {
                    Interface::Velocity => j.max_velocity,
                    _ => j.max_effort,
                };
            let set = step(j, slot, interface, target.clamp(-most, most), dt);
            let before = slot.set;
            *row = match frames::frame(station, j, slot, interface, set) {
                Ok(frames::Frame::Sent(carried)) => Some(self.sent(
                    station,
                    (i, j, slot),
                    interface,
                    (set, before, now),
                    carried,
                )),
                Ok(frames::Frame::Whj { frame, carried }) => {
                    batch.push((k, i, set, before, frame, carried));
                    None
                }
                Err(e) => Some(DeviceResult::failed(j.name.clone(), Failure::from(&e))),
            };
        }
        let mut buses: Vec<&str> = Vec::new();
        for &(_, i, ..) in &batch {
            if let Some(j) = self.joints.get(i)
                && !buses.contains(&j.bus.as_str())
            {
                buses.push(&j.bus);
            }
        }
        for bus in buses {
            let on_bus: Vec<_> = batch
                .iter()
                .filter(|b| self.joints.get(b.1).is_some_and(|j| j.bus == bus))
                .collect();
            let requests: Vec<robobus_whj::Request> = on_bus.iter().map(|b| b.4).collect();
            for (&&(k, i, set, before, _, carried), answer) in
                on_bus.iter().zip(frames::send_whj(station, bus, &requests))
            {
                let (Some(j), Some(slot), Some(row)) =
                    (self.joints.get(i), slots.get_mut(i), rows.get_mut(k))
                else {
                    continue;
                };
                *row = Some(match answer {
                    Ok(fb) => {
                        frames::record(j, slot, &fb);
                        self.sent(
                            station,
                            (i, j, slot),
                            interface,
                            (set, before, now),
                            carried,
                        )
                    }
                    Err(f) => DeviceResult::failed(j.name.clone(), f),
                });
            }
        }
        rows.into_iter().flatten().collect()
    }

    /// A joint's frame went out carrying `carried`: its set-point and time are kept, and
    /// the protection watches it; its row.
    fn sent(
        &self,
        station: &Station,
        (i, j, slot): (usize, &Joint, &mut Slot),
        interface: Interface,
        (set, before, now): (f64, f64, Instant),
        carried: f64,
    ) -> DeviceResult<String, f64> {
        slot.set = set;
        slot.last = Some(now);
        match self.watch(station, i, slot, interface, before) {
            Some(stop) => DeviceResult::failed(j.name.clone(), stop),
            None => DeviceResult::ok(j.name.clone(), carried),
        }
    }

    /// Every joint on velocity or effort (or on `only`): a zero target, then back on its
    /// position interface, held where it stands. One result per joint released.
    pub fn release(
        &self,
        station: &Station,
        only: Option<Interface>,
    ) -> Vec<DeviceResult<String, Interface>> {
        let mut slots = self.lock();
        self.joints
            .iter()
            .zip(slots.iter_mut())
            .filter(|(_, s)| s.active != Interface::Position && only.is_none_or(|o| o == s.active))
            .map(|(j, s)| {
                let active = s.active;
                let zero = frames::send(station, j, s, active, 0.0);
                s.set = 0.0;
                match zero.and_then(|_| switch_one(station, j, s, Interface::Position)) {
                    Ok(()) => DeviceResult::ok(j.name.clone(), Interface::Position),
                    Err(e) => DeviceResult::failed(j.name.clone(), Failure::from(&e)),
                }
            })
            .collect()
    }
}

/// A WHJ joint's measured speed in the joint frame (rad/s); `None` for a wCK servo.
fn whj_speed(station: &Station, j: &Joint) -> Result<Option<f64>, OpError> {
    let Units::Whj(map) = j.units else {
        return Ok(None);
    };
    let id = joint_id(j)?;
    let rpm = station
        .whj(Some(&j.bus))?
        .bus()
        .joint_unchecked(id)
        .speed()?
        .rpm();
    Ok(Some(map.speed_to_joint(rpm_to_rad_s(rpm))))
}

fn joint_id(j: &Joint) -> Result<JointId, OpError> {
    JointId::new(j.id).map_err(|e| refused("id", j.id, e.to_string()))
}

fn servo_id(j: &Joint) -> Result<ServoId, OpError> {
    ServoId::new(j.id).map_err(|e| refused("id", j.id, e.to_string()))
}

/// Switches one joint (checked already) and leaves it at rest on `to`.
fn switch_one(station: &Station, j: &Joint, s: &mut Slot, to: Interface) -> Result<(), OpError> {
    match j.units {
        Units::Whj(_) => {
            let port = station.whj(Some(&j.bus))?;
            let joint = port.bus().joint_unchecked(joint_id(j)?);
            if s.whj.is_none() {
                let identity = joint.identity()?;
                s.whj = Some((
                    identity.current_scale(),
                    EffortScale::of(identity.model, identity.reduction_ratio),
                ));
            }
            if to == Interface::Effort && s.whj.is_some_and(|(_, e)| e.is_none()) {
                return Err(OpError::Refused(format!(
                    "{}: its model has no torque constant in the models table; nothing was \
                     switched",
                    j.name
                )));
            }
            joint.set_mode(match to {
                Interface::Position => WorkMode::Position,
                Interface::Velocity => WorkMode::Speed,
                Interface::Effort => WorkMode::Current,
            })?;
            match to {
                Interface::Position => {}
                Interface::Velocity => drop(joint.command_speed(TargetSpeed(0))?),
                Interface::Effort => drop(joint.command_current(0.0)?),
            }
        }
        Units::Wck(..) => {
            let id = servo_id(j)?;
            let port = station.wck(Some(&j.bus))?;
            let mut bus = port.lock();
            let mut servo = bus.servo(id);
            if to == Interface::Velocity {
                servo.wheel(Rotation::Ccw, WheelSpeed::MIN)?;
            } else {
                let st = servo.status()?;
                servo.move_to(TorqueLevel::MIN, st.position)?;
            }
        }
    }
    s.active = to;
    s.set = 0.0;
    s.last = None;
    station
        .interfaces()
        .set(crate::station::interfaces::OffPosition {
            joint: j.name.clone(),
            family: j.family,
            bus: j.bus.clone(),
            id: j.id,
            interface: to,
        });
    Ok(())
}

/// The set-point for `target` after `dt_s`: clamped, ramped and (a WHJ joint) kept from a
/// soft limit.
fn step(j: &Joint, s: &Slot, interface: Interface, target: f64, dt_s: f64) -> f64 {
    let (most, rate) = match interface {
        Interface::Velocity => (j.max_velocity, j.max_acceleration),
        _ => (j.max_effort, j.effort_rate),
    };
    let target = target.clamp(-most, most);
    let step = rate * dt_s;
    let mut set = if (target - s.set).abs() <= step {
        target
    } else {
        s.set + step.copysign(target - s.set)
    };
    if let (Units::Whj(_), Some(at)) = (&j.units, s.at) {
        let (lo, hi) = j.limits;
        let room = if set > 0.0 { hi - at } else { at - lo };
        let room = (room - s.set.abs() * dt_s).max(0.0);
        set = match interface {
            Interface::Velocity => {
                let stoppable = (2.0 * j.max_acceleration * room).sqrt();
                set.clamp(-stoppable, stoppable)
            }
            _ if room <= 0.0 => 0.0,
            _ => set,
        };
    }
    set
}

mod frames;

#[cfg(all(test, feature = "sim"))]
mod tests;
