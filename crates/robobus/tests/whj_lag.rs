//! Streams of position set-points to a joint that lags behind them (a simulated drive
//! with too little current for the motion), on the simulator's virtual clock: each
//! set-point is planned against the joint's measured position, so none reaches the
//! joint's step protection (error 0x4000, "position command step"); a stream whose first
//! set-point is far from the joint is refused before its first frame; a joint that does
//! not move at all stops the stream as "not following". On a joint that follows, the
//! frames go out exactly as planned, and a wave within the limits is not "clamped".

#![allow(clippy::unwrap_used)] // tests

use crate::whj_common;

use robobus::ops::whj::{self as ops, ServoLoop, Shape, WaveArgs};
use robobus::ops::{Control, ErrorKind, OpError, SafeState};
use robobus::whj::{JointBus, JointBusConfig};
use robobus_sim::whj::{JointConfig, WhjModel, WhjSimHandle};
use robobus_whj::error_code::ErrorCode;
use robobus_whj::units::CurrentScale;
use robobus_whj::{JointId, WorkMode};
use whj_common::{configs, virtual_bus};

fn id(n: u8) -> JointId {
    JointId::new(n).unwrap()
}

/// Joint 1 at `at_deg`, enabled in position mode; its drive gives at most `amps` (`None`:
/// its full current).
fn joint(amps: Option<f64>, at_deg: f64) -> (JointBus, WhjSimHandle) {
    let mut cfg = JointConfig::new(1, WhjModel::Whj30).without_iap();
    cfg.drive_current_limit_a = amps;
    cfg.initial_position_deg = at_deg;
    let (bus, sim) = virtual_bus(configs(vec![cfg]));
    let j = bus.joint(id(1)).unwrap();
    j.set_mode(WorkMode::Position).unwrap();
    j.enable().unwrap();
    (bus, sim)
}

/// The error bits the simulated joint has latched.
fn latched(sim: &WhjSimHandle) -> ErrorCode {
    sim.with_bus(|b| b.joint(1).unwrap().state().error)
}

/// The frames the step limiter changes at the start of [`sine`]: it starts at 94 deg/s
/// from rest, more than the wave's 3000 deg/s^2 allow in one frame, and the set-point
/// catches up with it from there.
const START: u64 = 21;

/// A 15 deg, 1 Hz sine at 100 Hz for 2 s: within the wave limits (94 deg/s, 592 deg/s^2).
fn sine() -> WaveArgs {
    WaveArgs {
        joint: id(1),
        shape: Shape::Sine,
        servo: ServoLoop::Position,
        amplitude: 15.0,
        frequency: 1.0,
        offset: 0.0,
        duration: 2.0,
        rate_hz: 100.0,
        step_limit_deg: JointBusConfig::default().step_limit_deg,
    }
}

/// The wave that drove a lagging joint into its step fault (frames checked only against
/// the previous set-point) completes: the set-points the joint could not keep up with are
/// held back to the step limit from where it was measured, and counted.
#[test]
fn a_wave_on_a_lagging_joint_completes_with_its_set_points_held_back_never_step_faulted() {
    let (bus, sim) = joint(Some(0.7), 0.0);
    let j = bus.joint(id(1)).unwrap();
    let (plan, r) = ops::run_wave(&j, &sine(), &mut Control::none(), SafeState::Hold).unwrap();
    assert_eq!(r.cycles, plan.frames.len() as u64, "{r:?}");
    assert_eq!(r.complete, r.cycles, "{r:?}");
    assert!(r.held_back > 0, "{r:?}");
    // The plan's own limiter changed only the start (a sine starts at full speed).
    assert_eq!(r.clamped, START, "{r:?}");
    assert_eq!(r.last.as_ref().unwrap().error, "no error", "{r:?}");
    assert!(latched(&sim).is_empty(), "{}", latched(&sim));
    // It lagged: the tracking error shows it (the joint is far behind the request).
    assert!(r.tracking_max.unwrap() > 5.0, "{r:?}");
}

