//! Broadcast frames outside the cyclic loop: the 0x7F status query (`whj status
//! --broadcast`, `monitor --broadcast`) and 0x0F register access (`whj read / write
//! --broadcast`), one frame for joints 1..=7 and the end board.
//!
//! A broadcast is sent once and never resent. Its replies are credited only when they
//! arrived after the frame went out ([`JointBus::broadcast_replies_since`]) and answer
//! this request (the same register; for the end board the same command and register);
//! every slot asked for is reported, one without such a reply within
//! [`broadcast_window`] as a no-device failure. Register writes follow the same safety
//! classes, confirmation and firmware gates as point-to-point writes
//! ([`check_write`](super::check_write), [`check_joint_write`](super::check_joint_write));
//! a refused write sends nothing, for any joint.

use core::fmt;
use std::time::{Duration, Instant};

use robobus_whj::broadcast::{
    BroadcastRegister, BroadcastStatus, EndBoardOp, EndBoardRegister, EndBoardReply, RegisterOp,
    ReplyMask,
};
use robobus_whj::reply::BroadcastRegisterReply;
use robobus_whj::request::{ReadRange, WriteData};
use robobus_whj::units::CurrentScale;
use robobus_whj::{
    Address, BroadcastFeedback, CanFrame, JointId, RegisterAddr, RegisterInfo, Reply, Request,
};
use serde::Serialize;

use super::{
    JointSample, Plan, RegisterReport, ServoLoop, StatusReport, WaveArgs, check_joint_write,
    check_reading, check_write, confirm_text, plan_wave, prepare_wave, register_report, whj,
    word_reports, write_request,
};
use crate::ops::{DeviceResult, ErrorKind, Failure, OpError};
use crate::whj::{Joint, JointBus, RegisterValue, WhjError};
use robobus_whj::broadcast::{BroadcastCurrent, BroadcastPosition};
use robobus_whj::reply::ServoFeedback;

/// A slot of a broadcast frame: a joint (1..=7) or the end board. Serializes as the joint's
/// number or `"end-board"`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Slot {
    /// A joint's slot.
    Joint(JointId),
    /// The end board's field.
    EndBoard,
}

impl Serialize for Slot {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Self::Joint(j) => s.serialize_u8(j.get()),
            Self::EndBoard => s.serialize_str("end-board"),
        }
    }
}

impl fmt::Display for Slot {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Joint(j) => write!(f, "{j}"),
            Self::EndBoard => f.write_str("end board"),
        }
    }
}

/// What a broadcast register frame asks of the end board: a register of its own map
/// ([`EndBoardRegister`]) and, for a write, the value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EndBoardArg {
    /// Register address in the end board's map.
    pub addr: u8,
    /// The value to write (`None`: read).
    pub value: Option<u16>,
}

/// The 0x0F frames of a broadcast register read or write: what a dry run prints and the
/// real run ([`run_broadcast_plan`]) sends, in order (a write, then the read-back).
#[derive(Debug, Clone, PartialEq)]
pub struct BroadcastPlan {
    /// The frames.
    pub frames: Vec<Request>,
    /// The joints with an operation in their slot.
    pub joints: Vec<JointId>,
    /// The joints' register.
    pub addr: RegisterAddr,
    /// Words read per joint.
    pub count: u8,
    /// The register reported by name with its unit (`None`: raw words).
    pub named: Option<&'static RegisterInfo>,
    /// The end board's register, if its field is used.
    pub end_board: Option<EndBoardArg>,
    /// Whether the first frame writes.
    pub writes: bool,
    /// Notes for a human.
    pub notes: Vec<String>,
}

/// The smallest broadcast reply mask that selects every joint of `ids` (all 1..=7).
pub fn reply_mask(ids: &[JointId]) -> Result<ReplyMask, OpError> {
    reply_mask_with(ids, false)
}

/// [`reply_mask`] that also selects the end board when `end_board` is set.
pub fn reply_mask_with(ids: &[JointId], end_board: bool) -> Result<ReplyMask, OpError> {
    if let Some(bad) = ids.iter().find(|j| !j.has_broadcast_slot()) {
        return Err(OpError::invalid(
            "--broadcast JOINTS",
            bad.get(),
            "broadcast frames address joints 1..=7 only",
        ));
    }
    (0..=0xFu8)
        .filter_map(|code| ReplyMask::new(code).ok())
        .filter(|m| ids.iter().all(|j| m.selects(*j)) && (!end_board || m.selects_end_board()))
        .min_by_key(|m| m.joints().count() + usize::from(m.selects_end_board()))
        .ok_or_else(|| OpError::invalid("--broadcast JOINTS", ids.len(), "no reply mask fits"))
}

