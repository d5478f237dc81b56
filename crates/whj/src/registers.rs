//! The memory control table (§4 of the WHJ joint protocol reference) as data.
//!
//! Registers are 16-bit words addressed 0x00..=0x91. 32-bit values are L/H pairs: the low
//! word at the lower address. [`REGISTERS`] lists every documented register once (each
//! half of a pair is its own entry); addresses not listed are reserved (they read as 0 and
//! a write is acknowledged with "failed" by the simulator).

use core::fmt;

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
            Self::Voltage => Some(0.01),
            Self::Temperature | Self::Acceleration => Some(0.1),
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

#[allow(clippy::too_many_arguments)]
const fn r(
    addr: u8,
    name: &'static str,
    meaning: &'static str,
    unit: Unit,
    range: Option<(i32, i32)>,
    access: Access,
    init: Option<i32>,
    half: Half,
    persistence: Persistence,
    firmware: Option<Feature>,
    sources: &'static str,
    conflicts: &'static [&'static str],
) -> RegisterInfo {
    RegisterInfo {
        addr: RegisterAddr::known(addr),
        name,
        meaning,
        unit,
        range,
        access,
        init,
        half,
        persistence,
        firmware,
        sources,
        conflicts,
    }
}

use Access::{ReadOnly as RO, ReadWrite as RW, Unstated as UN};
use Half::{High as H, Low as L, Single as S};
use Persistence::{Fixed, Flash, Live, Ram, Trigger};

const FLAG: Option<(i32, i32)> = Some((0, 1));
const I32: Option<(i32, i32)> = Some((i32::MIN, i32::MAX));
const NONE: &[&str] = &[];
const ALL: &str = "EN ZH 10 11";

