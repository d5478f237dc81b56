//! `robobus::ops::whj` against the simulator: per-joint results, one plan for dry-run and
//! real run (frames captured on the wire), stop with the safe state, progress, and the
//! safety checks before a move. On the simulator's virtual clock (`WhjSimLink`): timed
//! operations (moves, waves, settle times) take simulated time only.

#![allow(clippy::unwrap_used, clippy::float_cmp)] // tests

use crate::whj_common;

use std::io::Write;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use robobus::ops::whj::{self as ops, MoveArgs, ServoLoop, Shape, WaveArgs};
use robobus::ops::{Control, ErrorKind, OpError, Progress, SafeState, StopToken};
use robobus::whj::{JointBus, JointBusConfig};
use robobus_link::{CaptureFrameLink, FrameLink, FrameLinkError, IdFilter, Received, read_candump};
use robobus_whj::units::{CurrentScale, Position};
use robobus_whj::{CanFrame, JointId, Reply, Request, WorkMode};
use whj_common::{chain, sim_link, virtual_config as config};

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
fn captured(n: u8) -> (robobus_sim::whj::WhjSimHandle, JointBus, Shared) {
    let (link, sim) = sim_link(chain(n));
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
    let (link, _sim) = sim_link(bus_sim);
    let bus = JointBus::open_with(
        link,
        JointBusConfig {
            connect_timeout: Duration::from_millis(300),
            ..config()
        },
    )
    .unwrap();
    let t = bus.now();
    let results = ops::status(&bus, &[id(1), id(2), id(3)]);
    // J2's IAP release is tried for the connect timeout while J1 and J3 answer at once:
    // attempt k of J2 ends at 20 k + 5 (k - 1) ms, the thirteenth at 320 ms is the first
    // past 300 ms; then J1 and J3 are identified, their limits and status read (about 1
    // ms of wire time, and the 0.5 ms collision window each reply is held for).
    let took = bus.now() - t;
    assert!(
        took >= Duration::from_millis(320) && took < Duration::from_millis(330),
        "{took:?}"
    );
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
        step_limit_deg: JointBusConfig::default().step_limit_deg,
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
    assert_eq!(report.clamped, 10, "{report:?}");
    // Tracking is against the requested target: a square wave of 2 deg cannot be
    // followed exactly, so the largest error is at least a good part of the step.
    assert_eq!(report.tracking_max.unwrap(), 3.8503, "{report:?}");
    // On the virtual clock every frame goes out on time and is answered.
    assert_eq!(
        (report.complete, report.deadline_misses, report.overruns),
        (50, 0, 0),
        "{report:?}"
    );
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

/// A relay that lets `on_recv` change (or hold back) every frame the client receives.
struct OnReceive<L, F>(L, F);

impl<L: FrameLink, F: FnMut(&mut Received)> FrameLink for OnReceive<L, F> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        self.0.send(frame)
    }
    fn recv(&mut self, deadline: std::time::Instant) -> Result<Received, FrameLinkError> {
        let mut r = self.0.recv(deadline)?;
        (self.1)(&mut r);
        Ok(r)
    }
    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        self.0.set_filters(filters)
    }

    robobus_link::forward_frame_link_clock!(0);
}

/// Rewrites the position of every status reply to 214748.36 deg (the implausible reading
/// of issue 14, item 1).
fn implausible_status(r: &mut Received) {
    if let Ok(Reply::Status { joint, mut status }) = Reply::from_frame(&r.frame) {
        status.position = Position(2_147_483_600);
        r.frame = Reply::Status { joint, status }.to_frame();
    }
}

