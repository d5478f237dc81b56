//! The robot operations (`robot.*`): a station's robot file read as one robot, its joints
//! by name in joint units, across every bus the file names. One file per operation
//! ([`sample`], [`calibrate`], [`play`], [`teach`], [`teleop`]); this module holds what
//! they share: the checks before a robot operation moves anything (`ready_at`) and how
//! every one of them ends, each bus of its joints in the robot file's `safe_state`
//! (`settle`).

use std::ops::RangeInclusive;

use serde::Serialize;

use robobus_wck::{ServoId, TorqueLevel};
use robobus_whj::WorkMode;

use crate::ops::SafeState;
use crate::ops::safe::{SafeDevice, WckServos as WckDevices, WhjJoints as WhjDevices};
use crate::ops::whj::ServoLoop;
use crate::ops::{DeviceResult, ErrorKind, Failure, OpError, Outcome};
use crate::robot::{JointConfig, RobotConfig};
use crate::station::Station;
use crate::station::sampler::RobotSampler;

pub mod calibrate;
pub mod play;
pub mod sample;
pub mod teach;
pub mod teleop;

pub use calibrate::{Calibrate, ZeroPose};
pub use play::{Blend, Commanded, Play, PlayTick, Taken};
pub use sample::Sample;
pub use teach::Teach;
pub use teleop::{Pair, Teleop};

/// The bus name of a robot operation's report (the station's robot file).
pub const ROBOT: &str = "robot";

pub(super) const fn yes() -> bool {
    true
}

/// The robot file `config` cut to the joints `names` (in that order) and the buses they
/// are on.
pub(super) fn only(config: &RobotConfig, names: &[String]) -> RobotConfig {
    let mut sub = config.clone();
    sub.joints = names
        .iter()
        .filter_map(|n| config.joints.iter().find(|j| &j.name == n).cloned())
        .collect();
    sub.buses
        .retain(|name, _| sub.joints.iter().any(|j| &j.bus == name));
    sub
}

/// A sampler of `config`'s joints on the station's ports.
pub(super) fn sampler(station: &Station, config: &RobotConfig) -> Result<RobotSampler, OpError> {
    RobotSampler::on_ports(
        config,
        |n| station.wck(Some(n)).ok(),
        |n| station.whj(Some(n)).ok(),
    )
    .map_err(|e| OpError::invalid("robot", "bus", e.to_string()))
}

/// Makes `config`'s wCK servos passive (torque off: moved by hand). A servo that does not
/// answer is found silent by the readings that follow.
pub(super) fn make_passive(station: &Station, config: &RobotConfig) -> Result<(), OpError> {
    for j in config.joints.iter().filter(|j| config.is_wck(j)) {
        let port = station.wck(Some(&j.bus))?;
        let id = robobus_wck::ServoId::new(j.id)
            .map_err(|e| OpError::invalid("robot", &j.name, e.to_string()))?;
        let _ = port.lock().servo(id).passive();
    }
    Ok(())
}