/// The memory control table, sorted by address.
#[rustfmt::skip]
pub static REGISTERS: [RegisterInfo; 70] = [
    r(0x00, "SIGNATURE", "constant signature (reserved); usable as a probe", Unit::Raw, None, RO, Some(0x1314), S, Fixed, None, ALL, NONE),
    r(0x01, "SYS_ID", "node ID; takes effect after save + power cycle (V1.1: immediately)", Unit::Raw, Some((1, 30)), RW, Some(1), S, Flash, None, ALL, &["C7", "C27"]),
    r(0x02, "SYS_MODEL_TYPE", "model code (see Model)", Unit::Enum, None, RO, None, S, Fixed, None, "EN ZH 11", &["C29"]),
    r(0x03, "SYS_FW_VERSION", "firmware version", Unit::Raw, None, RO, None, S, Fixed, None, ALL, &["C28"]),
    r(0x04, "SYS_ERROR", "error bitmap (see ErrorCode)", Unit::Raw, None, RO, Some(0), S, Live, None, ALL, &["C16"]),
    r(0x05, "SYS_VOLTAGE", "bus voltage", Unit::Voltage, None, RO, None, S, Live, None, ALL, NONE),
    r(0x06, "SYS_TEMP", "temperature", Unit::Temperature, None, RO, None, S, Live, None, ALL, NONE),
    r(0x07, "SYS_REDU_RATIO", "gear reduction ratio (80 or 100)", Unit::Raw, None, RO, None, S, Fixed, None, ALL, NONE),
    r(0x08, "SYS_BPS_CANFD_BRT", "arbitration bit rate: 0 = 250k, 1 = 500k, 2 = 1M", Unit::Enum, Some((0, 2)), RW, Some(0), S, Flash, None, "ZH", &["C11"]),
    r(0x09, "SYS_BPS_CANFD_DATA", "data bit rate: 0 = 250k, 1 = 500k, 2 = 1M, 3 = 2M, 4 = 4M, 5 = 5M", Unit::Enum, Some((0, 5)), RW, Some(2), S, Flash, None, "ZH", &["C11"]),
    r(0x0A, "SYS_ENABLE_DRIVER", "drive enable (wait 5 ms after disable)", Unit::Flag, FLAG, RW, Some(0), S, Ram, None, ALL, NONE),
    r(0x0B, "SYS_ENABLE_ON_POWER", "enable at power-up in the saved mode", Unit::Flag, FLAG, RW, Some(1), S, Flash, None, ALL, NONE),
    r(0x0C, "SYS_SAVE_TO_FLASH", "copy the RAM table to flash (only while disabled; wait 50 ms)", Unit::Flag, FLAG, RW, Some(0), S, Trigger, None, ALL, &["C13"]),
    r(0x0D, "SYS_DEMA_ABSPOS", "auto-calibrate the absolute sensor (never write from a client)", Unit::Flag, FLAG, RW, Some(0), S, Trigger, None, "ZH 10 11", &["C15"]),
    r(0x0E, "SYS_SET_ZERO_POS", "present position := 0 (kept after a save)", Unit::Flag, FLAG, RW, Some(0), S, Trigger, None, ALL, NONE),
    r(0x0F, "SYS_CLEAR_ERROR", "try to clear latched errors", Unit::Flag, FLAG, RW, Some(0), S, Trigger, None, ALL, &["C8"]),
    r(0x10, "CUR_CURRENT_L", "actual current, low word", Unit::Current, I32, RO, Some(0), L, Live, None, ALL, &["C2"]),
    r(0x11, "CUR_CURRENT_H", "actual current, high word", Unit::Current, None, RO, Some(0), H, Live, None, ALL, &["C2"]),
    r(0x12, "CUR_SPEED_L", "actual output speed, low word", Unit::ActualSpeed, I32, RO, None, L, Live, None, ALL, &["C1"]),
    r(0x13, "CUR_SPEED_H", "actual output speed, high word", Unit::ActualSpeed, None, RO, None, H, Live, None, ALL, &["C1"]),
    r(0x14, "CUR_POSITION_L", "actual output position, low word", Unit::Position, I32, RO, None, L, Live, None, ALL, NONE),
    r(0x15, "CUR_POSITION_H", "actual output position, high word", Unit::Position, None, RO, None, H, Live, None, ALL, NONE),
    r(0x18, "ARM_CALIBRATION_STATE", "arm calibration state: 0 none, 1 running, 2 done", Unit::Enum, Some((0, 2)), UN, Some(0), S, Flash, None, "ZH", &["C34"]),
    r(0x1F, "ON_DELAY", "0 = staggered (delayed) power-up, 1 = no delay", Unit::Flag, FLAG, RW, Some(0), S, Flash, Some(Feature::PowerUpDelay), "EN 11 DEMO", &["C33"]),
    r(0x2A, "MOT_MODEL_ID0", "unique ID bits 15..0", Unit::Raw, None, RO, None, S, Fixed, None, ALL, NONE),
    r(0x2B, "MOT_MODEL_ID1", "unique ID bits 31..16", Unit::Raw, None, RO, None, S, Fixed, None, ALL, NONE),
    r(0x2C, "MOT_MODEL_ID2", "unique ID bits 47..32", Unit::Raw, None, RO, None, S, Fixed, None, ALL, NONE),
    r(0x2D, "MOT_MODEL_ID3", "unique ID bits 63..48", Unit::Raw, None, RO, None, S, Fixed, None, ALL, NONE),
    r(0x2E, "MOT_MODEL_ID4", "unique ID bits 79..64", Unit::Raw, None, RO, None, S, Fixed, None, ALL, NONE),
    r(0x2F, "MOT_MODEL_ID5", "unique ID bits 95..80", Unit::Raw, None, RO, None, S, Fixed, None, ALL, NONE),
    r(0x30, "TAG_WORK_MODE", "work mode: 0 open loop, 1 current, 2 speed, 3 position", Unit::Enum, Some((0, 3)), RW, Some(3), S, Flash, None, ALL, NONE),
    r(0x31, "TAG_OPEN_PWM", "open-loop duty", Unit::Percent, Some((0, 100)), RW, Some(0), S, Ram, None, "EN ZH", NONE),
    r(0x32, "TAG_CURRENT_L", "target current, low word", Unit::Current, I32, RW, Some(0), L, Ram, None, ALL, &["C2"]),
    r(0x33, "TAG_CURRENT_H", "target current, high word", Unit::Current, None, RW, Some(0), H, Ram, None, ALL, &["C2"]),
    r(0x34, "TAG_SPEED_L", "target output speed, low word", Unit::TargetSpeed, I32, RW, Some(0), L, Ram, None, ALL, NONE),
    r(0x35, "TAG_SPEED_H", "target output speed, high word", Unit::TargetSpeed, None, RW, Some(0), H, Ram, None, ALL, NONE),
    r(0x36, "TAG_POSITION_L", "target output position, low word (clamped to 0x44..0x47 in mode 3)", Unit::Position, I32, RW, Some(0), L, Ram, None, ALL, &["C10"]),
    r(0x37, "TAG_POSITION_H", "target output position, high word", Unit::Position, None, RW, Some(0), H, Ram, None, ALL, &["C10"]),
    r(0x38, "TAG_SERVO_FLAG", "servo reply format: default or extended (layout undocumented)", Unit::Enum, Some((0, 2)), RW, Some(0), S, Ram, None, "ZH", &["C34"]),
    r(0x39, "SPEED_FF_FOLLOWING", "speed feed-forward switch / position-loop following coefficient", Unit::Raw, Some((0, 100)), RW, Some(0), S, Flash, None, ALL, &["C4"]),
    r(0x40, "LIT_MAX_CURRENT", "current limit", Unit::Current, None, RW, None, S, Flash, None, ALL, &["C31"]),
    r(0x41, "LIT_MAX_SPEED", "speed limit", Unit::SpeedLimit, None, RW, Some(3000), S, Flash, None, ALL, &["C3"]),
    r(0x42, "LIT_MAX_ACC", "acceleration limit", Unit::Acceleration, None, RW, Some(5000), S, Flash, None, ALL, NONE),
    r(0x43, "LIT_MAX_DEC", "deceleration limit", Unit::Acceleration, None, RW, None, S, Flash, None, ALL, &["C31"]),
    r(0x44, "LIT_MIN_POSITION_L", "lower position limit, low word", Unit::Position, I32, RW, None, L, Flash, None, ALL, &["C9"]),
    r(0x45, "LIT_MIN_POSITION_H", "lower position limit, high word", Unit::Position, None, RW, None, H, Flash, None, ALL, &["C9"]),
    r(0x46, "LIT_MAX_POSITION_L", "upper position limit, low word", Unit::Position, I32, RW, None, L, Flash, None, ALL, &["C9"]),
    r(0x47, "LIT_MAX_POSITION_H", "upper position limit, high word", Unit::Position, None, RW, None, H, Flash, None, ALL, &["C9"]),
    r(0x49, "IAP_FLAG", "0 = run the application, 1 = firmware update; write 0 after power-up", Unit::Flag, FLAG, RW, Some(0), S, Ram, None, ALL, &["C24"]),
    r(0x4B, "LIT_MAX_POS_DIFF_L", "maximum following error, low word (default 30°)", Unit::Position, I32, RW, Some(300_000), L, Flash, None, "ZH GRIP", &["C34"]),
    r(0x4C, "LIT_MAX_POS_DIFF_H", "maximum following error, high word", Unit::Position, None, RW, Some(4), H, Flash, None, "ZH GRIP", &["C34"]),
    r(0x4E, "BROADCAST_COUNTER", "broadcast receive counter (write 0 to clear)", Unit::Raw, Some((0, 255)), UN, None, S, Ram, Some(Feature::Broadcast), "11", NONE),
    r(0x50, "SEV_PARAME_UPDATE", "load the gain registers into the control loops", Unit::Flag, FLAG, RW, Some(0), S, Trigger, None, "ZH", &["C34"]),
    r(0x51, "SEV_CURRENT_P", "current-loop P gain (factory-tuned)", Unit::Raw, None, RW, None, S, Flash, None, ALL, NONE),
    r(0x52, "SEV_CURRENT_I", "current-loop I gain (factory-tuned)", Unit::Raw, None, RW, None, S, Flash, None, ALL, NONE),
    r(0x53, "SEV_CURRENT_D", "current-loop D gain (factory-tuned)", Unit::Raw, None, RW, None, S, Flash, None, ALL, NONE),
    r(0x54, "SEV_SPEED_P", "speed-loop P gain (EN mislabels it current-loop P)", Unit::Raw, None, RW, None, S, Flash, None, ALL, NONE),
    r(0x55, "SEV_SPEED_I", "speed-loop I gain", Unit::Raw, None, RW, None, S, Flash, None, ALL, NONE),
    r(0x56, "SEV_SPEED_D", "speed-loop D gain", Unit::Raw, None, RW, None, S, Flash, None, ALL, NONE),
    r(0x57, "SEV_SPEED_DS", "speed-loop P dead zone", Unit::Raw, None, RW, None, S, Flash, None, ALL, NONE),
    r(0x58, "SEV_POSITION_P", "position-loop P gain", Unit::Raw, None, RW, None, S, Flash, None, ALL, NONE),
    r(0x59, "SEV_POSITION_I", "position-loop I gain", Unit::Raw, None, RW, None, S, Flash, None, ALL, NONE),
    r(0x5A, "SEV_POSITION_D", "position-loop D gain", Unit::Raw, None, RW, None, S, Flash, None, ALL, NONE),
    r(0x5B, "SEV_POSITION_DS", "position-loop P dead zone", Unit::Raw, None, RW, None, S, Flash, None, ALL, NONE),
    r(0x5C, "SEV_POS_SMOOTH", "position-loop smoothing (higher = tighter following)", Unit::Raw, None, RW, None, S, Flash, None, "EN 11", NONE),
    r(0x5D, "SEV_SPD_FF", "speed feed-forward coefficient (higher = tighter following)", Unit::Raw, None, RW, None, S, Flash, None, "EN 11", NONE),
    r(0x69, "LOW_POWER_MODE", "1 = at most 80 W per joint", Unit::Flag, FLAG, RW, Some(0), S, Flash, Some(Feature::LowPowerMode), "EN 11 DEMO", NONE),
    r(0x6A, "STATE_BRK_DIRECT_ENABLE", "direct brake release for hard-stop recovery (once per power cycle)", Unit::Flag, FLAG, RW, Some(0), S, Ram, Some(Feature::BrakeRelease), "11", NONE),
    r(0x78, "ERROR", "error code (mirror of 0x04)", Unit::Raw, None, RO, Some(0), S, Live, None, ALL, &["C16"]),
    r(0x79, "END_BOARD_MODE", "0 = end board is not a joint, 1 = it acts as a joint", Unit::Flag, FLAG, RW, Some(0), S, Flash, Some(Feature::EndBoardMode), "EN 11 DEMO", NONE),
];

