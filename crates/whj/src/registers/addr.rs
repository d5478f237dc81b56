//! The address of every register in [`REGISTERS`](super::REGISTERS), by its vendor name (a
//! 32-bit pair by its base name for the low word and `_H` for the high word; 0x2A..=0x2F by its
//! first word).

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

#[cfg(test)]
mod tests {
    use crate::registers::addr;

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
}
