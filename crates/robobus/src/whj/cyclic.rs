//! The cyclic servo loop: the bus thread sends one command frame per joint (or one
//! broadcast frame for joints 1..=7) at a fixed rate, collects the feedback, and keeps
//! deadline-miss and latency statistics.
//!
//! Feedback is matched to commands per joint. A joint answers each servo (or broadcast)
//! frame with one feedback frame, in order, so its first feedback after a command answers
//! that command. When a cycle closes without a joint's feedback, that feedback is owed:
//! the joint's next feedback frame is counted as a late reply of the closed cycle, not as
//! the new cycle's feedback (which would leave every later cycle holding the previous
//! command's answer). A frame received before the running cycle's command can have been
//! answered is never that cycle's feedback: one bus carries the command, the feedback
//! frames already credited to the cycle and this frame one after the other, each for its
//! wire time at the WHJ bit rates. Before the next cycle's frames go out,
//! the driver reads every frame already received, so a frame that came before the next
//! command is credited to the cycle it answers (and a cycle whose last feedback came after
//! its deadline is reported as missed). The frames carry no sequence number, so a
//! feedback frame that is lost outright cannot be told from a late one. Two rules keep a
//! lost frame from shifting the matching for good: a cycle in which the joint's only frame
//! paid an older debt, at a time when it could also have answered this cycle's command,
//! owes its own frame only perhaps, and the joint's next frame gives that debt up (the
//! joint answered once for one command) if it comes as late in its cycle as the joint's
//! feedback ever has, else pays it; and an owed reply is given up as lost once it is four
//! periods (at least 20 ms) old. A lost frame therefore
//! costs one more missed cycle, and feedback is matched again from the cycle after.

use core::time::Duration;
use std::collections::VecDeque;
use std::sync::{Arc, Condvar, Mutex};
use std::time::Instant;

use robobus_whj::timing::{BitRates, frame_duration};
use robobus_whj::units::{ActualSpeed, Current, Position, TargetSpeed};
use robobus_whj::{
    BroadcastCurrent, BroadcastFeedback, BroadcastPosition, CanFrame, ErrorCode, Function, JointId,
    Reply, ReplyMask, Request, ServoFeedback,
};

use super::bus::{JointBus, lock};
use super::error::WhjError;
use super::trajectory::{MotionLimits, Profile};

mod owned;
pub use owned::OwnedCyclic;

/// Which servo frames the loop sends.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ServoMode {
    /// Position targets (`0x200+ID`, or broadcast 0x2F); the joint must be in position mode.
    #[default]
    Position,
    /// Speed targets (`0x300+ID`); point-to-point only.
    Speed,
    /// Current targets (`0x400+ID`, or broadcast 0x4F).
    Current,
}

/// Point-to-point frames (one command and one feedback per joint and cycle) or the
/// broadcast protocol (one frame for joints 1..=7, §8).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Protocol {
    /// `0x200/0x300/0x400+ID` → `0x500+ID`: 2·N frames per cycle.
    #[default]
    PointToPoint,
    /// 0x2F (position) or 0x4F (current) for joints 1..=7 → 24-byte feedback on
    /// `0x80+ID+1` (J6: 0x5FE): N+1 frames per cycle. Needs FW D5.xx / E2.xx.
    Broadcast,
}

/// Settings of a cyclic loop.
#[derive(Debug, Clone, PartialEq)]
pub struct CyclicConfig {
    /// The joints, in the order targets and feedback use.
    pub joints: Vec<JointId>,
    /// Cycle period (2 ms = 500 Hz).
    pub period: Duration,
    /// What the targets are.
    pub mode: ServoMode,
    /// Frame protocol.
    pub protocol: Protocol,
    /// Position mode: run every target through a speed / acceleration-limited profile
    /// ([`MotionLimits`]; its `period` is ignored, the loop's is used), so a far target
    /// becomes a smooth move instead of a step that trips error 0x4000. On by default.
    pub smooth: Option<MotionLimits>,
}

impl CyclicConfig {
    /// Position loop for `joints` at `period`, point-to-point, with default smoothing.
    pub fn position(joints: Vec<JointId>, period: Duration) -> Self {
        Self {
            joints,
            period,
            mode: ServoMode::Position,
            protocol: Protocol::PointToPoint,
            smooth: Some(MotionLimits::default()),
        }
    }

