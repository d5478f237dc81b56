//! One simulated WHJ joint: the firmware state machine over the device-side decoder of
//! `robobus-whj`, on top of the mechanics in [`super::physics`].
//!
//! [`SimJoint::handle`] takes a received frame and the time its last bit arrived and
//! returns the reply (if any) with the time it is ready to be sent; [`SimJoint::advance`]
//! integrates the mechanics up to a point in time. Rules and their sources are §6 of
//! the WHJ joint protocol reference; options for the conflicting ones are in [`JointConfig`].

use core::time::Duration;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robobus_whj::registers::{
    self, Access, Half, Persistence, RegisterInfo, TABLE_LEN, addr as reg,
};
use robobus_whj::reply::Reply as WireReply;
use robobus_whj::units::{ActualSpeed, Current, Position, Temperature, Voltage};
use robobus_whj::{
    BroadcastCurrent, BroadcastFeedback, BroadcastPosition, BroadcastRegister,
    BroadcastRegisterReply, CanFrame, CmdError, ErrorCode, Feature, FeedForward, JointId,
    JointStatus, Malformed, MalformedReason, RegisterAddr, RegisterOp, RegisterSlot, ReplyMask,
    Request, ServoFeedback, Words, WriteData, WriteStatus,
};

use super::config::{BroadcastReadReply, JointConfig, SpeedLimitUnit};
use super::model::rpm_to_rad_s;
use super::physics::{Drive, DriveLimits, Environment, Mechanics};

mod load;
mod protocol;
mod table;

pub use load::Obstacle;

use table::{factory_flash, init_word};

/// Position counts per degree.
const COUNTS_PER_DEG: f64 = 10_000.0;
/// Quiet time after a disable (§6.3).
const DISABLE_SETTLE: Duration = Duration::from_millis(5);
/// Busy time after a save to flash (§6.4).
const SAVE_BUSY: Duration = Duration::from_millis(50);
/// How far the output may pass a position limit before 0x0200 trips, counts (1°) \[inf\].
const LIMIT_TOLERANCE: i64 = 10_000;
/// An over-temperature bit clears only 5 K below the alarm \[inf\].
const TEMP_HYSTERESIS_C: f64 = 5.0;

/// A frame a joint sends, and the instant it is ready for arbitration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Reply {
    /// When the joint has finished processing and wants the bus.
    pub ready_at: Duration,
    /// The frame.
    pub frame: CanFrame,
}

/// What the joint's firmware is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Staggered power-up (`ON_DELAY` = 0): silent until the instant given.
    PowerUpDelay {
        /// When the bootloader starts.
        until: Duration,
    },
    /// In the bootloader: only a write to `IAP_FLAG` (0x49) is answered.
    Bootloader {
        /// When the bootloader started.
        since: Duration,
    },
    /// Running the application.
    Application,
}

/// A snapshot of the values a joint reports, in wire units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sample {
    /// Motor current in counts (1 or 2 mA per count).
    pub current: i32,
    /// Output speed in counts of 0.02 RPM.
    pub speed: i32,
    /// Output position in counts of 0.0001° (after the zero offset).
    pub position: i32,
    /// Whether the drive is enabled.
    pub enabled: bool,
    /// Latched error bits.
    pub error: u16,
    /// Bus voltage in counts of 0.01 V.
    pub voltage: i16,
    /// Temperature in counts of 0.1 °C.
    pub temperature: i16,
    /// Whether the brake is locked.
    pub brake_locked: bool,
    /// Broadcast receive counter.
    pub broadcast_counter: u8,
}

/// A snapshot of a joint's state in engineering units, for tests and displays.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointState {
    /// Node ID the joint answers to.
    pub id: u8,
    /// Firmware phase.
    pub phase: Phase,
    /// Reported position, degrees (after the zero offset).
    pub position_deg: f64,
    /// Physical output angle, degrees (the encoder before the zero offset).
    pub physical_deg: f64,
    /// Output speed, RPM.
    pub speed_rpm: f64,
    /// Motor current, A.
    pub current_a: f64,
    /// Winding temperature, °C.
    pub temperature_c: f64,
    /// Bus voltage, V.
    pub voltage_v: f64,
    /// Whether the drive is enabled.
    pub enabled: bool,
    /// Whether the brake is locked.
    pub brake_locked: bool,
    /// Latched error bits.
    pub error: ErrorCode,
    /// Work mode (0x30).
    pub mode: u16,
    /// Position target (0x36/0x37), counts.
    pub target_position: i32,
    /// Speed target (0x34/0x35), counts of 0.002 RPM.
    pub target_speed: i32,
    /// Current target (0x32/0x33), counts.
    pub target_current: i32,
    /// Electrical input power, W.
    pub input_power_w: f64,
}

