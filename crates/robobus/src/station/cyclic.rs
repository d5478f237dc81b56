//! A checked cyclic servo loop on a station's WHJ bus: the hot path of a front end that
//! streams targets itself (a Python control loop, a teleoperation bridge), with the same
//! checks as the catalogue's timed operations.
//!
//! [`CyclicLoop::start`] connects each joint, refuses one that is not enabled in the
//! loop's work mode, reads what each joint allows (its position limits, its model's peak
//! output speed, its current limit and current scale) and starts the bus's cyclic loop
//! ([`crate::whj::Cyclic`], position targets through its speed / acceleration-limited
//! profile). [`CyclicLoop::set`] checks every target against the host bounds and the
//! joint's own limits (the ones `ops::whj::check_demand` checks for a timed run) before it
//! reaches the loop: a target out of range is refused with
//! the joint, the value and the range, and the loop keeps its previous targets.
//! [`CyclicLoop::next`] gives each cycle's feedback in degrees, RPM and mA, a joint whose
//! feedback did not arrive as `None`, never an older value.

use std::time::Duration;

use robobus_whj::JointId;
use robobus_whj::units::{Current, CurrentScale, Position, TargetSpeed};
use serde::Serialize;

use super::Station;
use crate::ops::OpError;
use crate::ops::whj::{self as whj_ops, ServoLoop, require_ready};
use crate::whj::{
    CycleReport, CyclicConfig, CyclicStats, Joint, MotionLimits, OwnedCyclic, Protocol, ServoMode,
};

/// One joint's feedback in a cycle.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct JointFeedback {
    /// Position, degrees.
    pub position_deg: f64,
    /// Speed, output RPM.
    pub speed_rpm: f64,
    /// Current, mA.
    pub current_ma: i64,
    /// Drive enabled.
    pub enabled: bool,
    /// Error bits (`no error` or their names).
    pub error: String,
}

/// One cycle of a [`CyclicLoop`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CycleSample {
    /// Cycle number, from 0.
    pub cycle: u64,
    /// The cycle missed its deadline (feedback late or missing).
    pub missed: bool,
    /// First frame sent to last feedback received, µs (`None`: feedback missing).
    pub round_trip_us: Option<f64>,
    /// The targets sent this cycle, in the loop's unit (after smoothing and the step
    /// limit: what the joints were asked for).
    pub commanded: Vec<f64>,
    /// Each joint's feedback, in the loop's joint order (`None`: it did not arrive).
    pub feedback: Vec<Option<JointFeedback>>,
}

/// What a loop did (the bus's [`CyclicStats`], latencies in µs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CyclicSummary {
    /// Cycles run.
    pub cycles: u64,
    /// Cycles with feedback from every joint in time.
    pub complete: u64,
    /// Cycles whose feedback was not complete by the next tick.
    pub deadline_misses: u64,
    /// Feedback frames that did not arrive within their cycle.
    pub missing_replies: u64,
    /// Ticks skipped because the loop ran more than a period late.
    pub overruns: u64,
    /// Position set-points clamped to the step limit.
    pub step_clamps: u64,
    /// Reports dropped because nobody read them.
    pub reports_dropped: u64,
    /// Median cycle round trip, µs.
    pub round_trip_p50_us: f64,
    /// 99th percentile cycle round trip, µs.
    pub round_trip_p99_us: f64,
}

impl From<CyclicStats> for CyclicSummary {
    fn from(s: CyclicStats) -> Self {
        Self {
            cycles: s.cycles,
            complete: s.complete,
            deadline_misses: s.deadline_misses,
            missing_replies: s.missing_replies,
            overruns: s.overruns,
            step_clamps: s.step_clamps,
            reports_dropped: s.reports_dropped,
            round_trip_p50_us: s.round_trip.p50.as_secs_f64() * 1e6,
            round_trip_p99_us: s.round_trip.p99.as_secs_f64() * 1e6,
        }
    }
}

/// A running, checked cyclic loop (see the [module docs](self)). Stops when dropped; the
/// joints then stop by themselves (position: holding where they are, 20 ms after the last
/// frame; speed and current: the loop sends a zero target first).
#[derive(Debug)]
pub struct CyclicLoop {
    cyclic: Option<OwnedCyclic>,
    servo: ServoLoop,
    joints: Vec<JointId>,
    /// Each joint's allowed targets, in the loop's unit.
    limits: Vec<(f64, f64)>,
    scales: Vec<CurrentScale>,
}