/// Where each of the joints `names` of the robot file is now (joint degrees, in that
/// order), checked before a robot operation moves them: refused, nothing moved, when one
/// is off its position interface (`station::interfaces`), does not answer, stands
/// outside its soft limits, or is a WHJ joint not enabled in position mode (`what` needs it: "a trajectory"; the wCK servos would otherwise move
/// without it). The one check of `robot.play` and `robot.teleop`.
pub(super) fn ready_at(
    station: &Station,
    config: &RobotConfig,
    names: &[String],
    what: &str,
) -> Result<Vec<f64>, OpError> {
    station.interfaces().check_joints(names)?;
    let mut sampler = sampler(station, &only(config, names))?;
    let rows = sampler.sample(0.0);
    let mut at = Vec::with_capacity(names.len());
    for name in names {
        let Some(j) = config.joints.iter().find(|j| &j.name == name) else {
            return Err(OpError::invalid(
                "robot",
                name,
                format!("a joint of the robot file: {}", config.joint_names()),
            ));
        };
        let deg = match rows.iter().find(|r| &r.id == name).map(|r| &r.outcome) {
            Some(Outcome::Ok(s)) => s.position_deg,
            Some(Outcome::Failed(f)) => {
                return Err(OpError::Refused(format!(
                    "{name} did not answer ({}); nothing was moved",
                    f.error
                )));
            }
            None => {
                return Err(OpError::Refused(format!(
                    "{name} was not read; nothing was moved"
                )));
            }
        };
        let [lo, hi] =
            [j.limits[0].min(j.limits[1]), j.limits[0].max(j.limits[1])].map(f64::to_degrees);
        if !(lo - 0.5..=hi + 0.5).contains(&deg) {
            return Err(OpError::Refused(format!(
                "{name} is at {deg:.2}°, outside its soft limits {lo:.2}..={hi:.2}°; bring it \
                 inside first; nothing was moved"
            )));
        }
        at.push(deg);
    }
    for name in names {
        let Some(j) = config.joints.iter().find(|j| &j.name == name) else {
            continue;
        };
        if config.is_wck(j) {
            continue;
        }
        let port = station.whj(Some(&j.bus))?;
        let id = robobus_whj::JointId::new(j.id)
            .map_err(|e| OpError::invalid("robot", name, e.to_string()))?;
        let joint = port.bus().joint(id)?;
        crate::ops::whj::require_ready(&joint, ServoLoop::Position, what)
            .map_err(|e| OpError::Refused(format!("{name}: {e}; nothing was moved")))?;
    }
    Ok(at)
}

/// How every robot operation ends, for its plan.
pub(super) const END_NOTE: &str = "; at the end (finished, failed or stopped) each bus of \
     its joints is left in the robot file's safe_state (hold: a position frame at each enabled \
     WHJ joint's measured angle, a disabled one left so; disable: the WHJ joints disabled; \
     passive / break: the wCK servos passive / the bus-wide break)";

/// How a robot operation left one bus: in the robot file's `safe_state` for it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, schemars::JsonSchema)]
pub struct BusEnd {
    /// The bus (the file's name).
    pub bus: String,
    /// The file's `safe_state` for it (`passive`, `break`, `hold`, `disable`).
    pub safe_state: &'static str,
    /// The operation's joints on it that did not reach that state, each with why.
    pub failed: Vec<String>,
}

/// The end of a robot operation ([`settle`]): each bus of its joints, and the joints that
/// did not reach their bus's safe state.
#[derive(Debug, Default)]
pub(super) struct Settled {
    pub(super) buses: Vec<BusEnd>,
    /// By joint name.
    pub(super) failed: Vec<(String, Failure)>,
}

impl Settled {
    /// `rows` with the joints that did not reach their safe state failed (a row that had
    /// failed already says both).
    pub(super) fn fail_rows<T>(
        &self,
        rows: Vec<DeviceResult<String, T>>,
    ) -> Vec<DeviceResult<String, T>> {
        rows.into_iter()
            .map(|row| {
                let Some((_, f)) = self.failed.iter().find(|(n, _)| *n == row.id) else {
                    return row;
                };
                let failure = match row.outcome {
                    Outcome::Ok(_) => f.clone(),
                    Outcome::Failed(before) => Failure {
                        kind: before.kind,
                        error: format!("{}; {}", before.error, f.error),
                    },
                };
                DeviceResult::failed(row.id, failure)
            })
            .collect()
    }

    /// Logs the joints that did not reach their safe state (an operation that failed
    /// returns its own error).
    pub(super) fn log(&self) {
        for (_, f) in &self.failed {
            tracing::warn!("{}", f.error);
        }
    }

    /// The first joint among `names` that did not reach its safe state.
    pub(super) fn first_of(&self, names: &[String]) -> Option<Failure> {
        self.failed
            .iter()
            .find(|(n, _)| names.contains(n))
            .map(|(_, f)| f.clone())
    }
}

