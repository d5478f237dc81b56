//! A joint's 24-byte answer to the 0x2F, 0x4F and 0x7F broadcast frames (§8.8).

use crate::ErrorCode;
use crate::units::{ActualSpeed, Current, Position, Temperature, Voltage};

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
