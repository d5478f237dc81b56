//! Memory table, access rights, `CMD_ERR`, write forms, flash persistence, power-up (IAP,
//! staggered start), ID change: on the virtual clock.

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

use robobus_sim::whj::{JointConfig, Phase, WhjBus, WhjModel};
use robobus_whj::REGISTERS;
use robobus_whj::registers::{Access, Half, Persistence};
use whj_common::{
    exchange, frame, one, read, read_i32, silent, started, wait_ms, write1, write2, write4,
};

#[test]
fn initial_values_follow_the_register_table() {
    let mut bus = started(JointConfig::new(1, WhjModel::Whj30));
    for info in &REGISTERS {
        let a = info.addr.get();
        // Overrides documented in §10: bit-rate registers say 1M/5M (C11).
        let expected = match a {
            0x08 => Some(2),
            0x09 => Some(5),
            // 0x0A reads the live enable state: 0x0B = 1 enabled the joint at start-up.
            0x0A => Some(1),
            _ if matches!(info.persistence, Persistence::Live) => continue,
            _ => info.init,
        };
        let Some(expected) = expected else { continue };
        let words = read(&mut bus, 1, a, 1);
        // A pair's initial value is the i32 on its low word.
        let want = if info.half == Half::High {
            let low = REGISTERS
                .iter()
                .find(|r| r.addr.get() == a - 1)
                .and_then(|r| r.init)
                .unwrap_or(0);
            (low >> 16) as u16
        } else {
            (expected & 0xFFFF) as u16
        };
        assert_eq!(words[0], want, "register {a:#04x} {}", info.name);
    }
}

#[test]
fn identity_registers_per_model() {
    for (model, code, ratio) in [
        (WhjModel::Whj03, 0x07, 100),
        (WhjModel::Whj10B, 0x02, 80),
        (WhjModel::Whj30, 0x03, 80),
        (WhjModel::Whj60, 0x04, 100),
        (WhjModel::Whj120, 0x05, 100),
    ] {
        let mut cfg = JointConfig::new(1, model);
        cfg.unique_id = [1, 2, 3, 4, 5, 6];
        let mut bus = started(cfg);
        let w = read(&mut bus, 1, 0x00, 8);
        assert_eq!(&w[..4], &[0x1314, 1, code, 0xD522], "{model}");
        assert_eq!(w[7], ratio, "{model}");
        assert_eq!(read(&mut bus, 1, 0x2A, 6), vec![1, 2, 3, 4, 5, 6]);
        // Limits: ±360° in 0.0001°.
        assert_eq!(read_i32(&mut bus, 1, 0x44), -3_600_000);
        assert_eq!(read_i32(&mut bus, 1, 0x46), 3_600_000);
        assert_eq!(read_i32(&mut bus, 1, 0x4B), 300_000);
    }
}

#[test]
fn multi_register_read_is_one_snapshot_padded() {
    let mut bus = whj_common::joint1_at(WhjModel::Whj30, 12.5);
    // GRIP's read: 6 registers from 0x10 (current, speed, position) = 14 B, padded to 16.
    let r = one(&mut bus, frame(0x001, &[0x01, 0x10, 0x06]));
    assert_eq!(r.len(), 16);
    assert_eq!(&r.data()[14..], &[0, 0]);
    let pos = i32::from_le_bytes([r.data()[10], r.data()[11], r.data()[12], r.data()[13]]);
    assert_eq!(pos, 125_000);
    // The maximum of 31 registers fills a 64-byte frame; reserved addresses read 0.
    let w = read(&mut bus, 1, 0x16, 31);
    assert_eq!(w.len(), 31);
    assert_eq!(&w[..2], &[0, 0]);
}

