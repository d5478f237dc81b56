//! The firmware (and model) gates: which features need which firmware, and whether a
//! client may write a gated register.

use core::fmt;

use super::RegisterAddr;

/// A feature that only newer firmware (and for some, only some products) has (§6.8,
/// the broadcast protocol's preface, conflict C28).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Feature {
    /// The broadcast protocol (0x2F / 0x4F / 0x0F / 0x7F frames) and its receive counter 0x4E.
    Broadcast,
    /// Staggered power-up switch 0x1F (`ON_DELAY`).
    PowerUpDelay,
    /// Low-power mode 0x69 (at most 80 W per joint); WHJ10N/30/60 only.
    LowPowerMode,
    /// End-board mode 0x79.
    EndBoardMode,
    /// Direct brake release 0x6A (hard-stop recovery); WHJ30/60 only.
    BrakeRelease,
}

/// The lowest firmware version of one firmware line that has a feature.
///
/// The documents quote labels, not numbers: "519", "D5.XX" (normal joints), "E2.XX"
/// (multi-turn joints), "DA05/DA24/D522". They read as register 0x03 printed as four hex
/// digits (0xD519 → "D519"); that reading is inferred, so gates are soft (a client still
/// checks the joint's acknowledgement, and the doctor reports a failed gate as a warning).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum VersionFloor {
    /// A three-digit label ("519"): the last three hex digits reach it, on any line.
    LastDigits(u16),
    /// A four-digit label ("D522", "D5.XX" = 0xD500): the same leading hex digit and at
    /// least this version.
    SameLine(u16),
}

impl VersionFloor {
    /// Whether `version` (the raw register 0x03) is at or above this floor.
    pub const fn admits(self, version: u16) -> bool {
        match self {
            Self::LastDigits(min) => (version & 0x0FFF) >= (min & 0x0FFF),
            Self::SameLine(min) => (version >> 12) == (min >> 12) && version >= min,
        }
    }
}

/// The firmware (and model) requirement of one [`Feature`], with its source.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FirmwareGate {
    /// The feature.
    pub feature: Feature,
    /// What it is, for messages ("direct brake release 0x6A").
    pub what: &'static str,
    /// The version label the documents quote ("DA05 / DA24 / D522").
    pub label: &'static str,
    /// A version passes if any floor admits it.
    pub floors: &'static [VersionFloor],
    /// Whether only some products have it (see `models::ProductFacts::model_features`).
    pub model_gated: bool,
    /// Where the gate is documented (EN = EN-MCT, 11 = broadcast protocol V1.1, DEMO = the
    /// usage demo; section of the WHJ joint protocol reference).
    pub source: &'static str,
}

impl FirmwareGate {
    /// Whether firmware `version` has the feature (the model is not considered).
    pub fn admits(&self, version: crate::units::FirmwareVersion) -> bool {
        self.floors.iter().any(|f| f.admits(version.0))
    }
}

use VersionFloor::{LastDigits, SameLine};

const FW_519: &[VersionFloor] = &[LastDigits(0x519)];

/// Every firmware gate, one per [`Feature`] (index = the feature's position in the enum).
pub static FIRMWARE_GATES: [FirmwareGate; 5] = [
    FirmwareGate {
        feature: Feature::Broadcast,
        what: "broadcast protocol (0x2F / 0x4F / 0x0F / 0x7F, receive counter 0x4E)",
        label: "D5.XX (E2.XX on multi-turn joints)",
        floors: &[SameLine(0xD500), SameLine(0xE200)],
        model_gated: false,
        source: "11 (preface); §7",
    },
    FirmwareGate {
        feature: Feature::PowerUpDelay,
        what: "staggered power-up switch 0x1F",
        label: "519",
        floors: FW_519,
        model_gated: false,
        source: "EN, 11, DEMO; §6.8",
    },
    FirmwareGate {
        feature: Feature::LowPowerMode,
        what: "low-power mode 0x69 (WHJ10N / WHJ30 / WHJ60)",
        label: "519",
        floors: FW_519,
        model_gated: true,
        source: "EN, 11, DEMO; §6.8",
    },
    FirmwareGate {
        feature: Feature::EndBoardMode,
        what: "end-board mode 0x79",
        label: "519",
        floors: FW_519,
        model_gated: false,
        source: "EN, 11, DEMO; §6.8",
    },
    FirmwareGate {
        feature: Feature::BrakeRelease,
        what: "direct brake release 0x6A (WHJ30 / WHJ60)",
        label: "DA05 / DA24 / D522",
        floors: &[SameLine(0xD522), SameLine(0xDA05), SameLine(0xDA24)],
        model_gated: true,
        source: "11 only; §6.8",
    },
];

impl Feature {
    /// The gate of this feature.
    pub fn gate(self) -> &'static FirmwareGate {
        let i = match self {
            Self::Broadcast => 0,
            Self::PowerUpDelay => 1,
            Self::LowPowerMode => 2,
            Self::EndBoardMode => 3,
            Self::BrakeRelease => 4,
        };
        &FIRMWARE_GATES[i]
    }
}

