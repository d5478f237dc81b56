//! Helpers shared by the WHJ simulator tests (virtual clock).
#![allow(
    dead_code,
    unreachable_pub,
    missing_docs,
    clippy::unwrap_used,
    clippy::panic
)]

use std::time::Duration;

use robobus_sim::whj::{JointConfig, WhjBus, WhjModel};
use robobus_whj::CanFrame;

/// A CAN FD frame (BRS on) from an ID and payload.
pub fn frame(id: u16, data: &[u8]) -> CanFrame {
    CanFrame::new_fd(CanFrame::standard_id(id).unwrap(), data).unwrap()
}

/// Send `f` and expect exactly one reply; return it.
pub fn one(bus: &mut WhjBus, f: CanFrame) -> CanFrame {
    let replies = bus.request(f);
    assert_eq!(
        replies.len(),
        1,
        "expected one reply to {f:?}, got {replies:?}"
    );
    replies[0].frame
}

/// Send `f` and expect no reply.
pub fn silent(bus: &mut WhjBus, f: CanFrame) {
    let replies = bus.request(f);
    assert!(
        replies.is_empty(),
        "expected no reply to {f:?}, got {replies:?}"
    );
}

/// Send `f` to joint 1 and check the reply's ID and bytes.
pub fn exchange(bus: &mut WhjBus, f: CanFrame, id: u16, data: &[u8]) {
    let r = one(bus, f);
    assert_eq!(
        (r.raw_id(), r.data()),
        (u32::from(id), data),
        "reply to {f:?}"
    );
}

/// Write with a 1-byte value as in the vendor examples; expect the ack with `status`.
pub fn write1(bus: &mut WhjBus, id: u8, addr: u8, value: u8, status: u8) {
    exchange(
        bus,
        frame(u16::from(id), &[0x02, addr, value]),
        0x100 + u16::from(id),
        &[0x02, addr, status],
    );
}

/// Write a 16-bit value; expect the ack with `status`.
pub fn write2(bus: &mut WhjBus, id: u8, addr: u8, value: u16, status: u8) {
    let [a, b] = value.to_le_bytes();
    exchange(
        bus,
        frame(u16::from(id), &[0x02, addr, a, b]),
        0x100 + u16::from(id),
        &[0x02, addr, status],
    );
}

/// Write a 32-bit pair; expect the ack with `status`.
pub fn write4(bus: &mut WhjBus, id: u8, addr: u8, value: i32, status: u8) {
    let b = value.to_le_bytes();
    exchange(
        bus,
        frame(u16::from(id), &[0x02, addr, b[0], b[1], b[2], b[3]]),
        0x100 + u16::from(id),
        &[0x02, addr, status],
    );
}

/// Read `count` registers; return the words (padding dropped).
pub fn read(bus: &mut WhjBus, id: u8, addr: u8, count: u8) -> Vec<u16> {
    let r = one(bus, frame(u16::from(id), &[0x01, addr, count]));
    assert_eq!(r.raw_id(), 0x100 + u32::from(id));
    assert_eq!(&r.data()[..2], &[0x01, addr]);
    r.data()[2..2 + 2 * usize::from(count)]
        .chunks(2)
        .map(|c| u16::from_le_bytes([c[0], c[1]]))
        .collect()
}

/// Read a 32-bit pair.
pub fn read_i32(bus: &mut WhjBus, id: u8, addr: u8) -> i32 {
    let w = read(bus, id, addr, 2);
    i32::from_le_bytes([
        w[0].to_le_bytes()[0],
        w[0].to_le_bytes()[1],
        w[1].to_le_bytes()[0],
        w[1].to_le_bytes()[1],
    ])
}

/// Servo feedback fields: (current, speed, position, enable, error).
pub fn feedback(f: &CanFrame) -> (i32, i32, i32, u16, u16) {
    let d = f.data();
    assert_eq!(d.len(), 16, "{f:?}");
    let i = |k: usize| i32::from_le_bytes([d[k], d[k + 1], d[k + 2], d[k + 3]]);
    (
        i(0),
        i(4),
        i(8),
        u16::from_le_bytes([d[12], d[13]]),
        u16::from_le_bytes([d[14], d[15]]),
    )
}

/// A position servo frame to joint `id`.
pub fn pos_cmd(id: u8, counts: i32) -> CanFrame {
    frame(0x200 + u16::from(id), &counts.to_le_bytes())
}

/// One joint, application started (IAP handshake done), default options otherwise.
pub fn started(cfg: JointConfig) -> WhjBus {
    let id = cfg.id;
    let mut bus = WhjBus::with_configs([cfg], 7);
    write1(&mut bus, id, 0x49, 0, 1);
    bus.advance(Duration::from_millis(1));
    bus
}

/// Joint 1 of `model`, started, at `deg`.
pub fn joint1_at(model: WhjModel, deg: f64) -> WhjBus {
    let mut cfg = JointConfig::new(1, model);
    cfg.initial_position_deg = deg;
    started(cfg)
}

/// Let `ms` milliseconds pass.
pub fn wait_ms(bus: &mut WhjBus, ms: u64) {
    bus.advance(Duration::from_millis(ms));
}
