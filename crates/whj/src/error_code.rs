//! The 16-bit error code (register 0x04/0x78, servo feedback D14–D15, status D0–D1,
//! broadcast feedback D12–D13), §7 of the WHJ joint protocol reference.

use core::fmt;

/// How serious an error bit is, in the FAQ's classes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Severity {
    /// The user can fix it (remove the cause, reset parameters, power-cycle).
    General,
    /// Re-flash or factory repair.
    Severe,
    /// The FAQ does not class this bit.
    Unclassified,
}

/// Facts about one error bit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ErrorBitInfo {
    /// The bit mask (one bit set).
    pub mask: u16,
    /// Short name.
    pub name: &'static str,
    /// Cause, as the vendor documents describe it.
    pub cause: &'static str,
    /// Whether the bit disables the drive (unrecoverable until 0x0F := 1). Only 0x4000 is
    /// known not to; the rest are inferred (the documents never list them).
    pub disables_drive: bool,
    /// FAQ class.
    pub severity: Severity,
    /// What to do about it.
    pub remedy: &'static str,
}

/// All 16 error bits, lowest first.
pub static ERROR_BITS: [ErrorBitInfo; 16] = [
    bit(
        0x0001,
        "FOC rate too high",
        "FOC overrun",
        true,
        Severity::Severe,
        "contact support",
    ),
    bit(
        0x0002,
        "over-voltage",
        "supply above rating",
        true,
        Severity::General,
        "keep the supply within 20–27 V",
    ),
    bit(
        0x0004,
        "under-voltage",
        "supply below rating (battery sag, weak PSU under load)",
        true,
        Severity::General,
        "use a 20–27 V PSU of at least 600 W with hiccup mode",
    ),
    bit(
        0x0008,
        "over-temperature",
        "90 °C alarm reached",
        true,
        Severity::General,
        "cool down; check for overload or collision",
    ),
    bit(
        0x0010,
        "startup failure",
        "FOC start failed",
        true,
        Severity::General,
        "check the supply",
    ),
    bit(
        0x0020,
        "encoder error",
        "lost zero / encoder self-check failed (not in V1.1's list)",
        true,
        Severity::Unclassified,
        "power-cycle; clear, reduce load; check mechanical stress on the encoder",
    ),
    bit(
        0x0040,
        "over-current",
        "motor current too high",
        true,
        Severity::Unclassified,
        "reduce load or acceleration",
    ),
    bit(
        0x0080,
        "software error",
        "hardware/software mismatch; current-sense fault",
        true,
        Severity::Unclassified,
        "re-flash matching firmware",
    ),
    bit(
        0x0100,
        "temperature-sensor error",
        "temperature unreadable",
        true,
        Severity::Unclassified,
        "service",
    ),
    bit(
        0x0200,
        "position limit",
        "actual (V1.0: or target) position beyond 0x44–0x47",
        true,
        Severity::Unclassified,
        "move back into range",
    ),
    bit(
        0x0400,
        "illegal joint ID",
        "invalid ID (old header: DRV8320 driver fault)",
        true,
        Severity::Unclassified,
        "set an ID in 1..=30",
    ),
    bit(
        0x0800,
        "following error",
        "|target − actual| above 0x4B/0x4C (default 30°)",
        true,
        Severity::Unclassified,
        "slow down, check for a collision; clear and re-enable",
    ),
    bit(
        0x1000,
        "current-detect error",
        "current sensor fault at power-up",
        true,
        Severity::Unclassified,
        "power-cycle; service",
    ),
    bit(
        0x2000,
        "brake failure",
        "brake did not open / Hall signal wrong (GRIP: self-check)",
        true,
        Severity::Unclassified,
        "check the supply; service",
    ),
    bit(
        0x4000,
        "position command step",
        "|target − actual| > 10° (V1.0: a warning)",
        false,
        Severity::Unclassified,
        "send smaller steps; clear",
    ),
    bit(
        0x8000,
        "multi-turn count lost",
        "multi-turn joints only",
        true,
        Severity::Unclassified,
        "clear and re-home",
    ),
];

const fn bit(
    mask: u16,
    name: &'static str,
    cause: &'static str,
    disables_drive: bool,
    severity: Severity,
    remedy: &'static str,
) -> ErrorBitInfo {
    ErrorBitInfo {
        mask,
        name,
        cause,
        disables_drive,
        severity,
        remedy,
    }
}

/// The error bitmap. Every bit is named; unknown combinations are kept as they are.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct ErrorCode(pub u16);

