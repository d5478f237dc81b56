//! The fdcanusb line protocol as pure functions, for both ends: the host's commands and
//! the device's replies, each one text line.
//!
//! The host sends one command a line (ended by `\n`; the device also takes `\r`) and the
//! device answers every command with optional reply lines and then exactly one final line,
//! `OK` or `ERR <details>` (ended by `\r\n`). While the bus is on, the device also sends a
//! line for every frame it receives, unasked, between the lines of any answer:
//!
//! ```text
//! host   can std 201 50C30000 BF
//! device rcv 501 0000000050C30000000000000000803F e B F r t1234567 f-1
//! device OK
//! ```
//!
//! A received frame's line carries its identifier and data in hexadecimal and then
//! separate flags: `E`/`e` extended / base identifier, `B`/`b` bit-rate switch on / off,
//! `F`/`f` CAN FD / classic format, `R`/`r` remote / data frame, `tNNNN` the device's
//! receive time in microseconds (a 32-bit counter that wraps) and `fNN` the index of the
//! filter that matched it, in hexadecimal (`-1`: none). Firmware that leaves flags out is
//! understood: a missing `F` is a classic frame, a missing `E` a base identifier.
//!
//! A frame without data bytes cannot be sent: `can std ID` with no data is refused by the
//! firmware (`ERR insufficient options`), and [`encode_send`] refuses it before then.
//!
//! `can status` answers one line of `key=value` fields: `lec`, `dlec` (last error codes),
//! `err` (error passive), `warn` (error warning), `busoff`, `pexc` (protocol exception),
//! `tdc`; the emulated adapter adds `rxovf`, the frames it dropped because the host did
//! not read them in time. Fields the reader does not know are skipped.
//!
//! Every reader here is bounded: a line is at most [`MAX_LINE`] bytes ([`LineSplitter`]
//! skips a longer one, and bytes that are not printable ASCII, to the next line end) and
//! every parser refuses what is not the protocol with an error that quotes at most
//! [`QUOTED`] characters of it.

use core::fmt::{self, Write as _};

use robobus_whj::frame::{CanFrame, Id, MAX_CLASSIC_LEN, MAX_FD_LEN};

/// The longest line either end accepts, without its line end. The longest line of the
/// protocol, a received 64-byte frame with an extended identifier and every flag, is
/// about 170 characters.
pub const MAX_LINE: usize = 256;

/// At most this many characters of a bad line are quoted in an error.
pub const QUOTED: usize = 48;

/// The nominal (arbitration) bit rate setting, bit/s.
pub const BITRATE: &str = "can.bitrate";
/// The data-phase bit rate setting (used with bit-rate switch), bit/s.
pub const FD_BITRATE: &str = "can.fd_bitrate";
/// Whether frames are sent in CAN FD format by default (`1`) or classic (`0`).
pub const FDCAN_FRAME: &str = "can.fdcan_frame";
/// Whether CAN FD frames switch to the data bit rate by default.
pub const BITRATE_SWITCH: &str = "can.bitrate_switch";
/// Whether an unacknowledged frame is sent again until it is acknowledged.
pub const AUTOMATIC_RETRANSMISSION: &str = "can.automatic_retransmission";

/// A host command, as the device reads it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Command {
    /// `can on`: join the bus with the configured settings.
    CanOn,
    /// `can off`: leave the bus; settings may be changed again.
    CanOff,
    /// `can status`: the controller's error state.
    CanStatus,
    /// `conf get KEY`.
    ConfGet {
        /// The setting.
        key: String,
    },
    /// `conf set KEY VALUE`.
    ConfSet {
        /// The setting.
        key: String,
        /// Its new value, as text.
        value: String,
    },
    /// `can std ...` / `can ext ...`: send a frame.
    Send(SendRequest),
}

/// A frame to send, as `can std` / `can ext` give it: what the flags leave open
/// (`None`) the device's defaults (`can.fdcan_frame`, `can.bitrate_switch`) decide.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SendRequest {
    /// The identifier (`can std`: 11 bits, `can ext`: 29 bits).
    pub id: Id,
    /// The payload.
    pub data: Vec<u8>,
    /// `B` / `b`: bit-rate switch on / off.
    pub brs: Option<bool>,
    /// `F` / `f`: CAN FD / classic format.
    pub fd: Option<bool>,
    /// `R` / `r`: remote / data frame.
    pub remote: Option<bool>,
}