/// Result of a register write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum WriteOutcome {
    /// Acknowledged with status 1 (true) or 0 (false).
    Ack(bool),
    /// A read-only register: `CMD_ERR` permission error.
    Permission,
}

/// The flash copy of the table plus the zero offset.
#[derive(Debug, Clone, PartialEq, Eq)]
struct FlashImage {
    words: [u16; TABLE_LEN],
    zero_offset: i64,
}

/// Which stream the communication watchdog guards.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Guard {
    Position,
    Current,
}

/// A simulated WHJ joint.
#[derive(Debug, Clone)]
#[allow(clippy::struct_excessive_bools)] // independent firmware flags
pub struct SimJoint {
    cfg: JointConfig,
    rng: ChaCha8Rng,
    flash: FlashImage,
    ram: [u16; TABLE_LEN],
    phase: Phase,
    bus_id: u8,
    /// The bit rates it talks at: the flash's 0x08 / 0x09, taken at power-up (`None`: a
    /// code no rate has, and it hears nothing).
    rates: Option<robobus_whj::timing::BitRates>,
    enabled: bool,
    errors: u16,
    zero_offset: i64,
    mech: Mechanics,
    env: Environment,
    t: Duration,
    quiet_until: Duration,
    brake_release_used: bool,
    brake_released: bool,
    counter: u8,
    watchdog: Option<(Duration, Guard)>,
    inside_limits: bool,
    speed_ff: f64,
    current_ff: f64,
    frames_handled: u64,
}

impl SimJoint {
    /// A joint powered up at time zero with a factory-fresh flash built from `cfg`.
    /// `seed` drives the measurement noise (and nothing else).
    pub fn new(cfg: JointConfig, seed: u64) -> Self {
        let flash = FlashImage {
            words: factory_flash(&cfg),
            zero_offset: 0,
        };
        let env = Environment {
            supply_v: cfg.supply_voltage_v,
            supply_r: cfg.supply_resistance_ohm,
            ambient_c: cfg.ambient_temp_c,
            load_inertia: cfg.load.inertia_kgm2,
            gravity_nm: cfg.load.gravity_nm,
            external_nm: cfg.load.constant_nm,
            hand: None,
            obstacle: None,
        };
        let mech = Mechanics::new(cfg.initial_position_deg.to_radians(), &env);
        let rng = ChaCha8Rng::seed_from_u64(seed ^ (u64::from(cfg.id) << 32));
        let mut joint = Self {
            bus_id: cfg.id,
            rates: Some(robobus_whj::timing::BitRates::WHJ),
            cfg,
            rng,
            ram: flash.words,
            flash,
            phase: Phase::Application,
            enabled: false,
            errors: 0,
            zero_offset: 0,
            mech,
            env,
            t: Duration::ZERO,
            quiet_until: Duration::ZERO,
            brake_release_used: false,
            brake_released: false,
            counter: 0,
            watchdog: None,
            inside_limits: true,
            speed_ff: 0.0,
            current_ff: 0.0,
            frames_handled: 0,
        };
        joint.power_on(Duration::ZERO);
        joint
    }

    /// The configuration the joint was built with.
    pub fn config(&self) -> &JointConfig {
        &self.cfg
    }

    /// The node ID the joint answers to now.
    pub fn id(&self) -> u8 {
        self.bus_id
    }

    /// The firmware phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// The time up to which the mechanics have been integrated.
    pub fn time(&self) -> Duration {
        self.t
    }

    /// Number of frames the joint has answered.
    pub fn frames_handled(&self) -> u64 {
        self.frames_handled
    }

    /// The bit rates it talks at (taken from flash at power-up): a bus at other rates is
    /// noise to it, and it answers nothing there.
    pub const fn rates(&self) -> Option<robobus_whj::timing::BitRates> {
        self.rates
    }

