//! Diagnostics: what the station last learnt of each joint and bus of its robot file, as a
//! level (OK, warning, error, stale) with its reason and its values, for a front end to
//! publish (the bridge's `NS/diagnostics`, ROS 2's `diagnostic_msgs/msg/DiagnosticArray`).
//!
//! Nothing here touches a bus. A front end that samples the robot file's joints
//! (`robot.sample`) keeps its last reading of each joint in a [`Watch`] ([`Watch::record`]),
//! and [`Watch::diagnose`] turns those readings and what the station's WHJ buses saw anyway
//! (each joint's last status reply: its temperature, supply voltage and error bits; the
//! controller's bus-off state) into one [`Diagnosis`] per joint and per bus. A WHJ status
//! query answers the temperature and voltage with the position, so a sample already reads
//! them: diagnostics cost no frame of their own.
//!
//! The levels of a joint ([`diagnose_joint`]; the worst applies, its reasons in the
//! message):
//!
//! - **stale**: never read, or its last reading is older than the front end's
//!   `stale_after` (nothing of it is shown then: an old value is not this one);
//! - **error**: its last reading failed (silent: `no-device`, with the failure's text), an
//!   error bit that disables the drive, a temperature at or over its protection's stop
//!   limit ([`Limits::temperature_stop_c`]), or the host's protection stopped it
//!   ([`Fault`]);
//! - **warning**: an error bit that leaves the drive on, a temperature at or over its warning
//!   or derating limit, a supply voltage outside [`SUPPLY_V`];
//! - **OK** otherwise (held in the safe state says so in the message).
//!
//! A bus ([`diagnose_bus`]) is an error at bus-off or when none of its joints answered, a
//! warning when the controller is error passive or warning or some of its joints are
//! silent, stale when none of its joints was read recently.

use std::ops::RangeInclusive;
use std::time::{Duration, Instant};

use robobus_whj::{ErrorCode, JointId};
use serde::Serialize;

use super::Station;
use super::sampler::RobotJointSample;
use crate::ErrorKind;
use crate::ops::protect::{Fault, Limits};
use crate::ops::{DeviceResult, Failure, Outcome};
use crate::whj::BusState;

/// A joint not read for this long is stale, by default (a front end whose readings come
/// further apart than a third of it uses three of its periods).
pub const STALE_AFTER: Duration = Duration::from_secs(3);

/// The supply voltage the WHJ joints are made for, V (the vendor's remedy of the
/// under- and over-voltage bits: "keep the supply within 20–27 V"); outside it, a warning
/// before the joint's own bit.
pub const SUPPLY_V: RangeInclusive<f64> = 20.0..=27.0;

/// How a joint or bus is, in the order of `diagnostic_msgs/msg/DiagnosticStatus`'s levels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Level {
    /// Working.
    Ok,
    /// Working, with something to look at.
    Warn,
    /// Failed, or stopped.
    Error,
    /// Not read recently: nothing is known.
    Stale,
}

impl Level {
    /// Its byte in `DiagnosticStatus` (`OK` 0, `WARN` 1, `ERROR` 2, `STALE` 3).
    pub const fn byte(self) -> u8 {
        match self {
            Self::Ok => 0,
            Self::Warn => 1,
            Self::Error => 2,
            Self::Stale => 3,
        }
    }

    /// `OK`, `WARN`, `ERROR`, `STALE`.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Ok => "OK",
            Self::Warn => "WARN",
            Self::Error => "ERROR",
            Self::Stale => "STALE",
        }
    }

    /// How bad it is: stale is known to be worse than OK but not how much, so it ranks
    /// between a warning and an error when a bus sums up its joints.
    const fn rank(self) -> u8 {
        match self {
            Self::Ok => 0,
            Self::Warn => 1,
            Self::Stale => 2,
            Self::Error => 3,
        }
    }
}

/// One joint's or bus's diagnosis.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Diagnosis {
    /// `joint NAME` or `bus NAME` (a front end puts its own prefix before it).
    pub name: String,
    /// The device: `whj sim-whj 3`, `wck legs 0`, or the bus `whj sim-whj`.
    pub hardware_id: String,
    /// Its level.
    pub level: Level,
    /// Why: the reasons of its level, joined by `; ` (`OK` when there is nothing to say).
    pub message: String,
    /// What was read, as text: `position_deg`, `temperature_c`, `voltage_v`,
    /// `current_a`, `error_bits`, ... (none of a stale joint).
    pub values: Vec<(String, String)>,
}

