//! Commands and replies in words: their text form is their [`core::fmt::Display`], and
//! their values, by name, are [`Command::fields`] / [`Reply::fields`]. `robobus replay`
//! and the client show these.
//!
//! ```
//! use robobus_wck::{Command, Field, Position, Reply, ServoId, TorqueLevel};
//!
//! let command = Command::Move { id: ServoId::new(3)?, torque: TorqueLevel::new(0)?, position: Position::new(127)? };
//! assert_eq!(command.to_string(), "position move servo 3 to 127 (torque 0)");
//! let fields: Vec<Field> = command.fields().collect();
//! assert_eq!(fields[0].to_string(), "position 127");
//! let reply = command.decode_reply(&[0x12, 0x7F]).unwrap();
//! assert_eq!(reply.to_string(), "load 18, position 127");
//! assert_eq!(reply.fields().map(|f| f.name).collect::<Vec<_>>(), ["load", "position"]);
//! # Ok::<(), robobus_wck::RangeError>(())
//! ```

use core::fmt;

use crate::{Command, Reply};

/// One value of a command or a reply: its name and raw value (wCK values have no unit).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Field {
    /// What the value is (`position`, `torque`, `load`, `rotations`, `id`).
    pub name: &'static str,
    /// The value.
    pub value: i32,
}

impl Field {
    const fn new(name: &'static str, value: i32) -> Self {
        Self { name, value }
    }
}

impl fmt::Display for Field {
    /// `position 127`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} {}", self.name, self.value)
    }
}

impl Command {
    /// The target of a position move: `position`, then `torque` (no values for the other
    /// commands; their [`Display`](fmt::Display) form says what they set).
    pub fn fields(&self) -> impl Iterator<Item = Field> + use<> {
        let pair = match *self {
            Self::Move {
                torque, position, ..
            } => [
                Some(Field::new("position", i32::from(position.get()))),
                Some(Field::new("torque", i32::from(torque.get()))),
            ],
            _ => [None, None],
        };
        pair.into_iter().flatten()
    }
}

impl Reply {
    /// The values of a reply that reports a position: `load` (status), `rotations`
    /// (wheel) or `id` (break) first, then `position`; the 10-bit `position`. (No values
    /// for the replies that echo a setting; their [`Display`](fmt::Display) form says it.)
    pub fn fields(&self) -> impl Iterator<Item = Field> + use<> {
        let position = |p: crate::Position| Some(Field::new("position", i32::from(p.get())));
        let pair = match *self {
            Self::Status { load, position: p } => {
                [Some(Field::new("load", i32::from(load.get()))), position(p)]
            }
            Self::Passive { position: p } => [position(p), None],
            Self::Wheel {
                rotations,
                position: p,
            } => [
                Some(Field::new("rotations", i32::from(rotations))),
                position(p),
            ],
            Self::Break { id, position: p } => {
                [Some(Field::new("id", i32::from(id.get()))), position(p)]
            }
            Self::Position10(p) => [Some(Field::new("position", i32::from(p.get()))), None],
            _ => [None, None],
        };
        pair.into_iter().flatten()
    }
}
