//! A robot's velocity and effort interfaces against the simulators on their virtual
//! clocks: a wCK servo in wheel mode turning at the asked speed, a WHJ joint in speed mode
//! at the asked speed and in current mode at the asked current, the checked interface
//! switch (refused, nothing sent, where the file gives a joint no such interface or the
//! joint moves), the limits and ramps, and the watchdog's safe state on velocity silence.

#![allow(clippy::unwrap_used, clippy::panic, clippy::float_cmp)]

use crate::wck_support;
use crate::whj_common;

use std::f64::consts::TAU;
use std::time::Duration;

use robobus::error::ErrorKind;
use robobus::robot::simulated::sim_1108_wheel_speeds;
use robobus::robot::{Interface, LimitKind, Robot, RobotConfig, RobotError, StopCause};
use robobus_sim::wck::Mode;
use robobus_sim::whj::WhjSimHandle;

fn file(watchdog_s: f64, joints: &str) -> String {
    format!(
        r#"
        watchdog_timeout = {watchdog_s}
        [buses.legs]
        kind = "wck-external"
        safe_state = "passive"
        [buses.arm]
        kind = "whj-external"
        safe_state = "hold"
        {joints}
        "#
    )
}

/// A wheel `wheel` (wCK 0, position and velocity, the simulated servo's wheel speeds as
/// in `robobus::robot::simulated::DRIVE_ROBOT`) and a WHJ joint `elbow` (1) with
/// `interfaces`.
fn joints(interfaces: &str) -> String {
    format!(
        r#"
        [[joints]]
        name = "wheel"
        bus = "legs"
        id = 0
        limits = [-1.0, 1.0]
        max_velocity = 8.0
        max_acceleration = 100.0
        interfaces = ["position", "velocity"]
        wheel_speeds = {:?}

        [[joints]]
        name = "elbow"
        bus = "arm"
        id = 1
        limits = [-2.0, 2.0]
        max_velocity = 1.5
        max_acceleration = 20.0
        {interfaces}
        "#,
        sim_1108_wheel_speeds()
    )
}

const SPEED_AND_EFFORT: &str = r#"interfaces = ["position", "velocity", "effort"]
        max_effort = 5.0"#;

struct Rig {
    // Fields drop in order: the robot first (its safe stop still reaches the simulators).
    robot: Robot,
    wck: wck_support::Sim,
    whj: WhjSimHandle,
}

fn rig(text: &str) -> Rig {
    let config = RobotConfig::from_toml_str(text).unwrap();
    let mut wck = wck_support::serve_ids(&[0]);
    let (arm, whj) = whj_common::virtual_bus(whj_common::chain(1));
    let robot = Robot::builder(config)
        .wck_bus("legs", wck.bus())
        .whj_bus("arm", arm)
        .open()
        .unwrap();
    Rig { robot, wck, whj }
}

/// The simulated servo's shaft angle, unwrapped, rad.
fn wheel_angle(rig: &Rig) -> f64 {
    rig.wck.with_bus(|b| {
        let s = b.servo(b.slot_of(0).unwrap()).unwrap();
        #[allow(clippy::cast_precision_loss)] // a few rotations
        let turns = s.rotations() as f64;
        (turns * 360.0 + s.angle()).to_radians()
    })
}

fn wheel_mode(rig: &Rig) -> Mode {
    rig.wck
        .with_bus(|b| b.servo(b.slot_of(0).unwrap()).unwrap().mode())
}

fn elbow(rig: &Rig) -> robobus_sim::whj::JointState {
    rig.whj.with_bus(|b| b.joint(1).unwrap().state())
}

/// Frames the simulated WHJ joint handled, commands the wCK client sent.
fn traffic(rig: &Rig) -> (u64, u64) {
    (
        rig.whj.with_bus(|b| b.joint(1).unwrap().frames_handled()),
        rig.robot
            .with_wck_bus("legs", |b| b.stats().commands)
            .unwrap(),
    )
}

/// Commands `targets` (each joint in its interface's unit) every 10 ms for `time`.
fn hold_velocity(robot: &mut Robot, targets: &[f64], time: Duration) {
    let end = robot.now() + time;
    while robot.now() < end {
        robot.command_velocity(targets).unwrap();
        robot.sleep(Duration::from_millis(10));
    }
}

