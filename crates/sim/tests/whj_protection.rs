//! Protection: position step, following error, over-current, position limit, over-
//! temperature, supply voltage, clear error and recovery, low-power mode, end-board mode,
//! direct brake release: on the virtual clock.

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
use whj_common::{
    feedback, frame, joint1_at, one, pos_cmd, read, started, wait_ms, write1, write2, write4,
};

fn state(bus: &WhjBus) -> robobus_sim::whj::JointState {
    bus.joint(1).unwrap().state()
}

#[test]
fn position_step_over_ten_degrees_is_rejected_with_0x4000() {
    let mut bus = joint1_at(WhjModel::Whj30, 20.0);
    // Exactly 10° is accepted (the demo's 20° → 30°).
    one(&mut bus, pos_cmd(1, 300_000));
    wait_ms(&mut bus, 2000);
    assert_eq!(state(&bus).target_position, 300_000);
    // 10.01° is not: the previous target stays, 0x4000 latches, the drive stays enabled.
    let (_, _, _, _, err) = feedback(&one(&mut bus, pos_cmd(1, 400_100)));
    assert_eq!(err, 0, "feedback shows the state before the command");
    let st = state(&bus);
    assert_eq!(st.target_position, 300_000);
    assert_eq!(st.error.bits(), 0x4000);
    assert!(st.enabled);
    let (_, _, _, en, err) = feedback(&one(&mut bus, pos_cmd(1, 300_000)));
    assert_eq!((en, err), (1, 0x4000));
    // The register path is checked too (ack "failed").
    write4(&mut bus, 1, 0x36, -1, 0);
    // Clear: the bit goes, the joint keeps working.
    write1(&mut bus, 1, 0x0F, 1, 1);
    assert_eq!(read(&mut bus, 1, 0x04, 1), vec![0]);
    one(&mut bus, pos_cmd(1, 350_000));
    wait_ms(&mut bus, 1000);
    assert!((state(&bus).position_deg - 35.0).abs() < 1e-3);
}

#[test]
fn step_error_options() {
    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.step.step_error_disables = true;
    cfg.step.step_limit_deg = 2.0;
    let mut bus = started(cfg);
    one(&mut bus, pos_cmd(1, 25_000));
    let st = state(&bus);
    assert!(!st.enabled && st.error.bits() == 0x4000, "{st:?}");

    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.step.step_check_register_writes = false;
    let mut bus = started(cfg);
    write4(&mut bus, 1, 0x36, 150_000, 1);
    wait_ms(&mut bus, 1000);
    let st = state(&bus);
    assert!(
        st.error.is_empty() && (st.position_deg - 15.0).abs() < 1e-3,
        "{st:?}"
    );
}

#[test]
fn following_error_latches_0x0800_and_disables() {
    let mut bus = joint1_at(WhjModel::Whj30, 0.0);
    write4(&mut bus, 1, 0x4B, 20_000, 1); // 2°
    // A push beyond the peak torque (90 N·m) drags the joint away from its target.
    bus.joint_mut(1).unwrap().set_external_torque(150.0);
    wait_ms(&mut bus, 1000);
    let st = state(&bus);
    assert_eq!(st.error.bits() & 0x0800, 0x0800, "{st:?}");
    assert!(!st.enabled && st.brake_locked);
    // Enable is refused while the bit is latched.
    write1(&mut bus, 1, 0x0A, 1, 0);
    // Recovery (C8): clear, then mode 3 + enable. The joint stays disabled after the clear.
    bus.joint_mut(1).unwrap().set_external_torque(0.0);
    write1(&mut bus, 1, 0x0F, 1, 1);
    let st = state(&bus);
    assert!(st.error.is_empty() && !st.enabled, "{st:?}");
    write1(&mut bus, 1, 0x30, 3, 1);
    write1(&mut bus, 1, 0x0A, 1, 1);
    assert!(state(&bus).enabled);
}

#[test]
fn auto_enable_after_clear_is_an_option() {
    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.auto_enable_after_clear = true;
    let mut bus = started(cfg);
    write4(&mut bus, 1, 0x4B, 20_000, 1);
    bus.joint_mut(1).unwrap().set_external_torque(150.0);
    wait_ms(&mut bus, 1000);
    assert!(!state(&bus).enabled);
    bus.joint_mut(1).unwrap().set_external_torque(0.0);
    write1(&mut bus, 1, 0x0F, 1, 1);
    assert!(state(&bus).enabled);
}