/// How long a broadcast's replies are collected: eight replies take under 1 ms on the
/// wire; a broadcast is not resent, so it waits up to five reply timeouts (100 ms by
/// default) for slow links and simulators, and returns as soon as every slot answered.
pub fn broadcast_window(bus: &JointBus) -> Duration {
    (bus.config().reply_timeout * 5).max(Duration::from_millis(5))
}

/// How long a broadcast's replies are still collected after every slot has answered, to
/// see a second answer in a slot: two nodes that answer as one (a duplicate ID, a node
/// answering twice) go out back to back by CAN arbitration, well within this time (a
/// 24-byte reply takes about 0.1 ms at 1 / 5 Mbit/s).
pub const SECOND_ANSWER_GUARD: Duration = Duration::from_millis(1);

/// Waits until `credit` accepts a reply for every slot (then [`SECOND_ANSWER_GUARD`]
/// longer) or [`broadcast_window`] ends. Each slot gets the reply received after `sent`
/// that `credit` accepts (`Ok(None)`: none); two different ones in one slot are a device
/// failure naming both, never "the first wins".
fn collect<T: PartialEq + fmt::Debug>(
    bus: &JointBus,
    sent: Instant,
    slots: &[Slot],
    credit: impl Fn(Slot, &CanFrame) -> Option<T>,
) -> Vec<Result<Option<T>, Failure>> {
    let deadline = bus.now() + broadcast_window(bus);
    let mut settle: Option<Instant> = None;
    loop {
        let got = bus.broadcast_replies_since(sent);
        let now = bus.now();
        let complete = slots
            .iter()
            .all(|&slot| got.iter().any(|(_, f)| credit(slot, f).is_some()));
        if complete && settle.is_none() {
            settle = Some(now + SECOND_ANSWER_GUARD);
        }
        let until = settle.map_or(deadline, |s| s.min(deadline));
        if now >= until {
            return slots
                .iter()
                .map(|&slot| {
                    let mut answers = got.iter().filter_map(|(_, f)| credit(slot, f));
                    let first = answers.next();
                    let other = answers.find(|a| Some(a) != first.as_ref());
                    match (first, other) {
                        (Some(a), Some(b)) => Err(Failure::of(
                            ErrorKind::Device,
                            &format!(
                                "{slot}: two different answers to one broadcast frame ({a:?} \
                                 and {b:?}): two nodes answer as one, or one answers twice; \
                                 neither is credited"
                            ),
                        )),
                        (first, _) => Ok(first),
                    }
                })
                .collect();
        }
        // Receives meanwhile (on a simulated bus on virtual time, simulates meanwhile).
        bus.sleep_until(until.min(now + Duration::from_millis(2)));
    }
}

fn silent(slot: Slot, what: &str, bus: &JointBus) -> Failure {
    Failure::of(
        ErrorKind::NoDevice,
        &format!(
            "{slot}: no reply to the broadcast {what} within {} ms",
            broadcast_window(bus).as_millis()
        ),
    )
}

fn scale_of(bus: &JointBus, id: JointId) -> CurrentScale {
    bus.cached_identity(id)
        .map_or(CurrentScale::OneMilliamp, |i| i.current_scale())
}

// ---------------------------------------------------------------------------------------
// 0x7F status
// ---------------------------------------------------------------------------------------

/// One answer to a 0x7F frame.
#[derive(Debug, PartialEq)]
enum Answer {
    Joint(BroadcastFeedback),
    EndBoard(EndBoardReply),
}

/// One 0x7F frame to joints `ids` (and the end board); each joint's 24-byte feedback and
/// the end board's reply, `None` when none came.
#[allow(clippy::type_complexity)] // one result per slot, and the end board's
fn status_query(
    bus: &JointBus,
    ids: &[JointId],
    end_board: bool,
) -> Result<
    (
        Vec<Result<Option<BroadcastFeedback>, Failure>>,
        Result<Option<EndBoardReply>, Failure>,
    ),
    OpError,
> {
    let mask = reply_mask_with(ids, end_board)?;
    let sent = bus
        .send_broadcast(Request::BroadcastStatus(BroadcastStatus::new(mask)))
        .map_err(whj)?;
    let mut slots: Vec<Slot> = ids.iter().map(|&j| Slot::Joint(j)).collect();
    if end_board {
        slots.push(Slot::EndBoard);
    }
    let mut found = collect(bus, sent, &slots, |slot, f| match slot {
        Slot::Joint(id) => match Reply::from_frame(f) {
            Ok(Reply::BroadcastFeedback { joint, feedback }) if joint == id => {
                Some(Answer::Joint(feedback))
            }
            _ => None,
        },
        Slot::EndBoard => (f.standard_raw_id().map(Address::from_raw)
            == Some(Address::EndBoardFeedback))
        .then(|| EndBoardReply::decode(f.data()).map(Answer::EndBoard))
        .flatten(),
    });
    let board = if end_board {
        match found.pop() {
            Some(Ok(Some(Answer::EndBoard(r)))) => Ok(Some(r)),
            Some(Err(f)) => Err(f),
            _ => Ok(None),
        }
    } else {
        Ok(None)
    };
    let joints = found
        .into_iter()
        .map(|a| match a {
            Ok(Some(Answer::Joint(f))) => Ok(Some(f)),
            Err(f) => Err(f),
            _ => Ok(None),
        })
        .collect();
    Ok((joints, board))
}

