//! Joint → host frames: read replies, write acknowledgements, `CMD_ERR`, servo feedback,
//! status feedback and broadcast answers. [`Reply::to_frame`] encodes (simulator side);
//! [`Reply::from_frame`] decodes (host side) with a typed error for anything malformed.

use core::fmt;

use crate::ErrorCode;
use crate::broadcast::BroadcastFeedback;
use crate::frame::CanFrame;
use crate::id::{Address, Function, JointId};
use crate::registers::{self, MAX_READ_COUNT, RegisterAddr, UniqueId, WorkMode};
use crate::request::{CMD_RD, CMD_WR, ReadRange};
use crate::units::{
    ActualSpeed, Current, FirmwareVersion, Model, Position, TargetSpeed, Temperature, Voltage,
};

/// The `CMD_ERR` command byte used by default (conflict C12: undocumented; LICH uses
/// 0xFF). Decoders recognise `CMD_ERR` by its 2-byte length whatever the byte is.
pub const CMD_ERR: u8 = 0xFF;

/// Up to 31 register words of a read reply (fixed capacity, no allocation).
///
/// Invariant: words past `len` are zero, so derived equality compares the content.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct Words {
    len: u8,
    buf: [u16; MAX_READ_COUNT as usize],
}

/// More words than a reply can hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("{len} register words do not fit one reply (allowed: 1..=31)")]
pub struct WordsError {
    /// The number of words given.
    pub len: usize,
}

impl Words {
    /// No words.
    pub const EMPTY: Self = Self {
        len: 0,
        buf: [0; MAX_READ_COUNT as usize],
    };

    /// Copy up to 31 words.
    pub fn from_slice(words: &[u16]) -> Result<Self, WordsError> {
        let mut w = Self::EMPTY;
        let dst = w
            .buf
            .get_mut(..words.len())
            .ok_or(WordsError { len: words.len() })?;
        dst.copy_from_slice(words);
        #[allow(clippy::cast_possible_truncation)] // <= 31
        {
            w.len = words.len() as u8;
        }
        Ok(w)
    }

    /// The words.
    pub fn as_slice(&self) -> &[u16] {
        &self.buf[..usize::from(self.len)]
    }

    /// Number of words.
    pub const fn len(&self) -> usize {
        self.len as usize
    }

    /// Whether there are no words.
    pub const fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Keep only the first `count` words (drop the padding of a padded reply).
    #[must_use]
    pub fn truncated(mut self, count: usize) -> Self {
        // Keep the invariant that words past `len` are zero, so equality is by content.
        for w in self.buf.iter_mut().skip(count) {
            *w = 0;
        }
        #[allow(clippy::cast_possible_truncation)] // min with len <= 31
        {
            self.len = self.len.min(count.min(usize::from(MAX_READ_COUNT)) as u8);
        }
        self
    }
}

impl fmt::Debug for Words {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list()
            .entries(self.as_slice().iter().map(|w| Hex(*w)))
            .finish()
    }
}

struct Hex(u16);
impl fmt::Debug for Hex {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:#06x}", self.0)
    }
}

/// The status byte of a write acknowledgement.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum WriteStatus {
    /// 0x01: success.
    Ok,
    /// 0x00: failure (reserved address, invalid value, refused).
    Failed,
    /// Any other byte.
    Unknown(u8),
}

impl WriteStatus {
    /// From the wire byte.
    pub const fn from_raw(raw: u8) -> Self {
        match raw {
            1 => Self::Ok,
            0 => Self::Failed,
            other => Self::Unknown(other),
        }
    }
    /// The wire byte.
    pub const fn raw(self) -> u8 {
        match self {
            Self::Ok => 1,
            Self::Failed => 0,
            Self::Unknown(b) => b,
        }
    }
    /// Whether the write succeeded.
    pub const fn is_ok(self) -> bool {
        matches!(self, Self::Ok)
    }
}

/// The error byte of a `CMD_ERR` reply (§2.4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CmdError {
    /// 0x01: the frame breaks the protocol.
    Format,
    /// 0x02: no right to do this (write to a read-only register).
    Permission,
    /// Any other byte.
    Unknown(u8),
}

