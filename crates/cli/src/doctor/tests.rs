use super::*;

#[cfg(unix)]
#[test]
fn missing_port_fails_with_a_fix() {
    let f = serial::check_serial(Path::new("/nonexistent/ttyUSB9"), None, false);
    assert_eq!(f.len(), 1);
    assert_eq!(f[0].status, Status::Fail);
    assert!(
        f[0].fix
            .as_deref()
            .unwrap()
            .contains("`robobus ports` lists")
    );
}

fn windows_ports() -> robobus::ops::ports::PortList {
    use robobus::ops::ports::{Os, PortKind, RawPort, describe};
    let usb = |name: &str, vid, pid, m: &str, p: &str| RawPort {
        name: name.into(),
        kind: Some(PortKind::Usb),
        vid: Some(vid),
        pid: Some(pid),
        manufacturer: Some(m.into()),
        product: Some(p.into()),
        serial_number: Some("0042".into()),
    };
    describe(
        Os::Windows,
        [
            usb("COM8", 0x16d0, 0x117e, "Openlight Labs", "CANable2 b158aa7"),
            usb("COM9", 0x1209, 0x2323, "mjbots", "fdcanusb"),
            usb("COM3", 0x0403, 0x6001, "FTDI", "FT232R USB UART"),
            usb("COM4", 0x1234, 0x5678, "Acme", "Widget"),
            RawPort {
                name: "COM1".into(),
                kind: Some(PortKind::Unknown),
                ..RawPort::default()
            },
        ],
        &|_| None,
    )
}

#[test]
fn doctor_checks_the_usb_ports_the_os_lists_and_names_the_others() {
    let list = windows_ports();
    let (ports, notes) = serial::listed(&Ok(list));
    let names: Vec<_> = ports.iter().map(|p| p.display().to_string()).collect();
    assert_eq!(names, ["COM3", "COM4", "COM8", "COM9"]);
    assert_eq!(notes.len(), 1);
    assert_eq!(
        (notes[0].check, notes[0].status, notes[0].detail.as_str()),
        (
            "other ports",
            Status::Skip,
            "not USB, not checked (name one with --port): COM1"
        )
    );
    let empty = robobus::ops::ports::describe(robobus::ops::ports::Os::Macos, [], &|_| None);
    let (ports, notes) = serial::listed(&Ok(empty));
    assert!(ports.is_empty());
    assert_eq!(
        notes[0].detail,
        "no USB serial port found; ports are /dev/cu.* (`ls /dev/cu.*`); use the cu device, \
         not /dev/tty.*"
    );
}

#[test]
fn doctor_names_the_bus_option_of_each_can_fd_adapter() {
    let list = windows_ports();
    let info = |name: &str| serial::info_of(Some(&list), Path::new(name));
    // `\\.\COM8` is COM8.
    assert_eq!(info(r"\\.\COM8").map(|i| i.port.as_str()), Some("COM8"));
    let f = serial::adapter_finding("COM8", info("COM8"));
    assert_eq!(
        f.detail,
        "CANable 2.0 (slcan firmware), USB 16d0:117e (Openlight Labs, CANable2 b158aa7), \
         serial 0042: CAN FD adapter: --bus slcan:COM8"
    );
    let f = serial::can_fd_finding("COM8", info("COM8")).unwrap();
    assert_eq!(
        (f.check, f.status, f.detail.as_str()),
        (
            "can fd",
            Status::Ok,
            "CANable 2.0 (slcan firmware): WHJ joints through it with --bus slcan:COM8 (the \
             adapter is set to the joints' 1 / 5 Mbit/s); check them: robobus doctor \
             --whj-bus slcan:COM8"
        )
    );
    let f = serial::can_fd_finding("COM9", info("COM9")).unwrap();
    assert!(
        f.detail
            .starts_with("mjbots fdcanusb: WHJ joints through it with --bus fdcanusb:COM9")
    );
    // A UART adapter is no CAN FD adapter; an unknown one is said to be unknown.
    assert!(serial::can_fd_finding("COM3", info("COM3")).is_none());
    assert_eq!(
        serial::adapter_finding("COM4", info("COM4")).detail,
        "USB 1234:5678 (Acme, Widget), serial 0042: not an adapter robobus knows; a \
         USB-serial (UART) adapter is a wCK bus: --port COM4"
    );
    assert_eq!(
        serial::adapter_finding("/dev/pts/3", None).status,
        Status::Skip
    );
}

#[test]
fn doctor_gives_windows_and_macos_their_own_latency_advice() {
    use robobus::ops::ports::Os;
    let list = windows_ports();
    let ftdi = serial::info_of(Some(&list), Path::new("COM3"));
    let f = serial::latency_elsewhere(Os::Windows, "COM3", ftdi);
    assert_eq!(f.status, Status::Warn);
    assert_eq!(
        f.fix.as_deref(),
        Some(
            "FTDI latency timer (16 ms unless set): Device Manager > Ports (COM & LPT) > COM3 \
             > Properties > Port Settings > Advanced > Latency Timer (msec): 1"
        )
    );
    let ch = serial::info_of(Some(&list), Path::new("COM8"));
    let f = serial::latency_elsewhere(Os::Macos, "COM8", ch);
    assert_eq!(
        (f.status, f.detail.as_str()),
        (
            Status::Skip,
            "no latency timer to set on macos (not an FTDI adapter)"
        )
    );
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

#[cfg(target_os = "linux")]
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
