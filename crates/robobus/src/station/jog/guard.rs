//! The host's protection of jogs (a front end's slider or held button): each jogged
//! device's answers go to the one protection monitor ([`crate::ops::protect::Monitor`]),
//! one per device, as `robot.play`'s ticks do.
//!
//! A device's reading is where it reported itself at the jog (its servo frame's feedback
//! or its move's reply) against the position its previous jog sent, a WHJ joint's
//! current or a wCK servo's load (read as a current), and every [`TEMPERATURE_EVERY`] its temperature (a status query). Its limits
//! are the robot file's for the joint at that bus and ID, else its family's defaults. A
//! stop brings the device to its safe stop (a WHJ joint disabled where every product of
//! its model has a pin brake, else held where it is; a wCK servo passive) and
//! fails that jog naming the fault; every later jog of the device is refused, nothing
//! sent, until [`Jogger::resume`](super::Jogger::resume).

use std::collections::HashMap;
use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

use robobus_whj::JointId;
use robobus_whj::units::Model;

use super::Jogged;
use crate::ops::protect::{self, Action, Fault, Limits, Monitor, Reading};
use crate::ops::safe::WhjJoints;
use crate::ops::whj::ServoLoop;
use crate::ops::{Family, OpError, SafeState};
use crate::station::Station;

/// How often a jogged WHJ joint's temperature is read.
pub(crate) const TEMPERATURE_EVERY: Duration = Duration::from_millis(250);

/// One jogged device's protection.
#[derive(Debug)]
struct Watch {
    monitor: Monitor,
    model: Option<Model>,
    /// The device position the previous jog sent (WHJ degrees, wCK steps).
    last_sent: Option<f64>,
    next_temperature: Instant,
    stopped: Option<Fault>,
}

/// The protection of a [`Jogger`](super::Jogger)'s devices, by bus and ID.
#[derive(Debug, Default)]
pub(super) struct Guard {
    devices: Mutex<HashMap<(String, u8), Watch>>,
}

