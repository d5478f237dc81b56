//! A robot: named joints on wCK and WHJ buses, described in a TOML file, moved in SI
//! units with host-side safety.
//!
//! - [`RobotConfig`]: the file (buses, joints with ID, offset, direction, soft limits,
//!   speed and acceleration limits, the watchdog timeout and each bus's safe state).
//! - [`Robot::read`] reads every joint; [`Robot::command`] sends every target in one
//!   call per cycle (wCK: one synchronized move per bus when the bus's IDs are
//!   `0..n`, else one move per servo; WHJ: one position servo frame per joint).
//! - Every target is clamped to the soft limits, then speed- and acceleration-limited
//!   ([`RateLimiter`]); what a limit changed is reported ([`LimitEvent`]).
//! - A watchdog thread puts every bus in its [`SafeState`] if [`Robot::command`] is not
//!   called for `watchdog_timeout` (armed by the first command). The same safe stop
//!   runs on drop, on [`Robot::safe_stop`], and from a [`StopHandle`] (a program's own
//!   Ctrl-C handler calls [`StopHandle::interrupt`]; the library installs none). After a
//!   safe stop
//!   commands are refused ([`RobotError::SafeStopped`]) until [`Robot::resume`].
//!
//! Buses of kind `wck`, `whj-udp` and `whj-can` are opened from the file; kinds
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

mod config;
mod safety;
#[cfg(feature = "sim")]
mod simulated;

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
use robobus_whj::WorkMode;
use robobus_whj::units::CurrentScale;

pub use config::{BusConfig, JointConfig, RobotConfig, SafeState};
pub use safety::{LimitEvent, LimitKind, RateLimiter};

use crate::actuator::{
    ActuatorError, ActuatorState, JointLimits, JointMap, WckScale, rpm_to_rad_s, whj_position,
    whj_to_rad,
};
use crate::ops::safe::{SafeDevice, WckServos, WhjJoints};
use crate::ops::whj::ServoLoop;
use crate::wck::{WckBus, WckError};
use crate::whj::{Joint, JointBus, JointBusConfig, WhjError};

/// A byte link a [`Robot`] can hold: any [`ByteLink`] that is `Send` and `Debug`.
pub trait RobotByteLink: ByteLink + Send + fmt::Debug {}

impl<T: ByteLink + Send + fmt::Debug> RobotByteLink for T {}

/// The link type of the wCK buses a [`Robot`] holds (any byte link, boxed).
pub type DynByteLink = Box<dyn RobotByteLink>;

