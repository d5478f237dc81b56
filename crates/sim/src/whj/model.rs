//! Product parameters of the simulated WHJ models (§9 of the WHJ joint protocol reference).
//!
//! The published facts (code, ratio, peak speed, current scale, brake, features, torque,
//! power, inertia, mass) come from the one product table, [`robobus_whj::PRODUCTS`].
//!
//! The published data gives ratio, rated / peak torque, peak output speed, rated power and
//! current, weight and rotor inertia. Everything else a physics model needs (torque
//! constant, winding resistance, thermal time constant, friction) is not published; the
//! values here are inferences, documented on each field, and every one can be overridden
//! through [`ModelParams`].

use core::fmt;
use core::str::FromStr;

use robobus_whj::models::{PRODUCTS, ProductFacts};
use robobus_whj::registers::Feature;
use robobus_whj::units::{CurrentScale, Model};

/// One of the simulated WHJ joint products.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum WhjModel {
    /// WHJ03-M-D33-100-N (model code 0x07).
    Whj03,
    /// WHJ10-M-D50-80-B, with pin brake (model code 0x02).
    Whj10B,
    /// WHJ10-M-D50-80-N, no brake (model code 0x02).
    Whj10N,
    /// WHJ30-S-D60-80-B (model code 0x03).
    Whj30,
    /// WHJ60-S-D70-100-B (model code 0x04, 2 mA current LSB).
    Whj60,
    /// WHJ120-M-D88-100-B (model code 0x05, 2 mA current LSB).
    Whj120,
}

impl WhjModel {
    /// Every simulated model.
    pub const ALL: [Self; 6] = [
        Self::Whj03,
        Self::Whj10B,
        Self::Whj10N,
        Self::Whj30,
        Self::Whj60,
        Self::Whj120,
    ];

    /// This product's row of [`robobus_whj::PRODUCTS`].
    pub fn facts(self) -> &'static ProductFacts {
        let i = match self {
            Self::Whj03 => 0,
            Self::Whj10B => 1,
            Self::Whj10N => 2,
            Self::Whj30 => 3,
            Self::Whj60 => 4,
            Self::Whj120 => 5,
        };
        &PRODUCTS[i]
    }

    /// The protocol-level model (register 0x02).
    pub fn model(self) -> Model {
        self.facts().model
    }

    /// Short name as accepted on the command line (`whj30`, `whj10n`, ...).
    pub const fn name(self) -> &'static str {
        match self {
            Self::Whj03 => "whj03",
            Self::Whj10B => "whj10b",
            Self::Whj10N => "whj10n",
            Self::Whj30 => "whj30",
            Self::Whj60 => "whj60",
            Self::Whj120 => "whj120",
        }
    }

    /// Whether the product has a pin brake (the `B` suffix; C25: `N` models report 0).
    pub fn has_brake(self) -> bool {
        self.facts().pin_brake
    }

    /// Whether the low-power mode (0x69) exists on this model (WHJ10N/30/60, §6.8).
    pub fn supports_low_power(self) -> bool {
        self.facts().has(Feature::LowPowerMode)
    }

    /// Whether the direct brake release (0x6A) exists on this model (WHJ30/60, §6.8).
    pub fn supports_brake_release(self) -> bool {
        self.facts().has(Feature::BrakeRelease)
    }

    /// The product parameters of this model.
    pub fn params(self) -> ModelParams {
        let f = self.facts();
        let (rated, rpm, watts, amps) = (
            f.rated_torque_nm,
            f.peak_output_speed_rpm,
            f.rated_power_w,
            f.rated_current_a,
        );
        ModelParams {
            model: self,
            reduction_ratio: f.reduction_ratio,
            rated_torque_nm: rated,
            peak_torque_nm: f.peak_torque_nm,
            peak_speed_rpm: rpm,
            rated_power_w: watts,
            rated_current_a: amps,
            rotor_inertia_kgm2: f.rotor_inertia_kgm2,
            mass_kg: f.mass_kg,
            current_scale: f.current_scale,
            // [inf] Copper loss at rated current = 10 % of the rated power.
            winding_resistance_ohm: 0.10 * watts / (amps * amps),
            // [inf] Rated current held forever warms the joint by 40 K.
            thermal_resistance_k_per_w: 40.0 / (0.10 * watts),
            // [inf] Five minutes to 63 % of the final temperature.
            thermal_time_constant_s: 300.0,
            // [inf] 2 % of rated torque at peak speed (viscous) plus 1 % (Coulomb).
            viscous_friction_nms: 0.02 * rated / rpm_to_rad_s(rpm),
            coulomb_friction_nm: 0.01 * rated,
        }
    }
}

impl fmt::Display for WhjModel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A model name that is not one of the simulated products.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown WHJ model {given:?} (allowed: whj03, whj10 = whj10b, whj10n, whj30, whj60, whj120)"
)]
pub struct UnknownModel {
    /// What was given.
    pub given: String,
}

