//! The WHJ client session, sans-IO: request matching, deadlines, retries, settle times,
//! the bus-error state, the cyclic loop's state, the broadcast log and the telemetry, as
//! one state machine with time passed in.
//!
//! [`Session`] owns all of it. It never touches a link, a clock, a lock or a thread, and
//! it imports nothing of its driver ([`JointBus`](super::JointBus), which holds it under
//! its one lock and publishes what it polls out) nor of the handles: everything it needs
//! lives here or in its children (`config`: the settings and [`BusState`]; `telemetry`;
//! `matching`: [`Expect`], [`Attempt`], [`Outcome`]; `late`: answers that may come late;
//! `arbitration`: the duplicate check's collision window; `bus_state`: the bus-error
//! state; `cyclic`: the loop's pure state).
//! As quinn-proto's `Connection`, its methods come in classes:
//!
//! - **Commands** from the program, through the driver: [`Session::submit`] a
//!   transaction ([`Txn`]: a request, how long each attempt waits, how many attempts, a
//!   settle time after it), [`Session::abandon`] one, [`Session::start_cyclic`],
//!   [`Session::set_cyclic_targets`], [`Session::stop_cyclic`].
//! - **`handle_*`: input.** Every frame received ([`Session::handle_frame`]) and every
//!   receive error ([`Session::handle_link_error`]); the fate of each frame the session
//!   asked to send ([`Session::handle_sent`], [`Session::handle_send_failed`]); a broadcast
//!   frame the driver sent itself ([`Session::handle_broadcast_sent`]); a link that is
//!   gone ([`Session::handle_closed`]).
//! - **Time.** [`Session::handle_timeout`] lets time pass (reply deadlines and the retries
//!   they start, settle times, collision windows, bus-error holds, the loop's ticks);
//!   [`Session::next_deadline`] says when it is due again at the latest;
//!   [`Session::cyclic_due`] whether it would tick the loop.
//! - **`poll_*`: output.** [`Session::poll_transmit`] (a frame to send now),
//!   [`Session::poll_outcome`] (a finished transaction), [`Session::poll_event`] (cycle
//!   reports, the loop's end with its statistics), [`Session::poll_telemetry`] (what
//!   changed in the telemetry since the last poll).
//! - **Getters**, which change nothing: [`Session::awaiting`],
//!   [`Session::is_idle`], [`Session::broadcast_pending`], [`Session::cyclic_running`],
//!   [`Session::cyclic_stats`], [`Session::broadcast_replies_since`].
//!
//! Calling order of one driver step, `now` read from the link's clock each time:
//!
//! 1. if [`Session::cyclic_due`]: hand it the frames already received
//!    ([`Session::handle_frame`]), then the latest targets
//!    ([`Session::set_cyclic_targets`]);
//! 2. [`Session::handle_timeout`];
//! 3. [`Session::poll_transmit`] until `None`, sending each frame and reporting it
//!    ([`Session::handle_sent`] or [`Session::handle_send_failed`]);
//! 4. wait until [`Session::next_deadline`]: receiving (`handle_frame`,
//!    `handle_link_error`) if [`Session::awaiting`] or [`Session::broadcast_pending`],
//!    else sleeping; then steps 2 and 3 again;
//! 5. collect and publish: [`Session::poll_outcome`] for the transactions waited for,
//!    [`Session::poll_event`] until `None`, [`Session::poll_telemetry`].
//!
//! Commands come between steps; what they queue goes out at the next step.
//!
//! Matching: a reply is credited only to the request in flight on its reply ID that it
//! can answer (register, count, length, kind); at most one request per reply ID is in
//! flight, so a reply can belong to that request only, and only from the instant the
//! request itself can have crossed the wire. A reply to another request, or one before that
//! instant, is not credited and the request keeps waiting. Late replies: an attempt that
//! timed out with no frame at all on its reply ID may still be answered late (for
//! [`late::LATE_HORIZON_TIMEOUTS`] of its timeouts); a frame on that ID meanwhile that is not
//! credited counts as that late answer ([`BusHealth::late`]; otherwise unmatched). A
//! credited reply is held for a second answer, from its caller only (requests to other
//! reply IDs go out meanwhile): one frame of its length on the wire (an arbitration
//! loser's answer follows the winner's at once), lengthened by the wire time of every
//! request sent meanwhile (which wins arbitration over the loser's answer), plus the
//! link's allowance ([`JointBusConfig::collision_window`], by default the link's own
//! [`FrameLink::reply_allowance`](robobus_link::FrameLink::reply_allowance)). A second,
//! different reply
//! within the hold makes the attempt a [`Attempt::Duplicate`] (two joints at one ID),
//! unless a late answer
//! of that kind is due on the ID: then one joint answering the earlier attempt late and
//! then this one explains the two (a joint answers in order), and the second is held for
//! a window of its own (a third would be a second joint). A reply alone is credited unless
//! a late answer of its kind is due on its ID and the bus was seen delivering late within
//! [`late::LATE_EVIDENCE`] (a joint that was only silent never answers late); then it may be
//! that late answer, and the attempt is an [`Attempt::Late`]: nothing credited, made
//! again. Retries: an attempt whose outcome is [`Attempt::retryable`] is
//! queued again (behind what is queued) while the transaction has attempts left; after a
//! failed send, only from the next [`Session::handle_timeout`] on.

