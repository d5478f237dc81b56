//! `robot.play`: a trajectory of named joints (the CSV of [`crate::robot::trajectory`])
//! played on the station's robot file, across its buses and both families.
//!
//! The whole trajectory is checked against the file before anything is sent (joint names,
//! soft limits, `max_velocity`), and every joint it names is read
//! (`ready_at`): one that does not answer, stands outside its
//! soft limits, or is a WHJ joint not enabled in position mode refuses the run. The joints then go from
//! where they are to the first point on a half-cosine from rest to rest, each within its
//! `max_velocity` and `max_acceleration` (the lead-in, as long as the slowest needs), and
//! follow the trajectory, linearly between its points.
//! Every tick (`rate_hz`) each bus gets its joints' targets at the same instant, each bus
//! from its own thread: a position command per wCK servo (its reply is the servo's
//! position), a position servo frame per WHJ joint (its feedback the joint's position; the
//! joint must be enabled in position mode). The report gives per joint the tracking error
//! (the distance from where a joint reported itself to the target of the tick before) and
//! its failures, and for the run the skew between the buses' sends in a tick and how late
//! the sends were. Finished, failed or stopped, the run ends with each bus of its joints
//! in the robot file's `safe_state` (`settle`).

mod drive;
mod preflight;

use std::time::{Duration, Instant};

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use robobus_wck::BaudRate;

use super::ROBOT;
use crate::actuator::{JointMap, WckScale};
use crate::catalogue::effect::{Effect, Moved};
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::{Family, Plan};
use crate::catalogue::whj::PreflightArg;
use crate::motion::Tracking;
use crate::ops::protect::{self, Action, Fault, Monitor, Reading};
use crate::ops::whj::ServoLoop;
use crate::ops::{Control, DeviceResult, Failure, OpError, Outcome, Progress};
use crate::robot::RobotConfig;
use crate::robot::trajectory::Trajectory;
use crate::station::Station;
use crate::station::WhjPort;
use crate::station::clock::BusClock;
use crate::station::handles::{WckGroup, WhjGroup};
use crate::whj::Percentiles;

/// `robot.play` (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Play {
    /// The trajectory file's text: `time_s`, then a column per joint of the robot file
    /// (degrees in its joint frame); a row per point.
    pub trajectory: String,
    /// Ticks a second (1..=500; default 50).
    #[serde(default = "default_rate")]
    pub rate_hz: f64,
    /// The wCK servos' torque level (0 strongest ..= 4 weakest; default 2).
    #[serde(default = "default_torque")]
    pub torque: u8,
    /// Run a play of positions first on WHJ simulators seeded with its WHJ joints
    /// (`true`), never (`false`), or by default: when it lasts at most 60 s.
    #[serde(default, skip_serializing_if = "PreflightArg::is_default")]
    pub preflight: PreflightArg,
}

const fn default_rate() -> f64 {
    50.0
}

const fn default_torque() -> u8 {
    2
}

/// Range of `rate_hz`.
pub const PLAY_RATE_HZ: std::ops::RangeInclusive<f64> = 1.0..=500.0;

impl Play {
    /// Checks the values and parses the trajectory (named as the command line's options).
    pub fn check(&self) -> Result<Trajectory, OpError> {
        if !(self.rate_hz.is_finite() && PLAY_RATE_HZ.contains(&self.rate_hz)) {
            return Err(OpError::invalid(
                "--rate-hz",
                self.rate_hz,
                "out of range 1..=500",
            ));
        }
        if self.torque > 4 {
            return Err(OpError::invalid(
                "--torque",
                self.torque,
                "out of range 0..=4 (0 strongest)",
            ));
        }
        Trajectory::parse(&self.trajectory)
            .map_err(|e| OpError::invalid("trajectory", "(file)", e.to_string()))
    }

    /// What the trajectory's header names: positions (plain joint names), velocities
    /// (`NAME_deg_s`) or efforts (`NAME_nm`).
    pub fn interface(&self) -> Result<crate::robot::Interface, OpError> {
        drive::header(&self.trajectory).map(|(i, _)| i)
    }

    /// Checks the trajectory against the robot file `config` before anything opens (its
    /// joints, and each value against their limits: angles and speeds of a position
    /// play, the interface and its `max_velocity` / `max_effort` of a velocity or effort
    /// play); the parsed trajectory, its joints' plain names.
    pub fn check_against(&self, config: &RobotConfig) -> Result<Trajectory, OpError> {
        let (interface, text) = drive::header(&self.trajectory)?;
        if interface == crate::robot::Interface::Position {
            let t = self.check()?;
            t.check(config)
                .map_err(|e| OpError::invalid("trajectory", "(file)", e.to_string()))?;
            return Ok(t);
        }
        Play::check(self)?;
        drive::check(&text, interface, config).map(|(t, _)| t)
    }

