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

/// The host's reach for a WHJ joint's position set-point: at most this share of its bus's
/// step limit from where the joint last said it was (what `robot play` and the robot's
/// commands hold a set-point back to).
const WHJ_REACH_OF_STEP: f64 = 0.8;

/// `robot play`'s default rate, Hz.
const PLAY_RATE_HZ: f64 = 50.0;

/// What the built-in robot file lets its WHJ joints (simulated WHJ30s at their factory
/// settings) do, as (`max_velocity` rad/s, `max_acceleration` rad/s²): no more than such a
/// joint follows from rest when `robot play` drives it at its default 50 Hz, each
/// set-point within the host's reach (0.8 × the bus's default 5° step limit) of where the
/// joint last said it was.
///
/// A joint asked to go from rest to `v` is behind the set-point, at its next feedback, by
/// two ticks of `v` (its feedback is a tick old, the set-point a tick ahead) and by the
/// `v² / 2A` its reference loses reaching `v` at its acceleration limit `A` (register
/// 0x42, `LIT_MAX_ACC`: 500 rpm/s at the factory, the table's default, which the
/// simulator follows). `max_velocity` is the largest `v` within the reach (1.33 rad/s,
/// 76 °/s); `max_acceleration` half of `A` (26.2 rad/s²), so that the reference, which
/// also brakes toward each tick's set-point, keeps up with a lead-in.
#[must_use]
pub fn whj_follows() -> (f64, f64) {
    use robobus_whj::registers::{RegisterInfo, addr};
    let counts = RegisterInfo::by_addr(addr::LIT_MAX_ACC)
        .and_then(|r| r.init)
        .unwrap_or_default();
    let rpm_s = f64::from(counts) * robobus_whj::units::ACCELERATION_RPM_S_PER_COUNT;
    let a = rpm_s * std::f64::consts::TAU / 60.0;
    let reach = WHJ_REACH_OF_STEP
        * crate::whj::JointBusConfig::default()
            .step_limit_deg
            .to_radians();
    // v²/(2A) + 2v/r = reach, for v.
    let lag = 2.0 / PLAY_RATE_HZ;
    let v = a * ((lag * lag + 2.0 * reach / a).sqrt() - lag);
    (v, a / 2.0)
}

/// The robot file of [`Robot::simulated`] and
/// [`Station::simulated`](crate::station::Station::simulated): the humanoid's servos `s0`..`s15` on
/// `sim-wck` (centre 127, joint angle 0 there; 2 rad/s, 20 rad/s²) and the arm's joints
/// `j1`..`j7` on `sim-whj` (at the speed and acceleration of [`whj_follows`]), each within
/// ±2 rad. Its watchdog allows 0.5 s between commands (the default is 0.1 s): a cycle of
/// [`Robot::simulated`] reads 16 servos at 115200 bit/s
/// (about 45 ms), and the simulators share the caller's processor.
pub(crate) fn simulated_robot() -> String {
    robot_file(whj_follows())
}

/// The built-in robot file with its WHJ joints at (`max_velocity`, `max_acceleration`).
fn robot_file(whj: (f64, f64)) -> String {
    use std::fmt::Write as _;
    let mut t = String::from(
        "watchdog_timeout = 0.5\n\n[buses.sim-wck]\nkind = \"wck-external\"\n\n\
         [buses.sim-whj]\nkind = \"whj-external\"\n",
    );
    let joint = |t: &mut String, name: String, bus: &str, id: u8, (v, a): (f64, f64)| {
        let _ = write!(
            t,
            "\n[[joints]]\nname = \"{name}\"\nbus = \"{bus}\"\nid = {id}\nlimits = [-2.0, 2.0]\n\
             max_velocity = {v:?}\nmax_acceleration = {a:?}\n"
        );
    };
    for id in 0..SERVOS {
        joint(&mut t, format!("s{id}"), "sim-wck", id, (2.0, 20.0));
    }
    for id in 1..=JOINTS {
        joint(&mut t, format!("j{id}"), "sim-whj", id, whj);
    }
    t
}

impl Robot {
    /// The built-in simulated robot, opened: 16 wCK servos (IDs 0..=15, W1108) on the bus
    /// `sim-wck` as joints `s0`..`s15` (2 rad/s, 20 rad/s²), and 7 WHJ30 joints (IDs
    /// 1..=7) on `sim-whj` as `j1`..`j7` (as fast as [`whj_follows`]: 1.33 rad/s,
    /// 26.2 rad/s²), each within ±2 rad. The simulators run
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
    use serde_json::{Value, json};

    use super::*;
    use crate::catalogue::{Request, run};
    use crate::ops::{Control, OpError};
    use crate::station::Station;

