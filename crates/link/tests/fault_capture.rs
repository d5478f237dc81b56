//! Fault injection (reproducible by seed) and capture / replay over the in-memory links.

// Helpers outside #[test] functions may unwrap and panic too: a failure is a failed test.
#![allow(clippy::unwrap_used, clippy::panic)]

use std::time::{Duration, Instant};

use robobus_link::capture::{Dir, read_hex_log};
use robobus_link::{
    ByteLink, CaptureByteLink, CaptureFrameLink, FaultConfig, FaultyByteLink, FaultyFrameLink,
    FrameLink, FrameLinkError, IdFilter, LinkError, MemoryBus, MemoryByteLink, ReplayByteLink,
    ReplayFrameLink, read_candump,
};
use robobus_whj::CanFrame;

fn soon() -> Instant {
    Instant::now() + Duration::from_secs(2)
}

fn stream() -> Vec<u8> {
    (0..4096u32)
        .map(|i| u8::try_from((i * 7 + i / 256) % 256).unwrap())
        .collect()
}

/// Sends `stream()` through a faulty byte link (in 64-byte writes) and returns what arrived.
fn through_faulty_bytes(cfg: FaultConfig) -> Vec<u8> {
    let (a, mut b) = MemoryByteLink::pair();
    let mut a = FaultyByteLink::new(a, cfg);
    for chunk in stream().chunks(64) {
        a.write_all(chunk).unwrap();
    }
    let mut out = Vec::new();
    let mut buf = [0u8; 512];
    loop {
        match b.read_some(&mut buf, Instant::now()) {
            Ok(n) => out.extend_from_slice(&buf[..n]),
            Err(LinkError::Timeout { .. }) => break,
            Err(e) => panic!("{e}"),
        }
    }
    out
}

#[test]
fn byte_faults_are_reproducible_by_seed() {
    let cfg = |seed| FaultConfig {
        corrupt: 0.02,
        drop: 0.01,
        duplicate: 0.01,
        ..FaultConfig::seeded(seed)
    };
    let first = through_faulty_bytes(cfg(7));
    let again = through_faulty_bytes(cfg(7));
    let other = through_faulty_bytes(cfg(8));
    assert_eq!(first, again, "same seed, different stream");
    assert_ne!(first, other, "different seeds, same stream");
    assert_ne!(first, stream(), "no faults were injected");
    // No faults configured: the stream is untouched.
    assert_eq!(through_faulty_bytes(FaultConfig::seeded(7)), stream());
}

#[test]
fn byte_fault_rates_are_roughly_the_configured_ones() {
    let (a, mut b) = MemoryByteLink::pair();
    let mut a = FaultyByteLink::new(
        a,
        FaultConfig {
            corrupt: 0.1,
            ..FaultConfig::seeded(1)
        },
    );
    let data = stream();
    a.write_all(&data).unwrap();
    let mut got = vec![0u8; data.len()];
    b.read_exact(&mut got, soon()).unwrap();
    let flipped: Vec<u32> = data
        .iter()
        .zip(&got)
        .map(|(x, y)| (x ^ y).count_ones())
        .filter(|n| *n > 0)
        .collect();
    // Exactly one bit per corrupted byte; about 10 % of 4096 bytes.
    assert!(flipped.iter().all(|n| *n == 1));
    assert!(
        (250..=570).contains(&flipped.len()),
        "{} corrupted",
        flipped.len()
    );
    assert_eq!(a.stats().corrupted, flipped.len() as u64);
}

#[test]
fn truncate_and_disconnect_after_n() {
    let (a, mut b) = MemoryByteLink::pair();
    let cfg = FaultConfig {
        truncate: 1.0,
        disconnect_after: Some(3),
        ..FaultConfig::seeded(3)
    };
    let mut a = FaultyByteLink::new(a, cfg);
    for _ in 0..3 {
        a.write_all(&[1, 2, 3, 4, 5, 6, 7, 8]).unwrap();
    }
    assert!(matches!(a.write_all(&[1]), Err(LinkError::Closed { .. })));
    assert_eq!(a.stats().truncated, 3);
    // Each write was cut short: fewer than 24 bytes arrived.
    let mut buf = [0u8; 24];
    let err = b.read_exact(&mut buf, Instant::now()).unwrap_err();
    assert!(
        matches!(err, LinkError::Timeout { received, .. } if received < 24),
        "{err:?}"
    );
}

