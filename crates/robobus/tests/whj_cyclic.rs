//! The cyclic servo loop against seven simulated joints on the in-process bus:
//! point-to-point and broadcast, statistics, trajectory splitting of far targets.

#![allow(clippy::unwrap_used, clippy::panic, clippy::cast_precision_loss)]

mod whj_common;

use std::time::Duration;

use robobus::whj::{CycleReport, Cyclic, CyclicConfig, JointBus, Protocol, ServoMode, WhjError};
use robobus_whj::units::{Current, Position, TargetSpeed};
use robobus_whj::{ErrorCode, JointId, WorkMode};
use whj_common::{chain, memory};

/// Each test runs a real-time loop against a simulator on the wall clock: one at a time,
/// so that they do not starve each other on a small machine.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

fn ids(n: u8) -> Vec<JointId> {
    (1..=n).map(|i| JointId::new(i).unwrap()).collect()
}

fn deg(d: f64) -> Position {
    Position::from_degrees(d).unwrap()
}

/// The next complete cycle from now (a cycle can miss its deadline on a loaded machine).
fn complete_cycle(cyc: &Cyclic<'_>) -> CycleReport {
    cyc.clear_reports();
    (0..100)
        .filter_map(|_| cyc.next_report(Duration::from_millis(500)))
        .find(|r| !r.missed)
        .expect("no complete cycle in 100")
}

fn ready(bus: &JointBus, joints: &[JointId], mode: WorkMode) {
    for &id in joints {
        let j = bus.joint(id).unwrap();
        j.disable().unwrap();
        j.set_mode(mode).unwrap();
        j.enable().unwrap();
    }
}

#[test]
fn seven_joints_point_to_point_far_targets_become_smooth_moves() {
    let _serial = serial();
    let (_sim, link) = memory(chain(7));
    let bus = JointBus::open_with(link, whj_common::config()).unwrap();
    let joints = ids(7);
    ready(&bus, &joints, WorkMode::Position);
    let cyc = bus
        .cyclic(CyclicConfig::position(
            joints.clone(),
            Duration::from_millis(4),
        ))
        .unwrap();
    assert!(bus.cyclic_running());
    // 40° away from every joint: far beyond the 10° step protection.
    let targets: Vec<Position> = (0..7).map(|i| deg(40.0 - 5.0 * f64::from(i))).collect();
    cyc.set_positions(&targets).unwrap();
    // A single servo command to a joint of the loop is refused while it runs.
    let err = bus
        .joint_unchecked(joints[0])
        .command_position(deg(0.0))
        .unwrap_err();
    assert!(matches!(err, WhjError::Busy { .. }), "{err}");
    // Register traffic still works between the loop's frames.
    assert_eq!(
        bus.joint_unchecked(joints[3]).mode().unwrap(),
        WorkMode::Position
    );

    // 40° at 30 °/s with ramps: about 1.6 s; allow 3 s.
    let mut arrived = false;
    let mut max_step = 0.0f64;
    let mut last_cmd: Option<Vec<i32>> = None;
    for _ in 0..750 {
        let Some(r) = cyc.next_report(Duration::from_millis(200)) else {
            continue;
        };
        if let Some(prev) = &last_cmd {
            for (a, b) in prev.iter().zip(&r.commanded) {
                max_step = max_step.max(f64::from((a - b).abs()) / 10_000.0);
            }
        }
        last_cmd = Some(r.commanded.clone());
        for fb in r.feedback.iter().flatten() {
            assert!(!fb.error.contains(ErrorCode::POSITION_STEP), "{fb:?}");
            assert!(fb.enabled);
        }
        if r.feedback
            .iter()
            .zip(&targets)
            .all(|(fb, t)| fb.is_some_and(|f| (f.position.degrees() - t.degrees()).abs() < 0.1))
        {
            arrived = true;
            break;
        }
    }
    assert!(
        arrived,
        "joints did not reach their targets: {:?}",
        cyc.latest()
    );
    // Set-points move by 30 °/s × 4 ms per cycle. When a stalled machine holds the
    // simulated joint back, the client's step clamp (5° from the actual position; the
    // joint trips at 10°) holds the set-point, which rejoins the profile once released:
    // never a step beyond the clamp.
    assert!(max_step <= 5.0, "largest set-point step {max_step}°");
    let stats = cyc.stop();
    assert!(!bus.cyclic_running());
    eprintln!("point-to-point stats: {stats:#?}");
    assert!(stats.cycles >= 300, "{stats:?}");
    // Most cycles complete (the benchmark measures how many; a shared machine that stalls
    // the simulator's thread makes some miss).
    assert!(
        stats.complete * 2 >= stats.cycles,
        "too many misses: {stats:?}"
    );
    assert_eq!(stats.complete + stats.deadline_misses, stats.cycles);
    assert_eq!(stats.round_trip.samples as u64, stats.complete);
    assert!(stats.round_trip.p50 > Duration::ZERO && stats.round_trip.p50 <= stats.round_trip.p99);
    assert!(stats.round_trip.p99 <= stats.round_trip.max);
    // Every joint is error-free and holds its target after the loop.
    for (&id, t) in joints.iter().zip(&targets) {
        let s = bus.joint_unchecked(id).status().unwrap();
        assert!(s.error.is_empty(), "{id}: {:?}", s.error);
        assert!((s.position.degrees() - t.degrees()).abs() < 0.2);
    }
}

