//! Joint mechanics: motor, gearbox, inertia and load, the drive's control loops, heat and
//! supply.
//!
//! Everything is in SI units at the joint output (rad, rad/s, N·m, A). The firmware layer
//! ([`super::joint`]) converts to and from wire units and decides what the drive does; this
//! module only integrates the physics one fixed step at a time.
//!
//! The control loops are an idealised servo drive \[inf\]: a reference generator that moves
//! a reference position / speed towards the target under the speed and acceleration
//! limits, a PID that makes the output follow the reference, an ideal current loop
//! (actual current = demanded current after the current limit, the low-power cap and the
//! motor's torque–speed line), and a rigid gearbox.

use super::model::ModelParams;

/// What the drive is asked to do during a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Drive {
    /// Power stage off. `brake_locked` holds the output still.
    Off {
        /// Whether the brake pin is engaged.
        brake_locked: bool,
    },
    /// Mode 0: fixed duty cycle, 0..=1.
    OpenLoop {
        /// Duty cycle as a fraction.
        duty: f64,
    },
    /// Mode 1: motor current, A.
    Current {
        /// Target current.
        amps: f64,
    },
    /// Mode 2: output speed, rad/s.
    Speed {
        /// Target speed.
        rad_s: f64,
    },
    /// Mode 3: output position (physical angle), rad, with optional feed-forward.
    Position {
        /// Target angle.
        target: f64,
        /// Speed feed-forward, rad/s (0 when unused).
        speed_ff: f64,
        /// Current feed-forward, A (0 when unused).
        current_ff: f64,
    },
}

/// Limits the firmware applies, already converted to SI units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct DriveLimits {
    /// Current limit (0x40), A.
    pub max_current: f64,
    /// Speed limit (0x41), rad/s.
    pub max_speed: f64,
    /// Acceleration limit (0x42), rad/s².
    pub max_accel: f64,
    /// Input power cap (low-power mode), W; `None` when off.
    pub power_cap: Option<f64>,
}

/// External influences on the joint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Environment {
    /// Supply voltage at no load, V.
    pub supply_v: f64,
    /// Supply source resistance, Ω.
    pub supply_r: f64,
    /// Ambient temperature, °C.
    pub ambient_c: f64,
    /// Extra output inertia, kg·m².
    pub load_inertia: f64,
    /// Gravity torque amplitude, N·m.
    pub gravity_nm: f64,
    /// Constant external torque, N·m.
    pub external_nm: f64,
    /// A hand holding the output at this angle, rad (`None`: no hand): it pulls the output
    /// toward it like a firm grip, [`HAND_STIFFNESS`] and [`HAND_DAMPING`].
    pub hand: Option<f64>,
    /// A stop in the output's way (`None`: none).
    pub obstacle: Option<super::joint::Obstacle>,
}

/// A hand's grip on the output: torque per radian between the hand and the output,
/// N·m/rad \[inf\] (a firm grip: 1° apart pulls with about 0.9 N·m).
pub(crate) const HAND_STIFFNESS: f64 = 50.0;
/// A hand's damping of the output's speed, N·m·s/rad \[inf\].
pub(crate) const HAND_DAMPING: f64 = 5.0;

/// Electrical power the electronics draw at standstill, W \[inf\].
const IDLE_POWER_W: f64 = 1.5;
/// Below this speed the output is considered at rest for static friction, rad/s.
const REST_SPEED: f64 = 1e-4;

/// Mechanical, thermal and electrical state of one joint.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Mechanics {
    /// Physical output angle, rad.
    pub theta: f64,
    /// Output speed, rad/s.
    pub omega: f64,
    /// Motor current, A (signed like the torque it makes).
    pub current: f64,
    /// Winding temperature, °C.
    pub temp_c: f64,
    /// Bus voltage at the joint, V.
    pub bus_v: f64,
    /// Electrical input power during the last step, W.
    power_in: f64,
    /// Reference position of the position loop, rad.
    ref_pos: f64,
    /// Reference speed of the position / speed loop, rad/s.
    ref_vel: f64,
    /// Integral of the position (or speed) error.
    integral: f64,
    /// Whether the loops are initialised for the current drive mode.
    loop_mode: u8,
}

impl Mechanics {
    /// A joint at rest at `theta` (rad), at ambient temperature.
    pub(crate) fn new(theta: f64, env: &Environment) -> Self {
        Self {
            theta,
            omega: 0.0,
            current: 0.0,
            temp_c: env.ambient_c,
            bus_v: env.supply_v,
            power_in: IDLE_POWER_W,
            ref_pos: theta,
            ref_vel: 0.0,
            integral: 0.0,
            loop_mode: 0,
        }
    }

    /// Restart the reference generator from the present state (after enable, a mode
    /// change, or a target jump that must not be smoothed).
    pub(crate) fn reset_loops(&mut self) {
        self.ref_pos = self.theta;
        self.ref_vel = self.omega;
        self.integral = 0.0;
        self.loop_mode = 0;
    }

    /// The position loop's present reference (the commanded trajectory), rad.
    pub(crate) fn reference(&self) -> f64 {
        self.ref_pos
    }

