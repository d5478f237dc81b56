//! Mechanics scenarios on the virtual clock: moves, speed and torque levels, gains,
//! boundaries, over-load, passive, wheel and break modes.
#![allow(clippy::unwrap_used)] // test helpers

use crate::wck_support;

use core::time::Duration;

use robobus_sim::wck::{Mode, Model};
use robobus_wck::{
    Accel, Boundaries, Command, DGain, Overload, PGain, Position, Rotation, Speed, SyncMove,
    TorqueLevel, WheelSpeed,
};
use wck_support::{host, id, mv, status, time_to_reach};

const MS: Duration = Duration::from_millis(1);

/// A move's time to reach its target (polling every 2 ms, within one step) agrees with the
/// model's no-load speed from the manual (0.15 / 0.21 / 0.19 s per 60°) within 5 % + 50 ms:
/// the speed figure leaves out acceleration (17 ms at the default range 60) and the
/// position loop's lag.
#[test]
fn move_reaches_target_in_the_time_the_model_speed_predicts() {
    for model in Model::ALL {
        let mut h = host(model, &[0]);
        h.command(&mv(0, 0, 20));
        h.sleep(Duration::from_secs(2));
        assert_eq!(status(&mut h, 0).unwrap().1, 20);
        h.command(&mv(0, 0, 230));
        let t = time_to_reach(&mut h, 0, 230, 1, 2 * MS, Duration::from_secs(3)).unwrap();
        let predicted = model.no_load_move_seconds(210.0 * 269.0 / 255.0);
        let got = t.as_secs_f64();
        assert!(
            got >= predicted && got <= predicted * 1.05 + 0.05,
            "{model}: reached in {got:.3} s, predicted {predicted:.3} s"
        );
        // And it stays there within the control error.
        h.sleep(Duration::from_millis(200));
        let angle = h.bus().servo(0).unwrap().angle();
        assert!(
            (angle - 230.0 * 269.0 / 255.0).abs() <= 0.8,
            "{model}: {angle}"
        );
    }
}

#[test]
fn speed_level_and_torque_level_slow_a_move() {
    let fast = {
        let mut h = host(Model::W1108, &[0]);
        h.command(&mv(0, 0, 200));
        time_to_reach(&mut h, 0, 200, 1, 2 * MS, Duration::from_secs(5)).unwrap()
    };
    let speed10 = {
        let mut h = host(Model::W1108, &[0]);
        let speed = Speed::new(10).unwrap();
        h.command(&Command::RuntimeSpeedSet {
            id: id(0),
            speed,
            accel: Accel::DEFAULT,
        });
        h.command(&mv(0, 0, 200));
        time_to_reach(&mut h, 0, 200, 1, 2 * MS, Duration::from_secs(5)).unwrap()
    };
    let torque4 = {
        let mut h = host(Model::W1108, &[0]);
        h.command(&mv(0, 4, 200));
        time_to_reach(&mut h, 0, 200, 1, 2 * MS, Duration::from_secs(5)).unwrap()
    };
    // Speed level 10 of 30 is a third of the speed: about three times as long.
    let ratio = speed10.as_secs_f64() / fast.as_secs_f64();
    assert!(
        (2.5..3.5).contains(&ratio),
        "speed 10: {speed10:?} vs {fast:?}"
    );
    // Torque level 4 of 0..=4 drives at a fifth.
    let ratio = torque4.as_secs_f64() / fast.as_secs_f64();
    assert!(
        (4.0..6.0).contains(&ratio),
        "torque 4: {torque4:?} vs {fast:?}"
    );
}

