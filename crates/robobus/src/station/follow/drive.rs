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

use std::f64::consts::TAU;
use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

use robobus_wck::{Rotation, ServoId, TorqueLevel, WheelSpeed};
use robobus_whj::units::{Current, CurrentScale, TargetSpeed};
use robobus_whj::{JointId, WorkMode};
use serde::Serialize;

use crate::actuator::{JointMap, WckScale, rpm_to_rad_s};
use crate::ops::{DeviceResult, Failure, Family, OpError};
use crate::robot::{EffortScale, Interface, RobotConfig, WheelSpeeds};
use crate::station::Station;

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
}

/// Follows velocity and effort commands (see the [module docs](self)).
#[derive(Debug)]
pub struct Driver {
    joints: Vec<Joint>,
    slots: Mutex<Vec<Slot>>,
}

fn refused(what: &str, value: impl std::fmt::Display, expected: impl Into<String>) -> OpError {
    OpError::invalid(what, value, expected)
}

impl Driver {
    /// The driver of the station's robot file, every joint on its position interface.
    ///
    /// Errors: [`ErrorKind::BadInput`](crate::ErrorKind::BadInput) when the station has no robot file.
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
            };
            joints.len()
        ];
        Self {
            joints,
            slots: Mutex::new(slots),
        }
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
    /// [`ErrorKind::BadInput`](crate::ErrorKind::BadInput) or [`ErrorKind::Refused`](crate::ErrorKind::Refused), nothing sent); a joint already
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
                    Ok(()) => DeviceResult::ok(j.name.clone(), to),
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
    /// [`ErrorKind::BadInput`](crate::ErrorKind::BadInput) naming the value and its range (the count, a value not
    /// finite or past its limit); [`ErrorKind::Refused`](crate::ErrorKind::Refused) when no joint is on `interface`.
    pub fn plan(&self, interface: Interface, values: &[f64]) -> Result<Vec<(usize, f64)>, OpError> {
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
        plan.iter()
            .filter_map(|&(i, target)| {
                let j = self.joints.get(i)?;
                let slot = slots.get_mut(i)?;
                if slot.active != interface {
                    return Some(DeviceResult::failed(
                        j.name.clone(),
                        Failure::from(&OpError::Refused(format!(
                            "{}: on its {} interface, not {interface}",
                            j.name, slot.active
                        ))),
                    ));
                }
                let dt = slot
                    .last
                    .map_or(MAX_DT, |t| now.saturating_duration_since(t).min(MAX_DT))
                    .as_secs_f64();
                let set = step(j, slot, interface, target, dt);
                Some(match send(station, j, slot, interface, set) {
                    Ok(carried) => {
                        slot.set = set;
                        slot.last = Some(now);
                        DeviceResult::ok(j.name.clone(), carried)
                    }
                    Err(e) => DeviceResult::failed(j.name.clone(), Failure::from(&e)),
                })
            })
            .collect()
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
                let zero = send(station, j, s, active, 0.0);
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

/// Sends `value` (rad/s or N·m) to a joint on `interface`: what it carries at the
/// device's resolution; records where the joint reported itself.
fn send(
    station: &Station,
    j: &Joint,
    s: &mut Slot,
    interface: Interface,
    value: f64,
) -> Result<f64, OpError> {
    let sign = |reversed: bool| if reversed { -1.0 } else { 1.0 };
    match (&j.units, interface) {
        (Units::Wck(scale, Some(wheel)), Interface::Velocity) => {
            let (level, speed) = wheel.level(value).unwrap_or((0, 0.0));
            let device = speed * sign(scale.map.reversed);
            let rotation = if device < 0.0 {
                Rotation::Cw
            } else {
                Rotation::Ccw
            };
            let level = WheelSpeed::new(level).unwrap_or(WheelSpeed::MIN);
            let port = station.wck(Some(&j.bus))?;
            let st = port.lock().servo(servo_id(j)?).wheel(rotation, level)?;
            s.at = Some(scale.to_rad(st.position));
            Ok(speed)
        }
        (Units::Whj(map), Interface::Velocity | Interface::Effort) => {
            let port = station.whj(Some(&j.bus))?;
            let joint = port.bus().joint_unchecked(joint_id(j)?);
            let (fb, sent) = if interface == Interface::Velocity {
                let rpm = value * sign(map.reversed) * 60.0 / TAU;
                let target = TargetSpeed::from_rpm(rpm)
                    .map_err(|e| refused(&j.name, value, e.to_string()))?;
                let sent = rpm_to_rad_s(target.rpm()) * sign(map.reversed);
                (joint.command_speed(target)?, sent)
            } else {
                let Some((current, Some(k))) = s.whj else {
                    return Err(OpError::Refused(format!(
                        "{}: no torque constant known for its model",
                        j.name
                    )));
                };
                let ma = value / k.nm_per_a * 1e3 * sign(map.reversed);
                let counts = Current::from_milliamps(ma, current)
                    .map_err(|e| refused(&j.name, value, e.to_string()))?;
                #[allow(clippy::cast_precision_loss)] // mA of a joint
                let sent_ma = counts.milliamps(current) as f64;
                (
                    joint.command_current(sent_ma)?,
                    sent_ma / 1e3 * k.nm_per_a * sign(map.reversed),
                )
            };
            s.at = Some(map.to_joint(fb.position.degrees().to_radians()));
            Ok(sent)
        }
        _ => Err(OpError::Refused(format!(
            "{}: has no {interface} interface",
            j.name
        ))),
    }
}
