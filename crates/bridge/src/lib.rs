//! `robobus bridge`: a station's robot on Zenoh, in the message types ROS 2 reads.
//!
//! Keys, under an optional namespace `NS` (see [`Keys`]):
//!
//! - `NS/joint_states`: `sensor_msgs/msg/JointState` in CDR ([`cdr`]), every joint of the
//!   station's robot file that answered this sample, at the configured rate when the
//!   buses carry it ([`Capacity`]: otherwise as fast as they do, said at start and in the
//!   health); a joint whose reading failed is left out of that message, never repeated
//!   from an older one. Commands come first: a sample is not started while a command
//!   waits or is being applied, nor when the next command of a steady stream is due
//!   before the sample would end; the samples a slot missed are counted lost.
//! - `NS/joint_commands`: `std_msgs/msg/Float64MultiArray` in CDR, one target per joint
//!   in the file's order, in radians (the forward position controller of `ros2_controllers`).
//!   Each command is checked whole ([`Follower::plan`]) and stepped toward
//!   ([`Follower::apply`]); a malformed one is refused, an out-of-range, unarmed or stale
//!   one is held (nothing moves), each counted with its reason; one replaced by a newer
//!   one before it could be applied is counted superseded.
//! - `NS/joint_commands/velocity`, `NS/joint_commands/effort`: `Float64MultiArray` in
//!   CDR, rad/s or N·m, one per joint on that interface in the file's order, after
//!   `NS/robobus/interface` switched them (a queryable: `{"interface": "velocity",
//!   "joints": [...]}`); checked whole, admitted and watched as positions are
//!   ([`CommandKeys`], the library's `Driver`).
//! - `NS/diagnostics`: `diagnostic_msgs/msg/DiagnosticArray` in CDR ([`diagnostics`]) about
//!   once a second: one status per joint and per bus of the robot file (OK, warning, error
//!   or stale, with the reason and the values read), from the joint states' own samples.
//! - `NS/joint_trajectory`: `trajectory_msgs/msg/JointTrajectory` in CDR, played as
//!   `joint_trajectory_controller` plays it (checked whole, then through `robot.play`);
//!   its progress on `NS/controller_state` (`control_msgs/msg/JointTrajectoryControllerState`)
//!   and its end on `NS/joint_trajectory/result` (JSON, [`TrajectoryResult`]).
//! - `NS/robobus/run`: a queryable: a catalogue request in JSON in, its report out.
//! - `NS/robobus/plan`: a queryable: a request's dry run.
//! - `NS/robobus/arm`: a queryable: `true` / `false` (or `{"armed": B}`) arms or disarms,
//!   an empty query reads the state.
//! - `NS/robobus/health`: JSON about once a second (arming, safe stops, refusals, the
//!   telemetry's counts, each bus's answering devices), and the liveliness token
//!   `NS/robobus/bridge` while the bridge runs, with its claim `NS/robobus/bridge/C` (`C`:
//!   its start time and Zenoh ID) next to it.
//! - `NS/robobus/sim`: a queryable, only on the built-in simulated robot: the simulators'
//!   own state (the truth tests check motion against).
//!
//! Safety: nothing moves until the bridge is armed; motion requests and commands go
//! through the station's [`Guard`]; a command stream that goes quiet for the command
//! timeout brings the joints it moved to the safe state ([`Guard::hold`]); disarming, a
//! stalled bridge and the bridge's end do too. The bridge holds no state another bridge
//! needs: many run side by side, one per robot or bus, on one Zenoh router, each on its
//! own namespace: a bridge refuses a namespace another bridge it reaches serves
//! ([`BridgeError::InUse`]; of two started at once, the later gives way).

// The library's `OpError` is passed through as it is, as every front end does.
#![allow(clippy::result_large_err)]

pub use robobus::cdr;
mod capacity;
mod claim;
mod commands;
pub mod diagnostics;
mod health;
mod queries;
mod threads;
mod trajectory;
mod zconfig;

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use robobus::ErrorKind;
use robobus::frontend::guard::{Guard, GuardConfig, SafeEvent};
use robobus::frontend::live::LiveSimulator;
use robobus::frontend::{Admission, Arming, FrontEnd};
use robobus::ops::{OpError, SafeState, StopToken};
use robobus::station::Station;
use robobus::station::follow::Follower;
use zenoh::Wait as _;
use zenoh::bytes::Encoding;

