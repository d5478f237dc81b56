//! Every public wCK operation against the simulator: in process behind a `SimLink` (so
//! that the outcome does not depend on how loaded the machine is), and a real-port open of
//! the simulator's pseudo-terminal.
#![cfg(target_os = "linux")]
#![allow(clippy::unwrap_used)] // test helpers

use crate::wck_support;

use std::time::Duration;

use robobus::wck::{Gains, ScanOptions, SpeedAccel, WckError};
use robobus_sim::wck::Mode;
use robobus_wck::program::{DelayMs, Instruction, Program};
use robobus_wck::{
    Accel, BaudRate, Boundaries, DGain, DataByte, ExtServoId, IGain, IoBits, Overload, PGain,
    Position, Position10, Reply, Rotation, Speed, Target, TorqueLevel, WheelSpeed,
};
use wck_support::{id, serve_ids, serve_modules};

fn pos(p: u8) -> Position {
    Position::new(p).unwrap()
}

fn torque(t: u8) -> TorqueLevel {
    TorqueLevel::new(t).unwrap()
}

fn slot_mode(sim: &wck_support::Sim, servo_id: u8) -> Mode {
    sim.with_bus(move |b| b.servo(b.slot_of(servo_id).unwrap()).unwrap().mode())
}

#[test]
fn moves_status_10_bit_passive_and_wheel() {
    let mut sim = serve_ids(&[0, 1]);
    let mut bus = sim.bus();
    let mut servo = bus.servo(id(1));
    // A move replies the status before moving.
    let before = servo.move_to(torque(0), pos(200)).unwrap();
    assert_eq!(before.position, pos(127));
    sim.sleep(Duration::from_millis(600));
    let now = servo.status().unwrap();
    assert_eq!(now.position, pos(200));
    // The 10-bit read agrees with the 8-bit one in degrees.
    let p10 = servo.read10().unwrap();
    assert_eq!(p10.get(), 648, "{p10} vs {}", now.position); // 211° both
    let target = Position10::new(300).unwrap();
    let before10 = servo.move10(DataByte::new(0).unwrap(), target).unwrap();
    assert_eq!(before10, p10);
    sim.sleep(Duration::from_millis(600));
    let p10 = servo.read10().unwrap();
    assert_eq!(p10.get(), 300);
    // Servo 0 did not move.
    assert_eq!(bus.servo(id(0)).status().unwrap().position, pos(127));

    let at = bus.servo(id(1)).passive().unwrap();
    assert_eq!(at, pos(93), "{at}"); // the 10-bit 300 (97.5°) in 8-bit steps
    assert_eq!(slot_mode(&sim, 1), Mode::Passive);
    // Passive: turned by hand, it still reads.
    sim.with_bus(|b| b.servo_mut(1).unwrap().set_position(60));
    assert_eq!(bus.servo(id(1)).status().unwrap().position, pos(60));

    let wheel = bus
        .servo(id(1))
        .wheel(Rotation::Ccw, WheelSpeed::new(10).unwrap())
        .unwrap();
    assert_eq!(wheel.position, pos(60));
    assert_eq!(slot_mode(&sim, 1), Mode::Wheel);
    sim.sleep(Duration::from_millis(200));
    let moved = bus.servo(id(1)).status().unwrap().position;
    // 200 ms after the wheel command's reply, and the status read's transaction: the
    // line stays quiet for one byte time plus the turnaround spread (89.8 µs at 115200
    // bit/s) after a reply before it is credited.
    assert_eq!(moved, pos(106), "the wheel turns: 60 -> 106 in 200 ms");
    bus.servo(id(1)).move_to(torque(0), pos(127)).unwrap();
    assert_eq!(slot_mode(&sim, 1), Mode::Position);
}

