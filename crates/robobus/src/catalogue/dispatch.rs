//! The one dispatcher: [`plan`] and [`run`] of every [`Request`].

use std::time::Duration;

use robobus_wck::{BaudRate, Command};
use robobus_whj::REGISTERS;
use serde::Serialize;
use serde_json::{Map, Value, json};

use super::bounds::{ConfirmClass, refused};
use super::plan::Plan;
use super::{Family, Report, Request, wck, whj};
use crate::ops::wck as wops;
use crate::ops::whj as hops;
use crate::ops::{Control, DeviceResult, ErrorKind, Failure, OpError, worst_kind};
use crate::station::{Station, WckPort, WhjPort};
use crate::whj::JointBus;

/// Frames without a reply at the end of a wave after which the joint counts as gone (a
/// no-device failure): one lost reply is a glitch, ten in a row at the end a silent joint.
pub const GONE_AFTER: u64 = 10;

/// The plan of `request`: the exact packets / frames a run sends (its text form is what
/// the CLI's `--dry-run` prints), validated against the protocol's ranges and the host
/// bounds. Nothing is opened; the wCK packets are shown at 115200 bit/s (`wck.scan`
/// scans at that rate).
pub fn plan(request: &Request) -> Result<Plan, OpError> {
    plan_at(request, BaudRate::B115200)
}

/// Validates `request` as [`run`] will, without a station: its arguments against the
/// protocol's ranges and the host bounds. (A plan of a WHJ current target needs the
/// joint's model; a run reads it from the joint, so this does not ask for it.)
pub fn validate(request: &Request) -> Result<(), OpError> {
    match request.family() {
        Family::Wck => wck::prepare(request, BaudRate::B115200).map(drop),
        Family::Whj => whj::prepare(request, false).map(drop),
        Family::Robot => match request {
            Request::RobotCalibrate(r) => r.readings().map(drop),
            Request::RobotTeleop(r) => r.check(),
            Request::RobotPlay(r) => r.check().map(drop),
            Request::RobotTeach(r) => r.readings().map(drop),
            _ => Ok(()),
        },
        Family::Host => Ok(()),
    }
}

/// What `request` needs confirmed before it runs (the text a front end asks the user,
/// the CLI's prompt), validated as [`run`] validates it; `None` when it runs without
/// confirmation or carries `confirm: true` already.
pub fn confirmation(request: &Request) -> Result<Option<String>, OpError> {
    Ok(match request.family() {
        Family::Wck => {
            let p = wck::prepare(request, BaudRate::B115200)?;
            (p.confirm != ConfirmClass::None && !p.confirmed)
                .then(|| wck::confirm_text(p.confirm).to_owned())
        }
        Family::Whj => {
            let p = whj::prepare(request, false)?;
            (p.confirm != ConfirmClass::None && !p.confirmed).then_some(p.confirm_text)
        }
        Family::Robot => match request {
            Request::RobotTeach(r) => {
                r.readings()?;
                (!r.confirm).then(|| super::teach::TEACH_CONFIRM.to_owned())
            }
            _ => None,
        },
        Family::Host => None,
    })
}

/// [`plan`] with the wCK packets shown at `baud` (the rate of the port a run would use;
/// `wck.scan` starts there). WHJ plans do not depend on it.
pub fn plan_at(request: &Request, baud: BaudRate) -> Result<Plan, OpError> {
    let op = request.op();
    Ok(match request.family() {
        Family::Wck => {
            let p = wck::prepare(request, baud)?;
            let mut plan = Plan::wck(&op, &p.plan, baud);
            plan.confirm = p.confirm;
            plan.confirm_text =
                (p.confirm != ConfirmClass::None).then(|| wck::confirm_text(p.confirm).to_owned());
            plan.truncated = matches!(p.job, wck::Job::Play(..))
                && p.plan.steps.len() >= super::plan::MAX_PLAN_STEPS;
            plan
        }
        Family::Whj => {
            let p = whj::prepare(request, true)?;
            let mut plan = Plan::whj(&op, &p.plan);
            plan.confirm = p.confirm;
            plan.confirm_text = (p.confirm != ConfirmClass::None).then(|| p.confirm_text.clone());
            plan
        }
        Family::Robot => {
            let note = match request {
                Request::RobotCalibrate(r) => r.note()?,
                Request::RobotTeleop(r) => r.note()?,
                Request::RobotPlay(r) => r.note()?,
                Request::RobotTeach(r) => r.note()?,
                _ => ROBOT_SAMPLE_NOTE.into(),
            };
            let mut plan = Plan::notes_only(&op, Family::Robot, vec![note]);
            if let Request::RobotTeach(_) = request {
                // Limp joints: asked like a register of the `confirm` class.
                plan.confirm = ConfirmClass::Register;
                plan.confirm_text = Some(super::teach::TEACH_CONFIRM.to_owned());
            }
            plan
        }
        Family::Host => {
            Plan::notes_only(&op, Family::Host, vec![super::host::PORTS_NOTE.to_owned()])
        }
    })
}

