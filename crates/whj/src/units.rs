//! Units of the wire values, model codes and firmware versions (§5 of
//! the WHJ joint protocol reference).
//!
//! Every wire value keeps its raw integer; the newtypes here only add named conversions.
//! The scales are named constants in one place. Conversions use plain multiplication, so
//! they work without `std` or `libm`.

use core::fmt;

/// Position LSB: 0.0001° (3 600 000 counts per output revolution).
pub const POSITION_DEG_PER_COUNT: f64 = 0.0001;
/// Position counts per degree (10 000).
pub const POSITION_COUNTS_PER_DEG: i32 = 10_000;
/// Target speed LSB (0x34/0x35, 0x300 frames, speed feed-forward): 0.002 RPM.
pub const TARGET_SPEED_RPM_PER_COUNT: f64 = 0.002;
/// Actual speed LSB (0x12/0x13 and every feedback frame): 0.02 RPM.
///
/// Conflict C1: EN-MCT §2.2 says 0.002 RPM; V1.0, V1.1, ZH and public code say 0.02. This is
/// the one place the scale is chosen; [`ALT_ACTUAL_SPEED_RPM_PER_COUNT`] is the other reading.
pub const ACTUAL_SPEED_RPM_PER_COUNT: f64 = 0.02;
/// The alternative (EN-MCT) reading of the actual-speed LSB, conflict C1.
pub const ALT_ACTUAL_SPEED_RPM_PER_COUNT: f64 = 0.002;
/// Voltage LSB: 0.01 V.
pub const VOLTAGE_V_PER_COUNT: f64 = 0.01;
/// Temperature LSB: 0.1 °C.
pub const TEMPERATURE_C_PER_COUNT: f64 = 0.1;
/// Acceleration LSB of the acceleration registers: 0.1 rpm/s.
pub const ACCELERATION_RPM_S_PER_COUNT: f64 = 0.1;
/// Current feed-forward LSB in the 0x2F broadcast frame: 2 mA for every model.
pub const CURRENT_FF_MA_PER_COUNT: i32 = 2;

/// Round half away from zero and saturate into `i32` (no `libm` needed).
#[allow(clippy::cast_possible_truncation)] // `as` saturates; the range check is the caller's.
fn round_to_i64(x: f64) -> i64 {
    if x >= 0.0 {
        (x + 0.5) as i64
    } else {
        (x - 0.5) as i64
    }
}

/// A value that does not fit the wire type after scaling.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("{quantity} {value} out of range (allowed: {min}..={max})")]
pub struct UnitRangeError {
    /// What was converted ("position (°)", ...).
    pub quantity: &'static str,
    /// The value that was given, in engineering units.
    pub value: f64,
    /// Smallest allowed value in engineering units.
    pub min: f64,
    /// Largest allowed value in engineering units.
    pub max: f64,
}

fn scaled_i32(quantity: &'static str, value: f64, per_count: f64) -> Result<i32, UnitRangeError> {
    let min = f64::from(i32::MIN) * per_count;
    let max = f64::from(i32::MAX) * per_count;
    // NaN fails both comparisons and is rejected too.
    if value >= min && value <= max {
        let raw = round_to_i64(value / per_count);
        i32::try_from(raw).map_err(|_| UnitRangeError {
            quantity,
            value,
            min,
            max,
        })
    } else {
        Err(UnitRangeError {
            quantity,
            value,
            min,
            max,
        })
    }
}