impl SendRequest {
    /// The frame this request sends on a device whose defaults are `fd_default` and
    /// `brs_default`, or why the device refuses it (`ERR ...`'s details).
    pub fn frame(&self, fd_default: bool, brs_default: bool) -> Result<CanFrame, String> {
        if self.remote == Some(true) {
            return Err("remote frames are not supported".into());
        }
        let fd = self.fd.unwrap_or(fd_default);
        let built = if fd {
            CanFrame::new_fd(self.id, &self.data)
                .map(|f| f.with_brs(self.brs.unwrap_or(brs_default)))
        } else {
            CanFrame::new_classic(self.id, &self.data)
        };
        built.map_err(|e| format!("data invalid length: {e}"))
    }
}

/// Why a line is not a command the device knows (the text after `ERR `).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct CommandError(pub String);

/// Reads one host command line (without its line end).
///
/// # Errors
/// [`CommandError`] with the details an fdcanusb gives after `ERR`.
pub fn parse_command(line: &str) -> Result<Command, CommandError> {
    let err = |s: &str| Err(CommandError(s.into()));
    let mut words = line.split(' ').filter(|w| !w.is_empty());
    match (words.next(), words.next()) {
        (Some("can"), Some("on")) => Ok(Command::CanOn),
        (Some("can"), Some("off")) => Ok(Command::CanOff),
        (Some("can"), Some("status")) => Ok(Command::CanStatus),
        (Some("can"), Some(kind @ ("std" | "ext"))) => {
            parse_send(kind == "ext", words).map(Command::Send)
        }
        (Some("conf"), Some("get")) => match (words.next(), words.next()) {
            (Some(key), None) => Ok(Command::ConfGet { key: key.into() }),
            _ => err("usage: conf get KEY"),
        },
        (Some("conf"), Some("set")) => match (words.next(), words.next(), words.next()) {
            (Some(key), Some(value), None) => Ok(Command::ConfSet {
                key: key.into(),
                value: value.into(),
            }),
            _ => err("usage: conf set KEY VALUE"),
        },
        (Some("can" | "conf"), _) => err("unknown subcommand"),
        _ => err("unknown command"),
    }
}

fn parse_send<'a>(
    extended: bool,
    mut words: impl Iterator<Item = &'a str>,
) -> Result<SendRequest, CommandError> {
    let err = |s: &str| CommandError(s.into());
    let (Some(hexid), Some(hexdata)) = (words.next(), words.next()) else {
        return Err(err("insufficient options"));
    };
    let raw = parse_hex_id(hexid).ok_or_else(|| err("bad id"))?;
    let id = if extended {
        CanFrame::extended_id(raw).ok()
    } else {
        u16::try_from(raw)
            .ok()
            .and_then(|r| CanFrame::standard_id(r).ok())
    }
    .ok_or_else(|| err("bad id"))?;
    let data = parse_hex_data(hexdata).ok_or_else(|| err("invalid data"))?;
    let mut req = SendRequest {
        id,
        data,
        brs: None,
        fd: None,
        remote: None,
    };
    for c in words.flat_map(str::chars) {
        match c {
            'B' | 'b' => req.brs = Some(c == 'B'),
            'F' | 'f' => req.fd = Some(c == 'F'),
            'R' | 'r' => req.remote = Some(c == 'R'),
            _ => return Err(err("unknown flag")),
        }
    }
    Ok(req)
}

/// A hexadecimal identifier of 1..=8 digits.
fn parse_hex_id(s: &str) -> Option<u32> {
    if s.is_empty() || s.len() > 8 || !s.bytes().all(|b| b.is_ascii_hexdigit()) {
        return None;
    }
    u32::from_str_radix(s, 16).ok()
}

