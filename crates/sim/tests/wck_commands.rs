//! Every command of the manual's appendix A-1, sent as the manual's example packet (with
//! the four misprinted checksums corrected, see the wCK protocol notes), answered byte for
//! byte as a module does.
#![allow(clippy::unwrap_used)] // test helpers

use crate::wck_support;

use core::time::Duration;

use robobus_sim::wck::{Mode, Model};
use wck_support::host;

const T: Duration = Duration::from_millis(200);

/// Reply of a fresh module (ID 0, shaft at rest at 127, defaults) to `packet`.
fn fresh(packet: &[u8], n: usize) -> Vec<u8> {
    let mut h = host(Model::W1108, &[0]);
    h.transact(packet, n, T)
}

/// High-resolution reading of the shaft at standard position 127, split H3/L7.
fn pos10_of_127() -> [u8; 2] {
    let deg: f64 = 127.0 * 269.0 / 255.0;
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let p = (deg / (333.0 / 1023.0)).round() as u16;
    [
        u8::try_from(p >> 7).unwrap(),
        u8::try_from((p & 0x7F) << 1).unwrap(),
    ]
}

#[test]
fn a1_1_position_move_replies_load_and_position_before_moving() {
    assert_eq!(fresh(&[0xFF, 0x00, 0x7F, 0x7F], 2), [0x00, 0x7F]);
    let mut h = host(Model::W1108, &[0]);
    assert_eq!(h.transact(&[0xFF, 0x00, 0xC8, 0x48], 2, T), [0x00, 0x7F]);
    h.sleep(Duration::from_millis(30));
    // Moving now: it draws current, so the load byte is above zero.
    let reply = h.transact(&[0xFF, 0xA0, 0x00, 0x20], 2, T);
    assert!(reply[0] > 0 && reply[1] > 127, "{reply:?}");
}

#[test]
fn a1_2_synchronized_move_has_no_reply_and_moves_each_id() {
    let mut h = host(Model::W1108, &[0, 1]);
    assert!(
        h.transact(&[0xFF, 0x1F, 0x02, 0x64, 0x96, 0x64 ^ 0x96 & 0x7F], 2, T)
            .is_empty()
    );
    h.sleep(Duration::from_millis(500));
    assert_eq!(h.bus().servo(0).unwrap().position(), 0x64);
    assert_eq!(h.bus().servo(1).unwrap().position(), 0x96);
}

#[test]
fn a1_3_status_read() {
    assert_eq!(fresh(&[0xFF, 0xA0, 0x00, 0x20], 2), [0x00, 0x7F]);
}

#[test]
fn a1_4_passive() {
    let mut h = host(Model::W1108, &[0]);
    h.transact(&[0xFF, 0x00, 0x7F, 0x7F], 2, T);
    assert_eq!(h.bus().servo(0).unwrap().mode(), Mode::Position);
    assert_eq!(h.transact(&[0xFF, 0xC0, 0x10, 0x50], 2, T), [0x10, 0x7F]);
    assert_eq!(h.bus().servo(0).unwrap().mode(), Mode::Passive);
}

#[test]
fn a1_5_wheel_replies_rotation_count_and_position() {
    assert_eq!(fresh(&[0xFF, 0xC0, 0x3F, 0x7F], 2), [0x00, 0x7F]);
}

#[test]
fn a1_6_break() {
    let mut h = host(Model::W1108, &[0]);
    assert_eq!(h.transact(&[0xFF, 0xDF, 0x20, 0x7F], 2, T), [0x00, 0x7F]);
    assert_eq!(h.bus().servo(0).unwrap().mode(), Mode::Break);
}

#[test]
fn a1_7_baud_set_echoes_the_new_code() {
    // The manual prints 03 03 for this example; the reply echoes the new code.
    assert_eq!(
        fresh(&[0xFF, 0xE0, 0x08, 0x07, 0x07, 0x68], 2),
        [0x07, 0x07]
    );
}

#[test]
fn a1_8_9_gain_set_and_read() {
    let mut h = host(Model::W1108, &[0]);
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x0A, 0x00, 0x00, 0x6A], 2, T),
        [20, 30]
    );
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x09, 0x64, 0x64, 0x69], 2, T),
        [0x64, 0x64]
    );
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x0A, 0x00, 0x00, 0x6A], 2, T),
        [0x64, 0x64]
    );
}

#[test]
fn a1_10_11_i_gain_set_and_read() {
    let mut h = host(Model::W1108, &[0]);
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x16, 0x00, 0x00, 0x76], 2, T),
        [0, 0]
    );
    // The manual's example sets 100 although it recommends 0..=10.
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x15, 0x64, 0x64, 0x75], 2, T),
        [0x64, 0x64]
    );
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x16, 0x00, 0x00, 0x76], 2, T),
        [0x64, 0x64]
    );
}

#[test]
fn a1_12_runtime_gain_set() {
    // Checksum 0x6B (the manual misprints 0x69).
    assert_eq!(
        fresh(&[0xFF, 0xE0, 0x0B, 0x64, 0x64, 0x6B], 2),
        [0x64, 0x64]
    );
}

#[test]
fn a1_13_runtime_i_gain_set() {
    assert_eq!(
        fresh(&[0xFF, 0xE0, 0x18, 0x04, 0x04, 0x78], 2),
        [0x04, 0x04]
    );
}

