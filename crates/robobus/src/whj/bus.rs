//! [`JointBus`]: one thread owns the frame link; callers talk to it through a small
//! command interface (transactions, cyclic loop control) and read its telemetry.

use core::fmt;
use core::time::Duration;
use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender, SyncSender, TryRecvError};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::Instant;

use robobus_link::{BusErrorKind, FrameLink, FrameLinkError};
use robobus_whj::frame::padded_len;
use robobus_whj::registers::{self, UniqueId};
use robobus_whj::units::{ActualSpeed, Current, Position, Temperature, Voltage};
use robobus_whj::{CanFrame, ErrorCode, JointId, Reply, Request};

use super::cyclic::{CyclicRun, CyclicSetup};
use super::error::WhjError;
use super::joint::Joint;

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
    /// How often the bus thread looks for new commands while it waits for frames
    /// (default 0.5 ms).
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

/// The CAN controller state as the bus thread last saw it.
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
}

/// The latest values the bus thread saw from one joint (servo feedback, status, register
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

/// A snapshot of everything the bus thread knows: bus health and per-joint values.
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

    fn record(&mut self, reply: &Reply, now: Instant) {
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

/// The outcome of one attempt of one transaction, as the bus thread reports it.
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
}

/// What kind of reply a request expects.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Expect {
    Read { addr: u8, count: u8 },
    Write { addr: u8 },
    Servo,
    Status,
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
        }
    }

    /// Whether `reply` (carried by `frame`) answers a request of this kind.
    fn check(self, reply: &Reply, frame: &CanFrame) -> Result<(), Unanswered> {
        match (self, reply) {
            (Self::Read { .. } | Self::Write { .. }, Reply::CmdErr { .. })
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

/// One transaction submitted to the bus thread.
#[derive(Debug)]
pub(crate) struct Txn {
    request: Request,
    expect: Expect,
    timeout: Duration,
    quiet_after: Duration,
    submitted: Instant,
    reply: SyncSender<Attempt>,
}

/// What callers ask the bus thread to do.
#[derive(Debug)]
pub(crate) enum Command {
    Transact(Txn),
    StartCyclic(Box<CyclicSetup>, SyncSender<Result<(), WhjError>>),
    StopCyclic(SyncSender<()>),
    /// Send one broadcast frame (no reply is matched; replies land in the telemetry).
    Broadcast(CanFrame, SyncSender<Result<Instant, WhjError>>),
    Shutdown,
}

/// State shared between the bus thread and callers.
#[derive(Debug, Default)]
pub(crate) struct Shared {
    pub(crate) telemetry: Mutex<Telemetry>,
    /// The identity of each joint, read once per bus (by index = joint ID), so short-lived
    /// [`Joint`] handles do not read it again.
    pub(crate) identities: Mutex<[Option<super::joint::Identity>; 31]>,
    fatal: Mutex<Option<String>>,
    cyclic_running: AtomicBool,
    /// The latest frames on broadcast reply IDs (joints' 0x8x / 0xFx, the end board's 0x87
    /// / 0xF7) with their receive instants, oldest first, at most [`BROADCAST_LOG`].
    broadcast_log: Mutex<VecDeque<(Instant, CanFrame)>>,
}

/// How many broadcast replies [`JointBus::broadcast_replies_since`] keeps: eight nodes
/// answer one broadcast frame, so this holds the answers to the last eight.
const BROADCAST_LOG: usize = 64;

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

/// A WHJ CAN FD bus: owns a [`FrameLink`] on a thread of its own and hands out [`Joint`]
/// handles.
///
/// The bus thread sends every request, matches replies to requests by CAN ID and
/// function (`0x100+ID` read / write / `CMD_ERR`, `0x500+ID` servo feedback, `0x700+ID`
/// status), enforces per-request timeouts and settle times, runs the cyclic servo loop
/// ([`JointBus::cyclic`]) and keeps [`Telemetry`]. At most one request per reply ID is in
/// flight at a time, so a reply can only belong to that request; requests from several
/// threads queue up.
///
/// Bus errors: a bus-off report fails the requests in flight ([`WhjError::Bus`]) and
/// holds new ones until the bus has **recovered**, which means: the link reported a
/// controller restart, or any frame arrived again. Error-passive and error-warning reports
/// are surfaced in [`Telemetry::bus`] and in timeout errors; they count as recovered after
/// [`JointBusConfig::error_passive_hold`] without a new report. Reads and idempotent
/// operations are resent after a recovery; nothing else is.
#[derive(Debug)]
pub struct JointBus {
    tx: Mutex<Sender<Command>>,
    shared: Arc<Shared>,
    config: JointBusConfig,
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
        let (tx, rx) = mpsc::channel();
        let shared = Arc::new(Shared::default());
        let worker = Worker {
            link,
            rx,
            shared: Arc::clone(&shared),
            config,
            in_flight: HashMap::new(),
            queued: VecDeque::new(),
            quiet: HashMap::new(),
            passive_since: None,
            cyclic: None,
            last_drain: Instant::now(),
            broadcast_until: None,
        };
        let thread = std::thread::Builder::new()
            .name("whj-bus".into())
            .spawn(move || worker.run())
            .map_err(|e| WhjError::Link {
                detail: format!("cannot start the bus thread: {e}"),
            })?;
        Ok(Self {
            tx: Mutex::new(tx),
            shared,
            config,
            thread: Some(thread),
        })
    }

    /// The bus settings.
    pub const fn config(&self) -> &JointBusConfig {
        &self.config
    }

    /// Connects to joint `id`: releases it from the bootloader (`IAP_FLAG := 0`, repeated
    /// for up to [`JointBusConfig::connect_timeout`]; harmless if the application already
    /// runs) and reads its identity. A joint that never answers gives
    /// [`WhjError::Silent`], which names the likely causes (IAP, ID, bit rate).
    pub fn joint(&self, id: JointId) -> Result<Joint<'_>, WhjError> {
        Joint::connect(self, id)
    }

    /// A handle for joint `id` without the connect handshake (for a joint known to run its
    /// application). Its identity is read on first use, once per bus (the bus keeps it, so
    /// a handle made every sample costs no extra frames).
    pub fn joint_unchecked(&self, id: JointId) -> Joint<'_> {
        Joint::unchecked(self, id)
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
        let (done, rx) = mpsc::sync_channel(1);
        self.send_command(Command::Broadcast(request.to_frame(), done))?;
        rx.recv_timeout(Duration::from_secs(2))
            .map_err(|_| self.closed_error())?
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

    pub(crate) fn send_command(&self, cmd: Command) -> Result<(), WhjError> {
        lock(&self.tx).send(cmd).map_err(|_| self.closed_error())
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
        let (reply, rx) = mpsc::sync_channel(1);
        self.send_command(Command::Transact(Txn {
            request,
            expect,
            timeout,
            quiet_after,
            submitted: Instant::now(),
            reply,
        }))?;
        // The thread always answers (every transaction has a deadline); the margin only
        // guards against a thread that died.
        let limit = timeout
            + self.config.bus_recovery_timeout
            + self.config.save_settle
            + Duration::from_secs(2);
        rx.recv_timeout(limit).map_err(|_| self.closed_error())
    }

    pub(crate) fn start_cyclic(&self, setup: CyclicSetup) -> Result<(), WhjError> {
        let (done, rx) = mpsc::sync_channel(1);
        self.send_command(Command::StartCyclic(Box::new(setup), done))?;
        rx.recv_timeout(Duration::from_secs(2))
            .map_err(|_| self.closed_error())?
    }

    pub(crate) fn stop_cyclic(&self) {
        let (done, rx) = mpsc::sync_channel(1);
        if self.send_command(Command::StopCyclic(done)).is_ok() {
            let _ = rx.recv_timeout(Duration::from_secs(2));
        }
    }
}

