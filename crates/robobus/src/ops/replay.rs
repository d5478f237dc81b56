//! Replay: read a capture file and say what every frame or packet in it means.
//!
//! Two capture formats are read (see [`robobus_link::capture`] for both):
//!
//! - a **candump log** (`(1795360410.847412) can0 001##5020A01`): WHJ CAN FD frames. Each
//!   frame is a request or a reply by its CAN ID; it is decoded with the joint, the command,
//!   registers by name with value and unit (from the register table), servo targets and
//!   feedback in degrees, RPM and mA, error bits by name, broadcast frames slot by slot;
//! - a **hex log** (`0.001234 > FF 03 7F 7C`): wCK bytes. Written bytes are decoded into
//!   commands as a module would decode them; the bytes read after a command are its
//!   2-byte reply, decoded against that command. A log written on the host side (`>` host
//!   wrote) and one written by a simulator (`>` the simulated modules wrote) are both read:
//!   [`Side`] says which, or it is detected (the capture helper writes a comment naming
//!   the side; otherwise the side that first writes a `0xFF` header is the host).
//!
//! Nothing is dropped silently: a line that does not parse, a frame or packet that is
//! malformed (bad checksum, unknown command, truncated), bytes outside any packet and
//! reply bytes no command asked for each become an [`Entry`] of kind
//! [`EntryKind::Malformed`] or [`EntryKind::Unexpected`] with the reason; a command whose
//! reply never came is an [`EntryKind::Missing`] entry.
//!
//! The file is streamed: [`Replay`] reads one line at a time (at most [`MAX_LINE`] bytes)
//! and holds only the entries of that line, so a capture of any size replays in bounded
//! memory.
//!
//! ```
//! use robobus::ops::replay::{EntryKind, Replay, ReplayOptions};
//! let log = "0.000100 > FF 03 7F 7C\n0.000900 < 12 7F\n";
//! let entries: Vec<_> = Replay::from_reader(log.as_bytes(), "capture.log", &ReplayOptions::default())
//!     .unwrap()
//!     .collect::<Result<_, _>>()
//!     .unwrap();
//! assert_eq!(entries[0].text, "position move servo 3 to 127 (torque 0)");
//! assert_eq!(entries[1].kind, EntryKind::Reply);
//! assert_eq!(entries[1].text, "load 18, position 127");
//! ```

use std::collections::VecDeque;
use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufRead, BufReader, Read as _};
use std::path::{Path, PathBuf};
use std::time::Duration;

use robobus_link::capture::{Dir, HexRecord, parse_candump_line, parse_hex_line};
use robobus_wck::{Command, DecodeError, Reply as WckReply, StreamDecoder, Target};
use robobus_whj::broadcast::SLOTS;
use robobus_whj::registers::{Half, Unit, join_i32, split_i32};
use robobus_whj::reply::{BroadcastRegisterReply, Reply as WhjReply};
use robobus_whj::request::{ReadRange, Request, WriteData};
use robobus_whj::units::CurrentScale;
use robobus_whj::{Address, CanFrame, ErrorCode, JointId, RegisterAddr, RegisterSlot};
use robobus_whj::{RegisterOp, ReplyMask};
use serde::Serialize;

use super::{ErrorKind, OpError, human_bytes};

/// The longest line a capture may have: 64 KiB (a candump CAN FD line is under 200
/// bytes; a hex log line holds what one read or write call moved).
pub const MAX_LINE: usize = 64 << 10;

/// How many hex log records are looked at to detect the side before giving up and
/// taking the host side.
const SIDE_LOOKAHEAD: usize = 256;

/// The comment [`super::capture::capture_byte_link`] writes first, naming the side.
pub const HOST_SIDE_COMMENT: &str = "# robobus hex capture: host side (> host wrote, < host read)";

/// The comment a simulator's capture writes first ([`super::capture::capture_device_byte_link`]).
pub const DEVICE_SIDE_COMMENT: &str =
    "# robobus hex capture: device side (< device read, > device wrote)";

/// The capture format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Format {
    /// candump `-L` log of CAN FD frames (WHJ).
    Candump,
    /// Timestamped hex log of a byte link (wCK).
    Hex,
}

/// Which side wrote a hex log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Side {
    /// Detect it (the default).
    #[default]
    Auto,
    /// The host's log: `>` commands the host wrote, `<` replies it read.
    Host,
    /// A simulator's (device's) log: `<` commands it read, `>` replies it wrote.
    Device,
}

