//! `robot.teleop`: leader-follower teleoperation. Some joints of the station's robot file
//! (the leader, moved by hand) are read at a fixed rate and drive others (the follower)
//! through a joint map: each follower joint goes to its leader joint's angle × `scale` +
//! `offset_deg`, within the pair's `limits_deg` and the follower's soft limits. Both sides
//! are in the file's joint frame (its `offset`, `direction` and wCK `centre` applied), so a
//! leader and a follower calibrated into the same frame mirror each other with the
//! defaults, across families and buses.
//!
//! Each cycle reads every leader joint fresh, then steps every follower joint toward its
//! target with the [`Follower`]: at most one jog step per cycle (WHJ 2°, wCK 8 steps),
//! within the device's limits, a WHJ joint only when it is enabled in position mode. A
//! cycle in which any leader joint did not answer sends nothing: the follower holds where
//! it is (never moved half way on a partial reading). When no complete reading has come
//! for `leader_timeout_ms`, the run ends with the leader's failure.
//!
//! Before the first cycle every follower joint is read with `robot.play`'s check
//! (`ready_at`): a silent one, one outside its soft limits, or
//! a WHJ joint not enabled in position mode refuses the run, nothing sent. However the run
//! ends, each bus of the leader and the follower is left in the robot file's `safe_state`
//! (`settle`).

use std::collections::VecDeque;
use std::ops::RangeInclusive;
use std::time::{Duration, Instant};

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use robobus_wck::BaudRate;

use super::play::Spread;
use super::{ROBOT, out_of, within};
use crate::catalogue::effect::{Effect, Moved};
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::{Family, Plan};
use crate::motion::Tracking;
use crate::ops::protect::{self, Action, Fault, Monitor, Reading};
use crate::ops::{Control, DeviceResult, ErrorKind, Failure, OpError, Outcome, Progress};
use crate::station::Station;
use crate::station::clock::BusClock;
use crate::station::follow::Follower;
use crate::station::sampler::RobotSampler;

/// One leader joint driving one follower joint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Pair {
    /// The leader joint's name in the robot file.
    pub leader: String,
    /// The follower joint's name in the robot file.
    pub follower: String,
    /// Follower angle per leader angle (-10..=10; default 1; negative mirrors).
    #[serde(default = "one")]
    pub scale: f64,
    /// Added to the scaled leader angle, degrees (-360..=360; default 0).
    #[serde(default)]
    pub offset_deg: f64,
    /// The follower's range in this map, degrees `[min, max]` (within -360..=360; the
    /// follower's soft limits always apply too).
    #[serde(default)]
    pub limits_deg: Option<[f64; 2]>,
}

const fn one() -> f64 {
    1.0
}

/// `robot.teleop` (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Teleop {
    /// The pairs (1..=64): a follower joint appears once, and never as a leader; a
    /// leader joint may drive several followers.
    pub map: Vec<Pair>,
    /// Cycles a second (1..=200; default 50).
    #[serde(default = "default_rate")]
    pub rate_hz: f64,
    /// How long, seconds (0.1..=86400); none: until stopped.
    #[serde(default)]
    pub seconds: Option<f64>,
    /// The run ends when no complete leader reading has come for this long, ms
    /// (10..=10000; default 500).
    #[serde(default = "default_timeout")]
    pub leader_timeout_ms: u64,
    /// Make the leader's wCK servos passive first, to be moved by hand (default true).
    #[serde(default = "super::yes")]
    pub passive_leader: bool,
}

const fn default_rate() -> f64 {
    50.0
}

const fn default_timeout() -> u64 {
    500
}

/// Range of `rate_hz`.
pub const TELEOP_RATE_HZ: RangeInclusive<f64> = 1.0..=200.0;
/// Range of `seconds`.
pub const TELEOP_SECONDS: RangeInclusive<f64> = 0.1..=86_400.0;
/// Range of `leader_timeout_ms`.
pub const LEADER_TIMEOUT_MS: RangeInclusive<u64> = 10..=10_000;
/// Range of a pair's `scale`.
pub const SCALE: RangeInclusive<f64> = -10.0..=10.0;
/// Range of a pair's `offset_deg` and `limits_deg`.
pub const ANGLE_DEG: RangeInclusive<f64> = -360.0..=360.0;
/// The most pairs in a map.
pub const MAX_PAIRS: usize = 64;
/// The longest joint name in a pair (the robot file's names are shorter).
pub const MAX_NAME: usize = 64;
/// The loop latencies kept for the percentiles: the last this many cycles (the largest is
/// kept over the whole run).
pub const LATENCY_WINDOW: usize = 65_536;

