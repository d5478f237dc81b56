//! The four broadcast frames a host sends (0x2F position, 0x4F current, 0x0F register,
//! 0x7F status): their payloads and slots, encoded and decoded.

use super::{FeedForwardBits, ReplyMask, SLOTS};
use crate::id::JointId;
use crate::registers::{RegisterAddr, TABLE_LEN};
use crate::request::{ReadRange, WriteData};
use crate::units::{Current, Position};

/// One joint's slot in a 0x2F position frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct PositionSlot {
    /// Target position (0.0001°). Values whose top byte is 0x7F mean "no data" on the wire
    /// and cannot be sent as targets.
    pub position: Position,
    /// Speed feed-forward, i16 in 0.002 RPM.
    pub speed_ff: i16,
    /// Current feed-forward, i16 in 2 mA for every model.
    pub current_ff: i16,
}

impl PositionSlot {
    /// A slot with a target and no feed-forward values.
    pub const fn target(position: Position) -> Self {
        Self {
            position,
            speed_ff: 0,
            current_ff: 0,
        }
    }
}

/// The "no data" filler of a position slot: position 0x7FFFFFFF, then 0xFF.
pub const POSITION_NO_DATA: [u8; 8] = [0xFF, 0xFF, 0xFF, 0x7F, 0xFF, 0xFF, 0xFF, 0xFF];
/// The "no data" filler of a current slot: 0x7FFFFFFF.
pub const CURRENT_NO_DATA: [u8; 4] = [0xFF, 0xFF, 0xFF, 0x7F];

/// Whether an i32 target would read as "no data" (top byte 0x7F).
pub const fn is_no_data(value: i32) -> bool {
    value.to_le_bytes()[3] == 0x7F
}

/// 0x2F: position targets for joints 1..=7 (64 bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct BroadcastPosition {
    /// Slots for joints 1..=7; `None` = no data (the joint keeps its target).
    pub slots: [Option<PositionSlot>; SLOTS],
    /// End-board bytes D56..=D62 (0xFF when unused).
    pub end_board: [u8; 7],
    /// Feed-forward selectors (high nibble of D63).
    pub feed_forward: FeedForwardBits,
    /// Reply mask (low nibble of D63).
    pub mask: ReplyMask,
}

/// 0x4F: current targets for joints 1..=7 (48 bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct BroadcastCurrent {
    /// Target currents for joints 1..=7 (model-dependent counts); `None` = no data.
    pub slots: [Option<Current>; SLOTS],
    /// End-board bytes D28..=D46 (0xFF when unused).
    pub end_board: [u8; 19],
    /// Reply mask (low nibble of D47).
    pub mask: ReplyMask,
}

/// A register operation in a 0x0F slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RegisterOp {
    /// Read `range`; sent as `[04 01 idx cnt 00 FF FF]`.
    Read(ReadRange),
    /// Write `data` at `addr`; sent as `[N 02 idx data… FF…]`.
    Write {
        /// First register.
        addr: RegisterAddr,
        /// 1, 2 or 4 data bytes.
        data: WriteData,
    },
}

/// A joint's 7-byte slot in a 0x0F register frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RegisterSlot {
    /// Slot byte 0 = 0xFF: no operation.
    Empty,
    /// A valid operation.
    Op(RegisterOp),
    /// Anything else, kept raw (a joint ignores it).
    Invalid([u8; 7]),
}

/// 0x0F: register reads/writes for joints 1..=7 (64 bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct BroadcastRegister {
    /// Slots for joints 1..=7.
    pub slots: [RegisterSlot; SLOTS],
    /// End-board bytes D50..=D62 (`[cmd, index, len, data…]`, 0xFF when unused).
    pub end_board: [u8; 13],
    /// Reply mask (low nibble of D63).
    pub mask: ReplyMask,
}

/// 0x7F: status query (24 bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct BroadcastStatus {
    /// End-board bytes D0..=D22 (0x00 when unused).
    pub end_board: [u8; 23],
    /// Reply mask (low nibble of D23).
    pub mask: ReplyMask,
}

impl BroadcastPosition {
    /// No targets, no end-board data, feed-forward off.
    pub const fn new(mask: ReplyMask) -> Self {
        Self {
            slots: [None; SLOTS],
            end_board: [0xFF; 7],
            feed_forward: FeedForwardBits::OFF,
            mask,
        }
    }

    /// Set a joint's target (no feed-forward). `None` for IDs > 7 or a "no data" value.
    #[must_use]
    pub fn with_target(mut self, joint: JointId, position: Position) -> Option<Self> {
        if is_no_data(position.0) {
            return None;
        }
        *self.slots.get_mut(usize::from(joint.get()) - 1)? = Some(PositionSlot::target(position));
        Some(self)
    }

