//! Sampling (`robobus monitor`, the `*.sample` operations, the telemetry stream): read-only,
//! one result per device per sample.
//!
//! - WHJ joints by ID: [`sample_whj`] ([`JointSample`], device units), the fastest way the
//!   bus allows, and it says which ([`SampledBy`]): the cyclic loop's own feedback when a
//!   loop runs on the bus, one broadcast status frame for the joints that have a slot in
//!   it when asked (`broadcast`), else a status query and a speed read per joint, all of
//!   them pipelined ([`JointBus::request_many`]: sent together, each reply credited only
//!   to its request).
//! - wCK servos by ID: [`WckSampler`] (a status read per servo, [`WckSample`]; the speed is
//!   the position's derivative between two readings).
//! - A robot file's joints by name: [`RobotSampler`] opens the file's buses for reading only
//!   (nothing is enabled, nothing is released when it is dropped) and reports each joint as
//!   a joint angle ([`RobotJointSample`]: the file's `offset`, `direction` and wCK `centre`
//!   applied), in the file's order.
//!
//! A device that does not answer is a failed [`DeviceResult`] for that sample: its values
//! are missing, never the older ones of an earlier sample (a front end shows them as
//! stale). A sample never stops at a silent device. The buses of a robot file are read in
//! parallel, one thread per bus.

use std::time::Duration;

use robobus_link::ByteLink;
use robobus_wck::ServoId;
use robobus_whj::units::CurrentScale;
use robobus_whj::{JointId, Reply, Request};
use serde::Serialize;

use super::{WckPort, WhjPort};
use crate::actuator::{JointMap, WckScale};
use crate::ops::whj::{JointSample, check_reading, sample_broadcast};
use crate::ops::{DeviceResult, ErrorKind, Failure, OpError, Outcome};
use crate::robot::{BusConfig, RobotConfig, RobotError};
use crate::wck::{WckBus, WckConfig};
use crate::whj::{JointBus, JointBusConfig};

/// Degrees per second in one RPM.
const DEG_S_PER_RPM: f64 = 6.0;