    fn validate(&self) -> Result<(), String> {
        if self.joints.is_empty() {
            return Err("no joints".into());
        }
        for (i, j) in self.joints.iter().enumerate() {
            if self.joints[..i].contains(j) {
                return Err(format!("joint {j} listed twice"));
            }
        }
        if self.period < Duration::from_micros(250) || self.period > Duration::from_secs(1) {
            return Err(format!(
                "period {:?} out of range (allowed: 250 µs ..= 1 s)",
                self.period
            ));
        }
        if self.protocol == Protocol::Broadcast {
            if let Some(j) = self.joints.iter().find(|j| !j.has_broadcast_slot()) {
                return Err(format!(
                    "joint {j} has no broadcast slot (the broadcast protocol covers joints 1..=7)"
                ));
            }
            if self.mode == ServoMode::Speed {
                return Err(
                    "the broadcast protocol has no documented speed frame (0x3F); use point-to-point"
                        .into(),
                );
            }
        }
        if let Some(l) = &self.smooth {
            l.validate()?;
        }
        Ok(())
    }
}

/// One joint's feedback in a cycle (servo feedback or broadcast feedback).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Feedback {
    /// Actual position (0.0001° counts); "before the move" of this cycle's command.
    pub position: Position,
    /// Actual speed (0.02 RPM counts).
    pub speed: ActualSpeed,
    /// Actual current (1 or 2 mA counts by model).
    pub current: Current,
    /// Drive enabled.
    pub enabled: bool,
    /// Error bits.
    pub error: ErrorCode,
}

impl From<ServoFeedback> for Feedback {
    fn from(f: ServoFeedback) -> Self {
        Self {
            position: f.position,
            speed: f.speed,
            current: f.current,
            enabled: f.is_enabled(),
            error: f.error,
        }
    }
}

impl From<BroadcastFeedback> for Feedback {
    fn from(f: BroadcastFeedback) -> Self {
        Self {
            position: f.position,
            speed: f.speed,
            current: f.current,
            enabled: f.is_enabled(),
            error: f.error,
        }
    }
}

/// What happened in one cycle.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CycleReport {
    /// Cycle number, from 0.
    pub cycle: u64,
    /// When the cycle was due.
    pub scheduled: Instant,
    /// How late its frames went out.
    pub start_lateness: Duration,
    /// From the first frame sent to the last feedback received (`None` if feedback was
    /// missing; present but `missed` if the last feedback came after the deadline).
    pub round_trip: Option<Duration>,
    /// The raw targets sent, per joint (after smoothing and step clamping): 0.0001° for
    /// position, 0.002 RPM for speed, current counts for current.
    pub commanded: Vec<i32>,
    /// The feedback per joint (`None` = did not arrive within the cycle).
    pub feedback: Vec<Option<Feedback>>,
    /// Whether the cycle missed its deadline (feedback missing at the next tick, or
    /// received after it was due).
    pub missed: bool,
}

/// Latency percentiles of a loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Percentiles {
    /// Number of samples.
    pub samples: usize,
    /// Median.
    pub p50: Duration,
    /// 90th percentile.
    pub p90: Duration,
    /// 99th percentile.
    pub p99: Duration,
    /// Largest.
    pub max: Duration,
}

impl Percentiles {
    /// Percentiles of `samples` (nearest rank).
    pub fn of(samples: &[Duration]) -> Self {
        let mut s = samples.to_vec();
        s.sort_unstable();
        let pick = |q: f64| -> Duration {
            if s.is_empty() {
                return Duration::ZERO;
            }
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // 0..len
            let rank = ((q * s.len() as f64).ceil() as usize).clamp(1, s.len());
            s.get(rank - 1).copied().unwrap_or_default()
        };
        Self {
            samples: s.len(),
            p50: pick(0.50),
            p90: pick(0.90),
            p99: pick(0.99),
            max: s.last().copied().unwrap_or_default(),
        }
    }
}

/// Statistics of a cyclic loop.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct CyclicStats {
    /// Cycles run.
    pub cycles: u64,
    /// Cycles with feedback from every joint in time.
    pub complete: u64,
    /// Cycles whose feedback was not complete by the next tick.
    pub deadline_misses: u64,
    /// Feedback frames that did not arrive within their cycle.
    pub missing_replies: u64,
    /// Feedback frames that arrived after their cycle closed.
    pub late_replies: u64,
    /// Ticks skipped because the bus thread was more than a period late.
    pub overruns: u64,
    /// Frames the link refused to send.
    pub send_errors: u64,
    /// Position set-points clamped to the step limit around the actual position.
    pub step_clamps: u64,
    /// Cycle round trip (first frame sent → last feedback received), complete cycles.
    pub round_trip: Percentiles,
    /// How late each cycle's frames went out after its scheduled time.
    pub start_lateness: Percentiles,
    /// Reports dropped because nobody read them (the queue holds 256).
    pub reports_dropped: u64,
}

#[derive(Debug, Default)]
struct Acc {
    stats: CyclicStats,
    round_trips: Vec<Duration>,
    lateness: Vec<Duration>,
}

#[derive(Debug, Default)]
struct Reports {
    queue: VecDeque<CycleReport>,
    latest: Option<CycleReport>,
    finished: bool,
}

