//! Motor, gearbox and the firmware's position loop.
//!
//! The model, at the output shaft, in degrees, seconds and kg·cm:
//!
//! * A brushed DC motor behind the gearbox: with PWM duty `u` (−1..=1) the shaft torque is
//!   `T_stall · (u − ω/ω₀)`, where `T_stall` and `ω₀` are the model's stall torque and
//!   no-load speed (section 1-9). The reflected rotor inertia gives a mechanical time
//!   constant of 10 ms; the gear train adds Coulomb friction of 3 % of the stall torque.
//! * Supply current is `I_stall · |u − ω/ω₀|` while the motor is driven (see
//!   [`Model::stall_current_ma`]); the load byte a module reports is that current on the
//!   over-load code scale (A-1 (18)), so a load reading and an over-load threshold compare
//!   directly. Over-load compares the current low-pass filtered over 100 ms with the
//!   threshold and drops the servo into passive mode.
//! * Position control (the firmware): a reference moves towards the target with a
//!   trapezoidal profile, its top speed `ω₀ · (5 − level)/5 · speed/30` (speed 0 = no limit) and its
//!   acceleration `ω₀ · accel` per second (acceleration range 100 reaches full speed in
//!   10 ms, the default 60 in 17 ms, 20 in 50 ms). The duty is PID on the error to that
//!   reference, `u = kp·e + kd·ė + ki·∫e`, with `kp = 0.02·P` per degree,
//!   `kd = 0.000084·D` per °/s and `ki = 0.5·I` per °·s. The default gains (P 20, D 30)
//!   give a damping ratio of about 0.8; a larger P settles faster.
//! * The torque level of a position move (0 = max .. 4 = min) limits the duty to
//!   `(5 − level)/5`: a lower level is both weaker (stall torque) and slower (no-load
//!   speed), so it sags under a load the full level holds.
//! * Passive: no drive, the shaft turns against the gear friction and a viscous drag of
//!   `0.4 · T_stall · ω/ω₀` (a 1 kg·cm push turns a 1108 at about 95 °/s). Break: the winding is shorted (dynamic brake), torque
//!   `−T_stall · ω/ω₀`, no supply current. Wheel: duty `± speed/15`.
//! * The shaft angle lives in `0..360°` (the potentiometer frame: 0..=1023 high-resolution
//!   steps of 333/1023°, 0..=254 standard steps of 269/255°, both from the same zero;
//!   beyond their range a reading saturates). Every wrap from 360° to 0° counts one
//!   rotation up (counter-clockwise = increasing angle), every wrap down one rotation down.

use super::model::Model;

/// Control and integration period of the simulated firmware, in nanoseconds.
pub const TICK_NANOS: u64 = 500_000;
/// Control and integration period of the simulated firmware, in seconds.
pub const TICK_SECONDS: f64 = TICK_NANOS as f64 / 1e9;

/// Mechanical time constant (reflected rotor inertia over motor damping).
const TAU_MECH: f64 = 0.010;
/// Gear-train Coulomb friction as a fraction of the stall torque.
const FRICTION: f64 = 0.03;
/// Viscous drag of the gear train with the winding open (passive), as a fraction of the
/// motor's own damping `T_stall / ω₀`.
const PASSIVE_DRAG: f64 = 0.4;
/// Over-current filter time constant.
const TAU_CURRENT: f64 = 0.100;
/// Gain scales (see the module docs).
const KP_PER_UNIT: f64 = 0.02;
const KD_PER_UNIT: f64 = 0.000_084;
const KI_PER_UNIT: f64 = 0.5;
/// Anti-windup limit of the integral term (in duty).
const I_LIMIT: f64 = 0.5;

/// Degrees of one standard-resolution step (section 3-1).
pub const DEG_PER_STEP8: f64 = 269.0 / 255.0;
/// Degrees of one high-resolution step (section 3-1).
pub const DEG_PER_STEP10: f64 = 333.0 / 1023.0;

/// What drives the motor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Drive {
    /// Position control towards `target` degrees at torque level `level` (0..=4).
    Position {
        /// Target angle in degrees.
        target: f64,
        /// Torque level 0 (max) ..= 4 (min).
        level: u8,
    },
    /// Torque released.
    Passive,
    /// Dynamic brake.
    Brake,
    /// Continuous rotation; `ccw` increases the angle; speed 0..=15.
    Wheel {
        /// Counter-clockwise (angle increasing).
        ccw: bool,
        /// Wheel speed 0 (stop) ..= 15.
        speed: u8,
    },
}

