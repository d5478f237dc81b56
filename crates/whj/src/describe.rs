//! Requests and replies in words: one text form ([`fmt::Display`], with a joint's current
//! scale through [`Request::display`] / [`Reply::display`]) and one list of decoded values
//! ([`Request::fields`], [`Reply::fields`]), registers by name with their values in their
//! units. `robobus replay`, the client's error messages and the CLI show these.
//!
//! ```
//! use robobus_whj::{JointId, ReadRange, Reply, Request, registers::addr};
//! use robobus_whj::units::{CurrentScale, Position};
//!
//! let j1 = JointId::new(1)?;
//! let cmd = Request::PositionServo { joint: j1, target: Position::from_degrees(12.5)? };
//! assert_eq!(cmd.to_string(), "J1 position servo target position 12.5000 °");
//! let write = Request::enable(j1, true);
//! assert_eq!((write.name(), write.to_string().as_str()), ("write", "J1 write SYS_ENABLE_DRIVER 1"));
//! let fields = write.fields(CurrentScale::OneMilliamp);
//! assert_eq!((fields.as_slice()[0].raw, fields.as_slice()[0].unit), (1, ""));
//!
//! let read = Request::read_position(j1);
//! assert_eq!(read.to_string(), "J1 read 2 registers from 0x14 CUR_POSITION_L");
//! let range = ReadRange::new(addr::CUR_POSITION, 2)?;
//! let reply = Reply::read(j1, range, &[0x86A0, 0x0001])?;
//! assert_eq!(reply.to_string(), "J1 read reply: CUR_POSITION 10.0000 °");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! Allocation-free: a frame has at most 31 values (a read reply of 31 registers), held in
//! a [`Fields`] of fixed capacity.

use core::fmt;

use crate::broadcast::{
    END_BOARD_READ, END_BOARD_WRITE, EndBoardRegister, EndBoardReply, RegisterOp, RegisterSlot,
    ReplyMask, SLOTS,
};
use crate::registers::{self, Half, MAX_READ_COUNT, RegisterInfo, Unit, join_i32};
use crate::reply::{BroadcastRegisterReply, Reply, WriteStatus};
use crate::request::{ReadRange, Request};
use crate::units::{
    ActualSpeed, CURRENT_FF_MA_PER_COUNT, Current, CurrentScale, Position, Temperature, Voltage,
};
use crate::{ErrorCode, JointId, RegisterAddr};

impl Unit {
    /// Engineering units per count of a value in this unit on a joint with current scale
    /// `scale`: [`Unit::scale`], and the joint's mA per count for a current; `None` where
    /// a value is shown raw (identifiers, flags, enumerations, and the speed limit, whose
    /// unit depends on the firmware, C3).
    pub fn per_count(self, scale: CurrentScale) -> Option<f64> {
        match self {
            Self::Current => Some(f64::from(scale.ma_per_count())),
            Self::SpeedLimit => None,
            u => u.scale(),
        }
    }

    /// The decimals a value in this unit is shown with: its resolution (0.0001° → 4,
    /// 0.002 RPM → 3, 0.02 RPM and 0.01 V → 2, 0.1 °C and 0.1 rpm/s → 1, else 0).
    pub const fn decimals(self) -> usize {
        match self {
            Self::Position => 4,
            Self::TargetSpeed => 3,
            Self::ActualSpeed | Self::Voltage => 2,
            Self::Temperature | Self::Acceleration => 1,
            _ => 0,
        }
    }
}

impl RegisterInfo {
    /// The raw value of this register from its one word: a signed 16-bit value, except
    /// identifiers, flags and enumerations (unsigned).
    #[allow(clippy::cast_possible_wrap)] // registers are signed 16-bit words
    pub const fn word_value(&self, word: u16) -> i32 {
        match self.unit {
            Unit::Raw | Unit::Enum | Unit::Flag => word as i32,
            _ => word as i16 as i32,
        }
    }
}

/// What a decoded value is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FieldName {
    /// A quantity (`position`, `target speed`) or a register by name (a pair by its name
    /// without `_L`: `CUR_POSITION`).
    Named(&'static str),
    /// A register the table does not name, by address (`0x06`).
    Reserved(u8),
}