/// The supply of a WHJ joint, from its last status reply.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Supply {
    /// Temperature, °C.
    pub temperature_c: f64,
    /// Supply voltage, V.
    pub voltage_v: f64,
    /// Error bits.
    pub error: u16,
}

/// What is known of one joint for [`diagnose_joint`].
#[derive(Debug, Clone, PartialEq)]
pub struct JointFacts {
    /// Its last reading: how long ago, and what came back; `None`: never read.
    pub last: Option<(Duration, Outcome<RobotJointSample>)>,
    /// A WHJ joint's supply from the status reply of that reading (`None`: a wCK servo,
    /// or none as recent).
    pub supply: Option<Supply>,
    /// The host's protection limits of the joint (the robot file's, with its model's
    /// defaults).
    pub limits: Limits,
    /// Its model, as it identified (`WHJ30`).
    pub model: Option<String>,
    /// The host's protection stop that names it, while commands stay refused.
    pub protection_stop: Option<Fault>,
    /// The reason of the safe stop that holds it (`command timeout`), while no command
    /// moved it since.
    pub held: Option<String>,
}

fn put(values: &mut Vec<(String, String)>, key: &str, value: String) {
    values.push((key.to_owned(), value));
}

fn fmt(v: f64, decimals: usize) -> String {
    format!("{v:.decimals$}")
}

/// The diagnosis of one joint (see the [module docs](self) for the levels): `name` its
/// name in the file, `hardware_id` its device, `stale_after` the age of a reading that is
/// no longer news.
pub fn diagnose_joint(
    name: &str,
    hardware_id: String,
    facts: &JointFacts,
    stale_after: Duration,
) -> Diagnosis {
    let mut reasons: Vec<(Level, String)> = Vec::new();
    let mut values: Vec<(String, String)> = Vec::new();
    match &facts.last {
        None => reasons.push((Level::Stale, "not read yet".into())),
        Some((age, _)) if *age > stale_after => reasons.push((
            Level::Stale,
            format!(
                "not read for {:.1} s (stale after {:.1} s)",
                age.as_secs_f64(),
                stale_after.as_secs_f64()
            ),
        )),
        Some((age, Outcome::Failed(f))) => {
            put(&mut values, "last_read_s", fmt(age.as_secs_f64(), 3));
            put(&mut values, "failure", f.kind.name().to_owned());
            let what = if f.kind == ErrorKind::NoDevice {
                "silent"
            } else {
                "its reading failed"
            };
            reasons.push((Level::Error, format!("{what}: {}", f.error)));
        }
        Some((age, Outcome::Ok(s))) => {
            put(&mut values, "last_read_s", fmt(age.as_secs_f64(), 3));
            put(&mut values, "position_deg", fmt(s.position_deg, 3));
            if let Some(v) = s.speed_deg_s {
                put(&mut values, "speed_deg_s", fmt(v, 3));
            }
            #[allow(clippy::cast_precision_loss)] // |mA| < 2^53
            if let Some(ma) = s.current_ma {
                put(&mut values, "current_a", fmt(ma as f64 / 1e3, 3));
            }
            if let Some(nm) = s.effort_nm {
                put(&mut values, "effort_nm", fmt(nm, 3));
            }
            if let Some(load) = s.load {
                put(&mut values, "load", load.to_string());
            }
            if let Some(on) = s.enabled {
                put(&mut values, "enabled", on.to_string());
            }
            if let Some(p) = facts.supply {
                supply(p, &facts.limits, &mut values, &mut reasons);
            } else {
                // A wCK servo reports no error bits (`ok`); a WHJ joint's bits without
                // the status reply's code are taken at their worst.
                put(&mut values, "error_bits", s.error.clone());
                if s.error != "ok" && s.error != "no error" {
                    reasons.push((Level::Error, format!("error bits: {}", s.error)));
                }
            }
        }
    }
    if let Some(m) = &facts.model {
        put(&mut values, "model", m.clone());
    }
    if let Some(f) = &facts.protection_stop {
        put(&mut values, "protection", f.to_string());
        reasons.push((Level::Error, f.to_string()));
    }
    if let Some(why) = &facts.held {
        put(&mut values, "safe_stop", why.clone());
    }
    let level = reasons
        .iter()
        .map(|r| r.0)
        .max_by_key(|l| l.rank())
        .unwrap_or(Level::Ok);
    let mut message: Vec<String> = reasons
        .into_iter()
        .filter(|r| r.0 == level)
        .map(|r| r.1)
        .collect();
    if message.is_empty() {
        message.push(match &facts.held {
            Some(why) => format!("OK, held in the safe state ({why})"),
            None => "OK".into(),
        });
    }
    Diagnosis {
        name: format!("joint {name}"),
        hardware_id,
        level,
        message: message.join("; "),
        values,
    }
}

