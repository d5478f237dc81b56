use super::*;

fn entries(text: &str, options: ReplayOptions) -> Vec<Entry> {
    Replay::from_reader(text.as_bytes(), "t.log", &options)
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap()
}

#[test]
fn end_board_replies_are_decoded_by_register_name() {
    // The worked examples: tool power := 24 V answered on 0x87, IO1 := output on
    // 0xF7; a version read; a frame shorter than the header.
    let log = "(0.1) can0 087##5B80900000002070101000000\n\
               (0.2) can0 0F7##50F81000000021D0101000000\n\
               (0.3) can0 0F7##5010900000001030203020000\n\
               (0.4) can0 087##50102\n";
    let got: Vec<String> = entries(log, ReplayOptions::default())
        .into_iter()
        .map(|e| e.text)
        .collect();
    assert_eq!(
        got,
        [
            "end board: write 0x07 EB_VOLTAGE_OUTPUT ok (counter 184, status0 0x09, error 0x00)",
            "end board: write 0x1d EB_IO1_MODE ok (counter 15, status0 0x81, error 0x00)",
            "end board: read 0x03 EB_SW_VERSION = 0x0203 (counter 1, status0 0x09, error 0x00)",
            "MALFORMED: end-board reply shorter than its 8-byte header",
        ]
    );
}

#[test]
fn overlong_lines_and_bad_text_name_the_file_and_line() {
    let long = format!("0.0 > {}\n", "FF ".repeat(MAX_LINE / 3 + 10));
    let text = format!("0.000001 > FF 03 7F 7C\n{long}");
    let err = Replay::from_reader(text.as_bytes(), "big.log", &ReplayOptions::default())
        .unwrap()
        .find_map(Result::err)
        .unwrap();
    assert_eq!(err.kind(), ErrorKind::BadInput);
    assert_eq!(
        err.to_string(),
        "big.log: line 2: longer than the limit of 64 KiB"
    );
    let err =
        Replay::from_reader(&b"\xFF\xFE\n"[..], "bin.log", &ReplayOptions::default()).unwrap_err();
    assert_eq!(err.to_string(), "bin.log: line 1: not UTF-8 text (byte 0)");
    let err = Replay::from_reader(&b"hello\n"[..], "x.log", &ReplayOptions::default()).unwrap_err();
    assert!(
        err.to_string()
            .starts_with("x.log: line 1: neither a candump"),
        "{err}"
    );
    let err =
        Replay::from_reader(&b"\n# only\n"[..], "e.log", &ReplayOptions::default()).unwrap_err();
    assert_eq!(
        err.to_string(),
        "e.log: empty capture: no frame or packet in it"
    );
}

#[test]
fn wck_noise_truncation_and_orphans_are_flagged() {
    let log =
        "0.1 < 12\n0.2 > 00 FF 03\n0.3 > FF 03 7F 7C\n0.4 < 12\n0.5 > FF 03 7F 7C\n0.6 > FF A0\n";
    let got: Vec<(u64, EntryKind, String)> = entries(
        log,
        ReplayOptions {
            side: Side::Host,
            ..ReplayOptions::default()
        },
    )
    .into_iter()
    .map(|e| (e.line, e.kind, e.text))
    .collect();
    let want: Vec<(u64, EntryKind, String)> = vec![
        (1, EntryKind::Unexpected, "UNEXPECTED: no command was waiting for a reply".into()),
        (2, EntryKind::Malformed, "MALFORMED: 1 byte outside a packet (no 0xFF header before)".into()),
        (2, EntryKind::Malformed, "MALFORMED: truncated packet: new header after 2 bytes of 4".into()),
        (3, EntryKind::Request, "position move servo 3 to 127 (torque 0)".into()),
        (4, EntryKind::Malformed, "MALFORMED: truncated reply to position move: 1 of 2 bytes before the next packet (line 5)".into()),
        (5, EntryKind::Request, "position move servo 3 to 127 (torque 0)".into()),
        (5, EntryKind::Missing, "NO REPLY to position move (none before the next packet (line 6))".into()),
        (6, EntryKind::Malformed, "MALFORMED: truncated packet: the capture ends after 2 bytes".into()),
    ];
    assert_eq!(got, want);
}

#[test]
fn wck_replies_split_over_reads_and_implausible_replies() {
    // A reply read one byte at a time; a passive reply without the echoed mode byte;
    // a packet written in two calls.
    let log = "0.1 > FF 03 7F 7C\n0.2 < 12\n0.3 < 7F\n0.4 > FF C3 10 53\n0.5 < 11 7F\n0.6 > FF A3\n0.7 > 00 23\n0.8 < 00 7F\n";
    let got: Vec<(u64, EntryKind, String, String)> = entries(log, ReplayOptions::default())
        .into_iter()
        .map(|e| (e.line, e.kind, e.bytes, e.text))
        .collect();
    let want: Vec<(u64, EntryKind, String, String)> = vec![
        (
            1,
            EntryKind::Request,
            "FF 03 7F 7C".into(),
            "position move servo 3 to 127 (torque 0)".into(),
        ),
        (
            2,
            EntryKind::Reply,
            "12 7F".into(),
            "load 18, position 127".into(),
        ),
        (
            4,
            EntryKind::Request,
            "FF C3 10 53".into(),
            "passive servo 3".into(),
        ),
        (
            5,
            EntryKind::Malformed,
            "11 7F".into(),
            "MALFORMED: passive: reply mode byte is 17, but 16 was sent".into(),
        ),
        (
            6,
            EntryKind::Request,
            "FF A3 00 23".into(),
            "status read servo 3".into(),
        ),
        (
            8,
            EntryKind::Reply,
            "00 7F".into(),
            "load 0, position 127".into(),
        ),
    ];
    assert_eq!(got, want);
}
