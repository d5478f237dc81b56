//! Node IDs, CAN-ID function offsets and the mapping between CAN IDs and their meaning.
//!
//! A point-to-point CAN ID is `function offset + node ID` (§1.4 of
//! the WHJ joint protocol reference): `0x201` is a position servo command for joint 1. Node 0 is
//! the interface board, never a joint; it is reported as [`Address::InterfaceBoard`]. The
//! broadcast protocol (§8) adds the function IDs 0x0F, 0x2F, 0x4F, 0x7F and its own reply
//! IDs.
//!
//! **Collision:** the broadcast register frame 0x0F is also the register-command ID of
//! joint 15 (0x000 + 15). [`Address::from_raw`] reports joint 15; the frame decoders tell
//! the two apart by length (a broadcast register frame is 64 bytes, a register command
//! 3..=6). Avoid ID 15 on buses that use broadcast frames.

use core::fmt;

/// A joint's node ID on the bus: 1..=30 (`SYS_ID`, register 0x01).
///
/// ID 0 is the interface board (also called the broadcast ID) and is not a `JointId`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct JointId(u8);

/// A joint ID outside 1..=30.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("joint ID {value} out of range (allowed: 1..=30; 0 is the interface board)")]
pub struct JointIdError {
    /// The value that was given.
    pub value: u32,
}

impl JointId {
    /// Smallest joint ID.
    pub const MIN: Self = Self(1);
    /// Largest joint ID.
    pub const MAX: Self = Self(30);
    /// Factory default ID of a new joint.
    pub const FACTORY_DEFAULT: Self = Self(1);

    /// A joint ID from its raw value, or an error naming the value and the range 1..=30.
    pub const fn new(raw: u8) -> Result<Self, JointIdError> {
        if raw >= 1 && raw <= 30 {
            Ok(Self(raw))
        } else {
            Err(JointIdError { value: raw as u32 })
        }
    }

    /// The raw ID (1..=30).
    pub const fn get(self) -> u8 {
        self.0
    }

    /// Iterate over every joint ID, 1 to 30.
    pub fn all() -> impl Iterator<Item = Self> {
        (1..=30).map(Self)
    }

    /// The 11-bit CAN ID this joint uses for `function`.
    pub const fn can_id(self, function: Function) -> u16 {
        function.offset() + self.0 as u16
    }

    /// Whether this joint has a slot in the broadcast protocol (IDs 1..=7).
    pub const fn has_broadcast_slot(self) -> bool {
        self.0 <= 7
    }

    /// The CAN ID of this joint's 24-byte broadcast feedback (answer to 0x2F, 0x4F, 0x7F):
    /// `0x80 + ID + 1`, except joint 6 which uses 0x5FE (0x87 belongs to the end board).
    /// `None` for joints without a broadcast slot (ID > 7).
    pub const fn broadcast_feedback_id(self) -> Option<u16> {
        match self.0 {
            6 => Some(BROADCAST_FEEDBACK_J6_ID),
            1..=7 => Some(0x80 + self.0 as u16 + 1),
            _ => None,
        }
    }

    /// The CAN ID of this joint's broadcast register reply (answer to 0x0F):
    /// `0xF0 + ID + 1`, except joint 6 which uses 0x3FE (0xF7 belongs to the end board).
    /// `None` for joints without a broadcast slot (ID > 7).
    pub const fn broadcast_register_reply_id(self) -> Option<u16> {
        match self.0 {
            6 => Some(BROADCAST_REGISTER_REPLY_J6_ID),
            1..=7 => Some(0xF0 + self.0 as u16 + 1),
            _ => None,
        }
    }
}

impl TryFrom<u8> for JointId {
    type Error = JointIdError;
    fn try_from(raw: u8) -> Result<Self, Self::Error> {
        Self::new(raw)
    }
}

impl From<JointId> for u8 {
    fn from(id: JointId) -> u8 {
        id.0
    }
}

impl fmt::Display for JointId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "J{}", self.0)
    }
}

/// The function part of a point-to-point CAN ID (`CAN ID = offset + node ID`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Function {
    /// 0x000: register read/write command, host → joint.
    RegisterCommand,
    /// 0x100: read reply, write acknowledgement or `CMD_ERR`, joint → host.
    Reply,
    /// 0x200: position servo target (i32, 0.0001°), host → joint.
    PositionServo,
    /// 0x300: speed servo target (i32, 0.002 RPM), host → joint.
    SpeedServo,
    /// 0x400: current servo target (i32, mA or 2 mA), host → joint.
    CurrentServo,
    /// 0x500: 16-byte servo feedback, joint → host.
    ServoFeedback,
    /// 0x600: status query (0 bytes), host → joint.
    StatusQuery,
    /// 0x700: status feedback (16 or 12 bytes), joint → host.
    StatusFeedback,
}