/// One 0x7F frame; each joint's report made by `report` from its feedback, or a
/// no-device failure.
fn per_joint_status<T>(
    bus: &JointBus,
    ids: &[JointId],
    report: impl Fn(JointId, &BroadcastFeedback) -> T,
) -> Result<Vec<DeviceResult<u8, T>>, OpError> {
    let (found, _) = status_query(bus, ids, false)?;
    Ok(joint_results(bus, ids, found, report))
}

fn joint_results<T>(
    bus: &JointBus,
    ids: &[JointId],
    found: Vec<Result<Option<BroadcastFeedback>, Failure>>,
    report: impl Fn(JointId, &BroadcastFeedback) -> T,
) -> Vec<DeviceResult<u8, T>> {
    ids.iter()
        .zip(found)
        .map(|(&id, fb)| match fb {
            Err(failure) => DeviceResult::failed(id.get(), failure),
            // The joint's limits are read once per bus (a joint the broadcast reached but
            // the bus never spoke to costs one register read here, the first time).
            Ok(Some(f)) => match check_reading(
                &bus.joint_unchecked(id),
                f.position.degrees(),
                Some(f.speed.rpm()),
            ) {
                Ok(()) => DeviceResult::ok(id.get(), report(id, &f)),
                Err(e) => DeviceResult::failed(id.get(), Failure::from(&e)),
            },
            Ok(None) => {
                DeviceResult::failed(id.get(), silent(Slot::Joint(id), "status query", bus))
            }
        })
        .collect()
}

fn status_report(bus: &JointBus, id: JointId, f: &BroadcastFeedback) -> StatusReport {
    StatusReport {
        enabled: f.is_enabled(),
        mode: "-",
        position_deg: f.position.degrees(),
        current_ma: Some(f.current.milliamps(scale_of(bus, id))),
        voltage_v: f64::from(f.voltage.volts()),
        temperature_c: f64::from(f.temperature.celsius()),
        brake: if f.brake_locked() {
            "locked"
        } else {
            "released"
        },
        error: f.error.to_string(),
    }
}

/// Connects joints `ids` before a broadcast (IAP releases pipelined, identities read for
/// their current scales: [`JointBus::joints`]), so absent joints cost one connect timeout
/// in all, not one each. A joint that does not connect is named by the broadcast's own
/// result (as silent); this returns how many connected.
pub fn connect_for_broadcast(bus: &JointBus, ids: &[JointId]) -> usize {
    bus.joints(ids).iter().filter(|j| j.is_ok()).count()
}

/// `whj status --broadcast`: one 0x7F frame asks joints `ids` (1..=7) for their status;
/// every joint is reported, one that did not answer within [`broadcast_window`] as a
/// no-device failure. Joints outside `ids` that the mask also selects are not reported.
pub fn broadcast_status(
    bus: &JointBus,
    ids: &[JointId],
) -> Result<Vec<DeviceResult<u8, StatusReport>>, OpError> {
    per_joint_status(bus, ids, |id, f| status_report(bus, id, f))
}

/// The end board's state in its answer to a status query (status0 bits, §8.10).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[allow(clippy::struct_excessive_bools)] // eight independent status bits, as JSON booleans
pub struct EndBoardStatus {
    /// Digital channel 1 is an output.
    pub io1_output: bool,
    /// Digital channel 2 is an output.
    pub io2_output: bool,
    /// Digital channel 1 is high.
    pub io1_high: bool,
    /// Digital channel 2 is high.
    pub io2_high: bool,
    /// The teach button is pressed.
    pub teach_button: bool,
    /// The replay button is pressed.
    pub replay_button: bool,
    /// The gripper reports "in position".
    pub gripper_in_position: bool,
    /// The dexterous hand reports "in position".
    pub hand_in_position: bool,
    /// The board's system error byte, hex.
    pub error: String,
}