/// Why a robot operation failed.
#[derive(Debug, thiserror::Error)]
pub enum RobotError {
    /// The robot file is not valid TOML or does not fit the format.
    #[error("robot file, line {line}, column {column}: {message}")]
    Parse {
        /// 1-based line (0 if unknown).
        line: usize,
        /// 1-based column (0 if unknown).
        column: usize,
        /// What is wrong (names the field).
        message: String,
    },
    /// A value in the robot description is out of range or inconsistent.
    #[error("{item}: {field} = {value} is invalid; expected {expected}")]
    Invalid {
        /// The joint or bus (`"joint knee"`, `"bus legs"`).
        item: String,
        /// The field.
        field: &'static str,
        /// The value found.
        value: String,
        /// What is allowed.
        expected: String,
    },
    /// The robot file cannot be read.
    #[error("cannot read robot file {path}: {source}")]
    Io {
        /// The path.
        path: String,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// A wCK bus cannot be opened.
    #[error("bus {bus}: {source}")]
    OpenWck {
        /// The bus name.
        bus: String,
        /// The error (names the port).
        #[source]
        source: Box<WckError>,
    },
    /// A WHJ bus or its link cannot be opened.
    #[error("bus {bus}: cannot open {what}: {detail}")]
    OpenWhj {
        /// The bus name.
        bus: String,
        /// What was being opened (`"UDP bus 239.74.163.2:43113"`, `"SocketCAN can0"`).
        what: String,
        /// The error.
        detail: String,
    },
    /// A bus of an `*-external` kind was not supplied to the builder.
    #[error("bus {bus} has kind = \"{kind}\": supply it with RobotBuilder::{method}")]
    MissingBus {
        /// The bus name.
        bus: String,
        /// Its kind.
        kind: &'static str,
        /// The builder method that supplies it.
        method: &'static str,
    },
    /// A bus supplied to the builder is not in the file, or is of the other family.
    #[error("bus {bus}: a {supplied} bus was supplied, but the robot file {found}")]
    WrongBus {
        /// The bus name.
        bus: String,
        /// `"wCK"` or `"WHJ"`.
        supplied: &'static str,
        /// What the file says.
        found: String,
    },
    /// `command` got a different number of targets than there are joints.
    #[error("{got} targets given for {expected} joints ({names}); nothing sent")]
    TargetCount {
        /// Number of joints.
        expected: usize,
        /// Number of targets.
        got: usize,
        /// The joints, in order.
        names: String,
    },
    /// A joint operation failed (names the joint).
    #[error(transparent)]
    Actuator(#[from] ActuatorError),
    /// The robot is in its safe state; commands are refused until [`Robot::resume`].
    #[error("robot is in its safe state ({cause}); nothing sent; call Robot::resume")]
    SafeStopped {
        /// Why it stopped.
        cause: StopCause,
    },
    /// The watchdog thread cannot be started.
    #[error("cannot start the watchdog thread: {0}")]
    Watchdog(String),
}

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
    /// When the stop began.
    pub started: Instant,
    /// How long applying the safe states took (all buses).
    pub applied_in: Duration,
    /// Joints or buses that could not be put in their safe state, with the error.
    pub errors: Vec<String>,
}

/// What [`Robot::command`] sent.
#[derive(Debug, Clone, PartialEq)]
pub struct CommandReport {
    /// The set-point sent to each joint (joint order), rad, at the device's resolution.
    pub sent_rad: Vec<f64>,
    /// Targets that a limit changed.
    pub limited: Vec<LimitEvent>,
}

// ----- internals -----------------------------------------------------------------------

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

#[derive(Debug)]
struct WckSlot {
    name: String,
    bus: WckBus<DynByteLink>,
    torque: TorqueLevel,
    safe: SafeState,
}

#[derive(Debug)]
struct WhjSlot {
    name: String,
    bus: Arc<JointBus>,
    safe: SafeState,
}

#[derive(Debug, Clone, Copy)]
enum Device {
    Wck {
        bus: usize,
        id: ServoId,
        scale: WckScale,
    },
    Whj {
        bus: usize,
        id: JointId,
        map: JointMap,
        current: CurrentScale,
    },
}

#[derive(Debug)]
struct JointSlot {
    name: String,
    device: Device,
    limits: JointLimits,
    limiter: RateLimiter,
}

#[derive(Debug)]
struct Hardware {
    wck: Vec<WckSlot>,
    whj: Vec<WhjSlot>,
    joints: Vec<JointSlot>,
    /// When the previous command cycle ran (or the robot opened / resumed).
    last_cycle: Instant,
}

#[derive(Debug)]
struct Shared {
    hw: Mutex<Hardware>,
    /// The last successful command; `None` until the first (watchdog disarmed).
    last_command: Mutex<Option<Instant>>,
    stopped: Mutex<Option<SafeStopReport>>,
    quit: AtomicBool,
    timeout: Duration,
}

impl Shared {
    /// Puts every bus in its safe state (once; a second call returns the first report).
    fn safe_stop(&self, cause: StopCause) -> SafeStopReport {
        let started = Instant::now();
        let mut hw = lock(&self.hw);
        let mut stopped = lock(&self.stopped);
        if let Some(report) = stopped.as_ref() {
            return report.clone();
        }
        let errors = hw.apply_safe_states();
        let report = SafeStopReport {
            cause,
            started,
            applied_in: started.elapsed(),
            errors,
        };
        if !report.errors.is_empty() {
            tracing::warn!(errors = ?report.errors, "safe stop incomplete");
        }
        *stopped = Some(report.clone());
        *lock(&self.last_command) = None;
        report
    }

