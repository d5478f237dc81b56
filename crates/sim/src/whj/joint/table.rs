//! A joint's register table: reads, checked writes and what each write does, and the
//! factory flash image.

use super::{
    Access, COUNTS_PER_DEG, Duration, Half, JointConfig, Phase, RegisterAddr, RegisterInfo, Sample,
    SimJoint, SpeedLimitUnit, TABLE_LEN, WriteOutcome, reg, registers, round_i64, saturate_i32,
};

impl SimJoint {
    pub(super) fn read_word(&self, addr: u8, s: &Sample) -> u16 {
        let lo = |v: i32| (u32::from_ne_bytes(v.to_ne_bytes()) & 0xFFFF) as u16;
        let hi = |v: i32| (u32::from_ne_bytes(v.to_ne_bytes()) >> 16) as u16;
        let Ok(a) = RegisterAddr::new(addr) else {
            return 0;
        };
        match a {
            reg::SIGNATURE => registers::SIGNATURE_VALUE,
            reg::SYS_ERROR | reg::ERROR => s.error,
            reg::SYS_VOLTAGE => s.voltage.cast_unsigned(),
            reg::SYS_TEMP => s.temperature.cast_unsigned(),
            reg::SYS_ENABLE_DRIVER => u16::from(s.enabled),
            // Triggers read as 0.
            reg::SYS_SAVE_TO_FLASH
            | reg::SYS_DEMA_ABSPOS
            | reg::SYS_SET_ZERO_POS
            | reg::SYS_CLEAR_ERROR
            | reg::SEV_PARAME_UPDATE => 0,
            reg::CUR_CURRENT => lo(s.current),
            reg::CUR_CURRENT_H => hi(s.current),
            reg::CUR_SPEED => lo(s.speed),
            reg::CUR_SPEED_H => hi(s.speed),
            reg::CUR_POSITION => lo(s.position),
            reg::CUR_POSITION_H => hi(s.position),
            reg::BROADCAST_COUNTER if self.register_available(a) => u16::from(s.broadcast_counter),
            reg::STATE_BRK_DIRECT_ENABLE if self.register_available(a) => {
                u16::from(self.brake_released)
            }
            a if a.info().is_none() || !self.register_available(a) => 0,
            a => self.ram.get(a.index()).copied().unwrap_or(0),
        }
    }

    /// Read `count` registers from `start` into `out`, sampling the live values once.
    pub(crate) fn read_words(&mut self, start: u8, out: &mut [u16]) {
        let s = self.sample();
        for (i, w) in out.iter_mut().enumerate() {
            let a = usize::from(start) + i;
            *w = u8::try_from(a).map_or(0, |a| self.read_word(a, &s));
        }
    }

    /// Check a word write without side effects.
    pub(super) fn precheck(&self, addr: u8, value: u16) -> Result<(), WriteOutcome> {
        let Some(info) = RegisterInfo::by_raw(addr) else {
            return Err(WriteOutcome::Ack(false));
        };
        if info.access == Access::ReadOnly {
            return Err(WriteOutcome::Permission);
        }
        if !self.register_available(info.addr) {
            return Err(WriteOutcome::Ack(false));
        }
        if info.half == Half::Single && !info.in_range(i32::from(value.cast_signed())) {
            // Flags accept only 0/1 (§2.4); enumerations and IDs their documented range.
            return Err(WriteOutcome::Ack(false));
        }
        Ok(())
    }

