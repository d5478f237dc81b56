//! How timed WHJ operations end, on the simulator's virtual clock: a planned stream is
//! checked against its plan once (never refused half-way by the host's own step check), a
//! run stops when its joint falls silent or latches an error, and a timed target fails when
//! its joint did.

#![allow(clippy::unwrap_used)] // tests

use crate::whj_common;

use std::time::Duration;

use robobus::catalogue;
use robobus::ops::whj::{self as ops, MoveArgs, ServoLoop, Shape, TargetArgs, WaveArgs};
use robobus::ops::{Control, ErrorKind, OpError, Progress, SafeState, StopToken};
use robobus::station::Station;
use robobus::whj::{JointBus, JointBusConfig};
use robobus_sim::faults::{DeviceFault, DeviceFaultKind, FaultSchedule};
use robobus_sim::whj::{WhjSimHandle, WhjSimLink};
use robobus_whj::units::Position;
use robobus_whj::{JointId, Request, WorkMode};
use whj_common::{chain, virtual_config as config};

fn id(n: u8) -> JointId {
    JointId::new(n).unwrap()
}

/// One simulated joint on the virtual clock, enabled in `mode`, with `faults` at their
/// simulation times.
fn joint_in(mode: WorkMode, faults: Vec<DeviceFault>) -> (WhjSimHandle, JointBus) {
    let (link, sim) = WhjSimLink::with_faults(chain(1), FaultSchedule::new(faults));
    let bus = JointBus::open_with(link, config()).unwrap();
    let j = bus.joint(id(1)).unwrap();
    j.set_mode(mode).unwrap();
    j.enable().unwrap();
    (sim, bus)
}

fn step_limit() -> f64 {
    JointBusConfig::default().step_limit_deg
}

fn latch_at(secs: u64, bits: u16) -> Vec<DeviceFault> {
    vec![DeviceFault {
        at: Duration::from_secs(secs),
        id: 1,
        kind: DeviceFaultKind::Error(bits),
    }]
}

#[test]
fn a_move_at_the_step_limit_and_a_low_rate_runs_to_its_end() {
    // 100 deg/s at 20 Hz is exactly the 5 deg step limit per frame: the feedback (the
    // position before the previous frame) lags the next frame by about two steps, which
    // the old per-frame check refused half-way with a bad-input error.
    let (_sim, bus) = joint_in(WorkMode::Position, vec![]);
    let j = bus.joint(id(1)).unwrap();
    let args = MoveArgs {
        joint: id(1),
        target_deg: 60.0,
        max_speed_deg_s: 100.0,
        rate_hz: 20.0,
        step_limit_deg: step_limit(),
    };
    let plan = ops::plan_move(&args, 0.0, true).unwrap();
    let report = ops::run_move(&j, &args, &mut Control::none(), SafeState::Hold).unwrap();
    assert_eq!(report.frames, plan.frames.len() as u64);
    assert!((report.position_deg - 60.0).abs() <= 0.1, "{report:?}");
}

#[test]
fn a_position_wave_at_a_low_rate_runs_to_its_end() {
    let (_sim, bus) = joint_in(WorkMode::Position, vec![]);
    let j = bus.joint(id(1)).unwrap();
    let args = WaveArgs {
        joint: id(1),
        shape: Shape::Sine,
        servo: ServoLoop::Position,
        amplitude: 20.0,
        frequency: 1.0,
        offset: 0.0,
        duration: 2.0,
        rate_hz: 20.0,
        step_limit_deg: step_limit(),
    };
    let (plan, report) = ops::run_wave(&j, &args, &mut Control::none(), SafeState::Hold).unwrap();
    assert_eq!(report.cycles, plan.frames.len() as u64);
    assert_eq!(report.missing_replies, 0);
}

#[test]
fn a_plan_stepping_past_the_step_limit_is_refused_before_its_first_frame() {
    let frame = |deg: f64| ops::PlannedFrame {
        at: Duration::ZERO,
        request: Request::PositionServo {
            joint: id(1),
            target: Position::from_degrees(deg).unwrap(),
        },
    };
    let mut plan = ops::Plan {
        start_deg: Some(0.0),
        frames: vec![frame(4.0), frame(9.0), frame(14.5)],
        ..ops::Plan::default()
    };
    let e = ops::check_plan_steps(&plan, 5.0, "--max-speed").unwrap_err();
    assert_eq!(e.kind(), ErrorKind::BadInput);
    let text = e.to_string();
    assert!(text.contains("frame 2: 9.0000 -> 14.5000 deg"), "{text}");
    assert!(text.contains("--max-speed"), "{text}");
    // The first frame counts from the start.
    plan.frames = vec![frame(5.5)];
    assert!(ops::check_plan_steps(&plan, 5.0, "--max-speed").is_err());
    plan.frames = vec![frame(5.0), frame(10.0)];
    ops::check_plan_steps(&plan, 5.0, "--max-speed").unwrap();
}

