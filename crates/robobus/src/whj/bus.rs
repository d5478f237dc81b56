//! [`JointBus`], the driver of the WHJ client: the frame link and the sans-IO
//! [`Session`](super::session) behind one lock, driven by the caller's thread for request /
//! reply work and by a thread of its own for the cyclic loop; it publishes what the
//! session polls out ([`BusTelemetry`], the loop's reports) where callers read it without
//! that lock. `driving.rs` holds the lock and the step, `mailbox.rs` a loop's exchange with
//! its handle, `status_by_broadcast.rs` the status query of a link that cannot send a
//! frame without data.

use core::time::Duration;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Sender};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::Instant;

use robobus_link::{FrameLink, FrameLinkError};
use robobus_whj::{CanFrame, JointId, Reply, Request};

use super::error::{WhjError, attempt_error};
use super::identity::Identity;
use super::session::cyclic::{CyclicSetup, CyclicStats};
use super::session::{Attempt, BusTelemetry, Expect, JointBusConfig, Outcome, Session, Txn, TxnId};

mod driving;
mod mailbox;
mod status_by_broadcast;

use driving::{Core, CoreLock, Wake, background};
pub(crate) use mailbox::{CyclicMailbox, Polled};

/// What the driver publishes for callers, readable without the session's lock, and the
/// caches its handles keep per bus.
#[derive(Debug, Default)]
pub(crate) struct Shared {
    /// The session's telemetry as of the last time the lock was let go.
    pub(crate) telemetry: Mutex<BusTelemetry>,
    /// The identity of each joint, read once per bus (by index = joint ID), so short-lived
    /// [`Joint`](super::Joint) handles do not read it again.
    pub(crate) identities: Mutex<[Option<Identity>; 31]>,
    /// Each joint's position limits (0x44..0x47) as last read, forgotten when a frame that
    /// can write them goes out ([`JointBus::forget_limits_written_by`]).
    pub(crate) limits:
        Mutex<[Option<(robobus_whj::units::Position, robobus_whj::units::Position)>; 31]>,
    pub(crate) fatal: Mutex<Option<String>>,
    pub(crate) cyclic_running: AtomicBool,
}

pub(crate) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The most requests [`JointBus::request_many`] and [`JointBus::servo_many`] take in one
/// batch.
pub const MAX_PIPELINED: usize = 256;

/// `n` requests (`what`: "requests", "servo frames") fit in one pipelined batch, or the
/// error that says how many were given and how many fit.
pub(crate) fn within_batch(n: usize, what: &str) -> Result<(), WhjError> {
    if n > MAX_PIPELINED {
        return Err(WhjError::InvalidConfig {
            reason: format!("{n} {what} given, at most {MAX_PIPELINED} go in one pipelined batch"),
        });
    }
    Ok(())
}

/// A WHJ CAN FD bus: owns a [`FrameLink`] and hands out [`Joint`](super::Joint) handles.
///
/// The bus keeps a sans-IO session (request matching, deadlines, settle times, bus-error
/// state, the cyclic loop) next to its link, behind one lock. A request / reply is driven
/// by the caller's own thread: it sends the request and receives on the link itself until
/// its reply is there, with no hand-off to another thread. Whoever holds the lock drives
/// the whole session, so frames for other requests, the cyclic loop's ticks and
/// unsolicited frames are all handled by whichever thread is receiving. A thread of the
/// bus's own runs the cyclic loop ([`JointBus::cyclic`]) and, while nothing else uses the
/// bus, picks up unsolicited frames (other hosts' traffic, controller error reports) now
/// and then for [`BusTelemetry`]. On a link with a virtual clock there is no such thread:
/// the cyclic loop then runs while a caller waits (a request, [`JointBus::sleep_until`],
/// [`Cyclic::next_report`](super::Cyclic::next_report)).
///
/// Replies are matched to requests by CAN ID and function (`0x100+ID` read / write /
/// `CMD_ERR`, `0x500+ID` servo feedback, `0x700+ID` status). At most one request per
/// reply ID is in flight at a time, so a reply can only belong to that request; requests
/// from several threads queue up. [`JointBus::request_many`] sends requests to many
/// joints at once and collects the replies.
///
/// Time comes from the link ([`FrameLink::now`], [`FrameLink::sleep_until`]): the wall
/// clock on real links, virtual time on a simulated bus.
///
/// Bus errors: a bus-off report fails the requests in flight ([`WhjError::Bus`]) and
/// holds new ones until the bus has **recovered**, which means: the link reported a
/// controller restart, or any frame arrived again. Error-passive and error-warning reports
/// are surfaced in [`BusTelemetry::bus`] and in timeout errors; they count as recovered after
/// [`JointBusConfig::error_passive_hold`] without a new report. Reads and idempotent
/// operations are resent after a recovery; nothing else is.
#[derive(Debug)]
pub struct JointBus {
    core: Arc<CoreLock>,
    shared: Arc<Shared>,
    config: JointBusConfig,
    virtual_time: bool,
    /// Whether the link sends frames without data ([`FrameLink::sends_empty_frames`]);
    /// when not, status queries go by broadcast.
    empty_frames: bool,
    /// The duplicate check's allowance for the link's lateness (`None`: off).
    duplicate_check: Option<Duration>,
    wake: Mutex<Sender<Wake>>,
    thread: Option<JoinHandle<()>>,
}

