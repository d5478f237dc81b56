//! A robot: named joints on wCK and WHJ buses, described in a TOML file, moved in SI
//! units with host-side safety.
//!
//! - [`RobotConfig`]: the file (buses, joints with ID, offset, direction, soft limits,
//!   speed and acceleration limits, the watchdog timeout and each bus's safe state).
//! - Each joint is an [`Actuator`](crate::actuator::Actuator) (a wCK servo or a WHJ
//!   joint in SI units): [`Robot::read`] reads every joint through it ([`Robot::read_joint`]
//!   one, an index past the joints being [`RobotError::NoSuchJoint`]); [`Robot::command`]
//!   sends every target in one call per cycle (wCK: one synchronized move per bus when the
//!   bus's IDs are `0..n`, at the steps the servos' actuators would send, else each
//!   servo's actuator; WHJ: each joint's actuator, one position servo frame).
//! - Every target is clamped to the soft limits, then speed- and acceleration-limited
//!   ([`RateLimiter`]); what a limit changed is reported ([`LimitEvent`]).
//! - The robot runs on its buses' clock ([`Robot::now`], [`Robot::sleep_until`]): the
//!   wall clock on hardware, a simulator's virtual clock in tests (time moves only when
//!   the program waits; the robot keeps the virtual clocks of its buses together), so the
//!   same program runs on both and, on the virtual clock, exactly the same every time.
//! - A watchdog puts every bus in its [`SafeState`] (through [`SafeState::apply`], the
//!   operations' one safe stop) once [`Robot::command`] has not been called for
//!   `watchdog_timeout` (armed by the first command): on the wall clock a thread watches,
//!   on a virtual clock (where time passes only while the program waits) the calls that
//!   read or wait on the clock do ([`Robot::now`], [`Robot::sleep_until`], [`Robot::read`],
//!   [`Robot::command`]), and [`Robot::sleep_until`] stops at the watchdog's deadline, so
//!   it fires at the exact instant. The same safe stop
//!   runs on drop, on [`Robot::safe_stop`], and from a [`StopHandle`] (a program's own
//!   Ctrl-C handler calls [`StopHandle::interrupt`]; the library installs none). After a
//!   safe stop
//!   commands are refused ([`RobotError::SafeStopped`]) until [`Robot::resume`].
//!
//! - The host's protection ([`crate::ops::protect`], on by default; `guard.rs`) watches
//!   every command with what each WHJ joint's servo frame answered (and its temperature
//!   every [`TEMPERATURE_EVERY`]) and each wCK servo's status (load and position, read
//!   every [`WCK_READ_EVERY`]): a stall, a collision, heat or a runaway under effort
//!   brings the joint to rest (disabled where its brake holds it, else held; a wCK servo
//!   passive, or its bus's break) and fails the command ([`RobotError::Protection`]); later commands are refused
//!   ([`RobotError::ProtectionStopped`]) until [`Robot::clear_protection`].
//!   [`Robot::set_protection`] turns it off.
//!
//! Buses of kind `wck`, `whj-udp`, `whj-can` and `whj-bus` (any `--bus` address, such as
//! a serial-line CAN FD adapter's `slcan:COM8`) are opened from the file; kinds
//! `wck-external` / `whj-external` (and any bus the program wants to replace, such as
//! a simulator) are supplied through [`RobotBuilder::wck_bus`] /
//! [`RobotBuilder::whj_bus`].
//!
//! ```
//! # #[cfg(target_os = "linux")] {
//! use robobus::robot::{Robot, RobotConfig};
//! use robobus::wck::WckBus;
//! use robobus_link::{PtyOptions, PtyPair};
//! use robobus_sim::wck::{Bus, BusConfig, Endpoint, Model};
//! use robobus_wck::BaudRate;
//!
//! let config = RobotConfig::from_toml_str(r#"
//!     watchdog_timeout = 0.2
//!     [buses.legs]
//!     kind = "wck-external"
//!     [[joints]]
//!     name = "knee"
//!     bus = "legs"
//!     id = 0
//!     limits = [-0.5, 0.5]      # rad
//!     max_velocity = 3.0        # rad/s
//!     max_acceleration = 30.0   # rad/s²
//! "#)?;
//!
//! // A simulated wCK servo behind a pty.
//! let pty = PtyPair::open(&PtyOptions::default())?;
//! let _sim = Endpoint::spawn(
//!     Bus::with_servos(BusConfig::default(), Model::W1108, [0]),
//!     pty.master,
//!     pty.slave_path.clone(),
//! )?;
//! std::thread::sleep(std::time::Duration::from_millis(70));
//!
//! let mut robot = Robot::builder(config)
//!     .wck_bus("legs", WckBus::new(pty.slave, BaudRate::B115200)?)
//!     .open()?;
//! let report = robot.command(&[2.0])?;       // outside the soft limits
//! assert_eq!(report.limited[0].limited_rad, 0.5); // clamped (and reported)
//! assert!(robot.read()?[0].position_rad.abs() < 0.1);
//! # }
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod builder;
pub mod calibration;
mod config;
mod drive;
mod error;
mod guard;
mod hardware;
mod interface;
mod safety;
#[cfg(feature = "sim")]
pub mod simulated;
pub mod trajectory;

