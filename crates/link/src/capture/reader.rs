//! Reading a capture file back: lines of bounded length, the side comment of a hex log,
//! the format detected from the first line, and the records of either format in the
//! order of the file, each with its line number.

use std::collections::VecDeque;
use std::io::{self, BufRead, Read as _};

use super::{CandumpRecord, Dir, HexRecord, parse_candump_line, parse_hex_line};

/// The longest line a capture may have: 64 KiB (a candump CAN FD line is under 200
/// bytes; a hex log line holds what one read or write call moved). A whole number of KiB.
pub const MAX_LINE: usize = 64 << 10;

/// How many hex log records are looked at to detect the side before giving up and
/// taking the host side.
const SIDE_LOOKAHEAD: usize = 256;

/// The comment a host's hex capture starts with ([`Side::Host`]).
pub const HOST_SIDE_COMMENT: &str = "# robobus hex capture: host side (> host wrote, < host read)";

/// The comment a simulator's (device's) hex capture starts with ([`Side::Device`]).
pub const DEVICE_SIDE_COMMENT: &str =
    "# robobus hex capture: device side (< device read, > device wrote)";

/// A capture file's format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize),
    serde(rename_all = "kebab-case")
)]
pub enum Format {
    /// candump `-L` log of CAN FD frames (WHJ).
    Candump,
    /// Timestamped hex log of a byte link (wCK).
    Hex,
}

/// Which side wrote a hex log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize),
    serde(rename_all = "kebab-case")
)]
pub enum Side {
    /// Detect it (the default): from the side comment, else the side that first writes a
    /// byte `0xFF` (the wCK header) is the host.
    #[default]
    Auto,
    /// The host's log: `>` commands the host wrote, `<` replies it read.
    Host,
    /// A simulator's (device's) log: `<` commands it read, `>` replies it wrote.
    Device,
}

impl Side {
    /// The comment a capture of this side starts with (`None` for [`Side::Auto`]).
    pub const fn comment(self) -> Option<&'static str> {
        match self {
            Self::Auto => None,
            Self::Host => Some(HOST_SIDE_COMMENT),
            Self::Device => Some(DEVICE_SIDE_COMMENT),
        }
    }

    /// Whether bytes of direction `dir` in a log of this side go to the devices (are
    /// commands): `>` in the host's log (and while the side is unknown), `<` in a device's.
    pub const fn to_device(self, dir: Dir) -> bool {
        matches!(
            (self, dir),
            (Self::Host | Self::Auto, Dir::Written) | (Self::Device, Dir::Read)
        )
    }

    /// This side, or the side a comment names if this one is still [`Side::Auto`].
    fn or_comment(self, comment: &str) -> Self {
        if self != Self::Auto {
            self
        } else if comment.contains("host side") {
            Self::Host
        } else if comment.contains("device side") || comment.contains("simulator side") {
            Self::Device
        } else {
            Self::Auto
        }
    }
}

/// One record of a capture, in the order of the file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Record {
    /// A candump line's frame.
    Frame {
        /// 1-based line number.
        line: u64,
        /// The line.
        record: CandumpRecord,
    },
    /// A hex log line's bytes.
    Bytes {
        /// 1-based line number.
        line: u64,
        /// The line.
        record: HexRecord,
        /// Whether the bytes went to the devices (commands), by the log's [`Side`].
        to_device: bool,
    },
    /// A line of the capture's format that does not parse.
    Malformed {
        /// 1-based line number.
        line: u64,
        /// What is wrong, with the line (cut to 120 bytes).
        reason: String,
    },
}

