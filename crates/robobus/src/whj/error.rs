//! Errors of the WHJ client, with the facts in them.

use core::time::Duration;

use robobus_whj::registers::RegisterInfo;
use robobus_whj::units::{Position, UnitRangeError};
use robobus_whj::{CmdError, ErrorCode, JointId, Reply, Request, RequestError};

use super::session::{Attempt, BusState, Expect, describe};
use crate::error::ErrorKind;

/// Why a WHJ operation failed.
///
/// Every variant that concerns one joint names it (`J3`), and the ones about a register
/// name the register (`TAG_WORK_MODE (0x30)`).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WhjError {
    /// No (valid) reply arrived before the per-request timeout, on every attempt.
    #[error(
        "{joint}: no reply to {request} within {waited:?} after {attempts} attempt(s) \
         (expected {expected} on CAN ID {reply_id:#05x}; bus {bus_state}); is the joint \
         powered and connected, at this ID, and is the bus at 1 / 5 Mbit/s?"
    )]
    Timeout {
        /// The addressed joint.
        joint: JointId,
        /// What was sent (`read of CUR_POSITION_L (0x14), 2 registers`).
        request: String,
        /// What reply was expected (`read reply`, `write ack`, `servo feedback`, ...).
        expected: &'static str,
        /// The CAN ID the reply was expected on.
        reply_id: u16,
        /// How long the last attempt waited.
        waited: Duration,
        /// Attempts made.
        attempts: u32,
        /// The controller state when the last attempt gave up.
        bus_state: BusState,
    },
    /// The joint never answered the IAP release (`IAP_FLAG := 0`) at connect.
    #[error(
        "{joint} stays silent: no answer to the IAP release (write IAP_FLAG 0x49 := 0) within \
         {waited:?} ({attempts} attempt(s)). Check that the joint is powered (after power-up it \
         may stay silent for several seconds), that its node ID really is {joint} (factory \
         default 1), and that the bus runs at 1 Mbit/s arbitration / 5 Mbit/s data with CAN FD \
         and termination"
    )]
    Silent {
        /// The joint.
        joint: JointId,
        /// How long the host kept trying.
        waited: Duration,
        /// Attempts made.
        attempts: u32,
    },
    /// The joint answered `CMD_ERR`.
    #[error("{joint} rejected {request}: CMD_ERR {kind} (command byte {code:#04x})")]
    CmdErr {
        /// The joint.
        joint: JointId,
        /// What was sent.
        request: String,
        /// Format or permission error.
        kind: CmdError,
        /// The command byte of the reply (0xFF by default, C12).
        code: u8,
    },
    /// The joint acknowledged a write with status 0 (failure).
    #[error("{joint} refused the write of {value} to {register} ({addr:#04x}) (ack status 0)")]
    WriteRefused {
        /// The joint.
        joint: JointId,
        /// Register name.
        register: &'static str,
        /// Register address.
        addr: u8,
        /// The raw value written.
        value: i32,
    },
    /// The joint refused to enable: an error bit is latched (clear it first).
    #[error(
        "{joint} refused to enable: error code {code:?} is latched; clear it (clear_error) and \
         remove its cause first"
    )]
    EnableRefused {
        /// The joint.
        joint: JointId,
        /// The error bits read after the refusal.
        code: ErrorCode,
    },
    /// A reply that does not belong to the request, or is malformed, on every attempt.
    #[error("{joint}: bad reply to {request} after {attempts} attempt(s): {reason}")]
    BadReply {
        /// The joint.
        joint: JointId,
        /// What was sent.
        request: String,
        /// What was wrong with the last reply.
        reason: String,
        /// Attempts made.
        attempts: u32,
    },
    /// Two different replies answered one request within the collision window
    /// ([`JointBusConfig::collision_window`](super::JointBusConfig::collision_window)):
    /// two joints (or another node) answer at this ID. Neither value is credited.
    #[error(
        "{joint}: two different replies to {request}: {first} and {second}; two joints \
         answer at this ID (give one of them another ID)"
    )]
    DuplicateReply {
        /// The joint ID both replies came from.
        joint: JointId,
        /// What was sent.
        request: String,
        /// The first reply, summarised.
        first: String,
        /// The second, different reply, summarised.
        second: String,
    },
    /// The last attempt's reply came while a late answer to an earlier attempt was still
    /// due, so that which one answered the request could not be told (the bus or the
    /// adapter delays frames by about the reply timeout). No value is credited.
    #[error(
        "{joint}: replies to {request} came late: {reply} came while an answer to an \
         earlier attempt was still due, and which one it was could not be told in \
         {attempts} attempt(s); the bus or its adapter delays frames by about the reply \
         timeout"
    )]
    LateReply {
        /// The joint.
        joint: JointId,
        /// What was sent.
        request: String,
        /// The last reply that could not be credited, summarised.
        reply: String,
        /// Attempts made.
        attempts: u32,
    },
    /// Two reads of the same registers disagreed on every attempt (with
    /// [`JointBusConfig::verify_reads`](super::JointBusConfig::verify_reads)).
    #[error(
        "{joint}: reads of {register} ({addr:#04x}) never agreed twice in {attempts} attempt(s)"
    )]
    Unverified {
        /// The joint.
        joint: JointId,
        /// First register read.
        register: &'static str,
        /// Its address.
        addr: u8,
        /// Attempts made.
        attempts: u32,
    },
    /// Save to flash refused on the host: the joint is enabled (the firmware only saves
    /// while disabled).
    #[error(
        "{joint}: save to flash refused: the joint is enabled; disable it first (saving is only allowed while disabled)"
    )]
    SaveWhileEnabled {
        /// The joint.
        joint: JointId,
    },
    /// A position command would step further than the step limit from the actual position.
    #[error(
        "{joint}: position command {to_deg:.4}° is {:.4}° from the actual {from_deg:.4}° \
         (step limit {limit_deg}°; the joint would latch error 0x4000); a smooth move (`robobus whj move`, `Joint::move_to`) gets there in steps",
        (.to_deg - .from_deg).abs()
    )]
    StepTooLarge {
        /// The joint.
        joint: JointId,
        /// Actual position, degrees.
        from_deg: f64,
        /// Commanded position, degrees.
        to_deg: f64,
        /// The host's step limit, degrees.
        limit_deg: f64,
    },
    /// A move did not reach its target in time.
    #[error(
        "{joint}: move to {target_deg:.4}° ended at {actual_deg:.4}° after {waited:?} (error code {code:?})"
    )]
    MoveIncomplete {
        /// The joint.
        joint: JointId,
        /// Target, degrees.
        target_deg: f64,
        /// Where it was, degrees.
        actual_deg: f64,
        /// How long the host waited.
        waited: Duration,
        /// Error bits in the last feedback.
        code: ErrorCode,
    },
    /// No register with this name in the table.
    #[error("no register named {name:?} in the WHJ register table")]
    UnknownRegister {
        /// The name given.
        name: String,
    },
    /// A request refused on the host (read-only register, value out of range, ...);
    /// nothing was sent.
    #[error("{joint}: {source}")]
    Request {
        /// The joint.
        joint: JointId,
        /// Why.
        #[source]
        source: RequestError,
    },
    /// A value outside what the wire format can carry; nothing was sent.
    #[error("{joint}: {source}")]
    Unit {
        /// The joint.
        joint: JointId,
        /// Why.
        #[source]
        source: UnitRangeError,
    },
    /// The controller is bus-off (or error passive) and did not recover in time.
    #[error(
        "{joint}: {request} not completed: CAN bus {bus_state} ({detail}); waited {waited:?} for recovery"
    )]
    Bus {
        /// The joint.
        joint: JointId,
        /// What was being sent.
        request: String,
        /// The controller state.
        bus_state: BusState,
        /// The link's message.
        detail: String,
        /// How long the host waited for recovery.
        waited: Duration,
    },
    /// The operation conflicts with a running cyclic loop (its servo frames own the
    /// joint's feedback ID), or another cyclic loop is running.
    #[error("{joint}: {what} while a cyclic servo loop is running")]
    Busy {
        /// The joint.
        joint: JointId,
        /// What was refused.
        what: &'static str,
    },
    /// A cyclic loop configuration that cannot run.
    #[error("invalid cyclic loop configuration: {reason}")]
    InvalidConfig {
        /// Why.
        reason: String,
    },
    /// The link failed (closed, I/O error); the bus has stopped.
    #[error("WHJ bus link failed: {detail}")]
    Link {
        /// The link's message.
        detail: String,
    },
    /// The bus stopped working without a link error (a request that outlived every
    /// deadline the session gives it).
    #[error("WHJ bus is not running")]
    Closed,
}

