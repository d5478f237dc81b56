//! Moves and waves: planned once, sent as planned.

use std::time::Duration;

use robobus_whj::reply::ServoFeedback;
use robobus_whj::units::{Current, CurrentScale, Position, TargetSpeed};
use robobus_whj::{JointId, Request};
use serde::Serialize;

use crate::motion::{Limiter, Tracking};
use crate::ops::PreflightReport;
use crate::ops::protect::Fault;
use crate::ops::{Bound, Control, OpError, SafeState, StopToken};
use crate::whj::{Joint, MotionLimits, Percentiles, Profile, WhjError};

use super::{
    Plan, PlannedFrame, ServoLoop, check_demand, interrupted, mode_name, pause_until,
    plausible_position, require_ready, stream, whj,
};
use stream::FrameTimes;

/// What a run hands an observer of its frames (the pre-flight on the simulator): each
/// frame's index, its times and set-point, and the feedback that answered it.
pub(crate) type FrameObserver<'o> = &'o mut dyn FnMut(usize, Option<&ServoFeedback>, &FrameTimes);

// ---------------------------------------------------------------------------------------
// Moves
// ---------------------------------------------------------------------------------------

/// A smooth move (`whj move`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MoveArgs {
    /// The joint.
    pub joint: JointId,
    /// Target, degrees.
    pub target_deg: f64,
    /// Largest speed, degrees per second.
    pub max_speed_deg_s: f64,
    /// Frames per second.
    pub rate_hz: f64,
    /// Largest step of one frame, degrees (the bus's step limit:
    /// [`JointBusConfig::step_limit_deg`](crate::whj::JointBusConfig::step_limit_deg)).
    pub step_limit_deg: f64,
}

impl MoveArgs {
    /// Checks the arguments (nothing is sent).
    pub fn validate(&self) -> Result<(), OpError> {
        if !(self.target_deg.is_finite() && self.target_deg.abs() <= 720.0) {
            return Err(OpError::invalid(
                "<DEGREES>",
                self.target_deg,
                "allowed: -720..=720",
            ));
        }
        if !(self.max_speed_deg_s.is_finite() && self.max_speed_deg_s > 0.0) {
            return Err(OpError::invalid(
                "--max-speed",
                self.max_speed_deg_s,
                "allowed: more than 0 deg/s",
            ));
        }
        check_rate_and_step(self.rate_hz, self.step_limit_deg)?;
        Ok(())
    }

    /// The speed the plan uses: `max_speed_deg_s`, or less when one frame at that speed
    /// would step further than the step limit (the move is then split into more, smaller
    /// steps).
    pub fn planned_speed(&self) -> f64 {
        self.max_speed_deg_s.min(self.step_limit_deg * self.rate_hz)
    }

    /// The profile limits of the plan.
    pub fn limits(&self) -> MotionLimits {
        let speed = self.planned_speed();
        MotionLimits {
            max_speed_deg_s: speed,
            max_accel_deg_s2: (speed * 4.0).max(10.0),
            period: Duration::from_secs_f64(1.0 / self.rate_hz),
            ..MotionLimits::default()
        }
    }
}

/// Checks a frame rate (1..=1000 Hz) and a step limit (positive).
fn check_rate_and_step(rate_hz: f64, step_limit_deg: f64) -> Result<(), OpError> {
    if !(rate_hz.is_finite() && (FRAME_RATE_HZ.min..=FRAME_RATE_HZ.max).contains(&rate_hz)) {
        return Err(OpError::invalid("--rate-hz", rate_hz, "allowed: 1..=1000"));
    }
    if !(step_limit_deg.is_finite() && step_limit_deg > 0.0) {
        return Err(OpError::invalid(
            "step limit",
            step_limit_deg,
            "allowed: more than 0 deg",
        ));
    }
    Ok(())
}

/// The most frames one move may take (an hour at 100 Hz).
pub const MAX_MOVE_FRAMES: usize = 360_000;

/// Plans a move from `from_deg`: one position frame per period along the library's smooth
/// [`Profile`] (speed- and acceleration-limited, never a step beyond the step limit), the
/// last one exactly on the target. `assumed` says whether `from_deg` was assumed (dry run)
/// rather than measured.
pub fn plan_move(args: &MoveArgs, from_deg: f64, assumed: bool) -> Result<Plan, OpError> {
    plan_move_checked(args, from_deg, assumed, &StopToken::new())
}

/// How many frames a plan computes between two looks at its run's stop token.
const PLAN_CHECK_EVERY: usize = 4096;