const REPORT_QUEUE: usize = 256;
/// Late feedback is expected per joint for at most this many closed cycles.
const MAX_OWED: usize = 8;

/// How long an owed feedback frame is waited for before it counts as lost: four periods,
/// and at least 20 ms (the client's default reply timeout; a joint answers in about
/// 0.2 ms).
pub(crate) fn owed_expiry(period: Duration) -> Duration {
    (period * 4).max(Duration::from_millis(20))
}
/// Three nominal bit times at the joints' 1 Mbit/s arbitration rate.
fn intermission() -> Duration {
    Duration::from_nanos(3_000_000_000 / u64::from(BitRates::WHJ.nominal.get()))
}

/// Keep at most this many latency samples (about 30 min at 500 Hz).
const MAX_SAMPLES: usize = 1_000_000;

/// State shared by the loop (in the bus's session) and its [`Cyclic`] handle.
#[derive(Debug, Default)]
pub(crate) struct CyclicShared {
    targets: Mutex<Vec<i32>>,
    acc: Mutex<Acc>,
    reports: Mutex<Reports>,
    cv: Condvar,
}

/// Everything the session needs to start a loop.
#[derive(Debug)]
pub(crate) struct CyclicSetup {
    config: CyclicConfig,
    shared: Arc<CyclicShared>,
    initial: Vec<i32>,
    step_limit_deg: f64,
}

#[derive(Debug)]
struct InCycle {
    cycle: u64,
    scheduled: Instant,
    started: Instant,
    commanded: Vec<i32>,
    feedback: Vec<Option<Feedback>>,
    remaining: usize,
    last_reply: Option<Instant>,
    /// Per joint: the wire time of the command frame it answers and of the frames that
    /// go before it.
    command_time: Vec<Duration>,
    /// Wire time of the feedback frames credited to this cycle so far.
    feedback_wire: Duration,
}

impl InCycle {
    /// Whether `reply`, received at `now`, can answer this cycle's command to joint `i`:
    /// not before the command, the feedback frames already credited to this cycle and the
    /// reply itself have crossed the wire (one bus carries them one after the other, all
    /// after the cycle started).
    /// A receiver has a frame at the end of its EOF, the 3-bit intermission before the
    /// wire is free (which [`frame_duration`] includes): the last frame's is not waited.
    fn can_answer(&self, i: usize, reply: &CanFrame, now: Instant) -> bool {
        let command = self.command_time.get(i).copied().unwrap_or_default();
        let wire = command + self.feedback_wire + frame_duration(reply, BitRates::WHJ);
        now >= self.started + wire.saturating_sub(intermission())
    }
}

/// A feedback frame a closed cycle did not get.
#[derive(Debug, Clone, Copy)]
struct Debt {
    /// When the command it answers went out.
    sent: Instant,
    /// Owed only perhaps (the joint's frame in that cycle may have been its answer, if
    /// the frame for an earlier command was lost).
    perhaps: bool,
}

/// The loop as the session runs it.
#[derive(Debug)]
pub(crate) struct CyclicRun {
    config: CyclicConfig,
    shared: Arc<CyclicShared>,
    step_limit_deg: f64,
    next_tick: Instant,
    cycle: u64,
    current: Option<InCycle>,
    profiles: Vec<Profile>,
    actual: Vec<Option<Position>>,
    mask: ReplyMask,
    /// Per joint: when the frames of closed cycles still owed a feedback frame by the
    /// joint went out, oldest first.
    owed: Vec<VecDeque<Debt>>,
    /// Per joint: whether a feedback frame in the running cycle paid an owed one.
    paid: Vec<bool>,
    /// Per joint: the shortest time from a cycle's start to its feedback seen so far.
    fastest: Vec<Option<Duration>>,
}

impl CyclicRun {
    pub(crate) fn new(setup: CyclicSetup, now: Instant) -> Self {
        let limits = setup.config.smooth.unwrap_or_default();
        let profiles = setup
            .initial
            .iter()
            .map(|raw| Profile::new(Position(*raw).degrees(), limits))
            .collect();
        let actual = setup
            .initial
            .iter()
            .map(|raw| Some(Position(*raw)))
            .collect();
        let mask = best_mask(&setup.config.joints);
        let owed = vec![VecDeque::new(); setup.config.joints.len()];
        let paid = vec![false; setup.config.joints.len()];
        let fastest = vec![None; setup.config.joints.len()];
        Self {
            config: setup.config,
            shared: setup.shared,
            step_limit_deg: setup.step_limit_deg,
            next_tick: now,
            cycle: 0,
            current: None,
            profiles,
            actual,
            mask,
            owed,
            paid,
            fastest,
        }
    }

    pub(crate) fn due(&self, now: Instant) -> bool {
        now >= self.next_tick
    }