use core::time::Duration;
use std::collections::{HashMap, VecDeque};
use std::time::Instant;

use robobus_link::{FrameLinkError, WaitMode};
use robobus_whj::timing::{self, BitRates};
use robobus_whj::{CanFrame, JointId, Reply, Request};

mod arbitration;
mod bus_state;
mod config;
pub(crate) mod cyclic;
mod late;
mod matching;
mod telemetry;
#[cfg(test)]
mod tests;

use arbitration::Credited;
pub use config::{BusState, JointBusConfig};
use cyclic::{CyclicRun, CyclicSetup, CyclicStats};
use late::Owed;
use matching::Unanswered;
pub(crate) use matching::{Attempt, Expect, Outcome, describe};
pub use telemetry::{BusHealth, BusTelemetry, JointTelemetry};

/// How many frames on broadcast reply IDs the session keeps
/// ([`Session::broadcast_replies_since`]): eight nodes answer one broadcast frame, so this
/// holds the answers to the last eight.
pub(crate) const BROADCAST_LOG: usize = 64;

/// At most this many finished transactions wait to be polled (their callers gave up).
const MAX_DONE: usize = 4096;

/// One transaction: a request and how to wait for its reply.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Txn {
    /// The request (point-to-point).
    pub(crate) request: Request,
    /// The reply it waits for (`Expect::of(&request)`).
    pub(crate) expect: Expect,
    /// How long each attempt waits for its reply.
    pub(crate) timeout: Duration,
    /// After a successful write ack: how long nothing more is sent to the joint.
    pub(crate) quiet_after: Duration,
    /// When it was submitted (or queued again): a bus-off recovery is waited for from here.
    pub(crate) submitted: Instant,
    /// How many attempts it may take (1: sent once). It is sent again after an attempt
    /// whose outcome is [`Attempt::retryable`] until it took them.
    pub(crate) attempts: u32,
}

/// Names a submitted transaction.
pub(crate) type TxnId = u64;

/// A frame the session wants sent now.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Transmit {
    pub(crate) frame: CanFrame,
    /// The transaction it starts (`None`: a frame of the cyclic loop).
    txn: Option<(TxnId, u16)>,
}

/// What the session reports besides transactions ([`Session::poll_event`]).
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Event {
    /// A cycle of the cyclic loop closed.
    Cycle(cyclic::CycleReport),
    /// The cyclic loop ended (stopped, or the link is gone), with its final statistics;
    /// every report of it came before.
    CyclicEnded(CyclicStats),
}