    /// Integrate one step of `dt` seconds.
    #[allow(clippy::too_many_lines)]
    pub(crate) fn step(
        &mut self,
        dt: f64,
        drive: Drive,
        limits: &DriveLimits,
        p: &ModelParams,
        env: &Environment,
        bandwidth_hz: f64,
    ) {
        let inertia = p.output_inertia_kgm2() + env.load_inertia.max(0.0);
        let kt = p.torque_constant();
        let wb = core::f64::consts::TAU * bandwidth_hz.max(0.1);
        let max_speed = limits.max_speed.max(0.0);
        let max_accel = limits.max_accel.max(1e-6);

        // 1. Demanded motor current.
        let (demand, locked) = match drive {
            Drive::Off { brake_locked } => (0.0, brake_locked),
            Drive::OpenLoop { duty } => {
                self.loop_mode = 0;
                (duty.clamp(0.0, 1.0) * p.peak_current_a(), false)
            }
            Drive::Current { amps } => {
                self.loop_mode = 1;
                // The speed limit applies in current mode too (§6.2): near it, the drive
                // gives only the current that holds the limit.
                let mut amps = amps;
                if amps * self.omega > 0.0 {
                    let hold = 2.0 * inertia * wb * (max_speed - self.omega.abs())
                        + p.viscous_friction_nms * self.omega.abs()
                        + p.coulomb_friction_nm;
                    let cap = (hold / kt).max(0.0);
                    amps = amps.clamp(-cap, cap);
                }
                (amps, false)
            }
            Drive::Speed { rad_s } => {
                if self.loop_mode != 2 {
                    self.ref_vel = self.omega;
                    self.integral = 0.0;
                    self.loop_mode = 2;
                }
                let goal = rad_s.clamp(-max_speed, max_speed);
                let prev = self.ref_vel;
                self.ref_vel = approach(prev, goal, max_accel * dt);
                let accel = (self.ref_vel - prev) / dt;
                let err = self.ref_vel - self.omega;
                self.integral = (self.integral + err * dt).clamp(-1.0, 1.0);
                let kv = 2.0 * inertia * wb;
                let ki = inertia * wb * wb;
                let tau = inertia * accel
                    + p.viscous_friction_nms * self.ref_vel
                    + kv * err
                    + ki * self.integral;
                (tau / kt, false)
            }
            Drive::Position {
                target,
                speed_ff,
                current_ff,
            } => {
                if self.loop_mode != 3 {
                    self.ref_pos = self.theta;
                    self.ref_vel = self.omega;
                    self.integral = 0.0;
                    self.loop_mode = 3;
                }
                let prev = self.ref_vel;
                let err = target - self.ref_pos;
                // Fastest approach that can still stop at the target, no overshoot per step.
                let mut desired =
                    err.signum() * (2.0 * max_accel * err.abs()).sqrt().min(max_speed);
                if desired.abs() * dt > err.abs() {
                    desired = err / dt;
                }
                let desired = (desired + speed_ff).clamp(-max_speed, max_speed);
                self.ref_vel = approach(prev, desired, max_accel * dt);
                if (target - self.ref_pos).abs() <= (self.ref_vel * dt).abs()
                    && (self.ref_vel - speed_ff).abs() <= max_accel * dt
                {
                    self.ref_pos = target;
                    self.ref_vel = speed_ff.clamp(-max_speed, max_speed);
                } else {
                    self.ref_pos += self.ref_vel * dt;
                }
                let accel = (self.ref_vel - prev) / dt;
                let e = self.ref_pos - self.theta;
                let ev = self.ref_vel - self.omega;
                let ki = inertia * wb * wb * wb * 0.1;
                self.integral =
                    (self.integral + e * dt).clamp(-p.peak_torque_nm / ki, p.peak_torque_nm / ki);
                let kp = inertia * wb * wb;
                let kd = 1.8 * inertia * wb;
                let tau = inertia * accel
                    + p.viscous_friction_nms * self.ref_vel
                    + kp * e
                    + kd * ev
                    + ki * self.integral;
                (tau / kt + current_ff, false)
            }
        };

        // 2. Current limit, motor torque–speed line, low-power cap.
        let mut current = demand.clamp(-limits.max_current.abs(), limits.max_current.abs());
        if current * self.omega > 0.0 {
            // The supply voltage minus the back-EMF limits the current while motoring.
            let r = p.winding_resistance_ohm.max(1e-9);
            let cap = ((self.bus_v - kt * self.omega.abs()) / r).max(0.0);
            current = current.clamp(-cap, cap);
        }
        if let Some(cap_w) = limits.power_cap {
            let r = p.winding_resistance_ohm.max(1e-9);
            let emf = (kt * self.omega).abs();
            // Largest |I| with R·I² + |kt·ω|·I ≤ cap (motoring).
            let i_max =
                (-emf + (emf * emf + 4.0 * r * (cap_w - IDLE_POWER_W).max(0.0)).sqrt()) / (2.0 * r);
            if current * self.omega >= 0.0 {
                current = current.clamp(-i_max, i_max);
            }
        }
        if matches!(drive, Drive::Off { .. }) {
            current = 0.0;
        }
        self.current = current;

        // 3. Torques on the output.
        let omega_start = self.omega;
        let tau_motor = kt * current;
        let tau_hand = env.hand.map_or(0.0, |at| {
            HAND_STIFFNESS * (at - self.theta) - HAND_DAMPING * self.omega
        });
        let tau_stop = env
            .obstacle
            .map_or(0.0, |o| o.torque(self.theta, self.omega));
        let tau_load = -env.gravity_nm * self.theta.cos() + env.external_nm + tau_hand + tau_stop;
        let tau_drive = tau_motor + tau_load - p.viscous_friction_nms * self.omega;
        let at_rest = self.omega.abs() < REST_SPEED && tau_drive.abs() <= p.coulomb_friction_nm;
        if locked || at_rest {
            // The brake, or static friction, holds the output.
            self.omega = 0.0;
        } else {
            let friction = p.coulomb_friction_nm
                * if self.omega.abs() >= REST_SPEED {
                    self.omega.signum()
                } else {
                    tau_drive.signum()
                };
            let next = self.omega + (tau_drive - friction) / inertia * dt;
            // Coulomb friction stops the output, it never reverses it.
            self.omega = if self.omega != 0.0 && next.signum() != self.omega.signum() {
                0.0
            } else {
                next
            };
            self.theta += self.omega * dt;
        }

        // 4. Heat and supply.
        let copper = p.winding_resistance_ohm * current * current;
        let c_th = p.thermal_time_constant_s / p.thermal_resistance_k_per_w;
        let flow = (self.temp_c - env.ambient_c) / p.thermal_resistance_k_per_w;
        self.temp_c += (copper - flow) / c_th * dt;
        let p_in = tau_motor * omega_start + copper + IDLE_POWER_W;
        self.power_in = p_in;
        let i_bus = p_in / env.supply_v.max(1.0);
        self.bus_v = env.supply_v - env.supply_r * i_bus;
    }

