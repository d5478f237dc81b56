//! WHJ operations: what `robobus whj` does, as library calls any front end can make.
//!
//! Each operation takes typed, validated arguments and a connected [`JointBus`], and returns
//! a typed report. Operations on many joints return one [`DeviceResult`] per joint and carry
//! on past a silent one; the caller picks the exit code (the CLI: 3 when any was silent).
//! Long operations ([`run_move`], [`run_wave`]) take a [`Control`]; on stop they apply the
//! caller's [`SafeState`] through [`SafeState::apply`] (the same function the robot watchdog
//! uses) and return [`OpError::Interrupted`].
//!
//! # One plan
//!
//! [`plan_move`] and [`plan_wave`] compute every frame and its time once ([`Plan`]). A
//! dry-run shows the plan; the real run ([`run_move`], [`run_wave`]) sends exactly the
//! plan's servo frames at the plan's times. A move depends on where the joint is: the dry
//! run names the start angle it assumed ([`Plan::assumed`]), the real run plans from the
//! measured one (after checking that it is plausible and within the joint's limits).
//!
//! # Report schema (`--json`)
//!
//! Every report serializes to flat JSON objects whose field names carry their units
//! (`position_deg`, `speed_rpm`, `current_ma`, `voltage_v`, `temperature_c`); error bits are
//! text (`"no error"`, or the bit names joined by `, `). Per-joint results are
//! `{"id": N, ...fields}` for a joint that answered and `{"id": N, "kind", "error"}` for one
//! that did not ([`DeviceResult`]). The reports:
//!
//! - [`StatusReport`]: `enabled`, `mode`, `position_deg`, `current_ma` (null in the 12-byte
//!   layout), `voltage_v`, `temperature_c`, `brake` (`locked` / `released`), `error`;
//! - [`EnableReport`]: `enabled`, `error`; [`ClearReport`]: `error_before`, `error_after`;
//! - [`MoveReport`]: `from_deg`, `target_deg`, `position_deg` (a fresh reading after the
//!   move settled), `frames`, `seconds`, `step_limited` (the plan ran slower than asked so
//!   that no frame exceeds the step limit), `error`;
//! - [`WaveReport`]: `cycles`, `complete`, `missing_replies`, `deadline_misses`, `overruns`, `clamped`
//!   (set-points the step limiter changed), `tracking_rms`, `tracking_max` (against the
//!   *requested* target, in the loop's unit), `last` (the last feedback, or null when none
//!   came), `stale` (true when the last cycle had no reply), `missing_at_end`,
//!   `round_trip_p50_us`, `round_trip_p99_us`, `round_trip_max_us` (send to feedback of the
//!   answered frames, credited at the end of the bus's collision window; null without
//!   replies);
//! - [`SetIdReport`]: `new_id`, `saved`, `note`.
//! - broadcast register reads and writes ([`broadcast_read`], [`broadcast_write`]): one
//!   [`RegisterReport`] per register and [`Slot`], whose `id` is the joint's number or
//!   `"end-board"` (the end board's registers by their names in its own map, raw values);
//!   a slot without a credited reply is `{"id", "kind": "no-device", "error"}`.

// OpError carries the client errors by value, as they do (see `ops::read_bounded`).
#![allow(clippy::result_large_err)]

use std::time::{Duration, Instant};

use robobus_whj::error_code::ErrorCode;
use robobus_whj::reply::ServoFeedback;
use robobus_whj::units::{Current, CurrentScale, Position, TargetSpeed};
use robobus_whj::{JointId, Request, WorkMode};
use serde::Serialize;

use super::safe::WhjJoints;
use super::{Control, DeviceResult, Failure, OpError, Progress, SafeState};
use crate::whj::{Joint, JointBus, MotionLimits, Percentiles, Profile, WhjError};

/// A frame of a plan and when it goes out, from the start of the plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannedFrame {
    /// Time from the first frame.
    pub at: Duration,
    /// The request.
    pub request: Request,
}

/// The frames an operation sends, with their times, and what it assumed.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Plan {
    /// Requests sent before the timed frames (reads the real run makes to plan).
    pub reads: Vec<Request>,
    /// The timed frames.
    pub frames: Vec<PlannedFrame>,
    /// The start angle the plan begins from (moves, position waves), degrees.
    pub start_deg: Option<f64>,
    /// What the plan assumed about the device (`start angle 0 deg`), if anything.
    pub assumed: Option<String>,
    /// Notes for a human (what the frames do, what the joint must be in).
    pub notes: Vec<String>,
}

/// The work mode that a servo loop needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ServoLoop {
    /// Position targets, degrees.
    Position,
    /// Speed targets, RPM.
    Speed,
    /// Current targets, mA.
    Current,
}

impl ServoLoop {
    /// The work mode this loop needs.
    pub const fn mode(self) -> WorkMode {
        match self {
            Self::Position => WorkMode::Position,
            Self::Speed => WorkMode::Speed,
            Self::Current => WorkMode::Current,
        }
    }

    /// The unit of its values.
    pub const fn unit(self) -> &'static str {
        match self {
            Self::Position => "deg",
            Self::Speed => "RPM",
            Self::Current => "mA",
        }
    }
}

/// A work mode as the CLI and the reports name it.
pub const fn mode_name(m: WorkMode) -> &'static str {
    match m {
        WorkMode::OpenLoop => "open-loop",
        WorkMode::Current => "current",
        WorkMode::Speed => "speed",
        WorkMode::Position => "position",
        WorkMode::Unknown(_) => "unknown",
    }
}

fn whj(e: WhjError) -> OpError {
    OpError::Whj(e)
}

/// Waits on the bus's clock until `deadline` unless stopped first; `false` when stopped.
fn pause_until(bus: &JointBus, control: &Control<'_>, deadline: Instant) -> bool {
    control.sleep_with(deadline, |until| {
        if let Some(t) = until {
            bus.sleep_until(t);
        }
        bus.now()
    })
}

fn per_joint<T>(
    ids: &[JointId],
    mut f: impl FnMut(JointId) -> Result<T, OpError>,
) -> Vec<DeviceResult<u8, T>> {
    ids.iter()
        .map(|&id| match f(id) {
            Ok(v) => DeviceResult::ok(id.get(), v),
            Err(e) => DeviceResult::failed(id.get(), Failure::from(&e)),
        })
        .collect()
}

// ---------------------------------------------------------------------------------------
// Status, enable, clear, set-id
// ---------------------------------------------------------------------------------------

/// One joint's status (`whj status`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StatusReport {
    /// Drive enabled.
    pub enabled: bool,
    /// Work mode.
    pub mode: &'static str,
    /// Actual position, degrees.
    pub position_deg: f64,
    /// Actual current, mA (`None` in the 12-byte layout).
    pub current_ma: Option<i64>,
    /// Bus voltage, V.
    pub voltage_v: f64,
    /// Temperature, °C.
    pub temperature_c: f64,
    /// `locked` or `released`.
    pub brake: &'static str,
    /// Error bits.
    pub error: String,
}

