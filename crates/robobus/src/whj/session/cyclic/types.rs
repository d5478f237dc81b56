//! The cyclic loop's values: its settings ([`CyclicConfig`], [`ServoMode`], [`Protocol`])
//! and what it reports ([`CycleReport`], [`Feedback`], [`CyclicStats`], [`Percentiles`]).

use core::time::Duration;
use std::time::Instant;

use robobus_whj::units::{ActualSpeed, Current, Position};
use robobus_whj::{BroadcastFeedback, ErrorCode, JointId, ServoFeedback};

use crate::whj::trajectory::MotionLimits;

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

    pub(crate) fn validate(&self) -> Result<(), String> {
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
