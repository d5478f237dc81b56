//! Sending a plan's timed servo frames, and the rules that end a run early.
//!
//! A planned stream (a move's or a wave's frames) is checked once, before its first frame
//! ([`check_plan_steps`]): no frame steps further than the step limit from the frame before
//! it (or, for the first, from the planned start). A joint, though, checks each position
//! target against where it *is*, and a joint that lags (a load, a current limit) is further
//! behind the plan than one step. So every position set-point goes out planned against the
//! joint's measured position ([`motion::within_step`](crate::motion::within_step), the
//! rule of the cyclic loop too): never more than the step limit from its latest feedback
//! (before the first frame, its present position), held back to that when the plan is
//! further ahead, and counted ([`FrameTimes::held_back`]). A plan whose first set-point is
//! more than the step limit from where the joint is (a plan made elsewhere, or the joint
//! moved since) is refused before its first frame, naming the distance. On a joint that
//! follows, the frames go out exactly as planned. While it runs the feedback is watched:
//!
//! - **silence**: after [`SILENT_FRAMES`] frames in a row without feedback *and* at least
//!   [`SILENT_AFTER`] without any, the run stops, the joint is brought to the run's safe
//!   state, and the run fails as *no device* (exit 3), naming the joint;
//! - **the device's own state**: feedback with error bits or a disabled drive stops the run
//!   at once (safe state, *device* error naming the bits);
//! - **implausible feedback** ([`reading_fault`](super::reading_fault): a position outside
//!   the joint's limits) is never used: the run stops as a *device* error;
//! - **not following**: set-points held back for [`STALL_AFTER`] in a row while the joint
//!   moved less than one step limit means it is not following the plan (stalled, blocked,
//!   or commanded by someone else): the run stops as a *device* error. A joint that lags
//!   but moves runs to the end.
//! - **the host's protection** ([`protect::Monitor`](crate::ops::protect::Monitor), the
//!   one monitor of every moving operation, with its model's defaults
//!   ([`Limits::whj`](crate::ops::protect::Limits::whj))): each feedback is a reading (its
//!   position against the set-point sent before it, and in position mode its current: in
//!   speed and current mode the current follows the frames) and every
//!   [`TEMPERATURE_EVERY`] a status query adds the temperature. A stall, a collision or
//!   heat stops the run: the joint is disabled where its model's brake holds it
//!   ([`torque_off_is_safe`](crate::ops::protect::torque_off_is_safe)), else left in the
//!   run's safe state, and the run fails as a *device* error naming the joint, the
//!   quantity, the limit and the time. Warnings and derating are reported with the run (a
//!   planned stream cannot slow down: a derated joint carries on at the plan's speed).

use std::time::{Duration, Instant};

use robobus_whj::Request;
use robobus_whj::reply::ServoFeedback;
use robobus_whj::units::Position;

use super::{OpError, Plan, PlannedFrame, ServoLoop, broadcast, pause_until, reading_fault, whj};
use crate::motion::within_step;
use crate::ops::protect::{self, Action, Fault, Limits, Monitor, Reading};
use crate::ops::safe::WhjJoints;
use crate::ops::{Control, Progress, SafeState};
use crate::whj::Joint;

/// How often a running stream reads its joint's temperature for the host's protection (a
/// status query between two frames), as `robot play` does.
pub const TEMPERATURE_EVERY: Duration = Duration::from_millis(250);

/// When a planned frame went out and how long its exchange took.
#[derive(Debug, Clone, Copy)]
pub(crate) struct FrameTimes {
    /// When it was due, from the plan's start (what the pre-flight names).
    #[cfg_attr(not(feature = "sim"), allow(dead_code))]
    pub(crate) at: Duration,
    /// How late after its planned time the frame was handed to the bus.
    pub(crate) late: Duration,
    /// From handing the frame to the bus to its feedback (`None`: no feedback came).
    pub(crate) round_trip: Option<Duration>,
    /// Whether its position set-point was held back to the step limit from the joint's
    /// measured position (the joint lagged further behind the plan than that).
    pub(crate) held_back: bool,
    /// The position set-point it carried, degrees, and how far the plan's was from it
    /// (`None`: no position set-point).
    #[cfg_attr(not(feature = "sim"), allow(dead_code))]
    pub(crate) set_point: Option<(f64, f64)>,
}

