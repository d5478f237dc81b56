//! The host's protection in the robot file: `[protection]` and `[joints.protection]`
//! override the models table's defaults, each value checked with its field, value, range
//! and line.

#![allow(clippy::unwrap_used)]

use robobus::ErrorKind;
use robobus::ops::protect::Limits;
use robobus::robot::{RobotConfig, RobotError};
use robobus_whj::units::Model;

/// A wCK servo and a WHJ joint; `extra` goes after the WHJ joint (its
/// `[joints.protection]` table), `head` before the buses.
fn file(head: &str, extra: &str) -> String {
    format!(
        r#"{head}
[buses.legs]
kind = "wck-external"

[buses.arm]
kind = "whj-external"

[[joints]]
name = "knee"
bus = "legs"
id = 3
limits = [-1.0, 1.0]
max_velocity = 2.0
max_acceleration = 20.0

[[joints]]
name = "shoulder"
bus = "arm"
id = 1
limits = [-0.5, 0.5]
max_velocity = 0.5
max_acceleration = 2.0
{extra}"#
    )
}

#[test]
fn without_a_protection_table_each_joint_has_its_familys_defaults() {
    let c = RobotConfig::from_toml_str(&file("", "")).unwrap();
    assert!(c.protection.enabled);
    let shoulder = c.protection_of(&c.joints[1], Some(Model::Joint30));
    assert_eq!(shoulder, Limits::whj(Some(Model::Joint30)));
    assert_eq!(shoulder.stall_current_a, Some(7.8));
    assert_eq!(shoulder.temperature_stop_c, Some(85.0));
    assert_eq!(c.protection_of(&c.joints[0], None), Limits::wck());
}

#[test]
fn a_joints_overrides_replace_the_defaults_and_enabled_false_turns_it_off() {
    let c = RobotConfig::from_toml_str(&file(
        "",
        "[joints.protection]\nstall_current_a = 3.5\nstall_time_s = 0.5\n\
         temperature_stop_c = 88\nderate = 0.25\n",
    ))
    .unwrap();
    let l = c.protection_of(&c.joints[1], Some(Model::Joint30));
    assert_eq!(l.stall_current_a, Some(3.5));
    assert!((l.stall_time_s - 0.5).abs() < 1e-12);
    assert_eq!(l.temperature_stop_c, Some(88.0));
    assert!((l.derate - 0.25).abs() < 1e-12);
    // What it does not name stays the default.
    assert_eq!(l.collision_current_jump_a, Some(7.8));
    let c =
        RobotConfig::from_toml_str(&file("", "[joints.protection]\nenabled = false\n")).unwrap();
    assert_eq!(
        c.protection_of(&c.joints[1], Some(Model::Joint30)),
        Limits::OFF
    );
    let c = RobotConfig::from_toml_str(&file("[protection]\nenabled = false\n", "")).unwrap();
    assert_eq!(
        c.protection_of(&c.joints[1], Some(Model::Joint30)),
        Limits::OFF
    );
    assert_eq!(c.protection_of(&c.joints[0], None), Limits::OFF);
}

/// The error of a file with `extra` after the WHJ joint.
fn refused(extra: &str) -> RobotError {
    RobotConfig::from_toml_str(&file("", extra)).unwrap_err()
}

#[test]
fn a_bad_value_is_refused_naming_the_joint_the_field_the_value_the_range_and_the_line() {
    let e = refused("[joints.protection]\nstall_time_s = 0\n");
    assert_eq!(e.kind(), ErrorKind::BadInput);
    let RobotError::Invalid {
        item,
        field,
        value,
        expected,
    } = &e
    else {
        panic!("{e:?}")
    };
    assert_eq!(field, &"protection");
    assert_eq!(value, "stall_time_s = 0");
    assert_eq!(expected, "0.02..=10 s");
    // The [joints.protection] table of the second joint, on line 23 of the file.
    assert!(item.starts_with("joint shoulder (line 2"), "{item}");
    for (extra, says) in [
        ("stall_current_a = -1", "stall_current_a = -1"),
        ("derate = 2", "derate = 2"),
        (
            "temperature_warn_c = 1e9",
            "temperature_warn_c = 1000000000",
        ),
        (
            "temperature_stop_c = 70",
            "at least temperature_derate_c (80 °C): warning <= derating <= stop",
        ),
    ] {
        let e = refused(&format!("[joints.protection]\n{extra}\n"));
        assert!(e.to_string().contains(says), "{extra}: {e}");
    }
    // An unknown key (a typo) is a syntax error with its line.
    let e = refused("[joints.protection]\nstall_curent_a = 3\n");
    assert!(
        matches!(e, RobotError::Parse { line, .. } if line > 0),
        "{e:?}"
    );
}

#[test]
fn a_wck_servo_takes_a_stall_load_but_no_temperature_limit() {
    let text = file("", "").replace(
        "max_acceleration = 20.0\n",
        "max_acceleration = 20.0\nprotection = { temperature_stop_c = 60 }\n",
    );
    let e = RobotConfig::from_toml_str(&text).unwrap_err();
    assert!(
        e.to_string()
            .contains("on a wCK servo no temperature limit and no derating"),
        "{e}"
    );
    let text = file("", "").replace(
        "max_acceleration = 20.0\n",
        "max_acceleration = 20.0\nprotection = { stall_current_a = 0.3 }\n",
    );
    let c = RobotConfig::from_toml_str(&text).unwrap();
    assert_eq!(
        c.protection_of(&c.joints[0], None).stall_current_a,
        Some(0.3)
    );
    let text = file("", "").replace(
        "max_acceleration = 20.0\n",
        "max_acceleration = 20.0\nprotection = { collision_error_jump_deg = 12 }\n",
    );
    let c = RobotConfig::from_toml_str(&text).unwrap();
    assert_eq!(
        c.protection_of(&c.joints[0], None).collision_error_jump_deg,
        Some(12.0)
    );
}