#[test]
fn rx_side_faults_apply_to_reads() {
    let (mut a, b) = MemoryByteLink::pair();
    let cfg = FaultConfig {
        corrupt: 1.0,
        tx: false,
        ..FaultConfig::seeded(5)
    };
    let mut b = FaultyByteLink::new(b, cfg);
    a.write_all(&[0u8; 16]).unwrap();
    let mut buf = [0u8; 16];
    b.read_exact(&mut buf, soon()).unwrap();
    assert!(buf.iter().all(|x| x.is_power_of_two()), "{buf:?}");
}

fn frames() -> Vec<CanFrame> {
    (0..200u16)
        .map(|i| {
            let data: Vec<u8> = (0..16)
                .map(|k| u8::try_from((i + k) % 256).unwrap())
                .collect();
            CanFrame::new_fd(CanFrame::standard_id(0x100 + i % 16).unwrap(), &data).unwrap()
        })
        .collect()
}

fn through_faulty_frames(cfg: FaultConfig) -> Vec<CanFrame> {
    let bus = MemoryBus::new();
    let mut rx = bus.endpoint();
    let mut tx = FaultyFrameLink::new(bus.endpoint(), cfg);
    for f in frames() {
        tx.send(&f).unwrap();
    }
    let mut out = Vec::new();
    loop {
        match rx.recv(Instant::now()) {
            Ok(r) => out.push(r.frame),
            Err(FrameLinkError::Timeout) => break,
            Err(e) => panic!("{e}"),
        }
    }
    out
}

#[test]
fn frame_faults_are_reproducible_by_seed() {
    let cfg = |seed| FaultConfig {
        drop: 0.05,
        corrupt: 0.05,
        duplicate: 0.05,
        truncate: 0.05,
        ..FaultConfig::seeded(seed)
    };
    let first = through_faulty_frames(cfg(42));
    assert_eq!(first, through_faulty_frames(cfg(42)));
    assert_ne!(first, through_faulty_frames(cfg(43)));
    assert_ne!(first, frames());
    // Truncated frames keep legal CAN FD lengths and their flags.
    assert!(first.iter().all(|f| f.len() <= 16 && f.is_fd() && f.brs()));
    assert!(first.iter().any(|f| f.len() < 16), "no truncation happened");
    assert_eq!(through_faulty_frames(FaultConfig::seeded(42)), frames());
}

#[test]
fn frame_link_disconnects_after_n_calls() {
    let bus = MemoryBus::new();
    let _peer = bus.endpoint();
    let cfg = FaultConfig {
        disconnect_after: Some(2),
        ..FaultConfig::seeded(0)
    };
    let mut link = FaultyFrameLink::new(bus.endpoint(), cfg);
    let f = frames()[0];
    link.send(&f).unwrap();
    link.send(&f).unwrap();
    assert!(matches!(link.send(&f), Err(FrameLinkError::Closed { .. })));
    assert!(matches!(
        link.recv(soon()),
        Err(FrameLinkError::Closed { .. })
    ));
}

#[test]
fn delays_hold_traffic_back() {
    let (a, mut b) = MemoryByteLink::pair();
    let cfg = FaultConfig {
        delay: 1.0,
        delay_by: Duration::from_millis(40),
        ..FaultConfig::seeded(0)
    };
    let mut a = FaultyByteLink::new(a, cfg);
    let start = Instant::now();
    a.write_all(&[1]).unwrap();
    assert!(start.elapsed() >= Duration::from_millis(40));
    let mut one = [0u8];
    b.read_exact(&mut one, soon()).unwrap();
    assert_eq!(a.stats().delayed, 1);
}