    fn watchdog(&self) {
        let poll = (self.timeout / 10).clamp(Duration::from_micros(500), Duration::from_millis(5));
        while !self.quit.load(Ordering::Acquire) {
            std::thread::sleep(poll);
            let last = *lock(&self.last_command);
            if let Some(last) = last {
                let since = last.elapsed();
                if since > self.timeout && lock(&self.stopped).is_none() {
                    tracing::warn!(?since, "watchdog: control loop stalled, safe stop");
                    self.safe_stop(StopCause::Watchdog {
                        since_command: since,
                    });
                }
            }
        }
    }
}

impl Hardware {
    /// Every bus to its safe state through [`SafeState::apply`] (the operations' safe stop
    /// too); the failures, each naming its joint (or the bus, for the wCK break).
    fn apply_safe_states(&mut self) -> Vec<String> {
        let mut errors = Vec::new();
        let name_of = |joints: &[JointSlot], device: SafeDevice| -> Option<String> {
            joints
                .iter()
                .find(|j| match (j.device, device) {
                    (Device::Wck { id, .. }, SafeDevice::Servo(s)) => id.get() == s,
                    (Device::Whj { id, .. }, SafeDevice::Joint(s)) => id.get() == s,
                    _ => false,
                })
                .map(|j| j.name.clone())
        };
        for (b, slot) in self.wck.iter_mut().enumerate() {
            let ids: Vec<ServoId> = self
                .joints
                .iter()
                .filter_map(|j| match j.device {
                    Device::Wck { bus, id, .. } if bus == b => Some(id),
                    _ => None,
                })
                .collect();
            let failed = slot.safe.apply(&mut WckServos {
                bus: &mut slot.bus,
                ids: &ids,
                torque: slot.torque,
            });
            for f in failed {
                let name =
                    name_of(&self.joints, f.device).unwrap_or_else(|| format!("bus {}", slot.name));
                errors.push(format!("{name}: {}: {}", slot.safe.keyword(), f.error));
            }
        }
        for (b, slot) in self.whj.iter().enumerate() {
            let handles: Vec<Joint<'_>> = self
                .joints
                .iter()
                .filter_map(|j| match j.device {
                    Device::Whj { bus, id, .. } if bus == b => Some(slot.bus.joint_unchecked(id)),
                    _ => None,
                })
                .collect();
            let failed = slot.safe.apply(&mut WhjJoints {
                joints: &handles,
                servo: ServoLoop::Position,
            });
            for f in failed {
                let name =
                    name_of(&self.joints, f.device).unwrap_or_else(|| format!("bus {}", slot.name));
                errors.push(format!("{name}: {}: {}", slot.safe.keyword(), f.error));
            }
        }
        errors
    }

    fn read_joint(&mut self, index: usize) -> Result<ActuatorState, ActuatorError> {
        let Some(joint) = self.joints.get(index) else {
            return Err(ActuatorError::NotFinite {
                joint: format!("#{index}"),
                value: f64::NAN,
            });
        };
        let name = &joint.name;
        match joint.device {
            Device::Wck { bus, id, scale } => {
                let slot = &mut self.wck[bus];
                let status = slot
                    .bus
                    .servo(id)
                    .status()
                    .map_err(|source| ActuatorError::Wck {
                        joint: name.clone(),
                        source: Box::new(source),
                    })?;
                Ok(ActuatorState {
                    position_rad: scale.to_rad(status.position),
                    velocity_rad_s: None,
                    current_a: None,
                })
            }
            Device::Whj {
                bus,
                id,
                map,
                current,
            } => {
                let handle = self.whj[bus].bus.joint_unchecked(id);
                let whj = |source| ActuatorError::Whj {
                    joint: name.clone(),
                    source: Box::new(source),
                };
                let status = handle.status().map_err(whj)?;
                let speed = handle.speed().map_err(whj)?;
                Ok(ActuatorState {
                    position_rad: whj_to_rad(map, status.position),
                    velocity_rad_s: Some(map.speed_to_joint(rpm_to_rad_s(speed.rpm()))),
                    current_a: status.current.map(|c| c.milliamps(current) as f64 / 1000.0),
                })
            }
        }
    }