#[test]
fn a_move_is_not_planned_from_an_implausible_present_position() {
    let (link, _sim) = sim_link(chain(1));
    let log = Shared::default();
    let link = CaptureFrameLink::new(OnReceive(link, implausible_status), log.clone(), "rx")
        .with_tx_iface("tx");
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
fn writing_sys_id_is_refused_while_a_joint_answers_at_that_id() {
    let (_sim, bus, log) = captured(2);
    bus.joint(id(1)).unwrap();
    log.clear();
    let sys_id = robobus_whj::registers::addr::SYS_ID;
    let err = ops::write(&bus, id(1), sys_id, 2.0, false, None, true).unwrap_err();
    assert!(matches!(err, OpError::Refused(_)), "{err}");
    assert!(err.to_string().contains("answers at ID 2"), "{err}");
    assert!(
        log.sent().iter().all(|f| f.raw_id() == 0x002),
        "{:?}",
        log.sent()
    );
}

#[test]
fn set_id_reads_the_new_id_back_before_saving() {
    let (_sim, bus, log) = captured(1);
    bus.joint(id(1)).unwrap();
    log.clear();
    let r = ops::set_id(&bus, id(1), id(5)).unwrap();
    assert_eq!((r.new_id, r.read_back), (5, 5), "{r:?}");
    // The read of SYS_ID (0x01) goes out after the write and before the save.
    let sent = log.sent();
    let to_1: Vec<&[u8]> = sent
        .iter()
        .filter(|f| f.raw_id() == 0x001 || f.raw_id() == 0x005)
        .map(CanFrame::data)
        .collect();
    let write = to_1.iter().position(|d| d[..2] == [0x02, 0x01]).unwrap();
    let read = to_1
        .iter()
        .position(|d| d[..3] == [0x01, 0x01, 0x01])
        .unwrap();
    assert!(write < read, "{to_1:02X?}");
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
    bus.sleep_until(bus.now() + Duration::from_millis(20));
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

#[test]
fn scan_finds_two_joints_sharing_an_id_by_their_unique_ids() {
    use robobus_sim::whj::{JointConfig, WhjModel};
    let mut a = JointConfig::new(4, WhjModel::Whj30);
    a.unique_id = [1, 2, 3, 4, 5, 6];
    let mut b = JointConfig::new(4, WhjModel::Whj30);
    b.unique_id = [9, 9, 9, 9, 9, 9];
    let c = JointConfig::new(5, WhjModel::Whj30);
    let (link, _sim) = sim_link(whj_common::configs(vec![a, b, c]));
    let bus = JointBus::open_with(link, config()).unwrap();
    let report = ops::scan(&bus, &[id(4), id(5)], &mut Control::none()).unwrap();
    assert_eq!(report.found.len(), 2, "{report:?}");
    assert_eq!(report.duplicates.len(), 1, "{report:?}");
    assert_eq!(report.duplicates[0].id, 4);
    assert_ne!(
        report.duplicates[0].unique_ids[0],
        report.duplicates[0].unique_ids[1]
    );
    // A joint alone at its ID is never called a duplicate.
    assert!(ops::duplicates_of(&bus, id(5)).is_none());
}

#[test]
fn register_writes_follow_their_safety_class() {
    let (_sim, bus, log) = captured(1);
    bus.joint(id(1)).unwrap();
    let write = |addr: u8, value: u16| {
        Request::write(id(1), robobus_whj::RegisterAddr::new(addr).unwrap(), value).unwrap()
    };
    log.clear();
    // never: the absolute sensor calibration.
    let e = ops::write_register(&bus, write(0x0D, 1), true).unwrap_err();
    assert!(e.to_string().contains("never to write"), "{e}");
    // motion target: refused with a pointer to the command.
    let e = ops::write_register(
        &bus,
        Request::write_i32(id(1), robobus_whj::registers::addr::TAG_SPEED, 500_000).unwrap(),
        true,
    )
    .unwrap_err();
    assert!(e.to_string().contains("whj speed"), "{e}");
    // confirm: IAP_FLAG := 1 needs the confirmation and says what it does.
    let e = ops::write_register(&bus, write(0x49, 1), false).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused);
    assert!(
        e.to_string().contains("bootloader") && e.to_string().contains("--yes"),
        "{e}"
    );
    assert!(log.sent().is_empty(), "{:?}", log.sent());
    // Inverted position limits are refused.
    let e = ops::write_register(
        &bus,
        Request::write_i32(
            id(1),
            robobus_whj::registers::addr::LIT_MIN_POSITION,
            4_000_000,
        )
        .unwrap(),
        true,
    )
    .unwrap_err();
    assert!(e.to_string().contains("inverted"), "{e}");
    // plain: written and read back.
    let r = ops::write_register(&bus, write(0x30, 2), false).unwrap();
    assert_eq!(r[0].register, "TAG_WORK_MODE");
    assert_eq!(r[0].raw, 2);
}

#[test]
fn a_speed_target_checks_the_mode_and_stops_after_its_duration() {
    let (_sim, bus, log) = captured(1);
    let j = bus.joint(id(1)).unwrap();
    let args = ops::TargetArgs {
        joint: id(1),
        servo: ServoLoop::Speed,
        value: 2.0,
        duration: Some(Duration::from_millis(200)),
    };
    // In position mode nothing moves: refused before any frame.
    j.set_mode(WorkMode::Position).unwrap();
    j.enable().unwrap();
    log.clear();
    let e = ops::run_target(&j, &args, &mut Control::none(), SafeState::Hold).unwrap_err();
    assert!(e.to_string().contains("whj mode 1 speed"), "{e}");
    assert!(servo_frames(&log.sent()).is_empty());
    j.disable().unwrap();
    j.set_mode(WorkMode::Speed).unwrap();
    j.enable().unwrap();
    log.clear();
    let r = ops::run_target(&j, &args, &mut Control::none(), SafeState::Hold).unwrap();
    assert!(!r.keeps_running);
    let frames = servo_frames(&log.sent());
    assert_eq!(frames.len(), 2, "{frames:?}");
    assert_eq!(
        frames[1],
        Request::SpeedServo {
            joint: id(1),
            target: robobus_whj::units::TargetSpeed(0)
        }
        .to_frame()
    );
    // Without a duration the report says plainly that the joint keeps turning.
    let r = ops::run_target(
        &j,
        &ops::TargetArgs {
            duration: None,
            ..args
        },
        &mut Control::none(),
        SafeState::Hold,
    )
    .unwrap();
    assert!(r.keeps_running);
    assert!(r.note.contains("whj speed 1 0"), "{}", r.note);
}

#[test]
fn the_bus_keeps_joint_identities_and_owned_handles_cross_threads() {
    let (_sim, bus, log) = captured(1);
    let bus = Arc::new(bus);
    let owned = bus.owned_joint(id(1)).unwrap();
    log.clear();
    // Short-lived handles, as a monitor makes every sample: no identity reads any more.
    for _ in 0..3 {
        assert_eq!(
            bus.joint_unchecked(id(1)).identity().unwrap().model.name(),
            "WHJ30"
        );
    }
    assert!(log.sent().is_empty(), "{:?}", log.sent());
    // The owned handle lives on another thread.
    let h = std::thread::spawn(move || owned.joint().status().map(|s| s.is_enabled()));
    assert!(h.join().unwrap().is_ok());
}

/// A relay that sets error bit 0x0200 (position limit) in every status reply and servo
/// feedback: a joint that accepts commands but reports an error.
struct ErrorBits<L>(L);

impl<L: FrameLink> FrameLink for ErrorBits<L> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        self.0.send(frame)
    }
    fn recv(&mut self, deadline: std::time::Instant) -> Result<Received, FrameLinkError> {
        let mut r = self.0.recv(deadline)?;
        match Reply::from_frame(&r.frame) {
            Ok(Reply::Status { joint, mut status }) => {
                status.error = robobus_whj::ErrorCode(0x0200);
                r.frame = Reply::Status { joint, status }.to_frame();
            }
            Ok(Reply::ServoFeedback {
                joint,
                mut feedback,
            }) => {
                feedback.error = robobus_whj::ErrorCode(0x0200);
                r.frame = Reply::ServoFeedback { joint, feedback }.to_frame();
            }
            _ => {}
        }
        Ok(r)
    }
    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        self.0.set_filters(filters)
    }

    robobus_link::forward_frame_link_clock!(0);
}