/// Whether a run's plan may go on: `stop` set is [`OpError::Interrupted`] without a
/// detail, which [`stopped_planning`] turns into the run's stop.
fn planning(stop: &StopToken) -> Result<(), OpError> {
    if stop.is_stopped() {
        Err(OpError::Interrupted { detail: None })
    } else {
        Ok(())
    }
}

/// A plan's error as its run reports it: a stop while it was planned (see [`planning`])
/// brings joint `j` to `on_stop` and is the run's stop, before any of its frames was sent.
fn stopped_planning(j: &Joint<'_>, e: OpError, on_stop: SafeState, servo: ServoLoop) -> OpError {
    match e {
        OpError::Interrupted { detail: None } => match interrupted(j, on_stop, servo) {
            OpError::Interrupted {
                detail: Some(detail),
            } => OpError::Interrupted {
                detail: Some(format!(
                    "{detail} (stopped while its frames were planned: none was sent)"
                )),
            },
            other => other,
        },
        e => e,
    }
}

/// [`plan_move`], looking at `stop` every [`PLAN_CHECK_EVERY`] frames.
fn plan_move_checked(
    args: &MoveArgs,
    from_deg: f64,
    assumed: bool,
    stop: &StopToken,
) -> Result<Plan, OpError> {
    args.validate()?;
    let limits = args.limits();
    let points = Profile::plan_checked(from_deg, args.target_deg, limits, MAX_MOVE_FRAMES, || {
        planning(stop)
    })?
    .ok_or_else(|| {
        OpError::invalid(
            "--max-speed",
            args.max_speed_deg_s,
            format!(
                "the move from {from_deg} deg to {} deg would take more than {MAX_MOVE_FRAMES} \
                 frames; give a higher speed",
                args.target_deg
            ),
        )
    })?;
    let mut plan = Plan {
        reads: vec![Request::StatusQuery { joint: args.joint }],
        start_deg: Some(from_deg),
        ..Plan::default()
    };
    if assumed {
        plan.assumed = Some(format!(
            "start angle assumed {from_deg} deg (a real run reads the present position and \
             plans from it; give --from DEG to plan from another angle)"
        ));
    }
    for (k, deg) in points.iter().enumerate() {
        if k % PLAN_CHECK_EVERY == 0 {
            planning(stop)?;
        }
        let target = Position::from_degrees(*deg)
            .map_err(|e| OpError::invalid("<DEGREES>", deg, e.to_string()))?;
        plan.frames.push(PlannedFrame {
            at: limits.period * u32::try_from(k).unwrap_or(u32::MAX),
            request: Request::PositionServo {
                joint: args.joint,
                target,
            },
        });
    }
    stream::check_plan_steps(&plan, args.step_limit_deg, "--max-speed / --rate-hz")?;
    let speed = args.planned_speed();
    plan.notes.push(format!(
        "{} position frame(s), one every {:.3} ms, at most {speed} deg/s (acceleration {} \
         deg/s^2); then status queries until the joint is within {} deg of the target; the \
         joint must be enabled and in position mode",
        plan.frames.len(),
        1000.0 / args.rate_hz,
        limits.max_accel_deg_s2,
        limits.tolerance_deg
    ));
    #[allow(clippy::float_cmp)] // planned_speed returns one of its inputs
    if speed != args.max_speed_deg_s {
        plan.notes.push(format!(
            "--max-speed {} at --rate-hz {} would step {:.3} deg per frame, beyond the step \
             limit of {} deg: the move is split into smaller steps at {speed} deg/s",
            args.max_speed_deg_s,
            args.rate_hz,
            args.max_speed_deg_s / args.rate_hz,
            args.step_limit_deg
        ));
    }
    Ok(plan)
}

/// What a move did.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct MoveReport {
    /// Measured start, degrees.
    pub from_deg: f64,
    /// Target, degrees.
    pub target_deg: f64,
    /// Position after the move settled (a fresh status reading), degrees.
    pub position_deg: f64,
    /// Position frames sent.
    pub frames: u64,
    /// Wall time, seconds.
    pub seconds: f64,
    /// Whether the move ran slower than `--max-speed` to respect the step limit.
    pub step_limited: bool,
    /// Position frames whose set-point was held back to the step limit from the joint's
    /// latest measured position (the joint lagged further behind the plan than that).
    pub held_back: u64,
    /// Error bits after the move.
    pub error: String,
    /// The host's protection events that did not stop the move (warnings, derating), in
    /// order; left out of the JSON when there were none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub protection: Vec<Fault>,
    /// The pre-flight on the simulator that passed before the move (left out when none
    /// ran).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub preflight: Option<PreflightReport>,
}