#[test]
fn a1_14_id_set() {
    let mut h = host(Model::W1108, &[0]);
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x0C, 0x1E, 0x1E, 0x6C], 2, T),
        [0x1E, 0x1E]
    );
    assert_eq!(h.bus().servo(0).unwrap().id().get(), 30);
}

#[test]
fn a1_15_16_17_speed_set_read_and_runtime_set() {
    let mut h = host(Model::W1108, &[0]);
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x0E, 0x00, 0x00, 0x6E], 2, T),
        [0, 60]
    );
    // Checksum 0x17 (the manual misprints 0x1D).
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x0D, 0x1E, 0x64, 0x17], 2, T),
        [0x1E, 0x64]
    );
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x0E, 0x00, 0x00, 0x6E], 2, T),
        [0x1E, 0x64]
    );
    // Runtime speed set: no reply at all.
    let sent = [
        0xFF,
        0xE0,
        0x17,
        0x0A,
        0x14,
        (0xE0 ^ 0x17 ^ 0x0A ^ 0x14) & 0x7F,
    ];
    assert!(h.transact(&sent, 2, T).is_empty());
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x0E, 0x00, 0x00, 0x6E], 2, T),
        [0x0A, 0x14]
    );
    // The manual's own runtime example.
    assert!(
        h.transact(&[0xFF, 0xE0, 0x17, 0x1E, 0x64, 0x0D], 2, T)
            .is_empty()
    );
}

#[test]
fn a1_18_19_overload_set_and_read() {
    let mut h = host(Model::W1108, &[0]);
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x10, 0x00, 0x00, 0x70], 2, T),
        [33, 33]
    );
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x0F, 0x68, 0x68, 0x6F], 2, T),
        [0x68, 0x68]
    );
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x10, 0x00, 0x00, 0x70], 2, T),
        [0x68, 0x68]
    );
}

#[test]
fn a1_20_21_boundary_set_and_read() {
    let mut h = host(Model::W1108, &[0]);
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x12, 0x00, 0x00, 0x72], 2, T),
        [1, 254]
    );
    // The manual's example (lower 100 > upper 50, printed checksum 0x20, correct 0x27) is
    // refused by the decoder: no reply, nothing changes.
    assert!(
        h.transact(&[0xFF, 0xE0, 0x11, 0x64, 0x32, 0x27], 2, T)
            .is_empty()
    );
    let set = [
        0xFF,
        0xE0,
        0x11,
        0x32,
        0x64,
        (0xE0 ^ 0x11 ^ 0x32 ^ 0x64) & 0x7F,
    ];
    assert_eq!(h.transact(&set, 2, T), [0x32, 0x64]);
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x12, 0x00, 0x00, 0x72], 2, T),
        [0x32, 0x64]
    );
}

#[test]
fn a1_22_23_io_write_and_read() {
    let mut h = host(Model::W1108, &[0]);
    h.bus_mut().servo_mut(0).unwrap().set_adc(0xA5);
    // Checksum 0x05 (the manual misprints 0x04).
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x65, 0x00, 0x00, 0x05], 2, T),
        [0x00, 0xA5]
    );
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x64, 0x03, 0x03, 0x04], 2, T),
        [0x03, 0x03]
    );
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x65, 0x00, 0x00, 0x05], 2, T),
        [0x03, 0xA5]
    );
    assert!(h.bus().servo(0).unwrap().outputs().do2());
}

#[test]
fn a1_24_25_motion_data_write_and_read() {
    let mut h = host(Model::W1108, &[0]);
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x97, 0x00, 0x00, 0x77], 2, T),
        [0, 0]
    );
    let write = [
        0xFF, 0xE0, 0x96, 0x04, 0x10, 0x52, 0x31, 0x0A, 0x10, 0xAC, 0x31, 0x0A, 0x0C,
    ];
    assert_eq!(h.transact(&write, 2, T), [0x04, 0x04]);
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0x97, 0x00, 0x00, 0x77], 2, T),
        [0x04, 0x04]
    );
    assert!(h.bus().servo(0).unwrap().program_running());
}

#[test]
fn a1_26_27_ten_bit_move_and_read() {
    let mut h = host(Model::W1108, &[0]);
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0xC9, 0x00, 0x00, 0x29], 2, T),
        pos10_of_127()
    );
    // Move to 1000: beyond the default upper boundary 254 (268 degrees), so it stops there.
    assert_eq!(
        h.transact(&[0xFF, 0xE0, 0xC8, 0x00, 0x00, 0x07, 0xD0, 0x7F], 2, T),
        pos10_of_127()
    );
    h.sleep(Duration::from_secs(1));
    let reply = h.transact(&[0xFF, 0xE0, 0xC9, 0x00, 0x00, 0x29], 2, T);
    let p = (u16::from(reply[0]) << 7) | u16::from(reply[1] >> 1);
    let upper_deg = 254.0 * 269.0 / 255.0;
    let p_deg = f64::from(p) * 333.0 / 1023.0;
    assert!((p_deg - upper_deg).abs() < 1.0, "{p} = {p_deg} deg");
}

#[test]
fn other_ids_stay_silent() {
    let mut h = host(Model::W1108, &[0]);
    // Status read of ID 1, and of ID 0 with a wrong checksum.
    assert!(h.transact(&[0xFF, 0xA1, 0x00, 0x21], 2, T).is_empty());
    assert!(h.transact(&[0xFF, 0xA0, 0x00, 0x21], 2, T).is_empty());
    assert_eq!(h.bus().stats().decode_errors, 1);
}
