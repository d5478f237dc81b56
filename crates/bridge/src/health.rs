//! The bridge's outputs on a clock: joint states (each joint's last reading kept for the
//! diagnostics), and its health about once a second.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

use robobus::catalogue::Report;
use robobus::frontend::guard::SafeEvent;
use robobus::ops::{DeviceResult, ErrorKind, Failure, Outcome};
use robobus::station::Station;
use robobus::station::diagnostics::{Diagnosis, Stops, Watch};
use robobus::station::sampler::RobotJointSample;
use serde::Serialize;
use zenoh::Wait as _;

use crate::Shared;
use crate::cdr::{JointState, Time};

/// How often the health is published.
const HEALTH_PERIOD: Duration = Duration::from_secs(1);
/// The window the joint state rate achieved is measured over.
pub const RATE_WINDOW: Duration = Duration::from_secs(2);
/// Why samples were lost: the slot passed while a command stream had the buses.
pub(crate) const LOST_TO_COMMANDS: &str = "the buses were busy with commands (commands come first)";
/// Why samples were lost: a sample took longer than the period asked.
pub(crate) const LOST_TO_BUSES: &str =
    "a sample took longer than the period asked (the buses cannot carry the rate)";

/// The joint states' timing: when each of the last [`RATE_WINDOW`] was taken, and the
/// slots lost; and each joint's last reading, for the diagnostics.
#[derive(Debug, Default)]
pub(crate) struct StateClock {
    taken: Mutex<VecDeque<Instant>>,
    lost_reason: Mutex<Option<&'static str>>,
    lost_to_commands: AtomicU64,
    lost_total: AtomicU64,
    /// Each joint's last reading (made with the first sample).
    watch: Mutex<Option<Watch>>,
}

impl StateClock {
    /// Keeps each joint's reading of a sample taken at `at` (`None`: it failed as a
    /// whole) for the diagnostics.
    pub(crate) fn record(&self, station: &Station, report: Option<&Report>, at: Instant) {
        let mut watch = self.watch.lock().unwrap_or_else(PoisonError::into_inner);
        let watch = watch.get_or_insert_with(|| Watch::new(station));
        match report {
            Some(r) => watch.record(at, r.results.iter().filter_map(reading).collect()),
            None => watch.record_failure(
                at,
                &Failure::of(
                    ErrorKind::Device,
                    &"robot.sample failed as a whole: no joint was read",
                ),
            ),
        }
    }

    /// The diagnoses of the station's joints and buses at `now` from the last readings
    /// (every joint stale before the first).
    pub(crate) fn diagnose(
        &self,
        station: &Station,
        now: Instant,
        stale_after: Duration,
        stops: &Stops,
    ) -> Vec<Diagnosis> {
        let mut watch = self.watch.lock().unwrap_or_else(PoisonError::into_inner);
        watch
            .get_or_insert_with(|| Watch::new(station))
            .diagnose(station, now, stale_after, stops)
    }

    /// `n` slots passed without a sample, for `why`.
    pub(crate) fn lose(&self, n: u64, why: &'static str) {
        self.lost_total.fetch_add(n, Ordering::Relaxed);
        if why == LOST_TO_COMMANDS {
            self.lost_to_commands.fetch_add(n, Ordering::Relaxed);
        }
        *self
            .lost_reason
            .lock()
            .unwrap_or_else(PoisonError::into_inner) = Some(why);
    }

    /// A sample was taken at `at` (published or not).
    pub(crate) fn took(&self, at: Instant) {
        let mut t = self.taken.lock().unwrap_or_else(PoisonError::into_inner);
        t.push_back(at);
        while t
            .front()
            .is_some_and(|&f| at.saturating_duration_since(f) > RATE_WINDOW)
        {
            t.pop_front();
        }
    }

