//! WHJ frames of a candump log: requests and replies decoded and paired.

use robobus_whj::broadcast::SLOTS;
use robobus_whj::registers::{Half, Unit, join_i32, split_i32};
use robobus_whj::reply::{BroadcastRegisterReply, Reply as WhjReply};
use robobus_whj::request::{ReadRange, Request, WriteData};
use robobus_whj::units::CurrentScale;
use robobus_whj::{Address, CanFrame, ErrorCode, JointId, RegisterAddr, RegisterSlot};
use robobus_whj::{RegisterOp, ReplyMask};

use super::{Direction, Entry, EntryKind, Field, hex};

// ---------------------------------------------------------------------------------------
// WHJ frames
// ---------------------------------------------------------------------------------------

/// What the WHJ decoder remembers: the register count each joint last asked for (a read
/// reply is padded to a CAN FD length; the request says how many words are real).
#[derive(Debug, Default)]
pub(super) struct WhjState {
    asked: [Option<u8>; 31],
    /// Per joint, the point-to-point request still waiting for its reply: its line, time,
    /// what it expects and its description. Paired as the client pairs them
    /// (`Expect::answers`): by the joint's reply ID and the reply's content.
    waiting: [Option<Waited>; 31],
}

#[derive(Debug, Clone)]
struct Waited {
    line: u64,
    time: Option<String>,
    expect: crate::whj::session::Expect,
    what: String,
}

impl WhjState {
    /// Pairs entry `e` (just decoded from `frame`) with the requests waiting: a request
    /// ends the wait of an earlier one to the same joint (that one is missing its reply,
    /// returned here to be shown before `e`); a reply is credited to the request it
    /// answers, else marked unexpected (nobody asked, or it answers another request).
    pub(super) fn pair(&mut self, frame: &CanFrame, e: &mut Entry) -> Option<Entry> {
        match e.kind {
            // A malformed request that a joint answers (with a command error) waits for it.
            EntryKind::Malformed if e.direction == Direction::ToDevice => {
                let (joint, _) = Request::decode(frame).err()?.response()?;
                self.wait(
                    joint,
                    e,
                    crate::whj::session::Expect::CmdErr,
                    "a malformed request".into(),
                )
            }
            EntryKind::Request => {
                let req = Request::decode(frame).ok()?;
                let joint = req.joint()?;
                let expect = crate::whj::session::Expect::of(&req)?;
                self.wait(joint, e, expect, crate::whj::session::describe(&req))
            }
            EntryKind::Reply => {
                let Ok(reply) = WhjReply::from_frame(frame) else {
                    return None;
                };
                if matches!(
                    reply,
                    WhjReply::BroadcastFeedback { .. } | WhjReply::BroadcastRegister { .. }
                ) {
                    return None;
                }
                let slot = self.waiting.get_mut(usize::from(reply.joint().get()))?;
                let why = match slot
                    .as_ref()
                    .map(|w| (w.line, w.expect.answers(&reply, frame)))
                {
                    Some((_, Ok(()))) => {
                        *slot = None;
                        return None;
                    }
                    Some((line, Err((_, why)))) => {
                        format!("answers no waiting request ({why}; waiting since line {line})")
                    }
                    None => "no request to this joint was waiting for it".into(),
                };
                e.kind = EntryKind::Unexpected;
                e.text = format!("UNEXPECTED: {why}: {}", e.text);
                e.malformed = Some(why);
                None
            }
            _ => None,
        }
    }

    /// Joint `joint` now waits for `expect` (the request of entry `e`); an earlier wait of
    /// the same joint ends as a missing reply, returned.
    fn wait(
        &mut self,
        joint: JointId,
        e: &Entry,
        expect: crate::whj::session::Expect,
        what: String,
    ) -> Option<Entry> {
        let slot = self.waiting.get_mut(usize::from(joint.get()))?;
        let before = slot.take().map(|w| w.missing(&format!("line {}", e.line)));
        *slot = Some(Waited {
            line: e.line,
            time: e.time.clone(),
            expect,
            what,
        });
        before
    }

    /// The requests still waiting at the end of the capture, as missing replies.
    pub(super) fn finish(&mut self) -> Vec<Entry> {
        let mut out: Vec<Entry> = self
            .waiting
            .iter_mut()
            .filter_map(Option::take)
            .map(|w| w.missing("the end of the capture"))
            .collect();
        out.sort_by_key(|e| e.line);
        out
    }
}

