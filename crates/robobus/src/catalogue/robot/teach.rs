//! `robot.teach`: a trajectory recorded by hand, on the station's robot file, both
//! families: what `robot.play` plays back.
//!
//! The joints are made movable by hand first: a wCK servo passive (torque off), a WHJ joint
//! in current mode at `hold_ma` (0: limp; a small current helps against gravity). That
//! needs confirmation: a limp arm falls unless it is held. Every joint is then read
//! `seconds × rate_hz` times while the user moves it; a reading in which a joint did not
//! answer is left out of the trajectory (never filled with an older value) and counted.
//! At the end, and when stopped, every WHJ joint is disabled, set to position mode and
//! enabled again, then every bus goes to the robot file's `safe_state` (the robot
//! operations' one end, `settle`): with the defaults a WHJ joint
//! holds where it is and a wCK servo is passive. The report's summary is the trajectory
//! file (the CSV of [`crate::robot::trajectory`]).

use std::fmt::Write as _;
use std::time::Duration;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use robobus_wck::BaudRate;

use super::ROBOT;
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::effect::{Effect, Moved};
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::{Family, Plan};
use crate::ops::{Control, DeviceResult, ErrorKind, Failure, OpError, Outcome, Progress};
use crate::robot::RobotConfig;
use crate::station::Station;
use crate::station::clock::BusClock;
use crate::station::sampler::RobotSampler;

/// `robot.teach` (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Teach {
    /// How long the joints are read, seconds (0.1..=3600).
    pub seconds: f64,
    /// Readings (trajectory points) a second (1..=100; default 20).
    #[serde(default = "default_rate")]
    pub rate_hz: f64,
    /// The joints to record, by name; none: every joint of the robot file.
    #[serde(default)]
    pub joints: Option<Vec<String>>,
    /// The current a WHJ joint is held at while it is moved by hand, mA (-2000..=2000;
    /// default 0: limp).
    #[serde(default)]
    pub hold_ma: f64,
    /// Confirms that the joints go limp (a WHJ arm falls unless it is held).
    #[serde(default)]
    pub confirm: bool,
}

const fn default_rate() -> f64 {
    20.0
}

/// Range of `seconds`.
pub const TEACH_SECONDS: std::ops::RangeInclusive<f64> = 0.1..=3600.0;
/// Range of `rate_hz`.
pub const TEACH_RATE_HZ: std::ops::RangeInclusive<f64> = 1.0..=100.0;
/// Range of `hold_ma`.
pub const HOLD_MA: std::ops::RangeInclusive<f64> = -2000.0..=2000.0;

/// What a teach run needs confirmed.
pub const TEACH_CONFIRM: &str = "The robot file's wCK servos go passive and its WHJ joints \
     into current mode at the hold current: they go limp, and an arm falls under gravity \
     unless it is held. At the end each bus is left in the robot file's safe_state \
     (by default WHJ joints hold where they are, wCK servos stay passive).";

impl Teach {
    /// Checks the values (named as the command line's options); the number of readings.
    pub fn readings(&self) -> Result<u64, OpError> {
        for (option, v, range) in [
            ("--seconds", self.seconds, TEACH_SECONDS),
            ("--rate-hz", self.rate_hz, TEACH_RATE_HZ),
            ("--hold-ma", self.hold_ma, HOLD_MA),
        ] {
            super::within(option, v, &range)?;
        }
        if let Some(j) = &self.joints
            && (j.is_empty() || j.len() > crate::robot::trajectory::MAX_JOINTS)
        {
            return Err(OpError::invalid(
                "--joints",
                format!("{} names", j.len()),
                format!("1..={} joint names", crate::robot::trajectory::MAX_JOINTS),
            ));
        }
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // ≤ 360,000
        Ok(((self.seconds * self.rate_hz).round() as u64).max(1))
    }

    /// What a run sends, for the plan.
    pub fn note(&self) -> Result<String, OpError> {
        let n = self.readings()?;
        Ok(format!(
            "makes {} movable by hand (a wCK servo passive: FF <0xC0|ID> 00 <checksum>; a WHJ \
             joint disabled, set to current mode, enabled, and given {} mA), reads them {n} \
             times at {} Hz while you move them, then sets each WHJ joint back to position mode \
             (disabled, mode written, enabled) and leaves each bus in the robot file's \
             safe_state (hold: a position frame at the WHJ joint's measured angle; \
             disable: disabled; passive / break: the wCK servos passive / the bus-wide \
             break); the report's summary is the trajectory (CSV)",
            self.joints.as_ref().map_or_else(
                || "every joint of the robot file".to_owned(),
                |j| j.join(", ")
            ),
            self.hold_ma,
            self.rate_hz,
        ))
    }
}

