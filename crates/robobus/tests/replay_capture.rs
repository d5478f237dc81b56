//! Capture and replay: captures written by `ops::capture` around links to the simulators,
//! replayed by `ops::replay` with their meanings; malformed lines, corrupted frames and
//! packets flagged; arbitrary input never panics the decoder.

#![allow(clippy::unwrap_used)]

use crate::wck_support;
use crate::whj_common;

use std::path::Path;
use std::time::{Duration, Instant};

use proptest::prelude::*;
use robobus::ops::ErrorKind;
use robobus::ops::capture::{Overwrite, capture_byte_link, capture_frame_link};
use robobus::ops::replay::{
    self, Direction, Entry, EntryKind, Format, Replay, ReplayOptions, Side,
};
use robobus_link::{ByteLink, FrameLink};
use robobus_wck::{Command, Position as WckPos, ServoId, TorqueLevel};
use robobus_whj::broadcast::BroadcastPosition;
use robobus_whj::units::Position;
use robobus_whj::{CanFrame, JointId, ReplyMask, Request};

fn replay_file(path: &Path, options: ReplayOptions) -> Vec<Entry> {
    replay::open(path, &options)
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap()
}

/// (direction, kind, CAN ID, text) of every entry: everything but the times.
fn meanings(entries: &[Entry]) -> Vec<(Direction, EntryKind, Option<u32>, String)> {
    entries
        .iter()
        .map(|e| (e.direction, e.kind, e.can_id, e.text.clone()))
        .collect()
}

fn j1() -> JointId {
    JointId::new(1).unwrap()
}

fn fd(id: u16, data: &[u8]) -> CanFrame {
    CanFrame::new_fd_padded(CanFrame::standard_id(id).unwrap(), data).unwrap()
}

/// Sends `frame` and returns the replies that come within `wait` (the simulator answers
/// in well under 250 ms, even on a stalling virtual machine).
fn exchange(link: &mut impl FrameLink, frame: &CanFrame, replies: usize) {
    link.send(frame).unwrap();
    for _ in 0..replies {
        link.recv(Instant::now() + Duration::from_secs(2)).unwrap();
    }
}

#[test]
fn whj_capture_replays_with_registers_units_and_error_bits() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("whj.log");
    let (sim, endpoint) = whj_common::memory(whj_common::chain(1));
    let mut link = capture_frame_link(endpoint, &path, "can0", Overwrite::No).unwrap();
    exchange(&mut link, &Request::start_application(j1()).to_frame(), 1);
    exchange(&mut link, &Request::read_position(j1()).to_frame(), 1);
    exchange(&mut link, &Request::enable(j1(), true).to_frame(), 1);
    let target = Position::from_degrees(12.5).unwrap();
    exchange(
        &mut link,
        &Request::PositionServo {
            joint: j1(),
            target,
        }
        .to_frame(),
        1,
    );
    exchange(
        &mut link,
        &Request::StatusQuery { joint: j1() }.to_frame(),
        1,
    );
    // A write to the read-only SYS_ERROR (the joint answers with a permission error) and
    // a corrupted register command (unknown command byte 0x07: a format error).
    exchange(&mut link, &fd(0x001, &[0x02, 0x04, 0x00, 0x00]), 1);
    exchange(&mut link, &fd(0x001, &[0x07, 0x14, 0x02]), 1);
    let b = BroadcastPosition::new(ReplyMask::only(j1()).unwrap())
        .with_target(j1(), target)
        .unwrap();
    exchange(&mut link, &Request::BroadcastPosition(b).to_frame(), 1);
    // The file is complete line by line while the link is still open.
    let text = std::fs::read_to_string(&path).unwrap();
    assert_eq!(text.lines().count(), 16, "{text}");
    drop(link);
    drop(sim);

    let entries = replay_file(&path, ReplayOptions::default());
    assert!(entries.iter().all(|e| e.iface.as_deref() == Some("can0")));
    let got = meanings(&entries);
    let to = Direction::ToDevice;
    let from = Direction::FromDevice;
    let want: Vec<(Direction, EntryKind, Option<u32>, String)> = vec![
        (to, EntryKind::Request, Some(0x001), "J1 write IAP_FLAG 0".into()),
        (from, EntryKind::Reply, Some(0x101), "J1 write ack IAP_FLAG: ok".into()),
        (to, EntryKind::Request, Some(0x001), "J1 read 2 registers from 0x14 CUR_POSITION_L".into()),
        (from, EntryKind::Reply, Some(0x101), "J1 read reply: CUR_POSITION 0.0000 °".into()),
        (to, EntryKind::Request, Some(0x001), "J1 write SYS_ENABLE_DRIVER 1".into()),
        (from, EntryKind::Reply, Some(0x101), "J1 write ack SYS_ENABLE_DRIVER: ok".into()),
        (to, EntryKind::Request, Some(0x201), "J1 position servo target position 12.5000 °".into()),
        (from, EntryKind::Reply, Some(0x501), "J1 servo feedback: position 0.0000 °, speed 0.00 RPM, current 0 mA, enabled, no errors".into()),
        (to, EntryKind::Request, Some(0x601), "J1 status query".into()),
        (from, EntryKind::Reply, Some(0x701), "J1 status: position 0.0000 °, current 0 mA, voltage 24.00 V, temperature 25.0 °C, enabled, brake released, errors: position command step".into()),
        (to, EntryKind::Request, Some(0x001), "J1 write SYS_ERROR 0".into()),
        (from, EntryKind::Reply, Some(0x101), "J1 command error: permission error".into()),
        (to, EntryKind::Malformed, Some(0x001), "MALFORMED: unknown command byte 0x07 (allowed: 0x01 read, 0x02 write)".into()),
        (from, EntryKind::Reply, Some(0x101), "J1 command error: format error".into()),
        (to, EntryKind::Request, Some(0x02F), "broadcast position: J1 position 12.5000 °, J2 no data, J3 no data, J4 no data, J5 no data, J6 no data, J7 no data; replies from J1".into()),
        (from, EntryKind::Reply, Some(0x082), "J1 broadcast feedback: position 0.0000 °, speed 0.00 RPM, current 0 mA, voltage 24.00 V, temperature 25.0 °C, enabled, brake released, counter 1, errors: position command step".into()),
    ];
    assert_eq!(got, want);
    // Fields carry the values in units; the read reply's padding is cut to the count asked.
    let read = &entries[3];
    assert_eq!(read.fields.len(), 1);
    assert_eq!(
        (read.fields[0].name.as_str(), read.fields[0].unit),
        ("CUR_POSITION", "°")
    );
    let servo = &entries[6];
    assert_eq!(servo.fields[0].raw, 125_000);
    assert!((servo.fields[0].value - 12.5).abs() < 1e-9);
}

