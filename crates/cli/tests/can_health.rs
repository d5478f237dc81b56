//! CAN health read from the kernel, in User-Mode Linux with a real CAN controller driver:
//! the kernel's slcan (a serial-line CAN adapter) on a pseudo-terminal whose adapter end
//! this test plays. The adapter's state reports drive the kernel's controller state
//! (error-active, then error-passive, then bus-off) exactly as a USB adapter's would;
//! `robobus_link::socketcan::health` and `robobus doctor --can` read each state, its
//! counts and the advice, and a restart (down and up) brings it back. slcan is classic
//! CAN: it is reported as such, with the command that sets CAN FD, and doctor fails it.
#![cfg(target_os = "linux")]
#![allow(clippy::unwrap_used, clippy::panic)]

use crate::common;

use std::io::{Read, Write};
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use robobus_link::socketcan::health::{self, ControllerState};
use robobus_testkit::Inner;
use serde_json::Value;

#[test]
fn controller_states_forced_through_a_real_driver_are_read_and_advised() {
    Inner::exact(module_path!(), "inner_can_health", "ROBOBUS_IN_UML")
        .in_uml()
        .expect_marker("CAN HEALTH OK");
}

fn ip(args: &[&str]) {
    let out = Command::new("ip").args(args).output().unwrap();
    assert!(
        out.status.success(),
        "ip {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Waits until `f` holds (at most 3 s).
fn until(what: &str, mut f: impl FnMut() -> bool) {
    let end = Instant::now() + Duration::from_secs(3);
    while !f() {
        assert!(Instant::now() < end, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// `robobus --json doctor --can can0`'s controller finding, and its exit code.
fn doctor() -> (Value, Option<i32>) {
    let r = common::robobus(&["--json", "doctor", "--can", "can0"]);
    let v: Value = serde_json::from_str(&r.stdout).unwrap_or_else(|e| panic!("{e}: {r:#?}"));
    let f = v["findings"]
        .as_array()
        .unwrap()
        .iter()
        .find(|f| f["subject"] == "can0" && f["check"] == "controller")
        .cloned()
        .unwrap_or_else(|| panic!("no controller finding: {v:#}"));
    (f, r.code)
}

/// A pseudo-terminal in the guest's own devpts with the slcan line discipline on its
/// kernel end (`slcan_attach`, can-utils): the attach process, the adapter's end, and
/// what the kernel has sent the adapter so far (read all the time, so its writes
/// complete).
fn attach_adapter() -> (std::process::Child, std::fs::File, Arc<Mutex<Vec<u8>>>) {
    // The adapter's end (master) and the kernel's (slave, with the slcan line discipline),
    // in the guest's own devpts.
    let pts = std::path::PathBuf::from(std::env::var_os("ROBOBUS_UML_PTS").unwrap());
    let master = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(pts.join("ptmx"))
        .unwrap();
    rustix::pty::grantpt(&master).unwrap();
    rustix::pty::unlockpt(&master).unwrap();
    let name = rustix::pty::ptsname(&master, Vec::new()).unwrap();
    let number = name
        .to_str()
        .unwrap()
        .rsplit('/')
        .next()
        .unwrap()
        .to_owned();
    let slave = pts.join(number);
    let attach = Command::new("slcan_attach")
        .arg("-w")
        .arg(&slave)
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    // The adapter reads what the kernel sends it (open, bit rate) so its writes complete.
    let adapter = master;
    let heard = Arc::new(Mutex::new(Vec::new()));
    {
        let mut reader = adapter.try_clone().unwrap();
        let heard = Arc::clone(&heard);
        std::thread::spawn(move || {
            let mut buf = [0u8; 256];
            while let Ok(n) = reader.read(&mut buf) {
                if n == 0 {
                    break;
                }
                heard.lock().unwrap().extend_from_slice(&buf[..n]);
            }
        });
    }
    (attach, adapter, heard)
}

#[test]
#[ignore = "run by controller_states_forced_through_a_real_driver_are_read_and_advised in UML"]
fn inner_can_health() {
    assert!(std::env::var_os("ROBOBUS_IN_UML").is_some());
    let (mut attach, mut adapter, heard) = attach_adapter();
    until("can0", || {
        std::path::Path::new("/sys/class/net/can0").exists()
    });
    ip(&["link", "set", "can0", "type", "can", "bitrate", "1000000"]);
    ip(&["link", "set", "can0", "up"]);
    // The driver opened the adapter at 1 Mbit/s (slcan's S8) and is error-active.
    until("the open command", || {
        heard.lock().unwrap().windows(2).any(|w| w == b"O\r")
    });
    assert!(heard.lock().unwrap().windows(3).any(|w| w == b"S8\r"));
    let h = health::read("can0").unwrap();
    assert_eq!(h.kind.as_deref(), Some("can"), "{h:?}");
    assert_eq!(
        (h.state, h.up, h.bitrate),
        (Some(ControllerState::ErrorActive), true, Some(1_000_000)),
        "{h:?}"
    );
    // slcan is classic CAN: FD off, MTU 16, no data phase; the advice sets CAN FD.
    assert_eq!(
        (h.fd, h.mtu, h.data_bitrate),
        (Some(false), Some(16), None),
        "{h:?}"
    );
    let advice = h.advice().unwrap();
    assert!(
        advice.starts_with("can0 is classic CAN (CAN FD off, bitrate 1000000, no data phase)")
            && advice.contains("dbitrate 5000000 dsample-point 0.75 fd on"),
        "{advice}"
    );
    let (f, code) = doctor();
    assert_eq!((f["status"].as_str(), code), (Some("fail"), Some(5)), "{f}");
    let detail = f["detail"].as_str().unwrap();
    assert!(
        detail.starts_with(
            "error-active; so far 0 error-warning, 0 error-passive, 0 bus-off, 0 restarts"
        ) && detail.ends_with("; classic CAN (CAN FD off)"),
        "{f}"
    );
    assert!(f["fix"].as_str().unwrap().contains("fd on"), "{f}");

    // The adapter reports error-passive: receive errors 130, transmit errors 90.
    adapter.write_all(b"sp130090\r").unwrap();
    until("error-passive", || {
        health::read("can0").unwrap().state == Some(ControllerState::ErrorPassive)
    });
    let h = health::read("can0").unwrap();
    assert_eq!(h.stats.unwrap().error_passive, 1, "{h:?}");
    let (f, _) = doctor();
    // Error-passive on a classic controller: it fails (classic CAN) and says both.
    assert_eq!(f["status"], "fail", "{f}");
    assert!(
        f["detail"].as_str().unwrap().contains("1 error-passive"),
        "{f}"
    );
    let fix = f["fix"].as_str().unwrap();
    assert!(
        fix.starts_with("can0 is error-passive")
            && fix.contains("termination")
            && fix.contains("fd on"),
        "{fix}"
    );

    // Then bus-off: the controller leaves the bus, and says how to restart it.
    adapter.write_all(b"sb256256\r").unwrap();
    until("bus-off", || {
        health::read("can0").unwrap().state == Some(ControllerState::BusOff)
    });
    let h = health::read("can0").unwrap();
    assert_eq!((h.stats.unwrap().bus_off, h.carrier), (1, false), "{h:?}");
    let (f, code) = doctor();
    assert_eq!((f["status"].as_str(), code), (Some("fail"), Some(5)), "{f}");
    let fix = f["fix"].as_str().unwrap();
    assert!(
        fix.starts_with("can0 is bus-off")
            && fix.contains("sudo ip link set can0 type can restart"),
        "{fix}"
    );

    // This driver cannot restart from bus-off in place; down and up restarts it.
    ip(&["link", "set", "can0", "down"]);
    ip(&["link", "set", "can0", "up"]);
    until("error-active again", || {
        health::read("can0").unwrap().state == Some(ControllerState::ErrorActive)
    });
    catalogue_on_vcan0();
    let _ = attach.stdin.take().map(|mut s| s.write_all(b"\n"));
    let _ = attach.kill();
    let _ = attach.wait();
    println!("CAN HEALTH OK");
}

/// The catalogue's whj.can-health on a station's CAN FD bus (vcan0: no controller, MTU
/// 72: not classic).
fn catalogue_on_vcan0() {
    let mut station = robobus::station::Station::new();
    station.add_whj_at("vcan0", robobus::station::open_whj("vcan0", None).unwrap());
    let request: robobus::catalogue::Request =
        serde_json::from_value(serde_json::json!({"op": "whj.can-health"})).unwrap();
    let r =
        robobus::catalogue::run(&station, &request, &mut robobus::ops::Control::none()).unwrap();
    let row = serde_json::to_value(&r).unwrap()["results"][0].clone();
    assert_eq!(
        (row["id"].as_str(), row["kind"].as_str()),
        (Some("vcan0"), Some("vcan")),
        "{row}"
    );
    assert_eq!(
        (row["up"].as_bool(), row["state"].is_null()),
        (Some(true), true),
        "{row}"
    );
    // vcan0 carries CAN FD (MTU 72): not classic, nothing to advise.
    assert_eq!(
        (
            row["classic"].as_bool(),
            row["mtu"].as_u64(),
            row["advice"].is_null()
        ),
        (Some(false), Some(72), true),
        "{row}"
    );
}
