//! WHJ joints through an slcan CAN FD adapter, end to end: `robobus sim whj --bus
//! slcan:PATH` presents an emulated adapter (`CANable` 2.0 class) on a pty; python-can's own
//! `slcan` interface, unchanged, reads and writes a joint through it; the client's suites
//! run over `--bus slcan:PATH`; and a bad adapter address, a missing port, a rate the
//! adapter cannot take, and an adapter that answers nothing or garbage end with their
//! documented exit codes, nothing sent to a joint. (Linux: the simulator's pty; the
//! test provisions python-can itself with `scripts/py/ensure-venv`.)

#![cfg(unix)]
#![allow(clippy::unwrap_used, clippy::panic, clippy::float_cmp)] // test code

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use common::WhjSim;
use robobus_link::{ByteLink, LinkError, PtyOptions, PtyPair};
use serde_json::Value;

fn python() -> PathBuf {
    PathBuf::from(robobus_testkit::provision("py/ensure-venv"))
}

/// An emulated adapter with joints 1-7 behind it on a pty at a fresh path.
fn sim(dir: &Path, extra: &[&str]) -> WhjSim {
    let path = dir.join("slcan");
    WhjSim::start(&format!("slcan:{}", path.display()), extra)
}

const PYTHON_CLIENT: &str = r#"
import json, sys, can
bus = can.Bus(interface="slcan", channel=sys.argv[1], bitrate=1000000)
bus.set_bitrate(1000000, 5000000)
out = {"version": bus.get_version(2.0), "serial": bus.get_serial_number(2.0)}
def ask(data):
    bus.send(can.Message(arbitration_id=0x002, is_extended_id=False, is_fd=True,
                         bitrate_switch=True, data=data))
    while True:
        m = bus.recv(2.0)
        if m is None:
            return None
        if m.arbitration_id == 0x102:
            return {"data": list(m.data), "fd": m.is_fd, "brs": m.bitrate_switch}
out["read_id"] = ask([0x01, 0x01, 0x01])        # read SYS_ID (0x01), one register
out["write_enable"] = ask([0x02, 0x0A, 0x01, 0x00])  # SYS_ENABLE_DRIVER (0x0A) := 1
out["read_enable"] = ask([0x01, 0x0A, 0x01])
bus.shutdown()
print(json.dumps(out))
"#;

