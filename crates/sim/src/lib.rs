//! robobus simulators: wCK servos on a wire-timed multi-drop UART bus ([`wck`]) and WHJ
//! joints on a wire-timed CAN FD bus ([`whj`]).
//!
//! Time in every simulator is a [`core::time::Duration`] since the simulation started.
//! In tests the simulators run on a virtual clock (deterministic, faster than real time);
//! behind an endpoint they follow the wall clock.

pub mod faults;
pub mod lateness;
pub mod wck;
pub mod whj;

pub use lateness::{Lateness, LatenessSummary};
pub use robobus_link::WaitMode;
