#![allow(clippy::unwrap_used)]

use super::*;

const MS: Duration = Duration::from_millis(1);

fn reading(at: Instant, error: f64, current: f64) -> Reading {
    Reading {
        at,
        position_deg: Some(10.0),
        error_deg: Some(error),
        target_deg: None,
        current_a: Some(current),
        temperature_c: None,
    }
}

fn whj30() -> Limits {
    Limits::whj(Some(Model::Joint30))
}

#[test]
fn the_defaults_come_from_the_models_table() {
    let l = whj30();
    assert_eq!(l.stall_current_a, Some(7.8));
    assert_eq!(l.collision_current_jump_a, Some(7.8));
    assert_eq!(
        (
            l.temperature_warn_c,
            l.temperature_derate_c,
            l.temperature_stop_c
        ),
        (Some(75.0), Some(80.0), Some(85.0))
    );
    assert_eq!(
        Limits::whj(Some(Model::Joint60)).stall_current_a,
        Some(12.0)
    );
    assert_eq!(Limits::wck().temperature_stop_c, None);
    assert!(torque_off_is_safe(Some(Model::Joint30)));
    assert!(!torque_off_is_safe(Some(Model::Joint10)));
    assert!(!torque_off_is_safe(None));
}

#[test]
fn a_stall_stops_after_its_time_and_not_before() {
    let t0 = Instant::now();
    let mut m = Monitor::new(t0, vec![("j1".into(), whj30())]);
    // 8 A against 6° of error, a reading every 20 ms, rising slowly (no jump).
    for k in 0..15u32 {
        let f = m.feed(
            0,
            &reading(t0 + 20 * MS * k, 6.0, 8.0 + 0.01 * f64::from(k)),
        );
        assert!(f.is_empty(), "{k}: {f:?}");
    }
    let f = m.feed(0, &reading(t0 + 300 * MS, 6.0, 8.2));
    assert_eq!(f.len(), 1, "{f:?}");
    assert_eq!((f[0].check, f[0].action), (Check::Stall, Action::Stop));
    assert_eq!((f[0].quantity, f[0].limit), ("current_a", 7.8));
    assert!((f[0].at_s - 0.3).abs() < 1e-9);
    assert!(
        f[0].to_string()
            .starts_with("j1: stall protection: current 8.20 A")
    );
    // Reported once.
    assert!(m.feed(0, &reading(t0 + 320 * MS, 6.0, 8.2)).is_empty());
}

#[test]
fn a_shrinking_error_or_a_small_one_is_no_stall() {
    let t0 = Instant::now();
    let mut m = Monitor::new(t0, vec![("j1".into(), whj30())]);
    // High current, the error shrinking by a tenth every 100 ms: accelerating a load.
    let mut e = 8.0;
    for k in 0..50u32 {
        if k % 5 == 0 {
            e *= 0.85;
        }
        assert!(
            m.feed(0, &reading(t0 + 20 * MS * k, e, 9.0)).is_empty(),
            "{k}"
        );
    }
    // Holding a load at the target: high current, error under 1°.
    let mut m = Monitor::new(t0, vec![("j1".into(), whj30())]);
    for k in 0..100u32 {
        assert!(
            m.feed(0, &reading(t0 + 20 * MS * k, 0.5, 9.0)).is_empty(),
            "{k}"
        );
    }
    // Lifting a load 3° behind its target, moving 0.2° a reading.
    let mut m = Monitor::new(t0, vec![("j1".into(), whj30())]);
    for k in 0..100u32 {
        let r = Reading {
            position_deg: Some(0.2 * f64::from(k)),
            ..reading(t0 + 20 * MS * k, 3.0, 9.0)
        };
        assert!(m.feed(0, &r).is_empty(), "{k}");
    }
}

#[test]
fn a_jump_of_the_current_or_the_error_is_a_collision() {
    let t0 = Instant::now();
    let mut m = Monitor::new(t0, vec![("j1".into(), whj30())]);
    assert!(m.feed(0, &reading(t0, 1.0, 1.0)).is_empty());
    let f = m.feed(0, &reading(t0 + 20 * MS, 1.5, 9.0));
    assert_eq!(
        (f[0].check, f[0].quantity),
        (Check::Collision, "current_jump_a")
    );
    assert!((f[0].value - 8.0).abs() < 1e-9);
    let mut m = Monitor::new(t0, vec![("j1".into(), whj30())]);
    assert!(m.feed(0, &reading(t0, 1.0, 1.0)).is_empty());
    let f = m.feed(0, &reading(t0 + 20 * MS, 6.5, 1.0));
    assert_eq!(f[0].quantity, "following_error_jump_deg");
    // An error that grows no more than its target moved is no jump (a joint left
    // behind by a big step).
    let mut m = Monitor::new(t0, vec![("j1".into(), whj30())]);
    let step = |at, error, target| Reading {
        target_deg: Some(target),
        ..reading(at, error, 1.0)
    };
    assert!(m.feed(0, &step(t0, 0.0, 0.0)).is_empty());
    assert!(m.feed(0, &step(t0 + 20 * MS, 8.4, 8.4)).is_empty());
    let f = m.feed(0, &step(t0 + 40 * MS, 14.0, 8.4));
    assert_eq!(f[0].quantity, "following_error_jump_deg");
    // The same change over more than the jump window is no jump.
    let mut m = Monitor::new(t0, vec![("j1".into(), whj30())]);
    assert!(m.feed(0, &reading(t0, 1.0, 1.0)).is_empty());
    assert!(m.feed(0, &reading(t0 + 101 * MS, 6.5, 1.0)).is_empty());
}

