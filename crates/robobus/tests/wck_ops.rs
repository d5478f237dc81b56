//! `robobus::ops::wck` against the simulator: what a real run sends is, packet by packet,
//! the plan a dry-run shows; per-servo results; stop, progress and the safe state.
#![allow(clippy::unwrap_used, clippy::result_large_err)]

use crate::wck_support;

use std::time::Duration;

use robobus::ErrorKind;
use robobus::ops::wck::{
    self, Motion, Pose, ScanArgs, TeachArgs, TeachEvent, TeachTrigger, WckPlan, WheelArgs,
};
use robobus::ops::{Control, OpError, Progress, SafeState, StopToken};
use robobus::wck::WckBus;
use robobus_link::capture::Dir;
use robobus_link::{ByteLink, CaptureByteLink, read_hex_log};
use robobus_wck::{BaudRate, Command, Position, Rotation, ServoId, TorqueLevel, WheelSpeed};
use wck_support::{DEVICE, Sim, serve_ids};

type Captured<L> = WckBus<CaptureByteLink<L, Vec<u8>>>;

fn capture(sim: &mut Sim) -> Captured<impl ByteLink> {
    WckBus::new(
        CaptureByteLink::new(sim.link(), Vec::new()),
        BaudRate::B115200,
    )
    .unwrap()
    .with_device_name(DEVICE)
}

/// The packets written, with their times in ms since the capture started.
fn written<L: ByteLink>(bus: Captured<L>) -> Vec<(u64, Vec<u8>)> {
    let (_, log) = bus.into_link().into_parts();
    read_hex_log(log.as_slice())
        .unwrap()
        .into_iter()
        .filter(|r| r.dir == Dir::Written)
        .map(|r| (u64::try_from(r.at.as_millis()).unwrap(), r.bytes))
        .collect()
}

/// Asserts that `sent` is `plan`, packet by packet, each timed one sent at its planned
/// millisecond (the capture's clock is the simulator's virtual clock).
fn assert_sent_as_planned(sent: &[(u64, Vec<u8>)], plan: &WckPlan) {
    let planned: Vec<Vec<u8>> = plan
        .steps
        .iter()
        .map(|s| s.command.encode().as_bytes().to_vec())
        .collect();
    let bytes: Vec<Vec<u8>> = sent.iter().map(|(_, b)| b.clone()).collect();
    assert_eq!(bytes, planned, "the real run sent the dry-run's packets");
    let first = sent.first().map_or(0, |(t, _)| *t);
    for ((at, _), step) in sent.iter().zip(&plan.steps) {
        if let Some(due) = step.at_ms {
            assert_eq!(at - first, due, "sent at {at} ms, due at {due} ms");
        }
    }
}

fn id(raw: u8) -> ServoId {
    ServoId::new(raw).unwrap()
}

#[test]
fn a_timed_wheel_run_sends_its_dry_run_and_is_watched() {
    let mut sim = serve_ids(&[0, 1]);
    let mut bus = capture(&mut sim);
    let args = WheelArgs {
        id: id(1),
        rotation: Rotation::Ccw,
        speed: WheelSpeed::new(10).unwrap(),
        duration: Some(Duration::from_millis(650)),
        on_stop: SafeState::Passive,
    };
    let plan = args.plan();
    // Wheel at 0, status reads at 200, 400, 600 ms, passive at 650 ms, then the status
    // read of where it came to rest.
    let times: Vec<Option<u64>> = plan.steps.iter().map(|s| s.at_ms).collect();
    assert_eq!(
        times,
        [Some(0), Some(200), Some(400), Some(600), Some(650), None]
    );
    let report = wck::wheel(&mut bus, &args, &mut Control::none()).unwrap();
    let row = report.value().unwrap();
    assert_eq!(row.get("stopped").unwrap().cell(), "passive");
    // Where it came to rest (the plan's last status read), not where it started.
    let start = row.get("position").unwrap().cell();
    let rest = row.get("stopped_at").unwrap().cell();
    assert_ne!(rest, start, "{row:?}");
    assert_sent_as_planned(&written(bus), &plan);
    let now = sim.with_bus(|b| b.servo(1).unwrap().position());
    assert_eq!(rest, now.to_string(), "{row:?}");
}