/// One reading of a wCK servo.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
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
    pub(crate) fn with_scales(
        servos: impl IntoIterator<Item = (ServoId, Option<WckScale>)>,
    ) -> Self {
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
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct RobotJointSample {
    /// Joint angle, degrees.
    pub position_deg: f64,
    /// Joint speed, degrees per second (wCK: from consecutive readings; `None` when
    /// unknown).
    pub speed_deg_s: Option<f64>,
    /// Current, mA (WHJ; `None` for wCK and in the 12-byte status layout).
    pub current_ma: Option<i64>,
    /// Joint torque, N·m, estimated from the current and the identified model's rated
    /// torque over rated current, in the joint's direction (WHJ; `None` for wCK, without
    /// a current or an identified model).
    pub effort_nm: Option<f64>,
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
        port: WckPort,
        /// The joints' indices in the file.
        joints: Vec<usize>,
        sampler: WckSampler,
    },
    Whj {
        port: WhjPort,
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
        let (wck_ports, whj_ports) = open_robot_ports(config, whj, wck_margin)?;
        Self::on_ports(
            config,
            |n| wck_ports.iter().find(|p| p.name() == n).cloned(),
            |n| whj_ports.iter().find(|p| p.name() == n).cloned(),
        )
    }

    /// Samples the joints of `config` through buses opened already (a station's ports),
    /// found by the file's bus names; the WHJ joints are released and identified once
    /// here (one that stays silent shows in its samples).
    ///
    /// # Errors
    ///
    /// [`RobotError::Invalid`] (field `bus`) for a bus of the file that `wck` / `whj` do
    /// not supply.
    pub fn on_ports(
        config: &RobotConfig,
        wck: impl Fn(&str) -> Option<WckPort>,
        whj: impl Fn(&str) -> Option<WhjPort>,
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
            let missing = || RobotError::Invalid {
                item: format!("bus {name}"),
                field: "bus",
                value: format!("\"{name}\""),
                expected: "a bus that is open (none of that name and family is)".into(),
            };
            if bus.is_wck() {
                let port = wck(name).ok_or_else(missing)?;
                let servos: Vec<(usize, ServoId, WckScale)> = on_bus()
                    .filter_map(|(i, j)| Some((i, ServoId::new(j.id).ok()?, j.wck_scale())))
                    .collect();
                descriptions.push(bus_description(name, bus));
                buses.push(RobotBus::Wck {
                    port,
                    joints: servos.iter().map(|s| s.0).collect(),
                    sampler: WckSampler::with_scales(servos.iter().map(|s| (s.1, Some(s.2)))),
                });
            } else {
                let port = whj(name).ok_or_else(missing)?;
                let joints: Vec<(usize, JointId, JointMap)> = on_bus()
                    .filter_map(|(i, j)| Some((i, JointId::new(j.id).ok()?, j.map())))
                    .collect();
                connect_joints(port.bus(), joints.iter().map(|j| j.1));
                descriptions.push(bus_description(name, bus));
                buses.push(RobotBus::Whj { port, joints });
            }
        }
        Ok(Self {
            buses,
            joints: monitored_joints(config),
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

    /// One reading of every joint, in the file's order, at `t_s` seconds since the start:
    /// each bus read by a thread of its own, all at once.
    pub fn sample(&mut self, t_s: f64) -> Vec<DeviceResult<String, RobotJointSample>> {
        let mut out: Vec<Option<Outcome<RobotJointSample>>> =
            (0..self.joints.len()).map(|_| None).collect();
        let per_bus: Vec<Vec<(usize, Outcome<RobotJointSample>)>> = match &mut self.buses[..] {
            [] => Vec::new(),
            [one] => vec![sample_robot_bus(one, t_s)],
            many => std::thread::scope(|scope| {
                let running: Vec<_> = many
                    .iter_mut()
                    .map(|bus| {
                        std::thread::Builder::new()
                            .name("robobus-sample-bus".into())
                            .spawn_scoped(scope, move || sample_robot_bus(bus, t_s))
                    })
                    .collect();
                running
                    .into_iter()
                    .map(|t| t.ok().and_then(|t| t.join().ok()).unwrap_or_default())
                    .collect()
            }),
        };
        for (i, outcome) in per_bus.into_iter().flatten() {
            if let Some(slot) = out.get_mut(i) {
                *slot = Some(outcome);
            }
        }
        out.into_iter()
            .zip(&self.joints)
            .map(|(outcome, j)| DeviceResult {
                id: j.name.clone(),
                // A robot file's IDs are checked when it is read, and a bus whose thread
                // could not run leaves its joints here: never left out silently.
                outcome: outcome.unwrap_or_else(|| {
                    Outcome::Failed(Failure::of(
                        ErrorKind::Device,
                        &format!("joint {}: its bus was not read", j.name),
                    ))
                }),
            })
            .collect()
    }
}

/// One reading of the joints of one bus of a robot file: (index in the file, outcome).
fn sample_robot_bus(bus: &mut RobotBus, t_s: f64) -> Vec<(usize, Outcome<RobotJointSample>)> {
    match bus {
        RobotBus::Wck {
            port,
            joints,
            sampler,
        } => {
            let results = sampler.sample(&mut port.lock(), t_s);
            joints
                .iter()
                .zip(results)
                .map(|(&i, r)| {
                    (
                        i,
                        r.outcome.map(|s| RobotJointSample {
                            position_deg: s.position_deg,
                            speed_deg_s: s.speed_deg_s,
                            current_ma: None,
                            effort_nm: None,
                            load: Some(s.load),
                            enabled: None,
                            error: "ok".into(),
                        }),
                    )
                })
                .collect()
        }
        RobotBus::Whj { port, joints } => {
            let ids: Vec<JointId> = joints.iter().map(|j| j.1).collect();
            let results = match sample_whj(port.bus(), &ids, false) {
                Ok((results, _)) => results,
                Err(e) => ids
                    .iter()
                    .map(|id| DeviceResult::failed(id.get(), Failure::from(&e)))
                    .collect(),
            };
            joints
                .iter()
                .zip(results)
                .map(|(&(i, id, map), r)| {
                    let kt = port.bus().cached_identity(id).and_then(|d| {
                        robobus_whj::models::ProductFacts::torque_constant_of(
                            d.model,
                            d.reduction_ratio,
                        )
                    });
                    (
                        i,
                        r.outcome.map(|s| RobotJointSample {
                            position_deg: map.to_joint(s.position_deg.to_radians()).to_degrees(),
                            speed_deg_s: s.speed_rpm.map(|r| map.speed_to_joint(r * DEG_S_PER_RPM)),
                            current_ma: s.current_ma,
                            effort_nm: s
                                .current_ma
                                .zip(kt)
                                .map(|(ma, k)| effort_nm(ma, k, map.reversed)),
                            load: None,
                            enabled: Some(s.enabled),
                            error: s.error,
                        }),
                    )
                })
                .collect()
        }
    }
}

/// A WHJ joint's torque, N·m, from its current `ma` (mA) and its rated torque over rated
/// current `nm_per_a` (N·m per A), negated for a `reversed` joint.
pub fn effort_nm(ma: i64, nm_per_a: f64, reversed: bool) -> f64 {
    #[allow(clippy::cast_precision_loss)] // |mA| < 2^53
    let nm = ma as f64 / 1e3 * nm_per_a;
    if reversed { -nm } else { nm }
}

/// How a sample of WHJ joints was taken ([`sample_whj`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum SampledBy {
    /// A status query and a speed read per joint, all sent together and each reply
    /// credited to its own request.
    Pipelined,
    /// A status query and a speed read per joint, one after the other (the bus confirms
    /// every read by a second equal one: `verify_reads`).
    OneByOne,
    /// One broadcast status frame for the joints that have a slot in it (the others
    /// pipelined in the same sample).
    Broadcast,
    /// The feedback the cyclic loop running on the bus received after the sample began
    /// (a joint the loop did not answer for is read by pipelined requests).
    Cyclic,
    /// wCK: a status read per servo, back to back.
    StatusReads,
}

impl SampledBy {
    /// Its name as in reports: `pipelined`, `one-by-one`, `broadcast`, `cyclic`,
    /// `status-reads`.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Pipelined => "pipelined",
            Self::OneByOne => "one-by-one",
            Self::Broadcast => "broadcast",
            Self::Cyclic => "cyclic",
            Self::StatusReads => "status-reads",
        }
    }
}