#[test]
fn a_wck_wheel_turns_at_the_asked_speed() {
    let mut rig = rig(&file(0.2, &joints(SPEED_AND_EFFORT)));
    rig.robot.set_interface(1, Interface::Velocity).unwrap();
    rig.robot.set_interface(0, Interface::Velocity).unwrap();
    assert_eq!(
        rig.robot.interfaces(),
        [Interface::Velocity, Interface::Velocity]
    );
    // Entering wheel mode stops the wheel: level 0.
    assert_eq!(wheel_mode(&rig), Mode::Wheel);

    let level_7 = sim_1108_wheel_speeds()[6];
    // Up to speed (100 rad/s² at 10 ms cycles), then one second measured.
    hold_velocity(&mut rig.robot, &[level_7, 0.0], Duration::from_millis(500));
    let (t0, a0) = (rig.robot.now(), wheel_angle(&rig));
    hold_velocity(&mut rig.robot, &[level_7, 0.0], Duration::from_secs(1));
    let rate = (wheel_angle(&rig) - a0) / (rig.robot.now() - t0).as_secs_f64();
    assert!(
        (rate - level_7).abs() < 0.01 * level_7,
        "asked {level_7} rad/s, turned at {rate} rad/s"
    );

    // A speed between two levels goes out as the nearest (2.9 rad/s: level 7, 3.049).
    let report = rig.robot.command_velocity(&[2.9, 0.0]).unwrap();
    assert_eq!(report.sent_rad[0], level_7);
    assert_eq!(report.interfaces[0], Interface::Velocity);

    // Backwards: clockwise, the angle going down.
    hold_velocity(&mut rig.robot, &[-level_7, 0.0], Duration::from_millis(500));
    let (t0, a0) = (rig.robot.now(), wheel_angle(&rig));
    hold_velocity(&mut rig.robot, &[-level_7, 0.0], Duration::from_secs(1));
    let rate = (wheel_angle(&rig) - a0) / (rig.robot.now() - t0).as_secs_f64();
    assert!((rate + level_7).abs() < 0.01 * level_7, "turned at {rate}");
}

#[test]
fn a_wheel_speed_past_the_top_level_is_refused_and_nothing_is_sent() {
    let mut rig = rig(&file(0.2, &joints(SPEED_AND_EFFORT)));
    rig.robot.set_interface(0, Interface::Velocity).unwrap();
    rig.robot.set_interface(1, Interface::Velocity).unwrap();
    let top = *sim_1108_wheel_speeds().last().unwrap();
    let before = traffic(&rig);
    // Within max_velocity (8 rad/s), past the top level's 6.77 rad/s by more than half
    // the last level's step (0.47 rad/s): the servo cannot turn that fast.
    let err = rig.robot.command_velocity(&[top + 0.3, 0.0]).unwrap_err();
    let RobotError::Target {
        joint, interface, ..
    } = &err
    else {
        panic!("{err}");
    };
    assert_eq!((joint.as_str(), *interface), ("wheel", Interface::Velocity));
    assert_eq!(err.kind(), ErrorKind::BadInput);
    assert!(err.to_string().contains("nothing sent"), "{err}");
    assert_eq!(traffic(&rig), before);
}

#[test]
fn a_whj_joint_in_speed_mode_turns_at_the_asked_speed() {
    let mut rig = rig(&file(0.2, &joints(SPEED_AND_EFFORT)));
    rig.robot.set_interface(1, Interface::Velocity).unwrap();
    let s = elbow(&rig);
    assert_eq!((s.mode, s.target_speed), (2, 0), "speed mode, at rest");
    rig.robot.set_interface(0, Interface::Velocity).unwrap();

    hold_velocity(&mut rig.robot, &[0.0, 0.6], Duration::from_millis(300));
    let (t0, a0) = (rig.robot.now(), elbow(&rig).position_deg.to_radians());
    hold_velocity(&mut rig.robot, &[0.0, 0.6], Duration::from_millis(500));
    let rate = (elbow(&rig).position_deg.to_radians() - a0) / (rig.robot.now() - t0).as_secs_f64();
    assert!(
        (rate - 0.6).abs() < 0.006,
        "asked 0.6 rad/s, turned at {rate}"
    );
    // The target register holds 0.6 rad/s in 0.002 RPM counts.
    let rpm = f64::from(elbow(&rig).target_speed) * 0.002;
    assert!(
        (rpm * TAU / 60.0 - 0.6).abs() < 0.002 * TAU / 60.0,
        "{rpm} RPM"
    );
    // The robot reads it back in rad/s.
    let read = rig.robot.read_joint(1).unwrap().velocity_rad_s.unwrap();
    assert!((read - 0.6).abs() < 0.01, "{read}");
}