impl Teleop {
    /// Checks every value against its range and the map's rules (named as the command
    /// line's options); nothing needs a station.
    pub fn check(&self) -> Result<(), OpError> {
        within("--rate-hz", self.rate_hz, &TELEOP_RATE_HZ)?;
        if let Some(s) = self.seconds {
            within("--seconds", s, &TELEOP_SECONDS)?;
        }
        if !LEADER_TIMEOUT_MS.contains(&self.leader_timeout_ms) {
            return Err(out_of(
                "--leader-timeout-ms",
                self.leader_timeout_ms,
                &LEADER_TIMEOUT_MS,
            ));
        }
        if self.map.is_empty() || self.map.len() > MAX_PAIRS {
            return Err(OpError::invalid(
                "--map",
                format!("{} pairs", self.map.len()),
                format!("1..={MAX_PAIRS} pairs LEADER:FOLLOWER"),
            ));
        }
        for p in &self.map {
            for name in [&p.leader, &p.follower] {
                if name.is_empty() || name.chars().count() > MAX_NAME {
                    return Err(OpError::invalid(
                        "--map",
                        name,
                        format!("a joint name of 1..={MAX_NAME} characters"),
                    ));
                }
            }
            let pair = format!("{}:{}", p.leader, p.follower);
            if self.map.iter().any(|q| q.leader == p.follower) {
                return Err(OpError::invalid(
                    "--map",
                    &pair,
                    format!("{} follows, so it cannot also lead", p.follower),
                ));
            }
            if self.map.iter().filter(|q| q.follower == p.follower).count() > 1 {
                return Err(OpError::invalid(
                    "--map",
                    &pair,
                    format!("{} follows two leaders: one pair per follower", p.follower),
                ));
            }
            within("--map scale", p.scale, &SCALE)?;
            within("--map offset", p.offset_deg, &ANGLE_DEG)?;
            if let Some([lo, hi]) = p.limits_deg {
                within("--limit", lo, &ANGLE_DEG)?;
                within("--limit", hi, &ANGLE_DEG)?;
                if lo >= hi {
                    return Err(OpError::invalid(
                        "--limit",
                        format!("{}:{lo}:{hi}", p.follower),
                        "MIN below MAX",
                    ));
                }
            }
        }
        Ok(())
    }

    /// What a run sends, for the plan.
    pub fn note(&self) -> Result<String, OpError> {
        self.check()?;
        let pairs: Vec<String> = self
            .map
            .iter()
            .map(|p| {
                let limits = p
                    .limits_deg
                    .map(|[lo, hi]| format!(", within {lo}..={hi}°"))
                    .unwrap_or_default();
                format!(
                    "{} ← {} × {} + {}°{limits}",
                    p.follower, p.leader, p.scale, p.offset_deg
                )
            })
            .collect();
        Ok(format!(
            "{}every {:.1} ms ({} Hz) reads each leader joint (a status read per wCK servo; a \
             status query and a speed read per WHJ joint) and steps each follower joint toward \
             its target, within its soft limits: {}; a follower wCK servo gets a status read \
             and a move of at most 8 steps, a follower WHJ joint (enabled in position mode) \
             one position servo frame of at most 2°; a cycle without every leader reading \
             sends nothing (the follower holds); after {} ms without one the run ends, the \
             follower holding; {}{}",
            if self.passive_leader {
                "makes the leader's wCK servos passive (FF <0xC0|ID> 00 <checksum>, torque \
                 off), then "
            } else {
                ""
            },
            1000.0 / self.rate_hz,
            self.rate_hz,
            pairs.join("; "),
            self.leader_timeout_ms,
            self.seconds
                .map_or_else(|| "until stopped".to_owned(), |s| format!("for {s} s")),
            super::END_NOTE,
        ))
    }
}

