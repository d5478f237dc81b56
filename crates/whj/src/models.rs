//! The WHJ joint products as data (§9 of the WHJ joint protocol reference: the vendor's product
//! pages; §5.2 for the model codes; §6.8 for the model-gated features).
//!
//! [`PRODUCTS`] is the one table of model facts: every other layer (simulator, client,
//! command line) reads wire code, reduction ratio, peak output speed, current scale,
//! brake and model-gated features from here. Several products share one wire code (WHJ10
//! with and without brake both report 0x02), so facts a joint can be asked about by its
//! code ([`Model`]) are those all products with that code agree on; see
//! [`Model::facts`] and [`Model::may_have`].

use crate::registers::Feature;
use crate::units::{CurrentScale, Model};

/// The published facts of one WHJ product.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProductFacts {
    /// Short product name as the vendor writes it ("WHJ10N").
    pub name: &'static str,
    /// Full part number ("WHJ10-M-D50-80-N").
    pub part_number: &'static str,
    /// The model code the joint reports in register 0x02.
    pub model: Model,
    /// Gear reduction ratio (register 0x07).
    pub reduction_ratio: u16,
    /// Peak output speed, RPM (= the factory speed limit 3000 ÷ ratio, C3).
    pub peak_output_speed_rpm: f64,
    /// Current LSB on the wire (C2; 0x07 and 0x05 inferred).
    pub current_scale: CurrentScale,
    /// A pin brake (the `B` suffix; `N` models have none, C25).
    pub pin_brake: bool,
    /// Features that only some products have (the firmware gate applies on top):
    /// [`Feature::LowPowerMode`] on WHJ10N/30/60, [`Feature::BrakeRelease`] on WHJ30/60.
    pub model_features: &'static [Feature],
    /// Rated output torque, N·m.
    pub rated_torque_nm: f64,
    /// Peak output torque, N·m.
    pub peak_torque_nm: f64,
    /// Rated power, W.
    pub rated_power_w: f64,
    /// Rated current, A (the pages list rated power ÷ 24 V: a supply-side value).
    pub rated_current_a: f64,
    /// Rotor inertia, kg·m² (EN product page; C26).
    pub rotor_inertia_kgm2: f64,
    /// Mass, kg.
    pub mass_kg: f64,
}

impl ProductFacts {
    /// Whether this product has a model-gated `feature` (features that are not model-gated
    /// exist on every product; their firmware gate still applies).
    pub fn has(&self, feature: Feature) -> bool {
        !feature.gate().model_gated || self.model_features.contains(&feature)
    }

    /// The torque constant at the output, N·m per A of motor current, as the rated torque
    /// over the rated current: an estimate (the rated current is a supply-side value), the
    /// one the simulator uses.
    pub fn torque_constant_nm_per_a(&self) -> f64 {
        self.rated_torque_nm / self.rated_current_a
    }

    /// The output torque constant of a joint that identified as `model` with
    /// `reduction_ratio` (see [`Self::torque_constant_nm_per_a`]); `None` when no product
    /// matches or the products that match differ.
    pub fn torque_constant_of(model: Model, reduction_ratio: u16) -> Option<f64> {
        let mut k = PRODUCTS
            .iter()
            .filter(|p| p.model == model && p.reduction_ratio == reduction_ratio)
            .map(Self::torque_constant_nm_per_a);
        let first = k.next()?;
        k.all(|x| (x - first).abs() < 1e-9).then_some(first)
    }

    /// The product with this name, ignoring ASCII case and an optional `WHJ` prefix
    /// (`"whj30"`, `"30"`, `"WHJ10N"`); `"whj10"` is the braked WHJ10.
    pub fn by_name(name: &str) -> Option<&'static Self> {
        let n = name.trim();
        let n = n
            .get(..3)
            .filter(|p| p.eq_ignore_ascii_case("whj"))
            .map_or(n, |_| n.get(3..).unwrap_or_default());
        let n = match n {
            "3" => "03",
            "10" => "10B",
            other => other,
        };
        PRODUCTS
            .iter()
            .find(|p| p.name.get(3..).is_some_and(|s| s.eq_ignore_ascii_case(n)))
    }
}

/// The highest peak output speed of any product, RPM (37.5: WHJ10 and WHJ30): a bound a
/// command may check before it knows which joint it will talk to.
pub const fn max_peak_output_speed_rpm() -> f64 {
    let mut max = 0.0;
    let mut i = 0;
    while i < PRODUCTS.len() {
        if PRODUCTS[i].peak_output_speed_rpm > max {
            max = PRODUCTS[i].peak_output_speed_rpm;
        }
        i += 1;
    }
    max
}

const LOW_POWER_AND_RELEASE: &[Feature] = &[Feature::LowPowerMode, Feature::BrakeRelease];

