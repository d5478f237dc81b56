//! End to end: `robobus robot teleop` with the leader and the follower on two simulated
//! wCK buses, each `robobus sim wck` in its own process. The leader's shaft is turned
//! back and forth by the simulator's `--hand`; the follower tracks it; when the leader's
//! simulator is killed, the run ends with exit code 3 and the follower holds where it was.
#![cfg(target_os = "linux")]
#![allow(clippy::unwrap_used, clippy::panic, clippy::float_cmp)] // exact positions: steps are whole numbers

use crate::common;

use std::process::{Command, Stdio};
use std::time::Duration;

use common::robobus;
use robobus::actuator::WCK_DEGREES_PER_STEP;
use serde_json::Value;

const FILE: &str = r#"[buses.leader]
kind = "wck"
port = "LEADER"

[buses.follower]
kind = "wck"
port = "FOLLOWER"

[[joints]]
name = "lead"
bus = "leader"
id = 0
limits = [-1.5, 1.5]
max_velocity = 1.0
max_acceleration = 1.0

[[joints]]
name = "follow"
bus = "follower"
id = 0
limits = [-1.5, 1.5]
max_velocity = 1.0
max_acceleration = 1.0
"#;

/// The follower servo's position step, read by `robobus wck status`.
fn follower_steps(port: &str) -> f64 {
    let r = robobus(&["--json", "wck", "status", "--port", port, "0"]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    let v: Value = serde_json::from_str(&r.stdout).unwrap();
    v["results"][0]["position"].as_f64().unwrap()
}

#[test]
fn the_follower_tracks_the_leader_and_holds_when_its_simulator_is_killed() {
    // The leader's shaft swept between -40° and +40° every 2 s.
    let mut leader = Some(common::WckSim::start("0", &["--hand", "0:-40:40:2"]));
    let follower = common::WckSim::start("0", &[]);
    let dir = tempfile::tempdir().unwrap();
    let robot = dir.path().join("robot.toml");
    let text = FILE
        .replace("LEADER", leader.as_ref().unwrap().port())
        .replace("FOLLOWER", follower.port());
    std::fs::write(&robot, text).unwrap();
    let path = robot.to_str().unwrap();
    // The plan: nothing is opened.
    let plan = robobus(&[
        "--dry-run",
        "robot",
        "teleop",
        "--robot",
        path,
        "--map",
        "lead:follow:-1:5",
        "--limit",
        "follow:-30:30",
    ]);
    assert_eq!(plan.code, Some(0), "{plan:#?}");
    assert!(
        plan.stdout
            .contains("follow ← lead × -1 + 5°, within -30..=30°")
            && plan.stdout.contains("until stopped"),
        "{}",
        plan.stdout
    );
    // Bad input: exit 2, naming the option and what it allows.
    for (args, says) in [
        (
            vec!["--map", "lead:follow:20"],
            "--map scale 20: out of range -10..=10",
        ),
        (
            vec!["--map", "lead:follow", "--limit", "elbow:-5:5"],
            "no --map has the follower elbow",
        ),
        (vec!["--map", "lead"], "expected LEADER:FOLLOWER"),
        (vec!["--map", "lead:follow", "--rate-hz", "0"], "--rate-hz"),
    ] {
        let mut all = vec!["robot", "teleop", "--robot", path];
        all.extend(args);
        let r = robobus(&all);
        assert_eq!(r.code, Some(2), "{r:#?}");
        assert!(r.stderr.contains(says), "{says:?} not in {}", r.stderr);
    }

    let child = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args([
            "--json",
            "robot",
            "teleop",
            "--robot",
            path,
            "--map",
            "lead:follow",
            "--rate-hz",
            "50",
            "--leader-timeout-ms",
            "300",
            "--reply-margin",
            "300",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(2500));
    // The leader is gone: its simulator ends.
    drop(leader.take());
    let r = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(3), "{stderr}");
    assert!(
        stderr.contains("the leader gave no complete reading for")
            && stderr.contains("the follower held where it was"),
        "{stderr}"
    );
    let v: Value = serde_json::from_slice(&r.stdout).unwrap();
    let s = &v["summary"];
    assert_eq!(s["leader_lost"], true, "{v:#}");
    assert!(s["held"].as_u64().unwrap() >= 1, "{v:#}");
    let row = &v["results"][0];
    assert_eq!(row["id"], "follow", "{v:#}");
    assert_eq!(row["failed"], 0, "{v:#}");
    // About two seconds at 50 Hz, each cycle a fresh reading and a command.
    let commands = row["commands"].as_u64().unwrap();
    assert!(commands >= 50, "{v:#}");
    assert_eq!(s["commanded"], commands, "{v:#}");
    // It tracked: the sweep runs at 80°/s, a cycle is 20 ms; the start (the follower
    // 0..40° away) is the largest distance.
    assert!(row["tracking_rms_deg"].as_f64().unwrap() < 10.0, "{v:#}");
    assert!(row["tracking_max_deg"].as_f64().unwrap() <= 45.0, "{v:#}");
    // It holds: within a jog step of its last target, and it stays there.
    let target_steps = 127.0 + row["target_deg"].as_f64().unwrap() / WCK_DEGREES_PER_STEP;
    let at = follower_steps(follower.port());
    assert!(
        (at - target_steps).abs() <= 8.5,
        "{at} vs {target_steps}: {v:#}"
    );
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(follower_steps(follower.port()), at);
}
