//! Host-side commands: the 27 commands of the manual's appendix A-1, their packets and the
//! decoding of their replies.

use core::fmt;
use core::ops::Deref;

use crate::program::Program;
use crate::reply::{Reply, ReplyError};
use crate::values::{
    Accel, BaudRate, Boundaries, DGain, DataByte, ExtServoId, IGain, IoBits, Overload, PGain,
    Position, Position10, RangeError, Rotation, ServoId, Speed, TorqueLevel, WheelSpeed,
};

/// The packet header byte. It never occurs inside a packet: data bytes are 0..=254 and
/// checksums are masked to 7 bits.
pub const HEADER: u8 = 0xFF;

/// The longest packet: a synchronized move to 31 servos, 4 + 31 bytes.
pub const MAX_PACKET_LEN: usize = 35;

/// Every reply is two raw bytes, no header, no checksum.
pub const REPLY_LEN: usize = 2;

/// Set / read / extended command codes (byte 2 of a mode-7 packet; A-6).
pub mod code {
    /// (7) Baud rate set.
    pub const BAUD_SET: u8 = 0x08;
    /// (8) P, D gain set (EEPROM). Sent only by [`Command::GainSet`](crate::Command::GainSet).
    pub const GAIN_SET: u8 = 0x09;
    /// (9) P, D gain read.
    pub const GAIN_READ: u8 = 0x0A;
    /// (12) Runtime P, D gain set.
    pub const RUNTIME_GAIN_SET: u8 = 0x0B;
    /// (14) ID set. Sent only by [`Command::IdSet`](crate::Command::IdSet).
    pub const ID_SET: u8 = 0x0C;
    /// (15) Speed / acceleration set (EEPROM).
    pub const SPEED_SET: u8 = 0x0D;
    /// (16) Speed / acceleration read.
    pub const SPEED_READ: u8 = 0x0E;
    /// (18) Over-load set.
    pub const OVERLOAD_SET: u8 = 0x0F;
    /// (19) Over-load read.
    pub const OVERLOAD_READ: u8 = 0x10;
    /// (20) Boundary set.
    pub const BOUNDARY_SET: u8 = 0x11;
    /// (21) Boundary read.
    pub const BOUNDARY_READ: u8 = 0x12;
    /// (10) I gain set.
    pub const I_GAIN_SET: u8 = 0x15;
    /// (11) I gain read.
    pub const I_GAIN_READ: u8 = 0x16;
    /// (17) Runtime speed / acceleration set (no reply).
    pub const RUNTIME_SPEED_SET: u8 = 0x17;
    /// (13) Runtime I gain set.
    pub const RUNTIME_I_GAIN_SET: u8 = 0x18;
    /// (22) I/O write.
    pub const IO_WRITE: u8 = 0x64;
    /// (23) I/O read.
    pub const IO_READ: u8 = 0x65;
    /// (24) Motion data write.
    pub const MOTION_WRITE: u8 = 0x96;
    /// (25) Motion data read.
    pub const MOTION_READ: u8 = 0x97;
    /// (26) 10-bit position move (8-byte packet).
    pub const MOVE10: u8 = 0xC8;
    /// (27) 10-bit position read.
    pub const READ10: u8 = 0xC9;
}

/// XOR of `bytes`, masked to 7 bits: the checksum of every packet family, over the bytes
/// that family covers (see [`checksum_range`]).
pub const fn xor7(bytes: &[u8]) -> u8 {
    let mut acc = 0;
    let mut i = 0;
    while i < bytes.len() {
        acc ^= bytes[i];
        i += 1;
    }
    acc & 0x7F
}

/// The index range of a complete packet (header included, checksum excluded) that its
/// checksum covers, per family (the wCK protocol notes, "Packet shapes"):
/// 4-byte and 6-byte commands, motion write and the 10-bit commands cover byte 2..N
/// (index 1..len-1); the synchronized move covers only the position bytes (index 3..len-1).
pub const fn checksum_range(packet: &[u8]) -> core::ops::Range<usize> {
    let end = packet.len().saturating_sub(1);
    let is_sync = packet.len() > 2 && packet[1] & 0x1F == 0x1F && packet[1] >> 5 <= 4;
    let start = if is_sync { 3 } else { 1 };
    if start > end { end..end } else { start..end }
}