/// Pairs of hexadecimal digits, at most [`MAX_FD_LEN`] bytes.
fn parse_hex_data(s: &str) -> Option<Vec<u8>> {
    if !s.len().is_multiple_of(2) || s.len() > 2 * MAX_FD_LEN {
        return None;
    }
    s.as_bytes()
        .chunks(2)
        .map(|pair| {
            let text = core::str::from_utf8(pair).ok()?;
            if !text.bytes().all(|b| b.is_ascii_hexdigit()) {
                return None;
            }
            u8::from_str_radix(text, 16).ok()
        })
        .collect()
}

impl fmt::Display for Command {
    /// The command line, without its line end.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::CanOn => f.write_str("can on"),
            Self::CanOff => f.write_str("can off"),
            Self::CanStatus => f.write_str("can status"),
            Self::ConfGet { key } => write!(f, "conf get {key}"),
            Self::ConfSet { key, value } => write!(f, "conf set {key} {value}"),
            Self::Send(req) => {
                let (kind, raw) = match req.id {
                    Id::Standard(id) => ("std", u32::from(id.as_raw())),
                    Id::Extended(id) => ("ext", id.as_raw()),
                };
                write!(f, "can {kind} {raw:X} ")?;
                for b in &req.data {
                    write!(f, "{b:02X}")?;
                }
                let flags: String = [
                    req.brs.map(|on| if on { 'B' } else { 'b' }),
                    req.fd.map(|on| if on { 'F' } else { 'f' }),
                    req.remote.map(|on| if on { 'R' } else { 'r' }),
                ]
                .into_iter()
                .flatten()
                .collect();
                if !flags.is_empty() {
                    write!(f, " {flags}")?;
                }
                Ok(())
            }
        }
    }
}

/// The command line (with its `\n`) that sends `frame` exactly as it is: its format and
/// bit-rate switch given as flags, so the device's defaults do not matter.
///
/// # Errors
/// The reason an fdcanusb cannot send the frame: the protocol has no way to write an
/// empty payload (the device would read the flags as the data).
pub fn encode_send(frame: &CanFrame) -> Result<String, String> {
    if frame.is_empty() {
        return Err(
            "an fdcanusb cannot send a frame without data bytes (its `can std` needs at least \
             one; a WHJ bus asks status by broadcast instead): use an slcan adapter or \
             SocketCAN for such frames"
                .into(),
        );
    }
    let req = SendRequest {
        id: frame.id(),
        data: frame.data().to_vec(),
        brs: Some(frame.brs()),
        fd: Some(frame.is_fd()),
        remote: None,
    };
    Ok(format!("{}\n", Command::Send(req)))
}

/// A command line with its `\n`.
pub fn encode_command(cmd: &Command) -> String {
    format!("{cmd}\n")
}

/// A received frame as the device reports it (`rcv ...`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RcvLine {
    /// The frame (its FD and bit-rate-switch flags as received).
    pub frame: CanFrame,
    /// The device's receive time, µs (wraps at 2³²), if the line has one.
    pub timestamp_us: Option<u32>,
    /// The index of the filter that matched (`-1`: none), if the line has one (written in
    /// hexadecimal on the line).
    pub filter: Option<i32>,
}

/// A line the device sent, as the host reads it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DeviceLine {
    /// `OK`: the command in front succeeded.
    Ok,
    /// `ERR <details>`: the command in front failed.
    Err(String),
    /// A received data frame.
    Rcv(RcvLine),
    /// A received remote frame (robobus frames carry no remote frames; counted and skipped).
    RcvRemote,
    /// Any other line: a reply line of the command in front (a `conf get` value, a
    /// `can status` line).
    Text(String),
}

/// Why a `rcv` line does not parse.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("malformed rcv line {line:?}: {reason}")]
pub struct RcvError {
    /// At most [`QUOTED`] characters of the line.
    pub line: String,
    /// What is wrong.
    pub reason: &'static str,
}

/// Reads one device line (without its line end).
///
/// # Errors
/// [`RcvError`] for a `rcv` line that is not a frame.
pub fn parse_device_line(line: &str) -> Result<DeviceLine, RcvError> {
    if line == "OK" {
        return Ok(DeviceLine::Ok);
    }
    if line == "ERR" {
        return Ok(DeviceLine::Err(String::new()));
    }
    if let Some(details) = line.strip_prefix("ERR ") {
        return Ok(DeviceLine::Err(details.to_owned()));
    }
    if let Some(rest) = line.strip_prefix("rcv ").or((line == "rcv").then_some("")) {
        return parse_rcv(rest).map_err(|reason| RcvError {
            line: quote(line),
            reason,
        });
    }
    Ok(DeviceLine::Text(line.to_owned()))
}

