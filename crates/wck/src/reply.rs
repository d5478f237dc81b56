//! Replies: two raw bytes per command (A-1 "Response Packet", A-6), typed.

use crate::command::{Command, PASSIVE_D2, REPLY_LEN};
use crate::values::{
    Accel, BaudRate, Boundaries, DGain, ExtServoId, IGain, IoBits, Load, MotionCount, Overload,
    PGain, Position, Position10, ServoId, Speed, ValueError,
};

/// A decoded reply. Commands with the same reply shape share a variant.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Reply {
    /// Position move (1) and status read (3): load, then position.
    Status {
        /// Current load.
        load: Load,
        /// Current position.
        position: Position,
    },
    /// Passive (4): the command's mode byte `0x10` echoed, then the position.
    Passive {
        /// Current position.
        position: Position,
    },
    /// Wheel (5): rotations counted since power-up (0..=255, wraps), then position.
    Wheel {
        /// Rotation count.
        rotations: u8,
        /// Current position.
        position: Position,
    },
    /// Break (6): the answering module's ID, then its position.
    Break {
        /// The answering module.
        id: ServoId,
        /// Its position.
        position: Position,
    },
    /// Baud rate set (7): the new code, twice.
    Baud(BaudRate),
    /// P, D gain set / read / runtime set (8), (9), (12).
    Gains {
        /// P gain.
        p: PGain,
        /// D gain.
        d: DGain,
    },
    /// I gain set / read / runtime set (10), (11), (13): the gain, twice.
    IGain(IGain),
    /// ID set (14): the new ID, twice.
    Id(ExtServoId),
    /// Speed set / read (15), (16).
    SpeedAccel {
        /// Speed level.
        speed: Speed,
        /// Acceleration range.
        accel: Accel,
    },
    /// Over-load set / read (18), (19): the code, twice.
    Overload(Overload),
    /// Boundary set / read (20), (21).
    Boundaries(Boundaries),
    /// I/O write (22): the output value, twice.
    Outputs(IoBits),
    /// I/O read (23): outputs, then the 8-bit A/D input.
    Io {
        /// Digital outputs.
        outputs: IoBits,
        /// A/D input, 0..=255 for 0..=5 V.
        adc: u8,
    },
    /// Motion data write / read (24), (25): the instruction count, twice.
    MotionCount(MotionCount),
    /// 10-bit position move / read (26), (27).
    Position10(Position10),
}

impl Reply {
    /// The reply bytes a module sends (what the simulator writes).
    pub const fn to_bytes(&self) -> [u8; REPLY_LEN] {
        match *self {
            Self::Status { load, position } => [load.get(), position.get()],
            Self::Passive { position } => [PASSIVE_D2, position.get()],
            Self::Wheel {
                rotations,
                position,
            } => [rotations, position.get()],
            Self::Break { id, position } => [id.get(), position.get()],
            Self::Baud(baud) => [baud.code(), baud.code()],
            Self::Gains { p, d } => [p.get(), d.get()],
            Self::IGain(i) => [i.get(), i.get()],
            Self::Id(id) => [id.get(), id.get()],
            Self::SpeedAccel { speed, accel } => [speed.get(), accel.get()],
            Self::Overload(o) => [o.get(), o.get()],
            Self::Boundaries(b) => [b.lower().get(), b.upper().get()],
            Self::Outputs(bits) => [bits.get(), bits.get()],
            Self::Io { outputs, adc } => [outputs.get(), adc],
            Self::MotionCount(n) => [n.get(), n.get()],
            Self::Position10(p) => {
                let (h3, l7) = p.to_wire();
                [h3, l7]
            }
        }
    }
}

impl core::fmt::Display for Reply {
    /// A short human description, for example `load 4, position 96`.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Status { load, position } => write!(f, "load {load}, position {position}"),
            Self::Passive { position } => write!(f, "passive, position {position}"),
            Self::Wheel {
                rotations,
                position,
            } => {
                write!(f, "{rotations} rotations, position {position}")
            }
            Self::Break { id, position } => write!(f, "servo {id} in break, position {position}"),
            Self::Baud(baud) => write!(f, "baud rate {baud} (code {})", baud.code()),
            Self::Gains { p, d } => write!(f, "P {p}, D {d}"),
            Self::IGain(i) => write!(f, "I {i}"),
            Self::Id(id) => write!(f, "id {id}"),
            Self::SpeedAccel { speed, accel } => write!(f, "speed {speed}, accel {accel}"),
            Self::Overload(o) => write!(f, "over-load {o} ({} mA)", o.milliamps()),
            Self::Boundaries(b) => write!(f, "boundaries {b}"),
            Self::Outputs(bits) => write!(f, "outputs {bits}"),
            Self::Io { outputs, adc } => write!(f, "outputs {outputs}, A/D {adc}"),
            Self::MotionCount(n) => write!(f, "{n} motion instructions"),
            Self::Position10(p) => write!(f, "10-bit position {p}"),
        }
    }
}

/// A reply that is not plausible for the command it answers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, thiserror::Error)]
pub enum ReplyError {
    /// The command has no reply (synchronized move, runtime speed set).
    #[error("{command} has no reply")]
    NoReply {
        /// The command.
        command: &'static str,
    },
    /// Not exactly two bytes.
    #[error("{command}: expected {expected} reply bytes, got {received}")]
    Length {
        /// The command.
        command: &'static str,
        /// Expected length.
        expected: usize,
        /// Received length.
        received: usize,
    },
    /// A value the module should echo differs from what was sent.
    #[error("{command}: reply {what} is {received}, but {sent} was sent")]
    Echo {
        /// The command.
        command: &'static str,
        /// Which value.
        what: &'static str,
        /// What the command sent.
        sent: u8,
        /// What came back.
        received: u8,
    },
    /// The two bytes of a reply that repeats one value differ.
    #[error("{command}: the reply repeats one value, but its bytes are {first} and {second}")]
    Unequal {
        /// The command.
        command: &'static str,
        /// First byte.
        first: u8,
        /// Second byte.
        second: u8,
    },
    /// A value is out of its range.
    #[error("{command}: {error}")]
    Invalid {
        /// The command.
        command: &'static str,
        /// The range violation.
        error: ValueError,
    },
}

