//! The broadcast protocol V1.1 with seven joints: 0x7F status, 0x2F position, 0x4F
//! current, 0x0F register R/W, reply masks, reply IDs and their arbitration order, the
//! receive counter, and the 20 ms communication watchdog: on the virtual clock.

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

use std::time::Duration;

use robobus_sim::whj::{BroadcastReadReply, JointConfig, WhjBus, WhjModel};
use whj_common::{frame, wait_ms, write1};

/// Seven WHJ30 joints at 10°, 20°, … 70°, started.
fn arm() -> WhjBus {
    let cfgs = (1..=7).map(|id| {
        let mut c = JointConfig::new(id, WhjModel::Whj30);
        c.initial_position_deg = f64::from(id) * 10.0;
        c
    });
    let mut bus = WhjBus::with_configs(cfgs, 3).with_trace();
    for id in 1..=7 {
        write1(&mut bus, id, 0x49, 0, 1);
    }
    wait_ms(&mut bus, 1);
    bus
}

fn status_frame(mask: u8) -> robobus_whj::CanFrame {
    let mut d = [0u8; 24];
    d[23] = mask;
    frame(0x7F, &d)
}

fn position_frame(targets: [Option<i32>; 7], flags: u8) -> robobus_whj::CanFrame {
    let mut d = [0xFFu8; 64];
    for (i, t) in targets.iter().enumerate() {
        if let Some(t) = t {
            d[8 * i..8 * i + 4].copy_from_slice(&t.to_le_bytes());
            d[8 * i + 4..8 * i + 8].fill(0);
        } else {
            d[8 * i..8 * i + 8].copy_from_slice(&[0xFF, 0xFF, 0xFF, 0x7F, 0xFF, 0xFF, 0xFF, 0xFF]);
        }
    }
    d[63] = flags;
    frame(0x2F, &d)
}

fn ids(replies: &[robobus_sim::whj::Delivered]) -> Vec<u32> {
    replies.iter().map(|r| r.frame.raw_id()).collect()
}

#[test]
fn status_query_all_joints_in_arbitration_order() {
    let mut bus = arm();
    let replies = bus.request(status_frame(0x0F));
    // All seven become ready together; the lowest ID wins each round, joint 6 (0x5FE) last.
    assert_eq!(
        ids(&replies),
        vec![0x82, 0x83, 0x84, 0x85, 0x86, 0x88, 0x5FE]
    );
    for r in &replies {
        let d = r.frame.data();
        assert_eq!(d.len(), 24);
        let joint = match r.frame.raw_id() {
            0x5FE => 6,
            id => id - 0x81,
        };
        let pos = i32::from_le_bytes(d[8..12].try_into().unwrap());
        assert_eq!(pos, joint as i32 * 100_000);
        assert_eq!(i16::from_le_bytes([d[14], d[15]]), 2400);
        assert_eq!(d[18], 0x01, "enabled, brake released");
        assert_eq!(d[23], 1, "counter after the first broadcast frame");
    }
    // Back-to-back on the wire.
    let t = bus.trace();
    for w in t.windows(2).skip(t.len() - 7) {
        assert!(
            w[1].start >= w[0].end && w[1].start - w[0].end <= Duration::from_micros(3),
            "{w:?}"
        );
    }
}

#[test]
fn reply_masks_select_joints() {
    let mut bus = arm();
    for (mask, expected) in [
        (0x0, vec![]),
        (0x1, vec![0x82, 0x83, 0x84, 0x85]),
        (0x2, vec![0x86, 0x88, 0x5FE]),
        (0x3, vec![0x82, 0x83]),
        (0x4, vec![0x84, 0x85]),
        (0x5, vec![0x86, 0x5FE]),
        (0x6, vec![0x88]),
        (0x7, vec![0x82]),
        (0xC, vec![0x5FE]),
        (0xD, vec![0x88]),
        (0xE, vec![]),
    ] {
        assert_eq!(
            ids(&bus.request(status_frame(mask))),
            expected,
            "mask {mask:#x}"
        );
    }
    // Eleven frames so far: every joint counted them all, selected or not.
    let r = bus.request(status_frame(0x7));
    assert_eq!(r[0].frame.data()[23], 12);
    // 0x4E reads the counter; writing it sets it.
    assert_eq!(whj_common::read(&mut bus, 3, 0x4E, 1), vec![12]);
    write1(&mut bus, 3, 0x4E, 0, 1);
    assert_eq!(whj_common::read(&mut bus, 3, 0x4E, 1), vec![0]);
}

