//! Protection on the host: a joint pushing into an obstacle, hit by something, or running
//! hot is stopped by robobus, before the joint's own protection trips.
//!
//! [`Monitor`] is sans-IO: an operation that moves joints feeds it each joint's readings
//! with their instants ([`Reading`]: the position it reported, the target it was sent
//! before, its current, its temperature; a value it did not read is `None` and checks
//! nothing) and gets back what to do ([`Fault`] with its [`Action`]). Every moving
//! operation uses this one monitor (`robot.play`, `robot.teleop`, the station's jogs and
//! followed targets); what it does on [`Action::Stop`] is the operation's one safe stop
//! (the robot file's `safe_state` through [`SafeState::apply`](super::SafeState::apply)).
//!
//! The checks, per joint ([`Limits`]):
//!
//! - **stall**: the current stays at or over `stall_current_a` for `stall_time_s` while
//!   the following error (the distance from where the joint reported itself to its
//!   target) is at least `stall_error_deg` and neither shrinks (by a tenth) nor the joint
//!   moves (by `stall_error_deg`) meanwhile: a joint pushing against something that does
//!   not give. A joint holding a load at its target (error under `stall_error_deg`), or
//!   lifting one behind its target (moving), is not stalled.
//! - **collision**: the current rises by `collision_current_jump_a`, or the following
//!   error grows by `collision_error_jump_deg` more than the target moved (the joint
//!   pushed away from its target), between two readings at most `jump_window_s` apart
//!   ([`JUMP_WINDOW`] for a WHJ joint): a knock.
//! - **thermal**: the temperature reaches `temperature_warn_c` (a warning),
//!   `temperature_derate_c` (the joint's speed is held to `derate` of its
//!   `max_velocity` until it cools 5 K below) and `temperature_stop_c` (stopped).
//!
//! A joint driven in velocity or effort has no following error: it is fed with
//! [`Monitor::feed_driven`] and its [`Drive`]. In velocity the stall is the stall current
//! while the joint turns at under [`STALL_SPEED_SHARE`] of its commanded speed (commanded
//! at least [`STALL_MIN_COMMAND_DEG_S`]), and a current jump is a collision; in effort its
//! current is what it was sent, so neither is a fault, and it is stopped turning faster
//! than its `max_velocity` (**speed**: what it pushed against gave way). The thermal
//! checks are the same.
//!
//! The defaults come from the models table ([`robobus_whj::models::PRODUCTS`]): a WHJ
//! joint's stall current and current jump are its model's rated current, and the
//! temperatures are 15, 10 and 5 K under the joints' 90 °C over-temperature alarm
//! ([`WHJ_OVER_TEMPERATURE_C`]). A wCK reply carries the servo's load (its supply
//! current on the over-load code scale, [`wck_load_a`]) and its position, no temperature:
//! a wCK servo is watched for a stall and a collision, never for heat ([`Limits::wck`],
//! from the wCK rows of the models table, [`robobus_wck::models::PRODUCTS`]). Its
//! readings come further apart (a played motion reads one servo every 200 ms), so its
//! windows are sized to the reading period ([`Limits::for_reading_period`]). The robot
//! file overrides any of them per joint (`[joints.protection]`, [`Overrides`]) or turns
//! protection off for a joint or the whole file.

use std::fmt;
use std::time::{Duration, Instant};

use robobus_whj::units::Model;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// The WHJ joints' over-temperature alarm, °C (error bit 0x0008, "90 °C alarm reached").
pub const WHJ_OVER_TEMPERATURE_C: f64 = 90.0;

/// The longest time between two readings a jump is measured over, for a WHJ joint (read
/// every tick): readings further apart are a new start, not a jump.
pub const JUMP_WINDOW: Duration = Duration::from_millis(100);

/// A wCK servo's jump window by default, s: a little over the 200 ms a played motion
/// takes to read the same servo again ([`Limits::for_reading_period`] widens it for a
/// slower reading).
pub const WCK_JUMP_WINDOW_S: f64 = 0.25;

/// How long a wCK servo's stall lasts before the stop, by default, s: two of a played
/// motion's 200 ms status reads after the first that saw it.
pub const WCK_STALL_TIME_S: f64 = 0.4;

/// The following error at which a wCK servo pushing with its stall load counts as
/// stalled, by default, degrees: about three steps of 1.055°, well over the servo's own
/// ±0.8° control error.
pub const WCK_STALL_ERROR_DEG: f64 = 3.0;