impl Waited {
    fn missing(self, before: &str) -> Entry {
        let mut e = Entry::new(
            self.line,
            self.time,
            Direction::FromDevice,
            EntryKind::Missing,
        );
        e.text = format!("NO REPLY to {} (none before {before})", self.what);
        e.command = Some(self.expect.name().into());
        e
    }
}

fn decimals(unit: Unit) -> usize {
    match unit {
        Unit::Position => 4,
        Unit::TargetSpeed => 3,
        Unit::ActualSpeed | Unit::Voltage => 2,
        Unit::Temperature | Unit::Acceleration => 1,
        _ => 0,
    }
}

/// The voltage and temperature fields every status-like reply carries.
fn supply_fields(fields: &mut Vec<Field>, voltage: i16, temperature: i16, scale: CurrentScale) {
    fields.push(unit_field(
        "voltage",
        Unit::Voltage,
        i32::from(voltage),
        scale,
    ));
    fields.push(unit_field(
        "temperature",
        Unit::Temperature,
        i32::from(temperature),
        scale,
    ));
}

fn unit_field(name: impl Into<String>, unit: Unit, raw: i32, scale: CurrentScale) -> Field {
    let (value, symbol) = match unit {
        Unit::Current => (f64::from(raw) * f64::from(scale.ma_per_count()), "mA"),
        Unit::SpeedLimit | Unit::Raw | Unit::Flag | Unit::Enum => (f64::from(raw), ""),
        u => (f64::from(raw) * u.scale().unwrap_or(1.0), u.symbol()),
    };
    Field::new(name, i64::from(raw), value, symbol, decimals(unit))
}

fn error_names(code: ErrorCode, out: &mut Vec<&'static str>) {
    out.extend(code.iter().map(|b| b.name));
}

fn is_error_register(addr: u8) -> bool {
    addr == 0x04 || addr == 0x78
}

/// Registers from `start` holding `words`: pairs joined into one value, each by name
/// with its unit.
fn register_fields(
    start: u8,
    words: &[u16],
    scale: CurrentScale,
    prefix: &str,
    fields: &mut Vec<Field>,
    errors: &mut Vec<&'static str>,
) {
    let mut i = 0;
    while let Some(&word) = words.get(i) {
        let Some(addr) = u8::try_from(usize::from(start) + i).ok() else {
            break;
        };
        let info = RegisterAddr::new(addr).ok().and_then(RegisterAddr::info);
        match info {
            Some(info) if info.half == Half::Low && words.get(i + 1).is_some() => {
                let high = words.get(i + 1).copied().unwrap_or(0);
                let name = info.name.strip_suffix("_L").unwrap_or(info.name);
                fields.push(unit_field(
                    format!("{prefix}{name}"),
                    info.unit,
                    join_i32(word, high),
                    scale,
                ));
                i += 2;
            }
            Some(info) => {
                let raw = match (info.half, info.unit) {
                    (Half::Single, Unit::Voltage | Unit::Temperature) => {
                        i32::from(i16::from_le_bytes(word.to_le_bytes()))
                    }
                    _ => i32::from(word),
                };
                let unit = if info.half == Half::Single {
                    info.unit
                } else {
                    Unit::Raw
                };
                fields.push(unit_field(
                    format!("{prefix}{}", info.name),
                    unit,
                    raw,
                    scale,
                ));
                if is_error_register(addr) {
                    error_names(ErrorCode(word), errors);
                }
                i += 1;
            }
            None => {
                fields.push(Field::raw(format!("{prefix}{addr:#04x}"), word));
                i += 1;
            }
        }
    }
}

fn reg_name(addr: RegisterAddr) -> String {
    addr.info()
        .map_or_else(|| format!("{addr}"), |i| i.name.to_owned())
}

fn write_fields(
    addr: RegisterAddr,
    data: WriteData,
    scale: CurrentScale,
    prefix: &str,
    fields: &mut Vec<Field>,
    errors: &mut Vec<&'static str>,
) {
    match data {
        WriteData::Byte(b) => {
            register_fields(addr.get(), &[u16::from(b)], scale, prefix, fields, errors);
        }
        WriteData::Word(w) => register_fields(addr.get(), &[w], scale, prefix, fields, errors),
        WriteData::Pair(v) => {
            register_fields(addr.get(), &split_i32(v), scale, prefix, fields, errors);
        }
    }
}

fn read_text(range: ReadRange) -> String {
    format!(
        "read {} register{} from {} {}",
        range.count(),
        if range.count() == 1 { "" } else { "s" },
        range.start(),
        reg_name(range.start())
    )
}

fn mask_text(mask: ReplyMask) -> String {
    let joints: Vec<String> = mask.joints().map(|j| j.to_string()).collect();
    if joints.is_empty() {
        "no replies asked".into()
    } else {
        format!("replies from {}", joints.join(" "))
    }
}

