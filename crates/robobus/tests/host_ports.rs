//! `host.ports` through the catalogue: the machine's serial ports as the OS lists them,
//! read-only, on any station (the station's buses are not used).

use std::collections::BTreeSet;

use robobus::catalogue::{self, Effect, Request};
use robobus::ops::{Control, StopToken};
use robobus::station::Station;
use serde_json::json;

const ROW_KEYS: [&str; 11] = [
    "adapter",
    "id",
    "kind",
    "latency_advice",
    "latency_timer_ms",
    "manufacturer",
    "pid",
    "product",
    "serial_number",
    "use_for",
    "vid",
];

#[test]
fn host_ports_is_a_read_only_request_of_its_own_family_that_opens_nothing() {
    let request = Request::parse(r#"{"op": "host.ports"}"#).unwrap();
    assert_eq!(request.op(), "host.ports");
    assert_eq!(request.family(), catalogue::Family::Host);
    assert_eq!(request.effect(), Effect::Read);
    assert_eq!(request.moved().unwrap(), None);
    assert_eq!(request.bus(), None);
    assert_eq!(catalogue::confirmation(&request).unwrap(), None);
    let plan = catalogue::plan(&request).unwrap();
    assert_eq!(
        plan.to_text(),
        "# lists the serial ports the OS knows; no port is opened and nothing is sent\n"
    );
    assert!(plan.steps.is_empty());
    // It takes no arguments, not even a bus.
    let e = Request::parse(r#"{"op": "host.ports", "bus": "sim-wck"}"#).unwrap_err();
    assert_eq!(e.kind(), robobus::ops::ErrorKind::BadInput);
    assert!(e.to_string().contains("bus"), "{e}");
}

#[test]
fn host_ports_reports_each_port_the_os_lists_with_every_field_and_nothing_sent() {
    let station = Station::simulated().unwrap();
    let stop = StopToken::new();
    let request = Request::parse(r#"{"op": "host.ports"}"#).unwrap();
    let report = catalogue::run(&station, &request, &mut Control::new(&stop)).unwrap();
    station.leave();
    let report = serde_json::to_value(&report).unwrap();
    assert_eq!(report["op"], "host.ports");
    assert_eq!(report["bus"], "host");
    assert_eq!(report.get("failed"), None);
    let summary = &report["summary"];
    assert_eq!(
        summary.as_object().unwrap().keys().collect::<Vec<_>>(),
        ["left_out", "os", "ports", "where"]
    );
    let os = summary["os"].as_str().unwrap();
    assert!(["linux", "windows", "macos", "other"].contains(&os), "{os}");
    assert_eq!(os == "linux", cfg!(target_os = "linux"));
    let rows = report["results"].as_array().unwrap();
    assert_eq!(summary["ports"], json!(rows.len()));
    assert_eq!(summary["left_out"], 0);
    for row in rows {
        let keys: Vec<&str> = row
            .as_object()
            .unwrap()
            .keys()
            .map(String::as_str)
            .collect();
        assert_eq!(keys, ROW_KEYS, "{row}");
        let kind = row["kind"].as_str().unwrap();
        assert!(
            ["usb", "pci", "bluetooth", "unknown"].contains(&kind),
            "{row}"
        );
        // USB IDs exactly when the OS says it is a USB port.
        assert_eq!(row["vid"].is_u64(), kind == "usb", "{row}");
        assert_eq!(row["pid"].is_u64(), kind == "usb", "{row}");
        // What it is for names this very port.
        if let Some(use_for) = row["use_for"].as_str() {
            assert!(use_for.ends_with(row["id"].as_str().unwrap()), "{row}");
        }
    }
    if cfg!(target_os = "linux") {
        // Each listed port is a device the kernel has under /sys/class/tty, with its node.
        let ids: BTreeSet<&str> = rows.iter().map(|r| r["id"].as_str().unwrap()).collect();
        for id in &ids {
            let name = id.strip_prefix("/dev/").unwrap();
            assert!(
                std::path::Path::new("/sys/class/tty")
                    .join(name)
                    .join("device")
                    .exists(),
                "{id}"
            );
        }
        // Never a pseudo-terminal.
        assert!(ids.iter().all(|id| !id.starts_with("/dev/pts/")), "{ids:?}");
    }
}
