#![allow(clippy::unwrap_used)]

use std::time::Duration;

use super::*;
use crate::ops::Outcome;
use crate::station::clock::BusClock;

/// The built-in simulated station with a robot file of two WHJ joints with velocity
/// and effort, enabled in position mode, and its driver.
fn driven() -> (Station, robobus_sim::whj::WhjSimHandle, Driver) {
    let file = r#"
        [buses.sim-whj]
        kind = "whj-external"
        [[joints]]
        name = "j1"
        bus = "sim-whj"
        id = 1
        limits = [-2.0, 2.0]
        max_velocity = 2.0
        max_acceleration = 20.0
        interfaces = ["position", "velocity", "effort"]
        max_effort = 5.0
        [[joints]]
        name = "j2"
        bus = "sim-whj"
        id = 2
        limits = [-2.0, 2.0]
        max_velocity = 2.0
        max_acceleration = 20.0
        interfaces = ["position", "velocity"]
    "#;
    let (station, whj) = crate::station::follow::testing::enabled(file, "1-2");
    let driver = Driver::new(&station).unwrap();
    (station, whj, driver)
}

/// A wheel held still while streamed its level-2 speed (267 mA held on the simulated
/// 1108, under its 400 mA over-load): read every 0.25 s (at the commands at 0, 0.26,
/// 0.52, 0.78 s), the stall seen at 0.26 s and held for two periods (0.5 s), the
/// stream is stopped at 0.78 s naming the wheel, which is left passive (its bus's
/// safe state), and later commands are refused.
#[test]
fn a_wheel_held_still_under_a_velocity_stream_is_stopped_naming_it() {
    let (mut station, wck, _whj) = Station::simulated_with_handles().unwrap();
    station
        .set_robot(RobotConfig::from_toml_str(crate::robot::simulated::DRIVE_ROBOT).unwrap())
        .unwrap();
    let driver = Driver::new(&station).unwrap();
    driver
        .switch(&station, &["s0".to_owned()], Interface::Velocity)
        .unwrap();
    wck.with_bus(|b| b.servo_mut(0).unwrap().hold(true));
    let level_2 = crate::robot::simulated::sim_1108_wheel_speeds()[1];
    let clock = BusClock::of(&station, station.robot().unwrap()).unwrap();
    let start = clock.now();
    let mut stopped_at = None;
    for k in 0..100u32 {
        clock.sleep_until(start + Duration::from_millis(20) * k);
        let plan = driver.plan(Interface::Velocity, &[level_2]).unwrap();
        let done = driver.apply(&station, Interface::Velocity, &plan);
        if let Outcome::Failed(f) = &done[0].outcome {
            assert_eq!(f.kind, ErrorKind::Device, "{f:?}");
            assert!(
                f.error
                    .starts_with("s0: stall protection: current 0.27 A reached the limit 0.2 A")
                    && f.error.ends_with("servo 0 passive"),
                "{}",
                f.error
            );
            stopped_at = Some(f64::from(k) * 0.02);
            break;
        }
    }
    let t = stopped_at.expect("the stream was never stopped");
    assert!((0.77..=0.79).contains(&t), "{t}");
    assert_eq!(
        wck.with_bus(|b| b.servo(0).unwrap().mode()),
        robobus_sim::wck::Mode::Passive
    );
    assert!(driver.stopped().is_some());
    assert!(driver.plan(Interface::Velocity, &[level_2]).is_err());
}

