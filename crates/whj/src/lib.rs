//! RealMan WHJ joint CAN FD protocol (work in progress: see issue 3).
#![cfg_attr(not(feature = "std"), no_std)]

pub mod frame;

pub use frame::{CanFrame, FrameError};
