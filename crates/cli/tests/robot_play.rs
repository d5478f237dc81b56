//! End to end: `robobus robot play` of a trajectory over two simulated wCK buses (each
//! `robobus sim wck` in its own process, on the wall clock), recorded to MCAP and read
//! back by `robobus plot` (the `mcap` crate) and by Python's `mcap` reader; the commands
//! and the positions are on one time base. Bad trajectories are refused before anything
//! opens.
#![cfg(target_os = "linux")]
#![allow(clippy::unwrap_used, clippy::panic)]

use crate::common;

use common::robobus;
use serde_json::Value;

const ROBOT: &str = r#"[buses.legs]
kind = "wck"
port = "LEGS"

[buses.arm]
kind = "wck"
port = "ARM"

[[joints]]
name = "hip"
bus = "legs"
id = 0
limits = [-1.5, 1.5]
max_velocity = 2.0
max_acceleration = 10.0

[[joints]]
name = "knee"
bus = "legs"
id = 1
direction = -1
limits = [-1.5, 1.5]
max_velocity = 2.0
max_acceleration = 10.0

[[joints]]
name = "shoulder"
bus = "arm"
id = 0
limits = [-1.5, 1.5]
max_velocity = 2.0
max_acceleration = 10.0
"#;

const WAVE: &str = "# a wave of both buses\n\
    time_s,hip,knee,shoulder\n\
    0,0,0,0\n\
    0.5,20,-20,30\n\
    1.0,0,0,0\n";

/// Two simulated buses, the robot file naming them and the trajectory, in `dir`.
struct Setup {
    _legs: common::WckSim,
    _arm: common::WckSim,
    dir: tempfile::TempDir,
    robot: String,
    wave: String,
}

fn setup() -> Setup {
    let legs = common::WckSim::start("0-1", &[]);
    let arm = common::WckSim::start("0", &[]);
    let dir = tempfile::tempdir().unwrap();
    let robot = dir.path().join("robot.toml");
    std::fs::write(
        &robot,
        ROBOT
            .replace("LEGS", legs.port())
            .replace("ARM", arm.port()),
    )
    .unwrap();
    let wave = dir.path().join("wave.csv");
    std::fs::write(&wave, WAVE).unwrap();

    let (robot, wave) = (
        robot.to_str().unwrap().to_owned(),
        wave.to_str().unwrap().to_owned(),
    );
    Setup {
        _legs: legs,
        _arm: arm,
        dir,
        robot,
        wave,
    }
}

#[test]
fn a_trajectory_is_planned_as_its_request_and_refused_before_anything_opens() {
    // The simulators live as long as the test (a `..` would drop them at once).
    let Setup {
        _legs: _legs_sim,
        _arm: _arm_sim,
        dir,
        robot,
        wave,
    } = setup();
    let (robot, wave) = (robot.as_str(), wave.as_str());
    // The plan, and bad input: exit 2 before anything opens.
    let plan = robobus(&["--dry-run", "robot", "play", wave, "--robot", robot]);
    assert_eq!(plan.code, Some(0), "{plan:#?}");
    assert!(
        plan.stdout
            .contains("plays 3 points over 1 s, 50 ticks a second"),
        "{}",
        plan.stdout
    );
    // The same request through `robobus run` plans the same.
    let request = dir.path().join("request.json");
    let json = serde_json::json!({"op": "robot.play", "trajectory": WAVE, "rate_hz": 25});
    std::fs::write(&request, json.to_string()).unwrap();
    let cli = robobus(&[
        "--dry-run",
        "robot",
        "play",
        wave,
        "--robot",
        robot,
        "--rate-hz",
        "25",
    ]);
    let run = robobus(&["run", "--dry-run", request.to_str().unwrap()]);
    assert_eq!(
        (cli.code, run.code),
        (Some(0), Some(0)),
        "{cli:#?} {run:#?}"
    );
    assert_eq!(cli.stdout, run.stdout);
    // The pre-flight on the simulator: on by default (the plan says what it reads), off
    // with --no-preflight as with the request's `"preflight": false`.
    assert!(plan.stdout.contains("pre-flight:"), "{}", plan.stdout);
    let off = dir.path().join("off.json");
    let json = serde_json::json!({"op": "robot.play", "trajectory": WAVE, "preflight": false});
    std::fs::write(&off, json.to_string()).unwrap();
    let cli = robobus(&[
        "--dry-run",
        "robot",
        "play",
        wave,
        "--robot",
        robot,
        "--no-preflight",
    ]);
    let run = robobus(&["run", "--dry-run", off.to_str().unwrap()]);
    assert_eq!(
        (cli.code, run.code),
        (Some(0), Some(0)),
        "{cli:#?} {run:#?}"
    );
    assert_eq!(cli.stdout, run.stdout);
    assert!(!cli.stdout.contains("pre-flight"), "{}", cli.stdout);
    let fast = dir.path().join("fast.csv");
    std::fs::write(&fast, "time_s,hip\n0,0\n0.1,60\n").unwrap();
    for (args, says) in [
        (
            vec!["robot", "play", fast.to_str().unwrap(), "--robot", robot],
            "line 3: hip moves 60.000° in 0.100 s",
        ),
        (
            vec!["robot", "play", wave, "--robot", robot, "--rate-hz", "900"],
            "--rate-hz",
        ),
        (
            vec!["robot", "play", wave, "--robot", robot, "--record", "x.txt"],
            ".mcap",
        ),
        (
            vec![
                "robot",
                "play",
                wave,
                "--robot",
                robot,
                "--preflight",
                "--no-preflight",
            ],
            "--no-preflight",
        ),
    ] {
        let r = robobus(&args);
        assert_eq!(r.code, Some(2), "{r:#?}");
        assert!(r.stderr.contains(says), "{says:?} not in {}", r.stderr);
    }
}

