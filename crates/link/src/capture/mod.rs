//! Capture and replay: candump log files for frame links, a hex log for byte links; the
//! writer and the reader of each format side by side.
//!
//! # candump log format
//!
//! One frame per line, as `candump -l` writes it: `(1795360410.847412) vcan0 123##5DEADBEEF`.
//! The identifier is 3 hex digits (11-bit) or 8 (29-bit). A CAN FD frame is
//! `ID##<flags><hex data>` with the flags nibble BRS = 1, ESI = 2, FDF = 4 (we write FDF
//! set, like current kernels; the reader accepts any nibble, since older tools wrote
//! `##0` / `##1`); a classic frame is `ID#<hex data>`. The reader also accepts a trailing
//! ` R` / ` T` direction mark and `.` between data bytes; remote and error frames are
//! reported as errors (a [`CanFrame`] is a data frame). Every error names its line.
//!
//! # Hex log format (byte links)
//!
//! One line per write or read call: `<seconds> <dir> <hex bytes>`, e.g.
//! `0.001234 > FF 03 7F 7C` then `0.002760 < 12 7F`. `seconds` counts from the start of the
//! capture (6 decimals); `>` marks bytes this side wrote, `<` bytes it read; bytes are two
//! hex digits separated by single spaces. Lines starting with `#` and blank lines are
//! comments.
//!
//! A host's capture starts with the comment [`HOST_SIDE_COMMENT`], a simulator's with
//! [`DEVICE_SIDE_COMMENT`] ([`CaptureByteLink::with_side`]), so a reader knows whether `>`
//! marks commands or replies.
//!
//! # Reading
//!
//! [`parse_candump_line`] / [`parse_hex_line`] read one line, [`read_candump`] /
//! [`read_hex_log`] a whole log of a known format. [`CaptureReader`] reads a capture file
//! of either format as a front end gets it: lines of at most [`MAX_LINE`] bytes (bounded
//! memory for any size), a leading UTF-8 byte-order mark skipped, the format detected from
//! the first line, the side of a hex log from its comment or its first header, and every
//! line that does not parse a [`Record::Malformed`] naming its line.

use std::collections::VecDeque;
use std::fmt::Write as _;
use std::io::{self, Write};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use robobus_whj::frame::CanFrame;

use crate::byte::{ByteLink, LinkError};
use crate::frame_link::{FrameLink, FrameLinkError, IdFilter, Received, passes};

mod candump;
mod hex;
mod reader;

pub use candump::{
    CandumpError, CandumpErrorKind, CandumpRecord, CandumpWriter, format_candump_line,
    parse_candump_line, read_candump,
};
pub use hex::{Dir, HexLogError, HexRecord, format_hex_line, parse_hex_line, read_hex_log};
pub use reader::{
    CaptureError, CaptureReader, DEVICE_SIDE_COMMENT, Format, HOST_SIDE_COMMENT, MAX_LINE, Record,
    Side,
};

fn hex_nibble(c: u8) -> Option<u8> {
    match c {
        b'0'..=b'9' => Some(c - b'0'),
        b'a'..=b'f' => Some(c - b'a' + 10),
        b'A'..=b'F' => Some(c - b'A' + 10),
        _ => None,
    }
}

fn parse_hex_bytes(s: &str) -> Option<Vec<u8>> {
    let digits: Vec<u8> = s.bytes().filter(|c| *c != b'.').collect();
    if !digits.len().is_multiple_of(2) {
        return None;
    }
    digits
        .chunks(2)
        .map(|p| match p {
            [h, l] => Some((hex_nibble(*h)? << 4) | hex_nibble(*l)?),
            _ => None,
        })
        .collect()
}