pub use capacity::{BusTiming, Capacity};
pub use commands::{CommandKeys, DriveHealth, StreamHealth};
pub use health::{Health, RATE_WINDOW};
pub use trajectory::{TRAJECTORY_RATE_HZ, TrajectoryHealth, TrajectoryKeys, TrajectoryResult};
pub use zconfig::{DEFAULT_LISTEN, namespace_prefix};

#[cfg(test)]
use queries::run_request;
use queries::{declare_queries, query_text, reply_error, reply_json, reply_op_error};
#[cfg(test)]
use threads::follow;
use threads::{commands, states};

/// The guard session the bridge controls the station with.
const SESSION: u64 = 1;
/// The largest command or request payload, bytes.
pub const MAX_REQUEST: usize = 4 << 20;
/// Queries waiting for a worker at most; more are answered "busy".
const QUERY_QUEUE: usize = 16;
/// How long the guard waits for the bridge's own heartbeat (its command thread's loop)
/// before it brings moved devices to the safe state and disarms: a stalled bridge.
const STALL_TIMEOUT: Duration = Duration::from_secs(2);
/// The reason of the safe stop a quiet command stream causes.
pub const HOLD_REASON: &str = "command timeout";
/// Command timeouts accepted.
pub const COMMAND_TIMEOUT_MS: std::ops::RangeInclusive<u64> = 20..=5000;

/// How a bridge joins Zenoh.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ZenohMode {
    /// A peer: listens for others and may connect to a router or other peers. Two peers
    /// talk directly; behind a router without gossip, a peer reaches only the router's
    /// clients, so a site's router wants its bridges and consumers as clients.
    #[default]
    Peer,
    /// A client of the routers it connects to (`--connect` required, no `--listen`):
    /// everything goes through a router, which forwards between all its clients.
    Client,
}

impl ZenohMode {
    /// The name Zenoh's configuration uses.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Peer => "peer",
            Self::Client => "client",
        }
    }
}

/// How a bridge runs.
#[derive(Debug, Clone)]
pub struct BridgeConfig {
    /// The key prefix (`bot1`, `site/arm`), without leading or trailing `/`; `None`: none.
    pub namespace: Option<String>,
    /// Joint state rate, Hz.
    pub rate_hz: f64,
    /// Endpoints to listen on (default [`DEFAULT_LISTEN`]); empty: listen on none.
    pub listen: Vec<String>,
    /// Endpoints to connect to (a router).
    pub connect: Vec<String>,
    /// How the bridge joins Zenoh: a peer (default) or a client of a router.
    pub mode: ZenohMode,
    /// A Zenoh configuration file (TLS, access control, credentials); the endpoints
    /// and scouting above are set on top of it.
    pub zenoh_config: Option<PathBuf>,
    /// Armed from the start.
    pub armed: bool,
    /// Serve reads only: no request that changes a device, no command, no arming.
    pub read_only: bool,
    /// A command stream quiet for this long holds its joints.
    pub command_timeout: Duration,
    /// The state devices are brought to.
    pub safe_state: SafeState,
}

impl Default for BridgeConfig {
    fn default() -> Self {
        Self {
            namespace: None,
            rate_hz: 50.0,
            listen: vec![DEFAULT_LISTEN.to_owned()],
            connect: Vec::new(),
            mode: ZenohMode::Peer,
            zenoh_config: None,
            armed: false,
            read_only: false,
            command_timeout: Duration::from_millis(200),
            safe_state: SafeState::Hold,
        }
    }
}

impl BridgeConfig {
    /// Checks every option as [`Bridge::start`] does, opening nothing (a dry run): the
    /// keys it would declare, or the first bad option.
    pub fn check(&self) -> Result<Keys, BridgeError> {
        self.prepare().map(|(keys, _)| keys)
    }