/// On a joint that follows, the same wave goes out exactly as planned: nothing held back,
/// nothing clamped (its set-points are the requested sine, not a limiter lagging behind
/// it), and it tracks within a degree or two.
#[test]
fn a_wave_on_a_following_joint_is_sent_as_planned_and_not_counted_as_clamped() {
    let (bus, sim) = joint(None, 0.0);
    let j = bus.joint(id(1)).unwrap();
    let args = sine();
    let dry = ops::plan_wave(&args, 0.0, CurrentScale::OneMilliamp, true).unwrap();
    let (plan, r) = ops::run_wave(&j, &args, &mut Control::none(), SafeState::Hold).unwrap();
    assert_eq!(plan.frames, dry.frames);
    // Frames 1..=START catch up with the sine; every other set-point is the requested sine (to the wire's 0.0001 deg).
    let start = usize::try_from(START).unwrap();
    for (k, (f, want)) in dry.frames.iter().zip(ops::wave_targets(&args)).enumerate() {
        let robobus_whj::Request::PositionServo { target, .. } = f.request else {
            panic!("{f:?}");
        };
        let off = (target.degrees() - want).abs();
        assert_eq!(
            off >= 1e-3,
            (1..=start).contains(&k),
            "frame {k}: {target:?} vs {want}"
        );
    }
    assert_eq!((r.clamped, r.held_back), (START, 0), "{r:?}");
    assert!(r.tracking_max.unwrap() < 2.0, "{r:?}");
    assert!(latched(&sim).is_empty());
}

/// A wave whose offset lies 21 deg from the joint starts with a lead-in ramp from where the
/// joint is, which the plan's notes show and `clamped` counts; the rest is the wave.
#[test]
fn a_wave_far_from_the_joint_shows_its_lead_in_and_counts_only_it_as_clamped() {
    let (bus, sim) = joint(None, 0.0);
    let j = bus.joint(id(1)).unwrap();
    let args = WaveArgs {
        offset: 21.0,
        amplitude: 5.0,
        duration: 3.0,
        ..sine()
    };
    let plan = ops::prepare_wave(&j, &args).unwrap();
    let note = plan
        .notes
        .iter()
        .find(|n| n.contains("lead-in"))
        .unwrap_or_else(|| panic!("{:?}", plan.notes));
    assert!(
        note.starts_with(
            "the wave starts 21.0000 deg from 0 deg, more than the step limit of 5 deg: its first"
        ),
        "{note}"
    );
    let lead_in: u64 = note
        .split("its first ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .unwrap()
        .parse()
        .unwrap();
    assert!(lead_in > 0 && lead_in < 100, "{note}");
    let r = ops::execute_wave(&j, &args, &plan, &mut Control::none(), SafeState::Hold).unwrap();
    assert_eq!(r.clamped, lead_in, "{r:?}");
    assert_eq!(r.last.as_ref().unwrap().error, "no error", "{r:?}");
    assert!(latched(&sim).is_empty());
}

/// The number of clamped set-points a plan's note gives (`N of M set-point(s) clamped`).
fn clamped_note(plan: &ops::Plan) -> Option<(u64, usize)> {
    let note = plan
        .notes
        .iter()
        .find(|n| n.contains("set-point(s) clamped"))?;
    let mut words = note.split(' ');
    let n = words.next()?.parse().ok()?;
    let of = words.nth(1)?.parse().ok()?;
    assert!(note.contains("set-point(s) clamped, by up to "), "{note}");
    Some((n, of))
}

/// Before a wave runs, its plan from where the joint is says how many of its set-points
/// the step limiter changes, and the run counts exactly that many as `clamped`: a lead-in
/// from 21 deg away, and a wave whose joint stands 0.5 deg off its start (within the step
/// limit, so no lead-in note: the limiter catches up within its speed and acceleration);
/// a wave that starts where the joint is, within the limits, has no such note.
#[test]
fn a_waves_plan_says_how_many_set_points_its_run_counts_as_clamped() {
    let cases = [
        (0.0, 21.0, 5.0, 0.5, true),
        (0.5, 0.0, 8.0, 0.5, true),
        (0.0, 0.0, 2.0, 0.2, false),
    ];
    for (at_deg, offset, amplitude, frequency, any) in cases {
        let (bus, sim) = joint(None, at_deg);
        let j = bus.joint(id(1)).unwrap();
        let args = WaveArgs {
            offset,
            amplitude,
            frequency,
            duration: 3.0,
            rate_hz: 200.0,
            ..sine()
        };
        let plan = ops::prepare_wave(&j, &args).unwrap();
        let note = clamped_note(&plan);
        let r = ops::execute_wave(&j, &args, &plan, &mut Control::none(), SafeState::Hold).unwrap();
        if any {
            assert_eq!(
                note,
                Some((r.clamped, plan.frames.len())),
                "{:?}",
                plan.notes
            );
            assert!(r.clamped > 0, "{r:?}");
        } else {
            assert_eq!((note, r.clamped), (None, 0), "{:?}", plan.notes);
        }
        assert!(latched(&sim).is_empty());
    }
}

/// A plan whose first set-point is more than the step limit from where the joint is (a
/// plan made from another start, here 21 deg away) is refused before its first frame,
/// naming the distance, the limit and what to do; the joint is not moved.
#[test]
fn a_plan_starting_far_from_the_joint_is_refused_before_its_first_frame() {
    let (bus, sim) = joint(None, 21.0);
    let j = bus.joint(id(1)).unwrap();
    let args = sine();
    let plan = ops::plan_wave(&args, 0.0, CurrentScale::OneMilliamp, true).unwrap();
    let target = sim.with_bus(|b| b.joint(1).unwrap().state().target_position);
    let e = ops::execute_wave(&j, &args, &plan, &mut Control::none(), SafeState::Hold).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused, "{e}");
    let OpError::Refused(reason) = &e else {
        panic!("{e:?}")
    };
    assert!(
        reason.contains("the wave's first set-point 0.0000 deg is 21.0000 deg from where the joint is (21.0000 deg)"),
        "{reason}"
    );
    assert!(
        reason.contains("beyond the step limit of 5 deg"),
        "{reason}"
    );
    assert!(reason.contains("whj move 1 0.0000"), "{reason}");
    // No set-point reached the joint; it holds where it was.
    let st = sim.with_bus(|b| b.joint(1).unwrap().state());
    assert_eq!(st.target_position, target, "{st:?}");
    assert!((st.position_deg - 21.0).abs() < 0.01, "{st:?}");
    assert!(st.error.is_empty());
}

