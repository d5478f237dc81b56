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
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};

use robobus_link::capture::{CaptureError, CaptureReader, Record, format_time};
/// The capture formats, sides, comments and line limit (the reader's, in
/// [`robobus_link::capture`]).
pub use robobus_link::capture::{DEVICE_SIDE_COMMENT, Format, HOST_SIDE_COMMENT, MAX_LINE, Side};
use robobus_whj::units::CurrentScale;
use serde::Serialize;

use super::{ErrorKind, OpError};

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

impl From<&robobus_whj::Field> for Field {
    /// A WHJ value, named after the joint of its broadcast slot (`J3 position`).
    fn from(f: &robobus_whj::Field) -> Self {
        Self {
            name: match f.slot {
                Some(joint) => format!("{joint} {}", f.name),
                None => f.name.to_string(),
            },
            raw: f.raw,
            value: f.value,
            unit: f.unit,
            decimals: f.decimals,
        }
    }
}

impl From<robobus_wck::Field> for Field {
    fn from(f: robobus_wck::Field) -> Self {
        Self {
            name: f.name.into(),
            raw: i64::from(f.value),
            value: f64::from(f.value),
            unit: "",
            decimals: 0,
        }
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

    /// A WHJ request or reply as the protocol core describes it: what it is, its values
    /// and error bits, its text.
    fn described(
        mut self,
        command: &str,
        fields: &robobus_whj::Fields,
        text: impl std::fmt::Display,
    ) -> Self {
        self.command = Some(command.into());
        self.fields = fields.iter().map(Field::from).collect();
        self.errors = fields.errors().collect();
        self.text = text.to_string();
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

/// A capture being replayed: an iterator of its entries, in the order of the capture.
///
/// An item is an error only when the file itself cannot be read on (an I/O error, a line
/// longer than [`MAX_LINE`], text that is not UTF-8); the error names the file and the
/// line, and the iteration ends.
pub struct Replay<R> {
    reader: CaptureReader<R>,
    path: PathBuf,
    options: ReplayOptions,
    out: VecDeque<Entry>,
    done: bool,
    failed: bool,
    whj: WhjState,
    wck: WckState,
    summary: Summary,
}

impl<R> std::fmt::Debug for Replay<R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Replay")
            .field("path", &self.path)
            .field("format", &self.reader.format())
            .field("side", &self.reader.side())
            .field("line", &self.reader.line())
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

/// A capture that cannot be read on, as the error of the file at `path`.
fn file_error(path: &Path, e: &CaptureError) -> OpError {
    OpError::File {
        path: path.to_path_buf(),
        reason: e.to_string(),
        kind: if e.is_io() {
            ErrorKind::Link
        } else {
            ErrorKind::BadInput
        },
    }
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
        let path = path.as_ref().to_path_buf();
        let reader = CaptureReader::new(reader, options.format, options.side)
            .map_err(|e| file_error(&path, &e))?;
        Ok(Self {
            reader,
            path,
            options: *options,
            out: VecDeque::new(),
            done: false,
            failed: false,
            whj: WhjState::default(),
            wck: WckState::default(),
            summary: Summary::default(),
        })
    }

    /// The capture's format.
    pub const fn format(&self) -> Format {
        self.reader.format()
    }

    /// The side of a hex log (detected once the first header was seen; `Auto` before).
    pub const fn side(&self) -> Side {
        self.reader.side()
    }

    /// The counts of the entries returned so far.
    pub const fn summary(&self) -> Summary {
        self.summary
    }

    /// Reads on until at least one entry is queued or the capture ends.
    #[allow(clippy::result_large_err)]
    fn fill(&mut self) -> Result<(), OpError> {
        while self.out.is_empty() && !self.done {
            match self.reader.next() {
                None => {
                    match self.reader.format() {
                        Format::Candump => self.out.extend(self.whj.finish()),
                        Format::Hex => self.wck.finish(&mut self.out),
                    }
                    self.done = true;
                }
                Some(Err(e)) => return Err(file_error(&self.path, &e)),
                Some(Ok(Record::Frame { line, record })) => {
                    let mut e = self.whj.decode(&record.frame, self.options.current_scale);
                    e.line = line;
                    e.time = Some(format_time(record.timestamp));
                    e.iface = Some(record.iface);
                    if let Some(missing) = self.whj.pair(&record.frame, &mut e) {
                        self.out.push_back(missing);
                    }
                    self.out.push_back(e);
                }
                Some(Ok(Record::Bytes {
                    line,
                    record,
                    to_device,
                })) => {
                    let time = format_time(record.at);
                    if to_device {
                        self.wck.written(line, &time, &record.bytes, &mut self.out);
                    } else {
                        self.wck.read(line, &time, &record.bytes, &mut self.out);
                    }
                }
                Some(Ok(Record::Malformed { line, reason })) => self.out.push_back(
                    Entry::new(line, None, Direction::Unknown, EntryKind::Malformed)
                        .malformed(reason),
                ),
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

mod wck;
mod whj;

use wck::WckState;
use whj::WhjState;

#[cfg(test)]
mod tests;