/// One attempt of a transaction, before it goes out.
#[derive(Debug, Clone, Copy)]
struct Pending {
    id: TxnId,
    txn: Txn,
    /// Which attempt this is, from 1.
    attempt: u32,
}

#[derive(Debug)]
struct InFlight {
    pending: Pending,
    sent: Instant,
    deadline: Instant,
    /// The earliest its reply can arrive: the request's own wire time at the fastest
    /// WHJ rates after it went out.
    earliest: Instant,
    /// Whether a frame that it did not take arrived on its reply ID while it waited (its
    /// answer may have come, malformed or unfit): if it times out, no answer to it is
    /// expected late.
    stray: bool,
}

/// Whether `raw` is an ID on which joints or the end board answer broadcast frames.
fn is_broadcast_reply_id(raw: u16) -> bool {
    use robobus_whj::Address;
    matches!(
        Address::from_raw(raw),
        Address::BroadcastFeedback(_)
            | Address::BroadcastRegisterReply(_)
            | Address::EndBoardFeedback
            | Address::EndBoardRegisterReply
    )
}

/// The client's state of one bus (see the [module](self) notes).
#[derive(Debug)]
pub(crate) struct Session {
    config: JointBusConfig,
    /// The duplicate check's allowance for the link's lateness
    /// ([`JointBusConfig::collision_window`], else the link's own); `None`: the check is
    /// off, a reply is credited at once.
    allowance: Option<Duration>,
    /// Until when the frames the session sent occupy the wire, as far as it knows (each
    /// after the one before it).
    wire_busy: Option<Instant>,
    /// [`loser_time`](arbitration::loser_time) by raw ID, length and ESI, computed once each.
    loser_times: HashMap<(u32, usize, bool), Duration>,
    next_id: TxnId,
    queued: VecDeque<Pending>,
    /// Attempts to send again after a failed send, queued at the next `handle_timeout`.
    deferred: Vec<Pending>,
    in_flight: HashMap<u16, InFlight>,
    /// Replies received and held for the collision window, by reply ID.
    credited: HashMap<u16, Credited>,
    /// Per reply ID, one entry per attempt that timed out there with no frame on it:
    /// answers that may still come late (oldest first, at most [`late::LATE_KEPT`]).
    late_possible: HashMap<u16, VecDeque<Owed>>,
    /// When a frame was last known to be late (it came while nothing on its ID could
    /// take it, or beside an attempt's own reply, with an answer due on that ID).
    late_seen: Option<Instant>,
    done: HashMap<TxnId, Outcome>,
    /// Per joint: until when nothing is sent to it (a settle time).
    quiet: HashMap<u8, Instant>,
    passive_since: Option<Instant>,
    cyclic: Option<CyclicRun>,
    to_send: VecDeque<CanFrame>,
    events: VecDeque<Event>,
    /// Until when replies to the last broadcast frame are awaited (received at once
    /// rather than at the next drain).
    broadcast_until: Option<Instant>,
    /// The latest frames on broadcast reply IDs (joints' 0x8x / 0xFx, the end board's
    /// 0x87 / 0xF7) with their receive instants, oldest first, at most [`BROADCAST_LOG`].
    broadcast_log: VecDeque<(Instant, CanFrame)>,
    telemetry: BusTelemetry,
    /// What changed in `telemetry` since the last poll: joints by bit (`1 << ID`), and
    /// the bus health.
    changed_joints: u32,
    changed_bus: bool,
}

impl Session {
    /// A session with nothing queued, the bus active and no loop, on a link that does not
    /// say how late it delivers ([`robobus_link::DEFAULT_REPLY_ALLOWANCE`]).
    #[cfg(test)]
    pub(crate) fn new(config: JointBusConfig) -> Self {
        Self::on_link(config, robobus_link::DEFAULT_REPLY_ALLOWANCE)
    }

