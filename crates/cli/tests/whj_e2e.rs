//! End-to-end: the built `robobus whj ...` commands against `robobus sim whj` in another
//! process, on the python-can UDP multicast bus, inside a private network namespace.
//!
//! Each test re-executes itself inside a private network namespace (`unshare -n`, with
//! `ROBOBUS_IN_NETNS` set, loopback up and a multicast route there), starts the simulator
//! on its own group and port, and runs the commands, checking their effects through other commands (enable →
//! status shows enabled, move → position reached, write → read back, ...). No datagram
//! can leave the namespace.

#![cfg(target_os = "linux")] // private network namespaces
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::float_cmp,
    clippy::cast_precision_loss,
    clippy::many_single_char_names,
    clippy::similar_names
)] // Test code: a failed unwrap is a failed test.

use crate::common;

use std::io::Read as _;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

const INSIDE: &str = "ROBOBUS_IN_NETNS";

/// Runs the test `name` again inside a private network namespace (loopback up, multicast
/// routed to it); returns `true` when the caller is already inside (and should run the
/// test body).
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

use common::WhjSim as Sim;

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

#[test]
fn whj_e2e_scan_info_enable_move_save_registers() {
    if !in_netns("whj_e2e_scan_info_enable_move_save_registers") {
        return;
    }
    let sim = Sim::start("udp:239.74.163.11:43121", &[]);

    // Scan: the seven joints, nothing at 8.
    let found = sim.json(&["scan", "--joints", "1-8"]);
    let ids: Vec<u64> = found.iter().map(|r| r["id"].as_u64().unwrap()).collect();
    assert_eq!(ids, [1, 2, 3, 4, 5, 6, 7]);
    assert!(found.iter().all(|r| r["model"] == "WHJ30"), "{found:?}");
    // The table form names its columns.
    let t = sim.whj(&["scan", "--joints", "1-2"]);
    assert_eq!(t.code, Some(0), "{}", t.stderr);
    assert!(t.stdout.starts_with("JOINT"), "{}", t.stdout);
    // Two joints, then the summary: how many IDs were probed (no duplicates to name).
    assert_eq!(t.stdout.lines().count(), 4, "{}", t.stdout);
    assert!(t.stdout.ends_with("probed: 2\n"), "{}", t.stdout);

    // Info: identity and limits.
    let info = sim.json(&["info", "1"]);
    assert_eq!(info[0]["model"], "WHJ30");
    assert!(f(&info[0]["max_deg"]) > f(&info[0]["min_deg"]), "{info:?}");

    // Status after disable and after enable (the simulated joints power up enabled).
    let d = sim.json(&["disable", "1-2"]);
    assert!(d.iter().all(|r| r["enabled"] == false), "{d:?}");
    // A silent joint among others: every joint reported, the silent one named, exit 3.
    let r = sim.whj(&["--json", "status", "6-8"]);
    assert_eq!(r.code, Some(3), "{r:?}");
    let doc: Value = serde_json::from_str(&r.stdout).unwrap();
    let rows = doc["results"].as_array().unwrap();
    assert_eq!(rows.len(), 3, "{rows:?}");
    assert_eq!(
        (rows[0]["id"].as_u64(), rows[1]["id"].as_u64()),
        (Some(6), Some(7))
    );
    assert!(
        rows[0]["position_deg"].is_f64() && rows[1]["position_deg"].is_f64(),
        "{rows:?}"
    );
    assert_eq!(rows[2]["id"], 8);
    assert_eq!(rows[2]["kind"], "no-device", "{rows:?}");
    // The same by one broadcast status frame.
    let bst = sim.json(&["status", "1-3", "--broadcast"]);
    assert_eq!(bst.len(), 3, "{bst:?}");
    assert!(bst.iter().all(|r| r["position_deg"].is_f64()), "{bst:?}");
    let st = sim.json(&["status", "1-2"]);
    assert_eq!(st.len(), 2);
    assert_eq!(st[0]["enabled"], false, "{st:?}");
    assert_eq!(st[1]["enabled"], false, "{st:?}");
    let m = sim.json(&["mode", "1", "position"]);
    assert_eq!(m[0]["mode"], "position");
    let en = sim.json(&["enable", "1"]);
    assert_eq!(en[0]["enabled"], true);
    let st = sim.json(&["status", "1"]);
    assert_eq!(st[0]["enabled"], true, "{st:?}");
    assert_eq!(st[0]["mode"], "position");

    // Move 12° in safe steps; the position is reached.
    let mv = sim.json(&["move", "1", "12", "--max-speed", "60"]);
    assert!((f(&mv[0]["position_deg"]) - 12.0).abs() <= 0.1, "{mv:?}");
    assert!(f(&mv[0]["frames"]) > 20.0, "{mv:?}");
    let st = sim.json(&["status", "1"]);
    assert!((f(&st[0]["position_deg"]) - 12.0).abs() <= 0.2, "{st:?}");
    // And back, negative.
    let mv = sim.json(&["move", "1", "-5", "--max-speed", "90"]);
    assert!((f(&mv[0]["position_deg"]) + 5.0).abs() <= 0.1, "{mv:?}");

    // Save refused while enabled (exit 2, nothing written), allowed once disabled.
    let r = sim.whj(&["--yes", "save", "1"]);
    assert_eq!(r.code, Some(2), "{r:?}");
    assert!(r.stderr.contains("enabled"), "{}", r.stderr);
    // Without --yes and without a terminal: refused before anything is opened.
    let r = sim.whj(&["save", "2"]);
    assert_eq!(r.code, Some(2), "{r:?}");
    assert!(r.stderr.contains("--yes"), "{}", r.stderr);
    let d = sim.json(&["disable", "1"]);
    assert_eq!(d[0]["enabled"], false);
    let s = sim.json(&["--yes", "save", "1"]);
    assert_eq!(s[0]["saved"], true);

    // Registers: write in units, read back by name and by address.
    let w = sim.json(&["write", "2", "LIT_MAX_CURRENT", "5000"]);
    assert_eq!(f(&w[0]["value"]), 5000.0, "{w:?}");
    let r = sim.json(&["read", "2", "0x40"]);
    assert_eq!(f(&r[0]["raw"]), 5000.0, "{r:?}");
    assert_eq!(r[0]["unit"], "mA");
    let w = sim.json(&["write", "2", "LIT_MAX_POS_DIFF", "20"]);
    assert!((f(&w[0]["value"]) - 20.0).abs() < 1e-6, "{w:?}");
    let r = sim.json(&["read", "2", "lit_max_pos_diff"]);
    assert_eq!(f(&r[0]["raw"]), 200_000.0, "{r:?}");
    // (0x39 SPEED_FF_FOLLOWING: a plain register; 0x31, the open-loop duty, is refused.)
    let w = sim.json(&["write", "2", "0x39", "7", "--raw"]);
    assert_eq!(f(&w[0]["raw"]), 7.0, "{w:?}");
    let words = sim.json(&["read", "2", "0x38", "2"]);
    assert_eq!(words.len(), 2, "{words:?}");
    assert_eq!(f(&words[1]["raw"]), 7.0, "{words:?}");
    // Temperature in its unit.
    let t = sim.json(&["read", "2", "SYS_TEMP"]);
    assert_eq!(t[0]["unit"], "°C", "{t:?}");
    assert!((0.0..100.0).contains(&f(&t[0]["value"])), "{t:?}");

    // Zero: the present position becomes 0.
    let z = sim.json(&["zero", "1"]);
    assert!(f(&z[0]["position_deg"]).abs() < 0.05, "{z:?}");
    // Clear, release-iap on a running joint, set-id.
    let c = sim.json(&["clear", "1-2"]);
    assert_eq!(c.len(), 2);
    let rel = sim.json(&["release-iap", "3"]);
    assert_eq!(rel[0]["released"], true);
    let sid = sim.json(&["--yes", "set-id", "7", "9"]);
    assert_eq!(sid[0]["new_id"], 9);
}

