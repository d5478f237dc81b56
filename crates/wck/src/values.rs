//! Range-checked values of the wCK protocol.
//!
//! Every ranged quantity the manual names has its own newtype here. Constructors
//! (`new`, `TryFrom`) refuse out-of-range input with an error that names the
//! quantity, the value and the allowed range, so nothing out of range can reach
//! the encoder. Ranges come from the manual's appendix A-1 (Communication
//! Protocol), A-6 (Protocol Table) and section 1-9 (Electrical & Control
//! Specifications); defaults from A-5 (Default Parameter Settings).

use core::fmt;

/// A value outside the range the protocol allows for that quantity.
///
/// ```
/// use robobus_wck::{Position, RangeError};
/// let err = Position::new(255).unwrap_err();
/// assert_eq!(err, RangeError { what: "position", value: 255, min: 0, max: 254 });
/// assert_eq!(err.to_string(), "position 255 is out of range 0..=254");
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, thiserror::Error)]
#[error("{what} {value} is out of range {min}..={max}")]
pub struct RangeError {
    /// Which quantity (for example `"position"`).
    pub what: &'static str,
    /// The rejected value.
    pub value: u32,
    /// Smallest allowed value.
    pub min: u32,
    /// Largest allowed value.
    pub max: u32,
}

/// A value the protocol cannot carry, for the quantities whose rules are more than a range.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, thiserror::Error)]
pub enum ValueError {
    /// A plain range violation.
    #[error(transparent)]
    Range(#[from] RangeError),
    /// A baud-rate code that is not one of the eight the manual lists (A-1 (7)).
    #[error("baud rate code {code} is not one of 0, 1, 3, 7, 15, 23, 95, 191")]
    BaudCode {
        /// The rejected code.
        code: u8,
    },
    /// A bit rate that no wCK baud code selects.
    #[error(
        "{bps} bit/s is not a wCK baud rate (4800, 9600, 38400, 57600, 115200, 230400, 460800, 921600)"
    )]
    BitRate {
        /// The rejected bit rate.
        bps: u32,
    },
    /// Movement boundaries with the lower bound above the upper one.
    #[error("boundaries are inverted: lower {lower} is above upper {upper}")]
    InvertedBoundaries {
        /// The lower bound given.
        lower: u8,
        /// The upper bound given.
        upper: u8,
    },
    /// A motion-program delay whose low byte would be `0xFF`, which is reserved for the
    /// packet header (motion data bytes are 0..=254, A-1 (24)).
    #[error("delay {ms} ms cannot be sent: its low byte would be 0xFF, the packet header")]
    DelayLowByteFf {
        /// The rejected delay in milliseconds.
        ms: u16,
    },
}

/// An angle outside what a position type can express.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("{what}: {degrees} degrees is out of range 0..={max_degrees:.3}")]
pub struct AngleError {
    /// Which position type (`"position"` or `"10-bit position"`).
    pub what: &'static str,
    /// The rejected angle.
    pub degrees: f64,
    /// The largest angle the type can express.
    pub max_degrees: f64,
}