impl Operation for Teleop {
    const OP: &'static str = "robot.teleop";
    const FAMILY: Family = Family::Robot;
    const DOC: OpDoc = OpDoc {
        args: r#"`map`: 1..=64 pairs `{"leader", "follower", "scale"=1 (-10..=10), "offset_deg"=0 (-360..=360), "limits_deg": [min, max]}` (joint names of the robot file; a follower once, never also a leader), `rate_hz`=50 (1..=200), `seconds` (0.1..=86400; none: until stopped), `leader_timeout_ms`=500 (10..=10000), `passive_leader`=true"#,
        report: "one row per follower joint by name: `leader`, `commands`, `limited` (cut \
                 short by a jog step or a limit), `failed`, `target_deg`, `position_deg` (at \
                 the last command), `tracking_max_deg`, `tracking_rms_deg`; `summary`: \
                 `cycles`, `commanded`, `held` (cycles without every leader reading: nothing \
                 sent), `overruns`, `seconds`, `rate_hz`, `latency_ms` (`p50`, `p99`, `max`: \
                 from a cycle's leader reading to its last command), `leaders` (each one's \
                 `name`, `readings`, `failed`, `error`), `leader_lost` (the run ended because \
                 the leader went silent: `failed` is `no-device`), `interrupted`, `safe_state` \
                 (as `robot.play`'s), `protection` (the host's protection events of the \
                 follower joints, as `robot.play`'s: a stop ends the run and fails its \
                 joint's row). Refused before anything is sent when a follower joint is \
                 silent, outside its soft limits, or a WHJ joint not enabled in position mode \
                 (`robot.play`'s check)",
        confirm: "motion",
    };
    type Row = DeviceResult<String, Followed>;
    type Summary = TeleopSummary;

    fn effect(&self) -> Effect {
        Effect::Motion
    }

    fn moved(&self) -> Result<Option<Moved>, OpError> {
        Teleop::check(self).map(|()| None)
    }

    fn check(&self) -> Result<Confirm, OpError> {
        Teleop::check(self).map(|()| Confirm::NONE)
    }

    fn plan(&self, _baud: BaudRate) -> Result<Plan, OpError> {
        Ok(Plan::notes_only(
            Self::OP,
            Family::Robot,
            vec![self.note()?],
        ))
    }

    /// The leader's silence fails the run (its kind first, `no-device`), whatever the
    /// follower did.
    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, TeleopSummary>, OpError> {
        let t = run_teleop(cx.station, self, cx.control)?;
        let mut report = Report::devices_with(Self::OP, ROBOT, t.joints).summary(t.summary);
        if let Some(lost) = t.lost {
            report.failed = Some(lost.kind);
            report.error = Some(match report.error.take() {
                Some(e) => format!("{}; {e}", lost.error),
                None => lost.error,
            });
        }
        Ok(report)
    }
}

/// A follower joint's run (its row of the report, by the follower's name).
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct Followed {
    /// The leader joint that drove it.
    pub leader: String,
    /// Commands sent.
    pub commands: u64,
    /// Commands a jog step or a limit cut short of the leader's target.
    pub limited: u64,
    /// Commands that failed (the joint did not answer or refused).
    pub failed: u64,
    /// The last target (the leader mapped, within the limits), degrees.
    pub target_deg: Option<f64>,
    /// Where the joint was at its last command (read just before it), degrees.
    pub position_deg: Option<f64>,
    /// The largest distance from the joint to its target at a command, degrees.
    pub tracking_max_deg: f64,
    /// The root mean square of that distance over the commands, degrees.
    pub tracking_rms_deg: f64,
    #[serde(skip)]
    tracking: Tracking,
    #[serde(skip)]
    last_error: Option<Failure>,
}

/// A leader joint's readings.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct Led {
    /// Its name.
    pub name: String,
    /// Readings that answered.
    pub readings: u64,
    /// Readings that failed.
    pub failed: u64,
    /// The last failure, if any.
    pub error: Option<String>,
}