/// What an interactive operation asks of its front end while it runs (today: `wck.teach`
/// by events, and each pose as it is recorded). The defaults suit a front end with no
/// user at hand: no events (a recording by events then runs until the stop token), the
/// poses kept in the report's summary.
pub trait Interaction {
    /// `wck.teach` by events: waits at most `wait` for the user's next action.
    fn teach_event(&mut self, wait: Duration) -> wops::TeachEvent {
        std::thread::sleep(wait);
        wops::TeachEvent::Nothing
    }

    /// `wck.teach`: a pose was recorded (an error ends the recording, the servos in their
    /// `on_stop` state).
    #[allow(clippy::result_large_err)] // OpError carries the client errors by value
    fn pose(&mut self, pose: &wops::Pose) -> Result<(), OpError> {
        let _ = pose;
        Ok(())
    }

    /// `robot.play`: one tick was sent (a front end records it; an error ends the run
    /// where it is).
    #[allow(clippy::result_large_err)] // OpError carries the client errors by value
    fn play_tick(&mut self, tick: &super::play::PlayTick<'_>) -> Result<(), OpError> {
        let _ = tick;
        Ok(())
    }

    /// Whether the report's summary lists every pose (`false`: only their count, for a
    /// front end that writes them elsewhere as they come).
    fn keep_poses(&self) -> bool {
        true
    }
}

/// The [`Interaction`] of a front end without one: the defaults.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoInteraction;

impl Interaction for NoInteraction {}

/// Runs `request` on the station's bus it names (or the station's only bus of the
/// family): validates and plans it, refuses it when it needs confirmation and lacks it
/// ([`ErrorKind::Refused`], nothing sent), then executes the plan through the operation
/// of [`crate::ops`] with `control`'s stop token and progress. Device failures are in the
/// report (`failed`); an error is a failure of the whole request.
pub fn run(
    station: &Station,
    request: &Request,
    control: &mut Control<'_>,
) -> Result<Report, OpError> {
    run_with(station, request, control, &mut NoInteraction)
}