fn parse_timestamp(s: &str) -> Option<Duration> {
    let inner = s.strip_prefix('(')?.strip_suffix(')')?;
    let (secs, frac) = inner.split_once('.').unwrap_or((inner, ""));
    if secs.is_empty() || !secs.bytes().all(|c| c.is_ascii_digit()) {
        return None;
    }
    if frac.len() > 9 || !frac.bytes().all(|c| c.is_ascii_digit()) {
        return None;
    }
    let secs: u64 = secs.parse().ok()?;
    let nanos: u32 = if frac.is_empty() {
        0
    } else {
        frac.parse::<u32>().ok()? * 10u32.pow(9 - u32::try_from(frac.len()).ok()?)
    };
    Some(Duration::new(secs, nanos))
}

/// Writes a capture time as seconds with six decimals, as candump writes it and canplayer
/// requires (a time read with nanoseconds is written to the microsecond).
fn write_time(s: &mut String, t: Duration) {
    let _ = write!(s, "{}.{:06}", t.as_secs(), t.subsec_micros());
}

/// A capture time as the capture files write it: seconds with six decimals
/// (`1795360410.847412`, `0.001234`).
pub fn format_time(t: Duration) -> String {
    let mut s = String::with_capacity(20);
    write_time(&mut s, t);
    s
}

fn since_epoch(t: SystemTime) -> Duration {
    t.duration_since(UNIX_EPOCH).unwrap_or_default()
}

/// A frame link that records every frame sent and received to a candump log.
#[derive(Debug)]
pub struct CaptureFrameLink<L, W> {
    inner: L,
    log: CandumpWriter<W>,
    rx_iface: String,
    tx_iface: String,
}

impl<L: FrameLink, W: Write> CaptureFrameLink<L, W> {
    /// Wraps `inner`; frames in both directions are logged under `iface`.
    pub fn new(inner: L, out: W, iface: &str) -> Self {
        Self {
            inner,
            log: CandumpWriter::new(out),
            rx_iface: iface.into(),
            tx_iface: iface.into(),
        }
    }

    /// Logs sent frames under a different interface name (to tell directions apart).
    #[must_use]
    pub fn with_tx_iface(mut self, iface: &str) -> Self {
        self.tx_iface = iface.into();
        self
    }

    /// Flushes the log and returns the link and the log output.
    pub fn into_parts(mut self) -> (L, W) {
        let _ = self.log.flush();
        (self.inner, self.log.into_inner())
    }

    fn record(&mut self, frame: &CanFrame, at: SystemTime, tx: bool) -> io::Result<()> {
        let iface = if tx { &self.tx_iface } else { &self.rx_iface };
        let rec = CandumpRecord {
            timestamp: since_epoch(at),
            iface: iface.clone(),
            frame: *frame,
        };
        self.log.write(&rec)
    }
}

impl<L: FrameLink, W: Write> FrameLink for CaptureFrameLink<L, W> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        self.inner.send(frame)?;
        self.record(frame, SystemTime::now(), true)
            .map_err(|e| FrameLinkError::io("writing the candump capture", e))
    }

    fn recv(&mut self, deadline: Instant) -> Result<Received, FrameLinkError> {
        let r = self.inner.recv(deadline)?;
        self.record(&r.frame, r.timestamp.unwrap_or_else(SystemTime::now), false)
            .map_err(|e| FrameLinkError::io("writing the candump capture", e))?;
        Ok(r)
    }

    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        self.inner.set_filters(filters)
    }

    crate::forward_frame_link_clock!(inner);
}

/// A frame link that plays a candump capture back: `recv` returns the records in order
/// (optionally at their original pace), `send` is accepted and counted, and after the last
/// record `recv` reports `Closed`.
#[derive(Debug)]
pub struct ReplayFrameLink {
    records: VecDeque<CandumpRecord>,
    paced: Option<(Instant, Duration)>,
    pace: bool,
    filters: Vec<IdFilter>,
    sent: u64,
}

impl ReplayFrameLink {
    /// Replays `records`; with `paced`, each record is released at its original offset
    /// from the first one.
    pub fn new(records: impl IntoIterator<Item = CandumpRecord>, paced: bool) -> Self {
        Self {
            records: records.into_iter().collect(),
            paced: None,
            pace: paced,
            filters: Vec::new(),
            sent: 0,
        }
    }

