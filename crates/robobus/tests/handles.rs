//! The hot-path handles (`robobus::station::handles`) and the simulated robot: fresh readings per
//! device, a silent device failed without stopping the call, and every value checked
//! before anything is sent. The station is on the simulators' virtual clocks.

#![allow(clippy::unwrap_used)]

use crate::station_support;

use robobus::catalogue::{self, ErrorKind, Request};
use robobus::ops::Control;
use robobus::ops::whj::ServoLoop;
use robobus::robot::{Robot, StopCause};
use robobus::station::handles::{WckGroup, WhjGroup};
use robobus::station::{Station, WckPort, WhjPort};

/// wCK servos 0..=2 on `legs`, WHJ joints 1 and 2 on `arm`.
fn station() -> (Station, WckPort, WhjPort) {
    station_support::station("legs", "arm")
}

fn run(s: &Station, json: &str) {
    let r = Request::parse_many(json).unwrap().remove(0);
    let report = catalogue::run(s, &r, &mut Control::none()).unwrap();
    assert!(report.failed.is_none(), "{json}: {report:?}");
}

fn sent(w: &WckPort, j: &WhjPort) -> (u64, u64) {
    (
        w.lock().stats().attempts,
        j.bus().telemetry().bus.frames_sent,
    )
}

fn json<T: serde::Serialize>(v: &T) -> String {
    serde_json::to_string(v).unwrap()
}

#[test]
fn wck_servos_read_each_servo_and_fail_a_silent_one_alone() {
    let (s, _, _) = station();
    let servos = WckGroup::new(&s, None, &[0, 5, 2]).unwrap();
    assert_eq!(servos.ids(), [0, 5, 2]);
    assert_eq!(servos.bus(), "legs");
    let got = servos.status().unwrap();
    assert_eq!(
        json(&got[0]),
        r#"{"id":0,"position":127,"position_deg":133.97254901960784,"load":0}"#
    );
    assert_eq!(got[1].id, 5);
    assert_eq!(got[1].failure().unwrap().kind, ErrorKind::NoDevice);
    assert_eq!(json(&got[2]), json(&got[0]).replace("\"id\":0", "\"id\":2"));
}

#[test]
fn wck_moves_check_every_value_before_the_first_packet() {
    let (s, w, j) = station();
    let servos = WckGroup::new(&s, Some("legs"), &[0, 1, 2]).unwrap();
    let before = sent(&w, &j);
    for (positions, torque, what) in [
        (vec![100.0, 254.5, 120.0], 2, "position of servo 1 254.5"),
        (vec![100.0, 110.0, 255.0], 2, "position of servo 2 255"),
        (vec![100.0, f64::NAN, 120.0], 2, "position of servo 1 NaN"),
        (vec![-1.0, 110.0, 120.0], 2, "position of servo 0 -1"),
        (vec![100.0, 110.0], 2, "positions 2 value(s)"),
        (vec![100.0, 110.0, 120.0], 5, "torque 5"),
    ] {
        let e = servos.move_to(&positions, torque).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::BadInput, "{e}");
        assert!(e.to_string().starts_with(what), "{e}");
        let e = servos.sync_move(&positions, torque).unwrap_err();
        assert!(e.to_string().starts_with(what), "{e}");
    }
    assert_eq!(sent(&w, &j), before, "a refused move sends nothing");
    let replies = servos.move_to(&[100.0, 110.0, 120.0], 2).unwrap();
    assert_eq!(replies.len(), 3);
    assert!(replies.iter().all(|r| r.failure().is_none()), "{replies:?}");
    assert_eq!(sent(&w, &j).0, before.0 + 3);
    servos.sync_move(&[127.0, 127.0, 127.0], 0).unwrap();
    assert_eq!(
        sent(&w, &j).0,
        before.0 + 4,
        "one packet for the whole group"
    );
    let passive = servos.passive().unwrap();
    assert!(
        passive.iter().all(|r| json(r).contains("\"load\":null")),
        "{passive:?}"
    );
}

#[test]
fn a_wck_sync_move_needs_the_servos_it_addresses() {
    let (s, w, j) = station();
    let servos = WckGroup::new(&s, None, &[1, 2]).unwrap();
    let before = sent(&w, &j);
    let e = servos.sync_move(&[100.0, 100.0], 2).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused);
    assert!(e.to_string().contains("servos 0..=1"), "{e}");
    assert_eq!(sent(&w, &j), before);
    for (ids, what) in [
        (&[][..], "ids []: no servos given"),
        (&[31], "ids 31"),
        (&[1, 1], "ids 1: given twice"),
    ] {
        let e = WckGroup::new(&s, None, ids).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::BadInput);
        assert!(e.to_string().starts_with(what), "{e}");
    }
    let e = WckGroup::new(&s, Some("arms"), &[0]).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::BadInput, "{e}");
}