macro_rules! ranged_u8 {
    ($(#[$meta:meta])* $name:ident, $what:literal, $min:literal, $max:literal) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
        pub struct $name(u8);

        impl $name {
            /// The smallest allowed value.
            pub const MIN: Self = Self($min);
            /// The largest allowed value.
            pub const MAX: Self = Self($max);

            /// Checks `raw` against the allowed range.
            pub const fn new(raw: u8) -> Result<Self, RangeError> {
                if matches!(raw, $min..=$max) {
                    Ok(Self(raw))
                } else {
                    Err(RangeError { what: $what, value: raw as u32, min: $min, max: $max })
                }
            }

            /// The raw value, as it goes on the wire.
            pub const fn get(self) -> u8 {
                self.0
            }
        }

        impl TryFrom<u8> for $name {
            type Error = RangeError;
            fn try_from(raw: u8) -> Result<Self, RangeError> {
                Self::new(raw)
            }
        }

        impl From<$name> for u8 {
            fn from(value: $name) -> u8 {
                value.0
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                fmt::Display::fmt(&self.0, f)
            }
        }
    };
}

ranged_u8!(
    /// The ID of a wCK module as 4- and 6-byte commands address it: 0..=30.
    ///
    /// ID 31 is the broadcast address (synchronized move and break, A-1 (2), (6)); it is
    /// not a `ServoId` but [`Target::Broadcast`](crate::Target::Broadcast).
    ServoId, "servo id", 0, 30
);
ranged_u8!(
    /// A module ID as the 10-bit commands address it, in a full data byte: 0..=253
    /// (section 1-3, "Max 254 modules per channel (ID 0~253)"; A-1 (26), (27)).
    ExtServoId, "extended servo id", 0, 253
);
ranged_u8!(
    /// A standard-resolution position, 0..=254 (A-1 (1)); one step is 269°/255 ≈ 1.055°
    /// (section 3-1).
    Position, "position", 0, 254
);
ranged_u8!(
    /// Torque level of a position move: 0 (maximum) ..= 4 (minimum) (A-1 (1)).
    TorqueLevel, "torque level", 0, 4
);
ranged_u8!(
    /// Position-mode speed level 0..=30; 0 means no speed limit (A-1 (15), A-5).
    Speed, "speed", 0, 30
);
ranged_u8!(
    /// Wheel-mode speed: 0 (stop), 1 (minimum) ..= 15 (maximum) (A-1 (5)).
    WheelSpeed, "wheel speed", 0, 15
);
ranged_u8!(
    /// Acceleration range 20..=100 (A-1 (15), section 3-4); default 60.
    Accel, "acceleration", 20, 100
);
ranged_u8!(
    /// Proportional gain, 1..=254 on the wire (A-6). Section 1-9 recommends 1..=120 and
    /// A-1 (8) suggests P = 1.5 × D. Default 20.
    PGain, "P gain", 1, 254
);
ranged_u8!(
    /// Derivative gain, 0..=254 (A-1 (8)). Default 30.
    DGain, "D gain", 0, 254
);
ranged_u8!(
    /// Integral gain, 0..=254 on the wire; section 1-9 and A-1 (10) recommend 0..=10
    /// (the manual's own example (10) sets 100). Default 0.
    IGain, "I gain", 0, 254
);
ranged_u8!(
    /// The load a module reports with its position, 0..=254 (A-1 (1) response); the manual
    /// gives no unit.
    Load, "load", 0, 254
);
ranged_u8!(
    /// A full command data byte, 0..=254 (`0xFF` is reserved for the header). Used where the
    /// manual allows any data byte: the torque of a 10-bit move (A-1 (26), "Torque(0~254)")
    /// and the threshold of an A/D condition in a motion program (section 3-11).
    DataByte, "data byte", 0, 254
);
ranged_u8!(
    /// The two digital outputs of the external I/O port: bit 0 = D/O 1, bit 1 = D/O 2
    /// (A-1 (22), section 3-10).
    IoBits, "digital outputs", 0, 3
);
ranged_u8!(
    /// Number of instructions in a self-running motion program, 0..=8 (A-1 (24), (25)).
    MotionCount, "motion instruction count", 0, 8
);
ranged_u8!(
    /// Over-load (over-current) threshold code 33..=199, i.e. 400..=1800 mA (A-1 (18),
    /// section 3-7). Default 33 (400 mA). See [`OVERLOAD_TABLE`] for the conversion.
    Overload, "over-load", 33, 199
);

ranged_u8!(
    /// How many times a self-running motion program repeats, 1..=254 (section 3-11; 0 on
    /// the wire means forever, see [`Repeat`](crate::program::Repeat)).
    RepeatCount, "repeat count", 1, 254
);

impl ServoId {
    /// The raw broadcast ID (31) used by synchronized move and break. Not a valid `ServoId`.
    pub const BROADCAST_RAW: u8 = 31;
}

impl From<ServoId> for ExtServoId {
    fn from(id: ServoId) -> Self {
        Self(id.0)
    }
}

impl Speed {
    /// Default speed (A-5): 0, no speed limit.
    pub const DEFAULT: Self = Self(0);
}

impl Accel {
    /// Default acceleration range (A-5): 60.
    pub const DEFAULT: Self = Self(60);
}

impl PGain {
    /// Default P gain (A-5): 20.
    pub const DEFAULT: Self = Self(20);
    /// Top of the recommended range (section 1-9): 120.
    pub const RECOMMENDED_MAX: Self = Self(120);
}

impl DGain {
    /// Default D gain (A-5): 30.
    pub const DEFAULT: Self = Self(30);
}

impl IGain {
    /// Default I gain (A-5): 0.
    pub const DEFAULT: Self = Self(0);
    /// Top of the recommended range (section 1-9): 10.
    pub const RECOMMENDED_MAX: Self = Self(10);

    /// Whether the gain is inside the manual's recommended 0..=10.
    pub const fn is_recommended(self) -> bool {
        self.0 <= Self::RECOMMENDED_MAX.0
    }
}

impl IoBits {
    /// Builds the output value from the two channels.
    pub const fn from_outputs(do1: bool, do2: bool) -> Self {
        Self((do1 as u8) | ((do2 as u8) << 1))
    }

    /// Takes the two output bits from a byte whose upper bits are "arbitrary" (A-1 (22)).
    pub const fn from_masked(byte: u8) -> Self {
        Self(byte & 0b11)
    }

    /// Digital output 1 (bit 0).
    pub const fn do1(self) -> bool {
        self.0 & 1 != 0
    }

    /// Digital output 2 (bit 1).
    pub const fn do2(self) -> bool {
        self.0 & 2 != 0
    }
}

/// The manual's over-load table (A-1 (18)): code → current in mA.
///
/// The codes are close to, but not exactly on, a straight line from (33, 400 mA) to
/// (199, 1800 mA): the straight line would give 45 for 500 mA and 127 for 1200 mA, where
/// the table says 44 and 128. [`Overload::milliamps`] and [`Overload::from_milliamps`]
/// therefore interpolate linearly between these points, so every row of the table converts
/// exactly both ways.
pub const OVERLOAD_TABLE: [(u8, u16); 10] = [
    (33, 400),
    (44, 500),
    (56, 600),
    (68, 700),
    (80, 800),
    (92, 900),
    (104, 1000),
    (116, 1100),
    (128, 1200),
    (199, 1800),
];

impl Overload {
    /// Default threshold (A-5): 33, i.e. 400 mA.
    pub const DEFAULT: Self = Self(33);
    /// Smallest threshold current in mA.
    pub const MIN_MILLIAMPS: u16 = 400;
    /// Largest threshold current in mA.
    pub const MAX_MILLIAMPS: u16 = 1800;

    /// The threshold current in mA, interpolated in [`OVERLOAD_TABLE`] and rounded to the
    /// nearest mA.
    pub const fn milliamps(self) -> u16 {
        let code = self.0;
        let mut i = 0;
        while i + 1 < OVERLOAD_TABLE.len() {
            let (c0, m0) = OVERLOAD_TABLE[i];
            let (c1, m1) = OVERLOAD_TABLE[i + 1];
            if code <= c1 {
                let dc = (c1 - c0) as u32;
                let num = (code - c0) as u32 * (m1 - m0) as u32;
                #[allow(clippy::cast_possible_truncation)] // at most 1800
                return m0 + ((2 * num + dc) / (2 * dc)) as u16;
            }
            i += 1;
        }
        Self::MAX_MILLIAMPS
    }

    /// The code whose threshold is nearest to `ma` (400..=1800 mA), interpolated in
    /// [`OVERLOAD_TABLE`].
    pub const fn from_milliamps(ma: u16) -> Result<Self, RangeError> {
        if ma < Self::MIN_MILLIAMPS || ma > Self::MAX_MILLIAMPS {
            return Err(RangeError {
                what: "over-load current (mA)",
                value: ma as u32,
                min: Self::MIN_MILLIAMPS as u32,
                max: Self::MAX_MILLIAMPS as u32,
            });
        }
        let mut i = 0;
        while i + 1 < OVERLOAD_TABLE.len() {
            let (c0, m0) = OVERLOAD_TABLE[i];
            let (c1, m1) = OVERLOAD_TABLE[i + 1];
            if ma <= m1 {
                let dm = (m1 - m0) as u32;
                let num = (ma - m0) as u32 * (c1 - c0) as u32;
                #[allow(clippy::cast_possible_truncation)] // at most 199
                return Ok(Self(c0 + ((2 * num + dm) / (2 * dm)) as u8));
            }
            i += 1;
        }
        Ok(Self::MAX)
    }
}

/// A 10-bit (high-resolution) position, 0..=1023 (A-1 (26), (27)); one step is
/// 333°/1023 ≈ 0.325° (section 3-1).
///
/// On the wire it is split into `H3` (bits 9..7, in the low 3 bits of a byte) and `L7`
/// (bits 6..0, shifted left by one): 1000 = `0x3E8` → `07 D0`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Position10(u16);

impl Position10 {
    /// The smallest position.
    pub const MIN: Self = Self(0);
    /// The largest position.
    pub const MAX: Self = Self(1023);
    /// Degrees per step: the manual's unit angle 333°/1023 (section 3-1).
    pub const DEGREES_PER_STEP: f64 = 333.0 / 1023.0;

    /// Checks `raw` against 0..=1023.
    pub const fn new(raw: u16) -> Result<Self, RangeError> {
        if raw <= 1023 {
            Ok(Self(raw))
        } else {
            Err(RangeError {
                what: "10-bit position",
                value: raw as u32,
                min: 0,
                max: 1023,
            })
        }
    }

    /// The raw value.
    pub const fn get(self) -> u16 {
        self.0
    }

    /// The wire form: `(H3, L7 << 1)`.
    pub const fn to_wire(self) -> (u8, u8) {
        #[allow(clippy::cast_possible_truncation)] // both masked to a byte
        let wire = (((self.0 >> 7) & 0x07) as u8, ((self.0 & 0x7F) << 1) as u8);
        wire
    }

    /// Rebuilds a position from its wire form. Bits outside `H3` and `L7` are "X" (don't
    /// care) in the manual and ignored here; see [`Position10::from_wire_checked`].
    pub const fn from_wire(h3: u8, l7: u8) -> Self {
        Self((((h3 & 0x07) as u16) << 7) | ((l7 >> 1) as u16))
    }

    /// Like [`Position10::from_wire`], but refuses an `H3` byte above 7 (which would mean
    /// a position above 1023).
    pub const fn from_wire_checked(h3: u8, l7: u8) -> Result<Self, RangeError> {
        if h3 > 7 {
            Err(RangeError {
                what: "10-bit position high bits",
                value: h3 as u32,
                min: 0,
                max: 7,
            })
        } else {
            Ok(Self::from_wire(h3, l7))
        }
    }

    /// The angle in degrees.
    pub fn degrees(self) -> f64 {
        f64::from(self.0) * Self::DEGREES_PER_STEP
    }

    /// The nearest position to `degrees` (0..=333°).
    pub fn from_degrees(degrees: f64) -> Result<Self, AngleError> {
        let max_degrees = 1023.0 * Self::DEGREES_PER_STEP;
        let steps = steps_for(degrees, Self::DEGREES_PER_STEP, 1023.0).ok_or(AngleError {
            what: "10-bit position",
            degrees,
            max_degrees,
        })?;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // 0..=1023 checked
        let steps = steps as u16;
        Ok(Self(steps))
    }
}

impl TryFrom<u16> for Position10 {
    type Error = RangeError;
    fn try_from(raw: u16) -> Result<Self, RangeError> {
        Self::new(raw)
    }
}

impl fmt::Display for Position10 {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(&self.0, f)
    }
}