#[test]
fn enable_and_move_fail_naming_the_error_bits_the_joint_reports() {
    let (link, _sim) = sim_link(chain(1));
    let bus = JointBus::open_with(ErrorBits(link), config()).unwrap();
    let j = bus.joint(id(1)).unwrap();
    j.set_mode(WorkMode::Position).unwrap();
    let r = ops::enable(&bus, &[id(1)], true);
    let f = r[0].failure().unwrap();
    assert_eq!(f.kind, ErrorKind::Device, "{f:?}");
    assert!(f.error.contains("position limit"), "{}", f.error);
    // The joint is enabled (the write was acknowledged), but the move stops at the first
    // feedback that carries the error bits.
    let e = ops::run_move(
        &j,
        &move_args(1.0, 30.0, 100.0),
        &mut Control::none(),
        SafeState::Hold,
    )
    .unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Device, "{e}");
    assert!(e.to_string().contains("position limit"), "{e}");
}

#[test]
fn broadcast_status_reports_every_joint_and_names_the_silent_one() {
    let sim_bus =
        robobus_sim::whj::WhjBus::chain([1u8, 2, 4], robobus_sim::whj::WhjModel::Whj30, 5);
    let (link, _sim) = sim_link(sim_bus);
    let log = Shared::default();
    let link = CaptureFrameLink::new(link, log.clone(), "rx").with_tx_iface("tx");
    let bus = JointBus::open_with(link, config()).unwrap();
    // Readings are checked against each joint's position limits, which the bus reads once
    // (here, ahead of the broadcast frames counted below).
    for j in [1, 2, 4] {
        bus.joint(id(j)).unwrap().position_limits().unwrap();
    }
    // J1..J4: mask code 1 (J1-J4), the smallest that covers them.
    assert_eq!(
        ops::reply_mask(&[id(1), id(2), id(3), id(4)])
            .unwrap()
            .get(),
        1
    );
    assert!(ops::reply_mask(&[id(8)]).is_err());
    log.clear();
    let r = ops::broadcast_status(&bus, &[id(1), id(2), id(3), id(4)]).unwrap();
    // One frame out: the 0x7F query.
    let sent = log.sent();
    assert_eq!(sent.len(), 1, "{sent:?}");
    assert_eq!(sent[0].raw_id(), 0x7F);
    assert_eq!(r.len(), 4);
    assert!(r[0].is_ok() && r[1].is_ok() && r[3].is_ok(), "{r:?}");
    assert_eq!(r[2].failure().unwrap().kind, ErrorKind::NoDevice);
    assert!(r[0].value().unwrap().position_deg.abs() < 1.0);
    // No end board on this bus: asked for, it is named as silent; the joints still answer.
    let (joints, board) = ops::broadcast_status_with_end_board(&bus, &[id(1), id(2)]).unwrap();
    assert!(
        joints.iter().all(robobus::ops::DeviceResult::is_ok),
        "{joints:?}"
    );
    let f = board.failure().unwrap();
    assert_eq!(f.kind, ErrorKind::NoDevice);
    assert!(f.error.starts_with("end board: no reply"), "{f:?}");
}

#[test]
fn a_register_the_firmware_lacks_is_refused_before_anything_is_sent() {
    use robobus_sim::whj::{JointConfig, WhjModel};
    use robobus_whj::units::FirmwareVersion;
    // Firmware D510: before the "519" gate of the staggered power-up switch ON_DELAY (0x1F).
    let mut old = JointConfig::new(1, WhjModel::Whj30);
    old.firmware = FirmwareVersion(0xD510);
    let (link, _sim) = sim_link(whj_common::configs(vec![old]));
    let log = Shared::default();
    let link = CaptureFrameLink::new(link, log.clone(), "rx").with_tx_iface("tx");
    let bus = JointBus::open_with(link, config()).unwrap();
    bus.joint(id(1)).unwrap().identity().unwrap();
    log.clear();
    let on_delay = Request::write(id(1), robobus_whj::registers::addr::ON_DELAY, 1).unwrap();
    let e = ops::write_register(&bus, on_delay, true).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused);
    assert!(
        e.to_string().contains("ON_DELAY") && e.to_string().contains("D510"),
        "{e}"
    );
    // Connecting reads (IAP release, identity); the write itself (command 0x02 to 0x1F)
    // never goes out.
    let sent = log.sent();
    assert!(
        !sent.iter().any(|f| f.data().starts_with(&[0x02, 0x1F])),
        "{sent:?}"
    );
    // The same write on the simulator's default firmware goes through.
    let (link, _sim) = sim_link(chain(1));
    let bus = JointBus::open_with(link, config()).unwrap();
    let r = ops::write_register(&bus, on_delay, true).unwrap();
    assert_eq!((r[0].register, r[0].raw), ("ON_DELAY", 1));
}

