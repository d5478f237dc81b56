//! robobus: drive RoboBuilder wCK servos and RealMan WHJ joints from a host computer.
//!
//! The same API works on real hardware and on the robobus simulators; the link is the
//! only difference.
//!
//! Front ends (the `robobus` command, later a web server or Python bindings) call the
//! operations of [`ops`]: typed arguments, a plan, a typed report, a stop token and a
//! progress callback. Playing a keyframe motion on the simulated wCK bus with progress,
//! stopped halfway (the servos then hold where they are):
//!
//! ```
//! use std::time::Duration;
//! use robobus::ops::wck::{Motion, play};
//! use robobus::ops::{Control, Progress, SafeState, StopToken};
//! use robobus::wck::WckBus;
//! use robobus_sim::wck::{Bus, BusConfig, Model, SimLink};
//! use robobus_wck::BaudRate;
//!
//! let (link, _sim) = SimLink::new(Bus::with_servos(BusConfig::default(), Model::W1108, [0, 1]));
//! std::thread::sleep(Duration::from_millis(70)); // the modules power up
//! let mut bus = WckBus::new(link, BaudRate::B115200)?;
//! let motion = Motion::parse("pose 0 127 127\npose 1000 200 60\n")?;
//!
//! let stop = StopToken::new(); // a Ctrl-C handler or another thread may set it
//! let stopper = stop.clone();
//! let mut last_ms = 0;
//! let mut on_progress = |p: &Progress| {
//!     last_ms = p.done; // ms into the motion
//!     if p.done >= 500 {
//!         stopper.stop();
//!     }
//! };
//! let mut control = Control::new(&stop).with_progress(&mut on_progress);
//! let err = play(&mut bus, &motion, 50.0, SafeState::Hold, &mut control).unwrap_err();
//! drop(control);
//! assert_eq!(err.kind(), robobus::ErrorKind::Interrupted);
//! assert!((500..1000).contains(&last_ms));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

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