/// The end of a `robot.play` played to its end: with [`Station::holds_at_end`], each of
/// its joints holds its last point (a WHJ bus `hold`, a wCK bus left as the last
/// position commands left it, `hold` in the report); otherwise [`settle`].
pub(super) fn settle_at_end(station: &Station, config: &RobotConfig, names: &[String]) -> Settled {
    if !station.holds_at_end() {
        return settle(station, config, names);
    }
    let sub = only(config, names);
    let mut settled = Settled::default();
    for (bus, cfg) in &sub.buses {
        let joints: Vec<&JointConfig> = sub.joints.iter().filter(|j| &j.bus == bus).collect();
        let failed = if cfg.is_wck() {
            Vec::new()
        } else {
            settle_whj(station, bus, SafeState::Hold, &joints)
        };
        let mut end = BusEnd {
            bus: bus.clone(),
            safe_state: SafeState::Hold.keyword(),
            failed: Vec::new(),
        };
        for (name, kind, e) in failed {
            let f = Failure::of(kind, &format!("{name}: did not hold its last point: {e}"));
            end.failed.push(f.error.clone());
            settled.failed.push((name, f));
        }
        settled.buses.push(end);
    }
    settled
}

/// Ends a robot operation: every bus of the joints `names` in the `safe_state` the robot
/// file names for it, through [`SafeState::apply`] (the one safe stop), whether the
/// operation finished, failed or was stopped. wCK: `passive` makes each servo passive,
/// `break` sends the bus-wide break. WHJ: `hold` keeps each enabled joint holding where it
/// is in its loop (a position frame at its measured angle; speed or current 0) and leaves
/// a disabled joint disabled (nothing is enabled that was not); `disable` disables each
/// joint (brake models lock the brake). Every joint is tried; a joint that does not answer
/// is a failure of its own.
pub(super) fn settle(station: &Station, config: &RobotConfig, names: &[String]) -> Settled {
    settle_with(station, config, names, &[])
}

/// [`settle`], with the WHJ joints `torque_off` disabled whatever their bus's
/// `safe_state` (a joint the host's protection stopped, which would keep pushing or
/// heating while it holds; see [`crate::ops::protect::torque_off_is_safe`]).
pub(super) fn settle_with(
    station: &Station,
    config: &RobotConfig,
    names: &[String],
    torque_off: &[String],
) -> Settled {
    let sub = only(config, names);
    let mut settled = Settled::default();
    for (bus, cfg) in &sub.buses {
        let state = cfg.safe_state();
        let joints: Vec<&JointConfig> = sub.joints.iter().filter(|j| &j.bus == bus).collect();
        let failed = if cfg.is_wck() {
            settle_wck(station, bus, cfg.torque().unwrap_or(2), state, &joints)
        } else {
            let (off, rest): (Vec<&JointConfig>, Vec<&JointConfig>) =
                joints.iter().partition(|j| torque_off.contains(&j.name));
            let mut failed = settle_whj(station, bus, state, &rest);
            if !off.is_empty() {
                failed.extend(settle_whj(station, bus, SafeState::Disable, &off));
            }
            failed
        };
        let mut end = BusEnd {
            bus: bus.clone(),
            safe_state: state.keyword(),
            failed: Vec::new(),
        };
        for (name, kind, e) in failed {
            let f = Failure::of(
                kind,
                &format!(
                    "{name}: did not reach its safe state ({}): {e}",
                    state.keyword()
                ),
            );
            end.failed.push(f.error.clone());
            settled.failed.push((name, f));
        }
        settled.buses.push(end);
    }
    settled
}

/// A joint that did not reach its safe state: its name, the failure's kind and message.
type Unsettled = (String, ErrorKind, String);

/// Every joint of `joints` failed with `e`.
fn all_failed(joints: &[&JointConfig], e: &OpError) -> Vec<Unsettled> {
    joints
        .iter()
        .map(|j| (j.name.clone(), e.kind(), e.to_string()))
        .collect()
}

