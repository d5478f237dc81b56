//! robobus: drive RoboBuilder wCK servos and RealMan WHJ joints from a host computer.
//!
//! The same API works on real hardware and on the robobus simulators; the link is the
//! only difference.
//!
//! # Layers
//!
//! The rows run from the lowest layer up, and a module uses only the layers of the rows
//! above its own (a test, `tests/layers.rs`, finds any import circle and names its lines):
//!
//! | layer | where | what |
//! |---|---|---|
//! | protocol cores | crates `robobus-wck`, `robobus-whj` | packets and frames, sans-IO, `no_std` |
//! | links | crate `robobus-link` | byte links (serial, TCP, pty), CAN FD frame links, capture and replay |
//! | error kinds | [`error`] | [`ErrorKind`]: the one classification every front end maps (exit code, exception, HTTP status) |
//! | clients | [`wck`], [`whj`], [`motion`], [`cdr`] | a bus, its transactions and its device handles ([`wck::WckBus`] / [`wck::Servo`], [`whj::JointBus`] / [`whj::Joint`]); the one motion limiter and tracking measure; ROS 2's CDR |
//! | operations | [`ops`] | one library call per device operation: typed arguments, a plan, a typed report, a stop token, progress, the one safe stop |
//! | actuators, robots | [`actuator`], [`robot`] | a joint in SI units over either family; a robot file's named joints, limits and watchdog |
//! | station | [`station`] | the open buses a long-lived front end holds, their handles ([`station::handles`]), the checked cyclic loop, sampling, one bounded jog step ([`station::jog`]) and a robot's followed joint targets ([`station::follow`]) |
//! | demo | `demo` (feature `sim`) | the built-in simulated robot driven as a program drives hardware |
//! | catalogue | [`catalogue`] | one request type for every operation (one registered file each), its plan and its run on a station, typed reports, the telemetry stream |
//! | front-end kit | [`frontend`] | one request parser, admission (read-only, arming, the write-rate limit), the plan view, the guard, the live simulator |
//! | recordings | [`record`] | sample tables and their formats (CSV, JSON lines, MCAP) |
//!
//! The front ends (the `robobus` command, the web studio, the Python package and the Zenoh
//! bridge, each a crate of its own) call the catalogue: each turns its input into a
//! [`catalogue::Request`], admits it through [`frontend`], runs it on a
//! [`station::Station`] and renders the typed report; none holds device logic of its own.
//!
//! A program can call the operations of [`ops`] directly: typed arguments, a plan, a typed
//! report, a stop token and a progress callback. Playing a keyframe motion on the simulated
//! wCK bus with progress, stopped halfway (the servos then hold where they are):
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
//!
//! A smooth WHJ move from plain Rust, with its plan, a stop token and progress:
//!
//! ```
//! use robobus::ops::{Control, Progress, SafeState, StopToken};
//! use robobus::ops::whj::{self as ops, MoveArgs};
//! use robobus::whj::{JointBus, JointBusConfig};
//! use robobus_sim::whj::{WhjBus, WhjModel};
//! use robobus_whj::{JointId, WorkMode};
//!
//! // A simulated joint on an in-memory CAN FD bus (a SocketCAN link is the same call).
//! let (sim, wire) = robobus_sim::whj::spawn(WhjBus::chain(1..=1, WhjModel::Whj30, 7))?;
//! let bus = JointBus::open_with(wire.endpoint(), JointBusConfig::simulated())?;
//! let joint = bus.joint(JointId::new(1)?)?;
//! joint.set_mode(WorkMode::Position)?;
//! joint.enable()?;
//!
//! let args = MoveArgs {
//!     joint: JointId::new(1)?,
//!     target_deg: 2.0,
//!     max_speed_deg_s: 30.0,
//!     rate_hz: 100.0,
//!     step_limit_deg: bus.config().step_limit_deg,
//! };
//! // What a dry run shows: the exact frames, planned from an assumed start of 0 deg.
//! let plan = ops::plan_move(&args, 0.0, true)?;
//! // The real run: another thread (a signal handler, a web request) may call stop.stop();
//! // the joint is then left holding where it is and the call returns Interrupted.
//! let stop = StopToken::new();
//! let mut frames_sent = 0;
//! let mut on_progress = |p: &Progress| frames_sent = p.done;
//! let mut control = Control::new(&stop).with_progress(&mut on_progress);
//! let report = ops::run_move(&joint, &args, &mut control, SafeState::Hold)?;
//! drop(control);
//! assert_eq!(report.frames, plan.frames.len() as u64);
//! assert_eq!(frames_sent, report.frames);
//! assert!((report.position_deg - 2.0).abs() <= 0.1);
//! println!("{}", serde_json::to_string(&report)?); // the CLI's --json row
//!
//! drop(joint);
//! drop(bus);
//! sim.stop()?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

// Errors carry their facts by value (names, bytes, values): they are large, and they are
// the cold path. Boxing each would cost every caller a pattern change for no gain.
#![allow(clippy::result_large_err)]

pub mod actuator;
pub mod catalogue;
pub mod cdr;
#[cfg(feature = "sim")]
pub mod demo;
pub mod error;
pub mod frontend;
pub mod motion;
pub mod ops;
pub mod record;
pub mod robot;
pub mod station;
pub mod wck;
pub mod whj;

pub use actuator::{Actuator, ActuatorError, ActuatorState, JointLimits};
pub use error::ErrorKind;
pub use robobus_link::wait::{WaitMode, WaitModeError};
pub use robot::{Robot, RobotConfig, RobotError};
