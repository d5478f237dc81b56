//! `NS/joint_commands/velocity` and `NS/joint_commands/effort`: `std_msgs/msg/
//! Float64MultiArray` in CDR (what `ros2_controllers`' forward velocity and effort
//! controllers publish), and `NS/robobus/interface`, the queryable that switches joints
//! between their interfaces (what activating such a controller, which claims its joints'
//! interfaces, does).
//!
//! The semantics are the library's ([`robobus::station::follow::drive::Driver`]): this
//! module decodes, admits (armed, through the guard, as `NS/joint_commands`), hands over,
//! counts, and keeps the watchdog: a stream quiet for the command timeout brings its joints
//! to rest and back on their position interface ([`Driver::release`]), then the guard holds
//! what the bridge moved. Disarming releases them too. While a joint is on velocity or
//! effort, `NS/joint_commands` (positions) is held, nothing sent.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use robobus::cdr;
use robobus::ops::{OpError, Outcome};
use robobus::robot::Interface;
use robobus::station::follow::drive::{DriveJoint, Driver};
use serde::Serialize;
use zenoh::Wait as _;
use zenoh::query::Query;

use crate::{BridgeError, HOLD_REASON, MAX_REQUEST, SESSION, Shared, bump, zerr};

/// Interface queries waiting at most; more are answered busy.
const QUERY_QUEUE: usize = 4;

/// The keys of velocity and effort commands under a namespace prefix (`bot/` or empty).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CommandKeys {
    /// `NS/joint_commands/velocity`: rad/s, one per joint on velocity.
    pub velocity: String,
    /// `NS/joint_commands/effort`: N·m, one per joint on effort.
    pub effort: String,
    /// `NS/robobus/interface`: the queryable that reads and switches interfaces.
    pub interface: String,
}

impl CommandKeys {
    /// Under `prefix` (as [`crate::namespace_prefix`] makes it).
    #[must_use]
    pub fn under(prefix: &str) -> Self {
        Self {
            velocity: format!("{prefix}joint_commands/velocity"),
            effort: format!("{prefix}joint_commands/effort"),
            interface: format!("{prefix}robobus/interface"),
        }
    }
}

/// One stream's counts, in the health.
#[derive(Debug, Default)]
struct Counts {
    received: AtomicU64,
    applied: AtomicU64,
    superseded: AtomicU64,
    stale: AtomicU64,
    refused_malformed: AtomicU64,
    refused_out_of_range: AtomicU64,
    refused_not_armed: AtomicU64,
    joint_failures: AtomicU64,
    timeouts: AtomicU64,
}

/// One stream's counts as the health shows them.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct StreamHealth {
    /// Commands received.
    pub received: u64,
    /// Commands sent to the joints.
    pub applied: u64,
    /// Commands replaced by a newer one before they were taken.
    pub superseded: u64,
    /// Commands that waited longer than the command timeout (nothing sent).
    pub stale: u64,
    /// Refused: not a `Float64MultiArray`, or too large.
    pub refused_malformed: u64,
    /// Refused whole: a wrong count, a value not finite or past its limit, no joint on
    /// the interface.
    pub refused_out_of_range: u64,
    /// Refused: not armed.
    pub refused_not_armed: u64,
    /// Joints whose frame failed.
    pub joint_failures: u64,
    /// Times the stream went quiet and its joints were released.
    pub timeouts: u64,
}

impl Counts {
    fn health(&self) -> StreamHealth {
        let g = |c: &AtomicU64| c.load(Ordering::Relaxed);
        StreamHealth {
            received: g(&self.received),
            applied: g(&self.applied),
            superseded: g(&self.superseded),
            stale: g(&self.stale),
            refused_malformed: g(&self.refused_malformed),
            refused_out_of_range: g(&self.refused_out_of_range),
            refused_not_armed: g(&self.refused_not_armed),
            joint_failures: g(&self.joint_failures),
            timeouts: g(&self.timeouts),
        }
    }
}

/// Velocity and effort in the health.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DriveHealth {
    /// `NS/joint_commands/velocity`.
    pub velocity: StreamHealth,
    /// `NS/joint_commands/effort`.
    pub effort: StreamHealth,
    /// The joints on velocity now, in the order of a velocity command.
    pub velocity_joints: Vec<String>,
    /// The joints on effort now, in the order of an effort command.
    pub effort_joints: Vec<String>,
    /// The newest refusal or release, in words.
    pub last: Option<String>,
}

#[derive(Debug, Default)]
struct Inbox {
    velocity: Option<(Vec<u8>, Instant)>,
    effort: Option<(Vec<u8>, Instant)>,
    queries: Vec<Query>,
}