    /// Prepares every WHJ joint for position commands (mode, enable).
    fn enable_whj(&self) -> Result<(), ActuatorError> {
        for joint in &self.joints {
            if let Device::Whj { bus, id, .. } = joint.device {
                let handle = self.whj[bus].bus.joint_unchecked(id);
                let prepare = || -> Result<(), WhjError> {
                    if !handle.is_enabled()? {
                        handle.set_mode(WorkMode::Position)?;
                        handle.enable()?;
                    }
                    Ok(())
                };
                prepare().map_err(|source| ActuatorError::Whj {
                    joint: joint.name.clone(),
                    source: Box::new(source),
                })?;
            }
        }
        Ok(())
    }

    /// Restarts every joint's rate limiter at its measured angle.
    fn reset_limiters(&mut self) -> Result<(), ActuatorError> {
        for i in 0..self.joints.len() {
            let state = self.read_joint(i)?;
            if let Some(joint) = self.joints.get_mut(i) {
                joint.limiter = RateLimiter::new(state.position_rad);
            }
        }
        self.last_cycle = Instant::now();
        Ok(())
    }
}

// ----- builder -------------------------------------------------------------------------

/// Builds a [`Robot`] from a [`RobotConfig`], with buses the program supplies (see
/// [`Robot::builder`]).
#[derive(Debug)]
pub struct RobotBuilder {
    config: RobotConfig,
    wck: BTreeMap<String, WckBus<DynByteLink>>,
    whj: BTreeMap<String, JointBus>,
    error: Option<RobotError>,
}

impl RobotBuilder {
    /// Supplies the wCK bus `name` (any byte link: a pty to the simulator, a
    /// fault-injecting wrapper, a port opened with custom settings). It replaces what the
    /// file says for that bus, but keeps its torque and safe state.
    #[must_use]
    pub fn wck_bus<L: RobotByteLink + 'static>(
        mut self,
        name: impl Into<String>,
        bus: WckBus<L>,
    ) -> Self {
        let name = name.into();
        let config = *bus.config();
        let device = bus.device().to_owned();
        let baud = bus.baud();
        let boxed: DynByteLink = Box::new(bus.into_link());
        match WckBus::new(boxed, baud) {
            Ok(bus) => {
                self.wck
                    .insert(name, bus.with_config(config).with_device_name(device));
            }
            Err(source) => {
                self.error.get_or_insert(RobotError::OpenWck {
                    bus: name,
                    source: Box::new(source),
                });
            }
        }
        self
    }

    /// Supplies the WHJ bus `name` (any frame link: the in-memory bus to the simulator,
    /// a UDP bus, `SocketCAN`). It replaces what the file says for that bus.
    #[must_use]
    pub fn whj_bus(mut self, name: impl Into<String>, bus: JointBus) -> Self {
        self.whj.insert(name.into(), bus);
        self
    }

