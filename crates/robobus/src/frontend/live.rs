//! The built-in simulated robot on the wall clock, for front ends that run live (a web
//! studio, a pub/sub bridge): the same 16 wCK servos and 7 WHJ30 joints and robot file as
//! [`Station::simulated`], but moving in real time, with each bus's traffic optionally
//! captured, and a [`LiveSimulator`] that shows the simulators' own state (read from the
//! models, not over the bus: what a test checks a front end against).

use std::path::Path;
use std::sync::{Arc, Mutex, PoisonError};

use robobus_sim::wck::{Bus, BusConfig, Model, SimHandle, SimLink};
use robobus_sim::whj::{JointState, Served, WhjBus, WhjModel};
use robobus_wck::BaudRate;
use serde::Serialize;

use crate::ops::OpError;
use crate::ops::capture::{Overwrite, capture_byte_link_limited, capture_frame_link_limited};
use crate::robot::DynByteLink;
use crate::robot::RobotConfig;
use crate::robot::simulated::{JOINTS, SERVOS};
use crate::station::{CAPTURE_LIMIT, Station, capture_path};
use crate::wck::WckBus;
use crate::whj::{JointBus, JointBusConfig};

/// One simulated wCK servo as its model is now.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SimServo {
    /// Its ID.
    pub id: u8,
    /// Position, steps 0..=254.
    pub position: u8,
    /// Shaft angle, degrees.
    pub angle_deg: f64,
    /// Load byte it would report.
    pub load: u8,
    /// `position`, `passive`, `break`, `wheel` or `off`.
    pub mode: String,
    /// Runtime P and D gains.
    pub p_gain: u8,
    /// Runtime D gain.
    pub d_gain: u8,
}

/// One simulated WHJ joint as its model is now.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SimJointView {
    /// Its ID.
    pub id: u8,
    /// Reported position, degrees.
    pub position_deg: f64,
    /// Output speed, RPM.
    pub speed_rpm: f64,
    /// Motor current, A.
    pub current_a: f64,
    /// Drive enabled.
    pub enabled: bool,
    /// Work mode register (0 open loop, 1 current, 2 speed, 3 position).
    pub mode: u16,
    /// Position target, degrees.
    pub target_position_deg: f64,
    /// Speed target, RPM.
    pub target_speed_rpm: f64,
    /// Latched error bits.
    pub error: u16,
}

/// Both simulators' own state.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SimSnapshot {
    /// The wCK servos.
    pub wck: Vec<SimServo>,
    /// The WHJ joints.
    pub whj: Vec<SimJointView>,
}

/// The simulators behind [`Station::simulated_live`]: their own state.
#[derive(Debug, Clone)]
pub struct LiveSimulator {
    wck: SimHandle,
    whj: Arc<Mutex<Vec<JointState>>>,
}

impl LiveSimulator {
    /// The simulators' state now.
    pub fn snapshot(&self) -> SimSnapshot {
        let wck = self.wck.with_bus(|bus| {
            bus.servos()
                .map(|s| {
                    let rt = s.runtime();
                    SimServo {
                        id: s.id().get(),
                        position: s.position(),
                        angle_deg: s.angle(),
                        load: s.load(),
                        mode: format!("{:?}", s.mode()).to_lowercase(),
                        p_gain: rt.p.get(),
                        d_gain: rt.d.get(),
                    }
                })
                .collect()
        });
        let whj = self
            .whj
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .iter()
            .map(|j| SimJointView {
                id: j.id,
                position_deg: j.position_deg,
                speed_rpm: j.speed_rpm,
                current_a: j.current_a,
                enabled: j.enabled,
                mode: j.mode,
                target_position_deg: f64::from(j.target_position)
                    * robobus_whj::units::POSITION_DEG_PER_COUNT,
                target_speed_rpm: f64::from(j.target_speed)
                    * robobus_whj::units::TARGET_SPEED_RPM_PER_COUNT,
                error: j.error.bits(),
            })
            .collect();
        SimSnapshot { wck, whj }
    }
}

impl Station {
    /// The built-in simulated robot on the wall clock (see the [module docs](self)):
    /// `sim-wck` (servos 0..=15, W1108, 115200 bit/s) and `sim-whj` (joints 1..=7,
    /// WHJ30), the robot file of [`Station::simulated`]. With `capture_dir`, each bus's
    /// traffic is written there as `sim-wck.log` (hex log) and `sim-whj.log` (candump
    /// log), each at most [`CAPTURE_LIMIT`] bytes ([`Station::captures`]).
    pub fn simulated_live(capture_dir: Option<&Path>) -> Result<(Self, LiveSimulator), OpError> {
        let (link, wck_sim) = SimLink::new(Bus::with_servos(
            BusConfig::default(),
            Model::W1108,
            0..SERVOS,
        ));
        // The modules are deaf for 65 ms after power-up.
        std::thread::sleep(
            robobus_wck::timing::POWER_UP_DEAF.saturating_sub(wck_sim.now())
                + std::time::Duration::from_millis(5),
        );
        let mut captures = Vec::new();
        let wck_link: DynByteLink = match capture_dir {
            None => Box::new(link),
            Some(dir) => {
                let path = capture_path(dir, "sim-wck");
                let l = capture_byte_link_limited(link, &path, Overwrite::Yes, CAPTURE_LIMIT)?;
                captures.push(("sim-wck".to_owned(), path));
                Box::new(l)
            }
        };
        let wck = WckBus::new(wck_link, BaudRate::B115200)?.with_device_name("sim-wck");

        let states = Arc::new(Mutex::new(Vec::new()));
        let publish = Arc::clone(&states);
        let wire = robobus_link::MemoryBus::new();
        let served = Served::spawn_observed(
            "sim-whj",
            WhjBus::chain(1..=JOINTS, WhjModel::Whj30, 11),
            wire.endpoint(),
            move |bus| {
                let now: Vec<JointState> = bus
                    .joints()
                    .iter()
                    .map(robobus_sim::whj::SimJoint::state)
                    .collect();
                *publish.lock().unwrap_or_else(PoisonError::into_inner) = now;
            },
        )
        .map_err(|e| OpError::Device(format!("starting the simulated WHJ arm: {e}")))?;
        let config = JointBusConfig::simulated();
        let whj = match capture_dir {
            None => JointBus::open_with(wire.endpoint(), config)?,
            Some(dir) => {
                let path = capture_path(dir, "sim-whj");
                let l = capture_frame_link_limited(
                    wire.endpoint(),
                    &path,
                    "sim-whj",
                    Overwrite::Yes,
                    CAPTURE_LIMIT,
                )?;
                captures.push(("sim-whj".to_owned(), path));
                JointBus::open_with(l, config)?
            }
        };
        let mut s = Self::new();
        s.add_wck("sim-wck", wck);
        s.add_whj("sim-whj", whj);
        s.keep(Box::new(Mutex::new(served)));
        for (name, path) in captures {
            s.add_capture(name, path);
        }
        let robot = RobotConfig::from_toml_str(&crate::robot::simulated::simulated_robot())
            .map_err(|e| OpError::Device(format!("the built-in robot file: {e}")))?;
        s.set_robot(robot)?;
        Ok((
            s,
            LiveSimulator {
                wck: wck_sim,
                whj: states,
            },
        ))
    }
}
