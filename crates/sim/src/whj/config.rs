//! Configuration of a simulated joint: product, initial physical state, and every
//! behaviour the vendor documents disagree on, as a named option.
//!
//! Defaults follow the "Sim default" column of §10 of the WHJ joint protocol reference and the
//! `\[inf\]` rules of §6; the doc of each field names the rule or conflict it settles.

use core::time::Duration;

use robobus_whj::broadcast::FeedForwardLayout;
use robobus_whj::units::FirmwareVersion;

use super::model::{ModelParams, WhjModel};

/// How register 0x41 (`LIT_MAX_SPEED`) and 0x42 (`LIT_MAX_ACC`) are scaled (conflict C3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SpeedLimitUnit {
    /// 0x41 in 1/ratio output RPM (EN; the default 3000 then equals the published peak
    /// speed), 0x42 in 0.1 RPM/s at the output. The default.
    #[default]
    PerRatio,
    /// 0x41 in 0.01 output RPM (ZH/V1.0/V1.1/GRIP), 0x42 in 0.1 RPM/s at the output.
    CentiRpm,
}

/// Form of a joint's answer to a broadcast register read (C19).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BroadcastReadReply {
    /// `[01, index, data…]` as V1.1 prints it. The default.
    #[default]
    Doc,
    /// `[len, 01, index, data…]` as GRIP parses it.
    LengthPrefixed,
}

/// Which frames re-arm and trigger the 20 ms communication watchdog (§8.9).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[allow(clippy::struct_excessive_bools)]
pub struct WatchdogConfig {
    /// Time without a new command after which the joint stops (20 ms).
    pub timeout: Duration,
    /// Only 0x2F frames with valid data for this joint re-arm it (default: any 0x2F).
    pub rearm_only_with_data: bool,
    /// Also guard 0x4F current streams (on expiry: current target := 0). Default off.
    pub guard_broadcast_current: bool,
    /// Also guard point-to-point 0x200 position streams. Default off.
    pub guard_point_to_point: bool,
}

impl Default for WatchdogConfig {
    fn default() -> Self {
        Self {
            timeout: Duration::from_millis(20),
            rearm_only_with_data: false,
            guard_broadcast_current: false,
            guard_point_to_point: false,
        }
    }
}

/// How the joint powers up (§6.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BootConfig {
    /// Stay in the bootloader (answering only writes to 0x49) until `IAP_FLAG := 0` (C24).
    /// `false` boots straight into the application.
    pub wait_for_iap_flag: bool,
    /// Leave the bootloader on its own after this time (`bootloader_timeout_ms`); `None`
    /// (default) waits forever.
    pub bootloader_timeout: Option<Duration>,
    /// Staggered power-up delay while `ON_DELAY` (0x1F) = 0 (`boot_delay_ms`, C33: 0).
    pub boot_delay: Duration,
    /// Extra staggered delay per node ID (delay = `boot_delay + id × boot_delay_per_id`).
    pub boot_delay_per_id: Duration,
}

impl Default for BootConfig {
    fn default() -> Self {
        Self {
            wait_for_iap_flag: true,
            bootloader_timeout: None,
            boot_delay: Duration::ZERO,
            boot_delay_per_id: Duration::ZERO,
        }
    }
}

/// Position-step protection (§6.6, C10).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepConfig {
    /// A new position target further than this from the actual position is rejected and
    /// latches 0x4000 (10°).
    pub step_limit_deg: f64,
    /// Whether the rejection also disables the drive (default: no, a warning).
    pub step_error_disables: bool,
    /// Whether writes to 0x36/0x37 are checked too (default: yes).
    pub step_check_register_writes: bool,
}

impl Default for StepConfig {
    fn default() -> Self {
        Self {
            step_limit_deg: 10.0,
            step_error_disables: false,
            step_check_register_writes: true,
        }
    }
}

/// External load on the joint output.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Load {
    /// Extra inertia at the output, kg·m².
    pub inertia_kgm2: f64,
    /// Gravity torque amplitude, N·m: the load torque is `-gravity_nm × cos(θ)` with θ the
    /// physical output angle (0 = horizontal arm).
    pub gravity_nm: f64,
    /// Constant external torque, N·m (a push, a hard stop).
    pub constant_nm: f64,
}

