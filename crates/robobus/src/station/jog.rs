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

/// Handles made once, by key.
type Handles<K, T> = Mutex<HashMap<K, Arc<T>>>;

/// Jogs devices of a station; keeps each device's handle and limits after the first jog.
#[derive(Debug, Default)]
pub struct Jogger {
    whj: Handles<(String, u8), WhjGroup>,
    /// The handles of WHJ joints jogged together ([`Jogger::jog_many`]), by bus and IDs.
    whj_batches: Handles<(String, Vec<u8>), WhjGroup>,
    wck: Handles<(String, u8), WckJog>,
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

    /// One jog step of each of `reqs` (see [`Jogger::jog`]), one result per request in
    /// their order. The WHJ joints of one bus step in one batch: their servo frames go
    /// out together ([`WhjGroup::command`], `JointBus::servo_many`), so each reply's
    /// duplicate check overlaps the other joints' frames instead of one after another. A
    /// batch refused before anything is sent (a joint not enabled, past a limit, stopped
    /// by the protection) is jogged joint by joint instead, so that each joint gets its
    /// own answer and the others still move.
    pub fn jog_many(&self, station: &Station, reqs: &[JogRequest]) -> Vec<Result<Jogged, OpError>> {
        let mut out: Vec<Option<Result<Jogged, OpError>>> = reqs.iter().map(|_| None).collect();
        let mut by_bus: Vec<(String, Vec<usize>)> = Vec::new();
        for (k, req) in reqs.iter().enumerate() {
            if req.family != Family::Whj || !req.target.is_finite() {
                continue;
            }
            let Ok(port) = station.whj(req.bus.as_deref()) else {
                continue;
            };
            match by_bus.iter_mut().find(|(b, _)| b == port.name()) {
                Some((_, ks)) => ks.push(k),
                None => by_bus.push((port.name().to_owned(), vec![k])),
            }
        }
        for (bus, ks) in by_bus {
            if ks.len() < 2 {
                continue;
            }
            let batch: Vec<&JogRequest> = ks.iter().filter_map(|&k| reqs.get(k)).collect();
            if let Ok(done) = self.jog_whj_batch(station, &bus, &batch) {
                for (k, r) in ks.into_iter().zip(done) {
                    if let Some(slot) = out.get_mut(k) {
                        *slot = Some(r);
                    }
                }
            }
        }
        out.into_iter()
            .zip(reqs)
            .map(|(r, req)| r.unwrap_or_else(|| self.jog(station, req)))
            .collect()
    }