/// A joint that cannot move at all (no current) is not following: once its set-points
/// have been held back for `STALL_AFTER` without it moving a step limit toward them, the
/// wave stops as a device error and the joint is left holding, without a step fault.
#[test]
fn a_joint_that_does_not_move_stops_the_wave_as_not_following() {
    let (bus, sim) = joint(Some(0.0), 0.0);
    let j = bus.joint(id(1)).unwrap();
    // A slow sine: its set-points stay more than a step from 0 deg for 780 ms at a time.
    let args = WaveArgs {
        frequency: 0.5,
        ..sine()
    };
    let e = ops::run_wave(&j, &args, &mut Control::none(), SafeState::Hold).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Device, "{e}");
    let text = e.to_string();
    assert!(text.contains("joint 1 is not following the plan"), "{text}");
    assert!(
        text.contains("held back to the step limit of 5 deg for 5"),
        "{text}"
    );
    assert!(text.contains("joint 1 left holding"), "{text}");
    assert!(latched(&sim).is_empty(), "{}", latched(&sim));
}

/// A move on a lagging joint arrives: its set-points are held back while the joint is
/// behind, and the target goes out again after the plan's last frame until it goes out
/// unchanged; the frames sent count those, `held_back` how many were held back.
#[test]
fn a_move_on_a_lagging_joint_arrives_its_target_sent_again_until_unchanged() {
    // 0.3 A: the joint lags the plan (its set-points are held back) yet has the torque to
    // overcome its friction near the target. At 0.2-0.5 A the simulated WHJ30 may overshoot
    // and stop where friction holds it, 0.5-2 deg off, depending on when each frame
    // crossed the wire (the reply hold moves them by microseconds): a move that ends there
    // fails as MoveIncomplete, which is right for that joint, not what this test is about.
    let (bus, sim) = joint(Some(0.3), 0.0);
    let j = bus.joint(id(1)).unwrap();
    let args = ops::MoveArgs {
        joint: id(1),
        target_deg: 60.0,
        max_speed_deg_s: 100.0,
        rate_hz: 20.0,
        step_limit_deg: JointBusConfig::default().step_limit_deg,
    };
    let plan = ops::plan_move(&args, 0.0, true).unwrap();
    let r = ops::run_move(&j, &args, &mut Control::none(), SafeState::Hold).unwrap();
    assert!(r.held_back > 0, "{r:?}");
    assert!(r.frames > plan.frames.len() as u64, "{r:?}");
    assert!((r.position_deg - 60.0).abs() <= 0.1, "{r:?}");
    assert_eq!(r.error, "no error");
    assert!(latched(&sim).is_empty(), "{}", latched(&sim));
}

/// A broadcast (0x2F) wave is held against the joint's measured position as a
/// point-to-point one is: on the lagging joint it completes, its held-back set-points in
/// the joint's slot, without a step fault.
#[test]
fn a_broadcast_wave_on_a_lagging_joint_is_held_back_too() {
    let (bus, sim) = joint(Some(0.7), 0.0);
    let j = bus.joint(id(1)).unwrap();
    let args = sine();
    let plan = ops::prepare_broadcast_wave(&j, &args).unwrap();
    let r = ops::execute_wave(&j, &args, &plan, &mut Control::none(), SafeState::Hold).unwrap();
    assert_eq!(r.complete, plan.frames.len() as u64, "{r:?}");
    assert!(r.held_back > 0, "{r:?}");
    assert_eq!(r.clamped, START, "{r:?}");
    assert!(latched(&sim).is_empty(), "{}", latched(&sim));
}
