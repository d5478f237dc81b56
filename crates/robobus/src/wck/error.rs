//! Errors of the wCK client, with the facts in them.

use core::fmt;
use core::time::Duration;

use robobus_link::LinkError;
use robobus_wck::{BaudRate, RangeError, ReplyError, Target};

use crate::error::{ErrorKind, link_error_kind};

/// Bytes as hex, like the manual prints packets: `07 D0` (`none` when empty).
#[derive(Debug, Clone, Copy)]
pub struct Hex<'a>(pub &'a [u8]);

impl fmt::Display for Hex<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.is_empty() {
            return f.write_str("none");
        }
        for (i, b) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str(" ")?;
            }
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

/// Why a wCK operation failed.
///
/// Every variant names the device (the serial port path, or the name given with
/// [`WckBus::with_device_name`](super::WckBus::with_device_name)), the addressed module
/// and the manual's name of the command.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WckError {
    /// The module did not answer completely before the reply deadline (the modelled
    /// response time plus the configured margin), on every attempt.
    #[error(
        "{device}: {target} did not answer {command} at {baud}: {} of {expected} reply bytes \
         ({}) within {waited:?}, after {attempts} attempt(s); is it powered and connected, \
         and is it at this ID and baud rate?",
        .received.len(), Hex(.received)
    )]
    Timeout {
        /// The device (port path or bus name).
        device: String,
        /// Which module(s) the command addressed.
        target: Target,
        /// The command.
        command: &'static str,
        /// The bus baud rate.
        baud: BaudRate,
        /// How long the last attempt waited for its reply.
        waited: Duration,
        /// The bytes that did arrive on the last attempt.
        received: Vec<u8>,
        /// Reply bytes expected.
        expected: usize,
        /// Attempts made.
        attempts: u32,
    },
    /// The reply failed its plausibility check (out of range, wrong echo, repeated bytes
    /// that differ) on every attempt. The value is never returned.
    #[error(
        "{device}: implausible reply {} from {target} to {command} after {attempts} attempt(s): {reason}",
        Hex(.bytes)
    )]
    BadReply {
        /// The device.
        device: String,
        /// The addressed module(s).
        target: Target,
        /// The command.
        command: &'static str,
        /// The reply bytes of the last attempt.
        bytes: Vec<u8>,
        /// What was wrong with them.
        #[source]
        reason: ReplyError,
        /// Attempts made.
        attempts: u32,
    },
    /// A confirmed read ([`WckConfig::confirm_reads`](super::WckConfig::confirm_reads))
    /// never got enough equal replies in a row.
    #[error(
        "{device}: {target} never gave enough equal replies to {command} in {attempts} \
         attempts (last two: {} and {})",
        Hex(.previous), Hex(.last)
    )]
    Unconfirmed {
        /// The device.
        device: String,
        /// The addressed module.
        target: Target,
        /// The command.
        command: &'static str,
        /// The reply before the last one.
        previous: Vec<u8>,
        /// The last reply.
        last: Vec<u8>,
        /// Attempts made.
        attempts: u32,
    },
    /// The bytes received cannot be the command's one reply, on every attempt: some
    /// arrived before any module can have answered (stray bytes), or more than one
    /// reply's worth arrived (more than one answer; two different replies are named).
    /// wCK replies carry no ID, so such bytes are never credited: no value is returned.
    #[error(
        "{device}: the bytes received from {target} for {command} cannot be its one reply \
         ({detail}), after {attempts} attempt(s)"
    )]
    Unattributable {
        /// The device.
        device: String,
        /// The addressed module(s).
        target: Target,
        /// The command.
        command: &'static str,
        /// The bytes of the last attempt (at most 16).
        bytes: Vec<u8>,
        /// What arrived and why it cannot be the reply.
        detail: String,
        /// Attempts made.
        attempts: u32,
    },
    /// A setting was sent, but reading it back shows another value (or the module still
    /// answers at its old ID / baud rate): the change did not take.
    #[error("{device}: {command} to {target} did not take: expected {expected}, found {found}")]
    NotApplied {
        /// The device.
        device: String,
        /// The addressed module.
        target: Target,
        /// The command.
        command: &'static str,
        /// What should have been read back.
        expected: String,
        /// What was read back.
        found: String,
    },
    /// An ID or baud change could not be confirmed: the module answers neither with its
    /// old nor with its new setting.
    #[error("{device}: {command} to {target} could not be verified: {detail}")]
    NotVerified {
        /// The device.
        device: String,
        /// The addressed module (at its old ID).
        target: Target,
        /// The command.
        command: &'static str,
        /// What was tried and what happened.
        detail: String,
    },
    /// An ID change was refused because a module already answers at the new ID (two
    /// modules with one ID collide on the bus).
    #[error("{device}: refusing to give {target} ID {new_id}: a module already answers at that ID")]
    IdInUse {
        /// The device.
        device: String,
        /// The module that was to be renamed.
        target: Target,
        /// The requested ID.
        new_id: u8,
    },
    /// The byte link failed (port gone, I/O error). Never retried.
    #[error("{device}: link error during {command}: {source}")]
    Link {
        /// The device.
        device: String,
        /// The command being sent, or the bus operation.
        command: &'static str,
        /// The link's error.
        #[source]
        source: LinkError,
    },
    /// An argument is out of range; nothing was sent.
    #[error("{command}: {source}; nothing was sent")]
    Value {
        /// The command.
        command: &'static str,
        /// The range violation.
        #[source]
        source: RangeError,
    },
}

impl WckError {
    /// What kind of failure this is.
    pub fn kind(&self) -> ErrorKind {
        match self {
            Self::Timeout { .. } => ErrorKind::NoDevice,
            Self::BadReply { .. }
            | Self::Unconfirmed { .. }
            | Self::Unattributable { .. }
            | Self::NotApplied { .. }
            | Self::NotVerified { .. } => ErrorKind::Device,
            Self::IdInUse { .. } => ErrorKind::Refused,
            Self::Link { source, .. } => link_error_kind(source),
            Self::Value { .. } => ErrorKind::BadInput,
        }
    }
}

impl WckError {
    /// Whether this is a [`WckError::Timeout`].
    pub const fn is_timeout(&self) -> bool {
        matches!(self, Self::Timeout { .. })
    }

    /// The device the error happened on, if it names one.
    pub fn device(&self) -> Option<&str> {
        match self {
            Self::Timeout { device, .. }
            | Self::BadReply { device, .. }
            | Self::Unconfirmed { device, .. }
            | Self::Unattributable { device, .. }
            | Self::NotApplied { device, .. }
            | Self::NotVerified { device, .. }
            | Self::IdInUse { device, .. }
            | Self::Link { device, .. } => Some(device),
            Self::Value { .. } => None,
        }
    }
}
