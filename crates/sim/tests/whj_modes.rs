//! Work modes, enable / disable / brake, set zero, servo feedback timing, status frame,
//! and the mechanics' limits per model: on the virtual clock.

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

use robobus_sim::whj::{JointConfig, WhjModel};
use whj_common::{
    feedback, frame, joint1_at, one, pos_cmd, read, read_i32, started, wait_ms, write1, write2,
    write4,
};

fn state(bus: &robobus_sim::whj::WhjBus) -> robobus_sim::whj::JointState {
    bus.joint(1).unwrap().state()
}

#[test]
fn feedback_is_sampled_before_the_command() {
    let mut bus = joint1_at(WhjModel::Whj30, 0.0);
    let (_, _, pos, en, err) = feedback(&one(&mut bus, pos_cmd(1, 50_000)));
    assert_eq!((pos, en, err), (0, 1, 0));
    wait_ms(&mut bus, 30);
    let (_, speed, pos, _, _) = feedback(&one(&mut bus, pos_cmd(1, 50_000)));
    assert!(pos > 0 && pos < 50_000 && speed > 0, "{pos} {speed}");
    wait_ms(&mut bus, 2000);
    let (_, speed, pos, _, _) = feedback(&one(&mut bus, pos_cmd(1, 50_000)));
    assert_eq!((pos, speed), (50_000, 0));
}

#[test]
fn each_mode_acts_on_its_own_target() {
    let mut bus = joint1_at(WhjModel::Whj30, 0.0);
    // Wide limits: the joint turns several revolutions below.
    write4(&mut bus, 1, 0x44, -100_000_000, 1);
    write4(&mut bus, 1, 0x46, 100_000_000, 1);
    // Position mode: speed and current targets are stored but ignored.
    one(&mut bus, frame(0x301, &5000i32.to_le_bytes()));
    one(&mut bus, frame(0x401, &3000i32.to_le_bytes()));
    assert_eq!(read_i32(&mut bus, 1, 0x34), 5000);
    assert_eq!(read_i32(&mut bus, 1, 0x32), 3000);
    wait_ms(&mut bus, 500);
    assert_eq!(state(&bus).position_deg, 0.0);

    // Speed mode: a position target does nothing, a speed target turns the joint.
    write1(&mut bus, 1, 0x30, 2, 1);
    assert_eq!(
        read_i32(&mut bus, 1, 0x34),
        0,
        "mode change clears the speed target"
    );
    one(&mut bus, pos_cmd(1, 50_000));
    wait_ms(&mut bus, 500);
    assert!(state(&bus).position_deg.abs() < 1e-3);
    one(&mut bus, frame(0x301, &(-2500i32).to_le_bytes())); // -5 RPM
    wait_ms(&mut bus, 1000);
    assert!(
        (state(&bus).speed_rpm + 5.0).abs() < 0.01,
        "{:?}",
        state(&bus)
    );

    // Current mode: positive current turns the positive way.
    write1(&mut bus, 1, 0x30, 1, 1);
    one(&mut bus, frame(0x401, &1000i32.to_le_bytes()));
    wait_ms(&mut bus, 50);
    let st = state(&bus);
    assert!(
        (st.current_a - 1.0).abs() < 1e-6 && st.speed_rpm > 0.0,
        "{st:?}"
    );
    // Unloaded, it speeds up to the speed limit (37.5 RPM), which holds in current mode too.
    wait_ms(&mut bus, 1000);
    let st = state(&bus);
    assert!(
        (st.speed_rpm - 37.5).abs() < 0.1 && st.current_a < 1.0,
        "{st:?}"
    );

    // Open loop: duty from 0x31.
    write1(&mut bus, 1, 0x30, 0, 1);
    write1(&mut bus, 1, 0x31, 20, 1);
    wait_ms(&mut bus, 300);
    assert!(state(&bus).speed_rpm > 1.0, "{:?}", state(&bus));

    // Back to position: no jump, target = actual.
    write1(&mut bus, 1, 0x30, 3, 1);
    let st = state(&bus);
    assert!((f64::from(st.target_position) / 1e4 - st.position_deg).abs() < 1e-3);
    wait_ms(&mut bus, 2000);
    assert_eq!(state(&bus).speed_rpm, 0.0);
}