use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError, Weak};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use robobus_link::ByteLink;
use robobus_wck::{BaudRate, Position, ServoId, TorqueLevel};
use robobus_whj::JointId;
use robobus_whj::units::CurrentScale;

pub use builder::{RobotBuilder, open_wck_bus, open_whj_bus};
pub use config::{BusConfig, JointConfig, Protection, RobotConfig};
pub use error::RobotError;
pub use guard::{TEMPERATURE_EVERY, WCK_READ_EVERY};
use hardware::{Device, Drive, Hardware, JointSlot, Shared, WckSlot, WhjSlot, lock};
pub(crate) use interface::list as interface_list;
pub use interface::{EffortScale, Interface, WHEEL_LEVELS, WheelSpeeds};
pub use safety::{LimitEvent, LimitKind, RateLimiter};

use crate::actuator::{ActuatorError, ActuatorState, JointLimits, JointMap, WckScale, whj_to_rad};

use crate::ops::SafeState;
use crate::ops::safe::{SafeDevice, WckServos, WhjJoints};
use crate::ops::whj::ServoLoop;
use crate::wck::WckBus;
use crate::whj::{Joint, JointBus, JointBusConfig};

/// A byte link a [`Robot`] can hold: any [`ByteLink`] that is `Send` and `Debug`.
pub trait RobotByteLink: ByteLink + Send + fmt::Debug {}

impl<T: ByteLink + Send + fmt::Debug> RobotByteLink for T {}

/// The link type of the wCK buses a [`Robot`] holds (any byte link, boxed).
pub type DynByteLink = Box<dyn RobotByteLink>;

/// Why the robot went to its safe state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopCause {
    /// No [`Robot::command`] for longer than the watchdog timeout.
    Watchdog {
        /// Time since the last command when the watchdog fired.
        since_command: Duration,
    },
    /// An interrupt (a program's Ctrl-C / SIGTERM handler: [`StopHandle::interrupt`]).
    Interrupt,
    /// [`Robot::safe_stop`] or [`StopHandle::safe_stop`].
    Requested,
    /// The [`Robot`] was dropped.
    Drop,
}

impl fmt::Display for StopCause {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Watchdog { since_command } => write!(
                f,
                "watchdog: no command for {:.1} ms",
                since_command.as_secs_f64() * 1e3
            ),
            Self::Interrupt => f.write_str("interrupted (Ctrl-C)"),
            Self::Requested => f.write_str("safe stop requested"),
            Self::Drop => f.write_str("robot dropped"),
        }
    }
}

/// What a safe stop did.
#[derive(Debug, Clone, PartialEq)]
pub struct SafeStopReport {
    /// Why.
    pub cause: StopCause,
    /// When the stop began ([`Robot::now`]'s clock).
    pub started: Instant,
    /// How long applying the safe states took (all buses).
    pub applied_in: Duration,
    /// Joints or buses that could not be put in their safe state, with the error.
    pub errors: Vec<String>,
}