/// [`settle`] on a wCK bus: each joint that failed, with why.
fn settle_wck(
    station: &Station,
    bus: &str,
    torque: u8,
    state: SafeState,
    joints: &[&JointConfig],
) -> Vec<Unsettled> {
    let all = |e: &OpError| all_failed(joints, e);
    let port = match station.wck(Some(bus)) {
        Ok(p) => p,
        Err(e) => return all(&e),
    };
    let ids: Vec<ServoId> = joints
        .iter()
        .filter_map(|j| ServoId::new(j.id).ok())
        .collect();
    let torque = TorqueLevel::new(torque).unwrap_or(TorqueLevel::MIN);
    let mut guard = port.lock();
    let failed = state.apply(&mut WckDevices {
        bus: &mut guard,
        ids: &ids,
        torque,
    });
    let mut out = Vec::new();
    for f in failed {
        let error = f.error;
        match f.device {
            SafeDevice::Servo(id) => out.extend(
                joints
                    .iter()
                    .filter(|j| j.id == id)
                    .map(|j| (j.name.clone(), error.kind(), error.to_string())),
            ),
            _ => out.extend(all(&error)),
        }
    }
    out
}

/// [`settle`] on a WHJ bus: each joint that failed, with why.
fn settle_whj(
    station: &Station,
    bus: &str,
    state: SafeState,
    joints: &[&JointConfig],
) -> Vec<Unsettled> {
    let port = match station.whj(Some(bus)) {
        Ok(p) => p,
        Err(e) => return all_failed(joints, &e),
    };
    let mut out = Vec::new();
    for j in joints {
        let done = robobus_whj::JointId::new(j.id)
            .map_err(|e| OpError::invalid("robot", &j.name, e.to_string()))
            .and_then(|id| {
                // A joint the operation connected is not connected again (a silent one
                // would cost the connect timeout, not a reply's).
                let bus = port.bus();
                Ok(if bus.cached_identity(id).is_some() {
                    bus.joint_unchecked(id)
                } else {
                    bus.joint(id)?
                })
            })
            .and_then(|joint| {
                let (state, servo) = match state {
                    SafeState::Hold => {
                        if !joint.is_enabled()? {
                            // Disabled (braked): it stays so.
                            return Ok(());
                        }
                        match joint.mode()? {
                            WorkMode::Position => (SafeState::Hold, ServoLoop::Position),
                            WorkMode::Speed => (SafeState::Hold, ServoLoop::Speed),
                            WorkMode::Current => (SafeState::Hold, ServoLoop::Current),
                            // Open loop holds nothing: disabled.
                            _ => (SafeState::Disable, ServoLoop::Position),
                        }
                    }
                    other => (other, ServoLoop::Position),
                };
                match state
                    .apply(&mut WhjDevices {
                        joints: std::slice::from_ref(&joint),
                        servo,
                    })
                    .into_iter()
                    .next()
                {
                    Some(f) => Err(f.error),
                    None => Ok(()),
                }
            });
        if let Err(e) = done {
            out.push((j.name.clone(), e.kind(), e.to_string()));
        }
    }
    out
}

/// `v` out of `range`, as the option `option` says it.
pub(super) fn out_of<T: std::fmt::Display + PartialOrd>(
    option: &str,
    v: T,
    range: &RangeInclusive<T>,
) -> OpError {
    OpError::invalid(
        option,
        v,
        format!("out of range {}..={}", range.start(), range.end()),
    )
}

/// Checks that `v` is a finite number within `range` (the error names `option`).
pub(super) fn within(option: &str, v: f64, range: &RangeInclusive<f64>) -> Result<(), OpError> {
    if v.is_finite() && range.contains(&v) {
        Ok(())
    } else {
        Err(out_of(option, v, range))
    }
}

pub(super) fn no_robot() -> OpError {
    OpError::invalid(
        "robot",
        "(none)",
        "the station has no robot file (open it with --robot FILE.toml)",
    )
}

/// Every robot operation ends with each bus of its joints in the robot file's
/// `safe_state`: finished, failed or stopped.
#[cfg(all(test, feature = "sim"))]
mod end_tests {
    #![allow(clippy::unwrap_used)]

