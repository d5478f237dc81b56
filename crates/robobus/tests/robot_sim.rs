//! `Robot` and the `Actuator` view against the simulators on their virtual clocks: the
//! wCK simulator as an in-process byte link, the WHJ simulator as an in-process CAN FD
//! link (the client code paths a real UART and a real CAN link use). The robot takes
//! every instant from its buses, so time moves only when a test waits through the robot
//! ([`Robot::sleep`]): the runs take no wall time and are the same on any machine, and
//! the watchdog's instants are exact.

#![allow(clippy::unwrap_used, clippy::panic, clippy::float_cmp)]

use crate::wck_support;
use crate::whj_common;

use std::time::{Duration, Instant};

use robobus::actuator::{
    Actuator, ActuatorError, ActuatorState, JointLimits, JointMap, WckActuator, WckScale,
    WhjActuator,
};
use robobus::robot::{LimitKind, Robot, RobotConfig, RobotError, StopCause};
use robobus::wck::WckBus;
use robobus_sim::wck::Mode;
use robobus_sim::wck::SimLink;
use robobus_sim::whj::WhjSimHandle;
use robobus_wck::{ServoId, TorqueLevel};
use robobus_whj::JointId;

/// A robot file with a wCK bus `legs` and a WHJ bus `arm` supplied by the test.
fn config(watchdog_s: f64, wck_safe: &str, whj_safe: &str, joints: &str) -> RobotConfig {
    RobotConfig::from_toml_str(&format!(
        r#"
        watchdog_timeout = {watchdog_s}
        [buses.legs]
        kind = "wck-external"
        safe_state = "{wck_safe}"
        [buses.arm]
        kind = "whj-external"
        safe_state = "{whj_safe}"
        {joints}
        "#
    ))
    .unwrap()
}

fn joint(name: &str, bus: &str, id: u8, limits: [f64; 2], v: f64, a: f64) -> String {
    format!(
        "[[joints]]\nname = \"{name}\"\nbus = \"{bus}\"\nid = {id}\nlimits = [{}, {}]\nmax_velocity = {v}\nmax_acceleration = {a}\n",
        limits[0], limits[1]
    )
}

struct Rig {
    // Fields drop in order: the robot first (its safe stop still reaches the simulators).
    robot: Robot,
    wck: wck_support::Sim,
    _whj: WhjSimHandle,
}

/// wCK servos `wck_ids` on `legs`, WHJ joints 1..=`whj_n` on `arm`, each simulator on
/// its virtual clock.
fn rig(config: RobotConfig, wck_ids: &[u8], whj_n: u8) -> Rig {
    let mut wck = wck_support::serve_ids(wck_ids);
    let (arm, whj) = whj_common::virtual_bus(whj_common::chain(whj_n));
    let robot = Robot::builder(config)
        .wck_bus("legs", wck.bus())
        .whj_bus("arm", arm)
        .open()
        .unwrap();
    Rig {
        robot,
        wck,
        _whj: whj,
    }
}

fn wck_mode(sim: &wck_support::Sim, id: u8) -> Mode {
    sim.with_bus(move |b| b.servo(b.slot_of(id).unwrap()).unwrap().mode())
}

/// Waits (up to 1 s, in steps of 1 ms) until servo `id` is in `mode` (a synchronized
/// move has no reply, so the client returns before the module acts); how long it took.
fn await_mode(robot: &Robot, sim: &wck_support::Sim, id: u8, mode: Mode) -> Duration {
    let t = robot.now();
    while wck_mode(sim, id) != mode {
        assert!(
            robot.now() - t < Duration::from_secs(1),
            "servo {id} never {mode:?}"
        );
        robot.sleep(Duration::from_millis(1));
    }
    robot.now() - t
}

fn wck_step(sim: &wck_support::Sim, id: u8) -> u8 {
    sim.with_bus(move |b| b.servo(b.slot_of(id).unwrap()).unwrap().position())
}