#[test]
fn position_frame_moves_the_joints_with_data() {
    let mut bus = arm();
    let mut targets = [None; 7];
    targets[0] = Some(150_000); // J1 10° → 15°
    targets[6] = Some(650_000); // J7 70° → 65°
    let replies = bus.request(position_frame(targets, 0x0F));
    assert_eq!(replies.len(), 7);
    // Feedback shows the state before the command.
    assert_eq!(
        i32::from_le_bytes(replies[0].frame.data()[8..12].try_into().unwrap()),
        100_000
    );
    wait_ms(&mut bus, 5);
    // Keep streaming (the watchdog would stop them after 20 ms).
    for _ in 0..1000 {
        bus.request(position_frame(targets, 0x00));
        wait_ms(&mut bus, 1);
    }
    let pos = |bus: &WhjBus, id| bus.joint(id).unwrap().state().position_deg;
    assert!((pos(&bus, 1) - 15.0).abs() < 1e-3);
    assert!((pos(&bus, 7) - 65.0).abs() < 1e-3);
    assert!((pos(&bus, 3) - 30.0).abs() < 1e-9, "no data: target kept");
    // The step check applies to broadcast targets too.
    targets[0] = Some(300_000);
    bus.request(position_frame(targets, 0x00));
    assert_eq!(bus.joint(1).unwrap().state().error.bits(), 0x4000);
}

#[test]
fn disabled_joint_returns_only_its_status() {
    let mut bus = arm();
    write1(&mut bus, 2, 0x0A, 0, 1);
    wait_ms(&mut bus, 6);
    let mut targets = [None; 7];
    targets[1] = Some(210_000);
    let r = bus.request(position_frame(targets, 0x08));
    assert_eq!(ids(&r), vec![0x83]);
    assert_eq!(r[0].frame.data()[18], 0x80, "disabled, brake locked");
    wait_ms(&mut bus, 200);
    assert_eq!(bus.joint(2).unwrap().state().position_deg, 20.0);
}

#[test]
fn watchdog_stops_a_broken_stream_after_20_ms() {
    let mut bus = arm();
    let mut targets = [None; 7];
    // J1 streams a hold at 10°, then one last 5° step, then the host goes silent.
    targets[0] = Some(100_000);
    for _ in 0..100 {
        bus.request(position_frame(targets, 0x00));
        wait_ms(&mut bus, 1);
    }
    let t = 150_000;
    targets[0] = Some(t);
    bus.request(position_frame(targets, 0x00));
    // 19 ms later: still heading for the streamed target.
    wait_ms(&mut bus, 19);
    assert_eq!(bus.joint(1).unwrap().state().target_position, t);
    // After 20 ms without a frame: target := actual, still enabled, no error; it stops
    // short of the last target.
    wait_ms(&mut bus, 2);
    let st = bus.joint(1).unwrap().state();
    assert!(st.enabled && st.error.is_empty());
    assert!(
        st.target_position > 100_000 && st.target_position < t,
        "{st:?}"
    );
    wait_ms(&mut bus, 1000);
    let st = bus.joint(1).unwrap().state();
    assert!(st.position_deg < 14.9 && st.speed_rpm == 0.0, "{st:?}");
    // Joints that never got data were never armed.
    assert_eq!(bus.joint(2).unwrap().state().target_position, 200_000);
}

#[test]
fn current_frame_sets_current_targets() {
    let mut bus = arm();
    write1(&mut bus, 4, 0x30, 1, 1);
    let mut d = [0xFFu8; 48];
    for i in 0..7 {
        d[4 * i..4 * i + 4].copy_from_slice(&[0xFF, 0xFF, 0xFF, 0x7F]);
    }
    d[12..16].copy_from_slice(&500i32.to_le_bytes()); // J4: 500 mA
    d[47] = 0x0A;
    let r = bus.request(frame(0x4F, &d));
    assert_eq!(ids(&r), vec![0x85]);
    wait_ms(&mut bus, 20);
    let st = bus.joint(4).unwrap().state();
    assert!(
        (st.current_a - 0.5).abs() < 1e-9 && st.speed_rpm > 0.0,
        "{st:?}"
    );
}

