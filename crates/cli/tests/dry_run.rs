//! `--dry-run` prints exactly the bytes / frames of the manuals' examples, and nothing is
//! opened: every run names a port or bus that does not exist.

#![allow(clippy::unwrap_used, clippy::panic)] // test helpers: a failed unwrap is a failed test

use crate::common;

use common::{lines, ok, robobus};

const PORT: &str = "/nonexistent/ttyUSB9";

fn wck(args: &[&str]) -> Vec<String> {
    let mut all = vec!["wck", "--port", PORT, "--dry-run"];
    all.extend_from_slice(args);
    lines(&ok(&all)).into_iter().map(str::to_owned).collect()
}

fn whj(args: &[&str]) -> Vec<String> {
    let mut all = vec!["whj", "--bus", "vcan99", "--dry-run"];
    all.extend_from_slice(args);
    lines(&ok(&all)).into_iter().map(str::to_owned).collect()
}

#[test]
fn wck_packets_match_the_manual_a1_examples() {
    // (subcommand, packet as the manual's appendix A-1 prints it, corrected checksums)
    let cases: &[(&[&str], &str)] = &[
        (&["move", "3", "127"], "FF 03 7F 7C"),
        (&["move", "0", "127"], "FF 00 7F 7F"),
        (&["sync-move", "127", "127"], "FF 1F 02 7F 7F 00"),
        (&["status", "0"], "FF A0 00 20"),
        (&["passive", "0"], "FF C0 10 50"),
        (&["wheel", "0", "ccw", "15"], "FF C0 3F 7F"),
        (&["brake"], "FF DF 20 7F"),
        (&["set-baud", "0", "115200"], "FF E0 08 07 07 68"),
        (&["set", "gains", "0", "100", "100"], "FF E0 09 64 64 69"),
        (&["get", "gains", "0"], "FF E0 0A 00 00 6A"),
        (&["set", "i-gain", "0", "100"], "FF E0 15 64 64 75"),
        (&["get", "i-gain", "0"], "FF E0 16 00 00 76"),
        (
            &["set", "gains", "0", "100", "100", "--runtime"],
            "FF E0 0B 64 64 6B",
        ),
        (
            &["set", "i-gain", "0", "4", "--runtime"],
            "FF E0 18 04 04 78",
        ),
        (&["set-id", "0", "30"], "FF E0 0C 1E 1E 6C"),
        (&["set", "speed", "0", "30", "100"], "FF E0 0D 1E 64 17"),
        (&["get", "speed", "0"], "FF E0 0E 00 00 6E"),
        (
            &["set", "speed", "0", "30", "100", "--runtime"],
            "FF E0 17 1E 64 0D",
        ),
        (&["set", "overload", "0", "1000"], "FF E0 0F 68 68 6F"),
        (&["get", "overload", "0"], "FF E0 10 00 00 70"),
        (&["set", "bounds", "0", "50", "100"], "FF E0 11 32 64 27"),
        (&["get", "bounds", "0"], "FF E0 12 00 00 72"),
        (&["set", "io", "0", "3"], "FF E0 64 03 03 04"),
        (&["get", "io", "0"], "FF E0 65 00 00 05"),
        (&["program", "download", "0"], "FF E0 97 00 00 77"),
        (&["move10", "0", "1000"], "FF E0 C8 00 00 07 D0 7F"),
        (&["read10", "0"], "FF E0 C9 00 00 29"),
    ];
    for (args, packet) in cases {
        assert_eq!(wck(args), [*packet], "robobus wck --dry-run {args:?}");
    }
}

#[test]
fn wck_program_upload_matches_the_manual_a1_24_example() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("swing.wck");
    std::fs::write(
        &file,
        "# the manual's A-1 (24) example\nmove 82 torque 0\ndelay 266ms\nmove 172 torque 0\ndelay 266ms\n",
    )
    .unwrap();
    let f = file.to_str().unwrap();
    let expected = "FF E0 96 04 10 52 31 0A 10 AC 31 0A 0C";
    assert_eq!(wck(&["program", "upload", "0", f]), [expected]);
    // `program check` needs no port at all and prints the same packet.
    let out = ok(&["wck", "program", "check", f]);
    assert_eq!(lines(&out), [expected]);
    assert!(out.contains("4 instruction(s)"), "{out}");
    assert!(out.contains("10 52  move 82 torque 0"), "{out}");
}

