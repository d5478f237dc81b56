//! The broadcast-frame protocol V1.1 (§8 of the WHJ joint protocol reference): one frame carries
//! data for joints 1..=7 and the end-effector board; the last byte holds a 4-bit reply mask.
//!
//! The types here are the payloads of [`Request::BroadcastPosition`](crate::Request) and
//! friends and of the 24-byte [`BroadcastFeedback`]. End-board bytes are kept raw (the
//! end board has its own protocol, §8.10).

use crate::ErrorCode;
use crate::id::JointId;
use crate::registers::{RegisterAddr, TABLE_LEN};
use crate::request::{ReadRange, WriteData};
use crate::units::{ActualSpeed, Current, Position, Temperature, Voltage};

/// Number of joint slots in a broadcast frame (joints 1..=7).
pub const SLOTS: usize = 7;

/// Which nodes answer a broadcast frame (low nibble of its last byte, §8.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ReplyMask(u8);

/// A reply-mask value above 15.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("broadcast reply mask {value} out of range (allowed: 0..=15)")]
pub struct ReplyMaskError {
    /// The value that was given.
    pub value: u8,
}

/// Bit i (0..=6) = joint i+1 answers; bit 7 = the end board answers.
const MASK_TABLE: [u8; 16] = [
    0x00, // 0 none
    0x0F, // 1 J1-J4
    0xF0, // 2 J5, J6, end, J7
    0x03, // 3 J1, J2
    0x0C, // 4 J3, J4
    0x30, // 5 J5, J6
    0xC0, // 6 end, J7
    0x01, // 7 J1
    0x02, // 8 J2
    0x04, // 9 J3
    0x08, // A J4
    0x10, // B J5
    0x20, // C J6
    0x40, // D J7
    0x80, // E end board
    0xFF, // F all
];

impl ReplyMask {
    /// Nobody answers.
    pub const NONE: Self = Self(0);
    /// Joints 1..=7 and the end board answer.
    pub const ALL: Self = Self(0xF);
    /// Only the end board answers.
    pub const END_BOARD: Self = Self(0xE);

    /// A mask from its 4-bit code.
    pub const fn new(raw: u8) -> Result<Self, ReplyMaskError> {
        if raw <= 0xF {
            Ok(Self(raw))
        } else {
            Err(ReplyMaskError { value: raw })
        }
    }

    /// The 4-bit code.
    pub const fn get(self) -> u8 {
        self.0
    }

    /// The code that selects exactly this joint (7 for J1 … 0xD for J7), `None` for IDs > 7.
    pub const fn only(joint: JointId) -> Option<Self> {
        if joint.has_broadcast_slot() {
            Some(Self(6 + joint.get()))
        } else {
            None
        }
    }

    /// Whether `joint` answers.
    pub const fn selects(self, joint: JointId) -> bool {
        joint.has_broadcast_slot() && MASK_TABLE[self.0 as usize] & (1 << (joint.get() - 1)) != 0
    }

    /// Whether the end board answers.
    pub const fn selects_end_board(self) -> bool {
        MASK_TABLE[self.0 as usize] & 0x80 != 0
    }

    /// The joints that answer.
    pub fn joints(self) -> impl Iterator<Item = JointId> {
        JointId::all().take(SLOTS).filter(move |j| self.selects(*j))
    }
}

/// A feed-forward source selected in the 0x2F flags byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FeedForward {
    /// 0: off.
    Off,
    /// 1: computed inside the servo.
    Internal,
    /// 2: the host's values from the slot.
    Host,
    /// 3: undocumented.
    Unknown(u8),
}

impl FeedForward {
    /// From a 2-bit field.
    pub const fn from_bits(bits: u8) -> Self {
        match bits & 3 {
            0 => Self::Off,
            1 => Self::Internal,
            2 => Self::Host,
            other => Self::Unknown(other),
        }
    }
    /// The 2-bit field.
    pub const fn bits(self) -> u8 {
        match self {
            Self::Off => 0,
            Self::Internal => 1,
            Self::Host => 2,
            Self::Unknown(b) => b & 3,
        }
    }
}

/// Where the two feed-forward selectors sit in the high nibble of 0x2F's last byte
/// (ambiguous in V1.1, conflict C17).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum FeedForwardLayout {
    /// GRIP's layout: speed in bits 7..6, current in bits 5..4 (default).
    #[default]
    Grip,
    /// The other reading: speed in bits 5..4, current in bits 7..6.
    Swapped,
}

/// The high nibble of 0x2F's last byte, kept raw because its layout is ambiguous (C17).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct FeedForwardBits(u8);

impl FeedForwardBits {
    /// Both feed-forwards off (what a client should send).
    pub const OFF: Self = Self(0);

    /// Encode the two selectors in the given layout.
    pub const fn new(speed: FeedForward, current: FeedForward, layout: FeedForwardLayout) -> Self {
        match layout {
            FeedForwardLayout::Grip => Self(speed.bits() << 2 | current.bits()),
            FeedForwardLayout::Swapped => Self(current.bits() << 2 | speed.bits()),
        }
    }

    /// From the 4-bit high nibble (bits 7..4 of the flags byte, shifted down).
    pub const fn from_nibble(nibble: u8) -> Self {
        Self(nibble & 0xF)
    }