#[test]
fn register_frame_reads_and_writes() {
    let mut bus = arm();
    // V1.1 example: J1 writes mode 3 (1 data byte) → 0xF2: 02 30 01.
    let mut d = [0xFFu8; 64];
    d[..7].copy_from_slice(&[0x03, 0x02, 0x30, 0x03, 0xFF, 0xFF, 0xFF]);
    // J6 reads 2 registers from 0x14 (client form [04 01 idx cnt 00 FF FF]).
    d[35..42].copy_from_slice(&[0x04, 0x01, 0x14, 0x02, 0x00, 0xFF, 0xFF]);
    // J3 writes 0x31 := 7 (2 data bytes).
    d[14..21].copy_from_slice(&[0x04, 0x02, 0x31, 0x07, 0x00, 0xFF, 0xFF]);
    // Mask 7: only J1 answers; J3 and J6 still execute their slots.
    d[63] = 0x07;
    let r = bus.request(frame(0x0F, &d));
    assert_eq!(ids(&r), vec![0xF2]);
    assert_eq!(r[0].frame.data(), &[0x02, 0x30, 0x01]);
    assert_eq!(whj_common::read(&mut bus, 3, 0x31, 1), vec![7]);

    d[63] = 0x0F;
    let r = bus.request(frame(0x0F, &d));
    assert_eq!(ids(&r), vec![0xF2, 0xF4, 0x3FE]);
    assert_eq!(r[1].frame.data(), &[0x02, 0x31, 0x01]);
    assert_eq!(r[2].frame.data(), &[0x01, 0x14, 0xC0, 0x27, 0x09, 0x00]); // 60°

    // GRIP's length-prefixed read reply is an option (C19).
    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.broadcast_read_reply = BroadcastReadReply::LengthPrefixed;
    let mut bus = whj_common::started(cfg);
    let mut d = [0xFFu8; 64];
    d[..7].copy_from_slice(&[0x04, 0x01, 0x00, 0x01, 0xFF, 0xFF, 0xFF]);
    d[63] = 0x07;
    let r = bus.request(frame(0x0F, &d));
    assert_eq!(r[0].frame.data(), &[0x04, 0x01, 0x00, 0x14, 0x13]);
}

#[test]
fn watchdog_options() {
    // Guarding point-to-point 0x200 streams too.
    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.watchdog.guard_point_to_point = true;
    let mut bus = whj_common::started(cfg);
    bus.request(whj_common::pos_cmd(1, 50_000));
    wait_ms(&mut bus, 25);
    let st = bus.joint(1).unwrap().state();
    assert!(st.target_position < 50_000 && st.enabled, "{st:?}");

    // Guarding 0x4F current streams: on expiry the current target goes to 0.
    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.watchdog.guard_broadcast_current = true;
    let mut bus = whj_common::started(cfg);
    write1(&mut bus, 1, 0x30, 1, 1);
    let mut d = [0xFFu8; 48];
    for i in 1..7 {
        d[4 * i..4 * i + 4].copy_from_slice(&[0xFF, 0xFF, 0xFF, 0x7F]);
    }
    d[..4].copy_from_slice(&300i32.to_le_bytes());
    d[47] = 0x07;
    bus.request(frame(0x4F, &d));
    wait_ms(&mut bus, 19);
    assert_eq!(bus.joint(1).unwrap().state().target_current, 300);
    wait_ms(&mut bus, 2);
    assert_eq!(bus.joint(1).unwrap().state().target_current, 0);

    // Default: a point-to-point stream is not guarded.
    let mut bus = whj_common::joint1_at(WhjModel::Whj30, 0.0);
    bus.request(whj_common::pos_cmd(1, 50_000));
    wait_ms(&mut bus, 25);
    assert_eq!(bus.joint(1).unwrap().state().target_position, 50_000);
}

