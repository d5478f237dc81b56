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

/// End-board command byte: read registers.
pub const END_BOARD_READ: u8 = 0x01;
/// End-board command byte: write registers.
pub const END_BOARD_WRITE: u8 = 0x02;
/// Largest number of data bytes an end-board write carries (the 13-byte 0x0F slot less
/// its 3-byte header).
pub const END_BOARD_WRITE_MAX: usize = 10;
/// Largest register count of an end-board read (the 64-byte reply less its 8-byte header
/// holds 28 words; the client asks for far fewer).
pub const END_BOARD_READ_MAX: u8 = 16;

/// One operation in the end board's slot of a broadcast frame (§8.10):
/// `[cmd, index, len, data…]`, without the leading length byte of a joint slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EndBoardOp {
    /// `[01, index, count]`: read `count` 16-bit registers from `index`; the reply's
    /// length byte counts bytes (2 per register).
    Read {
        /// First register of the end board's own map.
        index: u8,
        /// Registers, 1..=[`END_BOARD_READ_MAX`].
        count: u8,
    },
    /// `[02, index, len, data…]`: write `len` bytes (little-endian, 2 per register) from
    /// `index`; the reply's data byte is 1 on success.
    Write {
        /// First register of the end board's own map.
        index: u8,
        /// Data bytes used, 1..=[`END_BOARD_WRITE_MAX`].
        len: u8,
        /// The data (`len` bytes used).
        data: [u8; END_BOARD_WRITE_MAX],
    },
}

/// An end-board operation that does not fit its field.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum EndBoardOpError {
    /// A read count outside 1..=[`END_BOARD_READ_MAX`].
    #[error("end-board read of {count} registers (allowed: 1..={END_BOARD_READ_MAX})")]
    Count {
        /// The count given.
        count: u8,
    },
    /// Write data of a length outside 1..=[`END_BOARD_WRITE_MAX`] bytes.
    #[error("end-board write of {len} bytes (allowed: 1..={END_BOARD_WRITE_MAX})")]
    Length {
        /// The length given.
        len: usize,
    },
}

impl EndBoardOp {
    /// A read of `count` registers from `index`.
    pub const fn read(index: u8, count: u8) -> Result<Self, EndBoardOpError> {
        if count == 0 || count > END_BOARD_READ_MAX {
            return Err(EndBoardOpError::Count { count });
        }
        Ok(Self::Read { index, count })
    }

    /// A write of `bytes` from `index`.
    pub fn write(index: u8, bytes: &[u8]) -> Result<Self, EndBoardOpError> {
        let len = bytes.len();
        if len == 0 || len > END_BOARD_WRITE_MAX {
            return Err(EndBoardOpError::Length { len });
        }
        let mut data = [0u8; END_BOARD_WRITE_MAX];
        data[..len].copy_from_slice(bytes);
        #[allow(clippy::cast_possible_truncation)] // len <= 10
        Ok(Self::Write {
            index,
            len: len as u8,
            data,
        })
    }

    /// The first register.
    pub const fn index(&self) -> u8 {
        match self {
            Self::Read { index, .. } | Self::Write { index, .. } => *index,
        }
    }

    /// Writes the operation into an end-board field padded with `fill`; `false` (and the
    /// field unchanged) when it does not fit.
    pub fn encode_into(&self, field: &mut [u8], fill: u8) -> bool {
        let bytes: &[u8] = match self {
            Self::Read { .. } => &[],
            Self::Write { len, data, .. } => &data[..usize::from(*len)],
        };
        if field.len() < 3 + bytes.len() {
            return false;
        }
        field.fill(fill);
        match self {
            Self::Read { index, count } => {
                field[..3].copy_from_slice(&[END_BOARD_READ, *index, *count]);
            }
            Self::Write { index, len, .. } => {
                field[..3].copy_from_slice(&[END_BOARD_WRITE, *index, *len]);
                field[3..3 + bytes.len()].copy_from_slice(bytes);
            }
        }
        true
    }

    /// Parses an end-board field: `None` when its command byte is neither read nor write
    /// (0x00 / 0xFF padding: no operation) or the operation does not fit.
    pub fn decode(field: &[u8]) -> Option<Self> {
        match *field {
            [END_BOARD_READ, index, count, ..] => Self::read(index, count).ok(),
            [END_BOARD_WRITE, index, len, ref rest @ ..] => {
                Self::write(index, rest.get(..usize::from(len))?).ok()
            }
            _ => None,
        }
    }
}

/// Header length of an end-board reply (0x87 / 0xF7).
pub const END_BOARD_REPLY_HEADER: usize = 8;

