//! Fault tests: the seeded fault injector between the client and the simulator, a
//! device that is unplugged, a link that goes away.
#![cfg(target_os = "linux")]
#![allow(clippy::unwrap_used)] // test helpers

use crate::wck_support;

use std::time::Duration;

use robobus::WaitMode;
use robobus::wck::Gains;
use robobus::wck::{WckBus, WckConfig, WckError};
use robobus_link::{FaultConfig, FaultyByteLink};
use robobus_sim::wck::{Bus, BusConfig, Eeprom, Faults, Model};
use robobus_wck::{
    BaudRate, Boundaries, DGain, ExtServoId, IGain, MotionCount, Overload, PGain, Position, Target,
    TorqueLevel,
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
        (2175, 1706, 189, 645),
        "the loop completed through retries: {stats:?} {injected:?}"
    );
}

/// What 10 000 reads of one module return through 1 % each of duplicated bytes (the link
/// repeats a byte it receives), doubled replies (the module answers a command twice, 0.5
/// ms apart) and shifted replies (a reply leaves 7 ms late, past its deadline, into the
/// next command's exchange). `guard`: [`WckConfig::guard`].
struct Through {
    wrong: Vec<u32>,
    errors: usize,
    stats: robobus::wck::WckStats,
    duplicated: u64,
    doubled: u64,
    shifted: u64,
}

fn reads_through_duplicated_doubled_and_shifted_bytes(
    confirm_reads: u8,
    guard: Option<Duration>,
    wait: WaitMode,
) -> Through {
    use robobus_sim::wck::{Bus, BusConfig, Faults, Model};
    let config = BusConfig {
        host_baud: BaudRate::B921600,
        seed: 11,
        faults: Faults {
            double_reply: 0.01,
            double_gap: Duration::from_micros(500),
            late_reply: 0.01,
            late_by: Duration::from_millis(7),
            ..Faults::default()
        },
        ..BusConfig::default()
    };
    let mut sim = wck_support::serve(Bus::with_servos(config, Model::W1108, [1u8]));
    sim.with_bus(|b| b.servo_mut(0).unwrap().hold(true));
    let faults = FaultConfig {
        duplicate: 0.01,
        tx: false,
        ..FaultConfig::seeded(5)
    };
    let config = WckConfig {
        confirm_reads,
        retries: 10,
        margin: Duration::from_millis(5),
        guard,
        wait,
        ..WckConfig::default()
    };
    let mut bus = WckBus::new(FaultyByteLink::new(sim.link(), faults), BaudRate::B921600)
        .unwrap()
        .with_config(config);
    let truth = Gains {
        p: PGain::new(20).unwrap(),
        d: DGain::new(30).unwrap(),
    };
    let (mut wrong, mut errors) = (Vec::new(), 0);
    for cycle in 0..10_000u32 {
        let mut s = bus.servo(id(1));
        let ok = match cycle % 4 {
            0 => s
                .status()
                .map(|v| v.position == Position::new(127).unwrap()),
            1 => s.gains().map(|v| v == truth),
            2 => s.overload().map(|v| v == Overload::DEFAULT),
            _ => s.boundaries().map(|v| v == Boundaries::DEFAULT),
        };
        match ok {
            Ok(true) => {}
            Ok(false) => wrong.push(cycle),
            Err(_) => errors += 1,
        }
    }
    let sim_stats = sim.with_bus(|b| b.stats());
    Through {
        wrong,
        errors,
        stats: bus.stats(),
        duplicated: bus.link().stats().duplicated,
        doubled: sim_stats.doubled_replies,
        shifted: sim_stats.late_replies,
    }
}

/// No wrong value through duplicated, doubled and shifted bytes, without confirmed
/// reads, with the default guard (one byte time plus the turnaround spread after each
/// reply: 13.9 µs at 921600 bit/s); and in the same run, the same seeds, wrong values
/// with the guard off: a byte the link duplicates within a reply (`a a b`) is then
/// credited as the reply `a a`. A doubled reply (its second answer 0.5 ms after the
/// first) comes after the guard, while the next command is on its way and before any
/// module can have answered it: it fails that attempt, which is asked again.
#[test]
fn duplicated_doubled_and_shifted_bytes_give_no_wrong_value_and_wrong_values_without_the_guard() {
    // Whether the client sleeps or spins for its replies, the same bytes are credited.
    for wait in [WaitMode::Sleep, WaitMode::SPIN] {
        let r = reads_through_duplicated_doubled_and_shifted_bytes(0, None, wait);
        assert!(
            r.wrong.is_empty(),
            "{wait}: wrong values at cycles {:?}",
            r.wrong
        );
        // Seeded faults on the virtual clock: the same run every time, and every read came
        // through its retries.
        assert_eq!(
            (r.duplicated, r.doubled, r.shifted, r.errors),
            (233, 113, 113, 0),
            "{wait}: {:?}",
            r.stats
        );
        assert_eq!(
            (r.stats.unattributable, r.stats.timeouts),
            (328, 113),
            "{wait}"
        );
        // The same seeds with the guard off.
        let off = reads_through_duplicated_doubled_and_shifted_bytes(0, Some(Duration::ZERO), wait);
        assert_eq!(off.wrong.len(), 71, "{wait}: {:?}", off.stats);
    }
}

