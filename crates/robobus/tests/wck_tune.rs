//! `robobus::ops::wck::tune` on the wCK simulator's mechanics, on its virtual clock: the
//! step responses of two gain sets, their figures of merit, the better one found, the
//! runtime gains set back, and the refusals before anything moves.

#![allow(clippy::unwrap_used)] // tests

use crate::station_support;

use robobus::ops::wck::tune::{self, Keep, TuneArgs};
use robobus::ops::{Control, ErrorKind};
use robobus::wck::Gains;
use robobus_wck::{DGain, PGain, ServoId, TorqueLevel};

fn gains(p: u8, d: u8) -> Gains {
    Gains {
        p: PGain::new(p).unwrap(),
        d: DGain::new(d).unwrap(),
    }
}

fn args(sets: Vec<Gains>) -> TuneArgs {
    TuneArgs {
        id: ServoId::new(1).unwrap(),
        amplitude: 20,
        gains: sets,
        hold_ms: 1500,
        torque: TorqueLevel::new(0).unwrap(),
        keep: Keep::None,
    }
}

#[test]
fn tuning_finds_the_better_of_two_gain_sets_on_the_simulated_mechanics() {
    let (_s, w, _j) = station_support::station("wck", "whj");
    let mut bus = w.lock();
    let start = bus
        .servo(ServoId::new(1).unwrap())
        .status()
        .unwrap()
        .position
        .get();
    let r = tune::tune(
        &mut bus,
        &args(vec![gains(2, 0), gains(20, 30)]),
        false,
        &mut Control::none(),
    )
    .unwrap();
    assert_eq!((r.start, r.target), (start, start + 20));
    let (slow, good) = (&r.responses[0], &r.responses[1]);
    assert_eq!((slow.p, good.p), (2, 20));
    // The manual's default gains rise and settle faster on the simulated mechanics, and
    // reach the target; P 2 stays a step short.
    assert!(good.rise_ms.unwrap() < slow.rise_ms.unwrap(), "{r:?}");
    assert!(
        good.settling_ms.unwrap() < slow.settling_ms.unwrap(),
        "{r:?}"
    );
    assert!(
        good.steady_state_error.abs() < 0.5,
        "{}",
        good.steady_state_error
    );
    assert!(
        slow.steady_state_error <= -0.5,
        "{}",
        slow.steady_state_error
    );
    assert_eq!((r.best, r.tied.len()), (Some(1), 0));
    // Readings every transaction for the whole hold, on the bus's clock.
    assert!(good.trace.len() > 100 && good.trace.last().unwrap().0 >= 1499.0);
    assert!(good.trace.windows(2).all(|w| w[1].0 > w[0].0));
    // Back at the start; the EEPROM gains untouched.
    let id = ServoId::new(1).unwrap();
    let mut at = 0;
    for _ in 0..2000 {
        at = bus.servo(id).status().unwrap().position.get();
        if at == start {
            break;
        }
    }
    assert_eq!(at, start);
    assert_eq!(bus.servo(id).gains().unwrap(), gains(20, 30));
}

#[test]
fn the_best_set_is_kept_in_eeprom_only_when_confirmed() {
    let (_s, w, _j) = station_support::station("wck", "whj");
    let mut bus = w.lock();
    let id = ServoId::new(1).unwrap();
    let keep = TuneArgs {
        keep: Keep::Eeprom,
        ..args(vec![gains(2, 0), gains(30, 20)])
    };
    let sent = bus.stats().attempts;
    let e = tune::tune(&mut bus, &keep, false, &mut Control::none()).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused, "{e}");
    assert_eq!(bus.stats().attempts, sent, "nothing was sent");
    let r = tune::tune(&mut bus, &keep, true, &mut Control::none()).unwrap();
    assert_eq!((r.best, r.kept), (Some(1), Keep::Eeprom));
    assert_eq!(bus.servo(id).gains().unwrap(), gains(30, 20));
}