#[test]
fn whj_joints_command_only_what_each_joint_accepts() {
    let (s, w, j) = station();
    let e = WhjGroup::new(&s, None, &[1, 3]).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::NoDevice, "{e}");
    let joints = WhjGroup::new(&s, None, &[2, 1]).unwrap();
    assert_eq!(joints.ids(), [2, 1]);
    let limits = joints.limits(ServoLoop::Speed);
    assert_eq!(limits, [(-37.5, 37.5), (-37.5, 37.5)]);
    let status = joints.status().unwrap();
    assert_eq!(status.len(), 2);
    assert!(
        json(&status[0]).starts_with(r#"{"id":2,"position_deg":"#),
        "{status:?}"
    );
    run(&s, r#"{"op": "whj.disable", "joints": "1-2"}"#);
    assert!(json(&joints.status().unwrap()[0]).contains(r#""enabled":false"#));

    // Not enabled: refused before any servo frame.
    let e = joints
        .command(ServoLoop::Position, &[0.0, 0.0])
        .unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused, "{e}");
    run(
        &s,
        r#"{"op": "whj.mode", "joints": "1-2", "mode": "position"}"#,
    );
    run(&s, r#"{"op": "whj.enable", "joints": "1-2"}"#);
    let here: Vec<f64> = joints
        .status()
        .unwrap()
        .iter()
        .map(|r| {
            serde_json::to_value(r).unwrap()["position_deg"]
                .as_f64()
                .unwrap()
        })
        .collect();

    let before = sent(&w, &j);
    let (lo, hi) = joints.limits(ServoLoop::Position)[0];
    for (targets, kind, what) in [
        (
            vec![here[0] + 30.0, here[1]],
            ErrorKind::Refused,
            "J2: position command 30",
        ),
        (
            vec![here[0], f64::INFINITY],
            ErrorKind::BadInput,
            "target of joint J1 inf",
        ),
        (
            vec![hi + 1.0, here[1]],
            ErrorKind::BadInput,
            "target of joint J2",
        ),
        (
            vec![lo - 1.0, here[1]],
            ErrorKind::BadInput,
            "target of joint J2",
        ),
        (vec![here[0]], ErrorKind::BadInput, "targets 1 value(s)"),
    ] {
        let e = joints.command(ServoLoop::Position, &targets).unwrap_err();
        assert_eq!(e.kind(), kind, "{e}");
        assert!(e.to_string().starts_with(what), "{e}");
    }
    // Only the readiness check's reads (work mode, enabled: once per joint, kept until a
    // feedback shows a joint disabled); the positions just read are recent enough for the
    // step check, and no servo frame went out.
    assert_eq!(sent(&w, &j), (before.0, before.1 + 4));
    let fb = joints
        .command(ServoLoop::Position, &[here[0] + 2.0, here[1] - 2.0])
        .unwrap();
    assert_eq!(fb.len(), 2);
    assert!(fb.iter().all(|r| r.failure().is_none()), "{fb:?}");
    assert!(json(&fb[0]).contains(r#""enabled":true"#), "{fb:?}");
    // Speed frames need speed mode.
    let e = joints.command(ServoLoop::Speed, &[1.0, 1.0]).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused, "{e}");
    let e = joints.command(ServoLoop::Speed, &[40.0, 1.0]).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::BadInput, "{e}");

    // A cyclic loop owns the bus's servo frames.
    let mut cyc =
        robobus::station::cyclic::CyclicLoop::start(&s, None, &[1], ServoLoop::Position, 100.0)
            .unwrap();
    let e = joints.command(ServoLoop::Position, &here).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused, "{e}");
    cyc.stop();
}

#[test]
fn the_simulated_robot_reads_and_commands_in_si_units() {
    let mut robot = Robot::simulated().unwrap();
    let names = robot.joint_names().to_vec();
    assert_eq!(names.len(), 23);
    assert_eq!((names[0].as_str(), names[22].as_str()), ("s0", "j7"));
    let state = robot.read().unwrap();
    assert_eq!(state.len(), 23);
    assert!(state[0].position_rad.abs() < 0.01, "{state:?}");
    assert!(state[0].velocity_rad_s.is_none());
    assert!(state[22].velocity_rad_s.is_some());
    let mut targets: Vec<f64> = state.iter().map(|s| s.position_rad).collect();
    targets[22] = 5.0;
    let sent = robot.command(&targets).unwrap();
    assert_eq!(sent.sent_rad.len(), 23);
    assert!(
        sent.limited.iter().any(|l| l.joint == "j7"),
        "5 rad is past the soft limit of 2 rad: {sent:?}"
    );
    let stop = robot.safe_stop();
    assert!(stop.errors.is_empty(), "{stop:?}");
    assert!(robot.command(&targets).is_err());
}

#[test]
fn on_the_wall_clock_a_thread_watches_the_simulated_robot() {
    let mut robot = Robot::simulated().unwrap();
    let here: Vec<f64> = robot
        .read()
        .unwrap()
        .iter()
        .map(|s| s.position_rad)
        .collect();
    robot.command(&here).unwrap();
    let commanded = robot.now();
    // Nothing calls into the robot meanwhile: only its watchdog thread can stop it.
    std::thread::sleep(robot.watchdog_timeout() * 3);
    let report = robot.safe_stop_report().unwrap();
    let StopCause::Watchdog { since_command } = report.cause else {
        panic!("{report:?}");
    };
    assert!(since_command >= robot.watchdog_timeout(), "{report:?}");
    assert!(
        report.started >= commanded + robot.watchdog_timeout(),
        "{report:?}"
    );
    assert!(report.errors.is_empty(), "{report:?}");
}

#[test]
fn a_handle_does_not_keep_its_bus_open() {
    let (s, w, j) = station();
    let servos = WckGroup::new(&s, None, &[0]).unwrap();
    let joints = WhjGroup::new(&s, None, &[1]).unwrap();
    assert!(servos.status().is_ok());
    // The test's own strong handles go; closing the station then closes both buses.
    drop((w, j));
    assert!(s.close().is_empty());
    let e = servos.status().unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused);
    assert!(e.to_string().starts_with("bus legs is closed"), "{e}");
    let e = joints.command(ServoLoop::Position, &[0.0]).unwrap_err();
    assert!(e.to_string().starts_with("bus arm is closed"), "{e}");
    assert_eq!(joints.status().unwrap_err().kind(), ErrorKind::Refused);
}