#[test]
fn a_move_stops_when_its_joint_falls_silent_and_names_it() {
    let (sim, bus) = joint_in(WorkMode::Position, vec![]);
    let j = bus.joint(id(1)).unwrap();
    let args = MoveArgs {
        joint: id(1),
        target_deg: 20.0,
        max_speed_deg_s: 10.0,
        rate_hz: 100.0,
        step_limit_deg: step_limit(),
    };
    let plan = ops::plan_move(&args, 0.0, true).unwrap();
    assert!(plan.frames.len() > 200, "{}", plan.frames.len());
    // Pull the plug once 96 frames (about 1 s) went out.
    let mut unplugged_at = None;
    let mut sent_at_unplug = 0;
    let mut on_progress = |p: &Progress| {
        if p.done == 96 && unplugged_at.is_none() {
            sim.set_unplugged(true);
            unplugged_at = Some(sim.now());
            sent_at_unplug = p.done;
        }
    };
    let stop = StopToken::new();
    let mut control = Control::new(&stop).with_progress(&mut on_progress);
    let e = ops::run_move(&j, &args, &mut control, SafeState::Hold).unwrap_err();
    drop(control);
    assert_eq!(e.kind(), ErrorKind::NoDevice, "{e}");
    assert!(matches!(e, OpError::NoDevice(_)), "{e:?}");
    let text = e.to_string();
    assert!(text.contains("joint 1 fell silent"), "{text}");
    // Each unanswered frame waits the 20 ms reply timeout: five of them pass 100 ms.
    assert!(
        text.contains(&format!("stopped after {} of", sent_at_unplug + 5)),
        "{text}"
    );
    // 100 ms of silence, then the safe state's try to hold the silent joint: its status
    // query, three attempts of 20 ms, and the gaps between them.
    let took = sim.now() - unplugged_at.unwrap();
    assert!(
        took >= ops::SILENT_AFTER + Duration::from_millis(60)
            && took < ops::SILENT_AFTER + Duration::from_millis(80),
        "{took:?}"
    );
}

#[test]
fn a_wave_stops_at_the_error_its_joint_latches() {
    // Over-temperature at 1 s into a 3 s wave: the joint disables itself.
    let (_sim, bus) = joint_in(WorkMode::Position, latch_at(1, 0x0008));
    let j = bus.joint(id(1)).unwrap();
    let args = WaveArgs {
        joint: id(1),
        shape: Shape::Sine,
        servo: ServoLoop::Position,
        amplitude: 5.0,
        frequency: 0.5,
        offset: 0.0,
        duration: 3.0,
        rate_hz: 100.0,
        step_limit_deg: step_limit(),
    };
    let e = ops::run_wave(&j, &args, &mut Control::none(), SafeState::Hold).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Device, "{e}");
    let text = e.to_string();
    assert!(text.to_lowercase().contains("temperature"), "{text}");
    assert!(text.contains("disabled at frame"), "{text}");
    assert!(
        text.contains("wave stopped; joint 1 left holding"),
        "{text}"
    );
}

#[test]
fn a_timed_speed_target_fails_when_its_joint_latches_an_error() {
    let (_sim, bus) = joint_in(WorkMode::Speed, latch_at(1, 0x0008));
    let j = bus.joint(id(1)).unwrap();
    let args = TargetArgs {
        joint: id(1),
        servo: ServoLoop::Speed,
        value: 2.0,
        duration: Some(Duration::from_secs(3)),
    };
    let t0 = bus.now();
    let e = ops::run_target(&j, &args, &mut Control::none(), SafeState::Hold).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Device, "{e}");
    assert!(e.to_string().contains("while running"), "{e}");
    // Found at the first status read after the fault, not at the end of the 3 s.
    let took = bus.now() - t0;
    assert!(took < Duration::from_millis(1100), "{took:?}");
}

