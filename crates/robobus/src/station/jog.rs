//! Jogging: one bounded step of one device toward a target, what a slider or a held
//! button of a front end sends again and again.
//!
//! Every jog takes where the device is now and commands at most one jog step from there
//! ([`WHJ_JOG_STEP_DEG`], [`WCK_JOG_STEP`]), never past the device's limits (a WHJ joint's
//! own position limits, the host bounds) nor the soft limits of the station's robot file
//! for that device. "Now" is the device's own latest answer when it is younger than
//! [`RECENT`] on the bus's clock (a WHJ joint's feedback or status, a wCK servo's reply to
//! the previous jog's move or status read), else a status read first: so a steady stream
//! of jogs costs one transaction per device, not two. A WHJ joint must be enabled in position mode; the frame goes through
//! the [`WhjGroup`] handle, so its step-limit and readiness checks apply as well.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use robobus_wck::{Position, ServoId};
use robobus_whj::JointId;
use serde::{Deserialize, Serialize};

use crate::ops::Family;
use crate::ops::whj::ServoLoop;
use crate::ops::{Failure, OpError};
use crate::station::Station;
use crate::station::handles::{WckGroup, WhjGroup};

pub(crate) mod guard;

/// The largest step of one WHJ jog, degrees.
pub const WHJ_JOG_STEP_DEG: f64 = 2.0;
/// The largest step of one wCK jog, position steps (about 8.4°).
pub const WCK_JOG_STEP: u8 = 8;
/// The torque level of a wCK jog's move (2: medium).
pub const WCK_JOG_TORQUE: u8 = 2;
/// How old a device's latest answer may be, on its bus's clock, for a jog to step from it
/// without reading the device first (the WHJ client's own rule for its step limit).
pub const RECENT: Duration = Duration::from_millis(100);

/// One jog: a device and the target it is stepped toward.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JogRequest {
    /// `wck` or `whj`.
    pub family: Family,
    /// The station's bus (`None`: its only one of the family).
    #[serde(default)]
    pub bus: Option<String>,
    /// Servo or joint ID.
    pub device: u8,
    /// Where to go: wCK position steps (0..=254), WHJ degrees.
    pub target: f64,
}

/// What one jog sent.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Jogged {
    /// The family.
    pub family: Family,
    /// The bus it ran on.
    pub bus: String,
    /// The device.
    pub device: u8,
    /// The target asked for.
    pub target: f64,
    /// Where the device was before the step (wCK steps, WHJ degrees).
    pub from: f64,
    /// The position commanded.
    pub sent: f64,
    /// Whether a jog step or a limit cut the step short of the target.
    pub limited: bool,
    /// The device's answer to the command (WHJ: servo feedback; wCK: the move's reply).
    pub feedback: serde_json::Value,
}

/// A jogged wCK servo's handle and its limits (steps).
type WckJog = (WckGroup, (f64, f64));

/// Jogs devices of a station; keeps each device's handle and limits after the first jog.
#[derive(Debug, Default)]
pub struct Jogger {
    whj: Mutex<HashMap<(String, u8), Arc<WhjGroup>>>,
    wck: Mutex<HashMap<(String, u8), Arc<WckJog>>>,
    /// Each wCK servo's latest answered position (steps), on its bus's clock.
    wck_seen: Mutex<HashMap<(String, u8), (Instant, u8)>>,
    /// The host's protection of the jogged devices (`None`: a caller that watches them
    /// itself).
    guard: Option<guard::Guard>,
}

impl Jogger {
    /// A jogger with no handle yet, whose jogs the host's protection watches (see
    /// `guard.rs`): a device that stalls, collides or runs hot is stopped and its later
    /// jogs refused until [`Jogger::resume`].
    pub fn new() -> Self {
        Self {
            guard: Some(guard::Guard::default()),
            ..Self::default()
        }
    }

    /// A jogger whose caller watches the devices itself (a [`Follower`]'s stream).
    ///
    /// [`Follower`]: crate::station::follow::Follower
    pub fn unwatched() -> Self {
        Self::default()
    }

    /// Takes jogs of a device the protection stopped again (once its cause is cleared).
    pub fn resume(&self, bus: &str, device: u8) {
        if let Some(g) = &self.guard {
            g.resume(bus, device);
        }
    }