/// A WHJ joint's supply from its last status reply: its values, and the reasons of its
/// error bits, temperature and voltage.
fn supply(
    p: Supply,
    limits: &Limits,
    values: &mut Vec<(String, String)>,
    reasons: &mut Vec<(Level, String)>,
) {
    let code = ErrorCode(p.error);
    values.extend([
        ("error_bits".to_owned(), code.to_string()),
        ("error_code".to_owned(), format!("{:#06x}", p.error)),
        ("temperature_c".to_owned(), fmt(p.temperature_c, 1)),
        ("voltage_v".to_owned(), fmt(p.voltage_v, 2)),
    ]);
    if !code.is_empty() {
        let level = if code.disables_drive() {
            Level::Error
        } else {
            Level::Warn
        };
        reasons.push((level, format!("error bits: {code}")));
    }
    reasons.extend(temperature(p.temperature_c, limits));
    if !SUPPLY_V.contains(&p.voltage_v) {
        reasons.push((
            Level::Warn,
            format!(
                "supply {:.2} V outside {}..{} V",
                p.voltage_v,
                SUPPLY_V.start(),
                SUPPLY_V.end()
            ),
        ));
    }
}

/// The temperature against the protection's limits: the highest reached.
fn temperature(c: f64, l: &Limits) -> Option<(Level, String)> {
    [
        (l.temperature_stop_c, Level::Error, "stop"),
        (l.temperature_derate_c, Level::Warn, "derating"),
        (l.temperature_warn_c, Level::Warn, "warning"),
    ]
    .into_iter()
    .find_map(|(limit, level, what)| {
        let limit = limit?;
        (c >= limit).then(|| {
            (
                level,
                format!("temperature {c:.1} °C at or over the {what} limit {limit} °C"),
            )
        })
    })
}

/// What is known of one bus for [`diagnose_bus`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BusFacts {
    /// `wck` or `whj`.
    pub family: &'static str,
    /// A WHJ bus's controller state and its bus-off reports so far.
    pub state: Option<(BusState, u64)>,
    /// The diagnoses of its joints: (name, level).
    pub joints: Vec<(String, Level)>,
}

/// The diagnosis of bus `name` (see the [module docs](self)).
pub fn diagnose_bus(name: &str, facts: &BusFacts) -> Diagnosis {
    let n = facts.joints.len();
    let named = |l: Level| -> Vec<&str> {
        facts
            .joints
            .iter()
            .filter(|j| j.1 == l)
            .map(|j| j.0.as_str())
            .collect()
    };
    let (failed, stale) = (named(Level::Error), named(Level::Stale));
    let answering = n - failed.len() - stale.len();
    let mut values = vec![
        ("joints".to_owned(), n.to_string()),
        ("answering".to_owned(), answering.to_string()),
    ];
    let mut reasons: Vec<(Level, String)> = Vec::new();
    if let Some((state, bus_off)) = facts.state {
        values.push(("state".into(), state.to_string()));
        values.push(("bus_off_events".into(), bus_off.to_string()));
        match state {
            BusState::BusOff => reasons.push((Level::Error, "bus-off".into())),
            BusState::ErrorPassive | BusState::ErrorWarning => {
                reasons.push((Level::Warn, format!("the controller is {state}")));
            }
            BusState::Active => {}
        }
    }
    if n > 0 && stale.len() == n {
        reasons.push((Level::Stale, "no joint read recently".into()));
    } else if !failed.is_empty() {
        let level = if answering == 0 {
            Level::Error
        } else {
            Level::Warn
        };
        reasons.push((
            level,
            format!(
                "{} of {n} joints in error: {}",
                failed.len(),
                failed.join(", ")
            ),
        ));
    }
    let level = reasons
        .iter()
        .map(|r| r.0)
        .max_by_key(|l| l.rank())
        .unwrap_or(Level::Ok);
    let message: Vec<String> = reasons
        .into_iter()
        .filter(|r| r.0 == level)
        .map(|r| r.1)
        .collect();
    Diagnosis {
        name: format!("bus {name}"),
        hardware_id: format!("{} {name}", facts.family),
        level,
        message: if message.is_empty() {
            format!("OK, {answering} of {n} joints answering")
        } else {
            message.join("; ")
        },
        values,
    }
}