    /// A session with nothing queued, the bus active and no loop, on a link that may
    /// deliver the second of two back-to-back frames `link_allowance` late
    /// ([`robobus_link::FrameLink::reply_allowance`]); the config's
    /// [`JointBusConfig::collision_window`] overrides it.
    pub(crate) fn on_link(config: JointBusConfig, link_allowance: Duration) -> Self {
        let allowance = match config.collision_window {
            None => Some(link_allowance),
            Some(w) if w.is_zero() => None,
            Some(w) => Some(w),
        };
        Self {
            config,
            allowance,
            wire_busy: None,
            loser_times: HashMap::new(),
            next_id: 0,
            queued: VecDeque::new(),
            deferred: Vec::new(),
            in_flight: HashMap::new(),
            credited: HashMap::new(),
            late_possible: HashMap::new(),
            late_seen: None,
            done: HashMap::new(),
            quiet: HashMap::new(),
            passive_since: None,
            cyclic: None,
            to_send: VecDeque::new(),
            events: VecDeque::new(),
            broadcast_until: None,
            broadcast_log: VecDeque::new(),
            telemetry: BusTelemetry::default(),
            changed_joints: 0,
            changed_bus: false,
        }
    }

    // Commands.

    /// Queues a transaction; its [`Outcome`] is polled ([`Session::poll_outcome`]) once
    /// it is finished.
    pub(crate) fn submit(&mut self, txn: Txn) -> TxnId {
        self.next_id += 1;
        self.queued.push_back(Pending {
            id: self.next_id,
            txn,
            attempt: 1,
        });
        self.next_id
    }

    /// Forgets a transaction whose caller no longer waits for it: it is not sent (again).
    pub(crate) fn abandon(&mut self, id: TxnId) {
        self.done.remove(&id);
        self.queued.retain(|p| p.id != id);
        self.deferred.retain(|p| p.id != id);
        // An attempt on the wire ends as it would, without another.
        for p in self.in_flight.values_mut().map(|f| &mut f.pending) {
            if p.id == id {
                p.txn.attempts = p.attempt;
            }
        }
        for p in self.credited.values_mut().map(|c| &mut c.pending) {
            if p.id == id {
                p.txn.attempts = p.attempt;
            }
        }
    }

    /// Starts a cyclic loop whose first tick is at `now`; `false` (and nothing changes)
    /// while one runs.
    #[must_use]
    pub(crate) fn start_cyclic(&mut self, setup: CyclicSetup, now: Instant) -> bool {
        if self.cyclic.is_some() {
            return false;
        }
        self.cyclic = Some(CyclicRun::new(setup, now));
        true
    }

    /// The targets the loop sends from its next tick on, one per joint (`false`, and
    /// nothing changes, if no loop runs or the count differs).
    pub(crate) fn set_cyclic_targets(&mut self, targets: Vec<i32>) -> bool {
        self.cyclic.as_mut().is_some_and(|c| c.set_targets(targets))
    }

    /// Stops the cyclic loop, if one runs: its last reports and then
    /// [`Event::CyclicEnded`] are polled next.
    pub(crate) fn stop_cyclic(&mut self) {
        if let Some(c) = self.cyclic.take() {
            let (reports, stats) = c.finish();
            self.events.extend(reports.into_iter().map(Event::Cycle));
            self.events.push_back(Event::CyclicEnded(stats));
        }
        self.to_send.clear();
    }

    // Input.

    /// A frame of [`Session::poll_transmit`] went out.
    pub(crate) fn handle_sent(&mut self) {
        self.health().frames_sent += 1;
    }