    /// One jog step of `req`'s device toward its target (see the [module docs](self)).
    /// A target that is not a finite number is refused, and nothing is sent.
    pub fn jog(&self, station: &Station, req: &JogRequest) -> Result<Jogged, OpError> {
        if !req.target.is_finite() {
            return Err(OpError::invalid(
                "target",
                req.target,
                "a finite number (wCK: steps 0..=254, WHJ: degrees)",
            ));
        }
        let bus = match req.family {
            Family::Whj => Some(station.whj(req.bus.as_deref())?.name().to_owned()),
            Family::Wck => Some(station.wck(req.bus.as_deref())?.name().to_owned()),
            _ => None,
        };
        if let Some(bus) = &bus {
            station
                .interfaces()
                .check_moved(req.family, Some(bus), &[req.device])?;
        }
        if let (Some(g), Some(bus)) = (&self.guard, &bus) {
            g.refuse(bus, req.device)?;
        }
        let jogged = match req.family {
            Family::Whj => self.jog_whj(station, req),
            Family::Wck => self.jog_wck(station, req),
            Family::Robot => Err(OpError::invalid(
                "family",
                "robot",
                "a jog moves one device: wck or whj",
            )),
            Family::Host => Err(OpError::invalid(
                "family",
                "host",
                "a jog moves one device: wck or whj",
            )),
        }?;
        if let Some(g) = &self.guard {
            g.watch(station, &jogged)?;
        }
        Ok(jogged)
    }

    /// Makes the handle of `req`'s device now, as its first jog would (a WHJ joint's
    /// identity handshake and limits, a wCK servo's boundaries: reads only), so that the
    /// first jog costs no more than the next. Nothing moves.
    pub fn prepare(&self, station: &Station, req: &JogRequest) -> Result<(), OpError> {
        match req.family {
            Family::Whj => self.whj_handle(station, req).map(drop),
            Family::Wck => self.wck_handle(station, req).map(drop),
            Family::Robot | Family::Host => Ok(()),
        }
    }

    fn whj_handle(
        &self,
        station: &Station,
        req: &JogRequest,
    ) -> Result<(crate::station::WhjPort, Arc<WhjGroup>), OpError> {
        let port = station.whj(req.bus.as_deref())?;
        let handle = cached(&self.whj, port.name(), req.device, || {
            WhjGroup::new(station, Some(port.name()), &[req.device])
        })?;
        Ok((port, handle))
    }

    fn wck_handle(
        &self,
        station: &Station,
        req: &JogRequest,
    ) -> Result<(crate::station::WckPort, Arc<WckJog>), OpError> {
        let id = ServoId::new(req.device).map_err(|e| {
            OpError::invalid("device", req.device, format!("{e} (allowed: 0..=30)"))
        })?;
        let port = station.wck(req.bus.as_deref())?;
        let entry = cached(&self.wck, port.name(), req.device, || {
            let servos = WckGroup::new(station, Some(port.name()), &[req.device])?;
            let b = port.lock().servo(id).boundaries()?;
            let bounds = (f64::from(b.lower().get()), f64::from(b.upper().get()));
            let limits =
                within_soft_limits(station, (Family::Wck, port.name(), req.device), bounds);
            Ok((servos, limits))
        })?;
        Ok((port, entry))
    }

    fn jog_whj(&self, station: &Station, req: &JogRequest) -> Result<Jogged, OpError> {
        let id = JointId::new(req.device).map_err(|e| {
            OpError::invalid("device", req.device, format!("{e} (allowed: 1..=30)"))
        })?;
        let (port, handle) = self.whj_handle(station, req)?;
        let limits = within_soft_limits(
            station,
            (Family::Whj, port.name(), req.device),
            handle.limits(ServoLoop::Position)[0],
        );
        let from = port.bus().joint_unchecked(id).recent_position()?.degrees();
        let (sent, limited) = step(from, req.target, limits, WHJ_JOG_STEP_DEG);
        let mut out = handle.command(ServoLoop::Position, &[sent])?;
        let feedback = one_result(out.pop())?;
        Ok(Jogged {
            family: Family::Whj,
            bus: port.name().to_owned(),
            device: req.device,
            target: req.target,
            from,
            sent,
            limited,
            feedback,
        })
    }