#[test]
fn an_obstacle_stops_a_velocity_stream_and_later_commands_are_refused() {
    let (station, whj, driver) = driven();
    let names = ["j1".to_owned(), "j2".to_owned()];
    driver
        .switch(&station, &names, Interface::Velocity)
        .unwrap();
    // A stop 5° above where j1 stands; j1 streamed 30°/s at 50 Hz, j2 0.
    whj.with_bus(|b| {
        let j = b.joint_mut(1).unwrap();
        let at = j.state().physical_deg + 5.0;
        j.set_obstacle(Some(robobus_sim::whj::Obstacle::above(at)));
    });
    let clock = BusClock::of(&station, station.robot().unwrap()).unwrap();
    let start = clock.now();
    let mut stopped_at = None;
    for k in 0..100u32 {
        clock.sleep_until(start + Duration::from_millis(20) * k);
        let plan = driver
            .plan(Interface::Velocity, &[30f64.to_radians(), 0.0])
            .unwrap();
        let done = driver.apply(&station, Interface::Velocity, &plan);
        if let Outcome::Failed(f) = &done[0].outcome {
            assert_eq!(f.kind, ErrorKind::Device, "{f:?}");
            assert!(
                f.error.starts_with("j1: stall protection: current ")
                    && f.error.contains("reached the limit 7.8 A at ")
                    && f.error.ends_with(
                        "(the joint did not move as commanded meanwhile); its drive \
                         disabled (its brake holds it: holding would keep it pushing or \
                         heating)"
                    ),
                "{}",
                f.error
            );
            stopped_at = Some(f64::from(k) * 0.02);
            break;
        }
    }
    // j1 reaches the stop at about 0.17 s; the stall current comes about 0.13 s later
    // and the stall time (0.3 s) after that the stream is stopped.
    let t = stopped_at.expect("the stream was never stopped");
    assert!((0.55..=0.7).contains(&t), "{t}");
    let events = driver.protection();
    assert_eq!(events.len(), 1, "{events:?}");
    assert_eq!(
        (events[0].joint.as_str(), events[0].quantity),
        ("j1", "current_a")
    );
    // j1 is back on position and disabled; j2 still on velocity.
    let j1 = whj.with_bus(|b| b.joint(1).unwrap().state());
    assert!(
        !j1.enabled && j1.current_a.abs() < 1e-9 && j1.mode == 3,
        "{j1:?}"
    );
    let on: Vec<String> = driver
        .on(Interface::Velocity)
        .into_iter()
        .map(|j| j.name)
        .collect();
    assert_eq!(on, ["j2"]);
    // Every later command is refused whole, nothing sent, until resumed.
    let frames = whj.with_bus(|b| b.joint(2).unwrap().frames_handled());
    let e = driver.plan(Interface::Velocity, &[0.1]).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused);
    assert!(
        e.to_string()
            .contains("protection stopped a driven joint (j1: stall protection"),
        "{e}"
    );
    assert_eq!(
        whj.with_bus(|b| b.joint(2).unwrap().frames_handled()),
        frames
    );
    driver.resume();
    let plan = driver.plan(Interface::Velocity, &[0.0]).unwrap();
    assert!(driver.apply(&station, Interface::Velocity, &plan)[0].is_ok());
}

/// A command's WHJ frames on one bus go out in one batch: one reply's duplicate check
/// overlaps the other joint's frame, so two joints together cost at least one feedback
/// frame less than one after the other, and each joint's row is its own.
#[test]
fn a_command_sends_one_buss_whj_frames_in_one_batch() {
    let (station, _whj, driver) = driven();
    let names = ["j1".to_owned(), "j2".to_owned()];
    driver
        .switch(&station, &names, Interface::Velocity)
        .unwrap();
    let clock = BusClock::of(&station, station.robot().unwrap()).unwrap();
    let plan = driver.plan(Interface::Velocity, &[0.0, 0.0]).unwrap();
    assert_eq!(plan.len(), 2);
    // The first command reads what the protection needs once.
    assert!(
        driver
            .apply(&station, Interface::Velocity, &plan)
            .iter()
            .all(crate::ops::DeviceResult::is_ok)
    );
    let t = clock.now();
    for one in plan.chunks(1) {
        let done = driver.apply(&station, Interface::Velocity, one);
        assert!(done.len() == 1 && done[0].is_ok(), "{done:?}");
    }
    let alone = clock.now() - t;
    let t = clock.now();
    let done = driver.apply(&station, Interface::Velocity, &plan);
    let together = clock.now() - t;
    let rows: Vec<&str> = done.iter().map(|r| r.id.as_str()).collect();
    assert_eq!(rows, ["j1", "j2"]);
    assert!(done.iter().all(crate::ops::DeviceResult::is_ok), "{done:?}");
    let id = robobus_whj::CanFrame::standard_id(0x501).unwrap();
    let feedback = robobus_whj::CanFrame::new_fd(id, &[0x55; 16]).unwrap();
    let frame = robobus_whj::timing::frame_duration(&feedback, robobus_whj::timing::BitRates::WHJ);
    assert!(
        together + frame <= alone,
        "together {together:?}, alone {alone:?}, a feedback frame {frame:?}"
    );
}