fn join_fields(fields: &[Field]) -> String {
    fields
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}

fn errors_text(errors: &[&str]) -> String {
    if errors.is_empty() {
        "no errors".into()
    } else {
        format!("errors: {}", errors.join(", "))
    }
}

fn joint_slot(i: usize) -> String {
    format!("J{} ", i + 1)
}

impl WhjState {
    pub(super) fn decode(&mut self, frame: &CanFrame, scale: CurrentScale) -> Entry {
        let mut e =
            Entry::new(0, None, Direction::Unknown, EntryKind::Other).with_bytes(frame.data());
        e.can_id = Some(frame.raw_id());
        let Some(raw) = frame.standard_raw_id() else {
            return e.malformed("extended 29-bit identifier (WHJ uses 11-bit IDs)");
        };
        let request = |e: Entry| {
            let mut e = e;
            e.direction = Direction::ToDevice;
            e
        };
        match Address::from_raw(raw) {
            Address::Joint { function, .. } | Address::InterfaceBoard { function }
                if function.is_request() =>
            {
                self.request(request(e), frame, scale)
            }
            Address::Broadcast(_) => self.request(request(e), frame, scale),
            Address::Joint { .. }
            | Address::BroadcastFeedback(_)
            | Address::BroadcastRegisterReply(_) => {
                e.direction = Direction::FromDevice;
                self.reply(e, frame, scale)
            }
            Address::InterfaceBoard { function } => {
                e.direction = Direction::FromDevice;
                e.text = format!("interface board {function:?} frame (not decoded)");
                e
            }
            Address::EndBoardFeedback | Address::EndBoardRegisterReply => {
                e.direction = Direction::FromDevice;
                match robobus_whj::EndBoardReply::decode(frame.data()) {
                    Some(r) => {
                        e.text = end_board_text(&r);
                        e
                    }
                    None => e.malformed("end-board reply shorter than its 8-byte header"),
                }
            }
            Address::IapData => {
                e.direction = Direction::ToDevice;
                e.text = "firmware update data (not decoded)".into();
                e
            }
            Address::Unknown(id) => e.malformed(format!("CAN ID {id:#05x} is not a WHJ ID")),
        }
    }