/// Frames in a row without feedback before a run counts its joint as silent.
pub const SILENT_FRAMES: u32 = 3;

/// How long a run goes without any feedback before its joint counts as silent (together
/// with [`SILENT_FRAMES`]: at 20 Hz three frames take 150 ms, at 1 kHz 100 ms take 100).
pub const SILENT_AFTER: Duration = Duration::from_millis(100);

/// How long set-points may be held back in a row, while the joint moves less than one step
/// limit, before the run stops as "not following".
pub const STALL_AFTER: Duration = Duration::from_millis(500);

/// Refuses a plan (nothing sent) whose position frames step further than `step_limit_deg`
/// from the frame before (the first from `plan.start_deg`). `hint` names the options that
/// change the steps (`--max-speed / --rate-hz`).
pub fn check_plan_steps(plan: &Plan, step_limit_deg: f64, hint: &str) -> Result<(), OpError> {
    // A plan computed in floating point may land a hair past the limit.
    let limit = step_limit_deg + 1e-9;
    let mut prev = plan.start_deg;
    for (k, f) in plan.frames.iter().enumerate() {
        let Request::PositionServo { target, .. } = f.request else {
            continue;
        };
        let deg = target.degrees();
        if let Some(p) = prev
            && (deg - p).abs() > limit
        {
            return Err(OpError::invalid(
                hint,
                format!("frame {k}: {p:.4} -> {deg:.4} deg"),
                format!(
                    "steps {:.4} deg, beyond the step limit of {step_limit_deg} deg: lower the \
                     speed or raise the rate",
                    (deg - p).abs()
                ),
            ));
        }
        prev = Some(deg);
    }
    Ok(())
}

/// What the stream watch needs to know about the run.
#[derive(Clone, Copy)]
pub(super) struct Watch {
    /// The loop the frames drive (and the safe state's mode).
    pub servo: ServoLoop,
    /// The safe state a stopped run leaves the joint in.
    pub on_stop: SafeState,
    /// The joint's position limits, degrees, for the plausibility of feedback.
    pub limits: (f64, f64),
    /// The step limit, degrees (for the follow check of position frames).
    pub step_limit_deg: f64,
    /// The progress stage (`move`, `wave`).
    pub stage: &'static str,
}

/// Brings the joint to the run's safe state and returns `error` (or, if the safe state
/// failed too, `error` with that said).
pub(super) fn stop_with(j: &Joint<'_>, watch: &Watch, error: OpError) -> OpError {
    let failed = watch.on_stop.apply(&mut WhjJoints {
        joints: core::slice::from_ref(j),
        servo: watch.servo,
    });
    let outcome = watch.on_stop.outcome(true);
    let tail = match failed.first() {
        None => format!("; joint {} left {outcome}", j.id().get()),
        Some(f) => format!("; could not leave joint {} {outcome}: {f}", j.id().get()),
    };
    match error {
        OpError::Device(m) => OpError::Device(format!("{m}{tail}")),
        OpError::NoDevice(m) => OpError::NoDevice(format!("{m}{tail}")),
        other => other,
    }
}

/// The position set-point `request` carries for `joint` (point-to-point, or its slot of a
/// 0x2F broadcast frame), degrees.
fn position_target(request: Request, joint: robobus_whj::JointId) -> Option<f64> {
    match request {
        Request::PositionServo { joint: to, target } if to == joint => Some(target.degrees()),
        Request::BroadcastPosition(b) => b.slot(joint).map(|s| s.position.degrees()),
        _ => None,
    }
}