    fn jog_wck(&self, station: &Station, req: &JogRequest) -> Result<Jogged, OpError> {
        let (port, entry) = self.wck_handle(station, req)?;
        let (servos, limits) = &*entry;
        let key = (port.name().to_owned(), req.device);
        let now = port.lock().now();
        let seen = self
            .wck_seen
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .get(&key)
            .copied();
        let from = match seen {
            Some((at, p)) if now.saturating_duration_since(at) < RECENT => f64::from(p),
            _ => f64::from(one_reading(servos.status()?)?.position),
        };
        let (sent, limited) = step(from, req.target.round(), *limits, f64::from(WCK_JOG_STEP));
        let sent = sent.round();
        let out = servos.move_to(&[sent], WCK_JOG_TORQUE)?;
        let reply = out.into_iter().next();
        let mut seen = self.wck_seen.lock().unwrap_or_else(PoisonError::into_inner);
        match reply.as_ref().map(|r| &r.outcome) {
            Some(crate::ops::Outcome::Ok(r)) => {
                seen.insert(key, (port.lock().now(), r.position));
            }
            // A servo that did not answer is read again before its next step.
            _ => {
                seen.remove(&key);
            }
        }
        drop(seen);
        let feedback = one_result(reply)?;
        Ok(Jogged {
            family: Family::Wck,
            bus: port.name().to_owned(),
            device: req.device,
            target: req.target,
            from,
            sent,
            limited,
            feedback,
        })
    }
}

/// The handle of `(bus, device)` in `map`, made by `make` the first time.
fn cached<T>(
    map: &Mutex<HashMap<(String, u8), Arc<T>>>,
    bus: &str,
    device: u8,
    make: impl FnOnce() -> Result<T, OpError>,
) -> Result<Arc<T>, OpError> {
    let mut map = map.lock().unwrap_or_else(PoisonError::into_inner);
    let key = (bus.to_owned(), device);
    if let Some(h) = map.get(&key) {
        return Ok(Arc::clone(h));
    }
    let h = Arc::new(make()?);
    map.insert(key, Arc::clone(&h));
    Ok(h)
}

/// `(lo, hi)` narrowed to the robot file's soft limits of the device, if it names it.
fn within_soft_limits(
    station: &Station,
    (family, bus, id): (Family, &str, u8),
    (lo, hi): (f64, f64),
) -> (f64, f64) {
    match soft_limits(station, family, bus, id) {
        Some((a, b)) => (lo.max(a), hi.min(b)),
        None => (lo, hi),
    }
}

/// The next commanded position: `target` within `limits`, at most `max_step` from `from`;
/// and whether that cut it short.
fn step(from: f64, target: f64, (lo, hi): (f64, f64), max_step: f64) -> (f64, bool) {
    let (lo, hi) = (lo.min(hi), hi.max(lo));
    // The step heads for the target clamped into the limits: a device outside them (moved
    // by hand, or overshooting a limit by a count) is brought back toward them whatever
    // the target, and nothing outside them is ever commanded beyond where it already is.
    let want = target.clamp(lo, hi);
    let next = from + (want - from).clamp(-max_step, max_step);
    (next, (next - target).abs() > 1e-9)
}

/// The soft limits of the station's robot file for this device, in the device's units
/// (WHJ degrees, wCK steps), if the file names it.
fn soft_limits(station: &Station, family: Family, bus: &str, id: u8) -> Option<(f64, f64)> {
    let robot = station.robot()?;
    let joint = robot.joints.iter().find(|j| j.bus == bus && j.id == id)?;
    let [a, b] = joint.limits;
    let (a, b) = match family {
        Family::Whj => {
            let map = joint.map();
            (map.to_device(a).to_degrees(), map.to_device(b).to_degrees())
        }
        Family::Wck => {
            let scale = joint.wck_scale();
            let steps = |rad: f64| {
                scale.to_position(rad).map_or_else(
                    || if rad < 0.0 { 0.0 } else { 254.0 },
                    |p: Position| f64::from(p.get()),
                )
            };
            (steps(a), steps(b))
        }
        Family::Robot | Family::Host => return None,
    };
    Some((a.min(b), a.max(b)))
}