#[test]
fn a_whj_joint_in_current_mode_takes_the_asked_effort_as_its_current() {
    let mut rig = rig(&file(0.2, &joints(SPEED_AND_EFFORT)));
    rig.robot.set_interface(1, Interface::Effort).unwrap();
    let s = elbow(&rig);
    assert_eq!(
        (s.mode, s.target_current),
        (1, 0),
        "current mode, no current"
    );

    // The WHJ30's torque constant: 30 N·m rated at 7.8 A.
    let kt = 30.0 / 7.8;
    let mut report = None;
    for _ in 0..10 {
        report = Some(
            rig.robot
                .command_targets(&[
                    robobus::robot::Target::Position(0.0),
                    robobus::robot::Target::Effort(1.0),
                ])
                .unwrap(),
        );
        rig.robot.sleep(Duration::from_millis(10));
    }
    let report = report.unwrap();
    // 1 N·m is 260 mA (0.26 A at 3.846 N·m/A), sent in 1 mA counts.
    assert_eq!(elbow(&rig).target_current, 260);
    assert!((report.sent_rad[1] - 0.260 * kt).abs() < 1e-9, "{report:?}");
    assert_eq!(report.interfaces, [Interface::Position, Interface::Effort]);
    let amps = elbow(&rig).current_a;
    assert!((amps - 0.26).abs() < 0.01, "the joint draws {amps} A");
    let read = rig.robot.read_joint(1).unwrap().current_a.unwrap();
    assert!((read - 0.26).abs() < 0.01, "read {read} A");
}

#[test]
fn an_interface_the_file_does_not_give_a_joint_is_refused_and_nothing_is_sent() {
    let mut rig = rig(&file(0.2, &joints("")));
    let before = traffic(&rig);
    let err = rig.robot.set_interface(1, Interface::Velocity).unwrap_err();
    assert!(
        matches!(&err, RobotError::NoInterface { joint, interface: Interface::Velocity, has }
            if joint == "elbow" && has == "position"),
        "{err}"
    );
    assert_eq!(err.kind(), ErrorKind::BadInput);
    let err = rig.robot.set_interface(0, Interface::Effort).unwrap_err();
    assert!(
        matches!(&err, RobotError::NoInterface { joint, has, .. }
            if joint == "wheel" && has == "position, velocity"),
        "{err}"
    );
    // A velocity for joints on their position interface is refused whole.
    let err = rig.robot.command_velocity(&[0.0, 0.5]).unwrap_err();
    assert!(
        matches!(&err, RobotError::WrongInterface { joint, asked: Interface::Velocity, active: Interface::Position }
            if joint == "wheel"),
        "{err}"
    );
    assert_eq!(err.kind(), ErrorKind::Refused);
    assert_eq!(traffic(&rig), before);
    assert_eq!(elbow(&rig).mode, 3, "still in position mode");
    assert_eq!(wheel_mode(&rig), Mode::Passive, "as it was opened");
    assert_eq!(rig.robot.interfaces(), [Interface::Position; 2]);
}

#[test]
fn a_joint_that_moves_cannot_switch_its_interface() {
    let mut rig = rig(&file(0.2, &joints(SPEED_AND_EFFORT)));
    rig.robot.set_interface(1, Interface::Velocity).unwrap();
    rig.robot.set_interface(0, Interface::Velocity).unwrap();
    hold_velocity(&mut rig.robot, &[0.0, 0.5], Duration::from_millis(200));
    let before = traffic(&rig);
    let err = rig.robot.set_interface(1, Interface::Effort).unwrap_err();
    assert!(
        matches!(&err, RobotError::Moving { joint, from: Interface::Velocity, to: Interface::Effort, .. }
            if joint == "elbow"),
        "{err}"
    );
    assert_eq!(err.kind(), ErrorKind::Refused);
    assert_eq!(traffic(&rig), before, "nothing sent");
    // Brought to rest (ramped down at 20 rad/s²), it switches: to position, holding
    // where it stopped.
    hold_velocity(&mut rig.robot, &[0.0, 0.0], Duration::from_millis(200));
    rig.robot.set_interface(1, Interface::Position).unwrap();
    let s = elbow(&rig);
    assert_eq!(s.mode, 3);
    let at = rig.robot.read_joint(1).unwrap().position_rad;
    assert!(at > 0.05, "it had turned: {at}");
    assert!(
        (f64::from(s.target_position) * 1e-4 - at.to_degrees()).abs() < 0.01,
        "holds where it stands: target {} counts, at {at} rad",
        s.target_position
    );
}

