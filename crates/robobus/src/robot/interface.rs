//! A joint's command interfaces: position (every joint), velocity (a WHJ joint's speed
//! mode, a wCK servo's wheel mode) and effort (a WHJ joint's current mode, through the
//! torque constant of the model it identified as), and how a velocity or an effort
//! becomes what the device is sent.

use std::fmt;

use serde::de::{self, SeqAccess, Visitor};
use serde::{Deserialize, Deserializer, Serialize};

use robobus_wck::{Rotation, WheelSpeed};
use robobus_whj::models::PRODUCTS;
use robobus_whj::units::Model;

/// What a joint is commanded in ([`Robot::set_interface`](super::Robot::set_interface)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Interface {
    /// Angles, rad (every joint; WHJ position mode, wCK position moves).
    Position,
    /// Speeds, rad/s (WHJ speed mode, wCK wheel mode).
    Velocity,
    /// Torques, N·m (WHJ current mode, through the model's torque constant).
    Effort,
}

impl Interface {
    /// Every interface, in the file's order.
    pub const ALL: [Self; 3] = [Self::Position, Self::Velocity, Self::Effort];

    /// The keyword of the robot file and the reports (`"position"`, ...).
    pub const fn keyword(self) -> &'static str {
        match self {
            Self::Position => "position",
            Self::Velocity => "velocity",
            Self::Effort => "effort",
        }
    }

    /// The unit of its values (`"rad"`, `"rad/s"`, `"N·m"`).
    pub const fn unit(self) -> &'static str {
        match self {
            Self::Position => "rad",
            Self::Velocity => "rad/s",
            Self::Effort => "N·m",
        }
    }
}

impl fmt::Display for Interface {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.keyword())
    }
}

/// The interfaces as a list for a message (`position, velocity`).
pub(crate) fn list(interfaces: &[Interface]) -> String {
    interfaces
        .iter()
        .map(|i| i.keyword())
        .collect::<Vec<_>>()
        .join(", ")
}

/// The wCK wheel levels.
pub const WHEEL_LEVELS: usize = 15;

/// What a wCK servo's wheel speeds 1..=15 turn its shaft at, rad/s (the robot file's
/// `wheel_speeds`).
///
/// The manual gives the wheel speed no unit: it is a drive level (the simulator, like the
/// module, drives the motor at duty `speed / 15`). Unloaded, level 15 turns at about the
/// model's no-load speed (wCK-1108: 400 °/s, 6.98 rad/s; wCK-1111: 286 °/s; wCK-1413:
/// 316 °/s) and level `k` at about `k / 15` of it, less the gear friction (most felt at the
/// low levels) and any load. The file gives either that top speed (one number: level `k`
/// is taken as `k / 15` of it) or the 15 speeds measured on the robot (a list, increasing).
#[derive(Debug, Clone, PartialEq)]
pub struct WheelSpeeds([f64; WHEEL_LEVELS]);

impl WheelSpeeds {
    /// Levels `k / 15 × top`.
    pub fn linear(top_rad_s: f64) -> Self {
        let mut s = [0.0; WHEEL_LEVELS];
        for (k, v) in s.iter_mut().enumerate() {
            #[allow(clippy::cast_precision_loss)] // k < 15
            let level = (k + 1) as f64;
            *v = top_rad_s * level / 15.0;
        }
        Self(s)
    }

    /// The measured speeds of levels 1..=15, rad/s.
    pub const fn measured(speeds: [f64; WHEEL_LEVELS]) -> Self {
        Self(speeds)
    }

    /// The speeds of levels 1..=15, rad/s.
    pub const fn speeds(&self) -> &[f64; WHEEL_LEVELS] {
        &self.0
    }

    /// The fastest, rad/s (level 15).
    pub fn top(&self) -> f64 {
        self.0[WHEEL_LEVELS - 1]
    }

    /// `None` if the speeds are valid (finite, > 0, strictly increasing, at most
    /// `most` rad/s), else what is wrong.
    pub(crate) fn fault(&self, most: f64) -> Option<String> {
        let mut prev = 0.0;
        for (k, &v) in self.0.iter().enumerate() {
            if !(v.is_finite() && v > prev && v <= most) {
                return Some(format!(
                    "level {} is {v} rad/s: the speeds must be finite, > 0, increasing and \
                     <= {most} rad/s",
                    k + 1
                ));
            }
            prev = v;
        }
        None
    }

    /// The wheel command nearest `rad_s` (joint frame; level 0 past the top level) of a
    /// servo turning the joint's way, or the other way when `reversed`: the device's
    /// direction and level, and the joint speed it turns at (rad/s).
    pub(crate) fn command(&self, rad_s: f64, reversed: bool) -> (Rotation, WheelSpeed, f64) {
        let (level, speed) = self.level(rad_s).unwrap_or((0, 0.0));
        let (rotation, level) = wheel_command(level, if reversed { -speed } else { speed });
        (rotation, level.unwrap_or(WheelSpeed::MIN), speed)
    }

