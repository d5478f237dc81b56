//! Bad input: exit code 2, a message naming the value, the allowed range and the
//! argument, nothing on stdout, and nothing opened (the port / bus named does not exist,
//! and the error is the validation one, not an I/O one).

#![allow(clippy::unwrap_used, clippy::panic)] // test helpers: a failed unwrap is a failed test

use crate::common;

use common::robobus;

const PORT: &str = "/nonexistent/ttyUSB9";

#[track_caller]
fn refused(args: &[&str], must_contain: &[&str]) {
    let r = robobus(args);
    assert_eq!(r.code, Some(2), "robobus {args:?}: {r:#?}");
    assert!(r.stdout.is_empty(), "robobus {args:?} printed {}", r.stdout);
    for s in must_contain {
        assert!(
            r.stderr.contains(s),
            "robobus {args:?}: stderr lacks {s:?}:\n{}",
            r.stderr
        );
    }
    assert!(
        !r.stderr.contains("No such file") && !r.stderr.contains("not yet available"),
        "robobus {args:?} got past validation:\n{}",
        r.stderr
    );
}

#[test]
fn wck_values_out_of_range_are_refused_before_anything_is_opened() {
    for dry in [false, true] {
        let mut base = vec!["wck", "--port", PORT];
        if dry {
            base.push("--dry-run");
        }
        let with = |rest: &[&'static str]| {
            let mut v = base.clone();
            v.extend_from_slice(rest);
            v
        };
        refused(
            &with(&["move", "31", "127"]),
            &["'31'", "<ID>", "servo id 31", "0..=30"],
        );
        refused(
            &with(&["move", "3", "255"]),
            &["<POSITION>", "position 255", "0..=254"],
        );
        refused(&with(&["move", "3", "1000"]), &["position 1000", "0..=254"]);
        refused(
            &with(&["move", "3", "12", "--torque", "5"]),
            &["--torque", "torque level 5", "0..=4"],
        );
        refused(
            &with(&["move10", "254", "0"]),
            &["extended servo id 254", "0..=253"],
        );
        refused(
            &with(&["move10", "3", "1024"]),
            &["10-bit position 1024", "0..=1023"],
        );
        refused(
            &with(&["wheel", "3", "cw", "16"]),
            &["<SPEED>", "wheel speed 16", "0..=15"],
        );
        refused(
            &with(&["set", "overload", "3", "1801"]),
            &["<MILLIAMPS>", "1801", "400..=1800"],
        );
        refused(
            &with(&["set", "speed", "3", "10", "19"]),
            &["<ACCEL>", "acceleration 19", "20..=100"],
        );
        refused(
            &with(&["set", "gains", "3", "0", "10"]),
            &["<P>", "P gain 0", "1..=254"],
        );
        refused(
            &with(&["set", "bounds", "3", "100", "50"]),
            &["<UPPER>", "lower 100", "upper 50"],
        );
        refused(
            &with(&["set", "io", "3", "4"]),
            &["<OUTPUTS>", "digital outputs 4", "0..=3"],
        );
        refused(
            &with(&["set-baud", "3", "19200"]),
            &["<RATE>", "19200", "115200"],
        );
        refused(
            &with(&["set-id", "3", "254"]),
            &["<NEW_ID>", "254", "0..=253"],
        );
        refused(
            &with(&["status", "0-31"]),
            &["<IDS>", "servo ID 31", "0..=30"],
        );
        refused(&with(&["status", "5-2"]), &["<IDS>", "backwards"]);
        refused(
            &with(&["move", "3", "x"]),
            &["<POSITION>", "`x` is not a whole number"],
        );
        refused(
            &with(&["teach", "0", "--rate-hz", "500"]),
            &["--rate-hz", "500", "0.1..=200"],
        );
    }
    refused(
        &["wck", "--port", PORT, "--baud", "1234", "brake"],
        &["--baud", "1234"],
    );
    for margin in ["abc", "10001", "1.5"] {
        refused(
            &["wck", "--port", PORT, "--reply-margin", margin, "brake"],
            &["--reply-margin", margin, "0..=10000"],
        );
    }
    let many: Vec<String> = (0..32).map(|_| "127".to_owned()).collect();
    let mut args = vec!["wck", "--port", PORT, "sync-move"];
    args.extend(many.iter().map(String::as_str));
    refused(&args, &["<POSITIONS>"]);
}