#[test]
fn bad_steps_are_refused_before_anything_moves() {
    let (_s, w, _j) = station_support::station("wck", "whj");
    let mut bus = w.lock();
    for bad in [
        TuneArgs {
            amplitude: 1,
            ..args(vec![gains(20, 30)])
        },
        TuneArgs {
            hold_ms: 10,
            ..args(vec![gains(20, 30)])
        },
        args(Vec::new()),
        args(vec![gains(20, 30); 9]),
    ] {
        let sent = bus.stats().attempts;
        let e = tune::tune(&mut bus, &bad, false, &mut Control::none()).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::BadInput, "{e}");
        assert_eq!(bus.stats().attempts, sent);
    }
    // A step that leaves the servo's boundaries.
    let id = ServoId::new(1).unwrap();
    let here = bus.servo(id).status().unwrap().position.get();
    bus.servo(id)
        .set_boundaries(
            robobus_wck::Boundaries::new(
                robobus_wck::Position::new(here - 5).unwrap(),
                robobus_wck::Position::new(here + 5).unwrap(),
            )
            .unwrap(),
        )
        .unwrap();
    let e = tune::tune(
        &mut bus,
        &args(vec![gains(20, 30)]),
        false,
        &mut Control::none(),
    )
    .unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused, "{e}");
    assert!(e.to_string().contains("boundaries"), "{e}");
    assert_eq!(
        bus.servo(id).status().unwrap().position.get(),
        here,
        "nothing moved"
    );
}

#[test]
fn figures_of_merit_are_exact_on_a_known_response() {
    // 0 → 10 steps: 10 % at 10 ms... 90 % (9) at 30 ms, a peak of 12 (20 %), in the
    // band (±1 step) from 50 ms on.
    let trace: Vec<(f64, u8)> = [
        (0.0, 100),
        (10.0, 101),
        (20.0, 105),
        (30.0, 109),
        (40.0, 112),
        (50.0, 111),
        (60.0, 110),
        (70.0, 110),
        (80.0, 110),
        (90.0, 110),
    ]
    .to_vec();
    let r = tune::figures(&trace, 100, 110, 20, 30);
    assert_eq!(r.rise_ms, Some(20.0));
    assert!((r.overshoot_pct - 20.0).abs() < 1e-9);
    assert_eq!(r.settling_ms, Some(50.0));
    assert!(r.steady_state_error.abs() < 1e-12);
    // Downwards, the same.
    let down: Vec<(f64, u8)> = trace.iter().map(|&(t, p)| (t, 200 - p)).collect();
    let r = tune::figures(&down, 100, 90, 20, 30);
    assert_eq!((r.rise_ms, r.settling_ms), (Some(20.0), Some(50.0)));
    // Never settled: still moving at the end.
    let r = tune::figures(&trace[..5], 100, 110, 20, 30);
    assert_eq!(r.settling_ms, None);
}

#[test]
fn the_catalogue_runs_a_tune_and_its_dry_run_is_the_plan() {
    use robobus::catalogue::{self, Request};
    let (s, _w, _j) = station_support::station("wck", "whj");
    let json = r#"{"op": "wck.tune", "id": 2, "gains": [[2, 0], [20, 30]], "hold_ms": 800}"#;
    let request = Request::parse_many(json).unwrap().remove(0);
    let plan = catalogue::plan(&request).unwrap();
    assert!(
        plan.notes.iter().any(|n| n.contains("2 gain sets")),
        "{plan:?}"
    );
    let r = catalogue::run(&s, &request, &mut Control::none()).unwrap();
    assert_eq!(r.results.len(), 2);
    assert_eq!(
        (r.results[1]["p"].as_u64(), r.results[1]["d"].as_u64()),
        (Some(20), Some(30))
    );
    let summary = r.summary.unwrap();
    assert_eq!(summary["best"], 1);
    assert_eq!(summary["kept"], "none");
    assert!(summary["responses"][1]["trace"].as_array().unwrap().len() > 50);
    // Out of range: refused naming the option, nothing sent.
    for bad in [
        r#"{"op": "wck.tune", "id": 2, "gains": [[0, 30]]}"#,
        r#"{"op": "wck.tune", "id": 2, "gains": [[20, 30]], "amplitude": 100}"#,
        r#"{"op": "wck.tune", "id": 2, "gains": []}"#,
    ] {
        let req = Request::parse_many(bad).unwrap().remove(0);
        let e = catalogue::run(&s, &req, &mut Control::none()).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::BadInput, "{bad}: {e}");
    }
    let eeprom = r#"{"op": "wck.tune", "id": 2, "gains": [[20, 30]], "keep": "eeprom"}"#;
    let req = Request::parse_many(eeprom).unwrap().remove(0);
    let e = catalogue::run(&s, &req, &mut Control::none()).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused, "{e}");
}