/// The whole run.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct TeleopSummary {
    /// Cycles run.
    pub cycles: u64,
    /// Cycles that commanded the follower.
    pub commanded: u64,
    /// Cycles without every leader reading: nothing sent, the follower held.
    pub held: u64,
    /// Ticks skipped because a cycle took longer than the period.
    pub overruns: u64,
    /// How long it ran, s.
    pub seconds: f64,
    /// Cycles a second achieved.
    pub rate_hz: f64,
    /// The loop latency.
    /// Loop latency, ms, from the start of a cycle's leader reading to its last follower
    /// command: median and 99th percentile of the last [`LATENCY_WINDOW`] cycles that
    /// commanded, the largest over the run.
    pub latency_ms: Spread,
    /// Each leader joint's readings.
    pub leaders: Vec<Led>,
    /// The run ended because the leader went silent.
    pub leader_lost: bool,
    /// The stop token ended it before its `seconds`.
    pub interrupted: bool,
    /// How it left each bus of the leader and the follower: in the robot file's
    /// `safe_state` (finished, the leader lost, or stopped).
    pub safe_state: Vec<super::BusEnd>,
    /// The host's protection events of the follower joints, in order: warnings,
    /// deratings and the stop (a stop ends the run in the safe state and fails its
    /// joint's row).
    pub protection: Vec<Fault>,
}

/// What a `robot.teleop` run did.
struct Teleoperated {
    /// Each follower joint's run, by name.
    joints: Vec<DeviceResult<String, Followed>>,
    /// The whole run.
    summary: TeleopSummary,
    /// The leader's failure that ended it.
    lost: Option<Failure>,
}

/// `robot.teleop` on the station's robot file.
fn run_teleop(
    station: &Station,
    r: &Teleop,
    control: &mut Control<'_>,
) -> Result<Teleoperated, OpError> {
    r.check()?;
    let mut run = Run::open(station, r)?;
    // Nothing below returns early: the run ends through `settle`.
    let period = Duration::from_secs_f64(1.0 / r.rate_hz);
    let timeout = Duration::from_millis(r.leader_timeout_ms);
    let end = r.seconds.map(Duration::from_secs_f64);
    let total = r.seconds.map(|s| {
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // ≤ 17,280,000
        let n = (s * r.rate_hz).ceil() as u64;
        n
    });
    let start = run.clock.now();
    let mut last_complete = start;
    let mut tick = 0u64;
    let mut interrupted = false;
    loop {
        let due = start + period * u32::try_from(tick).unwrap_or(u32::MAX);
        if end.is_some_and(|e| due.duration_since(start) >= e) {
            break;
        }
        let clock = &run.clock;
        if !control.sleep_with(due, |until| {
            if let Some(t) = until {
                clock.sleep_until(t);
            }
            clock.now()
        }) {
            interrupted = true;
            break;
        }
        let t0 = run.clock.now();
        if run.cycle(station, r, t0, t0.duration_since(start).as_secs_f64()) {
            last_complete = t0;
        } else if t0.duration_since(last_complete) >= timeout {
            run.lost = Some(run.silence(t0.duration_since(last_complete)));
            break;
        }
        control.report(&Progress::new("teleop", run.summary.cycles, total));
        if run.stopped.is_some() {
            break;
        }
        tick = next_tick(
            run.clock.now() - start,
            period,
            tick,
            &mut run.summary.overruns,
        );
    }
    let elapsed = run.clock.now().saturating_duration_since(start);
    // Each bus of the leader and the follower as the robot file says; a follower joint
    // the host's protection stopped torque off where its brake holds it.
    let torque_off = run.torque_off();
    let settled = super::settle_with(station, &run.config, &run.names, &torque_off);
    Ok(run.finish(r, elapsed, interrupted && end.is_some(), &settled))
}

/// The leader joints of `r`'s map, each once, in the map's order; a name the file does
/// not have is bad input.
fn leader_names(config: &crate::robot::RobotConfig, r: &Teleop) -> Result<Vec<String>, OpError> {
    let mut leaders: Vec<String> = Vec::new();
    for p in &r.map {
        if !config.joints.iter().any(|j| j.name == p.leader) {
            return Err(OpError::invalid(
                "--map",
                &p.leader,
                format!("a joint of the robot file: {}", config.joint_names()),
            ));
        }
        if !leaders.contains(&p.leader) {
            leaders.push(p.leader.clone());
        }
    }
    Ok(leaders)
}