macro_rules! raw_i32_newtype {
    ($(#[$m:meta])* $name:ident) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
        pub struct $name(pub i32);

        impl $name {
            /// The raw wire value.
            pub const fn raw(self) -> i32 {
                self.0
            }
        }

        impl From<i32> for $name {
            fn from(raw: i32) -> Self {
                Self(raw)
            }
        }

        impl From<$name> for i32 {
            fn from(v: $name) -> i32 {
                v.0
            }
        }
    };
}

raw_i32_newtype!(
    /// An output position in 0.0001° counts (i32; targets, actual position, limits).
    Position
);
raw_i32_newtype!(
    /// A target speed in 0.002 RPM counts (0x34/0x35, `0x300+ID` frames).
    TargetSpeed
);
raw_i32_newtype!(
    /// An actual speed in 0.02 RPM counts ([`ACTUAL_SPEED_RPM_PER_COUNT`], conflict C1).
    ActualSpeed
);
raw_i32_newtype!(
    /// A motor current in model-dependent counts (1 mA, or 2 mA on the larger models; see
    /// [`CurrentScale`]).
    Current
);

impl Position {
    /// Position in degrees.
    pub fn degrees(self) -> f64 {
        f64::from(self.0) * POSITION_DEG_PER_COUNT
    }

    /// The position nearest to `deg` degrees, or an error if it does not fit an i32.
    pub fn from_degrees(deg: f64) -> Result<Self, UnitRangeError> {
        scaled_i32("position (°)", deg, POSITION_DEG_PER_COUNT).map(Self)
    }
}

impl TargetSpeed {
    /// Target speed in RPM.
    pub fn rpm(self) -> f64 {
        f64::from(self.0) * TARGET_SPEED_RPM_PER_COUNT
    }

    /// The target speed nearest to `rpm`, or an error if it does not fit an i32.
    pub fn from_rpm(rpm: f64) -> Result<Self, UnitRangeError> {
        scaled_i32("target speed (RPM)", rpm, TARGET_SPEED_RPM_PER_COUNT).map(Self)
    }
}

impl ActualSpeed {
    /// Actual speed in RPM ([`ACTUAL_SPEED_RPM_PER_COUNT`]).
    pub fn rpm(self) -> f64 {
        f64::from(self.0) * ACTUAL_SPEED_RPM_PER_COUNT
    }

    /// The actual speed nearest to `rpm` (simulator side).
    pub fn from_rpm(rpm: f64) -> Result<Self, UnitRangeError> {
        scaled_i32("actual speed (RPM)", rpm, ACTUAL_SPEED_RPM_PER_COUNT).map(Self)
    }
}

impl Current {
    /// Current in mA for a joint with the given scale (widened: 2 × `i32::MIN` fits i64).
    pub fn milliamps(self, scale: CurrentScale) -> i64 {
        i64::from(self.0) * i64::from(scale.ma_per_count())
    }

    /// The current nearest to `ma` milliamps for a joint with the given scale.
    pub fn from_milliamps(ma: f64, scale: CurrentScale) -> Result<Self, UnitRangeError> {
        scaled_i32("current (mA)", ma, f64::from(scale.ma_per_count())).map(Self)
    }
}

/// A bus voltage in 0.01 V counts (i16).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Voltage(pub i16);

impl Voltage {
    /// The raw wire value.
    pub const fn raw(self) -> i16 {
        self.0
    }
    /// Voltage in volts.
    #[allow(clippy::cast_possible_truncation)] // |volts| < 328: exact to f32's precision
    pub fn volts(self) -> f32 {
        (f64::from(self.0) * VOLTAGE_V_PER_COUNT) as f32
    }
    /// Voltage in millivolts (exact).
    pub const fn millivolts(self) -> i32 {
        self.0 as i32 * 10
    }
}

/// A temperature in 0.1 °C counts (i16).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Temperature(pub i16);

impl Temperature {
    /// The raw wire value.
    pub const fn raw(self) -> i16 {
        self.0
    }
    /// Temperature in °C.
    #[allow(clippy::cast_possible_truncation)] // |°C| < 3,277: exact to f32's precision
    pub fn celsius(self) -> f32 {
        (f64::from(self.0) * TEMPERATURE_C_PER_COUNT) as f32
    }
}

/// How many mA one current count stands for (conflict C2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum CurrentScale {
    /// 1 mA per count (Joint 03/10/30, and the default for unknown models).
    #[default]
    OneMilliamp,
    /// 2 mA per count (Joint 60; Joint 120 by inference).
    TwoMilliamps,
}

impl CurrentScale {
    /// Milliamps per count (1 or 2).
    pub const fn ma_per_count(self) -> i32 {
        match self {
            Self::OneMilliamp => 1,
            Self::TwoMilliamps => 2,
        }
    }
}

/// The model code in register 0x02 (`SYS_MODEL_TYPE`, §5.2). Unknown codes survive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Model {
    /// 0x02: Joint 10 (internal J14), WHJ10.
    Joint10,
    /// 0x03: Joint 30 (J17), WHJ30.
    Joint30,
    /// 0x04: Joint 60 (J20), WHJ60; 2 mA current LSB.
    Joint60,
    /// 0x05: Joint 120 (J25), WHJ120; 2 mA current LSB (inferred).
    Joint120,
    /// 0x06: gripper (EN/ZH/GRIP only).
    Gripper,
    /// 0x07: Joint 03 (J3), WHJ03 (EN/V1.1 only).
    Joint03,
    /// Any other code.
    Unknown(u16),
}

impl Model {
    /// The model for a register value.
    pub const fn from_code(code: u16) -> Self {
        match code {
            0x02 => Self::Joint10,
            0x03 => Self::Joint30,
            0x04 => Self::Joint60,
            0x05 => Self::Joint120,
            0x06 => Self::Gripper,
            0x07 => Self::Joint03,
            other => Self::Unknown(other),
        }
    }

    /// The register value.
    pub const fn code(self) -> u16 {
        match self {
            Self::Joint10 => 0x02,
            Self::Joint30 => 0x03,
            Self::Joint60 => 0x04,
            Self::Joint120 => 0x05,
            Self::Gripper => 0x06,
            Self::Joint03 => 0x07,
            Self::Unknown(code) => code,
        }
    }

