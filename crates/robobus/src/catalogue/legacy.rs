//! The operations not yet in a file of their own: their checks, plans and runs as the
//! catalogue had them, one match per family over [`Request`], and the [`Operation`]
//! impls ([`legacy!`]) that route each such request here. An operation moved into its own
//! file leaves the `legacy!` list (its arms here then go unused and are removed with the
//! family's last one).

use robobus_wck::{BaudRate, Command};
use robobus_whj::REGISTERS;
use serde::Serialize;
use serde_json::{Map, Value, json};

use super::bounds::{ConfirmClass, refused};
use super::operation::{Confirm, Interaction, OpDoc, Operation, Report, RunCx};
use super::plan::Plan;
use super::{Family, Request, wck, whj};
use crate::ops::wck as wops;
use crate::ops::whj as hops;
use crate::ops::{Control, DeviceResult, ErrorKind, Failure, OpError, worst_kind};
use crate::station::{Station, WckPort, WhjPort};
use crate::whj::JointBus;

/// Frames without a reply at the end of a wave after which the joint counts as gone (a
/// no-device failure): one lost reply is a glitch, ten in a row at the end a silent joint.
pub const GONE_AFTER: u64 = 10;

/// What a not-yet-moved request needs confirmed, and whether it carries `confirm: true`.
fn check(request: &Request) -> Result<Confirm, OpError> {
    Ok(match request.family() {
        Family::Wck => {
            let p = wck::prepare(request, BaudRate::B115200)?;
            Confirm::of(p.confirm, wck::confirm_text(p.confirm))
        }
        Family::Whj => {
            let p = whj::prepare(request, false)?;
            Confirm::of(p.confirm, p.confirm_text)
        }
        Family::Robot => match request {
            Request::RobotCalibrate(r) => r.readings().map(|_| Confirm::NONE)?,
            Request::RobotTeleop(r) => r.check().map(|()| Confirm::NONE)?,
            Request::RobotPlay(r) => r.check().map(|_| Confirm::NONE)?,
            Request::RobotTeach(r) => {
                r.readings()?;
                Confirm::of(ConfirmClass::Register, super::teach::TEACH_CONFIRM)
            }
            _ => Confirm::NONE,
        },
        Family::Host => Confirm::NONE,
    })
}

/// The plan of a not-yet-moved request, its wCK packets at `baud`.
fn plan_at(request: &Request, baud: BaudRate) -> Result<Plan, OpError> {
    let op = request.op();
    Ok(match request.family() {
        Family::Wck => {
            let p = wck::prepare(request, baud)?;
            let mut plan = Plan::wck(op, &p.plan, baud);
            plan.confirm = p.confirm;
            plan.confirm_text =
                (p.confirm != ConfirmClass::None).then(|| wck::confirm_text(p.confirm).to_owned());
            plan.truncated = matches!(p.job, wck::Job::Play(..))
                && p.plan.steps.len() >= super::plan::MAX_PLAN_STEPS;
            plan
        }
        Family::Whj => {
            let p = whj::prepare(request, true)?;
            let mut plan = Plan::whj(op, &p.plan);
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
            let mut plan = Plan::notes_only(op, Family::Robot, vec![note]);
            if let Request::RobotTeach(_) = request {
                // Limp joints: asked like a register of the `confirm` class.
                plan.confirm = ConfirmClass::Register;
                plan.confirm_text = Some(super::teach::TEACH_CONFIRM.to_owned());
            }
            plan
        }
        Family::Host => {
            Plan::notes_only(op, Family::Host, vec![super::host::PORTS_NOTE.to_owned()])
        }
    })
}

