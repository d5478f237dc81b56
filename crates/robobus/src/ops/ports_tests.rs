use super::*;

fn raw(name: &str, ids: Option<(u16, u16)>, manufacturer: &str, product: &str) -> RawPort {
    RawPort {
        name: name.into(),
        kind: Some(if ids.is_some() {
            PortKind::Usb
        } else {
            PortKind::Unknown
        }),
        vid: ids.map(|i| i.0),
        pid: ids.map(|i| i.1),
        manufacturer: (!manufacturer.is_empty()).then(|| manufacturer.into()),
        product: (!product.is_empty()).then(|| product.into()),
        serial_number: ids.map(|_| "A10K1234".into()),
    }
}

#[test]
fn the_adapter_table_names_each_known_id_and_its_use() {
    let want: [(u16, u16, &str, &str); 13] = [
        (0x0403, 0x6001, "FTDI FT232R", "wCK bus: --port P / true"),
        (0x0403, 0x6010, "FTDI FT2232", "wCK bus: --port P / true"),
        (0x0403, 0x6011, "FTDI FT4232H", "wCK bus: --port P / true"),
        (
            0x0403,
            0x6014,
            "FTDI FT232H (as in the ROBOTIS U2D2)",
            "wCK bus: --port P / true",
        ),
        (
            0x0403,
            0x6015,
            "FTDI FT-X (FT231X, FT230X)",
            "wCK bus: --port P / true",
        ),
        (0x1a86, 0x7523, "WCH CH340", "wCK bus: --port P / false"),
        (0x1a86, 0x5523, "WCH CH341", "wCK bus: --port P / false"),
        (
            0x10c4,
            0xea60,
            "Silicon Labs CP210x",
            "wCK bus: --port P / false",
        ),
        (
            0x10c4,
            0xea70,
            "Silicon Labs CP2105",
            "wCK bus: --port P / false",
        ),
        (
            0x16d0,
            0x117e,
            "CANable 2.0 (slcan firmware)",
            "CAN FD adapter: --bus slcan:P / false",
        ),
        (
            0x1209,
            0x2323,
            "mjbots fdcanusb",
            "CAN FD adapter: --bus fdcanusb:P / false",
        ),
        // Not in the table: another FTDI chip, ST's generic virtual COM port.
        (0x0403, 0x6002, "", ""),
        (0x0483, 0x5740, "", ""),
    ];
    let got: Vec<(u16, u16, &str, String)> = want
        .iter()
        .map(|&(v, p, ..)| {
            let a = identify(v, p, None, None);
            let use_ = a.map(|a| format!("{} / {}", use_for(a.role, "P"), a.latency_timer));
            (v, p, a.map_or("", |a| a.name), use_.unwrap_or_default())
        })
        .collect();
    let want: Vec<(u16, u16, &str, String)> = want
        .iter()
        .map(|&(v, p, n, u)| (v, p, n, u.to_owned()))
        .collect();
    assert_eq!(got, want);
    assert_eq!(ADAPTERS.len(), 12);
}

#[test]
fn an_fdcanusb_is_known_by_its_strings_whatever_its_ids() {
    let a = identify(0x0483, 0x5740, Some("mjbots"), Some("fdcanusb")).unwrap();
    assert_eq!((a.name, a.role), ("mjbots fdcanusb", AdapterRole::Fdcanusb));
    assert_eq!(
        identify(0x0483, 0x5740, Some(" MJBOTS "), Some("FDCANUSB")).map(|a| a.name),
        Some("mjbots fdcanusb")
    );
    assert_eq!(
        identify(0x0483, 0x5740, Some("mjbots"), Some("moteus")),
        None
    );
    assert_eq!(identify(0x0483, 0x5740, None, Some("fdcanusb")), None);
}

#[test]
fn ports_are_described_sorted_and_com_ports_by_number() {
    let list = describe(
        Os::Windows,
        [
            raw(
                "COM12",
                Some((0x16d0, 0x117e)),
                "Openlight Labs",
                "CANable2 b158aa7",
            ),
            raw("COM3", Some((0x0403, 0x6001)), "FTDI", "FT232R USB UART"),
            raw("COM1", None, "", ""),
        ],
        &|_| panic!("no latency timer is read on Windows"),
    );
    let got: Vec<_> = list
        .ports
        .iter()
        .map(|p| serde_json::to_value(p).unwrap())
        .collect();
    assert_eq!(list.os, Os::Windows);
    assert_eq!(list.left_out, 0);
    assert_eq!(
        got,
        [
            serde_json::json!({
                "id": "COM1", "kind": "unknown", "vid": null, "pid": null,
                "manufacturer": null, "product": null, "serial_number": null,
                "adapter": null, "use_for": null, "latency_timer_ms": null,
                "latency_advice": null,
            }),
            serde_json::json!({
                "id": "COM3", "kind": "usb", "vid": 0x0403, "pid": 0x6001,
                "manufacturer": "FTDI", "product": "FT232R USB UART",
                "serial_number": "A10K1234", "adapter": "FTDI FT232R",
                "use_for": "wCK bus: --port COM3", "latency_timer_ms": null,
                "latency_advice": "FTDI latency timer (16 ms unless set): Device Manager > \
                    Ports (COM & LPT) > COM3 > Properties > Port Settings > Advanced > \
                    Latency Timer (msec): 1",
            }),
            serde_json::json!({
                "id": "COM12", "kind": "usb", "vid": 0x16d0, "pid": 0x117e,
                "manufacturer": "Openlight Labs", "product": "CANable2 b158aa7",
                "serial_number": "A10K1234", "adapter": "CANable 2.0 (slcan firmware)",
                "use_for": "CAN FD adapter: --bus slcan:COM12", "latency_timer_ms": null,
                "latency_advice": null,
            }),
        ]
    );
}

