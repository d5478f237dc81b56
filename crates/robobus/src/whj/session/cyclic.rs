//! The cyclic servo loop's state, sans-IO ([`CyclicRun`], run by the
//! [`Session`](super::Session)): at each tick it makes one command frame per joint (or one
//! broadcast frame for joints 1..=7) from the latest targets, credits the feedback, and
//! keeps deadline-miss and latency statistics and a bounded queue of [`CycleReport`]s. It
//! holds no lock and reads no clock: time is an argument of every method.
//!
//! Feedback is matched to commands per joint. A joint answers each servo (or broadcast)
//! frame with one feedback frame, in order, so its first feedback after a command answers
//! that command. When a cycle closes without a joint's feedback, that feedback is owed:
//! the joint's next feedback frame is counted as a late reply of the closed cycle, not as
//! the new cycle's feedback (which would leave every later cycle holding the previous
//! command's answer). A frame received before the running cycle's command can have been
//! answered is never that cycle's feedback: one bus carries the command, the feedback
//! frames already credited to the cycle and this frame one after the other, each for its
//! wire time at the WHJ bit rates. Before the next cycle's frames go out, the driver
//! reads every frame already received (`Session::cyclic_due`), so a frame that came
//! before the next command is credited to the cycle it answers (and a cycle whose last feedback came after
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
use std::time::Instant;

use robobus_whj::timing::{BitRates, frame_duration};
use robobus_whj::units::{Current, Position, TargetSpeed};
use robobus_whj::{
    BroadcastCurrent, BroadcastPosition, CanFrame, Function, JointId, Reply, ReplyMask, Request,
};

use crate::whj::trajectory::Profile;

mod types;
pub use types::{
    CycleReport, CyclicConfig, CyclicStats, Feedback, Percentiles, Protocol, ServoMode,
};

/// The most reports the loop keeps until they are polled.
const REPORT_QUEUE: usize = 256;
/// Late feedback is expected per joint for at most this many closed cycles.
const MAX_OWED: usize = 8;

/// How long an owed feedback frame is waited for before it counts as lost: four periods,
/// and at least 20 ms (the client's default reply timeout; a joint answers in about
/// 0.2 ms).
fn owed_expiry(period: Duration) -> Duration {
    (period * 4).max(Duration::from_millis(20))
}
/// Three nominal bit times at the joints' 1 Mbit/s arbitration rate.
fn intermission() -> Duration {
    Duration::from_nanos(3_000_000_000 / u64::from(BitRates::WHJ.nominal.get()))
}

/// Keep at most this many latency samples (about 30 min at 500 Hz).
const MAX_SAMPLES: usize = 1_000_000;

