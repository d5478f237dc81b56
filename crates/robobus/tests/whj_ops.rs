//! `robobus::ops::whj` against the simulator: per-joint results, one plan for dry-run and
//! real run (frames captured on the wire), stop with the safe state, progress, and the
//! safety checks before a move.

#![allow(clippy::unwrap_used, clippy::panic, clippy::float_cmp)] // tests

mod whj_common;

use std::io::Write;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use robobus::ops::whj::{self as ops, MoveArgs, ServoLoop, Shape, WaveArgs};
use robobus::ops::{Control, ErrorKind, OpError, Progress, SafeState, StopToken};
use robobus::whj::{JointBus, JointBusConfig};
use robobus_link::{CaptureFrameLink, FrameLink, FrameLinkError, IdFilter, Received, read_candump};
use robobus_whj::units::{CurrentScale, Position};
use robobus_whj::{CanFrame, JointId, Reply, Request, WorkMode};
use whj_common::{chain, config, memory};

/// A capture buffer shared with the bus thread.
#[derive(Clone, Default)]
struct Shared(Arc<Mutex<Vec<u8>>>);

impl Write for Shared {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(b);
        Ok(b.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Shared {
    fn clear(&self) {
        self.0.lock().unwrap().clear();
    }
    /// Frames the client sent (logged under `tx`).
    fn sent(&self) -> Vec<CanFrame> {
        let bytes = self.0.lock().unwrap().clone();
        read_candump(&bytes[..])
            .map(Result::unwrap)
            .filter(|r| r.iface == "tx")
            .map(|r| r.frame)
            .collect()
    }
}

fn id(n: u8) -> JointId {
    JointId::new(n).unwrap()
}

/// A bus to `n` simulated joints whose sent frames are captured.
fn captured(n: u8) -> (whj_common::Sim, JointBus, Shared) {
    let (sim, link) = memory(chain(n));
    let log = Shared::default();
    let link = CaptureFrameLink::new(link, log.clone(), "rx").with_tx_iface("tx");
    let bus = JointBus::open_with(link, config()).unwrap();
    (sim, bus, log)
}

fn ready(bus: &JointBus, joint: JointId, mode: WorkMode) {
    let j = bus.joint(joint).unwrap();
    j.set_mode(mode).unwrap();
    j.enable().unwrap();
}

fn servo_frames(frames: &[CanFrame]) -> Vec<CanFrame> {
    frames
        .iter()
        .copied()
        .filter(|f| matches!(f.raw_id() >> 8, 2..=4))
        .collect()
}

fn plan_frames(plan: &ops::Plan) -> Vec<CanFrame> {
    plan.frames.iter().map(|f| f.request.to_frame()).collect()
}

#[test]
fn status_of_three_joints_with_the_middle_one_silent_reports_all_three() {
    // Joints 1 and 3 on the bus, 2 missing.
    let bus_sim = robobus_sim::whj::WhjBus::chain([1u8, 3], robobus_sim::whj::WhjModel::Whj30, 5);
    let (_sim, link) = memory(bus_sim);
    let bus = JointBus::open_with(
        link,
        JointBusConfig {
            connect_timeout: Duration::from_millis(300),
            ..config()
        },
    )
    .unwrap();
    let results = ops::status(&bus, &[id(1), id(2), id(3)]);
    assert_eq!(results.len(), 3);
    assert!(results[0].is_ok() && results[2].is_ok(), "{results:?}");
    let f = results[1].failure().unwrap();
    assert_eq!(f.kind, ErrorKind::NoDevice, "{f:?}");
    assert!(
        f.error.contains("J2") || f.error.contains('2'),
        "{}",
        f.error
    );
    assert_eq!(
        robobus::ops::worst_kind(&results),
        Some(ErrorKind::NoDevice)
    );
    let json = serde_json::to_value(&results).unwrap();
    assert_eq!(json[0]["id"], 1);
    assert_eq!(json[0]["mode"], "position");
    assert_eq!(json[1]["kind"], "no-device");
}

fn move_args(target: f64, speed: f64, rate: f64) -> MoveArgs {
    MoveArgs {
        joint: id(1),
        target_deg: target,
        max_speed_deg_s: speed,
        rate_hz: rate,
        step_limit_deg: JointBusConfig::default().step_limit_deg,
    }
}

#[test]
fn a_real_move_sends_exactly_the_frames_its_dry_run_shows() {
    let (_sim, bus, log) = captured(1);
    ready(&bus, id(1), WorkMode::Position);
    let args = move_args(3.0, 30.0, 100.0);
    // The dry run from the same start (the simulated joint rests at 0 deg).
    let dry = ops::plan_move(&args, 0.0, true).unwrap();
    assert!(dry.assumed.as_deref().unwrap().contains("assumed 0 deg"));
    let j = bus.joint(id(1)).unwrap();
    log.clear();
    let mut seen = Vec::new();
    let mut on_progress = |p: &Progress| seen.push(p.done);
    let stop = StopToken::new();
    let mut control = Control::new(&stop).with_progress(&mut on_progress);
    let report = ops::run_move(&j, &args, &mut control, SafeState::Hold).unwrap();
    drop(control);
    let sent = log.sent();
    assert_eq!(
        servo_frames(&sent),
        plan_frames(&dry),
        "servo frames differ from the dry run"
    );
    assert_eq!(report.frames, dry.frames.len() as u64);
    assert_eq!(report.from_deg, 0.0);
    // The final position is a fresh status reading after the last frame.
    let last_frame = sent.iter().rposition(|f| f.raw_id() == 0x201).unwrap();
    assert!(sent[last_frame + 1..].iter().any(|f| f.raw_id() == 0x601));
    assert!((report.position_deg - 3.0).abs() <= 0.1, "{report:?}");
    assert_eq!(report.error, "no error");
    assert_eq!(seen.last().copied(), Some(dry.frames.len() as u64));
}

#[test]
fn a_real_wave_sends_exactly_the_frames_its_dry_run_shows() {
    let (_sim, bus, log) = captured(1);
    ready(&bus, id(1), WorkMode::Position);
    let args = WaveArgs {
        joint: id(1),
        shape: Shape::Square,
        servo: ServoLoop::Position,
        amplitude: 2.0,
        frequency: 2.0,
        offset: 0.0,
        duration: 0.5,
        rate_hz: 100.0,
    };
    let dry = ops::plan_wave(&args, 0.0, CurrentScale::OneMilliamp, true).unwrap();
    assert_eq!(dry.frames.len(), 50);
    let j = bus.joint(id(1)).unwrap();
    log.clear();
    let (plan, report) = ops::run_wave(&j, &args, &mut Control::none(), SafeState::Hold).unwrap();
    assert_eq!(plan.frames, dry.frames);
    assert_eq!(servo_frames(&log.sent()), plan_frames(&dry));
    assert_eq!(report.cycles, 50);
    // A square wave is stepped through the limiter: the first set-points are clamped.
    assert!(report.clamped > 0, "{report:?}");
    // Tracking is against the requested target: a square wave of 2 deg cannot be
    // followed exactly, so the largest error is at least a good part of the step.
    assert!(report.tracking_max.unwrap() > 0.5, "{report:?}");
    assert!(!report.stale);
}

#[test]
fn a_stopped_move_leaves_the_joint_holding_and_says_so() {
    let (_sim, bus, _log) = captured(1);
    ready(&bus, id(1), WorkMode::Position);
    let j = bus.joint(id(1)).unwrap();
    let stop = StopToken::new();
    let s = stop.clone();
    let mut on_progress = move |p: &Progress| {
        if p.done >= 16 {
            s.stop();
        }
    };
    let mut control = Control::new(&stop).with_progress(&mut on_progress);
    let err = ops::run_move(
        &j,
        &move_args(20.0, 30.0, 100.0),
        &mut control,
        SafeState::Hold,
    )
    .unwrap_err();
    drop(control);
    assert_eq!(err.kind(), ErrorKind::Interrupted);
    assert!(err.to_string().contains("joint 1 holding"), "{err}");
    let st = j.status().unwrap();
    assert!(st.is_enabled());
    assert!(st.position.degrees() < 19.0, "{}", st.position.degrees());

    // Disable as the safe state.
    let stop = StopToken::new();
    stop.stop();
    let err = ops::run_move(
        &j,
        &move_args(0.0, 30.0, 100.0),
        &mut Control::new(&stop),
        SafeState::Disable,
    )
    .unwrap_err();
    assert!(err.to_string().contains("disabled"), "{err}");
    assert!(!j.is_enabled().unwrap());
}

/// A relay that rewrites the position of every status reply to 214748.36 deg (the
/// implausible reading of issue 14, item 1).
struct ImplausibleStatus<L>(L);

impl<L: FrameLink> FrameLink for ImplausibleStatus<L> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        self.0.send(frame)
    }
    fn recv(&mut self, deadline: std::time::Instant) -> Result<Received, FrameLinkError> {
        let mut r = self.0.recv(deadline)?;
        if let Ok(Reply::Status { joint, mut status }) = Reply::from_frame(&r.frame) {
            status.position = Position(2_147_483_600);
            r.frame = Reply::Status { joint, status }.to_frame();
        }
        Ok(r)
    }
    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        self.0.set_filters(filters)
    }
}

