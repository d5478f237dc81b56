//! [`JointBus`]: the frame link and the client session behind one lock, driven by the
//! caller's thread for request / reply work and by a thread of its own for the cyclic
//! loop; [`Telemetry`] of what arrived.

use core::fmt;
use core::time::Duration;
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender, TryRecvError};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::Instant;

use robobus_link::{FrameLink, FrameLinkError};
use robobus_whj::registers::{self, UniqueId};
use robobus_whj::units::{ActualSpeed, Current, Position, Temperature, Voltage};
use robobus_whj::{CanFrame, ErrorCode, JointId, Reply, Request};

use super::cyclic::CyclicSetup;
use super::error::WhjError;
use super::joint::Joint;
use super::session::{Attempt, Expect, Session, Txn, TxnId};

/// Settings of a [`JointBus`]. `JointBusConfig::default()` follows the protocol reference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointBusConfig {
    /// How long one attempt waits for its reply (default 20 ms; a reply normally takes
    /// about 0.2 ms on a real 1 / 5 Mbit/s bus).
    pub reply_timeout: Duration,
    /// Extra attempts for reads and idempotent operations (default 2). Operations that
    /// are not idempotent (set zero, save to flash) are never resent.
    pub retries: u32,
    /// How long [`JointBus::joint`] keeps sending the IAP release before it calls a joint
    /// silent (default 5 s: joints with a staggered power-up stay silent for a while, C33).
    pub connect_timeout: Duration,
    /// Confirm every register read by a second, identical read (status queries and servo
    /// feedback are not confirmed: they change from frame to frame). For links that can
    /// deliver a corrupted payload (fault injection, a gateway without a checksum): a CAN
    /// controller drops corrupted frames itself (CRC), so this is off by default. Without
    /// it, replies are still matched by register, count and length, so a corrupted
    /// request or header is caught; only a flipped data bit is not.
    pub verify_reads: bool,
    /// Largest position step, degrees, that a single position command may make from the
    /// actual position (default 5°, half the joint's 10° protection, C10). Larger moves go
    /// through [`Joint::move_to`] or the cyclic loop's trajectory.
    pub step_limit_deg: f64,
    /// Quiet time after a disable during which nothing is sent to that joint (5 ms, §6.3).
    pub disable_settle: Duration,
    /// Quiet time after a save to flash (50 ms, §6.4).
    pub save_settle: Duration,
    /// How long a request waits for a bus-off controller to recover before it fails
    /// (default 1 s).
    pub bus_recovery_timeout: Duration,
    /// After an error-passive or error-warning report, how long without a new report
    /// before the bus counts as recovered (default 1 s).
    pub error_passive_hold: Duration,
    /// How long a received reply is held before it is credited (default 0.5 ms): a
    /// second, different reply to the same request within it (two nodes at one ID; the
    /// one that lost arbitration follows the winner within one frame, about 0.15 ms at
    /// 1 / 5 Mbit/s) fails the request with [`WhjError::DuplicateReply`] instead of
    /// crediting either. The next request on that reply ID waits for the window too.
    /// Zero credits the first reply at once (no duplicate detection).
    pub collision_window: Duration,
    /// The longest one receive or sleep of the driving thread lasts before it looks at
    /// the session again and lets other threads in (default 0.5 ms).
    pub poll_interval: Duration,
}

impl Default for JointBusConfig {
    fn default() -> Self {
        Self {
            reply_timeout: Duration::from_millis(20),
            retries: 2,
            connect_timeout: Duration::from_secs(5),
            verify_reads: false,
            step_limit_deg: 5.0,
            disable_settle: Duration::from_millis(5),
            save_settle: Duration::from_millis(50),
            bus_recovery_timeout: Duration::from_secs(1),
            error_passive_hold: Duration::from_secs(1),
            collision_window: Duration::from_micros(500),
            poll_interval: Duration::from_micros(500),
        }
    }
}