#[test]
fn whj_values_out_of_range_are_refused_before_anything_is_opened() {
    for dry in [false, true] {
        let mut base = vec!["whj", "--bus", "vcan99"];
        if dry {
            base.push("--dry-run");
        }
        let with = |rest: &[&'static str]| {
            let mut v = base.clone();
            v.extend_from_slice(rest);
            v
        };
        refused(
            &with(&["enable", "0"]),
            &["<JOINTS>", "joint ID 0", "1..=30"],
        );
        refused(&with(&["enable", "31"]), &["joint ID 31", "1..=30"]);
        refused(
            &with(&["move", "1", "400"]),
            &["<DEGREES>", "400", "-360..=360"],
        );
        refused(
            &with(&["move", "1", "10", "--max-speed", "500"]),
            &["--max-speed", "500", "0.1..=180"],
        );
        refused(
            &with(&["speed", "1", "-38"]),
            &["<RPM>", "-38", "-37.5..=37.5"],
        );
        refused(&with(&["current", "1", "40000"]), &["<MILLIAMPS>", "40000"]);
        refused(
            &with(&["read", "1", "0x92"]),
            &["<REGISTER>", "0x92", "0x00..=0x91"],
        );
        refused(
            &with(&["read", "1", "no_such_reg"]),
            &["<REGISTER>", "no_such_reg"],
        );
        refused(
            &with(&["write", "1", "sys_id", "40"]),
            &["SYS_ID", "40", "1..=30"],
        );
        refused(&with(&["write", "1", "cur_position", "1"]), &["read-only"]);
        refused(&with(&["set-id", "1", "31"]), &["<NEW_ID>", "31", "1..=30"]);
        refused(
            &with(&["wave", "1", "--amplitude", "300", "--offset", "100"]),
            &["--offset", "--amplitude", "400"],
        );
        refused(
            &with(&["wave", "1", "--amplitude", "1", "--frequency", "100"]),
            &["--frequency", "100", "0.01..="],
        );
        refused(&with(&["mode", "1", "torque"]), &["torque", "position"]);
        // Broadcast: joints 1..=7 only, one joint without it, end-board registers checked.
        refused(
            &with(&["read", "--broadcast", "1-8", "sys_temp"]),
            &["--broadcast JOINTS", "8", "1..=7"],
        );
        refused(
            &with(&["read", "1-2", "sys_temp"]),
            &["one joint", "--broadcast"],
        );
        refused(
            &with(&[
                "read",
                "--broadcast",
                "1",
                "sys_temp",
                "--end-board",
                "0x80",
            ]),
            &["--end-board", "0x80", "0x00..=0x7F"],
        );
        refused(
            &with(&[
                "write",
                "--broadcast",
                "1",
                "tag_work_mode",
                "3",
                "--end-board",
                "eb_sw_version=1",
            ]),
            &["--end-board", "EB_SW_VERSION", "not a writable"],
        );
        refused(
            &with(&["write", "--broadcast", "1-2", "sys_dema_abspos", "1"]),
            &["SYS_DEMA_ABSPOS", "never"],
        );
        for (extra, want) in [
            (["--mode", "speed"], ["--broadcast", "speed", "0x2F"]),
            (["--rate-hz", "50"], ["--rate-hz", "50", "100..=1000"]),
        ] {
            let mut args = with(&["wave", "1", "--amplitude", "1", "--broadcast"]);
            args.extend_from_slice(&extra);
            refused(&args, &want);
        }
    }
    refused(
        &["whj", "--bus", "udp:1.2.3.4:5", "--dry-run", "enable", "1"],
        &["--bus", "multicast"],
    );
    // Current scaling needs the model in a dry run.
    refused(&["whj", "--dry-run", "current", "1", "100"], &["--model"]);
}