    fn prepare(&self) -> Result<(Keys, zenoh::Config), BridgeError> {
        let keys = Keys::new(self.namespace.as_deref())?;
        if !robobus::catalogue::telemetry::RATE_HZ.contains(&self.rate_hz) {
            return Err(OpError::invalid(
                "--rate",
                self.rate_hz,
                format!(
                    "{}..={} Hz",
                    robobus::catalogue::telemetry::RATE_HZ.start(),
                    robobus::catalogue::telemetry::RATE_HZ.end()
                ),
            )
            .into());
        }
        let timeout_ms = self.command_timeout.as_millis();
        if !COMMAND_TIMEOUT_MS.contains(&u64::try_from(timeout_ms).unwrap_or(u64::MAX)) {
            return Err(OpError::invalid(
                "--command-timeout",
                format!("{timeout_ms} ms"),
                format!(
                    "{}..={} ms",
                    COMMAND_TIMEOUT_MS.start(),
                    COMMAND_TIMEOUT_MS.end()
                ),
            )
            .into());
        }
        let zconf = zconfig::build(self)?;
        Ok((keys, zconf))
    }
}

/// What can go wrong before a bridge runs.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    /// A bad option.
    #[error(transparent)]
    Op(#[from] OpError),
    /// Zenoh refused the configuration or could not open a session.
    #[error("zenoh: {0}")]
    Zenoh(String),
    /// A thread could not start.
    #[error("cannot start the bridge: {0}")]
    Start(#[from] std::io::Error),
    /// Another bridge serves the namespace (its liveliness token is up): this one did not
    /// start, or, when both started at once, the later one gave way.
    #[error(
        "{namespace} is in use: another bridge{} serves it{}; give this bridge another \
         --namespace (one per robot, like bot2 or site/arm2), or stop the other one",
        other.as_ref().map(|z| format!(" (Zenoh ID {z})")).unwrap_or_default(),
        if *gave_way {
            ", and started first: this one gave way and stopped (anything it had moved \
             is brought to its safe state)"
        } else {
            ": this one did not start and declared nothing"
        }
    )]
    InUse {
        /// The namespace as the message names it (`namespace "bot1"`, or the root one).
        namespace: String,
        /// The other bridge's Zenoh ID, where its claim names it.
        other: Option<String>,
        /// Both started at once and this one, the later, gave way.
        gave_way: bool,
    },
}

impl BridgeError {
    /// Its kind.
    pub fn kind(&self) -> ErrorKind {
        match self {
            Self::Op(e) => e.kind(),
            Self::Zenoh(_) | Self::Start(_) | Self::InUse { .. } => ErrorKind::NotAvailable,
        }
    }
}

fn zerr(e: impl std::fmt::Display) -> BridgeError {
    BridgeError::Zenoh(e.to_string())
}

/// The bridge's keys under its namespace.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Keys {
    /// `NS/joint_states`.
    pub joint_states: String,
    /// `NS/joint_commands`.
    pub joint_commands: String,
    /// `NS/diagnostics`.
    pub diagnostics: String,
    /// `NS/robobus/run`.
    pub run: String,
    /// `NS/robobus/plan`.
    pub plan: String,
    /// `NS/robobus/arm`.
    pub arm: String,
    /// `NS/robobus/health`.
    pub health: String,
    /// `NS/robobus/bridge` (liveliness).
    pub alive: String,
    /// `NS/robobus/sim`.
    pub sim: String,
}

impl Keys {
    /// The keys under `namespace` (checked by [`namespace_prefix`]).
    pub fn new(namespace: Option<&str>) -> Result<Self, OpError> {
        let p = namespace_prefix(namespace)?;
        let k = |s: &str| format!("{p}{s}");
        Ok(Self {
            joint_states: k("joint_states"),
            joint_commands: k("joint_commands"),
            diagnostics: k("diagnostics"),
            run: k("robobus/run"),
            plan: k("robobus/plan"),
            arm: k("robobus/arm"),
            health: k("robobus/health"),
            alive: k("robobus/bridge"),
            sim: k("robobus/sim"),
        })
    }
}

/// Counters of the bridge, shown in its health.
#[derive(Debug, Default)]
pub(crate) struct Counters {
    pub(crate) states_published: AtomicU64,
    pub(crate) joints_left_out: AtomicU64,
    pub(crate) samples_failed: AtomicU64,
    pub(crate) commands_received: AtomicU64,
    pub(crate) commands_applied: AtomicU64,
    pub(crate) commands_superseded: AtomicU64,
    pub(crate) commands_stale: AtomicU64,
    pub(crate) commands_held: AtomicU64,
    pub(crate) refused_malformed: AtomicU64,
    pub(crate) refused_out_of_range: AtomicU64,
    pub(crate) refused_not_armed: AtomicU64,
    pub(crate) joint_failures: AtomicU64,
    pub(crate) holds: AtomicU64,
    pub(crate) queries: AtomicU64,
    pub(crate) queries_refused: AtomicU64,
}