/// Commands `targets` every 10 ms until every joint is within `tol` rad or `limit` passes.
fn drive(robot: &mut Robot, targets: &[f64], tol: f64, limit: Duration) -> Vec<ActuatorState> {
    let start = robot.now();
    let goals: Vec<f64> = robot
        .limits()
        .iter()
        .zip(targets)
        .map(|(l, t)| l.clamp(*t).0)
        .collect();
    loop {
        robot.command(targets).unwrap();
        let states = robot.read().unwrap();
        let there = states
            .iter()
            .zip(&goals)
            .all(|(s, t)| (s.position_rad - t).abs() <= tol);
        if there {
            return states;
        }
        assert!(
            robot.now() - start < limit,
            "not at {targets:?} after {limit:?}: {states:?}"
        );
        robot.sleep(Duration::from_millis(10));
    }
}

#[test]
fn a_mixed_robot_moves_a_wck_servo_and_a_whj_joint_with_the_same_code() {
    let joints = joint("hip", "legs", 0, [-1.0, 1.0], 2.0, 20.0)
        + &joint("shoulder", "arm", 1, [-1.0, 1.0], 2.0, 20.0);
    let mut rig = rig(config(0.5, "passive", "hold", &joints), &[0], 1);
    assert_eq!(rig.robot.joint_names(), ["hip", "shoulder"]);
    assert_eq!(rig.robot.joint_index("shoulder"), Some(1));

    let start = rig.robot.read().unwrap();
    assert!(
        start[0].position_rad.abs() < 1e-9,
        "wCK at step 127 is 0 rad"
    );
    assert_eq!(start[0].velocity_rad_s, None);
    assert_eq!(start[0].current_a, None);
    assert!(start[1].position_rad.abs() < 0.01);
    assert!(start[1].velocity_rad_s.is_some() && start[1].current_a.is_some());

    let states = drive(&mut rig.robot, &[0.3, 0.3], 0.02, Duration::from_secs(4));
    // The wCK servo stands at the step nearest 0.3 rad (17.19° / 1.055° = 16.3 steps).
    assert_eq!(wck_step(&rig.wck, 0), 127 + 16);
    assert!((states[1].position_rad - 0.3).abs() <= 0.02);

    let states = drive(&mut rig.robot, &[-0.2, -0.4], 0.02, Duration::from_secs(4));
    assert_eq!(wck_step(&rig.wck, 0), 127 - 11);
    assert!((states[1].position_rad + 0.4).abs() <= 0.02);
    assert!(!rig.robot.is_stopped());
}

#[test]
fn targets_beyond_the_soft_limits_are_clamped_and_reported() {
    // Servo 2 alone on its bus: not IDs 0..n, so one move per servo instead of a
    // synchronized move.
    let joints = joint("hip", "legs", 2, [-0.3, 0.25], 5.0, 100.0)
        + &joint("shoulder", "arm", 1, [-0.2, 0.15], 2.0, 20.0);
    let mut rig = rig(config(0.5, "passive", "hold", &joints), &[2], 1);

    let report = rig.robot.command(&[4.0, -3.0]).unwrap();
    let clamps: Vec<_> = report
        .limited
        .iter()
        .filter(|e| e.kind == LimitKind::Position)
        .map(|e| (e.joint.as_str(), e.requested_rad, e.limited_rad))
        .collect();
    assert_eq!(clamps, [("hip", 4.0, 0.25), ("shoulder", -3.0, -0.2)]);

    let states = drive(&mut rig.robot, &[4.0, -3.0], 0.02, Duration::from_secs(4));
    assert!((states[0].position_rad - 0.25).abs() <= 0.02, "{states:?}");
    assert!((states[1].position_rad + 0.2).abs() <= 0.02, "{states:?}");
    // The joints are within 0.02 rad; the rate limiters may still be braking onto the
    // limits (they land exactly on them): command until neither limits the motion.
    let mut report = rig.robot.command(&[4.0, -3.0]).unwrap();
    for _ in 0..100 {
        if !report.limited.iter().any(|e| e.kind == LimitKind::Motion) {
            break;
        }
        rig.robot.sleep(Duration::from_millis(10));
        report = rig.robot.command(&[4.0, -3.0]).unwrap();
    }
    let step = (269.0_f64 / 255.0).to_radians();
    // At the device's resolution, but never outside the limits: 0.25 rad is 13.6 steps,
    // 14 steps would be past it.
    assert!(report.sent_rad[0] <= 0.25, "{report:?}");
    assert!(
        (report.sent_rad[0] - 13.0 * step).abs() < 1e-9,
        "{report:?}"
    );
    assert!((report.sent_rad[1] + 0.2).abs() < 1e-6, "{report:?}");
    // Never past the limit, at any time.
    assert_eq!(wck_step(&rig.wck, 2), 127 + 13);
}