#[test]
fn heat_warns_derates_and_stops_and_derating_ends_when_it_cools() {
    let t0 = Instant::now();
    let mut m = Monitor::new(t0, vec![("j1".into(), whj30())]);
    let hot = |c: f64, k: u32| Reading {
        temperature_c: Some(c),
        ..Reading::at(t0 + 100 * MS * k)
    };
    assert!(m.feed(0, &hot(74.9, 0)).is_empty());
    assert_eq!(m.feed(0, &hot(75.0, 1))[0].action, Action::Warn);
    assert!(m.feed(0, &hot(76.0, 2)).is_empty());
    let f = m.feed(0, &hot(80.5, 3));
    assert_eq!((f[0].action, f[0].limit), (Action::Derate, 80.0));
    assert!((m.speed_share(0) - 0.5).abs() < 1e-12);
    // Cooling 5 K under the derating temperature ends it.
    assert!(m.feed(0, &hot(75.5, 4)).is_empty());
    assert!((m.speed_share(0) - 0.5).abs() < 1e-12);
    assert!(m.feed(0, &hot(74.9, 5)).is_empty());
    assert!((m.speed_share(0) - 1.0).abs() < 1e-12);
    assert_eq!(m.feed(0, &hot(81.0, 6))[0].action, Action::Derate);
    let f = m.feed(0, &hot(85.0, 7));
    assert_eq!((f[0].action, f[0].check), (Action::Stop, Check::Thermal));
    assert_eq!(
        f[0].to_string(),
        "j1: thermal protection: temperature 85.00 °C reached the limit 85 °C at 0.700 s; \
             stopped in the safe state"
    );
}

#[test]
fn under_velocity_a_stall_is_a_high_current_while_the_joint_falls_short_of_its_speed() {
    let t0 = Instant::now();
    let at = |k: u32, current: f64| Reading {
        current_a: Some(current),
        position_deg: Some(10.0),
        ..Reading::at(t0 + 20 * MS * k)
    };
    let v30 = Drive::Velocity {
        commanded_deg_s: 30.0,
    };
    // 8 A, commanded 30°/s, turning at 14°/s (under half): stopped after 0.3 s.
    let mut m = Monitor::new(t0, vec![("j1".into(), whj30())]);
    for k in 0..15u32 {
        let f = m.feed_driven(0, &at(k, 8.0), Some(14.0), v30);
        assert!(f.is_empty(), "{k}: {f:?}");
    }
    let f = m.feed_driven(0, &at(15, 8.0), Some(14.0), v30);
    assert_eq!(
        (f[0].check, f[0].quantity, f[0].limit, f[0].action),
        (Check::Stall, "current_a", 7.8, Action::Stop)
    );
    assert!((f[0].at_s - 0.3).abs() < 1e-9);
    assert!(
        f[0].to_string()
            .ends_with("stopped in the safe state (the joint did not move as commanded meanwhile)")
    );
    // The same current at 16°/s (over half), or told to stand still (holding a
    // load), or turning the wrong way under a small command: no stall.
    let mut m = Monitor::new(t0, vec![("j1".into(), whj30())]);
    let still = Drive::Velocity {
        commanded_deg_s: 0.5,
    };
    for k in 0..50u32 {
        assert!(m.feed_driven(0, &at(k, 8.0), Some(16.0), v30).is_empty());
    }
    let mut m = Monitor::new(t0, vec![("j1".into(), whj30())]);
    for k in 0..50u32 {
        assert!(m.feed_driven(0, &at(k, 8.0), Some(-3.0), still).is_empty());
    }
    // A current jump is a collision under velocity too.
    let mut m = Monitor::new(t0, vec![("j1".into(), whj30())]);
    assert!(m.feed_driven(0, &at(0, 1.0), Some(30.0), v30).is_empty());
    let f = m.feed_driven(0, &at(1, 9.0), Some(30.0), v30);
    assert_eq!(
        (f[0].check, f[0].quantity),
        (Check::Collision, "current_jump_a")
    );
}