/// Reads the status of one connected joint; an implausible reading ([`check_reading`]) is a
/// device failure naming it.
pub fn joint_status(j: &Joint<'_>) -> Result<StatusReport, OpError> {
    let st = j.status().map_err(whj)?;
    check_reading(j, st.position.degrees(), None)?;
    let mode = j.mode().map_err(whj)?;
    let scale = j
        .identity()
        .map_or(CurrentScale::OneMilliamp, |i| i.current_scale());
    Ok(StatusReport {
        enabled: st.is_enabled(),
        mode: mode_name(mode),
        position_deg: st.position.degrees(),
        current_ma: st.current.map(|c| c.milliamps(scale)),
        voltage_v: f64::from(st.voltage.volts()),
        temperature_c: f64::from(st.temperature.celsius()),
        brake: if st.brake_locked() {
            "locked"
        } else {
            "released"
        },
        error: st.error.to_string(),
    })
}

/// `whj status`: connects the joints (IAP releases pipelined, [`JointBus::joints`]) and
/// reads each one's status; a silent joint is a failed result, the others are still read.
pub fn status(bus: &JointBus, ids: &[JointId]) -> Vec<DeviceResult<u8, StatusReport>> {
    let mut joints = bus.joints(ids).into_iter();
    per_joint(ids, |_| {
        let j = joints
            .next()
            .unwrap_or(Err(WhjError::Closed))
            .map_err(whj)?;
        joint_status(&j)
    })
}

/// The state a joint reports after enable / disable.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct EnableReport {
    /// Drive enabled, as the joint reports it afterwards.
    pub enabled: bool,
    /// Error bits afterwards.
    pub error: String,
}

/// `whj enable` / `whj disable`: writes the enable register, then reads the state back; a
/// joint that stays in the wrong state, or reports error bits after an enable, is a failed
/// result naming the bits.
pub fn enable(bus: &JointBus, ids: &[JointId], on: bool) -> Vec<DeviceResult<u8, EnableReport>> {
    per_joint(ids, |id| {
        let j = bus.joint(id).map_err(whj)?;
        if on { j.enable() } else { j.disable() }.map_err(whj)?;
        let st = j.status().map_err(whj)?;
        if st.is_enabled() != on {
            return Err(OpError::Device(format!(
                "{id}: still {} after {} (error bits: {})",
                if on { "disabled" } else { "enabled" },
                if on { "enable" } else { "disable" },
                st.error
            )));
        }
        if on && !st.error.is_empty() {
            return Err(OpError::Device(format!(
                "{id}: enabled, but reports error bits: {} (clear them with `whj clear`)",
                st.error
            )));
        }
        Ok(EnableReport {
            enabled: st.is_enabled(),
            error: st.error.to_string(),
        })
    })
}

/// The error bits before and after `whj clear`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct ClearReport {
    /// Error bits before the clear.
    pub error_before: String,
    /// Error bits left afterwards (bits whose cause persists stay set).
    pub error_after: String,
}

/// `whj clear`: reads the error bits, clears, reads them again.
pub fn clear(bus: &JointBus, ids: &[JointId]) -> Vec<DeviceResult<u8, ClearReport>> {
    per_joint(ids, |id| {
        let j = bus.joint(id).map_err(whj)?;
        let before: ErrorCode = j.error_code().map_err(whj)?;
        let after = j.clear_error().map_err(whj)?;
        Ok(ClearReport {
            error_before: before.to_string(),
            error_after: after.to_string(),
        })
    })
}

/// Whether any joint answers at `id`: the IAP release (`IAP_FLAG := 0`), which a joint
/// answers in its bootloader and in its application, sent up to three times.
pub fn answers(bus: &JointBus, id: JointId) -> Result<bool, OpError> {
    for _ in 0..3 {
        match bus.request(Request::start_application(id)) {
            Ok(_) => return Ok(true),
            Err(e) if e.is_timeout() => {}
            Err(e) => return Err(whj(e)),
        }
    }
    Ok(false)
}

/// What `whj set-id` did.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct SetIdReport {
    /// The new ID.
    pub new_id: u8,
    /// `SYS_ID` as read back after the write.
    pub read_back: u8,
    /// The ID the read-back was answered at: the old one (the new ID applies after a power
    /// cycle), or the new one (firmware that applies it at once).
    pub answered_at: u8,
    /// Saved to flash.
    pub saved: bool,
    /// When it applies.
    pub note: &'static str,
}

/// The plan of `whj set-id`: the frames [`set_id`] sends (at the old ID; a joint whose
/// firmware applies the ID at once gets the read-back and the save at the new one) and
/// the note that says so.
pub fn plan_set_id(id: JointId, new_id: JointId) -> Result<(Vec<Request>, String), OpError> {
    let sys_id = robobus_whj::registers::addr::SYS_ID;
    let frames = vec![
        Request::enable(id, false),
        Request::write(id, sys_id, u16::from(new_id.get()))
            .map_err(|e| OpError::invalid("<NEW_ID>", new_id.get(), e.to_string()))?,
        Request::Read {
            joint: id,
            range: robobus_whj::ReadRange::new(sys_id, 1)
                .map_err(|e| OpError::invalid("<NEW_ID>", new_id.get(), e.to_string()))?,
        },
        Request::save_to_flash(id),
    ];
    let note = format!(
        "disable, write SYS_ID, read it back, save; the new ID {n} applies after a power cycle \
         (firmware V1.1 applies it at once: the read-back and the save then go to ID {n})",
        n = new_id.get()
    );
    Ok((frames, note))
}

/// `whj set-id`: refused while a joint answers at the new ID (two joints would share it
/// after the next power cycle); otherwise disable, write `SYS_ID`, save to flash.
pub fn set_id(bus: &JointBus, id: JointId, new_id: JointId) -> Result<SetIdReport, OpError> {
    if new_id == id {
        return Err(OpError::invalid(
            "set-id <NEW_ID>",
            new_id.get(),
            "the joint already has this ID",
        ));
    }
    check_id_free(bus, id, new_id)?;
    let j = bus.joint(id).map_err(whj)?;
    j.disable().map_err(whj)?;
    j.write_register_raw("SYS_ID", i32::from(new_id.get()))
        .map_err(whj)?;
    // Read back: at the old ID (the new one applies after a power cycle), or at the new
    // one where the firmware applies it at once.
    let (at, read_back) = match j.read_words(robobus_whj::registers::addr::SYS_ID, 1) {
        Ok(w) => (j, w),
        Err(e) if e.is_timeout() => {
            let k = bus.joint_unchecked(new_id);
            let w = k
                .read_words(robobus_whj::registers::addr::SYS_ID, 1)
                .map_err(whj)?;
            (k, w)
        }
        Err(e) => return Err(whj(e)),
    };
    let read_back = read_back.first().copied().unwrap_or(0);
    if read_back != u16::from(new_id.get()) {
        return Err(OpError::Device(format!(
            "set-id {} {}: SYS_ID reads back {read_back} at ID {}; the ID did not take (not \
             saved)",
            id.get(),
            new_id.get(),
            at.id().get()
        )));
    }
    at.save_to_flash().map_err(whj)?;
    Ok(SetIdReport {
        new_id: new_id.get(),
        read_back: u8::try_from(read_back).unwrap_or(u8::MAX),
        answered_at: at.id().get(),
        saved: true,
        note: "the new ID applies after a power cycle of the joint",
    })
}

