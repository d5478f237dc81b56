//! The robot description: a TOML file of buses and named joints.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

use serde::de::{self, IgnoredAny, SeqAccess, Visitor};
use serde::{Deserialize, Deserializer};
use toml::Spanned;

use robobus_wck::Position;

use super::RobotError;
use super::interface::{self, Interface, WheelSpeeds};
use crate::actuator::{JointMap, WCK_DEFAULT_CENTRE, WckScale};
use crate::ops::SafeState;
use crate::ops::protect::{Limits, Overrides};

/// A bus in the robot file (`[buses.NAME]`, selected by `kind`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum BusConfig {
    /// `kind = "wck"`: a wCK multi-drop UART on a serial port.
    Wck {
        /// Serial port (`/dev/ttyUSB0`, or a simulator's pty).
        port: String,
        /// Bit rate, bit/s (one of the module's rates; default 115200).
        #[serde(default = "default_baud")]
        baud: u32,
        /// Torque level of position moves, 0 (maximum) ..= 4 (minimum); default 2.
        #[serde(default = "default_torque")]
        torque: u8,
        /// `"passive"` (default) or `"break"`.
        #[serde(default = "default_wck_safe")]
        safe_state: SafeState,
    },
    /// `kind = "whj-udp"`: WHJ joints on the python-can compatible UDP multicast bus.
    WhjUdp {
        /// Multicast group (default [`robobus_link::udp::DEFAULT_GROUP`], 239.74.163.2).
        group: Option<std::net::Ipv4Addr>,
        /// UDP port (default [`robobus_link::udp::DEFAULT_PORT`], 43113).
        port: Option<u16>,
        /// `"hold"` (default) or `"disable"`.
        #[serde(default = "default_whj_safe")]
        safe_state: SafeState,
    },
    /// `kind = "whj-can"`: WHJ joints on a `SocketCAN` interface (Linux).
    WhjCan {
        /// Interface name (`can0`).
        iface: String,
        /// `"hold"` (default) or `"disable"`.
        #[serde(default = "default_whj_safe")]
        safe_state: SafeState,
    },
    /// `kind = "whj-bus"`: WHJ joints on any bus address `--bus` takes: a serial-line CAN
    /// FD adapter (`slcan:/dev/ttyACM0`, `slcan:COM8`), `udp:GROUP:PORT`, or a `SocketCAN`
    /// interface.
    WhjBus {
        /// The bus address (`slcan:COM8`).
        bus: String,
        /// `"hold"` (default) or `"disable"`.
        #[serde(default = "default_whj_safe")]
        safe_state: SafeState,
    },
    /// `kind = "wck-external"`: a wCK bus the program supplies
    /// ([`RobotBuilder::wck_bus`](super::RobotBuilder::wck_bus)), for example a simulator.
    WckExternal {
        /// Torque level of position moves, 0..=4; default 2.
        #[serde(default = "default_torque")]
        torque: u8,
        /// `"passive"` (default) or `"break"`.
        #[serde(default = "default_wck_safe")]
        safe_state: SafeState,
    },
    /// `kind = "whj-external"`: a WHJ bus the program supplies
    /// ([`RobotBuilder::whj_bus`](super::RobotBuilder::whj_bus)).
    WhjExternal {
        /// `"hold"` (default) or `"disable"`.
        #[serde(default = "default_whj_safe")]
        safe_state: SafeState,
    },
}

const fn default_baud() -> u32 {
    115_200
}
const fn default_torque() -> u8 {
    2
}
const fn default_wck_safe() -> SafeState {
    SafeState::Passive
}
const fn default_whj_safe() -> SafeState {
    SafeState::Hold
}

impl BusConfig {
    /// Whether the bus carries wCK servos (else WHJ joints).
    pub const fn is_wck(&self) -> bool {
        matches!(self, Self::Wck { .. } | Self::WckExternal { .. })
    }

