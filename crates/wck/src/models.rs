//! The wCK models as data (the wCK user manual v1.07: section 1-9 "Electrical & Control
//! Specifications", section 3-7 "Over-current Protection", A-1 (18) "Over Load Set", A-5
//! "Default Parameter Settings").
//!
//! [`PRODUCTS`] is the one table of wCK model facts the host reads (its protection, see
//! `robobus::ops::protect`). A wCK module does not report its model, so what the host
//! uses is what every row agrees on ([`overload_default_ma`], [`slowest_no_load_speed_dps`]).

/// The published facts of one wCK model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProductFacts {
    /// The model as printed on the module ("wCK-1108").
    pub name: &'static str,
    /// Maximum no-load speed, seconds per 60° (section 1-9, at 7.4..8.4 V).
    pub seconds_per_60deg: f64,
    /// Maximum stall torque, kg·cm (section 1-9).
    pub stall_torque_kgcm: f64,
    /// Gear ratio denominator (section 1-3).
    pub gear_ratio: u16,
    /// The lowest over-current (over-load) protection threshold, mA (section 1-9, 3-7:
    /// "400 mA ~ 1,800 mA").
    pub overload_min_ma: u16,
    /// The highest over-current protection threshold, mA.
    pub overload_max_ma: u16,
    /// The factory over-current threshold, mA (A-5: code 33, 400 mA).
    pub overload_default_ma: u16,
}

impl ProductFacts {
    /// Maximum no-load speed, degrees a second.
    pub fn no_load_speed_dps(&self) -> f64 {
        60.0 / self.seconds_per_60deg
    }
}

/// Every wCK model of the manual's specification tables.
#[rustfmt::skip]
pub static PRODUCTS: [ProductFacts; 3] = [
    ProductFacts { name: "wCK-1108", seconds_per_60deg: 0.15, stall_torque_kgcm: 8.0, gear_ratio: 173, overload_min_ma: 400, overload_max_ma: 1800, overload_default_ma: 400 },
    ProductFacts { name: "wCK-1111", seconds_per_60deg: 0.21, stall_torque_kgcm: 11.0, gear_ratio: 241, overload_min_ma: 400, overload_max_ma: 1800, overload_default_ma: 400 },
    ProductFacts { name: "wCK-1413", seconds_per_60deg: 0.19, stall_torque_kgcm: 13.0, gear_ratio: 241, overload_min_ma: 400, overload_max_ma: 1800, overload_default_ma: 400 },
];

/// The factory over-current threshold every model shares, mA (400).
pub fn overload_default_ma() -> u16 {
    PRODUCTS
        .iter()
        .map(|p| p.overload_default_ma)
        .min()
        .unwrap_or(400)
}

/// The slowest model's no-load speed, degrees a second (wCK-1111, about 286 °/s): what a
/// wheel speed is at least worth on a module whose model is not known.
pub fn slowest_no_load_speed_dps() -> f64 {
    PRODUCTS
        .iter()
        .map(ProductFacts::no_load_speed_dps)
        .fold(f64::INFINITY, f64::min)
}

/// The load byte of a reply (0..=254) as a current, mA: the load is on the over-load code
/// scale of A-1 (18) (code 33 = 400 mA .. 199 = 1800 mA, [`crate::OVERLOAD_TABLE`]),
/// proportional below code 33 and continuing the last segment above 199.
pub fn load_milliamps(load: u8) -> f64 {
    let table = crate::OVERLOAD_TABLE;
    let l = f64::from(load);
    let (c0, m0) = table[0];
    if load <= c0 {
        return l * f64::from(m0) / f64::from(c0);
    }
    for pair in table.windows(2) {
        let [(c0, m0), (c1, m1)] = [pair[0], pair[1]];
        if load <= c1 {
            let (c0, c1) = (f64::from(c0), f64::from(c1));
            return f64::from(m0) + (l - c0) * f64::from(m1 - m0) / (c1 - c0);
        }
    }
    let [(c0, m0), (c1, m1)] = [table[table.len() - 2], table[table.len() - 1]];
    f64::from(m1) + (l - f64::from(c1)) * f64::from(m1 - m0) / f64::from(c1 - c0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_rows_agree_on_the_over_load_and_convert_loads_on_its_scale() {
        assert_eq!(overload_default_ma(), 400);
        assert!((slowest_no_load_speed_dps() - 60.0 / 0.21).abs() < 1e-9);
        assert!((load_milliamps(0)).abs() < 1e-9);
        assert!((load_milliamps(33) - 400.0).abs() < 1e-9);
        assert!((load_milliamps(104) - 1000.0).abs() < 1e-9);
        assert!((load_milliamps(199) - 1800.0).abs() < 1e-9);
        assert!(load_milliamps(254) > 1800.0);
        assert!((load_milliamps(16) - 16.0 * 400.0 / 33.0).abs() < 1e-9);
    }
}
