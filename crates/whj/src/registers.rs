//! The memory control table (§4 of the WHJ joint protocol reference) as data.
//!
//! Registers are 16-bit words addressed 0x00..=0x91. 32-bit values are L/H pairs: the low
//! word at the lower address. [`REGISTERS`] lists every documented register once (each
//! half of a pair is its own entry); addresses not listed are reserved (they read as 0 and
//! a write is acknowledged with "failed" by the simulator).

use core::fmt;

pub mod addr;
mod gates;
mod safety;
mod table;
mod values;

pub use gates::{
    FIRMWARE_GATES, Feature, FirmwareGate, GateRefusal, VersionFloor, gated_write_allowed,
};
pub use safety::{SAFETY_CLASSES, SafetyClass, safety_class};
pub use table::REGISTERS;
pub use values::{SIGNATURE_VALUE, UniqueId, WorkMode, initial_values, join_i32, split_i32};

/// Number of addressable words (0x00..=0x91; EN lists reserved entries up to 0x91).
pub const TABLE_LEN: usize = 0x92;

/// Most registers one read may ask for (a 64-byte reply holds 31 words).
pub const MAX_READ_COUNT: u8 = 31;

/// A register address in 0x00..=0x91.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct RegisterAddr(u8);

/// A register address outside the table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("register address {value:#04x} out of range (allowed: 0x00..=0x91)")]
pub struct RegisterAddrError {
    /// The address that was given.
    pub value: u32,
}

impl RegisterAddr {
    /// The highest address.
    pub const MAX: Self = Self(0x91);

    /// An address from its raw value, or an error naming it and the range.
    pub const fn new(raw: u8) -> Result<Self, RegisterAddrError> {
        if (raw as usize) < TABLE_LEN {
            Ok(Self(raw))
        } else {
            Err(RegisterAddrError { value: raw as u32 })
        }
    }

    /// An address known to be valid at compile time (panics in const evaluation otherwise).
    const fn known(raw: u8) -> Self {
        assert!((raw as usize) < TABLE_LEN);
        Self(raw)
    }

    /// The raw address.
    pub const fn get(self) -> u8 {
        self.0
    }

    /// The address as an index into a table of [`TABLE_LEN`] words (always in bounds).
    pub const fn index(self) -> usize {
        self.0 as usize
    }

    /// The address `n` words further on, if still in the table.
    #[allow(clippy::cast_possible_truncation)] // checked < TABLE_LEN
    pub const fn offset(self, n: u8) -> Result<Self, RegisterAddrError> {
        let raw = self.0 as u32 + n as u32;
        if (raw as usize) < TABLE_LEN {
            Ok(Self(raw as u8))
        } else {
            Err(RegisterAddrError { value: raw })
        }
    }

    /// The table entry for this address, or `None` if it is reserved.
    pub fn info(self) -> Option<&'static RegisterInfo> {
        RegisterInfo::by_addr(self)
    }
}

impl TryFrom<u8> for RegisterAddr {
    type Error = RegisterAddrError;
    fn try_from(raw: u8) -> Result<Self, Self::Error> {
        Self::new(raw)
    }
}

impl fmt::Display for RegisterAddr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:#04x}", self.0)
    }
}

/// Who may access a register.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Access {
    /// Read only: a write gets `CMD_ERR` permission error.
    ReadOnly,
    /// Read and write.
    ReadWrite,
    /// The documents do not say (`--`); treated as writable.
    Unstated,
}

impl Access {
    /// Whether a write is permitted.
    pub const fn is_writable(self) -> bool {
        !matches!(self, Self::ReadOnly)
    }
}

/// How a register's value lives (simulator persistence class, inferred from the docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Persistence {
    /// Configuration: saved by 0x0C, restored from flash at boot.
    Flash,
    /// Volatile command or target.
    Ram,
    /// Measured live value.
    Live,
    /// Fixed by firmware or hardware.
    Fixed,
    /// Write-1 trigger that clears itself.
    Trigger,
}