    /// Samples a second over the last [`RATE_WINDOW`]: the intervals between the samples
    /// taken in it over the time from the first of them until `now` (a rate that stopped
    /// falls as `now` moves on); `None` before two samples in the window.
    pub(crate) fn achieved_hz(&self, now: Instant) -> Option<f64> {
        let mut t = self.taken.lock().unwrap_or_else(PoisonError::into_inner);
        while t
            .front()
            .is_some_and(|&f| now.saturating_duration_since(f) > RATE_WINDOW)
        {
            t.pop_front();
        }
        let span = now.saturating_duration_since(*t.front()?);
        (t.len() >= 2 && !span.is_zero()).then(|| (t.len() - 1) as f64 / span.as_secs_f64())
    }
}

/// One bus of the robot file: its joints, and how many answered their last reading.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct BusHealth {
    /// The bus.
    pub name: String,
    /// Its joints in the robot file.
    pub joints: usize,
    /// Of them, those whose last reading answered.
    pub answering: usize,
}

/// Joint state publishing.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StatesHealth {
    /// The rate asked, Hz.
    pub asked_hz: f64,
    /// Samples taken a second over the last [`RATE_WINDOW`] (2 s): the intervals between
    /// them over the time since the first of them, Hz; `None` before two.
    pub achieved_hz: Option<f64>,
    /// The highest rate the buses carry, computed from their timing
    /// ([`Capacity`](crate::Capacity)), Hz; `None` without joints.
    pub bus_limit_hz: Option<f64>,
    /// Why the rate asked cannot be kept, when the buses cannot carry it.
    pub limited: Option<String>,
    /// Messages published.
    pub published: u64,
    /// Joints left out of a message (their reading failed), summed over messages.
    pub joints_left_out: u64,
    /// Samples whose read failed as a whole (nothing published for them).
    pub failed_samples: u64,
    /// Slots of the rate asked that passed without a sample: published + failed + lost
    /// is every slot since the first sample.
    pub lost_samples: u64,
    /// Of them, those that passed while commands had the buses.
    pub lost_to_commands: u64,
    /// Why the newest samples were lost.
    pub lost_reason: Option<String>,
}

/// Command following.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct CommandsHealth {
    /// Commands received.
    pub received: u64,
    /// Commands applied (every joint stepped or failed on its own).
    pub applied: u64,
    /// Commands replaced by a newer one before they were taken.
    pub superseded: u64,
    /// Commands the safety rules held: nothing moved (not armed, out of range, no robot
    /// file, stale). Received = applied + superseded + held + malformed, and one more
    /// while a command waits or is applied.
    pub held: u64,
    /// Why the newest held command moved nothing.
    pub last_held: Option<String>,
    /// Of the held, commands that waited longer than the command timeout before they
    /// could be taken (the buses were slower than the stream).
    pub stale: u64,
    /// Joints that failed in an applied command, summed.
    pub joint_failures: u64,
    /// Times the stream went quiet and its joints were held.
    pub holds: u64,
}

/// Refused commands, by reason.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Refusals {
    /// Not CDR of a `Float64MultiArray`.
    pub malformed: u64,
    /// Wrong count, not finite, outside a soft limit (or no robot file).
    pub out_of_range: u64,
    /// The bridge was not armed.
    pub not_armed: u64,
    /// The newest refusal's message.
    pub last: Option<String>,
}

/// What `NS/robobus/health` publishes.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Health {
    /// Seconds since the bridge started.
    pub uptime_s: f64,
    /// Commands and motion requests may move.
    pub armed: bool,
    /// Serves reads only (`BridgeConfig::read_only`): nothing that changes a device runs,
    /// nothing arms.
    pub read_only: bool,
    /// A command stream is being followed.
    pub streaming: bool,
    /// The joint state rate asked, Hz (what was achieved: `states.achieved_hz`).
    pub rate_hz: f64,
    /// The command timeout, ms.
    pub command_timeout_ms: u64,
    /// The robot file's buses.
    pub buses: Vec<BusHealth>,
    /// Joint states.
    pub states: StatesHealth,
    /// Commands.
    pub commands: CommandsHealth,
    /// Refused commands.
    pub refused: Refusals,
    /// Safe stops so far (command timeouts, disarming, a stalled bridge).
    pub safe_stops: u64,
    /// The newest safe stop.
    pub last_safe_stop: Option<SafeEvent>,
    /// Queries answered or waiting.
    pub queries: u64,
    /// Queries refused because the bridge was busy.
    pub queries_busy: u64,
    /// Trajectories on `NS/joint_trajectory`: received, refused, played and how they
    /// ended.
    pub trajectories: crate::TrajectoryHealth,
    /// Velocity and effort commands, and the joints on each.
    pub drives: crate::DriveHealth,
}