    /// Write consecutive registers from one command (1, 2 or 4 data bytes, §2.3).
    pub(crate) fn write_words(&mut self, start: u8, words: &[u16], now: Duration) -> WriteOutcome {
        let mut first_failure = None;
        for (i, &w) in words.iter().enumerate() {
            let Some(a) = usize::from(start)
                .checked_add(i)
                .and_then(|a| u8::try_from(a).ok())
            else {
                return WriteOutcome::Ack(false);
            };
            if let Err(outcome) = self.precheck(a, w) {
                if outcome == WriteOutcome::Permission {
                    return outcome;
                }
                first_failure.get_or_insert(outcome);
            }
        }
        if let Some(outcome) = first_failure {
            return outcome;
        }
        let mut ok = true;
        let mut i = 0;
        while i < words.len() {
            let Some(a) = u8::try_from(usize::from(start) + i)
                .ok()
                .and_then(|a| RegisterAddr::new(a).ok())
            else {
                break;
            };
            let w = words[i];
            // Targets are applied as one 32-bit value when both halves come together.
            if matches!(a, reg::TAG_CURRENT | reg::TAG_SPEED | reg::TAG_POSITION)
                && i + 1 < words.len()
            {
                let value = i32::from_ne_bytes(
                    (u32::from(words[i + 1]) << 16 | u32::from(w)).to_ne_bytes(),
                );
                ok &= self.write_target(a, value);
                i += 2;
                continue;
            }
            ok &= self.write_one(a, w, now);
            i += 1;
        }
        WriteOutcome::Ack(ok)
    }

    pub(super) fn write_target(&mut self, low: RegisterAddr, value: i32) -> bool {
        if low == reg::TAG_POSITION {
            self.set_position_target(value, true)
        } else {
            self.set_i32(low, value);
            true
        }
    }

    pub(super) fn write_one(&mut self, addr: RegisterAddr, value: u16, now: Duration) -> bool {
        let a = addr.index();
        match addr {
            reg::SYS_ID => {
                self.ram[a] = value;
                if self.cfg.id_change_immediate {
                    self.bus_id = u8::try_from(value).unwrap_or(self.bus_id);
                }
                true
            }
            reg::SYS_ENABLE_DRIVER => {
                if value == 1 {
                    self.enable()
                } else {
                    self.disable(now);
                    true
                }
            }
            reg::SYS_SAVE_TO_FLASH => value == 0 || self.save(now),
            reg::SYS_DEMA_ABSPOS => {
                if value == 1 {
                    tracing::warn!(
                        id = self.bus_id,
                        "SYS_DEMA_ABSPOS written: calibration not simulated (C15)"
                    );
                }
                true
            }
            reg::SYS_SET_ZERO_POS => {
                if value == 1 {
                    self.set_zero();
                }
                true
            }
            reg::SYS_CLEAR_ERROR => {
                if value == 1 {
                    self.clear_errors();
                }
                true
            }
            reg::TAG_WORK_MODE => {
                self.change_mode(value);
                true
            }
            reg::TAG_CURRENT
            | reg::TAG_CURRENT_H
            | reg::TAG_SPEED
            | reg::TAG_SPEED_H
            | reg::TAG_POSITION
            | reg::TAG_POSITION_H => {
                // A lone half: every 16-bit write applies at once (torn values possible).
                let low = match addr.info().map(|i| i.half) {
                    Some(Half::High) => addr.get().wrapping_sub(1),
                    _ => addr.get(),
                };
                let Ok(low) = RegisterAddr::new(low) else {
                    return false;
                };
                let mut words = [self.ram[low.index()], self.ram[low.index() + 1]];
                words[a - low.index()] = value;
                let v = i32::from_ne_bytes(
                    (u32::from(words[1]) << 16 | u32::from(words[0])).to_ne_bytes(),
                );
                self.write_target(low, v)
            }
            reg::IAP_FLAG => {
                if value == 1 {
                    // Firmware update requested: back to the bootloader.
                    self.enabled = false;
                    self.watchdog = None;
                    self.phase = Phase::Bootloader { since: now };
                }
                true
            }
            reg::BROADCAST_COUNTER => {
                self.counter = u8::try_from(value).unwrap_or(0);
                true
            }
            reg::SEV_PARAME_UPDATE => true,
            reg::STATE_BRK_DIRECT_ENABLE => self.write_brake_release(value),
            _ => {
                if let Some(w) = self.ram.get_mut(a) {
                    *w = value;
                }
                true
            }
        }
    }

    /// 0x6A direct brake release (§6.8): once per power cycle, only while disabled.
    pub(super) fn write_brake_release(&mut self, value: u16) -> bool {
        if value == 0 {
            self.brake_released = false;
            return true;
        }
        if self.enabled || self.brake_release_used {
            return false;
        }
        self.brake_release_used = true;
        self.brake_released = true;
        true
    }
}

