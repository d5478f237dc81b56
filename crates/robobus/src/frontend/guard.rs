//! The operator guard of a remote front end (a web page, a pub/sub bridge): who controls
//! a station, whether motion is armed, and the dead man's switch that brings every device
//! the operator moved to its safe state when the operator goes away.
//!
//! - **One controller.** Sessions are numbers the front end hands out; one of them at a
//!   time controls ([`Guard::take_control`]). A request that changes a device
//!   ([`Effect::Configure`] or [`Effect::Motion`]) from another session is refused
//!   ([`Guard::admit`]); reads are always admitted.
//! - **Motion needs arming.** [`Effect::Motion`] requests and jogs are admitted only from
//!   the controller while it is armed ([`Guard::arm`]). Each admitted motion records the
//!   devices it sets moving ([`Request::moved`]).
//! - **A dead man's switch.** While armed, the controller must call [`Guard::heartbeat`]
//!   at least every [`GuardConfig::heartbeat_timeout`]. When it stops, disarms, releases
//!   control or closes, the guard's own thread stops every running operation admitted
//!   through [`Guard::running`] (each ends in its own safe state) and applies
//!   [`SafeState::apply`] (the configured state) to every device moved since arming,
//!   then reports a [`SafeEvent`].

use std::collections::{BTreeMap, HashMap};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use robobus_wck::{ServoId, TorqueLevel};
use robobus_whj::JointId;
use serde::Serialize;

use crate::catalogue::{Effect, Family, Request};
use crate::ops::safe::{self, SafeDevices};
use crate::ops::whj::ServoLoop;
use crate::ops::{OpError, SafeState, StopToken};
use crate::station::Station;

/// The reason of a safe stop the guard made because the heartbeat stopped (it disarms).
pub const HEARTBEAT_LOST: &str = "heartbeat lost";

/// How a guard behaves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GuardConfig {
    /// The longest time between two heartbeats of an armed controller.
    pub heartbeat_timeout: Duration,
    /// The state moved devices are brought to.
    pub safe_state: SafeState,
}

impl Default for GuardConfig {
    /// 200 ms, hold.
    fn default() -> Self {
        Self {
            heartbeat_timeout: Duration::from_millis(200),
            safe_state: SafeState::Hold,
        }
    }
}

/// A device brought to its safe state.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Serialize)]
pub struct GuardedDevice {
    /// The family.
    pub family: Family,
    /// The station's bus.
    pub bus: String,
    /// Servo or joint ID.
    pub id: u8,
}

/// What the guard did when the operator went away or disarmed.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SafeEvent {
    /// Why (`"heartbeat lost"`, `"disarmed"`, `"control released"`).
    pub reason: String,
    /// The state applied (`"hold"`, ...).
    pub state: String,
    /// The devices brought to it.
    pub devices: Vec<GuardedDevice>,
    /// Operations that were running and were stopped.
    pub stopped_runs: usize,
    /// The devices that could not be brought to it, with why.
    pub failures: Vec<String>,
    /// How long after the cause the last device was in its state, ms.
    pub took_ms: f64,
}

/// One session's view of the guard.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct ControlView {
    /// This session controls.
    pub controller: bool,
    /// The controller is armed.
    pub armed: bool,
    /// Another session controls.
    pub held_by_other: bool,
}

#[derive(Debug, Default)]
struct State {
    controller: Option<u64>,
    armed: bool,
    last_beat: Option<Instant>,
    moved: BTreeMap<GuardedDevice, ServoLoop>,
    runs: HashMap<u64, StopToken>,
    next_run: u64,
    /// A trip asked for by a caller (`disarm`, `release`, `hold`), with its time and
    /// whether it disarms.
    pending: Option<(String, Instant, bool)>,
    closing: bool,
}

type OnSafe = Box<dyn Fn(&SafeEvent) + Send + Sync>;

struct Inner {
    station: Arc<Station>,
    config: GuardConfig,
    state: Mutex<State>,
    wake: Condvar,
    on_safe: OnSafe,
}

/// The guard of one station (see the [module docs](self)); its thread stops on drop.
pub struct Guard {
    inner: Arc<Inner>,
    thread: Option<JoinHandle<()>>,
}

impl std::fmt::Debug for Guard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Guard")
            .field("config", &self.inner.config)
            .finish_non_exhaustive()
    }
}