/// `request` with `joint`'s position set-point replaced by `deg` (a broadcast frame keeps
/// its other slots and feed-forward); `None` when `deg` has no position value.
fn with_position(request: Request, joint: robobus_whj::JointId, deg: f64) -> Option<Request> {
    let target = Position::from_degrees(deg).ok()?;
    match request {
        Request::PositionServo { joint: to, .. } if to == joint => {
            Some(Request::PositionServo { joint, target })
        }
        Request::BroadcastPosition(mut b) => {
            let slot = b.slots.get_mut(usize::from(joint.get()).checked_sub(1)?)?;
            slot.as_mut()?.position = target;
            Some(Request::BroadcastPosition(b))
        }
        _ => None,
    }
}

/// Where the joint is before a stream's first frame, and the refusal of a plan whose first
/// position set-point is more than the step limit from it (nothing sent). `None` when the
/// plan has no position frame for the joint.
fn measured_start(j: &Joint<'_>, plan: &Plan, watch: &Watch) -> Result<Option<f64>, OpError> {
    let Some(first) = plan
        .frames
        .iter()
        .find_map(|f| position_target(f.request, j.id()))
    else {
        return Ok(None);
    };
    let id = j.id().get();
    let at = j.recent_position().map_err(whj)?.degrees();
    if let Some(fault) = reading_fault(at, watch.limits, None) {
        return Err(OpError::Device(format!(
            "joint {id}: present {fault}; {} not started, nothing sent",
            watch.stage
        )));
    }
    let off = (first - at).abs();
    if off > watch.step_limit_deg + 1e-9 {
        return Err(OpError::Refused(format!(
            "joint {id}: the {}'s first set-point {first:.4} deg is {off:.4} deg from where \
             the joint is ({at:.4} deg), beyond the step limit of {} deg: plan it from the \
             joint's present position, or move the joint there first (whj move {id} \
             {first:.4}); nothing sent",
            watch.stage, watch.step_limit_deg
        )));
    }
    Ok(Some(at))
}

/// The joint's own step protection, degrees: a position target further than this from its
/// actual position is refused and latches 0x4000 (§6.6, C10).
const JOINT_STEP_PROTECTION_DEG: f64 = 10.0;

/// The position set-point a stream may send now: the planned one, held back to within
/// two step limits (at most [`JOINT_STEP_PROTECTION_DEG`]) of every place the joint may be
/// when the frame arrives. The feedback is the joint's position when the previous frame
/// arrived, one period old; since then the joint went toward its last set-point
/// (`last_sent`), or carried on as it moved over the period before (`previous`, the
/// feedback before `measured`: a joint that overshoots). A joint that follows gets the
/// plan unchanged (the plan steps at most one step limit a frame); one that lags or
/// overshoots never a target beyond its protection.
fn allowed_set_point(
    planned: f64,
    measured: f64,
    previous: Option<f64>,
    last_sent: f64,
    step_limit: f64,
) -> f64 {
    let reach = (2.0 * step_limit).min(JOINT_STEP_PROTECTION_DEG);
    let carried = previous.map_or(measured, |p| measured + (measured - p));
    let lo = measured.min(carried).min(last_sent);
    let hi = measured.max(carried).max(last_sent);
    if hi - lo > 2.0 * reach {
        // The joint moves further in a period than any set-point can cover: hold it in
        // the middle (the watch stops a joint that does not follow).
        return f64::midpoint(lo, hi);
    }
    // Within `reach` of both ends of [lo, hi]: of its middle, less half its width.
    within_step(planned, f64::midpoint(lo, hi), reach - (hi - lo) / 2.0)
}

/// What a stream knows of where its joint is, and how long its set-points have been held
/// back.
#[derive(Debug, Clone, Copy)]
struct Follow {
    /// The latest feedback's position (at first: the present position).
    measured: Option<f64>,
    /// The feedback before `measured`.
    previous: Option<f64>,
    /// The position set-point last sent (at first: where the joint holds).
    last_sent: Option<f64>,
    /// While set-points are held back in a row: since when, where the joint was then, and
    /// which way the plan was from it.
    held_since: Option<(Instant, f64, f64)>,
}