    /// A frame of [`Session::poll_transmit`] could not be sent at `now`. A bus error
    /// changes the state; the attempt ends (and may be sent again from the next
    /// [`Session::handle_timeout`] on).
    pub(crate) fn handle_send_failed(&mut self, tx: &Transmit, e: &FrameLinkError, now: Instant) {
        let Some((id, key)) = tx.txn else {
            if let Some(c) = self.cyclic.as_mut() {
                c.send_failed(&tx.frame, &e.to_string());
            }
            return;
        };
        if self.in_flight.get(&key).is_none_or(|f| f.pending.id != id) {
            return;
        }
        let Some(f) = self.in_flight.remove(&key) else {
            return;
        };
        let outcome = match e {
            FrameLinkError::BusOff { .. } | FrameLinkError::ErrorPassive { .. } => {
                self.link_error_state(e, now);
                Attempt::Bus {
                    state: self.state(),
                    detail: e.to_string(),
                    waited: Duration::ZERO,
                }
            }
            _ => Attempt::Link(e.to_string()),
        };
        if f.pending.attempt < f.pending.txn.attempts && outcome.retryable() {
            self.deferred.push(Pending {
                txn: Txn {
                    submitted: now,
                    ..f.pending.txn
                },
                attempt: f.pending.attempt + 1,
                ..f.pending
            });
        } else {
            self.finish(f.pending, outcome);
        }
    }

    /// The driver sent a broadcast frame itself at `now`: its replies are awaited for
    /// five reply timeouts.
    pub(crate) fn handle_broadcast_sent(&mut self, now: Instant) {
        self.health().frames_sent += 1;
        self.broadcast_until = Some(now + self.config.reply_timeout * 5);
    }

    /// A frame arrived at `now`.
    pub(crate) fn handle_frame(&mut self, frame: &CanFrame, now: Instant) {
        let decoded = Reply::from_frame(frame);
        self.outbid_by_received(frame, now);
        if frame.standard_raw_id().is_some_and(is_broadcast_reply_id) {
            if self.broadcast_log.len() >= BROADCAST_LOG {
                self.broadcast_log.pop_front();
            }
            self.broadcast_log.push_back((now, *frame));
        }
        self.health().frames_received += 1;
        match &decoded {
            Ok(reply) => {
                self.telemetry.record(reply, now);
                self.changed_joints |= 1u32
                    .checked_shl(u32::from(reply.joint().get()))
                    .unwrap_or(0);
            }
            Err(_) => self.health().malformed += 1,
        }
        if self.state() == BusState::BusOff {
            self.set_state(BusState::Active, None);
        }
        if let (Ok(reply), Some(c)) = (&decoded, self.cyclic.as_mut())
            && c.on_reply(reply, frame, now)
        {
            return;
        }
        let key = frame.standard_raw_id().unwrap_or(0);
        if self.credited.contains_key(&key) {
            self.second_answer(key, frame, decoded.as_ref().ok(), now);
            return;
        }
        let Some(mut f) = self.in_flight.remove(&key) else {
            self.count_stray(key, now, None);
            return;
        };
        if now < f.earliest {
            // Before the request itself can have crossed the wire: whatever this is, it
            // does not answer this attempt (a late answer to an earlier one, mostly).
            tracing::debug!("ignored a reply that came before its request was on the wire");
            // Unless it is a late answer to an earlier attempt, it may have been this
            // attempt's own, unfit.
            f.stray |= !self.count_stray(key, now, None);
            self.in_flight.insert(key, f);
            return;
        }
        if let Ok(reply) = &decoded
            && let Err(Unanswered::Other(reason)) = f.pending.txn.expect.check(reply, frame)
        {
            // A late reply to something else: the request is still waiting for its own.
            tracing::debug!(%reason, "ignored a reply that answers another request");
            // Unless it is a late answer to an earlier attempt, it may have been this
            // attempt's own, unfit.
            f.stray |= !self.count_stray(key, now, None);
            self.in_flight.insert(key, f);
            return;
        }
        let txn = f.pending.txn;
        let outcome = match decoded {
            Ok(reply) => match txn.expect.check(&reply, frame) {
                Ok(()) => {
                    let ok_write = matches!(
                        reply,
                        Reply::WriteAck { status, .. } if status.is_ok()
                    );
                    if ok_write && !txn.quiet_after.is_zero() {
                        let joint = reply.joint().get();
                        self.quiet.insert(joint, now + txn.quiet_after);
                    }
                    if self.allowance.is_none() {
                        self.credit(key, txn.expect, reply, now)
                    } else {
                        let (loser, hold) = self.hold(frame);
                        self.credited.insert(
                            key,
                            Credited {
                                pending: f.pending,
                                frame: *frame,
                                reply,
                                until: now + hold,
                                loser,
                            },
                        );
                        return;
                    }
                }
                Err(Unanswered::Bad(reason) | Unanswered::Other(reason)) => {
                    Attempt::Mismatch(reason)
                }
            },
            Err(e) => Attempt::Mismatch(e.to_string()),
        };
        self.conclude(f.pending, outcome, now);
    }