/// Every WHJ product of the vendor's pages, in the order of §9.
#[rustfmt::skip]
pub static PRODUCTS: [ProductFacts; 6] = [
    ProductFacts { name: "WHJ03", part_number: "WHJ03-M-D33-100-N", model: Model::Joint03, reduction_ratio: 100, peak_output_speed_rpm: 30.0, current_scale: CurrentScale::OneMilliamp, pin_brake: false, model_features: &[], rated_torque_nm: 3.0, peak_torque_nm: 9.0, rated_power_w: 20.0, rated_current_a: 0.8, rotor_inertia_kgm2: 1.52e-6, mass_kg: 0.170 },
    ProductFacts { name: "WHJ10B", part_number: "WHJ10-M-D50-80-B", model: Model::Joint10, reduction_ratio: 80, peak_output_speed_rpm: 37.5, current_scale: CurrentScale::OneMilliamp, pin_brake: true, model_features: &[], rated_torque_nm: 10.0, peak_torque_nm: 30.0, rated_power_w: 63.0, rated_current_a: 2.6, rotor_inertia_kgm2: 1.13e-5, mass_kg: 0.445 },
    ProductFacts { name: "WHJ10N", part_number: "WHJ10-M-D50-80-N", model: Model::Joint10, reduction_ratio: 80, peak_output_speed_rpm: 37.5, current_scale: CurrentScale::OneMilliamp, pin_brake: false, model_features: &[Feature::LowPowerMode], rated_torque_nm: 10.0, peak_torque_nm: 30.0, rated_power_w: 63.0, rated_current_a: 2.6, rotor_inertia_kgm2: 1.09e-5, mass_kg: 0.400 },
    ProductFacts { name: "WHJ30", part_number: "WHJ30-S-D60-80-B", model: Model::Joint30, reduction_ratio: 80, peak_output_speed_rpm: 37.5, current_scale: CurrentScale::OneMilliamp, pin_brake: true, model_features: LOW_POWER_AND_RELEASE, rated_torque_nm: 30.0, peak_torque_nm: 90.0, rated_power_w: 188.0, rated_current_a: 7.8, rotor_inertia_kgm2: 2.98e-5, mass_kg: 0.730 },
    ProductFacts { name: "WHJ60", part_number: "WHJ60-S-D70-100-B", model: Model::Joint60, reduction_ratio: 100, peak_output_speed_rpm: 30.0, current_scale: CurrentScale::TwoMilliamps, pin_brake: true, model_features: LOW_POWER_AND_RELEASE, rated_torque_nm: 60.0, peak_torque_nm: 180.0, rated_power_w: 292.0, rated_current_a: 12.0, rotor_inertia_kgm2: 5.51e-5, mass_kg: 1.000 },
    ProductFacts { name: "WHJ120", part_number: "WHJ120-M-D88-100-B", model: Model::Joint120, reduction_ratio: 100, peak_output_speed_rpm: 30.0, current_scale: CurrentScale::TwoMilliamps, pin_brake: true, model_features: &[], rated_torque_nm: 120.0, peak_torque_nm: 360.0, rated_power_w: 628.0, rated_current_a: 26.0, rotor_inertia_kgm2: 1.37e-4, mass_kg: 1.800 },
];

impl Model {
    /// The first product in [`PRODUCTS`] with this model code, or `None` (gripper,
    /// unknown codes). Products sharing a code agree on ratio, peak speed and current
    /// scale (a test checks it), so those can be read from here.
    pub const fn facts(self) -> Option<&'static ProductFacts> {
        let mut i = 0;
        while i < PRODUCTS.len() {
            if PRODUCTS[i].model.code() == self.code() {
                return Some(&PRODUCTS[i]);
            }
            i += 1;
        }
        None
    }

    /// Whether some product with this code has `feature` (for a model-gated feature
    /// on a shared code, such as low power on WHJ10, the joint itself decides). Unknown
    /// codes and the gripper: only features that are not model-gated.
    pub fn may_have(self, feature: Feature) -> bool {
        !feature.gate().model_gated || PRODUCTS.iter().any(|p| p.model == self && p.has(feature))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn products_sharing_a_code_agree_on_the_wire_facts() {
        for p in &PRODUCTS {
            let first = p.model.facts().unwrap();
            assert_eq!(p.reduction_ratio, first.reduction_ratio, "{}", p.name);
            assert_eq!(p.current_scale, first.current_scale, "{}", p.name);
            assert!((p.peak_output_speed_rpm - first.peak_output_speed_rpm).abs() < 1e-12);
            // Peak speed = factory limit 3000 / ratio (C3); peak torque = 3 × rated.
            assert!(
                (p.peak_output_speed_rpm - 3000.0 / f64::from(p.reduction_ratio)).abs() < 1e-9,
                "{}",
                p.name
            );
            assert!((p.peak_torque_nm - 3.0 * p.rated_torque_nm).abs() < 1e-9);
            assert!(
                p.part_number
                    .ends_with(if p.pin_brake { "-B" } else { "-N" })
            );
        }
    }

    #[test]
    fn names_and_model_gated_features() {
        for p in &PRODUCTS {
            assert_eq!(ProductFacts::by_name(p.name).unwrap().name, p.name);
        }
        assert_eq!(ProductFacts::by_name("whj10").unwrap().name, "WHJ10B");
        assert_eq!(ProductFacts::by_name("10n").unwrap().name, "WHJ10N");
        assert_eq!(ProductFacts::by_name("3").unwrap().name, "WHJ03");
        assert!(ProductFacts::by_name("whj7").is_none());
        assert!(ProductFacts::by_name("").is_none());
        let named = |n| ProductFacts::by_name(n).unwrap();
        assert!(named("whj10n").has(Feature::LowPowerMode));
        assert!(!named("whj10b").has(Feature::LowPowerMode));
        assert!(!named("whj10n").has(Feature::BrakeRelease));
        assert!(named("whj60").has(Feature::BrakeRelease));
        assert!(named("whj120").has(Feature::Broadcast));
        assert!(Model::Joint10.may_have(Feature::LowPowerMode));
        assert!(!Model::Joint120.may_have(Feature::LowPowerMode));
        assert!(!Model::Gripper.may_have(Feature::BrakeRelease));
        assert!(Model::Gripper.may_have(Feature::EndBoardMode));
        assert!((max_peak_output_speed_rpm() - 37.5).abs() < 1e-12);
    }
}