/// What [`Robot::command`] (and [`Robot::command_velocity`], [`Robot::command_effort`],
/// [`Robot::command_targets`]) sent.
#[derive(Debug, Clone, PartialEq)]
pub struct CommandReport {
    /// The set-point sent to each joint (joint order) at the device's resolution, in the
    /// unit of its interface: rad, rad/s (a wCK servo's: the speed of the wheel level
    /// sent), N·m (the current sent times the torque constant).
    pub sent_rad: Vec<f64>,
    /// Each joint's interface (joint order): the unit of `sent_rad`.
    pub interfaces: Vec<Interface>,
    /// Targets that a limit changed.
    pub limited: Vec<LimitEvent>,
}

/// One joint's target in one of its interfaces ([`Robot::command_targets`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Target {
    /// An angle, rad.
    Position(f64),
    /// A speed, rad/s.
    Velocity(f64),
    /// A torque, N·m.
    Effort(f64),
}

impl Target {
    /// The target of `interface` with `value` (in its unit).
    pub const fn new(interface: Interface, value: f64) -> Self {
        match interface {
            Interface::Position => Self::Position(value),
            Interface::Velocity => Self::Velocity(value),
            Interface::Effort => Self::Effort(value),
        }
    }

    /// Its interface.
    pub const fn interface(self) -> Interface {
        match self {
            Self::Position(_) => Interface::Position,
            Self::Velocity(_) => Interface::Velocity,
            Self::Effort(_) => Interface::Effort,
        }
    }

    /// Its value, in the interface's unit.
    pub const fn value(self) -> f64 {
        match self {
            Self::Position(v) | Self::Velocity(v) | Self::Effort(v) => v,
        }
    }
}

// ----- the robot -----------------------------------------------------------------------

/// A robot: its buses, its joints in SI units, its safety (see the [module](self)).
///
/// Dropping it puts every bus in its safe state and stops the watchdog.
#[derive(Debug)]
pub struct Robot {
    shared: Arc<Shared>,
    watchdog: Option<JoinHandle<()>>,
    names: Vec<String>,
    /// What the robot's buses need alive (the in-process simulators of
    /// [`Robot::simulated`]), dropped after the robot's own safe stop. Only held: without
    /// the `sim` feature nothing is put here.
    #[cfg_attr(not(feature = "sim"), allow(dead_code))]
    keep: Vec<Box<dyn std::fmt::Debug + Send + Sync>>,
}

impl Robot {
    /// A builder for `config`, to supply buses before opening.
    pub fn builder(config: RobotConfig) -> RobotBuilder {
        RobotBuilder {
            config,
            wck: BTreeMap::new(),
            whj: BTreeMap::new(),
            error: None,
        }
    }

    /// Opens the robot described by `config` (every bus from the file).
    pub fn open(config: RobotConfig) -> Result<Self, RobotError> {
        Self::builder(config).open()
    }

    /// Reads the robot file at `path` and opens the robot.
    pub fn from_toml_file(path: impl AsRef<Path>) -> Result<Self, RobotError> {
        Self::open(RobotConfig::from_toml_file(path)?)
    }

    /// Parses `text` as a robot file and opens the robot.
    pub fn from_toml_str(text: &str) -> Result<Self, RobotError> {
        Self::open(RobotConfig::from_toml_str(text)?)
    }

    /// The joint names, in the order of [`read`](Self::read) and
    /// [`command`](Self::command).
    pub fn joint_names(&self) -> &[String] {
        &self.names
    }

    /// The index of joint `name`.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// The soft limits of every joint (joint order).
    pub fn limits(&self) -> Vec<JointLimits> {
        lock(&self.shared.hw)
            .joints
            .iter()
            .map(|j| j.limits)
            .collect()
    }

    /// The watchdog timeout.
    pub fn watchdog_timeout(&self) -> Duration {
        self.shared.timeout
    }

    /// Reads every joint (joint order): angle (rad), speed (rad/s, WHJ) and current (A,
    /// WHJ). Works in the safe state too; does not feed the watchdog.
    pub fn read(&mut self) -> Result<Vec<ActuatorState>, RobotError> {
        let mut hw = lock(&self.shared.hw);
        self.shared.tick(&mut hw);
        let states = (0..hw.joints.len())
            .map(|i| Ok(hw.actuator(i)?.state()?))
            .collect();
        self.shared.tick(&mut hw);
        states
    }

