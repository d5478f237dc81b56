//! Register reads and writes, and speed and current targets.

use std::time::Duration;

use robobus_whj::units::{Current, CurrentScale, Position, TargetSpeed};
use robobus_whj::{JointId, Request};
use serde::Serialize;

use crate::ops::{Control, OpError, SafeState};
use crate::whj::{Joint, JointBus};

use super::{
    FeedbackReport, ServoLoop, check_demand, check_id_free, check_reading, degree_limits,
    interrupted, pause_until, require_ready, speed_fault, stream, whj,
};

// ---------------------------------------------------------------------------------------
// Registers
// ---------------------------------------------------------------------------------------

/// One register value (`whj read`, `whj write`).
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
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

pub(super) fn register_report(v: &crate::whj::RegisterValue) -> RegisterReport {
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
pub(super) fn word_reports(addr: robobus_whj::RegisterAddr, words: &[u16]) -> Vec<RegisterReport> {
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

/// What an end-board write does, for a confirmation prompt.
pub const END_BOARD_WRITE_TEXT: &str =
    "switches what is attached to the tool (power, IO, Modbus) through the end board";

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
                .then_some(END_BOARD_WRITE_TEXT)
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
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
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
            Unit::SpeedLimit => {
                return Err(OpError::invalid(
                    format!("write {name}"),
                    value,
                    "its unit depends on the firmware (0.01 RPM or 1/ratio RPM, conflict C3); \
                     give the value in counts with --raw",
                ));
            }
            other => other.per_count(scale).unwrap_or(1.0),
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