/// `sim whj` prints its "serving" line only once its serving loop takes frames: a client
/// that sends the moment the line appears (here the IAP release each joint waits for after
/// power-up) is answered, 20 simulator starts in a row. A frame sent before the loop
/// listens is lost for good, so the window is generous (1 s) for a machine that stalls.
#[test]
fn whj_e2e_the_first_frame_after_the_serving_line_is_answered_20_times() {
    use robobus_link::{FrameLink as _, UdpBus, UdpBusConfig};
    use robobus_whj::registers::addr;
    use robobus_whj::{JointId, Reply, Request};

    if !in_netns("whj_e2e_the_first_frame_after_the_serving_line_is_answered_20_times") {
        return;
    }
    let config = UdpBusConfig {
        group: "239.74.163.12".parse().unwrap(),
        port: 43122,
        ..UdpBusConfig::default()
    };
    let release = Request::write(JointId::new(1).unwrap(), addr::IAP_FLAG, 0)
        .unwrap()
        .to_frame();
    for run in 0..20 {
        // Our socket first, so that only the simulator's readiness is under test.
        let mut link = UdpBus::open(&config).unwrap();
        let sim = Sim::start("udp:239.74.163.12:43122", &[]);
        link.send(&release).unwrap();
        let deadline = Instant::now() + Duration::from_secs(1);
        let reply = loop {
            let rx = link
                .recv(deadline)
                .unwrap_or_else(|e| panic!("run {run}: no reply to the first frame: {e}"));
            if let Ok(r) = Reply::from_frame(&rx.frame) {
                break r;
            }
        };
        assert!(
            matches!(reply, Reply::WriteAck { joint, addr: a, .. } if joint.get() == 1 && a == addr::IAP_FLAG),
            "run {run}: {reply:?}"
        );
        drop(sim);
    }
}

