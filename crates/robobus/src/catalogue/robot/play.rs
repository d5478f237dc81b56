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

mod blend;
mod drive;
mod group;
mod offer;
mod player;
mod preflight;

use std::time::Duration;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use robobus_wck::BaudRate;

use super::ROBOT;
use crate::catalogue::effect::{Effect, Moved};
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::{Family, Plan};
use crate::catalogue::whj::PreflightArg;
use crate::motion::Tracking;
use crate::ops::protect::{self, Action, Fault};
use crate::ops::{Control, DeviceResult, Failure, OpError};
use crate::robot::RobotConfig;
use crate::robot::trajectory::Trajectory;
use crate::station::Station;
use crate::whj::Percentiles;
use group::{Group, check_steps, groups, models_of, step_limits};
use player::{Player, lead_in_s};

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
            let blend = interaction.play_blend();
            run_play(cx.station, self, cx.control, blend.as_deref(), &mut |t| {
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

pub use blend::{Blend, Commanded, Taken};
pub use preflight::{FlownJoint, PlayPreflight};

/// What a `robot.play` run did.
struct PlayedRun {
    joints: Vec<DeviceResult<String, Played>>,
    summary: PlaySummary,
}

/// How often each WHJ joint's temperature is read during a run (a status query), s.
pub(super) const TEMPERATURE_EVERY_S: f64 = 0.25;

/// The lead-in's peak speed over its mean: a half-cosine's, pi/2.
const LEAD_IN_PEAK: f64 = std::f64::consts::FRAC_PI_2;

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

/// `robot.play` on the station's robot file.
fn run_play(
    station: &Station,
    r: &Play,
    control: &mut Control<'_>,
    blend: Option<&Blend>,
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
    check_steps(
        &step_limits(&groups, index.len())?,
        &traj,
        &from,
        lead_in,
        r.rate_hz,
    )?;
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
    player.blend = blend;
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

/// The most ticks whose skew and lateness are kept (an hour at 500 Hz would be 1.8 M).
pub(super) const MAX_TIMED_TICKS: usize = 100_000;

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