/// Everything the session needs to start a loop.
#[derive(Debug)]
pub(crate) struct CyclicSetup {
    /// The loop's settings (validated).
    pub(crate) config: CyclicConfig,
    /// The first targets, one per joint (position mode: where each joint is).
    pub(crate) initial: Vec<i32>,
    /// [`JointBusConfig::step_limit_deg`](super::JointBusConfig::step_limit_deg).
    pub(crate) step_limit_deg: f64,
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
    step_limit_deg: f64,
    /// The latest targets, one per joint.
    targets: Vec<i32>,
    stats: CyclicStats,
    /// Round trips of complete cycles, at most [`MAX_SAMPLES`].
    round_trips: Vec<Duration>,
    /// How late each cycle started, at most [`MAX_SAMPLES`].
    lateness: Vec<Duration>,
    /// Closed cycles not yet polled, oldest first, at most [`REPORT_QUEUE`].
    reports: VecDeque<CycleReport>,
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
            step_limit_deg: setup.step_limit_deg,
            targets: setup.initial,
            stats: CyclicStats::default(),
            round_trips: Vec::new(),
            lateness: Vec::new(),
            reports: VecDeque::new(),
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
        let targets = self.targets.clone();
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
            self.stats.overruns += 1;
            self.next_tick = now + self.config.period;
        }
        if self.lateness.len() < MAX_SAMPLES {
            self.lateness.push(now.saturating_duration_since(scheduled));
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
                    let clamped = crate::motion::within_step(cmd, a, self.step_limit_deg);
                    #[allow(clippy::float_cmp)] // exact: did the clamp change it
                    if clamped != cmd {
                        clamps += 1;
                        cmd = clamped;
                    }
                }
                Position::from_degrees(cmd).map_or(*target, Position::raw)
            })
            .collect();
        self.stats.step_clamps += clamps;
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
                self.stats.late_replies += 1;
                return true;
            }
        }
        if !answerable {
            // Too early for the running cycle's command (or no cycle runs): the answer to
            // an earlier one.
            self.stats.late_replies += 1;
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
            _ => self.stats.late_replies += 1,
        }
        true
    }

    /// A frame of the loop could not be sent.
    pub(crate) fn send_failed(&mut self, frame: &CanFrame, error: &str) {
        tracing::warn!(id = frame.raw_id(), error, "cyclic frame not sent");
        self.stats.send_errors += 1;
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
        self.stats.cycles += 1;
        if complete {
            self.stats.complete += 1;
        } else {
            self.stats.deadline_misses += 1;
            self.stats.missing_replies += c.remaining as u64;
        }
        if let Some(rt) = round_trip
            && complete
            && self.round_trips.len() < MAX_SAMPLES
        {
            self.round_trips.push(rt);
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
        if self.reports.len() >= REPORT_QUEUE {
            self.reports.pop_front();
            self.stats.reports_dropped += 1;
        }
        self.reports.push_back(report);
    }

    /// Ends the loop: a cycle still waiting for feedback is left out rather than counted
    /// as a miss. Returns the reports not yet polled and the final statistics.
    pub(crate) fn finish(mut self) -> (VecDeque<CycleReport>, CyclicStats) {
        self.current = None;
        let stats = self.stats();
        (self.reports, stats)
    }

    /// The oldest closed cycle's report not yet polled.
    pub(crate) fn poll_report(&mut self) -> Option<CycleReport> {
        self.reports.pop_front()
    }

    /// Sets the targets sent from the next tick on (one per joint: `false`, and nothing
    /// changes, for another count).
    pub(crate) fn set_targets(&mut self, targets: Vec<i32>) -> bool {
        if targets.len() != self.config.joints.len() {
            return false;
        }
        self.targets = targets;
        true
    }

    /// The statistics so far, with the latency percentiles.
    pub(crate) fn stats(&self) -> CyclicStats {
        CyclicStats {
            round_trip: Percentiles::of(&self.round_trips),
            start_lateness: Percentiles::of(&self.lateness),
            ..self.stats.clone()
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use robobus_whj::units::ActualSpeed;
    use robobus_whj::{ErrorCode, ServoFeedback};

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
    fn loop_of(joints: &[JointId]) -> (Instant, CyclicRun, Vec<CanFrame>) {
        let t0 = Instant::now();
        let mut config = CyclicConfig::position(joints.to_vec(), Duration::from_millis(2));
        config.mode = ServoMode::Current;
        config.smooth = None;
        let setup = CyclicSetup {
            config,
            initial: vec![0; joints.len()],
            step_limit_deg: 10.0,
        };
        let mut run = CyclicRun::new(setup, t0);
        let commands = run.tick(t0);
        (t0, run, commands)
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

    fn one_joint_loop() -> (Instant, CyclicRun, Reply, CanFrame) {
        let joint = JointId::new(1).unwrap();
        let (t0, run, _) = loop_of(&[joint]);
        let (reply, frame) = feedback(joint);
        (t0, run, reply, frame)
    }

    #[test]
    fn feedback_read_after_the_deadline_marks_the_cycle_missed() {
        let (t0, mut run, reply, frame) = one_joint_loop();
        // Read 1 µs after the next tick was due, but before the loop ticked: it answers
        // cycle 0, late.
        let late = t0 + Duration::from_micros(2001);
        assert!(run.on_reply(&reply, &frame, late));
        let r = run.poll_report().unwrap();
        assert_eq!(r.cycle, 0);
        assert!(r.missed);
        assert_eq!(r.round_trip, Some(Duration::from_micros(2001)));
        assert!(r.feedback[0].is_some());
        let stats = run.stats();
        assert_eq!(
            (stats.complete, stats.deadline_misses, stats.late_replies),
            (0, 1, 0)
        );
        assert_eq!(stats.round_trip.samples, 0);
    }

    #[test]
    fn feedback_before_the_command_can_have_been_answered_is_not_the_cycles() {
        let (t0, mut run, reply, frame) = one_joint_loop();
        let floor = frame_duration(&run.frames(&[0])[0], BitRates::WHJ)
            + frame_duration(&frame, BitRates::WHJ).saturating_sub(intermission());
        // One nanosecond too early: an earlier command's answer, counted late.
        assert!(run.on_reply(
            &reply,
            &frame,
            t0 + floor.saturating_sub(Duration::from_nanos(1))
        ));
        assert!(run.awaiting());
        assert_eq!(run.stats().late_replies, 1);
        // At the floor it can be this cycle's answer.
        assert!(run.on_reply(&reply, &frame, t0 + floor));
        assert!(!run.awaiting());
        let r = run.poll_report().unwrap();
        assert_eq!((r.missed, r.round_trip), (false, Some(floor)));
    }

    /// Two joints: the second feedback frame of a cycle cannot come before both commands
    /// and both feedback frames have crossed the one wire, even when it comes late enough
    /// for its own command alone (a frame of an earlier cycle would otherwise complete
    /// this one with a round trip shorter than the wire allows).
    #[test]
    fn a_cycles_last_feedback_waits_for_every_frame_of_the_cycle_on_the_wire() {
        let joints = [JointId::new(1).unwrap(), JointId::new(2).unwrap()];
        let (t0, mut run, commands) = loop_of(&joints);
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
        assert_eq!(run.stats().late_replies, 1);
        // After every frame of the cycle: its answer.
        let all = both_commands + wire(&f1) + wire(&f2);
        assert!(run.on_reply(&r2, &f2, t0 + all));
        assert!(!run.awaiting());
        let r = run.poll_report().unwrap();
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