#[test]
fn joints_without_a_slot_ignore_broadcast_frames() {
    let mut bus = WhjBus::with_configs([JointConfig::new(9, WhjModel::Whj30).without_iap()], 1);
    assert!(bus.request(status_frame(0x0F)).is_empty());
    let mut targets = [None; 7];
    targets[0] = Some(10_000);
    assert!(bus.request(position_frame(targets, 0x0F)).is_empty());
    assert_eq!(bus.joint(9).unwrap().state().target_position, 0);
}

#[test]
fn firmware_before_the_broadcast_gate_ignores_broadcast_frames() {
    // Joints 1 and 2 on D4FF (before D5.XX), joint 3 on the multi-turn line E200, the
    // rest on the simulator's default: the register table's broadcast gate decides.
    let cfgs = (1..=7).map(|id| {
        let mut c = JointConfig::new(id, WhjModel::Whj30);
        c.firmware = robobus_whj::units::FirmwareVersion(match id {
            1 | 2 => 0xD4FF,
            3 => 0xE200,
            _ => 0xD522,
        });
        c
    });
    let mut bus = WhjBus::with_configs(cfgs, 3);
    for id in 1..=7 {
        write1(&mut bus, id, 0x49, 0, 1);
    }
    wait_ms(&mut bus, 1);
    let replies = bus.request(status_frame(0x0F));
    assert_eq!(ids(&replies), vec![0x84, 0x85, 0x86, 0x88, 0x5FE]);
    let targets = [Some(0), Some(0), None, None, None, None, None];
    // Mask 0x1 asks joints 1..=4 for feedback: only the two with broadcast firmware answer.
    let replies = bus.request(position_frame(targets, 0x01));
    assert_eq!(ids(&replies), vec![0x84, 0x85]);
}

#[test]
fn the_end_board_answers_its_field_when_the_mask_selects_it() {
    let mut bus = arm().with_end_board();
    // The worked example: 0x7F `02 07 01 03 00…`, mask E (tool power := 24 V) -> 0x87
    // `counter 00 00 00 00 02 07 01 01`; no joint answers.
    let mut d = [0u8; 24];
    d[..4].copy_from_slice(&[2, 7, 1, 3]);
    d[23] = 0x0E;
    let r = bus.request(frame(0x7F, &d));
    assert_eq!(ids(&r), [0x87]);
    assert_eq!(r[0].frame.data()[1..9], [0, 0, 0, 0, 2, 7, 1, 1]);
    assert_eq!(r[0].frame.data()[0], 1);
    assert_eq!(bus.end_board().unwrap().register(7), 3);
    // 0x0F with D50.. `02 1D 01 01` (IO1 := output), mask F: seven joints stay silent (no
    // operation in their slots), the end board answers on 0xF7 with status0 bit 7 set.
    let mut d = [0xFFu8; 64];
    d[50..54].copy_from_slice(&[2, 0x1D, 1, 1]);
    d[63] = 0x0F;
    let r = bus.request(frame(0x0F, &d));
    assert_eq!(ids(&r), [0xF7]);
    assert_eq!(r[0].frame.data()[..9], [2, 0x80, 0, 0, 0, 2, 0x1D, 1, 1]);
    // A read of the software version with J1 reading its temperature: both answer.
    let mut d = [0xFFu8; 64];
    d[..7].copy_from_slice(&[4, 1, 0x06, 1, 0, 0xFF, 0xFF]);
    d[50..53].copy_from_slice(&[1, 0x03, 1]);
    d[63] = 0x0F;
    let r = bus.request(frame(0x0F, &d));
    assert_eq!(ids(&r), [0xF2, 0xF7]);
    assert_eq!(r[1].frame.data()[5..10], [1, 3, 2, 0x03, 0x02]);
    // A write to a read-only register fails and changes nothing; mask 7 (J1 only) keeps
    // the end board silent, but it still counts the frame.
    let mut d = [0xFFu8; 64];
    d[50..54].copy_from_slice(&[2, 0x03, 1, 9]);
    d[63] = 0x0E;
    let r = bus.request(frame(0x0F, &d));
    assert_eq!(r[0].frame.data()[5..9], [2, 3, 1, 0]);
    assert_eq!(bus.end_board().unwrap().register(3), 0x0203);
    let r = bus.request(status_frame(7));
    assert_eq!(ids(&r), [0x82]);
    assert_eq!(bus.end_board().unwrap().counter(), 5);
}
