//! Fault tests with the seeded fault injector and scripted bus errors: corrupted frames
//! never become wrong values, an unplugged joint gives a timeout that names it, bus-off
//! is surfaced and recovered from. On the simulator's virtual clock (`WhjSimLink`), so
//! times are exact and seeded faults give the same counts on every run.

#![allow(clippy::unwrap_used)]

use crate::whj_common;

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use robobus::WaitMode;
use robobus::whj::{BusState, JointBus, JointBusConfig, WhjError};
use robobus_link::{
    BusErrorKind, FaultConfig, FaultyFrameLink, FrameLink, FrameLinkError, IdFilter, Received,
};
use robobus_sim::whj::{JointConfig, WhjModel};
use robobus_whj::{CanFrame, JointId};
use whj_common::{chain, configs, sim_link, virtual_config};

fn j(n: u8) -> JointId {
    JointId::new(n).unwrap()
}

#[test]
fn ten_thousand_reads_through_one_percent_corrupted_frames_return_no_wrong_value() {
    // A disabled joint at 12.3456° (brake locked: it does not move).
    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.initial_position_deg = 12.3456;
    let (link, _sim) = sim_link(configs(vec![cfg]));
    let faulty = FaultyFrameLink::new(
        link,
        FaultConfig {
            corrupt: 0.01,
            ..FaultConfig::seeded(7)
        },
    );
    let bus = JointBus::open_with(
        faulty,
        // A short timeout (a corrupted reply is ignored as an answer to something else,
        // and costs one) and enough retries for a run of corrupted frames.
        JointBusConfig {
            verify_reads: true,
            reply_timeout: Duration::from_millis(5),
            retries: 10,
            ..virtual_config()
        },
    )
    .unwrap();
    let joint = bus.joint(j(1)).unwrap();
    joint.disable().unwrap();
    let start = bus.now();
    for i in 0..10_000 {
        let p = joint.position().unwrap_or_else(|e| panic!("read {i}: {e}"));
        assert_eq!(p.raw(), 123_456, "read {i} returned a wrong value");
    }
    let t = bus.telemetry();
    eprintln!(
        "10 000 verified reads in {:?} of simulated time; bus {:?}",
        bus.now() - start,
        t.bus
    );
    // Corruption really happened and was caught: replies that did not fit their request
    // (ignored, the attempt timed out) or did not parse, and more frames than two per
    // read. The fault injector is seeded and the clock virtual: the counts are exact.
    assert_eq!(t.bus.frames_sent, 20_498, "{:?}", t.bus);
    assert_eq!(t.bus.frames_received, 20_498, "{:?}", t.bus);
    assert_eq!(t.bus.unmatched, 99, "{:?}", t.bus);
    assert_eq!(t.bus.malformed, 43, "{:?}", t.bus);
}

#[test]
fn without_read_verification_corrupted_payloads_would_slip_through() {
    // The control experiment for the test above: a CAN controller would drop these frames
    // (CRC), but a link without a checksum delivers them, and a flipped data bit is a
    // plausible value. This is why `verify_reads` exists.
    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.initial_position_deg = 12.3456;
    let (link, _sim) = sim_link(configs(vec![cfg]));
    let faulty = FaultyFrameLink::new(
        link,
        FaultConfig {
            corrupt: 0.05,
            tx: false,
            ..FaultConfig::seeded(7)
        },
    );
    let bus = JointBus::open_with(faulty, virtual_config()).unwrap();
    let joint = bus.joint(j(1)).unwrap();
    joint.disable().unwrap();
    let wrong = (0..2_000)
        .filter(|_| joint.position().unwrap().raw() != 123_456)
        .count();
    assert_eq!(
        wrong, 72,
        "corrupted values that got through without verification"
    );
}

#[test]
fn without_verification_corruption_is_still_never_a_mismatched_reply() {
    // Requests and replies are matched by register and length: a corrupted request (a
    // read of another register or count) or a corrupted header is retried, never returned.
    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.initial_position_deg = -3.0;
    let (link, _sim) = sim_link(configs(vec![cfg]));
    let faulty = FaultyFrameLink::new(
        link,
        FaultConfig {
            corrupt: 0.05,
            tx: true,
            rx: false,
            ..FaultConfig::seeded(3)
        },
    );
    let bus = JointBus::open_with(faulty, virtual_config()).unwrap();
    let joint = bus.joint(j(1)).unwrap();
    joint.disable().unwrap();
    for i in 0..2_000 {
        let p = joint.position().unwrap_or_else(|e| panic!("read {i}: {e}"));
        assert_eq!(p.raw(), -30_000, "read {i}");
    }
}