#[test]
fn whj_error_bits_by_name_and_bad_lines_flagged() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.log");
    // Servo feedback of J2 with over-voltage (0x0002) and following error (0x0800); a
    // line that is not a candump line; a classic frame; an unknown CAN ID; a short servo
    // feedback; an extended ID.
    std::fs::write(
        &path,
        "(100.000001) can0 502##5F4010000E8030000A086010001000208\n\
         garbage here\n\
         (100.000002) can0 001#01140200\n\
         (100.000003) can0 7F7##500\n\
         (100.000004) can0 502##50102\n\
         (100.000005) can0 00000001##5011402\n",
    )
    .unwrap();
    let entries = replay_file(&path, ReplayOptions::default());
    let got: Vec<(u64, EntryKind, String)> = entries
        .iter()
        .map(|e| (e.line, e.kind, e.text.clone()))
        .collect();
    assert_eq!(
        got,
        [
            (1, EntryKind::Unexpected, "UNEXPECTED: no request to this joint was waiting for it: J2 servo feedback: position 10.0000 °, speed 20.00 RPM, current 500 mA, enabled, errors: over-voltage, following error".into()),
            (2, EntryKind::Malformed, "MALFORMED: expected `(seconds.micros) iface ID#data`: \"garbage here\"".into()),
            (3, EntryKind::Malformed, "MALFORMED: classic CAN frame (WHJ joints take CAN FD frames only)".into()),
            (4, EntryKind::Malformed, "MALFORMED: CAN ID 0x7f7 is not a WHJ ID".into()),
            (5, EntryKind::Malformed, "MALFORMED: servo feedback of 2 bytes (allowed: 16)".into()),
            (6, EntryKind::Malformed, "MALFORMED: extended 29-bit identifier (WHJ uses 11-bit IDs)".into()),
        ]
    );
    assert_eq!(entries[0].errors, ["over-voltage", "following error"]);
}

fn wck_exchange(link: &mut impl ByteLink, packet: &[u8], reply: bool) {
    link.write_all(packet).unwrap();
    let mut buf = [0u8; 2];
    let deadline = link.now() + Duration::from_millis(50);
    let r = link.read_exact(&mut buf, deadline);
    assert_eq!(r.is_ok(), reply, "{packet:02X?}: {r:?}");
}