impl fmt::Display for FieldName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Named(name) => f.write_str(name),
            Self::Reserved(addr) => write!(f, "{addr:#04x}"),
        }
    }
}

/// One decoded value of a frame: a register, a target, a feedback quantity.
///
/// Shown as `name value unit` with the unit's decimals (`CUR_POSITION 10.0000 °`), after
/// the joint of its slot in a broadcast frame (`J3 position 12.5000 °`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Field {
    /// The joint whose slot of a broadcast frame the value is in.
    pub slot: Option<JointId>,
    /// What the value is.
    pub name: FieldName,
    /// The raw value on the wire.
    pub raw: i64,
    /// The value in `unit` (the raw value where there is no unit).
    pub value: f64,
    /// The unit symbol (`°`, `RPM`, `mA`, `V`, `°C`), empty for unitless values.
    pub unit: &'static str,
    /// The decimals the value is shown with.
    pub decimals: usize,
}

impl Field {
    const EMPTY: Self = Self::raw("", 0);

    /// A value in `unit`, converted with the joint's current scale ([`Unit::per_count`]);
    /// a current in counts where the scale is not known.
    fn of(name: &'static str, unit: Unit, raw: i32, scale: Option<CurrentScale>) -> Self {
        let per_count = match (unit, scale) {
            (Unit::Current, None) => None,
            (_, scale) => unit.per_count(scale.unwrap_or_default()),
        };
        Self {
            slot: None,
            name: FieldName::Named(name),
            raw: i64::from(raw),
            value: f64::from(raw) * per_count.unwrap_or(1.0),
            unit: match (per_count, unit) {
                (Some(_), _) => unit.symbol(),
                (None, Unit::Current) => "counts",
                (None, _) => "",
            },
            decimals: unit.decimals(),
        }
    }

    /// A unitless value.
    #[allow(clippy::cast_precision_loss)] // raw values are at most 32 bits
    const fn raw(name: &'static str, raw: i64) -> Self {
        Self {
            slot: None,
            name: FieldName::Named(name),
            raw,
            value: raw as f64,
            unit: "",
            decimals: 0,
        }
    }

    const fn in_slot(mut self, slot: Option<JointId>) -> Self {
        self.slot = slot;
        self
    }
}

impl fmt::Display for Field {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(joint) = self.slot {
            write!(f, "{joint} ")?;
        }
        write!(f, "{} {:.*}", self.name, self.decimals, self.value)?;
        if !self.unit.is_empty() {
            write!(f, " {}", self.unit)?;
        }
        Ok(())
    }
}

/// Most error codes one frame carries (a broadcast register frame writing an error
/// register in every slot).
const MAX_ERROR_CODES: usize = SLOTS + 1;

/// The decoded values of a frame, in the order of the frame, and the error codes it
/// carries (feedback and status error bits, an error register read or written).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fields {
    values: [Field; MAX_READ_COUNT as usize],
    len: usize,
    errors: [ErrorCode; MAX_ERROR_CODES],
    error_count: usize,
}

impl Fields {
    const EMPTY: Self = Self {
        values: [Field::EMPTY; MAX_READ_COUNT as usize],
        len: 0,
        errors: [ErrorCode(0); MAX_ERROR_CODES],
        error_count: 0,
    };

    /// The values.
    pub fn as_slice(&self) -> &[Field] {
        self.values.get(..self.len).unwrap_or_default()
    }

