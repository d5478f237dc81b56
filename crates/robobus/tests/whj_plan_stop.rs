//! A stop while a long WHJ move or wave is being planned (a slow move has up to 360 000
//! frames, a wave up to 600 000) ends the run there, with the stop's report (the joint in
//! its safe state), before any frame of the plan is sent. On the simulator's virtual
//! clock, the frames the client sent captured.

#![allow(clippy::unwrap_used)] // tests

use crate::whj_common;

use std::io::Write;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use robobus::catalogue::{self, Request};
use robobus::ops::whj::{self as ops, MoveArgs, ServoLoop, Shape, WaveArgs};
use robobus::ops::{Control, ErrorKind, SafeState, StopToken};
use robobus::station::Station;
use robobus::whj::{JointBus, JointBusConfig};
use robobus_link::{CaptureFrameLink, read_candump};
use robobus_whj::{CanFrame, JointId, WorkMode};
use whj_common::{chain, sim_link, virtual_config as config};

/// A capture buffer shared with the bus.
#[derive(Clone, Default)]
struct Captured(Arc<Mutex<Vec<u8>>>);

impl Write for Captured {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(b);
        Ok(b.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Captured {
    /// The servo frames (position, speed, current) the client sent since `clear`.
    fn servo_frames(&self) -> Vec<CanFrame> {
        let bytes = self.0.lock().unwrap().clone();
        read_candump(&bytes[..])
            .map(Result::unwrap)
            .filter(|r| r.iface == "tx")
            .map(|r| r.frame)
            .filter(|f| matches!(f.raw_id() >> 8, 2..=4))
            .collect()
    }

    fn clear(&self) {
        self.0.lock().unwrap().clear();
    }
}

/// Joint 1 on a simulated bus whose sent frames are captured, enabled in position mode.
fn joint_bus() -> (robobus_sim::whj::WhjSimHandle, JointBus, Captured) {
    let (link, sim) = sim_link(chain(1));
    let log = Captured::default();
    let link = CaptureFrameLink::new(link, log.clone(), "rx").with_tx_iface("tx");
    let bus = JointBus::open_with(link, config()).unwrap();
    let j = bus.joint(JointId::new(1).unwrap()).unwrap();
    j.set_mode(WorkMode::Position).unwrap();
    j.enable().unwrap();
    (sim, bus, log)
}

/// A stop token that asks to stop at its `nth` look (and counts its looks).
fn stop_at_look(nth: usize) -> (StopToken, Arc<AtomicUsize>) {
    let looks = Arc::new(AtomicUsize::new(0));
    let counted = Arc::clone(&looks);
    let token =
        StopToken::new().with_poll(move || counted.fetch_add(1, Ordering::SeqCst) + 1 >= nth);
    (token, looks)
}

/// 0.1 deg/s over 30 deg at 1000 frames/s: 300 000 frames to plan.
fn slow_move() -> MoveArgs {
    MoveArgs {
        joint: JointId::new(1).unwrap(),
        target_deg: 30.0,
        max_speed_deg_s: 0.1,
        rate_hz: 1000.0,
        step_limit_deg: JointBusConfig::default().step_limit_deg,
    }
}

#[test]
fn a_stop_while_a_move_is_planned_ends_the_planning_there_and_disables_the_joint_before_any_frame()
{
    let (_sim, bus, log) = joint_bus();
    let j = bus.joint(JointId::new(1).unwrap()).unwrap();
    log.clear();
    // A move whose plan is refused at its end, its 360 000th frame (0.1 deg/s over
    // 360 deg at 1000 frames/s would take 3.6 million): the stop ends it long before. The
    // plan looks at the token when it begins and every 4096 frames: the third look is
    // 8192 frames into it.
    let too_long = MoveArgs {
        target_deg: 360.0,
        ..slow_move()
    };
    assert!(ops::plan_move(&too_long, 0.0, true).is_err());
    let (stop, looks) = stop_at_look(3);
    let err =
        ops::run_move(&j, &too_long, &mut Control::new(&stop), SafeState::Disable).unwrap_err();
    assert_eq!(
        looks.load(Ordering::SeqCst),
        3,
        "the planning ended at the stop"
    );
    assert_eq!(log.servo_frames(), [], "no frame of the move was sent");
    assert!(!j.is_enabled().unwrap());
    assert_eq!(err.kind(), ErrorKind::Interrupted);
    assert_eq!(
        err.to_string(),
        "interrupted: joint 1 disabled (stopped while its frames were planned: none was sent)"
    );
}

#[test]
fn a_stopped_whj_move_request_holds_the_joint_where_it_stands_without_moving_it() {
    let (_sim, bus, log) = joint_bus();
    let before = bus
        .joint(JointId::new(1).unwrap())
        .unwrap()
        .status()
        .unwrap()
        .position;
    let mut station = Station::new();
    station.add_whj("arm", bus);
    let request = Request::parse_many(
        r#"{"op": "whj.move", "joint": 1, "degrees": 30, "max_speed": 0.1, "rate_hz": 1000}"#,
    )
    .unwrap()
    .remove(0);
    log.clear();
    let (stop, looks) = stop_at_look(2);
    let err = catalogue::run(&station, &request, &mut Control::new(&stop)).unwrap_err();
    assert_eq!(looks.load(Ordering::SeqCst), 2);
    // The one servo frame is the hold, at the position the joint stands at.
    let port = station.whj(None).unwrap();
    let j = port.bus().joint(JointId::new(1).unwrap()).unwrap();
    let hold = ops::Plan {
        frames: vec![ops::PlannedFrame {
            at: std::time::Duration::ZERO,
            request: robobus_whj::Request::PositionServo {
                joint: JointId::new(1).unwrap(),
                target: before,
            },
        }],
        ..ops::Plan::default()
    };
    let want: Vec<CanFrame> = hold.frames.iter().map(|f| f.request.to_frame()).collect();
    assert_eq!(log.servo_frames(), want);
    assert_eq!(j.status().unwrap().position, before);
    assert!(j.is_enabled().unwrap());
    assert_eq!(err.kind(), ErrorKind::Interrupted);
    assert_eq!(
        err.to_string(),
        "interrupted: joint 1 holding (stopped while its frames were planned: none was sent)"
    );
}

#[test]
fn a_stop_while_a_long_wave_is_planned_ends_it_before_any_frame_of_it() {
    let (_sim, bus, log) = joint_bus();
    let j = bus.joint(JointId::new(1).unwrap()).unwrap();
    log.clear();
    // 600 s at 1000 frames/s.
    let args = WaveArgs {
        joint: JointId::new(1).unwrap(),
        servo: ServoLoop::Position,
        shape: Shape::Sine,
        amplitude: 5.0,
        frequency: 0.5,
        offset: 0.0,
        duration: 600.0,
        rate_hz: 1000.0,
        step_limit_deg: JointBusConfig::default().step_limit_deg,
    };
    let (stop, looks) = stop_at_look(3);
    let err = ops::run_wave(&j, &args, &mut Control::new(&stop), SafeState::Disable).unwrap_err();
    assert_eq!(looks.load(Ordering::SeqCst), 3);
    assert_eq!(log.servo_frames(), []);
    assert!(!j.is_enabled().unwrap());
    assert_eq!(
        err.to_string(),
        "interrupted: joint 1 disabled (stopped while its frames were planned: none was sent)"
    );
}
