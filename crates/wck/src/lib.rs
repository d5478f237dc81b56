//! The wCK servo protocol (Robobuilder Co.): sans-IO, `no_std`, allocation-free.
//!
//! The source is the *wCK series User's Manual v1.07*: appendix A-1 (Communication
//! Protocol) for the packets, A-5 (Default Parameter Settings), A-6 (Protocol Table),
//! section 2-3 (Communication) for timing and section 3-11 (Self-running Motion) for motion
//! programs. Four checksums printed in A-1's examples are wrong; this crate uses the
//! formulas, and its tests say where the manual differs.
//!
//! - **Host side**: a typed [`Command`] (all 27 of A-1) encodes to a [`Packet`]
//!   ([`Command::encode`]); [`Command::decode_reply`] turns the 2 reply bytes into a typed
//!   [`Reply`], checking their plausibility (replies have no checksum).
//! - **Device side**: [`StreamDecoder`] turns the byte stream a module hears into commands,
//!   resynchronising on the `0xFF` header and reporting bad checksums, unknown codes,
//!   truncated packets and invalid fields as [`DecodeError`] values; [`Reply::to_bytes`]
//!   gives the bytes a module answers with.
//! - **Values**: every ranged quantity is a newtype whose constructor refuses out-of-range
//!   input with a [`RangeError`] naming the quantity, the value and the range.
//! - **In words**: a command's or reply's [`Display`](core::fmt::Display) form, and its
//!   values by name ([`Command::fields`], [`Reply::fields`]).
//! - **Motion programs**: [`program`] (instructions, programs, a text form).
//! - **Timing**: [`timing`] (wire time, turnaround, polling rates).
//!
//! Only [`Command::IdSet`] ever sends code `0x0C` (which renames a module) and only
//! [`Command::GainSet`] sends `0x09` (which overwrites the gains in EEPROM): there is no
//! raw-packet API to send them by mistake, unlike the manual's A-4 sample program.
//!
//! ```
//! use robobus_wck::{Command, Position, Reply, ServoId, StreamDecoder, TorqueLevel};
//!
//! // Host: move servo 3 to position 127 at full torque.
//! let command = Command::Move {
//!     id: ServoId::new(3)?,
//!     torque: TorqueLevel::new(0)?,
//!     position: Position::new(127)?,
//! };
//! let packet = command.encode();
//! assert_eq!(packet.as_bytes(), [0xFF, 0x03, 0x7F, 0x7C]);
//! assert_eq!((command.encoded_len(), command.reply_len()), (4, 2));
//!
//! // Device: the simulated servo decodes the bytes it hears...
//! let mut decoder = StreamDecoder::new();
//! let heard: Vec<_> = decoder.feed(&packet).collect();
//! assert_eq!(heard, [Ok(command)]);
//!
//! // ...and answers with its load and position.
//! let reply = Reply::Status { load: robobus_wck::Load::new(12)?, position: Position::new(90)? };
//! let bytes = reply.to_bytes();
//!
//! // Host: the reply, checked and typed.
//! assert_eq!(command.decode_reply(&bytes), Ok(reply));
//! // Out-of-range values never reach the encoder.
//! assert_eq!(Position::new(255).unwrap_err().to_string(), "position 255 is out of range 0..=254");
//! # Ok::<(), robobus_wck::RangeError>(())
//! ```
#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]

mod command;
mod decoder;
mod describe;
pub mod models;
pub mod program;
mod reply;
pub mod timing;
mod values;

pub use command::{
    Command, HEADER, MAX_PACKET_LEN, Packet, REPLY_LEN, SyncMove, Target, checksum_range, code,
    xor7,
};
pub use decoder::{DecodeError, DecoderStats, Feed, StreamDecoder, decode_packet};
pub use describe::Field;
pub use program::{Instruction, Program};
pub use reply::{Reply, ReplyError};
pub use values::{
    Accel, AngleError, BaudRate, Boundaries, DGain, DataByte, ExtServoId, IGain, IoBits, Load,
    MotionCount, OVERLOAD_TABLE, Overload, PGain, Position, Position10, RangeError, RepeatCount,
    Rotation, ServoId, Speed, TorqueLevel, ValueError, WheelSpeed,
};