#[test]
fn disabled_joint_answers_and_holds_on_its_brake() {
    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.load.constant_nm = 20.0;
    let mut bus = started(cfg);
    write1(&mut bus, 1, 0x0A, 0, 1);
    wait_ms(&mut bus, 10);
    let held = state(&bus).position_deg;
    // Status: disabled, brake locked.
    let r = one(&mut bus, frame(0x601, &[]));
    assert_eq!(&r.data()[6..8], &[0, 1]);
    // Servo frames still get feedback (enable 0) and do not move the joint.
    let (_, _, _, en, _) = feedback(&one(&mut bus, pos_cmd(1, 50_000)));
    assert_eq!(en, 0);
    wait_ms(&mut bus, 1000);
    assert_eq!(state(&bus).position_deg, held);
    // Enable: brake released, target = actual, the loop holds against the load.
    write1(&mut bus, 1, 0x0A, 1, 1);
    let r = one(&mut bus, frame(0x601, &[]));
    assert_eq!(&r.data()[6..8], &[1, 0]);
    wait_ms(&mut bus, 1000);
    assert!(state(&bus).position_deg.abs() < 0.01, "{:?}", state(&bus));

    // A WHJ10N has no brake: the load turns it while disabled, and its brake byte is 0.
    let mut cfg = JointConfig::new(1, WhjModel::Whj10N);
    cfg.load.constant_nm = 5.0;
    let mut bus = started(cfg);
    write1(&mut bus, 1, 0x0A, 0, 1);
    wait_ms(&mut bus, 10);
    let r = one(&mut bus, frame(0x601, &[]));
    assert_eq!(&r.data()[6..8], &[0, 0]);
    wait_ms(&mut bus, 200);
    assert!(state(&bus).position_deg > 1.0);
}

#[test]
fn set_zero_keeps_an_enabled_joint_still() {
    let mut bus = joint1_at(WhjModel::Whj30, 15.0);
    write1(&mut bus, 1, 0x0E, 1, 1);
    assert_eq!(read_i32(&mut bus, 1, 0x14), 0);
    assert_eq!(read_i32(&mut bus, 1, 0x36), 0);
    wait_ms(&mut bus, 500);
    let st = state(&bus);
    assert!(
        (st.physical_deg - 15.0).abs() < 1e-6 && st.position_deg.abs() < 1e-6,
        "{st:?}"
    );
    // Not saved: the offset is lost at the next power-up.
    bus.power_cycle_all();
    write1(&mut bus, 1, 0x49, 0, 1);
    assert_eq!(read_i32(&mut bus, 1, 0x14), 150_000);
    // Saved (while disabled): kept.
    write1(&mut bus, 1, 0x0E, 1, 1);
    write1(&mut bus, 1, 0x0A, 0, 1);
    wait_ms(&mut bus, 6);
    write1(&mut bus, 1, 0x0C, 1, 1);
    wait_ms(&mut bus, 60);
    bus.power_cycle_all();
    write1(&mut bus, 1, 0x49, 0, 1);
    assert_eq!(read_i32(&mut bus, 1, 0x14), 0);
}

#[test]
fn status_frame_sixteen_or_twelve_bytes() {
    let mut bus = joint1_at(WhjModel::Whj30, -3.5);
    let r = one(&mut bus, frame(0x601, &[]));
    assert_eq!((r.raw_id(), r.len()), (0x701, 16));
    assert_eq!(
        i32::from_le_bytes(r.data()[8..12].try_into().unwrap()),
        -35_000
    );
    assert_eq!(i16::from_le_bytes([r.data()[4], r.data()[5]]), 250); // 25.0 °C

    let mut cfg = JointConfig::new(1, WhjModel::Whj30);
    cfg.status_len_16 = false;
    let mut bus = started(cfg);
    assert_eq!(one(&mut bus, frame(0x601, &[])).len(), 12);
}

#[test]
fn position_mode_clamps_to_the_limits() {
    let mut bus = joint1_at(WhjModel::Whj30, 0.0);
    write4(&mut bus, 1, 0x46, 50_000, 1);
    one(&mut bus, pos_cmd(1, 80_000));
    assert_eq!(read_i32(&mut bus, 1, 0x36), 50_000);
    wait_ms(&mut bus, 2000);
    assert!((state(&bus).position_deg - 5.0).abs() < 1e-3);
}

#[test]
fn enabled_outside_the_limits_drives_to_the_limit() {
    // 50° outside the range: farther than the 30° following-error limit, which applies to
    // the commanded trajectory, not to the distance to the limit.
    let mut bus = joint1_at(WhjModel::Whj30, 60.0);
    write1(&mut bus, 1, 0x0A, 0, 1);
    wait_ms(&mut bus, 6);
    write4(&mut bus, 1, 0x46, 100_000, 1);
    write1(&mut bus, 1, 0x0A, 1, 1);
    assert_eq!(read_i32(&mut bus, 1, 0x36), 100_000);
    wait_ms(&mut bus, 3000);
    let st = state(&bus);
    assert!(
        (st.position_deg - 10.0).abs() < 1e-3 && st.enabled && st.error.is_empty(),
        "{st:?}"
    );
}