/// The end board's answer (0xF7 to 0x0F, 0x87 to the other broadcast frames, §8.10):
/// `D0` broadcast counter · `D1` status0 · `D2` status1 · `D3` Modbus read length ·
/// `D4` system error · `D5` cmd · `D6` index · `D7` len · `D8…` data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct EndBoardReply {
    /// Broadcast frames received (wraps 255 → 0).
    pub counter: u8,
    /// Status bits, 7→0: DIO1 mode, DIO2 mode, teach button, replay button, DIO1 state,
    /// gripper in position, hand in position, DIO2 state.
    pub status0: u8,
    /// Reserved.
    pub status1: u8,
    /// Modbus bytes read.
    pub modbus_read_len: u8,
    /// System error.
    pub sys_error: u8,
    /// The command answered (1 read, 2 write; 0 when the slot held none).
    pub cmd: u8,
    /// The register answered.
    pub index: u8,
    /// Length byte: data bytes of a read; of a write, the length written.
    pub len: u8,
    data: [u8; 64 - END_BOARD_REPLY_HEADER],
    data_len: u8,
}

impl EndBoardReply {
    /// A reply (simulator side); `data` beyond 56 bytes is cut.
    pub fn new(header: [u8; END_BOARD_REPLY_HEADER], data: &[u8]) -> Self {
        let n = data.len().min(64 - END_BOARD_REPLY_HEADER);
        let mut d = [0u8; 64 - END_BOARD_REPLY_HEADER];
        d[..n].copy_from_slice(&data[..n]);
        #[allow(clippy::cast_possible_truncation)] // n <= 56
        Self {
            counter: header[0],
            status0: header[1],
            status1: header[2],
            modbus_read_len: header[3],
            sys_error: header[4],
            cmd: header[5],
            index: header[6],
            len: header[7],
            data: d,
            data_len: n as u8,
        }
    }

    /// Parses a reply payload (at least the 8-byte header).
    pub fn decode(payload: &[u8]) -> Option<Self> {
        let header: [u8; END_BOARD_REPLY_HEADER] =
            payload.get(..END_BOARD_REPLY_HEADER)?.try_into().ok()?;
        Some(Self::new(header, &payload[END_BOARD_REPLY_HEADER..]))
    }

    /// The data bytes after the header (a frame's padding included).
    pub fn data(&self) -> &[u8] {
        &self.data[..usize::from(self.data_len)]
    }

    /// The payload (header, then data).
    pub fn encode(&self, out: &mut [u8; 64]) -> usize {
        out[..END_BOARD_REPLY_HEADER].copy_from_slice(&[
            self.counter,
            self.status0,
            self.status1,
            self.modbus_read_len,
            self.sys_error,
            self.cmd,
            self.index,
            self.len,
        ]);
        let n = usize::from(self.data_len);
        out[END_BOARD_REPLY_HEADER..END_BOARD_REPLY_HEADER + n].copy_from_slice(self.data());
        END_BOARD_REPLY_HEADER + n
    }

    /// Whether this answers `op`: the same command and register, and a read's length
    /// byte covers the registers asked for.
    pub fn answers(&self, op: &EndBoardOp) -> bool {
        match op {
            EndBoardOp::Read { index, count } => {
                self.cmd == END_BOARD_READ
                    && self.index == *index
                    && usize::from(self.len) >= 2 * usize::from(*count)
                    && self.data().len() >= 2 * usize::from(*count)
            }
            EndBoardOp::Write { index, .. } => {
                self.cmd == END_BOARD_WRITE && self.index == *index && !self.data().is_empty()
            }
        }
    }

    /// The `i`-th 16-bit word of a read reply.
    pub fn word(&self, i: usize) -> Option<u16> {
        let d = self.data();
        Some(u16::from_le_bytes([*d.get(2 * i)?, *d.get(2 * i + 1)?]))
    }

    /// Whether a write reply says it succeeded (data byte 1).
    pub fn write_ok(&self) -> bool {
        self.cmd == END_BOARD_WRITE && self.data().first() == Some(&1)
    }
}

/// One register of the end board's own map (§8.10; unrelated to a joint's table).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EndBoardRegister {
    /// Address.
    pub addr: u8,
    /// Name.
    pub name: &'static str,
    /// Whether the host may write it.
    pub writable: bool,
    /// What it is.
    pub meaning: &'static str,
}

const fn eb(
    addr: u8,
    name: &'static str,
    writable: bool,
    meaning: &'static str,
) -> EndBoardRegister {
    EndBoardRegister {
        addr,
        name,
        writable,
        meaning,
    }
}