/// One sample of WHJ joints `ids` (sorted, no repeats) the fastest way the bus allows, and
/// which way that was: the cyclic loop's feedback when a loop runs on the bus; with
/// `broadcast`, one broadcast status frame for the joints that have a slot in it; else a
/// status query and a speed read per joint, pipelined (one by one when the bus confirms
/// its reads, `verify_reads`). Each joint's reading is checked as
/// [`whj::sample`](crate::ops::whj::sample) checks it; a joint that does not answer is a
/// failed row, never an older value. The joints are not connected here (a caller connects
/// them once: a joint never connected still answers, its current in 1 mA counts).
///
/// # Errors
///
/// The broadcast frame could not be sent (the rows of a pipelined sample carry their own
/// failures).
pub fn sample_whj(
    bus: &crate::whj::JointBus,
    ids: &[JointId],
    broadcast: bool,
) -> Result<(Vec<DeviceResult<u8, JointSample>>, SampledBy), OpError> {
    if bus.cyclic_running() {
        return Ok((from_cyclic(bus, ids), SampledBy::Cyclic));
    }
    if broadcast && ids.iter().any(|id| id.has_broadcast_slot()) {
        let (slotted, rest): (Vec<JointId>, Vec<JointId>) =
            ids.iter().partition(|id| id.has_broadcast_slot());
        let mut rows = sample_broadcast(bus, &slotted)?;
        if !rest.is_empty() {
            rows.extend(pipelined(bus, &rest));
            rows.sort_by_key(|r| r.id);
        }
        return Ok((rows, SampledBy::Broadcast));
    }
    if bus.config().verify_reads {
        return Ok((crate::ops::whj::sample(bus, ids), SampledBy::OneByOne));
    }
    Ok((pipelined(bus, ids), SampledBy::Pipelined))
}

