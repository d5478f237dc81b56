//! The self-running motion program (section 3-11, A-1 (24)) on the virtual clock.
#![allow(clippy::unwrap_used)] // test helpers

use crate::wck_support;

use core::time::Duration;

use robobus_sim::wck::{Drive, Model};
use robobus_wck::program::Program;
use robobus_wck::{Command, IoBits};
use wck_support::{AWAKE, host, id};

const DEG8: f64 = 269.0 / 255.0;

/// The target the position loop is driving to, in standard steps.
fn target(h: &robobus_sim::wck::VirtualHost) -> Option<u8> {
    match h.bus().servo(0).unwrap().mechanics().drive() {
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        Drive::Position { target, .. } => Some((target / DEG8).round() as u8),
        _ => None,
    }
}

#[test]
fn manual_example_shuttles_between_82_and_172_every_266_ms() {
    let mut h = host(Model::W1108, &[0]);
    let write = [
        0xFF, 0xE0, 0x96, 0x04, 0x10, 0x52, 0x31, 0x0A, 0x10, 0xAC, 0x31, 0x0A, 0x0C,
    ];
    assert_eq!(h.transact(&write, 2, Duration::from_millis(200)), [4, 4]);
    // Sample every millisecond for 3 s: when does the target change, which extremes does
    // the shaft reach?
    let mut switches: Vec<(Duration, u8)> = Vec::new();
    let mut extremes: Vec<u8> = Vec::new();
    let mut last = target(&h);
    let mut lo = 255u8;
    let mut hi = 0u8;
    for _ in 0..3000 {
        h.sleep(Duration::from_millis(1));
        let p = h.bus().servo(0).unwrap().position();
        lo = lo.min(p);
        hi = hi.max(p);
        let now = target(&h);
        if now != last {
            let t = now.unwrap();
            switches.push((h.now(), t));
            // Record the extreme reached on the leg that just ended.
            extremes.push(if t == 172 { lo } else { hi });
            lo = 255;
            hi = 0;
            last = now;
        }
    }
    assert!(switches.len() >= 10, "{switches:?}");
    // Alternating targets 172 / 82 ...
    for w in switches.windows(2) {
        assert_ne!(w[0].1, w[1].1);
        assert!([82, 172].contains(&w[1].1));
        // ... 266 ms apart (0x10A ms), to the control tick.
        let gap = w[1].0.saturating_sub(w[0].0);
        assert!(
            gap.abs_diff(Duration::from_millis(266)) <= Duration::from_millis(1),
            "{gap:?}"
        );
    }
    // ... and each leg reaches its end (82 or 172, within one step) before turning back.
    for (i, e) in extremes.iter().enumerate().skip(1) {
        let expected: u8 = if switches[i].1 == 172 { 82 } else { 172 };
        assert!(
            e.abs_diff(expected) <= 1,
            "leg {i}: reached {e}, expected {expected}"
        );
    }
}

#[test]
fn conditions_outputs_repeat_and_end() {
    let text = "output 1\nif adc >= 128\nmove 200 torque 0\ndelay 300ms\n\
                output 2\nmove 50 torque 0\ndelay 300ms\nrepeat 2\n";
    let program = Program::parse(text).unwrap();
    let run = |adc: u8| {
        let mut h = host(Model::W1108, &[0]);
        h.bus_mut().servo_mut(0).unwrap().set_adc(adc);
        assert_eq!(
            h.command(&Command::MotionWrite { id: id(0), program }),
            [8, 8]
        );
        let mut targets = Vec::new();
        let mut outputs = Vec::new();
        for _ in 0..1600 {
            h.sleep(Duration::from_millis(1));
            let s = h.bus().servo(0).unwrap();
            if let Some(t) = target(&h)
                && targets.last() != Some(&t)
            {
                targets.push(t);
            }
            if outputs.last() != Some(&s.outputs()) {
                outputs.push(s.outputs());
            }
        }
        (
            targets,
            outputs,
            h.bus().servo(0).unwrap().program_running(),
        )
    };
    let bits = |b| IoBits::new(b).unwrap();
    // A/D below 128: the move to 200 is skipped (a false condition skips the next
    // instruction); two passes, then the program stops.
    let (targets, outputs, running) = run(10);
    assert_eq!(targets, [50]);
    assert_eq!(outputs, [bits(1), bits(2), bits(1), bits(2)]);
    assert!(!running);
    // A/D at 200: it goes to 200 and back to 50, twice.
    let (targets, _, running) = run(200);
    assert_eq!(targets, [200, 50, 200, 50]);
    assert!(!running);
}

#[test]
fn program_is_kept_in_eeprom_and_runs_after_power_up() {
    let mut h = host(Model::W1108, &[0]);
    let program = Program::parse("move 30 torque 0\ndelay 100ms\nend\n").unwrap();
    h.command(&Command::MotionWrite { id: id(0), program });
    h.sleep(Duration::from_secs(1));
    assert_eq!(h.bus().servo(0).unwrap().position(), 30);
    assert!(!h.bus().servo(0).unwrap().program_running());
    h.bus_mut().servo_mut(0).unwrap().set_position(120);
    h.bus_mut().power_cycle(0);
    h.sleep(AWAKE + Duration::from_secs(1));
    assert_eq!(h.bus().servo(0).unwrap().position(), 30);
    // Count 0 switches it off.
    assert_eq!(
        h.command(&Command::MotionWrite {
            id: id(0),
            program: Program::EMPTY
        }),
        [0, 0]
    );
    assert_eq!(h.command(&Command::MotionRead { id: id(0) }), [0, 0]);
}