#[test]
fn speed_and_acceleration_limits_per_model() {
    for (model, peak_rpm) in [
        (WhjModel::Whj03, 30.0),
        (WhjModel::Whj10B, 37.5),
        (WhjModel::Whj30, 37.5),
        (WhjModel::Whj60, 30.0),
        (WhjModel::Whj120, 30.0),
    ] {
        let mut bus = joint1_at(model, 0.0);
        write1(&mut bus, 1, 0x30, 2, 1);
        // 100 RPM requested; the 0x41 default (3000 / ratio RPM) caps it at the peak speed.
        one(&mut bus, frame(0x301, &50_000i32.to_le_bytes()));
        // 0x42 = 5000 × 0.1 rpm/s = 500 rpm/s: half-way after peak/1000 s.
        let half = (peak_rpm / 1000.0 * 1000.0) as u64;
        wait_ms(&mut bus, half);
        let mid = state(&bus).speed_rpm;
        assert!((mid - peak_rpm / 2.0).abs() < 1.5, "{model}: {mid}");
        wait_ms(&mut bus, 1000);
        let st = state(&bus);
        assert!((st.speed_rpm - peak_rpm).abs() < 0.05, "{model}: {st:?}");
        // Halving 0x41 halves the top speed.
        write2(&mut bus, 1, 0x41, 1500, 1);
        wait_ms(&mut bus, 1000);
        assert!(
            (state(&bus).speed_rpm - peak_rpm / 2.0).abs() < 0.05,
            "{model}"
        );
    }
}

#[test]
fn current_limit_clamps_the_current() {
    let mut bus = joint1_at(WhjModel::Whj60, 0.0);
    write1(&mut bus, 1, 0x30, 1, 1);
    write2(&mut bus, 1, 0x40, 1000, 1); // 2000 mA on a 2 mA joint
    one(&mut bus, frame(0x401, &5000i32.to_le_bytes()));
    wait_ms(&mut bus, 50);
    let st = state(&bus);
    assert!((st.current_a - 2.0).abs() < 1e-9, "{st:?}");
    // The feedback reports 2 mA counts.
    let (cur, _, _, _, _) = feedback(&one(&mut bus, frame(0x401, &5000i32.to_le_bytes())));
    assert_eq!(cur, 1000);
    assert_eq!(read(&mut bus, 1, 0x10, 1), vec![1000]);
}

#[test]
fn temperature_rises_with_current_and_voltage_sags() {
    let mut bus = joint1_at(WhjModel::Whj30, 0.0);
    let t0 = state(&bus).temperature_c;
    let v0 = state(&bus).voltage_v;
    // Hold against a load that needs about the rated torque.
    bus.joint_mut(1).unwrap().set_external_torque(-30.0);
    wait_ms(&mut bus, 60_000);
    let st = state(&bus);
    assert!(st.temperature_c > t0 + 5.0, "{st:?}");
    assert!(st.voltage_v < v0 - 0.01, "{st:?}");
    // Twice the torque, four times the copper loss: a faster rise.
    let mut bus2 = joint1_at(WhjModel::Whj30, 0.0);
    bus2.joint_mut(1).unwrap().set_external_torque(-60.0);
    wait_ms(&mut bus2, 60_000);
    let st2 = bus2.joint(1).unwrap().state();
    assert!(
        st2.temperature_c - t0 > 3.0 * (st.temperature_c - t0),
        "{st:?} {st2:?}"
    );
    // The register and the status frame report it.
    let w = read(&mut bus2, 1, 0x05, 2);
    assert_eq!(w[1] as i16, (st2.temperature_c * 10.0).round() as i16);
}

/// A joint whose drive gives less current than a motion needs
/// (`JointConfig::drive_current_limit_a`) falls behind its position target, as a loaded
/// joint does, its current at that limit; the same joint with its full current is nearly
/// there in that time.
#[test]
fn a_drive_current_limit_makes_the_joint_lag_behind_its_target() {
    let at = |amps: Option<f64>, ms: u64| {
        let mut cfg = JointConfig::new(1, WhjModel::Whj30);
        cfg.drive_current_limit_a = amps;
        let mut bus = started(cfg);
        one(&mut bus, pos_cmd(1, 50_000));
        wait_ms(&mut bus, ms);
        state(&bus)
    };
    let full = at(None, 60);
    let weak = at(Some(0.2), 60);
    assert!(full.position_deg > 4.0, "{full:?}");
    assert!(weak.position_deg < 2.0, "{weak:?}");
    assert_eq!(weak.current_a.abs(), 0.2, "{weak:?}");
    assert!(weak.error.is_empty(), "{weak:?}");
}