impl Operation for Teach {
    const OP: &'static str = "robot.teach";
    const FAMILY: Family = Family::Robot;
    const DOC: OpDoc = OpDoc {
        args: "`seconds` (0.1..=3600), `rate_hz`=20 (1..=100), `joints` (names; none: every \
               joint of the robot file), `hold_ma`=0 (a WHJ joint's current while moved by \
               hand, -2000..=2000), `confirm`",
        report: "one row per joint by name: `samples`, `failed`, `min_deg`, `max_deg`, `ended` \
                 (how it was left: its bus's `safe_state` in the robot file, `holding`, \
                 `disabled`, `passive` or `braked`, or why not); `summary`: `trajectory` (the \
                 trajectory file `robot.play` plays), `points`, `dropped` (readings left out: a \
                 joint did not answer), `readings`, `interrupted`. wCK servos go passive and \
                 WHJ joints into current mode first, so it needs `confirm`",
        confirm: "limp joints",
    };
    type Row = DeviceResult<String, Taught>;
    type Summary = TeachSummary;

    /// Limp joints: an arm falls unless held.
    fn effect(&self) -> Effect {
        Effect::Motion
    }

    fn moved(&self) -> Result<Option<Moved>, OpError> {
        self.readings().map(|_| None)
    }

    fn confirmed(&self) -> bool {
        self.confirm
    }

    fn confirm(&mut self) {
        self.confirm = true;
    }

    fn check(&self) -> Result<Confirm, OpError> {
        self.readings()?;
        Ok(Confirm::of(ConfirmClass::Register, TEACH_CONFIRM))
    }

    /// Limp joints: asked like a register of the `confirm` class.
    fn plan(&self, _baud: BaudRate) -> Result<Plan, OpError> {
        let mut plan = Plan::notes_only(Self::OP, Family::Robot, vec![self.note()?]);
        plan.confirm = ConfirmClass::Register;
        plan.confirm_text = Some(TEACH_CONFIRM.to_owned());
        Ok(plan)
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, TeachSummary>, OpError> {
        let t = run_teach(cx.station, self, cx.control)?;
        Ok(Report::devices_with(Self::OP, ROBOT, t.joints).summary(t.summary))
    }
}

/// A recorded joint (its row of the report, by name).
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct Taught {
    /// Readings it answered.
    pub samples: u64,
    /// Readings it did not answer (the trajectory leaves those readings out).
    pub failed: u64,
    /// The smallest angle recorded, degrees.
    pub min_deg: Option<f64>,
    /// The largest angle recorded, degrees.
    pub max_deg: Option<f64>,
    /// Where it was left, in its bus's safe state (`holding`, `disabled`, `passive`,
    /// `braked`), or why it could not be.
    pub ended: String,
    #[serde(skip)]
    settled: bool,
    #[serde(skip)]
    last_error: Option<Failure>,
}

/// What a `robot.teach` run did.
struct TaughtRun {
    joints: Vec<DeviceResult<String, Taught>>,
    summary: TeachSummary,
}

/// The summary of `robot.teach`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct TeachSummary {
    /// The trajectory file (CSV) `robot.play` plays.
    pub trajectory: String,
    /// Its points (the readings every joint answered).
    pub points: u64,
    /// Readings left out: a joint did not answer.
    pub dropped: u64,
    /// Readings asked for.
    pub readings: u64,
    /// The stop token ended the reading early.
    pub interrupted: bool,
}

/// A joint being taught: its name, family, bus and ID.
struct Joint {
    name: String,
    wck: bool,
    bus: String,
    id: u8,
}