/// Refuses an ID change of joint `id` to `new_id` while a joint answers at `new_id` (two
/// joints would share it after the next power cycle); nothing is sent to joint `id`.
pub fn check_id_free(bus: &JointBus, id: JointId, new_id: JointId) -> Result<(), OpError> {
    if answers(bus, new_id)? {
        return Err(OpError::Refused(format!(
            "set-id {} {}: a joint answers at ID {} already; after the next power cycle two \
             joints would share it. Give that joint another ID first; nothing was sent to \
             joint {}",
            id.get(),
            new_id.get(),
            new_id.get(),
            id.get()
        )));
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Safe state
// ---------------------------------------------------------------------------------------

/// After a stop: the joint to `safe` ([`SafeState::apply`]), then [`OpError::Interrupted`]
/// saying what it did.
fn interrupted(j: &Joint<'_>, safe: SafeState, servo: ServoLoop) -> OpError {
    safe.interrupted(&mut WhjJoints {
        joints: core::slice::from_ref(j),
        servo,
    })
}

// ---------------------------------------------------------------------------------------
// Checks before motion
// ---------------------------------------------------------------------------------------

/// Refuses unless the joint is enabled in the loop's work mode (nothing is sent).
pub fn require_ready(j: &Joint<'_>, servo: ServoLoop, what: &str) -> Result<(), OpError> {
    let id = j.id().get();
    let want = servo.mode();
    let mode = j.mode().map_err(whj)?;
    if mode != want {
        return Err(OpError::Refused(format!(
            "joint {id} is in {} mode; {what} needs {} mode: run `robobus whj mode {id} {}` \
             first; nothing sent",
            mode_name(mode),
            mode_name(want),
            mode_name(want)
        )));
    }
    if !j.is_enabled().map_err(whj)? {
        return Err(OpError::Refused(format!(
            "joint {id} is disabled; run `robobus whj enable {id}` first; nothing sent"
        )));
    }
    Ok(())
}

/// Checks that `lo..=hi` (in the loop's unit) is within what this joint allows: angles
/// within its position limits (0x44..0x47), speeds within its model's peak output speed,
/// currents within its current limit (0x40, when it holds a value).
pub fn check_demand(j: &Joint<'_>, servo: ServoLoop, lo: f64, hi: f64) -> Result<(), OpError> {
    let id = j.id().get();
    let worst = lo.abs().max(hi.abs());
    match servo {
        ServoLoop::Position => {
            let (min, max) = j.position_limits().map_err(whj)?;
            let (min, max) = (min.degrees(), max.degrees());
            if lo < min || hi > max {
                let asked = if lo < min { lo } else { hi };
                return Err(OpError::invalid(
                    "angle",
                    format!("{asked} deg"),
                    format!(
                        "outside joint {id}'s position limits {min}..={max} deg (registers \
                         0x44..0x47)"
                    ),
                ));
            }
        }
        ServoLoop::Speed => {
            let model = j.identity().map_err(whj)?.model;
            if let Some(peak) = model.peak_output_speed_rpm()
                && worst > peak
            {
                return Err(OpError::invalid(
                    "speed",
                    format!("{worst} RPM"),
                    format!(
                        "beyond joint {id}'s peak output speed: -{peak}..={peak} RPM ({model}, \
                         product parameters)"
                    ),
                ));
            }
        }
        ServoLoop::Current => {
            let limit = j
                .read_register("LIT_MAX_CURRENT")
                .map_err(whj)?
                .value
                .filter(|v| *v > 0.0);
            if let Some(limit) = limit
                && worst > limit
            {
                return Err(OpError::invalid(
                    "current",
                    format!("{worst} mA"),
                    format!(
                        "beyond joint {id}'s current limit: -{limit}..={limit} mA (register \
                         0x40 LIT_MAX_CURRENT)"
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// How far outside its limits a joint may read before the reading counts as implausible,
/// degrees (a joint may overshoot a limit slightly).
pub const LIMIT_SLACK_DEG: f64 = 1.0;

/// How far beyond its model's peak output speed a joint may read before the reading
/// counts as implausible (a joint back-driven by a load can exceed its peak a little).
pub const SPEED_SLACK: f64 = 1.5;

/// The one plausibility rule for what a joint reports (status, monitor samples, broadcast
/// feedback, the feedback of every timed run): a finite position within its position limits
/// `limits` (degrees) plus [`LIMIT_SLACK_DEG`], and a speed within [`SPEED_SLACK`] times its
/// model's peak output speed. `None` if the reading is plausible, else what is wrong with it.
pub fn reading_fault(
    position_deg: f64,
    limits: (f64, f64),
    speed: Option<(f64, robobus_whj::units::Model)>,
) -> Option<String> {
    let (min, max) = limits;
    if !(position_deg.is_finite()
        && position_deg >= min - LIMIT_SLACK_DEG
        && position_deg <= max + LIMIT_SLACK_DEG)
    {
        return Some(format!(
            "position {position_deg:.4} deg is outside its position limits {min}..={max} deg: \
             the reading is implausible"
        ));
    }
    speed.and_then(|(rpm, model)| speed_fault(rpm, model))
}

/// The speed half of [`reading_fault`].
fn speed_fault(rpm: f64, model: robobus_whj::units::Model) -> Option<String> {
    let peak = model.peak_output_speed_rpm()?;
    (!(rpm.is_finite() && rpm.abs() <= peak * SPEED_SLACK)).then(|| {
        format!(
            "speed {rpm:.3} RPM is beyond {SPEED_SLACK} times its peak output speed of {peak} \
             RPM ({model}): the reading is implausible"
        )
    })
}

/// Checks a reading of joint `j` with [`reading_fault`], against the position limits the
/// bus knows ([`Joint::known_position_limits`]: read once, again after a write that can
/// change them) and its model. An implausible reading is a *device* failure that names
/// the value; it is never reported as the joint's state.
pub fn check_reading(
    j: &Joint<'_>,
    position_deg: f64,
    speed_rpm: Option<f64>,
) -> Result<(), OpError> {
    let (min, max) = j.known_position_limits().map_err(whj)?;
    let model = j.identity().ok().map(|i| i.model);
    let speed = speed_rpm.zip(model);
    match reading_fault(position_deg, (min.degrees(), max.degrees()), speed) {
        None => Ok(()),
        Some(fault) => Err(OpError::Device(format!("joint {}: {fault}", j.id().get()))),
    }
}

/// Reads the present position and checks it is plausible: within the joint's position
/// limits, read now (plus [`LIMIT_SLACK_DEG`]). A move is never planned from an implausible
/// reading.
pub fn plausible_position(j: &Joint<'_>) -> Result<f64, OpError> {
    let at = j.status().map_err(whj)?.position.degrees();
    let (min, max) = j.position_limits().map_err(whj)?;
    if let Some(fault) = reading_fault(at, (min.degrees(), max.degrees()), None) {
        return Err(OpError::Device(format!(
            "joint {}: present {fault} (or the joint is out of range); no move planned, \
             nothing sent",
            j.id().get()
        )));
    }
    Ok(at)
}

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
    if !(rate_hz.is_finite() && (1.0..=1000.0).contains(&rate_hz)) {
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
    args.validate()?;
    let limits = args.limits();
    let points =
        Profile::plan(from_deg, args.target_deg, limits, MAX_MOVE_FRAMES).ok_or_else(|| {
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
#[derive(Debug, Clone, PartialEq, Serialize)]
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
    /// Error bits after the move.
    pub error: String,
}

/// The plan a real move runs: checks the joint (enabled in position mode, the target within
/// its limits, the present position plausible), then plans from the measured position.
pub fn prepare_move(j: &Joint<'_>, args: &MoveArgs) -> Result<Plan, OpError> {
    args.validate()?;
    require_ready(j, ServoLoop::Position, "move")?;
    check_demand(j, ServoLoop::Position, args.target_deg, args.target_deg)?;
    let from = plausible_position(j)?;
    plan_move(args, from, false)
}

/// When a planned frame went out and how long its exchange took.
#[derive(Debug, Clone, Copy)]
struct FrameTimes {
    /// How late after its planned time the frame was handed to the bus.
    late: Duration,
    /// From handing the frame to the bus to its feedback (`None`: no feedback came).
    round_trip: Option<Duration>,
}

/// The joint's position limits in degrees (what feedback is checked against).
fn degree_limits(j: &Joint<'_>) -> Result<(f64, f64), OpError> {
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
    let plan = prepare_move(j, args)?;
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
    let Ok(sent) = stream::send_frames(j, plan, control, &watch, |_, _, _| {})? else {
        return Err(interrupted(j, on_stop, ServoLoop::Position));
    };
    let limits = args.limits();
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
        error: status.error.to_string(),
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

/// Largest |angle| a wave may ask for, degrees.
pub const WAVE_MAX_DEG: f64 = 360.0;
/// Largest |speed| a wave may ask for, RPM.
pub const WAVE_MAX_RPM: f64 = 37.5;
/// Largest |current| a wave may ask for, mA.
pub const WAVE_MAX_MA: f64 = 30_000.0;
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
            ServoLoop::Position => WAVE_MAX_DEG,
            ServoLoop::Speed => WAVE_MAX_RPM,
            ServoLoop::Current => WAVE_MAX_MA,
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

/// Plans a wave: one servo frame per period. Position waves start at `from_deg` and go
/// through the step limiter ([`WAVE_LIMITS`] at the wave's rate), so a square wave becomes
/// steep ramps and no frame steps beyond the step limit; speed and current waves are sent
/// as requested. `scale` converts mA to counts (the joint's model).
pub fn plan_wave(
    args: &WaveArgs,
    from_deg: f64,
    scale: CurrentScale,
    assumed: bool,
) -> Result<Plan, OpError> {
    args.validate()?;
    let period = Duration::from_secs_f64(1.0 / args.rate_hz);
    let dt = period.as_secs_f64();
    let mut profile = Profile::new(
        from_deg,
        MotionLimits {
            period,
            // Never a frame beyond the step limit, however low the rate.
            max_speed_deg_s: WAVE_LIMITS
                .max_speed_deg_s
                .min(args.step_limit_deg * args.rate_hz),
            ..WAVE_LIMITS
        },
    );
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
        let request = match args.servo {
            ServoLoop::Position => {
                let v = profile.step(want, dt);
                Request::PositionServo {
                    joint,
                    target: Position::from_degrees(v).map_err(bad)?,
                }
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
            " (position frames go through the step limiter: at most 180 deg/s, 3000 deg/s^2)"
        } else {
            ""
        }
    ));
    Ok(plan)
}

/// The last feedback of a wave.
#[derive(Debug, Clone, PartialEq, Serialize)]
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
#[derive(Debug, Clone, PartialEq, Serialize)]
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
    /// Position set-points the step limiter changed from the requested value.
    pub clamped: u64,
    /// RMS of (measured − requested), in the loop's unit (`None` without replies).
    pub tracking_rms: Option<f64>,
    /// Largest |measured − requested|.
    pub tracking_max: Option<f64>,
    /// The unit of the tracking values.
    pub unit: &'static str,
    /// The last feedback that came (`None` when none came).
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
    let plan = prepare_wave(j, args)?;
    let report = execute_wave(j, args, &plan, control, on_stop)?;
    Ok((plan, report))
}

/// The plan a real wave runs (see [`run_wave`]).
pub fn prepare_wave(j: &Joint<'_>, args: &WaveArgs) -> Result<Plan, OpError> {
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
    plan_wave(args, from, scale, false)
}

/// Runs a prepared wave plan (see [`run_wave`]).
pub fn execute_wave(
    j: &Joint<'_>,
    args: &WaveArgs,
    plan: &Plan,
    control: &mut Control<'_>,
    on_stop: SafeState,
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
        tracking_rms: None,
        tracking_max: None,
        unit: args.servo.unit(),
        last: None,
        stale: false,
        missing_at_end: 0,
        round_trip_p50_us: None,
        round_trip_p99_us: None,
        round_trip_max_us: None,
    };
    for (f, want) in plan.frames.iter().zip(&targets) {
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
            r.clamped += 1;
        }
    }
    let (mut sq, mut max, mut n) = (0.0f64, 0.0f64, 0u64);
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
    let outcome = stream::send_frames(j, plan, control, &watch, |k, fb, times| {
        let late = times.late;
        round_trips.extend(times.round_trip);
        let now = bus.now();
        if k > 0 && now.duration_since(last_sent) > period * 2 {
            r.overruns += 1;
        }
        last_sent = now;
        r.cycles += 1;
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
            let e = (got - want).abs();
            sq += e * e;
            max = max.max(e);
            n += 1;
        }
        r.last = Some(FeedbackReport::of(fb, scale));
    })?;
    if outcome.is_err() {
        return Err(interrupted(j, on_stop, args.servo));
    }
    if n > 0 {
        #[allow(clippy::cast_precision_loss)]
        let rms = (sq / n as f64).sqrt();
        r.tracking_rms = Some(rms);
        r.tracking_max = Some(max);
    }
    if !round_trips.is_empty() {
        let p = Percentiles::of(&round_trips);
        let us = |d: Duration| u64::try_from(d.as_micros()).unwrap_or(u64::MAX);
        r.round_trip_p50_us = Some(us(p.p50));
        r.round_trip_p99_us = Some(us(p.p99));
        r.round_trip_max_us = Some(us(p.max));
    }
    Ok(r)
}

// ---------------------------------------------------------------------------------------
// Scan, info, modes, zero, save, release-IAP
// ---------------------------------------------------------------------------------------

/// A joint's identity (`whj scan`, `whj info`, `whj release-iap`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct IdentityReport {
    /// Model name.
    pub model: &'static str,
    /// Firmware version (four hex digits).
    pub firmware: String,
    /// Node ID register.
    pub node_id: u16,
    /// Gear reduction ratio.
    pub reduction: u16,
    /// 96-bit unique ID.
    pub unique_id: String,
}

impl IdentityReport {
    /// The report of an identity.
    pub fn of(i: &crate::whj::Identity) -> Self {
        Self {
            model: i.model.name(),
            firmware: i.firmware.to_string(),
            node_id: i.node_id,
            reduction: i.reduction_ratio,
            unique_id: i.unique_id.to_string(),
        }
    }
}

/// Two joints answering at one ID (two different unique IDs 0x2A..0x2F to one read).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Duplicate {
    /// The shared ID.
    pub id: u8,
    /// The unique IDs that answered.
    pub unique_ids: [String; 2],
}

/// What `whj scan` found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScanReport {
    /// Joints that answered, in ID order.
    pub found: Vec<DeviceResult<u8, IdentityReport>>,
    /// IDs that more than one joint answers.
    pub duplicates: Vec<Duplicate>,
    /// IDs probed.
    pub probed: usize,
    /// Set when the scan was stopped before its last ID (`found` holds what it found
    /// until then): how far it got.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stopped: Option<String>,
}

/// Reads of the unique ID [`duplicates_of`] makes after the connect's own read.
const DUPLICATE_PROBES: usize = 3;

/// Whether more than one joint answers at `id` (already connected on `bus`): reads the
/// unique ID (0x2A..0x2F). Two joints at one ID both answer each read, the second within
/// the bus's collision window ([`JointBusConfig::collision_window`]), so the read fails
/// with [`WhjError::DuplicateReply`] and the bus records both unique IDs
/// ([`JointTelemetry::unique_id_conflict`]) on the first read already; the further reads
/// only matter without a collision window. `doctor` calls this too.
///
/// [`JointTelemetry::unique_id_conflict`]: crate::whj::JointTelemetry::unique_id_conflict
/// [`JointBusConfig::collision_window`]: crate::whj::JointBusConfig::collision_window
pub fn duplicates_of(bus: &JointBus, id: JointId) -> Option<Duplicate> {
    let j = bus.joint_unchecked(id);
    for _ in 0..DUPLICATE_PROBES {
        if bus.telemetry().joint(id).unique_id_conflict.is_some() {
            break;
        }
        let read = j.read_words(robobus_whj::registers::addr::MOT_MODEL_ID, 6);
        if matches!(read, Err(WhjError::DuplicateReply { .. })) {
            break;
        }
        if bus.config().collision_window.is_zero() {
            // The second joint's reply comes after the first one's.
            bus.sleep_until(bus.now() + Duration::from_millis(5));
        }
    }
    conflict_of(bus, id)
}

/// The two unique IDs the bus has seen answer at `id`, if it saw two.
fn conflict_of(bus: &JointBus, id: JointId) -> Option<Duplicate> {
    bus.telemetry()
        .joint(id)
        .unique_id_conflict
        .map(|(a, b)| Duplicate {
            id: id.get(),
            unique_ids: [a.to_string(), b.to_string()],
        })
}

/// How long a scan waits for joints to answer their IAP release: a joint in its
/// bootloader answers at once, so an absent ID costs this, not the bus's connect timeout
/// (which allows for joints still powering up).
pub const SCAN_CONNECT_TIMEOUT: Duration = Duration::from_millis(150);

/// `whj scan`: connects every ID at once (IAP releases pipelined, then identify;
/// [`SCAN_CONNECT_TIMEOUT`] is what the absent IDs cost, once for all of them) and checks
/// each joint found for a second joint at its ID. IDs that stay silent are left out of
/// `found`; other failures are kept. Stopped by `control`, it returns what it found so
/// far with [`ScanReport::stopped`] set.
pub fn scan(
    bus: &JointBus,
    ids: &[JointId],
    control: &mut Control<'_>,
) -> Result<ScanReport, OpError> {
    let mut report = ScanReport {
        found: Vec::new(),
        duplicates: Vec::new(),
        probed: ids.len(),
        stopped: None,
    };
    let stopped_after = |k: usize| Some(format!("scan stopped after {k} of {} IDs", ids.len()));
    if control.stopped() {
        report.stopped = stopped_after(0);
        return Ok(report);
    }
    control.report(&Progress::new("scan", 0, Some(ids.len() as u64)).with_note("connecting"));
    let connected = bus.joints_within(ids, SCAN_CONNECT_TIMEOUT);
    for (k, (&id, joint)) in ids.iter().zip(connected).enumerate() {
        if control.stopped() {
            report.stopped = stopped_after(k);
            return Ok(report);
        }
        control.report(
            &Progress::new("scan", k as u64, Some(ids.len() as u64))
                .with_note(format!("J{}", id.get())),
        );
        match joint {
            Ok(j) => {
                let ident = j.identity().map_err(whj)?;
                report
                    .found
                    .push(DeviceResult::ok(id.get(), IdentityReport::of(&ident)));
                if let Some(d) = duplicates_of(bus, id) {
                    report.duplicates.push(d);
                }
            }
            Err(e) if e.is_timeout() => {}
            Err(e) => {
                // Two joints at the ID fail its connect with a duplicate reply: named in
                // the duplicates as well as in the joint's failure.
                if matches!(e, WhjError::DuplicateReply { .. })
                    && let Some(d) = conflict_of(bus, id).or_else(|| duplicates_of(bus, id))
                {
                    report.duplicates.push(d);
                }
                report
                    .found
                    .push(DeviceResult::failed(id.get(), Failure::from(&e)));
            }
        }
    }
    control.report(&Progress::new(
        "scan",
        ids.len() as u64,
        Some(ids.len() as u64),
    ));
    Ok(report)
}

/// `whj info`: identity, mode and position limits.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct InfoReport {
    /// Identity.
    #[serde(flatten)]
    pub identity: IdentityReport,
    /// Work mode.
    pub mode: &'static str,
    /// Lower position limit, degrees.
    pub min_deg: f64,
    /// Upper position limit, degrees.
    pub max_deg: f64,
}

/// `whj info` of one joint.
pub fn info(bus: &JointBus, id: JointId) -> Result<InfoReport, OpError> {
    let j = bus.joint(id).map_err(whj)?;
    let ident = j.identity().map_err(whj)?;
    let (min, max) = j.position_limits().map_err(whj)?;
    let mode = j.mode().map_err(whj)?;
    Ok(InfoReport {
        identity: IdentityReport::of(&ident),
        mode: mode_name(mode),
        min_deg: min.degrees(),
        max_deg: max.degrees(),
    })
}

/// The work mode a joint reports after `whj mode`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct ModeReport {
    /// Work mode read back.
    pub mode: &'static str,
}

/// `whj mode`: sets the mode, reads it back (a joint that reports another mode fails).
pub fn set_mode(
    bus: &JointBus,
    ids: &[JointId],
    mode: WorkMode,
) -> Vec<DeviceResult<u8, ModeReport>> {
    per_joint(ids, |id| {
        let j = bus.joint(id).map_err(whj)?;
        j.set_mode(mode).map_err(whj)?;
        let now = j.mode().map_err(whj)?;
        if now != mode {
            return Err(OpError::Device(format!(
                "{id}: reports {} mode after the change to {}",
                mode_name(now),
                mode_name(mode)
            )));
        }
        Ok(ModeReport {
            mode: mode_name(now),
        })
    })
}

/// The position after `whj zero`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ZeroReport {
    /// Position read after the zero, degrees.
    pub position_deg: f64,
}

/// `whj zero`: the present position becomes 0 deg.
pub fn zero(bus: &JointBus, id: JointId) -> Result<ZeroReport, OpError> {
    let j = bus.joint(id).map_err(whj)?;
    j.set_zero().map_err(whj)?;
    Ok(ZeroReport {
        position_deg: j.position().map_err(whj)?.degrees(),
    })
}

/// `whj save`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct SaveReport {
    /// Saved.
    pub saved: bool,
}