/// The plan a real move runs: checks the joint (enabled in position mode, the target within
/// its limits, the present position plausible), then plans from the measured position.
pub fn prepare_move(j: &Joint<'_>, args: &MoveArgs) -> Result<Plan, OpError> {
    prepare_move_checked(j, args, &StopToken::new())
}

/// [`prepare_move`] for a run under `control`: a stop while its frames are planned (a
/// slow move has up to [`MAX_MOVE_FRAMES`]) ends it there, the joint brought to `on_stop`,
/// with the [`OpError::Interrupted`] of a stop during the move; none of its frames was
/// sent.
pub fn prepare_move_stoppable(
    j: &Joint<'_>,
    args: &MoveArgs,
    control: &Control<'_>,
    on_stop: SafeState,
) -> Result<Plan, OpError> {
    prepare_move_checked(j, args, control.token())
        .map_err(|e| stopped_planning(j, e, on_stop, ServoLoop::Position))
}

fn prepare_move_checked(j: &Joint<'_>, args: &MoveArgs, stop: &StopToken) -> Result<Plan, OpError> {
    args.validate()?;
    require_ready(j, ServoLoop::Position, "move")?;
    check_demand(j, ServoLoop::Position, args.target_deg, args.target_deg)?;
    let from = plausible_position(j)?;
    plan_move_checked(args, from, false, stop)
}

/// The joint's position limits in degrees (what feedback is checked against).
pub(super) fn degree_limits(j: &Joint<'_>) -> Result<(f64, f64), OpError> {
    let (min, max) = j.position_limits().map_err(whj)?;
    Ok((min.degrees(), max.degrees()))
}

/// Runs a move: [`prepare_move`], then the plan's frames at their times, then status
/// queries until the joint is within the tolerance (or the settle timeout passes:
/// [`WhjError::MoveIncomplete`]). The final position is that fresh reading; error bits or a
/// disabled drive afterwards fail the move, naming the bits. On stop: `on_stop`.
pub fn run_move(
    j: &Joint<'_>,
    args: &MoveArgs,
    control: &mut Control<'_>,
    on_stop: SafeState,
) -> Result<MoveReport, OpError> {
    let plan = prepare_move_stoppable(j, args, control, on_stop)?;
    execute_move(j, args, &plan, control, on_stop)
}

/// Runs a prepared move plan (see [`run_move`]).
pub fn execute_move(
    j: &Joint<'_>,
    args: &MoveArgs,
    plan: &Plan,
    control: &mut Control<'_>,
    on_stop: SafeState,
) -> Result<MoveReport, OpError> {
    execute_move_observed(j, args, plan, control, on_stop, &mut |_, _, _| {})
}

/// [`execute_move`], each frame handed to `observe` as it is answered.
pub(crate) fn execute_move_observed(
    j: &Joint<'_>,
    args: &MoveArgs,
    plan: &Plan,
    control: &mut Control<'_>,
    on_stop: SafeState,
    observe: FrameObserver<'_>,
) -> Result<MoveReport, OpError> {
    let id = j.id();
    let bus = j.bus();
    let began = bus.now();
    let from_deg = plan.start_deg.unwrap_or(f64::NAN);
    let watch = stream::Watch {
        servo: ServoLoop::Position,
        on_stop,
        limits: degree_limits(j)?,
        step_limit_deg: args.step_limit_deg,
        stage: "move",
    };
    let mut held_back = 0u64;
    let limits = args.limits();
    let finish = stream::Finish {
        period: limits.period,
        within: limits.settle_timeout,
    };
    let mut protection = Vec::new();
    let Ok(sent) = stream::send_frames(
        j,
        plan,
        control,
        &watch,
        Some(finish),
        &mut protection,
        |k, fb, times| {
            held_back += u64::from(times.held_back);
            observe(k, fb, &times);
        },
    )?
    else {
        return Err(interrupted(j, on_stop, ServoLoop::Position));
    };
    let settle_start = bus.now();
    let status = loop {
        if control.stopped() {
            return Err(interrupted(j, on_stop, ServoLoop::Position));
        }
        let st = j.status().map_err(whj)?;
        if !st.is_enabled() || !st.error.is_empty() {
            return Err(OpError::Device(format!(
                "{id}: {} after the move to {:.4} deg, at {:.4} deg (error bits: {})",
                if st.is_enabled() { "error" } else { "disabled" },
                args.target_deg,
                st.position.degrees(),
                st.error
            )));
        }
        if (st.position.degrees() - args.target_deg).abs() <= limits.tolerance_deg {
            break st;
        }
        let now = bus.now();
        if now.saturating_duration_since(settle_start) > limits.settle_timeout {
            return Err(whj(WhjError::MoveIncomplete {
                joint: id,
                target_deg: args.target_deg,
                actual_deg: st.position.degrees(),
                waited: now.saturating_duration_since(began),
                code: st.error,
            }));
        }
        if !pause_until(bus, control, now + limits.period) {
            return Err(interrupted(j, on_stop, ServoLoop::Position));
        }
    };
    #[allow(clippy::float_cmp)]
    let step_limited = args.planned_speed() != args.max_speed_deg_s;
    Ok(MoveReport {
        from_deg,
        target_deg: args.target_deg,
        position_deg: status.position.degrees(),
        frames: sent,
        seconds: bus.now().saturating_duration_since(began).as_secs_f64(),
        step_limited,
        held_back,
        error: status.error.to_string(),
        protection,
        preflight: None,
    })
}