#[test]
fn under_effort_the_current_is_not_watched_but_a_runaway_and_heat_are() {
    let t0 = Instant::now();
    let effort = Drive::Effort { max_deg_s: 100.0 };
    let mut m = Monitor::new(t0, vec![("j1".into(), whj30())]);
    // A commanded current step of 9 A, held for a second at no speed: no event.
    for k in 0..50u32 {
        let r = Reading {
            current_a: Some(if k == 0 { 0.0 } else { 9.0 }),
            ..Reading::at(t0 + 20 * MS * k)
        };
        assert!(m.feed_driven(0, &r, Some(0.0), effort).is_empty(), "{k}");
    }
    let r = Reading {
        temperature_c: Some(80.0),
        ..Reading::at(t0 + 1000 * MS)
    };
    let f = m.feed_driven(0, &r, Some(50.0), effort);
    assert_eq!((f[0].check, f[0].action), (Check::Thermal, Action::Derate));
    let f = m.feed_driven(0, &Reading::at(t0 + 1020 * MS), Some(-100.5), effort);
    assert_eq!(
        f[0].to_string(),
        "j1: speed protection: speed 100.50 °/s reached the limit 100 °/s at 1.020 s; \
             stopped in the safe state"
    );
    // A joint whose protection is off: nothing.
    let mut m = Monitor::new(t0, vec![("j1".into(), Limits::OFF)]);
    let r = Reading::at(t0);
    assert!(m.feed_driven(0, &r, Some(500.0), effort).is_empty());
}

#[test]
fn overrides_replace_the_defaults_and_are_checked() {
    let o = Overrides {
        stall_current_a: Some(3.0),
        temperature_stop_c: Some(70.0),
        ..Overrides::default()
    };
    // 70 °C under the default derating temperature (80): refused.
    let e = o.check(whj30()).unwrap_err();
    assert_eq!(e.0, "temperature_stop_c");
    let o = Overrides {
        stall_current_a: Some(3.0),
        ..Overrides::default()
    };
    o.check(whj30()).unwrap();
    assert_eq!(whj30().with(Some(&o)).stall_current_a, Some(3.0));
    let bad = Overrides {
        stall_time_s: Some(f64::NAN),
        ..Overrides::default()
    };
    assert_eq!(bad.check(whj30()).unwrap_err().2, "0.02..=10 s");
    let off = Overrides {
        enabled: Some(false),
        ..Overrides::default()
    };
    assert_eq!(whj30().with(Some(&off)), Limits::OFF);
}

#[test]
fn wck_defaults_come_from_the_wck_rows_and_fit_a_reading_every_200_ms() {
    let l = Limits::wck();
    // Half and all of the factory over-load (400 mA, A-5); no temperature.
    assert_eq!(l.stall_current_a, Some(0.2));
    assert_eq!(l.collision_current_jump_a, None);
    assert_eq!((l.stall_time_s, l.stall_error_deg), (0.4, 3.0));
    assert_eq!((l.temperature_warn_c, l.temperature_stop_c), (None, None));
    assert!((wck_load_a(33) - 0.4).abs() < 1e-12);
    let slow = l.for_reading_period(Duration::from_millis(400));
    assert!((slow.jump_window_s - 0.5).abs() < 1e-12);
    assert!((slow.stall_time_s - 0.8).abs() < 1e-12);
    // Where the robot file turns the load jump on, a load rise across one 200 ms reading
    // period is a collision on a wCK servo; the same readings are a new start on a WHJ
    // joint (its 100 ms window).
    let t0 = Instant::now();
    let jump = Limits {
        collision_current_jump_a: Some(0.4),
        ..l
    };
    let mut m = Monitor::new(t0, vec![("servo 0".into(), jump)]);
    assert!(m.feed(0, &reading(t0, 1.0, 0.05)).is_empty());
    let f = m.feed(0, &reading(t0 + 200 * MS, 1.0, 0.6));
    assert_eq!(
        (f[0].check, f[0].quantity, f[0].joint.as_str()),
        (Check::Collision, "current_jump_a", "servo 0")
    );
    let mut m = Monitor::new(t0, vec![("j1".into(), whj30())]);
    assert!(m.feed(0, &reading(t0, 1.0, 0.0)).is_empty());
    assert!(m.feed(0, &reading(t0 + 200 * MS, 1.0, 9.0)).is_empty());
    // A stall read every 200 ms: seen at 0, stopped at the third reading (0.4 s).
    let mut m = Monitor::new(t0, vec![("servo 0".into(), l)]);
    assert!(m.feed(0, &reading(t0, 6.0, 0.3)).is_empty());
    assert!(m.feed(0, &reading(t0 + 200 * MS, 6.0, 0.3)).is_empty());
    let f = m.feed(0, &reading(t0 + 400 * MS, 6.0, 0.3));
    assert_eq!((f[0].check, f[0].limit), (Check::Stall, 0.2));
}