#[test]
fn speed_and_acceleration_limits_spread_a_large_step() {
    // 0.4 rad (22.9°) at once would trip the WHJ joint's 10° step protection; limited
    // to 0.5 rad/s it takes at least 0.8 s.
    let (vmax, amax) = (0.5, 5.0);
    let joints = joint("shoulder", "arm", 1, [-1.0, 1.0], vmax, amax);
    let mut rig = rig(config(0.5, "passive", "hold", &joints), &[0], 1);

    let start = rig.robot.now();
    let mut last: Option<(Instant, f64)> = None;
    let mut motion_reports = 0;
    let mut first = true;
    loop {
        // The robot takes its time stamp as the call begins, on its clock: exactly this.
        let now = rig.robot.now();
        let report = rig.robot.command(&[0.4]).unwrap();
        let sent = report.sent_rad[0];
        motion_reports += report
            .limited
            .iter()
            .filter(|e| e.kind == LimitKind::Motion && e.requested_rad == 0.4)
            .count();
        if let Some((t, prev)) = last {
            let dt = now.duration_since(t).as_secs_f64();
            assert!(
                (sent - prev).abs() <= vmax * dt + 1e-5,
                "step {} rad in {dt} s",
                sent - prev
            );
        }
        if first {
            // Starting from rest: at most a·dt² in the first cycle.
            assert!(sent.abs() < 0.01, "first set-point {sent}");
            first = false;
        }
        last = Some((now, sent));
        if (sent - 0.4).abs() < 1e-6 {
            break;
        }
        assert!(
            rig.robot.now() - start < Duration::from_secs(8),
            "never reached"
        );
        rig.robot.sleep(Duration::from_millis(10));
    }
    // 0.4 rad at 0.5 rad/s at most.
    let took = rig.robot.now() - start;
    assert!(took >= Duration::from_millis(800), "{took:?}");
    assert!(motion_reports > 10);
    drive(&mut rig.robot, &[0.4], 0.02, Duration::from_secs(2));
}

#[test]
fn a_late_cycle_never_jumps_past_the_whj_step_limit() {
    // 300 ms between two commands at 2 rad/s would allow 0.6 rad (34°) at once; the
    // joint refuses more than 5° a command, so the set-point waits for it instead.
    let joints = joint("shoulder", "arm", 1, [-1.0, 1.0], 2.0, 100.0);
    let mut rig = rig(config(0.5, "passive", "hold", &joints), &[0], 1);
    rig.robot.command(&[0.0]).unwrap();
    rig.robot.sleep(Duration::from_millis(300));
    let report = rig.robot.command(&[0.8]).unwrap();
    let step = report
        .limited
        .iter()
        .find(|e| e.kind == LimitKind::Step)
        .unwrap_or_else(|| panic!("{report:?}"));
    assert!(step.requested_rad > 0.2, "{step:?}");
    assert!(
        (step.limited_rad - 0.8 * 5.0_f64.to_radians()).abs() < 0.01,
        "{step:?}"
    );
    assert!(
        (report.sent_rad[0] - step.limited_rad).abs() < 1e-5,
        "{report:?}"
    );
    // And the motion goes on from there.
    drive(&mut rig.robot, &[0.8], 0.02, Duration::from_secs(4));
}