fn bump(c: &AtomicU64) {
    c.fetch_add(1, Ordering::Relaxed);
}

/// What the command subscriber left for the command thread.
#[derive(Debug, Default)]
struct Inbox {
    /// The newest command payload not yet taken, and when it arrived.
    newest: Option<(Vec<u8>, Instant)>,
    /// When the latest command arrived.
    last_arrival: Option<Instant>,
    /// The stream's interval between commands (smoothed), while it is steady.
    interval: Option<Duration>,
    /// A command is being applied.
    applying: bool,
}

impl Inbox {
    /// When the stream's next command is due, and its interval.
    fn next_due(&self) -> Option<(Instant, Duration)> {
        self.last_arrival
            .zip(self.interval)
            .map(|(at, every)| (at + every, every))
    }
}

/// The newest command, waiting for the command thread.
#[derive(Debug, Default)]
struct Mailbox {
    slot: Mutex<Inbox>,
    ready: Condvar,
}

impl Mailbox {
    /// The inbox, locked (a thread that panicked holding it left it usable).
    fn inbox(&self) -> std::sync::MutexGuard<'_, Inbox> {
        self.slot.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// The arming and safe-stop state, shared with the guard's report callback.
#[derive(Debug, Default)]
pub(crate) struct Status {
    /// The operator's intent: commands and motion requests may move.
    pub(crate) armed: AtomicBool,
    /// A command stream is being followed (a command within the timeout).
    pub(crate) streaming: AtomicBool,
    pub(crate) last_safe: Mutex<Option<SafeEvent>>,
    pub(crate) safe_stops: AtomicU64,
}

/// What every thread of a bridge shares.
pub(crate) struct Shared {
    pub(crate) station: Arc<Station>,
    pub(crate) sim: Option<LiveSimulator>,
    pub(crate) guard: Guard,
    /// Read-only, arming and the write rate: the library's one admission.
    pub(crate) admission: Admission,
    pub(crate) follower: Option<Follower>,
    pub(crate) config: BridgeConfig,
    pub(crate) keys: Keys,
    pub(crate) status: Arc<Status>,
    pub(crate) counters: Counters,
    pub(crate) last_refusal: Mutex<Option<String>>,
    /// Why the newest held command moved nothing.
    pub(crate) last_held: Mutex<Option<String>>,
    /// What the buses carry.
    pub(crate) capacity: Capacity,
    /// The joint states' timing.
    pub(crate) states: health::StateClock,
    /// Each joint's last reading: answered or not (in the file's order).
    pub(crate) joint_ok: Mutex<Vec<Option<bool>>>,
    pub(crate) trajectories: trajectory::Trajectories,
    /// Velocity and effort commands.
    pub(crate) drives: commands::Drives,
    mailbox: Mailbox,
    stop: StopToken,
    /// Why the bridge gave way to another on its namespace, once it has.
    displaced: Mutex<Option<BridgeError>>,
    pub(crate) started: Instant,
}

impl std::fmt::Debug for Shared {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Shared")
            .field("keys", &self.keys)
            .finish_non_exhaustive()
    }
}

impl Shared {
    fn refuse(&self, counter: &AtomicU64, why: String) {
        bump(counter);
        tracing::debug!("command refused: {why}");
        *self
            .last_refusal
            .lock()
            .unwrap_or_else(PoisonError::into_inner) = Some(why);
    }

    /// A command the safety rules kept from moving anything (not armed, out of range,
    /// stale), counted under `counter` too.
    fn hold_command(&self, counter: &AtomicU64, why: String) {
        bump(&self.counters.commands_held);
        *self
            .last_held
            .lock()
            .unwrap_or_else(PoisonError::into_inner) = Some(why.clone());
        self.refuse(counter, why);
    }