/// Which half of a 32-bit value a register is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Half {
    /// A 16-bit register on its own.
    Single,
    /// Bits 15..0 of a 32-bit value; the high word is at address + 1.
    Low,
    /// Bits 31..16 of a 32-bit value; the low word is at address − 1.
    High,
}

/// The unit and scale of a register's value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Unit {
    /// No unit: an identifier, code, bitmap or raw gain.
    Raw,
    /// A flag: 0 or 1.
    Flag,
    /// An enumeration (see the meaning).
    Enum,
    /// 0.0001° per count.
    Position,
    /// 0.002 RPM per count.
    TargetSpeed,
    /// 0.02 RPM per count (C1).
    ActualSpeed,
    /// 1 mA per count, or 2 mA on Joint 60/120 (C2).
    Current,
    /// 0.01 V per count.
    Voltage,
    /// 0.1 °C per count.
    Temperature,
    /// Percent (0–100).
    Percent,
    /// 0.1 rpm/s per count.
    Acceleration,
    /// 0x41: 0.01 RPM or 1/ratio output RPM (C3).
    SpeedLimit,
}

impl Unit {
    /// Engineering units per count, where one fixed scale exists (current depends on the
    /// model, the speed limit on the reading of C3).
    pub const fn scale(self) -> Option<f64> {
        match self {
            Self::Position => Some(crate::units::POSITION_DEG_PER_COUNT),
            Self::TargetSpeed => Some(crate::units::TARGET_SPEED_RPM_PER_COUNT),
            Self::ActualSpeed => Some(crate::units::ACTUAL_SPEED_RPM_PER_COUNT),
            Self::Voltage => Some(crate::units::VOLTAGE_V_PER_COUNT),
            Self::Temperature => Some(crate::units::TEMPERATURE_C_PER_COUNT),
            Self::Acceleration => Some(crate::units::ACCELERATION_RPM_S_PER_COUNT),
            Self::Percent => Some(1.0),
            Self::Raw | Self::Flag | Self::Enum | Self::Current | Self::SpeedLimit => None,
        }
    }

    /// The unit's symbol ("°", "RPM", "mA", ...), empty for unitless values.
    pub const fn symbol(self) -> &'static str {
        match self {
            Self::Position => "°",
            Self::TargetSpeed | Self::ActualSpeed | Self::SpeedLimit => "RPM",
            Self::Current => "mA",
            Self::Voltage => "V",
            Self::Temperature => "°C",
            Self::Percent => "%",
            Self::Acceleration => "rpm/s",
            Self::Raw | Self::Flag | Self::Enum => "",
        }
    }
}

/// One register of the memory control table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegisterInfo {
    /// Address.
    pub addr: RegisterAddr,
    /// Vendor name (`SYS_ID`, `CUR_POSITION_L`, ...); descriptive for unnamed ones.
    pub name: &'static str,
    /// What it means.
    pub meaning: &'static str,
    /// Unit and scale.
    pub unit: Unit,
    /// Allowed raw values (inclusive), where documented. For a pair, the range of the
    /// combined i32 is on the low word.
    pub range: Option<(i32, i32)>,
    /// Access.
    pub access: Access,
    /// Initial (factory) value where documented. On a pair's low word this is the whole
    /// i32; the high word carries its own 16 bits (300 000 = 0x0004_93E0 → L 0x93E0, H 4).
    pub init: Option<i32>,
    /// Whether this is half of a 32-bit value.
    pub half: Half,
    /// Persistence class.
    pub persistence: Persistence,
    /// The feature whose firmware (and, for some, model) gate this register sits behind,
    /// if any; [`Feature::gate`] has the rule and its source.
    pub firmware: Option<Feature>,
    /// Source documents: EN = EN-MCT, ZH = ZH-MCT, 10 = V1.0, 11 = V1.1, GRIP, DEMO.
    pub sources: &'static str,
    /// Conflicts in §10 that concern this register ("C1", ...); empty if none.
    pub conflicts: &'static [&'static str],
}