impl Followed {
    fn new(leader: &str) -> Self {
        Self {
            leader: leader.to_owned(),
            commands: 0,
            limited: 0,
            failed: 0,
            target_deg: None,
            position_deg: None,
            tracking_max_deg: 0.0,
            tracking_rms_deg: 0.0,
            tracking: Tracking::default(),
            last_error: None,
        }
    }
}

impl TeleopSummary {
    fn new(leaders: impl Iterator<Item = String>) -> Self {
        Self {
            cycles: 0,
            commanded: 0,
            held: 0,
            overruns: 0,
            seconds: 0.0,
            rate_hz: 0.0,
            latency_ms: Spread::of(&[]),
            leaders: leaders
                .map(|name| Led {
                    name,
                    readings: 0,
                    failed: 0,
                    error: None,
                })
                .collect(),
            leader_lost: false,
            interrupted: false,
            safe_state: Vec::new(),
            protection: Vec::new(),
        }
    }
}

/// A run's state between cycles.
struct Run {
    follower: Follower,
    sampler: RobotSampler,
    clock: BusClock,
    /// Each pair's leader: its index among the leader joints.
    pair_leader: Vec<usize>,
    /// Each pair's range in joint degrees: its own limits within the follower's.
    ranges: Vec<(f64, f64)>,
    rows: Vec<Followed>,
    summary: TeleopSummary,
    latencies: VecDeque<Duration>,
    worst: Duration,
    /// The robot file, and the leader's and the follower's joints (what the run ends by
    /// bringing to their safe state).
    config: crate::robot::RobotConfig,
    names: Vec<String>,
    /// The latest readings of the leader joints (`None`: failed in this cycle).
    angles: Vec<Option<f64>>,
    lost: Option<Failure>,
    /// The host's protection of the follower joints, by pair.
    monitor: Monitor,
    /// Per pair, the follower's model (a WHJ joint's, as it identified), its
    /// `max_velocity` (degrees a second) and the position it was last sent (joint
    /// degrees).
    models: Vec<Option<robobus_whj::units::Model>>,
    max_speed_deg: Vec<f64>,
    last_sent: Vec<Option<f64>>,
    /// When the WHJ followers' temperature is read next, s into the run.
    next_temperature: f64,
    /// The protection's stop, by pair.
    stopped: Option<usize>,
}

