//! Broadcast frames outside the cyclic loop: the 0x7F status query (`whj status
//! --broadcast`, `monitor --broadcast`) and 0x0F register access (`whj read / write
//! --broadcast`), one frame for joints 1..=7 and the end board.
//!
//! A broadcast is sent once and never resent. Its replies are credited only when they
//! arrived after the frame went out ([`JointBus::broadcast_replies_since`]) and answer
//! this request (the same register; for the end board the same command and register);
//! every slot asked for is reported, one without such a reply within
//! [`broadcast_window`] as a no-device failure. Register writes follow the same safety
//! classes, confirmation and firmware gates as point-to-point writes
//! ([`check_write`](super::check_write), [`check_joint_write`](super::check_joint_write));
//! a refused write sends nothing, for any joint.

use core::fmt;
use std::time::{Duration, Instant};

use robobus_whj::broadcast::ReplyMask;
use robobus_whj::units::CurrentScale;
use robobus_whj::{CanFrame, JointId, Reply, Request};
use serde::Serialize;

use crate::ops::{ErrorKind, Failure, OpError};
use crate::whj::{Joint, JointBus, WhjError};
use robobus_whj::reply::ServoFeedback;

pub mod end_board;
mod registers;
mod status;
mod wave;

pub use registers::{
    BroadcastPlan, EndBoardArg, broadcast_read, broadcast_write, plan_broadcast_read,
    plan_broadcast_write, run_broadcast_plan,
};
pub use status::{
    EndBoardStatus, StatusWithEndBoard, broadcast_status, broadcast_status_with_end_board,
    connect_for_broadcast, sample_broadcast,
};
pub use wave::{BROADCAST_WAVE_MIN_HZ, plan_broadcast_wave, prepare_broadcast_wave};

/// A slot of a broadcast frame: a joint (1..=7) or the end board. Serializes as the joint's
/// number or `"end-board"`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Slot {
    /// A joint's slot.
    Joint(JointId),
    /// The end board's field.
    EndBoard,
}

impl Serialize for Slot {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Self::Joint(j) => s.serialize_u8(j.get()),
            Self::EndBoard => s.serialize_str("end-board"),
        }
    }
}

impl schemars::JsonSchema for Slot {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "Slot".into()
    }

    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({
            "description": "A joint's number (1..=7), or `end-board`.",
            "oneOf": [
                {"type": "integer", "minimum": 1, "maximum": 7},
                {"const": "end-board"}
            ]
        })
    }
}

impl fmt::Display for Slot {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Joint(j) => write!(f, "{j}"),
            Self::EndBoard => f.write_str("end board"),
        }
    }
}

/// The smallest broadcast reply mask that selects every joint of `ids` (all 1..=7).
pub fn reply_mask(ids: &[JointId]) -> Result<ReplyMask, OpError> {
    reply_mask_with(ids, false)
}

/// [`reply_mask`] that also selects the end board when `end_board` is set.
pub fn reply_mask_with(ids: &[JointId], end_board: bool) -> Result<ReplyMask, OpError> {
    if let Some(bad) = ids.iter().find(|j| !j.has_broadcast_slot()) {
        return Err(OpError::invalid(
            "--broadcast JOINTS",
            bad.get(),
            "broadcast frames address joints 1..=7 only",
        ));
    }
    (0..=0xFu8)
        .filter_map(|code| ReplyMask::new(code).ok())
        .filter(|m| ids.iter().all(|j| m.selects(*j)) && (!end_board || m.selects_end_board()))
        .min_by_key(|m| m.joints().count() + usize::from(m.selects_end_board()))
        .ok_or_else(|| OpError::invalid("--broadcast JOINTS", ids.len(), "no reply mask fits"))
}

/// How long a broadcast's replies are collected: eight replies take under 1 ms on the
/// wire; a broadcast is not resent, so it waits up to five reply timeouts (100 ms by
/// default) for slow links and simulators, and returns as soon as every slot answered.
pub fn broadcast_window(bus: &JointBus) -> Duration {
    (bus.config().reply_timeout * 5).max(Duration::from_millis(5))
}

/// How long a broadcast's replies are still collected after every slot has answered, to
/// see a second answer in a slot: two nodes that answer as one (a duplicate ID, a node
/// answering twice) go out back to back by CAN arbitration, well within this time (a
/// 24-byte reply takes about 0.1 ms at 1 / 5 Mbit/s).
pub const SECOND_ANSWER_GUARD: Duration = Duration::from_millis(1);

