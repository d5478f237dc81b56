//! The pre-flight on the simulator (`robobus::ops::preflight`), on the simulators' virtual
//! clock: the wave that drove a lagging joint into its step fault is refused before its
//! first frame, naming the frame, its time, the joint and the reason, with nothing sent;
//! the same wave on a joint that can follow it passes, and the real run then sends
//! exactly the plan the dry run shows and the pre-flight ran. Through the catalogue the
//! pre-flight is on by default, `"preflight": false` runs without it, and the dry run
//! says what it reads and refuses.

#![allow(clippy::unwrap_used)] // tests

use crate::whj_common;

use std::io::Write;
use std::sync::{Arc, Mutex};

use robobus::catalogue::{self, Request};
use robobus::ops::whj::{self as ops, ServoLoop, Shape, WaveArgs};
use robobus::ops::{Control, ErrorKind, OpError, SafeState, preflight};
use robobus::station::Station;
use robobus::whj::{JointBus, JointBusConfig};
use robobus_link::{CaptureFrameLink, read_candump};
use robobus_sim::whj::{JointConfig, WhjModel, WhjSimHandle, WhjSimLink};
use robobus_whj::units::CurrentScale;
use robobus_whj::{CanFrame, JointId, WorkMode};
use serde_json::json;
use whj_common::{configs, virtual_config};

fn id(n: u8) -> JointId {
    JointId::new(n).unwrap()
}

/// A capture buffer of the frames the client sent.
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
    /// The servo frames (0x200..0x4FF) the client sent.
    fn servo_frames(&self) -> Vec<CanFrame> {
        let bytes = self.0.lock().unwrap().clone();
        read_candump(&bytes[..])
            .map(Result::unwrap)
            .filter(|r| r.iface == "tx" && matches!(r.frame.raw_id() >> 8, 2..=4))
            .map(|r| r.frame)
            .collect()
    }
}

/// The "real" joint: a WHJ30 at 0 deg whose current limit register (0x40, a setting the
/// pre-flight reads) is `limit_ma` when given, enabled in position mode; its sent frames
/// captured.
fn real_joint(limit_ma: Option<f64>) -> (JointBus, WhjSimHandle, Shared) {
    let cfg = JointConfig::new(1, WhjModel::Whj30).without_iap();
    let (link, sim) = WhjSimLink::new(configs(vec![cfg]));
    let log = Shared::default();
    let link = CaptureFrameLink::new(link, log.clone(), "rx").with_tx_iface("tx");
    let bus = JointBus::open_with(link, virtual_config()).unwrap();
    let j = bus.joint(id(1)).unwrap();
    if let Some(ma) = limit_ma {
        j.write_register("LIT_MAX_CURRENT", ma).unwrap();
    }
    j.set_mode(WorkMode::Position).unwrap();
    j.enable().unwrap();
    (bus, sim, log)
}

/// The wave of the lagging-joint step fault: 15 deg, 1 Hz, 100 Hz for 2 s.
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

