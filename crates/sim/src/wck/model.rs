//! The wCK models the simulator knows, with the figures of the manual's specification
//! tables (section 1-9, "Electrical & Control Specifications").

use std::fmt;
use std::str::FromStr;

/// A wCK model. The figures are the manual's, at the recommended supply voltage
/// (7.4..8.4 V): maximum no-load speed and maximum stall torque (section 1-9), gear ratio
/// (section 1-8).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Model {
    /// wCK-1108: 0.15 s / 60°, 8 kg·cm, gear 1/173.
    #[default]
    W1108,
    /// wCK-1111: 0.21 s / 60°, 11 kg·cm, gear 1/241.
    W1111,
    /// wCK-1413: 0.19 s / 60°, 13 kg·cm, gear 1/241.
    W1413,
}

impl Model {
    /// Every model.
    pub const ALL: [Self; 3] = [Self::W1108, Self::W1111, Self::W1413];

    /// The model number as printed on the module (1108, 1111, 1413).
    pub const fn number(self) -> u16 {
        match self {
            Self::W1108 => 1108,
            Self::W1111 => 1111,
            Self::W1413 => 1413,
        }
    }

    /// The model for a number (1108, 1111, 1413).
    pub const fn from_number(number: u16) -> Option<Self> {
        match number {
            1108 => Some(Self::W1108),
            1111 => Some(Self::W1111),
            1413 => Some(Self::W1413),
            _ => None,
        }
    }

    /// Maximum no-load speed as the manual gives it: seconds per 60° (section 1-9).
    pub const fn seconds_per_60deg(self) -> f64 {
        match self {
            Self::W1108 => 0.15,
            Self::W1111 => 0.21,
            Self::W1413 => 0.19,
        }
    }

    /// Maximum no-load speed in degrees per second.
    pub fn no_load_speed_dps(self) -> f64 {
        60.0 / self.seconds_per_60deg()
    }

    /// Maximum stall torque in kg·cm (section 1-9).
    pub const fn stall_torque_kgcm(self) -> f64 {
        match self {
            Self::W1108 => 8.0,
            Self::W1111 => 11.0,
            Self::W1413 => 13.0,
        }
    }

    /// Gear ratio denominator (section 1-8): 173 or 241.
    pub const fn gear_ratio(self) -> u16 {
        match self {
            Self::W1108 => 173,
            Self::W1111 | Self::W1413 => 241,
        }
    }

    /// Supply current at stall with full drive, in mA.
    ///
    /// The manual gives no stall current, only the over-current protection range
    /// 400..=1800 mA (section 1-9). The simulator assumes a stall current a little above
    /// that range, so every threshold can trip and the highest one just does; it grows
    /// with the stall torque.
    pub const fn stall_current_ma(self) -> f64 {
        match self {
            Self::W1108 => 2000.0,
            Self::W1111 => 2200.0,
            Self::W1413 => 2400.0,
        }
    }

    /// Predicted time for a move of `degrees` at full speed with no load, from the manual's
    /// speed figure alone (no acceleration or settling).
    pub fn no_load_move_seconds(self, degrees: f64) -> f64 {
        degrees.abs() / 60.0 * self.seconds_per_60deg()
    }
}

impl fmt::Display for Model {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "wCK-{}", self.number())
    }
}

/// A model name that is not one of 1108, 1111, 1413.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown wCK model {given:?}: expected one of 1108, 1111, 1413")]
pub struct UnknownModel {
    /// What was given.
    pub given: String,
}

impl FromStr for Model {
    type Err = UnknownModel;

    /// Accepts `1108`, `wCK-1108`, `wck1108` (any case), and likewise for 1111 and 1413.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let t = s.trim().to_ascii_lowercase();
        let digits = t.trim_start_matches("wck").trim_start_matches('-');
        digits
            .parse::<u16>()
            .ok()
            .and_then(Self::from_number)
            .ok_or_else(|| UnknownModel {
                given: s.to_owned(),
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn figures_from_the_manual() {
        assert!((Model::W1108.no_load_speed_dps() - 400.0).abs() < 1e-9);
        assert!((Model::W1413.stall_torque_kgcm() - 13.0).abs() < 1e-12);
        assert_eq!(Model::W1111.gear_ratio(), 241);
        assert!((Model::W1111.no_load_move_seconds(120.0) - 0.42).abs() < 1e-12);
    }

    #[test]
    fn parses_names() {
        assert_eq!("1108".parse::<Model>(), Ok(Model::W1108));
        assert_eq!("wCK-1413".parse::<Model>(), Ok(Model::W1413));
        assert_eq!("WCK1111".parse::<Model>(), Ok(Model::W1111));
        let err = "1208".parse::<Model>().unwrap_err();
        assert!(err.to_string().contains("1208"));
        for m in Model::ALL {
            assert_eq!(m.number().to_string().parse::<Model>(), Ok(m));
        }
    }
}