    /// The values, in order.
    pub fn iter(&self) -> core::slice::Iter<'_, Field> {
        self.as_slice().iter()
    }

    /// Number of values.
    pub const fn len(&self) -> usize {
        self.len
    }

    /// Whether there are none.
    pub const fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The error codes, in the order of the frame.
    pub fn error_codes(&self) -> &[ErrorCode] {
        self.errors.get(..self.error_count).unwrap_or_default()
    }

    /// The names of the error bits set ([`ErrorCode::iter`]), code after code.
    pub fn errors(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.error_codes()
            .iter()
            .flat_map(|code| code.iter().map(|bit| bit.name))
    }

    fn push(&mut self, field: Field) {
        if let Some(slot) = self.values.get_mut(self.len) {
            *slot = field;
            self.len += 1;
        }
    }

    fn push_error(&mut self, code: ErrorCode) {
        if let Some(slot) = self.errors.get_mut(self.error_count) {
            *slot = code;
            self.error_count += 1;
        }
    }

    /// Position, speed and current of a feedback frame.
    fn push_motion(
        &mut self,
        position: Position,
        speed: ActualSpeed,
        current: Current,
        scale: Option<CurrentScale>,
    ) {
        self.push(Field::of("position", Unit::Position, position.0, scale));
        self.push(Field::of("speed", Unit::ActualSpeed, speed.0, scale));
        self.push(Field::of("current", Unit::Current, current.0, scale));
    }

    /// Voltage and temperature of a status or feedback frame.
    fn push_supply(&mut self, voltage: Voltage, temperature: Temperature) {
        let (v, t) = (i32::from(voltage.0), i32::from(temperature.0));
        self.push(Field::of("voltage", Unit::Voltage, v, None));
        self.push(Field::of("temperature", Unit::Temperature, t, None));
    }

    /// The registers from `start` holding `words`: a pair joined into one value, each by
    /// name in its unit; an error register's bits also as an error code.
    fn push_registers(
        &mut self,
        slot: Option<JointId>,
        start: u8,
        words: &[u16],
        scale: Option<CurrentScale>,
    ) {
        let mut i = 0;
        while let Some(&word) = words.get(i) {
            let Some(addr) = u8::try_from(usize::from(start) + i).ok() else {
                break;
            };
            let field = match (RegisterInfo::by_raw(addr), words.get(i + 1)) {
                (Some(info), Some(&high)) if info.half == Half::Low => {
                    let name = info.name.strip_suffix("_L").unwrap_or(info.name);
                    i += 1;
                    Field::of(name, info.unit, join_i32(word, high), scale)
                }
                (Some(info), _) if info.half == Half::Single => {
                    if addr == registers::addr::SYS_ERROR.get()
                        || addr == registers::addr::ERROR.get()
                    {
                        self.push_error(ErrorCode(word));
                    }
                    Field::of(info.name, info.unit, info.word_value(word), scale)
                }
                // Half of a pair alone: its word, raw.
                (Some(info), _) => Field::raw(info.name, i64::from(word)),
                (None, _) => Field {
                    name: FieldName::Reserved(addr),
                    ..Field::raw("", i64::from(word))
                },
            };
            self.push(field.in_slot(slot));
            i += 1;
        }
    }

    /// Writes the values `range` of those of joint `slot`, separated by `, `, each without
    /// its slot.
    fn write_joined(
        &self,
        f: &mut fmt::Formatter<'_>,
        range: core::ops::Range<usize>,
        slot: Option<JointId>,
    ) -> fmt::Result {
        let shown = self.as_slice().get(range).unwrap_or_default();
        for (i, field) in shown.iter().filter(|x| x.slot == slot).enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            write!(f, "{}", field.in_slot(None))?;
        }
        Ok(())
    }

    /// Writes all values of joint `slot`.
    fn write_all(&self, f: &mut fmt::Formatter<'_>, slot: Option<JointId>) -> fmt::Result {
        self.write_joined(f, 0..self.len, slot)
    }

    /// `no errors`, or `errors: ` and the names of the error bits.
    fn write_errors(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, name) in self.errors().enumerate() {
            f.write_str(if i == 0 { "errors: " } else { ", " })?;
            f.write_str(name)?;
        }
        if self.errors().next().is_none() {
            f.write_str("no errors")?;
        }
        Ok(())
    }
}

impl<'a> IntoIterator for &'a Fields {
    type Item = &'a Field;
    type IntoIter = core::slice::Iter<'a, Field>;

    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

/// The joint of broadcast slot `i` (0-based).
fn slot_joint(i: usize) -> Option<JointId> {
    u8::try_from(i + 1).ok().and_then(|n| JointId::new(n).ok())
}

/// A register's name, or its address where the table names none.
struct RegName(RegisterAddr);

impl fmt::Display for RegName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0.info() {
            Some(info) => f.write_str(info.name),
            None => write!(f, "{}", self.0),
        }
    }
}