#[test]
fn velocities_are_clamped_ramped_and_stop_short_of_a_soft_limit() {
    let mut rig = rig(&file(0.2, &joints(SPEED_AND_EFFORT)));
    rig.robot.set_interface(0, Interface::Velocity).unwrap();
    rig.robot.set_interface(1, Interface::Velocity).unwrap();
    rig.robot.sleep(Duration::from_millis(10));
    let report = rig.robot.command_velocity(&[0.0, 4.0]).unwrap();
    // Clamped to max_velocity 1.5, then ramped: 20 rad/s² over the 10 ms since the
    // switch... (the first cycle counts from the robot's last command cycle: its opening)
    let motion: Vec<_> = report
        .limited
        .iter()
        .filter(|e| e.joint == "elbow" && e.kind == LimitKind::Motion)
        .map(|e| (e.requested_rad, e.limited_rad))
        .collect();
    assert_eq!(motion[0], (4.0, 1.5));
    assert!(motion[1].1 < 1.5, "{motion:?}");
    assert!(
        report
            .limited
            .iter()
            .all(|e| e.interface == Interface::Velocity)
    );
    // Held at 1.5 rad/s towards the limit at 2 rad: slowed to what can stop at 20 rad/s²,
    // and it stops before the limit.
    let mut stopped_by_limit = false;
    for _ in 0..400 {
        let report = rig.robot.command_velocity(&[0.0, 1.5]).unwrap();
        stopped_by_limit |= report
            .limited
            .iter()
            .any(|e| e.joint == "elbow" && e.kind == LimitKind::Position);
        rig.robot.sleep(Duration::from_millis(10));
    }
    assert!(stopped_by_limit);
    let s = rig.robot.read_joint(1).unwrap();
    // The speed loop lags its target a little: it stops within 0.005 rad (0.3°) past.
    assert!(s.position_rad <= 2.0 + 0.005, "{s:?}");
    assert!(s.position_rad > 1.9, "{s:?}");
    assert!(s.velocity_rad_s.unwrap().abs() < 0.05, "{s:?}");
}

#[test]
fn velocity_silence_trips_the_watchdog_into_the_safe_state() {
    let timeout = Duration::from_millis(100);
    let mut rig = rig(&file(0.1, &joints(SPEED_AND_EFFORT)));
    rig.robot.set_interface(0, Interface::Velocity).unwrap();
    rig.robot.set_interface(1, Interface::Velocity).unwrap();
    let level_5 = sim_1108_wheel_speeds()[4];
    hold_velocity(&mut rig.robot, &[level_5, 0.5], Duration::from_millis(300));
    rig.robot.command_velocity(&[level_5, 0.5]).unwrap();
    let last = rig.robot.now();
    assert_eq!(wheel_mode(&rig), Mode::Wheel);
    assert!(elbow(&rig).speed_rpm > 4.0);

    // Silence: the watchdog fires at the timeout exactly.
    rig.robot.sleep(Duration::from_millis(300));
    let report = rig.robot.safe_stop_report().unwrap();
    assert_eq!(
        report.cause,
        StopCause::Watchdog {
            since_command: timeout
        }
    );
    assert_eq!(report.started, last + timeout);
    assert!(report.errors.is_empty(), "{report:?}");
    // wCK: passive (the wheel let go); WHJ: held in its loop, speed target 0, stopped.
    assert_eq!(wheel_mode(&rig), Mode::Passive);
    let s = elbow(&rig);
    assert_eq!((s.mode, s.target_speed), (2, 0));
    assert!(s.speed_rpm.abs() < 0.05, "{s:?}");
    let err = rig.robot.command_velocity(&[0.0, 0.0]).unwrap_err();
    assert!(matches!(err, RobotError::SafeStopped { .. }), "{err}");

    // Resumed: every joint back on position, the WHJ joint in position mode.
    rig.robot.resume().unwrap();
    assert_eq!(rig.robot.interfaces(), [Interface::Position; 2]);
    assert_eq!(elbow(&rig).mode, 3);
    rig.robot.command(&[0.0, 0.3]).unwrap();
}

