//! How replies are matched to requests ([`Expect`]) and what one attempt of a request
//! came to ([`Attempt`]); the session's [`Outcome`] of a whole transaction. Plain values:
//! the driver hands them to the handles, which turn them into errors.

use core::time::Duration;

use robobus_whj::frame::padded_len;
use robobus_whj::registers::RegisterInfo;
use robobus_whj::{CanFrame, CmdError, RegisterAddr, Reply, Request};

use super::BusState;

/// The outcome of one attempt of one transaction, as the session reports it.
#[derive(Debug, Clone)]
pub(crate) enum Attempt {
    /// The matching reply (a `CMD_ERR` included).
    Reply {
        /// The reply.
        reply: Reply,
    },
    /// A frame arrived on the reply ID that claims to answer this request but cannot
    /// (malformed, wrong length). Replies to other requests are ignored instead.
    Mismatch(String),
    /// Nothing arrived in time.
    Timeout {
        /// How long the attempt waited.
        waited: Duration,
        /// The controller state at the time.
        state: BusState,
    },
    /// The controller went bus-off while the request was in flight, or did not recover
    /// in time.
    Bus {
        /// The state.
        state: BusState,
        /// The link's message.
        detail: String,
        /// How long the request waited.
        waited: Duration,
    },
    /// The link failed.
    Link(String),
    /// A cyclic loop owns the reply ID.
    Busy,
    /// Two different replies answered the request within its collision window
    /// ([`JointBusConfig::collision_window`](super::JointBusConfig::collision_window)): two
    /// nodes answer at this ID. Neither is credited.
    Duplicate {
        /// The first reply.
        first: Reply,
        /// The second, different one.
        second: Reply,
    },
    /// The reply came alone while an answer to an earlier attempt of this kind on its
    /// reply ID, which timed out, was still due: it may be that late answer. It is not
    /// credited, and the attempt is made again.
    Late {
        /// The reply.
        reply: Reply,
    },
}

impl Attempt {
    /// Whether a transaction that may be resent ([`Txn::attempts`](super::Txn::attempts)
    /// above 1) is resent after this attempt: after a timeout, a malformed reply, a bus
    /// error, a reply that may be late ([`Attempt::Late`]), and a `CMD_ERR`
    /// format error or undefined error code (a corrupted request causes the one, only a
    /// corrupted reply carries the other). Never after a reply,
    /// another `CMD_ERR`, a duplicate reply, a busy reply ID or a failed link.
    pub(crate) const fn retryable(&self) -> bool {
        match self {
            Self::Reply {
                reply: Reply::CmdErr { error, .. },
            } => matches!(error, CmdError::Format | CmdError::Unknown(_)),
            Self::Timeout { .. } | Self::Mismatch(_) | Self::Bus { .. } | Self::Late { .. } => true,
            Self::Reply { .. } | Self::Link(_) | Self::Busy | Self::Duplicate { .. } => false,
        }
    }
}

/// How a transaction ended: its last attempt, and how many attempts were made.
#[derive(Debug, Clone)]
pub(crate) struct Outcome {
    /// The last attempt's outcome.
    pub(crate) attempt: Attempt,
    /// Attempts made (from 1).
    pub(crate) attempts: u32,
}

/// What kind of reply a request expects.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Expect {
    Read {
        addr: u8,
        count: u8,
    },
    Write {
        addr: u8,
    },
    Servo,
    Status,
    /// A command error: what a joint answers a malformed register request with (a capture
    /// replay pairs it; the client never sends one).
    CmdErr,
}

impl Expect {
    pub(crate) fn of(request: &Request) -> Option<Self> {
        match request {
            Request::Read { range, .. } => Some(Self::Read {
                addr: range.start().get(),
                count: range.count(),
            }),
            Request::Write { addr, .. } => Some(Self::Write { addr: addr.get() }),
            Request::PositionServo { .. }
            | Request::SpeedServo { .. }
            | Request::CurrentServo { .. } => Some(Self::Servo),
            Request::StatusQuery { .. } => Some(Self::Status),
            _ => None,
        }
    }

    /// A name for error messages.
    pub(crate) const fn name(self) -> &'static str {
        match self {
            Self::Read { .. } => "read reply",
            Self::Write { .. } => "write ack",
            Self::Servo => "servo feedback",
            Self::Status => "status feedback",
            Self::CmdErr => "command error",
        }
    }

    /// Whether `reply` (carried by `frame`) answers a request of this kind (`Ok`), or
    /// why not: `Err(true)` for a reply to another request (another register or kind),
    /// `Err(false)` for a malformed one. With the reason. (What `robobus replay` uses to
    /// pair a capture's requests with their replies, as the client pairs them.)
    pub(crate) fn answers(self, reply: &Reply, frame: &CanFrame) -> Result<(), (bool, String)> {
        self.check(reply, frame).map_err(|u| match u {
            Unanswered::Other(r) => (true, r),
            Unanswered::Bad(r) => (false, r),
        })
    }

    /// Whether `reply` (carried by `frame`) answers a request of this kind.
    pub(super) fn check(self, reply: &Reply, frame: &CanFrame) -> Result<(), Unanswered> {
        match (self, reply) {
            (Self::Read { .. } | Self::Write { .. } | Self::CmdErr, Reply::CmdErr { .. })
            | (Self::Servo, Reply::ServoFeedback { .. })
            | (Self::Status, Reply::Status { .. }) => Ok(()),
            (Self::Read { addr, count }, Reply::Read { addr: a, words, .. }) => {
                let want_len = padded_len(2 + 2 * usize::from(count));
                if a.get() != addr {
                    Err(Unanswered::Other(format!(
                        "read reply for register {:#04x}, expected {addr:#04x}",
                        a.get()
                    )))
                } else if want_len != Some(frame.len()) || words.len() < usize::from(count) {
                    Err(Unanswered::Bad(format!(
                        "read reply of {} bytes, expected {} for {count} register(s)",
                        frame.len(),
                        want_len.unwrap_or(0)
                    )))
                } else {
                    Ok(())
                }
            }
            (Self::Write { addr }, Reply::WriteAck { addr: a, .. }) if a.get() == addr => Ok(()),
            (Self::Write { addr }, Reply::WriteAck { addr: a, .. }) => {
                Err(Unanswered::Other(format!(
                    "write ack for register {:#04x}, expected {addr:#04x}",
                    a.get()
                )))
            }
            (want, got) => Err(Unanswered::Other(format!(
                "expected a {}, got {got:?}",
                want.name()
            ))),
        }
    }
}

/// Why a well-formed reply on a request's reply ID does not answer it.
#[derive(Debug)]
pub(super) enum Unanswered {
    /// It answers another request (another register, another kind): a late reply to an
    /// earlier request that timed out, or one sent by another client. Ignored; the
    /// request keeps waiting.
    Other(String),
    /// It claims to answer this request but has the wrong shape: an error.
    Bad(String),
}

fn register_name(addr: RegisterAddr) -> &'static str {
    RegisterInfo::by_addr(addr).map_or("reserved", |i| i.name)
}

/// A short description of a request for error messages, which name the joint already:
/// the protocol core's text without the joint (`{:#}`: `write SYS_ENABLE_DRIVER 1`,
/// `position servo target position 12.5000 °`, currents in counts), except a read, which
/// names its register as `CUR_POSITION_L (0x14)`.
pub(crate) fn describe(request: &Request) -> String {
    match request {
        Request::Read { range, .. } => format!(
            "read of {} ({:#04x}), {} register(s)",
            register_name(range.start()),
            range.start().get(),
            range.count()
        ),
        other => format!("{other:#}"),
    }
}