impl EndBoardStatus {
    /// The state in a reply's status bytes.
    pub fn of(r: &EndBoardReply) -> Self {
        let bit = |n: u8| r.status0 & (1 << n) != 0;
        Self {
            io1_output: bit(7),
            io2_output: bit(6),
            teach_button: bit(5),
            replay_button: bit(4),
            io1_high: bit(3),
            gripper_in_position: bit(2),
            hand_in_position: bit(1),
            io2_high: bit(0),
            error: format!("0x{:02X}", r.sys_error),
        }
    }
}

/// The joints' and the end board's results of one status query.
pub type StatusWithEndBoard = (
    Vec<DeviceResult<u8, StatusReport>>,
    DeviceResult<Slot, EndBoardStatus>,
);

/// `whj status --broadcast --end-board`: [`broadcast_status`] and, in the same 0x7F frame,
/// the end board's state (or a no-device failure when it did not answer).
pub fn broadcast_status_with_end_board(
    bus: &JointBus,
    ids: &[JointId],
) -> Result<StatusWithEndBoard, OpError> {
    let (found, board) = status_query(bus, ids, true)?;
    let joints = joint_results(bus, ids, found, |id, f| status_report(bus, id, f));
    let board = match board {
        Ok(Some(r)) => DeviceResult::ok(Slot::EndBoard, EndBoardStatus::of(&r)),
        Ok(None) => {
            DeviceResult::failed(Slot::EndBoard, silent(Slot::EndBoard, "status query", bus))
        }
        Err(failure) => DeviceResult::failed(Slot::EndBoard, failure),
    };
    Ok((joints, board))
}

/// `monitor --broadcast`: samples joints `ids` (1..=7) with one 0x7F frame, instead of
/// two point-to-point frames per joint ([`sample`](super::sample)). A joint that does not
/// answer is a failed result: the caller marks it missing.
pub fn sample_broadcast(
    bus: &JointBus,
    ids: &[JointId],
) -> Result<Vec<DeviceResult<u8, JointSample>>, OpError> {
    per_joint_status(bus, ids, |id, f| JointSample {
        position_deg: f.position.degrees(),
        speed_rpm: Some(f.speed.rpm()),
        current_ma: Some(f.current.milliamps(scale_of(bus, id))),
        enabled: f.is_enabled(),
        error: f.error.to_string(),
    })
}

// ---------------------------------------------------------------------------------------
// 0x0F register read / write
// ---------------------------------------------------------------------------------------

/// What an end-board write does, for a confirmation prompt.
pub const END_BOARD_WRITE_TEXT: &str =
    "switches what is attached to the tool (power, IO, Modbus) through the end board";

fn end_board_register(addr: u8) -> &'static str {
    EndBoardRegister::by_addr(addr).map_or("(reserved)", |r| r.name)
}

fn register_frame(
    mask: ReplyMask,
    ops: &[(JointId, RegisterOp)],
    end_board: Option<EndBoardOp>,
) -> Result<Request, OpError> {
    let mut frame = BroadcastRegister::new(mask);
    for &(j, op) in ops {
        frame = frame
            .with_op(j, op)
            .ok_or_else(|| OpError::invalid("--broadcast JOINTS", j.get(), "joints 1..=7 only"))?;
    }
    if let Some(op) = end_board
        && !op.encode_into(&mut frame.end_board, 0xFF)
    {
        return Err(OpError::invalid(
            "--end-board",
            format!("{op:?}"),
            "does not fit the 13-byte end-board field",
        ));
    }
    Ok(Request::BroadcastRegister(frame))
}

/// `whj read --broadcast`: the 0x0F frame that reads `addr` on joints `ids` (1..=7) and,
/// with `end_board`, one register of the end board's map. `count`: as point-to-point
/// (`None` = the register, or pair, by name with its unit).
pub fn plan_broadcast_read(
    ids: &[JointId],
    addr: RegisterAddr,
    count: Option<u8>,
    end_board: Option<u8>,
) -> Result<BroadcastPlan, OpError> {
    let info = RegisterInfo::by_addr(addr);
    let named = if count.is_none() { info } else { None };
    let count = count.unwrap_or(match info.map(|i| i.half) {
        Some(robobus_whj::registers::Half::Low) => 2,
        _ => 1,
    });
    let range = ReadRange::new(addr, count)
        .map_err(|e| OpError::invalid("read <REGISTER> [COUNT]", count, e.to_string()))?;
    let eb = end_board
        .map(|a| EndBoardOp::read(a, 1))
        .transpose()
        .map_err(|e| OpError::invalid("--end-board", format!("{end_board:?}"), e.to_string()))?;
    let mask = reply_mask_with(ids, eb.is_some())?;
    let ops: Vec<_> = ids.iter().map(|&j| (j, RegisterOp::Read(range))).collect();
    let frame = register_frame(mask, &ops, eb)?;
    let mut notes = vec![format!(
        "one broadcast register frame (0x0F), reply mask {:#X}: joints {} read {} register(s) \
         from {:#04x}{}",
        mask.get(),
        list(ids),
        count,
        addr.get(),
        end_board.map_or(String::new(), |a| format!(
            "; the end board reads {} ({a:#04x})",
            end_board_register(a)
        ))
    )];
    notes.push("a real run connects each joint first".into());
    Ok(BroadcastPlan {
        frames: vec![frame],
        joints: ids.to_vec(),
        addr,
        count,
        named,
        end_board: end_board.map(|addr| EndBoardArg { addr, value: None }),
        writes: false,
        notes,
    })
}