    /// What a run sends, for the plan.
    pub fn note(&self) -> Result<String, OpError> {
        let (interface, plain) = drive::header(&self.trajectory)?;
        if interface != crate::robot::Interface::Position {
            self.check()?;
            let t = Trajectory::parse(&plain)
                .map_err(|e| OpError::invalid("trajectory", "(file)", e.to_string()))?;
            return Ok(format!(
                "reads {joints} and refuses if one is silent or outside its soft limits; \
                 switches them at rest to {interface} (WHJ: speed / current mode at zero; \
                 wCK: wheel mode at level 0), then plays {n} points over {d} s, {r} ticks a \
                 second: a {what} per joint, ramped; at the end a zero target, WHJ joints \
                 back in position mode{END}",
                joints = t.joints().join(", "),
                n = t.len(),
                d = t.duration_s(),
                r = self.rate_hz,
                what = if interface == crate::robot::Interface::Velocity {
                    "speed servo frame (WHJ) or wheel command (wCK)"
                } else {
                    "current servo frame"
                },
                END = super::END_NOTE,
            ));
        }
        let t = self.check()?;
        Ok(format!(
            "reads {joints} (a status read per wCK servo; a status query and a speed read per \
             WHJ joint) and refuses if one is silent or outside its soft limits; {flight}moves \
             them to the first point no faster than each one's max_velocity, then plays {n} \
             points over {d} s, {r} ticks a second: each bus at the same instant, a position \
             command per wCK servo (torque {torque}) and a position servo frame per WHJ joint \
             (enabled in position mode){END}",
            joints = t.joints().join(", "),
            flight = preflight::note(self.preflight.asked(), t.duration_s()),
            n = t.len(),
            d = t.duration_s(),
            r = self.rate_hz,
            torque = self.torque,
            END = super::END_NOTE,
        ))
    }
}

impl Operation for Play {
    const OP: &'static str = "robot.play";
    const FAMILY: Family = Family::Robot;
    const DOC: OpDoc = OpDoc {
        args: "`trajectory` (a trajectory file's text: `time_s`, then a column per joint of \
               the robot file, degrees in its joint frame; columns `NAME_deg_s` or `NAME_nm` \
               play velocities, deg/s, or efforts, N·m, on joints with that interface; see \
               `docs/hardware.md`), \
               `rate_hz`=50 (1..=500), `torque`=2 (wCK servos, 0..=4), `preflight` (a play \
               of positions; default: on up to 60 s)",
        report: "one row per joint by name: `commands`, `failed`, `limited` (sent short of the \
                 trajectory's target: a WHJ joint that lagged), `start_deg`, `target_deg` (the \
                 last), `position_deg` (reported at the last command), `tracking_max_deg`, \
                 `tracking_rms_deg` (from where the joint reported itself to the target of the \
                 tick before), `sent_deg_s` / `sent_nm` (a velocity / effort play: the last \
                 value sent); `summary`: `lead_in_s`, `duration_s`, `ticks`, `overruns`, \
                 `buses`, `skew_ms` (per tick, the first send of the first bus to that of the \
                 last) and `late_ms` (`p50`, `p99`, `max`), `interrupted`, `safe_state` (per \
                 bus: `bus`, the file's `safe_state` it was left in, `failed`: the joints that \
                 did not get there). Refused before anything moves when the trajectory does \
                 not fit the robot file or a joint is silent, outside its limits, or a WHJ \
                 joint not enabled in position mode. Finished, failed or stopped, it ends with \
                 each bus of its joints in the robot file's `safe_state` (as `robot.teleop`, \
                 `robot.calibrate` and `robot.teach` do). `summary.protection`: the host's \
                 protection events (`joint`, `check`: stall / collision / thermal, \
                 `quantity`, `value`, `limit`, `at_s`, `action`: warn / derate / stop); a \
                 stop ends the run in the safe state and fails its joint's row. \
                 `summary.preflight` (a play of positions pre-flown on WHJ simulators seeded \
                 with its WHJ joints): `ticks`, `simulated_s`, `joints` (`joint`, `bus`, \
                 `seed`), `not_flown` (its wCK servos); refused before the first tick when a \
                 simulated joint is held back, latches error bits, fails or is derated",
        confirm: "motion",
    };
    type Row = DeviceResult<String, Played>;
    type Summary = PlaySummary;

    fn effect(&self) -> Effect {
        Effect::Motion
    }

    fn moved(&self) -> Result<Option<Moved>, OpError> {
        Play::check(self).map(|_| None)
    }

    fn check(&self) -> Result<Confirm, OpError> {
        Play::check(self).map(|_| Confirm::NONE)
    }

    fn plan(&self, _baud: BaudRate) -> Result<Plan, OpError> {
        Ok(Plan::notes_only(
            Self::OP,
            Family::Robot,
            vec![self.note()?],
        ))
    }

