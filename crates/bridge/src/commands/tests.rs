//! Velocity and effort commands on the built-in simulated robot (its simulators' own
//! state is what is checked).

#![allow(clippy::unwrap_used)]
#![allow(clippy::float_cmp)] // a zero target is exactly zero

use std::sync::atomic::AtomicBool;

use robobus::frontend::live::LiveSimulator;
use robobus::robot::RobotConfig;
use robobus::robot::simulated::{DRIVE_ROBOT, sim_1108_wheel_speeds};
use robobus::station::Station;

use super::*;
use crate::{BridgeConfig, Keys, run_request};

/// The simulated robot with its file of a wheel `s0`, a WHJ joint `j1` with velocity and
/// effort and `j2` with position alone ([`DRIVE_ROBOT`]); armed, its WHJ joints enabled in position mode,
/// and a thread feeding the guard's heartbeat until the flag is set.
fn armed() -> (Arc<Shared>, Arc<AtomicBool>) {
    let (mut station, live) = Station::simulated_live(None).unwrap();
    station
        .set_robot(RobotConfig::from_toml_str(DRIVE_ROBOT).unwrap())
        .unwrap();
    let s = Shared::new(
        station,
        Some(live),
        BridgeConfig::default(),
        Keys::new(None).unwrap(),
    )
    .unwrap();
    crate::testing::armed(s, "1-2")
}

fn sim(s: &Shared) -> &LiveSimulator {
    s.sim.as_ref().unwrap()
}

