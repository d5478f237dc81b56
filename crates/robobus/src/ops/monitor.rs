//! The monitor's sampling (`robobus monitor`): read-only, one result per device per sample.
//!
//! - WHJ joints by ID: [`whj::sample`](super::whj::sample) (a status query and a speed
//!   read per joint, [`JointSample`](super::whj::JointSample), device units).
//! - wCK servos by ID: [`WckSampler`] (a status read per servo, [`WckSample`]; the speed is
//!   the position's derivative between two readings).
//! - A robot file's joints by name: [`RobotSampler`] opens the file's buses for reading only
//!   (nothing is enabled, nothing is released when it is dropped) and reports each joint as
//!   a joint angle ([`RobotJointSample`]: the file's `offset`, `direction` and wCK `centre`
//!   applied), in the file's order.
//!
//! A device that does not answer is a failed [`DeviceResult`] for that sample: its values
//! are missing, never the older ones of an earlier sample (a front end shows them as
//! stale). A sample never stops at a silent device.

use std::time::Duration;

use robobus_link::ByteLink;
use robobus_wck::ServoId;
use robobus_whj::JointId;
use serde::Serialize;

use super::{DeviceResult, ErrorKind, Failure, Outcome};
use crate::actuator::{JointMap, WckScale};
use crate::robot::{BusConfig, DynByteLink, RobotConfig, RobotError};
use crate::wck::{WckBus, WckConfig};
use crate::whj::{JointBus, JointBusConfig};

/// Degrees per second in one RPM.
const DEG_S_PER_RPM: f64 = 6.0;

/// One reading of a wCK servo.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WckSample {
    /// Position, degrees: the servo's own (0..=269°, as `robobus wck status` prints), or a
    /// robot file's joint angle.
    pub position_deg: f64,
    /// Speed, degrees per second, from this reading and the servo's previous one (`None`
    /// for its first).
    pub speed_deg_s: Option<f64>,
    /// Load, 0..=255.
    pub load: u8,
}

/// Samples wCK servos: a status read each, the speed from consecutive readings.
#[derive(Debug, Clone)]
pub struct WckSampler {
    servos: Vec<(ServoId, Option<WckScale>)>,
    /// (time s, degrees) of each servo's previous reading.
    last: Vec<Option<(f64, f64)>>,
}

impl WckSampler {
    /// Servos `ids`, in the servos' own degrees.
    pub fn new(ids: &[ServoId]) -> Self {
        Self::with_scales(ids.iter().map(|&id| (id, None)))
    }

    /// Servos with their conversion to joint angles (`None`: the servo's own degrees).
    pub fn with_scales(servos: impl IntoIterator<Item = (ServoId, Option<WckScale>)>) -> Self {
        let servos: Vec<_> = servos.into_iter().collect();
        Self {
            last: vec![None; servos.len()],
            servos,
        }
    }

    /// One reading of every servo, at `t_s` seconds since the start (for the speed).
    pub fn sample<L: ByteLink>(
        &mut self,
        bus: &mut WckBus<L>,
        t_s: f64,
    ) -> Vec<DeviceResult<u8, WckSample>> {
        self.servos
            .iter()
            .zip(&mut self.last)
            .map(|(&(id, scale), prev)| match bus.servo(id).status() {
                Ok(st) => {
                    let deg = scale.map_or_else(
                        || st.position.degrees(),
                        |s| s.to_rad(st.position).to_degrees(),
                    );
                    let speed_deg_s =
                        prev.and_then(|(t0, p0)| (t_s > t0).then(|| (deg - p0) / (t_s - t0)));
                    *prev = Some((t_s, deg));
                    DeviceResult::ok(
                        id.get(),
                        WckSample {
                            position_deg: deg,
                            speed_deg_s,
                            load: st.load.get(),
                        },
                    )
                }
                Err(e) => DeviceResult::failed(id.get(), Failure::from(&e)),
            })
            .collect()
    }
}

/// One reading of a robot file's joint, as a joint angle.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RobotJointSample {
    /// Joint angle, degrees.
    pub position_deg: f64,
    /// Joint speed, degrees per second (wCK: from consecutive readings; `None` when
    /// unknown).
    pub speed_deg_s: Option<f64>,
    /// Current, mA (WHJ; `None` for wCK and in the 12-byte status layout).
    pub current_ma: Option<i64>,
    /// Load, 0..=255 (wCK; `None` for WHJ).
    pub load: Option<u8>,
    /// Drive enabled (WHJ; `None` for wCK).
    pub enabled: Option<bool>,
    /// Error bits (WHJ: `no error` or the bit names; wCK: `ok`).
    pub error: String,
}

/// A robot file's joint as the monitor shows it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct MonitoredJoint {
    /// The joint's name in the file.
    pub name: String,
    /// Whether it is a wCK servo (else a WHJ joint).
    pub wck: bool,
}

#[derive(Debug)]
enum RobotBus {
    Wck {
        bus: WckBus<DynByteLink>,
        /// The joints' indices in the file.
        joints: Vec<usize>,
        sampler: WckSampler,
    },
    Whj {
        bus: JointBus,
        joints: Vec<(usize, JointId, JointMap)>,
    },
}

/// Samples every joint of a robot file through the file's own buses, read-only.
#[derive(Debug)]
pub struct RobotSampler {
    buses: Vec<RobotBus>,
    joints: Vec<MonitoredJoint>,
    descriptions: Vec<String>,
}