// ---------------------------------------------------------------------------------------
// Waves
// ---------------------------------------------------------------------------------------

/// Shape of a test wave.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Shape {
    /// offset + amplitude · sin(2π f t).
    Sine,
    /// offset ± amplitude by the sign of sin(2π f t).
    Square,
}

/// A test wave (`whj wave`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WaveArgs {
    /// The joint.
    pub joint: JointId,
    /// Shape.
    pub shape: Shape,
    /// The loop it drives.
    pub servo: ServoLoop,
    /// Amplitude, in the loop's unit.
    pub amplitude: f64,
    /// Frequency, Hz.
    pub frequency: f64,
    /// Offset, in the loop's unit.
    pub offset: f64,
    /// Duration, seconds.
    pub duration: f64,
    /// Frames per second.
    pub rate_hz: f64,
    /// Largest step of one position frame, degrees (the bus's step limit).
    pub step_limit_deg: f64,
}

/// Largest |target angle| sent to a WHJ joint, degrees: one turn either way.
pub const MAX_DEG: f64 = 360.0;
/// Largest |target speed| sent to a WHJ joint, output RPM: the highest published peak
/// output speed of any model (WHJ10 / WHJ30, 37.5 RPM).
pub const MAX_RPM: f64 = 37.5;
/// Largest |target current| sent to a WHJ joint, mA (the vendor publishes no peak).
pub const MAX_MA: f64 = 30_000.0;
/// WHJ frame rate (`--rate-hz` of move and wave, the rate of a station's cyclic loop).
pub const FRAME_RATE_HZ: Bound = Bound {
    what: "rate (Hz)",
    unit: "Hz",
    min: 1.0,
    max: 1000.0,
};
/// The step limiter of position waves: a square wave becomes steep ramps.
pub const WAVE_LIMITS: MotionLimits = MotionLimits {
    max_speed_deg_s: 180.0,
    max_accel_deg_s2: 3000.0,
    period: Duration::from_millis(5),
    tolerance_deg: 0.1,
    settle_timeout: Duration::from_secs(2),
};

impl WaveArgs {
    /// The requested value at `t` seconds.
    pub fn at(&self, t: f64) -> f64 {
        let s = (std::f64::consts::TAU * self.frequency * t).sin();
        match self.shape {
            Shape::Sine => self.offset + self.amplitude * s,
            Shape::Square if s >= 0.0 => self.offset + self.amplitude,
            Shape::Square => self.offset - self.amplitude,
        }
    }

    /// Checks the arguments (nothing is sent).
    pub fn validate(&self) -> Result<(), OpError> {
        check_rate_and_step(self.rate_hz, self.step_limit_deg)?;
        if !(self.amplitude.is_finite() && self.amplitude >= 0.0) {
            return Err(OpError::invalid(
                "--amplitude",
                self.amplitude,
                "allowed: >= 0",
            ));
        }
        let fmax = (self.rate_hz / 4.0).min(20.0);
        if !(0.01..=fmax).contains(&self.frequency) {
            return Err(OpError::invalid(
                "--frequency",
                format!("{} Hz", self.frequency),
                format!("out of range 0.01..={fmax} (at most 20 Hz and at most --rate-hz / 4)"),
            ));
        }
        if !(0.01..=600.0).contains(&self.duration) {
            return Err(OpError::invalid(
                "--duration",
                format!("{} s", self.duration),
                "out of range 0.01..=600",
            ));
        }
        let limit = match self.servo {
            ServoLoop::Position => MAX_DEG,
            ServoLoop::Speed => MAX_RPM,
            ServoLoop::Current => MAX_MA,
        };
        let peak = self.offset.abs() + self.amplitude;
        if peak.is_nan() || peak > limit {
            let unit = self.servo.unit();
            return Err(OpError::invalid(
                "--offset / --amplitude",
                format!("{} / {}", self.offset, self.amplitude),
                format!("reach {peak} {unit}, outside -{limit}..={limit} {unit}"),
            ));
        }
        Ok(())
    }

