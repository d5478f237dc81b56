//! Every public `Joint` operation against the simulated joints, on the simulator's
//! virtual clock (`WhjSimLink`: the client drives the simulated bus itself, no thread, no
//! wall clock), so times and counts are exact.

#![allow(clippy::unwrap_used)]

use crate::whj_common;

use std::time::Duration;

use robobus::whj::{JointBusConfig, MotionLimits, WhjError};
use robobus_sim::whj::{JointConfig, WhjModel};
use robobus_whj::units::{Position, TargetSpeed};
use robobus_whj::{ErrorCode, JointId, Reply, Request, WorkMode};
use whj_common::{chain, configs, virtual_bus, virtual_bus_with};

fn j(n: u8) -> JointId {
    JointId::new(n).unwrap()
}

fn deg(d: f64) -> Position {
    Position::from_degrees(d).unwrap()
}

/// No retries: a frame dropped by the simulator (e.g. inside a settle time) fails the test.
fn strict() -> JointBusConfig {
    JointBusConfig {
        retries: 0,
        ..whj_common::virtual_config()
    }
}

#[test]
fn connect_releases_iap_and_identifies() {
    let mut cfg = JointConfig::new(3, WhjModel::Whj60);
    cfg.unique_id = [0x1111, 0x2222, 0x3333, 0x4444, 0x5555, 0x6666];
    let (bus, _sim) = virtual_bus_with(configs(vec![cfg]), strict());

    // Still in the bootloader: a read is dropped, and the timeout names the joint and
    // the reply it waited for.
    let err = bus.joint_unchecked(j(3)).position().unwrap_err();
    let msg = err.to_string();
    assert!(err.is_timeout(), "{msg}");
    assert!(
        msg.contains("J3") && msg.contains("0x103") && msg.contains("read reply"),
        "{msg}"
    );
    assert!(msg.contains("CUR_POSITION_L (0x14)"), "{msg}");

    let joint = bus.joint(j(3)).unwrap();
    let id = joint.identity().unwrap();
    assert_eq!(id.model.name(), "WHJ60");
    assert_eq!(id.firmware.to_string(), "D522");
    assert_eq!(id.node_id, 3);
    assert_eq!(id.reduction_ratio, 100);
    assert_eq!(id.signature, 0x1314);
    assert_eq!(
        id.unique_id.0,
        [0x1111, 0x2222, 0x3333, 0x4444, 0x5555, 0x6666]
    );
    assert_eq!(id.current_scale().ma_per_count(), 2);
    // Now the application runs and answers.
    assert_eq!(joint.position().unwrap(), Position(0));
    // identify() reads again and agrees.
    assert_eq!(joint.identify().unwrap(), id);
}

#[test]
fn connect_keeps_trying_through_a_staggered_power_up() {
    let mut cfg = JointConfig::new(2, WhjModel::Whj10B);
    cfg.boot.boot_delay = Duration::from_millis(300);
    let (bus, _sim) = virtual_bus(configs(vec![cfg]));
    let t = bus.now();
    let joint = bus.joint(j(2)).unwrap();
    // The joint answers from 300 ms on; a release goes out at most one reply timeout plus
    // the 5 ms pause later and is answered within a millisecond.
    let took = bus.now() - t;
    let timeout = bus.config().reply_timeout;
    assert!(
        took >= Duration::from_millis(300) && took <= Duration::from_millis(306) + timeout,
        "{took:?}"
    );
    assert_eq!(joint.identity().unwrap().model.name(), "WHJ10");
}

#[test]
fn a_silent_joint_gives_a_clear_message() {
    let (bus, _sim) = virtual_bus_with(
        chain(2),
        // Nothing answers: the default reply timeout, 150 ms of attempts.
        JointBusConfig {
            connect_timeout: Duration::from_millis(150),
            ..JointBusConfig::default()
        },
    );
    let t = bus.now();
    let err = bus.joint(j(5)).unwrap_err();
    // Attempt k ends at 20 k + 5 (k - 1) ms (20 ms timeout, 5 ms pause): the first end at
    // or past 150 ms is the seventh, at 170 ms.
    assert_eq!(bus.now() - t, Duration::from_millis(170));
    assert!(
        matches!(err, WhjError::Silent { joint, attempts: 7, waited } if joint == j(5) && waited == Duration::from_millis(170)),
        "{err:?}"
    );
    let msg = err.to_string();
    for needle in ["J5", "IAP", "node ID", "1 Mbit/s", "5 Mbit/s"] {
        assert!(msg.contains(needle), "{needle:?} missing in {msg}");
    }
    // The joints that exist are unaffected.
    assert!(bus.joint(j(2)).is_ok());
}