#[test]
fn a_move_is_not_planned_from_an_implausible_present_position() {
    let (_sim, link) = memory(chain(1));
    let log = Shared::default();
    let link =
        CaptureFrameLink::new(ImplausibleStatus(link), log.clone(), "rx").with_tx_iface("tx");
    let bus = JointBus::open_with(link, config()).unwrap();
    ready(&bus, id(1), WorkMode::Position);
    let j = bus.joint(id(1)).unwrap();
    log.clear();
    let err = ops::run_move(
        &j,
        &move_args(15.0, 30.0, 100.0),
        &mut Control::none(),
        SafeState::Hold,
    )
    .unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Device, "{err}");
    let msg = err.to_string();
    assert!(
        msg.contains("214748.36") && msg.contains("outside its position limits"),
        "{msg}"
    );
    assert!(servo_frames(&log.sent()).is_empty());
}

#[test]
fn a_move_needs_position_mode_and_an_enabled_joint() {
    let (_sim, bus, log) = captured(1);
    let j = bus.joint(id(1)).unwrap();
    j.set_mode(WorkMode::Speed).unwrap();
    log.clear();
    let err = ops::run_move(
        &j,
        &move_args(1.0, 30.0, 100.0),
        &mut Control::none(),
        SafeState::Hold,
    )
    .unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Refused);
    assert!(err.to_string().contains("whj mode 1 position"), "{err}");
    assert!(servo_frames(&log.sent()).is_empty());
}