#[test]
fn a_wheel_run_whose_servo_goes_silent_ends_early() {
    let mut sim = serve_ids(&[0, 1]);
    let handle = sim.handle.clone();
    let mut bus = sim.bus();
    let args = WheelArgs {
        id: id(1),
        rotation: Rotation::Cw,
        speed: WheelSpeed::new(5).unwrap(),
        duration: Some(Duration::from_secs(20)),
        on_stop: SafeState::Passive,
    };
    let started = handle.now();
    handle.at(started + Duration::from_millis(300), |b| b.unplug(1));
    let err = wck::wheel(&mut bus, &args, &mut Control::none()).unwrap_err();
    assert_eq!(err.kind(), ErrorKind::NoDevice, "{err}");
    assert!(err.to_string().contains("servo 1"), "{err}");
    // Noticed at the watch read at 400 ms, not after 20 s: it fails after 4 attempts (4 ×
    // 11.53 ms reply wait, 3 × 50 ms late window), then the passive command to the silent
    // servo does too (after one more late window), then the last 2 ms drain.
    assert_eq!(
        handle.now().checked_sub(started),
        Some(Duration::from_nanos(844_219_464))
    );
}

#[test]
fn play_sends_its_dry_run() {
    let mut sim = serve_ids(&[0, 1]);
    let mut bus = capture(&mut sim);
    let motion =
        Motion::parse("torque 1\npose 100 100 150\npose 100 120 130\nhold 40\npose 60 127 127\n")
            .unwrap();
    let plan = motion.plan(50.0);
    let report = wck::play(
        &mut bus,
        &motion,
        50.0,
        SafeState::Hold,
        &mut Control::none(),
    )
    .unwrap();
    assert_eq!(report.sent, plan.steps.len() as u64);
    assert_eq!(report.last_positions, [127, 127]);
    assert_eq!(report.planned_ms, 300);
    assert_sent_as_planned(&written(bus), &plan);
}

#[test]
fn a_scan_sends_the_plan_of_what_it_found() {
    let mut sim = serve_ids(&[0, 2, 3]);
    let mut bus = capture(&mut sim);
    let args = ScanArgs::new((0..=5).map(id).collect(), BaudRate::B115200, false);
    let mut seen = Vec::new();
    let mut on_progress = |p: &Progress| seen.push(p.done);
    let stop = StopToken::new();
    let mut control = Control::new(&stop).with_progress(&mut on_progress);
    let report = wck::scan(&mut bus, &args, &mut control).unwrap();
    drop(control);
    assert_eq!(seen, [1, 2, 3, 4, 5, 6]);
    let found: Vec<u8> = report.found.iter().map(|f| f.id).collect();
    assert_eq!(found, [0, 2, 3]);
    let plan = args.plan(&|_, i| found.contains(&i.get()));
    assert_sent_as_planned(&written(bus), &plan);
    // The dry-run's assumption (nobody answers) is the same planner.
    let dry = args.plan(&|_, _| false);
    assert_eq!(dry.steps.len(), 12);
}