impl JointBusConfig {
    /// Settings for simulated joints on the same machine (`robobus sim whj`, an in-process
    /// `robobus_sim::whj` bus): a 250 ms reply timeout and 5 retries instead of 20 ms and
    /// 2. The simulator is a thread or process that a loaded (or shared, virtual) machine
    /// can hold for hundreds of milliseconds; a real joint answers in about 0.2 ms.
    #[must_use]
    pub fn simulated() -> Self {
        Self {
            reply_timeout: Duration::from_millis(250),
            retries: 5,
            ..Self::default()
        }
    }
}

/// The CAN controller state as the client last saw it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum BusState {
    /// Error active: working normally.
    #[default]
    Active,
    /// Error warning (error counter ≥ 96): still working.
    ErrorWarning,
    /// Error passive (error counter ≥ 128): still working, many frames fail.
    ErrorPassive,
    /// Bus-off: the controller sends and receives nothing until it restarts.
    BusOff,
}

impl fmt::Display for BusState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Active => "active",
            Self::ErrorWarning => "error warning",
            Self::ErrorPassive => "error passive",
            Self::BusOff => "bus-off",
        })
    }
}

/// Counters and state of the bus itself.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct BusHealth {
    /// Controller state now.
    pub state: BusState,
    /// Bus-off reports received.
    pub bus_off_events: u64,
    /// Error-passive reports received.
    pub error_passive_events: u64,
    /// Other bus-error reports (warning, no ACK, protocol errors, restarts).
    pub other_bus_errors: u64,
    /// Times the bus recovered from bus-off or error passive.
    pub recoveries: u64,
    /// The last bus or link error message.
    pub last_error: Option<String>,
    /// Frames sent.
    pub frames_sent: u64,
    /// Frames received.
    pub frames_received: u64,
    /// Received frames no request was waiting for, or that answer another request than
    /// the one waiting (late replies, other hosts' traffic); they are ignored.
    pub unmatched: u64,
    /// Received frames that are not valid joint replies.
    pub malformed: u64,
    /// Requests answered by two different replies (two nodes at one ID).
    pub duplicates: u64,
}

/// The latest values the client saw from one joint (servo feedback, status, register
/// reads, broadcast feedback), in wire units with typed conversions.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct JointTelemetry {
    /// When anything last arrived from this joint.
    pub updated: Option<Instant>,
    /// Actual position (0.0001° counts).
    pub position: Option<Position>,
    /// Actual speed (0.02 RPM counts).
    pub speed: Option<ActualSpeed>,
    /// Actual current (1 or 2 mA counts by model).
    pub current: Option<Current>,
    /// Drive enabled.
    pub enabled: Option<bool>,
    /// Error bits.
    pub error: Option<ErrorCode>,
    /// Bus voltage (0.01 V counts).
    pub voltage: Option<Voltage>,
    /// Temperature (0.1 °C counts).
    pub temperature: Option<Temperature>,
    /// Replies received from this joint.
    pub replies: u64,
    /// The unique ID (0x2A..0x2F) last read from this joint ID.
    pub unique_id: Option<UniqueId>,
    /// Two different unique IDs answered reads at this joint ID: two joints share the ID
    /// (the first seen and the differing one).
    pub unique_id_conflict: Option<(UniqueId, UniqueId)>,
}

/// A snapshot of everything the client knows: bus health and per-joint values.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Telemetry {
    /// Bus counters and state.
    pub bus: BusHealth,
    joints: [JointTelemetry; 31],
}

impl Telemetry {
    /// The latest values of one joint.
    pub fn joint(&self, id: JointId) -> &JointTelemetry {
        // IDs are 1..=30, so the index is always in bounds; fall back to slot 0 anyway.
        self.joints
            .get(usize::from(id.get()))
            .unwrap_or(&self.joints[0])
    }

    fn joint_mut(&mut self, id: JointId) -> Option<&mut JointTelemetry> {
        self.joints.get_mut(usize::from(id.get()))
    }