    /// The level nearest to `|rad_s|` (0: stop) and its signed speed, or `None` when
    /// `|rad_s|` is nearer to a level past 15 than to 15 (faster than the servo turns).
    pub(crate) fn level(&self, rad_s: f64) -> Option<(u8, f64)> {
        let want = rad_s.abs();
        let top = self.top();
        let last_gap = top - self.0[WHEEL_LEVELS - 2];
        if want > top + last_gap / 2.0 {
            return None;
        }
        let mut best = (0_u8, 0.0_f64);
        for (k, &v) in self.0.iter().enumerate() {
            if (v - want).abs() < (best.1 - want).abs() {
                #[allow(clippy::cast_possible_truncation)] // k < 15
                let level = (k + 1) as u8;
                best = (level, v);
            }
        }
        Some((best.0, best.1.copysign(rad_s)))
    }
}

/// A wheel command: the device's direction and level for a joint speed of the sign
/// `device_sign` (the joint's direction).
pub(crate) fn wheel_command(level: u8, device_rad_s: f64) -> (Rotation, Option<WheelSpeed>) {
    // Counter-clockwise turns the position up (device angle increasing).
    let rotation = if device_rad_s < 0.0 {
        Rotation::Cw
    } else {
        Rotation::Ccw
    };
    (rotation, WheelSpeed::new(level).ok())
}

impl<'de> Deserialize<'de> for WheelSpeeds {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Speeds;
        impl<'de> Visitor<'de> for Speeds {
            type Value = WheelSpeeds;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(
                    "the speed of wheel level 15 in rad/s, or a list of the 15 speeds of \
                     levels 1..=15 in rad/s",
                )
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<Self::Value, E> {
                Ok(WheelSpeeds::linear(v))
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<Self::Value, E> {
                #[allow(clippy::cast_precision_loss)] // a file's small integer
                Ok(WheelSpeeds::linear(v as f64))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Self::Value, E> {
                #[allow(clippy::cast_precision_loss)] // a file's small integer
                Ok(WheelSpeeds::linear(v as f64))
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
                let mut s = [0.0; WHEEL_LEVELS];
                let mut n = 0;
                while let Some(v) = seq.next_element::<f64>()? {
                    if let Some(slot) = s.get_mut(n) {
                        *slot = v;
                    }
                    n += 1;
                }
                if n != WHEEL_LEVELS {
                    return Err(de::Error::invalid_length(n, &self));
                }
                Ok(WheelSpeeds(s))
            }
        }
        d.deserialize_any(Speeds)
    }
}

/// The effort facts of a WHJ joint's model: its output torque constant (N·m per A of
/// motor current, rated torque over rated current, as the samples' `effort_nm` and the
/// simulator use) and its peak torque.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EffortScale {
    /// N·m per A at the output.
    pub nm_per_a: f64,
    /// The product's peak output torque, N·m.
    pub peak_nm: f64,
}

impl EffortScale {
    /// The facts of a joint that identified as `model` with `reduction_ratio`; `None` when
    /// no product matches or the products that match differ.
    pub fn of(model: Model, reduction_ratio: u16) -> Option<Self> {
        let mut matching = PRODUCTS
            .iter()
            .filter(|p| p.model == model && p.reduction_ratio == reduction_ratio)
            .map(|p| Self {
                nm_per_a: p.torque_constant_nm_per_a(),
                peak_nm: p.peak_torque_nm,
            });
        let first = matching.next()?;
        matching
            .all(|o| {
                (o.nm_per_a - first.nm_per_a).abs() < 1e-9
                    && (o.peak_nm - first.peak_nm).abs() < 1e-9
            })
            .then_some(first)
    }
}

#[cfg(test)]
#[allow(clippy::float_cmp)] // exact table values
mod tests {
    use super::*;

    #[test]
    fn a_speed_goes_to_the_nearest_wheel_level_and_past_the_top_is_refused() {
        let s = WheelSpeeds::linear(7.5); // 0.5 rad/s a level
        assert_eq!(s.level(0.0), Some((0, 0.0)));
        assert_eq!(s.level(0.24), Some((0, 0.0)));
        assert_eq!(s.level(0.26), Some((1, 0.5)));
        assert_eq!(s.level(-2.1), Some((4, -2.0)));
        assert_eq!(s.level(7.74), Some((15, 7.5)));
        assert_eq!(s.level(7.76), None);
        assert_eq!(s.level(-7.76), None);
    }

    #[test]
    fn the_whj30s_effort_scale_is_its_rated_torque_over_rated_current() {
        let e = EffortScale::of(Model::Joint30, 80).unwrap();
        assert_eq!(e.nm_per_a, 30.0 / 7.8);
        assert_eq!(e.peak_nm, 90.0);
        assert_eq!(EffortScale::of(Model::Joint30, 81), None);
    }
}
