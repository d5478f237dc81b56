//! Simulated WHJ joints on a wire-timed CAN FD bus (issue 6).
//!
//! - [`SimJoint`]: one joint's firmware (memory table, flash, bootloader, work modes,
//!   protection) over the device-side decoder of `robobus-whj`, driving a physics model
//!   of motor, gearbox, load, heat and supply ([`WhjModel`] parameters from §9 of
//!   the WHJ joint protocol reference).
//! - [`WhjBus`]: the wire: arbitration by CAN ID, exact frame durations, processing
//!   delays; virtual clock in tests, wall clock behind an endpoint.
//! - [`WhjSimLink`]: the bus as an in-process frame link on a virtual clock (no thread).
//! - [`serve`]: the same bus on a real frame link (python-can UDP bus, `SocketCAN`) on the
//!   wall clock; [`Served`] runs it on a thread of its own, [`spawn`] on an in-memory bus.
//! - [`adapter`]: emulated serial-line CAN FD adapters (slcan) with the joints behind
//!   them, served to a host program on a byte stream or in process on the virtual clock.
//! - Options for every rule the vendor documents disagree on: [`JointConfig`]; defaults
//!   follow the "Sim default" column of §10 of the WHJ joint protocol reference.
//!
//! ```
//! use core::time::Duration;
//! use robobus_sim::whj::{WhjBus, WhjModel};
//! use robobus_whj::CanFrame;
//!
//! // Three WHJ30 joints (IDs 1..=3) on the virtual clock.
//! let mut bus = WhjBus::chain(1..=3, WhjModel::Whj30, 42);
//! // Leave the bootloader: the usage demo's "required operation".
//! let iap = CanFrame::new_fd(CanFrame::standard_id(0x001)?, &[0x02, 0x49, 0x00])?;
//! let replies = bus.request(iap);
//! assert_eq!(replies[0].frame.raw_id(), 0x101);
//! assert_eq!(replies[0].frame.data(), &[0x02, 0x49, 0x01]);
//!
//! // Position servo to 5°: the 16-byte feedback shows the position before the move ...
//! let cmd = CanFrame::new_fd(CanFrame::standard_id(0x201)?, &50_000i32.to_le_bytes())?;
//! let fb = bus.request(cmd);
//! assert_eq!((fb[0].frame.raw_id(), fb[0].frame.len()), (0x501, 16));
//! assert_eq!(&fb[0].frame.data()[8..12], &[0, 0, 0, 0]);
//! // ... and one simulated second later the joint is there.
//! bus.advance(Duration::from_secs(1));
//! let state = bus.joint(1).map(|j| j.state()).ok_or("joint 1")?;
//! assert!((state.position_deg - 5.0).abs() < 1e-3);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod adapter;
mod bus;
mod config;
mod end_board;
mod endpoint;
mod joint;
mod link;
mod model;
mod physics;

pub use bus::{BusStats, Delivered, Node, WhjBus, WireFrame};
pub use config::{
    BootConfig, BroadcastReadReply, JointConfig, Load, SpeedLimitUnit, StepConfig, WatchdogConfig,
};
pub use end_board::SimEndBoard;
pub use endpoint::{ServeStats, Served, serve, serve_observed, serve_precise, serve_with, spawn};
pub use joint::{JointState, Obstacle, Phase, Reply, Sample, SimJoint};
pub use link::{WhjSimHandle, WhjSimLink};
pub use model::{ModelParams, UnknownModel, WhjModel};
