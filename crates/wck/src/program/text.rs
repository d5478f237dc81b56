//! The motion program's text form (see the [parent module](super)): the parser of
//! [`Program::parse`] and `FromStr`, and its errors with their line and column.

use core::fmt;
use core::str::FromStr;

use super::{Compare, DelayMs, Instruction, MAX_INSTRUCTIONS, MotionType, Program, Repeat};
use crate::values::{
    DataByte, IoBits, Position, RangeError, RepeatCount, Rotation, TorqueLevel, ValueError,
    WheelSpeed,
};

/// [`Program::parse`]: the text form, line by line.
pub(super) fn parse_program(text: &str) -> Result<Program, ParseError> {
    let mut program = Program::EMPTY;
    for (index, raw_line) in text.lines().enumerate() {
        let line_no = index + 1;
        let line = raw_line.split('#').next().unwrap_or("");
        let mut tokens = Tokens { line, pos: 0 };
        let Some(first) = tokens.next() else { continue };
        let instruction = parse_instruction(first, &mut tokens).map_err(|e| e.at(line_no))?;
        if let Some(extra) = tokens.next() {
            return Err(ParseErrorAt::expected("end of line", extra).at(line_no));
        }
        program.push(instruction).map_err(|_| ParseError {
            line: line_no,
            column: first.column,
            kind: ParseErrorKind::TooManyInstructions,
        })?;
    }
    Ok(program)
}

impl FromStr for Program {
    type Err = ParseError;
    fn from_str(s: &str) -> Result<Self, ParseError> {
        Self::parse(s)
    }
}

impl FromStr for Instruction {
    type Err = ParseError;
    /// Parses one instruction (one line of the text form).
    fn from_str(s: &str) -> Result<Self, ParseError> {
        let line = s.split('#').next().unwrap_or("");
        let mut tokens = Tokens { line, pos: 0 };
        let Some(first) = tokens.next() else {
            return Err(ParseErrorAt::end("an instruction", line).at(1));
        };
        let instruction = parse_instruction(first, &mut tokens).map_err(|e| e.at(1))?;
        if let Some(extra) = tokens.next() {
            return Err(ParseErrorAt::expected("end of line", extra).at(1));
        }
        Ok(instruction)
    }
}

/// Text of the token a parse error stopped at, copied (at most 16 bytes) so the error does
/// not borrow the input.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Found {
    bytes: [u8; 16],
    len: u8,
    truncated: bool,
}

impl Found {
    /// The end of the line (no token).
    pub const END_OF_LINE: Self = Self {
        bytes: [0; 16],
        len: 0,
        truncated: false,
    };

    fn new(text: &str) -> Self {
        let mut end = text.len().min(16);
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        let mut bytes = [0; 16];
        if let (Some(dst), Some(src)) = (bytes.get_mut(..end), text.as_bytes().get(..end)) {
            dst.copy_from_slice(src);
        }
        #[allow(clippy::cast_possible_truncation)] // at most 16
        let len = end as u8;
        Self {
            bytes,
            len,
            truncated: end < text.len(),
        }
    }

    /// The token text (possibly cut), empty at the end of a line.
    pub fn as_str(&self) -> &str {
        self.bytes
            .get(..usize::from(self.len))
            .and_then(|b| core::str::from_utf8(b).ok())
            .unwrap_or("")
    }
}

impl fmt::Display for Found {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.len == 0 {
            f.write_str("end of line")
        } else {
            write!(
                f,
                "`{}{}`",
                self.as_str(),
                if self.truncated { "…" } else { "" }
            )
        }
    }
}

/// What went wrong while parsing the text form.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ParseErrorKind {
    /// Something else was expected here.
    Expected {
        /// What the parser wanted (for example "a comparison operator (==, >, <, >=, <=)").
        expected: &'static str,
        /// What it found.
        found: Found,
    },
    /// A number is outside the range of its field.
    Value(ValueError),
    /// A ninth instruction.
    TooManyInstructions,
}