/// The same with three equal replies required for every read.
#[test]
fn duplicated_doubled_and_shifted_bytes_give_no_wrong_value_with_confirmed_reads() {
    let r = reads_through_duplicated_doubled_and_shifted_bytes(3, None, WaitMode::Sleep);
    assert!(r.wrong.is_empty(), "wrong values at cycles {:?}", r.wrong);
    assert_eq!(
        (r.duplicated, r.doubled, r.shifted, r.errors),
        (591, 296, 302, 0),
        "{:?}",
        r.stats
    );
    assert_eq!((r.stats.unattributable, r.stats.timeouts), (832, 302));
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

/// Bytes already waiting when a program opens the bus (a late reply to a previous
/// program) are drained before the first command: they are nobody's reply.
#[test]
fn bytes_waiting_before_the_first_command_are_nobodys_reply() {
    let mut sim = wck_support::serve_modules(&[(3, BaudRate::B115200, 200)]);
    let now = sim.now();
    // Two bytes of a status reply (load 0, position 40) to a command nobody sent here.
    sim.with_bus(|b| b.inject_to_host(now, &[0x00, 40]));
    let mut bus = sim.bus();
    let status = bus.servo(id(3)).status().unwrap();
    assert_eq!(status.position, Position::new(200).unwrap());
    assert_eq!(bus.stats().attempts, 1);
}

/// A late reply to a program that used the port before (the P / D gains it read, 40 and
/// 90) arrives 5 ms after this program opened the bus, while the module's own replies come
/// 15 ms late (still within a 30 ms margin): the move's `position_before` is the module's
/// position, never the stale D gain. Opening the bus waits out a late window, dropping
/// (and counting) what arrives.
#[test]
fn a_late_reply_to_a_previous_program_is_never_a_moves_position_before() {
    let config = BusConfig {
        faults: Faults {
            late_reply: 1.0,
            late_by: Duration::from_millis(15),
            ..Faults::default()
        },
        ..BusConfig::default()
    };
    let mut sim_bus = Bus::new(config);
    let eeprom = Eeprom {
        id: ExtServoId::new(3).unwrap(),
        ..Eeprom::default()
    };
    sim_bus.add(Model::W1108, eeprom, 200.0 * 269.0 / 255.0);
    let mut sim = wck_support::serve(sim_bus);
    let at = sim.now() + Duration::from_millis(5);
    sim.with_bus(|b| b.inject_to_host(at, &[40, 90]));
    let mut bus = sim.bus().with_config(WckConfig {
        margin: Duration::from_millis(30),
        ..WckConfig::default()
    });
    let before = bus
        .servo(id(3))
        .move_to(TorqueLevel::new(2).unwrap(), Position::new(200).unwrap())
        .unwrap();
    assert_eq!(before.position, Position::new(200).unwrap());
    assert_eq!(bus.stats().dropped, 2);
    assert_eq!(bus.stats().attempts, 1);
}

/// A module that answers every command twice (0.5 ms apart, within a turnaround) never
/// gives its value to the module asked next: its own reads are its own answer (the two
/// answers are the same bytes, and the first was followed by the guard's quiet time); its
/// second answer arrives while the next module's command is on its way, before that
/// module can have answered, and fails that attempt, which is asked again: every module
/// reads its own position, and each second answer is counted once.
#[test]
fn a_module_answering_twice_never_gives_its_value_to_another() {
    let modules: Vec<(u8, BaudRate, u8)> = (0..6u8)
        .map(|n| (n, BaudRate::B115200, 20 + 30 * n))
        .collect();
    let mut sim = wck_support::serve_modules(&modules);
    sim.with_bus(|b| b.set_answers_twice(0, Some(Duration::from_micros(500))));
    let mut bus = sim.bus();
    for round in 0..3 {
        for n in 0..6u8 {
            let got = bus.servo(id(n)).status();
            assert_eq!(
                got.unwrap().position,
                Position::new(20 + 30 * n).unwrap(),
                "round {round}, module {n}"
            );
        }
    }
    let stats = bus.stats();
    assert_eq!((stats.unattributable, stats.retries), (3, 3), "{stats:?}");
    // Without retries, the reading that fails is module 1's, the one asked next.
    bus.config_mut().retries = 0;
    let got: Vec<_> = (0..3u8)
        .map(|n| bus.servo(id(n)).status().map_err(Box::new))
        .collect();
    assert!(got[0].is_ok() && got[2].is_ok(), "{got:?}");
    let e = got[1].as_ref().unwrap_err();
    assert!(
        matches!(**e, WckError::Unattributable { .. })
            && e.to_string()
                .contains("before any module can have answered"),
        "{e}"
    );
}
