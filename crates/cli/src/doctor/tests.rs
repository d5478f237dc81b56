use super::*;

#[test]
fn missing_port_fails_with_a_fix() {
    let f = check_serial(Path::new("/nonexistent/ttyUSB9"), false);
    assert_eq!(f.len(), 1);
    assert_eq!(f[0].status, Status::Fail);
    assert!(f[0].fix.as_deref().unwrap().contains("/dev/serial/by-id"));
}

#[test]
fn can_interface_from_a_fake_sysfs() {
    let dir = tempfile::tempdir().unwrap();
    let vcan = dir.path().join("vcan7");
    std::fs::create_dir(&vcan).unwrap();
    std::fs::write(vcan.join("type"), "280\n").unwrap();
    std::fs::write(vcan.join("flags"), "0x1\n").unwrap();
    std::fs::write(vcan.join("mtu"), "16\n").unwrap();
    let f = check_can(dir.path(), "vcan7");
    let mtu = f.iter().find(|f| f.check == "fd mtu").unwrap();
    assert_eq!(mtu.status, Status::Fail);
    assert!(mtu.fix.as_deref().unwrap().contains("mtu 72"));
    std::fs::write(vcan.join("mtu"), "72\n").unwrap();
    std::fs::write(vcan.join("flags"), "0x0\n").unwrap();
    let f = check_can(dir.path(), "vcan7");
    assert!(
        f.iter()
            .any(|f| f.check == "fd mtu" && f.status == Status::Ok)
    );
    assert!(
        f.iter()
            .any(|f| f.check == "up" && f.status == Status::Fail)
    );
    let missing = check_can(dir.path(), "vcan8");
    assert_eq!(missing[0].status, Status::Fail);
    assert_eq!(find_can_interfaces(dir.path()), ["vcan7"]);
}

#[test]
fn bit_rates_are_judged_from_ip_json() {
    let good: serde_json::Value = serde_json::from_str(
        r#"{"ctrlmode":["FD"],"bittiming":{"bitrate":1000000},"data_bittiming":{"bitrate":5000000}}"#,
    )
    .unwrap();
    assert_eq!(bit_rate_finding("can0", &good, "x").status, Status::Ok);
    let classic: serde_json::Value =
        serde_json::from_str(r#"{"bittiming":{"bitrate":500000}}"#).unwrap();
    let f = bit_rate_finding("can0", &classic, "setup");
    assert_eq!(f.status, Status::Fail);
    assert!(f.detail.contains("500000") && f.detail.contains("fd off"));
    assert_eq!(f.fix.as_deref(), Some("setup"));
    // Right rates, wrong sample points (as `ip -json` prints them): a warning.
    let points: serde_json::Value = serde_json::from_str(
        r#"{"ctrlmode":["FD"],"bittiming":{"bitrate":1000000,"sample_point":"0.875"},
            "data_bittiming":{"bitrate":5000000,"sample_point":"0.750"}}"#,
    )
    .unwrap();
    let f = bit_rate_finding("can0", &points, "setup");
    assert_eq!(f.status, Status::Warn, "{f:?}");
    assert!(f.detail.contains("0.875 / 0.750"), "{}", f.detail);
    let right: serde_json::Value = serde_json::from_str(
        r#"{"ctrlmode":["FD"],"bittiming":{"bitrate":1000000,"sample_point":"0.800"},
            "data_bittiming":{"bitrate":5000000,"sample_point":0.75}}"#,
    )
    .unwrap();
    assert_eq!(bit_rate_finding("can0", &right, "x").status, Status::Ok);
}

#[test]
fn the_can_fd_fix_sets_the_demo_sample_points() {
    let dir = tempfile::tempdir().unwrap();
    let f = check_can(dir.path(), "can3");
    let fix = f[0].fix.as_deref().unwrap();
    assert!(
        fix.contains(
            "ip link set can3 type can bitrate 1000000 sample-point 0.8 dbitrate 5000000 \
             dsample-point 0.75 fd on"
        ),
        "{fix}"
    );
}

#[test]
fn names_are_bounded() {
    assert!(check_iface("--can", "can0").is_ok());
    assert!(check_iface("--can", "abcdefghijklmno").is_ok()); // 15 bytes
    let e = check_iface("--can", "abcdefghijklmnop")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("--can `abcdefghijklmnop`: an interface name has 1..=15"),
        "{e}"
    );
    let long = "a".repeat(65_536);
    let e = check_iface("--can", &long).unwrap_err().to_string();
    assert!(e.contains("(65536 bytes)") && e.len() < 200, "{e}");
    assert!(check_iface("--can", "").is_err());
    assert!(check_iface("--can", "../x").is_err());
    assert!(check_iface("--can", "can 0").is_err());
    let ok = "/".repeat(4095);
    assert!(check_path("--port", std::ffi::OsStr::new(&ok)).is_ok());
    let e = check_path("--port", std::ffi::OsStr::new(&"/".repeat(4096)))
        .unwrap_err()
        .to_string();
    assert!(e.contains("--port") && e.contains("1..=4095 bytes"), "{e}");
}

#[test]
fn a_controller_running_classic_can_fails_with_the_can_fd_command() {
    use robobus_link::socketcan::health::{CanHealth, ControllerState};
    let health = |fd| CanHealth {
        iface: "can0".into(),
        kind: Some("can".into()),
        up: true,
        carrier: true,
        state: Some(ControllerState::ErrorActive),
        bitrate: Some(1_000_000),
        fd: Some(fd),
        ..CanHealth::default()
    };
    let f = controller_finding(&health(false));
    assert_eq!(f.status, Status::Fail, "{f:?}");
    assert!(f.detail.ends_with("; classic CAN (CAN FD off)"), "{f:?}");
    let fix = f.fix.unwrap();
    assert!(
        fix.starts_with("can0 is classic CAN (CAN FD off, bitrate 1000000, no data phase)")
            && fix.contains("type can bitrate 1000000 sample-point 0.8 dbitrate 5000000"),
        "{fix}"
    );
    let f = controller_finding(&health(true));
    assert_eq!((f.status, f.fix), (Status::Ok, None));
}
