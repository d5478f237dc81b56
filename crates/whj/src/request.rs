//! Host → joint frames: register commands, servo targets, status queries and broadcast
//! frames. [`Request::to_frame`] encodes (host side); [`Request::from_frame`] decodes what a
//! joint receives (device side) or says exactly why the frame is malformed.

use core::fmt;

use crate::broadcast::{BroadcastCurrent, BroadcastPosition, BroadcastRegister, BroadcastStatus};
use crate::frame::CanFrame;
use crate::id::{Address, BroadcastFunction, Function, JointId};
use crate::registers::{
    self, Access, Half, MAX_READ_COUNT, RegisterAddr, RegisterInfo, TABLE_LEN, WorkMode,
};
use crate::reply::CmdError;
use crate::units::{Current, Position, TargetSpeed};

/// Command byte of a register read.
pub const CMD_RD: u8 = 0x01;
/// Command byte of a register write.
pub const CMD_WR: u8 = 0x02;

/// A run of registers to read: `count` (1..=31) words from `start`, all inside the table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ReadRange {
    start: RegisterAddr,
    count: u8,
}

impl ReadRange {
    /// A range, or an error if `count` is 0, above 31, or runs past the table's end.
    pub const fn new(start: RegisterAddr, count: u8) -> Result<Self, RequestError> {
        if count == 0 || count > MAX_READ_COUNT {
            return Err(RequestError::ReadCount {
                count,
                max: MAX_READ_COUNT,
            });
        }
        if start.get() as usize + count as usize > TABLE_LEN {
            return Err(RequestError::ReadPastEnd {
                addr: start.get(),
                count,
            });
        }
        Ok(Self { start, count })
    }

    /// First register.
    pub const fn start(self) -> RegisterAddr {
        self.start
    }

    /// Number of registers.
    pub const fn count(self) -> u8 {
        self.count
    }

    /// Whether `addr` is inside the range.
    pub const fn contains(self, addr: RegisterAddr) -> bool {
        addr.get() >= self.start.get() && addr.get() < self.start.get() + self.count
    }
}

/// The data of a register write (conflict C5: the spec says 2 bytes, every example uses
/// 1, the target-position example uses 4).
///
/// The checked constructors ([`Request::write`], [`Request::write_i32`]) use
/// [`WriteData::Word`] for single registers and [`WriteData::Pair`] for 32-bit pairs, as
/// the reference advises; [`WriteData::Byte`] reproduces the vendor examples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum WriteData {
    /// 1 data byte, zero-extended into one register (`02 30 03`).
    Byte(u8),
    /// 2 data bytes LE, one register (the spec; the default for single registers).
    Word(u16),
    /// 4 data bytes LE: `index` := low word, `index + 1` := high word (`02 36 10 27 00 00`).
    Pair(i32),
}

impl WriteData {
    /// The data bytes and how many of them are used (1, 2 or 4).
    pub const fn to_bytes(self) -> ([u8; 4], usize) {
        match self {
            Self::Byte(b) => ([b, 0, 0, 0], 1),
            Self::Word(w) => {
                let [a, b] = w.to_le_bytes();
                ([a, b, 0, 0], 2)
            }
            Self::Pair(v) => (v.to_le_bytes(), 4),
        }
    }

    /// Number of data bytes on the wire.
    pub const fn len(self) -> usize {
        self.to_bytes().1
    }

    /// Whether there are no data bytes (never: at least one).
    pub const fn is_empty(self) -> bool {
        false
    }

    /// The register values written: one word, or (low, high) for a pair.
    pub const fn words(self) -> ([u16; 2], usize) {
        match self {
            Self::Byte(b) => ([b as u16, 0], 1),
            Self::Word(w) => ([w, 0], 1),
            Self::Pair(v) => (registers::split_i32(v), 2),
        }
    }