    /// Whether feedback of the running cycle is still expected.
    pub(crate) const fn awaiting(&self) -> bool {
        self.current.is_some()
    }

    pub(crate) const fn next_event(&self) -> Instant {
        self.next_tick
    }

    /// Whether frames on `reply_id` belong to this loop.
    pub(crate) fn owns(&self, reply_id: u16) -> bool {
        self.config.protocol == Protocol::PointToPoint
            && self
                .config
                .joints
                .iter()
                .any(|j| j.can_id(Function::ServoFeedback) == reply_id)
    }

    /// Closes the running cycle and starts the next: returns the frames to send.
    pub(crate) fn tick(&mut self, now: Instant) -> Vec<CanFrame> {
        self.close_cycle();
        let scheduled = self.next_tick;
        let targets = lock(&self.shared.targets).clone();
        let commanded = self.commands(&targets);
        let frames = self.frames(&commanded);
        let n = self.config.joints.len();
        let command_time = (0..n)
            .map(|i| match frames.get(i) {
                // Point-to-point: a frame sent earlier with a lower ID goes first.
                Some(own) if frames.len() == n => frames
                    .get(..=i)
                    .unwrap_or_default()
                    .iter()
                    .filter(|f| f.raw_id() <= own.raw_id())
                    .map(|f| frame_duration(f, BitRates::WHJ))
                    .sum(),
                _ => frames
                    .first()
                    .map(|f| frame_duration(f, BitRates::WHJ))
                    .unwrap_or_default(),
            })
            .collect();
        self.current = Some(InCycle {
            cycle: self.cycle,
            scheduled,
            started: now,
            commanded,
            feedback: vec![None; n],
            remaining: n,
            last_reply: None,
            command_time,
            feedback_wire: Duration::ZERO,
        });
        self.cycle += 1;
        self.next_tick += self.config.period;
        if self.next_tick <= now {
            lock(&self.shared.acc).stats.overruns += 1;
            self.next_tick = now + self.config.period;
        }
        let mut acc = lock(&self.shared.acc);
        if acc.lateness.len() < MAX_SAMPLES {
            acc.lateness.push(now.saturating_duration_since(scheduled));
        }
        frames
    }

    fn commands(&mut self, targets: &[i32]) -> Vec<i32> {
        if self.config.mode != ServoMode::Position {
            return targets.to_vec();
        }
        let dt = self.config.period.as_secs_f64();
        let mut clamps = 0;
        let out = targets
            .iter()
            .zip(self.profiles.iter_mut())
            .zip(&self.actual)
            .map(|((target, profile), actual)| {
                let goal = Position(*target).degrees();
                let mut cmd = if self.config.smooth.is_some() {
                    profile.step(goal, dt)
                } else {
                    goal
                };
                if let Some(a) = actual {
                    let a = a.degrees();
                    let clamped = cmd.clamp(a - self.step_limit_deg, a + self.step_limit_deg);
                    #[allow(clippy::float_cmp)] // exact: did the clamp change it
                    if clamped != cmd {
                        clamps += 1;
                        cmd = clamped;
                    }
                }
                Position::from_degrees(cmd).map_or(*target, Position::raw)
            })
            .collect();
        if clamps > 0 {
            lock(&self.shared.acc).stats.step_clamps += clamps;
        }
        out
    }

    fn frames(&self, commanded: &[i32]) -> Vec<CanFrame> {
        let joints = self.config.joints.iter().zip(commanded);
        match (self.config.protocol, self.config.mode) {
            (Protocol::PointToPoint, mode) => joints
                .map(|(&joint, &raw)| {
                    match mode {
                        ServoMode::Position => Request::PositionServo {
                            joint,
                            target: Position(raw),
                        },
                        ServoMode::Speed => Request::SpeedServo {
                            joint,
                            target: TargetSpeed(raw),
                        },
                        ServoMode::Current => Request::CurrentServo {
                            joint,
                            target: Current(raw),
                        },
                    }
                    .to_frame()
                })
                .collect(),
            (Protocol::Broadcast, ServoMode::Current) => {
                let mut f = BroadcastCurrent::new(self.mask);
                for (&joint, &raw) in joints {
                    f = f.with_target(joint, Current(raw)).unwrap_or(f);
                }
                vec![Request::BroadcastCurrent(f).to_frame()]
            }
            (Protocol::Broadcast, _) => {
                let mut f = BroadcastPosition::new(self.mask);
                for (&joint, &raw) in joints {
                    f = f.with_target(joint, Position(raw)).unwrap_or(f);
                }
                vec![Request::BroadcastPosition(f).to_frame()]
            }
        }
    }

