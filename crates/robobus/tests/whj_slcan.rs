//! The client over an slcan CAN FD adapter on the simulator's virtual clock: `SlcanLink`
//! on an emulated adapter (`AdapterSimLink`) in front of seven simulated joints. Every
//! character of the adapter's serial link costs its time, so the suites see a real
//! adapter's timing, exactly and whatever the machine's load: joints connect, report,
//! move, and the cyclic loop completes every cycle.

#![allow(clippy::unwrap_used, clippy::float_cmp)] // test code: a joint at rest reads exactly 0

use crate::whj_common;

use std::time::Duration;

use robobus::whj::{CyclicConfig, JointBus};
use robobus_link::{FrameLink, SlcanConfig, SlcanLink};
use robobus_sim::whj::adapter::{AdapterSimLink, SlcanAdapter};
use robobus_sim::whj::{WhjSimHandle, WhjSimLink};
use robobus_whj::units::Position;
use robobus_whj::{JointId, WorkMode};
use whj_common::{chain, virtual_config};

/// `n` joints behind an emulated slcan adapter, on the virtual clock.
fn slcan_bus(n: u8) -> (JointBus, WhjSimHandle) {
    let (sim, handle) = WhjSimLink::new(chain(n));
    let port = AdapterSimLink::new(Box::new(SlcanAdapter::default()), sim);
    let link = SlcanLink::open(port, "sim", &SlcanConfig::default()).unwrap();
    assert!(link.virtual_time());
    (JointBus::open_with(link, virtual_config()).unwrap(), handle)
}

fn ids(n: u8) -> Vec<JointId> {
    (1..=n).map(|i| JointId::new(i).unwrap()).collect()
}

#[test]
fn joints_connect_report_and_move_through_an_slcan_adapter_on_the_virtual_clock() {
    let (bus, sim) = slcan_bus(7);
    for id in ids(7) {
        let j = bus.joint(id).unwrap();
        let s = j.status().unwrap();
        assert!(s.error.is_empty(), "{id}: {:?}", s.error);
        assert_eq!(s.position.degrees(), 0.0);
    }
    let j = bus.joint(JointId::new(2).unwrap()).unwrap();
    j.set_mode(WorkMode::Position).unwrap();
    j.enable().unwrap();
    j.command_position(Position::from_degrees(3.0).unwrap())
        .unwrap();
    bus.sleep_until(bus.now() + Duration::from_secs(1));
    let s = j.status().unwrap();
    assert!((s.position.degrees() - 3.0).abs() < 0.01, "{s:?}");
    let at = sim.with_bus(|b| b.joint(2).unwrap().state().position_deg);
    assert!((at - 3.0).abs() < 0.01);
}

#[test]
fn the_cyclic_loop_completes_every_cycle_through_an_slcan_adapter_on_the_virtual_clock() {
    let (bus, _sim) = slcan_bus(7);
    let joints = ids(7);
    for &id in &joints {
        let j = bus.joint(id).unwrap();
        j.set_mode(WorkMode::Position).unwrap();
        j.enable().unwrap();
    }
    let cyc = bus
        .cyclic(CyclicConfig::position(
            joints.clone(),
            Duration::from_millis(4),
        ))
        .unwrap();
    let targets: Vec<Position> = (0..7)
        .map(|i| Position::from_degrees(f64::from(i) - 3.0).unwrap())
        .collect();
    cyc.set_positions(&targets).unwrap();
    bus.sleep_until(bus.now() + Duration::from_millis(400));
    let stats = cyc.stop();
    eprintln!("{stats:#?}");
    assert_eq!(
        (
            stats.cycles,
            stats.complete,
            stats.deadline_misses,
            stats.late_replies
        ),
        (100, 100, 0, 0),
        "{stats:?}"
    );
    // Seven 16-byte feedback lines of 38 characters at 10 µs each reach the host one
    // after the other: a cycle's replies take at least 2.66 ms on the adapter's serial
    // link alone.
    assert!(
        stats.round_trip.p50 >= Duration::from_micros(2660),
        "{stats:?}"
    );
    for (&id, t) in joints.iter().zip(&targets) {
        let s = bus.joint_unchecked(id).status().unwrap();
        assert!(
            (s.position.degrees() - t.degrees()).abs() < 0.2,
            "{id}: {s:?}"
        );
    }
}