    /// A receive failed with `e` at `now`. Bus errors change the bus state (a bus-off
    /// ends the attempts in flight); a closed link is [`Session::handle_closed`].
    pub(crate) fn handle_link_error(&mut self, e: &FrameLinkError, now: Instant) {
        match e {
            FrameLinkError::BusOff { .. }
            | FrameLinkError::ErrorPassive { .. }
            | FrameLinkError::BusError { .. } => {
                self.link_error_state(e, now);
                if self.state() == BusState::BusOff {
                    let detail = e.to_string();
                    let failed: Vec<InFlight> = self.in_flight.drain().map(|(_, f)| f).collect();
                    for f in failed {
                        let outcome = Attempt::Bus {
                            state: BusState::BusOff,
                            detail: detail.clone(),
                            waited: now.saturating_duration_since(f.sent),
                        };
                        self.conclude(f.pending, outcome, now);
                    }
                }
            }
            FrameLinkError::Closed { .. } => self.handle_closed(&e.to_string()),
            other => {
                tracing::warn!(error = %other, "WHJ bus receive error");
                self.health().last_error = Some(other.to_string());
            }
        }
    }

    /// The link is gone (`detail` says why): every transaction fails, the cyclic loop
    /// ends.
    pub(crate) fn handle_closed(&mut self, detail: &str) {
        self.health().last_error = Some(detail.to_owned());
        self.credit_due(None);
        let in_flight: Vec<Pending> = self.in_flight.drain().map(|(_, f)| f.pending).collect();
        let queued: Vec<Pending> = self
            .queued
            .drain(..)
            .chain(self.deferred.drain(..))
            .collect();
        for p in in_flight.into_iter().chain(queued) {
            self.finish(p, Attempt::Link(detail.to_owned()));
        }
        self.stop_cyclic();
    }

    // Time.

    /// Whether the cyclic loop's next tick is due at `now`: frames already received are
    /// handed in first, so that none is taken for the next cycle's.
    pub(crate) fn cyclic_due(&self, now: Instant) -> bool {
        self.cyclic.as_ref().is_some_and(|c| c.due(now))
    }

    /// Lets time pass until `now`: bus-error holds end, the cyclic loop ticks, held
    /// replies are credited, attempts time out (and are queued again if they may be),
    /// settle times end.
    pub(crate) fn handle_timeout(&mut self, now: Instant) {
        self.queued.extend(self.deferred.drain(..));
        self.recover_passive(now);
        if let Some(c) = self.cyclic.as_mut()
            && c.due(now)
        {
            self.to_send.extend(c.tick(now));
        }
        self.expire(now);
    }

    /// When [`Session::handle_timeout`] is due at the latest (a deadline, a tick, the end
    /// of a collision window or a settle time, or the poll interval).
    pub(crate) fn next_deadline(&self, now: Instant) -> Instant {
        let mut wake = now + self.config.poll_interval;
        for f in self.in_flight.values() {
            wake = wake.min(f.deadline);
        }
        for c in self.credited.values() {
            wake = wake.min(c.until);
        }
        if let Some(c) = &self.cyclic {
            wake = wake.min(c.next_event());
        }
        for until in self.quiet.values() {
            if *until > now {
                wake = wake.min(*until);
            }
        }
        if !self.to_send.is_empty() {
            wake = now;
        }
        wake.max(now)
    }