/// Index from address to position in [`REGISTERS`] (0xFF = reserved), built at compile time.
static INDEX: [u8; TABLE_LEN] = build_index();

#[allow(clippy::cast_possible_truncation)] // REGISTERS has fewer than 255 entries.
const fn build_index() -> [u8; TABLE_LEN] {
    let mut index = [0xFFu8; TABLE_LEN];
    let mut i = 0;
    while i < REGISTERS.len() {
        let addr = REGISTERS[i].addr.0 as usize;
        assert!(index[addr] == 0xFF, "duplicate register address");
        index[addr] = i as u8;
        i += 1;
    }
    index
}

impl RegisterInfo {
    /// The entry for an address, or `None` if it is reserved.
    pub fn by_addr(addr: RegisterAddr) -> Option<&'static Self> {
        let i = *INDEX.get(usize::from(addr.0))?;
        REGISTERS.get(usize::from(i))
    }

    /// The entry for a raw address, or `None` if it is reserved or outside the table.
    pub fn by_raw(raw: u8) -> Option<&'static Self> {
        RegisterAddr::new(raw).ok().and_then(Self::by_addr)
    }

    /// The entry whose name matches, ignoring ASCII case. A pair's base name
    /// (`"cur_position"`) finds its low word.
    pub fn by_name(name: &str) -> Option<&'static Self> {
        REGISTERS
            .iter()
            .find(|r| r.name.eq_ignore_ascii_case(name))
            .or_else(|| {
                REGISTERS.iter().find(|r| {
                    r.half == Half::Low
                        && r.name.len() == name.len() + 2
                        && r.name
                            .get(..name.len())
                            .is_some_and(|b| b.eq_ignore_ascii_case(name))
                })
            })
    }

    /// The address of the other half of a 32-bit pair.
    pub fn partner(&self) -> Option<RegisterAddr> {
        match self.half {
            Half::Single => None,
            Half::Low => self.addr.offset(1).ok(),
            Half::High => self
                .addr
                .get()
                .checked_sub(1)
                .and_then(|a| RegisterAddr::new(a).ok()),
        }
    }

    /// Whether a raw 16-bit value (or, for a low word, a combined i32) is in range.
    pub fn in_range(&self, value: i32) -> bool {
        self.range.is_none_or(|(lo, hi)| value >= lo && value <= hi)
    }
}

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
/// and read-only registers are not this function's business (see [`RegisterInfo::access`]).
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