/// What `j` accepts as a `servo` target, in that loop's unit (its position limits within
/// the host's bound, its model's peak output speed, its current limit), and its current
/// scale.
pub(crate) fn allowed(
    j: &Joint<'_>,
    servo: ServoLoop,
) -> Result<((f64, f64), CurrentScale), OpError> {
    let identity = j.identity()?;
    let range = match servo {
        ServoLoop::Position => {
            let (min, max) = j.position_limits()?;
            (
                min.degrees().max(-whj_ops::MAX_DEG),
                max.degrees().min(whj_ops::MAX_DEG),
            )
        }
        ServoLoop::Speed => {
            let peak = identity
                .model
                .peak_output_speed_rpm()
                .unwrap_or(whj_ops::MAX_RPM)
                .min(whj_ops::MAX_RPM);
            (-peak, peak)
        }
        ServoLoop::Current => {
            let limit = j
                .read_register("LIT_MAX_CURRENT")?
                .value
                .filter(|v| *v > 0.0)
                .unwrap_or(whj_ops::MAX_MA)
                .min(whj_ops::MAX_MA);
            (-limit, limit)
        }
    };
    Ok((range, identity.model.current_scale()))
}

/// Checks `targets` (one per joint of `joints`, in `servo`'s unit) against each joint's
/// `limits`: the first one out of range is refused, naming the joint, the value and the
/// range.
pub(crate) fn check_targets(
    servo: ServoLoop,
    joints: &[JointId],
    limits: &[(f64, f64)],
    targets: &[f64],
) -> Result<(), OpError> {
    if targets.len() != joints.len() {
        return Err(OpError::invalid(
            "targets",
            format!("{} value(s)", targets.len()),
            format!("one per joint: {} joint(s)", joints.len()),
        ));
    }
    let u = unit(servo);
    for ((&t, &(lo, hi)), id) in targets.iter().zip(limits).zip(joints) {
        if !(t.is_finite() && (lo..=hi).contains(&t)) {
            return Err(OpError::invalid(
                format!("target of joint {id}"),
                format!("{t} {u}"),
                format!("out of range (allowed: {lo}..={hi} {u}); no target was changed"),
            ));
        }
    }
    Ok(())
}

/// The loop's unit, for messages.
const fn unit(servo: ServoLoop) -> &'static str {
    match servo {
        ServoLoop::Position => "deg",
        ServoLoop::Speed => "RPM",
        ServoLoop::Current => "mA",
    }
}

impl CyclicLoop {
    /// Starts a loop of `servo` targets for `joints` on the station's WHJ bus `bus` at
    /// `rate_hz` (the host's frame-rate bound). Position targets start at each joint's
    /// present position, speed and current targets at 0; position targets are followed
    /// with the default [`MotionLimits`].
    pub fn start(
        station: &Station,
        bus: Option<&str>,
        joints: &[u8],
        servo: ServoLoop,
        rate_hz: f64,
    ) -> Result<Self, OpError> {
        Self::start_with(
            station,
            bus,
            joints,
            servo,
            rate_hz,
            MotionLimits::default(),
        )
    }

    /// [`start`](Self::start), position targets followed within `smooth` (its speed and
    /// acceleration limits; the loop's period is `rate_hz`'s).
    pub fn start_with(
        station: &Station,
        bus: Option<&str>,
        joints: &[u8],
        servo: ServoLoop,
        rate_hz: f64,
        smooth: MotionLimits,
    ) -> Result<Self, OpError> {
        let rate_hz = whj_ops::FRAME_RATE_HZ.check("rate_hz", rate_hz)?;
        let ids = crate::ops::distinct_ids::<JointId>("joints", "joints", joints)?;
        let port = station.whj(bus)?;
        let mut limits = Vec::with_capacity(ids.len());
        let mut scales = Vec::with_capacity(ids.len());
        for &id in &ids {
            let j = port.bus().joint(id)?;
            require_ready(&j, servo, "a cyclic loop")?;
            let (range, scale) = allowed(&j, servo)?;
            limits.push(range);
            scales.push(scale);
        }
        let config = CyclicConfig {
            joints: ids.clone(),
            period: Duration::from_secs_f64(1.0 / rate_hz),
            mode: match servo {
                ServoLoop::Position => ServoMode::Position,
                ServoLoop::Speed => ServoMode::Speed,
                ServoLoop::Current => ServoMode::Current,
            },
            protocol: Protocol::PointToPoint,
            smooth: (servo == ServoLoop::Position).then_some(smooth),
        };
        let cyclic = port.shared_bus().cyclic_owned(config)?;
        Ok(Self {
            cyclic: Some(cyclic),
            servo,
            joints: ids,
            limits,
            scales,
        })
    }