#[test]
fn linux_reads_an_ftdi_latency_timer_and_advises_only_when_it_is_not_1_ms() {
    let ports = [
        raw(
            "/dev/ttyUSB1",
            Some((0x0403, 0x6001)),
            "FTDI",
            "FT232R USB UART",
        ),
        raw(
            "/dev/ttyUSB0",
            Some((0x0403, 0x6015)),
            "FTDI",
            "FT231X USB UART",
        ),
        raw("/dev/ttyACM0", Some((0x1209, 0x2323)), "mjbots", "fdcanusb"),
        raw("/dev/ttyUSB2", Some((0x1a86, 0x7523)), "", "USB Serial"),
    ];
    let asked = std::cell::RefCell::new(Vec::new());
    let list = describe(Os::Linux, ports, &|p| {
        asked.borrow_mut().push(p.to_owned());
        (p == "/dev/ttyUSB0").then_some(1).or(Some(16))
    });
    // Only the FTDI chips have a timer to read.
    assert_eq!(*asked.borrow(), ["/dev/ttyUSB0", "/dev/ttyUSB1"]);
    let rows: Vec<_> = list
        .ports
        .iter()
        .map(|p| {
            (
                p.port.as_str(),
                p.latency_timer_ms,
                p.latency_advice.is_some(),
                p.use_for.as_deref(),
            )
        })
        .collect();
    assert_eq!(
        rows,
        [
            (
                "/dev/ttyACM0",
                None,
                false,
                Some("CAN FD adapter: --bus fdcanusb:/dev/ttyACM0")
            ),
            (
                "/dev/ttyUSB0",
                Some(1),
                false,
                Some("wCK bus: --port /dev/ttyUSB0")
            ),
            (
                "/dev/ttyUSB1",
                Some(16),
                true,
                Some("wCK bus: --port /dev/ttyUSB1")
            ),
            (
                "/dev/ttyUSB2",
                None,
                false,
                Some("wCK bus: --port /dev/ttyUSB2")
            ),
        ]
    );
    assert_eq!(
        list.ports[2].latency_advice.as_deref(),
        Some(
            "latency timer 16 ms: each reply can wait that long in the adapter; set 1 ms: \
             `echo 1 | sudo tee /sys/bus/usb-serial/devices/ttyUSB1/latency_timer` (or \
             `robobus doctor --port /dev/ttyUSB1 --fix` as root); to keep it, a udev rule in \
             /etc/udev/rules.d/99-ftdi-latency.rules: ACTION==\"add\", \
             SUBSYSTEM==\"usb-serial\", DRIVER==\"ftdi_sio\", ATTR{latency_timer}=\"1\""
        )
    );
}

#[test]
fn each_os_has_its_own_latency_advice() {
    let ftdi = identify(0x0403, 0x6014, None, None);
    let mac = latency_advice(Os::Macos, "/dev/cu.usbserial-A1", ftdi, None).unwrap();
    assert!(mac.starts_with("FTDI latency timer (16 ms unless set): Apple's built-in"));
    assert!(mac.contains("--reply-margin"), "{mac}");
    let linux = latency_advice(Os::Linux, "/dev/ttyUSB3", ftdi, None).unwrap();
    assert!(
        linux.starts_with("the latency timer (16 ms unless set): each reply"),
        "{linux}"
    );
    assert!(linux.contains("/sys/bus/usb-serial/devices/ttyUSB3/latency_timer"));
    let win = latency_advice(Os::Windows, "COM7", ftdi, None).unwrap();
    assert!(win.contains("> COM7 > Properties > Port Settings > Advanced > Latency Timer"));
    // A chip without a timer, or one already at 1 ms: nothing to do.
    let ch340 = identify(0x1a86, 0x7523, None, None);
    assert_eq!(latency_advice(Os::Windows, "COM7", ch340, None), None);
    assert_eq!(
        latency_advice(Os::Linux, "/dev/ttyUSB3", ftdi, Some(1)),
        None
    );
    assert_eq!(
        latency_advice(Os::Linux, "/dev/ttyUSB3", None, Some(16)),
        None
    );
}

#[test]
fn macos_lists_the_call_out_device_not_its_dial_in_twin() {
    let list = describe(
        Os::Macos,
        [
            raw(
                "/dev/tty.usbserial-A10K",
                Some((0x0403, 0x6001)),
                "FTDI",
                "FT232R",
            ),
            raw(
                "/dev/cu.usbserial-A10K",
                Some((0x0403, 0x6001)),
                "FTDI",
                "FT232R",
            ),
            raw("/dev/tty.Bluetooth-Incoming-Port", None, "", ""),
        ],
        &|_| None,
    );
    let names: Vec<_> = list.ports.iter().map(|p| p.port.as_str()).collect();
    assert_eq!(
        names,
        ["/dev/cu.usbserial-A10K", "/dev/tty.Bluetooth-Incoming-Port"]
    );
}

#[test]
fn the_listing_is_bounded_in_ports_and_text() {
    let many = (0..300).map(|n| RawPort {
        name: format!("COM{n}"),
        product: Some("x".repeat(1000)),
        ..RawPort::default()
    });
    let list = describe(Os::Windows, many, &|_| None);
    assert_eq!(
        (list.ports.len(), list.left_out),
        (MAX_PORTS, 300 - MAX_PORTS)
    );
    assert_eq!(
        list.ports[0].product.as_deref().map(str::len),
        Some(MAX_TEXT)
    );
    assert_eq!(list.ports[255].port, "COM255");
    assert_eq!(sort_key(r"\\.\COM12"), (0, 12, String::new()));
    assert_eq!(sort_key("/dev/ttyS0"), (1, 0, "/dev/ttyS0".into()));
}