/// A speed wave stopped halfway with `Hold`: the last frame is a speed target of 0 and the
/// joint stays enabled (held in its loop, not in position mode).
#[test]
fn a_stopped_speed_wave_holds_the_joint_at_speed_zero() {
    let (_sim, bus, log) = captured(1);
    ready(&bus, id(1), WorkMode::Speed);
    let j = bus.joint(id(1)).unwrap();
    let args = WaveArgs {
        joint: id(1),
        shape: Shape::Sine,
        servo: ServoLoop::Speed,
        amplitude: 5.0,
        frequency: 1.0,
        offset: 5.0,
        duration: 10.0,
        rate_hz: 100.0,
        step_limit_deg: JointBusConfig::default().step_limit_deg,
    };
    let stop = StopToken::new();
    let s = stop.clone();
    let mut on_progress = move |p: &Progress| {
        if p.done >= 20 {
            s.stop();
        }
    };
    let mut control = Control::new(&stop).with_progress(&mut on_progress);
    let err = ops::run_wave(&j, &args, &mut control, SafeState::Hold).unwrap_err();
    drop(control);
    assert_eq!(err.to_string(), "interrupted: joint 1 holding");
    let servo = servo_frames(&log.sent());
    assert!(servo.len() >= 21, "{}", servo.len());
    assert_eq!(
        Request::from_frame(servo.last().unwrap()).unwrap(),
        Request::SpeedServo {
            joint: id(1),
            target: robobus_whj::units::TargetSpeed(0)
        }
    );
    assert!(j.is_enabled().unwrap());
    assert_eq!(j.mode().unwrap(), WorkMode::Speed);
}

/// `SafeState::apply` on several joints disables each past a silent one and names it.
#[test]
fn the_safe_state_reaches_every_joint_past_a_silent_one() {
    use robobus::ops::safe::{SafeDevice, WhjJoints};
    let (_sim, bus, _log) = captured(2);
    ready(&bus, id(1), WorkMode::Position);
    ready(&bus, id(2), WorkMode::Position);
    let joints = [
        bus.joint_unchecked(id(1)),
        bus.joint_unchecked(id(3)),
        bus.joint_unchecked(id(2)),
    ];
    let failed = SafeState::Disable.apply(&mut WhjJoints {
        joints: &joints,
        servo: ServoLoop::Position,
    });
    let devices: Vec<SafeDevice> = failed.iter().map(|f| f.device).collect();
    assert_eq!(devices, [SafeDevice::Joint(3)]);
    assert_eq!(failed[0].error.kind(), ErrorKind::NoDevice, "{}", failed[0]);
    assert!(
        failed[0].to_string().starts_with("joint 3: "),
        "{}",
        failed[0]
    );
    assert!(!joints[0].is_enabled().unwrap());
    assert!(!joints[2].is_enabled().unwrap());
}

/// A wave reports the round trip of its frames (send to feedback), on the simulator's
/// virtual clock: a joint that takes 4 ms to answer gives every frame the same round trip,
/// 4 ms plus the two frames' wire time (1 / 5 Mbit/s: well under 0.2 ms).
#[test]
fn a_wave_reports_the_round_trip_of_its_frames() {
    let mut cfg = robobus_sim::whj::JointConfig::new(1, robobus_sim::whj::WhjModel::Whj30);
    cfg.processing_delay = Duration::from_millis(4);
    let (link, _sim) = sim_link(whj_common::configs(vec![cfg]));
    let bus = JointBus::open_with(link, config()).unwrap();
    ready(&bus, id(1), WorkMode::Position);
    let args = WaveArgs {
        joint: id(1),
        shape: Shape::Sine,
        servo: ServoLoop::Position,
        amplitude: 1.0,
        frequency: 1.0,
        offset: 0.0,
        duration: 0.3,
        rate_hz: 100.0,
        step_limit_deg: JointBusConfig::default().step_limit_deg,
    };
    let j = bus.joint(id(1)).unwrap();
    let (_, report) = ops::run_wave(&j, &args, &mut Control::none(), SafeState::Hold).unwrap();
    assert_eq!((report.cycles, report.complete), (30, 30), "{report:?}");
    let p50 = report.round_trip_p50_us.unwrap();
    let p99 = report.round_trip_p99_us.unwrap();
    let max = report.round_trip_max_us.unwrap();
    // 4 ms of processing, the frames, and the collision window the reply is held for.
    let window = u64::try_from(bus.duplicate_check().unwrap().as_micros()).unwrap();
    assert!(
        (4_000 + window..4_200 + window).contains(&p50),
        "{report:?}"
    );
    assert!(
        p50 <= p99 && p99 <= max && max < 4_200 + window,
        "{report:?}"
    );
    let json = serde_json::to_value(&report).unwrap();
    assert_eq!(json["round_trip_p50_us"], p50);
}

/// A captured bus to WHJ30 joints `ids` and an end board.
fn captured_with_end_board(ids: &[u8]) -> (robobus_sim::whj::WhjSimHandle, JointBus, Shared) {
    let sim_bus =
        robobus_sim::whj::WhjBus::chain(ids.iter().copied(), robobus_sim::whj::WhjModel::Whj30, 5)
            .with_end_board();
    let (link, sim) = sim_link(sim_bus);
    let log = Shared::default();
    let link = CaptureFrameLink::new(link, log.clone(), "rx").with_tx_iface("tx");
    let bus = JointBus::open_with(link, config()).unwrap();
    for &j in ids {
        bus.joint(id(j)).unwrap();
    }
    (sim, bus, log)
}

fn broadcast_frames(frames: &[CanFrame]) -> Vec<CanFrame> {
    frames
        .iter()
        .copied()
        .filter(|f| f.raw_id() == 0x0F)
        .collect()
}