/// Time for the shaft to settle within the control error (±0.8°) and stay there.
fn settle_time(p: u8, d: u8) -> Duration {
    let mut h = host(Model::W1108, &[0]);
    let gains = Command::RuntimeGainSet {
        id: id(0),
        p: PGain::new(p).unwrap(),
        d: DGain::new(d).unwrap(),
    };
    assert_eq!(h.command(&gains), [p, d]);
    h.command(&mv(0, 0, 60));
    let start = h.now();
    let target = 60.0 * 269.0 / 255.0;
    let mut settled_at = None;
    for _ in 0..3000 {
        h.sleep(MS);
        let err = (h.bus().servo(0).unwrap().angle() - target).abs();
        if err <= 0.8 {
            settled_at.get_or_insert(h.now().saturating_sub(start));
        } else {
            settled_at = None;
        }
    }
    settled_at.unwrap()
}

#[test]
fn higher_gains_settle_faster() {
    let low = settle_time(5, 3);
    let default = settle_time(20, 30);
    let high = settle_time(120, 80);
    assert!(
        low > default && default > high,
        "{low:?} {default:?} {high:?}"
    );
}

#[test]
fn low_torque_level_sags_under_load_and_load_reading_rises() {
    let hold = |torque: u8, overload: u8| {
        let mut h = host(Model::W1108, &[0]);
        let overload = Overload::new(overload).unwrap();
        h.command(&Command::OverloadSet {
            id: id(0),
            overload,
        });
        h.command(&mv(0, torque, 127));
        h.sleep(Duration::from_millis(300));
        // 3 kg·cm pulling towards smaller angles (3/8 of the 1108's stall torque).
        h.bus_mut().servo_mut(0).unwrap().push(-3.0);
        h.sleep(Duration::from_secs(2));
        (status(&mut h, 0).unwrap(), h.bus().servo(0).unwrap().mode())
    };
    // With the threshold at 1800 mA, torque level 0 holds; level 4 cannot.
    let ((load0, pos0), mode0) = hold(0, 199);
    let ((_, pos4), _) = hold(4, 199);
    assert_eq!(mode0, Mode::Position);
    assert!(pos0.abs_diff(127) <= 2, "torque 0 holds: {pos0}");
    assert!(pos4 < 100, "torque 4 (1.6 kg·cm) gives way: {pos4}");
    assert!(load0 > 50, "holding 3 kg·cm draws current: load {load0}");
    // At the default 400 mA, holding 3 kg·cm (about 750 mA) is an over-load.
    let ((_, pos), mode) = hold(0, 33);
    assert_eq!(mode, Mode::Passive);
    assert!(pos.abs_diff(127) > 10, "{pos}");
}

#[test]
fn boundaries_clamp_position_commands() {
    let mut h = host(Model::W1108, &[0]);
    let bounds = Boundaries::new(Position::new(50).unwrap(), Position::new(200).unwrap()).unwrap();
    assert_eq!(
        h.command(&Command::BoundarySet { id: id(0), bounds }),
        [50, 200]
    );
    h.command(&mv(0, 0, 250));
    h.sleep(Duration::from_secs(1));
    assert_eq!(status(&mut h, 0).unwrap().1, 200);
    h.command(&mv(0, 0, 3));
    h.sleep(Duration::from_secs(1));
    assert_eq!(status(&mut h, 0).unwrap().1, 50);
    let sync = SyncMove::new(TorqueLevel::new(0).unwrap(), &[Position::new(254).unwrap()]).unwrap();
    h.command(&Command::SyncMove(sync));
    h.sleep(Duration::from_secs(1));
    assert_eq!(status(&mut h, 0).unwrap().1, 200);
}

