//! The host's protection of a program's own loop on a [`Robot`] (`Robot::command`,
//! `command_velocity`, `command_effort`: what a Python loop calls), on the WHJ
//! simulator's virtual clock: a loop pushing a joint into an obstacle is stopped by the
//! one monitor, the joint disabled (a WHJ30's brake holds it), the error naming the joint,
//! the quantity, the limit and the time; every later command is refused, nothing sent,
//! until `Robot::clear_protection`; with the protection turned off the same loop pushes
//! on. A wCK servo's synchronized move has no reply: its status read every 0.25 s feeds
//! the same monitor, and a loop pushing it into the wCK simulator's hand is stopped, the
//! servo passive.

#![allow(clippy::unwrap_used, clippy::panic, clippy::float_cmp)]

use crate::wck_support;
use crate::whj_common;

use std::time::Duration;

use robobus::error::ErrorKind;
use robobus::ops::protect::{Action, Check, Fault};
use robobus::robot::{Interface, Robot, RobotConfig, RobotError};
use robobus_sim::whj::{JointState, Obstacle, WhjSimHandle};

/// A robot of one WHJ30 joint `elbow` (ID 1) with `extra` lines (interfaces, effort).
fn rig(extra: &str) -> (Robot, WhjSimHandle) {
    let text = format!(
        r#"
        watchdog_timeout = 0.2
        [buses.arm]
        kind = "whj-external"
        safe_state = "hold"
        [[joints]]
        name = "elbow"
        bus = "arm"
        id = 1
        limits = [-2.0, 2.0]
        max_velocity = 1.5
        max_acceleration = 20.0
        {extra}
        "#
    );
    let config = RobotConfig::from_toml_str(&text).unwrap();
    let (arm, whj) = whj_common::virtual_bus(whj_common::chain(1));
    let robot = Robot::builder(config).whj_bus("arm", arm).open().unwrap();
    (robot, whj)
}

const SPEED_AND_EFFORT: &str = r#"interfaces = ["position", "velocity", "effort"]
        max_effort = 5.0"#;

/// A stop at 5 degrees in the way of the joint turning up.
fn block(sim: &WhjSimHandle) {
    sim.with_bus(|b| {
        b.joint_mut(1)
            .unwrap()
            .set_obstacle(Some(Obstacle::above(5.0)));
    });
}

fn elbow(sim: &WhjSimHandle) -> JointState {
    sim.with_bus(|b| b.joint(1).unwrap().state())
}

fn frames(sim: &WhjSimHandle) -> u64 {
    sim.with_bus(|b| b.joint(1).unwrap().frames_handled())
}

/// Calls `command(robot, t)` every 10 ms (robot clock, `t` seconds since the first) for
/// at most `seconds`; the first error and when it came (s since the first command).
fn loop_until_error(
    robot: &mut Robot,
    seconds: f64,
    mut command: impl FnMut(&mut Robot, f64) -> Result<(), RobotError>,
) -> Option<(RobotError, f64)> {
    let start = robot.now();
    loop {
        let t = (robot.now() - start).as_secs_f64();
        if t >= seconds {
            return None;
        }
        if let Err(e) = command(robot, t) {
            return Some((e, t));
        }
        robot.sleep(Duration::from_millis(10));
    }
}

/// The protection stop `e` must be (kind device, [`RobotError::Protection`]): its fault,
/// checked to be a `check` of `quantity` on `joint`, and what the stop did.
fn protection_stop<'e>(
    e: &'e RobotError,
    (joint, check, quantity): (&str, Check, &str),
) -> (&'e Fault, &'e str) {
    assert_eq!(e.kind(), ErrorKind::Device, "{e}");
    let RobotError::Protection { fault, stopped } = e else {
        panic!("{e}");
    };
    assert_eq!(
        (fault.joint.as_str(), fault.check, fault.quantity),
        (joint, check, quantity),
        "{e}"
    );
    (fault, stopped)
}

/// A position loop: a ramp up at 1 rad/s from 0 to 1 rad (through the stop at 5 deg).
fn ramp(robot: &mut Robot, t: f64) -> Result<(), RobotError> {
    robot.command(&[t.min(1.0)]).map(drop)
}

