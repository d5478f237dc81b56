//! robobus: drive RoboBuilder wCK servos and RealMan WHJ joints from a host computer.
//!
//! The same API works on real hardware and on the robobus simulators; the link is the
//! only difference.

// Errors carry their facts by value (names, bytes, values): they are large, and they are
// the cold path. Boxing each would cost every caller a pattern change for no gain.
#![allow(clippy::result_large_err)]

pub mod actuator;
#[cfg(feature = "sim")]
pub mod demo;
pub mod error;
pub mod ops;
pub mod robot;
pub mod wck;
pub mod whj;

pub use actuator::{Actuator, ActuatorError, ActuatorState, JointLimits};
pub use error::ErrorKind;
pub use robot::{Robot, RobotConfig, RobotError};