    /// Switch the supply off and on again at `now`: RAM is lost, flash survives, the joint
    /// goes through its power-up delay and bootloader again. The output keeps its angle.
    pub fn power_cycle(&mut self, now: Duration) {
        self.advance(now);
        self.mech.omega = 0.0;
        self.mech.current = 0.0;
        self.power_on(now);
    }

    /// Fault injection: latch the error `bits` at `now`, as the firmware does when it
    /// detects a fault (bits that disable the drive disable it).
    pub fn inject_error(&mut self, bits: u16, now: Duration) {
        self.advance(now);
        self.latch(bits);
    }

    /// Fault injection: from `now` on the joint answers nothing (a broken transceiver, a
    /// cut cable) until it is power-cycled.
    pub fn fall_silent(&mut self, now: Duration) {
        self.advance(now);
        self.quiet_until = Duration::MAX;
    }

    /// Change the supply voltage (a sagging battery, a bad PSU).
    pub fn set_supply_voltage(&mut self, volts: f64) {
        self.env.supply_v = volts;
    }

    /// Change the constant external torque on the output, N·m (a push, a hard stop).
    pub fn set_external_torque(&mut self, nm: f64) {
        self.env.external_nm = nm;
    }

    /// A hand holding the output at `degrees` (its output angle; `None`: let go). The hand
    /// pulls like a firm grip: a limp joint (disabled without a brake, or in current mode
    /// at a small current) follows it within a few degrees, a braked or position-holding
    /// one does not.
    pub fn set_hand(&mut self, degrees: Option<f64>) {
        self.env.hand = degrees.map(f64::to_radians);
    }

    /// Change the gravity torque amplitude on the output, N·m.
    pub fn set_gravity_torque(&mut self, nm: f64) {
        self.env.gravity_nm = nm;
    }

    /// Change the ambient temperature, °C.
    pub fn set_ambient_temperature(&mut self, celsius: f64) {
        self.env.ambient_c = celsius;
    }

    /// The state in engineering units (no measurement noise).
    pub fn state(&self) -> JointState {
        JointState {
            id: self.bus_id,
            phase: self.phase,
            position_deg: self.reported_position() as f64 / COUNTS_PER_DEG,
            physical_deg: self.mech.theta.to_degrees(),
            speed_rpm: self.mech.omega * 60.0 / core::f64::consts::TAU,
            current_a: self.mech.current,
            temperature_c: self.mech.temp_c,
            voltage_v: self.mech.bus_v,
            enabled: self.enabled,
            brake_locked: self.brake_locked(),
            error: ErrorCode(self.errors),
            mode: self.ram[reg::TAG_WORK_MODE.index()],
            target_position: self.get_i32(reg::TAG_POSITION),
            target_speed: self.get_i32(reg::TAG_SPEED),
            target_current: self.get_i32(reg::TAG_CURRENT),
            input_power_w: self.mech.input_power(),
        }
    }

    /// The value a register read would return now (live values sampled without noise).
    pub fn register(&self, addr: u8) -> u16 {
        let sample = self.sample_exact();
        self.read_word(addr, &sample)
    }

    // ----- time -------------------------------------------------------------------------

    /// Integrate the mechanics and run the firmware's timers up to `now`. The state is
    /// sampled in fixed steps (`physics_step`); calls with a `now` in the past do nothing.
    pub fn advance(&mut self, now: Duration) {
        let step = self.cfg.physics_step.max(Duration::from_micros(1));
        let dt = step.as_secs_f64();
        while self.t + step <= now {
            self.t += step;
            let t = self.t;
            self.run_timers(t);
            if self.phase != Phase::Application {
                // Powered down or in the bootloader: the brake (if any) holds the output.
                let drive = Drive::Off {
                    brake_locked: self.cfg.model.has_brake(),
                };
                let limits = self.limits();
                self.mech.step(
                    dt,
                    drive,
                    &limits,
                    &self.cfg.params,
                    &self.env,
                    self.cfg.position_bandwidth_hz,
                );
                continue;
            }
            let drive = self.drive();
            let limits = self.limits();
            self.mech.step(
                dt,
                drive,
                &limits,
                &self.cfg.params,
                &self.env,
                self.cfg.position_bandwidth_hz,
            );
            self.protect();
        }
    }