/// A capture that cannot be read on; every error but [`CaptureError::Empty`] names its
/// line.
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// Reading failed.
    #[error("line {line}: cannot read: {source}")]
    Read {
        /// 1-based line number.
        line: u64,
        /// The I/O error.
        #[source]
        source: io::Error,
    },
    /// A line longer than [`MAX_LINE`].
    #[error("line {line}: longer than the limit of {} KiB", MAX_LINE >> 10)]
    TooLong {
        /// 1-based line number.
        line: u64,
    },
    /// A line that is not UTF-8 text.
    #[error("line {line}: not UTF-8 text (byte {valid_up_to})")]
    NotUtf8 {
        /// 1-based line number.
        line: u64,
        /// The bytes of the line that are valid.
        valid_up_to: usize,
    },
    /// No line but blank lines and comments (format to be detected).
    #[error("empty capture: no frame or packet in it")]
    Empty,
    /// The first line is of neither format (format to be detected).
    #[error(
        "line {line}: neither a candump log line (`(seconds) iface ID##data`) nor a hex log line (`seconds > FF 03 7F 7C`)"
    )]
    UnknownFormat {
        /// 1-based line number.
        line: u64,
    },
}

impl CaptureError {
    /// Whether the file could not be read (rather than read and refused).
    pub const fn is_io(&self) -> bool {
        matches!(self, Self::Read { .. })
    }
}

/// Lines of at most [`MAX_LINE`] bytes.
#[derive(Debug)]
struct Lines<R> {
    reader: R,
    line: u64,
    buf: Vec<u8>,
}

impl<R: BufRead> Lines<R> {
    fn next_line(&mut self) -> Result<Option<(u64, String)>, CaptureError> {
        self.buf.clear();
        let limit = u64::try_from(MAX_LINE)
            .unwrap_or(u64::MAX)
            .saturating_add(1);
        let n = (&mut self.reader)
            .take(limit)
            .read_until(b'\n', &mut self.buf)
            .map_err(|source| CaptureError::Read {
                line: self.line + 1,
                source,
            })?;
        if n == 0 {
            return Ok(None);
        }
        self.line += 1;
        if self.buf.last() == Some(&b'\n') {
            self.buf.pop();
        } else if self.buf.len() > MAX_LINE {
            return Err(CaptureError::TooLong { line: self.line });
        }
        if self.buf.last() == Some(&b'\r') {
            self.buf.pop();
        }
        // A UTF-8 byte-order mark (editors on Windows write one) is not part of the text.
        if self.line == 1 && self.buf.starts_with(b"\xEF\xBB\xBF") {
            self.buf.drain(..3);
        }
        let text = std::str::from_utf8(&self.buf).map_err(|e| CaptureError::NotUtf8 {
            line: self.line,
            valid_up_to: e.valid_up_to(),
        })?;
        Ok(Some((self.line, text.to_owned())))
    }
}

/// The format of a capture's first meaningful line.
fn detect(line: &str) -> Option<Format> {
    if parse_candump_line(line).is_ok() || line.trim_start().starts_with('(') {
        Some(Format::Candump)
    } else if parse_hex_line(line).is_ok() {
        Some(Format::Hex)
    } else {
        None
    }
}

/// `text`, cut to 120 bytes (at a character boundary) with `...` where it was cut.
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

/// A hex log line, parsed: `None` for a comment or a blank line.
fn hex_line(text: &str) -> Option<Result<HexRecord, String>> {
    parse_hex_line(text)
        .map_err(|e| format!("{e}: {:?}", clip(text)))
        .transpose()
}