#[test]
fn cmd_err_format_and_permission() {
    let mut bus = started(JointConfig::new(1, WhjModel::Whj30));
    let format = [0xFF, 0x01];
    let permission = [0xFF, 0x02];
    // Unknown command, too short, bad write length, count 0, past the end, bad address.
    for bad in [
        &[0x05, 0x30, 0x00][..],
        &[0x01, 0x14][..],
        &[0x02, 0x30, 0x01, 0x00, 0x00][..],
        &[0x01, 0x14, 0x00][..],
        &[0x01, 0x90, 0x05][..],
        &[0x01, 0x92, 0x01][..],
        &[0x01, 0x14, 0x20][..],
    ] {
        exchange(&mut bus, frame(0x001, bad), 0x101, &format);
    }
    // Read-only registers: permission error, nothing written.
    for info in REGISTERS.iter().filter(|r| r.access == Access::ReadOnly) {
        exchange(
            &mut bus,
            frame(0x001, &[0x02, info.addr.get(), 0x00, 0x00]),
            0x101,
            &permission,
        );
    }
    assert_eq!(read(&mut bus, 1, 0x02, 1), vec![0x03]);
    // A 4-byte write whose second word is read-only is refused as a whole.
    exchange(
        &mut bus,
        frame(0x001, &[0x02, 0x03, 0, 0, 0, 0]),
        0x101,
        &permission,
    );
    // Other joints stay silent; a frame to node 0 is ignored.
    silent(&mut bus, frame(0x002, &[0x05]));
    silent(&mut bus, frame(0x000, &[0x01, 0x14, 0x02]));
}

#[test]
fn cmd_err_code_is_an_option() {
    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.cmd_err_code = 0xEE;
    let mut bus = started(cfg);
    exchange(
        &mut bus,
        frame(0x001, &[0x07, 0x30, 0x00]),
        0x101,
        &[0xEE, 0x01],
    );
}

#[test]
fn reserved_and_invalid_values_are_acked_failed() {
    let mut bus = started(JointConfig::new(1, WhjModel::Whj30));
    write2(&mut bus, 1, 0x16, 5, 0); // reserved
    write1(&mut bus, 1, 0x0E, 2, 0); // flag with a value other than 0/1
    write1(&mut bus, 1, 0x30, 4, 0); // work mode 4
    write1(&mut bus, 1, 0x01, 0, 0); // ID 0
    write1(&mut bus, 1, 0x01, 31, 0); // ID 31
    assert_eq!(read(&mut bus, 1, 0x30, 1), vec![3]);
    assert_eq!(read(&mut bus, 1, 0x16, 1), vec![0]);
}

#[test]
fn write_forms_one_two_four_bytes() {
    let mut bus = started(JointConfig::new(1, WhjModel::Whj30));
    write1(&mut bus, 1, 0x31, 42, 1);
    assert_eq!(read(&mut bus, 1, 0x31, 1), vec![42]);
    write2(&mut bus, 1, 0x41, 0x0BB8 - 1000, 1);
    assert_eq!(read(&mut bus, 1, 0x41, 1), vec![2000]);
    write4(&mut bus, 1, 0x44, -900_000, 1);
    assert_eq!(read_i32(&mut bus, 1, 0x44), -900_000);
    // Separate L and H writes apply one at a time (a torn value in between).
    write2(&mut bus, 1, 0x32, 0xFFFF, 1);
    assert_eq!(read_i32(&mut bus, 1, 0x32), 0xFFFF);
    write2(&mut bus, 1, 0x33, 0xFFFF, 1);
    assert_eq!(read_i32(&mut bus, 1, 0x32), -1);
}

#[test]
fn save_only_while_disabled_then_busy_and_persistent() {
    let mut bus = started(JointConfig::new(1, WhjModel::Whj30));
    write2(&mut bus, 1, 0x41, 1500, 1); // flash class
    write1(&mut bus, 1, 0x31, 10, 1); // RAM class
    // Enabled (0x0B = 1 at start-up): save refused.
    write1(&mut bus, 1, 0x0C, 1, 0);
    write1(&mut bus, 1, 0x0A, 0, 1);
    wait_ms(&mut bus, 6);
    write1(&mut bus, 1, 0x0C, 1, 1);
    // Busy for 50 ms: frames are dropped.
    wait_ms(&mut bus, 49);
    silent(&mut bus, frame(0x001, &[0x01, 0x41, 0x01]));
    wait_ms(&mut bus, 2);
    assert_eq!(read(&mut bus, 1, 0x41, 1), vec![1500]);
    assert_eq!(
        read(&mut bus, 1, 0x0C, 1),
        vec![0],
        "the flag clears itself"
    );
    // Changed after the save: lost at the power cycle.
    write2(&mut bus, 1, 0x42, 1234, 1);
    bus.power_cycle_all();
    silent(&mut bus, frame(0x001, &[0x01, 0x41, 0x01]));
    write1(&mut bus, 1, 0x49, 0, 1);
    assert_eq!(read(&mut bus, 1, 0x41, 1), vec![1500]);
    assert_eq!(read(&mut bus, 1, 0x42, 1), vec![5000]);
    assert_eq!(read(&mut bus, 1, 0x31, 1), vec![0]);
}

