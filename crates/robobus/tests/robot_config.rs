//! The robot file: parsing errors name the line, the field and the value; value checks
//! name the joint or bus.

#![allow(clippy::unwrap_used)]

use robobus::ops::SafeState;
use robobus::robot::{BusConfig, Robot, RobotConfig, RobotError};

const GOOD: &str = r#"
watchdog_timeout = 0.05

[buses.legs]
kind = "wck"
port = "/dev/ttyUSB7"
baud = 57600
torque = 1
safe_state = "break"

[buses.arm]
kind = "whj-udp"
port = 43999

[[joints]]
name = "knee"
bus = "legs"
id = 3
offset = 0.1
direction = -1
limits = [-1.0, 1.5]
max_velocity = 2.0
max_acceleration = 20.0
centre = 120

[[joints]]
name = "shoulder"
bus = "arm"
id = 1
limits = [-0.5, 0.5]
max_velocity = 0.5
max_acceleration = 2.0
"#;

#[test]
fn a_complete_file_parses_with_defaults_filled_in() {
    let c = RobotConfig::from_toml_str(GOOD).unwrap();
    assert_eq!(c.watchdog().as_millis(), 50);
    assert_eq!(
        c.buses["legs"],
        BusConfig::Wck {
            port: "/dev/ttyUSB7".into(),
            baud: 57_600,
            torque: 1,
            safe_state: SafeState::Break,
        }
    );
    assert_eq!(
        c.buses["arm"],
        BusConfig::WhjUdp {
            group: None,
            port: Some(43_999),
            safe_state: SafeState::Hold,
        }
    );
    let knee = &c.joints[0];
    assert_eq!(
        (knee.id, knee.direction, knee.centre, knee.limits),
        (3, -1, Some(120), [-1.0, 1.5])
    );
    let shoulder = &c.joints[1];
    assert_eq!((shoulder.direction, shoulder.offset), (1, 0.0));
}

fn err(text: &str) -> String {
    RobotConfig::from_toml_str(text).unwrap_err().to_string()
}

#[test]
fn a_misspelt_field_names_the_field_and_its_line() {
    let text = GOOD.replace("max_velocity = 0.5", "max_speed = 0.5");
    let line = text.lines().position(|l| l.contains("max_speed")).unwrap() + 1;
    let e = RobotConfig::from_toml_str(&text).unwrap_err();
    let RobotError::Parse { line: at, .. } = &e else {
        panic!("{e:?}");
    };
    let msg = e.to_string();
    assert!(msg.contains("max_speed"), "{msg}");
    // The unknown key is reported at its line or at its table's header just above.
    assert!(
        (line - 8..=line).contains(at),
        "line {at}, expected near {line}: {msg}"
    );
}

#[test]
fn a_syntax_error_gives_the_exact_line() {
    let text = GOOD.replace("id = 3", "id = = 3");
    let line = text.lines().position(|l| l.contains("= = 3")).unwrap() + 1;
    match RobotConfig::from_toml_str(&text).unwrap_err() {
        RobotError::Parse { line: at, .. } => assert_eq!(at, line),
        other => panic!("{other:?}"),
    }
}

#[test]
fn missing_and_mistyped_fields_are_named() {
    let msg = err(&GOOD.replace("limits = [-0.5, 0.5]\n", ""));
    assert!(msg.contains("limits"), "{msg}");
    let msg = err(&GOOD.replace("id = 1\n", "id = \"one\"\n"));
    assert!(msg.contains("line"), "{msg}");
    let msg = err(&GOOD.replace("kind = \"whj-udp\"", "kind = \"whj-serial\""));
    assert!(msg.contains("whj-serial"), "{msg}");
}

#[test]
fn value_errors_name_the_joint_the_field_and_the_value() {
    let cases = [
        (
            GOOD.replace("direction = -1", "direction = 2"),
            ["joint knee", "direction = 2", "1 or -1"],
        ),
        (
            GOOD.replace("limits = [-0.5, 0.5]", "limits = [0.5, -0.5]"),
            ["joint shoulder", "limits", "min <= max"],
        ),
        (
            GOOD.replace("bus = \"arm\"", "bus = \"torso\""),
            ["joint shoulder", "torso", "arm, legs"],
        ),
        (
            GOOD.replace("max_acceleration = 2.0", "max_acceleration = 0.0"),
            ["joint shoulder", "max_acceleration = 0", "> 0"],
        ),
        (
            GOOD.replace("id = 1\n", "id = 0\n"),
            ["joint shoulder", "id = 0", "1..=30 (WHJ)"],
        ),
        (
            GOOD.replace("id = 3", "id = 31"),
            ["joint knee", "id = 31", "0..=30 (wCK)"],
        ),
        (
            GOOD.replace("name = \"shoulder\"", "name = \"knee\""),
            ["joint knee", "name = knee", "used once"],
        ),
        (
            GOOD.replace("safe_state = \"break\"", "safe_state = \"hold\""),
            ["bus legs", "safe_state = hold", "passive"],
        ),
        (
            GOOD.replace("torque = 1", "torque = 5"),
            ["bus legs", "torque = 5", "0..=4"],
        ),
        (
            GOOD.replace("watchdog_timeout = 0.05", "watchdog_timeout = 0"),
            ["watchdog_timeout = 0", "0.001", "s"],
        ),
    ];
    for (text, needles) in cases {
        let msg = err(&text);
        for n in needles {
            assert!(msg.contains(n), "{n:?} missing in {msg}");
        }
    }
}