/// Everything about one simulated joint. Build with [`JointConfig::new`] and adjust fields.
#[derive(Debug, Clone, PartialEq)]
#[allow(clippy::struct_excessive_bools)]
pub struct JointConfig {
    /// Node ID in flash at first power-up (1..=30).
    pub id: u8,
    /// Product.
    pub model: WhjModel,
    /// Physical parameters (from [`WhjModel::params`]; override to experiment).
    pub params: ModelParams,
    /// Firmware version in 0x03 (C28; default 0xD522, passes every gate).
    pub firmware: FirmwareVersion,
    /// 96-bit unique ID (0x2A..0x2F, low word first).
    pub unique_id: [u16; 6],
    /// Physical output angle at power-up, degrees (the absolute encoder reading).
    pub initial_position_deg: f64,
    /// Position limits written to flash at first power-up, degrees (default ±360°, §6.5).
    pub position_limits_deg: (f64, f64),
    /// Supply voltage at no load, V (default 24.00).
    pub supply_voltage_v: f64,
    /// Source resistance of the supply, Ω: the bus voltage sags by `R × I_bus` \[inf\].
    pub supply_resistance_ohm: f64,
    /// Ambient temperature, °C (the joint starts at it).
    pub ambient_temp_c: f64,
    /// Over-temperature alarm (0x0008), °C (90, §6.9).
    pub over_temp_c: f64,
    /// Under-voltage trip (0x0004), V (20.0 \[inf\]).
    pub under_voltage_v: f64,
    /// Over-voltage trip (0x0002), V (27.0 \[inf\]).
    pub over_voltage_v: f64,
    /// Hardware over-current trip (0x0040) as a multiple of the peak current \[inf\]: the
    /// 0x40 limit clamps the controllers, a current above this trips.
    pub over_current_factor: f64,
    /// Input power cap of the low-power mode (0x69 = 1), W (80).
    pub low_power_cap_w: f64,
    /// Load on the output.
    pub load: Load,
    /// The most current the drive can give, A, whatever the current limit register 0x40
    /// says (`None`, the default: 0x40 alone limits it) \[inf\]: a weak or hot drive. With
    /// less current than a motion needs (against a [`Load`], or to accelerate the output)
    /// the joint falls behind its position set-points, as a real loaded joint does.
    pub drive_current_limit_a: Option<f64>,
    /// Standard deviation of the measured-current noise, mA (0 = exact; seeded).
    pub current_noise_ma: f64,
    /// Physics integration step.
    pub physics_step: Duration,
    /// Time from the end of a received frame to the reply being ready for arbitration.
    pub processing_delay: Duration,
    /// Boot behaviour.
    pub boot: BootConfig,
    /// Frames within 5 ms of a disable and 50 ms of a save are dropped (`strict_settle`, §6.3/6.4).
    pub strict_settle: bool,
    /// Re-enable on its own after a successful clear-error (C8; default off).
    pub auto_enable_after_clear: bool,
    /// A new ID written to 0x01 takes effect at once instead of after save + reboot (C7).
    pub id_change_immediate: bool,
    /// Position-step protection.
    pub step: StepConfig,
    /// Scale of 0x41/0x42 (C3).
    pub speed_limit_unit: SpeedLimitUnit,
    /// Status reply length: 16 (default) or 12 (C6).
    pub status_len_16: bool,
    /// `CMD_ERR` command byte (C12; 0xFF).
    pub cmd_err_code: u8,
    /// Command 0x03 (GRIP's write-without-reply) writes silently instead of `CMD_ERR`.
    pub silent_write_cmd3: bool,
    /// Writes of any even length set consecutive registers (default: only 1, 2, 4 bytes).
    pub any_even_write_length: bool,
    /// Frames to node 0: apply writes without replying (default: ignore, C32).
    pub apply_id0_writes: bool,
    /// Classic (non-FD) frames are handled like FD ones (default: ignored, §1.1).
    pub accept_classic_frames: bool,
    /// Broadcast 0x2F feed-forward selector layout (C17).
    pub feed_forward_layout: FeedForwardLayout,
    /// Broadcast register-read reply form (C19).
    pub broadcast_read_reply: BroadcastReadReply,
    /// Communication watchdog (§8.9).
    pub watchdog: WatchdogConfig,
    /// Position-loop bandwidth of the simulated controller, Hz.
    pub position_bandwidth_hz: f64,
}

impl JointConfig {
    /// Defaults for joint `id` of product `model`.
    pub fn new(id: u8, model: WhjModel) -> Self {
        Self {
            id,
            model,
            params: model.params(),
            firmware: FirmwareVersion::SIMULATOR_DEFAULT,
            unique_id: [
                0x5157,
                0x4A48,
                u16::from(id),
                0x0000,
                model.model().code(),
                0x5253,
            ],
            initial_position_deg: 0.0,
            position_limits_deg: (-360.0, 360.0),
            supply_voltage_v: 24.0,
            supply_resistance_ohm: 0.05,
            ambient_temp_c: 25.0,
            over_temp_c: 90.0,
            under_voltage_v: 20.0,
            over_voltage_v: 27.0,
            over_current_factor: 1.5,
            low_power_cap_w: 80.0,
            load: Load::default(),
            drive_current_limit_a: None,
            current_noise_ma: 0.0,
            physics_step: Duration::from_micros(100),
            processing_delay: Duration::from_micros(20),
            boot: BootConfig::default(),
            strict_settle: true,
            auto_enable_after_clear: false,
            id_change_immediate: false,
            step: StepConfig::default(),
            speed_limit_unit: SpeedLimitUnit::default(),
            status_len_16: true,
            cmd_err_code: 0xFF,
            silent_write_cmd3: false,
            any_even_write_length: false,
            apply_id0_writes: false,
            accept_classic_frames: false,
            feed_forward_layout: FeedForwardLayout::default(),
            broadcast_read_reply: BroadcastReadReply::default(),
            watchdog: WatchdogConfig::default(),
            position_bandwidth_hz: 25.0,
        }
    }

    /// The same configuration with the bootloader handshake switched off (the joint
    /// boots straight into the application).
    #[must_use]
    pub fn without_iap(mut self) -> Self {
        self.boot.wait_for_iap_flag = false;
        self
    }
}