impl CmdError {
    /// From the wire byte.
    pub const fn from_raw(raw: u8) -> Self {
        match raw {
            1 => Self::Format,
            2 => Self::Permission,
            other => Self::Unknown(other),
        }
    }
    /// The wire byte.
    pub const fn raw(self) -> u8 {
        match self {
            Self::Format => 1,
            Self::Permission => 2,
            Self::Unknown(b) => b,
        }
    }
}

impl fmt::Display for CmdError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Format => f.write_str("format error"),
            Self::Permission => f.write_str("permission error"),
            Self::Unknown(b) => write!(f, "unknown error {b:#04x}"),
        }
    }
}

/// The 16-byte servo feedback `0x500+ID` (§3.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ServoFeedback {
    /// Actual current.
    pub current: Current,
    /// Actual speed (0.02 RPM).
    pub speed: ActualSpeed,
    /// Actual position, before the new command is applied.
    pub position: Position,
    /// Enable state (1 = on), u16.
    pub enable: u16,
    /// Error bits.
    pub error: ErrorCode,
}

impl ServoFeedback {
    /// Payload length.
    pub const LEN: usize = 16;

    /// Whether the drive is enabled.
    pub const fn is_enabled(&self) -> bool {
        self.enable != 0
    }

    fn encode(&self) -> [u8; 16] {
        let mut b = [0u8; 16];
        b[0..4].copy_from_slice(&self.current.0.to_le_bytes());
        b[4..8].copy_from_slice(&self.speed.0.to_le_bytes());
        b[8..12].copy_from_slice(&self.position.0.to_le_bytes());
        b[12..14].copy_from_slice(&self.enable.to_le_bytes());
        b[14..16].copy_from_slice(&self.error.0.to_le_bytes());
        b
    }

    fn decode(b: &[u8; 16]) -> Self {
        Self {
            current: Current(i32_at(b, 0)),
            speed: ActualSpeed(i32_at(b, 4)),
            position: Position(i32_at(b, 8)),
            enable: u16::from_le_bytes([b[12], b[13]]),
            error: ErrorCode(u16::from_le_bytes([b[14], b[15]])),
        }
    }
}

fn i32_at(b: &[u8], i: usize) -> i32 {
    match b.get(i..i + 4) {
        Some(&[b0, b1, b2, b3]) => i32::from_le_bytes([b0, b1, b2, b3]),
        _ => 0,
    }
}

/// The status feedback `0x700+ID` (§3.3): 16 bytes, or 12 in the older layout without
/// current.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct JointStatus {
    /// Error bits.
    pub error: ErrorCode,
    /// Bus voltage.
    pub voltage: Voltage,
    /// Temperature.
    pub temperature: Temperature,
    /// Enable state (1 = on), u8.
    pub enable: u8,
    /// Brake state: 0 released, 1 locked.
    pub brake: u8,
    /// Actual position.
    pub position: Position,
    /// Actual current; `None` in the 12-byte layout.
    pub current: Option<Current>,
}

impl JointStatus {
    /// Whether the drive is enabled.
    pub const fn is_enabled(&self) -> bool {
        self.enable != 0
    }

    /// Whether the brake is locked.
    pub const fn brake_locked(&self) -> bool {
        self.brake != 0
    }

    fn encode(&self) -> ([u8; 16], usize) {
        let mut b = [0u8; 16];
        b[0..2].copy_from_slice(&self.error.0.to_le_bytes());
        b[2..4].copy_from_slice(&self.voltage.0.to_le_bytes());
        b[4..6].copy_from_slice(&self.temperature.0.to_le_bytes());
        b[6] = self.enable;
        b[7] = self.brake;
        b[8..12].copy_from_slice(&self.position.0.to_le_bytes());
        match self.current {
            Some(c) => {
                b[12..16].copy_from_slice(&c.0.to_le_bytes());
                (b, 16)
            }
            None => (b, 12),
        }
    }

    fn decode(b: &[u8]) -> Option<Self> {
        let current = match b.len() {
            16 => Some(Current(i32_at(b, 12))),
            12 => None,
            _ => return None,
        };
        Some(Self {
            error: ErrorCode(u16::from_le_bytes([b[0], b[1]])),
            voltage: Voltage(i16::from_le_bytes([b[2], b[3]])),
            temperature: Temperature(i16::from_le_bytes([b[4], b[5]])),
            enable: b[6],
            brake: b[7],
            position: Position(i32_at(b, 8)),
            current,
        })
    }
}