    /// Reads joint `index` (the order of [`joint_names`](Self::joint_names); see
    /// [`read`](Self::read)). An index past the last joint is
    /// [`RobotError::NoSuchJoint`].
    pub fn read_joint(&mut self, index: usize) -> Result<ActuatorState, RobotError> {
        let mut hw = lock(&self.shared.hw);
        self.shared.tick(&mut hw);
        let state = hw.actuator(index).and_then(|mut a| Ok(a.state()?));
        self.shared.tick(&mut hw);
        state
    }

    /// Sends one cycle of targets (rad, joint order) and feeds the watchdog.
    ///
    /// Each target is clamped to the joint's soft limits, then followed at no more than
    /// its `max_velocity` / `max_acceleration` over the time since the previous call
    /// (at most the watchdog timeout, on the robot's clock); changed targets are reported
    /// in [`CommandReport::limited`]. A non-finite target or a wrong count is refused
    /// before anything is sent, and so is a joint not on its position interface
    /// ([`RobotError::WrongInterface`]); a command that comes a watchdog timeout or more
    /// after the previous one finds the robot safe-stopped ([`RobotError::SafeStopped`]).
    pub fn command(&mut self, targets: &[f64]) -> Result<CommandReport, RobotError> {
        self.command_all(Interface::Position, targets)
    }

    /// Sends one cycle of speeds (rad/s, joint order; every joint on its velocity
    /// interface, [`set_interface`](Self::set_interface)) and feeds the watchdog, as
    /// [`command_targets`](Self::command_targets) does.
    pub fn command_velocity(&mut self, rad_s: &[f64]) -> Result<CommandReport, RobotError> {
        self.command_all(Interface::Velocity, rad_s)
    }

    /// Sends one cycle of efforts (N·m, joint order; every joint on its effort interface,
    /// [`set_interface`](Self::set_interface)) and feeds the watchdog, as
    /// [`command_targets`](Self::command_targets) does.
    pub fn command_effort(&mut self, nm: &[f64]) -> Result<CommandReport, RobotError> {
        self.command_all(Interface::Effort, nm)
    }

    fn command_all(
        &mut self,
        interface: Interface,
        values: &[f64],
    ) -> Result<CommandReport, RobotError> {
        let targets: Vec<Target> = values.iter().map(|&v| Target::new(interface, v)).collect();
        self.command_targets(&targets)
    }

