//! The station: the long-lived set of open buses a server, a Python session or a bridge
//! holds, with one cheap-to-clone handle type per family.
//!
//! A wCK port is driven by whichever thread holds its lock (one request at a time, in
//! full: a scan or a motion is never interleaved with another request's packets); a WHJ
//! bus is a [`JointBus`], whose own lock and thread do the same. Both handles are
//! `Send + Sync` and clone as one `Arc`. Closing the station (or dropping it) brings every
//! device to its safe state: the wCK bus-wide break, every connected WHJ joint disabled.

pub(crate) mod clock;
pub mod cyclic;
pub mod diagnostics;
pub mod follow;
pub mod handles;
pub mod interfaces;
pub mod jog;
pub mod sampler;

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use robobus_wck::{BaudRate, TorqueLevel};
use robobus_whj::JointId;
use sampler::{RobotJointSample, RobotSampler};

use crate::ops::capture::{Overwrite, capture_byte_link_limited, capture_frame_link_limited};
use crate::ops::safe::{WckServos, WhjJoints};
use crate::ops::whj::ServoLoop;
use crate::ops::{DeviceResult, OpError, SafeState};
use crate::robot::{DynByteLink, RobotConfig};
use crate::wck::WckBus;
use crate::whj::{JointBus, JointBusConfig};

/// A wCK port of a station (clones share the port).
#[derive(Debug, Clone)]
pub struct WckPort(Arc<WckInner>);

#[derive(Debug)]
struct WckInner {
    name: String,
    bus: Mutex<WckBus<DynByteLink>>,
    verify_reads: Option<bool>,
}

impl WckPort {
    /// A port over an open bus, named `name` in requests and reports.
    pub fn new(name: impl Into<String>, bus: WckBus<DynByteLink>) -> Self {
        Self::with_verify_reads(name, bus, None)
    }

    /// [`WckPort::new`] with the reads of every request confirmed by a second equal reply
    /// (`Some(true)`, the CLI's `--verify-reads`), never (`Some(false)`), or as each plan
    /// decides (`None`: reads that decide what is written next are confirmed).
    pub fn with_verify_reads(
        name: impl Into<String>,
        bus: WckBus<DynByteLink>,
        verify_reads: Option<bool>,
    ) -> Self {
        Self(Arc::new(WckInner {
            name: name.into(),
            bus: Mutex::new(bus),
            verify_reads,
        }))
    }

    /// The port's read confirmation rule (see [`WckPort::with_verify_reads`]).
    pub fn verify_reads(&self) -> Option<bool> {
        self.0.verify_reads
    }

    /// Its name.
    pub fn name(&self) -> &str {
        &self.0.name
    }

    /// The bus, for one whole operation (a poisoned lock is recovered: the bus itself
    /// holds no half-done state between transactions).
    pub fn lock(&self) -> MutexGuard<'_, WckBus<DynByteLink>> {
        self.0
            .bus
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// A reference that does not keep the port open: once its station and every strong
    /// handle are gone, [`WeakWckPort::upgrade`] gives `None` (the port is closed).
    pub(crate) fn downgrade(&self) -> WeakWckPort {
        WeakWckPort(Arc::downgrade(&self.0))
    }
}

/// A [`WckPort`] that does not keep the port open (see [`WckPort::downgrade`]).
#[derive(Debug, Clone)]
pub(crate) struct WeakWckPort(std::sync::Weak<WckInner>);

impl WeakWckPort {
    /// The port, if it is still open.
    pub(crate) fn upgrade(&self) -> Option<WckPort> {
        self.0.upgrade().map(WckPort)
    }
}

/// A WHJ bus of a station (clones share the bus).
#[derive(Debug, Clone)]
pub struct WhjPort(Arc<WhjInner>);

#[derive(Debug)]
struct WhjInner {
    name: String,
    /// The SocketCAN interface the bus runs on, if it does (not on a UDP or simulated bus).
    can_interface: Option<String>,
    bus: Arc<JointBus>,
    /// Joints a sample has tried to connect (by ID), answered or not.
    tried: Mutex<[bool; 31]>,
}