#[test]
fn frame_capture_writes_candump_and_replays_it() {
    let bus = MemoryBus::new();
    let mut peer = bus.endpoint();
    let mut link = CaptureFrameLink::new(bus.endpoint(), Vec::new(), "vcan0").with_tx_iface("tx0");
    let sent = frames()[..3].to_vec();
    for f in &sent {
        link.send(f).unwrap();
    }
    let answer = CanFrame::new_classic(CanFrame::standard_id(0x7).unwrap(), &[9, 8]).unwrap();
    peer.send(&answer).unwrap();
    assert_eq!(link.recv(soon()).unwrap().frame, answer);
    let (_, log) = link.into_parts();
    let text = String::from_utf8(log).unwrap();
    let records: Vec<_> = read_candump(text.as_bytes())
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(records.len(), 4, "{text}");
    assert!(records[..3].iter().all(|r| r.iface == "tx0"));
    assert_eq!(records[3].iface, "vcan0");
    let logged: Vec<CanFrame> = records.iter().map(|r| r.frame).collect();
    assert_eq!(&logged[..3], sent.as_slice());
    assert_eq!(logged[3], answer);
    assert!(text.lines().next().unwrap().contains("##5"), "{text}");

    // Replay: all records, in order, then Closed; filters apply.
    let mut replay = ReplayFrameLink::new(records.clone(), false);
    for f in &logged {
        assert_eq!(replay.recv(soon()).unwrap().frame, *f);
    }
    assert!(matches!(
        replay.recv(soon()),
        Err(FrameLinkError::Closed { .. })
    ));
    let mut replay = ReplayFrameLink::new(records, false);
    replay.set_filters(&[IdFilter::standard(0x7)]).unwrap();
    assert_eq!(replay.recv(soon()).unwrap().frame, answer);
    replay.send(&answer).unwrap();
    assert_eq!(replay.sent(), 1);
}

#[test]
fn paced_replay_keeps_the_captures_timing() {
    let text = "(100.000000) vcan0 001##1AA\n(100.080000) vcan0 002##1BB\n";
    let records: Vec<_> = read_candump(text.as_bytes())
        .collect::<Result<_, _>>()
        .unwrap();
    let mut replay = ReplayFrameLink::new(records, true);
    let start = Instant::now();
    replay.recv(soon()).unwrap();
    // The second frame is due 80 ms later: a 10 ms deadline times out.
    assert!(
        replay
            .recv(Instant::now() + Duration::from_millis(10))
            .unwrap_err()
            .is_timeout()
    );
    assert_eq!(replay.recv(soon()).unwrap().frame.raw_id(), 2);
    assert!(start.elapsed() >= Duration::from_millis(80));
}

#[test]
fn byte_capture_writes_a_hex_log_and_replays_it() {
    let (a, mut b) = MemoryByteLink::pair();
    let mut link = CaptureByteLink::new(a, Vec::new());
    link.write_all(&[0xFF, 0x03, 0x7F, 0x7C]).unwrap();
    b.write_all(&[0x12, 0x7F]).unwrap();
    let mut answer = [0u8; 2];
    link.read_exact(&mut answer, soon()).unwrap();
    let (_, log) = link.into_parts();
    let text = String::from_utf8(log).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert!(lines[0].ends_with(" > FF 03 7F 7C"), "{text}");
    assert!(lines[1].ends_with(" < 12 7F"), "{text}");
    let records = read_hex_log(text.as_bytes()).unwrap();
    assert_eq!(records[0].dir, Dir::Written);
    assert_eq!(records[1].bytes, vec![0x12, 0x7F]);

    let mut replay = ReplayByteLink::new(records, false);
    replay.write_all(&[0xFF, 0x03, 0x7F, 0x7C]).unwrap();
    let mut got = [0u8; 2];
    replay.read_exact(&mut got, soon()).unwrap();
    assert_eq!(got, [0x12, 0x7F]);
    assert_eq!(replay.written(), &[0xFF, 0x03, 0x7F, 0x7C]);
    assert!(matches!(
        replay.read_some(&mut got, soon()),
        Err(LinkError::Closed { .. })
    ));

    let err = read_hex_log("# comment\n0.1 > FF\n0.2 ? 00\n".as_bytes()).unwrap_err();
    assert_eq!(err.line, 3);
    assert!(err.to_string().contains("line 3"), "{err}");
}