/// A running operation admitted by the guard: stopped when the guard trips; forgotten
/// when dropped.
pub struct RunTicket {
    inner: Arc<Inner>,
    id: u64,
}

impl std::fmt::Debug for RunTicket {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RunTicket")
            .field("id", &self.id)
            .finish_non_exhaustive()
    }
}

impl Drop for RunTicket {
    fn drop(&mut self) {
        self.inner.lock().runs.remove(&self.id);
    }
}

impl Inner {
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

impl Guard {
    /// A guard of `station`; `on_safe` hears of every safe stop (on the guard's thread).
    ///
    /// Errors: the guard's thread cannot be started.
    pub fn new(
        station: Arc<Station>,
        config: GuardConfig,
        on_safe: impl Fn(&SafeEvent) + Send + Sync + 'static,
    ) -> std::io::Result<Self> {
        let inner = Arc::new(Inner {
            station,
            config,
            state: Mutex::new(State::default()),
            wake: Condvar::new(),
            on_safe: Box::new(on_safe),
        });
        let watcher = Arc::clone(&inner);
        let thread = std::thread::Builder::new()
            .name("robobus-guard".into())
            .spawn(move || watch(&watcher))?;
        Ok(Self {
            inner,
            thread: Some(thread),
        })
    }

    /// The configuration.
    pub fn config(&self) -> GuardConfig {
        self.inner.config
    }

    /// `session`'s view.
    pub fn view(&self, session: u64) -> ControlView {
        let s = self.inner.lock();
        ControlView {
            controller: s.controller == Some(session),
            armed: s.armed,
            held_by_other: s.controller.is_some_and(|c| c != session),
        }
    }

    /// Makes `session` the controller if nobody is; its view afterwards.
    pub fn take_control(&self, session: u64) -> ControlView {
        {
            let mut s = self.inner.lock();
            if s.controller.is_none() {
                s.controller = Some(session);
            }
        }
        self.view(session)
    }

    /// `session` stops controlling (a page closed): if it was armed, its moved devices
    /// are brought to the safe state.
    pub fn release_control(&self, session: u64) {
        let mut s = self.inner.lock();
        if s.controller == Some(session) {
            s.controller = None;
            if s.armed || !s.moved.is_empty() {
                s.pending = Some(("control released".into(), Instant::now(), true));
                self.inner.wake.notify_all();
            }
        }
    }

    /// Arms motion for the controller `session` (its heartbeat clock starts now).
    pub fn arm(&self, session: u64) -> Result<(), OpError> {
        let mut s = self.inner.lock();
        if s.controller != Some(session) {
            return Err(not_controller());
        }
        s.armed = true;
        s.last_beat = Some(Instant::now());
        self.inner.wake.notify_all();
        Ok(())
    }

    /// Disarms: stops running operations and brings the moved devices to the safe state
    /// (reported by a [`SafeEvent`]).
    pub fn disarm(&self, session: u64) -> Result<(), OpError> {
        let mut s = self.inner.lock();
        if s.controller != Some(session) {
            return Err(not_controller());
        }
        s.armed = false;
        s.pending = Some(("disarmed".into(), Instant::now(), true));
        self.inner.wake.notify_all();
        Ok(())
    }

    /// Brings the devices moved since arming to the safe state now, with `reason`, and
    /// stops the running operations, but stays armed: what a command stream that went
    /// quiet asks for (the next command may move again). `since` is when the cause
    /// happened (for [`SafeEvent::took_ms`]). Nothing happens when nothing was moved.
    pub fn hold(&self, session: u64, reason: &str, since: Instant) -> Result<(), OpError> {
        let mut s = self.inner.lock();
        if s.controller != Some(session) {
            return Err(not_controller());
        }
        if !s.moved.is_empty() || !s.runs.is_empty() {
            s.pending = Some((reason.to_owned(), since, false));
            self.inner.wake.notify_all();
        }
        Ok(())
    }

    /// Whether any device was moved since arming (or since the last safe stop).
    pub fn has_moved(&self) -> bool {
        !self.inner.lock().moved.is_empty()
    }

    /// The armed controller's heartbeat.
    pub fn heartbeat(&self, session: u64) {
        let mut s = self.inner.lock();
        if s.controller == Some(session) && s.armed {
            s.last_beat = Some(Instant::now());
        }
    }