/// Waits until `credit` accepts a reply for every slot (then [`SECOND_ANSWER_GUARD`]
/// longer) or [`broadcast_window`] ends. Each slot gets the reply received after `sent`
/// that `credit` accepts (`Ok(None)`: none); two different ones in one slot are a device
/// failure naming both, never "the first wins".
fn collect<T: PartialEq + fmt::Debug>(
    bus: &JointBus,
    sent: Instant,
    slots: &[Slot],
    credit: impl Fn(Slot, &CanFrame) -> Option<T>,
) -> Vec<Result<Option<T>, Failure>> {
    let deadline = bus.now() + broadcast_window(bus);
    let mut settle: Option<Instant> = None;
    loop {
        let got = bus.broadcast_replies_since(sent);
        let now = bus.now();
        let complete = slots
            .iter()
            .all(|&slot| got.iter().any(|(_, f)| credit(slot, f).is_some()));
        if complete && settle.is_none() {
            settle = Some(now + SECOND_ANSWER_GUARD);
        }
        let until = settle.map_or(deadline, |s| s.min(deadline));
        if now >= until {
            return slots
                .iter()
                .map(|&slot| {
                    let mut answers = got.iter().filter_map(|(_, f)| credit(slot, f));
                    let first = answers.next();
                    let other = answers.find(|a| Some(a) != first.as_ref());
                    match (first, other) {
                        (Some(a), Some(b)) => Err(Failure::of(
                            ErrorKind::Device,
                            &format!(
                                "{slot}: two different answers to one broadcast frame ({a:?} \
                                 and {b:?}): two nodes answer as one, or one answers twice; \
                                 neither is credited"
                            ),
                        )),
                        (first, _) => Ok(first),
                    }
                })
                .collect();
        }
        // Receives meanwhile (on a simulated bus on virtual time, simulates meanwhile).
        bus.sleep_until(until.min(now + Duration::from_millis(2)));
    }
}

fn silent(slot: Slot, what: &str, bus: &JointBus) -> Failure {
    Failure::of(
        ErrorKind::NoDevice,
        &format!(
            "{slot}: no reply to the broadcast {what} within {} ms",
            broadcast_window(bus).as_millis()
        ),
    )
}

fn scale_of(bus: &JointBus, id: JointId) -> CurrentScale {
    bus.cached_identity(id)
        .map_or(CurrentScale::OneMilliamp, |i| i.current_scale())
}

/// Sends one broadcast servo frame and waits one reply timeout for `j`'s 24-byte
/// feedback, received after the frame went out; `None` when none came.
pub(super) fn broadcast_servo(
    j: &Joint<'_>,
    request: Request,
) -> Result<Option<ServoFeedback>, WhjError> {
    let bus = j.bus();
    let sent = bus.send_broadcast(request)?;
    let deadline = sent + bus.config().reply_timeout;
    let mut settle: Option<Instant> = None;
    loop {
        let replies = bus.broadcast_replies_since(sent);
        let mut answers = replies
            .iter()
            .filter_map(|(_, f)| match Reply::from_frame(f) {
                Ok(Reply::BroadcastFeedback { joint, feedback }) if joint == j.id() => {
                    Some(feedback)
                }
                _ => None,
            });
        let first = answers.next();
        let other = answers.find(|a| Some(a) != first.as_ref());
        let now = bus.now();
        if let (Some(a), Some(b)) = (first, other) {
            return Err(WhjError::BadReply {
                joint: j.id(),
                request: "broadcast servo frame".into(),
                reason: format!(
                    "two different answers to one frame (positions {:.4} and {:.4} deg): two \
                     joints answer as one, or one answers twice; neither is credited",
                    a.position.degrees(),
                    b.position.degrees()
                ),
                attempts: 1,
            });
        }
        if first.is_some() && settle.is_none() {
            settle = Some(now + SECOND_ANSWER_GUARD);
        }
        if (first.is_some() && settle.is_some_and(|s| now >= s)) || now >= deadline {
            return Ok(first.map(|f| ServoFeedback {
                current: f.current,
                speed: f.speed,
                position: f.position,
                enable: u16::from(f.is_enabled()),
                error: f.error,
            }));
        }
        let until = settle.unwrap_or(deadline).min(deadline);
        bus.sleep_until(until.min(now + Duration::from_micros(200)));
    }
}