#[test]
fn status_of_many_servos_reports_each_one_past_a_silent_one() {
    let mut sim = serve_ids(&[1, 3]);
    let mut bus = sim.bus();
    let mut plan = WckPlan::default();
    for i in 1..=3 {
        plan.push(Command::StatusRead { id: id(i) });
    }
    let report = wck::run_steps(&mut bus, "status", &plan, &mut Control::none()).unwrap();
    let ok: Vec<bool> = report
        .results
        .iter()
        .map(robobus::ops::DeviceResult::is_ok)
        .collect();
    assert_eq!(ok, [true, false, true]);
    let silent = report.results[1].failure().unwrap();
    assert_eq!(silent.kind, ErrorKind::NoDevice);
    assert!(silent.error.contains("servo 2"), "{}", silent.error);
    let json = serde_json::to_value(&report).unwrap();
    assert_eq!(json["results"][0]["id"], 1);
    assert_eq!(json["results"][0]["position"], 127);
    assert_eq!(json["results"][1]["kind"], "no-device");
    assert_eq!(json["results"][2]["id"], 3);
}

#[test]
fn a_stopped_play_brings_the_servos_to_the_safe_state() {
    let mut sim = serve_ids(&[0, 1]);
    let mut bus = capture(&mut sim);
    let motion = Motion::parse("pose 0 100 100\npose 5000 200 200\n").unwrap();
    let stop = StopToken::new();
    let stopper = stop.clone();
    let mut on_progress = |p: &Progress| {
        if p.done >= 200 {
            stopper.stop();
        }
    };
    let mut control = Control::new(&stop).with_progress(&mut on_progress);
    let err = wck::play(&mut bus, &motion, 50.0, SafeState::Passive, &mut control).unwrap_err();
    drop(control);
    assert!(matches!(err, OpError::Interrupted { .. }), "{err}");
    assert_eq!(err.kind(), ErrorKind::Interrupted);
    let sent = written(bus);
    let tail: Vec<Vec<u8>> = sent
        .iter()
        .rev()
        .take(2)
        .rev()
        .map(|(_, b)| b.clone())
        .collect();
    let passive = |i| Command::Passive { id: id(i) }.encode().as_bytes().to_vec();
    assert_eq!(
        tail,
        [passive(0), passive(1)],
        "the safe state went out last"
    );
    assert!(
        sent.len() < 30,
        "stopped after about 200 ms, not at the end"
    );
}

/// Synchronized moves have no reply: the status reads that watch the servos end a play
/// whose servo stops answering, in the safe state, naming the servo (exit 3), instead of
/// reporting every move as played.
#[test]
fn a_play_ends_when_a_servo_stops_answering() {
    let mut sim = serve_ids(&[0, 1]);
    let handle = sim.handle.clone();
    let mut bus = sim.bus();
    let motion = Motion::parse("pose 0 100 100\npose 5000 200 200\n").unwrap();
    let mut unplugged = false;
    let mut on_progress = |p: &Progress| {
        if p.done >= 1000 && !unplugged {
            unplugged = true;
            handle.with_bus(|b| b.unplug(1));
        }
    };
    let stop = StopToken::new();
    let mut control = Control::new(&stop).with_progress(&mut on_progress);
    let t0 = bus.now();
    let err = wck::play(&mut bus, &motion, 50.0, SafeState::Passive, &mut control).unwrap_err();
    drop(control);
    assert_eq!(err.kind(), ErrorKind::NoDevice, "{err}");
    assert!(err.to_string().contains("servo 1"), "{err}");
    // Found by a watch read of servo 1 (every other read: within 400 ms, then its
    // retries), not at the end of the 5 s motion.
    let took = bus.now() - t0;
    assert!(took < Duration::from_millis(1800), "{took:?}");
}