    /// One batch of jog steps of WHJ joints on `bus` ([`Jogger::jog_many`]): `Err` when it
    /// was refused with nothing sent, else each joint's result.
    fn jog_whj_batch(
        &self,
        station: &Station,
        bus: &str,
        reqs: &[&JogRequest],
    ) -> Result<Vec<Result<Jogged, OpError>>, OpError> {
        let port = station.whj(Some(bus))?;
        let mut ids = Vec::with_capacity(reqs.len());
        let mut joints = Vec::with_capacity(reqs.len());
        for req in reqs {
            joints.push(JointId::new(req.device).map_err(|e| {
                OpError::invalid("device", req.device, format!("{e} (allowed: 1..=30)"))
            })?);
            if ids.contains(&req.device) {
                return Err(OpError::invalid("device", req.device, "each joint once"));
            }
            ids.push(req.device);
        }
        station
            .interfaces()
            .check_moved(Family::Whj, Some(bus), &ids)?;
        if let Some(g) = &self.guard {
            for &id in &ids {
                g.refuse(bus, id)?;
            }
        }
        let handle = cached(&self.whj_batches, (bus.to_owned(), ids.clone()), || {
            WhjGroup::new(station, Some(bus), &ids)
        })?;
        let telemetry = port.bus().telemetry();
        let limits = handle.limits(ServoLoop::Position);
        let mut steps = Vec::with_capacity(reqs.len());
        for ((req, &joint), &own) in reqs.iter().zip(&joints).zip(&limits) {
            let limits = within_soft_limits(station, (Family::Whj, bus, req.device), own);
            let from = port
                .bus()
                .joint_unchecked(joint)
                .recent_position_in(&telemetry)?
                .degrees();
            let (sent, limited) = step(from, req.target, limits, WHJ_JOG_STEP_DEG);
            steps.push((from, sent, limited));
        }
        let sent: Vec<f64> = steps.iter().map(|s| s.1).collect();
        let rows = handle.command(ServoLoop::Position, &sent)?;
        Ok(reqs
            .iter()
            .zip(steps)
            .zip(rows)
            .map(|((req, (from, sent, limited)), row)| {
                let jogged = Jogged {
                    family: Family::Whj,
                    bus: bus.to_owned(),
                    device: req.device,
                    target: req.target,
                    from,
                    sent,
                    limited,
                    feedback: one_result(Some(row))?,
                };
                if let Some(g) = &self.guard {
                    g.watch(station, &jogged)?;
                }
                Ok(jogged)
            })
            .collect())
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
        let handle = cached(&self.whj, (port.name().to_owned(), req.device), || {
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
        let entry = cached(&self.wck, (port.name().to_owned(), req.device), || {
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

/// The handle of `key` in `map`, made by `make` the first time.
fn cached<K: Eq + std::hash::Hash, T>(
    map: &Handles<K, T>,
    key: K,
    make: impl FnOnce() -> Result<T, OpError>,
) -> Result<Arc<T>, OpError> {
    let mut map = map.lock().unwrap_or_else(PoisonError::into_inner);
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

    #[cfg(feature = "sim")]
    #[test]
    fn the_whj_joints_of_one_bus_step_in_one_batch_and_a_refused_one_alone() {
        use crate::catalogue::{Request, run};
        let station = Station::simulated().unwrap();
        for r in [
            r#"{"op": "whj.mode", "joints": "1-7", "mode": "position"}"#,
            r#"{"op": "whj.enable", "joints": "1-6"}"#,
            r#"{"op": "whj.disable", "joints": "7"}"#,
        ] {
            let r: Request = serde_json::from_str(r).unwrap();
            run(&station, &r, &mut crate::ops::Control::none()).unwrap();
        }
        let jogger = Jogger::unwatched();
        let jogs = |n: u8| -> Vec<JogRequest> {
            (1..=n)
                .map(|device| JogRequest {
                    family: Family::Whj,
                    bus: None,
                    device,
                    target: 1.0,
                })
                .collect()
        };
        // Joint 7 is not enabled: the batch is refused before anything is sent, and each
        // joint is jogged alone: 7 is refused, the others step.
        let done = jogger.jog_many(&station, &jogs(7));
        for (d, r) in (1..=7u8).zip(&done) {
            match r {
                Ok(j) => assert!(d < 7 && j.device == d && j.sent > j.from, "{j:?}"),
                Err(e) => assert!(d == 7 && e.kind() == crate::ErrorKind::Refused, "J{d}: {e}"),
            }
        }
        let port = station.whj(None).unwrap();
        let bus = port.bus();
        let reqs = jogs(6);
        // The batch's handle is made (and its joints' readiness read) by its first jog.
        assert!(jogger.jog_many(&station, &reqs).iter().all(Result::is_ok));
        let t = bus.now();
        for r in &reqs {
            jogger.jog(&station, r).unwrap();
        }
        let alone = bus.now() - t;
        let t = bus.now();
        let done = jogger.jog_many(&station, &reqs);
        let together = bus.now() - t;
        for (d, r) in (1..=6u8).zip(&done) {
            let j = r.as_ref().unwrap();
            assert_eq!(j.device, d);
            assert!((j.sent - 1.0).abs() < 1e-9 || j.sent > j.from, "{j:?}");
        }
        // Each reply is held for an arbitration loser's answer, at least one feedback
        // frame long: together, five of the six holds overlap the other frames.
        let id = robobus_whj::CanFrame::standard_id(0x501).unwrap();
        let feedback = robobus_whj::CanFrame::new_fd(id, &[0x55; 16]).unwrap();
        let frame =
            robobus_whj::timing::frame_duration(&feedback, robobus_whj::timing::BitRates::WHJ);
        assert!(
            together + frame * 5 <= alone,
            "together {together:?}, alone {alone:?}, a feedback frame {frame:?}"
        );
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