#[test]
fn the_watchdog_puts_wck_servos_passive_within_its_timeout() {
    let timeout = Duration::from_millis(100);
    let joints = joint("hip", "legs", 0, [-1.0, 1.0], 2.0, 20.0)
        + &joint("knee", "legs", 1, [-1.0, 1.0], 2.0, 20.0);
    let mut rig = rig(config(0.1, "passive", "hold", &joints), &[0, 1], 1);
    assert_eq!(rig.robot.watchdog_timeout(), timeout);

    // Not armed before the first command.
    rig.robot.sleep(timeout * 2);
    assert!(!rig.robot.is_stopped());

    rig.robot.command(&[0.1, 0.1]).unwrap();
    let stalled = rig.robot.now();
    await_mode(&rig.robot, &rig.wck, 0, Mode::Position);
    let passive = loop {
        if wck_mode(&rig.wck, 0) == Mode::Passive && wck_mode(&rig.wck, 1) == Mode::Passive {
            break rig.robot.now() - stalled;
        }
        assert!(
            rig.robot.now() - stalled < Duration::from_secs(2),
            "never went passive"
        );
        rig.robot.sleep(Duration::from_millis(1));
    };
    let report = rig.robot.safe_stop_report().unwrap();
    let StopCause::Watchdog { since_command } = report.cause else {
        panic!("{report:?}");
    };
    assert!(report.errors.is_empty(), "{report:?}");
    // Fired at the timeout exactly (the virtual clock stops there); the two passive
    // commands with their replies take their wire time on the 115200 bit/s bus.
    assert_eq!(since_command, timeout);
    assert_eq!(report.started, stalled + timeout);
    let passive_command = robobus_wck::timing::transaction_time(
        &robobus_wck::Command::Passive {
            id: ServoId::new(0).unwrap(),
        },
        robobus_wck::BaudRate::B115200,
    );
    // Each is its transaction, then the line stays quiet for the guard time; the bit-level
    // simulator's reply ends a few µs after the timing model's.
    let each = passive_command + robobus::wck::reply_guard(robobus_wck::BaudRate::B115200);
    assert!(
        report.applied_in >= 2 * passive_command
            && report.applied_in < 2 * each + Duration::from_micros(20),
        "{report:?}, a passive command takes {passive_command:?}"
    );
    // Seen in the next 1 ms step after the stop.
    assert!(passive > timeout, "{passive:?}");
    assert!(
        passive <= timeout + report.applied_in + Duration::from_millis(1),
        "{passive:?}"
    );

    // Refused until resumed; then it moves again.
    let err = rig.robot.command(&[0.1, 0.1]).unwrap_err();
    assert!(matches!(err, RobotError::SafeStopped { .. }), "{err:?}");
    assert!(err.to_string().contains("watchdog"), "{err}");
    rig.robot.resume().unwrap();
    rig.robot.command(&[0.1, 0.1]).unwrap();
    await_mode(&rig.robot, &rig.wck, 0, Mode::Position);
}

#[test]
fn the_watchdog_can_break_the_wck_bus() {
    let joints = joint("hip", "legs", 0, [-1.0, 1.0], 2.0, 20.0);
    let mut rig = rig(config(0.05, "break", "hold", &joints), &[0], 1);
    rig.robot.command(&[0.05]).unwrap();
    let took = await_mode(&rig.robot, &rig.wck, 0, Mode::Break);
    // 50 ms timeout, and the break on the wire.
    assert!(
        took > Duration::from_millis(50) && took < Duration::from_millis(60),
        "{took:?}"
    );
    assert_eq!(
        rig.robot.safe_stop_report().unwrap().cause,
        StopCause::Watchdog {
            since_command: Duration::from_millis(50)
        }
    );
}

/// Waits (in steps of 1 ms) for a watchdog stop and returns the time from the last
/// command to the end of the safe stop.
fn await_stop(robot: &Robot, since: Instant) -> Duration {
    loop {
        if let Some(r) = robot.safe_stop_report() {
            return r.started.duration_since(since) + r.applied_in;
        }
        assert!(
            robot.now() - since < Duration::from_secs(2),
            "watchdog never fired"
        );
        robot.sleep(Duration::from_millis(1));
    }
}