#[test]
fn wck_program_check_reports_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bad.wck");
    std::fs::write(&file, "move 82 torque 0\ndelay 266ms\nmove 300 torque 0\n").unwrap();
    let r = robobus(&["wck", "program", "check", file.to_str().unwrap()]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("bad.wck:3:6:"), "{}", r.stderr);
    assert!(r.stderr.contains("300"), "{}", r.stderr);
    assert!(r.stdout.is_empty());
}

#[test]
fn wck_scan_reads_every_id_and_all_bauds_switch_rates() {
    // The dry-run assumes that nobody answers: each ID is read twice (the real run's
    // second probe of a silent ID), as the plan's note says.
    let packets = wck(&["scan"]);
    assert_eq!(packets.len(), 62);
    assert_eq!(packets[0], "FF A0 00 20");
    assert_eq!(packets[1], "FF A0 00 20");
    let out = ok(&["wck", "--dry-run", "scan", "--all-bauds", "--ids", "0-1"]);
    assert!(out.contains("2 times if it stays silent"), "{out}");
    assert_eq!(lines(&out).len(), 32);
    assert!(out.contains("# 4800 bit/s\nFF A0 00 20\n"), "{out}");
    assert!(out.contains("# 921600 bit/s\n"), "{out}");
}

#[test]
fn global_options_go_before_or_after_the_subcommand() {
    let before = ok(&["--dry-run", "wck", "--port", PORT, "move", "3", "127"]);
    let after = ok(&["wck", "move", "3", "127", "--port", PORT, "--dry-run"]);
    assert_eq!(before, "FF 03 7F 7C\n");
    assert_eq!(after, before);
}