fn scale_of(bus: &crate::whj::JointBus, id: JointId) -> CurrentScale {
    bus.cached_identity(id)
        .map_or(CurrentScale::OneMilliamp, |i| i.current_scale())
}

/// A status query and a speed read per joint, all sent at once.
fn pipelined(bus: &crate::whj::JointBus, ids: &[JointId]) -> Vec<DeviceResult<u8, JointSample>> {
    let speed = robobus_whj::registers::addr::CUR_SPEED;
    let mut requests = Vec::with_capacity(ids.len() * 2);
    for &id in ids {
        requests.push(Request::StatusQuery { joint: id });
        match Request::read(id, speed, 2) {
            Ok(r) => requests.push(r),
            Err(_) => requests.push(Request::StatusQuery { joint: id }),
        }
    }
    let replies = match bus.request_many(&requests) {
        Ok(r) => r,
        Err(e) => {
            let e = OpError::Whj(e);
            return ids
                .iter()
                .map(|id| DeviceResult::failed(id.get(), Failure::from(&e)))
                .collect();
        }
    };
    let mut replies = replies.into_iter();
    ids.iter()
        .map(|&id| {
            let status = replies.next();
            let speed_reply = replies.next();
            let reading = (|| {
                let st = match status {
                    Some(Ok(Reply::Status { status, .. })) => status,
                    Some(Err(e)) => return Err(OpError::Whj(e)),
                    other => {
                        return Err(OpError::Device(format!(
                            "joint {}: expected a status reply, got {other:?}",
                            id.get()
                        )));
                    }
                };
                let speed_rpm = match speed_reply {
                    Some(Ok(Reply::Read { addr, words, .. })) if addr == speed => {
                        let w = words.truncated(2);
                        let at = |i: usize| w.as_slice().get(i).copied().unwrap_or(0);
                        Some(
                            robobus_whj::units::ActualSpeed(robobus_whj::registers::join_i32(
                                at(0),
                                at(1),
                            ))
                            .rpm(),
                        )
                    }
                    _ => None,
                };
                let j = bus.joint_unchecked(id);
                check_reading(&j, st.position.degrees(), speed_rpm)?;
                Ok(JointSample {
                    position_deg: st.position.degrees(),
                    speed_rpm,
                    current_ma: st.current.map(|c| c.milliamps(scale_of(bus, id))),
                    enabled: st.is_enabled(),
                    error: st.error.to_string(),
                })
            })();
            match reading {
                Ok(s) => DeviceResult::ok(id.get(), s),
                Err(e) => DeviceResult::failed(id.get(), Failure::from(&e)),
            }
        })
        .collect()
}

/// The cyclic loop's feedback that arrived after this call began, for each joint; a joint
/// without any within the bus's reply timeout is read by pipelined requests instead.
fn from_cyclic(bus: &crate::whj::JointBus, ids: &[JointId]) -> Vec<DeviceResult<u8, JointSample>> {
    let began = bus.now();
    let limit = began + bus.config().reply_timeout;
    let step = Duration::from_micros(250);
    let fresh = |t: &crate::whj::BusTelemetry| {
        ids.iter()
            .filter(|&&id| t.joint(id).updated.is_some_and(|u| u > began))
            .count()
    };
    let mut telemetry = bus.telemetry();
    while fresh(&telemetry) < ids.len() && bus.now() < limit && bus.cyclic_running() {
        bus.sleep_until((bus.now() + step).min(limit));
        telemetry = bus.telemetry();
    }
    let mut rows = Vec::with_capacity(ids.len());
    let mut missing = Vec::new();
    for &id in ids {
        let j = telemetry.joint(id);
        let value = j
            .updated
            .filter(|&u| u > began)
            .and_then(|_| Some((j.position?, j.speed, j.current, j.enabled?, j.error?)));
        match value {
            Some((position, speed, current, enabled, error)) => {
                let speed_rpm = speed.map(robobus_whj::units::ActualSpeed::rpm);
                let row =
                    match check_reading(&bus.joint_unchecked(id), position.degrees(), speed_rpm) {
                        Ok(()) => DeviceResult::ok(
                            id.get(),
                            JointSample {
                                position_deg: position.degrees(),
                                speed_rpm,
                                current_ma: current.map(|c| c.milliamps(scale_of(bus, id))),
                                enabled,
                                error: error.to_string(),
                            },
                        ),
                        Err(e) => DeviceResult::failed(id.get(), Failure::from(&e)),
                    };
                rows.push(row);
            }
            None => missing.push(id),
        }
    }
    if !missing.is_empty() {
        rows.extend(pipelined(bus, &missing));
        rows.sort_by_key(|r| r.id);
    }
    rows
}