#[test]
fn a_position_loop_into_an_obstacle_is_stopped_naming_the_joint_quantity_limit_and_time() {
    let (mut robot, sim) = rig("");
    assert!(robot.protection(), "on by default");
    block(&sim);
    let (e, t) = loop_until_error(&mut robot, 3.0, ramp).expect("the loop was not stopped");
    // The set-point reaches the stop at 0.087 s; the current the WHJ30's rated 7.8 A soon
    // after, and the stall time (0.3 s) later the loop is stopped.
    let (fault, stopped) = protection_stop(&e, ("elbow", Check::Stall, "current_a"));
    assert_eq!(fault.limit, 7.8, "{e}");
    assert_eq!(fault.action, Action::Stop);
    // At 0.48 s on the robot's clock (it opened at 0), as much into the loop.
    assert!((0.47..0.49).contains(&fault.at_s), "{e}");
    assert!((0.47..0.49).contains(&t), "stopped at {t} s");
    let text = e.to_string();
    assert!(
        text.starts_with("elbow: stall protection: current ")
            && text.contains(" A reached the limit 7.8 A at ")
            && text.ends_with(
                "; its drive disabled (its brake holds it: holding would keep it pushing or \
                 heating); every later command is refused until Robot::clear_protection"
            ),
        "{text}"
    );
    assert!(stopped.starts_with("its drive disabled"), "{stopped}");
    // Disabled: its brake holds it short of the far side of the stop, no current pushes.
    let st = elbow(&sim);
    assert!(!st.enabled && st.brake_locked, "{st:?}");
    assert!(st.current_a.abs() < 1e-9, "{st:?}");
    assert!(st.position_deg < 10.0, "{st:?}");
    assert_eq!(robot.protection_stops().len(), 1);
    assert_eq!(robot.protection_events().last(), Some(fault));

    // Every later command is refused, nothing sent, naming the stop and the way out.
    let before = frames(&sim);
    let again = robot.command(&[0.0]).unwrap_err();
    assert_eq!(again.kind(), ErrorKind::Refused, "{again}");
    assert!(
        matches!(&again, RobotError::ProtectionStopped { fault: f } if **f == *fault),
        "{again}"
    );
    assert!(
        again
            .to_string()
            .ends_with("nothing sent; call Robot::clear_protection once the cause is cleared"),
        "{again}"
    );
    let switch = robot.set_interface(0, Interface::Position).unwrap_err();
    assert!(
        matches!(switch, RobotError::ProtectionStopped { .. }),
        "{switch}"
    );
    assert_eq!(frames(&sim), before, "nothing sent");

    // Cleared (the obstacle gone), the joint is enabled and takes commands again.
    sim.with_bus(|b| b.joint_mut(1).unwrap().set_obstacle(None));
    let cleared = robot.clear_protection().unwrap();
    assert_eq!(cleared.len(), 1);
    assert!(robot.protection_stops().is_empty());
    assert!(elbow(&sim).enabled);
    let at = robot.read().unwrap()[0].position_rad;
    robot.command(&[at]).unwrap();
}

#[test]
fn with_the_protection_turned_off_the_same_loop_pushes_on_into_the_obstacle() {
    let (mut robot, sim) = rig("");
    robot.set_protection(false);
    assert!(!robot.protection());
    block(&sim);
    let got = loop_until_error(&mut robot, 1.0, ramp);
    assert!(got.is_none(), "{:?}", got.map(|g| g.0.to_string()));
    // Still enabled and pushing against the stop with more than the rated current.
    let st = elbow(&sim);
    assert!(st.enabled && st.current_a.abs() > 7.8, "{st:?}");
    assert!(robot.protection_events().is_empty());
}

#[test]
fn a_velocity_loop_into_an_obstacle_is_stopped_and_the_joint_goes_back_to_position() {
    let (mut robot, sim) = rig(SPEED_AND_EFFORT);
    robot.set_interface(0, Interface::Velocity).unwrap();
    block(&sim);
    let (e, _) = loop_until_error(&mut robot, 3.0, |r, _| r.command_velocity(&[0.5]).map(drop))
        .expect("the loop was not stopped");
    let (fault, _) = protection_stop(&e, ("elbow", Check::Stall, "current_a"));
    // At 0.63 s: the speed set-point ramps up at 20 rad/s², the joint reaches the stop at
    // about 0.2 s, its current the stall current soon after.
    assert!((0.62..0.65).contains(&fault.at_s), "{e}");
    // Back on position (mode 3), disabled, its brake holding it.
    let st = elbow(&sim);
    assert_eq!(st.mode, 3, "{st:?}");
    assert!(!st.enabled && st.brake_locked, "{st:?}");
    assert_eq!(robot.interfaces(), [Interface::Position]);
    let again = robot.command_velocity(&[0.0]).unwrap_err();
    assert!(
        matches!(again, RobotError::ProtectionStopped { .. }),
        "{again}"
    );
}