impl Follow {
    const fn new(measured: Option<f64>) -> Self {
        Self {
            measured,
            previous: None,
            last_sent: measured,
            held_since: None,
        }
    }

    /// `request` as it may go out at `now` ([`allowed_set_point`]), and whether it was
    /// held back; `Err` (the message) when the joint is not following.
    fn hold(
        &mut self,
        request: Request,
        joint: robobus_whj::JointId,
        now: Instant,
        step_limit: f64,
    ) -> Result<(Request, bool), String> {
        let mut out = (request, false);
        if let (Some(planned), Some(at), Some(last)) = (
            position_target(request, joint),
            self.measured,
            self.last_sent,
        ) {
            let allowed = allowed_set_point(planned, at, self.previous, last, step_limit);
            #[allow(clippy::float_cmp)] // exact: did the step limit change it
            if allowed != planned {
                out = (
                    with_position(request, joint, allowed).unwrap_or(request),
                    true,
                );
                match self.held_since {
                    Some((since, from, way))
                        if (at - from) * way < step_limit
                            && now.saturating_duration_since(since) >= STALL_AFTER =>
                    {
                        return Err(format!(
                            "joint {} is not following the plan: its set-points were held \
                             back to the step limit of {step_limit} deg for {} ms while it \
                             moved from {from:.4} to {at:.4} deg, not one step limit toward \
                             them",
                            joint.get(),
                            now.saturating_duration_since(since).as_millis(),
                        ));
                    }
                    // Held back before, and not yet a step limit nearer: waiting.
                    Some((_, from, way)) if (at - from) * way < step_limit => {}
                    // The first held-back set-point, or the joint moved on: time from here.
                    _ => self.held_since = Some((now, at, (planned - at).signum())),
                }
            }
        }
        if !out.1 {
            self.held_since = None;
        }
        if let Some(p) = position_target(out.0, joint) {
            self.last_sent = Some(p);
        }
        Ok(out)
    }

    /// A feedback came: the joint was at `deg`.
    const fn measured(&mut self, deg: f64) {
        self.previous = self.measured;
        self.measured = Some(deg);
    }
}

/// The host's protection of a stream's joint (see the module docs): its monitor, when
/// the temperature is read next, and the events that did not stop the run.
struct Guard {
    monitor: Monitor,
    model: Option<robobus_whj::units::Model>,
    scale: robobus_whj::units::CurrentScale,
    next_temperature: Instant,
}

impl Guard {
    /// The joint's guard from `start`, with its model's limits (the identity the bus
    /// read; a joint it does not know is watched with the defaults of an unknown model).
    fn new(j: &Joint<'_>, start: Instant) -> Self {
        let identity = j.identity().ok();
        let model = identity.map(|i| i.model);
        Self {
            monitor: Monitor::new(
                start,
                vec![(format!("joint {}", j.id().get()), Limits::whj(model))],
            ),
            model,
            scale: identity.map_or(robobus_whj::units::CurrentScale::OneMilliamp, |i| {
                i.current_scale()
            }),
            next_temperature: start,
        }
    }

    /// Feeds one feedback (`before`: the position set-point sent before the frame it
    /// answers), with the temperature when it is due; the fault that stops the run, if
    /// any. The other events go to `events` (at most [`protect::MAX_EVENTS`]).
    fn feed(
        &mut self,
        j: &Joint<'_>,
        watch: &Watch,
        fb: &ServoFeedback,
        before: Option<f64>,
        events: &mut Vec<Fault>,
    ) -> Option<Fault> {
        let now = j.bus().now();
        let temperature_c = if now >= self.next_temperature {
            self.next_temperature = now + TEMPERATURE_EVERY;
            j.status()
                .ok()
                .map(|st| f64::from(st.temperature.celsius()))
        } else {
            None
        };
        let position = fb.position.degrees();
        #[allow(clippy::cast_precision_loss)] // |mA| < 2^53
        let current_a = fb.current.milliamps(self.scale) as f64 / 1e3;
        let reading = Reading {
            at: now,
            position_deg: Some(position),
            error_deg: before.map(|b| (position - b).abs()),
            target_deg: before,
            // In speed and current mode the current follows what the frames ask (a
            // square wave's edges jump by design): only a position stream's is watched.
            current_a: (watch.servo == ServoLoop::Position).then_some(current_a),
            temperature_c,
        };
        let mut stop = None;
        for f in self.monitor.feed(0, &reading) {
            tracing::warn!("{f}");
            if f.action == Action::Stop {
                stop = Some(f);
            } else if events.len() < protect::MAX_EVENTS {
                events.push(f);
            }
        }
        stop
    }

