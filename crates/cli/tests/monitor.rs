//! `robobus monitor` without a terminal: plain lines, a CSV recording `robobus plot`
//! reads, an MCAP recording that `robobus plot` and Python's `mcap` reader read back,
//! `--duration`, and bad options. (The ratatui screen itself is tested with
//! ratatui's `TestBackend` in the module's unit tests.)

#![allow(clippy::unwrap_used, clippy::panic)] // Test code.

use crate::common;

#[test]
fn monitor_records_the_simulated_arm_to_csv_and_stops_by_itself() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("arm.csv");
    let started = std::time::Instant::now();
    let r = common::robobus(&[
        "monitor",
        "--sim",
        "--joints",
        "1-3",
        "--rate-hz",
        "40",
        "--duration",
        "2",
        "--record",
        csv.to_str().unwrap(),
    ]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert!(started.elapsed().as_secs_f64() < 20.0);
    // One plain line per second, naming the joints.
    assert!(r.stdout.lines().count() >= 2, "{}", r.stdout);
    assert!(
        r.stdout.contains("j1") && r.stdout.contains("j3"),
        "{}",
        r.stdout
    );
    assert!(r.stderr.contains("samples recorded"), "{}", r.stderr);

    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header = lines.next().unwrap();
    assert_eq!(
        header,
        "t_s,j1_deg,j1_rpm,j1_mA,j2_deg,j2_rpm,j2_mA,j3_deg,j3_rpm,j3_mA"
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert!((40..=90).contains(&rows.len()), "{} rows", rows.len());
    assert!(rows.iter().all(|r| r.len() == 10));
    // The arm moves: joint 1's position changes by degrees over the run.
    let j1: Vec<f64> = rows.iter().filter_map(|r| r[1].parse().ok()).collect();
    let (lo, hi) = j1
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    assert!(hi - lo > 2.0, "joint 1 stayed within {lo}..{hi}");

    // `robobus plot` reads the recording.
    let png = dir.path().join("arm.png");
    let p = common::robobus(&["plot", csv.to_str().unwrap(), "-o", png.to_str().unwrap()]);
    assert_eq!(p.code, Some(0), "{}", p.stderr);
    assert!(p.stdout.contains("9 signals"), "{}", p.stdout);
}

#[test]
fn monitor_records_mcap_that_plot_and_pythons_mcap_reader_read_back() {
    let dir = tempfile::tempdir().unwrap();
    let mcap = dir.path().join("arm.mcap");
    let r = common::robobus(&[
        "--json",
        "monitor",
        "--sim",
        "--joints",
        "1-2",
        "--rate-hz",
        "40",
        "--duration",
        "1.5",
        "--record",
        mcap.to_str().unwrap(),
    ]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    // What --json printed is what the samples channel holds, sample for sample.
    let printed: Vec<serde_json::Value> = r
        .stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert!(printed.len() >= 20, "{} samples", printed.len());

    // `robobus plot` reads it as the CSV form's columns.
    let svg = dir.path().join("arm.svg");
    let p = common::robobus(&["plot", mcap.to_str().unwrap(), "-o", svg.to_str().unwrap()]);
    assert_eq!(p.code, Some(0), "{}", p.stderr);
    assert!(
        p.stdout
            .contains(&format!("{} rows, 6 signals", printed.len())),
        "{}",
        p.stdout
    );

    // Python's mcap reader, with the ROS 2 decoder for the joint states.
    let py = robobus_testkit::provision("py/ensure-venv");
    let script = robobus_testkit::workspace_root().join("scripts/py/read_mcap.py");
    let out = std::process::Command::new(&py)
        .arg(&script)
        .arg(&mcap)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let samples = &v["channels"]["/robobus/samples"];
    assert_eq!(samples["message_encoding"], "json");
    assert_eq!(samples["schema_encoding"], "jsonschema");
    assert_eq!(samples["count"], printed.len());
    let states = &v["channels"]["/joint_states"];
    assert_eq!(states["message_encoding"], "cdr");
    assert_eq!(states["schema"], "sensor_msgs/msg/JointState");
    assert_eq!(states["schema_encoding"], "ros2msg");
    let read: Vec<&serde_json::Value> = v["samples"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| &s["sample"])
        .collect();
    assert_eq!(read, printed.iter().collect::<Vec<_>>());
    // Each joint state: the answering joints of one sample, at that sample's time, in
    // radians.
    let joint_states = v["states"].as_array().unwrap();
    assert!(joint_states.len() + 2 >= printed.len(), "{v}");
    let times: Vec<u64> = v["samples"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["log_time"].as_u64().unwrap())
        .collect();
    for js in joint_states {
        let at = js["log_time"].as_u64().unwrap();
        assert_eq!(js["stamp_ns"].as_u64(), Some(at));
        let k = times.iter().position(|&t| t == at).unwrap();
        let sample = &printed[k];
        let fresh: Vec<&serde_json::Value> = sample["channels"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|c| c["stale"] == false)
            .collect();
        assert_eq!(js["name"].as_array().unwrap().len(), fresh.len());
        // The joints as the bridge names them, each with the torque the bridge would
        // estimate from its current (the simulated WHJ30's torque constant), never NaN.
        assert_eq!(js["effort"].as_array().unwrap().len(), fresh.len(), "{js}");
        for (name, effort) in js["name"]
            .as_array()
            .unwrap()
            .iter()
            .zip(js["effort"].as_array().unwrap())
        {
            assert!(name == "j1" || name == "j2", "{js}");
            assert!(effort.is_f64(), "{js}");
        }
        for (i, c) in fresh.iter().enumerate() {
            assert_eq!(js["name"][i], c["name"]);
            let radians = js["position"][i].as_f64().unwrap();
            let deg = c["position_deg"].as_f64().unwrap();
            assert!(
                (radians - deg.to_radians()).abs() < 1e-9,
                "{radians} vs {deg}"
            );
        }
    }
}

#[test]
fn monitor_refuses_bad_options() {
    let r = common::robobus(&["monitor", "--duration", "1"]);
    assert_eq!(r.code, Some(2));
    assert!(
        r.stderr.contains("--bus") && r.stderr.contains("--sim"),
        "{}",
        r.stderr
    );
    let r = common::robobus(&["monitor", "--sim", "--record", "out.txt"]);
    assert_eq!(r.code, Some(2));
    assert!(
        r.stderr.contains(".csv") && r.stderr.contains(".mcap"),
        "{}",
        r.stderr
    );
    let r = common::robobus(&["monitor", "--sim", "--joints", "0-3"]);
    assert_eq!(r.code, Some(2));
    assert!(r.stderr.contains("1..=30"), "{}", r.stderr);
    let r = common::robobus(&["monitor", "--sim", "--rate-hz", "500"]);
    assert_eq!(r.code, Some(2));
    assert!(r.stderr.contains("1..=200"), "{}", r.stderr);
    let r = common::robobus(&["monitor", "--bus", "udp", "--sim"]);
    assert_eq!(r.code, Some(2));
}

/// A dashboard whose terminal goes away (a killed tmux, a dropped SSH session) ends
/// promptly instead of spinning on end of file until killed (Unix: a pty plays the
/// terminal).
#[cfg(unix)]
#[test]
fn monitor_ends_when_its_terminal_hangs_up() {
    use std::process::{Command, Stdio};
    use std::time::{Duration, Instant};

    use robobus_link::{PtyOptions, PtyPair};

    let pair = PtyPair::open(&PtyOptions::default()).unwrap();
    let tty = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&pair.slave_path)
        .unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(["monitor", "--sim", "--joints", "1-2", "--duration", "60"])
        .stdin(tty.try_clone().unwrap())
        .stdout(tty.try_clone().unwrap())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    drop(tty);
    // Drain what it draws so it never blocks on a full pty, then hang up.
    std::thread::sleep(Duration::from_millis(1500));
    assert!(child.try_wait().unwrap().is_none(), "monitor ended early");
    drop(pair);
    let hung_up = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        if hung_up.elapsed() > Duration::from_secs(10) {
            let _ = child.kill();
            panic!("monitor kept running 10 s after its terminal hung up");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A capture file on a full disk ends the monitor naming the cause ("No space left on
/// device"), exit 1, instead of marking every sample a bad reply. The full disk is a
/// 16 KiB tmpfs in a private mount namespace (`unshare -m`, as root).
#[test]
fn a_capture_on_a_full_disk_ends_the_monitor_naming_the_cause() {
    let sim = common::WckSim::start("0-1", &[]);
    let dir = tempfile::tempdir().unwrap();
    let mnt = dir.path().join("full");
    std::fs::create_dir(&mnt).unwrap();
    let script = format!(
        "mount -t tmpfs -o size=16k robobus-full {mnt} && exec {bin} monitor --port {port} \
         --servos 0-1 --rate-hz 200 --duration 20 --json --capture {mnt}/c.log",
        mnt = mnt.display(),
        bin = env!("CARGO_BIN_EXE_robobus"),
        port = sim.port(),
    );
    let out = std::process::Command::new("unshare")
        .args(["-m", "sh", "-c", &script])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("No space left on device"), "{err}");
    assert!(err.contains("capture"), "{err}");
}
