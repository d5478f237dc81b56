//! The client suite that runs against the simulators and, unchanged, against real devices.
//!
//! By default it runs on simulated buses on the virtual clock (3 wCK servos, 2 WHJ
//! joints). Environment variables name real devices instead (see
//! `robobus_testkit::devices`): for example
//!
//! ```text
//! ROBOBUS_TEST_WCK_PORT=/dev/ttyUSB0 ROBOBUS_TEST_WCK_IDS=0-15 \
//! ROBOBUS_TEST_WHJ_BUS=can0 ROBOBUS_TEST_WHJ_JOINTS=1-6 \
//!   cargo test -p robobus --test integration device_suite:: -- --test-threads 1
//! ```
//!
//! On real devices the suite only reads unless `ROBOBUS_TEST_MOTION=1`; then it moves each
//! device a little from where it is and back (2° for a WHJ joint, 6 steps for a wCK
//! servo), and leaves a WHJ joint disabled if it found it so. A family the environment
//! does not name is not tested there (the test says so on its output).
//!
//! The suite's tests are the ones named `suite_*`. The path through the environment is
//! tested too: `devices_named_by_the_environment_on_a_serial_port_and_a_udp_bus`
//! serves the simulators as a machine's devices (wCK on a pseudo-terminal, WHJ on UDP
//! multicast inside a private network namespace) and re-runs the suite pointed at them,
//! reading only and then moving.

#![allow(clippy::unwrap_used, clippy::panic, clippy::print_stdout)] // tests

use crate::station_support;

use std::sync::Arc;
use std::time::Duration;

use robobus::catalogue::telemetry::Telemetry;
use robobus::catalogue::{self, Report, Request};
use robobus::ops::Control;
use robobus::record::SampleTable;
use robobus::station::{Station, StationConfig};
#[cfg(target_os = "linux")]
use robobus_testkit::Inner;
use robobus_testkit::devices::{self, Hardware};

/// What the suite runs on.
struct Target {
    station: Arc<Station>,
    /// wCK servos, if a wCK bus is there.
    wck: Option<Vec<u8>>,
    /// WHJ joints, if a WHJ bus is there.
    whj: Option<Vec<u8>>,
    /// Whether the suite may move the devices.
    motion: bool,
    /// Real devices (else the simulators).
    hardware: bool,
}

fn target() -> Target {
    match devices::hardware() {
        None => {
            let (station, _w, _j) = station_support::station("wck", "whj");
            Target {
                station: Arc::new(station),
                wck: Some(vec![0, 1, 2]),
                whj: Some(vec![1, 2]),
                motion: true,
                hardware: false,
            }
        }
        Some(h) => on_hardware(h),
    }
}

fn on_hardware(h: Hardware) -> Target {
    let config = StationConfig {
        wck_ports: h.wck.iter().map(|w| w.port.clone()).collect(),
        wck_baud: h.wck.as_ref().map(|w| {
            robobus_wck::BaudRate::from_bits_per_second(w.baud)
                .unwrap_or_else(|e| panic!("ROBOBUS_TEST_WCK_BAUD={}: {e}", w.baud))
        }),
        whj_buses: h.whj.iter().map(|w| w.bus.clone()).collect(),
        // An absent joint is part of the suite: do not wait the full connect time for it.
        whj_connect_timeout: Some(Duration::from_millis(300)),
        ..StationConfig::default()
    };
    let station = Station::open(&config).unwrap_or_else(|e| panic!("opening {config:?}: {e}"));
    Target {
        station: Arc::new(station),
        wck: h.wck.map(|w| w.ids),
        whj: h.whj.map(|w| w.joints),
        motion: h.motion,
        hardware: true,
    }
}

fn run(s: &Station, json: &str) -> Report {
    let mut r = Request::parse_many(json).unwrap_or_else(|e| panic!("{json}: {e}"));
    assert_eq!(r.len(), 1);
    catalogue::run(s, &r.remove(0), &mut Control::none()).unwrap_or_else(|e| panic!("{json}: {e}"))
}

fn list(ids: &[u8]) -> String {
    ids.iter().map(u8::to_string).collect::<Vec<_>>().join(",")
}

fn row(r: &Report, id: u8) -> &serde_json::Value {
    r.results
        .iter()
        .find(|row| row["id"] == id)
        .unwrap_or_else(|| panic!("no row {id}: {:?}", r.results))
}

/// Says on the test's output that a family was not there to test.
fn not_here(family: &str) {
    println!("{family}: no bus named in the environment, not tested here");
}

