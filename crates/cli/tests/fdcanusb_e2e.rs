//! WHJ joints through mjbots' fdcanusb, end to end: `robobus sim whj --bus fdcanusb:PATH`
//! presents an emulated fdcanusb on a pty; the client's suites run over `--bus
//! fdcanusb:PATH` (an fdcanusb cannot send the point-to-point status query, a frame
//! without data: the bus asks status by broadcast); and a bad address, a missing port, a rate the adapter cannot be set to, and an adapter that
//! answers nothing or garbage end with their documented exit codes, nothing sent to a
//! joint. (Linux: the simulator's pty.)

#![cfg(unix)]
#![allow(clippy::unwrap_used, clippy::panic, clippy::float_cmp)] // test code

use crate::common;

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use common::WhjSim;
use robobus_link::{ByteLink, LinkError, PtyOptions, PtyPair};
use serde_json::Value;

/// An emulated fdcanusb with joints 1-7 behind it on a pty at a fresh path.
fn sim(dir: &Path, extra: &[&str]) -> WhjSim {
    let path = dir.join("fdcanusb");
    WhjSim::start(&format!("fdcanusb:{}", path.display()), extra)
}

#[test]
fn fdcanusb_e2e_scan_status_move_wave_monitor_and_run_over_the_emulated_adapter() {
    let dir = tempfile::tempdir().unwrap();
    let sim = sim(
        dir.path(),
        &["--current-noise-ma", "0", "--initial-deg", "2.5"],
    );
    let bus = sim.bus.clone();

    let found = sim.json(&["scan", "--joints", "1-8"]);
    let ids: Vec<u64> = found.iter().map(|r| r["id"].as_u64().unwrap()).collect();
    assert_eq!(ids, [1, 2, 3, 4, 5, 6, 7], "{found:?}");

    let st = sim.json(&["status", "--broadcast", "1-3"]);
    assert_eq!(st.len(), 3, "{st:?}");
    assert!(st.iter().all(|r| r["position_deg"] == 2.5), "{st:?}");
    // The point-to-point status: an fdcanusb cannot send its empty frame, so the bus asks
    // by broadcast; the same values.
    let st = sim.json(&["status", "1-3"]);
    assert_eq!(st.len(), 3, "{st:?}");
    assert!(st.iter().all(|r| r["position_deg"] == 2.5), "{st:?}");

    sim.json(&["enable", "1"]);
    sim.json(&["move", "1", "12", "--max-speed", "60"]);
    let st = sim.json(&["status", "1"]);
    let at = st[0]["position_deg"].as_f64().unwrap();
    assert!((at - 12.0).abs() < 0.05, "{st:?}");

    sim.json(&["enable", "3"]);
    let r = sim.whj(&["wave", "3", "--amplitude", "5", "--duration", "0.5"]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);

    // monitor samples the joints through the adapter, point to point and by broadcast,
    // and records them.
    for broadcast in [false, true] {
        let csv = dir.path().join(format!("m-{broadcast}.csv"));
        let mut args = vec![
            "monitor",
            "--bus",
            &bus,
            "--joints",
            "1-2",
            "--duration",
            "1",
        ];
        if broadcast {
            args.push("--broadcast");
        }
        args.extend(["--record", csv.to_str().unwrap()]);
        let r = common::robobus(&args);
        assert_eq!(r.code, Some(0), "{}", r.stderr);
        let rows = std::fs::read_to_string(&csv).unwrap();
        assert!(rows.lines().count() > 3, "{rows}");
    }

    // `run` gives the subcommand's report; a dry run opens nothing.
    let file = dir.path().join("request.json");
    let want = sim.json(&["status", "1-3"]);
    std::fs::write(&file, r#"{"op": "whj.status", "joints": "1-3"}"#).unwrap();
    let r = common::robobus(&["run", "--whj-bus", &bus, file.to_str().unwrap()]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let report: Value = serde_json::from_str(&r.stdout).unwrap();
    assert_eq!(report["results"].as_array().unwrap(), &want);
    let r = common::robobus(&[
        "--dry-run",
        "whj",
        "--bus",
        "fdcanusb:/nonexistent/robobus-fdcanusb",
        "move",
        "1",
        "5",
    ]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
}

#[test]
fn fdcanusb_e2e_bad_addresses_and_ports_exit_2_3_4_naming_the_value() {
    for (bus, code, says) in [
        ("fdcanusb:", 2, "expected fdcanusb:PORT"),
        (
            "fdcanusb:/nonexistent/robobus-fdcanusb",
            3,
            "/nonexistent/robobus-fdcanusb",
        ),
        ("fdcanusb:COM8", 4, "COM8"),
    ] {
        let r = common::robobus(&["whj", "--bus", bus, "status", "--broadcast", "1"]);
        assert_eq!(r.code, Some(code), "{bus}: {}", r.stderr);
        assert!(r.stderr.contains(says), "{bus}: {}", r.stderr);
    }
    // A simulator serves its adapter on a pty path or TCP, not on a COM port.
    let r = common::robobus(&["sim", "whj", "--bus", "fdcanusb:COM3"]);
    assert_eq!(r.code, Some(2), "{}", r.stderr);
    assert!(
        r.stderr
            .contains("(fdcanusb:/tmp/robobus-fdcanusb) or on TCP (fdcanusb:socket://"),
        "{}",
        r.stderr
    );
}

/// Runs `whj --bus fdcanusb:<pty> status --broadcast 1` against a pty whose other end
/// answers each line the client writes with `answer(line)`; returns the run, how long it
/// took and every line the client wrote (read until the pty has been quiet for 500 ms
/// after the client exited, at most 10 s).
fn against(answer: fn(&str) -> String) -> (common::Run, Duration, Vec<String>) {
    let PtyPair {
        mut master,
        slave,
        slave_path,
    } = PtyPair::open(&PtyOptions::default()).unwrap();
    drop(slave);
    let bus = format!("fdcanusb:{}", slave_path.display());
    let exited = Arc::new(AtomicBool::new(false));
    let client_exited = Arc::clone(&exited);
    let reader = std::thread::spawn(move || {
        let mut written = Vec::new();
        let mut partial = Vec::new();
        let mut buf = [0u8; 256];
        let end = Instant::now() + Duration::from_secs(10);
        while Instant::now() < end {
            // Once the client has exited, a read that times out after 500 ms has found
            // everything it wrote.
            let after_exit = client_exited.load(Ordering::SeqCst);
            let wait = Duration::from_millis(if after_exit { 500 } else { 50 });
            match master.read_some(&mut buf, Instant::now() + wait) {
                Ok(n) => {
                    for &b in &buf[..n] {
                        if b == b'\n' {
                            let line = String::from_utf8_lossy(&partial).into_owned();
                            partial.clear();
                            let reply = answer(&line);
                            written.push(line);
                            if !reply.is_empty() {
                                master.write_all(reply.as_bytes()).unwrap();
                            }
                        } else {
                            partial.push(b);
                        }
                    }
                }
                Err(LinkError::Timeout { .. }) if after_exit => break,
                Err(LinkError::Timeout { .. }) => {}
                Err(LinkError::Closed { .. }) => break,
                Err(e) => panic!("{e}"),
            }
        }
        written
    });
    let t0 = Instant::now();
    let r = common::robobus(&["whj", "--bus", &bus, "status", "--broadcast", "1"]);
    let took = t0.elapsed();
    exited.store(true, Ordering::SeqCst);
    (r, took, reader.join().unwrap())
}

fn no_frame_and_never_on(written: &[String]) {
    assert!(
        !written
            .iter()
            .any(|l| l.starts_with("can std") || l.starts_with("can ext") || l == "can on"),
        "{written:?}"
    );
}

#[test]
fn fdcanusb_e2e_an_adapter_answering_nothing_or_garbage_is_no_device_and_nothing_reaches_a_joint() {
    let (r, took, written) = against(|_| String::new());
    assert_eq!(r.code, Some(3), "{}", r.stderr);
    assert!(
        r.stderr.contains("no answer to `can off` within 500 ms"),
        "{}",
        r.stderr
    );
    assert!(took < Duration::from_secs(5), "{took:?}");
    assert_eq!(written, ["can off"]);

    // An slcan adapter refuses what it does not know with BEL.
    let (r, _, written) = against(|_| "\x07".into());
    assert_eq!(r.code, Some(3), "{}", r.stderr);
    assert!(
        r.stderr.contains("not the fdcanusb protocol") && r.stderr.contains("\\a"),
        "{}",
        r.stderr
    );
    no_frame_and_never_on(&written);

    let (r, _, written) = against(|_| "ERROR 42\r\n".into());
    assert_eq!(r.code, Some(3), "{}", r.stderr);
    assert!(r.stderr.contains("\"ERROR 42\""), "{}", r.stderr);
    no_frame_and_never_on(&written);
}

/// An fdcanusb that cannot be set to 5 Mbit/s data: it refuses the rate as the emulated
/// one does, and takes everything else.
fn no_5_mbit(line: &str) -> String {
    if line == "can off" {
        "ERR already in BusOff\r\n".into()
    } else if line.starts_with("conf set can.fd_bitrate ") {
        "ERR can.fd_bitrate 5000000 cannot be set (allowed: 125000..=2000000 bit/s)\r\n".into()
    } else if let Some(key) = line.strip_prefix("conf get ") {
        let value = if key == "can.bitrate" { "1000000" } else { "1" };
        format!("{value}\r\nOK\r\n")
    } else {
        "OK\r\n".into()
    }
}

#[test]
fn fdcanusb_e2e_a_data_rate_the_adapter_cannot_take_is_bad_input_naming_it_and_what_it_allows() {
    let (r, _, written) = against(no_5_mbit);
    assert_eq!(r.code, Some(2), "{}", r.stderr);
    assert!(
        r.stderr.contains("cannot set can.fd_bitrate to 5000000")
            && r.stderr.contains("allowed: 125000..=2000000 bit/s"),
        "{}",
        r.stderr
    );
    assert_eq!(
        written,
        [
            "can off",
            "conf set can.bitrate 1000000",
            "conf get can.bitrate",
            "conf set can.fd_bitrate 5000000",
        ]
    );
}

#[test]
fn fdcanusb_e2e_the_emulated_adapter_serves_over_tcp_and_its_joints_report_through_it() {
    // A port free a moment ago (loopback only).
    let free = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let given = format!("fdcanusb:socket://127.0.0.1:{free}");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args([
            "sim",
            "whj",
            "--joints",
            "1-2",
            "--no-iap",
            "--initial-deg",
            "-4",
        ])
        .args(["--bus", &given])
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut err = std::io::BufReader::new(child.stderr.take().unwrap());
    let mut line = String::new();
    std::io::BufRead::read_line(&mut err, &mut line).unwrap();
    assert!(
        line.contains(&format!("fdcanusb on TCP socket://127.0.0.1:{free}")),
        "{line}"
    );
    let r = common::robobus(&["--json", "whj", "--bus", &given, "status", "1-2"]);
    let _ = child.kill();
    let _ = child.wait();
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let doc: Value = serde_json::from_str(&r.stdout).unwrap();
    let rows = doc["results"].as_array().unwrap();
    assert_eq!(rows.len(), 2, "{doc}");
    assert!(rows.iter().all(|r| r["position_deg"] == -4.0), "{doc}");
}