#[test]
fn enable_disable_modes_and_settle_times() {
    let (bus, sim) = virtual_bus_with(chain(1), strict());
    let joint = bus.joint(j(1)).unwrap();
    assert_eq!(joint.mode().unwrap(), WorkMode::Position);
    joint.set_mode(WorkMode::Speed).unwrap();
    assert_eq!(joint.mode().unwrap(), WorkMode::Speed);
    joint.set_mode(WorkMode::Position).unwrap();
    // SYS_ENABLE_ON_POWER = 1 (factory default): the application starts enabled.
    assert!(joint.is_enabled().unwrap());
    joint.disable().unwrap();
    assert!(!joint.is_enabled().unwrap());
    joint.enable().unwrap();
    assert!(joint.is_enabled().unwrap());
    assert!(joint.status().unwrap().is_enabled());
    // The simulator drops every frame for 5 ms after a disable; with no retries, the read
    // right after only succeeds because the bus holds it back for the settle time: it
    // goes out exactly 5 ms after the disable's acknowledgement and is answered within
    // 1 ms.
    for _ in 0..3 {
        joint.disable().unwrap();
        let t = bus.now();
        assert!(!joint.is_enabled().unwrap());
        let took = bus.now() - t;
        assert!(
            took > Duration::from_millis(5) && took < Duration::from_millis(6),
            "{took:?}"
        );
        joint.enable().unwrap();
    }
    joint.disable().unwrap();
    drop(bus);
    assert!(!sim.with_bus(|b| b.joint(1).unwrap().state().enabled));
}

#[test]
fn save_to_flash_is_refused_while_enabled_and_settles_after() {
    let (bus, sim) = virtual_bus_with(chain(1), strict());
    let joint = bus.joint(j(1)).unwrap();
    joint.set_position_limits(deg(-45.0), deg(45.0)).unwrap();
    joint.enable().unwrap();
    let sent_before = bus.telemetry().bus.frames_sent;
    let err = joint.save_to_flash().unwrap_err();
    assert!(
        matches!(err, WhjError::SaveWhileEnabled { joint } if joint == j(1)),
        "{err}"
    );
    assert!(err.to_string().contains("disable it first"), "{err}");
    // Only the enable-state read went out, no save.
    assert_eq!(bus.telemetry().bus.frames_sent, sent_before + 1);
    joint.disable().unwrap();
    joint.save_to_flash().unwrap();
    // 50 ms busy after the save: the next request waits instead of being dropped.
    let t = bus.now();
    assert_eq!(joint.position_limits().unwrap(), (deg(-45.0), deg(45.0)));
    let took = bus.now() - t;
    assert!(
        took > Duration::from_millis(50) && took < Duration::from_millis(51),
        "{took:?}"
    );
    // The limits survive a power cycle now.
    sim.with_bus(robobus_sim::whj::WhjBus::power_cycle_all);
    let joint = bus.joint(j(1)).unwrap();
    assert_eq!(joint.position_limits().unwrap(), (deg(-45.0), deg(45.0)));
}