    fn run_timers(&mut self, t: Duration) {
        match self.phase {
            Phase::PowerUpDelay { until } if t >= until => {
                if self.cfg.boot.wait_for_iap_flag {
                    self.phase = Phase::Bootloader { since: until };
                } else {
                    self.start_application();
                }
            }
            Phase::Bootloader { since } => {
                if let Some(timeout) = self.cfg.boot.bootloader_timeout
                    && t >= since + timeout
                {
                    self.start_application();
                }
            }
            _ => {}
        }
        if let Some((deadline, guard)) = self.watchdog
            && t >= deadline
        {
            // Communication lost: stop by itself, stay enabled, no error bit (§8.9).
            self.watchdog = None;
            match guard {
                Guard::Position => {
                    let actual = self.reported_position();
                    self.set_i32(reg::TAG_POSITION, actual);
                    self.speed_ff = 0.0;
                    self.current_ff = 0.0;
                }
                Guard::Current => self.set_i32(reg::TAG_CURRENT, 0),
            }
            tracing::debug!(id = self.bus_id, "communication watchdog expired");
        }
    }

    // ----- power-up ---------------------------------------------------------------------

    fn power_on(&mut self, now: Duration) {
        self.t = self.t.max(now);
        self.enabled = false;
        self.errors = 0;
        self.watchdog = None;
        self.brake_release_used = false;
        self.brake_released = false;
        self.quiet_until = Duration::ZERO;
        self.counter = 0;
        self.speed_ff = 0.0;
        self.current_ff = 0.0;
        self.ram = self.flash.words;
        self.zero_offset = self.flash.zero_offset;
        self.bus_id = u8::try_from(self.flash.words[reg::SYS_ID.index()]).unwrap_or(1);
        self.rates = robobus_whj::timing::BitRates::of_codes(
            self.flash.words[reg::SYS_BPS_CANFD_BRT.index()],
            self.flash.words[reg::SYS_BPS_CANFD_DATA.index()],
        );
        let delayed =
            self.flash.words[reg::ON_DELAY.index()] == 0 && self.has_feature(Feature::PowerUpDelay);
        let delay = if delayed {
            self.cfg.boot.boot_delay + self.cfg.boot.boot_delay_per_id * u32::from(self.bus_id)
        } else {
            Duration::ZERO
        };
        if delay > Duration::ZERO {
            self.phase = Phase::PowerUpDelay { until: now + delay };
        } else if self.cfg.boot.wait_for_iap_flag {
            self.phase = Phase::Bootloader { since: now };
        } else {
            self.start_application();
        }
    }

    /// Flash → RAM, 0x38 := 0, targets cleared, enable at power-up if 0x0B = 1 (§6.1).
    fn start_application(&mut self) {
        self.phase = Phase::Application;
        self.ram = self.flash.words;
        for info in &registers::REGISTERS {
            if info.persistence == Persistence::Ram || info.persistence == Persistence::Trigger {
                let a = usize::from(info.addr.get());
                if let Some(slot) = self.ram.get_mut(a) {
                    *slot = init_word(info);
                }
            }
        }
        self.ram[reg::TAG_SERVO_FLAG.index()] = 0;
        self.enabled = false;
        self.mech.reset_loops();
        if self.ram[reg::SYS_ENABLE_ON_POWER.index()] == 1 {
            let _ = self.enable();
        }
    }

    // ----- units ------------------------------------------------------------------------

    /// Whether a gated register exists on this model and firmware: the register table's
    /// firmware gate, and for model-gated features the product's own feature list.
    fn register_available(&self, addr: RegisterAddr) -> bool {
        addr.info()
            .and_then(|info| info.firmware)
            .is_none_or(|feature| self.has_feature(feature))
    }

    /// Whether this joint's product and firmware have `feature`.
    fn has_feature(&self, feature: Feature) -> bool {
        self.cfg.model.facts().has(feature) && feature.gate().admits(self.cfg.firmware)
    }

    fn get_i32(&self, low: RegisterAddr) -> i32 {
        let low = low.index();
        let lo = u32::from(self.ram.get(low).copied().unwrap_or(0));
        let hi = u32::from(self.ram.get(low + 1).copied().unwrap_or(0));
        i32::from_ne_bytes(((hi << 16) | lo).to_ne_bytes())
    }