#[test]
fn a_timed_current_target_fails_when_its_joint_latches_an_error() {
    let (_sim, bus) = joint_in(WorkMode::Current, latch_at(1, 0x0200));
    let j = bus.joint(id(1)).unwrap();
    let args = TargetArgs {
        joint: id(1),
        servo: ServoLoop::Current,
        value: 100.0,
        duration: Some(Duration::from_secs(2)),
    };
    let e = ops::run_target(&j, &args, &mut Control::none(), SafeState::Hold).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Device, "{e}");
}

#[test]
fn a_timed_speed_target_fails_when_its_joint_falls_silent() {
    let faults = vec![DeviceFault {
        at: Duration::from_secs(1),
        id: 1,
        kind: DeviceFaultKind::Silent,
    }];
    let (_sim, bus) = joint_in(WorkMode::Speed, faults);
    let j = bus.joint(id(1)).unwrap();
    let args = TargetArgs {
        joint: id(1),
        servo: ServoLoop::Speed,
        value: 2.0,
        duration: Some(Duration::from_secs(3)),
    };
    let e = ops::run_target(&j, &args, &mut Control::none(), SafeState::Hold).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::NoDevice, "{e}");
    assert!(e.to_string().contains("fell silent"), "{e}");
}

/// `whj status --broadcast` of absent joints (round 2 took 5.1 s for four: the connect
/// timeout before the frame): the joints are released for as many attempts as a request
/// has (`retries + 1`, each waiting one reply timeout, 5 ms apart: 70 ms by default, for
/// all absent joints together), then the frame's replies are collected for the broadcast
/// window (100 ms). The absent joints are no-device rows (exit code 3), the present ones
/// fresh readings.
#[test]
fn a_broadcast_status_with_four_joints_absent_costs_one_reply_budget_then_the_window() {
    let (link, sim) = WhjSimLink::new(chain(3));
    let mut station = Station::new();
    let port = station.add_whj("arm", JointBus::open_with(link, config()).unwrap());
    let bus = port.bus();
    let status = |joints: &str| {
        let json = format!(r#"{{"op": "whj.status", "joints": "{joints}", "broadcast": true}}"#);
        let request = catalogue::Request::parse_many(&json).unwrap().remove(0);
        let t0 = bus.now();
        let r = catalogue::run(&station, &request, &mut Control::none()).unwrap();
        (r, bus.now() - t0)
    };
    let (reply_timeout, attempts) = (config().reply_timeout, config().retries + 1);
    let releases = reply_timeout * attempts + Duration::from_millis(5) * (attempts - 1);
    let window = ops::broadcast_window(bus);
    assert_eq!(
        (releases, window),
        (Duration::from_millis(70), Duration::from_millis(100))
    );
    // Only absent joints: exactly the releases' attempts, then the window.
    let (r, took) = status("4-7");
    assert_eq!(took, releases + window);
    assert_eq!(r.failed_kind(), Some(ErrorKind::NoDevice), "{r:?}");
    assert!(
        r.results.iter().all(|row| row["kind"] == "no-device"),
        "{r:?}"
    );
    // With joints 1..=3 present: the same, and their own frames (the identity and limits
    // reads, each well under a millisecond): never a connect timeout.
    let (r, took) = status("1-7");
    let extra = took
        .checked_sub(releases + window)
        .unwrap_or_else(|| panic!("{took:?}"));
    assert!(extra < Duration::from_millis(10), "{took:?}");
    assert_eq!(r.failed_kind(), Some(ErrorKind::NoDevice), "{r:?}");
    let ids: Vec<_> = r.results.iter().map(|v| v["id"].clone()).collect();
    assert_eq!(
        ids,
        (1..=7).map(|i| serde_json::json!(i)).collect::<Vec<_>>()
    );
    for (n, row) in r.results.iter().enumerate() {
        if n < 3 {
            let joint = u8::try_from(n + 1).unwrap();
            let actual = sim.with_bus(|b| b.joint(joint).unwrap().state().position_deg);
            let reported = row["position_deg"]
                .as_f64()
                .unwrap_or_else(|| panic!("{row}"));
            assert!(
                (reported - actual).abs() < 0.01,
                "joint {joint}: {reported} reported, {actual} actual"
            );
        } else {
            assert_eq!(row["kind"], "no-device", "{row}");
            let error = row["error"].as_str().unwrap();
            assert!(error.contains("no reply to the broadcast"), "{row}");
        }
    }
}
