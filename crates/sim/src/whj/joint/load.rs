//! What a test puts in a joint's way: an obstacle the output runs into, and heat in its
//! winding.
//!
//! An [`Obstacle`] is a stiff, damped stop at an angle of the output: on its far side
//! the output is pushed back with [`Obstacle::STIFFNESS`] per radian (about 35 N·m a
//! degree: no WHJ joint's peak torque gets more than a few degrees into it) and damped
//! with [`Obstacle::DAMPING`]; on the near side it does nothing. A joint driven into it
//! stops there while its position loop raises the current toward its limit, as a real
//! joint does against a wall or a person. [`SimJoint::set_winding_temperature`] puts the
//! winding at a temperature at once (a joint that ran hot before the test), from where
//! the thermal model carries on.

use super::SimJoint;

/// A stop in the way of the output: on its far side the output is pushed back with
/// [`Obstacle::STIFFNESS`] per radian and damped with [`Obstacle::DAMPING`]; on its near
/// side it does nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Obstacle {
    /// Where the stop is, degrees of the output (the physical angle).
    pub at_deg: f64,
    /// `true`: it stops the output turning up past `at_deg`; `false`: down past it.
    pub above: bool,
}

impl Obstacle {
    /// Torque per radian the stop pushes back with, N·m/rad \[inf\]: a rigid fixture.
    pub const STIFFNESS: f64 = 2000.0;
    /// Damping of the output's speed while in contact, N·m·s/rad \[inf\].
    pub const DAMPING: f64 = 20.0;

    /// A stop at `at_deg` that the output cannot pass turning up.
    pub const fn above(at_deg: f64) -> Self {
        Self {
            at_deg,
            above: true,
        }
    }

    /// A stop at `at_deg` that the output cannot pass turning down.
    pub const fn below(at_deg: f64) -> Self {
        Self {
            at_deg,
            above: false,
        }
    }

    /// The torque on the output at `theta` (rad) turning at `omega` (rad/s), N·m.
    pub(crate) fn torque(&self, theta: f64, omega: f64) -> f64 {
        let at = self.at_deg.to_radians();
        let into = if self.above { theta - at } else { at - theta };
        if into <= 0.0 {
            return 0.0;
        }
        let push = Self::STIFFNESS * into;
        let sign = if self.above { -1.0 } else { 1.0 };
        sign * push - Self::DAMPING * omega
    }
}

impl SimJoint {
    /// Puts an obstacle in the output's way (`None` takes it away).
    pub fn set_obstacle(&mut self, obstacle: Option<Obstacle>) {
        self.env.obstacle = obstacle;
    }

    /// Sets the winding temperature, °C, at once (the thermal model carries on from it).
    pub fn set_winding_temperature(&mut self, celsius: f64) {
        if celsius.is_finite() {
            self.mech.temp_c = celsius;
        }
    }
}

#[cfg(test)]
#[allow(clippy::float_cmp)] // exact values are asserted on purpose
mod tests {
    use super::Obstacle;

    #[test]
    fn an_obstacle_pushes_back_only_past_its_angle() {
        let o = Obstacle::above(10.0);
        assert_eq!(o.torque(5f64.to_radians(), 0.0), 0.0);
        let t = o.torque(11f64.to_radians(), 0.0);
        assert!(
            (t + Obstacle::STIFFNESS * 1f64.to_radians()).abs() < 1e-9,
            "{t}"
        );
        let b = Obstacle::below(-10.0);
        assert_eq!(b.torque(0.0, 0.0), 0.0);
        assert!(b.torque(-11f64.to_radians(), 0.0) > 0.0);
    }
}