    /// Whether `session` may run `request` now; an admitted motion's devices are recorded
    /// for the safe stop. `session` is `None` for a client without one (a script), which
    /// may change devices only while nobody controls, and never move them.
    pub fn admit(&self, session: Option<u64>, request: &Request) -> Result<(), OpError> {
        match request.effect() {
            Effect::Read => Ok(()),
            Effect::Configure => {
                let s = self.inner.lock();
                match s.controller {
                    Some(c) if session != Some(c) => Err(not_controller()),
                    _ => Ok(()),
                }
            }
            Effect::Motion => {
                let moved = request.moved()?;
                let followers = self.followers(request);
                let mut s = self.inner.lock();
                motion_allowed(&s, session)?;
                for d in followers {
                    s.moved.insert(d, ServoLoop::Position);
                }
                if let Some(m) = moved {
                    let bus = self.bus_name(m.family, m.bus.as_deref())?;
                    for id in m.ids {
                        s.moved.insert(
                            GuardedDevice {
                                family: m.family,
                                bus: bus.clone(),
                                id,
                            },
                            m.servo,
                        );
                    }
                }
                Ok(())
            }
        }
    }

    /// Whether `session` may jog `device` on `bus`; records it as moved (position loop).
    pub fn admit_jog(
        &self,
        session: Option<u64>,
        family: Family,
        bus: Option<&str>,
        device: u8,
    ) -> Result<(), OpError> {
        let bus = self.bus_name(family, bus)?;
        let mut s = self.inner.lock();
        motion_allowed(&s, session)?;
        s.moved.insert(
            GuardedDevice {
                family,
                bus,
                id: device,
            },
            ServoLoop::Position,
        );
        Ok(())
    }

    /// Registers a running operation's stop token: the guard stops it when it trips.
    pub fn running(&self, token: &StopToken) -> RunTicket {
        let mut s = self.inner.lock();
        let id = s.next_run;
        s.next_run += 1;
        s.runs.insert(id, token.clone());
        RunTicket {
            inner: Arc::clone(&self.inner),
            id,
        }
    }

    /// The devices a `robot.teleop` moves: its followers, found in the station's robot
    /// file (a name it does not have is refused by the run itself).
    fn followers(&self, request: &Request) -> Vec<GuardedDevice> {
        let Request::RobotTeleop(t) = request else {
            return Vec::new();
        };
        let Some(robot) = self.inner.station.robot() else {
            return Vec::new();
        };
        t.map
            .iter()
            .filter_map(|p| robot.joints.iter().find(|j| j.name == p.follower))
            .map(|j| GuardedDevice {
                family: if robot.is_wck(j) {
                    Family::Wck
                } else {
                    Family::Whj
                },
                bus: j.bus.clone(),
                id: j.id,
            })
            .collect()
    }

