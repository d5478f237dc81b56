//! Interoperability with the real python-can package (installed by the test into a venv
//! under `target/pyenv` through `scripts/py/ensure-venv`).
//!
//! - datagrams: our encoding is byte-identical to python-can's, and python-can decodes ours;
//! - a live exchange of 4-, 16- and 64-byte BRS frames both ways between a python-can
//!   process and this test, inside a private network namespace (`unshare -n`, as
//!   the `robobus-link` docs describe) on python-can's default group and port;
//! - candump logs written by us read back by python-can's `CanutilsLogReader`.

// Linux only: the live exchange runs in a private network namespace (`unshare -n`), and
// the venv is made by a shell script.
#![cfg(target_os = "linux")]
// Helpers outside #[test] functions may unwrap and panic too: a failure is a failed test.
#![allow(clippy::unwrap_used, clippy::panic)]

use crate::common;

use std::fmt::Write as _;
use std::io::{BufRead, BufReader, Write};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use robobus_link::capture::CandumpWriter;
use robobus_link::{CandumpRecord, FrameLink, UdpBus, UdpBusConfig, pycan, read_candump};
use robobus_testkit::Inner;
use robobus_whj::CanFrame;

fn fd(id: u16, data: &[u8]) -> CanFrame {
    CanFrame::new_fd(CanFrame::standard_id(id).unwrap(), data).unwrap()
}

fn hex(b: &[u8]) -> String {
    if b.is_empty() {
        return "-".into();
    }
    let mut s = String::with_capacity(2 * b.len());
    for x in b {
        let _ = write!(s, "{x:02x}");
    }
    s
}

fn sample_frames() -> Vec<(f64, CanFrame)> {
    let ext =
        |id: u32, data: &[u8]| CanFrame::new_fd(CanFrame::extended_id(id).unwrap(), data).unwrap();
    let classic = |id: u16, data: &[u8]| {
        CanFrame::new_classic(CanFrame::standard_id(id).unwrap(), data).unwrap()
    };
    let ramp = |n: usize| {
        (0..n)
            .map(|i| u8::try_from(i * 37 % 256).unwrap())
            .collect::<Vec<u8>>()
    };
    vec![
        (0.0, fd(0x000, &[])),
        (1.5, fd(0x07F, &[1, 2, 3, 4])),
        (1_795_360_410.847_412, fd(0x080, &ramp(16))),
        (1_795_360_410.847_413, fd(0x0FF, &ramp(64))),
        (2.0e9, fd(0x100, &ramp(12)).with_brs(false)),
        (3.25, fd(0x7FF, &ramp(8)).with_esi(true)),
        (4.0, ext(0x1FFF_FFFF, &ramp(48))),
        (5.0, ext(0x12345, &ramp(20))),
        (6.0, classic(0x123, &ramp(8))),
        (7.0, classic(0x001, &[])),
    ]
}

#[test]
fn datagrams_are_byte_identical_to_python_cans_own() {
    let py = common::python();
    let mut child = Command::new(&py)
        .arg(common::py_script("pack.py"))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let frames = sample_frames();
    let mut input = String::new();
    for (ts, f) in &frames {
        let _ = writeln!(
            input,
            "{ts:?} {:x} {} {} {} {} {} {}",
            f.raw_id(),
            u8::from(f.is_extended()),
            u8::from(f.is_fd()),
            u8::from(f.brs()),
            u8::from(f.esi()),
            hex(f.data()),
            hex(&pycan::encode(f, *ts)),
        );
    }
    child
        .stdin
        .take()
        .unwrap()
        .write_all(input.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "pack.py failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), frames.len());
    for ((ts, f), line) in frames.iter().zip(lines) {
        let (theirs, fields) = line.split_once('\t').unwrap();
        assert_eq!(hex(&pycan::encode(f, *ts)), theirs, "datagram of {f:?}");
        // And python-can decodes our datagram into the same message.
        let expected = format!(
            "{ts:?} {:x} {} {} {} {} {}",
            f.raw_id(),
            u8::from(f.is_extended()),
            u8::from(f.is_fd()),
            u8::from(f.brs()),
            u8::from(f.esi()),
            hex(f.data())
        );
        assert_eq!(
            fields, expected,
            "python-can's view of our datagram for {f:?}"
        );
        // And we decode theirs.
        let bytes: Vec<u8> = (0..theirs.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&theirs[i..i + 2], 16).unwrap())
            .collect();
        assert_eq!(pycan::decode_frame(&bytes).unwrap(), (*f, *ts));
    }
}

/// Environment variable telling the inner test it runs inside the namespace.
const NETNS_ENV: &str = "ROBOBUS_LINK_IN_NETNS";

#[test]
fn python_can_and_robobus_exchange_brs_frames_in_a_private_network_namespace() {
    let py = common::python();
    Inner::exact(module_path!(), "inner_exchange_with_python_can", NETNS_ENV)
        .env(NETNS_ENV, &py)
        .in_private_netns()
        .expect_marker("INTEROP OK");
}