    use robobus_sim::wck::Mode;
    use serde_json::{Value, json};

    use super::play::PlayTick;
    use crate::catalogue::{Interaction, Request, run, run_with};
    use crate::ops::{Control, ErrorKind, OpError, StopToken};
    use crate::robot::RobotConfig;
    use crate::robot::simulated::simulated_robot;
    use crate::station::Station;

    const WAVE: &str = "time_s,s0,s1,j1,j2\n0,0,0,0,0\n0.5,10,-10,5,-5\n1,0,0,0,0\n";

    fn req(v: Value) -> Request {
        serde_json::from_value(v).unwrap()
    }

    /// The simulated station with its robot file's buses given `wck` / `whj` as their
    /// `safe_state` (`None`: the defaults, passive and hold), joints 1 and 2 enabled in
    /// position mode.
    fn station(
        wck: Option<&str>,
        whj: Option<&str>,
    ) -> (
        Station,
        robobus_sim::wck::SimHandle,
        robobus_sim::whj::WhjSimHandle,
    ) {
        let (mut station, wck_sim, whj_sim) = Station::simulated_with_handles().unwrap();
        let mut text = simulated_robot();
        if let Some(s) = wck {
            text = text.replace(
                "kind = \"wck-external\"\n",
                &format!("kind = \"wck-external\"\nsafe_state = \"{s}\"\n"),
            );
        }
        if let Some(s) = whj {
            text = text.replace(
                "kind = \"whj-external\"\n",
                &format!("kind = \"whj-external\"\nsafe_state = \"{s}\"\n"),
            );
        }
        station
            .set_robot(RobotConfig::from_toml_str(&text).unwrap())
            .unwrap();
        for r in [
            json!({"op": "whj.mode", "joints": "1-2", "mode": "position"}),
            json!({"op": "whj.enable", "joints": "1-2"}),
        ] {
            run(&station, &req(r), &mut Control::none()).unwrap();
        }
        (station, wck_sim, whj_sim)
    }

    /// WHJ joint `id`: (enabled, position mode, brake locked, |target - position| in
    /// degrees).
    fn whj_state(sim: &robobus_sim::whj::WhjSimHandle, id: u8) -> (bool, bool, bool, f64) {
        sim.with_bus(|b| {
            let s = b.joint(id).unwrap().state();
            let target = s.target_position as f64 / 10_000.0;
            (
                s.enabled,
                s.mode == 3,
                s.brake_locked,
                (target - s.position_deg).abs(),
            )
        })
    }

    fn wck_mode(sim: &robobus_sim::wck::SimHandle, id: usize) -> Mode {
        sim.with_bus(|b| b.servo(id).unwrap().mode())
    }

    /// Joints 1 and 2 enabled in position mode, holding where they are (the target within
    /// half a degree of the position: the measured angle it was given), their brakes released.
    #[track_caller]
    fn holding(whj: &robobus_sim::whj::WhjSimHandle) {
        for id in [1, 2] {
            let (enabled, position, locked, off) = whj_state(whj, id);
            assert!(enabled && position && !locked, "joint {id}");
            assert!(off < 0.5, "joint {id}: target {off}° from where it is");
        }
    }

    fn play(station: &Station) -> Value {
        let request = req(json!({"op": "robot.play", "trajectory": WAVE, "rate_hz": 50}));
        serde_json::to_value(run(station, &request, &mut Control::none()).unwrap()).unwrap()
    }

    #[test]
    fn a_played_trajectory_ends_as_the_robot_file_says_and_plays_again() {
        let (station, wck, whj) = station(None, None);
        let v = play(&station);
        assert_eq!(v["failed"], Value::Null, "{v:#}");
        assert_eq!(
            v["summary"]["safe_state"],
            json!([
                {"bus": "sim-wck", "safe_state": "passive", "failed": []},
                {"bus": "sim-whj", "safe_state": "hold", "failed": []},
            ]),
            "{v:#}"
        );
        holding(&whj);
        assert_eq!(
            (wck_mode(&wck, 0), wck_mode(&wck, 1)),
            (Mode::Passive, Mode::Passive)
        );
        // The joints are ready for the next run.
        let again = play(&station);
        assert_eq!(again["failed"], Value::Null, "{again:#}");
        holding(&whj);
    }

