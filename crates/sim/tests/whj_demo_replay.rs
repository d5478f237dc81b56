//! Replay of every exchange in the vendor's CAN FD usage demo against the simulator on the
//! virtual clock. Each command frame gets a reply of exactly the demo's ID and length;
//! the bytes equal the demo's where the simulated state was set up to match it (initial
//! angle, supply voltage, temperature), and every other field equals the simulated state.

#![allow(
    clippy::unwrap_used,
    clippy::float_cmp,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap,
    clippy::cast_precision_loss,
    clippy::unchecked_time_subtraction,
    clippy::panic
)] // Test code: a failed unwrap is a failed test; exact float equality is asserted on purpose.

use crate::whj_common;

use robobus_sim::whj::{JointConfig, WhjBus, WhjModel};
use whj_common::{exchange, feedback, frame, one, silent, wait_ms};

/// Joint 1 as in the demo: a WHJ30 (1 mA current LSB) on a 23.00 V supply at 49.0 °C.
fn demo_joint(initial_deg: f64) -> WhjBus {
    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.initial_position_deg = initial_deg;
    cfg.supply_voltage_v = 23.0;
    cfg.supply_resistance_ohm = 0.0;
    cfg.ambient_temp_c = 49.0;
    WhjBus::with_configs([cfg], 1)
}

/// "IAP Online Update Flag (Required Operation)": `0x01 02 49 00` → `0x101 02 49 01`.
fn iap(bus: &mut WhjBus) {
    exchange(
        bus,
        frame(0x001, &[0x02, 0x49, 0x00]),
        0x101,
        &[0x02, 0x49, 0x01],
    );
    wait_ms(bus, 10);
}

fn le32(d: &[u8], k: usize) -> i32 {
    i32::from_le_bytes([d[k], d[k + 1], d[k + 2], d[k + 3]])
}

#[test]
fn basic_demo_read_write_servo() {
    let mut bus = demo_joint(1.0);
    // Before the IAP handshake the joint is in its bootloader and stays silent.
    silent(&mut bus, frame(0x001, &[0x01, 0x14, 0x02]));
    iap(&mut bus);

    // E1: read the position (2 registers from 0x14): 0x2710 = 1.0000°.
    exchange(
        &mut bus,
        frame(0x001, &[0x01, 0x14, 0x02]),
        0x101,
        &[0x01, 0x14, 0x10, 0x27, 0x00, 0x00],
    );
    wait_ms(&mut bus, 10);

    // E2: target position 1° as a 4-byte write.
    exchange(
        &mut bus,
        frame(0x001, &[0x02, 0x36, 0x10, 0x27, 0x00, 0x00]),
        0x101,
        &[0x02, 0x36, 0x01],
    );
    assert_eq!(bus.joint(1).unwrap().state().target_position, 10_000);
    wait_ms(&mut bus, 10);

    // E3: position servo 1° → 16-byte feedback: position 0x2710 (the demo prints 0x2010,
    // C23), enabled, no error; current and speed are the simulated ones.
    let before = bus.joint(1).unwrap().state();
    let r = one(&mut bus, frame(0x201, &[0x10, 0x27, 0x00, 0x00]));
    assert_eq!((r.raw_id(), r.len()), (0x501, 16));
    let (current, speed, position, enable, error) = feedback(&r);
    assert_eq!(
        &r.data()[8..16],
        &[0x10, 0x27, 0x00, 0x00, 0x01, 0x00, 0x00, 0x00]
    );
    assert_eq!((position, enable, error), (10_000, 1, 0));
    assert_eq!(current, (before.current_a * 1000.0).round() as i32);
    assert_eq!(speed, (before.speed_rpm / 0.02).round() as i32);
}