#[test]
fn overload_drops_into_passive_mode() {
    let mut h = host(Model::W1108, &[0]);
    h.bus_mut().servo_mut(0).unwrap().hold(true);
    h.command(&mv(0, 0, 220));
    h.sleep(Duration::from_millis(20));
    assert_eq!(h.bus().servo(0).unwrap().mode(), Mode::Position);
    h.sleep(Duration::from_millis(500));
    let s = h.bus().servo(0).unwrap();
    assert_eq!(s.mode(), Mode::Passive);
    assert_eq!(s.overload_trips(), 1);
    // Passive now: let go and push it by hand, it follows.
    h.bus_mut().servo_mut(0).unwrap().hold(false);
    h.bus_mut().servo_mut(0).unwrap().push(1.0);
    h.sleep(Duration::from_millis(300));
    h.bus_mut().servo_mut(0).unwrap().push(0.0);
    assert!(status(&mut h, 0).unwrap().1 > 140);

    // A higher threshold (1800 mA) holds out longer against the same stall.
    let mut h2 = host(Model::W1108, &[0]);
    let overload = Overload::new(199).unwrap();
    h2.command(&Command::OverloadSet {
        id: id(0),
        overload,
    });
    h2.bus_mut().servo_mut(0).unwrap().hold(true);
    h2.command(&mv(0, 0, 220));
    h2.sleep(Duration::from_millis(100));
    assert_eq!(h2.bus().servo(0).unwrap().mode(), Mode::Position);
}

#[test]
fn passive_mode_lets_a_hand_turn_the_shaft_and_reads_it() {
    let mut h = host(Model::W1108, &[0]);
    h.command(&mv(0, 0, 127));
    h.sleep(Duration::from_millis(100));
    assert_eq!(h.command(&Command::Passive { id: id(0) }), [0x10, 127]);
    h.bus_mut().servo_mut(0).unwrap().set_position(60);
    assert_eq!(status(&mut h, 0).unwrap(), (0, 60));
    // A push turns it; held, it stays.
    h.bus_mut().servo_mut(0).unwrap().push(2.0);
    h.sleep(Duration::from_millis(200));
    let pushed = status(&mut h, 0).unwrap().1;
    assert!(pushed > 70, "{pushed}");
    h.bus_mut().servo_mut(0).unwrap().hold(true);
    let held = status(&mut h, 0).unwrap().1;
    h.sleep(Duration::from_millis(200));
    assert_eq!(status(&mut h, 0).unwrap().1, held);
    // Under position control a push barely moves it.
    h.bus_mut().servo_mut(0).unwrap().hold(false);
    h.bus_mut().servo_mut(0).unwrap().push(1.0);
    h.command(&mv(0, 0, 60));
    h.sleep(Duration::from_millis(500));
    assert!(status(&mut h, 0).unwrap().1.abs_diff(60) <= 1);
}

#[test]
fn wheel_mode_counts_rotations() {
    let mut h = host(Model::W1108, &[0]);
    let wheel = |rotation, speed| Command::Wheel {
        id: id(0),
        rotation,
        speed: WheelSpeed::new(speed).unwrap(),
    };
    assert_eq!(h.command(&wheel(Rotation::Ccw, 15))[0], 0);
    // 400 °/s for 5 s: 2000° = 5.5 turns.
    h.sleep(Duration::from_secs(5));
    assert_eq!(h.command(&wheel(Rotation::Ccw, 15))[0], 5);
    assert_eq!(h.bus().servo(0).unwrap().rotations(), 5);
    // Half the speed the other way for 7.2 s: 1440° = 4 turns back.
    h.command(&wheel(Rotation::Cw, 7));
    h.sleep(Duration::from_secs(8));
    let r = h.command(&wheel(Rotation::Cw, 0))[0];
    assert!(r <= 2, "{r}");
    h.sleep(Duration::from_secs(1));
    // Speed 0 stops it.
    let a = h.bus().servo(0).unwrap().angle();
    h.sleep(Duration::from_millis(500));
    assert!((h.bus().servo(0).unwrap().angle() - a).abs() < 0.5);
}