/// The stops a front end knows of, for [`Watch::diagnose`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Stops {
    /// The host's protection stop (it names its joint), while it lasts.
    pub protection: Option<Fault>,
    /// The reason of the safe stop that holds devices, and those devices (bus, ID), while
    /// no command moved them since.
    pub held: Option<(String, Vec<(String, u8)>)>,
}

/// A reading: when it was taken, and what came back.
type Reading = (Instant, Outcome<RobotJointSample>);

/// A front end's last reading of each joint of the station's robot file (see the
/// [module docs](self)).
#[derive(Debug, Clone, Default)]
pub struct Watch {
    /// Per joint of the file, by name: its last reading.
    last: Vec<(String, Option<Reading>)>,
}

impl Watch {
    /// A watch of the station's robot file's joints, none read yet (empty without a
    /// robot file).
    pub fn new(station: &Station) -> Self {
        Self {
            last: station
                .robot()
                .map(|r| r.joints.iter().map(|j| (j.name.clone(), None)).collect())
                .unwrap_or_default(),
        }
    }

    /// A sample's rows (a `robot.sample`'s, by joint name), taken at `at`; a row of a
    /// joint the file does not have is ignored.
    pub fn record(&mut self, at: Instant, rows: Vec<DeviceResult<String, RobotJointSample>>) {
        for row in rows {
            if let Some(slot) = self.last.iter_mut().find(|(n, _)| *n == row.id) {
                slot.1 = Some((at, row.outcome));
            }
        }
    }

    /// A sample that failed as a whole at `at`: every joint's reading failed with it.
    pub fn record_failure(&mut self, at: Instant, failure: &Failure) {
        for slot in &mut self.last {
            slot.1 = Some((at, Outcome::Failed(failure.clone())));
        }
    }