/// A joint's answer to a 0x0F broadcast register frame (on `0xF0+ID+1`, J6: 0x3FE).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BroadcastRegisterReply {
    /// `[02, index, status]`.
    WriteAck {
        /// Register written.
        addr: RegisterAddr,
        /// Outcome.
        status: WriteStatus,
    },
    /// `[01, index, data…]` (V1.1), or `[len, 01, index, data…]` (GRIP's parser, C19)
    /// when `length_prefix` is set.
    Read {
        /// First register.
        addr: RegisterAddr,
        /// The words (padding included when the frame was padded).
        words: Words,
        /// The leading length byte of GRIP's form, if present.
        length_prefix: Option<u8>,
    },
}

/// A frame from a joint.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Reply {
    /// `0x100+ID [01, index, words…]`. Padding of the frame shows up as extra zero words;
    /// use [`Words::truncated`] with the count you asked for.
    Read {
        /// Answering joint.
        joint: JointId,
        /// First register.
        addr: RegisterAddr,
        /// The words.
        words: Words,
    },
    /// `0x100+ID [02, index, status]`.
    WriteAck {
        /// Answering joint.
        joint: JointId,
        /// Register written.
        addr: RegisterAddr,
        /// Outcome.
        status: WriteStatus,
    },
    /// `0x100+ID [CMD_ERR, ERR]` (2 bytes).
    CmdErr {
        /// Answering joint.
        joint: JointId,
        /// The command byte as received (default [`CMD_ERR`]).
        code: u8,
        /// The error.
        error: CmdError,
    },
    /// `0x500+ID`: servo feedback.
    ServoFeedback {
        /// Answering joint.
        joint: JointId,
        /// The feedback.
        feedback: ServoFeedback,
    },
    /// `0x700+ID`: status feedback.
    Status {
        /// Answering joint.
        joint: JointId,
        /// The status.
        status: JointStatus,
    },
    /// `0x80+ID+1` (J6: 0x5FE): 24-byte broadcast feedback.
    BroadcastFeedback {
        /// Answering joint.
        joint: JointId,
        /// The feedback.
        feedback: BroadcastFeedback,
    },
    /// `0xF0+ID+1` (J6: 0x3FE): broadcast register reply.
    BroadcastRegister {
        /// Answering joint.
        joint: JointId,
        /// The reply.
        reply: BroadcastRegisterReply,
    },
}

/// A frame the host cannot read as a reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("malformed reply on CAN ID {id:#05x}: {reason}")]
pub struct ReplyError {
    /// Raw CAN ID.
    pub id: u32,
    /// Why.
    pub reason: ReplyErrorReason,
}

/// Why a frame is not a valid reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ReplyErrorReason {
    /// A classic CAN frame.
    #[error("classic CAN frame (joints answer with CAN FD)")]
    ClassicFrame,
    /// A 29-bit identifier.
    #[error("extended 29-bit identifier")]
    ExtendedId,
    /// The ID is not a joint → host reply ID (end-board replies included).
    #[error("not a joint reply ID")]
    NotAReply,
    /// Wrong payload length.
    #[error("{what} of {len} bytes (allowed: {allowed})")]
    Length {
        /// What the ID says the frame is.
        what: &'static str,
        /// Payload length.
        len: usize,
        /// Allowed lengths.
        allowed: &'static str,
    },
    /// First byte neither read, write nor a 2-byte `CMD_ERR`.
    #[error(
        "unknown reply command byte {cmd:#04x} in a {len}-byte reply (allowed: 0x01 read, 0x02 write, or any byte in a 2-byte CMD_ERR)"
    )]
    UnknownCommand {
        /// The byte.
        cmd: u8,
        /// Payload length.
        len: usize,
    },
    /// Register address outside the table.
    #[error("register address {addr:#04x} out of range (allowed: 0x00..=0x91)")]
    Address {
        /// The address.
        addr: u8,
    },
}

impl Reply {
    /// A read reply from register values (simulator side).
    pub fn read(joint: JointId, range: ReadRange, words: &[u16]) -> Result<Self, WordsError> {
        let words = Words::from_slice(words)?;
        Ok(Self::Read {
            joint,
            addr: range.start(),
            words,
        })
    }

    /// A `CMD_ERR` reply with the default command byte [`CMD_ERR`].
    pub const fn cmd_err(joint: JointId, error: CmdError) -> Self {
        Self::CmdErr {
            joint,
            code: CMD_ERR,
            error,
        }
    }