    #[test]
    fn a_file_that_says_disable_and_break_is_followed() {
        let (station, wck, whj) = station(Some("break"), Some("disable"));
        let v = play(&station);
        assert_eq!(v["failed"], Value::Null, "{v:#}");
        for id in [1, 2] {
            let (enabled, _, locked, _) = whj_state(&whj, id);
            assert!(!enabled && locked, "joint {id}");
        }
        assert_eq!(
            (wck_mode(&wck, 0), wck_mode(&wck, 1)),
            (Mode::Break, Mode::Break)
        );
        // A joint left disabled refuses the next run before anything moves.
        let request = req(json!({"op": "robot.play", "trajectory": WAVE}));
        let e = run(&station, &request, &mut Control::none()).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Refused, "{e}");
        assert!(e.to_string().contains("j1: joint 1 is disabled"), "{e}");
    }

    /// Stops the run after `after` ticks (`stop`), or fails it there.
    struct EndAt {
        after: usize,
        ticks: usize,
        stop: Option<StopToken>,
    }

    impl Interaction for EndAt {
        fn play_tick(&mut self, _: &PlayTick<'_>) -> Result<(), OpError> {
            self.ticks += 1;
            if self.ticks < self.after {
                return Ok(());
            }
            match &self.stop {
                Some(s) => {
                    s.stop();
                    Ok(())
                }
                None => Err(OpError::Device("the recording failed".into())),
            }
        }
    }

    #[test]
    fn a_stopped_or_failed_play_ends_as_the_robot_file_says() {
        for stop in [Some(StopToken::new()), None] {
            let (station, wck, whj) = station(None, None);
            let request = req(json!({"op": "robot.play", "trajectory": WAVE, "rate_hz": 50}));
            let token = stop.clone().unwrap_or_default();
            let mut end = EndAt {
                after: 20,
                ticks: 0,
                stop,
            };
            let result = run_with(&station, &request, &mut Control::new(&token), &mut end);
            match &end.stop {
                Some(_) => {
                    let v = serde_json::to_value(result.unwrap()).unwrap();
                    assert_eq!(v["summary"]["interrupted"], true, "{v:#}");
                }
                None => assert!(result.unwrap_err().to_string().contains("recording failed")),
            }
            // Stopped mid-way (10 of 50 ticks to the second point): holding there.
            holding(&whj);
            let at = whj.with_bus(|b| b.joint(1).unwrap().state().position_deg);
            assert!(at > 1.0, "joint 1 at {at}°");
            assert_eq!(
                (wck_mode(&wck, 0), wck_mode(&wck, 1)),
                (Mode::Passive, Mode::Passive)
            );
        }
    }

    /// Makes WHJ joint 2 silent at the 20th tick.
    struct Silence(robobus_sim::whj::WhjSimHandle, usize);

    impl Interaction for Silence {
        fn play_tick(&mut self, _: &PlayTick<'_>) -> Result<(), OpError> {
            self.1 += 1;
            if self.1 == 20 {
                self.0.with_bus(|b| {
                    let now = b.now();
                    b.joint_mut(2).unwrap().fall_silent(now);
                });
            }
            Ok(())
        }
    }

    #[test]
    fn a_joint_silent_at_the_end_fails_its_row_and_the_others_still_hold() {
        let (station, wck, whj) = station(None, None);
        let request = req(json!({"op": "robot.play", "trajectory": WAVE, "rate_hz": 50}));
        let mut silence = Silence(whj.clone(), 0);
        let report = run_with(&station, &request, &mut Control::none(), &mut silence).unwrap();
        let v = serde_json::to_value(report).unwrap();
        assert_eq!(v["failed"], "no-device", "{v:#}");
        let j2 = v["results"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["id"] == "j2")
            .unwrap();
        assert!(
            j2["error"]
                .as_str()
                .unwrap()
                .contains("j2: did not reach its safe state (hold)"),
            "{j2}"
        );
        let failed = &v["summary"]["safe_state"][1]["failed"];
        assert_eq!(failed.as_array().unwrap().len(), 1, "{v:#}");
        assert!(failed[0].as_str().unwrap().starts_with("j2: "), "{v:#}");
        // The others reached theirs.
        let (enabled, position, locked, off) = whj_state(&whj, 1);
        assert!(enabled && position && !locked && off < 0.5);
        assert_eq!(
            (wck_mode(&wck, 0), wck_mode(&wck, 1)),
            (Mode::Passive, Mode::Passive)
        );
    }

    #[test]
    fn teleop_and_calibrate_end_as_the_robot_file_says() {
        let (station, wck, whj) = station(None, None);
        let teleop = req(json!({
            "op": "robot.teleop",
            "map": [{"leader": "s0", "follower": "j1"}, {"leader": "s2", "follower": "s1"}],
            "seconds": 0.2,
        }));
        let v =
            serde_json::to_value(run(&station, &teleop, &mut Control::none()).unwrap()).unwrap();
        assert_eq!(v["failed"], Value::Null, "{v:#}");
        assert_eq!(
            v["summary"]["safe_state"],
            json!([
                {"bus": "sim-wck", "safe_state": "passive", "failed": []},
                {"bus": "sim-whj", "safe_state": "hold", "failed": []},
            ]),
            "{v:#}"
        );
        holding(&whj);
        assert_eq!(wck_mode(&wck, 1), Mode::Passive);
        // Calibrate moves nothing and leaves the WHJ joints as they were: holding.
        let calibrate = req(json!({"op": "robot.calibrate", "seconds": 0.2}));
        run(&station, &calibrate, &mut Control::none()).unwrap();
        holding(&whj);
        // The next play runs.
        let again = play(&station);
        assert_eq!(again["failed"], Value::Null, "{again:#}");
    }

    #[test]
    fn a_disabled_silent_or_out_of_limits_follower_refuses_teleop_before_anything_is_sent() {
        let (station, wck, whj) = station(None, None);
        run(
            &station,
            &req(json!({"op": "whj.disable", "joints": "2"})),
            &mut Control::none(),
        )
        .unwrap();
        wck.with_bus(|b| b.servo_mut(6).unwrap().power_off(std::time::Duration::ZERO));
        let centre = 127.0 * robobus_sim::wck::mechanics::DEG_PER_STEP8;
        wck.with_bus(|b| b.servo_mut(4).unwrap().set_angle(centre + 120.0));
        for (follower, says) in [
            (
                "j2",
                "j2: joint 2 is disabled; run `robobus whj enable 2` first",
            ),
            ("s6", "s6 did not answer"),
            ("s4", "s4 is at"),
        ] {
            let teleop = req(json!({
                "op": "robot.teleop",
                "map": [{"leader": "s0", "follower": "s1"}, {"leader": "s2", "follower": follower}],
                "seconds": 0.2,
            }));
            let before = wck.with_bus(|b| b.servo(1).unwrap().position());
            let e = run(&station, &teleop, &mut Control::none()).unwrap_err();
            assert_eq!(e.kind(), ErrorKind::Refused, "{follower}: {e}");
            assert!(e.to_string().contains(says), "{follower}: {e}");
            assert!(e.to_string().contains("nothing was moved"), "{e}");
            assert_eq!(wck.with_bus(|b| b.servo(1).unwrap().position()), before);
            let (enabled, ..) = whj_state(&whj, 2);
            assert!(!enabled);
        }
    }
}

/// A report's row of device `name` (its `id`), in the tests of these operations.
#[cfg(all(test, feature = "sim"))]
#[allow(clippy::unwrap_used)]
fn row<'a>(report: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    report["results"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["id"] == name)
        .unwrap()
}
