//! The built-in simulated robot (feature `sim`): the humanoid of [`SERVOS`] wCK servos
//! and the arm of [`JOINTS`] WHJ joints of `robobus demo` and
//! [`Station::simulated`](crate::station::Station::simulated), their robot file, the
//! robot itself as a [`Robot`] (in-process on the wall clock) and the arm a monitor
//! watches without hardware ([`SimArm`]).

use robobus_sim::wck::{Bus, BusConfig, Model, SimLink};
use robobus_wck::BaudRate;

use super::{Robot, RobotConfig, RobotError};
use crate::wck::WckBus;

mod arm;

pub(crate) use arm::ArmServer;
pub use arm::SimArm;

/// wCK servos of the humanoid (IDs 0..SERVOS).
pub const SERVOS: u8 = 16;
/// WHJ joints of the arm (IDs 1..=JOINTS).
pub const JOINTS: u8 = 7;

/// A robot file of the built-in simulators for velocity and effort
/// (`examples/sim_drive.toml`, what `robobus bridge --simulated --robot` takes): servo 0 as
/// the wheel `s0` (position and velocity, its `wheel_speeds` those of
/// [`sim_1108_wheel_speeds`]), WHJ joint 1 as `j1` (position, velocity and effort up to
/// 5 N·m) and joint 2 as `j2` (position only), on the buses `sim-wck` and `sim-whj`. The
/// tests of velocity and effort commands share it.
pub const DRIVE_ROBOT: &str = include_str!("../../examples/sim_drive.toml");

/// What the simulated wCK-1108's wheel levels 1..=15 turn it at, unloaded, rad/s: its
/// no-load speed (400 °/s) times the level's duty `k / 15`, less its gear friction (3 % of
/// the stall torque), as a robot file gives the speeds measured on the robot
/// ([`DRIVE_ROBOT`]'s `wheel_speeds`).
#[must_use]
pub fn sim_1108_wheel_speeds() -> [f64; super::WHEEL_LEVELS] {
    std::array::from_fn(|i| {
        #[allow(clippy::cast_precision_loss)] // 1..=15
        let k = (i + 1) as f64;
        400_f64.to_radians() * (k / 15.0 - 0.03)
    })
}

/// The robot file of [`Robot::simulated`] and
/// [`Station::simulated`](crate::station::Station::simulated): the humanoid's servos `s0`..`s15` on
/// `sim-wck` (centre 127, joint angle 0 there) and the arm's joints `j1`..`j7` on `sim-whj`.
/// Its watchdog allows 0.5 s between commands (the default is 0.1 s): a cycle of
/// [`Robot::simulated`] reads 16 servos at 115200 bit/s
/// (about 45 ms), and the simulators share the caller's processor.
pub(crate) fn simulated_robot() -> String {
    use std::fmt::Write as _;
    let mut t = String::from(
        "watchdog_timeout = 0.5\n\n[buses.sim-wck]\nkind = \"wck-external\"\n\n\
         [buses.sim-whj]\nkind = \"whj-external\"\n",
    );
    let joint = |t: &mut String, name: String, bus: &str, id: u8| {
        let _ = write!(
            t,
            "\n[[joints]]\nname = \"{name}\"\nbus = \"{bus}\"\nid = {id}\nlimits = [-2.0, 2.0]\n\
             max_velocity = 2.0\nmax_acceleration = 20.0\n"
        );
    };
    for id in 0..SERVOS {
        joint(&mut t, format!("s{id}"), "sim-wck", id);
    }
    for id in 1..=JOINTS {
        joint(&mut t, format!("j{id}"), "sim-whj", id);
    }
    t
}

impl Robot {
    /// The built-in simulated robot, opened: 16 wCK servos (IDs 0..=15, W1108) on the bus
    /// `sim-wck` as joints `s0`..`s15`, and 7 WHJ30 joints (IDs 1..=7) on `sim-whj` as
    /// `j1`..`j7`, each with limits of ±2 rad, 2 rad/s and 20 rad/s². The simulators run
    /// in this process on the wall clock (the robot's watchdog and speed limits are
    /// measured on it), and stop when the robot is dropped, after its safe stop.
    pub fn simulated() -> Result<Self, RobotError> {
        Self::simulated_with(RobotConfig::from_toml_str(&simulated_robot())?)
    }

    /// The built-in simulators (as [`Robot::simulated`]) driven through the robot file
    /// `config` instead of the built-in one: its buses must be `sim-wck` (servos 0..=15)
    /// and `sim-whj` (joints 1..=7); its joints any of those, with their own limits and
    /// interfaces.
    pub fn simulated_with(config: RobotConfig) -> Result<Self, RobotError> {
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

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::float_cmp)] // exact: the file's numbers are the function's
mod tests {
    use super::*;

    #[test]
    fn the_drive_robot_files_wheel_speeds_are_the_simulated_servos() {
        let robot = RobotConfig::from_toml_str(DRIVE_ROBOT).unwrap();
        let names: Vec<&str> = robot.joints.iter().map(|j| j.name.as_str()).collect();
        assert_eq!(names, ["s0", "j1", "j2"]);
        let speeds = robot.joints[0].wheel_speeds.as_ref().unwrap().speeds();
        assert_eq!(speeds, &sim_1108_wheel_speeds());
    }
}