/// A parse error of the motion program text form, pointing at a line and column (both
/// starting at 1; columns count characters).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, thiserror::Error)]
#[error("line {line}, column {column}: {kind}")]
pub struct ParseError {
    /// Line number, from 1.
    pub line: usize,
    /// Column, from 1, in characters.
    pub column: usize,
    /// What went wrong.
    pub kind: ParseErrorKind,
}

impl fmt::Display for ParseErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Expected { expected, found } => write!(f, "expected {expected}, found {found}"),
            Self::Value(e) => fmt::Display::fmt(e, f),
            Self::TooManyInstructions => {
                write!(f, "a program holds at most {MAX_INSTRUCTIONS} instructions")
            }
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct Token<'a> {
    text: &'a str,
    column: usize,
}

struct Tokens<'a> {
    line: &'a str,
    pos: usize,
}

impl<'a> Tokens<'a> {
    fn next(&mut self) -> Option<Token<'a>> {
        let rest = self.line.get(self.pos..)?;
        let start = self.pos + (rest.len() - rest.trim_start().len());
        let tail = self.line.get(start..)?;
        if tail.is_empty() {
            self.pos = self.line.len();
            return None;
        }
        let len = tail.find(char::is_whitespace).unwrap_or(tail.len());
        self.pos = start + len;
        let column = self.line.get(..start).map_or(1, |s| s.chars().count() + 1);
        Some(Token {
            text: tail.get(..len)?,
            column,
        })
    }

    /// Column just after the last token (where "end of line" errors point).
    fn end_column(&self) -> usize {
        self.line.trim_end().chars().count() + 1
    }
}

struct ParseErrorAt {
    column: usize,
    kind: ParseErrorKind,
}

impl ParseErrorAt {
    fn expected(expected: &'static str, token: Token<'_>) -> Self {
        Self {
            column: token.column,
            kind: ParseErrorKind::Expected {
                expected,
                found: Found::new(token.text),
            },
        }
    }

    fn end(expected: &'static str, line: &str) -> Self {
        Self {
            column: line.trim_end().chars().count() + 1,
            kind: ParseErrorKind::Expected {
                expected,
                found: Found::END_OF_LINE,
            },
        }
    }

    fn at(self, line: usize) -> ParseError {
        ParseError {
            line,
            column: self.column,
            kind: self.kind,
        }
    }
}

fn want<'a>(tokens: &mut Tokens<'a>, expected: &'static str) -> Result<Token<'a>, ParseErrorAt> {
    tokens.next().ok_or(ParseErrorAt {
        column: tokens.end_column(),
        kind: ParseErrorKind::Expected {
            expected,
            found: Found::END_OF_LINE,
        },
    })
}

fn keyword(tokens: &mut Tokens<'_>, word: &'static str) -> Result<(), ParseErrorAt> {
    let token = want(tokens, word)?;
    if token.text == word {
        Ok(())
    } else {
        Err(ParseErrorAt::expected(word, token))
    }
}

fn number(token: Token<'_>) -> Result<u32, ParseErrorAt> {
    if !token.text.bytes().all(|b| b.is_ascii_digit()) {
        return Err(ParseErrorAt::expected("a decimal number", token));
    }
    token
        .text
        .parse::<u32>()
        .map_err(|_| ParseErrorAt::expected("a decimal number", token))
}

/// Reads a number for a byte-sized ranged field.
fn field<T>(
    tokens: &mut Tokens<'_>,
    expected: &'static str,
    new: fn(u8) -> Result<T, RangeError>,
) -> Result<T, ParseErrorAt> {
    let token = want(tokens, expected)?;
    let n = number(token)?;
    // 255 is out of range for every byte field, so it stands in for anything larger and the
    // error then reports the real value.
    new(u8::try_from(n).unwrap_or(u8::MAX)).map_err(|mut e| {
        e.value = n;
        ParseErrorAt {
            column: token.column,
            kind: ParseErrorKind::Value(ValueError::Range(e)),
        }
    })
}

