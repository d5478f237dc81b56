//! The duplicate check's collision window: a reply is held for a second answer (an
//! arbitration loser's, two joints at one ID) for the wire time of the loser's frame plus
//! the link's allowance, lengthened by every frame that wins arbitration over it meanwhile;
//! replies whose window closed are credited.

use core::time::Duration;
use std::time::Instant;

use robobus_whj::timing::{self, BitRates};
use robobus_whj::{CanFrame, Reply};

use super::{Pending, Session};

/// A request whose reply arrived, held for the collision window: a second, different
/// reply to it before `until` makes it a [`Attempt::Duplicate`](super::Attempt::Duplicate).
#[derive(Debug)]
pub(super) struct Credited {
    pub(super) pending: Pending,
    pub(super) frame: CanFrame,
    pub(super) reply: Reply,
    pub(super) until: Instant,
    /// [`loser_time`] of `frame`.
    pub(super) loser: Duration,
}

/// How long after a reply in `frame` has arrived a second node that answered the same
/// request at the same ID, and lost arbitration to it, is done sending its own: the
/// intermission, then a frame of the winner's ID and length at the WHJ rates
/// ([`timing::frame_duration`] counts the intermission after each frame), with as many
/// stuff bits as any payload of that length can have: the loser's data differ from the
/// winner's, and so do its stuff bits (joint 1's 16-byte status frame takes 62.2 µs with
/// a payload of 0x55 bytes, 68.6 µs with the most stuff bits, intermission included).
pub(super) fn loser_time(frame: &CanFrame) -> Duration {
    let bits = timing::frame_bits(frame);
    let most = frame
        .standard_raw_id()
        .filter(|_| frame.is_fd() && frame.brs())
        .and_then(|id| timing::fd_data_stuff_bounds(id, frame.len(), frame.esi()));
    if let Some((_, most)) = most {
        timing::FrameBits {
            data_bits: bits.data_bits + most.saturating_sub(bits.stuff_data),
            stuff_data: most.max(bits.stuff_data),
            ..bits
        }
        .duration(BitRates::WHJ)
    } else {
        // Not a WHJ frame: a quarter more than its own, the most stuff bits can add.
        let own = bits.duration(BitRates::WHJ);
        own + own / 4
    }
}

/// The most [`Session`] keeps of [`loser_time`] by reply ID and length (every standard ID
/// at every CAN FD length fits).
const LOSER_TIMES_KEPT: usize = 2048 * 16;

impl Session {
    /// Whether a held reply's hold ends by `now` ([`Session::handle_timeout`] credits it):
    /// frames already received are handed in first, so that a second answer that came at
    /// the hold's last instant (an arbitration loser's, one frame after the winner's on a
    /// link that adds nothing) is seen before the first is credited.
    pub(crate) fn hold_ends(&self, now: Instant) -> bool {
        self.credited.values().any(|c| c.until <= now)
    }

    /// The duplicate check's allowance for the link's lateness, `None` when it is off
    /// (see [`JointBusConfig::collision_window`](super::JointBusConfig::collision_window)).
    pub(crate) const fn allowance(&self) -> Option<Duration> {
        self.allowance
    }

    /// How long a reply that arrived in `frame` is held for a second answer: the wire
    /// time of the arbitration loser's frame ([`loser_time`]: the winner's ID and length,
    /// the most stuff bits) and the intermission before it, at the WHJ rates, plus the
    /// link's allowance ([`Session::allowance`]). Returns the loser's time and the hold.
    pub(super) fn hold(&mut self, frame: &CanFrame) -> (Duration, Duration) {
        let key = (frame.raw_id(), frame.len(), frame.esi());
        let loser = if let Some(t) = self.loser_times.get(&key) {
            *t
        } else {
            let t = loser_time(frame);
            if self.loser_times.len() < LOSER_TIMES_KEPT {
                self.loser_times.insert(key, t);
            }
            t
        };
        (loser, loser + self.allowance.unwrap_or_default())
    }

    /// `frame` goes out at `now` while replies are held: a request wins arbitration over
    /// an arbitration loser's reply (its ID is lower), so each held reply's second answer
    /// may come only after it: each hold lasts at least until `frame` has crossed the
    /// wire (after the frames sent before it) and a loser's frame could have followed,
    /// plus the link's allowance.
    pub(super) fn outbid(&mut self, frame: &CanFrame, now: Instant) {
        let start = self.wire_busy.map_or(now, |t| t.max(now));
        let sent = start + timing::frame_duration(frame, BitRates::WHJ);
        self.wire_busy = Some(sent);
        let allowance = self.allowance.unwrap_or_default();
        for c in self.credited.values_mut() {
            c.until = c.until.max(sent + c.loser + allowance);
        }
    }

    /// `frame` arrived at `now` while replies are held: a frame with a lower ID than a
    /// held reply's won arbitration over its loser's answer, which may follow it at once,
    /// so that hold lasts at least a loser's frame and the allowance from now.
    pub(super) fn outbid_by_received(&mut self, frame: &CanFrame, now: Instant) {
        let id = frame.raw_id();
        let allowance = self.allowance.unwrap_or_default();
        for c in self.credited.values_mut() {
            if id < c.frame.raw_id() {
                c.until = c.until.max(now + c.loser + allowance);
            }
        }
    }

    /// Credits the replies whose collision window closed by `now` (all, finally, with
    /// `None`).
    pub(super) fn credit_due(&mut self, now: Option<Instant>) {
        let due: Vec<u16> = self
            .credited
            .iter()
            .filter(|(_, c)| now.is_none_or(|t| c.until <= t))
            .map(|(k, _)| *k)
            .collect();
        for key in due {
            if let Some(c) = self.credited.remove(&key) {
                let outcome = self.credit(key, c.pending.txn.expect, c.reply, c.until);
                match now {
                    Some(now) => self.conclude(c.pending, outcome, now),
                    None => self.finish(c.pending, outcome),
                }
            }
        }
    }
}