/// How to read a capture.
#[derive(Debug, Clone, Copy, Default)]
pub struct ReplayOptions {
    /// The format; `None` detects it from the first line.
    pub format: Option<Format>,
    /// Which side wrote a hex log.
    pub side: Side,
    /// mA per current count of the WHJ joints (1 mA unless the joints are Joint 60/120).
    pub current_scale: CurrentScale,
}

/// Which way an entry travelled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Direction {
    /// From the host to the devices (a request, a command).
    ToDevice,
    /// From a device to the host (a reply, feedback).
    FromDevice,
    /// Not known (a line that does not parse, a CAN ID that is not WHJ's).
    Unknown,
}

impl Direction {
    /// `>` to the devices, `<` from them, `?` unknown.
    pub const fn arrow(self) -> &'static str {
        match self {
            Self::ToDevice => ">",
            Self::FromDevice => "<",
            Self::Unknown => "?",
        }
    }
}

/// What an entry is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum EntryKind {
    /// A request or command from the host.
    Request,
    /// A reply or feedback from a device.
    Reply,
    /// A frame of a known kind that is not matched to a request: interface-board frames and
    /// firmware data (not decoded), end-board replies (decoded by register name).
    Other,
    /// A command's reply that never came (the next command, or the end of the capture,
    /// came first).
    Missing,
    /// Bytes from a device that no command asked for.
    Unexpected,
    /// A line, frame or packet that is malformed; `malformed` says why.
    Malformed,
}

/// One decoded value: a register, a target, a feedback quantity.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Field {
    /// Its name: the register's name (`CUR_POSITION`), or the quantity's (`position`,
    /// `J3 position` in a broadcast frame).
    pub name: String,
    /// The raw value on the wire.
    pub raw: i64,
    /// The value in `unit` (the raw value where there is no unit).
    pub value: f64,
    /// The unit symbol (`°`, `RPM`, `mA`, `V`, `°C`), empty for unitless values.
    pub unit: &'static str,
    #[serde(skip)]
    decimals: usize,
}

impl Field {
    fn new(
        name: impl Into<String>,
        raw: i64,
        value: f64,
        unit: &'static str,
        decimals: usize,
    ) -> Self {
        Self {
            name: name.into(),
            raw,
            value,
            unit,
            decimals,
        }
    }

    fn raw(name: impl Into<String>, raw: impl Into<i64>) -> Self {
        let raw = raw.into();
        #[allow(clippy::cast_precision_loss)] // raw values are at most 32 bits
        Self::new(name, raw, raw as f64, "", 0)
    }
}

impl std::fmt::Display for Field {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} {:.*}", self.name, self.decimals, self.value)?;
        if !self.unit.is_empty() {
            write!(f, " {}", self.unit)?;
        }
        Ok(())
    }
}

/// One frame, packet, reply or malformed line of a capture.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Entry {
    /// 1-based line of the capture where it starts.
    pub line: u64,
    /// Its time as the capture wrote it (candump: seconds since the Unix epoch; hex log:
    /// seconds since the capture began); `None` when the line does not parse.
    pub time: Option<String>,
    /// Which way it travelled.
    pub direction: Direction,
    /// What it is.
    pub kind: EntryKind,
    /// The candump interface name.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub iface: Option<String>,
    /// The CAN ID (WHJ).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub can_id: Option<u32>,
    /// The bytes (a frame's data, a packet, a reply), as hex pairs separated by spaces.
    pub bytes: String,
    /// The joint or servo addressed or answering, if one.
    pub device: Option<u8>,
    /// The command (`read`, `write`, `servo feedback`, `position move`, ...).
    pub command: Option<String>,
    /// The decoded values.
    pub fields: Vec<Field>,
    /// The names of the error bits set (WHJ error code).
    pub errors: Vec<&'static str>,
    /// Why the entry is malformed or unexpected.
    pub malformed: Option<String>,
    /// Its meaning in one line of text.
    pub text: String,
}

impl Entry {
    fn new(line: u64, time: Option<String>, direction: Direction, kind: EntryKind) -> Self {
        Self {
            line,
            time,
            direction,
            kind,
            iface: None,
            can_id: None,
            bytes: String::new(),
            device: None,
            command: None,
            fields: Vec::new(),
            errors: Vec::new(),
            malformed: None,
            text: String::new(),
        }
    }

    fn malformed(mut self, reason: impl Into<String>) -> Self {
        let reason = reason.into();
        self.kind = EntryKind::Malformed;
        self.text = format!("MALFORMED: {reason}");
        self.malformed = Some(reason);
        self
    }

    fn with_bytes(mut self, bytes: &[u8]) -> Self {
        self.bytes = hex(bytes);
        self
    }
}