    /// The slot of `joint` (`None` if absent or no data).
    pub fn slot(&self, joint: JointId) -> Option<PositionSlot> {
        self.slots
            .get(usize::from(joint.get()) - 1)
            .copied()
            .flatten()
    }

    pub(crate) fn encode(&self, out: &mut [u8; 64]) {
        for (i, slot) in self.slots.iter().enumerate() {
            let b = match slot {
                Some(s) => {
                    let mut b = [0u8; 8];
                    b[..4].copy_from_slice(&s.position.0.to_le_bytes());
                    b[4..6].copy_from_slice(&s.speed_ff.to_le_bytes());
                    b[6..].copy_from_slice(&s.current_ff.to_le_bytes());
                    b
                }
                None => POSITION_NO_DATA,
            };
            out[i * 8..i * 8 + 8].copy_from_slice(&b);
        }
        out[56..63].copy_from_slice(&self.end_board);
        out[63] = self.feed_forward.nibble() << 4 | self.mask.get();
    }

    pub(crate) fn decode(d: &[u8; 64]) -> Self {
        let mut slots = [None; SLOTS];
        for (i, slot) in slots.iter_mut().enumerate() {
            let s = &d[i * 8..i * 8 + 8];
            if s[3] != 0x7F {
                *slot = Some(PositionSlot {
                    position: Position(i32::from_le_bytes([s[0], s[1], s[2], s[3]])),
                    speed_ff: i16::from_le_bytes([s[4], s[5]]),
                    current_ff: i16::from_le_bytes([s[6], s[7]]),
                });
            }
        }
        let mut end_board = [0u8; 7];
        end_board.copy_from_slice(&d[56..63]);
        Self {
            slots,
            end_board,
            feed_forward: FeedForwardBits::from_nibble(d[63] >> 4),
            mask: ReplyMask(d[63] & 0xF),
        }
    }
}

impl BroadcastCurrent {
    /// No targets, no end-board data.
    pub const fn new(mask: ReplyMask) -> Self {
        Self {
            slots: [None; SLOTS],
            end_board: [0xFF; 19],
            mask,
        }
    }

    /// Set a joint's target current. `None` for IDs > 7 or a "no data" value.
    #[must_use]
    pub fn with_target(mut self, joint: JointId, current: Current) -> Option<Self> {
        if is_no_data(current.0) {
            return None;
        }
        *self.slots.get_mut(usize::from(joint.get()) - 1)? = Some(current);
        Some(self)
    }

    /// The target of `joint` (`None` if absent, no data, or ID > 7).
    pub fn slot(&self, joint: JointId) -> Option<Current> {
        self.slots
            .get(usize::from(joint.get()) - 1)
            .copied()
            .flatten()
    }

    pub(crate) fn encode(&self, out: &mut [u8; 48]) {
        for (i, slot) in self.slots.iter().enumerate() {
            let b = match slot {
                Some(c) => c.0.to_le_bytes(),
                None => CURRENT_NO_DATA,
            };
            out[i * 4..i * 4 + 4].copy_from_slice(&b);
        }
        out[28..47].copy_from_slice(&self.end_board);
        out[47] = self.mask.get();
    }

    pub(crate) fn decode(d: &[u8; 48]) -> Self {
        let mut slots = [None; SLOTS];
        for (i, slot) in slots.iter_mut().enumerate() {
            let s = &d[i * 4..i * 4 + 4];
            if s[3] != 0x7F {
                *slot = Some(Current(i32::from_le_bytes([s[0], s[1], s[2], s[3]])));
            }
        }
        let mut end_board = [0u8; 19];
        end_board.copy_from_slice(&d[28..47]);
        Self {
            slots,
            end_board,
            mask: ReplyMask(d[47] & 0xF),
        }
    }
}

impl RegisterSlot {
    /// The 7 wire bytes.
    pub fn encode(&self) -> [u8; 7] {
        match self {
            Self::Empty => [0xFF; 7],
            Self::Invalid(raw) => *raw,
            Self::Op(RegisterOp::Read(range)) => [
                4,
                0x01,
                range.start().get(),
                range.count(),
                0x00,
                0xFF,
                0xFF,
            ],
            Self::Op(RegisterOp::Write { addr, data }) => {
                let mut b = [0xFF; 7];
                let (bytes, n) = data.to_bytes();
                #[allow(clippy::cast_possible_truncation)] // n <= 4
                {
                    b[0] = n as u8 + 2;
                }
                b[1] = 0x02;
                b[2] = addr.get();
                b[3..3 + n].copy_from_slice(&bytes[..n]);
                b
            }
        }
    }

    /// Parse 7 slot bytes (lenient as §8.4 advises: read length byte 3 or 4, count high
    /// byte 0x00 or 0xFF, padding not checked).
    pub fn decode(s: [u8; 7]) -> Self {
        if s[0] == 0xFF {
            return Self::Empty;
        }
        let Ok(addr) = RegisterAddr::new(s[2]) else {
            return Self::Invalid(s);
        };
        decode_op(s, addr).map_or(Self::Invalid(s), Self::Op)
    }
}