fn list(ids: &[JointId]) -> String {
    ids.iter()
        .map(|j| j.get().to_string())
        .collect::<Vec<_>>()
        .join(",")
}

/// `whj write --broadcast`: a 0x0F frame that writes `value` (the register's unit, or
/// counts with `raw`; each joint's current scale from `scale`) into `addr` of joints `ids`,
/// and the end board's register if given, then the read-back frame. Motion targets and
/// `never` registers are refused here; a write to a read-only end-board register too.
pub fn plan_broadcast_write(
    ids: &[JointId],
    addr: RegisterAddr,
    value: f64,
    raw: bool,
    scale: &dyn Fn(JointId) -> CurrentScale,
    end_board: Option<EndBoardArg>,
) -> Result<BroadcastPlan, OpError> {
    if let Err(e @ OpError::Refused(_)) = check_write(addr, true) {
        return Err(e);
    }
    let mut ops = Vec::with_capacity(ids.len());
    let mut confirm = None;
    for &j in ids {
        let req = write_request(j, addr, value, raw, scale(j))?;
        confirm = confirm.or_else(|| confirm_text(&req));
        let Request::Write { addr, data, .. } = req else {
            return Err(OpError::invalid(
                "write",
                format!("{req:?}"),
                "not a register write",
            ));
        };
        ops.push((j, RegisterOp::Write { addr, data }));
    }
    let eb = match end_board {
        None => None,
        Some(EndBoardArg { addr: a, value }) => {
            let reg = EndBoardRegister::by_addr(a)
                .filter(|r| r.writable)
                .ok_or_else(|| {
                    OpError::invalid(
                        "--end-board ADDR=VALUE",
                        format!("{a:#04x}"),
                        format!(
                            "{} is not a writable end-board register (see the end-board table \
                         in the docs)",
                            end_board_register(a)
                        ),
                    )
                })?;
            let v = value.ok_or_else(|| {
                OpError::invalid("--end-board ADDR=VALUE", reg.name, "a write needs a value")
            })?;
            let bytes = v.to_le_bytes();
            let data: &[u8] = if v <= 0xFF { &bytes[..1] } else { &bytes };
            Some(
                EndBoardOp::write(a, data)
                    .map_err(|e| OpError::invalid("--end-board ADDR=VALUE", v, e.to_string()))?,
            )
        }
    };
    let mask = reply_mask_with(ids, eb.is_some())?;
    let write = register_frame(mask, &ops, eb)?;
    let unnamed_count = match ops.first() {
        Some((
            _,
            RegisterOp::Write {
                data: WriteData::Pair(_),
                ..
            },
        )) => Some(2),
        _ => Some(1),
    };
    let count = RegisterInfo::by_addr(addr).map_or(unnamed_count, |_| None);
    let mut plan = plan_broadcast_read(ids, addr, count, end_board.map(|e| e.addr))?;
    plan.frames.insert(0, write);
    plan.writes = true;
    plan.end_board = end_board;
    let name = RegisterInfo::by_addr(addr).map_or("reserved register", |i| i.name);
    plan.notes = vec![format!(
        "one broadcast register frame (0x0F) writes {name} on joints {}{}, then one reads it \
         back; reply mask {:#X}",
        list(ids),
        end_board.map_or(String::new(), |e| format!(
            " and the end board's {} ({:#04x})",
            end_board_register(e.addr),
            e.addr
        )),
        mask.get()
    )];
    if let Some(what) = confirm {
        plan.notes.push(format!("{name}: {what} (needs --yes)"));
    }
    if end_board.is_some() {
        plan.notes.push(format!(
            "an end-board write {END_BOARD_WRITE_TEXT} (needs --yes)"
        ));
    }
    plan.notes
        .push("a real run connects each joint first and checks its firmware".into());
    Ok(plan)
}