#[test]
fn execution_opens_the_port_and_names_it_when_it_is_missing() {
    // wCK runs through the client: a port that does not exist is "no device" (exit 3),
    // and the message names the path.
    let r = robobus(&["wck", "--port", PORT, "move", "3", "127"]);
    assert_eq!(r.code, Some(3), "{r:#?}");
    assert!(r.stderr.contains(PORT), "{}", r.stderr);
    assert!(r.stderr.contains("does not exist"), "{}", r.stderr);
    // WHJ runs through the client too: a SocketCAN interface that does not exist is
    // "no device" (exit 3) on a kernel with SocketCAN, "not available" (4) on one without
    // (see `socketcan_on_a_kernel_without_it_is_exit_4_naming_the_interface`), and the
    // message names it.
    let r = robobus(&["whj", "--bus", "vcan99", "enable", "1"]);
    assert_eq!(r.code, Some(missing_can_interface()), "{r:#?}");
    assert!(r.stderr.contains("vcan99"), "{}", r.stderr);
    // Without --dry-run the port / bus is required.
    let r = robobus(&["wck", "move", "3", "127"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("--port"), "{}", r.stderr);
    let r = robobus(&["whj", "enable", "1"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("--bus"), "{}", r.stderr);
}

/// The exit code of opening a SocketCAN interface that does not exist: 3 (no device) on a
/// kernel with SocketCAN, 4 (not available) on one without.
#[cfg(target_os = "linux")]
fn missing_can_interface() -> i32 {
    if robobus_link::socketcan::kernel_has_can() {
        3
    } else {
        4
    }
}

/// The exit code of opening a SocketCAN interface: 4 (not available) where SocketCAN does
/// not exist.
#[cfg(not(target_os = "linux"))]
const fn missing_can_interface() -> i32 {
    4
}

/// Exit code 4 end to end: a SocketCAN bus on a kernel without SocketCAN (`socket(AF_CAN)`
/// fails with EAFNOSUPPORT, as on the development machine, whose CAN tests run in
/// User-Mode Linux). Nothing is opened; the message names the interface and says what
/// is missing. On a kernel with SocketCAN the same command is a missing interface (3).
#[cfg(target_os = "linux")]
#[test]
fn socketcan_on_a_kernel_without_it_is_exit_4_naming_the_interface() {
    let r = robobus(&["whj", "--bus", "vcan0", "status", "1"]);
    assert!(r.stdout.is_empty(), "{r:#?}");
    assert!(r.stderr.contains("vcan0"), "{}", r.stderr);
    if robobus_link::socketcan::kernel_has_can() {
        assert_eq!(r.code, Some(3), "{r:#?}");
        assert!(r.stderr.contains("ip link"), "{}", r.stderr);
    } else {
        assert_eq!(r.code, Some(4), "{r:#?}");
        assert!(
            r.stderr.contains("no SocketCAN support") && r.stderr.contains("EAFNOSUPPORT"),
            "{}",
            r.stderr
        );
    }
}

/// Exit code 4 end to end where SocketCAN does not exist (Windows, macOS): nothing is
/// opened, and the message names the interface and that SocketCAN is Linux's.
#[cfg(not(target_os = "linux"))]
#[test]
fn socketcan_on_a_system_without_it_is_exit_4_naming_the_interface() {
    let r = robobus(&["whj", "--bus", "vcan0", "status", "1"]);
    assert!(r.stdout.is_empty(), "{r:#?}");
    assert_eq!(r.code, Some(4), "{r:#?}");
    assert!(
        r.stderr.contains("vcan0") && r.stderr.contains("Linux"),
        "{}",
        r.stderr
    );
}

#[test]
fn memory_rewrites_need_confirmation_without_a_terminal() {
    // stdin of a test is not a terminal: without --yes the command is refused (exit 2)...
    for (args, next) in [
        (&["wck", "--port", PORT, "set-id", "3", "4"][..], 3),
        (
            &["wck", "--port", PORT, "set", "gains", "3", "30", "20"][..],
            3,
        ),
        (
            &["whj", "--bus", "vcan99", "save", "1"][..],
            missing_can_interface(),
        ),
    ] {
        let r = robobus(args);
        assert_eq!(r.code, Some(2), "{args:?}: {r:#?}");
        assert!(r.stderr.contains("--yes"), "{}", r.stderr);
        // ...and with --yes it gets as far as opening the (missing) port or interface.
        let mut yes = args.to_vec();
        yes.push("--yes");
        assert_eq!(robobus(&yes).code, Some(next), "{yes:?}");
    }
    // Runtime settings and motion need no confirmation: straight to the (missing) port.
    let r = robobus(&[
        "wck",
        "--port",
        PORT,
        "set",
        "gains",
        "3",
        "30",
        "20",
        "--runtime",
    ]);
    assert_eq!(r.code, Some(3), "{r:#?}");
    assert!(r.stderr.contains(PORT), "{}", r.stderr);
}

#[test]
fn negative_values_get_the_range_error_not_an_unknown_flag() {
    refused(
        &["wck", "--port", PORT, "move", "3", "-1"],
        &["position -1 is out of range 0..=254", "<POSITION>"],
    );
    refused(
        &["wck", "--port", PORT, "wheel", "1", "ccw", "-3"],
        &["wheel speed -3 is out of range 0..=15", "<SPEED>"],
    );
    refused(&["wck", "--port", PORT, "status", "-2"], &["-2"]);
}

#[test]
fn empty_items_of_an_id_list_are_refused() {
    refused(
        &["wck", "--port", PORT, "status", "1,,2"],
        &["item 2 is empty"],
    );
    refused(
        &["whj", "--bus", "udp", "status", "1,"],
        &["item 2 is empty"],
    );
}

#[test]
fn under_json_an_error_is_json_with_its_kind() {
    let r = robobus(&["--json", "wck", "--port", PORT, "status", "1"]);
    assert_eq!(r.code, Some(3), "{r:#?}");
    let v: serde_json::Value = serde_json::from_str(r.stderr.trim()).unwrap();
    assert_eq!(v["error"]["kind"], "no-device", "{v}");
    assert_eq!(v["error"]["exit_code"], 3, "{v}");
    assert!(
        v["error"]["message"].as_str().unwrap().contains(PORT),
        "{v}"
    );
    // A refused value under --json: bad input, exit 2.
    let r = robobus(&[
        "--json",
        "whj",
        "--bus",
        "udp",
        "--dry-run",
        "move",
        "1",
        "30",
        "--rate-hz",
        "0",
    ]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    let v: serde_json::Value = serde_json::from_str(r.stderr.trim()).unwrap();
    assert_eq!(v["error"]["kind"], "bad-input", "{v}");
}

#[test]
fn missing_files_and_folders_are_bad_input_before_any_work() {
    refused(
        &[
            "plot",
            "/nonexistent/run.csv",
            "-o",
            "/tmp/robobus-plot.svg",
        ],
        &["/nonexistent/run.csv: no such file"],
    );
    refused(
        &[
            "plot",
            "/nonexistent/run.csv",
            "-o",
            "/nonexistent/dir/x.svg",
        ],
        &["--output /nonexistent/dir/x.svg", "does not exist"],
    );
    // The demo checks its plot path before it runs (it would otherwise fail at the end).
    let start = std::time::Instant::now();
    refused(
        &["demo", "--plot", "/nonexistent/dir/x.svg"],
        &["--plot /nonexistent/dir/x.svg", "does not exist"],
    );
    assert!(start.elapsed() < std::time::Duration::from_secs(3));
}

#[test]
fn fault_error_masks_need_their_hex_prefix() {
    refused(
        &[
            "--dry-run",
            "sim",
            "whj",
            "--bus",
            "udp",
            "--fault-error",
            "2:4000@1",
        ],
        &["need the 0x prefix", "--fault-error"],
    );
}

#[test]
fn a_huge_value_is_named_not_echoed_whole() {
    let huge = "9".repeat(100_000);
    let r = robobus(&["wck", "--port", PORT, "move", "3", &huge]);
    assert_eq!(r.code, Some(2), "exit");
    assert!(
        r.stderr.len() < 1000,
        "{} bytes of error text",
        r.stderr.len()
    );
    assert!(r.stderr.contains("(100002 characters)"), "{}", r.stderr);
    assert!(r.stdout.is_empty());
}

#[test]
fn simulator_values_have_ranges() {
    refused(
        &["sim", "whj", "--bus", "udp", "--current-noise-ma", "1e308"],
        &["--current-noise-ma", "allowed: 0..=10000"],
    );
    refused(
        &["sim", "whj", "--bus", "udp", "--initial-deg", "400"],
        &["--initial-deg 400", "allowed: -360..=360"],
    );
}

#[test]
fn a_dry_run_of_a_simulator_opens_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("wck0");
    let r = robobus(&[
        "--dry-run",
        "sim",
        "wck",
        "--servos",
        "0-5",
        "--link",
        link.to_str().unwrap(),
    ]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    assert!(r.stdout.contains("would serve 6 simulated wCK"), "{r:#?}");
    assert!(!link.exists(), "a dry run made the link");
    // (The UDP bus is multicast: a dry run must not join it, here in the machine's own
    // network namespace.)
    let r = robobus(&["--dry-run", "sim", "whj", "--bus", "udp", "--joints", "1-7"]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    assert!(r.stdout.contains("nothing opened"), "{r:#?}");
}