    fn set_i32(&mut self, low: RegisterAddr, value: i32) {
        let low = low.index();
        let bits = u32::from_ne_bytes(value.to_ne_bytes());
        if let Some(w) = self.ram.get_mut(low) {
            *w = (bits & 0xFFFF) as u16;
        }
        if let Some(w) = self.ram.get_mut(low + 1) {
            *w = (bits >> 16) as u16;
        }
    }

    /// Physical encoder angle in counts.
    fn physical_counts(&self) -> i64 {
        round_i64(self.mech.theta.to_degrees() * COUNTS_PER_DEG)
    }

    /// Reported position in counts (saturated into i32).
    fn reported_position(&self) -> i32 {
        saturate_i32(self.physical_counts() - self.zero_offset)
    }

    fn counts_to_physical_rad(&self, counts: i32) -> f64 {
        ((i64::from(counts) + self.zero_offset) as f64 / COUNTS_PER_DEG).to_radians()
    }

    fn position_limits(&self) -> (i32, i32) {
        let lo = self.get_i32(reg::LIT_MIN_POSITION);
        let hi = self.get_i32(reg::LIT_MAX_POSITION);
        if lo <= hi { (lo, hi) } else { (hi, lo) }
    }

    fn clamp_to_limits(&self, counts: i32) -> i32 {
        let (lo, hi) = self.position_limits();
        counts.clamp(lo, hi)
    }

    fn ma_per_count(&self) -> f64 {
        self.cfg.params.ma_per_count()
    }

    fn limits(&self) -> DriveLimits {
        let p = &self.cfg.params;
        let register =
            f64::from(self.ram[reg::LIT_MAX_CURRENT.index()]) * self.ma_per_count() / 1000.0;
        let max_current = self
            .cfg
            .drive_current_limit_a
            .filter(|a| a.is_finite())
            .map_or(register, |a| register.min(a.abs()));
        let raw_speed = f64::from(self.ram[reg::LIT_MAX_SPEED.index()]);
        let max_speed_rpm = match self.cfg.speed_limit_unit {
            SpeedLimitUnit::PerRatio => raw_speed / f64::from(p.reduction_ratio.max(1)),
            SpeedLimitUnit::CentiRpm => raw_speed * 0.01,
        };
        let max_accel = rpm_to_rad_s(f64::from(self.ram[reg::LIT_MAX_ACC.index()]) * 0.1);
        let low_power = self.ram[reg::LOW_POWER_MODE.index()] == 1
            && self.register_available(reg::LOW_POWER_MODE);
        DriveLimits {
            max_current,
            max_speed: rpm_to_rad_s(max_speed_rpm),
            max_accel,
            power_cap: low_power.then_some(self.cfg.low_power_cap_w),
        }
    }

    fn brake_locked(&self) -> bool {
        self.cfg.model.has_brake() && !self.enabled && !self.brake_released
    }

    fn drive(&self) -> Drive {
        if !self.enabled {
            return Drive::Off {
                brake_locked: self.brake_locked(),
            };
        }
        match self.ram[reg::TAG_WORK_MODE.index()] {
            0 => Drive::OpenLoop {
                duty: f64::from(self.ram[reg::TAG_OPEN_PWM.index()].min(100)) / 100.0,
            },
            1 => Drive::Current {
                amps: f64::from(self.get_i32(reg::TAG_CURRENT)) * self.ma_per_count() / 1000.0
                    + self.current_ff,
            },
            2 => Drive::Speed {
                rad_s: rpm_to_rad_s(f64::from(self.get_i32(reg::TAG_SPEED)) * 0.002),
            },
            _ => {
                let target = self.clamp_to_limits(self.get_i32(reg::TAG_POSITION));
                Drive::Position {
                    target: self.counts_to_physical_rad(target),
                    speed_ff: self.speed_ff,
                    current_ff: self.current_ff,
                }
            }
        }
    }

    // ----- protection -------------------------------------------------------------------

    fn latch(&mut self, bits: u16) {
        let new = bits & !self.errors;
        if new == 0 {
            return;
        }
        self.errors |= bits;
        tracing::debug!(
            id = self.bus_id,
            bits = format_args!("{new:#06x}"),
            "error latched"
        );
        if ErrorCode(new).disables_drive() && self.enabled {
            self.enabled = false;
            self.watchdog = None;
        }
    }