#[test]
fn a_stop_ends_the_tune_holding_where_it_is() {
    use robobus::ops::{Progress, StopToken};
    let (_s, w, _j) = station_support::station("wck", "whj");
    let mut bus = w.lock();
    let stop = StopToken::new();
    let token = stop.clone();
    // Stopped while the first set settles at the start (the check inside the reading
    // loops, not only between sets).
    let mut at_first = |p: &Progress| {
        if p.done == 0 {
            token.stop();
        }
    };
    let mut control = Control::new(&stop).with_progress(&mut at_first);
    let e = tune::tune(
        &mut bus,
        &args(vec![gains(20, 30), gains(2, 0), gains(30, 20)]),
        false,
        &mut control,
    )
    .unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Interrupted, "{e}");
    assert_eq!(
        bus.servo(ServoId::new(1).unwrap()).gains().unwrap(),
        gains(20, 30),
        "EEPROM untouched"
    );
}

#[test]
#[allow(clippy::float_cmp)] // the same readings at the same instants of the virtual clock
fn identical_gain_sets_are_a_tie_with_identical_figures() {
    let (_s, w, _j) = station_support::station("wck", "whj");
    let mut bus = w.lock();
    let r = tune::tune(
        &mut bus,
        &args(vec![gains(20, 30), gains(20, 30)]),
        false,
        &mut Control::none(),
    )
    .unwrap();
    let (a, b) = (&r.responses[0], &r.responses[1]);
    // Each run starts from the same state: the same figures, and the same readings at
    // the same times, within the resolution of a reading (one position step).
    assert_eq!(
        (
            a.rise_ms,
            a.overshoot_pct,
            a.settling_ms,
            a.steady_state_error
        ),
        (
            b.rise_ms,
            b.overshoot_pct,
            b.settling_ms,
            b.steady_state_error
        ),
        "{r:?}"
    );
    assert_eq!(a.trace.len(), b.trace.len());
    for (x, y) in a.trace.iter().zip(&b.trace) {
        assert!(x.0 == y.0 && x.1.abs_diff(y.1) <= 1, "{x:?} {y:?}");
    }
    assert_eq!(
        (r.best, r.tied.as_slice()),
        (None, [0, 1].as_slice()),
        "{r:?}"
    );
}

#[test]
fn the_servo_is_back_at_its_start_when_tune_returns() {
    let (_s, w, _j) = station_support::station("wck", "whj");
    let mut bus = w.lock();
    let id = ServoId::new(1).unwrap();
    let start = bus.servo(id).status().unwrap().position.get();
    let r = tune::tune(
        &mut bus,
        &args(vec![gains(2, 0), gains(20, 30)]),
        false,
        &mut Control::none(),
    )
    .unwrap();
    assert_eq!(r.start, start);
    // The first reading after the return: there already, and at rest.
    assert_eq!(bus.servo(id).status().unwrap().position.get(), start);
    let t = bus.now() + std::time::Duration::from_millis(300);
    while bus.now() < t {
        assert_eq!(bus.servo(id).status().unwrap().position.get(), start);
    }
}
