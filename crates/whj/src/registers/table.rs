//! The memory control table itself ([`REGISTERS`], one entry per documented register) and
//! the lookups into it.

use super::{Access, Feature, Half, Persistence, RegisterAddr, RegisterInfo, TABLE_LEN, Unit};

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::registers::{RegisterAddrError, addr, split_i32};

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
}