    /// Frames sent into the replay so far.
    pub const fn sent(&self) -> u64 {
        self.sent
    }
}

impl FrameLink for ReplayFrameLink {
    fn send(&mut self, _frame: &CanFrame) -> Result<(), FrameLinkError> {
        self.sent += 1;
        Ok(())
    }

    fn recv(&mut self, deadline: Instant) -> Result<Received, FrameLinkError> {
        loop {
            let Some(rec) = self.records.front() else {
                return Err(FrameLinkError::Closed {
                    context: "replay: end of capture".into(),
                });
            };
            if self.pace {
                let (start, first) = *self.paced.get_or_insert((Instant::now(), rec.timestamp));
                let due = start + rec.timestamp.saturating_sub(first);
                if due > deadline {
                    std::thread::sleep(deadline.saturating_duration_since(Instant::now()));
                    return Err(FrameLinkError::Timeout);
                }
                std::thread::sleep(due.saturating_duration_since(Instant::now()));
            }
            let Some(rec) = self.records.pop_front() else {
                continue;
            };
            if passes(&self.filters, &rec.frame) {
                return Ok(Received {
                    frame: rec.frame,
                    timestamp: Some(UNIX_EPOCH + rec.timestamp),
                });
            }
        }
    }

    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        self.filters = filters.to_vec();
        Ok(())
    }
}

/// A byte link that records every write and read to a hex log.
#[derive(Debug)]
pub struct CaptureByteLink<L, W> {
    inner: L,
    out: W,
    start: Instant,
}

impl<L: ByteLink, W: Write> CaptureByteLink<L, W> {
    /// Wraps `inner`; the log's clock starts now.
    pub fn new(inner: L, out: W) -> Self {
        Self {
            start: inner.now(),
            inner,
            out,
        }
    }

    /// Wraps `inner` as [`CaptureByteLink::new`] does, after writing the comment that names
    /// the side the log is written on ([`Side::comment`]; nothing for [`Side::Auto`]), so
    /// that a reader knows whether `>` marks commands or replies.
    pub fn with_side(inner: L, mut out: W, side: Side) -> io::Result<Self> {
        if let Some(comment) = side.comment() {
            writeln!(out, "{comment}")?;
        }
        Ok(Self::new(inner, out))
    }

    /// Flushes the log and returns the link and the log output.
    pub fn into_parts(mut self) -> (L, W) {
        let _ = self.out.flush();
        (self.inner, self.out)
    }

    fn record(&mut self, dir: Dir, bytes: &[u8]) -> Result<(), LinkError> {
        let rec = HexRecord {
            at: self.inner.now().saturating_duration_since(self.start),
            dir,
            bytes: bytes.to_vec(),
        };
        writeln!(self.out, "{}", format_hex_line(&rec))
            .map_err(|e| LinkError::io("writing the hex capture", e))
    }
}

impl<L: ByteLink, W: Write> ByteLink for CaptureByteLink<L, W> {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        self.inner.write_all(bytes)?;
        self.record(Dir::Written, bytes)
    }

    fn read_some(&mut self, buf: &mut [u8], deadline: Instant) -> Result<usize, LinkError> {
        let n = self.inner.read_some(buf, deadline)?;
        let got = buf.get(..n).unwrap_or_default().to_vec();
        self.record(Dir::Read, &got)?;
        Ok(n)
    }

    fn discard_input(&mut self) -> Result<(), LinkError> {
        self.inner.discard_input()
    }

    crate::forward_byte_link_rate_and_clock!(inner);
}

/// A byte link that plays the `<` (read) records of a hex log back as incoming bytes
/// (optionally at their original pace); writes are accepted and kept for inspection.
/// After the last record, reads report `Closed`.
#[derive(Debug)]
pub struct ReplayByteLink {
    records: VecDeque<HexRecord>,
    buffered: VecDeque<u8>,
    start: Option<Instant>,
    pace: bool,
    written: Vec<u8>,
    baud: u32,
}

