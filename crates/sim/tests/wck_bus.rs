//! Bus and firmware timing on the virtual clock: turnaround, deaf time after power-up,
//! the EEPROM busy window, EEPROM vs runtime across a power cycle, ID and baud changes,
//! duplicate IDs, unplugged modules, seeded faults.
#![allow(clippy::unwrap_used)] // test helpers

use crate::wck_support;

use core::time::Duration;

use proptest::prelude::*;
use robobus_sim::wck::{Bus, BusConfig, Eeprom, Faults, Model, Timing, VirtualHost};
use robobus_wck::timing::{T_EEPROM, T_PROC, byte_time};
use robobus_wck::{
    Accel, BaudRate, Boundaries, Command, DGain, ExtServoId, IGain, PGain, Position, Speed,
};
use wck_support::{AWAKE, host, host_with, id, mv, status};

const STATUS0: [u8; 4] = [0xFF, 0xA0, 0x00, 0x20];
const T: Duration = Duration::from_millis(200);

#[test]
fn reply_bytes_leave_the_wire_after_turnaround_at_the_baud_rate() {
    for baud in BaudRate::ALL {
        let config = BusConfig {
            host_baud: baud,
            max_skew: Duration::ZERO,
            ..Default::default()
        };
        let mut h = host_with(config, Model::W1108, &[0]);
        let start = h.now();
        let got = h.transact_timed(&STATUS0, 2, T);
        let cmd_end = start + byte_time(baud) * 4;
        let b = byte_time(baud);
        // One nanosecond of rounding per byte at most.
        let close = |a: Duration, e: Duration| a.abs_diff(e) <= Duration::from_nanos(8);
        assert_eq!(got.len(), 2, "{baud}");
        assert!(close(got[0].0, cmd_end + T_PROC + b), "{baud}: {got:?}");
        assert!(close(got[1].0, cmd_end + T_PROC + 2 * b), "{baud}: {got:?}");
        // The manual's response time at 115200: 1180 µs from the last command byte.
        if baud == BaudRate::B115200 {
            let response = got[1].0.saturating_sub(cmd_end);
            assert!(response.abs_diff(Duration::from_micros(1180)) < Duration::from_micros(1));
        }
    }
}

#[test]
fn zero_turnaround_for_benchmarks() {
    let config = BusConfig {
        timing: Timing::ZERO,
        max_skew: Duration::ZERO,
        ..Default::default()
    };
    let bus = Bus::with_servos(config, Model::W1108, [0]);
    let mut h = VirtualHost::new(bus);
    // No deaf time either.
    let got = h.transact_timed(&STATUS0, 2, T);
    let b = byte_time(BaudRate::B115200);
    assert!(
        got[1].0.abs_diff(b * 6) <= Duration::from_nanos(8),
        "{got:?}"
    );
}

#[test]
fn deaf_for_65_ms_after_power_up() {
    let bus = Bus::with_servos(BusConfig::default(), Model::W1108, [0]);
    let mut h = VirtualHost::new(bus);
    h.sleep(Duration::from_millis(60));
    assert!(h.transact(&STATUS0, 2, Duration::from_millis(3)).is_empty());
    h.advance_to(Duration::from_millis(65));
    assert_eq!(h.transact(&STATUS0, 2, Duration::from_millis(3)), [0, 127]);
    // Again after a power cycle.
    h.bus_mut().power_cycle(0);
    h.sleep(Duration::from_millis(64));
    assert!(h.transact(&STATUS0, 2, Duration::from_millis(3)).is_empty());
    h.sleep(Duration::from_millis(2));
    assert_eq!(h.transact(&STATUS0, 2, Duration::from_millis(3)).len(), 2);
}