impl WhjPort {
    /// A port over an open bus (a UDP or simulated one: [`WhjPort::on_can`] for a bus on
    /// a SocketCAN interface).
    pub fn new(name: impl Into<String>, bus: JointBus) -> Self {
        Self(Arc::new(WhjInner {
            name: name.into(),
            can_interface: None,
            bus: Arc::new(bus),
            tried: Mutex::new([false; 31]),
        }))
    }

    /// A port over a bus open on the SocketCAN interface `iface`.
    pub fn on_can(name: impl Into<String>, iface: impl Into<String>, bus: JointBus) -> Self {
        Self(Arc::new(WhjInner {
            name: name.into(),
            can_interface: Some(iface.into()),
            bus: Arc::new(bus),
            tried: Mutex::new([false; 31]),
        }))
    }

    /// The SocketCAN interface the bus runs on (`None` for a UDP or simulated bus): what
    /// the kernel's CAN health and the `ip link` advice name.
    pub fn can_interface(&self) -> Option<&str> {
        self.0.can_interface.as_deref()
    }

    /// Of `ids`, those neither connected on this bus nor tried by an earlier call, now
    /// marked as tried: a sample connects each joint once per station, so a silent joint
    /// costs one connect timeout, not one per sample (sampling itself needs no connect).
    pub(crate) fn untried(&self, ids: &[JointId]) -> Vec<JointId> {
        let mut tried = self
            .0
            .tried
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        ids.iter()
            .copied()
            .filter(|&id| {
                let slot = &mut tried[usize::from(id.get()).min(30)];
                let first = !*slot && self.0.bus.cached_identity(id).is_none();
                *slot = true;
                first
            })
            .collect()
    }

    /// Its name.
    pub fn name(&self) -> &str {
        &self.0.name
    }

    /// The bus.
    pub fn bus(&self) -> &JointBus {
        &self.0.bus
    }

    /// The bus as a shared handle (what a loop that outlives a borrow keeps:
    /// [`JointBus::cyclic_owned`]).
    pub(crate) fn shared_bus(&self) -> Arc<JointBus> {
        Arc::clone(&self.0.bus)
    }

    /// A reference that does not keep the bus open (see [`WckPort::downgrade`]).
    pub(crate) fn downgrade(&self) -> WeakWhjPort {
        WeakWhjPort(Arc::downgrade(&self.0))
    }
}

/// A [`WhjPort`] that does not keep the bus open (see [`WhjPort::downgrade`]).
#[derive(Debug, Clone)]
pub(crate) struct WeakWhjPort(std::sync::Weak<WhjInner>);

impl WeakWhjPort {
    /// The bus, if it is still open.
    pub(crate) fn upgrade(&self) -> Option<WhjPort> {
        self.0.upgrade().map(WhjPort)
    }
}

/// What a station opens: the CLI's `--wck-port`, `--whj-bus` and `--robot` values.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct StationConfig {
    /// Serial ports of wCK buses (each opened at `wck_baud`).
    pub wck_ports: Vec<String>,
    /// The rate of the wCK ports.
    pub wck_baud: Option<BaudRate>,
    /// WHJ bus addresses (`udp`, `udp:GROUP:PORT`, `can0`).
    pub whj_buses: Vec<String>,
    /// A robot file whose buses are opened too (named as in the file); `robot.sample`
    /// reads its joints.
    pub robot: Option<PathBuf>,
    /// Extra time to wait for each wCK reply beyond its wire time (the CLI's
    /// `--reply-margin`; `None`: the port's default).
    pub wck_reply_margin: Option<Duration>,
    /// How long a WHJ joint is given to answer its connect (`None`: the client's default).
    pub whj_connect_timeout: Option<Duration>,
    /// A folder where each `wck_ports` / `whj_buses` bus's traffic is captured (a hex log
    /// or a candump log named after the bus, at most [`CAPTURE_LIMIT`] bytes each; the
    /// robot file's buses are not captured): [`Station::captures`] lists them.
    pub capture_dir: Option<PathBuf>,
    /// How the buses it opens wait for replies (the CLI's `--wait`).
    pub wait: crate::WaitMode,
}