impl ReplayByteLink {
    /// Replays the read records of `records`.
    pub fn new(records: impl IntoIterator<Item = HexRecord>, paced: bool) -> Self {
        Self {
            records: records.into_iter().filter(|r| r.dir == Dir::Read).collect(),
            buffered: VecDeque::new(),
            start: None,
            pace: paced,
            written: Vec::new(),
            baud: 115_200,
        }
    }

    /// Everything written into the replay so far.
    pub fn written(&self) -> &[u8] {
        &self.written
    }
}

impl ByteLink for ReplayByteLink {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        self.written.extend_from_slice(bytes);
        Ok(())
    }

    fn read_some(&mut self, buf: &mut [u8], deadline: Instant) -> Result<usize, LinkError> {
        if buf.is_empty() {
            return Ok(0);
        }
        let start = *self.start.get_or_insert_with(Instant::now);
        while self.buffered.is_empty() {
            let Some(rec) = self.records.front() else {
                return Err(LinkError::Closed {
                    context: "replay: end of capture".into(),
                });
            };
            if self.pace {
                let due = start + rec.at;
                if due > deadline {
                    std::thread::sleep(deadline.saturating_duration_since(Instant::now()));
                    return Err(LinkError::Timeout {
                        received: 0,
                        expected: buf.len(),
                    });
                }
                std::thread::sleep(due.saturating_duration_since(Instant::now()));
            }
            if let Some(rec) = self.records.pop_front() {
                self.buffered.extend(rec.bytes);
            }
        }
        let n = buf.len().min(self.buffered.len());
        for (slot, b) in buf.iter_mut().zip(self.buffered.drain(..n)) {
            *slot = b;
        }
        Ok(n)
    }

    fn discard_input(&mut self) -> Result<(), LinkError> {
        self.buffered.clear();
        Ok(())
    }

    fn set_baud(&mut self, baud: u32) -> Result<(), LinkError> {
        self.baud = baud;
        Ok(())
    }

    fn baud(&self) -> Option<u32> {
        Some(self.baud)
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;
    use robobus_whj::frame::FrameError;

    use super::*;

    fn rec(line: &str) -> CandumpRecord {
        parse_candump_line(line).unwrap()
    }

    #[test]
    fn times_are_written_with_six_decimals_as_canplayer_requires() {
        // Nanoseconds are read (other tools write them) and written to the microsecond.
        let r = rec("(12.000001999) can0 001##1024900");
        assert_eq!(r.timestamp, Duration::new(12, 1999));
        assert_eq!(format_candump_line(&r), "(12.000001) can0 001##5024900");
        assert!(format_candump_line(&rec("(1.5) can0 123#00")).starts_with("(1.500000) "));
        let h = parse_hex_line("0.001500500 < 00 7F").unwrap().unwrap();
        assert_eq!(format_hex_line(&h), "0.001500 < 00 7F");
    }

    #[test]
    fn reads_candump_lines_with_any_flags_nibble() {
        let r = rec("(1795360410.847412) vcan0 123##4DEADBEEF");
        assert_eq!(r.timestamp, Duration::new(1_795_360_410, 847_412_000));
        assert_eq!(r.iface, "vcan0");
        assert_eq!(r.frame.raw_id(), 0x123);
        assert_eq!(r.frame.data(), [0xDE, 0xAD, 0xBE, 0xEF]);
        assert!(r.frame.is_fd() && !r.frame.brs() && !r.frame.esi());
        let r = rec("(1.5) can1 12345678##3AABB.CC");
        assert!(r.frame.is_extended() && r.frame.brs() && r.frame.esi());
        assert_eq!(r.frame.len(), 3);
        assert!(rec("(0.000001) vcan0 7FF##1").frame.brs());
        assert!(rec("(0.000001) vcan0 7FF##5 R").frame.brs());
        let c = rec("(2.0) vcan0 001#0102");
        assert!(!c.frame.is_fd() && c.frame.data() == [1, 2]);
    }

    #[test]
    fn writes_what_candump_writes() {
        let f = CanFrame::new_fd(
            CanFrame::standard_id(0x123).unwrap(),
            &[0xDE, 0xAD, 0xBE, 0xEF],
        )
        .unwrap();
        let r = CandumpRecord {
            timestamp: Duration::new(1_795_360_410, 847_412_999),
            iface: "vcan0".into(),
            frame: f,
        };
        assert_eq!(
            format_candump_line(&r),
            "(1795360410.847412) vcan0 123##5DEADBEEF"
        );
        let e = CanFrame::new_classic(CanFrame::extended_id(0x1F).unwrap(), &[]).unwrap();
        let r = CandumpRecord { frame: e, ..r };
        assert_eq!(
            format_candump_line(&r),
            "(1795360410.847412) vcan0 0000001F#"
        );
    }

    #[test]
    fn errors_name_the_line_and_the_problem() {
        let text = "(1.0) vcan0 123##1AA\n\n(1.0) vcan0 123#R\n(x) vcan0 1#\n(1.0) vcan0 1234##1AA\n(1.0) vcan0 123##1A\n(1.0) vcan0 123##1AABBCCDDEEFF0011223\n(1.0) vcan0 20000080#0000000000000000\n(1.0) vcan0\n(1.0) vcan0 800#00\n";
        let results: Vec<_> = read_candump(text.as_bytes()).collect();
        assert!(results[0].is_ok());
        let errs: Vec<(usize, CandumpErrorKind)> = results[1..]
            .iter()
            .map(|r| match r {
                Err(CandumpError::Parse { line, kind }) => (*line, kind.clone()),
                other => panic!("{other:?}"),
            })
            .collect();
        assert_eq!(
            errs[0],
            (3, CandumpErrorKind::Unsupported("a remote frame"))
        );
        assert_eq!(errs[1], (4, CandumpErrorKind::Timestamp("(x)".into())));
        assert_eq!(errs[2], (5, CandumpErrorKind::Id("1234".into())));
        assert_eq!(errs[3], (6, CandumpErrorKind::Data("A".into())));
        assert!(matches!(errs[4], (7, CandumpErrorKind::Data(_))));
        assert_eq!(
            errs[5],
            (8, CandumpErrorKind::Unsupported("an error frame"))
        );
        assert_eq!(errs[6], (9, CandumpErrorKind::Layout));
        assert!(matches!(
            errs[7],
            (
                10,
                CandumpErrorKind::Frame(FrameError::IdOutOfRange { raw: 0x800 })
            )
        ));
        let shown = CandumpError::Parse {
            line: 3,
            kind: errs[0].1.clone(),
        }
        .to_string();
        assert!(shown.contains("line 3"), "{shown}");
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(512))]

        #[test]
        fn arbitrary_lines_never_panic(line in "\\PC{0,80}") {
            let _ = parse_candump_line(&line);
            let _ = parse_hex_line(&line);
        }

        #[test]
        fn candump_round_trip(id in 0u16..=0x7FF, dlc in 0u8..16, fill in any::<u8>(), brs: bool, esi: bool, secs in 0u64..4_000_000_000, micros in 0u32..1_000_000) {
            let len = robobus_whj::frame::dlc_to_len(dlc).unwrap();
            let data: Vec<u8> = (0..len).map(|i| fill ^ u8::try_from(i).unwrap()).collect();
            let frame = CanFrame::new_fd(CanFrame::standard_id(id).unwrap(), &data).unwrap().with_brs(brs).with_esi(esi);
            let r = CandumpRecord { timestamp: Duration::new(secs, micros * 1000), iface: "can0".into(), frame };
            prop_assert_eq!(parse_candump_line(&format_candump_line(&r)).unwrap(), r);
        }
    }
}