    pub(crate) fn record(&mut self, reply: &Reply, now: Instant) {
        let Some(t) = self.joint_mut(reply.joint()) else {
            return;
        };
        t.updated = Some(now);
        t.replies += 1;
        match reply {
            Reply::ServoFeedback { feedback: f, .. } => {
                t.position = Some(f.position);
                t.speed = Some(f.speed);
                t.current = Some(f.current);
                t.enabled = Some(f.is_enabled());
                t.error = Some(f.error);
            }
            Reply::Status { status: s, .. } => {
                t.position = Some(s.position);
                t.current = s.current.or(t.current);
                t.enabled = Some(s.is_enabled());
                t.error = Some(s.error);
                t.voltage = Some(s.voltage);
                t.temperature = Some(s.temperature);
            }
            Reply::BroadcastFeedback { feedback: f, .. } => {
                t.position = Some(f.position);
                t.speed = Some(f.speed);
                t.current = Some(f.current);
                t.enabled = Some(f.is_enabled());
                t.error = Some(f.error);
                t.voltage = Some(f.voltage);
                t.temperature = Some(f.temperature);
            }
            Reply::Read { addr, words, .. } => {
                if *addr == registers::addr::MOT_MODEL_ID && words.len() >= 6 {
                    let mut id = [0u16; 6];
                    for (slot, w) in id.iter_mut().zip(words.as_slice()) {
                        *slot = *w;
                    }
                    let id = UniqueId(id);
                    match t.unique_id {
                        Some(seen) if seen != id && t.unique_id_conflict.is_none() => {
                            t.unique_id_conflict = Some((seen, id));
                        }
                        _ => t.unique_id = Some(id),
                    }
                }
                if let Some(p) = reply.actual_position() {
                    t.position = Some(p);
                }
                if let Some(e) = reply.error_code() {
                    t.error = Some(e);
                }
                if let Some(e) = reply.enabled() {
                    t.enabled = Some(e);
                }
            }
            _ => {}
        }
    }
}

/// State shared by the session, the bus's thread and callers, readable without the
/// session's lock.
#[derive(Debug, Default)]
pub(crate) struct Shared {
    pub(crate) telemetry: Mutex<Telemetry>,
    /// The identity of each joint, read once per bus (by index = joint ID), so short-lived
    /// [`Joint`] handles do not read it again.
    pub(crate) identities: Mutex<[Option<super::joint::Identity>; 31]>,
    /// Each joint's position limits (0x44..0x47) as last read, forgotten when a frame that
    /// can write them goes out ([`JointBus::forget_limits_written_by`]).
    pub(crate) limits:
        Mutex<[Option<(robobus_whj::units::Position, robobus_whj::units::Position)>; 31]>,
    pub(crate) fatal: Mutex<Option<String>>,
    pub(crate) cyclic_running: AtomicBool,
    /// The latest frames on broadcast reply IDs (joints' 0x8x / 0xFx, the end board's 0x87
    /// / 0xF7) with their receive instants, oldest first, at most [`BROADCAST_LOG`].
    pub(crate) broadcast_log: Mutex<VecDeque<(Instant, CanFrame)>>,
}

/// How many broadcast replies [`JointBus::broadcast_replies_since`] keeps: eight nodes
/// answer one broadcast frame, so this holds the answers to the last eight.
pub(crate) const BROADCAST_LOG: usize = 64;

pub(crate) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// A joint handle that owns a share of its bus (`Arc<JointBus>`): `Send + Sync + 'static`,
/// so a web server, a Python binding or a bridge can keep it. [`OwnedJoint::joint`] lends
/// the full [`Joint`] API; the identity comes from the bus's cache.
#[derive(Debug, Clone)]
pub struct OwnedJoint {
    bus: Arc<JointBus>,
    id: JointId,
}

impl OwnedJoint {
    /// The joint's ID.
    pub const fn id(&self) -> JointId {
        self.id
    }

    /// The bus.
    pub const fn bus(&self) -> &Arc<JointBus> {
        &self.bus
    }

    /// The joint's handle (no frames: the identity is cached in the bus).
    pub fn joint(&self) -> Joint<'_> {
        self.bus.joint_unchecked(self.id)
    }
}