/// The largest capture file of one bus a station writes, bytes (64 MiB): a long session
/// stops capturing there, saying so in the file.
pub const CAPTURE_LIMIT: u64 = 64 << 20;

/// The capture file of bus `name` in `dir` (the name with anything but letters, digits,
/// `-` and `_` as `_`, then `.log`).
pub fn capture_path(dir: &Path, name: &str) -> PathBuf {
    let clean: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    dir.join(format!("{}.log", clean.trim_start_matches('_')))
}

/// The open buses (see the [module docs](self)).
#[derive(Debug, Default)]
pub struct Station {
    wck: Vec<WckPort>,
    whj: Vec<WhjPort>,
    /// What keeps in-process simulators alive.
    keep: Vec<Box<dyn std::fmt::Debug + Send + Sync>>,
    /// The robot file whose joints `robot.sample` reads, if the station has one.
    robot: Option<Arc<RobotConfig>>,
    /// Each captured bus's file (bus name, path).
    captures: Vec<(String, PathBuf)>,
    /// Its sampler, made at the first `robot.sample` (that connects the WHJ joints once),
    /// with the time it was made (for the wCK speeds between two readings).
    robot_sampler: Mutex<Option<(std::time::Instant, RobotSampler)>>,
    /// The shared samplings of its buses (`catalogue::telemetry`: one per bus and kind of
    /// reading), by key; each lives as long as a subscription to it or its thread.
    streams: Mutex<std::collections::HashMap<String, SharedStream>>,
    /// Its joints off their position interface (`interfaces`).
    interfaces: interfaces::Interfaces,
    /// Whether a `robot.play` played to its end leaves its joints holding its last point
    /// ([`Station::set_hold_at_end`]).
    hold_at_end: std::sync::atomic::AtomicBool,
    closed: bool,
}

/// A shared sampling of a station's bus, as the station keeps it (not keeping it alive).
pub(crate) type SharedStream = std::sync::Weak<dyn std::any::Any + Send + Sync>;

impl Station {
    /// An empty station.
    pub fn new() -> Self {
        Self::default()
    }

    /// Opens every bus of `config`; the first that cannot be opened fails the whole (a
    /// port or interface that is not there: [`ErrorKind::NoDevice`](crate::ErrorKind);
    /// a robot file that does not read or check: bad input naming it).
    pub fn open(config: &StationConfig) -> Result<Self, OpError> {
        let mut s = Self::new();
        let baud = config.wck_baud.unwrap_or(BaudRate::B115200);
        let margin = |mut bus: WckBus<DynByteLink>| {
            if let Some(m) = config.wck_reply_margin {
                bus.config_mut().margin = m;
            }
            bus.config_mut().wait = config.wait;
            bus
        };
        let whj = JointBusConfig {
            connect_timeout: config
                .whj_connect_timeout
                .unwrap_or(JointBusConfig::default().connect_timeout),
            wait: config.wait,
            ..JointBusConfig::default()
        };
        let dir = config.capture_dir.as_deref();
        for port in &config.wck_ports {
            let capture = dir.map(|d| capture_path(d, port));
            let bus = open_wck_limited(port, baud, capture.as_deref())?;
            if let Some(path) = capture {
                s.captures.push((port.clone(), path));
            }
            s.add_wck(port.clone(), margin(bus));
        }
        for addr in &config.whj_buses {
            let capture = dir.map(|d| capture_path(d, addr));
            s.add_whj_at(addr, open_whj_limited(addr, capture.as_deref(), whj)?);
            if let Some(path) = capture {
                s.captures.push((addr.clone(), path));
            }
        }
        if let Some(path) = &config.robot {
            let refuse = |e: &dyn std::fmt::Display| {
                OpError::invalid("--robot", path.display(), e.to_string())
            };
            let text = crate::ops::read_bounded(path, 1 << 20)?; // RobotConfig::MAX_FILE_BYTES
            let robot = RobotConfig::from_toml_str(&text).map_err(|e| refuse(&e))?;
            let absent = |e: crate::RobotError| match e {
                crate::RobotError::OpenWck { .. } | crate::RobotError::OpenWhj { .. } => {
                    OpError::NoDevice(format!("{}: {e}", path.display()))
                }
                e => refuse(&e),
            };
            let (wck, whj) =
                sampler::open_robot_ports(&robot, whj, config.wck_reply_margin).map_err(absent)?;
            for p in wck {
                s.add_wck_port(p);
            }
            for p in whj {
                s.whj.push(p);
            }
            s.set_robot(robot).map_err(|e| refuse(&e))?;
        }
        Ok(s)
    }