/// Rounds `degrees / step` to the nearest step, `None` outside `0..=max_steps` (half a
/// step of slack at either end) or for NaN.
fn steps_for(degrees: f64, step: f64, max_steps: f64) -> Option<f64> {
    let steps = degrees / step + 0.5;
    if steps.is_nan() || steps < 0.0 || steps >= max_steps + 1.0 {
        return None;
    }
    Some(steps)
}

impl Position {
    /// Degrees per step: the manual's unit angle 269°/255 ≈ 1.055° (section 3-1).
    pub const DEGREES_PER_STEP: f64 = 269.0 / 255.0;

    /// The angle in degrees (position 254 is about 267.9°).
    pub fn degrees(self) -> f64 {
        f64::from(self.0) * Self::DEGREES_PER_STEP
    }

    /// The nearest position to `degrees` (0..=about 268°).
    pub fn from_degrees(degrees: f64) -> Result<Self, AngleError> {
        let max_degrees = 254.0 * Self::DEGREES_PER_STEP;
        let steps = steps_for(degrees, Self::DEGREES_PER_STEP, 254.0).ok_or(AngleError {
            what: "position",
            degrees,
            max_degrees,
        })?;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // 0..=254 checked
        let steps = steps as u8;
        Ok(Self(steps))
    }
}