#[test]
fn gains_speed_overload_boundaries_and_io() {
    let mut sim = serve_ids(&[4]);
    let mut bus = sim.bus();
    let mut s = bus.servo(id(4));
    let eeprom = |sim: &wck_support::Sim| sim.with_bus(|b| *b.servo(0).unwrap().eeprom());

    // P, D gains: defaults, EEPROM write (verified), runtime write.
    assert_eq!(
        s.gains().unwrap(),
        Gains {
            p: PGain::DEFAULT,
            d: DGain::DEFAULT
        }
    );
    let g = Gains {
        p: PGain::new(40).unwrap(),
        d: DGain::new(60).unwrap(),
    };
    s.set_gains(g).unwrap();
    assert_eq!(s.gains().unwrap(), g);
    let runtime = Gains {
        p: PGain::new(50).unwrap(),
        d: DGain::new(70).unwrap(),
    };
    s.set_runtime_gains(runtime).unwrap();
    assert_eq!(s.gains().unwrap(), runtime);
    let e = eeprom(&sim);
    assert_eq!((e.p, e.d), (g.p, g.d), "runtime gains stay out of EEPROM");

    // I gain.
    let mut s = bus.servo(id(4));
    assert_eq!(s.i_gain().unwrap(), IGain::DEFAULT);
    s.set_i_gain(IGain::new(5).unwrap()).unwrap();
    assert_eq!(s.i_gain().unwrap().get(), 5);
    s.set_runtime_i_gain(IGain::new(7).unwrap()).unwrap();
    assert_eq!(s.i_gain().unwrap().get(), 7);
    assert_eq!(eeprom(&sim).i.get(), 5);

    // Speed and acceleration.
    let mut s = bus.servo(id(4));
    assert_eq!(
        s.speed().unwrap(),
        SpeedAccel {
            speed: Speed::DEFAULT,
            accel: Accel::DEFAULT
        }
    );
    let sa = SpeedAccel {
        speed: Speed::new(10).unwrap(),
        accel: Accel::new(40).unwrap(),
    };
    s.set_speed(sa).unwrap();
    assert_eq!(s.speed().unwrap(), sa);
    let rt = SpeedAccel {
        speed: Speed::new(20).unwrap(),
        accel: Accel::new(80).unwrap(),
    };
    s.set_runtime_speed(rt).unwrap();
    assert_eq!(
        s.speed().unwrap(),
        rt,
        "the simulator reports runtime values"
    );
    let e = eeprom(&sim);
    assert_eq!((e.speed, e.accel), (sa.speed, sa.accel));

    // Over-load, in codes and mA.
    let mut s = bus.servo(id(4));
    assert_eq!(s.overload().unwrap(), Overload::DEFAULT);
    assert_eq!(s.overload_milliamps().unwrap(), 400);
    s.set_overload_milliamps(1000).unwrap();
    assert_eq!(s.overload_milliamps().unwrap(), 1000);
    assert_eq!(s.overload().unwrap().get(), 104);
    let attempts = s.bus().stats().attempts;
    let err = s.set_overload_milliamps(2000).unwrap_err();
    assert!(matches!(err, WckError::Value { .. }), "{err}");
    assert!(err.to_string().contains("2000"), "{err}");
    assert_eq!(s.bus().stats().attempts, attempts, "nothing was sent");
    s.set_overload(Overload::new(150).unwrap()).unwrap();
    assert_eq!(eeprom(&sim).overload.get(), 150);

    // Boundaries, and a move limited by them.
    let mut s = bus.servo(id(4));
    assert_eq!(s.boundaries().unwrap(), Boundaries::DEFAULT);
    let bounds = Boundaries::new(pos(50), pos(200)).unwrap();
    s.set_boundaries(bounds).unwrap();
    assert_eq!(s.boundaries().unwrap(), bounds);
    assert_eq!(eeprom(&sim).bounds, bounds);
    s.move_to(torque(0), pos(250)).unwrap();
    sim.sleep(Duration::from_millis(500));
    let p = s.status().unwrap().position.get();
    assert_eq!(p, 200, "stopped at the upper boundary");

    // I/O.
    sim.with_bus(|b| b.servo_mut(0).unwrap().set_adc(123));
    let mut s = bus.servo(id(4));
    let io = s.io().unwrap();
    assert_eq!(
        (io.outputs, io.adc),
        (IoBits::from_outputs(false, false), 123)
    );
    s.set_outputs(IoBits::from_outputs(true, false)).unwrap();
    assert_eq!(s.io().unwrap().outputs, IoBits::from_outputs(true, false));
    assert_eq!(
        sim.with_bus(|b| b.servo(0).unwrap().outputs()),
        IoBits::from_outputs(true, false)
    );
}

