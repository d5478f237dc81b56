//! The broadcast-frame protocol V1.1 (§8 of the WHJ joint protocol reference): one frame carries
//! data for joints 1..=7 and the end-effector board; the last byte holds a 4-bit reply mask.
//!
//! The types here are the payloads of [`Request::BroadcastPosition`](crate::Request) and
//! friends and of the 24-byte [`BroadcastFeedback`]. End-board bytes are kept raw (the
//! end board has its own protocol, §8.10).
use crate::id::JointId;

mod end_board;
mod feedback;
mod frames;

pub use end_board::{
    END_BOARD_READ, END_BOARD_READ_MAX, END_BOARD_REGISTERS, END_BOARD_REPLY_HEADER,
    END_BOARD_WRITE, END_BOARD_WRITE_MAX, EndBoardOp, EndBoardOpError, EndBoardRegister,
    EndBoardReply,
};
pub use feedback::BroadcastFeedback;
pub use frames::{
    BroadcastCurrent, BroadcastPosition, BroadcastRegister, BroadcastStatus, CURRENT_NO_DATA,
    POSITION_NO_DATA, PositionSlot, RegisterOp, RegisterSlot, is_no_data,
};

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
}
