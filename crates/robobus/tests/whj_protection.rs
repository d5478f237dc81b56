//! The host's protection of `whj wave` and `whj move` (the one monitor of
//! `robobus::ops::protect`), on the simulator's virtual clock: a joint driven into a stop
//! is stopped by the stall check, disabled (its brake holds it) and the run fails naming
//! the joint, the quantity, the limit and the time; a hot joint is warned about, derated
//! and then stopped at its temperatures.

#![allow(clippy::unwrap_used)] // tests

use crate::whj_common;

use robobus::ops::protect::{Action, Check};
use robobus::ops::whj::{self as ops, MoveArgs, ServoLoop, Shape, WaveArgs};
use robobus::ops::{Control, ErrorKind, Progress, SafeState, StopToken};
use robobus::whj::{JointBus, JointBusConfig};
use robobus_sim::whj::{JointConfig, Obstacle, WhjModel, WhjSimHandle};
use robobus_whj::{JointId, WorkMode};
use whj_common::{configs, virtual_bus};

fn id(n: u8) -> JointId {
    JointId::new(n).unwrap()
}

/// A WHJ30 (a pin brake) as joint 1 at 0 deg, enabled in position mode.
fn joint() -> (JointBus, WhjSimHandle) {
    let cfg = JointConfig::new(1, WhjModel::Whj30).without_iap();
    let (bus, sim) = virtual_bus(configs(vec![cfg]));
    let j = bus.joint(id(1)).unwrap();
    j.set_mode(WorkMode::Position).unwrap();
    j.enable().unwrap();
    (bus, sim)
}

/// A 15 deg, 0.5 Hz sine at 100 Hz for `seconds`.
fn sine(seconds: f64) -> WaveArgs {
    WaveArgs {
        joint: id(1),
        shape: Shape::Sine,
        servo: ServoLoop::Position,
        amplitude: 15.0,
        frequency: 0.5,
        offset: 0.0,
        duration: seconds,
        rate_hz: 100.0,
        step_limit_deg: JointBusConfig::default().step_limit_deg,
    }
}

/// The time in a fault's text (`... at 0.760 s; ...`).
fn at_s(text: &str) -> f64 {
    let tail = text.split(" at ").nth(1).unwrap();
    tail.split(' ').next().unwrap().parse().unwrap()
}

#[test]
fn a_wave_into_an_obstacle_is_stopped_by_the_stall_check_naming_the_joint() {
    let (bus, sim) = joint();
    // A stop at 5 deg in the sine's way: the set-point passes it at 0.107 s.
    sim.with_bus(|b| {
        b.joint_mut(1)
            .unwrap()
            .set_obstacle(Some(Obstacle::above(5.0)));
    });
    let j = bus.joint(id(1)).unwrap();
    let e = ops::run_wave(&j, &sine(4.0), &mut Control::none(), SafeState::Hold).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Device, "{e}");
    let text = e.to_string();
    assert!(
        text.starts_with("joint 1: stall protection: current ")
            && text.contains(" A reached the limit 7.8 A at "),
        "{text}"
    );
    // The current reaches the WHJ30's rated current soon after the contact, and the
    // stall time (0.3 s) later the wave stops: well before the sine turns back (1 s).
    let at = at_s(&text);
    assert!((0.4..0.9).contains(&at), "{text}");
    assert!(text.contains("wave stopped after "), "{text}");
    assert!(text.ends_with("joint 1 left disabled"), "{text}");
    // Disabled: its brake holds it, no current pushes into the stop any more.
    let st = sim.with_bus(|b| b.joint(1).unwrap().state());
    assert!(!st.enabled && st.brake_locked, "{st:?}");
    assert!(st.current_a.abs() < 1e-9, "{st:?}");
    assert!(st.error.is_empty(), "{st:?}");
}

#[test]
fn a_move_into_an_obstacle_is_stopped_by_the_stall_check_naming_the_joint() {
    let (bus, sim) = joint();
    sim.with_bus(|b| {
        b.joint_mut(1)
            .unwrap()
            .set_obstacle(Some(Obstacle::above(5.0)));
    });
    let j = bus.joint(id(1)).unwrap();
    let args = MoveArgs {
        joint: id(1),
        target_deg: 30.0,
        max_speed_deg_s: 20.0,
        rate_hz: 100.0,
        step_limit_deg: JointBusConfig::default().step_limit_deg,
    };
    let e = ops::run_move(&j, &args, &mut Control::none(), SafeState::Hold).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Device, "{e}");
    let text = e.to_string();
    assert!(
        text.starts_with("joint 1: stall protection: current ")
            && text.contains("reached the limit 7.8 A at ")
            && text.contains("move stopped after "),
        "{text}"
    );
    let st = sim.with_bus(|b| b.joint(1).unwrap().state());
    assert!(!st.enabled && st.brake_locked, "{st:?}");
    // The stop holds it a few degrees into its far side (no joint gets further).
    assert!(st.position_deg < 10.0, "{st:?}");
}

