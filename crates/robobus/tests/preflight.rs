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

/// A robot file of joints `j1` and `j2` (WHJ joints 1 and 2) on the bus `sim-whj`.
const ARM: &str = "[buses.sim-whj]\nkind = \"whj-external\"\n\n\
    [[joints]]\nname = \"j1\"\nbus = \"sim-whj\"\nid = 1\nlimits = [-2.0, 2.0]\n\
    max_velocity = 2.0\nmax_acceleration = 20.0\n\n\
    [[joints]]\nname = \"j2\"\nbus = \"sim-whj\"\nid = 2\nlimits = [-2.0, 2.0]\n\
    max_velocity = 2.0\nmax_acceleration = 20.0\n";

/// A station of the robot file [`ARM`] on a simulated bus of two WHJ30 joints at 0 deg,
/// enabled in position mode, joint 1's current limit at `limit_ma` when given; the
/// frames the client sends captured.
fn arm(limit_ma: Option<f64>) -> (Station, WhjSimHandle, Shared) {
    let cfgs = (1..=2)
        .map(|n| JointConfig::new(n, WhjModel::Whj30).without_iap())
        .collect();
    let (link, sim) = WhjSimLink::new(configs(cfgs));
    let log = Shared::default();
    let link = CaptureFrameLink::new(link, log.clone(), "rx").with_tx_iface("tx");
    let bus = JointBus::open_with(link, virtual_config()).unwrap();
    for n in 1..=2 {
        let j = bus.joint(id(n)).unwrap();
        if let (1, Some(ma)) = (n, limit_ma) {
            j.write_register("LIT_MAX_CURRENT", ma).unwrap();
        }
        j.set_mode(WorkMode::Position).unwrap();
        j.enable().unwrap();
    }
    let mut station = Station::new();
    station.add_whj("sim-whj", bus);
    station
        .set_robot(robobus::robot::RobotConfig::from_toml_str(ARM).unwrap())
        .unwrap();
    (station, sim, log)
}

/// j1 out to 60 deg and back at 60 deg/s (within its `max_velocity`, 1.2 deg a tick at
/// 50 Hz), j2 a little.
const FAST: &str = "time_s,j1,j2\n0,0,0\n1,60,5\n2,0,0\n";

fn play_request(extra: &serde_json::Value) -> Request {
    let mut v = json!({"op": "robot.play", "trajectory": FAST, "rate_hz": 50.0});
    for (k, x) in extra.as_object().unwrap() {
        v[k] = x.clone();
    }
    serde_json::from_value(v).unwrap()
}

#[test]
fn robot_play_driving_a_lagging_whj_joint_too_fast_is_refused_before_its_first_tick_with_no_servo_frame_sent()
 {
    // 300 mA: joint 1 cannot accelerate to 60 deg/s in time.
    let (station, sim, log) = arm(Some(300.0));
    let handled = sim.with_bus(|b| b.joint(1).unwrap().frames_handled());
    log.clear();
    let e = catalogue::run(&station, &play_request(&json!({})), &mut Control::none()).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused, "{e}");
    let OpError::Preflight(refusal) = &e else {
        panic!("{e:?}")
    };
    assert_eq!(refusal.joint, "j1 (joint 1 on sim-whj)", "{refusal:?}");
    assert!(
        refusal
            .reason
            .starts_with("the joint lagged behind the plan: its set-point was clamped "),
        "{refusal:?}"
    );
    // The tick and its time are the play's (50 Hz from its start, no lead-in).
    assert!(refusal.frame > 0, "{refusal:?}");
    #[allow(clippy::cast_precision_loss)]
    let at = refusal.frame as f64 / 50.0;
    assert!((refusal.at_s - at).abs() < 1e-9, "{refusal:?}");
    assert!(
        e.to_string().starts_with(&format!(
            "pre-flight on the simulator: frame {} at {:.3} s: j1 (joint 1 on sim-whj): ",
            refusal.frame, refusal.at_s
        )),
        "{e}"
    );
    // Only reads went out: no servo frame, and the real joint moved not at all.
    assert!(log.servo_frames().is_empty());
    assert!(sim.with_bus(|b| b.joint(1).unwrap().frames_handled()) > handled);
    let j1 = sim.with_bus(|b| b.joint(1).unwrap().state());
    assert!(j1.position_deg.abs() < 1e-6, "{j1:?}");
    // The prediction holds: played anyway, j1 lags and its targets are held back.
    let report = catalogue::run(
        &station,
        &play_request(&json!({"preflight": false})),
        &mut Control::none(),
    )
    .unwrap();
    let v = serde_json::to_value(&report).unwrap();
    assert!(v["results"][0]["limited"].as_u64().unwrap() > 0, "{v:#}");
    assert!(v["summary"].get("preflight").is_none(), "{v:#}");
}