    /// The `kind` keyword of the file (`"wck"`, `"whj-udp"`, ...).
    pub const fn kind(&self) -> &'static str {
        match self {
            Self::Wck { .. } => "wck",
            Self::WhjUdp { .. } => "whj-udp",
            Self::WhjCan { .. } => "whj-can",
            Self::WhjBus { .. } => "whj-bus",
            Self::WckExternal { .. } => "wck-external",
            Self::WhjExternal { .. } => "whj-external",
        }
    }

    /// The configured safe state.
    pub const fn safe_state(&self) -> SafeState {
        match self {
            Self::Wck { safe_state, .. }
            | Self::WhjUdp { safe_state, .. }
            | Self::WhjCan { safe_state, .. }
            | Self::WhjBus { safe_state, .. }
            | Self::WckExternal { safe_state, .. }
            | Self::WhjExternal { safe_state } => *safe_state,
        }
    }

    /// The torque level of wCK moves (`None` on a WHJ bus).
    pub const fn torque(&self) -> Option<u8> {
        match self {
            Self::Wck { torque, .. } | Self::WckExternal { torque, .. } => Some(*torque),
            _ => None,
        }
    }
}

/// One joint (`[[joints]]`). Angles are joint angles in rad.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointConfig {
    /// Unique name.
    pub name: String,
    /// The `[buses.NAME]` it is on.
    pub bus: String,
    /// Device ID (wCK 0..=30, WHJ 1..=30).
    pub id: u8,
    /// Device angle at joint zero, rad (wCK: relative to `centre`); default 0.
    #[serde(default)]
    pub offset: f64,
    /// `1` or `-1` (joint turns opposite to the device); default 1.
    #[serde(default = "default_direction")]
    pub direction: i8,
    /// Soft position limits `[min, max]`, rad (exactly two numbers).
    #[serde(deserialize_with = "exact_pair")]
    pub limits: [f64; 2],
    /// Largest commanded speed, rad/s.
    pub max_velocity: f64,
    /// Largest commanded acceleration, rad/s².
    pub max_acceleration: f64,
    /// wCK only: the position step taken as device angle 0 (default 127).
    pub centre: Option<u8>,
    /// The host's protection of this joint instead of the defaults
    /// (`[joints.protection]`; see [`crate::ops::protect`]).
    #[serde(default)]
    pub protection: Option<Overrides>,
    /// The command interfaces the joint has (default `["position"]`): `"position"` always,
    /// `"velocity"` (a WHJ joint's speed mode; a wCK servo's wheel mode, which needs
    /// `wheel_speeds`), `"effort"` (a WHJ joint's current mode, which needs `max_effort`).
    #[serde(default)]
    pub interfaces: Option<Vec<Interface>>,
    /// Largest commanded effort, N·m (required with `"effort"`; at most the model's peak
    /// torque, checked when the joint identifies).
    pub max_effort: Option<f64>,
    /// Fastest change of the commanded effort, N·m/s (default ten times `max_effort`:
    /// zero to full in 0.1 s).
    pub max_effort_rate: Option<f64>,
    /// wCK only, with `"velocity"`: what wheel speeds 1..=15 turn the joint at, rad/s (one
    /// number: level 15's, the others in proportion; or the 15 measured speeds). See
    /// [`WheelSpeeds`].
    pub wheel_speeds: Option<WheelSpeeds>,
}

const fn default_direction() -> i8 {
    1
}

/// `[min, max]`: exactly two numbers (serde's array would drop the rest silently).
fn exact_pair<'de, D: Deserializer<'de>>(d: D) -> Result<[f64; 2], D::Error> {
    struct Pair;
    impl<'de> Visitor<'de> for Pair {
        type Value = [f64; 2];
        fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.write_str("exactly two numbers [min, max] in rad")
        }
        fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
            let min: f64 = seq
                .next_element()?
                .ok_or_else(|| de::Error::invalid_length(0, &self))?;
            let max: f64 = seq
                .next_element()?
                .ok_or_else(|| de::Error::invalid_length(1, &self))?;
            let mut n = 2;
            while seq.next_element::<IgnoredAny>()?.is_some() {
                n += 1;
            }
            if n > 2 {
                return Err(de::Error::invalid_length(n, &self));
            }
            Ok([min, max])
        }
    }
    d.deserialize_seq(Pair)
}