#[test]
fn an_unplugged_joint_gives_a_timeout_naming_it() {
    // A silent joint costs its timeouts, whether the driver sleeps or spins.
    for wait in [WaitMode::Sleep, WaitMode::SPIN] {
        unplugged_joint(JointBusConfig {
            wait,
            ..virtual_config()
        });
    }
}

fn unplugged_joint(config: JointBusConfig) {
    let (link, sim) = sim_link(chain(2));
    let bus = JointBus::open_with(link, config).unwrap();
    let joint = bus.joint(j(2)).unwrap();
    for _ in 0..100 {
        joint.position().unwrap();
    }
    sim.set_unplugged(true);
    let t = bus.now();
    let err = joint.position().unwrap_err();
    // Three attempts of the reply timeout each, back to back.
    assert_eq!(bus.now() - t, bus.config().reply_timeout * 3);
    let msg = err.to_string();
    assert!(
        matches!(err, WhjError::Timeout { joint, attempts: 3, reply_id: 0x102, .. } if joint == j(2)),
        "{msg}"
    );
    for needle in ["J2", "read reply", "0x102", "3 attempt", "powered"] {
        assert!(msg.contains(needle), "{needle:?} missing in {msg}");
    }
    // A non-idempotent operation is tried once.
    let err = joint.set_zero().unwrap_err();
    assert!(
        matches!(err, WhjError::Timeout { attempts: 1, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("SYS_SET_ZERO_POS"), "{err}");
}

#[test]
fn a_closed_link_stops_the_bus_with_a_clear_error() {
    let (link, _sim) = sim_link(chain(1));
    let faulty = FaultyFrameLink::new(
        link,
        FaultConfig {
            disconnect_after: Some(40),
            ..FaultConfig::seeded(1)
        },
    );
    let bus = JointBus::open_with(faulty, virtual_config()).unwrap();
    let joint = bus.joint(j(1)).unwrap();
    let err = loop {
        if let Err(e) = joint.position() {
            break e;
        }
    };
    assert!(matches!(err, WhjError::Link { .. }), "{err}");
    assert!(err.to_string().contains("disconnected"), "{err}");
    // Later calls report the same cause, not a hang.
    let err = joint.status().unwrap_err();
    assert!(err.to_string().contains("disconnected"), "{err}");
}

/// A link that reports scripted controller errors before passing frames through.
struct ScriptedErrors<L> {
    inner: L,
    script: Arc<Mutex<VecDeque<FrameLinkError>>>,
}

impl<L: FrameLink> FrameLink for ScriptedErrors<L> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        self.inner.send(frame)
    }
    fn recv(&mut self, deadline: Instant) -> Result<Received, FrameLinkError> {
        if let Some(e) = self.script.lock().unwrap().pop_front() {
            return Err(e);
        }
        self.inner.recv(deadline)
    }
    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        self.inner.set_filters(filters)
    }

    robobus_link::forward_frame_link_clock!(inner);
}

fn bus_off() -> FrameLinkError {
    FrameLinkError::BusOff {
        iface: "can0".into(),
    }
}