    /// Sends one cycle of targets, each joint's in the interface it is on (joint order),
    /// and feeds the watchdog: positions as [`command`](Self::command) sends them;
    /// velocities (rad/s) clamped to `max_velocity` and ramped at `max_acceleration`,
    /// never towards a WHJ joint's soft limit faster than it can stop there (a wCK servo's
    /// wheel mode turns without limits), a wCK speed sent as the nearest wheel level
    /// ([`WheelSpeeds`]); efforts (N·m) clamped to `max_effort`, ramped at
    /// `max_effort_rate` and dropped where they push a joint past a soft limit it stands
    /// on, sent as the current of the joint model's torque constant ([`EffortScale`]).
    /// Every limit that acted is in [`CommandReport::limited`].
    ///
    /// Refused before anything is sent: a wrong count, a non-finite target, a target of
    /// an interface its joint is not on ([`RobotError::WrongInterface`]), a speed or an
    /// effort beyond what the device can do ([`RobotError::Target`]: past the top wheel
    /// level, the WHJ model's peak speed or torque), a robot in its safe state.
    #[allow(clippy::too_many_lines)] // the checks, then each interface's limits, then the sends
    pub fn command_targets(&mut self, targets: &[Target]) -> Result<CommandReport, RobotError> {
        if targets.len() != self.names.len() {
            return Err(RobotError::TargetCount {
                expected: self.names.len(),
                got: targets.len(),
                names: self.names.join(", "),
            });
        }
        if let Some((name, target)) = self
            .names
            .iter()
            .zip(targets)
            .find(|(_, t)| t.interface() == Interface::Position && !t.value().is_finite())
        {
            return Err(ActuatorError::NotFinite {
                joint: name.clone(),
                value: target.value(),
            }
            .into());
        }
        let mut hw = lock(&self.shared.hw);
        let now = self.shared.tick(&mut hw);
        if let Some(report) = lock(&self.shared.stopped).as_ref() {
            return Err(RobotError::SafeStopped {
                cause: report.cause,
            });
        }
        if let Some(refused) = hw.guard.refusal() {
            return Err(refused);
        }
        for (i, (joint, target)) in hw.joints.iter().zip(targets).enumerate() {
            if joint.drive.active != target.interface() {
                return Err(RobotError::WrongInterface {
                    joint: joint.name.clone(),
                    asked: target.interface(),
                    active: joint.drive.active,
                });
            }
            hw.check_target(i, target.interface(), target.value())?;
        }
        let dt = now
            .duration_since(hw.last_cycle)
            .min(self.shared.timeout)
            .as_secs_f64();
        let positions = targets.iter().any(|t| t.interface() == Interface::Position);
        let reach = if positions {
            hw.step_reach()?
        } else {
            vec![None; targets.len()]
        };
        let mut limited = Vec::new();
        let mut setpoints = Vec::with_capacity(targets.len());
        let shares: Vec<f64> = (0..targets.len()).map(|i| hw.guard.share(i)).collect();
        for (((joint, target), reach), share) in
            hw.joints.iter_mut().zip(targets).zip(reach).zip(shares)
        {
            let Target::Position(target) = *target else {
                setpoints.push(None);
                continue;
            };
            let mut event = |kind, requested_rad, limited_rad| {
                limited.push(LimitEvent {
                    joint: joint.name.clone(),
                    interface: Interface::Position,
                    kind,
                    requested_rad,
                    limited_rad,
                });
            };
            let (clamped, was_clamped) = joint.limits.clamp(target);
            if was_clamped {
                event(LimitKind::Position, target, clamped);
            }
            // A joint derated for heat moves at its share of max_velocity.
            let derated = JointLimits {
                max_velocity_rad_s: joint.limits.max_velocity_rad_s * share,
                ..joint.limits
            };
            let set = joint
                .limiter
                .step(clamped, dt, &derated)
                .clamp(joint.limits.min_rad, joint.limits.max_rad);
            if (set - clamped).abs() > 1e-12 {
                event(LimitKind::Motion, clamped, set);
            }
            let mut set = set;
            if let Some((lo, hi)) = reach
                && !(lo..=hi).contains(&set)
            {
                let held = set.clamp(lo, hi);
                event(LimitKind::Step, set, held);
                joint.limiter = RateLimiter::new(held);
                set = held;
            }
            setpoints.push(Some(set));
        }
        let mut outs = Vec::new();
        for (i, target) in targets.iter().enumerate() {
            if target.interface() != Interface::Position {
                outs.push((
                    i,
                    hw.plan(i, target.interface(), target.value(), dt, &mut limited)?,
                ));
            }
        }
        let (mut sent_rad, mut sensed) = hw.send(&setpoints)?;
        let frames: Vec<(usize, drive::Out)> = outs.iter().map(|&(i, (out, _))| (i, out)).collect();
        let answers = hw.send_outs(&frames)?;
        for ((i, (_, sent)), answer) in outs.into_iter().zip(answers) {
            if let Some(s) = sent_rad.get_mut(i) {
                *s = sent;
            }
            if let Some(s) = sensed.get_mut(i) {
                *s = answer;
            }
        }
        let interfaces: Vec<Interface> = targets.iter().map(|t| t.interface()).collect();
        let stopped = Self::protect(&mut hw, now, &interfaces, &setpoints, &sensed);
        // The frames went out: the cycle counts, and the watchdog runs from its end.
        hw.last_cycle = now;
        *lock(&self.shared.last_command) = Some(hw.now());
        if let Some(e) = stopped? {
            return Err(e);
        }
        Ok(CommandReport {
            sent_rad,
            interfaces: targets.iter().map(|t| t.interface()).collect(),
            limited,
        })
    }

