//! RealMan WHJ joint CAN FD protocol: sans-IO, `no_std`, allocation-free.
//!
//! Both sides of the wire are covered: a host encodes [`Request`]s and decodes
//! [`Reply`]s; a simulated joint decodes [`Request::from_frame`] (or learns exactly why a
//! frame is [`Malformed`] and which `CMD_ERR` to answer) and encodes its [`Reply`]. The
//! register table is data ([`REGISTERS`], with the firmware gates [`FIRMWARE_GATES`]), the
//! products are data ([`PRODUCTS`]: code, ratio, peak speed, current scale, features), units are named conversions ([`units`]),
//! errors are a named bit set ([`ErrorCode`]), [`describe`] puts requests and replies in
//! words (their `Display`, their values by name in their units), and [`timing`] gives each
//! frame's exact duration on the wire. Sources: the vendor's CAN FD usage demo and the WHJ joint protocol reference
//! (section numbers in the docs refer to the latter).
//!
//! # Conventions where the documents disagree (§10)
//!
//! * Register writes: [`WriteData`] keeps the 1-, 2- and 4-byte forms (C5). The checked
//!   constructors [`Request::write`] / [`Request::write_i32`] send the spec's 2 bytes for a
//!   single register and 4 bytes for a 32-bit pair; the flag helpers
//!   ([`Request::enable`], [`Request::set_mode`], [`Request::start_application`], ...)
//!   send the vendor examples' 1-byte form, byte for byte.
//! * `CMD_ERR` (C12) is recognised by its 2-byte length; its command byte is kept, and
//!   [`reply::CMD_ERR`] = 0xFF is sent by default.
//! * Actual speed is 0.02 RPM ([`units::ACTUAL_SPEED_RPM_PER_COUNT`], C1); current is
//!   1 or 2 mA per count by model ([`units::Model::current_scale`], C2).
//! * Status feedback is accepted with 16 or 12 bytes (C6); read replies may carry padding
//!   words ([`Words::truncated`]).
//! * The broadcast 0x2F feed-forward bits are kept raw ([`FeedForwardBits`], C17); the
//!   0x0F read reply is accepted with or without GRIP's length prefix (C19).
//! * CAN ID 0x00F is joint 15's register command unless the frame is 64 bytes long, in
//!   which case it is the broadcast register frame ([`id`]).
//!
//! # Example
//!
//! ```
//! use robobus_whj::{JointId, Reply, Request, WorkMode, units::Position, timing};
//!
//! let j1 = JointId::new(1)?;
//! // Host: switch to position mode, then command 30°.
//! let mode = Request::set_mode(j1, WorkMode::Position).to_frame();
//! assert_eq!((mode.raw_id(), mode.data()), (0x001, &[0x02, 0x30, 0x03][..]));
//! let cmd = Request::PositionServo { joint: j1, target: Position::from_degrees(30.0)? };
//! let frame = cmd.to_frame();
//! assert_eq!(frame.data(), &[0xE0, 0x93, 0x04, 0x00]);
//!
//! // Joint side: decode what arrived.
//! assert_eq!(Request::from_frame(&frame)?, cmd);
//!
//! // Host: decode the joint's servo feedback (usage demo, "position mode control").
//! let fb = robobus_whj::CanFrame::new_fd(
//!     robobus_whj::CanFrame::standard_id(0x501)?,
//!     &[0xC0, 0xFF, 0xFF, 0xFF, 0, 0, 0, 0, 0x40, 0x0D, 0x03, 0x00, 0x01, 0x00, 0x00, 0x00],
//! )?;
//! let Reply::ServoFeedback { joint, feedback } = Reply::from_frame(&fb)? else { unreachable!() };
//! assert_eq!(joint, j1);
//! assert_eq!(feedback.position.degrees(), 20.0);
//! assert_eq!(feedback.current.raw(), -64);
//! assert!(feedback.is_enabled() && feedback.error.is_empty());
//!
//! // Wire time of the command at 1 / 5 Mbit/s.
//! let t = timing::frame_duration(&frame, timing::BitRates::WHJ);
//! assert!(t.as_nanos() >= 42_000 && t.as_nanos() <= 46_600);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![cfg_attr(not(feature = "std"), no_std)]
// Vendor and product names (RealMan, WeiHan) are not code identifiers.
#![allow(clippy::doc_markdown)]

pub mod broadcast;
pub mod describe;
pub mod error_code;
pub mod frame;
pub mod id;
pub mod models;
pub mod registers;
pub mod reply;
pub mod request;
pub mod timing;
pub mod units;

pub use broadcast::{
    BroadcastCurrent, BroadcastFeedback, BroadcastPosition, BroadcastRegister, BroadcastStatus,
    EndBoardOp, EndBoardReply, FeedForward, FeedForwardBits, FeedForwardLayout, PositionSlot,
    RegisterOp, RegisterSlot, ReplyMask,
};
pub use describe::{Described, Field, FieldName, Fields};
pub use error_code::{ErrorBitInfo, ErrorCode};
pub use frame::{CanFrame, FrameError};
pub use id::{Address, BroadcastFunction, Function, JointId, JointIdError};
pub use models::{PRODUCTS, ProductFacts};
pub use registers::{
    FIRMWARE_GATES, Feature, FirmwareGate, GateRefusal, REGISTERS, RegisterAddr, RegisterAddrError,
    RegisterInfo, WorkMode, gated_write_allowed,
};
pub use reply::{
    BroadcastRegisterReply, CmdError, JointStatus, Reply, ReplyError, ReplyErrorReason,
    ServoFeedback, Words, WriteStatus,
};
pub use request::{Malformed, MalformedReason, ReadRange, Request, RequestError, WriteData};

/// Build a CAN FD frame (BRS on) for an ID and payload that are valid by construction:
/// every caller passes an 11-bit ID and at most 64 bytes.
pub(crate) fn fd_frame(id: u16, data: &[u8]) -> CanFrame {
    let id = embedded_can::StandardId::new(id).unwrap_or(embedded_can::StandardId::ZERO);
    let data = data.get(..data.len().min(frame::MAX_FD_LEN)).unwrap_or(&[]);
    CanFrame::new_fd_padded(id, data).unwrap_or_else(|_| CanFrame::empty_fd(id))
}
