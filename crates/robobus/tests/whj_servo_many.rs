//! `JointBus::servo_many`: servo frames to many joints in one pipelined batch, on the
//! simulator's virtual clock, so times and frame orders are exact.

#![allow(clippy::unwrap_used)]

use crate::whj_common;

use std::time::Duration;

use robobus::whj::{JointBus, WhjError};
use robobus_sim::whj::{JointConfig, Node, WhjModel};
use robobus_whj::units::{Position, TargetSpeed};
use robobus_whj::{JointId, Request, WorkMode};
use whj_common::{chain, configs, virtual_bus};

fn j(n: u8) -> JointId {
    JointId::new(n).unwrap()
}

fn deg(d: f64) -> Position {
    Position::from_degrees(d).unwrap()
}

/// Joints `ids` out of the bootloader, in `mode`, enabled (their write acks are the
/// same from two joints at one ID, their identities are not, so they are not read).
fn ready(bus: &JointBus, ids: &[u8], mode: WorkMode) {
    for &n in ids {
        let joint = bus.joint_unchecked(j(n));
        joint.release_iap().unwrap();
        joint.set_mode(mode).unwrap();
        joint.enable().unwrap();
    }
}

fn position_frames(ids: &[u8], deg_each: f64) -> Vec<Request> {
    ids.iter()
        .map(|&n| Request::PositionServo {
            joint: j(n),
            target: deg(deg_each),
        })
        .collect()
}

#[test]
fn a_batch_goes_out_together_and_pays_one_duplicate_check_not_one_per_joint() {
    let ids = [1, 2, 3, 4, 5, 6, 7];
    let (bus, sim) = virtual_bus(chain(7).with_trace());
    ready(&bus, &ids, WorkMode::Position);
    // One joint after another: each reply held for the check before the next frame.
    let t = bus.now();
    for &n in &ids {
        bus.joint_unchecked(j(n))
            .command_position(deg(0.5))
            .unwrap();
    }
    let serial = bus.now() - t;

    // The same frames in one batch.
    let traced = sim.with_bus(|b| b.trace().len());
    let t = bus.now();
    let answers = bus.servo_many(&position_frames(&ids, 1.0)).unwrap();
    let batch = bus.now() - t;
    assert_eq!(answers.len(), 7);
    for a in &answers {
        let fb = a.as_ref().unwrap();
        assert!(fb.is_enabled() && fb.error.is_empty(), "{fb:?}");
    }
    // All seven frames were on the wire before the first feedback, each feedback came
    // from the joint it was sent to, in turn.
    let wire = sim.with_bus(|b| b.trace()[traced..].to_vec());
    let hosts: Vec<bool> = wire.iter().map(|w| w.source == Node::Host).collect();
    assert_eq!(hosts, [[true; 7], [false; 7]].concat(), "{wire:?}");
    let answered: Vec<u32> = wire[7..].iter().map(|w| w.frame.raw_id()).collect();
    assert_eq!(answered, [0x501, 0x502, 0x503, 0x504, 0x505, 0x506, 0x507]);
    // Each reply is held for an arbitration loser's answer, at least a frame of its own
    // length: the checks of six replies overlapped the frames of the others, so the batch
    // saves at least six of them over the serial loop.
    let frame =
        robobus_whj::timing::frame_duration(&wire[7].frame, robobus_whj::timing::BitRates::WHJ);
    assert!(
        batch + frame * 6 <= serial,
        "batch {batch:?}, serial {serial:?}, a feedback frame {frame:?}"
    );
}