#[test]
fn the_robot_file_names_the_joint_value_and_range_of_a_wrong_interface() {
    let wck_effort = r#"
        [[joints]]
        name = "wheel"
        bus = "legs"
        id = 0
        limits = [-1.0, 1.0]
        max_velocity = 6.0
        max_acceleration = 100.0
        interfaces = ["position", "effort"]
        max_effort = 1.0
    "#;
    let err = RobotConfig::from_toml_str(&file(0.1, wck_effort)).unwrap_err();
    let text = err.to_string();
    assert!(
        text.starts_with("joint wheel (line ")
            && text.contains("interfaces = [position, effort] is invalid")
            && text.contains("no current mode"),
        "{text}"
    );
    let no_wheel_speeds = wck_effort
        .replace("\"effort\"]", "\"velocity\"]")
        .replace("max_effort = 1.0", "");
    let err = RobotConfig::from_toml_str(&file(0.1, &no_wheel_speeds)).unwrap_err();
    assert!(
        err.to_string()
            .contains("wheel_speeds = none is invalid; expected the wheel speeds"),
        "{err}"
    );
    let no_position = r#"
        [[joints]]
        name = "elbow"
        bus = "arm"
        id = 1
        limits = [-1.0, 1.0]
        max_velocity = 1.0
        max_acceleration = 10.0
        interfaces = ["velocity"]
    "#;
    let err = RobotConfig::from_toml_str(&file(0.1, no_position)).unwrap_err();
    assert!(
        err.to_string()
            .contains("interfaces = [velocity] is invalid; expected a list with \"position\""),
        "{err}"
    );
    let no_max_effort = no_position.replace("[\"velocity\"]", "[\"position\", \"effort\"]");
    let err = RobotConfig::from_toml_str(&file(0.1, &no_max_effort)).unwrap_err();
    assert!(
        err.to_string().contains("max_effort = none is invalid"),
        "{err}"
    );
    let too_much = format!("{no_max_effort}\nmax_effort = 100.0\n");
    // Within the file's bound, past the WHJ30's 90 N·m peak: refused when it identifies.
    let config = RobotConfig::from_toml_str(&file(0.1, &too_much)).unwrap();
    let (arm, _whj) = whj_common::virtual_bus(whj_common::chain(1));
    let mut wck = wck_support::serve_ids(&[0]);
    let err = Robot::builder(config)
        .wck_bus("legs", wck.bus())
        .whj_bus("arm", arm)
        .open()
        .unwrap_err();
    assert!(
        err.to_string()
            .contains("max_effort = 100 is invalid; expected at most the peak torque of the joint's model, 90 N·m"),
        "{err}"
    );
    let levels = "interfaces = [\"position\", \"velocity\"]\nwheel_speeds = [1.0, 2.0]";
    let short = wck_effort
        .replace("interfaces = [\"position\", \"effort\"]", levels)
        .replace("max_effort = 1.0", "");
    let err = RobotConfig::from_toml_str(&file(0.1, &short)).unwrap_err();
    assert!(err.to_string().contains("15 speeds"), "{err}");
}

#[test]
fn a_reversed_joint_turns_its_way_and_a_speed_past_the_models_peak_is_refused() {
    let text = file(0.2, &joints(SPEED_AND_EFFORT))
        .replace("id = 0\n", "id = 0\n        direction = -1\n")
        .replace("id = 1\n", "id = 1\n        direction = -1\n")
        .replace("max_velocity = 1.5", "max_velocity = 5.0");
    let mut rig = rig(&text);
    rig.robot.set_interface(0, Interface::Velocity).unwrap();
    rig.robot.set_interface(1, Interface::Velocity).unwrap();
    let level_5 = sim_1108_wheel_speeds()[4];
    let (a0, p0) = (
        wheel_angle(&rig),
        rig.robot.read_joint(1).unwrap().position_rad,
    );
    hold_velocity(&mut rig.robot, &[level_5, 0.5], Duration::from_millis(500));
    // Joint angles up: the servo's shaft and the WHJ joint's device angle down.
    assert!(
        wheel_angle(&rig) < a0 - 0.5,
        "{} -> {}",
        a0,
        wheel_angle(&rig)
    );
    assert!(elbow(&rig).target_speed < 0);
    let p1 = rig.robot.read_joint(1).unwrap().position_rad;
    assert!(p1 > p0 + 0.1, "{p0} -> {p1}");
    let v = rig.robot.read_joint(1).unwrap().velocity_rad_s.unwrap();
    assert!((v - 0.5).abs() < 0.01, "{v}");

    // The WHJ30 turns at most 37.5 RPM (3.93 rad/s): 4.5 rad/s is refused, nothing sent.
    let before = traffic(&rig);
    let err = rig.robot.command_velocity(&[0.0, 4.5]).unwrap_err();
    assert!(
        matches!(&err, RobotError::Target { joint, interface: Interface::Velocity, value, expected }
            if joint == "elbow" && *value == 4.5 && expected.contains("-3.9270..=3.9270 rad/s")),
        "{err}"
    );
    assert_eq!(traffic(&rig), before);
}
