//! One actuator model over both families, in SI units.
//!
//! An [`Actuator`] is a joint seen in radians, rad/s and amperes, whatever drives it: a
//! wCK servo ([`WckActuator`], 8-bit positions of 269°/255 ≈ 1.055° a step) or a WHJ
//! joint ([`WhjActuator`], positions in 0.0001° counts, currents in mA). A [`JointMap`]
//! turns device angles into joint angles (zero offset and direction), and [`JointLimits`]
//! are the host-side soft limits every command is clamped to. A
//! [`Robot`](crate::robot::Robot) reads and commands each of its joints through this view;
//! the safe states go through [`SafeState::apply`] ([`Actuator::apply_safe`]).
//!
//! ```
//! use robobus::actuator::{Actuator, ActuatorError};
//!
//! /// The same code moves a wCK servo or a WHJ joint.
//! fn nudge(joint: &mut dyn Actuator, by_rad: f64) -> Result<f64, ActuatorError> {
//!     let now = joint.state()?.position_rad;
//!     Ok(joint.command_position(now + by_rad)?.sent_rad)
//! }
//! ```

use robobus_link::ByteLink;
use robobus_wck::{Position, TorqueLevel};
use robobus_whj::WorkMode;
use robobus_whj::units::{CurrentScale, Position as WhjPosition};

use crate::error::ErrorKind;
use crate::ops::SafeState;
use crate::ops::safe::{SafeFailure, WckServos, WhjJoints};
use crate::ops::whj::ServoLoop;
use crate::wck::{Servo, WckError};
use crate::whj::{Joint, WhjError};

/// Degrees per wCK position step (the manual's 269°/255, section 3-1).
pub const WCK_DEGREES_PER_STEP: f64 = Position::DEGREES_PER_STEP;

/// The wCK step taken as joint zero by default (the middle of 0..=254).
pub const WCK_DEFAULT_CENTRE: u8 = 127;

/// What an actuator reports, in SI units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActuatorState {
    /// Joint angle, rad (after offset and direction).
    pub position_rad: f64,
    /// Joint velocity, rad/s, where the device reports it (WHJ: yes; wCK: `None`).
    pub velocity_rad_s: Option<f64>,
    /// Motor current, A, where the device reports it in a unit (WHJ: yes; wCK: `None`,
    /// its load byte has no unit).
    pub current_a: Option<f64>,
}

/// Host-side limits of one joint (joint frame, after offset and direction).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLimits {
    /// Lowest allowed angle, rad.
    pub min_rad: f64,
    /// Highest allowed angle, rad.
    pub max_rad: f64,
    /// Largest commanded speed, rad/s (used by [`Robot`](crate::robot::Robot)).
    pub max_velocity_rad_s: f64,
    /// Largest commanded acceleration, rad/s² (used by [`Robot`](crate::robot::Robot)).
    pub max_acceleration_rad_s2: f64,
}

impl JointLimits {
    /// Clamps `rad` into `min_rad..=max_rad`. Returns the clamped value and whether it
    /// changed.
    pub fn clamp(&self, rad: f64) -> (f64, bool) {
        let clamped = rad.clamp(self.min_rad, self.max_rad);
        (clamped, (clamped - rad).abs() > 0.0)
    }
}

/// How a device angle becomes a joint angle: `joint = direction × (device − offset)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointMap {
    /// Device angle at joint zero, rad (for a wCK servo: relative to its centre step).
    pub offset_rad: f64,
    /// `true` if the joint turns opposite to the device.
    pub reversed: bool,
}

impl Default for JointMap {
    fn default() -> Self {
        Self {
            offset_rad: 0.0,
            reversed: false,
        }
    }
}

impl JointMap {
    fn sign(self) -> f64 {
        if self.reversed { -1.0 } else { 1.0 }
    }

    /// The joint angle (rad) of a device angle (rad).
    pub fn to_joint(self, device_rad: f64) -> f64 {
        self.sign() * (device_rad - self.offset_rad)
    }

    /// The device angle (rad) of a joint angle (rad).
    pub fn to_device(self, joint_rad: f64) -> f64 {
        self.sign() * joint_rad + self.offset_rad
    }

    /// A joint speed (rad/s) from a device speed (rad/s).
    pub fn speed_to_joint(self, device_rad_s: f64) -> f64 {
        self.sign() * device_rad_s
    }
}

/// The result of one position command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Commanded {
    /// The angle sent, rad (after the soft limits and the device's resolution).
    pub sent_rad: f64,
    /// Whether the request was outside the soft limits and was clamped.
    pub clamped: bool,
}