    /// One diagnosis per joint of the station's robot file, in the file's order, then one
    /// per bus in the file's order, at `now` (the instant the readings' `at` are measured
    /// on); a reading older than `stale_after` is stale. Reads nothing from a device: the
    /// WHJ buses' last status replies and controller state are what they received anyway.
    pub fn diagnose(
        &self,
        station: &Station,
        now: Instant,
        stale_after: Duration,
        stops: &Stops,
    ) -> Vec<Diagnosis> {
        let Some(config) = station.robot() else {
            return Vec::new();
        };
        let mut joints = Vec::with_capacity(config.joints.len());
        for (j, (_, last)) in config.joints.iter().zip(&self.last) {
            let wck = config.is_wck(j);
            let port = (!wck).then(|| station.whj(Some(&j.bus)).ok()).flatten();
            let id = JointId::new(j.id).ok();
            let identity = port
                .as_ref()
                .zip(id)
                .and_then(|(p, id)| p.bus().cached_identity(id));
            let last = last
                .as_ref()
                .map(|(at, o)| (now.saturating_duration_since(*at), o.clone()));
            // The supply of the joint's last status reply: only when this reading
            // answered and that reply is within `stale_after` too (on the bus's clock; a
            // sample's status query is that reply).
            let supply = match (&last, &port, id) {
                (Some((age, Outcome::Ok(_))), Some(port), Some(id)) if *age <= stale_after => {
                    let bus = port.bus();
                    let telemetry = bus.telemetry();
                    let jt = telemetry.joint(id);
                    let fresh = jt.updated.is_some_and(|updated| {
                        bus.now().saturating_duration_since(updated) <= stale_after
                    });
                    match (fresh, jt.temperature, jt.voltage, jt.error) {
                        (true, Some(celsius), Some(volts), Some(error)) => Some(Supply {
                            temperature_c: f64::from(celsius.celsius()),
                            voltage_v: f64::from(volts.volts()),
                            error: error.bits(),
                        }),
                        _ => None,
                    }
                }
                _ => None,
            };
            let facts = JointFacts {
                last,
                supply,
                limits: config.protection_of(j, identity.map(|i| i.model)),
                model: identity.map(|i| i.model.name().to_owned()),
                protection_stop: stops.protection.clone().filter(|f| f.joint == j.name),
                held: stops.held.as_ref().and_then(|(why, devices)| {
                    devices
                        .iter()
                        .any(|(b, id)| *b == j.bus && *id == j.id)
                        .then(|| why.clone())
                }),
            };
            let family = if wck { "wck" } else { "whj" };
            joints.push(diagnose_joint(
                &j.name,
                format!("{family} {} {}", j.bus, j.id),
                &facts,
                stale_after,
            ));
        }
        let mut buses = Vec::with_capacity(config.buses.len());
        for (name, bus) in &config.buses {
            let state = (!bus.is_wck())
                .then(|| station.whj(Some(name)).ok())
                .flatten()
                .map(|p| {
                    let h = p.bus().telemetry().bus;
                    (h.state, h.bus_off_events)
                });
            let facts = BusFacts {
                family: if bus.is_wck() { "wck" } else { "whj" },
                state,
                joints: config
                    .joints
                    .iter()
                    .zip(&joints)
                    .filter(|(j, _)| j.bus == *name)
                    .map(|(j, d)| (j.name.clone(), d.level))
                    .collect(),
            };
            buses.push(diagnose_bus(name, &facts));
        }
        joints.extend(buses);
        joints
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ops::protect::{Action, Check, WHJ_OVER_TEMPERATURE_C};

    const STALE: Duration = Duration::from_secs(3);

    fn sample() -> RobotJointSample {
        RobotJointSample {
            position_deg: 12.5,
            speed_deg_s: Some(0.0),
            current_ma: Some(250),
            effort_nm: Some(0.5),
            load: None,
            enabled: Some(true),
            error: "no error".into(),
        }
    }

    fn answered(temperature_c: f64, voltage_v: f64, error: u16) -> JointFacts {
        JointFacts {
            last: Some((Duration::from_millis(20), Outcome::Ok(sample()))),
            supply: Some(Supply {
                temperature_c,
                voltage_v,
                error,
            }),
            limits: Limits::whj(Some(robobus_whj::units::Model::Joint30)),
            model: Some("WHJ30".into()),
            protection_stop: None,
            held: None,
        }
    }

    fn diagnose(facts: &JointFacts) -> Diagnosis {
        diagnose_joint("j3", "whj arm 3".into(), facts, STALE)
    }

    fn value<'a>(d: &'a Diagnosis, key: &str) -> Option<&'a str> {
        d.values
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    #[test]
    fn a_joint_that_answered_cool_on_a_good_supply_is_ok_with_its_values() {
        let d = diagnose(&answered(35.0, 24.0, 0));
        assert_eq!((d.level, d.message.as_str()), (Level::Ok, "OK"));
        assert_eq!(d.name, "joint j3");
        assert_eq!(d.hardware_id, "whj arm 3");
        for (k, v) in [
            ("position_deg", "12.500"),
            ("current_a", "0.250"),
            ("temperature_c", "35.0"),
            ("voltage_v", "24.00"),
            ("error_bits", "no error"),
            ("error_code", "0x0000"),
            ("last_read_s", "0.020"),
            ("model", "WHJ30"),
        ] {
            assert_eq!(value(&d, k), Some(v), "{k}");
        }
    }

    #[test]
    fn a_silent_joint_is_an_error_naming_its_failure() {
        let facts = JointFacts {
            last: Some((
                Duration::from_millis(40),
                Outcome::Failed(Failure::of(
                    ErrorKind::NoDevice,
                    &"joint 3: no reply within 2.0 ms",
                )),
            )),
            supply: None,
            ..answered(35.0, 24.0, 0)
        };
        let d = diagnose(&facts);
        assert_eq!(d.level, Level::Error);
        assert_eq!(d.message, "silent: joint 3: no reply within 2.0 ms");
        assert_eq!(value(&d, "failure"), Some("no-device"));
        // No value it did not read.
        assert_eq!(value(&d, "position_deg"), None);
        assert_eq!(value(&d, "temperature_c"), None);
    }