    /// A command payload as it arrives: it replaces a waiting one (superseded, counted)
    /// and wakes the command thread.
    fn post(&self, payload: Vec<u8>, now: Instant) {
        let mut inbox = self.mailbox.inbox();
        if inbox.newest.replace((payload, now)).is_some() {
            bump(&self.counters.commands_superseded);
        }
        // A steady stream's interval: a gap longer than the command timeout starts again.
        let gap = inbox.last_arrival.map(|t| now.saturating_duration_since(t));
        inbox.interval = match (gap, inbox.interval) {
            (Some(g), _) if g > self.config.command_timeout => None,
            (Some(g), None) => Some(g),
            (Some(g), Some(i)) => Some((i * 3 + g) / 4),
            (None, _) => None,
        };
        inbox.last_arrival = Some(now);
        drop(inbox);
        self.mailbox.ready.notify_all();
    }

    /// Arms or disarms (the operator's intent and the guard).
    pub(crate) fn set_armed(&self, armed: bool) -> Result<(), OpError> {
        if armed {
            self.admission.may_arm()?;
            self.guard.arm(SESSION)?;
        } else if self.status.armed.load(Ordering::SeqCst) || self.guard.has_moved() {
            self.guard.disarm(SESSION)?;
        }
        self.status.armed.store(armed, Ordering::SeqCst);
        self.status.streaming.store(false, Ordering::SeqCst);
        Ok(())
    }

    pub(crate) fn armed(&self) -> bool {
        self.status.armed.load(Ordering::SeqCst)
    }

    /// How the admission sees the bridge: its guard, as its one session.
    fn arming(&self) -> Arming<'_> {
        Arming::Guard {
            guard: &self.guard,
            session: Some(SESSION),
        }
    }

    /// What every thread shares, before anything is declared: the guard (its control
    /// taken by the bridge's session) and the admission.
    fn new(
        station: Station,
        sim: Option<LiveSimulator>,
        config: BridgeConfig,
        keys: Keys,
    ) -> Result<Arc<Self>, BridgeError> {
        let station = Arc::new(station);
        // A trajectory played to its end holds its last point; the guard's safe state is
        // for stops, faults and a lost operator.
        station.set_hold_at_end(true);
        let follower = Follower::new(&station).ok();
        let drives = commands::Drives::new(&station);
        let joints = follower.as_ref().map_or(0, |f| f.joints().len());
        // Each joint's handle now (reads only), so that the first command costs no more
        // than the next; a silent joint is tried again by the first command.
        if let Some(f) = follower.as_ref().filter(|_| !config.read_only) {
            for r in f.prepare(&station) {
                if let robobus::ops::Outcome::Failed(e) = r.outcome {
                    tracing::info!("joint {}: {}", r.id, e.error);
                }
            }
        }
        let capacity = Capacity::of(&station, follower.as_ref().map_or(&[], Follower::joints));
        if let Some(note) = capacity.note(config.rate_hz) {
            tracing::warn!("{note}");
        }
        let status = Arc::new(Status::default());
        let report = Arc::clone(&status);
        let guard = Guard::new(
            Arc::clone(&station),
            GuardConfig {
                heartbeat_timeout: STALL_TIMEOUT,
                safe_state: config.safe_state,
            },
            move |e: &SafeEvent| {
                tracing::info!(
                    "safe stop ({}): {} devices {} in {:.1} ms",
                    e.reason,
                    e.devices.len(),
                    e.state,
                    e.took_ms
                );
                bump(&report.safe_stops);
                // The guard disarmed itself: the bridge stalled (a disarm asked for is
                // already recorded, and a re-arm may have followed it).
                if e.reason == robobus::frontend::guard::HEARTBEAT_LOST {
                    report.armed.store(false, Ordering::SeqCst);
                }
                report.streaming.store(false, Ordering::SeqCst);
                *report
                    .last_safe
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner) = Some(e.clone());
            },
        )?;
        guard.take_control(SESSION);
        let admission = Admission::new(
            FrontEnd {
                name: "this bridge".into(),
                read_only_how: "started with --read-only".into(),
                arm_how: format!("--armed, or arm on {}", keys.arm),
            },
            config.read_only,
        );
        Ok(Arc::new(Self {
            station,
            sim,
            guard,
            admission,
            follower,
            config,
            keys,
            status,
            counters: Counters::default(),
            last_refusal: Mutex::new(None),
            last_held: Mutex::new(None),
            capacity,
            states: health::StateClock::default(),
            joint_ok: Mutex::new(vec![None; joints]),
            trajectories: trajectory::Trajectories::default(),
            drives,
            mailbox: Mailbox::default(),
            stop: StopToken::new(),
            displaced: Mutex::new(None),
            started: Instant::now(),
        }))
    }
}