impl FromStr for WhjModel {
    type Err = UnknownModel;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let lower = s.trim().to_ascii_lowercase();
        let name = lower.strip_prefix("whj").unwrap_or(&lower);
        match name {
            "03" | "3" => Ok(Self::Whj03),
            "10" | "10b" => Ok(Self::Whj10B),
            "10n" => Ok(Self::Whj10N),
            "30" => Ok(Self::Whj30),
            "60" => Ok(Self::Whj60),
            "120" => Ok(Self::Whj120),
            _ => Err(UnknownModel {
                given: s.to_owned(),
            }),
        }
    }
}

/// RPM to rad/s.
pub(crate) fn rpm_to_rad_s(rpm: f64) -> f64 {
    rpm * core::f64::consts::TAU / 60.0
}

/// Physical parameters of one joint product (all at the output side unless stated).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelParams {
    /// Which product.
    pub model: WhjModel,
    /// Gear reduction ratio (register 0x07).
    pub reduction_ratio: u16,
    /// Rated output torque, N·m.
    pub rated_torque_nm: f64,
    /// Peak output torque, N·m (3 × rated on every model).
    pub peak_torque_nm: f64,
    /// Peak output speed, RPM.
    pub peak_speed_rpm: f64,
    /// Rated power, W.
    pub rated_power_w: f64,
    /// Rated current, A. The product pages list rated power ÷ 24 V, a supply-side value;
    /// the simulator uses it as the motor current at rated torque \[inf\], so the output
    /// torque constant is `rated_torque / rated_current`.
    pub rated_current_a: f64,
    /// Rotor inertia, kg·m² (EN product page; C26). Reflected to the output by ratio².
    pub rotor_inertia_kgm2: f64,
    /// Joint mass, kg.
    pub mass_kg: f64,
    /// Current LSB on the wire (C2).
    pub current_scale: CurrentScale,
    /// Phase winding resistance, Ω \[inf\].
    pub winding_resistance_ohm: f64,
    /// Thermal resistance housing → ambient, K/W \[inf\].
    pub thermal_resistance_k_per_w: f64,
    /// Thermal time constant, s \[inf\].
    pub thermal_time_constant_s: f64,
    /// Viscous friction at the output, N·m·s/rad \[inf\].
    pub viscous_friction_nms: f64,
    /// Coulomb friction at the output, N·m \[inf\].
    pub coulomb_friction_nm: f64,
}

impl ModelParams {
    /// Output torque per ampere of motor current, N·m/A \[inf\].
    pub fn torque_constant(&self) -> f64 {
        self.rated_torque_nm / self.rated_current_a
    }

    /// Peak motor current, A (the current that gives peak torque).
    pub fn peak_current_a(&self) -> f64 {
        self.peak_torque_nm / self.torque_constant()
    }

    /// Rotor inertia reflected to the output, kg·m².
    pub fn output_inertia_kgm2(&self) -> f64 {
        let n = f64::from(self.reduction_ratio);
        self.rotor_inertia_kgm2 * n * n
    }

    /// Peak output speed, rad/s.
    pub fn peak_speed_rad_s(&self) -> f64 {
        rpm_to_rad_s(self.peak_speed_rpm)
    }

    /// Milliamps per current count on the wire.
    pub fn ma_per_count(&self) -> f64 {
        f64::from(self.current_scale.ma_per_count())
    }
}

#[cfg(test)]
#[allow(clippy::float_cmp)] // exact values are asserted on purpose
mod tests {
    use super::*;

    #[test]
    fn names_parse_back() {
        for m in WhjModel::ALL {
            assert_eq!(m.name().parse::<WhjModel>(), Ok(m));
            // The row of the product table is this product's.
            assert!(m.facts().name.eq_ignore_ascii_case(m.name()), "{m}");
        }
        assert_eq!("WHJ10".parse::<WhjModel>(), Ok(WhjModel::Whj10B));
        let err = "whj7".parse::<WhjModel>().unwrap_err();
        assert!(err.to_string().contains("whj7") && err.to_string().contains("whj120"));
    }

    #[test]
    fn params_follow_the_product_pages() {
        let p = WhjModel::Whj30.params();
        assert_eq!(p.reduction_ratio, 80);
        assert!((p.peak_current_a() - 23.4).abs() < 1e-9);
        assert!((p.output_inertia_kgm2() - 2.98e-5 * 6400.0).abs() < 1e-12);
        assert_eq!(WhjModel::Whj60.params().ma_per_count(), 2.0);
        assert_eq!(WhjModel::Whj10N.params().ma_per_count(), 1.0);
        // Peak speed = 3000 / ratio RPM (C3) on every model.
        for m in WhjModel::ALL {
            let p = m.params();
            assert!(
                (p.peak_speed_rpm - 3000.0 / f64::from(p.reduction_ratio)).abs() < 1e-9,
                "{m}"
            );
            assert!(
                (p.peak_torque_nm - 3.0 * p.rated_torque_nm).abs() < 1e-9,
                "{m}"
            );
        }
    }
}