/// [`run`] with a front end's [`Interaction`] (key presses and live poses of a teach).
pub fn run_with(
    station: &Station,
    request: &Request,
    control: &mut Control<'_>,
    interaction: &mut dyn Interaction,
) -> Result<Report, OpError> {
    let op = request.op();
    match request.family() {
        Family::Wck => {
            // A program check sends nothing: it needs no port.
            if matches!(request, Request::WckProgramCheck(_)) {
                let p = wck::prepare(request, BaudRate::B115200)?;
                if let wck::Job::Check(program, id) = p.job {
                    return Ok(check_report(&op, request.bus().unwrap_or(""), program, id));
                }
            }
            let port = station.wck(request.bus())?;
            let baud = port.lock().baud();
            let p = wck::prepare(request, baud)?;
            if p.confirm != ConfirmClass::None && !p.confirmed {
                return Err(refused(wck::confirm_text(p.confirm)));
            }
            run_wck(&port, &op, p, control, interaction)
        }
        Family::Whj => {
            let p = whj::prepare(request, false)?;
            if p.confirm != ConfirmClass::None && !p.confirmed {
                return Err(refused(&p.confirm_text));
            }
            if matches!(p.job, whj::Job::Registers) {
                return Ok(registers_report(&op));
            }
            if matches!(p.job, whj::Job::CanHealth) {
                return can_health_report(station, request.bus(), &op);
            }
            let port = station.whj(request.bus())?;
            run_whj(&port, &op, &p, control)
        }
        Family::Robot => match request {
            Request::RobotCalibrate(r) => {
                let c = super::robot::run_calibrate(station, r, control)?;
                let mut report = device_report(&op, "robot", &c.joints);
                report.summary = Some(json!({
                    "readings": c.taken,
                    "interrupted": c.taken < c.asked,
                }));
                Ok(report)
            }
            Request::RobotPlay(r) => {
                let p =
                    super::play::run_play(station, r, control, &mut |t| interaction.play_tick(t))?;
                let mut report = device_report(&op, "robot", &p.joints);
                report.summary = serde_json::to_value(&p.summary).ok();
                Ok(report)
            }
            Request::RobotTeach(r) => {
                let t = super::teach::run_teach(station, r, control)?;
                let mut report = device_report(&op, "robot", &t.joints);
                report.summary = Some(json!({
                    "trajectory": t.trajectory,
                    "points": t.points,
                    "dropped": t.dropped,
                    "readings": t.asked,
                    "interrupted": t.interrupted,
                }));
                Ok(report)
            }
            Request::RobotTeleop(r) => {
                let t = super::teleop::run_teleop(station, r, control)?;
                let mut report = device_report(&op, "robot", &t.joints);
                report.summary = serde_json::to_value(&t.summary).ok();
                // The leader's silence fails the run (no-device), whatever the follower did.
                if let Some(lost) = t.lost {
                    report.failed = Some(lost.kind.name().to_owned());
                    report.error = Some(match report.error.take() {
                        Some(e) => format!("{}; {e}", lost.error),
                        None => lost.error,
                    });
                }
                Ok(report)
            }
            _ => robot_report(station, &op),
        },
        // Nothing of the station is used: the host's own serial ports.
        Family::Host => super::host::ports_report(&op),
    }
}

/// `whj.can-health` on the station's WHJ bus `bus`: its interface is the bus's address
/// (`can0`) or, for a robot file's bus, the file's `iface`. A bus without one (UDP, a
/// simulator) is a row without a controller that says so.
#[cfg(not(target_os = "linux"))]
fn can_health_report(station: &Station, bus: Option<&str>, _op: &str) -> Result<Report, OpError> {
    let port = station.whj(bus)?;
    Err(OpError::NotAvailable(format!(
        "whj.can-health on {}: a CAN controller's state is read from Linux's SocketCAN \
         (netlink) only; on this system run `robobus whj monitor` on the bus (an adapter's \
         bus-off, error-passive and overruns show there) or `robobus doctor`",
        port.name()
    )))
}

/// `whj.can-health` on the station's WHJ bus `bus`: its interface is the bus's address
/// (`can0`) or, for a robot file's bus, the file's `iface`. A bus without one (UDP, a
/// simulator) is a row without a controller that says so.
#[cfg(target_os = "linux")]
fn can_health_report(station: &Station, bus: Option<&str>, op: &str) -> Result<Report, OpError> {
    use robobus_link::socketcan::health::{self, HealthError};
    let port = station.whj(bus)?;
    let name = port.name();
    let iface = port.can_interface().map(str::to_owned);
    let none = || {
        json!({
            "id": name,
            "kind": Value::Null,
            "state": Value::Null,
            "advice": format!(
                "{name} is not a CAN interface (a UDP or simulated bus): it has no CAN \
                 controller"
            ),
        })
    };
    let row = match iface.as_deref().map(health::read) {
        None | Some(Err(HealthError::NoSuchInterface(_) | HealthError::BadName(_))) => none(),
        Some(Err(e)) => {
            return Err(OpError::Device(format!(
                "{}: {e}",
                iface.as_deref().unwrap_or(name)
            )));
        }
        Some(Ok(h)) => {
            let mut row = serde_json::to_value(&h).unwrap_or(Value::Null);
            row["advice"] = h.advice().map_or(Value::Null, Value::from);
            // Classic CAN (CAN FD off): WHJ joints cannot hear it; the advice says how.
            row["classic"] = Value::from(h.classic());
            row["id"] = Value::from(h.iface.clone());
            row
        }
    };
    Ok(report(op, name, vec![row]))
}