fn decode_op(s: [u8; 7], addr: RegisterAddr) -> Option<RegisterOp> {
    match (s[0], s[1]) {
        (3 | 4, 0x01) => {
            if s[0] == 4 && s[4] != 0 && s[4] != 0xFF {
                None
            } else {
                ReadRange::new(addr, s[3]).ok().map(RegisterOp::Read)
            }
        }
        (3, 0x02) => Some(RegisterOp::Write {
            addr,
            data: WriteData::Byte(s[3]),
        }),
        (4, 0x02) => Some(RegisterOp::Write {
            addr,
            data: WriteData::Word(u16::from_le_bytes([s[3], s[4]])),
        }),
        (6, 0x02) if usize::from(addr.get()) + 1 < TABLE_LEN => Some(RegisterOp::Write {
            addr,
            data: WriteData::Pair(i32::from_le_bytes([s[3], s[4], s[5], s[6]])),
        }),
        _ => None,
    }
}

impl BroadcastRegister {
    /// No operations, no end-board data.
    pub const fn new(mask: ReplyMask) -> Self {
        Self {
            slots: [RegisterSlot::Empty; SLOTS],
            end_board: [0xFF; 13],
            mask,
        }
    }

    /// Put an operation in a joint's slot. `None` for IDs > 7.
    #[must_use]
    pub fn with_op(mut self, joint: JointId, op: RegisterOp) -> Option<Self> {
        *self.slots.get_mut(usize::from(joint.get()) - 1)? = RegisterSlot::Op(op);
        Some(self)
    }

    /// The slot of `joint` (`Empty` for IDs > 7).
    pub fn slot(&self, joint: JointId) -> RegisterSlot {
        self.slots
            .get(usize::from(joint.get()) - 1)
            .copied()
            .unwrap_or(RegisterSlot::Empty)
    }

    pub(crate) fn encode(&self, out: &mut [u8; 64]) {
        for (i, slot) in self.slots.iter().enumerate() {
            out[i * 7..i * 7 + 7].copy_from_slice(&slot.encode());
        }
        out[49] = 0xFF;
        out[50..63].copy_from_slice(&self.end_board);
        out[63] = self.mask.get();
    }

    pub(crate) fn decode(d: &[u8; 64]) -> Self {
        let mut slots = [RegisterSlot::Empty; SLOTS];
        for (i, slot) in slots.iter_mut().enumerate() {
            let mut s = [0u8; 7];
            s.copy_from_slice(&d[i * 7..i * 7 + 7]);
            *slot = RegisterSlot::decode(s);
        }
        let mut end_board = [0u8; 13];
        end_board.copy_from_slice(&d[50..63]);
        Self {
            slots,
            end_board,
            mask: ReplyMask(d[63] & 0xF),
        }
    }
}

impl BroadcastStatus {
    /// A status query with no end-board data.
    pub const fn new(mask: ReplyMask) -> Self {
        Self {
            end_board: [0; 23],
            mask,
        }
    }

    pub(crate) fn encode(&self, out: &mut [u8; 24]) {
        out[..23].copy_from_slice(&self.end_board);
        out[23] = self.mask.get();
    }

    pub(crate) fn decode(d: &[u8; 24]) -> Self {
        let mut end_board = [0u8; 23];
        end_board.copy_from_slice(&d[..23]);
        Self {
            end_board,
            mask: ReplyMask(d[23] & 0xF),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn register_slots() {
        let read = RegisterSlot::Op(RegisterOp::Read(
            ReadRange::new(RegisterAddr::new(0x14).unwrap(), 2).unwrap(),
        ));
        assert_eq!(read.encode(), [4, 1, 0x14, 2, 0, 0xFF, 0xFF]);
        assert_eq!(RegisterSlot::decode(read.encode()), read);
        // GRIP's form with 0xFF count high byte and a 3-byte length.
        assert_eq!(
            RegisterSlot::decode([4, 1, 0x14, 2, 0xFF, 0xFF, 0xFF]),
            read
        );
        assert_eq!(
            RegisterSlot::decode([3, 1, 0x14, 2, 0xFF, 0xFF, 0xFF]),
            read
        );
        assert_eq!(RegisterSlot::decode([0xFF; 7]), RegisterSlot::Empty);
        let bad = [5, 2, 0x30, 3, 0, 0, 0];
        assert_eq!(RegisterSlot::decode(bad), RegisterSlot::Invalid(bad));
        let past_end = [4, 1, 0x90, 5, 0, 0xFF, 0xFF];
        assert_eq!(
            RegisterSlot::decode(past_end),
            RegisterSlot::Invalid(past_end)
        );
    }
}