    /// Each tick goes to the front end's [`Interaction::play_tick`](crate::catalogue::Interaction::play_tick).
    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, PlaySummary>, OpError> {
        let interaction = &mut *cx.interaction;
        let p = if self.interface()? == crate::robot::Interface::Position {
            run_play(cx.station, self, cx.control, &mut |t| {
                interaction.play_tick(t)
            })?
        } else {
            drive::run(cx.station, self, cx.control)?
        };
        Ok(Report::devices_with(Self::OP, ROBOT, p.joints).summary(p.summary))
    }
}

/// A joint's run (its row of the report, by name).
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct Played {
    /// Commands sent.
    pub commands: u64,
    /// Commands that failed (no reply, refused).
    pub failed: u64,
    /// Commands sent short of the trajectory's target: a WHJ joint that lagged behind by
    /// more than its step allows got a target within it.
    pub limited: u64,
    /// Where it was before the run, degrees.
    pub start_deg: f64,
    /// The last target, degrees.
    pub target_deg: f64,
    /// Where it reported itself at its last command, degrees.
    pub position_deg: Option<f64>,
    /// The largest distance from where it reported itself to the target of the tick
    /// before, degrees.
    pub tracking_max_deg: f64,
    /// The root mean square of that distance, degrees.
    pub tracking_rms_deg: f64,
    /// A velocity play's last speed sent, deg/s (at the device's resolution; a wCK
    /// servo's: its wheel level's speed); absent otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sent_deg_s: Option<f64>,
    /// An effort play's last effort sent, N·m (the current sent times the torque
    /// constant); absent otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sent_nm: Option<f64>,
    #[serde(skip)]
    tracking: Tracking,
    #[serde(skip)]
    last_error: Option<Failure>,
    /// The host's protection stopped the run on this joint.
    #[serde(skip)]
    protection: Option<Failure>,
}

/// How a run's times spread, ms.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, JsonSchema)]
pub struct Spread {
    /// Median.
    pub p50: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest.
    pub max: f64,
}

impl Spread {
    /// Of `samples` (all zero without any).
    pub(super) fn of(samples: &[Duration]) -> Self {
        let p = Percentiles::of(samples);
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        Self {
            p50: ms(p.p50),
            p99: ms(p.p99),
            max: ms(p.max),
        }
    }
}

/// The whole run.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct PlaySummary {
    /// The lead-in to the first point, s.
    pub lead_in_s: f64,
    /// The trajectory's own length, s.
    pub duration_s: f64,
    /// Ticks run.
    pub ticks: u64,
    /// Ticks skipped because one ran longer than the period.
    pub overruns: u64,
    /// The buses, in the order of the sends.
    pub buses: Vec<String>,
    /// Per tick, the time between the first and the last bus's first send.
    pub skew_ms: Spread,
    /// Per tick, how long after the tick the last bus's first send went.
    pub late_ms: Spread,
    /// The stop token ended it early.
    pub interrupted: bool,
    /// How it left each bus: in the robot file's `safe_state` (finished, failed or
    /// stopped).
    pub safe_state: Vec<super::BusEnd>,
    /// The host's protection events, in order: warnings, deratings and the stop (a stop
    /// ends the run in the safe state and fails its joint's row).
    pub protection: Vec<Fault>,
    /// The pre-flight on the simulator that passed before the play (left out when none
    /// ran).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub preflight: Option<PlayPreflight>,
}

pub use preflight::{FlownJoint, PlayPreflight};

/// What a `robot.play` run did.
struct PlayedRun {
    joints: Vec<DeviceResult<String, Played>>,
    summary: PlaySummary,
}

/// What a joint reported in a tick: its position (joint degrees), and where read, its
/// current and temperature.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Sensed {
    position: f64,
    current_a: Option<f64>,
    temperature_c: Option<f64>,
}

impl Sensed {
    const fn at(position: f64) -> Self {
        Self {
            position,
            current_a: None,
            temperature_c: None,
        }
    }
}

/// A joint's outcome in a tick, by its column: what it reported, or why not.
type Outcomes = Vec<(usize, Result<Sensed, Failure>)>;

/// How often each WHJ joint's temperature is read during a run (a status query), s.
pub(super) const TEMPERATURE_EVERY_S: f64 = 0.25;

/// The joints of one bus and their handle, each by its column with how its angles turn
/// into its device's units.
enum Group {
    Wck(WckGroup, Vec<(usize, WckScale)>),
    Whj(WhjGroup, WhjPort, Vec<(usize, JointMap)>),
}

impl Group {
    fn columns(&self) -> Vec<usize> {
        match self {
            Self::Wck(_, c) => c.iter().map(|x| x.0).collect(),
            Self::Whj(_, _, c) => c.iter().map(|x| x.0).collect(),
        }
    }