    /// A human-readable name ("WHJ60"), or "unknown".
    pub const fn name(self) -> &'static str {
        match self {
            Self::Joint10 => "WHJ10",
            Self::Joint30 => "WHJ30",
            Self::Joint60 => "WHJ60",
            Self::Joint120 => "WHJ120",
            Self::Gripper => "gripper",
            Self::Joint03 => "WHJ03",
            Self::Unknown(_) => "unknown",
        }
    }

    /// The current LSB of this model (2 mA on Joint 60/120, else 1 mA; C2), from
    /// [`crate::PRODUCTS`]; 1 mA for the gripper and unknown codes.
    pub const fn current_scale(self) -> CurrentScale {
        match self.facts() {
            Some(p) => p.current_scale,
            None => CurrentScale::OneMilliamp,
        }
    }

    /// The peak output speed from the product pages, RPM, if known (from
    /// [`crate::PRODUCTS`]): 30 (WHJ03), 37.5 (WHJ10, WHJ30), 30 (WHJ60, WHJ120); each
    /// equals the factory speed limit 3000 (0x41) divided by the reduction ratio (§9, C3).
    pub const fn peak_output_speed_rpm(self) -> Option<f64> {
        match self.facts() {
            Some(p) => Some(p.peak_output_speed_rpm),
            None => None,
        }
    }

    /// The gear reduction ratio from the product pages, if known (from [`crate::PRODUCTS`]).
    pub const fn reduction_ratio(self) -> Option<u16> {
        match self.facts() {
            Some(p) => Some(p.reduction_ratio),
            None => None,
        }
    }
}

impl fmt::Display for Model {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Unknown(code) => write!(f, "unknown model {code:#06x}"),
            other => f.write_str(other.name()),
        }
    }
}

/// The firmware version in register 0x03 (§5.3, conflict C28), kept raw.
///
/// Feature gates quote labels such as "519", "D5.XX" and "D522"; these read as the
/// register printed as four hex digits, which is what [`fmt::Display`] shows. The gates
/// themselves are data: [`crate::FIRMWARE_GATES`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct FirmwareVersion(pub u16);

impl FirmwareVersion {
    /// Default version of a simulated joint (passes every documented gate).
    pub const SIMULATOR_DEFAULT: Self = Self(0xD522);

    /// The high byte (major in the V1.0/EN reading).
    pub const fn major(self) -> u8 {
        self.0.to_be_bytes()[0]
    }

    /// The low byte (minor in the V1.0/EN reading).
    pub const fn minor(self) -> u8 {
        self.0.to_be_bytes()[1]
    }
}

impl fmt::Display for FirmwareVersion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:04X}", self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversions() {
        assert!((Position(10_000).degrees() - 1.0).abs() < 1e-12);
        assert_eq!(Position::from_degrees(30.0).unwrap(), Position(300_000));
        assert_eq!(Position::from_degrees(-0.00005).unwrap(), Position(-1));
        assert!(Position::from_degrees(1e9).is_err());
        assert!(Position::from_degrees(f64::NAN).is_err());
        assert_eq!(TargetSpeed::from_rpm(5.0).unwrap(), TargetSpeed(2500));
        assert!((ActualSpeed(2).rpm() - 0.04).abs() < 1e-12);
        assert_eq!(Current(-6).milliamps(CurrentScale::TwoMilliamps), -12);
        assert_eq!(
            Current::from_milliamps(500.0, Model::Joint60.current_scale()).unwrap(),
            Current(250)
        );
        assert_eq!(Voltage(2300).millivolts(), 23_000);
        assert!((Temperature(490).celsius() - 49.0).abs() < 1e-4);
    }

    #[test]
    fn models() {
        for code in 0..=0x10u16 {
            assert_eq!(Model::from_code(code).code(), code);
        }
        assert_eq!(Model::from_code(4), Model::Joint60);
        assert_eq!(Model::Joint60.current_scale(), CurrentScale::TwoMilliamps);
        assert_eq!(Model::Joint30.current_scale(), CurrentScale::OneMilliamp);
        // Peak speed = factory limit 3000 / ratio (C3), the published figures.
        for m in [
            Model::Joint03,
            Model::Joint10,
            Model::Joint30,
            Model::Joint60,
            Model::Joint120,
        ] {
            let (peak, ratio) = (
                m.peak_output_speed_rpm().unwrap(),
                m.reduction_ratio().unwrap(),
            );
            assert!((peak - 3000.0 / f64::from(ratio)).abs() < 1e-9, "{m}");
        }
        assert_eq!(Model::Joint10.peak_output_speed_rpm(), Some(37.5));
        assert_eq!(Model::Joint120.peak_output_speed_rpm(), Some(30.0));
        assert_eq!(Model::Gripper.peak_output_speed_rpm(), None);
        assert_eq!(std::format!("{}", FirmwareVersion(0xD522)), "D522");
    }
}