#[test]
fn a_trajectory_on_two_buses_is_played_recorded_and_read_back() {
    // The simulators live as long as the test (a `..` would drop them at once).
    let Setup {
        _legs: _legs_sim,
        _arm: _arm_sim,
        dir,
        robot,
        wave,
    } = setup();
    let (robot, wave) = (robot.as_str(), wave.as_str());
    let mcap = dir.path().join("wave.mcap");
    let r = robobus(&[
        "--json",
        "robot",
        "play",
        wave,
        "--robot",
        robot,
        "--record",
        mcap.to_str().unwrap(),
        "--reply-margin",
        "300",
    ]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    let v: Value = serde_json::from_str(&r.stdout).unwrap();
    let s = &v["summary"];
    assert_eq!(s["buses"], serde_json::json!(["arm", "legs"]), "{s}");
    let ticks = s["ticks"].as_u64().unwrap();
    // 1 s at 50 Hz, both ends included, unless a slow tick was skipped (counted).
    assert_eq!(ticks + s["overruns"].as_u64().unwrap(), 51, "{s}");
    for row in v["results"].as_array().unwrap() {
        assert_eq!(row["commands"], ticks, "{row}");
        assert_eq!(row["failed"], 0, "{row}");
        assert!(row["position_deg"].as_f64().unwrap().abs() < 2.2, "{row}");
    }
    assert!(
        r.stderr.contains(&format!("{ticks} ticks recorded")),
        "{}",
        r.stderr
    );

    // `robobus plot` (the mcap crate) reads the positions and the targets.
    let svg = dir.path().join("wave.svg");
    let p = robobus(&["plot", mcap.to_str().unwrap(), "-o", svg.to_str().unwrap()]);
    assert_eq!(p.code, Some(0), "{}", p.stderr);
    assert!(
        p.stdout.contains(&format!("{ticks} rows, 12 signals")),
        "{}",
        p.stdout
    );

    read_back_in_python(&mcap, ticks, &v);
}

/// Python's mcap reader: the targets as `JointState` on their own topic, each at the time
/// of the sample that carries the same targets in degrees, the trajectory at that time.
fn read_back_in_python(mcap: &std::path::Path, ticks: u64, report: &Value) {
    // Python's mcap reader: the targets as JointState on their own topic, each at the
    // time of the sample that carries the same targets in degrees.
    let py = robobus_testkit::provision("py/ensure-venv");
    let script = robobus_testkit::workspace_root().join("scripts/py/read_mcap.py");
    let out = std::process::Command::new(&py)
        .arg(&script)
        .arg(mcap)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let m: Value = serde_json::from_slice(&out.stdout).unwrap();
    let commands = &m["channels"]["/robobus/joint_commands"];
    assert_eq!(commands["schema"], "sensor_msgs/msg/JointState");
    assert_eq!(commands["count"], ticks);
    assert_eq!(m["channels"]["/robobus/samples"]["count"], ticks);
    let samples = m["samples"].as_array().unwrap();
    for (c, s) in m["commands"].as_array().unwrap().iter().zip(samples) {
        assert_eq!(c["log_time"], s["log_time"]);
        assert_eq!(c["stamp_ns"], c["log_time"]);
        assert_eq!(c["name"], serde_json::json!(["hip", "knee", "shoulder"]));
        for (i, ch) in s["sample"]["channels"]
            .as_array()
            .unwrap()
            .iter()
            .enumerate()
        {
            let rad = c["position"][i].as_f64().unwrap();
            let deg = ch["target_deg"].as_f64().unwrap();
            assert!((rad - deg.to_radians()).abs() < 1e-9, "{rad} vs {deg}");
        }
    }
    // Every sample's targets are the trajectory at its time (the joints started at their
    // zero: no lead-in), linear between the points.
    assert_eq!(report["summary"]["lead_in_s"], 0.0, "{report:#}");
    for sample in samples {
        let t = sample["sample"]["t_s"].as_f64().unwrap();
        let f = if t <= 0.5 { t / 0.5 } else { (1.0 - t) / 0.5 };
        let targets = sample["sample"]["channels"].as_array().unwrap();
        for (c, peak) in targets.iter().zip([20.0, -20.0, 30.0]) {
            let got = c["target_deg"].as_f64().unwrap();
            // The time is recorded to 0.1 ms.
            assert!(
                (got - peak * f).abs() < 0.01,
                "t = {t}: {got} for {}",
                peak * f
            );
        }
    }
}