/// Counts over a whole replay.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct Summary {
    /// Entries in all.
    pub entries: u64,
    /// Requests and commands.
    pub requests: u64,
    /// Replies and feedback.
    pub replies: u64,
    /// Missing replies.
    pub missing: u64,
    /// Unexpected bytes.
    pub unexpected: u64,
    /// Malformed entries.
    pub malformed: u64,
}

impl Summary {
    /// Counts one entry.
    pub const fn add(&mut self, entry: &Entry) {
        self.entries += 1;
        match entry.kind {
            EntryKind::Request => self.requests += 1,
            EntryKind::Reply => self.replies += 1,
            EntryKind::Missing => self.missing += 1,
            EntryKind::Unexpected => self.unexpected += 1,
            EntryKind::Malformed => self.malformed += 1,
            EntryKind::Other => {}
        }
    }
}

fn hex(bytes: &[u8]) -> String {
    let mut s = String::with_capacity(bytes.len() * 3);
    for (i, b) in bytes.iter().enumerate() {
        if i > 0 {
            s.push(' ');
        }
        let _ = write!(s, "{b:02X}");
    }
    s
}

fn fmt_time(t: Duration) -> String {
    format!("{}.{:06}", t.as_secs(), t.subsec_micros())
}

/// Reads lines of at most [`MAX_LINE`] bytes.
struct Lines<R> {
    reader: R,
    path: PathBuf,
    line: u64,
    buf: Vec<u8>,
}

impl<R: BufRead> Lines<R> {
    #[allow(clippy::result_large_err)] // OpError, as every operation returns
    fn next_line(&mut self) -> Result<Option<(u64, String)>, OpError> {
        self.buf.clear();
        let limit = u64::try_from(MAX_LINE)
            .unwrap_or(u64::MAX)
            .saturating_add(1);
        let n = (&mut self.reader)
            .take(limit)
            .read_until(b'\n', &mut self.buf)
            .map_err(|e| {
                self.error(self.line + 1, &format!("cannot read: {e}"), ErrorKind::Link)
            })?;
        if n == 0 {
            return Ok(None);
        }
        self.line += 1;
        if self.buf.last() == Some(&b'\n') {
            self.buf.pop();
        } else if self.buf.len() > MAX_LINE {
            return Err(self.error(
                self.line,
                &format!("longer than the limit of {}", human_bytes(limit - 1)),
                ErrorKind::BadInput,
            ));
        }
        if self.buf.last() == Some(&b'\r') {
            self.buf.pop();
        }
        // A UTF-8 byte-order mark (editors on Windows write one) is not part of the text.
        if self.line == 1 && self.buf.starts_with(b"\xEF\xBB\xBF") {
            self.buf.drain(..3);
        }
        let text = std::str::from_utf8(&self.buf).map_err(|e| {
            self.error(
                self.line,
                &format!("not UTF-8 text (byte {})", e.valid_up_to()),
                ErrorKind::BadInput,
            )
        })?;
        Ok(Some((self.line, text.to_owned())))
    }

    fn error(&self, line: u64, reason: &str, kind: ErrorKind) -> OpError {
        OpError::File {
            path: self.path.clone(),
            reason: format!("line {line}: {reason}"),
            kind,
        }
    }
}

/// A capture being replayed: an iterator of its entries, in the order of the capture.
///
/// An item is an error only when the file itself cannot be read on (an I/O error, a line
/// longer than [`MAX_LINE`], text that is not UTF-8); the error names the file and the
/// line, and the iteration ends.
pub struct Replay<R> {
    lines: Lines<R>,
    format: Format,
    side: Side,
    options: ReplayOptions,
    out: VecDeque<Entry>,
    /// The first meaningful line, read to detect the format.
    first: Option<(u64, String)>,
    /// Hex records read ahead while the side is unknown.
    ahead: VecDeque<(u64, Result<HexRecord, String>)>,
    done: bool,
    failed: bool,
    whj: WhjState,
    wck: WckState,
    summary: Summary,
}

impl<R> std::fmt::Debug for Replay<R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Replay")
            .field("path", &self.lines.path)
            .field("format", &self.format)
            .field("side", &self.side)
            .field("line", &self.lines.line)
            .finish_non_exhaustive()
    }
}