/// The fields after `rcv `: the identifier, the data (possibly empty: two spaces in a
/// row) and the flags, separated by single spaces.
fn parse_rcv(rest: &str) -> Result<DeviceLine, &'static str> {
    let mut fields = rest.split(' ');
    let raw = fields
        .next()
        .and_then(parse_hex_id)
        .ok_or("the identifier is not 1..=8 hexadecimal digits")?;
    let data = fields
        .next()
        .and_then(parse_hex_data)
        .ok_or("the data is not pairs of hexadecimal digits (at most 64 bytes)")?;
    let (mut extended, mut brs, mut fd, mut remote) = (false, false, false, false);
    let (mut timestamp_us, mut filter) = (None, None);
    for field in fields.filter(|f| !f.is_empty()) {
        match field {
            "E" | "e" => extended = field == "E",
            "B" | "b" => brs = field == "B",
            "F" | "f" => fd = field == "F",
            "R" | "r" => remote = field == "R",
            _ => {
                if let Some(t) = field.strip_prefix('t') {
                    timestamp_us = Some(
                        t.parse::<u32>()
                            .ok()
                            .filter(|_| t.bytes().all(|b| b.is_ascii_digit()))
                            .ok_or("the timestamp is not a 32-bit count of µs")?,
                    );
                } else if let Some(n) = field.strip_prefix('f') {
                    filter = Some(parse_filter(n).ok_or("the filter index is not -1 or 00..=FF")?);
                } else {
                    return Err("unknown flag");
                }
            }
        }
    }
    if remote {
        return Ok(DeviceLine::RcvRemote);
    }
    let id = if extended {
        CanFrame::extended_id(raw).map_err(|_| "extended identifier above 0x1FFFFFFF")?
    } else {
        u16::try_from(raw)
            .ok()
            .and_then(|r| CanFrame::standard_id(r).ok())
            .ok_or("base identifier above 0x7FF")?
    };
    let frame = if fd {
        CanFrame::new_fd(id, &data)
            .map_err(|_| "CAN FD data of a length no DLC has")?
            .with_brs(brs)
    } else if data.len() <= MAX_CLASSIC_LEN {
        CanFrame::new_classic(id, &data).map_err(|_| "classic data above 8 bytes")?
    } else {
        return Err("classic data above 8 bytes");
    };
    Ok(DeviceLine::Rcv(RcvLine {
        frame,
        timestamp_us,
        filter,
    }))
}

/// A filter index: `-1` (none matched) or one or two hexadecimal digits (the firmware
/// writes it as a hex byte).
fn parse_filter(n: &str) -> Option<i32> {
    if n == "-1" {
        return Some(-1);
    }
    if n.is_empty() || n.len() > 2 || !n.bytes().all(|b| b.is_ascii_hexdigit()) {
        return None;
    }
    i32::from_str_radix(n, 16).ok()
}

/// The device's line (with `\r\n`) for a received frame.
pub fn encode_rcv(frame: &CanFrame, timestamp_us: Option<u32>, filter: Option<i32>) -> String {
    let mut line = format!("rcv {:X} ", frame.raw_id());
    for b in frame.data() {
        let _ = write!(line, "{b:02X}");
    }
    let _ = write!(
        line,
        " {} {} {} r",
        if frame.is_extended() { 'E' } else { 'e' },
        if frame.brs() { 'B' } else { 'b' },
        if frame.is_fd() { 'F' } else { 'f' },
    );
    if let Some(t) = timestamp_us {
        let _ = write!(line, " t{t}");
    }
    match filter {
        Some(n) if n < 0 => line.push_str(" f-1"),
        Some(n) => {
            let _ = write!(line, " f{n:02X}");
        }
        None => {}
    }
    line.push_str("\r\n");
    line
}

/// The device's final line for a command that succeeded.
pub const OK_LINE: &str = "OK\r\n";