#[test]
fn wck_capture_replays_commands_and_replies_from_either_side() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("wck.log");
    let mut sim = wck_support::serve_ids(&[3]);
    let mut link = capture_byte_link(sim.link(), &path, Overwrite::No).unwrap();
    let s3 = ServoId::new(3).unwrap();
    let status = Command::StatusRead { id: s3 }.encode();
    wck_exchange(&mut link, status.as_bytes(), true);
    let mv = Command::Move {
        id: s3,
        torque: TorqueLevel::new(2).unwrap(),
        position: WckPos::new(100).unwrap(),
    }
    .encode();
    wck_exchange(&mut link, mv.as_bytes(), true);
    // Servo 5 is not on the bus: no reply.
    let absent = Command::StatusRead {
        id: ServoId::new(5).unwrap(),
    }
    .encode();
    wck_exchange(&mut link, absent.as_bytes(), false);
    // A corrupted packet (checksum off by one): the module ignores it.
    let mut bad = status.as_bytes().to_vec();
    bad[3] ^= 1;
    wck_exchange(&mut link, &bad, false);
    wck_exchange(
        &mut link,
        Command::Passive { id: s3 }.encode().as_bytes(),
        true,
    );
    drop(link);

    let host = replay_file(&path, ReplayOptions::default());
    let got = meanings(&host);
    let to = Direction::ToDevice;
    let from = Direction::FromDevice;
    let want: Vec<(Direction, EntryKind, Option<u32>, String)> = vec![
        (to, EntryKind::Request, None, "status read servo 3".into()),
        (from, EntryKind::Reply, None, "load 0, position 127".into()),
        (
            to,
            EntryKind::Request,
            None,
            "position move servo 3 to 100 (torque 2)".into(),
        ),
        (from, EntryKind::Reply, None, "load 0, position 127".into()),
        (to, EntryKind::Request, None, "status read servo 5".into()),
        (
            from,
            EntryKind::Missing,
            None,
            "NO REPLY to status read (none before the next packet (line 9))".into(),
        ),
        (
            to,
            EntryKind::Malformed,
            None,
            "MALFORMED: bad checksum: computed 0x23, received 0x22".into(),
        ),
        (to, EntryKind::Request, None, "passive servo 3".into()),
        (from, EntryKind::Reply, None, "passive, position 108".into()),
    ];
    // The shaft has moved from 127 toward 100 by the passive command, 100 ms (on the
    // simulator's virtual clock) after the move.
    assert_eq!(got, want);
    assert_eq!(host[0].bytes, "FF A3 00 23");

    // The same capture as the simulator would write it (directions reversed, no
    // comment): detected as the device's side, the same meanings.
    let text = std::fs::read_to_string(&path).unwrap();
    // The side comment is replaced by one that does not name a side (same line numbers).
    let mut device_log = String::new();
    for l in text.lines() {
        let l = if l.starts_with('#') {
            "# a simulator's capture".to_owned()
        } else if l.contains(" > ") {
            l.replace(" > ", " < ")
        } else {
            l.replace(" < ", " > ")
        };
        device_log.push_str(&l);
        device_log.push('\n');
    }
    let device_path = dir.path().join("device.log");
    std::fs::write(&device_path, device_log).unwrap();
    let mut r = replay::open(&device_path, &ReplayOptions::default()).unwrap();
    let device: Vec<Entry> = r.by_ref().collect::<Result<_, _>>().unwrap();
    assert_eq!(r.side(), Side::Device);
    assert_eq!(meanings(&device), got);
    // Given the wrong side, the replies are not taken for commands silently.
    let wrong = replay_file(
        &device_path,
        ReplayOptions {
            side: Side::Host,
            ..ReplayOptions::default()
        },
    );
    assert!(
        wrong.iter().any(|e| e.kind == EntryKind::Unexpected),
        "{wrong:#?}"
    );
}

#[test]
fn capture_refuses_to_overwrite_unless_asked() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("exists.log");
    std::fs::write(&path, "keep me\n").unwrap();
    let (_sim, endpoint) = whj_common::memory(whj_common::chain(1));
    let err = capture_frame_link(endpoint, &path, "can0", Overwrite::No).unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Refused);
    assert!(err.to_string().contains("already exists"), "{err}");
    assert_eq!(std::fs::read_to_string(&path).unwrap(), "keep me\n");
    let mut sim = wck_support::serve_ids(&[0]);
    let link = capture_byte_link(sim.link(), &path, Overwrite::Yes).unwrap();
    drop(link);
    assert_eq!(
        std::fs::read_to_string(&path).unwrap(),
        format!("{}\n", replay::HOST_SIDE_COMMENT)
    );
    let (_sim, endpoint) = whj_common::memory(whj_common::chain(1));
    let err = capture_frame_link(endpoint, &dir.path().join("x.log"), "can 0", Overwrite::No)
        .unwrap_err();
    assert_eq!(err.kind(), ErrorKind::BadInput);
}

