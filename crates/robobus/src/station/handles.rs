//! Handles for the hot paths of a front end that drives devices call by call (a Python
//! control loop, a teleoperation bridge): a group of wCK servos and a group of WHJ joints
//! on one of a station's buses, each call a few transactions with no request to parse or
//! plan, and the same checks as the catalogue's operations. The checked cyclic loop is
//! [`CyclicLoop`](super::cyclic::CyclicLoop); a robot in SI units is
//! [`Robot`](crate::robot::Robot).
//!
//! - Every value is checked before anything is sent: one out of range refuses the whole
//!   call, naming the device, the value and the range, and nothing reaches any device.
//! - Every reading is fresh: a device that does not answer is a failed result for that
//!   call, never the values of an earlier one, and the call carries on past it.
//! - A call holds its bus for its whole length: it is never interleaved with another
//!   request's transactions.
//! - A handle does not keep its bus open: once the station is closed, every call fails
//!   (`Refused`, naming the bus) and the port is free for another program at once.

use std::sync::Mutex;

use robobus_wck::{Position, ServoId, TorqueLevel};
use robobus_whj::units::{Current, CurrentScale, Position as WhjPosition, TargetSpeed};
use robobus_whj::{JointId, Reply, Request};
use serde::Serialize;

use super::cyclic::{JointFeedback, allowed, check_targets};
use super::{Station, WckPort, WeakWckPort, WeakWhjPort, WhjPort};
use crate::ops::distinct_ids;
use crate::ops::whj::{JointSample, ServoLoop, check_reading, require_ready};
use crate::ops::{DeviceResult, Failure, OpError};
use crate::whj::MAX_PIPELINED;

/// One wCK servo's reading.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct WckReading {
    /// Position, 0..=254 steps.
    pub position: u8,
    /// The same position in degrees (1.055° per step, 0..=268°).
    pub position_deg: f64,
    /// Load, 0..=254 (no unit; `None` where the reply has none: a passive command).
    pub load: Option<u8>,
}

impl WckReading {
    fn of(position: Position, load: Option<u8>) -> Self {
        Self {
            position: position.get(),
            position_deg: position.degrees(),
            load,
        }
    }
}

/// wCK servos on one of a station's ports (clones share the port).
#[derive(Debug, Clone)]
pub struct WckGroup {
    port: WeakWckPort,
    name: String,
    ids: Vec<ServoId>,
}

/// The refusal of a call on a bus whose station was closed.
fn closed(bus: &str) -> OpError {
    OpError::Refused(format!(
        "bus {bus} is closed (its station was closed); open it again; nothing was sent"
    ))
}

impl WckGroup {
    /// Servos `ids` on the station's wCK port `bus` (`None`: its only one). Nothing is
    /// sent.
    pub fn new(station: &Station, bus: Option<&str>, ids: &[u8]) -> Result<Self, OpError> {
        let ids = distinct_ids::<ServoId>("ids", "servos", ids)?;
        let port = station.wck(bus)?;
        Ok(Self {
            port: port.downgrade(),
            name: port.name().to_owned(),
            ids,
        })
    }

    /// The servos, in the order of every call's values and results.
    pub fn ids(&self) -> Vec<u8> {
        self.ids.iter().map(|id| id.get()).collect()
    }

    /// The port's name.
    pub fn bus(&self) -> &str {
        &self.name
    }

    fn port(&self) -> Result<WckPort, OpError> {
        self.port.upgrade().ok_or_else(|| closed(&self.name))
    }

    /// Reads each servo's position and load.
    pub fn status(&self) -> Result<Vec<DeviceResult<u8, WckReading>>, OpError> {
        let port = self.port()?;
        let mut bus = port.lock();
        Ok(self
            .ids
            .iter()
            .map(|&id| match bus.servo(id).status() {
                Ok(st) => {
                    DeviceResult::ok(id.get(), WckReading::of(st.position, Some(st.load.get())))
                }
                Err(e) => DeviceResult::failed(id.get(), Failure::from(&OpError::from(e))),
            })
            .collect())
    }