#[test]
fn eeprom_write_takes_121_ms_and_the_module_ignores_the_bus_meanwhile() {
    let mut h = host(Model::W1108, &[0]);
    let bounds = Boundaries::new(Position::new(10).unwrap(), Position::new(240).unwrap()).unwrap();
    let cmd = Command::BoundarySet { id: id(0), bounds };
    let start = h.now();
    let end = h.send(cmd.encode().as_bytes());
    let wire = robobus_wck::timing::wire_time(6, BaudRate::B115200);
    assert!(end.saturating_sub(start).abs_diff(wire) <= Duration::from_nanos(1));
    // 50 ms later the host asks for the status: no answer, the module is writing.
    h.sleep(Duration::from_millis(50));
    assert!(h.transact(&STATUS0, 2, Duration::from_millis(5)).is_empty());
    // The EEPROM reply arrives T_EEPROM after the command, and nothing else.
    let got = h.receive_until(4, end + T_EEPROM + Duration::from_millis(5));
    let bytes: Vec<u8> = got.iter().map(|b| b.1).collect();
    assert_eq!(bytes, [10, 240]);
    let b = byte_time(BaudRate::B115200);
    assert!(got[1].0.abs_diff(end + T_EEPROM + 2 * b) <= Duration::from_nanos(8));
    // Afterwards it answers normally.
    assert_eq!(h.transact(&STATUS0, 2, T), [0, 127]);
}

#[test]
fn eeprom_survives_a_power_cycle_and_runtime_values_do_not() {
    let mut h = host(Model::W1108, &[0]);
    let (p, d) = (PGain::new(50).unwrap(), DGain::new(40).unwrap());
    assert_eq!(h.command(&Command::GainSet { id: id(0), p, d }), [50, 40]);
    let i = IGain::new(3).unwrap();
    assert_eq!(h.command(&Command::IGainSet { id: id(0), i }), [3, 3]);
    let (speed, accel) = (Speed::new(12).unwrap(), Accel::new(80).unwrap());
    assert_eq!(
        h.command(&Command::SpeedSet {
            id: id(0),
            speed,
            accel
        }),
        [12, 80]
    );

    let (rp, rd) = (PGain::new(90).unwrap(), DGain::new(60).unwrap());
    h.command(&Command::RuntimeGainSet {
        id: id(0),
        p: rp,
        d: rd,
    });
    h.command(&Command::RuntimeIGainSet {
        id: id(0),
        i: IGain::new(7).unwrap(),
    });
    let (rs, ra) = (Speed::new(25).unwrap(), Accel::new(30).unwrap());
    h.command(&Command::RuntimeSpeedSet {
        id: id(0),
        speed: rs,
        accel: ra,
    });
    h.command(&Command::IoWrite {
        id: id(0),
        outputs: robobus_wck::IoBits::new(3).unwrap(),
    });
    assert_eq!(h.command(&Command::GainRead { id: id(0) }), [90, 60]);
    assert_eq!(h.command(&Command::IGainRead { id: id(0) }), [7, 7]);
    assert_eq!(h.command(&Command::SpeedRead { id: id(0) }), [25, 30]);

    h.bus_mut().power_cycle(0);
    h.sleep(AWAKE);
    assert_eq!(h.command(&Command::GainRead { id: id(0) }), [50, 40]);
    assert_eq!(h.command(&Command::IGainRead { id: id(0) }), [3, 3]);
    assert_eq!(h.command(&Command::SpeedRead { id: id(0) }), [12, 80]);
    assert_eq!(h.command(&Command::IoRead { id: id(0) }), [0, 0]);
}

#[test]
fn eeprom_persists_in_a_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("eeprom.txt");
    let mut h = host(Model::W1108, &[0, 1]);
    let overload = robobus_wck::Overload::new(104).unwrap();
    h.command(&Command::OverloadSet {
        id: id(1),
        overload,
    });
    h.command(&Command::IdSet {
        id: id(0),
        new_id: ExtServoId::new(7).unwrap(),
    });
    h.bus().save_eeproms(&path).unwrap();

    let mut h2 = host(Model::W1108, &[0, 1]);
    h2.bus_mut().load_eeproms(&path).unwrap();
    h2.sleep(AWAKE);
    assert_eq!(h2.command(&Command::OverloadRead { id: id(1) }), [104, 104]);
    assert!(status(&mut h2, 0).is_none());
    assert_eq!(status(&mut h2, 7), Some((0, 127)));
    assert_eq!(Eeprom::load(&path).unwrap().len(), 2);
}