#[test]
fn motion_program_upload_is_verified_and_count_reads_back() {
    let mut sim = serve_ids(&[2]);
    let mut bus = sim.bus();
    let mut s = bus.servo(id(2));
    assert_eq!(s.program_count().unwrap().get(), 0);
    let program = Program::new(&[
        Instruction::Move {
            torque: torque(0),
            position: pos(82),
        },
        Instruction::Delay(DelayMs::new(266).unwrap()),
        Instruction::Move {
            torque: torque(0),
            position: pos(172),
        },
        Instruction::Delay(DelayMs::new(266).unwrap()),
    ])
    .unwrap();
    s.upload_program(&program).unwrap();
    assert_eq!(s.program_count().unwrap().get(), 4);
    assert_eq!(
        sim.with_bus(|b| b.servo(0).unwrap().eeprom().program),
        program
    );
    // The program runs: the shaft swings between 82 and 172.
    let (mut low, mut high) = (u8::MAX, 0);
    let start = sim.now();
    while (low > 90 || high < 165) && sim.now().saturating_sub(start) < Duration::from_secs(5) {
        let p = bus.servo(id(2)).status().unwrap().position.get();
        (low, high) = (low.min(p), high.max(p));
        sim.sleep(Duration::from_millis(20));
    }
    assert_eq!(
        (low, high),
        (82, 167),
        "the shaft swings between 82 and 172"
    );
    // An empty program switches it off.
    bus.servo(id(2)).upload_program(&Program::EMPTY).unwrap();
    assert_eq!(bus.servo(id(2)).program_count().unwrap().get(), 0);
}

#[test]
fn id_change_is_verified_at_the_new_id_and_refused_when_taken() {
    let mut sim = serve_ids(&[0, 1]);
    let mut bus = sim.bus();
    let err = bus
        .servo(id(0))
        .set_id(ExtServoId::new(1).unwrap())
        .unwrap_err();
    assert!(matches!(err, WckError::IdInUse { new_id: 1, .. }), "{err}");
    assert_eq!(
        sim.with_bus(|b| b.servo(0).unwrap().id().get()),
        0,
        "nothing renamed"
    );

    let mut s = bus.servo(id(0));
    s.set_id(ExtServoId::new(7).unwrap()).unwrap();
    assert_eq!(s.id(), id(7), "the handle follows");
    assert_eq!(s.status().unwrap().position, pos(127));
    assert_eq!(sim.with_bus(|b| b.servo(0).unwrap().id().get()), 7);
    let old = bus.servo(id(0)).status().unwrap_err();
    assert!(old.is_timeout(), "{old}");

    // Above 30 only the 10-bit commands reach it.
    bus.servo(id(7))
        .set_id(ExtServoId::new(200).unwrap())
        .unwrap();
    let p = bus.read10(ExtServoId::new(200).unwrap()).unwrap();
    assert_eq!(p.get(), 412, "{p}"); // 127 × 1.055° in steps of 0.325°
    let before = bus
        .move10(
            ExtServoId::new(200).unwrap(),
            DataByte::new(0).unwrap(),
            Position10::new(500).unwrap(),
        )
        .unwrap();
    assert_eq!(before, p);
}

#[test]
fn baud_change_is_verified_at_the_new_rate_and_the_bus_follows() {
    let mut sim = serve_ids(&[3]);
    let mut bus = sim.bus();
    bus.servo(id(3)).set_baud(BaudRate::B57600).unwrap();
    assert_eq!(bus.baud(), BaudRate::B57600);
    assert_eq!(
        sim.with_bus(|b| b.servo(0).unwrap().baud()),
        BaudRate::B57600
    );
    assert_eq!(bus.servo(id(3)).status().unwrap().position, pos(127));
    // Back, and the host alone can switch too.
    bus.servo(id(3)).set_baud(BaudRate::B921600).unwrap();
    bus.set_host_baud(BaudRate::B115200).unwrap();
    assert!(bus.servo(id(3)).status().unwrap_err().is_timeout());
    bus.set_host_baud(BaudRate::B921600).unwrap();
    assert_eq!(bus.servo(id(3)).status().unwrap().position, pos(127));
}