impl Run {
    /// Resolves the map on the station's robot file, opens the leader's sampler and the
    /// follower, and makes the leader's wCK servos passive if asked.
    fn open(station: &Station, r: &Teleop) -> Result<Self, OpError> {
        let config = station.robot().cloned().ok_or_else(super::no_robot)?;
        let leaders = leader_names(&config, r)?;
        let followers: Vec<String> = r.map.iter().map(|p| p.follower.clone()).collect();
        let follower = Follower::of_joints(station, &followers)?;
        // The leader's own sampler: only its joints and their buses.
        // The loop's clock spans the leader's and the follower's buses.
        let all: Vec<String> = leaders.iter().chain(&followers).cloned().collect();
        let clock = BusClock::of(station, &super::only(&config, &all))?;
        let led = super::only(&config, &leaders);
        let sampler = super::sampler(station, &led)?;
        let mut ranges = Vec::with_capacity(r.map.len());
        for (p, f) in r.map.iter().zip(follower.joints()) {
            let [lo, hi] = f.limits_rad.map(f64::to_degrees);
            let (lo, hi) = match p.limits_deg {
                Some([a, b]) => (lo.max(a), hi.min(b)),
                None => (lo, hi),
            };
            if lo > hi {
                return Err(OpError::invalid(
                    "--limit",
                    &p.follower,
                    "a range that overlaps the follower's soft limits (the robot file's limits)",
                ));
            }
            ranges.push((lo, hi));
        }
        // Refused before anything is sent: a follower joint that is silent, outside its
        // soft limits, or a WHJ joint not enabled in position mode (as play refuses).
        super::ready_at(station, &config, &followers, "teleoperation")?;
        if r.passive_leader {
            super::make_passive(station, &led)?;
        }
        let pair_leader = r
            .map
            .iter()
            .map(|p| {
                led.joints
                    .iter()
                    .position(|j| j.name == p.leader)
                    .unwrap_or(0)
            })
            .collect();
        let rows = r.map.iter().map(|p| Followed::new(&p.leader)).collect();
        let summary = TeleopSummary::new(led.joints.iter().map(|j| j.name.clone()));
        let models: Vec<Option<robobus_whj::units::Model>> = follower
            .joints()
            .iter()
            .map(|f| {
                if f.family != Family::Whj {
                    return None;
                }
                let id = robobus_whj::JointId::new(f.id).ok()?;
                let port = station.whj(Some(&f.bus)).ok()?;
                let model = port.bus().joint_unchecked(id).identity().ok();
                model.map(|i| i.model)
            })
            .collect();
        let joint_of = |name: &str| config.joints.iter().find(|j| j.name == name);
        let monitor = Monitor::new(
            clock.now(),
            followers
                .iter()
                .zip(&models)
                .zip(follower.joints())
                .map(|((n, &m), f)| {
                    let limits =
                        joint_of(n).map_or(protect::Limits::OFF, |j| config.protection_of(j, m));
                    // A wCK follower is read at each command's reply: its windows at
                    // least a cycle (the wCK defaults are sized for 200 ms).
                    let limits = if f.family == Family::Wck {
                        limits.for_reading_period(Duration::from_secs_f64(1.0 / r.rate_hz))
                    } else {
                        limits
                    };
                    (n.clone(), limits)
                })
                .collect(),
        );
        let max_speed_deg = followers
            .iter()
            .map(|n| joint_of(n).map_or(0.0, |j| j.max_velocity.to_degrees()))
            .collect();
        Ok(Self {
            follower,
            sampler,
            clock,
            pair_leader,
            ranges,
            rows,
            angles: vec![None; summary.leaders.len()],
            summary,
            latencies: VecDeque::new(),
            worst: Duration::ZERO,
            names: all,
            config,
            lost: None,
            monitor,
            last_sent: vec![None; r.map.len()],
            models,
            max_speed_deg,
            next_temperature: 0.0,
            stopped: None,
        })
    }

    /// One cycle started at `t0` (`t_s` seconds into the run): reads the leader and, with every leader joint read,
    /// commands the follower. Whether the reading was complete.
    fn cycle(&mut self, station: &Station, r: &Teleop, t0: Instant, t_s: f64) -> bool {
        self.summary.cycles += 1;
        let readings = self.sampler.sample(t_s);
        self.angles.fill(None);
        for ((row, l), a) in readings
            .into_iter()
            .zip(&mut self.summary.leaders)
            .zip(&mut self.angles)
        {
            match row.outcome {
                Outcome::Ok(s) => {
                    l.readings += 1;
                    *a = Some(s.position_deg);
                }
                Outcome::Failed(f) => {
                    l.failed += 1;
                    l.error = Some(f.error);
                }
            }
        }
        if self.angles.iter().any(Option::is_none) {
            self.summary.held += 1;
            return false;
        }
        let mut targets = Vec::with_capacity(r.map.len());
        let mut clamped = Vec::with_capacity(r.map.len());
        for ((p, &li), &(lo, hi)) in r.map.iter().zip(&self.pair_leader).zip(&self.ranges) {
            let want =
                self.angles.get(li).copied().flatten().unwrap_or(0.0) * p.scale + p.offset_deg;
            clamped.push(!(lo..=hi).contains(&want));
            targets.push(want.clamp(lo, hi));
        }
        // A derated follower moves no faster than its share of its max_velocity.
        let period_s = 1.0 / r.rate_hz;
        for (i, t) in targets.iter_mut().enumerate() {
            let share = self.monitor.speed_share(i);
            if let (true, Some(Some(prev)), Some(v)) = (
                share < 1.0,
                self.last_sent.get(i),
                self.max_speed_deg.get(i),
            ) {
                let most = share * v * period_s;
                *t = t.clamp(prev - most, prev + most);
            }
            *t = t.to_radians();
        }
        // Within the soft limits, a target can still lie past a wCK servo's range (a file
        // whose limits reach beyond it): every follower row fails this cycle, and nothing
        // is sent.
        let plan = match self.follower.plan(&targets) {
            Ok(plan) => plan,
            Err(e) => {
                for row in &mut self.rows {
                    row.failed += 1;
                    row.last_error = Some(Failure::from(&e));
                }
                self.summary.held += 1;
                return true;
            }
        };
        let done = self.follower.apply(station, &plan);
        let took = self.clock.now().saturating_duration_since(t0);
        self.worst = self.worst.max(took);
        if self.latencies.len() == LATENCY_WINDOW {
            self.latencies.pop_front();
        }
        self.latencies.push_back(took);
        self.summary.commanded += 1;
        self.protect(station, &done, t_s);
        for (i, (row, result)) in self.rows.iter_mut().zip(done).enumerate() {
            let target_deg = targets.get(i).copied().unwrap_or(0.0).to_degrees();
            row.target_deg = Some(target_deg);
            match result.outcome {
                Outcome::Ok(j) => {
                    row.commands += 1;
                    if j.limited || clamped.get(i).copied().unwrap_or(false) {
                        row.limited += 1;
                    }
                    if let Some(at) = self.follower.joint_rad(i, j.from) {
                        let at = at.to_degrees();
                        row.position_deg = Some(at);
                        row.tracking.add(at, target_deg);
                    }
                }
                Outcome::Failed(f) => {
                    row.failed += 1;
                    row.last_error = Some(f);
                }
            }
        }
        true
    }