#[test]
fn over_current_trips_0x0040() {
    let mut bus = joint1_at(WhjModel::Whj30, 0.0);
    write4(&mut bus, 1, 0x44, -100_000_000, 1);
    write4(&mut bus, 1, 0x46, 100_000_000, 1);
    write1(&mut bus, 1, 0x30, 1, 1);
    // Within the hardware trip (1.5 × 23.4 A): fine.
    write2(&mut bus, 1, 0x40, 40_000, 1);
    one(&mut bus, frame(0x401, &30_000i32.to_le_bytes()));
    wait_ms(&mut bus, 5);
    assert_eq!(state(&bus).error.bits(), 0);
    // Above it: over-current, drive off.
    bus.joint_mut(1).unwrap().set_external_torque(-200.0);
    one(&mut bus, frame(0x401, &38_000i32.to_le_bytes()));
    wait_ms(&mut bus, 5);
    let st = state(&bus);
    assert_eq!(st.error.bits(), 0x0040, "{st:?}");
    assert!(!st.enabled);
}

#[test]
fn leaving_the_position_range_trips_0x0200() {
    let mut bus = joint1_at(WhjModel::Whj30, 0.0);
    write4(&mut bus, 1, 0x46, 50_000, 1); // +5°
    write1(&mut bus, 1, 0x30, 2, 1);
    one(&mut bus, frame(0x301, &5000i32.to_le_bytes())); // 10 RPM = 60°/s
    wait_ms(&mut bus, 1000);
    let st = state(&bus);
    assert_eq!(st.error.bits(), 0x0200, "{st:?}");
    assert!(
        !st.enabled && st.position_deg > 5.0 && st.position_deg < 7.0,
        "{st:?}"
    );
}

#[test]
fn over_temperature_trips_0x0008_and_clears_only_when_cool() {
    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.ambient_temp_c = 85.0;
    let mut bus = started(cfg);
    bus.joint_mut(1).unwrap().set_external_torque(-80.0);
    wait_ms(&mut bus, 60_000);
    let st = state(&bus);
    assert_eq!(st.error.bits(), 0x0008, "{st:?}");
    assert!(!st.enabled);
    // Still hot: the bit stays.
    write1(&mut bus, 1, 0x0F, 1, 1);
    assert_eq!(state(&bus).error.bits(), 0x0008);
    bus.joint_mut(1).unwrap().set_ambient_temperature(25.0);
    wait_ms(&mut bus, 600_000);
    write1(&mut bus, 1, 0x0F, 1, 1);
    assert_eq!(state(&bus).error.bits(), 0);
}

#[test]
fn supply_voltage_trips() {
    let mut bus = joint1_at(WhjModel::Whj30, 0.0);
    bus.joint_mut(1).unwrap().set_supply_voltage(19.0);
    wait_ms(&mut bus, 1);
    let r = one(&mut bus, frame(0x601, &[]));
    assert_eq!(u16::from_le_bytes([r.data()[0], r.data()[1]]), 0x0004);
    assert!((i16::from_le_bytes([r.data()[2], r.data()[3]]) - 1900).abs() <= 1);
    assert_eq!(r.data()[6], 0, "under-voltage disables");
    bus.joint_mut(1).unwrap().set_supply_voltage(28.0);
    wait_ms(&mut bus, 1);
    write1(&mut bus, 1, 0x0F, 1, 1);
    assert_eq!(state(&bus).error.bits(), 0x0002);
    bus.joint_mut(1).unwrap().set_supply_voltage(24.0);
    wait_ms(&mut bus, 1);
    write1(&mut bus, 1, 0x0F, 1, 1);
    assert_eq!(state(&bus).error.bits(), 0);
}

#[test]
fn low_power_mode_caps_input_at_80_w() {
    let run = |low_power: bool| {
        let mut bus = joint1_at(WhjModel::Whj60, 0.0);
        write4(&mut bus, 1, 0x44, -100_000_000, 1);
        write4(&mut bus, 1, 0x46, 100_000_000, 1);
        write1(&mut bus, 1, 0x69, u8::from(low_power), 1);
        write1(&mut bus, 1, 0x30, 1, 1);
        one(&mut bus, frame(0x401, &15_000i32.to_le_bytes())); // 30 A
        let mut peak: f64 = 0.0;
        for _ in 0..200 {
            wait_ms(&mut bus, 1);
            peak = peak.max(state(&bus).input_power_w);
        }
        peak
    };
    let capped = run(true);
    let free = run(false);
    assert!(capped <= 80.0 + 1e-6, "{capped}");
    assert!(free > 200.0, "{free}");
    // Only WHJ10N/30/60 have it: a WHJ120 acks failure and reads 0.
    let mut bus = joint1_at(WhjModel::Whj120, 0.0);
    write1(&mut bus, 1, 0x69, 1, 0);
    assert_eq!(read(&mut bus, 1, 0x69, 1), vec![0]);
}

