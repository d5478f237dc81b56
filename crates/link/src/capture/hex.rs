//! The hex log format of byte links: one line per write or read call.

use std::fmt::Write as _;
use std::io::BufRead;
use std::time::Duration;

use super::{parse_hex_bytes, parse_timestamp, write_time};

/// Direction of a hex log record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dir {
    /// Bytes this side wrote (`>`).
    Written,
    /// Bytes this side read (`<`).
    Read,
}

/// One line of a hex log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HexRecord {
    /// Time since the start of the capture.
    pub at: Duration,
    /// Direction.
    pub dir: Dir,
    /// The bytes.
    pub bytes: Vec<u8>,
}

/// A hex log line that could not be read.
#[derive(Debug, thiserror::Error)]
#[error("hex log line {line}: {what}")]
pub struct HexLogError {
    /// 1-based line number.
    pub line: usize,
    /// What is wrong.
    pub what: String,
}

/// Formats one hex log line (no newline).
pub fn format_hex_line(rec: &HexRecord) -> String {
    let mut s = String::with_capacity(20 + 3 * rec.bytes.len());
    write_time(&mut s, rec.at);
    s.push(' ');
    s.push(match rec.dir {
        Dir::Written => '>',
        Dir::Read => '<',
    });
    for b in &rec.bytes {
        let _ = write!(s, " {b:02X}");
    }
    s
}

/// Parses one hex log line (`Ok(None)` for comments and blank lines).
pub fn parse_hex_line(line: &str) -> Result<Option<HexRecord>, String> {
    let t = line.trim();
    if t.is_empty() || t.starts_with('#') {
        return Ok(None);
    }
    let mut parts = t.split_whitespace();
    let ts = parts.next().unwrap_or_default();
    let at = parse_timestamp(&format!("({ts})")).ok_or_else(|| format!("bad time {ts:?}"))?;
    let dir = match parts.next() {
        Some(">") => Dir::Written,
        Some("<") => Dir::Read,
        other => return Err(format!("bad direction {other:?} (expected > or <)")),
    };
    let bytes = parts
        .map(|p| {
            if p.len() == 2 {
                parse_hex_bytes(p).and_then(|v| v.first().copied())
            } else {
                None
            }
            .ok_or_else(|| format!("bad byte {p:?} (two hex digits)"))
        })
        .collect::<Result<Vec<u8>, String>>()?;
    Ok(Some(HexRecord { at, dir, bytes }))
}

/// Reads every record of a hex log.
pub fn read_hex_log(reader: impl BufRead) -> Result<Vec<HexRecord>, HexLogError> {
    let mut out = Vec::new();
    for (i, line) in reader.lines().enumerate() {
        let line = line.map_err(|e| HexLogError {
            line: i + 1,
            what: e.to_string(),
        })?;
        if let Some(r) = parse_hex_line(&line).map_err(|what| HexLogError { line: i + 1, what })? {
            out.push(r);
        }
    }
    Ok(out)
}