#[test]
fn sync_move_moves_every_servo_and_break_stops_them_all() {
    let mut sim = serve_ids(&[0, 1, 2]);
    let mut bus = sim.bus();
    bus.sync_move(torque(0), &[pos(60), pos(127), pos(200)])
        .unwrap();
    sim.sleep(Duration::from_millis(700));
    for (n, want) in [(0, 60), (1, 127), (2, 200)] {
        let p = bus.servo(id(n)).status().unwrap().position.get();
        assert_eq!(p, want, "servo {n}");
    }
    let err = bus.sync_move(torque(0), &[]).unwrap_err();
    assert!(matches!(err, WckError::Value { .. }), "{err}");

    // Three modules answer a break at once: the command was heard either way.
    // Their replies collide on the wired-AND line: IDs 0 & 1 & 2, positions 60 & 127 & 200.
    let reply = bus.break_all().unwrap();
    assert_eq!(
        reply,
        Some(Reply::Break {
            id: id(0),
            position: pos(0b0011_1100 & 0b0111_1111 & 0b1100_1000) // 8
        })
    );
    for n in 0..3 {
        assert_eq!(slot_mode(&sim, n), Mode::Break, "servo {n}");
    }
}

#[test]
fn break_with_one_servo_reports_its_id() {
    let mut sim = serve_ids(&[9]);
    let mut bus = sim.bus();
    let reply = bus.break_all().unwrap();
    assert_eq!(
        reply,
        Some(Reply::Break {
            id: id(9),
            position: pos(127)
        })
    );
    assert_eq!(slot_mode(&sim, 9), Mode::Break);
    // Any command leaves break mode again.
    bus.servo(id(9)).move_to(torque(0), pos(127)).unwrap();
    assert_eq!(slot_mode(&sim, 9), Mode::Position);
}

#[test]
fn execute_sends_any_typed_command_with_its_policy() {
    let mut sim = serve_ids(&[5]);
    let mut bus = sim.bus();
    let reply = bus
        .execute(&robobus_wck::Command::StatusRead { id: id(5) })
        .unwrap();
    assert_eq!(
        reply,
        Some(Reply::Status {
            load: robobus_wck::Load::new(0).unwrap(),
            position: pos(127)
        })
    );
    let none = bus
        .execute(&robobus_wck::Command::RuntimeSpeedSet {
            id: id(5),
            speed: Speed::new(3).unwrap(),
            accel: Accel::new(30).unwrap(),
        })
        .unwrap();
    assert_eq!(none, None);
    assert_eq!(bus.servo(id(5)).speed().unwrap().speed.get(), 3);
}

#[test]
fn scan_finds_every_module_and_reports_progress() {
    let mut sim = serve_ids(&[0, 3, 4]);
    let mut bus = sim.bus();
    let mut calls = Vec::new();
    let report = bus
        .scan(&ScanOptions::default().ids(0..=6), |p| calls.push(*p))
        .unwrap();
    let ids: Vec<u8> = report.found.iter().map(|f| f.id.get()).collect();
    assert_eq!(ids, [0, 3, 4]);
    assert!(report.duplicates.is_empty(), "{report:?}");
    assert!(report.found.iter().all(|f| f.baud == BaudRate::B115200));
    assert_eq!(calls.len(), 7);
    assert_eq!(
        calls.iter().map(|p| p.done).collect::<Vec<_>>(),
        (1..=7).collect::<Vec<_>>()
    );
    assert!(calls.iter().all(|p| p.total == 7));
    assert_eq!(calls.last().unwrap().found, 3);
}

#[test]
fn scan_over_every_baud_rate_detects_each_module_rate() {
    let mut sim = serve_modules(&[
        (2, BaudRate::B57600, 100),
        (5, BaudRate::B921600, 140),
        (1, BaudRate::B9600, 127),
    ]);
    let mut bus = sim.bus();
    let report = bus
        .scan(&ScanOptions::all_bauds().ids(0..=5), |_| {})
        .unwrap();
    let mut found: Vec<(u8, BaudRate)> =
        report.found.iter().map(|f| (f.id.get(), f.baud)).collect();
    found.sort_by_key(|f| f.0);
    assert_eq!(
        found,
        [
            (1, BaudRate::B9600),
            (2, BaudRate::B57600),
            (5, BaudRate::B921600)
        ],
        "{report:?}"
    );
    assert!(report.duplicates.is_empty(), "{report:?}");
    assert_eq!(bus.baud(), BaudRate::B115200, "the bus rate is restored");
}