#[test]
fn broadcast_register_read_reports_every_slot_the_end_board_and_the_silent_joint() {
    let (_sim, bus, log) = captured_with_end_board(&[1, 2, 4]);
    let temp = robobus_whj::registers::addr::SYS_TEMP;
    let ids = [id(1), id(2), id(3), id(4)];
    let dry = ops::plan_broadcast_read(&ids, temp, None, Some(0x03)).unwrap();
    // Joints 1..4 and the end board: mask F (all), the smallest that covers them.
    let Request::BroadcastRegister(frame) = dry.frames[0] else {
        panic!("{dry:?}")
    };
    assert_eq!(frame.mask.get(), 0xF);
    assert_eq!(frame.end_board[..3], [0x01, 0x03, 0x01]);
    log.clear();
    let (plan, r) = ops::broadcast_read(&bus, &ids, temp, None, Some(0x03)).unwrap();
    assert_eq!(plan, dry);
    // Exactly the dry run's frame went out, once.
    let sent: Vec<_> = dry.frames.iter().map(Request::to_frame).collect();
    assert_eq!(broadcast_frames(&log.sent()), sent);
    assert_eq!(r.len(), 5, "{r:?}");
    for k in [0, 1, 3] {
        let v = r[k].value().unwrap();
        assert_eq!((v.register, v.unit), ("SYS_TEMP", "°C"), "{r:?}");
        assert!(v.value.unwrap() > 0.0);
    }
    assert_eq!(r[2].id, ops::Slot::Joint(id(3)));
    let f = r[2].failure().unwrap();
    assert_eq!(f.kind, ErrorKind::NoDevice);
    assert!(
        f.error.contains("joint 3") || f.error.contains('3'),
        "{f:?}"
    );
    assert_eq!(r[4].id, ops::Slot::EndBoard);
    let eb = r[4].value().unwrap();
    assert_eq!((eb.register, eb.raw), ("EB_SW_VERSION", 0x0203));
    assert_eq!(
        serde_json::to_value(&r[4]).unwrap()["id"],
        serde_json::json!("end-board")
    );
}

#[test]
fn broadcast_register_write_sends_its_dry_run_and_reads_back() {
    let (sim, bus, log) = captured_with_end_board(&[1, 2, 3]);
    let mode = robobus_whj::registers::addr::TAG_WORK_MODE;
    let ids = [id(1), id(2), id(3)];
    let io1 = ops::EndBoardArg {
        addr: 0x1D,
        value: Some(1),
    };
    let dry = ops::plan_broadcast_write(
        &ids,
        mode,
        2.0,
        false,
        &|_| CurrentScale::OneMilliamp,
        Some(io1),
    )
    .unwrap();
    assert_eq!(dry.frames.len(), 2);
    log.clear();
    let (plan, r) =
        ops::broadcast_write(&bus, &ids, mode, 2.0, false, None, Some(io1), true).unwrap();
    assert_eq!(plan.frames, dry.frames);
    let sent: Vec<_> = dry.frames.iter().map(Request::to_frame).collect();
    assert_eq!(broadcast_frames(&log.sent()), sent);
    // The write frame: `[04 02 30 02 00 FF FF]` (a 2-byte word) in slots 1..3, `02 1D 01
    // 01` for the end board; J1..J3 + end board: mask F.
    assert_eq!(sent[0].data()[..7], [4, 2, 0x30, 2, 0, 0xFF, 0xFF]);
    assert_eq!(sent[0].data()[21], 0xFF);
    assert_eq!(sent[0].data()[50..54], [2, 0x1D, 1, 1]);
    assert_eq!(sent[0].data()[63], 0x0F);
    assert_eq!(r.len(), 4, "{r:?}");
    for k in 0..3 {
        let v = r[k].value().unwrap();
        assert_eq!((v.register, v.raw), ("TAG_WORK_MODE", 2), "{r:?}");
    }
    assert_eq!(r[3].value().unwrap().raw, 1);
    // One 0x7F frame for the joints and the end board (mask F): IO1 is an output now. (The
    // joints' position limits, which readings are checked against, are read once first.)
    for j in ids {
        bus.joint(j).unwrap().position_limits().unwrap();
    }
    log.clear();
    let (joints, board) = ops::broadcast_status_with_end_board(&bus, &ids).unwrap();
    assert_eq!(log.sent().len(), 1);
    assert_eq!(log.sent()[0].data()[23], 0x0F);
    assert!(
        joints.iter().all(robobus::ops::DeviceResult::is_ok),
        "{joints:?}"
    );
    let b = board.value().unwrap();
    assert!(b.io1_output && !b.io2_output, "{b:?}");
    drop(bus);
    assert_eq!(sim.with_bus(|b| b.end_board().unwrap().register(0x1D)), 1);
}