#[test]
fn quiet_five_ms_after_disable() {
    let mut bus = started(JointConfig::new(1, WhjModel::Whj30));
    write1(&mut bus, 1, 0x0A, 0, 1);
    wait_ms(&mut bus, 4);
    silent(&mut bus, frame(0x601, &[]));
    wait_ms(&mut bus, 2);
    assert_eq!(one(&mut bus, frame(0x601, &[])).raw_id(), 0x701);

    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.strict_settle = false;
    let mut bus = started(cfg);
    write1(&mut bus, 1, 0x0A, 0, 1);
    assert_eq!(one(&mut bus, frame(0x601, &[])).raw_id(), 0x701);
}

#[test]
fn bootloader_answers_only_the_iap_flag() {
    let mut bus = WhjBus::with_configs([JointConfig::new(1, WhjModel::Whj30)], 1);
    assert!(matches!(
        bus.joint(1).unwrap().phase(),
        Phase::Bootloader { .. }
    ));
    silent(&mut bus, frame(0x601, &[]));
    silent(&mut bus, frame(0x201, &[0, 0, 0, 0]));
    silent(&mut bus, frame(0x001, &[0x02, 0x0A, 0x01]));
    // IAP_FLAG := 1 is acknowledged but stays in the bootloader; := 0 starts the application
    // (the 2-byte form from PHX/LICH works too).
    write1(&mut bus, 1, 0x49, 1, 1);
    silent(&mut bus, frame(0x601, &[]));
    exchange(
        &mut bus,
        frame(0x001, &[0x02, 0x49, 0x00, 0x00]),
        0x101,
        &[0x02, 0x49, 0x01],
    );
    assert_eq!(bus.joint(1).unwrap().phase(), Phase::Application);
    // 0x0B = 1: enabled in the saved mode with target = actual.
    let st = bus.joint(1).unwrap().state();
    assert!(st.enabled && st.mode == 3 && st.target_position == 0);
    // Writing 0 again is harmless.
    write1(&mut bus, 1, 0x49, 0, 1);
}

#[test]
fn iap_can_be_switched_off_or_time_out() {
    let mut bus = WhjBus::with_configs([JointConfig::new(1, WhjModel::Whj30).without_iap()], 1);
    assert_eq!(one(&mut bus, frame(0x601, &[])).raw_id(), 0x701);

    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.boot.bootloader_timeout = Some(Duration::from_secs(2));
    let mut bus = WhjBus::with_configs([cfg], 1);
    silent(&mut bus, frame(0x601, &[]));
    wait_ms(&mut bus, 2000);
    assert_eq!(one(&mut bus, frame(0x601, &[])).raw_id(), 0x701);
}

#[test]
fn staggered_power_up() {
    let mut cfgs = Vec::new();
    for id in 1..=3 {
        let mut cfg = JointConfig::new(id, WhjModel::Whj30);
        cfg.boot.boot_delay = Duration::from_millis(100);
        cfg.boot.boot_delay_per_id = Duration::from_millis(50);
        cfgs.push(cfg);
    }
    let mut bus = WhjBus::with_configs(cfgs, 1);
    // Joint n wakes at 100 + 50 n ms; before that even the IAP write gets no answer.
    wait_ms(&mut bus, 140);
    silent(&mut bus, frame(0x001, &[0x02, 0x49, 0x00]));
    wait_ms(&mut bus, 20);
    write1(&mut bus, 1, 0x49, 0, 1);
    silent(&mut bus, frame(0x003, &[0x02, 0x49, 0x00]));
    wait_ms(&mut bus, 100);
    write1(&mut bus, 3, 0x49, 0, 1);
    // ON_DELAY := 1 saved: the next power-up is immediate.
    write1(&mut bus, 1, 0x0A, 0, 1);
    wait_ms(&mut bus, 6);
    write1(&mut bus, 1, 0x1F, 1, 1);
    write1(&mut bus, 1, 0x0C, 1, 1);
    wait_ms(&mut bus, 60);
    bus.power_cycle_all();
    write1(&mut bus, 1, 0x49, 0, 1);
    silent(&mut bus, frame(0x002, &[0x02, 0x49, 0x00]));
}