    /// Feeds what this cycle's frames answered (`sensed`, joint order; a WHJ joint's
    /// temperature read when due) to the host's protection; a joint it stops is brought
    /// to rest through the one guard, and the first stop is the error.
    fn protect(
        hw: &mut Hardware,
        now: Instant,
        interfaces: &[Interface],
        setpoints: &[Option<f64>],
        sensed: &[Option<guard::Sensed>],
    ) -> Result<Option<RobotError>, RobotError> {
        if !hw.guard.on {
            return Ok(None);
        }
        let mut first = None;
        for (i, &interface) in interfaces.iter().enumerate() {
            let Some(joint) = hw.joints.get(i) else {
                continue;
            };
            let set = match interface {
                Interface::Position => setpoints.get(i).copied().flatten().unwrap_or(0.0),
                Interface::Velocity => joint.drive.velocity,
                Interface::Effort => joint.drive.effort,
            };
            let max_rad_s = joint.limits.max_velocity_rad_s;
            let temperature_c = match joint.device {
                Device::Whj { bus, id, .. } if hw.guard.temperature_due(i, now) => {
                    let name = joint.name.clone();
                    let status = hw.whj.get(bus).map(|s| s.bus.joint_unchecked(id).status());
                    match status {
                        Some(Ok(s)) => Some(f64::from(s.temperature.celsius())),
                        Some(Err(source)) => {
                            return Err(ActuatorError::Whj {
                                joint: name,
                                source: Box::new(source),
                            }
                            .into());
                        }
                        None => None,
                    }
                }
                _ => None,
            };
            // A wCK servo's synchronized move has no reply: its status, read when due.
            let answer = match hw.wck_reading(i, now)? {
                Some(read) => Some(read),
                None => sensed.get(i).copied().flatten(),
            };
            if let Some(fault) =
                hw.guard
                    .feed(i, now, interface, answer, temperature_c, (set, max_rad_s))
            {
                let stopped = hw.protection_stop(i);
                first.get_or_insert(RobotError::Protection {
                    fault: Box::new(fault),
                    stopped,
                });
            }
        }
        Ok(first)
    }

    /// Whether the host's protection watches this robot's commands (on when it opens;
    /// the robot file's `[protection]` and `[joints.protection]` set its limits).
    pub fn protection(&self) -> bool {
        lock(&self.shared.hw).guard.on
    }

    /// Turns the host's protection of this robot's commands on or off (on when it
    /// opens). Off, nothing watches a stall, a collision, heat or a runaway under effort:
    /// a command pushing a joint into an obstacle goes on until the joint's own
    /// protection trips. Turning it on starts every joint's watch afresh; a stop already
    /// latched stays until [`clear_protection`](Self::clear_protection).
    pub fn set_protection(&mut self, on: bool) {
        let mut hw = lock(&self.shared.hw);
        if on && !hw.guard.on {
            hw.guard.restart_all();
        }
        hw.guard.on = on;
    }

    /// The host's protection events of this robot's commands so far (warnings,
    /// derating, stops; at most [`MAX_EVENTS`](crate::ops::protect::MAX_EVENTS), the
    /// oldest dropped).
    pub fn protection_events(&self) -> Vec<crate::ops::protect::Fault> {
        lock(&self.shared.hw).guard.events.clone()
    }

    /// The stops the host's protection latched (each joint's, joint order; empty when
    /// none did).
    pub fn protection_stops(&self) -> Vec<crate::ops::protect::Fault> {
        lock(&self.shared.hw)
            .guard
            .stopped
            .iter()
            .flatten()
            .cloned()
            .collect()
    }

    /// Takes commands again after the host's protection stopped joints: each of them
    /// back on its position interface, a WHJ joint whose drive was disabled enabled again
    /// (holding where it stands), its speed limiting restarted at its measured angle and
    /// its watch afresh. Returns the stops cleared (none: nothing done). Call it once the
    /// cause (the obstacle, the heat) is gone.
    pub fn clear_protection(&mut self) -> Result<Vec<crate::ops::protect::Fault>, RobotError> {
        let mut hw = lock(&self.shared.hw);
        self.shared.tick(&mut hw);
        let cleared = hw.clear_protection()?;
        self.shared.tick(&mut hw);
        Ok(cleared)
    }

