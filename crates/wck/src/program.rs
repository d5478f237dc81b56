//! The self-running motion program (manual section 3-11, command A-1 (24) Motion Data Write).
//!
//! A program is up to 8 instructions; each instruction is two bytes on the wire, a command
//! byte `(main << 4) | sub` and a data byte. A module runs its program by itself while the
//! instruction count is above 0.
//!
//! # Text form
//!
//! One instruction per line; tokens are separated by whitespace; `#` starts a comment that
//! runs to the end of the line; blank lines are ignored. Numbers are decimal.
//!
//! ```text
//! none                     main 0: no operation
//! move <0..=254> torque <0..=4>
//!                          main 1: position control at a torque level (0 = max)
//! motion passive           main 2, sub 1: release torque
//! motion break             main 2, sub 2: power down (break mode)
//! wheel ccw <0..=15>       main 2, sub 3: wheel mode counter-clockwise at a speed
//! wheel cw <0..=15>        main 2, sub 4: wheel mode clockwise at a speed
//! delay <ms>ms             main 3: wait 0..=4095 ms (`delay 266ms`, `delay 266 ms`);
//!                          delays whose low byte is 0xFF (255, 511, ...) cannot be sent
//! output <0..=3>           main 4: digital outputs (bit 0 = D/O 1, bit 1 = D/O 2)
//! if pos <op> <0..=254>    main 5: position condition
//! if adc <op> <0..=254>    main 6: A/D condition
//!                          <op> is one of == > < >= <=
//! repeat <1..=254>         main 7: number of repetitions
//! repeat forever           main 7 with data 0
//! end                      main 8: end of program
//! ```
//!
//! [`Program`]'s `Display` writes exactly this form (one instruction and a newline each),
//! and [`Program::parse`] reads it back; errors carry the line and column.
//!
//! ```
//! use robobus_wck::program::{Instruction, Program};
//! let program = Program::parse("move 82 torque 0\ndelay 266ms\nmove 172 torque 0\ndelay 266ms\n")?;
//! assert_eq!(program.len(), 4);
//! let mut pairs = program.pairs();
//! assert_eq!(pairs.next(), Some((0x10, 0x52)));
//! assert_eq!(pairs.next(), Some((0x31, 0x0A)));
//! assert_eq!(program.to_string().parse::<Program>()?, program);
//! # Ok::<(), robobus_wck::program::ParseError>(())
//! ```
//!
//! # Conditions
//!
//! The manual does not say what a condition instruction (main 5, 6) does when it is false.
//! robobus decides it once, in [`FALSE_CONDITION`]: a false condition **skips the next
//! instruction**; a true one lets it run.

use core::fmt;

use crate::values::{
    DataByte, IoBits, Position, RangeError, RepeatCount, Rotation, TorqueLevel, ValueError,
    WheelSpeed,
};

/// What a motion-program condition does when it is false.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FalseCondition {
    /// The instruction right after the condition is skipped; execution goes on after it.
    SkipNext,
    /// Execution stays on the condition until it becomes true.
    WaitUntilTrue,
}

/// The one place robobus decides the behaviour of a false condition (the manual is silent):
/// the next instruction is skipped. The simulator implements this.
pub const FALSE_CONDITION: FalseCondition = FalseCondition::SkipNext;

/// Maximum number of instructions in a program (A-1 (24): motion count 0..=8).
pub const MAX_INSTRUCTIONS: usize = 8;

/// Comparison operator of a condition instruction (sub field of main 5 and 6).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Compare {
    /// `==` (sub 1)
    Eq,
    /// `>` (sub 2)
    Gt,
    /// `<` (sub 3)
    Lt,
    /// `>=` (sub 4)
    Ge,
    /// `<=` (sub 5)
    Le,
}

impl Compare {
    /// All operators in sub-field order.
    pub const ALL: [Self; 5] = [Self::Eq, Self::Gt, Self::Lt, Self::Ge, Self::Le];

    /// The sub-field value.
    pub const fn sub(self) -> u8 {
        match self {
            Self::Eq => 1,
            Self::Gt => 2,
            Self::Lt => 3,
            Self::Ge => 4,
            Self::Le => 5,
        }
    }