/// A WHJ CAN FD bus: owns a [`FrameLink`] and hands out [`Joint`] handles.
///
/// The bus keeps a sans-IO session (request matching, deadlines, settle times, bus-error
/// state, the cyclic loop) next to its link, behind one lock. A request / reply is driven
/// by the caller's own thread: it sends the request and receives on the link itself until
/// its reply is there, with no hand-off to another thread. Whoever holds the lock drives
/// the whole session, so frames for other requests, the cyclic loop's ticks and
/// unsolicited frames are all handled by whichever thread is receiving. A thread of the
/// bus's own runs the cyclic loop ([`JointBus::cyclic`]) and, while nothing else uses the
/// bus, picks up unsolicited frames (other hosts' traffic, controller error reports) now
/// and then for [`Telemetry`]. On a link with a virtual clock there is no such thread:
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
/// are surfaced in [`Telemetry::bus`] and in timeout errors; they count as recovered after
/// [`JointBusConfig::error_passive_hold`] without a new report. Reads and idempotent
/// operations are resent after a recovery; nothing else is.
#[derive(Debug)]
pub struct JointBus {
    core: Arc<CoreLock>,
    shared: Arc<Shared>,
    config: JointBusConfig,
    virtual_time: bool,
    wake: Mutex<Sender<Wake>>,
    thread: Option<JoinHandle<()>>,
}

/// What the bus's own thread is told.
#[derive(Debug)]
enum Wake {
    /// A cyclic loop started, or replies to a broadcast frame are due.
    Work,
    Shutdown,
}

/// The link and the session, and how many threads wait for them.
struct CoreLock {
    core: Mutex<Core>,
    /// Threads waiting for `core` (the bus thread lets them in between its steps).
    waiters: AtomicUsize,
}

impl fmt::Debug for CoreLock {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("CoreLock").finish_non_exhaustive()
    }
}

impl CoreLock {
    fn lock(&self) -> MutexGuard<'_, Core> {
        self.waiters.fetch_add(1, Ordering::AcqRel);
        let g = lock(&self.core);
        self.waiters.fetch_sub(1, Ordering::AcqRel);
        g
    }
}

/// The driver: the link and the session it feeds.
struct Core {
    link: Box<dyn FrameLink + Send>,
    session: Session,
    shared: Arc<Shared>,
    last_drain: Instant,
    closed: bool,
}

/// The most requests [`JointBus::request_many`] takes in one batch.
pub const MAX_PIPELINED: usize = 256;

/// How often the bus thread reads unsolicited frames while nothing else uses the bus
/// (rarely: on a link whose receive timeout rounds up to the kernel tick, an empty read
/// costs a tick).
const DRAIN_INTERVAL: Duration = Duration::from_millis(100);

impl Core {
    fn now(&self) -> Instant {
        self.link.now()
    }

    /// One step of the session: time passes, due frames go out, then one frame (or
    /// error) is received, or the link's clock is left to run, until the next event or
    /// `until`, whichever is first. With `listen`, the step receives even when the session
    /// awaits nothing (frames that answer a broadcast land in the telemetry).
    fn step(&mut self, until: Instant, listen: bool) {
        if self.closed {
            return;
        }
        if !self.transmit() {
            return;
        }
        let now = self.link.now();
        let wake = self.session.next_wake(now).min(until).max(now);
        if listen || self.session.awaiting() || self.session.broadcast_pending(now) {
            self.last_drain = now;
            match self.link.recv(wake) {
                Ok(rx) => {
                    let at = self.link.now();
                    self.session.on_frame(&rx.frame, at);
                }
                Err(FrameLinkError::Timeout) => {}
                Err(e) => self.link_error(&e),
            }
        } else if wake > now {
            self.link.sleep_until(wake);
        }
        // Whatever became due meanwhile (a tick, the next queued request) goes out now.
        if !self.closed {
            self.transmit();
        }
    }