#[test]
fn bus_off_is_surfaced_and_reads_recover() {
    let (link, _sim) = sim_link(chain(1));
    let script = Arc::new(Mutex::new(VecDeque::new()));
    let link = ScriptedErrors {
        inner: link,
        script: Arc::clone(&script),
    };
    let bus = JointBus::open_with(link, virtual_config()).unwrap();
    let joint = bus.joint(j(1)).unwrap();
    joint.disable().unwrap();
    let before = joint.position().unwrap();

    // Bus-off while a read is in flight: that attempt fails, the retry waits for the
    // recovery (the first reply arriving shows the bus works again) and succeeds.
    script.lock().unwrap().push_back(bus_off());
    assert_eq!(joint.position().unwrap(), before);
    let t = bus.telemetry().bus;
    assert_eq!(t.bus_off_events, 1);
    assert_eq!(t.recoveries, 1);
    assert_eq!(t.state, BusState::Active);
    assert!(t.last_error.unwrap().contains("bus-off"));

    // Without retries the caller sees the bus-off, naming joint and request.
    drop(bus);
    let (link2, _sim2) = sim_link(chain(1));
    let bus = JointBus::open_with(
        ScriptedErrors {
            inner: link2,
            script: Arc::clone(&script),
        },
        JointBusConfig {
            retries: 0,
            ..virtual_config()
        },
    )
    .unwrap();
    let joint = bus.joint(j(1)).unwrap();
    script.lock().unwrap().push_back(bus_off());
    let err = joint.position().unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(
            err,
            WhjError::Bus {
                bus_state: BusState::BusOff,
                ..
            }
        ),
        "{msg}"
    );
    assert!(
        msg.contains("J1") && msg.contains("CUR_POSITION_L") && msg.contains("bus-off"),
        "{msg}"
    );
    // A restart report recovers the bus; requests work again.
    script.lock().unwrap().push_back(FrameLinkError::BusError {
        iface: "can0".into(),
        kind: BusErrorKind::Restarted,
    });
    joint.position().unwrap();
    assert_eq!(bus.telemetry().bus.state, BusState::Active);
}

#[test]
fn error_passive_is_reported_and_does_not_stop_traffic() {
    let (link, _sim) = sim_link(chain(1));
    let script = Arc::new(Mutex::new(VecDeque::new()));
    let bus = JointBus::open_with(
        ScriptedErrors {
            inner: link,
            script: Arc::clone(&script),
        },
        JointBusConfig {
            error_passive_hold: Duration::from_millis(100),
            ..virtual_config()
        },
    )
    .unwrap();
    let joint = bus.joint(j(1)).unwrap();
    script
        .lock()
        .unwrap()
        .push_back(FrameLinkError::ErrorPassive {
            iface: "can0".into(),
        });
    joint.status().unwrap();
    let t = bus.telemetry().bus;
    assert_eq!(t.state, BusState::ErrorPassive);
    assert_eq!(t.error_passive_events, 1);
    // No new report for the hold time: recovered.
    bus.sleep_until(bus.now() + Duration::from_millis(150));
    joint.status().unwrap();
    let t = bus.telemetry().bus;
    assert_eq!(t.state, BusState::Active);
    assert_eq!(t.recoveries, 1);
}

/// Two WHJ30 joints that both answer as J1, at 0° and 50° (disabled: they stay there).
fn two_at_one_id() -> robobus_sim::whj::WhjBus {
    let a = JointConfig::new(1, WhjModel::Whj30);
    let mut b = JointConfig::new(1, WhjModel::Whj30);
    b.initial_position_deg = 50.0;
    b.unique_id = [9, 9, 9, 9, 9, 9];
    configs(vec![a, b])
}

#[test]
fn two_joints_answering_as_one_id_are_a_duplicate_fault_naming_both_values_every_time() {
    let (bus, _sim) = whj_common::virtual_bus(two_at_one_id());
    // Every status, every time: never 0° or 50° as if one joint had answered.
    for run in 0..4 {
        let r = robobus::ops::whj::status(&bus, &[j(1)]);
        let f = r[0].failure().unwrap_or_else(|| panic!("run {run}: {r:?}"));
        assert_eq!(f.kind, robobus::ErrorKind::Device, "run {run}: {f:?}");
        assert!(
            f.error.contains("two different replies"),
            "run {run}: {f:?}"
        );
        // Deterministic: the duplicate check finds them on every run.
        let d = robobus::ops::whj::duplicates_of(&bus, j(1))
            .unwrap_or_else(|| panic!("run {run}: no duplicate found"));
        assert_eq!(d.id, 1);
    }
    // A position read names both positions.
    let e = bus.joint_unchecked(j(1)).position().unwrap_err();
    let text = e.to_string();
    assert!(matches!(e, WhjError::DuplicateReply { .. }), "{e}");
    assert!(
        text.contains("0.0000") && text.contains("50.0000"),
        "{text}"
    );
    assert_eq!(e.kind(), robobus::ErrorKind::Device);
    assert!(
        bus.telemetry().bus.duplicates >= 5,
        "{:?}",
        bus.telemetry().bus
    );
}
