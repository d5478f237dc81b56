//! WHJ joints (RealMan, CAN FD): a [`JointBus`] owns the frame link and a sans-IO client
//! session, [`Joint`] handles borrow it.
//!
//! - [`JointBus::open`] takes any [`FrameLink`](robobus_link::FrameLink): `SocketCAN`
//!   on real hardware, the python-can compatible UDP bus, or an in-memory bus with the
//!   simulator on the other end: the code path is the same. The session matches
//!   replies to requests by CAN ID and function, applies per-request timeouts and the
//!   documented settle times, surfaces bus errors and waits for recovery, and keeps
//!   [`BusTelemetry`] (the small command / telemetry interface that displays and bridges
//!   attach to).
//! - [`JointBus::joint`] connects: IAP release (`IAP_FLAG := 0`, the vendor's required
//!   operation), then identify (model, firmware, unique ID). A silent joint gives a
//!   [`WhjError::Silent`] that names IAP, ID and bit rate as suspects.
//! - [`Joint`]: enable / disable, modes, zero, clear error, save to flash (refused while
//!   enabled), limits, register read / write by name with units, position / speed /
//!   current servo commands with feedback, status, and [`Joint::move_to`] for moves of
//!   any size along a smooth [`Profile`].
//! - [`JointBus::cyclic`]: a fixed-rate servo loop for N joints, point-to-point or with
//!   the broadcast protocol, with deadline-miss and latency statistics.
//! - Request / reply work runs on the caller's thread (no hand-off to a bus thread);
//!   [`JointBus::request_many`] and [`JointBus::joints`] pipeline requests to many joints
//!   (send all, then collect). All time comes from the link's clock, so on
//!   `robobus_sim::whj::WhjSimLink` the client runs on the simulator's virtual clock.
//! - Retries only for reads and idempotent operations; a reply that does not answer the
//!   request is never returned as a value. Errors ([`WhjError`]) name the joint, the
//!   register and the reply that was expected.
//!
//! ```
//! use std::sync::{Arc, atomic::{AtomicBool, Ordering}};
//! use robobus::whj::JointBus;
//! use robobus_link::MemoryBus;
//! use robobus_sim::whj::{WhjBus, WhjModel};
//! use robobus_whj::{JointId, WorkMode, units::Position};
//!
//! // The simulator serves joints 1..=2 on an in-memory CAN FD bus, on its own thread.
//! let wire = MemoryBus::new();
//! let mut sim_end = wire.endpoint();
//! let stop = Arc::new(AtomicBool::new(false));
//! let sim_stop = Arc::clone(&stop);
//! let sim = std::thread::spawn(move || {
//!     let mut sim = WhjBus::chain(1..=2, WhjModel::Whj30, 7);
//!     robobus_sim::whj::serve(&mut sim, &mut sim_end, &sim_stop)
//! });
//!
//! let bus = JointBus::open(wire.endpoint())?;
//! let j1 = bus.joint(JointId::new(1)?)?; // IAP release + identify
//! assert_eq!(j1.identity()?.model.name(), "WHJ30");
//! j1.set_mode(WorkMode::Position)?;
//! j1.enable()?;
//! let fb = j1.command_position(Position::from_degrees(2.0)?)?;
//! assert!(fb.is_enabled());
//! assert_eq!(j1.read_register("TAG_POSITION")?.raw, 20_000);
//! j1.disable()?;
//!
//! drop(bus);
//! stop.store(true, Ordering::Relaxed);
//! sim.join().unwrap()?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod bus;
mod cyclic;
mod error;
mod identity;
pub(crate) mod joint;
pub(crate) mod session;
mod trajectory;

pub use bus::{JointBus, MAX_PIPELINED};
pub use cyclic::{Cyclic, OwnedCyclic};
pub use error::WhjError;
pub use identity::Identity;
pub use joint::{Joint, OwnedJoint, RegisterValue};
pub use session::cyclic::{
    CycleReport, CyclicConfig, CyclicStats, Feedback, Percentiles, Protocol, ServoMode,
};
pub use session::{BusHealth, BusState, BusTelemetry, JointBusConfig, JointTelemetry};
pub use trajectory::{MotionLimits, Profile};