/// `whj.end-board`: one row, `end-board`: what the board answered, or its failure.
fn end_board_report(
    bus: &JointBus,
    op: &str,
    name: &str,
    job: super::whj::end_board::EndBoardJob,
) -> Report {
    use super::whj::end_board::EndBoardJob as E;
    use crate::ops::whj::broadcast::end_board as eb;
    let json = |v: &dyn erased::Ser| serde_json::to_value(erased::Wrap(v)).unwrap_or(Value::Null);
    let value = match job {
        E::Status => eb::state(bus).map(|s| json(&s)),
        E::Power(p) => eb::set_power(bus, p).map(|s| json(&s)),
        E::Io(c, out) => eb::set_io(bus, c, out).map(|s| json(&s)),
        E::Force => eb::force(bus).map(|s| json(&s)),
    };
    let result = match value {
        Ok(v) => DeviceResult::ok("end-board", v),
        Err(e) => DeviceResult::failed("end-board", Failure::from(&e)),
    };
    device_report(op, name, &[result])
}

/// What a `robot.sample` reads (its frames depend on the station's robot file).
const ROBOT_SAMPLE_NOTE: &str = "reads every joint of the station's robot file, read-only: a \
     status read per wCK servo (FF <0xA0|ID> 00 <checksum>), a status query (0x600+ID) and a \
     speed register read per WHJ joint; a real run first connects each WHJ joint once";

/// `robot.sample` on the station's robot file: one row per joint, by name.
fn robot_report(station: &Station, op: &str) -> Result<Report, OpError> {
    let results = station.sample_robot().ok_or_else(|| {
        OpError::invalid(
            "robot",
            "(none)",
            "the station has no robot file (open it with --robot FILE.toml)",
        )
    })??;
    Ok(device_report(op, "robot", &results))
}

/// A row: `id` first, then the value's fields.
fn row(id: impl Serialize, value: &impl Serialize) -> Value {
    let mut r = Map::new();
    r.insert("id".into(), json!(id));
    if let Ok(Value::Object(fields)) = serde_json::to_value(value) {
        for (k, v) in fields {
            r.insert(k, v);
        }
    }
    Value::Object(r)
}

pub(super) fn report(op: &str, bus: &str, results: Vec<Value>) -> Report {
    Report {
        op: op.to_owned(),
        bus: bus.to_owned(),
        results,
        summary: None,
        failed: None,
        error: None,
    }
}

/// Per-device results as rows, with the worst failure.
fn device_report<I: Serialize, T: Serialize>(
    op: &str,
    bus: &str,
    results: &[DeviceResult<I, T>],
) -> Report {
    let mut r = report(
        op,
        bus,
        results
            .iter()
            .map(|d| serde_json::to_value(d).unwrap_or(Value::Null))
            .collect(),
    );
    fail_with(
        &mut r,
        worst_kind(results),
        results
            .iter()
            .filter_map(|d| d.failure().map(|f| f.error.clone())),
    );
    r
}

fn fail_with(r: &mut Report, kind: Option<ErrorKind>, messages: impl Iterator<Item = String>) {
    if let Some(k) = kind {
        r.failed = Some(k.name().to_owned());
        let text: Vec<String> = messages.collect();
        r.error = Some(text.join("; "));
    }
}

fn summary(value: &impl Serialize) -> Option<Value> {
    serde_json::to_value(value).ok()
}

// ----- wCK -----