    /// Takes a reply (decoded from `frame`) if it belongs to this loop.
    pub(crate) fn on_reply(&mut self, reply: &Reply, frame: &CanFrame, now: Instant) -> bool {
        let (joint, fb) = match (self.config.protocol, reply) {
            (Protocol::PointToPoint, Reply::ServoFeedback { joint, feedback }) => {
                (*joint, Feedback::from(*feedback))
            }
            (Protocol::Broadcast, Reply::BroadcastFeedback { joint, feedback }) => {
                (*joint, Feedback::from(*feedback))
            }
            _ => return false,
        };
        let Some(i) = self.config.joints.iter().position(|j| *j == joint) else {
            return false;
        };
        if let Some(a) = self.actual.get_mut(i) {
            *a = Some(fb.position);
        }
        let answerable = self
            .current
            .as_ref()
            .is_some_and(|c| c.can_answer(i, frame, now));
        let since_start = self
            .current
            .as_ref()
            .map(|c| now.saturating_duration_since(c.started));
        // As late in the cycle as the joint's feedback has ever come: only then is a frame
        // taken for this cycle's rather than for one owed perhaps.
        let typical = answerable
            && since_start
                .zip(self.fastest.get(i).copied().flatten())
                .is_none_or(|(t, fastest)| t >= fastest);
        if let Some(owed) = self.owed.get_mut(i) {
            let expiry = owed_expiry(self.config.period);
            while owed.front().is_some_and(|d| {
                // Too old to still be on its way: that feedback frame was lost. Or owed
                // only perhaps, and this frame can be the running cycle's answer: then
                // that frame was lost.
                now.saturating_duration_since(d.sent) > expiry || (d.perhaps && typical)
            }) {
                owed.pop_front();
            }
            if owed.pop_front().is_some() {
                // The answer to an earlier cycle's command, which closed without it. Only
                // if it came when it could also have answered this cycle's command may
                // this cycle's own answer have been lost instead.
                if answerable && let Some(p) = self.paid.get_mut(i) {
                    *p = true;
                }
                lock(&self.shared.acc).stats.late_replies += 1;
                return true;
            }
        }
        if !answerable {
            // Too early for the running cycle's command (or no cycle runs): the answer to
            // an earlier one.
            lock(&self.shared.acc).stats.late_replies += 1;
            return true;
        }
        let slot = self.current.as_mut().and_then(|c| {
            c.feedback
                .get_mut(i)
                .map(|s| (s, &mut c.remaining, &mut c.last_reply, &mut c.feedback_wire))
        });
        match slot {
            Some((s @ None, remaining, last, wire)) => {
                if let (Some(f), Some(t)) = (self.fastest.get_mut(i), since_start) {
                    *f = Some(f.map_or(t, |f| f.min(t)));
                }
                *s = Some(fb);
                *remaining -= 1;
                *last = Some(now);
                *wire += frame_duration(frame, BitRates::WHJ);
                if *remaining == 0 {
                    self.close_cycle();
                }
            }
            _ => lock(&self.shared.acc).stats.late_replies += 1,
        }
        true
    }

    pub(crate) fn send_failed(&self, frame: &CanFrame, error: &str) {
        tracing::warn!(id = frame.raw_id(), error, "cyclic frame not sent");
        lock(&self.shared.acc).stats.send_errors += 1;
    }

    fn close_cycle(&mut self) {
        let Some(c) = self.current.take() else {
            return;
        };
        // Feedback read after the cycle's deadline (the next tick) is late, even if the
        // next cycle's frames had not gone out yet.
        let deadline = c.scheduled + self.config.period;
        let complete = c.remaining == 0 && c.last_reply.is_none_or(|t| t <= deadline);
        for ((owed, paid), fb) in self.owed.iter_mut().zip(&mut self.paid).zip(&c.feedback) {
            // A joint that answered once in this cycle (paying an older debt, when its
            // frame could also have been this cycle's answer) owes this cycle's frame
            // only perhaps: its frame for the earlier command may have been lost. The
            // next frame settles it: one too early for the next cycle's command pays it.
            if fb.is_none() {
                if owed.len() >= MAX_OWED {
                    owed.pop_front();
                }
                owed.push_back(Debt {
                    sent: c.started,
                    perhaps: *paid,
                });
            }
            *paid = false;
        }
        let round_trip = if c.remaining == 0 {
            c.last_reply.map(|t| t.saturating_duration_since(c.started))
        } else {
            None
        };
        {
            let mut acc = lock(&self.shared.acc);
            acc.stats.cycles += 1;
            if complete {
                acc.stats.complete += 1;
            } else {
                acc.stats.deadline_misses += 1;
                acc.stats.missing_replies += c.remaining as u64;
            }
            if let Some(rt) = round_trip
                && complete
                && acc.round_trips.len() < MAX_SAMPLES
            {
                acc.round_trips.push(rt);
            }
        }
        let report = CycleReport {
            cycle: c.cycle,
            scheduled: c.scheduled,
            start_lateness: c.started.saturating_duration_since(c.scheduled),
            round_trip,
            commanded: c.commanded,
            feedback: c.feedback,
            missed: !complete,
        };
        let mut r = lock(&self.shared.reports);
        if r.queue.len() >= REPORT_QUEUE {
            r.queue.pop_front();
            lock(&self.shared.acc).stats.reports_dropped += 1;
        }
        r.latest = Some(report.clone());
        r.queue.push_back(report);
        drop(r);
        self.shared.cv.notify_all();
    }

