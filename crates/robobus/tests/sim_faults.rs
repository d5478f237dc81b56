//! The simulators' fault injection, as `robobus sim wck` / `robobus sim whj` apply it from
//! the command line, seen through the client library with the simulators in process:
//!
//! - link faults (`FaultyByteLink` / `FaultyFrameLink`: drop, corrupt, duplicate,
//!   truncate) repeat from their seed: the same seed gives the same outcome of every
//!   transaction, another seed another one;
//! - device faults on a schedule (`robobus_sim::faults`): a silent servo / joint gives the
//!   client a timeout that names it, a power-cycled servo is deaf for 65 ms and then
//!   answers, a power-cycled joint is back in its bootloader until connected again, a
//!   joint that latches error bits reports them in its status.

#![allow(clippy::unwrap_used)] // test code
#![cfg(target_os = "linux")]

use crate::wck_support;
use crate::whj_common;

use std::time::Duration;

use robobus::wck::{WckBus, WckConfig};
use robobus::whj::{JointBus, JointBusConfig};
use robobus_link::{FaultConfig, FaultyByteLink, FaultyFrameLink, MemoryBus};
use robobus_sim::faults::{DeviceFault, DeviceFaultKind, FaultSchedule};
use robobus_sim::whj::{JointConfig, Served, WhjModel};
use robobus_wck::{BaudRate, ServoId};
use robobus_whj::JointId;

fn link_faults(seed: u64) -> FaultConfig {
    FaultConfig {
        drop: 0.02,
        corrupt: 0.02,
        duplicate: 0.02,
        truncate: 0.02,
        ..FaultConfig::seeded(seed)
    }
}

/// 300 status reads of servo 1 through a faulty link, no retries: what each one gave.
///
/// The faults act on the commands (`rx: false`): which reply bytes a client reads and
/// which it flushes as stale depends on the wall clock the in-process link follows, and
/// on the receiving side each byte read draws from the seeded stream. The servo is held
/// (a command corrupted into a move cannot turn it), so every answer reads 127.
fn wck_outcomes(seed: u64) -> Vec<String> {
    let mut sim = wck_support::serve_fast(&[1], BaudRate::B115200);
    sim.with_bus(|b| b.servo_mut(0).unwrap().hold(true));
    let link = FaultyByteLink::new(
        sim.link(),
        FaultConfig {
            rx: false,
            ..link_faults(seed)
        },
    );
    let config = WckConfig {
        retries: 0,
        ..WckConfig::default()
    };
    let mut bus = WckBus::new(link, BaudRate::B115200)
        .unwrap()
        .with_config(config);
    (0..300)
        .map(|_| match bus.servo(ServoId::new(1).unwrap()).status() {
            Ok(s) => format!("ok {}", s.position.get()),
            Err(e) => format!("err timeout={}", e.is_timeout()),
        })
        .collect()
}

#[test]
fn wck_link_faults_repeat_from_their_seed() {
    let a = wck_outcomes(42);
    assert_eq!(a, wck_outcomes(42), "same seed, same outcome");
    let failed = a.iter().filter(|o| o.starts_with("err")).count();
    assert!(
        (5..295).contains(&failed),
        "faults should hit some reads: {failed} of 300 failed"
    );
    assert_ne!(a, wck_outcomes(43), "another seed, other faults");
}

#[test]
fn wck_device_faults_on_schedule_as_the_client_sees_them() {
    let sim = wck_support::serve_fast(&[1, 2], BaudRate::B115200);
    let start = sim.with_bus(|b| b.now());
    let at = start + Duration::from_millis(200);
    let mut schedule = FaultSchedule::new(vec![
        DeviceFault {
            at,
            id: 1,
            kind: DeviceFaultKind::Silent,
        },
        DeviceFault {
            at,
            id: 2,
            kind: DeviceFaultKind::PowerCycle,
        },
    ]);
    let mut sim = sim;
    let handle = sim.handle.clone();
    let config = WckConfig {
        retries: 0,
        ..WckConfig::default()
    };
    let mut bus = WckBus::new(sim.link(), BaudRate::B115200)
        .unwrap()
        .with_config(config);
    let s1 = ServoId::new(1).unwrap();
    let s2 = ServoId::new(2).unwrap();
    // Before the faults both answer, every time.
    while handle.with_bus(|b| b.now()) < at {
        bus.servo(s1).status().unwrap();
        bus.servo(s2).status().unwrap();
    }
    let hit: usize = handle.with_bus(|b| {
        let now = b.now();
        schedule
            .take_due(now)
            .iter()
            .map(|f| b.apply_fault(f))
            .sum()
    });
    assert_eq!(hit, 2);
    // Servo 2 browned out: deaf for the 65 ms after power-up (asked first: after a
    // timeout the client waits out its late-reply window, 50 ms, before the next packet),
    // then back.
    let e = bus.servo(s2).status().unwrap_err();
    assert!(e.is_timeout(), "{e}");
    // Servo 1 is silent: a timeout naming it.
    let e = bus.servo(s1).status().unwrap_err();
    assert!(e.is_timeout(), "{e}");
    assert!(e.to_string().contains('1'), "{e}");
    let back = handle.with_bus(|b| b.now()) + Duration::from_millis(70);
    while handle.with_bus(|b| b.now()) < back {
        let _ = bus.servo(s2).status();
    }
    bus.servo(s2).status().unwrap();
    assert!(bus.servo(s1).status().unwrap_err().is_timeout());
}