#[test]
fn id_change_takes_effect_after_the_reply() {
    let mut h = host(Model::W1108, &[0]);
    let new_id = ExtServoId::new(5).unwrap();
    assert_eq!(h.command(&Command::IdSet { id: id(0), new_id }), [5, 5]);
    assert!(status(&mut h, 0).is_none());
    assert_eq!(status(&mut h, 5), Some((0, 127)));
    // An ID above 30 is reachable with the 10-bit commands only.
    let high = ExtServoId::new(200).unwrap();
    assert_eq!(
        h.command(&Command::IdSet {
            id: id(5),
            new_id: high
        }),
        [200, 200]
    );
    assert!(status(&mut h, 5).is_none());
    assert_eq!(h.command(&Command::Read10 { id: high }).len(), 2);
}

#[test]
fn baud_change_answers_at_the_old_rate_then_listens_at_the_new_one() {
    let mut h = host(Model::W1108, &[0]);
    let set = Command::BaudSet {
        id: id(0),
        baud: BaudRate::B57600,
    };
    assert_eq!(h.command(&set), [15, 15]);
    // A client still at 115200 gets nothing sensible back.
    let reply = h.transact(&STATUS0, 2, Duration::from_millis(5));
    assert_ne!(reply, [0, 127]);
    // At 57600 it works.
    h.bus_mut().set_host_baud(BaudRate::B57600);
    assert_eq!(h.transact(&STATUS0, 2, Duration::from_millis(5)), [0, 127]);
    // The rate is in EEPROM: still 57600 after a power cycle.
    h.bus_mut().power_cycle(0);
    h.sleep(AWAKE);
    assert_eq!(h.transact(&STATUS0, 2, Duration::from_millis(5)), [0, 127]);
    h.bus_mut().set_host_baud(BaudRate::B115200);
    assert_ne!(h.transact(&STATUS0, 2, Duration::from_millis(5)), [0, 127]);
}

#[test]
fn duplicate_ids_garble_replies_and_both_move() {
    let config = BusConfig {
        seed: 7,
        ..Default::default()
    };
    let bus = Bus::with_servos(config, Model::W1108, [3, 3]);
    let mut h = VirtualHost::new(bus);
    h.bus_mut().servo_mut(0).unwrap().set_position(40);
    h.bus_mut().servo_mut(1).unwrap().set_position(201);
    h.sleep(AWAKE);
    let reply = h.transact(&[0xFF, 0xA3, 0x00, 0x23], 2, T);
    assert_ne!(reply, [0, 40]);
    assert_ne!(reply, [0, 201]);
    h.command(&mv(3, 0, 127));
    h.sleep(Duration::from_secs(1));
    assert_eq!(h.bus().servo(0).unwrap().position(), 127);
    assert_eq!(h.bus().servo(1).unwrap().position(), 127);
    // Alone again (one unplugged), the other answers cleanly.
    h.bus_mut().unplug(1);
    assert_eq!(status(&mut h, 3).map(|s| s.1), Some(127));
}

#[test]
fn unplugged_module_is_silent_and_comes_back_deaf_then_listening() {
    let mut h = host(Model::W1108, &[0, 1]);
    h.bus_mut().unplug(1);
    assert!(status(&mut h, 1).is_none());
    assert_eq!(status(&mut h, 0), Some((0, 127)));
    h.bus_mut().plug(1);
    assert!(status(&mut h, 1).is_none());
    h.sleep(AWAKE);
    assert_eq!(status(&mut h, 1), Some((0, 127)));
}

fn faulty_run(seed: u64) -> Vec<u8> {
    let faults = Faults {
        drop_host: 0.05,
        flip_host: 0.05,
        drop_reply: 0.05,
        flip_reply: 0.05,
        ..Faults::default()
    };
    let config = BusConfig {
        seed,
        faults,
        ..Default::default()
    };
    let mut h = host_with(config, Model::W1108, &[0, 1, 2]);
    let mut got = Vec::new();
    for k in 0..60u8 {
        let n = k % 3;
        got.extend(h.transact(
            &[0xFF, 0xA0 | n, 0, (0xA0 | n) & 0x7F],
            2,
            Duration::from_millis(3),
        ));
        got.push(0xEE);
    }
    got
}