/// `read 2 registers from 0x14 CUR_POSITION_L`.
struct ReadText(ReadRange);

impl fmt::Display for ReadText {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (start, count) = (self.0.start(), self.0.count());
        let s = if count == 1 { "" } else { "s" };
        write!(
            f,
            "read {count} register{s} from {start} {}",
            RegName(start)
        )
    }
}

/// `replies from J1 J3`, or `no replies asked`.
struct MaskText(ReplyMask);

impl fmt::Display for MaskText {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut joints = self.0.joints();
        match joints.next() {
            None => f.write_str("no replies asked"),
            Some(first) => {
                write!(f, "replies from {first}")?;
                joints.try_for_each(|j| write!(f, " {j}"))
            }
        }
    }
}

impl fmt::Display for WriteStatus {
    /// `ok`, `failed`, `unknown(N)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Ok => f.write_str("ok"),
            Self::Failed => f.write_str("failed"),
            Self::Unknown(b) => write!(f, "unknown({b})"),
        }
    }
}

/// A request or reply in words ([`Request::display`], [`Reply::display`]): currents in mA
/// with a joint's current scale, in counts without one (the plain [`fmt::Display`] form).
/// The alternate form (`{:#}`) leaves out the joint a point-to-point frame is for or from
/// (for a message that names it already).
#[derive(Debug, Clone, Copy)]
pub struct Described<'a, T> {
    frame: &'a T,
    scale: Option<CurrentScale>,
}

impl Request {
    /// What the request is: `read`, `write`, `position servo`, `speed servo`, `current
    /// servo`, `status query`, `broadcast position`, `broadcast current`, `broadcast
    /// register`, `broadcast status query`.
    pub const fn name(&self) -> &'static str {
        match self {
            Self::Read { .. } => "read",
            Self::Write { .. } => "write",
            Self::PositionServo { .. } => "position servo",
            Self::SpeedServo { .. } => "speed servo",
            Self::CurrentServo { .. } => "current servo",
            Self::StatusQuery { .. } => "status query",
            Self::BroadcastPosition(_) => "broadcast position",
            Self::BroadcastCurrent(_) => "broadcast current",
            Self::BroadcastRegister(_) => "broadcast register",
            Self::BroadcastStatus(_) => "broadcast status query",
        }
    }

    /// The values the request carries, currents converted with `scale`: the registers a
    /// write sets, a servo target, a broadcast frame's targets and register writes slot
    /// by slot (feed-forward values only where not 0).
    pub fn fields(&self, scale: CurrentScale) -> Fields {
        self.fields_with(Some(scale))
    }

    fn fields_with(&self, scale: Option<CurrentScale>) -> Fields {
        let mut out = Fields::EMPTY;
        match self {
            Self::Read { .. } | Self::StatusQuery { .. } | Self::BroadcastStatus(_) => {}
            Self::Write { addr, data, .. } => {
                let (words, n) = data.words();
                let words = words.get(..n).unwrap_or_default();
                out.push_registers(None, addr.get(), words, scale);
            }
            Self::PositionServo { target, .. } => {
                out.push(Field::of(
                    "target position",
                    Unit::Position,
                    target.0,
                    scale,
                ));
            }
            Self::SpeedServo { target, .. } => {
                out.push(Field::of(
                    "target speed",
                    Unit::TargetSpeed,
                    target.0,
                    scale,
                ));
            }
            Self::CurrentServo { target, .. } => {
                out.push(Field::of("target current", Unit::Current, target.0, scale));
            }
            Self::BroadcastPosition(b) => {
                for (i, slot) in b.slots.iter().enumerate() {
                    let Some(s) = slot else { continue };
                    let joint = slot_joint(i);
                    let position = Field::of("position", Unit::Position, s.position.0, scale);
                    out.push(position.in_slot(joint));
                    if s.speed_ff != 0 {
                        let ff = i32::from(s.speed_ff);
                        let speed = Field::of("speed feed-forward", Unit::TargetSpeed, ff, scale);
                        out.push(speed.in_slot(joint));
                    }
                    if s.current_ff != 0 {
                        let raw = i32::from(s.current_ff);
                        out.push(Field {
                            value: f64::from(raw * CURRENT_FF_MA_PER_COUNT),
                            unit: "mA",
                            ..Field::raw("current feed-forward", i64::from(raw)).in_slot(joint)
                        });
                    }
                }
            }
            Self::BroadcastCurrent(b) => {
                for (i, slot) in b.slots.iter().enumerate() {
                    if let Some(c) = slot {
                        let current = Field::of("current", Unit::Current, c.0, scale);
                        out.push(current.in_slot(slot_joint(i)));
                    }
                }
            }
            Self::BroadcastRegister(b) => {
                for (i, slot) in b.slots.iter().enumerate() {
                    if let RegisterSlot::Op(RegisterOp::Write { addr, data }) = slot {
                        let (words, n) = data.words();
                        let words = words.get(..n).unwrap_or_default();
                        out.push_registers(slot_joint(i), addr.get(), words, scale);
                    }
                }
            }
        }
        out
    }

    /// The request in words with currents converted with `scale` (its [`fmt::Display`]
    /// form shows currents in counts).
    pub const fn display(&self, scale: CurrentScale) -> Described<'_, Self> {
        Described {
            frame: self,
            scale: Some(scale),
        }
    }
}

