//! The wall-clock endpoint: `serve` on an in-memory frame link answers like the virtual
//! bus, no earlier than the wire allows, and stops when asked.

#![allow(clippy::unwrap_used, clippy::panic)] // Test code: a failed unwrap is a failed test.

use crate::whj_common;

use std::time::{Duration, Instant};

use robobus_link::{FrameLink, MemoryBus};
use robobus_sim::WaitMode;
use robobus_sim::whj::{ServeStats, Served, WhjBus, WhjModel, spawn};
use whj_common::{frame, pos_cmd};

#[test]
fn serve_answers_on_the_wall_clock_and_stops() {
    let (server, wire) = spawn(WhjBus::chain(1..=7, WhjModel::Whj60, 1)).unwrap();
    let stats = answers(server, &wire);
    assert_eq!(stats.wait, WaitMode::Sleep);
}

#[test]
fn the_precise_mode_answers_the_same_and_reports_each_frames_lateness() {
    let wire = MemoryBus::new();
    let server = Served::spawn_precise(
        "precise",
        WhjBus::chain(1..=7, WhjModel::Whj60, 1),
        wire.endpoint(),
    )
    .unwrap();
    let stats = answers(server, &wire);
    assert_eq!(stats.wait, WaitMode::SPIN);
}

/// Three requests and a silent joint; returns what the server did.
fn answers(server: Served, wire: &MemoryBus) -> ServeStats {
    let mut host = wire.endpoint();

    let mut ask = |f, want: u32| {
        let t0 = Instant::now();
        host.send(&f).unwrap();
        let got = host.recv(Instant::now() + Duration::from_secs(2)).unwrap();
        assert_eq!(got.frame.raw_id(), want, "reply to {f:?}");
        (got.frame, t0.elapsed())
    };
    let (ack, _) = ask(frame(0x003, &[0x02, 0x49, 0x00]), 0x103);
    assert_eq!(ack.data(), &[0x02, 0x49, 0x01]);
    // A servo command and its feedback take at least their wire time (103 µs) plus the
    // 20 µs processing delay.
    let (fb, rtt) = ask(pos_cmd(3, 1000), 0x503);
    assert_eq!(fb.len(), 16);
    assert!(rtt >= Duration::from_micros(123), "{rtt:?}");
    // Joint 4 is still in its bootloader: no answer.
    host.send(&frame(0x604, &[])).unwrap();
    let none = host.recv(Instant::now() + Duration::from_millis(50));
    assert!(none.unwrap_err().is_timeout());

    let (_, stats) = server.stop().unwrap();
    assert_eq!((stats.received, stats.sent), (3, 2));
    // Both frames' releases are in the record (wall-clock values, not checked).
    let l = stats.lateness;
    assert_eq!(l.releases, 2, "{stats:?}");
    assert!(l.p50 <= l.p99 && l.p99.is_some_and(|p| p <= l.max), "{l:?}");
    stats
}