#[allow(clippy::too_many_lines)] // one flat arm per command reads best
pub(crate) fn decode(cmd: &Command, bytes: &[u8]) -> Result<Reply, ReplyError> {
    let command = cmd.name();
    if cmd.reply_len() == 0 {
        return Err(ReplyError::NoReply { command });
    }
    let &[a, b] = bytes else {
        return Err(ReplyError::Length {
            command,
            expected: REPLY_LEN,
            received: bytes.len(),
        });
    };
    let invalid = |error: ValueError| ReplyError::Invalid { command, error };
    let range = |error| invalid(ValueError::Range(error));
    let echo = |what, sent: u8, received: u8| {
        if sent == received {
            Ok(())
        } else {
            Err(ReplyError::Echo {
                command,
                what,
                sent,
                received,
            })
        }
    };
    let equal = || {
        if a == b {
            Ok(())
        } else {
            Err(ReplyError::Unequal {
                command,
                first: a,
                second: b,
            })
        }
    };
    Ok(match *cmd {
        Command::Move { .. } | Command::StatusRead { .. } => Reply::Status {
            load: Load::new(a).map_err(range)?,
            position: Position::new(b).map_err(range)?,
        },
        Command::Passive { .. } => {
            echo("mode byte", PASSIVE_D2, a)?;
            Reply::Passive {
                position: Position::new(b).map_err(range)?,
            }
        }
        Command::Wheel { .. } => Reply::Wheel {
            rotations: a,
            position: Position::new(b).map_err(range)?,
        },
        Command::Break => Reply::Break {
            id: ServoId::new(a).map_err(range)?,
            position: Position::new(b).map_err(range)?,
        },
        Command::BaudSet { baud, .. } => {
            equal()?;
            echo("baud code", baud.code(), a)?;
            Reply::Baud(baud)
        }
        Command::GainSet { p, d, .. } | Command::RuntimeGainSet { p, d, .. } => {
            echo("P gain", p.get(), a)?;
            echo("D gain", d.get(), b)?;
            Reply::Gains { p, d }
        }
        Command::GainRead { .. } => Reply::Gains {
            p: PGain::new(a).map_err(range)?,
            d: DGain::new(b).map_err(range)?,
        },
        Command::IGainSet { i, .. } | Command::RuntimeIGainSet { i, .. } => {
            equal()?;
            echo("I gain", i.get(), a)?;
            Reply::IGain(i)
        }
        Command::IGainRead { .. } => {
            equal()?;
            Reply::IGain(IGain::new(a).map_err(range)?)
        }
        Command::IdSet { new_id, .. } => {
            equal()?;
            echo("new id", new_id.get(), a)?;
            Reply::Id(new_id)
        }
        Command::SpeedSet { speed, accel, .. } => {
            echo("speed", speed.get(), a)?;
            echo("acceleration", accel.get(), b)?;
            Reply::SpeedAccel { speed, accel }
        }
        Command::SpeedRead { .. } => Reply::SpeedAccel {
            speed: Speed::new(a).map_err(range)?,
            accel: Accel::new(b).map_err(range)?,
        },
        Command::OverloadSet { overload, .. } => {
            equal()?;
            echo("over-load", overload.get(), a)?;
            Reply::Overload(overload)
        }
        Command::OverloadRead { .. } => {
            equal()?;
            Reply::Overload(Overload::new(a).map_err(range)?)
        }
        Command::BoundarySet { bounds, .. } => {
            echo("lower boundary", bounds.lower().get(), a)?;
            echo("upper boundary", bounds.upper().get(), b)?;
            Reply::Boundaries(bounds)
        }
        Command::BoundaryRead { .. } => {
            Reply::Boundaries(Boundaries::from_raw(a, b).map_err(invalid)?)
        }
        Command::IoWrite { outputs, .. } => {
            equal()?;
            echo("outputs", outputs.get(), a)?;
            Reply::Outputs(outputs)
        }
        Command::IoRead { .. } => Reply::Io {
            outputs: IoBits::from_masked(a),
            adc: b,
        },
        Command::MotionWrite { ref program, .. } => {
            equal()?;
            echo("instruction count", program.count().get(), a)?;
            Reply::MotionCount(program.count())
        }
        Command::MotionRead { .. } => {
            equal()?;
            Reply::MotionCount(MotionCount::new(a).map_err(range)?)
        }
        Command::Move10 { .. } | Command::Read10 { .. } => {
            Reply::Position10(Position10::from_wire_checked(a, b).map_err(range)?)
        }
        Command::SyncMove(_) | Command::RuntimeSpeedSet { .. } => {
            return Err(ReplyError::NoReply { command });
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_is_readable() {
        let r = Reply::Overload(Overload::new(104).unwrap());
        assert_eq!(r.to_string(), "over-load 104 (1000 mA)");
        assert_eq!(
            Reply::Baud(BaudRate::B115200).to_string(),
            "baud rate 115200 bit/s (code 7)"
        );
        let p = Reply::Position10(Position10::new(1000).unwrap());
        assert_eq!(p.to_bytes(), [0x07, 0xD0]);
    }
}