    /// Electrical input power during the last step, W.
    pub(crate) fn input_power(&self) -> f64 {
        self.power_in
    }
}

/// Move `from` towards `to` by at most `step`.
fn approach(from: f64, to: f64, step: f64) -> f64 {
    if to > from {
        (from + step).min(to)
    } else {
        (from - step).max(to)
    }
}

#[cfg(test)]
#[allow(clippy::float_cmp)] // exact values are asserted on purpose
mod tests {
    use super::super::model::WhjModel;
    use super::*;

    fn env() -> Environment {
        Environment {
            supply_v: 24.0,
            supply_r: 0.05,
            ambient_c: 25.0,
            load_inertia: 0.0,
            gravity_nm: 0.0,
            external_nm: 0.0,
            hand: None,
            obstacle: None,
        }
    }

    fn limits(p: &ModelParams) -> DriveLimits {
        DriveLimits {
            max_current: p.peak_current_a(),
            max_speed: p.peak_speed_rad_s(),
            max_accel: 500.0 * core::f64::consts::TAU / 60.0,
            power_cap: None,
        }
    }

    #[test]
    fn position_loop_reaches_target_within_limits() {
        let p = WhjModel::Whj30.params();
        let e = env();
        let l = limits(&p);
        let mut m = Mechanics::new(0.0, &e);
        let target = 10f64.to_radians();
        let mut max_speed: f64 = 0.0;
        for _ in 0..20_000 {
            m.step(
                1e-4,
                Drive::Position {
                    target,
                    speed_ff: 0.0,
                    current_ff: 0.0,
                },
                &l,
                &p,
                &e,
                25.0,
            );
            max_speed = max_speed.max(m.omega.abs());
        }
        assert!(
            (m.theta - target).abs() < 1e-4,
            "theta {}",
            m.theta.to_degrees()
        );
        assert!(max_speed <= l.max_speed * 1.05, "{max_speed}");
        assert!(m.reference() == target);
    }

    #[test]
    fn brake_holds_against_load() {
        let p = WhjModel::Whj30.params();
        let mut e = env();
        e.external_nm = 50.0;
        let mut m = Mechanics::new(0.5, &e);
        for _ in 0..1000 {
            m.step(
                1e-4,
                Drive::Off { brake_locked: true },
                &limits(&p),
                &p,
                &e,
                25.0,
            );
        }
        assert_eq!(m.theta, 0.5);
        assert_eq!(m.current, 0.0);
        for _ in 0..1000 {
            m.step(
                1e-4,
                Drive::Off {
                    brake_locked: false,
                },
                &limits(&p),
                &p,
                &e,
                25.0,
            );
        }
        assert!(m.theta > 0.5);
    }

    #[test]
    fn low_power_caps_input_power() {
        let p = WhjModel::Whj30.params();
        let e = env();
        let mut l = limits(&p);
        l.power_cap = Some(80.0);
        let mut m = Mechanics::new(0.0, &e);
        for _ in 0..20_000 {
            m.step(1e-4, Drive::Current { amps: 20.0 }, &l, &p, &e, 25.0);
            assert!(m.input_power() <= 80.0 + 1e-6, "{}", m.input_power());
        }
        assert!(m.omega > 0.0);
    }
}