/// A capture file read back: an iterator of its [`Record`]s, one per line that is not
/// blank or a comment, in the order of the file, in bounded memory (one line at a time,
/// at most [`MAX_LINE`] bytes; a hex log of unknown side is read at most 256 records
/// ahead to find it).
///
/// Lines that do not parse are [`Record::Malformed`]; an item is an error only when the
/// file cannot be read on (an I/O error, a line too long, text that is not UTF-8), and
/// the iteration ends there.
///
/// ```
/// use robobus_link::capture::{CaptureReader, Format, Record, Side};
/// let log = "# robobus hex capture: host side (> host wrote, < host read)\n\
///            0.000100 > FF 03 7F 7C\n0.000900 < 12 7F\n";
/// let mut reader = CaptureReader::new(log.as_bytes(), None, Side::Auto)?;
/// assert_eq!((reader.format(), reader.side()), (Format::Hex, Side::Host));
/// let Some(Ok(Record::Bytes { line, record, to_device })) = reader.next() else { panic!() };
/// assert_eq!((line, record.bytes, to_device), (2, vec![0xFF, 0x03, 0x7F, 0x7C], true));
/// # Ok::<(), robobus_link::capture::CaptureError>(())
/// ```
#[derive(Debug)]
pub struct CaptureReader<R> {
    lines: Lines<R>,
    format: Format,
    side: Side,
    /// The first meaningful line, read to detect the format.
    first: Option<(u64, String)>,
    /// Hex records read ahead while the side is unknown.
    ahead: VecDeque<(u64, Result<HexRecord, String>)>,
    failed: bool,
}

impl<R> CaptureReader<R> {
    /// The capture's format.
    pub const fn format(&self) -> Format {
        self.format
    }

    /// The side of a hex log (known once a side comment or the first header was seen;
    /// [`Side::Auto`] before).
    pub const fn side(&self) -> Side {
        self.side
    }

    /// The last line read (1-based; 0 before the first).
    pub const fn line(&self) -> u64 {
        self.lines.line
    }
}

impl<R: BufRead> CaptureReader<R> {
    /// Reads a capture from `reader` in `format` (`None`: detected from the first line
    /// that is not blank or a comment), written by `side` (a hex log's side comment
    /// decides where `side` is [`Side::Auto`]).
    pub fn new(reader: R, format: Option<Format>, side: Side) -> Result<Self, CaptureError> {
        let mut lines = Lines {
            reader,
            line: 0,
            buf: Vec::new(),
        };
        let mut side = side;
        let mut first = None;
        while let Some((n, text)) = lines.next_line()? {
            let t = text.trim();
            if t.is_empty() {
                continue;
            }
            if t.starts_with('#') {
                side = side.or_comment(t);
                continue;
            }
            first = Some((n, text));
            break;
        }
        let format = match (format, &first) {
            (Some(f), _) => f,
            (None, None) => return Err(CaptureError::Empty),
            (None, Some((n, text))) => {
                detect(text).ok_or(CaptureError::UnknownFormat { line: *n })?
            }
        };
        Ok(Self {
            lines,
            format,
            side,
            first,
            ahead: VecDeque::new(),
            failed: false,
        })
    }

    fn next_line(&mut self) -> Result<Option<(u64, String)>, CaptureError> {
        if let Some(l) = self.first.take() {
            return Ok(Some(l));
        }
        self.lines.next_line()
    }

    fn next_frame(&mut self) -> Result<Option<Record>, CaptureError> {
        while let Some((line, text)) = self.next_line()? {
            if text.trim().is_empty() {
                continue;
            }
            return Ok(Some(match parse_candump_line(&text) {
                Ok(record) => Record::Frame { line, record },
                Err(kind) => Record::Malformed {
                    line,
                    reason: format!("{kind}: {:?}", clip(&text)),
                },
            }));
        }
        Ok(None)
    }

    /// Reads ahead until a side comment or a header shows which side writes the commands.
    fn find_side(&mut self) -> Result<(), CaptureError> {
        while self.side == Side::Auto {
            let Some((n, text)) = self.next_line()? else {
                self.side = Side::Host;
                break;
            };
            let t = text.trim();
            if t.starts_with('#') {
                self.side = Side::Auto.or_comment(t);
                continue;
            }
            match hex_line(&text) {
                None => {}
                Some(Ok(rec)) => {
                    if rec.bytes.contains(&0xFF) {
                        self.side = match rec.dir {
                            Dir::Written => Side::Host,
                            Dir::Read => Side::Device,
                        };
                    }
                    self.ahead.push_back((n, Ok(rec)));
                }
                Some(Err(e)) => self.ahead.push_back((n, Err(e))),
            }
            if self.ahead.len() >= SIDE_LOOKAHEAD && self.side == Side::Auto {
                self.side = Side::Host;
            }
        }
        Ok(())
    }

