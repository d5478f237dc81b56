//! Late replies (see the [session](super)'s notes on matching): the answers still owed by
//! attempts that timed out with no frame on their reply ID, and what a frame that may be
//! one of them comes to: counted late, a second answer explained, or a reply alone not
//! credited.

use core::time::Duration;
use std::time::Instant;

use robobus_whj::{CanFrame, Reply};

use super::{Attempt, Credited, Expect, InFlight, Session};

/// How long, in reply timeouts of the attempt, an answer to an attempt that timed out is
/// still expected: a frame on its reply ID until then may be that late answer.
pub(super) const LATE_HORIZON_TIMEOUTS: u32 = 4;

/// At most this many timed-out attempts per reply ID are remembered as possibly still
/// answered late (the oldest is forgotten first).
pub(super) const LATE_KEPT: usize = 16;

/// For how long after a frame on the bus was known to be late a reply alone is doubted
/// while an answer to an earlier attempt is due on its ID: a bus that delivers late does so
/// for a while (a loaded host, a busy adapter), and a joint that was only silent (off,
/// starting, unplugged) never answers late.
pub(super) const LATE_EVIDENCE: Duration = Duration::from_secs(5);

/// An attempt that timed out without any frame on its reply ID: its answer (to a request
/// of the kind `expect`) may still come late, until `until`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Owed {
    pub(super) expect: Expect,
    pub(super) until: Instant,
}

impl Session {
    /// The attempt `f` on `key` timed out with no frame on its ID: its answer is owed for
    /// [`LATE_HORIZON_TIMEOUTS`] of its timeouts.
    pub(super) fn owe(&mut self, key: u16, f: &InFlight) {
        let late = self.late_possible.entry(key).or_default();
        if late.len() >= LATE_KEPT {
            late.pop_front();
        }
        late.push_back(Owed {
            expect: f.pending.txn.expect,
            until: f.sent + f.pending.txn.timeout * LATE_HORIZON_TIMEOUTS,
        });
    }

    /// Forgets the answers no longer owed at `now`.
    pub(super) fn forget_late(&mut self, now: Instant) {
        self.late_possible.retain(|_, late| {
            late.retain(|o| o.until > now);
            !late.is_empty()
        });
    }

    /// A frame on reply ID `key` (its reply, if it decodes) arrived at `now` while a
    /// reply on that ID is held for its collision window: a second answer to the same
    /// request if it answers it, and a fault if it differs.
    pub(super) fn second_answer(
        &mut self,
        key: u16,
        frame: &CanFrame,
        reply: Option<&Reply>,
        now: Instant,
    ) {
        let Some(c) = self.credited.get(&key) else {
            return;
        };
        let expect = c.pending.txn.expect;
        let answers = reply.is_some_and(|r| expect.check(r, frame).is_ok());
        let (true, Some(second)) = (answers && c.frame != *frame, reply) else {
            self.count_stray(key, now, answers.then_some(expect));
            return;
        };
        let Some(c) = self.credited.remove(&key) else {
            return;
        };
        if self.take_late(key, now, Some(expect)) {
            // An answer of this kind to an earlier attempt was still due: one joint
            // answering that attempt late, then this one, explains the two replies (in
            // that order: a joint answers in order). The second is held for a window of
            // its own: a third would be a second joint.
            tracing::debug!(late = ?c.reply, reply = ?second, "a late reply before a WHJ request's own");
            self.health().late += 1;
            self.late_seen = Some(now);
            let (loser, hold) = self.hold(frame);
            self.credited.insert(
                key,
                Credited {
                    frame: *frame,
                    reply: *second,
                    until: now + hold,
                    loser,
                    ..c
                },
            );
        } else {
            tracing::warn!(first = ?c.reply, second = ?second, "two different replies to one WHJ request");
            self.health().duplicates += 1;
            let outcome = Attempt::Duplicate {
                first: c.reply,
                second: *second,
            };
            self.conclude(c.pending, outcome, now);
        }
    }

    /// Whether a frame on reply ID `key` at `now` may be the late answer to an attempt
    /// that timed out there (one of the kind `expect` first, else any); if so, that
    /// attempt counts as answered from now on.
    pub(super) fn take_late(&mut self, key: u16, now: Instant, expect: Option<Expect>) -> bool {
        let Some(late) = self.late_possible.get_mut(&key) else {
            return false;
        };
        late.retain(|o| o.until > now);
        let owed = late
            .iter()
            .position(|o| expect.is_some_and(|e| e == o.expect))
            .or_else(|| late.front().map(|_| 0));
        let taken = owed.and_then(|i| late.remove(i)).is_some();
        if late.is_empty() {
            self.late_possible.remove(&key);
        }
        taken
    }

    /// A frame on reply ID `key` that answers nothing waiting (a reply of the kind
    /// `expect`, if known): a late answer to an attempt that timed out
    /// ([`BusHealth::late`]: `true`), or else unmatched.
    pub(super) fn count_stray(&mut self, key: u16, now: Instant, expect: Option<Expect>) -> bool {
        let late = self.take_late(key, now, expect);
        if late {
            self.health().late += 1;
            self.late_seen = Some(now);
        } else {
            self.health().unmatched += 1;
        }
        late
    }

    /// What `reply`, alone on `key` at `at` for a request of the kind `expect`, comes to:
    /// the attempt's reply, unless an answer of that kind to an earlier attempt that timed
    /// out there is still due and the bus delivered a frame late within
    /// [`LATE_EVIDENCE`]; then it may be that late answer, and it is not credited
    /// ([`Attempt::Late`]: the attempt is made again, and one answer stays due).
    pub(super) fn credit(
        &mut self,
        key: u16,
        expect: Expect,
        reply: Reply,
        at: Instant,
    ) -> Attempt {
        let doubted = self
            .late_seen
            .is_some_and(|seen| at.saturating_duration_since(seen) < LATE_EVIDENCE);
        let (true, Some(late)) = (doubted, self.late_possible.get_mut(&key)) else {
            return Attempt::Reply { reply };
        };
        let Some(owed) = late.iter_mut().find(|o| o.expect == expect && o.until > at) else {
            return Attempt::Reply { reply };
        };
        // One answer stays due: that late one, or this attempt's own. It stays due no
        // longer than the late one would have (a lost answer holds up its ID only so long).
        tracing::debug!(
            ?reply,
            "a WHJ reply that may be a late answer to an earlier attempt"
        );
        let until = owed.until;
        *owed = Owed { expect, until };
        self.health().late += 1;
        Attempt::Late { reply }
    }
}