impl Function {
    /// All functions in CAN-ID order.
    pub const ALL: [Self; 8] = [
        Self::RegisterCommand,
        Self::Reply,
        Self::PositionServo,
        Self::SpeedServo,
        Self::CurrentServo,
        Self::ServoFeedback,
        Self::StatusQuery,
        Self::StatusFeedback,
    ];

    /// The CAN-ID offset (0x000, 0x100, … 0x700).
    pub const fn offset(self) -> u16 {
        match self {
            Self::RegisterCommand => 0x000,
            Self::Reply => 0x100,
            Self::PositionServo => 0x200,
            Self::SpeedServo => 0x300,
            Self::CurrentServo => 0x400,
            Self::ServoFeedback => 0x500,
            Self::StatusQuery => 0x600,
            Self::StatusFeedback => 0x700,
        }
    }

    /// The function whose offset is `offset` (a multiple of 0x100 up to 0x700).
    pub const fn from_offset(offset: u16) -> Option<Self> {
        match offset {
            0x000 => Some(Self::RegisterCommand),
            0x100 => Some(Self::Reply),
            0x200 => Some(Self::PositionServo),
            0x300 => Some(Self::SpeedServo),
            0x400 => Some(Self::CurrentServo),
            0x500 => Some(Self::ServoFeedback),
            0x600 => Some(Self::StatusQuery),
            0x700 => Some(Self::StatusFeedback),
            _ => None,
        }
    }

    /// Whether frames of this function travel host → joint.
    pub const fn is_request(self) -> bool {
        matches!(
            self,
            Self::RegisterCommand
                | Self::PositionServo
                | Self::SpeedServo
                | Self::CurrentServo
                | Self::StatusQuery
        )
    }
}

/// The broadcast-protocol function IDs (§8.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BroadcastFunction {
    /// 0x0F: register read/write for joints 1..=7 (64 bytes).
    Register,
    /// 0x2F: position servo for joints 1..=7 (64 bytes).
    Position,
    /// 0x4F: current servo for joints 1..=7 (48 bytes).
    Current,
    /// 0x7F: status query (24 bytes).
    Status,
}

impl BroadcastFunction {
    /// The CAN ID of this broadcast frame.
    pub const fn can_id(self) -> u16 {
        match self {
            Self::Register => 0x0F,
            Self::Position => 0x2F,
            Self::Current => 0x4F,
            Self::Status => 0x7F,
        }
    }

    /// The payload length of this broadcast frame in bytes (64, 64, 48, 24).
    pub const fn payload_len(self) -> usize {
        match self {
            Self::Register | Self::Position => 64,
            Self::Current => 48,
            Self::Status => 24,
        }
    }
}

/// CAN ID on which joint 6 sends its 24-byte broadcast feedback.
pub const BROADCAST_FEEDBACK_J6_ID: u16 = 0x5FE;
/// CAN ID on which joint 6 sends its broadcast register reply.
pub const BROADCAST_REGISTER_REPLY_J6_ID: u16 = 0x3FE;
/// CAN ID of the end-effector board's broadcast feedback (0x2F/0x4F/0x7F).
pub const END_BOARD_FEEDBACK_ID: u16 = 0x87;
/// CAN ID of the end-effector board's broadcast register reply (0x0F).
pub const END_BOARD_REGISTER_REPLY_ID: u16 = 0xF7;
/// CAN ID reserved for IAP firmware data (protocol not public).
pub const IAP_DATA_ID: u16 = 0x7F0;

/// What an 11-bit CAN ID means on a WHJ bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Address {
    /// A point-to-point frame to or from a joint.
    Joint {
        /// The function offset.
        function: Function,
        /// The joint.
        joint: JointId,
    },
    /// A point-to-point frame to or from node 0, the interface board (joints ignore it).
    InterfaceBoard {
        /// The function offset.
        function: Function,
    },
    /// A broadcast-protocol frame (host → joints 1..=7 and end board). 0x0F is reported
    /// as joint 15's register command instead; see the module docs.
    Broadcast(BroadcastFunction),
    /// A joint's 24-byte broadcast feedback (0x82..=0x88 without 0x87, or 0x5FE).
    BroadcastFeedback(JointId),
    /// A joint's broadcast register reply (0xF2..=0xF8 without 0xF7, or 0x3FE).
    BroadcastRegisterReply(JointId),
    /// The end-effector board's broadcast feedback (0x87).
    EndBoardFeedback,
    /// The end-effector board's broadcast register reply (0xF7).
    EndBoardRegisterReply,
    /// IAP firmware data (0x7F0; protocol not public).
    IapData,
    /// Any other ID (kept as a value).
    Unknown(u16),
}