/// Movement boundaries: the module only moves within `lower..=upper` (A-1 (20), section
/// 3-5). Default 1..=254 (A-5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Boundaries {
    lower: Position,
    upper: Position,
}

impl Boundaries {
    /// Default boundaries (A-5): 1..=254.
    pub const DEFAULT: Self = Self {
        lower: Position(1),
        upper: Position(254),
    };

    /// Checks `lower <= upper`.
    ///
    /// The manual's own example (20) sets lower 100, upper 50; robobus refuses that.
    pub const fn new(lower: Position, upper: Position) -> Result<Self, ValueError> {
        if lower.0 <= upper.0 {
            Ok(Self { lower, upper })
        } else {
            Err(ValueError::InvertedBoundaries {
                lower: lower.0,
                upper: upper.0,
            })
        }
    }

    /// Checks raw bytes: both positions (0..=254) and their order.
    pub const fn from_raw(lower: u8, upper: u8) -> Result<Self, ValueError> {
        let lower = match Position::new(lower) {
            Ok(p) => p,
            Err(e) => return Err(ValueError::Range(e)),
        };
        let upper = match Position::new(upper) {
            Ok(p) => p,
            Err(e) => return Err(ValueError::Range(e)),
        };
        Self::new(lower, upper)
    }

    /// The lower bound.
    pub const fn lower(self) -> Position {
        self.lower
    }