    /// The operator for a sub-field value.
    pub const fn from_sub(sub: u8) -> Option<Self> {
        match sub {
            1 => Some(Self::Eq),
            2 => Some(Self::Gt),
            3 => Some(Self::Lt),
            4 => Some(Self::Ge),
            5 => Some(Self::Le),
            _ => None,
        }
    }

    /// The operator's text.
    pub const fn symbol(self) -> &'static str {
        match self {
            Self::Eq => "==",
            Self::Gt => ">",
            Self::Lt => "<",
            Self::Ge => ">=",
            Self::Le => "<=",
        }
    }

    /// Evaluates `left <op> right`.
    pub const fn holds(self, left: u8, right: u8) -> bool {
        match self {
            Self::Eq => left == right,
            Self::Gt => left > right,
            Self::Lt => left < right,
            Self::Ge => left >= right,
            Self::Le => left <= right,
        }
    }
}

impl fmt::Display for Compare {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.symbol())
    }
}

/// Motion type (main 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MotionType {
    /// Release torque (sub 1).
    Passive,
    /// Power down / break mode (sub 2).
    Break,
    /// Wheel mode in a direction at a speed (sub 3 = CCW, 4 = CW; data = speed).
    Wheel(Rotation, WheelSpeed),
}

/// A delay of a motion program in milliseconds, 0..=4095 (main 3), except values whose low
/// byte is `0xFF` (255, 511, …, 4095), which the packet cannot carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct DelayMs(u16);

impl DelayMs {
    /// The longest delay the 12-bit field holds (4095 itself cannot be sent).
    pub const FIELD_MAX: u16 = 4095;

    /// Checks the range and the low byte.
    pub const fn new(ms: u16) -> Result<Self, ValueError> {
        if ms > Self::FIELD_MAX {
            return Err(ValueError::Range(RangeError {
                what: "delay (ms)",
                value: ms as u32,
                min: 0,
                max: Self::FIELD_MAX as u32,
            }));
        }
        if ms & 0xFF == 0xFF {
            return Err(ValueError::DelayLowByteFf { ms });
        }
        Ok(Self(ms))
    }

    /// The delay in milliseconds.
    pub const fn get(self) -> u16 {
        self.0
    }

    /// The delay as a [`core::time::Duration`].
    pub const fn duration(self) -> core::time::Duration {
        core::time::Duration::from_millis(self.0 as u64)
    }
}

/// Repetition count (main 7).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Repeat {
    /// Repeat forever (data 0).
    Forever,
    /// Repeat a number of times (data 1..=254).
    Times(RepeatCount),
}

/// One instruction of a self-running motion program (section 3-11).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Instruction {
    /// Main 0: no operation.
    #[default]
    None,
    /// Main 1: go to a position at a torque level (sub = torque 0..=4, data = position).
    Move {
        /// Torque level (the manual's table calls the sub field "Speed (0~4)" and the
        /// programmer screen "Torq 0~4").
        torque: TorqueLevel,
        /// Target position.
        position: Position,
    },
    /// Main 2: motion type.
    Motion(MotionType),
    /// Main 3: wait.
    Delay(DelayMs),
    /// Main 4: set the digital outputs.
    Output(IoBits),
    /// Main 5: position condition, `position <op> value`. See [`FALSE_CONDITION`].
    IfPosition(Compare, Position),
    /// Main 6: A/D condition, `adc <op> value`. See [`FALSE_CONDITION`].
    IfAdc(Compare, DataByte),
    /// Main 7: number of repetitions.
    Repeat(Repeat),
    /// Main 8: end of program.
    End,
}

/// A command/data byte pair that is not a valid instruction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, thiserror::Error)]
pub enum InstructionError {
    /// The main instruction (high nibble) is not 0..=8.
    #[error("unknown main instruction {main} in command byte {command:#04x}")]
    UnknownMain {
        /// The command byte.
        command: u8,
        /// Its high nibble.
        main: u8,
    },
    /// The sub instruction (low nibble) is not defined for this main instruction.
    #[error("main instruction {main} has no sub instruction {sub}")]
    UnknownSub {
        /// The main instruction.
        main: u8,
        /// The rejected sub field.
        sub: u8,
    },
    /// A field value is out of range.
    #[error(transparent)]
    Value(#[from] ValueError),
}

impl From<RangeError> for InstructionError {
    fn from(e: RangeError) -> Self {
        Self::Value(ValueError::Range(e))
    }
}

impl Instruction {
    /// The main instruction number (high nibble of the command byte).
    pub const fn main(self) -> u8 {
        match self {
            Self::None => 0,
            Self::Move { .. } => 1,
            Self::Motion(_) => 2,
            Self::Delay(_) => 3,
            Self::Output(_) => 4,
            Self::IfPosition(..) => 5,
            Self::IfAdc(..) => 6,
            Self::Repeat(_) => 7,
            Self::End => 8,
        }
    }