fn get(c: &AtomicU64) -> u64 {
    c.load(Ordering::Relaxed)
}

/// The health now.
pub(crate) fn of(s: &Shared) -> Health {
    let c = &s.counters;
    let ok = s
        .joint_ok
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .clone();
    let mut buses: Vec<BusHealth> = Vec::new();
    if let Some(f) = &s.follower {
        for (j, ok) in f.joints().iter().zip(&ok) {
            let i = buses
                .iter()
                .position(|b| b.name == j.bus)
                .unwrap_or_else(|| {
                    buses.push(BusHealth {
                        name: j.bus.clone(),
                        joints: 0,
                        answering: 0,
                    });
                    buses.len() - 1
                });
            buses[i].joints += 1;
            buses[i].answering += usize::from(*ok == Some(true));
        }
    }
    Health {
        uptime_s: s.started.elapsed().as_secs_f64(),
        armed: s.armed(),
        read_only: s.admission.read_only(),
        streaming: s.status.streaming.load(Ordering::SeqCst),
        rate_hz: s.config.rate_hz,
        command_timeout_ms: u64::try_from(s.config.command_timeout.as_millis()).unwrap_or(0),
        buses,
        states: StatesHealth {
            asked_hz: s.config.rate_hz,
            achieved_hz: s.states.achieved_hz(Instant::now()),
            bus_limit_hz: s.capacity.states_hz(),
            limited: s.capacity.note(s.config.rate_hz),
            published: get(&c.states_published),
            joints_left_out: get(&c.joints_left_out),
            failed_samples: get(&c.samples_failed),
            lost_samples: get(&s.states.lost_total),
            lost_to_commands: get(&s.states.lost_to_commands),
            lost_reason: s
                .states
                .lost_reason
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .map(str::to_owned),
        },
        commands: CommandsHealth {
            received: get(&c.commands_received),
            applied: get(&c.commands_applied),
            superseded: get(&c.commands_superseded),
            held: get(&c.commands_held),
            last_held: s
                .last_held
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .clone(),
            stale: get(&c.commands_stale),
            joint_failures: get(&c.joint_failures),
            holds: get(&c.holds),
        },
        refused: Refusals {
            malformed: get(&c.refused_malformed),
            out_of_range: get(&c.refused_out_of_range),
            not_armed: get(&c.refused_not_armed),
            last: s
                .last_refusal
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .clone(),
        },
        safe_stops: get(&s.status.safe_stops),
        last_safe_stop: s
            .status
            .last_safe
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone(),
        queries: get(&c.queries),
        queries_busy: get(&c.queries_refused),
        trajectories: s.trajectories.health(),
        drives: s.drives.health(),
    }
}