#[test]
fn robot_play_on_joints_that_follow_passes_its_preflight_which_ran_the_real_runs_ticks() {
    let (station, _sim, log) = arm(None);
    let req = play_request(&json!({}));
    let notes = serde_json::to_value(catalogue::plan(&req).unwrap()).unwrap()["notes"].to_string();
    assert!(
        notes.contains("pre-flight: the WHJ joints' identity, status, mode and settings"),
        "{notes}"
    );
    log.clear();
    let t0 = std::time::Instant::now();
    let report = catalogue::run(&station, &req, &mut Control::none()).unwrap();
    let with = t0.elapsed();
    let v = serde_json::to_value(&report).unwrap();
    let s = &v["summary"];
    assert_eq!(v["failed"], serde_json::Value::Null, "{v:#}");
    let flight = &s["preflight"];
    // 2 s at 50 Hz, both ends: the real run's 101 ticks, in 2 s of simulated time.
    assert_eq!(flight["ticks"], 101, "{v:#}");
    assert_eq!(flight["ticks"], s["ticks"], "{v:#}");
    assert!(
        (flight["simulated_s"].as_f64().unwrap() - 2.0).abs() < 0.02,
        "{flight}"
    );
    assert_eq!(flight["joints"][0]["joint"], "j1", "{flight}");
    assert_eq!(flight["joints"][1]["bus"], "sim-whj", "{flight}");
    assert_eq!(flight["joints"][0]["seed"]["mode"], "position", "{flight}");
    assert_eq!(flight["not_flown"], json!([]), "{flight}");
    for row in v["results"].as_array().unwrap() {
        assert_eq!(row["limited"], 0, "{row}");
    }
    // The real run sent a servo frame per joint and tick, and one per joint as it held
    // them at the end (the robot file's safe state).
    assert_eq!(log.servo_frames().len(), 2 * 101 + 2);
    // What the pre-flight costs (shown, not judged: the wall clock of a shared machine).
    let t0 = std::time::Instant::now();
    catalogue::run(
        &station,
        &play_request(&json!({"preflight": false})),
        &mut Control::none(),
    )
    .unwrap();
    eprintln!(
        "robot.play of 2 s: {with:?} pre-flown, {:?} without",
        t0.elapsed()
    );
    // Asked off or too long for the default, the plan says nothing of it.
    for extra in [
        json!({"preflight": false}),
        json!({"trajectory": "time_s,j1\n0,0\n61,1\n"}),
    ] {
        let notes = serde_json::to_value(catalogue::plan(&play_request(&extra)).unwrap()).unwrap()
            ["notes"]
            .to_string();
        assert!(!notes.contains("pre-flight"), "{extra}: {notes}");
    }
}

/// On the built-in robot a play of wCK servos and WHJ joints pre-flies its WHJ joints
/// and names its wCK servos as not flown; one of wCK servos only is not pre-flown.
#[test]
fn robot_play_preflies_its_whj_joints_and_names_the_wck_servos_it_does_not() {
    let station = station(None);
    let port = station.whj(None).unwrap();
    let j = port.bus().joint(id(2)).unwrap();
    j.set_mode(WorkMode::Position).unwrap();
    j.enable().unwrap();
    drop(j);
    drop(port);
    let req: Request = serde_json::from_value(json!({"op": "robot.play",
        "trajectory": "time_s,s0,j1,j2\n0,0,0,0\n1,20,10,-10\n"}))
    .unwrap();
    let v = serde_json::to_value(catalogue::run(&station, &req, &mut Control::none()).unwrap())
        .unwrap();
    let flight = &v["summary"]["preflight"];
    assert_eq!(flight["not_flown"], json!(["s0"]), "{v:#}");
    let flown: Vec<&str> = flight["joints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| j["joint"].as_str().unwrap())
        .collect();
    assert_eq!(flown, ["j1", "j2"], "{v:#}");
    let req: Request = serde_json::from_value(
        json!({"op": "robot.play", "trajectory": "time_s,s0\n0,0\n1,20\n", "preflight": true}),
    )
    .unwrap();
    let v = serde_json::to_value(catalogue::run(&station, &req, &mut Control::none()).unwrap())
        .unwrap();
    assert!(v["summary"].get("preflight").is_none(), "{v:#}");
}