/// The simulators' state once `ok` holds of it (their WHJ copy is published every few
/// ms), or the last one after 2 s.
fn until(
    s: &Shared,
    ok: impl Fn(&robobus::frontend::live::SimSnapshot) -> bool,
) -> robobus::frontend::live::SimSnapshot {
    let deadline = Instant::now() + Duration::from_secs(2);
    loop {
        let snap = sim(s).snapshot();
        if ok(&snap) || Instant::now() > deadline {
            return snap;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn command(data: &[f64]) -> Vec<u8> {
    cdr::Float64MultiArray {
        dim: Vec::new(),
        data_offset: 0,
        data: data.to_vec(),
    }
    .encode()
}

fn last(s: &Shared) -> String {
    s.drives.health().last.unwrap_or_default()
}

/// Sends `data` on `interface` every 20 ms for `ms`.
fn stream(s: &Shared, interface: Interface, data: &[f64], ms: u64) {
    for _ in 0..ms / 20 {
        assert!(
            follow(s, interface, &command(data), Instant::now()),
            "{}",
            last(s)
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn a_velocity_stream_turns_the_wheel_and_the_whj_joint_at_the_asked_speeds() {
    let (s, done) = armed();
    let reply = interface(&s, r#"{"interface": "velocity", "joints": ["s0", "j1"]}"#).unwrap();
    assert_eq!(
        reply["velocity"],
        serde_json::json!(["s0", "j1"]),
        "{reply}"
    );
    assert_eq!(s.drives.health().velocity_joints, ["s0", "j1"]);
    let level_7 = sim_1108_wheel_speeds()[6];
    let a0 = sim(&s).snapshot().wck[0].angle_deg;
    stream(&s, Interface::Velocity, &[level_7, 0.5], 600);
    let snap = until(&s, |n| n.whj[0].target_speed_rpm > 0.0);
    assert_eq!(snap.wck[0].mode, "wheel", "{:?}", snap.wck[0]);
    assert!(
        (snap.wck[0].angle_deg - a0).abs() > 10.0,
        "{a0} {:?}",
        snap.wck[0]
    );
    // j1 in speed mode at 0.5 rad/s (4.775 RPM), turning at it.
    let j1 = &snap.whj[0];
    let rpm = 0.5 * 60.0 / std::f64::consts::TAU;
    assert_eq!(j1.mode, 2, "{j1:?}");
    assert!((j1.target_speed_rpm - rpm).abs() < 0.002, "{j1:?}");
    assert!((j1.speed_rpm - rpm).abs() < 0.05 * rpm, "{j1:?}");
    let h = s.drives.health();
    assert_eq!(h.velocity.applied, 30, "{h:?}");
    assert_eq!(h.velocity.refused_out_of_range, 0, "{h:?}");
    // To rest, then back on position: the joint in position mode, the wheel out of wheel
    // mode.
    stream(&s, Interface::Velocity, &[0.0, 0.0], 200);
    interface(&s, r#"{"interface": "position", "joints": ["s0", "j1"]}"#).unwrap();
    let snap = until(&s, |n| n.whj[0].mode == 3);
    assert_eq!(snap.whj[0].mode, 3, "{:?}", snap.whj[0]);
    assert_ne!(snap.wck[0].mode, "wheel", "{:?}", snap.wck[0]);
    assert!(s.drives.health().velocity_joints.is_empty());
    done.store(true, Ordering::SeqCst);
}

#[test]
fn velocity_is_refused_where_a_joint_lacks_the_interface_or_was_not_switched() {
    let (s, done) = armed();
    let before = sim(&s).snapshot();
    // Not switched: nothing is on velocity.
    assert!(!follow(
        &s,
        Interface::Velocity,
        &command(&[0.5]),
        Instant::now()
    ));
    assert!(
        last(&s).starts_with(
            "joint_commands/velocity: no joint is on its velocity interface: switch the \
             joints first"
        ),
        "{}",
        last(&s)
    );
    // j2 has position alone: refused whole, nothing switched.
    let e = interface(&s, r#"{"interface": "velocity", "joints": ["s0", "j2"]}"#).unwrap_err();
    assert_eq!(e.kind(), robobus::ErrorKind::BadInput);
    assert!(
        e.to_string().contains("j2") && e.to_string().contains("position"),
        "{e}"
    );
    assert!(s.drives.health().velocity_joints.is_empty());
    // A wCK servo has no effort.
    let e = interface(&s, r#"{"interface": "effort", "joints": ["s0"]}"#).unwrap_err();
    assert!(e.to_string().contains("s0"), "{e}");
    assert_eq!(sim(&s).snapshot().wck[0].mode, before.wck[0].mode);
    assert_eq!(sim(&s).snapshot().whj[1].mode, before.whj[1].mode);
    // Switched: a wrong count, a NaN, past max_velocity are refused whole.
    interface(&s, r#"{"interface": "velocity", "joints": ["j1"]}"#).unwrap();
    for (data, says) in [
        (
            vec![0.5, 0.5],
            "one velocity per joint on that interface: 1 values, in the order j1",
        ),
        (vec![f64::NAN], "j1"),
        (vec![2.5], "-2..=2 rad/s (its max_velocity)"),
    ] {
        assert!(!follow(
            &s,
            Interface::Velocity,
            &command(&data),
            Instant::now()
        ));
        assert!(last(&s).contains(says), "{}", last(&s));
    }
    assert_eq!(s.drives.health().velocity.refused_out_of_range, 4);
    assert_eq!(sim(&s).snapshot().whj[0].target_speed_rpm, 0.0);
    // Positions are held while a joint is on velocity.
    assert!(!crate::follow(&s, &command(&[0.0, 0.0, 0.0])));
    assert!(
        s.last_held
            .lock()
            .unwrap()
            .as_deref()
            .is_some_and(|m| m.starts_with("joint_commands: j1 (velocity) not on the position")),
        "{:?}",
        s.last_held.lock().unwrap()
    );
    // Not armed: no switch, no command.
    s.set_armed(false).unwrap();
    let e = interface(&s, r#"{"interface": "velocity", "joints": ["s0"]}"#).unwrap_err();
    assert!(e.to_string().contains("not armed"), "{e}");
    done.store(true, Ordering::SeqCst);
}

#[test]
fn a_quiet_velocity_stream_brings_its_joints_to_rest_on_position() {
    let (s, done) = armed();
    interface(&s, r#"{"interface": "velocity", "joints": ["s0", "j1"]}"#).unwrap();
    stream(
        &s,
        Interface::Velocity,
        &[sim_1108_wheel_speeds()[6], 0.5],
        200,
    );
    // Within the timeout nothing happens.
    watch(&s, Instant::now());
    assert_eq!(s.drives.health().velocity_joints, ["s0", "j1"]);
    // Quiet for longer than the 200 ms timeout.
    watch(&s, Instant::now() + Duration::from_millis(250));
    let h = s.drives.health();
    assert_eq!(h.velocity.timeouts, 1, "{h:?}");
    assert!(h.velocity_joints.is_empty(), "{h:?}");
    assert_eq!(
        h.last.as_deref(),
        Some(
            "joint_commands/velocity: command timeout: s0, j1 brought to rest and back on \
             position"
        )
    );
    let snap = until(&s, |n| n.whj[0].mode == 3);
    assert_eq!(
        (snap.whj[0].mode, snap.whj[0].target_speed_rpm),
        (3, 0.0),
        "{:?}",
        snap.whj[0]
    );
    assert_ne!(snap.wck[0].mode, "wheel", "{:?}", snap.wck[0]);
    // A later command finds nothing on velocity.
    assert!(!follow(
        &s,
        Interface::Velocity,
        &command(&[0.5, 0.5]),
        Instant::now()
    ));
    done.store(true, Ordering::SeqCst);
}

#[test]
fn an_effort_stream_drives_the_whj_joint_in_current_mode() {
    let (s, done) = armed();
    interface(&s, r#"{"interface": "effort", "joints": ["j1"]}"#).unwrap();
    stream(&s, Interface::Effort, &[0.5], 200);
    let snap = until(&s, |n| n.whj[0].current_a > 0.1);
    let j1 = &snap.whj[0];
    assert_eq!(j1.mode, 1, "{j1:?}");
    // 0.5 N·m through the WHJ30's 30/7.8 N·m per A: 0.13 A.
    assert!((j1.current_a - 0.5 / (30.0 / 7.8)).abs() < 0.05, "{j1:?}");
    assert_eq!(s.drives.health().effort.applied, 10);
    done.store(true, Ordering::SeqCst);
}

#[test]
fn the_bridges_end_brings_joints_off_position_back_on_it() {
    let (s, done) = armed();
    interface(&s, r#"{"interface": "velocity", "joints": ["j1"]}"#).unwrap();
    stream(&s, Interface::Velocity, &[0.5], 100);
    s.stop.stop();
    serve(&s);
    assert!(s.drives.health().velocity_joints.is_empty());
    let snap = until(&s, |n| n.whj[0].mode == 3);
    assert_eq!(
        (snap.whj[0].mode, snap.whj[0].target_speed_rpm),
        (3, 0.0),
        "{:?}",
        snap.whj[0]
    );
    done.store(true, Ordering::SeqCst);
}

/// A trajectory's results.
#[derive(Default)]
struct Results(std::sync::Mutex<Vec<crate::trajectory::TrajectoryResult>>);

impl crate::trajectory::Sink for Results {
    fn state(&self, _: &cdr::JointTrajectoryControllerState) {}

    fn result(&self, r: &crate::trajectory::TrajectoryResult) {
        self.0.lock().unwrap().push(r.clone());
    }
}

#[test]
fn motions_of_positions_of_a_joint_on_velocity_are_refused_until_it_is_back_on_position() {
    let (s, done) = armed();
    interface(&s, r#"{"interface": "velocity", "joints": ["j1"]}"#).unwrap();
    let said = "j1 is on its velocity interface: a motion of positions needs it on its \
                position interface; switch it back to position first; nothing was sent";
    // A robobus/run motion of it (j1 is WHJ joint 1), and a robot.play naming it.
    let at = sim(&s).snapshot().whj[0].clone();
    for request in [
        r#"{"op":"whj.move","joint":1,"degrees":5}"#,
        r#"{"op":"robot.play","trajectory":"time_s,j1\n0,0\n1,5\n"}"#,
    ] {
        let e = run_request(&s, request).unwrap_err();
        assert_eq!(e.kind(), robobus::ErrorKind::Refused, "{request}: {e}");
        assert!(e.to_string().contains(said), "{request}: {e}");
    }
    // A jog of it (the studio's).
    let jog = robobus::station::jog::JogRequest {
        family: robobus::ops::Family::Whj,
        bus: None,
        device: 1,
        target: 5.0,
    };
    let e = robobus::station::jog::Jogger::new()
        .jog(&s.station, &jog)
        .unwrap_err();
    assert_eq!(e.kind(), robobus::ErrorKind::Refused, "{e}");
    assert!(e.to_string().contains(said), "{e}");
    // A ROS 2 trajectory of it: refused whole, nothing moved.
    let results = Arc::new(Results::default());
    let sink: Arc<dyn crate::trajectory::Sink> = results.clone();
    let payload = cdr::JointTrajectory {
        joint_names: vec!["j1".into()],
        points: vec![cdr::JointTrajectoryPoint {
            positions: vec![0.1],
            time_from_start: cdr::Duration::from_secs_f64(1.0),
            ..cdr::JointTrajectoryPoint::default()
        }],
        ..cdr::JointTrajectory::default()
    }
    .encode();
    crate::trajectory::take_up(&s, &sink, &payload);
    let deadline = Instant::now() + Duration::from_secs(20);
    while results.0.lock().unwrap().is_empty() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(10));
    }
    let r = results.0.lock().unwrap()[0].clone();
    assert_eq!(r.status, "refused", "{r:?}");
    assert_eq!(r.error_code, Some(cdr::result_code::INVALID_GOAL));
    assert_eq!(r.error_string, format!("joint_trajectory: {said}"));
    let now = sim(&s).snapshot().whj[0].clone();
    assert_eq!(now.mode, 2, "{now:?}");
    assert!(
        (now.position_deg - at.position_deg).abs() < 0.01,
        "{at:?} {now:?}"
    );
    // j2, on position, still moves; j1 once switched back.
    run_request(&s, r#"{"op":"whj.move","joint":2,"degrees":1}"#).unwrap();
    interface(&s, r#"{"interface": "position", "joints": ["j1"]}"#).unwrap();
    run_request(&s, r#"{"op":"whj.move","joint":1,"degrees":1}"#).unwrap();
    done.store(true, Ordering::SeqCst);
}

#[test]
fn a_trajectory_played_to_its_end_holds_its_last_point_instead_of_the_safe_state() {
    // s0 is a wCK servo on a bus whose safe_state is passive (the default): the
    // trajectory's end leaves it in position control at its last point, not passive.
    let (s, done) = armed();
    let results = Arc::new(Results::default());
    let sink: Arc<dyn crate::trajectory::Sink> = results.clone();
    let goal = 10_f64.to_radians();
    let payload = cdr::JointTrajectory {
        joint_names: vec!["s0".into(), "j1".into()],
        points: vec![cdr::JointTrajectoryPoint {
            positions: vec![goal, goal],
            time_from_start: cdr::Duration::from_secs_f64(0.5),
            ..cdr::JointTrajectoryPoint::default()
        }],
        ..cdr::JointTrajectory::default()
    }
    .encode();
    crate::trajectory::take_up(&s, &sink, &payload);
    let deadline = Instant::now() + Duration::from_secs(20);
    while results.0.lock().unwrap().is_empty() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(10));
    }
    let r = results.0.lock().unwrap()[0].clone();
    assert_eq!(r.status, "reached", "{r:?}");
    let snap = sim(&s).snapshot();
    assert_eq!(snap.wck[0].mode, "position", "{:?}", snap.wck[0]);
    assert!(
        snap.whj[0].enabled && snap.whj[0].mode == 3,
        "{:?}",
        snap.whj[0]
    );
    // Still there a while later (held, not let go).
    std::thread::sleep(Duration::from_millis(300));
    let later = sim(&s).snapshot();
    assert_eq!(later.wck[0].mode, "position", "{:?}", later.wck[0]);
    let end = r.joints.iter().find(|j| j.joint == "s0").unwrap();
    let at = end.position_deg.unwrap();
    assert!((at - 10.0).abs() <= 1.0, "{end:?}");
    done.store(true, Ordering::SeqCst);
}