    /// The answering joint.
    pub const fn joint(&self) -> JointId {
        match self {
            Self::Read { joint, .. }
            | Self::WriteAck { joint, .. }
            | Self::CmdErr { joint, .. }
            | Self::ServoFeedback { joint, .. }
            | Self::Status { joint, .. }
            | Self::BroadcastFeedback { joint, .. }
            | Self::BroadcastRegister { joint, .. } => *joint,
        }
    }

    /// The 11-bit CAN ID the reply travels on.
    pub const fn can_id(&self) -> u16 {
        match self {
            Self::Read { joint, .. }
            | Self::WriteAck { joint, .. }
            | Self::CmdErr { joint, .. } => joint.can_id(Function::Reply),
            Self::ServoFeedback { joint, .. } => joint.can_id(Function::ServoFeedback),
            Self::Status { joint, .. } => joint.can_id(Function::StatusFeedback),
            Self::BroadcastFeedback { joint, .. } => Address::BroadcastFeedback(*joint).to_raw(),
            Self::BroadcastRegister { joint, .. } => {
                Address::BroadcastRegisterReply(*joint).to_raw()
            }
        }
    }

    /// Encode into a CAN FD frame (BRS on), padded with zeros to a legal length.
    pub fn to_frame(&self) -> CanFrame {
        let mut buf = [0u8; 64];
        let len = match self {
            Self::Read { addr, words, .. } => {
                buf[0] = CMD_RD;
                buf[1] = addr.get();
                put_words(&mut buf[2..], words) + 2
            }
            Self::WriteAck { addr, status, .. } => {
                buf[..3].copy_from_slice(&[CMD_WR, addr.get(), status.raw()]);
                3
            }
            Self::CmdErr { code, error, .. } => {
                buf[..2].copy_from_slice(&[*code, error.raw()]);
                2
            }
            Self::ServoFeedback { feedback, .. } => {
                buf[..16].copy_from_slice(&feedback.encode());
                16
            }
            Self::Status { status, .. } => {
                let (b, n) = status.encode();
                buf[..n].copy_from_slice(&b[..n]);
                n
            }
            Self::BroadcastFeedback { feedback, .. } => {
                buf[..24].copy_from_slice(&feedback.encode());
                24
            }
            Self::BroadcastRegister { reply, .. } => match reply {
                BroadcastRegisterReply::WriteAck { addr, status } => {
                    buf[..3].copy_from_slice(&[CMD_WR, addr.get(), status.raw()]);
                    3
                }
                BroadcastRegisterReply::Read {
                    addr,
                    words,
                    length_prefix: None,
                } => {
                    buf[0] = CMD_RD;
                    buf[1] = addr.get();
                    put_words(&mut buf[2..], words) + 2
                }
                BroadcastRegisterReply::Read {
                    addr,
                    words,
                    length_prefix: Some(n),
                } => {
                    buf[0] = *n;
                    buf[1] = CMD_RD;
                    buf[2] = addr.get();
                    // At most 30 words fit after a 3-byte header.
                    put_words(&mut buf[3..], &words.truncated(30)) + 3
                }
            },
        };
        crate::fd_frame(self.can_id(), &buf[..len])
    }

    /// Decode a frame received by the host.
    pub fn from_frame(frame: &CanFrame) -> Result<Self, ReplyError> {
        let id = frame.raw_id();
        let err = |reason| ReplyError { id, reason };
        if !frame.is_fd() {
            return Err(err(ReplyErrorReason::ClassicFrame));
        }
        let Some(raw) = frame.standard_raw_id() else {
            return Err(err(ReplyErrorReason::ExtendedId));
        };
        let d = frame.data();
        let length = |what, allowed| {
            err(ReplyErrorReason::Length {
                what,
                len: d.len(),
                allowed,
            })
        };
        match Address::from_raw(raw) {
            Address::Joint {
                function: Function::Reply,
                joint,
            } => decode_reply(joint, d).map_err(err),
            Address::Joint {
                function: Function::ServoFeedback,
                joint,
            } => {
                let b: &[u8; 16] = d.try_into().map_err(|_| length("servo feedback", "16"))?;
                Ok(Self::ServoFeedback {
                    joint,
                    feedback: ServoFeedback::decode(b),
                })
            }
            Address::Joint {
                function: Function::StatusFeedback,
                joint,
            } => {
                let status =
                    JointStatus::decode(d).ok_or_else(|| length("status feedback", "12 or 16"))?;
                Ok(Self::Status { joint, status })
            }
            Address::BroadcastFeedback(joint) => {
                let b: &[u8; 24] = d
                    .try_into()
                    .map_err(|_| length("broadcast feedback", "24"))?;
                Ok(Self::BroadcastFeedback {
                    joint,
                    feedback: BroadcastFeedback::decode(b),
                })
            }
            Address::BroadcastRegisterReply(joint) => decode_broadcast_register(d)
                .map(|reply| Self::BroadcastRegister { joint, reply })
                .map_err(err),
            _ => Err(err(ReplyErrorReason::NotAReply)),
        }
    }