/// Runs inside the private namespace (started by the test above, loopback up and
/// multicast routed to it); fails when run any other way.
#[test]
#[ignore = "run by python_can_and_robobus_exchange_brs_frames_in_a_private_network_namespace inside unshare -n"]
// One namespace runs the whole scenario, step by step.
#[allow(clippy::too_many_lines)]
fn inner_exchange_with_python_can() {
    let py = std::env::var(NETNS_ENV)
        .expect("this test only runs inside the private namespace its outer test creates");

    // python-can's defaults: group 239.74.163.2, port 43113 (private namespace: nobody else).
    let mut bus = UdpBus::open(&UdpBusConfig::default()).unwrap();

    // `python -m can.logger` on the same bus records everything in candump format.
    let logdir = tempfile::tempdir().unwrap();
    let logfile = logdir.path().join("logger.log");
    let mut logger = Command::new(&py)
        .args([
            "-u",
            "-m",
            "can.logger",
            "-i",
            "udp_multicast",
            "-c",
            "239.74.163.2",
            "-f",
        ])
        .arg(&logfile)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut logger_out = BufReader::new(logger.stdout.take().unwrap());
    let mut banner = String::new();
    while !banner.contains("Connected to") {
        banner.clear();
        assert!(
            logger_out.read_line(&mut banner).unwrap() > 0,
            "can.logger exited early"
        );
    }

    let mut peer = Command::new(&py)
        .arg(common::py_script("peer.py"))
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let (tx, rx) = mpsc::channel();
    let stdout = peer.stdout.take().unwrap();
    let reader = std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines() {
            let line = line.unwrap();
            let done = line == "done";
            tx.send(line).unwrap();
            if done {
                break;
            }
        }
    });
    let ready = rx
        .recv_timeout(Duration::from_secs(30))
        .expect("peer.py never said ready");
    assert_eq!(ready, "ready");

    let ramp = |n: usize, k: u8| {
        (0..n)
            .map(|i| u8::try_from(i).unwrap().wrapping_mul(k))
            .collect::<Vec<u8>>()
    };
    let sent = [
        fd(0x10, &ramp(4, 3)),
        fd(0x11, &ramp(16, 5)),
        fd(0x12, &ramp(64, 7)),
    ];
    for f in &sent {
        assert!(f.brs() && f.is_fd());
        bus.send(f).unwrap();
    }
    let deadline = Instant::now() + Duration::from_secs(20);
    let mut replies = Vec::new();
    while replies.len() < sent.len() {
        replies.push(bus.recv(deadline).expect("reply from python-can").frame);
    }
    replies.sort_by_key(CanFrame::raw_id);
    for (f, r) in sent.iter().zip(&replies) {
        let reversed: Vec<u8> = f.data().iter().rev().copied().collect();
        assert_eq!(r.raw_id(), f.raw_id() | 0x100);
        assert_eq!(r.data(), reversed.as_slice());
        assert!(r.is_fd() && r.brs() && !r.esi());
    }
    let mut peer_lines = Vec::new();
    loop {
        let line = rx
            .recv_timeout(Duration::from_secs(20))
            .expect("peer.py output");
        if line == "done" {
            break;
        }
        peer_lines.push(line);
    }
    peer_lines.sort();
    let expected: Vec<String> = sent
        .iter()
        .map(|f| format!("rx {:x} 1 1 {}", f.raw_id(), hex(f.data())))
        .collect();
    assert_eq!(peer_lines, expected);
    assert!(peer.wait().unwrap().success());
    reader.join().unwrap();
    // Our own three frames came back and were filtered; nothing malformed.
    assert_eq!(bus.stats().echoes, 3);
    assert_eq!(bus.stats().malformed, 0);

    // Stop the logger like a user would (Ctrl-C), after giving it time to take the last
    // datagrams off its socket, and read its log with our reader.
    std::thread::sleep(Duration::from_secs(1));
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(i32::try_from(logger.id()).unwrap()),
        nix::sys::signal::Signal::SIGINT,
    )
    .unwrap();
    assert!(logger.wait().unwrap().success());
    let text = std::fs::read_to_string(&logfile).unwrap();
    let mut from_logger: Vec<CanFrame> = read_candump(text.as_bytes())
        .map(|r| r.unwrap_or_else(|e| panic!("{e} in:\n{text}")).frame)
        .collect();
    let mut expected: Vec<CanFrame> = sent.to_vec();
    expected.extend(&replies);
    from_logger.sort_by_key(CanFrame::raw_id);
    assert_eq!(from_logger, expected, "can.logger wrote:\n{text}");
    println!("INTEROP OK");
}

#[test]
fn candump_logs_we_write_are_read_by_python_cans_reader() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("capture.log");
    let mut w = CandumpWriter::new(std::fs::File::create(&path).unwrap());
    let frames = sample_frames();
    for (i, (_, f)) in frames.iter().enumerate() {
        let rec = CandumpRecord {
            timestamp: Duration::new(1_795_360_410 + i as u64, 847_412_000),
            iface: if i % 2 == 0 {
                "vcan0".into()
            } else {
                "can1".into()
            },
            frame: *f,
        };
        w.write(&rec).unwrap();
    }
    w.flush().unwrap();
    drop(w);
    let out = Command::new(common::python())
        .arg(common::py_script("readlog.py"))
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "readlog.py failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), frames.len());
    for (i, ((_, f), line)) in frames.iter().zip(lines).enumerate() {
        let expected = format!(
            "{}.847412 {} {:x} {} {} {} {} {}",
            1_795_360_410 + i as u64,
            if i % 2 == 0 { "vcan0" } else { "can1" },
            f.raw_id(),
            u8::from(f.is_extended()),
            u8::from(f.is_fd()),
            u8::from(f.brs()),
            u8::from(f.esi()),
            hex(f.data())
        );
        assert_eq!(line, expected);
    }
}