    /// Frames in the wave.
    pub fn count(&self) -> usize {
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // <= 600_000
        let n = (self.duration * self.rate_hz).round().max(1.0) as usize;
        n
    }
}

/// The requested values of a wave, one per frame (what tracking is measured against).
pub fn wave_targets(args: &WaveArgs) -> Vec<f64> {
    #[allow(clippy::cast_precision_loss)]
    (0..args.count())
        .map(|k| args.at(k as f64 / args.rate_hz))
        .collect()
}

/// The set-points a wave's step limiter changed from the request, counted as
/// [`execute_wave`] counts `clamped`, and the largest change.
#[derive(Debug, Default, Clone, Copy)]
struct Clamps {
    count: usize,
    largest_deg: f64,
}

impl Clamps {
    fn add(&mut self, sent_deg: f64, want_deg: f64) {
        let by = (sent_deg - want_deg).abs();
        if by > 1e-3 {
            self.count += 1;
            self.largest_deg = self.largest_deg.max(by);
        }
    }

    /// The plan's note: how many of its `frames` set-points are clamped, by up to how much.
    fn note(&self, frames: usize, from_deg: f64) -> Option<String> {
        (self.count > 0).then(|| {
            format!(
                "{} of {frames} set-point(s) clamped, by up to {:.3} deg: the step limiter \
                 changes them from what the wave asks (a run from {from_deg} deg counts them \
                 as `clamped`)",
                self.count, self.largest_deg
            )
        })
    }
}

/// The step limiter of a position wave: the requested value itself whenever the step to it
/// keeps within the limits (speed, and speed change per frame), so a wave the joint may
/// follow is sent unchanged; otherwise the one motion limiter
/// ([`Limiter`](crate::motion::Limiter)) from the present set-point and speed, until it
/// lands on the request again. A set-point differs from the request only where the request
/// asked for more than the limits allow, and while it catches up after that.
#[derive(Debug, Clone, Copy)]
struct WaveLimiter {
    limiter: Limiter,
    on_track: bool,
    max_speed: f64,
    max_accel: f64,
}

impl WaveLimiter {
    const fn new(from_deg: f64, max_speed: f64, max_accel: f64) -> Self {
        Self {
            limiter: Limiter::new(from_deg),
            on_track: true,
            max_speed,
            max_accel,
        }
    }

    /// The set-point of the next frame, `dt` seconds on, for the request `want`.
    fn step(&mut self, want: f64, dt: f64) -> f64 {
        // (A rounding error's worth of slack, as the limiter has.)
        let slack = 1.0 + 1e-9;
        if self.on_track {
            let speed = (want - self.limiter.position()) / dt;
            if speed.abs() <= self.max_speed * slack
                && (speed - self.limiter.speed()).abs() <= self.max_accel * dt * slack
            {
                self.limiter = Limiter::moving(want, speed);
                return want;
            }
            self.on_track = false;
        }
        let next = self.limiter.step(want, dt, self.max_speed, self.max_accel);
        #[allow(clippy::float_cmp)] // the limiter lands exactly on the request
        if next == want {
            self.on_track = true;
        }
        next
    }
}

/// Plans a wave: one servo frame per period. Position waves start at `from_deg` and go
/// through the wave's step limiter ([`WAVE_LIMITS`] at the wave's rate, never a frame
/// beyond the step limit): a wave within the limits is sent as requested, a square wave
/// becomes steep ramps, and a wave that starts away from `from_deg` gets a lead-in ramp
/// (the plan's notes say how long). Speed and current waves are sent as requested. `scale`
/// converts mA to counts (the joint's model).
pub fn plan_wave(
    args: &WaveArgs,
    from_deg: f64,
    scale: CurrentScale,
    assumed: bool,
) -> Result<Plan, OpError> {
    plan_wave_checked(args, from_deg, scale, assumed, &StopToken::new())
}