/// A running bridge (see the [crate docs](crate)); [`Bridge::run`] serves until stopped.
pub struct Bridge {
    shared: Arc<Shared>,
    session: zenoh::Session,
    threads: Vec<JoinHandle<()>>,
    declared: Vec<Box<dyn std::any::Any + Send>>,
    /// Shut down already (by [`Bridge::run`]).
    done: bool,
}

impl std::fmt::Debug for Bridge {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bridge")
            .field("keys", &self.shared.keys)
            .finish_non_exhaustive()
    }
}

impl Bridge {
    /// Opens a Zenoh session for `station` and declares every key (see the
    /// [crate docs](crate)); `sim`: the built-in simulators, for `NS/robobus/sim`.
    ///
    /// One bridge per namespace: before declaring anything it asks Zenoh for the
    /// namespace's liveliness tokens, and declares its own claim (`NS/robobus/bridge/C`,
    /// `C` its start time and Zenoh ID) next to `NS/robobus/bridge`. Of two bridges whose
    /// sessions reach each other, the later one does not start, or, if both started at
    /// once, stops as soon as it sees the earlier one's claim ([`Bridge::run`] returns
    /// the error).
    ///
    /// # Errors
    ///
    /// [`BridgeError::Op`] for a bad option, [`BridgeError::InUse`] for a namespace
    /// another bridge serves, [`BridgeError::Zenoh`] when Zenoh cannot open a session.
    pub fn start(
        station: Station,
        sim: Option<LiveSimulator>,
        config: BridgeConfig,
    ) -> Result<Self, BridgeError> {
        let (keys, zconf) = config.prepare()?;
        let shared = Shared::new(station, sim, config, keys)?;
        Self::declare(shared, zconf)
    }

    fn declare(shared: Arc<Shared>, zconf: zenoh::Config) -> Result<Self, BridgeError> {
        let session = zenoh::open(zconf).wait().map_err(zerr)?;
        // The namespace first: on one another bridge serves, nothing is declared and
        // nothing armed. A bridge that started first turning up later stops this one.
        let weak = Arc::downgrade(&shared);
        let claim = claim::claim(&session, &shared.keys, move |e| {
            if let Some(s) = weak.upgrade() {
                tracing::error!("{e}");
                *s.displaced.lock().unwrap_or_else(PoisonError::into_inner) = Some(e);
                s.stop.stop();
                s.mailbox.ready.notify_all();
            }
        })?;
        if shared.config.armed {
            shared.set_armed(true)?;
        }
        let keys = shared.keys.clone();
        let mut declared: Vec<Box<dyn std::any::Any + Send>> = vec![Box::new(claim)];
        let mut threads = Vec::new();

        // Commands: the newest one waits for the command thread; an older one not yet
        // taken is superseded (counted), as a position stream means.
        let s = Arc::clone(&shared);
        let sub = session
            .declare_subscriber(keys.joint_commands.clone())
            .callback(move |sample| {
                bump(&s.counters.commands_received);
                let payload = sample.payload();
                if payload.len() > MAX_REQUEST {
                    s.refuse(
                        &s.counters.refused_malformed,
                        format!(
                            "a command of {} bytes: more than the {MAX_REQUEST} read",
                            payload.len()
                        ),
                    );
                    return;
                }
                s.post(payload.to_bytes().into_owned(), Instant::now());
            })
            .wait()
            .map_err(zerr)?;
        declared.push(Box::new(sub));
        let s = Arc::clone(&shared);
        threads.push(spawn("robobus-commands", move || commands(&s))?);

        threads.extend(declare_queries(&shared, &session, &mut declared)?);
        threads.extend(trajectory::declare(&shared, &session, &mut declared)?);
        threads.extend(commands::declare(&shared, &session, &mut declared)?);

        // Joint states and diagnostics (on a bridge that moves joints), health.
        let moves = shared.follower.is_some();
        let cdr = Encoding::APPLICATION_CDR;
        let publishers: [(bool, &str, Encoding, &str, Publish); 3] = [
            (
                moves,
                &keys.joint_states,
                cdr.clone(),
                "robobus-states",
                states,
            ),
            (
                moves,
                &keys.diagnostics,
                cdr,
                "robobus-diagnostics",
                diagnostics::publish,
            ),
            (
                true,
                &keys.health,
                Encoding::APPLICATION_JSON,
                "robobus-health",
                health::publish_health,
            ),
        ];
        for (_, key, encoding, name, publish) in publishers.into_iter().filter(|p| p.0) {
            threads.push(publishing(&shared, &session, key, encoding, name, publish)?);
        }

        // Liveliness.
        let token = session
            .liveliness()
            .declare_token(keys.alive.clone())
            .wait()
            .map_err(zerr)?;
        declared.push(Box::new(token));
        Ok(Self {
            shared,
            session,
            threads,
            declared,
            done: false,
        })
    }