    /// For a read reply: the i32 formed by the L/H pair at `addr` (low word) and `addr+1`,
    /// if both are in the reply.
    pub fn read_i32(&self, addr: RegisterAddr) -> Option<i32> {
        let Self::Read {
            addr: start, words, ..
        } = self
        else {
            return None;
        };
        let i = usize::from(addr.get().checked_sub(start.get())?);
        let w = words.as_slice();
        Some(registers::join_i32(*w.get(i)?, *w.get(i + 1)?))
    }

    /// For a read reply: the word at `addr`, if it is in the reply.
    pub fn read_word(&self, addr: RegisterAddr) -> Option<u16> {
        let Self::Read {
            addr: start, words, ..
        } = self
        else {
            return None;
        };
        let i = usize::from(addr.get().checked_sub(start.get())?);
        words.as_slice().get(i).copied()
    }
}

/// Typed views of the common registers in a read reply. Each returns `None` unless the
/// reply is a [`Reply::Read`] that covers the register(s).
impl Reply {
    /// Node ID (0x01).
    pub fn joint_id_register(&self) -> Option<u16> {
        self.read_word(registers::addr::SYS_ID)
    }
    /// Model (0x02).
    pub fn model(&self) -> Option<Model> {
        self.read_word(registers::addr::SYS_MODEL_TYPE)
            .map(Model::from_code)
    }
    /// Firmware version (0x03).
    pub fn firmware_version(&self) -> Option<FirmwareVersion> {
        self.read_word(registers::addr::SYS_FW_VERSION)
            .map(FirmwareVersion)
    }
    /// Error code (0x04).
    pub fn error_code(&self) -> Option<ErrorCode> {
        self.read_word(registers::addr::SYS_ERROR).map(ErrorCode)
    }
    /// Voltage (0x05).
    #[allow(clippy::cast_possible_wrap)] // registers are signed 16-bit words
    pub fn voltage(&self) -> Option<Voltage> {
        self.read_word(registers::addr::SYS_VOLTAGE)
            .map(|w| Voltage(w as i16))
    }
    /// Temperature (0x06).
    #[allow(clippy::cast_possible_wrap)] // registers are signed 16-bit words
    pub fn temperature(&self) -> Option<Temperature> {
        self.read_word(registers::addr::SYS_TEMP)
            .map(|w| Temperature(w as i16))
    }
    /// Drive enable (0x0A).
    pub fn enabled(&self) -> Option<bool> {
        self.read_word(registers::addr::SYS_ENABLE_DRIVER)
            .map(|w| w != 0)
    }
    /// IAP flag (0x49): `true` = firmware update mode.
    pub fn iap_flag(&self) -> Option<bool> {
        self.read_word(registers::addr::IAP_FLAG).map(|w| w != 0)
    }
    /// Work mode (0x30).
    pub fn work_mode(&self) -> Option<WorkMode> {
        self.read_word(registers::addr::TAG_WORK_MODE)
            .map(WorkMode::from_raw)
    }
    /// Actual current (0x10/0x11).
    pub fn actual_current(&self) -> Option<Current> {
        self.read_i32(registers::addr::CUR_CURRENT).map(Current)
    }
    /// Actual speed (0x12/0x13).
    pub fn actual_speed(&self) -> Option<ActualSpeed> {
        self.read_i32(registers::addr::CUR_SPEED).map(ActualSpeed)
    }
    /// Actual position (0x14/0x15).
    pub fn actual_position(&self) -> Option<Position> {
        self.read_i32(registers::addr::CUR_POSITION).map(Position)
    }
    /// Target current (0x32/0x33).
    pub fn target_current(&self) -> Option<Current> {
        self.read_i32(registers::addr::TAG_CURRENT).map(Current)
    }
    /// Target speed (0x34/0x35).
    pub fn target_speed(&self) -> Option<TargetSpeed> {
        self.read_i32(registers::addr::TAG_SPEED).map(TargetSpeed)
    }
    /// Target position (0x36/0x37).
    pub fn target_position(&self) -> Option<Position> {
        self.read_i32(registers::addr::TAG_POSITION).map(Position)
    }
    /// Position limits (0x44..=0x47) as (min, max).
    pub fn position_limits(&self) -> Option<(Position, Position)> {
        Some((
            Position(self.read_i32(registers::addr::LIT_MIN_POSITION)?),
            Position(self.read_i32(registers::addr::LIT_MAX_POSITION)?),
        ))
    }
    /// The 96-bit unique ID (0x2A..=0x2F).
    pub fn unique_id(&self) -> Option<UniqueId> {
        let mut id = [0u16; 6];
        for (k, slot) in (0u8..).zip(id.iter_mut()) {
            *slot = self.read_word(registers::addr::MOT_MODEL_ID.offset(k).ok()?)?;
        }
        Some(UniqueId(id))
    }
}