    /// Lets time pass in the session and sends what is due; `false` if the link closed.
    fn transmit(&mut self) -> bool {
        if self.session.cyclic_due(self.link.now()) {
            // Frames received before the next cycle's command goes out answer earlier
            // commands: take them before the tick (the loop does not read between a
            // closed cycle and the next tick, and a late-running thread reaches the tick
            // with frames still queued).
            self.drain();
            if self.closed {
                return false;
            }
        }
        let now = self.link.now();
        self.session.on_time(now);
        while let Some(tx) = self.session.poll_transmit(now) {
            match self.link.send(&tx.frame) {
                Ok(()) => self.session.sent(),
                Err(e) => {
                    self.session.send_failed(&tx, &e, self.link.now());
                    if matches!(e, FrameLinkError::Closed { .. }) {
                        self.fatal(&e);
                        return false;
                    }
                }
            }
        }
        true
    }

    /// Picks up frames that arrived while nothing was awaited, without waiting.
    fn drain(&mut self) {
        self.last_drain = self.link.now();
        for _ in 0..64 {
            if self.closed {
                return;
            }
            let now = self.link.now();
            match self.link.recv(now) {
                Ok(rx) => self.session.on_frame(&rx.frame, now),
                Err(FrameLinkError::Timeout) => return,
                Err(e) => {
                    self.link_error(&e);
                    return;
                }
            }
        }
    }

    fn link_error(&mut self, e: &FrameLinkError) {
        let now = self.link.now();
        self.session.on_link_error(e, now);
        match e {
            FrameLinkError::Closed { .. } => self.fatal(e),
            FrameLinkError::BusOff { .. }
            | FrameLinkError::ErrorPassive { .. }
            | FrameLinkError::BusError { .. } => {}
            // A transient operating-system error: back off briefly.
            _ => self.link.sleep_until(now + Duration::from_millis(1)),
        }
    }