    /// Stops the joint for `fault`: disabled where its model's brake holds it, else in the
    /// run's safe state; the run's error names the fault.
    fn stop(&self, j: &Joint<'_>, watch: &Watch, fault: &Fault, sent: u64) -> OpError {
        let on_stop = if protect::torque_off_is_safe(self.model) {
            SafeState::Disable
        } else {
            watch.on_stop
        };
        let watch = Watch { on_stop, ..*watch };
        stop_with(
            j,
            &watch,
            OpError::Device(format!(
                "{fault}; {} stopped after {sent} frame(s)",
                watch.stage
            )),
        )
    }
}

/// How a move finishes when its last set-point was held back (the joint lagged): the
/// target goes out again every `period` until it goes out unchanged, for at most `within`
/// after the plan's last frame.
#[derive(Debug, Clone, Copy)]
pub(super) struct Finish {
    /// Time between two frames (the plan's period).
    pub period: Duration,
    /// How long after the plan's last frame the target may still go out.
    pub within: Duration,
}

/// Sends the timed frames of `plan` at their times, planned against the joint's measured
/// position and watched as the module docs say. `on_frame` gets each frame's index, its
/// feedback (`None`: no reply) and its times; with `finish`, a held-back last set-point
/// goes out again as [`Finish`] says. The host's protection events that did not stop the
/// run go to `events`. Returns the frames sent, or `Err(())` inside `Ok` when the
/// caller's token stopped it (the caller applies the safe state and reports the
/// interruption).
pub(super) fn send_frames(
    j: &Joint<'_>,
    plan: &Plan,
    control: &mut Control<'_>,
    watch: &Watch,
    finish: Option<Finish>,
    events: &mut Vec<Fault>,
    mut on_frame: impl FnMut(usize, Option<&ServoFeedback>, FrameTimes),
) -> Result<Result<u64, ()>, OpError> {
    let bus = j.bus();
    let joint = j.id();
    let id = joint.get();
    let mut follow = Follow::new(measured_start(j, plan, watch)?);
    let start = bus.now();
    let mut guard = Guard::new(j, start);
    let total = plan.frames.len() as u64;
    let mut sent = 0u64;
    let mut missing = 0u32;
    let mut last_heard: Instant = start;
    let mut last_held_back = false;
    for k in 0.. {
        let f = match (plan.frames.get(k), plan.frames.last(), finish) {
            (Some(f), _, _) => *f,
            // The plan's last set-point was held back: it goes out again, one period
            // apart, until it goes out unchanged (or `within` is over).
            (None, Some(last), Some(finish)) if last_held_back => {
                let extra = u32::try_from(k + 1 - plan.frames.len()).unwrap_or(u32::MAX);
                let after = finish.period.saturating_mul(extra);
                if after > finish.within {
                    break;
                }
                PlannedFrame {
                    at: last.at + after,
                    request: last.request,
                }
            }
            _ => break,
        };
        let due = start + f.at;
        if control.stopped() || !pause_until(bus, control, due) {
            return Ok(Err(()));
        }
        let before = follow.last_sent;
        let (request, held_back) = follow
            .hold(f.request, j.id(), bus.now(), watch.step_limit_deg)
            .map_err(|m| {
                let m = format!("{m}; {} stopped after {sent} frame(s)", watch.stage);
                stop_with(j, watch, OpError::Device(m))
            })?;
        last_held_back = held_back;
        let sent_at = bus.now();
        let late = sent_at.saturating_duration_since(due);
        let fb = if request.joint().is_none() {
            broadcast::broadcast_servo(j, request).map_err(whj)?
        } else {
            match j.send_planned(request) {
                Ok(fb) => Some(fb),
                Err(e) if e.is_timeout() => None,
                Err(e) => return Err(stop_with(j, watch, whj(e))),
            }
        };
        let now = bus.now();
        let round_trip = fb.is_some().then(|| now.saturating_duration_since(sent_at));
        sent += 1;
        let set_point = position_target(request, joint).map(|sent| {
            let planned = position_target(f.request, joint).unwrap_or(sent);
            (sent, (planned - sent).abs())
        });
        on_frame(
            k,
            fb.as_ref(),
            FrameTimes {
                at: f.at,
                late,
                round_trip,
                held_back,
                set_point,
            },
        );
        if sent <= total && (sent.is_multiple_of(16) || sent == total) {
            control.report(&Progress::new(watch.stage, sent, Some(total)));
        }
        let Some(fb) = fb else {
            missing += 1;
            let quiet = now.saturating_duration_since(last_heard);
            if missing >= SILENT_FRAMES && quiet >= SILENT_AFTER {
                return Err(stop_with(
                    j,
                    watch,
                    OpError::NoDevice(format!(
                        "joint {id} fell silent: no feedback to {missing} frame(s) in a row \
                         ({} ms); {} stopped after {sent} of {total} frame(s)",
                        quiet.as_millis(),
                        watch.stage
                    )),
                ));
            }
            continue;
        };
        missing = 0;
        last_heard = now;
        let when = format!("at frame {k} of {total}");
        check_feedback(j, watch, &fb, &when)?;
        if let Some(fault) = guard.feed(j, watch, &fb, before, events) {
            return Err(guard.stop(j, watch, &fault, sent));
        }
        follow.measured(fb.position.degrees());
    }
    Ok(Ok(sent))
}