/// A wCK reply's load byte (0..=254) as a current, A: the load is the supply current on
/// the over-load code scale (A-1 (18); [`robobus_wck::models::load_milliamps`]).
pub fn wck_load_a(load: u8) -> f64 {
    robobus_wck::models::load_milliamps(load) / 1e3
}

/// The most events an operation keeps (a joint hovering at a temperature limit for
/// hours would otherwise grow its report without bound); a stop is always kept.
pub const MAX_EVENTS: usize = 256;

/// How far under its derate temperature a derated joint must cool to run at full speed
/// again, K.
pub const DERATE_HYSTERESIS_K: f64 = 5.0;

/// The following error at which a joint pushing with a stall current counts as stalled,
/// by default, degrees.
pub const DEFAULT_STALL_ERROR_DEG: f64 = 1.0;
/// How long a stall lasts before the joint is stopped, by default, s.
pub const DEFAULT_STALL_TIME_S: f64 = 0.3;
/// The following-error jump between two readings that is a collision, by default,
/// degrees.
pub const DEFAULT_COLLISION_ERROR_JUMP_DEG: f64 = 5.0;
/// The share of its `max_velocity` a derated joint keeps, by default.
pub const DEFAULT_DERATE: f64 = 0.5;

/// Whether a WHJ joint of `model` may be stopped with its torque off: every product with
/// that code has a pin brake, which locks when the drive is disabled (WHJ10 is made with
/// and without one: held, not disabled). A joint stopped for pushing into something, or
/// for heat, keeps pushing or heating while it holds, so the operation disables it where
/// it may.
pub fn torque_off_is_safe(model: Option<Model>) -> bool {
    let mut products = robobus_whj::models::PRODUCTS
        .iter()
        .filter(|p| Some(p.model) == model)
        .peekable();
    products.peek().is_some() && products.all(|p| p.pin_brake)
}

/// One joint's checks (see the [module docs](self)); a `None` limit checks nothing.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, JsonSchema)]
pub struct Limits {
    /// The current of a stall, A (its magnitude).
    pub stall_current_a: Option<f64>,
    /// How long a stall lasts before the stop, s.
    pub stall_time_s: f64,
    /// The least following error of a stall, degrees.
    pub stall_error_deg: f64,
    /// A rise of the current between two readings that is a collision, A.
    pub collision_current_jump_a: Option<f64>,
    /// A growth of the following error between two readings that is a collision,
    /// degrees.
    pub collision_error_jump_deg: Option<f64>,
    /// The temperature of a warning, °C.
    pub temperature_warn_c: Option<f64>,
    /// The temperature from which the joint is derated, °C.
    pub temperature_derate_c: Option<f64>,
    /// The temperature of a stop, °C.
    pub temperature_stop_c: Option<f64>,
    /// The share of its `max_velocity` a derated joint keeps (0.05..=1).
    pub derate: f64,
    /// Whether a joint driven in effort is stopped turning faster than its
    /// `max_velocity` ([`Drive::Effort`]).
    pub runaway: bool,
    /// The longest time between two readings a jump is measured over, s.
    pub jump_window_s: f64,
}

impl Limits {
    /// Nothing checked (a joint whose protection the robot file turned off).
    pub const OFF: Self = Self {
        stall_current_a: None,
        stall_time_s: DEFAULT_STALL_TIME_S,
        stall_error_deg: DEFAULT_STALL_ERROR_DEG,
        collision_current_jump_a: None,
        collision_error_jump_deg: None,
        temperature_warn_c: None,
        temperature_derate_c: None,
        temperature_stop_c: None,
        derate: 1.0,
        runaway: false,
        jump_window_s: JUMP_WINDOW.as_secs_f64(),
    };

    /// The defaults of a WHJ joint of `model` (see the [module docs](self)); a model the
    /// table does not know (`None`, the gripper) is watched for the following-error jump
    /// and its temperature only.
    pub fn whj(model: Option<Model>) -> Self {
        let rated = model.and_then(Model::facts).map(|f| f.rated_current_a);
        Self {
            stall_current_a: rated,
            collision_current_jump_a: rated,
            collision_error_jump_deg: Some(DEFAULT_COLLISION_ERROR_JUMP_DEG),
            temperature_warn_c: Some(WHJ_OVER_TEMPERATURE_C - 15.0),
            temperature_derate_c: Some(WHJ_OVER_TEMPERATURE_C - 10.0),
            temperature_stop_c: Some(WHJ_OVER_TEMPERATURE_C - 5.0),
            derate: DEFAULT_DERATE,
            runaway: true,
            ..Self::OFF
        }
    }