/// Opens a capture file for replay.
#[allow(clippy::result_large_err)] // OpError, as every operation returns
pub fn open(path: &Path, options: &ReplayOptions) -> Result<Replay<BufReader<File>>, OpError> {
    let file = File::open(path).map_err(|e| OpError::File {
        path: path.to_path_buf(),
        reason: format!("cannot open: {e}"),
        kind: super::io_kind(&e),
    })?;
    if file.metadata().is_ok_and(|m| m.is_dir()) {
        return Err(OpError::File {
            path: path.to_path_buf(),
            reason: "is a directory, not a capture file".into(),
            kind: ErrorKind::BadInput,
        });
    }
    Replay::from_reader(BufReader::new(file), path, options)
}

impl<R: BufRead> Replay<R> {
    /// Replays a capture from `reader`; `path` names it in errors. Reads up to the first
    /// line that is not blank or a comment to detect the format (unless given).
    #[allow(clippy::result_large_err)] // OpError, as every operation returns
    pub fn from_reader(
        reader: R,
        path: impl AsRef<Path>,
        options: &ReplayOptions,
    ) -> Result<Self, OpError> {
        let mut lines = Lines {
            reader,
            path: path.as_ref().to_path_buf(),
            line: 0,
            buf: Vec::new(),
        };
        let mut side = options.side;
        let mut first = None;
        while let Some((n, text)) = lines.next_line()? {
            let t = text.trim();
            if t.is_empty() {
                continue;
            }
            if t.starts_with('#') {
                side = side_comment(t, side);
                continue;
            }
            first = Some((n, text));
            break;
        }
        let format = match (options.format, &first) {
            (Some(f), _) => f,
            (None, None) => {
                return Err(OpError::File {
                    path: lines.path,
                    reason: "empty capture: no frame or packet in it".into(),
                    kind: ErrorKind::BadInput,
                });
            }
            (None, Some((n, text))) => detect(text).ok_or_else(|| OpError::File {
                path: lines.path.clone(),
                reason: format!(
                    "line {n}: neither a candump log line (`(seconds) iface ID##data`) nor a hex log line (`seconds > FF 03 7F 7C`)"
                ),
                kind: ErrorKind::BadInput,
            })?,
        };
        Ok(Self {
            lines,
            format,
            side,
            options: *options,
            out: VecDeque::new(),
            first,
            ahead: VecDeque::new(),
            done: false,
            failed: false,
            whj: WhjState::default(),
            wck: WckState::default(),
            summary: Summary::default(),
        })
    }

    /// The capture's format.
    pub const fn format(&self) -> Format {
        self.format
    }

    /// The side of a hex log (detected once the first header was seen; `Auto` before).
    pub const fn side(&self) -> Side {
        self.side
    }

    /// The counts of the entries returned so far.
    pub const fn summary(&self) -> Summary {
        self.summary
    }

    #[allow(clippy::result_large_err)]
    fn next_line(&mut self) -> Result<Option<(u64, String)>, OpError> {
        if let Some(l) = self.first.take() {
            return Ok(Some(l));
        }
        self.lines.next_line()
    }

    /// Reads on until at least one entry is queued or the capture ends.
    #[allow(clippy::result_large_err)]
    fn fill(&mut self) -> Result<(), OpError> {
        while self.out.is_empty() && !self.done {
            match self.format {
                Format::Candump => {
                    if let Some((n, text)) = self.next_line()? {
                        self.candump_line(n, &text);
                    } else {
                        self.out.extend(self.whj.finish());
                        self.done = true;
                    }
                }
                Format::Hex => self.hex_step()?,
            }
        }
        Ok(())
    }

    fn candump_line(&mut self, n: u64, text: &str) {
        if text.trim().is_empty() {
            return;
        }
        let entry = match parse_candump_line(text) {
            Ok(rec) => {
                let mut e = self.whj.decode(&rec.frame, self.options.current_scale);
                e.line = n;
                e.time = Some(fmt_time(rec.timestamp));
                e.iface = Some(rec.iface);
                if let Some(missing) = self.whj.pair(&rec.frame, &mut e) {
                    self.out.push_back(missing);
                }
                e
            }
            Err(kind) => Entry::new(n, None, Direction::Unknown, EntryKind::Malformed)
                .malformed(format!("{kind}: {:?}", clip(text))),
        };
        self.out.push_back(entry);
    }