impl fmt::Display for Described<'_, Request> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let request = self.frame;
        let fields = request.fields_with(self.scale);
        if let (Some(joint), false) = (request.joint(), f.alternate()) {
            write!(f, "{joint} ")?;
        }
        match request {
            Request::Read { range, .. } => write!(f, "{}", ReadText(*range)),
            Request::StatusQuery { .. } => f.write_str(request.name()),
            Request::Write { .. }
            | Request::PositionServo { .. }
            | Request::SpeedServo { .. }
            | Request::CurrentServo { .. } => {
                write!(f, "{} ", request.name())?;
                fields.write_all(f, None)
            }
            Request::BroadcastPosition(b) => {
                let data = b.slots.map(|slot| slot.is_some());
                write_targets(f, request.name(), data, b.mask, &fields)
            }
            Request::BroadcastCurrent(b) => {
                let data = b.slots.map(|slot| slot.is_some());
                write_targets(f, request.name(), data, b.mask, &fields)
            }
            Request::BroadcastRegister(b) => {
                write!(f, "{}: ", request.name())?;
                let mut parts = 0;
                for (i, slot) in b.slots.iter().enumerate() {
                    let Some(joint) = slot_joint(i) else { continue };
                    if *slot == RegisterSlot::Empty {
                        continue;
                    }
                    f.write_str(if parts == 0 { "" } else { ", " })?;
                    parts += 1;
                    match slot {
                        RegisterSlot::Empty => {}
                        RegisterSlot::Op(RegisterOp::Read(range)) => {
                            write!(f, "{joint} {}", ReadText(*range))?;
                        }
                        RegisterSlot::Op(RegisterOp::Write { .. }) => {
                            write!(f, "{joint} write ")?;
                            fields.write_all(f, Some(joint))?;
                        }
                        RegisterSlot::Invalid(bytes) => {
                            write!(f, "{joint} invalid slot")?;
                            bytes.iter().try_for_each(|b| write!(f, " {b:02X}"))?;
                        }
                    }
                }
                if parts == 0 {
                    f.write_str("no operations")?;
                }
                write!(f, "; {}", MaskText(b.mask))
            }
            Request::BroadcastStatus(b) => write!(f, "{}; {}", request.name(), MaskText(b.mask)),
        }
    }
}