    /// Parse 1, 2 or 4 data bytes.
    pub fn from_bytes(data: &[u8]) -> Option<Self> {
        match *data {
            [b] => Some(Self::Byte(b)),
            [a, b] => Some(Self::Word(u16::from_le_bytes([a, b]))),
            [a, b, c, d] => Some(Self::Pair(i32::from_le_bytes([a, b, c, d]))),
            _ => None,
        }
    }
}

/// A frame from the host to joints.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Request {
    /// `0x000+ID [01, index, count]`: read `count` registers.
    Read {
        /// Addressed joint.
        joint: JointId,
        /// Registers to read.
        range: ReadRange,
    },
    /// `0x000+ID [02, index, data…]`: write 1, 2 or 4 bytes.
    Write {
        /// Addressed joint.
        joint: JointId,
        /// First register written.
        addr: RegisterAddr,
        /// The data.
        data: WriteData,
    },
    /// `0x200+ID`: position servo target.
    PositionServo {
        /// Addressed joint.
        joint: JointId,
        /// Target (0.0001°).
        target: Position,
    },
    /// `0x300+ID`: speed servo target.
    SpeedServo {
        /// Addressed joint.
        joint: JointId,
        /// Target (0.002 RPM).
        target: TargetSpeed,
    },
    /// `0x400+ID`: current servo target.
    CurrentServo {
        /// Addressed joint.
        joint: JointId,
        /// Target (1 or 2 mA per count by model).
        target: Current,
    },
    /// `0x600+ID`, no data: status query.
    StatusQuery {
        /// Addressed joint.
        joint: JointId,
    },
    /// 0x2F broadcast position frame.
    BroadcastPosition(BroadcastPosition),
    /// 0x4F broadcast current frame.
    BroadcastCurrent(BroadcastCurrent),
    /// 0x0F broadcast register frame.
    BroadcastRegister(BroadcastRegister),
    /// 0x7F broadcast status query.
    BroadcastStatus(BroadcastStatus),
}

/// A request the host refused to build (nothing is sent).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum RequestError {
    /// Read count outside 1..=31.
    #[error("read count {count} out of range (allowed: 1..={max})")]
    ReadCount {
        /// The count given.
        count: u8,
        /// Largest count.
        max: u8,
    },
    /// The read runs past the end of the table.
    #[error("read of {count} registers from {addr:#04x} runs past the table end 0x91")]
    ReadPastEnd {
        /// First register.
        addr: u8,
        /// The count given.
        count: u8,
    },
    /// The register is read-only.
    #[error("register {name} ({addr:#04x}) is read-only; write refused")]
    ReadOnly {
        /// Register address.
        addr: u8,
        /// Register name.
        name: &'static str,
    },
    /// The value is outside the register's documented range.
    #[error(
        "value {value} out of range for write to {name} ({addr:#04x}) (allowed: {min}..={max})"
    )]
    ValueOutOfRange {
        /// Register address.
        addr: u8,
        /// Register name.
        name: &'static str,
        /// The value given.
        value: i32,
        /// Smallest allowed.
        min: i32,
        /// Largest allowed.
        max: i32,
    },
    /// A 32-bit write must start at the low word of a documented pair.
    #[error("register {addr:#04x} is not the low word of a 32-bit pair; 4-byte write refused")]
    NotAPair {
        /// Register address.
        addr: u8,
    },
    /// A 16-bit write to half of a 32-bit pair would leave a torn value.
    #[error("register {addr:#04x} is half of a 32-bit pair; use write_i32")]
    HalfOfPair {
        /// Register address.
        addr: u8,
    },
}

impl Request {
    /// Read `count` registers from `addr` (checked: count 1..=31, inside the table).
    pub const fn read(joint: JointId, addr: RegisterAddr, count: u8) -> Result<Self, RequestError> {
        match ReadRange::new(addr, count) {
            Ok(range) => Ok(Self::Read { joint, range }),
            Err(e) => Err(e),
        }
    }