/// What the velocity and effort streams share with the bridge.
#[derive(Debug)]
pub(crate) struct Drives {
    pub(crate) driver: Option<Driver>,
    velocity: Counts,
    effort: Counts,
    inbox: Mutex<Inbox>,
    ready: Condvar,
    last: Mutex<Option<String>>,
    /// When each stream's newest command was applied (velocity, effort).
    applied_at: Mutex<[Option<Instant>; 2]>,
}

impl Drives {
    pub(crate) fn new(station: &robobus::station::Station) -> Self {
        Self {
            driver: Driver::new(station).ok(),
            velocity: Counts::default(),
            effort: Counts::default(),
            inbox: Mutex::new(Inbox::default()),
            ready: Condvar::new(),
            last: Mutex::new(None),
            applied_at: Mutex::new([None, None]),
        }
    }

    fn counts(&self, interface: Interface) -> &Counts {
        if interface == Interface::Velocity {
            &self.velocity
        } else {
            &self.effort
        }
    }

    fn note(&self, counter: &AtomicU64, why: String) {
        bump(counter);
        tracing::debug!("{why}");
        *self.last.lock().unwrap_or_else(PoisonError::into_inner) = Some(why);
    }

    pub(crate) fn health(&self) -> DriveHealth {
        let names = |i| {
            self.driver
                .as_ref()
                .map(|d| d.on(i).into_iter().map(|j| j.name).collect())
                .unwrap_or_default()
        };
        DriveHealth {
            velocity: self.velocity.health(),
            effort: self.effort.health(),
            velocity_joints: names(Interface::Velocity),
            effort_joints: names(Interface::Effort),
            last: self
                .last
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .clone(),
        }
    }

    /// Why a position command may not move the joints now: some are on velocity or
    /// effort.
    pub(crate) fn blocks_positions(&self) -> Option<String> {
        let off: Vec<String> = self
            .driver
            .as_ref()?
            .joints()
            .into_iter()
            .filter(|j| j.interface != Interface::Position)
            .map(|j| format!("{} ({})", j.name, j.interface))
            .collect();
        (!off.is_empty()).then(|| {
            format!(
                "joint_commands: {} not on the position interface: switch them back \
                 (robobus/interface, {{\"interface\": \"position\", \"joints\": [...]}}); \
                 nothing was sent",
                off.join(", ")
            )
        })
    }

    fn post(&self, interface: Interface, payload: Vec<u8>, now: Instant) {
        let mut inbox = self.inbox.lock().unwrap_or_else(PoisonError::into_inner);
        let slot = if interface == Interface::Velocity {
            &mut inbox.velocity
        } else {
            &mut inbox.effort
        };
        if slot.replace((payload, now)).is_some() {
            bump(&self.counts(interface).superseded);
        }
        drop(inbox);
        self.ready.notify_all();
    }
}

/// The subscribers, the queryable and the thread that serves them.
pub(crate) fn declare(
    shared: &Arc<Shared>,
    session: &zenoh::Session,
    declared: &mut Vec<Box<dyn std::any::Any + Send>>,
) -> Result<Vec<JoinHandle<()>>, BridgeError> {
    // A read-only bridge moves nothing: it offers no command stream and no switch.
    if shared.config.read_only {
        return Ok(Vec::new());
    }
    let keys = CommandKeys::under(&crate::namespace_prefix(
        shared.config.namespace.as_deref(),
    )?);
    for (key, interface) in [
        (keys.velocity.clone(), Interface::Velocity),
        (keys.effort.clone(), Interface::Effort),
    ] {
        let s = Arc::clone(shared);
        let sub = session
            .declare_subscriber(key)
            .callback(move |sample| {
                let d = &s.drives;
                bump(&d.counts(interface).received);
                let payload = sample.payload();
                if payload.len() > MAX_REQUEST {
                    d.note(
                        &d.counts(interface).refused_malformed,
                        format!(
                            "joint_commands/{interface}: a command of {} bytes: more than \
                             the {MAX_REQUEST} read",
                            payload.len()
                        ),
                    );
                    return;
                }
                d.post(interface, payload.to_bytes().into_owned(), Instant::now());
            })
            .wait()
            .map_err(zerr)?;
        declared.push(Box::new(sub));
    }
    let s = Arc::clone(shared);
    let q = session
        .declare_queryable(keys.interface)
        .callback(move |query| {
            let mut inbox = s
                .drives
                .inbox
                .lock()
                .unwrap_or_else(PoisonError::into_inner);
            if inbox.queries.len() >= QUERY_QUEUE {
                drop(inbox);
                crate::reply_error(
                    &query,
                    "refused",
                    &format!(
                        "the bridge is busy: {QUERY_QUEUE} interface queries are waiting; \
                         nothing was switched"
                    ),
                );
                return;
            }
            inbox.queries.push(query);
            drop(inbox);
            s.drives.ready.notify_all();
        })
        .wait()
        .map_err(zerr)?;
    declared.push(Box::new(q));
    let s = Arc::clone(shared);
    Ok(vec![crate::spawn("robobus-drives", move || serve(&s))?])
}