/// A broadcast position or current frame: its values slot by slot (`no data` in a slot
/// without), then who is asked to reply.
fn write_targets(
    f: &mut fmt::Formatter<'_>,
    name: &str,
    data: [bool; SLOTS],
    mask: ReplyMask,
    fields: &Fields,
) -> fmt::Result {
    write!(f, "{name}: ")?;
    for (i, data) in data.into_iter().enumerate() {
        if i > 0 {
            f.write_str(", ")?;
        }
        match slot_joint(i) {
            Some(joint) if data => fields
                .iter()
                .filter(|x| x.slot == Some(joint))
                .enumerate()
                .try_for_each(|(k, field)| {
                    let sep = if k > 0 { ", " } else { "" };
                    write!(f, "{sep}{field}")
                })?,
            Some(joint) => write!(f, "{joint} no data")?,
            None => f.write_str("no data")?,
        }
    }
    write!(f, "; {}", MaskText(mask))
}

impl fmt::Display for Request {
    /// The request in words, currents in counts (in mA with [`Request::display`]; the
    /// alternate form leaves out the joint, see [`Described`]):
    /// `J1 write SYS_ENABLE_DRIVER 1`, `J1 read 2 registers from 0x14 CUR_POSITION_L`,
    /// `broadcast position: J1 position 12.5000 °, J2 no data, ...; replies from J1`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        Described {
            frame: self,
            scale: None,
        }
        .fmt(f)
    }
}

impl Reply {
    /// What the reply is: `read reply`, `write ack`, `command error`, `servo feedback`,
    /// `status`, `broadcast feedback`, `broadcast register write ack`, `broadcast register
    /// read reply`.
    pub const fn name(&self) -> &'static str {
        match self {
            Self::Read { .. } => "read reply",
            Self::WriteAck { .. } => "write ack",
            Self::CmdErr { .. } => "command error",
            Self::ServoFeedback { .. } => "servo feedback",
            Self::Status { .. } => "status",
            Self::BroadcastFeedback { .. } => "broadcast feedback",
            Self::BroadcastRegister {
                reply: BroadcastRegisterReply::WriteAck { .. },
                ..
            } => "broadcast register write ack",
            Self::BroadcastRegister {
                reply: BroadcastRegisterReply::Read { .. },
                ..
            } => "broadcast register read reply",
        }
    }

    /// The values the reply carries, currents converted with `scale`, and its error
    /// codes: registers read (all the words given: cut a padded reply to the count asked
    /// with [`Words::truncated`](crate::Words::truncated) first), the command byte of a
    /// `CMD_ERR`, feedback and status quantities with the enable, brake, state and counter
    /// bytes raw.
    pub fn fields(&self, scale: CurrentScale) -> Fields {
        self.fields_with(Some(scale))
    }

    fn fields_with(&self, scale: Option<CurrentScale>) -> Fields {
        let mut out = Fields::EMPTY;
        match self {
            Self::Read { addr, words, .. }
            | Self::BroadcastRegister {
                reply: BroadcastRegisterReply::Read { addr, words, .. },
                ..
            } => out.push_registers(None, addr.get(), words.as_slice(), scale),
            Self::WriteAck { .. }
            | Self::BroadcastRegister {
                reply: BroadcastRegisterReply::WriteAck { .. },
                ..
            } => {}
            Self::CmdErr { code, .. } => out.push(Field::raw("code", i64::from(*code))),
            Self::ServoFeedback { feedback: fb, .. } => {
                out.push_motion(fb.position, fb.speed, fb.current, scale);
                out.push(Field::raw("enabled", i64::from(fb.enable)));
                out.push_error(fb.error);
            }
            Self::Status { status: s, .. } => {
                out.push(Field::of("position", Unit::Position, s.position.0, scale));
                if let Some(c) = s.current {
                    out.push(Field::of("current", Unit::Current, c.0, scale));
                }
                out.push_supply(s.voltage, s.temperature);
                out.push(Field::raw("enabled", i64::from(s.enable)));
                out.push(Field::raw("brake", i64::from(s.brake)));
                out.push_error(s.error);
            }
            Self::BroadcastFeedback { feedback: fb, .. } => {
                out.push_motion(fb.position, fb.speed, fb.current, scale);
                out.push_supply(fb.voltage, fb.temperature);
                out.push(Field::raw("state", i64::from(fb.state)));
                out.push(Field::raw("counter", i64::from(fb.counter)));
                out.push_error(fb.error);
            }
        }
        out
    }

    /// The reply in words with currents converted with `scale` (its [`fmt::Display`] form
    /// shows currents in counts).
    pub const fn display(&self, scale: CurrentScale) -> Described<'_, Self> {
        Described {
            frame: self,
            scale: Some(scale),
        }
    }
}