/// Publishes the health about once a second until the bridge stops.
pub(crate) fn publish_health(s: &Shared, publisher: &zenoh::pubsub::Publisher<'static>) {
    let mut next = std::time::Instant::now();
    while !s.stop.is_stopped() {
        if std::time::Instant::now() >= next {
            let body = serde_json::to_string(&of(s)).unwrap_or_default();
            if let Err(e) = publisher.put(body).wait() {
                tracing::warn!("health: {e}");
            }
            next += HEALTH_PERIOD;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The joint state message of one sample: every joint whose reading answered, in the
/// robot file's order; `None` when none did (a read that failed as a whole). Marks each
/// joint answering or not.
pub(crate) fn joint_state(s: &Shared, report: Option<&Report>, unix_ms: f64) -> Option<JointState> {
    let c = &s.counters;
    let mut ok = s.joint_ok.lock().unwrap_or_else(PoisonError::into_inner);
    let Some(report) = report else {
        c.samples_failed.fetch_add(1, Ordering::Relaxed);
        ok.iter_mut().for_each(|o| *o = Some(false));
        return None;
    };
    let mut msg = JointState {
        stamp: Time::from_unix_ms(unix_ms),
        ..JointState::default()
    };
    for (i, row) in report.results.iter().enumerate() {
        let position = row.get("position_deg").and_then(serde_json::Value::as_f64);
        let name = row.get("id").and_then(serde_json::Value::as_str);
        if let Some(o) = ok.get_mut(i) {
            *o = Some(position.is_some());
        }
        let (Some(name), Some(deg)) = (name, position) else {
            c.joints_left_out.fetch_add(1, Ordering::Relaxed);
            continue;
        };
        msg.name.push(name.to_owned());
        msg.position.push(deg.to_radians());
        // Unknown (a wCK servo's first reading): NaN, as JointState marks a value it
        // does not have.
        msg.velocity.push(
            row.get("speed_deg_s")
                .and_then(serde_json::Value::as_f64)
                .map_or(f64::NAN, f64::to_radians),
        );
        msg.effort.push(
            row.get("effort_nm")
                .and_then(serde_json::Value::as_f64)
                .unwrap_or(f64::NAN),
        );
    }
    if msg.name.is_empty() {
        // No joint answered: the sample failed as a whole.
        c.samples_failed.fetch_add(1, Ordering::Relaxed);
        return None;
    }
    Some(msg)
}

/// One `robot.sample` row as the library typed it: a joint's reading or its failure
/// (`None` for a row without its name).
fn reading(row: &serde_json::Value) -> Option<DeviceResult<String, RobotJointSample>> {
    let id = row.get("id")?.as_str()?.to_owned();
    let f = |k: &str| row.get(k).and_then(serde_json::Value::as_f64);
    let text = |k: &str| row.get(k).and_then(serde_json::Value::as_str);
    let outcome = match f("position_deg") {
        Some(position_deg) => Outcome::Ok(RobotJointSample {
            position_deg,
            speed_deg_s: f("speed_deg_s"),
            current_ma: row.get("current_ma").and_then(serde_json::Value::as_i64),
            effort_nm: f("effort_nm"),
            load: row
                .get("load")
                .and_then(serde_json::Value::as_u64)
                .and_then(|l| u8::try_from(l).ok()),
            enabled: row.get("enabled").and_then(serde_json::Value::as_bool),
            error: text("error").unwrap_or_default().to_owned(),
        }),
        None => Outcome::Failed(Failure {
            kind: row
                .get("kind")
                .and_then(|k| serde_json::from_value(k.clone()).ok())
                .unwrap_or(ErrorKind::Device),
            error: text("error").unwrap_or("no reading").to_owned(),
        }),
    };
    Some(DeviceResult { id, outcome })
}

/// Publishes one sample (its report, or `None` for a read that failed as a whole) taken
/// at `at` as a joint state, and keeps its readings for the diagnostics.
pub(crate) fn publish_sample(
    s: &Shared,
    report: Option<&Report>,
    unix_ms: f64,
    at: Instant,
    publisher: &zenoh::pubsub::Publisher<'static>,
) {
    s.states.took(at);
    s.states.record(&s.station, report, at);
    if let Some(msg) = joint_state(s, report, unix_ms) {
        match publisher.put(msg.encode()).wait() {
            Ok(()) => {
                s.counters.states_published.fetch_add(1, Ordering::Relaxed);
            }
            Err(e) => tracing::warn!("joint states: {e}"),
        }
    }
}