fn joints_of(config: &RobotConfig, r: &Teach) -> Result<Vec<Joint>, OpError> {
    let names: Vec<String> = match &r.joints {
        Some(n) => n.clone(),
        None => config.joints.iter().map(|j| j.name.clone()).collect(),
    };
    names
        .iter()
        .enumerate()
        .map(|(k, n)| {
            if names[..k].contains(n) {
                return Err(OpError::invalid("--joints", n, "a joint named once"));
            }
            let j = config.joints.iter().find(|j| &j.name == n).ok_or_else(|| {
                OpError::invalid(
                    "--joints",
                    n,
                    format!("a joint of the robot file: {}", config.joint_names()),
                )
            })?;
            Ok(Joint {
                name: n.clone(),
                wck: config.is_wck(j),
                bus: j.bus.clone(),
                id: j.id,
            })
        })
        .collect()
}

/// A joint's device on its bus.
enum Device {
    Wck(crate::station::WckPort, robobus_wck::ServoId),
    Whj(crate::station::WhjPort, robobus_whj::JointId),
}

impl Joint {
    fn device(&self, station: &Station) -> Result<Device, OpError> {
        let bad = |e: &dyn std::fmt::Display| OpError::invalid("robot", &self.name, e.to_string());
        Ok(if self.wck {
            Device::Wck(
                station.wck(Some(&self.bus))?,
                robobus_wck::ServoId::new(self.id).map_err(|e| bad(&e))?,
            )
        } else {
            Device::Whj(
                station.whj(Some(&self.bus))?,
                robobus_whj::JointId::new(self.id).map_err(|e| bad(&e))?,
            )
        })
    }
}

/// A WHJ joint switched to `mode`: disabled, the mode written, enabled again.
fn switch(
    port: &crate::station::WhjPort,
    id: robobus_whj::JointId,
    mode: robobus_whj::WorkMode,
) -> Result<crate::whj::Joint<'_>, OpError> {
    let joint = port.bus().joint(id)?;
    joint.disable()?;
    joint.set_mode(mode)?;
    joint.enable()?;
    Ok(joint)
}

/// Makes `j` movable by hand.
fn release(station: &Station, j: &Joint, hold_ma: f64) -> Result<(), OpError> {
    match j.device(station)? {
        Device::Wck(port, id) => {
            port.lock().servo(id).passive()?;
        }
        Device::Whj(port, id) => {
            switch(&port, id, robobus_whj::WorkMode::Current)?.command_current(hold_ma)?;
        }
    }
    Ok(())
}

/// Undoes [`release`] on a WHJ joint: back in position mode, enabled (it holds where it
/// is); a wCK servo stays as it is. The robot file's safe state follows ([`settle`]).
///
/// [`settle`]: super::settle
fn restore(station: &Station, j: &Joint) -> Result<(), OpError> {
    if let Device::Whj(port, id) = j.device(station)? {
        switch(&port, id, robobus_whj::WorkMode::Position)?;
    }
    Ok(())
}

/// Ends a run: each joint back from limp ([`restore`]), then every bus in the robot
/// file's safe state; each joint's `ended` says where it was left, or why not.
fn end(station: &Station, config: &RobotConfig, joints: &[Joint], rows: &mut [Taught]) {
    let restored: Vec<Result<(), OpError>> = joints.iter().map(|j| restore(station, j)).collect();
    let names: Vec<String> = joints.iter().map(|j| j.name.clone()).collect();
    let settled = super::settle(station, config, &names);
    for ((row, j), back) in rows.iter_mut().zip(joints).zip(restored) {
        let state = config
            .buses
            .get(&j.bus)
            .map(crate::robot::BusConfig::safe_state);
        (row.ended, row.settled) = match (back, settled.failed.iter().find(|(n, _)| *n == j.name)) {
            (Err(e), _) => (format!("not back in position mode: {e}"), false),
            (Ok(()), Some((_, f))) => (f.error.clone(), false),
            (Ok(()), None) => (state.map_or("", |s| s.outcome(!j.wck)).to_owned(), true),
        };
    }
}

/// A sampler of `joints` and the clock of their buses.
fn reader(
    station: &Station,
    config: &RobotConfig,
    joints: &[Joint],
) -> Result<(RobotSampler, BusClock), OpError> {
    let names: Vec<String> = joints.iter().map(|j| j.name.clone()).collect();
    let sub = super::only(config, &names);
    Ok((super::sampler(station, &sub)?, BusClock::of(station, &sub)?))
}