    /// The upper bound.
    pub const fn upper(self) -> Position {
        self.upper
    }

    /// `position` limited to the boundaries.
    pub fn clamp(self, position: Position) -> Position {
        position.clamp(self.lower, self.upper)
    }
}

impl fmt::Display for Boundaries {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}..={}", self.lower, self.upper)
    }
}

/// The eight baud rates a wCK module supports (A-1 (7)).
///
/// Each code is `921600 / baud − 1`, the UBRR divisor of an AVR clocked at 14.7456 MHz.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum BaudRate {
    /// 4800 bit/s, code 191.
    B4800,
    /// 9600 bit/s, code 95.
    B9600,
    /// 38400 bit/s, code 23.
    B38400,
    /// 57600 bit/s, code 15.
    B57600,
    /// 115200 bit/s, code 7 (the default, A-5).
    B115200,
    /// 230400 bit/s, code 3.
    B230400,
    /// 460800 bit/s, code 1.
    B460800,
    /// 921600 bit/s, code 0.
    B921600,
}

impl BaudRate {
    /// All eight rates, slowest first.
    pub const ALL: [Self; 8] = [
        Self::B4800,
        Self::B9600,
        Self::B38400,
        Self::B57600,
        Self::B115200,
        Self::B230400,
        Self::B460800,
        Self::B921600,
    ];
    /// The default (A-5): 115200 bit/s.
    pub const DEFAULT: Self = Self::B115200;