#[test]
fn the_watchdog_disables_whj_joints_within_its_timeout() {
    let timeout = Duration::from_millis(100);
    let joints = joint("shoulder", "arm", 1, [-1.0, 1.0], 2.0, 20.0)
        + &joint("elbow", "arm", 2, [-1.0, 1.0], 2.0, 20.0);
    let mut rig = rig(config(0.1, "passive", "disable", &joints), &[0], 2);
    let arm = rig.robot.whj_bus("arm").unwrap();
    let j1 = JointId::new(1).unwrap();
    let j2 = JointId::new(2).unwrap();
    assert!(arm.joint_unchecked(j1).is_enabled().unwrap());

    rig.robot.command(&[0.05, -0.05]).unwrap();
    let stalled = rig.robot.now();
    let safe = await_stop(&rig.robot, stalled);
    assert!(!arm.joint_unchecked(j1).is_enabled().unwrap());
    assert!(!arm.joint_unchecked(j2).is_enabled().unwrap());
    // At the timeout exactly, and two disables (a request and its reply each) later.
    let report = rig.robot.safe_stop_report().unwrap();
    assert_eq!(report.started, stalled + timeout, "{report:?}");
    assert!(safe > timeout, "{safe:?}");
    assert!(safe < timeout + Duration::from_millis(2), "{safe:?}");

    // Resume re-enables them in position mode, and commands flow again.
    rig.robot.resume().unwrap();
    assert!(arm.joint_unchecked(j1).is_enabled().unwrap());
    drive(&mut rig.robot, &[0.1, -0.1], 0.02, Duration::from_secs(3));
}

#[test]
fn the_watchdog_hold_keeps_whj_joints_powered_where_they_are() {
    let joints = joint("shoulder", "arm", 1, [-1.0, 1.0], 0.5, 5.0);
    let mut rig = rig(config(0.1, "passive", "hold", &joints), &[0], 1);
    let arm = rig.robot.whj_bus("arm").unwrap();
    let j1 = arm.joint_unchecked(JointId::new(1).unwrap());

    // Stall in the middle of a move towards 0.8 rad.
    for _ in 0..40 {
        rig.robot.command(&[0.8]).unwrap();
        rig.robot.sleep(Duration::from_millis(10));
    }
    let stalled = rig.robot.now();
    await_stop(&rig.robot, stalled);
    rig.robot.sleep(Duration::from_millis(300));
    assert!(j1.is_enabled().unwrap());
    let target = f64::from(j1.read_register("TAG_POSITION").unwrap().raw) / 1e4;
    let actual = j1.position().unwrap().degrees();
    assert!(
        target > 5.0 && target < 40.0,
        "held at {target}° (mid-move)"
    );
    assert!(
        (target - actual).abs() < 1.0,
        "target {target}°, at {actual}°"
    );
}

#[test]
fn dropping_the_robot_puts_every_bus_in_its_safe_state() {
    let joints = joint("hip", "legs", 0, [-1.0, 1.0], 2.0, 20.0)
        + &joint("shoulder", "arm", 1, [-1.0, 1.0], 2.0, 20.0);
    let rig = rig(config(5.0, "passive", "disable", &joints), &[0], 1);
    let Rig {
        mut robot,
        wck,
        _whj,
    } = rig;
    robot.command(&[0.1, 0.05]).unwrap();
    await_mode(&robot, &wck, 0, Mode::Position);
    let arm = robot.whj_bus("arm").unwrap();
    let j1 = JointId::new(1).unwrap();
    assert!(arm.joint_unchecked(j1).is_enabled().unwrap());

    drop(robot);
    assert_eq!(wck_mode(&wck, 0), Mode::Passive);
    assert!(!arm.joint_unchecked(j1).is_enabled().unwrap());
}

#[test]
fn a_stop_handle_stops_the_robot_from_another_thread() {
    let joints = joint("hip", "legs", 0, [-1.0, 1.0], 2.0, 20.0);
    let mut rig = rig(config(5.0, "passive", "hold", &joints), &[0], 1);
    rig.robot.command(&[0.1]).unwrap();
    let handle = rig.robot.stop_handle();
    let report = std::thread::spawn(move || handle.safe_stop())
        .join()
        .unwrap()
        .unwrap();
    assert_eq!(report.cause, StopCause::Requested);
    assert_eq!(wck_mode(&rig.wck, 0), Mode::Passive);
    // A second stop reports the first.
    assert_eq!(rig.robot.safe_stop().cause, StopCause::Requested);
    let err = rig.robot.command(&[0.1]).unwrap_err().to_string();
    assert!(err.contains("safe stop requested"), "{err}");
}