/// The device's final line for a command that failed.
pub fn encode_err(details: &str) -> String {
    format!("ERR {details}\r\n")
}

/// The controller's state as `can status` reports it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[allow(clippy::struct_excessive_bools)] // the firmware's own flags, one field each
pub struct Status {
    /// Last error code of the arbitration phase (0 none, 7 unchanged).
    pub lec: u32,
    /// Last error code of the data phase.
    pub dlec: u32,
    /// Error passive (an error counter at 128 or more).
    pub error_passive: bool,
    /// Error warning (an error counter at 96 or more).
    pub warning: bool,
    /// Bus-off (the transmit error counter passed 255).
    pub bus_off: bool,
    /// A protocol exception was seen.
    pub protocol_exception: bool,
    /// The transmitter delay compensation value.
    pub tdc: u32,
    /// Frames the device dropped because its line to the host was full (the emulated
    /// adapter's field; `None` when the line has none).
    pub rx_overruns: Option<u32>,
}

/// Why a `can status` line does not parse.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("malformed status line {line:?}: {reason}")]
pub struct StatusError {
    /// At most [`QUOTED`] characters of the line.
    pub line: String,
    /// What is wrong.
    pub reason: &'static str,
}

/// Reads a `can status` reply line. It must carry `busoff` and `err`; fields it does not
/// know are skipped.
///
/// # Errors
/// [`StatusError`] for a line without the two fields or with a value that is not a number.
pub fn parse_status(line: &str) -> Result<Status, StatusError> {
    let bad = |reason| StatusError {
        line: quote(line),
        reason,
    };
    let mut status = Status::default();
    let (mut saw_busoff, mut saw_err) = (false, false);
    for field in line.split(' ').filter(|f| !f.is_empty()) {
        let (key, value) = field
            .split_once('=')
            .ok_or_else(|| bad("a field is not key=value"))?;
        let value: u32 = value.parse().map_err(|_| bad("a value is not a number"))?;
        match key {
            "lec" => status.lec = value,
            "dlec" => status.dlec = value,
            "err" => {
                status.error_passive = value != 0;
                saw_err = true;
            }
            "warn" => status.warning = value != 0,
            "busoff" => {
                status.bus_off = value != 0;
                saw_busoff = true;
            }
            "pexc" => status.protocol_exception = value != 0,
            "tdc" => status.tdc = value,
            "rxovf" => status.rx_overruns = Some(value),
            _ => {}
        }
    }
    if !(saw_busoff && saw_err) {
        return Err(bad("no busoff= and err= fields"));
    }
    Ok(status)
}

/// The device's `can status` reply line (with `\r\n`).
pub fn encode_status(s: &Status) -> String {
    let mut line = format!(
        "lec={} dlec={} err={} warn={} busoff={} pexc={} tdc={}",
        s.lec,
        s.dlec,
        u8::from(s.error_passive),
        u8::from(s.warning),
        u8::from(s.bus_off),
        u8::from(s.protocol_exception),
        s.tdc
    );
    if let Some(n) = s.rx_overruns {
        let _ = write!(line, " rxovf={n}");
    }
    line.push_str("\r\n");
    line
}

/// At most [`QUOTED`] characters of `s`, for messages.
pub fn quote(s: &str) -> String {
    s.chars().take(QUOTED).collect()
}

/// What [`LineSplitter`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Line<'a> {
    /// A complete line of printable ASCII, without its line end (never empty).
    Text(&'a str),
    /// A line skipped: longer than [`MAX_LINE`], or with bytes that are not printable
    /// ASCII. `len` is how many bytes it had (counted up to [`usize::MAX`]).
    Garbage {
        /// Bytes skipped.
        len: usize,
    },
}

/// Cuts a byte stream into lines ended by `\n` or `\r` (`\r\n` is one end; empty lines
/// are skipped). Holds at most [`MAX_LINE`] bytes: a longer line, or one with a byte that
/// is not printable ASCII, is skipped to its end and reported as [`Line::Garbage`].
#[derive(Debug, Clone, Default)]
pub struct LineSplitter {
    buf: Vec<u8>,
    /// Bytes of the current line so far when it is being skipped.
    skipping: Option<usize>,
}