    /// Opens the remaining buses, connects every joint (WHJ: IAP release, identify,
    /// position mode, enable; wCK: a status read), reads every angle and starts the
    /// watchdog.
    pub fn open(mut self) -> Result<Robot, RobotError> {
        if let Some(e) = self.error.take() {
            return Err(e);
        }
        let config = self.config;
        config.validate()?;
        for (name, supplied) in [
            (self.wck.keys().collect::<Vec<_>>(), "wCK"),
            (self.whj.keys().collect::<Vec<_>>(), "WHJ"),
        ]
        .iter()
        .flat_map(|(names, fam)| names.iter().map(move |n| (*n, *fam)))
        {
            let found = match config.buses.get(name) {
                None => "has no such bus".to_owned(),
                Some(b) if b.is_wck() != (supplied == "wCK") => {
                    format!(
                        "says it is a {} bus",
                        if b.is_wck() { "wCK" } else { "WHJ" }
                    )
                }
                Some(_) => continue,
            };
            return Err(RobotError::WrongBus {
                bus: name.clone(),
                supplied,
                found,
            });
        }

        let mut wck_slots = Vec::new();
        let mut whj_slots = Vec::new();
        let mut index: BTreeMap<&str, usize> = BTreeMap::new();
        for (name, bus) in &config.buses {
            let safe = bus.safe_state();
            if bus.is_wck() {
                let wck = match self.wck.remove(name) {
                    Some(b) => b,
                    None => open_wck_bus(name, bus)?,
                };
                let torque = TorqueLevel::new(bus.torque().unwrap_or(2)).map_err(|_| {
                    RobotError::Invalid {
                        item: format!("bus {name}"),
                        field: "torque",
                        value: bus.torque().unwrap_or(2).to_string(),
                        expected: "0..=4".into(),
                    }
                })?;
                index.insert(name, wck_slots.len());
                wck_slots.push(WckSlot {
                    name: name.clone(),
                    bus: wck,
                    torque,
                    safe,
                });
            } else {
                let whj = match self.whj.remove(name) {
                    Some(b) => b,
                    None => open_whj_bus(name, bus, JointBusConfig::default())?,
                };
                index.insert(name, whj_slots.len());
                whj_slots.push(WhjSlot {
                    name: name.clone(),
                    bus: Arc::new(whj),
                    safe,
                });
            }
        }

        let mut joints = Vec::new();
        for j in &config.joints {
            joints.push(build_joint(j, &config, &index, &whj_slots)?);
        }

        let mut hw = Hardware {
            wck: wck_slots,
            whj: whj_slots,
            joints,
            last_cycle: Instant::now(),
        };
        hw.enable_whj()?;
        hw.reset_limiters()?;
        let names = hw.joints.iter().map(|j| j.name.clone()).collect();
        let shared = Arc::new(Shared {
            hw: Mutex::new(hw),
            last_command: Mutex::new(None),
            stopped: Mutex::new(None),
            quit: AtomicBool::new(false),
            timeout: config.watchdog(),
        });
        let dog = Arc::clone(&shared);
        let watchdog = std::thread::Builder::new()
            .name("robot-watchdog".into())
            .spawn(move || dog.watchdog())
            .map_err(|e| RobotError::Watchdog(e.to_string()))?;
        Ok(Robot {
            shared,
            watchdog: Some(watchdog),
            names,
            keep: Vec::new(),
        })
    }
}

/// Resolves one joint of the file: its device, map and limits (WHJ: connects it).
fn build_joint(
    j: &JointConfig,
    config: &RobotConfig,
    index: &BTreeMap<&str, usize>,
    whj_slots: &[WhjSlot],
) -> Result<JointSlot, RobotError> {
    let map = j.map();
    let limits = JointLimits {
        min_rad: j.limits[0],
        max_rad: j.limits[1],
        max_velocity_rad_s: j.max_velocity,
        max_acceleration_rad_s2: j.max_acceleration,
    };
    let bus = index.get(j.bus.as_str()).copied().unwrap_or(0);
    let invalid = |field: &'static str, value: String, expected: String| RobotError::Invalid {
        item: format!("joint {}", j.name),
        field,
        value,
        expected,
    };
    let device = if config.buses.get(&j.bus).is_some_and(BusConfig::is_wck) {
        let id = ServoId::new(j.id).map_err(|e| invalid("id", j.id.to_string(), e.to_string()))?;
        Device::Wck {
            bus,
            id,
            scale: j.wck_scale(),
        }
    } else {
        let id = JointId::new(j.id).map_err(|e| invalid("id", j.id.to_string(), e.to_string()))?;
        let slot = whj_slots
            .get(bus)
            .ok_or_else(|| invalid("bus", j.bus.clone(), "a WHJ bus".into()))?;
        let whj = |source| ActuatorError::Whj {
            joint: j.name.clone(),
            source: Box::new(source),
        };
        let handle = slot.bus.joint(id).map_err(whj)?;
        let current = handle.identity().map_err(whj)?.current_scale();
        Device::Whj {
            bus,
            id,
            map,
            current,
        }
    };
    Ok(JointSlot {
        name: j.name.clone(),
        device,
        limits,
        limiter: RateLimiter::new(0.0),
    })
}