    /// The defaults of a wCK servo, from the wCK rows of the models table (a module does
    /// not report its model: the values every row agrees on): its load read as a current
    /// ([`wck_load_a`]); a stall at half the factory over-current threshold (400 mA, A-5:
    /// a servo pushing harder soon trips its own protection and goes passive) for
    /// [`WCK_STALL_TIME_S`] against at least [`WCK_STALL_ERROR_DEG`]; a collision the
    /// following-error jump within [`WCK_JUMP_WINDOW_S`]. A load jump is no collision by
    /// default: the firmware drives its motor at the torque level's full duty on any
    /// error over a few degrees, so the load jumps as much at the start of every move as
    /// against a hand (`collision_current_jump_a` in the robot file turns it on). No
    /// temperature: a wCK reply carries none.
    pub fn wck() -> Self {
        let overload_a = f64::from(robobus_wck::models::overload_default_ma()) / 1e3;
        Self {
            stall_current_a: Some(overload_a / 2.0),
            stall_time_s: WCK_STALL_TIME_S,
            stall_error_deg: WCK_STALL_ERROR_DEG,
            collision_error_jump_deg: Some(DEFAULT_COLLISION_ERROR_JUMP_DEG),
            jump_window_s: WCK_JUMP_WINDOW_S,
            ..Self::OFF
        }
    }

    /// These limits for a joint read every `period` (a played wCK motion reads each of its
    /// N servos every N × 200 ms): the jump window at least 1.25 periods (two readings in
    /// a row are compared) and a stall at least two periods (it is seen on three
    /// readings).
    #[must_use]
    pub fn for_reading_period(self, period: Duration) -> Self {
        let p = period.as_secs_f64();
        Self {
            jump_window_s: self.jump_window_s.max(1.25 * p),
            stall_time_s: self.stall_time_s.max(2.0 * p),
            ..self
        }
    }

    /// These limits with the robot file's `overrides` for the joint (all of them off
    /// when it says `enabled = false`).
    #[must_use]
    pub fn with(self, overrides: Option<&Overrides>) -> Self {
        let Some(o) = overrides else { return self };
        if o.enabled == Some(false) {
            return Self::OFF;
        }
        Self {
            stall_current_a: o.stall_current_a.or(self.stall_current_a),
            stall_time_s: o.stall_time_s.unwrap_or(self.stall_time_s),
            stall_error_deg: o.stall_error_deg.unwrap_or(self.stall_error_deg),
            collision_current_jump_a: o.collision_current_jump_a.or(self.collision_current_jump_a),
            collision_error_jump_deg: o.collision_error_jump_deg.or(self.collision_error_jump_deg),
            temperature_warn_c: o.temperature_warn_c.or(self.temperature_warn_c),
            temperature_derate_c: o.temperature_derate_c.or(self.temperature_derate_c),
            temperature_stop_c: o.temperature_stop_c.or(self.temperature_stop_c),
            derate: o.derate.unwrap_or(self.derate),
            runaway: self.runaway,
            jump_window_s: self.jump_window_s,
        }
    }
}

/// A joint's protection in the robot file (`[joints.protection]`): any of the
/// [`Limits`] instead of the default, or `enabled = false` to turn the joint's
/// protection off. Each value is checked ([`Overrides::check`]).
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Overrides {
    /// `false`: no check on this joint (default true).
    pub enabled: Option<bool>,
    /// The current of a stall, A (0.01..=100).
    pub stall_current_a: Option<f64>,
    /// How long a stall lasts before the stop, s (0.02..=10).
    pub stall_time_s: Option<f64>,
    /// The least following error of a stall, degrees (0.1..=90).
    pub stall_error_deg: Option<f64>,
    /// A current rise that is a collision, A (0.01..=100).
    pub collision_current_jump_a: Option<f64>,
    /// A following-error growth that is a collision, degrees (0.1..=90).
    pub collision_error_jump_deg: Option<f64>,
    /// The temperature of a warning, °C (20..=150).
    pub temperature_warn_c: Option<f64>,
    /// The temperature from which the joint is derated, °C (20..=150).
    pub temperature_derate_c: Option<f64>,
    /// The temperature of a stop, °C (20..=150).
    pub temperature_stop_c: Option<f64>,
    /// The share of its `max_velocity` a derated joint keeps (0.05..=1).
    pub derate: Option<f64>,
}