impl JointBus {
    /// Opens a bus on `link` with [`JointBusConfig::default`] and starts its thread.
    pub fn open<L: FrameLink + Send + 'static>(link: L) -> Result<Self, WhjError> {
        Self::open_with(link, JointBusConfig::default())
    }

    /// Opens a bus on `link` with `config` and starts its thread.
    pub fn open_with<L: FrameLink + Send + 'static>(
        link: L,
        config: JointBusConfig,
    ) -> Result<Self, WhjError> {
        let shared = Arc::new(Shared::default());
        let last_drain = link.now();
        let virtual_time = link.virtual_time();
        let empty_frames = link.sends_empty_frames();
        let session = Session::on_link(config, link.reply_allowance());
        let duplicate_check = session.allowance();
        let core = Arc::new(CoreLock::new(Core {
            link: Box::new(link),
            session,
            shared: Arc::clone(&shared),
            cyclic: None,
            last_drain,
            closed: false,
        }));
        let (tx, rx) = mpsc::channel();
        // On virtual time the clock moves only when someone drives the link: the cyclic
        // loop runs whenever a caller waits ([`JointBus::sleep_until`], a request, a
        // cycle report), and no thread may run it ahead on the wall clock.
        let thread = if virtual_time {
            None
        } else {
            let thread_core = Arc::clone(&core);
            Some(
                std::thread::Builder::new()
                    .name("whj-bus".into())
                    .spawn(move || background(&thread_core, &rx))
                    .map_err(|e| WhjError::Link {
                        detail: format!("cannot start the bus thread: {e}"),
                    })?,
            )
        };
        Ok(Self {
            core,
            shared,
            config,
            virtual_time,
            empty_frames,
            duplicate_check,
            wake: Mutex::new(tx),
            thread,
        })
    }

    /// The bus settings.
    pub const fn config(&self) -> &JointBusConfig {
        &self.config
    }

    /// Whether replies are held for a second answer from a duplicate node, and how much
    /// later than the wire the link may deliver it: [`JointBusConfig::collision_window`]
    /// if set, else the link's own [`FrameLink::reply_allowance`]; `None` when the check
    /// is off (`collision_window: Some(Duration::ZERO)`).
    pub const fn duplicate_check(&self) -> Option<Duration> {
        self.duplicate_check
    }

    /// The bus's clock: the link's ([`FrameLink::now`]). Instants in [`BusTelemetry`] and
    /// cycle reports are on this clock.
    pub fn now(&self) -> Instant {
        self.core.lock().now()
    }

    /// Whether the bus runs on a virtual clock ([`FrameLink::virtual_time`]).
    pub const fn virtual_time(&self) -> bool {
        self.virtual_time
    }

    /// Waits until the bus's clock reaches `deadline`, receiving frames meanwhile (into
    /// [`BusTelemetry`]; the cyclic loop keeps its ticks). On a simulated bus on virtual time
    /// this returns as soon as simulated time got there.
    pub fn sleep_until(&self, deadline: Instant) {
        loop {
            let mut core = self.core.lock();
            if core.now() >= deadline || core.closed {
                return;
            }
            core.step(deadline, true);
        }
    }
    /// Joint `id`'s position limits as this bus last read them, if it did.
    pub(crate) fn cached_limits(
        &self,
        id: JointId,
    ) -> Option<(robobus_whj::units::Position, robobus_whj::units::Position)> {
        lock(&self.shared.limits)
            .get(usize::from(id.get()))
            .copied()
            .flatten()
    }

    pub(crate) fn cache_limits(
        &self,
        id: JointId,
        limits: (robobus_whj::units::Position, robobus_whj::units::Position),
    ) {
        if let Some(slot) = lock(&self.shared.limits).get_mut(usize::from(id.get())) {
            *slot = Some(limits);
        }
    }

    /// Forgets the cached position limits that `request` may change: a write into
    /// 0x44..=0x47, point-to-point or in a joint's slot of a 0x0F frame, forgets that
    /// joint's.
    fn forget_limits_written_by(&self, request: &Request) {
        use robobus_whj::broadcast::{RegisterOp, RegisterSlot};
        use robobus_whj::registers::addr;
        let lo = addr::LIT_MIN_POSITION.get();
        let hi = addr::LIT_MAX_POSITION.get() + 1;
        let touches = |addr: robobus_whj::RegisterAddr, data: robobus_whj::WriteData| {
            let first = addr.get();
            let words = u8::try_from(data.to_bytes().1.div_ceil(2)).unwrap_or(2);
            first <= hi && first + words > lo
        };
        let mut limits = lock(&self.shared.limits);
        match *request {
            Request::Write { joint, addr, data } if touches(addr, data) => {
                if let Some(slot) = limits.get_mut(usize::from(joint.get())) {
                    *slot = None;
                }
            }
            Request::BroadcastRegister(ref b) => {
                for (k, slot) in b.slots.iter().enumerate() {
                    if let RegisterSlot::Op(RegisterOp::Write { addr, data }) = *slot
                        && touches(addr, data)
                        && let Some(cached) = limits.get_mut(k + 1)
                    {
                        *cached = None;
                    }
                }
            }
            _ => {}
        }
    }

    /// The identity this bus has read from joint `id`, if any.
    pub fn cached_identity(&self, id: JointId) -> Option<Identity> {
        lock(&self.shared.identities)
            .get(usize::from(id.get()))
            .copied()
            .flatten()
    }

    pub(crate) fn cache_identity(&self, id: JointId, identity: Identity) {
        if let Some(slot) = lock(&self.shared.identities).get_mut(usize::from(id.get())) {
            *slot = Some(identity);
        }
    }

    /// Sends one point-to-point request and waits for its reply (one attempt, no retry;
    /// timeout [`JointBusConfig::reply_timeout`]). A `CMD_ERR` reply is returned as a
    /// reply. Broadcast requests are refused ([`WhjError::InvalidConfig`]); use
    /// [`JointBus::cyclic`] with [`Protocol::Broadcast`](super::Protocol::Broadcast).
    pub fn request(&self, request: Request) -> Result<Reply, WhjError> {
        self.request_with_timeout(request, self.config.reply_timeout)
    }

    /// [`JointBus::request`] with its own reply timeout.
    pub fn request_with_timeout(
        &self,
        request: Request,
        timeout: Duration,
    ) -> Result<Reply, WhjError> {
        let joint = request.joint().ok_or_else(|| WhjError::InvalidConfig {
            reason: "broadcast frames are sent by the cyclic loop, not as single requests".into(),
        })?;
        match self.transact(request, timeout, Duration::ZERO, 1)?.attempt {
            Attempt::Reply { reply, .. } => Ok(reply),
            other => Err(attempt_error(joint, &request, other, 1)),
        }
    }

    /// Sends one broadcast frame (0x7F status query, 0x0F register access, ...) outside a
    /// cyclic loop and returns when it went out. Replies are not matched to it: they land
    /// in [`BusTelemetry`] (newer than the returned instant), see
    /// [`ops::whj::broadcast_status`](crate::ops::whj::broadcast_status). A point-to-point
    /// request is refused ([`WhjError::InvalidConfig`]).
    pub fn send_broadcast(&self, request: Request) -> Result<Instant, WhjError> {
        if request.joint().is_some() {
            return Err(WhjError::InvalidConfig {
                reason: "send_broadcast takes broadcast frames only; use request()".into(),
            });
        }
        let mut core = self.core.lock();
        if core.closed {
            return Err(self.closed_error());
        }
        if core.session.cyclic_running() {
            return Err(WhjError::InvalidConfig {
                reason: "a cyclic loop is running on this bus".into(),
            });
        }
        self.forget_limits_written_by(&request);
        let at = core.now();
        match core.link.send(&request.to_frame()) {
            Ok(()) => {
                core.session.handle_broadcast_sent(at);
                drop(core);
                // The bus's thread receives the replies meanwhile.
                let _ = lock(&self.wake).send(Wake::Work);
                Ok(at)
            }
            Err(e) => {
                if matches!(e, FrameLinkError::Closed { .. }) {
                    core.fatal(&e);
                }
                Err(WhjError::Link {
                    detail: e.to_string(),
                })
            }
        }
    }

    /// The frames received on broadcast reply IDs (joints' `0x80+ID+1` / `0xF0+ID+1`,
    /// J6's 0x5FE / 0x3FE, the end board's 0x87 / 0xF7) strictly after `since` (the instant
    /// [`JointBus::send_broadcast`] returned), with their receive instants, oldest first.
    /// The bus keeps the last 64 of them.
    pub fn broadcast_replies_since(&self, since: Instant) -> Vec<(Instant, CanFrame)> {
        self.core.lock().session.broadcast_replies_since(since)
    }

    /// A snapshot of the bus health and the latest values from every joint.
    pub fn telemetry(&self) -> BusTelemetry {
        lock(&self.shared.telemetry).clone()
    }

    /// Whether a cyclic loop is running.
    pub fn cyclic_running(&self) -> bool {
        self.shared.cyclic_running.load(Ordering::Acquire)
    }

    pub(crate) fn closed_error(&self) -> WhjError {
        match lock(&self.shared.fatal).clone() {
            Some(detail) => WhjError::Link { detail },
            None => WhjError::Closed,
        }
    }

    /// One transaction: `request` with up to `attempts` attempts of `timeout` each (the
    /// session resends it after an outcome that allows it), then nothing more to its joint
    /// for `quiet_after` after a successful write ack.
    pub(crate) fn transact(
        &self,
        request: Request,
        timeout: Duration,
        quiet_after: Duration,
        attempts: u32,
    ) -> Result<Outcome, WhjError> {
        self.run(&[request], timeout, quiet_after, attempts)?
            .pop()
            .unwrap_or_else(|| Err(self.closed_error()))
    }

    /// Each of `requests` with up to `attempts` attempts of
    /// [`JointBusConfig::reply_timeout`] each, pipelined as in [`JointBus::attempt_many`];
    /// outcomes in request order.
    pub(crate) fn transact_many(
        &self,
        requests: &[Request],
        attempts: u32,
    ) -> Result<Vec<Result<Outcome, WhjError>>, WhjError> {
        self.run(
            requests,
            self.config.reply_timeout,
            Duration::ZERO,
            attempts,
        )
    }

    /// One attempt of each of `requests`, pipelined: all are queued at once, each goes out
    /// as soon as its reply ID is free (at once for requests to different joints), and
    /// each reply is credited to its own request only. Outcomes in request order.
    pub(crate) fn attempt_many(
        &self,
        requests: &[Request],
        timeout: Duration,
    ) -> Result<Vec<Result<Attempt, WhjError>>, WhjError> {
        Ok(self
            .run(requests, timeout, Duration::ZERO, 1)?
            .into_iter()
            .map(|o| o.map(|o| o.attempt))
            .collect())
    }

    /// Submits one transaction per request and drives the session until every one is
    /// finished; their outcomes in request order. On a link that cannot send a frame
    /// without data, status queries are asked by broadcast instead
    /// ([`JointBus::run_status_by_broadcast`]).
    fn run(
        &self,
        requests: &[Request],
        timeout: Duration,
        quiet_after: Duration,
        attempts: u32,
    ) -> Result<Vec<Result<Outcome, WhjError>>, WhjError> {
        if !self.empty_frames
            && requests
                .iter()
                .any(|r| matches!(r, Request::StatusQuery { .. }))
        {
            return self.run_status_by_broadcast(requests, timeout, quiet_after, attempts);
        }
        self.run_session(requests, timeout, quiet_after, attempts)
    }

    /// [`JointBus::run`] through the session, every request as it is.
    fn run_session(
        &self,
        requests: &[Request],
        timeout: Duration,
        quiet_after: Duration,
        attempts: u32,
    ) -> Result<Vec<Result<Outcome, WhjError>>, WhjError> {
        let mut txns = Vec::with_capacity(requests.len());
        for request in requests {
            let expect = Expect::of(request).ok_or_else(|| WhjError::InvalidConfig {
                reason: "broadcast frames are not single requests".into(),
            })?;
            self.forget_limits_written_by(request);
            txns.push((*request, expect));
        }
        let attempts = attempts.max(1);
        let mut core = self.core.lock();
        if core.closed {
            return Err(self.closed_error());
        }
        let submitted = core.now();
        let ids: Vec<TxnId> = txns
            .into_iter()
            .map(|(request, expect)| {
                core.session.submit(Txn {
                    request,
                    expect,
                    timeout,
                    quiet_after,
                    submitted,
                    attempts,
                })
            })
            .collect();
        drop(core);
        // Every attempt has a deadline, so the session always finishes a transaction; the
        // limit only guards against a session that lost one. Requests on one reply ID go
        // one after another, so the limit grows with the batch, and with the attempts.
        let batch = u32::try_from(ids.len().clamp(1, MAX_PIPELINED)).unwrap_or(1);
        let per_attempt = timeout.saturating_mul(batch)
            + self.config.bus_recovery_timeout
            + self.config.save_settle
            + Duration::from_secs(2);
        let limit = submitted
            .checked_add(per_attempt.saturating_mul(attempts))
            .unwrap_or(submitted + per_attempt);
        Ok(self.finish_all(&ids, limit))
    }

    /// Drives the session until every transaction of `ids` is finished, or until `limit`;
    /// their outcomes in the same order.
    fn finish_all(&self, ids: &[TxnId], limit: Instant) -> Vec<Result<Outcome, WhjError>> {
        let mut out: Vec<Option<Result<Outcome, WhjError>>> = ids.iter().map(|_| None).collect();
        loop {
            let mut core = self.core.lock();
            for (slot, id) in out.iter_mut().zip(ids) {
                if slot.is_none() {
                    *slot = core.session.poll_outcome(*id).map(Ok);
                }
            }
            if out.iter().all(Option::is_some) {
                break;
            }
            if core.closed || core.now() >= limit {
                for (slot, id) in out.iter_mut().zip(ids) {
                    if slot.is_none() {
                        core.session.abandon(*id);
                        *slot = Some(Err(self.closed_error()));
                    }
                }
                break;
            }
            core.step(limit, false);
        }
        out.into_iter()
            .map(|o| o.unwrap_or_else(|| Err(self.closed_error())))
            .collect()
    }

    /// Point-to-point requests to many joints at once (send all, then collect): one
    /// attempt each, no retry, timeout [`JointBusConfig::reply_timeout`]. Each reply is
    /// credited only to the request it answers; results are in request order, a
    /// `CMD_ERR` reply returned as a reply. At most [`MAX_PIPELINED`] requests; broadcast
    /// requests are refused ([`WhjError::InvalidConfig`]).
    pub fn request_many(
        &self,
        requests: &[Request],
    ) -> Result<Vec<Result<Reply, WhjError>>, WhjError> {
        within_batch(requests.len(), "requests")?;
        let mut joints = Vec::with_capacity(requests.len());
        for r in requests {
            joints.push(r.joint().ok_or_else(|| WhjError::InvalidConfig {
                reason:
                    "broadcast frames are sent by the cyclic loop, not as single requests".into(),
            })?);
        }
        let outcomes = self.attempt_many(requests, self.config.reply_timeout)?;
        Ok(outcomes
            .into_iter()
            .zip(requests.iter().zip(joints))
            .map(|(outcome, (request, joint))| match outcome? {
                Attempt::Reply { reply } => Ok(reply),
                other => Err(attempt_error(joint, request, other, 1)),
            })
            .collect())
    }

    /// Starts the session's cyclic loop with `setup`, its handle's side in `mailbox`.
    pub(crate) fn start_cyclic(
        &self,
        setup: CyclicSetup,
        mailbox: Arc<CyclicMailbox>,
    ) -> Result<(), WhjError> {
        let mut core = self.core.lock();
        if core.closed {
            return Err(self.closed_error());
        }
        let now = core.now();
        if !core.session.start_cyclic(setup, now) {
            return Err(WhjError::InvalidConfig {
                reason: "a cyclic loop is already running on this bus".into(),
            });
        }
        core.cyclic = Some(mailbox);
        drop(core);
        let _ = lock(&self.wake).send(Wake::Work);
        Ok(())
    }

    /// Stops the loop of `mailbox`, if it still runs; its end is in the mailbox on return.
    pub(crate) fn stop_cyclic(&self, mailbox: &Arc<CyclicMailbox>) {
        let mut core = self.core.lock();
        if core
            .cyclic
            .as_ref()
            .is_some_and(|m| Arc::ptr_eq(m, mailbox))
        {
            core.session.stop_cyclic();
        }
    }

    /// The statistics of the loop of `mailbox`: so far while it runs, final once it ended.
    pub(crate) fn cyclic_stats(&self, mailbox: &Arc<CyclicMailbox>) -> CyclicStats {
        let running = {
            let core = self.core.lock();
            core.cyclic
                .as_ref()
                .filter(|m| Arc::ptr_eq(m, mailbox))
                .and_then(|_| core.session.cyclic_stats())
        };
        let stats = running.or_else(|| mailbox.ended()).unwrap_or_default();
        mailbox.with_dropped(stats)
    }
}

impl Drop for JointBus {
    fn drop(&mut self) {
        let _ = lock(&self.wake).send(Wake::Shutdown);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