#[test]
fn break_stops_every_servo() {
    let mut h = host(Model::W1108, &[0, 1, 2]);
    let positions: Vec<Position> = [10, 240, 20].map(|p| Position::new(p).unwrap()).to_vec();
    let sync = SyncMove::new(TorqueLevel::new(0).unwrap(), &positions).unwrap();
    h.command(&Command::SyncMove(sync));
    h.sleep(Duration::from_millis(150));
    for i in 0..3 {
        assert!(h.bus().servo(i).unwrap().mechanics().velocity().abs() > 100.0);
    }
    // Every module answers a break at once: three replies on one wire.
    h.command(&Command::Break);
    h.sleep(Duration::from_millis(60));
    let before: Vec<f64> = (0..3).map(|i| h.bus().servo(i).unwrap().angle()).collect();
    h.sleep(Duration::from_millis(500));
    for (i, a) in before.iter().enumerate() {
        let s = h.bus().servo(i).unwrap();
        assert_eq!(s.mode(), Mode::Break);
        assert!((s.angle() - a).abs() < 0.5, "servo {i} still moving");
        assert!((s.angle() - 127.0 * 269.0 / 255.0).abs() < 100.0);
    }
    // Break is stiff: a push that turns a passive shaft barely moves it.
    h.bus_mut().servo_mut(0).unwrap().push(1.0);
    h.sleep(Duration::from_millis(300));
    let v = h.bus().servo(0).unwrap().mechanics().velocity();
    assert!(v.abs() < 60.0, "{v}");
}

#[test]
fn i_gain_removes_the_steady_error_under_load() {
    let error = |i: u8| {
        let mut h = host(Model::W1108, &[0]);
        let i = robobus_wck::IGain::new(i).unwrap();
        h.command(&Command::RuntimeIGainSet { id: id(0), i });
        h.command(&mv(0, 0, 127));
        h.sleep(Duration::from_millis(300));
        // 1.2 kg·cm: 300 mA, below the default 400 mA over-load threshold.
        h.bus_mut().servo_mut(0).unwrap().push(-1.2);
        h.sleep(Duration::from_secs(3));
        (h.bus().servo(0).unwrap().angle() - 127.0 * 269.0 / 255.0).abs()
    };
    let without = error(0);
    let with = error(10);
    assert!(without > 0.2, "P alone leaves an error: {without}");
    assert!(with < without / 5.0, "I gain: {with} vs {without}");
}

#[test]
fn a_lower_acceleration_range_starts_slower() {
    let reach = |accel: u8| {
        let mut h = host(Model::W1108, &[0]);
        let accel = Accel::new(accel).unwrap();
        h.command(&Command::RuntimeSpeedSet {
            id: id(0),
            speed: Speed::DEFAULT,
            accel,
        });
        h.command(&mv(0, 0, 140));
        time_to_reach(&mut h, 0, 140, 0, MS, Duration::from_secs(2)).unwrap()
    };
    let slow = reach(20);
    let fast = reach(100);
    // 50 ms vs 10 ms to full speed: about 40 ms apart on a short move.
    assert!(
        slow > fast + Duration::from_millis(20),
        "{slow:?} vs {fast:?}"
    );
}

mod props {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]
        /// Whatever the outside world does to the shaft and whatever position the host
        /// asks for, readings stay in range and nothing panics.
        #[test]
        fn readings_stay_in_range(
            torque in prop_oneof![-20.0..20.0f64, Just(f64::NAN), Just(f64::INFINITY)],
            angle in prop_oneof![-1000.0..1000.0f64, Just(f64::NAN)],
            held in any::<bool>(),
            level in 0u8..=4,
            target in 0u8..=254,
            model in 0usize..3,
        ) {
            let mut h = host(Model::ALL[model], &[0]);
            h.bus_mut().servo_mut(0).unwrap().set_angle(angle);
            h.bus_mut().servo_mut(0).unwrap().push(torque);
            h.bus_mut().servo_mut(0).unwrap().hold(held);
            h.command(&mv(0, level, target));
            h.sleep(Duration::from_millis(200));
            let s = h.bus().servo(0).unwrap();
            prop_assert!((0.0..360.0).contains(&s.angle()));
            prop_assert!(s.position() <= 254 && s.position10() <= 1023 && s.load() <= 254);
            let reply = status(&mut h, 0);
            prop_assert!(reply.is_some());
        }
    }
}