    /// Write one 16-bit register with the spec's 2-byte form. Refuses read-only registers,
    /// halves of 32-bit pairs and values outside the documented range. Reserved addresses
    /// are allowed (the joint acknowledges them with "failed").
    pub fn write(joint: JointId, addr: RegisterAddr, value: u16) -> Result<Self, RequestError> {
        if let Some(info) = addr.info() {
            check_writable(info)?;
            if info.half != Half::Single {
                return Err(RequestError::HalfOfPair { addr: addr.get() });
            }
            check_range(info, i32::from(value))?;
        }
        Ok(Self::Write {
            joint,
            addr,
            data: WriteData::Word(value),
        })
    }

    /// Write a 32-bit value to a pair in one 4-byte frame (`addr` is the low word).
    pub fn write_i32(joint: JointId, addr: RegisterAddr, value: i32) -> Result<Self, RequestError> {
        let Some(info) = addr.info().filter(|i| i.half == Half::Low) else {
            return Err(RequestError::NotAPair { addr: addr.get() });
        };
        check_writable(info)?;
        check_range(info, value)?;
        Ok(Self::Write {
            joint,
            addr,
            data: WriteData::Pair(value),
        })
    }

    /// `IAP_FLAG := 0` in the vendor's 1-byte form (`02 49 00`): start the application.
    pub const fn start_application(joint: JointId) -> Self {
        Self::Write {
            joint,
            addr: registers::addr::IAP_FLAG,
            data: WriteData::Byte(0),
        }
    }

    /// Enable (`true`) or disable the drive (`02 0A 01` / `02 0A 00`).
    pub const fn enable(joint: JointId, on: bool) -> Self {
        Self::Write {
            joint,
            addr: registers::addr::SYS_ENABLE_DRIVER,
            data: WriteData::Byte(on as u8),
        }
    }

    /// Set the work mode (`02 30 03` for position). Unknown modes are sent as 2 bytes.
    #[allow(clippy::cast_possible_truncation)] // checked <= 0xFF
    pub const fn set_mode(joint: JointId, mode: WorkMode) -> Self {
        let raw = mode.raw();
        let data = if raw <= 0xFF {
            WriteData::Byte(raw as u8)
        } else {
            WriteData::Word(raw)
        };
        Self::Write {
            joint,
            addr: registers::addr::TAG_WORK_MODE,
            data,
        }
    }

    /// Clear latched errors (`02 0F 01`).
    pub const fn clear_error(joint: JointId) -> Self {
        Self::Write {
            joint,
            addr: registers::addr::SYS_CLEAR_ERROR,
            data: WriteData::Byte(1),
        }
    }

    /// Make the present position 0° (`02 0E 01`).
    pub const fn set_zero(joint: JointId) -> Self {
        Self::Write {
            joint,
            addr: registers::addr::SYS_SET_ZERO_POS,
            data: WriteData::Byte(1),
        }
    }

    /// Save the RAM table to flash (`02 0C 01`; only while disabled, then wait 50 ms).
    pub const fn save_to_flash(joint: JointId) -> Self {
        Self::Write {
            joint,
            addr: registers::addr::SYS_SAVE_TO_FLASH,
            data: WriteData::Byte(1),
        }
    }

    /// Write the target position register pair (`02 36 <i32>`).
    pub const fn set_target_position(joint: JointId, target: Position) -> Self {
        Self::Write {
            joint,
            addr: registers::addr::TAG_POSITION,
            data: WriteData::Pair(target.0),
        }
    }

    /// Read the actual position pair (`01 14 02`).
    pub const fn read_position(joint: JointId) -> Self {
        Self::Read {
            joint,
            range: ReadRange {
                start: registers::addr::CUR_POSITION,
                count: 2,
            },
        }
    }

    /// Read actual current, speed and position (6 registers from 0x10).
    pub const fn read_motion(joint: JointId) -> Self {
        Self::Read {
            joint,
            range: ReadRange {
                start: registers::addr::CUR_CURRENT,
                count: 6,
            },
        }
    }