/// The gains and limits in effect (runtime values).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Tuning {
    /// P gain.
    pub p: u8,
    /// D gain.
    pub d: u8,
    /// I gain.
    pub i: u8,
    /// Speed level 0..=30 (0 = no limit).
    pub speed: u8,
    /// Acceleration range 20..=100.
    pub accel: u8,
    /// Over-load threshold in mA.
    pub overload_ma: u16,
}

/// What an external hand or load does to the shaft (the test API).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct External {
    /// A constant torque on the shaft in kg·cm (positive turns towards larger angles).
    pub torque: f64,
    /// The shaft is held still.
    pub held: bool,
}

/// The shaft and the position loop of one servo.
#[derive(Debug, Clone)]
pub struct Mechanics {
    model: Model,
    angle: f64,
    velocity: f64,
    rotations: i64,
    drive: Drive,
    ref_pos: f64,
    ref_vel: f64,
    integral: f64,
    current_ma: f64,
    filtered_ma: f64,
    /// External influences.
    pub external: External,
}

/// What one tick reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TickEvent {
    /// Nothing special.
    None,
    /// The filtered current exceeded the threshold: the servo went passive.
    Overload,
}

impl Mechanics {
    /// A shaft at rest at `angle` degrees, passive.
    pub fn new(model: Model, angle: f64) -> Self {
        let angle = angle.rem_euclid(360.0);
        Self {
            model,
            angle,
            velocity: 0.0,
            rotations: 0,
            drive: Drive::Passive,
            ref_pos: angle,
            ref_vel: 0.0,
            integral: 0.0,
            current_ma: 0.0,
            filtered_ma: 0.0,
            external: External::default(),
        }
    }

    /// The model.
    pub const fn model(&self) -> Model {
        self.model
    }

    /// Shaft angle in degrees, `0..360`.
    pub const fn angle(&self) -> f64 {
        self.angle
    }

    /// Shaft speed in degrees per second (positive = counter-clockwise).
    pub const fn velocity(&self) -> f64 {
        self.velocity
    }

    /// Turns the shaft to `degrees` at once (a hand setting it), at rest. Non-finite
    /// values are ignored.
    pub fn set_angle(&mut self, degrees: f64) {
        if !degrees.is_finite() {
            return;
        }
        self.angle = degrees.rem_euclid(360.0);
        self.velocity = 0.0;
        self.ref_pos = self.angle;
        self.ref_vel = 0.0;
        self.integral = 0.0;
    }

    /// The drive in effect.
    pub const fn drive(&self) -> Drive {
        self.drive
    }

    /// Changes the drive. A new position target keeps the reference where the shaft is
    /// if the servo was not under position control before.
    pub fn set_drive(&mut self, drive: Drive) {
        let was_position = matches!(self.drive, Drive::Position { .. });
        if !was_position && matches!(drive, Drive::Position { .. }) {
            self.ref_pos = self.angle;
            self.ref_vel = self.velocity;
            self.integral = 0.0;
        }
        self.drive = drive;
    }

    /// Full rotations since power-up (counter-clockwise positive).
    pub const fn rotations(&self) -> i64 {
        self.rotations
    }

    /// Clears the rotation counter (power-up).
    pub fn reset_rotations(&mut self) {
        self.rotations = 0;
    }

    /// Instantaneous supply current in mA.
    pub const fn current_ma(&self) -> f64 {
        self.current_ma
    }

    /// Filtered supply current in mA (what over-load compares).
    pub const fn filtered_current_ma(&self) -> f64 {
        self.filtered_ma
    }

    /// The standard-resolution reading 0..=254.
    pub fn position8(&self) -> u8 {
        quantize(self.angle, DEG_PER_STEP8, 254)
    }

    /// The high-resolution reading 0..=1023.
    pub fn position10(&self) -> u16 {
        quantize_u16(self.angle, DEG_PER_STEP10, 1023)
    }

    /// The load byte: the supply current on the over-load code scale, 0..=254.
    pub fn load(&self) -> u8 {
        load_code(self.current_ma)
    }