#[test]
fn broadcast_position_for_a_seven_joint_chain() {
    let _serial = serial();
    let (sim, link) = memory(chain(7));
    let bus = JointBus::open_with(link, whj_common::config()).unwrap();
    let joints = ids(7);
    ready(&bus, &joints, WorkMode::Position);
    let cyc = bus
        .cyclic(CyclicConfig {
            protocol: Protocol::Broadcast,
            ..CyclicConfig::position(joints.clone(), Duration::from_millis(2))
        })
        .unwrap();
    let targets: Vec<Position> = (0..7).map(|i| deg(f64::from(i) - 3.0)).collect();
    cyc.set_positions(&targets).unwrap();
    // Within 0.05° of the targets, in well under a second (up to 5 s on a stalled machine).
    let near = |r: &CycleReport| {
        r.feedback
            .iter()
            .zip(&targets)
            .all(|(fb, t)| fb.is_some_and(|f| (f.position.degrees() - t.degrees()).abs() < 0.05))
    };
    let start = std::time::Instant::now();
    let mut r = complete_cycle(&cyc);
    while !near(&r) && start.elapsed() < Duration::from_secs(5) {
        std::thread::sleep(Duration::from_millis(50));
        r = complete_cycle(&cyc);
    }
    for ((fb, t), id) in r.feedback.iter().zip(&targets).zip(&joints) {
        let fb = fb.unwrap_or_else(|| panic!("no broadcast feedback from {id}"));
        assert!(
            (fb.position.degrees() - t.degrees()).abs() < 0.05,
            "{id}: {fb:?}"
        );
        assert!(fb.error.is_empty());
    }
    let stats = cyc.stop();
    eprintln!("broadcast stats: {stats:#?}");
    // The loop ran, and cycles completed (the benchmark measures how many; a shared
    // machine that stalls the simulator's thread makes some miss).
    assert!(stats.cycles >= 50, "{stats:?}");
    assert!(stats.complete >= 20, "{stats:?}");
    drop(bus);
    // One 0x2F frame per cycle, not seven point-to-point frames.
    let (sim_bus, serve) = sim.stop();
    let host_frames = sim_bus.stats().host_frames;
    assert!(
        host_frames < stats.cycles + 200,
        "{host_frames} host frames for {} cycles",
        stats.cycles
    );
    assert!(serve.sent >= stats.complete * 7);
}

#[test]
fn current_loop_point_to_point_and_broadcast() {
    let _serial = serial();
    let (_sim, link) = memory(chain(2));
    let bus = JointBus::open_with(link, whj_common::config()).unwrap();
    let joints = ids(2);
    ready(&bus, &joints, WorkMode::Current);
    for protocol in [Protocol::PointToPoint, Protocol::Broadcast] {
        let cyc = bus
            .cyclic(CyclicConfig {
                mode: ServoMode::Current,
                protocol,
                smooth: None,
                ..CyclicConfig::position(joints.clone(), Duration::from_millis(5))
            })
            .unwrap();
        cyc.set_currents(&[Current(100), Current(-100)]).unwrap();
        let err = cyc.set_positions(&[deg(0.0), deg(0.0)]).unwrap_err();
        assert!(
            err.to_string()
                .contains("Position targets given to a Current loop"),
            "{err}"
        );
        assert!(cyc.set_currents(&[Current(1)]).is_err());
        std::thread::sleep(Duration::from_millis(100));
        // At least eleven complete cycles, each commanding and reading back both joints.
        for _ in 0..11 {
            let r = complete_cycle(&cyc);
            assert_eq!(r.commanded, vec![100, -100]);
            assert!(
                r.feedback.iter().all(Option::is_some),
                "{protocol:?}: {r:?}"
            );
        }
        cyc.set_currents(&[Current(0), Current(0)]).unwrap();
        let stats = cyc.stop();
        assert!(stats.complete > 10, "{protocol:?}: {stats:?}");
    }
}