    /// Checks one position per servo (whole steps 0..=254) and the torque level (0..=4).
    fn targets(
        &self,
        positions: &[f64],
        torque: u8,
    ) -> Result<(Vec<Position>, TorqueLevel), OpError> {
        if positions.len() != self.ids.len() {
            return Err(OpError::invalid(
                "positions",
                format!("{} value(s)", positions.len()),
                format!("one per servo: {} servo(s)", self.ids.len()),
            ));
        }
        let torque = TorqueLevel::new(torque)
            .map_err(|e| OpError::invalid("torque", torque, format!("{e} (allowed: 0..=4)")))?;
        let ps = positions
            .iter()
            .zip(&self.ids)
            .map(|(&p, id)| {
                let whole = p.is_finite() && p.fract() == 0.0 && (0.0..=254.0).contains(&p);
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // checked
                let step = whole.then_some(p as u8).and_then(|s| Position::new(s).ok());
                step.ok_or_else(|| {
                    OpError::invalid(
                        format!("position of servo {id}"),
                        p,
                        "allowed: whole steps 0..=254",
                    )
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok((ps, torque))
    }

    /// Moves each servo to its position (steps, one per servo) at `torque` (0 strongest
    /// ..= 4 weakest), one position command each; every value is checked before the first
    /// is sent. Each result is the servo's reply to its command.
    pub fn move_to(
        &self,
        positions: &[f64],
        torque: u8,
    ) -> Result<Vec<DeviceResult<u8, WckReading>>, OpError> {
        let (ps, torque) = self.targets(positions, torque)?;
        let port = self.port()?;
        let mut bus = port.lock();
        Ok(self
            .ids
            .iter()
            .zip(ps)
            .map(|(&id, p)| match bus.servo(id).move_to(torque, p) {
                Ok(st) => {
                    DeviceResult::ok(id.get(), WckReading::of(st.position, Some(st.load.get())))
                }
                Err(e) => DeviceResult::failed(id.get(), Failure::from(&OpError::from(e))),
            })
            .collect())
    }

    /// Moves every servo at once with one synchronized position packet (no replies). The
    /// packet addresses servos 0..N-1 in order, so the group must be exactly those.
    pub fn sync_move(&self, positions: &[f64], torque: u8) -> Result<(), OpError> {
        let in_order = self
            .ids
            .iter()
            .enumerate()
            .all(|(i, id)| usize::from(id.get()) == i);
        if !in_order {
            return Err(OpError::Refused(format!(
                "a synchronized move addresses servos 0..N-1 in order, and this group is {:?}: \
                 make the group of servos 0..={}; nothing was sent",
                self.ids(),
                self.ids.len() - 1
            )));
        }
        let (ps, torque) = self.targets(positions, torque)?;
        self.port()?.lock().sync_move(torque, &ps)?;
        Ok(())
    }

    /// Makes each servo passive (no torque: it can be moved by hand); each result is its
    /// position.
    pub fn passive(&self) -> Result<Vec<DeviceResult<u8, WckReading>>, OpError> {
        let port = self.port()?;
        let mut bus = port.lock();
        Ok(self
            .ids
            .iter()
            .map(|&id| match bus.servo(id).passive() {
                Ok(p) => DeviceResult::ok(id.get(), WckReading::of(p, None)),
                Err(e) => DeviceResult::failed(id.get(), Failure::from(&OpError::from(e))),
            })
            .collect())
    }
}

/// What a joint accepts, read once when the group is made.
#[derive(Debug, Clone, Copy)]
struct Allowed {
    position_deg: (f64, f64),
    speed_rpm: (f64, f64),
    current_ma: (f64, f64),
    scale: CurrentScale,
}

/// WHJ joints on one of a station's buses: fresh status, and one servo frame per joint
/// per command, each target checked against the host bounds and the joint's own limits.
#[derive(Debug)]
pub struct WhjGroup {
    port: WeakWhjPort,
    name: String,
    ids: Vec<JointId>,
    allowed: Vec<Allowed>,
    /// The work mode every joint was last found enabled in (checked before the first
    /// command of a mode, and again after a feedback shows a joint disabled).
    ready: Mutex<Option<ServoLoop>>,
}

impl WhjGroup {
    /// Joints `ids` on the station's WHJ bus `bus` (`None`: its only one): connects each
    /// (the identity handshake) and reads what it accepts (its position limits, its
    /// model's peak speed, its current limit). A joint that does not answer fails the
    /// whole call, naming it.
    pub fn new(station: &Station, bus: Option<&str>, ids: &[u8]) -> Result<Self, OpError> {
        let joints = distinct_ids::<JointId>("joints", "joints", ids)?;
        let port = station.whj(bus)?;
        let mut out = Vec::with_capacity(joints.len());
        for &id in &joints {
            let j = port.bus().joint(id)?;
            let (position_deg, scale) = allowed(&j, ServoLoop::Position)?;
            let (speed_rpm, _) = allowed(&j, ServoLoop::Speed)?;
            let (current_ma, _) = allowed(&j, ServoLoop::Current)?;
            out.push(Allowed {
                position_deg,
                speed_rpm,
                current_ma,
                scale,
            });
        }
        Ok(Self {
            port: port.downgrade(),
            name: port.name().to_owned(),
            ids: joints,
            allowed: out,
            ready: Mutex::new(None),
        })
    }

    /// The joints, in the order of every call's values and results.
    pub fn ids(&self) -> Vec<u8> {
        self.ids.iter().map(|id| id.get()).collect()
    }

    /// The bus's name.
    pub fn bus(&self) -> &str {
        &self.name
    }

    fn port(&self) -> Result<WhjPort, OpError> {
        self.port.upgrade().ok_or_else(|| closed(&self.name))
    }

    /// The bus's step limit: how far a position target may be from a joint's measured
    /// position, degrees.
    pub fn step_limit_deg(&self) -> Result<f64, OpError> {
        Ok(self.port()?.bus().config().step_limit_deg)
    }

    /// What each joint accepts as a `servo` target, `(low, high)` in that mode's unit
    /// (degrees, RPM, mA).
    pub fn limits(&self, servo: ServoLoop) -> Vec<(f64, f64)> {
        self.allowed
            .iter()
            .map(|a| match servo {
                ServoLoop::Position => a.position_deg,
                ServoLoop::Speed => a.speed_rpm,
                ServoLoop::Current => a.current_ma,
            })
            .collect()
    }

    /// Reads each joint: a status query and a speed read (position, speed, current,
    /// enabled, error bits).
    pub fn status(&self) -> Result<Vec<DeviceResult<u8, JointSample>>, OpError> {
        Ok(crate::ops::whj::sample(self.port()?.bus(), &self.ids))
    }

    /// Reads each joint's position, degrees: the status queries go out together
    /// ([`JointBus::request_many`](crate::whj::JointBus::request_many), at most
    /// [`MAX_PIPELINED`] at a time), each answer credited only to its own query and checked
    /// as [`status`](Self::status) checks it (within the joint's limits). One attempt each:
    /// a joint that does not answer is a failed result, never an older value.
    pub fn positions(&self) -> Result<Vec<DeviceResult<u8, f64>>, OpError> {
        let port = self.port()?;
        let bus = port.bus();
        let mut out = Vec::with_capacity(self.ids.len());
        for chunk in self.ids.chunks(MAX_PIPELINED) {
            let queries: Vec<Request> = chunk
                .iter()
                .map(|&joint| Request::StatusQuery { joint })
                .collect();
            for (&id, reply) in chunk.iter().zip(bus.request_many(&queries)?) {
                let read = reply.map_err(OpError::from).and_then(|r| match r {
                    Reply::Status { status, .. } => {
                        let deg = status.position.degrees();
                        check_reading(&bus.joint_unchecked(id), deg, None)?;
                        Ok(deg)
                    }
                    other => Err(OpError::Device(format!(
                        "joint {id}: a status query was answered with {other:?}"
                    ))),
                });
                out.push(match read {
                    Ok(deg) => DeviceResult::ok(id.get(), deg),
                    Err(e) => DeviceResult::failed(id.get(), Failure::from(&e)),
                });
            }
        }
        Ok(out)
    }

    fn lock_ready(&self) -> std::sync::MutexGuard<'_, Option<ServoLoop>> {
        self.ready
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Sends one `servo` frame per joint (targets in that mode's unit: degrees, RPM, mA,
    /// one per joint) in one pipelined batch
    /// ([`JointBus::servo_many`](crate::whj::JointBus::servo_many)) and returns each
    /// joint's feedback (for position: where it was when the frame arrived), a joint that
    /// failed as its own row. Refused, with nothing sent, when a target is outside its
    /// joint's limits, when a position target is further than the bus's step limit from
    /// the joint's measured position (use `whj.move` for large moves), when a joint is
    /// not enabled in that mode, or while a cyclic loop runs on the bus.
    pub fn command(
        &self,
        servo: ServoLoop,
        targets: &[f64],
    ) -> Result<Vec<DeviceResult<u8, JointFeedback>>, OpError> {
        check_targets(servo, &self.ids, &self.limits(servo), targets)?;
        let port = self.port()?;
        let bus = port.bus();
        if bus.cyclic_running() {
            return Err(OpError::Refused(format!(
                "a cyclic loop is running on bus {}: stop it before sending servo frames; \
                 nothing was sent",
                self.bus()
            )));
        }
        let mut ready = self.lock_ready();
        if *ready != Some(servo) {
            *ready = None;
            for &id in &self.ids {
                require_ready(&bus.joint_unchecked(id), servo, "a servo command")?;
            }
            *ready = Some(servo);
        }
        let bad =
            |e: robobus_whj::units::UnitRangeError| OpError::invalid("targets", "", e.to_string());
        // Every frame is made (and every value converted) before the first is sent.
        let mut frames = Vec::with_capacity(self.ids.len());
        for ((&joint, &t), a) in self.ids.iter().zip(targets).zip(&self.allowed) {
            frames.push(match servo {
                ServoLoop::Position => Request::PositionServo {
                    joint,
                    target: WhjPosition::from_degrees(t).map_err(bad)?,
                },
                ServoLoop::Speed => Request::SpeedServo {
                    joint,
                    target: TargetSpeed::from_rpm(t).map_err(bad)?,
                },
                ServoLoop::Current => Request::CurrentServo {
                    joint,
                    target: Current::from_milliamps(t, a.scale).map_err(bad)?,
                },
            });
        }
        // One pipelined batch: each reply's duplicate check overlaps the other joints'
        // frames. An error here (a position target too far from its joint's measured
        // position, or that position unreadable) refused the batch with nothing sent.
        let sent = bus.servo_many(&frames)?;
        let mut out = Vec::with_capacity(self.ids.len());
        for ((&id, sent), a) in self.ids.iter().zip(sent).zip(&self.allowed) {
            out.push(match sent {
                Ok(f) => {
                    if !f.is_enabled() {
                        *ready = None;
                    }
                    DeviceResult::ok(
                        id.get(),
                        JointFeedback {
                            position_deg: f.position.degrees(),
                            speed_rpm: f.speed.rpm(),
                            current_ma: f.current.milliamps(a.scale),
                            enabled: f.is_enabled(),
                            error: f.error.to_string(),
                        },
                    )
                }
                Err(e) => DeviceResult::failed(id.get(), Failure::from(&OpError::from(e))),
            });
        }
        drop(ready);
        Ok(out)
    }
}

/// The handles are `Send + Sync`: a front end may keep them on any thread.
const _: () = {
    const fn send_sync<T: Send + Sync>() {}
    send_sync::<WckGroup>();
    send_sync::<WhjGroup>();
};