#[test]
fn wck_limits_beyond_the_servo_range_are_refused_with_the_range() {
    // Centre 120, offset 0.1, reversed: the servo reaches about -2.30..=2.10 rad.
    let msg = err(&GOOD.replace("limits = [-1.0, 1.5]", "limits = [-1.0, 2.5]"));
    assert!(
        msg.contains("joint knee") && msg.contains("[-1, 2.5]") && msg.contains("centre 120"),
        "{msg}"
    );
    let range = msg.split("reach: ").nth(1).unwrap();
    let (lo, hi) = range.split_once("..=").unwrap();
    let hi: f64 = hi.split(' ').next().unwrap().parse().unwrap();
    let lo: f64 = lo.parse().unwrap();
    let step = (269.0_f64 / 255.0).to_radians();
    assert!((lo - (0.1 - 134.0 * step)).abs() < 1e-3, "{lo}");
    assert!((hi - (0.1 + 120.0 * step)).abs() < 1e-3, "{hi}");
}

#[test]
fn a_missing_file_names_the_path() {
    let msg = RobotConfig::from_toml_file("/nonexistent/robot.toml")
        .unwrap_err()
        .to_string();
    assert!(msg.contains("/nonexistent/robot.toml"), "{msg}");
}

#[test]
fn the_sample_robot_file_parses() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/robot.toml");
    let c = RobotConfig::from_toml_file(path).unwrap();
    assert!(c.joints.len() >= 2);
    assert!(c.buses.values().any(BusConfig::is_wck));
    assert!(c.buses.values().any(|b| !b.is_wck()));
}

#[test]
fn external_buses_must_be_supplied() {
    let text = r#"
        [buses.sim]
        kind = "whj-external"
        [[joints]]
        name = "j1"
        bus = "sim"
        id = 1
        limits = [-1.0, 1.0]
        max_velocity = 1.0
        max_acceleration = 1.0
    "#;
    let msg = Robot::from_toml_str(text).unwrap_err().to_string();
    assert!(
        msg.contains("bus sim") && msg.contains("whj-external") && msg.contains("whj_bus"),
        "{msg}"
    );
}

#[test]
fn opening_a_missing_port_names_the_bus_and_the_port() {
    let text = r#"
        [buses.legs]
        kind = "wck"
        port = "/nonexistent/tty"
        [[joints]]
        name = "knee"
        bus = "legs"
        id = 0
        limits = [-1.0, 1.0]
        max_velocity = 1.0
        max_acceleration = 1.0
    "#;
    let msg = Robot::from_toml_str(text).unwrap_err().to_string();
    assert!(
        msg.contains("bus legs") && msg.contains("/nonexistent/tty"),
        "{msg}"
    );
}

/// The 1-based line of the first line containing `needle`.
fn line_of(text: &str, needle: &str) -> usize {
    text.lines().position(|l| l.contains(needle)).unwrap() + 1
}

#[test]
fn limits_take_exactly_two_numbers() {
    for limits in ["[-0.5, 0.5, 9.0]", "[-0.5, 0.5, \"x\", 1]", "[0.5]", "[]"] {
        let text = GOOD.replace("limits = [-0.5, 0.5]", &format!("limits = {limits}"));
        let e = RobotConfig::from_toml_str(&text).unwrap_err();
        let RobotError::Parse { line, column, .. } = &e else {
            panic!("{limits}: {e:?}");
        };
        assert_eq!(
            *line,
            line_of(&text, &format!("limits = {limits}")),
            "{limits}: {e}"
        );
        assert!(*column > 1, "{e}");
        assert!(e.to_string().contains("two numbers"), "{e}");
    }
}