/// A write refused because the joint's firmware or model lacks the register's feature.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GateRefusal {
    /// The register's name.
    pub register: &'static str,
    /// Its address.
    pub addr: RegisterAddr,
    /// What the feature is.
    pub what: &'static str,
    /// The version label the documents require.
    pub needs: &'static str,
    /// The joint's firmware version.
    pub firmware: crate::units::FirmwareVersion,
    /// The joint's model.
    pub model: crate::units::Model,
    /// True if the model (not the firmware) lacks the feature.
    pub model_lacks: bool,
}

impl fmt::Display for GateRefusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "register {} ({}) is the {}: ",
            self.register, self.addr, self.what
        )?;
        if self.model_lacks {
            write!(f, "a {} joint does not have it", self.model)
        } else {
            write!(
                f,
                "it needs firmware {} or later, this joint runs {}",
                self.needs, self.firmware
            )
        }
    }
}

impl core::error::Error for GateRefusal {}

/// Whether a client may write `addr` on a joint of `model` running `firmware`: `Ok` for
/// ungated registers and for gated ones whose gate passes; a [`GateRefusal`] naming the
/// register, the feature, the required version and the joint's own otherwise. Reserved
/// and read-only registers are not this function's business (see
/// [`RegisterInfo::access`](super::RegisterInfo::access)).
///
/// For a model code several products share (WHJ10 with and without brake), a model-gated
/// feature is allowed if any of them has it; the joint's acknowledgement decides.
pub fn gated_write_allowed(
    addr: RegisterAddr,
    model: crate::units::Model,
    firmware: crate::units::FirmwareVersion,
) -> Result<(), GateRefusal> {
    let Some(info) = addr.info() else {
        return Ok(());
    };
    let Some(feature) = info.firmware else {
        return Ok(());
    };
    let gate = feature.gate();
    let refusal = |model_lacks| GateRefusal {
        register: info.name,
        addr,
        what: gate.what,
        needs: gate.label,
        firmware,
        model,
        model_lacks,
    };
    if !model.may_have(feature) {
        return Err(refusal(true));
    }
    if !gate.admits(firmware) {
        return Err(refusal(false));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::registers::{REGISTERS, addr};

    #[test]
    fn firmware_gates_are_data() {
        use crate::units::{FirmwareVersion as Fw, Model};
        for (i, g) in FIRMWARE_GATES.iter().enumerate() {
            assert_eq!(
                g.feature.gate(),
                g,
                "gate {i} is not at its feature's index"
            );
            assert!(!g.floors.is_empty() && !g.source.is_empty());
        }
        // Every gated register names a feature; the five gated ones are exactly these.
        let gated: std::vec::Vec<u8> = REGISTERS
            .iter()
            .filter(|r| r.firmware.is_some())
            .map(|r| r.addr.get())
            .collect();
        assert_eq!(gated, [0x1F, 0x4E, 0x69, 0x6A, 0x79]);
        let b = Feature::Broadcast.gate();
        assert!(b.admits(Fw(0xD500)) && b.admits(Fw(0xE2A0)));
        assert!(!b.admits(Fw(0xD4FF)) && !b.admits(Fw(0x0522)) && !b.admits(Fw(0xE1FF)));
        let fw519 = Feature::PowerUpDelay.gate();
        assert!(fw519.admits(Fw(0xD519)) && fw519.admits(Fw(0x0519)));
        assert!(!fw519.admits(Fw(0xD518)));
        let brake = Feature::BrakeRelease.gate();
        assert!(brake.admits(Fw(0xD522)) && brake.admits(Fw(0xDA05)) && brake.admits(Fw(0xDA24)));
        assert!(!brake.admits(Fw(0xD521)) && !brake.admits(Fw(0xC522)));

        // The client-side check: ungated registers always, gated ones by firmware and model.
        let old = Fw(0xD505);
        assert_eq!(
            gated_write_allowed(addr::TAG_WORK_MODE, Model::Joint30, old),
            Ok(())
        );
        assert_eq!(
            gated_write_allowed(addr::ON_DELAY, Model::Joint30, Fw(0xD519)),
            Ok(())
        );
        let e = gated_write_allowed(addr::ON_DELAY, Model::Joint30, old).unwrap_err();
        assert!(!e.model_lacks && e.needs == "519" && e.register == "ON_DELAY");
        assert_eq!(
            std::format!("{e}"),
            "register ON_DELAY (0x1f) is the staggered power-up switch 0x1F: it needs \
             firmware 519 or later, this joint runs D505"
        );
        let e = gated_write_allowed(addr::STATE_BRK_DIRECT_ENABLE, Model::Joint120, Fw(0xD522))
            .unwrap_err();
        assert!(e.model_lacks, "{e}");
        assert!(std::format!("{e}").contains("a WHJ120 joint does not have it"));
        assert_eq!(
            gated_write_allowed(addr::STATE_BRK_DIRECT_ENABLE, Model::Joint60, Fw(0xDA05)),
            Ok(())
        );
        // A shared code (WHJ10 B / N): allowed, the joint decides.
        assert_eq!(
            gated_write_allowed(addr::LOW_POWER_MODE, Model::Joint10, Fw(0xD519)),
            Ok(())
        );
    }
}