/// Runs a [`BroadcastPlan`]: for a write, checks the confirmation and every joint's
/// firmware gates and limits first (a refusal sends nothing), sends the write, credits
/// the acks, then sends the read-back; reports one result per register and slot.
pub fn run_broadcast_plan(
    bus: &JointBus,
    plan: &BroadcastPlan,
    confirmed: bool,
) -> Result<Vec<DeviceResult<Slot, RegisterReport>>, OpError> {
    let mut slots: Vec<Slot> = plan.joints.iter().map(|&j| Slot::Joint(j)).collect();
    if plan.end_board.is_some() {
        slots.push(Slot::EndBoard);
    }
    let mut failed: Vec<Option<Failure>> = vec![None; slots.len()];
    let mut frames = plan.frames.iter();
    if plan.writes {
        let Some(Request::BroadcastRegister(write)) = frames.next() else {
            return Err(OpError::invalid("plan", "frames", "no write frame"));
        };
        check_write(plan.addr, confirmed)?;
        if let Some(e) = plan.end_board
            && !confirmed
        {
            return Err(OpError::Refused(format!(
                "write end-board {} ({:#04x}) {END_BOARD_WRITE_TEXT}; confirm with --yes; \
                 nothing was sent",
                end_board_register(e.addr),
                e.addr
            )));
        }
        for &j in &plan.joints {
            if let RegisterOp::Write { addr, data } = op_of(write, j)? {
                check_joint_write(&bus.joint_unchecked(j), addr, data)?;
            }
        }
        let sent = bus
            .send_broadcast(Request::BroadcastRegister(*write))
            .map_err(whj)?;
        let eb_op = EndBoardOp::decode(&write.end_board);
        let acks = collect(bus, sent, &slots, |slot, f| {
            credit_write(slot, f, plan.addr, eb_op.as_ref())
        });
        for ((slot, ack), fail) in slots.iter().zip(acks).zip(&mut failed) {
            *fail = match ack {
                Err(failure) => Some(failure),
                Ok(None) => Some(silent(*slot, "register write", bus)),
                Ok(Some(false)) => Some(Failure::of(
                    ErrorKind::Device,
                    &format!("{slot}: refused the broadcast write (status 0)"),
                )),
                Ok(Some(true)) => None,
            };
        }
    }
    let Some(Request::BroadcastRegister(read)) = frames.next() else {
        return Err(OpError::invalid("plan", "frames", "no read frame"));
    };
    let sent = bus
        .send_broadcast(Request::BroadcastRegister(*read))
        .map_err(whj)?;
    let eb_op = EndBoardOp::decode(&read.end_board);
    let reads = collect(bus, sent, &slots, |slot, f| {
        credit_read(slot, f, plan.addr, plan.count, eb_op.as_ref())
    });
    let mut out = Vec::new();
    for ((&slot, read), fail) in slots.iter().zip(reads).zip(failed) {
        if let Some(f) = fail {
            out.push(DeviceResult::failed(slot, f));
            continue;
        }
        let read = match read {
            Ok(read) => read,
            Err(failure) => {
                out.push(DeviceResult::failed(slot, failure));
                continue;
            }
        };
        match (slot, read) {
            (_, None) => out.push(DeviceResult::failed(
                slot,
                silent(slot, "register read", bus),
            )),
            (Slot::Joint(j), Some(Read::Joint(words))) => match plan.named {
                Some(info) => out.push(DeviceResult::ok(
                    slot,
                    register_report(&RegisterValue::of(info, &words, scale_of(bus, j))),
                )),
                None => out.extend(
                    word_reports(plan.addr, &words)
                        .into_iter()
                        .map(|r| DeviceResult::ok(slot, r)),
                ),
            },
            (_, Some(Read::EndBoard { index, word })) => out.push(DeviceResult::ok(
                slot,
                RegisterReport {
                    addr: format!("0x{index:02X}"),
                    register: end_board_register(index),
                    raw: i64::from(word),
                    value: None,
                    unit: "",
                },
            )),
            (Slot::EndBoard, Some(Read::Joint(_))) => {}
        }
    }
    Ok(out)
}

fn op_of(frame: &BroadcastRegister, j: JointId) -> Result<RegisterOp, OpError> {
    match frame.slot(j) {
        robobus_whj::RegisterSlot::Op(op) => Ok(op),
        other => Err(OpError::invalid(
            "plan",
            format!("{other:?}"),
            "no operation",
        )),
    }
}

#[derive(Debug, PartialEq)]
enum Read {
    Joint(Vec<u16>),
    EndBoard { index: u8, word: u16 },
}