    /// Whether this is a condition (main 5 or 6).
    pub const fn is_condition(self) -> bool {
        matches!(self, Self::IfPosition(..) | Self::IfAdc(..))
    }

    /// The wire form: `(command, data)`. "Don't care" fields are sent as 0.
    pub const fn to_pair(self) -> (u8, u8) {
        let (sub, data) = match self {
            Self::None | Self::End | Self::Repeat(Repeat::Forever) => (0, 0),
            Self::Move { torque, position } => (torque.get(), position.get()),
            Self::Motion(MotionType::Passive) => (1, 0),
            Self::Motion(MotionType::Break) => (2, 0),
            Self::Motion(MotionType::Wheel(rotation, speed)) => (rotation.nibble(), speed.get()),
            #[allow(clippy::cast_possible_truncation)] // split of a 12-bit value
            Self::Delay(ms) => ((ms.0 >> 8) as u8, (ms.0 & 0xFF) as u8),
            Self::Output(bits) => (0, bits.get()),
            Self::IfPosition(op, value) => (op.sub(), value.get()),
            Self::IfAdc(op, value) => (op.sub(), value.get()),
            Self::Repeat(Repeat::Times(n)) => (0, n.get()),
        };
        ((self.main() << 4) | sub, data)
    }

    /// Decodes a `(command, data)` pair. Fields the manual marks "X" are ignored.
    pub fn from_pair(command: u8, data: u8) -> Result<Self, InstructionError> {
        let main = command >> 4;
        let sub = command & 0x0F;
        let unknown_sub = InstructionError::UnknownSub { main, sub };
        Ok(match main {
            0 => Self::None,
            1 => Self::Move {
                torque: TorqueLevel::new(sub).map_err(|_| unknown_sub)?,
                position: Position::new(data)?,
            },
            2 => Self::Motion(match sub {
                1 => MotionType::Passive,
                2 => MotionType::Break,
                3 => MotionType::Wheel(Rotation::Ccw, WheelSpeed::new(data)?),
                4 => MotionType::Wheel(Rotation::Cw, WheelSpeed::new(data)?),
                _ => return Err(unknown_sub),
            }),
            3 => Self::Delay(DelayMs::new((u16::from(sub) << 8) | u16::from(data))?),
            4 => Self::Output(IoBits::new(data)?),
            5 => Self::IfPosition(
                Compare::from_sub(sub).ok_or(unknown_sub)?,
                Position::new(data)?,
            ),
            6 => Self::IfAdc(
                Compare::from_sub(sub).ok_or(unknown_sub)?,
                DataByte::new(data)?,
            ),
            7 => Self::Repeat(match data {
                0 => Repeat::Forever,
                n => Repeat::Times(RepeatCount::new(n)?),
            }),
            8 => Self::End,
            _ => return Err(InstructionError::UnknownMain { command, main }),
        })
    }
}

impl fmt::Display for Instruction {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::None => f.write_str("none"),
            Self::Move { torque, position } => write!(f, "move {position} torque {torque}"),
            Self::Motion(MotionType::Passive) => f.write_str("motion passive"),
            Self::Motion(MotionType::Break) => f.write_str("motion break"),
            Self::Motion(MotionType::Wheel(Rotation::Ccw, speed)) => write!(f, "wheel ccw {speed}"),
            Self::Motion(MotionType::Wheel(Rotation::Cw, speed)) => write!(f, "wheel cw {speed}"),
            Self::Delay(ms) => write!(f, "delay {}ms", ms.get()),
            Self::Output(bits) => write!(f, "output {bits}"),
            Self::IfPosition(op, value) => write!(f, "if pos {op} {value}"),
            Self::IfAdc(op, value) => write!(f, "if adc {op} {value}"),
            Self::Repeat(Repeat::Forever) => f.write_str("repeat forever"),
            Self::Repeat(Repeat::Times(n)) => write!(f, "repeat {n}"),
            Self::End => f.write_str("end"),
        }
    }
}

