//! The safe state of an interrupted run, and the checks before any motion.

use crate::ops::safe::WhjJoints;
use crate::ops::{OpError, SafeState};
use crate::whj::Joint;

use super::{ServoLoop, mode_name, whj};

// ---------------------------------------------------------------------------------------
// Safe state
// ---------------------------------------------------------------------------------------

/// After a stop: the joint to `safe` ([`SafeState::apply`]), then [`OpError::Interrupted`]
/// saying what it did.
pub(super) fn interrupted(j: &Joint<'_>, safe: SafeState, servo: ServoLoop) -> OpError {
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
pub(super) fn speed_fault(rpm: f64, model: robobus_whj::units::Model) -> Option<String> {
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