/// The largest WHJ device angle, rad: the position registers hold ±2^31 counts of
/// 0.0001° (±214 748°).
const WHJ_MAX_DEVICE_RAD: f64 =
    (i32::MAX as f64) * robobus_whj::units::POSITION_DEG_PER_COUNT * (std::f64::consts::PI / 180.0);

/// Where a value error is, for its line and column.
#[derive(Debug, Clone)]
enum Site {
    Robot(&'static str),
    Bus(String, &'static str),
    Joint(usize, &'static str),
}

/// The positions of the file's items, from a second, lenient parse (`Spanned` values).
#[derive(Debug, Deserialize)]
struct Spans {
    watchdog_timeout: Option<Spanned<IgnoredAny>>,
    #[serde(default)]
    buses: BTreeMap<String, Spanned<BTreeMap<String, Spanned<IgnoredAny>>>>,
    #[serde(default)]
    joints: Vec<Spanned<BTreeMap<String, Spanned<IgnoredAny>>>>,
}

impl Spans {
    /// Byte offset of the value of `site`'s field, else of its table.
    fn offset(&self, site: &Site) -> Option<usize> {
        let in_table = |t: &Spanned<BTreeMap<String, Spanned<IgnoredAny>>>, field: &str| -> usize {
            t.get_ref()
                .get(field)
                .map_or(t.span().start, |v| v.span().start)
        };
        match site {
            Site::Robot(field) => match *field {
                "watchdog_timeout" => self.watchdog_timeout.as_ref().map(|v| v.span().start),
                _ => Some(0),
            },
            Site::Bus(name, field) => self.buses.get(name).map(|t| in_table(t, field)),
            Site::Joint(i, field) => self.joints.get(*i).map(|t| in_table(t, field)),
        }
    }
}

impl JointConfig {
    /// How the device angle becomes this joint's angle (`offset`, `direction`).
    pub fn map(&self) -> JointMap {
        JointMap {
            offset_rad: self.offset,
            reversed: self.direction < 0,
        }
    }

    /// The step-to-angle conversion of a wCK joint (`centre`, `offset`, `direction`).
    pub fn wck_scale(&self) -> WckScale {
        WckScale {
            centre: self.centre.unwrap_or(WCK_DEFAULT_CENTRE),
            map: self.map(),
        }
    }

    /// The command interfaces of the joint (`interfaces`; position alone by default).
    pub fn interfaces(&self) -> Vec<Interface> {
        self.interfaces
            .clone()
            .unwrap_or_else(|| vec![Interface::Position])
    }

    /// Whether the joint has `interface`.
    pub fn has(&self, interface: Interface) -> bool {
        interface == Interface::Position
            || self
                .interfaces
                .as_ref()
                .is_some_and(|i| i.contains(&interface))
    }

    /// The fastest change of its commanded effort, N·m/s (`max_effort_rate`, else ten
    /// times `max_effort`; 0 without effort).
    pub fn effort_rate(&self) -> f64 {
        self.max_effort_rate
            .unwrap_or_else(|| 10.0 * self.max_effort.unwrap_or(0.0))
    }
}

/// A robot file: `watchdog_timeout` (s), `[buses.NAME]` tables and `[[joints]]`.
///
/// ```
/// use robobus::robot::RobotConfig;
///
/// let config = RobotConfig::from_toml_str(r#"
///     watchdog_timeout = 0.1   # s
///
///     [buses.legs]
///     kind = "wck"
///     port = "/dev/ttyUSB0"
///     baud = 115200
///     safe_state = "passive"
///
///     [buses.arm]
///     kind = "whj-can"
///     iface = "can0"
///     safe_state = "disable"
///
///     [[joints]]
///     name = "knee"
///     bus = "legs"
///     id = 0
///     limits = [-1.0, 1.0]      # rad
///     max_velocity = 2.0        # rad/s
///     max_acceleration = 20.0   # rad/s²
///
///     [[joints]]
///     name = "shoulder"
///     bus = "arm"
///     id = 1
///     direction = -1
///     limits = [-0.5, 0.5]
///     max_velocity = 0.5
///     max_acceleration = 2.0
/// "#)?;
/// assert_eq!(config.joints[1].name, "shoulder");
/// # Ok::<(), robobus::robot::RobotError>(())
/// ```
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotConfig {
    /// Watchdog timeout, s: the robot is put in its safe state if
    /// [`Robot::command`](super::Robot::command) is not called for this long
    /// (default 0.1 s).
    #[serde(default = "default_watchdog")]
    pub watchdog_timeout: f64,
    /// The buses by name.
    pub buses: BTreeMap<String, BusConfig>,
    /// The joints, in the order of [`Robot::read`](super::Robot::read) and
    /// [`Robot::command`](super::Robot::command).
    pub joints: Vec<JointConfig>,
    /// The host's protection (`[protection]`; see [`crate::ops::protect`]).
    #[serde(default)]
    pub protection: Protection,
}

/// The robot file's `[protection]` table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Protection {
    /// `false`: no joint of the file is protected by the host (default true).
    #[serde(default = "default_protected")]
    pub enabled: bool,
}

impl Default for Protection {
    fn default() -> Self {
        Self { enabled: true }
    }
}

const fn default_protected() -> bool {
    true
}

const fn default_watchdog() -> f64 {
    0.1
}

impl RobotConfig {
    /// Whether `joint` is on a wCK bus of this file (else a WHJ one).
    #[must_use]
    pub fn is_wck(&self, joint: &JointConfig) -> bool {
        self.buses.get(&joint.bus).is_some_and(BusConfig::is_wck)
    }

    /// The host's protection of `joint` (a WHJ joint of `model`, as it identified; `None`
    /// for a wCK servo or a model not known): the defaults of its family and model with
    /// the file's overrides, nothing checked when the file turns protection off.
    #[must_use]
    pub fn protection_of(
        &self,
        joint: &JointConfig,
        model: Option<robobus_whj::units::Model>,
    ) -> Limits {
        if !self.protection.enabled {
            return Limits::OFF;
        }
        let defaults = if self.is_wck(joint) {
            Limits::wck()
        } else {
            Limits::whj(model)
        };
        defaults.with(joint.protection.as_ref())
    }

    /// The joints' names, as a list for a message (`hip, knee, ankle`).
    #[must_use]
    pub fn joint_names(&self) -> String {
        self.joints
            .iter()
            .map(|j| j.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The largest robot file read (1 MiB): a real robot needs a few kB, and a file
    /// argument such as `/dev/zero` must not grow memory without bound.
    pub const MAX_FILE_BYTES: usize = 1 << 20;

    /// The largest joint speed a robot file may ask for, rad/s (no wCK module or WHJ
    /// joint turns faster than about 6 rad/s at its output).
    pub const MAX_JOINT_VELOCITY: f64 = 100.0;

    /// The largest joint acceleration a robot file may ask for, rad/s².
    pub const MAX_JOINT_ACCELERATION: f64 = 10_000.0;

    /// The largest joint effort a robot file may ask for, N·m (the largest WHJ joint peaks
    /// at 360 N·m; the model's own peak is checked when the joint identifies).
    pub const MAX_JOINT_EFFORT: f64 = 1_000.0;

    /// The fastest effort change a robot file may ask for, N·m/s.
    pub const MAX_JOINT_EFFORT_RATE: f64 = 100_000.0;

    /// Parses and checks a robot file. Syntax errors give the line and column; errors in
    /// the values name the joint or bus, the field and the value.
    pub fn from_toml_str(text: &str) -> Result<Self, RobotError> {
        if text.len() > Self::MAX_FILE_BYTES {
            return Err(RobotError::Parse {
                line: 0,
                column: 0,
                message: format!(
                    "the file has {} bytes, more than the {} bytes (1 MiB) \
                     a robot file may have",
                    text.len(),
                    Self::MAX_FILE_BYTES
                ),
            });
        }
        if text.trim().is_empty() {
            return Err(RobotError::Parse {
                line: 1,
                column: 1,
                message: "the file is empty: a robot file needs [buses.NAME] tables and \
                          [[joints]]"
                    .into(),
            });
        }
        let config: Self = toml::from_str(text).map_err(|e| {
            let (line, column) = e.span().map_or((0, 0), |s| line_column(text, s.start));
            RobotError::Parse {
                line,
                column,
                message: e.message().to_owned(),
            }
        })?;
        if let Err(located) = config.check() {
            let (site, mut error) = *located;
            // Name the line and column of the offending value (or of its table).
            let at = toml::from_str::<Spans>(text)
                .ok()
                .and_then(|spans| spans.offset(&site));
            if let (Some(offset), RobotError::Invalid { item, .. }) = (at, &mut error) {
                let (line, column) = line_column(text, offset);
                *item = format!("{item} (line {line}, column {column})");
            }
            return Err(error);
        }
        Ok(config)
    }

    /// Reads and parses the robot file at `path`.
    /// Files larger than [`Self::MAX_FILE_BYTES`] are refused without reading further.
    pub fn from_toml_file(path: impl AsRef<Path>) -> Result<Self, RobotError> {
        use std::io::Read as _;
        let path = path.as_ref();
        let io = |source| RobotError::Io {
            path: path.display().to_string(),
            source,
        };
        let file = std::fs::File::open(path).map_err(io)?;
        let mut bytes = Vec::new();
        file.take(Self::MAX_FILE_BYTES as u64 + 1)
            .read_to_end(&mut bytes)
            .map_err(io)?;
        if bytes.len() > Self::MAX_FILE_BYTES {
            return Err(io(std::io::Error::other(format!(
                "larger than {} bytes (1 MiB), the limit for a robot file",
                Self::MAX_FILE_BYTES
            ))));
        }
        let text = String::from_utf8(bytes).map_err(|e| {
            io(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!(
                    "not UTF-8 text (byte {} is invalid)",
                    e.utf8_error().valid_up_to()
                ),
            ))
        })?;
        Self::from_toml_str(&text)
    }

    /// The watchdog timeout as a [`Duration`].
    pub fn watchdog(&self) -> Duration {
        Duration::from_secs_f64(self.watchdog_timeout)
    }

    /// Checks the values (everything the parser cannot): unique joint names, known buses,
    /// IDs, limits, directions and safe states per family.
    pub fn validate(&self) -> Result<(), RobotError> {
        self.check().map_err(|b| b.1)
    }

    fn check(&self) -> Result<(), Box<(Site, RobotError)>> {
        if !(self.watchdog_timeout.is_finite() && (0.001..=10.0).contains(&self.watchdog_timeout)) {
            return Err(Box::new((
                Site::Robot("watchdog_timeout"),
                RobotError::Invalid {
                    item: "robot".into(),
                    field: "watchdog_timeout",
                    value: self.watchdog_timeout.to_string(),
                    expected: "0.001..=10 s".into(),
                },
            )));
        }
        if self.joints.is_empty() {
            return Err(Box::new((
                Site::Robot("joints"),
                RobotError::Invalid {
                    item: "robot".into(),
                    field: "joints",
                    value: "none".into(),
                    expected: "at least one [[joints]] table".into(),
                },
            )));
        }
        for (name, bus) in &self.buses {
            let state = bus.safe_state();
            let ok = if bus.is_wck() {
                matches!(state, SafeState::Passive | SafeState::Break)
            } else {
                matches!(state, SafeState::Hold | SafeState::Disable)
            };
            if !ok {
                return Err(Box::new((
                    Site::Bus(name.clone(), "safe_state"),
                    RobotError::Invalid {
                        item: format!("bus {name}"),
                        field: "safe_state",
                        value: state.keyword().into(),
                        expected: if bus.is_wck() {
                            "\"passive\" or \"break\" on a wCK bus".into()
                        } else {
                            "\"hold\" or \"disable\" on a WHJ bus".into()
                        },
                    },
                )));
            }
            if let Some(torque) = bus.torque()
                && torque > 4
            {
                return Err(Box::new((
                    Site::Bus(name.clone(), "torque"),
                    RobotError::Invalid {
                        item: format!("bus {name}"),
                        field: "torque",
                        value: torque.to_string(),
                        expected: "0..=4".into(),
                    },
                )));
            }
            let names_something = |s: &str| !s.trim().is_empty() && !s.contains('\0');
            let empty = match bus {
                BusConfig::Wck { port, .. } => (!names_something(port)).then_some(("port", port)),
                BusConfig::WhjCan { iface, .. } => {
                    (!names_something(iface)).then_some(("iface", iface))
                }
                _ => None,
            };
            if let BusConfig::Wck { port, .. } = bus
                && names_something(port)
            {
                check_port(name, port)?;
            }
            if let BusConfig::WhjBus { bus: addr, .. } = bus
                && let Err(e) = addr.parse::<robobus_link::FrameLinkSpec>()
            {
                return Err(Box::new((
                    Site::Bus(name.clone(), "bus"),
                    RobotError::Invalid {
                        item: format!("bus {name}"),
                        field: "bus",
                        value: format!("{:?}", e.value),
                        expected: e.reason,
                    },
                )));
            }
            if let Some((field, value)) = empty {
                return Err(Box::new((
                    Site::Bus(name.clone(), field),
                    RobotError::Invalid {
                        item: format!("bus {name}"),
                        field,
                        value: format!("{value:?}"),
                        expected: "a device name without NUL bytes".into(),
                    },
                )));
            }
        }
        for (i, joint) in self.joints.iter().enumerate() {
            self.validate_joint(i, joint)
                .map_err(|(field, e)| Box::new((Site::Joint(i, field), e)))?;
        }
        Ok(())
    }

    #[allow(clippy::too_many_lines)] // one check per field, in the file's order
    fn validate_joint(
        &self,
        index: usize,
        joint: &JointConfig,
    ) -> Result<(), (&'static str, RobotError)> {
        let item = format!("joint {}", joint.name);
        let invalid = |field: &'static str, value: String, expected: &str| {
            (
                field,
                RobotError::Invalid {
                    item: item.clone(),
                    field,
                    value,
                    expected: expected.into(),
                },
            )
        };
        if joint.name.trim().is_empty() {
            return Err(invalid(
                "name",
                format!("{:?}", joint.name),
                "a non-empty name",
            ));
        }
        if self.joints[..index].iter().any(|j| j.name == joint.name) {
            return Err(invalid("name", joint.name.clone(), "a name used once"));
        }
        let Some(bus) = self.buses.get(&joint.bus) else {
            let known: Vec<&str> = self.buses.keys().map(String::as_str).collect();
            return Err(invalid(
                "bus",
                joint.bus.clone(),
                &format!("one of the [buses]: {}", known.join(", ")),
            ));
        };
        let (ids, id_text) = if bus.is_wck() {
            (0..=30, "0..=30 (wCK)")
        } else {
            (1..=30, "1..=30 (WHJ)")
        };
        if !ids.contains(&joint.id) {
            return Err(invalid("id", joint.id.to_string(), id_text));
        }
        if self.joints[..index]
            .iter()
            .any(|j| j.bus == joint.bus && j.id == joint.id)
        {
            return Err(invalid(
                "id",
                joint.id.to_string(),
                "an ID used once per bus",
            ));
        }
        if joint.direction != 1 && joint.direction != -1 {
            return Err(invalid("direction", joint.direction.to_string(), "1 or -1"));
        }
        if !joint.offset.is_finite() {
            return Err(invalid(
                "offset",
                joint.offset.to_string(),
                "a finite angle in rad",
            ));
        }
        let [min, max] = joint.limits;
        if !(min.is_finite() && max.is_finite() && min <= max) {
            return Err(invalid(
                "limits",
                format!("[{min}, {max}]"),
                "[min, max] in rad with min <= max",
            ));
        }
        for (field, value, most, unit) in [
            (
                "max_velocity",
                joint.max_velocity,
                Self::MAX_JOINT_VELOCITY,
                "rad/s",
            ),
            (
                "max_acceleration",
                joint.max_acceleration,
                Self::MAX_JOINT_ACCELERATION,
                "rad/s²",
            ),
        ] {
            if !(value.is_finite() && value > 0.0 && value <= most) {
                return Err(invalid(
                    field,
                    value.to_string(),
                    &format!("a number > 0 and <= {most} {unit}"),
                ));
            }
        }
        if !bus.is_wck() {
            // The device angles of both limits (and of joint zero) must fit the joint's
            // position registers.
            let device =
                |joint_angle: f64| joint.offset + f64::from(joint.direction.signum()) * joint_angle;
            let worst = [device(min), device(max), joint.offset]
                .into_iter()
                .fold(0.0_f64, |m, a| m.max(a.abs()));
            if worst > WHJ_MAX_DEVICE_RAD {
                return Err(invalid(
                    "limits",
                    format!("[{min}, {max}] with offset {}", joint.offset),
                    &format!(
                        "joint angles whose device angle (offset + direction × angle) is \
                         within ±{WHJ_MAX_DEVICE_RAD:.1} rad (the WHJ position registers)"
                    ),
                ));
            }
        }
        Self::validate_interfaces(joint, bus.is_wck())
            .map_err(|(field, value, expected)| invalid(field, value, &expected))?;
        if let Some(centre) = joint.centre {
            if !bus.is_wck() {
                return Err(invalid(
                    "centre",
                    centre.to_string(),
                    "no centre on a WHJ joint",
                ));
            }
            if centre > 254 {
                return Err(invalid("centre", centre.to_string(), "0..=254"));
            }
        }
        if let Some(p) = &joint.protection {
            if bus.is_wck() {
                let measured = [
                    ("temperature_warn_c", p.temperature_warn_c),
                    ("temperature_derate_c", p.temperature_derate_c),
                    ("temperature_stop_c", p.temperature_stop_c),
                    ("derate", p.derate),
                ];
                if let Some((name, Some(v))) = measured.iter().find(|(_, v)| v.is_some()) {
                    return Err(invalid(
                        "protection",
                        format!("{name} = {v}"),
                        "on a wCK servo no temperature limit and no derating (its replies \
                         carry its load and position, no temperature)",
                    ));
                }
            }
            let defaults = if bus.is_wck() {
                Limits::wck()
            } else {
                Limits::whj(None)
            };
            if let Err((name, value, allowed)) = p.check(defaults) {
                return Err(invalid("protection", format!("{name} = {value}"), &allowed));
            }
        }
        if bus.is_wck() {
            let scale = joint.wck_scale();
            if joint.limits.iter().any(|&l| scale.to_position(l).is_none()) {
                let a = scale.to_rad(Position::MIN);
                let b = scale.to_rad(Position::MAX);
                return Err(invalid(
                    "limits",
                    format!("[{min}, {max}]"),
                    &format!(
                        "angles the servo can reach: {:.4}..={:.4} rad (steps 0..=254, centre {}, offset {} rad)",
                        a.min(b),
                        a.max(b),
                        scale.centre,
                        joint.offset
                    ),
                ));
            }
        }
        Ok(())
    }
}

impl RobotConfig {
    /// Checks a joint's `interfaces` and the fields they need: the field, the value and
    /// what is allowed, when something is wrong.
    fn validate_interfaces(
        joint: &JointConfig,
        wck: bool,
    ) -> Result<(), (&'static str, String, String)> {
        let listed = joint.interfaces();
        let shown = format!("[{}]", interface::list(&listed));
        if !listed.contains(&Interface::Position) {
            return Err((
                "interfaces",
                shown,
                "a list with \"position\" (every joint has it)".into(),
            ));
        }
        if let Some(dup) = listed
            .iter()
            .enumerate()
            .find(|(i, x)| listed[..*i].contains(x))
            .map(|(_, x)| x)
        {
            return Err(("interfaces", shown, format!("\"{dup}\" listed once")));
        }
        if wck && joint.has(Interface::Effort) {
            return Err((
                "interfaces",
                shown,
                "\"position\" and \"velocity\" on a wCK servo (it has no current mode:                  effort only on WHJ joints)"
                    .into(),
            ));
        }
        if joint.has(Interface::Velocity) && wck && joint.wheel_speeds.is_none() {
            return Err((
                "wheel_speeds",
                "none".into(),
                "the wheel speeds of a wCK joint with \"velocity\" (rad/s of wheel level 15,                  or of levels 1..=15)"
                    .into(),
            ));
        }
        if let Some(w) = &joint.wheel_speeds {
            if !wck {
                return Err((
                    "wheel_speeds",
                    format!("{:?}", w.speeds()),
                    "no wheel_speeds on a WHJ joint (its speed mode takes rad/s)".into(),
                ));
            }
            if let Some(fault) = w.fault(Self::MAX_JOINT_VELOCITY) {
                return Err(("wheel_speeds", format!("{:?}", w.speeds()), fault));
            }
        }
        let effort = joint.has(Interface::Effort);
        match joint.max_effort {
            None if effort => {
                return Err((
                    "max_effort",
                    "none".into(),
                    "the largest effort in N·m of a joint with \"effort\"".into(),
                ));
            }
            Some(v) if !effort => {
                return Err((
                    "max_effort",
                    v.to_string(),
                    "no max_effort without \"effort\" in interfaces".into(),
                ));
            }
            Some(v) if !(v.is_finite() && v > 0.0 && v <= Self::MAX_JOINT_EFFORT) => {
                return Err((
                    "max_effort",
                    v.to_string(),
                    format!("a number > 0 and <= {} N·m", Self::MAX_JOINT_EFFORT),
                ));
            }
            _ => {}
        }
        if let Some(v) = joint.max_effort_rate {
            if !effort {
                return Err((
                    "max_effort_rate",
                    v.to_string(),
                    "no max_effort_rate without \"effort\" in interfaces".into(),
                ));
            }
            if !(v.is_finite() && v > 0.0 && v <= Self::MAX_JOINT_EFFORT_RATE) {
                return Err((
                    "max_effort_rate",
                    v.to_string(),
                    format!("a number > 0 and <= {} N·m/s", Self::MAX_JOINT_EFFORT_RATE),
                ));
            }
        }
        Ok(())
    }
}

/// 1-based line and column of byte `offset` in `text`.
fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let before = text.get(..offset).unwrap_or(text);
    let line = before.matches('\n').count() + 1;
    let column = before.rfind('\n').map_or(before.chars().count(), |nl| {
        before.get(nl + 1..).map_or(0, |s| s.chars().count())
    }) + 1;
    (line, column)
}

/// A wCK bus's `port` must be a port address ([`robobus_link::PortSpec`]).
fn check_port(name: &str, port: &str) -> Result<(), Box<(Site, RobotError)>> {
    port.parse::<robobus_link::PortSpec>()
        .map(drop)
        .map_err(|e| {
            Box::new((
                Site::Bus(name.to_owned(), "port"),
                RobotError::Invalid {
                    item: format!("bus {name}"),
                    field: "port",
                    value: format!("{:?}", e.value),
                    expected: format!("{} ({})", robobus_link::port::PORT_SYNTAX, e.reason),
                },
            ))
        })
}