/// `enabled` or `disabled`.
const fn enabled(on: bool) -> &'static str {
    if on { "enabled" } else { "disabled" }
}

/// `locked` or `released`.
const fn brake(locked: bool) -> &'static str {
    if locked { "locked" } else { "released" }
}

impl fmt::Display for Described<'_, Reply> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let reply = self.frame;
        let fields = reply.fields_with(self.scale);
        if !f.alternate() {
            write!(f, "{} ", reply.joint())?;
        }
        f.write_str(reply.name())?;
        // The quantities shown before the state bytes (raw, after them in the fields).
        let quantities = fields.len().saturating_sub(2);
        match reply {
            Reply::Read { .. }
            | Reply::BroadcastRegister {
                reply: BroadcastRegisterReply::Read { .. },
                ..
            } => {
                f.write_str(": ")?;
                fields.write_all(f, None)
            }
            Reply::WriteAck { addr, status, .. }
            | Reply::BroadcastRegister {
                reply: BroadcastRegisterReply::WriteAck { addr, status },
                ..
            } => write!(f, " {}: {status}", RegName(*addr)),
            Reply::CmdErr { error, .. } => write!(f, ": {error}"),
            Reply::ServoFeedback { feedback: fb, .. } => {
                f.write_str(": ")?;
                fields.write_joined(f, 0..3, None)?;
                write!(f, ", {}, ", enabled(fb.is_enabled()))?;
                fields.write_errors(f)
            }
            Reply::Status { status: s, .. } => {
                f.write_str(": ")?;
                fields.write_joined(f, 0..quantities, None)?;
                let (on, locked) = (enabled(s.is_enabled()), brake(s.brake_locked()));
                write!(f, ", {on}, brake {locked}, ")?;
                fields.write_errors(f)
            }
            Reply::BroadcastFeedback { feedback: fb, .. } => {
                f.write_str(": ")?;
                fields.write_joined(f, 0..quantities, None)?;
                let (on, locked) = (enabled(fb.is_enabled()), brake(fb.brake_locked()));
                write!(f, ", {on}, brake {locked}, counter {}, ", fb.counter)?;
                fields.write_errors(f)
            }
        }
    }
}

impl fmt::Display for Reply {
    /// The reply in words, currents in counts (in mA with [`Reply::display`]; the
    /// alternate form leaves out the joint, see [`Described`]):
    /// `J1 write ack SYS_ENABLE_DRIVER: ok`, `J1 servo feedback: position 10.0000 °, speed
    /// 20.00 RPM, current 500 counts, enabled, errors: over-voltage`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        Described {
            frame: self,
            scale: None,
        }
        .fmt(f)
    }
}

impl fmt::Display for EndBoardReply {
    /// The register answered (by its name in the end board's map), the data and the
    /// status bytes: `end board: write 0x07 EB_VOLTAGE_OUTPUT ok (counter 184, status0
    /// 0x09, error 0x00)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let name = EndBoardRegister::by_addr(self.index).map_or("(reserved)", |reg| reg.name);
        f.write_str("end board: ")?;
        match self.cmd {
            END_BOARD_READ => {
                write!(f, "read {:#04x} {name} =", self.index)?;
                let n = usize::from(self.len / 2).min(self.data().len() / 2);
                (0..n)
                    .filter_map(|i| self.word(i))
                    .try_for_each(|w| write!(f, " {w:#06x}"))?;
            }
            END_BOARD_WRITE => {
                let ok = if self.write_ok() { "ok" } else { "failed" };
                write!(f, "write {:#04x} {name} {ok}", self.index)?;
            }
            _ => f.write_str("no operation")?,
        }
        write!(
            f,
            " (counter {}, status0 {:#04x}, error {:#04x})",
            self.counter, self.status0, self.sys_error
        )
    }
}

#[cfg(test)]
mod tests;