/// Which module(s) a command addresses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Target {
    /// One module, by its 5-bit ID (4- and 6-byte commands).
    Servo(ServoId),
    /// One module, by its full-byte ID (10-bit commands).
    Extended(ExtServoId),
    /// Every module on the channel (ID 31: synchronized move, break).
    Broadcast,
}

impl Target {
    /// Whether a module with ID `id` acts on the command.
    pub fn includes(self, id: ExtServoId) -> bool {
        match self {
            Self::Servo(s) => ExtServoId::from(s) == id,
            Self::Extended(e) => e == id,
            Self::Broadcast => true,
        }
    }
}

impl fmt::Display for Target {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Servo(id) => write!(f, "servo {id}"),
            Self::Extended(id) => write!(f, "servo {id} (10-bit)"),
            Self::Broadcast => f.write_str("all servos"),
        }
    }
}

/// Synchronized position move payload: one torque level and the target positions of IDs
/// `0..count` (A-1 (2)).
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct SyncMove {
    torque: TorqueLevel,
    // Invariant: slots at and after `count` hold position 0, so derived equality works.
    positions: [Position; 31],
    count: u8,
}

impl SyncMove {
    /// Maximum number of servos (IDs 0..=30).
    pub const MAX_SERVOS: usize = 31;

    /// Targets for IDs `0..positions.len()` (1..=31 positions).
    pub fn new(torque: TorqueLevel, positions: &[Position]) -> Result<Self, RangeError> {
        let count = positions.len();
        if !(1..=Self::MAX_SERVOS).contains(&count) {
            return Err(RangeError {
                what: "synchronized move servo count",
                value: u32::try_from(count).unwrap_or(u32::MAX),
                min: 1,
                max: 31,
            });
        }
        let mut all = [Position::MIN; 31];
        for (slot, p) in all.iter_mut().zip(positions) {
            *slot = *p;
        }
        #[allow(clippy::cast_possible_truncation)] // 1..=31
        let count = count as u8;
        Ok(Self {
            torque,
            positions: all,
            count,
        })
    }

    /// The torque level.
    pub const fn torque(&self) -> TorqueLevel {
        self.torque
    }

    /// Target positions, indexed by servo ID.
    pub fn positions(&self) -> &[Position] {
        self.positions.get(..usize::from(self.count)).unwrap_or(&[])
    }

    /// The target of servo `id`, if the move includes it.
    pub fn position_of(&self, id: ServoId) -> Option<Position> {
        self.positions().get(usize::from(id.get())).copied()
    }
}

// Shows only the used slots; the rest are padding.
#[allow(clippy::missing_fields_in_debug)]
impl fmt::Debug for SyncMove {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("SyncMove")
            .field("torque", &self.torque)
            .field("positions", &self.positions())
            .finish()
    }
}

/// A command packet, ready to write: at most [`MAX_PACKET_LEN`] bytes, stored inline.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct Packet {
    bytes: [u8; MAX_PACKET_LEN],
    len: u8,
}

impl Packet {
    fn from_slice(src: &[u8]) -> Self {
        let mut bytes = [0; MAX_PACKET_LEN];
        let len = src.len().min(MAX_PACKET_LEN);
        if let (Some(dst), Some(src)) = (bytes.get_mut(..len), src.get(..len)) {
            dst.copy_from_slice(src);
        }
        #[allow(clippy::cast_possible_truncation)] // at most 35
        let len = len as u8;
        Self { bytes, len }
    }

    /// The packet bytes.
    pub fn as_bytes(&self) -> &[u8] {
        self.bytes.get(..usize::from(self.len)).unwrap_or(&[])
    }
}

impl Deref for Packet {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        self.as_bytes()
    }
}

impl AsRef<[u8]> for Packet {
    fn as_ref(&self) -> &[u8] {
        self.as_bytes()
    }
}

impl fmt::Debug for Packet {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Packet({self})")
    }
}