    /// Feeds the follower's answers to a command (`t_s` seconds into the run) to the
    /// host's protection, a WHJ follower's temperature read every 0.25 s.
    fn protect(
        &mut self,
        station: &Station,
        done: &[DeviceResult<String, crate::station::jog::Jogged>],
        t_s: f64,
    ) {
        let temperatures = if t_s >= self.next_temperature {
            self.next_temperature = t_s + super::play::TEMPERATURE_EVERY_S;
            self.temperatures(station)
        } else {
            vec![None; self.rows.len()]
        };
        let now = self.clock.now();
        for (i, result) in done.iter().enumerate() {
            let Outcome::Ok(j) = &result.outcome else {
                continue;
            };
            // Where the joint reported itself at this command, and its current.
            // The device position it answered with: WHJ degrees, wCK steps.
            let key = if j.family == Family::Wck {
                "position"
            } else {
                "position_deg"
            };
            let device = j.feedback.get(key).and_then(serde_json::Value::as_f64);
            let at = device.and_then(|d| self.follower.joint_rad(i, d));
            let reading = Reading {
                at: now,
                position_deg: at.map(f64::to_degrees),
                error_deg: at
                    .zip(self.last_sent.get(i).copied().flatten())
                    .map(|(a, sent)| (a.to_degrees() - sent).abs()),
                target_deg: self.last_sent.get(i).copied().flatten(),
                // A WHJ joint's current, a wCK servo's load (its move's reply) as one.
                current_a: crate::station::jog::guard::current_a_of(&j.feedback),
                temperature_c: temperatures.get(i).copied().flatten(),
            };
            for f in self.monitor.feed(i, &reading) {
                tracing::warn!("{f}");
                if f.action == Action::Stop {
                    self.stopped = Some(i);
                }
                if self.summary.protection.len() < protect::MAX_EVENTS || f.action == Action::Stop {
                    self.summary.protection.push(f);
                }
            }
            if let Some(slot) = self.last_sent.get_mut(i) {
                *slot = self.follower.joint_rad(i, j.sent).map(f64::to_degrees);
            }
        }
    }

    /// Each WHJ follower's temperature, read now (a status query; `None` for a wCK servo
    /// or a joint that did not answer, whose next command finds it silent).
    fn temperatures(&self, station: &Station) -> Vec<Option<f64>> {
        self.follower
            .joints()
            .iter()
            .map(|f| {
                if f.family != Family::Whj {
                    return None;
                }
                let id = robobus_whj::JointId::new(f.id).ok()?;
                let port = station.whj(Some(&f.bus)).ok()?;
                let status = port.bus().joint_unchecked(id).status().ok()?;
                Some(f64::from(status.temperature.celsius()))
            })
            .collect()
    }