/// Opens the wCK bus `name` of a robot file on its serial port, without a [`Robot`]: no
/// watchdog and no safe stop on drop, for tools that only read (such as a monitor).
///
/// # Errors
///
/// [`RobotError::Invalid`] for a baud rate the modules do not have,
/// [`RobotError::OpenWck`] when the port cannot be opened, [`RobotError::MissingBus`]
/// for a `wck-external` bus (the program supplies it), [`RobotError::Invalid`] (field
/// `kind`) for a WHJ bus.
pub fn open_wck_bus(name: &str, bus: &BusConfig) -> Result<WckBus<DynByteLink>, RobotError> {
    match bus {
        #[cfg(unix)]
        BusConfig::Wck { port, baud, .. } => {
            let rate = BaudRate::from_bits_per_second(*baud).map_err(|e| RobotError::Invalid {
                item: format!("bus {name}"),
                field: "baud",
                value: baud.to_string(),
                expected: format!("a wCK rate ({e})"),
            })?;
            let open = WckBus::open(port, rate).map_err(|source| RobotError::OpenWck {
                bus: name.to_owned(),
                source: Box::new(source),
            })?;
            let config = *open.config();
            let boxed: DynByteLink = Box::new(open.into_link());
            Ok(WckBus::new(boxed, rate)
                .map_err(|source| RobotError::OpenWck {
                    bus: name.to_owned(),
                    source: Box::new(source),
                })?
                .with_config(config)
                .with_device_name(port.clone()))
        }
        BusConfig::WckExternal { .. } => Err(RobotError::MissingBus {
            bus: name.to_owned(),
            kind: "wck-external",
            method: "wck_bus",
        }),
        other => Err(RobotError::Invalid {
            item: format!("bus {name}"),
            field: "kind",
            value: other.kind().to_owned(),
            expected: "a wCK bus (wck)".into(),
        }),
    }
}