/// The thread: interface queries, then the newest command of each stream, then the
/// watchdog; at the bridge's end, every joint released to position.
fn serve(s: &Shared) {
    let timeout = s.config.command_timeout;
    let tick = (timeout / 4).clamp(Duration::from_millis(5), Duration::from_millis(50));
    while !s.stop.is_stopped() {
        let (queries, velocity, effort) = {
            let inbox = s
                .drives
                .inbox
                .lock()
                .unwrap_or_else(PoisonError::into_inner);
            let (mut inbox, _) = s
                .drives
                .ready
                .wait_timeout_while(inbox, tick, |m| {
                    m.velocity.is_none()
                        && m.effort.is_none()
                        && m.queries.is_empty()
                        && !s.stop.is_stopped()
                })
                .unwrap_or_else(PoisonError::into_inner);
            (
                std::mem::take(&mut inbox.queries),
                inbox.velocity.take(),
                inbox.effort.take(),
            )
        };
        for q in queries {
            let reply = query_text(&q).and_then(|t| interface(s, &t));
            match reply {
                Ok(v) => crate::reply_json(&q, &v),
                Err(e) => crate::reply_op_error(&q, &e),
            }
        }
        for (interface, next) in [(Interface::Velocity, velocity), (Interface::Effort, effort)] {
            if let Some((payload, at)) = next {
                take(s, interface, &payload, at);
            }
        }
        watch(s, Instant::now());
    }
    // The bridge's end: every joint off position to rest and back on it, before the guard
    // brings what the bridge moved to the safe state.
    if let Some(driver) = &s.drives.driver {
        for r in driver.release(&s.station, None) {
            if let Outcome::Failed(f) = r.outcome {
                tracing::warn!("joint {}: could not go back to position: {}", r.id, f.error);
            }
        }
    }
}

fn query_text(query: &Query) -> Result<String, OpError> {
    crate::query_text(query)
}

/// A command that waited: stale past the timeout, else followed.
fn take(s: &Shared, interface: Interface, payload: &[u8], at: Instant) {
    let timeout = s.config.command_timeout;
    let waited = at.elapsed();
    if waited > timeout {
        let d = &s.drives;
        d.note(
            &d.counts(interface).stale,
            format!(
                "joint_commands/{interface}: waited {} ms, longer than the command timeout {} \
                 ms: nothing was sent",
                waited.as_millis(),
                timeout.as_millis()
            ),
        );
    } else {
        follow(s, interface, payload, at);
    }
}

/// One command (arrived `at`): decoded, admitted, checked whole, applied; the stream's
/// watchdog restarts from `at`. Whether it was applied.
pub(crate) fn follow(s: &Shared, interface: Interface, payload: &[u8], at: Instant) -> bool {
    let d = &s.drives;
    let c = d.counts(interface);
    let what = format!("joint_commands/{interface}");
    let msg = match cdr::Float64MultiArray::decode(payload) {
        Ok(m) => m,
        Err(e) => {
            d.note(&c.refused_malformed, format!("{what}: {e}"));
            return false;
        }
    };
    let Some(driver) = &d.driver else {
        d.note(
            &c.refused_out_of_range,
            format!("{what}: the station has no robot file"),
        );
        return false;
    };
    if let Err(r) = s.admission.check_motion(s.arming(), &what) {
        d.note(&c.refused_not_armed, r.to_string());
        return false;
    }
    let plan = match driver.plan(interface, &msg.data) {
        Ok(p) => p,
        Err(e) => {
            d.note(&c.refused_out_of_range, format!("{what}: {e}"));
            return false;
        }
    };
    if let Err(why) = admit(s, &driver.on(interface)) {
        d.note(&c.refused_not_armed, format!("{what}: {why}"));
        return false;
    }
    let results = driver.apply(&s.station, interface, &plan);
    let failed = results
        .iter()
        .filter(|r| matches!(r.outcome, Outcome::Failed(_)))
        .count();
    c.joint_failures.fetch_add(failed as u64, Ordering::Relaxed);
    bump(&c.applied);
    d.applied_at.lock().unwrap_or_else(PoisonError::into_inner)
        [usize::from(interface == Interface::Effort)] = Some(at);
    true
}

/// The guard's admission of each joint (recorded as moved, for the safe stop).
fn admit(s: &Shared, joints: &[DriveJoint]) -> Result<(), String> {
    for j in joints {
        s.admission
            .admit_jog(s.arming(), j.family, Some(&j.bus), j.id)
            .map_err(|r| r.to_string())?;
    }
    Ok(())
}

