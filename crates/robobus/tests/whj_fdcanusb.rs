//! The client over mjbots' fdcanusb on the simulator's virtual clock: `FdcanusbLink` on an
//! emulated fdcanusb (`AdapterSimLink`) in front of simulated joints, every character of
//! the adapter's text lines on its serial time, so the suites see the adapter's timing
//! exactly, whatever the machine's load.
//!
//! An fdcanusb cannot send a frame without data bytes (its firmware refuses `can std`
//! without data), and WHJ's point-to-point status query (`0x600+ID`) is such a frame: the
//! bus asks a joint's status with the broadcast status query (0x7F) instead. Joints
//! connect, report, move, and the cyclic loop completes every cycle at a period the
//! adapter carries.

#![allow(clippy::unwrap_used, clippy::float_cmp)] // test code

use crate::whj_common;

use std::time::Duration;

use robobus::whj::{CyclicConfig, JointBus};
use robobus_link::{FdcanusbConfig, FdcanusbLink, FrameLink};
use robobus_sim::whj::adapter::{AdapterSimLink, FdcanusbAdapter};
use robobus_sim::whj::{WhjBus, WhjModel, WhjSimHandle, WhjSimLink};
use robobus_whj::units::Position;
use robobus_whj::{JointId, WorkMode};
use whj_common::{chain, virtual_config};

/// The joints of `sim` behind an emulated fdcanusb, on the virtual clock.
fn fdcanusb_bus_of(sim: WhjBus) -> (JointBus, WhjSimHandle) {
    let (sim, handle) = WhjSimLink::new(sim);
    let port = AdapterSimLink::new(Box::new(FdcanusbAdapter::default()), sim);
    let link = FdcanusbLink::open(port, "sim", FdcanusbConfig::default()).unwrap();
    assert!(link.virtual_time());
    assert!(!link.sends_empty_frames());
    (JointBus::open_with(link, virtual_config()).unwrap(), handle)
}

fn fdcanusb_bus(n: u8) -> (JointBus, WhjSimHandle) {
    fdcanusb_bus_of(chain(n))
}

fn ids(n: u8) -> Vec<JointId> {
    (1..=n).map(|i| JointId::new(i).unwrap()).collect()
}

/// The status queries (`0x600+ID`, no data) that reached the joints' bus.
fn status_queries(sim: &WhjSimHandle) -> usize {
    sim.with_bus(|b| {
        b.trace()
            .iter()
            .filter(|w| (0x601..=0x61E).contains(&w.frame.raw_id()))
            .count()
    })
}

#[test]
fn joints_connect_report_and_move_through_an_fdcanusb_on_the_virtual_clock() {
    let (bus, sim) = fdcanusb_bus_of(chain(7).with_trace());
    for id in ids(7) {
        let j = bus.joint(id).unwrap();
        let s = j.status().unwrap();
        assert!(s.error.is_empty(), "{id}: {:?}", s.error);
        assert_eq!(s.position.degrees(), 0.0);
        assert!(s.current.is_some());
    }
    let j = bus.joint(JointId::new(2).unwrap()).unwrap();
    j.set_mode(WorkMode::Position).unwrap();
    j.enable().unwrap();
    assert!(j.status().unwrap().is_enabled());
    j.command_position(Position::from_degrees(3.0).unwrap())
        .unwrap();
    bus.sleep_until(bus.now() + Duration::from_secs(1));
    let s = j.status().unwrap();
    assert!((s.position.degrees() - 3.0).abs() < 0.01, "{s:?}");
    let at = sim.with_bus(|b| b.joint(2).unwrap().state().position_deg);
    assert!((at - 3.0).abs() < 0.01);
    // Every status was asked by broadcast.
    assert_eq!(status_queries(&sim), 0);
}

#[test]
fn a_status_query_to_a_joint_without_a_broadcast_slot_is_refused_naming_why() {
    let (bus, sim) = fdcanusb_bus_of(WhjBus::chain([8], WhjModel::Whj30, 7).with_trace());
    let j = bus.joint(JointId::new(8).unwrap()).unwrap();
    let msg = j.status().unwrap_err().to_string();
    assert!(
        msg.contains("cannot send the status query (0x600+ID, a frame without data)")
            && msg.contains("joints 1..=7 only"),
        "{msg}"
    );
    assert_eq!(status_queries(&sim), 0);
}

#[test]
fn the_cyclic_loop_completes_every_cycle_through_an_fdcanusb_on_the_virtual_clock() {
    let (bus, _sim) = fdcanusb_bus(7);
    let joints = ids(7);
    for &id in &joints {
        let j = bus.joint(id).unwrap();
        j.set_mode(WorkMode::Position).unwrap();
        j.enable().unwrap();
    }
    let cyc = bus
        .cyclic(CyclicConfig::position(
            joints.clone(),
            Duration::from_millis(10),
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
        (40, 40, 0, 0),
        "{stats:?}"
    );
    // Seven 16-byte feedback lines of at least 55 characters at 10 µs each reach the host
    // one after the other: a cycle's replies take at least 3.85 ms on the adapter's
    // serial link alone.
    assert!(
        stats.round_trip.p50 >= Duration::from_micros(3850),
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