#[test]
fn teach_hands_over_each_pose_as_it_is_recorded_and_keeps_them_on_stop() {
    let mut sim = serve_ids(&[0, 1]);
    let mut bus = sim.bus();
    let args = TeachArgs {
        ids: vec![id(0), id(1)],
        trigger: TeachTrigger::Events { pose_ms: 300 },
        torque: TorqueLevel::MIN,
        on_stop: SafeState::Hold,
    };
    let stop = StopToken::new();
    let mut asked = 0;
    let stopper = stop.clone();
    let mut events = |_: Duration| {
        asked += 1;
        match asked {
            1 | 2 => TeachEvent::Record,
            3 => {
                stopper.stop(); // e.g. Ctrl-C
                TeachEvent::Nothing
            }
            _ => TeachEvent::Finish,
        }
    };
    let mut poses: Vec<Pose> = Vec::new();
    let mut on_pose = |p: &Pose| {
        poses.push(p.clone());
        Ok(())
    };
    let mut control = Control::new(&stop);
    let err = wck::teach(&mut bus, &args, &mut control, &mut events, &mut on_pose).unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Interrupted, "{err}");
    assert!(err.to_string().contains("hold"), "{err}");
    assert_eq!(poses.len(), 3, "the first pose and one per event, all kept");
    assert!(
        poses
            .iter()
            .all(|p| p.ms == 300 && p.positions == [Position::new(127).unwrap(); 2])
    );
    // Teach records servos 0..N-1 only.
    let bad = TeachArgs {
        ids: vec![id(1)],
        ..args
    };
    assert_eq!(bad.check().unwrap_err().kind(), ErrorKind::BadInput);
}

#[test]
fn one_shot_parameter_reads_are_confirmed_by_default() {
    let gains = WckPlan::one(Command::GainRead { id: id(0) });
    let status = WckPlan::one(Command::StatusRead { id: id(0) });
    assert_eq!(wck::confirm_reads_for(&gains, None), 2);
    assert_eq!(wck::confirm_reads_for(&gains, Some(false)), 1);
    assert_eq!(wck::confirm_reads_for(&status, None), 1);
    assert_eq!(wck::confirm_reads_for(&status, Some(true)), 2);
}

#[test]
fn a_scan_with_one_percent_byte_loss_finds_16_servos_and_no_false_duplicate() {
    use robobus_link::{FaultConfig, FaultyByteLink};
    let ids: Vec<u8> = (0..16).collect();
    for seed in [1, 2, 3] {
        let mut sim = wck_support::serve_fast(&ids, BaudRate::B115200);
        let faults = FaultConfig {
            drop: 0.01,
            ..FaultConfig::seeded(seed)
        };
        let mut bus = WckBus::new(FaultyByteLink::new(sim.link(), faults), BaudRate::B115200)
            .unwrap()
            .with_device_name(DEVICE);
        let args = ScanArgs::new((0..=15).map(id).collect(), BaudRate::B115200, false);
        let report = wck::scan(&mut bus, &args, &mut Control::none()).unwrap();
        let found: Vec<u8> = report.found.iter().map(|f| f.id).collect();
        assert!(
            report.duplicates.is_empty(),
            "seed {seed}: false duplicates {:?} (dropped {})",
            report.duplicates,
            bus.link().stats().dropped
        );
        assert_eq!(
            found, ids,
            "seed {seed}: every servo that answered is listed"
        );
    }
}

#[test]
fn a_shared_bus_serves_servo_handles_on_other_threads() {
    use robobus::ops::wck::SharedWckBus;
    let mut sim = serve_ids(&[0, 1]);
    let shared = SharedWckBus::new(sim.bus());
    let handles: Vec<_> = [0, 1]
        .into_iter()
        .map(|i| {
            let servo = shared.servo(id(i));
            std::thread::spawn(move || servo.status().unwrap().position.get())
        })
        .collect();
    let positions: Vec<u8> = handles.into_iter().map(|h| h.join().unwrap()).collect();
    assert_eq!(positions, [127, 127]);
    let report = shared.with(|bus| {
        wck::run_steps(
            bus,
            "status",
            &WckPlan::one(Command::StatusRead { id: id(1) }),
            &mut Control::none(),
        )
    });
    assert!(report.unwrap().results[0].is_ok());
}