    /// Removes power: no drive, no current.
    pub fn power_off(&mut self) {
        self.drive = Drive::Passive;
        self.current_ma = 0.0;
        self.filtered_ma = 0.0;
        self.integral = 0.0;
    }

    /// Advances one [`TICK_SECONDS`] step.
    pub fn tick(&mut self, tuning: &Tuning) -> TickEvent {
        let dt = TICK_SECONDS;
        let w0 = self.model.no_load_speed_dps();
        let t_stall = self.model.stall_torque_kgcm();
        let inertia = t_stall * TAU_MECH / w0;
        let (motor_torque, driven_duty) = match self.drive {
            Drive::Position { target, level } => {
                let limit = f64::from(5 - level.min(4)) / 5.0;
                let u = self.position_duty(target, limit, *tuning, w0, dt);
                (t_stall * (u - self.velocity / w0), true)
            }
            Drive::Passive => (-PASSIVE_DRAG * t_stall * self.velocity / w0, false),
            Drive::Brake => (-t_stall * self.velocity / w0, false),
            Drive::Wheel { ccw, speed } => {
                let mag = f64::from(speed.min(15)) / 15.0;
                let u = if ccw { mag } else { -mag };
                (t_stall * (u - self.velocity / w0), true)
            }
        };
        self.current_ma = if driven_duty {
            self.model.stall_current_ma() * (motor_torque / t_stall).abs().min(1.0)
        } else {
            0.0
        };
        self.filtered_ma += (self.current_ma - self.filtered_ma) * (dt / TAU_CURRENT);

        if self.external.held {
            self.velocity = 0.0;
        } else {
            let drive_torque = motor_torque + self.external.torque;
            let friction = FRICTION * t_stall;
            let net = if self.velocity.abs() < 1e-6 {
                // Static friction: the shaft starts only if the drive overcomes it.
                if drive_torque.abs() <= friction {
                    0.0
                } else {
                    drive_torque - friction * drive_torque.signum()
                }
            } else {
                drive_torque - friction * self.velocity.signum()
            };
            let new_velocity = self.velocity + net / inertia * dt;
            // Friction stops the shaft rather than reversing it.
            self.velocity = if self.velocity != 0.0
                && new_velocity.signum() != self.velocity.signum()
                && drive_torque.abs() <= friction
            {
                0.0
            } else {
                new_velocity
            };
            let mut angle = self.angle + self.velocity * dt;
            if !angle.is_finite() {
                // Only a non-finite external torque gets here: stop rather than spin.
                angle = self.angle;
                self.velocity = 0.0;
            }
            let turns = (angle / 360.0).floor();
            if turns != 0.0 {
                angle -= 360.0 * turns;
                self.ref_pos -= 360.0 * turns;
                // A tick moves the shaft by far less than 2^53 turns.
                #[allow(clippy::cast_possible_truncation)]
                let whole = turns as i64;
                self.rotations += whole;
            }
            self.angle = angle.rem_euclid(360.0);
        }

        if driven_duty && self.filtered_ma > f64::from(tuning.overload_ma) {
            self.drive = Drive::Passive;
            self.current_ma = 0.0;
            self.integral = 0.0;
            return TickEvent::Overload;
        }
        TickEvent::None
    }

    /// The duty of the position loop for one step.
    fn position_duty(&mut self, target: f64, limit: f64, tuning: Tuning, w0: f64, dt: f64) -> f64 {
        let speed_factor = if tuning.speed == 0 {
            1.0
        } else {
            f64::from(tuning.speed.min(30)) / 30.0
        };
        let v_max = w0 * limit * speed_factor;
        let a_max = w0 * f64::from(tuning.accel.clamp(20, 100));
        // Trapezoidal reference.
        let dist = target - self.ref_pos;
        let v_des = dist.signum() * v_max.min((2.0 * a_max * dist.abs()).sqrt());
        let dv = (v_des - self.ref_vel).clamp(-a_max * dt, a_max * dt);
        self.ref_vel += dv;
        let next = self.ref_pos + self.ref_vel * dt;
        if (target - next).signum() != dist.signum() || dist == 0.0 {
            self.ref_pos = target;
            self.ref_vel = 0.0;
        } else {
            self.ref_pos = next;
        }
        let err = self.ref_pos - self.angle;
        let derr = self.ref_vel - self.velocity;
        let ki = KI_PER_UNIT * f64::from(tuning.i);
        if ki > 0.0 {
            self.integral = (self.integral + err * dt).clamp(-I_LIMIT / ki, I_LIMIT / ki);
        } else {
            self.integral = 0.0;
        }
        let u = KP_PER_UNIT * f64::from(tuning.p) * err
            + KD_PER_UNIT * f64::from(tuning.d) * derr
            + ki * self.integral;
        u.clamp(-limit, limit)
    }
}