    fn protect(&mut self) {
        let p = self.cfg.params;
        if self.mech.temp_c >= self.cfg.over_temp_c {
            self.latch(ErrorCode::OVER_TEMPERATURE.bits());
        }
        if self.mech.bus_v < self.cfg.under_voltage_v {
            self.latch(ErrorCode::UNDER_VOLTAGE.bits());
        }
        if self.mech.bus_v > self.cfg.over_voltage_v {
            self.latch(ErrorCode::OVER_VOLTAGE.bits());
        }
        if self.mech.current.abs() > self.cfg.over_current_factor * p.peak_current_a() {
            self.latch(ErrorCode::OVER_CURRENT.bits());
        }
        if !self.enabled {
            return;
        }
        let actual = self.physical_counts() - self.zero_offset;
        if self.ram[reg::TAG_WORK_MODE.index()] == 3 {
            // Following error: the commanded trajectory (the target approached under the
            // speed and acceleration limits) minus the actual position. Comparing with the
            // final target instead would trip whenever a joint enabled outside its range
            // drives back to the limit (C9).
            let max_diff = i64::from(self.get_i32(reg::LIT_MAX_POS_DIFF));
            let commanded =
                round_i64(self.mech.reference().to_degrees() * COUNTS_PER_DEG) - self.zero_offset;
            if max_diff > 0 && (commanded - actual).abs() > max_diff {
                self.latch(ErrorCode::FOLLOWING_ERROR.bits());
            }
        }
        let (lo, hi) = self.position_limits();
        let (lo, hi) = (i64::from(lo), i64::from(hi));
        let inside = actual >= lo && actual <= hi;
        if self.inside_limits && (actual < lo - LIMIT_TOLERANCE || actual > hi + LIMIT_TOLERANCE) {
            self.latch(ErrorCode::POSITION_LIMIT.bits());
            self.inside_limits = false;
        } else if inside {
            self.inside_limits = true;
        }
    }

    /// Clear the bits whose cause has ended (§6.4, §7).
    fn clear_errors(&mut self) {
        let mut keep = 0u16;
        if self.mech.temp_c >= self.cfg.over_temp_c - TEMP_HYSTERESIS_C {
            keep |= ErrorCode::OVER_TEMPERATURE.bits();
        }
        if self.mech.bus_v < self.cfg.under_voltage_v {
            keep |= ErrorCode::UNDER_VOLTAGE.bits();
        }
        if self.mech.bus_v > self.cfg.over_voltage_v {
            keep |= ErrorCode::OVER_VOLTAGE.bits();
        }
        self.errors &= keep;
        if self.errors == 0 && self.cfg.auto_enable_after_clear && !self.enabled {
            let _ = self.enable();
        }
    }

    // ----- actions ----------------------------------------------------------------------

    /// Enable the drive; false if refused (a latched error, or the brake released by 0x6A).
    fn enable(&mut self) -> bool {
        if self.errors != 0 || self.brake_released {
            return false;
        }
        if self.enabled {
            return true;
        }
        self.enabled = true;
        self.mech.reset_loops();
        let actual = self.reported_position();
        // Target := actual, clamped: a joint outside its range drives to the limit (C9).
        let target = self.clamp_to_limits(actual);
        self.set_i32(reg::TAG_POSITION, target);
        self.set_i32(reg::TAG_SPEED, 0);
        self.set_i32(reg::TAG_CURRENT, 0);
        self.speed_ff = 0.0;
        self.current_ff = 0.0;
        let (lo, hi) = self.position_limits();
        self.inside_limits = actual >= lo && actual <= hi;
        true
    }

    fn disable(&mut self, now: Duration) {
        self.enabled = false;
        self.watchdog = None;
        if self.cfg.strict_settle {
            self.quiet_until = self.quiet_until.max(now + DISABLE_SETTLE);
        }
    }

    fn change_mode(&mut self, mode: u16) {
        self.ram[reg::TAG_WORK_MODE.index()] = mode;
        // No jump: position target := actual, speed and current targets := 0 (§6.2).
        let actual = self.reported_position();
        let target = if mode == 3 {
            self.clamp_to_limits(actual)
        } else {
            actual
        };
        self.set_i32(reg::TAG_POSITION, target);
        self.set_i32(reg::TAG_SPEED, 0);
        self.set_i32(reg::TAG_CURRENT, 0);
        self.speed_ff = 0.0;
        self.current_ff = 0.0;
        self.watchdog = None;
        self.mech.reset_loops();
    }