/// [`plan_wave`], looking at `stop` every [`PLAN_CHECK_EVERY`] frames.
fn plan_wave_checked(
    args: &WaveArgs,
    from_deg: f64,
    scale: CurrentScale,
    assumed: bool,
    stop: &StopToken,
) -> Result<Plan, OpError> {
    args.validate()?;
    let period = Duration::from_secs_f64(1.0 / args.rate_hz);
    let dt = period.as_secs_f64();
    // Never a frame beyond the step limit, however low the rate.
    let max_speed = WAVE_LIMITS
        .max_speed_deg_s
        .min(args.step_limit_deg * args.rate_hz);
    let mut limiter = WaveLimiter::new(from_deg, max_speed, WAVE_LIMITS.max_accel_deg_s2);
    // Frames before the set-point first reaches the request (a lead-in from `from_deg`).
    let mut lead_in: Option<usize> = None;
    let mut clamps = Clamps::default();
    let mut plan = Plan::default();
    if args.servo == ServoLoop::Position {
        plan.reads.push(Request::StatusQuery { joint: args.joint });
        plan.start_deg = Some(from_deg);
        if assumed {
            plan.assumed = Some(format!(
                "start angle assumed {from_deg} deg (a real run starts the step limiter at \
                 the present position)"
            ));
        }
    }
    let bad =
        |e: robobus_whj::units::UnitRangeError| OpError::invalid("wave", "value", e.to_string());
    let joint = args.joint;
    for (k, want) in wave_targets(args).into_iter().enumerate() {
        if k % PLAN_CHECK_EVERY == 0 {
            planning(stop)?;
        }
        let request = match args.servo {
            ServoLoop::Position => {
                let v = limiter.step(want, dt);
                if lead_in.is_none() && limiter.on_track {
                    lead_in = Some(k);
                }
                let target = Position::from_degrees(v).map_err(bad)?;
                clamps.add(target.degrees(), want);
                Request::PositionServo { joint, target }
            }
            ServoLoop::Speed => Request::SpeedServo {
                joint,
                target: TargetSpeed::from_rpm(want).map_err(bad)?,
            },
            ServoLoop::Current => Request::CurrentServo {
                joint,
                target: Current::from_milliamps(want, scale).map_err(bad)?,
            },
        };
        plan.frames.push(PlannedFrame {
            at: period * u32::try_from(k).unwrap_or(u32::MAX),
            request,
        });
    }
    stream::check_plan_steps(
        &plan,
        args.step_limit_deg,
        "--amplitude / --frequency / --rate-hz",
    )?;
    plan.notes.push(format!(
        "{:?} wave, {} frame(s) at {} Hz; the joint must be enabled and in {} mode{}",
        args.shape,
        plan.frames.len(),
        args.rate_hz,
        mode_name(args.servo.mode()),
        if args.servo == ServoLoop::Position {
            format!(
                " (position frames go through the step limiter: at most {max_speed} deg/s, \
                 {} deg/s^2; a real run holds back, and counts as held_back, a set-point \
                 more than {} deg from where a lagging joint can be)",
                WAVE_LIMITS.max_accel_deg_s2,
                (2.0 * args.step_limit_deg).min(10.0)
            )
        } else {
            String::new()
        }
    ));
    plan.notes.extend(clamps.note(plan.frames.len(), from_deg));
    let first = wave_targets(args).first().copied().unwrap_or(from_deg);
    if args.servo == ServoLoop::Position && (first - from_deg).abs() > args.step_limit_deg {
        plan.notes.push(match lead_in {
            Some(k) => format!(
                "the wave starts {:.4} deg from {from_deg} deg, more than the step limit of {} \
                 deg: its first {k} set-point(s) are a lead-in ramp to it (counted as clamped)",
                (first - from_deg).abs(),
                args.step_limit_deg
            ),
            None => format!(
                "the wave starts {:.4} deg from {from_deg} deg and its set-points never reach \
                 what it asks for (every one counted as clamped): move the joint nearer \
                 --offset first, or lower --amplitude / --frequency",
                (first - from_deg).abs()
            ),
        });
    }
    Ok(plan)
}

/// The last feedback of a wave.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct FeedbackReport {
    /// Drive enabled.
    pub enabled: bool,
    /// Position, degrees.
    pub position_deg: f64,
    /// Speed, RPM.
    pub speed_rpm: f64,
    /// Current, mA.
    pub current_ma: i64,
    /// Error bits.
    pub error: String,
}