impl Guard {
    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<(String, u8), Watch>> {
        self.devices.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Refuses a jog of a device the protection stopped (nothing sent).
    pub(super) fn refuse(&self, bus: &str, device: u8) -> Result<(), OpError> {
        let key = (bus.to_owned(), device);
        match self.lock().get(&key).and_then(|w| w.stopped.clone()) {
            None => Ok(()),
            Some(stop) => Err(OpError::Refused(format!(
                "protection stopped this device ({stop}); nothing was sent: resume once the \
                 cause is cleared"
            ))),
        }
    }

    /// Takes jogs of the device again (its protection starts afresh).
    pub(super) fn resume(&self, bus: &str, device: u8) {
        self.lock().remove(&(bus.to_owned(), device));
    }

    /// Feeds a jog's answer to the device's monitor; a stop brings the device to its
    /// safe stop and is this jog's error.
    pub(super) fn watch(&self, station: &Station, j: &Jogged) -> Result<(), OpError> {
        let now = now(station, j);
        let key = (j.bus.clone(), j.device);
        let mut devices = self.lock();
        let w = devices.entry(key).or_insert_with(|| {
            let model = model(station, j.family, &j.bus, j.device);
            let (name, limits) = limits(station, j, model);
            Watch {
                monitor: Monitor::new(now, vec![(name, limits)]),
                model,
                last_sent: None,
                next_temperature: now,
                stopped: None,
            }
        });
        let deg = |device: f64| match j.family {
            Family::Wck => device * robobus_wck::Position::DEGREES_PER_STEP,
            _ => device,
        };
        let key = if j.family == Family::Wck {
            "position"
        } else {
            "position_deg"
        };
        let position = j.feedback.get(key).and_then(serde_json::Value::as_f64);
        let before = w.last_sent.map(deg);
        let temperature = now >= w.next_temperature;
        if temperature {
            w.next_temperature = now + TEMPERATURE_EVERY;
        }
        let reading = reading_of(
            now,
            &j.feedback,
            position,
            before,
            deg,
            temperature
                .then(|| temperature_of(station, j.family, &j.bus, j.device))
                .flatten(),
        );
        w.last_sent = Some(j.sent);
        let stop = w.monitor.feed(0, &reading).into_iter().find(|f| {
            tracing::warn!("{f}");
            f.action == Action::Stop
        });
        let Some(stop) = stop else { return Ok(()) };
        w.stopped = Some(stop.clone());
        let model = w.model;
        drop(devices);
        let end = safe_stop(station, j.family, &j.bus, j.device, model);
        Err(OpError::Device(format!("{stop}{end}")))
    }
}

/// The bus's clock now (the station's port of the device).
fn now(station: &Station, j: &Jogged) -> Instant {
    match j.family {
        Family::Wck => station
            .wck(Some(&j.bus))
            .map_or_else(|_| Instant::now(), |p| p.lock().now()),
        _ => station
            .whj(Some(&j.bus))
            .map_or_else(|_| Instant::now(), |p| p.bus().now()),
    }
}

/// The device's name and limits: the robot file's joint at its bus and ID, else its
/// family's defaults.
fn limits(station: &Station, j: &Jogged, model: Option<Model>) -> (String, Limits) {
    let defaults = || match j.family {
        Family::Wck => Limits::wck(),
        _ => Limits::whj(model),
    };
    let fallback = || {
        let what = if j.family == Family::Wck {
            "wCK servo"
        } else {
            "WHJ joint"
        };
        (format!("{what} {} on {}", j.device, j.bus), defaults())
    };
    let Some(config) = station.robot() else {
        return fallback();
    };
    config
        .joints
        .iter()
        .find(|c| c.bus == j.bus && c.id == j.device)
        .map_or_else(fallback, |c| {
            (c.name.clone(), config.protection_of(c, model))
        })
}

/// The model a WHJ joint identified as (`None`: a wCK servo, or not known).
pub(crate) fn model(station: &Station, family: Family, bus: &str, id: u8) -> Option<Model> {
    if family != Family::Whj {
        return None;
    }
    let id = JointId::new(id).ok()?;
    let port = station.whj(Some(bus)).ok()?;
    port.bus().cached_identity(id).map(|i| i.model)
}

/// A WHJ joint's temperature, read now (`None`: a wCK servo, or no answer).
/// One protection reading from a jog's answer: `position` (device units, `deg` turns them
/// into degrees) against the set-point sent before it (`before`, degrees), the answer's
/// current, and a temperature if one was read.
pub(crate) fn reading_of(
    at: Instant,
    feedback: &serde_json::Value,
    position: Option<f64>,
    before: Option<f64>,
    deg: impl Fn(f64) -> f64,
    temperature_c: Option<f64>,
) -> Reading {
    Reading {
        at,
        position_deg: position.map(&deg),
        error_deg: position.zip(before).map(|(p, b)| (deg(p) - b).abs()),
        target_deg: before,
        current_a: current_a_of(feedback),
        temperature_c,
    }
}

/// The current in a device's answer, A: a WHJ joint's `current_ma`, or a wCK servo's
/// `load` (its move's reply) read as a current ([`protect::wck_load_a`]); `None` in an
/// answer without either.
pub(crate) fn current_a_of(feedback: &serde_json::Value) -> Option<f64> {
    if let Some(ma) = feedback
        .get("current_ma")
        .and_then(serde_json::Value::as_f64)
    {
        return Some(ma / 1e3);
    }
    feedback
        .get("load")
        .and_then(serde_json::Value::as_u64)
        .and_then(|l| u8::try_from(l).ok())
        .map(protect::wck_load_a)
}

pub(crate) fn temperature_of(station: &Station, family: Family, bus: &str, id: u8) -> Option<f64> {
    if family != Family::Whj {
        return None;
    }
    let id = JointId::new(id).ok()?;
    let port = station.whj(Some(bus)).ok()?;
    let status = port.bus().joint_unchecked(id).status().ok()?;
    Some(f64::from(status.temperature.celsius()))
}

/// Brings a device that tripped to its safe stop: a WHJ joint disabled where its model's
/// brake holds it, else held where it is; a wCK servo passive. What it did, for the
/// fault's text.
pub(crate) fn safe_stop(
    station: &Station,
    family: Family,
    bus: &str,
    id: u8,
    model: Option<Model>,
) -> String {
    if family != Family::Whj {
        // Holding would keep a stalled servo pushing: its torque off.
        let passive = robobus_wck::ServoId::new(id)
            .map_err(|e| e.to_string())
            .and_then(|id| {
                let port = station.wck(Some(bus)).map_err(|e| e.to_string())?;
                let mut bus = port.lock();
                bus.servo(id).passive().map(drop).map_err(|e| e.to_string())
            });
        return match passive {
            Ok(()) => "; passive (its torque off: holding would keep it pushing)".into(),
            Err(e) => format!("; it did not reach its safe state (passive): {e}"),
        };
    }
    let (state, what) = if protect::torque_off_is_safe(model) {
        (
            SafeState::Disable,
            "its drive disabled (its brake holds it: holding would keep it pushing or heating)",
        )
    } else {
        (SafeState::Hold, "held where it is")
    };
    let Ok(id) = JointId::new(id) else {
        return String::new();
    };
    let Ok(port) = station.whj(Some(bus)) else {
        return "; its bus is closed".into();
    };
    let bus = port.bus();
    let joint = [bus.joint_unchecked(id)];
    let failed = state.apply(&mut WhjJoints {
        joints: &joint,
        servo: ServoLoop::Position,
    });
    match failed.first() {
        None => format!("; {what}"),
        Some(f) => format!(
            "; it did not reach its safe state ({}): {}",
            state.keyword(),
            f.error
        ),
    }
}

#[cfg(all(test, feature = "sim"))]
mod tests {
    #![allow(clippy::unwrap_used)]