    fn next_bytes(&mut self) -> Result<Option<Record>, CaptureError> {
        self.find_side()?;
        let item = if let Some(item) = self.ahead.pop_front() {
            Some(item)
        } else {
            loop {
                match self.next_line()? {
                    None => break None,
                    Some((n, text)) => {
                        if let Some(r) = hex_line(&text) {
                            break Some((n, r));
                        }
                    }
                }
            }
        };
        Ok(item.map(|(line, r)| match r {
            Ok(record) => Record::Bytes {
                line,
                to_device: self.side.to_device(record.dir),
                record,
            },
            Err(reason) => Record::Malformed { line, reason },
        }))
    }
}

impl<R: BufRead> Iterator for CaptureReader<R> {
    type Item = Result<Record, CaptureError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        let next = match self.format {
            Format::Candump => self.next_frame(),
            Format::Hex => self.next_bytes(),
        };
        self.failed = next.is_err();
        next.transpose()
    }
}

#[cfg(test)]
mod tests {
    use std::time::{Duration, Instant};

    use robobus_whj::CanFrame;

    use super::*;
    use crate::capture::{CaptureByteLink, CaptureFrameLink};
    use crate::{ByteLink, FrameLink, MemoryBus, MemoryByteLink};

    fn records(text: &[u8]) -> Vec<Record> {
        CaptureReader::new(text, None, Side::Auto)
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap()
    }

    fn fd(id: u16, data: &[u8]) -> CanFrame {
        CanFrame::new_fd(CanFrame::standard_id(id).unwrap(), data).unwrap()
    }

    /// What the frame writer writes, the reader reads back: the same frames, in order,
    /// under the interface name of their direction.
    #[test]
    fn candump_captures_read_back_as_written() {
        let bus = MemoryBus::new();
        let mut joint = bus.endpoint();
        let mut out = Vec::new();
        {
            let mut host =
                CaptureFrameLink::new(bus.endpoint(), &mut out, "can0").with_tx_iface("can0tx");
            let sent = fd(0x001, &[0x01, 0x14, 0x02]).with_brs(true);
            host.send(&sent).unwrap();
            assert_eq!(
                joint
                    .recv(Instant::now() + Duration::from_secs(1))
                    .unwrap()
                    .frame,
                sent
            );
            joint.send(&fd(0x101, &[0x01, 0x14, 0, 0, 0, 0])).unwrap();
            host.recv(Instant::now() + Duration::from_secs(1)).unwrap();
        }
        let mut reader = CaptureReader::new(&out[..], None, Side::Auto).unwrap();
        assert_eq!(reader.format(), Format::Candump);
        let got: Vec<(u64, String, CanFrame)> = reader
            .by_ref()
            .map(|r| match r.unwrap() {
                Record::Frame { line, record } => (line, record.iface, record.frame),
                other => panic!("{other:?}"),
            })
            .collect();
        assert_eq!(
            got,
            [
                (
                    1,
                    "can0tx".into(),
                    fd(0x001, &[0x01, 0x14, 0x02]).with_brs(true)
                ),
                (2, "can0".into(), fd(0x101, &[0x01, 0x14, 0, 0, 0, 0])),
            ]
        );
        assert_eq!(reader.line(), 2);
    }