/// `whj save`: copies RAM to flash (refused while a joint is enabled).
pub fn save(bus: &JointBus, ids: &[JointId]) -> Vec<DeviceResult<u8, SaveReport>> {
    per_joint(ids, |id| {
        let j = bus.joint(id).map_err(whj)?;
        j.save_to_flash().map_err(whj)?;
        Ok(SaveReport { saved: true })
    })
}

/// `whj release-iap`: starts the application of joints in the bootloader.
pub fn release_iap(bus: &JointBus, ids: &[JointId]) -> Vec<DeviceResult<u8, IdentityReport>> {
    per_joint(ids, |id| {
        let j = bus.joint_unchecked(id);
        j.release_iap().map_err(whj)?;
        Ok(IdentityReport::of(&j.identity().map_err(whj)?))
    })
}

// ---------------------------------------------------------------------------------------
// Registers
// ---------------------------------------------------------------------------------------

/// One register value (`whj read`, `whj write`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RegisterReport {
    /// Address, `0x14`.
    pub addr: String,
    /// Name (a pair by its name without `_L`), or `(reserved)`.
    pub register: &'static str,
    /// Raw value.
    pub raw: i64,
    /// Value in its unit, where the register has a fixed scale.
    pub value: Option<f64>,
    /// Unit symbol.
    pub unit: &'static str,
}