    /// Gives the station a robot file: `robot.sample` then reads its joints through the
    /// station's buses of the file's names (an `wck-external` / `whj-external` bus is
    /// one added with that name). Every bus of the file must be open here already, in
    /// its family.
    pub fn set_robot(&mut self, config: RobotConfig) -> Result<(), OpError> {
        for (name, bus) in &config.buses {
            let open = if bus.is_wck() {
                self.wck(Some(name)).is_ok()
            } else {
                self.whj(Some(name)).is_ok()
            };
            if !open {
                return Err(OpError::invalid(
                    "bus",
                    name,
                    format!(
                        "the robot file's bus is not open in the station as a {} bus",
                        if bus.is_wck() { "wCK" } else { "WHJ" }
                    ),
                ));
            }
        }
        self.robot = Some(Arc::new(config));
        *self
            .robot_sampler
            .get_mut()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = None;
        Ok(())
    }

    /// The shared samplings of the station's buses, by key (see `catalogue::telemetry`).
    pub(crate) fn streams(
        &self,
    ) -> MutexGuard<'_, std::collections::HashMap<String, SharedStream>> {
        self.streams
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Each captured bus's capture file (bus name, path).
    pub fn captures(&self) -> &[(String, PathBuf)] {
        &self.captures
    }

    /// Records that bus `name`'s traffic is captured into `path`.
    pub fn add_capture(&mut self, name: impl Into<String>, path: PathBuf) {
        self.captures.push((name.into(), path));
    }

    /// The robot file of the station, if it has one.
    pub fn robot(&self) -> Option<&RobotConfig> {
        self.robot.as_deref()
    }

    /// Which of its joints are off their position interface, and the check that refuses
    /// a motion of positions of them (see [`interfaces`]).
    pub fn interfaces(&self) -> &interfaces::Interfaces {
        &self.interfaces
    }

    /// Whether a `robot.play` played to its end (not stopped, nothing failed, no
    /// protection stop) leaves its joints holding its last point, as
    /// `joint_trajectory_controller` holds a trajectory's end: WHJ joints held in
    /// position, wCK servos keeping the torque of their last position command. Off by
    /// default (every end goes to the robot file's `safe_state`, what a command-line run,
    /// with no watchdog after it, needs); a front end whose guard brings the joints to
    /// their safe state when its operator is lost (the bridge) turns it on, the safe
    /// state then being for stops, faults and the watchdog.
    pub fn set_hold_at_end(&self, hold: bool) {
        self.hold_at_end
            .store(hold, std::sync::atomic::Ordering::Relaxed);
    }

