//! The host's protection of wCK motions on the simulator's virtual clock: a played motion
//! into a gripped servo and a wheel held still under velocity are stopped, naming the
//! servo, in the protection's safe state (see `ops::protect::Limits::wck`).
#![allow(clippy::unwrap_used, clippy::result_large_err)]

use std::time::Duration;

use robobus::ErrorKind;
use robobus::ops::wck::{self, Motion, WheelArgs};
use robobus::ops::{Control, SafeState};
use robobus_sim::wck::Mode;
use robobus_wck::{Overload, Rotation, ServoId, WheelSpeed};

use crate::wck_support::serve_ids;

/// A motion of servo 0 from 100 to 200 steps in 3 s (35 °/s) at torque level 3 (the
/// servo's duty at most 0.4: 800 mA held), the servo's own over-load at its highest
/// (1800 mA), so only the host can stop it; the hand grips the shaft 1 s in.
#[test]
fn a_wck_play_into_a_gripped_servo_is_stopped_within_the_stall_time_naming_it() {
    let mut sim = serve_ids(&[0]);
    sim.with_bus(|b| {
        let s = b.servo_mut(0).unwrap();
        let e = robobus_sim::wck::Eeprom {
            overload: Overload::new(199).unwrap(),
            ..*s.eeprom()
        };
        s.set_eeprom(e);
    });
    let handle = sim.handle.clone();
    let mut bus = sim.bus();
    let motion = Motion::parse("torque 3\npose 300 100\npose 3000 200\n").unwrap();
    let started = handle.now();
    handle.at(started + Duration::from_secs(1), |b| {
        b.servo_mut(0).unwrap().hold(true);
    });
    let err = wck::play(
        &mut bus,
        &motion,
        50.0,
        SafeState::Hold,
        &mut Control::none(),
    )
    .unwrap_err();
    let text = err.to_string();
    assert_eq!(err.kind(), ErrorKind::Device, "{text}");
    // The status reads (every 200 ms) see 800 mA held from the first after the grip, at
    // 1.2 s, the target running away; the stall time (0.4 s) later, at 1.6 s, the play
    // stops: within the stall time and one reading period of the grip, long before the
    // motion's end at 3.3 s.
    assert!(
        text.starts_with("servo 0: stall protection: current 0.8"),
        "{text}"
    );
    assert!(text.contains("reached the limit 0.2 A at 1.60"), "{text}");
    assert!(
        text.contains("the play stopped at 1600 ms, servo(s) 0 passive"),
        "{text}"
    );
    let took = handle.now().saturating_sub(started);
    assert!(
        took > Duration::from_secs(1) && took <= Duration::from_millis(1650),
        "stopped {took:?} after the start: {text}"
    );
    sim.with_bus(|b| {
        let s = b.servo(0).unwrap();
        assert_eq!(s.mode(), Mode::Passive);
        assert_eq!(
            s.overload_trips(),
            0,
            "the host stopped it, not its own protection"
        );
    });
}

/// A wheel at speed 2 of 15 held still from the start: 267 mA, under the servo's
/// factory over-load (400 mA), so it would push for the whole 5 s; the host stops it at
/// the third status read (0.6 s: the stall seen at 0.2 s, held for its 0.4 s).
#[test]
fn a_wheel_held_still_under_velocity_is_stopped_naming_the_servo() {
    let mut sim = serve_ids(&[0, 1]);
    sim.with_bus(|b| b.servo_mut(1).unwrap().hold(true));
    let handle = sim.handle.clone();
    let mut bus = sim.bus();
    let args = WheelArgs {
        id: ServoId::new(1).unwrap(),
        rotation: Rotation::Ccw,
        speed: WheelSpeed::new(2).unwrap(),
        duration: Some(Duration::from_secs(5)),
        on_stop: SafeState::Passive,
    };
    let started = handle.now();
    let err = wck::wheel(&mut bus, &args, &mut Control::none()).unwrap_err();
    let text = err.to_string();
    assert_eq!(err.kind(), ErrorKind::Device, "{text}");
    assert!(
        text.starts_with(
            "servo 1: stall protection: current 0.27 A reached the limit 0.2 A at 0.6"
        ),
        "{text}"
    );
    assert!(
        text.contains("the wheel stopped at 600 ms, servo(s) 1 passive"),
        "{text}"
    );
    let took = handle.now().saturating_sub(started);
    assert!(took < Duration::from_millis(700), "{took:?}");
    sim.with_bus(|b| assert_eq!(b.servo(1).unwrap().mode(), Mode::Passive));
}

/// The same wheel turning freely runs its whole time: its load (about 60 mA of friction)
/// is no stall.
#[test]
fn a_free_wheel_is_not_stopped() {
    let mut sim = serve_ids(&[1]);
    let mut bus = sim.bus();
    let args = WheelArgs {
        id: ServoId::new(1).unwrap(),
        rotation: Rotation::Ccw,
        speed: WheelSpeed::new(2).unwrap(),
        duration: Some(Duration::from_secs(3)),
        on_stop: SafeState::Passive,
    };
    wck::wheel(&mut bus, &args, &mut Control::none()).unwrap();
}