impl Address {
    /// Classify a raw 11-bit CAN ID. Values above 0x7FF are [`Address::Unknown`].
    pub const fn from_raw(raw: u16) -> Self {
        match raw {
            0x2F => return Self::Broadcast(BroadcastFunction::Position),
            0x4F => return Self::Broadcast(BroadcastFunction::Current),
            0x7F => return Self::Broadcast(BroadcastFunction::Status),
            END_BOARD_FEEDBACK_ID => return Self::EndBoardFeedback,
            END_BOARD_REGISTER_REPLY_ID => return Self::EndBoardRegisterReply,
            BROADCAST_FEEDBACK_J6_ID => return Self::BroadcastFeedback(JointId(6)),
            BROADCAST_REGISTER_REPLY_J6_ID => return Self::BroadcastRegisterReply(JointId(6)),
            IAP_DATA_ID => return Self::IapData,
            #[allow(clippy::cast_possible_truncation)] // 1..=7
            0x82..=0x88 => return Self::BroadcastFeedback(JointId((raw - 0x81) as u8)),
            #[allow(clippy::cast_possible_truncation)] // 1..=7
            0xF2..=0xF8 => return Self::BroadcastRegisterReply(JointId((raw - 0xF1) as u8)),
            _ => {}
        }
        let node = raw & 0xFF;
        let Some(function) = Function::from_offset(raw & 0x700) else {
            return Self::Unknown(raw);
        };
        if raw > 0x7FF {
            Self::Unknown(raw)
        } else if node == 0 {
            Self::InterfaceBoard { function }
        } else if node <= 30 {
            Self::Joint {
                function,
                joint: JointId(node as u8),
            }
        } else {
            Self::Unknown(raw)
        }
    }

    /// The raw 11-bit CAN ID of this address.
    pub const fn to_raw(self) -> u16 {
        match self {
            Self::Joint { function, joint } => joint.can_id(function),
            Self::InterfaceBoard { function } => function.offset(),
            Self::Broadcast(f) => f.can_id(),
            Self::BroadcastFeedback(j) => match j.broadcast_feedback_id() {
                Some(id) => id,
                None => 0x81 + j.0 as u16,
            },
            Self::BroadcastRegisterReply(j) => match j.broadcast_register_reply_id() {
                Some(id) => id,
                None => 0xF1 + j.0 as u16,
            },
            Self::EndBoardFeedback => END_BOARD_FEEDBACK_ID,
            Self::EndBoardRegisterReply => END_BOARD_REGISTER_REPLY_ID,
            Self::IapData => IAP_DATA_ID,
            Self::Unknown(raw) => raw,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn joint_id_range() {
        assert_eq!(JointId::new(0), Err(JointIdError { value: 0 }));
        assert_eq!(JointId::new(31), Err(JointIdError { value: 31 }));
        assert_eq!(JointId::new(30).unwrap().get(), 30);
        assert_eq!(JointId::all().count(), 30);
        let msg = std::string::ToString::to_string(&JointId::new(31).unwrap_err());
        assert!(msg.contains("31") && msg.contains("1..=30"), "{msg}");
    }

    #[test]
    fn addresses_round_trip() {
        for raw in 0..=0x7FFu16 {
            let a = Address::from_raw(raw);
            assert_eq!(a.to_raw(), raw, "{raw:#x} -> {a:?}");
        }
        let j1 = JointId::new(1).unwrap();
        assert_eq!(
            Address::from_raw(0x201),
            Address::Joint {
                function: Function::PositionServo,
                joint: j1
            }
        );
        assert_eq!(
            Address::from_raw(0x600),
            Address::InterfaceBoard {
                function: Function::StatusQuery
            }
        );
        assert_eq!(Address::from_raw(0x82), Address::BroadcastFeedback(j1));
        assert_eq!(
            Address::from_raw(0x5FE),
            Address::BroadcastFeedback(JointId::new(6).unwrap())
        );
        assert_eq!(Address::from_raw(0x87), Address::EndBoardFeedback);
        assert_eq!(Address::from_raw(0x11F), Address::Unknown(0x11F));
        assert_eq!(
            Address::from_raw(0x00F),
            Address::Joint {
                function: Function::RegisterCommand,
                joint: JointId::new(15).unwrap()
            }
        );
    }

    #[test]
    fn broadcast_reply_ids() {
        let ids: std::vec::Vec<_> = (1..=7)
            .map(|i| JointId::new(i).unwrap().broadcast_feedback_id().unwrap())
            .collect();
        assert_eq!(ids, [0x82, 0x83, 0x84, 0x85, 0x86, 0x5FE, 0x88]);
        assert_eq!(
            JointId::new(7).unwrap().broadcast_register_reply_id(),
            Some(0xF8)
        );
        assert_eq!(
            JointId::new(6).unwrap().broadcast_register_reply_id(),
            Some(0x3FE)
        );
        assert_eq!(JointId::new(8).unwrap().broadcast_feedback_id(), None);
    }
}