/// The watchdog at `now`: a stream whose newest command is older than the timeout
/// releases its joints; disarmed, every joint off position is released.
pub(crate) fn watch(s: &Shared, now: Instant) {
    let Some(driver) = &s.drives.driver else {
        return;
    };
    let timeout = s.config.command_timeout;
    for (k, interface) in [Interface::Velocity, Interface::Effort]
        .into_iter()
        .enumerate()
    {
        let quiet = {
            let mut at = s
                .drives
                .applied_at
                .lock()
                .unwrap_or_else(PoisonError::into_inner);
            match at[k] {
                Some(t) if now.saturating_duration_since(t) > timeout || !s.armed() => {
                    at[k] = None;
                    Some(t)
                }
                _ => None,
            }
        };
        let off = !driver.on(interface).is_empty();
        if let Some(t) = quiet.filter(|_| off) {
            let released = driver.release(&s.station, Some(interface));
            let failed: Vec<String> = released
                .iter()
                .filter_map(|r| match &r.outcome {
                    Outcome::Failed(f) => Some(format!("{}: {}", r.id, f.error)),
                    Outcome::Ok(_) => None,
                })
                .collect();
            let d = &s.drives;
            d.note(
                &d.counts(interface).timeouts,
                format!(
                    "joint_commands/{interface}: {}: {} brought to rest and back on position{}",
                    if s.armed() { HOLD_REASON } else { "disarmed" },
                    released
                        .iter()
                        .map(|r| r.id.as_str())
                        .collect::<Vec<_>>()
                        .join(", "),
                    if failed.is_empty() {
                        String::new()
                    } else {
                        format!(" (failed: {})", failed.join("; "))
                    }
                ),
            );
            if s.armed() {
                let _ = s.guard.hold(SESSION, HOLD_REASON, t + timeout);
            }
        } else if !s.armed() && off {
            driver.release(&s.station, Some(interface));
        }
    }
}

/// What `NS/robobus/interface` asks for.
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Switch {
    interface: Interface,
    joints: Vec<String>,
}

/// The reply of `NS/robobus/interface`.
#[derive(Debug, Serialize)]
struct InterfaceReply {
    joints: Vec<DriveJoint>,
    velocity: Vec<String>,
    effort: Vec<String>,
}

/// One interface query: empty reads; `{"interface": I, "joints": [...]}` switches (armed).
pub(crate) fn interface(s: &Shared, text: &str) -> Result<serde_json::Value, OpError> {
    let driver = s.drives.driver.as_ref().ok_or_else(|| {
        OpError::invalid(
            "robot",
            "none",
            "interfaces need a robot file (--robot FILE)",
        )
    })?;
    let t = text.trim();
    if !t.is_empty() {
        let ask: Switch = serde_json::from_str(t).map_err(|e| {
            OpError::invalid(
                "interface",
                robobus::ops::cut(t),
                format!(
                    "{{\"interface\": \"position\" | \"velocity\" | \"effort\", \"joints\": \
                     [NAME, ...]}}, or nothing to read ({e})"
                ),
            )
        })?;
        if ask.joints.is_empty() || ask.joints.len() > 256 {
            return Err(OpError::invalid(
                "joints",
                format!("{} names", ask.joints.len()),
                "1..=256 joint names of the robot file",
            ));
        }
        s.admission
            .check_motion(s.arming(), "robobus/interface")
            .map_err(|r| OpError::Refused(r.to_string()))?;
        let named: Vec<DriveJoint> = driver
            .joints()
            .into_iter()
            .filter(|j| ask.joints.contains(&j.name))
            .collect();
        admit(s, &named).map_err(OpError::Refused)?;
        let done = driver.switch(&s.station, &ask.joints, ask.interface)?;
        let failed: Vec<String> = done
            .iter()
            .filter_map(|r| match &r.outcome {
                Outcome::Failed(f) => Some(format!("{}: {}", r.id, f.error)),
                Outcome::Ok(_) => None,
            })
            .collect();
        if !failed.is_empty() {
            return Err(OpError::Refused(format!(
                "switching to {}: {}",
                ask.interface,
                failed.join("; ")
            )));
        }
        // A switched stream starts afresh: no watchdog until its first command.
        let k = usize::from(ask.interface == Interface::Effort);
        if ask.interface != Interface::Position {
            s.drives
                .applied_at
                .lock()
                .unwrap_or_else(PoisonError::into_inner)[k] = None;
        }
    }
    let names = |i| driver.on(i).into_iter().map(|j| j.name).collect();
    Ok(serde_json::to_value(InterfaceReply {
        joints: driver.joints(),
        velocity: names(Interface::Velocity),
        effort: names(Interface::Effort),
    })
    .unwrap_or_default())
}

#[cfg(test)]
mod tests;