#[test]
fn a_refused_broadcast_write_sends_nothing() {
    use robobus_sim::whj::{JointConfig, WhjModel};
    use robobus_whj::units::FirmwareVersion;
    let (_sim, bus, log) = captured_with_end_board(&[1, 2]);
    let ids = [id(1), id(2)];
    log.clear();
    // confirm class without confirmation, never class, motion target: refused before
    // anything is sent (not even the connect).
    let iap = robobus_whj::registers::addr::IAP_FLAG;
    let e = ops::broadcast_write(&bus, &ids, iap, 1.0, false, None, None, false).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused);
    assert!(e.to_string().contains("--yes"), "{e}");
    let calib = robobus_whj::RegisterAddr::new(0x0D).unwrap();
    let e = ops::broadcast_write(&bus, &ids, calib, 1.0, false, None, None, true).unwrap_err();
    assert!(e.to_string().contains("never to write"), "{e}");
    assert!(log.sent().is_empty(), "{:?}", log.sent());
    // An end-board write needs the confirmation too; no 0x0F frame goes out.
    let mode = robobus_whj::registers::addr::TAG_WORK_MODE;
    let power = ops::EndBoardArg {
        addr: 0x07,
        value: Some(3),
    };
    let e =
        ops::broadcast_write(&bus, &ids, mode, 3.0, false, None, Some(power), false).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused);
    // A read-only end-board register is bad input.
    let version = ops::EndBoardArg {
        addr: 0x03,
        value: Some(1),
    };
    let e = ops::plan_broadcast_write(
        &ids,
        mode,
        3.0,
        false,
        &|_| CurrentScale::OneMilliamp,
        Some(version),
    )
    .unwrap_err();
    assert_eq!(e.kind(), ErrorKind::BadInput);
    assert!(broadcast_frames(&log.sent()).is_empty(), "{:?}", log.sent());
    // The firmware gate: one joint before the "519" gate of ON_DELAY refuses the whole
    // frame.
    let mut old = JointConfig::new(2, WhjModel::Whj30);
    old.firmware = FirmwareVersion(0xD510);
    let (link, _sim) = sim_link(whj_common::configs(vec![
        JointConfig::new(1, WhjModel::Whj30),
        old,
    ]));
    let log = Shared::default();
    let link = CaptureFrameLink::new(link, log.clone(), "rx").with_tx_iface("tx");
    let bus = JointBus::open_with(link, config()).unwrap();
    let on_delay = robobus_whj::registers::addr::ON_DELAY;
    let e = ops::broadcast_write(&bus, &ids, on_delay, 1.0, false, None, None, true).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused);
    assert!(e.to_string().contains("D510"), "{e}");
    assert!(broadcast_frames(&log.sent()).is_empty(), "{:?}", log.sent());
}

#[test]
fn broadcast_sampling_sends_one_status_query_per_sample() {
    let (_sim, bus, log) = captured_with_end_board(&[1, 3]);
    // The first sample also reads each answering joint's position limits (once per bus).
    ops::sample_broadcast(&bus, &[id(1), id(2), id(3)]).unwrap();
    log.clear();
    let r = ops::sample_broadcast(&bus, &[id(1), id(2), id(3)]).unwrap();
    let sent = log.sent();
    assert_eq!(sent.len(), 1, "{sent:?}");
    assert_eq!(sent[0].raw_id(), 0x7F);
    // J1..J3 fit mask 1 (J1-J4); the end board is not asked.
    assert_eq!(sent[0].data()[23], 1);
    assert!(r[0].is_ok() && r[2].is_ok(), "{r:?}");
    assert_eq!(r[1].failure().unwrap().kind, ErrorKind::NoDevice);
    assert_eq!(r[0].value().unwrap().speed_rpm, Some(0.0));
}

#[test]
fn a_broadcast_wave_sends_exactly_its_dry_run_as_0x2f_frames() {
    let (_sim, bus, log) = captured(2);
    ready(&bus, id(2), WorkMode::Position);
    let args = WaveArgs {
        joint: id(2),
        shape: Shape::Sine,
        servo: ServoLoop::Position,
        amplitude: 1.0,
        frequency: 2.0,
        offset: 0.0,
        duration: 0.5,
        rate_hz: 100.0,
        step_limit_deg: JointBusConfig::default().step_limit_deg,
    };
    let dry = ops::plan_broadcast_wave(&args, 0.0, CurrentScale::OneMilliamp, true).unwrap();
    assert_eq!(dry.frames.len(), 50);
    // J2's slot carries the target, every other slot "no data", mask 8 (J2 only).
    let first = dry.frames[1].request.to_frame();
    assert_eq!(first.raw_id(), 0x2F);
    assert_eq!(first.data()[..8], robobus_whj::broadcast::POSITION_NO_DATA);
    assert_ne!(first.data()[11], 0x7F);
    assert_eq!(first.data()[63], 8);
    let j = bus.joint(id(2)).unwrap();
    let plan = ops::prepare_broadcast_wave(&j, &args).unwrap();
    log.clear();
    let report =
        ops::execute_wave(&j, &args, &plan, &mut Control::none(), SafeState::Hold).unwrap();
    assert_eq!(plan.frames, dry.frames);
    let sent: Vec<_> = log
        .sent()
        .into_iter()
        .filter(|f| f.raw_id() == 0x2F)
        .collect();
    assert_eq!(sent, plan_frames(&dry));
    assert_eq!(report.cycles, 50);
    assert!(report.complete >= 45, "{report:?}");
    assert!(report.tracking_max.unwrap() < 1.0, "{report:?}");
    // A current wave goes out as 0x4F frames with the target in J2's slot, mask 8.
    let current = WaveArgs {
        servo: ServoLoop::Current,
        amplitude: 100.0,
        ..args
    };
    let cur = ops::plan_broadcast_wave(&current, 0.0, CurrentScale::OneMilliamp, true).unwrap();
    let f = cur.frames[1].request.to_frame();
    assert_eq!((f.raw_id(), f.len()), (0x4F, 48));
    assert_eq!(f.data()[..4], robobus_whj::broadcast::CURRENT_NO_DATA);
    assert_ne!(f.data()[4..8], robobus_whj::broadcast::CURRENT_NO_DATA);
    assert_eq!(f.data()[47], 8);
    // Speed waves have no broadcast frame; a position stream slower than 100 Hz would trip
    // the joints' 20 ms watchdog between frames.
    let speed = WaveArgs {
        servo: ServoLoop::Speed,
        ..args
    };
    let e = ops::plan_broadcast_wave(&speed, 0.0, CurrentScale::OneMilliamp, true).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::BadInput);
    let slow = WaveArgs {
        rate_hz: 40.0,
        frequency: 1.0,
        ..args
    };
    let e = ops::plan_broadcast_wave(&slow, 0.0, CurrentScale::OneMilliamp, true).unwrap_err();
    assert!(
        e.to_string().contains("--rate-hz") && e.to_string().contains("20 ms"),
        "{e}"
    );
}