#[test]
fn limits_and_registers_by_name_with_units() {
    let (bus, _sim) = virtual_bus(chain(1));
    let joint = bus.joint(j(1)).unwrap();
    assert_eq!(joint.position_limits().unwrap(), (deg(-360.0), deg(360.0)));
    joint.set_position_limits(deg(-90.0), deg(120.5)).unwrap();
    assert_eq!(joint.position_limits().unwrap(), (deg(-90.0), deg(120.5)));
    let max = joint.read_register("lit_max_position").unwrap();
    assert_eq!(max.raw, 1_205_000);
    assert!((max.value.unwrap() - 120.5).abs() < 1e-9);
    assert_eq!(max.unit, "°");
    assert_eq!(max.to_string(), "LIT_MAX_POSITION = 120.5 ° (raw 1205000)");
    let err = joint
        .set_position_limits(deg(10.0), deg(-10.0))
        .unwrap_err();
    assert!(err.to_string().contains("above max"), "{err}");

    let v = joint.read_register("SYS_VOLTAGE").unwrap();
    assert_eq!(v.unit, "V");
    assert!((v.value.unwrap() - 24.0).abs() < 0.5, "{v}");
    let t = joint.read_register("sys_temp").unwrap();
    assert!((t.value.unwrap() - 25.0).abs() < 2.0, "{t}");
    assert_eq!(joint.read_register("TAG_WORK_MODE").unwrap().raw, 3);

    joint.write_register("LIT_MAX_ACC", 400.0).unwrap(); // rpm/s → 0.1 rpm/s counts
    assert_eq!(joint.read_register("LIT_MAX_ACC").unwrap().raw, 4000);
    joint.write_register("TAG_SPEED", 5.0).unwrap(); // RPM → 0.002 RPM counts
    assert_eq!(joint.read_register("TAG_SPEED").unwrap().raw, 2500);
    joint.write_register_raw("TAG_POSITION", -12_345).unwrap();
    assert_eq!(joint.read_register("tag_position").unwrap().raw, -12_345);

    // Refused on the host, nothing sent.
    let sent = bus.telemetry().bus.frames_sent;
    let err = joint.write_register("SYS_VOLTAGE", 30.0).unwrap_err();
    assert!(err.to_string().contains("read-only"), "{err}");
    let err = joint.write_register_raw("TAG_WORK_MODE", 9).unwrap_err();
    assert!(
        err.to_string().contains("TAG_WORK_MODE") && err.to_string().contains("0..=3"),
        "{err}"
    );
    let err = joint.read_register("NO_SUCH_REGISTER").unwrap_err();
    assert!(matches!(err, WhjError::UnknownRegister { .. }), "{err}");
    assert_eq!(bus.telemetry().bus.frames_sent, sent);

    // Bypassing the host's check with a raw request: the joint answers CMD_ERR
    // (permission), returned as a reply by the raw interface.
    let reply = bus
        .request(Request::Write {
            joint: j(1),
            addr: robobus_whj::registers::addr::SYS_VOLTAGE,
            data: robobus_whj::WriteData::Word(1),
        })
        .unwrap();
    assert!(
        matches!(
            reply,
            Reply::CmdErr {
                error: robobus_whj::CmdError::Permission,
                ..
            }
        ),
        "{reply:?}"
    );

    // A write the joint refuses (a reserved address) names the register.
    let err = joint
        .write_word(robobus_whj::RegisterAddr::new(0x3A).unwrap(), 1)
        .unwrap_err();
    assert!(
        matches!(err, WhjError::WriteRefused { addr: 0x3A, .. }),
        "{err}"
    );
}

#[test]
fn position_commands_step_limit_and_smooth_moves() {
    let (bus, _sim) = virtual_bus(chain(1));
    let joint = bus.joint(j(1)).unwrap();
    joint.set_mode(WorkMode::Position).unwrap();
    joint.enable().unwrap();
    let fb = joint.command_position(deg(4.0)).unwrap();
    assert!(fb.is_enabled() && fb.error.is_empty());
    assert!(
        fb.position.degrees().abs() < 0.01,
        "feedback is the position before moving"
    );
    bus.sleep_until(bus.now() + Duration::from_millis(600));
    assert!((joint.position().unwrap().degrees() - 4.0).abs() < 0.05);

    // 30° away: refused on the host before anything is sent.
    let sent = bus.telemetry().bus.frames_sent;
    let err = joint.command_position(deg(34.0)).unwrap_err();
    assert!(matches!(err, WhjError::StepTooLarge { .. }), "{err}");
    assert!(err.to_string().contains("move_to"), "{err}");
    assert_eq!(bus.telemetry().bus.frames_sent, sent);

    // move_to splits 86° into small steps: the joint arrives without error 0x4000.
    let limits = MotionLimits {
        max_speed_deg_s: 90.0,
        max_accel_deg_s2: 360.0,
        ..MotionLimits::default()
    };
    let t = bus.now();
    let fb = joint.move_to(deg(90.0), limits).unwrap();
    assert!((fb.position.degrees() - 90.0).abs() <= 0.1, "{fb:?}");
    assert!(fb.error.is_empty(), "{:?}", fb.error);
    assert!(
        bus.now() - t >= Duration::from_millis(950),
        "a 86° move at 90 °/s takes > 0.95 s"
    );
    let back = joint.move_to(deg(-20.0), limits).unwrap();
    assert!((back.position.degrees() + 20.0).abs() <= 0.1);
    assert!(joint.status().unwrap().error.is_empty());
    let bad = MotionLimits {
        max_speed_deg_s: 0.0,
        ..MotionLimits::default()
    };
    assert!(matches!(
        joint.move_to(deg(0.0), bad),
        Err(WhjError::InvalidConfig { .. })
    ));
}