#[test]
fn bad_targets_are_refused_before_anything_is_sent() {
    let joints = joint("hip", "legs", 0, [-1.0, 1.0], 2.0, 20.0)
        + &joint("shoulder", "arm", 1, [-1.0, 1.0], 2.0, 20.0);
    let mut rig = rig(config(5.0, "passive", "hold", &joints), &[0], 1);
    let sent_before = rig.wck.with_bus(|b| b.stats());

    let err = rig.robot.command(&[0.1]).unwrap_err().to_string();
    assert!(
        err.contains("1 targets given for 2 joints (hip, shoulder)"),
        "{err}"
    );
    let err = rig.robot.command(&[0.1, f64::NAN]).unwrap_err().to_string();
    assert!(err.contains("shoulder") && err.contains("NaN"), "{err}");
    assert_eq!(rig.wck.with_bus(|b| b.stats()), sent_before);
}

#[test]
fn a_joint_is_read_by_its_index_and_an_index_past_the_joints_is_an_error() {
    let joints = joint("hip", "legs", 0, [-1.0, 1.0], 2.0, 20.0)
        + &joint("shoulder", "arm", 1, [-1.0, 1.0], 2.0, 20.0);
    let mut rig = rig(config(5.0, "passive", "hold", &joints), &[0], 1);
    let all = rig.robot.read().unwrap();
    assert_eq!(rig.robot.read_joint(0).unwrap(), all[0]);
    assert!(rig.robot.read_joint(1).unwrap().velocity_rad_s.is_some());
    let err = rig.robot.read_joint(2).unwrap_err();
    assert!(
        matches!(err, RobotError::NoSuchJoint { index: 2, .. }),
        "{err:?}"
    );
    assert_eq!(err.kind(), robobus::ErrorKind::BadInput);
    assert_eq!(
        err.to_string(),
        "no joint #2: the robot's joints are hip, shoulder (#0 on)"
    );
}

#[test]
fn a_supplied_bus_must_match_the_file() {
    let joints = joint("hip", "legs", 0, [-1.0, 1.0], 2.0, 20.0);
    let mut wck = wck_support::serve_ids(&[0]);
    let err = Robot::builder(config(1.0, "passive", "hold", &joints))
        .wck_bus("arm", wck.bus())
        .open()
        .unwrap_err()
        .to_string();
    assert!(err.contains("bus arm") && err.contains("WHJ"), "{err}");
}

// ----- the Actuator view ---------------------------------------------------------------

/// The same code for both families: step towards `target` every 10 ms (`pause` lets
/// 10 ms pass on the joint's clock) until there, for at most 3 s.
fn settle(
    joint: &mut dyn Actuator,
    target: f64,
    tol: f64,
    pause: &dyn Fn(),
) -> Result<ActuatorState, ActuatorError> {
    for _ in 0..300 {
        let sent = joint.command_position(target)?;
        assert!(!sent.clamped);
        let state = joint.state()?;
        if (state.position_rad - target).abs() <= tol {
            return Ok(state);
        }
        pause();
    }
    panic!("{}: not at {target} rad after 3 s", joint.name());
}

const PAUSE: Duration = Duration::from_millis(10);

const LIMITS: JointLimits = JointLimits {
    min_rad: -0.5,
    max_rad: 0.5,
    max_velocity_rad_s: 1.0,
    max_acceleration_rad_s2: 10.0,
};