    /// Ends the loop: closes the last cycle and wakes waiting readers.
    pub(crate) fn finish(mut self) {
        // A cycle still waiting for feedback is left out rather than counted as a miss.
        self.current = None;
        lock(&self.shared.reports).finished = true;
        self.shared.cv.notify_all();
    }
}

/// The reply-mask code selecting the fewest nodes that include all of `joints`.
fn best_mask(joints: &[JointId]) -> ReplyMask {
    (1u8..=0xF)
        .filter_map(|code| ReplyMask::new(code).ok())
        .filter(|m| joints.iter().all(|j| m.selects(*j)))
        .min_by_key(|m| m.joints().count() + usize::from(m.selects_end_board()))
        .unwrap_or(ReplyMask::ALL)
}

/// A running cyclic loop (see [`JointBus::cyclic`]). Stops when dropped.
///
/// Set targets at any time ([`Cyclic::set_positions`], ...); the bus thread sends the
/// latest ones at every tick. Read what happened with [`Cyclic::next_report`] (one
/// [`CycleReport`] per cycle, queued up to 256) or [`Cyclic::latest`], and the statistics
/// with [`Cyclic::stats`].
#[derive(Debug)]
pub struct Cyclic<'a> {
    bus: owned::BusRef<'a>,
    shared: Arc<CyclicShared>,
    config: CyclicConfig,
    stopped: bool,
}

impl JointBus {
    /// Starts a cyclic servo loop. In position mode the loop starts by holding each
    /// joint's present position (read with a status query). The joints should be enabled
    /// in the matching work mode. Only one loop runs per bus; while it runs, single servo
    /// commands to its joints are refused ([`WhjError::Busy`]); register reads and writes
    /// still work between its frames.
    pub fn cyclic(&self, config: CyclicConfig) -> Result<Cyclic<'_>, WhjError> {
        config
            .validate()
            .map_err(|reason| WhjError::InvalidConfig { reason })?;
        if self.cyclic_running() {
            return Err(WhjError::InvalidConfig {
                reason: "a cyclic loop is already running on this bus".into(),
            });
        }
        let initial = if config.mode == ServoMode::Position {
            config
                .joints
                .iter()
                .map(|j| Ok(self.joint_unchecked(*j).status()?.position.raw()))
                .collect::<Result<Vec<_>, WhjError>>()?
        } else {
            vec![0; config.joints.len()]
        };
        let shared = Arc::new(CyclicShared {
            targets: Mutex::new(initial.clone()),
            ..CyclicShared::default()
        });
        self.start_cyclic(CyclicSetup {
            config: config.clone(),
            shared: Arc::clone(&shared),
            initial,
            step_limit_deg: self.config().step_limit_deg,
        })?;
        Ok(Cyclic {
            bus: owned::BusRef::Borrowed(self),
            shared,
            config,
            stopped: false,
        })
    }
}