/// A self-running motion program: up to [`MAX_INSTRUCTIONS`] instructions, stored inline.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Program {
    // Invariant: slots at and after `len` hold `Instruction::None`, so derived equality and
    // hashing only see the used part.
    instructions: [Instruction; MAX_INSTRUCTIONS],
    len: u8,
}

/// A motion program byte sequence that does not decode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, thiserror::Error)]
pub enum ProgramError {
    /// More than 8 instructions, or an odd number of bytes.
    #[error(transparent)]
    Count(#[from] RangeError),
    /// One instruction is invalid.
    #[error("instruction {index}: {error}")]
    Instruction {
        /// Zero-based index of the instruction.
        index: usize,
        /// What is wrong with it.
        error: InstructionError,
    },
}

impl Program {
    /// The empty program (count 0: self-running motion off).
    pub const EMPTY: Self = Self {
        instructions: [Instruction::None; MAX_INSTRUCTIONS],
        len: 0,
    };

    /// A program from a slice of at most 8 instructions.
    pub fn new(instructions: &[Instruction]) -> Result<Self, RangeError> {
        let mut program = Self::EMPTY;
        for &instruction in instructions {
            program.push(instruction)?;
        }
        Ok(program)
    }

    /// Appends an instruction; fails when the program already holds 8.
    pub fn push(&mut self, instruction: Instruction) -> Result<(), RangeError> {
        let len = usize::from(self.len);
        let slot = self.instructions.get_mut(len).ok_or(RangeError {
            what: "motion instruction count",
            value: u32::from(self.len) + 1,
            min: 0,
            max: 8,
        })?;
        *slot = instruction;
        self.len += 1;
        Ok(())
    }

    /// The instructions.
    pub fn instructions(&self) -> &[Instruction] {
        self.instructions
            .get(..usize::from(self.len))
            .unwrap_or(&[])
    }

    /// Number of instructions.
    pub const fn len(&self) -> usize {
        self.len as usize
    }

    /// Whether the program is empty (self-running motion off).
    pub const fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The instruction count as sent on the wire.
    pub const fn count(&self) -> crate::values::MotionCount {
        match crate::values::MotionCount::new(self.len) {
            Ok(c) => c,
            Err(_) => crate::values::MotionCount::MAX,
        }
    }

    /// The `(command, data)` pairs in order.
    pub fn pairs(&self) -> impl Iterator<Item = (u8, u8)> + '_ {
        self.instructions().iter().map(|i| i.to_pair())
    }

    /// Decodes `(command, data)` pairs laid out flat: `cmd0 data0 cmd1 data1 …`.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, ProgramError> {
        let count = bytes.len() / 2;
        if !bytes.len().is_multiple_of(2) || count > MAX_INSTRUCTIONS {
            return Err(ProgramError::Count(RangeError {
                what: "motion program bytes",
                value: u32::try_from(bytes.len()).unwrap_or(u32::MAX),
                min: 0,
                max: 16,
            }));
        }
        let mut program = Self::EMPTY;
        for (index, pair) in bytes.chunks_exact(2).enumerate() {
            if let [command, data] = *pair {
                let instruction = Instruction::from_pair(command, data)
                    .map_err(|error| ProgramError::Instruction { index, error })?;
                program.push(instruction)?;
            }
        }
        Ok(program)
    }

    /// Parses the text form (see the [module docs](self)).
    pub fn parse(text: &str) -> Result<Self, ParseError> {
        text::parse_program(text)
    }
}

// Shows only the used slots; the rest are padding.
#[allow(clippy::missing_fields_in_debug)]
impl fmt::Debug for Program {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_tuple("Program")
            .field(&self.instructions())
            .finish()
    }
}

impl fmt::Display for Program {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for instruction in self.instructions() {
            writeln!(f, "{instruction}")?;
        }
        Ok(())
    }
}

mod text;

pub use text::{Found, ParseError, ParseErrorKind};

#[cfg(test)]
mod tests;