#[test]
fn actuators_of_both_families_move_with_the_same_code() {
    let mut wck_sim = wck_support::serve_ids(&[3]);
    let mut wck: WckBus<SimLink> = wck_sim.bus();
    let scale = WckScale {
        centre: 100,
        map: JointMap {
            offset_rad: 0.0,
            reversed: true,
        },
    };
    let mut servo = WckActuator::new(
        "wrist",
        wck.servo(ServoId::new(3).unwrap()),
        scale,
        LIMITS,
        TorqueLevel::new(2).unwrap(),
    );
    // Step 127 with centre 100, reversed: -27 steps.
    let start = servo.state().unwrap();
    assert!((start.position_rad + 27.0 * (269.0_f64 / 255.0).to_radians()).abs() < 1e-9);
    settle(&mut servo, 0.1, 0.02, &|| wck_sim.sleep(PAUSE)).unwrap();
    assert_eq!(wck_step(&wck_sim, 3), 100 - 5);
    let err = servo
        .command_position(f64::INFINITY)
        .unwrap_err()
        .to_string();
    assert!(err.contains("wrist") && err.contains("inf"), "{err}");
    let clamped = servo.command_position(2.0).unwrap();
    assert!(clamped.clamped && clamped.sent_rad <= 0.5 + 0.01);
    servo.relax().unwrap();
    assert_eq!(wck_mode(&wck_sim, 3), Mode::Passive);
    servo.hold().unwrap();
    assert_eq!(wck_mode(&wck_sim, 3), Mode::Position);

    let (bus, _whj_sim) = whj_common::virtual_bus(whj_common::chain(1));
    let mut joint = WhjActuator::new(
        "elbow",
        bus.joint(JointId::new(1).unwrap()).unwrap(),
        JointMap {
            offset_rad: 0.05,
            reversed: false,
        },
        LIMITS,
    )
    .unwrap();
    // Device at 0 rad, offset 0.05 rad: the joint reads -0.05 rad.
    assert!((joint.state().unwrap().position_rad + 0.05).abs() < 0.005);
    // (One frame per command: keep within the joint's 5° step limit.)
    let state = settle(&mut joint, 0.03, 0.005, &|| {
        bus.sleep_until(bus.now() + PAUSE);
    })
    .unwrap();
    assert!(state.current_a.is_some());
    // 0.08 rad on the device, in 0.0001° counts.
    let raw = bus
        .joint_unchecked(JointId::new(1).unwrap())
        .read_register("TAG_POSITION")
        .unwrap()
        .raw;
    assert!(
        (f64::from(raw) / 1e4 - 0.08_f64.to_degrees()).abs() < 1e-3,
        "{raw}"
    );
    joint.relax().unwrap();
    assert!(
        !bus.joint_unchecked(JointId::new(1).unwrap())
            .is_enabled()
            .unwrap()
    );
}

/// The servo frames (`first`..`first + 6`) and feedback of joints 1..=7 in `trace` from
/// `from` on: (from the host, raw ID), in wire order.
fn servo_traffic(sim: &WhjSimHandle, from: usize, first: u32) -> Vec<(bool, u32)> {
    sim.with_bus(|b| {
        b.trace()[from..]
            .iter()
            .filter(|w| {
                (first..first + 7).contains(&w.frame.raw_id())
                    || (0x501..=0x507).contains(&w.frame.raw_id())
            })
            .map(|w| (w.source == robobus_sim::whj::Node::Host, w.frame.raw_id()))
            .collect()
    })
}

#[test]
fn a_command_sends_each_whj_bus_its_servo_frames_in_one_batch() {
    let joints: String = (1..=7)
        .map(|n| {
            joint(&format!("j{n}"), "arm", n, [-1.0, 1.0], 2.0, 20.0)
                + "interfaces = [\"position\", \"velocity\"]\n"
        })
        .collect();
    let config = RobotConfig::from_toml_str(&format!(
        "watchdog_timeout = 0.5\n[buses.arm]\nkind = \"whj-external\"\nsafe_state = \"hold\"\n{joints}"
    ))
    .unwrap();
    let (arm, sim) = whj_common::virtual_bus(whj_common::chain(7).with_trace());
    let mut robot = Robot::builder(config).whj_bus("arm", arm).open().unwrap();
    let here: Vec<f64> = robot
        .read()
        .unwrap()
        .iter()
        .map(|s| s.position_rad)
        .collect();
    // Every frame of a cycle was on the wire before the first feedback: each reply's
    // duplicate check overlapped the other joints' frames.
    let batch = |first: u32| -> Vec<(bool, u32)> {
        (first..first + 7)
            .map(|id| (true, id))
            .chain((0x501..=0x507).map(|id| (false, id)))
            .collect()
    };
    for round in 0..3 {
        let traced = sim.with_bus(|b| b.trace().len());
        robot.command(&here).unwrap();
        assert_eq!(
            servo_traffic(&sim, traced, 0x201),
            batch(0x201),
            "round {round}"
        );
    }
    // Speed servo frames, the same.
    for i in 0..7 {
        robot
            .set_interface(i, robobus::robot::Interface::Velocity)
            .unwrap();
    }
    for round in 0..3 {
        let traced = sim.with_bus(|b| b.trace().len());
        robot.command_velocity(&[0.0; 7]).unwrap();
        assert_eq!(
            servo_traffic(&sim, traced, 0x301),
            batch(0x301),
            "round {round}"
        );
    }
}