impl Cyclic<'_> {
    /// The joints, in target / feedback order.
    pub fn joints(&self) -> &[JointId] {
        &self.config.joints
    }

    /// The loop's configuration.
    pub const fn config(&self) -> &CyclicConfig {
        &self.config
    }

    fn set_raw(&self, mode: ServoMode, raw: Vec<i32>) -> Result<(), WhjError> {
        if mode != self.config.mode {
            return Err(WhjError::InvalidConfig {
                reason: format!("{mode:?} targets given to a {:?} loop", self.config.mode),
            });
        }
        if raw.len() != self.config.joints.len() {
            return Err(WhjError::InvalidConfig {
                reason: format!(
                    "{} targets given for {} joints",
                    raw.len(),
                    self.config.joints.len()
                ),
            });
        }
        *lock(&self.shared.targets) = raw;
        Ok(())
    }

    /// Sets the position targets (one per joint; position mode). With smoothing on, far
    /// targets are approached along the speed / acceleration-limited profile; in any
    /// case the set-point sent stays within the step limit of the last measured position.
    pub fn set_positions(&self, targets: &[Position]) -> Result<(), WhjError> {
        self.set_raw(
            ServoMode::Position,
            targets.iter().map(|p| p.raw()).collect(),
        )
    }

    /// Sets the speed targets (0.002 RPM counts; speed mode).
    pub fn set_speeds(&self, targets: &[TargetSpeed]) -> Result<(), WhjError> {
        self.set_raw(ServoMode::Speed, targets.iter().map(|s| s.raw()).collect())
    }

    /// Sets the current targets (model current counts; current mode).
    pub fn set_currents(&self, targets: &[Current]) -> Result<(), WhjError> {
        self.set_raw(
            ServoMode::Current,
            targets.iter().map(|c| c.raw()).collect(),
        )
    }

    /// Waits up to `timeout` for the next cycle's report (oldest first). `None` on
    /// timeout or once the loop has stopped. On a bus with a virtual clock the wait runs
    /// the bus, and `timeout` is of its time.
    pub fn next_report(&self, timeout: Duration) -> Option<CycleReport> {
        if self.bus.virtual_time() {
            return self.drive_to_report(timeout);
        }
        let deadline = Instant::now() + timeout;
        let mut r = lock(&self.shared.reports);
        loop {
            if let Some(rep) = r.queue.pop_front() {
                return Some(rep);
            }
            if r.finished {
                return None;
            }
            let now = Instant::now();
            if now >= deadline {
                return None;
            }
            r = self
                .shared
                .cv
                .wait_timeout(r, deadline - now)
                .map_or_else(|e| e.into_inner().0, |(g, _)| g);
        }
    }

    /// [`Cyclic::next_report`] on a virtual clock: runs the bus (and so the loop) until a
    /// report is there or `timeout` of the bus's time has passed.
    fn drive_to_report(&self, timeout: Duration) -> Option<CycleReport> {
        let deadline = self.bus.now() + timeout;
        loop {
            {
                let mut r = lock(&self.shared.reports);
                if let Some(rep) = r.queue.pop_front() {
                    return Some(rep);
                }
                if r.finished {
                    return None;
                }
            }
            let now = self.bus.now();
            if now >= deadline {
                return None;
            }
            self.bus.sleep_until(deadline.min(now + self.config.period));
        }
    }

    /// Drops queued reports (e.g. before waiting for a fresh one).
    pub fn clear_reports(&self) {
        lock(&self.shared.reports).queue.clear();
    }

    /// The most recent report, if any cycle has finished.
    pub fn latest(&self) -> Option<CycleReport> {
        lock(&self.shared.reports).latest.clone()
    }

    /// Statistics so far.
    pub fn stats(&self) -> CyclicStats {
        let acc = lock(&self.shared.acc);
        CyclicStats {
            round_trip: Percentiles::of(&acc.round_trips),
            start_lateness: Percentiles::of(&acc.lateness),
            ..acc.stats.clone()
        }
    }

    /// Stops the loop and returns its statistics.
    pub fn stop(mut self) -> CyclicStats {
        self.halt();
        self.stats()
    }

    fn halt(&mut self) {
        if !self.stopped {
            self.stopped = true;
            self.bus.stop_cyclic();
        }
    }
}