#[allow(clippy::too_many_lines)] // one arm per job
fn run_wck(
    port: &WckPort,
    op: &str,
    p: wck::Prepared,
    control: &mut Control<'_>,
    interaction: &mut dyn Interaction,
) -> Result<Report, OpError> {
    let name = port.name().to_owned();
    let mut guard = port.lock();
    let bus = &mut *guard;
    Ok(match p.job {
        wck::Job::Steps(action) => {
            let saved = bus.config_mut().confirm_reads;
            bus.config_mut().confirm_reads = wck::confirm_reads_for(&p.plan, port.verify_reads());
            let result = wops::run_steps(bus, action, &p.plan, control);
            bus.config_mut().confirm_reads = saved;
            device_report(op, &name, &result?.results)
        }
        wck::Job::Scan(args) => {
            let r = wops::scan(bus, &args, control)?;
            let mut out = report(
                op,
                &name,
                r.found
                    .iter()
                    .map(|f| serde_json::to_value(f).unwrap_or(Value::Null))
                    .collect(),
            );
            out.summary = Some(json!({
                "bauds_tried": r.bauds_tried,
                "duplicates": r.duplicates,
            }));
            if let Some(why) = &r.stopped {
                // What it found before the stop stays in the report.
                out.failed = Some(ErrorKind::Interrupted.name().into());
                out.error = Some(format!("{name}: {why}"));
            } else if !r.duplicates.is_empty() {
                // As whj.scan: an ID that more than one module answers is a device fault.
                let ids: Vec<String> = r
                    .duplicates
                    .iter()
                    .map(|d| format!("ID {} at {} bit/s", d.id, d.baud))
                    .collect();
                out.failed = Some(ErrorKind::Device.name().into());
                out.error = Some(format!(
                    "{name}: more than one module answers at {}; give each module its own ID",
                    ids.join(", ")
                ));
            } else if r.is_empty() {
                let rates: Vec<String> = args.bauds.iter().map(ToString::to_string).collect();
                out.failed = Some(ErrorKind::NoDevice.name().into());
                out.error = Some(format!(
                    "{name}: no servo answered at any of the scanned IDs ({}) at {}; check \
                     power, wiring and the baud rate (--all-bauds tries every rate)",
                    wops::ids_text(&args.ids),
                    rates.join(", ")
                ));
            }
            out
        }
        wck::Job::Tune(args) => {
            let r = wops::tune::tune(bus, &args, p.confirmed, control)?;
            let rows = r
                .responses
                .iter()
                .map(|x| {
                    json!({
                        "id": args.id.get(),
                        "p": x.p,
                        "d": x.d,
                        "rise_ms": x.rise_ms,
                        "overshoot_pct": x.overshoot_pct,
                        "settling_ms": x.settling_ms,
                        "steady_state_error": x.steady_state_error,
                    })
                })
                .collect();
            let mut out = report(op, &name, rows);
            out.summary = summary(&r);
            out
        }
        wck::Job::Wheel(args) => {
            let r = wops::wheel(bus, &args, control)?;
            device_report(op, &name, std::slice::from_ref(&r))
        }
        wck::Job::Teach(args) => {
            let keep = interaction.keep_poses();
            let mut poses = Vec::new();
            let mut count = 0u64;
            let result = {
                let cell = std::cell::RefCell::new(&mut *interaction);
                let mut events = |wait| cell.borrow_mut().teach_event(wait);
                let mut on_pose = |pose: &wops::Pose| {
                    count += 1;
                    if keep {
                        poses.push(pose.clone());
                    }
                    cell.borrow_mut().pose(pose)
                };
                wops::teach(bus, &args, control, &mut events, &mut on_pose)
            };
            // The poses recorded before a stop or a failure are the report's still.
            let mut out = report(op, &name, Vec::new());
            if let Err(e) = result {
                out.failed = Some(e.kind().name().to_owned());
                out.error = Some(e.to_string());
            }
            let mut summary = json!({
                "ids": args.ids.iter().map(|i| i.get()).collect::<Vec<_>>(),
                "torque": args.torque.get(),
                "recorded": count,
            });
            if keep && let Value::Object(m) = &mut summary {
                m.insert("poses".into(), json!(poses));
            }
            out.summary = Some(summary);
            out
        }
        wck::Job::Play(motion, rate, safe) => {
            let r = wops::play(bus, &motion, rate, safe, control)?;
            let mut out = report(op, &name, Vec::new());
            out.summary = summary(&r);
            out
        }
        wck::Job::Check(program, id) => check_report(op, &name, program, id),
        job @ (wck::Job::Backup(_) | wck::Job::Diff(..) | wck::Job::Restore(..)) => {
            wck_settings(bus, op, &name, job)?
        }
        wck::Job::Sample(ids) => {
            let mut sampler = crate::ops::monitor::WckSampler::new(&ids);
            let results = sampler.sample(bus, 0.0);
            device_report(op, &name, &results)
        }
    })
}