    fn save(&mut self, now: Duration) -> bool {
        if self.enabled {
            return false;
        }
        for info in &registers::REGISTERS {
            if info.persistence == Persistence::Flash {
                let a = usize::from(info.addr.get());
                if let (Some(f), Some(r)) = (self.flash.words.get_mut(a), self.ram.get(a)) {
                    *f = *r;
                }
            }
        }
        self.flash.zero_offset = self.zero_offset;
        if self.cfg.strict_settle {
            self.quiet_until = self.quiet_until.max(now + SAVE_BUSY);
        }
        true
    }

    fn set_zero(&mut self) {
        let before = i64::from(self.reported_position());
        self.zero_offset = self.physical_counts();
        // Shift the targets by the same amount so an enabled joint stays still (§6.4).
        let shift = before;
        let target = i64::from(self.get_i32(reg::TAG_POSITION)) - shift;
        self.set_i32(reg::TAG_POSITION, saturate_i32(target));
    }

    /// Apply a new position target from any source; false if the step check rejected it.
    fn set_position_target(&mut self, counts: i32, from_register: bool) -> bool {
        let mode3 = self.ram[reg::TAG_WORK_MODE.index()] == 3;
        let target = if mode3 {
            self.clamp_to_limits(counts)
        } else {
            counts
        };
        let checked =
            self.enabled && mode3 && (!from_register || self.cfg.step.step_check_register_writes);
        if checked {
            let limit = round_i64(self.cfg.step.step_limit_deg * COUNTS_PER_DEG);
            let actual = i64::from(self.reported_position());
            if (i64::from(target) - actual).abs() > limit {
                self.latch(ErrorCode::POSITION_STEP.bits());
                if self.cfg.step.step_error_disables {
                    self.enabled = false;
                    self.watchdog = None;
                }
                return false;
            }
        }
        self.set_i32(reg::TAG_POSITION, target);
        true
    }

    // ----- frames -----------------------------------------------------------------------

    /// A frame whose last bit arrived at `now`: act on it and return the reply, if any,
    /// with the time it is ready for arbitration (`now + processing_delay`).
    ///
    /// The mechanics are advanced to `now` first, so servo feedback shows the state
    /// before the command takes effect (§3.2).
    pub fn handle(&mut self, frame: &CanFrame, now: Duration) -> Option<Reply> {
        self.advance(now);
        if matches!(self.phase, Phase::PowerUpDelay { .. }) || now < self.quiet_until {
            return None;
        }
        let frame = if frame.is_fd() {
            *frame
        } else if self.cfg.accept_classic_frames && !frame.is_extended() {
            CanFrame::new_fd(frame.id(), frame.data()).ok()?
        } else {
            return None;
        };
        let me = JointId::new(self.bus_id).ok()?;
        let reply = match Request::from_frame(&frame) {
            Ok(req) => self.dispatch(req, me, now),
            Err(bad) => self.malformed(&frame, &bad, me, now),
        }?;
        self.frames_handled += 1;
        Some(Reply {
            ready_at: now + self.cfg.processing_delay,
            frame: reply.to_frame(),
        })
    }
}

/// Round half away from zero, saturating.
#[allow(clippy::cast_possible_truncation)] // `as` saturates, which is what we want.
pub(crate) fn round_i64(x: f64) -> i64 {
    x.round() as i64
}

pub(crate) fn saturate_i32(x: i64) -> i32 {
    i32::try_from(x).unwrap_or(if x < 0 { i32::MIN } else { i32::MAX })
}

fn saturate_i16(x: i64) -> i16 {
    i16::try_from(x).unwrap_or(if x < 0 { i16::MIN } else { i16::MAX })
}

fn status(ok: bool) -> WriteStatus {
    if ok {
        WriteStatus::Ok
    } else {
        WriteStatus::Failed
    }
}

/// A standard normal sample (Box–Muller).
fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random::<f64>().max(1e-12);
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (core::f64::consts::TAU * u2).cos()
}