#[test]
fn a_too_fast_move_is_split_into_steps_within_the_step_limit() {
    // 180 deg/s at 1 Hz would be 180 deg per frame.
    let args = move_args(30.0, 180.0, 1.0);
    let plan = ops::plan_move(&args, 0.0, true).unwrap();
    let mut last = 0.0;
    for f in &plan.frames {
        let Request::PositionServo { target, .. } = f.request else {
            panic!()
        };
        assert!((target.degrees() - last).abs() <= args.step_limit_deg + 1e-4);
        last = target.degrees();
    }
    assert!((last - 30.0).abs() < 1e-9);
    assert!(
        plan.notes
            .iter()
            .any(|n| n.contains("split into smaller steps")),
        "{:?}",
        plan.notes
    );
}

#[test]
fn set_id_is_refused_while_a_joint_answers_at_the_new_id() {
    let (_sim, bus, log) = captured(2);
    bus.joint(id(1)).unwrap();
    log.clear();
    let err = ops::set_id(&bus, id(1), id(2)).unwrap_err();
    assert!(matches!(err, OpError::Refused(_)), "{err}");
    assert!(err.to_string().contains("answers at ID 2"), "{err}");
    // Only the probe of ID 2 went out: nothing to joint 1 (no disable, write or save).
    assert!(
        log.sent().iter().all(|f| f.raw_id() == 0x002),
        "{:?}",
        log.sent()
    );
}

#[test]
fn clear_shows_the_error_bits_before_and_after() {
    let (_sim, bus, _log) = captured(1);
    ready(&bus, id(1), WorkMode::Position);
    // A 30 deg step (past the joint's 10 deg protection), sent around the client's check.
    bus.request(Request::PositionServo {
        joint: id(1),
        target: Position::from_degrees(30.0).unwrap(),
    })
    .unwrap();
    std::thread::sleep(Duration::from_millis(20));
    let r = ops::clear(&bus, &[id(1)]);
    let v = r[0].value().unwrap();
    assert_ne!(v.error_before, "no error", "{v:?}");
    assert_eq!(v.error_after, "no error", "{v:?}");
}

#[test]
fn enable_reports_the_state_the_joint_reports() {
    let (_sim, bus, _log) = captured(2);
    let r = ops::enable(&bus, &[id(1), id(2)], true);
    assert!(r.iter().all(robobus::ops::DeviceResult::is_ok), "{r:?}");
    assert!(r[0].value().unwrap().enabled);
    let r = ops::enable(&bus, &[id(2)], false);
    assert!(!r[0].value().unwrap().enabled);
}