/// `wck.backup`, `wck.diff` and `wck.restore` on a locked bus.
fn wck_settings<L: robobus_link::ByteLink>(
    bus: &mut crate::wck::WckBus<L>,
    op: &str,
    name: &str,
    job: wck::Job,
) -> Result<Report, OpError> {
    let name = name.to_owned();
    Ok(match job {
        wck::Job::Backup(id) => {
            let s = wops::settings::backup(bus, id)?;
            let mut out = report(op, &name, vec![row(id.get(), &s)]);
            out.summary = summary(&s);
            out
        }
        wck::Job::Diff(id, with) => {
            let a = wops::settings::backup(bus, id)?;
            let (b, of) = match with {
                wck::WckDiffWith::File(s) => (
                    s,
                    s.servo.map_or_else(
                        || "the factory settings".into(),
                        |n| format!("the file (servo {n})"),
                    ),
                ),
                wck::WckDiffWith::Servo(o) => (
                    wops::settings::backup(bus, o)?,
                    format!("servo {}", o.get()),
                ),
            };
            let d = wops::settings::diff(&a, &b);
            let mut out = report(op, &name, d.iter().map(|x| row(id.get(), x)).collect());
            out.summary = Some(json!({ "differ": d.len(), "with": of }));
            out
        }
        wck::Job::Restore(id, s) => {
            let r = wops::settings::restore(bus, id, &s)?;
            let mut out = report(
                op,
                &name,
                r.steps.iter().map(|x| row(id.get(), x)).collect(),
            );
            out.summary = Some(json!({ "written": r.written }));
            out
        }
        // Only the three settings jobs come here (see the caller).
        _ => {
            return Err(OpError::NotAvailable(format!(
                "{op}: not a settings operation"
            )));
        }
    })
}

/// `wck.program.check`: the program's instructions and its upload packet.
fn check_report(
    op: &str,
    bus: &str,
    program: robobus_wck::program::Program,
    id: robobus_wck::ServoId,
) -> Report {
    let packet = Command::MotionWrite { id, program }.encode();
    let instructions: Vec<Value> = program
        .instructions()
        .iter()
        .map(|i| {
            let (c, d) = i.to_pair();
            json!({"text": i.to_string(), "command": c, "data": d})
        })
        .collect();
    let mut out = report(op, bus, Vec::new());
    out.summary = Some(json!({
        "ok": true,
        "instructions": instructions,
        "upload_packet": {"id": id.get(), "hex": packet.to_string(), "bytes": packet.as_bytes()},
    }));
    out
}

// ----- WHJ -----

fn registers_report(op: &str) -> Report {
    let rows = REGISTERS
        .iter()
        .map(|r| {
            let safety = robobus_whj::registers::safety_class(r.addr);
            let note = match safety {
                robobus_whj::registers::SafetyClass::Plain => None,
                robobus_whj::registers::SafetyClass::Confirm(t)
                | robobus_whj::registers::SafetyClass::Motion(t)
                | robobus_whj::registers::SafetyClass::Never(t) => Some(t),
            };
            json!({
                "id": r.addr.get(),
                "name": r.name,
                "unit": r.unit.symbol(),
                "scale": r.unit.scale(),
                "range": r.range.map(|(a, b)| [a, b]),
                "writable": r.access.is_writable(),
                "meaning": r.meaning,
                "safety": safety.keyword(),
                "safety_note": note,
            })
        })
        .collect();
    report(op, "(none)", rows)
}