fn put_words(out: &mut [u8], words: &Words) -> usize {
    let mut n = 0;
    for (chunk, w) in out.chunks_exact_mut(2).zip(words.as_slice()) {
        chunk.copy_from_slice(&w.to_le_bytes());
        n += 2;
    }
    n
}

fn take_words(data: &[u8]) -> Words {
    let mut w = Words::EMPTY;
    let mut n = 0u8;
    for (slot, c) in w.buf.iter_mut().zip(data.chunks_exact(2)) {
        *slot = u16::from_le_bytes([c[0], c[1]]);
        n += 1;
    }
    w.len = n;
    w
}

fn addr_of(raw: u8) -> Result<RegisterAddr, ReplyErrorReason> {
    RegisterAddr::new(raw).map_err(|_| ReplyErrorReason::Address { addr: raw })
}

fn decode_reply(joint: JointId, d: &[u8]) -> Result<Reply, ReplyErrorReason> {
    match *d {
        [code, error] => Ok(Reply::CmdErr {
            joint,
            code,
            error: CmdError::from_raw(error),
        }),
        [CMD_WR, index, status] => Ok(Reply::WriteAck {
            joint,
            addr: addr_of(index)?,
            status: WriteStatus::from_raw(status),
        }),
        [CMD_RD, index, ref data @ ..] if data.len() >= 2 && data.len() % 2 == 0 => {
            Ok(Reply::Read {
                joint,
                addr: addr_of(index)?,
                words: take_words(data),
            })
        }
        [CMD_RD, ..] => Err(ReplyErrorReason::Length {
            what: "read reply",
            len: d.len(),
            allowed: "4..=64, even",
        }),
        [CMD_WR, ..] => Err(ReplyErrorReason::Length {
            what: "write ack",
            len: d.len(),
            allowed: "3",
        }),
        [cmd, ..] => Err(ReplyErrorReason::UnknownCommand { cmd, len: d.len() }),
        [] => Err(ReplyErrorReason::Length {
            what: "register reply",
            len: 0,
            allowed: "2..=64",
        }),
    }
}

fn decode_broadcast_register(d: &[u8]) -> Result<BroadcastRegisterReply, ReplyErrorReason> {
    match *d {
        [CMD_WR, index, status] => Ok(BroadcastRegisterReply::WriteAck {
            addr: addr_of(index)?,
            status: WriteStatus::from_raw(status),
        }),
        [CMD_RD, index, ref data @ ..] if data.len() >= 2 && data.len() % 2 == 0 => {
            Ok(BroadcastRegisterReply::Read {
                addr: addr_of(index)?,
                words: take_words(data),
                length_prefix: None,
            })
        }
        [n, CMD_RD, index, ref data @ ..] if data.len() >= 2 => Ok(BroadcastRegisterReply::Read {
            addr: addr_of(index)?,
            words: take_words(data),
            length_prefix: Some(n),
        }),
        [cmd, ..] => Err(ReplyErrorReason::UnknownCommand { cmd, len: d.len() }),
        [] => Err(ReplyErrorReason::Length {
            what: "broadcast register reply",
            len: 0,
            allowed: "3..=64",
        }),
    }
}