fn credit_write(
    slot: Slot,
    f: &CanFrame,
    addr: RegisterAddr,
    eb: Option<&EndBoardOp>,
) -> Option<bool> {
    match slot {
        Slot::Joint(id) => match Reply::from_frame(f).ok()? {
            Reply::BroadcastRegister {
                joint,
                reply: BroadcastRegisterReply::WriteAck { addr: a, status },
            } if joint == id && a == addr => Some(status.is_ok()),
            _ => None,
        },
        Slot::EndBoard => {
            let r = end_board_reply(f)?;
            r.answers(eb?).then(|| r.write_ok())
        }
    }
}

fn credit_read(
    slot: Slot,
    f: &CanFrame,
    addr: RegisterAddr,
    count: u8,
    eb: Option<&EndBoardOp>,
) -> Option<Read> {
    match slot {
        Slot::Joint(id) => match Reply::from_frame(f).ok()? {
            Reply::BroadcastRegister {
                joint,
                reply: BroadcastRegisterReply::Read { addr: a, words, .. },
            } if joint == id && a == addr && words.len() >= usize::from(count) => {
                Some(Read::Joint(words.as_slice()[..usize::from(count)].to_vec()))
            }
            _ => None,
        },
        Slot::EndBoard => {
            let r = end_board_reply(f)?;
            let op = eb?;
            r.answers(op).then(|| Read::EndBoard {
                index: op.index(),
                word: r.word(0).unwrap_or(0),
            })
        }
    }
}

fn end_board_reply(f: &CanFrame) -> Option<EndBoardReply> {
    (f.standard_raw_id().map(Address::from_raw) == Some(Address::EndBoardRegisterReply))
        .then(|| EndBoardReply::decode(f.data()))
        .flatten()
}

/// `whj read --broadcast`: connects each joint (IAP release, identity for the current
/// scale; a silent one is named by the result), then runs [`plan_broadcast_read`].
pub fn broadcast_read(
    bus: &JointBus,
    ids: &[JointId],
    addr: RegisterAddr,
    count: Option<u8>,
    end_board: Option<u8>,
) -> Result<(BroadcastPlan, Vec<DeviceResult<Slot, RegisterReport>>), OpError> {
    let plan = plan_broadcast_read(ids, addr, count, end_board)?;
    for &id in ids {
        let _ = bus.joint(id);
    }
    let results = run_broadcast_plan(bus, &plan, false)?;
    Ok((plan, results))
}

/// `whj write --broadcast`: checks the register's safety class and the confirmation
/// first, connects each joint (a silent one is reported and left out of the frame: its
/// firmware cannot be checked), plans the frames with each joint's current scale (or
/// `scale`), and runs them ([`run_broadcast_plan`]).
#[allow(clippy::too_many_arguments)]
pub fn broadcast_write(
    bus: &JointBus,
    ids: &[JointId],
    addr: RegisterAddr,
    value: f64,
    raw: bool,
    scale: Option<CurrentScale>,
    end_board: Option<EndBoardArg>,
    confirmed: bool,
) -> Result<(BroadcastPlan, Vec<DeviceResult<Slot, RegisterReport>>), OpError> {
    check_write(addr, confirmed)?;
    // Plan once up front so bad input is refused before anything is sent.
    let mut dry = plan_broadcast_write(
        ids,
        addr,
        value,
        raw,
        &|_| CurrentScale::OneMilliamp,
        end_board,
    )?;
    let mut gone = Vec::new();
    let mut present = Vec::new();
    for &id in ids {
        match bus.joint(id).and_then(|j| j.identity()) {
            Ok(_) => present.push(id),
            Err(e) => gone.push(DeviceResult::failed(Slot::Joint(id), Failure::from(&e))),
        }
    }
    if present.is_empty() && end_board.is_none() {
        dry.frames.clear();
        dry.notes = vec!["no joint answered: nothing was sent".into()];
        return Ok((dry, gone));
    }
    let plan = plan_broadcast_write(
        &present,
        addr,
        value,
        raw,
        &|j| scale.unwrap_or_else(|| scale_of(bus, j)),
        end_board,
    )?;
    let mut results = run_broadcast_plan(bus, &plan, confirmed)?;
    results.extend(gone);
    results.sort_by_key(|r| match r.id {
        Slot::Joint(j) => u16::from(j.get()),
        Slot::EndBoard => u16::MAX,
    });
    Ok((plan, results))
}

// ---------------------------------------------------------------------------------------
// Broadcast waves (0x2F / 0x4F)
// ---------------------------------------------------------------------------------------

/// The lowest frame rate of a broadcast wave: a joint that gets no 0x2F frame for 20 ms
/// stops by itself (the communication watchdog of broadcast position servo), so frames
/// must never be more than 10 ms apart.
pub const BROADCAST_WAVE_MIN_HZ: f64 = 100.0;