#[test]
fn a_duplicate_answer_fails_its_own_joint_only_and_the_others_are_credited() {
    // Joint 3 twice, the twin 50° away: both answer frames to 3 with different feedback.
    let mut all: Vec<JointConfig> = (1..=5)
        .map(|n| JointConfig::new(n, WhjModel::Whj30))
        .collect();
    let mut twin = JointConfig::new(3, WhjModel::Whj30);
    twin.initial_position_deg = 50.0;
    twin.unique_id = [9, 9, 9, 9, 9, 9];
    all.push(twin);
    let (bus, _sim) = virtual_bus(configs(all));
    ready(&bus, &[1, 2, 3, 4, 5], WorkMode::Speed);
    let duplicates = bus.telemetry().bus.duplicates;
    let frames: Vec<Request> = (1..=5)
        .map(|n| Request::SpeedServo {
            joint: j(n),
            target: TargetSpeed(0),
        })
        .collect();
    for run in 0..3 {
        let answers = bus.servo_many(&frames).unwrap();
        for (n, a) in (1..=5u8).zip(&answers) {
            if n == 3 {
                assert!(
                    matches!(a, Err(WhjError::DuplicateReply { joint, .. }) if *joint == j(3)),
                    "run {run}: {a:?}"
                );
            } else {
                let fb = a
                    .as_ref()
                    .unwrap_or_else(|e| panic!("run {run}, J{n}: {e}"));
                assert!(
                    fb.position.degrees().abs() < 0.01,
                    "run {run}, J{n}: {fb:?}"
                );
            }
        }
    }
    assert!(bus.telemetry().bus.duplicates > duplicates);
}

#[test]
fn a_step_too_large_or_a_frame_that_is_not_a_servo_frame_refuses_the_batch_with_nothing_sent() {
    let (bus, _sim) = virtual_bus(chain(3));
    ready(&bus, &[1, 2, 3], WorkMode::Position);
    // A first batch where they are: the step checks measure from its feedback after.
    bus.servo_many(&position_frames(&[1, 2, 3], 0.0)).unwrap();
    let sent = bus.telemetry().bus.frames_sent;
    let mut frames = position_frames(&[1, 2, 3], 1.0);
    frames[2] = Request::PositionServo {
        joint: j(3),
        target: deg(30.0),
    };
    let err = bus.servo_many(&frames).unwrap_err();
    assert!(
        matches!(err, WhjError::StepTooLarge { joint, .. } if joint == j(3)),
        "{err}"
    );
    assert_eq!(err.kind(), robobus::ErrorKind::Refused);
    frames[2] = Request::StatusQuery { joint: j(3) };
    let err = bus.servo_many(&frames).unwrap_err();
    assert!(matches!(err, WhjError::InvalidConfig { .. }), "{err}");
    let many = position_frames(&[1], 0.0).repeat(robobus::whj::MAX_PIPELINED + 1);
    assert!(matches!(
        bus.servo_many(&many),
        Err(WhjError::InvalidConfig { .. })
    ));
    assert_eq!(bus.telemetry().bus.frames_sent, sent);
}

#[test]
fn a_silent_joint_fails_alone_after_its_retries_and_the_others_answer() {
    let (bus, _sim) = virtual_bus(chain(3));
    ready(&bus, &[1, 2, 3], WorkMode::Speed);
    let frames: Vec<Request> = [1, 9, 3]
        .iter()
        .map(|&n| Request::SpeedServo {
            joint: j(n),
            target: TargetSpeed(0),
        })
        .collect();
    let t = bus.now();
    let answers = bus.servo_many(&frames).unwrap();
    assert!(answers[0].is_ok() && answers[2].is_ok(), "{answers:?}");
    let retries = bus.config().retries;
    assert!(
        matches!(&answers[1], Err(WhjError::Timeout { joint, attempts, reply_id: 0x509, .. })
            if *joint == j(9) && *attempts == retries + 1),
        "{:?}",
        answers[1]
    );
    // The silent joint's attempts, one after another; the others within the first.
    let timeout = bus.config().reply_timeout;
    let took = bus.now() - t;
    assert!(
        took >= timeout * (retries + 1)
            && took < timeout * (retries + 1) + Duration::from_millis(2),
        "{took:?}"
    );
}