#[test]
fn slcan_e2e_python_cans_slcan_interface_reads_and_writes_a_joint_through_the_emulated_adapter() {
    let py = python();
    let dir = tempfile::tempdir().unwrap();
    let sim = sim(dir.path(), &["--no-iap"]);
    let path = dir.path().join("slcan");
    let out = Command::new(&py)
        .args(["-c", PYTHON_CLIENT, path.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "python-can failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let got: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(got["version"], serde_json::json!([10, 13]), "{got}");
    assert_eq!(got["serial"], "RB01");
    // CAN FD with bit-rate switch, as the joints send.
    let frame = |data: &[u8]| serde_json::json!({"data": data, "fd": true, "brs": true});
    assert_eq!(got["read_id"], frame(&[0x01, 0x01, 0x02, 0x00]));
    assert_eq!(got["write_enable"], frame(&[0x02, 0x0A, 0x01]));
    assert_eq!(got["read_enable"], frame(&[0x01, 0x0A, 0x01, 0x00]));
    // robobus over the same adapter sees what python-can wrote.
    let st = sim.json(&["status", "2"]);
    assert_eq!(st[0]["enabled"], true, "{st:?}");
}

#[test]
fn slcan_e2e_scan_status_move_wave_monitor_and_run_over_the_emulated_adapter() {
    let dir = tempfile::tempdir().unwrap();
    let sim = sim(dir.path(), &["--current-noise-ma", "0"]);
    let bus = sim.bus.clone();

    let found = sim.json(&["scan", "--joints", "1-8"]);
    let ids: Vec<u64> = found.iter().map(|r| r["id"].as_u64().unwrap()).collect();
    assert_eq!(ids, [1, 2, 3, 4, 5, 6, 7], "{found:?}");

    let st = sim.json(&["status", "1-3"]);
    assert_eq!(st.len(), 3);
    assert!(st.iter().all(|r| r["position_deg"] == 0.0), "{st:?}");

    sim.json(&["enable", "1"]);
    sim.json(&["move", "1", "12", "--max-speed", "60"]);
    let st = sim.json(&["status", "1"]);
    let at = st[0]["position_deg"].as_f64().unwrap();
    assert!((at - 12.0).abs() < 0.05, "{st:?}");

    sim.json(&["enable", "3"]);
    let r = sim.whj(&["wave", "3", "--amplitude", "5", "--duration", "0.5"]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);

    // monitor samples the joints through the adapter and records them.
    let csv = dir.path().join("m.csv");
    let r = common::robobus(&[
        "monitor",
        "--bus",
        &bus,
        "--joints",
        "1-2",
        "--duration",
        "1",
        "--record",
        csv.to_str().unwrap(),
    ]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let rows = std::fs::read_to_string(&csv).unwrap();
    assert!(rows.lines().count() > 3, "{rows}");

    // `run` gives the subcommand's report (of joints at rest, never enabled: the same
    // values twice); a dry run opens nothing.
    let want = sim.json(&["status", "4-5"]);
    let file = dir.path().join("request.json");
    std::fs::write(&file, r#"{"op": "whj.status", "joints": "4-5"}"#).unwrap();
    let r = common::robobus(&["run", "--whj-bus", &bus, file.to_str().unwrap()]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let report: Value = serde_json::from_str(&r.stdout).unwrap();
    assert_eq!(report["results"].as_array().unwrap(), &want);
    let r = common::robobus(&[
        "--dry-run",
        "whj",
        "--bus",
        "slcan:/nonexistent/robobus-slcan",
        "move",
        "1",
        "5",
    ]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
}

#[test]
fn slcan_e2e_bad_addresses_ports_and_rates_exit_2_3_4_naming_the_value() {
    for (bus, code, says) in [
        ("canable:/dev/ttyACM0", 2, "slcan:PORT[@BAUD]"),
        ("slcan:/dev/ttyACM0@7", 2, "300..=12000000"),
        (
            "slcan:/nonexistent/robobus-slcan",
            3,
            "/nonexistent/robobus-slcan",
        ),
        ("slcan:COM8", 4, "COM8"),
    ] {
        let r = common::robobus(&["whj", "--bus", bus, "status", "1"]);
        assert_eq!(r.code, Some(code), "{bus}: {}", r.stderr);
        assert!(r.stderr.contains(says), "{bus}: {}", r.stderr);
    }
    // The simulated adapter cannot be powered up at a rate an slcan adapter has no code
    // for: refused before the path appears.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("slcan");
    let bus = format!("slcan:{}", path.display());
    let r = common::robobus(&[
        "sim",
        "whj",
        "--bus",
        &bus,
        "--bitrate",
        "500000",
        "--dbitrate",
        "500000",
    ]);
    assert_eq!(r.code, Some(2), "{}", r.stderr);
    assert!(
        r.stderr
            .contains("data bit rate 500000 bit/s: an slcan adapter cannot be set to it (allowed: 1000000, 2000000, 4000000, 5000000)"),
        "{}",
        r.stderr
    );
    assert!(!path.exists());
    // A dry run says what it would serve and makes no pty.
    let r = common::robobus(&["--dry-run", "sim", "whj", "--bus", &bus]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert!(
        r.stdout.contains(&format!(
            "on slcan adapter on serial port {}; nothing opened",
            path.display()
        )),
        "{}",
        r.stdout
    );
    assert!(!path.exists());
}

/// Runs `whj --bus slcan:<pty> status 1` against a pty whose other end `answer`s each
/// write; returns the run, how long it took and every byte the client wrote.
fn against(answer: &'static [u8]) -> (common::Run, Duration, Vec<u8>) {
    let PtyPair {
        mut master,
        slave,
        slave_path,
    } = PtyPair::open(&PtyOptions::default()).unwrap();
    drop(slave);
    let bus = format!("slcan:{}", slave_path.display());
    let reader = std::thread::spawn(move || {
        let mut written = Vec::new();
        let mut buf = [0u8; 256];
        let end = Instant::now() + Duration::from_secs(10);
        while Instant::now() < end {
            match master.read_some(&mut buf, Instant::now() + Duration::from_millis(50)) {
                Ok(n) => {
                    written.extend_from_slice(&buf[..n]);
                    if !answer.is_empty() {
                        master.write_all(answer).unwrap();
                    }
                }
                Err(LinkError::Timeout { .. }) => {
                    if written.ends_with(b"C\r") && written.len() > 2 {
                        break;
                    }
                }
                Err(e) => panic!("{e}"),
            }
        }
        written
    });
    let t0 = Instant::now();
    let r = common::robobus(&["whj", "--bus", &bus, "status", "1"]);
    let took = t0.elapsed();
    (r, took, reader.join().unwrap())
}

#[test]
fn slcan_e2e_an_adapter_answering_nothing_or_garbage_is_no_device_and_nothing_reaches_a_joint() {
    let (r, took, written) = against(b"");
    assert_eq!(r.code, Some(3), "{}", r.stderr);
    assert!(
        r.stderr
            .contains("no answer to V (version, expected V<version>\\r) within 500 ms"),
        "{}",
        r.stderr
    );
    assert!(took < Duration::from_secs(5), "{took:?}");
    // Close, version request, and the close on the way out: no frame, and no empty line
    // (which the CANable 2.0 firmware answers by carrying out its last command again).
    assert_eq!(String::from_utf8_lossy(&written), "C\rV\rC\r");

    let (r, _, written) = against(b"ERROR 42\r\n");
    assert_eq!(r.code, Some(3), "{}", r.stderr);
    assert!(r.stderr.contains("\"ERROR 42\\r"), "{}", r.stderr);
    assert!(r.stderr.contains("not the slcan protocol"), "{}", r.stderr);
    assert!(
        !written
            .split(|&b| b == b'\r')
            .any(|l| l.first().is_some_and(|c| b"tdbTDB".contains(c))),
        "{:?}",
        String::from_utf8_lossy(&written)
    );
}

#[test]
fn slcan_e2e_a_robot_files_whj_bus_reaches_the_joints_through_the_adapter() {
    let dir = tempfile::tempdir().unwrap();
    let sim = sim(dir.path(), &[]);
    sim.json(&["enable", "2"]);
    sim.json(&["move", "2", "12", "--max-speed", "60"]);
    let robot = dir.path().join("robot.toml");
    std::fs::write(
        &robot,
        format!(
            r#"
[buses.arm]
kind = "whj-bus"
bus = "{}"

[[joints]]
name = "elbow"
bus = "arm"
id = 2
limits = [-1.0, 1.0]
max_velocity = 1.0
max_acceleration = 1.0
"#,
            sim.bus
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
    ]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    let samples = common::json_lines(&r.stdout);
    let last = &samples.last().unwrap()["channels"];
    assert_eq!(last[0]["name"], "elbow");
    let at = last[0]["position_deg"].as_f64().unwrap();
    assert!((at - 12.0).abs() < 0.2, "{last}");
    // A bus address that does not parse is named with the syntax.
    std::fs::write(
        &robot,
        "[buses.arm]\nkind = \"whj-bus\"\nbus = \"canable:COM8\"\n\n[[joints]]\nname = \"elbow\"\nbus = \"arm\"\nid = 2\nlimits = [-1.0, 1.0]\nmax_velocity = 1.0\nmax_acceleration = 1.0\n",
    )
    .unwrap();
    let r = common::robobus(&[
        "monitor",
        "--robot",
        robot.to_str().unwrap(),
        "--duration",
        "1",
    ]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("slcan:PORT[@BAUD]"), "{}", r.stderr);
}

#[test]
fn slcan_e2e_the_emulated_adapter_serves_over_tcp_and_announces_its_address() {
    // A port free a moment ago (loopback only).
    let free = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let given = format!("slcan:socket://127.0.0.1:{free}");
    let mut child = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(["sim", "whj", "--joints", "1-2", "--no-iap"])
        .args(["--bus", &given])
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut err = std::io::BufReader::new(child.stderr.take().unwrap());
    let mut line = String::new();
    std::io::BufRead::read_line(&mut err, &mut line).unwrap();
    let bus = line
        .split("(--bus ")
        .nth(1)
        .and_then(|rest| rest.split(')').next())
        .unwrap_or_else(|| panic!("no address in {line:?}"))
        .to_owned();
    assert_eq!(bus, given, "{line}");
    assert!(
        line.contains(&format!("slcan adapter on TCP socket://127.0.0.1:{free}")),
        "{line}"
    );
    let r = common::robobus(&["--json", "whj", "--bus", &bus, "scan", "--joints", "1-3"]);
    let _ = child.kill();
    let _ = child.wait();
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let doc: Value = serde_json::from_str(&r.stdout).unwrap();
    let ids: Vec<u64> = doc["results"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["id"].as_u64().unwrap())
        .collect();
    assert_eq!(ids, [1, 2]);
}