impl ErrorCode {
    /// No error.
    pub const NONE: Self = Self(0);
    /// 0x0001 FOC rate too high.
    pub const FOC_RATE: Self = Self(0x0001);
    /// 0x0002 over-voltage.
    pub const OVER_VOLTAGE: Self = Self(0x0002);
    /// 0x0004 under-voltage.
    pub const UNDER_VOLTAGE: Self = Self(0x0004);
    /// 0x0008 over-temperature.
    pub const OVER_TEMPERATURE: Self = Self(0x0008);
    /// 0x0010 startup failure.
    pub const STARTUP_FAILURE: Self = Self(0x0010);
    /// 0x0020 encoder error.
    pub const ENCODER: Self = Self(0x0020);
    /// 0x0040 over-current.
    pub const OVER_CURRENT: Self = Self(0x0040);
    /// 0x0080 software error.
    pub const SOFTWARE: Self = Self(0x0080);
    /// 0x0100 temperature-sensor error.
    pub const TEMP_SENSOR: Self = Self(0x0100);
    /// 0x0200 position limit.
    pub const POSITION_LIMIT: Self = Self(0x0200);
    /// 0x0400 illegal joint ID.
    pub const ILLEGAL_ID: Self = Self(0x0400);
    /// 0x0800 following error.
    pub const FOLLOWING_ERROR: Self = Self(0x0800);
    /// 0x1000 current-detect error.
    pub const CURRENT_DETECT: Self = Self(0x1000);
    /// 0x2000 brake failure.
    pub const BRAKE: Self = Self(0x2000);
    /// 0x4000 position command step (does not disable the drive).
    pub const POSITION_STEP: Self = Self(0x4000);
    /// 0x8000 multi-turn count lost.
    pub const MULTI_TURN_LOST: Self = Self(0x8000);

    /// The raw bitmap.
    pub const fn bits(self) -> u16 {
        self.0
    }
    /// Whether no bit is set.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }
    /// Whether every bit of `other` is set.
    pub const fn contains(self, other: Self) -> bool {
        self.0 & other.0 == other.0
    }
    /// Both sets of bits.
    #[must_use]
    pub const fn union(self, other: Self) -> Self {
        Self(self.0 | other.0)
    }
    /// These bits without those of `other`.
    #[must_use]
    pub const fn difference(self, other: Self) -> Self {
        Self(self.0 & !other.0)
    }
    /// Whether any set bit disables the drive.
    pub fn disables_drive(self) -> bool {
        self.iter().any(|b| b.disables_drive)
    }
    /// The facts about every set bit, lowest first.
    pub fn iter(self) -> impl Iterator<Item = &'static ErrorBitInfo> {
        ERROR_BITS.iter().filter(move |b| self.0 & b.mask != 0)
    }
    /// The facts about a single-bit mask, if `mask` has exactly one bit set.
    pub fn info(mask: u16) -> Option<&'static ErrorBitInfo> {
        ERROR_BITS.iter().find(|b| b.mask == mask)
    }
}

impl core::ops::BitOr for ErrorCode {
    type Output = Self;
    fn bitor(self, rhs: Self) -> Self {
        self.union(rhs)
    }
}

impl core::ops::BitOrAssign for ErrorCode {
    fn bitor_assign(&mut self, rhs: Self) {
        self.0 |= rhs.0;
    }
}

impl fmt::Debug for ErrorCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ErrorCode({:#06x}: {self})", self.0)
    }
}

/// Lists the names of the set bits separated by ", ", or "no error".
impl fmt::Display for ErrorCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.is_empty() {
            return f.write_str("no error");
        }
        for (i, b) in self.iter().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            f.write_str(b.name)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::string::ToString;

    #[test]
    fn all_bits_are_distinct_and_named() {
        let mut all = 0u16;
        for (i, b) in ERROR_BITS.iter().enumerate() {
            assert_eq!(b.mask, 1 << i);
            assert!(!b.name.is_empty() && !b.cause.is_empty());
            all |= b.mask;
        }
        assert_eq!(all, 0xFFFF);
        assert_eq!(ErrorCode(0xFFFF).iter().count(), 16);
    }

    #[test]
    fn display_and_class() {
        assert_eq!(ErrorCode::NONE.to_string(), "no error");
        let e = ErrorCode::OVER_VOLTAGE | ErrorCode::POSITION_STEP;
        assert_eq!(e.to_string(), "over-voltage, position command step");
        assert!(e.disables_drive());
        assert!(!ErrorCode::POSITION_STEP.disables_drive());
        assert!(e.contains(ErrorCode::POSITION_STEP));
        assert_eq!(
            e.difference(ErrorCode::OVER_VOLTAGE),
            ErrorCode::POSITION_STEP
        );
        assert_eq!(ErrorCode::info(0x0008).unwrap().name, "over-temperature");
        assert!(ErrorCode::info(0x0003).is_none());
    }
}