impl Drop for Cyclic<'_> {
    fn drop(&mut self) {
        self.halt();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_by_nearest_rank() {
        let s: Vec<Duration> = (1..=100).map(Duration::from_micros).collect();
        let p = Percentiles::of(&s);
        assert_eq!(p.samples, 100);
        assert_eq!(p.p50, Duration::from_micros(50));
        assert_eq!(p.p90, Duration::from_micros(90));
        assert_eq!(p.p99, Duration::from_micros(99));
        assert_eq!(p.max, Duration::from_micros(100));
        assert_eq!(Percentiles::of(&[]), Percentiles::default());
    }

    /// A current loop for joint 1 at 2 ms, driven by hand: its first cycle started at the
    /// returned instant; and a feedback frame of joint 1.
    /// A current loop of `joints` at 2 ms, ticked once at the returned instant; the frames
    /// that tick sent.
    fn loop_of(joints: &[JointId]) -> (Instant, CyclicRun, Arc<CyclicShared>, Vec<CanFrame>) {
        let t0 = Instant::now();
        let shared = Arc::new(CyclicShared {
            targets: Mutex::new(vec![0; joints.len()]),
            ..CyclicShared::default()
        });
        let mut config = CyclicConfig::position(joints.to_vec(), Duration::from_millis(2));
        config.mode = ServoMode::Current;
        config.smooth = None;
        let setup = CyclicSetup {
            config,
            shared: Arc::clone(&shared),
            initial: vec![0; joints.len()],
            step_limit_deg: 10.0,
        };
        let mut run = CyclicRun::new(setup, t0);
        let commands = run.tick(t0);
        (t0, run, shared, commands)
    }

    /// Joint `joint`'s servo feedback, and its frame.
    fn feedback(joint: JointId) -> (Reply, CanFrame) {
        let reply = Reply::ServoFeedback {
            joint,
            feedback: ServoFeedback {
                current: Current(0),
                speed: ActualSpeed(0),
                position: Position(0),
                enable: 1,
                error: ErrorCode::NONE,
            },
        };
        let frame = reply.to_frame();
        (reply, frame)
    }

    fn one_joint_loop() -> (Instant, CyclicRun, Arc<CyclicShared>, Reply, CanFrame) {
        let joint = JointId::new(1).unwrap();
        let (t0, run, shared, _) = loop_of(&[joint]);
        let (reply, frame) = feedback(joint);
        (t0, run, shared, reply, frame)
    }

    #[test]
    fn feedback_read_after_the_deadline_marks_the_cycle_missed() {
        let (t0, mut run, shared, reply, frame) = one_joint_loop();
        // Read 1 µs after the next tick was due, but before the loop ticked: it answers
        // cycle 0, late.
        let late = t0 + Duration::from_micros(2001);
        assert!(run.on_reply(&reply, &frame, late));
        let r = lock(&shared.reports).queue.pop_front().unwrap();
        assert_eq!(r.cycle, 0);
        assert!(r.missed);
        assert_eq!(r.round_trip, Some(Duration::from_micros(2001)));
        assert!(r.feedback[0].is_some());
        let stats = lock(&shared.acc).stats.clone();
        assert_eq!(
            (stats.complete, stats.deadline_misses, stats.late_replies),
            (0, 1, 0)
        );
        assert!(lock(&shared.acc).round_trips.is_empty());
    }

    #[test]
    fn feedback_before_the_command_can_have_been_answered_is_not_the_cycles() {
        let (t0, mut run, shared, reply, frame) = one_joint_loop();
        let floor = frame_duration(&run.frames(&[0])[0], BitRates::WHJ)
            + frame_duration(&frame, BitRates::WHJ).saturating_sub(intermission());
        // One nanosecond too early: an earlier command's answer, counted late.
        assert!(run.on_reply(
            &reply,
            &frame,
            t0 + floor.saturating_sub(Duration::from_nanos(1))
        ));
        assert!(run.awaiting());
        assert_eq!(lock(&shared.acc).stats.late_replies, 1);
        // At the floor it can be this cycle's answer.
        assert!(run.on_reply(&reply, &frame, t0 + floor));
        assert!(!run.awaiting());
        let r = lock(&shared.reports).queue.pop_front().unwrap();
        assert_eq!((r.missed, r.round_trip), (false, Some(floor)));
    }

    /// Two joints: the second feedback frame of a cycle cannot come before both commands
    /// and both feedback frames have crossed the one wire, even when it comes late enough
    /// for its own command alone (a frame of an earlier cycle would otherwise complete
    /// this one with a round trip shorter than the wire allows).
    #[test]
    fn a_cycles_last_feedback_waits_for_every_frame_of_the_cycle_on_the_wire() {
        let joints = [JointId::new(1).unwrap(), JointId::new(2).unwrap()];
        let (t0, mut run, shared, commands) = loop_of(&joints);
        let (r1, f1) = feedback(joints[0]);
        let (r2, f2) = feedback(joints[1]);
        let wire = |f: &CanFrame| frame_duration(f, BitRates::WHJ);
        let both_commands =
            (wire(&commands[0]) + wire(&commands[1])).saturating_sub(intermission());
        // Joint 1 answers as early as the wire allows.
        let first = (wire(&commands[0]) + wire(&f1)).saturating_sub(intermission());
        assert!(run.on_reply(&r1, &f1, t0 + first));
        // Joint 2's frame once its own command and itself could have crossed, but before
        // joint 1's feedback could have too: not this cycle's.
        let alone = both_commands + wire(&f2);
        assert!(run.on_reply(&r2, &f2, t0 + alone));
        assert!(run.awaiting());
        assert_eq!(lock(&shared.acc).stats.late_replies, 1);
        // After every frame of the cycle: its answer.
        let all = both_commands + wire(&f1) + wire(&f2);
        assert!(run.on_reply(&r2, &f2, t0 + all));
        assert!(!run.awaiting());
        let r = lock(&shared.reports).queue.pop_front().unwrap();
        assert_eq!((r.missed, r.round_trip), (false, Some(all)));
    }

    #[test]
    fn masks_cover_the_joints_with_the_fewest_extra_nodes() {
        let j = |n| JointId::new(n).unwrap();
        assert_eq!(best_mask(&[j(1)]).get(), 7);
        assert_eq!(best_mask(&[j(1), j(2)]).get(), 3);
        assert_eq!(best_mask(&[j(3), j(4)]).get(), 4);
        assert_eq!(best_mask(&[j(1), j(3)]).get(), 1);
        assert_eq!(best_mask(&[j(7)]).get(), 0xD);
        let all: Vec<_> = (1..=7).map(j).collect();
        assert_eq!(best_mask(&all), ReplyMask::ALL);
    }
}