    /// Read the 96-bit unique ID (6 registers from 0x2A).
    pub const fn read_unique_id(joint: JointId) -> Self {
        Self::Read {
            joint,
            range: ReadRange {
                start: registers::addr::MOT_MODEL_ID,
                count: 6,
            },
        }
    }

    /// Read signature, ID, model and firmware version (4 registers from 0x00).
    pub const fn read_identity(joint: JointId) -> Self {
        Self::Read {
            joint,
            range: ReadRange {
                start: registers::addr::SIGNATURE,
                count: 4,
            },
        }
    }

    /// Read the position limits (4 registers from 0x44: min L/H, max L/H).
    pub const fn read_position_limits(joint: JointId) -> Self {
        Self::Read {
            joint,
            range: ReadRange {
                start: registers::addr::LIT_MIN_POSITION,
                count: 4,
            },
        }
    }

    /// The addressed joint, for point-to-point requests.
    pub const fn joint(&self) -> Option<JointId> {
        match self {
            Self::Read { joint, .. }
            | Self::Write { joint, .. }
            | Self::PositionServo { joint, .. }
            | Self::SpeedServo { joint, .. }
            | Self::CurrentServo { joint, .. }
            | Self::StatusQuery { joint } => Some(*joint),
            _ => None,
        }
    }

    /// The 11-bit CAN ID this request is sent on.
    pub const fn can_id(&self) -> u16 {
        match self {
            Self::Read { joint, .. } | Self::Write { joint, .. } => {
                joint.can_id(Function::RegisterCommand)
            }
            Self::PositionServo { joint, .. } => joint.can_id(Function::PositionServo),
            Self::SpeedServo { joint, .. } => joint.can_id(Function::SpeedServo),
            Self::CurrentServo { joint, .. } => joint.can_id(Function::CurrentServo),
            Self::StatusQuery { joint } => joint.can_id(Function::StatusQuery),
            Self::BroadcastPosition(_) => BroadcastFunction::Position.can_id(),
            Self::BroadcastCurrent(_) => BroadcastFunction::Current.can_id(),
            Self::BroadcastRegister(_) => BroadcastFunction::Register.can_id(),
            Self::BroadcastStatus(_) => BroadcastFunction::Status.can_id(),
        }
    }

    /// The CAN ID of the point-to-point answer (`0x100+ID`, `0x500+ID` or `0x700+ID`);
    /// `None` for broadcast frames (see [`ReplyMask`](crate::ReplyMask)).
    pub const fn reply_id(&self) -> Option<u16> {
        match self {
            Self::Read { joint, .. } | Self::Write { joint, .. } => {
                Some(joint.can_id(Function::Reply))
            }
            Self::PositionServo { joint, .. }
            | Self::SpeedServo { joint, .. }
            | Self::CurrentServo { joint, .. } => Some(joint.can_id(Function::ServoFeedback)),
            Self::StatusQuery { joint } => Some(joint.can_id(Function::StatusFeedback)),
            _ => None,
        }
    }

    /// Encode into a CAN FD frame (BRS on).
    pub fn to_frame(&self) -> CanFrame {
        let mut buf = [0u8; 64];
        let len = match self {
            Self::Read { range, .. } => {
                buf[..3].copy_from_slice(&[CMD_RD, range.start.get(), range.count]);
                3
            }
            Self::Write { addr, data, .. } => {
                let (bytes, n) = data.to_bytes();
                buf[0] = CMD_WR;
                buf[1] = addr.get();
                buf[2..2 + n].copy_from_slice(&bytes[..n]);
                2 + n
            }
            Self::PositionServo {
                target: Position(v),
                ..
            }
            | Self::SpeedServo {
                target: TargetSpeed(v),
                ..
            }
            | Self::CurrentServo {
                target: Current(v), ..
            } => return crate::fd_frame(self.can_id(), &v.to_le_bytes()),
            Self::StatusQuery { .. } => return crate::fd_frame(self.can_id(), &[]),
            Self::BroadcastPosition(b) => {
                b.encode(&mut buf);
                64
            }
            Self::BroadcastRegister(b) => {
                b.encode(&mut buf);
                64
            }
            Self::BroadcastCurrent(b) => {
                let mut d = [0u8; 48];
                b.encode(&mut d);
                buf[..48].copy_from_slice(&d);
                48
            }
            Self::BroadcastStatus(b) => {
                let mut d = [0u8; 24];
                b.encode(&mut d);
                buf[..24].copy_from_slice(&d);
                24
            }
        };
        crate::fd_frame(self.can_id(), &buf[..len])
    }