#[test]
fn whj_raw_writes_refuse_fractions() {
    // LIT_MAX_ACC (0x42), a plain register.
    let r = robobus(&["whj", "--dry-run", "write", "1", "0x42", "1.5", "--raw"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("not a whole number"), "{}", r.stderr);
}

#[test]
fn wck_json_form_is_machine_readable() {
    let out = ok(&[
        "wck",
        "--port",
        PORT,
        "--dry-run",
        "--json",
        "move",
        "3",
        "127",
    ]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    // The library's plan: the operation, then each packet with its rate and bytes.
    assert_eq!(v["op"], "wck.move");
    assert_eq!(v["family"], "wck");
    let p = &v["steps"][0];
    assert_eq!(p["line"], "FF 03 7F 7C");
    assert_eq!(p["bytes"], serde_json::json!([255, 3, 127, 124]));
    assert_eq!(p["what"], "position move servo 3");
    assert_eq!(p["baud"], 115_200);
}

#[test]
fn wck_play_interpolates_keyframes_into_sync_moves() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("wave.motion");
    std::fs::write(
        &file,
        "# two servos\ntorque 1\npose 500 100 200\npose 100 120 180\nhold 40\npose 0 0 0\n",
    )
    .unwrap();
    let f = file.to_str().unwrap();
    // 50 Hz: 20 ms period; the 100 ms transition takes 5 steps of 4 counts. Right after
    // the first move at or past 200 ms and past 600 ms, a status read watches servo 0,
    // then servo 1 (moves have no reply).
    let packets = wck(&["play", f]);
    let expect = |a: u8, b: u8| format!("FF 3F 02 {a:02X} {b:02X} {:02X}", (a ^ b) & 0x7F);
    assert_eq!(
        packets,
        [
            expect(100, 200),
            expect(104, 196),
            "FF A0 00 20".to_string(),
            expect(108, 192),
            expect(112, 188),
            expect(116, 184),
            expect(120, 180),
            "FF A1 00 21".to_string(),
            expect(0, 0),
        ]
    );
    let out = ok(&["wck", "--dry-run", "--json", "play", f]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let times: Vec<f64> = v["steps"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|p| p["t_ms"].as_f64())
        .collect();
    assert_eq!(times, [0.0, 520.0, 540.0, 560.0, 580.0, 600.0, 640.0]);
}

#[test]
fn wck_play_errors_point_into_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bad.motion");
    std::fs::write(&file, "pose 0 1 2\npose 100 1 2 3\n").unwrap();
    let r = robobus(&["wck", "--dry-run", "play", file.to_str().unwrap()]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("bad.motion:2:1:"), "{}", r.stderr);
    assert!(r.stderr.contains("3 servos"), "{}", r.stderr);
}

#[test]
fn whj_frames_match_the_usage_demo() {
    let cases: &[(&[&str], &[&str])] = &[
        (&["enable", "1"], &["001##1020A01"]),
        (&["disable", "1"], &["001##1020A00"]),
        (&["mode", "1", "position"], &["001##1023003"]),
        (&["release-iap", "1"], &["001##1024900"]),
        (&["clear", "1"], &["001##1020F01"]),
        (&["zero", "1"], &["001##1020E01"]),
        (&["save", "1"], &["001##1020C01"]),
        (&["status", "1"], &["601##1"]),
        // One 0x7F frame, reply mask 1 (J1-J4) covering J1-J3.
        (
            &["status", "1-3", "--broadcast"],
            &["07F##1000000000000000000000000000000000000000000000001"],
        ),
        (&["read", "1", "cur_position"], &["001##1011402"]),
        (&["read", "1", "0x06"], &["001##1010601"]),
        (
            &["enable", "1-3"],
            &["001##1020A01", "002##1020A01", "003##1020A01"],
        ),
        (&["speed", "2", "1"], &["302##1F4010000"]),
        (
            &["speed", "2", "1", "--duration", "2"],
            &["302##1F4010000", "302##100000000"],
        ),
        (
            &["--model", "whj30", "write", "1", "lit_max_current", "5000"],
            &["001##102408813"],
        ),
    ];
    for (args, frames) in cases {
        assert_eq!(whj(args), *frames, "robobus whj --dry-run {args:?}");
    }
    // The usage demo's `02 36 E0 93 04 00` (TAG_POSITION := 30 deg) is a motion target: a
    // register write of it would jump past the step limit, so it is refused, dry run or
    // not, with a pointer to `whj move` (whose last frame carries the same 30 deg).
    for args in [
        &["whj", "--dry-run", "write", "1", "tag_position", "30"][..],
        &["whj", "--dry-run", "write", "1", "0x36", "300000", "--raw"][..],
    ] {
        let r = robobus(args);
        assert_eq!(r.code, Some(2), "{r:#?}");
        assert!(r.stderr.contains("whj move"), "{}", r.stderr);
        assert!(r.stdout.is_empty(), "{}", r.stdout);
    }
    let r = robobus(&["whj", "--dry-run", "write", "1", "SYS_DEMA_ABSPOS", "1"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("never to write"), "{}", r.stderr);
}

#[test]
fn whj_move_steps_to_the_target_and_ends_on_it() {
    // The plan is the library's smooth profile (the one a real run sends): a status query
    // (the real run plans from the position it reads), then one frame per period, never
    // faster than --max-speed, the last exactly on the target.
    // 0 -> 0.2 deg at 10 deg/s (acceleration 40 deg/s^2), 100 Hz: the speed changes by
    // 0.4 deg/s a frame, so the move is 50 units of 0.004 deg; speeds of 1, 2, .., 7, .., 1
    // units cover 49, one more frame the 50th: 14 frames.
    let frames = whj(&["move", "1", "0.2", "--from", "0", "--rate-hz", "100"]);
    assert_eq!(frames.len(), 1 + 14, "{frames:?}");
    assert_eq!(frames[0], "601##1");
    assert_eq!(frames.last().unwrap(), "201##1D0070000");
    // The usage demo's 30 deg target: E0 93 04 00 ends the move. 20 deg/s (80 deg/s^2) at
    // 200 Hz: 0.4 deg/s a frame, 0.1 deg = 50 units of 0.002 deg: again 14 frames.
    let frames = whj(&[
        "move",
        "1",
        "30",
        "--from",
        "29.9",
        "--max-speed",
        "20",
        "--rate-hz",
        "200",
    ]);
    assert_eq!(frames.last().unwrap(), "201##1E0930400");
    assert_eq!(frames.len(), 1 + 14, "{frames:?}");
    // Without --from the dry run says what it assumed.
    let out = ok(&["whj", "--dry-run", "move", "1", "1"]);
    assert!(out.contains("# start angle assumed 0 deg"), "{out}");
    // Too fast for the step limit at this rate: split into smaller steps, said plainly.
    let out = ok(&[
        "whj",
        "--dry-run",
        "move",
        "1",
        "30",
        "--max-speed",
        "180",
        "--rate-hz",
        "1",
    ]);
    assert!(out.contains("split into smaller steps"), "{out}");
}

#[test]
fn whj_wave_has_one_frame_per_period() {
    let out = ok(&[
        "whj",
        "--dry-run",
        "--json",
        "wave",
        "1",
        "--amplitude",
        "4",
        "--frequency",
        "1",
        "--duration",
        "1",
        "--rate-hz",
        "4",
    ]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let frames = v["steps"].as_array().unwrap();
    let lines: Vec<&str> = frames.iter().map(|f| f["line"].as_str().unwrap()).collect();
    // A status query first (a real run starts the step limiter where the joint is), then
    // sin at 0, 90, 180, 270 degrees of phase: 0, +4, 0, -4 degrees (4 deg per frame is
    // within the step limit, so nothing is clamped).
    assert_eq!(
        lines,
        [
            "601##1",
            "201##100000000",
            "201##1409C0000",
            "201##100000000",
            "201##1C063FFFF"
        ]
    );
    let t: Vec<Option<f64>> = frames.iter().map(|f| f["t_ms"].as_f64()).collect();
    assert_eq!(t, [None, Some(0.0), Some(250.0), Some(500.0), Some(750.0)]);
}

#[test]
fn wck_timed_wheel_shows_the_watch_reads_and_the_stop() {
    let out = ok(&[
        "wck",
        "--port",
        PORT,
        "--dry-run",
        "--json",
        "wheel",
        "1",
        "ccw",
        "10",
        "--duration",
        "0.5",
        "--on-stop",
        "hold",
    ]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let packets = v["steps"].as_array().unwrap();
    let seen: Vec<(Option<f64>, &str)> = packets
        .iter()
        .map(|p| (p["t_ms"].as_f64(), p["what"].as_str().unwrap()))
        .collect();
    assert_eq!(seen.len(), 6, "{out}");
    assert_eq!(seen[0].0, Some(0.0));
    assert_eq!(seen[1].0, Some(200.0));
    assert_eq!(seen[2].0, Some(400.0));
    assert_eq!(seen[3].0, Some(500.0));
    assert_eq!(seen[1].1, seen[3].1, "status reads");
    assert_eq!(seen[4], (None, "position move servo 1"));
    // Then where the shaft came to rest.
    assert_eq!(seen[5], (None, seen[1].1));
    let notes = v["notes"].to_string();
    assert!(notes.contains("assumed 127"), "{notes}");
}

#[test]
fn whj_wave_from_plans_the_step_limiter_from_that_angle() {
    let first_target = |extra: &[&str]| {
        let mut args = vec![
            "whj",
            "--bus",
            "udp",
            "--dry-run",
            "--json",
            "wave",
            "1",
            "--amplitude",
            "5",
            "--frequency",
            "0.5",
            "--duration",
            "0.1",
        ];
        args.extend_from_slice(extra);
        let v: serde_json::Value = serde_json::from_str(&ok(&args)).unwrap();
        v
    };
    let at_zero = first_target(&[]);
    assert!(at_zero.to_string().contains("assumed 0 deg"), "{at_zero}");
    let at_thirty = first_target(&["--from", "30"]);
    assert!(!at_thirty.to_string().contains("assumed"), "{at_thirty}");
    // The limiter starts at 30 deg and steps towards the wave (at 0 deg at t = 0).
    assert_ne!(at_zero["steps"], at_thirty["steps"]);
}