fn one_result<T: Serialize>(
    r: Option<crate::ops::DeviceResult<u8, T>>,
) -> Result<serde_json::Value, OpError> {
    let r = r.ok_or_else(|| OpError::Device("no result for the jogged device".into()))?;
    match r.outcome {
        crate::ops::Outcome::Ok(v) => Ok(serde_json::to_value(v).unwrap_or_default()),
        crate::ops::Outcome::Failed(f) => Err(failure(&f)),
    }
}

fn one_reading(
    mut r: Vec<crate::ops::DeviceResult<u8, crate::station::handles::WckReading>>,
) -> Result<crate::station::handles::WckReading, OpError> {
    let r = r
        .pop()
        .ok_or_else(|| OpError::Device("no result for the jogged servo".into()))?;
    match r.outcome {
        crate::ops::Outcome::Ok(v) => Ok(v),
        crate::ops::Outcome::Failed(f) => Err(failure(&f)),
    }
}

/// The error of the one device a jog addressed.
fn failure(f: &Failure) -> OpError {
    use crate::ErrorKind as K;
    let m = f.error.clone();
    match f.kind {
        K::NoDevice => OpError::NoDevice(m),
        K::Refused | K::BadInput => OpError::Refused(m),
        K::Interrupted => OpError::Interrupted { detail: Some(m) },
        K::NotAvailable => OpError::NotAvailable(m),
        K::Device | K::Link => OpError::Device(m),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Commands the wCK bus of `station` has issued so far.
    #[cfg(feature = "sim")]
    fn wck_commands(station: &Station) -> u64 {
        station.wck(None).unwrap().lock().stats().commands
    }

    #[cfg(feature = "sim")]
    #[test]
    fn a_wck_jog_steps_from_the_servos_answer_while_it_is_recent_and_reads_it_again_after() {
        let station = Station::simulated().unwrap();
        let jogger = Jogger::new();
        let req = JogRequest {
            family: Family::Wck,
            bus: None,
            device: 3,
            target: 200.0,
        };
        jogger.prepare(&station, &req).unwrap();
        // The first jog reads the servo, then moves it: two commands.
        let before = wck_commands(&station);
        let first = jogger.jog(&station, &req).unwrap();
        assert_eq!(wck_commands(&station) - before, 2);
        // Exact: the step is added to the reading as the jog adds it.
        #[allow(clippy::float_cmp)]
        {
            assert_eq!(first.sent, first.from + f64::from(WCK_JOG_STEP));
        }
        // The next, within RECENT on the bus's clock, steps from the move's reply: one.
        let before = wck_commands(&station);
        let second = jogger.jog(&station, &req).unwrap();
        assert_eq!(wck_commands(&station) - before, 1);
        assert!((second.from - second.sent).abs() <= f64::from(WCK_JOG_STEP));
        // Once the reply is older than RECENT, the servo is read again first.
        {
            let port = station.wck(None).unwrap();
            let mut bus = port.lock();
            let later = bus.now() + RECENT;
            bus.sleep_until(later);
        }
        let before = wck_commands(&station);
        jogger.jog(&station, &req).unwrap();
        assert_eq!(wck_commands(&station) - before, 2);
    }

    #[test]
    fn a_step_is_bounded_by_the_jog_step_and_the_limits() {
        assert_eq!(step(0.0, 10.0, (-90.0, 90.0), 2.0), (2.0, true));
        assert_eq!(step(0.0, -1.5, (-90.0, 90.0), 2.0), (-1.5, false));
        assert_eq!(step(89.0, 120.0, (-90.0, 90.0), 2.0), (90.0, true));
        // Outside the limits: back toward them, whatever the target, a step at a time.
        assert_eq!(step(95.0, 120.0, (-90.0, 90.0), 2.0), (93.0, true));
        assert_eq!(step(95.0, 0.0, (-90.0, 90.0), 2.0), (93.0, true));
        assert_eq!(step(90.001, 120.0, (-90.0, 90.0), 2.0), (90.0, true));
    }
}