    /// Decode a frame as a joint receives it: the request, or exactly why it is malformed
    /// (including a write to a read-only register, which a joint answers with a
    /// permission error). Use [`Request::decode`] to skip the permission check.
    pub fn from_frame(frame: &CanFrame) -> Result<Self, Malformed> {
        let req = Self::decode(frame)?;
        req.check_permission().map_err(|addr| Malformed {
            id: frame.raw_id(),
            joint: req.joint(),
            reason: MalformedReason::ReadOnly { addr },
        })?;
        Ok(req)
    }

    /// Decode the frame's syntax only (no access check).
    pub fn decode(frame: &CanFrame) -> Result<Self, Malformed> {
        let id = frame.raw_id();
        let err = |joint: Option<JointId>, reason| Malformed { id, joint, reason };
        if !frame.is_fd() {
            return Err(err(None, MalformedReason::ClassicFrame));
        }
        let Some(raw) = frame.standard_raw_id() else {
            return Err(err(None, MalformedReason::ExtendedId));
        };
        let d = frame.data();
        // 0x0F is both joint 15's register command and the broadcast register frame; the
        // broadcast frame is the only 64-byte one.
        let address = if raw == BroadcastFunction::Register.can_id() && d.len() == 64 {
            Address::Broadcast(BroadcastFunction::Register)
        } else {
            Address::from_raw(raw)
        };
        match address {
            Address::Joint { function, joint } => {
                decode_p2p(function, joint, d).map_err(|reason| err(Some(joint), reason))
            }
            Address::Broadcast(f) => decode_broadcast(f, d).ok_or_else(|| {
                err(
                    None,
                    MalformedReason::BroadcastLength {
                        len: d.len(),
                        expected: f.payload_len(),
                    },
                )
            }),
            Address::InterfaceBoard { .. } => Err(err(None, MalformedReason::InterfaceBoard)),
            _ => Err(err(None, MalformedReason::NotARequest)),
        }
    }

    /// `Err(addr)` if this request writes a read-only register (in any slot).
    fn check_permission(&self) -> Result<(), u8> {
        let check = |addr: RegisterAddr, data: WriteData| {
            let (_, n) = data.words();
            for k in 0..n {
                #[allow(clippy::cast_possible_truncation)] // k < 2
                let a = addr.offset(k as u8).ok().and_then(RegisterAddr::info);
                if a.is_some_and(|i| i.access == Access::ReadOnly) {
                    #[allow(clippy::cast_possible_truncation)]
                    return Err(addr.get() + k as u8);
                }
            }
            Ok(())
        };
        match self {
            Self::Write { addr, data, .. } => check(*addr, *data),
            _ => Ok(()),
        }
    }
}

fn check_writable(info: &RegisterInfo) -> Result<(), RequestError> {
    if info.access.is_writable() {
        Ok(())
    } else {
        Err(RequestError::ReadOnly {
            addr: info.addr.get(),
            name: info.name,
        })
    }
}

fn check_range(info: &RegisterInfo, value: i32) -> Result<(), RequestError> {
    match info.range {
        Some((min, max)) if value < min || value > max => Err(RequestError::ValueOutOfRange {
            addr: info.addr.get(),
            name: info.name,
            value,
            min,
            max,
        }),
        _ => Ok(()),
    }
}