    // Output.

    /// The next frame to send now: the cyclic loop's first, then a queued request whose
    /// reply ID is free and whose joint is not settling. A request is in flight from here
    /// on; report the send with [`Session::handle_sent`] or
    /// [`Session::handle_send_failed`].
    pub(crate) fn poll_transmit(&mut self, now: Instant) -> Option<Transmit> {
        if let Some(frame) = self.to_send.pop_front() {
            self.outbid(&frame, now);
            return Some(Transmit { frame, txn: None });
        }
        let bus_off = self.state() == BusState::BusOff;
        let mut i = 0;
        while let Some(p) = self.queued.get(i).copied() {
            let key = p.txn.request.reply_id().unwrap_or(0);
            let joint = p.txn.request.joint().map_or(0, JointId::get);
            if self.cyclic.as_ref().is_some_and(|c| c.owns(key)) {
                self.queued.remove(i);
                self.conclude(p, Attempt::Busy, now);
                continue;
            }
            if bus_off {
                let waited = now.saturating_duration_since(p.txn.submitted);
                if waited >= self.config.bus_recovery_timeout {
                    self.queued.remove(i);
                    let outcome = Attempt::Bus {
                        state: BusState::BusOff,
                        detail: self.last_error(),
                        waited,
                    };
                    self.conclude(p, outcome, now);
                    continue;
                }
                i += 1;
                continue;
            }
            let busy = self.in_flight.contains_key(&key) || self.credited.contains_key(&key);
            let quiet = self.quiet.get(&joint).is_some_and(|t| *t > now);
            if busy || quiet {
                i += 1;
                continue;
            }
            self.queued.remove(i);
            let frame = p.txn.request.to_frame();
            self.outbid(&frame, now);
            self.in_flight.insert(
                key,
                InFlight {
                    pending: p,
                    sent: now,
                    deadline: now + p.txn.timeout,
                    earliest: now + timing::frame_duration(&frame, BitRates::WHJ),
                    stray: false,
                },
            );
            return Some(Transmit {
                frame,
                txn: Some((p.id, key)),
            });
        }
        None
    }

    /// The outcome of transaction `id`, once it is finished (taken: polled once).
    pub(crate) fn poll_outcome(&mut self, id: TxnId) -> Option<Outcome> {
        self.done.remove(&id)
    }

    /// The next cycle report or end of the loop, oldest first.
    pub(crate) fn poll_event(&mut self) -> Option<Event> {
        self.events.pop_front().or_else(|| {
            self.cyclic
                .as_mut()
                .and_then(CyclicRun::poll_report)
                .map(Event::Cycle)
        })
    }

    /// Copies into `snapshot` what changed in the telemetry since the last poll; `false`
    /// (and nothing is copied) if nothing did. A snapshot that got every copy equals the
    /// session's own.
    pub(crate) fn poll_telemetry(&mut self, snapshot: &mut BusTelemetry) -> bool {
        if !self.telemetry_changed() {
            return false;
        }
        snapshot.copy_from(&self.telemetry, self.changed_joints, self.changed_bus);
        self.changed_joints = 0;
        self.changed_bus = false;
        true
    }

    // Getters.

    /// Whether [`Session::poll_telemetry`] has something to copy.
    pub(crate) const fn telemetry_changed(&self) -> bool {
        self.changed_joints != 0 || self.changed_bus
    }

    /// Whether a frame is expected: a reply in flight or held, feedback of the running
    /// cycle, or a bus-off recovery that queued requests wait for. Only then does the
    /// driver block in the link's receive; otherwise it sleeps.
    /// How the driver waits (from the settings).
    pub(crate) const fn wait_mode(&self) -> WaitMode {
        self.config.wait
    }