#[test]
fn step_error_clear_error_and_refused_enable() {
    let (bus, _sim) = virtual_bus(chain(1));
    let joint = bus.joint(j(1)).unwrap();
    joint.enable().unwrap();
    // Bypass the host's check with a raw request: a 20° step latches 0x4000.
    let reply = bus
        .request(Request::PositionServo {
            joint: j(1),
            target: deg(20.0),
        })
        .unwrap();
    assert!(matches!(reply, Reply::ServoFeedback { .. }));
    let code = joint.status().unwrap().error;
    assert!(code.contains(ErrorCode::POSITION_STEP), "{code:?}");
    assert_eq!(joint.error_code().unwrap(), code);
    // Enable with the bit latched is refused, with the bits in the error.
    let err = joint.enable().unwrap_err();
    assert!(
        matches!(err, WhjError::EnableRefused { code, .. } if code.contains(ErrorCode::POSITION_STEP)),
        "{err}"
    );
    assert!(err.to_string().contains("clear_error"), "{err}");
    assert_eq!(joint.clear_error().unwrap(), ErrorCode::NONE);
    joint.set_mode(WorkMode::Position).unwrap();
    joint.enable().unwrap();
    assert!(joint.status().unwrap().is_enabled());
}

#[test]
fn set_zero_makes_the_present_position_zero() {
    let (bus, _sim) = virtual_bus(configs(vec![{
        let mut c = JointConfig::new(1, WhjModel::Whj30);
        c.initial_position_deg = 12.5;
        c
    }]));
    let joint = bus.joint(j(1)).unwrap();
    assert!((joint.position().unwrap().degrees() - 12.5).abs() < 0.01);
    joint.set_zero().unwrap();
    assert!(joint.position().unwrap().degrees().abs() < 0.01);
}

#[test]
fn speed_and_current_commands_with_feedback() {
    let (bus, _sim) = virtual_bus(chain(2));
    let joint = bus.joint(j(2)).unwrap();
    joint.set_mode(WorkMode::Speed).unwrap();
    joint.enable().unwrap();
    let fb = joint
        .command_speed(TargetSpeed::from_rpm(5.0).unwrap())
        .unwrap();
    assert!(fb.is_enabled());
    bus.sleep_until(bus.now() + Duration::from_millis(500));
    let rpm = joint.speed().unwrap().rpm();
    assert!((rpm - 5.0).abs() < 0.5, "{rpm} RPM");
    let fb = joint.command_speed(TargetSpeed(0)).unwrap();
    assert!((fb.speed.rpm() - 5.0).abs() < 0.5);
    bus.sleep_until(bus.now() + Duration::from_millis(300));
    assert!(joint.speed().unwrap().rpm().abs() < 0.2);

    joint.disable().unwrap();
    joint.set_mode(WorkMode::Current).unwrap();
    joint.enable().unwrap();
    let fb = joint.command_current(300.0).unwrap();
    assert!(fb.is_enabled() && fb.error.is_empty());
    let fb = joint.command_current(0.0).unwrap();
    assert!(fb.is_enabled());
    joint.disable().unwrap();
    let err = joint.command_current(1e12).unwrap_err();
    assert!(matches!(err, WhjError::Unit { .. }), "{err}");
}

#[test]
fn status_and_telemetry() {
    let (bus, _sim) = virtual_bus(chain(2));
    let joint = bus.joint(j(1)).unwrap();
    joint.disable().unwrap();
    let s = joint.status().unwrap();
    assert!((s.voltage.volts() - 24.0).abs() < 0.5);
    assert!((s.temperature.celsius() - 25.0).abs() < 2.0);
    assert!(!s.is_enabled());
    assert!(
        s.brake_locked(),
        "a WHJ30 (B) locks its brake when disabled"
    );
    assert!(s.error.is_empty());
    let t = bus.telemetry();
    let jt = t.joint(j(1));
    assert_eq!(jt.enabled, Some(false));
    assert_eq!(jt.voltage, Some(s.voltage));
    // IAP release, the two identity reads, the disable and the status query.
    assert_eq!(jt.replies, 5);
    assert!(t.joint(j(2)).updated.is_none());
    assert_eq!(t.bus.state, robobus::whj::BusState::Active);
    assert_eq!(t.bus.frames_sent, t.bus.frames_received);
    assert_eq!(t.bus.malformed, 0);
    assert_eq!(joint.id(), j(1));
    assert_eq!(
        joint.bus().config().reply_timeout,
        JointBusConfig::default().reply_timeout
    );

    // Raw requests: one attempt with the timeout given; broadcast frames are refused.
    let t = bus.now();
    let err = bus
        .request_with_timeout(
            Request::StatusQuery { joint: j(9) },
            Duration::from_millis(5),
        )
        .unwrap_err();
    assert_eq!(bus.now() - t, Duration::from_millis(5));
    assert!(
        matches!(
            err,
            WhjError::Timeout {
                attempts: 1,
                reply_id: 0x709,
                ..
            }
        ),
        "{err}"
    );
    let broadcast = Request::BroadcastStatus(robobus_whj::BroadcastStatus::new(
        robobus_whj::ReplyMask::ALL,
    ));
    assert!(matches!(
        bus.request(broadcast),
        Err(WhjError::InvalidConfig { .. })
    ));
}

