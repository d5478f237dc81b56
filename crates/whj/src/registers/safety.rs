//! The client's write policy on top of the table: each register's safety class.

use super::{Access, RegisterAddr, RegisterInfo};

/// How a client may write a register: its safety class ([`safety_class`]).
///
/// Enforced by the client library's register write (`robobus::ops::whj::write_register`);
/// kept apart from [`REGISTERS`](super::REGISTERS) so the table of facts and the policy on
/// top of it can be read (and changed) separately.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SafetyClass {
    /// An ordinary setting: written as asked.
    Plain,
    /// Needs an explicit confirmation (`--yes`); the text says what the write does.
    Confirm(&'static str),
    /// A motion target or drive switch: refused; the text names the command to use (which
    /// applies the joint's limits and the step-limit planner).
    Motion(&'static str),
    /// Never written by a client; the text says why.
    Never(&'static str),
}

impl SafetyClass {
    /// `plain`, `confirm`, `motion`, `never`.
    pub const fn keyword(self) -> &'static str {
        match self {
            Self::Plain => "plain",
            Self::Confirm(_) => "confirm",
            Self::Motion(_) => "motion",
            Self::Never(_) => "never",
        }
    }
}

/// The safety class of every register address: read-only and reserved addresses are
/// [`SafetyClass::Never`]; see [`SAFETY_CLASSES`] for the writable ones that are not plain.
pub fn safety_class(addr: RegisterAddr) -> SafetyClass {
    let Some(info) = RegisterInfo::by_addr(addr) else {
        return SafetyClass::Never("a reserved address: no documented register there");
    };
    if let Some((_, class)) = SAFETY_CLASSES.iter().find(|(name, _)| *name == info.name) {
        return *class;
    }
    if info.access == Access::ReadOnly {
        return SafetyClass::Never("read-only: the joint refuses the write");
    }
    SafetyClass::Plain
}

/// The writable registers that are not [`SafetyClass::Plain`], by name (both halves of a
/// pair are listed). Position limits are plain, but the client refuses a write that would
/// leave them inverted (min > max).
pub const SAFETY_CLASSES: [(&str, SafetyClass); 18] = {
    use SafetyClass::{Confirm, Motion, Never};
    const MOVE: SafetyClass =
        Motion("a position target: use `whj move` (limits and step-limit planner)");
    const SPEED: SafetyClass =
        Motion("a speed target: use `whj speed` (mode, enable and limit checks)");
    const CURRENT: SafetyClass =
        Motion("a current target: use `whj current` (mode, enable and limit checks)");
    [
        (
            "SYS_ID",
            Confirm(
                "changes the joint's bus ID (it applies after a power cycle; use `whj set-id`, which checks the new ID is free)",
            ),
        ),
        (
            "SYS_BPS_CANFD_BRT",
            Confirm(
                "changes the arbitration bit rate: after a save and power cycle the joint answers only at the new rate",
            ),
        ),
        (
            "SYS_BPS_CANFD_DATA",
            Confirm(
                "changes the data bit rate: after a save and power cycle the joint answers only at the new rate",
            ),
        ),
        (
            "SYS_ENABLE_DRIVER",
            Motion(
                "switches the drive: use `whj enable` / `whj disable` (they verify the state afterwards)",
            ),
        ),
        (
            "SYS_ENABLE_ON_POWER",
            Confirm("makes the joint enable its drive by itself at power-up"),
        ),
        (
            "SYS_SAVE_TO_FLASH",
            Confirm("writes the RAM table to flash (use `whj save`)"),
        ),
        (
            "SYS_DEMA_ABSPOS",
            Never(
                "auto-calibrates the absolute position sensor: a factory operation the register table says never to write from a client",
            ),
        ),
        (
            "SYS_SET_ZERO_POS",
            Confirm("makes the present position 0 deg: a calibration (use `whj zero`)"),
        ),
        (
            "ARM_CALIBRATION_STATE",
            Confirm("changes the arm calibration state: a calibration"),
        ),
        (
            "TAG_OPEN_PWM",
            Never("an open-loop duty: nothing limits speed or current in open loop"),
        ),
        ("TAG_CURRENT_L", CURRENT),
        ("TAG_CURRENT_H", CURRENT),
        ("TAG_SPEED_L", SPEED),
        ("TAG_SPEED_H", SPEED),
        ("TAG_POSITION_L", MOVE),
        ("TAG_POSITION_H", MOVE),
        (
            "IAP_FLAG",
            Confirm(
                "1 drops the joint into its bootloader (it stops answering commands until released with `whj release-iap`); 0 starts the application",
            ),
        ),
        (
            "STATE_BRK_DIRECT_ENABLE",
            Confirm(
                "releases the brake directly (once per power cycle): an arm under load may fall",
            ),
        ),
    ]
};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::registers::addr;

    #[test]
    fn every_register_has_a_safety_class_and_the_table_names_real_registers() {
        for (name, _) in &SAFETY_CLASSES {
            assert!(RegisterInfo::by_name(name).is_some(), "{name}");
        }
        assert!(matches!(
            safety_class(RegisterAddr::known(0x0D)),
            SafetyClass::Never(_)
        ));
        assert!(matches!(
            safety_class(addr::IAP_FLAG),
            SafetyClass::Confirm(_)
        ));
        assert!(matches!(
            safety_class(addr::TAG_POSITION),
            SafetyClass::Motion(_)
        ));
        assert_eq!(safety_class(addr::TAG_WORK_MODE), SafetyClass::Plain);
        assert!(matches!(
            safety_class(addr::CUR_POSITION),
            SafetyClass::Never(_)
        ));
        assert!(matches!(
            safety_class(RegisterAddr::known(0x16)),
            SafetyClass::Never(_)
        ));
    }
}