fn line() -> impl Strategy<Value = String> {
    prop_oneof![
        "\\PC{0,80}",
        "[0-9.]{1,12} [<>] ([0-9A-Fa-f]{2} ){0,40}",
        "\\([0-9]{1,10}\\.[0-9]{1,6}\\) can0 [0-9A-F]{3}##[0-9A-F]{0,130}",
        "\\([0-9]{1,10}\\.[0-9]{1,6}\\) can0 [0-9A-F]{3,8}#[#0-9A-FR. ]{0,40}",
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn arbitrary_lines_never_panic_the_decoder(lines in proptest::collection::vec(line(), 1..40), format in 0u8..3, side in 0u8..3) {
        let text = lines.join("\n");
        let options = ReplayOptions {
            format: match format { 0 => None, 1 => Some(Format::Candump), _ => Some(Format::Hex) },
            side: match side { 0 => Side::Auto, 1 => Side::Host, _ => Side::Device },
            ..ReplayOptions::default()
        };
        if let Ok(r) = Replay::from_reader(text.as_bytes(), "p.log", &options) {
            let mut count = 0usize;
            for e in r {
                let e = e.unwrap();
                prop_assert!(e.line >= 1 && e.line <= lines.len() as u64);
                prop_assert!(!e.text.is_empty());
                count += 1;
                prop_assert!(count < 100_000);
            }
        }
    }
}

/// An endless hex log: a command and its reply, again and again.
struct Endless(usize);

impl std::io::Read for Endless {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        const PAIR: &[u8] = b"0.000100 > FF A3 00 23\n0.000900 < 00 7F\n";
        let mut n = 0;
        while n < buf.len() {
            buf[n] = PAIR[self.0 % PAIR.len()];
            self.0 += 1;
            n += 1;
        }
        Ok(n)
    }
}

#[test]
fn a_capture_is_streamed_not_read_whole() {
    // Only a streaming reader can hand out entries of a file that never ends.
    let r = Replay::from_reader(
        std::io::BufReader::new(Endless(0)),
        "endless.log",
        &ReplayOptions::default(),
    )
    .unwrap();
    let entries: Vec<Entry> = r.take(20_000).map(Result::unwrap).collect();
    assert_eq!(entries.len(), 20_000);
    assert!(
        entries
            .iter()
            .step_by(2)
            .all(|e| e.text == "status read servo 3")
    );
    assert!(
        entries
            .iter()
            .skip(1)
            .step_by(2)
            .all(|e| e.text == "load 0, position 127")
    );
    assert_eq!(entries[19_999].line, 20_000);
    let dir = tempfile::tempdir().unwrap();
    let err = replay::open(dir.path(), &ReplayOptions::default()).unwrap_err();
    assert_eq!(err.kind(), ErrorKind::BadInput);
    assert!(err.to_string().contains("is a directory"), "{err}");
}

/// Requests and replies are paired as the client pairs them: two unanswered queries are
/// missing replies, a reply nobody asked for and a reply for another register are
/// unexpected, and the summary counts them.
#[test]
fn whj_requests_and_replies_are_paired_and_the_summary_counts_what_is_missing() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("pairs.log");
    std::fs::write(
        &path,
        // 1: J1 status query, never answered (J1 asked again at line 2).
        // 2: J1 status query, answered at 3.
        // 4: J2 read of 0x14 (2 registers), answered with a reply for 0x10: unexpected.
        // 5: J3 status feedback nobody asked for: unexpected.
        // J2's read is still waiting at the end: missing.
        "(100.000001) can0 601##1\n\
         (100.000002) can0 601##1\n\
         (100.000003) can0 701##1000000000000000000000000F0000000\n\
         (100.000004) can0 002##1011402\n\
         (100.000005) can0 102##1011000000000\n\
         (100.000006) can0 703##1000000000000000000000000F0000000\n",
    )
    .unwrap();
    let mut replay = robobus::ops::replay::open(&path, &ReplayOptions::default()).unwrap();
    let entries: Vec<_> = replay.by_ref().map(Result::unwrap).collect();
    let kinds: Vec<(u64, EntryKind)> = entries.iter().map(|e| (e.line, e.kind)).collect();
    assert_eq!(
        kinds,
        [
            (1, EntryKind::Request),
            (1, EntryKind::Missing),
            (2, EntryKind::Request),
            (3, EntryKind::Reply),
            (4, EntryKind::Request),
            (5, EntryKind::Unexpected),
            (6, EntryKind::Unexpected),
            (4, EntryKind::Missing),
        ],
        "{entries:#?}"
    );
    let s = replay.summary();
    assert_eq!((s.missing, s.unexpected), (2, 2), "{s:?}");
}