impl Drop for JointBus {
    fn drop(&mut self) {
        let _ = lock(&self.tx).send(Command::Shutdown);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[derive(Debug)]
struct InFlight {
    txn: Txn,
    sent: Instant,
    deadline: Instant,
}

/// The bus thread.
struct Worker<L> {
    link: L,
    rx: Receiver<Command>,
    shared: Arc<Shared>,
    config: JointBusConfig,
    in_flight: HashMap<u16, InFlight>,
    queued: VecDeque<Txn>,
    quiet: HashMap<u8, Instant>,
    passive_since: Option<Instant>,
    cyclic: Option<CyclicRun>,
    last_drain: Instant,
    /// Until when replies to the last broadcast frame are awaited (received at once
    /// rather than at the next drain).
    broadcast_until: Option<Instant>,
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

/// How often the bus thread reads unsolicited frames while it awaits nothing (rarely: on
/// a link whose receive timeout rounds up to the kernel tick, an empty read costs a tick).
const DRAIN_INTERVAL: Duration = Duration::from_millis(100);

enum Flow {
    Continue,
    Stop,
}

impl<L: FrameLink> Worker<L> {
    fn run(mut self) {
        loop {
            if matches!(self.wait_for_work(), Flow::Stop) {
                break;
            }
            let now = Instant::now();
            self.recover_passive(now);
            if let Some(c) = self.cyclic.as_mut()
                && c.due(now)
            {
                let frames = c.tick(now);
                for frame in frames {
                    if let Err(e) = self.send(&frame) {
                        if let Some(c) = self.cyclic.as_mut() {
                            c.send_failed(&frame, &e.to_string());
                        }
                        if matches!(e, FrameLinkError::Closed { .. }) {
                            self.fatal(&e);
                            return;
                        }
                    }
                }
            }
            self.start_queued(Instant::now());
            if self.awaiting() {
                let deadline = self.next_wake(Instant::now());
                if self.receive(deadline) {
                    return;
                }
            } else if self.drain_due(Instant::now()) {
                // Nothing is awaited: pick up unsolicited frames (other hosts' traffic,
                // controller error reports) now and then, without waiting.
                self.last_drain = Instant::now();
                for _ in 0..64 {
                    match self.link.recv(Instant::now()) {
                        Ok(rx) => self.dispatch(rx.frame),
                        Err(FrameLinkError::Timeout) => break,
                        Err(e) => {
                            if self.link_error(e) {
                                return;
                            }
                            break;
                        }
                    }
                }
            }
            self.expire(Instant::now());
        }
        self.fail_all(|_| Attempt::Link("the bus was closed".into()));
    }

    /// Receives one frame (or error) until `deadline`; `true` if the thread must stop.
    fn receive(&mut self, deadline: Instant) -> bool {
        self.last_drain = Instant::now();
        match self.link.recv(deadline) {
            Ok(rx) => {
                self.dispatch(rx.frame);
                false
            }
            Err(FrameLinkError::Timeout) => false,
            Err(e) => self.link_error(e),
        }
    }

    /// Whether a frame is expected: a reply in flight, replies to a broadcast frame just
    /// sent (for five reply timeouts), feedback of the running cycle, or a
    /// bus-off recovery that queued requests wait for. Only then does the thread block in
    /// the link's receive; otherwise it sleeps on the command channel, whose timeout is
    /// precise (some links' receive timeouts round up to the kernel tick, e.g. UDP's
    /// `SO_RCVTIMEO`), so cyclic ticks stay on time.
    fn awaiting(&self) -> bool {
        !self.in_flight.is_empty()
            || self.broadcast_until.is_some_and(|t| t > Instant::now())
            || self.cyclic.as_ref().is_some_and(CyclicRun::awaiting)
            || (!self.queued.is_empty() && self.state() == BusState::BusOff)
    }

    fn drain_due(&self, now: Instant) -> bool {
        self.cyclic.is_none()
            && self.queued.is_empty()
            && now.duration_since(self.last_drain) >= DRAIN_INTERVAL
    }

    /// Sleeps on the command channel until a command arrives or the next timed event
    /// (cyclic tick, end of a settle time, drain), then takes every waiting command.
    fn wait_for_work(&mut self) -> Flow {
        if !self.awaiting() && self.queued.is_empty() {
            let now = Instant::now();
            let mut wake = self.last_drain + DRAIN_INTERVAL;
            if let Some(c) = &self.cyclic {
                wake = wake.min(c.next_event());
            }
            match self.rx.recv_timeout(wake.saturating_duration_since(now)) {
                Ok(cmd) => {
                    if matches!(self.command(cmd), Flow::Stop) {
                        return Flow::Stop;
                    }
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return Flow::Stop,
            }
        } else if !self.awaiting() {
            // Queued requests wait for a settle time to end (or for a busy reply ID).
            let now = Instant::now();
            let mut wake = now + self.config.poll_interval;
            for until in self.quiet.values() {
                if *until > now {
                    wake = wake.min(*until);
                }
            }
            if let Some(c) = &self.cyclic {
                wake = wake.min(c.next_event());
            }
            match self.rx.recv_timeout(wake.saturating_duration_since(now)) {
                Ok(cmd) => {
                    if matches!(self.command(cmd), Flow::Stop) {
                        return Flow::Stop;
                    }
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return Flow::Stop,
            }
        }
        loop {
            match self.rx.try_recv() {
                Ok(cmd) => {
                    if matches!(self.command(cmd), Flow::Stop) {
                        return Flow::Stop;
                    }
                }
                Err(TryRecvError::Empty) => return Flow::Continue,
                Err(TryRecvError::Disconnected) => return Flow::Stop,
            }
        }
    }

    fn command(&mut self, cmd: Command) -> Flow {
        match cmd {
            Command::Transact(txn) => self.queued.push_back(txn),
            Command::StartCyclic(setup, done) => {
                let r = if self.cyclic.is_some() {
                    Err(WhjError::InvalidConfig {
                        reason: "a cyclic loop is already running on this bus".into(),
                    })
                } else {
                    self.cyclic = Some(CyclicRun::new(*setup, Instant::now()));
                    self.shared.cyclic_running.store(true, Ordering::Release);
                    Ok(())
                };
                let _ = done.send(r);
            }
            Command::StopCyclic(done) => {
                if let Some(c) = self.cyclic.take() {
                    c.finish();
                }
                self.shared.cyclic_running.store(false, Ordering::Release);
                let _ = done.send(());
            }
            Command::Broadcast(frame, done) => {
                let r = if self.cyclic.is_some() {
                    Err(WhjError::InvalidConfig {
                        reason: "a cyclic loop is running on this bus".into(),
                    })
                } else {
                    let at = Instant::now();
                    self.broadcast_until = Some(at + self.config.reply_timeout * 5);
                    self.send(&frame).map(|()| at).map_err(|e| WhjError::Link {
                        detail: e.to_string(),
                    })
                };
                let _ = done.send(r);
            }
            Command::Shutdown => return Flow::Stop,
        }
        Flow::Continue
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
            && now.duration_since(since) >= self.config.error_passive_hold
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

    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        self.link.send(frame)?;
        lock(&self.shared.telemetry).bus.frames_sent += 1;
        Ok(())
    }

    fn start_queued(&mut self, now: Instant) {
        let bus_off = self.state() == BusState::BusOff;
        let mut i = 0;
        while i < self.queued.len() {
            let Some(txn) = self.queued.get(i) else { break };
            let key = txn.request.reply_id().unwrap_or(0);
            let joint = txn.request.joint().map_or(0, JointId::get);
            let busy = self.in_flight.contains_key(&key);
            let quiet = self.quiet.get(&joint).is_some_and(|t| *t > now);
            if self.cyclic.as_ref().is_some_and(|c| c.owns(key)) {
                if let Some(txn) = self.queued.remove(i) {
                    let _ = txn.reply.send(Attempt::Busy);
                }
                continue;
            }
            if bus_off {
                let waited = now.duration_since(txn.submitted);
                if waited >= self.config.bus_recovery_timeout
                    && let Some(txn) = self.queued.remove(i)
                {
                    let detail = self.last_error();
                    let _ = txn.reply.send(Attempt::Bus {
                        state: BusState::BusOff,
                        detail,
                        waited,
                    });
                    continue;
                }
                i += 1;
                continue;
            }
            if busy || quiet {
                i += 1;
                continue;
            }
            let Some(txn) = self.queued.remove(i) else {
                break;
            };
            let frame = txn.request.to_frame();
            match self.send(&frame) {
                Ok(()) => {
                    let sent = Instant::now();
                    self.in_flight.insert(
                        key,
                        InFlight {
                            deadline: sent + txn.timeout,
                            sent,
                            txn,
                        },
                    );
                }
                Err(e @ (FrameLinkError::BusOff { .. } | FrameLinkError::ErrorPassive { .. })) => {
                    self.link_error_state(&e);
                    let _ = txn.reply.send(Attempt::Bus {
                        state: self.state(),
                        detail: e.to_string(),
                        waited: Duration::ZERO,
                    });
                }
                Err(e) => {
                    let _ = txn.reply.send(Attempt::Link(e.to_string()));
                    if matches!(e, FrameLinkError::Closed { .. }) {
                        self.fatal(&e);
                    }
                }
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

    fn next_wake(&self, now: Instant) -> Instant {
        let mut wake = now + self.config.poll_interval;
        for f in self.in_flight.values() {
            wake = wake.min(f.deadline);
        }
        if let Some(c) = &self.cyclic {
            wake = wake.min(c.next_event());
        }
        for until in self.quiet.values() {
            if *until > now {
                wake = wake.min(*until);
            }
        }
        wake.max(now)
    }

    fn dispatch(&mut self, frame: CanFrame) {
        let now = Instant::now();
        let decoded = Reply::from_frame(&frame);
        if frame.standard_raw_id().is_some_and(is_broadcast_reply_id) {
            let mut log = lock(&self.shared.broadcast_log);
            if log.len() >= BROADCAST_LOG {
                log.pop_front();
            }
            log.push_back((now, frame));
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
            && c.on_reply(reply, now)
        {
            return;
        }
        let key = frame.standard_raw_id().unwrap_or(0);
        let Some(f) = self.in_flight.remove(&key) else {
            lock(&self.shared.telemetry).bus.unmatched += 1;
            return;
        };
        if let Ok(reply) = &decoded
            && let Err(Unanswered::Other(reason)) = f.txn.expect.check(reply, &frame)
        {
            // A late reply to something else: the request is still waiting for its own.
            tracing::debug!(%reason, "ignored a reply that answers another request");
            lock(&self.shared.telemetry).bus.unmatched += 1;
            self.in_flight.insert(key, f);
            return;
        }
        let outcome = match decoded {
            Ok(reply) => match f.txn.expect.check(&reply, &frame) {
                Ok(()) => {
                    let ok_write = matches!(
                        reply,
                        Reply::WriteAck { status, .. } if status.is_ok()
                    );
                    if ok_write && !f.txn.quiet_after.is_zero() {
                        let joint = reply.joint().get();
                        self.quiet.insert(joint, now + f.txn.quiet_after);
                    }
                    Attempt::Reply { reply }
                }
                Err(Unanswered::Bad(reason) | Unanswered::Other(reason)) => {
                    Attempt::Mismatch(reason)
                }
            },
            Err(e) => Attempt::Mismatch(e.to_string()),
        };
        let _ = f.txn.reply.send(outcome);
    }

    fn expire(&mut self, now: Instant) {
        let expired: Vec<u16> = self
            .in_flight
            .iter()
            .filter(|(_, f)| f.deadline <= now)
            .map(|(k, _)| *k)
            .collect();
        let state = self.state();
        for key in expired {
            if let Some(f) = self.in_flight.remove(&key) {
                let _ = f.txn.reply.send(Attempt::Timeout {
                    waited: now.duration_since(f.sent),
                    state,
                });
            }
        }
        self.quiet.retain(|_, until| *until > now);
    }

    fn link_error_state(&mut self, e: &FrameLinkError) {
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
                self.passive_since = Some(Instant::now());
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
                        self.passive_since = Some(Instant::now());
                        if state != BusState::BusOff {
                            self.set_state(BusState::ErrorPassive, detail);
                        }
                    }
                    BusErrorKind::ErrorWarning => {
                        self.passive_since = Some(Instant::now());
                        if state == BusState::Active {
                            self.set_state(BusState::ErrorWarning, detail);
                        }
                    }
                    BusErrorKind::NoAck | BusErrorKind::Other { .. } => {
                        t = lock(&self.shared.telemetry);
                        t.bus.last_error = detail;
                    }
                }
            }
            _ => {
                t.bus.last_error = detail;
            }
        }
    }

    /// Handles a receive error; returns `true` if the thread must stop.
    fn link_error(&mut self, e: FrameLinkError) -> bool {
        match e {
            FrameLinkError::BusOff { .. }
            | FrameLinkError::ErrorPassive { .. }
            | FrameLinkError::BusError { .. } => {
                self.link_error_state(&e);
                if self.state() == BusState::BusOff {
                    let detail = e.to_string();
                    let now = Instant::now();
                    let failed: Vec<u16> = self.in_flight.keys().copied().collect();
                    for key in failed {
                        if let Some(f) = self.in_flight.remove(&key) {
                            let _ = f.txn.reply.send(Attempt::Bus {
                                state: BusState::BusOff,
                                detail: detail.clone(),
                                waited: now.duration_since(f.sent),
                            });
                        }
                    }
                }
                false
            }
            FrameLinkError::Closed { .. } => {
                self.fatal(&e);
                true
            }
            other => {
                // A transient operating-system error: report it, back off briefly.
                tracing::warn!(error = %other, "WHJ bus receive error");
                lock(&self.shared.telemetry).bus.last_error = Some(other.to_string());
                std::thread::sleep(Duration::from_millis(1));
                false
            }
        }
    }

    fn fatal(&mut self, e: &FrameLinkError) {
        let detail = e.to_string();
        tracing::error!(error = %detail, "WHJ bus link failed; bus thread stops");
        *lock(&self.shared.fatal) = Some(detail.clone());
        lock(&self.shared.telemetry).bus.last_error = Some(detail.clone());
        self.fail_all(|_| Attempt::Link(detail.clone()));
        if let Some(c) = self.cyclic.take() {
            c.finish();
        }
        self.shared.cyclic_running.store(false, Ordering::Release);
    }

    fn fail_all(&mut self, outcome: impl Fn(&Txn) -> Attempt) {
        for (_, f) in self.in_flight.drain() {
            let _ = f.txn.reply.send(outcome(&f.txn));
        }
        for txn in self.queued.drain(..) {
            let _ = txn.reply.send(outcome(&txn));
        }
        while let Ok(cmd) = self.rx.try_recv() {
            match cmd {
                Command::Transact(txn) => {
                    let _ = txn.reply.send(outcome(&txn));
                }
                Command::StartCyclic(_, done) => {
                    let _ = done.send(Err(WhjError::Closed));
                }
                Command::StopCyclic(done) => {
                    let _ = done.send(());
                }
                Command::Broadcast(_, done) => {
                    let _ = done.send(Err(WhjError::Closed));
                }
                Command::Shutdown => {}
            }
        }
    }
}
