//! The capture file's lines: bounded reading, the side comment, the format.

use std::io::{BufRead, Read as _};
use std::path::PathBuf;

use robobus_link::capture::{parse_candump_line, parse_hex_line};

use super::{ErrorKind, Format, MAX_LINE, OpError, Side, human_bytes};

/// Reads lines of at most [`MAX_LINE`] bytes.
pub(super) struct Lines<R> {
    pub(super) reader: R,
    pub(super) path: PathBuf,
    pub(super) line: u64,
    pub(super) buf: Vec<u8>,
}

impl<R: BufRead> Lines<R> {
    #[allow(clippy::result_large_err)] // OpError, as every operation returns
    pub(super) fn next_line(&mut self) -> Result<Option<(u64, String)>, OpError> {
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

pub(super) fn side_comment(comment: &str, side: Side) -> Side {
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

pub(super) fn detect(line: &str) -> Option<Format> {
    if parse_candump_line(line).is_ok() || line.trim_start().starts_with('(') {
        Some(Format::Candump)
    } else if parse_hex_line(line).is_ok() {
        Some(Format::Hex)
    } else {
        None
    }
}