    /// Sends `targets` (joint degrees, by column) to the group's devices: each column's
    /// outcome, what it reported (with `temperature`, a WHJ joint's temperature read
    /// after its command).
    fn send(&self, targets: &[f64], torque: u8, temperature: bool) -> Outcomes {
        let rad = |c: usize| targets.get(c).copied().unwrap_or(0.0).to_radians();
        let results: Result<Outcomes, OpError> = match self {
            Self::Wck(h, cols) => {
                let steps: Vec<f64> = cols
                    .iter()
                    .map(|&(c, s)| s.to_position(rad(c)).map_or(-1.0, |p| f64::from(p.get())))
                    .collect();
                h.move_to(&steps, torque).map(|r| {
                    cols.iter()
                        .zip(r)
                        .map(|(&(c, s), d)| {
                            let at = match d.outcome {
                                Outcome::Ok(reading) => {
                                    robobus_wck::Position::new(reading.position)
                                        .map(|p| Sensed::at(s.to_rad(p).to_degrees()))
                                        .map_err(|e| Failure::of(crate::ErrorKind::Device, &e))
                                }
                                Outcome::Failed(f) => Err(f),
                            };
                            (c, at)
                        })
                        .collect()
                })
            }
            Self::Whj(h, port, cols) => {
                let degrees: Vec<f64> = cols
                    .iter()
                    .map(|&(c, m)| m.to_device(rad(c)).to_degrees())
                    .collect();
                h.command(ServoLoop::Position, &degrees)
                    .map(|r| {
                        cols.iter()
                            .zip(r)
                            .map(|(&(c, m), d)| {
                                let at = match d.outcome {
                                    Outcome::Ok(fb) => Ok(Sensed {
                                    position: m.to_joint(fb.position_deg.to_radians()).to_degrees(),
                                    #[allow(clippy::cast_precision_loss)] // mA of a joint
                                    current_a: Some(fb.current_ma as f64 / 1e3),
                                    temperature_c: None,
                                }),
                                    Outcome::Failed(f) => Err(f),
                                };
                                (c, at)
                            })
                            .collect::<Outcomes>()
                    })
                    .map(|mut out| {
                        if temperature {
                            let bus = port.bus();
                            for ((_, o), id) in out.iter_mut().zip(h.ids()) {
                                let Ok(sensed) = o else { continue };
                                let Ok(joint) = robobus_whj::JointId::new(id) else {
                                    continue;
                                };
                                match bus.joint_unchecked(joint).status() {
                                    Ok(st) => {
                                        sensed.temperature_c =
                                            Some(f64::from(st.temperature.celsius()));
                                    }
                                    Err(e) => *o = Err(Failure::from(&OpError::from(e))),
                                }
                            }
                        }
                        out
                    })
            }
        };
        results.unwrap_or_else(|e| {
            let f = Failure::from(&e);
            self.columns()
                .into_iter()
                .map(|c| (c, Err(f.clone())))
                .collect()
        })
    }
}

/// The trajectory's joints grouped by bus, in the file's bus order, with the clock of
/// those buses.
fn groups(
    station: &Station,
    config: &RobotConfig,
    traj: &Trajectory,
    index: &[usize],
) -> Result<(Vec<Group>, BusClock), OpError> {
    let mut groups = Vec::new();
    for name in config.buses.keys() {
        let cols: Vec<(usize, &crate::robot::JointConfig)> = index
            .iter()
            .enumerate()
            .filter_map(|(c, &i)| config.joints.get(i).map(|j| (c, j)))
            .filter(|(_, j)| &j.bus == name)
            .collect();
        let Some((_, first)) = cols.first() else {
            continue;
        };
        let ids: Vec<u8> = cols.iter().map(|(_, j)| j.id).collect();
        groups.push(if config.is_wck(first) {
            Group::Wck(
                WckGroup::new(station, Some(name), &ids)?,
                cols.iter().map(|(c, j)| (*c, j.wck_scale())).collect(),
            )
        } else {
            Group::Whj(
                WhjGroup::new(station, Some(name), &ids)?,
                station.whj(Some(name))?,
                cols.iter().map(|(c, j)| (*c, j.map())).collect(),
            )
        });
    }
    let clock = BusClock::of(station, &super::only(config, traj.joints()))?;
    Ok((groups, clock))
}

/// Per column, how far a WHJ joint's target may be sent from where it last reported
/// itself: 0.8 of its bus's step limit (`None` for a wCK servo).
fn steps_of(groups: &[Group], columns: usize) -> Result<Vec<Option<f64>>, OpError> {
    let mut steps = vec![None; columns];
    for g in groups {
        if let Group::Whj(h, _, cols) = g {
            let limit = h.step_limit_deg()?;
            for &(c, _) in cols {
                if let Some(s) = steps.get_mut(c) {
                    *s = Some(0.8 * limit);
                }
            }
        }
    }
    Ok(steps)
}

