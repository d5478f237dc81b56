//! The slcan line protocol with its CAN FD extension, as pure functions: what a host
//! writes and reads, and what an adapter parses and answers.
//!
//! Every message is ASCII ended by `\r` (carriage return). The host's commands:
//!
//! | Line | Meaning | Answer |
//! |---|---|---|
//! | `O` / `L` / `C` | open (normal mode) / open listen-only / close the channel | `\r` |
//! | `S0`..`S8` | nominal bit rate 10k, 20k, 50k, 100k, 125k, 250k, 500k, 750k, 1M | `\r` |
//! | `Y2` / `Y5` | data bit rate 2 / 5 Mbit/s | `\r` |
//! | `M0` / `M1` | normal / silent mode | `\r` |
//! | `A0` / `A1` | automatic retransmission off / on | `\r` |
//! | `V` / `N` | version / serial number | `Vhhss\r` / `Nxxxx\r` |
//! | `F` | status flags (channel open only) | `Fxx\r` |
//! | `tIIIL<data>` / `TIIIIIIIIL<data>` | classic frame, 11 / 29-bit ID, `L` = 0..8 | `\r` |
//! | `dIIIL<data>` / `DIIIIIIIIL<data>` | CAN FD frame without bit-rate switch | `\r` |
//! | `bIIIL<data>` / `BIIIIIIIIL<data>` | CAN FD frame with bit-rate switch | `\r` |
//!
//! For FD frames `L` is a hex DLC code 0..F (0..8, 12, 16, 20, 24, 32, 48, 64 bytes), and
//! the data is exactly that many bytes as two uppercase hex digits each. A command the
//! adapter cannot carry out is answered by `\a` (BEL) instead of `\r`. Some firmwares
//! answer a sent frame with `z\r` / `Z\r` (Lawicel's transmit acknowledgement); both
//! are accepted. Received frames come unasked, in the same format as the frames sent.
//!
//! Every input is bounded: a line longer than [`MAX_LINE`] is dropped whole, and
//! anything up to the next `\r` after it, so garbage resynchronises at a carriage return.

use robobus_whj::frame::{CanFrame, dlc_to_len, len_to_dlc};

/// The longest line either side sends: `B`, 8 ID digits, the DLC, 128 data digits and a
/// 4-digit timestamp.
pub const MAX_LINE: usize = 1 + 8 + 1 + 128 + 4;

/// Acknowledges a command.
pub const ACK: u8 = b'\r';
/// Refuses a command (BEL).
pub const BEL: u8 = 0x07;

/// The nominal bit rates of `S0`..`S8`, by their code.
pub const NOMINAL_RATES: [u32; 9] = [
    10_000, 20_000, 50_000, 100_000, 125_000, 250_000, 500_000, 750_000, 1_000_000,
];

/// The data bit rates an slcan FD adapter can be set to: `Y1`, `Y2`, `Y4`, `Y5` (the
/// `CANable` 2.0 firmware's codes; the WHJ joints' 250 and 500 kbit/s have none).
pub const DATA_RATES: [(u8, u32); 4] = [
    (1, 1_000_000),
    (2, 2_000_000),
    (4, 4_000_000),
    (5, 5_000_000),
];

/// The `S` code of a nominal rate.
pub fn nominal_code(rate: u32) -> Option<u8> {
    NOMINAL_RATES
        .iter()
        .position(|&r| r == rate)
        .and_then(|i| u8::try_from(i).ok())
}

/// The `Y` code of a data rate.
pub fn data_code(rate: u32) -> Option<u8> {
    DATA_RATES.iter().find(|(_, r)| *r == rate).map(|(c, _)| *c)
}

/// The rate of a `Y` code.
pub fn data_rate(code: u8) -> Option<u32> {
    DATA_RATES.iter().find(|(c, _)| *c == code).map(|(_, r)| *r)
}