#[test]
fn end_board_mode_persists_and_needs_fw_519() {
    let mut bus = joint1_at(WhjModel::Whj30, 0.0);
    write1(&mut bus, 1, 0x79, 1, 1);
    write1(&mut bus, 1, 0x0A, 0, 1);
    wait_ms(&mut bus, 6);
    write1(&mut bus, 1, 0x0C, 1, 1);
    wait_ms(&mut bus, 60);
    bus.power_cycle_all();
    write1(&mut bus, 1, 0x49, 0, 1);
    assert_eq!(read(&mut bus, 1, 0x79, 1), vec![1]);

    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.firmware = robobus_whj::units::FirmwareVersion(0xD510);
    let mut bus = started(cfg);
    for addr in [0x79, 0x1F, 0x69] {
        write1(&mut bus, 1, addr, 1, 0);
        assert_eq!(read(&mut bus, 1, addr, 1), vec![0]);
    }
}

#[test]
fn firmware_gates_follow_the_register_table() {
    // Every gated register of the table, on each firmware: present (writable, reads back)
    // exactly when the table's gate admits the version. E2.XX is the multi-turn joints'
    // broadcast line: it has the broadcast counter although its last digits are below 500.
    use robobus_whj::units::FirmwareVersion;
    for fw in [
        0xD4FF, 0xD500, 0xD518, 0xD519, 0xD521, 0xD522, 0xDA05, 0xE200,
    ] {
        let version = FirmwareVersion(fw);
        let mut cfg = JointConfig::new(1, WhjModel::Whj30);
        cfg.firmware = version;
        let mut bus = started(cfg);
        write1(&mut bus, 1, 0x0A, 0, 1);
        wait_ms(&mut bus, 6);
        for info in robobus_whj::REGISTERS
            .iter()
            .filter(|r| r.firmware.is_some())
        {
            let a = info.addr.get();
            let present = info.firmware.unwrap().gate().admits(version);
            let value = if a == 0x4E { 7 } else { 1 };
            write1(&mut bus, 1, a, value, u8::from(present));
            let expect = if present { u16::from(value) } else { 0 };
            assert_eq!(
                read(&mut bus, 1, a, 1),
                vec![expect],
                "{} on {version}",
                info.name
            );
        }
    }
    // The table's reading, spelled out: which of 0x1F, 0x4E, 0x69, 0x6A, 0x79 exist.
    for (fw, present) in [
        (0xD4FF, [false, false, false, false, false]),
        (0xD519, [true, true, true, false, true]),
        (0xD522, [true, true, true, true, true]),
        (0xE200, [false, true, false, false, false]),
    ] {
        let mut cfg = JointConfig::new(1, WhjModel::Whj30);
        cfg.firmware = FirmwareVersion(fw);
        let mut bus = started(cfg);
        write1(&mut bus, 1, 0x0A, 0, 1);
        wait_ms(&mut bus, 6);
        for (a, p) in [0x1F, 0x4E, 0x69, 0x6A, 0x79].into_iter().zip(present) {
            write1(&mut bus, 1, a, 1, u8::from(p));
        }
    }
}

#[test]
fn direct_brake_release_once_per_power_cycle() {
    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.load.gravity_nm = 20.0;
    let mut bus = started(cfg);
    // While enabled: refused.
    write1(&mut bus, 1, 0x6A, 1, 0);
    write1(&mut bus, 1, 0x0A, 0, 1);
    wait_ms(&mut bus, 6);
    let held = state(&bus).position_deg;
    write1(&mut bus, 1, 0x6A, 1, 1);
    let r = one(&mut bus, frame(0x601, &[]));
    assert_eq!(r.data()[7], 0, "brake released");
    wait_ms(&mut bus, 200);
    assert!(
        state(&bus).position_deg < held - 1.0,
        "gravity pulls the arm down"
    );
    // Enable refused while 0x6A = 1; 0x6A := 0 locks the brake again.
    write1(&mut bus, 1, 0x0A, 1, 0);
    write1(&mut bus, 1, 0x6A, 0, 1);
    assert_eq!(one(&mut bus, frame(0x601, &[])).data()[7], 1);
    // Once per power cycle.
    write1(&mut bus, 1, 0x6A, 1, 0);
    write1(&mut bus, 1, 0x0A, 1, 1);
    // Not on a WHJ10.
    let mut bus = joint1_at(WhjModel::Whj10B, 0.0);
    write1(&mut bus, 1, 0x0A, 0, 1);
    wait_ms(&mut bus, 6);
    write1(&mut bus, 1, 0x6A, 1, 0);
}