#[allow(clippy::too_many_lines)] // one arm per operation
fn run_whj(
    port: &WhjPort,
    op: &str,
    p: &whj::Prepared,
    control: &mut Control<'_>,
) -> Result<Report, OpError> {
    use whj::Job as J;
    let name = port.name();
    let bus: &JointBus = port.bus();
    let safe = p.on_stop.into();
    let one = |id: u8, v: &dyn erased::Ser| report(op, name, vec![row(id, &erased::Wrap(v))]);
    Ok(match &p.job {
        J::Scan(ids) => {
            let r = hops::scan(bus, ids, control)?;
            let mut out = device_report(op, name, &r.found);
            out.summary = Some(json!({ "duplicates": r.duplicates, "probed": r.probed }));
            if let Some(why) = &r.stopped {
                // What it found before the stop stays in the report.
                out.failed = Some(ErrorKind::Interrupted.name().into());
                out.error = Some(format!("{name}: {why}"));
            } else if r.found.is_empty() {
                out.failed = Some(ErrorKind::NoDevice.name().into());
                out.error = Some(format!(
                    "no joint answered on IDs {}",
                    ids.iter()
                        .map(|j| j.get().to_string())
                        .collect::<Vec<_>>()
                        .join(",")
                ));
            } else if !r.duplicates.is_empty() && out.failed.is_none() {
                out.failed = Some(ErrorKind::Device.name().into());
                out.error = Some(
                    r.duplicates
                        .iter()
                        .map(|d| {
                            format!(
                                "ID {} is answered by two joints (unique IDs {} and {})",
                                d.id, d.unique_ids[0], d.unique_ids[1]
                            )
                        })
                        .collect::<Vec<_>>()
                        .join("; "),
                );
            }
            out
        }
        J::Info(id) => one(id.get(), &hops::info(bus, *id)?),
        J::Status(ids) => device_report(op, name, &hops::status(bus, ids)),
        J::BroadcastStatus(ids, end_board) => {
            // Connect each joint first (IAP release, identity for the current scale), for
            // one request's reply budget; a silent one is named by the broadcast's result.
            hops::connect_for_broadcast(bus, ids);
            if *end_board {
                let (joints, board) = hops::broadcast_status_with_end_board(bus, ids)?;
                let mut out = device_report(op, name, &joints);
                let b = device_report(op, name, std::slice::from_ref(&board));
                out.results.extend(b.results);
                if out.failed.is_none() {
                    out.failed = b.failed;
                    out.error = b.error;
                }
                out
            } else {
                device_report(op, name, &hops::broadcast_status(bus, ids)?)
            }
        }
        J::Enable(ids, on) => device_report(op, name, &hops::enable(bus, ids, *on)),
        J::Mode(ids, mode) => device_report(op, name, &hops::set_mode(bus, ids, *mode)),
        J::Move(args) => {
            let j = bus.joint(args.joint)?;
            let plan = hops::prepare_move(&j, args)?;
            one(
                args.joint.get(),
                &hops::execute_move(&j, args, &plan, control, safe)?,
            )
        }
        J::Target(args) => {
            let j = bus.joint(args.joint)?;
            one(
                args.joint.get(),
                &hops::run_target(&j, args, control, safe)?,
            )
        }
        J::Zero(id) => one(id.get(), &hops::zero(bus, *id)?),
        J::Clear(ids) => device_report(op, name, &hops::clear(bus, ids)),
        J::Save(ids) => device_report(op, name, &hops::save(bus, ids)),
        J::Read(joints, addr, count, broadcast, end_board) => {
            if *broadcast {
                device_report(
                    op,
                    name,
                    &hops::broadcast_read(bus, joints, *addr, *count, *end_board)?.1,
                )
            } else {
                let mut rows = Vec::new();
                for &j in joints {
                    rows.extend(
                        hops::read_registers(bus, j, *addr, *count)?
                            .iter()
                            .map(|r| row(j.get(), r)),
                    );
                }
                report(op, name, rows)
            }
        }
        J::Write {
            joints,
            addr,
            value,
            raw,
            scale,
            broadcast,
            end_board,
        } => {
            if *broadcast {
                let (_, results) = hops::broadcast_write(
                    bus,
                    joints,
                    *addr,
                    *value,
                    *raw,
                    *scale,
                    *end_board,
                    p.confirmed,
                )?;
                device_report(op, name, &results)
            } else {
                let mut rows = Vec::new();
                for &j in joints {
                    rows.extend(
                        hops::write(bus, j, *addr, *value, *raw, *scale, p.confirmed)?
                            .iter()
                            .map(|r| row(j.get(), r)),
                    );
                }
                report(op, name, rows)
            }
        }
        J::Registers => registers_report(op),
        J::EndBoard(job) => end_board_report(bus, op, name, *job),
        // Run by `can_health_report` before the bus is driven.
        J::CanHealth => report(op, name, Vec::new()),
        J::SetRates(ids, rates) => {
            let results = hops::rates::set_rates(bus, ids, *rates)?;
            let mut out = device_report(op, name, &results);
            // Next steps only for joints that saved new rates: a refused run changed none.
            out.summary =
                hops::rates::next_steps_after(name, port.can_interface(), *rates, &results)
                    .map(|next| json!({ "next": next }));
            out
        }
        J::Backup(id) | J::Defaults(id) => {
            let s = if matches!(p.job, J::Defaults(_)) {
                hops::settings::defaults(bus, *id)?
            } else {
                hops::settings::backup(bus, *id)?
            };
            let mut out = one(
                id.get(),
                &json!({
                    "model": s.model,
                    "firmware": s.firmware,
                    "settings": s.settings.len(),
                }),
            );
            out.summary = summary(&s);
            out
        }
        J::Diff(id, with) => {
            let a = hops::settings::backup(bus, *id)?;
            // Against a file, only the registers it holds: what it leaves out is counted.
            let (d, summary) = match with {
                whj::DiffWith::File(s) => {
                    let (d, left_out) = hops::settings::diff_file(&a, s);
                    let of = format!("the file (joint {})", s.joint);
                    let summary = json!({ "differ": d.len(), "with": of, "left_out": left_out });
                    (d, summary)
                }
                whj::DiffWith::Joint(o) => {
                    let d = hops::settings::diff(&a, &hops::settings::backup(bus, *o)?);
                    let summary =
                        json!({ "differ": d.len(), "with": format!("joint {}", o.get()) });
                    (d, summary)
                }
            };
            let mut out = report(op, name, d.iter().map(|x| row(id.get(), x)).collect());
            out.summary = Some(summary);
            out
        }
        J::Restore(id, s) => {
            let r = hops::settings::restore(bus, *id, s, p.confirmed)?;
            let mut out = report(op, name, r.steps.iter().map(|x| row(id.get(), x)).collect());
            out.summary = Some(json!({
                "written": r.written,
                "saved": r.saved,
                "differ_after": r.differ_after,
            }));
            out
        }
        J::SetId(id, new_id) => one(id.get(), &hops::set_id(bus, *id, *new_id)?),
        J::Wave(args, broadcast) => {
            let j = bus.joint(args.joint)?;
            let plan = if *broadcast {
                hops::prepare_broadcast_wave(&j, args)?
            } else {
                hops::prepare_wave(&j, args)?
            };
            let r = hops::execute_wave(&j, args, &plan, control, safe)?;
            let mut first = match &r.last {
                Some(fb) => row(args.joint.get(), fb),
                None => row(args.joint.get(), &()),
            };
            if let Value::Object(m) = &mut first {
                m.insert("cycles".into(), json!(r.cycles));
                m.insert("stale".into(), json!(r.stale || r.last.is_none()));
            }
            let mut out = report(op, name, vec![first]);
            let mut s = serde_json::to_value(&r).unwrap_or(Value::Null);
            if let Value::Object(m) = &mut s {
                m.remove("last");
            }
            out.summary = Some(s);
            let silent = if r.complete == 0 {
                Some(format!(
                    "joint {}: no reply to any of the {} wave frames",
                    args.joint.get(),
                    r.cycles
                ))
            } else if r.missing_at_end >= GONE_AFTER {
                Some(format!(
                    "joint {}: silent for the last {} wave frames ({} of {} without a reply; the last \
                     values shown are stale)",
                    args.joint.get(),
                    r.missing_at_end,
                    r.missing_replies,
                    r.cycles
                ))
            } else {
                None
            };
            if let Some(e) = silent {
                out.failed = Some(ErrorKind::NoDevice.name().into());
                out.error = Some(e);
            }
            out
        }
        J::ReleaseIap(ids) => {
            let results = hops::release_iap(bus, ids);
            let mut out = device_report(op, name, &results);
            for (r, res) in out.results.iter_mut().zip(&results) {
                if let (Value::Object(m), true) = (r, res.is_ok()) {
                    m.insert("released".into(), json!(true));
                }
            }
            out
        }
        J::Sample(ids, broadcast) => {
            // Joints this bus has not connected yet are connected first (together; a
            // silent one shows in its row), once per station: a telemetry stream does not
            // wait for a silent joint's connect at every sample.
            let _ = bus.joints(&port.untried(ids));
            if *broadcast {
                device_report(op, name, &hops::sample_broadcast(bus, ids)?)
            } else {
                device_report(op, name, &hops::sample(bus, ids))
            }
        }
    })
}

/// `&dyn Serialize` without an extra crate: the rows only need `serde_json::to_value`.
mod erased {
    use serde::Serialize;

    pub(super) trait Ser {
        fn value(&self) -> serde_json::Value;
    }
    impl<T: Serialize> Ser for T {
        fn value(&self) -> serde_json::Value {
            serde_json::to_value(self).unwrap_or(serde_json::Value::Null)
        }
    }
    pub(super) struct Wrap<'a>(pub(super) &'a dyn Ser);
    impl Serialize for Wrap<'_> {
        fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
            self.0.value().serialize(s)
        }
    }
}
