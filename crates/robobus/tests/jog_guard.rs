//! A front end's safety pieces on the built-in simulated robot (virtual clocks): jogs take
//! one bounded step within the limits, and the guard admits by controller, arming and
//! effect, and brings what was moved to a hold when disarmed.

#![allow(clippy::unwrap_used)]

use std::sync::Arc;
use std::sync::mpsc;
use std::time::Duration;

use robobus::catalogue::{ErrorKind, Family, Request};
use robobus::frontend::guard::{Guard, GuardConfig, GuardedDevice};
use robobus::station::Station;
use robobus::station::jog::{JogRequest, Jogger, WCK_JOG_STEP, WHJ_JOG_STEP_DEG};

fn jog(family: Family, device: u8, target: f64) -> JogRequest {
    JogRequest {
        family,
        bus: None,
        device,
        target,
    }
}

#[test]
fn a_jog_is_one_step_toward_the_target_within_the_soft_limits() {
    let station = Station::simulated().unwrap();
    let jogger = Jogger::new();
    // WHJ joint 1 (enabled in position mode at 0°): one jog step toward 10°.
    let j = jogger.jog(&station, &jog(Family::Whj, 1, 10.0)).unwrap();
    assert_eq!(
        (j.bus.as_str(), j.from, j.sent, j.limited),
        ("sim-whj", 0.0, WHJ_JOG_STEP_DEG, true)
    );
    // A near target is reached in one step, not passed.
    let j = jogger.jog(&station, &jog(Family::Whj, 2, -1.5)).unwrap();
    assert_eq!((j.sent, j.limited), (-1.5, false));
    // The built-in robot file limits every joint to ±2 rad: a jog toward 500° stops at
    // 114.59°, reached step by step.
    let mut last = 0.0;
    for _ in 0..80 {
        let j = jogger.jog(&station, &jog(Family::Whj, 3, 500.0)).unwrap();
        assert!(j.sent - j.from <= WHJ_JOG_STEP_DEG + 1e-9, "{j:?}");
        last = j.sent;
        station_sleep(&station, Duration::from_millis(300));
    }
    assert!((last - 2f64.to_degrees()).abs() < 1e-6, "stopped at {last}");

    // wCK servo 0 at step 127: one jog step (8) toward 200.
    let j = jogger.jog(&station, &jog(Family::Wck, 0, 200.0)).unwrap();
    assert_eq!((j.from, j.sent), (127.0, 127.0 + f64::from(WCK_JOG_STEP)));
    // Refusals name the value; nothing is sent.
    let e = jogger
        .jog(&station, &jog(Family::Whj, 1, f64::NAN))
        .unwrap_err();
    assert_eq!(e.kind(), ErrorKind::BadInput);
    let e = jogger
        .jog(&station, &jog(Family::Wck, 40, 100.0))
        .unwrap_err();
    assert_eq!(e.kind(), ErrorKind::BadInput);
    assert!(e.to_string().contains("40"), "{e}");
}

/// Lets the simulated joints move: a status read of each WHJ joint waits on the bus's
/// virtual clock.
fn station_sleep(station: &Station, d: Duration) {
    let port = station.whj(None).unwrap();
    let bus = port.bus();
    let until = bus.now() + d;
    bus.sleep_until(until);
}

fn req(json: &str) -> Request {
    serde_json::from_str(json).unwrap()
}

