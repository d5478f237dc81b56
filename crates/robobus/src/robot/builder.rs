//! Opening a robot: the buses from the file or supplied by the program, each joint
//! resolved and connected.

use super::{
    ActuatorError, Arc, AtomicBool, BTreeMap, BaudRate, BusConfig, Device, Drive, Duration,
    DynByteLink, EffortScale, Hardware, Instant, Interface, JointBus, JointBusConfig, JointConfig,
    JointId, JointLimits, JointSlot, Mutex, RateLimiter, Robot, RobotByteLink, RobotConfig,
    RobotError, ServoId, Shared, TorqueLevel, WckBus, WckSlot, WhjSlot,
};

use super::guard::Guard;
use robobus_whj::units::Model;

// ----- builder -------------------------------------------------------------------------

/// Builds a [`Robot`] from a [`RobotConfig`], with buses the program supplies (see
/// [`Robot::builder`]).
#[derive(Debug)]
pub struct RobotBuilder {
    pub(super) config: RobotConfig,
    pub(super) wck: BTreeMap<String, WckBus<DynByteLink>>,
    pub(super) whj: BTreeMap<String, JointBus>,
    pub(super) error: Option<RobotError>,
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
    /// watchdog (a thread when a bus runs on the wall clock).
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
                let origin = wck.now();
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
                    origin,
                });
            } else {
                let whj = match self.whj.remove(name) {
                    Some(b) => b,
                    None => open_whj_bus(name, bus, JointBusConfig::default())?,
                };
                index.insert(name, whj_slots.len());
                whj_slots.push(WhjSlot {
                    name: name.clone(),
                    origin: whj.now(),
                    bus: Arc::new(whj),
                    safe,
                });
            }
        }

        // The robot's time zero: the first bus's clock now (each bus's own instant of it
        // is its `origin`, taken before any bus was driven).
        let origin = wck_slots.first().map_or_else(
            || whj_slots.first().map_or_else(Instant::now, |s| s.origin),
            |s| s.origin,
        );
        let mut joints = Vec::new();
        let mut watched = Vec::new();
        for j in &config.joints {
            let (slot, model) = build_joint(j, &config, &index, &whj_slots)?;
            // The host's protection: the models table's defaults with the file's.
            let limits = config.protection_of(j, model);
            // A wCK servo is read every WCK_READ_EVERY: its windows sized to that.
            let limits = if config.is_wck(j) {
                limits.for_reading_period(super::WCK_READ_EVERY)
            } else {
                limits
            };
            watched.push((j.name.clone(), limits, model));
            joints.push(slot);
        }

        let mut hw = Hardware {
            wck: wck_slots,
            whj: whj_slots,
            joints,
            last_cycle: origin,
            origin,
            guard: Guard::new(origin, watched),
        };
        hw.enable_whj()?;
        hw.reset_limiters()?;
        start(hw, config.watchdog())
    }
}

/// The robot on its connected hardware, with its watchdog: a thread when a bus runs on
/// the wall clock; on a virtual clock time moves only inside calls into the robot, which
/// serve the watchdog themselves.
fn start(hw: Hardware, timeout: Duration) -> Result<Robot, RobotError> {
    let names = hw.joints.iter().map(|j| j.name.clone()).collect();
    let wall_time = hw.wall_time();
    let shared = Arc::new(Shared {
        hw: Mutex::new(hw),
        last_command: Mutex::new(None),
        stopped: Mutex::new(None),
        quit: AtomicBool::new(false),
        timeout,
    });
    let watchdog = if wall_time {
        let dog = Arc::clone(&shared);
        Some(
            std::thread::Builder::new()
                .name("robot-watchdog".into())
                .spawn(move || dog.watchdog())
                .map_err(|e| RobotError::Watchdog(e.to_string()))?,
        )
    } else {
        None
    };
    Ok(Robot {
        shared,
        watchdog,
        names,
        keep: Vec::new(),
    })
}

/// Resolves one joint of the file: its device, map and limits (WHJ: connects it), and
/// the model a WHJ joint identified as.
fn build_joint(
    j: &JointConfig,
    config: &RobotConfig,
    index: &BTreeMap<&str, usize>,
    whj_slots: &[WhjSlot],
) -> Result<(JointSlot, Option<Model>), RobotError> {
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
    let mut peak_rad_s = None;
    let mut effort_scale = None;
    let mut model = None;
    let device = if config.is_wck(j) {
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
        let identity = handle.identity().map_err(whj)?;
        let current = identity.current_scale();
        model = Some(identity.model);
        peak_rad_s = identity
            .model
            .peak_output_speed_rpm()
            .map(|rpm| rpm * core::f64::consts::TAU / 60.0);
        if j.has(Interface::Effort) {
            let scale = EffortScale::of(identity.model, identity.reduction_ratio).ok_or_else(|| {
                invalid(
                    "interfaces",
                    "\"effort\"".into(),
                    format!(
                        "a joint whose model has a torque constant in the product table                          (it identified as {} with reduction ratio {})",
                        identity.model, identity.reduction_ratio
                    ),
                )
            })?;
            let most = j.max_effort.unwrap_or(0.0);
            if most > scale.peak_nm {
                return Err(invalid(
                    "max_effort",
                    most.to_string(),
                    format!(
                        "at most the peak torque of the joint's model, {} N·m ({} with \
                         reduction ratio {})",
                        scale.peak_nm, identity.model, identity.reduction_ratio
                    ),
                ));
            }
            effort_scale = Some(scale);
        }
        Device::Whj {
            bus,
            id,
            map,
            current,
        }
    };
    let slot = JointSlot {
        name: j.name.clone(),
        device,
        limits,
        limiter: RateLimiter::new(0.0),
        drive: Drive {
            interfaces: j.interfaces(),
            active: Interface::Position,
            velocity: 0.0,
            effort: 0.0,
            max_effort: j.max_effort.unwrap_or(0.0),
            effort_rate: j.effort_rate(),
            wheel: j.wheel_speeds.clone(),
            effort_scale,
            peak_rad_s,
        },
    };
    Ok((slot, model))
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
        BusConfig::WhjBus { bus: addr, .. } => {
            let spec: robobus_link::FrameLinkSpec = addr
                .parse()
                .map_err(|e: robobus_link::SpecError| fail(addr.clone(), e.to_string()))?;
            let what = spec.describe();
            let link = spec.open().map_err(|e| fail(what.clone(), e.to_string()))?;
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