fn register_report(v: &crate::whj::RegisterValue) -> RegisterReport {
    let info = v.info;
    let name = if info.half == robobus_whj::registers::Half::Low {
        info.name.strip_suffix("_L").unwrap_or(info.name)
    } else {
        info.name
    };
    RegisterReport {
        addr: format!("0x{:02X}", info.addr.get()),
        register: name,
        raw: i64::from(v.raw),
        value: v.value,
        unit: v.unit,
    }
}

/// `whj read`: a register (a pair as one value) by name with its unit when `count` is
/// `None` and the address is a documented register, else `count` raw words.
pub fn read_registers(
    bus: &JointBus,
    id: JointId,
    addr: robobus_whj::RegisterAddr,
    count: Option<u8>,
) -> Result<Vec<RegisterReport>, OpError> {
    let j = bus.joint(id).map_err(whj)?;
    let info = robobus_whj::RegisterInfo::by_addr(addr);
    if let (Some(info), None) = (info, count) {
        let v = j.read_register(info.name).map_err(whj)?;
        check_register_reading(&j, &v)?;
        return Ok(vec![register_report(&v)]);
    }
    let words = j.read_words(addr, count.unwrap_or(1)).map_err(whj)?;
    Ok(word_reports(addr, &words))
}

/// The plausibility rule ([`reading_fault`]) for a register read by name: the actual
/// position (`CUR_POSITION`) against the joint's limits, the actual speed (`CUR_SPEED`)
/// against its model's peak. Other registers are reported as read.
fn check_register_reading(j: &Joint<'_>, v: &crate::whj::RegisterValue) -> Result<(), OpError> {
    use robobus_whj::registers::addr as reg;
    let Some(value) = v.value else {
        return Ok(());
    };
    if v.info.addr == reg::CUR_POSITION {
        check_reading(j, value, None)
    } else if v.info.addr == reg::CUR_SPEED
        && let Some(model) = j.identity().ok().map(|i| i.model)
        && let Some(fault) = speed_fault(value, model)
    {
        Err(OpError::Device(format!("joint {}: {fault}", j.id().get())))
    } else {
        Ok(())
    }
}