impl fmt::Display for Packet {
    /// Hex bytes separated by spaces, like the manual prints them: `FF 00 7F 7F`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, b) in self.as_bytes().iter().enumerate() {
            if i > 0 {
                f.write_str(" ")?;
            }
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

/// One of the 27 commands of the manual's appendix A-1. The numbers in the variant docs are
/// the manual's example numbers.
///
/// Every field is a range-checked value, so every `Command` encodes to a valid packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Command {
    /// (1) Position move: go to `position` at `torque`; replies load and position.
    Move {
        /// Addressed module.
        id: ServoId,
        /// Torque level, 0 = max.
        torque: TorqueLevel,
        /// Target position.
        position: Position,
    },
    /// (2) Synchronized position move of IDs `0..n` (broadcast, no reply).
    SyncMove(SyncMove),
    /// (3) Status read: replies load and position.
    StatusRead {
        /// Addressed module.
        id: ServoId,
    },
    /// (4) Passive: release torque; replies position.
    Passive {
        /// Addressed module.
        id: ServoId,
    },
    /// (5) Wheel mode: turn continuously; replies rotation count and position.
    Wheel {
        /// Addressed module.
        id: ServoId,
        /// Direction.
        rotation: Rotation,
        /// Speed, 0 = stop.
        speed: WheelSpeed,
    },
    /// (6) Break: every module on the channel enters break mode; the answering module
    /// replies its ID and position.
    Break,
    /// (7) Baud rate set (EEPROM); replies the new code twice.
    BaudSet {
        /// Addressed module.
        id: ServoId,
        /// New rate.
        baud: BaudRate,
    },
    /// (8) P, D gain set (EEPROM, code 0x09); replies the new gains.
    GainSet {
        /// Addressed module.
        id: ServoId,
        /// New P gain.
        p: PGain,
        /// New D gain.
        d: DGain,
    },
    /// (9) P, D gain read.
    GainRead {
        /// Addressed module.
        id: ServoId,
    },
    /// (10) I gain set (EEPROM).
    IGainSet {
        /// Addressed module.
        id: ServoId,
        /// New I gain.
        i: IGain,
    },
    /// (11) I gain read.
    IGainRead {
        /// Addressed module.
        id: ServoId,
    },
    /// (12) Runtime P, D gain set (lost at power-off).
    RuntimeGainSet {
        /// Addressed module.
        id: ServoId,
        /// P gain.
        p: PGain,
        /// D gain.
        d: DGain,
    },
    /// (13) Runtime I gain set (lost at power-off).
    RuntimeIGainSet {
        /// Addressed module.
        id: ServoId,
        /// I gain.
        i: IGain,
    },
    /// (14) ID set (EEPROM, code 0x0C): renames the module; replies the new ID twice.
    IdSet {
        /// Addressed module (its current ID).
        id: ServoId,
        /// New ID, 0..=253. IDs above 30 are reachable only with the 10-bit commands; the
        /// manual's "new ID 0~254" includes 254, which no command could address, so it is
        /// refused.
        new_id: ExtServoId,
    },
    /// (15) Speed / acceleration set (EEPROM).
    SpeedSet {
        /// Addressed module.
        id: ServoId,
        /// Speed level.
        speed: Speed,
        /// Acceleration range.
        accel: Accel,
    },
    /// (16) Speed / acceleration read.
    SpeedRead {
        /// Addressed module.
        id: ServoId,
    },
    /// (17) Runtime speed / acceleration set (lost at power-off, **no reply**).
    RuntimeSpeedSet {
        /// Addressed module.
        id: ServoId,
        /// Speed level.
        speed: Speed,
        /// Acceleration range.
        accel: Accel,
    },
    /// (18) Over-load set (EEPROM).
    OverloadSet {
        /// Addressed module.
        id: ServoId,
        /// New threshold.
        overload: Overload,
    },
    /// (19) Over-load read.
    OverloadRead {
        /// Addressed module.
        id: ServoId,
    },
    /// (20) Boundary set (EEPROM).
    BoundarySet {
        /// Addressed module.
        id: ServoId,
        /// New boundaries.
        bounds: Boundaries,
    },
    /// (21) Boundary read.
    BoundaryRead {
        /// Addressed module.
        id: ServoId,
    },
    /// (22) I/O write: set the two digital outputs.
    IoWrite {
        /// Addressed module.
        id: ServoId,
        /// Output bits.
        outputs: IoBits,
    },
    /// (23) I/O read: replies the outputs and the 8-bit A/D input.
    IoRead {
        /// Addressed module.
        id: ServoId,
    },
    /// (24) Motion data write: store a self-running program (count 0 switches it off).
    MotionWrite {
        /// Addressed module.
        id: ServoId,
        /// The program.
        program: Program,
    },
    /// (25) Motion data read: replies the instruction count.
    MotionRead {
        /// Addressed module.
        id: ServoId,
    },
    /// (26) 10-bit position move: replies the current 10-bit position.
    Move10 {
        /// Addressed module.
        id: ExtServoId,
        /// Torque, a full data byte per the manual ("Torque(0~254)").
        torque: DataByte,
        /// Target position.
        position: Position10,
    },
    /// (27) 10-bit position read.
    Read10 {
        /// Addressed module.
        id: ExtServoId,
    },
}