/// The end board's registers (0x60..=0x6F write and 0x70..=0x7F read buffers of the Modbus
/// bridge are listed by their first address).
pub const END_BOARD_REGISTERS: [EndBoardRegister; 17] = [
    eb(0x02, "EB_MODEL_TYPE", false, "end board model"),
    eb(
        0x03,
        "EB_SW_VERSION",
        false,
        "software version, major byte then minor byte",
    ),
    eb(
        0x07,
        "EB_VOLTAGE_OUTPUT",
        true,
        "tool power: 0 = 0 V, 2 = 12 V, 3 = 24 V",
    ),
    eb(
        0x0C,
        "EB_SAVE_TO_FLASH",
        true,
        "1 = save 0x00..=0x0B to flash",
    ),
    eb(
        0x0F,
        "EB_MODBUS_RTU",
        true,
        "RS-485 Modbus RTU: 0 off, 1 = 9600, 2 = 115200, 3 = 460800 baud",
    ),
    eb(0x10, "EB_TEACH_IO", false, "teach button: 1 = pressed"),
    eb(
        0x11,
        "EB_TRAJECTORY_RECORD",
        false,
        "replay button: 1 = pressed and released",
    ),
    eb(
        0x1D,
        "EB_IO1_MODE",
        true,
        "digital channel 1: 0 = input, 1 = output",
    ),
    eb(
        0x1E,
        "EB_IO2_MODE",
        true,
        "digital channel 2: 0 = input, 1 = output",
    ),
    eb(
        0x1F,
        "EB_ON_DELAY",
        true,
        "0 = delayed power-up, 1 = no delay",
    ),
    eb(
        0x33,
        "EB_FORCE_FX_L",
        false,
        "force/torque sensor Fx..Mz, L/H pairs 0x33..=0x3E",
    ),
    eb(
        0x5C,
        "EB_MODBUS_WRITE_LEN",
        true,
        "bytes in the Modbus write buffer",
    ),
    eb(
        0x5D,
        "EB_MODBUS_READ_LEN",
        true,
        "bytes read into the Modbus read buffer",
    ),
    eb(
        0x60,
        "EB_MODBUS_WRITE",
        true,
        "Modbus write buffer 0x60..=0x6F (32 bytes)",
    ),
    eb(
        0x70,
        "EB_MODBUS_READ",
        false,
        "Modbus read buffer 0x70..=0x7F",
    ),
    eb(0x78, "EB_ERROR", false, "error code"),
    eb(
        0x79,
        "EB_END_BOARD_MODE",
        true,
        "0 = the end board is not a joint, 1 = it acts as one",
    ),
];

impl EndBoardRegister {
    /// The register at `addr` (the Modbus buffers and the sensor pairs by any of their
    /// addresses).
    pub fn by_addr(addr: u8) -> Option<&'static Self> {
        let base = match addr {
            0x34..=0x3E => 0x33,
            0x61..=0x6F => 0x60,
            0x71..=0x7F => 0x70,
            a => a,
        };
        END_BOARD_REGISTERS.iter().find(|r| r.addr == base)
    }

    /// The register named `name` (case-insensitive, with or without `EB_`).
    pub fn by_name(name: &str) -> Option<&'static Self> {
        END_BOARD_REGISTERS.iter().find(|r| {
            r.name.eq_ignore_ascii_case(name)
                || r.name
                    .get(3..)
                    .is_some_and(|n| n.eq_ignore_ascii_case(name))
        })
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

    #[test]
    fn end_board_ops_and_replies_follow_the_worked_examples() {
        // 0x0F with D50..: `02 1D 01 01` (IO1 := output), padded with 0xFF.
        let op = EndBoardOp::write(0x1D, &[1]).unwrap();
        let mut field = [0u8; 13];
        assert!(op.encode_into(&mut field, 0xFF));
        assert_eq!(field[..5], [2, 0x1D, 1, 1, 0xFF]);
        assert_eq!(EndBoardOp::decode(&field), Some(op));
        // 0x7F `02 07 01 03 00…` (tool power := 24 V) -> 0x87 `B8 09 00 00 00 02 07 01 01`.
        let reply = EndBoardReply::decode(&[0xB8, 9, 0, 0, 0, 2, 7, 1, 1]).unwrap();
        assert!(reply.answers(&EndBoardOp::write(7, &[3]).unwrap()) && reply.write_ok());
        assert_eq!(reply.counter, 0xB8);
        // A read of 7 registers is answered with 14 data bytes.
        let read = EndBoardOp::read(0x70, 7).unwrap();
        let mut r = [0u8; 22];
        r[..8].copy_from_slice(&[0xC7, 9, 0, 0x0D, 0, 1, 0x70, 0x0E]);
        r[8..10].copy_from_slice(&[0x02, 0x03]);
        let reply = EndBoardReply::decode(&r).unwrap();
        assert!(reply.answers(&read));
        assert_eq!(reply.word(0), Some(0x0302));
        assert!(!reply.answers(&EndBoardOp::read(0x71, 7).unwrap()));
        // Too long for the 7-byte field of 0x2F; bounds.
        let long = EndBoardOp::write(0x60, &[0; 5]).unwrap();
        let mut seven = [0xAA; 7];
        assert!(!long.encode_into(&mut seven, 0xFF));
        assert_eq!(seven, [0xAA; 7]);
        assert_eq!(
            EndBoardOp::read(1, 0),
            Err(EndBoardOpError::Count { count: 0 })
        );
        assert_eq!(
            EndBoardOp::write(1, &[0; 11]),
            Err(EndBoardOpError::Length { len: 11 })
        );
        assert_eq!(EndBoardOp::decode(&[0; 13]), None);
        assert_eq!(EndBoardRegister::by_name("io1_mode").unwrap().addr, 0x1D);
        assert_eq!(
            EndBoardRegister::by_addr(0x65).unwrap().name,
            "EB_MODBUS_WRITE"
        );
    }
}