impl WhjError {
    /// What kind of failure this is.
    pub fn kind(&self) -> ErrorKind {
        match self {
            Self::Timeout { .. } | Self::Silent { .. } => ErrorKind::NoDevice,
            Self::CmdErr { .. }
            | Self::WriteRefused { .. }
            | Self::EnableRefused { .. }
            | Self::BadReply { .. }
            | Self::DuplicateReply { .. }
            | Self::LateReply { .. }
            | Self::Unverified { .. }
            | Self::MoveIncomplete { .. } => ErrorKind::Device,
            Self::SaveWhileEnabled { .. } | Self::StepTooLarge { .. } | Self::Busy { .. } => {
                ErrorKind::Refused
            }
            Self::UnknownRegister { .. }
            | Self::Request { .. }
            | Self::Unit { .. }
            | Self::InvalidConfig { .. } => ErrorKind::BadInput,
            Self::Bus { .. } | Self::Link { .. } | Self::Closed => ErrorKind::Link,
        }
    }
}

impl WhjError {
    /// Whether the error is a [`WhjError::Timeout`] or [`WhjError::Silent`].
    pub const fn is_timeout(&self) -> bool {
        matches!(self, Self::Timeout { .. } | Self::Silent { .. })
    }
}

/// The error for a transaction's last attempt (`attempts` made in all).
pub(crate) fn attempt_error(
    joint: JointId,
    request: &Request,
    attempt: Attempt,
    attempts: u32,
) -> WhjError {
    let description = describe(request);
    match attempt {
        Attempt::Timeout { waited, state } => WhjError::Timeout {
            joint,
            request: description,
            expected: Expect::of(request).map_or("reply", Expect::name),
            reply_id: request.reply_id().unwrap_or(0),
            waited,
            attempts,
            bus_state: state,
        },
        Attempt::Mismatch(reason) => WhjError::BadReply {
            joint,
            request: description,
            reason,
            attempts,
        },
        Attempt::Bus {
            state,
            detail,
            waited,
        } => WhjError::Bus {
            joint,
            request: description,
            bus_state: state,
            detail,
            waited,
        },
        Attempt::Link(detail) => WhjError::Link { detail },
        Attempt::Busy => WhjError::Busy {
            joint,
            what: "single servo command refused",
        },
        Attempt::Duplicate { first, second } => WhjError::DuplicateReply {
            joint,
            request: description,
            first: summarize(&first),
            second: summarize(&second),
        },
        Attempt::Late { reply } => WhjError::LateReply {
            joint,
            request: description,
            reply: summarize(&reply),
            attempts,
        },
        Attempt::Reply {
            reply: Reply::CmdErr { error, code, .. },
            ..
        } => WhjError::CmdErr {
            joint,
            request: description,
            kind: error,
            code,
        },
        Attempt::Reply { reply, .. } => WhjError::BadReply {
            joint,
            request: description,
            reason: format!("unexpected reply {reply:?}"),
            attempts,
        },
    }
}

/// A reply in a few words for error messages: its position and error bits where it has
/// them, its register words otherwise.
pub(crate) fn summarize(reply: &Reply) -> String {
    match reply {
        Reply::Read { addr, .. } if reply.actual_position().is_some() => format!(
            "{} ({:#04x}): position {:.4}°",
            RegisterInfo::by_addr(*addr).map_or("reserved", |i| i.name),
            addr.get(),
            reply.actual_position().map_or(0.0, Position::degrees)
        ),
        Reply::Read { addr, words, .. } => format!(
            "{} ({:#04x}) = {:?}",
            RegisterInfo::by_addr(*addr).map_or("reserved", |i| i.name),
            addr.get(),
            words.as_slice()
        ),
        other => match (other.actual_position(), other.error_code()) {
            (Some(p), Some(e)) => format!("position {:.4}° (error {e:?})", p.degrees()),
            (Some(p), None) => format!("position {:.4}°", p.degrees()),
            _ => format!("{other:?}"),
        },
    }
}