#[test]
fn whj_e2e_wave_speed_current_and_interrupt() {
    if !in_netns("whj_e2e_wave_speed_current_and_interrupt") {
        return;
    }
    let sim = Sim::start("udp:239.74.163.12:43122", &[]);

    // A wave needs the joint enabled in the matching mode: refused otherwise, nothing sent.
    sim.json(&["disable", "3"]);
    let r = sim.whj(&["wave", "3", "--amplitude", "5", "--duration", "0.5"]);
    assert_eq!(r.code, Some(2), "{r:?}");
    assert!(r.stderr.contains("enable"), "{}", r.stderr);

    sim.json(&["mode", "3", "position"]);
    sim.json(&["enable", "3"]);
    let out = sim.whj(&[
        "--json",
        "wave",
        "3",
        "--amplitude",
        "5",
        "--frequency",
        "1",
        "--duration",
        "1.5",
        "--rate-hz",
        "200",
    ]);
    assert_eq!(out.code, Some(0), "{}", out.stderr);
    let doc: Value = serde_json::from_str(&out.stdout).unwrap();
    let stats = &doc["summary"];
    let cycles = f(&stats["cycles"]);
    assert!((250.0..=320.0).contains(&cycles), "{stats}");
    // Tracking against the requested target, in the wave's unit.
    assert_eq!(stats["unit"], "deg", "{stats}");
    assert!(f(&stats["tracking_rms"]) < 1.0, "{stats}");
    assert!(f(&stats["tracking_max"]) < 3.0, "{stats}");
    assert!(
        stats["clamped"].is_u64() && stats["overruns"].is_u64(),
        "{stats}"
    );
    // Complete cycles are counted (the rate is the benchmark's business: a loaded
    // machine running a debug build misses some).
    assert!(f(&stats["complete"]) > 0.0, "{stats}");
    // The round trip of the answered frames, send to feedback, in µs.
    let rt = ["p50", "p99", "max"].map(|p| f(&stats[format!("round_trip_{p}_us")]));
    assert!(rt[0] > 0.0 && rt.is_sorted_by(|a, b| a <= b), "{stats}");

    // Square wave, plain text with a summary.
    let out = sim.whj(&[
        "wave",
        "3",
        "--shape",
        "square",
        "--amplitude",
        "2",
        "--duration",
        "0.5",
    ]);
    assert_eq!(out.code, Some(0), "{}", out.stderr);
    assert!(out.stdout.contains("deadline_misses"), "{}", out.stdout);

    // Ctrl-C (SIGINT) during a long wave: exit 130, joint disabled with --on-stop disable.
    let mut child = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args([
            "whj",
            "--bus",
            &sim.bus,
            "--on-stop",
            "disable",
            "wave",
            "3",
        ])
        .args(["--amplitude", "3", "--duration", "30"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(1500));
    let pid = child.id().to_string();
    assert!(
        Command::new("kill")
            .args(["-INT", &pid])
            .status()
            .unwrap()
            .success()
    );
    let status = child.wait().unwrap();
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    assert_eq!(status.code(), Some(130), "{err}");
    assert!(err.contains("disabled"), "{err}");
    let st = sim.json(&["status", "3"]);
    assert_eq!(st[0]["enabled"], false, "{st:?}");

    // Speed servo frame in speed mode: the feedback comes back.
    sim.json(&["mode", "4", "speed"]);
    sim.json(&["enable", "4"]);
    let sp = sim.json(&["speed", "4", "2.5"]);
    assert_eq!(sp[0]["enabled"], true, "{sp:?}");
    std::thread::sleep(Duration::from_millis(300));
    let sp = sim.json(&["speed", "4", "0"]);
    assert!(f(&sp[0]["speed_rpm"]) > 0.5, "the joint turned: {sp:?}");
    // Current servo frame.
    sim.json(&["mode", "5", "current"]);
    sim.json(&["enable", "5"]);
    let cu = sim.json(&["current", "5", "200"]);
    assert_eq!(cu[0]["id"], 5, "{cu:?}");
    sim.json(&["disable", "4-5"]);
}

#[test]
fn whj_e2e_timeouts_and_bad_input() {
    if !in_netns("whj_e2e_timeouts_and_bad_input") {
        return;
    }
    let sim = Sim::start("udp:239.74.163.13:43123", &[]);

    // A joint that is not on the bus: exit 3, the message names it.
    let r = sim.whj(&["status", "12"]);
    assert_eq!(r.code, Some(3), "{r:?}");
    assert!(r.stderr.contains("12"), "{}", r.stderr);
    let r = sim.whj(&["scan", "--joints", "20-22"]);
    assert_eq!(r.code, Some(3), "{r:?}");
    assert!(r.stderr.contains("no joint answered"), "{}", r.stderr);

    // Bad input: exit 2, the value and the allowed range named, nothing sent.
    for (args, needle) in [
        (vec!["move", "1", "400"], "-360..=360"),
        (vec!["speed", "1", "99"], "-37.5..=37.5"),
        (vec!["status", "31"], "31"),
        (vec!["read", "1", "NOPE"], "NOPE"),
        (vec!["write", "1", "LOW_POWER_MODE", "2"], "0..=1"),
        // A drive switch is refused with a pointer to the command that verifies it.
        (vec!["write", "1", "SYS_ENABLE_DRIVER", "1"], "whj enable"),
        // A confirm-class register says what it does and needs --yes.
        (vec!["write", "1", "IAP_FLAG", "1"], "bootloader"),
        (
            vec!["wave", "1", "--amplitude", "5", "--frequency", "90"],
            "--frequency",
        ),
    ] {
        let r = sim.whj(&args);
        assert_eq!(r.code, Some(2), "{args:?}: {r:?}");
        assert!(r.stderr.contains(needle), "{args:?}: {}", r.stderr);
    }
    let r = common::robobus(&["whj", "--bus", "udp:1.2.3.4:5", "status", "1"]);
    assert_eq!(r.code, Some(2), "{r:?}");
    assert!(r.stderr.contains("multicast"), "{}", r.stderr);
    // The joints are still fine after all that.
    let st = sim.json(&["status", "1"]);
    assert_eq!(st[0]["error"], "no error", "{st:?}");
}

#[test]
fn whj_e2e_doctor_probes_the_joints() {
    if !in_netns("whj_e2e_doctor_probes_the_joints") {
        return;
    }
    let sim = Sim::start("udp:239.74.163.14:43124", &[]);
    let doctor = || {
        let r = common::robobus(&[
            "doctor",
            "--json",
            "--whj-bus",
            sim.bus.as_str(),
            "--joints",
            "1,2,9",
        ]);
        let v: Value =
            serde_json::from_str(&r.stdout).unwrap_or_else(|e| panic!("not JSON ({e}): {r:?}"));
        (r.code, v)
    };
    let status = |v: &Value, subject: &str, check: &str| -> String {
        v["findings"]
            .as_array()
            .unwrap()
            .iter()
            .find(|f| f["subject"] == subject && f["check"] == check)
            .unwrap_or_else(|| panic!("no {check} finding for {subject}: {v:#}"))["status"]
            .as_str()
            .unwrap()
            .to_owned()
    };
    let bus = &sim.bus;
    // As shipped, the joints wait in their bootloader: released (a warning); J9 is absent.
    let (code, v) = doctor();
    assert_eq!(code, Some(5), "{v:#}");
    assert_eq!(status(&v, &format!("J1 on {bus}"), "iap"), "warn", "{v:#}");
    assert_eq!(status(&v, &format!("J2 on {bus}"), "iap"), "warn", "{v:#}");
    assert_eq!(status(&v, &format!("J9 on {bus}"), "iap"), "fail", "{v:#}");
    assert_eq!(status(&v, &format!("J1 on {bus}"), "duplicate-id"), "ok");
    assert_eq!(status(&v, &format!("J1 on {bus}"), "firmware"), "ok");
    // Now running: fine.
    let (_, v) = doctor();
    assert_eq!(status(&v, &format!("J1 on {bus}"), "iap"), "ok", "{v:#}");
}

/// `robobus monitor --robot FILE` on a robot of two buses (a WHJ arm on the UDP bus and a
/// wCK leg on a `robobus sim wck` pty): every joint by name, in the file's order, as joint
/// angles (offset and direction applied); the arm stays enabled afterwards (the monitor
/// only reads: no safe stop).
#[test]
fn whj_e2e_monitor_reads_a_robot_file() {
    if !in_netns("whj_e2e_monitor_reads_a_robot_file") {
        return;
    }
    let sim = Sim::start("udp:239.74.163.15:43125", &[]);
    sim.json(&["enable", "2"]);
    let mv = sim.json(&["move", "2", "12", "--max-speed", "60"]);
    assert!((f(&mv[0]["position_deg"]) - 12.0).abs() <= 0.1, "{mv:?}");

    let wck = common::WckSim::start("4", &[]);
    let dir = tempfile::tempdir().unwrap();
    let robot = dir.path().join("robot.toml");
    std::fs::write(
        &robot,
        format!(
            r#"
[buses.arm]
kind = "whj-udp"
group = "239.74.163.15"
port = 43125

[buses.leg]
kind = "wck"
port = "{}"

[[joints]]
name = "hip"
bus = "leg"
id = 4
offset = 0.1
limits = [-1.0, 1.0]
max_velocity = 1.0
max_acceleration = 1.0

[[joints]]
name = "elbow"
bus = "arm"
id = 2
direction = -1
offset = 0.05
limits = [-1.0, 1.0]
max_velocity = 1.0
max_acceleration = 1.0
"#,
            wck.port()
        ),
    )
    .unwrap();
    let r = common::robobus(&[
        "--json",
        "monitor",
        "--robot",
        robot.to_str().unwrap(),
        "--rate-hz",
        "10",
        "--duration",
        "1",
        "--reply-margin",
        "300",
    ]);
    drop(wck);
    assert_eq!(r.code, Some(0), "{r:#?}");
    let samples = common::json_lines(&r.stdout);
    assert!(samples.len() >= 3, "{}", r.stdout);
    let last = &samples.last().unwrap()["channels"];
    assert_eq!(last[0]["name"], "hip");
    assert_eq!(last[1]["name"], "elbow");
    // The wCK servo rests at step 127 (device angle 0): joint = 0 - 0.1 rad.
    assert!(
        (f(&last[0]["position_deg"]) + 0.1f64.to_degrees()).abs() < 0.6,
        "{last}"
    );
    assert!(last[0]["load"].is_number(), "{last}");
    // The joint at 12°, mirrored about 0.05 rad: -(12° - 2.865°).
    assert!(
        (f(&last[1]["position_deg"]) + (12.0 - 0.05f64.to_degrees())).abs() < 0.2,
        "{last}"
    );
    assert_eq!(last[1]["enabled"], true, "{last}");
    assert!(last[1]["current_ma"].is_number(), "{last}");
    // Read only: the arm is still enabled after the monitor ended.
    let st = sim.json(&["status", "2"]);
    assert_eq!(st[0]["enabled"], true, "{st:?}");
}

/// Motion commands are checked against the connected joint's own bounds before any servo
/// frame: its model's peak speed (WHJ60: 30 RPM), its position limits, its current limit.
#[test]
fn whj_e2e_motion_is_checked_against_the_joints_own_bounds() {
    if !in_netns("whj_e2e_motion_is_checked_against_the_joints_own_bounds") {
        return;
    }
    let sim = Sim::start_model("udp:239.74.163.16:43126", "whj60", &[]);
    let refused = |args: &[&str], needles: &[&str]| {
        let r = sim.whj(args);
        assert_eq!(r.code, Some(2), "{args:?}: {r:?}");
        for n in needles {
            assert!(r.stderr.contains(n), "{args:?}: {n} not in {}", r.stderr);
        }
    };

    // Speed: 35 RPM passes the CLI's bound (37.5) but not a WHJ60's peak (30).
    sim.json(&["mode", "2", "speed"]);
    sim.json(&["enable", "2"]);
    refused(&["speed", "2", "35"], &["35 RPM", "-30..=30", "WHJ60"]);
    refused(
        &[
            "wave",
            "2",
            "--mode",
            "speed",
            "--amplitude",
            "20",
            "--offset",
            "15",
        ],
        &["35 RPM", "WHJ60"],
    );
    // Nothing was sent: at 35 RPM (210°/s) the shaft would have turned by now.
    std::thread::sleep(Duration::from_millis(200));
    let st = sim.json(&["status", "2"]);
    assert!(
        f(&st[0]["position_deg"]).abs() < 0.5,
        "nothing sent: {st:?}"
    );
    let sp = sim.json(&["speed", "2", "20"]);
    assert_eq!(sp[0]["id"], 2, "{sp:?}");
    sim.json(&["speed", "2", "0"]);
    sim.json(&["disable", "2"]);

    // Position: the joint's upper limit, lowered to 20°.
    sim.json(&["write", "3", "LIT_MAX_POSITION", "20"]);
    sim.json(&["mode", "3", "position"]);
    sim.json(&["enable", "3"]);
    refused(&["move", "3", "30"], &["30 deg", "..=20 deg", "0x44"]);
    refused(
        &["wave", "3", "--amplitude", "15", "--offset", "10"],
        &["25 deg", "..=20 deg"],
    );
    let st = sim.json(&["status", "3"]);
    assert!(
        f(&st[0]["position_deg"]).abs() < 0.1,
        "did not move: {st:?}"
    );
    let mv = sim.json(&["move", "3", "15", "--max-speed", "60"]);
    assert!((f(&mv[0]["position_deg"]) - 15.0).abs() <= 0.1, "{mv:?}");
    sim.json(&["disable", "3"]);

    // Current: the joint's limit register, set to 1000 mA.
    sim.json(&["write", "4", "LIT_MAX_CURRENT", "1000"]);
    sim.json(&["mode", "4", "current"]);
    sim.json(&["enable", "4"]);
    refused(
        &["current", "4", "-1500"],
        &["1500 mA", "-1000..=1000", "LIT_MAX_CURRENT"],
    );
    let cu = sim.json(&["current", "4", "400"]);
    assert_eq!(cu[0]["id"], 4, "{cu:?}");
    sim.json(&["current", "4", "0"]);
    sim.json(&["disable", "4"]);
}

#[test]
fn whj_e2e_capture_on_both_sides_replays_with_meanings() {
    if !in_netns("whj_e2e_capture_on_both_sides_replays_with_meanings") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let sim_log = dir.path().join("sim.log");
    let host_log = dir.path().join("host.log");
    let sim = Sim::start(
        "udp:239.74.163.14:43124",
        &["--capture", sim_log.to_str().unwrap()],
    );
    let r = sim.whj(&["--capture", host_log.to_str().unwrap(), "status", "3"]);
    assert_eq!(r.code, Some(0), "{r:?}");
    drop(sim);
    for (log, what) in [(&host_log, "host"), (&sim_log, "simulator")] {
        let r = common::robobus(&["replay", log.to_str().unwrap()]);
        assert_eq!(r.code, Some(0), "{what}: {r:?}");
        // candump lines under the UDP bus's name; the IAP release and the status read of
        // joint 3, and the joint's answers, decoded by register name.
        assert!(
            r.stdout.contains("> 003 02 49 00  J3 write IAP_FLAG 0"),
            "{what}: {}",
            r.stdout
        );
        assert!(r.stdout.contains("< 103 "), "{what}: {}", r.stdout);
        assert!(r.stdout.contains(" 0 malformed"), "{what}: {}", r.stdout);
        let text = std::fs::read_to_string(log).unwrap();
        assert!(
            text.lines()
                .all(|l| l.starts_with('(') && l.contains(") udp ")),
            "{what}: {text}"
        );
    }
}

/// A CAN FD frame in cansend syntax without its flags nibble (a candump log adds the FD
/// flag to it): `00F##<data>`.
fn id_and_data(frame: &str) -> String {
    match frame.split_once("##") {
        Some((id, rest)) => format!("{id}##{}", rest.get(1..).unwrap_or("")),
        None => frame.to_owned(),
    }
}

/// The 0x0F frames (only the host sends them) of a candump log.
fn register_broadcasts(log: &std::path::Path) -> Vec<String> {
    std::fs::read_to_string(log)
        .unwrap()
        .lines()
        .filter_map(|l| l.split_whitespace().nth(2))
        .filter(|f| f.starts_with("00F##"))
        .map(id_and_data)
        .collect()
}

/// The frames of a dry run's text, in cansend syntax.
fn dry_frames(args: &[&str]) -> Vec<String> {
    let mut all = vec!["whj", "--dry-run"];
    all.extend_from_slice(args);
    let r = common::robobus(&all);
    assert_eq!(r.code, Some(0), "{r:?}");
    r.stdout
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(id_and_data)
        .collect()
}

#[test]
fn whj_e2e_broadcast_registers_with_the_end_board() {
    if !in_netns("whj_e2e_broadcast_registers_with_the_end_board") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let sim = Sim::start(
        "udp:239.74.163.17:43127",
        &["--end-board", "--fault-silent", "3@0"],
    );
    // One 0x0F frame reads SYS_TEMP on joints 1..4 and the end board's version; joint 3
    // is silent: every slot is reported, joint 3 as no-device, exit code 3.
    let read = [
        "read",
        "--broadcast",
        "1-4",
        "SYS_TEMP",
        "--end-board",
        "EB_SW_VERSION",
    ];
    let log = dir.path().join("read.log");
    let mut args = vec!["--json", "--capture", log.to_str().unwrap()];
    args.extend_from_slice(&read);
    let r = sim.whj(&args);
    assert_eq!(r.code, Some(3), "{r:?}");
    let doc: Value = serde_json::from_str(&r.stdout).unwrap();
    let rows = doc["results"].as_array().unwrap();
    assert_eq!(rows.len(), 5, "{rows:?}");
    for k in [0, 1, 3] {
        assert_eq!(rows[k]["unit"], "°C", "{rows:?}");
        assert!((0.0..100.0).contains(&f(&rows[k]["value"])), "{rows:?}");
    }
    assert_eq!(
        (rows[2]["id"].as_u64(), &rows[2]["kind"]),
        (Some(3), &Value::from("no-device"))
    );
    assert_eq!(rows[4]["id"], "end-board");
    assert_eq!(
        (f(&rows[4]["raw"]), &rows[4]["register"]),
        (515.0, &Value::from("EB_SW_VERSION"))
    );
    // The real run sent exactly the dry run's frame.
    assert_eq!(register_broadcasts(&log), dry_frames(&read));

    // A broadcast write: refused without --yes when the end board is written (nothing is
    // opened), then confirmed: written and read back in a second frame.
    let write = [
        "write",
        "--broadcast",
        "1-2",
        "TAG_WORK_MODE",
        "3",
        "--end-board",
        "EB_IO1_MODE=1",
    ];
    let r = sim.whj(&write);
    assert_eq!(r.code, Some(2), "{r:?}");
    assert!(r.stderr.contains("--yes"), "{}", r.stderr);
    let log = dir.path().join("write.log");
    let mut args = vec!["--yes", "--capture", log.to_str().unwrap()];
    args.extend_from_slice(&write);
    let w = sim.json(&args);
    assert_eq!(w.len(), 3, "{w:?}");
    assert!(
        w[..2]
            .iter()
            .all(|r| r["raw"] == 3 && r["register"] == "TAG_WORK_MODE"),
        "{w:?}"
    );
    assert_eq!(
        (w[2]["id"].as_str(), f(&w[2]["raw"])),
        (Some("end-board"), 1.0)
    );
    assert_eq!(register_broadcasts(&log), dry_frames(&write));
    // The end board answers a status query in the same frame as the joints: IO1 is now an
    // output.
    let st = sim.json(&["status", "--broadcast", "1-2", "--end-board"]);
    assert_eq!(st.len(), 3, "{st:?}");
    assert_eq!(
        (&st[2]["id"], &st[2]["io1_output"]),
        (&Value::from("end-board"), &Value::from(true))
    );
    assert_eq!(st[2]["io2_output"], false, "{st:?}");
    // A dangerous register is refused before anything is sent, broadcast or not.
    let r = sim.whj(&["write", "--broadcast", "1-2", "SYS_DEMA_ABSPOS", "1"]);
    assert_eq!(r.code, Some(2), "{r:?}");
}

#[test]
fn whj_e2e_broadcast_wave_and_monitor() {
    if !in_netns("whj_e2e_broadcast_wave_and_monitor") {
        return;
    }
    let sim = Sim::start("udp:239.74.163.18:43128", &["--fault-silent", "3@0"]);
    // A wave as broadcast position frames, and the monitor sampling by 0x7F.
    let wv = sim.json(&[
        "wave",
        "1",
        "--broadcast",
        "--amplitude",
        "1",
        "--duration",
        "0.3",
    ]);
    assert_eq!(f(&wv[0]["cycles"]), 60.0, "{wv:?}");
    assert_eq!(wv[0]["stale"], false, "{wv:?}");
    let r = common::robobus(&[
        "--json",
        "monitor",
        "--bus",
        "udp:239.74.163.18:43128",
        "--broadcast",
        "--joints",
        "1-3",
        "--rate-hz",
        "10",
        "--duration",
        "1",
    ]);
    // Joint 3 stays silent: exit 3, its values null and stale, the others fresh.
    assert_eq!(r.code, Some(3), "{r:?}");
    let last: Value = serde_json::from_str(r.stdout.lines().last().unwrap()).unwrap();
    let ch = last["channels"].as_array().unwrap();
    assert!(
        ch[0]["position_deg"].is_f64() && ch[1]["position_deg"].is_f64(),
        "{ch:?}"
    );
    assert_eq!(
        (ch[2]["stale"].as_bool(), ch[2]["position_deg"].is_null()),
        (Some(true), true)
    );
    let r = common::robobus(&["monitor", "--bus", "udp", "--broadcast", "--joints", "8"]);
    assert_eq!(r.code, Some(2), "{r:?}");
    assert!(r.stderr.contains("1..=7"), "{}", r.stderr);
}

/// `robobus run` with a request gives the report the subcommand gives with the same
/// arguments, on the same simulated bus (rows keyed `id` there, `joint` in the CLI).
#[test]
fn whj_e2e_run_reports_what_the_subcommands_report() {
    if !in_netns("whj_e2e_run_reports_what_the_subcommands_report") {
        return;
    }
    let bus = "udp:239.74.163.19:43129";
    // Without current noise: two reads of a joint at rest give the same values.
    let sim = Sim::start(bus, &["--current-noise-ma", "0"]);
    let dir = tempfile::tempdir().unwrap();
    for (args, request) in [
        (&["info", "2"][..], r#"{"op": "whj.info", "joint": 2}"#),
        (
            &["status", "1-3"][..],
            r#"{"op": "whj.status", "joints": "1-3"}"#,
        ),
        (
            &["read", "2", "SYS_ID"][..],
            r#"{"op": "whj.read", "joints": "2", "register": "SYS_ID"}"#,
        ),
        (
            &["status", "--broadcast", "1-7"][..],
            r#"{"op": "whj.status", "joints": "1-7", "broadcast": true}"#,
        ),
    ] {
        // The subcommand's --json is the request's report.
        let want: Vec<Value> = sim.json(args);
        let file = dir.path().join("request.json");
        std::fs::write(&file, request).unwrap();
        let r = common::robobus(&["run", "--whj-bus", bus, file.to_str().unwrap()]);
        assert_eq!(r.code, Some(0), "{request}: {}", r.stderr);
        let report: Value = serde_json::from_str(&r.stdout).unwrap();
        assert_eq!(report["bus"], bus, "{report}");
        assert_eq!(report["results"].as_array().unwrap(), &want, "{request}");
    }
}

#[test]
fn whj_e2e_backup_diff_and_restore_settings() {
    if !in_netns("whj_e2e_backup_diff_and_restore_settings") {
        return;
    }
    let sim = Sim::start("udp:239.74.163.19:43129", &[]);
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("j1.json");
    let file_s = file.to_str().unwrap();
    for j in ["1", "2"] {
        sim.json(&["disable", j]);
    }
    sim.json(&["write", "1", "SEV_POSITION_P", "4321", "--raw"]);
    // The backup file: the documented format, joint 1's values.
    let r = sim.whj(&["backup", "1", "-o", file_s]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
    assert_eq!(doc["format"], "robobus-whj-settings");
    assert_eq!(
        (doc["joint"].as_u64(), doc["model"].as_str()),
        (Some(1), Some("WHJ30"))
    );
    let p = doc["settings"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["register"] == "SEV_POSITION_P")
        .unwrap();
    assert_eq!(p["raw"], 4321);
    // Joint 2 differs in its ID and the gain, from the file and from joint 1.
    for args in [
        &["diff", "2", file_s][..],
        &["diff", "2", "--with", "1"][..],
    ] {
        let rows = sim.json(args);
        let regs: Vec<&str> = rows
            .iter()
            .map(|r| r["register"].as_str().unwrap())
            .collect();
        assert_eq!(regs, ["SYS_ID", "SEV_POSITION_P"], "{args:?}");
    }
    // The dry run opens nothing and says what the run does.
    let r = sim.whj(&["--dry-run", "restore", "2", file_s]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert!(r.stdout.contains("never SYS_ID"), "{}", r.stdout);
    // Without --yes (no terminal to ask): refused, nothing written.
    let r = sim.whj(&["restore", "2", file_s]);
    assert_eq!(r.code, Some(2), "{}", r.stderr);
    assert_eq!(sim.json(&["diff", "2", file_s]).len(), 2);
    // With --yes: the gain is written and saved; the ID stays.
    let rows = sim.json(&["--yes", "restore", "2", file_s]);
    let gain = rows
        .iter()
        .find(|r| r["register"] == "SEV_POSITION_P")
        .unwrap();
    assert_eq!(gain["action"], "written", "{rows:?}");
    let id = rows.iter().find(|r| r["register"] == "SYS_ID").unwrap();
    assert!(
        id["action"].as_str().unwrap().starts_with("skipped"),
        "{rows:?}"
    );
    let left = sim.json(&["diff", "2", file_s]);
    assert_eq!(left.len(), 1);
    assert_eq!(left[0]["register"], "SYS_ID");
    // An enabled joint is refused.
    sim.json(&["enable", "2"]);
    let r = sim.whj(&["--yes", "restore", "2", file_s]);
    assert_ne!(r.code, Some(0));
    assert!(r.stderr.contains("disable it"), "{}", r.stderr);
}

/// `robobus robot teach` on a WHJ joint of the simulator in its own process, moved by the
/// simulator's `--hand` (it follows only while teach holds it limp in current mode):
/// the trajectory has the hand's sweep, and the joint is left holding, in position mode.
#[test]
fn whj_e2e_teach_by_hand_then_hold() {
    if !in_netns("whj_e2e_teach_by_hand_then_hold") {
        return;
    }
    let sim = Sim::start("udp:239.74.163.16:43126", &["--hand", "3:-15:15:2"]);
    let dir = tempfile::tempdir().unwrap();
    let robot = dir.path().join("robot.toml");
    std::fs::write(
        &robot,
        r#"
[buses.arm]
kind = "whj-udp"
group = "239.74.163.16"
port = 43126

[[joints]]
name = "wrist"
bus = "arm"
id = 3
limits = [-1.0, 1.0]
max_velocity = 1.0
max_acceleration = 1.0
"#,
    )
    .unwrap();
    let out = dir.path().join("taught.csv");
    let r = common::robobus(&[
        "--json",
        "--yes",
        "robot",
        "teach",
        "--robot",
        robot.to_str().unwrap(),
        "--seconds",
        "2",
        "--rate-hz",
        "20",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    let v: serde_json::Value = serde_json::from_str(&r.stdout).unwrap();
    let wrist = &v["results"][0];
    // The hand swept -15..15° over the 2 s; the joint followed within its grip.
    assert!(
        f(&wrist["max_deg"]) > 8.0 && f(&wrist["min_deg"]) < -8.0,
        "{wrist}"
    );
    assert_eq!(wrist["ended"], "holding", "{wrist}");
    let text = std::fs::read_to_string(&out).unwrap();
    assert!(text.contains("time_s,wrist\n"), "{text}");
    // Held, as the robot file's `safe_state` (the default, hold) says: enabled in
    // position mode, its brake released, after the command has ended: the hand no
    // longer moves it.
    let st = sim.json(&["status", "3"]);
    assert_eq!(
        (
            st[0]["mode"].as_str(),
            st[0]["brake"].as_str(),
            st[0]["enabled"].as_bool()
        ),
        (Some("position"), Some("released"), Some(true)),
        "{st:?}"
    );
    let a = f(&sim.json(&["status", "3"])[0]["position_deg"]);
    std::thread::sleep(Duration::from_millis(500));
    let b = f(&sim.json(&["status", "3"])[0]["position_deg"]);
    assert!((a - b).abs() < 1.0, "{a} then {b}");
}

/// `robobus whj set-rates` on the simulator in its own process, whose bit rates are real:
/// after its power cycle (the simulator's `--fault-power-cycle`) joint 1 is at the new
/// rates and silent on the 1 / 5 Mbit/s bus, while joint 2 still answers.
#[test]
fn whj_e2e_set_rates_then_the_joint_is_silent_at_the_old_rates() {
    if !in_netns("whj_e2e_set_rates_then_the_joint_is_silent_at_the_old_rates") {
        return;
    }
    let sim = Sim::start("udp:239.74.163.17:43127", &["--fault-power-cycle", "1@4"]);
    let _ = sim.json(&["disable", "1"]);
    // Without --yes (and no terminal) nothing is written.
    let r = sim.whj(&[
        "set-rates",
        "1",
        "--bitrate",
        "500000",
        "--dbitrate",
        "2000000",
    ]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    // A pair a joint cannot be set to is bad input.
    let r = sim.whj(&[
        "--yes",
        "set-rates",
        "1",
        "--bitrate",
        "500000",
        "--dbitrate",
        "3000000",
    ]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("--dbitrate"), "{}", r.stderr);
    let r = sim.whj(&[
        "--json",
        "--yes",
        "set-rates",
        "1",
        "--bitrate",
        "500000",
        "--dbitrate",
        "2000000",
    ]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    let doc: Value = serde_json::from_str(&r.stdout).unwrap();
    assert_eq!(
        doc["results"][0]["after"],
        serde_json::json!([500_000, 2_000_000])
    );
    assert!(
        doc["summary"]["next"]
            .as_str()
            .unwrap()
            .contains("robobus sim whj --bitrate 500000 --dbitrate 2000000"),
        "{doc}"
    );
    // Still at the old rates until the power cycle (4 s after the simulator started).
    assert_eq!(sim.json(&["status", "1"])[0]["id"], 1);
    std::thread::sleep(Duration::from_millis(4500));
    let r = sim.whj(&["status", "1"]);
    assert_eq!(r.code, Some(3), "{r:#?}");
    assert_eq!(sim.json(&["status", "2"])[0]["id"], 2);
}

/// A refused `robobus whj set-rates` (an enabled joint) says why and no next steps
/// (power-cycle, `ip link`, scan), in text and in `--json`: nothing changed; when only some
/// joints saved the new rates, the next steps name them.
#[test]
fn whj_e2e_a_refused_set_rates_prints_no_next_steps() {
    if !in_netns("whj_e2e_a_refused_set_rates_prints_no_next_steps") {
        return;
    }
    let sim = Sim::start("udp:239.74.163.20:43130", &[]);
    let _ = sim.json(&["enable", "1"]);
    let _ = sim.json(&["disable", "2"]);
    let rates = ["--bitrate", "500000", "--dbitrate", "2000000"];
    let set = |json: bool, joints: &str| {
        let mut args = if json { vec!["--json"] } else { vec![] };
        args.extend(["--yes", "set-rates", joints]);
        args.extend(rates);
        sim.whj(&args)
    };
    let r = set(false, "1");
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("joint 1: enabled"), "{}", r.stderr);
    for said in [&r.stdout, &r.stderr] {
        for step in ["next", "power-cycle", "ip link", "scan"] {
            assert!(!said.contains(step), "{step} in {said}");
        }
    }
    let r = set(true, "1");
    assert_eq!(r.code, Some(2), "{r:#?}");
    let doc: Value = serde_json::from_str(&r.stdout).unwrap();
    assert_eq!(doc["results"][0]["kind"], "refused", "{doc}");
    assert_eq!(doc.get("summary"), None, "{doc}");
    // Joint 2 (disabled) saves, joint 1 is refused: the steps are for joint 2 only.
    let r = set(true, "1-2");
    assert_eq!(r.code, Some(2), "{r:#?}");
    let doc: Value = serde_json::from_str(&r.stdout).unwrap();
    assert_eq!(doc["results"][1]["saved"], true, "{doc}");
    let next = doc["summary"]["next"].as_str().unwrap();
    assert!(
        next.starts_with("only joint 2 saved the new rates (the others kept theirs): for it, ")
            && next.contains("power-cycle"),
        "{next}"
    );
}

#[test]
fn whj_e2e_late_replies_are_never_taken_for_two_joints_at_one_id() {
    if !in_netns("whj_e2e_late_replies_are_never_taken_for_two_joints_at_one_id") {
        return;
    }
    // 30 % of the simulator's frames held back for the client's reply timeout (20 ms): the
    // answer to an attempt that timed out comes while the retry waits.
    let sim = Sim::start(
        "udp:239.74.163.40:43140",
        &["--delay", "0.3", "--delay-ms", "20", "--fault-seed", "11"],
    );
    // A turning joint: every status differs from the one before.
    for args in [
        ["mode", "1", "speed"].as_slice(),
        &["enable", "1"],
        &["speed", "1", "2"],
    ] {
        let ok = (0..10).any(|_| sim.whj(args).code == Some(0));
        assert!(ok, "whj {args:?} never went through");
    }
    let mut ok = 0;
    for i in 0..12 {
        let r = sim.whj(&["status", "1"]);
        assert!(
            !r.stderr.contains("two joints answer"),
            "read {i}: one joint taken for two: {}",
            r.stderr
        );
        match r.code {
            Some(0) => ok += 1,
            // Every attempt's reply held back (a timeout), or beside a late one.
            Some(3) => {}
            Some(1) => assert!(r.stderr.contains("came late"), "read {i}: {}", r.stderr),
            _ => panic!("read {i}: {r:?}"),
        }
    }
    assert!(ok > 0, "no read of 12 went through");
}
