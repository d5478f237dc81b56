//! `robobus::station::sampler` against the wCK simulator: one result per device per sample, a
//! silent device failed (never an older value), speeds from consecutive readings on the
//! caller's clock, robot-file joints as joint angles in the file's order.

#![allow(clippy::unwrap_used, clippy::float_cmp)] // tests

use crate::wck_support;

use robobus::ErrorKind;
use robobus::station::sampler::{WckSample, WckSampler};
use wck_support::{id, serve_ids};
// The robot-file test serves its wCK bus on a pty (Unix).
#[cfg(unix)]
use {
    robobus::robot::{RobotConfig, RobotError},
    robobus::station::sampler::{MonitoredJoint, RobotJointSample, RobotSampler},
    robobus::whj::JointBusConfig,
    wck_support::serve_pty,
};

/// Degrees of a wCK position step, as `robobus wck status` prints them (269° over 255
/// steps).
fn deg(step: u8) -> f64 {
    robobus_wck::Position::new(step).unwrap().degrees()
}

#[test]
fn wck_samples_report_each_servo_and_derive_the_speed_from_the_callers_clock() {
    let mut sim = serve_ids(&[0, 1]);
    let mut bus = sim.bus();
    let set = |slot_id: u8, step: u8| {
        sim.with_bus(move |b| {
            let slot = b.slot_of(slot_id).unwrap();
            b.servo_mut(slot).unwrap().set_position(step);
        });
    };
    set(1, 200);
    let mut sampler = WckSampler::new(&[id(0), id(1), id(3)]);
    let first = sampler.sample(&mut bus, 10.0);
    let ids: Vec<u8> = first.iter().map(|r| r.id).collect();
    assert_eq!(ids, [0, 1, 3]);
    assert_eq!(
        first[1].value(),
        Some(&WckSample {
            position_deg: deg(200),
            speed_deg_s: None,
            load: first[1].value().unwrap().load,
        })
    );
    assert_eq!(first[0].value().unwrap().position_deg, deg(127));
    // Servo 3 is not there: a failure of its own, the others still read.
    assert_eq!(first[2].failure().unwrap().kind, ErrorKind::NoDevice);

    // 10 steps in 0.5 s of the caller's clock.
    set(1, 210);
    let second = sampler.sample(&mut bus, 10.5);
    let s1 = second[1].value().unwrap();
    assert_eq!(s1.position_deg, deg(210));
    assert_eq!(s1.speed_deg_s, Some((deg(210) - deg(200)) / 0.5));
    assert_eq!(second[0].value().unwrap().speed_deg_s, Some(0.0));
    assert!(second[2].value().is_none(), "never an older value");
}

#[cfg(unix)] // a robot file's wCK bus on a pty
#[test]
fn a_robot_file_is_sampled_as_joint_angles_in_its_order() {
    let mut sim = serve_pty(&[0, 1]);
    drop(sim.slave.take()); // the sampler opens the port by its path
    sim.with_bus(|b| {
        let slot = b.slot_of(1).unwrap();
        b.servo_mut(slot).unwrap().set_position(200);
    });
    let port = sim.endpoint.path().display().to_string();
    let file = format!(
        r#"
        [buses.legs]
        kind = "wck"
        port = "{port}"

        [[joints]]
        name = "left knee"
        bus = "legs"
        id = 1
        direction = -1
        offset = 0.05
        limits = [-1.5, 0.2]
        max_velocity = 1.0
        max_acceleration = 1.0

        [[joints]]
        name = "hip"
        bus = "legs"
        id = 0
        centre = 100
        limits = [-1.0, 1.0]
        max_velocity = 1.0
        max_acceleration = 1.0
        "#
    );
    let config = RobotConfig::from_toml_str(&file).unwrap();
    let margin = Some(wck_support::PTY_MARGIN);
    let mut sampler = RobotSampler::open(&config, JointBusConfig::default(), margin).unwrap();
    assert_eq!(
        sampler.joints(),
        [
            MonitoredJoint {
                name: "left knee".into(),
                wck: true
            },
            MonitoredJoint {
                name: "hip".into(),
                wck: true
            }
        ]
    );
    assert_eq!(
        sampler.buses(),
        [format!("legs: wCK {port} at 115200 bit/s")]
    );
    let sample = sampler.sample(0.0);
    assert_eq!(sample[0].id, "left knee");
    assert_eq!(sample[1].id, "hip");
    let knee = sample[0].value().unwrap();
    // Step 200 is 73 steps past the default centre 127, mirrored about 0.05 rad.
    let want = -((73.0 * 269.0 / 255.0_f64).to_radians() - 0.05);
    assert!(
        (knee.position_deg - want.to_degrees()).abs() < 1e-9,
        "{knee:?}"
    );
    assert_eq!(
        (
            knee.speed_deg_s,
            knee.current_ma,
            knee.enabled,
            knee.error.as_str()
        ),
        (None, None, None, "ok")
    );
    let hip: &RobotJointSample = sample[1].value().unwrap();
    // Step 127 with centre 100: 27 steps.
    assert!(
        (hip.position_deg - 27.0 * 269.0 / 255.0).abs() < 1e-9,
        "{hip:?}"
    );
    assert!(hip.load.is_some());

    // A bus a program supplies cannot be monitored: refused, naming the bus and kind.
    let external = file.replace(
        &format!("kind = \"wck\"\n        port = \"{port}\""),
        "kind = \"wck-external\"",
    );
    let config = RobotConfig::from_toml_str(&external).unwrap();
    let err = RobotSampler::open(&config, JointBusConfig::default(), margin).unwrap_err();
    assert!(
        matches!(err, RobotError::Invalid { field: "kind", .. }),
        "{err}"
    );
    assert!(
        err.to_string().contains("bus legs") && err.to_string().contains("wck-external"),
        "{err}"
    );
}
