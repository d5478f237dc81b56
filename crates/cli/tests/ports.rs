//! `robobus ports` and doctor's use of the same listing, end to end: the ports the OS
//! lists, exactly as the kernel has them (this machine may have no USB port at all), a
//! simulator's pseudo-terminal never among them, and doctor checking the USB ones and
//! naming the others.

#![allow(clippy::unwrap_used, clippy::panic)] // test helpers: a failed unwrap is a failed test

use crate::common;

#[cfg(target_os = "linux")]
use std::collections::BTreeSet;

#[cfg(unix)]
use common::WckSim;
use common::{ok, robobus};
use serde_json::Value;

const ROW_KEYS: [&str; 11] = [
    "adapter",
    "id",
    "kind",
    "latency_advice",
    "latency_timer_ms",
    "manufacturer",
    "pid",
    "product",
    "serial_number",
    "use_for",
    "vid",
];

fn ports_json() -> Value {
    serde_json::from_str(&ok(&["ports", "--json"])).unwrap()
}

/// The serial ports the kernel has, read here without robobus: every tty under
/// /sys/class/tty with a device of a serial subsystem, whose /dev node exists (what
/// serialport's scan without libudev lists).
#[cfg(target_os = "linux")]
fn kernel_ports() -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for e in std::fs::read_dir("/sys/class/tty").unwrap().flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let dev = std::path::Path::new("/dev").join(&name);
        if !dev.exists() {
            continue;
        }
        if name.starts_with("rfcomm") {
            out.insert(dev.display().to_string());
            continue;
        }
        let Ok(sub) = std::fs::canonicalize(e.path().join("device/subsystem")) else {
            continue;
        };
        let sub = sub.file_name().unwrap().to_string_lossy().into_owned();
        if ["amba", "pci", "pnp", "serial-base", "usb", "usb-serial"].contains(&sub.as_str()) {
            out.insert(dev.display().to_string());
        }
    }
    out
}

#[test]
fn ports_json_is_the_host_ports_report_of_exactly_the_ports_the_kernel_has() {
    let v = ports_json();
    assert_eq!(
        v.as_object().unwrap().keys().collect::<Vec<_>>(),
        ["bus", "op", "results", "summary"]
    );
    assert_eq!(
        (v["op"].as_str(), v["bus"].as_str()),
        (Some("host.ports"), Some("host"))
    );
    let rows = v["results"].as_array().unwrap();
    for row in rows {
        let keys: Vec<&str> = row
            .as_object()
            .unwrap()
            .keys()
            .map(String::as_str)
            .collect();
        assert_eq!(keys, ROW_KEYS, "{row}");
        assert_eq!(row["vid"].is_u64(), row["kind"] == "usb", "{row}");
    }
    let summary = &v["summary"];
    assert_eq!(summary["ports"].as_u64(), Some(rows.len() as u64));
    assert_eq!(summary["left_out"], 0);
    #[cfg(target_os = "linux")]
    {
        assert_eq!(summary["os"], "linux");
        let listed: BTreeSet<String> = rows
            .iter()
            .map(|r| r["id"].as_str().unwrap().to_owned())
            .collect();
        assert_eq!(listed, kernel_ports());
    }
}

#[cfg(unix)]
#[test]
fn a_simulators_pseudo_terminal_is_not_a_port_the_os_lists() {
    let sim = WckSim::start("0", &[]);
    let pty = std::fs::canonicalize(sim.port()).unwrap();
    let v = ports_json();
    let ids: Vec<&str> = v["results"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["id"].as_str().unwrap())
        .collect();
    assert!(!ids.contains(&pty.to_str().unwrap()), "{ids:?}");
    assert!(ids.iter().all(|id| !id.starts_with("/dev/pts/")), "{ids:?}");
    // Named, it is checked, and said not to be in the listing.
    let r = robobus(&["--json", "doctor", "--port", sim.port()]);
    let d: Value = serde_json::from_str(&r.stdout).unwrap();
    let adapter = d["findings"]
        .as_array()
        .unwrap()
        .iter()
        .find(|f| f["check"] == "adapter")
        .unwrap();
    assert_eq!(adapter["status"], "skip");
    assert_eq!(
        adapter["detail"],
        "not in the OS's port listing (a pseudo-terminal, or a port the OS cannot describe)"
    );
}

#[test]
fn ports_text_has_a_line_per_listed_port_and_dry_run_sends_nothing() {
    let v = ports_json();
    let ids: Vec<&str> = v["results"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["id"].as_str().unwrap())
        .collect();
    let text = ok(&["ports"]);
    if ids.is_empty() {
        assert_eq!(
            text,
            format!(
                "no serial port found; {}\n",
                v["summary"]["where"].as_str().unwrap()
            )
        );
    } else {
        let mut lines = text.lines();
        let header: Vec<&str> = lines.next().unwrap().split_whitespace().collect();
        assert_eq!(header, ["PORT", "KIND", "USB", "ADAPTER", "USE"]);
        let first: Vec<&str> = lines
            .filter(|l| !l.starts_with(' '))
            .map(|l| l.split_whitespace().next().unwrap())
            .collect();
        assert_eq!(first, ids);
    }
    assert_eq!(
        ok(&["ports", "--dry-run"]),
        "# lists the serial ports the OS knows; no port is opened and nothing is sent\n"
    );
}

