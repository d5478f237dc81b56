//! End to end: `robobus robot play` of a CSV of velocities on a wCK servo in wheel mode
//! (`robobus sim wck` in its own process, on the wall clock): the wheel level sent for the
//! asked speed, the servo left in the robot file's safe state; a joint without the
//! velocity interface, or a speed past its limit, refused (exit 2) before anything opens.
#![cfg(target_os = "linux")]
#![allow(clippy::unwrap_used, clippy::panic)]

use crate::common;

use common::robobus;
use serde_json::Value;

/// A wheel (velocity, level 15 at 6.98 rad/s: 400 °/s, the wCK-1108's no-load speed)
/// and a knee (position only) on one bus.
const ROBOT: &str = r#"[buses.base]
kind = "wck"
port = "PORT"

[[joints]]
name = "wheel"
bus = "base"
id = 0
limits = [-1.5, 1.5]
max_velocity = 7.0
max_acceleration = 50.0
interfaces = ["position", "velocity"]
wheel_speeds = 6.981317

[[joints]]
name = "knee"
bus = "base"
id = 1
limits = [-1.5, 1.5]
max_velocity = 2.0
max_acceleration = 10.0
"#;

#[test]
fn a_csv_of_velocities_turns_a_wheel_and_one_past_its_interface_is_refused() {
    let sim = common::WckSim::start("0-1", &[]);
    let dir = tempfile::tempdir().unwrap();
    let robot = dir.path().join("robot.toml");
    std::fs::write(&robot, ROBOT.replace("PORT", sim.port())).unwrap();
    let robot = robot.to_str().unwrap();
    let csv = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p.to_str().unwrap().to_owned()
    };
    // 180 °/s: nearest the level of 7 × 400 / 15 = 186.7 °/s.
    let spin = csv("spin.csv", "time_s,wheel_deg_s\n0,180\n0.5,180\n");
    let r = robobus(&[
        "--json",
        "robot",
        "play",
        &spin,
        "--robot",
        robot,
        "--reply-margin",
        "300",
    ]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    let v: Value = serde_json::from_str(&r.stdout).unwrap();
    let row = &v["results"][0];
    assert_eq!(row["id"], "wheel", "{v:#}");
    assert_eq!(row["failed"], 0, "{row}");
    let ticks = v["summary"]["ticks"].as_u64().unwrap();
    assert_eq!(row["commands"], ticks, "{row}");
    let sent = row["sent_deg_s"].as_f64().unwrap();
    assert!((sent - 7.0 * 400.0 / 15.0).abs() < 1e-3, "{row}");
    assert_eq!(
        v["summary"]["safe_state"][0]["safe_state"], "passive",
        "{v:#}"
    );

    for (file, says) in [
        (
            csv("knee.csv", "time_s,knee_deg_s\n0,10\n"),
            "knee has no velocity interface in the robot file (its interfaces: position)",
        ),
        (
            csv("fast.csv", "time_s,wheel_deg_s\n0,10\n1,420\n"),
            "trajectory line 3: wheel 420 deg/s is outside -401.070..=401.070 deg/s",
        ),
    ] {
        let r = robobus(&["robot", "play", &file, "--robot", robot]);
        assert_eq!(r.code, Some(2), "{r:#?}");
        assert!(r.stderr.contains(says), "{says:?} not in {}", r.stderr);
    }
}