/// Why an actuator operation failed.
#[derive(Debug, thiserror::Error)]
pub enum ActuatorError {
    /// A target that is not a finite number; nothing was sent.
    #[error("{joint}: target {value} rad is not a finite number; nothing sent")]
    NotFinite {
        /// The joint.
        joint: String,
        /// The rejected target.
        value: f64,
    },
    /// A target the device cannot express even after the soft limits (a joint whose
    /// limits reach past the device's range); nothing was sent.
    #[error(
        "{joint}: {value_rad:.4} rad is device angle {device_deg:.3}°, outside the device range {min_deg:.3}..={max_deg:.3}°; nothing sent"
    )]
    OutOfDeviceRange {
        /// The joint.
        joint: String,
        /// The joint angle, rad.
        value_rad: f64,
        /// The device angle it maps to, degrees.
        device_deg: f64,
        /// The device's lowest angle, degrees.
        min_deg: f64,
        /// The device's highest angle, degrees.
        max_deg: f64,
    },
    /// The wCK bus failed.
    #[error("{joint}: {source}")]
    Wck {
        /// The joint.
        joint: String,
        /// The bus error (names the device, module and command).
        #[source]
        source: Box<WckError>,
    },
    /// The WHJ bus failed.
    #[error("{joint}: {source}")]
    Whj {
        /// The joint.
        joint: String,
        /// The bus error (names the joint, register or request).
        #[source]
        source: Box<WhjError>,
    },
    /// The joint could not be brought to a safe state ([`Actuator::apply_safe`]).
    #[error("{joint}: safe state {}: {source}", .state.keyword())]
    Safe {
        /// The joint.
        joint: String,
        /// The state.
        state: SafeState,
        /// What failed (names the device and the error).
        #[source]
        source: Box<SafeFailure>,
    },
}

impl ActuatorError {
    /// What kind of failure this is.
    pub fn kind(&self) -> ErrorKind {
        match self {
            Self::NotFinite { .. } | Self::OutOfDeviceRange { .. } => ErrorKind::BadInput,
            Self::Wck { source, .. } => source.kind(),
            Self::Whj { source, .. } => source.kind(),
            Self::Safe { source, .. } => source.error.kind(),
        }
    }
}

/// The one result of [`SafeState::apply`] on a single joint: its first failure.
fn safe_result(
    joint: &str,
    state: SafeState,
    failed: Vec<SafeFailure>,
) -> Result<(), ActuatorError> {
    match failed.into_iter().next() {
        None => Ok(()),
        Some(f) => Err(ActuatorError::Safe {
            joint: joint.to_owned(),
            state,
            source: Box::new(f),
        }),
    }
}

/// A joint in SI units, whichever family drives it.
pub trait Actuator {
    /// The joint's name (in error messages).
    fn name(&self) -> &str;

    /// Reads the joint: angle (rad), speed (rad/s) and current (A) where known.
    fn state(&mut self) -> Result<ActuatorState, ActuatorError>;

    /// Reads the joint's angle alone, rad (what [`state`](Self::state) reads, with no
    /// more exchanges than the angle needs).
    fn position(&mut self) -> Result<f64, ActuatorError> {
        self.state().map(|s| s.position_rad)
    }

    /// Commands the joint to `rad` (clamped to the soft [`limits`](Self::limits); a
    /// non-finite target is refused and nothing is sent).
    fn command_position(&mut self, rad: f64) -> Result<Commanded, ActuatorError>;

    /// The joint's soft limits.
    fn limits(&self) -> JointLimits;

    /// Brings the joint to `state` through [`SafeState::apply`], the one safe stop of
    /// the operations, the robot and the front ends (what each state means per family is
    /// in [`ops::safe`](crate::ops::safe); a wCK break is the bus-wide break).
    fn apply_safe(&mut self, state: SafeState) -> Result<(), ActuatorError>;

    /// Safe state "relax": torque off (wCK passive, WHJ drive disabled):
    /// [`SafeState::Passive`].
    fn relax(&mut self) -> Result<(), ActuatorError> {
        self.apply_safe(SafeState::Passive)
    }

    /// Safe state "hold": stay where the joint is now, under power: [`SafeState::Hold`].
    fn hold(&mut self) -> Result<(), ActuatorError> {
        self.apply_safe(SafeState::Hold)
    }
}

// ----- wCK -----------------------------------------------------------------------------

/// Converts between wCK position steps (0..=254) and joint angles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WckScale {
    /// The step taken as device angle 0 (default [`WCK_DEFAULT_CENTRE`]).
    pub centre: u8,
    /// Offset and direction.
    pub map: JointMap,
}

impl WckScale {
    /// The joint angle (rad) of position step `position`.
    pub fn to_rad(self, position: Position) -> f64 {
        let steps = f64::from(position.get()) - f64::from(self.centre);
        self.map
            .to_joint((steps * WCK_DEGREES_PER_STEP).to_radians())
    }