/// The address of every register in [`REGISTERS`], by its vendor name (a 32-bit pair by its
/// base name for the low word and `_H` for the high word; 0x2A..=0x2F by its first word).
pub mod addr {
    use super::RegisterAddr;

    /// 0x00 constant signature 0x1314.
    pub const SIGNATURE: RegisterAddr = RegisterAddr::known(0x00);
    /// 0x01 node ID.
    pub const SYS_ID: RegisterAddr = RegisterAddr::known(0x01);
    /// 0x02 model code.
    pub const SYS_MODEL_TYPE: RegisterAddr = RegisterAddr::known(0x02);
    /// 0x03 firmware version.
    pub const SYS_FW_VERSION: RegisterAddr = RegisterAddr::known(0x03);
    /// 0x04 error code.
    pub const SYS_ERROR: RegisterAddr = RegisterAddr::known(0x04);
    /// 0x05 voltage.
    pub const SYS_VOLTAGE: RegisterAddr = RegisterAddr::known(0x05);
    /// 0x06 temperature.
    pub const SYS_TEMP: RegisterAddr = RegisterAddr::known(0x06);
    /// 0x07 reduction ratio.
    pub const SYS_REDU_RATIO: RegisterAddr = RegisterAddr::known(0x07);
    /// 0x0A drive enable.
    pub const SYS_ENABLE_DRIVER: RegisterAddr = RegisterAddr::known(0x0A);
    /// 0x0B enable at power-up.
    pub const SYS_ENABLE_ON_POWER: RegisterAddr = RegisterAddr::known(0x0B);
    /// 0x08 arbitration bit rate code.
    pub const SYS_BPS_CANFD_BRT: RegisterAddr = RegisterAddr::known(0x08);
    /// 0x09 data bit rate code.
    pub const SYS_BPS_CANFD_DATA: RegisterAddr = RegisterAddr::known(0x09);
    /// 0x0C save to flash.
    pub const SYS_SAVE_TO_FLASH: RegisterAddr = RegisterAddr::known(0x0C);
    /// 0x0D absolute-sensor auto-calibration trigger (never written by a client).
    pub const SYS_DEMA_ABSPOS: RegisterAddr = RegisterAddr::known(0x0D);
    /// 0x0E set zero position.
    pub const SYS_SET_ZERO_POS: RegisterAddr = RegisterAddr::known(0x0E);
    /// 0x0F clear errors.
    pub const SYS_CLEAR_ERROR: RegisterAddr = RegisterAddr::known(0x0F);
    /// 0x10/0x11 actual current.
    pub const CUR_CURRENT: RegisterAddr = RegisterAddr::known(0x10);
    /// 0x11 actual current, high word.
    pub const CUR_CURRENT_H: RegisterAddr = RegisterAddr::known(0x11);
    /// 0x12/0x13 actual speed.
    pub const CUR_SPEED: RegisterAddr = RegisterAddr::known(0x12);
    /// 0x13 actual speed, high word.
    pub const CUR_SPEED_H: RegisterAddr = RegisterAddr::known(0x13);
    /// 0x14/0x15 actual position.
    pub const CUR_POSITION: RegisterAddr = RegisterAddr::known(0x14);
    /// 0x15 actual position, high word.
    pub const CUR_POSITION_H: RegisterAddr = RegisterAddr::known(0x15);
    /// 0x18 arm calibration state.
    pub const ARM_CALIBRATION_STATE: RegisterAddr = RegisterAddr::known(0x18);
    /// 0x1F power-up delay switch.
    pub const ON_DELAY: RegisterAddr = RegisterAddr::known(0x1F);
    /// 0x2A..=0x2F 96-bit unique ID.
    pub const MOT_MODEL_ID: RegisterAddr = RegisterAddr::known(0x2A);
    /// 0x30 work mode.
    pub const TAG_WORK_MODE: RegisterAddr = RegisterAddr::known(0x30);
    /// 0x31 open-loop duty.
    pub const TAG_OPEN_PWM: RegisterAddr = RegisterAddr::known(0x31);
    /// 0x32/0x33 target current.
    pub const TAG_CURRENT: RegisterAddr = RegisterAddr::known(0x32);
    /// 0x33 target current, high word.
    pub const TAG_CURRENT_H: RegisterAddr = RegisterAddr::known(0x33);
    /// 0x34/0x35 target speed.
    pub const TAG_SPEED: RegisterAddr = RegisterAddr::known(0x34);
    /// 0x35 target speed, high word.
    pub const TAG_SPEED_H: RegisterAddr = RegisterAddr::known(0x35);
    /// 0x36/0x37 target position.
    pub const TAG_POSITION: RegisterAddr = RegisterAddr::known(0x36);
    /// 0x37 target position, high word.
    pub const TAG_POSITION_H: RegisterAddr = RegisterAddr::known(0x37);
    /// 0x38 servo reply format.
    pub const TAG_SERVO_FLAG: RegisterAddr = RegisterAddr::known(0x38);
    /// 0x39 speed feed-forward / following coefficient.
    pub const SPEED_FF_FOLLOWING: RegisterAddr = RegisterAddr::known(0x39);
    /// 0x40 current limit.
    pub const LIT_MAX_CURRENT: RegisterAddr = RegisterAddr::known(0x40);
    /// 0x41 speed limit.
    pub const LIT_MAX_SPEED: RegisterAddr = RegisterAddr::known(0x41);
    /// 0x42 acceleration limit.
    pub const LIT_MAX_ACC: RegisterAddr = RegisterAddr::known(0x42);
    /// 0x43 deceleration limit.
    pub const LIT_MAX_DEC: RegisterAddr = RegisterAddr::known(0x43);
    /// 0x44/0x45 lower position limit.
    pub const LIT_MIN_POSITION: RegisterAddr = RegisterAddr::known(0x44);
    /// 0x45 lower position limit, high word.
    pub const LIT_MIN_POSITION_H: RegisterAddr = RegisterAddr::known(0x45);
    /// 0x46/0x47 upper position limit.
    pub const LIT_MAX_POSITION: RegisterAddr = RegisterAddr::known(0x46);
    /// 0x47 upper position limit, high word.
    pub const LIT_MAX_POSITION_H: RegisterAddr = RegisterAddr::known(0x47);
    /// 0x49 IAP flag.
    pub const IAP_FLAG: RegisterAddr = RegisterAddr::known(0x49);
    /// 0x4B/0x4C maximum following error.
    pub const LIT_MAX_POS_DIFF: RegisterAddr = RegisterAddr::known(0x4B);
    /// 0x4C maximum following error, high word.
    pub const LIT_MAX_POS_DIFF_H: RegisterAddr = RegisterAddr::known(0x4C);
    /// 0x4E broadcast receive counter.
    pub const BROADCAST_COUNTER: RegisterAddr = RegisterAddr::known(0x4E);
    /// 0x50 load the gains into the control loops.
    pub const SEV_PARAME_UPDATE: RegisterAddr = RegisterAddr::known(0x50);
    /// 0x51 current-loop P gain.
    pub const SEV_CURRENT_P: RegisterAddr = RegisterAddr::known(0x51);
    /// 0x52 current-loop I gain.
    pub const SEV_CURRENT_I: RegisterAddr = RegisterAddr::known(0x52);
    /// 0x53 current-loop D gain.
    pub const SEV_CURRENT_D: RegisterAddr = RegisterAddr::known(0x53);
    /// 0x54 speed-loop P gain.
    pub const SEV_SPEED_P: RegisterAddr = RegisterAddr::known(0x54);
    /// 0x55 speed-loop I gain.
    pub const SEV_SPEED_I: RegisterAddr = RegisterAddr::known(0x55);
    /// 0x56 speed-loop D gain.
    pub const SEV_SPEED_D: RegisterAddr = RegisterAddr::known(0x56);
    /// 0x57 speed-loop P dead zone.
    pub const SEV_SPEED_DS: RegisterAddr = RegisterAddr::known(0x57);
    /// 0x58 position-loop P gain.
    pub const SEV_POSITION_P: RegisterAddr = RegisterAddr::known(0x58);
    /// 0x59 position-loop I gain.
    pub const SEV_POSITION_I: RegisterAddr = RegisterAddr::known(0x59);
    /// 0x5A position-loop D gain.
    pub const SEV_POSITION_D: RegisterAddr = RegisterAddr::known(0x5A);
    /// 0x5B position-loop P dead zone.
    pub const SEV_POSITION_DS: RegisterAddr = RegisterAddr::known(0x5B);
    /// 0x5C position-loop smoothing.
    pub const SEV_POS_SMOOTH: RegisterAddr = RegisterAddr::known(0x5C);
    /// 0x5D speed feed-forward coefficient.
    pub const SEV_SPD_FF: RegisterAddr = RegisterAddr::known(0x5D);
    /// 0x69 low-power mode.
    pub const LOW_POWER_MODE: RegisterAddr = RegisterAddr::known(0x69);
    /// 0x6A direct brake release.
    pub const STATE_BRK_DIRECT_ENABLE: RegisterAddr = RegisterAddr::known(0x6A);
    /// 0x78 error code mirror.
    pub const ERROR: RegisterAddr = RegisterAddr::known(0x78);
    /// 0x79 end-board mode.
    pub const END_BOARD_MODE: RegisterAddr = RegisterAddr::known(0x79);
}

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