#[test]
fn id_change_after_save_and_power_cycle() {
    let mut bus = started(JointConfig::new(1, WhjModel::Whj30));
    write1(&mut bus, 1, 0x0A, 0, 1);
    wait_ms(&mut bus, 6);
    // The ack comes from the old ID; the joint keeps answering to 1 until the reboot.
    write1(&mut bus, 1, 0x01, 5, 1);
    assert_eq!(read(&mut bus, 1, 0x01, 1), vec![5]);
    write1(&mut bus, 1, 0x0C, 1, 1);
    wait_ms(&mut bus, 60);
    bus.power_cycle_all();
    silent(&mut bus, frame(0x001, &[0x02, 0x49, 0x00]));
    write1(&mut bus, 5, 0x49, 0, 1);
    assert_eq!(read(&mut bus, 5, 0x01, 1), vec![5]);

    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.id_change_immediate = true;
    let mut bus = started(cfg);
    write1(&mut bus, 1, 0x01, 9, 1);
    silent(&mut bus, frame(0x601, &[]));
    assert_eq!(one(&mut bus, frame(0x609, &[])).raw_id(), 0x709);
}

#[test]
fn options_for_undocumented_commands() {
    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.silent_write_cmd3 = true;
    cfg.any_even_write_length = true;
    cfg.apply_id0_writes = true;
    let mut bus = started(cfg);
    // 0x03: write without reply.
    silent(&mut bus, frame(0x001, &[0x03, 0x31, 0x07]));
    assert_eq!(read(&mut bus, 1, 0x31, 1), vec![7]);
    // Six data bytes: three registers.
    exchange(
        &mut bus,
        frame(0x001, &[0x02, 0x41, 0xE8, 0x03, 0xD0, 0x07, 0xB8, 0x0B]),
        0x101,
        &[0x02, 0x41, 0x01],
    );
    assert_eq!(read(&mut bus, 1, 0x41, 3), vec![1000, 2000, 3000]);
    // Node 0: applied, no reply.
    silent(&mut bus, frame(0x000, &[0x02, 0x31, 0x09]));
    assert_eq!(read(&mut bus, 1, 0x31, 1), vec![9]);
}

#[test]
fn classic_frames_are_ignored_unless_accepted() {
    let classic = |id: u16, data: &[u8]| {
        robobus_whj::CanFrame::new_classic(robobus_whj::CanFrame::standard_id(id).unwrap(), data)
            .unwrap()
    };
    let mut bus = started(JointConfig::new(1, WhjModel::Whj30));
    silent(&mut bus, classic(0x001, &[0x01, 0x00, 0x01]));
    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.accept_classic_frames = true;
    let mut bus = started(cfg);
    // Answered, and the answer is a CAN FD frame with BRS.
    let r = one(&mut bus, classic(0x001, &[0x01, 0x00, 0x01]));
    assert!(r.is_fd() && r.brs());
    assert_eq!(r.data(), &[0x01, 0x00, 0x14, 0x13]);
}

#[test]
fn trigger_flags_clear_themselves() {
    let mut bus = started(JointConfig::new(1, WhjModel::Whj30));
    // 0x0D (absolute-sensor calibration, C15): acknowledged, not simulated; 0x50: loads
    // the gains. Both read 0 afterwards, as do 0x0E and 0x0F.
    for addr in [0x0D, 0x50, 0x0E, 0x0F] {
        write1(&mut bus, 1, addr, 1, 1);
        assert_eq!(read(&mut bus, 1, addr, 1), vec![0], "{addr:#x}");
    }
    // 0x38 (servo reply format) is stored and forced to 0 at the next start.
    write1(&mut bus, 1, 0x38, 1, 1);
    assert_eq!(read(&mut bus, 1, 0x38, 1), vec![1]);
    bus.power_cycle_all();
    write1(&mut bus, 1, 0x49, 0, 1);
    assert_eq!(read(&mut bus, 1, 0x38, 1), vec![0]);
}
