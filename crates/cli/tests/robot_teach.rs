//! End to end: `robobus robot teach` records a trajectory by hand from servos that
//! `robobus sim wck --hand` turns back and forth in its own process; it asks for
//! confirmation first, and what it writes is a trajectory `robobus robot play` accepts.
#![cfg(target_os = "linux")]
#![allow(clippy::unwrap_used, clippy::panic)]

use crate::common;

use common::robobus;
use serde_json::Value;

const FILE: &str = r#"[buses.arm]
kind = "wck"
port = "PORT"

[[joints]]
name = "elbow"
bus = "arm"
id = 0
limits = [-1.5, 1.5]
max_velocity = 2.0
max_acceleration = 10.0

[[joints]]
name = "wrist"
bus = "arm"
id = 1
direction = -1
limits = [-1.5, 1.5]
max_velocity = 2.0
max_acceleration = 10.0
"#;

#[test]
fn a_trajectory_taught_by_hand_is_written_and_plays() {
    // Servo 0 swept between -30° and 30° every 2 s, servo 1 between 0° and 20°.
    let sim = common::WckSim::start("0-1", &["--hand", "0:-30:30:2", "--hand", "1:0:20:2"]);
    let dir = tempfile::tempdir().unwrap();
    let robot = dir.path().join("robot.toml");
    std::fs::write(&robot, FILE.replace("PORT", sim.port())).unwrap();
    let out = dir.path().join("taught.csv");
    let (robot, out_s) = (robot.to_str().unwrap(), out.to_str().unwrap());
    let args = [
        "robot",
        "teach",
        "--robot",
        robot,
        "--seconds",
        "1.5",
        "-o",
        out_s,
    ];
    // Limp joints: without --yes (and no terminal to ask on) nothing happens.
    let r = robobus(&args);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(
        r.stderr.contains("go limp") && r.stderr.contains("--yes"),
        "{}",
        r.stderr
    );
    assert!(!out.exists());
    // The plan names the confirmation.
    let mut plan = vec!["--dry-run"];
    plan.extend(args);
    let p = robobus(&plan);
    assert_eq!(p.code, Some(0), "{p:#?}");
    assert!(p.stdout.contains("30 times at 20 Hz"), "{}", p.stdout);

    let mut run = vec!["--json", "--yes"];
    run.extend(args);
    run.extend(["--reply-margin", "300"]);
    let r = robobus(&run);
    assert_eq!(r.code, Some(0), "{r:#?}");
    let v: Value = serde_json::from_str(&r.stdout).unwrap();
    assert_eq!(v["summary"]["points"], 30, "{v:#}");
    // The mirrored wrist reads the servo's angle negated.
    let wrist = &v["results"][1];
    assert!(wrist["max_deg"].as_f64().unwrap() <= 1.1, "{wrist}");
    assert!(wrist["min_deg"].as_f64().unwrap() < -5.0, "{wrist}");
    // Left as the robot file's bus says (a wCK bus's default: passive).
    assert_eq!(wrist["ended"], "passive");
    let text = std::fs::read_to_string(&out).unwrap();
    assert!(text.contains("time_s,elbow,wrist\n"), "{text}");
    assert_eq!(text.lines().filter(|l| !l.starts_with('#')).count(), 31);
    // `robot play` accepts it: checked against the robot file, nothing opened.
    let p = robobus(&["--dry-run", "robot", "play", out_s, "--robot", robot]);
    assert_eq!(p.code, Some(0), "{p:#?}");
    assert!(p.stdout.contains("plays 30 points"), "{}", p.stdout);
}