impl Overrides {
    /// Each value's range, by the field's name.
    pub const RANGES: [(&'static str, f64, f64, &'static str); 9] = [
        ("stall_current_a", 0.01, 100.0, "A"),
        ("stall_time_s", 0.02, 10.0, "s"),
        ("stall_error_deg", 0.1, 90.0, "°"),
        ("collision_current_jump_a", 0.01, 100.0, "A"),
        ("collision_error_jump_deg", 0.1, 90.0, "°"),
        ("temperature_warn_c", 20.0, 150.0, "°C"),
        ("temperature_derate_c", 20.0, 150.0, "°C"),
        ("temperature_stop_c", 20.0, 150.0, "°C"),
        ("derate", 0.05, 1.0, ""),
    ];

    fn values(&self) -> [Option<f64>; 9] {
        [
            self.stall_current_a,
            self.stall_time_s,
            self.stall_error_deg,
            self.collision_current_jump_a,
            self.collision_error_jump_deg,
            self.temperature_warn_c,
            self.temperature_derate_c,
            self.temperature_stop_c,
            self.derate,
        ]
    }

    /// Checks every value against its range, and that the temperatures of the limits
    /// `with` these overrides rise from warning to derating to stop. The error is the
    /// field, the value and what is allowed.
    pub fn check(&self, with: Limits) -> Result<(), (&'static str, String, String)> {
        for ((field, lo, hi, unit), v) in Self::RANGES.iter().zip(self.values()) {
            if let Some(v) = v
                && !(v.is_finite() && (*lo..=*hi).contains(&v))
            {
                return Err((field, v.to_string(), format!("{lo}..={hi} {unit}")));
            }
        }
        let l = with.with(Some(self));
        let temps = [
            ("temperature_warn_c", l.temperature_warn_c),
            ("temperature_derate_c", l.temperature_derate_c),
            ("temperature_stop_c", l.temperature_stop_c),
        ];
        for pair in temps.windows(2) {
            if let [(low_name, Some(low)), (name, Some(high))] = pair
                && high < low
            {
                return Err((
                    name,
                    high.to_string(),
                    format!("at least {low_name} ({low} °C): warning <= derating <= stop"),
                ));
            }
        }
        Ok(())
    }
}

/// Which check found a fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Check {
    /// A joint pushing against something that does not give.
    Stall,
    /// A jump of the current or of the following error.
    Collision,
    /// The temperature.
    Thermal,
    /// A joint driven in effort turning faster than its `max_velocity` (what it pushed
    /// against gave way, or nothing holds it).
    Speed,
}

/// What a fault makes the operation do.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Action {
    /// Go on; the fault is reported.
    Warn,
    /// Go on with the joint's speed held to its `derate` share.
    Derate,
    /// Stop every joint of the operation in its safe state.
    Stop,
}

/// A protection event: which joint, what was measured against which limit, when, and
/// what it made the operation do.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct Fault {
    /// The joint, by its name in the robot file.
    pub joint: String,
    /// The check.
    pub check: Check,
    /// The quantity measured: `current_a`, `current_jump_a`, `following_error_jump_deg`,
    /// `speed_deg_s` or `temperature_c`.
    pub quantity: &'static str,
    /// Its value.
    pub value: f64,
    /// The limit it reached.
    pub limit: f64,
    /// When, s since the operation's start.
    pub at_s: f64,
    /// What it made the operation do.
    pub action: Action,
}

impl fmt::Display for Fault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (what, unit) = match self.quantity {
            "current_a" => ("current", "A"),
            "current_jump_a" => ("current jump", "A"),
            "following_error_jump_deg" => ("following-error jump", "°"),
            "speed_deg_s" => ("speed", "°/s"),
            _ => ("temperature", "°C"),
        };
        let check = match self.check {
            Check::Stall => "stall",
            Check::Collision => "collision",
            Check::Thermal => "thermal",
            Check::Speed => "speed",
        };
        let action = match self.action {
            Action::Warn => "warning",
            Action::Derate => "derated",
            Action::Stop => "stopped in the safe state",
        };
        write!(
            f,
            "{joint}: {check} protection: {what} {value:.2} {unit} reached the limit {limit} \
             {unit} at {at:.3} s; {action}",
            joint = self.joint,
            value = self.value,
            limit = self.limit,
            at = self.at_s,
        )?;
        if self.check == Check::Stall {
            write!(f, " (the joint did not move as commanded meanwhile)")?;
        }
        Ok(())
    }
}