impl FeedbackReport {
    /// The report of one feedback.
    pub fn of(fb: &ServoFeedback, scale: CurrentScale) -> Self {
        Self {
            enabled: fb.is_enabled(),
            position_deg: fb.position.degrees(),
            speed_rpm: fb.speed.rpm(),
            current_ma: fb.current.milliamps(scale),
            error: fb.error.to_string(),
        }
    }
}

/// What a wave did.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct WaveReport {
    /// Frames sent.
    pub cycles: u64,
    /// Frames answered.
    pub complete: u64,
    /// Frames without a reply.
    pub missing_replies: u64,
    /// Frames sent more than one period late.
    pub deadline_misses: u64,
    /// Frames whose exchange took longer than one period.
    pub overruns: u64,
    /// Position set-points the plan's step limiter changed from the requested value:
    /// where the wave asked for more speed or acceleration than allowed (a square wave's
    /// edges, a lead-in from where the joint was), and while it caught up after that. A
    /// wave within the limits has none (a joint lagging behind is not clamping: see
    /// `held_back` and the tracking error).
    pub clamped: u64,
    /// Position frames whose set-point the run held back to the step limit from the
    /// joint's latest measured position, because the joint lagged further behind the plan
    /// than that (a load, a current limit); those frames differ from the plan. 0 on a
    /// joint that follows.
    pub held_back: u64,
    /// RMS of (measured − requested), in the loop's unit (`None` without replies).
    pub tracking_rms: Option<f64>,
    /// Largest |measured − requested|.
    pub tracking_max: Option<f64>,
    /// The unit of the tracking values.
    pub unit: &'static str,
    /// The last feedback that came (`None` when none came; left out of the JSON then).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub last: Option<FeedbackReport>,
    /// Whether the last frame went without a reply (`last` is then older).
    pub stale: bool,
    /// Frames without a reply in a row at the end of the wave.
    pub missing_at_end: u64,
    /// Round trip of the answered frames, from handing a frame to the bus to its
    /// feedback: median, µs (`None` without replies).
    pub round_trip_p50_us: Option<u64>,
    /// The 99th percentile (nearest rank), µs.
    pub round_trip_p99_us: Option<u64>,
    /// The longest, µs.
    pub round_trip_max_us: Option<u64>,
    /// The host's protection events that did not stop the wave (warnings, derating), in
    /// order; left out of the JSON when there were none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub protection: Vec<Fault>,
    /// The pre-flight on the simulator that passed before the wave (left out when none
    /// ran).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub preflight: Option<PreflightReport>,
}

/// Runs a wave: checks the joint (enabled in the wave's mode, the values within its
/// bounds), plans it from the present position, and sends the plan's frames at their
/// times. Tracking compares each reply (the joint's state when the next frame arrives)
/// with the value *requested* for the previous frame, so a clamped or ignored wave shows
/// as an error. On stop: `on_stop`.
pub fn run_wave(
    j: &Joint<'_>,
    args: &WaveArgs,
    control: &mut Control<'_>,
    on_stop: SafeState,
) -> Result<(Plan, WaveReport), OpError> {
    let plan = prepare_wave_stoppable(j, args, control, on_stop)?;
    let report = execute_wave(j, args, &plan, control, on_stop)?;
    Ok((plan, report))
}

/// The plan a real wave runs (see [`run_wave`]).
pub fn prepare_wave(j: &Joint<'_>, args: &WaveArgs) -> Result<Plan, OpError> {
    prepare_wave_checked(j, args, &StopToken::new())
}

/// [`prepare_wave`] for a run under `control`: a stop while its frames are planned (up to
/// 600 000) ends it there, the joint brought to `on_stop`, with the
/// [`OpError::Interrupted`] of a stop during the wave; none of its frames was sent.
pub fn prepare_wave_stoppable(
    j: &Joint<'_>,
    args: &WaveArgs,
    control: &Control<'_>,
    on_stop: SafeState,
) -> Result<Plan, OpError> {
    prepare_wave_checked(j, args, control.token())
        .map_err(|e| stopped_planning(j, e, on_stop, args.servo))
}

fn prepare_wave_checked(j: &Joint<'_>, args: &WaveArgs, stop: &StopToken) -> Result<Plan, OpError> {
    args.validate()?;
    require_ready(j, args.servo, "wave")?;
    check_demand(
        j,
        args.servo,
        args.offset - args.amplitude,
        args.offset + args.amplitude,
    )?;
    let from = if args.servo == ServoLoop::Position {
        plausible_position(j)?
    } else {
        0.0
    };
    let scale = j.identity().map_err(whj)?.current_scale();
    plan_wave_checked(args, from, scale, false, stop)
}