/// How a client may write a register: its safety class ([`safety_class`]).
///
/// Enforced by the client library's register write (`robobus::ops::whj::write_register`);
/// kept apart from [`REGISTERS`] so the table of facts and the policy on top of it can be
/// read (and changed) separately.
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

    #[test]
    fn table_is_sorted_and_consistent() {
        for w in REGISTERS.windows(2) {
            assert!(
                w[0].addr < w[1].addr,
                "{:?} before {:?}",
                w[0].name,
                w[1].name
            );
        }
        for reg in &REGISTERS {
            assert_eq!(RegisterInfo::by_addr(reg.addr).unwrap().name, reg.name);
            match reg.half {
                Half::Low => {
                    let hi = RegisterInfo::by_addr(reg.partner().unwrap()).unwrap();
                    assert_eq!(hi.half, Half::High, "{}", reg.name);
                    assert_eq!(hi.access, reg.access, "{}", reg.name);
                    assert_eq!(
                        hi.name.trim_end_matches("_H"),
                        reg.name.trim_end_matches("_L")
                    );
                }
                Half::High => {
                    let lo = RegisterInfo::by_addr(reg.partner().unwrap()).unwrap();
                    assert_eq!(lo.half, Half::Low, "{}", reg.name);
                }
                Half::Single => assert!(reg.partner().is_none()),
            }
            if let (Half::Low, Some(init)) = (reg.half, reg.init) {
                let hi = RegisterInfo::by_addr(reg.partner().unwrap()).unwrap();
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                let hi_init = hi.init.map(|v| v as u16);
                assert_eq!(hi_init, Some(split_i32(init)[1]), "{}", hi.name);
            }
            if let (Some(init), Some(_)) = (reg.init, reg.range) {
                assert!(reg.in_range(init), "{} init {init}", reg.name);
            }
        }
    }

    #[test]
    fn lookups() {
        assert_eq!(RegisterInfo::by_name("sys_id").unwrap().addr, addr::SYS_ID);
        assert_eq!(
            RegisterInfo::by_name("Cur_Position").unwrap().addr,
            addr::CUR_POSITION
        );
        assert_eq!(
            RegisterInfo::by_name("CUR_POSITION_H").unwrap().addr.get(),
            0x15
        );
        assert!(RegisterInfo::by_name("nope").is_none());
        assert!(RegisterInfo::by_raw(0x16).is_none()); // reserved
        assert!(RegisterInfo::by_raw(0xA0).is_none()); // outside
        assert_eq!(RegisterInfo::by_raw(0x30).unwrap().init, Some(3));
        assert_eq!(RegisterInfo::by_raw(0x14).unwrap().access, Access::ReadOnly);
        assert_eq!(
            RegisterAddr::new(0x92),
            Err(RegisterAddrError { value: 0x92 })
        );
        assert_eq!(addr::TAG_POSITION.offset(1).unwrap().get(), 0x37);
        assert!(RegisterAddr::MAX.offset(1).is_err());
    }

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

    #[test]
    fn named_addresses_match_the_table() {
        for (a, name) in [
            (addr::SYS_BPS_CANFD_BRT, "SYS_BPS_CANFD_BRT"),
            (addr::SYS_DEMA_ABSPOS, "SYS_DEMA_ABSPOS"),
            (addr::CUR_POSITION_H, "CUR_POSITION_H"),
            (addr::TAG_SERVO_FLAG, "TAG_SERVO_FLAG"),
            (addr::LIT_MAX_POS_DIFF_H, "LIT_MAX_POS_DIFF_H"),
            (addr::SEV_PARAME_UPDATE, "SEV_PARAME_UPDATE"),
            (addr::SEV_SPD_FF, "SEV_SPD_FF"),
            (addr::END_BOARD_MODE, "END_BOARD_MODE"),
            (addr::TAG_POSITION, "TAG_POSITION_L"),
        ] {
            assert_eq!(a.info().unwrap().name, name);
        }
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