    #[test]
    fn a_joint_not_read_within_stale_after_is_stale_and_shows_nothing_old() {
        let mut facts = answered(35.0, 24.0, 0);
        facts.last = Some((Duration::from_millis(3001), Outcome::Ok(sample())));
        let d = diagnose(&facts);
        assert_eq!(d.level, Level::Stale);
        assert_eq!(d.message, "not read for 3.0 s (stale after 3.0 s)");
        assert_eq!(value(&d, "position_deg"), None);
        assert_eq!(value(&d, "temperature_c"), None);
        // At the limit it is still news.
        facts.last = Some((STALE, Outcome::Ok(sample())));
        assert_eq!(diagnose(&facts).level, Level::Ok);
        facts.last = None;
        let d = diagnose(&facts);
        assert_eq!(
            (d.level, d.message.as_str()),
            (Level::Stale, "not read yet")
        );
    }

    #[test]
    fn heat_warns_at_the_warning_and_derating_limits_and_is_an_error_at_the_stop_limit() {
        let l = Limits::whj(Some(robobus_whj::units::Model::Joint30));
        assert_eq!(
            (
                l.temperature_warn_c,
                l.temperature_derate_c,
                l.temperature_stop_c
            ),
            (
                Some(WHJ_OVER_TEMPERATURE_C - 15.0),
                Some(WHJ_OVER_TEMPERATURE_C - 10.0),
                Some(WHJ_OVER_TEMPERATURE_C - 5.0)
            )
        );
        for (c, level, message) in [
            (74.9, Level::Ok, "OK"),
            (
                75.0,
                Level::Warn,
                "temperature 75.0 °C at or over the warning limit 75 °C",
            ),
            (
                80.0,
                Level::Warn,
                "temperature 80.0 °C at or over the derating limit 80 °C",
            ),
            (
                85.0,
                Level::Error,
                "temperature 85.0 °C at or over the stop limit 85 °C",
            ),
        ] {
            let d = diagnose(&answered(c, 24.0, 0));
            assert_eq!((d.level, d.message.as_str()), (level, message), "{c} °C");
        }
        // The robot file's own limits are the ones applied.
        let mut facts = answered(62.0, 24.0, 0);
        facts.limits.temperature_stop_c = Some(60.0);
        assert_eq!(diagnose(&facts).level, Level::Error);
        // Protection off: no limit, the joint's own bit says it.
        facts.limits = Limits::OFF;
        assert_eq!(diagnose(&facts).level, Level::Ok);
    }

    #[test]
    fn error_bits_that_disable_the_drive_are_errors_the_others_warnings() {
        let d = diagnose(&answered(40.0, 24.0, 0x0008));
        assert_eq!(d.level, Level::Error);
        assert_eq!(d.message, "error bits: over-temperature");
        assert_eq!(value(&d, "error_code"), Some("0x0008"));
        // 0x4000 is the one bit known to leave the drive on.
        let d = diagnose(&answered(40.0, 24.0, 0x4000));
        assert_eq!(d.level, Level::Warn, "{}", d.message);
        assert!(d.message.starts_with("error bits: "), "{}", d.message);
    }

    #[test]
    fn error_bits_without_the_status_replys_code_are_taken_at_their_worst() {
        let mut facts = answered(40.0, 24.0, 0);
        facts.supply = None;
        assert_eq!(diagnose(&facts).level, Level::Ok);
        facts.last = Some((
            Duration::from_millis(20),
            Outcome::Ok(RobotJointSample {
                error: "position limit".into(),
                ..sample()
            }),
        ));
        let d = diagnose(&facts);
        assert_eq!(
            (d.level, d.message.as_str()),
            (Level::Error, "error bits: position limit")
        );
    }