const MODE_SET: u8 = 7 << 5;
/// Data byte 1 of the 10-bit commands: mode 7, low bits "arbitrary" (sent as 0).
const D1_10BIT: u8 = MODE_SET;
/// Data byte 2 of a passive command: mode 1 in the top nibble, low nibble arbitrary (0).
pub(crate) const PASSIVE_D2: u8 = 0x10;
/// Data byte 2 of a break command: mode 2 in the top nibble.
pub(crate) const BREAK_D2: u8 = 0x20;

fn op4(d1: u8, d2: u8) -> Packet {
    Packet::from_slice(&[HEADER, d1, d2, (d1 ^ d2) & 0x7F])
}

fn set6(id: ServoId, code: u8, d3: u8, d4: u8) -> Packet {
    let d1 = MODE_SET | id.get();
    Packet::from_slice(&[HEADER, d1, code, d3, d4, xor7(&[d1, code, d3, d4])])
}

impl Command {
    /// The command's name as the manual's A-1 headings give it (for messages).
    pub const fn name(&self) -> &'static str {
        match self {
            Self::Move { .. } => "position move",
            Self::SyncMove(_) => "synchronized position move",
            Self::StatusRead { .. } => "status read",
            Self::Passive { .. } => "passive",
            Self::Wheel { .. } => "wheel",
            Self::Break => "break",
            Self::BaudSet { .. } => "baud rate set",
            Self::GainSet { .. } => "P, D gain set",
            Self::GainRead { .. } => "P, D gain read",
            Self::IGainSet { .. } => "I gain set",
            Self::IGainRead { .. } => "I gain read",
            Self::RuntimeGainSet { .. } => "runtime P, D gain set",
            Self::RuntimeIGainSet { .. } => "runtime I gain set",
            Self::IdSet { .. } => "ID set",
            Self::SpeedSet { .. } => "speed set",
            Self::SpeedRead { .. } => "speed read",
            Self::RuntimeSpeedSet { .. } => "runtime speed set",
            Self::OverloadSet { .. } => "over-load set",
            Self::OverloadRead { .. } => "over-load read",
            Self::BoundarySet { .. } => "boundary set",
            Self::BoundaryRead { .. } => "boundary read",
            Self::IoWrite { .. } => "I/O write",
            Self::IoRead { .. } => "I/O read",
            Self::MotionWrite { .. } => "motion data write",
            Self::MotionRead { .. } => "motion data read",
            Self::Move10 { .. } => "10-bit position move",
            Self::Read10 { .. } => "10-bit position read",
        }
    }

    /// The set / read / extended code (byte 2 of a mode-7 packet), `None` for the 8-bit
    /// commands.
    pub const fn code(&self) -> Option<u8> {
        Some(match self {
            Self::Move { .. }
            | Self::SyncMove(_)
            | Self::StatusRead { .. }
            | Self::Passive { .. }
            | Self::Wheel { .. }
            | Self::Break => return None,
            Self::BaudSet { .. } => code::BAUD_SET,
            Self::GainSet { .. } => code::GAIN_SET,
            Self::GainRead { .. } => code::GAIN_READ,
            Self::IGainSet { .. } => code::I_GAIN_SET,
            Self::IGainRead { .. } => code::I_GAIN_READ,
            Self::RuntimeGainSet { .. } => code::RUNTIME_GAIN_SET,
            Self::RuntimeIGainSet { .. } => code::RUNTIME_I_GAIN_SET,
            Self::IdSet { .. } => code::ID_SET,
            Self::SpeedSet { .. } => code::SPEED_SET,
            Self::SpeedRead { .. } => code::SPEED_READ,
            Self::RuntimeSpeedSet { .. } => code::RUNTIME_SPEED_SET,
            Self::OverloadSet { .. } => code::OVERLOAD_SET,
            Self::OverloadRead { .. } => code::OVERLOAD_READ,
            Self::BoundarySet { .. } => code::BOUNDARY_SET,
            Self::BoundaryRead { .. } => code::BOUNDARY_READ,
            Self::IoWrite { .. } => code::IO_WRITE,
            Self::IoRead { .. } => code::IO_READ,
            Self::MotionWrite { .. } => code::MOTION_WRITE,
            Self::MotionRead { .. } => code::MOTION_READ,
            Self::Move10 { .. } => code::MOVE10,
            Self::Read10 { .. } => code::READ10,
        })
    }

    /// Which module(s) the command addresses.
    pub const fn target(&self) -> Target {
        match *self {
            Self::SyncMove(_) | Self::Break => Target::Broadcast,
            Self::Move10 { id, .. } | Self::Read10 { id } => Target::Extended(id),
            Self::Move { id, .. }
            | Self::StatusRead { id }
            | Self::Passive { id }
            | Self::Wheel { id, .. }
            | Self::BaudSet { id, .. }
            | Self::GainSet { id, .. }
            | Self::GainRead { id }
            | Self::IGainSet { id, .. }
            | Self::IGainRead { id }
            | Self::RuntimeGainSet { id, .. }
            | Self::RuntimeIGainSet { id, .. }
            | Self::IdSet { id, .. }
            | Self::SpeedSet { id, .. }
            | Self::SpeedRead { id }
            | Self::RuntimeSpeedSet { id, .. }
            | Self::OverloadSet { id, .. }
            | Self::OverloadRead { id }
            | Self::BoundarySet { id, .. }
            | Self::BoundaryRead { id }
            | Self::IoWrite { id, .. }
            | Self::IoRead { id }
            | Self::MotionWrite { id, .. }
            | Self::MotionRead { id } => Target::Servo(id),
        }
    }

    /// Whether the module stores the setting in EEPROM (about 121 ms turnaround, section
    /// 2-3), as opposed to operation, read and runtime commands.
    pub const fn writes_eeprom(&self) -> bool {
        matches!(
            self,
            Self::BaudSet { .. }
                | Self::GainSet { .. }
                | Self::IGainSet { .. }
                | Self::IdSet { .. }
                | Self::SpeedSet { .. }
                | Self::OverloadSet { .. }
                | Self::BoundarySet { .. }
                | Self::MotionWrite { .. }
        )
    }

    /// Length of the command packet in bytes: 4 for the 8-bit commands, 4 + N for a
    /// synchronized move to N servos, 6 for set / read / extended commands, 5 + 2·n for a
    /// motion data write of n instructions (header, data 1, code, count, pairs, checksum:
    /// the manual's example (24) is 13 bytes for 4 instructions) and 8 for the 10-bit move.
    pub const fn encoded_len(&self) -> usize {
        match self {
            Self::Move { .. }
            | Self::StatusRead { .. }
            | Self::Passive { .. }
            | Self::Wheel { .. }
            | Self::Break => 4,
            Self::SyncMove(s) => 4 + s.count as usize,
            Self::MotionWrite { program, .. } => 5 + 2 * program.len(),
            Self::Move10 { .. } => 8,
            _ => 6,
        }
    }

    /// Length of the reply in bytes: 2, or 0 for the synchronized move and the runtime
    /// speed set.
    pub const fn reply_len(&self) -> usize {
        match self {
            Self::SyncMove(_) | Self::RuntimeSpeedSet { .. } => 0,
            _ => REPLY_LEN,
        }
    }

    /// Encodes the command packet.
    #[must_use]
    pub fn encode(&self) -> Packet {
        match *self {
            Self::Move {
                id,
                torque,
                position,
            } => op4((torque.get() << 5) | id.get(), position.get()),
            Self::SyncMove(ref s) => {
                let mut bytes = [0u8; MAX_PACKET_LEN];
                bytes[0] = HEADER;
                bytes[1] = (s.torque.get() << 5) | ServoId::BROADCAST_RAW;
                bytes[2] = s.count;
                let mut cs = 0;
                for (dst, p) in bytes[3..].iter_mut().zip(s.positions()) {
                    *dst = p.get();
                    cs ^= p.get();
                }
                let n = 3 + usize::from(s.count);
                bytes[n] = cs & 0x7F;
                Packet::from_slice(&bytes[..=n])
            }
            Self::StatusRead { id } => op4((5 << 5) | id.get(), 0),
            Self::Passive { id } => op4((6 << 5) | id.get(), PASSIVE_D2),
            Self::Wheel {
                id,
                rotation,
                speed,
            } => op4((6 << 5) | id.get(), (rotation.nibble() << 4) | speed.get()),
            Self::Break => op4((6 << 5) | ServoId::BROADCAST_RAW, BREAK_D2),
            Self::BaudSet { id, baud } => set6(id, code::BAUD_SET, baud.code(), baud.code()),
            Self::GainSet { id, p, d } => set6(id, code::GAIN_SET, p.get(), d.get()),
            Self::GainRead { id } => set6(id, code::GAIN_READ, 0, 0),
            Self::IGainSet { id, i } => set6(id, code::I_GAIN_SET, i.get(), i.get()),
            Self::IGainRead { id } => set6(id, code::I_GAIN_READ, 0, 0),
            Self::RuntimeGainSet { id, p, d } => set6(id, code::RUNTIME_GAIN_SET, p.get(), d.get()),
            Self::RuntimeIGainSet { id, i } => set6(id, code::RUNTIME_I_GAIN_SET, i.get(), i.get()),
            Self::IdSet { id, new_id } => set6(id, code::ID_SET, new_id.get(), new_id.get()),
            Self::SpeedSet { id, speed, accel } => {
                set6(id, code::SPEED_SET, speed.get(), accel.get())
            }
            Self::SpeedRead { id } => set6(id, code::SPEED_READ, 0, 0),
            Self::RuntimeSpeedSet { id, speed, accel } => {
                set6(id, code::RUNTIME_SPEED_SET, speed.get(), accel.get())
            }
            Self::OverloadSet { id, overload } => {
                set6(id, code::OVERLOAD_SET, overload.get(), overload.get())
            }
            Self::OverloadRead { id } => set6(id, code::OVERLOAD_READ, 0, 0),
            Self::BoundarySet { id, bounds } => set6(
                id,
                code::BOUNDARY_SET,
                bounds.lower().get(),
                bounds.upper().get(),
            ),
            Self::BoundaryRead { id } => set6(id, code::BOUNDARY_READ, 0, 0),
            Self::IoWrite { id, outputs } => set6(id, code::IO_WRITE, outputs.get(), outputs.get()),
            Self::IoRead { id } => set6(id, code::IO_READ, 0, 0),
            Self::MotionWrite { id, ref program } => {
                let mut bytes = [0u8; MAX_PACKET_LEN];
                bytes[0] = HEADER;
                bytes[1] = MODE_SET | id.get();
                bytes[2] = code::MOTION_WRITE;
                bytes[3] = program.count().get();
                let mut n = 4;
                for (command, data) in program.pairs() {
                    bytes[n] = command;
                    bytes[n + 1] = data;
                    n += 2;
                }
                bytes[n] = xor7(&bytes[1..n]);
                Packet::from_slice(&bytes[..=n])
            }
            Self::MotionRead { id } => set6(id, code::MOTION_READ, 0, 0),
            Self::Move10 {
                id,
                torque,
                position,
            } => {
                let (h3, l7) = position.to_wire();
                let body = [D1_10BIT, code::MOVE10, id.get(), torque.get(), h3, l7];
                let cs = xor7(&body);
                Packet::from_slice(&[
                    HEADER, body[0], body[1], body[2], body[3], body[4], body[5], cs,
                ])
            }
            Self::Read10 { id } => {
                let body = [D1_10BIT, code::READ10, id.get(), id.get()];
                let cs = xor7(&body);
                Packet::from_slice(&[HEADER, body[0], body[1], body[2], body[3], cs])
            }
        }
    }

    /// Decodes and checks the reply to this command.
    ///
    /// Replies carry no checksum, so the check is for plausibility: the length, values in
    /// range, echoes equal to what was sent (a set command's reply repeats the new value)
    /// and bytes the manual sends twice being equal.
    pub fn decode_reply(&self, bytes: &[u8]) -> Result<Reply, ReplyError> {
        crate::reply::decode(self, bytes)
    }
}