impl LineSplitter {
    /// An empty splitter.
    pub fn new() -> Self {
        Self {
            buf: Vec::with_capacity(MAX_LINE),
            skipping: None,
        }
    }

    /// Feeds `bytes`, calling `out` for every line they complete, in order.
    pub fn feed(&mut self, bytes: &[u8], mut out: impl FnMut(Line<'_>)) {
        for &b in bytes {
            if b == b'\n' || b == b'\r' {
                if let Some(len) = self.skipping.take() {
                    out(Line::Garbage { len });
                } else if !self.buf.is_empty() {
                    // Every byte is printable ASCII, so this is always UTF-8.
                    if let Ok(text) = core::str::from_utf8(&self.buf) {
                        out(Line::Text(text));
                    }
                }
                self.buf.clear();
                continue;
            }
            if let Some(len) = &mut self.skipping {
                *len = len.saturating_add(1);
                continue;
            }
            if !(b == b' ' || b.is_ascii_graphic()) || self.buf.len() >= MAX_LINE {
                self.skipping = Some(self.buf.len() + 1);
                self.buf.clear();
                continue;
            }
            self.buf.push(b);
        }
    }

    /// Drops a partial line (after the input was discarded).
    pub fn clear(&mut self) {
        self.buf.clear();
        self.skipping = None;
    }

    /// Whether a partial line is held.
    pub fn is_mid_line(&self) -> bool {
        !self.buf.is_empty() || self.skipping.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fd(id: u16, data: &[u8]) -> CanFrame {
        CanFrame::new_fd(CanFrame::standard_id(id).unwrap(), data).unwrap()
    }

    #[test]
    fn host_commands_are_byte_exact() {
        let cases = [
            (Command::CanOn, "can on\n"),
            (Command::CanOff, "can off\n"),
            (Command::CanStatus, "can status\n"),
            (
                Command::ConfGet {
                    key: BITRATE.into(),
                },
                "conf get can.bitrate\n",
            ),
            (
                Command::ConfSet {
                    key: FD_BITRATE.into(),
                    value: "5000000".into(),
                },
                "conf set can.fd_bitrate 5000000\n",
            ),
        ];
        for (cmd, line) in cases {
            assert_eq!(encode_command(&cmd), line);
            assert_eq!(parse_command(line.trim_end()), Ok(cmd));
        }
        assert_eq!(
            encode_send(&fd(0x201, &[0x50, 0xC3, 0, 0])).unwrap(),
            "can std 201 50C30000 BF\n"
        );
        assert_eq!(
            encode_send(&fd(0x7, &[1]).with_brs(false)).unwrap(),
            "can std 7 01 bF\n"
        );
        let classic =
            CanFrame::new_classic(CanFrame::standard_id(0x7FF).unwrap(), &[0xAB]).unwrap();
        assert_eq!(encode_send(&classic).unwrap(), "can std 7FF AB bf\n");
        let ext = CanFrame::new_fd(CanFrame::extended_id(0x1234_5678).unwrap(), &[0; 12]).unwrap();
        assert_eq!(
            encode_send(&ext).unwrap(),
            "can ext 12345678 000000000000000000000000 BF\n"
        );
        let e = encode_send(&fd(0x7, &[])).unwrap_err();
        assert!(e.contains("without data"), "{e}");
    }

    #[test]
    fn the_device_reads_send_commands_as_the_firmware_does() {
        let Command::Send(req) = parse_command("can std 201 50C30000 BF").unwrap() else {
            panic!("not a send");
        };
        assert_eq!(req.frame(true, true), Ok(fd(0x201, &[0x50, 0xC3, 0, 0])));
        // Flags may be separated by spaces, in any order, or left to the defaults.
        let Command::Send(req) = parse_command("can std 7 0102 f  b").unwrap() else {
            panic!("not a send");
        };
        let f = req.frame(true, true).unwrap();
        assert!(!f.is_fd() && !f.brs());
        let Command::Send(req) = parse_command("can std 7 0102").unwrap() else {
            panic!("not a send");
        };
        assert_eq!(req.frame(true, false), Ok(fd(7, &[1, 2]).with_brs(false)));
        for (line, detail) in [
            ("can std 7", "insufficient options"),
            ("can std 800 01", "bad id"),
            ("can ext 20000000 01", "bad id"),
            ("can std xyz 01", "bad id"),
            ("can std 7 012", "invalid data"),
            ("can std 7 0G", "invalid data"),
            ("can std 7 01 Q", "unknown flag"),
            ("can fly", "unknown subcommand"),
            ("conf get", "usage: conf get KEY"),
            ("conf set can.bitrate", "usage: conf set KEY VALUE"),
            ("hello", "unknown command"),
        ] {
            assert_eq!(
                parse_command(line),
                Err(CommandError(detail.into())),
                "{line}"
            );
        }
        let Command::Send(req) = parse_command("can std 7 010203040506070809 F").unwrap() else {
            panic!("not a send");
        };
        assert!(
            req.frame(true, true)
                .unwrap_err()
                .contains("invalid length")
        );
        let Command::Send(req) = parse_command("can std 7 01 R").unwrap() else {
            panic!("not a send");
        };
        assert!(req.frame(true, true).unwrap_err().contains("remote"));
    }

    #[test]
    fn received_frames_round_trip_with_flags_timestamp_and_filter() {
        let f = fd(0x501, &[0x11; 16]);
        let line = encode_rcv(&f, Some(1_234_567), Some(-1));
        assert_eq!(
            line,
            "rcv 501 11111111111111111111111111111111 e B F r t1234567 f-1\r\n"
        );
        assert_eq!(
            parse_device_line(line.trim_end()),
            Ok(DeviceLine::Rcv(RcvLine {
                frame: f,
                timestamp_us: Some(1_234_567),
                filter: Some(-1),
            }))
        );
        // The firmware's own form: the identifier in whole bytes, no timestamp, the filter
        // index in hexadecimal; an empty payload.
        assert_eq!(
            parse_device_line("rcv 0501 0102 e B F r f0A"),
            Ok(DeviceLine::Rcv(RcvLine {
                frame: fd(0x501, &[1, 2]),
                timestamp_us: None,
                filter: Some(10),
            }))
        );
        assert_eq!(
            encode_rcv(&fd(0x501, &[1, 2]), None, Some(10)),
            "rcv 501 0102 e B F r f0A\r\n"
        );
        assert_eq!(
            parse_device_line("rcv 1FFFFFFF  E b F r f3"),
            Ok(DeviceLine::Rcv(RcvLine {
                frame: CanFrame::new_fd(CanFrame::extended_id(0x1FFF_FFFF).unwrap(), &[])
                    .unwrap()
                    .with_brs(false),
                timestamp_us: None,
                filter: Some(3),
            }))
        );
        // A classic frame; flags left out mean base identifier, classic format.
        assert_eq!(
            parse_device_line("rcv 7 0102"),
            Ok(DeviceLine::Rcv(RcvLine {
                frame: CanFrame::new_classic(CanFrame::standard_id(7).unwrap(), &[1, 2]).unwrap(),
                timestamp_us: None,
                filter: None,
            }))
        );
        assert_eq!(
            parse_device_line("rcv 7 01 e b f R"),
            Ok(DeviceLine::RcvRemote)
        );
        assert_eq!(
            parse_device_line("rcv 7 01 e B F r t4294967295"),
            Ok(DeviceLine::Rcv(RcvLine {
                frame: fd(7, &[1]),
                timestamp_us: Some(u32::MAX),
                filter: None,
            }))
        );
    }

    #[test]
    fn malformed_received_frames_are_refused_with_the_reason() {
        for (line, reason) in [
            ("rcv", "identifier"),
            ("rcv 800 01 e B F", "base identifier above 0x7FF"),
            ("rcv 20000000 01 E B F", "extended identifier above"),
            ("rcv 123456789 01", "identifier"),
            ("rcv 7 010", "data"),
            ("rcv 7 0Z", "data"),
            ("rcv 7 010203040506070809 e B F", "no DLC"),
            ("rcv 7 000000000000000000 e b f", "classic data above 8"),
            ("rcv 7 01 e B F t4294967296", "timestamp"),
            ("rcv 7 01 e B F t-1", "timestamp"),
            ("rcv 7 01 e B F f100", "filter"),
            ("rcv 7 01 e B F f-2", "filter"),
            ("rcv 7 01 X", "unknown flag"),
        ] {
            let e = parse_device_line(line).unwrap_err();
            assert!(e.reason.contains(reason), "{line}: {e}");
        }
        let long = format!("rcv 7 {}", "Z".repeat(200));
        let e = parse_device_line(&long).unwrap_err();
        assert_eq!(e.line.chars().count(), QUOTED);
    }

    #[test]
    fn final_lines_and_reply_lines() {
        assert_eq!(parse_device_line("OK"), Ok(DeviceLine::Ok));
        assert_eq!(
            parse_device_line("ERR not in BusOn"),
            Ok(DeviceLine::Err("not in BusOn".into()))
        );
        assert_eq!(parse_device_line("ERR"), Ok(DeviceLine::Err(String::new())));
        assert_eq!(
            parse_device_line("1000000"),
            Ok(DeviceLine::Text("1000000".into()))
        );
        assert_eq!(OK_LINE, "OK\r\n");
        assert_eq!(encode_err("bad id"), "ERR bad id\r\n");
    }

    #[test]
    fn status_lines_round_trip_and_unknown_fields_are_skipped() {
        let s = Status {
            lec: 3,
            dlec: 7,
            error_passive: true,
            warning: true,
            bus_off: false,
            protocol_exception: false,
            tdc: 12,
            rx_overruns: Some(4),
        };
        let line = encode_status(&s);
        assert_eq!(
            line,
            "lec=3 dlec=7 err=1 warn=1 busoff=0 pexc=0 tdc=12 rxovf=4\r\n"
        );
        assert_eq!(parse_status(line.trim_end()), Ok(s));
        let firmware =
            parse_status("lec=0 dlec=7 err=0 warn=0 busoff=1 pexc=0 tdc=0 new=5").unwrap();
        assert!(firmware.bus_off && !firmware.error_passive);
        assert_eq!(firmware.rx_overruns, None);
        for bad in [
            "",
            "mode:BUSON",
            "busoff=1",
            "err=0 busoff=x",
            "err busoff=1",
        ] {
            assert!(parse_status(bad).is_err(), "{bad}");
        }
    }

    fn split(splitter: &mut LineSplitter, bytes: &[u8]) -> Vec<Result<String, usize>> {
        let mut out = Vec::new();
        splitter.feed(bytes, |line| {
            out.push(match line {
                Line::Text(t) => Ok(t.to_owned()),
                Line::Garbage { len } => Err(len),
            });
        });
        out
    }

    #[test]
    fn lines_are_cut_at_either_end_and_garbage_is_skipped_to_the_next_end() {
        let mut s = LineSplitter::new();
        assert_eq!(
            split(&mut s, b"OK\r\nERR x\n\r\nrcv 7"),
            vec![Ok("OK".into()), Ok("ERR x".into())]
        );
        assert!(s.is_mid_line());
        assert_eq!(split(&mut s, b" 01\r"), vec![Ok("rcv 7 01".into())]);
        assert!(!s.is_mid_line());
        // A byte that is not printable ASCII spoils its line only.
        assert_eq!(
            split(&mut s, b"O\x07K\r\nOK\n"),
            vec![Err(3), Ok("OK".into())]
        );
        // An overlong line is skipped whole, however long, in bounded memory.
        let long = vec![b'A'; MAX_LINE * 100];
        assert_eq!(split(&mut s, &long), vec![]);
        assert!(s.buf.capacity() <= MAX_LINE * 2);
        assert_eq!(
            split(&mut s, b"B\nOK\n"),
            vec![Err(MAX_LINE * 100 + 1), Ok("OK".into())]
        );
        // A line of exactly MAX_LINE bytes is still a line.
        let exact = vec![b'A'; MAX_LINE];
        let mut with_end = exact.clone();
        with_end.push(b'\n');
        assert_eq!(
            split(&mut s, &with_end),
            vec![Ok(String::from_utf8(exact).unwrap())]
        );
        s.feed(b"partial", |_| {});
        s.clear();
        assert_eq!(split(&mut s, b"OK\n"), vec![Ok("OK".into())]);
    }
}