    #[allow(clippy::too_many_lines, clippy::many_single_char_names)] // one arm per request kind reads best
    fn request(&mut self, mut e: Entry, frame: &CanFrame, scale: CurrentScale) -> Entry {
        let req = match Request::decode(frame) {
            Ok(r) => r,
            Err(m) => {
                e.device = m.joint.map(JointId::get);
                return e.malformed(m.reason.to_string());
            }
        };
        e.kind = EntryKind::Request;
        e.device = req.joint().map(JointId::get);
        let who = req.joint().map_or_else(String::new, |j| format!("{j} "));
        let (command, text) = match req {
            Request::Read { joint, range } => {
                if let Some(slot) = self.asked.get_mut(usize::from(joint.get())) {
                    *slot = Some(range.count());
                }
                ("read", read_text(range))
            }
            Request::Write { addr, data, .. } => {
                write_fields(addr, data, scale, "", &mut e.fields, &mut e.errors);
                ("write", format!("write {}", join_fields(&e.fields)))
            }
            Request::PositionServo { target, .. } => {
                e.fields.push(unit_field(
                    "target position",
                    Unit::Position,
                    target.0,
                    scale,
                ));
                ("position servo", format!("position servo {}", e.fields[0]))
            }
            Request::SpeedServo { target, .. } => {
                e.fields.push(unit_field(
                    "target speed",
                    Unit::TargetSpeed,
                    target.0,
                    scale,
                ));
                ("speed servo", format!("speed servo {}", e.fields[0]))
            }
            Request::CurrentServo { target, .. } => {
                e.fields
                    .push(unit_field("target current", Unit::Current, target.0, scale));
                ("current servo", format!("current servo {}", e.fields[0]))
            }
            Request::StatusQuery { .. } => ("status query", "status query".into()),
            Request::BroadcastPosition(b) => {
                let mut parts = Vec::new();
                for (i, slot) in b.slots.iter().enumerate() {
                    let p = joint_slot(i);
                    match slot {
                        Some(s) => {
                            let f = unit_field(
                                format!("{p}position"),
                                Unit::Position,
                                s.position.0,
                                scale,
                            );
                            parts.push(f.to_string());
                            e.fields.push(f);
                            if s.speed_ff != 0 {
                                let f = unit_field(
                                    format!("{p}speed feed-forward"),
                                    Unit::TargetSpeed,
                                    i32::from(s.speed_ff),
                                    scale,
                                );
                                parts.push(f.to_string());
                                e.fields.push(f);
                            }
                            if s.current_ff != 0 {
                                let raw = i32::from(s.current_ff);
                                let f = Field::new(
                                    format!("{p}current feed-forward"),
                                    i64::from(raw),
                                    f64::from(raw * robobus_whj::units::CURRENT_FF_MA_PER_COUNT),
                                    "mA",
                                    0,
                                );
                                parts.push(f.to_string());
                                e.fields.push(f);
                            }
                        }
                        None => parts.push(format!("{p}no data")),
                    }
                }
                (
                    "broadcast position",
                    format!(
                        "broadcast position: {}; {}",
                        parts.join(", "),
                        mask_text(b.mask)
                    ),
                )
            }
            Request::BroadcastCurrent(b) => {
                let mut parts = Vec::new();
                for (i, slot) in b.slots.iter().enumerate() {
                    let p = joint_slot(i);
                    match slot {
                        Some(c) => {
                            let f = unit_field(format!("{p}current"), Unit::Current, c.0, scale);
                            parts.push(f.to_string());
                            e.fields.push(f);
                        }
                        None => parts.push(format!("{p}no data")),
                    }
                }
                (
                    "broadcast current",
                    format!(
                        "broadcast current: {}; {}",
                        parts.join(", "),
                        mask_text(b.mask)
                    ),
                )
            }
            Request::BroadcastRegister(b) => {
                let mut parts = Vec::new();
                for (i, slot) in b.slots.iter().enumerate().take(SLOTS) {
                    let p = joint_slot(i);
                    match slot {
                        RegisterSlot::Empty => {}
                        RegisterSlot::Op(RegisterOp::Read(range)) => {
                            parts.push(format!("{p}{}", read_text(*range)));
                        }
                        RegisterSlot::Op(RegisterOp::Write { addr, data }) => {
                            let mut fs = Vec::new();
                            write_fields(*addr, *data, scale, "", &mut fs, &mut e.errors);
                            parts.push(format!("{p}write {}", join_fields(&fs)));
                            e.fields.extend(fs.into_iter().map(|mut f| {
                                f.name = format!("{p}{}", f.name);
                                f
                            }));
                        }
                        RegisterSlot::Invalid(bytes) => {
                            parts.push(format!("{p}invalid slot {}", hex(bytes)));
                        }
                    }
                }
                if parts.is_empty() {
                    parts.push("no operations".into());
                }
                (
                    "broadcast register",
                    format!(
                        "broadcast register: {}; {}",
                        parts.join(", "),
                        mask_text(b.mask)
                    ),
                )
            }
            Request::BroadcastStatus(b) => (
                "broadcast status query",
                format!("broadcast status query; {}", mask_text(b.mask)),
            ),
        };
        e.command = Some(command.into());
        e.text = format!("{who}{text}");
        e
    }