/// The factory flash image of a joint.
pub(super) fn factory_flash(cfg: &JointConfig) -> [u16; TABLE_LEN] {
    let p = &cfg.params;
    let mut w = [0u16; TABLE_LEN];
    for info in &registers::REGISTERS {
        if let Some(slot) = w.get_mut(usize::from(info.addr.get())) {
            *slot = init_word(info);
        }
    }
    let mut put32 = |low: usize, v: i32| {
        let bits = u32::from_ne_bytes(v.to_ne_bytes());
        w[low] = (bits & 0xFFFF) as u16;
        w[low + 1] = (bits >> 16) as u16;
    };
    put32(
        reg::LIT_MIN_POSITION.index(),
        saturate_i32(round_i64(cfg.position_limits_deg.0 * COUNTS_PER_DEG)),
    );
    put32(
        reg::LIT_MAX_POSITION.index(),
        saturate_i32(round_i64(cfg.position_limits_deg.1 * COUNTS_PER_DEG)),
    );
    put32(reg::LIT_MAX_POS_DIFF.index(), 300_000);
    w[reg::SIGNATURE.index()] = registers::SIGNATURE_VALUE;
    w[reg::SYS_ID.index()] = u16::from(cfg.id);
    w[reg::SYS_MODEL_TYPE.index()] = cfg.model.model().code();
    w[reg::SYS_FW_VERSION.index()] = cfg.firmware.0;
    w[reg::SYS_REDU_RATIO.index()] = p.reduction_ratio;
    // C11: the bit-rate registers say what the bus really runs at (1M / 5M).
    w[reg::SYS_BPS_CANFD_BRT.index()] = 2;
    w[reg::SYS_BPS_CANFD_DATA.index()] = 5;
    let peak_counts = p.peak_current_a() * 1000.0 / p.ma_per_count();
    w[reg::LIT_MAX_CURRENT.index()] = u16::try_from(round_i64(peak_counts)).unwrap_or(u16::MAX);
    w[reg::LIT_MAX_SPEED.index()] = match cfg.speed_limit_unit {
        SpeedLimitUnit::PerRatio => 3000,
        SpeedLimitUnit::CentiRpm => {
            u16::try_from(round_i64(p.peak_speed_rpm * 100.0)).unwrap_or(u16::MAX)
        }
    };
    w[reg::LIT_MAX_ACC.index()] = 5000;
    w[reg::LIT_MAX_DEC.index()] = 5000;
    w[reg::MOT_MODEL_ID.index()..reg::MOT_MODEL_ID.index() + 6].copy_from_slice(&cfg.unique_id);
    // Factory gains: raw values, not used by the idealised loops [inf].
    let gains: [(RegisterAddr, u16); 13] = [
        (reg::SEV_CURRENT_P, 1200),
        (reg::SEV_CURRENT_I, 60),
        (reg::SEV_CURRENT_D, 0),
        (reg::SEV_SPEED_P, 800),
        (reg::SEV_SPEED_I, 20),
        (reg::SEV_SPEED_D, 0),
        (reg::SEV_SPEED_DS, 0),
        (reg::SEV_POSITION_P, 300),
        (reg::SEV_POSITION_I, 0),
        (reg::SEV_POSITION_D, 0),
        (reg::SEV_POSITION_DS, 0),
        (reg::SEV_POS_SMOOTH, 50),
        (reg::SEV_SPD_FF, 50),
    ];
    for (a, v) in gains {
        w[a.index()] = v;
    }
    w
}

pub(super) fn init_word(info: &RegisterInfo) -> u16 {
    // A pair's initial value is the i32 on its low word.
    let v = match info.half {
        Half::High => info
            .partner()
            .and_then(RegisterInfo::by_addr)
            .and_then(|low| low.init)
            .unwrap_or(0),
        Half::Single | Half::Low => info.init.unwrap_or(0),
    };
    let bits = u32::from_ne_bytes(v.to_ne_bytes());
    match info.half {
        Half::High => (bits >> 16) as u16,
        Half::Single | Half::Low => (bits & 0xFFFF) as u16,
    }
}