    fn cyclic(&self) -> Result<&OwnedCyclic, OpError> {
        self.cyclic
            .as_ref()
            .ok_or_else(|| OpError::Refused("the cyclic loop has stopped".into()))
    }

    /// The joints, in target and feedback order.
    pub fn joints(&self) -> Vec<u8> {
        self.joints.iter().map(|j| j.get()).collect()
    }

    /// Each joint's allowed targets, in the loop's unit (degrees, RPM or mA).
    pub fn limits(&self) -> &[(f64, f64)] {
        &self.limits
    }

    /// Sets the targets, one per joint in the loop's unit; each is checked against the
    /// joint's limits first, and on a refusal none is changed.
    pub fn set(&self, targets: &[f64]) -> Result<(), OpError> {
        check_targets(self.servo, &self.joints, &self.limits, targets)?;
        let bad =
            |e: robobus_whj::units::UnitRangeError| OpError::invalid("targets", "", e.to_string());
        let c = self.cyclic()?;
        match self.servo {
            ServoLoop::Position => c.set_positions(
                &targets
                    .iter()
                    .map(|&t| Position::from_degrees(t).map_err(bad))
                    .collect::<Result<Vec<_>, _>>()?,
            )?,
            ServoLoop::Speed => c.set_speeds(
                &targets
                    .iter()
                    .map(|&t| TargetSpeed::from_rpm(t).map_err(bad))
                    .collect::<Result<Vec<_>, _>>()?,
            )?,
            ServoLoop::Current => c.set_currents(
                &targets
                    .iter()
                    .zip(&self.scales)
                    .map(|(&t, &s)| Current::from_milliamps(t, s).map_err(bad))
                    .collect::<Result<Vec<_>, _>>()?,
            )?,
        }
        Ok(())
    }

    fn sample(&self, r: &CycleReport) -> CycleSample {
        #[allow(clippy::cast_precision_loss)] // counts far below 2^52
        let commanded = r
            .commanded
            .iter()
            .zip(&self.scales)
            .map(|(&raw, &s)| match self.servo {
                ServoLoop::Position => Position(raw).degrees(),
                ServoLoop::Speed => TargetSpeed(raw).rpm(),
                ServoLoop::Current => Current(raw).milliamps(s) as f64,
            })
            .collect();
        CycleSample {
            cycle: r.cycle,
            missed: r.missed,
            round_trip_us: r.round_trip.map(|d| d.as_secs_f64() * 1e6),
            commanded,
            feedback: r
                .feedback
                .iter()
                .zip(&self.scales)
                .map(|(f, &s)| {
                    f.map(|f| JointFeedback {
                        position_deg: f.position.degrees(),
                        speed_rpm: f.speed.rpm(),
                        current_ma: f.current.milliamps(s),
                        enabled: f.enabled,
                        error: f.error.to_string(),
                    })
                })
                .collect(),
        }
    }

    /// The next cycle (oldest first, up to 256 queued), waiting at most `timeout`; `None`
    /// on timeout or once the loop has stopped.
    pub fn next(&self, timeout: Duration) -> Option<CycleSample> {
        let r = self.cyclic.as_ref()?.next_report(timeout)?;
        Some(self.sample(&r))
    }

    /// The most recent cycle, if one has finished.
    pub fn latest(&self) -> Option<CycleSample> {
        let r = self.cyclic.as_ref()?.latest()?;
        Some(self.sample(&r))
    }

    /// Drops the queued cycles (before waiting for a fresh one).
    pub fn clear(&self) {
        if let Some(c) = &self.cyclic {
            c.clear_reports();
        }
    }

    /// What the loop did so far.
    pub fn summary(&self) -> Option<CyclicSummary> {
        self.cyclic.as_ref().map(|c| c.stats().into())
    }

    /// Stops the loop; what it did (`None` if it was stopped before).
    pub fn stop(&mut self) -> Option<CyclicSummary> {
        self.finish().map(Into::into)
    }

    /// Stops the loop; the bus's own statistics of it (every latency percentile), `None`
    /// if it was stopped before.
    pub fn finish(&mut self) -> Option<CyclicStats> {
        self.cyclic.take().map(OwnedCyclic::stop)
    }
}

/// The loop is `Send + Sync`: a front end may keep it on any thread.
const _: () = {
    const fn send_sync<T: Send + Sync>() {}
    send_sync::<CyclicLoop>();
};
