//! The WHJ client session, sans-IO: request matching, deadlines, settle times, the
//! bus-error state and the cyclic loop, as a state machine with time passed in.
//!
//! [`Session`] never touches a link or a clock. Its driver ([`JointBus`](super::JointBus),
//! from the caller's thread for request / reply work and from its own thread only for the
//! cyclic loop and for picking up unsolicited frames) asks it what to send
//! ([`Session::poll_transmit`]), how long to wait ([`Session::next_wake`]), hands it every
//! frame and link error that arrives ([`Session::on_frame`], [`Session::on_link_error`])
//! and the time ([`Session::on_time`]), and collects finished attempts
//! ([`Session::take`]). A reply is credited only to the request in flight on its reply
//! ID that it can answer (register, count, length, kind); at most one request per reply ID
//! is in flight, so a reply can belong to that request only.

use core::time::Duration;
use std::collections::{HashMap, VecDeque};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Instant;

use robobus_link::{BusErrorKind, FrameLinkError};
use robobus_whj::frame::padded_len;
use robobus_whj::{CanFrame, JointId, Reply, Request};

use super::bus::{BROADCAST_LOG, BusState, JointBusConfig, Shared, lock};
use super::cyclic::{CyclicRun, CyclicSetup};
use super::error::WhjError;

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
    /// ([`JointBusConfig::collision_window`]): two nodes answer at this ID. Neither is
    /// credited.
    Duplicate {
        /// The first reply.
        first: Reply,
        /// The second, different one.
        second: Reply,
    },
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
    fn check(self, reply: &Reply, frame: &CanFrame) -> Result<(), Unanswered> {
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
enum Unanswered {
    /// It answers another request (another register, another kind): a late reply to an
    /// earlier request that timed out, or one sent by another client. Ignored; the
    /// request keeps waiting.
    Other(String),
    /// It claims to answer this request but has the wrong shape: an error.
    Bad(String),
}

/// One transaction: a request and how to wait for its reply.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Txn {
    pub(crate) request: Request,
    pub(crate) expect: Expect,
    pub(crate) timeout: Duration,
    pub(crate) quiet_after: Duration,
    pub(crate) submitted: Instant,
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

#[derive(Debug)]
struct InFlight {
    id: TxnId,
    txn: Txn,
    sent: Instant,
    deadline: Instant,
}

/// A request whose reply arrived, held for the collision window: a second, different
/// reply to it before `until` makes it a [`Attempt::Duplicate`].
#[derive(Debug)]
struct Credited {
    id: TxnId,
    expect: Expect,
    frame: CanFrame,
    reply: Reply,
    until: Instant,
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

/// At most this many finished attempts wait to be taken (their callers gave up).
const MAX_DONE: usize = 4096;

/// The client's state of one bus (see the [module](self) notes).
#[derive(Debug)]
pub(crate) struct Session {
    shared: Arc<Shared>,
    config: JointBusConfig,
    next_id: TxnId,
    queued: VecDeque<(TxnId, Txn)>,
    in_flight: HashMap<u16, InFlight>,
    /// Replies received and held for the collision window, by reply ID.
    credited: HashMap<u16, Credited>,
    done: HashMap<TxnId, Attempt>,
    quiet: HashMap<u8, Instant>,
    passive_since: Option<Instant>,
    cyclic: Option<CyclicRun>,
    to_send: VecDeque<CanFrame>,
    /// Until when replies to the last broadcast frame are awaited (received at once
    /// rather than at the next drain).
    broadcast_until: Option<Instant>,
}

impl Session {
    pub(crate) fn new(shared: Arc<Shared>, config: JointBusConfig) -> Self {
        Self {
            shared,
            config,
            next_id: 0,
            queued: VecDeque::new(),
            in_flight: HashMap::new(),
            credited: HashMap::new(),
            done: HashMap::new(),
            quiet: HashMap::new(),
            passive_since: None,
            cyclic: None,
            to_send: VecDeque::new(),
            broadcast_until: None,
        }
    }

    /// Queues a transaction; its outcome is [`Session::take`]n once it is finished.
    pub(crate) fn submit(&mut self, txn: Txn) -> TxnId {
        self.next_id += 1;
        self.queued.push_back((self.next_id, txn));
        self.next_id
    }

    /// The outcome of a finished transaction.
    pub(crate) fn take(&mut self, id: TxnId) -> Option<Attempt> {
        self.done.remove(&id)
    }

    /// Forgets a transaction whose caller no longer waits for it.
    pub(crate) fn abandon(&mut self, id: TxnId) {
        self.done.remove(&id);
        self.queued.retain(|(i, _)| *i != id);
    }

    fn finish(&mut self, id: TxnId, outcome: Attempt) {
        if self.done.len() >= MAX_DONE {
            self.done.clear();
        }
        self.done.insert(id, outcome);
    }

    /// A broadcast frame went out at `now`: its replies are awaited for five reply
    /// timeouts.
    pub(crate) fn broadcast_sent(&mut self, now: Instant) {
        self.broadcast_until = Some(now + self.config.reply_timeout * 5);
    }

    /// Whether replies to a broadcast frame are still awaited at `now`.
    pub(crate) fn broadcast_pending(&self, now: Instant) -> bool {
        self.broadcast_until.is_some_and(|t| t > now)
    }

    /// Whether a cyclic loop runs.
    pub(crate) const fn cyclic_running(&self) -> bool {
        self.cyclic.is_some()
    }

    /// Starts a cyclic loop whose first tick is at `now`.
    pub(crate) fn start_cyclic(
        &mut self,
        setup: CyclicSetup,
        now: Instant,
    ) -> Result<(), WhjError> {
        if self.cyclic.is_some() {
            return Err(WhjError::InvalidConfig {
                reason: "a cyclic loop is already running on this bus".into(),
            });
        }
        self.cyclic = Some(CyclicRun::new(setup, now));
        self.shared.cyclic_running.store(true, Ordering::Release);
        Ok(())
    }

    /// Stops the cyclic loop, if one runs.
    pub(crate) fn stop_cyclic(&mut self) {
        if let Some(c) = self.cyclic.take() {
            c.finish();
        }
        self.to_send.clear();
        self.shared.cyclic_running.store(false, Ordering::Release);
    }

    /// Whether the cyclic loop's next tick is due at `now`: frames already received are
    /// read first, so that none is taken for the next cycle's.
    pub(crate) fn cyclic_due(&self, now: Instant) -> bool {
        self.cyclic.as_ref().is_some_and(|c| c.due(now))
    }

    /// Lets time pass: bus-error holds end, the cyclic loop ticks, attempts time out,
    /// settle times end.
    pub(crate) fn on_time(&mut self, now: Instant) {
        self.recover_passive(now);
        if let Some(c) = self.cyclic.as_mut()
            && c.due(now)
        {
            self.to_send.extend(c.tick(now));
        }
        self.expire(now);
    }

    /// The next frame to send now: the cyclic loop's first, then a queued request whose
    /// reply ID is free and whose joint is not settling. A request is in flight from here
    /// on; report a failed send with [`Session::send_failed`], a sent frame with
    /// [`Session::sent`].
    pub(crate) fn poll_transmit(&mut self, now: Instant) -> Option<Transmit> {
        if let Some(frame) = self.to_send.pop_front() {
            return Some(Transmit { frame, txn: None });
        }
        let bus_off = self.state() == BusState::BusOff;
        let mut i = 0;
        while let Some((id, txn)) = self.queued.get(i).copied() {
            let key = txn.request.reply_id().unwrap_or(0);
            let joint = txn.request.joint().map_or(0, JointId::get);
            if self.cyclic.as_ref().is_some_and(|c| c.owns(key)) {
                self.queued.remove(i);
                self.finish(id, Attempt::Busy);
                continue;
            }
            if bus_off {
                let waited = now.saturating_duration_since(txn.submitted);
                if waited >= self.config.bus_recovery_timeout {
                    self.queued.remove(i);
                    let detail = self.last_error();
                    self.finish(
                        id,
                        Attempt::Bus {
                            state: BusState::BusOff,
                            detail,
                            waited,
                        },
                    );
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
            self.in_flight.insert(
                key,
                InFlight {
                    id,
                    txn,
                    sent: now,
                    deadline: now + txn.timeout,
                },
            );
            return Some(Transmit {
                frame: txn.request.to_frame(),
                txn: Some((id, key)),
            });
        }
        None
    }

    /// A frame of [`Session::poll_transmit`] went out.
    pub(crate) fn sent(&self) {
        lock(&self.shared.telemetry).bus.frames_sent += 1;
    }

    /// A frame of [`Session::poll_transmit`] could not be sent.
    pub(crate) fn send_failed(&mut self, tx: &Transmit, e: &FrameLinkError, now: Instant) {
        let Some((id, key)) = tx.txn else {
            if let Some(c) = self.cyclic.as_ref() {
                c.send_failed(&tx.frame, &e.to_string());
            }
            return;
        };
        self.in_flight.remove(&key);
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
        self.finish(id, outcome);
    }

    /// Whether a frame is expected: a reply in flight, feedback of the running cycle, or
    /// a bus-off recovery that queued requests wait for. Only then does the driver block in
    /// the link's receive; otherwise it sleeps.
    pub(crate) fn awaiting(&self) -> bool {
        !self.in_flight.is_empty()
            || !self.credited.is_empty()
            || self.cyclic.as_ref().is_some_and(CyclicRun::awaiting)
            || (!self.queued.is_empty() && self.state() == BusState::BusOff)
    }

    /// Whether nothing is queued, in flight or cycling.
    pub(crate) fn is_idle(&self) -> bool {
        self.queued.is_empty()
            && self.in_flight.is_empty()
            && self.credited.is_empty()
            && self.cyclic.is_none()
    }

    /// When the driver must look again at the latest (a deadline, a tick, the end of a
    /// settle time, or the poll interval).
    pub(crate) fn next_wake(&self, now: Instant) -> Instant {
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

    /// A frame arrived at `now`.
    pub(crate) fn on_frame(&mut self, frame: &CanFrame, now: Instant) {
        let decoded = Reply::from_frame(frame);
        if frame.standard_raw_id().is_some_and(is_broadcast_reply_id) {
            let mut log = lock(&self.shared.broadcast_log);
            if log.len() >= BROADCAST_LOG {
                log.pop_front();
            }
            log.push_back((now, *frame));
        }
        {
            let mut t = lock(&self.shared.telemetry);
            t.bus.frames_received += 1;
            match &decoded {
                Ok(reply) => t.record(reply, now),
                Err(_) => t.bus.malformed += 1,
            }
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
        if let Some(c) = self.credited.get(&key) {
            // The request was answered already; this is a second answer to it if it
            // answers the same request, and a fault if it differs.
            let answers = decoded
                .as_ref()
                .is_ok_and(|reply| c.expect.check(reply, frame).is_ok());
            if let (true, Ok(second)) = (answers && c.frame != *frame, &decoded)
                && let Some(c) = self.credited.remove(&key)
            {
                tracing::warn!(first = ?c.reply, second = ?second, "two different replies to one WHJ request");
                lock(&self.shared.telemetry).bus.duplicates += 1;
                self.finish(
                    c.id,
                    Attempt::Duplicate {
                        first: c.reply,
                        second: *second,
                    },
                );
            } else {
                lock(&self.shared.telemetry).bus.unmatched += 1;
            }
            return;
        }
        let Some(f) = self.in_flight.remove(&key) else {
            lock(&self.shared.telemetry).bus.unmatched += 1;
            return;
        };
        if let Ok(reply) = &decoded
            && let Err(Unanswered::Other(reason)) = f.txn.expect.check(reply, frame)
        {
            // A late reply to something else: the request is still waiting for its own.
            tracing::debug!(%reason, "ignored a reply that answers another request");
            lock(&self.shared.telemetry).bus.unmatched += 1;
            self.in_flight.insert(key, f);
            return;
        }
        let outcome = match decoded {
            Ok(reply) => match f.txn.expect.check(&reply, frame) {
                Ok(()) => {
                    let ok_write = matches!(
                        reply,
                        Reply::WriteAck { status, .. } if status.is_ok()
                    );
                    if ok_write && !f.txn.quiet_after.is_zero() {
                        let joint = reply.joint().get();
                        self.quiet.insert(joint, now + f.txn.quiet_after);
                    }
                    if self.config.collision_window.is_zero() {
                        Attempt::Reply { reply }
                    } else {
                        self.credited.insert(
                            key,
                            Credited {
                                id: f.id,
                                expect: f.txn.expect,
                                frame: *frame,
                                reply,
                                until: now + self.config.collision_window,
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
        self.finish(f.id, outcome);
    }

    /// Credits the replies whose collision window closed by `now` (all with `None`).
    fn credit_due(&mut self, now: Option<Instant>) {
        let due: Vec<u16> = self
            .credited
            .iter()
            .filter(|(_, c)| now.is_none_or(|t| c.until <= t))
            .map(|(k, _)| *k)
            .collect();
        for key in due {
            if let Some(c) = self.credited.remove(&key) {
                self.finish(c.id, Attempt::Reply { reply: c.reply });
            }
        }
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
                self.finish(
                    f.id,
                    Attempt::Timeout {
                        waited: now.saturating_duration_since(f.sent),
                        state,
                    },
                );
            }
        }
        self.quiet.retain(|_, until| *until > now);
    }

    /// A receive failed with `e` at `now`. Bus errors change the bus state (a bus-off
    /// fails the requests in flight); a closed link fails everything.
    pub(crate) fn on_link_error(&mut self, e: &FrameLinkError, now: Instant) {
        match e {
            FrameLinkError::BusOff { .. }
            | FrameLinkError::ErrorPassive { .. }
            | FrameLinkError::BusError { .. } => {
                self.link_error_state(e, now);
                if self.state() == BusState::BusOff {
                    let detail = e.to_string();
                    let failed: Vec<InFlight> = self.in_flight.drain().map(|(_, f)| f).collect();
                    for f in failed {
                        self.finish(
                            f.id,
                            Attempt::Bus {
                                state: BusState::BusOff,
                                detail: detail.clone(),
                                waited: now.saturating_duration_since(f.sent),
                            },
                        );
                    }
                }
            }
            FrameLinkError::Closed { .. } => self.fail_all(&e.to_string()),
            other => {
                tracing::warn!(error = %other, "WHJ bus receive error");
                lock(&self.shared.telemetry).bus.last_error = Some(other.to_string());
            }
        }
    }

    /// The link is gone: every transaction fails with `detail`, the cyclic loop ends.
    pub(crate) fn fail_all(&mut self, detail: &str) {
        self.credit_due(None);
        let in_flight: Vec<TxnId> = self.in_flight.drain().map(|(_, f)| f.id).collect();
        let queued: Vec<TxnId> = self.queued.drain(..).map(|(id, _)| id).collect();
        for id in in_flight.into_iter().chain(queued) {
            self.finish(id, Attempt::Link(detail.to_owned()));
        }
        self.stop_cyclic();
    }

    fn state(&self) -> BusState {
        lock(&self.shared.telemetry).bus.state
    }

    fn set_state(&self, state: BusState, detail: Option<String>) {
        let mut t = lock(&self.shared.telemetry);
        let was = t.bus.state;
        if was != state && state == BusState::Active {
            t.bus.recoveries += 1;
            tracing::info!(from = %was, "CAN bus recovered");
        }
        t.bus.state = state;
        if let Some(d) = detail {
            t.bus.last_error = Some(d);
        }
    }

    fn recover_passive(&mut self, now: Instant) {
        if let Some(since) = self.passive_since
            && now.saturating_duration_since(since) >= self.config.error_passive_hold
        {
            self.passive_since = None;
            if matches!(
                self.state(),
                BusState::ErrorPassive | BusState::ErrorWarning
            ) {
                self.set_state(BusState::Active, None);
            }
        }
    }

    fn last_error(&self) -> String {
        lock(&self.shared.telemetry)
            .bus
            .last_error
            .clone()
            .unwrap_or_else(|| "no detail".into())
    }

    /// Applies a bus error reported at `now` to the state.
    fn link_error_state(&mut self, e: &FrameLinkError, now: Instant) {
        let detail = Some(e.to_string());
        let mut t = lock(&self.shared.telemetry);
        match e {
            FrameLinkError::BusOff { .. } => {
                t.bus.bus_off_events += 1;
                drop(t);
                tracing::warn!(error = %e, "CAN bus-off");
                self.set_state(BusState::BusOff, detail);
            }
            FrameLinkError::ErrorPassive { .. } => {
                t.bus.error_passive_events += 1;
                let state = t.bus.state;
                drop(t);
                self.passive_since = Some(now);
                if state != BusState::BusOff {
                    self.set_state(BusState::ErrorPassive, detail);
                }
            }
            FrameLinkError::BusError { kind, .. } => {
                t.bus.other_bus_errors += 1;
                let state = t.bus.state;
                drop(t);
                match kind {
                    BusErrorKind::Restarted => self.set_state(BusState::Active, detail),
                    BusErrorKind::BusOff => self.set_state(BusState::BusOff, detail),
                    BusErrorKind::ErrorPassive => {
                        self.passive_since = Some(now);
                        if state != BusState::BusOff {
                            self.set_state(BusState::ErrorPassive, detail);
                        }
                    }
                    BusErrorKind::ErrorWarning => {
                        self.passive_since = Some(now);
                        if state == BusState::Active {
                            self.set_state(BusState::ErrorWarning, detail);
                        }
                    }
                    BusErrorKind::NoAck | BusErrorKind::Other { .. } => {
                        lock(&self.shared.telemetry).bus.last_error = detail;
                    }
                }
            }
            _ => {
                t.bus.last_error = detail;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use robobus_whj::RegisterAddr;
    use robobus_whj::request::ReadRange;

    fn j1() -> JointId {
        JointId::new(1).unwrap()
    }

    fn read(addr: u8, count: u8) -> (Request, ReadRange) {
        let range = ReadRange::new(RegisterAddr::new(addr).unwrap(), count).unwrap();
        (Request::Read { joint: j1(), range }, range)
    }

    /// Replies credited at once (the tests of other rules than the collision window).
    fn no_window() -> JointBusConfig {
        JointBusConfig {
            collision_window: Duration::ZERO,
            ..JointBusConfig::default()
        }
    }

    fn txn(request: Request, submitted: Instant) -> Txn {
        Txn {
            request,
            expect: Expect::of(&request).unwrap(),
            timeout: Duration::from_millis(20),
            quiet_after: Duration::ZERO,
            submitted,
        }
    }

    #[test]
    fn a_reply_to_another_register_is_not_credited_and_the_deadline_is_exact() {
        let t0 = Instant::now();
        let mut s = Session::new(Arc::default(), no_window());
        let (req, _) = read(0x14, 2);
        let id = s.submit(txn(req, t0));
        let tx = s.poll_transmit(t0).unwrap();
        assert_eq!(tx.frame, req.to_frame());
        // A second request on the same reply ID waits for the first.
        let (other, other_range) = read(0x2A, 6);
        let second = s.submit(txn(other, t0));
        assert!(s.poll_transmit(t0).is_none());
        // A late reply for register 0x2A arrives: it answers another request, so the read
        // of 0x14 keeps waiting.
        let late = Reply::read(j1(), other_range, &[0; 6]).unwrap();
        s.on_frame(&late.to_frame(), t0 + Duration::from_millis(1));
        assert!(s.take(id).is_none());
        // Nothing else comes: it times out exactly at its deadline, not before.
        s.on_time(t0 + Duration::from_micros(19_999));
        assert!(s.take(id).is_none());
        s.on_time(t0 + Duration::from_millis(20));
        assert!(matches!(
            s.take(id),
            Some(Attempt::Timeout { waited, state: BusState::Active }) if waited == Duration::from_millis(20)
        ));
        // Now the second request goes out, and the same reply is credited to it.
        let t1 = t0 + Duration::from_millis(20);
        assert_eq!(s.poll_transmit(t1).unwrap().frame, other.to_frame());
        s.on_frame(&late.to_frame(), t1);
        let got = s.take(second);
        assert!(
            matches!(&got, Some(Attempt::Reply { reply: Reply::Read { addr, words, .. } }) if addr.get() == 0x2A && words.len() >= 6),
            "{got:?}"
        );
    }

    #[test]
    fn a_settle_time_holds_the_next_request_to_the_joint_until_it_ends() {
        let t0 = Instant::now();
        let mut s = Session::new(Arc::default(), no_window());
        let write = Request::write(j1(), RegisterAddr::new(0x0A).unwrap(), 0).unwrap();
        let id = s.submit(Txn {
            quiet_after: Duration::from_millis(5),
            ..txn(write, t0)
        });
        s.poll_transmit(t0).unwrap();
        let ack = Reply::WriteAck {
            joint: j1(),
            addr: RegisterAddr::new(0x0A).unwrap(),
            status: robobus_whj::reply::WriteStatus::Ok,
        };
        s.on_frame(&ack.to_frame(), t0);
        assert!(matches!(s.take(id), Some(Attempt::Reply { .. })));
        let (req, _) = read(0x14, 2);
        s.submit(txn(req, t0));
        let settled = t0 + Duration::from_millis(5);
        assert_eq!(s.next_wake(t0), t0 + Duration::from_micros(500));
        assert!(s.poll_transmit(t0 + Duration::from_micros(4_999)).is_none());
        assert_eq!(s.poll_transmit(settled).unwrap().frame, req.to_frame());
    }

    #[test]
    fn a_second_different_reply_within_the_collision_window_is_a_duplicate_not_a_value() {
        let t0 = Instant::now();
        let window = JointBusConfig::default().collision_window;
        assert_eq!(window, Duration::from_micros(500));
        let mut s = Session::new(Arc::default(), JointBusConfig::default());
        let (req, range) = read(0x14, 2);
        let id = s.submit(txn(req, t0));
        s.poll_transmit(t0).unwrap();
        let first = Reply::read(j1(), range, &[0, 0]).unwrap();
        let second = Reply::read(j1(), range, &[0x1A80, 0x0007]).unwrap();
        let t1 = t0 + Duration::from_micros(200);
        s.on_frame(&first.to_frame(), t1);
        // Held for the window: not credited yet, and the reply ID stays busy.
        assert!(s.take(id).is_none());
        assert_eq!(s.next_wake(t1), t1 + window);
        let next = s.submit(txn(req, t1));
        assert!(s.poll_transmit(t1).is_none());
        // The joint that lost arbitration answers too, differently: a fault.
        s.on_frame(&second.to_frame(), t1 + Duration::from_micros(150));
        let got = s.take(id);
        assert!(
            matches!(&got, Some(Attempt::Duplicate { first: f, second: g }) if *f == first && *g == second),
            "{got:?}"
        );
        // The next request goes out, and one reply (or identical ones) is credited once
        // the window closed, not before.
        let t2 = t1 + Duration::from_micros(150);
        assert!(s.poll_transmit(t2).is_some());
        s.on_frame(&first.to_frame(), t2);
        s.on_frame(&first.to_frame(), t2 + Duration::from_micros(100));
        s.on_time(t2 + Duration::from_micros(499));
        assert!(s.take(next).is_none());
        s.on_time(t2 + window);
        assert!(matches!(s.take(next), Some(Attempt::Reply { reply }) if reply == first));
        assert_eq!(lock(&s.shared.telemetry).bus.duplicates, 1);
    }
}
