//! Capture: record everything a link sends and receives to a file, as it goes.
//!
//! A front end that offers `--capture FILE` wraps the link it opened with
//! [`capture_byte_link`] (wCK: a hex log) or [`capture_frame_link`] (WHJ: a candump log)
//! before handing it to the client. The file is created new (an existing file is refused
//! unless [`Overwrite::Yes`] is given) and written through a line buffer, so every line
//! reaches the file when it is complete: a Ctrl-C or a crash loses at most the line being
//! written. [`super::replay`] reads both formats back (through the link's
//! [`CaptureReader`](robobus_link::CaptureReader), beside the writers).

use std::fs::{File, OpenOptions};
use std::io::LineWriter;
use std::path::Path;

use robobus_link::capture::Side;
use robobus_link::{ByteLink, CaptureByteLink, CaptureFrameLink, FrameLink};

use super::{ErrorKind, OpError};

/// Whether an existing capture file may be replaced.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Overwrite {
    /// Refuse an existing file (the default).
    #[default]
    No,
    /// Truncate and replace it.
    Yes,
}

/// The file a capture writes into: line-buffered (each line is flushed when complete),
/// and bounded when a limit is given.
pub type CaptureFile = LineWriter<BoundedFile>;

/// A file that takes at most a number of bytes: the line that would pass the limit is
/// replaced by a comment saying the capture stopped there, and everything after it is
/// dropped (the link it records goes on working).
#[derive(Debug)]
pub struct BoundedFile {
    file: File,
    left: u64,
    full: bool,
}

impl BoundedFile {
    /// `file`, taking at most `limit` bytes.
    pub const fn new(file: File, limit: u64) -> Self {
        Self {
            file,
            left: limit,
            full: false,
        }
    }

    /// Whether the limit was reached.
    pub const fn is_full(&self) -> bool {
        self.full
    }
}

impl std::io::Write for BoundedFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if self.full {
            return Ok(buf.len());
        }
        if buf.len() as u64 > self.left {
            self.full = true;
            let note = b"# capture stopped here: the file reached its size limit\n";
            if note.len() as u64 <= self.left {
                self.file.write_all(note)?;
            }
            return Ok(buf.len());
        }
        let n = self.file.write(buf)?;
        self.left -= n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

#[allow(clippy::result_large_err)] // OpError, as every operation returns
fn create_limited(path: &Path, overwrite: Overwrite, limit: u64) -> Result<CaptureFile, OpError> {
    let mut options = OpenOptions::new();
    options.write(true);
    match overwrite {
        Overwrite::No => options.create_new(true),
        Overwrite::Yes => options.create(true).truncate(true),
    };
    let file = options.open(path).map_err(|e| {
        let (reason, kind) = if e.kind() == std::io::ErrorKind::AlreadyExists {
            (
                "already exists; not overwritten (choose another file, or allow overwriting)"
                    .to_owned(),
                ErrorKind::Refused,
            )
        } else {
            (
                format!("cannot create the capture file: {e}"),
                ErrorKind::BadInput,
            )
        };
        OpError::File {
            path: path.to_path_buf(),
            reason,
            kind,
        }
    })?;
    Ok(LineWriter::new(BoundedFile::new(file, limit)))
}

/// Wraps a byte link (wCK) so every write and read is logged to `path` as a hex log; the
/// first line is a comment saying it is the host's side, so a replay reads `>` as the
/// host's commands.
#[allow(clippy::result_large_err)] // OpError, as every operation returns
pub fn capture_byte_link<L: ByteLink>(
    link: L,
    path: &Path,
    overwrite: Overwrite,
) -> Result<CaptureByteLink<L, CaptureFile>, OpError> {
    capture_with_side(link, path, overwrite, Side::Host)
}

/// Like [`capture_byte_link`], for the device's end of the line (a simulator): the first
/// line says so, and a replay reads `<` as the commands the device received.
#[allow(clippy::result_large_err)] // OpError, as every operation returns
pub fn capture_device_byte_link<L: ByteLink>(
    link: L,
    path: &Path,
    overwrite: Overwrite,
) -> Result<CaptureByteLink<L, CaptureFile>, OpError> {
    capture_with_side(link, path, overwrite, Side::Device)
}

#[allow(clippy::result_large_err)] // OpError, as every operation returns
fn capture_with_side<L: ByteLink>(
    link: L,
    path: &Path,
    overwrite: Overwrite,
    side: Side,
) -> Result<CaptureByteLink<L, CaptureFile>, OpError> {
    capture_limited(link, path, overwrite, side, u64::MAX)
}

/// [`capture_byte_link`] into a file of at most `limit` bytes (see [`BoundedFile`]).
#[allow(clippy::result_large_err)] // OpError, as every operation returns
pub fn capture_byte_link_limited<L: ByteLink>(
    link: L,
    path: &Path,
    overwrite: Overwrite,
    limit: u64,
) -> Result<CaptureByteLink<L, CaptureFile>, OpError> {
    capture_limited(link, path, overwrite, Side::Host, limit)
}

#[allow(clippy::result_large_err)] // OpError, as every operation returns
fn capture_limited<L: ByteLink>(
    link: L,
    path: &Path,
    overwrite: Overwrite,
    side: Side,
    limit: u64,
) -> Result<CaptureByteLink<L, CaptureFile>, OpError> {
    let out = create_limited(path, overwrite, limit)?;
    CaptureByteLink::with_side(link, out, side).map_err(|e| OpError::File {
        path: path.to_path_buf(),
        reason: format!("cannot write the capture file: {e}"),
        kind: ErrorKind::Link,
    })
}

/// Wraps a frame link (WHJ) so every frame sent and received is logged to `path` as a
/// candump log under the interface name `iface` (what `candump -L` would write; the
/// file can be played back with can-utils' `canplayer`).
#[allow(clippy::result_large_err)] // OpError, as every operation returns
pub fn capture_frame_link<L: FrameLink>(
    link: L,
    path: &Path,
    iface: &str,
    overwrite: Overwrite,
) -> Result<CaptureFrameLink<L, CaptureFile>, OpError> {
    capture_frame_link_limited(link, path, iface, overwrite, u64::MAX)
}

/// [`capture_frame_link`] into a file of at most `limit` bytes (see [`BoundedFile`]).
#[allow(clippy::result_large_err)] // OpError, as every operation returns
pub fn capture_frame_link_limited<L: FrameLink>(
    link: L,
    path: &Path,
    iface: &str,
    overwrite: Overwrite,
    limit: u64,
) -> Result<CaptureFrameLink<L, CaptureFile>, OpError> {
    if iface.is_empty() || iface.chars().any(|c| c.is_whitespace() || c.is_control()) {
        return Err(OpError::invalid(
            "interface name",
            format!("{iface:?}"),
            "one word without spaces (`can0`, `vcan0`)",
        ));
    }
    Ok(CaptureFrameLink::new(
        link,
        create_limited(path, overwrite, limit)?,
        iface,
    ))
}