#[test]
fn preflight_refuses_the_lagging_joint_wave_before_its_first_frame_naming_frame_time_and_reason() {
    // 0.7 A: the current of the lagging joint that step-faulted.
    let (bus, sim, log) = real_joint(Some(700.0));
    let j = bus.joint(id(1)).unwrap();
    let args = sine();
    let plan = ops::prepare_wave(&j, &args).unwrap();
    let seed = preflight::seed_whj(&j).unwrap();
    assert_eq!(
        (seed.model.as_str(), seed.mode.as_str(), seed.enabled),
        ("WHJ30", "position", true),
        "{seed:?}"
    );
    let limit = seed.settings.get("LIT_MAX_CURRENT").unwrap();
    assert_eq!(limit.value, Some(700.0), "{limit:?}");
    log.clear();
    let handled = sim.with_bus(|b| b.joint(1).unwrap().frames_handled());
    let e = preflight::whj_wave(&seed, &args, &plan, &Control::none()).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused, "{e}");
    let OpError::Preflight(refusal) = &e else {
        panic!("{e:?}")
    };
    assert_eq!(refusal.joint, "joint 1");
    // The frame and its time are the plan's.
    let frame = plan.frames[refusal.frame];
    assert!(
        (frame.at.as_secs_f64() - refusal.at_s).abs() < 1e-9,
        "{refusal:?}"
    );
    assert!(
        refusal.frame > 0 && refusal.frame < plan.frames.len(),
        "{refusal:?}"
    );
    assert!(
        refusal
            .reason
            .starts_with("the joint lagged behind the plan: its set-point was clamped "),
        "{refusal:?}"
    );
    let text = e.to_string();
    assert!(
        text.starts_with(&format!(
            "pre-flight on the simulator: frame {} at {:.3} s: joint 1: ",
            refusal.frame, refusal.at_s
        )) && text.contains("nothing was sent"),
        "{text}"
    );
    // Nothing reached the real joint: no frame at all.
    assert!(log.servo_frames().is_empty());
    assert_eq!(
        sim.with_bus(|b| b.joint(1).unwrap().frames_handled()),
        handled
    );
    // The prediction holds: run anyway, the real joint lags and its set-points are held
    // back (the step fault it would have had).
    let r = ops::execute_wave(&j, &args, &plan, &mut Control::none(), SafeState::Hold).unwrap();
    assert!(r.held_back > 0, "{r:?}");
}

#[test]
fn preflight_passes_the_same_wave_on_a_joint_that_follows_and_the_real_run_sends_the_dry_runs_plan()
{
    let (bus, _sim, log) = real_joint(None);
    let j = bus.joint(id(1)).unwrap();
    let args = sine();
    let dry = ops::plan_wave(&args, 0.0, CurrentScale::OneMilliamp, true).unwrap();
    let plan = ops::prepare_wave(&j, &args).unwrap();
    assert_eq!(plan.frames, dry.frames);
    let seed = preflight::seed_whj(&j).unwrap();
    let flight = preflight::whj_wave(&seed, &args, &plan, &Control::none()).unwrap();
    assert_eq!(flight.frames, plan.frames.len() as u64, "{flight:?}");
    assert!(
        (flight.simulated_s - preflight::plan_length(&plan).as_secs_f64()).abs() < 0.02,
        "{flight:?}"
    );
    log.clear();
    let r = ops::execute_wave(&j, &args, &plan, &mut Control::none(), SafeState::Hold).unwrap();
    assert_eq!(r.held_back, 0, "{r:?}");
    let dry_frames: Vec<CanFrame> = dry.frames.iter().map(|f| f.request.to_frame()).collect();
    assert_eq!(log.servo_frames(), dry_frames);
}

/// A station holding the built-in simulated robot, joint 1 of its arm in position mode,
/// enabled, with its current limit at `limit_ma` when given.
fn station(limit_ma: Option<f64>) -> Station {
    let station = Station::simulated().unwrap();
    let port = station.whj(None).unwrap();
    let j = port.bus().joint(id(1)).unwrap();
    if let Some(ma) = limit_ma {
        j.write_register("LIT_MAX_CURRENT", ma).unwrap();
    }
    j.set_mode(WorkMode::Position).unwrap();
    j.enable().unwrap();
    drop(j);
    drop(port);
    station
}

fn wave_request(extra: &serde_json::Value) -> Request {
    let mut v = json!({"op": "whj.wave", "joint": 1, "amplitude": 15.0, "frequency": 1.0,
                       "duration": 2.0, "rate_hz": 100.0});
    for (k, x) in extra.as_object().unwrap() {
        v[k] = x.clone();
    }
    serde_json::from_value(v).unwrap()
}

#[test]
fn whj_wave_is_preflown_by_default_and_refused_on_a_lagging_joint_and_runs_without_it() {
    let station = station(Some(700.0));
    let e = catalogue::run(&station, &wave_request(&json!({})), &mut Control::none()).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused, "{e}");
    assert!(matches!(e, OpError::Preflight(_)), "{e:?}");
    // Without it the wave runs, its set-points held back where the joint lags.
    let req = wave_request(&json!({"preflight": false}));
    let report = catalogue::run(&station, &req, &mut Control::none()).unwrap();
    let v = serde_json::to_value(&report).unwrap();
    assert!(v["summary"]["held_back"].as_u64().unwrap() > 0, "{v:#}");
    assert!(v["summary"].get("preflight").is_none(), "{v:#}");
}