#[test]
fn value_errors_give_the_line_and_column_of_the_value() {
    let text = GOOD.replace("limits = [-0.5, 0.5]", "limits = [0.5, -0.5]");
    let msg = err(&text);
    let line = line_of(&text, "limits = [0.5");
    assert!(
        msg.contains(&format!("joint shoulder (line {line}, column 10)")),
        "{msg}"
    );
    let text = GOOD.replace("torque = 1", "torque = 5");
    let msg = err(&text);
    let line = line_of(&text, "torque = 5");
    assert!(
        msg.contains(&format!("bus legs (line {line}, column 10)")),
        "{msg}"
    );
    // A duplicate name is reported at the second joint's name.
    let text = GOOD.replace("name = \"shoulder\"", "name = \"knee\"");
    let msg = err(&text);
    let second = text.match_indices("name = \"knee\"").nth(1).unwrap().0;
    let line = text[..second].matches('\n').count() + 1;
    assert!(msg.contains(&format!("(line {line}, column 8)")), "{msg}");
}

#[test]
fn empty_and_jointless_files_are_refused() {
    for text in ["", "   \n\t\n"] {
        let e = RobotConfig::from_toml_str(text).unwrap_err();
        assert!(
            matches!(
                e,
                RobotError::Parse {
                    line: 1,
                    column: 1,
                    ..
                }
            ),
            "{e:?}"
        );
        assert!(e.to_string().contains("empty"), "{e}");
    }
    let msg = err("# only a comment\nwatchdog_timeout = 0.1\n");
    assert!(msg.contains("buses") || msg.contains("joints"), "{msg}");
    let no_joints = r#"
        joints = []
        [buses.legs]
        kind = "wck"
        port = "/dev/ttyUSB0"
    "#;
    let msg = err(no_joints);
    assert!(
        msg.contains("joints = none") && msg.contains("at least one [[joints]]"),
        "{msg}"
    );
}

#[test]
fn non_finite_and_absurd_values_are_refused() {
    let cases = [
        ("offset = 0.1", "offset = nan", "offset"),
        ("limits = [-0.5, 0.5]", "limits = [-inf, 0.5]", "limits"),
        ("max_velocity = 0.5", "max_velocity = inf", "max_velocity"),
        ("max_velocity = 0.5", "max_velocity = 1e300", "<= 100 rad/s"),
        (
            "max_acceleration = 2.0",
            "max_acceleration = 1e9",
            "<= 10000",
        ),
        // WHJ: device angles beyond the position registers (±214 748°).
        (
            "limits = [-0.5, 0.5]",
            "limits = [-1e9, 1e9]",
            "position registers",
        ),
        (
            "limits = [-0.5, 0.5]",
            "limits = [-0.5, 0.5]\noffset = 4000.0",
            "offset 4000",
        ),
        // wCK: an offset that puts the limits beyond the servo's reach.
        ("offset = 0.1", "offset = 5.0", "angles the servo can reach"),
        ("name = \"knee\"", "name = \"\"", "a non-empty name"),
        ("port = \"/dev/ttyUSB7\"", "port = \"\"", "port"),
    ];
    for (from, to, needle) in cases {
        let text = GOOD.replace(from, to);
        assert_ne!(text, GOOD, "{from}");
        let msg = err(&text);
        assert!(msg.contains(needle), "{to}: {needle:?} missing in {msg}");
        assert!(msg.contains("line"), "{to}: no line in {msg}");
    }
}

#[test]
fn unknown_keys_are_refused_everywhere() {
    for (from, to) in [
        (
            "watchdog_timeout = 0.05",
            "watchdog_timeout = 0.05\nwatchdog = 1",
        ),
        ("baud = 57600", "baud = 57600\nparity = \"none\""),
        ("centre = 120", "centre = 120\ngear = 2"),
    ] {
        let text = GOOD.replace(from, to);
        let e = RobotConfig::from_toml_str(&text).unwrap_err();
        assert!(
            matches!(e, RobotError::Parse { line, .. } if line > 0),
            "{e:?}"
        );
        let key = to.lines().nth(1).unwrap().split(' ').next().unwrap();
        assert!(e.to_string().contains(key), "{key}: {e}");
    }
}