#[test]
#[allow(clippy::too_many_lines)] // The demo's exchanges, one after another, in its order.
fn usage_examples_in_order() {
    let mut bus = demo_joint(20.0033);
    iap(&mut bus);

    // E5: status. Error 0, 23.00 V, 49.0 °C, enabled (0x0B = 1 enables at start-up),
    // brake released, 20.0033°, current as simulated.
    let r = one(&mut bus, frame(0x601, &[]));
    assert_eq!((r.raw_id(), r.len()), (0x701, 16));
    let d = r.data();
    assert_eq!(
        &d[..12],
        &[
            0x00, 0x00, 0xFC, 0x08, 0xEA, 0x01, 0x01, 0x00, 0x61, 0x0D, 0x03, 0x00
        ]
    );
    let st = bus.joint(1).unwrap().state();
    assert_eq!(le32(d, 12), (st.current_a * 1000.0).round() as i32);
    wait_ms(&mut bus, 10);

    // E6: position mode.
    exchange(
        &mut bus,
        frame(0x001, &[0x02, 0x30, 0x03]),
        0x101,
        &[0x02, 0x30, 0x01],
    );
    wait_ms(&mut bus, 10);

    // E7: 20° → 30° (a step within ±10°): feedback shows the position before the move.
    let r = one(&mut bus, frame(0x201, &[0xE0, 0x93, 0x04, 0x00]));
    assert_eq!((r.raw_id(), r.len()), (0x501, 16));
    let (_, speed, position, enable, error) = feedback(&r);
    assert_eq!((speed, position, enable, error), (0, 200_033, 1, 0));
    // "After obtaining the joint status again, the angle is within ±10° of the start."
    wait_ms(&mut bus, 3000);
    let r = one(&mut bus, frame(0x601, &[]));
    let pos = le32(r.data(), 8);
    assert!((pos - 300_000).abs() <= 20, "{pos}");
    assert!((pos - 200_033).abs() <= 100_000);

    // E8: current mode; E9: 500 mA → feedback before the command, then the joint turns
    // the positive way.
    exchange(
        &mut bus,
        frame(0x001, &[0x02, 0x30, 0x01]),
        0x101,
        &[0x02, 0x30, 0x01],
    );
    wait_ms(&mut bus, 10);
    let r = one(&mut bus, frame(0x401, &[0xF4, 0x01, 0x00, 0x00]));
    assert_eq!((r.raw_id(), r.len()), (0x501, 16));
    let (_, _, before, enable, error) = feedback(&r);
    assert_eq!((enable, error), (1, 0));
    assert!((before - 300_000).abs() <= 20);
    wait_ms(&mut bus, 200);
    let st = bus.joint(1).unwrap().state();
    assert!((st.current_a - 0.5).abs() < 0.01, "{st:?}");
    assert!(st.speed_rpm > 0.0 && st.position_deg > 30.0, "{st:?}");

    // E10: speed mode; E11: 5 RPM (2500 × 0.002) → the joint settles at 5 RPM, which the
    // feedback reports as 250 × 0.02 RPM.
    exchange(
        &mut bus,
        frame(0x001, &[0x02, 0x30, 0x02]),
        0x101,
        &[0x02, 0x30, 0x01],
    );
    wait_ms(&mut bus, 10);
    let r = one(&mut bus, frame(0x301, &[0xC4, 0x09, 0x00, 0x00]));
    assert_eq!((r.raw_id(), r.len()), (0x501, 16));
    wait_ms(&mut bus, 1000);
    let r = one(&mut bus, frame(0x301, &[0xC4, 0x09, 0x00, 0x00]));
    let (_, speed, _, enable, error) = feedback(&r);
    assert_eq!((enable, error), (1, 0));
    assert!((speed - 250).abs() <= 1, "{speed}");
    wait_ms(&mut bus, 10);

    // E12: clear error.
    exchange(
        &mut bus,
        frame(0x001, &[0x02, 0x0F, 0x01]),
        0x101,
        &[0x02, 0x0F, 0x01],
    );
    wait_ms(&mut bus, 10);
    // Back to position mode to stop, then E13: set zero → the position reads 0.
    exchange(
        &mut bus,
        frame(0x001, &[0x02, 0x30, 0x03]),
        0x101,
        &[0x02, 0x30, 0x01],
    );
    wait_ms(&mut bus, 1000);
    exchange(
        &mut bus,
        frame(0x001, &[0x02, 0x0E, 0x01]),
        0x101,
        &[0x02, 0x0E, 0x01],
    );
    wait_ms(&mut bus, 10);
    exchange(
        &mut bus,
        frame(0x001, &[0x01, 0x14, 0x02]),
        0x101,
        &[0x01, 0x14, 0x00, 0x00, 0x00, 0x00],
    );
    wait_ms(&mut bus, 10);

    // E14: enable and disable, both acknowledged with status 1.
    exchange(
        &mut bus,
        frame(0x001, &[0x02, 0x0A, 0x01]),
        0x101,
        &[0x02, 0x0A, 0x01],
    );
    wait_ms(&mut bus, 10);
    exchange(
        &mut bus,
        frame(0x001, &[0x02, 0x0A, 0x00]),
        0x101,
        &[0x02, 0x0A, 0x01],
    );
    wait_ms(&mut bus, 10);
    let st = bus.joint(1).unwrap().state();
    assert!(!st.enabled && st.brake_locked);

    // Low-power, end-effector and time-sharing power-on registers (FW ≥ 519, WHJ30).
    for addr in [0x69, 0x79, 0x1F] {
        exchange(
            &mut bus,
            frame(0x001, &[0x02, addr, 0x01]),
            0x101,
            &[0x02, addr, 0x01],
        );
        wait_ms(&mut bus, 10);
        exchange(
            &mut bus,
            frame(0x001, &[0x01, addr, 0x01]),
            0x101,
            &[0x01, addr, 0x01, 0x00],
        );
        wait_ms(&mut bus, 10);
    }
}

#[test]
fn demo_status_bytes_can_be_reproduced_exactly() {
    // With a load that makes the holding current -6 mA (as in the demo), every byte of
    // the status reply equals the demo's.
    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.initial_position_deg = 20.0033;
    cfg.supply_voltage_v = 23.0;
    cfg.supply_resistance_ohm = 0.0;
    cfg.ambient_temp_c = 49.0;
    // Without static friction the position loop holds a constant load with exactly the
    // current that balances it.
    cfg.params.coulomb_friction_nm = 0.0;
    cfg.load.constant_nm = 0.006 * cfg.params.torque_constant();
    let mut bus = WhjBus::with_configs([cfg], 1);
    iap(&mut bus);
    wait_ms(&mut bus, 2000);
    let r = one(&mut bus, frame(0x601, &[]));
    let d = r.data();
    assert_eq!(&d[..8], &[0x00, 0x00, 0xFC, 0x08, 0xEA, 0x01, 0x01, 0x00]);
    assert_eq!(&d[12..16], &[0xFA, 0xFF, 0xFF, 0xFF], "{r:?}");
    assert!((le32(d, 8) - 200_033).abs() <= 1, "{r:?}");
}