/// Checks one feedback frame of a running operation: a plausible position, no error bits, an
/// enabled drive. Otherwise the joint is brought to the safe state and the run fails as a
/// *device* error saying `when`.
pub(super) fn check_feedback(
    j: &Joint<'_>,
    watch: &Watch,
    fb: &ServoFeedback,
    when: &str,
) -> Result<(), OpError> {
    check_state(
        j,
        watch,
        fb.position.degrees(),
        fb.is_enabled(),
        fb.error,
        when,
    )
}

/// Reads the joint's status during a running operation and checks it as
/// [`check_feedback`] does; a joint that does not answer stops the run as *no device*.
pub(super) fn check_status(j: &Joint<'_>, watch: &Watch) -> Result<(), OpError> {
    match j.status() {
        Ok(st) => check_state(
            j,
            watch,
            st.position.degrees(),
            st.is_enabled(),
            st.error,
            "while running",
        ),
        Err(e) if e.is_timeout() => Err(stop_with(
            j,
            watch,
            OpError::NoDevice(format!(
                "joint {} fell silent during the {}: {e}",
                j.id().get(),
                watch.stage
            )),
        )),
        Err(e) => Err(stop_with(j, watch, whj(e))),
    }
}

fn check_state(
    j: &Joint<'_>,
    watch: &Watch,
    at: f64,
    enabled: bool,
    error: robobus_whj::error_code::ErrorCode,
    when: &str,
) -> Result<(), OpError> {
    let id = j.id().get();
    if let Some(fault) = reading_fault(at, watch.limits, None) {
        return Err(stop_with(
            j,
            watch,
            OpError::Device(format!(
                "joint {id}: {fault} ({when}); {} stopped",
                watch.stage
            )),
        ));
    }
    if !enabled || !error.is_empty() {
        return Err(stop_with(
            j,
            watch,
            OpError::Device(format!(
                "joint {id}: {} {when} (error bits: {error}); {} stopped",
                if enabled { "error" } else { "disabled" },
                watch.stage
            )),
        ));
    }
    Ok(())
}