/// A relay that turns joint 1's first broadcast register reply into an answer for
/// `SYS_VOLTAGE` (0x05) and drops its later ones.
struct OneWrongRegisterReply<L>(L, bool);

impl<L: FrameLink> FrameLink for OneWrongRegisterReply<L> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        self.0.send(frame)
    }
    fn recv(&mut self, deadline: std::time::Instant) -> Result<Received, FrameLinkError> {
        loop {
            let mut r = self.0.recv(deadline)?;
            if r.frame.raw_id() != 0xF2 {
                return Ok(r);
            }
            if !self.1 {
                self.1 = true;
                let mut d = r.frame.data().to_vec();
                d[1] = 0x05;
                r.frame = CanFrame::new_fd(r.frame.id(), &d).unwrap();
                return Ok(r);
            }
        }
    }
    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        self.0.set_filters(filters)
    }

    robobus_link::forward_frame_link_clock!(0);
}

#[test]
fn a_broadcast_reply_counts_only_for_its_register_and_only_after_its_frame() {
    let (link, _sim) = sim_link(chain(2));
    let bus = JointBus::open_with(OneWrongRegisterReply(link, false), config()).unwrap();
    let ids = [id(1), id(2)];
    let temp = robobus_whj::registers::addr::SYS_TEMP;
    let volts = robobus_whj::registers::addr::SYS_VOLTAGE;
    // Joint 1's reply answers SYS_VOLTAGE: not credited to a SYS_TEMP read.
    let (_, r) = ops::broadcast_read(&bus, &ids, temp, None, None).unwrap();
    assert_eq!(r[0].failure().unwrap().kind, ErrorKind::NoDevice, "{r:?}");
    assert_eq!(r[1].value().unwrap().register, "SYS_TEMP");
    // Nor to the next SYS_VOLTAGE read: it arrived before that frame was sent.
    let (_, r) = ops::broadcast_read(&bus, &ids, volts, None, None).unwrap();
    assert_eq!(r[0].failure().unwrap().kind, ErrorKind::NoDevice, "{r:?}");
    assert_eq!(r[1].value().unwrap().register, "SYS_VOLTAGE");
}

/// Rewrites joint 2's position in every broadcast feedback frame to 214748.3647 deg.
fn implausible_broadcast(r: &mut Received) {
    if let Ok(Reply::BroadcastFeedback {
        joint,
        mut feedback,
    }) = Reply::from_frame(&r.frame)
        && joint == id(2)
    {
        feedback.position = Position(i32::MAX);
        r.frame = Reply::BroadcastFeedback { joint, feedback }.to_frame();
    }
}

/// An implausible reading is never shown as the joint's state: `status`, broadcast
/// `status` and both monitor samplings report it as a device failure naming the value,
/// and the other joints as usual.
#[test]
fn implausible_readings_are_failures_in_status_and_samples() {
    let (link, _sim) = sim_link(chain(2));
    let link = OnReceive(link, |r: &mut Received| {
        if let Ok(Reply::Status { joint, .. }) = Reply::from_frame(&r.frame)
            && joint == id(2)
        {
            implausible_status(r);
        }
        implausible_broadcast(r);
    });
    let bus = JointBus::open_with(link, config()).unwrap();
    let ids = [id(1), id(2)];
    let check = |what: &str, failure: Option<&robobus::ops::Failure>| {
        let f = failure.unwrap_or_else(|| panic!("{what}: joint 2 read as valid"));
        assert_eq!(f.kind, ErrorKind::Device, "{what}: {f:?}");
        assert!(
            f.error.contains("214748.36") && f.error.contains("implausible"),
            "{what}: {}",
            f.error
        );
    };
    let r = ops::status(&bus, &ids);
    assert!(r[0].is_ok(), "{r:?}");
    check("status", r[1].failure());
    let r = ops::sample(&bus, &ids);
    assert!(r[0].is_ok(), "{r:?}");
    check("sample", r[1].failure());
    let r = ops::broadcast_status(&bus, &ids).unwrap();
    assert!(r[0].is_ok(), "{r:?}");
    check("broadcast status", r[1].failure());
    let r = ops::sample_broadcast(&bus, &ids).unwrap();
    assert!(r[0].is_ok(), "{r:?}");
    check("broadcast sample", r[1].failure());
    assert_eq!(robobus::ops::worst_kind(&r), Some(ErrorKind::Device));
}

/// `whj read` of the actual position or speed applies the same rule: an implausible value is
/// a device failure naming it, never a row; other registers are reported as read.
#[test]
fn implausible_register_reads_of_position_and_speed_are_failures() {
    let (link, _sim) = sim_link(chain(1));
    let link = OnReceive(link, |r: &mut Received| {
        let d = r.frame.data();
        if r.frame.raw_id() == 0x101 && d.len() >= 6 && d[0] == 0x01 && matches!(d[1], 0x12 | 0x14)
        {
            let mut data = d.to_vec();
            data[2..6].copy_from_slice(&[0xFF, 0xFF, 0xFF, 0x7F]);
            r.frame = CanFrame::new_fd(r.frame.id(), &data).unwrap();
        }
    });
    let bus = JointBus::open_with(link, config()).unwrap();
    for name in ["CUR_POSITION", "CUR_SPEED"] {
        let info = robobus_whj::RegisterInfo::by_name(name).unwrap();
        let e = ops::read_registers(&bus, id(1), info.addr, None).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Device, "{name}: {e}");
        assert!(e.to_string().contains("implausible"), "{name}: {e}");
        // Raw words are what they are: reported, not judged.
        let r = ops::read_registers(&bus, id(1), info.addr, Some(2)).unwrap();
        assert_eq!(r.len(), 2, "{name}");
    }
    let info = robobus_whj::RegisterInfo::by_name("SYS_ID").unwrap();
    assert!(ops::read_registers(&bus, id(1), info.addr, None).is_ok());
}

