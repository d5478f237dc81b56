//! End to end: `robobus robot calibrate` on a robot file whose wCK servos are served by
//! `robobus sim wck` in its own process, their shafts turned back and forth by its
//! `--hand` (as someone calibrating the robot does): the file gets each joint's range as
//! its limits, keeps its comments, and `robobus monitor --robot` then reads it.
#![cfg(target_os = "linux")]
#![allow(clippy::unwrap_used, clippy::panic)]

use crate::common;

use common::robobus;
use serde_json::Value;

const FILE: &str = r#"# the legs, calibrated by hand
[buses.leg]
kind = "wck"
port = "PORT"

[[joints]]
name = "hip"          # left hip
bus = "leg"
id = 0
limits = [-2.0, 2.0]  # placeholder
max_velocity = 1.0
max_acceleration = 1.0

[[joints]]
name = "knee"
bus = "leg"
id = 1
direction = -1
limits = [-2.0, 2.0]
max_velocity = 1.0
max_acceleration = 1.0
"#;

#[test]
fn calibration_by_hand_writes_limits_the_monitor_then_accepts() {
    // Servo 0 swept between -40° and 50°, servo 1 between -20° and 30°, once a second.
    let sim = common::WckSim::start("0-1", &["--hand", "0:-40:50:1", "--hand", "1:-20:30:1"]);
    let dir = tempfile::tempdir().unwrap();
    let robot = dir.path().join("robot.toml");
    let original = FILE.replace("PORT", sim.port());
    std::fs::write(&robot, &original).unwrap();
    let path = robot.to_str().unwrap();
    // The plan first: nothing opened.
    let plan = robobus(&[
        "--dry-run",
        "robot",
        "calibrate",
        "--robot",
        path,
        "--seconds",
        "1",
    ]);
    assert_eq!(plan.code, Some(0), "{plan:#?}");
    assert!(
        plan.stdout.contains("passive") && plan.stdout.contains("20 times"),
        "{}",
        plan.stdout
    );
    // Bad input: exit 2 naming the option and its range, the file untouched.
    let bad = robobus(&[
        "robot",
        "calibrate",
        "--robot",
        path,
        "--seconds",
        "0",
        "--write",
    ]);
    assert_eq!(bad.code, Some(2), "{bad:#?}");
    assert!(
        bad.stderr.contains("--seconds") && bad.stderr.contains("0.1..=600"),
        "{}",
        bad.stderr
    );

    // Two and a half sweeps, each end passed at least twice.
    let r = robobus(&[
        "--json",
        "robot",
        "calibrate",
        "--robot",
        path,
        "--seconds",
        "2.5",
        "--zero",
        "keep",
        "--reply-margin",
        "300",
        "--write",
    ]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    let v: Value = serde_json::from_str(&r.stdout).unwrap();
    assert_eq!(v["op"], "robot.calibrate");
    // The knee is mounted mirrored: its joint angles are the servo's, negated.
    for (row, lo, hi) in [
        (&v["results"][0], -40.0, 50.0),
        (&v["results"][1], -30.0, 20.0),
    ] {
        let min = row["min_deg"].as_f64().unwrap();
        let max = row["max_deg"].as_f64().unwrap();
        // The sweep was read at 20 Hz: the extremes within what the hand turns in half a
        // reading's 50 ms (4.5° at the hip's 180°/s). (Swept twice a second, 9°: 20 Hz
        // readings of a 2 Hz sweep fall on the same points of every sweep, and a start
        // that put none near an end failed the 8° below.)
        assert!((min - lo).abs() < 8.0 && (max - hi).abs() < 8.0, "{row}");
        let limits = &row["limits_rad"];
        assert!(
            (limits[0].as_f64().unwrap().to_degrees() - (min + 2.0)).abs() < 1e-3,
            "{row}"
        );
    }
    // Written in place, the old file kept beside it, the comments and order kept.
    let text = std::fs::read_to_string(&robot).unwrap();
    assert_eq!(
        std::fs::read_to_string(dir.path().join("robot.toml.bak")).unwrap(),
        original
    );
    for kept in [
        "# the legs, calibrated by hand",
        "# left hip",
        "# placeholder",
        "direction = -1",
    ] {
        assert!(text.contains(kept), "{kept:?} lost in:\n{text}");
    }
    assert!(!text.contains("limits = [-2.0, 2.0]  #"), "{text}");
    // The monitor reads the calibrated robot.
    let m = robobus(&[
        "--json",
        "monitor",
        "--robot",
        path,
        "--rate-hz",
        "10",
        "--duration",
        "0.5",
        "--reply-margin",
        "300",
    ]);
    assert_eq!(m.code, Some(0), "{m:#?}");
    let samples = common::json_lines(&m.stdout);
    assert_eq!(
        samples.last().unwrap()["channels"][1]["name"],
        "knee",
        "{}",
        m.stdout
    );
}

#[test]
fn ctrl_c_ends_the_reading_keeps_what_was_read_and_exits_130() {
    let sim = common::WckSim::start("0-1", &["--hand", "0:-30:30:0.4", "--hand", "1:-10:40:0.4"]);
    let dir = tempfile::tempdir().unwrap();
    let robot = dir.path().join("robot.toml");
    std::fs::write(&robot, FILE.replace("PORT", sim.port())).unwrap();
    let out = dir.path().join("calibrated.toml");
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args([
            "--json",
            "robot",
            "calibrate",
            "--seconds",
            "60",
            "--reply-margin",
            "300",
        ])
        .arg("--robot")
        .arg(&robot)
        .arg("-o")
        .arg(&out)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let signalled = std::process::Command::new("kill")
        .arg("-INT")
        .arg(child.id().to_string())
        .status()
        .unwrap();
    assert!(signalled.success());
    let r = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(130), "{stderr}");
    let v: Value = serde_json::from_slice(&r.stdout).unwrap();
    assert_eq!(v["summary"]["interrupted"], true, "{v}");
    let n = v["summary"]["readings"].as_u64().unwrap();
    assert!((5..1200).contains(&n), "{v}");
    // What was read went into the output file; the robot file is untouched.
    let text = std::fs::read_to_string(&out).unwrap();
    assert!(
        text.contains("# left hip") && !text.contains("limits = [-2.0, 2.0]  #"),
        "{text}"
    );
    assert_eq!(
        std::fs::read_to_string(&robot).unwrap(),
        FILE.replace("PORT", sim.port())
    );
}