/// Sets joint 1's winding temperature when the wave's progress passes given frames.
fn heat_at(sim: &WhjSimHandle, at: &[(u64, f64)], p: &Progress) {
    for &(frame, celsius) in at {
        if p.done == frame {
            sim.with_bus(|b| {
                b.joint_mut(1).unwrap().set_winding_temperature(celsius);
            });
        }
    }
}

#[test]
fn a_hot_joint_on_a_wave_is_warned_about_then_derated_and_the_wave_reports_both() {
    let (bus, sim) = joint();
    let j = bus.joint(id(1)).unwrap();
    // Progress comes every 16 frames (0.16 s): 76 degC after frame 32, 81 after 96.
    let plan_heat = [(32, 76.0), (96, 81.0)];
    let mut on_progress = |p: &Progress| heat_at(&sim, &plan_heat, p);
    let stop = StopToken::new();
    let mut control = Control::new(&stop).with_progress(&mut on_progress);
    let (_, r) = ops::run_wave(&j, &sine(2.0), &mut control, SafeState::Hold).unwrap();
    drop(control);
    let seen: Vec<_> = r
        .protection
        .iter()
        .map(|f| (f.joint.as_str(), f.check, f.action, f.limit))
        .collect();
    assert_eq!(
        seen,
        [
            ("joint 1", Check::Thermal, Action::Warn, 75.0),
            ("joint 1", Check::Thermal, Action::Derate, 80.0),
        ],
        "{:?}",
        r.protection
    );
    // Read every 0.25 s: the first reading after each change.
    let t: Vec<f64> = r.protection.iter().map(|f| f.at_s).collect();
    assert!(t[0] > 0.32 && t[0] <= 0.32 + 0.26, "{t:?}");
    assert!(t[1] > 0.96 && t[1] <= 0.96 + 0.26, "{t:?}");
    let json = serde_json::to_value(&r).unwrap();
    assert_eq!(json["protection"][1]["action"], "derate", "{json}");
    assert_eq!(json["protection"][1]["quantity"], "temperature_c", "{json}");
    assert_eq!(r.cycles, 200, "{r:?}");
}

#[test]
fn a_joint_hotter_than_its_stop_temperature_stops_the_wave() {
    let (bus, sim) = joint();
    let j = bus.joint(id(1)).unwrap();
    let plan_heat = [(48, 86.0)];
    let mut on_progress = |p: &Progress| heat_at(&sim, &plan_heat, p);
    let stop = StopToken::new();
    let mut control = Control::new(&stop).with_progress(&mut on_progress);
    let e = ops::run_wave(&j, &sine(2.0), &mut control, SafeState::Hold).unwrap_err();
    drop(control);
    assert_eq!(e.kind(), ErrorKind::Device, "{e}");
    let text = e.to_string();
    assert!(
        text.starts_with("joint 1: thermal protection: temperature 86.")
            && text.contains("reached the limit 85 °C at "),
        "{text}"
    );
    let at = at_s(&text);
    assert!(at > 0.48 && at <= 0.48 + 0.26, "{text}");
    let st = sim.with_bus(|b| b.joint(1).unwrap().state());
    assert!(!st.enabled, "{st:?}");
}

/// A wave on a joint that follows it, cool and unobstructed, reports no protection event
/// and its JSON has no `protection` key.
#[test]
fn a_wave_within_every_limit_reports_no_protection_event() {
    let (bus, _sim) = joint();
    let j = bus.joint(id(1)).unwrap();
    let (_, r) = ops::run_wave(&j, &sine(2.0), &mut Control::none(), SafeState::Hold).unwrap();
    assert!(r.protection.is_empty(), "{:?}", r.protection);
    let json = serde_json::to_value(&r).unwrap();
    assert!(json.get("protection").is_none(), "{json}");
}

/// In current mode the current is what the frames ask (a square wave's edges jump by
/// design, here from 0 to 9 A, more than the WHJ30's 7.8 A collision jump): it is not
/// taken for a collision, and the wave runs to its end (the output against a stop).
#[test]
fn a_square_current_wave_s_current_jumps_are_not_taken_for_a_collision() {
    let (bus, sim) = joint();
    let j = bus.joint(id(1)).unwrap();
    j.disable().unwrap();
    j.set_mode(WorkMode::Current).unwrap();
    j.enable().unwrap();
    sim.with_bus(|b| {
        let joint = b.joint_mut(1).unwrap();
        joint.set_obstacle(Some(Obstacle::above(5.0)));
    });
    let args = WaveArgs {
        shape: Shape::Square,
        servo: ServoLoop::Current,
        amplitude: 4500.0,
        offset: 4500.0,
        frequency: 5.0,
        ..sine(1.0)
    };
    let (_, r) = ops::run_wave(&j, &args, &mut Control::none(), SafeState::Hold).unwrap();
    assert_eq!(r.cycles, 100, "{r:?}");
    assert!(r.protection.is_empty(), "{:?}", r.protection);
}