/// The allowed rates, for messages: `10000, 20000, …, 1000000`.
pub fn list_rates(rates: impl IntoIterator<Item = u32>) -> String {
    rates
        .into_iter()
        .map(|r| r.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// A command from the host (everything but a frame has no argument beyond one digit).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// An empty line (`\r` alone): acknowledged, nothing done.
    Empty,
    /// `O`: open the channel in normal mode.
    Open,
    /// `L`: open the channel listen-only.
    Listen,
    /// `C`: close the channel.
    Close,
    /// `Sn`: nominal bit rate code 0..=8.
    Nominal(u8),
    /// `Yn`: data bit rate code (2 or 5).
    Data(u8),
    /// `M0` / `M1`: normal / silent mode.
    Silent(bool),
    /// `A0` / `A1`: automatic retransmission off / on.
    AutoRetransmit(bool),
    /// `V`: version.
    Version,
    /// `N`: serial number.
    Serial,
    /// `F`: status flags.
    Status,
    /// A frame to send.
    Frame(CanFrame),
}

/// Why a host line is not a command (the adapter answers it with BEL).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CommandError {
    /// The first character is no command.
    #[error("unknown command {0:?}")]
    Unknown(char),
    /// The command's argument is missing, extra, or out of range.
    #[error("bad argument for {command:?}: {reason}")]
    BadArgument {
        /// The command letter.
        command: char,
        /// What is wrong.
        reason: &'static str,
    },
    /// A frame line that does not parse.
    #[error(transparent)]
    Frame(#[from] FrameLineError),
}

/// Why a frame line does not parse.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum FrameLineError {
    /// Not a frame's first character.
    #[error("not a frame line")]
    NotAFrame,
    /// A character that is not a hex digit.
    #[error("non-hex character at {at}")]
    NotHex {
        /// Its position in the line.
        at: usize,
    },
    /// The identifier is beyond 11 / 29 bits.
    #[error("identifier {id:#X} out of range")]
    IdOutOfRange {
        /// The identifier.
        id: u32,
    },
    /// A DLC code the frame kind cannot have (above 8 for classic frames).
    #[error("DLC code {dlc:X} not allowed for this frame kind")]
    BadDlc {
        /// The code.
        dlc: u8,
    },
    /// The line is shorter or longer than its DLC says.
    #[error("line of {got} characters, the DLC says {expected}")]
    Length {
        /// Characters the line has (without `\r`).
        got: usize,
        /// Characters the DLC asks for.
        expected: usize,
    },
}

/// The frame line of `frame` with its `\r`: `b` / `d` / `t` (upper case for 29-bit IDs),
/// the identifier, the DLC code and the data in uppercase hex.
pub fn encode_frame(frame: &CanFrame) -> Vec<u8> {
    let mut out = Vec::with_capacity(12 + 2 * frame.len());
    let kind = match (frame.is_fd(), frame.brs()) {
        (true, true) => b'b',
        (true, false) => b'd',
        (false, _) => b't',
    };
    if frame.is_extended() {
        out.push(kind.to_ascii_uppercase());
        push_hex(&mut out, frame.raw_id(), 8);
    } else {
        out.push(kind);
        push_hex(&mut out, frame.raw_id(), 3);
    }
    let dlc = if frame.is_fd() {
        len_to_dlc(frame.len()).unwrap_or(0)
    } else {
        u8::try_from(frame.len()).unwrap_or(0)
    };
    push_hex(&mut out, u32::from(dlc), 1);
    for &b in frame.data() {
        push_hex(&mut out, u32::from(b), 2);
    }
    out.push(ACK);
    out
}

fn push_hex(out: &mut Vec<u8>, value: u32, digits: u32) {
    const HEX: &[u8; 16] = b"0123456789ABCDEF";
    for i in (0..digits).rev() {
        let nibble = (value >> (4 * i)) & 0xF;
        out.push(HEX[nibble as usize]);
    }
}

fn hex_value(c: u8) -> Option<u8> {
    match c {
        b'0'..=b'9' => Some(c - b'0'),
        b'a'..=b'f' => Some(c - b'a' + 10),
        b'A'..=b'F' => Some(c - b'A' + 10),
        _ => None,
    }
}

fn hex_field(line: &[u8], from: usize, digits: usize) -> Result<u32, FrameLineError> {
    let mut v = 0u32;
    for at in from..from + digits {
        let c = line.get(at).copied().ok_or(FrameLineError::Length {
            got: line.len(),
            expected: from + digits,
        })?;
        v = (v << 4) | u32::from(hex_value(c).ok_or(FrameLineError::NotHex { at })?);
    }
    Ok(v)
}

