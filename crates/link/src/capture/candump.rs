//! The candump log format: one CAN frame per line, as `candump -l` writes it.

use std::fmt::Write as _;
use std::io::{self, BufRead, Write};
use std::time::Duration;

use robobus_whj::frame::{CanFrame, FrameError};

use super::{parse_hex_bytes, parse_timestamp, write_time};

/// One line of a candump log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CandumpRecord {
    /// Time since the Unix epoch (candump's clock).
    pub timestamp: Duration,
    /// Interface name (`vcan0`, `can1`, ...).
    pub iface: String,
    /// The frame.
    pub frame: CanFrame,
}

/// What is wrong with a candump line.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CandumpErrorKind {
    /// Not `(timestamp) iface frame`.
    #[error("expected `(seconds.micros) iface ID#data`")]
    Layout,
    /// The timestamp is not `(seconds.fraction)`.
    #[error("bad timestamp {0:?}")]
    Timestamp(String),
    /// The identifier is not 3 or 8 hex digits.
    #[error("bad identifier {0:?} (3 hex digits for 11-bit, 8 for 29-bit)")]
    Id(String),
    /// The data is not pairs of hex digits.
    #[error("bad data {0:?} (pairs of hex digits)")]
    Data(String),
    /// A remote or error frame (not a data frame).
    #[error("{0} not supported (only data frames)")]
    Unsupported(&'static str),
    /// Illegal length or identifier for the frame kind.
    #[error(transparent)]
    Frame(#[from] FrameError),
}

/// A candump line that could not be read, with its 1-based line number.
#[derive(Debug, thiserror::Error)]
pub enum CandumpError {
    /// The line is malformed.
    #[error("candump log line {line}: {kind}")]
    Parse {
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        kind: CandumpErrorKind,
    },
    /// Reading failed.
    #[error("reading candump log at line {line}: {source}")]
    Io {
        /// 1-based line number.
        line: usize,
        /// The I/O error.
        #[source]
        source: io::Error,
    },
}

/// Parses one candump log line (without line-number context).
pub fn parse_candump_line(line: &str) -> Result<CandumpRecord, CandumpErrorKind> {
    let mut parts = line.split_whitespace();
    let (Some(ts), Some(iface), Some(frame)) = (parts.next(), parts.next(), parts.next()) else {
        return Err(CandumpErrorKind::Layout);
    };
    match (parts.next(), parts.next()) {
        (None | Some("R" | "T" | "r" | "t"), None) => {}
        _ => return Err(CandumpErrorKind::Layout),
    }
    let timestamp = parse_timestamp(ts).ok_or_else(|| CandumpErrorKind::Timestamp(ts.into()))?;
    let (id_str, rest) = frame.split_once('#').ok_or(CandumpErrorKind::Layout)?;
    let raw = u32::from_str_radix(id_str, 16)
        .ok()
        .filter(|_| id_str.bytes().all(|c| c.is_ascii_hexdigit()))
        .ok_or_else(|| CandumpErrorKind::Id(id_str.into()))?;
    let id = match id_str.len() {
        3 => CanFrame::standard_id(u16::try_from(raw).unwrap_or(u16::MAX))?,
        8 if raw & 0x2000_0000 != 0 => return Err(CandumpErrorKind::Unsupported("an error frame")),
        8 => CanFrame::extended_id(raw & !0x8000_0000)?,
        _ => return Err(CandumpErrorKind::Id(id_str.into())),
    };
    let frame = if let Some(fd) = rest.strip_prefix('#') {
        let mut chars = fd.chars();
        let flags = chars
            .next()
            .and_then(|c| c.to_digit(16))
            .ok_or_else(|| CandumpErrorKind::Data(fd.into()))?;
        let data = chars.as_str();
        let bytes = parse_hex_bytes(data).ok_or_else(|| CandumpErrorKind::Data(data.into()))?;
        CanFrame::new_fd(id, &bytes)?
            .with_brs(flags & 1 != 0)
            .with_esi(flags & 2 != 0)
    } else {
        if rest.starts_with(['R', 'r']) {
            return Err(CandumpErrorKind::Unsupported("a remote frame"));
        }
        let bytes = parse_hex_bytes(rest).ok_or_else(|| CandumpErrorKind::Data(rest.into()))?;
        CanFrame::new_classic(id, &bytes)?
    };
    Ok(CandumpRecord {
        timestamp,
        iface: iface.to_owned(),
        frame,
    })
}

/// Formats one candump log line (no newline).
pub fn format_candump_line(rec: &CandumpRecord) -> String {
    let mut s = String::with_capacity(64 + 2 * rec.frame.len());
    s.push('(');
    write_time(&mut s, rec.timestamp);
    let _ = write!(s, ") {} {:#}", rec.iface, rec.frame);
    s
}

/// Reads every record of a candump log; blank lines are skipped.
pub fn read_candump(
    reader: impl BufRead,
) -> impl Iterator<Item = Result<CandumpRecord, CandumpError>> {
    reader.lines().enumerate().filter_map(|(i, line)| {
        let line_no = i + 1;
        match line {
            Err(source) => Some(Err(CandumpError::Io {
                line: line_no,
                source,
            })),
            Ok(l) if l.trim().is_empty() => None,
            Ok(l) => Some(parse_candump_line(&l).map_err(|kind| CandumpError::Parse {
                line: line_no,
                kind,
            })),
        }
    })
}

/// Writes candump log lines.
#[derive(Debug)]
pub struct CandumpWriter<W> {
    out: W,
}

impl<W: Write> CandumpWriter<W> {
    /// A writer into `out`.
    pub const fn new(out: W) -> Self {
        Self { out }
    }

    /// Writes one record as a line.
    pub fn write(&mut self, rec: &CandumpRecord) -> io::Result<()> {
        writeln!(self.out, "{}", format_candump_line(rec))
    }

    /// Flushes the output.
    pub fn flush(&mut self) -> io::Result<()> {
        self.out.flush()
    }

    /// The output.
    pub fn into_inner(self) -> W {
        self.out
    }
}