    /// The instant from which a spinning driver polls, from `now` on: a request's reply
    /// cannot come before the request has crossed the wire; a cyclic loop's feedback may
    /// come at any time; with only held replies left, what ends the wait is the end of
    /// their collision window (a rival frame that comes sooner still ends it).
    pub(crate) fn earliest_reply(&self, now: Instant) -> Instant {
        if self.cyclic.as_ref().is_some_and(CyclicRun::awaiting) {
            return now;
        }
        let next = self
            .in_flight
            .values()
            .map(|f| f.earliest)
            .min()
            .or_else(|| self.credited.values().map(|c| c.until).min());
        next.map_or(now, |t| t.max(now))
    }

    pub(crate) fn awaiting(&self) -> bool {
        !self.in_flight.is_empty()
            || !self.credited.is_empty()
            || self.cyclic.as_ref().is_some_and(CyclicRun::awaiting)
            || (!self.queued.is_empty() && self.state() == BusState::BusOff)
    }

    /// Whether nothing is queued, in flight or cycling.
    pub(crate) fn is_idle(&self) -> bool {
        self.queued.is_empty()
            && self.deferred.is_empty()
            && self.in_flight.is_empty()
            && self.credited.is_empty()
            && self.cyclic.is_none()
    }

    /// Whether replies to a broadcast frame are still awaited at `now`.
    pub(crate) fn broadcast_pending(&self, now: Instant) -> bool {
        self.broadcast_until.is_some_and(|t| t > now)
    }

    /// The frames received on broadcast reply IDs strictly after `since`, with their
    /// receive instants, oldest first (the last [`BROADCAST_LOG`] are kept).
    pub(crate) fn broadcast_replies_since(&self, since: Instant) -> Vec<(Instant, CanFrame)> {
        self.broadcast_log
            .iter()
            .filter(|(at, _)| *at > since)
            .copied()
            .collect()
    }

    /// Whether a cyclic loop runs.
    pub(crate) const fn cyclic_running(&self) -> bool {
        self.cyclic.is_some()
    }

    /// The running loop's statistics so far.
    pub(crate) fn cyclic_stats(&self) -> Option<CyclicStats> {
        self.cyclic.as_ref().map(CyclicRun::stats)
    }

    // Internals.

    /// The bus health, marked changed.
    fn health(&mut self) -> &mut BusHealth {
        self.changed_bus = true;
        &mut self.telemetry.bus
    }

    /// Attempt `p` ended with `outcome` at `now`: queued again if the transaction may
    /// take another attempt and the outcome allows one, finished otherwise.
    fn conclude(&mut self, p: Pending, outcome: Attempt, now: Instant) {
        if p.attempt < p.txn.attempts && outcome.retryable() {
            let joint = p.txn.request.joint();
            tracing::debug!(
                ?joint,
                attempt = p.attempt,
                ?outcome,
                "WHJ request attempt failed"
            );
            self.queued.push_back(Pending {
                txn: Txn {
                    submitted: now,
                    ..p.txn
                },
                attempt: p.attempt + 1,
                ..p
            });
        } else {
            self.finish(p, outcome);
        }
    }

    fn finish(&mut self, p: Pending, attempt: Attempt) {
        if self.done.len() >= MAX_DONE {
            self.done.clear();
        }
        self.done.insert(
            p.id,
            Outcome {
                attempt,
                attempts: p.attempt,
            },
        );
    }

    fn expire(&mut self, now: Instant) {
        self.credit_due(Some(now));
        let expired: Vec<u16> = self
            .in_flight
            .iter()
            .filter(|(_, f)| f.deadline <= now)
            .map(|(k, _)| *k)
            .collect();
        let state = self.state();
        for key in expired {
            if let Some(f) = self.in_flight.remove(&key) {
                if !f.stray {
                    self.owe(key, &f);
                }
                let outcome = Attempt::Timeout {
                    waited: now.saturating_duration_since(f.sent),
                    state,
                };
                self.conclude(f.pending, outcome, now);
            }
        }
        self.quiet.retain(|_, until| *until > now);
        self.forget_late(now);
    }
}