    use serde_json::json;

    use crate::catalogue::{Request, run};
    use crate::ops::{Control, ErrorKind, Family};
    use crate::station::Station;
    use crate::station::jog::{JogRequest, Jogger};

    #[test]
    fn a_joint_jogged_into_an_obstacle_is_stopped_and_its_later_jogs_refused() {
        let (station, _wck, whj) = Station::simulated_with_handles().unwrap();
        for r in [
            json!({"op": "whj.mode", "joints": "1", "mode": "position"}),
            json!({"op": "whj.enable", "joints": "1"}),
        ] {
            let r: Request = serde_json::from_value(r).unwrap();
            run(&station, &r, &mut Control::none()).unwrap();
        }
        whj.with_bus(|b| {
            b.joint_mut(1)
                .unwrap()
                .set_obstacle(Some(robobus_sim::whj::Obstacle::above(5.0)));
        });
        let jogger = Jogger::new();
        let req = JogRequest {
            family: Family::Whj,
            bus: None,
            device: 1,
            target: 30.0,
        };
        // A held button: a jog every 20 ms on the bus's clock.
        let port = station.whj(None).unwrap();
        let start = port.bus().now();
        let mut stop = None;
        for k in 0..100u32 {
            let due = start + std::time::Duration::from_millis(20) * k;
            port.bus().sleep_until(due);
            if let Err(e) = jogger.jog(&station, &req) {
                stop = Some((k, e));
                break;
            }
        }
        let (k, e) = stop.unwrap();
        assert_eq!(e.kind(), ErrorKind::Device, "{e}");
        let text = e.to_string();
        assert!(
            text.contains("j1: stall protection: current ")
                && text.contains("reached the limit 7.8 A at ")
                && text.contains("its drive disabled"),
            "{text}"
        );
        // 2° a jog reaches the stop at the third; the stall time (0.3 s) after the
        // current passes the stall current the jog fails.
        assert!((20..=45).contains(&k), "{k}: {text}");
        let j1 = whj.with_bus(|b| b.joint(1).unwrap().state());
        assert!(!j1.enabled && j1.current_a.abs() < 1e-9, "{j1:?}");
        // Later jogs of it are refused, nothing sent.
        let e = jogger.jog(&station, &req).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Refused, "{e}");
        assert!(
            e.to_string().contains("protection stopped this device"),
            "{e}"
        );
        jogger.resume("sim-whj", 1);
        // Resumed, its jogs go out again (the feedback shows it disabled: the frame moves
        // nothing).
        let j = jogger.jog(&station, &req).unwrap();
        assert_eq!(j.feedback["enabled"], false, "{j:?}");
    }
}