/// The point-to-point servo frames of a wave plan as broadcast frames: position targets in
/// 0x2F, currents in 0x4F, the joint's slot only, reply mask "this joint". Speed waves
/// have no broadcast frame.
fn as_broadcast(mut plan: Plan, args: &WaveArgs) -> Result<Plan, OpError> {
    let joint = args.joint;
    let mask = ReplyMask::only(joint).ok_or_else(|| {
        OpError::invalid(
            "wave <JOINT> --broadcast",
            joint.get(),
            "broadcast frames address joints 1..=7 only",
        )
    })?;
    match args.servo {
        ServoLoop::Speed => {
            return Err(OpError::invalid(
                "wave --mode --broadcast",
                "speed",
                "the broadcast protocol has position (0x2F) and current (0x4F) frames only",
            ));
        }
        ServoLoop::Position if args.rate_hz < BROADCAST_WAVE_MIN_HZ => {
            return Err(OpError::invalid(
                "--rate-hz",
                args.rate_hz,
                format!(
                    "{BROADCAST_WAVE_MIN_HZ}..=1000 with --broadcast: a joint stops a \
                     broadcast position stream after 20 ms without a frame"
                ),
            ));
        }
        _ => {}
    }
    let no_data = || OpError::invalid("wave", "value", "a target that reads as \"no data\"");
    for f in &mut plan.frames {
        f.request = match f.request {
            Request::PositionServo { target, .. } => Request::BroadcastPosition(
                BroadcastPosition::new(mask)
                    .with_target(joint, target)
                    .ok_or_else(no_data)?,
            ),
            Request::CurrentServo { target, .. } => Request::BroadcastCurrent(
                BroadcastCurrent::new(mask)
                    .with_target(joint, target)
                    .ok_or_else(no_data)?,
            ),
            other => other,
        };
    }
    plan.notes.push(format!(
        "sent as broadcast {} frames (reply mask {:#X}: joint {} answers); the joint stops by \
         itself 20 ms after the last position frame, holding where it is",
        if args.servo == ServoLoop::Position {
            "position (0x2F)"
        } else {
            "current (0x4F)"
        },
        mask.get(),
        joint.get()
    ));
    Ok(plan)
}

/// `whj wave --broadcast` dry run: [`plan_wave`] as broadcast frames.
pub fn plan_broadcast_wave(
    args: &WaveArgs,
    from_deg: f64,
    scale: CurrentScale,
    assumed: bool,
) -> Result<Plan, OpError> {
    as_broadcast(plan_wave(args, from_deg, scale, assumed)?, args)
}

/// `whj wave --broadcast`: [`prepare_wave`] (the same checks and start position) as
/// broadcast frames; run it with [`execute_wave`](super::execute_wave).
pub fn prepare_broadcast_wave(j: &Joint<'_>, args: &WaveArgs) -> Result<Plan, OpError> {
    as_broadcast(prepare_wave(j, args)?, args)
}

/// Sends one broadcast servo frame and waits one reply timeout for `j`'s 24-byte
/// feedback, received after the frame went out; `None` when none came.
pub(super) fn broadcast_servo(
    j: &Joint<'_>,
    request: Request,
) -> Result<Option<ServoFeedback>, WhjError> {
    let bus = j.bus();
    let sent = bus.send_broadcast(request)?;
    let deadline = sent + bus.config().reply_timeout;
    let mut settle: Option<Instant> = None;
    loop {
        let replies = bus.broadcast_replies_since(sent);
        let mut answers = replies
            .iter()
            .filter_map(|(_, f)| match Reply::from_frame(f) {
                Ok(Reply::BroadcastFeedback { joint, feedback }) if joint == j.id() => {
                    Some(feedback)
                }
                _ => None,
            });
        let first = answers.next();
        let other = answers.find(|a| Some(a) != first.as_ref());
        let now = bus.now();
        if let (Some(a), Some(b)) = (first, other) {
            return Err(WhjError::BadReply {
                joint: j.id(),
                request: "broadcast servo frame".into(),
                reason: format!(
                    "two different answers to one frame (positions {:.4} and {:.4} deg): two \
                     joints answer as one, or one answers twice; neither is credited",
                    a.position.degrees(),
                    b.position.degrees()
                ),
                attempts: 1,
            });
        }
        if first.is_some() && settle.is_none() {
            settle = Some(now + SECOND_ANSWER_GUARD);
        }
        if (first.is_some() && settle.is_some_and(|s| now >= s)) || now >= deadline {
            return Ok(first.map(|f| ServoFeedback {
                current: f.current,
                speed: f.speed,
                position: f.position,
                enable: u16::from(f.is_enabled()),
                error: f.error,
            }));
        }
        let until = settle.unwrap_or(deadline).min(deadline);
        bus.sleep_until(until.min(now + Duration::from_micros(200)));
    }
}
