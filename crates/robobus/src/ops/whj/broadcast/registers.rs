//! 0x0F register access: `whj read / write --broadcast`, planned as frames and run with
//! each slot's reply credited (joints 1..=7 and the end board's register).

use robobus_whj::broadcast::{
    BroadcastRegister, EndBoardOp, EndBoardRegister, EndBoardReply, RegisterOp, ReplyMask,
};
use robobus_whj::reply::BroadcastRegisterReply;
use robobus_whj::request::{ReadRange, WriteData};
use robobus_whj::units::CurrentScale;
use robobus_whj::{Address, CanFrame, JointId, RegisterAddr, RegisterInfo, Reply, Request};

use super::{Slot, collect, reply_mask_with, scale_of, silent};
use crate::ops::whj::{
    END_BOARD_WRITE_TEXT, RegisterReport, check_joint_write, check_write, confirm_text,
    register_report, whj, word_reports, write_request,
};
use crate::ops::{DeviceResult, ErrorKind, Failure, OpError};
use crate::whj::{JointBus, RegisterValue};

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
