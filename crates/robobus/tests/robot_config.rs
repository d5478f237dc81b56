//! The robot file: parsing errors name the line, the field and the value; value checks
//! name the joint or bus.

#![allow(clippy::unwrap_used, clippy::panic)]

use robobus::robot::{BusConfig, Robot, RobotConfig, RobotError, SafeState};

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