#[test]
fn files_over_the_size_limit_are_refused_without_reading_them_whole() {
    let limit = RobotConfig::MAX_FILE_BYTES;
    assert_eq!(limit, 1 << 20);
    // Text: a valid file padded with comments past the limit.
    let mut big = GOOD.to_owned();
    while big.len() <= limit {
        big.push_str("# padding padding padding padding padding padding padding\n");
    }
    let msg = err(&big);
    assert!(msg.contains("1048576") && msg.contains("1 MiB"), "{msg}");
    // Files: one byte over the limit, and an endless device.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("big.toml");
    std::fs::write(&path, &big).unwrap();
    let msg = RobotConfig::from_toml_file(&path).unwrap_err().to_string();
    assert!(msg.contains("big.toml") && msg.contains("1 MiB"), "{msg}");
    let msg = RobotConfig::from_toml_file("/dev/zero")
        .unwrap_err()
        .to_string();
    assert!(msg.contains("/dev/zero") && msg.contains("1 MiB"), "{msg}");
    // At the limit exactly: read and parsed.
    let mut exact = GOOD.to_owned();
    exact.push_str(&"#".repeat(limit - exact.len() - 1));
    exact.push('\n');
    assert_eq!(exact.len(), limit);
    std::fs::write(&path, &exact).unwrap();
    RobotConfig::from_toml_file(&path).unwrap();
}

#[test]
fn a_file_that_is_not_utf8_names_the_byte() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bin.toml");
    std::fs::write(&path, b"watchdog_timeout = 0.1\n\xff\xfe").unwrap();
    let msg = RobotConfig::from_toml_file(&path).unwrap_err().to_string();
    assert!(msg.contains("UTF-8") && msg.contains("byte 23"), "{msg}");
}

mod properties {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        /// Arbitrary bytes never panic the reader: an error or a checked config.
        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("r.toml");
            std::fs::write(&path, &bytes).unwrap();
            if let Ok(c) = RobotConfig::from_toml_file(&path) {
                prop_assert!(c.validate().is_ok() && !c.joints.is_empty());
            }
            let _ = RobotConfig::from_toml_str(&String::from_utf8_lossy(&bytes));
        }

        /// Mutations of a good file (a line dropped, duplicated or a token replaced)
        /// never panic, and whatever parses passes validation.
        #[test]
        fn mutated_files_never_panic(
            line in 0usize..40,
            action in 0u8..3,
            token in prop::sample::select(vec![
                "nan", "inf", "-inf", "1e308", "-1e308", "[]", "[1, 2, 3]", "\"\"", "0",
                "-1", "255", "{}", "[[joints]]", "[buses.x]", "= =",
            ]),
        ) {
            let mut lines: Vec<String> = GOOD.lines().map(str::to_owned).collect();
            let i = line % lines.len();
            match action {
                0 => { lines.remove(i); }
                1 => { let l = lines[i].clone(); lines.insert(i, l); }
                _ => {
                    if let Some((key, _)) = lines[i].split_once(" = ") {
                        lines[i] = format!("{key} = {token}");
                    } else {
                        lines[i] = token.to_owned();
                    }
                }
            }
            if let Ok(c) = RobotConfig::from_toml_str(&lines.join("\n")) {
                prop_assert!(c.validate().is_ok());
            }
        }

        /// Anything over the limit is refused, whatever it holds.
        #[test]
        fn oversized_input_is_refused(extra in 1usize..4096, fill in any::<u8>()) {
            let c = char::from(b' ' + fill % 90);
            // One ASCII character repeated (`str::repeat` copies in blocks: collecting a
            // million chars one by one took 0.13 s a case in a test build).
            let text = c.to_string().repeat(RobotConfig::MAX_FILE_BYTES + extra);
            let msg = RobotConfig::from_toml_str(&text).unwrap_err().to_string();
            prop_assert!(msg.contains("1 MiB"), "{}", msg);
        }
    }
}

/// A wCK bus's port is any port address (`COM12`, `socket://HOST:PORT`, a device path);
/// one in none of those forms names the bus, the value and the forms.
#[test]
fn a_wck_port_is_a_port_address_and_a_bad_one_names_the_forms() {
    for port in ["COM12", "socket://127.0.0.1:5600", "/dev/cu.usbserial-A1"] {
        let text = GOOD.replace("/dev/ttyUSB7", port);
        let config = RobotConfig::from_toml_str(&text).unwrap();
        assert!(
            matches!(&config.buses["legs"], BusConfig::Wck { port: p, .. } if p == port),
            "{port}"
        );
    }
    let text = GOOD.replace("/dev/ttyUSB7", "socket://127.0.0.1:0");
    let msg = err(&text);
    let line = text.lines().position(|l| l.contains("socket://")).unwrap() + 1;
    assert!(
        msg.contains("legs")
            && msg.contains("socket://127.0.0.1:0")
            && msg.contains("port 0")
            && msg.contains("COM3")
            && msg.contains(&format!("line {line}")),
        "{msg}"
    );
}