#[test]
fn suite_every_listed_device_answers_a_status_read_with_values_in_range() {
    let t = target();
    match &t.wck {
        Some(ids) => {
            let r = run(
                &t.station,
                &format!(r#"{{"op": "wck.status", "ids": "{}"}}"#, list(ids)),
            );
            assert_eq!(r.failed, None, "{:?}", r.results);
            for &id in ids {
                let s = row(&r, id);
                let p = s["position"].as_u64().unwrap();
                assert!(p <= 254, "{s}");
                assert!(s["load"].as_u64().unwrap() <= 255, "{s}");
                assert!(
                    (0.0..=269.0).contains(&s["degrees"].as_f64().unwrap()),
                    "{s}"
                );
            }
        }
        None => not_here("wCK"),
    }
    match &t.whj {
        Some(joints) => {
            let r = run(
                &t.station,
                &format!(r#"{{"op": "whj.status", "joints": "{}"}}"#, list(joints)),
            );
            assert_eq!(r.failed, None, "{:?}", r.results);
            for &id in joints {
                let s = row(&r, id);
                assert!(s["position_deg"].as_f64().unwrap().abs() <= 360.0, "{s}");
                assert!(s["enabled"].is_boolean(), "{s}");
                assert!(
                    (8.0..=60.0).contains(&s["voltage_v"].as_f64().unwrap()),
                    "{s}"
                );
                assert!(
                    (-40.0..=120.0).contains(&s["temperature_c"].as_f64().unwrap()),
                    "{s}"
                );
            }
        }
        None => not_here("WHJ"),
    }
}

#[test]
fn suite_an_absent_id_is_a_no_device_row_and_the_others_still_answer() {
    let t = target();
    if let Some(ids) = &t.wck {
        let absent = devices::absent(ids, 0, 30).unwrap();
        let mut asked = ids.clone();
        asked.insert(0, absent);
        let r = run(
            &t.station,
            &format!(r#"{{"op": "wck.status", "ids": "{}"}}"#, list(&asked)),
        );
        assert_eq!(row(&r, absent)["kind"], "no-device", "{:?}", r.results);
        assert_eq!(r.failed.map(robobus::ErrorKind::name), Some("no-device"));
        for &id in ids {
            assert!(row(&r, id)["position"].is_u64(), "{:?}", r.results);
        }
    }
    if let Some(joints) = &t.whj {
        let absent = devices::absent(joints, 1, 30).unwrap();
        let mut asked = joints.clone();
        asked.insert(0, absent);
        let r = run(
            &t.station,
            &format!(r#"{{"op": "whj.status", "joints": "{}"}}"#, list(&asked)),
        );
        assert_eq!(row(&r, absent)["kind"], "no-device", "{:?}", r.results);
        for &id in joints {
            assert!(row(&r, id)["position_deg"].is_number(), "{:?}", r.results);
        }
    }
}

/// `n` samples of `request` taken into `table`.
fn stream(s: &Arc<Station>, request: &str, n: u64, table: &mut SampleTable) {
    let mut r = Request::parse_many(request).unwrap();
    let t = Telemetry::paused(s, r.remove(0), 20.0, Some(n)).unwrap();
    let sub = t.subscribe(64).unwrap();
    assert_eq!(t.join().samples, n);
    for d in sub {
        let t_s = table.t_s + 0.05;
        table.take(&d, t_s).unwrap();
    }
}

#[test]
fn suite_a_sample_stream_gives_a_fresh_row_per_device_every_sample() {
    let t = target();
    if let Some(ids) = &t.wck {
        let mut table = SampleTable::wck(ids);
        let request = format!(r#"{{"op": "wck.sample", "ids": "{}"}}"#, list(ids));
        stream(&t.station, &request, 3, &mut table);
        assert_eq!(table.samples, 3);
        assert!(table.silent().is_empty(), "{table:?}");
        assert!(
            table
                .rows
                .iter()
                .all(|r| r.answered == 3 && r.failures == 0)
        );
        // From the second reading on, a speed.
        assert!(table.rows.iter().all(|r| r.speed.is_some()), "{table:?}");
    }
    if let Some(joints) = &t.whj {
        let mut table = SampleTable::whj(joints);
        let request = format!(r#"{{"op": "whj.sample", "joints": "{}"}}"#, list(joints));
        stream(&t.station, &request, 3, &mut table);
        assert!(table.silent().is_empty(), "{table:?}");
        assert!(
            table
                .rows
                .iter()
                .all(|r| r.answered == 3 && r.enabled.is_some() && r.effort.is_some()),
            "{table:?}"
        );
    }
}

/// Reads servo `id`'s position until it is within one step of `want` (at most 5,000
/// reads: about 5 s on a real bus at 115200 bit/s, the simulator's clock runs with them).
fn wck_reaches(s: &Station, id: u8, want: u64) -> u64 {
    let mut at = 0;
    for _ in 0..5000 {
        at = run(s, &format!(r#"{{"op": "wck.status", "ids": "{id}"}}"#)).results[0]["position"]
            .as_u64()
            .unwrap();
        if at.abs_diff(want) <= 1 {
            break;
        }
    }
    at
}

#[test]
fn suite_a_small_move_arrives_and_is_undone() {
    let t = target();
    if !t.motion {
        println!("not moving the devices: set ROBOBUS_TEST_MOTION=1 to allow small moves");
        return;
    }
    assert!(t.hardware || (t.wck.is_some() && t.whj.is_some()));
    for &id in t.wck.iter().flatten() {
        let start = run(
            &t.station,
            &format!(r#"{{"op": "wck.status", "ids": "{id}"}}"#),
        );
        let from = start.results[0]["position"].as_u64().unwrap();
        let to = if from > 127 { from - 6 } else { from + 6 };
        run(
            &t.station,
            &format!(r#"{{"op": "wck.move", "id": {id}, "position": {to}}}"#),
        );
        assert!(
            wck_reaches(&t.station, id, to).abs_diff(to) <= 1,
            "servo {id}"
        );
        run(
            &t.station,
            &format!(r#"{{"op": "wck.move", "id": {id}, "position": {from}}}"#),
        );
        assert!(
            wck_reaches(&t.station, id, from).abs_diff(from) <= 1,
            "servo {id}"
        );
    }
    for &id in t.whj.iter().flatten() {
        let status = run(
            &t.station,
            &format!(r#"{{"op": "whj.status", "joints": "{id}"}}"#),
        );
        let was_enabled = status.results[0]["enabled"] == true;
        let from = status.results[0]["position_deg"].as_f64().unwrap();
        for json in [
            format!(r#"{{"op": "whj.enable", "joints": "{id}"}}"#),
            format!(r#"{{"op": "whj.mode", "joints": "{id}", "mode": "position"}}"#),
        ] {
            assert_eq!(run(&t.station, &json).failed, None, "{json}");
        }
        let to = if from > 0.0 { from - 2.0 } else { from + 2.0 };
        for target in [to, from] {
            let r = run(
                &t.station,
                &format!(
                    r#"{{"op": "whj.move", "joint": {id}, "degrees": {target}, "max_speed": 5}}"#
                ),
            );
            assert_eq!(r.failed, None, "{:?}", r.results);
            let at = r.results[0]["position_deg"].as_f64().unwrap();
            assert!(
                (at - target).abs() < 0.2,
                "joint {id} at {at}, wanted {target}"
            );
        }
        if !was_enabled {
            run(
                &t.station,
                &format!(r#"{{"op": "whj.disable", "joints": "{id}"}}"#),
            );
        }
    }
}

/// Set inside the private network namespace of the environment test.
#[cfg(target_os = "linux")]
const NETNS_ENV: &str = "ROBOBUS_SUITE_IN_NETNS";

#[cfg(target_os = "linux")] // a private network namespace, and the wCK simulator on a pty
#[test]
fn devices_named_by_the_environment_on_a_serial_port_and_a_udp_bus() {
    Inner::exact(
        module_path!(),
        "inner_serves_the_simulators_as_hardware",
        NETNS_ENV,
    )
    .timeout_s(180)
    .in_private_netns()
    .expect_marker("DEVICE SUITE ON HARDWARE PATHS OK");
}

#[cfg(target_os = "linux")]
#[test]
#[ignore = "run by devices_named_by_the_environment_on_a_serial_port_and_a_udp_bus inside unshare -n"]
fn inner_serves_the_simulators_as_hardware() {
    use robobus_link::{UdpBus, UdpBusConfig};
    use robobus_sim::wck::{Bus, BusConfig, Model};
    use robobus_sim::whj::{Served, WhjBus, WhjModel};
    assert!(
        std::env::var_os(NETNS_ENV).is_some(),
        "this test only runs inside the private network namespace its outer test creates"
    );
    let (wck, _slave) =
        robobus_sim::wck::spawn(Bus::with_servos(BusConfig::default(), Model::W1108, 0..3))
            .unwrap();
    let udp = UdpBusConfig {
        group: std::net::Ipv4Addr::new(239, 74, 165, 1),
        port: 43_401,
        ..UdpBusConfig::default()
    };
    let whj = Served::spawn(
        "sim-whj",
        WhjBus::chain(1..=2, WhjModel::Whj30, 11),
        UdpBus::open(&udp).unwrap(),
    )
    .unwrap();
    for motion in ["0", "1"] {
        let out = Inner::matching(module_path!(), "suite_", "ROBOBUS_TEST_MOTION")
            .not_ignored()
            .env("ROBOBUS_TEST_MOTION", motion)
            .env("ROBOBUS_TEST_WCK_PORT", wck.path().as_os_str())
            .env("ROBOBUS_TEST_WCK_IDS", "0-2")
            .env(
                "ROBOBUS_TEST_WHJ_BUS",
                format!("udp:{}:{}", udp.group, udp.port),
            )
            .env("ROBOBUS_TEST_WHJ_JOINTS", "1-2")
            .here()
            .expect_marker("test result: ok. 4 passed");
        // Read-only unless asked: the move test says it did not move.
        assert_eq!(
            out.contains("not moving the devices"),
            motion == "0",
            "{out}"
        );
        assert!(!out.contains("not tested here"), "{out}");
    }
    drop(whj);
    drop(wck);
    println!("DEVICE SUITE ON HARDWARE PATHS OK");
}