/// Parses a frame line (without its `\r`). `timestamp`: also accept 4 trailing hex digits
/// (a millisecond timestamp some firmwares append to received frames), ignored.
///
/// # Errors
/// [`FrameLineError`] saying what is wrong.
pub fn parse_frame(line: &[u8], timestamp: bool) -> Result<CanFrame, FrameLineError> {
    let (&kind, _) = line.split_first().ok_or(FrameLineError::NotAFrame)?;
    let (fd, brs) = match kind.to_ascii_lowercase() {
        b't' => (false, false),
        b'd' => (true, false),
        b'b' => (true, true),
        _ => return Err(FrameLineError::NotAFrame),
    };
    let extended = kind.is_ascii_uppercase();
    let id_digits = if extended { 8 } else { 3 };
    let id = hex_field(line, 1, id_digits)?;
    let dlc_at = 1 + id_digits;
    let dlc = u8::try_from(hex_field(line, dlc_at, 1)?).unwrap_or(u8::MAX);
    if !fd && dlc > 8 {
        return Err(FrameLineError::BadDlc { dlc });
    }
    let len = if fd {
        dlc_to_len(dlc).ok_or(FrameLineError::BadDlc { dlc })?
    } else {
        usize::from(dlc)
    };
    let expected = dlc_at + 1 + 2 * len;
    if line.len() != expected && !(timestamp && line.len() == expected + 4) {
        return Err(FrameLineError::Length {
            got: line.len(),
            expected,
        });
    }
    if line.len() > expected {
        hex_field(line, expected, 4)?;
    }
    let mut data = [0u8; 64];
    for (i, slot) in data.iter_mut().take(len).enumerate() {
        *slot = u8::try_from(hex_field(line, dlc_at + 1 + 2 * i, 2)?).unwrap_or(0);
    }
    let data = data.get(..len).unwrap_or_default();
    let ident = if extended {
        CanFrame::extended_id(id).map_err(|_| FrameLineError::IdOutOfRange { id })?
    } else {
        let raw = u16::try_from(id).map_err(|_| FrameLineError::IdOutOfRange { id })?;
        CanFrame::standard_id(raw).map_err(|_| FrameLineError::IdOutOfRange { id })?
    };
    let frame = if fd {
        CanFrame::new_fd(ident, data).map(|f| f.with_brs(brs))
    } else {
        CanFrame::new_classic(ident, data)
    };
    frame.map_err(|_| FrameLineError::BadDlc { dlc })
}

/// The line of a command, with its `\r`.
pub fn encode_command(command: &Command) -> Vec<u8> {
    let digit = |letter: u8, d: u8| vec![letter, b'0' + d.min(9), ACK];
    match command {
        Command::Empty => vec![ACK],
        Command::Open => b"O\r".to_vec(),
        Command::Listen => b"L\r".to_vec(),
        Command::Close => b"C\r".to_vec(),
        Command::Nominal(code) => digit(b'S', *code),
        Command::Data(code) => digit(b'Y', *code),
        Command::Silent(on) => digit(b'M', u8::from(*on)),
        Command::AutoRetransmit(on) => digit(b'A', u8::from(*on)),
        Command::Version => b"V\r".to_vec(),
        Command::Serial => b"N\r".to_vec(),
        Command::Status => b"F\r".to_vec(),
        Command::Frame(frame) => encode_frame(frame),
    }
}

/// Parses a host's line (without its `\r`), as an adapter does.
///
/// # Errors
/// [`CommandError`]: the adapter answers BEL.
pub fn parse_command(line: &[u8]) -> Result<Command, CommandError> {
    let Some((&first, rest)) = line.split_first() else {
        return Ok(Command::Empty);
    };
    let letter = char::from(first);
    let bare = |c: Command| {
        if rest.is_empty() {
            Ok(c)
        } else {
            Err(CommandError::BadArgument {
                command: letter,
                reason: "takes no argument",
            })
        }
    };
    let digit = || match rest {
        [d @ b'0'..=b'9'] => Ok(d - b'0'),
        _ => Err(CommandError::BadArgument {
            command: letter,
            reason: "takes one digit",
        }),
    };
    let flag = || match digit()? {
        0 => Ok(false),
        1 => Ok(true),
        _ => Err(CommandError::BadArgument {
            command: letter,
            reason: "takes 0 or 1",
        }),
    };
    match first {
        b'O' => bare(Command::Open),
        b'L' => bare(Command::Listen),
        b'C' => bare(Command::Close),
        b'V' => bare(Command::Version),
        b'N' => bare(Command::Serial),
        b'F' => bare(Command::Status),
        b'S' => {
            let code = digit()?;
            if usize::from(code) < NOMINAL_RATES.len() {
                Ok(Command::Nominal(code))
            } else {
                Err(CommandError::BadArgument {
                    command: letter,
                    reason: "no such nominal rate (S0..S8)",
                })
            }
        }
        b'Y' => {
            let code = digit()?;
            if data_rate(code).is_some() {
                Ok(Command::Data(code))
            } else {
                Err(CommandError::BadArgument {
                    command: letter,
                    reason: "no such data rate (Y2, Y5)",
                })
            }
        }
        b'M' => Ok(Command::Silent(flag()?)),
        b'A' => Ok(Command::AutoRetransmit(flag()?)),
        b't' | b'T' | b'd' | b'D' | b'b' | b'B' => Ok(Command::Frame(parse_frame(line, false)?)),
        _ => Err(CommandError::Unknown(letter)),
    }
}