/// Each joint's row: a joint that missed readings, or does not hold at the end, fails it.
fn results(joints: &[Joint], rows: Vec<Taught>) -> Vec<DeviceResult<String, Taught>> {
    joints
        .iter()
        .zip(rows)
        .map(|(j, mut row)| match row.last_error.take() {
            Some(f) => DeviceResult::failed(
                j.name.clone(),
                Failure {
                    kind: if row.samples == 0 {
                        ErrorKind::NoDevice
                    } else {
                        f.kind
                    },
                    error: format!(
                        "{}: {} of {} readings failed (left out of the trajectory); the \
                         last: {}; at the end: {}",
                        j.name,
                        row.failed,
                        row.failed + row.samples,
                        f.error,
                        row.ended
                    ),
                },
            ),
            None if !row.settled => DeviceResult::failed(
                j.name.clone(),
                Failure::of(ErrorKind::Device, &format!("{}: {}", j.name, row.ended)),
            ),
            None => DeviceResult::ok(j.name.clone(), row),
        })
        .collect()
}

/// `robot.teach` on the station's robot file.
fn run_teach(
    station: &Station,
    r: &Teach,
    control: &mut Control<'_>,
) -> Result<TaughtRun, OpError> {
    let readings = r.readings()?;
    if !r.confirm {
        return Err(crate::catalogue::bounds::refused(TEACH_CONFIRM));
    }
    let config = station.robot().cloned().ok_or_else(super::no_robot)?;
    let joints = joints_of(&config, r)?;
    let (mut sampler, clock) = reader(station, &config, &joints)?;
    let mut rows: Vec<Taught> = joints
        .iter()
        .map(|_| Taught {
            samples: 0,
            failed: 0,
            min_deg: None,
            max_deg: None,
            ended: String::new(),
            settled: false,
            last_error: None,
        })
        .collect();
    // Released one by one; a failure ends the run as its end does: those released so far
    // back, every bus in its safe state.
    for (k, j) in joints.iter().enumerate() {
        if let Err(e) = release(station, j, r.hold_ma) {
            end(station, &config, &joints[..=k], &mut rows[..=k]);
            return Err(e);
        }
    }
    let mut csv = format!(
        "# taught by hand: {} readings at {} Hz\ntime_s,{}\n",
        readings,
        r.rate_hz,
        joints
            .iter()
            .map(|j| j.name.as_str())
            .collect::<Vec<_>>()
            .join(",")
    );
    let period = Duration::from_secs_f64(1.0 / r.rate_hz);
    let start = clock.now();
    let (mut taken, mut points, mut dropped) = (0u64, 0u64, 0u64);
    for k in 0..readings {
        let due = start + period * u32::try_from(k).unwrap_or(u32::MAX);
        if !control.sleep_with(due, |until| {
            if let Some(t) = until {
                clock.sleep_until(t);
            }
            clock.now()
        }) {
            break;
        }
        let t_s = (due - start).as_secs_f64();
        let got = sampler.sample(t_s);
        let mut line = format!("{t_s:.4}");
        let mut complete = true;
        for (row, reading) in rows.iter_mut().zip(got) {
            match reading.outcome {
                Outcome::Ok(s) => {
                    row.samples += 1;
                    let a = s.position_deg;
                    row.min_deg = Some(row.min_deg.map_or(a, |m| m.min(a)));
                    row.max_deg = Some(row.max_deg.map_or(a, |m| m.max(a)));
                    let _ = write!(line, ",{a:.4}");
                }
                Outcome::Failed(f) => {
                    row.failed += 1;
                    row.last_error = Some(f);
                    complete = false;
                }
            }
        }
        taken += 1;
        if complete {
            csv.push_str(&line);
            csv.push('\n');
            points += 1;
        } else {
            dropped += 1;
        }
        control.report(&Progress::new("teach", taken, Some(readings)));
    }
    end(station, &config, &joints, &mut rows);
    let results = results(&joints, rows);
    Ok(TaughtRun {
        joints: results,
        summary: TeachSummary {
            trajectory: csv,
            points,
            dropped,
            readings,
            interrupted: taken < readings,
        },
    })
}

#[cfg(all(test, feature = "sim"))]
mod tests {
    #![allow(clippy::unwrap_used)]

    use std::time::Duration;

    use serde_json::{Value, json};

    use crate::catalogue::{Request, confirmation, run};
    use crate::ops::{Control, ErrorKind};
    use crate::station::Station;

    fn req(v: Value) -> Request {
        serde_json::from_value(v).unwrap()
    }