/// One joint's readings at an instant; `None`: not read (that check waits).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    /// When it was read.
    pub at: Instant,
    /// Where the joint reported itself, degrees.
    pub position_deg: Option<f64>,
    /// The following error: the distance from where the joint reported itself to the
    /// target it was sent before, degrees.
    pub error_deg: Option<f64>,
    /// That target, degrees (a jump of the error is counted beyond the target's own
    /// move).
    pub target_deg: Option<f64>,
    /// The current, A.
    pub current_a: Option<f64>,
    /// The temperature, °C.
    pub temperature_c: Option<f64>,
}

impl Reading {
    /// A reading at `at` with nothing read yet.
    pub const fn at(at: Instant) -> Self {
        Self {
            at,
            position_deg: None,
            error_deg: None,
            target_deg: None,
            current_a: None,
            temperature_c: None,
        }
    }
}

/// How a joint not sent positions is driven: what its readings are compared with
/// ([`Monitor::feed_driven`]; there is no following error to watch).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Drive {
    /// In velocity (a WHJ joint's speed mode): the speed it was sent before the reading,
    /// degrees a second. A stall is its current at `stall_current_a` while it turns at
    /// less than [`STALL_SPEED_SHARE`] of that speed, for `stall_time_s`; a collision is
    /// a jump of the current.
    Velocity {
        /// The commanded speed, °/s.
        commanded_deg_s: f64,
    },
    /// In effort (a WHJ joint's current mode): its current is what it was sent, so
    /// neither its level nor a jump is a fault; it is stopped when it turns faster than
    /// `max_deg_s` (its `max_velocity`; [`Limits::runaway`], on for a WHJ joint).
    Effort {
        /// The joint's `max_velocity`, °/s.
        max_deg_s: f64,
    },
}

/// Under velocity, a joint pushing with a stall current is stalled while it turns at
/// less than this share of its commanded speed.
pub const STALL_SPEED_SHARE: f64 = 0.5;

/// Under velocity, the least commanded speed a stall is looked for at, °/s (a joint
/// told to stand still and holding against a load is not stalled).
pub const STALL_MIN_COMMAND_DEG_S: f64 = 1.0;

/// What the monitor keeps of one joint.
#[derive(Debug, Clone)]
struct Watch {
    name: String,
    limits: Limits,
    /// The last current and following error, with their instants.
    last_current: Option<(Instant, f64)>,
    last_error: Option<(Instant, f64, Option<f64>)>,
    /// A stall under way: since when, and the following error and the position it
    /// started with.
    stall: Option<(Instant, f64, Option<f64>)>,
    /// The thermal action in force (`None`: below the warning).
    thermal: Option<Action>,
    stopped: bool,
}

/// The protection of an operation's joints (see the [module docs](self)).
#[derive(Debug, Clone)]
pub struct Monitor {
    start: Instant,
    joints: Vec<Watch>,
}

impl Monitor {
    /// A monitor of `joints` (name and limits, by the operation's index), started at
    /// `start` (faults give their time since then).
    pub fn new(start: Instant, joints: Vec<(String, Limits)>) -> Self {
        Self {
            start,
            joints: joints
                .into_iter()
                .map(|(name, limits)| Watch {
                    name,
                    limits,
                    last_current: None,
                    last_error: None,
                    stall: None,
                    thermal: None,
                    stopped: false,
                })
                .collect(),
        }
    }

    /// Replaces joint `index`'s limits (its model became known), its watch afresh.
    pub fn set_limits(&mut self, index: usize, limits: Limits) {
        if let Some(w) = self.joints.get_mut(index) {
            *w = Watch {
                name: std::mem::take(&mut w.name),
                limits,
                last_current: None,
                last_error: None,
                stall: None,
                thermal: None,
                stopped: false,
            };
        }
    }

    /// The limits of joint `index`.
    pub fn limits(&self, index: usize) -> Option<&Limits> {
        self.joints.get(index).map(|w| &w.limits)
    }