fn decode_p2p(function: Function, joint: JointId, d: &[u8]) -> Result<Request, MalformedReason> {
    let servo = |d: &[u8]| match *d {
        [b0, b1, b2, b3] => Ok(i32::from_le_bytes([b0, b1, b2, b3])),
        _ => Err(MalformedReason::ServoLength {
            function,
            len: d.len(),
        }),
    };
    match function {
        Function::RegisterCommand => decode_register(joint, d),
        Function::PositionServo => Ok(Request::PositionServo {
            joint,
            target: Position(servo(d)?),
        }),
        Function::SpeedServo => Ok(Request::SpeedServo {
            joint,
            target: TargetSpeed(servo(d)?),
        }),
        Function::CurrentServo => Ok(Request::CurrentServo {
            joint,
            target: Current(servo(d)?),
        }),
        Function::StatusQuery if d.is_empty() => Ok(Request::StatusQuery { joint }),
        Function::StatusQuery => Err(MalformedReason::StatusQueryLength { len: d.len() }),
        Function::Reply | Function::ServoFeedback | Function::StatusFeedback => {
            Err(MalformedReason::NotARequest)
        }
    }
}

fn decode_register(joint: JointId, d: &[u8]) -> Result<Request, MalformedReason> {
    let [cmd, index, rest @ ..] = d else {
        return Err(MalformedReason::TooShort { len: d.len() });
    };
    if rest.is_empty() {
        return Err(MalformedReason::TooShort { len: d.len() });
    }
    let addr = RegisterAddr::new(*index)
        .map_err(|_| MalformedReason::AddressOutOfTable { addr: *index })?;
    match *cmd {
        CMD_RD => {
            let [count] = *rest else {
                return Err(MalformedReason::ReadLength { len: d.len() });
            };
            match ReadRange::new(addr, count) {
                Ok(range) => Ok(Request::Read { joint, range }),
                Err(RequestError::ReadPastEnd { .. }) => Err(MalformedReason::ReadPastEnd {
                    addr: *index,
                    count,
                }),
                Err(_) => Err(MalformedReason::ReadCount { count }),
            }
        }
        CMD_WR => {
            let data = WriteData::from_bytes(rest).ok_or(MalformedReason::WriteLength {
                data_len: rest.len(),
            })?;
            if matches!(data, WriteData::Pair(_)) && addr.offset(1).is_err() {
                return Err(MalformedReason::AddressOutOfTable {
                    addr: index.wrapping_add(1),
                });
            }
            Ok(Request::Write { joint, addr, data })
        }
        other => Err(MalformedReason::UnknownCommand { cmd: other }),
    }
}

fn decode_broadcast(f: BroadcastFunction, d: &[u8]) -> Option<Request> {
    Some(match f {
        BroadcastFunction::Position => {
            Request::BroadcastPosition(BroadcastPosition::decode(d.try_into().ok()?))
        }
        BroadcastFunction::Current => {
            Request::BroadcastCurrent(BroadcastCurrent::decode(d.try_into().ok()?))
        }
        BroadcastFunction::Register => {
            Request::BroadcastRegister(BroadcastRegister::decode(d.try_into().ok()?))
        }
        BroadcastFunction::Status => {
            Request::BroadcastStatus(BroadcastStatus::decode(d.try_into().ok()?))
        }
    })
}

/// A frame a joint cannot act on, with the reason.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("malformed request on CAN ID {id:#05x}: {reason}")]
pub struct Malformed {
    /// Raw CAN ID of the frame.
    pub id: u32,
    /// The addressed joint, if the ID names one.
    pub joint: Option<JointId>,
    /// Why.
    pub reason: MalformedReason,
}

impl Malformed {
    /// What the addressed joint answers: `Some((joint, error))` for a `CMD_ERR` reply on
    /// `0x100+ID`, `None` if the frame is silently ignored (not for a joint, classic or
    /// extended frame, broadcast frame of the wrong length).
    pub const fn response(&self) -> Option<(JointId, CmdError)> {
        match (self.joint, self.reason.cmd_err()) {
            (Some(j), Some(e)) => Some((j, e)),
            _ => None,
        }
    }
}