    #[test]
    fn taught_by_hand_on_both_buses_then_played_back() {
        let (station, wck, whj) = Station::simulated_with_handles().unwrap();
        // Servo 0 is turned by hand to +20°, then to -10°; a hand takes joint 1 to +10°.
        let centre = 127.0 * robobus_sim::wck::mechanics::DEG_PER_STEP8;
        let t0 = wck.now();
        // The hand turns it at 50°/s: 2° every 40 ms, up to +20° and back to -10°.
        let path = (1..=10)
            .map(|k| f64::from(k) * 2.0)
            .chain((1..=15).map(|k| 20.0 - f64::from(k) * 2.0));
        for (k, deg) in (1u64..).zip(path) {
            wck.at(t0 + Duration::from_millis(40 * k), move |b| {
                b.servo_mut(0).unwrap().set_angle(centre + deg);
            });
        }
        whj.with_bus(|b| b.joint_mut(1).unwrap().set_hand(Some(10.0)));
        let teach = json!({"op": "robot.teach", "seconds": 1, "joints": ["s0", "j1"]});
        // Limp joints need confirmation: refused without it, nothing sent.
        assert!(
            confirmation(&req(teach.clone()))
                .unwrap()
                .unwrap()
                .contains("go limp")
        );
        let e = run(&station, &req(teach.clone()), &mut Control::none()).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Refused, "{e}");
        let mut confirmed = teach;
        confirmed["confirm"] = json!(true);
        let v = serde_json::to_value(run(&station, &req(confirmed), &mut Control::none()).unwrap())
            .unwrap();
        whj.with_bus(|b| b.joint_mut(1).unwrap().set_hand(None));
        assert_eq!(v["failed"], Value::Null, "{v:#}");
        let s = &v["summary"];
        assert_eq!(
            (s["points"].as_u64(), s["dropped"].as_u64()),
            (Some(20), Some(0)),
            "{v:#}"
        );
        let row = |n: &str| {
            v["results"]
                .as_array()
                .unwrap()
                .iter()
                .find(|r| r["id"] == n)
                .unwrap()
                .clone()
        };
        let (s0, j1) = (row("s0"), row("j1"));
        let step = robobus_sim::wck::mechanics::DEG_PER_STEP8;
        assert!(
            (s0["max_deg"].as_f64().unwrap() - 20.0).abs() <= step,
            "{s0}"
        );
        // On its way back to -10° when the reading ends.
        let min = s0["min_deg"].as_f64().unwrap();
        assert!((-10.0 - step..=-4.0).contains(&min), "{s0}");
        // The limp joint followed the hand, within its grip's few degrees.
        let max = j1["max_deg"].as_f64().unwrap();
        assert!((8.0..=10.5).contains(&max), "{j1}");
        // Each as its bus's safe state in the robot file: the wCK servo passive, the WHJ
        // joint holding (back in position mode, enabled).
        assert_eq!(
            (s0["ended"].as_str(), j1["ended"].as_str()),
            (Some("passive"), Some("holding"))
        );
        let held = whj.with_bus(|b| b.joint(1).unwrap().state());
        assert!(
            held.enabled && held.mode == 3 && !held.brake_locked,
            "{held:?}"
        );
        // The trajectory is a file robot.play reads, and plays back.
        let text = s["trajectory"].as_str().unwrap();
        let parsed = crate::robot::trajectory::Trajectory::parse(text).unwrap();
        assert_eq!(parsed.joints(), ["s0", "j1"]);
        // Its lead-in takes j1 from where the hand left it to the first point, then the
        // hand's motion, within the built-in file's max_velocity and max_acceleration:
        // what the simulated joint follows from rest (robot::simulated::whj_follows). The
        // pre-flight on the simulator passes it, and no target is held back.
        let play = req(json!({"op": "robot.play", "trajectory": text, "rate_hz": 50}));
        let p = serde_json::to_value(run(&station, &play, &mut Control::none()).unwrap()).unwrap();
        assert_eq!(p["failed"], Value::Null, "{p:#}");
        assert_eq!(
            p["summary"]["preflight"]["joints"][0]["joint"], "j1",
            "{p:#}"
        );
        for r in p["results"].as_array().unwrap() {
            assert!(r["tracking_rms_deg"].as_f64().unwrap() < 3.0, "{r}");
            assert_eq!(r["limited"], 0, "{r}");
        }
    }
}