/// Opens every bus of a robot file for reading, as station ports named as in the file
/// (wCK with `wck_margin` if given and `whj`'s wait mode, WHJ with `whj`); a bus a program supplies
/// (`wck-external`, `whj-external`) is refused ([`RobotError::Invalid`], field `kind`).
pub fn open_robot_ports(
    config: &RobotConfig,
    whj: JointBusConfig,
    wck_margin: Option<Duration>,
) -> Result<(Vec<WckPort>, Vec<WhjPort>), RobotError> {
    let mut wck_ports = Vec::new();
    let mut whj_ports = Vec::new();
    for (name, bus) in &config.buses {
        match bus {
            BusConfig::Wck { .. } => {
                let open = crate::robot::open_wck_bus(name, bus)?;
                let wck = WckConfig {
                    margin: wck_margin.unwrap_or(open.config().margin),
                    wait: whj.wait,
                    ..*open.config()
                };
                wck_ports.push(WckPort::new(name.clone(), open.with_config(wck)));
            }
            BusConfig::WhjUdp { .. } | BusConfig::WhjBus { .. } => {
                let jb = crate::robot::open_whj_bus(name, bus, whj)?;
                whj_ports.push(WhjPort::new(name.clone(), jb));
            }
            BusConfig::WhjCan { iface, .. } => {
                let jb = crate::robot::open_whj_bus(name, bus, whj)?;
                whj_ports.push(WhjPort::on_can(name.clone(), iface.clone(), jb));
            }
            BusConfig::WckExternal { .. } | BusConfig::WhjExternal { .. } => {
                return Err(RobotError::Invalid {
                    item: format!("bus {name}"),
                    field: "kind",
                    value: format!("\"{}\"", bus.kind()),
                    expected: "a bus opened from the file (kind wck, whj-udp, whj-can or \
                               whj-bus); an external bus is one a program supplies"
                        .into(),
                });
            }
        }
    }
    Ok((wck_ports, whj_ports))
}

/// The joints of a robot file as the monitor shows them, in the file's order.
pub fn monitored_joints(config: &RobotConfig) -> Vec<MonitoredJoint> {
    config
        .joints
        .iter()
        .map(|j| MonitoredJoint {
            name: j.name.clone(),
            wck: config.is_wck(j),
        })
        .collect()
}

/// One line for a robot file's bus: `legs: wCK /dev/ttyUSB0 at 115200 bit/s`,
/// `arm: WHJ can0`, `arm: WHJ UDP`, `sim: wCK (supplied by the program)`.
pub fn bus_description(name: &str, bus: &BusConfig) -> String {
    match bus {
        BusConfig::Wck { port, baud, .. } => format!("{name}: wCK {port} at {baud} bit/s"),
        BusConfig::WhjCan { iface, .. } => format!("{name}: WHJ {iface}"),
        BusConfig::WhjUdp { .. } => format!("{name}: WHJ UDP"),
        BusConfig::WhjBus { bus, .. } => format!("{name}: WHJ {bus}"),
        BusConfig::WckExternal { .. } => format!("{name}: wCK (supplied by the program)"),
        BusConfig::WhjExternal { .. } => format!("{name}: WHJ (supplied by the program)"),
    }
}

/// Releases and identifies joints (the vendor's required first operation) before they are
/// sampled; one that stays silent shows in its samples (logged here).
fn connect_joints(bus: &JointBus, ids: impl IntoIterator<Item = JointId>) {
    for id in ids {
        if let Err(e) = bus.joint(id) {
            tracing::info!("joint {id}: {e}");
        }
    }
}