    /// The share of its speed joint `index` keeps: its `derate` while derated, else 1.
    pub fn speed_share(&self, index: usize) -> f64 {
        self.joints.get(index).map_or(1.0, |w| {
            if w.thermal >= Some(Action::Derate) {
                w.limits.derate
            } else {
                1.0
            }
        })
    }

    /// Feeds joint `index`'s reading: the new events it makes, the most severe first
    /// (none past a stop, which is reported once; nothing for an index past the joints).
    pub fn feed(&mut self, index: usize, r: &Reading) -> Vec<Fault> {
        let start = self.start;
        let Some(watch) = self.joints.get_mut(index) else {
            return Vec::new();
        };
        if watch.stopped {
            return Vec::new();
        }
        let at_s = r.at.saturating_duration_since(start).as_secs_f64();
        let mut out = watch.collisions(r, at_s);
        out.extend(watch.stall(r, at_s));
        out.extend(watch.thermal(r, at_s));
        if let Some(i) = r.current_a {
            watch.last_current = Some((r.at, i));
        }
        if let Some(e) = r.error_deg {
            watch.last_error = Some((r.at, e, r.target_deg));
        }
        Self::ordered(watch, out)
    }

    /// Feeds joint `index`'s reading while it is driven in velocity or effort (`drive`),
    /// with its measured speed (°/s; `None`: not read): the new events it makes, as
    /// [`feed`](Self::feed) does. The reading's following error is not looked at; its
    /// current and temperature are (see [`Drive`]).
    pub fn feed_driven(
        &mut self,
        index: usize,
        r: &Reading,
        speed_deg_s: Option<f64>,
        drive: Drive,
    ) -> Vec<Fault> {
        let start = self.start;
        let Some(watch) = self.joints.get_mut(index) else {
            return Vec::new();
        };
        if watch.stopped {
            return Vec::new();
        }
        let at_s = r.at.saturating_duration_since(start).as_secs_f64();
        let plain = Reading {
            error_deg: None,
            target_deg: None,
            ..*r
        };
        let mut out = Vec::new();
        match drive {
            Drive::Velocity { commanded_deg_s } => {
                out.extend(watch.collisions(&plain, at_s));
                out.extend(watch.speed_stall(&plain, speed_deg_s, commanded_deg_s, at_s));
                if let Some(i) = r.current_a {
                    watch.last_current = Some((r.at, i));
                }
            }
            Drive::Effort { max_deg_s } => {
                watch.stall = None;
                watch.last_current = None;
                if let Some(v) = speed_deg_s
                    && watch.limits.runaway
                    && v.abs() >= max_deg_s
                {
                    out.push(watch.fault(
                        Check::Speed,
                        "speed_deg_s",
                        (v.abs(), max_deg_s),
                        at_s,
                        Action::Stop,
                    ));
                }
            }
        }
        watch.last_error = None;
        out.extend(watch.thermal(&plain, at_s));
        Self::ordered(watch, out)
    }

    /// The events most severe first; a stop alone, and the joint stopped.
    fn ordered(watch: &mut Watch, mut out: Vec<Fault>) -> Vec<Fault> {
        out.sort_by_key(|f| std::cmp::Reverse(f.action));
        if out.first().is_some_and(|f| f.action == Action::Stop) {
            watch.stopped = true;
            out.truncate(1);
        }
        out
    }
}

impl Watch {
    fn fault(
        &self,
        check: Check,
        quantity: &'static str,
        (value, limit): (f64, f64),
        at_s: f64,
        action: Action,
    ) -> Fault {
        Fault {
            joint: self.name.clone(),
            check,
            quantity,
            value,
            limit,
            at_s,
            action,
        }
    }

    /// A jump of the current or of the following error since the reading before.
    fn collisions(&self, r: &Reading, at_s: f64) -> Vec<Fault> {
        let mut out = Vec::new();
        let lim = self.limits;
        let recent = |t: Instant| {
            r.at.saturating_duration_since(t).as_secs_f64() <= lim.jump_window_s + 1e-9
        };
        if let (Some(i), Some(jump)) = (r.current_a, lim.collision_current_jump_a)
            && let Some((_, before)) = self.last_current.filter(|(t, _)| recent(*t))
            && i.abs() - before.abs() >= jump
        {
            let rise = i.abs() - before.abs();
            out.push(self.fault(
                Check::Collision,
                "current_jump_a",
                (rise, jump),
                at_s,
                Action::Stop,
            ));
        }
        if let (Some(e), Some(jump)) = (r.error_deg, lim.collision_error_jump_deg)
            && let Some((_, before, target_before)) = self.last_error.filter(|(t, ..)| recent(*t))
        {
            let moved = r
                .target_deg
                .zip(target_before)
                .map_or(0.0, |(a, b)| (a - b).abs());
            let grown = e.abs() - before.abs() - moved;
            if grown >= jump {
                out.push(self.fault(
                    Check::Collision,
                    "following_error_jump_deg",
                    (grown, jump),
                    at_s,
                    Action::Stop,
                ));
            }
        }
        out
    }