#[test]
fn an_effort_loop_on_a_free_joint_is_stopped_past_its_max_velocity() {
    let (mut robot, sim) = rig(SPEED_AND_EFFORT);
    robot.set_interface(0, Interface::Effort).unwrap();
    let (e, _) = loop_until_error(&mut robot, 3.0, |r, _| r.command_effort(&[4.0]).map(drop))
        .expect("the loop was not stopped");
    let (fault, _) = protection_stop(&e, ("elbow", Check::Speed, "speed_deg_s"));
    assert_eq!(fault.limit, 1.5_f64.to_degrees());
    assert!((0.12..0.15).contains(&fault.at_s), "{e}");
    let st = elbow(&sim);
    assert!(!st.enabled && st.brake_locked, "{st:?}");
    assert_eq!(st.mode, 3, "{st:?}");
}

#[test]
fn an_effort_loop_with_the_protection_off_runs_the_free_joint_past_its_max_velocity() {
    let (mut robot, sim) = rig(SPEED_AND_EFFORT);
    robot.set_protection(false);
    robot.set_interface(0, Interface::Effort).unwrap();
    let got = loop_until_error(&mut robot, 1.0, |r, _| r.command_effort(&[4.0]).map(drop));
    assert!(got.is_none(), "{:?}", got.map(|g| g.0.to_string()));
    let st = elbow(&sim);
    assert!(st.enabled, "{st:?}");
    assert!(st.speed_rpm.abs() * 6.0 > 1.5_f64.to_degrees(), "{st:?}");
}

#[test]
fn a_hot_joint_in_a_loop_is_derated_then_stopped_at_its_temperatures() {
    let (mut robot, sim) = rig("");
    let heat = |c: f64| {
        sim.with_bus(|b| b.joint_mut(1).unwrap().set_winding_temperature(c));
    };
    heat(81.0);
    // A ramp at 1 rad/s: derated, the joint's set-point moves at half its 1.5 rad/s.
    let got = loop_until_error(&mut robot, 0.5, ramp);
    assert!(got.is_none(), "{:?}", got.map(|g| g.0.to_string()));
    // The first reading at 81 °C is past the derating temperature: one event.
    let events = robot.protection_events();
    assert_eq!(events.len(), 1, "{events:?}");
    assert_eq!(
        (events[0].check, events[0].action, events[0].limit),
        (Check::Thermal, Action::Derate, 80.0)
    );
    // Half of 1.5 rad/s, under the ramp's 1 rad/s: 0.5 s took it to about 0.37 rad,
    // not to the ramp's 0.5.
    let at = robot.read().unwrap()[0].position_rad;
    assert!((0.3..0.4).contains(&at), "at {at} rad");
    heat(86.0);
    let (e, _) = loop_until_error(&mut robot, 1.0, ramp).expect("not stopped");
    let RobotError::Protection { fault, .. } = &e else {
        panic!("{e}");
    };
    assert_eq!(
        (fault.check, fault.quantity, fault.limit),
        (Check::Thermal, "temperature_c", 85.0),
        "{e}"
    );
    assert!(!elbow(&sim).enabled);
}

/// A robot of one wCK servo `knee` (ID 0, on a passive bus), its own over-load at its
/// highest (1800 mA, so only the host can stop it), gripped by the simulator's hand.
fn gripped_knee() -> (Robot, wck_support::Sim) {
    gripped_wck("")
}