    /// What the byte writer writes (with its side comment), the reader reads back: the
    /// same bytes and directions, commands marked by the side the comment names.
    #[test]
    fn hex_captures_read_back_as_written_with_their_side() {
        for side in [Side::Host, Side::Device] {
            let (mut near, mut far) = MemoryByteLink::pair();
            let mut out = Vec::new();
            {
                let mut link = CaptureByteLink::with_side(&mut near, &mut out, side).unwrap();
                link.write_all(&[0xFF, 0x03, 0x7F, 0x7C]).unwrap();
                far.write_all(&[0x12, 0x7F]).unwrap();
                let mut buf = [0u8; 2];
                link.read_exact(&mut buf, Instant::now() + Duration::from_secs(1))
                    .unwrap();
            }
            let text = String::from_utf8(out.clone()).unwrap();
            assert_eq!(text.lines().next(), side.comment(), "{text}");
            let mut reader = CaptureReader::new(&out[..], None, Side::Auto).unwrap();
            assert_eq!((reader.format(), reader.side()), (Format::Hex, side));
            let got: Vec<(u64, Dir, Vec<u8>, bool)> = reader
                .by_ref()
                .map(|r| match r.unwrap() {
                    Record::Bytes {
                        line,
                        record,
                        to_device,
                    } => (line, record.dir, record.bytes, to_device),
                    other => panic!("{other:?}"),
                })
                .collect();
            let host = side == Side::Host;
            assert_eq!(
                got,
                [
                    (2, Dir::Written, vec![0xFF, 0x03, 0x7F, 0x7C], host),
                    (3, Dir::Read, vec![0x12, 0x7F], !host),
                ]
            );
        }
    }

    #[test]
    fn the_side_is_found_from_the_first_header_or_else_is_the_host() {
        let mut r = CaptureReader::new(&b"0.1 < 12\n0.2 < FF 03\n"[..], None, Side::Auto).unwrap();
        assert_eq!(r.side(), Side::Auto);
        let first = r.next().unwrap().unwrap();
        assert_eq!(r.side(), Side::Device);
        assert!(matches!(
            first,
            Record::Bytes {
                line: 1,
                to_device: true,
                ..
            }
        ));
        let r = CaptureReader::new(&b"0.1 > 12\n"[..], None, Side::Auto).unwrap();
        assert_eq!(r.count(), 1);
        // A given side is kept whatever the comment says.
        let r = CaptureReader::new(
            HOST_SIDE_COMMENT.as_bytes(),
            Some(Format::Hex),
            Side::Device,
        );
        assert_eq!(r.unwrap().side(), Side::Device);
    }

    #[test]
    fn bad_lines_are_records_and_bad_files_errors_naming_the_line() {
        let got = records(b"(1.0) can0 001##1011402\n\n(x) can0 001#00\n");
        assert!(matches!(got[0], Record::Frame { line: 1, .. }));
        assert_eq!(
            got[1],
            Record::Malformed {
                line: 3,
                reason: "bad timestamp \"(x)\": \"(x) can0 001#00\"".into()
            }
        );
        let long = format!("0.1 > FF\n0.2 > {}\n", "00 ".repeat(MAX_LINE / 3 + 1));
        let err = CaptureReader::new(long.as_bytes(), None, Side::Auto)
            .unwrap()
            .find_map(Result::err)
            .unwrap();
        assert_eq!(err.to_string(), "line 2: longer than the limit of 64 KiB");
        assert!(!err.is_io());
        let err =
            CaptureReader::new(&b"\xEF\xBB\xBF\n\xC3\x28\n"[..], None, Side::Auto).unwrap_err();
        assert_eq!(err.to_string(), "line 2: not UTF-8 text (byte 0)");
        let err = CaptureReader::new(&b"# only\n\n"[..], None, Side::Auto).unwrap_err();
        assert_eq!(err.to_string(), "empty capture: no frame or packet in it");
        let err = CaptureReader::new(&b"hello\n"[..], None, Side::Auto).unwrap_err();
        assert!(
            err.to_string().starts_with("line 1: neither a candump"),
            "{err}"
        );
        let clipped = clip(&"é".repeat(100));
        assert!(
            clipped.len() <= 123 && clipped.ends_with("..."),
            "{clipped}"
        );
    }
}