/// What a host reads: one message from the adapter.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reply {
    /// `\r` alone: the oldest outstanding command was carried out.
    Ack,
    /// `z\r` / `Z\r`: a sent frame was carried out (Lawicel's transmit acknowledgement).
    TxAck,
    /// BEL: the oldest outstanding command was refused.
    Refused,
    /// A received frame.
    Frame(CanFrame),
    /// `V…`: the version text after the `V`.
    Version(String),
    /// `N…`: the serial number after the `N`.
    Serial(String),
    /// `Fxx`: the status flags.
    Status(u8),
    /// A line that is none of these (the line, at most [`MAX_LINE`] bytes).
    Garbage(Vec<u8>),
}

/// Lawicel status flag: the receive FIFO overflowed (frames lost).
pub const STATUS_RX_FULL: u8 = 1 << 0;
/// Lawicel status flag: the transmit FIFO overflowed (frames lost).
pub const STATUS_TX_FULL: u8 = 1 << 1;
/// Lawicel status flag: error warning (an error counter reached 96).
pub const STATUS_ERROR_WARNING: u8 = 1 << 2;
/// Lawicel status flag: data overrun.
pub const STATUS_OVERRUN: u8 = 1 << 3;
/// Lawicel status flag: error passive (an error counter reached 128).
pub const STATUS_ERROR_PASSIVE: u8 = 1 << 5;
/// Lawicel status flag: arbitration lost.
pub const STATUS_ARBITRATION_LOST: u8 = 1 << 6;
/// Lawicel status flag: bus error; `CANable`-class adapters raise it while the controller
/// is bus-off.
pub const STATUS_BUS_ERROR: u8 = 1 << 7;

/// Parses one adapter message: a line without its `\r`, or `None` for a BEL.
pub fn parse_reply(line: Option<&[u8]>) -> Reply {
    let Some(line) = line else {
        return Reply::Refused;
    };
    let text = || String::from_utf8_lossy(line.get(1..).unwrap_or_default()).into_owned();
    match line.first() {
        None => Reply::Ack,
        Some(b'z' | b'Z') if line.len() == 1 => Reply::TxAck,
        Some(b't' | b'T' | b'd' | b'D' | b'b' | b'B') => {
            parse_frame(line, true).map_or_else(|_| Reply::Garbage(line.to_vec()), Reply::Frame)
        }
        Some(b'V') if line.len() > 1 && line.iter().all(u8::is_ascii_graphic) => {
            Reply::Version(text())
        }
        Some(b'N') if line.len() > 1 && line.iter().all(u8::is_ascii_graphic) => {
            Reply::Serial(text())
        }
        Some(b'F') if line.len() == 3 => hex_field(line, 1, 2)
            .ok()
            .and_then(|v| u8::try_from(v).ok())
            .map_or_else(|| Reply::Garbage(line.to_vec()), Reply::Status),
        Some(_) => Reply::Garbage(line.to_vec()),
    }
}

/// Splits a byte stream into messages: lines ended by `\r`, and BEL on its own. Bounded:
/// a line longer than [`MAX_LINE`] is dropped with everything up to the next `\r`.
#[derive(Debug, Default, Clone)]
pub struct LineSplitter {
    line: Vec<u8>,
    /// Dropping an over-long line until its `\r`.
    overlong: bool,
    /// Over-long lines dropped so far.
    dropped: u64,
}

/// One message out of a [`LineSplitter`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Message {
    /// A line, without its `\r`.
    Line(Vec<u8>),
    /// A BEL.
    Bel,
    /// An over-long line was dropped (reported once per line).
    Overlong,
}