    fn bus_name(&self, family: Family, bus: Option<&str>) -> Result<String, OpError> {
        let station = &self.inner.station;
        Ok(match family {
            Family::Wck => station.wck(bus)?.name().to_owned(),
            Family::Whj => station.whj(bus)?.name().to_owned(),
            Family::Robot => bus.unwrap_or("robot").to_owned(),
            Family::Host => crate::catalogue::host::HOST.to_owned(),
        })
    }
}

impl Drop for Guard {
    fn drop(&mut self) {
        {
            let mut s = self.inner.lock();
            s.closing = true;
            if s.armed || !s.moved.is_empty() {
                s.pending = Some(("closing".into(), Instant::now(), true));
            }
        }
        self.inner.wake.notify_all();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The torque level a wCK hold moves at (2: medium).
const HOLD_TORQUE: u8 = 2;

fn not_controller() -> OpError {
    OpError::Refused(
        "another session controls this station (or none was given): take control first; \
         nothing was sent"
            .into(),
    )
}

fn motion_allowed(s: &State, session: Option<u64>) -> Result<(), OpError> {
    if session.is_none() || s.controller != session {
        return Err(OpError::Refused(
            "motion needs the controlling session, armed (take control and arm first); \
             nothing was sent"
                .into(),
        ));
    }
    if !s.armed {
        return Err(OpError::Refused(
            "motion is not armed: arm first; nothing was sent".into(),
        ));
    }
    Ok(())
}

/// The guard's thread: waits for the heartbeat deadline or a trip, then trips.
fn watch(inner: &Inner) {
    let timeout = inner.config.heartbeat_timeout;
    let mut s = inner.lock();
    loop {
        let now = Instant::now();
        let lost = s.armed
            && s.last_beat
                .is_some_and(|t| now.saturating_duration_since(t) > timeout);
        let cause = if let Some(p) = s.pending.take() {
            Some(p)
        } else if lost {
            // The cause is the heartbeat that did not come.
            let due = s.last_beat.map_or(now, |t| t + timeout);
            Some((HEARTBEAT_LOST.to_owned(), due, true))
        } else {
            None
        };
        if let Some((reason, since, disarm)) = cause {
            if disarm {
                s.armed = false;
            }
            let tokens: Vec<StopToken> = s.runs.values().cloned().collect();
            let moved = std::mem::take(&mut s.moved);
            drop(s);
            let event = trip(inner, reason, since, &tokens, moved);
            (inner.on_safe)(&event);
            s = inner.lock();
            continue;
        }
        if s.closing {
            return;
        }
        s = match (s.armed, s.last_beat) {
            (true, Some(t)) => {
                let wait = (t + timeout).saturating_duration_since(now) + Duration::from_millis(1);
                inner
                    .wake
                    .wait_timeout(s, wait)
                    .unwrap_or_else(PoisonError::into_inner)
                    .0
            }
            _ => inner.wake.wait(s).unwrap_or_else(PoisonError::into_inner),
        };
    }
}

/// Stops the running operations and brings the moved devices to the safe state.
fn trip(
    inner: &Inner,
    reason: String,
    since: Instant,
    tokens: &[StopToken],
    moved: BTreeMap<GuardedDevice, ServoLoop>,
) -> SafeEvent {
    for t in tokens {
        t.stop();
    }
    let state = inner.config.safe_state;
    let mut failures = Vec::new();
    // One application per bus and loop: wCK servos by bus, WHJ joints by bus and loop.
    let mut groups: BTreeMap<(Family, String, u8), Vec<u8>> = BTreeMap::new();
    for (d, servo) in &moved {
        let l = match servo {
            ServoLoop::Position => 0,
            ServoLoop::Speed => 1,
            ServoLoop::Current => 2,
        };
        groups
            .entry((d.family, d.bus.clone(), l))
            .or_default()
            .push(d.id);
    }
    for ((family, bus, l), ids) in groups {
        let servo = [ServoLoop::Position, ServoLoop::Speed, ServoLoop::Current][usize::from(l)];
        let failed = match family {
            Family::Wck => inner.station.wck(Some(&bus)).and_then(|port| {
                let ids: Vec<ServoId> = ids.iter().filter_map(|&i| ServoId::new(i).ok()).collect();
                let torque = TorqueLevel::new(HOLD_TORQUE)
                    .map_err(|e| OpError::invalid("torque", HOLD_TORQUE, e.to_string()))?;
                let mut guard = port.lock();
                let mut devices = safe::WckServos {
                    bus: &mut guard,
                    ids: &ids,
                    torque,
                };
                Ok(apply(state, &mut devices))
            }),
            Family::Whj => inner.station.whj(Some(&bus)).map(|port| {
                let bus = port.bus();
                // Connected (the identity handshake) if nothing has yet: a joint that
                // does not answer it is a failure of its own, the others are held.
                let mut unreachable = Vec::new();
                let joints: Vec<_> = ids
                    .iter()
                    .filter_map(|&i| JointId::new(i).ok())
                    .filter_map(|id| {
                        bus.joint(id)
                            .map_err(|e| unreachable.push(format!("joint {id}: {e}")))
                            .ok()
                    })
                    .collect();
                let mut failed = apply(
                    state,
                    &mut safe::WhjJoints {
                        joints: &joints,
                        servo,
                    },
                );
                failed.extend(unreachable);
                failed
            }),
            Family::Robot | Family::Host => Ok(Vec::new()),
        };
        match failed {
            Ok(f) => failures.extend(f),
            Err(e) => failures.push(format!("bus {bus}: {e}")),
        }
    }
    SafeEvent {
        reason,
        state: format!("{state:?}").to_lowercase(),
        devices: moved.into_keys().collect(),
        stopped_runs: tokens.len(),
        failures,
        took_ms: since.elapsed().as_secs_f64() * 1e3,
    }
}

fn apply(state: SafeState, devices: &mut impl SafeDevices) -> Vec<String> {
    state
        .apply(devices)
        .into_iter()
        .map(|f| f.to_string())
        .collect()
}