    /// The keys it serves.
    pub fn keys(&self) -> &Keys {
        &self.shared.keys
    }

    /// The joints of a command, in order (empty without a robot file).
    pub fn joint_names(&self) -> Vec<String> {
        self.shared
            .follower
            .as_ref()
            .map(|f| f.joints().iter().map(|j| j.name.clone()).collect())
            .unwrap_or_default()
    }

    /// Its Zenoh ID.
    pub fn zid(&self) -> String {
        self.session.zid().to_string()
    }

    /// What the station's buses carry (computed from their timing).
    pub fn capacity(&self) -> &Capacity {
        &self.shared.capacity
    }

    /// What to tell the user at start when the buses carry less than the joint state rate
    /// asked; `None` when they carry it.
    pub fn rate_note(&self) -> Option<String> {
        self.shared.capacity.note(self.shared.config.rate_hz)
    }

    /// The health now (what `NS/robobus/health` publishes).
    pub fn health(&self) -> Health {
        health::of(&self.shared)
    }

    /// Serves until `stop` is set; then stops its threads, brings every device it moved
    /// to the safe state, withdraws its keys and closes the session and the station.
    ///
    /// # Errors
    ///
    /// [`BridgeError::InUse`] when it stopped because a bridge that started before it
    /// serves its namespace too (see [`Bridge::start`]); a Zenoh error closing the session.
    pub fn run(mut self, stop: &StopToken) -> Result<(), BridgeError> {
        while !stop.is_stopped() && !self.shared.stop.is_stopped() {
            std::thread::sleep(Duration::from_millis(20));
        }
        let closed = self.shutdown();
        match self.displaced() {
            Some(e) => Err(e),
            None => closed,
        }
    }

    /// Why it stopped by itself, if it did: another bridge that started before it serves
    /// its namespace too (taken: `None` after).
    fn displaced(&self) -> Option<BridgeError> {
        self.shared
            .displaced
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take()
    }

    /// Whether it gave way to another bridge on its namespace and stopped serving (the
    /// error [`Bridge::run`] then returns).
    pub fn gave_way(&self) -> bool {
        self.shared
            .displaced
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .is_some()
    }

    fn shutdown(&mut self) -> Result<(), BridgeError> {
        self.done = true;
        self.shared.stop.stop();
        self.shared.mailbox.ready.notify_all();
        // The declarations first: no callback runs after this.
        self.declared.clear();
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
        let closed = self.session.close().wait().map_err(zerr);
        // Every device moved is brought to the safe state before the station closes.
        let _ = self.shared.set_armed(false);
        closed
    }
}

impl Drop for Bridge {
    fn drop(&mut self) {
        if !self.done {
            let _ = self.shutdown();
        }
    }
}

fn spawn(name: &str, f: impl FnOnce() + Send + 'static) -> std::io::Result<JoinHandle<()>> {
    std::thread::Builder::new().name(name.to_owned()).spawn(f)
}

/// What a publishing thread runs until the bridge stops.
type Publish = fn(&Shared, &zenoh::pubsub::Publisher<'static>);

/// Declares a publisher on `key` with `encoding` and a thread `name` that publishes on it
/// with `publish` until the bridge stops.
fn publishing(
    shared: &Arc<Shared>,
    session: &zenoh::Session,
    key: &str,
    encoding: Encoding,
    name: &str,
    publish: Publish,
) -> Result<JoinHandle<()>, BridgeError> {
    let publisher = session
        .declare_publisher(key.to_owned())
        .encoding(encoding)
        .wait()
        .map_err(zerr)?;
    let s = Arc::clone(shared);
    Ok(spawn(name, move || publish(&s, &publisher))?)
}

#[cfg(test)]
mod testing;
#[cfg(test)]
mod tests;
