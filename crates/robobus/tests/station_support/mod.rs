//! Shared by the catalogue tests: a station of simulated buses on the virtual clocks.

#![allow(dead_code, unreachable_pub, clippy::unwrap_used)]

use robobus::station::{Station, WckPort, WhjPort};
use robobus::wck::WckBus;
use robobus::whj::{JointBus, JointBusConfig};
use robobus_link::ByteLink as _;
use robobus_sim::wck::{Bus, BusConfig, Model, SimLink};
use robobus_sim::whj::{WhjBus, WhjModel, WhjSimLink};
use robobus_wck::BaudRate;

/// wCK servos 0..=2 on the port `wck`, WHJ joints 1 and 2 on the bus `whj`, on the
/// virtual clocks; the station keeps the simulators.
pub fn station(wck: &str, whj: &str) -> (Station, WckPort, WhjPort) {
    let (mut link, sim) =
        SimLink::virtual_clock(Bus::with_servos(BusConfig::default(), Model::W1108, 0..3));
    let now = link.now();
    link.sleep_until(now + std::time::Duration::from_millis(100));
    let wck_bus = WckBus::new(
        Box::new(link) as robobus::robot::DynByteLink,
        BaudRate::B115200,
    )
    .unwrap();
    let (whj_link, whj_sim) = WhjSimLink::new(WhjBus::chain(1..=2, WhjModel::Whj30, 11));
    let whj_bus = JointBus::open_with(whj_link, JointBusConfig::default()).unwrap();
    let mut s = Station::new();
    let w = s.add_wck(wck, wck_bus);
    let j = s.add_whj(whj, whj_bus);
    s.keep(Box::new(std::sync::Mutex::new(sim)));
    s.keep(Box::new(std::sync::Mutex::new(whj_sim)));
    (s, w, j)
}