    /// A high current while the following error does not shrink and the joint does not
    /// move.
    fn stall(&mut self, r: &Reading, at_s: f64) -> Option<Fault> {
        let lim = self.limits;
        let (i, e, stall) = match (r.current_a, r.error_deg, lim.stall_current_a) {
            (Some(i), Some(e), Some(stall)) => (i.abs(), e.abs(), stall),
            _ => return None,
        };
        if i < stall || e < lim.stall_error_deg {
            self.stall = None;
            return None;
        }
        let moved = |p0: Option<f64>| {
            p0.zip(r.position_deg)
                .is_some_and(|(a, b)| (a - b).abs() >= lim.stall_error_deg)
        };
        match self.stall {
            Some((since, e0, p0)) if !(e < 0.9 * e0 || moved(p0)) => {
                let held = r.at.saturating_duration_since(since).as_secs_f64();
                (held >= lim.stall_time_s)
                    .then(|| self.fault(Check::Stall, "current_a", (i, stall), at_s, Action::Stop))
            }
            _ => {
                self.stall = Some((r.at, e, r.position_deg));
                None
            }
        }
    }

    /// Under velocity: a high current while the joint turns at less than
    /// [`STALL_SPEED_SHARE`] of its commanded speed (see [`Drive::Velocity`]).
    fn speed_stall(
        &mut self,
        r: &Reading,
        speed_deg_s: Option<f64>,
        commanded_deg_s: f64,
        at_s: f64,
    ) -> Option<Fault> {
        let lim = self.limits;
        let (i, v, stall) = match (r.current_a, speed_deg_s, lim.stall_current_a) {
            (Some(i), Some(v), Some(stall)) => (i.abs(), v, stall),
            _ => return None,
        };
        let wanted = commanded_deg_s.abs();
        let along = v * commanded_deg_s.signum();
        if i < stall || wanted < STALL_MIN_COMMAND_DEG_S || along >= STALL_SPEED_SHARE * wanted {
            self.stall = None;
            return None;
        }
        if let Some((since, ..)) = self.stall {
            let held = r.at.saturating_duration_since(since).as_secs_f64();
            (held >= lim.stall_time_s)
                .then(|| self.fault(Check::Stall, "current_a", (i, stall), at_s, Action::Stop))
        } else {
            self.stall = Some((r.at, wanted - along, r.position_deg));
            None
        }
    }

    /// Warning, derating, stop; derating ends 5 K under its temperature.
    fn thermal(&mut self, r: &Reading, at_s: f64) -> Option<Fault> {
        let t = r.temperature_c?;
        let lim = self.limits;
        let levels = [
            (lim.temperature_stop_c, Action::Stop),
            (lim.temperature_derate_c, Action::Derate),
            (lim.temperature_warn_c, Action::Warn),
        ];
        let reached = levels
            .iter()
            .find(|(limit, _)| limit.is_some_and(|c| t >= c))
            .map(|&(limit, a)| (limit.unwrap_or(t), a));
        if let Some((limit, a)) = reached
            && Some(a) > self.thermal
        {
            self.thermal = Some(a);
            return Some(self.fault(Check::Thermal, "temperature_c", (t, limit), at_s, a));
        }
        let cool = |c: Option<f64>| c.is_some_and(|c| t < c - DERATE_HYSTERESIS_K);
        if self.thermal == Some(Action::Derate) && cool(lim.temperature_derate_c) {
            self.thermal = if cool(lim.temperature_warn_c) {
                None
            } else {
                Some(Action::Warn)
            };
        } else if self.thermal == Some(Action::Warn) && cool(lim.temperature_warn_c) {
            self.thermal = None;
        }
        None
    }
}

#[cfg(test)]
mod tests;