#[test]
fn whj_wave_on_a_joint_that_follows_reports_its_preflight_and_the_dry_run_says_it_runs() {
    let station = station(None);
    let req = wave_request(&json!({}));
    let plan = catalogue::plan(&req).unwrap();
    let notes = serde_json::to_value(&plan).unwrap()["notes"].to_string();
    assert!(
        notes.contains("pre-flight: before the first frame joint 1's identity"),
        "{notes}"
    );
    let report = catalogue::run(&station, &req, &mut Control::none()).unwrap();
    let v = serde_json::to_value(&report).unwrap();
    let flight = &v["summary"]["preflight"];
    assert_eq!(flight["frames"], 200, "{v:#}");
    assert_eq!(flight["seed"]["mode"], "position", "{v:#}");
    assert_eq!(v["summary"]["held_back"], 0, "{v:#}");
    // Asked off, the plan says nothing of it; a 61 s wave is not pre-flown by default.
    let off = catalogue::plan(&wave_request(&json!({"preflight": false}))).unwrap();
    assert!(
        !serde_json::to_value(&off).unwrap()["notes"]
            .to_string()
            .contains("pre-flight")
    );
    let long = catalogue::plan(&wave_request(&json!({"duration": 61.0}))).unwrap();
    assert!(
        !serde_json::to_value(&long).unwrap()["notes"]
            .to_string()
            .contains("pre-flight")
    );
}

/// A move on a joint that follows passes its pre-flight and reports it; the same move on a
/// joint whose current limit is far too low for it is refused, naming its frame.
#[test]
fn whj_move_is_preflown_passes_on_a_following_joint_and_is_refused_on_a_weak_one() {
    let request: Request = serde_json::from_value(
        json!({"op": "whj.move", "joint": 1, "degrees": 40.0, "max_speed": 120.0}),
    )
    .unwrap();
    let report = catalogue::run(&station(None), &request, &mut Control::none()).unwrap();
    let v = serde_json::to_value(&report).unwrap();
    let row = &v["results"][0];
    assert_eq!(row["held_back"], 0, "{v:#}");
    assert_eq!(row["preflight"]["frames"], row["frames"], "{v:#}");
    let e = catalogue::run(&station(Some(300.0)), &request, &mut Control::none()).unwrap_err();
    let OpError::Preflight(refusal) = &e else {
        panic!("{e:?}")
    };
    assert_eq!(refusal.joint, "joint 1", "{refusal:?}");
    assert!(refusal.frame > 0, "{refusal:?}");
}

/// Speed and broadcast waves are pre-flown too (their frames on the seeded simulator) and
/// pass on a joint that follows them.
#[test]
fn speed_and_broadcast_waves_pass_their_preflight_on_a_joint_that_follows() {
    let station = station(None);
    let broadcast = wave_request(&json!({"broadcast": true, "amplitude": 5.0}));
    let report = catalogue::run(&station, &broadcast, &mut Control::none()).unwrap();
    let v = serde_json::to_value(&report).unwrap();
    assert_eq!(v["summary"]["preflight"]["frames"], 200, "{v:#}");
    let port = station.whj(None).unwrap();
    let j = port.bus().joint(id(1)).unwrap();
    j.disable().unwrap();
    j.set_mode(WorkMode::Speed).unwrap();
    j.enable().unwrap();
    drop(j);
    drop(port);
    let speed = wave_request(&json!({"mode": "speed", "amplitude": 5.0}));
    let report = catalogue::run(&station, &speed, &mut Control::none()).unwrap();
    let v = serde_json::to_value(&report).unwrap();
    assert_eq!(v["summary"]["preflight"]["seed"]["mode"], "speed", "{v:#}");
}