/// The position set-points of `plan` that differ from the wave's `targets` (the step
/// limiter changed them).
fn clamped(args: &WaveArgs, plan: &Plan, targets: &[f64]) -> u64 {
    let mut n = 0;
    for (f, want) in plan.frames.iter().zip(targets) {
        // The set-point the frame carries for the wave's joint, point-to-point or in its
        // slot of a 0x2F broadcast frame.
        let sent = match f.request {
            Request::PositionServo { target, .. } => Some(target),
            Request::BroadcastPosition(b) => b.slot(args.joint).map(|s| s.position),
            _ => None,
        };
        if let Some(target) = sent
            && (target.degrees() - want).abs() > 1e-3
        {
            n += 1;
        }
    }
    n
}

/// Runs a prepared wave plan (see [`run_wave`]).
pub fn execute_wave(
    j: &Joint<'_>,
    args: &WaveArgs,
    plan: &Plan,
    control: &mut Control<'_>,
    on_stop: SafeState,
) -> Result<WaveReport, OpError> {
    execute_wave_observed(j, args, plan, control, on_stop, &mut |_, _, _| {})
}

/// [`execute_wave`], each frame handed to `observe` as it is answered.
pub(crate) fn execute_wave_observed(
    j: &Joint<'_>,
    args: &WaveArgs,
    plan: &Plan,
    control: &mut Control<'_>,
    on_stop: SafeState,
    observe: FrameObserver<'_>,
) -> Result<WaveReport, OpError> {
    let scale = j.identity().map_err(whj)?.current_scale();
    let targets = wave_targets(args);
    let period = Duration::from_secs_f64(1.0 / args.rate_hz);
    let mut r = WaveReport {
        cycles: 0,
        complete: 0,
        missing_replies: 0,
        deadline_misses: 0,
        overruns: 0,
        clamped: 0,
        held_back: 0,
        tracking_rms: None,
        tracking_max: None,
        unit: args.servo.unit(),
        last: None,
        stale: false,
        missing_at_end: 0,
        round_trip_p50_us: None,
        round_trip_p99_us: None,
        round_trip_max_us: None,
        protection: Vec::new(),
        preflight: None,
    };
    r.clamped = clamped(args, plan, &targets);
    let mut tracking = Tracking::default();
    let bus = j.bus();
    let mut last_sent = bus.now();
    let mut round_trips = Vec::with_capacity(plan.frames.len());
    let watch = stream::Watch {
        servo: args.servo,
        on_stop,
        limits: degree_limits(j)?,
        step_limit_deg: args.step_limit_deg,
        stage: "wave",
    };
    let mut protection = Vec::new();
    let outcome = stream::send_frames(
        j,
        plan,
        control,
        &watch,
        None,
        &mut protection,
        |k, fb, times| {
            observe(k, fb, &times);
            let late = times.late;
            round_trips.extend(times.round_trip);
            let now = bus.now();
            if k > 0 && now.duration_since(last_sent) > period * 2 {
                r.overruns += 1;
            }
            last_sent = now;
            r.cycles += 1;
            r.held_back += u64::from(times.held_back);
            if late > period {
                r.deadline_misses += 1;
            }
            let Some(fb) = fb else {
                r.missing_replies += 1;
                r.missing_at_end += 1;
                r.stale = true;
                return;
            };
            r.stale = false;
            r.missing_at_end = 0;
            r.complete += 1;
            if k > 0
                && let Some(want) = targets.get(k - 1)
            {
                let got = match args.servo {
                    ServoLoop::Position => fb.position.degrees(),
                    ServoLoop::Speed => fb.speed.rpm(),
                    #[allow(clippy::cast_precision_loss)] // |mA| < 2^53
                    ServoLoop::Current => fb.current.milliamps(scale) as f64,
                };
                tracking.add(got, *want);
            }
            r.last = Some(FeedbackReport::of(fb, scale));
        },
    )?;
    if outcome.is_err() {
        return Err(interrupted(j, on_stop, args.servo));
    }
    r.protection = protection;
    r.tracking_rms = tracking.rms();
    r.tracking_max = tracking.max();
    if !round_trips.is_empty() {
        let p = Percentiles::of(&round_trips);
        let us = |d: Duration| u64::try_from(d.as_micros()).unwrap_or(u64::MAX);
        r.round_trip_p50_us = Some(us(p.p50));
        r.round_trip_p99_us = Some(us(p.p99));
        r.round_trip_max_us = Some(us(p.max));
    }
    Ok(r)
}