    /// The 4-bit nibble.
    pub const fn nibble(self) -> u8 {
        self.0
    }

    /// The speed feed-forward selector under `layout`.
    pub const fn speed(self, layout: FeedForwardLayout) -> FeedForward {
        match layout {
            FeedForwardLayout::Grip => FeedForward::from_bits(self.0 >> 2),
            FeedForwardLayout::Swapped => FeedForward::from_bits(self.0),
        }
    }

    /// The current feed-forward selector under `layout`.
    pub const fn current(self, layout: FeedForwardLayout) -> FeedForward {
        match layout {
            FeedForwardLayout::Grip => FeedForward::from_bits(self.0),
            FeedForwardLayout::Swapped => FeedForward::from_bits(self.0 >> 2),
        }
    }
}

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

/// A joint's 24-byte answer to 0x2F, 0x4F and 0x7F (§8.8).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct BroadcastFeedback {
    /// Actual current.
    pub current: Current,
    /// Actual speed (0.02 RPM).
    pub speed: ActualSpeed,
    /// Actual position.
    pub position: Position,
    /// Error bits.
    pub error: ErrorCode,
    /// Bus voltage.
    pub voltage: Voltage,
    /// Temperature.
    pub temperature: Temperature,
    /// D18: bit 0 = enabled, bit 7 = brake locked; other bits kept raw.
    pub state: u8,
    /// D19..=D22: motor encoder count (undocumented; 0 in every example).
    pub encoder: i32,
    /// D23: broadcast receive counter (wraps 255 → 0).
    pub counter: u8,
}

impl BroadcastFeedback {
    /// Payload length in bytes.
    pub const LEN: usize = 24;
    /// `state` bit: drive enabled.
    pub const STATE_ENABLED: u8 = 0x01;
    /// `state` bit: brake locked.
    pub const STATE_BRAKE_LOCKED: u8 = 0x80;

    /// Whether the drive is enabled.
    pub const fn is_enabled(&self) -> bool {
        self.state & Self::STATE_ENABLED != 0
    }

    /// Whether the brake is locked.
    pub const fn brake_locked(&self) -> bool {
        self.state & Self::STATE_BRAKE_LOCKED != 0
    }

    /// The 24 wire bytes.
    pub fn encode(&self) -> [u8; 24] {
        let mut b = [0u8; 24];
        b[0..4].copy_from_slice(&self.current.0.to_le_bytes());
        b[4..8].copy_from_slice(&self.speed.0.to_le_bytes());
        b[8..12].copy_from_slice(&self.position.0.to_le_bytes());
        b[12..14].copy_from_slice(&self.error.0.to_le_bytes());
        b[14..16].copy_from_slice(&self.voltage.0.to_le_bytes());
        b[16..18].copy_from_slice(&self.temperature.0.to_le_bytes());
        b[18] = self.state;
        b[19..23].copy_from_slice(&self.encoder.to_le_bytes());
        b[23] = self.counter;
        b
    }

    /// Parse the 24 wire bytes.
    pub fn decode(b: &[u8; 24]) -> Self {
        let i32_at = |i: usize| i32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        Self {
            current: Current(i32_at(0)),
            speed: ActualSpeed(i32_at(4)),
            position: Position(i32_at(8)),
            error: ErrorCode(u16::from_le_bytes([b[12], b[13]])),
            voltage: Voltage(i16::from_le_bytes([b[14], b[15]])),
            temperature: Temperature(i16::from_le_bytes([b[16], b[17]])),
            state: b[18],
            encoder: i32_at(19),
            counter: b[23],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn j(n: u8) -> JointId {
        JointId::new(n).unwrap()
    }

    #[test]
    fn masks_follow_the_table() {
        let who = |m: u8| {
            let m = ReplyMask::new(m).unwrap();
            (
                m.joints().map(JointId::get).collect::<std::vec::Vec<_>>(),
                m.selects_end_board(),
            )
        };
        assert_eq!(who(0), (vec![], false));
        assert_eq!(who(1), (vec![1, 2, 3, 4], false));
        assert_eq!(who(2), (vec![5, 6, 7], true));
        assert_eq!(who(6), (vec![7], true));
        assert_eq!(who(0xE), (vec![], true));
        assert_eq!(who(0xF), (vec![1, 2, 3, 4, 5, 6, 7], true));
        for n in 1..=7 {
            assert_eq!(who(ReplyMask::only(j(n)).unwrap().get()), (vec![n], false));
        }
        assert!(ReplyMask::only(j(8)).is_none());
        assert!(!ReplyMask::ALL.selects(j(8)));
        assert_eq!(ReplyMask::new(16), Err(ReplyMaskError { value: 16 }));
    }

    #[test]
    fn feed_forward_layouts() {
        let g = FeedForwardBits::new(
            FeedForward::Internal,
            FeedForward::Host,
            FeedForwardLayout::Grip,
        );
        // GRIP: speed << 6 | current << 4 in the byte.
        assert_eq!(g.nibble() << 4, 1 << 6 | 2 << 4);
        assert_eq!(g.speed(FeedForwardLayout::Grip), FeedForward::Internal);
        assert_eq!(g.current(FeedForwardLayout::Swapped), FeedForward::Internal);
        assert_eq!(FeedForward::from_bits(3), FeedForward::Unknown(3));
    }

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