#[test]
fn faults_are_seeded_and_reproducible() {
    let a = faulty_run(1);
    assert_eq!(a, faulty_run(1));
    assert_ne!(a, faulty_run(2));
    let clean: Vec<u8> = (0..60).flat_map(|_| [0, 127, 0xEE]).collect();
    assert!(a.len() > 100, "most replies still arrive: {a:?}");
    assert_ne!(a, clean);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]
    /// Whatever the host sends, at whatever rate, the bus never panics and time moves on.
    #[test]
    fn arbitrary_traffic_never_panics(
        chunks in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..40), 0..12),
        baud_idx in 0usize..8,
        gaps in proptest::collection::vec(0u64..3000, 12),
    ) {
        let config = BusConfig { host_baud: BaudRate::ALL[baud_idx], ..Default::default() };
        let mut h = host_with(config, Model::W1413, &[0, 1, 1, 30]);
        h.bus_mut().servo_mut(2).unwrap().set_position(3);
        for (c, gap) in chunks.iter().zip(gaps) {
            h.send(c);
            h.sleep(Duration::from_micros(gap));
        }
        h.sleep(Duration::from_millis(300));
        prop_assert!(h.bus().stats().host_bytes >= chunks.iter().map(|c| c.len() as u64).sum::<u64>());
    }
}

#[test]
fn sync_move_is_wire_timed_and_reaches_every_listed_id() {
    let mut h = host(Model::W1111, &[0, 1, 2, 3]);
    let positions: Vec<Position> = [30, 60, 90].map(|p| Position::new(p).unwrap()).to_vec();
    let sync =
        robobus_wck::SyncMove::new(robobus_wck::TorqueLevel::new(0).unwrap(), &positions).unwrap();
    let cmd = Command::SyncMove(sync);
    let start = h.now();
    let end = h.send(cmd.encode().as_bytes());
    let wire = robobus_wck::timing::sync_move_time(3, BaudRate::B115200);
    assert!(end.saturating_sub(start).abs_diff(wire) <= Duration::from_nanos(1));
    h.sleep(Duration::from_secs(2));
    let got: Vec<u8> = (0..4)
        .map(|i| h.bus().servo(i).unwrap().position())
        .collect();
    // ID 3 is not in the list and stays passive where it was.
    assert_eq!(got, [30, 60, 90, 127]);
}

#[test]
fn modules_at_another_baud_rate_read_garbage_and_stay_put() {
    let config = BusConfig {
        max_skew: Duration::ZERO,
        ..Default::default()
    };
    let mut bus = Bus::new(config);
    let fast = Eeprom::default();
    let slow = Eeprom {
        id: ExtServoId::new(1).unwrap(),
        baud: BaudRate::B57600,
        ..Eeprom::default()
    };
    bus.add(Model::W1108, fast, 127.0 * 269.0 / 255.0);
    bus.add(Model::W1108, slow, 127.0 * 269.0 / 255.0);
    let mut h = VirtualHost::new(bus);
    h.sleep(AWAKE);
    // At 115200 only servo 0 understands; servo 1 hears noise and neither moves nor answers.
    for _ in 0..20 {
        h.command(&mv(1, 0, 30));
    }
    assert_eq!(status(&mut h, 0), Some((0, 127)));
    assert_ne!(status(&mut h, 1), Some((0, 127)));
    h.sleep(Duration::from_millis(300));
    assert_eq!(h.bus().servo(1).unwrap().position(), 127);
    assert!(h.bus().stats().commands >= 2);
    // At 57600 it is the other way round.
    h.bus_mut().set_host_baud(BaudRate::B57600);
    assert_eq!(status(&mut h, 1), Some((0, 127)));
    assert_ne!(status(&mut h, 0), Some((0, 127)));
    assert_eq!(h.command(&mv(1, 0, 30)), [0, 127]);
    h.sleep(Duration::from_millis(600));
    assert_eq!(h.bus().servo(1).unwrap().position(), 30);
    assert_eq!(h.bus().servo(0).unwrap().position(), 127);
}