    /// See [`Station::set_hold_at_end`].
    pub fn holds_at_end(&self) -> bool {
        self.hold_at_end.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// One reading of every joint of the station's robot file, in the file's order, as
    /// joint angles (see [`RobotSampler`]); `None` without a robot file. The first call
    /// connects the WHJ joints (a silent one costs one connect timeout, once).
    pub(crate) fn sample_robot(
        &self,
    ) -> Option<Result<Vec<DeviceResult<String, RobotJointSample>>, OpError>> {
        let config = self.robot.as_deref()?;
        let mut slot = self
            .robot_sampler
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if slot.is_none() {
            let sampler = RobotSampler::on_ports(
                config,
                |n| self.wck(Some(n)).ok(),
                |n| self.whj(Some(n)).ok(),
            )
            .map_err(|e| OpError::invalid("robot", "bus", e.to_string()));
            match sampler {
                Ok(sampler) => *slot = Some((std::time::Instant::now(), sampler)),
                Err(e) => return Some(Err(e)),
            }
        }
        let (since, sampler) = slot.as_mut()?;
        Some(Ok(sampler.sample(since.elapsed().as_secs_f64())))
    }

    /// The built-in simulated robot of `robobus demo`, in-process on the simulators'
    /// virtual clocks: 16 wCK servos (IDs 0..=15, W1108, 115200 bit/s) as `sim-wck` and 7
    /// WHJ30 joints (IDs 1..=7) as `sim-whj`. No hardware, no wall-clock waits.
    #[cfg(feature = "sim")]
    pub fn simulated() -> Result<Self, OpError> {
        Self::simulated_with_handles().map(|(s, _, _)| s)
    }

    /// [`Station::simulated`], and handles on its two simulators (their own counters).
    #[cfg(feature = "sim")]
    pub(crate) fn simulated_with_handles() -> Result<
        (
            Self,
            robobus_sim::wck::SimHandle,
            robobus_sim::whj::WhjSimHandle,
        ),
        OpError,
    > {
        use robobus_link::ByteLink as _;
        use robobus_sim::wck::{Bus, BusConfig, Model, SimLink};
        use robobus_sim::whj::{WhjBus, WhjModel, WhjSimLink};
        let (mut link, wck_sim) = SimLink::virtual_clock(Bus::with_servos(
            BusConfig::default(),
            Model::W1108,
            0..crate::robot::simulated::SERVOS,
        ));
        // The modules are deaf for 65 ms after power-up: wait that out on their clock.
        let now = link.now();
        link.sleep_until(
            now + robobus_wck::timing::POWER_UP_DEAF + std::time::Duration::from_millis(5),
        );
        let bus = WckBus::new(Box::new(link) as DynByteLink, BaudRate::B115200)?
            .with_device_name("sim-wck");
        let (whj_link, whj_sim) = WhjSimLink::new(WhjBus::chain(
            1..=crate::robot::simulated::JOINTS,
            WhjModel::Whj30,
            11,
        ));
        let mut s = Self::new();
        s.add_wck("sim-wck", bus);
        s.add_whj(
            "sim-whj",
            JointBus::open_with(whj_link, JointBusConfig::default())?,
        );
        s.keep.push(Box::new(Mutex::new(wck_sim.clone())));
        s.keep.push(Box::new(Mutex::new(whj_sim.clone())));
        let robot = RobotConfig::from_toml_str(&crate::robot::simulated::simulated_robot())
            .map_err(|e| OpError::Device(format!("the built-in robot file: {e}")))?;
        s.set_robot(robot)?;
        Ok((s, wck_sim, whj_sim))
    }

    /// Adds a wCK bus named `name`.
    pub fn add_wck(&mut self, name: impl Into<String>, bus: WckBus<DynByteLink>) -> WckPort {
        let p = WckPort::new(name, bus);
        self.wck.push(p.clone());
        p
    }

    /// Adds a wCK port made by the caller ([`WckPort::with_verify_reads`]).
    pub fn add_wck_port(&mut self, port: WckPort) -> WckPort {
        self.wck.push(port.clone());
        port
    }

    /// Adds the WHJ bus opened from the address `addr` (what `--whj-bus` takes: `udp`,
    /// `udp:GROUP:PORT` or a SocketCAN interface), named so: on a SocketCAN interface when
    /// the address names one.
    pub fn add_whj_at(&mut self, addr: &str, bus: JointBus) -> WhjPort {
        match addr.parse::<robobus_link::FrameLinkSpec>() {
            Ok(robobus_link::FrameLinkSpec::SocketCan(iface)) => {
                self.add_whj_port(WhjPort::on_can(addr, iface, bus))
            }
            _ => self.add_whj(addr, bus),
        }
    }

    /// Adds a WHJ port made by the caller ([`WhjPort::on_can`]).
    pub fn add_whj_port(&mut self, port: WhjPort) -> WhjPort {
        self.whj.push(port.clone());
        port
    }

    /// Adds a WHJ bus named `name` (a UDP or simulated one: [`Station::add_whj_port`] with
    /// [`WhjPort::on_can`] for one on a SocketCAN interface).
    pub fn add_whj(&mut self, name: impl Into<String>, bus: JointBus) -> WhjPort {
        let p = WhjPort::new(name, bus);
        self.whj.push(p.clone());
        p
    }

    /// Keeps `thing` (a simulator's handle) alive as long as the station.
    pub fn keep(&mut self, thing: Box<dyn std::fmt::Debug + Send + Sync>) {
        self.keep.push(thing);
    }

    /// The wCK port `name`, or the only one when `name` is `None`.
    pub fn wck(&self, name: Option<&str>) -> Result<WckPort, OpError> {
        pick(&self.wck, name, "wCK", WckPort::name)
    }

    /// The WHJ bus `name`, or the only one when `name` is `None`.
    pub fn whj(&self, name: Option<&str>) -> Result<WhjPort, OpError> {
        pick(&self.whj, name, "WHJ", WhjPort::name)
    }

    /// The names of the wCK ports and the WHJ buses.
    pub fn names(&self) -> (Vec<String>, Vec<String>) {
        (
            self.wck.iter().map(|p| p.name().to_owned()).collect(),
            self.whj.iter().map(|p| p.name().to_owned()).collect(),
        )
    }

    /// Brings every device to its safe state (wCK: the bus-wide break; WHJ: every joint
    /// the bus has connected disabled); the failures, one message per device.
    pub fn close(mut self) -> Vec<String> {
        self.safe_stop()
    }

    /// Closes the station leaving every device as the last request left it: what a
    /// one-shot command wants (`robobus whj enable 1` must leave the joint enabled; an
    /// interrupted request has brought its devices to its own `on_stop` state already).
    pub fn leave(mut self) {
        self.closed = true;
    }

    fn safe_stop(&mut self) -> Vec<String> {
        if self.closed {
            return Vec::new();
        }
        self.closed = true;
        let mut failed = Vec::new();
        for p in &self.wck {
            let mut bus = p.lock();
            let f = SafeState::Break.apply(&mut WckServos {
                bus: &mut bus,
                ids: &[],
                torque: TorqueLevel::MIN,
            });
            failed.extend(f.into_iter().map(|f| format!("{}: {f}", p.name())));
        }
        for p in &self.whj {
            let bus = p.bus();
            let joints: Vec<_> = (1..=30)
                .filter_map(|raw| JointId::new(raw).ok())
                .filter(|id| bus.cached_identity(*id).is_some())
                .map(|id| bus.joint_unchecked(id))
                .collect();
            if joints.is_empty() {
                continue;
            }
            let f = SafeState::Disable.apply(&mut WhjJoints {
                joints: &joints,
                servo: ServoLoop::Position,
            });
            failed.extend(f.into_iter().map(|f| format!("{}: {f}", p.name())));
        }
        failed
    }
}

impl Drop for Station {
    fn drop(&mut self) {
        for f in self.safe_stop() {
            tracing::warn!("station close: {f}");
        }
    }
}

fn pick<T: Clone>(
    all: &[T],
    name: Option<&str>,
    family: &str,
    name_of: fn(&T) -> &str,
) -> Result<T, OpError> {
    let names = || {
        all.iter()
            .map(|p| name_of(p).to_owned())
            .collect::<Vec<_>>()
            .join(", ")
    };
    match name {
        Some(n) => all
            .iter()
            .find(|p| name_of(p) == n)
            .cloned()
            .ok_or_else(|| {
                OpError::invalid(
                    "bus",
                    n,
                    format!(
                        "the station has no {family} bus of that name (it has: {})",
                        names()
                    ),
                )
            }),
        None => match all {
            [one] => Ok(one.clone()),
            [] => Err(OpError::invalid(
                "bus",
                "(none)",
                format!("the station has no {family} bus"),
            )),
            _ => Err(OpError::invalid(
                "bus",
                "(none)",
                format!(
                    "the station has several {family} buses: name one ({})",
                    names()
                ),
            )),
        },
    }
}

/// Opens the WHJ bus at `addr` (`udp`, `udp:GROUP:PORT`, a SocketCAN interface) as
/// [`Station::open`] does, optionally logging every frame to `capture` as a candump log
/// (an existing file is refused before anything is sent). An address that does not parse
/// is bad input, an interface that is not there no device.
pub fn open_whj(addr: &str, capture: Option<&Path>) -> Result<JointBus, OpError> {
    open_whj_with(addr, capture, JointBusConfig::default())
}

/// [`open_whj`] with a client configuration.
pub fn open_whj_with(
    addr: &str,
    capture: Option<&Path>,
    config: JointBusConfig,
) -> Result<JointBus, OpError> {
    open_whj_capture(addr, capture.map(|p| (p, Overwrite::No, u64::MAX)), config)
}

/// A station's WHJ bus: a capture replaces an older file and stops at [`CAPTURE_LIMIT`].
fn open_whj_limited(
    addr: &str,
    capture: Option<&Path>,
    config: JointBusConfig,
) -> Result<JointBus, OpError> {
    open_whj_capture(
        addr,
        capture.map(|p| (p, Overwrite::Yes, CAPTURE_LIMIT)),
        config,
    )
}

fn open_whj_capture(
    addr: &str,
    capture: Option<(&Path, Overwrite, u64)>,
    config: JointBusConfig,
) -> Result<JointBus, OpError> {
    let spec: robobus_link::FrameLinkSpec = addr
        .parse()
        .map_err(|e| OpError::invalid("bus", addr, format!("{e}")))?;
    let link = spec.open()?;
    match capture {
        None => Ok(JointBus::open_with(link, config)?),
        Some((path, overwrite, limit)) => {
            let link =
                capture_frame_link_limited(link, path, spec.candump_iface(), overwrite, limit)?;
            Ok(JointBus::open_with(link, config)?)
        }
    }
}

/// Opens the wCK port `port` at `baud` as [`Station::open`] does, optionally logging
/// every byte written and read to `capture` (an existing file is refused).
pub fn open_wck_port(
    port: &str,
    baud: BaudRate,
    capture: Option<&Path>,
) -> Result<WckBus<DynByteLink>, OpError> {
    open_wck_capture(port, baud, capture.map(|p| (p, Overwrite::No, u64::MAX)))
}

/// A station's wCK port: a capture replaces an older file and stops at [`CAPTURE_LIMIT`].
fn open_wck_limited(
    port: &str,
    baud: BaudRate,
    capture: Option<&Path>,
) -> Result<WckBus<DynByteLink>, OpError> {
    open_wck_capture(
        port,
        baud,
        capture.map(|p| (p, Overwrite::Yes, CAPTURE_LIMIT)),
    )
}

fn open_wck_capture(
    port: &str,
    baud: BaudRate,
    capture: Option<(&Path, Overwrite, u64)>,
) -> Result<WckBus<DynByteLink>, OpError> {
    let bus = WckBus::open(port, baud)?;
    match capture {
        None => bus.try_map_link(|l| Ok::<_, OpError>(Box::new(l) as DynByteLink)),
        Some((path, overwrite, limit)) => bus.try_map_link(|l| {
            capture_byte_link_limited(l, path, overwrite, limit).map(|l| Box::new(l) as DynByteLink)
        }),
    }
}