impl LineSplitter {
    /// An empty splitter.
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds `bytes`, calling `out` with each complete message in order.
    pub fn feed(&mut self, bytes: &[u8], mut out: impl FnMut(Message)) {
        for &b in bytes {
            match b {
                ACK => {
                    if self.overlong {
                        self.overlong = false;
                    } else {
                        out(Message::Line(core::mem::take(&mut self.line)));
                    }
                }
                BEL if !self.overlong => {
                    // A BEL ends whatever came before it on the line (a refusal is sent
                    // alone; anything half-received before it is noise).
                    self.line.clear();
                    out(Message::Bel);
                }
                // Line feeds some terminals add are not part of the protocol.
                b'\n' => {}
                _ if self.overlong => {}
                _ if self.line.len() >= MAX_LINE => {
                    self.line.clear();
                    self.overlong = true;
                    self.dropped += 1;
                    out(Message::Overlong);
                }
                _ => self.line.push(b),
            }
        }
    }

    /// Bytes of an unfinished line held.
    pub fn pending(&self) -> usize {
        self.line.len()
    }

    /// Forgets an unfinished line.
    pub fn clear(&mut self) {
        self.line.clear();
        self.overlong = false;
    }

    /// Over-long lines dropped so far.
    pub const fn dropped(&self) -> u64 {
        self.dropped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fd(id: u16, data: &[u8]) -> CanFrame {
        CanFrame::new_fd(CanFrame::standard_id(id).unwrap(), data).unwrap()
    }

    #[test]
    fn frames_encode_byte_exact_with_fd_dlc_codes() {
        assert_eq!(
            encode_frame(&fd(0x007, &[0x01, 0x0A, 0xFF])),
            b"b0073010AFF\r"
        );
        assert_eq!(
            encode_frame(&fd(0x507, &[0u8; 16])),
            [b"b507A".as_slice(), &[b'0'; 32], b"\r"].concat()
        );
        assert_eq!(encode_frame(&fd(0x7FF, &[0u8; 64])).get(4), Some(&b'F'));
        assert_eq!(encode_frame(&fd(0x001, &[0u8; 12])).get(4), Some(&b'9'));
        assert_eq!(encode_frame(&fd(0x123, &[])), b"b1230\r");
        assert_eq!(
            encode_frame(&fd(0x123, &[0xAB]).with_brs(false)),
            b"d1231AB\r"
        );
        let classic = CanFrame::new_classic(CanFrame::standard_id(0x12).unwrap(), &[1, 2]);
        assert_eq!(encode_frame(&classic.unwrap()), b"t01220102\r");
        let ext = CanFrame::new_fd(CanFrame::extended_id(0x1ABC_DEF0).unwrap(), &[0x55]);
        assert_eq!(encode_frame(&ext.unwrap()), b"B1ABCDEF0155\r");
    }

    #[test]
    fn frame_lines_round_trip_and_every_length_is_checked() {
        for len in [0usize, 1, 8, 12, 16, 20, 24, 32, 48, 64] {
            let data: Vec<u8> = (0..len).map(|i| u8::try_from(i).unwrap()).collect();
            for frame in [fd(0x105, &data), fd(0x105, &data).with_brs(false)] {
                let line = encode_frame(&frame);
                let body = line.strip_suffix(b"\r").unwrap();
                assert_eq!(parse_frame(body, false), Ok(frame));
                assert!(body.len() <= MAX_LINE);
            }
        }
        // Lowercase hex is accepted; a timestamp only where asked for.
        assert_eq!(parse_frame(b"b1071ab", false), Ok(fd(0x107, &[0xAB])));
        assert_eq!(parse_frame(b"b1071AB1234", true), Ok(fd(0x107, &[0xAB])));
        assert_eq!(
            parse_frame(b"b1071AB1234", false),
            Err(FrameLineError::Length {
                got: 11,
                expected: 7
            })
        );
        assert_eq!(
            parse_frame(b"b1079AB", false),
            Err(FrameLineError::Length {
                got: 7,
                expected: 29
            })
        );
        assert_eq!(
            parse_frame(b"t1079", false),
            Err(FrameLineError::BadDlc { dlc: 9 })
        );
        assert_eq!(
            parse_frame(b"b8001AB", false),
            Err(FrameLineError::IdOutOfRange { id: 0x800 })
        );
        assert_eq!(
            parse_frame(b"B200000001AB", false),
            Err(FrameLineError::IdOutOfRange { id: 0x2000_0000 })
        );
        assert_eq!(
            parse_frame(b"b1G71AB", false),
            Err(FrameLineError::NotHex { at: 2 })
        );
        assert_eq!(parse_frame(b"x", false), Err(FrameLineError::NotAFrame));
        assert_eq!(parse_frame(b"", false), Err(FrameLineError::NotAFrame));
    }

    #[test]
    fn commands_encode_and_parse_back_and_bad_ones_are_refused() {
        for cmd in [
            Command::Open,
            Command::Listen,
            Command::Close,
            Command::Nominal(8),
            Command::Nominal(0),
            Command::Data(2),
            Command::Data(5),
            Command::Silent(false),
            Command::Silent(true),
            Command::AutoRetransmit(true),
            Command::Version,
            Command::Serial,
            Command::Status,
            Command::Frame(fd(0x7, &[1, 2, 3])),
        ] {
            let line = encode_command(&cmd);
            assert_eq!(line.last(), Some(&b'\r'));
            assert_eq!(parse_command(line.strip_suffix(b"\r").unwrap()), Ok(cmd));
        }
        assert_eq!(encode_command(&Command::Nominal(8)), b"S8\r");
        assert_eq!(encode_command(&Command::Data(5)), b"Y5\r");
        assert_eq!(parse_command(b""), Ok(Command::Empty));
        assert_eq!(parse_command(b"Q"), Err(CommandError::Unknown('Q')));
        for bad in [
            &b"S9"[..],
            b"S",
            b"S88",
            b"Y3",
            b"Y",
            b"M2",
            b"A",
            b"Ox",
            b"F1",
        ] {
            assert!(
                matches!(parse_command(bad), Err(CommandError::BadArgument { .. })),
                "{bad:?}"
            );
        }
        assert!(matches!(
            parse_command(b"b1073AB"),
            Err(CommandError::Frame(FrameLineError::Length { .. }))
        ));
    }

    #[test]
    fn replies_parse_and_garbage_is_named() {
        assert_eq!(parse_reply(Some(b"")), Reply::Ack);
        assert_eq!(parse_reply(None), Reply::Refused);
        assert_eq!(parse_reply(Some(b"z")), Reply::TxAck);
        assert_eq!(parse_reply(Some(b"Z")), Reply::TxAck);
        assert_eq!(parse_reply(Some(b"V1013")), Reply::Version("1013".into()));
        assert_eq!(parse_reply(Some(b"NA1B2")), Reply::Serial("A1B2".into()));
        assert_eq!(parse_reply(Some(b"FA4")), Reply::Status(0xA4));
        assert_eq!(
            parse_reply(Some(b"b1071AB")),
            Reply::Frame(fd(0x107, &[0xAB]))
        );
        for g in [&b"FX1"[..], b"F123", b"hello", b"b10", b"V", b"\xff"] {
            assert_eq!(parse_reply(Some(g)), Reply::Garbage(g.to_vec()), "{g:?}");
        }
    }

    #[test]
    fn the_splitter_resynchronises_at_a_carriage_return_and_stays_bounded() {
        let mut s = LineSplitter::new();
        let mut got = Vec::new();
        s.feed(b"\rb1071AB\r\x07z\r\nV10", |m| got.push(m));
        s.feed(b"13\r", |m| got.push(m));
        assert_eq!(
            got,
            [
                Message::Line(vec![]),
                Message::Line(b"b1071AB".to_vec()),
                Message::Bel,
                Message::Line(b"z".to_vec()),
                Message::Line(b"V1013".to_vec()),
            ]
        );
        got.clear();
        // A megabyte of garbage without a carriage return: one report, nothing kept.
        s.feed(&vec![b'x'; 1 << 20], |m| got.push(m));
        assert_eq!(got, [Message::Overlong]);
        assert_eq!(s.pending(), 0);
        got.clear();
        s.feed(b"yy\rb1071AB\r", |m| got.push(m));
        assert_eq!(got, [Message::Line(b"b1071AB".to_vec())]);
        assert_eq!(s.dropped(), 1);
    }

    #[test]
    fn rate_codes_and_their_lists() {
        assert_eq!(nominal_code(1_000_000), Some(8));
        assert_eq!(nominal_code(10_000), Some(0));
        assert_eq!(nominal_code(800_000), None);
        assert_eq!(data_code(5_000_000), Some(5));
        assert_eq!(data_code(4_000_000), Some(4));
        assert_eq!(data_code(500_000), None);
        assert_eq!(data_rate(2), Some(2_000_000));
        assert_eq!(
            list_rates(DATA_RATES.map(|d| d.1)),
            "1000000, 2000000, 4000000, 5000000"
        );
    }
}