impl fmt::Display for Command {
    /// A one-line human description, for example `position move servo 0 to 127 (torque 0)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let name = self.name();
        let target = self.target();
        match self {
            Self::Move {
                torque, position, ..
            } => {
                write!(f, "{name} {target} to {position} (torque {torque})")
            }
            Self::SyncMove(s) => {
                write!(f, "{name} torque {} positions [", s.torque())?;
                for (i, p) in s.positions().iter().enumerate() {
                    if i > 0 {
                        f.write_str(", ")?;
                    }
                    write!(f, "{p}")?;
                }
                f.write_str("]")
            }
            Self::Wheel {
                rotation, speed, ..
            } => {
                let dir = match rotation {
                    Rotation::Ccw => "ccw",
                    Rotation::Cw => "cw",
                };
                write!(f, "{name} {target} {dir} speed {speed}")
            }
            Self::BaudSet { baud, .. } => write!(f, "{name} {target} to {baud}"),
            Self::GainSet { p, d, .. } | Self::RuntimeGainSet { p, d, .. } => {
                write!(f, "{name} {target} P {p} D {d}")
            }
            Self::IGainSet { i, .. } | Self::RuntimeIGainSet { i, .. } => {
                write!(f, "{name} {target} I {i}")
            }
            Self::IdSet { new_id, .. } => write!(f, "{name} {target} to {new_id}"),
            Self::SpeedSet { speed, accel, .. } | Self::RuntimeSpeedSet { speed, accel, .. } => {
                write!(f, "{name} {target} speed {speed} accel {accel}")
            }
            Self::OverloadSet { overload, .. } => {
                write!(
                    f,
                    "{name} {target} to {overload} ({} mA)",
                    overload.milliamps()
                )
            }
            Self::BoundarySet { bounds, .. } => write!(f, "{name} {target} to {bounds}"),
            Self::IoWrite { outputs, .. } => write!(f, "{name} {target} outputs {outputs}"),
            Self::MotionWrite { program, .. } => {
                write!(f, "{name} {target}, {} instructions", program.len())
            }
            Self::Move10 {
                torque, position, ..
            } => {
                write!(f, "{name} {target} to {position} (torque {torque})")
            }
            _ => write!(f, "{name} {target}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn targets_say_who_acts() {
        let three = ServoId::new(3).unwrap();
        let status = Command::StatusRead { id: three };
        assert_eq!(status.target(), Target::Servo(three));
        assert!(status.target().includes(ExtServoId::new(3).unwrap()));
        assert!(!status.target().includes(ExtServoId::new(4).unwrap()));
        assert!(
            Command::Break
                .target()
                .includes(ExtServoId::new(200).unwrap())
        );
        let read10 = Command::Read10 {
            id: ExtServoId::new(200).unwrap(),
        };
        assert!(read10.target().includes(ExtServoId::new(200).unwrap()));
        assert!(!read10.target().includes(ExtServoId::new(3).unwrap()));
    }

    #[test]
    fn checksum_ranges_per_family() {
        assert_eq!(checksum_range(&[0xFF, 0x00, 0x7F, 0x7F]), 1..3);
        assert_eq!(checksum_range(&[0xFF, 0x1F, 0x02, 0x7F, 0x7F, 0x00]), 3..5);
        assert_eq!(checksum_range(&[0xFF, 0xDF, 0x20, 0x7F]), 1..3);
        assert_eq!(checksum_range(&[0xFF]), 0..0);
        assert_eq!(checksum_range(&[]), 0..0);
        assert_eq!(xor7(&[0xE0, 0x0B, 0x64, 0x64]), 0x6B);
    }

    #[test]
    fn packets_print_like_the_manual() {
        let p = Command::StatusRead {
            id: ServoId::new(0).unwrap(),
        }
        .encode();
        assert_eq!(p.to_string(), "FF A0 00 20");
        assert_eq!(format!("{p:?}"), "Packet(FF A0 00 20)");
    }
}