/// Raw words read from `addr` on, one report each (named where the table names them).
fn word_reports(addr: robobus_whj::RegisterAddr, words: &[u16]) -> Vec<RegisterReport> {
    (addr.get()..)
        .zip(words)
        .map(|(k, &w)| RegisterReport {
            addr: format!("0x{k:02X}"),
            register: robobus_whj::RegisterAddr::new(k)
                .ok()
                .and_then(robobus_whj::RegisterInfo::by_addr)
                .map_or("(reserved)", |i| i.name),
            raw: i64::from(w),
            value: None,
            unit: "",
        })
        .collect()
}

/// Checks a register write against the register's safety class
/// ([`robobus_whj::registers::safety_class`]): motion targets and `never` registers are
/// refused with the reason (and the command to use); `confirm` registers need
/// `confirmed` (the CLI's `--yes` or its prompt). Returns the text of what a `confirm`
/// write does, if it is one.
pub fn check_write(
    addr: robobus_whj::RegisterAddr,
    confirmed: bool,
) -> Result<Option<&'static str>, OpError> {
    use robobus_whj::registers::SafetyClass;
    let name = robobus_whj::RegisterInfo::by_addr(addr).map_or("(reserved)", |i| i.name);
    match robobus_whj::registers::safety_class(addr) {
        SafetyClass::Plain => Ok(None),
        SafetyClass::Confirm(what) if confirmed => Ok(Some(what)),
        SafetyClass::Confirm(what) => Err(OpError::Refused(format!(
            "write {name} ({:#04x}) {what}; confirm with --yes; nothing was sent",
            addr.get()
        ))),
        SafetyClass::Motion(why) | SafetyClass::Never(why) => Err(OpError::Refused(format!(
            "write {name} ({:#04x}) refused: {why}; nothing was sent",
            addr.get()
        ))),
    }
}

/// The safety class of the register a request writes, if it is a confirm write: what it
/// does (for a front end's confirmation prompt).
/// A broadcast register frame: the first confirm write among its slots, or the end
/// board's write ([`END_BOARD_WRITE_TEXT`]).
pub fn confirm_text(request: &Request) -> Option<&'static str> {
    use robobus_whj::{RegisterOp, RegisterSlot};
    let of = |addr| match robobus_whj::registers::safety_class(addr) {
        robobus_whj::registers::SafetyClass::Confirm(what) => Some(what),
        _ => None,
    };
    match request {
        Request::Write { addr, .. } => of(*addr),
        Request::BroadcastRegister(b) => b
            .slots
            .iter()
            .find_map(|s| match s {
                RegisterSlot::Op(RegisterOp::Write { addr, .. }) => of(*addr),
                _ => None,
            })
            .or_else(|| {
                matches!(
                    robobus_whj::EndBoardOp::decode(&b.end_board),
                    Some(robobus_whj::EndBoardOp::Write { .. })
                )
                .then_some(broadcast::END_BOARD_WRITE_TEXT)
            }),
        _ => None,
    }
}