/// Implausible broadcast feedback stops a broadcast wave as a device failure: it never
/// enters the tracking figures.
#[test]
fn a_broadcast_wave_stops_at_implausible_feedback() {
    let (link, _sim) = sim_link(chain(2));
    let bus = JointBus::open_with(OnReceive(link, implausible_broadcast), config()).unwrap();
    ready(&bus, id(2), WorkMode::Position);
    let args = WaveArgs {
        joint: id(2),
        shape: Shape::Sine,
        servo: ServoLoop::Position,
        amplitude: 1.0,
        frequency: 2.0,
        offset: 0.0,
        duration: 0.5,
        rate_hz: 100.0,
        step_limit_deg: JointBusConfig::default().step_limit_deg,
    };
    let j = bus.joint(id(2)).unwrap();
    let plan = ops::prepare_broadcast_wave(&j, &args).unwrap();
    let e = ops::execute_wave(&j, &args, &plan, &mut Control::none(), SafeState::Hold).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Device, "{e}");
    let text = e.to_string();
    assert!(
        text.contains("214748.3647") && text.contains("implausible"),
        "{text}"
    );
}

/// A relay after which joint 1 answers every broadcast frame twice: its own feedback,
/// then the same frame with the position at 50 deg (what two joints on one ID, or one
/// answering twice, put in one slot).
struct AnswersTwice<L> {
    inner: L,
    queued: Option<Received>,
}

impl<L: FrameLink> FrameLink for AnswersTwice<L> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        self.inner.send(frame)
    }
    fn recv(&mut self, deadline: std::time::Instant) -> Result<Received, FrameLinkError> {
        if let Some(r) = self.queued.take() {
            return Ok(r);
        }
        let r = self.inner.recv(deadline)?;
        if let Ok(Reply::BroadcastFeedback {
            joint,
            mut feedback,
        }) = Reply::from_frame(&r.frame)
            && joint == id(1)
        {
            feedback.position = Position::from_degrees(50.0).unwrap();
            let mut second = r;
            second.frame = Reply::BroadcastFeedback { joint, feedback }.to_frame();
            self.queued = Some(second);
        }
        Ok(r)
    }
    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        self.inner.set_filters(filters)
    }

    robobus_link::forward_frame_link_clock!(inner);
}

/// Two different answers in one joint's broadcast slot: that slot is a device failure
/// naming both, never the first (or a neighbour's) value; the other joint reads as usual.
#[test]
fn two_different_answers_in_one_broadcast_slot_are_a_fault() {
    let (link, _sim) = sim_link(chain(2));
    let link = AnswersTwice {
        inner: link,
        queued: None,
    };
    let bus = JointBus::open_with(link, config()).unwrap();
    for j in [1, 2] {
        bus.joint(id(j)).unwrap();
    }
    for round in 0..4 {
        let r = ops::broadcast_status(&bus, &[id(1), id(2)]).unwrap();
        let f = r[0]
            .failure()
            .unwrap_or_else(|| panic!("round {round}: {r:?}"));
        assert_eq!(f.kind, ErrorKind::Device, "{f:?}");
        assert!(f.error.contains("two different answers"), "{}", f.error);
        assert!(r[1].value().unwrap().position_deg.abs() < 1.0, "{r:?}");
        let s = ops::sample_broadcast(&bus, &[id(1), id(2)]).unwrap();
        assert_eq!(s[0].failure().unwrap().kind, ErrorKind::Device, "{s:?}");
    }
}

/// A broadcast wave counts the set-points its step limiter changed, as a point-to-point
/// wave does (it reported 0 whatever it clamped).
#[test]
fn a_broadcast_wave_counts_its_clamped_set_points() {
    let args = WaveArgs {
        joint: id(2),
        shape: Shape::Square,
        servo: ServoLoop::Position,
        amplitude: 10.0,
        frequency: 1.0,
        offset: 0.0,
        duration: 1.0,
        rate_hz: 100.0,
        step_limit_deg: JointBusConfig::default().step_limit_deg,
    };
    let mut clamped = Vec::new();
    for broadcast in [false, true] {
        let (_sim, bus, _log) = captured(2);
        ready(&bus, id(2), WorkMode::Position);
        let j = bus.joint(id(2)).unwrap();
        let plan = if broadcast {
            ops::prepare_broadcast_wave(&j, &args).unwrap()
        } else {
            ops::prepare_wave(&j, &args).unwrap()
        };
        let r = ops::execute_wave(&j, &args, &plan, &mut Control::none(), SafeState::Hold).unwrap();
        clamped.push(r.clamped);
    }
    assert!(clamped[0] > 0, "{clamped:?}");
    assert_eq!(clamped[0], clamped[1], "point-to-point vs broadcast");
}

/// The connect a dry run shows is what a real connect sends (the release answered at
/// once here, so it goes out once).
#[test]
fn a_connect_sends_the_frames_a_dry_run_shows_for_it() {
    let (_sim, bus, log) = captured(1);
    log.clear();
    bus.joint(id(1)).unwrap();
    let shown: Vec<CanFrame> = robobus::whj::Joint::connect_requests(id(1))
        .iter()
        .map(Request::to_frame)
        .collect();
    assert_eq!(log.sent(), shown);
}
