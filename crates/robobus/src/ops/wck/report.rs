//! The result of one wCK command as named fields (the JSON keys and the table columns).

use robobus_wck::{Command, Position, Reply};
use serde::ser::{Serialize, SerializeMap, Serializer};

/// A field value: a whole number, a number of degrees / volts (two decimals), a text, a
/// flag or a list of whole numbers.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(untagged)]
pub enum FieldValue {
    /// A whole number.
    Int(i64),
    /// A measured quantity, rounded to two decimals.
    Real(f64),
    /// A text.
    Text(String),
    /// A flag.
    Flag(bool),
    /// Whole numbers (positions of a synchronized move, a pose).
    List(Vec<i64>),
}

impl FieldValue {
    /// A quantity rounded to two decimals.
    pub fn real(v: f64) -> Self {
        Self::Real((v * 100.0).round() / 100.0)
    }

    /// The table cell: numbers as they are (reals with one decimal), lists space-separated.
    pub fn cell(&self) -> String {
        match self {
            Self::Int(n) => n.to_string(),
            Self::Real(f) => format!("{f:.1}"),
            Self::Text(s) => s.clone(),
            Self::Flag(b) => b.to_string(),
            Self::List(v) => v
                .iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join(" "),
        }
    }
}

impl From<u8> for FieldValue {
    fn from(v: u8) -> Self {
        Self::Int(i64::from(v))
    }
}
impl From<u16> for FieldValue {
    fn from(v: u16) -> Self {
        Self::Int(i64::from(v))
    }
}
impl From<u32> for FieldValue {
    fn from(v: u32) -> Self {
        Self::Int(i64::from(v))
    }
}
impl From<u64> for FieldValue {
    fn from(v: u64) -> Self {
        Self::Int(i64::try_from(v).unwrap_or(i64::MAX))
    }
}
impl From<bool> for FieldValue {
    fn from(v: bool) -> Self {
        Self::Flag(v)
    }
}
impl From<&str> for FieldValue {
    fn from(v: &str) -> Self {
        Self::Text(v.to_string())
    }
}

/// Named fields in order; serialized as one JSON object.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Fields(pub Vec<(&'static str, FieldValue)>);

impl Fields {
    /// Appends a field.
    pub fn push(&mut self, key: &'static str, value: impl Into<FieldValue>) {
        self.0.push((key, value.into()));
    }

    /// The value of a field.
    pub fn get(&self, key: &str) -> Option<&FieldValue> {
        self.0.iter().find(|(k, _)| *k == key).map(|(_, v)| v)
    }

    fn position(&mut self, key: &'static str, deg_key: &'static str, p: Position) {
        self.push(key, p.get());
        self.0.push((deg_key, FieldValue::real(p.degrees())));
    }
}

impl Serialize for Fields {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(Some(self.0.len()))?;
        for (k, v) in &self.0 {
            m.serialize_entry(k, v)?;
        }
        m.end()
    }
}

/// The fields of a command and its reply (the servo's `id` is beside them, in
/// [`crate::ops::DeviceResult`]). Units are in the names: `position` (0..=254
/// steps), `position10` (0..=1023), `degrees`, `load`, `milliamps`, `baud` (bit/s),
/// `adc_volts`; a move's reply is the status *before* it (`load_before`,
/// `position_before`). A break on a shared bus: see [`BREAK_CLEAN`] and [`BREAK_COLLIDED`].
#[allow(clippy::too_many_lines)] // one arm per reply shape
pub fn reply_fields(command: &Command, reply: Option<Reply>) -> Fields {
    let mut row = Fields::default();
    let moving = matches!(command, Command::Move { .. } | Command::Move10 { .. });
    match *command {
        Command::Move {
            position, torque, ..
        } => {
            row.position("target_position", "target_degrees", position);
            row.push("torque", torque.get());
        }
        Command::Move10 {
            position, torque, ..
        } => {
            row.push("target_position10", position.get());
            row.0
                .push(("target_degrees", FieldValue::real(position.degrees())));
            row.push("torque", torque.get());
        }
        Command::SyncMove(sync) => {
            row.0.push((
                "positions",
                FieldValue::List(
                    sync.positions()
                        .iter()
                        .map(|p| i64::from(p.get()))
                        .collect(),
                ),
            ));
            row.push("torque", sync.torque().get());
            row.push("reply", "none (the command has no reply)");
        }
        Command::RuntimeSpeedSet { speed, accel, .. } => {
            row.push("speed", speed.get());
            row.push("accel", accel.get());
            row.push("reply", "none (the command has no reply)");
        }
        _ => {}
    }
    let Some(reply) = reply else {
        if matches!(command, Command::Break) {
            row.push("reply", "collided (several modules answered)");
            row.push("meaning", BREAK_COLLIDED);
        }
        return row;
    };
    match reply {
        Reply::Status { load, position } => {
            if moving {
                row.push("load_before", load.get());
                row.position("position_before", "degrees_before", position);
            } else {
                row.push("load", load.get());
                row.position("position", "degrees", position);
            }
        }
        Reply::Passive { position } => row.position("position", "degrees", position),
        Reply::Wheel {
            rotations,
            position,
        } => {
            row.push("rotations", rotations);
            row.position("position", "degrees", position);
        }
        Reply::Break { id, position } => {
            row.push("answered_by", id.get());
            row.position("position", "degrees", position);
            row.push("meaning", BREAK_CLEAN);
        }
        Reply::Baud(b) => row.push("baud", b.bits_per_second()),
        Reply::Gains { p, d } => {
            row.push("p_gain", p.get());
            row.push("d_gain", d.get());
        }
        Reply::IGain(i) => row.push("i_gain", i.get()),
        Reply::Id(id) => row.push("new_id", id.get()),
        Reply::SpeedAccel { speed, accel } => {
            row.push("speed", speed.get());
            row.push("accel", accel.get());
        }
        Reply::Overload(o) => {
            row.push("milliamps", o.milliamps());
            row.push("overload_code", o.get());
        }
        Reply::Boundaries(b) => {
            row.position("lower", "lower_degrees", b.lower());
            row.position("upper", "upper_degrees", b.upper());
        }
        Reply::Outputs(o) => {
            row.push("outputs", o.get());
            row.push("do1", o.do1());
            row.push("do2", o.do2());
        }
        Reply::Io { outputs, adc } => {
            row.push("outputs", outputs.get());
            row.push("do1", outputs.do1());
            row.push("do2", outputs.do2());
            row.push("adc", adc);
            row.0
                .push(("adc_volts", FieldValue::real(f64::from(adc) * 5.0 / 255.0)));
        }
        Reply::MotionCount(n) => row.push("instructions", n.get()),
        Reply::Position10(p) => {
            if moving {
                row.push("position10_before", p.get());
                row.0
                    .push(("degrees_before", FieldValue::real(p.degrees())));
            } else {
                row.push("position10", p.get());
                row.0.push(("degrees", FieldValue::real(p.degrees())));
            }
        }
    }
    row
}

/// What a clean break reply means: every module on the bus answers a break at the same
/// instant, so two plausible bytes prove that the command was heard, and name one module
/// only when one module is on the bus.
pub const BREAK_CLEAN: &str = "the break was heard; with one module on the bus this is its ID \
     and position, with several the replies overlap on the wire and the bytes may mix them \
     (read each servo's status for its position)";

/// What a garbled break reply means.
pub const BREAK_COLLIDED: &str = "the break was heard by at least one module; the \
     overlapping replies carry no ID or position (read each servo's status)";