/// Opens the WHJ bus `name` of a robot file (`whj-udp` or `whj-can`) with `config`,
/// without a [`Robot`]: no joint is enabled, no watchdog and no safe stop on drop, for
/// tools that only read (such as a monitor).
///
/// # Errors
///
/// [`RobotError::OpenWhj`] when the link cannot be opened, [`RobotError::MissingBus`] for
/// a `whj-external` bus (the program supplies it), [`RobotError::Invalid`] (field `kind`)
/// for a wCK bus.
pub fn open_whj_bus(
    name: &str,
    bus: &BusConfig,
    config: JointBusConfig,
) -> Result<JointBus, RobotError> {
    let fail = |what: String, detail: String| RobotError::OpenWhj {
        bus: name.to_owned(),
        what,
        detail,
    };
    match bus {
        #[cfg(unix)]
        BusConfig::WhjUdp { group, port, .. } => {
            let mut cfg = robobus_link::UdpBusConfig::default();
            if let Some(g) = group {
                cfg.group = *g;
            }
            if let Some(p) = port {
                cfg.port = *p;
            }
            let what = format!("UDP bus {}:{}", cfg.group, cfg.port);
            let link =
                robobus_link::UdpBus::open(&cfg).map_err(|e| fail(what.clone(), e.to_string()))?;
            JointBus::open_with(link, config).map_err(|e| fail(what, e.to_string()))
        }
        #[cfg(target_os = "linux")]
        BusConfig::WhjCan { iface, .. } => {
            let what = format!("SocketCAN {iface}");
            let link = robobus_link::SocketCanLink::open(iface)
                .map_err(|e| fail(what.clone(), e.to_string()))?;
            JointBus::open_with(link, config).map_err(|e| fail(what, e.to_string()))
        }
        BusConfig::WhjExternal { .. } => Err(RobotError::MissingBus {
            bus: name.to_owned(),
            kind: "whj-external",
            method: "whj_bus",
        }),
        other => Err(RobotError::Invalid {
            item: format!("bus {name}"),
            field: "kind",
            value: other.kind().to_owned(),
            expected: "a WHJ bus (whj-udp or whj-can)".into(),
        }),
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
        (0..hw.joints.len())
            .map(|i| hw.read_joint(i).map_err(RobotError::from))
            .collect()
    }

    /// Sends one cycle of targets (rad, joint order) and feeds the watchdog.
    ///
    /// Each target is clamped to the joint's soft limits, then followed at no more than
    /// its `max_velocity` / `max_acceleration` over the time since the previous call
    /// (at most the watchdog timeout); changed targets are reported in
    /// [`CommandReport::limited`]. A non-finite target or a wrong count is refused
    /// before anything is sent.
    pub fn command(&mut self, targets: &[f64]) -> Result<CommandReport, RobotError> {
        if targets.len() != self.names.len() {
            return Err(RobotError::TargetCount {
                expected: self.names.len(),
                got: targets.len(),
                names: self.names.join(", "),
            });
        }
        if let Some((name, &value)) = self.names.iter().zip(targets).find(|(_, v)| !v.is_finite()) {
            return Err(ActuatorError::NotFinite {
                joint: name.clone(),
                value,
            }
            .into());
        }
        let mut hw = lock(&self.shared.hw);
        if let Some(report) = lock(&self.shared.stopped).as_ref() {
            return Err(RobotError::SafeStopped {
                cause: report.cause,
            });
        }
        let now = Instant::now();
        let dt = now
            .duration_since(hw.last_cycle)
            .min(self.shared.timeout)
            .as_secs_f64();
        let reach = hw.step_reach()?;
        let mut limited = Vec::new();
        let mut setpoints = Vec::with_capacity(targets.len());
        for ((joint, &target), reach) in hw.joints.iter_mut().zip(targets).zip(reach) {
            let (clamped, was_clamped) = joint.limits.clamp(target);
            if was_clamped {
                limited.push(LimitEvent {
                    joint: joint.name.clone(),
                    kind: LimitKind::Position,
                    requested_rad: target,
                    limited_rad: clamped,
                });
            }
            let set = joint
                .limiter
                .step(clamped, dt, &joint.limits)
                .clamp(joint.limits.min_rad, joint.limits.max_rad);
            if (set - clamped).abs() > 1e-12 {
                limited.push(LimitEvent {
                    joint: joint.name.clone(),
                    kind: LimitKind::Motion,
                    requested_rad: clamped,
                    limited_rad: set,
                });
            }
            let mut set = set;
            if let Some((lo, hi)) = reach
                && !(lo..=hi).contains(&set)
            {
                let held = set.clamp(lo, hi);
                limited.push(LimitEvent {
                    joint: joint.name.clone(),
                    kind: LimitKind::Step,
                    requested_rad: set,
                    limited_rad: held,
                });
                joint.limiter = RateLimiter::new(held);
                set = held;
            }
            setpoints.push(set);
        }
        let sent_rad = hw.send(&setpoints)?;
        hw.last_cycle = now;
        *lock(&self.shared.last_command) = Some(Instant::now());
        Ok(CommandReport { sent_rad, limited })
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

    /// Leaves the safe state: re-enables WHJ joints in position mode, restarts every
    /// joint's speed limiting from its measured angle, and disarms the watchdog until
    /// the next [`command`](Self::command).
    pub fn resume(&mut self) -> Result<(), RobotError> {
        let mut hw = lock(&self.shared.hw);
        hw.enable_whj()?;
        hw.reset_limiters()?;
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
        hw.wck
            .iter_mut()
            .find(|s| s.name == name)
            .map(|s| f(&mut s.bus))
    }
}

impl Hardware {
    /// For each WHJ joint, the set-points it accepts now (joint frame, rad): within 80 %
    /// of the bus's step limit of its measured angle (telemetry under 100 ms old, else a
    /// status query); `None` for wCK joints.
    fn step_reach(&self) -> Result<Vec<Option<(f64, f64)>>, RobotError> {
        let telemetry: Vec<_> = self.whj.iter().map(|s| s.bus.telemetry()).collect();
        let mut reach = Vec::with_capacity(self.joints.len());
        for joint in &self.joints {
            let Device::Whj { bus, id, map, .. } = joint.device else {
                reach.push(None);
                continue;
            };
            let (Some(slot), Some(t)) = (self.whj.get(bus), telemetry.get(bus)) else {
                reach.push(None);
                continue;
            };
            let t = t.joint(id);
            let actual = match (t.position, t.updated) {
                (Some(p), Some(at))
                    if slot.bus.now().saturating_duration_since(at)
                        < Duration::from_millis(100) =>
                {
                    p
                }
                _ => {
                    let status = slot.bus.joint_unchecked(id).status().map_err(|source| {
                        ActuatorError::Whj {
                            joint: joint.name.clone(),
                            source: Box::new(source),
                        }
                    })?;
                    status.position
                }
            };
            let at = whj_to_rad(map, actual);
            let step = 0.8 * slot.bus.config().step_limit_deg.to_radians();
            reach.push(Some((at - step, at + step)));
        }
        Ok(reach)
    }

    /// Sends `setpoints` (rad, joint order); returns what was sent at device resolution.
    fn send(&mut self, setpoints: &[f64]) -> Result<Vec<f64>, RobotError> {
        let mut sent = vec![0.0; setpoints.len()];
        // wCK: per bus, one synchronized move if its IDs are exactly 0..n.
        for (b, slot) in self.wck.iter_mut().enumerate() {
            let mut members: Vec<(usize, ServoId, Position)> = Vec::new();
            for (i, joint) in self.joints.iter().enumerate() {
                if let Device::Wck { bus, id, scale } = joint.device
                    && bus == b
                {
                    let rad = setpoints.get(i).copied().unwrap_or(0.0);
                    let position = quantize_within(scale, rad, &joint.limits)
                        .ok_or_else(|| scale.range_error(&joint.name, rad))?;
                    if let Some(s) = sent.get_mut(i) {
                        *s = scale.to_rad(position);
                    }
                    members.push((i, id, position));
                }
            }
            members.sort_by_key(|m| m.1.get());
            let contiguous = members
                .iter()
                .enumerate()
                .all(|(k, m)| usize::from(m.1.get()) == k);
            if contiguous && !members.is_empty() {
                let positions: Vec<Position> = members.iter().map(|m| m.2).collect();
                slot.bus
                    .sync_move(slot.torque, &positions)
                    .map_err(|source| ActuatorError::Wck {
                        joint: format!("bus {} (synchronized move)", slot.name),
                        source: Box::new(source),
                    })?;
            } else {
                for &(i, id, position) in &members {
                    slot.bus
                        .servo(id)
                        .move_to(slot.torque, position)
                        .map_err(|source| ActuatorError::Wck {
                            joint: self.joints[i].name.clone(),
                            source: Box::new(source),
                        })?;
                }
            }
        }
        // WHJ: one position servo frame per joint.
        for (i, joint) in self.joints.iter().enumerate() {
            if let Device::Whj { bus, id, map, .. } = joint.device {
                let rad = setpoints.get(i).copied().unwrap_or(0.0);
                let position = whj_position(&joint.name, map, rad)?;
                self.whj[bus]
                    .bus
                    .joint_unchecked(id)
                    .command_position(position)
                    .map_err(|source| ActuatorError::Whj {
                        joint: joint.name.clone(),
                        source: Box::new(source),
                    })?;
                if let Some(s) = sent.get_mut(i) {
                    *s = whj_to_rad(map, position);
                }
            }
        }
        Ok(sent)
    }
}

/// The wCK step nearest `rad` that lies within the soft limits (the nearest step may be
/// just past a limit; then the neighbour inside is taken).
fn quantize_within(scale: WckScale, rad: f64, limits: &JointLimits) -> Option<Position> {
    let nearest = scale.to_position(rad)?;
    let inside = |p: Position| {
        let r = scale.to_rad(p);
        r >= limits.min_rad - 1e-12 && r <= limits.max_rad + 1e-12
    };
    if inside(nearest) {
        return Some(nearest);
    }
    let raw = nearest.get();
    [raw.checked_sub(1), raw.checked_add(1)]
        .into_iter()
        .flatten()
        .filter_map(|r| Position::new(r).ok())
        .filter(|&p| inside(p))
        .min_by(|&a, &b| {
            (scale.to_rad(a) - rad)
                .abs()
                .total_cmp(&(scale.to_rad(b) - rad).abs())
        })
        .or(Some(nearest))
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