    /// The interface each joint is commanded in now (joint order; position after opening
    /// and after [`resume`](Self::resume)).
    pub fn interfaces(&self) -> Vec<Interface> {
        lock(&self.shared.hw)
            .joints
            .iter()
            .map(|j| j.drive.active)
            .collect()
    }

    /// The interfaces the robot file gives joint `index` (position first); `None` past the
    /// last joint.
    pub fn available_interfaces(&self, index: usize) -> Option<Vec<Interface>> {
        lock(&self.shared.hw)
            .joints
            .get(index)
            .map(|j| j.drive.interfaces.clone())
    }

    /// Switches joint `index` to `interface`, and leaves it safe there: a WHJ joint's work
    /// mode is changed (the joint takes its angle as its position target and zero speed
    /// and current) and a zero speed or current target follows; a wCK servo enters wheel
    /// mode at level 0 (stopped), or leaves it with a move to where it stands. Its
    /// set-points start at rest (a position one at its measured angle). Asking for the
    /// interface it is on sends nothing.
    ///
    /// Refused, nothing sent: an index past the joints, an interface the robot file does
    /// not give the joint ([`RobotError::NoInterface`]), a robot in its safe state
    /// ([`RobotError::SafeStopped`]), a joint that moves ([`RobotError::Moving`]: its
    /// set-point is not at rest, or a WHJ joint turns faster than 0.05 rad/s). Does not
    /// feed the watchdog.
    pub fn set_interface(&mut self, index: usize, interface: Interface) -> Result<(), RobotError> {
        let mut hw = lock(&self.shared.hw);
        self.shared.tick(&mut hw);
        let Some(joint) = hw.joints.get(index) else {
            return Err(RobotError::NoSuchJoint {
                index,
                names: self.names.join(", "),
            });
        };
        if !joint.drive.interfaces.contains(&interface) {
            return Err(RobotError::NoInterface {
                joint: joint.name.clone(),
                interface,
                has: interface::list(&joint.drive.interfaces),
            });
        }
        if let Some(report) = lock(&self.shared.stopped).as_ref() {
            return Err(RobotError::SafeStopped {
                cause: report.cause,
            });
        }
        if let Some(refused) = hw.guard.refusal() {
            return Err(refused);
        }
        let from = joint.drive.active;
        if from == interface {
            return Ok(());
        }
        let name = joint.name.clone();
        if let Some(why) = hw.moving(index)? {
            return Err(RobotError::Moving {
                joint: name,
                from,
                to: interface,
                why,
            });
        }
        hw.switch(index, interface)?;
        self.shared.tick(&mut hw);
        Ok(())
    }

    /// The robot's clock: the clock of its buses (see the [module](self)). Every instant
    /// the robot reports ([`SafeStopReport::started`]) and every time it measures (the
    /// watchdog, the speed limits) is on it.
    pub fn now(&self) -> Instant {
        self.shared.tick(&mut lock(&self.shared.hw))
    }

    /// Waits until `deadline` on the robot's clock: on the wall clock it sleeps (the
    /// watchdog thread watches meanwhile); on a virtual clock every bus's simulation runs
    /// to `deadline` at once, stopping at the watchdog's deadline on the way if it falls
    /// before (the safe stop then happens at that exact instant). Sends nothing and does
    /// not feed the watchdog.
    pub fn sleep_until(&self, deadline: Instant) {
        loop {
            let mut hw = lock(&self.shared.hw);
            let now = self.shared.tick(&mut hw);
            if now >= deadline {
                return;
            }
            if hw.wall_time() {
                drop(hw);
                std::thread::sleep(deadline.saturating_duration_since(now));
                continue;
            }
            let until = self
                .shared
                .watchdog_due()
                .filter(|due| *due < deadline)
                .unwrap_or(deadline)
                .max(now);
            hw.advance_to(until);
            if hw.now() <= now {
                // No bus could run (a closed bus's clock stands still): nothing to wait for.
                return;
            }
        }
    }