    /// Bits per second.
    pub const fn bits_per_second(self) -> u32 {
        match self {
            Self::B4800 => 4800,
            Self::B9600 => 9600,
            Self::B38400 => 38_400,
            Self::B57600 => 57_600,
            Self::B115200 => 115_200,
            Self::B230400 => 230_400,
            Self::B460800 => 460_800,
            Self::B921600 => 921_600,
        }
    }

    /// The wire code.
    pub const fn code(self) -> u8 {
        #[allow(clippy::cast_possible_truncation)] // at most 191
        let code = ((921_600 / self.bits_per_second()) - 1) as u8;
        code
    }

    /// The rate for a wire code.
    pub const fn from_code(code: u8) -> Result<Self, ValueError> {
        match code {
            191 => Ok(Self::B4800),
            95 => Ok(Self::B9600),
            23 => Ok(Self::B38400),
            15 => Ok(Self::B57600),
            7 => Ok(Self::B115200),
            3 => Ok(Self::B230400),
            1 => Ok(Self::B460800),
            0 => Ok(Self::B921600),
            _ => Err(ValueError::BaudCode { code }),
        }
    }

    /// The rate for a bit rate in bit/s.
    pub const fn from_bits_per_second(bps: u32) -> Result<Self, ValueError> {
        match bps {
            4800 => Ok(Self::B4800),
            9600 => Ok(Self::B9600),
            38_400 => Ok(Self::B38400),
            57_600 => Ok(Self::B57600),
            115_200 => Ok(Self::B115200),
            230_400 => Ok(Self::B230400),
            460_800 => Ok(Self::B460800),
            921_600 => Ok(Self::B921600),
            _ => Err(ValueError::BitRate { bps }),
        }
    }
}

impl fmt::Display for BaudRate {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} bit/s", self.bits_per_second())
    }
}

/// Wheel-mode rotation direction (A-1 (5)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Rotation {
    /// Counter-clockwise (mode nibble 3).
    Ccw,
    /// Clockwise (mode nibble 4).
    Cw,
}