    /// `trajectory` played by `robot.play` at 50 Hz (pre-flown) on the built-in simulators
    /// through the built-in file, or through it with its WHJ joints at `whj`, joint 1
    /// enabled in position mode at 0°: the report, or the refusal.
    fn play(whj: Option<(f64, f64)>, trajectory: &str) -> Result<Value, OpError> {
        let (mut station, _wck, _whj) = Station::simulated_with_handles().unwrap();
        if let Some(whj) = whj {
            station
                .set_robot(RobotConfig::from_toml_str(&robot_file(whj)).unwrap())
                .unwrap();
        }
        let req = |v: Value| -> Request { serde_json::from_value(v).unwrap() };
        for r in [
            json!({"op": "whj.mode", "joints": "1", "mode": "position"}),
            json!({"op": "whj.enable", "joints": "1"}),
        ] {
            run(&station, &req(r), &mut Control::none()).unwrap();
        }
        let play = json!({"op": "robot.play", "trajectory": trajectory, "rate_hz": 50});
        run(&station, &req(play), &mut Control::none())
            .map(|report| serde_json::to_value(report).unwrap())
    }

    /// j1 from rest to `deg_s` at once, for half a second, then held.
    fn jump(deg_s: f64) -> String {
        format!("time_s,j1\n0,0\n0.5,{}\n1,{}\n", deg_s / 2.0, deg_s / 2.0)
    }

    /// j1 held `deg` away from where it stands: the play is its lead-in.
    fn away(deg: f64) -> String {
        format!("time_s,j1\n0,{deg}\n1,{deg}\n")
    }

    #[test]
    fn the_built_in_whj_joints_are_as_fast_as_the_simulated_joint_follows_from_rest() {
        let (v, a) = whj_follows();
        // From the factory acceleration limit (500 rpm/s) and the 4° reach at 50 Hz.
        assert!((v - 1.3257).abs() < 1e-4, "{v}");
        assert!(
            (a - 500.0 * std::f64::consts::TAU / 60.0 / 2.0).abs() < 1e-12,
            "{a}"
        );
        let robot = RobotConfig::from_toml_str(&simulated_robot()).unwrap();
        let j1 = robot.joints.iter().find(|j| j.name == "j1").unwrap();
        // What the built-in file allows its WHJ joints at its limits passes the
        // pre-flight, nothing held back: a jump from rest to max_velocity, a lead-in
        // limited by the speed (100°) and one limited by the acceleration (8°).
        let vmax = j1.max_velocity.to_degrees() - 1e-6;
        for trajectory in [jump(vmax), away(100.0), away(8.0)] {
            let p = play(None, &trajectory).unwrap();
            assert_eq!(p["failed"], Value::Null, "{trajectory}: {p:#}");
            assert_eq!(p["results"][0]["limited"], 0, "{trajectory}: {p:#}");
            assert!(p["summary"]["preflight"].is_object(), "{p:#}");
        }
        for j in &robot.joints {
            let claimed = (j.max_velocity, j.max_acceleration);
            if j.name.starts_with('j') {
                assert_eq!(claimed, (v, a), "{}", j.name);
            } else {
                assert_eq!(claimed, (2.0, 20.0), "{}", j.name);
            }
        }
    }

    #[test]
    fn a_file_claiming_more_than_the_whj_joint_follows_is_refused_naming_tick_joint_and_reason() {
        // The lead-in of 15° within 2 rad/s and 20 rad/s² (what the built-in file once
        // claimed) peaks at 93°/s: the joint lags more than the reach at tick 7.
        let e = play(Some((2.0, 20.0)), &away(15.0)).unwrap_err();
        let OpError::Preflight(r) = &e else {
            panic!("{e:?}")
        };
        assert_eq!((r.frame, r.at_s), (7, 0.14), "{r:?}");
        assert_eq!(r.joint, "j1 (joint 1 on sim-whj)");
        assert!(
            r.reason.starts_with(
                "the joint lagged behind the plan: its set-point was clamped 0.3125 deg short"
            ),
            "{r:?}"
        );
        // A jump from rest to a fifth more than the built-in max_velocity: refused too.
        let (v, a) = whj_follows();
        let fast = v * 1.2;
        let e = play(Some((fast, a)), &jump(fast.to_degrees() - 1e-6)).unwrap_err();
        assert!(
            matches!(&e, OpError::Preflight(r) if r.joint.starts_with("j1 ")),
            "{e:?}"
        );
    }

    #[test]
    fn the_drive_robot_files_wheel_speeds_are_the_simulated_servos() {
        let robot = RobotConfig::from_toml_str(DRIVE_ROBOT).unwrap();
        let names: Vec<&str> = robot.joints.iter().map(|j| j.name.as_str()).collect();
        assert_eq!(names, ["s0", "j1", "j2"]);
        let speeds = robot.joints[0].wheel_speeds.as_ref().unwrap().speeds();
        assert_eq!(speeds, &sim_1108_wheel_speeds());
    }
}