/// Refuses a trajectory whose WHJ joints would step more than half their bus's step
/// limit in one tick (a joint lagging by a tick would then be refused its next frame):
/// the fastest segment, and the lead-in, at `rate_hz`.
fn check_steps(
    groups: &[Group],
    traj: &Trajectory,
    from: &[f64],
    lead_in: f64,
    rate_hz: f64,
) -> Result<(), OpError> {
    for g in groups {
        let Group::Whj(h, _, cols) = g else { continue };
        let limit = h.step_limit_deg()?;
        for &(c, _) in cols {
            let lead = match (traj.first().get(c), from.get(c)) {
                (Some(a), Some(b)) if lead_in > 0.0 => LEAD_IN_PEAK * (a - b).abs() / lead_in,
                _ => 0.0,
            };
            let speed = traj.max_speed(c).max(lead);
            let step = speed / rate_hz;
            if step > limit / 2.0 {
                let name = traj.joints().get(c).map_or("?", String::as_str);
                return Err(OpError::invalid(
                    "--rate-hz",
                    rate_hz,
                    format!(
                        "{name} moves up to {speed:.1}°/s: at {rate_hz} Hz a tick steps \
                         {step:.2}°, more than half its bus's {limit}° step limit; play at \
                         --rate-hz {} or more",
                        (2.0 * speed / limit).ceil()
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// A protection stop among `faults` fails its joint's row (`rows` and `models` by column
/// of `joints`), naming what it measured; returns the joints to leave torque off, where
/// that is safe (holding would keep them pushing or heating).
fn fail_protection_stop(
    faults: &[Fault],
    joints: &[String],
    rows: &mut [Played],
    models: &[Option<robobus_whj::units::Model>],
) -> Vec<String> {
    let mut torque_off = Vec::new();
    if let Some(stop) = faults.iter().find(|f| f.action == Action::Stop)
        && let Some(c) = joints.iter().position(|n| *n == stop.joint)
        && let Some(row) = rows.get_mut(c)
    {
        let off = models
            .get(c)
            .is_some_and(|m| m.is_some() && protect::torque_off_is_safe(*m));
        let end = if off {
            torque_off.push(stop.joint.clone());
            "; its drive disabled (its brake holds it: holding would keep it pushing or heating)"
        } else {
            ""
        };
        row.protection = Some(Failure::of(
            crate::ErrorKind::Device,
            &format!("{stop}{end}"),
        ));
    }
    torque_off
}

/// Per column, the model a WHJ joint identified as (`None`: a wCK servo).
fn models_of(index: &[usize], groups: &[Group]) -> Vec<Option<robobus_whj::units::Model>> {
    (0..index.len())
        .map(|c| {
            groups.iter().find_map(|g| match g {
                Group::Whj(h, port, cols) => {
                    let k = cols.iter().position(|x| x.0 == c)?;
                    let id = robobus_whj::JointId::new(*h.ids().get(k)?).ok()?;
                    port.bus()
                        .joint_unchecked(id)
                        .identity()
                        .ok()
                        .map(|i| i.model)
                }
                Group::Wck(..) => None,
            })
        })
        .collect()
}

/// `robot.play` on the station's robot file.
fn run_play(
    station: &Station,
    r: &Play,
    control: &mut Control<'_>,
    on_tick: &mut dyn FnMut(&PlayTick<'_>) -> Result<(), OpError>,
) -> Result<PlayedRun, OpError> {
    let traj = r.check()?;
    let config = station.robot().cloned().ok_or_else(super::no_robot)?;
    let index = traj
        .check(&config)
        .map_err(|e| OpError::invalid("trajectory", "(file)", e.to_string()))?;
    let (groups, clock) = groups(station, &config, &traj, &index)?;
    let from = super::ready_at(station, &config, traj.joints(), "a trajectory")?;
    // The lead-in: a half-cosine from rest to rest, as long as the slowest joint needs to
    // stay within its max_velocity and max_acceleration on it.
    let lead_in = traj
        .first()
        .iter()
        .zip(&from)
        .zip(&index)
        .map(|((a, b), &i)| {
            let j = &config.joints[i];
            lead_in_s(
                (a - b).abs(),
                j.max_velocity.to_degrees(),
                j.max_acceleration.to_degrees(),
            )
        })
        .fold(0.0, f64::max);
    check_steps(&groups, &traj, &from, lead_in, r.rate_hz)?;
    // The same play first on WHJ simulators seeded with its WHJ joints (refused before
    // the first tick when one of them would not follow it).
    let flight = preflight::fly(
        r,
        &config,
        (&traj, &index),
        &groups,
        (&from, lead_in),
        control,
    )?;
    let mut rows: Vec<Played> = from.iter().map(|&s| Played::new(s)).collect();
    let models = models_of(&index, &groups);
    let mut player = Player::new(
        r,
        &config,
        (&traj, &index),
        (&groups, &clock),
        (&from, lead_in),
        &models,
    )?;
    let run = player.run(&mut rows, control, on_tick);
    let faults = std::mem::take(&mut player.faults);
    let torque_off = fail_protection_stop(&faults, traj.joints(), &mut rows, &models);
    // Finished, stopped or failed: each bus as the robot file says.
    // Played to its end, nothing failed: held there where the station says so.
    let finished = run.as_ref().is_ok_and(|t| !t.interrupted)
        && torque_off.is_empty()
        && !faults.iter().any(|f| f.action == Action::Stop)
        && rows.iter().all(|r| r.failed == 0);
    let settled = if finished {
        super::settle_at_end(station, &config, traj.joints())
    } else {
        super::settle_with(station, &config, traj.joints(), &torque_off)
    };
    let timing = run.inspect_err(|_| settled.log())?;
    let names = traj.joints();
    Ok(PlayedRun {
        joints: settled.fail_rows(
            names
                .iter()
                .zip(rows)
                .map(|(n, row)| row.result(n))
                .collect(),
        ),
        summary: PlaySummary {
            lead_in_s: lead_in,
            duration_s: traj.duration_s(),
            ticks: timing.ticks,
            overruns: timing.overruns,
            buses: clock.buses().map(|b| b.name().to_owned()).collect(),
            skew_ms: Spread::of(&timing.skew),
            late_ms: Spread::of(&timing.late),
            interrupted: timing.interrupted,
            safe_state: settled.buses,
            protection: faults,
            preflight: flight,
        },
    })
}

pub use crate::catalogue::operation::PlayTick;

/// What the tick loop measured.
#[derive(Debug, Default)]
struct Timing {
    ticks: u64,
    overruns: u64,
    skew: Vec<Duration>,
    late: Vec<Duration>,
    interrupted: bool,
}

/// The most ticks whose skew and lateness are kept (an hour at 500 Hz would be 1.8 M).
pub(super) const MAX_TIMED_TICKS: usize = 100_000;

struct Player<'a> {
    traj: &'a Trajectory,
    from: &'a [f64],
    lead_in: f64,
    period: Duration,
    groups: &'a [Group],
    clock: &'a BusClock,
    torque: u8,
    /// Per column, how far a WHJ joint's target may be from where it last reported
    /// itself (`None`: a wCK servo, which takes any target in its range).
    steps: Vec<Option<f64>>,
    /// Per column, the joint's `max_velocity`, degrees a second (a derated joint keeps
    /// its share of it).
    max_speed_deg: Vec<f64>,
    /// The host's protection of the joints, by column.
    monitor: Monitor,
    /// Its events so far.
    faults: Vec<Fault>,
    /// The first target sent short of the trajectory's (what the pre-flight refuses).
    held_back: Option<HeldBack>,
}

/// A target sent short of the trajectory's: the tick, its time, the column, what was
/// sent and what the trajectory asked, degrees.
#[derive(Debug, Clone, Copy, PartialEq)]
struct HeldBack {
    tick: u64,
    t_s: f64,
    column: usize,
    sent: f64,
    target: f64,
}

impl From<(u64, f64, usize, f64, f64)> for HeldBack {
    fn from((tick, t_s, column, sent, target): (u64, f64, usize, f64, f64)) -> Self {
        Self {
            tick,
            t_s,
            column,
            sent,
            target,
        }
    }
}

impl<'a> Player<'a> {
    /// The player of `r` for the trajectory `traj` (its columns the robot file's
    /// joints `index`) on `groups` paced by `clock`, from the joints' positions `from`
    /// after the lead-in `lead_in`; `models` the WHJ joints' (by column).
    fn new(
        r: &Play,
        config: &RobotConfig,
        (traj, index): (&'a Trajectory, &[usize]),
        (groups, clock): (&'a [Group], &'a BusClock),
        (from, lead_in): (&'a [f64], f64),
        models: &[Option<robobus_whj::units::Model>],
    ) -> Result<Self, OpError> {
        let monitor = Monitor::new(
            clock.now(),
            index
                .iter()
                .zip(models)
                .map(|(&i, &m)| {
                    let j = &config.joints[i];
                    (j.name.clone(), config.protection_of(j, m))
                })
                .collect(),
        );
        Ok(Self {
            traj,
            from,
            lead_in,
            period: Duration::from_secs_f64(1.0 / r.rate_hz),
            groups,
            clock,
            torque: r.torque,
            steps: steps_of(groups, traj.joints().len())?,
            max_speed_deg: index
                .iter()
                .map(|&i| config.joints[i].max_velocity.to_degrees())
                .collect(),
            monitor,
            faults: Vec::new(),
            held_back: None,
        })
    }
}

/// The lead-in's peak speed over its mean: a half-cosine's, pi/2.
const LEAD_IN_PEAK: f64 = std::f64::consts::FRAC_PI_2;

/// How long a half-cosine lead-in over `distance` degrees takes to peak at no more than
/// `max_speed` deg/s and `max_accel` deg/s²: its peak speed is pi/2 · d / T, its peak
/// acceleration pi²/2 · d / T².
fn lead_in_s(distance: f64, max_speed: f64, max_accel: f64) -> f64 {
    let by_speed = LEAD_IN_PEAK * distance / max_speed;
    let by_accel = std::f64::consts::PI * (distance / (2.0 * max_accel)).sqrt();
    by_speed.max(by_accel)
}

impl Player<'_> {
    /// The targets at `t_s` since the start (joint degrees, by column).
    fn targets(&self, t_s: f64) -> Vec<f64> {
        if t_s < self.lead_in {
            // From rest to rest: a joint that must accelerate is not asked to jump to its
            // speed (it would lag, and its targets would be held back).
            let f = (1.0 - (std::f64::consts::PI * t_s / self.lead_in).cos()) / 2.0;
            self.from
                .iter()
                .zip(self.traj.first())
                .map(|(a, b)| a + (b - a) * f)
                .collect()
        } else {
            self.traj.at(t_s - self.lead_in)
        }
    }

    fn run(
        &mut self,
        rows: &mut [Played],
        control: &mut Control<'_>,
        on_tick: &mut dyn FnMut(&PlayTick<'_>) -> Result<(), OpError>,
    ) -> Result<Timing, OpError> {
        let total = self.lead_in + self.traj.duration_s();
        let clock = self.clock;
        let start = clock.now();
        let mut timing = Timing::default();
        let mut before: Option<Vec<f64>> = None;
        let mut last_at: Vec<Option<f64>> = self.from.iter().map(|&f| Some(f)).collect();
        let mut last_sent: Vec<f64> = self.from.to_vec();
        let mut next_temperature = 0.0;
        let period_s = self.period.as_secs_f64();
        let mut k: u64 = 0;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // ≤ 3600 s × 500 Hz
        let last = (total / self.period.as_secs_f64()).ceil() as u64;
        while k <= last {
            let due = start + self.period * u32::try_from(k).unwrap_or(u32::MAX);
            if !control.sleep_with(due, |until| {
                if let Some(t) = until {
                    clock.sleep_until(t);
                }
                clock.now()
            }) {
                timing.interrupted = true;
                break;
            }
            let t_s = (due - start).as_secs_f64().min(total);
            let targets = self.targets(t_s);
            // A WHJ joint lagging behind is sent no further than its step allows; a
            // derated one no faster than its share of its max_velocity.
            let sent: Vec<f64> = targets
                .iter()
                .zip(&self.steps)
                .zip(&last_at)
                .enumerate()
                .map(|(c, ((&t, step), at))| {
                    let t = match (step, at) {
                        (Some(s), Some(a)) => t.clamp(a - s, a + s),
                        _ => t,
                    };
                    let share = self.monitor.speed_share(c);
                    match (share < 1.0, last_sent.get(c), self.max_speed_deg.get(c)) {
                        (true, Some(&prev), Some(&v)) => {
                            let most = share * v * period_s;
                            t.clamp(prev - most, prev + most)
                        }
                        _ => t,
                    }
                })
                .collect();
            let temperature = t_s >= next_temperature;
            if temperature {
                next_temperature = t_s + TEMPERATURE_EVERY_S;
            }
            let (sensed, sends) = self.tick(&sent, temperature);
            let stop = self.protect(clock.now(), &sensed, &last_sent);
            last_sent.clone_from(&sent);
            let positions: Vec<Result<f64, Failure>> =
                sensed.into_iter().map(|r| r.map(|s| s.position)).collect();
            if let (Some(first), Some(last)) = (sends.iter().min(), sends.iter().max())
                && timing.skew.len() < MAX_TIMED_TICKS
            {
                timing.skew.push(last.saturating_duration_since(*first));
                timing.late.push(last.saturating_duration_since(due));
            }
            for (c, (row, p)) in rows.iter_mut().zip(&positions).enumerate() {
                let target = targets.get(c).copied().unwrap_or(f64::NAN);
                let prior = before.as_ref().and_then(|b| b.get(c).copied());
                row.take(target, p, prior);
                if let Some(&x) = sent.get(c).filter(|&&x| (x - target).abs() > 1e-9) {
                    row.limited += 1;
                    let at = (timing.ticks, t_s, c, x, target);
                    self.held_back.get_or_insert(HeldBack::from(at));
                }
                if let (Ok(at), Some(slot)) = (p, last_at.get_mut(c)) {
                    *slot = Some(*at);
                }
            }
            let reported: Vec<Option<f64>> =
                positions.iter().map(|p| p.as_ref().ok().copied()).collect();
            on_tick(&PlayTick {
                t_s,
                joints: self.traj.joints(),
                targets: &sent,
                positions: &reported,
            })?;
            before = Some(targets);
            timing.ticks += 1;
            control.report(&Progress::new("play", k + 1, Some(last + 1)));
            if stop {
                break;
            }
            // Ticks a slow one ran past are skipped, not caught up.
            let now = clock.now().saturating_duration_since(start);
            #[allow(clippy::cast_possible_truncation)] // ticks of at most an hour
            let behind = (now.as_nanos() / self.period.as_nanos().max(1)) as u64;
            if behind > k + 1 {
                timing.overruns += behind - k - 1;
                k = behind;
            } else {
                k += 1;
            }
        }
        Ok(timing)
    }

    /// Feeds what the joints reported at `now` to the protection (the following error
    /// against the targets sent the tick before); whether it stops the run.
    fn protect(
        &mut self,
        now: Instant,
        sensed: &[Result<Sensed, Failure>],
        sent_before: &[f64],
    ) -> bool {
        let mut stop = false;
        for (c, s) in sensed.iter().enumerate() {
            let Ok(s) = s else { continue };
            let reading = Reading {
                at: now,
                position_deg: Some(s.position),
                error_deg: sent_before.get(c).map(|t| (s.position - t).abs()),
                target_deg: sent_before.get(c).copied(),
                current_a: s.current_a,
                temperature_c: s.temperature_c,
            };
            for f in self.monitor.feed(c, &reading) {
                stop |= f.action == Action::Stop;
                tracing::warn!("{f}");
                if self.faults.len() < protect::MAX_EVENTS || f.action == Action::Stop {
                    self.faults.push(f);
                }
            }
        }
        stop
    }

    /// Sends one tick's targets, each bus from its own thread (a WHJ joint's temperature
    /// read after its command when `temperature`); each joint's outcome by column and
    /// each bus's first send (this clock).
    fn tick(
        &self,
        targets: &[f64],
        temperature: bool,
    ) -> (Vec<Result<Sensed, Failure>>, Vec<Instant>) {
        let n = targets.len();
        let mut positions: Vec<Result<Sensed, Failure>> = (0..n)
            .map(|_| {
                Err(Failure::of(
                    crate::ErrorKind::Device,
                    &"not commanded this tick",
                ))
            })
            .collect();
        let mut sends = Vec::with_capacity(self.groups.len());
        let clock = self.clock;
        let torque = self.torque;
        let results: Vec<(Option<Instant>, Outcomes)> = std::thread::scope(|s| {
            let handles: Vec<_> = self
                .groups
                .iter()
                .enumerate()
                .map(|(i, g)| {
                    s.spawn(move || {
                        // Every bus is at the tick (the clock slept them there); the
                        // instant its first send goes, on the clock's time line.
                        let sent = clock.bus_now(i);
                        (sent, g.send(targets, torque, temperature))
                    })
                })
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().unwrap_or((None, Vec::new())))
                .collect()
        });
        for (sent, outcomes) in results {
            sends.extend(sent);
            for (c, o) in outcomes {
                if let Some(slot) = positions.get_mut(c) {
                    *slot = o;
                }
            }
        }
        (positions, sends)
    }
}

impl Played {
    fn new(start_deg: f64) -> Self {
        Self {
            commands: 0,
            failed: 0,
            limited: 0,
            start_deg,
            target_deg: start_deg,
            position_deg: None,
            tracking_max_deg: 0.0,
            tracking_rms_deg: 0.0,
            sent_deg_s: None,
            sent_nm: None,
            tracking: Tracking::default(),
            last_error: None,
            protection: None,
        }
    }

    /// One tick's outcome: the target sent, where the joint reported itself, and the
    /// target of the tick before.
    fn take(&mut self, target: f64, at: &Result<f64, Failure>, before: Option<f64>) {
        self.target_deg = target;
        match at {
            Ok(p) => {
                self.commands += 1;
                if p.is_finite() {
                    self.position_deg = Some(*p);
                    if let Some(b) = before {
                        self.tracking.add(*p, b);
                    }
                }
            }
            Err(f) => {
                self.failed += 1;
                self.last_error = Some(f.clone());
            }
        }
    }

    fn result(mut self, name: &str) -> DeviceResult<String, Played> {
        self.tracking_max_deg = self.tracking.max().unwrap_or(0.0);
        self.tracking_rms_deg = self.tracking.rms().unwrap_or(0.0);
        if let Some(f) = self.protection.take() {
            return DeviceResult::failed(name.to_owned(), f);
        }
        match self.last_error.take() {
            Some(f) => DeviceResult::failed(
                name.to_owned(),
                Failure {
                    kind: f.kind,
                    error: format!(
                        "{name}: {} of {} commands failed; the last: {}",
                        self.failed,
                        self.failed + self.commands,
                        f.error
                    ),
                },
            ),
            None => DeviceResult::ok(name.to_owned(), self),
        }
    }
}

#[cfg(all(test, feature = "sim"))]
mod tests;