/// Why a frame is not a valid request.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum MalformedReason {
    /// A classic CAN frame (joints ignore these).
    #[error("classic CAN frame (WHJ joints take CAN FD frames only)")]
    ClassicFrame,
    /// A 29-bit identifier.
    #[error("extended 29-bit identifier (WHJ uses 11-bit IDs)")]
    ExtendedId,
    /// Node 0, the interface board.
    #[error("addressed to node 0, the interface board")]
    InterfaceBoard,
    /// Not a host → joint ID (a reply ID or unknown).
    #[error("not a host-to-joint CAN ID")]
    NotARequest,
    /// Register command shorter than 3 bytes.
    #[error("register command of {len} bytes is too short (allowed: 3..=6)")]
    TooShort {
        /// Payload length.
        len: usize,
    },
    /// Command byte other than 0x01/0x02.
    #[error("unknown command byte {cmd:#04x} (allowed: 0x01 read, 0x02 write)")]
    UnknownCommand {
        /// The command byte.
        cmd: u8,
    },
    /// A read that is not exactly 3 bytes.
    #[error("read command of {len} bytes (allowed: 3)")]
    ReadLength {
        /// Payload length.
        len: usize,
    },
    /// A read count of 0 or above 31.
    #[error("read count {count} out of range (allowed: 1..=31)")]
    ReadCount {
        /// The count.
        count: u8,
    },
    /// A read past the table's end.
    #[error("read of {count} registers from {addr:#04x} runs past the table end 0x91")]
    ReadPastEnd {
        /// First register.
        addr: u8,
        /// The count.
        count: u8,
    },
    /// A write with other than 1, 2 or 4 data bytes.
    #[error("write with {data_len} data bytes (allowed: 1, 2 or 4)")]
    WriteLength {
        /// Number of data bytes.
        data_len: usize,
    },
    /// A register address outside the table.
    #[error("register address {addr:#04x} out of range (allowed: 0x00..=0x91)")]
    AddressOutOfTable {
        /// The address.
        addr: u8,
    },
    /// A servo frame that is not 4 bytes.
    #[error("{function:?} frame of {len} bytes (allowed: 4)")]
    ServoLength {
        /// The servo function.
        function: Function,
        /// Payload length.
        len: usize,
    },
    /// A status query with data.
    #[error("status query of {len} bytes (allowed: 0)")]
    StatusQueryLength {
        /// Payload length.
        len: usize,
    },
    /// A broadcast frame of the wrong length.
    #[error("broadcast frame of {len} bytes (allowed: {expected})")]
    BroadcastLength {
        /// Payload length.
        len: usize,
        /// Required length.
        expected: usize,
    },
    /// A write to a read-only register (permission error).
    #[error("write to read-only register {addr:#04x}")]
    ReadOnly {
        /// The read-only register.
        addr: u8,
    },
}

impl Malformed {
    /// The `CMD_ERR` reply a joint sends for this frame (default command byte
    /// [`CMD_ERR`](crate::reply::CMD_ERR)), or `None` if it stays silent.
    pub const fn reply(&self) -> Option<crate::Reply> {
        match self.response() {
            Some((joint, error)) => Some(crate::Reply::cmd_err(joint, error)),
            None => None,
        }
    }
}

impl MalformedReason {
    /// The `CMD_ERR` code a joint answers with, or `None` if it stays silent.
    pub const fn cmd_err(&self) -> Option<CmdError> {
        match self {
            Self::ClassicFrame
            | Self::ExtendedId
            | Self::InterfaceBoard
            | Self::NotARequest
            | Self::BroadcastLength { .. } => None,
            Self::ReadOnly { .. } => Some(CmdError::Permission),
            _ => Some(CmdError::Format),
        }
    }
}

impl fmt::Display for ReadRange {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} x{}", self.start, self.count)
    }
}