    /// The nearest position step to joint angle `rad`, if it lies within 0..=254
    /// (half a step of slack at either end).
    pub fn to_position(self, rad: f64) -> Option<Position> {
        let device_deg = self.map.to_device(rad).to_degrees();
        let steps = (device_deg / WCK_DEGREES_PER_STEP + f64::from(self.centre)).round();
        if !(0.0..=254.0).contains(&steps) {
            return None;
        }
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // 0..=254 checked
        Position::new(steps as u8).ok()
    }

    /// The step for joint angle `rad` within `limits`: the nearest step, or where that
    /// lies just past a limit, its neighbour inside (`None` outside 0..=254).
    pub fn position_within(self, rad: f64, limits: &JointLimits) -> Option<Position> {
        let nearest = self.to_position(rad)?;
        let inside = |p: Position| {
            let r = self.to_rad(p);
            r >= limits.min_rad - 1e-12 && r <= limits.max_rad + 1e-12
        };
        if inside(nearest) {
            return Some(nearest);
        }
        let raw = nearest.get();
        [raw.checked_sub(1), raw.checked_add(1)]
            .into_iter()
            .flatten()
            .filter_map(|r| Position::new(r).ok())
            .filter(|&p| inside(p))
            .min_by(|&a, &b| {
                (self.to_rad(a) - rad)
                    .abs()
                    .total_cmp(&(self.to_rad(b) - rad).abs())
            })
            .or(Some(nearest))
    }

    /// The device-range error for joint angle `rad`.
    pub(crate) fn range_error(self, joint: &str, rad: f64) -> ActuatorError {
        ActuatorError::OutOfDeviceRange {
            joint: joint.to_owned(),
            value_rad: rad,
            device_deg: self.map.to_device(rad).to_degrees()
                + f64::from(self.centre) * WCK_DEGREES_PER_STEP,
            min_deg: 0.0,
            max_deg: 254.0 * WCK_DEGREES_PER_STEP,
        }
    }
}

/// A wCK servo as an [`Actuator`]: 8-bit positions (269°/255 a step, zero at
/// [`WckScale::centre`]), moved with a position move at a fixed torque level to the step
/// nearest the target within the soft limits ([`WckScale::position_within`]).
#[derive(Debug)]
pub struct WckActuator<'a, L> {
    name: String,
    servo: Servo<'a, L>,
    scale: WckScale,
    limits: JointLimits,
    torque: TorqueLevel,
}

impl<'a, L: ByteLink> WckActuator<'a, L> {
    /// Wraps `servo`; moves use `torque` (0 = maximum .. 4 = minimum).
    pub fn new(
        name: impl Into<String>,
        servo: Servo<'a, L>,
        scale: WckScale,
        limits: JointLimits,
        torque: TorqueLevel,
    ) -> Self {
        Self {
            name: name.into(),
            servo,
            scale,
            limits,
            torque,
        }
    }

    fn wck(&self, source: WckError) -> ActuatorError {
        ActuatorError::Wck {
            joint: self.name.clone(),
            source: Box::new(source),
        }
    }
}

impl<L: ByteLink> Actuator for WckActuator<'_, L> {
    fn name(&self) -> &str {
        &self.name
    }

    fn state(&mut self) -> Result<ActuatorState, ActuatorError> {
        let status = self.servo.status().map_err(|e| self.wck(e))?;
        Ok(ActuatorState {
            position_rad: self.scale.to_rad(status.position),
            velocity_rad_s: None,
            current_a: None,
        })
    }

    fn command_position(&mut self, rad: f64) -> Result<Commanded, ActuatorError> {
        if !rad.is_finite() {
            return Err(ActuatorError::NotFinite {
                joint: self.name.clone(),
                value: rad,
            });
        }
        let (target, clamped) = self.limits.clamp(rad);
        let position = self
            .scale
            .position_within(target, &self.limits)
            .ok_or_else(|| self.scale.range_error(&self.name, target))?;
        self.servo
            .move_to(self.torque, position)
            .map_err(|e| self.wck(e))?;
        Ok(Commanded {
            sent_rad: self.scale.to_rad(position),
            clamped,
        })
    }

    fn limits(&self) -> JointLimits {
        self.limits
    }

    fn apply_safe(&mut self, state: SafeState) -> Result<(), ActuatorError> {
        let ids = [self.servo.id()];
        let failed = state.apply(&mut WckServos {
            bus: self.servo.bus(),
            ids: &ids,
            torque: self.torque,
        });
        safe_result(&self.name, state, failed)
    }
}

// ----- WHJ -----------------------------------------------------------------------------

/// The joint angle (rad) of a WHJ position.
pub fn whj_to_rad(map: JointMap, position: WhjPosition) -> f64 {
    map.to_joint(position.degrees().to_radians())
}