fn j(n: u8) -> JointId {
    JointId::new(n).unwrap()
}

/// 200 status queries of joint 1 through a faulty client link, no retries.
///
/// On the simulator's virtual clock: which frames come within a query's wait is then the
/// same on every run. On the wall clock it was not: a late or duplicated frame that a
/// loaded host delivered after the wait instead of within it drew another fault from the
/// seeded stream, and the same seed gave another outcome.
fn whj_outcomes(seed: u64) -> Vec<String> {
    let mut joint = JointConfig::new(1, WhjModel::Whj30);
    // Out of its bootloader from power-up: connecting is no part of what is measured.
    joint.boot.wait_for_iap_flag = false;
    let (link, _sim) = whj_common::sim_link(whj_common::configs(vec![joint]));
    let config = JointBusConfig {
        retries: 0,
        ..whj_common::virtual_config()
    };
    let bus = JointBus::open_with(FaultyFrameLink::new(link, link_faults(seed)), config).unwrap();
    let joint = bus.joint_unchecked(j(1));
    (0..200)
        .map(|_| match joint.status() {
            Ok(s) => format!("ok {:#06x}", s.error.bits()),
            Err(e) => format!("err timeout={}", e.is_timeout()),
        })
        .collect()
}

#[test]
fn whj_link_faults_repeat_from_their_seed() {
    let a = whj_outcomes(42);
    assert_eq!(a, whj_outcomes(42), "same seed, same outcome");
    let failed = a.iter().filter(|o| o.starts_with("err")).count();
    assert!(
        (3..197).contains(&failed),
        "faults should hit some queries: {failed} of 200 failed"
    );
    assert_ne!(a, whj_outcomes(43), "another seed, other faults");
}

#[test]
fn whj_device_faults_on_schedule_as_the_client_sees_them() {
    let at = Duration::from_millis(600);
    let faults = FaultSchedule::new(vec![
        DeviceFault {
            at,
            id: 1,
            kind: DeviceFaultKind::Error(0x4000),
        },
        DeviceFault {
            at,
            id: 2,
            kind: DeviceFaultKind::Silent,
        },
        DeviceFault {
            at,
            id: 3,
            kind: DeviceFaultKind::PowerCycle,
        },
    ]);
    let wire = MemoryBus::new();
    let t0 = std::time::Instant::now();
    let _sim =
        Served::spawn_with("sim-whj", whj_common::chain(3), wire.endpoint(), faults).unwrap();
    let config = JointBusConfig {
        retries: 0,
        ..whj_common::config()
    };
    let bus = JointBus::open_with(wire.endpoint(), config).unwrap();
    let joints: Vec<_> = (1..=3).map(|n| bus.joint(j(n)).unwrap()).collect();
    let before: Vec<u16> = joints
        .iter()
        .map(|jt| jt.status().unwrap().error.bits())
        .collect();
    assert!(
        t0.elapsed() < at,
        "the machine stalled past the faults before the first look ({:?})",
        t0.elapsed()
    );
    assert_eq!(before, [0, 0, 0]);
    std::thread::sleep((at + Duration::from_millis(50)).saturating_sub(t0.elapsed()));

    // Joint 1 reports the latched bits.
    assert_eq!(joints[0].status().unwrap().error.bits() & 0x4000, 0x4000);
    // Joint 2 is silent: a timeout that names it.
    let e = joints[1].status().unwrap_err();
    assert!(e.is_timeout() && e.to_string().contains("J2"), "{e}");
    // Joint 3 browned out: back in its bootloader, silent to a status query until it is
    // connected (released) again.
    assert!(joints[2].status().unwrap_err().is_timeout());
    let again = bus.joint(j(3)).unwrap();
    assert_eq!(again.status().unwrap().error.bits(), 0);
}