/// Runs a not-yet-moved request (checked and confirmed already).
fn run_with(
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
                    return Ok(check_report(op, request.bus().unwrap_or(""), program, id));
                }
            }
            let port = station.wck(request.bus())?;
            let baud = port.lock().baud();
            let p = wck::prepare(request, baud)?;
            if p.confirm != ConfirmClass::None && !p.confirmed {
                return Err(refused(wck::confirm_text(p.confirm)));
            }
            run_wck(&port, op, p, control, interaction)
        }
        Family::Whj => {
            let p = whj::prepare(request, false)?;
            if p.confirm != ConfirmClass::None && !p.confirmed {
                return Err(refused(&p.confirm_text));
            }
            if matches!(p.job, whj::Job::Registers) {
                return Ok(registers_report(op));
            }
            if matches!(p.job, whj::Job::CanHealth) {
                return can_health_report(station, request.bus(), op);
            }
            let port = station.whj(request.bus())?;
            run_whj(&port, op, &p, control)
        }
        Family::Robot => match request {
            Request::RobotCalibrate(r) => {
                let c = super::robot::run_calibrate(station, r, control)?;
                let mut report = device_report(op, "robot", &c.joints);
                report.summary = Some(json!({
                    "readings": c.taken,
                    "interrupted": c.taken < c.asked,
                }));
                Ok(report)
            }
            Request::RobotPlay(r) => {
                let p =
                    super::play::run_play(station, r, control, &mut |t| interaction.play_tick(t))?;
                let mut report = device_report(op, "robot", &p.joints);
                report.summary = serde_json::to_value(&p.summary).ok();
                Ok(report)
            }
            Request::RobotTeach(r) => {
                let t = super::teach::run_teach(station, r, control)?;
                let mut report = device_report(op, "robot", &t.joints);
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
                let mut report = device_report(op, "robot", &t.joints);
                report.summary = serde_json::to_value(&t.summary).ok();
                // The leader's silence fails the run (no-device), whatever the follower did.
                if let Some(lost) = t.lost {
                    report.failed = Some(lost.kind);
                    report.error = Some(match report.error.take() {
                        Some(e) => format!("{}; {e}", lost.error),
                        None => lost.error,
                    });
                }
                Ok(report)
            }
            _ => robot_report(station, op),
        },
        // Nothing of the station is used: the host's own serial ports.
        Family::Host => super::host::ports_report(op),
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
        r.failed = Some(k);
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
                out.failed = Some(ErrorKind::Interrupted);
                out.error = Some(format!("{name}: {why}"));
            } else if !r.duplicates.is_empty() {
                // As whj.scan: an ID that more than one module answers is a device fault.
                let ids: Vec<String> = r
                    .duplicates
                    .iter()
                    .map(|d| format!("ID {} at {} bit/s", d.id, d.baud))
                    .collect();
                out.failed = Some(ErrorKind::Device);
                out.error = Some(format!(
                    "{name}: more than one module answers at {}; give each module its own ID",
                    ids.join(", ")
                ));
            } else if r.is_empty() {
                let rates: Vec<String> = args.bauds.iter().map(ToString::to_string).collect();
                out.failed = Some(ErrorKind::NoDevice);
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
                out.failed = Some(e.kind());
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
            let mut sampler = crate::station::sampler::WckSampler::new(&ids);
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
                out.failed = Some(ErrorKind::Interrupted);
                out.error = Some(format!("{name}: {why}"));
            } else if r.found.is_empty() {
                out.failed = Some(ErrorKind::NoDevice);
                out.error = Some(format!(
                    "no joint answered on IDs {}",
                    ids.iter()
                        .map(|j| j.get().to_string())
                        .collect::<Vec<_>>()
                        .join(",")
                ));
            } else if !r.duplicates.is_empty() && out.failed.is_none() {
                out.failed = Some(ErrorKind::Device);
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
                out.failed = Some(ErrorKind::NoDevice);
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

/// The [`Operation`] of a request whose operation is not yet in a file of its own: each
/// method routes through the family's match above.
macro_rules! legacy {
    (@bus bus) => {
        fn bus(&self) -> Option<&str> {
            self.bus.as_deref()
        }
    };
    (@bus nobus) => {};
    (@confirm confirm) => {
        fn confirmed(&self) -> bool {
            self.confirm
        }
        fn confirm(&mut self) {
            self.confirm = true;
        }
    };
    (@confirm noconfirm) => {};
    ($( $ty:ty => $op:literal, $variant:ident, $fam:ident, $bus:ident, $conf:ident,
        [$args:literal, $report:literal, $confirm:literal]; )*) => {$(
        impl Operation for $ty {
            const OP: &'static str = $op;
            const FAMILY: Family = Family::$fam;
            const DOC: OpDoc = OpDoc { args: $args, report: $report, confirm: $confirm };
            type Row = Value;
            type Summary = Value;

            legacy!(@bus $bus);
            legacy!(@confirm $conf);

            fn effect(&self) -> super::Effect {
                Request::$variant(self.clone()).legacy_effect()
            }
            fn moved(&self) -> Result<Option<super::Moved>, OpError> {
                Request::$variant(self.clone()).legacy_moved()
            }
            fn check(&self) -> Result<Confirm, OpError> {
                check(&Request::$variant(self.clone()))
            }
            fn plan(&self, baud: BaudRate) -> Result<Plan, OpError> {
                plan_at(&Request::$variant(self.clone()), baud)
            }
            fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report, OpError> {
                run_with(cx.station, &Request::$variant(self.clone()), cx.control, cx.interaction)
            }
        }
    )*};
}

use super::{host, play, robot, teach, teleop};

legacy! {
    wck::Scan => "wck.scan", WckScan, Wck, bus, noconfirm,
        [r#"`ids`="0-30", `all_bauds`"#,
         "found servos; summary: scan report",
         "-"];
    wck::Status => "wck.status", WckStatus, Wck, bus, noconfirm,
        ["`ids`",
         "id, load, position, degrees",
         "-"];
    wck::Move => "wck.move", WckMove, Wck, bus, noconfirm,
        ["`id`, `position` (0..=254), `torque` (0..=4)",
         "`load_before`, `position_before`",
         "-"];
    wck::Move10 => "wck.move10", WckMove10, Wck, bus, noconfirm,
        ["`id` (0..=253), `position` (0..=1023), `torque` (0..=254)",
         "reply fields",
         "-"];
    wck::Read10 => "wck.read10", WckRead10, Wck, bus, noconfirm,
        ["`id`",
         "position10",
         "-"];
    wck::SyncMove => "wck.sync-move", WckSyncMove, Wck, bus, noconfirm,
        ["`positions` [0..=254], `torque`",
         "(no reply)",
         "-"];
    wck::Passive => "wck.passive", WckPassive, Wck, bus, noconfirm,
        ["`ids`",
         "position",
         "-"];
    wck::Wheel => "wck.wheel", WckWheel, Wck, bus, noconfirm,
        ["`id`, `direction` (ccw/cw), `speed` (0..=15), `duration` s, `on_stop`",
         "wheel fields, `ran_ms`",
         "-"];
    wck::Brake => "wck.brake", WckBrake, Wck, bus, noconfirm,
        ["-",
         "break fields",
         "-"];
    wck::Get => "wck.get", WckGet, Wck, bus, noconfirm,
        ["`param` (gains, i-gain, speed, overload, bounds, io), `id`",
         "the parameter",
         "-"];
    wck::Set => "wck.set", WckSet, Wck, bus, confirm,
        ["`param`, `id`, `p` `d` / `i` / `speed` `accel` / `milliamps` / `lower` `upper` / `outputs`, `runtime`",
         "read-back",
         "EEPROM unless runtime"];
    wck::SetId => "wck.set-id", WckSetId, Wck, bus, confirm,
        ["`id`, `new_id`",
         "verified at the new ID",
         "ID"];
    wck::SetBaud => "wck.set-baud", WckSetBaud, Wck, bus, confirm,
        ["`id`, `rate` bit/s",
         "verified at the new rate",
         "EEPROM"];
    wck::ProgramUpload => "wck.program.upload", WckProgramUpload, Wck, bus, confirm,
        ["`id`, `program` (text form)",
         "read-back",
         "EEPROM"];
    wck::ProgramDownload => "wck.program.download", WckProgramDownload, Wck, bus, noconfirm,
        ["`id`",
         "the program",
         "-"];
    wck::ProgramCheck => "wck.program.check", WckProgramCheck, Wck, bus, noconfirm,
        ["`program`, `id`=0",
         "summary: instructions, upload packet (nothing sent)",
         "-"];
    wck::Teach => "wck.teach", WckTeach, Wck, bus, noconfirm,
        ["`ids` 0..N-1, `rate_hz` (0.1..=200), `duration` s (0.1..=3600), `pose_ms` (0..=600000), `torque`, `on_stop`; without `rate_hz` and `duration` a pose per record event of the front end's `Interaction`",
         "summary: `ids`, `torque`, `recorded`, `poses` (also after a stop: `failed` says why it ended)",
         "-"];
    wck::Play => "wck.play", WckPlay, Wck, bus, noconfirm,
        ["`motion` (keyframe text), `rate_hz`=50, `on_stop`",
         "summary: play report",
         "-"];
    wck::Sample => "wck.sample", WckSample, Wck, bus, noconfirm,
        ["`ids`",
         "`position_deg`, `speed_deg_s`, `load`",
         "-"];
    wck::Tune => "wck.tune", WckTune, Wck, bus, confirm,
        ["`id`, `gains` (`[[P, D], ...]`), `amplitude`=20, `hold_ms`=1000, `torque`, `keep` (`none`, `runtime`, `eeprom`)",
         "one row per gain set: `rise_ms`, `overshoot_pct`, `settling_ms`, `steady_state_error`; `summary`: `start`, `target`, `best` (`null` on a tie), `tied` (the sets whose responses differ by no more than the measurement's resolution: a reading in settling time, a position step in overshoot), `kept` (a tie keeps the first tied set) and each set's trace; every step starts with the servo at rest at the start, and the run returns with it back there",
         "EEPROM with `keep: eeprom`"];
    wck::Backup => "wck.backup", WckBackup, Wck, bus, noconfirm,
        ["`id`",
         "the settings (`p_gain`, `d_gain`, `i_gain`, `speed`, `accel`, `overload`, `lower`, `upper`); `summary` is the settings file",
         "-"];
    wck::Diff => "wck.diff", WckDiff, Wck, bus, noconfirm,
        ["`id`, `settings` (a settings file's text), `factory` or `other` (a servo)",
         "one row per group that differs (`setting`, `a`, `b`)",
         "-"];
    wck::Restore => "wck.restore", WckRestore, Wck, bus, confirm,
        ["`id`, `settings` or `factory`",
         "one row per group written (only those that differ, each verified); `summary`: `written`",
         "EEPROM"];
    whj::Scan => "whj.scan", WhjScan, Whj, bus, noconfirm,
        [r#"`joints`="1-30""#,
         "identity per joint; summary: duplicates",
         "-"];
    whj::Info => "whj.info", WhjInfo, Whj, bus, noconfirm,
        ["`joint`",
         "identity, unique ID, limits, status",
         "-"];
    whj::Status => "whj.status", WhjStatus, Whj, bus, noconfirm,
        ["`joints`, `broadcast`, `end_board`",
         "status per joint (and `end-board`)",
         "-"];
    whj::Enable => "whj.enable", WhjEnable, Whj, bus, noconfirm,
        ["`joints`",
         "enabled",
         "-"];
    whj::Disable => "whj.disable", WhjDisable, Whj, bus, noconfirm,
        ["`joints`",
         "enabled",
         "-"];
    whj::Mode => "whj.mode", WhjMode, Whj, bus, noconfirm,
        ["`joints`, `mode` (open-loop, current, speed, position)",
         "mode",
         "-"];
    whj::Move => "whj.move", WhjMove, Whj, bus, noconfirm,
        ["`joint`, `degrees` (±360), `max_speed` deg/s (0.1..=180)=10, `rate_hz` (1..=1000)=200, `from`, `on_stop`",
         "move report",
         "-"];
    whj::Speed => "whj.speed", WhjSpeed, Whj, bus, noconfirm,
        ["`joint`, `rpm` (±37.5), `duration` s (0.01..=3600), `on_stop`",
         "target report",
         "-"];
    whj::Current => "whj.current", WhjCurrent, Whj, bus, noconfirm,
        ["`joint`, `milliamps` (±30000), `duration`, `model`, `on_stop`",
         "target report",
         "-"];
    whj::Zero => "whj.zero", WhjZero, Whj, bus, noconfirm,
        ["`joint`",
         "zero report",
         "-"];
    whj::Clear => "whj.clear", WhjClear, Whj, bus, noconfirm,
        ["`joints`",
         "error before / after",
         "-"];
    whj::Save => "whj.save", WhjSave, Whj, bus, confirm,
        ["`joints`",
         "saved",
         "flash"];
    whj::Read => "whj.read", WhjRead, Whj, bus, noconfirm,
        ["`joints`, `register` (name or address), `count`, `broadcast`, `end_board`",
         "one row per register",
         "-"];
    whj::Write => "whj.write", WhjWrite, Whj, bus, confirm,
        ["`joints`, `register`, `value` (register unit; counts with `raw`), `broadcast`, `end_board` (`REG=VALUE`), `model`",
         "read-back",
         "register class / flash"];
    whj::Registers => "whj.registers", WhjRegisters, Whj, bus, noconfirm,
        ["-",
         "the register table (nothing sent)",
         "-"];
    whj::SetId => "whj.set-id", WhjSetId, Whj, bus, confirm,
        ["`joint`, `new_id`",
         "set-id report",
         "ID"];
    whj::Wave => "whj.wave", WhjWave, Whj, bus, noconfirm,
        ["`joint`, `shape`, `mode`, `amplitude`, `frequency` Hz=0.5, `offset`, `duration` s=4, `rate_hz`=200, `broadcast`, `model`, `on_stop`",
         "last feedback; summary: wave statistics",
         "-"];
    whj::ReleaseIap => "whj.release-iap", WhjReleaseIap, Whj, bus, noconfirm,
        ["`joints`",
         "identity (connect / IAP release)",
         "-"];
    whj::Sample => "whj.sample", WhjSample, Whj, bus, noconfirm,
        ["`joints`, `broadcast`",
         "position, speed, current, enabled, error",
         "-"];
    whj::Backup => "whj.backup", WhjBackup, Whj, bus, noconfirm,
        ["`joint`",
         "model, firmware, settings count; `summary` is the settings file (every register the joint keeps in flash, raw and in its unit)",
         "-"];
    whj::Defaults => "whj.defaults", WhjDefaults, Whj, bus, noconfirm,
        ["`joint`",
         "model, firmware, settings count; `summary` is a settings file of the values the vendor documents for that model and firmware (modes at power-up, speed and acceleration limits, following error, feature switches; not the gains and current and position limits tuned per joint, nor the ID and bit rates), for `whj.restore`: the joints have no factory reset",
         "-"];
    whj::EndBoard => "whj.end-board", WhjEndBoard, Whj, bus, confirm,
        ["`action`: `status`, `power` (`volts`: 0, 12 or 24), `io` (`channel` 1 or 2, `mode` `input` / `output`) or `force`",
         "one row `end-board`: its state (`model`, `version`, `tool_volts`, `io1_output`, `io2_output`, `io1_high`, `io2_high`, `teach_button`, `replay_button`, `gripper_in_position`, `hand_in_position`, `error`); a write's `register`, `read_back` and `meaning` (written, then read back); or the force sensor's `fx`, `fy`, `fz`, `mx`, `my`, `mz` (raw: the vendor does not document their unit). A board that does not answer is `no-device`",
         "register: tool power on, a channel's direction (power off needs none)"];
    whj::SetRates => "whj.set-rates", WhjSetRates, Whj, bus, confirm,
        ["`joints`, `bitrate` (250000 / 500000 / 1000000), `dbitrate` (250000 / 500000 / 1000000 / 2000000 / 4000000 / 5000000, at least `bitrate`), `confirm`",
         "per joint: `before` and `after` ([arbitration, data] bit/s; written, read back), `saved`; an enabled joint is refused; `summary.next`, only when a joint saved (naming the joints that did when some did not): power-cycle the joints, set the adapter to the new rates (the command), and how to find a joint that is lost",
         "register"];
    whj::CanHealth => "whj.can-health", WhjCanHealth, Whj, bus, noconfirm,
        ["-",
         "one row, the interface (`id`): `kind`, `up`, `carrier`, `state` (`error-active`, `error-warning`, `error-passive`, `bus-off`, `stopped`; null without a controller, as on vcan), `tx_errors`, `rx_errors` (where the driver reports them), `restart_ms`, `bitrate`, `data_bitrate`, `fd` (CAN FD on; null without a controller), `mtu`, `classic` (FD off, or MTU 16 without a controller: WHJ joints cannot hear it; `advice` gives the CAN FD command), `stats` (changes to error-warning, error-passive, bus-off; restarts; bus errors), frame error and drop counts, `advice`. Nothing is sent on the bus; a bus without a CAN interface (UDP, simulated) is a row without a controller (`kind` and `state` null, `advice` says so). A telemetry stream takes it",
         "-"];
    whj::Diff => "whj.diff", WhjDiff, Whj, bus, noconfirm,
        ["`joint`, `settings` (a settings file's text) or `other` (a joint)",
         "one row per setting that differs (`a`, `b`, values and unit); against a file only the settings it holds, `summary.left_out` counting the joint's settings it leaves out",
         "-"];
    whj::Restore => "whj.restore", WhjRestore, Whj, bus, confirm,
        ["`joint`, `settings`",
         "one row per differing setting: written or skipped (the bus identity is never written); `summary`: `written`, `saved`, `differ_after`",
         "flash (and the `confirm` registers the file sets)"];
    robot::Sample => "robot.sample", RobotSample, Robot, nobus, noconfirm,
        ["-",
         "one row per joint of the station's robot file, `id` its name: `position_deg`, `speed_deg_s`, `current_ma` (WHJ), `load` (wCK), `enabled`, `error`",
         "-"];
    robot::Calibrate => "robot.calibrate", RobotCalibrate, Robot, nobus, noconfirm,
        ["`seconds` (0.1..=600), `rate_hz`=20 (1..=100), `zero` (`end`: the pose at the end becomes the zero; `keep`), `margin_deg`=2 (0..=30), `passive`=true (wCK servos torque off first)",
         "one row per joint by name: `samples`, `min_deg` / `max_deg` (the range it was moved through), `zero_deg`, `offset_rad` and `limits_rad` for the robot file (and `offset_before_rad`, `limits_before_rad`); `summary`: `readings`, `interrupted` (stopped early, with what was read). The file is not written: `robobus robot calibrate --write` writes it, keeping its comments",
         "-"];
    teleop::Teleop => "robot.teleop", RobotTeleop, Robot, nobus, noconfirm,
        [r#"`map`: 1..=64 pairs `{"leader", "follower", "scale"=1 (-10..=10), "offset_deg"=0 (-360..=360), "limits_deg": [min, max]}` (joint names of the robot file; a follower once, never also a leader), `rate_hz`=50 (1..=200), `seconds` (0.1..=86400; none: until stopped), `leader_timeout_ms`=500 (10..=10000), `passive_leader`=true"#,
         "one row per follower joint by name: `leader`, `commands`, `limited` (cut short by a jog step or a limit), `failed`, `target_deg`, `position_deg` (at the last command), `tracking_max_deg`, `tracking_rms_deg`; `summary`: `cycles`, `commanded`, `held` (cycles without every leader reading: nothing sent), `overruns`, `seconds`, `rate_hz`, `latency_ms` (`p50`, `p99`, `max`: from a cycle's leader reading to its last command), `leaders` (each one's `readings`, `failed`, `error`), `leader_lost` (the run ended because the leader went silent: `failed` is `no-device`), `interrupted`, `safe_state` (as `robot.play`'s). Refused before anything is sent when a follower joint is silent, outside its soft limits, or a WHJ joint not enabled in position mode (`robot.play`'s check)",
         "motion"];
    play::Play => "robot.play", RobotPlay, Robot, nobus, noconfirm,
        ["`trajectory` (a trajectory file's text: `time_s`, then a column per joint of the robot file, degrees in its joint frame; see `docs/hardware.md`), `rate_hz`=50 (1..=500), `torque`=2 (wCK servos, 0..=4)",
         "one row per joint by name: `commands`, `failed`, `start_deg`, `target_deg` (the last), `position_deg` (reported at the last command), `tracking_max_deg`, `tracking_rms_deg` (from where the joint reported itself to the target of the tick before); `summary`: `lead_in_s`, `duration_s`, `ticks`, `overruns`, `buses`, `skew_ms` (per tick, the first send of the first bus to that of the last) and `late_ms` (`p50`, `p99`, `max`), `interrupted`, `safe_state` (per bus: `bus`, the file's `safe_state` it was left in, `failed`: the joints that did not get there). Refused before anything moves when the trajectory does not fit the robot file or a joint is silent, outside its limits, or a WHJ joint not enabled in position mode. Finished, failed or stopped, it ends with each bus of its joints in the robot file's `safe_state` (as `robot.teleop`, `robot.calibrate` and `robot.teach` do)",
         "motion"];
    teach::Teach => "robot.teach", RobotTeach, Robot, nobus, confirm,
        ["`seconds` (0.1..=3600), `rate_hz`=20 (1..=100), `joints` (names; none: every joint of the robot file), `hold_ma`=0 (a WHJ joint's current while moved by hand, -2000..=2000), `confirm`",
         "one row per joint by name: `samples`, `failed`, `min_deg`, `max_deg`, `ended` (how it was left: its bus's `safe_state` in the robot file, `holding`, `disabled`, `passive` or `braked`, or why not); `summary`: `trajectory` (the trajectory file `robot.play` plays), `points`, `dropped` (readings left out: a joint did not answer), `readings`, `interrupted`. wCK servos go passive and WHJ joints into current mode first, so it needs `confirm`",
         "limp joints"];
    host::Ports => "host.ports", HostPorts, Host, nobus, noconfirm,
        ["-",
         "one row per serial port the OS lists (`id`: `COM3` on Windows, `/dev/cu.usbserial-A10K` on macOS, `/dev/ttyUSB0` / `/dev/ttyACM0` on Linux; a simulator's pseudo-terminal is not a port the OS lists): `kind` (`usb`, `pci`, `bluetooth`, `unknown`), `vid`, `pid` (numbers), `manufacturer`, `product`, `serial_number`, `adapter` (recognised from robobus's table: `FTDI FT232R`, `WCH CH340`, `Silicon Labs CP210x`, `CANable 2.0 (slcan firmware)`, `mjbots fdcanusb`, ...), `use_for` (`wCK bus: --port PORT`, `CAN FD adapter: --bus slcan:PORT`, `CAN FD adapter: --bus fdcanusb:PORT`), `latency_timer_ms` (an FTDI adapter's, read from sysfs on Linux; null elsewhere), `latency_advice` (how to set it to 1 ms on this OS; null when nothing is to be done); `summary`: `os`, `ports`, `left_out` (past 256), `where` (where this OS puts serial ports). No port is opened, nothing is sent; the station's buses are not used",
         "-"];
}