fn compare(tokens: &mut Tokens<'_>) -> Result<Compare, ParseErrorAt> {
    const EXPECTED: &str = "a comparison operator (==, >, <, >=, <=)";
    let token = want(tokens, EXPECTED)?;
    Compare::ALL
        .into_iter()
        .find(|op| op.symbol() == token.text)
        .ok_or(ParseErrorAt::expected(EXPECTED, token))
}

fn delay(tokens: &mut Tokens<'_>) -> Result<DelayMs, ParseErrorAt> {
    const EXPECTED: &str = "a delay in milliseconds such as `266ms`";
    let token = want(tokens, EXPECTED)?;
    let digits = token.text.strip_suffix("ms").unwrap_or(token.text);
    if digits.is_empty() {
        return Err(ParseErrorAt::expected(EXPECTED, token));
    }
    let n = number(Token {
        text: digits,
        column: token.column,
    })
    .map_err(|_| ParseErrorAt::expected(EXPECTED, token))?;
    if digits.len() == token.text.len() {
        keyword(tokens, "ms")?;
    }
    DelayMs::new(u16::try_from(n).unwrap_or(u16::MAX)).map_err(|e| {
        let e = match e {
            ValueError::Range(mut r) => {
                r.value = n;
                ValueError::Range(r)
            }
            other => other,
        };
        ParseErrorAt {
            column: token.column,
            kind: ParseErrorKind::Value(e),
        }
    })
}

fn parse_instruction(
    first: Token<'_>,
    tokens: &mut Tokens<'_>,
) -> Result<Instruction, ParseErrorAt> {
    Ok(match first.text {
        "none" => Instruction::None,
        "move" => {
            let position = field(tokens, "a position (0..=254)", Position::new)?;
            keyword(tokens, "torque")?;
            let torque = field(tokens, "a torque level (0..=4)", TorqueLevel::new)?;
            Instruction::Move { torque, position }
        }
        "motion" => {
            let token = want(tokens, "`passive` or `break`")?;
            match token.text {
                "passive" => Instruction::Motion(MotionType::Passive),
                "break" => Instruction::Motion(MotionType::Break),
                _ => return Err(ParseErrorAt::expected("`passive` or `break`", token)),
            }
        }
        "wheel" => {
            let token = want(tokens, "`cw` or `ccw`")?;
            let rotation = match token.text {
                "cw" => Rotation::Cw,
                "ccw" => Rotation::Ccw,
                _ => return Err(ParseErrorAt::expected("`cw` or `ccw`", token)),
            };
            let speed = field(tokens, "a wheel speed (0..=15)", WheelSpeed::new)?;
            Instruction::Motion(MotionType::Wheel(rotation, speed))
        }
        "delay" => Instruction::Delay(delay(tokens)?),
        "output" => Instruction::Output(field(tokens, "an output value (0..=3)", IoBits::new)?),
        "if" => {
            let token = want(tokens, "`pos` or `adc`")?;
            match token.text {
                "pos" => {
                    let op = compare(tokens)?;
                    Instruction::IfPosition(
                        op,
                        field(tokens, "a position (0..=254)", Position::new)?,
                    )
                }
                "adc" => {
                    let op = compare(tokens)?;
                    Instruction::IfAdc(op, field(tokens, "an A/D value (0..=254)", DataByte::new)?)
                }
                _ => return Err(ParseErrorAt::expected("`pos` or `adc`", token)),
            }
        }
        "repeat" => {
            let token = want(tokens, "a repeat count (1..=254) or `forever`")?;
            if token.text == "forever" {
                Instruction::Repeat(Repeat::Forever)
            } else {
                // Re-read the token as a number field.
                let mut again = Tokens {
                    line: token.text,
                    pos: 0,
                };
                let count = field(
                    &mut again,
                    "a repeat count (1..=254) or `forever`",
                    RepeatCount::new,
                )
                .map_err(|mut e| {
                    e.column += token.column - 1;
                    e
                })?;
                Instruction::Repeat(Repeat::Times(count))
            }
        }
        "end" => Instruction::End,
        _ => {
            return Err(ParseErrorAt::expected(
                "an instruction (none, move, motion, wheel, delay, output, if, repeat, end)",
                first,
            ));
        }
    })
}
