//! End to end: `robobus robot play` on WHJ joints of `robobus sim whj` in its own process
//! (UDP multicast inside a private network namespace) ends with the bus in the robot
//! file's `safe_state`, after the command has exited: `hold` leaves the joints enabled in
//! position mode, so the next `robot play` runs; `disable` leaves them disabled.
#![cfg(target_os = "linux")]
#![allow(clippy::unwrap_used, clippy::panic)]

use crate::common;

use serde_json::Value;

const INSIDE: &str = "ROBOBUS_IN_NETNS";

/// Runs the test `name` again inside a private network namespace; `true` inside it.
fn in_netns(name: &str) -> bool {
    if std::env::var_os(INSIDE).is_some() {
        return true;
    }
    robobus_testkit::Inner::exact(module_path!(), name, INSIDE)
        .not_ignored()
        .timeout_s(300)
        .in_private_netns()
        .expect_marker("1 passed");
    false
}

const ROBOT: &str = r#"[buses.arm]
kind = "whj-udp"
group = "GROUP"
port = PORT
SAFE

[[joints]]
name = "shoulder"
bus = "arm"
id = 1
limits = [-1.0, 1.0]
max_velocity = 1.0
max_acceleration = 5.0

[[joints]]
name = "elbow"
bus = "arm"
id = 2
limits = [-1.0, 1.0]
max_velocity = 1.0
max_acceleration = 5.0
"#;

const WAVE: &str = "time_s,shoulder,elbow\n0,0,0\n0.5,5,-5\n1,0,0\n";

/// Each joint's (enabled, mode, brake) as `robobus whj status` reads them.
fn states(bus: &str) -> Vec<(bool, String, String)> {
    let r = common::robobus(&["--json", "whj", "--bus", bus, "status", "1-2"]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    let v: Value = serde_json::from_str(&r.stdout).unwrap();
    v["results"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| {
            (
                s["enabled"].as_bool().unwrap(),
                s["mode"].as_str().unwrap().to_owned(),
                s["brake"].as_str().unwrap().to_owned(),
            )
        })
        .collect()
}

/// Plays the wave twice on a file whose WHJ bus says `safe` (empty: the default), with
/// `robobus robot play`.
fn play_twice(group: &str, port: &str, safe: &str) -> (common::Run, common::Run, String) {
    play_twice_with(group, port, safe, false)
}

/// [`play_twice`], through `robobus run` and a `robot.play` request with `run`.
fn play_twice_with(
    group: &str,
    port: &str,
    safe: &str,
    run: bool,
) -> (common::Run, common::Run, String) {
    let bus = format!("udp:{group}:{port}");
    let _sim = common::WhjSim::start(&bus, &[]);
    for args in [["mode", "1-2", "position"].as_slice(), &["enable", "1-2"]] {
        let mut all = vec!["whj", "--bus", bus.as_str()];
        all.extend_from_slice(args);
        let r = common::robobus(&all);
        assert_eq!(r.code, Some(0), "{r:#?}");
    }
    let dir = tempfile::tempdir().unwrap();
    let robot = dir.path().join("robot.toml");
    let text = ROBOT
        .replace("GROUP", group)
        .replace("PORT", port)
        .replace("SAFE", safe);
    std::fs::write(&robot, text).unwrap();
    let wave = dir.path().join("wave.csv");
    std::fs::write(&wave, WAVE).unwrap();
    let request = dir.path().join("play.json");
    let json = serde_json::json!({"op": "robot.play", "trajectory": WAVE});
    std::fs::write(&request, json.to_string()).unwrap();
    let args: Vec<&str> = if run {
        let (robot, request) = (robot.to_str().unwrap(), request.to_str().unwrap());
        vec!["run", "--robot", robot, request]
    } else {
        let (wave, robot) = (wave.to_str().unwrap(), robot.to_str().unwrap());
        vec!["--json", "robot", "play", wave, "--robot", robot]
    };
    let first = common::robobus(&args);
    let after = format!("{:?}", states(&bus));
    let second = common::robobus(&args);
    (first, second, after)
}

#[test]
fn robot_play_leaves_whj_joints_holding_as_the_file_says_and_plays_again() {
    if !in_netns("robot_play_leaves_whj_joints_holding_as_the_file_says_and_plays_again") {
        return;
    }
    let (first, second, after) = play_twice("239.74.163.21", "43131", "");
    assert_eq!(first.code, Some(0), "{first:#?}");
    let v: Value = serde_json::from_str(&first.stdout).unwrap();
    assert_eq!(
        v["summary"]["safe_state"],
        serde_json::json!([{"bus": "arm", "safe_state": "hold", "failed": []}]),
        "{v:#}"
    );
    // After the command exited: enabled in position mode, the brakes released.
    let holding = "(true, \"position\", \"released\")";
    assert_eq!(after, format!("[{holding}, {holding}]"));
    assert_eq!(second.code, Some(0), "{second:#?}");
}

#[test]
fn robot_play_leaves_whj_joints_disabled_when_the_file_says_disable() {
    if !in_netns("robot_play_leaves_whj_joints_disabled_when_the_file_says_disable") {
        return;
    }
    let (first, second, after) = play_twice("239.74.163.22", "43132", "safe_state = \"disable\"");
    assert_eq!(first.code, Some(0), "{first:#?}");
    let disabled = "(false, \"position\", \"locked\")";
    assert_eq!(after, format!("[{disabled}, {disabled}]"));
    // The next play is refused before anything moves: the file asked for disabled joints.
    assert_ne!(second.code, Some(0), "{second:#?}");
    assert!(
        second.stderr.contains("shoulder: joint 1 is disabled"),
        "{}",
        second.stderr
    );
}

#[test]
fn a_robot_play_request_through_robobus_run_leaves_the_joints_holding_too() {
    if !in_netns("a_robot_play_request_through_robobus_run_leaves_the_joints_holding_too") {
        return;
    }
    let (first, second, after) = play_twice_with("239.74.163.23", "43133", "", true);
    assert_eq!(first.code, Some(0), "{first:#?}");
    let holding = "(true, \"position\", \"released\")";
    assert_eq!(after, format!("[{holding}, {holding}]"));
    assert_eq!(second.code, Some(0), "{second:#?}");
}