/// The checks of a register write that depend on the joint: a register whose feature its
/// product or firmware lacks (the register table's firmware gates,
/// [`robobus_whj::registers::gated_write_allowed`]) and position limits that would end up
/// inverted (min > max) are refused before anything is sent.
pub fn check_joint_write(
    j: &Joint<'_>,
    addr: robobus_whj::RegisterAddr,
    data: robobus_whj::request::WriteData,
) -> Result<(), OpError> {
    let joint = j.id();
    let identity = j.identity().map_err(whj)?;
    if let Err(refusal) =
        robobus_whj::registers::gated_write_allowed(addr, identity.model, identity.firmware)
    {
        return Err(OpError::Refused(format!(
            "{joint}: {refusal}; the write was not sent"
        )));
    }
    let min_addr = robobus_whj::registers::addr::LIT_MIN_POSITION;
    let max_addr = robobus_whj::registers::addr::LIT_MAX_POSITION;
    if let robobus_whj::request::WriteData::Pair(v) = data
        && (addr == min_addr || addr == max_addr)
    {
        let (min, max) = j.position_limits().map_err(whj)?;
        let (lo, hi) = if addr == min_addr {
            (v, max.raw())
        } else {
            (min.raw(), v)
        };
        if lo > hi {
            return Err(OpError::Refused(format!(
                "{joint}: position limits would be inverted: min {} deg > max {} deg; nothing \
                 was sent",
                Position(lo).degrees(),
                Position(hi).degrees()
            )));
        }
    }
    Ok(())
}

/// `whj write`: sends the planned write request (the one a dry run prints) after
/// [`check_write`], refuses a register the joint's model or firmware lacks
/// ([`robobus_whj::registers::gated_write_allowed`]) and position limits that would end up
/// inverted (min > max), and reads the register back.
pub fn write_register(
    bus: &JointBus,
    request: Request,
    confirmed: bool,
) -> Result<Vec<RegisterReport>, OpError> {
    let Request::Write { joint, addr, data } = request else {
        return Err(OpError::invalid(
            "write",
            format!("{request:?}"),
            "not a register write",
        ));
    };
    check_write(addr, confirmed)?;
    let j = bus.joint(joint).map_err(whj)?;
    check_joint_write(&j, addr, data)?;
    match data {
        robobus_whj::request::WriteData::Pair(v) => j.write_i32(addr, v),
        robobus_whj::request::WriteData::Word(w) => j.write_word(addr, w),
        robobus_whj::request::WriteData::Byte(b) => j.write_word(addr, u16::from(b)),
    }
    .map_err(whj)?;
    let count = match data {
        robobus_whj::request::WriteData::Pair(_) => Some(2),
        _ => None,
    };
    match robobus_whj::RegisterInfo::by_addr(addr) {
        Some(_) => read_registers(bus, joint, addr, None),
        None => read_registers(bus, joint, addr, count.or(Some(1))),
    }
}

// ---------------------------------------------------------------------------------------
// Speed and current targets
// ---------------------------------------------------------------------------------------

/// A speed or current target (`whj speed`, `whj current`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetArgs {
    /// The joint.
    pub joint: JointId,
    /// [`ServoLoop::Speed`] (RPM) or [`ServoLoop::Current`] (mA).
    pub servo: ServoLoop,
    /// The target, in the loop's unit.
    pub value: f64,
    /// How long to keep it; then target 0 (also on stop). `None`: the joint keeps it.
    pub duration: Option<Duration>,
}

/// What a speed or current target did.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TargetReport {
    /// The feedback to the target frame.
    #[serde(flatten)]
    pub feedback: FeedbackReport,
    /// Whether the joint still runs the target (no `--duration`).
    pub keeps_running: bool,
    /// What to do about it, or what was done.
    pub note: String,
}

/// The frame of a target.
pub fn target_request(args: &TargetArgs, scale: CurrentScale) -> Result<Request, OpError> {
    Ok(match args.servo {
        ServoLoop::Speed => Request::SpeedServo {
            joint: args.joint,
            target: TargetSpeed::from_rpm(args.value)
                .map_err(|e| OpError::invalid("<RPM>", args.value, e.to_string()))?,
        },
        ServoLoop::Current => Request::CurrentServo {
            joint: args.joint,
            target: Current::from_milliamps(args.value, scale)
                .map_err(|e| OpError::invalid("<MILLIAMPS>", args.value, e.to_string()))?,
        },
        ServoLoop::Position => {
            return Err(OpError::invalid("target", "position", "use a move"));
        }
    })
}

/// How often a timed speed or current target reads the joint's status while it runs.
pub const TARGET_POLL: Duration = Duration::from_millis(50);

/// Sends a speed or current target after checking the joint is enabled in that mode and
/// the value within its bounds. With a duration: runs it (stoppable), reading the joint's
/// status every [`TARGET_POLL`], then sends target 0. Error bits, a disabled drive or an
/// implausible reading (at any point, the last feedback included) stop it in the safe
/// state as a *device* error; a joint that stops answering as *no device*. On stop:
/// `on_stop`.
pub fn run_target(
    j: &Joint<'_>,
    args: &TargetArgs,
    control: &mut Control<'_>,
    on_stop: SafeState,
) -> Result<TargetReport, OpError> {
    let what = match args.servo {
        ServoLoop::Speed => "speed",
        _ => "current",
    };
    require_ready(j, args.servo, what)?;
    check_demand(j, args.servo, args.value, args.value)?;
    let scale = j.identity().map_err(whj)?.current_scale();
    let request = target_request(args, scale)?;
    let fb = j.servo_request(request).map_err(whj)?;
    let id = j.id().get();
    let Some(duration) = args.duration else {
        #[allow(clippy::float_cmp)]
        let idle = args.value == 0.0;
        return Ok(TargetReport {
            feedback: FeedbackReport::of(&fb, scale),
            keeps_running: !idle,
            note: if idle {
                format!("{what} target 0")
            } else {
                format!(
                    "the joint keeps this {what} target until told otherwise: stop it with \
                     `robobus whj {what} {id} 0` or `robobus whj disable {id}`"
                )
            },
        });
    };
    let watch = stream::Watch {
        servo: args.servo,
        on_stop,
        limits: degree_limits(j)?,
        step_limit_deg: j.bus().config().step_limit_deg,
        stage: what,
    };
    stream::check_feedback(j, &watch, &fb, "after the target frame")?;
    let bus = j.bus();
    let end = bus.now() + duration;
    loop {
        let now = bus.now();
        if now >= end {
            break;
        }
        if !pause_until(bus, control, end.min(now + TARGET_POLL)) {
            return Err(interrupted(j, on_stop, args.servo));
        }
        stream::check_status(j, &watch)?;
    }
    let zero = TargetArgs {
        value: 0.0,
        ..*args
    };
    let fb = match j.servo_request(target_request(&zero, scale)?) {
        Ok(fb) => fb,
        Err(e) => return Err(stream::stop_with(j, &watch, whj(e))),
    };
    stream::check_feedback(j, &watch, &fb, "at the end")?;
    Ok(TargetReport {
        feedback: FeedbackReport::of(&fb, scale),
        keeps_running: false,
        note: format!("{what} target 0 after {} s", duration.as_secs_f64()),
    })
}