    #[allow(clippy::result_large_err)]
    fn hex_step(&mut self) -> Result<(), OpError> {
        if self.side == Side::Auto {
            // Read ahead until a header shows which side writes the commands.
            while self.side == Side::Auto {
                let Some((n, text)) = self.next_line()? else {
                    self.side = Side::Host;
                    break;
                };
                let t = text.trim();
                if t.starts_with('#') {
                    self.side = side_comment(t, Side::Auto);
                    continue;
                }
                match parse_hex_line(&text) {
                    Ok(None) => {}
                    Ok(Some(rec)) => {
                        if rec.bytes.contains(&0xFF) {
                            self.side = match rec.dir {
                                Dir::Written => Side::Host,
                                Dir::Read => Side::Device,
                            };
                        }
                        self.ahead.push_back((n, Ok(rec)));
                    }
                    Err(e) => self
                        .ahead
                        .push_back((n, Err(format!("{e}: {:?}", clip(&text))))),
                }
                if self.ahead.len() >= SIDE_LOOKAHEAD && self.side == Side::Auto {
                    self.side = Side::Host;
                }
            }
        }
        let item = if let Some(item) = self.ahead.pop_front() {
            Some(item)
        } else {
            loop {
                match self.next_line()? {
                    None => break None,
                    Some((n, text)) => match parse_hex_line(&text) {
                        Ok(None) => {}
                        Ok(Some(rec)) => break Some((n, Ok(rec))),
                        Err(e) => break Some((n, Err(format!("{e}: {:?}", clip(&text))))),
                    },
                }
            }
        };
        match item {
            None => {
                self.wck.finish(&mut self.out);
                self.done = true;
            }
            Some((n, Ok(rec))) => {
                let to_device = matches!(
                    (self.side, rec.dir),
                    (Side::Host | Side::Auto, Dir::Written) | (Side::Device, Dir::Read)
                );
                let time = fmt_time(rec.at);
                if to_device {
                    self.wck.written(n, &time, &rec.bytes, &mut self.out);
                } else {
                    self.wck.read(n, &time, &rec.bytes, &mut self.out);
                }
            }
            Some((n, Err(reason))) => {
                self.out.push_back(
                    Entry::new(n, None, Direction::Unknown, EntryKind::Malformed).malformed(reason),
                );
            }
        }
        Ok(())
    }
}

impl<R: BufRead> Iterator for Replay<R> {
    type Item = Result<Entry, OpError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        if let Err(e) = self.fill() {
            self.failed = true;
            return Some(Err(e));
        }
        let entry = self.out.pop_front()?;
        self.summary.add(&entry);
        Some(Ok(entry))
    }
}

fn clip(text: &str) -> String {
    const MAX: usize = 120;
    if text.len() <= MAX {
        return text.to_owned();
    }
    let mut end = MAX;
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    format!("{}...", text.get(..end).unwrap_or_default())
}

fn side_comment(comment: &str, side: Side) -> Side {
    if side != Side::Auto {
        return side;
    }
    if comment.contains("host side") {
        Side::Host
    } else if comment.contains("device side") || comment.contains("simulator side") {
        Side::Device
    } else {
        Side::Auto
    }
}

fn detect(line: &str) -> Option<Format> {
    if parse_candump_line(line).is_ok() || line.trim_start().starts_with('(') {
        Some(Format::Candump)
    } else if parse_hex_line(line).is_ok() {
        Some(Format::Hex)
    } else {
        None
    }
}

// ---------------------------------------------------------------------------------------
// WHJ frames
// ---------------------------------------------------------------------------------------