impl Rotation {
    /// The mode nibble in the top of data byte 2.
    pub const fn nibble(self) -> u8 {
        match self {
            Self::Ccw => 3,
            Self::Cw => 4,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overload_table_rows_convert_exactly_both_ways() {
        for (code, ma) in OVERLOAD_TABLE {
            let o = Overload::new(code).unwrap();
            assert_eq!(o.milliamps(), ma, "code {code}");
            assert_eq!(Overload::from_milliamps(ma).unwrap(), o, "{ma} mA");
        }
    }

    #[test]
    fn overload_codes_round_trip_through_milliamps_and_are_monotonic() {
        let mut last = 0;
        for code in 33..=199 {
            let o = Overload::new(code).unwrap();
            let ma = o.milliamps();
            assert!(ma > last, "code {code}: {ma} mA not above {last}");
            last = ma;
            assert_eq!(Overload::from_milliamps(ma).unwrap(), o);
        }
        assert_eq!(
            Overload::from_milliamps(1801).unwrap_err(),
            RangeError {
                what: "over-load current (mA)",
                value: 1801,
                min: 400,
                max: 1800
            }
        );
        assert!(Overload::from_milliamps(399).is_err());
    }

    #[test]
    fn baud_codes_match_the_manual() {
        let codes: [u8; 8] = [191, 95, 23, 15, 7, 3, 1, 0];
        for (rate, code) in BaudRate::ALL.into_iter().zip(codes) {
            assert_eq!(rate.code(), code);
            assert_eq!(BaudRate::from_code(code).unwrap(), rate);
            assert_eq!(
                BaudRate::from_bits_per_second(rate.bits_per_second()).unwrap(),
                rate
            );
        }
        for code in 0..=255u8 {
            if !codes.contains(&code) {
                assert_eq!(
                    BaudRate::from_code(code),
                    Err(ValueError::BaudCode { code })
                );
            }
        }
        assert_eq!(
            BaudRate::from_bits_per_second(19_200),
            Err(ValueError::BitRate { bps: 19_200 })
        );
    }

    #[test]
    fn ten_bit_split_matches_the_manual_example() {
        let p = Position10::new(1000).unwrap();
        assert_eq!(p.to_wire(), (0x07, 0xD0));
        for raw in 0..=1023 {
            let p = Position10::new(raw).unwrap();
            let (h, l) = p.to_wire();
            assert_eq!(Position10::from_wire_checked(h, l).unwrap(), p);
        }
        assert!(Position10::from_wire_checked(8, 0).is_err());
        assert!(Position10::new(1024).is_err());
    }

    #[test]
    fn degrees_follow_the_manual_unit_angles() {
        let p = Position::new(255 / 2).unwrap();
        assert!((p.degrees() - 127.0 * 1.054_902).abs() < 1e-3);
        assert!((Position::MAX.degrees() - 267.945).abs() < 1e-3);
        assert!((Position10::MAX.degrees() - 333.0).abs() < 1e-9);
        assert_eq!(Position::from_degrees(0.0).unwrap(), Position::MIN);
        assert_eq!(Position::from_degrees(268.0).unwrap(), Position::MAX);
        assert_eq!(Position10::from_degrees(333.0).unwrap(), Position10::MAX);
        assert_eq!(Position10::from_degrees(0.325_513_2).unwrap().get(), 1);
        for raw in 0..=254 {
            let p = Position::new(raw).unwrap();
            assert_eq!(Position::from_degrees(p.degrees()).unwrap(), p);
        }
        for raw in 0..=1023 {
            let p = Position10::new(raw).unwrap();
            assert_eq!(Position10::from_degrees(p.degrees()).unwrap(), p);
        }
        let err = Position::from_degrees(270.0).unwrap_err();
        assert_eq!(err.what, "position");
        assert!(Position::from_degrees(-1.0).is_err());
        assert!(Position::from_degrees(f64::NAN).is_err());
        assert!(Position10::from_degrees(334.0).is_err());
    }

    #[test]
    fn boundaries_refuse_inverted_ranges() {
        let lo = Position::new(100).unwrap();
        let hi = Position::new(50).unwrap();
        assert_eq!(
            Boundaries::new(lo, hi),
            Err(ValueError::InvertedBoundaries {
                lower: 100,
                upper: 50
            })
        );
        let b = Boundaries::new(hi, lo).unwrap();
        assert_eq!(b.clamp(Position::new(200).unwrap()), lo);
        assert_eq!(b.clamp(Position::new(3).unwrap()), hi);
        assert!(Boundaries::from_raw(0, 255).is_err());
    }

    #[test]
    fn range_errors_name_value_and_range() {
        assert_eq!(
            ServoId::new(31).unwrap_err().to_string(),
            "servo id 31 is out of range 0..=30"
        );
        assert_eq!(
            Accel::new(19).unwrap_err(),
            RangeError {
                what: "acceleration",
                value: 19,
                min: 20,
                max: 100
            }
        );
        assert!(PGain::new(0).is_err());
        assert!(ExtServoId::new(254).is_err());
        assert_eq!(IoBits::from_outputs(true, false).get(), 1);
        assert_eq!(IoBits::from_outputs(false, true).get(), 2);
        assert!(IoBits::new(3).unwrap().do2());
    }
}