/// The WHJ position (0.0001° counts) of joint angle `rad`.
pub fn whj_position(joint: &str, map: JointMap, rad: f64) -> Result<WhjPosition, ActuatorError> {
    let device_deg = map.to_device(rad).to_degrees();
    WhjPosition::from_degrees(device_deg).map_err(|_| ActuatorError::OutOfDeviceRange {
        joint: joint.to_owned(),
        value_rad: rad,
        device_deg,
        min_deg: WhjPosition(i32::MIN).degrees(),
        max_deg: WhjPosition(i32::MAX).degrees(),
    })
}

/// A WHJ joint as an [`Actuator`], in position mode: each command is one position servo
/// frame (the joint refuses steps over 10°: keep commands close to the actual angle, or
/// let [`Robot`](crate::robot::Robot) limit their speed).
#[derive(Debug)]
pub struct WhjActuator<'a> {
    name: String,
    joint: Joint<'a>,
    map: JointMap,
    limits: JointLimits,
    scale: CurrentScale,
}

impl<'a> WhjActuator<'a> {
    /// Wraps `joint` (connected); reads its identity for the current scale, switches it to
    /// position mode and enables it.
    pub fn new(
        name: impl Into<String>,
        joint: Joint<'a>,
        map: JointMap,
        limits: JointLimits,
    ) -> Result<Self, ActuatorError> {
        let name = name.into();
        let prepare = || -> Result<CurrentScale, WhjError> {
            let scale = joint.identity()?.current_scale();
            joint.set_mode(WorkMode::Position)?;
            joint.enable()?;
            Ok(scale)
        };
        let scale = prepare().map_err(|source| ActuatorError::Whj {
            joint: name.clone(),
            source: Box::new(source),
        })?;
        Ok(Self::prepared(name, joint, map, limits, scale))
    }

    /// Wraps `joint` as it is, sending nothing: for a joint already identified (its
    /// current `scale` known) and prepared, as a [`Robot`](crate::robot::Robot)'s are.
    pub fn prepared(
        name: impl Into<String>,
        joint: Joint<'a>,
        map: JointMap,
        limits: JointLimits,
        scale: CurrentScale,
    ) -> Self {
        Self {
            name: name.into(),
            joint,
            map,
            limits,
            scale,
        }
    }

    /// Makes sure the drive is on for position commands: a joint whose drive is off is
    /// switched to position mode and enabled (one that is on is left as it is).
    pub fn ensure_enabled(&self) -> Result<(), ActuatorError> {
        let prepare = || -> Result<(), WhjError> {
            if !self.joint.is_enabled()? {
                self.joint.set_mode(WorkMode::Position)?;
                self.joint.enable()?;
            }
            Ok(())
        };
        prepare().map_err(|e| self.whj(e))
    }

    fn whj(&self, source: WhjError) -> ActuatorError {
        ActuatorError::Whj {
            joint: self.name.clone(),
            source: Box::new(source),
        }
    }
}

impl Actuator for WhjActuator<'_> {
    fn name(&self) -> &str {
        &self.name
    }

    fn position(&mut self) -> Result<f64, ActuatorError> {
        let status = self.joint.status().map_err(|e| self.whj(e))?;
        Ok(whj_to_rad(self.map, status.position))
    }

    fn state(&mut self) -> Result<ActuatorState, ActuatorError> {
        let status = self.joint.status().map_err(|e| self.whj(e))?;
        let speed = self.joint.speed().map_err(|e| self.whj(e))?;
        Ok(ActuatorState {
            position_rad: whj_to_rad(self.map, status.position),
            velocity_rad_s: Some(self.map.speed_to_joint(rpm_to_rad_s(speed.rpm()))),
            current_a: status
                .current
                .map(|c| c.milliamps(self.scale) as f64 / 1000.0),
        })
    }

    fn command_position(&mut self, rad: f64) -> Result<Commanded, ActuatorError> {
        if !rad.is_finite() {
            return Err(ActuatorError::NotFinite {
                joint: self.name.clone(),
                value: rad,
            });
        }
        let (target, clamped) = self.limits.clamp(rad);
        let position = whj_position(&self.name, self.map, target)?;
        self.joint
            .command_position(position)
            .map_err(|e| self.whj(e))?;
        Ok(Commanded {
            sent_rad: whj_to_rad(self.map, position),
            clamped,
        })
    }

    fn limits(&self) -> JointLimits {
        self.limits
    }

    fn apply_safe(&mut self, state: SafeState) -> Result<(), ActuatorError> {
        let failed = state.apply(&mut WhjJoints {
            joints: core::slice::from_ref(&self.joint),
            servo: ServoLoop::Position,
        });
        safe_result(&self.name, state, failed)
    }
}

/// rad/s of a speed in RPM.
pub(crate) fn rpm_to_rad_s(rpm: f64) -> f64 {
    rpm * core::f64::consts::TAU / 60.0
}
