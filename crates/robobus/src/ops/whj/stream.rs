//! Sending a plan's timed servo frames, and the rules that end a run early.
//!
//! A planned stream (a move's or a wave's frames) is checked once, before its first frame
//! ([`check_plan_steps`]): no frame steps further than the step limit from the frame before
//! it (or, for the first, from the planned start). While it runs, each frame goes out as
//! planned; the host does not re-check it against the last feedback, which is the position
//! *before* the previous frame and so lags the plan by a frame or two. Instead the run is
//! watched:
//!
//! - **silence**: after [`SILENT_FRAMES`] frames in a row without feedback *and* at least
//!   [`SILENT_AFTER`] without any, the run stops, the joint is brought to the run's safe
//!   state, and the run fails as *no device* (exit 3), naming the joint;
//! - **the device's own state**: feedback with error bits or a disabled drive stops the run
//!   at once (safe state, *device* error naming the bits);
//! - **implausible feedback** ([`reading_fault`](super::reading_fault): a position outside
//!   the joint's limits) is never used: the run stops as a *device* error;
//! - **not following**: a position frame about to go out further than
//!   [`FOLLOW_STEPS`] step limits from the joint's reported position means the joint is not
//!   following the plan (stalled, blocked, or commanded by someone else): the run stops as a
//!   *device* error, before that frame is sent.

use std::time::{Duration, Instant};

use robobus_whj::Request;
use robobus_whj::reply::ServoFeedback;

use super::{FrameTimes, OpError, Plan, ServoLoop, broadcast, pause_until, reading_fault, whj};
use crate::ops::safe::WhjJoints;
use crate::ops::{Control, Progress, SafeState};
use crate::whj::Joint;

/// Frames in a row without feedback before a run counts its joint as silent.
pub const SILENT_FRAMES: u32 = 3;

/// How long a run goes without any feedback before its joint counts as silent (together
/// with [`SILENT_FRAMES`]: at 20 Hz three frames take 150 ms, at 1 kHz 100 ms take 100).
pub const SILENT_AFTER: Duration = Duration::from_millis(100);

/// How many step limits a position frame may lie from the joint's reported position
/// before the run stops as "not following". The feedback is the position before the
/// previous frame, so a joint that follows lies about two steps behind the next frame.
pub const FOLLOW_STEPS: f64 = 3.0;

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

/// Sends the timed frames of `plan` at their times, watched as the module docs say.
/// `on_frame` gets each frame's index, its feedback (`None`: no reply) and its times.
/// Returns the frames sent, or `Err(())` inside `Ok` when the caller's token stopped it
/// (the caller applies the safe state and reports the interruption).
pub(super) fn send_frames(
    j: &Joint<'_>,
    plan: &Plan,
    control: &mut Control<'_>,
    watch: &Watch,
    mut on_frame: impl FnMut(usize, Option<&ServoFeedback>, FrameTimes),
) -> Result<Result<u64, ()>, OpError> {
    let bus = j.bus();
    let id = j.id().get();
    let start = bus.now();
    let total = plan.frames.len() as u64;
    let mut sent = 0u64;
    let mut missing = 0u32;
    let mut last_heard: Instant = start;
    let mut last_position: Option<f64> = None;
    for (k, f) in plan.frames.iter().enumerate() {
        let due = start + f.at;
        if control.stopped() || !pause_until(bus, control, due) {
            return Ok(Err(()));
        }
        if let (Request::PositionServo { target, .. }, Some(at)) = (f.request, last_position) {
            let off = (target.degrees() - at).abs();
            if off > FOLLOW_STEPS * watch.step_limit_deg {
                return Err(stop_with(
                    j,
                    watch,
                    OpError::Device(format!(
                        "joint {id} is not following the plan: frame {k} ({:.4} deg) is {off:.4} \
                         deg from its reported position {at:.4} deg (more than {FOLLOW_STEPS} \
                         step limits of {} deg); {} stopped after {sent} frame(s)",
                        target.degrees(),
                        watch.step_limit_deg,
                        watch.stage
                    )),
                ));
            }
        }
        let sent_at = bus.now();
        let late = sent_at.saturating_duration_since(due);
        let fb = if f.request.joint().is_none() {
            broadcast::broadcast_servo(j, f.request).map_err(whj)?
        } else {
            match j.send_planned(f.request) {
                Ok(fb) => Some(fb),
                Err(e) if e.is_timeout() => None,
                Err(e) => return Err(stop_with(j, watch, whj(e))),
            }
        };
        let now = bus.now();
        let round_trip = fb.is_some().then(|| now.saturating_duration_since(sent_at));
        sent += 1;
        on_frame(k, fb.as_ref(), FrameTimes { late, round_trip });
        if sent.is_multiple_of(16) || sent == total {
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
        let at = fb.position.degrees();
        last_position = Some(at);
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
