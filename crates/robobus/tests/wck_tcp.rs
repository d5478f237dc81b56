//! The wCK client over TCP: the simulator's endpoint served on a loopback listener
//! (`robobus_sim::wck::spawn_tcp`, what `robobus sim wck --listen` runs) and the client
//! opening `socket://127.0.0.1:PORT` with `WckBus::open` as it opens any port: scan,
//! status, moves, the TCP margin, a simulator that goes away, and a client that leaves
//! and comes back.
#![allow(clippy::unwrap_used)] // test helpers

use crate::wck_support;

use std::time::{Duration, Instant};

use robobus::wck::{PortLink, ScanOptions, WckBus, WckError};
use robobus_link::{LinkError, PortSpec, WaitMode};
use robobus_sim::wck::{Bus, BusConfig, Endpoint, Model};
use robobus_wck::{BaudRate, Position, TorqueLevel};
use wck_support::{AWAKE, id, pty_config};

/// Modules `ids` at 115200 bit/s served over TCP on a free loopback port, awake.
fn serve_tcp(ids: &[u8]) -> Endpoint {
    let config = BusConfig {
        host_baud: BaudRate::B115200,
        ..BusConfig::default()
    };
    let bus = Bus::with_servos(config, Model::W1108, ids.iter().copied());
    let endpoint =
        robobus_sim::wck::spawn_tcp(bus, "127.0.0.1:0".parse().unwrap(), WaitMode::Sleep).unwrap();
    while endpoint.with_bus(|b| b.now()).unwrap() < AWAKE {
        std::thread::sleep(Duration::from_millis(5));
    }
    endpoint
}

/// The client, opened by the endpoint's address, with the margins of the pty clients
/// (a simulator thread on a loaded machine).
fn client(endpoint: &Endpoint) -> WckBus<PortLink> {
    WckBus::open(endpoint.path(), BaudRate::B115200)
        .unwrap()
        .with_config(pty_config())
}

fn pos(p: u8) -> Position {
    Position::new(p).unwrap()
}

#[test]
fn the_endpoint_is_named_by_its_socket_address_and_opening_it_adds_the_tcp_margin() {
    let endpoint = serve_tcp(&[0]);
    let PortSpec::Tcp { host, port } = endpoint.port().clone() else {
        panic!("{:?}", endpoint.port());
    };
    assert_eq!(host, "127.0.0.1");
    assert_ne!(port, 0);
    assert_eq!(
        endpoint.path().to_str().unwrap(),
        format!("socket://127.0.0.1:{port}")
    );
    let mut bus = WckBus::open(endpoint.path(), BaudRate::B115200).unwrap();
    assert_eq!(
        bus.config().margin,
        robobus::wck::DEFAULT_MARGIN + robobus::wck::TCP_MARGIN
    );
    assert_eq!(bus.link().port(), endpoint.port());
    assert_eq!(bus.servo(id(0)).status().unwrap().position, pos(127));
}

#[test]
fn scan_status_and_move_over_tcp() {
    let endpoint = serve_tcp(&[0, 2, 5]);
    let mut bus = client(&endpoint);
    let report = bus
        .scan(
            &ScanOptions {
                ids: 0..=6,
                ..ScanOptions::default()
            },
            |_| {},
        )
        .unwrap();
    let found: Vec<u8> = report.found.iter().map(|f| f.id.get()).collect();
    assert_eq!(found, [0, 2, 5]);
    assert!(report.duplicates.is_empty());

    let before = bus
        .servo(id(2))
        .move_to(TorqueLevel::new(0).unwrap(), pos(90))
        .unwrap();
    assert_eq!(before.position, pos(127));
    let deadline = Instant::now() + Duration::from_secs(3);
    loop {
        let now = bus.servo(id(2)).status().unwrap().position.get();
        if now.abs_diff(90) <= 1 {
            break;
        }
        assert!(Instant::now() < deadline, "servo 2 stays at {now}");
        std::thread::sleep(Duration::from_millis(50));
    }
    // A silent ID times out as on a serial port.
    let e = bus.servo(id(1)).status().unwrap_err();
    assert!(e.is_timeout(), "{e}");
}

/// A client that leaves and a new one that connects: the bus goes on (a port closed and
/// opened again), the servo where the first client left it.
#[test]
fn a_client_that_reconnects_finds_the_bus_as_it_left_it() {
    let endpoint = serve_tcp(&[1]);
    let mut first = client(&endpoint);
    first
        .servo(id(1))
        .move_to(TorqueLevel::new(0).unwrap(), pos(60))
        .unwrap();
    drop(first);
    std::thread::sleep(Duration::from_millis(600));
    let mut second = client(&endpoint);
    let now = second.servo(id(1)).status().unwrap().position.get();
    assert!(now.abs_diff(60) <= 1, "{now}");
}

/// A simulator that stops is a closed link, named, not a timeout taken for a silent servo.
#[test]
fn a_simulator_that_stops_is_a_closed_link_naming_the_address() {
    let endpoint = serve_tcp(&[0]);
    let mut bus = client(&endpoint);
    assert_eq!(bus.servo(id(0)).status().unwrap().position, pos(127));
    let address = endpoint.port().to_string();
    endpoint.stop().unwrap();
    let e = bus.servo(id(0)).status().unwrap_err();
    match &e {
        WckError::Link {
            source: LinkError::Closed { context },
            ..
        } => assert!(context.contains(&address), "{context}"),
        other => panic!("{other:?}"),
    }
}