#[test]
fn the_guard_admits_by_controller_arming_and_effect_and_holds_what_moved() {
    let station = Arc::new(Station::simulated().unwrap());
    let (tx, rx) = mpsc::channel();
    let guard = Guard::new(Arc::clone(&station), GuardConfig::default(), move |e| {
        tx.send(e.clone()).unwrap();
    })
    .unwrap();
    let (me, other) = (1, 2);
    let read = req(r#"{"op":"whj.status","joints":"1"}"#);
    let configure = req(r#"{"op":"whj.mode","joints":"1","mode":"position"}"#);
    let motion = req(r#"{"op":"whj.move","joint":1,"degrees":5}"#);
    // Nobody controls: reads and settings from anyone, motion from nobody.
    guard.admit(None, &read).unwrap();
    guard.admit(None, &configure).unwrap();
    assert_eq!(
        guard.admit(None, &motion).unwrap_err().kind(),
        ErrorKind::Refused
    );
    // One controller; the other session watches.
    assert!(guard.take_control(me).controller);
    let view = guard.take_control(other);
    assert!(!view.controller && view.held_by_other);
    guard.admit(Some(other), &read).unwrap();
    assert_eq!(
        guard.admit(Some(other), &configure).unwrap_err().kind(),
        ErrorKind::Refused
    );
    assert_eq!(
        guard.admit(None, &configure).unwrap_err().kind(),
        ErrorKind::Refused
    );
    guard.admit(Some(me), &configure).unwrap();
    // Motion needs arming, by the controller only.
    assert_eq!(
        guard.admit(Some(me), &motion).unwrap_err().kind(),
        ErrorKind::Refused
    );
    assert_eq!(guard.arm(other).unwrap_err().kind(), ErrorKind::Refused);
    guard.arm(me).unwrap();
    assert!(guard.view(me).armed);
    guard.admit(Some(me), &motion).unwrap();
    assert_eq!(
        guard.admit(Some(other), &motion).unwrap_err().kind(),
        ErrorKind::Refused
    );
    guard.admit_jog(Some(me), Family::Wck, None, 3).unwrap();
    // Disarming brings the moved devices to a hold, reported once.
    guard.disarm(me).unwrap();
    let event = rx.recv_timeout(Duration::from_secs(10)).unwrap();
    assert_eq!(event.reason, "disarmed");
    assert_eq!(event.state, "hold");
    assert_eq!(
        event.devices,
        [
            GuardedDevice {
                family: Family::Wck,
                bus: "sim-wck".into(),
                id: 3
            },
            GuardedDevice {
                family: Family::Whj,
                bus: "sim-whj".into(),
                id: 1
            },
        ]
    );
    assert!(event.failures.is_empty(), "{:?}", event.failures);
    assert!(!guard.view(me).armed);
    assert_eq!(
        guard.admit(Some(me), &motion).unwrap_err().kind(),
        ErrorKind::Refused
    );
    // Releasing control with nothing moved since reports nothing.
    guard.release_control(me);
    assert!(rx.recv_timeout(Duration::from_millis(200)).is_err());
    assert!(guard.take_control(other).controller);
}

#[test]
fn a_hold_brings_the_moved_devices_to_the_safe_state_and_stays_armed() {
    let station = Arc::new(Station::simulated().unwrap());
    let (tx, rx) = mpsc::channel();
    let guard = Guard::new(
        Arc::clone(&station),
        GuardConfig {
            heartbeat_timeout: Duration::from_secs(60),
            ..GuardConfig::default()
        },
        move |e| tx.send(e.clone()).unwrap(),
    )
    .unwrap();
    let me = 1;
    guard.take_control(me);
    // Nothing moved: a hold has nothing to do and reports nothing.
    guard.arm(me).unwrap();
    let at = std::time::Instant::now();
    guard.hold(me, "command timeout", at).unwrap();
    assert!(rx.recv_timeout(Duration::from_millis(200)).is_err());
    assert!(!guard.has_moved());
    // Another session cannot ask for one.
    assert_eq!(
        guard.hold(2, "x", at).unwrap_err().kind(),
        ErrorKind::Refused
    );
    guard
        .admit_jog(Some(me), Family::Whj, Some("sim-whj"), 2)
        .unwrap();
    assert!(guard.has_moved());
    guard.hold(me, "command timeout", at).unwrap();
    let event = rx.recv_timeout(Duration::from_secs(10)).unwrap();
    assert_eq!(
        (event.reason.as_str(), event.state.as_str()),
        ("command timeout", "hold")
    );
    assert_eq!(event.devices.len(), 1);
    assert!(event.failures.is_empty(), "{:?}", event.failures);
    // Still armed: the next command may move again; what was held is forgotten.
    assert!(guard.view(me).armed && !guard.has_moved());
    guard
        .admit_jog(Some(me), Family::Whj, Some("sim-whj"), 2)
        .unwrap();
}

#[test]
fn a_follower_steps_every_joint_and_refuses_a_bad_command_whole() {
    use robobus::station::follow::Follower;
    let station = Station::simulated().unwrap();
    let f = Follower::new(&station).unwrap();
    let names: Vec<&str> = f.joints().iter().map(|j| j.name.as_str()).collect();
    assert_eq!(names.len(), 23);
    assert_eq!((names[0], names[16], names[22]), ("s0", "j1", "j7"));
    // j1 toward 0.5 rad (28.6°): one 2° step; s0 toward 0.1 rad (5.7°, 5 steps): reached.
    let mut t = vec![0.0; 23];
    t[16] = 0.5;
    t[0] = 0.1;
    let done = f.apply(&station, &f.plan(&t).unwrap());
    assert_eq!(done.len(), 23);
    let ok = |i: usize| match &done[i].outcome {
        robobus::ops::Outcome::Ok(j) => j.clone(),
        robobus::ops::Outcome::Failed(e) => panic!("{}: {e:?}", done[i].id),
    };
    assert_eq!((ok(16).sent, ok(16).limited), (WHJ_JOG_STEP_DEG, true));
    assert_eq!(
        (ok(0).from, ok(0).sent, ok(0).limited),
        (127.0, 132.0, false)
    );
    // One joint out of its soft limits: the whole command is refused, nothing is sent.
    let mut bad = t.clone();
    bad[22] = 2.5;
    let e = f.plan(&bad).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::BadInput);
    assert!(e.to_string().contains("j7"), "{e}");
}

#[test]
fn a_teleoperation_needs_arming_and_its_followers_are_held_on_a_disarm() {
    let station = Arc::new(Station::simulated().unwrap());
    let (tx, rx) = mpsc::channel();
    let guard = Guard::new(Arc::clone(&station), GuardConfig::default(), move |e| {
        tx.send(e.clone()).unwrap();
    })
    .unwrap();
    let teleop = req(r#"{"op":"robot.teleop","seconds":1,
            "map":[{"leader":"s0","follower":"s4"},{"leader":"s0","follower":"j2"}]}"#);
    assert_eq!(
        guard.admit(None, &teleop).unwrap_err().kind(),
        ErrorKind::Refused
    );
    let me = 1;
    assert!(guard.take_control(me).controller);
    assert_eq!(
        guard.admit(Some(me), &teleop).unwrap_err().kind(),
        ErrorKind::Refused
    );
    guard.arm(me).unwrap();
    guard.admit(Some(me), &teleop).unwrap();
    // The followers (not the leader) are what the safe stop holds.
    guard.disarm(me).unwrap();
    let event = rx.recv_timeout(Duration::from_secs(10)).unwrap();
    assert_eq!(event.reason, "disarmed");
    assert_eq!(
        event.devices,
        [
            GuardedDevice {
                family: Family::Wck,
                bus: "sim-wck".into(),
                id: 4
            },
            GuardedDevice {
                family: Family::Whj,
                bus: "sim-whj".into(),
                id: 2
            },
        ]
    );
}
