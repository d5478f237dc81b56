//! The built-in simulated robot as a [`Robot`]: the humanoid and the arm of
//! `robobus demo`, in-process on the wall clock, with the robot file of
//! [`Station::simulated`](crate::station::Station::simulated).

use robobus_sim::wck::{Bus, BusConfig, Model, SimLink};
use robobus_wck::BaudRate;

use super::{Robot, RobotConfig, RobotError};
use crate::demo::{ArmServer, JOINTS, SERVOS};
use crate::wck::WckBus;

impl Robot {
    /// The built-in simulated robot, opened: 16 wCK servos (IDs 0..=15, W1108) on the bus
    /// `sim-wck` as joints `s0`..`s15`, and 7 WHJ30 joints (IDs 1..=7) on `sim-whj` as
    /// `j1`..`j7`, each with limits of ±2 rad, 2 rad/s and 20 rad/s². The simulators run
    /// in this process on the wall clock (the robot's watchdog and speed limits are
    /// measured on it), and stop when the robot is dropped, after its safe stop.
    pub fn simulated() -> Result<Self, RobotError> {
        let config = RobotConfig::from_toml_str(&crate::station::simulated_robot())?;
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
        let wck = WckBus::new(link, BaudRate::B115200)
            .map_err(|source| RobotError::OpenWck {
                bus: "sim-wck".into(),
                source: Box::new(source),
            })?
            .with_device_name("sim-wck");
        let (arm, whj) =
            ArmServer::start((1..=JOINTS).collect(), 11).map_err(|e| RobotError::OpenWhj {
                bus: "sim-whj".into(),
                what: "the simulated arm".into(),
                detail: e.to_string(),
            })?;
        let mut robot = Self::builder(config)
            .wck_bus("sim-wck", wck)
            .whj_bus("sim-whj", whj)
            .open()?;
        robot.keep.push(Box::new(wck_sim));
        robot.keep.push(Box::new(arm));
        Ok(robot)
    }
}