    /// The follower joint the protection stopped, if torque off is safe for it.
    fn torque_off(&self) -> Vec<String> {
        self.stopped
            .filter(|&i| protect::torque_off_is_safe(self.models.get(i).copied().flatten()))
            .and_then(|i| self.follower.joints().get(i))
            .map(|f| vec![f.name.clone()])
            .unwrap_or_default()
    }

    /// The failure of a leader silent for `silent`: which joints, and why.
    fn silence(&self, silent: Duration) -> Failure {
        let joints: Vec<String> = self
            .summary
            .leaders
            .iter()
            .zip(&self.angles)
            .filter(|(_, a)| a.is_none())
            .map(|(l, _)| match &l.error {
                Some(e) => format!("{}: {e}", l.name),
                None => l.name.clone(),
            })
            .collect();
        Failure::of(
            ErrorKind::NoDevice,
            &format!(
                "the leader gave no complete reading for {} ms; the follower held where it was \
                 ({})",
                silent.as_millis(),
                joints.join("; ")
            ),
        )
    }

    /// The report of the run, `elapsed` long.
    fn finish(
        mut self,
        r: &Teleop,
        elapsed: Duration,
        interrupted: bool,
        settled: &super::Settled,
    ) -> Teleoperated {
        let torque_off = self.torque_off();
        let s = &mut self.summary;
        s.seconds = elapsed.as_secs_f64();
        #[allow(clippy::cast_precision_loss)] // a count of cycles
        let cycles = s.cycles as f64;
        s.rate_hz = if s.seconds > 0.0 {
            cycles / s.seconds
        } else {
            0.0
        };
        s.latency_ms = Spread::of(self.latencies.make_contiguous());
        s.latency_ms.max = self.worst.as_secs_f64() * 1e3;
        s.leader_lost = self.lost.is_some();
        s.interrupted = interrupted;
        let joints = r
            .map
            .iter()
            .zip(self.rows)
            .enumerate()
            .map(|(i, (p, mut row))| {
                row.tracking_max_deg = row.tracking.max().unwrap_or(0.0);
                row.tracking_rms_deg = row.tracking.rms().unwrap_or(0.0);
                if self.stopped == Some(i)
                    && let Some(stop) = s.protection.iter().find(|f| f.action == Action::Stop)
                {
                    let off = if torque_off.contains(&p.follower) {
                        "; its drive disabled (its brake holds it: holding would keep it \
                         pushing or heating)"
                    } else {
                        ""
                    };
                    return DeviceResult::failed(
                        p.follower.clone(),
                        Failure::of(ErrorKind::Device, &format!("{stop}{off}")),
                    );
                }
                match row.last_error.take() {
                    Some(f) => DeviceResult::failed(
                        p.follower.clone(),
                        Failure {
                            kind: f.kind,
                            error: format!(
                                "{}: {} of {} commands failed; the last: {}",
                                p.follower,
                                row.failed,
                                row.failed + row.commands,
                                f.error
                            ),
                        },
                    ),
                    None => DeviceResult::ok(p.follower.clone(), row),
                }
            })
            .collect();
        // A leader joint that did not reach its safe state fails the run as its silence
        // does (it has no row of its own).
        let leaders: Vec<String> = s.leaders.iter().map(|l| l.name.clone()).collect();
        let lost = self.lost.or_else(|| settled.first_of(&leaders));
        s.safe_state.clone_from(&settled.buses);
        Teleoperated {
            joints: settled.fail_rows(joints),
            summary: self.summary,
            lost,
        }
    }
}

/// The tick after `tick`; the ticks a slow cycle ran past are skipped (counted in
/// `overruns`), not caught up.
fn next_tick(elapsed: Duration, period: Duration, tick: u64, overruns: &mut u64) -> u64 {
    let behind = u64::try_from(elapsed.as_nanos() / period.as_nanos().max(1)).unwrap_or(u64::MAX);
    let next = tick + 1;
    if behind > next {
        *overruns += behind - next;
        behind
    } else {
        next
    }
}

#[cfg(all(test, feature = "sim"))]
mod tests;
