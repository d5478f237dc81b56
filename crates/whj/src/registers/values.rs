//! Register values: the signature, work modes, the unique ID, the initial values and the
//! 32-bit L/H pairs as words.

use core::fmt;

use super::{Half, REGISTERS, TABLE_LEN};

/// Value of register 0x00 on every joint.
pub const SIGNATURE_VALUE: u16 = 0x1314;

/// The work mode in register 0x30. Unknown values survive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum WorkMode {
    /// 0: open loop (duty in 0x31; not recommended).
    OpenLoop,
    /// 1: current (torque) servo.
    Current,
    /// 2: speed servo.
    Speed,
    /// 3: position servo (factory default).
    Position,
    /// Any other value.
    Unknown(u16),
}

impl WorkMode {
    /// The mode for a register value.
    pub const fn from_raw(raw: u16) -> Self {
        match raw {
            0 => Self::OpenLoop,
            1 => Self::Current,
            2 => Self::Speed,
            3 => Self::Position,
            other => Self::Unknown(other),
        }
    }

    /// The register value.
    pub const fn raw(self) -> u16 {
        match self {
            Self::OpenLoop => 0,
            Self::Current => 1,
            Self::Speed => 2,
            Self::Position => 3,
            Self::Unknown(raw) => raw,
        }
    }
}

/// The 96-bit unique ID in 0x2A..=0x2F (word 0 = bits 15..0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct UniqueId(pub [u16; 6]);

impl UniqueId {
    /// The ID as one number.
    pub fn as_u128(self) -> u128 {
        self.0
            .iter()
            .rev()
            .fold(0u128, |acc, w| (acc << 16) | u128::from(*w))
    }
}

impl fmt::Display for UniqueId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:024X}", self.as_u128())
    }
}

/// The documented initial value of every address as raw 16-bit words (0 where none is
/// documented, and for reserved addresses). Note conflict C11: ZH's 0x08/0x09 inits (0/2 =
/// 250k/1M) contradict the 1M/5M bus; a simulator may prefer 2/5.
#[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // bit-exact words
pub fn initial_values() -> [u16; TABLE_LEN] {
    let mut table = [0u16; TABLE_LEN];
    for reg in &REGISTERS {
        if let (Some(init), Some(slot)) = (reg.init, table.get_mut(usize::from(reg.addr.get()))) {
            *slot = match reg.half {
                Half::Low => split_i32(init)[0],
                Half::Single | Half::High => init as u16,
            };
        }
    }
    table
}

/// Split an i32 into its (low, high) register words.
#[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // bit-exact split
pub const fn split_i32(value: i32) -> [u16; 2] {
    let v = value as u32;
    [v as u16, (v >> 16) as u16]
}

/// Join (low, high) register words into an i32.
#[allow(clippy::cast_possible_wrap)] // bit-exact join
pub const fn join_i32(low: u16, high: u16) -> i32 {
    ((high as u32) << 16 | low as u32) as i32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn initial_values_follow_the_table() {
        let t = initial_values();
        assert_eq!(t[0x00], SIGNATURE_VALUE);
        assert_eq!(t[0x30], 3);
        assert_eq!(t[0x41], 3000);
        assert_eq!((t[0x4B], t[0x4C]), (0x93E0, 4));
        assert_eq!(join_i32(t[0x4B], t[0x4C]), 300_000);
        assert_eq!(t[0x16], 0); // reserved
    }

    #[test]
    fn words() {
        assert_eq!(split_i32(10_000), [0x2710, 0]);
        assert_eq!(split_i32(-6), [0xFFFA, 0xFFFF]);
        assert_eq!(join_i32(0x0D61, 0x0003), 200_033);
        assert_eq!(WorkMode::from_raw(3), WorkMode::Position);
        assert_eq!(WorkMode::from_raw(9).raw(), 9);
        let id = UniqueId([1, 0, 0, 0, 0, 0x8000]);
        assert_eq!(std::format!("{id}"), "800000000000000000000001");
    }
}
