//! robobus: drive RoboBuilder wCK servos and RealMan WHJ joints from a host computer.
//!
//! The same API works on real hardware and on the robobus simulators; the link is the
//! only difference.

pub mod actuator;
pub mod error;
pub mod ops;
pub mod robot;
pub mod wck;
pub mod whj;

pub use actuator::{Actuator, ActuatorError, ActuatorState, JointLimits};
pub use error::ErrorKind;
pub use robot::{Robot, RobotConfig, RobotError};