#[test]
fn speed_loop_point_to_point() {
    let _serial = serial();
    let (_sim, link) = memory(chain(3));
    let bus = JointBus::open_with(link, whj_common::config()).unwrap();
    let joints = ids(3);
    ready(&bus, &joints, WorkMode::Speed);
    let cyc = bus
        .cyclic(CyclicConfig {
            mode: ServoMode::Speed,
            smooth: None,
            ..CyclicConfig::position(joints.clone(), Duration::from_millis(5))
        })
        .unwrap();
    assert_eq!(cyc.joints(), &joints[..]);
    assert_eq!(cyc.config().mode, ServoMode::Speed);
    let rpm = |r: f64| TargetSpeed::from_rpm(r).unwrap();
    cyc.set_speeds(&[rpm(2.0), rpm(-3.0), rpm(0.0)]).unwrap();
    // At speed in well under a second (up to 5 s on a stalled machine).
    let start = std::time::Instant::now();
    let at_speed = |speeds: &[f64]| {
        speeds.len() == 3
            && speeds
                .iter()
                .zip([2.0, -3.0, 0.0])
                .all(|(got, want)| (got - want).abs() < 0.3)
    };
    let mut speeds: Vec<f64> = Vec::new();
    while !at_speed(&speeds) && start.elapsed() < Duration::from_secs(5) {
        std::thread::sleep(Duration::from_millis(50));
        let r = complete_cycle(&cyc);
        speeds = r.feedback.iter().map(|f| f.unwrap().speed.rpm()).collect();
    }
    assert!(at_speed(&speeds), "{speeds:?}");
    assert_eq!(cyc.latest().unwrap().commanded, vec![1000, -1500, 0]);
    // Ten more complete cycles: the statistics count at least those.
    for _ in 0..10 {
        complete_cycle(&cyc);
    }
    cyc.set_speeds(&[rpm(0.0); 3]).unwrap();
    let stats = cyc.stop();
    assert!(stats.complete >= 10, "{stats:?}");
    assert_eq!(
        stats.complete + stats.deadline_misses,
        stats.cycles,
        "{stats:?}"
    );
}

#[test]
fn invalid_configurations_are_refused() {
    let (_sim, link) = memory(chain(1));
    let bus = JointBus::open_with(link, whj_common::config()).unwrap();
    let j8 = JointId::new(8).unwrap();
    let cases = [
        (
            CyclicConfig::position(vec![], Duration::from_millis(2)),
            "no joints",
        ),
        (
            CyclicConfig::position(ids(1).repeat(2), Duration::from_millis(2)),
            "twice",
        ),
        (
            CyclicConfig::position(ids(1), Duration::from_micros(10)),
            "period",
        ),
        (
            CyclicConfig {
                protocol: Protocol::Broadcast,
                ..CyclicConfig::position(vec![j8], Duration::from_millis(2))
            },
            "broadcast slot",
        ),
        (
            CyclicConfig {
                protocol: Protocol::Broadcast,
                mode: ServoMode::Speed,
                ..CyclicConfig::position(ids(1), Duration::from_millis(2))
            },
            "speed",
        ),
    ];
    for (cfg, needle) in cases {
        let err = bus.cyclic(cfg).unwrap_err();
        assert!(err.to_string().contains(needle), "{needle}: {err}");
    }
    // A second loop on the same bus is refused while one runs.
    bus.joint(ids(1)[0]).unwrap();
    let first = bus
        .cyclic(CyclicConfig::position(ids(1), Duration::from_millis(5)))
        .unwrap();
    let err = bus
        .cyclic(CyclicConfig::position(ids(1), Duration::from_millis(5)))
        .unwrap_err();
    assert!(err.to_string().contains("already running"), "{err}");
    drop(first);
    assert!(!bus.cyclic_running());
}