    #[allow(clippy::too_many_lines)] // one arm per reply kind reads best
    fn reply(&self, mut e: Entry, frame: &CanFrame, scale: CurrentScale) -> Entry {
        let reply = match WhjReply::from_frame(frame) {
            Ok(r) => r,
            Err(err) => return e.malformed(err.reason.to_string()),
        };
        e.kind = EntryKind::Reply;
        let joint = reply.joint();
        e.device = Some(joint.get());
        let (command, text) = match reply {
            WhjReply::Read { addr, words, .. } => {
                let words = match self.asked.get(usize::from(joint.get())).copied().flatten() {
                    Some(n) => words.truncated(usize::from(n)),
                    None => words,
                };
                register_fields(
                    addr.get(),
                    words.as_slice(),
                    scale,
                    "",
                    &mut e.fields,
                    &mut e.errors,
                );
                (
                    "read reply",
                    format!("read reply: {}", join_fields(&e.fields)),
                )
            }
            WhjReply::WriteAck { addr, status, .. } => (
                "write ack",
                format!(
                    "write ack {}: {}",
                    reg_name(addr),
                    if status.is_ok() {
                        "ok".to_owned()
                    } else {
                        format!("{status:?}").to_lowercase()
                    }
                ),
            ),
            WhjReply::CmdErr { code, error, .. } => {
                e.fields.push(Field::raw("code", code));
                ("command error", format!("command error: {error}"))
            }
            WhjReply::ServoFeedback { feedback: f, .. } => {
                e.fields
                    .push(unit_field("position", Unit::Position, f.position.0, scale));
                e.fields
                    .push(unit_field("speed", Unit::ActualSpeed, f.speed.0, scale));
                e.fields
                    .push(unit_field("current", Unit::Current, f.current.0, scale));
                e.fields.push(Field::raw("enabled", f.enable));
                error_names(f.error, &mut e.errors);
                (
                    "servo feedback",
                    format!(
                        "servo feedback: {}, {}, {}",
                        join_fields(&e.fields[..3]),
                        if f.is_enabled() {
                            "enabled"
                        } else {
                            "disabled"
                        },
                        errors_text(&e.errors)
                    ),
                )
            }
            WhjReply::Status { status: s, .. } => {
                e.fields
                    .push(unit_field("position", Unit::Position, s.position.0, scale));
                if let Some(c) = s.current {
                    e.fields
                        .push(unit_field("current", Unit::Current, c.0, scale));
                }
                supply_fields(&mut e.fields, s.voltage.0, s.temperature.0, scale);
                let shown = join_fields(&e.fields);
                e.fields.push(Field::raw("enabled", s.enable));
                e.fields.push(Field::raw("brake", s.brake));
                error_names(s.error, &mut e.errors);
                (
                    "status",
                    format!(
                        "status: {shown}, {}, brake {}, {}",
                        if s.is_enabled() {
                            "enabled"
                        } else {
                            "disabled"
                        },
                        if s.brake_locked() {
                            "locked"
                        } else {
                            "released"
                        },
                        errors_text(&e.errors)
                    ),
                )
            }
            WhjReply::BroadcastFeedback { feedback: f, .. } => {
                e.fields
                    .push(unit_field("position", Unit::Position, f.position.0, scale));
                e.fields
                    .push(unit_field("speed", Unit::ActualSpeed, f.speed.0, scale));
                e.fields
                    .push(unit_field("current", Unit::Current, f.current.0, scale));
                supply_fields(&mut e.fields, f.voltage.0, f.temperature.0, scale);
                let shown = join_fields(&e.fields);
                e.fields.push(Field::raw("state", f.state));
                e.fields.push(Field::raw("counter", f.counter));
                error_names(f.error, &mut e.errors);
                (
                    "broadcast feedback",
                    format!(
                        "broadcast feedback: {shown}, {}, brake {}, counter {}, {}",
                        if f.is_enabled() {
                            "enabled"
                        } else {
                            "disabled"
                        },
                        if f.brake_locked() {
                            "locked"
                        } else {
                            "released"
                        },
                        f.counter,
                        errors_text(&e.errors)
                    ),
                )
            }
            WhjReply::BroadcastRegister { reply, .. } => match reply {
                BroadcastRegisterReply::WriteAck { addr, status } => (
                    "broadcast register write ack",
                    format!(
                        "broadcast register write ack {}: {}",
                        reg_name(addr),
                        if status.is_ok() {
                            "ok".to_owned()
                        } else {
                            format!("{status:?}").to_lowercase()
                        }
                    ),
                ),
                BroadcastRegisterReply::Read { addr, words, .. } => {
                    register_fields(
                        addr.get(),
                        words.as_slice(),
                        scale,
                        "",
                        &mut e.fields,
                        &mut e.errors,
                    );
                    (
                        "broadcast register read reply",
                        format!("broadcast register read reply: {}", join_fields(&e.fields)),
                    )
                }
            },
        };
        e.command = Some(command.into());
        e.text = format!("{joint} {text}");
        e
    }
}

/// An end-board reply in words: the register answered (by its name in the end board's
/// map), the data, and the status byte.
fn end_board_text(r: &robobus_whj::EndBoardReply) -> String {
    let name = robobus_whj::broadcast::EndBoardRegister::by_addr(r.index)
        .map_or("(reserved)", |reg| reg.name);
    let what = match r.cmd {
        robobus_whj::broadcast::END_BOARD_READ => {
            let n = usize::from(r.len / 2).min(r.data().len() / 2);
            let words: Vec<String> = (0..n)
                .filter_map(|i| r.word(i))
                .map(|w| format!("{w:#06x}"))
                .collect();
            format!("read {:#04x} {name} = {}", r.index, words.join(" "))
        }
        robobus_whj::broadcast::END_BOARD_WRITE => format!(
            "write {:#04x} {name} {}",
            r.index,
            if r.write_ok() { "ok" } else { "failed" }
        ),
        _ => "no operation".into(),
    };
    format!(
        "end board: {what} (counter {}, status0 {:#04x}, error {:#04x})",
        r.counter, r.status0, r.sys_error
    )
}
