//! Fault tests: the seeded fault injector between the client and the simulator, a
//! device that is unplugged, a link that goes away.
#![cfg(target_os = "linux")]
#![allow(clippy::unwrap_used, clippy::panic)] // test helpers

mod wck_support;

use std::time::Duration;

use robobus::wck::Gains;
use robobus::wck::{WckBus, WckConfig, WckError};
use robobus_link::{FaultConfig, FaultyByteLink};
use robobus_wck::{
    BaudRate, Boundaries, DGain, IGain, MotionCount, Overload, PGain, Position, Target,
};
use wck_support::{id, serve_fast, serve_ids};

/// 10 000 reads with 1 % of the bytes corrupted in both directions (one random bit
/// flipped in each such byte): every value returned is the true one, and none fails.
///
/// Corruption that the plausibility checks cannot see (a flipped bit in a status reply
/// still reads as a plausible position) is caught by `confirm_reads: 3` (three equal
/// replies in a row; two for the reads that repeat their value); corrupted commands
/// are mostly rejected by the module's checksum and time out. A command corrupted into
/// a move (bit 7 of the mode byte is outside the 7-bit checksum) cannot move the shaft:
/// it is held.
#[test]
fn a_read_loop_with_one_percent_corrupted_bytes_returns_no_wrong_value() {
    // At 921600 bit/s a transaction is 1.07 ms, mostly the module's turnaround; the
    // simulated clock skips the waits.
    let mut sim = serve_fast(&[1], BaudRate::B921600);
    sim.with_bus(|b| b.servo_mut(0).unwrap().hold(true));
    let link = sim.link();
    let faults = FaultConfig {
        corrupt: 0.01,
        ..FaultConfig::seeded(7)
    };
    let config = WckConfig {
        confirm_reads: 3,
        retries: 10,
        margin: Duration::from_millis(5),
        ..WckConfig::default()
    };
    let mut bus = WckBus::new(FaultyByteLink::new(link, faults), BaudRate::B921600)
        .unwrap()
        .with_config(config);

    // Ground truth, set on the module directly.
    let truth = Gains {
        p: PGain::new(20).unwrap(),
        d: DGain::new(30).unwrap(),
    };
    let mut wrong = Vec::new();
    let mut errors = Vec::new();
    for cycle in 0..10_000u32 {
        let mut s = bus.servo(id(1));
        let ok = match cycle % 5 {
            0 => s
                .status()
                .map(|v| v.position == Position::new(127).unwrap()),
            1 => s.gains().map(|v| v == truth),
            2 => s.i_gain().map(|v| v == IGain::DEFAULT),
            3 => s.overload().map(|v| v == Overload::DEFAULT),
            _ => s.boundaries().map(|v| v == Boundaries::DEFAULT),
        };
        match ok {
            Ok(true) => {}
            Ok(false) => wrong.push(cycle),
            Err(e) => errors.push(format!("cycle {cycle}: {e}")),
        }
    }
    let count = bus.servo(id(1)).program_count();
    assert_eq!(count.ok(), Some(MotionCount::new(0).unwrap()));
    let stats = bus.stats();
    let injected = bus.link().stats();
    eprintln!("{stats:?}\n{injected:?}");
    assert!(wrong.is_empty(), "wrong values at cycles {wrong:?}");
    assert!(errors.is_empty(), "{errors:#?}");
    // Seeded faults on the virtual clock: the same run every time.
    assert_eq!(
        (
            injected.corrupted,
            stats.retries,
            stats.bad_replies,
            stats.mismatches
        ),
        (2175, 1706, 189, 646),
        "the loop completed through retries: {stats:?} {injected:?}"
    );
}

#[test]
fn an_unplugged_device_is_a_clear_timeout_naming_it() {
    let mut sim = serve_ids(&[5]);
    let path = wck_support::DEVICE;
    let mut bus = sim.bus();
    assert!(bus.servo(id(5)).status().is_ok());
    sim.with_bus(|b| b.unplug(0));
    let err = bus.servo(id(5)).status().unwrap_err();
    match &err {
        WckError::Timeout {
            device,
            target,
            received,
            attempts,
            waited,
            ..
        } => {
            assert_eq!(device, path);
            assert_eq!(*target, Target::Servo(id(5)));
            assert!(received.is_empty());
            assert_eq!(*attempts, 4);
            // The modelled transaction (1.53 ms) plus the 10 ms margin.
            assert_eq!(*waited, Duration::from_nanos(11_527_433));
        }
        other => panic!("{other:?}"),
    }
    let text = err.to_string();
    assert!(
        text.contains(path) && text.contains("servo 5") && text.contains("did not answer"),
        "{text}"
    );
    // Plugged back in, it answers once it is awake.
    sim.with_bus(|b| b.plug(0));
    sim.sleep(wck_support::AWAKE);
    assert!(bus.servo(id(5)).status().is_ok());
}

#[test]
fn a_link_that_goes_away_is_a_link_error_naming_the_device() {
    let mut sim = serve_ids(&[0]);
    let link = sim.link();
    let faults = FaultConfig {
        disconnect_after: Some(4),
        ..FaultConfig::seeded(1)
    };
    let mut bus = WckBus::new(FaultyByteLink::new(link, faults), BaudRate::B115200)
        .unwrap()
        .with_device_name("/dev/ttyUSB7");
    let mut last = Ok(());
    for _ in 0..10 {
        last = bus.servo(id(0)).status().map(drop);
        if last.is_err() {
            break;
        }
    }
    let err = last.unwrap_err();
    assert!(matches!(err, WckError::Link { .. }), "{err}");
    assert!(err.to_string().contains("/dev/ttyUSB7"), "{err}");
    assert_eq!(err.device(), Some("/dev/ttyUSB7"));
}