#[test]
fn handles_work_from_several_threads() {
    let (bus, _sim) = virtual_bus(chain(3));
    for n in 1..=3 {
        bus.joint(j(n)).unwrap();
    }
    std::thread::scope(|s| {
        for n in 1..=3u8 {
            let bus = &bus;
            s.spawn(move || {
                let joint = bus.joint_unchecked(j(n));
                joint
                    .set_position_limits(deg(-f64::from(n)), deg(f64::from(n)))
                    .unwrap();
                for _ in 0..50 {
                    assert_eq!(
                        joint.position_limits().unwrap(),
                        (deg(-f64::from(n)), deg(f64::from(n)))
                    );
                    assert_eq!(joint.identity().unwrap().node_id, u16::from(n));
                }
            });
        }
    });
}

#[test]
fn pipelined_requests_go_out_together_and_each_reply_is_credited_to_its_own() {
    let (bus, sim) = virtual_bus(chain(3).with_trace());
    for n in 1..=3 {
        bus.joint(j(n)).unwrap();
    }
    let traced = sim.with_bus(|b| b.trace().len());
    let t = bus.now();
    // Joint 4 does not exist; the three others answer, each its own request.
    let requests = [4, 3, 1, 2].map(|n| Request::StatusQuery { joint: j(n) });
    let replies = bus.request_many(&requests).unwrap();
    assert!(
        matches!(&replies[0], Err(WhjError::Timeout { joint, attempts: 1, reply_id: 0x704, .. }) if *joint == j(4)),
        "{:?}",
        replies[0]
    );
    for (reply, n) in replies[1..].iter().zip([3, 1, 2]) {
        assert!(
            matches!(reply, Ok(Reply::Status { joint, .. }) if *joint == j(n)),
            "{reply:?}"
        );
    }
    // The batch took exactly the one reply timeout of the silent joint.
    assert_eq!(bus.now() - t, bus.config().reply_timeout);
    // All four requests were on the wire before the first reply (send all, then collect).
    let wire = sim.with_bus(|b| b.trace()[traced..].to_vec());
    let sources: Vec<bool> = wire
        .iter()
        .map(|w| w.source == robobus_sim::whj::Node::Host)
        .collect();
    assert_eq!(sources, [true, true, true, true, false, false, false]);
    // Broadcast requests and oversized batches are refused before anything is sent.
    let sent = bus.telemetry().bus.frames_sent;
    let broadcast = Request::BroadcastStatus(robobus_whj::BroadcastStatus::new(
        robobus_whj::ReplyMask::ALL,
    ));
    assert!(matches!(
        bus.request_many(&[requests[1], broadcast]),
        Err(WhjError::InvalidConfig { .. })
    ));
    let many = vec![requests[1]; robobus::whj::MAX_PIPELINED + 1];
    assert!(matches!(
        bus.request_many(&many),
        Err(WhjError::InvalidConfig { .. })
    ));
    assert_eq!(bus.telemetry().bus.frames_sent, sent);
}

#[test]
fn connecting_many_joints_costs_an_absent_ones_connect_timeout_once() {
    let (bus, _sim) = virtual_bus_with(
        chain(3),
        JointBusConfig {
            connect_timeout: Duration::from_millis(150),
            ..JointBusConfig::default()
        },
    );
    let t = bus.now();
    let joints = bus.joints(&[j(1), j(5), j(2), j(6), j(3)]);
    // Two absent IDs, tried together: 7 attempts each, 170 ms (see
    // a_silent_joint_gives_a_clear_message), then the three joints found are identified.
    let took = bus.now() - t;
    assert!(
        took >= Duration::from_millis(170) && took < Duration::from_millis(175),
        "{took:?}"
    );
    let ok: Vec<u8> = joints
        .iter()
        .filter_map(|r| r.as_ref().ok().map(|jt| jt.id().get()))
        .collect();
    assert_eq!(ok, [1, 2, 3]);
    for (r, n) in [(&joints[1], 5), (&joints[3], 6)] {
        assert!(
            matches!(r, Err(WhjError::Silent { joint, attempts: 7, .. }) if *joint == j(n)),
            "{:?}",
            r.as_ref().err()
        );
    }
    assert_eq!(
        joints[2].as_ref().unwrap().identity().unwrap().node_id,
        2,
        "identified at connect"
    );
}