/// The write request for `value` into the register at `addr` (in the register's unit, or
/// counts with `raw`), converting units (`scale`: the joint's current LSB). The request a
/// dry run prints and [`write()`] sends.
pub fn write_request(
    joint: JointId,
    addr: robobus_whj::RegisterAddr,
    value: f64,
    raw: bool,
    scale: CurrentScale,
) -> Result<Request, OpError> {
    use robobus_whj::registers::{Half, Unit};
    let info = robobus_whj::RegisterInfo::by_addr(addr);
    let name = info.map_or("reserved register", |i| i.name);
    let option = format!("write {name} <VALUE>");
    if !value.is_finite() {
        return Err(OpError::invalid(option, value, "not a finite number"));
    }
    let unit = info.map_or(Unit::Raw, |i| i.unit);
    let per_count = if raw {
        1.0
    } else {
        match unit {
            Unit::Current => f64::from(scale.ma_per_count()),
            Unit::SpeedLimit => {
                return Err(OpError::invalid(
                    format!("write {name}"),
                    value,
                    "its unit depends on the firmware (0.01 RPM or 1/ratio RPM, conflict C3); \
                     give the value in counts with --raw",
                ));
            }
            other => other.scale().unwrap_or(1.0),
        }
    };
    let counts = (value / per_count).round();
    if (counts - value / per_count).abs() > 1e-6 && (raw || unit.scale().is_none()) {
        return Err(OpError::invalid(
            option,
            value,
            "not a whole number of counts",
        ));
    }
    if counts < f64::from(i32::MIN) || counts > f64::from(i32::MAX) {
        return Err(OpError::invalid(
            option,
            value,
            format!("{counts} counts, outside the 32-bit range"),
        ));
    }
    #[allow(clippy::cast_possible_truncation)] // checked just above
    let counts = counts as i32;
    let bad = |e: robobus_whj::RequestError| {
        OpError::invalid("write <REGISTER> <VALUE>", value, e.to_string())
    };
    if info.map(|i| i.half) == Some(Half::Low) {
        return Request::write_i32(joint, addr, counts).map_err(bad);
    }
    let word = u16::try_from(counts).map_err(|_| {
        OpError::invalid(
            option.clone(),
            value,
            format!("{counts} counts is out of range 0..=65535 for a 16-bit register"),
        )
    })?;
    Request::write(joint, addr, word).map_err(bad)
}

/// Whether a register's value depends on the joint's current scale (mA registers).
pub fn needs_current_scale(addr: robobus_whj::RegisterAddr, raw: bool) -> bool {
    !raw && robobus_whj::RegisterInfo::by_addr(addr)
        .is_some_and(|i| i.unit == robobus_whj::registers::Unit::Current)
}

/// `whj write` by value: [`write_request`] with `scale` or (when `None`) the joint's own
/// current scale, then [`write_register`].
pub fn write(
    bus: &JointBus,
    joint: JointId,
    addr: robobus_whj::RegisterAddr,
    value: f64,
    raw: bool,
    scale: Option<CurrentScale>,
    confirmed: bool,
) -> Result<Vec<RegisterReport>, OpError> {
    check_write(addr, confirmed)?;
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // 1..=30 checked
    if addr == robobus_whj::registers::addr::SYS_ID
        && value.fract() == 0.0
        && (1.0..=30.0).contains(&value)
        && let Ok(new_id) = JointId::new(value as u8)
        && new_id != joint
    {
        // The same rule as `set-id`: never an ID that another joint answers at.
        check_id_free(bus, joint, new_id)?;
    }
    let scale = match scale {
        Some(s) => s,
        None if needs_current_scale(addr, raw) => bus
            .joint(joint)
            .map_err(whj)?
            .identity()
            .map_err(whj)?
            .current_scale(),
        None => CurrentScale::OneMilliamp,
    };
    write_register(
        bus,
        write_request(joint, addr, value, raw, scale)?,
        confirmed,
    )
}

// ---------------------------------------------------------------------------------------
// Monitor sampling
// ---------------------------------------------------------------------------------------

/// One sample of one joint (`robobus monitor`): a status query and a speed read.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct JointSample {
    /// Actual position, degrees.
    pub position_deg: f64,
    /// Actual speed, RPM (`None` when the speed read failed).
    pub speed_rpm: Option<f64>,
    /// Actual current, mA (`None` in the 12-byte status layout).
    pub current_ma: Option<i64>,
    /// Drive enabled.
    pub enabled: bool,
    /// Error bits.
    pub error: String,
}

/// Samples joints once each, without the connect handshake (the bus caches identities, so
/// a sample costs two frames per joint). A joint that does not answer is a failed result:
/// the caller marks it missing, never shows older values as this sample's.
pub fn sample(bus: &JointBus, ids: &[JointId]) -> Vec<DeviceResult<u8, JointSample>> {
    per_joint(ids, |id| {
        let j = bus.joint_unchecked(id);
        let scale = j
            .identity()
            .map_or(CurrentScale::OneMilliamp, |i| i.current_scale());
        let st = j.status().map_err(whj)?;
        let speed_rpm = j.speed().ok().map(robobus_whj::units::ActualSpeed::rpm);
        check_reading(&j, st.position.degrees(), speed_rpm)?;
        Ok(JointSample {
            position_deg: st.position.degrees(),
            speed_rpm,
            current_ma: st.current.map(|c| c.milliamps(scale)),
            enabled: st.is_enabled(),
            error: st.error.to_string(),
        })
    })
}

// ---------------------------------------------------------------------------------------
// Broadcast frames (0x7F status, 0x0F registers, sampling)
// ---------------------------------------------------------------------------------------

mod broadcast;
mod stream;

pub use stream::{FOLLOW_STEPS, SILENT_AFTER, SILENT_FRAMES, check_plan_steps};

pub use broadcast::{
    BROADCAST_WAVE_MIN_HZ, BroadcastPlan, END_BOARD_WRITE_TEXT, EndBoardArg, EndBoardStatus,
    SECOND_ANSWER_GUARD, Slot, StatusWithEndBoard, broadcast_read, broadcast_status,
    broadcast_status_with_end_board, broadcast_window, broadcast_write, connect_for_broadcast,
    plan_broadcast_read, plan_broadcast_wave, plan_broadcast_write, prepare_broadcast_wave,
    reply_mask, reply_mask_with, run_broadcast_plan, sample_broadcast,
};