    fn fatal(&mut self, e: &FrameLinkError) {
        let detail = e.to_string();
        tracing::error!(error = %detail, "WHJ bus link failed");
        *lock(&self.shared.fatal) = Some(detail.clone());
        lock(&self.shared.telemetry).bus.last_error = Some(detail.clone());
        self.session.fail_all(&detail);
        self.closed = true;
    }
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
        let core = Arc::new(CoreLock {
            core: Mutex::new(Core {
                link: Box::new(link),
                session: Session::new(Arc::clone(&shared), config),
                shared: Arc::clone(&shared),
                last_drain,
                closed: false,
            }),
            waiters: AtomicUsize::new(0),
        });
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
            wake: Mutex::new(tx),
            thread,
        })
    }

    /// The bus settings.
    pub const fn config(&self) -> &JointBusConfig {
        &self.config
    }

    /// The bus's clock: the link's ([`FrameLink::now`]). Instants in [`Telemetry`] and
    /// cycle reports are on this clock.
    pub fn now(&self) -> Instant {
        self.core.lock().now()
    }

    /// Whether the bus runs on a virtual clock ([`FrameLink::virtual_time`]).
    pub const fn virtual_time(&self) -> bool {
        self.virtual_time
    }

    /// Waits until the bus's clock reaches `deadline`, receiving frames meanwhile (into
    /// [`Telemetry`]; the cyclic loop keeps its ticks). On a simulated bus on virtual time this returns as
    /// soon as simulated time got there.
    pub fn sleep_until(&self, deadline: Instant) {
        loop {
            let mut core = self.core.lock();
            if core.now() >= deadline || core.closed {
                return;
            }
            core.step(deadline, true);
        }
    }
    /// Connects to joint `id`: releases it from the bootloader (`IAP_FLAG := 0`, repeated
    /// for up to [`JointBusConfig::connect_timeout`]; harmless if the application already
    /// runs) and reads its identity. A joint that never answers gives
    /// [`WhjError::Silent`], which names the likely causes (IAP, ID, bit rate).
    pub fn joint(&self, id: JointId) -> Result<Joint<'_>, WhjError> {
        Joint::connect(self, id)
    }

    /// Connects many joints at once ([`JointBus::joint`] for each, with the IAP releases
    /// pipelined: an absent joint costs the connect timeout once for the whole batch, not
    /// once per joint). Results in `ids` order.
    pub fn joints(&self, ids: &[JointId]) -> Vec<Result<Joint<'_>, WhjError>> {
        Joint::connect_many(self, ids, self.config().connect_timeout)
    }

    /// [`JointBus::joints`] waiting at most `timeout` for the joints to answer instead of
    /// [`JointBusConfig::connect_timeout`] (a scan: a joint in its bootloader answers the
    /// release at once, an absent ID must not cost seconds).
    pub fn joints_within(
        &self,
        ids: &[JointId],
        timeout: Duration,
    ) -> Vec<Result<Joint<'_>, WhjError>> {
        Joint::connect_many(self, ids, timeout)
    }

    /// A handle for joint `id` without the connect handshake (for a joint known to run its
    /// application). Its identity is read on first use, once per bus (the bus keeps it, so
    /// a handle made every sample costs no extra frames).
    pub fn joint_unchecked(&self, id: JointId) -> Joint<'_> {
        Joint::unchecked(self, id)
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
    pub fn cached_identity(&self, id: JointId) -> Option<super::joint::Identity> {
        lock(&self.shared.identities)
            .get(usize::from(id.get()))
            .copied()
            .flatten()
    }

    pub(crate) fn cache_identity(&self, id: JointId, identity: super::joint::Identity) {
        if let Some(slot) = lock(&self.shared.identities).get_mut(usize::from(id.get())) {
            *slot = Some(identity);
        }
    }

    /// Connects joint `id` ([`JointBus::joint`]) and returns a handle that owns (a share
    /// of) the bus, for front ends that keep a joint for a long time or on another thread.
    pub fn owned_joint(self: &Arc<Self>, id: JointId) -> Result<OwnedJoint, WhjError> {
        self.joint(id)?;
        Ok(OwnedJoint {
            bus: Arc::clone(self),
            id,
        })
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
        match self.attempt(request, timeout, Duration::ZERO)? {
            Attempt::Reply { reply, .. } => Ok(reply),
            other => Err(super::joint::attempt_error(
                joint,
                &super::joint::describe(&request),
                &request,
                other,
                1,
            )),
        }
    }

    /// Sends one broadcast frame (0x7F status query, 0x0F register access, ...) outside a
    /// cyclic loop and returns when it went out. Replies are not matched to it: they land
    /// in [`Telemetry`] (newer than the returned instant), see
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
                core.session.sent();
                core.session.broadcast_sent(at);
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
        lock(&self.shared.broadcast_log)
            .iter()
            .filter(|(at, _)| *at > since)
            .copied()
            .collect()
    }

    /// A snapshot of the bus health and the latest values from every joint.
    pub fn telemetry(&self) -> Telemetry {
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

    /// One attempt of one transaction.
    pub(crate) fn attempt(
        &self,
        request: Request,
        timeout: Duration,
        quiet_after: Duration,
    ) -> Result<Attempt, WhjError> {
        let expect = Expect::of(&request).ok_or_else(|| WhjError::InvalidConfig {
            reason: "broadcast frames are not single requests".into(),
        })?;
        self.forget_limits_written_by(&request);
        let mut core = self.core.lock();
        if core.closed {
            return Err(self.closed_error());
        }
        let submitted = core.now();
        let id = core.session.submit(Txn {
            request,
            expect,
            timeout,
            quiet_after,
            submitted,
        });
        drop(core);
        self.finish(id, submitted, timeout)
    }

    /// Drives the session until transaction `id` is finished.
    fn finish(
        &self,
        id: TxnId,
        submitted: Instant,
        timeout: Duration,
    ) -> Result<Attempt, WhjError> {
        let mut out = self.finish_all(&[id], submitted, timeout);
        out.pop().unwrap_or_else(|| Err(self.closed_error()))
    }

    /// Drives the session until every transaction of `ids` is finished; their outcomes in
    /// the same order.
    fn finish_all(
        &self,
        ids: &[TxnId],
        submitted: Instant,
        timeout: Duration,
    ) -> Vec<Result<Attempt, WhjError>> {
        // Every transaction has a deadline, so the session always finishes it; the limit
        // only guards against a session that lost one. Requests on one reply ID go one
        // after another, so the limit grows with the batch.
        let batch = u32::try_from(ids.len().clamp(1, MAX_PIPELINED)).unwrap_or(1);
        let limit = submitted
            + timeout * batch
            + self.config.bus_recovery_timeout
            + self.config.save_settle
            + Duration::from_secs(2);
        let mut out: Vec<Option<Result<Attempt, WhjError>>> = ids.iter().map(|_| None).collect();
        loop {
            let mut core = self.core.lock();
            for (slot, id) in out.iter_mut().zip(ids) {
                if slot.is_none() {
                    *slot = core.session.take(*id).map(Ok);
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

    /// One attempt of each of `requests`, pipelined: all are queued at once, each goes out
    /// as soon as its reply ID is free (at once for requests to different joints), and
    /// each reply is credited to its own request only. Outcomes in request order.
    pub(crate) fn attempt_many(
        &self,
        requests: &[Request],
        timeout: Duration,
    ) -> Result<Vec<Result<Attempt, WhjError>>, WhjError> {
        let mut txns = Vec::with_capacity(requests.len());
        for request in requests {
            let expect = Expect::of(request).ok_or_else(|| WhjError::InvalidConfig {
                reason: "broadcast frames are not single requests".into(),
            })?;
            self.forget_limits_written_by(request);
            txns.push((*request, expect));
        }
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
                    quiet_after: Duration::ZERO,
                    submitted,
                })
            })
            .collect();
        drop(core);
        Ok(self.finish_all(&ids, submitted, timeout))
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
        if requests.len() > MAX_PIPELINED {
            return Err(WhjError::InvalidConfig {
                reason: format!(
                    "{} requests given, at most {MAX_PIPELINED} go in one pipelined batch",
                    requests.len()
                ),
            });
        }
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
                other => Err(super::joint::attempt_error(
                    joint,
                    &super::joint::describe(request),
                    request,
                    other,
                    1,
                )),
            })
            .collect())
    }

    pub(crate) fn start_cyclic(&self, setup: CyclicSetup) -> Result<(), WhjError> {
        let mut core = self.core.lock();
        if core.closed {
            return Err(self.closed_error());
        }
        let now = core.now();
        core.session.start_cyclic(setup, now)?;
        drop(core);
        let _ = lock(&self.wake).send(Wake::Work);
        Ok(())
    }

    pub(crate) fn stop_cyclic(&self) {
        self.core.lock().session.stop_cyclic();
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

/// The bus's own thread: runs the cyclic loop while one runs, receives the replies to a
/// broadcast frame while they are due; otherwise picks up unsolicited frames every
/// [`DRAIN_INTERVAL`] while nothing else uses the bus.
fn background(core: &CoreLock, wake: &Receiver<Wake>) {
    let mut wait = DRAIN_INTERVAL;
    loop {
        match wake.recv_timeout(wait) {
            Ok(Wake::Shutdown) | Err(RecvTimeoutError::Disconnected) => return,
            Ok(Wake::Work) | Err(RecvTimeoutError::Timeout) => {}
        }
        loop {
            let mut c = core.lock();
            if c.closed {
                wait = DRAIN_INTERVAL;
                break;
            }
            let now = c.now();
            if c.session.cyclic_running() || c.session.broadcast_pending(now) {
                let until = now + DRAIN_INTERVAL;
                c.step(until, false);
                drop(c);
                // Callers waiting for the lock go first.
                for _ in 0..1000 {
                    if core.waiters.load(Ordering::Acquire) == 0 {
                        break;
                    }
                    std::thread::yield_now();
                }
                match wake.try_recv() {
                    Ok(Wake::Shutdown) | Err(TryRecvError::Disconnected) => return,
                    Ok(Wake::Work) | Err(TryRecvError::Empty) => {}
                }
                continue;
            }
            let now = c.now();
            if c.session.is_idle() && now.saturating_duration_since(c.last_drain) >= DRAIN_INTERVAL
            {
                c.drain();
            }
            wait = (c.last_drain + DRAIN_INTERVAL)
                .saturating_duration_since(now)
                .max(Duration::from_millis(1));
            break;
        }
    }
}