/// [`gripped_knee`] with `extra` lines for the joint.
fn gripped_wck(extra: &str) -> (Robot, wck_support::Sim) {
    let config = RobotConfig::from_toml_str(&format!(
        r#"
        watchdog_timeout = 0.2
        [buses.legs]
        kind = "wck-external"
        safe_state = "passive"
        [[joints]]
        name = "knee"
        bus = "legs"
        id = 0
        limits = [-1.0, 1.0]
        max_velocity = 8.0
        max_acceleration = 100.0
        {extra}
        "#,
    ))
    .unwrap();
    let mut sim = wck_support::serve_ids(&[0]);
    sim.handle.with_bus(|b| {
        let s = b.servo_mut(0).unwrap();
        let e = robobus_sim::wck::Eeprom {
            overload: robobus_wck::Overload::new(199).unwrap(),
            ..*s.eeprom()
        };
        s.set_eeprom(e);
        s.hold(true);
    });
    let robot = Robot::builder(config)
        .wck_bus("legs", sim.bus())
        .open()
        .unwrap();
    (robot, sim)
}

#[test]
fn a_position_loop_pushing_a_gripped_wck_servo_is_stopped_naming_it_and_left_passive() {
    let (mut robot, sim) = gripped_knee();
    let (e, t) = loop_until_error(&mut robot, 3.0, |r, t| r.command(&[t.min(0.5)]).map(drop))
        .expect("the loop was not stopped");
    let (fault, stopped) = protection_stop(&e, ("knee", Check::Stall, "current_a"));
    assert_eq!(fault.limit, 0.2, "{e}");
    // Its status is read every 0.25 s: the first read after the grip with the target
    // away (0.25 s) sees 1.2 A pushing, and the stall time sized to that period (0.5 s,
    // two reads) later, at the read of 0.75 s, the loop is stopped.
    assert!((0.74..0.77).contains(&fault.at_s), "{e}");
    assert!((0.74..0.77).contains(&t), "stopped at {t} s");
    assert!(
        e.to_string()
            .starts_with("knee: stall protection: current 1.20 A reached the limit 0.2 A at 0.7"),
        "{e}"
    );
    assert_eq!(
        stopped,
        "passive (its torque off: holding would keep it pushing)"
    );
    sim.handle.with_bus(|b| {
        let s = b.servo(0).unwrap();
        assert_eq!(s.mode(), robobus_sim::wck::Mode::Passive);
        assert_eq!(
            s.overload_trips(),
            0,
            "the host stopped it, not its own protection"
        );
    });
    let again = robot.command(&[0.0]).unwrap_err();
    assert!(
        matches!(again, RobotError::ProtectionStopped { .. }),
        "{again}"
    );
}

#[test]
fn with_the_protection_off_a_loop_pushes_on_into_the_gripped_wck_servo() {
    let (mut robot, sim) = gripped_knee();
    robot.set_protection(false);
    let got = loop_until_error(&mut robot, 2.0, |r, t| r.command(&[t.min(0.5)]).map(drop));
    assert!(got.is_none(), "{:?}", got.map(|g| g.0.to_string()));
    sim.handle.with_bus(|b| {
        assert_ne!(b.servo(0).unwrap().mode(), robobus_sim::wck::Mode::Passive);
    });
    assert!(robot.protection_events().is_empty());
}

#[test]
fn a_velocity_loop_turning_a_gripped_wck_wheel_is_stopped_and_it_goes_back_to_position() {
    let (mut robot, sim) = gripped_wck(&format!(
        "interfaces = [\"position\", \"velocity\"]\nwheel_speeds = {:?}",
        robobus::robot::simulated::sim_1108_wheel_speeds()
    ));
    robot.set_interface(0, Interface::Velocity).unwrap();
    let (e, t) = loop_until_error(&mut robot, 3.0, |r, _| r.command_velocity(&[2.0]).map(drop))
        .expect("the loop was not stopped");
    let (fault, stopped) = protection_stop(&e, ("knee", Check::Stall, "current_a"));
    // Read every 0.25 s: the first read is where the wheel's speed is measured from, the
    // second (0.25 s) sees it still under 0.67 A, and the stall time sized to the period
    // (0.5 s) later, at the read of 0.75 s, the loop is stopped.
    assert!((0.76..0.79).contains(&fault.at_s), "{e}");
    assert!((0.76..0.79).contains(&t), "stopped at {t} s");
    assert_eq!(
        stopped,
        "passive (its torque off: holding would keep it pushing)"
    );
    assert_eq!(robot.interfaces(), [Interface::Position]);
    sim.handle.with_bus(|b| {
        assert_eq!(b.servo(0).unwrap().mode(), robobus_sim::wck::Mode::Passive);
    });
}