    /// Waits `duration` on the robot's clock ([`sleep_until`](Self::sleep_until)).
    pub fn sleep(&self, duration: Duration) {
        self.sleep_until(self.now() + duration);
    }

    /// Puts every bus in its safe state now (once; later calls return the first
    /// report). Commands are refused until [`resume`](Self::resume).
    pub fn safe_stop(&self) -> SafeStopReport {
        self.shared.safe_stop(StopCause::Requested)
    }

    /// The report of the safe stop the robot is in, if it is in one.
    pub fn safe_stop_report(&self) -> Option<SafeStopReport> {
        lock(&self.shared.stopped).clone()
    }

    /// Whether the robot is in its safe state.
    pub fn is_stopped(&self) -> bool {
        lock(&self.shared.stopped).is_some()
    }

    /// Leaves the safe state: every joint back on its position interface (WHJ joints in
    /// speed or current mode switched to position mode), WHJ joints re-enabled in
    /// position mode, every joint's speed limiting restarted from its measured angle, and
    /// the watchdog disarmed until the next [`command`](Self::command). A joint the host's
    /// protection stopped stays stopped until [`clear_protection`](Self::clear_protection).
    pub fn resume(&mut self) -> Result<(), RobotError> {
        let mut hw = lock(&self.shared.hw);
        hw.back_to_position()?;
        hw.enable_whj()?;
        hw.reset_limiters()?;
        hw.guard.restart_all();
        *lock(&self.shared.stopped) = None;
        *lock(&self.shared.last_command) = None;
        Ok(())
    }

    /// A handle that can safe-stop the robot from another thread or a signal handler.
    pub fn stop_handle(&self) -> StopHandle {
        StopHandle {
            shared: Arc::downgrade(&self.shared),
        }
    }

    /// The WHJ bus `name` (for diagnostics: telemetry, register reads). Commands sent
    /// through it bypass the robot's limits.
    pub fn whj_bus(&self, name: &str) -> Option<Arc<JointBus>> {
        lock(&self.shared.hw)
            .whj
            .iter()
            .find(|s| s.name == name)
            .map(|s| Arc::clone(&s.bus))
    }

    /// Runs `f` on the wCK bus `name` (for diagnostics; the watchdog waits meanwhile).
    /// Commands sent through it bypass the robot's limits.
    pub fn with_wck_bus<R>(
        &self,
        name: &str,
        f: impl FnOnce(&mut WckBus<DynByteLink>) -> R,
    ) -> Option<R> {
        let mut hw = lock(&self.shared.hw);
        let result = hw
            .wck
            .iter_mut()
            .find(|s| s.name == name)
            .map(|s| f(&mut s.bus));
        self.shared.tick(&mut hw);
        result
    }
}

impl Drop for Robot {
    fn drop(&mut self) {
        self.shared.quit.store(true, Ordering::Release);
        if let Some(t) = self.watchdog.take() {
            let _ = t.join();
        }
        self.shared.safe_stop(StopCause::Drop);
    }
}

/// Safe-stops a [`Robot`] from another thread (or a signal handler); does nothing once
/// the robot is gone.
#[derive(Debug, Clone)]
pub struct StopHandle {
    shared: Weak<Shared>,
}

impl StopHandle {
    /// Puts the robot in its safe state ([`StopCause::Requested`]). Returns the report,
    /// or `None` if the robot no longer exists.
    pub fn safe_stop(&self) -> Option<SafeStopReport> {
        self.stop(StopCause::Requested)
    }

    /// Puts the robot in its safe state for an interrupt ([`StopCause::Interrupt`]): what
    /// a program's Ctrl-C / SIGTERM handler calls. The program keeps running, and the
    /// robot's next [`command`](Robot::command) fails with [`RobotError::SafeStopped`].
    pub fn interrupt(&self) -> Option<SafeStopReport> {
        self.stop(StopCause::Interrupt)
    }

    fn stop(&self, cause: StopCause) -> Option<SafeStopReport> {
        self.shared.upgrade().map(|s| s.safe_stop(cause))
    }
}