    #[test]
    fn a_supply_outside_its_rating_warns() {
        let d = diagnose(&answered(40.0, 19.5, 0));
        assert_eq!(
            (d.level, d.message.as_str()),
            (Level::Warn, "supply 19.50 V outside 20..27 V")
        );
        assert_eq!(diagnose(&answered(40.0, 27.0, 0)).level, Level::Ok);
    }

    #[test]
    fn a_protection_stop_is_an_error_and_a_safe_stop_is_said() {
        let fault = Fault {
            joint: "j3".into(),
            check: Check::Stall,
            quantity: "current_a",
            value: 2.5,
            limit: 2.0,
            at_s: 1.25,
            action: Action::Stop,
        };
        let mut facts = answered(40.0, 24.0, 0);
        facts.protection_stop = Some(fault.clone());
        let d = diagnose(&facts);
        assert_eq!(d.level, Level::Error);
        assert_eq!(d.message, fault.to_string());
        facts.protection_stop = None;
        facts.held = Some("command timeout".into());
        let d = diagnose(&facts);
        assert_eq!(
            (d.level, d.message.as_str()),
            (Level::Ok, "OK, held in the safe state (command timeout)")
        );
        assert_eq!(value(&d, "safe_stop"), Some("command timeout"));
    }

    #[test]
    fn a_bus_is_an_error_at_bus_off_or_with_no_joint_answering_and_warns_for_some() {
        let bus = |state, joints: &[Level]| {
            diagnose_bus(
                "arm",
                &BusFacts {
                    family: "whj",
                    state: Some((state, 0)),
                    joints: joints
                        .iter()
                        .enumerate()
                        .map(|(i, l)| (format!("j{}", i + 1), *l))
                        .collect(),
                },
            )
        };
        let d = bus(BusState::Active, &[Level::Ok, Level::Warn]);
        assert_eq!(
            (d.level, d.message.as_str()),
            (Level::Ok, "OK, 2 of 2 joints answering")
        );
        assert_eq!(d.hardware_id, "whj arm");
        let d = bus(BusState::Active, &[Level::Ok, Level::Error, Level::Ok]);
        assert_eq!(
            (d.level, d.message.as_str()),
            (Level::Warn, "1 of 3 joints in error: j2")
        );
        let d = bus(BusState::Active, &[Level::Error, Level::Error]);
        assert_eq!(d.level, Level::Error);
        let d = bus(BusState::BusOff, &[Level::Ok]);
        assert_eq!((d.level, d.message.as_str()), (Level::Error, "bus-off"));
        let d = bus(BusState::ErrorPassive, &[Level::Ok]);
        assert_eq!(
            (d.level, d.message.as_str()),
            (Level::Warn, "the controller is error passive")
        );
        let d = bus(BusState::Active, &[Level::Stale, Level::Stale]);
        assert_eq!(d.level, Level::Stale);
    }

    #[cfg(feature = "sim")]
    #[test]
    fn the_simulated_robot_sampled_is_ok_with_each_joints_supply_and_stale_later() {
        let station = Station::simulated().unwrap();
        let mut watch = Watch::new(&station);
        let t0 = Instant::now();
        let d = watch.diagnose(&station, t0, STALE, &Stops::default());
        let n = station.robot().unwrap().joints.len();
        assert_eq!(d.len(), n + 2);
        assert!(d[..n].iter().all(|d| d.level == Level::Stale));
        let rows = station.sample_robot().unwrap().unwrap();
        watch.record(t0, rows);
        let d = watch.diagnose(&station, t0, STALE, &Stops::default());
        for j in &d {
            assert_eq!(j.level, Level::Ok, "{j:?}");
        }
        let j1 = d.iter().find(|d| d.name == "joint j1").unwrap();
        assert_eq!(j1.hardware_id, "whj sim-whj 1");
        assert!(value(j1, "temperature_c").is_some(), "{j1:?}");
        let volts: f64 = value(j1, "voltage_v").unwrap().parse().unwrap();
        assert!(SUPPLY_V.contains(&volts), "{j1:?}");
        assert_eq!(value(j1, "model"), Some("WHJ30"));
        let later = watch.diagnose(&station, t0 + STALE * 2, STALE, &Stops::default());
        assert!(later[..n].iter().all(|d| d.level == Level::Stale));
        assert!(later[n..].iter().all(|d| d.level == Level::Stale));
    }
}