/// Nearest step of `deg` at `step` degrees, saturated at `0..=max`.
fn quantize(deg: f64, step: f64, max: u8) -> u8 {
    let s = (deg / step).round();
    if s.is_nan() || s <= 0.0 {
        0
    } else if s >= f64::from(max) {
        max
    } else {
        // In 0..max: exact.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let v = s as u8;
        v
    }
}

/// Nearest step of `deg` at `step` degrees, saturated at `0..=max`.
fn quantize_u16(deg: f64, step: f64, max: u16) -> u16 {
    let s = (deg / step).round();
    if s.is_nan() || s <= 0.0 {
        0
    } else if s >= f64::from(max) {
        max
    } else {
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let v = s as u16;
        v
    }
}

/// A current in mA on the over-load code scale of A-1 (18): 400 mA → 33, 1800 mA → 199,
/// proportional below 400 mA, saturating at 254.
pub fn load_code(ma: f64) -> u8 {
    let table = robobus_wck::OVERLOAD_TABLE;
    let code = if ma <= 400.0 {
        ma * 33.0 / 400.0
    } else {
        let mut code = None;
        for pair in table.windows(2) {
            if let [(c0, m0), (c1, m1)] = pair {
                let (m0, m1) = (f64::from(*m0), f64::from(*m1));
                if ma <= m1 {
                    code = Some(f64::from(*c0) + (ma - m0) * f64::from(c1 - c0) / (m1 - m0));
                    break;
                }
            }
        }
        code.unwrap_or_else(|| 199.0 + (ma - 1800.0) * (199.0 - 128.0) / 600.0)
    };
    quantize(code, 1.0, 254)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tuning() -> Tuning {
        Tuning {
            p: 20,
            d: 30,
            i: 0,
            speed: 0,
            accel: 60,
            overload_ma: 1800,
        }
    }

    #[test]
    fn load_code_follows_the_table() {
        assert_eq!(load_code(0.0), 0);
        assert_eq!(load_code(400.0), 33);
        assert_eq!(load_code(1000.0), 104);
        assert_eq!(load_code(1800.0), 199);
        assert_eq!(load_code(10_000.0), 254);
    }

    #[test]
    fn readings_quantize_and_saturate() {
        let mut m = Mechanics::new(Model::W1108, 0.0);
        assert_eq!(m.position8(), 0);
        m.set_angle(127.0 * DEG_PER_STEP8);
        assert_eq!(m.position8(), 127);
        m.set_angle(1000.0 * DEG_PER_STEP10);
        assert_eq!(m.position10(), 1000);
        m.set_angle(300.0);
        assert_eq!(m.position8(), 254);
        m.set_angle(359.0);
        assert_eq!(m.position10(), 1023);
    }

    #[test]
    fn holds_target_and_settles() {
        let mut m = Mechanics::new(Model::W1108, 50.0);
        m.set_drive(Drive::Position {
            target: 100.0,
            level: 0,
        });
        for _ in 0..2000 {
            m.tick(&tuning());
        }
        assert!((m.angle() - 100.0).abs() < 0.5, "{}", m.angle());
        assert!(m.velocity().abs() < 1.0);
    }

    #[test]
    fn wheel_counts_rotations_both_ways() {
        let mut m = Mechanics::new(Model::W1108, 10.0);
        m.set_drive(Drive::Wheel {
            ccw: true,
            speed: 15,
        });
        // 400 deg/s for 10 s: about 11 turns.
        for _ in 0..20_000 {
            m.tick(&tuning());
        }
        assert!((10..=11).contains(&m.rotations()), "{}", m.rotations());
        m.set_drive(Drive::Wheel {
            ccw: false,
            speed: 15,
        });
        for _ in 0..40_000 {
            m.tick(&tuning());
        }
        assert!(m.rotations() < 0, "{}", m.rotations());
    }
}