#[test]
fn scan_detects_two_modules_sharing_an_id() {
    // Two modules with ID 3 whose shafts stand apart, and a single module 4.
    let mut sim = serve_modules(&[
        (3, BaudRate::B115200, 100),
        (3, BaudRate::B115200, 150),
        (4, BaudRate::B115200, 127),
    ]);
    let mut bus = sim.bus();
    let report = bus
        .scan(&ScanOptions::default().ids(2..=5), |_| {})
        .unwrap();
    let found: Vec<u8> = report.found.iter().map(|f| f.id.get()).collect();
    assert_eq!(found, [4], "{report:?}");
    assert_eq!(report.duplicates.len(), 1, "{report:?}");
    assert_eq!(report.duplicates[0].id, id(3));
    assert!(!report.duplicates[0].evidence.is_empty());
}

#[test]
fn scan_detects_colliding_replies_at_a_high_rate() {
    let mut sim = serve_modules(&[
        (6, BaudRate::B921600, 127),
        (6, BaudRate::B921600, 127),
        (7, BaudRate::B921600, 90),
    ]);
    let mut bus = sim.bus();
    let report = bus
        .scan(&ScanOptions::at(BaudRate::B921600).ids(5..=8), |_| {})
        .unwrap();
    eprintln!("{report:#?}");
    let found: Vec<u8> = report.found.iter().map(|f| f.id.get()).collect();
    assert_eq!(found, [7], "{report:?}");
    assert_eq!(
        report
            .duplicates
            .iter()
            .map(|d| d.id.get())
            .collect::<Vec<_>>(),
        [6]
    );
}

#[test]
fn errors_name_the_device_the_servo_and_the_command() {
    let mut sim = serve_ids(&[0]);
    let path = wck_support::DEVICE;
    let mut bus = sim.bus();
    let err = bus.servo(id(12)).gains().unwrap_err();
    match &err {
        WckError::Timeout {
            device,
            target,
            command,
            received,
            attempts,
            ..
        } => {
            assert_eq!(device, path);
            assert_eq!(*target, Target::Servo(id(12)));
            assert_eq!(*command, "P, D gain read");
            assert!(received.is_empty());
            assert_eq!(*attempts, 4);
        }
        other => panic!("{other:?}"),
    }
    let text = err.to_string();
    assert!(text.contains(path) && text.contains("servo 12"), "{text}");
}

/// `WckBus::open` on the simulator's pty path, the way a real port is opened. The
/// `serialport` crate sets the line rate with termios2 (`BOTHER`); the simulator must read
/// that rate, not crash on it (a regression test: it once did).
#[test]
fn wck_open_by_path() {
    let sim = wck_support::serve_pty(&[0]);
    let mut bus = robobus::wck::WckBus::open(sim.endpoint.path(), BaudRate::B115200)
        .unwrap()
        .with_config(wck_support::pty_config());
    assert_eq!(bus.servo(id(0)).status().unwrap().position, pos(127));
    // A move and its effect, through the pty.
    let before = bus.servo(id(0)).move_to(torque(0), pos(90)).unwrap();
    assert_eq!(before.position, pos(127));
    std::thread::sleep(Duration::from_millis(500));
    let now = bus.servo(id(0)).status().unwrap().position.get();
    assert!(now.abs_diff(90) <= 1, "{now}");
    assert_eq!(slot_mode_pty(&sim, 0), Mode::Position);
}

/// A pty's other end is a process the scheduler may hold (the simulator on a loaded
/// machine held replies past the 10 ms margin, and a fresh simulator's first scan missed
/// servos): opening one adds `PTY_MARGIN` to the reply margin, through its path and
/// through a symlink to it.
#[test]
fn opening_a_pty_adds_the_pty_margin() {
    let sim = wck_support::serve_pty(&[0]);
    let path = sim.endpoint.path();
    let bus = robobus::wck::WckBus::open(path, BaudRate::B115200).unwrap();
    let pty = robobus::wck::DEFAULT_MARGIN + robobus::wck::PTY_MARGIN;
    assert_eq!(bus.config().margin, pty);
    drop(bus);
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("wck");
    std::os::unix::fs::symlink(path, &link).unwrap();
    let mut bus = robobus::wck::WckBus::open(&link, BaudRate::B115200).unwrap();
    assert_eq!(bus.config().margin, pty);
    assert_eq!(bus.servo(id(0)).status().unwrap().position, pos(127));
}

fn slot_mode_pty(sim: &wck_support::PtySim, servo_id: u8) -> Mode {
    sim.with_bus(move |b| b.servo(b.slot_of(servo_id).unwrap()).unwrap().mode())
}
