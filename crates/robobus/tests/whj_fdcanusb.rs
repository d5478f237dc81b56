//! The client over mjbots' fdcanusb on the simulator's virtual clock: `FdcanusbLink` on an
//! emulated fdcanusb (`AdapterSimLink`) in front of simulated joints, every character of
//! the adapter's text lines on its serial time.
//!
//! An fdcanusb cannot send a frame without data bytes (its firmware refuses `can std`
//! without data), and WHJ's point-to-point status query (`0x600+ID`) is such a frame: a
//! joint's status is read through it with the broadcast status query (0x7F), and the
//! point-to-point query is refused on the host, naming why, with nothing sent.

#![allow(clippy::unwrap_used, clippy::panic)]

mod whj_common;

use robobus::ops::whj::{broadcast_status, connect_for_broadcast};
use robobus::whj::JointBus;
use robobus_link::{FdcanusbConfig, FdcanusbLink, FrameLink};
use robobus_sim::whj::adapter::{AdapterSimLink, FdcanusbAdapter};
use robobus_sim::whj::{WhjSimHandle, WhjSimLink};
use robobus_whj::JointId;
use whj_common::{chain, virtual_config};

/// `n` joints behind an emulated fdcanusb, on the virtual clock.
fn fdcanusb_bus(n: u8) -> (JointBus, WhjSimHandle) {
    let (sim, handle) = WhjSimLink::new(chain(n));
    let port = AdapterSimLink::new(Box::new(FdcanusbAdapter::default()), sim);
    let link = FdcanusbLink::open(port, "sim", FdcanusbConfig::default()).unwrap();
    assert!(link.virtual_time());
    (JointBus::open_with(link, virtual_config()).unwrap(), handle)
}

fn ids(n: u8) -> Vec<JointId> {
    (1..=n).map(|i| JointId::new(i).unwrap()).collect()
}

#[test]
fn joints_connect_and_report_their_status_by_broadcast_through_an_fdcanusb() {
    let (bus, sim) = fdcanusb_bus(7);
    let joints = ids(7);
    assert_eq!(connect_for_broadcast(&bus, &joints), 7);
    let rows = broadcast_status(&bus, &joints).unwrap();
    assert_eq!(rows.len(), 7);
    for (row, id) in rows.iter().zip(1u8..) {
        let robobus::ops::Outcome::Ok(report) = &row.outcome else {
            panic!("{id}: {row:?}");
        };
        let at = sim.with_bus(|b| b.joint(id).unwrap().state().position_deg);
        assert_eq!(row.id, id);
        assert!(
            (report.position_deg - at).abs() < 1e-3,
            "{id}: {report:?} at {at}"
        );
        assert_eq!(report.error, "no error", "{id}: {report:?}");
    }
}

#[test]
fn a_point_to_point_status_query_is_refused_on_the_host_naming_why_and_nothing_is_sent() {
    let (bus, sim) = fdcanusb_bus(1);
    let j = bus.joint(JointId::new(1).unwrap()).unwrap();
    let before = sim.with_bus(|b| b.stats().host_frames);
    let msg = j.status().unwrap_err().to_string();
    assert!(
        msg.contains("an fdcanusb cannot send a frame without data bytes")
            && msg.contains("0x600+ID")
            && msg.contains("whj status --broadcast"),
        "{msg}"
    );
    assert_eq!(sim.with_bus(|b| b.stats().host_frames), before);
}