/// A timed wheel run stopped halfway leaves the servo in the chosen safe state (one
/// `SafeState::apply` for the operations and the robot watchdog).
#[test]
fn a_stopped_wheel_run_leaves_the_servo_in_each_safe_state() {
    use robobus_sim::wck::Mode;
    for (state, mode, says) in [
        (SafeState::Passive, Mode::Passive, "servo(s) 1 passive"),
        (SafeState::Break, Mode::Break, "servo(s) 1 braked"),
        (SafeState::Hold, Mode::Position, "servo(s) 1 holding"),
    ] {
        let mut sim = serve_ids(&[0, 1]);
        let mut bus = sim.bus();
        let args = WheelArgs {
            id: id(1),
            rotation: Rotation::Ccw,
            speed: WheelSpeed::new(10).unwrap(),
            duration: Some(Duration::from_secs(20)),
            on_stop: state,
        };
        // Stopped after the watch read at 400 ms of the 20 s run (the virtual clock).
        let stop = StopToken::new();
        let stopper = stop.clone();
        let mut on_progress = |p: &Progress| {
            if p.done >= 400 {
                stopper.stop();
            }
        };
        let mut control = Control::new(&stop).with_progress(&mut on_progress);
        let err = wck::wheel(&mut bus, &args, &mut control).unwrap_err();
        drop(control);
        assert!(sim.now() < Duration::from_secs(1), "{:?}", sim.now());
        assert_eq!(err.kind(), ErrorKind::Interrupted);
        assert_eq!(err.to_string(), format!("interrupted: {says}"));
        let (mode_now, mode_other) = sim.with_bus(|b| {
            let m = |id| b.servo(b.slot_of(id).unwrap()).unwrap().mode();
            (m(1), m(0))
        });
        assert_eq!(mode_now, mode, "{state:?}");
        // The break is one broadcast: servo 0 brakes too; otherwise it is left alone.
        let other = if state == SafeState::Break {
            Mode::Break
        } else {
            Mode::Passive
        };
        assert_eq!(mode_other, other, "{state:?}");
    }
}

/// `SafeState::apply` tries every servo past a silent one and names each failure.
#[test]
fn the_safe_state_reaches_every_servo_past_a_silent_one() {
    use robobus::ops::safe::{SafeDevice, WckServos};
    use robobus_sim::wck::Mode;
    let mut sim = serve_ids(&[0, 2]);
    let mut bus = sim.bus();
    sim.with_bus(|b| {
        for id in [0, 2] {
            let slot = b.slot_of(id).unwrap();
            assert_eq!(b.servo(slot).unwrap().mode(), Mode::Passive);
        }
    });
    // Hold first (every module is passive at power-up): servos 0 and 2 go to position
    // control, servo 1 does not answer.
    let ids = [id(0), id(1), id(2)];
    let failed = SafeState::Hold.apply(&mut WckServos {
        bus: &mut bus,
        ids: &ids,
        torque: TorqueLevel::MIN,
    });
    let devices: Vec<SafeDevice> = failed.iter().map(|f| f.device).collect();
    assert_eq!(devices, [SafeDevice::Servo(1)]);
    assert_eq!(failed[0].error.kind(), ErrorKind::NoDevice, "{}", failed[0]);
    assert!(
        failed[0].to_string().starts_with("servo 1: "),
        "{}",
        failed[0]
    );
    let modes = sim.with_bus(|b| [0, 2].map(|id| b.servo(b.slot_of(id).unwrap()).unwrap().mode()));
    assert_eq!(modes, [Mode::Position, Mode::Position]);
    // Passive: the same, back to passive.
    let failed = SafeState::Passive.apply(&mut WckServos {
        bus: &mut bus,
        ids: &ids,
        torque: TorqueLevel::MIN,
    });
    assert_eq!(failed.len(), 1);
    let modes = sim.with_bus(|b| [0, 2].map(|id| b.servo(b.slot_of(id).unwrap()).unwrap().mode()));
    assert_eq!(modes, [Mode::Passive, Mode::Passive]);
}