impl RobotSampler {
    /// Opens the buses of `config` for reading (WHJ with `whj`, whose joints are released
    /// and identified; one that stays silent is reported by its samples; wCK with the
    /// port's settings and, if given, the reply margin `wck_margin`).
    ///
    /// # Errors
    ///
    /// [`RobotError::OpenWck`] / [`RobotError::OpenWhj`] when a port or link cannot be
    /// opened; [`RobotError::Invalid`] (field `kind`) for a bus a program supplies
    /// (`wck-external`, `whj-external`).
    pub fn open(
        config: &RobotConfig,
        whj: JointBusConfig,
        wck_margin: Option<Duration>,
    ) -> Result<Self, RobotError> {
        let mut buses = Vec::new();
        let mut descriptions = Vec::new();
        for (name, bus) in &config.buses {
            let on_bus = || {
                config
                    .joints
                    .iter()
                    .enumerate()
                    .filter(move |(_, j)| &j.bus == name)
            };
            match bus {
                BusConfig::Wck { port, baud, .. } => {
                    let open = crate::robot::open_wck_bus(name, bus)?;
                    let wck = WckConfig {
                        margin: wck_margin.unwrap_or(open.config().margin),
                        ..*open.config()
                    };
                    let servos: Vec<(usize, ServoId, WckScale)> = on_bus()
                        .filter_map(|(i, j)| Some((i, ServoId::new(j.id).ok()?, j.wck_scale())))
                        .collect();
                    descriptions.push(format!("{name}: wCK {port} at {baud} bit/s"));
                    buses.push(RobotBus::Wck {
                        bus: open.with_config(wck),
                        joints: servos.iter().map(|s| s.0).collect(),
                        sampler: WckSampler::with_scales(servos.iter().map(|s| (s.1, Some(s.2)))),
                    });
                }
                BusConfig::WhjUdp { .. } | BusConfig::WhjCan { .. } => {
                    let jb = crate::robot::open_whj_bus(name, bus, whj)?;
                    let joints: Vec<(usize, JointId, JointMap)> = on_bus()
                        .filter_map(|(i, j)| Some((i, JointId::new(j.id).ok()?, j.map())))
                        .collect();
                    connect_joints(&jb, joints.iter().map(|j| j.1));
                    descriptions.push(match bus {
                        BusConfig::WhjCan { iface, .. } => format!("{name}: WHJ {iface}"),
                        _ => format!("{name}: WHJ UDP"),
                    });
                    buses.push(RobotBus::Whj { bus: jb, joints });
                }
                BusConfig::WckExternal { .. } | BusConfig::WhjExternal { .. } => {
                    return Err(RobotError::Invalid {
                        item: format!("bus {name}"),
                        field: "kind",
                        value: format!("\"{}\"", bus.kind()),
                        expected: "a bus the monitor opens itself (kind wck, whj-udp or \
                                   whj-can); an external bus is one a program supplies"
                            .into(),
                    });
                }
            }
        }
        let joints = config
            .joints
            .iter()
            .map(|j| MonitoredJoint {
                name: j.name.clone(),
                wck: config.buses.get(&j.bus).is_some_and(BusConfig::is_wck),
            })
            .collect();
        Ok(Self {
            buses,
            joints,
            descriptions,
        })
    }

    /// The joints, in the file's order (the order of every sample).
    pub fn joints(&self) -> &[MonitoredJoint] {
        &self.joints
    }

    /// One line per bus: `legs: wCK /dev/ttyUSB0 at 115200 bit/s`, `arm: WHJ can0`.
    pub fn buses(&self) -> &[String] {
        &self.descriptions
    }

    /// One reading of every joint, in the file's order, at `t_s` seconds since the start.
    pub fn sample(&mut self, t_s: f64) -> Vec<DeviceResult<String, RobotJointSample>> {
        let mut out: Vec<Option<Outcome<RobotJointSample>>> =
            (0..self.joints.len()).map(|_| None).collect();
        for bus in &mut self.buses {
            match bus {
                RobotBus::Wck {
                    bus,
                    joints,
                    sampler,
                } => {
                    for (&i, r) in joints.iter().zip(sampler.sample(bus, t_s)) {
                        out[i] = Some(r.outcome.map(|s| RobotJointSample {
                            position_deg: s.position_deg,
                            speed_deg_s: s.speed_deg_s,
                            current_ma: None,
                            load: Some(s.load),
                            enabled: None,
                            error: "ok".into(),
                        }));
                    }
                }
                RobotBus::Whj { bus, joints } => {
                    let ids: Vec<JointId> = joints.iter().map(|j| j.1).collect();
                    for (&(i, _, map), r) in joints.iter().zip(super::whj::sample(bus, &ids)) {
                        out[i] = Some(r.outcome.map(|s| RobotJointSample {
                            position_deg: map.to_joint(s.position_deg.to_radians()).to_degrees(),
                            speed_deg_s: s.speed_rpm.map(|r| map.speed_to_joint(r * DEG_S_PER_RPM)),
                            current_ma: s.current_ma,
                            load: None,
                            enabled: Some(s.enabled),
                            error: s.error,
                        }));
                    }
                }
            }
        }
        out.into_iter()
            .zip(&self.joints)
            .map(|(outcome, j)| DeviceResult {
                id: j.name.clone(),
                // A robot file's IDs are checked when it is read; never left out silently.
                outcome: outcome.unwrap_or_else(|| {
                    Outcome::Failed(Failure::of(
                        ErrorKind::BadInput,
                        &format!("joint {}: not on an opened bus", j.name),
                    ))
                }),
            })
            .collect()
    }
}

/// Releases and identifies joints (the vendor's required first operation) before they are
/// sampled; one that stays silent shows in its samples (logged here).
pub fn connect_joints(bus: &JointBus, ids: impl IntoIterator<Item = JointId>) {
    for id in ids {
        if let Err(e) = bus.joint(id) {
            tracing::info!("joint {id}: {e}");
        }
    }
}