/// What the WHJ decoder remembers: the register count each joint last asked for (a read
/// reply is padded to a CAN FD length; the request says how many words are real).
#[derive(Debug, Default)]
struct WhjState {
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
    fn pair(&mut self, frame: &CanFrame, e: &mut Entry) -> Option<Entry> {
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
                self.wait(joint, e, expect, crate::whj::joint::describe(&req))
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
    fn finish(&mut self) -> Vec<Entry> {
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
    fn decode(&mut self, frame: &CanFrame, scale: CurrentScale) -> Entry {
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
                                    f64::from(raw * 2),
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

// ---------------------------------------------------------------------------------------
// wCK packets
// ---------------------------------------------------------------------------------------

/// Bytes kept at most in one noise or unexpected entry before it is emitted.
const MAX_RUN: usize = 256;

/// A command waiting for its reply.
#[derive(Debug)]
struct Waiting {
    command: Command,
    line: u64,
    time: String,
    /// Reply bytes so far, and the line and time of the first.
    bytes: Vec<u8>,
    first: Option<(u64, String)>,
}

/// A run of bytes being collected (noise, unexpected reply bytes).
#[derive(Debug, Default)]
struct Run {
    bytes: Vec<u8>,
    start: Option<(u64, String)>,
}

impl Run {
    fn push(&mut self, line: u64, time: &str, byte: u8) {
        if self.start.is_none() {
            self.start = Some((line, time.to_owned()));
        }
        self.bytes.push(byte);
    }

    fn take(&mut self) -> Option<(u64, String, Vec<u8>)> {
        let (line, time) = self.start.take()?;
        Some((line, time, std::mem::take(&mut self.bytes)))
    }
}

#[derive(Debug, Default)]
struct WckState {
    decoder: StreamDecoder,
    /// Bytes of the packet in progress.
    packet: Vec<u8>,
    packet_start: Option<(u64, String)>,
    noise: Run,
    unexpected: Run,
    waiting: Option<Waiting>,
}

fn servo_of(command: &Command) -> Option<u8> {
    match command.target() {
        Target::Servo(id) => Some(id.get()),
        Target::Extended(id) => Some(id.get()),
        Target::Broadcast => None,
    }
}

fn wck_reply_fields(reply: WckReply, fields: &mut Vec<Field>) {
    match reply {
        WckReply::Status { load, position } => {
            fields.push(Field::raw("load", load.get()));
            fields.push(Field::raw("position", position.get()));
        }
        WckReply::Passive { position } => fields.push(Field::raw("position", position.get())),
        WckReply::Wheel {
            rotations,
            position,
        } => {
            fields.push(Field::raw("rotations", rotations));
            fields.push(Field::raw("position", position.get()));
        }
        WckReply::Break { id, position } => {
            fields.push(Field::raw("id", id.get()));
            fields.push(Field::raw("position", position.get()));
        }
        WckReply::Position10(p) => fields.push(Field::raw("position", p.get())),
        _ => {}
    }
}

impl WckState {
    fn flush_noise(&mut self, out: &mut VecDeque<Entry>) {
        if let Some((line, time, bytes)) = self.noise.take() {
            let n = bytes.len();
            out.push_back(
                Entry::new(line, Some(time), Direction::ToDevice, EntryKind::Malformed)
                    .with_bytes(&bytes)
                    .malformed(format!(
                        "{n} byte{} outside a packet (no 0xFF header before)",
                        if n == 1 { "" } else { "s" }
                    )),
            );
        }
    }

    fn flush_unexpected(&mut self, out: &mut VecDeque<Entry>) {
        if let Some((line, time, bytes)) = self.unexpected.take() {
            let mut e = Entry::new(
                line,
                Some(time),
                Direction::FromDevice,
                EntryKind::Unexpected,
            )
            .with_bytes(&bytes);
            let reason = "no command was waiting for a reply";
            e.text = format!("UNEXPECTED: {reason}");
            e.malformed = Some(reason.into());
            out.push_back(e);
        }
    }

    /// Ends the wait for a reply: missing, or truncated if some bytes came.
    fn end_wait(&mut self, why: &str, out: &mut VecDeque<Entry>) {
        let Some(w) = self.waiting.take() else {
            return;
        };
        let name = w.command.name();
        let device = servo_of(&w.command);
        if let Some((line, time)) = w.first {
            let mut e = Entry::new(
                line,
                Some(time),
                Direction::FromDevice,
                EntryKind::Malformed,
            )
            .with_bytes(&w.bytes)
            .malformed(format!(
                "truncated reply to {name}: {} of 2 bytes before {why}",
                w.bytes.len()
            ));
            e.device = device;
            e.command = Some(name.into());
            out.push_back(e);
        } else {
            let mut e = Entry::new(
                w.line,
                Some(w.time),
                Direction::FromDevice,
                EntryKind::Missing,
            );
            e.device = device;
            e.command = Some(name.into());
            e.text = format!("NO REPLY to {name} (none before {why})");
            out.push_back(e);
        }
    }

    fn written(&mut self, line: u64, time: &str, bytes: &[u8], out: &mut VecDeque<Entry>) {
        self.flush_unexpected(out);
        for &b in bytes {
            if self.decoder.is_idle() && b != robobus_wck::HEADER {
                self.noise.push(line, time, b);
                if self.noise.bytes.len() >= MAX_RUN {
                    self.flush_noise(out);
                }
                continue;
            }
            if b == robobus_wck::HEADER {
                self.flush_noise(out);
                // Half duplex: a new packet means the reply to the last one is over.
                if self.waiting.is_some() {
                    self.end_wait(&format!("the next packet (line {line})"), out);
                }
            }
            if self.decoder.is_idle() {
                self.packet.clear();
                self.packet_start = Some((line, time.to_owned()));
            }
            self.packet.push(b);
            let Some(event) = self.decoder.push(b) else {
                continue;
            };
            let (start_line, start_time) = self
                .packet_start
                .take()
                .unwrap_or_else(|| (line, time.to_owned()));
            let raw = if matches!(event, Err(DecodeError::Truncated { .. })) {
                self.packet.pop();
                let raw = std::mem::take(&mut self.packet);
                self.packet.push(b);
                self.packet_start = Some((line, time.to_owned()));
                raw
            } else {
                std::mem::take(&mut self.packet)
            };
            let e = Entry::new(
                start_line,
                Some(start_time.clone()),
                Direction::ToDevice,
                EntryKind::Request,
            )
            .with_bytes(&raw);
            match event {
                Ok(command) => {
                    let mut e = e;
                    e.device = servo_of(&command);
                    e.command = Some(command.name().into());
                    if let Command::Move {
                        torque, position, ..
                    } = command
                    {
                        e.fields.push(Field::raw("position", position.get()));
                        e.fields.push(Field::raw("torque", torque.get()));
                    }
                    e.text = command.to_string();
                    out.push_back(e);
                    if command.reply_len() > 0 {
                        self.waiting = Some(Waiting {
                            command,
                            line: start_line,
                            time: start_time,
                            bytes: Vec::new(),
                            first: None,
                        });
                    }
                }
                Err(err) => out.push_back(e.malformed(err.to_string())),
            }
        }
        // Noise is emitted per line; a packet in progress may go on in the next line.
        self.flush_noise(out);
    }

    fn read(&mut self, line: u64, time: &str, bytes: &[u8], out: &mut VecDeque<Entry>) {
        for &b in bytes {
            let Some(w) = self.waiting.as_mut() else {
                self.unexpected.push(line, time, b);
                if self.unexpected.bytes.len() >= MAX_RUN {
                    self.flush_unexpected(out);
                }
                continue;
            };
            if w.first.is_none() {
                w.first = Some((line, time.to_owned()));
            }
            w.bytes.push(b);
            if w.bytes.len() < robobus_wck::REPLY_LEN {
                continue;
            }
            let Some(w) = self.waiting.take() else {
                continue;
            };
            let (first_line, first_time) = w.first.unwrap_or_else(|| (line, time.to_owned()));
            let mut e = Entry::new(
                first_line,
                Some(first_time),
                Direction::FromDevice,
                EntryKind::Reply,
            )
            .with_bytes(&w.bytes);
            e.device = servo_of(&w.command);
            e.command = Some(w.command.name().into());
            match w.command.decode_reply(&w.bytes) {
                Ok(reply) => {
                    wck_reply_fields(reply, &mut e.fields);
                    e.text = reply.to_string();
                    out.push_back(e);
                }
                Err(err) => out.push_back(e.malformed(err.to_string())),
            }
        }
        self.flush_unexpected(out);
    }

    fn finish(&mut self, out: &mut VecDeque<Entry>) {
        self.flush_noise(out);
        if !self.decoder.is_idle() && !self.packet.is_empty() {
            let (line, time) = self.packet_start.take().unwrap_or_default();
            let n = self.packet.len();
            out.push_back(
                Entry::new(line, Some(time), Direction::ToDevice, EntryKind::Malformed)
                    .with_bytes(&self.packet)
                    .malformed(format!(
                        "truncated packet: the capture ends after {n} bytes"
                    )),
            );
            self.packet.clear();
            self.decoder.reset();
        }
        self.end_wait("the end of the capture", out);
        self.flush_unexpected(out);
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

#[cfg(test)]
mod tests {
    use super::*;

    fn entries(text: &str, options: ReplayOptions) -> Vec<Entry> {
        Replay::from_reader(text.as_bytes(), "t.log", &options)
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap()
    }

    #[test]
    fn end_board_replies_are_decoded_by_register_name() {
        // The worked examples: tool power := 24 V answered on 0x87, IO1 := output on
        // 0xF7; a version read; a frame shorter than the header.
        let log = "(0.1) can0 087##5B80900000002070101000000\n\
                   (0.2) can0 0F7##50F81000000021D0101000000\n\
                   (0.3) can0 0F7##5010900000001030203020000\n\
                   (0.4) can0 087##50102\n";
        let got: Vec<String> = entries(log, ReplayOptions::default())
            .into_iter()
            .map(|e| e.text)
            .collect();
        assert_eq!(
            got,
            [
                "end board: write 0x07 EB_VOLTAGE_OUTPUT ok (counter 184, status0 0x09, error 0x00)",
                "end board: write 0x1d EB_IO1_MODE ok (counter 15, status0 0x81, error 0x00)",
                "end board: read 0x03 EB_SW_VERSION = 0x0203 (counter 1, status0 0x09, error 0x00)",
                "MALFORMED: end-board reply shorter than its 8-byte header",
            ]
        );
    }

    #[test]
    fn overlong_lines_and_bad_text_name_the_file_and_line() {
        let long = format!("0.0 > {}\n", "FF ".repeat(MAX_LINE / 3 + 10));
        let text = format!("0.000001 > FF 03 7F 7C\n{long}");
        let err = Replay::from_reader(text.as_bytes(), "big.log", &ReplayOptions::default())
            .unwrap()
            .find_map(Result::err)
            .unwrap();
        assert_eq!(err.kind(), ErrorKind::BadInput);
        assert_eq!(
            err.to_string(),
            "big.log: line 2: longer than the limit of 64 KiB"
        );
        let err = Replay::from_reader(&b"\xFF\xFE\n"[..], "bin.log", &ReplayOptions::default())
            .unwrap_err();
        assert_eq!(err.to_string(), "bin.log: line 1: not UTF-8 text (byte 0)");
        let err =
            Replay::from_reader(&b"hello\n"[..], "x.log", &ReplayOptions::default()).unwrap_err();
        assert!(
            err.to_string()
                .starts_with("x.log: line 1: neither a candump"),
            "{err}"
        );
        let err = Replay::from_reader(&b"\n# only\n"[..], "e.log", &ReplayOptions::default())
            .unwrap_err();
        assert_eq!(
            err.to_string(),
            "e.log: empty capture: no frame or packet in it"
        );
    }

    #[test]
    fn wck_noise_truncation_and_orphans_are_flagged() {
        let log = "0.1 < 12\n0.2 > 00 FF 03\n0.3 > FF 03 7F 7C\n0.4 < 12\n0.5 > FF 03 7F 7C\n0.6 > FF A0\n";
        let got: Vec<(u64, EntryKind, String)> = entries(
            log,
            ReplayOptions {
                side: Side::Host,
                ..ReplayOptions::default()
            },
        )
        .into_iter()
        .map(|e| (e.line, e.kind, e.text))
        .collect();
        let want: Vec<(u64, EntryKind, String)> = vec![
            (1, EntryKind::Unexpected, "UNEXPECTED: no command was waiting for a reply".into()),
            (2, EntryKind::Malformed, "MALFORMED: 1 byte outside a packet (no 0xFF header before)".into()),
            (2, EntryKind::Malformed, "MALFORMED: truncated packet: new header after 2 bytes of 4".into()),
            (3, EntryKind::Request, "position move servo 3 to 127 (torque 0)".into()),
            (4, EntryKind::Malformed, "MALFORMED: truncated reply to position move: 1 of 2 bytes before the next packet (line 5)".into()),
            (5, EntryKind::Request, "position move servo 3 to 127 (torque 0)".into()),
            (5, EntryKind::Missing, "NO REPLY to position move (none before the next packet (line 6))".into()),
            (6, EntryKind::Malformed, "MALFORMED: truncated packet: the capture ends after 2 bytes".into()),
        ];
        assert_eq!(got, want);
    }

    #[test]
    fn wck_replies_split_over_reads_and_implausible_replies() {
        // A reply read one byte at a time; a passive reply without the echoed mode byte;
        // a packet written in two calls.
        let log = "0.1 > FF 03 7F 7C\n0.2 < 12\n0.3 < 7F\n0.4 > FF C3 10 53\n0.5 < 11 7F\n0.6 > FF A3\n0.7 > 00 23\n0.8 < 00 7F\n";
        let got: Vec<(u64, EntryKind, String, String)> = entries(log, ReplayOptions::default())
            .into_iter()
            .map(|e| (e.line, e.kind, e.bytes, e.text))
            .collect();
        let want: Vec<(u64, EntryKind, String, String)> = vec![
            (
                1,
                EntryKind::Request,
                "FF 03 7F 7C".into(),
                "position move servo 3 to 127 (torque 0)".into(),
            ),
            (
                2,
                EntryKind::Reply,
                "12 7F".into(),
                "load 18, position 127".into(),
            ),
            (
                4,
                EntryKind::Request,
                "FF C3 10 53".into(),
                "passive servo 3".into(),
            ),
            (
                5,
                EntryKind::Malformed,
                "11 7F".into(),
                "MALFORMED: passive: reply mode byte is 17, but 16 was sent".into(),
            ),
            (
                6,
                EntryKind::Request,
                "FF A3 00 23".into(),
                "status read servo 3".into(),
            ),
            (
                8,
                EntryKind::Reply,
                "00 7F".into(),
                "load 0, position 127".into(),
            ),
        ];
        assert_eq!(got, want);
    }
}