#[test]
fn doctor_checks_the_usb_ports_of_the_listing_and_names_the_others() {
    let v = ports_json();
    let rows = v["results"].as_array().unwrap();
    let id = |r: &Value| r["id"].as_str().unwrap().to_owned();
    let usb: Vec<String> = rows.iter().filter(|r| r["kind"] == "usb").map(id).collect();
    let others: Vec<String> = rows.iter().filter(|r| r["kind"] != "usb").map(id).collect();
    let r = robobus(&["--json", "doctor"]);
    let d: Value = serde_json::from_str(&r.stdout).unwrap();
    let findings = d["findings"].as_array().unwrap();
    let serial: Vec<(&str, &str, &str)> = findings
        .iter()
        .filter(|f| f["subject"] == "serial")
        .map(|f| {
            (
                f["check"].as_str().unwrap(),
                f["status"].as_str().unwrap(),
                f["detail"].as_str().unwrap(),
            )
        })
        .collect();
    let mut want = Vec::new();
    let no_usb = format!(
        "no USB serial port found; {}",
        v["summary"]["where"].as_str().unwrap()
    );
    if usb.is_empty() {
        want.push(("ports", "skip", no_usb.as_str()));
    }
    let named = format!(
        "not USB, not checked (name one with --port): {}",
        others.join(", ")
    );
    if !others.is_empty() {
        want.push(("other ports", "skip", named.as_str()));
    }
    assert_eq!(serial, want);
    // Each USB port has its adapter finding, with the listing's use of it.
    for port in &usb {
        let f = findings
            .iter()
            .find(|f| f["subject"] == port.as_str() && f["check"] == "adapter")
            .unwrap_or_else(|| panic!("no adapter finding for {port}: {findings:#?}"));
        let row = rows.iter().find(|r| r["id"] == port.as_str()).unwrap();
        if let Some(use_for) = row["use_for"].as_str() {
            assert!(f["detail"].as_str().unwrap().ends_with(use_for), "{f}");
        }
    }
}

#[test]
fn doctor_takes_a_serial_line_can_fd_adapter_as_whj_bus_and_bounds_its_port() {
    let long = format!("slcan:/dev/{}", "a".repeat(5000));
    let r = robobus(&["doctor", "--whj-bus", &long]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(
        r.stderr.contains("--whj-bus") && r.stderr.contains("1..=4095 bytes"),
        "{}",
        r.stderr
    );
    assert!(r.stdout.is_empty(), "{}", r.stdout);
    // A port that is not there: the probe's open fails (a finding), nothing is sent.
    let r = robobus(&[
        "--json",
        "doctor",
        "--whj-bus",
        "slcan:/nonexistent/ttyACM9",
    ]);
    assert_eq!(r.code, Some(5), "{r:#?}");
    let d: Value = serde_json::from_str(&r.stdout).unwrap();
    let open = d["findings"]
        .as_array()
        .unwrap()
        .iter()
        .find(|f| f["subject"] == "slcan:/nonexistent/ttyACM9")
        .unwrap_or_else(|| panic!("{d:#}"));
    assert_eq!(
        (open["check"].as_str(), open["status"].as_str()),
        (Some("open"), Some("fail"))
    );
    assert!(
        open["detail"]
            .as_str()
            .unwrap()
            .contains("/nonexistent/ttyACM9"),
        "{open}"
    );
}

/// `robobus sim whj --bus ADDR --joints 1-2` in its own process, killed on drop.
#[cfg(unix)]
struct AdapterSim {
    child: std::process::Child,
    _dir: tempfile::TempDir,
}

#[cfg(unix)]
impl Drop for AdapterSim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Starts an emulated adapter (`slcan` or `fdcanusb`) at a pty symlink; returns its path.
#[cfg(unix)]
fn adapter_sim(kind: &str) -> (AdapterSim, String) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(kind).display().to_string();
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args([
            "sim",
            "whj",
            "--joints",
            "1-2",
            "--bus",
            &format!("{kind}:{path}"),
        ])
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let sim = AdapterSim { child, _dir: dir };
    let t0 = std::time::Instant::now();
    while !std::path::Path::new(&path).exists() {
        assert!(
            t0.elapsed() < std::time::Duration::from_secs(20),
            "no {path}"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    (sim, path)
}

#[cfg(unix)]
#[test]
fn doctor_says_a_serial_line_can_fd_adapter_answers_then_probes_its_joints() {
    for kind in ["slcan", "fdcanusb"] {
        let (_sim, path) = adapter_sim(kind);
        let bus = format!("{kind}:{path}");
        let r = robobus(&["--json", "doctor", "--whj-bus", &bus, "--joints", "1-2"]);
        let d: Value = serde_json::from_str(&r.stdout).unwrap_or_else(|e| panic!("{e}: {r:#?}"));
        let findings = d["findings"].as_array().unwrap();
        let adapter = findings
            .iter()
            .find(|f| f["subject"] == bus.as_str() && f["check"] == "adapter")
            .unwrap_or_else(|| panic!("no adapter finding: {findings:#?}"));
        assert_eq!(adapter["status"], "ok");
        let detail = adapter["detail"].as_str().unwrap();
        if kind == "slcan" {
            let version = detail
                .strip_prefix(&format!("slcan adapter on {path} answers (version "))
                .and_then(|v| v.strip_suffix("), set to 1 / 5 Mbit/s"))
                .unwrap_or_else(|| panic!("{detail}"));
            assert!(!version.is_empty(), "{detail}");
        } else {
            assert_eq!(
                detail,
                format!("fdcanusb on {path} answers, set to 1 / 5 Mbit/s")
            );
        }
        // Then the joints behind it, each found once.
        for joint in ["J1", "J2"] {
            let subject = format!("{joint} on {bus}");
            let dup = findings
                .iter()
                .find(|f| f["subject"] == subject.as_str() && f["check"] == "duplicate-id")
                .unwrap_or_else(|| panic!("no {subject}: {findings:#?}"));
            assert_eq!(dup["status"], "ok", "{dup}");
        }
    }
}
